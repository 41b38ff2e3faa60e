/* params.h: the scene's differentiable parameters as the gradient kernels see them.
 *
 * A gradient (reverse mode) or a tangent (forward mode) has the layout of the scene buffers it
 * differentiates, so a parameter is the same slots in both (pyclpt/gradients/layout.py maps names
 * to slots):
 *   mats   MAT_STRIDE floats per material: MAT_COLOR (rgb), MAT_SPEC (rgb), MAT_ALPHA
 *   lights LIGHT_STRIDE floats per emitter: LIGHT_RADIANCE (rgb) of emissive triangles and of the
 *          constant environment
 *   tex8   4 floats (RGBA) per texel of texels8: the texel's linear value (after sRGB decoding)
 *   tex32  4 floats per texel of texels32 (bitmaps stored as floats, environment maps)
 *   verts  3 floats per vertex of the packed vertex arrays (scene_vnormals' order): its world position
 *          (-DGRAD_GEOMETRY, gradients/geometry.h)
 *   lightpos 6 floats per emitter: a point or spot light's position, a spot light's axis (-DGRAD_GEOMETRY)
 *   camera 12 floats: the camera's origin and its basis F, R, U (-DGRAD_CAMERA, gradients/geometry.h)
 *   vnormals 3 floats per vertex (as verts): its vertex normal, before the interpolated normal is normalised
 *          (-DGRAD_GEOMETRY: triangles with vertex normals)
 *   inst   12 floats per instance record (instanced scenes, -DGRAD_INSTANCES): its object-to-world's 3x3 by
 *          columns, then its translation (gradients/geometry.h)
 * A textured reflectance is scale * texel values * the material's constant (1 unless changed): its
 * gradient goes to the texels (bilinear weights, texture.h tex_taps) and to the constant.
 *
 * -D specialisations say what is differentiated (the rest costs nothing): GRAD_COLOR (diffuse
 * reflectance of diffuse and plastic materials), GRAD_SPEC (specular reflectance of conductors and
 * plastics), GRAD_ALPHA (roughness of rough conductors, plastics and dielectrics), GRAD_EMISSION (area
 * lights' radiance), GRAD_ENV (the environment's radiance or texels), GRAD_GEOMETRY (where meshes' vertices
 * and point lights are: the interior term of gradients/geometry.h), GRAD_CAMERA (where the camera is; implies
 * GRAD_GEOMETRY), GRAD_INSTANCES (where instances are: an instance's to_world; implies GRAD_GEOMETRY).
 * alpha_up, alpha_down: the material records packed again with alpha (1 +- BSDF_DIFF_STEP)
 * (pyclpt/gradients/replay.py), for the roughness derivative (bsdf_derivative.h).
 *
 * Reverse mode scatters with float atomic adds (a compare-and-swap loop on the word's bits: OpenCL 1.2
 * has no float atomics), so the last bits of a gradient depend on the order work-items finish; the
 * path contributions themselves are a pure function of the seed. */
#ifndef PYCLPT_GRADIENT_PARAMS_H
#define PYCLPT_GRADIENT_PARAMS_H

#include "integrators/path.h"

#if (defined(GRAD_CAMERA) || defined(GRAD_INSTANCES)) && !defined(GRAD_GEOMETRY)
#define GRAD_GEOMETRY 1
#endif

#define GRAD_PARAMS                                                                                         \
    __global float *grad_mats, __global float *grad_lights, __global float *grad_tex8, __global float *grad_tex32, \
        __global float *grad_verts, __global float *grad_lightpos, __global float *grad_camera,                 \
        __global float *grad_vnormals, __global float *grad_inst, __global const float *alpha_up,            \
        __global const float *alpha_down, int grad_moving_lo, int grad_moving_hi
#define GRAD_INIT                                                                                             \
    {grad_mats,     grad_lights, grad_tex8, grad_tex32, grad_verts, grad_lightpos, grad_camera, grad_vnormals,     \
     grad_inst,     alpha_up,    alpha_down, grad_moving_lo, grad_moving_hi, {0}, {{0.0f}}, 0}

/* Adjoints a path adds to the same slots (its materials' colours, the light triangles it samples) are
 * summed in private memory first, in up to GRAD_CACHE slots, and added to the buffers once, when the
 * path ends (grad_flush): a few atomics per path instead of a few per vertex. */
#ifndef GRAD_CACHE
#define GRAD_CACHE 8
#endif

