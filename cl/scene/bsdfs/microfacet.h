/* microfacet.h: the microfacet distributions of the rough materials, GGX (Trowbridge-Reitz) and
 * Beckmann, following Walter et al. 2007 and Mitsuba 3's microfacet.h: D(m), Smith's masking G1 and
 * visible-normal sampling with its pdf (Heitz 2018 for GGX, Jakob 2014 for Beckmann). m is a
 * microfacet normal with m.z > 0, v any direction. Needs nothing but core/common.h; scene/bsdf.h
 * makes a Microfacet from a material (microfacet_of).
 *
 * Anisotropic roughness (Mitsuba's alpha_u along the shading frame's s = x axis, alpha_v along t = y)
 * is compiled in with -DSCENE_HAS_ANISOTROPY (pyclpt/buffers/materials.py); an isotropic
 * distribution (alpha_v == alpha) then still takes the isotropic arithmetic, so its results are the
 * same bits as without the define. Sampling stretches by (alpha, alpha_v), which for an isotropic
 * distribution is the same multiplication as before. */
#ifndef PYCLPT_BSDFS_MICROFACET_H
#define PYCLPT_BSDFS_MICROFACET_H

#include "core/common.h"

typedef struct {
    float alpha; /* alpha_u: roughness along x (the shading frame's s) */
#ifdef SCENE_HAS_ANISOTROPY
    float alpha_v; /* roughness along y (t); == alpha for an isotropic distribution */
#endif
    bool beckmann;
} Microfacet;

/* The roughness along y. */
static inline float mf_alpha_v(Microfacet d) {
#ifdef SCENE_HAS_ANISOTROPY
    return d.alpha_v;
#else
    return d.alpha;
#endif
}

/* True for an anisotropic distribution (never without -DSCENE_HAS_ANISOTROPY). */
static inline bool mf_anisotropic(Microfacet d) {
#ifdef SCENE_HAS_ANISOTROPY
    return d.alpha_v != d.alpha;
#else
    return false;
#endif
}

#define INV_SQRT_PI_F 0.56418958354775628695f

/* Inverse error function, single precision (Giles 2012, "Approximating the erfinv function",
 * GPU Computing Gems Jade ch. 10); |x| < 1. */
static inline float erfinv_f(float x) {
    float w = -m_log(m_max((1.0f - x) * (1.0f + x), 1e-30f));
    float p;
    if (w < 5.0f) {
        w = w - 2.5f;
        p = 2.81022636e-08f;
        p = 3.43273939e-07f + p * w;
        p = -3.5233877e-06f + p * w;
        p = -4.39150654e-06f + p * w;
        p = 0.00021858087f + p * w;
        p = -0.00125372503f + p * w;
        p = -0.00417768164f + p * w;
        p = 0.246640727f + p * w;
        p = 1.50140941f + p * w;
    } else {
        w = m_sqrt(w) - 3.0f;
        p = -0.000200214257f;
        p = 0.000100950558f + p * w;
        p = 0.00134934322f + p * w;
        p = -0.00367342844f + p * w;
        p = 0.00573950773f + p * w;
        p = -0.0076224613f + p * w;
        p = 0.00943887047f + p * w;
        p = 1.00167406f + p * w;
        p = 2.83297682f + p * w;
    }
    return p * x;
}

/* The normal distribution D(m) (per unit solid angle of m; integrates D(m) m.z to 1). */
static inline float mf_d(Microfacet d, vec3 m) {
    if (!(m.z > 0.0f)) return 0.0f;
    float a2 = d.alpha * d.alpha;
    float c2 = m.z * m.z;
    float xy2 = m.x * m.x + m.y * m.y;
    float r;
    if (d.beckmann) {
        float ex = xy2 / (a2 * c2);
        if (mf_anisotropic(d)) { /* (x / alpha_u)^2 + (y / alpha_v)^2 in place of xy2 / alpha^2 */
            float sx = m.x / d.alpha, sy = m.y / mf_alpha_v(d);
            ex = (sx * sx + sy * sy) / c2;
            a2 = d.alpha * mf_alpha_v(d);
        }
        float e = m_exp(-ex);
        if (e == 0.0f) return 0.0f;
        r = e / (PI_F * a2 * c2 * c2);
    } else {
        float t = xy2 / a2 + c2;
        if (mf_anisotropic(d)) {
            float sx = m.x / d.alpha, sy = m.y / mf_alpha_v(d);
            t = sx * sx + sy * sy + c2;
            a2 = d.alpha * mf_alpha_v(d);
        }
        r = 1.0f / (PI_F * a2 * t * t);
    }
    /* as Mitsuba: drop values too small to matter (avoids denormals downstream) */
    return (r * m.z > 1e-20f && m_isfinite(r)) ? r : 0.0f;
}

