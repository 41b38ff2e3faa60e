/* compact_scatter: the second half of the order-preserving compaction of a queue.
 * One work-item per block of COMPACT_BLOCK entries: its output offset is the sum of
 * the earlier blocks' counts; it copies its flagged entries to out_queue and, when
 * rest_q >= 0, the others to rest_queue, both in source order, so the outputs list
 * slots in ascending order as the source does. The last block writes the counts.
 * Consumes: the source queue and flags[0 .. n-1], n = counters[bounce * Q_COUNT + src_q];
 *           block_counts from compact_count.
 * Produces: out_queue and its count counters[out_bounce * Q_COUNT + out_q]; if rest_q >= 0,
 *           rest_queue and its count counters[bounce * Q_COUNT + rest_q].
 * With -DCOMPACT_GROUP (GPU class) a work-group of lanes does each block's work. */
#include "integrators/wavefront/compact.h"

#ifdef COMPACT_GROUP
/* GPU class: a work-group per block. The group sums the earlier blocks' counts (a strided partial sum a
 * lane, then a scan), scans its lanes' counts for each lane's offset, and each lane copies its
 * COMPACT_PER_LANE consecutive entries in order: the same queues as the one-work-item version. */
__kernel __attribute__((reqd_work_group_size(COMPACT_GROUP, 1, 1)))
void compact_scatter(QUEUE_ARGS, int src_q, __global const uchar* flags,
                     __global const int* block_counts, __global const int* src_queue,
                     __global int* out_queue, int out_bounce, int out_q,
                     __global int* rest_queue, int rest_q) {
    __local int scratch[COMPACT_GROUP];
    int block = (int)get_group_id(0), lid = (int)get_local_id(0);
    int n = queue_count(counters, bounce, src_q);
    int begin = block * COMPACT_BLOCK;
    if (begin >= n) return; /* the whole group */
    int end = min(begin + COMPACT_BLOCK, n);
    int earlier = 0;
    for (int b = lid; b < block; b += COMPACT_GROUP) earlier += block_counts[b];
    int base;
    compact_group_scan(earlier, scratch, &base);
    int lo = min(begin + lid * COMPACT_PER_LANE, end), hi = min(lo + COMPACT_PER_LANE, end);
    int block_total;
    int out = base + compact_group_scan(compact_lane_count(flags, lo, hi), scratch, &block_total);
    for (int i = lo; i < hi; ++i) {
        int slot = src_queue[i];
        if (flags[i]) out_queue[out++] = slot;
        else if (rest_q >= 0) rest_queue[i - out] = slot;
    }
    if (lid == 0 && end == n) {
        counters[out_bounce * Q_COUNT + out_q] = base + block_total;
        if (rest_q >= 0) counters[bounce * Q_COUNT + rest_q] = n - (base + block_total);
    }
}
#else
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
#endif
