/* megakernel: one work-item runs a whole path for one (pixel, sample).
 *
 * Consumes: the film slots [offset, offset + count) of a batch of frames starting at sample
 *           first_sample (slot f: pixel f % pixels, sample first_sample + f / pixels; path.h).
 * Produces: each path's radiance in frame[f] (3 floats), 0 for a NaN/inf sample, which
 *           adds 1 to drop_marks[f] (counted by the film after the batch); with -DAOVS its G-buffer
 *           record in aovs (slot f of aov_n; integrators/gbuffer.h).
 * The baseline the wavefront integrator is measured against: same estimator
 * (path.h), same random numbers. */
#include "integrators/path.h"

__kernel SCALAR_KERNEL void megakernel(SCENE_PARAMS, __global float* frame, __global uchar* drop_marks,
                         uint seed, uint first_sample, int offset, int count, int max_depth,
                         __global float* aovs, int aov_n) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    int f = offset + i;
    int pixel = film_pixel(&sc, f);
    RngKey key = rng_key(seed, (uint)pixel, film_sample(&sc, first_sample, f));
    PathState ps;
    camera_path(&sc, key, pixel, &ps);
    if (max_depth != 0) path_continue(&sc, key, &ps, max_depth, aov_out(aovs, aov_n, f));
    film_commit(frame, drop_marks, f, ps.L);
}
