/* sampling.h: warping uniform numbers to directions and points, frames, MIS. */
#ifndef PYCLPT_SAMPLING_H
#define PYCLPT_SAMPLING_H

#include "core/common.h"

/* Orthonormal frame around n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"). */
typedef struct {
    vec3 s, t, n;
} Frame;

static inline Frame frame_from(vec3 n) {
    float sign = m_copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    Frame f;
    f.s = v3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    f.t = v3(b, sign + n.y * n.y * a, -n.y);
    f.n = n;
    return f;
}

static inline vec3 to_local(Frame f, vec3 v) { return v3(m_dot(v, f.s), m_dot(v, f.t), m_dot(v, f.n)); }
static inline vec3 to_world(Frame f, vec3 v) {
    return v3_add(v3_add(v3_scale(f.s, v.x), v3_scale(f.t, v.y)), v3_scale(f.n, v.z));
}

/* Shirley-Chiu concentric mapping of [0,1)^2 to the unit disk. */
static inline vec2 square_to_disk_concentric(vec2 u) {
    float ox = 2.0f * u.x - 1.0f, oy = 2.0f * u.y - 1.0f;
    /* selects, not branches: both quotients are computed (a NaN for o = 0 is never chosen).
     * |ox| > |oy| as (ox - oy)(ox + oy) > 0: the same decision for every u (ox, oy are multiples of
     * 2^-23 in [-1, 1], so neither factor rounds to or past zero and the product cannot underflow),
     * but not a comparison of two alike expressions, which LLVM's SLP vectorizer would pair into a
     * <2 x float> operation that stops PoCL's vectorizer (docs/wavefront.md). */
    bool x_major = (ox - oy) * (ox + oy) > 0.0f;
    float r = x_major ? ox : oy;
    float theta = x_major ? (PI_F / 4.0f) * (oy / ox) : (PI_F / 2.0f) - (PI_F / 4.0f) * (ox / oy);
    float c, s = m_sincos(theta, &c);
    bool centre = ox == 0.0f && oy == 0.0f;
    return v2(centre ? 0.0f : r * c, centre ? 0.0f : r * s);
}

static inline vec3 square_to_cosine_hemisphere(vec2 u) {
    vec2 d = square_to_disk_concentric(u);
    float z = m_sqrt(m_max(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return v3(d.x, d.y, z);
}

static inline float cosine_hemisphere_pdf(vec3 v) { return v.z > 0.0f ? v.z * INV_PI_F : 0.0f; }

static inline vec3 square_to_uniform_sphere(vec2 u) {
    float z = 1.0f - 2.0f * u.x;
    float r = m_sqrt(m_max(0.0f, 1.0f - z * z));
    float phi = 2.0f * PI_F * u.y;
    float c, s = m_sincos(phi, &c);
    return v3(r * c, r * s, z);
}

#define UNIFORM_SPHERE_PDF (0.25f * INV_PI_F)

/* Uniform barycentrics (b1, b2) on a triangle. */
static inline vec2 square_to_triangle(vec2 u) {
    float su = m_sqrt(u.x);
    return v2(1.0f - su, u.y * su);
}

static inline float power_heuristic(float pdf_a, float pdf_b) {
    float a2 = pdf_a * pdf_a, b2 = pdf_b * pdf_b;
    return a2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* Offset a ray origin off a surface along its geometric normal so that the new
 * ray cannot hit the surface it leaves (Waechter & Binder, Ray Tracing Gems ch. 6). */
static inline float offset_ray_coord(float p, float n) {
    const float origin = 1.0f / 32.0f, float_scale = 1.0f / 65536.0f, int_scale = 256.0f;
    int of = (int)(int_scale * n);
    float p_i = as_float(as_int(p) + ((p < 0.0f) ? -of : of));
    return m_abs(p) < origin ? p + float_scale * n : p_i;
}

static inline vec3 offset_ray_origin(vec3 p, vec3 ng) {
    return v3(offset_ray_coord(p.x, ng.x), offset_ray_coord(p.y, ng.y), offset_ray_coord(p.z, ng.z));
}

#endif
