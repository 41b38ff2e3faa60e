/* backward: reverse-mode gradients by path replay (Vicini, Speierer and Jakob 2021, Mitsuba's prb).
 *
 * Consumes: the film slots [offset, offset + count) of a batch of frames starting at sample
 *           first_sample (slot f: pixel f % pixels, sample first_sample + f / pixels; path.h), and
 *           image_grad, dLoss/dImage (3 floats per pixel), scaled by inv_spp (the image is the
 *           mean of spp samples).
 * Produces: the adjoints of the scene's parameters added to the gradient buffers (params.h: GRAD_PARAMS,
 *           float atomics); drop_marks[f] = 1 for a path whose radiance was NaN or inf (dropped, its
 *           gradient too; counted by the host). Nothing else: the closest hits of a path's first
 *           REPLAY_HITS bounces, cached by the primal pass for its replay, stay in private memory.
 *
 * One work-item per path; dL = image_grad[pixel] / spp (-DFILM_SPLAT, a splatting film: the filter-weighted
 * sum of image_grad over the pixels the sample reaches, splat_adjoint). The path's contributions and what they
 * differentiate into, with G the radiance the path gathered up to and including a vertex and L its
 * total:
 *   emission at a hit, C = beta Le w:   dLe += dL beta w
 *   next-event estimation, C:           dLe_light += dL beta f w / pdf,   dtheta += dL C (df/dtheta) / f
 *   BSDF sample at the vertex:          dtheta += dL (L - G) (df/dtheta) / f
 * since everything the path gathers after a vertex went through f there. The first two are known at
 * the vertex; the third needs L, known only when the path ends. So the primal pass (the estimator of
 * path.h, the same calls in the same order, so the same L) scatters the first two at once and keeps
 * the third's (df/dtheta)/f and G for its first DEFERRED_VERTICES vertices (private memory, a few
 * hundred bytes whatever the depth), scattered when L is known. A path longer than that is traced
 * again from its camera ray with the same random numbers (rng keys: seed, pixel, sample, bounce,
 * dimension): the replay, which scatters the third term of its later vertices (DEFERRED_VERTICES = 0:
 * every vertex, Mitsuba's prb as published). Shadow-ray visibility of the first 32 bounces is kept as
 * bits for the replay, and the closest hits of its first REPLAY_HITS bounces (t, u, v, prim) too, so that the
 * replay (with -DGRAD_GEOMETRY that of every path meeting a moving mesh) traverses the BVH only past them. A path's adjoints are summed
 * privately per slot and added to the buffers when it ends (params.h: grad_put3, grad_flush). Memory: nothing
 * per path, sample or bounce in device memory; per work-item, private memory grows by REPLAY_HITS x 16 bytes
 * (128 by default) where a replay can happen (-DGRAD_BSDF or -DGRAD_GEOMETRY), which a GPU keeps in slow local
 * memory: keep REPLAY_HITS small. */
#include "gradients/bsdf_derivative.h"
#ifdef GRAD_GEOMETRY
#include "gradients/geometry.h"
#endif
#ifdef FILM_SPLAT
#include "film/splat.h"

/* A splatting film's (film/splat.h; -DSPLAT_FILTER, the filter's extent in CONST_FILTER_RADIUS): the adjoint
 * of a sample of pixel `pixel` (film_pixel's index, in the image padded by the reach, CONST_FILM_PAD) at `pos`
 * in it, sum over the image's pixels p it reaches of image_grad[p] w_p,
 * image_grad scaled by the host by 1 / p's expected sum of weights per frame (pyclpt/gradients/replay.py),
 * so that times inv_spp it is dLoss/dL of the ratio sum w L / sum w with the sum of the weights at its mean. */
static inline vec3 splat_adjoint(const Scene* sc, __global const float* image_grad, int pixel, vec2 pos) {
    __global const float* c = sc->consts;
    int width = (int)c[CONST_WIDTH], height = (int)c[CONST_HEIGHT], reach = (int)c[CONST_FILM_PAD];
    float extent = c[CONST_FILTER_RADIUS];
    int qx = pixel % (width + 2 * reach) - reach, qy = pixel / (width + 2 * reach) - reach; /* film_pixel's */
    vec3 sum = v3_splat(0.0f);
    for (int dy = -reach; dy <= reach; ++dy) {
        int py = qy - dy;
        if (py < 0 || py >= height) continue;
        for (int dx = -reach; dx <= reach; ++dx) {
            int px = qx - dx;
            if (px < 0 || px >= width) continue;
            float w = splat_pair_weight(extent, dx, dy, pos);
            sum = v3_add(sum, v3_scale(load3(image_grad, py * width + px), w));
        }
    }
    return sum;
}
#endif

