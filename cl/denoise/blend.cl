/* blend: the seed's denoiser (a note on a Vulkan/NRD integration that shipped only this): a fixed
 * exponential blend of the frames, history = 0.7 history + 0.3 frame (history_weight = 0.7), with
 * no reprojection. The first frame after a reset is the frame itself. One work-item per pixel.
 *
 * Consumes: color[3 p + c] (interleaved RGB; NaN/inf replaced by 0, all three channels, and
 *           counted); history[3 p + c] (the previous output, unless first != 0).
 * Produces: history[3 p + c] = the output of this frame (in place); marks[p] = 1 where the colour
 *           was not finite, else 0 (summed by film/count_dropped.cl). */
#include "denoise/svgf.h"

__kernel void blend(__global const float* color, __global float* history, __global uchar* marks, int pixels,
                    int unit, int first, float history_weight) {
    int p = get_global_id(0);
    if (p >= pixels) return;
    bool bad;
    vec3 c = load_color(color, p, unit, &bad);
    __global float* h = history + 3 * p;
    vec3 prev = rgb_at(h, unit);
    float a = first ? 0.0f : history_weight;
    vec3 out = v3_add(v3_scale(prev, a), v3_scale(c, 1.0f - a));
    out = first ? c : out;
    h[0] = out.x;
    h[unit] = out.y;
    h[2 * unit] = out.z;
    marks[p] = bad ? 1 : 0;
}
