/* path_init: camera rays for the wave's (pixel, sample) pairs.
 * Consumes: slots 0 .. count-1, pixel = pixel_offset + slot.
 * Produces: the path state of each slot and the ray queue of bounce 0 (slot i at entry i, so in
 *           order) with its count; with max_depth 0 the radiance in frame[pixel] instead. */
#include "integrators/wavefront/wavefront.h"

__kernel void path_init(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global int* ray_queue,
                        __global float* frame, __global uchar* drop_marks,
                        uint seed, uint sample, int pixel_offset, int count, int max_depth) {
    int slot = get_global_id(0);
    if (slot >= count) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int pixel = pixel_offset + slot;
    PathState ps;
    camera_path(&sc, rng_key(seed, (uint)pixel, sample), pixel, &ps);
    if (max_depth == 0) {
        film_commit(frame, drop_marks, pixel, ps.L);
        return;
    }
    path_set_pixel(&P, slot, pixel);
    path_set_L(&P, slot, ps.L);
    path_store_ray(&P, slot, &ps);
    ray_queue[slot] = slot;
    if (slot == 0) counters[bounce * Q_COUNT + Q_RAY] = count;
}
