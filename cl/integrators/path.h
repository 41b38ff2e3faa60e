/* path.h: the path-tracing estimator as small stage functions.
 *
 * The megakernel calls them in a loop; the wavefront integrator calls each from
 * its own kernel. Both run the same arithmetic on the same random numbers in the
 * same order, so they produce the same image for the same seed.
 *
 * Depth follows Mitsuba: max_depth = 1 renders emitters seen directly, 2 adds
 * direct lighting, -1 is unlimited (paths end by Russian roulette). A path's
 * `depth` is the bounce index of its current ray (0 for the camera ray). */
#ifndef PYCLPT_PATH_H
#define PYCLPT_PATH_H

#include "core/common.h"
#include "core/rng.h"
#include "core/sampling.h"
#include "scene/bsdf.h"
#include "scene/scene.h"
#include "scene/lights.h"
#include "scene/bvh.h"
#include "film/rfilter.h"
#include "integrators/gbuffer.h"

/* Russian roulette starts on rays of this bounce index. */
#ifndef RR_DEPTH
#define RR_DEPTH 3
#endif
/* ... and keeps a path with probability min(RR_FACTOR * its throughput relative to the first bounce's * eta^2,
 * 0.95) (path_sample_bsdf; docs/architecture.md, "Russian roulette": 2 was the most efficient of 1 to 4). */
#ifndef RR_FACTOR
#define RR_FACTOR 2.0f
#endif

#define PATH_PREV_DELTA 1
/* The flags a BSDF sample keeps: the G-buffer's (gbuffer.h), and only when it is recorded. */
#ifdef AOVS
#define PATH_KEPT_FLAGS(flags) ((flags) & PATH_ALBEDO_DONE)
#else
#define PATH_KEPT_FLAGS(flags) 0
#endif

typedef struct {
    vec3 org, dir;    /* current ray; dir is unit length */
    vec3 beta;        /* throughput */
    vec3 L;           /* radiance gathered so far */
    float prev_pdf;   /* solid-angle pdf of the BSDF sample that made the ray */
    float rr_scale;   /* the roulette's scale of the throughput (path_sample_bsdf): the squared product of
                       * the relative IORs crossed, over the first bounce's throughput when that is below 1 */
    int depth;        /* bounce index of the current ray */
    int flags;        /* PATH_* */
} PathState;

typedef struct {
    vec3 org, dir;
    float tmax;
    vec3 contrib;     /* radiance added if the ray is unoccluded */
} ShadowRay;

static inline bool depth_allows(int depth, int max_depth) { return max_depth < 0 || depth < max_depth; }

/* A launch renders a batch of frames: samples first_sample, first_sample + 1, ... of every pixel of the
 * film. The path of film slot f = j * pixels + p is sample first_sample + j of the film's pixel p, and
 * commits to frame j of the film's frame buffer (frames stacked: film_commit writes frame[3 f],
 * drop_marks[f]). film_pixel is that pixel's index in the image, which keys its random numbers and
 * places its camera ray: p itself, or with -DFILM_CROP p's place in the crop window, so a cropped film's
 * pixels are exactly the image's. A splatting film's window reaches CONST_FILM_PAD pixels beyond the
 * image (its margin): its index is then in the image padded by that much on each side (camera_path). */
static inline int film_pixel(const Scene* sc, int f) {
    int p = f % film_pixels(sc);
#ifdef FILM_CROP
    __global const float* c = sc->consts;
    int w = (int)c[CONST_CROP_WIDTH], pad = (int)c[CONST_FILM_PAD];
    p = ((int)c[CONST_CROP_Y] + pad + p / w) * ((int)c[CONST_WIDTH] + 2 * pad) + (int)c[CONST_CROP_X] + pad + p % w;
#endif
    return p;
}
static inline uint film_sample(const Scene* sc, uint first_sample, int f) {
    return first_sample + (uint)(f / film_pixels(sc));
}

