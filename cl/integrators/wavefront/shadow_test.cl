/* shadow_test: any-hit visibility of each queued shadow ray.
 * Consumes: the shadow queue of this bounce.
 * Produces: flags[i] = 1 for an unoccluded ray, 0 for an occluded one (compaction then
 *           builds the light-contribution queue); an unoccluded deferred environment sample's
 *           contribution times the environment's radiance along it (ENV_DEFERRED, path_lit). */
#include "integrators/wavefront/wavefront.h"

__kernel SCALAR_KERNEL void shadow_test(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* shadow_queue,
                          __global uchar* flags, uint seed, uint first_sample) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_SHADOW)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = shadow_queue[i];
    float tmax = path_get_shadow_tmax(&P, slot);
    vec3 dir = path_get_shadow_dir(&P, slot);
    bool occluded = scene_occluded(&sc, path_key(&P, &sc, slot, seed, first_sample), bounce,
                                   path_get_shadow_org(&P, slot), dir, tmax);
    flags[i] = occluded ? 0 : 1;
#if ENV_DEFERRED
    if (!occluded && m_isinf(tmax)) /* an environment sample: its radiance (path_lit) */
        path_set_shadow_contrib(&P, slot, path_env_lit(&sc, dir, path_get_shadow_contrib(&P, slot)));
#endif
}
