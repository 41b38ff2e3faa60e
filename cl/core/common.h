/* common.h: definitions every pyclpt kernel shares.
 *
 * Floating-point contraction is off so that the same expression compiles to the
 * same arithmetic in every kernel: the megakernel and the wavefront stages must
 * produce bit-identical paths from the same random numbers. */
#ifndef PYCLPT_COMMON_H
#define PYCLPT_COMMON_H

#pragma OPENCL FP_CONTRACT OFF

#include "core/math.h"

#define PI_F 3.14159265358979323846f
#define INV_PI_F 0.31830988618379067154f
#define INV_2PI_F 0.15915494309189533577f
#define INF_F INFINITY

/* Ray offset from a surface, scaled by the hit point's magnitude. */
#define RAY_EPS 1e-4f

static inline vec3 load3(__global const float* p, int i) {
    return v3(p[3 * i + 0], p[3 * i + 1], p[3 * i + 2]);
}

/* Three consecutive floats from p (an RGB triple of a record). */
static inline vec3 rgb_at(__global const float* p) { return v3(p[0], p[1], p[2]); }

static inline void store3(__global float* p, int i, vec3 v) {
    p[3 * i + 0] = v.x;
    p[3 * i + 1] = v.y;
    p[3 * i + 2] = v.z;
}

static inline float max3(vec3 v) { return m_max(v.x, m_max(v.y, v.z)); }

static inline float luminance(vec3 c) {
    return 0.212671f * c.x + 0.715160f * c.y + 0.072169f * c.z;
}

static inline bool all_finite3(vec3 v) {
    return m_isfinite(v.x) && m_isfinite(v.y) && m_isfinite(v.z);
}

#endif