#define VIS_BITS 32
/* Vertices whose BSDF-sample term the primal pass keeps for the end of the path (the later ones are
 * done by a replay of the path). */
#ifndef DEFERRED_VERTICES
#define DEFERRED_VERTICES 8
#endif
#define DEFERRED_SLOTS (DEFERRED_VERTICES > 0 ? DEFERRED_VERTICES : 1)

/* Bounces whose closest hit the primal pass keeps for the replay (REPLAY_HITS x 16 bytes of private memory,
 * local memory on a GPU, so few; 0: the replay traces every bounce again). The replay traces the same rays
 * (same random numbers, same arithmetic) and scene_closest is a pure function of them: its traversal is
 * deterministic, an alpha mask's random number is keyed by (seed, pixel, sample, bounce, query, triangle)
 * (scene/mask.h, with the instance's record in instanced scenes) and consumes no state, an instanced hit's
 * transform is found again from its packed prim (instances.h, surface_at), and nothing but t, u, v and prim is
 * written (-DPATH_TRACE's traversal counters, scene.h, are the megakernel's only). So a kept hit is the one the
 * replay would find, to the bit, a miss (prim -1) included. Compiled in only where a replay can happen. */
#ifndef REPLAY_HITS
#define REPLAY_HITS 8
#endif
#if REPLAY_HITS > 0 && (defined(GRAD_BSDF) || defined(GRAD_GEOMETRY))
#define REPLAY_CACHE
#define REPLAY_SLOTS REPLAY_HITS
#else
#define REPLAY_SLOTS 1
#endif

/* The closest hit of the path's ray at its bounce ps->depth: the primal pass (replay false) traces it and keeps it
 * in hits[depth] for a bounce before REPLAY_HITS, the replay takes the kept one there (and traces the later ones). */
static inline bool walk_closest(const Scene* sc, RngKey key, const PathState* ps, bool replay, Hit* hits, Hit* hit) {
#ifdef REPLAY_CACHE
    if (ps->depth < REPLAY_HITS) {
        if (replay) {
            *hit = hits[ps->depth];
            return hit->prim >= 0;
        }
        bool found = scene_closest(sc, key, ps->depth, ps->org, ps->dir, hit);
        hits[ps->depth] = *hit;
        return found;
    }
#endif
    return scene_closest(sc, key, ps->depth, ps->org, ps->dir, hit);
}

/* A vertex's BSDF-sample term, waiting for the path's radiance. */
typedef struct {
    BsdfRatios r;
    vec3 gathered; /* G: the radiance gathered up to and including the vertex */
    vec2 uv;
    int material;
} Deferred;

#ifdef GRAD_GEOMETRY
/* The path ended at vertex gc: the last three vertices' adjoints to the buffers (one on a moving mirror's ray
 * first, its ray's to the mirror before it). */
static inline void geo_end(const Scene* sc, Grads* gr, GeoVertex* ga, GeoVertex* gb, GeoVertex* gc) {
    geo_flush_ray(sc, gr, gb, gc);
    geo_flush_ray(sc, gr, ga, gb);
    geo_scatter(sc, gr, ga);
    geo_scatter(sc, gr, gb);
    geo_scatter(sc, gr, gc);
}

/* The interior term of a visible light sample n at vertex gc (reached from gb, r_bc away): its BSDF factor's
 * directions and frame, and the light's end: an emissive triangle's point attached to it (its cosine, 1 / r^2,
 * area Jacobian), a point or spot light's position (and a spot's axis, through its falloff), a direction to the
 * environment or a directional light fixed. */
