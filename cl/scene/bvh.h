/* bvh.h: ray queries against the flattened BVH of pyclpt/accel/bvh.py.
 *
 * BVH_WIDTH (-D, default 8; pyclpt.accel.bvh.DEFAULT_WIDTH, passed with the
 * scene's defines) picks the node layout the buffer holds: 2, 4 or 8 children.
 *
 * Binary node record (16 floats, 64 bytes, read as four float4):
 *   [0:3] left min   [3:6] left max   [6:9] right min   [9:12] right max
 *   [12] left link   [13] right link  (int32 bits)       [14:16] unused
 * link >= 0: internal node index. link with the high bit set: leaf with
 * start = (link & 0x7fffffff) >> 5, count = link & 31 (count 0 = empty child,
 * whose box is inverted and therefore never entered).
 * Wide node record (BVH_WIDTH = W = 4 or 8; 8 * W floats, 128 or 256 bytes, read
 * as eight floatW): lo_x[W] hi_x[W] lo_y[W] hi_y[W] lo_z[W] hi_z[W] link[W]
 * zero[W], the child boxes as structure of arrays so that one work-item tests
 * all W boxes with floatW arithmetic. Links as above; unused children are
 * empty leaves with inverted boxes. Hit children are pushed on the stack
 * sorted far to near and the nearest is visited next.
 * Triangles (9 floats each, leaf order): v0, e1 = v1 - v0, e2 = v2 - v0.
 *
 * Box test: per-ray precomputed reciprocal direction, components of
 * magnitude below 1e-18 (zero, denormal) replaced by +-1e18, so it never holds
 * inf and (bound - org) * inv never forms 0 * inf. The near/far planes are
 * picked by the sign of the reciprocal, which also rejects inverted (empty)
 * boxes. The far distance is scaled up by 1 + 2^-21 so rounding in
 * the slab test cannot cull a box whose triangle the intersector would hit.
 *
 * Triangle test: Moeller-Trumbore without backface culling, with the division
 * deferred until a hit is certain; t must lie in (0, tmax).
 *
 * BVH_LEAF_PACKETS (-D, default 0; wide nodes only; pyclpt.buffers.scene passes 1 for
 * width 8): leaf links are LEAF_BIT | q << 5 | count with q the leaf's first packet
 * record, BVH_PACKET_ROWS (10) rows of BVH_WIDTH words from the start of the node
 * buffer: idx[W] (leaf-order triangle index, int32 bits; -1 = padding) v0x[W] v0y[W]
 * v0z[W] e1x[W] e1y[W] e1z[W] e2x[W] e2y[W] e2z[W], ceil(count / W) records per leaf
 * (pyclpt.accel.bvh.leaf_packet_buffer). A record's W triangles are tested together
 * in floatW arithmetic with the scalar test's operations, in its order, per lane;
 * padding lanes have zero edges (det = 0, never hit). The passing lanes are then
 * taken in leaf order with the scalar loop's rule (re-checked against the current
 * tmax, opacity test per candidate), so the hits are the scalar loop's, bit for bit.
 * `tris` is then not read by the traversal (surface_at and the lights still use it).
 */
#ifndef PYCLPT_BVH_H
#define PYCLPT_BVH_H

#include "core/common.h"
#include "scene/mask.h"

/* The traversal loops count their work through BVH_COUNT(alpha, nodes visited, triangles tested):
 * empty unless -DPATH_TRACE defines it (scene/mask.h; pyclpt/gpu/simt.py). */
#ifndef BVH_COUNT
#define BVH_COUNT(alpha, nodes, prims)
#endif

typedef struct {
    float t;
    float u;
    float v;
    int prim; /* leaf-order triangle index, -1 for none */
} Hit;

#ifndef BVH_WIDTH
#define BVH_WIDTH 8
#endif

#if BVH_WIDTH != 2 && BVH_WIDTH != 4 && BVH_WIDTH != 8
#error "BVH_WIDTH must be 2, 4 or 8"
#endif

/* Stack entries: a node pushes at most BVH_WIDTH - 1, and the builder limits
 * the depth to fit (pyclpt.accel.bvh.STACK_SIZE mirrors these; -DBVH_STACK_SIZE
 * overrides, for a shorter stack with a tree built to fit it). */
