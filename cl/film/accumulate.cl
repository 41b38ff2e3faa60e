/* accumulate: adds frames to the running sum, in frame order; resolve: the average.
 *
 * One work-item per pixel over a 2D range (work-groups ACC_LOCAL_X x ACC_LOCAL_Y; the host
 * picks the shape). Two kernels share one body, accumulate_pixel:
 *   accumulate_batch  `count` frames stacked in `frames` (Accumulator.add_batch), one launch;
 *   accumulate_frame  one frame: the same body with count = 1, so the frame loop disappears and
 *                     a CPU driver can vectorise across work-items (Accumulator.add).
 * Both run the same arithmetic in the same order, so they give bit-identical sums.
 *
 * Consumes: frames[first + k * frame_stride + pixel * ACC_CHANNELS + channel], k < count.
 * Produces: state[pixel * ACC_CHANNELS + channel] (the running sum, see accumulate.h);
 *           counters[0] += pixel samples with a NaN/inf value (added as zero),
 *           counters[1] += pixel samples whose sum would not be finite (not added).
 * Frame k is the (n0 + k + 1)-th frame; past frame ema_max (ema_max > 0) the sum follows an
 * exponential moving average with weight 1 / ema_max. `opaque` is always 0 (the Kahan guard,
 * accumulate.h). */
#include "film/accumulate.h"

/* Channel loops are unrolled in the source: the per-channel arrays then become scalars before
 * the driver builds its work-item loops (PoCL otherwise keeps arrays of pairs in memory, one per
 * work-item, and cannot vectorise). */
#define CHANNEL_LOOP(c) _Pragma("unroll") for (int c = 0; c < ACC_CHANNELS; ++c)

#ifndef ACC_LOCAL_X
#define ACC_LOCAL_X 16
#endif
#ifndef ACC_LOCAL_Y
#define ACC_LOCAL_Y 16
#endif

static inline __attribute__((always_inline))
void accumulate_pixel(__global acc_store_t* state, __global const input_t* frames, size_t base,
                      ulong first, ulong frame_stride, int count, uint n0, uint ema_max,
                      uint opaque, volatile __global uint* counters) {
    acc_t a[ACC_CHANNELS];
    CHANNEL_LOOP(c) a[c] = acc_load(state, base + c);
    uint skipped = 0u, overflowed = 0u;
    __global const input_t* f = frames + first + base;
    for (int k = 0; k < count; ++k, f += frame_stride) {
        input_t v[ACC_CHANNELS];
        uint bad = 0u;
        CHANNEL_LOOP(c) {
            v[c] = f[c];
            bad |= input_bad(v[c]);
        }
        CHANNEL_LOOP(c) v[c] = bad ? (input_t)0 : v[c];
        uint n = n0 + (uint)k + 1u;
        bool ema = ema_max != 0u && n > ema_max;
        acc_t next[ACC_CHANNELS];
        uint over = 0u;
        CHANNEL_LOOP(c) {
            next[c] = ema ? acc_ema(a[c], v[c], ema_max, opaque) : acc_add(a[c], v[c], opaque);
            over |= acc_bad(next[c]);
        }
        CHANNEL_LOOP(c) a[c] = over ? a[c] : next[c];
        skipped += bad;
        overflowed += over;
    }
    CHANNEL_LOOP(c) acc_store(state, base + c, a[c]);
    if (skipped) atomic_add(&counters[0], skipped);
    if (overflowed) atomic_add(&counters[1], overflowed);
}

#define PIXEL_BASE()                                                  \
    int x = get_global_id(0), y = get_global_id(1);                   \
    if (x >= width || y >= height) return;                            \
    size_t base = ((size_t)y * width + x) * ACC_CHANNELS

__kernel __attribute__((reqd_work_group_size(ACC_LOCAL_X, ACC_LOCAL_Y, 1)))
void accumulate_batch(__global acc_store_t* state, __global const input_t* frames, int width, int height,
                      ulong first, ulong frame_stride, int count, uint n0, uint ema_max, uint opaque,
                      volatile __global uint* counters) {
    PIXEL_BASE();
    accumulate_pixel(state, frames, base, first, frame_stride, count, n0, ema_max, opaque, counters);
}

__kernel __attribute__((reqd_work_group_size(ACC_LOCAL_X, ACC_LOCAL_Y, 1)))
void accumulate_frame(__global acc_store_t* state, __global const input_t* frames, int width, int height,
                      ulong first, uint n0, uint ema_max, uint opaque, volatile __global uint* counters) {
    PIXEL_BASE();
    accumulate_pixel(state, frames, base, first, 0, 1, n0, ema_max, opaque, counters);
}

/* resolve: the output image, out[pixel * ACC_CHANNELS + channel] = sum / divisor as float. */
__kernel __attribute__((reqd_work_group_size(ACC_LOCAL_X, ACC_LOCAL_Y, 1)))
void resolve(__global const acc_store_t* state, __global float* out, int width, int height, uint divisor) {
    PIXEL_BASE();
    CHANNEL_LOOP(c) out[base + c] = acc_mean(acc_load(state, base + c), divisor);
}
