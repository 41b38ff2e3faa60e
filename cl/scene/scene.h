/* scene.h: the scene as the kernels see it, a set of plain buffers written by
 * pyclpt/scene_buffers.py (the offsets below are mirrored there).
 *
 *   nodes      BVH nodes, 8 * BVH_WIDTH floats each, then leaf packets with BVH_LEAF_PACKETS (bvh.h);
 *              with SCENE_HAS_INSTANCES also the top level and the instance records (instances.h)
 *   tris       triangles in BVH leaf order: v0, e1 = v1 - v0, e2 = v2 - v0 (9 floats)
 *   tri_info   2 ints per triangle: material id | TRI_HAS_* flags, light index or -1
 *   tri_vidx   3 ints per triangle: vertex indices into vnormals / vuvs
 *   vnormals   3 floats per vertex (shading normals)
 *   vuvs       2 floats per vertex
 *   materials  MAT_STRIDE floats per material (bsdf.h)
 *   lights     LIGHT_STRIDE floats per emitter (lights.h)
 *   light_data emitter tables that do not fit a light record (environment-map CDFs, lights.h)
 *   consts     camera, film and environment (CONST_* below)
 *   textures, texels8, texels32   texture records and texels (texture.h)
 */
#ifndef PYCLPT_SCENE_H
#define PYCLPT_SCENE_H

#include "core/common.h"
#include "scene/bvh.h"
#include "scene/bsdf.h"
#include "core/sampling.h"
#include "scene/texture.h"
#include "scene/mask.h"
#ifdef SCENE_HAS_INSTANCES
#include "scene/instances.h"
#endif

#define CONST_CAM_ORIGIN 0
#define CONST_CAM_FORWARD 3
#define CONST_CAM_RIGHT 6  /* scaled by tan(fov_x / 2) */
#define CONST_CAM_UP 9     /* scaled by tan(fov_y / 2) */
#define CONST_WIDTH 12
#define CONST_HEIGHT 13
#define CONST_ENV_RADIANCE 14 /* constant environment (rgb; lights.h reads the light record) */
#define CONST_ENV_LIGHT 17 /* index of the environment in `lights`, or -1 */
#define CONST_NUM_LIGHTS 18
#define CONST_UNIT 19 /* 1.0: the stride of record reads, opaque to the compiler (rgb_at, core/common.h) */
/* the previous frame's camera, as CONST_CAM_*: motion vectors (film/aovs.h); the current one when none moved */
#define CONST_PREV_CAM_ORIGIN 20
#define CONST_PREV_CAM_FORWARD 23
#define CONST_PREV_CAM_RIGHT 26
#define CONST_PREV_CAM_UP 29
#define CONST_LENS_RADIUS 32    /* thinlens: aperture radius */
#define CONST_FOCUS_DISTANCE 33 /* thinlens: the distance in focus, along forward */
#define CONST_FILTER_RADIUS 34  /* the film's reconstruction filter (film/rfilter.h): the tent's radius */
#define CONST_FILTER_TABLE 35   /* FILTER_TABLE + 1 floats: the gaussian's inverse-CDF table */
#define FILTER_TABLE 128
/* the crop window, with -DFILM_CROP (pyclpt.film.crop): the film holds the pixels [x, x + width) x
 * [y, y + height) of the CONST_WIDTH x CONST_HEIGHT image */
#define CONST_CROP_X 164
#define CONST_CROP_Y 165
#define CONST_CROP_WIDTH 166
#define CONST_CROP_HEIGHT 167
/* a splatting film's margin (pyclpt/film/splat.py): its pixels are keyed in the image padded by CONST_FILM_PAD
 * pixels on each side (index (y + pad) (width + 2 pad) + x + pad; 0, the same index, otherwise), and its crop
 * window may reach that far beyond the image */
#define CONST_FILM_PAD 168
#define CONST_COUNT 169

/* Reconstruction filters (pyclpt.scene.model.ReconstructionFilter.kind): -DSCENE_FILTER=kind compiles the
 * tent's or the gaussian's sampling of the pixel offset in (pyclpt/buffers/rfilter.py); without it, the
 * box: a uniform offset, as before filters existed. */
