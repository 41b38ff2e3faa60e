/* geometry.h: the interior term of moving geometry, for the gradient kernels (-DGRAD_GEOMETRY).
 *
 * The material form of the path integral (Zhang, Miller, Yan, Gkioulekas and Zhao 2020, "Path-space
 * differentiable rendering"): a path is a chain of points, each attached to the surface it lies on, so that
 * when the surfaces move the points move with them and what changes is the integrand of the area form:
 *   the BSDF values (f |cos| at each vertex, through its two directions and its normal's frame),
 *   the other end's cosine and the 1/r^2 of every segment sampled from a BSDF or a light,
 *   the area Jacobian of each attached point (a triangle that grows spreads its points out).
 * The sampling densities and MIS weights are held fixed (detached), as in prb: their derivatives sum to zero
 * over the strategies when all are expressed in area measure. What is not an area-measure point:
 *   the first hit slides along its camera ray (the pixel integral is over the film), and so does a point
 *   reached by a delta (smooth specular) lobe, along its ray; a smooth conductor's vertex (a mirror) reached along
 *   such a ray slides along it too and reflects it, and the next hit slides along the reflected ray, which moves
 *   with the mirror's point and normal and the incoming ray ("a moving planar (or smooth-shaded) mirror" below:
 *   one mirror at a time); any other vertex of a delta-only material (glass, a second mirror in a row, a mirror
 *   reached after a rough bounce) is held still, and so is a direction to the environment or a directional light
 *   (a point at infinity).
 * A point on triangle T with barycentrics b moves as sum_j b_j dv_j (attached), or along its ray d as
 * d (n . dp) / (n . d) (sliding); the triangle's unit normal and area follow its vertices' motion.
 *
 * Reverse mode (backward.cl's replay, where the path's radiance L is known): the factors of a segment carry
 * everything gathered after it (L - G, the radiance gathered after the segment's first vertex), the factors of a
 * light sample its contribution; their log-derivatives, weighted by dLoss/dL, give adjoints of the points'
 * positions, normals and area Jacobians (GeoVertex), scattered when no later factor needs the vertex into
 * grad_verts (3 floats per vertex of the scene's packed vertex arrays) and grad_lightpos (GEO_LIGHT_STRIDE floats
 * per light record: a point or spot light's position, a spot light's axis). Forward mode (forward.cl): the tangents of the same quantities from the
 * tangent buffers of the same layout, and the log-derivatives added to the throughput's tangent.
 *
 * BSDF values are differentiated with respect to their two local directions in closed form for diffuse ones,
 * by central differences of bsdf_eval for the others (GEO_FD_STEP, the directions renormalised), a coordinate whose two evaluations straddle the
 * support's edge (one zero, one not) left out; the frame follows the shading normal by the smallest rotation
 * (isotropic BSDFs do not see the twist). The shading normal is the triangle's (flat shading) or, on a triangle
 * with vertex normals (TRI_HAS_NORMALS), ns = m / |m|, m = sum b_j n_j, which moves with the vertex normals n_j
 * (their adjoints go to grad_vnormals, 3 floats per vertex, their tangents come from the tangent buffer of that
 * name; the host chains them to the positions through the normals update() computes) and, for a sliding point,
 * with its barycentrics: the point moves over its triangle by D = dx - sum b_j dv_j (in the plane), so
 * db1 = D . (e2 x n) / |e1 x e2| and db2 = D . (n x e1) / |e1 x e2|. The area-form cosines keep the triangle's
 * normal. A sliding point's texture coordinates move with its barycentrics too (geo_bsdf_bary: bilinear
 * bitmaps; the host refuses textures whose value jumps). The host refuses bump maps and anisotropic frames on a
 * moving mesh (pyclpt/gradients/). */
#ifndef PYCLPT_GRADIENT_GEOMETRY_H
#define PYCLPT_GRADIENT_GEOMETRY_H

#include "gradients/params.h"

/* Instanced scenes (-DSCENE_HAS_INSTANCES): a hit's prim is the packed id of scene/instances.h; a GeoVertex keeps
 * its leaf-order triangle (id) and its instance record (rec; -1: the identity, an emitter's triangle), and every
 * triangle quantity is taken to world space through the record: the vertices x by A x + t (A, t: the record's
 * object-to-world), edges by A, vertex normals by N = A^-T (unnormalised: the shading normal N m / |N m| is
 * surface_at's). The world adjoints of a triangle's vertices (g_j) and vertex normals (h_j) go back to object space
 * (A^T g_j to grad_verts, N^T h_j to grad_vnormals: the shapegroup's meshes, summed over its instances; the plain
 * meshes' record is the identity) and, with -DGRAD_INSTANCES (an instance's to_world differentiated), to the
 * record's 12 floats of grad_inst (GEO_INST_STRIDE: the columns of A, then t): x moves by dA x + dt, so
 * dA += g_j x_j^T, dt += g_j; N n moves by -N dA^T (N n), so dA -= (N n_j) (N^T h_j)^T. Forward mode reads the
 * same 12 floats as dA, dt. A mirroring record (det A < 0) turns surface_at's geometric normal against the world
 * edges' cross product: geo_flip. */
#define GEO_INST_STRIDE 12

#define GEO_FD_STEP 1e-3f

#define GEO_FIXED 0    /* does not move (the camera, a delta-only vertex held still, no vertex) */
#define GEO_ATTACHED 1 /* attached to its triangle by its barycentrics */
#define GEO_SLIDING 2  /* on a ray (the camera's, a delta lobe's, a moving mirror's), where it meets its triangle */
#define GEO_POINT 3    /* a point or spot light's position */

/* grad_lightpos / the tangent's lightpos: per light record, its position (3 floats) and a spot light's axis (3) */
#define GEO_LIGHT_STRIDE 6

typedef struct {
    vec3 p;     /* position */
    vec3 n;     /* its triangle's unit normal (winding order) */
    vec3 d;     /* GEO_SLIDING: the ray's direction */
    float b1, b2; /* barycentrics (u, v) on the triangle */
    int kind;   /* GEO_* */
    int id;     /* leaf-order triangle, or the light record of a GEO_POINT */
    int rec;    /* instanced scenes: the triangle's instance record (-1: none, the identity) */
    vec3 gx, gn, gs; /* reverse mode: the adjoints of the position, the triangle's normal, the shading normal */
    float gj;   /*               and of the log of the area Jacobian */
    vec3 dx, dn, ds; /* forward mode: their tangents */
    float dj;
    float gb1, gb2; /* reverse mode: the adjoints of a sliding point's barycentrics through its textures */
    float db1, db2; /* forward mode: a sliding point's barycentrics' tangents (geo_shading_motion) */
    int camera;   /* -DGRAD_CAMERA: the camera ray's hit, t from the camera at film coordinates (sx, sy) */
    float t, sx, sy;
    vec3 gwi, dd; /* the adjoint (reverse) or tangent (forward, dd = -d wi) of its ray's direction (camera, mray) */
    int mirror;   /* a moving mirror's vertex: a smooth conductor's, sliding (geo_hit_kind) */
    int mray;     /* on the ray a moving mirror reflected (origin the mirror's vertex), t from it (geo_mirror_ray) */
} GeoVertex;

