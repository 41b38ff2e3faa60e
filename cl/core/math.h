/* math.h: the scalar and vector math of the kernels, in a form PoCL can inline.
 *
 * PoCL 3.0 (LLVM 14) calls every OpenCL math builtin (sqrt, fabs, fmin, dot, normalize, sin, ...)
 * out of line, and one call stops LLVM from vectorizing a kernel's work-item loop. Clang's
 * __builtin_sqrtf, __builtin_fabsf, __builtin_fminf, ... become LLVM intrinsics that are inlined
 * and vectorize. pyclpt/device/program.py passes -DINLINE_MATH on PoCL devices, which
 * maps the m_* functions below to those builtins; elsewhere (or with -DSTANDARD_MATH)
 * they are the standard OpenCL builtins. Both are exact where the OpenCL builtin is
 * (sqrt, fabs, fmin/fmax, floor, ceil, rint, copysign, fma): they differ in the last bit at most
 * (m_rsqrt is 1 / sqrt, two roundings: 1.5 ulp; OpenCL's rsqrt allows 2 ulp).
 *
 * NaN: __builtin_fminf/fmaxf are llvm.minnum/maxnum, which return the non-NaN operand as
 * OpenCL's fmin/fmax do (m_clamp(NaN, lo, hi) = lo, as OpenCL's clamp). m_isfinite, m_isnan,
 * m_isinf test the exponent bits, so they stay right whatever the compiler assumes about NaN
 * (pyclpt never passes -cl-finite-math-only or -cl-fast-relaxed-math).
 *
 * Vectors are vec3/vec2/vec4 structs of floats (below), not float3: m_dot, m_cross, m_length,
 * m_normalize are written out on components. m_normalize of a zero vector returns it unchanged (no NaN).
 *
 * Own approximations, arithmetic only (Cephes-style range reduction and minimax polynomials),
 * the same on every device. Max error over the stated range, measured against numpy float64 by
 * tests/test_math.py (ulp = of the exact result in float32):
 *
 *   function       range                 max error (bound tested)   used in
 *   m_sin, m_cos   |x| <= 2 pi           9.1e-8 absolute            sampling angles (disk, sphere,
 *   m_sincos       |x| <= 8192           2.6e-7 absolute (3e-7)     GGX visible normals, env map)
 *   m_exp          normal results        0.96 ulp (1.5 ulp);        Beckmann D, G1, sampling
 *                                        denormal results within 2^-148; 0 below -104, inf above 88.72
 *   m_log          all positive floats   0.75 ulp (1.5 ulp) where |ln x| > 1e-3, erfinv, Beckmann sampling
 *                                        0.5 ulp near x = 1
 *   m_atan2        all (y, x)            2.7e-7 rad absolute (3e-7)  env map lookup (u)
 *   m_acos         [-1, 1]               3.0e-7 rad absolute (3.5e-7) env map lookup (v)
 *
 * (max over 200k-400k uniform samples of the range, this header in INLINE_MATH mode on PoCL 3.0;
 * the standard mode gives the same figures.) These errors are harmless where the functions are used:
 * an angle off by 3e-7 rad moves a sampled direction by less than float rounding does, the
 * sampling routines' pdfs are evaluated from the direction actually produced, and D, G1, erfinv
 * and the env-map texel coordinates tolerate relative errors of 1e-6.
 *
 * Outside |x| <= 8192 m_sin/m_cos are not accurate (no call site comes near). Special values
 * (0, +-inf, NaN, denormals) behave as the C library's: exp(-inf) = 0, exp(inf) = inf,
 * log(0) = -inf, log(x < 0) = NaN, log(inf) = inf, NaN in gives NaN out; sin/cos of inf is NaN.
 *
 * pow and tan: no device code calls them.
 *
 * Kept exact: erf and erfc (Beckmann only, scene/bsdfs/microfacet.h): Lambda(a) subtracts erfc(a)
 * from a nearly equal term, so erfc needs its full relative accuracy at large a, and the sampling
 * routine's Newton steps solve an equation built on erf, whose inverse erfinv_f must match it. */
