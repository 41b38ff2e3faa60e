/* bsdf.h: the materials, evaluated and sampled in the local shading frame
 * (z = shading normal). Conventions follow Mitsuba 3: wi points towards the
 * previous path vertex, wo towards the next; values include |cos(wo)|;
 * one-sided reflective materials are black when seen from behind unless the
 * material is two-sided.
 *
 * A material is MAT_STRIDE floats in the `materials` buffer (see
 * pyclpt/scene_buffers.py, which writes the same offsets). */
#ifndef PYCLPT_BSDF_H
#define PYCLPT_BSDF_H

#include "common.h"
#include "sampling.h"

#define MAT_STRIDE 16
#define MAT_DIFFUSE 0
#define MAT_CONDUCTOR 1
#define MAT_ROUGHCONDUCTOR 2
#define MAT_DIELECTRIC 3

#define MAT_TYPE 0
#define MAT_FLAGS 1
#define MAT_COLOR 2   /* reflectance (diffuse) or specular reflectance, rgb */
#define MAT_ETA 5     /* conductor eta rgb; dielectric: interior / exterior IOR in [5] */
#define MAT_K 8       /* conductor k rgb */
#define MAT_ALPHA 11  /* GGX roughness */
#define MAT_TRANS 12  /* dielectric specular transmittance rgb */

#define MAT_FLAG_TWOSIDED 1

typedef __global const float* Material;

typedef struct {
    float3 wo;      /* sampled direction, local frame */
    float3 weight;  /* value * |cos(wo)| / pdf, with the radiance-scaling factor of refraction */
    float pdf;      /* solid-angle pdf (the discrete probability for delta lobes) */
    float eta;      /* relative IOR crossed (1 for reflection) */
    bool delta;
} BsdfSample;

static inline int mat_type(Material m) { return (int)m[MAT_TYPE]; }
static inline bool mat_twosided(Material m) { return (((int)m[MAT_FLAGS]) & MAT_FLAG_TWOSIDED) != 0; }
static inline float3 mat_rgb(Material m, int at) { return (float3)(m[at], m[at + 1], m[at + 2]); }

/* True when the material has only delta lobes (no light sampling there). */
static inline bool bsdf_is_delta(Material m) {
    int t = mat_type(m);
    return t == MAT_CONDUCTOR || t == MAT_DIELECTRIC;
}

/* ---- Fresnel ---- */

/* Unpolarised Fresnel reflectance of a conductor with complex IOR eta + i k (cos_i >= 0). */
static inline float3 fresnel_conductor(float cos_i, float3 eta, float3 k) {
    float c2 = cos_i * cos_i, s2 = 1.0f - c2;
    float3 eta2 = eta * eta, k2 = k * k;
    float3 t0 = eta2 - k2 - s2;
    float3 a2pb2 = sqrt(fmax(t0 * t0 + 4.0f * eta2 * k2, 0.0f));
    float3 t1 = a2pb2 + c2;
    float3 a = sqrt(fmax(0.5f * (a2pb2 + t0), 0.0f));
    float3 t2 = 2.0f * cos_i * a;
    float3 rs = (t1 - t2) / (t1 + t2);
    float3 t3 = c2 * a2pb2 + s2 * s2;
    float3 t4 = t2 * s2;
    float3 rp = rs * (t3 - t4) / (t3 + t4);
    return 0.5f * (rp + rs);
}

/* Dielectric Fresnel reflectance for a signed cos_i (negative: from inside), eta = int/ext.
 * Returns F and the signed cosine of the refracted direction and eta_ti = 1/eta_it. */
static inline float fresnel_dielectric(float cos_i, float eta, float* cos_t, float* eta_ti) {
    bool outside = cos_i >= 0.0f;
    float eta_it = outside ? eta : 1.0f / eta;
    *eta_ti = 1.0f / eta_it;
    float cos_t_sqr = 1.0f - (1.0f - cos_i * cos_i) * (*eta_ti) * (*eta_ti);
    float ci = fabs(cos_i);
    if (cos_t_sqr <= 0.0f) {
        *cos_t = 0.0f;
        return 1.0f;
    }
    float ct = sqrt(cos_t_sqr);
    float a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    float a_p = (eta_it * ci - ct) / (eta_it * ci + ct);
    *cos_t = outside ? -ct : ct;
    return 0.5f * (a_s * a_s + a_p * a_p);
}

static inline float3 reflect_local(float3 w) { return (float3)(-w.x, -w.y, w.z); }

/* ---- GGX (Trowbridge-Reitz), isotropic ---- */

static inline float ggx_d(float3 m, float alpha) {
    if (m.z <= 0.0f) return 0.0f;
    float a2 = alpha * alpha;
    float c2 = m.z * m.z;
    float t = (m.x * m.x + m.y * m.y) / a2 + c2;
    return 1.0f / (PI_F * a2 * t * t);
}

/* Smith's shadowing term for one direction, with the microfacet m's sidedness. */
static inline float ggx_g1(float3 v, float3 m, float alpha) {
    if (dot(v, m) * v.z <= 0.0f) return 0.0f;
    float xy2 = alpha * alpha * (v.x * v.x + v.y * v.y);
    if (xy2 <= 0.0f) return 1.0f;
    float tan2 = xy2 / (v.z * v.z);
    return 2.0f / (1.0f + sqrt(1.0f + tan2));
}

