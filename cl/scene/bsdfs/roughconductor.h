/* roughconductor.h: Mitsuba 3's `roughconductor` (MAT_ROUGHCONDUCTOR, src/bsdfs/roughconductor.cpp):
 * microfacet reflection F D G / (4 cos_i) (Walter et al. 2007), visible-normal sampling. One-sided:
 * scene/bsdf.h, which includes this file, calls it with wi.z > 0 (and wo.z > 0 for eval). */
#ifndef PYCLPT_BSDFS_ROUGHCONDUCTOR_H
#define PYCLPT_BSDFS_ROUGHCONDUCTOR_H

#include "scene/bsdfs/record.h"
#include "scene/bsdfs/fresnel.h"
#include "scene/bsdfs/microfacet.h"

/* F D G / (4 cos_i) and the pdf of roughconductor_sample. */
static inline vec3 roughconductor_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
    Microfacet d = microfacet_of(b);
    vec3 h = m_normalize(v3_add(wi, wo));
    float dh = mf_d(d, h);
    if (dh == 0.0f) return v3_splat(0.0f);
    float g1_i = mf_g1(d, wi, h);
    float g = g1_i * mf_g1(d, wo, h);
    vec3 f = v3_mul(fresnel_conductor(m_dot(wi, h), bsdf_eta(b), b->k), b->spec);
    /* pdf_visible(h) / (4 wo.h) with wi.h = wo.h */
    *pdf = dh * g1_i / (4.0f * wi.z);
    return v3_scale(f, dh * g / (4.0f * wi.z));
}

/* A visible normal, wo its mirror image; weight = F G1(wo). */
static inline bool roughconductor_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    Microfacet d = microfacet_of(b);
    vec3 h = mf_sample_visible(d, wi, u);
    s->wo = v3_sub(v3_scale(h, 2.0f * m_dot(wi, h)), wi);
    if (s->wo.z <= 0.0f) return false;
    s->pdf = mf_pdf_visible(d, wi, h) / (4.0f * m_dot(s->wo, h));
    vec3 f = v3_mul(fresnel_conductor(m_dot(wi, h), bsdf_eta(b), b->k), b->spec);
    /* with visible-normal sampling, weight = F * G1(wo) */
    s->weight = v3_scale(f, mf_g1(d, s->wo, h));
    return true;
}

#endif
