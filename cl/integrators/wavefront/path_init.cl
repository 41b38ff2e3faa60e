/* path_init: camera rays for the wave's (pixel, sample) pairs.
 * Consumes: slots 0 .. count-1, film slot f = offset + slot of the batch starting at sample
 *           first_sample (pixel f % pixels, sample first_sample + f / pixels; integrators/path.h).
 * Produces: the path state of each slot and the ray queue of bounce 0 (slot i at entry i, so in
 *           order) with its count; with max_depth 0 the radiance in frame[f] instead. */
#include "integrators/wavefront/wavefront.h"

__kernel void path_init(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global int* ray_queue,
                        __global float* frame, __global uchar* drop_marks,
                        uint seed, uint first_sample, int offset, int count, int max_depth) {
    int slot = get_global_id(0);
    if (slot >= count) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int f = offset + slot;
    int pixel = film_pixel(&sc, f);
    PathState ps;
    camera_path(&sc, rng_key(seed, (uint)pixel, film_sample(&sc, first_sample, f)), pixel, &ps);
    if (max_depth == 0) {
        film_commit(frame, drop_marks, f, ps.L);
        return;
    }
    path_set_film_slot(&P, slot, f);
    path_set_L(&P, slot, ps.L);
    path_store_ray(&P, slot, &ps);
    ray_queue[slot] = slot;
    if (slot == 0) counters[bounce * Q_COUNT + Q_RAY] = count;
}
