/* megakernel: one work-item runs a whole path for one (pixel, sample).
 *
 * Consumes: the film slots [offset, offset + count) of a batch of frames starting at sample
 *           first_sample (slot f: pixel f % pixels, sample first_sample + f / pixels; path.h).
 * Produces: each path's radiance in frame[f] (3 floats), 0 for a NaN/inf sample, which
 *           adds 1 to drop_marks[f] (counted by the film after the batch); with -DAOVS its G-buffer
 *           record in aovs (slot f of aov_n; integrators/gbuffer.h).
 * The baseline the wavefront integrator is measured against: same estimator
 * (path.h), same random numbers.
 * With -DPATH_TRACE (pyclpt/gpu/simt.py, never in a normal render) it also takes a trace buffer of
 * PATH_TRACE_WORDS x trace_rows x trace_slots ints and records each path's bounces in it (path.h). */
#include "integrators/path.h"

#ifdef PATH_TRACE
#define MEGAKERNEL_TRACE_PARAMS , __global int *trace, int trace_slots, int trace_rows
#else
#define MEGAKERNEL_TRACE_PARAMS
#endif

__kernel SCALAR_KERNEL void megakernel(SCENE_PARAMS, __global float* frame, __global uchar* drop_marks,
                         uint seed, uint first_sample, int offset, int count, int max_depth,
                         __global float* aovs, int aov_n MEGAKERNEL_TRACE_PARAMS) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    int f = offset + i;
#ifdef PATH_TRACE
    int steps[2] = {0, 0};
    sc.bvh_steps = steps;
    sc.trace = trace + f;
    sc.trace_stride = trace_slots;
    sc.trace_rows = trace_rows;
#endif
    int pixel = film_pixel(&sc, f);
    RngKey key = rng_key(seed, (uint)pixel, film_sample(&sc, first_sample, f));
    PathState ps;
    camera_path(&sc, key, pixel, &ps);
    if (max_depth != 0) path_continue(&sc, key, &ps, max_depth, aov_out(aovs, aov_n, f));
    film_commit(frame, drop_marks, f, ps.L);
}
