/* edge_radiance: the radiance on the two sides of points of the image's silhouette edges, for the
 * boundary term of primary visibility (pyclpt/gradients/edges.py, docs/differentiable.md).
 *
 * Consumes: count points, points[4 i .. 4 i + 3] = a film position x, y (pixels from the image's
 *           top-left corner, continuous) and the edge's unit normal nx, ny there (film space).
 * Produces: radiance[3 (2 i)] the radiance of the camera path through (x, y) - eps n, radiance[3 (2 i + 1)]
 *           through (x, y) + eps n: the estimator of path.h, both sides with the same random numbers
 *           (key: seed, point i, sample 0), so that their difference has the variance of the edge only;
 *           0 for a NaN or inf one, which adds 1 to drop_marks[2 i (+ 1)]. */
#include "integrators/path.h"

__kernel SCALAR_KERNEL void edge_radiance(SCENE_PARAMS, __global const float* points, __global float* radiance,
                                          __global uchar* drop_marks, uint seed, int count, int max_depth,
                                          float eps) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    RngKey key = rng_key(seed, (uint)i, 0u);
    float x = points[4 * i], y = points[4 * i + 1], nx = points[4 * i + 2], ny = points[4 * i + 3];
    for (int side = 0; side < 2; side++) {
        float s = side == 0 ? -eps : eps;
        PathState ps;
        camera_ray(&sc, key, x + s * nx, y + s * ny, &ps);
        if (max_depth != 0) path_continue(&sc, key, &ps, max_depth, aov_out(0, 0, 0));
        film_commit(radiance, drop_marks, 2 * i + side, ps.L);
    }
}
