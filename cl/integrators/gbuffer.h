/* gbuffer.h: what the integrators record for the G-buffer (film/aovs.h) beside the radiance, when
 * the program is built with -DAOVS: at the first hit its normal, view depth, roughness, ids and
 * motion vector and emitted radiance; at the second ray's hit its distance; at the first non-delta vertex its albedo
 * times the throughput of the specular chain before it. The megakernel (path_continue) and the
 * wavefront's stages (process_hit, miss) call the same functions with the same values, so both give
 * the same G-buffer. Without -DAOVS nothing here is called and the kernels are unchanged.
 *
 * Each path writes only its own film slot's record (AovOut.f), plain stores, no atomics; the
 * film clears the records before every batch (0, ids -1: pyclpt/film/aovs.py). */
#ifndef PYCLPT_GBUFFER_H
#define PYCLPT_GBUFFER_H

#include "film/aovs.h"
#include "scene/bsdf.h"
#include "scene/lights.h"
#include "scene/scene.h"

/* A path flag (beside path.h's PATH_PREV_DELTA): the path's albedo is recorded. */
#define PATH_ALBEDO_DONE 2

/* The G-buffer records of a batch and the slot of the path at hand. */
typedef struct {
    __global float* p; /* planar: channel c of slot f at p[c * n + f] */
    int n;             /* slots of the batch */
    int f;             /* this path's film slot */
} AovOut;

static inline AovOut aov_out(__global float* p, int n, int f) {
    AovOut o;
    o.p = p;
    o.n = n;
    o.f = f;
    return o;
}

static inline void aov_put(AovOut o, int c, float v) { o.p[c * o.n + o.f] = v; }

static inline void aov_put3(AovOut o, int c, vec3 v) {
    aov_put(o, c, v.x);
    aov_put(o, c + 1, v.y);
    aov_put(o, c + 2, v.z);
}

/* Where the camera whose constants start at consts[base] (CONST_CAM_ORIGIN or CONST_PREV_CAM_ORIGIN)
 * sees the offset d from its origin (a point minus the origin, or a direction: a point at infinity),
 * in pixels, x right, y down: camera_path's mapping inverted. False behind the camera. */
static inline bool camera_screen(const Scene* sc, int base, vec3 d, vec2* px) {
    __global const float* c = sc->consts + base;
    vec3 forward = rgb_at(c + 3, sc->unit), right = rgb_at(c + 6, sc->unit), up = rgb_at(c + 9, sc->unit);
    float z = m_dot(d, forward);
#if SCENE_CAMERA == CAMERA_ORTHOGRAPHIC
    float sx = m_dot(d, right) / m_dot(right, right); /* parallel projection */
    float sy = m_dot(d, up) / m_dot(up, up);
#else
    float sx = m_dot(d, right) / (m_dot(right, right) * z);
    float sy = m_dot(d, up) / (m_dot(up, up) * z);
#endif
    px->x = (sx + 1.0f) * 0.5f * sc->consts[CONST_WIDTH];
    px->y = (1.0f - sy) * 0.5f * sc->consts[CONST_HEIGHT];
    return z > 0.0f;
}

/* The motion vector of a point p (at_infinity: of the direction p): where the previous frame's camera saw
 * it minus where this frame's camera sees it, in pixels; AOV_OFFSCREEN behind the previous camera. */
static inline vec2 gbuffer_motion(const Scene* sc, vec3 p, bool at_infinity) {
    __global const float* c = sc->consts;
    vec3 d_prev = at_infinity ? p : v3_sub(p, rgb_at(c + CONST_PREV_CAM_ORIGIN, sc->unit));
    vec3 d_cur = at_infinity ? p : v3_sub(p, rgb_at(c + CONST_CAM_ORIGIN, sc->unit));
    vec2 prev, cur;
#if SCENE_CAMERA == CAMERA_ORTHOGRAPHIC
    if (at_infinity) return v2(0.0f, 0.0f); /* every pixel of a parallel projection sees the same direction */
#endif
    bool seen = camera_screen(sc, CONST_PREV_CAM_ORIGIN, d_prev, &prev);
    camera_screen(sc, CONST_CAM_ORIGIN, d_cur, &cur);
    return seen ? v2(prev.x - cur.x, prev.y - cur.y) : v2(AOV_OFFSCREEN, AOV_OFFSCREEN);
}

