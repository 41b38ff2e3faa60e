/* plastic.h: Mitsuba 3's `plastic` (MAT_PLASTIC, src/bsdfs/plastic.cpp): a smooth dielectric coating
 * (delta reflection F_i times b->spec) over a diffuse base b->color seen through it, with the
 * coating's internal reflections (b->fdr_int; MAT_FLAG_NONLINEAR for Mitsuba's `nonlinear`). Also
 * the helpers roughplastic.h shares: the lobe-choice probability and the base. One-sided:
 * scene/bsdf.h, which includes this file, calls it with wi.z > 0 (and wo.z > 0 for eval). */
#ifndef PYCLPT_BSDFS_PLASTIC_H
#define PYCLPT_BSDFS_PLASTIC_H

#include "scene/bsdfs/record.h"
#include "core/sampling.h"
#include "scene/bsdfs/fresnel.h"

/* Probability of sampling the specular (coating) lobe of the plastics: Mitsuba's
 * F_i s / (F_i s + (1 - F_i)(1 - s)) with s = mean(specular) / (mean(diffuse) + mean(specular)),
 * where Mitsuba's means are over whole textures and these are the values at this point.
 * t_i is the coating's transmittance (1 - F_i for the smooth coating). */
static inline float plastic_prob_specular(const Bsdf* b, float t_i) {
    float sm = mean3(b->spec), dm = mean3(b->color);
    float s = (sm + dm) > 0.0f ? sm / (sm + dm) : 0.5f;
    float ps = (1.0f - t_i) * s, pd = t_i * (1.0f - s);
    /* at most 1: a GPU compiler may contract ps + pd into fma((1 - t_i), s, pd), whose unrounded product can
     * fall below the rounded ps (NVIDIA's OpenCL: 1 + 2^-23, so 1 - this a negative pdf) */
    return (ps + pd) > 0.0f ? m_min(ps / (ps + pd), 1.0f) : s;
}

/* The diffuse base seen through the coating, without the transmittances:
 * diffuse / (1 - (nonlinear ? diffuse * r_int : r_int)) / eta^2 / pi. */
static inline vec3 plastic_base(const Bsdf* b) {
    vec3 diff = b->color;
    vec3 denom = (b->flags & MAT_FLAG_NONLINEAR) ? v3_rsubs(1.0f, v3_scale(diff, b->fdr_int)) : v3_splat(1.0f - b->fdr_int);
    return v3_scale(v3_div(diff, m_max3s(denom, 1e-6f)), INV_PI_F / (b->ior * b->ior));
}

/* The diffuse part (the coating is a delta): base (1 - F_i)(1 - F_o) cos_o. */
static inline vec3 plastic_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
    float f_i = fresnel_dielectric_f(wi.z, b->ior), f_o = fresnel_dielectric_f(wo.z, b->ior);
    float pd = 1.0f - plastic_prob_specular(b, 1.0f - f_i);
    *pdf = pd * cosine_hemisphere_pdf(wo);
    return v3_scale(plastic_base(b), (1.0f - f_i) * (1.0f - f_o) * wo.z);
}

/* The coating's mirror direction with probability plastic_prob_specular, else the base's
 * cosine-weighted direction. */
static inline bool plastic_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    float f_i = fresnel_dielectric_f(wi.z, b->ior);
    float ps = plastic_prob_specular(b, 1.0f - f_i);
    if (u_lobe < ps) {
        s->wo = reflect_local(wi);
        s->pdf = ps;
        s->delta = true;
        s->weight = v3_scale(b->spec, f_i / ps);
    } else {
        s->wo = square_to_cosine_hemisphere(u);
        if (s->wo.z <= 0.0f) return false;
        vec3 value = plastic_eval(b, wi, s->wo, &s->pdf);
        s->weight = v3_divs(value, s->pdf);
    }
    return true;
}

#endif
