/* atrous: one iteration of SVGF's edge-avoiding a-trous wavelet filter (Falcor's SVGFAtrous).
 * One work-item per pixel, 2D range; pyclpt/denoise/svgf.py runs `iterations` of them with
 * step = 2^i, ping-ponging, iteration feedback_tap writing into the colour history.
 *
 * A 5x5 B3-spline kernel (1/16, 1/4, 3/8, 1/4, 1/16, normalised to the centre: 1/6, 2/3, 1, 2/3,
 * 1/6) at taps p + step (dx, dy), each weighted by
 *   depth      exp(-|z - zq| / (phi_depth max(GEO_GRAD, 1e-8) step |(dx, dy)|))
 *   normal     max(0, cos)^phi_normal (svgf.h, normal_weight; 1 where p's normal is unknown)
 *   luminance  exp(-|l - lq| w_pq / (phi_color sqrt(g + 1e-10))), g = g3x3(var) of p,
 *              w_pq = lerp(1, r^(-1/2), s), r = clamp(var_q / g, 1/4, 1): at s = 1, 1 / sigma with
 *              sigma^2 the smaller of g and q's variance (floored at g / 4), in p and q alike;
 *              r^(-1/2) by a polynomial (rsqrt_quarter_to_one), not a square root a tap
 * (g3x3: the 3x3 Gaussian 1/4, 1/8, 1/16 of the variance around p, renormalised over the surface
 * pixels inside the image: a background pixel's variance, never divided by its history, would
 * loosen its neighbours' weights; on a history's first frame each neighbour's variance capped at
 * VARIANCE_CAP x p's, see vcap). s ramps from 0 at a history of SYMMETRIC_FROM (2) frames to 1 at
 * SYMMETRIC_FULL (8): on a history of a few frames the weight is (nearly) symmetric in p and q, so
 * a noisy pixel beside quiet ones no longer gives its energy away while they take none in (what
 * darkened the converged image: docs/denoising.md, "Energy"; from 8 to 32 frames, as it was
 * ramped before, it still darkened frame 8 by 0.6 to 1.2 % on the cornell-box: "Energy at 8
 * frames"); on a history's first two frames, whose variance is a spatial estimate, p's own keeps
 * a bright neighbour's noise out. The centre counts with weight 1;
 * taps outside the image or on the background count 0. The illumination is averaged with the weights
 * w, the variance with w^2 (/ (sum w)^2): the variance of the filtered value. Background pixels
 * (depth 0) pass through.
 *
 * Consumes: src[c * pixels + p] (c < 3 illumination, c = 3 variance: variance or the previous
 *           iteration), geo (GEO_*, reproject), len (N, reproject); all padded (svgf.h, PAD).
 * Produces: dst[c * pixels + p] (padded), the same four channels filtered. */
#include "denoise/svgf.h"

#define SYMMETRIC_FROM 2.0f
#define SYMMETRIC_FULL 8.0f
#define VARIANCE_CAP 4.0f /* see vcap below */

/* r^(-1/2) for r in [1/4, 1]: a degree-4 least-squares polynomial (relative error 0.4 %; a weight
 * needs no more). */
static inline float rsqrt_quarter_to_one(float r) {
    float y = 3.64376563f;
    y = y * r - 11.45154359f;
    y = y * r + 14.07266626f;
    y = y * r - 8.7170127f;
    return y * r + 3.4562242f;
}

