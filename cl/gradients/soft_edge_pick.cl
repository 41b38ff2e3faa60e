/* soft_edge_pick: for each shading point, one edge of a mesh that is a silhouette seen from it, chosen in
 * proportion to the angle it subtends there; the search of the soft-shadow boundary term
 * (pyclpt/gradients/shadows.py, sample_soft_edges; docs/differentiable.md). One work-item per shading
 * point, one pass over the mesh's edges (a weighted reservoir of one, its single uniform number rescaled at each
 * edge, so that the loop keeps no list of angles).
 *
 * Consumes: count points, points[3 i .. 3 i + 2] (world space); u[i], uniform in [0, 1); ranges[2 i], ranges[2 i
 *           + 1]: the first of point i's edges and their number (one mesh's: every mesh's edges are in one
 *           array); edges, EDGE_STRIDE floats each: its end points a and b, then a point p and the unit normal n
 *           of its first face, of its second face, and a flag, 1 for an edge of one face (a boundary edge: a
 *           silhouette from everywhere; the second face repeats the first).
 * Produces: pick[i], the chosen edge, counted from the first of point i's (-1: no edge is a silhouette from
 *           point i, or they subtend no angle), inv_pdf[i] = the total angle of the silhouette edges over the
 *           chosen edge's (0 with pick -1).
 *
 * An edge of two faces is a silhouette from x when x lies on the front of one and the back of the other
 * (n . (x - p) > 0 for one face only); its angle is atan2(|da x db|, da . db), da and db the vectors from x to its
 * end points (atan2 needs no unit vectors; 0 where x is at an end point). The reservoir keeps edge e with
 * probability angle_e / (the angles so far): in the end, each with angle_e / total, the probability inv_pdf
 * reports (up to the rounding of the rescaled uniform, a few ulps). */
#include "core/common.h"

#define EDGE_STRIDE 20

/* The angle edge e subtends at x if it is a silhouette from x, else 0. */
static inline float edge_angle(__global const float* edges, int e, vec3 x) {
    __global const float* r = edges + EDGE_STRIDE * e;
    vec3 a = v3(r[0], r[1], r[2]), b = v3(r[3], r[4], r[5]);
    vec3 pa = v3(r[6], r[7], r[8]), na = v3(r[9], r[10], r[11]);
    vec3 pb = v3(r[12], r[13], r[14]), nb = v3(r[15], r[16], r[17]);
    bool side_a = m_dot(na, v3_sub(x, pa)) > 0.0f, side_b = m_dot(nb, v3_sub(x, pb)) > 0.0f;
    bool silhouette = r[18] > 0.5f || side_a != side_b;
    vec3 da = v3_sub(a, x), db = v3_sub(b, x);
    if (!silhouette || !(m_dot(da, da) > 0.0f) || !(m_dot(db, db) > 0.0f)) return 0.0f;
    float angle = m_atan2(m_length(m_cross(da, db)), m_dot(da, db));
    return m_isfinite(angle) ? angle : 0.0f;
}

__kernel void soft_edge_pick(__global const float* points, __global const float* u, __global const float* edges,
                             __global const int* ranges, __global int* pick, __global float* inv_pdf, int count) {
    int i = get_global_id(0);
    if (i >= count) return;
    vec3 x = load3(points, i);
    edges += EDGE_STRIDE * ranges[2 * i];
    int edge_count = ranges[2 * i + 1];
    float total = 0.0f, v = u[i], chosen_angle = 0.0f;
    int chosen = -1;
    for (int e = 0; e < edge_count; ++e) {
        float angle = edge_angle(edges, e, x);
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
    pick[i] = chosen;
    inv_pdf[i] = chosen >= 0 ? total / chosen_angle : 0.0f;
}