#define FILTER_BOX 0
#define FILTER_TENT 1
#define FILTER_GAUSSIAN 2
#ifndef SCENE_FILTER
#define SCENE_FILTER FILTER_BOX
#endif

/* Camera kinds (pyclpt.scene.model.Camera.kind): -DSCENE_CAMERA=kind compiles a thin lens or an
 * orthographic camera in (pyclpt/buffers/scene.py; without it, a pinhole), so that path_init has no
 * branch on the kind and stays vectorized. Perspective and thin lens: right and up scale the image
 * plane at distance 1 along forward; orthographic: they are the image's half-extent in world units,
 * and rays start on that rectangle and go along forward. */
#define CAMERA_PERSPECTIVE 0
#define CAMERA_THINLENS 1
#define CAMERA_ORTHOGRAPHIC 2
#ifndef SCENE_CAMERA
#define SCENE_CAMERA CAMERA_PERSPECTIVE
#endif

typedef struct {
    __global const float* nodes;
    __global const float* tris;
    __global const int* tri_info;
    __global const int* tri_vidx;
    __global const float* vnormals;
    __global const float* vuvs;
    __global const float* materials;
    __global const float* lights;
    __global const float* light_data;
    __global const float* consts;
    Textures tex;
    int unit; /* 1, read from consts[CONST_UNIT] (rgb_at, core/common.h) */
#ifdef PATH_TRACE /* the megakernel's instrumented render (integrators/path.h); 0 in SCENE_INIT */
    int* bvh_steps;       /* the path's traversal counters (BVH_COUNT, scene/mask.h) */
    __global int* trace;  /* its trace record: word w of bounce b at trace[(w * trace_rows + b) * trace_stride] */
    int trace_stride, trace_rows;
#endif
} Scene;

#define SCENE_PARAMS                                                                       \
    __global const float *scene_nodes, __global const float *scene_tris,                   \
        __global const int *scene_tri_info, __global const int *scene_tri_vidx,            \
        __global const float *scene_vnormals, __global const float *scene_vuvs,            \
        __global const float *scene_materials, __global const float *scene_lights,         \
        __global const float *scene_light_data, __global const float *scene_consts,        \
        __global const float *scene_textures, __global const uchar *scene_texels8,         \
        __global const float *scene_texels32

#define SCENE_INIT                                                                          \
    {scene_nodes, scene_tris, scene_tri_info, scene_tri_vidx, scene_vnormals, scene_vuvs,  \
     scene_materials, scene_lights, scene_light_data, scene_consts,                        \
     {scene_textures, scene_texels8, scene_texels32, (int)scene_consts[CONST_UNIT]},        \
     (int)scene_consts[CONST_UNIT]}

/* What a path needs to know about the point it hit. */
typedef struct {
    vec3 p;       /* position */
    vec3 ng;      /* geometric normal (winding order), unit */
    Frame sh;     /* shading frame */
    vec2 uv;      /* texture coordinates (barycentrics where the mesh has none) */
    int material;
    int light;    /* emitter index of the triangle, or -1 */
} Surface;

static inline Material scene_material(const Scene* sc, int id) { return sc->materials + MAT_STRIDE * id; }

/* The film's pixels: the image's, or with -DFILM_CROP its crop window's. */
static inline int film_pixels(const Scene* sc) {
#ifdef FILM_CROP
    return (int)sc->consts[CONST_CROP_WIDTH] * (int)sc->consts[CONST_CROP_HEIGHT];
#else
    return (int)sc->consts[CONST_WIDTH] * (int)sc->consts[CONST_HEIGHT];
#endif
}

#ifdef DEVICE_CLASS_GPU
/* GPUs: a material's textures looked up apart from its constants (bsdf_textures, then bsdf_textured: bsdf_at's
 * values), so that a wavefront stage can look them up in a step of its own (docs/gpu.md, "The shading stages in
 * steps"): the factors of Bsdf.color and spec, 1 where untextured (which leaves a product unchanged). */