static inline GeoVertex geo_fixed(vec3 p) {
    GeoVertex v;
    v.p = p;
    v.n = v.d = v.gx = v.gn = v.gs = v.dx = v.dn = v.ds = v.gwi = v.dd = v3_splat(0.0f);
    v.b1 = v.b2 = v.gj = v.dj = v.t = v.sx = v.sy = 0.0f;
    v.gb1 = v.gb2 = v.db1 = v.db2 = 0.0f;
    v.kind = GEO_FIXED;
    v.id = v.rec = -1;
    v.camera = v.mirror = v.mray = 0;
    return v;
}


/* Whether leaf-order triangle prim is a moving mesh's: its vertices in the packed range [moving_lo, moving_hi) whose
 * adjoints the host reads (params.h; a camera's, a light's or an instance's motion: the host passes every vertex).
 * Always true in an instanced scene (a triangle's vertices there are its shapegroup's, whichever instance moves). */
static inline bool geo_moving_prim(const Scene* sc, const Grads* gr, int prim) {
#ifdef SCENE_HAS_INSTANCES
    return true;
#else
    int k = sc->tri_vidx[3 * prim];
    return k >= gr->moving_lo && k < gr->moving_hi;
#endif
}

/* ---- triangles in world space (instanced scenes: through the vertex's instance record) ------------------ */

/* The instance record of v's triangle (0: none, the identity). */
static inline __global const float* geo_record(const Scene* sc, const GeoVertex* v) {
#ifdef SCENE_HAS_INSTANCES
    return v->rec >= 0 ? inst_record(sc->nodes, v->rec) : 0;
#else
    return 0;
#endif
}

/* Vertex j (0, 1, 2) of leaf-order triangle tri, in its mesh's (object) space. */
static inline vec3 geo_local_vertex(const Scene* sc, int tri, int j) {
    __global const float* t = sc->tris + 9 * tri;
    vec3 v0 = rgb_at(t, sc->unit);
    return j == 0 ? v0 : v3_add(v0, rgb_at(t + 3 * j, sc->unit));
}

/* The world edges e1 = v1 - v0, e2 = v2 - v0 of v's triangle. */
static inline void geo_edges(const Scene* sc, const GeoVertex* v, vec3* e1, vec3* e2) {
    __global const float* t = sc->tris + 9 * v->id;
    *e1 = rgb_at(t + 3, sc->unit);
    *e2 = rgb_at(t + 6, sc->unit);
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) {
        *e1 = inst_vector(r + INST_O2W, *e1);
        *e2 = inst_vector(r + INST_O2W, *e2);
    }
#endif
}

/* -1 where surface_at's geometric normal is against e1 x e2 (a mirroring instance), else 1. */
static inline float geo_flip(const Scene* sc, const GeoVertex* v) {
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) {
        __global const float* m = r + INST_O2W;
        float det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                    m[2] * (m[4] * m[9] - m[5] * m[8]);
        return det < 0.0f ? -1.0f : 1.0f;
    }
#endif
    return 1.0f;
}

/* Vertex normal k (an index into vnormals) of v's triangle in world space, unnormalised (N n). */
static inline vec3 geo_vnormal(const Scene* sc, const GeoVertex* v, int k) {
    vec3 n = rgb_at(sc->vnormals + 3 * k, sc->unit);
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) n = inst_normal(r + INST_NORMAL, n);
#endif
    return n;
}

#ifdef SCENE_HAS_INSTANCES
/* M^T g for the 3x3 part of a row-major matrix whose rows are `stride` floats apart. */
static inline vec3 geo_transposed(__global const float* m, int stride, vec3 g) {
    return v3(m[0] * g.x + m[stride] * g.y + m[2 * stride] * g.z, m[1] * g.x + m[stride + 1] * g.y + m[2 * stride + 1] * g.z,
              m[2] * g.x + m[stride + 2] * g.y + m[2 * stride + 2] * g.z);
}

/* sum_c col_c u_c over the first three columns of a record's 12 floats of grad_inst (dA u). */
static inline vec3 geo_inst_apply(__global const float* c, vec3 u) {
    return v3_add(v3_add(v3_scale(tangent3(c), u.x), v3_scale(tangent3(c + 3), u.y)), v3_scale(tangent3(c + 6), u.z));
}
#endif

/* Reverse mode: the world adjoints g0, g1, g2 of v's triangle's vertices to grad_verts (object space) and, with
 * -DGRAD_INSTANCES, to its record's grad_inst. */
static inline void geo_put_vertices(const Scene* sc, Grads* gr, const GeoVertex* v, vec3 g0, vec3 g1, vec3 g2) {
    __global const int* vi = sc->tri_vidx + 3 * v->id;
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) {
#ifdef GRAD_INSTANCES
        vec3 x0 = geo_local_vertex(sc, v->id, 0), x1 = geo_local_vertex(sc, v->id, 1), x2 = geo_local_vertex(sc, v->id, 2);
        __global float* gi = gr->inst + GEO_INST_STRIDE * v->rec;
        grad_put3(gr, gi, v3_add(v3_add(v3_scale(g0, x0.x), v3_scale(g1, x1.x)), v3_scale(g2, x2.x)));
        grad_put3(gr, gi + 3, v3_add(v3_add(v3_scale(g0, x0.y), v3_scale(g1, x1.y)), v3_scale(g2, x2.y)));
        grad_put3(gr, gi + 6, v3_add(v3_add(v3_scale(g0, x0.z), v3_scale(g1, x1.z)), v3_scale(g2, x2.z)));
        grad_put3(gr, gi + 9, v3_add(v3_add(g0, g1), g2));
#endif
        g0 = geo_transposed(r + INST_O2W, 4, g0);
        g1 = geo_transposed(r + INST_O2W, 4, g1);
        g2 = geo_transposed(r + INST_O2W, 4, g2);
    }
#endif
    grad_put3(gr, gr->verts + 3 * vi[0], g0);
    grad_put3(gr, gr->verts + 3 * vi[1], g1);
    grad_put3(gr, gr->verts + 3 * vi[2], g2);
}

/* Reverse mode: the world adjoints h0, h1, h2 of v's triangle's (unnormalised) vertex normals to grad_vnormals
 * (object space) and, with -DGRAD_INSTANCES, to its record's grad_inst. */