#ifndef BVH_STACK_SIZE
#if BVH_WIDTH == 2
#define BVH_STACK_SIZE 64
#elif BVH_WIDTH == 4
#define BVH_STACK_SIZE 128
#else
#define BVH_STACK_SIZE 192
#endif
#endif

/* BVH_STACK_DISTANCES (-D, default 1): the stack holds each subtree's entry distance beside
 * its node, and closest-hit pops skip subtrees not nearer than the current hit (CPU layout).
 * 0 (the GPU layout: pyclpt.accel.bvh.STACK_DISTANCES, docs/bvh.md "Layouts per device class"): node indices only
 * (4 bytes an entry, half the per-thread memory, which GPUs keep in slow local memory), and a
 * popped subtree is culled by testing its children's boxes against the current nearest hit. */
#ifndef BVH_STACK_DISTANCES
#define BVH_STACK_DISTANCES 1
#endif
#define BVH_TFAR_SCALE 1.00000048f /* 1 + 2^-21 */

/* Everything below is written with plain operators rather than builtins
 * (fmin, select, dot, cross, vload*): the PoCL 3.0 binary distribution calls
 * those out of line, which made traversal 2.3x slower. Node records are read
 * through a float4 pointer instead of vload4 (same aligned 16-byte loads on
 * GPUs); this needs `nodes` 16-byte aligned, which every OpenCL buffer start
 * is. */

typedef struct {
    float4 org;       /* xyz; w = 0 */
    float4 inv;       /* reciprocal direction, never 0 or inf; w = 1 */
    int4 neg;         /* -1 where inv < 0: the near plane is the box max */
    float dx, dy, dz; /* direction */
    int nx, ny, nz;   /* 1 where inv < 0 (wide nodes: offset of the near plane's row) */
} BvhRay;

static inline float bvh_safe_rcp(float d) {
    const float tiny = 1e-18f;
    return (d >= tiny || d <= -tiny) ? 1.0f / d : (d < 0.0f ? -1e18f : 1e18f);
}

static inline BvhRay bvh_make_ray(vec3 org, vec3 dir) {
    BvhRay r;
    r.org = (float4)(org.x, org.y, org.z, 0.0f);
    r.inv = (float4)(bvh_safe_rcp(dir.x), bvh_safe_rcp(dir.y), bvh_safe_rcp(dir.z), 1.0f);
    r.neg = r.inv < (float4)(0.0f);
    r.dx = dir.x;
    r.dy = dir.y;
    r.dz = dir.z;
    r.nx = r.inv.x < 0.0f ? 1 : 0;
    r.ny = r.inv.y < 0.0f ? 1 : 0;
    r.nz = r.inv.z < 0.0f ? 1 : 0;
    return r;
}

static inline float bvh_min(float a, float b) { return a < b ? a : b; }
static inline float bvh_max(float a, float b) { return a > b ? a : b; }

/* Entry distance of the ray into box [lo, hi] (xyz; w ignored) clipped to
 * [0, tmax]; +inf when missed, including for inverted (empty) boxes. */
static inline float bvh_box(float4 lo, float4 hi, float4 org, float4 inv, int4 neg, float tmax) {
    float4 tn = ((neg ? hi : lo) - org) * inv;
    float4 tf = ((neg ? lo : hi) - org) * inv;
    float t0 = bvh_max(bvh_max(tn.x, tn.y), bvh_max(tn.z, 0.0f));
    float t1 = bvh_min(bvh_min(tf.x, tf.y), bvh_min(tf.z, tmax)) * BVH_TFAR_SCALE;
    return t0 <= t1 ? t0 : INFINITY;
}

/* Both children of `node`: entry distances (inf = missed) and links. Node
 * records are 64-byte aligned in any OpenCL buffer, so they are read as float4. */
static inline void bvh_node(__global const float* nodes, int node, const BvhRay* r, float tmax,
                            float* tl, float* tr, int* ll, int* lr) {
    __global const float4* p = (__global const float4*)nodes + 4 * node;
    float4 a = p[0]; /* lmin.xyz lmax.x */
    float4 b = p[1]; /* lmax.yz rmin.xy */
    float4 c = p[2]; /* rmin.z rmax.xyz */
    float4 d = p[3]; /* links, padding */
    *tl = bvh_box(a, (float4)(a.w, b.x, b.y, 0.0f), r->org, r->inv, r->neg, tmax);
    *tr = bvh_box((float4)(b.z, b.w, c.x, 0.0f), c.yzwx, r->org, r->inv, r->neg, tmax);
    *ll = as_int(d.x);
    *lr = as_int(d.y);
}

