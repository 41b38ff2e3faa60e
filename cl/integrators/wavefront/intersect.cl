/* intersect: closest hit for every queued ray.
 * Consumes: the ray queue of this bounce.
 * Produces: the hit record (hit_t/u/v/prim) and flags[i] = 1 for a hit, 0 for a miss
 *           (compaction then splits the ray queue into the hit and miss queues). */
#include "integrators/wavefront/wavefront.h"

__kernel SCALAR_KERNEL void intersect(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* ray_queue,
                        __global uchar* flags, uint seed, uint first_sample) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_RAY)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = ray_queue[i];
    Hit hit;
    bool found = scene_closest(&sc, path_key(&P, &sc, slot, seed, first_sample), bounce, path_get_org(&P, slot),
                               path_get_dir(&P, slot), &hit);
    if (found) path_store_hit(&P, slot, &hit);
    flags[i] = found ? 1 : 0;
}