static inline void geo_put_vnormals(const Scene* sc, Grads* gr, const GeoVertex* v, vec3 h0, vec3 h1, vec3 h2) {
    __global const int* vi = sc->tri_vidx + 3 * v->id;
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) {
        __global const float* nm = r + INST_NORMAL;
        h0 = geo_transposed(nm, 3, h0);
        h1 = geo_transposed(nm, 3, h1);
        h2 = geo_transposed(nm, 3, h2);
#ifdef GRAD_INSTANCES
        vec3 w0 = geo_vnormal(sc, v, vi[0]), w1 = geo_vnormal(sc, v, vi[1]), w2 = geo_vnormal(sc, v, vi[2]);
        __global float* gi = gr->inst + GEO_INST_STRIDE * v->rec;
        grad_put3(gr, gi, v3_neg(v3_add(v3_add(v3_scale(w0, h0.x), v3_scale(w1, h1.x)), v3_scale(w2, h2.x))));
        grad_put3(gr, gi + 3, v3_neg(v3_add(v3_add(v3_scale(w0, h0.y), v3_scale(w1, h1.y)), v3_scale(w2, h2.y))));
        grad_put3(gr, gi + 6, v3_neg(v3_add(v3_add(v3_scale(w0, h0.z), v3_scale(w1, h1.z)), v3_scale(w2, h2.z))));
#endif
    }
#endif
    grad_put3(gr, gr->vnormals + 3 * vi[0], h0);
    grad_put3(gr, gr->vnormals + 3 * vi[1], h1);
    grad_put3(gr, gr->vnormals + 3 * vi[2], h2);
}

/* Forward mode: the world tangent of vertex j of v's triangle (vertex index k). */
static inline vec3 geo_vertex_tangent(const Scene* sc, const Grads* tg, const GeoVertex* v, int j, int k) {
    vec3 d = tangent3(tg->verts + 3 * k);
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) {
        d = inst_vector(r + INST_O2W, d);
#ifdef GRAD_INSTANCES
        __global const float* c = tg->inst + GEO_INST_STRIDE * v->rec;
        d = v3_add(v3_add(d, geo_inst_apply(c, geo_local_vertex(sc, v->id, j))), tangent3(c + 9));
#endif
    }
#endif
    return d;
}

/* Forward mode: the world tangent of the (unnormalised) vertex normal k of v's triangle. */
static inline vec3 geo_vnormal_tangent(const Scene* sc, const Grads* tg, const GeoVertex* v, int k) {
    vec3 d = tangent3(tg->vnormals + 3 * k);
#ifdef SCENE_HAS_INSTANCES
    __global const float* r = geo_record(sc, v);
    if (r) {
        __global const float* nm = r + INST_NORMAL;
        d = inst_normal(nm, d);
#ifdef GRAD_INSTANCES
        __global const float* c = tg->inst + GEO_INST_STRIDE * v->rec;
        vec3 w = geo_vnormal(sc, v, k); /* -N dA^T w */
        d = v3_sub(d, inst_normal(nm, v3(m_dot(tangent3(c), w), m_dot(tangent3(c + 3), w), m_dot(tangent3(c + 6), w))));
#endif
    }
#endif
    return d;
}

#ifdef GRAD_CAMERA
/* The moving camera (a pinhole or orthographic: -DGRAD_CAMERA, the sensor's to_world and fov differentiated): its
 * origin O and the basis F, R, U of camera_ray, whose ray through film coordinates (sx, sy) is d = v / |v|,
 * v = F + sx R + sy U. The camera ray's hit slides along the moving ray, x = O + t d on the moving triangle, so
 *   dx = P (dO + t dd) + d (n . dp) / (n . d),   P u = u - d (n . u) / (n . d),
 * and its incident direction -d turns with the ray. Their adjoints go to 12 floats (O, F, R, U: grad_camera),
 * which the host chains to to_world and fov (pyclpt/gradients/differentiate.py). An orthographic camera
 * (-DSCENE_CAMERA=CAMERA_ORTHOGRAPHIC, camera_ray's): the ray's origin o = O + sx R + sy U moves over the film
 * rectangle and its direction is d = F (unit: the host's chain through basis() normalises it), so
 * dx = P (dO + sx dR + sy dU + t dF) + d (n . dp) / (n . d). */
static inline vec3 geo_camera_v(const Scene* sc, float sx, float sy) {
    __global const float* c = sc->consts;
    return v3_add(v3_add(rgb_at(c + CONST_CAM_FORWARD, sc->unit), v3_scale(rgb_at(c + CONST_CAM_RIGHT, sc->unit), sx)),
                  v3_scale(rgb_at(c + CONST_CAM_UP, sc->unit), sy));
}

/* Marks v, the hit of the camera ray from origin through film position film, as the camera's. */
static inline void geo_camera_hit(const Scene* sc, GeoVertex* v, vec2 film, vec3 origin) {
    if (v->kind != GEO_SLIDING) return; /* a vertex held still (geo_hit_kind) */
    __global const float* c = sc->consts;
    v->camera = 1;
    v->sx = 2.0f * (film.x / c[CONST_WIDTH]) - 1.0f;
    v->sy = 1.0f - 2.0f * (film.y / c[CONST_HEIGHT]);
    v->t = m_length(v3_sub(v->p, origin));
}

/* Reverse mode: the camera hit's adjoints to the camera's 12 floats, gx the adjoint of its position. */
static inline void geo_camera_scatter(const Scene* sc, Grads* gr, const GeoVertex* v, vec3 gx) {
    float nd = m_dot(v->n, v->d);
    if (nd == 0.0f) return;
    vec3 q = v3_sub(gx, v3_scale(v->n, m_dot(v->d, gx) / nd)); /* P^T gx */
    vec3 g_dd = v3_sub(v3_scale(q, v->t), v->gwi);
#if SCENE_CAMERA == CAMERA_ORTHOGRAPHIC
    /* o = O + sx R + sy U, d = F */
    grad_put3(gr, gr->camera, q);
    grad_put3(gr, gr->camera + 3, g_dd);
    grad_put3(gr, gr->camera + 6, v3_scale(q, v->sx));
    grad_put3(gr, gr->camera + 9, v3_scale(q, v->sy));
#else
    vec3 w = geo_camera_v(sc, v->sx, v->sy);
    vec3 g_v = v3_divs(v3_sub(g_dd, v3_scale(v->d, m_dot(v->d, g_dd))), m_length(w));
    grad_put3(gr, gr->camera, q);
    grad_put3(gr, gr->camera + 3, g_v);
    grad_put3(gr, gr->camera + 6, v3_scale(g_v, v->sx));
    grad_put3(gr, gr->camera + 9, v3_scale(g_v, v->sy));
#endif
}