static inline void geo_nee(const Scene* sc, Grads* gr, RngKey key, int depth, const Surface* s, const Bsdf* b,
                           const NeeSample* n, vec3 dL, vec3 dir_in, GeoVertex* gb, GeoVertex* gc, float r_bc) {
    vec3 C = n->sr.contrib;
    float a = m_dot(dL, C);
    vec3 g_wi, g_wo;
    geo_bsdf_adjoint(sc, s, b, v3_neg(dir_in), n->ls.wi, n->f, C, dL, gc, &g_wi, &g_wo);
    if (gc->kind == GEO_ATTACHED && r_bc > 0.0f) geo_segment_adjoint(gc, gb, v3_neg(dir_in), r_bc, g_wi, 0.0f);
    else if (gc->camera || gc->mray) gc->gwi = v3_add(gc->gwi, g_wi); /* the camera's (a mirror's) ray turns */
    GeoVertex gy;
    if (!geo_light_end(sc, key, depth, n, gc, &gy)) return;
    float r = n->ls.dist;
    if (gy.kind == GEO_ATTACHED) geo_area_segment(gc, &gy, n->ls.wi, r, a, g_wo); /* its cosine, 1 / r^2, area */
    else { /* a point: 1 / r^2, and a spot's falloff F(c), c = -wi . axis */
        vec3 axis;
        float k = a * geo_spot_falloff(sc, n->ls.light, n->ls.wi, &axis);
        if (k != 0.0f) {
            g_wo = v3_sub(g_wo, v3_scale(axis, k));
            grad_put3(gr, gr->lightpos + GEO_LIGHT_STRIDE * n->ls.light + 3, v3_scale(n->ls.wi, -k));
        }
        geo_segment_adjoint(gc, &gy, n->ls.wi, r, g_wo, -2.0f * a / r);
    }
    geo_scatter(sc, gr, &gy);
}
#endif

/* One walk along the path (path_continue's loop). The primal pass (replay false) scatters the emission
 * and next-event terms, defers the BSDF-sample terms of vertices before DEFERRED_VERTICES (at most
 * that many, in deferred) and says in *more whether later vertices need a replay; it records
 * shadow-ray visibility in *visible and the closest hits of bounces before REPLAY_HITS in hits. The
 * replay (replay true, L_total known) takes those hits (walk_closest) and scatters the BSDF-sample
 * terms of the vertices from DEFERRED_VERTICES on. Returns the path's radiance.
 * Inlined at both calls (ALWAYS_INLINE, cl/core/common.h), each with its own constant `replay` (a call with a
 * run-time flag kept the replay's branches in the primal walk's loop and its arrays behind pointers: the walk alone
 * took 1.1x as long on Intel's runtime, the backward pass with the boundary terms 1.04x on Intel's and on PoCL;
 * docs/differentiable.md). */
