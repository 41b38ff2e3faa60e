/* accumulate.h: the running sum of the accumulator (pyclpt/accumulator.py) in four precisions.
 *
 * One source, specialised with -D:
 *   ACC_PRECISION  ACC_SINGLE (float sum), ACC_COMPENSATED (Kahan: float sum + float correction),
 *                  ACC_DOUBLE (double sum stored as two uint words, as_double/as_uint2; needs
 *                  cl_khr_fp64), ACC_DOUBLE_FLOAT (emulated double: an unevaluated float pair
 *                  hi + lo, for devices without cl_khr_fp64)
 *   ACC_INPUT      ACC_INPUT_FLOAT | ACC_INPUT_UINT | ACC_INPUT_INT: the element type of a frame
 *   ACC_CHANNELS   values per pixel (1..4), interleaved: frame[pixel * ACC_CHANNELS + channel]
 *
 * Each precision defines the stored type acc_store_t (one per channel), the working type acc_t
 * and five functions: acc_load / acc_store (memory <-> working type), acc_add (sum += x),
 * acc_ema (sum += x - sum / m, an exponential moving average kept in sum form: the mean is
 * sum / m), acc_bad (1 if the sum is not finite, else 0) and acc_mean (sum / n as a float, for
 * the output). The finiteness tests are bit tests returning 0/1, so that the kernel has no
 * branches per value and a CPU driver can vectorise it across work-items.
 *
 * acc_add / acc_ema take `opaque`, a kernel argument that is always 0, for the Kahan guard below.
 *
 * The compensated and emulated-double arithmetic is exact only under IEEE evaluation: these
 * programs are never built with -cl-fast-relaxed-math / -cl-unsafe-math-optimizations, common.h
 * turns FP_CONTRACT off, and the Kahan step is guarded (KAHAN_GUARD) so that no compiler can
 * fold (t - s) - y to 0. */
#ifndef PYCLPT_ACCUMULATE_H
#define PYCLPT_ACCUMULATE_H

#include "core/common.h"

#define ACC_SINGLE 0
#define ACC_COMPENSATED 1
#define ACC_DOUBLE 2
#define ACC_DOUBLE_FLOAT 3

#define ACC_INPUT_FLOAT 0
#define ACC_INPUT_UINT 1
#define ACC_INPUT_INT 2

#if !defined(ACC_PRECISION) || !defined(ACC_INPUT) || !defined(ACC_CHANNELS)
#error "accumulate.h needs -DACC_PRECISION, -DACC_INPUT and -DACC_CHANNELS"
#endif
#if ACC_CHANNELS < 1 || ACC_CHANNELS > 4
#error "ACC_CHANNELS must be 1..4"
#endif

/* 1 if a float is NaN or infinite (all exponent bits set), else 0 */
static inline uint float_bad(float x) { return (as_uint(x) & 0x7f800000u) == 0x7f800000u; }

/* ---- input element type ------------------------------------------------------------------ */
#if ACC_INPUT == ACC_INPUT_FLOAT
typedef float input_t;
static inline uint input_bad(input_t v) { return float_bad(v); }
#elif ACC_INPUT == ACC_INPUT_UINT
typedef uint input_t;
static inline uint input_bad(input_t v) { return 0u; }
#elif ACC_INPUT == ACC_INPUT_INT
typedef int input_t;
static inline uint input_bad(input_t v) { return 0u; }
#else
#error "unknown ACC_INPUT"
#endif

/* ---- float pairs: Kahan (sum, correction) and double-float (hi + lo, |lo| <= ulp(hi) / 2) ----
 * A struct of two scalars rather than a float2: after inlining it becomes two scalars, which a
 * CPU driver's loop vectoriser can widen across work-items (it cannot widen float2 values). */
typedef struct {
    float x, y;
} fpair;

static inline fpair fpair_make(float x, float y) {
    fpair p;
    p.x = x;
    p.y = y;
    return p;
}

static inline fpair fpair_neg(fpair a) { return fpair_make(-a.x, -a.y); }

static inline fpair two_sum(float a, float b) {
    float s = a + b;
    float bb = s - a;
    return fpair_make(s, (a - (s - bb)) + (b - bb));
}

static inline fpair fast_two_sum(float a, float b) { /* |a| >= |b| */
    float s = a + b;
    return fpair_make(s, b - (s - a));
}

static inline fpair df_add(fpair a, fpair b) {
    fpair s = two_sum(a.x, b.x);
    fpair t = two_sum(a.y, b.y);
    s = fast_two_sum(s.x, s.y + t.x);
    return fast_two_sum(s.x, s.y + t.y);
}

/* an integer as an exact float pair */
static inline fpair uint_df(uint n) {
    float hi = (float)n;
    return fpair_make(hi, (float)((long)n - (long)hi));
}

/* a * b for a float b (the product's rounding error by fma, which OpenCL rounds once) */
static inline fpair df_mul_f(fpair a, float b) {
    float p = a.x * b;
    float e = fma(a.x, b, -p) + a.y * b;
    return fast_two_sum(p, e);
}

/* a / b: a long division in three float quotients */
static inline fpair df_div(fpair a, fpair b) {
    float q1 = a.x / b.x;
    fpair r = df_add(a, fpair_neg(df_mul_f(b, q1)));
    float q2 = r.x / b.x;
    r = df_add(r, fpair_neg(df_mul_f(b, q2)));
    float q3 = r.x / b.x;
    return df_add(fast_two_sum(q1, q2), fpair_make(q3, 0.0f));
}

