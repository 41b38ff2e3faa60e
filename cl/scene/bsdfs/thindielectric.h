/* thindielectric.h: Mitsuba 3's `thindielectric` (MAT_THINDIELECTRIC, src/bsdfs/thindielectric.cpp):
 * a thin slab, delta reflection with the internal reflections summed, R' = 2R / (1 + R), and
 * straight-through transmission 1 - R' (no refraction, eta 1). Delta only (no eval); two-sided.
 * Included by scene/bsdf.h. */
#ifndef PYCLPT_BSDFS_THINDIELECTRIC_H
#define PYCLPT_BSDFS_THINDIELECTRIC_H

#include "scene/bsdfs/record.h"
#include "scene/bsdfs/fresnel.h"

/* R' = R + T R T / (1 - R^2) = 2R / (1 + R) with R at |cos_i| from outside; reflection with
 * probability R', else straight through. */
static inline bool thindielectric_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    float r = fresnel_dielectric_f(m_abs(wi.z), b->ior);
    r = 2.0f * r / (1.0f + r);
    s->delta = true;
    if (u_lobe < r) {
        s->wo = reflect_local(wi);
        s->pdf = r;
        s->weight = b->spec;
    } else {
        s->wo = v3_neg(wi);
        s->pdf = 1.0f - r;
        s->weight = bsdf_trans(b);
    }
    return s->pdf > 0.0f;
}

#endif
