/* The splatting film's passes over a batch of frames (film/splat.h, pyclpt/film/splat.py): splat_axes, then
 * splat_gather.
 *
 * The film renders its window (width x height pixels at (x0, y0) of the image) with a margin of `reach`
 * pixels on each side, inside the image or beyond it (Mitsuba's sample_border): in_width = width + 2 reach
 * columns a frame, in_pixels = in_width (height + 2 reach). A sample's film position is recomputed from its
 * random numbers: splat_position of its pixel's index in the image padded by `reach` (padded_width pixels a
 * row, as film_pixel gives it) and sample first_sample + j for frame j.
 *
 * Consumes: the frame buffer of a batch (the integrators' radiance per film slot of the margined window).
 * Produces: per frame, the filter-weighted sums of its samples' radiance and of their weights per pixel of the
 *           window (what the two accumulators sum; the image is their ratio). Each kernel says its own below. */
#include "core/common.h"
#include "film/splat.h"

#define SPLAT_TAPS(reach) (2 * (reach) + 1)

/* splat_axes: one work-item per sample (margined pixel q, frame j; global size in_width x (height + 2 reach)
 * x count): the filter's weights along each axis in the pixels it reaches, w(d - 1/2 + pos) for the pixel d
 * = -reach..reach pixels before q (splat_pair_weight's factors), so the gather multiplies instead of drawing
 * (2 reach + 1)^2 positions and evaluating w twice for each.
 * Consumes: nothing but the random numbers' keys.
 * Produces: axes[(2 (j in_pixels + q) + a) taps + d + reach], a = 0 (x), 1 (y); taps = 2 reach + 1. */
__kernel void splat_axes(__global float* axes, int width, int height, int padded_width, int x0, int y0, uint seed,
                         uint first_sample, int reach, float extent) {
    int qx = get_global_id(0), qy = get_global_id(1), j = get_global_id(2);
    int in_width = width + 2 * reach, in_height = height + 2 * reach;
    if (qx >= in_width || qy >= in_height) return;
    vec2 pos = splat_position(seed, (uint)((y0 + qy) * padded_width + x0 + qx), first_sample + (uint)j);
    size_t q = (size_t)j * (size_t)in_width * (size_t)in_height + (size_t)qy * in_width + qx;
    __global float* ax = axes + 2 * q * SPLAT_TAPS(reach);
    __global float* ay = ax + SPLAT_TAPS(reach);
    for (int d = -reach; d <= reach; ++d) {
        ax[d + reach] = splat_weight(extent, ((float)d - 0.5f) + pos.x);
        ay[d + reach] = splat_weight(extent, ((float)d - 0.5f) + pos.y);
    }
}

/* splat_gather: one work-item per window pixel p and frame j (global size width x height x count): the
 * weighted sum of the frame's samples of p's (2 reach + 1)^2 neighbours q = p + (dx, dy), each weighted by
 * w_pq = ax_q[dx] ay_q[dy] (splat_axes), in a fixed order (rows, then columns), and the sum of the weights.
 * Consumes: frame[3 (j in_pixels + q) + c] (the integrators' radiance per film slot, path.h film_commit),
 *           axes (splat_axes).
 * Produces: out[3 (j pixels + p) + c] = inv_norm * sum_q w_pq L_q (c < 3),
 *           weights[j pixels + p] = inv_norm * sum_q w_pq (pixels = width height);
 *           inv_norm = 1 / (integral of w)^2, so both average to about the image and 1. */
__kernel void splat_gather(__global const float* frame, __global const float* axes, __global float* out,
                           __global float* weights, int width, int height, int reach, float inv_norm) {
    int x = get_global_id(0), y = get_global_id(1), j = get_global_id(2);
    if (x >= width || y >= height) return;
    int in_width = width + 2 * reach;
    size_t in_base = (size_t)j * (size_t)in_width * (size_t)(height + 2 * reach);
    float r = 0.0f, g = 0.0f, b = 0.0f, wsum = 0.0f;
    for (int dy = -reach; dy <= reach; ++dy) {
        int qy = y + reach + dy; /* in the margined window */
        for (int dx = -reach; dx <= reach; ++dx) {
            int qx = x + reach + dx;
            size_t q = in_base + (size_t)qy * in_width + qx;
            __global const float* ax = axes + 2 * q * SPLAT_TAPS(reach);
            float w = ax[dx + reach] * ax[SPLAT_TAPS(reach) + dy + reach];
            __global const float* L = frame + 3 * q;
            r += w * L[0];
            g += w * L[1];
            b += w * L[2];
            wsum += w;
        }
    }
    size_t p = (size_t)j * (size_t)width * (size_t)height + (size_t)y * width + x;
    out[3 * p + 0] = r * inv_norm;
    out[3 * p + 1] = g * inv_norm;
    out[3 * p + 2] = b * inv_norm;
    weights[p] = wsum * inv_norm;
}