/* What every hit of a path records (gbuffer_hit): the second ray's hit distance, and the albedo at the first
 * non-delta vertex (times the throughput beta; PATH_ALBEDO_DONE is then set in *flags). */
static inline void gbuffer_albedo(AovOut o, const Bsdf* b, vec3 beta, int* flags) {
    if (bsdf_is_delta(b)) return;
    aov_put3(o, AOV_ALBEDO, v3_mul(beta, bsdf_albedo(b)));
    *flags |= PATH_ALBEDO_DONE;
}

static inline GPU_INLINE void gbuffer_hit_path(const Scene* sc, AovOut o, const Surface* s, float t, int depth,
                                               vec3 beta, int* flags) {
    if (depth == 1) aov_put(o, AOV_HITDIST, t);
    if (*flags & PATH_ALBEDO_DONE) return;
    Bsdf b = bsdf_at(sc, s);
    gbuffer_albedo(o, &b, beta, flags);
}

/* What the camera ray's hit records (gbuffer_hit): its normal, roughness (of the material's record: no texture
 * changes it), view depth, motion vector, emitted radiance and ids. */
static inline GPU_INLINE void gbuffer_hit_first(const Scene* sc, AovOut o, int prim, const Surface* s, vec3 dir) {
    __global const float* c = sc->consts;
    aov_put3(o, AOV_NORMAL, s->sh.n);
    Bsdf b = bsdf_from(scene_material(sc, s->material), sc->unit);
    aov_put(o, AOV_ROUGHNESS, bsdf_roughness(&b));
    aov_put(o, AOV_DEPTH, m_dot(v3_sub(s->p, rgb_at(c + CONST_CAM_ORIGIN, sc->unit)),
                                 rgb_at(c + CONST_CAM_FORWARD, sc->unit)));
    vec2 mv = gbuffer_motion(sc, s->p, false);
    aov_put(o, AOV_MOTION, mv.x);
    aov_put(o, AOV_MOTION + 1, mv.y);
    aov_put3(o, AOV_EMISSION, light_emitted(sc, s->light, s->ng, dir, s->uv)); /* path_hit_emission's, w = 1 */
    aov_put(o, AOV_PRIM, as_float(prim));
    aov_put(o, AOV_MATERIAL, as_float(s->material));
}

/* A path's ray of bounce `depth` along dir hit triangle `prim` at distance t, surface s; beta is the
 * path's throughput and *flags its PATH_* flags (PATH_ALBEDO_DONE is set once the albedo is recorded). */
static inline void gbuffer_hit(const Scene* sc, AovOut o, int prim, const Surface* s, float t, int depth,
                               vec3 dir, vec3 beta, int* flags) {
    gbuffer_hit_path(sc, o, s, t, depth, beta, flags);
    if (depth == 0) gbuffer_hit_first(sc, o, prim, s, dir);
}

/* A path's ray of bounce `depth` along dir left the scene: the camera ray's motion vector (a point at
 * infinity) and the environment it sees (path_miss's, without MIS); every other channel keeps its
 * cleared value. */
static inline void gbuffer_miss(const Scene* sc, AovOut o, int depth, vec3 dir) {
    if (depth != 0) return;
    vec2 mv = gbuffer_motion(sc, dir, true);
    aov_put(o, AOV_MOTION, mv.x);
    aov_put(o, AOV_MOTION + 1, mv.y);
    float pdf;
    aov_put3(o, AOV_EMISSION, env_eval(sc, dir, false, &pdf));
}

#endif