__kernel void atrous(__global const float* src, __global const float* geo, __global const float* len,
                     __global float* dst, int width, int height, int step, float phi_color, float phi_normal,
                     float phi_depth) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    src += PAD;
    geo += PAD;
    len += PAD;
    dst += PAD;

    vec3 c = planar3(src, n, p);
    float var = src[3 * n + p];
    float z = geo[GEO_DEPTH * n + p];
    vec3 nrm = planar3(geo + GEO_NORMAL * n, n, p);
    float l = luminance(c);
    /* an unknown (zero) centre normal: no normal weight; an unknown tap normal: cos 0 */
    float phi_n = v3_is_zero(nrm) ? 0.0f : phi_normal;

    /* On the first frame of a history (N = 1) p's variance is variance.cl's spatial estimate of the
     * quietest quadrant around p, which keeps to p's side of an edge; a neighbour's across it (a
     * bright light's, hundreds of times p's, or a new firefly's) enters the blur at most VARIANCE_CAP
     * x p's own. Uncapped, it loosened p's luminance weight and p took the light in: with 3
     * iterations instead of 5 the wider ones no longer diluted that (tests/test_denoise.py, the light
     * and the firefly tests). Capped from N = 2 on as well, the Cornell boxes did not change and the
     * living room's relMSE at frame 8 rose from 0.339 to 0.345; from N = 2 on the variance is a
     * temporal one, from the pixel's own samples. */
    float vcap = len[p] < 1.5f ? VARIANCE_CAP * var : INFINITY; /* N = 1 */
    float gvar = 0.0f, gw = 0.0f;
    UNROLL for (int dy = -1; dy <= 1; ++dy) {
        UNROLL for (int dx = -1; dx <= 1; ++dx) {
            const float k = (dx == 0 ? 0.5f : 0.25f) * (dy == 0 ? 0.5f : 0.25f);
            int tx = x + dx, ty = y + dy;
            int q = row_at(y, dy, width, height) + tx;
            bool use = tx >= 0 && tx < width && ty >= 0 && ty < height && geo[GEO_DEPTH * n + q] > 0.0f;
            float kin = use ? k : 0.0f;
            gvar += kin * m_min(src[3 * n + q], vcap);
            gw += kin;
        }
    }
    gvar = gw > 0.0f ? gvar / gw : var; /* gw = 0: p is background and passes through */
    float inv_phi = 1.0f / phi_color;
    /* how far the luminance weight is made symmetric in p and q: 0 up to SYMMETRIC_FROM frames of
     * history, 1 from SYMMETRIC_FULL on, linear between */
    float sym = m_clamp((len[p] - SYMMETRIC_FROM) / (SYMMETRIC_FULL - SYMMETRIC_FROM), 0.0f, 1.0f);
    float inv_z = 1.0f / (phi_depth * m_max(geo[GEO_GRAD * n + p], 1e-8f) * (float)step);
    float inv_l_p = inv_phi * m_rsqrt(gvar + VARIANCE_EPS); /* p's own: the weight on a short history */
    float inv_g = 1.0f / (gvar + VARIANCE_EPS);

    float sw = 1.0f, sv = var;
    vec3 sum = c;
    UNROLL for (int dy = -2; dy <= 2; ++dy) {
        UNROLL for (int dx = -2; dx <= 2; ++dx) {
            if (dx == 0 && dy == 0) continue;
            const float k = (dx == 0 ? 1.0f : (dx == 1 || dx == -1) ? 2.0f / 3.0f : 1.0f / 6.0f)
                            * (dy == 0 ? 1.0f : (dy == 1 || dy == -1) ? 2.0f / 3.0f : 1.0f / 6.0f);
            const float inv_dist = 1.0f / m_sqrt((float)(dx * dx + dy * dy));
            int tx = x + dx * step, ty = y + dy * step;
            bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
            int q = row_at(y, dy * step, width, height) + tx;
            vec3 cq = planar3(src, n, q);
            float zq = geo[GEO_DEPTH * n + q];
            float wn = normal_weight(m_dot(nrm, planar3(geo + GEO_NORMAL * n, n, q)), phi_n);
            float vq = src[3 * n + q];
            /* symmetric in p and q: sigma^2 = the smaller of p's blurred and q's own variance, floored
             * at a quarter of p's; 1 / sigma as p's times (v / g)^(-1/2), v / g in [1/4, 1], by a
             * polynomial (rsqrt_quarter_to_one: no square root a tap, which made this pass 7.7 times
             * slower on PoCL), the factor ramped in by sym */
            float f = rsqrt_quarter_to_one(m_clamp(vq * inv_g, 0.25f, 1.0f));
            float inv_l = inv_l_p * lerpf(1.0f, f, sym);
            float e = -m_abs(l - luminance(cq)) * inv_l - m_abs(z - zq) * inv_z * inv_dist;
            float w = (inside && zq > 0.0f) ? k * wn * exp_weight(e) : 0.0f;
            sw += w;
            sum = v3_add(sum, v3_scale(cq, w));
            sv += w * w * vq;
        }
    }
    bool surface = z > 0.0f;
    float inv = 1.0f / sw;
    store_planar3(dst, n, p, surface ? v3_scale(sum, inv) : c);
    dst[3 * n + p] = surface ? sv * inv * inv : var;
}
