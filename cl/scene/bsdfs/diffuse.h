/* diffuse.h: Mitsuba 3's `diffuse` (MAT_DIFFUSE, src/bsdfs/diffuse.cpp): Lambertian reflection of
 * the diffuse reflectance b->color, cosine-weighted sampling. One-sided: scene/bsdf.h, which
 * dispatches to it, calls it with wi.z > 0 (and wo.z > 0 for eval). */
#ifndef PYCLPT_BSDFS_DIFFUSE_H
#define PYCLPT_BSDFS_DIFFUSE_H

#include "scene/bsdfs/record.h"
#include "core/sampling.h"

static inline vec3 diffuse_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
    *pdf = cosine_hemisphere_pdf(wo);
    return v3_scale(b->color, INV_PI_F * wo.z);
}

static inline bool diffuse_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    s->wo = square_to_cosine_hemisphere(u);
    s->pdf = cosine_hemisphere_pdf(s->wo);
    s->weight = b->color;
    return true;
}

#endif