/* Forward mode: the camera's tangent added to its hit's motion (dx) and to its ray's direction (dd). */
static inline void geo_camera_motion(const Scene* sc, const Grads* tg, GeoVertex* v) {
    if (!v->camera) return;
    float nd = m_dot(v->n, v->d);
    if (nd == 0.0f) return;
#if SCENE_CAMERA == CAMERA_ORTHOGRAPHIC
    /* o = O + sx R + sy U, d = F */
    v->dd = tangent3(tg->camera + 3);
    vec3 u = v3_add(v3_add(tangent3(tg->camera), v3_scale(tangent3(tg->camera + 6), v->sx)),
                    v3_add(v3_scale(tangent3(tg->camera + 9), v->sy), v3_scale(v->dd, v->t)));
#else
    vec3 w = geo_camera_v(sc, v->sx, v->sy);
    vec3 dw = v3_add(v3_add(tangent3(tg->camera + 3), v3_scale(tangent3(tg->camera + 6), v->sx)),
                     v3_scale(tangent3(tg->camera + 9), v->sy));
    v->dd = v3_divs(v3_sub(dw, v3_scale(v->d, m_dot(v->d, dw))), m_length(w));
    vec3 u = v3_add(tangent3(tg->camera), v3_scale(v->dd, v->t));
#endif
    v->dx = v3_add(v->dx, v3_sub(u, v3_scale(v->d, m_dot(v->n, u) / nd)));
}
#endif

/* The point at barycentrics (b1, b2) of leaf-order triangle tri in instance record rec (-1: none), attached or
 * sliding along d. */
static inline GeoVertex geo_on_leaf(const Scene* sc, int tri, int rec, float b1, float b2, vec3 p, int kind, vec3 d) {
    GeoVertex v = geo_fixed(p);
    v.b1 = b1;
    v.b2 = b2;
    v.kind = kind;
    v.id = tri;
    v.rec = rec;
    v.d = d;
    vec3 e1, e2;
    geo_edges(sc, &v, &e1, &e2);
    v.n = m_normalize(m_cross(e1, e2));
    return v;
}

/* The point at barycentrics (b1, b2) of a hit's prim (instanced scenes: the packed id). */
static inline GeoVertex geo_on_triangle(const Scene* sc, int prim, float b1, float b2, vec3 p, int kind, vec3 d) {
#ifdef SCENE_HAS_INSTANCES
    int bits = inst_tri_bits(sc->nodes);
    return geo_on_leaf(sc, prim & ((1 << bits) - 1), prim >> bits, b1, b2, p, kind, d);
#else
    return geo_on_leaf(sc, prim, -1, b1, b2, p, kind, d);
#endif
}

/* The far end of a light sample n taken at vertex gc with rng key (key, depth): an emissive triangle's point,
 * attached (GEO_ATTACHED; its barycentrics are light_sample's); a point or spot light's position (GEO_POINT; a
 * spot's falloff: geo_spot_falloff). Returns false for a direction to the environment or a directional light
 * (fixed: a point at infinity). */
static inline bool geo_light_end(const Scene* sc, RngKey key, int depth, const NeeSample* n, const GeoVertex* gc,
                                 GeoVertex* gy) {
    __global const float* l = sc->lights + LIGHT_STRIDE * n->ls.light;
    int type = (int)l[LIGHT_TYPE];
    if (type == LIGHT_TRIANGLE) {
        int prim = as_int(l[LIGHT_PRIM]);
        float u_select;
        vec2 u;
        rng_light(key, depth, &u_select, &u);
        u = square_to_triangle(u);
        __global const float* t = sc->tris + 9 * prim;
        vec3 y = v3_add(v3_add(rgb_at(t, sc->unit), v3_scale(rgb_at(t + 3, sc->unit), u.x)),
                        v3_scale(rgb_at(t + 6, sc->unit), u.y));
        *gy = geo_on_leaf(sc, prim, -1, u.x, u.y, y, GEO_ATTACHED, v3_splat(0.0f)); /* emitters: plain meshes */
        return true;
    }
    if (type != LIGHT_POINT && type != LIGHT_SPOT) return false;
    *gy = geo_fixed(v3_add(gc->p, v3_scale(n->ls.wi, n->ls.dist)));
    gy->kind = GEO_POINT;
    gy->id = n->ls.light;
    return true;
}

/* A spot light's falloff F(c) at c = -wi . axis (lights.h: 1 inside the beam, linear in angle to 0 at the
 * cutoff): its log-derivative dF/dc / F, 0 inside the beam and for any other light; *axis its axis. */
static inline float geo_spot_falloff(const Scene* sc, int light, vec3 wi, vec3* axis) {
    *axis = v3_splat(0.0f);
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    if (!(HAS_LIGHT(LIGHT_SPOT) && (int)l[LIGHT_TYPE] == LIGHT_SPOT)) return 0.0f;
    __global const float* s = sc->light_data + as_int(l[LIGHT_PRIM]);
    *axis = rgb_at(s + SPOT_AXIS, sc->unit);
    float c = -m_dot(wi, *axis);
    if (c >= s[SPOT_COS_BEAM] || c <= s[SPOT_COS_CUTOFF]) return 0.0f;
    float sin_t = m_sqrt(m_max(1.0f - c * c, 0.0f));
    float f = (s[SPOT_CUTOFF] - m_acos(m_clamp(c, -1.0f, 1.0f))) * s[SPOT_INV_TRANSITION];
    return f > 0.0f && sin_t > 0.0f ? s[SPOT_INV_TRANSITION] / (sin_t * f) : 0.0f; /* d acos(c)/dc = -1/sin */
}

/* ---- reverse mode ------------------------------------------------------------------------------------ */

/* A triangle's vertex normals n0, n1, n2 and their interpolation m at the vertex's barycentrics (the shading
 * normal is m / |m|); false for a triangle without vertex normals (flat: the shading normal is its own), and,
 * under -DGEO_NORMALS_FOLLOW_FACES (nothing differentiated moves a mesh's vertices apart: poses, lights, the
 * camera, which carry a face's normal and its vertex normals alike), for one whose three vertex normals are
 * the same and along its own (a cube's, a rectangle's face): flat to the derivative, nothing scattered to its
 * vertex normals. */
static inline bool geo_vertex_normals(const Scene* sc, const GeoVertex* v, vec3* n0, vec3* n1, vec3* n2, vec3* m) {
    if (!(sc->tri_info[2 * v->id] & TRI_HAS_NORMALS)) return false;
    __global const int* vi = sc->tri_vidx + 3 * v->id;
    *n0 = geo_vnormal(sc, v, vi[0]);
    *n1 = geo_vnormal(sc, v, vi[1]);
    *n2 = geo_vnormal(sc, v, vi[2]);
#ifdef GEO_NORMALS_FOLLOW_FACES
    if (v3_is_zero(v3_sub(*n0, *n1)) && v3_is_zero(v3_sub(*n0, *n2)) && m_dot(*n0, v->n) >= (1.0f - 1e-5f) * m_length(*n0))
        return false;
#endif
    *m = v3_add(v3_add(v3_scale(*n0, 1.0f - v->b1 - v->b2), v3_scale(*n1, v->b1)), v3_scale(*n2, v->b2));
    float len = m_length(*m);
    return len > 0.0f && m_isfinite(len);
}

