/* dielectric.h: Mitsuba 3's `dielectric` (MAT_DIELECTRIC, src/bsdfs/dielectric.cpp): delta
 * reflection with probability F, else delta refraction with radiance scaled by eta_ti^2. Delta only
 * (no eval); two-sided by nature (wi on either side). Included by scene/bsdf.h. */
#ifndef PYCLPT_BSDFS_DIELECTRIC_H
#define PYCLPT_BSDFS_DIELECTRIC_H

#include "scene/bsdfs/record.h"
#include "scene/bsdfs/fresnel.h"

/* Smooth dielectric: reflection with probability F, else refraction (dielectric.cpp). */
static inline bool dielectric_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    float cos_t, eta_ti;
    float f = fresnel_dielectric(wi.z, b->ior, &cos_t, &eta_ti);
    s->delta = true;
    if (u_lobe <= f) {
        s->wo = reflect_local(wi);
        s->pdf = f;
        s->weight = b->spec;
    } else {
        s->wo = v3(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
        s->pdf = 1.0f - f;
        s->eta = 1.0f / eta_ti;
        /* radiance is compressed into a smaller solid angle on entering */
        s->weight = v3_scale(bsdf_trans(b), eta_ti * eta_ti);
    }
    return s->pdf > 0.0f;
}

#endif