/* Moeller-Trumbore, no backface culling, division deferred until the hit is
 * certain. On a hit with 0 < t < tmax stores t, u, v and returns true. */
static inline bool bvh_triangle(__global const float* tris, int i, const BvhRay* r, float tmax,
                                float* t_out, float* u_out, float* v_out) {
    __global const float* p = tris + 9 * i;
    float v0x = p[0], v0y = p[1], v0z = p[2];
    float e1x = p[3], e1y = p[4], e1z = p[5];
    float e2x = p[6], e2y = p[7], e2z = p[8];
    /* pv = dir x e2, det = e1 . pv */
    float pvx = r->dy * e2z - r->dz * e2y;
    float pvy = r->dz * e2x - r->dx * e2z;
    float pvz = r->dx * e2y - r->dy * e2x;
    float det = e1x * pvx + e1y * pvy + e1z * pvz;
    /* Work with |det| and sign-flipped numerators: no division to reject. */
    float sgn = det < 0.0f ? -1.0f : 1.0f;
    float adet = det * sgn;
    float sx = r->org.x - v0x, sy = r->org.y - v0y, sz = r->org.z - v0z;
    float u = (sx * pvx + sy * pvy + sz * pvz) * sgn;
    if (!(u >= 0.0f && u <= adet)) return false; /* also rejects NaN */
    /* q = s x e1 */
    float qx = sy * e1z - sz * e1y;
    float qy = sz * e1x - sx * e1z;
    float qz = sx * e1y - sy * e1x;
    float v = (r->dx * qx + r->dy * qy + r->dz * qz) * sgn;
    if (!(v >= 0.0f && u + v <= adet)) return false;
    float t = (e2x * qx + e2y * qy + e2z * qz) * sgn;
    if (!(t > 0.0f && adet > 0.0f && t < tmax * adet)) return false;
    float inv = 1.0f / adet;
    float th = t * inv;
    if (!(th < tmax)) return false; /* the scaled compare may round the other way */
    *t_out = th;
    *u_out = u * inv;
    *v_out = v * inv;
    return true;
}

/* The result of a closest-hit traversal: true when something was hit. */
static inline bool bvh_hit_out(Hit* hit, float t, float u, float v, int prim) {
    hit->t = t;
    hit->u = u;
    hit->v = v;
    hit->prim = prim;
    return prim >= 0;
}

/* The leaf `cur` (LEAF_BIT | start << 5 | count), its triangles one at a time in leaf order:
 * a strictly nearer hit that passes the opacity test replaces the best one. */
static inline void bvh_leaf_closest(__global const float* tris, int cur, const BvhRay* r, float* best, float* bu,
                                    float* bv, int* prim, const AlphaTest* alpha) {
    int start = (cur & 0x7fffffff) >> 5;
    int end = start + (cur & 31);
    for (int i = start; i < end; ++i) {
        float t, u, v;
        if (bvh_triangle(tris, i, r, *best, &t, &u, &v) && alpha_accept(alpha, i, u, v)) {
            *best = t;
            *bu = u;
            *bv = v;
            *prim = i;
        }
    }
}

/* True if a triangle of the leaf `cur` that passes the opacity test is hit with 0 < t < tmax. */
static inline bool bvh_leaf_any(__global const float* tris, int cur, const BvhRay* r, float tmax,
                                const AlphaTest* alpha) {
    int start = (cur & 0x7fffffff) >> 5;
    int end = start + (cur & 31);
    for (int i = start; i < end; ++i) {
        float t, u, v;
        if (bvh_triangle(tris, i, r, tmax, &t, &u, &v) && alpha_accept(alpha, i, u, v)) return true;
    }
    return false;
}

#if BVH_WIDTH == 2
/* Closest hit with 0 < t < tmax that passes the opacity test (alpha may be 0: all opaque), in the tree
 * whose root is node `root` (0: the scene's; instances.h: a shapegroup's). On a miss hit->prim = -1 and
 * hit->t = tmax. */