static inline ALWAYS_INLINE vec3 backward_walk(const Scene* sc, Grads* gr, RngKey key, int pixel, int max_depth,
                                              vec3 dL, bool replay, vec3 L_total, uint* visible, Hit* hits,
                                              Deferred* deferred, int* n_deferred, bool* more, bool* touched) {
    PathState ps;
    camera_path(sc, key, pixel, &ps);
    if (max_depth == 0) return ps.L;
#ifdef GRAD_GEOMETRY
    /* the replay's interior term of moving geometry (geometry.h): ga and gb the two vertices before the ray's
       hit (gb made the ray; at first the camera), the ray's segment an area-form one (a non-delta BSDF sample,
       whose factors wait for its far end: seg_a, seg_gw) or one its hit slides along */
    GeoVertex ga = geo_fixed(ps.org), gb = ga, gc = ga;
    bool seg_area = false;
    float seg_a = 0.0f, r_bc = 0.0f;
    vec3 seg_gw = v3_splat(0.0f);
#endif
    for (;;) {
        Hit hit;
        if (!walk_closest(sc, key, &ps, replay, hits, &hit)) {
#ifdef GRAD_GEOMETRY
            if (replay) { /* a direction to the environment: nothing moves it */
                geo_flush_ray(sc, gr, &ga, &gb);
                geo_scatter(sc, gr, &ga);
                geo_scatter(sc, gr, &gb);
            }
#endif
#ifdef GRAD_ENV
            if (!replay) {
                bool mis = !(ps.flags & PATH_PREV_DELTA);
                float light_pdf;
                vec3 le = env_eval(sc, ps.dir, mis, &light_pdf);
                if (!v3_is_zero(le)) {
                    float w = mis ? power_heuristic(ps.prev_pdf, light_pdf) : 1.0f;
                    grad_emitter(sc, gr, env_light(sc), ps.dir, v3_scale(v3_mul(dL, ps.beta), w));
                }
            }
#endif
            path_miss(sc, &ps);
            return ps.L;
        }
        Surface s = surface_hit(sc, hit.prim, hit.u, hit.v, ps.dir);
#ifdef GRAD_GEOMETRY
        if (!replay && geo_moving_prim(sc, gr, hit.prim)) *touched = true;
        Bsdf b = bsdf_at(sc, &s); /* here already: a delta vertex is a moving mirror's or held still */
        if (replay) {
            int mirror;
            int kind = geo_hit_kind(&b, seg_area, &gb, &mirror);
            gc = geo_on_triangle(sc, hit.prim, hit.u, hit.v, s.p, kind, ps.dir);
            gc.mirror = mirror;
#ifdef GRAD_CAMERA
            if (ps.depth == 0) geo_camera_hit(sc, &gc, camera_film_position(sc, key, pixel), gb.p);
#endif
            geo_mirror_ray(&gc, &gb); /* on the ray a moving mirror reflected */
            r_bc = m_length(v3_sub(gc.p, gb.p));
            if (seg_area && r_bc > 0.0f) geo_area_segment(&gb, &gc, ps.dir, r_bc, seg_a, seg_gw);
        }
#endif
#ifdef GRAD_EMISSION
        if (!replay && !v3_is_zero(light_emitted(sc, s.light, s.ng, ps.dir, s.uv))) {
            float w = 1.0f; /* path_hit_emission's MIS weight */
            if (!(ps.flags & PATH_PREV_DELTA))
                w = power_heuristic(ps.prev_pdf, light_pdf_area(sc, s.light, hit.t, -m_dot(s.ng, ps.dir)));
            grad_emitter(sc, gr, s.light, ps.dir, v3_scale(v3_mul(dL, ps.beta), w));
        }
#endif
        path_hit_emission(sc, &s, hit.t, &ps);
        if (!depth_allows(ps.depth + 1, max_depth)) {
#ifdef GRAD_GEOMETRY
            if (replay) geo_end(sc, gr, &ga, &gb, &gc);
#endif
            return ps.L;
        }
#ifndef GRAD_GEOMETRY
        Bsdf b = bsdf_at(sc, &s);
#endif
        vec3 wi = to_local(s.sh, v3_neg(ps.dir));
        NeeSample n;
        if (path_nee(sc, key, &s, &b, &ps, &n)) {
            bool vis = (replay && ps.depth < VIS_BITS)
                           ? ((*visible >> ps.depth) & 1u) != 0
                           : !scene_occluded(sc, key, ps.depth, n.sr.org, n.sr.dir, n.sr.tmax);
            if (vis) {
#ifdef GRAD_GEOMETRY
                if (replay) geo_nee(sc, gr, key, ps.depth, &s, &b, &n, dL, ps.dir, &gb, &gc, r_bc);
#endif
                ps.L = v3_add(ps.L, n.sr.contrib);
                if (!replay) {
                    if (ps.depth < VIS_BITS) *visible |= 1u << ps.depth;
#ifdef GRAD_GEOMETRY
                    __global const float* lr = sc->lights + LIGHT_STRIDE * n.ls.light; /* a moving emitter's point */
                    if ((int)lr[LIGHT_TYPE] == LIGHT_TRIANGLE && geo_moving_prim(sc, gr, as_int(lr[LIGHT_PRIM])))
                        *touched = true;
#endif
                    grad_emitter(sc, gr, n.ls.light, n.ls.wi, v3_scale(v3_mul(v3_mul(dL, ps.beta), n.f), n.weight));
#ifdef GRAD_BSDF
                    if (bsdf_differentiated(&b)) {
                        BsdfRatios r = bsdf_ratios(gr, &s, &b, wi, n.wo, false);
                        BsdfAdjoint g = bsdf_adjoint(&r, v3_mul(dL, n.sr.contrib));
                        grad_bsdf(sc, gr, s.material, s.uv, &g);
                    }
#endif
                }
            }
        }
        int depth = ps.depth;
        vec3 gathered = ps.L;
#ifdef GRAD_GEOMETRY
        vec3 dir_in = ps.dir;
#endif
        if (!path_sample_bsdf(key, &s, &b, &ps, max_depth)) {
#ifdef GRAD_GEOMETRY
            if (replay) geo_end(sc, gr, &ga, &gb, &gc);
#endif
            return ps.L;
        }
#ifdef GRAD_GEOMETRY
        if (replay) {
            seg_area = !(ps.flags & PATH_PREV_DELTA);
            seg_a = 0.0f;
            seg_gw = v3_splat(0.0f);
            if (seg_area) { /* everything gathered after this vertex flows through its BSDF and the new segment */
                vec3 through = v3_sub(L_total, gathered);
                float pdf;
                vec3 f = bsdf_eval(&b, wi, to_local(s.sh, ps.dir), &pdf);
                vec3 g_wi;
                geo_bsdf_adjoint(sc, &s, &b, v3_neg(dir_in), ps.dir, f, through, dL, &gc, &g_wi, &seg_gw);
                if (gc.kind == GEO_ATTACHED && r_bc > 0.0f) geo_segment_adjoint(&gc, &gb, v3_neg(dir_in), r_bc, g_wi, 0.0f);
                else if (gc.camera || gc.mray) gc.gwi = v3_add(gc.gwi, g_wi);
                seg_a = m_dot(dL, through);
            }
            if (gc.mirror) geo_fresnel_adjoint(sc, &b, dL, v3_sub(L_total, gathered), &gc); /* its Fresnel factor */
            geo_flush_ray(sc, gr, &ga, &gb); /* complete: its ray's adjoints to the mirror ga before ga's scatter */
            geo_scatter(sc, gr, &ga); /* no later factor needs it */
            ga = gb;
            gb = gc;
        }
#endif
#ifdef GRAD_BSDF
        /* everything the rest of the path gathers went through f at this vertex */
        if (bsdf_differentiated(&b)) {
            bool delta = (ps.flags & PATH_PREV_DELTA) != 0;
            vec3 wo = to_local(s.sh, ps.dir);
            if (!replay && depth < DEFERRED_VERTICES) {
                Deferred* d = &deferred[(*n_deferred)++];
                d->r = bsdf_ratios(gr, &s, &b, wi, wo, delta);
                d->gathered = gathered;
                d->uv = s.uv;
                d->material = s.material;
            } else if (!replay) {
                *more = true;
            } else if (depth >= DEFERRED_VERTICES) {
                BsdfRatios r = bsdf_ratios(gr, &s, &b, wi, wo, delta);
                BsdfAdjoint g = bsdf_adjoint(&r, v3_mul(dL, v3_sub(L_total, gathered)));
                grad_bsdf(sc, gr, s.material, s.uv, &g);
            }
        }
#endif
    }
}