/* Visible-normal sampling (Heitz 2018), wi in the upper hemisphere. */
static inline float3 ggx_sample_visible(float3 wi, float alpha, float2 u) {
    float3 vh = normalize((float3)(alpha * wi.x, alpha * wi.y, wi.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    float3 t2 = cross(vh, t1);
    float r = sqrt(u.x);
    float phi = 2.0f * PI_F * u.y;
    float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
    float3 nh = p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return normalize((float3)(alpha * nh.x, alpha * nh.y, fmax(1e-6f, nh.z)));
}

/* pdf of the visible normal m seen from wi. */
static inline float ggx_pdf_visible(float3 wi, float3 m, float alpha) {
    if (wi.z <= 0.0f) return 0.0f;
    return ggx_g1(wi, m, alpha) * fmax(dot(wi, m), 0.0f) * ggx_d(m, alpha) / wi.z;
}

/* ---- evaluation and sampling ---- */

/* Flip both directions to the front side for two-sided materials. */
static inline void bsdf_orient(Material m, float3* wi, float3* wo) {
    if (mat_twosided(m) && wi->z < 0.0f) {
        wi->z = -wi->z;
        wo->z = -wo->z;
    }
}

/* f(wi, wo) |cos wo| and the solid-angle pdf of sampling wo; zero for delta materials. */
static inline float3 bsdf_eval(Material m, float3 wi, float3 wo, float* pdf) {
    *pdf = 0.0f;
    int type = mat_type(m);
    bsdf_orient(m, &wi, &wo);
    if (wi.z <= 0.0f || wo.z <= 0.0f) return (float3)(0.0f);
    if (type == MAT_DIFFUSE) {
        *pdf = cosine_hemisphere_pdf(wo);
        return mat_rgb(m, MAT_COLOR) * (INV_PI_F * wo.z);
    }
    if (type == MAT_ROUGHCONDUCTOR) {
        float alpha = m[MAT_ALPHA];
        float3 h = normalize(wi + wo);
        float d = ggx_d(h, alpha);
        if (d == 0.0f) return (float3)(0.0f);
        float g = ggx_g1(wi, h, alpha) * ggx_g1(wo, h, alpha);
        float3 f = fresnel_conductor(dot(wi, h), mat_rgb(m, MAT_ETA), mat_rgb(m, MAT_K)) *
                   mat_rgb(m, MAT_COLOR);
        *pdf = ggx_pdf_visible(wi, h, alpha) / (4.0f * dot(wo, h));
        return f * (d * g / (4.0f * wi.z));
    }
    return (float3)(0.0f);
}

/* Sample wo given wi; false when no direction could be sampled. */
static inline bool bsdf_sample(Material m, float3 wi, float u_lobe, float2 u, BsdfSample* s) {
    int type = mat_type(m);
    s->eta = 1.0f;
    s->delta = false;
    if (type == MAT_DIELECTRIC) {
        float cos_t, eta_ti;
        float cos_i = wi.z;
        float f = fresnel_dielectric(cos_i, m[MAT_ETA], &cos_t, &eta_ti);
        s->delta = true;
        if (u_lobe <= f) {
            s->wo = reflect_local(wi);
            s->pdf = f;
            s->weight = mat_rgb(m, MAT_COLOR);
        } else {
            s->wo = (float3)(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
            s->pdf = 1.0f - f;
            s->eta = 1.0f / eta_ti;
            /* radiance is compressed into a smaller solid angle on entering */
            s->weight = mat_rgb(m, MAT_TRANS) * (eta_ti * eta_ti);
        }
        return s->pdf > 0.0f;
    }
    bool flipped = mat_twosided(m) && wi.z < 0.0f;
    if (flipped) wi.z = -wi.z;
    if (wi.z <= 0.0f) return false;
    if (type == MAT_DIFFUSE) {
        s->wo = square_to_cosine_hemisphere(u);
        s->pdf = cosine_hemisphere_pdf(s->wo);
        s->weight = mat_rgb(m, MAT_COLOR);
    } else if (type == MAT_CONDUCTOR) {
        s->wo = reflect_local(wi);
        s->pdf = 1.0f;
        s->delta = true;
        s->weight = fresnel_conductor(wi.z, mat_rgb(m, MAT_ETA), mat_rgb(m, MAT_K)) * mat_rgb(m, MAT_COLOR);
    } else if (type == MAT_ROUGHCONDUCTOR) {
        float alpha = m[MAT_ALPHA];
        float3 h = ggx_sample_visible(wi, alpha, u);
        s->wo = 2.0f * dot(wi, h) * h - wi;
        if (s->wo.z <= 0.0f) return false;
        s->pdf = ggx_pdf_visible(wi, h, alpha) / (4.0f * dot(s->wo, h));
        float3 f = fresnel_conductor(dot(wi, h), mat_rgb(m, MAT_ETA), mat_rgb(m, MAT_K)) *
                   mat_rgb(m, MAT_COLOR);
        /* with visible-normal sampling, weight = F * G1(wo) */
        s->weight = f * ggx_g1(s->wo, h, alpha);
    } else {
        return false;
    }
    if (flipped) s->wo.z = -s->wo.z;
    return s->pdf > 0.0f;
}

#endif