/* ---- a moving planar (or smooth-shaded) mirror ---------------------------------------------------------
 * A vertex m of a smooth conductor (delta reflection only) reached along a sliding ray (the camera's, or a
 * delta lobe's fixed one) slides along that ray on its moving triangle as any sliding point does (its ray's
 * motion: the camera's), and reflects it about its shading normal ns (the triangle's, or m / |m| of its vertex
 * normals with its barycentrics sliding): r = d - 2 (ns . d) ns turns with the incoming direction d and ns,
 *   dr = dd - 2 [(dns . d + ns . dd) ns + (ns . d) dns].
 * The next hit x slides along the moving ray (origin m, direction r): dx = P (dm + t dr) + r (n . dp) / (n . r),
 * its incident direction -r turning with it (the camera hit's rule, the ray's origin and direction the mirror's).
 * Reverse mode: x's adjoints (q = P^T gx to the origin, t q - gwi to r) go to m's position, its incident
 * direction (g_d = g_r - 2 ns (ns . g_r)) and its shading normal (-2 [(ns . d) g_r + (ns . g_r) d]), when x is
 * complete (geo_flush_ray: the window's shift after x's successor, or the path's end), before m's own scatter.
 * The conductor's Fresnel factor F(c), c = |ns . d|, turns with d and ns too (geo_fresnel_slope: its
 * log-derivative times dc in forward mode; in reverse mode, weighted by what flows through the mirror, to d and ns).
 * One mirror at a time: a delta vertex right after a moving mirror, and one reached along an area-form segment
 * (after a rough bounce), is held still, and the ray after it is fixed. */

/* Whether b reflects like a smooth mirror only (a smooth conductor). */
static inline bool geo_mirror_material(const Bsdf* b) {
    return HAS_MATERIAL(MAT_CONDUCTOR) && b->type == MAT_CONDUCTOR;
}

/* The kind of a hit on material b, reached along an area-form segment (seg_area) or not from vertex prev; *mirror
 * set for a moving mirror's vertex. */
static inline int geo_hit_kind(const Bsdf* b, bool seg_area, const GeoVertex* prev, int* mirror) {
    *mirror = 0;
    if (!bsdf_is_delta(b)) return seg_area ? GEO_ATTACHED : GEO_SLIDING;
    if (seg_area || prev->mirror || !geo_mirror_material(b)) return GEO_FIXED; /* held still */
    *mirror = 1;
    return GEO_SLIDING;
}

/* Marks x, the hit of the ray that the moving mirror m reflected, as sliding along that moving ray. */
static inline void geo_mirror_ray(GeoVertex* x, const GeoVertex* m) {
    if (!m->mirror || x->kind != GEO_SLIDING) return;
    x->mray = 1;
    x->t = m_length(v3_sub(x->p, m->p));
}

/* The unit shading normal of v as geo_shading_motion's ds moves it: m / |m|, or the triangle's (flipped). */
static inline vec3 geo_shading_normal(const Scene* sc, const GeoVertex* v) {
    vec3 n0, n1, n2, m;
    if (geo_vertex_normals(sc, v, &n0, &n1, &n2, &m)) return m_normalize(m);
    return v3_scale(v->n, geo_flip(sc, v));
}

/* A moving mirror m's Fresnel factor F(c) (conductor_sample's, c = |wi . ns| = |d . ns|): its log-derivative
 * dF/dc / F per channel, by central differences of fresnel_conductor (clamped to [0, 1]); *dc_dd and *dc_dns
 * the gradients of c with respect to m's incoming direction d and its shading normal ns. */
static inline vec3 geo_fresnel_slope(const Scene* sc, const Bsdf* b, const GeoVertex* m, vec3* dc_dd, vec3* dc_dns) {
    vec3 ns = geo_shading_normal(sc, m);
    float nd = m_dot(ns, m->d), sign = nd < 0.0f ? -1.0f : 1.0f, c = m_abs(nd);
    *dc_dd = v3_scale(ns, sign);
    *dc_dns = v3_scale(m->d, sign);
    float c0 = m_max(c - GEO_FD_STEP, 0.0f), c1 = m_min(c + GEO_FD_STEP, 1.0f);
    if (!(c1 > c0)) return v3_splat(0.0f);
    vec3 df = v3_sub(fresnel_conductor(c1, bsdf_eta(b), b->k), fresnel_conductor(c0, bsdf_eta(b), b->k));
    return safe_div3(v3_scale(df, 1.0f / (c1 - c0)), fresnel_conductor(c, bsdf_eta(b), b->k));
}

/* Reverse mode: the moving mirror m's Fresnel factor, through which `through` (everything gathered after m) flows,
 * weighted by dL: its adjoints to m's incident direction (wi = -d) and shading normal. */
static inline void geo_fresnel_adjoint(const Scene* sc, const Bsdf* b, vec3 dL, vec3 through, GeoVertex* m) {
    vec3 dc_dd, dc_dns;
    float g = m_dot(v3_mul(dL, through), geo_fresnel_slope(sc, b, m, &dc_dd, &dc_dns));
    m->gwi = v3_sub(m->gwi, v3_scale(dc_dd, g));
    m->gs = v3_add(m->gs, v3_scale(dc_dns, g));
}

/* Reverse mode: x's ray adjoints (gx its position's, with its slide) to the mirror m it came from. */
static inline void geo_ray_adjoint(const Scene* sc, const GeoVertex* x, vec3 gx, GeoVertex* m) {
    float nd = m_dot(x->n, x->d);
    if (nd == 0.0f) return;
    vec3 q = v3_sub(gx, v3_scale(x->n, m_dot(x->d, gx) / nd)); /* P^T gx: the ray's origin */
    vec3 g_r = v3_sub(v3_scale(q, x->t), x->gwi);           /* its direction r */
    m->gx = v3_add(m->gx, q);
    vec3 ns = geo_shading_normal(sc, m);
    float nsd = m_dot(ns, m->d), nsg = m_dot(ns, g_r);
    vec3 g_d = v3_sub(g_r, v3_scale(ns, 2.0f * nsg));
    m->gwi = v3_sub(m->gwi, g_d); /* wi = -d */
    m->gs = v3_sub(m->gs, v3_scale(v3_add(v3_scale(g_r, nsd), v3_scale(m->d, nsg)), 2.0f));
}

/* A vertex's adjoints to its triangle's three vertices and vertex normals (or its point light's position); one
 * on a moving mirror's ray (v->mray) its ray's to the mirror mir (0: none). */