/* pair storage: two floats per value, (x, y) at [2 i], [2 i + 1] */
static inline fpair fpair_load(__global const float* s, size_t i) { return fpair_make(s[2 * i], s[2 * i + 1]); }
static inline void fpair_store(__global float* s, size_t i, fpair a) {
    s[2 * i] = a.x;
    s[2 * i + 1] = a.y;
}

/* ---- the four precisions ------------------------------------------------------------------ */
#if ACC_PRECISION == ACC_SINGLE

typedef float acc_store_t;
typedef float acc_t;
static inline acc_t acc_load(__global const acc_store_t* s, size_t i) { return s[i]; }
static inline void acc_store(__global acc_store_t* s, size_t i, acc_t a) { s[i] = a; }
static inline acc_t acc_add(acc_t a, input_t x, uint opaque) { return a + (float)x; }
static inline acc_t acc_ema(acc_t a, input_t x, uint m, uint opaque) { return a + ((float)x - a / (float)m); }
static inline uint acc_bad(acc_t a) { return float_bad(a); }
static inline float acc_mean(acc_t a, uint n) { return a / (float)n; }

#elif ACC_PRECISION == ACC_COMPENSATED

/* (x, y) = (running sum s, Kahan correction c); the true sum is s - c.
 * The step t = s + y; c' = (t - s) - y must be evaluated as written: a compiler allowed to
 * reassociate (fast/unsafe math) folds c' to 0. Besides never building this program with such
 * options, KAHAN_GUARD makes the fold impossible:
 *   1 (default)  t = s + y and d = t - s pass through an integer XOR with `opaque`, a kernel
 *                argument that is always 0: no compiler can know that they equal s + y and t - s,
 *                so d - y cannot be rewritten. Two integer ops, which a CPU driver vectorises.
 *   2            t and t - s in volatile temporaries (also safe; they stay in memory, slower).
 *   0            no guard (plain IEEE evaluation; bench/accumulation.py measures it). */
#ifndef KAHAN_GUARD
#define KAHAN_GUARD 1
#endif
typedef float acc_store_t;
typedef fpair acc_t;
static inline acc_t acc_load(__global const acc_store_t* s, size_t i) { return fpair_load(s, i); }
static inline void acc_store(__global acc_store_t* s, size_t i, acc_t a) { fpair_store(s, i, a); }
static inline acc_t kahan_add(acc_t a, float x, uint opaque) {
    float y = x - a.y;
#if KAHAN_GUARD == 2
    volatile float t = a.x + y;
    volatile float d = t - a.x;
#elif KAHAN_GUARD == 1
    float t = as_float(as_uint(a.x + y) ^ opaque);
    float d = as_float(as_uint(t - a.x) ^ opaque);
#else
    float t = a.x + y;
    float d = t - a.x;
#endif
    return fpair_make(t, d - y);
}
static inline acc_t acc_add(acc_t a, input_t x, uint opaque) { return kahan_add(a, (float)x, opaque); }
static inline acc_t acc_ema(acc_t a, input_t x, uint m, uint opaque) {
    return kahan_add(a, (float)x - (a.x - a.y) / (float)m, opaque);
}
static inline uint acc_bad(acc_t a) { return float_bad(a.x) | float_bad(a.y); }
static inline float acc_mean(acc_t a, uint n) { return (a.x - a.y) / (float)n; }

#elif ACC_PRECISION == ACC_DOUBLE

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
/* The double's 64 bits as two uint words (memory order), as a 32-bit texture would hold them. */
typedef uint2 acc_store_t;
typedef double acc_t;
static inline acc_t acc_load(__global const acc_store_t* s, size_t i) { return as_double(s[i]); }
static inline void acc_store(__global acc_store_t* s, size_t i, acc_t a) { s[i] = as_uint2(a); }
static inline acc_t acc_add(acc_t a, input_t x, uint opaque) { return a + (double)x; }
static inline acc_t acc_ema(acc_t a, input_t x, uint m, uint opaque) { return a + ((double)x - a / (double)m); }
static inline uint acc_bad(acc_t a) {
    return (as_ulong(a) & 0x7ff0000000000000UL) == 0x7ff0000000000000UL;
}
static inline float acc_mean(acc_t a, uint n) { return (float)(a / (double)n); }

#elif ACC_PRECISION == ACC_DOUBLE_FLOAT

typedef float acc_store_t;
typedef fpair acc_t;
static inline acc_t acc_load(__global const acc_store_t* s, size_t i) { return fpair_load(s, i); }
static inline void acc_store(__global acc_store_t* s, size_t i, acc_t a) { fpair_store(s, i, a); }
/* the input as an exact float pair (an integer above 2^24 keeps its low bits in lo) */
static inline fpair input_df(input_t x) {
#if ACC_INPUT == ACC_INPUT_FLOAT
    return fpair_make(x, 0.0f);
#else
    float hi = (float)x;
    return fpair_make(hi, (float)((long)x - (long)hi));
#endif
}
static inline acc_t acc_add(acc_t a, input_t x, uint opaque) { return df_add(a, input_df(x)); }
static inline acc_t acc_ema(acc_t a, input_t x, uint m, uint opaque) {
    fpair mean = df_div(a, uint_df(m));
    return df_add(a, df_add(input_df(x), fpair_neg(mean)));
}
static inline uint acc_bad(acc_t a) { return float_bad(a.x) | float_bad(a.y); }
static inline float acc_mean(acc_t a, uint n) {
    fpair q = df_div(a, uint_df(n));
    return q.x + q.y;
}

#else
#error "unknown ACC_PRECISION"
#endif

#endif
