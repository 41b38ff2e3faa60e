/* instances.h: two-level traversal for instanced scenes (Mitsuba shapegroup + instance), compiled in
 * with -DSCENE_HAS_INSTANCES (pyclpt/accel/instances.py builds the buffers; docs/bvh.md "Instances").
 *
 * The node buffer starts with a header (node 0, which no traversal visits; int32 words): the top
 * level's root node, the instance records' first word and the packed id's triangle bits (below), so
 * that one program serves every instanced scene. Then every bottom-level BVH (one per shapegroup and one for the plain
 * meshes, links relocated into one array, one global leaf-order triangle index; leaf packets for
 * width 8), then the top level: a BVH of the same width over the instances' world boxes, whose
 * leaves index instance records, INST_STRIDE words each:
 *   [0:12]  world-to-object 3x4, row-major      [12:24] object-to-world 3x4 (points)
 *   [24:33] inverse transpose of object-to-world's 3x3 (normals)   [33] root node (int32 bits)
 * A ray is taken to object space (direction not normalised, so t is the same in both spaces and one
 * `best` carries across instances) and the instance's bottom level is traversed from its root with
 * bvh.h's own functions. The plain meshes are an instance with the identity transform (exact).
 *
 * A hit's prim is the packed id tri | record << bits (the triangle's global leaf-order index and the
 * instance record; bits from the header), so the hit record, the wavefront's path state and the
 * G-buffer keep their one int; surface_at (scene.h) unpacks it and transforms the surface to world space. */
#ifndef PYCLPT_INSTANCES_H
#define PYCLPT_INSTANCES_H

#include "core/common.h"
#include "scene/bvh.h"

#ifndef SCENE_HAS_INSTANCES
#error "instances.h is compiled in with -DSCENE_HAS_INSTANCES"
#endif

#define INST_STRIDE 36
#define INST_W2O 0
#define INST_O2W 12
#define INST_NORMAL 24
#define INST_ROOT 33
/* header words (pyclpt.accel.instances.HEADER_*) */
#define INST_HEADER_ROOT 0
#define INST_HEADER_RECORDS 1
#define INST_HEADER_TRI_BITS 2

static inline int inst_tri_bits(__global const float* nodes) { return as_int(nodes[INST_HEADER_TRI_BITS]); }

static inline __global const float* inst_record(__global const float* nodes, int r) {
    return nodes + as_int(nodes[INST_HEADER_RECORDS]) + INST_STRIDE * r;
}

