/* conductor.h: Mitsuba 3's `conductor` (MAT_CONDUCTOR, src/bsdfs/conductor.cpp): delta reflection
 * weighted by the complex Fresnel reflectance of (bsdf_eta(b), b->k) times b->spec. Delta only (no
 * eval). One-sided: scene/bsdf.h, which includes this file, calls it with wi.z > 0. */
#ifndef PYCLPT_BSDFS_CONDUCTOR_H
#define PYCLPT_BSDFS_CONDUCTOR_H

#include "scene/bsdfs/record.h"
#include "scene/bsdfs/fresnel.h"

static inline bool conductor_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    s->wo = reflect_local(wi);
    s->pdf = 1.0f;
    s->delta = true;
    s->weight = v3_mul(fresnel_conductor(wi.z, bsdf_eta(b), b->k), b->spec);
    return true;
}

#endif