static inline bool bvh_closest_from(__global const float* nodes, __global const float* tris, int root, vec3 org,
                                    vec3 dir, float tmax, Hit* hit, const AlphaTest* alpha) {
    BvhRay r = bvh_make_ray(org, dir);
    int stack_node[BVH_STACK_SIZE];
#if BVH_STACK_DISTANCES
    float stack_t[BVH_STACK_SIZE];
#endif
    int sp = 0;
    float best = tmax;
    float bu = 0.0f, bv = 0.0f;
    int prim = -1;
    int cur = root;
    for (;;) {
        if (cur >= 0) {
            BVH_COUNT(alpha, 1, 0);
            float tl, tr;
            int ll, lr;
            bvh_node(nodes, cur, &r, best, &tl, &tr, &ll, &lr);
            bool hl = tl != INFINITY, hr = tr != INFINITY;
            if (hl && hr) {
                /* Visit the nearer child first; keep the other for later. */
                bool swap = tr < tl;
                cur = swap ? lr : ll;
                stack_node[sp] = swap ? ll : lr;
#if BVH_STACK_DISTANCES
                stack_t[sp] = swap ? tl : tr;
#endif
                ++sp;
                continue;
            }
            if (hl) { cur = ll; continue; }
            if (hr) { cur = lr; continue; }
        } else {
            BVH_COUNT(alpha, 0, cur & 31);
            bvh_leaf_closest(tris, cur, &r, &best, &bu, &bv, &prim, alpha);
        }
#if BVH_STACK_DISTANCES
        /* Pop the next subtree that may still hold something nearer. */
        while (sp > 0 && !(stack_t[sp - 1] < best)) --sp;
#endif
        if (sp == 0) break;
        cur = stack_node[--sp];
    }
    return bvh_hit_out(hit, best, bu, bv, prim);
}

/* True if anything that passes the opacity test is hit with 0 < t < tmax (returns at the first), in the
 * tree whose root is node `root`. */
static inline bool bvh_any_from(__global const float* nodes, __global const float* tris, int root, vec3 org,
                                vec3 dir, float tmax, const AlphaTest* alpha) {
    BvhRay r = bvh_make_ray(org, dir);
    int stack_node[BVH_STACK_SIZE];
    int sp = 0;
    int cur = root;
    for (;;) {
        if (cur >= 0) {
            BVH_COUNT(alpha, 1, 0);
            float tl, tr;
            int ll, lr;
            bvh_node(nodes, cur, &r, tmax, &tl, &tr, &ll, &lr);
            bool hl = tl != INFINITY, hr = tr != INFINITY;
            if (hl && hr) {
                bool swap = tr < tl;
                cur = swap ? lr : ll;
                stack_node[sp++] = swap ? ll : lr;
                continue;
            }
            if (hl) { cur = ll; continue; }
            if (hr) { cur = lr; continue; }
        } else {
            BVH_COUNT(alpha, 0, cur & 31);
            if (bvh_leaf_any(tris, cur, &r, tmax, alpha)) return true;
        }
        if (sp == 0) return false;
        cur = stack_node[--sp];
    }
}

#else /* wide nodes */

#if BVH_WIDTH == 4
typedef float4 BvhVf;
typedef int4 BvhVi;
#define BVH_AS_VI as_int4
#define BVH_EACH(M) M(s0) M(s1) M(s2) M(s3)
#else
typedef float8 BvhVf;
typedef int8 BvhVi;
#define BVH_AS_VI as_int8
#define BVH_EACH(M) M(s0) M(s1) M(s2) M(s3) M(s4) M(s5) M(s6) M(s7)
#endif

static inline BvhVf bvh_vmin(BvhVf a, BvhVf b) { return a < b ? a : b; }
static inline BvhVf bvh_vmax(BvhVf a, BvhVf b) { return a > b ? a : b; }

/* Entry distances of the ray into the BVH_WIDTH child boxes of `node`,
 * clipped to [0, tmax] (INFINITY where missed), and the child links: the
 * binary node's slab test, component for component, on SoA rows. The row
 * of the near plane per axis is picked by the ray's sign (nx, ny, nz). */