/* path init: the camera ray through the film position (x, y) (pixels from the image's top-left corner)
 * and, for a thin lens, a point on the aperture. */
static inline void camera_ray(const Scene* sc, RngKey key, float x, float y, PathState* ps) {
    __global const float* c = sc->consts;
    float sx = 2.0f * (x / c[CONST_WIDTH]) - 1.0f;
    float sy = 1.0f - 2.0f * (y / c[CONST_HEIGHT]);
    vec3 forward = rgb_at(c + CONST_CAM_FORWARD, sc->unit), right = rgb_at(c + CONST_CAM_RIGHT, sc->unit);
    vec3 up = rgb_at(c + CONST_CAM_UP, sc->unit);
    ps->org = rgb_at(c + CONST_CAM_ORIGIN, sc->unit);
    ps->dir = m_normalize(v3_add(v3_add(forward, v3_scale(right, sx)), v3_scale(up, sy)));
#if SCENE_CAMERA == CAMERA_ORTHOGRAPHIC
    /* Mitsuba's orthographic: from the image rectangle, along forward */
    ps->org = v3_add(ps->org, v3_add(v3_scale(right, sx), v3_scale(up, sy)));
    ps->dir = forward;
#elif SCENE_CAMERA == CAMERA_THINLENS
    {
        /* Mitsuba's thinlens: from a point of the aperture disk towards where the pinhole ray meets the
         * plane in focus */
        vec2 a = square_to_disk_concentric(rng_2d(key, 0, DIM_LENS_U));
        float r = c[CONST_LENS_RADIUS];
        vec3 lens = v3_add(ps->org, v3_add(v3_scale(m_normalize(right), r * a.x), v3_scale(m_normalize(up), r * a.y)));
        vec3 plane = v3_add(v3_add(forward, v3_scale(right, sx)), v3_scale(up, sy));
        vec3 focus = v3_add(ps->org, v3_scale(plane, c[CONST_FOCUS_DISTANCE]));
        ps->org = lens;
        ps->dir = m_normalize(v3_sub(focus, lens));
    }
#endif
    ps->beta = v3_splat(1.0f);
    ps->L = v3_splat(0.0f);
    ps->prev_pdf = 0.0f;
    ps->rr_scale = 1.0f;
    ps->depth = 0;
    ps->flags = PATH_PREV_DELTA; /* the camera ray counts as a delta sample: no MIS */
}

/* The camera ray of (pixel, sample) through a position drawn from the film's reconstruction filter around
 * the pixel's centre (camera_film_position: that position) (film/rfilter.h; the box and a splatting film: uniform in the pixel). `pixel`: the
 * index of film_pixel, in the image padded by CONST_FILM_PAD pixels on each side (0 but for a splatting
 * film: the image's index). */
static inline vec2 camera_film_position(const Scene* sc, RngKey key, int pixel) {
    __global const float* c = sc->consts;
    int pad = (int)c[CONST_FILM_PAD];
    int width = (int)c[CONST_WIDTH] + 2 * pad;
    vec2 j = rng_2d(key, 0, DIM_CAMERA_X);
    return v2((float)(pixel % width - pad) + rfilter_position(c, j.x), (float)(pixel / width - pad) +
              rfilter_position(c, j.y));
}
static inline void camera_path(const Scene* sc, RngKey key, int pixel, PathState* ps) {
    vec2 x = camera_film_position(sc, key, pixel);
    camera_ray(sc, key, x.x, x.y, ps);
}

/* miss: the environment seen along the ray, MIS-weighted against light sampling. */
static inline void path_miss(const Scene* sc, PathState* ps) {
    bool mis = !(ps->flags & PATH_PREV_DELTA);
    float light_pdf;
    vec3 le = env_eval(sc, ps->dir, mis, &light_pdf);
    if (v3_is_zero(le)) return;
    float w = 1.0f;
    if (mis) w = power_heuristic(ps->prev_pdf, light_pdf);
    ps->L = v3_add(ps->L, v3_scale(v3_mul(ps->beta, le), w));
}

