/* compact_scatter: the second half of the order-preserving compaction of a queue.
 * One work-item per block of COMPACT_BLOCK entries: its output offset is the sum of
 * the earlier blocks' counts; it copies its flagged entries to out_queue and, when
 * rest_q >= 0, the others to rest_queue, both in source order, so the outputs list
 * slots in ascending order as the source does. The last block writes the counts.
 * Consumes: the source queue and flags[0 .. n-1], n = counters[bounce * Q_COUNT + src_q];
 *           block_counts from compact_count.
 * Produces: out_queue and its count counters[out_bounce * Q_COUNT + out_q]; if rest_q >= 0,
 *           rest_queue and its count counters[bounce * Q_COUNT + rest_q]. */
#include "integrators/wavefront/wavefront.h"

__kernel void compact_scatter(QUEUE_ARGS, int src_q, __global const uchar* flags,
                              __global const int* block_counts, __global const int* src_queue,
                              __global int* out_queue, int out_bounce, int out_q,
                              __global int* rest_queue, int rest_q) {
    int block = get_global_id(0);
    int n = queue_count(counters, bounce, src_q);
    int begin = block * COMPACT_BLOCK;
    if (begin >= n) return;
    int end = min(begin + COMPACT_BLOCK, n);
    int out = 0;
    for (int b = 0; b < block; ++b) out += block_counts[b];
    if (rest_q >= 0) {
        for (int i = begin; i < end; ++i) {
            int slot = src_queue[i];
            if (flags[i]) out_queue[out++] = slot;
            else rest_queue[i - out] = slot;
        }
    } else {
        for (int i = begin; i < end; ++i) {
            int slot = src_queue[i];
            if (flags[i]) out_queue[out++] = slot;
        }
    }
    if (end == n) {
        counters[out_bounce * Q_COUNT + out_q] = out;
        if (rest_q >= 0) counters[bounce * Q_COUNT + rest_q] = n - out;
    }
}
