/* variance: SVGF's variance estimate (Falcor's SVGFFilterMoments), the a-trous filter's input.
 * One work-item per pixel, 2D range.
 *
 * Where the history holds SHORT_HISTORY (4) frames or more, the temporal one: var = m2 - m1^2 of
 * the luminance moments. On a shorter history, Falcor's spatial one: the moments averaged over the
 * (2 radius + 1)^2 pixels around p (DenoiserSettings.variance_radius; Falcor's 7x7 is radius 3)
 * with cross-bilateral weights (depth: exp(-|z - zq| / (3 max(GEO_GRAD, 1e-8) |offset|)), normal:
 * max(0, cos)^phi_normal, luminance: exp(-|l - lq| / phi_color); background pixels and pixels
 * outside the image excluded), boosted by 4 / N for the first frames, as Falcor does. Three
 * changes, measured (docs/denoising-passes.md), as a spatial estimate also sees what lies across an
 * edge (a light beside a dark ceiling) and the a-trous filter then blurs across it:
 *   - on the first frame, the smallest of it and the estimates over the four quadrants of the
 *     window that hold p (those with at least 3 samples' weight), whichever side of an edge is
 *     quiet (Kuwahara's idea);
 *   - from the second frame on, the smaller of it and the temporal estimate with Bessel's
 *     correction (N / (N - 1)), unbiased from N samples;
 *   - the illumination is passed on as accumulated, not averaged over the window as Falcor does (a
 *     blur before the a-trous filter).
 * On a 64x64 Cornell box the error of the first three frames fell from 0.33, 0.25, 0.27 to 0.06,
 * 0.02, 0.02 (the plain frame's: 0.42, 0.20, 0.12).
 *
 * The spatial estimate is a branch taken by few pixels once the history has built up (those just
 * disoccluded), so it must stay a branch: its loops run to the run-time `radius`, which keeps a
 * vectorizer from if-converting them into work that every pixel would pay (on PoCL an unrolled 7x7
 * here was vectorized, and the pass took 70 times as long at 1280x720 with no short history at all).
 *
 * Then var is divided by the effective sample count of the accumulated estimate,
 * min(N, n_eff_max): the variance of the mean that the filter smooths, not of one sample, so that the
 * a-trous weights tighten as the history converges (n_eff_max = (2 - alpha_min) / alpha_min, the
 * count an exponential moving average of weight alpha_min reaches; 1 keeps plain SVGF's per-sample
 * variance). Background pixels (depth 0) pass through.
 *
 * Consumes: accum[c * pixels + p] (c < 3, the long history from clip_history), moments (2),
 *           len (N), geo (GEO_*, reproject); all padded (svgf.h, PAD).
 * Produces: out[c * pixels + p] (padded): c < 3 the illumination (accum's), c = 3 its luminance
 *           variance. */
#include "denoise/svgf.h"

#define SHORT_HISTORY 4.0f

/* Weighted sums of the luminance moments: weight, w m1, w m2. */
typedef struct {
    float w, m1, m2;
} moment_sums_t;

static inline moment_sums_t msum_add(moment_sums_t a, moment_sums_t b) {
    moment_sums_t r = {a.w + b.w, a.m1 + b.m1, a.m2 + b.m2};
    return r;
}

/* The variance of a weighted set of moments, m2 - m1^2 of the weighted means. */
static inline float msum_variance(moment_sums_t s) {
    float inv = 1.0f / m_max(s.w, 1e-6f);
    float mean = s.m1 * inv;
    return m_max(s.m2 * inv - mean * mean, 0.0f);
}

/* The cross-bilateral sums over the taps p + (dx, dy), dx in [dx0, dx1], dy in [dy0, dy1]: one of
 * the nine regions (left, centre, right x above, centre, below) of the window, so that each tap is
 * weighted once and the window's and its quadrants' sums are sums of regions. */