typedef struct {
    vec3 color, spec;
} BsdfTextures;

static inline GPU_INLINE BsdfTextures bsdf_textures(const Scene* sc, const Surface* s) {
    BsdfTextures f;
    f.color = v3_splat(1.0f);
    f.spec = f.color;
#ifdef SCENE_HAS_TEXTURES
    Material m = scene_material(sc, s->material);
    int type = mat_type(m);
    /* one lookup at a time (a loop kept rolled), so that two lookups' texels are not in registers together */
#pragma unroll 1
    for (int k = 0; k < 2; ++k) {
        int t = k == 0 ? mat_color_texture(m, type) : (int)m[MAT_SPEC_TEX];
        if (t < 0) continue;
        vec3 c = tex_eval(&sc->tex, t, s->uv);
        if (k == 0) f.color = c;
        else f.spec = c;
    }
#endif
    return f;
}

static inline GPU_INLINE Bsdf bsdf_textured(const Scene* sc, const Surface* s, BsdfTextures f) {
    Bsdf b = bsdf_from(scene_material(sc, s->material), sc->unit);
#ifdef SCENE_HAS_TEXTURES
    b.color = v3_mul(b.color, f.color);
    b.spec = v3_mul(b.spec, f.spec);
#endif
    return b;
}
#endif

/* The material of a surface with its textures looked up at the surface's uv. */
static inline GPU_INLINE Bsdf bsdf_at(const Scene* sc, const Surface* s) {
#ifdef DEVICE_CLASS_GPU
    /* the textures looked up first, and the material's constants read after them, so that the constants are not
     * in registers together with a lookup's texels */
    return bsdf_textured(sc, s, bsdf_textures(sc, s));
#else
    Material m = scene_material(sc, s->material);
    Bsdf b = bsdf_from(m, sc->unit);
#ifdef SCENE_HAS_TEXTURES /* pyclpt/buffers/materials.py: some reflectance or transmittance is textured */
    int t = mat_color_texture(m, b.type); /* the diffuse reflectance's or the transmittance's */
    if (t >= 0) b.color = v3_mul(b.color, tex_eval(&sc->tex, t, s->uv));
    t = (int)m[MAT_SPEC_TEX];
    if (t >= 0) b.spec = v3_mul(b.spec, tex_eval(&sc->tex, t, s->uv));
#endif
    return b;
#endif
}

/* dp/du of triangle prim from its uvs (Mitsuba's Mesh::compute_surface_interaction); false where the
 * mesh has none or they are degenerate. */
static inline bool tri_dpdu(const Scene* sc, int prim, int info, vec3* dpdu, vec3* dpdv) {
    if (!(info & TRI_HAS_UVS)) return false;
    __global const int* vi = sc->tri_vidx + 3 * prim;
    __global const float* tri = sc->tris + 9 * prim;
    vec3 e1 = rgb_at(tri + 3, sc->unit), e2 = rgb_at(tri + 6, sc->unit);
    vec2 t0 = v2(sc->vuvs[2 * vi[0]], sc->vuvs[2 * vi[0] + 1]);
    vec2 d1 = v2(sc->vuvs[2 * vi[1]] - t0.x, sc->vuvs[2 * vi[1] + 1] - t0.y);
    vec2 d2 = v2(sc->vuvs[2 * vi[2]] - t0.x, sc->vuvs[2 * vi[2] + 1] - t0.y);
    float det = d1.x * d2.y - d1.y * d2.x;
    if (!(m_abs(det) > 1e-12f)) return false;
    float inv = 1.0f / det;
    *dpdu = v3_scale(v3_sub(v3_scale(e1, d2.y), v3_scale(e2, d1.y)), inv);
    *dpdv = v3_scale(v3_sub(v3_scale(e2, d1.x), v3_scale(e1, d2.x)), inv);
    return true;
}

/* Bump mapping (Mitsuba `bumpmap`): displace the surface along the shading normal
 * by scale * height(uv) and take the normal of the displaced surface; the height
 * gradient is a forward difference over one texel (one hundredth of the unit
 * square for procedural textures). Needs the mesh's uv parameterisation. */