/* The gradient (or tangent) buffers, the material records repacked with every roughness moved up and
 * down by BSDF_DIFF_STEP (alpha (1 +- step): a rough plastic's coating tables depend on it;
 * bsdf_derivative.h), and (reverse mode) the path's pending adjoints. */
typedef struct {
    __global float* mats;
    __global float* lights;
    __global float* tex8;
    __global float* tex32;
    __global float* verts;
    __global float* lightpos;
    __global float* camera;
    __global float* vnormals;
    __global float* inst;
    __global const float* alpha_up;
    __global const float* alpha_down;
    /* reverse mode: the packed vertices [moving_lo, moving_hi) whose adjoints the host reads (the moving meshes';
       geometry.h, geo_scatter: a triangle outside scatters nothing); forward mode: unused */
    int moving_lo, moving_hi;
    __global float* pending_at[GRAD_CACHE]; /* three floats each */
    vec3 pending[GRAD_CACHE];
    int n_pending;
} Grads;

/* Which parameters each material kind has. */
static inline bool mat_has_color(int t) { return t == MAT_DIFFUSE || t == MAT_PLASTIC || t == MAT_ROUGHPLASTIC; }
static inline bool mat_has_spec(int t) {
    return t == MAT_CONDUCTOR || t == MAT_ROUGHCONDUCTOR || t == MAT_PLASTIC || t == MAT_ROUGHPLASTIC;
}
static inline bool mat_has_alpha(int t) {
    return t == MAT_ROUGHCONDUCTOR || t == MAT_ROUGHPLASTIC || t == MAT_ROUGHDIELECTRIC;
}

/* *p += v, atomically (compare-and-swap on the bits); nothing for 0 or a non-finite v (a NaN or inf
 * contribution is dropped: the kernels count the paths that had one). */
static inline void grad_add(__global float* p, float v) {
    if (v == 0.0f || !m_isfinite(v)) return;

    volatile __global uint* q = (volatile __global uint*)p;
    /* the first read atomic too (atomic_or with 0 changes nothing): a plain read racing another work
       item's atomic_cmpxchg is a data race (Oclgrind reports it), though the loop retries on a stale value */
    uint old = atomic_or(q, 0u), seen;
    do {
        seen = old;
        old = atomic_cmpxchg(q, seen, as_uint(as_float(seen) + v));
    } while (old != seen);
}

static inline void grad_add3(__global float* p, vec3 v) {
    grad_add(p, v.x);
    grad_add(p + 1, v.y);
    grad_add(p + 2, v.z);
}

/* Reverse mode: v added to the three floats at p, through the path's pending sums. */
static inline void grad_put3(Grads* gr, __global float* p, vec3 v) {
    if (v3_is_zero(v)) return;
    for (int k = 0; k < gr->n_pending; k++) {
        if (gr->pending_at[k] == p) {
            gr->pending[k] = v3_add(gr->pending[k], v);
            return;
        }
    }
    if (gr->n_pending < GRAD_CACHE) {
        gr->pending_at[gr->n_pending] = p;
        gr->pending[gr->n_pending] = v;
        gr->n_pending++;
        return;
    }
    grad_add3(p, v);
}

/* The path's pending sums to the buffers (at its end). */
static inline void grad_flush(Grads* gr) {
    for (int k = 0; k < gr->n_pending; k++) grad_add3(gr->pending_at[k], gr->pending[k]);
    gr->n_pending = 0;
}

static inline vec3 tangent3(__global const float* p) { return v3(p[0], p[1], p[2]); }

/* rgb of 4-float texel records at taps, weighted */
static inline vec3 taps_gather(const TexTaps* k, __global const float* tex8, __global const float* tex32) {
    __global const float* src = k->is_float ? tex32 : tex8;
    vec3 out = v3_splat(0.0f);
    for (int i = 0; i < k->n; i++)
        if (k->at[i] >= 0) out = v3_add(out, v3_scale(tangent3(src + 4 * k->at[i]), k->w[i]));
    return out;
}

static inline void taps_scatter(Grads* gr, const TexTaps* k, vec3 g) {
    __global float* dst = k->is_float ? gr->tex32 : gr->tex8;
    for (int i = 0; i < k->n; i++)
        if (k->at[i] >= 0) grad_put3(gr, dst + 4 * k->at[i], v3_scale(g, k->w[i]));
}

