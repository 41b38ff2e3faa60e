/* sample_bsdf: next direction, throughput update and Russian roulette.
 * Consumes: the hit queue of this bounce (after hit processing and light contribution).
 * Produces: for survivors the next ray and flags[i] = 1 (compaction then builds the next
 *           bounce's ray queue); paths that end (depth limit, invalid sample, roulette) get
 *           flags[i] = 0 and commit their radiance to frame[film slot]. */
#include "integrators/wavefront/wavefront.h"

__kernel void sample_bsdf(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* hit_queue,
                          __global uchar* flags, __global float* frame, __global uchar* drop_marks,
                          uint seed, uint first_sample, int max_depth) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_HIT)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = hit_queue[i];
    PathState ps;
    ps.dir = path_get_dir(&P, slot);
    ps.beta = path_get_beta(&P, slot);
    ps.rr_scale = path_get_rr_scale(&P, slot);
    ps.depth = bounce;
#ifdef AOVS
    ps.flags = path_get_flags(&P, slot); /* PATH_ALBEDO_DONE carries on (PATH_KEPT_FLAGS, path.h) */
#endif
    Surface s = surface_hit(&sc, path_get_hit_prim(&P, slot), path_get_hit_u(&P, slot), path_get_hit_v(&P, slot), ps.dir);
    Bsdf b = bsdf_at(&sc, &s);
    bool alive = path_sample_bsdf(path_key(&P, &sc, slot, seed, first_sample), &s, &b, &ps, max_depth);
#ifdef DEVICE_CLASS_GPU
    /* GPUs (-DDEVICE_CLASS_GPU, pyclpt/buffers/scene.py): the slot read again after the flag store (a
     * uchar store, which may alias the queue as far as the compiler knows), so that the stores below
     * compute the path state's addresses afresh instead of keeping the loads' (64-bit each) alive across
     * the shading: 73 -> 58 registers on sm_90 (docs/bvh.md, "Layouts per device class"). The same values;
     * CPUs keep the order below, where the reload cost PoCL's stage 2-7 %. */
    flags[i] = alive ? 1 : 0;
    slot = hit_queue[i];
    if (alive) path_store_ray(&P, slot, &ps);
    else film_commit(frame, drop_marks, path_get_film_slot(&P, slot), path_get_L(&P, slot));
#else
    if (alive) path_store_ray(&P, slot, &ps);
    else film_commit(frame, drop_marks, path_get_film_slot(&P, slot), path_get_L(&P, slot));
    flags[i] = alive ? 1 : 0;
#endif
}
