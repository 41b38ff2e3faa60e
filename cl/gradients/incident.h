/* incident.h: the radiance a surface point receives from two directions either side of an occluder's outline,
 * times its BSDF, for the soft-shadow boundary terms (vertex_radiance.cl at the vertices of camera paths;
 * pyclpt/gradients/shadows.py). */
#ifndef PYCLPT_GRADIENT_INCIDENT_H
#define PYCLPT_GRADIENT_INCIDENT_H

#include "gradients/edge_pick.h"
#include "integrators/path.h"

/* The candidate edges of the soft-shadow term and what moves: the records (edge_pick.h) in blocks, one a mesh
 * (edge_pick's blocks, spheres, n_blocks), the meshes' packed vertex ranges (mesh_vertices[j], [j + 1]) and
 * whether each moves (mesh_moving[j]). */
typedef struct {
    __global const float* edges;
    __global const int* blocks;
    __global const float* spheres;
    int n_blocks;
    __global const int* mesh_vertices;
    __global const int* mesh_moving;
    int n_meshes;
} EdgeSet;

/* The mesh whose packed vertex range holds vertex k (a binary search of mesh_vertices). */
static inline int mesh_of_vertex(const EdgeSet* set, int k) {
    int lo = 0, hi = set->n_meshes; /* mesh_vertices[lo] <= k < mesh_vertices[hi] */
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (set->mesh_vertices[mid] <= k) lo = mid;
        else hi = mid;
    }
    return lo;
}

/* first_prim of the side whose ray meets the occluder at the edge (side_on_occluder): not traced. */
#define SIDE_OCCLUDER (-2)
/* The relative tolerance of a side's first hit in the plane of one of the edge's faces (edge_plane_offset's, at
 * the hit point, whose distance adds to the scale). */
#define SIDE_PLANE_TOL 1e-4f

/* One side's direction from surface s, f(wi, wo) |cos| there (0: below the surface) and its ray's first hit. */
typedef struct {
    vec3 dir, f;
    Hit hit;
    bool found;
} SideStart;

static inline SideStart side_start(const Scene* sc, RngKey key, const Surface* s, const Bsdf* b, vec3 wi, vec3 w,
                                   vec3 n, float eps, int depth) {
    SideStart st;
    st.dir = m_normalize(v3_add(w, v3_scale(n, eps)));
    vec3 wo = to_local(s->sh, st.dir);
    float pdf;
    st.f = bsdf_eval(b, wi, wo, &pdf); /* value x |cos| */
    st.found = false;
    st.hit.prim = -1;
    if (m_dot(st.dir, s->ng) * wo.z > 0.0f && !v3_is_zero(st.f))
        st.found = scene_closest(sc, key, depth, spawn_origin(s, st.dir), st.dir, &st.hit);
    else
        st.f = v3_splat(0.0f);
    return st;
}

/* Whether a side's ray met the occluder at the edge first: its first hit is a triangle of the occluder (its
 * vertices in the occluder's packed range [lo, hi)) in the plane of one of the edge's two faces (the record r,
 * edge_pick.h). Only the side that meets the edge's faces does: the other passes the edge, and a ray meets a
 * plane once, where it passes, so whatever it meets beyond, the occluder's other parts included (a concave
 * occluder, a mesh shadowing itself), is off those planes. */
static inline bool side_on_occluder(const Scene* sc, const Surface* s, const SideStart* st,
                                    __global const float* r, float dist, int lo, int hi) {
    if (!st->found) return false;
    int k = sc->tri_vidx[3 * st->hit.prim];
    if (k < lo || k >= hi) return false;
    vec3 p = v3_add(spawn_origin(s, st->dir), v3_scale(st->dir, st->hit.t));
    float scale = m_max(m_max(m_abs(p.x), m_abs(p.y)), m_abs(p.z)) + dist;
    bool off_a, off_b;
    (void)edge_plane_offset(r + 6, p, SIDE_PLANE_TOL, scale, &off_a);
    (void)edge_plane_offset(r + 10, p, SIDE_PLANE_TOL, scale, &off_b);
    return !off_a || !off_b;
}

/* f |cos| L_i along a side's direction: L_i the estimator of path.h from s, its first ray at bounce `depth`. */
static inline vec3 side_radiance(const Scene* sc, RngKey key, const Surface* s, const SideStart* st, int depth,
                                 int max_depth) {
    if (v3_is_zero(st->f)) return v3_splat(0.0f);
    PathState ps;
    ps.org = spawn_origin(s, st->dir);
    ps.dir = st->dir;
    ps.beta = v3_splat(1.0f);
    ps.L = v3_splat(0.0f);
    ps.prev_pdf = 0.0f;
    ps.rr_scale = 1.0f;
    ps.depth = depth;
    ps.flags = PATH_PREV_DELTA;
    path_continue_from(sc, key, &ps, max_depth, aov_out(0, 0, 0), st->found ? &st->hit : 0);
    return v3_mul(st->f, ps.L);
}

