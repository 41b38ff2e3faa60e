/* modulate: the denoised colour, the filtered illumination times the albedo. One work-item per
 * pixel, 2D range.
 *
 * The albedo divides as in demodulate (svgf.h, albedo_divisors: floored at ALBEDO_REL x the largest
 * channel; 1 where no channel is above ALBEDO_MIN, or the channel is not finite), so a pixel
 * whose illumination came through unfiltered gets its colour back exactly.
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
 *           aovs (cl/film/aovs.h: the albedo); emis[c * pixels + p] (padded: reproject's emission
 *           history); gains (deficit_gain: shares and levels per tile).
 * Produces: out[3 p + c] (interleaved RGB, written through the opaque stride unit = 1). */
#include "denoise/svgf.h"

__kernel void modulate(__global const float* src, __global const float* aovs, __global const float* emis,
                       __global const float* gains, __global float* out, int width, int height, int unit,
                       int give_back) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    src += PAD;
    emis += PAD;
    vec3 g = v3_splat(0.0f), lev = v3_splat(0.0f);
    if (give_back) {
        /* the robust shares of the 2x2 tiles around p, bilinear between the tiles' centres */
        int ntx = deficit_tiles(width), nty = deficit_tiles(height);
        float u = ((float)x + 0.5f) / (float)DEFICIT_TILE - 0.5f, v = ((float)y + 0.5f) / (float)DEFICIT_TILE - 0.5f;
        float fu = m_floor(u), fv = m_floor(v);
        int u0 = (int)fu, v0 = (int)fv;
        float wu = u - fu, wv = v - fv;
        int x0 = clampi(u0, 0, ntx - 1), x1 = clampi(u0 + 1, 0, ntx - 1);
        int y0 = clampi(v0, 0, nty - 1) * ntx, y1 = clampi(v0 + 1, 0, nty - 1) * ntx;
        float gc[3], lc[3];
        for (int c = 0; c < 6; ++c) {
            __global const float* plane = gains + c * ntx * nty;
            float v = (plane[y0 + x0] * (1.0f - wu) + plane[y0 + x1] * wu) * (1.0f - wv)
                      + (plane[y1 + x0] * (1.0f - wu) + plane[y1 + x1] * wu) * wv;
            if (c < 3) gc[c] = m_min(v, DEFICIT_MAX);
            else lc[c - 3] = v;
        }
        g = v3(gc[0], gc[1], gc[2]);
        lev = v3(lc[0], lc[1], lc[2]);
    }
    vec3 il = planar3(src, n, p);
    il = v3_add(il, v3_mul(lev, g)); /* g = 0: il exactly */
    vec3 c = v3_add(v3_mul(il, aov_divisor(aovs, n, p)), planar3(emis, n, p));
    c = all_finite3(c) ? c : v3_splat(0.0f);
    __global float* o = out + 3 * p;
    o[0] = c.x;
    o[unit] = c.y;
    o[2 * unit] = c.z;
}
