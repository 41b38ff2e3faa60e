/* clip_history: SVGF's temporal pass, second half: the long history, clipped into the fast
 * history's neighbourhood (NRD RELAX's history clamping), blended with the frame's sample.
 * One work-item per pixel and colour channel, 3D range (width x height x 3): the clipping and the
 * blend are per channel, and one channel a work-item leaves no alike x/y/z computations side by side
 * for PoCL's SLP pre-pass to pair (which would stop its work-item loop vectorizer).
 *
 * The fast history (reproject: alpha max(fast_alpha, 1/N), a few frames) follows a change of the
 * lighting within those frames; the long one (alpha max(alpha_min, 1/N)) would show the old
 * lighting for tens of frames (ghosting). So before the blend, the reprojected long history is
 * clamped per channel into mean +- clip_gamma x sigma of the fast history over the
 * (2 CLIP_RADIUS + 1)^2 pixels around p inside the image (sigma with Bessel's correction; a box of
 * one pixel, in a 1x1 image, does not clip), widened to hold p's own fast history; clip_gamma < 0:
 * not clipped. Then history =
 * lerp(clipped, sample, max(alpha_min, 1/N)); a non-finite result (an overflow) becomes the sample.
 *
 * Consumes: temporal[0..2] (the sample) and temporal[3..5] (the reprojected long history) from
 *           reproject; fast[c * pixels + p] (this frame's fast history); len[p] (N); all
 *           padded (svgf.h, PAD).
 * Produces: accum[c * pixels + p] (padded), c < 3: the long history of this frame (demodulated
 *           illumination). */
#include "denoise/svgf.h"

#ifndef CLIP_RADIUS /* -DCLIP_RADIUS from pyclpt/denoise/svgf.py (DenoiserSettings.clip_radius) */
#error "CLIP_RADIUS must be defined (-DCLIP_RADIUS=1 or 2)"
#endif

__kernel void clip_history(__global const float* temporal, __global const float* fast, __global const float* len,
                           __global float* accum, int width, int height, float alpha_min, float clip_gamma) {
    int x = get_global_id(0), y = get_global_id(1), c = get_global_id(2);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    __global const float* f = fast + PAD + c * n;
    temporal += PAD + c * n;
    len += PAD;
    accum += PAD + c * n;

    /* the statistics of the box about its centre's value, which keeps mean2 - mean^2 from cancelling
     * to garbage where the values are nearly equal (a converged smooth area: the centre would be
     * clipped by its rounding errors) */
    float centre = f[p];
    float sum = 0.0f, sum2 = 0.0f, count = 0.0f;
    UNROLL for (int dy = -CLIP_RADIUS; dy <= CLIP_RADIUS; ++dy) {
        UNROLL for (int dx = -CLIP_RADIUS; dx <= CLIP_RADIUS; ++dx) {
            int tx = x + dx, ty = y + dy;
            float w = (tx >= 0 && tx < width && ty >= 0 && ty < height) ? 1.0f : 0.0f;
            float v = w * (f[row_at(y, dy, width, height) + tx] - centre);
            sum += v;
            sum2 += v * v;
            count += w;
        }
    }
    float dmean = sum / count;
    float mean = centre + dmean;
    /* the spread of the box's values with Bessel's correction (count / (count - 1)): a box of one
     * pixel (a 1x1 image) tells nothing of the spread and does not clip, rather than clipping the
     * long history to the fast one, its noise and all */
    float var_s = m_max(sum2 / count - dmean * dmean, 0.0f);
    float sigma = count > 1.5f ? m_sqrt(var_s * count / (count - 1.0f)) : INFINITY;
    float s = temporal[p], h = temporal[3 * n + p];
    float g = m_max(clip_gamma, 0.0f);
    float spread = sigma < INFINITY ? g * sigma : INFINITY; /* not 0 x inf */
    /* the box always holds the pixel's own fast history: a history that agrees with its own recent
     * frames is never clipped (an isolated bright pixel among dark ones would be, by a 5x5 box) */
    h = clip_gamma >= 0.0f ? m_clamp(h, m_min(mean - spread, centre), m_max(mean + spread, centre)) : h;
    float out = lerpf(h, s, m_max(alpha_min, 1.0f / len[p]));
    accum[p] = m_isfinite(out) ? out : s;
}
