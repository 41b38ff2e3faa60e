/* count_dropped: adds up a batch's dropped (NaN/inf) samples and clears their marks.
 *
 * The integrators' film_commit (integrators/path.h) writes 0 to the frame for a NaN/inf sample
 * and adds 1 to marks[film slot] (a plain add: one path owns a slot per batch), so the stages that
 * commit need no atomic. One work-item sums COUNT_CHUNK marks; integer sums do not depend on
 * the order the work-items run in.
 * Consumes: marks[0 .. pixels-1] (uchar, dropped samples per film slot since the last count;
 *           pixels = the batch's frames times the image's pixels).
 * Produces: dropped[0] += their sum; marks zeroed. */

#include "film/marks.h"

#ifndef COUNT_CHUNK /* -DCOUNT_CHUNK from pyclpt/film/film.py, which sizes the launch by it */
#error "COUNT_CHUNK must be defined (-DCOUNT_CHUNK=...)"
#endif

__kernel void count_dropped(__global uchar* marks, int pixels, volatile __global int* dropped) {
    int begin = (int)get_global_id(0) * COUNT_CHUNK;
    if (begin >= pixels) return;
    int sum = take_marks(marks, begin, min(begin + COUNT_CHUNK, pixels));
    if (sum != 0) atomic_add(dropped, sum);
}
