/* svgf.h: what the passes of the SVGF denoiser (the .cl files of cl/denoise, pyclpt/denoise/svgf.py) share.
 *
 * Buffers are planar floats: channel c of pixel p = y * width + x at buf[c * pixels + p]; the input
 * colour and the output are interleaved RGB (3 floats a pixel, read and written through an opaque
 * stride `unit` = 1: rgb_at, core/common.h, so that PoCL's SLP pre-pass does not pair the loads).
 *
 * The internal buffers (not the colour, the AOVs or the output) have PAD floats before and after
 * their planes, zero at allocation and never written, and every kernel offsets its pointers to them by
 * PAD. A stencil tap then reads buf[plane + row * width + x + dx] with only the row clamped: an x
 * outside the image lands in the neighbouring row, plane or pad, always inside the allocation and
 * finite, and gets weight 0. Across a row of work-items such an address is affine in x, so the
 * vectorizers load it as one contiguous vector instead of a gather.
 *
 * The geometry record GEO_* is what reproject keeps of the frame's G-buffer (cl/film/aovs.h),
 * sanitized: the passes after it and the next frame's reprojection read it, not the AOVs.
 *   GEO_DEPTH     view depth, > 0 on a surface, 0 on the background (a miss, or a non-finite or
 *                 non-positive depth in the AOVs)
 *   GEO_NORMAL    3: unit normal; 0 where unknown (a miss, a zero or non-finite normal): the normal
 *                 tests and weights then pass
 *   GEO_GRAD      the depth gradient: |dz/dx| + |dz/dy|, each the smaller of the two one-sided
 *                 differences to surface neighbours (so a depth edge on one side does not count)
 *   GEO_MATERIAL  the material id as int bits (-1 background)
 * The illumination buffers (temporal, history colour, the a-trous ping-pong) hold RGB and, in the
 * 4-channel ones, the luminance variance in channel 3. */
#ifndef PYCLPT_DENOISE_SVGF_H
#define PYCLPT_DENOISE_SVGF_H

#include "core/common.h"
#include "film/aovs.h"

#define GEO_DEPTH 0
#define GEO_NORMAL 1
#define GEO_GRAD 4
#define GEO_MATERIAL 5 /* last: its int bits (NaN patterns as floats) are never read as a neighbour's float */
#define GEO_COUNT 6

/* Floats of padding before and after an internal buffer: at least the farthest x offset of a tap,
 * 2 x 2^(iterations - 1) for the a-trous filter (iterations <= 8, DenoiserSettings). */
#define PAD 256

/* Albedo below this (or not finite) does not divide the colour: treated as 1, in demodulation and
 * modulation alike, so that modulate(demodulate(c)) = c exactly where it divides and trivially
 * where it does not. */
#define ALBEDO_MIN 1e-3f

/* A channel of an albedo divides as at least this fraction of the albedo's largest channel. The
 * G-buffer is one jittered sample a frame, so a strongly coloured texel's small channel (a blue of
 * 0.0005 to 0.02 beside a red of 0.3) changes many times over from frame to frame: divided by it,
 * the history accumulated c / a_k of one frame and was multiplied by another frame's a, which put
 * blue blotches of 100x the reference into the living room (relMSE 14 at frame 8 against the plain
 * average's 1.7). Floored, the divisor of such a channel is steady, and modulation still inverts
 * demodulation exactly (both use this rule). */
#define ALBEDO_REL 0.1f

/* Colour channels beyond this magnitude are clamped to it, so that squares (the moments) stay finite. */
#define MAX_RADIANCE 1e18f

/* The variance floor of the a-trous luminance weight (Falcor's epsVariance). */
#define VARIANCE_EPS 1e-10f

/* The unrolled stencils: constant trip counts that the compiler flattens. */


#define UNROLL _Pragma("unroll")

static inline int clampi(int v, int lo, int hi) { return m_imin(m_imax(v, lo), hi); }

/* The divisors of an albedo: where some finite channel is above ALBEDO_MIN, each finite channel
 * divides as the larger of it and ALBEDO_REL x the largest such channel (a small or zero channel
 * included); a non-finite channel, or every channel of an albedo without one above ALBEDO_MIN, as 1. */
static inline float divisor_with_floor(float a, float top) {
    return (m_isfinite(a) && top > 0.0f) ? m_max(a, top) : 1.0f;
}

static inline float dividing_part(float a) { return (a > ALBEDO_MIN && a < INFINITY) ? a : 0.0f; }

static inline vec3 albedo_divisors(vec3 a) {
    float top = ALBEDO_REL * m_max(m_max(dividing_part(a.x), dividing_part(a.y)), dividing_part(a.z));
    return v3(divisor_with_floor(a.x, top), divisor_with_floor(a.y, top), divisor_with_floor(a.z, top));
}

static inline vec3 planar3(__global const float* b, int n, int p) { return v3(b[p], b[n + p], b[2 * n + p]); }

static inline void store_planar3(__global float* b, int n, int p, vec3 v) {
    b[p] = v.x;
    b[n + p] = v.y;
    b[2 * n + p] = v.z;
}

/* The albedo of AOV record p, as the divisor of demodulation (non-finite channels: 1). */
static inline vec3 aov_divisor(__global const float* aovs, int n, int p) {
    return albedo_divisors(planar3(aovs + AOV_ALBEDO * n, n, p));
}