/* m: a 3x4 row-major matrix. */
static inline vec3 inst_point(__global const float* m, vec3 p) {
    return v3(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
              m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}

static inline vec3 inst_vector(__global const float* m, vec3 d) {
    return v3(m[0] * d.x + m[1] * d.y + m[2] * d.z, m[4] * d.x + m[5] * d.y + m[6] * d.z,
              m[8] * d.x + m[9] * d.y + m[10] * d.z);
}

/* n: a 3x3 row-major matrix. */
static inline vec3 inst_normal(__global const float* n, vec3 v) { return mat3_mul(n, v); }

/* The opacity test inside instance record r (its random numbers keyed by the packed id). */
static inline const AlphaTest* inst_alpha(const AlphaTest* alpha, int r, int bits, AlphaTest* out) {
    if (alpha == 0) return 0;
    *out = *alpha;
    out->inst_id = (uint)r << bits;
    return out;
}

/* Push the top-level children of node `cur` the ray enters before tmax, nearest on top; returns how many.
 * With -DBVH_STACK_DISTANCES=0 (bvh.h) the stack holds nodes only (stack_t unused). */
#if BVH_STACK_DISTANCES
#define INST_SET_T(i, v) stack_t[i] = (v)
#else
#define INST_SET_T(i, v)
#endif
static inline int inst_push(__global const float* nodes, int cur, const BvhRay* r, float tmax, int* stack_node,
                            float* stack_t, int sp) {
#if BVH_WIDTH == 2
    float tl, tr;
    int ll, lr;
    bvh_node(nodes, cur, r, tmax, &tl, &tr, &ll, &lr);
    bool hl = tl != INFINITY, hr = tr != INFINITY;
    if (hl && hr) {
        bool swap = tr < tl;
        stack_node[sp] = swap ? ll : lr;
        INST_SET_T(sp, swap ? tl : tr);
        stack_node[sp + 1] = swap ? lr : ll;
        INST_SET_T(sp + 1, swap ? tr : tl);
        return 2;
    }
    stack_node[sp] = hl ? ll : lr;
    INST_SET_T(sp, hl ? tl : tr);
    return (hl || hr) ? 1 : 0;
#else
    BvhVi l;
    BvhVf t = bvh_wide_node(nodes, cur, r, tmax, &l);
#if BVH_STACK_DISTANCES
    return bvh_wide_push(t, l, stack_node, stack_t, sp);
#else
    return bvh_wide_push_nodes(t, l, stack_node, sp);
#endif
#endif
}
#undef INST_SET_T

/* The top level's stack of distances: one entry with the node-only stack (never read). */
#if BVH_STACK_DISTANCES
#define INST_STACK_T BVH_STACK_SIZE
#else
#define INST_STACK_T 1
#endif

/* Closest hit with 0 < t < tmax over every instance; hit->prim is the packed id (-1 on a miss). */
static inline bool inst_closest(__global const float* nodes, __global const float* tris, vec3 org, vec3 dir,
                                float tmax, Hit* hit, const AlphaTest* alpha) {
    BvhRay r = bvh_make_ray(org, dir);
    int stack_node[BVH_STACK_SIZE];
    float stack_t[INST_STACK_T];
    int sp = 0;
    float best = tmax, bu = 0.0f, bv = 0.0f;
    int id = -1;
    int bits = inst_tri_bits(nodes);
    int cur = as_int(nodes[INST_HEADER_ROOT]);
    for (;;) {
        if (cur >= 0) {
            int n = inst_push(nodes, cur, &r, best, stack_node, stack_t, sp);
            sp += n;
            if (n > 0) {
                cur = stack_node[--sp];
                continue;
            }
        } else {
            int start = (cur & 0x7fffffff) >> 5;
            for (int k = start; k < start + (cur & 31); ++k) {
                __global const float* rec = inst_record(nodes, k);
                AlphaTest a;
                Hit h;
                if (bvh_closest_from(nodes, tris, as_int(rec[INST_ROOT]), inst_point(rec + INST_W2O, org),
                                     inst_vector(rec + INST_W2O, dir), best, &h, inst_alpha(alpha, k, bits, &a))) {
                    best = h.t;
                    bu = h.u;
                    bv = h.v;
                    id = h.prim | (k << bits);
                }
            }
        }
#if BVH_STACK_DISTANCES
        while (sp > 0 && !(stack_t[sp - 1] < best)) --sp;
#endif
        if (sp == 0) break;
        cur = stack_node[--sp];
    }
    return bvh_hit_out(hit, best, bu, bv, id);
}

/* True if any instance has a hit that passes the opacity test with 0 < t < tmax. */
static inline bool inst_any(__global const float* nodes, __global const float* tris, vec3 org, vec3 dir,
                            float tmax, const AlphaTest* alpha) {
    BvhRay r = bvh_make_ray(org, dir);
    int stack_node[BVH_STACK_SIZE];
    float stack_t[INST_STACK_T];
    int sp = 0;
    int bits = inst_tri_bits(nodes);
    int cur = as_int(nodes[INST_HEADER_ROOT]);
    for (;;) {
        if (cur >= 0) {
            sp += inst_push(nodes, cur, &r, tmax, stack_node, stack_t, sp);
        } else {
            int start = (cur & 0x7fffffff) >> 5;
            for (int k = start; k < start + (cur & 31); ++k) {
                __global const float* rec = inst_record(nodes, k);
                AlphaTest a;
                if (bvh_any_from(nodes, tris, as_int(rec[INST_ROOT]), inst_point(rec + INST_W2O, org),
                                 inst_vector(rec + INST_W2O, dir), tmax, inst_alpha(alpha, k, bits, &a)))
                    return true;
            }
        }
        if (sp == 0) return false;
        cur = stack_node[--sp];
    }
}

#endif
