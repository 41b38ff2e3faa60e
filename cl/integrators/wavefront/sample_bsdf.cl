/* sample_bsdf: next direction, throughput update and Russian roulette.
 * Consumes: the hit queue of this bounce (after hit processing and light contribution).
 * Produces: survivors in the ray queue of the next bounce; paths that end
 *           (depth limit, invalid sample, roulette) commit their radiance to frame[pixel]. */
#include "integrators/wavefront/wavefront.h"

__kernel void sample_bsdf(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* hit_queue,
                          __global int* next_ray_queue, __global float* frame, volatile __global int* dropped,
                          uint seed, uint sample, int max_depth) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_HIT)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = hit_queue[i];
    PathState ps;
    ps.dir = path_get_dir(&P, slot);
    ps.beta = path_get_beta(&P, slot);
    ps.eta_scale = path_get_eta_scale(&P, slot);
    ps.depth = bounce;
    Surface s = surface_at(&sc, path_get_hit_prim(&P, slot), path_get_hit_u(&P, slot), path_get_hit_v(&P, slot));
    Bsdf b = bsdf_at(&sc, &s);
    if (path_sample_bsdf(path_key(&P, slot, seed, sample), &s, &b, &ps, max_depth)) {
        path_store_ray(&P, slot, &ps);
        queue_push(next_ray_queue, counters, bounce + 1, Q_RAY, slot);
    } else {
        film_commit(frame, dropped, path_get_pixel(&P, slot), path_get_L(&P, slot));
    }
}
