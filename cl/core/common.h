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

/* SCALAR_KERNEL: a kernel that Intel's CPU runtime must not vectorize across work-items. Its compiler
 * runs several work-items in the SIMD lanes of one thread, which pays for straight-line stages
 * (sample_bsdf 3x, process_hit 2.3x) but not where a loop of data-dependent length runs per work-item
 * (BVH traversal: intersect 0.5x, shadow_test 0.3x; the megakernel's bounce loop: 0.55x), since
 * every lane waits for the longest: docs/devices.md. intel_vec_len_hint(1) (extension
 * cl_intel_vec_len_hint, whose macro Intel's compiler defines) keeps those scalar; elsewhere it is
 * nothing. */
#ifdef cl_intel_vec_len_hint
#define SCALAR_KERNEL __attribute__((intel_vec_len_hint(1)))
#else
#define SCALAR_KERNEL
#endif

/* GPU_INLINE: functions a GPU compiler must inline (-DDEVICE_CLASS_GPU, the GPU layout: docs/gpu.md).
 * A call that passes the address of a private struct keeps the struct on the per-thread stack, which
 * GPUs place in slow local memory (the texture lookup put 88 bytes there in the traversal kernels).
 * CPU builds are unchanged. */
#ifdef DEVICE_CLASS_GPU
#define GPU_INLINE __attribute__((always_inline))
#else
#define GPU_INLINE
#endif

/* ALWAYS_INLINE: a function inlined wherever it is called, on every device (the backward pass's walk, called with a
 * constant `replay` at two places: cl/gradients/backward.cl). Not in a build without optimisation (-cl-opt-disable,
 * Oclgrind's): its interpreter cannot create a kernel into which a function with pointer arguments was inlined at
 * -O0 (llvm.experimental.noalias.scope.decl). */
#ifdef __OPTIMIZE__
#define ALWAYS_INLINE __attribute__((always_inline))
#else
#define ALWAYS_INLINE
#endif

/* Ray offset from a surface, scaled by the hit point's magnitude. */
#define RAY_EPS 1e-4f

static inline vec3 load3(__global const float* p, int i) {
    return v3(p[3 * i + 0], p[3 * i + 1], p[3 * i + 2]);
}

/* Three consecutive floats of a record (an RGB triple, a position): p[0], p[unit], p[2 unit], where
 * unit is 1 read at run time (Scene.unit, from the CONST_UNIT slot of the scene's constants). PoCL
 * runs LLVM's SLP vectorizer on each work-item function before it vectorizes the loop over
 * work-items; loads the compiler can prove adjacent let SLP pair x and y into <2 x float>
 * operations, and one such instruction stops the loop vectorizer (docs/wavefront.md,
 * "Vectorized stages"). Through an opaque stride they stay scalar, and the work-item loop
 * vectorizes. Costs nothing on a GPU. */
static inline vec3 rgb_at(__global const float* p, int unit) { return v3(p[0], p[unit], p[2 * unit]); }

/* A 3x3 row-major matrix in a buffer times v, and its transpose times v. */
static inline vec3 mat3_mul(__global const float* m, vec3 v) {
    return v3(m[0] * v.x + m[1] * v.y + m[2] * v.z, m[3] * v.x + m[4] * v.y + m[5] * v.z,
              m[6] * v.x + m[7] * v.y + m[8] * v.z);
}

static inline vec3 mat3_tmul(__global const float* m, vec3 v) {
    return v3(m[0] * v.x + m[3] * v.y + m[6] * v.z, m[1] * v.x + m[4] * v.y + m[7] * v.z,
              m[2] * v.x + m[5] * v.y + m[8] * v.z);
}

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
