/* incident_radiance: the radiance reaching the surface a camera ray sees from two directions either side of an
 * edge, times the BSDF there, for the boundary term of soft shadows (pyclpt/gradients/shadows.py,
 * soft_shadow_boundary; docs/differentiable.md).
 *
 * Consumes: count samples, samples[8 i .. 8 i + 7] = a film position x, y (pixels from the image's top-left
 *           corner), a unit direction w (world) and a unit n perpendicular to it (the edge's side).
 * Produces: radiance[3 (2 i)] = f(wi, w - eps n) |cos| L_i(w - eps n) at the camera ray's first hit, radiance[3 (2 i
 *           + 1)] the same for w + eps n: L_i the estimator of path.h from there (both sides with the same random
 *           numbers, key: seed, sample i, 0; the emission it meets counted whole, as after a delta sample); 0 where
 *           the camera ray misses, the direction is below the surface or the depth allows no bounce; a NaN or inf
 *           one gives 0 and adds 1 to drop_marks[2 i (+ 1)]; first_prim[2 i (+ 1)] the leaf-order triangle that
 *           side's ray meets first (-1: none) and first_hit[3 (2 i (+ 1))] its distance and barycentrics there, so
 *           that the host can tell the occluder's side from the one that passes it, and what lies behind. */
#include "gradients/incident.h"

__kernel SCALAR_KERNEL void incident_radiance(SCENE_PARAMS, __global const float* samples, __global float* radiance,
                                              __global int* first_prim, __global float* first_hit,
                                              __global uchar* drop_marks, uint seed,
                                              int count, int max_depth, float eps) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    RngKey key = rng_key(seed, (uint)i, 0u);
    __global const float* q = samples + 8 * i;
    PathState cam;
    camera_ray(&sc, key, q[0], q[1], &cam);
    Hit hit;
    bool found = depth_allows(1, max_depth) && scene_closest(&sc, key, 0, cam.org, cam.dir, &hit);
    Surface s;
    Bsdf b;
    vec3 wi = v3_splat(0.0f);
    if (found) {
        s = surface_hit(&sc, hit.prim, hit.u, hit.v, cam.dir);
        b = bsdf_at(&sc, &s);
        wi = to_local(s.sh, v3_neg(cam.dir));
    }
    incident_sides(&sc, key, found, &s, &b, wi, v3(q[2], q[3], q[4]), v3(q[5], q[6], q[7]), eps, 1, max_depth, i,
                   radiance, first_prim, first_hit, drop_marks);
}
