/* finish_paths: the last paths of a wave, each run to its end in one work-item, as the megakernel
 * runs it (path_continue, integrators/path.h): once few paths remain, the launches of a bounce's
 * stages cost more than they save (pyclpt/integrators/wavefront.py: tail_paths).
 * Consumes: the ray queue of this bounce (the paths' state as sample_bsdf stored it).
 * Produces: each path's radiance in frame[film slot] (0 and a mark in drop_marks for NaN/inf); the
 *           queues of later bounces stay empty; with -DAOVS the G-buffer values of its later bounces
 *           (integrators/gbuffer.h) in aovs; for the statistics, each later bounce it traced a ray at
 *           counted in tail_alive[bounce] (rows 0 .. max_depth + 1; the host reads and clears them). */
#include "integrators/wavefront/wavefront.h"

__kernel SCALAR_KERNEL void finish_paths(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* ray_queue,
                                         __global float* frame, __global uchar* drop_marks, uint seed, uint first_sample,
                                         int max_depth, __global float* aovs, int aov_n,
                                         __global int* tail_alive) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_RAY)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = ray_queue[i];
    PathState ps = path_load_ray(&P, slot, bounce);
    int f = path_get_film_slot(&P, slot);
    path_continue(&sc, path_key(&P, &sc, slot, seed, first_sample), &ps, max_depth, aov_out(aovs, aov_n, f));
    film_commit(frame, drop_marks, f, ps.L);
    for (int b = bounce + 1; b <= ps.depth && b <= max_depth + 1; ++b) atomic_inc(&tail_alive[b]);
}
