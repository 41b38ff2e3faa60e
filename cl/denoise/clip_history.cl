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
 * Anti-lag (NRD RELAX's idea, measured here as a test statistic): over the same box, restricted to
 * the pixels that hold a history (N >= 2: their reprojected long history is not the 0 of a
 * disocclusion), the mean of the fast histories and the mean of the long ones estimate the same
 * value while the lighting holds still, and differ when it changes (the fast one follows within a
 * few frames, the long one does not). Their difference over the standard error of the fast mean
 * (the box's spread over sqrt(count), Bessel-corrected) is written per channel; spatial detail
 * cancels, as both means are over the same pixels, and one outlier in the box cannot raise it above
 * about 1. The antilag pass of the same frame cuts the histories where its 3x3 mean exceeds
 * DenoiserSettings.antilag (cl/denoise/antilag.cl). 0 where clip_gamma < 0 (no clipping, no
 * anti-lag) or fewer than 3 pixels hold a history.
 *
 * Consumes: temporal[0..2] (the sample) and temporal[3..5] (the reprojected long history) from
 *           reproject; fast[c * pixels + p] (this frame's fast history); len[p] (N); moments;
 *           sample (demodulate: the raw sample, before the clamp); deficit (reproject: the clamp's
 *           deficit history reprojected); all padded (svgf.h, PAD).
 * Produces: accum[c * pixels + p] (padded), c < 3: the long history of this frame (demodulated
 *           illumination); lag[c * pixels + p] (padded), c < 3: the anti-lag statistic above, read
 *           by the antilag pass; deficit[c * pixels + p] (padded), c < 3: the clamp's deficit history
 *           of this frame (below; read by the deficit pass). */
#include "denoise/svgf.h"

#ifndef CLIP_RADIUS /* -DCLIP_RADIUS from pyclpt/denoise/svgf.py (DenoiserSettings.clip_radius) */
#error "CLIP_RADIUS must be defined (-DCLIP_RADIUS=1 or 2)"
#endif

__kernel void clip_history(__global const float* temporal, __global const float* fast, __global const float* len,
                           __global const float* moments, __global const float* sample, __global float* deficit,
                           __global float* accum, __global float* lag, int width, int height, float alpha_min,
                           float clip_gamma, float fast_var, float clip_noise) {
    int x = get_global_id(0), y = get_global_id(1), c = get_global_id(2);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    __global const float* f = fast + PAD + c * n;
    temporal += PAD + c * n;
    len += PAD;
    moments += PAD;
    accum += PAD + c * n;
    sample += PAD + c * n;
    deficit += PAD + c * n;
    lag += PAD + c * n;
    __global const float* hl = temporal + 3 * n; /* the reprojected long history, channel c */

    /* the statistics of the box about its centre's value, which keeps mean2 - mean^2 from cancelling
     * to garbage where the values are nearly equal (a converged smooth area: the centre would be
     * clipped by its rounding errors) */
    float centre = f[p];
    float sum = 0.0f, sum2 = 0.0f, count = 0.0f;
    /* the anti-lag's sums over the pixels with a history; trel: their relative temporal variance (of
     * the luminance, from the moments; scale-free, so it holds for every channel and any level) */
    float hsum = 0.0f, fsum = 0.0f, fsum2 = 0.0f, hcount = 0.0f, trel = 0.0f;
    UNROLL for (int dy = -CLIP_RADIUS; dy <= CLIP_RADIUS; ++dy) {
        UNROLL for (int dx = -CLIP_RADIUS; dx <= CLIP_RADIUS; ++dx) {
            int tx = x + dx, ty = y + dy;
            float w = (tx >= 0 && tx < width && ty >= 0 && ty < height) ? 1.0f : 0.0f;
            int q = row_at(y, dy, width, height) + tx;
            float v = w * (f[q] - centre);
            sum += v;
            sum2 += v * v;
            count += w;
            float wh = len[q] > 1.5f ? w : 0.0f;
            fsum += wh * v;
            fsum2 += wh * v * v;
            float m1 = moments[q];
            hsum += wh * (hl[q] - centre);
            hcount += wh;
            trel += wh * m_max(moments[n + q] - m1 * m1, 0.0f) / m_max(m1 * m1, 1e-30f);
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
    float h0 = h;
    h = clip_gamma >= 0.0f ? m_clamp(h, m_min(mean - spread, centre), m_max(mean + spread, centre)) : h;
    float a = m_max(alpha_min, 1.0f / len[p]);
    float out = lerpf(h, s, a);
    accum[p] = m_isfinite(out) ? out : s;

    /* the anti-lag statistic: |mean fast - mean long| / standard error of the mean fast, over the box's
     * pixels with a history; the floor 1e-3 of the level keeps a flat (converged or black) box at 0 */
    float hinv = 1.0f / m_max(hcount, 1.0f);
    float fmean = fsum * hinv, hmean = hsum * hinv;
    float fvar = m_max(fsum2 * hinv - fmean * fmean, 0.0f) * hcount / m_max(hcount - 1.0f, 1.0f);
    /* the standard error of the fast mean: the larger of the box's spread (Bessel) and the temporal
     * noise at the fast mean's level (the spread alone underestimates it in a box of skewed values
     * that holds none of their rare bright ones) */
    float level = centre + fmean;
    float se = m_sqrt(m_max(fvar, fast_var * trel * hinv * level * level) * hinv)
               + 1e-3f * (m_abs(centre + fmean) + m_abs(centre + hmean)) + 1e-20f;
    float t = m_abs(fmean - hmean) / se;
    lag[p] = (clip_gamma >= 0.0f && hcount > 2.5f && m_isfinite(t)) ? t : 0.0f;
    /* the clamp's deficit history: what the firefly clamp took from this channel (the raw sample
     * minus the clamped one), accumulated with the long history's weight. Where the clip lowered the
     * long history for a change of the lighting (t over clip_noise), the deficit shrinks with it (the
     * old light's deficit goes with the old light); where t stays at or under clip_noise, what the clip
     * moved is the noise of a skewed 1-sample distribution (its box clips the bright side of a young
     * history more often than the dark side) and joins the deficit, signed. */
    bool noise = clip_noise > 0.0f && clip_gamma >= 0.0f && !(t > clip_noise);
    float shrink = (h0 > 0.0f && !noise) ? m_clamp(h / h0, 0.0f, 1.0f) : 1.0f;
    float dfc = lerpf(deficit[p] * shrink + (noise ? h0 - h : 0.0f), m_max(sample[p] - s, 0.0f), a);
    deficit[p] = m_isfinite(dfc) ? dfc : 0.0f;
}