static inline GPU_INLINE vec3 bump_normal(const Scene* sc, Material m, int prim, int info, vec2 uv, vec3 ns) {
    int t = (int)m[MAT_BUMP_TEX];
    vec3 dpdu, dpdv;
    if (t < 0 || !tri_dpdu(sc, prim, info, &dpdu, &dpdv)) return ns;
    __global const float* rec = sc->tex.info + TEX_STRIDE * t;
    bool bitmap = (int)rec[TEX_KIND] == TEX_BITMAP;
    /* steps of about a texel: the uv transform's column lengths (its diagonal when it has no skew) */
    float a = rec[TEX_UV], b = rec[TEX_UV + 1], c = rec[TEX_UV + 3], d = rec[TEX_UV + 4];
    float su = c != 0.0f ? m_sqrt(a * a + c * c) : a, sv = b != 0.0f ? m_sqrt(b * b + d * d) : d;
    float du = bitmap ? 1.0f / (rec[TEX_WIDTH] * su) : 0.01f;
    float dv = bitmap ? 1.0f / (rec[TEX_HEIGHT] * sv) : 0.01f;
    float scale = m[MAT_BUMP_SCALE];
    float h = tex_eval1(&sc->tex, t, uv);
    float dhdu = scale * (tex_eval1(&sc->tex, t, v2(uv.x + du, uv.y + 0.0f)) - h) / du;
    float dhdv = scale * (tex_eval1(&sc->tex, t, v2(uv.x + 0.0f, uv.y + dv)) - h) / dv;
    /* tangents made orthogonal to the shading normal, then displaced */
    vec3 pu = v3_add(v3_sub(dpdu, v3_scale(ns, m_dot(ns, dpdu))), v3_scale(ns, dhdu));
    vec3 pv = v3_add(v3_sub(dpdv, v3_scale(ns, m_dot(ns, dpdv))), v3_scale(ns, dhdv));
    vec3 n = m_cross(pu, pv);
    float len = m_length(n);
    if (!(len > 0.0f) || !m_isfinite(len)) return ns;
    n = v3_divs(n, len);
    return m_dot(n, ns) < 0.0f ? v3_neg(n) : n;
}

#ifdef SCENE_HAS_ANISOTROPY
/* Mitsuba's shading frame (SurfaceInteraction::initialize_sh_frame): s = dp/du made orthogonal to the
 * shading normal ns, t = ns x s; dp/du from the triangle's uvs, or coordinate_system(ng).s where the
 * mesh has none (Mitsuba's Mesh::compute_surface_interaction). `fallback` where that degenerates. */
static inline Frame uv_frame(const Scene* sc, int prim, int info, vec3 ng, vec3 ns, Frame fallback) {
    vec3 dpdu, dpdv;
    if (!tri_dpdu(sc, prim, info, &dpdu, &dpdv)) dpdu = frame_from(ng).s;
    vec3 sv = v3_sub(dpdu, v3_scale(ns, m_dot(ns, dpdu)));
    float len = m_length(sv);
    if (!(len > 0.0f) || !m_isfinite(len)) return fallback;
    Frame f;
    f.n = ns;
    f.s = v3_divs(sv, len);
    f.t = m_cross(ns, f.s);
    return f;
}
#endif

/* The surface's geometry at barycentrics u, v of leaf-order triangle prim, in its mesh's space: its position,
 * geometric normal, material, emitter and texture coordinates, without the shading frame (surface_local);
 * *info: the triangle's info word. */
static inline GPU_INLINE Surface surface_geometry_local(const Scene* sc, int prim, float u, float v, int* info) {
    Surface s;
    __global const float* t = sc->tris + 9 * prim;
    vec3 v0 = rgb_at(t, sc->unit), e1 = rgb_at(t + 3, sc->unit), e2 = rgb_at(t + 6, sc->unit);
    s.p = v3_add(v3_add(v0, v3_scale(e1, u)), v3_scale(e2, v));
    s.ng = m_normalize(m_cross(e1, e2));
    *info = sc->tri_info[2 * prim];
    s.material = *info & TRI_MAT_MASK;
    s.light = sc->tri_info[2 * prim + 1];
    s.uv = tri_uv(sc->tri_vidx, sc->vuvs, prim, *info, u, v);
    return s;
}

