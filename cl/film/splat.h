/* splat.h: the film's reconstruction filter by splatting, as Mitsuba's film: a sample drawn uniformly in
 * its pixel (the box's jitter: camera_path compiled without -DSCENE_FILTER) counts in every pixel p the
 * filter reaches with weight w(x - cx_p) w(y - cy_p) (x, y: its film position; cx_p, cy_p: p's centre), and
 * p's value is the sum of its weighted samples over the sum of their weights. There is no scatter: a
 * gather (film/splat.cl; the backward pass's adjoint, gradients/backward.cl) lets a pixel sum the samples
 * of its neighbours, whose film positions are recomputed from the random numbers that placed them (key
 * seed, pixel, sample; bounce 0, DIM_CAMERA_X/Y), in a fixed order, so the image does not depend on the
 * integrator, the layout or the order in which paths ended. pyclpt/film/splat.py holds the same weights in
 * numpy.
 *
 * -DSPLAT_FILTER=FILTER_TENT | FILTER_GAUSSIAN; `extent` is the filter's radius (the tent's radius, 4
 * stddev for the gaussian), `reach` the neighbours summed on each side, ceil(extent + 1/2) - 1. */
#ifndef PYCLPT_SPLAT_H
#define PYCLPT_SPLAT_H

#include "core/rng.h"

#ifndef FILTER_TENT
#define FILTER_TENT 1 /* as scene/scene.h */
#define FILTER_GAUSSIAN 2
#endif

/* w(x), Mitsuba's definitions (src/rfilters/tent.cpp; gaussian.cpp: exp(-x^2 / (2 stddev^2)) minus its
 * value at 4 stddev, alpha = -1 / (2 stddev^2) = -8 / extent^2). */
static inline float splat_weight(float extent, float x) {
#if SPLAT_FILTER == FILTER_TENT
    return m_max(0.0f, 1.0f - m_abs(x) / extent);
#elif SPLAT_FILTER == FILTER_GAUSSIAN
    float alpha = -8.0f / (extent * extent);
    return m_max(0.0f, m_exp(alpha * x * x) - m_exp(-8.0f));
#else
#error "splat.h needs -DSPLAT_FILTER=FILTER_TENT or FILTER_GAUSSIAN"
#endif
}

/* The position in its pixel, [0, 1)^2, of sample `sample` of image pixel `pixel` (camera_path's jitter). */
static inline vec2 splat_position(uint seed, uint pixel, uint sample) {
    return rng_2d(rng_key(seed, pixel, sample), 0u, DIM_CAMERA_X);
}

/* The weight in pixel p of a sample at `pos` in its pixel q, dx = x_q - x_p and dy = y_q - y_p pixels from
 * p: w at its offset from p's centre, dx - 1/2 + pos.x (and y). */
static inline float splat_pair_weight(float extent, int dx, int dy, vec2 pos) {
    float ox = ((float)dx - 0.5f) + pos.x, oy = ((float)dy - 0.5f) + pos.y;
    return splat_weight(extent, ox) * splat_weight(extent, oy);
}

#endif
