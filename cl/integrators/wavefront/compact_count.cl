/* compact_count: the first half of the order-preserving compaction of a queue.
 * One work-item per block of COMPACT_BLOCK entries of the source queue counts the
 * entries its stage flagged (flags[i] != 0).
 * Consumes: flags[0 .. n-1] written by the stage that read the source queue, with
 *           n = counters[bounce * Q_COUNT + src_q].
 * Produces: block_counts[block], the flagged entries of each block. */
#include "integrators/wavefront/wavefront.h"

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
