/* Per-pixel (or per-slot) marks, one uchar each, added up by chunks of work-items: count_dropped's
 * NaN/inf samples, light_change's pixels that saw a light change (cl/denoise/light_change.cl). A
 * pass that writes marks needs no atomic; the pass that counts them adds one sum a chunk. */
#ifndef PYCLPT_FILM_MARKS_H
#define PYCLPT_FILM_MARKS_H

/* The sum of marks[begin .. end-1], which are then zeroed (only where the sum is not 0: a chunk
 * without marks is read, never written). */
static inline int take_marks(__global uchar* marks, int begin, int end) {
    int sum = 0;
    for (int i = begin; i < end; ++i) sum += marks[i];
    if (sum != 0)
        for (int i = begin; i < end; ++i) marks[i] = 0;
    return sum;
}

#endif
