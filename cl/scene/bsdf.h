/* bsdf.h: the materials, evaluated and sampled in the local shading frame
 * (z = shading normal). Conventions follow Mitsuba 3: wi points towards the
 * previous path vertex, wo towards the next; values include |cos(wo)|;
 * one-sided reflective materials are black when seen from behind unless the
 * material is two-sided; dielectrics are two-sided and scale radiance by
 * eta_ti^2 on refraction.
 *
 * A material is MAT_STRIDE floats in the `materials` buffer (see
 * pyclpt/material_buffers.py, which writes the same offsets); the kernels
 * resolve its textures at a surface point into a Bsdf (bsdf_at, scene.h) and
 * evaluate and sample that.
 *
 * Materials (Mitsuba 3 plugin of the same name; the source files cited are
 * Mitsuba 3's src/bsdfs/ and include/mitsuba/render/microfacet.h):
 *   diffuse          Lambertian, cosine-weighted sampling
 *   conductor        delta reflection, complex Fresnel
 *   roughconductor   microfacet reflection (Walter et al. 2007), visible normals
 *   dielectric       delta reflection / refraction chosen by Fresnel
 *   roughdielectric  microfacet reflection + refraction (Walter et al. 2007,
 *                    roughdielectric.cpp), visible normals, lobe chosen by F(wi.m)
 *   thindielectric   delta reflection with the internal reflections summed,
 *                    R' = 2R / (1 + R), and straight-through transmission 1 - R'
 *   plastic          delta coating reflection + diffuse base seen through it
 *                    (plastic.cpp)
 *   roughplastic     microfacet coating reflection + diffuse base (roughplastic.cpp)
 * Microfacet distributions: GGX (default) or Beckmann (MAT_FLAG_BECKMANN), with
 * Smith's separable masking (the exact erfc form for Beckmann) and visible-normal
 * sampling (Heitz 2018 for GGX; Jakob 2014's numerical inversion for Beckmann). */
#ifndef PYCLPT_BSDF_H
#define PYCLPT_BSDF_H

#include "core/common.h"
#include "core/sampling.h"

#define MAT_STRIDE 32
#define MAT_DIFFUSE 0
#define MAT_CONDUCTOR 1
#define MAT_ROUGHCONDUCTOR 2
#define MAT_DIELECTRIC 3
#define MAT_ROUGHDIELECTRIC 4
#define MAT_THINDIELECTRIC 5
#define MAT_PLASTIC 6
#define MAT_ROUGHPLASTIC 7

#define MAT_TYPE 0
#define MAT_FLAGS 1
#define MAT_COLOR 2        /* rgb: diffuse reflectance (diffuse, plastic) */
#define MAT_COLOR_TEX 5    /* texture multiplying MAT_COLOR, or -1 */
#define MAT_SPEC 6         /* rgb: specular reflectance */
#define MAT_SPEC_TEX 9
#define MAT_TRANS 10       /* rgb: specular transmittance (dielectrics) */
#define MAT_IOR 13         /* interior / exterior IOR (dielectrics, plastic) */
#define MAT_ETA 14         /* rgb: conductor eta */
#define MAT_K 17           /* rgb: conductor k */
#define MAT_ALPHA 20       /* microfacet roughness */
#define MAT_OPACITY 21     /* mask: opacity (1 = opaque) ... */
#define MAT_OPACITY_TEX 22 /* ... or its texture, or -1 */
#define MAT_BUMP_TEX 23    /* bump map height texture, or -1 */
#define MAT_BUMP_SCALE 24
#define MAT_FDR_INT 25     /* plastic: diffuse Fresnel reflectance seen from inside the coating;
                              roughplastic: the rough coating's internal reflectance */
#define MAT_TRANS_TEX 26
#define MAT_RP_TRANS 27    /* roughplastic: RP_KNOTS half floats (5 slots, 27..31): the coating's
                              transmittance t(cos) at cos = (k / (RP_KNOTS - 1))^2 */
#define RP_KNOTS 10

#define MAT_FLAG_TWOSIDED 1
#define MAT_FLAG_NONLINEAR 2 /* plastic: Mitsuba's `nonlinear` internal scattering */
#define MAT_FLAG_BECKMANN 4  /* microfacet distribution: Beckmann instead of GGX */
#define MAT_FLAG_MASKED 8    /* has an opacity (Mitsuba `mask`) */

