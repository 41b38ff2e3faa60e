/* bsdf_derivative.h: derivatives of a BSDF's value with respect to its parameters, at a pair of
 * directions, for the gradient kernels.
 *
 * A path's contribution through a vertex is proportional to the BSDF value f there (the sampling pdf
 * is held fixed: sampling decisions are not differentiated, as in Mitsuba's prb), so the derivative of
 * the contribution C is C (df/dtheta) / f, channel by channel.
 *
 * Non-delta lobes: df/dtheta by central differences of bsdf_eval itself, the BSDF's own code, at the
 * same two directions: every channel of f depends only on that channel of a reflectance, so one pair
 * of evaluations per parameter group gives its three channels. f is linear in the reflectances of
 * every material but the `nonlinear` plastic, where differences are exact; the step is
 * BSDF_DIFF_STEP (reflectances) or BSDF_DIFF_STEP * alpha (roughness): relative errors near 1e-4.
 * The roughness moves through records packed again on the host with alpha (1 +- BSDF_DIFF_STEP)
 * (Grads.alpha_up, alpha_down), so a rough plastic's coating tables (its transmittance and internal
 * reflectance, which depend on alpha) move with it.
 * Delta lobes (conductor, plastic's coating): their value is specular reflectance * Fresnel, so
 * (df/dspec) / f = 1 / spec. */
#ifndef PYCLPT_BSDF_DERIVATIVE_H
#define PYCLPT_BSDF_DERIVATIVE_H

#include "gradients/params.h"

#define BSDF_DIFF_STEP (1.0f / 64.0f)

#if defined(GRAD_COLOR) || defined(GRAD_SPEC) || defined(GRAD_ALPHA)
#define GRAD_BSDF 1 /* some material parameter is differentiated */
#endif

typedef struct {
    vec3 color; /* per channel: MAT_COLOR */
    vec3 spec;  /* MAT_SPEC */
    float alpha;
} BsdfAdjoint;

static inline vec3 safe_div3(vec3 a, vec3 b) {
    return v3(b.x != 0.0f ? a.x / b.x : 0.0f, b.y != 0.0f ? a.y / b.y : 0.0f, b.z != 0.0f ? a.z / b.z : 0.0f);
}

/* bsdf_eval of b with one reflectance moved by d * h (group 0: colour, 1: specular). */
static inline vec3 bsdf_eval_moved(const Bsdf* b, vec3 wi, vec3 wo, int group, vec3 d, float h) {
    Bsdf m = *b;
    if (group == 0) m.color = v3_add(m.color, v3_scale(d, h));
    else m.spec = v3_add(m.spec, v3_scale(d, h));
    float pdf;
    return bsdf_eval(&m, wi, wo, &pdf);
}

/* d f / d(reflectance group) along direction d, by central differences (step h along d). */
static inline vec3 bsdf_eval_derivative(const Bsdf* b, vec3 wi, vec3 wo, int group, vec3 d, float h) {
    vec3 fp = bsdf_eval_moved(b, wi, wo, group, d, h);
    vec3 fm = bsdf_eval_moved(b, wi, wo, group, d, -h);
    return v3_scale(v3_sub(fp, fm), 0.5f / h);
}

/* b with the roughness (and what depends on it: a rough plastic's coating tables) of record `rec`. */
static inline vec3 bsdf_eval_record(const Bsdf* b, Material rec, vec3 wi, vec3 wo) {
    Bsdf m = *b;
    m.alpha = rec[MAT_ALPHA];
    m.fdr_int = rec[MAT_FDR_INT];
    m.mat = rec;
    float pdf;
    return bsdf_eval(&m, wi, wo, &pdf);
}

/* d f / d alpha of material `mat`, by central differences between its records packed with alpha moved
 * up and down (Grads.alpha_up, alpha_down). */
static inline vec3 bsdf_alpha_derivative(const Grads* gr, int mat, const Bsdf* b, vec3 wi, vec3 wo) {
    Material up = gr->alpha_up + MAT_STRIDE * mat, down = gr->alpha_down + MAT_STRIDE * mat;
    float h = up[MAT_ALPHA] - down[MAT_ALPHA];
    if (!(h > 0.0f)) return v3_splat(0.0f);
    return v3_scale(v3_sub(bsdf_eval_record(b, up, wi, wo), bsdf_eval_record(b, down, wi, wo)), 1.0f / h);
}

/* The derivatives of f with respect to the material's parameters, divided by f, channel by channel
 * (0 where f is 0): the adjoint of a parameter is then a * ratio, a = the adjoint of the radiance that
 * went through f (bsdf_adjoint). delta: wo is a delta lobe's direction. Only the groups compiled in
 * (GRAD_COLOR, GRAD_SPEC, GRAD_ALPHA) are evaluated. */
typedef struct {
    vec3 color;
    vec3 spec;
    vec3 alpha;
} BsdfRatios;

