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
    if (max_depth != 0) {
        for (;;) {
            Hit hit;
            if (!scene_closest(&sc, key, ps.depth, ps.org, ps.dir, &hit)) {
                path_miss(&sc, &ps);
                break;
            }
            Surface s = surface_at(&sc, hit.prim, hit.u, hit.v);
            path_hit_emission(&sc, &s, hit.t, &ps);
            if (!depth_allows(ps.depth + 1, max_depth)) break;
            Bsdf b = bsdf_at(&sc, &s); /* the material at the hit, textures looked up once */
            ShadowRay sr;
            if (path_sample_light(&sc, key, &s, &b, &ps, &sr) &&
                !scene_occluded(&sc, key, ps.depth, sr.org, sr.dir, sr.tmax))
                ps.L = v3_add(ps.L, sr.contrib);
            if (!path_sample_bsdf(key, &s, &b, &ps, max_depth)) break;
        }
    }
    film_commit(frame, drop_marks, pixel, ps.L);
}