/* Relative IORs closer to 1 than this make a rough dielectric an index-matched
 * (invisible) interface: the microfacet refraction lobe degenerates to a delta. */
#define BSDF_INDEX_MATCHED_EPS 1e-4f
/* Mitsuba's lower bound on microfacet roughness. */
#define BSDF_MIN_ALPHA 1e-4f

typedef __global const float* Material;

/* A material's parameters at one surface point (textures already looked up). */
typedef struct {
    int type;
    int flags;
    float3 color;  /* diffuse reflectance */
    float3 spec;   /* specular reflectance */
    float3 trans;  /* specular transmittance */
    float3 eta, k; /* conductor */
    float ior;     /* interior / exterior */
    float alpha;   /* roughness */
    float fdr_int; /* plastic: internal diffuse reflectance of the coating */
    Material mat;  /* the record (roughplastic reads its transmittance knots from it) */
} Bsdf;

typedef struct {
    float3 wo;      /* sampled direction, local frame */
    float3 weight;  /* value * |cos(wo)| / pdf, with the radiance-scaling factor of refraction */
    float pdf;      /* solid-angle pdf (the discrete probability for delta lobes) */
    float eta;      /* relative IOR crossed (1 for reflection) */
    bool delta;
} BsdfSample;

static inline int mat_type(Material m) { return (int)m[MAT_TYPE]; }
static inline int mat_flags(Material m) { return (int)m[MAT_FLAGS]; }
static inline float3 mat_rgb(Material m, int at) { return (float3)(m[at], m[at + 1], m[at + 2]); }

/* The material's constant parameters (textures not applied: see bsdf_at in scene.h). */
static inline Bsdf bsdf_from(Material m) {
    Bsdf b;
    b.type = mat_type(m);
    b.flags = mat_flags(m);
    b.color = mat_rgb(m, MAT_COLOR);
    b.spec = mat_rgb(m, MAT_SPEC);
    b.trans = mat_rgb(m, MAT_TRANS);
    b.eta = mat_rgb(m, MAT_ETA);
    b.k = mat_rgb(m, MAT_K);
    b.ior = m[MAT_IOR];
    b.alpha = m[MAT_ALPHA];
    b.fdr_int = m[MAT_FDR_INT];
    b.mat = m;
    return b;
}

static inline bool bsdf_twosided(const Bsdf* b) { return (b->flags & MAT_FLAG_TWOSIDED) != 0; }

/* A rough dielectric between equal indices: nothing but straight-through transmission. */
static inline bool bsdf_index_matched(const Bsdf* b) { return fabs(b->ior - 1.0f) < BSDF_INDEX_MATCHED_EPS; }