static inline BsdfRatios bsdf_ratios(const Grads* gr, const Surface* s, const Bsdf* b, vec3 wi, vec3 wo, bool delta) {
    BsdfRatios r;
    r.color = v3_splat(0.0f);
    r.spec = v3_splat(0.0f);
    r.alpha = v3_splat(0.0f);
    int t = b->type;
    if (delta) {
#ifdef GRAD_SPEC
        /* value = spec * Fresnel: (d value / d spec) / value = 1 / spec */
        if (t == MAT_CONDUCTOR || t == MAT_PLASTIC) r.spec = safe_div3(v3_splat(1.0f), b->spec);
#endif
        return r;
    }
    float pdf;
    vec3 f = bsdf_eval(b, wi, wo, &pdf);
#ifdef GRAD_COLOR
    if (mat_has_color(t)) r.color = safe_div3(bsdf_eval_derivative(b, wi, wo, 0, v3_splat(1.0f), BSDF_DIFF_STEP), f);
#endif
#ifdef GRAD_SPEC
    if (mat_has_spec(t) && t != MAT_CONDUCTOR)
        r.spec = safe_div3(bsdf_eval_derivative(b, wi, wo, 1, v3_splat(1.0f), BSDF_DIFF_STEP), f);
#endif
#ifdef GRAD_ALPHA
    if (mat_has_alpha(t)) r.alpha = safe_div3(bsdf_alpha_derivative(gr, s->material, b, wi, wo), f);
#endif
    return r;
}

/* The adjoints of the parameters for the adjoint a of the radiance that went through f. */
static inline BsdfAdjoint bsdf_adjoint(const BsdfRatios* r, vec3 a) {
    BsdfAdjoint g;
    g.color = v3_mul(a, r->color);
    g.spec = v3_mul(a, r->spec);
    g.alpha = a.x * r->alpha.x + a.y * r->alpha.y + a.z * r->alpha.z;
    return g;
}

/* True when the material at a vertex has a parameter being differentiated. */
static inline bool bsdf_differentiated(const Bsdf* b) {
    int t = b->type;
    bool any = false;
#ifdef GRAD_COLOR
    any = any || mat_has_color(t);
#endif
#ifdef GRAD_SPEC
    any = any || mat_has_spec(t);
#endif
#ifdef GRAD_ALPHA
    any = any || mat_has_alpha(t);
#endif
    return any;
}

/* The tangents of a material's parameters at a surface point (forward mode). */
typedef struct {
    vec3 color, spec;
    float alpha;
} BsdfTangent;

/* Forward mode at one vertex: (df along the tangent) / f, channel by channel (0 where f is 0). */
static inline vec3 bsdf_tangent_ratio(const Grads* tg, const Surface* s, const Bsdf* b, vec3 wi, vec3 wo, bool delta,
                                      const BsdfTangent* d) {
    int t = b->type;
    if (delta) {
        if (t == MAT_CONDUCTOR || t == MAT_PLASTIC) return safe_div3(d->spec, b->spec);
        return v3_splat(0.0f);
    }
    float pdf;
    vec3 f = bsdf_eval(b, wi, wo, &pdf);
    vec3 df = v3_splat(0.0f);
    if (mat_has_color(t) && !v3_is_zero(d->color))
        df = v3_add(df, bsdf_eval_derivative(b, wi, wo, 0, d->color, BSDF_DIFF_STEP));
    if (mat_has_spec(t) && t != MAT_CONDUCTOR && !v3_is_zero(d->spec))
        df = v3_add(df, bsdf_eval_derivative(b, wi, wo, 1, d->spec, BSDF_DIFF_STEP));
    if (mat_has_alpha(t) && d->alpha != 0.0f)
        df = v3_add(df, v3_scale(bsdf_alpha_derivative(tg, s->material, b, wi, wo), d->alpha));
    return safe_div3(df, f);
}

/* Reverse mode: a vertex's parameter adjoints to the gradient buffers (material `material` at uv). */
static inline void grad_bsdf(const Scene* sc, Grads* gr, int material, vec2 uv, const BsdfAdjoint* g) {
#ifdef GRAD_COLOR
    if (!v3_is_zero(g->color)) grad_color(sc, gr, material, MAT_COLOR, MAT_COLOR_TEX, uv, g->color);
#endif
#ifdef GRAD_SPEC
    if (!v3_is_zero(g->spec)) grad_color(sc, gr, material, MAT_SPEC, MAT_SPEC_TEX, uv, g->spec);
#endif
#ifdef GRAD_ALPHA
    grad_put3(gr, gr->mats + MAT_STRIDE * material + MAT_ALPHA, v3(g->alpha, 0.0f, 0.0f));
#endif
}

/* Forward mode: the tangents of the material at s. */
static inline BsdfTangent tangent_bsdf(const Scene* sc, const Grads* tg, const Surface* s) {
    BsdfTangent d;
    d.color = tangent_color(sc, tg, s->material, MAT_COLOR, MAT_COLOR_TEX, s->uv);
    d.spec = tangent_color(sc, tg, s->material, MAT_SPEC, MAT_SPEC_TEX, s->uv);
    d.alpha = tg->mats[MAT_STRIDE * s->material + MAT_ALPHA];
    return d;
}

#endif