static inline BvhVf bvh_wide_node(__global const float* nodes, int node, const BvhRay* r, float tmax,
                                  BvhVi* links) {
    __global const BvhVf* p = (__global const BvhVf*)nodes + 8 * node;
    BvhVf ox = (BvhVf)(r->org.x), oy = (BvhVf)(r->org.y), oz = (BvhVf)(r->org.z);
    BvhVf ix = (BvhVf)(r->inv.x), iy = (BvhVf)(r->inv.y), iz = (BvhVf)(r->inv.z);
    BvhVf tnx = (p[r->nx] - ox) * ix;
    BvhVf tfx = (p[1 - r->nx] - ox) * ix;
    BvhVf tny = (p[2 + r->ny] - oy) * iy;
    BvhVf tfy = (p[3 - r->ny] - oy) * iy;
    BvhVf tnz = (p[4 + r->nz] - oz) * iz;
    BvhVf tfz = (p[5 - r->nz] - oz) * iz;
    BvhVf t0 = bvh_vmax(bvh_vmax(tnx, tny), bvh_vmax(tnz, (BvhVf)(0.0f)));
    BvhVf t1 = bvh_vmin(bvh_vmin(tfx, tfy), bvh_vmin(tfz, (BvhVf)(tmax))) * BVH_TFAR_SCALE;
    *links = BVH_AS_VI(p[6]);
    return t0 <= t1 ? t0 : (BvhVf)(INFINITY);
}

/* Push the hit children of a node (entry distances t, links l) on the stack,
 * sorted so that the nearest is on top; returns how many were pushed. */
static inline int bvh_wide_push(BvhVf t, BvhVi l, int* stack_node, float* stack_t, int sp) {
    int base = sp;
#define BVH_PUSH(c)                   \
    if (t.c != INFINITY) {            \
        stack_node[sp] = l.c;         \
        stack_t[sp] = t.c;            \
        ++sp;                         \
    }
    BVH_EACH(BVH_PUSH)
#undef BVH_PUSH
    /* Insertion sort of the (at most BVH_WIDTH) new entries, far to near. */
    for (int i = base + 1; i < sp; ++i) {
        float kt = stack_t[i];
        int kn = stack_node[i];
        int j = i - 1;
        while (j >= base && stack_t[j] < kt) {
            stack_t[j + 1] = stack_t[j];
            stack_node[j + 1] = stack_node[j];
            --j;
        }
        stack_t[j + 1] = kt;
        stack_node[j + 1] = kn;
    }
    return sp - base;
}

/* BVH_ANY_SORT (-D, default 0): 0, any-hit traversal pushes a node's hit children in child order,
 * node indices only: an occlusion query has no nearest hit to find first, so it skips the sort and
 * the distances (1.0-2.4x the any-hit rate of the shared scenes on CPUs, docs/bvh.md "Against
 * Embree"); 1, sorted far to near as closest hit does. The answer is the same either way (the
 * opacity test of a candidate does not depend on the order candidates are met in). */
#ifndef BVH_ANY_SORT
#define BVH_ANY_SORT 0
#endif

/* The hit children of a node (entry distances t, links l) pushed in child order, without their
 * distances; returns how many were pushed. */
static inline int bvh_wide_push_unsorted(BvhVf t, BvhVi l, int* stack_node, int sp) {
    int base = sp;
#define BVH_PUSH_ANY(c)               \
    if (t.c != INFINITY) stack_node[sp++] = l.c;
    BVH_EACH(BVH_PUSH_ANY)
#undef BVH_PUSH_ANY
    return sp - base;
}

#if !BVH_STACK_DISTANCES
/* The node-only stack: the hit children of a node (entry distances t, links l) are sorted far
 * to near in registers (a sorting network on the W lanes, missed children last) and pushed
 * without their distances, the nearest on top; returns how many were pushed. */
#define BVH_CSWAP(i, j)                                       \
    if (t##i < t##j) {                                        \
        float tt = t##i; t##i = t##j; t##j = tt;              \
        int ll = l##i; l##i = l##j; l##j = ll;                \
    }
