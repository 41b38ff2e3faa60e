/* modulate: the denoised colour, the filtered illumination times the albedo. One work-item per
 * pixel, 2D range.
 *
 * With conserve, the filtered illumination of a surface pixel is first scaled by the filter's
 * energy balance (conserve.cl, conserve_gain.cl: per 8x8 tile, bilinear between the tiles' centres),
 * ramped in with the pixel's history length N (svgf.h, conserve_ramp: none up to 2 frames, all from
 * 8 on).
 *
 * The albedo is the footprint albedo A of reproject (the pixel's divisors, svgf.h albedo_divisors,
 * blended as its long history), which demodulated the samples, so a pixel whose illumination came
 * through unfiltered gets its colour history back exactly (A x the long history is the colour's
 * moving average; with a constant albedo, A is its divisor and the frame's colour comes back).
 * Then the emission history (reproject: the emitted part of the colour, never filtered) is added back.
 * With give_back, the firefly clamp's deficit first (cl/denoise/deficit.cl): the illumination gets
 * g x level added, g the tiles' shares and level their mean illumination (sum d H / sum d), both
 * bilinear between the centres of the 2x2 tiles around p (deficit_gain: a tile's share is the mean
 * of the deficit pass's shares over the 3x3 tiles around it, the largest left out, so that one
 * tile's outlier, a lone firefly, gives nothing back; g is 0 exactly where no tile around has a
 * share). Added to the level rather than scaling the pixel, the energy goes where the light is on
 * average, not into the blotches that the clamp already let through.
 * A non-finite product (an overflow) is written as 0: no NaN or inf ever leaves the denoiser.
 *
 * Consumes: src[c * pixels + p] (padded, svgf.h; c < 3: the filtered illumination, the last
 *           a-trous iteration);
 *           albedo (reproject: the footprint albedo A, padded); emis[c * pixels + p] (padded: reproject's emission
 *           history); gains (deficit_gain: shares and levels per tile); conserve (conserve_gain: the
 *           gain per 8x8 tile, c < 3); geo (GEO_DEPTH, padded), len (N, padded).
 * Produces: out[3 p + c] (interleaved RGB, written through the opaque stride unit = 1). */
#include "denoise/svgf.h"

__kernel void modulate(__global const float* src, __global const float* albedo, __global const float* emis,
                       __global const float* gains, __global const float* conserve, __global const float* geo,
                       __global const float* len, __global float* out, int width, int height, int unit,
                       int give_back, int conserve_on) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    src += PAD;
    emis += PAD;
    geo += PAD;
    len += PAD;
    albedo += PAD;
    vec3 il = planar3(src, n, p);
    /* the filter's energy balance (conserve.cl), bilinear between the tiles' centres, ramped in with
     * the history as the a-trous weight's symmetry is (conserve_ramp) */
    float ramp = conserve_on && geo[GEO_DEPTH * n + p] > 0.0f ? conserve_ramp(len[p]) : 0.0f;
    if (ramp > 0.0f) {
        int ntx = conserve_tiles(width), nty = conserve_tiles(height), count = ntx * nty;
        float k[3];
        for (int c = 0; c < 3; ++c)
            k[c] = lerpf(1.0f, tile_bilinear(conserve + c * count, ntx, nty, CONSERVE_TILE, x, y), ramp);
        il = v3_mul(il, v3(k[0], k[1], k[2]));
    }
    vec3 g = v3_splat(0.0f), lev = v3_splat(0.0f);
    if (give_back) {
        /* the robust shares of the 2x2 tiles around p, bilinear between the tiles' centres */
        int ntx = deficit_tiles(width), nty = deficit_tiles(height), count = ntx * nty;
        float gc[3], lc[3];
        for (int c = 0; c < 3; ++c) {
            gc[c] = m_min(tile_bilinear(gains + c * count, ntx, nty, DEFICIT_TILE, x, y), DEFICIT_MAX_LONG);
            lc[c] = tile_bilinear(gains + (3 + c) * count, ntx, nty, DEFICIT_TILE, x, y);
        }
        g = v3(gc[0], gc[1], gc[2]);
        lev = v3(lc[0], lc[1], lc[2]);
    }
    il = v3_add(il, v3_mul(lev, g)); /* g = 0: il exactly */
    vec3 c = v3_add(v3_mul(il, planar3(albedo, n, p)), planar3(emis, n, p));
    c = all_finite3(c) ? c : v3_splat(0.0f);
    __global float* o = out + 3 * p;
    o[0] = c.x;
    o[unit] = c.y;
    o[2 * unit] = c.z;
}
