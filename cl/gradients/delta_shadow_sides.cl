/* delta_shadow_sides: at a vertex of a camera path (the camera ray's first hit, or a later vertex path_vertices.cl
 * chose), the outline that a point or spot light's hard shadow draws on the surfaces it sees, through one point of
 * an occluder's edge, and what reaches the vertex either side of it: the boundary term of hard shadows after the
 * first bounce (cl/gradients/delta_sides.h; pyclpt/gradients/shadows.py, delta_sample_chunks;
 * docs/differentiable.md).
 *
 * Consumes: count samples, prims[i] the vertex's leaf-order triangle, samples[6 i ..] = its barycentrics u, v, the
 *           world direction back along the path (3; at the camera's hit, depth 0: the film position x, y of the
 *           camera ray, whose direction is found again here, and 0) and t in [0, 1) for the edge's point;
 *           depths[i] the vertex's bounce (the camera's hit: 0); edge_ids[i] the candidate edge, a row of `edges`
 *           (DELTA_EDGE_STRIDE floats: its end points and the record index of the light that sees it as a
 *           silhouette).
 * Produces: radiance[3 (2 i)] = f(wi, w - eps n) |cos| times the light's direct contribution at the surface that
 *           direction meets (its BSDF, cosine, intensity over the squared distance and visibility), w the direction
 *           to the outline's point, n the outline's unit normal on the sphere of directions; radiance[3 (2 i + 1)]
 *           the same for w + eps n; both 0 where the edge casts no outline the vertex sees, the vertex's BSDF is a
 *           delta or the depth allows no light sample there; a NaN or inf one gives 0 and adds 1 to
 *           drop_marks[2 i (+ 1)]; receiver_prim[i] the leaf-order triangle the light's ray meets behind the edge
 *           point (-1: no outline) and receiver_hit[3 i ..] its distance from just beyond the edge point and
 *           barycentrics; outline[5 i ..] the curve's measure per unit t, the distance from the vertex to the
 *           outline's point and n (3). */
#include "gradients/delta_sides.h"
#include "gradients/vertex.h"

__kernel SCALAR_KERNEL void delta_shadow_sides(SCENE_PARAMS, __global const int* prims, __global const float* samples,
                                               __global const int* depths, __global const int* edge_ids,
                                               __global const float* edges, __global float* radiance,
                                               __global int* receiver_prim, __global float* receiver_hit,
                                               __global uchar* drop_marks, __global float* outline, uint seed,
                                               int count, int max_depth, float eps) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    RngKey key = rng_key(seed, (uint)i, 0u);
    __global const float* q = samples + 6 * i;
    vec3 back = vertex_back(&sc, key, q, depths[i]);
    vec3 side[2] = {v3_splat(0.0f), v3_splat(0.0f)};
    Hit rh;
    rh.prim = -1;
    float speed = 0.0f, dist = 0.0f;
    vec3 n = v3_splat(0.0f);
    int bounce = depths[i] + 1; /* the ray from the vertex to the receiver */
    bool found = false;
    if (depth_allows(bounce + 1, max_depth)) { /* a light sample at the receiver */
        Surface s = surface_hit(&sc, prims[i], q[0], q[1], v3_neg(back));
        Bsdf b = bsdf_at(&sc, &s);
        if (!bsdf_is_delta(&b))
            found = delta_sides(&sc, key, &s, &b, to_local(s.sh, back), edges + DELTA_EDGE_STRIDE * edge_ids[i],
                                q[5], eps, bounce, &rh, &speed, &dist, &n, side);
    }
    if (!found) {
        side[0] = side[1] = n = v3_splat(0.0f);
        speed = dist = 0.0f;
        rh.prim = -1;
    }
    film_commit(radiance, drop_marks, 2 * i, side[0]);
    film_commit(radiance, drop_marks, 2 * i + 1, side[1]);
    receiver_prim[i] = rh.prim;
    store3(receiver_hit, i, found ? v3(rh.t, rh.u, rh.v) : v3_splat(0.0f));
    outline[5 * i] = speed;
    outline[5 * i + 1] = dist;
    store3(outline + 5 * i + 2, 0, n);
}
