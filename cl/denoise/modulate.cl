/* modulate: the denoised colour, the filtered illumination times the albedo. One work-item per
 * pixel, 2D range.
 *
 * The albedo divides as in demodulate (svgf.h, albedo_divisors: floored at ALBEDO_REL x the largest
 * channel; 1 where no channel is above ALBEDO_MIN, or the channel is not finite), so a pixel
 * whose illumination came through unfiltered gets its colour back exactly.
 * Then the emission history (reproject: the emitted part of the colour, never filtered) is added back.
 * A non-finite product (an overflow) is written as 0: no NaN or inf ever leaves the denoiser.
 *
 * Consumes: src[c * pixels + p] (padded, svgf.h; c < 3: the filtered illumination, the last
 *           a-trous iteration);
 *           aovs (cl/film/aovs.h: the albedo); emis[c * pixels + p] (padded: reproject's emission
 *           history).
 * Produces: out[3 p + c] (interleaved RGB, written through the opaque stride unit = 1). */
#include "denoise/svgf.h"

__kernel void modulate(__global const float* src, __global const float* aovs, __global const float* emis,
                       __global float* out, int width, int height, int unit) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    src += PAD;
    emis += PAD;
    vec3 c = v3_add(v3_mul(planar3(src, n, p), aov_divisor(aovs, n, p)), planar3(emis, n, p));
    c = all_finite3(c) ? c : v3_splat(0.0f);
    __global float* o = out + 3 * p;
    o[0] = c.x;
    o[unit] = c.y;
    o[2 * unit] = c.z;
}
