/* process_hit: emission at the hit (MIS-weighted against the BSDF sample that
 * found it), then light sampling: choose an emitter and a point on it.
 * Consumes: the hit queue of this bounce.
 * Produces: updated radiance; for valid light samples (pdf > 0, non-zero
 *           contribution) a shadow ray and flags[i] = 1, else flags[i] = 0
 *           (compaction then builds the shadow queue). Every hit path stays in
 *           the hit queue for BSDF sampling. With -DAOVS: the G-buffer values of this bounce in
 *           aovs and the path's flags (PATH_ALBEDO_DONE; integrators/gbuffer.h). */
#include "integrators/wavefront/wavefront.h"

#ifdef DEVICE_CLASS_GPU
/* GPUs (-DDEVICE_CLASS_GPU) run the stage in steps, each of which reads what it needs from the path state and
 * builds the surface afresh after a store that may alias every buffer (queue_reread), so that no step holds
 * another's values in registers: the shading stages' budget (docs/gpu.md, "The shading stages in steps"). The
 * same functions on the same values as the CPU's order below: the same results. */

/* Light sampling, first step: the light sample seen from the hit (path_nee_light), kept in the path's shadow-ray
 * slots for process_hit_weigh (dir: wi; tmax: the distance; contrib: the radiance; org.x: the pdf, negated for a
 * delta light). False where there is none (a delta material, no sample). */
static inline GPU_INLINE bool process_hit_light(const Scene* sc, const PathStore* P, int slot, int bounce,
                                                uint seed, uint first_sample) {
    Surface s = path_hit_surface(sc, P, slot);
    if (mat_is_delta(scene_material(sc, s.material))) return false;
    LightSample ls;
    if (!path_nee_light(sc, path_key(P, sc, slot, seed, first_sample), s.p, bounce, &ls, !ENV_DEFERRED)) return false;
    path_set_shadow_dir(P, slot, ls.wi);
    path_set_shadow_tmax(P, slot, ls.dist);
    path_set_shadow_contrib(P, slot, ls.radiance);
    path_set_shadow_org(P, slot, v3(ls.delta ? -ls.pdf : ls.pdf, 0.0f, 0.0f)); /* pdf > 0 (light_sample) */
    return true;
}

/* ... and its second: the shadow ray (path_nee_ray), stored before the material is looked up, then the BSDF at the
 * light sample and the contribution (path_nee_weigh). True where the shadow ray can contribute. */
static inline GPU_INLINE bool process_hit_weigh(const Scene* sc, const PathStore* P, int slot, int bounce,
                                                BsdfTextures tx) {
    NeeSample n;
    n.ls.wi = path_get_shadow_dir(P, slot);
    n.ls.dist = path_get_shadow_tmax(P, slot);
    float pdf = path_get_shadow_org(P, slot).x;
    PathState ps;
    ps.dir = path_get_dir(P, slot);
    ps.depth = bounce;
    Surface s = path_hit_surface(sc, P, slot);
    vec3 wi;
    if (!path_nee_ray(&s, &ps, &n, &wi)) return false;
    path_set_shadow_org(P, slot, n.sr.org); /* the direction is there already */
    path_set_shadow_tmax(P, slot, n.sr.tmax);
    Bsdf b = bsdf_textured(sc, &s, tx);
    float bsdf_pdf = path_nee_eval(&b, wi, &n);
    n.ls.radiance = path_get_shadow_contrib(P, slot);
    n.ls.pdf = m_abs(pdf);
    n.ls.delta = pdf < 0.0f;
    ps.beta = path_get_beta(P, slot);
    if (!path_nee_weigh(&ps, bsdf_pdf, &n)) return false;
    path_set_shadow_contrib(P, slot, n.sr.contrib);
    return true;
}
#endif

__kernel void process_hit(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* hit_queue,
                          __global uchar* flags, uint seed, uint first_sample, int max_depth,
                          __global float* aovs, int aov_n) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_HIT)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = hit_queue[i];
#ifdef DEVICE_CLASS_GPU
    path_keep_hit_normal(&sc, &P, slot);
    slot = queue_reread(flags, hit_queue, i);
    {
        /* the emission */
        PathState ps = path_load_shading(&P, slot, bounce);
        Surface s = path_hit_surface(&sc, &P, slot);
        path_hit_emission(&sc, &s, path_get_hit_t(&P, slot), &ps);
        path_set_L(&P, slot, ps.L);
    }
    bool shadow = false;
    if (depth_allows(bounce + 1, max_depth)) {
        /* light sampling */
        slot = queue_reread(flags, hit_queue, i);
        if (process_hit_light(&sc, &P, slot, bounce, seed, first_sample)) {
            slot = queue_reread(flags, hit_queue, i);
            BsdfTextures tx = path_hit_textures(&sc, &P, flags, hit_queue, i, &slot);
            shadow = process_hit_weigh(&sc, &P, slot, bounce, tx);
        }
    }
#ifdef AOVS
    slot = queue_reread(flags, hit_queue, i);
    /* the G-buffer: what every hit records (gbuffer_hit_path: the hit distance, the albedo with the textures
     * looked up in a step of their own), then what the camera ray's records */
    if (bounce == 1) aov_put(aov_out(aovs, aov_n, path_get_film_slot(&P, slot)), AOV_HITDIST, path_get_hit_t(&P, slot));
    if (!(path_get_flags(&P, slot) & PATH_ALBEDO_DONE)) {
        BsdfTextures tx = path_hit_textures(&sc, &P, flags, hit_queue, i, &slot);
        Surface s = path_hit_surface(&sc, &P, slot);
        Bsdf b = bsdf_textured(&sc, &s, tx);
        int pflags = path_get_flags(&P, slot);
        gbuffer_albedo(aov_out(aovs, aov_n, path_get_film_slot(&P, slot)), &b, path_get_beta(&P, slot), &pflags);
        path_set_flags(&P, slot, pflags);
    }
    if (bounce == 0) {
        slot = queue_reread(flags, hit_queue, i);
        Surface s = path_hit_surface(&sc, &P, slot);
        gbuffer_hit_first(&sc, aov_out(aovs, aov_n, path_get_film_slot(&P, slot)), path_get_hit_prim(&P, slot), &s,
                          path_get_dir(&P, slot));
    }
#endif
#else
    PathState ps = path_load_shading(&P, slot, bounce);
    int prim = path_get_hit_prim(&P, slot);
    Surface s = surface_hit(&sc, prim, path_get_hit_u(&P, slot), path_get_hit_v(&P, slot), ps.dir);
#ifdef AOVS
    gbuffer_hit(&sc, aov_out(aovs, aov_n, path_get_film_slot(&P, slot)), prim, &s, path_get_hit_t(&P, slot), bounce,
                ps.dir, ps.beta, &ps.flags);
    path_set_flags(&P, slot, ps.flags);
#endif
    path_hit_emission(&sc, &s, path_get_hit_t(&P, slot), &ps);
    path_set_L(&P, slot, ps.L);
    bool shadow = false;
    if (depth_allows(bounce + 1, max_depth)) {
        ShadowRay sr;
        Bsdf b = bsdf_at(&sc, &s);
        shadow = path_sample_light(&sc, path_key(&P, &sc, slot, seed, first_sample), &s, &b, &ps, &sr);
        if (shadow) path_store_shadow(&P, slot, &sr);
    }
#endif
    flags[i] = shadow ? 1 : 0;
}
