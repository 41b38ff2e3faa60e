/* bsdf.h: the materials, evaluated and sampled in the local shading frame
 * (z = shading normal). This file holds the dispatch the integrator calls (bsdf_is_delta,
 * bsdf_eval, bsdf_sample); what every material shares (the record layout: MAT_* offsets and type
 * ids; the Bsdf a kernel works with; bsdf_from) is in scene/bsdfs/record.h, which each material's
 * header includes. Each material lives in its own header under scene/bsdfs/, one per Mitsuba 3
 * plug-in, included below (no header includes this one: no circle).
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
 * Adding a material: a type id in scene/bsdfs/record.h, its header under scene/bsdfs/ (including
 * record.h; NAME_eval for its non-delta lobes, NAME_sample), its #include and its lines in the
 * dispatch below. */
#ifndef PYCLPT_BSDF_H
#define PYCLPT_BSDF_H

#include "scene/bsdfs/record.h"

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

/* True when a material of kind t (MAT_*) and relative IOR ior has only delta lobes (no light sampling there). */
static inline bool kind_is_delta(int t, float ior) {
    /* one test per kind, each compiled only for a kind the scene has */
    if (HAS_MATERIAL(MAT_CONDUCTOR) && t == MAT_CONDUCTOR) return true;
    if (HAS_MATERIAL(MAT_DIELECTRIC) && t == MAT_DIELECTRIC) return true;
    if (HAS_MATERIAL(MAT_THINDIELECTRIC) && t == MAT_THINDIELECTRIC) return true;
    return HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && t == MAT_ROUGHDIELECTRIC && ior_index_matched(ior);
}

static inline bool bsdf_is_delta(const Bsdf* b) { return kind_is_delta(b->type, b->ior); }

/* The same from the material's record, before its textures are looked up (bsdf_at). */
static inline bool mat_is_delta(Material m) { return kind_is_delta(mat_type(m), m[MAT_IOR]); }

/* The G-buffer's albedo (film/aovs.h), what a denoiser demodulates by: the diffuse reflectance of
 * diffuse and plastic materials, a rough conductor's specular reflectance times its Fresnel
 * reflectance at normal incidence, a rough dielectric's specular transmittance. Delta materials
 * have none: the G-buffer takes the next non-delta vertex's. */
static inline vec3 bsdf_albedo(const Bsdf* b) {
    int t = b->type;
    if (HAS_MATERIAL(MAT_ROUGHCONDUCTOR) && t == MAT_ROUGHCONDUCTOR) {
        vec3 e = bsdf_eta(b), k = b->k;
        vec3 k2 = v3_mul(k, k);
        vec3 em = v3_sub(e, v3_splat(1.0f)), ep = v3_add(e, v3_splat(1.0f));
        vec3 f0 = v3_div(v3_add(v3_mul(em, em), k2), v3_add(v3_mul(ep, ep), k2));
        return v3_mul(b->spec, f0);
    }
    if (HAS_MATERIAL(MAT_ROUGHDIELECTRIC) && t == MAT_ROUGHDIELECTRIC) return bsdf_trans(b);
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
static inline GPU_INLINE vec3 bsdf_eval(const Bsdf* b, vec3 wi, vec3 wo, float* pdf) {
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
static inline GPU_INLINE bool bsdf_sample(const Bsdf* b, vec3 wi, float u_lobe, vec2 u, BsdfSample* s) {
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