/* The texture of a material's colour slot (MAT_COLOR_TEX, MAT_SPEC_TEX), -1 for none. */
static inline int color_texture(Material m, int tex_slot) {
#ifdef SCENE_HAS_TEXTURES
    return (int)m[tex_slot];
#else
    return -1;
#endif
}

/* Reverse mode: the adjoint g of a material's colour (slot MAT_COLOR or MAT_SPEC) at uv, to its
 * constant or to its texels and constant. */
static inline void grad_color(const Scene* sc, Grads* gr, int mat, int slot, int tex_slot, vec2 uv, vec3 g) {
    Material m = scene_material(sc, mat);
    int t = color_texture(m, tex_slot);
    if (t < 0) {
        grad_put3(gr, gr->mats + MAT_STRIDE * mat + slot, g);
        return;
    }
    /* value = constant * scale * sum_k w_k texel_k */
    vec3 tex = tex_eval(&sc->tex, t, uv);
    grad_put3(gr, gr->mats + MAT_STRIDE * mat + slot, v3_mul(g, tex));
    vec3 k = v3_mul(rgb_at(m + slot, 1), rgb_at(sc->tex.info + TEX_STRIDE * t + TEX_SCALE, 1));
    TexTaps taps = tex_taps(&sc->tex, t, uv);
    taps_scatter(gr, &taps, v3_mul(g, k));
}

/* Forward mode: the tangent of a material's colour at uv. */
static inline vec3 tangent_color(const Scene* sc, const Grads* tg, int mat, int slot, int tex_slot, vec2 uv) {
    Material m = scene_material(sc, mat);
    vec3 d = tangent3(tg->mats + MAT_STRIDE * mat + slot);
    int t = color_texture(m, tex_slot);
    if (t < 0) return d;
    vec3 tex = tex_eval(&sc->tex, t, uv);
    vec3 k = v3_mul(rgb_at(m + slot, 1), rgb_at(sc->tex.info + TEX_STRIDE * t + TEX_SCALE, 1));
    TexTaps taps = tex_taps(&sc->tex, t, uv);
    return v3_add(v3_mul(d, tex), v3_mul(k, taps_gather(&taps, tg->tex8, tg->tex32)));
}

/* The radiance of emitter `light` seen along world direction dir: reverse mode adds g (the adjoint of
 * that radiance) to its parameters; forward mode returns its tangent. Point, directional and spot
 * lights are not differentiated. */
static inline void grad_emitter(const Scene* sc, Grads* gr, int light, vec3 dir, vec3 g) {
    if (light < 0) return;
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    int type = (int)l[LIGHT_TYPE];
    if (type == LIGHT_POINT || type == LIGHT_DIRECTIONAL || type == LIGHT_SPOT) return;
    if (type == LIGHT_ENVMAP) {
#ifdef GRAD_ENV
        __global const float* e = sc->light_data + as_int(l[LIGHT_PRIM]);
        TexTaps taps = env_taps(sc, e, env_texel_coords(e, env_to_local(e, dir)));
        taps_scatter(gr, &taps, v3_scale(g, e[ENV_SCALE]));
#endif
        return;
    }
#ifndef GRAD_ENV
    if (type == LIGHT_CONSTANT) return;
#endif
#ifndef GRAD_EMISSION
    if (type == LIGHT_TRIANGLE) return;
#endif
    grad_put3(gr, gr->lights + LIGHT_STRIDE * light + LIGHT_RADIANCE, g);
}

static inline vec3 tangent_emitter(const Scene* sc, const Grads* tg, int light, vec3 dir) {
    if (light < 0) return v3_splat(0.0f);
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    int type = (int)l[LIGHT_TYPE];
    if (type == LIGHT_POINT || type == LIGHT_DIRECTIONAL || type == LIGHT_SPOT) return v3_splat(0.0f);
    if (type == LIGHT_ENVMAP) {
        __global const float* e = sc->light_data + as_int(l[LIGHT_PRIM]);
        TexTaps taps = env_taps(sc, e, env_texel_coords(e, env_to_local(e, dir)));
        return v3_scale(taps_gather(&taps, tg->tex8, tg->tex32), e[ENV_SCALE]);
    }
    return tangent3(tg->lights + LIGHT_STRIDE * light + LIGHT_RADIANCE);
}

/* The environment's emitter index (-1: none). */
static inline int env_light(const Scene* sc) { return (int)sc->consts[CONST_ENV_LIGHT]; }

#endif
