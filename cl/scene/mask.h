/* mask.h: stochastic opacity (Mitsuba's `mask` material), tested while a ray
 * traverses the BVH, so closest-hit and shadow queries both honour it.
 *
 * A candidate hit on a triangle flagged TRI_MASKED is kept with probability
 * equal to its material's opacity at the hit's uv; the decision's random
 * number is a pure function of (seed, pixel, sample, bounce, query, triangle),
 * like every other random number, so every integrator makes the same choice.
 * Without -DSCENE_HAS_MASKS the test compiles away. */
#ifndef PYCLPT_MASK_H
#define PYCLPT_MASK_H

#include "core/common.h"
#include "core/rng.h"
#include "scene/texture.h"
#include "scene/bsdf.h"

/* tri_info[2 * prim] holds the material id and these flags */
#define TRI_MAT_MASK 0x00ffffff
#define TRI_HAS_NORMALS (1 << 24)
#define TRI_HAS_UVS (1 << 25)
#define TRI_MASKED (1 << 26) /* material has an opacity */

/* What the opacity test needs: the scene's triangle, material and texture data and
 * the random-number key of the path and its query (DIM_MASK_CLOSEST or DIM_MASK_SHADOW). */
typedef struct {
    __global const int* tri_info;
    __global const int* tri_vidx;
    __global const float* vuvs;
    __global const float* materials;
    Textures tex;
    RngKey key;
    uint bounce;
    uint dim;
#ifdef SCENE_HAS_INSTANCES
    uint inst_id; /* the instance's bits of a hit's packed id (instances.h): instances draw apart */
#endif
#ifdef PATH_TRACE
    int* steps; /* the traversal's counters (BVH_COUNT below): nodes visited, triangles tested; or 0 */
#endif
} AlphaTest;

/* -DPATH_TRACE (the megakernel's instrumented render, integrators/path.h; pyclpt/gpu/simt.py): the
 * traversal loops of bvh.h count their work through BVH_COUNT, which every query reaches through
 * its opacity test record (scene_alpha in scene.h points it at the path's counters). Without the
 * define BVH_COUNT is empty (bvh.h) and nothing here exists. */
#ifdef PATH_TRACE
#define BVH_COUNT(alpha, nodes, prims)                                  \
    do {                                                                \
        if ((alpha) != 0 && (alpha)->steps != 0) {                      \
            (alpha)->steps[0] += (nodes);                               \
            (alpha)->steps[1] += (prims);                               \
        }                                                               \
    } while (0)
#endif

/* Texture coordinates of barycentrics (u, v) on leaf-order triangle prim
 * (the barycentrics themselves where the mesh has none). */
static inline vec2 tri_uv(__global const int* tri_vidx, __global const float* vuvs, int prim, int info,
                            float u, float v) {
    if (!(info & TRI_HAS_UVS)) return v2(u, v);
    __global const int* vi = tri_vidx + 3 * prim;
    __global const float* t0 = vuvs + 2 * vi[0];
    __global const float* t1 = vuvs + 2 * vi[1];
    __global const float* t2 = vuvs + 2 * vi[2];
    float w = 1.0f - u - v;
    return v2(w * t0[0] + u * t1[0] + v * t2[0], w * t0[1] + u * t1[1] + v * t2[1]);
}

/* Opacity of a material at uv (1 = opaque). */
static inline float material_opacity(const Textures* tx, Material m, vec2 uv) {
    int t = (int)m[MAT_OPACITY_TEX];
    float o = t >= 0 ? m[MAT_OPACITY] * tex_opacity(tx, t, uv) : m[MAT_OPACITY];
    return m_clamp(o, 0.0f, 1.0f);
}

/* False when the ray passes through the candidate hit (prim, u, v). */
static inline bool alpha_accept(const AlphaTest* a, int prim, float u, float v) {
#ifdef SCENE_HAS_MASKS
    if (a == 0) return true;
    int info = a->tri_info[2 * prim];
    if (!(info & TRI_MASKED)) return true;
    Material m = a->materials + MAT_STRIDE * (info & TRI_MAT_MASK);
    float opacity = material_opacity(&a->tex, m, tri_uv(a->tri_vidx, a->vuvs, prim, info, u, v));
    if (opacity >= 1.0f) return true;
    if (opacity <= 0.0f) return false;
#ifdef SCENE_HAS_INSTANCES
    return rng_1d_at(a->key, a->bounce, a->dim, (uint)prim | a->inst_id) < opacity;
#else
    return rng_1d_at(a->key, a->bounce, a->dim, (uint)prim) < opacity;
#endif
#else
    return true;
#endif
}

#endif
