/* record.h: what every material shares (scene/bsdf.h's types): the record layout (MAT_* offsets and
 * type ids, pyclpt/buffers/materials.py writes the same), the Bsdf a kernel works with (a material's
 * parameters at one surface point, textures already looked up), BsdfSample, bsdf_from and the small
 * helpers of the materials. Each material header under scene/bsdfs/ includes this; scene/bsdf.h includes
 * it, then the materials, then holds the dispatch. */
#ifndef PYCLPT_BSDFS_RECORD_H
#define PYCLPT_BSDFS_RECORD_H

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
    vec3 color;    /* the diffuse reflectance (diffuse, plastics); a dielectric's specular transmittance
                      (bsdf_trans) and a conductor's eta (bsdf_eta) share its place: no material has two of the
                      three, and a kernel then holds one vec3 for them (mat_color_at) */
    vec3 spec;     /* specular reflectance */
    vec3 k;        /* conductor */
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

static inline bool mat_is_dielectric(int t) {
    return t == MAT_DIELECTRIC || t == MAT_ROUGHDIELECTRIC || t == MAT_THINDIELECTRIC;
}
static inline bool mat_is_conductor(int t) { return t == MAT_CONDUCTOR || t == MAT_ROUGHCONDUCTOR; }

/* Where a material of kind t keeps the parameter of Bsdf.color (its diffuse reflectance, transmittance or eta) in
 * its record, and the texture that multiplies it (-1: none; a conductor's eta has no texture). */
static inline int mat_color_at(int t) {
    return mat_is_dielectric(t) ? MAT_TRANS : mat_is_conductor(t) ? MAT_ETA : MAT_COLOR;
}
static inline int mat_color_texture(Material m, int t) {
    return mat_is_conductor(t) ? -1 : (int)m[mat_is_dielectric(t) ? MAT_TRANS_TEX : MAT_COLOR_TEX];
}

static inline int mat_type(Material m) { return (int)m[MAT_TYPE]; }
static inline int mat_flags(Material m) { return (int)m[MAT_FLAGS]; }
static inline vec3 mat_rgb(Material m, int at, int unit) { return rgb_at(m + at, unit); }

/* The material's constant parameters (textures not applied: see bsdf_at in scene.h); unit as rgb_at's. */
static inline Bsdf bsdf_from(Material m, int unit) {
    Bsdf b;
    b.type = mat_type(m);
    b.flags = mat_flags(m);
    b.color = mat_rgb(m, mat_color_at(b.type), unit);
    b.spec = mat_rgb(m, MAT_SPEC, unit);
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

/* A dielectric's specular transmittance, a conductor's eta (Bsdf.color's place). */
static inline vec3 bsdf_trans(const Bsdf* b) { return b->color; }
static inline vec3 bsdf_eta(const Bsdf* b) { return b->color; }

static inline bool bsdf_twosided(const Bsdf* b) { return (b->flags & MAT_FLAG_TWOSIDED) != 0; }

/* A rough dielectric between equal indices: nothing but straight-through transmission. */
static inline bool ior_index_matched(float ior) { return m_abs(ior - 1.0f) < BSDF_INDEX_MATCHED_EPS; }
static inline bool bsdf_index_matched(const Bsdf* b) { return ior_index_matched(b->ior); }

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

#endif
