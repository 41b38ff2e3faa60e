/* wavefront.h: what the seven wavefront stages share — the path state accessors
 * (generated from pyclpt/path_state.py for the SoA or AoS layout), the queues
 * and the per-bounce counters.
 *
 * Queues hold path slots (0 .. wave size - 1). Each is compacted: a producer
 * takes the next free entry with atomic_inc on its counter. Counters live in
 * one int buffer, Q_COUNT per bounce (counters[bounce * Q_COUNT + queue]), all
 * zeroed on the device before a wave; so the counts of every bounce remain for
 * the statistics. The ray queue is double-buffered across bounces: bounce b
 * reads ray queue b % 2 and sample_bsdf fills (b + 1) % 2. */
#ifndef PYCLPT_WAVEFRONT_H
#define PYCLPT_WAVEFRONT_H

#include "path.h"
#include "path_state.h"

#define Q_RAY 0     /* rays to intersect (bounce b) */
#define Q_HIT 1     /* paths that hit a surface: hit processing, then BSDF sampling */
#define Q_MISS 2    /* paths that left the scene */
#define Q_SHADOW 3  /* shadow rays to test */
#define Q_LIGHT 4   /* unoccluded shadow rays: light contribution */
#define Q_COUNT 5

#define QUEUE_ARGS __global int *counters, int bounce

static inline int queue_count(__global const int* counters, int bounce, int q) {
    return counters[bounce * Q_COUNT + q];
}

static inline void queue_push(__global int* queue, __global int* counters, int bounce, int q, int slot) {
    int at = atomic_inc((volatile __global int*)&counters[bounce * Q_COUNT + q]);
    queue[at] = slot;
}

/* The random-number key of the path in a slot: (seed, pixel, sample). */
static inline RngKey path_key(const PathStore* P, int slot, uint seed, uint sample) {
    return rng_key(seed, (uint)path_get_pixel(P, slot), sample);
}

#endif