#ifndef PYCLPT_MATH_H
#define PYCLPT_MATH_H

#if defined(INLINE_MATH) && !defined(STANDARD_MATH)
#define M_PICK(builtin, standard) builtin
#else
#define M_PICK(builtin, standard) standard
#endif
static inline float m_sqrt(float x) { return M_PICK(__builtin_sqrtf, sqrt)(x); }
static inline float m_abs(float x) { return M_PICK(__builtin_fabsf, fabs)(x); }
static inline float m_min(float a, float b) { return M_PICK(__builtin_fminf, fmin)(a, b); }
static inline float m_max(float a, float b) { return M_PICK(__builtin_fmaxf, fmax)(a, b); }
static inline float m_floor(float x) { return M_PICK(__builtin_floorf, floor)(x); }
static inline float m_ceil(float x) { return M_PICK(__builtin_ceilf, ceil)(x); }
static inline float m_rint(float x) { return M_PICK(__builtin_rintf, rint)(x); }
static inline float m_copysign(float a, float b) { return M_PICK(__builtin_copysignf, copysign)(a, b); }
static inline float m_fma(float a, float b, float c) { return M_PICK(__builtin_fmaf, fma)(a, b, c); }

static inline float m_rsqrt(float x) { return 1.0f / m_sqrt(x); }
static inline float m_clamp(float x, float lo, float hi) { return m_min(m_max(x, lo), hi); }
static inline int m_imin(int a, int b) { return a < b ? a : b; }
static inline int m_imax(int a, int b) { return a > b ? a : b; }
static inline bool m_isfinite(float x) { return (as_uint(x) & 0x7f800000u) != 0x7f800000u; }
static inline bool m_isnan(float x) { return (as_uint(x) & 0x7fffffffu) > 0x7f800000u; }
static inline bool m_isinf(float x) { return (as_uint(x) & 0x7fffffffu) == 0x7f800000u; }

/* ---- 3-vectors on scalars -------------------------------------------------------- */

/* vec3, vec2 and vec4 are structs of floats, not OpenCL's float3/float2/float4: LLVM's loop vectorizer,
 * which PoCL uses to run a kernel's work-items 8 or 16 at a time, refuses any instruction of vector type
 * ("instruction return type cannot be vectorized"), while a struct of scalars becomes plain scalars once
 * inlined. The operations are componentwise IEEE arithmetic, as on float3: v3_add(v3_mul(a, b), c) is
 * a * b + c rounded the same way (FP_CONTRACT is off, core/common.h). Buffers hold scalar fields.
 *
 * aligned(32) makes each type larger than 16 bytes, so the x86-64 calling convention passes and
 * returns it in memory, which SROA turns back into scalars once inlined. A 12-byte struct would be
 * returned as {<2 x float>, float}: x and y packed into one vector register, vector values that
 * (1) PoCL's pre-pass SLP vectorizer builds <2 x float> arithmetic on, which stops its work-item
 * loop vectorizer (docs/wavefront.md, "Vectorized stages"), and (2) Intel's CPU vectorizer
 * miscompiles: with 12-byte vec3 (as with float3 before them) its vectorized wavefront stages gave
 * wrong images (docs/devices.md; tests/test_devices.py fails without the alignment). */
typedef struct __attribute__((aligned(32))) {
    float x, y, z;
} vec3;
typedef struct __attribute__((aligned(32))) {
    float x, y;
} vec2;
typedef struct __attribute__((aligned(32))) {
    float x, y, z, w;
} vec4;

