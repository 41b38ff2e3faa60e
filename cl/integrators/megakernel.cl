/* megakernel: one work-item runs a whole path for one (pixel, sample).
 *
 * Consumes: the pixels [pixel_offset, pixel_offset + count) of one sample index.
 * Produces: each path's radiance in frame[pixel] (3 floats), 0 for a NaN/inf sample, which
 *           adds 1 to drop_marks[pixel] (counted by the film after the frame).
 * The baseline the wavefront integrator is measured against: same estimator
 * (path.h), same random numbers. */
#include "integrators/path.h"

__kernel SCALAR_KERNEL void megakernel(SCENE_PARAMS, __global float* frame, __global uchar* drop_marks,
                         uint seed, uint sample, int pixel_offset, int count, int max_depth) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    int pixel = pixel_offset + i;
    RngKey key = rng_key(seed, (uint)pixel, sample);
    PathState ps;
    camera_path(&sc, key, pixel, &ps);
    if (max_depth != 0) path_continue(&sc, key, &ps, max_depth);
    film_commit(frame, drop_marks, pixel, ps.L);
}
