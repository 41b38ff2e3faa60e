/* bsdf.h: the materials, evaluated and sampled in the local shading frame
 * (z = shading normal). This file holds what every material shares: the record layout
 * (MAT_* offsets and type ids), the Bsdf a kernel works with, and the dispatch the
 * integrator calls (bsdf_from, bsdf_is_delta, bsdf_eval, bsdf_sample). Each material
 * lives in its own header under scene/bsdfs/, included below, one per Mitsuba 3 plug-in.
 *
 * Conventions follow Mitsuba 3: wi points towards the previous path vertex, wo towards
 * the next; values include |cos(wo)|; one-sided reflective materials are black when seen
 * from behind unless the material is two-sided; dielectrics are two-sided and scale
 * radiance by eta_ti^2 on refraction.
 *
 * A material is MAT_STRIDE floats in the `materials` buffer (see
 * pyclpt/buffers/materials.py, which writes the same offsets); the kernels
 * resolve its textures at a surface point into a Bsdf (bsdf_at, scene.h) and
 * evaluate and sample that.
 *
 * Materials (Mitsuba 3 plug-in of the same name; the source files cited are
 * Mitsuba 3's src/bsdfs/ and include/mitsuba/render/microfacet.h):
 *   diffuse          bsdfs/diffuse.h          Lambertian, cosine-weighted sampling
 *   conductor        bsdfs/conductor.h        delta reflection, complex Fresnel
 *   roughconductor   bsdfs/roughconductor.h   microfacet reflection (Walter et al. 2007), visible normals
 *   dielectric       bsdfs/dielectric.h       delta reflection / refraction chosen by Fresnel
 *   roughdielectric  bsdfs/roughdielectric.h  microfacet reflection + refraction, visible normals,
 *                                             lobe chosen by F(wi.m)
 *   thindielectric   bsdfs/thindielectric.h   delta reflection with the internal reflections summed,
 *                                             R' = 2R / (1 + R), and straight-through transmission 1 - R'
 *   plastic          bsdfs/plastic.h          delta coating reflection + diffuse base seen through it
 *   roughplastic     bsdfs/roughplastic.h     microfacet coating reflection + diffuse base
 * Shared by them: bsdfs/fresnel.h (conductor and dielectric Fresnel) and bsdfs/microfacet.h
 * (GGX (default) or Beckmann (MAT_FLAG_BECKMANN), with Smith's separable masking (the exact
 * erfc form for Beckmann) and visible-normal sampling (Heitz 2018 for GGX; Jakob 2014's
 * numerical inversion for Beckmann)), isotropic or, for rough conductors and dielectrics,
 * anisotropic (MAT_FLAG_ANISOTROPIC, -DSCENE_HAS_ANISOTROPY).
 *
 * Mitsuba's `twosided` with two BSDFs is two records: the front one has MAT_FLAG_BACK and the back
 * one's id in MAT_BACK, and the hit takes the back one where wi is below the shading normal
 * (surface_face in scene.h, -DSCENE_HAS_BACK_MATERIALS); both are flagged two-sided, so the back one
 * sees the directions flipped to its front (bsdf_orient), as Mitsuba's twosided does.
 *
 * Adding a material: a type id below, its header under scene/bsdfs/ (NAME_eval for its
 * non-delta lobes, NAME_sample), its #include and its lines in the dispatch at the end. */
#ifndef PYCLPT_BSDF_H
#define PYCLPT_BSDF_H

#include "core/common.h"
#include "core/sampling.h"
#include "scene/bsdfs/fresnel.h"
#include "scene/bsdfs/microfacet.h"

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
#define MAT_ALPHA_V 27     /* roughconductor, roughdielectric with MAT_FLAG_ANISOTROPIC: the roughness
                              along the shading frame's t (MAT_ALPHA is alpha_u, along s) */
#define MAT_BACK 10        /* with MAT_FLAG_BACK: the back side's material id (Mitsuba `twosided` with two
                              BSDFs; the front one has no transmission, so MAT_TRANS's slot is free) */

