/* sampling.h: warping uniform numbers to directions and points, frames, MIS. */
#ifndef PYCLPT_SAMPLING_H
#define PYCLPT_SAMPLING_H

#include "core/common.h"

/* Orthonormal frame around n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"). */
typedef struct {
    float3 s, t, n;
} Frame;

static inline Frame frame_from(float3 n) {
    float sign = m_copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    Frame f;
    f.s = (float3)(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    f.t = (float3)(b, sign + n.y * n.y * a, -n.y);
    f.n = n;
    return f;
}

static inline float3 to_local(Frame f, float3 v) { return (float3)(m_dot(v, f.s), m_dot(v, f.t), m_dot(v, f.n)); }
static inline float3 to_world(Frame f, float3 v) { return f.s * v.x + f.t * v.y + f.n * v.z; }

/* Shirley-Chiu concentric mapping of [0,1)^2 to the unit disk. */
static inline float2 square_to_disk_concentric(float2 u) {
    float2 o = 2.0f * u - 1.0f;
    if (o.x == 0.0f && o.y == 0.0f) return (float2)(0.0f, 0.0f);
    float r, theta;
    if (m_abs(o.x) > m_abs(o.y)) {
        r = o.x;
        theta = (PI_F / 4.0f) * (o.y / o.x);
    } else {
        r = o.y;
        theta = (PI_F / 2.0f) - (PI_F / 4.0f) * (o.x / o.y);
    }
    float c, s = m_sincos(theta, &c);
    return r * (float2)(c, s);
}

static inline float3 square_to_cosine_hemisphere(float2 u) {
    float2 d = square_to_disk_concentric(u);
    float z = m_sqrt(m_max(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return (float3)(d.x, d.y, z);
}

static inline float cosine_hemisphere_pdf(float3 v) { return v.z > 0.0f ? v.z * INV_PI_F : 0.0f; }

static inline float3 square_to_uniform_sphere(float2 u) {
    float z = 1.0f - 2.0f * u.x;
    float r = m_sqrt(m_max(0.0f, 1.0f - z * z));
    float phi = 2.0f * PI_F * u.y;
    float c, s = m_sincos(phi, &c);
    return (float3)(r * c, r * s, z);
}

#define UNIFORM_SPHERE_PDF (0.25f * INV_PI_F)

/* Uniform barycentrics (b1, b2) on a triangle. */
static inline float2 square_to_triangle(float2 u) {
    float su = m_sqrt(u.x);
    return (float2)(1.0f - su, u.y * su);
}

static inline float power_heuristic(float pdf_a, float pdf_b) {
    float a2 = pdf_a * pdf_a, b2 = pdf_b * pdf_b;
    return a2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* Offset a ray origin off a surface along its geometric normal so that the new
 * ray cannot hit the surface it leaves (Waechter & Binder, Ray Tracing Gems ch. 6). */
static inline float3 offset_ray_origin(float3 p, float3 ng) {
    const float origin = 1.0f / 32.0f, float_scale = 1.0f / 65536.0f, int_scale = 256.0f;
    int3 of = (int3)((int)(int_scale * ng.x), (int)(int_scale * ng.y), (int)(int_scale * ng.z));
    float3 p_i = (float3)(
        as_float(as_int(p.x) + ((p.x < 0.0f) ? -of.x : of.x)),
        as_float(as_int(p.y) + ((p.y < 0.0f) ? -of.y : of.y)),
        as_float(as_int(p.z) + ((p.z < 0.0f) ? -of.z : of.z)));
    return (float3)(m_abs(p.x) < origin ? p.x + float_scale * ng.x : p_i.x,
                    m_abs(p.y) < origin ? p.y + float_scale * ng.y : p_i.y,
                    m_abs(p.z) < origin ? p.z + float_scale * ng.z : p_i.z);
}

#endif
