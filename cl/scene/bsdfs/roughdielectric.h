/* roughdielectric.h: Mitsuba 3's `roughdielectric` (MAT_ROUGHDIELECTRIC, src/bsdfs/roughdielectric.cpp):
 * microfacet reflection and refraction (Walter et al. 2007), a visible normal of wi's side, the
 * lobe chosen by F(wi.m). Two-sided (wi on either side). An index-matched interface
 * (bsdf_index_matched) is a delta pass-through. Included by scene/bsdf.h. */
#ifndef PYCLPT_BSDFS_ROUGHDIELECTRIC_H
#define PYCLPT_BSDFS_ROUGHDIELECTRIC_H

#include "scene/bsdfs/record.h"
#include "scene/bsdfs/fresnel.h"
#include "scene/bsdfs/microfacet.h"

/* Walter et al. 2007, eqs. 20-21, with Mitsuba's radiance scaling:
 * reflection F D G / (4 |cos_i|); refraction eta^2 (1 - F) D G |wi.m| |wo.m| / (|cos_i| (wi.m + eta wo.m)^2)
 * times the radiance scaling 1 / eta^2, which cancels, eta being the IOR of wo's side over wi's.
 * The pdf is that of roughdielectric_sample: visible normal, lobe probability, half-vector Jacobian. */
static inline vec3 roughdielectric_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
    float cos_i = wi.z, cos_o = wo.z;
    if (cos_i == 0.0f || cos_o == 0.0f || bsdf_index_matched(b)) return v3_splat(0.0f);
    Microfacet d = microfacet_of(b);
    bool reflect = cos_i * cos_o > 0.0f;
    float eta = cos_i > 0.0f ? b->ior : 1.0f / b->ior; /* IOR of wo's side over wi's */
    vec3 hv = v3_add(wi, v3_scale(wo, reflect ? 1.0f : eta));
    float len = m_length(hv);
    if (!(len > 1e-7f)) return v3_splat(0.0f);
    vec3 m = v3_divs(hv, len);
    if (m.z < 0.0f) m = v3_neg(m);
    float dm = mf_d(d, m);
    float g1_i = mf_g1(d, wi, m), g1_o = mf_g1(d, wo, m);
    if (dm == 0.0f || g1_i == 0.0f || g1_o == 0.0f) return v3_splat(0.0f);
    float wi_m = m_dot(wi, m), wo_m = m_dot(wo, m);
    float ct, eti;
    float f = fresnel_dielectric(wi_m, b->ior, &ct, &eti);
    float aci = m_abs(cos_i);
    /* visible-normal density from wi flipped to the upper side: D G1(wi) |wi.m| / |cos_i| */
    float prob = dm * g1_i * m_abs(wi_m) / aci;
    if (reflect) {
        *pdf = prob * f / (4.0f * m_abs(wo_m));
        return v3_scale(b->spec, f * dm * g1_i * g1_o / (4.0f * aci));
    }
    float denom = wi_m + eta * wo_m;
    float denom2 = denom * denom;
    *pdf = prob * (1.0f - f) * (eta * eta * m_abs(wo_m) / denom2);
    return v3_scale(bsdf_trans(b), (1.0f - f) * dm * g1_i * g1_o * m_abs(wi_m * wo_m) / (aci * denom2));
}

/* A visible normal of wi's side, then reflection with probability F(wi.m), else refraction
 * through m; weight = G1(wo, m) (times eta_ti^2 on refraction). */
static inline bool roughdielectric_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    float cos_i = wi.z;
    if (cos_i == 0.0f) return false;
    if (bsdf_index_matched(b)) { /* an invisible interface */
        s->wo = v3_neg(wi);
        s->pdf = 1.0f;
        s->delta = true;
        s->weight = bsdf_trans(b);
        return true;
    }
    Microfacet d = microfacet_of(b);
    vec3 wi_up = cos_i > 0.0f ? wi : v3_neg(wi);
    vec3 m = mf_sample_visible(d, wi_up, u);
    float pdf_m = mf_pdf_visible(d, wi_up, m);
    if (!(pdf_m > 0.0f)) return false;
    float cos_t, eta_ti;
    float wi_m = m_dot(wi, m);
    float f = fresnel_dielectric(wi_m, b->ior, &cos_t, &eta_ti);
    if (u_lobe <= f) {
        s->wo = v3_sub(v3_scale(m, 2.0f * wi_m), wi);
        float wo_m = m_dot(s->wo, m);
        s->pdf = pdf_m * f / (4.0f * m_abs(wo_m));
        s->weight = b->spec;
    } else {
        s->wo = v3_sub(v3_scale(m, wi_m * eta_ti + cos_t), v3_scale(wi, eta_ti));
        float eta = 1.0f / eta_ti;
        float wo_m = m_dot(s->wo, m);
        float denom = wi_m + eta * wo_m;
        s->pdf = pdf_m * (1.0f - f) * (eta * eta * m_abs(wo_m) / (denom * denom));
        s->eta = eta;
        s->weight = v3_scale(bsdf_trans(b), eta_ti * eta_ti);
    }
    float g1_o = mf_g1(d, s->wo, m);
    if (g1_o == 0.0f) return false; /* wo on the wrong side of the macrosurface */
    s->weight = v3_scale(s->weight, g1_o);
    return s->pdf > 0.0f && m_isfinite(s->pdf);
}

#endif
