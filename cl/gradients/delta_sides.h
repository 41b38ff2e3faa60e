/* delta_sides.h: the outline a point, spot or directional light's hard shadow draws on a surface, seen from a
 * vertex of a camera path, and what reaches the vertex either side of it: the boundary term of hard shadows after
 * the first bounce (delta_shadow_sides.cl; pyclpt/gradients/shadows.py, delta_sample_chunks;
 * docs/differentiable.md).
 *
 * An occluder's edge that the light sees as a silhouette casts the outline: the light's ray through the edge's
 * point q goes on to the first surface behind it, at r. From a vertex y that sees r, the outline is a curve on
 * y's sphere of directions through w = (r - y) / |r - y|; as q slides along the edge (q = a + t (b - a)), r
 * slides along the receiver's plane, dr/dt = sigma P (b - a) (sigma = |r - l| / |q - l|, 1 for a directional
 * light's parallel rays; P projecting along the light's ray onto the plane of normal n_r:
 * P v = v - d (n_r . v) / (n_r . d)), and w by dw/dt = (dr/dt - w (w . dr/dt)) / |r - y|. The curve's measure
 * per unit t is |w x dw/dt| and its unit normal n = w x dw/dt / |w x dw/dt|. Either side, w -+ eps n, the
 * vertex's BSDF and cosine times the light's direct contribution at the surface that side's ray meets (its BSDF,
 * cosine, the light's intensity over the squared distance or a directional light's irradiance, and its
 * visibility): one side lit, the other in the shadow. */
#ifndef PYCLPT_GRADIENT_DELTA_SIDES_H
#define PYCLPT_GRADIENT_DELTA_SIDES_H

#include "integrators/path.h"

/* The candidate edges: DELTA_EDGE_STRIDE floats each, its end points a and b, the record index of the light
 * that sees it as a silhouette (int bits) and, for a directional light, how far behind an edge point its ray may
 * start, outside the scene (pyclpt/gradients/shadows.py, DELTA_EDGE_STRIDE). */
#define DELTA_EDGE_STRIDE 8
/* The relative offsets of the rays: the lit test stops this far short of the edge point, the receiver ray starts
 * this far beyond it (shadows.RAY_EPS), the vertex's view of the receiver point may end this far short. */
#define DELTA_RAY_EPS 1e-4f
#define DELTA_VIEW_EPS 1e-3f

/* The light `light`'s direct contribution along -dir at the surface the ray (org, dir) meets first, times its
 * BSDF and cosine: f(-dir, wl) |cos| I / |l - p|^2 V(p, l); 0 where the ray meets nothing, a delta BSDF or the
 * back of the surface as the light sees it. */
static inline vec3 delta_side_light(const Scene* sc, RngKey key, int bounce, vec3 org, vec3 dir, int light) {
    Hit h;
    if (!scene_closest(sc, key, bounce, org, dir, &h)) return v3_splat(0.0f);
    Surface s = surface_hit(sc, h.prim, h.u, h.v, dir);
    Bsdf b = bsdf_at(sc, &s);
    if (bsdf_is_delta(&b)) return v3_splat(0.0f);
    LightSample ls;
    if (!light_sample_id(sc, light, s.p, v2(0.0f, 0.0f), &ls)) return v3_splat(0.0f);
    vec3 wo = to_local(s.sh, ls.wi);
    if (m_dot(ls.wi, s.ng) * wo.z <= 0.0f) return v3_splat(0.0f);
    float pdf;
    vec3 f = bsdf_eval(&b, to_local(s.sh, v3_neg(dir)), wo, &pdf);
    if (v3_is_zero(f)) return v3_splat(0.0f);
    vec3 o = spawn_origin(&s, ls.wi);
    float tmax = ls.dist * (1.0f - DELTA_RAY_EPS) - m_length(v3_sub(o, s.p));
    if (!(tmax > 0.0f) || scene_occluded(sc, key, bounce + 1, o, ls.wi, tmax)) return v3_splat(0.0f);
    return v3_mul(f, ls.radiance);
}

