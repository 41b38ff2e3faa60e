/* vertex_radiance: at a vertex of a camera path (the camera ray's first hit, or a later vertex path_vertices.cl
 * chose), one edge of an occluder that is a silhouette from it, picked in proportion to the angle it subtends, and
 * the radiance reaching the vertex from two directions either side of the outline there, times the BSDF: the
 * boundary term of soft shadows and of every occluder's outline in the incident light (pyclpt/gradients/shadows.py,
 * sample_soft_edges; docs/differentiable.md).
 *
 * Consumes: count samples, prims[i] the vertex's leaf-order triangle, samples[8 i ..] = its barycentrics u, v, the
 *           world direction back along the path (3; at the camera's hit, depth 0: the film position x, y of the
 *           camera ray, whose direction is found again here, and 0), a uniform for the edge's pick, t in [0, 1)
 *           for its point and a uniform for the pick's strategy;
 *           depths[i] the vertex's bounce (the camera's hit: 0); moves[i] 1 if the vertex moves with what is
 *           differentiated; `edges` (every mesh's records, cl/gradients/edge_pick.h) in n_blocks blocks, one a
 *           mesh: blocks[3 k ..] its first edge, their number, 1 if the mesh moves, spheres[4 k ..] its bounding
 *           sphere (the vertex's own mesh among them: a mesh's outlines on itself); mesh_vertices[j], [j + 1]:
 *           the packed vertex range of mesh j, mesh_moving[j] 1 if it moves (n_meshes meshes).
 * Produces: pick[i] the edge, counted from the sample's first, picked in proportion to the angle it subtends among
 *           those that are silhouettes from the vertex (-1: none), the occluder its mesh; outline[5 i ..] the
 *           outline's measure per sample, the distance to the edge point and the outline's unit normal n (3);
 *           radiance[3 (2 i)] = f(wi, w - eps n) |cos| L_i(w - eps n),
 *           w the direction to the edge's point at t, radiance[3 (2 i + 1)] the same for w + eps n: L_i the
 *           estimator of path.h from there, its first ray at bounce depths[i] + 1 (both sides with the random numbers
 *           of key (seed, i, 0); the emission it meets counted whole, as after a delta sample); 0 for the side that
 *           meets the occluder at the edge first (untraced), for both unless exactly one side meets it, where the
 *           direction is below the surface or the depth allows no bounce; a NaN or inf one gives 0 and adds 1 to
 *           drop_marks[2 i (+ 1)]; first_prim[2 i (+ 1)] the leaf-order triangle that side's ray meets first (-1:
 *           none; -2, SIDE_OCCLUDER: the occluder at the edge) and first_hit[3 (2 i (+ 1))] its distance and
 *           barycentrics there: what lies behind the outline on the side that passes it (cl/gradients/incident.h,
 *           incident_sides). */
#include "gradients/incident.h"
#include "gradients/vertex.h"

__kernel SCALAR_KERNEL void vertex_radiance(SCENE_PARAMS, __global const int* prims, __global const float* samples,
                                            __global const int* depths, __global const int* moves,
                                            __global const float* edges, __global const int* blocks,
                                            __global const float* spheres, __global const int* mesh_vertices,
                                            __global const int* mesh_moving, __global float* radiance,
                                            __global int* first_prim, __global float* first_hit,
                                            __global uchar* drop_marks, __global int* pick,
                                            __global float* outline, uint seed, int count, int max_depth, float eps,
                                            int n_blocks, int n_meshes) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    RngKey key = rng_key(seed, (uint)i, 0u);
    __global const float* q = samples + 8 * i;
    vec3 back = vertex_back(&sc, key, q, depths[i]);
    Surface s = surface_hit(&sc, prims[i], q[0], q[1], v3_neg(back));
    Bsdf b = bsdf_at(&sc, &s);
    vec3 wi = to_local(s.sh, back);
    EdgeSet set = {edges, blocks, spheres, n_blocks, mesh_vertices, mesh_moving, n_meshes};
    incident_sides(&sc, key, &s, &b, wi, &set, moves[i] != 0, q[5], q[7], q[6], eps, depths[i] + 1, max_depth, i,
                   radiance, first_prim, first_hit, drop_marks, pick, outline);
}
