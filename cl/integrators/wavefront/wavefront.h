/* wavefront.h: what the seven wavefront stages share — the path state accessors
 * (generated from pyclpt/path_state.py for the SoA or AoS layout), the queues and
 * their per-bounce counters (queues.h), and the GPU class's shading steps.
 *
 * The stages read their queue's entries below its count; the order-preserving
 * compaction (compact.h) builds the next queues from the flags they write. The ray
 * queue is double-buffered across bounces: bounce b reads ray queue b % 2 and the
 * compaction after sample_bsdf fills (b + 1) % 2. */
#ifndef PYCLPT_WAVEFRONT_H
#define PYCLPT_WAVEFRONT_H

#include "integrators/path.h"
#include "integrators/wavefront/queues.h"
#include "path_state.h"

#ifdef DEVICE_CLASS_GPU
/* GPUs: the shading stages build a hit's surface in each of their steps (process_hit.cl, sample_bsdf.cl). The first
 * keeps the shading normal (the vertex normals interpolated, the bump map applied) in the path's ray origin, which
 * no stage reads between intersect and sample_bsdf's next ray (path_store_ray), and the others take it from there
 * (surface_hit_shaded): the same surface without the normal's lookups again. Not in scenes with anisotropic
 * materials, whose frame is more than its normal (uv_frame in scene/scene.h). */
#ifndef SCENE_HAS_ANISOTROPY
#define HIT_NORMAL_KEPT 1
#endif

/* The surface a path in the hit queue hit, built whole (surface_hit). */
static inline GPU_INLINE Surface path_hit_surface_whole(const Scene* sc, const PathStore* P, int slot) {
    return surface_hit(sc, path_get_hit_prim(P, slot), path_get_hit_u(P, slot), path_get_hit_v(P, slot),
                       path_get_dir(P, slot));
}

/* The surface a path in the hit queue hit (its kept normal's, where HIT_NORMAL_KEPT). */
static inline GPU_INLINE Surface path_hit_surface(const Scene* sc, const PathStore* P, int slot) {
#ifdef HIT_NORMAL_KEPT
    return surface_hit_shaded(sc, path_get_hit_prim(P, slot), path_get_hit_u(P, slot), path_get_hit_v(P, slot),
                              path_get_dir(P, slot), path_get_org(P, slot));
#else
    return path_hit_surface_whole(sc, P, slot);
#endif
}

/* The first step of process_hit: the hit's shading normal kept for path_hit_surface. */
static inline GPU_INLINE void path_keep_hit_normal(const Scene* sc, const PathStore* P, int slot) {
#ifdef HIT_NORMAL_KEPT
    path_set_org(P, slot, path_hit_surface_whole(sc, P, slot).sh.n);
#endif
}

/* A stage's step boundary on GPUs: the work-item's flag cleared (a uchar store, which may alias every buffer, so
 * that the compiler reads what the next step needs afresh instead of holding it in registers across the step) and
 * its queue entry read again. The stage stores the flag's value at its end. */
static inline int queue_reread(__global uchar* flags, __global const int* queue, int i) {
    flags[i] = 0;
    return queue[i];
}

/* The textures of the material a path in the queue hit (bsdf_textures), looked up in a step of their own; *slot is
 * its queue entry, read again after the step. Without textures (-DSCENE_HAS_TEXTURES unset) nothing. */
static inline GPU_INLINE BsdfTextures path_hit_textures(const Scene* sc, const PathStore* P, __global uchar* flags,
                                                        __global const int* queue, int i, int* slot) {
    BsdfTextures f;
#ifdef SCENE_HAS_TEXTURES
    Surface s = path_hit_surface(sc, P, *slot);
    f = bsdf_textures(sc, &s);
    *slot = queue_reread(flags, queue, i);
#else
    f.color = f.spec = v3_splat(1.0f);
#endif
    return f;
}
#endif

/* The random-number key of the path in a slot: (seed, pixel, sample), from its film slot. */
static inline RngKey path_key(const PathStore* P, const Scene* sc, int slot, uint seed, uint first_sample) {
    int f = path_get_film_slot(P, slot);
    return rng_key(seed, (uint)film_pixel(sc, f), film_sample(sc, first_sample, f));
}

/* What shading needs of a path: the incoming ray, throughput, radiance and the
 * previous BSDF sample (miss and process_hit). */
static inline PathState path_load_shading(const PathStore* P, int slot, int bounce) {
    PathState ps;
    ps.dir = path_get_dir(P, slot);
    ps.beta = path_get_beta(P, slot);
    ps.L = path_get_L(P, slot);
    ps.flags = path_get_flags(P, slot);
    ps.prev_pdf = path_get_prev_pdf(P, slot);
    ps.depth = bounce;
    return ps;
}

/* Everything path_continue needs to run a queued path on from its current ray (finish_paths). */
static inline PathState path_load_ray(const PathStore* P, int slot, int bounce) {
    PathState ps = path_load_shading(P, slot, bounce);
    ps.org = path_get_org(P, slot);
    ps.rr_scale = path_get_rr_scale(P, slot);
    return ps;
}

/* The closest hit of a path's ray (intersect), for process_hit and sample_bsdf. */
static inline void path_store_hit(const PathStore* P, int slot, const Hit* hit) {
    path_set_hit_t(P, slot, hit->t);
    path_set_hit_u(P, slot, hit->u);
    path_set_hit_v(P, slot, hit->v);
    path_set_hit_prim(P, slot, hit->prim);
}

/* A path's shadow ray (process_hit), for shadow_test and light_contribution. */
static inline void path_store_shadow(const PathStore* P, int slot, const ShadowRay* sr) {
    path_set_shadow_org(P, slot, sr->org);
    path_set_shadow_dir(P, slot, sr->dir);
    path_set_shadow_tmax(P, slot, sr->tmax);
    path_set_shadow_contrib(P, slot, sr->contrib);
}

/* Store the next ray of a path and what the next bounce needs to weight it
 * (path_init and sample_bsdf). */
static inline void path_store_ray(const PathStore* P, int slot, const PathState* ps) {
    path_set_org(P, slot, ps->org);
    path_set_dir(P, slot, ps->dir);
    path_set_beta(P, slot, ps->beta);
    path_set_rr_scale(P, slot, ps->rr_scale);
    path_set_prev_pdf(P, slot, ps->prev_pdf);
    path_set_flags(P, slot, ps->flags);
    path_set_depth(P, slot, ps->depth);
}

#endif