static inline void side_store(__global float* radiance, __global int* first_prim, __global float* first_hit,
                              __global uchar* drop_marks, int f, const SideStart* st, bool occluder, vec3 out) {
    film_commit(radiance, drop_marks, f, out);
    first_prim[f] = occluder ? SIDE_OCCLUDER : st->found ? st->hit.prim : -1;
    store3(first_hit, f, st->found ? v3(st->hit.t, st->hit.u, st->hit.v) : v3_splat(0.0f));
}

/* Sample i at surface s (bsdf b, wi the local direction towards where the path came from; `moves`: whether s moves
 * with what is differentiated): an edge of `set` (edge_pick.h: picked with uniforms u and coin), and its point at
 * t; its mesh, the occluder, has packed vertices [mesh_vertices[j], mesh_vertices[j + 1]); two directions
 * w -+ eps n either side of the outline
 * there; radiance[3 (2 i + side)] = f(wi, w -+ eps n) |cos| L_i(w -+ eps n), L_i the estimator of path.h from
 * there, its first ray at bounce `depth` (the emission it meets counted whole, as after a delta sample); 0 where the
 * direction is below the surface or `depth` allows no bounce; a NaN or inf one 0 and 1 in drop_marks; the
 * leaf-order triangle each side's ray meets first in first_prim (-1: none; SIDE_OCCLUDER: the side that meets the
 * edge's faces, below) and its distance and barycentrics in first_hit; pick[i] the edge (-1: none, the sides 0)
 * and outline[5 i ..] the outline's measure per sample (its speed over the pick's probability), the distance to
 * the edge point and the outline's unit normal n (3).
 * The boundary term takes the material form, in which the side
 * whose ray meets the occluder at the edge first has no jump (the occluder's points stay in its area integral), so
 * its path is not traced and its radiance is 0; and unless exactly one side meets it, the edge is no outline of
 * it from s (something nearer hides it, or both sides pass it): as eps -> 0 both sides' light is the same, so
 * neither path is traced and both are 0 (the host drops samples without a jump); nor where neither s, the
 * occluder nor what the passing side meets first moves (the outline stays where it is on that background). */
static inline void incident_sides(const Scene* sc, RngKey key, const Surface* s, const Bsdf* b, vec3 wi,
                                  const EdgeSet* set, bool moves, float u, float coin, float t, float eps, int depth,
                                  int max_depth, int i, __global float* radiance,
                                  __global int* first_prim, __global float* first_hit, __global uchar* drop_marks,
                                  __global int* pick, __global float* outline) {
    __global const float* edges = set->edges;
    __global const int* mesh_vertices = set->mesh_vertices;
    SideStart minus, plus;
    minus.found = plus.found = false;
    vec3 out_minus = v3_splat(0.0f), out_plus = v3_splat(0.0f), w, n = v3_splat(0.0f);
    float inv_pdf = 0.0f, dist = 0.0f, speed = 0.0f;
    bool on_minus = false, on_plus = false;
    int e = depth_allows(depth, max_depth)
                ? edge_pick(edges, set->blocks, set->spheres, set->n_blocks, s->p, moves, u, coin, &inv_pdf)
                : -1;
    if (e >= 0) speed = edge_point(edges, e, s->p, t, &w, &dist, &n);
    if (!(speed > 0.0f)) e = -1;
    if (e >= 0) {
        minus = side_start(sc, key, s, b, wi, w, n, -eps, depth);
        plus = side_start(sc, key, s, b, wi, w, n, eps, depth);
        __global const float* r = edges + EDGE_STRIDE * e;
        int j = edge_mesh(edges, e), lo = mesh_vertices[j], hi = mesh_vertices[j + 1];
        on_minus = side_on_occluder(sc, s, &minus, r, dist, lo, hi);
        on_plus = side_on_occluder(sc, s, &plus, r, dist, lo, hi);
        /* a still point, a still occluder and a still background: nothing moves there, nothing to trace */
        const SideStart* passing = on_plus ? &minus : &plus;
        bool still = !moves && !set->mesh_moving[j] &&
                     !(passing->found && set->mesh_moving[mesh_of_vertex(set, sc->tri_vidx[3 * passing->hit.prim])]);
        if (on_minus != on_plus && !still) {
            if (on_plus) out_minus = side_radiance(sc, key, s, &minus, depth, max_depth);
            else out_plus = side_radiance(sc, key, s, &plus, depth, max_depth);
        }
    }
    side_store(radiance, first_prim, first_hit, drop_marks, 2 * i, &minus, on_minus, out_minus);
    side_store(radiance, first_prim, first_hit, drop_marks, 2 * i + 1, &plus, on_plus, out_plus);
    pick[i] = e;
    outline[5 * i] = e >= 0 ? speed * inv_pdf : 0.0f;
    outline[5 * i + 1] = dist;
    store3(outline + 5 * i + 2, 0, n);
}

#endif