/* The part of colour c that the first hit emitted towards the camera (the AOV_EMISSION record e of
 * cl/film/aovs.h: an emitter or the environment seen directly), per channel e clamped into
 * [0, max(c, 0)] (a non-finite e: 0), so that c = (c - e) + e exactly and c - e >= 0 wherever c >= 0.
 * It is taken out before demodulation and added back after the filter (Falcor's SVGF does the
 * same): an emitter's radiance is noise-free and must not be blurred into, or demodulated with,
 * the light its surroundings reflect. */
static inline float emitted_part(float c, float e) { return m_isfinite(e) ? m_clamp(e, 0.0f, m_max(c, 0.0f)) : 0.0f; }

static inline vec3 emitted3(vec3 c, vec3 e) {
    return v3(emitted_part(c.x, e.x), emitted_part(c.y, e.y), emitted_part(c.z, e.z));
}

/* Colour p of an interleaved RGB buffer with NaN/inf replaced by 0 (all three channels, as the
 * film does); *bad is set when it was. */
static inline vec3 load_color(__global const float* color, int p, int unit, bool* bad) {
    vec3 c = rgb_at(color + 3 * p, unit);
    *bad = !all_finite3(c);
    return *bad ? v3_splat(0.0f) : c;
}

static inline vec3 clamp_radiance(vec3 c) {
    return v3(m_clamp(c.x, -MAX_RADIANCE, MAX_RADIANCE), m_clamp(c.y, -MAX_RADIANCE, MAX_RADIANCE),
              m_clamp(c.z, -MAX_RADIANCE, MAX_RADIANCE));
}

/* e^x for the edge-stopping weights, x <= 0 (clamped to [-87, 0]): 2^(x log2 e) as 2^i 2^f, i an
 * integer, f in [0, 1), 2^f by a degree-5 minimax polynomial (relative error 9e-8 in exact
 * arithmetic, a few 1e-7 in float; e^0 = 1 - 6e-8). Half the work of m_exp, which also handles
 * every range and special value; a weight needs none of that, and the result never falls in the
 * denormal range (e^-87 ~ 1.6e-38). The a-trous pass spends a third of its time here. */
static inline float exp_weight(float x) {
    float t = m_clamp(x, -87.0f, 0.0f) * 1.44269504088896341f;
    float i = m_floor(t);
    float f = t - i;
    float p = 1.8775767e-3f;
    p = p * f + 8.9893397e-3f;
    p = p * f + 5.5826318e-2f;
    p = p * f + 2.4015361e-1f;
    p = p * f + 6.9315308e-1f;
    p = p * f + 9.9999994e-1f;
    return as_float(as_uint(p) + ((uint)(int)i << 23)); /* unsigned: a negative shift is undefined */
}

/* x^e for x in [0, 1] and e >= 0, as exp(e ln x) on the inline math (pow is a call on PoCL); x is
 * floored at 1e-20 so that e = 0 gives 1 and no NaN appears. */
static inline float pow01(float x, float e) { return m_exp(e * m_log(m_max(x, 1e-20f))); }

/* a + (b - a) t, Falcor's lerp (t = 1 gives b exactly when a is finite). */
static inline float lerpf(float a, float b, float t) { return a + (b - a) * t; }

static inline vec3 lerp3(vec3 a, vec3 b, float t) {
    return v3(lerpf(a.x, b.x, t), lerpf(a.y, b.y, t), lerpf(a.z, b.z, t));
}

/* The normal weight max(0, cos)^phi_normal: by NORMAL_SQUARINGS squarings where phi_normal is a
 * power of two (-DNORMAL_SQUARINGS=log2(phi_normal), from pyclpt/denoise/svgf.py: 7 multiplies for
 * Falcor's 128 instead of a log and an exp), else as pow01; 1 where phi is 0 (the passes pass 0
 * for a pixel whose own normal is unknown). */
static inline float normal_weight(float c, float phi) {
#ifdef NORMAL_SQUARINGS
    float w = m_max(c, 0.0f);
    UNROLL for (int i = 0; i < NORMAL_SQUARINGS; ++i) w *= w;
#else
    float w = pow01(m_max(c, 0.0f), phi);
#endif
    return phi > 0.0f ? w : 1.0f;
}

/* Row y + dy clamped to the image, times width: the row part of a stencil tap's index. */
static inline int row_at(int y, int dy, int width, int height) { return clampi(y + dy, 0, height - 1) * width; }

/* cos of the angle between two unit normals; 1 where either is unknown (zero). */
static inline float normal_agreement(vec3 a, vec3 b) {
    float d = m_dot(a, b);
    return (v3_is_zero(a) || v3_is_zero(b)) ? 1.0f : d;
}

/* The clamp's deficit (cl/denoise/deficit.cl, deficit_gain.cl, modulate.cl): the image is cut into
 * DEFICIT_TILE x DEFICIT_TILE tiles (pyclpt/denoise/svgf.py, DEFICIT_TILE), each with the share of
 * its light that the firefly clamp took, per channel; a tile's own share is at most DEFICIT_MAX
 * (0.25 raised the living room's relMSE at frame 8 from 0.344 to 0.353 x the plain average's, 0.1
 * lowered it to 0.332 and gave back a third less; docs/denoising.md), and what modulate gives back at
 * most DEFICIT_MAX too. A share under DEFICIT_EPS is rounding (a noise-free history and its deficit-
 * free twin differ by an ulp) and counts as 0, so that g is exactly 0 where nothing was clamped. */
#define DEFICIT_TILE 16
#define DEFICIT_MAX 0.2f
#define DEFICIT_EPS 1e-4f

static inline int deficit_tiles(int size) { return (size + DEFICIT_TILE - 1) / DEFICIT_TILE; }

#endif