#define BVH_PUSH_NODE(i)                                      \
    if (t##i != INFINITY) stack_node[sp++] = l##i;
static inline int bvh_wide_push_nodes(BvhVf t, BvhVi l, int* stack_node, int sp) {
    int base = sp;
    /* missed children (INFINITY) sort first, far to near, and are skipped */
    float t0 = t.s0, t1 = t.s1, t2 = t.s2, t3 = t.s3;
    int l0 = l.s0, l1 = l.s1, l2 = l.s2, l3 = l.s3;
#if BVH_WIDTH == 4
    BVH_CSWAP(0, 1) BVH_CSWAP(2, 3) BVH_CSWAP(0, 2) BVH_CSWAP(1, 3) BVH_CSWAP(1, 2)
    BVH_PUSH_NODE(0) BVH_PUSH_NODE(1) BVH_PUSH_NODE(2) BVH_PUSH_NODE(3)
#else
    float t4 = t.s4, t5 = t.s5, t6 = t.s6, t7 = t.s7;
    int l4 = l.s4, l5 = l.s5, l6 = l.s6, l7 = l.s7;
    BVH_CSWAP(0, 2) BVH_CSWAP(1, 3) BVH_CSWAP(4, 6) BVH_CSWAP(5, 7)
    BVH_CSWAP(0, 4) BVH_CSWAP(1, 5) BVH_CSWAP(2, 6) BVH_CSWAP(3, 7)
    BVH_CSWAP(0, 1) BVH_CSWAP(2, 3) BVH_CSWAP(4, 5) BVH_CSWAP(6, 7)
    BVH_CSWAP(2, 4) BVH_CSWAP(3, 5)
    BVH_CSWAP(1, 4) BVH_CSWAP(3, 6)
    BVH_CSWAP(1, 2) BVH_CSWAP(3, 4) BVH_CSWAP(5, 6)
    BVH_PUSH_NODE(0) BVH_PUSH_NODE(1) BVH_PUSH_NODE(2) BVH_PUSH_NODE(3)
    BVH_PUSH_NODE(4) BVH_PUSH_NODE(5) BVH_PUSH_NODE(6) BVH_PUSH_NODE(7)
#endif
    return sp - base;
}
#undef BVH_CSWAP
#undef BVH_PUSH_NODE
#endif

#ifndef BVH_LEAF_PACKETS
#define BVH_LEAF_PACKETS 0
#endif

#if BVH_LEAF_PACKETS
#if BVH_WIDTH == 4
#define BVH_LANES(M) M(s0, 0) M(s1, 1) M(s2, 2) M(s3, 3)
#else
#define BVH_LANES(M) M(s0, 0) M(s1, 1) M(s2, 2) M(s3, 3) M(s4, 4) M(s5, 5) M(s6, 6) M(s7, 7)
#endif
#define BVH_PACKET_ROWS 10

/* bvh_triangle on BVH_WIDTH triangles at once: the packet record at row `row`
 * (floatW units) of the node buffer is idx[W] v0x v0y v0z e1x e1y e1z e2x e2y e2z,
 * padding lanes have idx -1 and zero edges (det = 0: never hit). Every lane does
 * the scalar test's operations in the same order (no early exits); returns the
 * lanes that pass against tmax, with t (divided), u, v, the undivided t and |det|
 * for the re-check against a nearer tmax. */
static inline BvhVi bvh_packet(__global const BvhVf* p, const BvhRay* r, float tmax, BvhVf* t_out, BvhVf* u_out,
                               BvhVf* v_out, BvhVf* tn_out, BvhVf* adet_out) {
    BvhVf v0x = p[1], v0y = p[2], v0z = p[3];
    BvhVf e1x = p[4], e1y = p[5], e1z = p[6];
    BvhVf e2x = p[7], e2y = p[8], e2z = p[9];
    BvhVf dx = (BvhVf)(r->dx), dy = (BvhVf)(r->dy), dz = (BvhVf)(r->dz);
    BvhVf pvx = dy * e2z - dz * e2y;
    BvhVf pvy = dz * e2x - dx * e2z;
    BvhVf pvz = dx * e2y - dy * e2x;
    BvhVf det = e1x * pvx + e1y * pvy + e1z * pvz;
    BvhVf sgn = det < (BvhVf)(0.0f) ? (BvhVf)(-1.0f) : (BvhVf)(1.0f);
    BvhVf adet = det * sgn;
    BvhVf sx = (BvhVf)(r->org.x) - v0x, sy = (BvhVf)(r->org.y) - v0y, sz = (BvhVf)(r->org.z) - v0z;
    BvhVf u = (sx * pvx + sy * pvy + sz * pvz) * sgn;
    BvhVf qx = sy * e1z - sz * e1y;
    BvhVf qy = sz * e1x - sx * e1z;
    BvhVf qz = sx * e1y - sy * e1x;
    BvhVf v = (dx * qx + dy * qy + dz * qz) * sgn;
    BvhVf t = (e2x * qx + e2y * qy + e2z * qz) * sgn;
    BvhVf zero = (BvhVf)(0.0f);
    BvhVi ok = (u >= zero) & (u <= adet) & (v >= zero) & (u + v <= adet) & (t > zero) & (adet > zero)
               & (t < (BvhVf)(tmax) * adet);
    BvhVf inv = (BvhVf)(1.0f) / adet;
    BvhVf th = t * inv;
    ok = ok & (th < (BvhVf)(tmax));
    *t_out = th;
    *u_out = u * inv;
    *v_out = v * inv;
    *tn_out = t;
    *adet_out = adet;
    return ok;
}

/* The leaf `cur` (LEAF_BIT | packet << 5 | count, packet in units of BVH_PACKET_ROWS rows):
 * closest hit, lanes taken in leaf order with the scalar loop's rule (a lane found against
 * the packet's starting tmax is re-checked against the current one, exactly the scalar test). */
static inline void bvh_packet_leaf_closest(__global const float* nodes, int cur, const BvhRay* r, float* best,
                                           float* bu, float* bv, int* prim, const AlphaTest* alpha) {
    int q = (cur & 0x7fffffff) >> 5;
    int count = cur & 31;
    __global const BvhVf* p = (__global const BvhVf*)nodes + BVH_PACKET_ROWS * q;
    for (int k = 0; k < count; k += BVH_WIDTH, p += BVH_PACKET_ROWS) {
        BvhVf t, u, v, tn, adet;
        BvhVi ok = bvh_packet(p, r, *best, &t, &u, &v, &tn, &adet);
        BvhVi idx = BVH_AS_VI(p[0]);
#define BVH_LANE_CLOSEST(c, j)                                                                     \
        if (ok.c && tn.c < *best * adet.c && t.c < *best && alpha_accept(alpha, idx.c, u.c, v.c)) { \
            *best = t.c;                                                                           \
            *bu = u.c;                                                                             \
            *bv = v.c;                                                                             \
            *prim = idx.c;                                                                         \
        }
        BVH_LANES(BVH_LANE_CLOSEST)
#undef BVH_LANE_CLOSEST
    }
}

static inline bool bvh_packet_leaf_any(__global const float* nodes, int cur, const BvhRay* r, float tmax,
                                       const AlphaTest* alpha) {
    int q = (cur & 0x7fffffff) >> 5;
    int count = cur & 31;
    __global const BvhVf* p = (__global const BvhVf*)nodes + BVH_PACKET_ROWS * q;
    for (int k = 0; k < count; k += BVH_WIDTH, p += BVH_PACKET_ROWS) {
        BvhVf t, u, v, tn, adet;
        BvhVi ok = bvh_packet(p, r, tmax, &t, &u, &v, &tn, &adet);
        BvhVi idx = BVH_AS_VI(p[0]);
#define BVH_LANE_ANY(c, j) \
        if (ok.c && alpha_accept(alpha, idx.c, u.c, v.c)) return true;
        BVH_LANES(BVH_LANE_ANY)
#undef BVH_LANE_ANY
    }
    return false;
}
#endif /* BVH_LEAF_PACKETS */

/* Closest hit with 0 < t < tmax that passes the opacity test (alpha may be 0: all opaque), in the tree
 * whose root is node `root` (0: the scene's; instances.h: a shapegroup's). On a miss hit->prim = -1 and
 * hit->t = tmax. */
static inline bool bvh_closest_from(__global const float* nodes, __global const float* tris, int root, vec3 org,
                                    vec3 dir, float tmax, Hit* hit, const AlphaTest* alpha) {
    BvhRay r = bvh_make_ray(org, dir);
    int stack_node[BVH_STACK_SIZE];
#if BVH_STACK_DISTANCES
    float stack_t[BVH_STACK_SIZE];
#endif
    int sp = 0;
    float best = tmax;
    float bu = 0.0f, bv = 0.0f;
    int prim = -1;
    int cur = root;
    for (;;) {
        if (cur >= 0) {
            BVH_COUNT(alpha, 1, 0);
            BvhVi l;
            BvhVf t = bvh_wide_node(nodes, cur, &r, best, &l);
#if BVH_STACK_DISTANCES
            int n = bvh_wide_push(t, l, stack_node, stack_t, sp);
#else
            int n = bvh_wide_push_nodes(t, l, stack_node, sp);
#endif
            sp += n;
            /* As in the binary traversal: the nearest hit child next, unconditionally. */
            if (n > 0) {
                cur = stack_node[--sp];
                continue;
            }
        } else {
            BVH_COUNT(alpha, 0, cur & 31);
#if BVH_LEAF_PACKETS
            bvh_packet_leaf_closest(nodes, cur, &r, &best, &bu, &bv, &prim, alpha);
#else
            bvh_leaf_closest(tris, cur, &r, &best, &bu, &bv, &prim, alpha);
#endif
        }
#if BVH_STACK_DISTANCES
        /* Pop the next subtree that may still hold something nearer. */
        while (sp > 0 && !(stack_t[sp - 1] < best)) --sp;
#endif
        if (sp == 0) break;
        cur = stack_node[--sp];
    }
    return bvh_hit_out(hit, best, bu, bv, prim);
}

/* True if anything that passes the opacity test is hit with 0 < t < tmax (returns at the first), in the
 * tree whose root is node `root`. */
static inline bool bvh_any_from(__global const float* nodes, __global const float* tris, int root, vec3 org,
                                vec3 dir, float tmax, const AlphaTest* alpha) {
    BvhRay r = bvh_make_ray(org, dir);
    int stack_node[BVH_STACK_SIZE];
#if BVH_STACK_DISTANCES && BVH_ANY_SORT
    float stack_t[BVH_STACK_SIZE];
#endif
    int sp = 0;
    int cur = root;
    for (;;) {
        if (cur >= 0) {
            BVH_COUNT(alpha, 1, 0);
            BvhVi l;
            BvhVf t = bvh_wide_node(nodes, cur, &r, tmax, &l);
#if !BVH_ANY_SORT
            sp += bvh_wide_push_unsorted(t, l, stack_node, sp);
#elif BVH_STACK_DISTANCES
            sp += bvh_wide_push(t, l, stack_node, stack_t, sp);
#else
            sp += bvh_wide_push_nodes(t, l, stack_node, sp);
#endif
        } else {
            BVH_COUNT(alpha, 0, cur & 31);
#if BVH_LEAF_PACKETS
            if (bvh_packet_leaf_any(nodes, cur, &r, tmax, alpha)) return true;
#else
            if (bvh_leaf_any(tris, cur, &r, tmax, alpha)) return true;
#endif
        }
        if (sp == 0) return false;
        cur = stack_node[--sp];
    }
}

#endif /* BVH_WIDTH */

/* The scene's tree (root node 0), honouring opacity. */
static inline bool bvh_closest_alpha(__global const float* nodes, __global const float* tris, vec3 org,
                                     vec3 dir, float tmax, Hit* hit, const AlphaTest* alpha) {
    return bvh_closest_from(nodes, tris, 0, org, dir, tmax, hit, alpha);
}

static inline bool bvh_any_alpha(__global const float* nodes, __global const float* tris, vec3 org,
                                 vec3 dir, float tmax, const AlphaTest* alpha) {
    return bvh_any_from(nodes, tris, 0, org, dir, tmax, alpha);
}

/* The queries without opacity (every triangle opaque). */
static inline bool bvh_closest(__global const float* nodes, __global const float* tris, vec3 org,
                               vec3 dir, float tmax, Hit* hit) {
    return bvh_closest_alpha(nodes, tris, org, dir, tmax, hit, 0);
}

static inline bool bvh_any(__global const float* nodes, __global const float* tris, vec3 org,
                           vec3 dir, float tmax) {
    return bvh_any_alpha(nodes, tris, org, dir, tmax, 0);
}

#endif
