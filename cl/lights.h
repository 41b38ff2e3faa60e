/* lights.h: emitters. Each is LIGHT_STRIDE floats in the `lights` buffer:
 * emissive triangles (one-sided area lights, Mitsuba's `area` emitter) and the
 * constant environment. One emitter is chosen by the cumulative `cdf` column
 * (proportional to emitted power, written by pyclpt/scene_buffers.py). */
#ifndef PYCLPT_LIGHTS_H
#define PYCLPT_LIGHTS_H

#include "scene.h"

#define LIGHT_STRIDE 8
#define LIGHT_PRIM 0     /* leaf-order triangle (int bits), -1 for the environment */
#define LIGHT_PMF 1      /* probability of choosing this emitter */
#define LIGHT_AREA 2
#define LIGHT_RADIANCE 3 /* rgb */
#define LIGHT_CDF 6      /* inclusive cumulative pmf */

typedef struct {
    float3 wi;       /* unit direction from the shading point to the emitter */
    float dist;      /* distance to the sampled point (INF for the environment) */
    float3 radiance; /* emitted radiance towards the shading point */
    float pdf;       /* solid-angle pdf, emitter choice included */
} LightSample;

static inline int num_lights(const Scene* sc) { return (int)sc->consts[CONST_NUM_LIGHTS]; }

static inline int light_choose(const Scene* sc, float u) {
    int lo = 0, hi = num_lights(sc) - 1;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (u < sc->lights[LIGHT_STRIDE * mid + LIGHT_CDF]) hi = mid;
        else lo = mid + 1;
    }
    return lo;
}

/* Solid-angle pdf that light sampling gives the point y on emissive triangle `light`,
 * seen from distance dist with cosine cos_l at the emitter. */
static inline float light_pdf_area(const Scene* sc, int light, float dist, float cos_l) {
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    if (cos_l <= 0.0f) return 0.0f;
    return l[LIGHT_PMF] * dist * dist / (l[LIGHT_AREA] * cos_l);
}

static inline float light_pdf_env(const Scene* sc) {
    int env = (int)sc->consts[CONST_ENV_LIGHT];
    return env < 0 ? 0.0f : sc->lights[LIGHT_STRIDE * env + LIGHT_PMF] * UNIFORM_SPHERE_PDF;
}

static inline float3 env_radiance(const Scene* sc) {
    return (float3)(sc->consts[CONST_ENV_RADIANCE], sc->consts[CONST_ENV_RADIANCE + 1],
                    sc->consts[CONST_ENV_RADIANCE + 2]);
}

/* Sample an emitter and a point on it as seen from p; false when the sample carries nothing. */
static inline bool light_sample(const Scene* sc, float3 p, float u_select, float2 u, LightSample* ls) {
    int n = num_lights(sc);
    if (n == 0) return false;
    int id = light_choose(sc, u_select);
    __global const float* l = sc->lights + LIGHT_STRIDE * id;
    int prim = as_int(l[LIGHT_PRIM]);
    if (prim < 0) {
        ls->wi = square_to_uniform_sphere(u);
        ls->dist = INF_F;
        ls->radiance = env_radiance(sc);
        ls->pdf = l[LIGHT_PMF] * UNIFORM_SPHERE_PDF;
        return ls->pdf > 0.0f;
    }
    __global const float* t = sc->tris + 9 * prim;
    float3 v0 = (float3)(t[0], t[1], t[2]);
    float3 e1 = (float3)(t[3], t[4], t[5]);
    float3 e2 = (float3)(t[6], t[7], t[8]);
    float2 b = square_to_triangle(u);
    float3 y = v0 + b.x * e1 + b.y * e2;
    float3 ng = normalize(cross(e1, e2));
    float3 d = y - p;
    float dist2 = dot(d, d);
    if (!(dist2 > 0.0f)) return false;
    ls->dist = sqrt(dist2);
    ls->wi = d / ls->dist;
    float cos_l = -dot(ls->wi, ng);
    ls->pdf = light_pdf_area(sc, id, ls->dist, cos_l);
    ls->radiance = (float3)(l[LIGHT_RADIANCE], l[LIGHT_RADIANCE + 1], l[LIGHT_RADIANCE + 2]);
    return ls->pdf > 0.0f;
}

/* Radiance an emissive triangle sends along -dir (one-sided: front faces only). */
static inline float3 light_emitted(const Scene* sc, int light, float3 ng, float3 dir) {
    if (light < 0 || dot(ng, dir) >= 0.0f) return (float3)(0.0f);
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    return (float3)(l[LIGHT_RADIANCE], l[LIGHT_RADIANCE + 1], l[LIGHT_RADIANCE + 2]);
}

#endif
