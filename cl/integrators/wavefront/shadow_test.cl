/* shadow_test: any-hit visibility of each queued shadow ray.
 * Consumes: the shadow queue of this bounce.
 * Produces: an entry in the light-contribution queue for each unoccluded ray. */
#include "integrators/wavefront/wavefront.h"

__kernel void shadow_test(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* shadow_queue,
                          __global int* light_queue, uint seed, uint sample) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_SHADOW)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = shadow_queue[i];
    if (!scene_occluded(&sc, path_key(&P, slot, seed, sample), bounce, path_get_shadow_org(&P, slot),
                        path_get_shadow_dir(&P, slot), path_get_shadow_tmax(&P, slot)))
        queue_push(light_queue, counters, bounce, Q_LIGHT, slot);
}
