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

/* Edges [first, first + count) of `edges`: one more pass of edge_pick's reservoir (total, chosen, its angle, the
 * rescaled uniform v). */
static inline void edge_reservoir(__global const float* edges, int first, int count, vec3 x, float xmax, float* v,
                                  float* total, int* chosen, float* chosen_angle) {
    for (int e = first; e < first + count; ++e) {
        float angle = edge_angle(edges, e, x, xmax);
        if (!(angle > 0.0f)) continue;
        *total += angle;
        float keep = angle / *total;
        if (*v < keep) {
            *chosen = e;
            *chosen_angle = angle;
            *v = *v / keep;
        } else {
            *v = (*v - keep) / (1.0f - keep);
        }
        *v = m_min(*v, 0.99999994f); /* in [0, 1) whatever the rounding (the float below 1) */
    }
}

/* The share of a still shading point's samples that pick among the moving meshes' edges (the rest pick among the
 * still meshes' edges near them, below). */
#define SOFT_MOVING_SHARE 0.75f

/* Whether the cones from x around bounding spheres s1 and s2 (centre, radius) overlap: the angle between their
 * axes at most the sum of their half-angles (x inside one: yes). */
static inline bool cones_overlap(vec3 x, __global const float* s1, __global const float* s2) {
    vec3 d1 = v3_sub(v3(s1[0], s1[1], s1[2]), x), d2 = v3_sub(v3(s2[0], s2[1], s2[2]), x);
    float l1 = m_length(d1), l2 = m_length(d2);
    if (!(l1 > s1[3]) || !(l2 > s2[3])) return true;
    float sin1 = s1[3] / l1, sin2 = s2[3] / l2;
    float cos1 = m_sqrt(1.0f - sin1 * sin1), cos2 = m_sqrt(1.0f - sin2 * sin2);
    float cos_sum = cos1 * cos2 - sin1 * sin2; /* cos of the half-angles' sum (< 0: past a right angle) */
    return cos_sum <= 0.0f || m_dot(d1, d2) >= cos_sum * l1 * l2;
}

/* The edges in blocks, one a mesh: blocks[3 k ..] = its first edge, their number and 1 if the mesh moves;
 * spheres[4 k ..] its bounding sphere. One edge that is a silhouette from x, picked in proportion to its angle
 * (uniform v in [0, 1)): its index (-1: none), and *inv_pdf = 1 / its probability (0 with -1).
 * A shading point that moves (`moves`) picks among every edge. A still one picks among the moving meshes' edges
 * with probability SOFT_MOVING_SHARE (coin below it), else among the still meshes' edges whose mesh's cone from x
 * overlaps a moving mesh's: their outline over a moving background moves relative to it (the material form). Each
 * strategy stands for its own part of the edges, so each pick is weighted by its strategy's probability alone. */
static inline int edge_pick(__global const float* edges, __global const int* blocks, __global const float* spheres,
                            int n_blocks, vec3 x, bool moves, float v, float coin, float* inv_pdf) {
    float total = 0.0f, chosen_angle = 0.0f;
    float xmax = m_max(m_max(m_abs(x.x), m_abs(x.y)), m_abs(x.z));
    int chosen = -1;
    bool moving_part = coin < SOFT_MOVING_SHARE;
    for (int k = 0; k < n_blocks; ++k) {
        bool moving = blocks[3 * k + 2] != 0;
        if (!moves) {
            if (moving != moving_part) continue;
            if (!moving) {
                bool near = false;
                for (int j = 0; j < n_blocks && !near; ++j)
                    near = blocks[3 * j + 2] != 0 && cones_overlap(x, spheres + 4 * k, spheres + 4 * j);
                if (!near) continue;
            }
        }
        edge_reservoir(edges, blocks[3 * k], blocks[3 * k + 1], x, xmax, &v, &total, &chosen, &chosen_angle);
    }
    float share = moves ? 1.0f : moving_part ? SOFT_MOVING_SHARE : 1.0f - SOFT_MOVING_SHARE;
    *inv_pdf = chosen >= 0 ? total / (chosen_angle * share) : 0.0f;
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