/* hit processing, part 1: emission at the hit, MIS-weighted against light sampling. */
static inline void path_hit_emission(const Scene* sc, const Surface* s, float t, PathState* ps) {
    vec3 le = light_emitted(sc, s->light, s->ng, ps->dir, s->uv);
    if (v3_is_zero(le)) return;
    float w = 1.0f;
    if (!(ps->flags & PATH_PREV_DELTA)) {
        float light_pdf = light_pdf_area(sc, s->light, t, -m_dot(s->ng, ps->dir));
        w = power_heuristic(ps->prev_pdf, light_pdf);
    }
    ps->L = v3_add(ps->L, v3_scale(v3_mul(ps->beta, le), w));
}

/* A light sample seen from a surface: the shadow ray and the factors of its contribution
 * contrib = beta * f * radiance * weight, kept apart for the gradient kernels (cl/gradients/). */
typedef struct {
    ShadowRay sr;
    LightSample ls;
    vec3 f;         /* bsdf_eval at the light's direction: value * |cos| */
    vec3 wo;        /* the light's direction in the shading frame */
    float weight;   /* MIS weight / pdf */
} NeeSample;

/* Next-event estimation, part 1: the light sample seen from the point p at the path's bounce (false: none). */
static inline GPU_INLINE bool path_nee_light(const Scene* sc, RngKey key, vec3 p, int depth, LightSample* ls,
                                             bool env_radiance) {
    float u_sel;
    vec2 u;
    rng_light(key, depth, &u_sel, &u);
    return light_sample(sc, p, u_sel, u, ls, env_radiance);
}

/* Next-event estimation, part 2: the light sample n->ls (path_nee_light) seen from the surface s along the path's
 * ray: the directions in the shading frame (n->wo, *wi) and the shadow ray's origin, direction and length. False
 * where the geometric normal and the shading frame disagree about the side, or the ray has no length. */
static inline GPU_INLINE bool path_nee_ray(const Surface* s, const PathState* ps, NeeSample* n, vec3* wi) {
    *wi = to_local(s->sh, v3_neg(ps->dir));
    n->wo = to_local(s->sh, n->ls.wi);
    /* the geometric normal must agree with the shading frame about the side */
    if (m_dot(n->ls.wi, s->ng) * n->wo.z <= 0.0f) return false;
    ShadowRay* sr = &n->sr;
    sr->org = spawn_origin(s, n->ls.wi);
    sr->dir = n->ls.wi;
    sr->tmax = m_isinf(n->ls.dist) ? INF_F : n->ls.dist * (1.0f - 1e-4f) - m_length(v3_sub(sr->org, s->p));
    return sr->tmax > 0.0f;
}

/* Next-event estimation, part 3: the BSDF b at the light sample (path_nee_ray's directions): n->f, and the pdf of
 * BSDF sampling the same direction. */
static inline GPU_INLINE float path_nee_eval(const Bsdf* b, vec3 wi, NeeSample* n) {
    float bsdf_pdf;
    n->f = bsdf_eval(b, wi, n->wo, &bsdf_pdf);
    return bsdf_pdf;
}

/* Next-event estimation, part 4: the light sample's MIS weight against BSDF sampling (bsdf_pdf: path_nee_eval's) and
 * the shadow ray's contribution. False for a sample that cannot contribute (a zero value). */
static inline GPU_INLINE bool path_nee_weigh(const PathState* ps, float bsdf_pdf, NeeSample* n) {
    /* a delta light (point) cannot be hit by BSDF sampling: its sample takes the whole weight */
    float w = n->ls.delta ? 1.0f : power_heuristic(n->ls.pdf, bsdf_pdf);
    n->weight = w / n->ls.pdf;
    n->sr.contrib = v3_scale(v3_mul(v3_mul(ps->beta, n->f), n->ls.radiance), n->weight);
    return max3(n->sr.contrib) > 0.0f;
}