__kernel SCALAR_KERNEL void backward(SCENE_PARAMS, __global const float* image_grad, __global uchar* drop_marks,
                                     uint seed, uint first_sample, int offset, int count, int max_depth,
                                     float inv_spp, GRAD_PARAMS) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    Grads gr = GRAD_INIT;
    int f = offset + i;
    int pixel = film_pixel(&sc, f);
    RngKey key = rng_key(seed, (uint)pixel, film_sample(&sc, first_sample, f));
#ifdef FILM_SPLAT
    vec3 dL = v3_scale(splat_adjoint(&sc, image_grad, pixel, splat_position(seed, (uint)pixel, key.sample)), inv_spp);
#else
    vec3 dL = v3_scale(load3(image_grad, f % film_pixels(&sc)), inv_spp); /* the film's pixel */
#endif
    if (v3_is_zero(dL)) return;
    uint visible = 0;
    Hit hits[REPLAY_SLOTS];
    Deferred deferred[DEFERRED_SLOTS];
    int n_deferred = 0;
    bool more = false, touched = false;
    vec3 L = backward_walk(&sc, &gr, key, pixel, max_depth, dL, false, v3_splat(0.0f), &visible, hits, deferred,
                           &n_deferred, &more, &touched);
    if (!all_finite3(L)) { /* dropped, with its gradient */
        drop_marks[f] = (uchar)1;
        return;
    }
#ifdef GRAD_BSDF
    for (int k = 0; k < n_deferred; k++) {
        BsdfAdjoint g = bsdf_adjoint(&deferred[k].r, v3_mul(dL, v3_sub(L, deferred[k].gathered)));
        grad_bsdf(&sc, &gr, deferred[k].material, deferred[k].uv, &g);
    }
#endif
#ifdef GRAD_GEOMETRY
    /* the interior term of moving geometry is the replay's (it needs the path's radiance), for a path with a
       vertex or a light sample on a moving mesh (geo_moving_prim): on none, no factor of it moves */
    more = more || touched;
#endif
#if defined(GRAD_BSDF) || defined(GRAD_GEOMETRY)
    if (more)
        backward_walk(&sc, &gr, key, pixel, max_depth, dL, true, L, &visible, hits, deferred, &n_deferred, &more,
                      &touched);
#endif
    grad_flush(&gr);
}