#define MAT_FLAG_TWOSIDED 1
#define MAT_FLAG_NONLINEAR 2 /* plastic: Mitsuba's `nonlinear` internal scattering */
#define MAT_FLAG_BECKMANN 4  /* microfacet distribution: Beckmann instead of GGX */
#define MAT_FLAG_MASKED 8    /* has an opacity (Mitsuba `mask`) */
#define MAT_FLAG_ANISOTROPIC 16 /* alpha_u != alpha_v (MAT_ALPHA_V; -DSCENE_HAS_ANISOTROPY) */
#define MAT_FLAG_BACK 32     /* a different material on the back side (MAT_BACK; -DSCENE_HAS_BACK_MATERIALS) */
#define MAT_FLAG_UV_FRAME 64 /* shading frame's s from dp/du, as Mitsuba's (anisotropic materials; scene.h) */

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
    vec3 color;    /* diffuse reflectance */
    vec3 spec;     /* specular reflectance */
    vec3 trans;    /* specular transmittance */
    vec3 eta, k;   /* conductor */
    float ior;     /* interior / exterior */
    float alpha;   /* roughness (alpha_u of an anisotropic one) */
#ifdef SCENE_HAS_ANISOTROPY
    float alpha_v; /* roughness along t (MAT_ALPHA_V), read where MAT_FLAG_ANISOTROPIC is set */
#endif
    float fdr_int; /* plastic: internal diffuse reflectance of the coating */
    Material mat;  /* the record (roughplastic reads its transmittance knots from it) */
} Bsdf;

typedef struct {
    vec3 wo;        /* sampled direction, local frame */
    vec3 weight;    /* value * |cos(wo)| / pdf, with the radiance-scaling factor of refraction */
    float pdf;      /* solid-angle pdf (the discrete probability for delta lobes) */
    float eta;      /* relative IOR crossed (1 for reflection) */
    bool delta;
} BsdfSample;

static inline int mat_type(Material m) { return (int)m[MAT_TYPE]; }
static inline int mat_flags(Material m) { return (int)m[MAT_FLAGS]; }
static inline vec3 mat_rgb(Material m, int at, int unit) { return rgb_at(m + at, unit); }

/* The material's constant parameters (textures not applied: see bsdf_at in scene.h); unit as rgb_at's. */
static inline Bsdf bsdf_from(Material m, int unit) {
    Bsdf b;
    b.type = mat_type(m);
    b.flags = mat_flags(m);
    b.color = mat_rgb(m, MAT_COLOR, unit);
    b.spec = mat_rgb(m, MAT_SPEC, unit);
    b.trans = mat_rgb(m, MAT_TRANS, unit);
    b.eta = mat_rgb(m, MAT_ETA, unit);
    b.k = mat_rgb(m, MAT_K, unit);
    b.ior = m[MAT_IOR];
    b.alpha = m[MAT_ALPHA];
#ifdef SCENE_HAS_ANISOTROPY
    b.alpha_v = m[MAT_ALPHA_V];
#endif
    b.fdr_int = m[MAT_FDR_INT];
    b.mat = m;
    return b;
}

static inline bool bsdf_twosided(const Bsdf* b) { return (b->flags & MAT_FLAG_TWOSIDED) != 0; }

/* A rough dielectric between equal indices: nothing but straight-through transmission. */
static inline bool bsdf_index_matched(const Bsdf* b) { return m_abs(b->ior - 1.0f) < BSDF_INDEX_MATCHED_EPS; }

/* The microfacet distribution of a rough material (bsdfs/microfacet.h). */
static inline Microfacet microfacet_of(const Bsdf* b) {
    Microfacet d;
    d.alpha = m_max(b->alpha, BSDF_MIN_ALPHA);
#ifdef SCENE_HAS_ANISOTROPY
    d.alpha_v = (b->flags & MAT_FLAG_ANISOTROPIC) ? m_max(b->alpha_v, BSDF_MIN_ALPHA) : d.alpha;
#endif
    d.beckmann = (b->flags & MAT_FLAG_BECKMANN) != 0;
    return d;
}

