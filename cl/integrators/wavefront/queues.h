/* queues.h: the wavefront's queues and their per-bounce counters, which the stages (wavefront.h) and the
 * compaction (compact.h) share. Nothing of the scene or the path state: the compaction kernels build from
 * this alone, so one program serves every scene.
 *
 * Queues hold path slots (0 .. wave size - 1). Counters live in one int buffer, Q_COUNT per bounce
 * (counters[bounce * Q_COUNT + queue]), all zeroed on the device before a wave; so the counts of every
 * bounce remain for the statistics. */
#ifndef PYCLPT_WAVEFRONT_QUEUES_H
#define PYCLPT_WAVEFRONT_QUEUES_H

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

#endif