static inline vec3 v3(float x, float y, float z) {
    vec3 r;
    r.x = x;
    r.y = y;
    r.z = z;
    return r;
}
static inline vec2 v2(float x, float y) {
    vec2 r;
    r.x = x;
    r.y = y;
    return r;
}
static inline vec4 v4(float x, float y, float z, float w) {
    vec4 r;
    r.x = x;
    r.y = y;
    r.z = z;
    r.w = w;
    return r;
}
static inline vec3 v3_splat(float s) { return v3(s, s, s); }
static inline vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline vec3 v3_mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline vec3 v3_div(vec3 a, vec3 b) { return v3(a.x / b.x, a.y / b.y, a.z / b.z); }
static inline vec3 v3_scale(vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline vec3 v3_divs(vec3 a, float s) { return v3(a.x / s, a.y / s, a.z / s); }
static inline vec3 v3_rsubs(float s, vec3 a) { return v3(s - a.x, s - a.y, s - a.z); } /* s - a */
static inline vec3 v3_neg(vec3 a) { return v3(-a.x, -a.y, -a.z); }
static inline bool v3_is_zero(vec3 v) { return v.x == 0.0f && v.y == 0.0f && v.z == 0.0f; }
static inline vec4 v4_add(vec4 a, vec4 b) { return v4(a.x + b.x, a.y + b.y, a.z + b.z, a.w + b.w); }
static inline vec4 v4_scale(vec4 a, float s) { return v4(a.x * s, a.y * s, a.z * s, a.w * s); }
static inline vec3 v4_xyz(vec4 a) { return v3(a.x, a.y, a.z); }

static inline float m_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline vec3 m_cross(vec3 a, vec3 b) {
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float m_length(vec3 v) { return m_sqrt(m_dot(v, v)); }
static inline vec3 m_normalize(vec3 v) {
    float l2 = m_dot(v, v);
    float inv = 1.0f / m_sqrt(l2);
    return v3_scale(v, l2 > 0.0f ? inv : 1.0f); /* one select, not one per component */
}
static inline vec3 m_max3s(vec3 v, float s) { return v3(m_max(v.x, s), m_max(v.y, s), m_max(v.z, s)); }

/* A half float's bits to float, exactly, for finite halves (vload_half is a call on PoCL): the
 * exponent rebiased by 127 - 15, denormal halves (exponent 0) as mantissa * 2^-24. */
static inline float m_half_to_float(ushort h) {
    uint e = (h >> 10) & 0x1fu, m = h & 0x3ffu;
    float mag = e == 0u ? (float)m * 0x1p-24f : as_float(((e + 112u) << 23) | (m << 13));
    return (h & 0x8000u) ? -mag : mag;
}

/* ---- own approximations (error table above) ------------------------------------ */

/* sin and cos of x (|x| <= 8192): x = q pi/2 + r, |r| <= pi/4 (three-part Cody-Waite pi/2),
 * Cephes sinf/cosf minimax polynomials on r, the quadrant q picking and signing them. */
static inline float m_sincos(float x, float* cos_out) {
    float q = m_rint(x * 0.636619772367581343f);
    float r = ((x - q * 1.5703125f) - q * 4.837512969970703125e-4f) - q * 7.54978995489188216e-8f;
    int qi = (int)q;
    float z = r * r;
    float s0 = r + r * z * (-1.6666654611e-1f + z * (8.3321608736e-3f + z * -1.9515295891e-4f));
    float c0 = 1.0f - 0.5f * z + z * z * (4.166664568298827e-2f + z * (-1.388731625493765e-3f + z * 2.443315711809948e-5f));
    float s = (qi & 1) ? c0 : s0;
    float c = (qi & 1) ? s0 : c0;
    *cos_out = ((qi + 1) & 2) ? -c : c;
    return (qi & 2) ? -s : s;
}
static inline float m_sin(float x) { float c; return m_sincos(x, &c); }
static inline float m_cos(float x) { float c; m_sincos(x, &c); return c; }

/* 2^k for an integer k in [-126, 127]. */
static inline float m_pow2i(int k) { return as_float((uint)(k + 127) << 23); }

/* e^x: x = n ln2 + r (two-part ln2), Cephes expf polynomial on r, 2^n applied in two halves so
 * that denormal results round once. */
static inline float m_exp(float x) {
    float xc = m_clamp(x, -104.0f, 89.0f);
    float n = m_rint(xc * 1.44269504088896341f);
    float r = (xc - n * 0.693359375f) - n * -2.12194440e-4f;
    float z = r * r;
    float p = (((((1.9875691500e-4f * r + 1.3981999507e-3f) * r + 8.3334519073e-3f) * r + 4.1665795894e-2f) * r
                + 1.6666665459e-1f) * r + 5.0000001201e-1f) * z + r + 1.0f;
    int ni = (int)n;
    int n1 = ni / 2;
    float e = p * m_pow2i(n1) * m_pow2i(ni - n1);
    return m_isnan(x) ? x : e;
}

/* ln x: x = m 2^e with m in [sqrt(1/2), sqrt(2)) (denormals scaled by 2^23 first), Cephes logf
 * polynomial on m - 1, e ln2 added in two parts. */
static inline float m_log(float x) {
    bool sub = x < 1.17549435e-38f;
    float xs = sub ? x * 8388608.0f : x;
    uint b = as_uint(xs);
    int e = (int)((b >> 23) & 0xffu) - 126 - (sub ? 23 : 0);
    float m = as_float((b & 0x007fffffu) | 0x3f000000u);
    bool low = m < 0.707106781186547524f;
    e -= low ? 1 : 0;
    float f = low ? m + m - 1.0f : m - 1.0f;
    float z = f * f;
    float y = ((((((((7.0376836292e-2f * f - 1.1514610310e-1f) * f + 1.1676998740e-1f) * f - 1.2420140846e-1f) * f
                  + 1.4249322787e-1f) * f - 1.6668057665e-1f) * f + 2.0000714765e-1f) * f - 2.4999993993e-1f) * f
              + 3.3333331174e-1f) * f * z;
    float fe = (float)e;
    y += -2.12194440e-4f * fe;
    y += -0.5f * z;
    float r = (f + y) + 0.693359375f * fe;
    r = x == INFINITY ? x : r;
    r = x == 0.0f ? -INFINITY : r;
    return (x < 0.0f || m_isnan(x)) ? NAN : r;
}

/* atan of t in [0, 1]: Cephes atanf (t > tan(pi/8): atan(1) + atan((t - 1) / (t + 1))). */
static inline float m_atan01(float t) {
    bool big = t > 0.414213562373095f;
    float a = big ? (t - 1.0f) / (t + 1.0f) : t;
    float z = a * a;
    float p = (((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z - 3.33329491539e-1f) * z * a + a;
    return big ? 0.785398163397448310f + p : p;
}

/* atan2(y, x) in [-pi, pi]: the octant reduced to atan of min/max in [0, 1]. */
static inline float m_atan2(float y, float x) {
    float ax = m_abs(x), ay = m_abs(y);
    float hi = m_max(ax, ay), lo = m_min(ax, ay);
    float t = hi > 0.0f ? lo / hi : 0.0f;
    t = (m_isinf(ax) && m_isinf(ay)) ? 1.0f : t;
    float a = m_atan01(t);
    a = ay > ax ? 1.57079632679489662f - a : a;
    a = (x < 0.0f || (x == 0.0f && m_copysign(1.0f, x) < 0.0f)) ? 3.14159265358979324f - a : a;
    a = m_copysign(a, y);
    return (m_isnan(x) || m_isnan(y)) ? NAN : a;
}

/* acos(x) for x in [-1, 1] (NaN outside): Cephes asinf on [0, 1/2], and
 * acos(x) = 2 asin(sqrt((1 - x) / 2)) above. */
static inline float m_acos(float x) {
    float ax = m_abs(x);
    bool big = ax > 0.5f;
    float z = big ? 0.5f * (1.0f - ax) : ax * ax;
    float s = big ? m_sqrt(z) : ax;
    float p = ((((4.2163199048e-2f * z + 2.4181311049e-2f) * z + 4.5470025998e-2f) * z + 7.4953002686e-2f) * z
               + 1.6666752422e-1f) * z * s + s;
    float a = big ? 2.0f * p : 1.57079632679489662f - p; /* acos(|x|) */
    a = x < 0.0f ? 3.14159265358979324f - a : a;
    return (ax > 1.0f || m_isnan(x)) ? NAN : a;
}

#endif