/* The surface at barycentrics u, v of leaf-order triangle prim, in its mesh's space. */
static inline GPU_INLINE Surface surface_local(const Scene* sc, int prim, float u, float v) {
    int info;
    Surface s = surface_geometry_local(sc, prim, u, v, &info);
    vec3 ns = s.ng;
    if (info & TRI_HAS_NORMALS) {
        int i0 = sc->tri_vidx[3 * prim], i1 = sc->tri_vidx[3 * prim + 1], i2 = sc->tri_vidx[3 * prim + 2];
        vec3 n0 = rgb_at(sc->vnormals + 3 * i0, sc->unit), n1 = rgb_at(sc->vnormals + 3 * i1, sc->unit);
        vec3 n2 = rgb_at(sc->vnormals + 3 * i2, sc->unit);
        vec3 n = v3_add(v3_add(v3_scale(n0, 1.0f - u - v), v3_scale(n1, u)), v3_scale(n2, v));
        float len = m_length(n);
        if (len > 0.0f && m_isfinite(len)) ns = v3_divs(n, len);
    }
#ifdef SCENE_HAS_BUMPMAPS
    ns = bump_normal(sc, scene_material(sc, s.material), prim, info, s.uv, ns);
#endif
    s.sh = frame_from(ns);
#ifdef SCENE_HAS_ANISOTROPY
    if (mat_flags(scene_material(sc, s.material)) & MAT_FLAG_UV_FRAME) s.sh = uv_frame(sc, prim, info, s.ng, ns, s.sh);
#endif
    return s;
}

/* Rebuild the surface from a hit record (hit.prim, barycentrics u, v), in world space. */
#ifdef SCENE_HAS_INSTANCES
/* prim is the packed id of instances.h: the triangle's surface through its instance's transforms
 * (points by object-to-world, normals by its inverse transpose, as Mitsuba's instances). */
static inline int surface_local_prim(const Scene* sc, int prim) { return prim & ((1 << inst_tri_bits(sc->nodes)) - 1); }
static inline __global const float* surface_instance(const Scene* sc, int prim) {
    return inst_record(sc->nodes, prim >> inst_tri_bits(sc->nodes));
}
/* The position and geometric normal of a surface in its mesh's space carried into the world by instance record rec. */
static inline GPU_INLINE void surface_place(__global const float* rec, Surface* s) {
    s->p = inst_point(rec + INST_O2W, s->p);
    s->ng = m_normalize(inst_normal(rec + INST_NORMAL, s->ng));
}
static inline GPU_INLINE Surface surface_at(const Scene* sc, int prim, float u, float v) {
    Surface s = surface_local(sc, surface_local_prim(sc, prim), u, v);
    __global const float* rec = surface_instance(sc, prim);
    surface_place(rec, &s);
    vec3 ns = m_normalize(inst_normal(rec + INST_NORMAL, s.sh.n));
#ifdef SCENE_HAS_ANISOTROPY
    if (mat_flags(scene_material(sc, s.material)) & MAT_FLAG_UV_FRAME) {
        /* the tangent carried into the world (a vector, by object-to-world), orthogonal to the normal */
        vec3 tw = inst_vector(rec + INST_O2W, s.sh.s);
        vec3 sv = v3_sub(tw, v3_scale(ns, m_dot(ns, tw)));
        float len = m_length(sv);
        if (len > 0.0f && m_isfinite(len)) {
            s.sh.n = ns;
            s.sh.s = v3_divs(sv, len);
            s.sh.t = m_cross(ns, s.sh.s);
            return s;
        }
    }
#endif
    s.sh = frame_from(ns);
    return s;
}
#else
static inline GPU_INLINE Surface surface_at(const Scene* sc, int prim, float u, float v) {
    return surface_local(sc, prim, u, v);
}
#endif

