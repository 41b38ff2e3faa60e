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
 *   GEO_MOTION    2: the sample's motion (aovs.h, AOV_MOTION: previous position - pixel), AOV_OFFSCREEN in both
 *                 where it was not seen or not finite; the next frame's reproject compares it with its own
 *                 (moves_with)
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
#define GEO_MOTION 5
#define GEO_MATERIAL 7 /* last: its int bits (NaN patterns as floats) are never read as a neighbour's float */
#define GEO_COUNT 8

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
 * its light that the firefly clamp took, per channel; a tile's own share is at most DEFICIT_MAX (on a
 * short history; deficit_cap below), and what modulate gives back at most DEFICIT_MAX_LONG.
 * DEFICIT_MAX was 0.2 when the share given back was the robust mean of the 3x3 tiles' (0.25 raised
 * the living room's relMSE at frame 8 from 0.344 to 0.353 x the plain average's, 0.1 lowered it to
 * 0.332 and gave back a third less); 0.25 since it is the tile's
 * own share up to DEFICIT_OUTLIER x that mean (deficit_gain.cl): the room's relMSE 0.338 (0.331 at
 * 0.2, 0.350 at 0.3), the cornell-bunny's 32-frame means 0.9958 / 0.9942 / 0.9933 of the plain
 * average's (0.9949 / 0.9932 / 0.9926 at 0.2; its ceiling beside the light has tiles whose share is
 * 0.4 to 0.9); docs/denoising.md, "Energy at 32 frames". A share under DEFICIT_EPS is rounding (a
 * noise-free history and its deficit-free twin differ by an ulp) and counts as 0, so that g is
 * exactly 0 where nothing was clamped. */
#define DEFICIT_TILE 16
#define DEFICIT_MAX 0.25f
/* The cap of a tile's share grows with its pixels' mean history length N, from DEFICIT_MAX at
 * DEFICIT_LONG_FROM frames to DEFICIT_MAX_LONG at DEFICIT_LONG_FULL (linear between): the cap keeps a
 * young tile's noisy share of a sparse light from coming back as the tile's level (the room's relMSE
 * at frame 8), but on a history of 16 to 32 frames the share is measured over as many frames, and
 * a cap of 0.25 kept the cornell-bunny's ceiling tiles (shares 0.4 to 0.9) from most of their
 * deficit: its 32-frame blue mean 0.9941 of the plain average's, 0.9976 with the ramp
 * (docs/denoising.md, "The deficit's cap on a long history"). Frame 8 and a light change 16 frames in are as
 * before (N <= 17 there). modulate caps what it gives back at DEFICIT_MAX_LONG. */
#define DEFICIT_MAX_LONG 0.75f
#define DEFICIT_LONG_FROM 16.0f
#define DEFICIT_LONG_FULL 32.0f
#define DEFICIT_OUTLIER 5.0f /* deficit_gain.cl */
#define DEFICIT_EPS 1e-4f

static inline int deficit_tiles(int size) { return (size + DEFICIT_TILE - 1) / DEFICIT_TILE; }

/* The most of its light a tile's share may be, for its pixels' mean history length n (above). */
static inline float deficit_cap(float n) {
    float r = m_clamp((n - DEFICIT_LONG_FROM) / (DEFICIT_LONG_FULL - DEFICIT_LONG_FROM), 0.0f, 1.0f);
    return DEFICIT_MAX + (DEFICIT_MAX_LONG - DEFICIT_MAX) * r;
}

/* Tile p's value of a per-tile plane (tiles of `tile` pixels, ntx x nty of them), bilinear between
 * the tiles' centres (clamped at the image's border): the deficit's shares and levels, the conserve
 * gains, as modulate reads them. */
static inline float tile_bilinear(__global const float* plane, int ntx, int nty, int tile, int x, int y) {
    float u = ((float)x + 0.5f) / (float)tile - 0.5f, v = ((float)y + 0.5f) / (float)tile - 0.5f;
    float fu = m_floor(u), fv = m_floor(v);
    int u0 = (int)fu, v0 = (int)fv;
    float wu = u - fu, wv = v - fv;
    int x0 = clampi(u0, 0, ntx - 1), x1 = clampi(u0 + 1, 0, ntx - 1);
    int y0 = clampi(v0, 0, nty - 1) * ntx, y1 = clampi(v0 + 1, 0, nty - 1) * ntx;
    return (plane[y0 + x0] * (1.0f - wu) + plane[y0 + x1] * wu) * (1.0f - wv)
           + (plane[y1 + x0] * (1.0f - wu) + plane[y1 + x1] * wu) * wv;
}

/* The a-trous filter's energy balance (cl/denoise/conserve.cl): tiles of CONSERVE_TILE x
 * CONSERVE_TILE pixels (pyclpt/denoise/svgf.py, CONSERVE_TILE), each with the gain that gives its
 * filtered light the sum of its unfiltered light, within [1 / CONSERVE_MAX, CONSERVE_MAX] (a bound
 * for a tile whose filtered light is nearly 0; in the frame of the evaluation's light change the
 * cornell-box's tiles are at 0.77 to 1.27). */
#define CONSERVE_TILE 8
#define CONSERVE_MAX 2.0f
/* conserve_gain: a tile's gain - 1 at most CONSERVE_OUTLIER x the robust mean of its 3x3 tiles'
 * (a lone firefly's tile gets nothing), and 0 under CONSERVE_EPS (rounding). */
#define CONSERVE_OUTLIER 10.0f
#define CONSERVE_EPS 1e-4f

/* The lighting changed in view (light_change.cl, light_age.cl): pixels summed by one work-item; the
 * share of the image's pixels (at least LIGHT_CHANGE_MIN) that must see a light change (reproject's
 * light_changed: the static living room flags up to 8 of its 14,400 pixels a frame, the cornell-box's
 * light turned down by 4 flags 134 at 120x120); the age's cap (the age the histories start with). */
#define LIGHT_CHUNK 1024
#define LIGHT_CHANGE_SHARE (1.0f / 400.0f)
#define LIGHT_CHANGE_MIN 16
#define LIGHT_AGE_MAX (1 << 20)

static inline int conserve_tiles(int size) { return (size + CONSERVE_TILE - 1) / CONSERVE_TILE; }

/* How much of the conserve gain a pixel with a history of N frames takes: 0 up to CONSERVE_FROM,
 * 1 from CONSERVE_FULL on, linear between, as the a-trous luminance weight is made symmetric
 * (atrous.cl, SYMMETRIC_FROM, SYMMETRIC_FULL). On the first frames of a history the filter dims a
 * light's edge on purpose (p's own variance, a spatial estimate there, keeps a bright neighbour's
 * noise out); a tile's gain would give that light to the whole tile, the dark band beside the light
 * included (tests/test_denoise.py::test_a_light_does_not_bleed_into_its_dark_surroundings: its band
 * at 0.136 relMSE in the first frame with the gain at once, under 0.071 asked). */
#define CONSERVE_FROM 2.0f
#define CONSERVE_FULL 8.0f

static inline float conserve_ramp(float n) {
    return m_clamp((n - CONSERVE_FROM) / (CONSERVE_FULL - CONSERVE_FROM), 0.0f, 1.0f);
}

static inline float conserve_ratio(float unfiltered, float filtered) {
    return filtered > 0.0f ? m_clamp(unfiltered / filtered, 1.0f / CONSERVE_MAX, CONSERVE_MAX) : 1.0f;
}

#endif
