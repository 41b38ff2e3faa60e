/* conserve: the a-trous filter's energy balance, per tile. One work-item per tile of CONSERVE_TILE x
 * CONSERVE_TILE pixels (svgf.h), 2D range; after the last a-trous iteration, before modulate.
 *
 * The a-trous filter is a normalised gather: each pixel's output is a weighted mean of its
 * neighbours, but a pixel's own light reaches its neighbours with their weights over their sums, not
 * its own. A bright pixel beside quiet ones (a loose luminance weight among tight ones) gives more of
 * its light away than they take in, and the image loses energy: 0.4 % of the cornell-bunny's after
 * 32 frames (the evaluation's frames: 0.992 of the plain average's with the filter's input, 0.9885
 * with its output; 1 % with no clamp and no clipping; docs/denoising.md, "Energy at 32 frames"). Per
 * tile and channel this writes the gain
 *   G = sum d max(H, 0) / sum d max(F, 0)
 * over the tile's surface pixels (depth > 0), H the filter's input (the long history), F its output,
 * d the footprint albedo (reproject; the sums weigh each pixel as its colour does); 1 where the tile has no
 * light in F, clamped into [1 / CONSERVE_MAX, CONSERVE_MAX]; then moved towards 1 by the share of the
 * tile's surface pixels whose history is short (1 - the mean of conserve_ramp(N), svgf.h). Where the
 * anti-lag has just cut histories, the light the filter takes from the uncut ones is largely the old
 * light it should lose: at the evaluation's light change (x0.25) the region's relMSE in the frame of
 * the change was 0.0967 on the cornell-bunny with the tile's full gain, 0.0915 with this, 0.0846
 * without a gain (0.0616, 0.0615 and 0.0565 on the cornell-box). conserve_gain limits it against the
 * tiles around (a lone firefly's tile gets none), and modulate scales the filtered illumination by
 * it, bilinear between the tiles' centres: the filter keeps its shape and each tile the light it was
 * given. But a tile's sum of H is noisy (64 pixels of an 8-frame history at 1 sample a frame: its
 * relative spread was 8 % on the cornell-box at 256x256, frame 8), and the filter's loss in a tile is
 * mostly that noise crossing its border: a full gain put the tile's noise back as 8-pixel blotches. So
 * only the part of e = sum d H - sum d F that stands out of that noise is kept: e^2 / (e^2 + sigma^2
 * v) of it, v = sum d^2 var_H (var_H: the history's luminance variance, as variance.cl estimates it
 * from the moments, divided by min(N, n_eff_max), per channel in proportion to the channel's level),
 * sigma = DenoiserSettings.conserve_sigma (docs/denoising.md, "The filter's balance without the
 * tiles' noise"). Tiles of 8 pixels, not the deficit's 16: the loss sits at the edges of the light, and the
 * smaller tile puts it back there (measured before conserve_gain's limit: the living room's relMSE
 * at frame 8 0.337 x the plain average's with 8, 0.348 with 16, 0.360 with 32; the cornell-box's
 * FLIP 1.070, 1.105 and 1.137 x OIDN's).
 *
 * Consumes: accum[c * pixels + p] (c < 3: the long history, the filter's input), src[c * pixels + p]
 *           (c < 3: the last a-trous iteration's output), geo (GEO_DEPTH), len (N), moments (2: the
 *           luminance moments), all padded (svgf.h, PAD); albedo (reproject: the footprint albedo A, padded).
 * Produces: gains[c * tile_count + ty * tiles_x + tx], c < 3: the tile's gain G. */
#include "denoise/svgf.h"

__kernel void conserve(__global const float* accum, __global const float* src, __global const float* geo,
                       __global const float* len, __global const float* albedo, __global const float* moments,
                       __global float* gains, int width, int height, float n_eff_max, float sigma) {
    int tx = get_global_id(0), ty = get_global_id(1);
    int ntx = conserve_tiles(width), nty = conserve_tiles(height);
    if (tx >= ntx || ty >= nty) return;
    int n = width * height;
    accum += PAD;
    src += PAD;
    geo += PAD;
    len += PAD;
    albedo += PAD;
    moments += PAD;
    /* per channel: the sums of the unfiltered and the filtered light, and the variance of the first */
    float sh[3] = {0.0f, 0.0f, 0.0f}, sf[3] = {0.0f, 0.0f, 0.0f}, sv[3] = {0.0f, 0.0f, 0.0f};
    float ramp = 0.0f, surface = 0.0f;
    int x1 = min((tx + 1) * CONSERVE_TILE, width), y1 = min((ty + 1) * CONSERVE_TILE, height);
    for (int y = ty * CONSERVE_TILE; y < y1; ++y) {
        for (int x = tx * CONSERVE_TILE; x < x1; ++x) {
            int p = y * width + x;
            float w = geo[GEO_DEPTH * n + p] > 0.0f ? 1.0f : 0.0f;
            ramp += w * conserve_ramp(len[p]);
            surface += w;
            vec3 d = v3_scale(planar3(albedo, n, p), w);
            vec3 h = planar3(accum, n, p), f = planar3(src, n, p);
            float dc[3] = {d.x, d.y, d.z}, hc[3] = {h.x, h.y, h.z}, fc[3] = {f.x, f.y, f.z};
            /* the variance of the history's luminance (variance.cl's temporal estimate), per channel in
             * proportion to the channel's level */
            float N = len[p], m1 = moments[p], m2 = moments[n + p], l = luminance(h);
            float var = N > 1.5f ? m_max(m2 - m1 * m1, 0.0f) * N / ((N - 1.0f) * m_min(N, n_eff_max)) : m2;
            float inv_l2 = l > 0.0f ? var / (l * l) : 0.0f;
            for (int c = 0; c < 3; ++c) {
                sh[c] += dc[c] * m_max(hc[c], 0.0f);
                sf[c] += dc[c] * m_max(fc[c], 0.0f);
                sv[c] += dc[c] * dc[c] * (l > 0.0f ? hc[c] * hc[c] * inv_l2 : var);
            }
        }
    }
    int t = ty * ntx + tx, count = ntx * nty;
    float share = surface > 0.0f ? ramp / surface : 0.0f;
    for (int c = 0; c < 3; ++c) {
        /* the filter's loss e kept as far as it stands out of the noise of the tile's unfiltered
         * light: e^2 / (e^2 + sigma^2 var) of it (a Wiener gain) */
        float e = sh[c] - sf[c], e2 = e * e;
        float keep = e2 > 0.0f ? e2 / (e2 + sigma * sigma * sv[c]) : 0.0f;
        gains[c * count + t] = lerpf(1.0f, conserve_ratio(sf[c] + keep * e, sf[c]), share);
    }
}
