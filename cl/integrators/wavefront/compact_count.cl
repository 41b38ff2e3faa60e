/* compact_count: the first half of the order-preserving compaction of a queue.
 * One work-item per block of COMPACT_BLOCK entries of the source queue counts the
 * entries its stage flagged (flags[i] != 0).
 * Consumes: flags[0 .. n-1] written by the stage that read the source queue, with
 *           n = counters[bounce * Q_COUNT + src_q].
 * Produces: block_counts[block], the flagged entries of each block.
 * With -DCOMPACT_GROUP (GPU class) a work-group of lanes does each block's work. */
#include "integrators/wavefront/compact.h"

#ifdef COMPACT_GROUP
/* GPU class: a work-group per block, each lane counting its COMPACT_PER_LANE entries (wavefront.h). */
__kernel __attribute__((reqd_work_group_size(COMPACT_GROUP, 1, 1)))
void compact_count(QUEUE_ARGS, int src_q, __global const uchar* flags, __global int* block_counts) {
    __local int scratch[COMPACT_GROUP];
    int block = (int)get_group_id(0);
    int n = queue_count(counters, bounce, src_q);
    int begin = block * COMPACT_BLOCK;
    if (begin >= n) return; /* the whole group */
    int lo = min(begin + (int)get_local_id(0) * COMPACT_PER_LANE, n);
    int total;
    compact_group_scan(compact_lane_count(flags, lo, min(lo + COMPACT_PER_LANE, n)), scratch, &total);
    if (get_local_id(0) == 0) block_counts[block] = total;
}
#else
__kernel void compact_count(QUEUE_ARGS, int src_q, __global const uchar* flags, __global int* block_counts) {
    int block = get_global_id(0);
    int n = queue_count(counters, bounce, src_q);
    int begin = block * COMPACT_BLOCK;
    if (begin >= n) return;
    int end = min(begin + COMPACT_BLOCK, n);
    int sum = 0;
    for (int i = begin; i < end; ++i) sum += flags[i];
    block_counts[block] = sum;
}
#endif