/* hit processing, part 2: next-event estimation, with its factors (NeeSample): path_nee_light, path_nee_ray,
 * path_nee_eval, then path_nee_weigh (the steps of the GPU's process_hit). Writes a shadow ray only for a sample that
 * can contribute (pdf > 0, non-zero value). With env_radiance false an environment sample's radiance is left out of
 * ls.radiance and contrib (ENV_DEFERRED: path_lit adds it). */
static inline bool path_nee_sample(const Scene* sc, RngKey key, const Surface* s, const Bsdf* b, const PathState* ps,
                                   NeeSample* n, bool env_radiance) {
    if (bsdf_is_delta(b)) return false;
    vec3 wi;
    return path_nee_light(sc, key, s->p, ps->depth, &n->ls, env_radiance) && path_nee_ray(s, ps, n, &wi) &&
           path_nee_weigh(ps, path_nee_eval(b, wi, n), n);
}

/* path_nee_sample with every factor, the light's radiance included (the gradient kernels) */
static inline bool path_nee(const Scene* sc, RngKey key, const Surface* s, const Bsdf* b, const PathState* ps,
                            NeeSample* n) {
    return path_nee_sample(sc, key, s, b, ps, n, true);
}

/* next-event estimation's shadow ray alone (path_nee_sample), an environment sample's radiance deferred where
 * ENV_DEFERRED: what the ray adds when unoccluded is path_lit's */
static inline bool path_sample_light(const Scene* sc, RngKey key, const Surface* s, const Bsdf* b,
                                     const PathState* ps, ShadowRay* sr) {
    NeeSample n;
    if (!path_nee_sample(sc, key, s, b, ps, &n, !ENV_DEFERRED)) return false;
    *sr = n.sr;
    return true;
}

/* A deferred environment sample's contribution along dir once unoccluded: times the environment's radiance. */
static inline vec3 path_env_lit(const Scene* sc, vec3 dir, vec3 contrib) {
    float pdf;
    return v3_mul(contrib, env_eval(sc, dir, false, &pdf));
}

/* The radiance an unoccluded shadow ray of path_sample_light adds: its contribution, times the environment's
 * radiance along it for a deferred environment sample (an infinite tmax: ENV_DEFERRED). */
static inline vec3 path_lit(const Scene* sc, const ShadowRay* sr) {
#if ENV_DEFERRED
    if (m_isinf(sr->tmax)) return path_env_lit(sc, sr->dir, sr->contrib);
#endif
    return sr->contrib;
}

/* BSDF sampling, after bsdf_sample: the sample bs taken from the surface s: the next ray, throughput update and
 * Russian roulette. Returns false when the path ends (the sample's side, zero throughput, roulette). */
static inline GPU_INLINE bool path_bsdf_take(const Surface* s, const BsdfSample* bs, float u_roulette,
                                             PathState* ps) {
    vec3 dir = to_world(s->sh, bs->wo);
    /* reject samples whose side disagrees between shading and geometric normals */
    if (m_dot(dir, s->ng) * bs->wo.z <= 0.0f) return false;
    ps->beta = v3_mul(ps->beta, bs->weight);
    ps->rr_scale *= bs->eta * bs->eta;
    ps->prev_pdf = bs->pdf;
    ps->flags = PATH_KEPT_FLAGS(ps->flags) | (bs->delta ? PATH_PREV_DELTA : 0);
    ps->org = spawn_origin(s, dir);
    ps->dir = dir;
    ps->depth += 1;
    float beta_max = max3(ps->beta);
    if (!(beta_max > 0.0f)) return false;
    /* The roulette weighs the throughput relative to the first bounce's (docs/architecture.md, "Russian
     * roulette"): what a path adds to its pixel, as a share of what the pixel shows. A dark first surface
     * (whose pixel is dark too) no longer ends its paths sooner than a bright one. */
    if (ps->depth == 1 && beta_max < 1.0f) ps->rr_scale /= beta_max;
    if (ps->depth >= RR_DEPTH) {
        float q = m_min(RR_FACTOR * beta_max * ps->rr_scale, 0.95f);
        if (u_roulette >= q) return false;
        ps->beta = v3_divs(ps->beta, q);
    }
    return true;
}

