/* aov_accumulate: a batch's G-buffer records added to the per-pixel G-buffer, in sample order.
 * Consumes: slots (planar, film/aovs.h: channel c of film slot f at slots[c * n + f], n the slots of a
 *           full batch; the records of the first `frames` frames: slot f = j * frame_pixels + pixel is frame j,
 *           frame_pixels = traced_width x traced height, the window the integrators render), first (1: the
 *           sums start over with this batch, e.g. every frame of a progressive render; 0: they go on), total
 *           (the frames summed after this batch); width, pad: the G-buffer is the window of `pixels` pixels,
 *           `width` wide, at (pad, pad) of the rendered one (a splatting film renders a margin of pad
 *           pixels around its window, pyclpt/film/splat.py; 0 else: the same pixels).
 * Produces: sum[c * pixels + p] += frame j's value (times 2^-32, see below), j = 0, 1, ... (one work-item a pixel, so the sum's
 *           order is fixed); mean[c * pixels + p] = sum / total for the averaged channels, and for the
 *           ids (AOV_FLOATS ..) the pixel's first sample's value, kept in sum as well. */
#include "core/common.h"
#include "film/aovs.h"

/* The sums are of the values times 2^-32 (exact: a power of two) and the means scaled back, so that a
 * sum of values up to FLT_MAX (a 3e38 emitter) over up to 2^31 frames stays finite; a mean is the
 * same bits as sum / total unscaled (values below about 1e-29 may lose bits to subnormals). */
#define AOV_SUM_SCALE 2.3283064365386962890625e-10f /* 2^-32 */
#define AOV_MEAN_SCALE 4294967296.0f               /* 2^32 */

__kernel void aov_accumulate(__global const float* slots, int n, int pixels, int frames, int first, int total,
                             __global float* sum, __global float* mean, int frame_pixels, int width,
                             int traced_width, int pad) {
    int p = get_global_id(0);
    if (p >= pixels) return;
    int f = (p / width + pad) * traced_width + p % width + pad; /* its slot in frame 0 */
    float inv = 1.0f / (float)total;
    for (int c = 0; c < AOV_FLOATS; ++c) {
        float s = first ? 0.0f : sum[c * pixels + p];
        for (int j = 0; j < frames; ++j) s += slots[c * n + j * frame_pixels + f] * AOV_SUM_SCALE;
        sum[c * pixels + p] = s;
        mean[c * pixels + p] = (s * inv) * AOV_MEAN_SCALE;
    }
    for (int c = AOV_FLOATS; c < AOV_COUNT; ++c) {
        float id = first ? slots[c * n + f] : sum[c * pixels + p];
        sum[c * pixels + p] = id;
        mean[c * pixels + p] = id;
    }
}
