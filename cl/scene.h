/* scene.h: the scene as the kernels see it, a set of plain buffers written by
 * pyclpt/scene_buffers.py (the offsets below are mirrored there).
 *
 *   nodes      BVH nodes, 16 floats each (bvh.h)
 *   tris       triangles in BVH leaf order: v0, e1 = v1 - v0, e2 = v2 - v0 (9 floats)
 *   tri_info   2 ints per triangle: material id | TRI_HAS_* flags, light index or -1
 *   tri_vidx   3 ints per triangle: vertex indices into vnormals / vuvs
 *   vnormals   3 floats per vertex (shading normals)
 *   vuvs       2 floats per vertex
 *   materials  MAT_STRIDE floats per material (bsdf.h)
 *   lights     LIGHT_STRIDE floats per emitter (lights.h)
 *   consts     camera, film and environment (CONST_* below)
 */
#ifndef PYCLPT_SCENE_H
#define PYCLPT_SCENE_H

#include "common.h"
#include "bvh.h"
#include "bsdf.h"
#include "sampling.h"

#define TRI_MAT_MASK 0x00ffffff
#define TRI_HAS_NORMALS (1 << 24)
#define TRI_HAS_UVS (1 << 25)

#define CONST_CAM_ORIGIN 0
#define CONST_CAM_FORWARD 3
#define CONST_CAM_RIGHT 6  /* scaled by tan(fov_x / 2) */
#define CONST_CAM_UP 9     /* scaled by tan(fov_y / 2) */
#define CONST_WIDTH 12
#define CONST_HEIGHT 13
#define CONST_ENV_RADIANCE 14
#define CONST_ENV_LIGHT 17 /* index of the environment in `lights`, or -1 */
#define CONST_NUM_LIGHTS 18
#define CONST_COUNT 20

typedef struct {
    __global const float* nodes;
    __global const float* tris;
    __global const int* tri_info;
    __global const int* tri_vidx;
    __global const float* vnormals;
    __global const float* vuvs;
    __global const float* materials;
    __global const float* lights;
    __global const float* consts;
} Scene;

#define SCENE_PARAMS                                                                       \
    __global const float *scene_nodes, __global const float *scene_tris,                   \
        __global const int *scene_tri_info, __global const int *scene_tri_vidx,            \
        __global const float *scene_vnormals, __global const float *scene_vuvs,            \
        __global const float *scene_materials, __global const float *scene_lights,         \
        __global const float *scene_consts

#define SCENE_INIT                                                                          \
    {scene_nodes, scene_tris, scene_tri_info, scene_tri_vidx, scene_vnormals, scene_vuvs,  \
     scene_materials, scene_lights, scene_consts}

/* What a path needs to know about the point it hit. */
typedef struct {
    float3 p;     /* position */
    float3 ng;    /* geometric normal (winding order), unit */
    Frame sh;     /* shading frame */
    int material;
    int light;    /* emitter index of the triangle, or -1 */
} Surface;

static inline Material scene_material(const Scene* sc, int id) { return sc->materials + MAT_STRIDE * id; }

/* Rebuild the surface from a hit record (leaf-order triangle, barycentrics u, v). */
static inline Surface surface_at(const Scene* sc, int prim, float u, float v) {
    Surface s;
    __global const float* t = sc->tris + 9 * prim;
    float3 v0 = (float3)(t[0], t[1], t[2]);
    float3 e1 = (float3)(t[3], t[4], t[5]);
    float3 e2 = (float3)(t[6], t[7], t[8]);
    s.p = v0 + u * e1 + v * e2;
    s.ng = normalize(cross(e1, e2));
    int info = sc->tri_info[2 * prim];
    s.material = info & TRI_MAT_MASK;
    s.light = sc->tri_info[2 * prim + 1];
    float3 ns = s.ng;
    if (info & TRI_HAS_NORMALS) {
        int i0 = sc->tri_vidx[3 * prim], i1 = sc->tri_vidx[3 * prim + 1], i2 = sc->tri_vidx[3 * prim + 2];
        float3 n = (1.0f - u - v) * load3(sc->vnormals, i0) + u * load3(sc->vnormals, i1) +
                   v * load3(sc->vnormals, i2);
        float len = length(n);
        if (len > 0.0f && isfinite(len)) ns = n / len;
    }
    s.sh = frame_from(ns);
    return s;
}

/* Origin for a ray leaving s in direction d: offset to d's side of the surface. */
static inline float3 spawn_origin(const Surface* s, float3 d) {
    return offset_ray_origin(s->p, dot(d, s->ng) >= 0.0f ? s->ng : -s->ng);
}

#endif