/* Smith's masking for one direction, zero where v sees the back of m (or m from behind). */
static inline float mf_g1(Microfacet d, vec3 v, vec3 m) {
    if (m_dot(v, m) * v.z <= 0.0f) return 0.0f;
    float xy2 = d.alpha * d.alpha * (v.x * v.x + v.y * v.y);
    if (mf_anisotropic(d)) { /* (alpha_u v.x)^2 + (alpha_v v.y)^2 */
        float sx = d.alpha * v.x, sy = mf_alpha_v(d) * v.y;
        xy2 = sx * sx + sy * sy;
    }
    if (xy2 <= 0.0f) return 1.0f;
    if (d.beckmann) {
        /* a = 1 / (alpha tan theta); Lambda(a) = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2 */
        float a = m_abs(v.z) / m_sqrt(xy2);
        if (a > 9.0f) return 1.0f;
        float lambda = 0.5f * (m_exp(-a * a) * INV_SQRT_PI_F / a - erfc(a)); /* exact erfc: see core/math.h */
        return 1.0f / (1.0f + m_max(lambda, 0.0f));
    }
    float tan2 = xy2 / (v.z * v.z);
    return 2.0f / (1.0f + m_sqrt(1.0f + tan2));
}

/* Visible-normal sampling of GGX at alpha = 1 (Heitz 2018, "Sampling the GGX Distribution of
 * Visible Normals"): the stretched direction vh (z > 0) to a normal of the hemisphere. */
static inline vec3 ggx_sample_visible_11(vec3 vh, vec2 u) {
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 0.0f ? v3_scale(v3(-vh.y, vh.x, 0.0f), m_rsqrt(lensq)) : v3(1.0f, 0.0f, 0.0f);
    vec3 t2 = m_cross(vh, t1);
    float r = m_sqrt(u.x);
    float phi = 2.0f * PI_F * u.y;
    float cos_phi, sin_phi = m_sincos(phi, &cos_phi);
    float p1 = r * cos_phi;
    float p2 = r * sin_phi;
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * m_sqrt(m_max(0.0f, 1.0f - p1 * p1)) + s * p2;
    return v3_add(v3_add(v3_scale(t1, p1), v3_scale(t2, p2)), v3_scale(vh, m_sqrt(m_max(0.0f, 1.0f - p1 * p1 - p2 * p2))));
}

/* Visible-slope sampling of Beckmann at alpha = 1 for an incident cosine cos_i > 0
 * (Jakob 2014, "An Improved Visible Normal Sampling Routine for the Beckmann Distribution",
 * as in Mitsuba 3's sample_visible_11): the slope CDF inverted by Newton steps in the erf domain. */
static inline vec2 beckmann_sample_visible_11(float cos_i, vec2 u) {
    float tan_i = m_sqrt(m_max(0.0f, 1.0f - cos_i * cos_i)) / cos_i;
    float cot_i = 1.0f / tan_i; /* inf at normal incidence: erf(inf) = 1, exp(-inf) = 0 */
    float maxval = erf(cot_i); /* exact erf (core/math.h) */
    float gauss = tan_i > 0.0f ? INV_SQRT_PI_F * tan_i * m_exp(-cot_i * cot_i) : 0.0f;
    u = v2(m_clamp(u.x, 1e-6f, 1.0f - 1e-6f), m_clamp(u.y, 1e-6f, 1.0f - 1e-6f));
    /* initial guess: the analytic solution at grazing incidence */
    float x = maxval - (maxval + 1.0f) * erf(m_sqrt(-m_log(u.x)));
    float target = u.x * (1.0f + maxval + gauss);
    const float lo = -1.0f + 1e-6f;
    float hi = m_max(lo, m_min(maxval, 1.0f - 1e-6f));
    x = m_clamp(x, lo, hi);
    for (int i = 0; i < 3; ++i) {
        float slope = erfinv_f(x);
        float value = 1.0f + x + INV_SQRT_PI_F * tan_i * m_exp(-slope * slope) - target;
        float deriv = 1.0f - slope * tan_i;
        float step = value / deriv;
        if (m_isfinite(step)) x = m_clamp(x - step, lo, hi);
    }
    return v2(erfinv_f(x), erfinv_f(m_clamp(2.0f * u.y - 1.0f, lo, 1.0f - 1e-6f)));
}

/* A visible normal for wi (wi.z > 0), distributed as D(m) G1(wi, m) max(0, wi.m) / wi.z. */
static inline GPU_INLINE vec3 mf_sample_visible(Microfacet d, vec3 wi, vec2 u) {
    float ay = mf_alpha_v(d);
    vec3 vh = m_normalize(v3(d.alpha * wi.x, ay * wi.y, wi.z));
    vec3 m;
    if (d.beckmann) {
        float lensq = vh.x * vh.x + vh.y * vh.y;
        float inv = lensq > 0.0f ? m_rsqrt(lensq) : 0.0f;
        float cos_phi = lensq > 0.0f ? vh.x * inv : 1.0f, sin_phi = vh.y * inv;
        vec2 s = beckmann_sample_visible_11(vh.z, u);
        float sx = (cos_phi * s.x - sin_phi * s.y) * d.alpha;
        float sy = (sin_phi * s.x + cos_phi * s.y) * ay;
        m = v3(-sx, -sy, 1.0f);
    } else {
        vec3 nh = ggx_sample_visible_11(vh, u);
        m = v3(d.alpha * nh.x, ay * nh.y, m_max(1e-6f, nh.z));
    }
    return m_normalize(m);
}

/* Density of mf_sample_visible producing m (per unit solid angle of m). */
static inline float mf_pdf_visible(Microfacet d, vec3 wi, vec3 m) {
    if (wi.z <= 0.0f) return 0.0f;
    return mf_d(d, m) * mf_g1(d, wi, m) * m_max(m_dot(wi, m), 0.0f) / wi.z;
}

#endif