static inline moment_sums_t region_sums(__global const float* accum, __global const float* moments,
                                        __global const float* geo, int n, int x, int y, int width, int height,
                                        int dx0, int dx1, int dy0, int dy1, float l, float z, vec3 nrm,
                                        float phi_n, float inv_l, float inv_z) {
    moment_sums_t s = {0.0f, 0.0f, 0.0f};
    for (int dy = dy0; dy <= dy1; ++dy) {
        for (int dx = dx0; dx <= dx1; ++dx) {
            int tx = x + dx, ty = y + dy;
            bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
            int q = row_at(y, dy, width, height) + tx;
            float zq = geo[GEO_DEPTH * n + q];
            float wn = normal_weight(m_dot(nrm, planar3(geo + GEO_NORMAL * n, n, q)), phi_n);
            float d2 = (float)(dx * dx + dy * dy);
            float dist = d2 > 0.0f ? m_rsqrt(d2) : 0.0f; /* 1 / |offset| */
            float e = -m_abs(l - luminance(planar3(accum, n, q))) * inv_l - m_abs(z - zq) * inv_z * dist;
            float w = (inside && zq > 0.0f) ? wn * exp_weight(e) : 0.0f;
            s.w += w;
            s.m1 += w * moments[q];
            s.m2 += w * moments[n + q];
        }
    }
    return s;
}

__kernel void variance(__global const float* accum, __global const float* moments, __global const float* len,
                       __global const float* geo, __global float* out, int width, int height, int radius,
                       float phi_color, float phi_normal, float n_eff_max) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    accum += PAD;
    moments += PAD;
    len += PAD;
    geo += PAD;
    out += PAD;

    vec3 rgb = planar3(accum, n, p);
    float m1 = moments[p], m2 = moments[n + p], N = len[p];
    float var = m_max(m2 - m1 * m1, 0.0f);
    float z = geo[GEO_DEPTH * n + p];
    if (N < SHORT_HISTORY && z > 0.0f) {
        vec3 nrm = planar3(geo + GEO_NORMAL * n, n, p);
        float phi_n = v3_is_zero(nrm) ? 0.0f : phi_normal;
        float l = luminance(rgb);
        float inv_z = 1.0f / (3.0f * m_max(geo[GEO_GRAD * n + p], 1e-8f));
        float inv_l = 1.0f / phi_color;
        /* regions[3 * row + column], rows above, at and below p, columns left, at and right of it */
        moment_sums_t r[9];
        UNROLL for (int k = 0; k < 9; ++k) {
            int cx = k % 3 - 1, cy = k / 3 - 1;
            r[k] = region_sums(accum, moments, geo, n, x, y, width, height, cx < 0 ? -radius : cx, cx > 0 ? radius : cx,
                               cy < 0 ? -radius : cy, cy > 0 ? radius : cy, l, z, nrm, phi_n, inv_l, inv_z);
        }
        moment_sums_t all = r[0];
        UNROLL for (int k = 1; k < 9; ++k) all = msum_add(all, r[k]);
        float spatial = msum_variance(all);
        /* first frame: the quietest quadrant holding p with at least 3 samples' weight */
        UNROLL for (int k = 0; k < 4; ++k) {
            int corner = (k & 2 ? 6 : 0) + (k & 1 ? 2 : 0);
            int side_x = (k & 2 ? 6 : 0) + 1, side_y = 3 + (k & 1 ? 2 : 0);
            moment_sums_t quadrant = msum_add(msum_add(r[corner], r[side_x]), msum_add(r[side_y], r[4]));
            bool use = N < 1.5f && quadrant.w > 2.5f;
            spatial = use ? m_min(spatial, msum_variance(quadrant)) : spatial;
        }
        float temporal = N > 1.0f ? var * N / (N - 1.0f) : INFINITY; /* Bessel: unbiased from N samples */
        var = m_min(spatial, temporal) * (SHORT_HISTORY / N);
    }
    var = z > 0.0f ? var / m_min(N, n_eff_max) : var;
    store_planar3(out, n, p, rgb);
    out[3 * n + p] = var;
}