/* BSDF sampling: the next direction, throughput update and Russian roulette (the random numbers, bsdf_sample, then
 * path_bsdf_take). Returns false when the path ends (depth limit, no valid sample, roulette). */
static inline GPU_INLINE bool path_sample_bsdf(RngKey key, const Surface* s, const Bsdf* b, PathState* ps,
                                               int max_depth) {
    if (!depth_allows(ps->depth + 1, max_depth)) return false;
    float u_lobe, u_roulette;
    vec2 u;
    rng_bsdf(key, ps->depth, &u_lobe, &u, &u_roulette);
    BsdfSample bs;
    if (!bsdf_sample(b, to_local(s->sh, v3_neg(ps->dir)), u_lobe, u, &bs)) return false;
    return path_bsdf_take(s, &bs, u_roulette, ps);
}

/* -DPATH_TRACE (never in a normal render; pyclpt/gpu/simt.py builds the megakernel with it): path_continue
 * records what each path did at each bounce in the Scene's trace record (scene.h): word 0 the
 * PATH_TRACE_* flags below, with the material kind hit (MAT_* of bsdf.h) in bits 8-15; words 1, 2 the
 * closest-hit ray's BVH nodes visited and triangles tested; words 3, 4 the shadow ray's (BVH_COUNT,
 * scene/mask.h). Bounces at or past trace_rows are not recorded. The arithmetic is untouched: the
 * image is the plain render's bit for bit (tests/test_simt.py). */
#ifdef PATH_TRACE
#define PATH_TRACE_ALIVE 1     /* a ray was traced at this bounce */
#define PATH_TRACE_HIT 2       /* it hit a surface */
#define PATH_TRACE_SHADOW 4    /* a shadow ray was cast (a valid light sample) */
#define PATH_TRACE_LIT 8       /* ... and it was unoccluded */
#define PATH_TRACE_CONTINUED 16 /* the BSDF sample made a next ray (the path goes on) */
#define PATH_TRACE_NEXT 32     /* the depth limit allowed light and BSDF sampling at this hit */
#define PATH_TRACE_ENV_LIT 64  /* the unoccluded shadow ray was a deferred environment sample (path_lit) */
#define PATH_TRACE_WORDS 5
static inline void path_trace_put(const Scene* sc, int bounce, int word, int v) {
    if (sc->trace != 0 && bounce < sc->trace_rows) sc->trace[(word * sc->trace_rows + bounce) * sc->trace_stride] = v;
}
static inline void path_trace_steps(const Scene* sc, int bounce, int word) {
    if (sc->bvh_steps == 0) return;
    path_trace_put(sc, bounce, word, sc->bvh_steps[0]);
    path_trace_put(sc, bounce, word + 1, sc->bvh_steps[1]);
    sc->bvh_steps[0] = 0;
    sc->bvh_steps[1] = 0;
}
#endif

/* The closest hit of the path's current ray: *first where it is given (its first ray's hit, already found; then
 * *first is cleared), else a traversal. */
static inline bool path_next_hit(const Scene* sc, RngKey key, const PathState* ps, const Hit** first, Hit* hit) {
    if (*first != 0) {
        *hit = **first;
        *first = 0;
        return true;
    }
    return scene_closest(sc, key, ps->depth, ps->org, ps->dir, hit);
}

/* The rest of a path from its current ray, bounce after bounce, until it leaves the scene, reaches the
 * depth limit or ends by roulette: the megakernel's loop, which the wavefront's finish_paths stage also
 * runs for the last paths of a wave. With -DAOVS it records the G-buffer in aov (gbuffer.h). `first`: the
 * current ray's hit where the caller has found it (0: none found yet; a miss is not passed). */
