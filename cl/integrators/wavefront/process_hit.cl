/* process_hit: emission at the hit (MIS-weighted against the BSDF sample that
 * found it), then light sampling: choose an emitter and a point on it.
 * Consumes: the hit queue of this bounce.
 * Produces: updated radiance; for valid light samples (pdf > 0, non-zero
 *           contribution) a shadow ray and flags[i] = 1, else flags[i] = 0
 *           (compaction then builds the shadow queue). Every hit path stays in
 *           the hit queue for BSDF sampling. With -DAOVS: the G-buffer values of this bounce in
 *           aovs and the path's flags (PATH_ALBEDO_DONE; integrators/gbuffer.h). */
#include "integrators/wavefront/wavefront.h"

__kernel void process_hit(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* hit_queue,
                          __global uchar* flags, uint seed, uint first_sample, int max_depth,
                          __global float* aovs, int aov_n) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_HIT)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = hit_queue[i];
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
    flags[i] = shadow ? 1 : 0;
}