/* The outline from vertex s (bsdf b, wi the local direction back along the path; its ray to r at bounce
 * `bounce`) of candidate edge `edge` at parameter t: false when it casts none that s sees (the light does not
 * reach the edge point, nothing is behind it, s does not see the receiver point); else *r_hit the receiver ray's
 * hit (its distance from the start just beyond the edge point), *speed the curve's measure per unit t, *dist
 * |r - y|, *n the curve's unit normal, and side[0], side[1] f(wi, w -+ eps n) |cos| times the light's direct
 * contribution there (delta_side_light). */
static inline bool delta_sides(const Scene* sc, RngKey key, const Surface* s, const Bsdf* b, vec3 wi,
                               __global const float* edge, float t, float eps, int bounce, Hit* r_hit,
                               float* speed, float* dist, vec3* n, vec3* side) {
    int light = as_int(edge[6]);
    vec3 a = v3(edge[0], edge[1], edge[2]), ab = v3_sub(v3(edge[3], edge[4], edge[5]), a);
    vec3 q = v3_add(a, v3_scale(ab, t));
    LightSample ls;
    if (!light_sample_id(sc, light, q, v2(0.0f, 0.0f), &ls) || !(ls.dist > 0.0f)) return false;
    bool parallel = m_isinf(ls.dist); /* a directional light: its rays from a point behind q, outside the scene */
    if (parallel) ls.dist = edge[7];
    vec3 d = v3_neg(ls.wi), l = v3_add(q, v3_scale(ls.wi, ls.dist));
    /* lit through the edge: nothing between the light and the edge point */
    if (scene_occluded(sc, key, bounce, l, d, ls.dist * (1.0f - DELTA_RAY_EPS))) return false;
    vec3 start = v3_add(q, v3_scale(d, DELTA_RAY_EPS * ls.dist));
    if (!scene_closest(sc, key, bounce, start, d, r_hit)) return false;
    vec3 r = v3_add(start, v3_scale(d, r_hit->t));
    Surface sr = surface_hit(sc, r_hit->prim, r_hit->u, r_hit->v, d);
    float dn = m_dot(d, sr.ng);
    if (!(m_abs(dn) > 1e-6f)) return false;
    vec3 yr = v3_sub(r, s->p);
    *dist = m_length(yr);
    if (!(*dist > 0.0f)) return false;
    vec3 w = v3_divs(yr, *dist);
    /* seen from s: in front of its surface, nothing between */
    vec3 o = spawn_origin(s, w);
    float tmax = *dist * (1.0f - DELTA_VIEW_EPS) - m_length(v3_sub(o, s->p));
    if (!(tmax > 0.0f) || scene_occluded(sc, key, bounce, o, w, tmax)) return false;
    float sigma = parallel ? 1.0f : m_length(v3_sub(r, l)) / ls.dist;
    vec3 dr_dt = v3_scale(v3_sub(ab, v3_scale(d, m_dot(sr.ng, ab) / dn)), sigma);
    vec3 dw_dt = v3_divs(v3_sub(dr_dt, v3_scale(w, m_dot(w, dr_dt))), *dist);
    vec3 c = m_cross(w, dw_dt);
    *speed = m_length(c);
    if (!(*speed > 0.0f) || !m_isfinite(*speed)) return false;
    *n = v3_divs(c, *speed);
    for (int k = 0; k < 2; ++k) {
        vec3 dir = m_normalize(v3_add(w, v3_scale(*n, k == 0 ? -eps : eps)));
        vec3 wo = to_local(s->sh, dir);
        float pdf;
        vec3 f = bsdf_eval(b, wi, wo, &pdf);
        side[k] = m_dot(dir, s->ng) * wo.z > 0.0f && !v3_is_zero(f)
                      ? v3_mul(f, delta_side_light(sc, key, bounce, spawn_origin(s, dir), dir, light))
                      : v3_splat(0.0f);
    }
    return true;
}

#endif
