/* path_vertices: one later vertex of each camera path, for the soft-shadow boundary term of the light the
 * surfaces receive after the first bounce (pyclpt/gradients/shadows.py, sample_soft_edges; docs/differentiable.md).
 *
 * Consumes: count film positions, film[2 i], film[2 i + 1] (pixels from the image's top-left corner).
 * Produces: for path i (the camera ray through film position i, continued by BSDF sampling with the random numbers of
 *           key (seed, i, 0) as path.h's estimator continues it, Russian roulette included): of its vertices after
 *           the camera's hit that were reached by a non-delta sample, whose BSDF is not delta-only and from which
 *           the depth allows a bounce, one chosen uniformly: vertex_prim[i] its leaf-order triangle (-1: none),
 *           vertex[8 i ..] its barycentrics u, v, the world direction back along the path (3), the throughput that
 *           reached it (3: the estimator's beta, f |cos| / pdf of the bounces before and 1 / q of the roulette) times
 *           the number of such vertices (1 / the probability of the choice); vertex_depth[i] its bounce (the
 *           camera's hit: 0); first_prim[i] the leaf-order triangle the camera ray meets (-1: none) and first_hit[3
 *           i ..] its distance and barycentrics there (the shading points of the first bounce).
 *
 * The chosen vertex is attached to its surface (the interior term's material form, cl/gradients/geometry.h): the
 * outlines of occluders in the light it receives, as its surface, the occluders and the surfaces behind them move,
 * are the boundary term of its incident integral, weighted by that throughput. */
#include "integrators/path.h"

/* DIM_VERTEX_CHOICE (core/rng.h): the reservoir's numbers, a dimension of each bounce that path.h never draws */

__kernel SCALAR_KERNEL void path_vertices(SCENE_PARAMS, __global const float* film, __global int* vertex_prim,
                                          __global float* vertex, __global int* vertex_depth,
                                          __global int* first_prim, __global float* first_hit, uint seed, int count,
                                          int max_depth) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    RngKey key = rng_key(seed, (uint)i, 0u);
    PathState ps;
    camera_ray(&sc, key, film[2 * i], film[2 * i + 1], &ps);
    int chosen = -1, depth = 0, seen = 0;
    float cu = 0.0f, cv = 0.0f;
    first_prim[i] = -1;
    store3(first_hit, i, v3_splat(0.0f));
    vec3 cdir = v3_splat(0.0f), cbeta = v3_splat(0.0f);
    while (depth_allows(ps.depth, max_depth)) {
        Hit hit;
        if (!scene_closest(&sc, key, ps.depth, ps.org, ps.dir, &hit)) break;
        if (ps.depth == 0) {
            first_prim[i] = hit.prim;
            store3(first_hit, i, v3(hit.t, hit.u, hit.v));
        }
        Surface s = surface_hit(&sc, hit.prim, hit.u, hit.v, ps.dir);
        Bsdf b = bsdf_at(&sc, &s);
        bool later = ps.depth > 0 && !(ps.flags & PATH_PREV_DELTA);
        if (later && !bsdf_is_delta(&b) && depth_allows(ps.depth + 1, max_depth)) {
            seen += 1; /* a reservoir of one: the k-th such vertex replaces the kept one with probability 1 / k */
            if (rng_1d(key, ps.depth, DIM_VERTEX_CHOICE) * (float)seen < 1.0f) {
                chosen = hit.prim;
                cu = hit.u;
                cv = hit.v;
                cdir = v3_neg(ps.dir);
                cbeta = ps.beta;
                depth = ps.depth;
            }
        }
        if (!path_sample_bsdf(key, &s, &b, &ps, max_depth)) break;
    }
    vertex_prim[i] = chosen;
    vertex_depth[i] = depth;
    __global float* v = vertex + 8 * i;
    v[0] = cu;
    v[1] = cv;
    v[2] = cdir.x;
    v[3] = cdir.y;
    v[4] = cdir.z;
    v[5] = cbeta.x * (float)seen;
    v[6] = cbeta.y * (float)seen;
    v[7] = cbeta.z * (float)seen;
}
