/* vertex_radiance: the radiance reaching a later vertex of a camera path from two directions either side of an
 * occluder's outline, times the BSDF there (path_vertices.cl chose the vertex), for the soft-shadow boundary term
 * after the first bounce (pyclpt/gradients/shadows.py, sample_soft_edges; docs/differentiable.md).
 *
 * Consumes: count samples, prims[i] the vertex's leaf-order triangle, samples[11 i ..] = its barycentrics u, v, the
 *           world direction back along the path (3), a unit direction w (3, world) and a unit n perpendicular to it
 *           (3, the edge's side), depths[i] the vertex's bounce (the camera's hit: 0).
 * Produces: as incident_radiance, with the random numbers of key (seed, i, 0) and the sides' first rays at bounce
 *           depths[i] + 1 (cl/gradients/incident.h, incident_sides): radiance[3 (2 i (+ 1))], first_prim[2 i (+
 *           1)], first_hit[3 (2 i (+ 1))], drop_marks[2 i (+ 1)]. */
#include "gradients/incident.h"

__kernel SCALAR_KERNEL void vertex_radiance(SCENE_PARAMS, __global const int* prims, __global const float* samples,
                                            __global const int* depths, __global float* radiance,
                                            __global int* first_prim, __global float* first_hit,
                                            __global uchar* drop_marks, uint seed, int count, int max_depth, float eps) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    RngKey key = rng_key(seed, (uint)i, 0u);
    __global const float* q = samples + 11 * i;
    vec3 back = v3(q[2], q[3], q[4]);
    Surface s = surface_hit(&sc, prims[i], q[0], q[1], v3_neg(back));
    Bsdf b = bsdf_at(&sc, &s);
    vec3 wi = to_local(s.sh, back);
    incident_sides(&sc, key, true, &s, &b, wi, v3(q[5], q[6], q[7]), v3(q[8], q[9], q[10]), eps, depths[i] + 1,
                   max_depth, i, radiance, first_prim, first_hit, drop_marks);
}