static inline void geo_scatter_ray(const Scene* sc, Grads* gr, const GeoVertex* v, GeoVertex* mir) {
    if (v->kind == GEO_POINT) {
        grad_put3(gr, gr->lightpos + GEO_LIGHT_STRIDE * v->id, v->gx);
        return;
    }
    if (v->kind == GEO_FIXED) return;
    /* a triangle of a mesh that does not move: nothing reads its vertices' adjoints (the host reads the packed
       vertices [moving_lo, moving_hi), the moving meshes'); a camera hit's adjoints still go to the camera, a
       moving mirror's ray's to the mirror. In the Cornell box with one box moving, most vertices are the walls':
       this saved 30 % of the backward pass. */
    bool ray = mir != 0 && v->mray;
    bool put = v->camera || geo_moving_prim(sc, gr, v->id);
    if (!put && !ray) return;
    vec3 e1, e2;
    geo_edges(sc, v, &e1, &e2);
    vec3 c = m_cross(e1, e2);
    float len = m_length(c);
    if (!(len > 0.0f)) return;
    vec3 n = v3_divs(c, len);
    float b0 = 1.0f - v->b1 - v->b2;
    vec3 gx = v->gx, gn = v->gn, g_slide = v3_splat(0.0f);
    vec3 n0, n1, n2, m;
    float g1 = v->gb1, g2 = v->gb2; /* the adjoints of a sliding point's barycentrics: its textures', its normal's */
    if (geo_vertex_normals(sc, v, &n0, &n1, &n2, &m)) { /* the shading normal m / |m| */
        float lm = m_length(m);
        vec3 ns = v3_divs(m, lm);
        vec3 gm = v3_divs(v3_sub(v->gs, v3_scale(ns, m_dot(ns, v->gs))), lm);
        if (put) geo_put_vnormals(sc, gr, v, v3_scale(gm, b0), v3_scale(gm, v->b1), v3_scale(gm, v->b2));
        g1 += m_dot(gm, v3_sub(n1, n0));
        g2 += m_dot(gm, v3_sub(n2, n0));
    } else {
        gn = v3_add(gn, v3_scale(v->gs, geo_flip(sc, v))); /* flat: the shading normal is the triangle's */
    }
    if (v->kind == GEO_SLIDING) { /* its barycentrics, through its motion over the triangle D = dx - dp */
        g_slide = v3_divs(v3_add(v3_scale(m_cross(e2, n), g1), v3_scale(m_cross(n, e1), g2)), len);
        gx = v3_add(gx, g_slide);
    }
#ifdef GRAD_CAMERA
    if (v->camera) geo_camera_scatter(sc, gr, v, gx);
#endif
    if (ray) geo_ray_adjoint(sc, v, gx, mir);
    if (!put) return;
    vec3 gp = gx; /* the adjoint of the triangle's material point under the vertex */
    if (v->kind == GEO_SLIDING) {
        float nd = m_dot(n, v->d);
        gp = nd != 0.0f ? v3_scale(n, m_dot(v->d, gx) / nd) : v3_splat(0.0f);
        gp = v3_sub(gp, g_slide);
    }
    /* n = c / |c|, log J = log |c| + const: the adjoint of c */
    vec3 gc = v3_divs(v3_add(v3_sub(gn, v3_scale(n, m_dot(n, gn))), v3_scale(n, v->gj)), len);
    vec3 ge1 = m_cross(e2, gc), ge2 = m_cross(gc, e1);
    geo_put_vertices(sc, gr, v, v3_sub(v3_scale(gp, b0), v3_add(ge1, ge2)), v3_add(v3_scale(gp, v->b1), ge1),
                     v3_add(v3_scale(gp, v->b2), ge2));
}

static inline void geo_scatter(const Scene* sc, Grads* gr, const GeoVertex* v) { geo_scatter_ray(sc, gr, v, 0); }

/* Reverse mode: x, complete (no later factor needs it), on the ray of the moving mirror m before it: its adjoints
 * scattered, its ray's to m (which the caller scatters after), and x held still from then on. */
static inline void geo_flush_ray(const Scene* sc, Grads* gr, GeoVertex* m, GeoVertex* x) {
    if (!x->mray) return;
    geo_scatter_ray(sc, gr, x, m);
    x->kind = GEO_FIXED;
    x->mray = x->camera = 0;
}

/* The adjoint g_w of the unit direction w = (b - a) / r and g_r of the distance r, to a's and b's positions. */
static inline void geo_segment_adjoint(GeoVertex* a, GeoVertex* b, vec3 w, float r, vec3 g_w, float g_r) {
    vec3 g = v3_add(v3_divs(v3_sub(g_w, v3_scale(w, m_dot(w, g_w))), r), v3_scale(w, g_r));
    b->gx = v3_add(b->gx, g);
    a->gx = v3_sub(a->gx, g);
}

/* The adjoint of a direction's local coordinates (to_local(f, w)) to the world direction (returned) and to the
 * frame's normal (added to *gn): the frame turns with the normal by the smallest rotation. */
static inline vec3 geo_local_adjoint(Frame f, vec3 w, vec3 gl, vec3* gn) {
    float nw = m_dot(f.n, w);
    *gn = v3_add(*gn, v3_sub(v3_scale(w, gl.z), v3_scale(v3_add(v3_scale(f.s, gl.x), v3_scale(f.t, gl.y)), nw)));
    return to_world(f, gl);
}

/* f(wi, wo) |cos| with the local directions moved by h along the unit coordinate axis k of the six (wi's three,
 * then wo's), renormalised. */
static inline vec3 geo_bsdf_moved(const Bsdf* b, vec3 wi, vec3 wo, int k, float h) {
    if (k < 3) {
        if (k == 0) wi.x += h; else if (k == 1) wi.y += h; else wi.z += h;
        wi = m_normalize(wi);
    } else {
        if (k == 3) wo.x += h; else if (k == 4) wo.y += h; else wo.z += h;
        wo = m_normalize(wo);
    }
    float pdf;
    return bsdf_eval(b, wi, wo, &pdf);
}

/* A diffuse BSDF's value f = reflectance / pi |wo.z| (where wi and wo are on its sides; 0 elsewhere) has the
 * derivative f / wo.z along wo.z and none along wi: no differences needed. */
static inline bool geo_diffuse(const Bsdf* b) { return HAS_MATERIAL(MAT_DIFFUSE) && b->type == MAT_DIFFUSE; }

/* The gradient of s . f(wi, wo) |cos| with respect to the local directions (wi's in *g_wi, wo's in *g_wo). */
static inline void geo_bsdf_gradient(const Bsdf* b, vec3 wi, vec3 wo, vec3 s, vec3* g_wi, vec3* g_wo) {
    if (geo_diffuse(b)) {
        float pdf;
        vec3 f = bsdf_eval(b, wi, wo, &pdf);
        *g_wi = v3_splat(0.0f);
        *g_wo = v3(0.0f, 0.0f, wo.z != 0.0f ? m_dot(s, f) / wo.z : 0.0f);
        return;
    }
    float g[6];
    for (int k = 0; k < 6; k++) {
        vec3 fp = geo_bsdf_moved(b, wi, wo, k, GEO_FD_STEP), fm = geo_bsdf_moved(b, wi, wo, k, -GEO_FD_STEP);
        bool straddles = (max3(fp) > 0.0f) != (max3(fm) > 0.0f);
        g[k] = straddles ? 0.0f : m_dot(s, v3_sub(fp, fm)) * (0.5f / GEO_FD_STEP);
    }
    *g_wi = v3(g[0], g[1], g[2]);
    *g_wo = v3(g[3], g[4], g[5]);
}