static inline vec3 reflect_local(vec3 w) { return v3(-w.x, -w.y, w.z); }

static inline float mean3(vec3 v) { return (v.x + v.y + v.z) * (1.0f / 3.0f); }

/* ---- the materials, one Mitsuba plug-in each ---- */

#include "scene/bsdfs/diffuse.h"
#include "scene/bsdfs/conductor.h"
#include "scene/bsdfs/roughconductor.h"
#include "scene/bsdfs/dielectric.h"
#include "scene/bsdfs/roughdielectric.h"
#include "scene/bsdfs/thindielectric.h"
#include "scene/bsdfs/plastic.h"
#include "scene/bsdfs/roughplastic.h"

/* ---- dispatch ---- */

/* -DSCENE_MATERIALS=mask (pyclpt/buffers/materials.py) lists the material kinds a scene has (bit MAT_*): the
 * dispatch below compiles only those, so a stage shading one kind has no branch on the kind and can be
 * vectorized. Without it every kind is compiled. */
#ifdef SCENE_MATERIALS
#define HAS_MATERIAL(t) ((bool)(((SCENE_MATERIALS) >> (t)) & 1))
#else
#define HAS_MATERIAL(t) true
#endif

/* True when the material has only delta lobes (no light sampling there). */
static inline bool bsdf_is_delta(const Bsdf* b) {
    int t = b->type; /* one test per kind, each compiled only for a kind the scene has */
    if (HAS_MATERIAL(MAT_CONDUCTOR) && t == MAT_CONDUCTOR) return true;
    if (HAS_MATERIAL(MAT_DIELECTRIC) && t == MAT_DIELECTRIC) return true;
    if (HAS_MATERIAL(MAT_THINDIELECTRIC) && t == MAT_THINDIELECTRIC) return true;
    return HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && t == MAT_ROUGHDIELECTRIC && bsdf_index_matched(b);
}

/* The G-buffer's albedo (film/aovs.h), what a denoiser demodulates by: the diffuse reflectance of
 * diffuse and plastic materials, a rough conductor's specular reflectance times its Fresnel
 * reflectance at normal incidence, a rough dielectric's specular transmittance. Delta materials
 * have none: the G-buffer takes the next non-delta vertex's. */
static inline vec3 bsdf_albedo(const Bsdf* b) {
    int t = b->type;
    if (HAS_MATERIAL(MAT_ROUGHCONDUCTOR) && t == MAT_ROUGHCONDUCTOR) {
        vec3 e = b->eta, k = b->k;
        vec3 k2 = v3_mul(k, k);
        vec3 em = v3_sub(e, v3_splat(1.0f)), ep = v3_add(e, v3_splat(1.0f));
        vec3 f0 = v3_div(v3_add(v3_mul(em, em), k2), v3_add(v3_mul(ep, ep), k2));
        return v3_mul(b->spec, f0);
    }
    if (HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && t == MAT_ROUGHDIELECTRIC) return b->trans;
    return b->color;
}

/* The G-buffer's linear roughness: the microfacet alpha of rough conductors and dielectrics (of an
 * anisotropic one sqrt(alpha_u alpha_v)), 1 for diffuse and plastic materials (their diffuse base), 0 for
 * smooth conductors and dielectrics. */
static inline float bsdf_rough_alpha(const Bsdf* b) {
#ifdef SCENE_HAS_ANISOTROPY
    if (b->flags & MAT_FLAG_ANISOTROPIC) return m_sqrt(b->alpha * b->alpha_v);
#endif
    return b->alpha;
}

static inline float bsdf_roughness(const Bsdf* b) {
    int t = b->type;
    if (HAS_MATERIAL(MAT_ROUGHCONDUCTOR) && t == MAT_ROUGHCONDUCTOR) return bsdf_rough_alpha(b);
    if (HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && t == MAT_ROUGHDIELECTRIC) return bsdf_rough_alpha(b);
    return bsdf_is_delta(b) ? 0.0f : 1.0f;
}