/* A two-sided material with a different back (-DSCENE_HAS_BACK_MATERIALS; MAT_FLAG_BACK, Mitsuba `twosided` with
 * two BSDFs) replaced by its back material where wi = -dir is below the shading normal (to_local(s.sh, -dir).z < 0,
 * the test Mitsuba's twosided makes; negation is exact, so the two tests agree to the bit). */
static inline void surface_face(const Scene* sc, Surface* s, vec3 dir) {
#ifdef SCENE_HAS_BACK_MATERIALS
    Material m = scene_material(sc, s->material);
    if ((mat_flags(m) & MAT_FLAG_BACK) && m_dot(dir, s->sh.n) > 0.0f) s->material = (int)m[MAT_BACK];
#endif
}

/* The surface a path's ray along dir hit, on the side it hit (surface_face). */
static inline GPU_INLINE Surface surface_hit(const Scene* sc, int prim, float u, float v, vec3 dir) {
    Surface s = surface_at(sc, prim, u, v);
    surface_face(sc, &s, dir);
    return s;
}

#ifndef SCENE_HAS_ANISOTROPY
/* surface_hit where its shading normal ns is known (a surface_hit's s.sh.n, kept by the wavefront's stages on GPUs:
 * cl/integrators/wavefront/wavefront.h, path_hit_surface): the same Surface without the vertex normals and the bump
 * map. The shading frame is frame_from(ns) in a scene without anisotropic materials (uv_frame). */
static inline GPU_INLINE Surface surface_hit_shaded(const Scene* sc, int prim, float u, float v, vec3 dir, vec3 ns) {
    int info;
#ifdef SCENE_HAS_INSTANCES
    Surface s = surface_geometry_local(sc, surface_local_prim(sc, prim), u, v, &info);
    surface_place(surface_instance(sc, prim), &s);
#else
    Surface s = surface_geometry_local(sc, prim, u, v, &info);
#endif
    s.sh = frame_from(ns);
    surface_face(sc, &s, dir);
    return s;
}
#endif

/* The opacity test of a path's query: dim is DIM_MASK_CLOSEST or DIM_MASK_SHADOW. */
static inline AlphaTest scene_alpha(const Scene* sc, RngKey key, int bounce, uint dim) {
    AlphaTest a = {sc->tri_info, sc->tri_vidx, sc->vuvs, sc->materials, sc->tex, key, (uint)bounce, dim};
#ifdef PATH_TRACE
    a.steps = sc->bvh_steps;
#endif
    return a;
}

/* Closest hit of a path's ray at `bounce`, honouring opacity. */
static inline bool scene_closest(const Scene* sc, RngKey key, int bounce, vec3 org, vec3 dir, Hit* hit) {
    AlphaTest a = scene_alpha(sc, key, bounce, DIM_MASK_CLOSEST);
#ifdef SCENE_HAS_INSTANCES
    return inst_closest(sc->nodes, sc->tris, org, dir, INF_F, hit, &a);
#else
    return bvh_closest_alpha(sc->nodes, sc->tris, org, dir, INF_F, hit, &a);
#endif
}

/* True when a shadow ray of `bounce` is blocked before tmax, honouring opacity. */
static inline bool scene_occluded(const Scene* sc, RngKey key, int bounce, vec3 org, vec3 dir, float tmax) {
    AlphaTest a = scene_alpha(sc, key, bounce, DIM_MASK_SHADOW);
#ifdef SCENE_HAS_INSTANCES
    return inst_any(sc->nodes, sc->tris, org, dir, tmax, &a);
#else
    return bvh_any_alpha(sc->nodes, sc->tris, org, dir, tmax, &a);
#endif
}

/* Origin for a ray leaving s in direction d: offset to d's side of the surface. */
static inline vec3 spawn_origin(const Surface* s, vec3 d) {
    return offset_ray_origin(s->p, m_dot(d, s->ng) >= 0.0f ? s->ng : v3_neg(s->ng));
}

#endif