/* A sliding point's textures (-DSCENE_HAS_TEXTURES): as it slides over its triangle its texture coordinates move
 * with its barycentrics (an attached point keeps them: the material form), and so does every textured quantity
 * of its BSDF. d f(wi, wo) / d b_k (k = 1, 2) by central differences of the BSDF built at the texture coordinates
 * of barycentrics b_k +- GEO_UV_STEP (the shading frame kept), local directions; 0 at any other point. */
#define GEO_UV_STEP 1e-3f

static inline vec3 geo_bsdf_bary(const Scene* sc, const Surface* s, const GeoVertex* v, int k, vec3 wi, vec3 wo) {
#ifdef SCENE_HAS_TEXTURES
    if (v->kind != GEO_SLIDING) return v3_splat(0.0f);
    int info = sc->tri_info[2 * v->id];
    vec3 f[2];
    for (int j = 0; j < 2; ++j) {
        float h = j == 0 ? GEO_UV_STEP : -GEO_UV_STEP;
        Surface t = *s;
        t.uv = tri_uv(sc->tri_vidx, sc->vuvs, v->id, info, v->b1 + (k == 1 ? h : 0.0f), v->b2 + (k == 2 ? h : 0.0f));
        Bsdf b = bsdf_at(sc, &t);
        float pdf;
        f[j] = bsdf_eval(&b, wi, wo, &pdf);
    }
    return v3_scale(v3_sub(f[0], f[1]), 0.5f / GEO_UV_STEP);
#else
    (void)sc; (void)s; (void)v; (void)k; (void)wi; (void)wo;
    return v3_splat(0.0f);
#endif
}

/* Forward mode: the tangent of a sliding point's textured BSDF value f(wi, wo) (local directions) as its
 * barycentrics move (db1, db2: geo_shading_motion). */
static inline vec3 geo_bsdf_bary_tangent(const Scene* sc, const Surface* s, const GeoVertex* v, vec3 wi, vec3 wo) {
    if (v->kind != GEO_SLIDING || (v->db1 == 0.0f && v->db2 == 0.0f)) return v3_splat(0.0f);
    return v3_add(v3_scale(geo_bsdf_bary(sc, s, v, 1, wi, wo), v->db1),
                  v3_scale(geo_bsdf_bary(sc, s, v, 2, wi, wo), v->db2));
}

/* Reverse mode, a BSDF factor f(wi, wo) |cos| at vertex v (surface srf, f its value) through which the radiance C
 * flows, weighted by dL: its adjoints to v's normal and to the two world directions (returned in *g_wi, *g_wo), and
 * a sliding point's to its barycentrics through its textures (geo_bsdf_bary). */
static inline void geo_bsdf_adjoint(const Scene* sc, const Surface* srf, const Bsdf* b, vec3 wi_w, vec3 wo_w,
                                    vec3 f, vec3 C, vec3 dL, GeoVertex* v, vec3* g_wi, vec3* g_wo) {
    Frame fr = srf->sh;
    vec3 s = safe_div3(v3_mul(dL, C), f);
    vec3 gli, glo, wi = to_local(fr, wi_w), wo = to_local(fr, wo_w);
    geo_bsdf_gradient(b, wi, wo, s, &gli, &glo);
    *g_wi = geo_local_adjoint(fr, wi_w, gli, &v->gs);
    *g_wo = geo_local_adjoint(fr, wo_w, glo, &v->gs);
    if (v->kind == GEO_SLIDING) {
        v->gb1 += m_dot(s, geo_bsdf_bary(sc, srf, v, 1, wi, wo));
        v->gb2 += m_dot(s, geo_bsdf_bary(sc, srf, v, 2, wi, wo));
    }
}

/* Reverse mode, the area-form factors of segment a -> b (direction w, length r) other than a's BSDF: b's cosine,
 * 1 / r^2 and b's area Jacobian, with scalar weight a_w = dL . (what flows through) and g_w the adjoint of w from
 * a's BSDF. */
static inline void geo_area_segment(GeoVertex* a, GeoVertex* b, vec3 w, float r, float a_w, vec3 g_w) {
    float cb = m_dot(b->n, w);
    if (cb != 0.0f) {
        b->gn = v3_add(b->gn, v3_scale(w, a_w / cb));
        g_w = v3_add(g_w, v3_scale(b->n, a_w / cb));
    }
    b->gj += a_w;
    geo_segment_adjoint(a, b, w, r, g_w, -2.0f * a_w / r);
}

/* ---- forward mode ------------------------------------------------------------------------------------ */

/* The tangents of a vertex's position, normal and log area Jacobian from the tangent buffers. */
static inline void geo_motion(const Scene* sc, const Grads* tg, GeoVertex* v) {
    if (v->kind == GEO_POINT) {
        v->dx = tangent3(tg->lightpos + GEO_LIGHT_STRIDE * v->id);
        return;
    }
    if (v->kind == GEO_FIXED) return;
    vec3 e1, e2;
    geo_edges(sc, v, &e1, &e2);
    __global const int* vi = sc->tri_vidx + 3 * v->id;
    vec3 d0 = geo_vertex_tangent(sc, tg, v, 0, vi[0]), d1 = geo_vertex_tangent(sc, tg, v, 1, vi[1]),
         d2 = geo_vertex_tangent(sc, tg, v, 2, vi[2]);
    vec3 c = m_cross(e1, e2);
    float len = m_length(c);
    if (!(len > 0.0f)) return;
    vec3 n = v3_divs(c, len);
    vec3 dp = v3_add(v3_add(v3_scale(d0, 1.0f - v->b1 - v->b2), v3_scale(d1, v->b1)), v3_scale(d2, v->b2));
    if (v->kind == GEO_SLIDING) {
        float nd = m_dot(n, v->d);
        dp = nd != 0.0f ? v3_scale(v->d, m_dot(n, dp) / nd) : v3_splat(0.0f);
    }
    v->dx = dp;
    vec3 dc = v3_add(m_cross(v3_sub(d1, d0), e2), m_cross(e1, v3_sub(d2, d0)));
    v->dn = v3_divs(v3_sub(dc, v3_scale(n, m_dot(n, dc))), len);
    v->dj = v->kind == GEO_ATTACHED ? m_dot(n, dc) / len : 0.0f;
}

/* The tangent of a vertex's shading normal (v->ds), once its motion (v->dx, with the camera's) is known: the
 * triangle's normal's (flat), or that of m / |m| through the vertex normals' tangents and, for a sliding point,
 * its barycentrics'. */
