/* roughplastic.h: Mitsuba 3's `roughplastic` (MAT_ROUGHPLASTIC, src/bsdfs/roughplastic.cpp): a rough
 * coating F D G / (4 cos_i) over the plastic's diffuse base weighted by the coating's transmittance
 * t(cos) (RP_KNOTS half floats the host computed, pyclpt/buffers/microfacet.py) and its internal
 * reflectance (b->fdr_int). One-sided: scene/bsdf.h, which includes this file, calls it with
 * wi.z > 0 (and wo.z > 0 for eval). */
#ifndef PYCLPT_BSDFS_ROUGHPLASTIC_H
#define PYCLPT_BSDFS_ROUGHPLASTIC_H

#include "scene/bsdfs/record.h"
#include "core/sampling.h"
#include "scene/bsdfs/fresnel.h"
#include "scene/bsdfs/microfacet.h"
#include "scene/bsdfs/plastic.h"

/* The coating's transmittance t(cos) of a rough plastic, linear in sqrt(cos) between the knots
 * pyclpt/buffers/microfacet.py computed on the host (Mitsuba keeps a 64-entry table linear in cos). */
static inline float roughplastic_transmittance(const Bsdf* b, float cos_theta) {
    __global const ushort* knots = (__global const ushort*)(b->mat + MAT_RP_TRANS);
    float x = m_sqrt(m_clamp(cos_theta, 0.0f, 1.0f)) * (float)(RP_KNOTS - 1);
    int i = m_imin((int)x, RP_KNOTS - 2);
    float f = x - (float)i;
    float v0 = m_half_to_float(knots[i]), v1 = m_half_to_float(knots[i + 1]);
    return v0 + f * (v1 - v0);
}

/* Coating F D G / (4 cos_i) + base t_i t_o cos_o, and the pdf of both lobes together. */
static inline vec3 roughplastic_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
    Microfacet d = microfacet_of(b);
    float t_i = roughplastic_transmittance(b, wi.z), t_o = roughplastic_transmittance(b, wo.z);
    float ps = plastic_prob_specular(b, t_i);
    vec3 h = m_normalize(v3_add(wi, wo));
    float dh = mf_d(d, h);
    float g1_i = mf_g1(d, wi, h);
    float spec_pdf = dh * g1_i / (4.0f * wi.z);
    *pdf = ps * spec_pdf + (1.0f - ps) * cosine_hemisphere_pdf(wo);
    float f = fresnel_dielectric_f(m_dot(wi, h), b->ior);
    vec3 value = v3_scale(b->spec, f * dh * g1_i * mf_g1(d, wo, h) / (4.0f * wi.z));
    return v3_add(value, v3_scale(plastic_base(b), t_i * t_o * wo.z));
}

/* The coating (a visible normal) or the base (cosine-weighted), chosen by plastic_prob_specular;
 * the weight of both lobes together, as Mitsuba: eval / pdf. */
static inline bool roughplastic_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    float ps = plastic_prob_specular(b, roughplastic_transmittance(b, wi.z));
    if (u_lobe < ps) {
        vec3 h = mf_sample_visible(microfacet_of(b), wi, u);
        s->wo = v3_sub(v3_scale(h, 2.0f * m_dot(wi, h)), wi);
    } else {
        s->wo = square_to_cosine_hemisphere(u);
    }
    if (s->wo.z <= 0.0f) return false;
    /* the weight of both lobes together, as Mitsuba: eval / pdf */
    vec3 value = roughplastic_eval(b, wi, s->wo, &s->pdf);
    if (!(s->pdf > 0.0f)) return false;
    s->weight = v3_divs(value, s->pdf);
    return true;
}

#endif
