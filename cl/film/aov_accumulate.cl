/* aov_accumulate: a batch's G-buffer records added to the per-pixel G-buffer, in sample order.
 * Consumes: slots (planar, film/aovs.h: channel c of film slot f at slots[c * n + f], n the slots of a
 *           full batch; the records of the first `frames` frames: slot f = j * pixels + pixel is frame j), first (1: the sums
 *           start over with this batch, e.g. every frame of a progressive render; 0: they go on), total
 *           (the frames summed after this batch).
 * Produces: sum[c * pixels + p] += frame j's value, j = 0, 1, ... (one work-item a pixel, so the sum's
 *           order is fixed); mean[c * pixels + p] = sum / total for the averaged channels, and for the
 *           ids (AOV_FLOATS ..) the pixel's first sample's value, kept in sum as well. */
#include "core/common.h"
#include "film/aovs.h"

__kernel void aov_accumulate(__global const float* slots, int n, int pixels, int frames, int first, int total,
                             __global float* sum, __global float* mean) {
    int p = get_global_id(0);
    if (p >= pixels) return;
    float inv = 1.0f / (float)total;
    for (int c = 0; c < AOV_FLOATS; ++c) {
        float s = first ? 0.0f : sum[c * pixels + p];
        for (int j = 0; j < frames; ++j) s += slots[c * n + j * pixels + p];
        sum[c * pixels + p] = s;
        mean[c * pixels + p] = s * inv;
    }
    for (int c = AOV_FLOATS; c < AOV_COUNT; ++c) {
        float id = first ? slots[c * n + p] : sum[c * pixels + p];
        sum[c * pixels + p] = id;
        mean[c * pixels + p] = id;
    }
}