/* True when the material has only delta lobes (no light sampling there). */
static inline bool bsdf_is_delta(const Bsdf* b) {
    int t = b->type;
    return t == MAT_CONDUCTOR || t == MAT_DIELECTRIC || t == MAT_THINDIELECTRIC ||
           (t == MAT_ROUGHDIELECTRIC && bsdf_index_matched(b));
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

/* F alone, for cos_i >= 0 on the outside of an interface int/ext = eta. */
static inline float fresnel_dielectric_f(float cos_i, float eta) {
    float ct, eti;
    return fresnel_dielectric(cos_i, eta, &ct, &eti);
}

static inline float3 reflect_local(float3 w) { return (float3)(-w.x, -w.y, w.z); }

static inline float mean3(float3 v) { return (v.x + v.y + v.z) * (1.0f / 3.0f); }

/* ---- microfacet distributions: isotropic GGX (Trowbridge-Reitz) and Beckmann ----
 * Following Walter et al. 2007 and Mitsuba 3's microfacet.h; m is a microfacet normal
 * with m.z > 0, v any direction. */

typedef struct {
    float alpha;
    bool beckmann;
} Microfacet;

static inline Microfacet microfacet_of(const Bsdf* b) {
    Microfacet d;
    d.alpha = fmax(b->alpha, BSDF_MIN_ALPHA);
    d.beckmann = (b->flags & MAT_FLAG_BECKMANN) != 0;
    return d;
}

#define INV_SQRT_PI_F 0.56418958354775628695f

/* Inverse error function, single precision (Giles 2012, "Approximating the erfinv function",
 * GPU Computing Gems Jade ch. 10); |x| < 1. */
static inline float erfinv_f(float x) {
    float w = -log(fmax((1.0f - x) * (1.0f + x), 1e-30f));
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
        w = sqrt(w) - 3.0f;
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
static inline float mf_d(Microfacet d, float3 m) {
    if (!(m.z > 0.0f)) return 0.0f;
    float a2 = d.alpha * d.alpha;
    float c2 = m.z * m.z;
    float xy2 = m.x * m.x + m.y * m.y;
    float r;
    if (d.beckmann) {
        float e = exp(-xy2 / (a2 * c2));
        if (e == 0.0f) return 0.0f;
        r = e / (PI_F * a2 * c2 * c2);
    } else {
        float t = xy2 / a2 + c2;
        r = 1.0f / (PI_F * a2 * t * t);
    }
    /* as Mitsuba: drop values too small to matter (avoids denormals downstream) */
    return (r * m.z > 1e-20f && isfinite(r)) ? r : 0.0f;
}

/* Smith's masking for one direction, zero where v sees the back of m (or m from behind). */
static inline float mf_g1(Microfacet d, float3 v, float3 m) {
    if (dot(v, m) * v.z <= 0.0f) return 0.0f;
    float xy2 = d.alpha * d.alpha * (v.x * v.x + v.y * v.y);
    if (xy2 <= 0.0f) return 1.0f;
    if (d.beckmann) {
        /* a = 1 / (alpha tan theta); Lambda(a) = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2 */
        float a = fabs(v.z) / sqrt(xy2);
        if (a > 9.0f) return 1.0f;
        float lambda = 0.5f * (exp(-a * a) * INV_SQRT_PI_F / a - erfc(a));
        return 1.0f / (1.0f + fmax(lambda, 0.0f));
    }
    float tan2 = xy2 / (v.z * v.z);
    return 2.0f / (1.0f + sqrt(1.0f + tan2));
}

/* Visible-normal sampling of GGX at alpha = 1 (Heitz 2018, "Sampling the GGX Distribution of
 * Visible Normals"): the stretched direction vh (z > 0) to a normal of the hemisphere. */
static inline float3 ggx_sample_visible_11(float3 vh, float2 u) {
    float lensq = vh.x * vh.x + vh.y * vh.y;
    float3 t1 = lensq > 0.0f ? (float3)(-vh.y, vh.x, 0.0f) * rsqrt(lensq) : (float3)(1.0f, 0.0f, 0.0f);
    float3 t2 = cross(vh, t1);
    float r = sqrt(u.x);
    float phi = 2.0f * PI_F * u.y;
    float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(fmax(0.0f, 1.0f - p1 * p1)) + s * p2;
    return p1 * t1 + p2 * t2 + sqrt(fmax(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
}

/* Visible-slope sampling of Beckmann at alpha = 1 for an incident cosine cos_i > 0
 * (Jakob 2014, "An Improved Visible Normal Sampling Routine for the Beckmann Distribution",
 * as in Mitsuba 3's sample_visible_11): the slope CDF inverted by Newton steps in the erf domain. */
static inline float2 beckmann_sample_visible_11(float cos_i, float2 u) {
    float tan_i = sqrt(fmax(0.0f, 1.0f - cos_i * cos_i)) / cos_i;
    float cot_i = 1.0f / tan_i; /* inf at normal incidence: erf(inf) = 1, exp(-inf) = 0 */
    float maxval = erf(cot_i);
    float gauss = tan_i > 0.0f ? INV_SQRT_PI_F * tan_i * exp(-cot_i * cot_i) : 0.0f;
    u = clamp(u, 1e-6f, 1.0f - 1e-6f);
    /* initial guess: the analytic solution at grazing incidence */
    float x = maxval - (maxval + 1.0f) * erf(sqrt(-log(u.x)));
    float target = u.x * (1.0f + maxval + gauss);
    const float lo = -1.0f + 1e-6f;
    float hi = fmax(lo, fmin(maxval, 1.0f - 1e-6f));
    x = clamp(x, lo, hi);
    for (int i = 0; i < 3; ++i) {
        float slope = erfinv_f(x);
        float value = 1.0f + x + INV_SQRT_PI_F * tan_i * exp(-slope * slope) - target;
        float deriv = 1.0f - slope * tan_i;
        float step = value / deriv;
        if (isfinite(step)) x = clamp(x - step, lo, hi);
    }
    return (float2)(erfinv_f(x), erfinv_f(clamp(2.0f * u.y - 1.0f, lo, 1.0f - 1e-6f)));
}

/* A visible normal for wi (wi.z > 0), distributed as D(m) G1(wi, m) max(0, wi.m) / wi.z. */
static inline float3 mf_sample_visible(Microfacet d, float3 wi, float2 u) {
    float3 vh = normalize((float3)(d.alpha * wi.x, d.alpha * wi.y, wi.z));
    float3 m;
    if (d.beckmann) {
        float lensq = vh.x * vh.x + vh.y * vh.y;
        float inv = lensq > 0.0f ? rsqrt(lensq) : 0.0f;
        float cos_phi = lensq > 0.0f ? vh.x * inv : 1.0f, sin_phi = vh.y * inv;
        float2 s = beckmann_sample_visible_11(vh.z, u);
        float sx = (cos_phi * s.x - sin_phi * s.y) * d.alpha;
        float sy = (sin_phi * s.x + cos_phi * s.y) * d.alpha;
        m = (float3)(-sx, -sy, 1.0f);
    } else {
        float3 nh = ggx_sample_visible_11(vh, u);
        m = (float3)(d.alpha * nh.x, d.alpha * nh.y, fmax(1e-6f, nh.z));
    }
    return normalize(m);
}

/* Density of mf_sample_visible producing m (per unit solid angle of m). */
static inline float mf_pdf_visible(Microfacet d, float3 wi, float3 m) {
    if (wi.z <= 0.0f) return 0.0f;
    return mf_d(d, m) * mf_g1(d, wi, m) * fmax(dot(wi, m), 0.0f) / wi.z;
}

/* ---- lobes (directions already oriented: wi.z > 0 for the one-sided ones) ---- */

/* Rough conductor: F D G / (4 cos_i), visible-normal sampling (roughconductor.cpp). */
static inline float3 roughconductor_eval(const Bsdf* b, float3 wi, float3 wo, float* pdf) {
    Microfacet d = microfacet_of(b);
    float3 h = normalize(wi + wo);
    float dh = mf_d(d, h);
    if (dh == 0.0f) return (float3)(0.0f);
    float g1_i = mf_g1(d, wi, h);
    float g = g1_i * mf_g1(d, wo, h);
    float3 f = fresnel_conductor(dot(wi, h), b->eta, b->k) * b->spec;
    /* pdf_visible(h) / (4 wo.h) with wi.h = wo.h */
    *pdf = dh * g1_i / (4.0f * wi.z);
    return f * (dh * g / (4.0f * wi.z));
}

/* The coating's transmittance t(cos) of a rough plastic, linear in sqrt(cos) between the knots
 * pyclpt/microfacet.py computed on the host (Mitsuba keeps a 64-entry table linear in cos). */
static inline float roughplastic_transmittance(const Bsdf* b, float cos_theta) {
    __global const half* knots = (__global const half*)(b->mat + MAT_RP_TRANS);
    float x = sqrt(clamp(cos_theta, 0.0f, 1.0f)) * (float)(RP_KNOTS - 1);
    int i = min((int)x, RP_KNOTS - 2);
    float f = x - (float)i;
    float v0 = vload_half(i, knots), v1 = vload_half(i + 1, knots);
    return v0 + f * (v1 - v0);
}

/* Probability of sampling the specular (coating) lobe of the plastics: Mitsuba's
 * F_i s / (F_i s + (1 - F_i)(1 - s)) with s = mean(specular) / (mean(diffuse) + mean(specular)),
 * where Mitsuba's means are over whole textures and these are the values at this point.
 * t_i is the coating's transmittance (1 - F_i for the smooth coating). */
static inline float plastic_prob_specular(const Bsdf* b, float t_i) {
    float sm = mean3(b->spec), dm = mean3(b->color);
    float s = (sm + dm) > 0.0f ? sm / (sm + dm) : 0.5f;
    float ps = (1.0f - t_i) * s, pd = t_i * (1.0f - s);
    return (ps + pd) > 0.0f ? ps / (ps + pd) : s;
}

/* The diffuse base seen through the coating, without the transmittances:
 * diffuse / (1 - (nonlinear ? diffuse * r_int : r_int)) / eta^2 / pi. */
static inline float3 plastic_base(const Bsdf* b) {
    float3 diff = b->color;
    float3 denom = (b->flags & MAT_FLAG_NONLINEAR) ? 1.0f - diff * b->fdr_int : (float3)(1.0f - b->fdr_int);
    return diff / fmax(denom, 1e-6f) * (INV_PI_F / (b->ior * b->ior));
}

/* Smooth plastic, diffuse part (plastic.cpp): base (1 - F_i)(1 - F_o) cos_o. */
static inline float3 plastic_eval(const Bsdf* b, float3 wi, float3 wo, float* pdf) {
    float f_i = fresnel_dielectric_f(wi.z, b->ior), f_o = fresnel_dielectric_f(wo.z, b->ior);
    float pd = 1.0f - plastic_prob_specular(b, 1.0f - f_i);
    *pdf = pd * cosine_hemisphere_pdf(wo);
    return plastic_base(b) * ((1.0f - f_i) * (1.0f - f_o) * wo.z);
}

/* Rough plastic (roughplastic.cpp): coating F D G / (4 cos_i) + base t_i t_o cos_o. */
static inline float3 roughplastic_eval(const Bsdf* b, float3 wi, float3 wo, float* pdf) {
    Microfacet d = microfacet_of(b);
    float t_i = roughplastic_transmittance(b, wi.z), t_o = roughplastic_transmittance(b, wo.z);
    float ps = plastic_prob_specular(b, t_i);
    float3 h = normalize(wi + wo);
    float dh = mf_d(d, h);
    float g1_i = mf_g1(d, wi, h);
    float spec_pdf = dh * g1_i / (4.0f * wi.z);
    *pdf = ps * spec_pdf + (1.0f - ps) * cosine_hemisphere_pdf(wo);
    float f = fresnel_dielectric_f(dot(wi, h), b->ior);
    float3 value = b->spec * (f * dh * g1_i * mf_g1(d, wo, h) / (4.0f * wi.z));
    return value + plastic_base(b) * (t_i * t_o * wo.z);
}

/* Rough dielectric (Walter et al. 2007, eqs. 20-21, with Mitsuba's radiance scaling; roughdielectric.cpp):
 * reflection F D G / (4 |cos_i|); refraction eta^2 (1 - F) D G |wi.m| |wo.m| / (|cos_i| (wi.m + eta wo.m)^2)
 * times the radiance scaling 1 / eta^2, which cancels, eta being the IOR of wo's side over wi's.
 * The pdf is that of roughdielectric_sample: visible normal, lobe probability, half-vector Jacobian. */
static inline float3 roughdielectric_eval(const Bsdf* b, float3 wi, float3 wo, float* pdf) {
    float cos_i = wi.z, cos_o = wo.z;
    if (cos_i == 0.0f || cos_o == 0.0f || bsdf_index_matched(b)) return (float3)(0.0f);
    Microfacet d = microfacet_of(b);
    bool reflect = cos_i * cos_o > 0.0f;
    float eta = cos_i > 0.0f ? b->ior : 1.0f / b->ior; /* IOR of wo's side over wi's */
    float3 hv = wi + wo * (reflect ? 1.0f : eta);
    float len = length(hv);
    if (!(len > 1e-7f)) return (float3)(0.0f);
    float3 m = hv / len;
    if (m.z < 0.0f) m = -m;
    float dm = mf_d(d, m);
    float g1_i = mf_g1(d, wi, m), g1_o = mf_g1(d, wo, m);
    if (dm == 0.0f || g1_i == 0.0f || g1_o == 0.0f) return (float3)(0.0f);
    float wi_m = dot(wi, m), wo_m = dot(wo, m);
    float ct, eti;
    float f = fresnel_dielectric(wi_m, b->ior, &ct, &eti);
    float aci = fabs(cos_i);
    /* visible-normal density from wi flipped to the upper side: D G1(wi) |wi.m| / |cos_i| */
    float prob = dm * g1_i * fabs(wi_m) / aci;
    if (reflect) {
        *pdf = prob * f / (4.0f * fabs(wo_m));
        return b->spec * (f * dm * g1_i * g1_o / (4.0f * aci));
    }
    float denom = wi_m + eta * wo_m;
    float denom2 = denom * denom;
    *pdf = prob * (1.0f - f) * (eta * eta * fabs(wo_m) / denom2);
    return b->trans * ((1.0f - f) * dm * g1_i * g1_o * fabs(wi_m * wo_m) / (aci * denom2));
}

/* ---- evaluation and sampling ---- */

/* Flip both directions to the front side for two-sided materials. */
static inline void bsdf_orient(const Bsdf* b, float3* wi, float3* wo) {
    if (bsdf_twosided(b) && wi->z < 0.0f) {
        wi->z = -wi->z;
        wo->z = -wo->z;
    }
}

/* f(wi, wo) |cos wo| and the solid-angle pdf of bsdf_sample producing wo, both of the
 * non-delta lobes only (zero for delta materials). */
static inline float3 bsdf_eval(const Bsdf* b, float3 wi, float3 wo, float* pdf) {
    *pdf = 0.0f;
    int type = b->type;
    if (type == MAT_ROUGHDIELECTRIC) return roughdielectric_eval(b, wi, wo, pdf);
    bsdf_orient(b, &wi, &wo);
    if (wi.z <= 0.0f || wo.z <= 0.0f) return (float3)(0.0f);
    if (type == MAT_DIFFUSE) {
        *pdf = cosine_hemisphere_pdf(wo);
        return b->color * (INV_PI_F * wo.z);
    }
    if (type == MAT_ROUGHCONDUCTOR) return roughconductor_eval(b, wi, wo, pdf);
    if (type == MAT_PLASTIC) return plastic_eval(b, wi, wo, pdf);
    if (type == MAT_ROUGHPLASTIC) return roughplastic_eval(b, wi, wo, pdf);
    return (float3)(0.0f);
}

/* Smooth dielectric: reflection with probability F, else refraction (dielectric.cpp). */
static inline bool dielectric_sample(const Bsdf* b, float3 wi, float u_lobe, BsdfSample* s) {
    float cos_t, eta_ti;
    float f = fresnel_dielectric(wi.z, b->ior, &cos_t, &eta_ti);
    s->delta = true;
    if (u_lobe <= f) {
        s->wo = reflect_local(wi);
        s->pdf = f;
        s->weight = b->spec;
    } else {
        s->wo = (float3)(-eta_ti * wi.x, -eta_ti * wi.y, cos_t);
        s->pdf = 1.0f - f;
        s->eta = 1.0f / eta_ti;
        /* radiance is compressed into a smaller solid angle on entering */
        s->weight = b->trans * (eta_ti * eta_ti);
    }
    return s->pdf > 0.0f;
}

/* Thin dielectric (thindielectric.cpp): R' = R + T R T / (1 - R^2) = 2R / (1 + R) with R at |cos_i|
 * from outside; reflection with probability R', else straight through (no refraction, eta 1). */
static inline bool thindielectric_sample(const Bsdf* b, float3 wi, float u_lobe, BsdfSample* s) {
    float r = fresnel_dielectric_f(fabs(wi.z), b->ior);
    r = 2.0f * r / (1.0f + r);
    s->delta = true;
    if (u_lobe < r) {
        s->wo = reflect_local(wi);
        s->pdf = r;
        s->weight = b->spec;
    } else {
        s->wo = -wi;
        s->pdf = 1.0f - r;
        s->weight = b->trans;
    }
    return s->pdf > 0.0f;
}

/* Rough dielectric: a visible normal of wi's side, then reflection with probability F(wi.m),
 * else refraction through m; weight = G1(wo, m) (times eta_ti^2 on refraction). */
static inline bool roughdielectric_sample(const Bsdf* b, float3 wi, float u_lobe, float2 u, BsdfSample* s) {
    float cos_i = wi.z;
    if (cos_i == 0.0f) return false;
    if (bsdf_index_matched(b)) { /* an invisible interface */
        s->wo = -wi;
        s->pdf = 1.0f;
        s->delta = true;
        s->weight = b->trans;
        return true;
    }
    Microfacet d = microfacet_of(b);
    float3 wi_up = cos_i > 0.0f ? wi : -wi;
    float3 m = mf_sample_visible(d, wi_up, u);
    float pdf_m = mf_pdf_visible(d, wi_up, m);
    if (!(pdf_m > 0.0f)) return false;
    float cos_t, eta_ti;
    float wi_m = dot(wi, m);
    float f = fresnel_dielectric(wi_m, b->ior, &cos_t, &eta_ti);
    if (u_lobe <= f) {
        s->wo = 2.0f * wi_m * m - wi;
        float wo_m = dot(s->wo, m);
        s->pdf = pdf_m * f / (4.0f * fabs(wo_m));
        s->weight = b->spec;
    } else {
        s->wo = m * (wi_m * eta_ti + cos_t) - wi * eta_ti;
        float eta = 1.0f / eta_ti;
        float wo_m = dot(s->wo, m);
        float denom = wi_m + eta * wo_m;
        s->pdf = pdf_m * (1.0f - f) * (eta * eta * fabs(wo_m) / (denom * denom));
        s->eta = eta;
        s->weight = b->trans * (eta_ti * eta_ti);
    }
    float g1_o = mf_g1(d, s->wo, m);
    if (g1_o == 0.0f) return false; /* wo on the wrong side of the macrosurface */
    s->weight *= g1_o;
    return s->pdf > 0.0f && isfinite(s->pdf);
}

/* Sample wo given wi; false when no direction could be sampled. */
static inline bool bsdf_sample(const Bsdf* b, float3 wi, float u_lobe, float2 u, BsdfSample* s) {
    int type = b->type;
    s->eta = 1.0f;
    s->delta = false;
    if (type == MAT_DIELECTRIC) return dielectric_sample(b, wi, u_lobe, s);
    if (type == MAT_THINDIELECTRIC) return thindielectric_sample(b, wi, u_lobe, s);
    if (type == MAT_ROUGHDIELECTRIC) return roughdielectric_sample(b, wi, u_lobe, u, s);
    bool flipped = bsdf_twosided(b) && wi.z < 0.0f;
    if (flipped) wi.z = -wi.z;
    if (wi.z <= 0.0f) return false;
    if (type == MAT_DIFFUSE) {
        s->wo = square_to_cosine_hemisphere(u);
        s->pdf = cosine_hemisphere_pdf(s->wo);
        s->weight = b->color;
    } else if (type == MAT_CONDUCTOR) {
        s->wo = reflect_local(wi);
        s->pdf = 1.0f;
        s->delta = true;
        s->weight = fresnel_conductor(wi.z, b->eta, b->k) * b->spec;
    } else if (type == MAT_ROUGHCONDUCTOR) {
        Microfacet d = microfacet_of(b);
        float3 h = mf_sample_visible(d, wi, u);
        s->wo = 2.0f * dot(wi, h) * h - wi;
        if (s->wo.z <= 0.0f) return false;
        s->pdf = mf_pdf_visible(d, wi, h) / (4.0f * dot(s->wo, h));
        float3 f = fresnel_conductor(dot(wi, h), b->eta, b->k) * b->spec;
        /* with visible-normal sampling, weight = F * G1(wo) */
        s->weight = f * mf_g1(d, s->wo, h);
    } else if (type == MAT_PLASTIC) {
        float f_i = fresnel_dielectric_f(wi.z, b->ior);
        float ps = plastic_prob_specular(b, 1.0f - f_i);
        if (u_lobe < ps) {
            s->wo = reflect_local(wi);
            s->pdf = ps;
            s->delta = true;
            s->weight = b->spec * (f_i / ps);
        } else {
            s->wo = square_to_cosine_hemisphere(u);
            if (s->wo.z <= 0.0f) return false;
            float3 value = plastic_eval(b, wi, s->wo, &s->pdf);
            s->weight = value / s->pdf;
        }
    } else if (type == MAT_ROUGHPLASTIC) {
        float ps = plastic_prob_specular(b, roughplastic_transmittance(b, wi.z));
        if (u_lobe < ps) {
            float3 h = mf_sample_visible(microfacet_of(b), wi, u);
            s->wo = 2.0f * dot(wi, h) * h - wi;
        } else {
            s->wo = square_to_cosine_hemisphere(u);
        }
        if (s->wo.z <= 0.0f) return false;
        /* the weight of both lobes together, as Mitsuba: eval / pdf */
        float3 value = roughplastic_eval(b, wi, s->wo, &s->pdf);
        if (!(s->pdf > 0.0f)) return false;
        s->weight = value / s->pdf;
    } else {
        return false;
    }
    if (flipped) s->wo.z = -s->wo.z;
    return s->pdf > 0.0f;
}

#endif