static inline void geo_shading_motion(const Scene* sc, const Grads* tg, GeoVertex* v) {
    v->ds = v3_scale(v->dn, geo_flip(sc, v));
    if (v->kind != GEO_ATTACHED && v->kind != GEO_SLIDING) return;
    __global const int* vi = sc->tri_vidx + 3 * v->id;
    float b0 = 1.0f - v->b1 - v->b2;
    if (v->kind == GEO_SLIDING) { /* its barycentrics move as it slides over the triangle, D = dx - dp */
        vec3 e1, e2;
        geo_edges(sc, v, &e1, &e2);
        vec3 c = m_cross(e1, e2);
        float len = m_length(c);
        if (len > 0.0f) {
            vec3 n = v3_divs(c, len);
            vec3 dp = v3_add(v3_add(v3_scale(geo_vertex_tangent(sc, tg, v, 0, vi[0]), b0),
                                    v3_scale(geo_vertex_tangent(sc, tg, v, 1, vi[1]), v->b1)),
                             v3_scale(geo_vertex_tangent(sc, tg, v, 2, vi[2]), v->b2));
            vec3 slide = v3_sub(v->dx, dp);
            v->db1 = m_dot(slide, m_cross(e2, n)) / len;
            v->db2 = m_dot(slide, m_cross(n, e1)) / len;
        }
    }
    vec3 n0, n1, n2, m;
    if (!geo_vertex_normals(sc, v, &n0, &n1, &n2, &m)) return;
    vec3 dm = v3_add(v3_add(v3_scale(geo_vnormal_tangent(sc, tg, v, vi[0]), b0),
                            v3_scale(geo_vnormal_tangent(sc, tg, v, vi[1]), v->b1)),
                     v3_scale(geo_vnormal_tangent(sc, tg, v, vi[2]), v->b2));
    dm = v3_add(dm, v3_add(v3_scale(v3_sub(n1, n0), v->db1), v3_scale(v3_sub(n2, n0), v->db2)));
    float lm = m_length(m);
    vec3 ns = v3_divs(m, lm);
    v->ds = v3_divs(v3_sub(dm, v3_scale(ns, m_dot(ns, dm))), lm);
}

/* Forward mode: the tangent of the direction r = d - 2 (ns . d) ns the moving mirror m reflects its ray into. */
static inline vec3 geo_reflected_tangent(const Scene* sc, const GeoVertex* m) {
    vec3 ns = geo_shading_normal(sc, m), d = m->d;
    vec3 dns = m->ds; /* the mirror's normal turns */
    float a = m_dot(dns, d) + m_dot(ns, m->dd);
    return v3_sub(m->dd, v3_scale(v3_add(v3_scale(ns, a), v3_scale(dns, m_dot(ns, d))), 2.0f));
}

/* Forward mode: the log-tangent of the moving mirror m's Fresnel factor (per channel). */
static inline vec3 geo_fresnel_tangent(const Scene* sc, const Bsdf* b, const GeoVertex* m) {
    vec3 dc_dd, dc_dns;
    vec3 slope = geo_fresnel_slope(sc, b, m, &dc_dd, &dc_dns);
    return v3_scale(slope, m_dot(dc_dd, m->dd) + m_dot(dc_dns, m->ds));
}

/* Forward mode: the motion of x's ray (geo_mirror_ray: origin m, direction r) added to x's (dx, after geo_motion;
 * dd the ray's turn), before geo_shading_motion. */
static inline void geo_ray_motion(const Scene* sc, GeoVertex* x, const GeoVertex* m) {
    if (!x->mray) return;
    float nd = m_dot(x->n, x->d);
    if (nd == 0.0f) return;
    x->dd = geo_reflected_tangent(sc, m);
    vec3 u = v3_add(m->dx, v3_scale(x->dd, x->t));
    x->dx = v3_add(x->dx, v3_sub(u, v3_scale(x->d, m_dot(x->n, u) / nd)));
}

/* The tangent of the unit direction from a to b (length r). */
static inline vec3 geo_direction_tangent(const GeoVertex* a, const GeoVertex* b, vec3 w, float r) {
    vec3 d = v3_sub(b->dx, a->dx);
    return v3_divs(v3_sub(d, v3_scale(w, m_dot(w, d))), r);
}

/* The tangent of a direction's local coordinates: dw the world direction's, dn the frame's normal's. */
static inline vec3 geo_local_tangent(Frame f, vec3 w, vec3 dw, vec3 dn) {
    float nw = m_dot(f.n, w);
    return v3(m_dot(f.s, dw) - m_dot(f.s, dn) * nw, m_dot(f.t, dw) - m_dot(f.t, dn) * nw, m_dot(f.n, dw) + m_dot(dn, w));
}

/* The derivative of f(wi, wo) |cos| along local tangents (dwi, dwo), by central differences. */
static inline vec3 geo_bsdf_tangent(const Bsdf* b, vec3 wi, vec3 wo, vec3 dwi, vec3 dwo) {
    float pdf;
    if (geo_diffuse(b)) return wo.z != 0.0f ? v3_scale(bsdf_eval(b, wi, wo, &pdf), dwo.z / wo.z) : v3_splat(0.0f);
    float m = m_max(m_length(dwi), m_length(dwo));
    if (!(m > 0.0f) || !m_isfinite(m)) return v3_splat(0.0f);
    float h = GEO_FD_STEP / m;
    vec3 fp = bsdf_eval(b, m_normalize(v3_add(wi, v3_scale(dwi, h))), m_normalize(v3_add(wo, v3_scale(dwo, h))), &pdf);
    vec3 fm = bsdf_eval(b, m_normalize(v3_sub(wi, v3_scale(dwi, h))), m_normalize(v3_sub(wo, v3_scale(dwo, h))), &pdf);
    if ((max3(fp) > 0.0f) != (max3(fm) > 0.0f)) return v3_splat(0.0f);
    return v3_scale(v3_sub(fp, fm), 0.5f / h);
}

/* The local Jacobian of f(wi, wo) |cos| / f with respect to wo's three local coordinates (columns), for a
 * segment whose far end is not known yet (forward.cl). */
static inline void geo_bsdf_wo_jacobian(const Bsdf* b, vec3 wi, vec3 wo, vec3 f, vec3* jac) {
    if (geo_diffuse(b)) {
        jac[0] = jac[1] = v3_splat(0.0f);
        jac[2] = safe_div3(v3_scale(f, wo.z != 0.0f ? 1.0f / wo.z : 0.0f), f);
        return;
    }
    for (int k = 0; k < 3; k++) {
        vec3 fp = geo_bsdf_moved(b, wi, wo, 3 + k, GEO_FD_STEP), fm = geo_bsdf_moved(b, wi, wo, 3 + k, -GEO_FD_STEP);
        bool straddles = (max3(fp) > 0.0f) != (max3(fm) > 0.0f);
        jac[k] = straddles ? v3_splat(0.0f) : safe_div3(v3_scale(v3_sub(fp, fm), 0.5f / GEO_FD_STEP), f);
    }
}

/* The log-derivative of the area-form factors of segment a -> b other than a's BSDF: b's cosine, 1 / r^2, b's
 * area Jacobian. */
static inline float geo_area_segment_tangent(const GeoVertex* a, const GeoVertex* b, vec3 w, float r, vec3 dw) {
    float cb = m_dot(b->n, w);
    float dcos = cb != 0.0f ? (m_dot(b->dn, w) + m_dot(b->n, dw)) / cb : 0.0f;
    return dcos - 2.0f * m_dot(w, v3_sub(b->dx, a->dx)) / r + b->dj;
}

#endif