static inline void path_continue_from(const Scene* sc, RngKey key, PathState* ps, int max_depth, AovOut aov,
                                      const Hit* first) {
    for (;;) {
        Hit hit;
#ifdef PATH_TRACE
        int bounce = ps->depth;
        bool found = path_next_hit(sc, key, ps, &first, &hit);
        int tr = PATH_TRACE_ALIVE | (found ? PATH_TRACE_HIT : 0);
        path_trace_steps(sc, bounce, 1);
        path_trace_put(sc, bounce, 0, tr);
        if (!found) {
#else
        if (!path_next_hit(sc, key, ps, &first, &hit)) {
#endif
#ifdef AOVS
            gbuffer_miss(sc, aov, ps->depth, ps->dir);
#endif
            path_miss(sc, ps);
            return;
        }
        Surface s = surface_hit(sc, hit.prim, hit.u, hit.v, ps->dir);
#ifdef AOVS
        gbuffer_hit(sc, aov, hit.prim, &s, hit.t, ps->depth, ps->dir, ps->beta, &ps->flags);
#endif
#ifdef PATH_TRACE
        tr |= (mat_type(scene_material(sc, s.material)) & 255) << 8;
        path_trace_put(sc, bounce, 0, tr);
#endif
        path_hit_emission(sc, &s, hit.t, ps);
        if (!depth_allows(ps->depth + 1, max_depth)) return;
        Bsdf b = bsdf_at(sc, &s); /* the material at the hit, textures looked up once */
        ShadowRay sr;
#ifdef PATH_TRACE
        bool shadow = path_sample_light(sc, key, &s, &b, ps, &sr);
        bool lit = shadow && !scene_occluded(sc, key, ps->depth, sr.org, sr.dir, sr.tmax);
        if (lit) ps->L = v3_add(ps->L, path_lit(sc, &sr));
        path_trace_steps(sc, bounce, 3);
        tr |= PATH_TRACE_NEXT | (shadow ? PATH_TRACE_SHADOW : 0) | (lit ? PATH_TRACE_LIT : 0) |
              (lit && ENV_DEFERRED && m_isinf(sr.tmax) ? PATH_TRACE_ENV_LIT : 0);
        bool more = path_sample_bsdf(key, &s, &b, ps, max_depth);
        path_trace_put(sc, bounce, 0, tr | (more ? PATH_TRACE_CONTINUED : 0));
        if (!more) return;
#else
        if (path_sample_light(sc, key, &s, &b, ps, &sr) && !scene_occluded(sc, key, ps->depth, sr.org, sr.dir, sr.tmax))
            ps->L = v3_add(ps->L, path_lit(sc, &sr));
        if (!path_sample_bsdf(key, &s, &b, ps, max_depth)) return;
#endif
    }
}

static inline void path_continue(const Scene* sc, RngKey key, PathState* ps, int max_depth, AovOut aov) {
    path_continue_from(sc, key, ps, max_depth, aov, 0);
}

/* The end of a path: its radiance goes to its film slot f (see film_pixel); a NaN or inf sample is
 * dropped (0 is written) and marked in drop_marks[f], which the film counts after the batch
 * (cl/film/count_dropped.cl). A plain add, not an atomic: one path owns its slot in a batch,
 * so the stages that commit can vectorize; a path committed twice would count twice. */
static inline void film_commit(__global float* frame, __global uchar* drop_marks, int f, vec3 L) {
    bool bad = !all_finite3(L);
    drop_marks[f] += bad ? (uchar)1 : (uchar)0;
    frame[3 * f + 0] = bad ? 0.0f : L.x;
    frame[3 * f + 1] = bad ? 0.0f : L.y;
    frame[3 * f + 2] = bad ? 0.0f : L.z;
}

#endif