/* Flip both directions to the front side for two-sided materials. */
static inline void bsdf_orient(const Bsdf* b, vec3* wi, vec3* wo) {
    if (bsdf_twosided(b) && wi->z < 0.0f) {
        wi->z = -wi->z;
        wo->z = -wo->z;
    }
}

/* f(wi, wo) |cos wo| and the solid-angle pdf of bsdf_sample producing wo, both of the
 * non-delta lobes only (zero for delta materials). */
static inline vec3 bsdf_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
    *pdf = 0.0f;
    int type = b->type;
    /* two-sided by nature: both directions as they are */
    if (HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && type == MAT_ROUGHDIELECTRIC) return roughdielectric_eval(b, wi, wo, pdf);
    /* one-sided: on the front side (two-sided ones flipped there) */
    bsdf_orient(b, &wi, &wo);
    if (wi.z <= 0.0f || wo.z <= 0.0f) return v3_splat(0.0f);
    if (HAS_MATERIAL(MAT_DIFFUSE) && type == MAT_DIFFUSE) return diffuse_eval(b, wi, wo, pdf);
    if (HAS_MATERIAL(MAT_ROUGHCONDUCTOR) && type == MAT_ROUGHCONDUCTOR) return roughconductor_eval(b, wi, wo, pdf);
    if (HAS_MATERIAL(MAT_PLASTIC) && type == MAT_PLASTIC) return plastic_eval(b, wi, wo, pdf);
    if (HAS_MATERIAL(MAT_ROUGHPLASTIC) && type == MAT_ROUGHPLASTIC) return roughplastic_eval(b, wi, wo, pdf);
    return v3_splat(0.0f); /* conductor, dielectric, thindielectric: delta lobes only */
}

/* Sample wo given wi; false when no direction could be sampled. */
static inline bool bsdf_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
    int type = b->type;
    s->eta = 1.0f;
    s->delta = false;
    /* two-sided by nature: wi on either side */
    if (HAS_MATERIAL(MAT_DIELECTRIC) && type == MAT_DIELECTRIC) return dielectric_sample(b, wi, u_lobe, u, s);
    if (HAS_MATERIAL(MAT_THINDIELECTRIC) && type == MAT_THINDIELECTRIC) return thindielectric_sample(b, wi, u_lobe, u, s);
    if (HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && type == MAT_ROUGHDIELECTRIC) return roughdielectric_sample(b, wi, u_lobe, u, s);
    /* one-sided: sampled on the front side, wo mirrored back for a two-sided material seen from behind */
    bool flipped = bsdf_twosided(b) && wi.z < 0.0f;
    if (flipped) wi.z = -wi.z;
    if (wi.z <= 0.0f) return false;
    bool sampled;
    if (HAS_MATERIAL(MAT_DIFFUSE) && type == MAT_DIFFUSE) sampled = diffuse_sample(b, wi, u_lobe, u, s);
    else if (HAS_MATERIAL(MAT_CONDUCTOR) && type == MAT_CONDUCTOR) sampled = conductor_sample(b, wi, u_lobe, u, s);
    else if (HAS_MATERIAL(MAT_ROUGHCONDUCTOR) && type == MAT_ROUGHCONDUCTOR) sampled = roughconductor_sample(b, wi, u_lobe, u, s);
    else if (HAS_MATERIAL(MAT_PLASTIC) && type == MAT_PLASTIC) sampled = plastic_sample(b, wi, u_lobe, u, s);
    else if (HAS_MATERIAL(MAT_ROUGHPLASTIC) && type == MAT_ROUGHPLASTIC) sampled = roughplastic_sample(b, wi, u_lobe, u, s);
    else return false;
    if (!sampled) return false;
    if (flipped) s->wo.z = -s->wo.z;
    return s->pdf > 0.0f;
}

#endif
