/* incident.h: the radiance a surface point receives from two directions either side of an occluder's outline,
 * times its BSDF, for the soft-shadow boundary terms (incident_radiance.cl at the surfaces the camera sees,
 * vertex_radiance.cl at the later vertices of camera paths; pyclpt/gradients/shadows.py). */
#ifndef PYCLPT_GRADIENT_INCIDENT_H
#define PYCLPT_GRADIENT_INCIDENT_H

#include "integrators/path.h"

/* Sample i's two sides at surface s (found: a surface at all; bsdf b, wi the local direction towards where the path
 * came from): radiance[3 (2 i + side)] = f(wi, w -+ eps n) |cos| L_i(w -+ eps n), L_i the estimator of path.h from
 * there, its first ray at bounce `depth` (the emission it meets counted whole, as after a delta sample); 0 where
 * the direction is below the surface or `depth` allows no bounce; a NaN or inf one 0 and 1 in drop_marks; the
 * leaf-order triangle each side's ray meets first in first_prim (-1: none) and its distance and barycentrics in
 * first_hit. */
static inline void incident_sides(const Scene* sc, RngKey key, bool found, const Surface* s, const Bsdf* b, vec3 wi,
                                  vec3 w, vec3 n, float eps, int depth, int max_depth, int i,
                                  __global float* radiance, __global int* first_prim, __global float* first_hit,
                                  __global uchar* drop_marks) {
    found = found && depth_allows(depth, max_depth);
    for (int side = 0; side < 2; side++) {
        vec3 out = v3_splat(0.0f);
        int prim = -1;
        vec3 where = v3_splat(0.0f);
        if (found) {
            vec3 dir = m_normalize(v3_add(w, v3_scale(n, side == 0 ? -eps : eps)));
            vec3 wo = to_local(s->sh, dir);
            float pdf;
            vec3 f = bsdf_eval(b, wi, wo, &pdf); /* value x |cos| */
            if (m_dot(dir, s->ng) * wo.z > 0.0f && !v3_is_zero(f)) {
                PathState ps;
                ps.org = spawn_origin(s, dir);
                ps.dir = dir;
                ps.beta = v3_splat(1.0f);
                ps.L = v3_splat(0.0f);
                ps.prev_pdf = 0.0f;
                ps.eta_scale = 1.0f;
                ps.depth = depth;
                ps.flags = PATH_PREV_DELTA;
                Hit next;
                if (scene_closest(sc, key, depth, ps.org, ps.dir, &next)) {
                    prim = next.prim;
                    where = v3(next.t, next.u, next.v);
                }
                path_continue(sc, key, &ps, max_depth, aov_out(0, 0, 0));
                out = v3_mul(f, ps.L);
            }
        }
        film_commit(radiance, drop_marks, 2 * i + side, out);
        first_prim[2 * i + side] = prim;
        store3(first_hit, 2 * i + side, where);
    }
}

#endif
