/* miss: environment radiance for paths that left the scene (MIS-weighted); the path ends.
 * Consumes: the miss queue of this bounce.
 * Produces: the path's radiance in frame[film slot] (0 and a mark in drop_marks for NaN/inf); with
 *           -DAOVS a camera ray's motion vector in aovs (integrators/gbuffer.h). */
#include "integrators/wavefront/wavefront.h"

__kernel void miss(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* miss_queue,
                   __global float* frame, __global uchar* drop_marks, __global float* aovs, int aov_n) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_MISS)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = miss_queue[i];
    PathState ps = path_load_shading(&P, slot, bounce);
    int f = path_get_film_slot(&P, slot);
#ifdef AOVS
    gbuffer_miss(&sc, aov_out(aovs, aov_n, f), bounce, ps.dir);
#endif
    path_miss(&sc, &ps);
    film_commit(frame, drop_marks, f, ps.L);
}
