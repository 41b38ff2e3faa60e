/* compact.h: what the two kernels of the order-preserving compaction (compact_count.cl, compact_scatter.cl)
 * share; built with -DCOMPACT_BLOCK (and on the GPU class -DCOMPACT_GROUP) alone. */
#ifndef PYCLPT_WAVEFRONT_COMPACT_H
#define PYCLPT_WAVEFRONT_COMPACT_H

#include "integrators/wavefront/queues.h"

/* Entries of a queue that one work-item of the compaction stages handles: -DCOMPACT_BLOCK from
 * pyclpt/integrators/wavefront.py, which sizes the block-count buffer by it. */
#ifndef COMPACT_BLOCK
#error "COMPACT_BLOCK must be defined (-DCOMPACT_BLOCK=...)"
#endif

/* COMPACT_GROUP (-D, GPU class only: pyclpt/integrators/wavefront.py): the compaction runs one
 * work-group of COMPACT_GROUP lanes per block instead of one work-item, each lane owning
 * COMPACT_BLOCK / COMPACT_GROUP consecutive entries, so a GPU keeps its lanes busy (docs/gpu.md).
 * The counts are integers: the queues are the one-work-item version's, entry for entry. */
#ifdef COMPACT_GROUP
#if COMPACT_BLOCK % COMPACT_GROUP != 0
#error "COMPACT_BLOCK must be a multiple of COMPACT_GROUP"
#endif
#define COMPACT_PER_LANE (COMPACT_BLOCK / COMPACT_GROUP)

/* The work-group's exclusive prefix sum of v (Hillis-Steele in local memory `scratch`, COMPACT_GROUP
 * ints); *total receives the group's sum. Every lane of the group must call it. always_inline: PoCL 3.0
 * crashes when it runs a barrier inside a function it kept out of line (two calls in one kernel). */
static inline __attribute__((always_inline)) int compact_group_scan(int v, __local int* scratch, int* total) {
    int lid = (int)get_local_id(0);
    scratch[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int off = 1; off < COMPACT_GROUP; off <<= 1) {
        int t = lid >= off ? scratch[lid - off] : 0;
        barrier(CLK_LOCAL_MEM_FENCE);
        scratch[lid] += t;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    int inclusive = scratch[lid];
    *total = scratch[COMPACT_GROUP - 1];
    barrier(CLK_LOCAL_MEM_FENCE); /* scratch is free again for the next call */
    return inclusive - v;
}

/* The flagged entries among this lane's entries [lo, hi) of a block. */
static inline int compact_lane_count(__global const uchar* flags, int lo, int hi) {
    int sum = 0;
    for (int i = lo; i < hi; ++i) sum += flags[i];
    return sum;
}
#endif

#endif
