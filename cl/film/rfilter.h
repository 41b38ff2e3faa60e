/* rfilter.h: the film's reconstruction filter, by filter importance sampling: the camera ray's position in
 * its pixel is drawn from the normalised filter w(x) w(y) (Mitsuba's rfilter definitions, x and y in pixels
 * from the pixel's centre), with sample weight 1, so a pixel's plain average converges to what Mitsuba's
 * film gives when it splats samples with weights w and divides by their sum. pyclpt/buffers/rfilter.py
 * writes the constants and holds the same mapping in numpy. (A filter with estimator "splat" compiles the
 * box here and its film splats: film/splat.h.)
 *
 *   box (the default, no -D): uniform in the pixel, u itself;
 *   tent (radius r): the inverse of its CDF, r (sqrt(2u) - 1) or r (1 - sqrt(2 - 2u));
 *   gaussian: |x| interpolated in a table of the half filter's inverse CDF at t = (1 - |2u - 1|)^(1/4),
 *   the sign from u < 1/2.
 *
 * Needs scene/scene.h (CONST_FILTER_*, SCENE_FILTER). */
#ifndef PYCLPT_RFILTER_H
#define PYCLPT_RFILTER_H

#include "core/math.h"
#include "scene/scene.h"

/* The position in the pixel, in [0, 1) for the box and around 0.5 otherwise, for one uniform number u. */
static inline float rfilter_position(__global const float* c, float u) {
#if SCENE_FILTER == FILTER_TENT
    float r = c[CONST_FILTER_RADIUS];
    float x = u < 0.5f ? m_sqrt(2.0f * u) - 1.0f : 1.0f - m_sqrt(2.0f - 2.0f * u);
    return 0.5f + r * x;
#elif SCENE_FILTER == FILTER_GAUSSIAN
    float t = m_sqrt(m_sqrt(1.0f - m_abs(2.0f * u - 1.0f))) * (float)FILTER_TABLE;
    int k = m_imin((int)t, FILTER_TABLE - 1);
    float f = t - (float)k;
    float a = c[CONST_FILTER_TABLE + k], b = c[CONST_FILTER_TABLE + k + 1];
    float x = a + f * (b - a);
    return u < 0.5f ? 0.5f - x : 0.5f + x;
#else
    (void)c;
    return u;
#endif
}

#endif
