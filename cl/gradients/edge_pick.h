/* edge_pick.h: for a shading point, one edge of a mesh that is a silhouette seen from it, chosen in proportion to
 * the angle it subtends there, and the point of it the boundary term crosses: the search of the soft-shadow
 * boundary term (vertex_radiance.cl; pyclpt/gradients/shadows.py, sample_soft_edges;
 * docs/differentiable.md). One pass over the mesh's edges (a weighted reservoir of one, its single uniform number
 * rescaled at each edge, so that the loop keeps no list of angles).
 *
 * The edges: EDGE_STRIDE floats each, one cache line (shadows.EDGE_STRIDE, MeshEdges.records): its end points a
 * and b, then the unit normal n of its first face and n . p for a point p of that face, the same for its second
 * face, a flag, 1 for an edge of one face (a boundary edge: a silhouette from everywhere; the second face repeats
 * the first), and the index of its mesh.
 *
 * An edge of two faces is a silhouette from x when x lies on the front of one and the back of the other
 * (n . x > n . p for one face only); its angle is atan2(|da x db|, da . db), da and db the vectors from x to its
 * end points (atan2 needs no unit vectors; 0 where x is at an end point). The reservoir keeps edge e with
 * probability angle_e / (the angles so far): in the end, each with angle_e / total, the probability the pick
 * reports (up to the rounding of the rescaled uniform, a few ulps). */
#ifndef PYCLPT_GRADIENT_EDGE_PICK_H
#define PYCLPT_GRADIENT_EDGE_PICK_H

#include "core/common.h"

#define EDGE_STRIDE 16

/* The index of edge e's mesh. */
static inline int edge_mesh(__global const float* edges, int e) { return (int)edges[EDGE_STRIDE * e + 15]; }

/* The relative tolerance of x's side of a face's plane (edge_plane_offset): nearer, x lies in the plane (a point of
 * the face itself, or of a face of the same plane, rounded), from where the edge is seen edge-on. */
#define EDGE_PLANE_TOL 1e-5f

/* x's signed offset from the plane (n, n . p) at r[0 .. 3], and whether it is off the plane: beyond
 * tol (|n . p| + scale), scale the largest of |x|'s coordinates (and what else sets the rounding). */
static inline float edge_plane_offset(__global const float* r, vec3 x, float tol, float scale, bool* off) {
    float h = r[0] * x.x + r[1] * x.y + r[2] * x.z - r[3];
    *off = m_abs(h) > tol * (m_abs(r[3]) + scale);
    return h;
}

/* The angle edge e subtends at x if it is a silhouette from x, else 0. A mesh's outlines on itself count (a fold
 * shadowing the rest of its mesh): only an edge one of whose faces' planes holds x (the edges of x's own triangle)
 * is left out. (From a point on a convex mesh no edge of it is a silhouette: the point is behind its other faces.) */
static inline float edge_angle(__global const float* edges, int e, vec3 x, float xmax) {
    __global const float* r = edges + EDGE_STRIDE * e;
    bool off_a, off_b;
    bool side_a = edge_plane_offset(r + 6, x, EDGE_PLANE_TOL, xmax, &off_a) > 0.0f;
    bool side_b = edge_plane_offset(r + 10, x, EDGE_PLANE_TOL, xmax, &off_b) > 0.0f;
    if (!off_a || !off_b) return 0.0f; /* x in a face's plane: the edge edge-on */
    if (!(r[14] > 0.5f || side_a != side_b)) return 0.0f; /* not a silhouette from x */
    vec3 da = v3_sub(v3(r[0], r[1], r[2]), x), db = v3_sub(v3(r[3], r[4], r[5]), x);
    if (!(m_dot(da, da) > 0.0f) || !(m_dot(db, db) > 0.0f)) return 0.0f;
    float angle = m_atan2(m_length(m_cross(da, db)), m_dot(da, db));
    return m_isfinite(angle) ? angle : 0.0f;
}

/* Among edges [0, count) of `edges`, one that is a silhouette from x, with probability its angle over their total
 * (uniform v in [0, 1)): its index (-1: none is, or they subtend no angle), and *inv_pdf = the total over its
 * angle (0 with -1). */
static inline int edge_pick(__global const float* edges, int count, vec3 x, float v, float* inv_pdf) {
    float total = 0.0f, chosen_angle = 0.0f;
    float xmax = m_max(m_max(m_abs(x.x), m_abs(x.y)), m_abs(x.z));
    int chosen = -1;
    for (int e = 0; e < count; ++e) {
        float angle = edge_angle(edges, e, x, xmax);
        if (!(angle > 0.0f)) continue;
        total += angle;
        float keep = angle / total;
        if (v < keep) {
            chosen = e;
            chosen_angle = angle;
            v = v / keep;
        } else {
            v = (v - keep) / (1.0f - keep);
        }
        v = m_min(v, 0.99999994f); /* in [0, 1) whatever the rounding (the float below 1) */
    }
    *inv_pdf = chosen >= 0 ? total / chosen_angle : 0.0f;
    return chosen;
}

/* The point e = a + t (b - a) of edge `e` seen from x: the unit direction *w to it, its distance *dist, the unit
 * normal *n of the outline on the sphere of directions (w x dw/dt, dw/dt = ((b - a) - w (w . (b - a))) / |e - x|)
 * and the outline's speed |w x dw/dt| (the measure of the curve per unit t; 0: degenerate). */
static inline float edge_point(__global const float* edges, int e, vec3 x, float t, vec3* w, float* dist, vec3* n) {
    __global const float* r = edges + EDGE_STRIDE * e;
    vec3 a = v3(r[0], r[1], r[2]), ab = v3_sub(v3(r[3], r[4], r[5]), a);
    vec3 d = v3_sub(v3_add(a, v3_scale(ab, t)), x);
    *dist = m_length(d);
    *w = v3_divs(d, *dist);
    vec3 dw_dt = v3_divs(v3_sub(ab, v3_scale(*w, m_dot(*w, ab))), *dist);
    vec3 c = m_cross(*w, dw_dt);
    float speed = m_length(c);
    *n = speed > 0.0f ? v3_divs(c, speed) : v3_splat(0.0f);
    return m_isfinite(speed) && *dist > 0.0f ? speed : 0.0f;
}

#endif
