/* light_age: frames since the lighting last changed in view. One work-item; after light_change.
 *
 * Where at least LIGHT_CHANGE_SHARE of the pixels (and LIGHT_CHANGE_MIN) saw a light change this frame
 * (light_change), the age is
 * 0, else one more than the last frame's (capped); antilag cuts more readily while it is under
 * DenoiserSettings.antilag_frames: a light turned down by 4 changes the light of every surface it
 * reaches in this frame, but the dim, noisy ones (a box's face lit only indirectly) show it to the
 * anti-lag's statistic only over several frames, and kept the old light there for tens of frames
 * (docs/denoising.md, "The light change: cutting more readily after it").
 *
 * Consumes: changed[0] (light_change: this frame's count), age[0] (the last frame's).
 * Produces: age[0]; changed[0] zeroed for the next frame. */
#include "denoise/svgf.h"

__kernel void light_age(volatile __global int* changed, __global int* age, int pixels) {
    if (get_global_id(0) != 0) return;
    int least = max(LIGHT_CHANGE_MIN, (int)(LIGHT_CHANGE_SHARE * (float)pixels));
    age[0] = changed[0] >= least ? 0 : min(age[0] + 1, LIGHT_AGE_MAX);
    changed[0] = 0;
}
