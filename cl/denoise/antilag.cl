/* antilag: NRD RELAX's history reset where the fast and the long history disagree, in the frame
 * that sees the disagreement. One work-item per pixel, 2D range; after clip_history, before variance.
 *
 * clip_history measures, per channel, t: how many standard errors the mean of the fast histories
 * in the box around p stands from the mean of the long ones (the statistic is described there).
 * Here t is the largest channel's, averaged over the 3x3 pixels around p inside the image: a change
 * of the lighting raises it over a whole neighbourhood, the noise of one box does not (on the static
 * synthetic scene of tests/test_denoise.py no history is cut in 16 frames at antilag 3.5; from one
 * pixel's t, 4 % were at 3.5). a = clamp(4 (t - antilag) / antilag, 0, 1) (DenoiserSettings.antilag;
 * 0: off): from t = 1.25 antilag on, the history restarts from this frame's sample. The cut is the one
 * reproject would have made had the history been N' = round((N - 1) (1 - a)) + 1 frames long, this
 * frame's included (N: reproject's length): each blend of this frame, the long history's
 * max(alpha_min, 1/N) (the emission history's too), the fast history's max(fast_alpha, 1/N) and the
 * moments' max(moments_alpha_min, 1/N), is redone with N' by blending its result once more towards
 * the sample, by (w' - w) / (1 - w)
 * (w, w' the sample's weights with N and N'), which gives the sample the weight w' and the rest of
 * the history the weight 1 - w', without dividing by 1 - w where it is 0 (N = 1: w = w' = 1).
 *
 * Before this pass the cut was made by the next frame's reproject, from the statistic of this one:
 * a light change then showed the old light one frame longer, and the restarted history was one
 * frame younger than a fresh run's ever after (docs/denoising.md, "The light change, in the same frame").
 *
 * The clamp's deficit history (clip_history) is cut the same way, towards this frame's deficit (the
 * raw sample minus the clamped one).
 *
 * While fewer than DenoiserSettings.antilag_frames frames have passed since the lighting changed in view
 * (light_age: at least LIGHT_CHANGE_SHARE of the pixels saw a light change), the threshold is antilag_changed
 * (if lower): the dim surfaces a changed light reaches show the change to the statistic only over
 * several frames (docs/denoising.md, "The light change: cutting more readily after it").
 *
 * Consumes: light_age[0] (light_age: frames since the lighting changed in view); temporal[0..2] (reproject:
 *           this frame's sample, clamped); sample (demodulate: the raw
 *           sample); deficit (clip_history: the clamp's deficit history); emission (demodulate: the
 *           frame's emitted part); lag[c * pixels + p] (c < 3, clip_history: t); accum
 *           (clip_history: the long history), fast, moments, len, emis (reproject: the fast
 *           history, luminance moments, N, the emission history); all padded (svgf.h, PAD).
 * Produces: accum[c * pixels + p] (c < 3), fast (3), moments (2), len (N'), emis (3), deficit (3) of pixel p,
 *           cut in place (each work-item writes its own pixel only, and reads no buffer it writes
 *           at another pixel). */
#include "denoise/svgf.h"

/* The weight of the sample after the cut, folded into a blend already made with weight w. */
static inline float recut(float w, float w_cut) { return w < 1.0f ? (w_cut - w) / (1.0f - w) : 0.0f; }

__kernel void antilag(__global const float* temporal, __global const float* emission, __global const float* lag,
                      __global const float* sample, __global float* deficit, __global float* accum,
                      __global float* fast, __global float* moments, __global float* len, __global float* emis,
                      __global const int* light_age, int width, int height, float antilag, float antilag_changed,
                      int antilag_frames, float alpha_min, float moments_alpha_min, float fast_alpha) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    temporal += PAD;
    emission += PAD;
    emis += PAD;
    lag += PAD;
    sample += PAD;
    deficit += PAD;
    accum += PAD;
    fast += PAD;
    moments += PAD;
    len += PAD;

    /* t: the largest channel's statistic, averaged over the 3x3 pixels around p inside the image */
    float t = 0.0f, count = 0.0f;
    UNROLL for (int dy = -1; dy <= 1; ++dy) {
        UNROLL for (int dx = -1; dx <= 1; ++dx) {
            int tx = x + dx, ty = y + dy;
            float w = (tx >= 0 && tx < width && ty >= 0 && ty < height) ? 1.0f : 0.0f;
            int q = row_at(y, dy, width, height) + tx;
            t += w * m_max(m_max(lag[q], lag[n + q]), lag[2 * n + q]);
            count += w;
        }
    }
    t /= count;
    /* a few frames after the lighting changed in view (light_age), the lower threshold */
    float thr = light_age[0] < antilag_frames ? m_min(antilag, antilag_changed) : antilag;
    float a = thr > 0.0f ? m_clamp(4.0f * (t - thr) / thr, 0.0f, 1.0f) : 0.0f;
    float N = len[p];
    float N_cut = m_floor((N - 1.0f) * (1.0f - a) + 0.5f) + 1.0f;
    if (!(a > 0.0f) || !(N_cut < N)) return; /* a branch: taken where the lighting changed */
    vec3 s = planar3(temporal, n, p);
    float l = luminance(s);
    float bc = recut(m_max(alpha_min, 1.0f / N), m_max(alpha_min, 1.0f / N_cut));
    float bf = recut(m_max(fast_alpha, 1.0f / N), m_max(fast_alpha, 1.0f / N_cut));
    float bm = recut(m_max(moments_alpha_min, 1.0f / N), m_max(moments_alpha_min, 1.0f / N_cut));
    store_planar3(accum, n, p, lerp3(planar3(accum, n, p), s, bc));
    store_planar3(fast, n, p, lerp3(planar3(fast, n, p), s, bf));
    store_planar3(emis, n, p, lerp3(planar3(emis, n, p), planar3(emission, n, p), bc));
    vec3 ds = v3_sub(planar3(sample, n, p), s); /* the clamp's deficit of this frame's sample */
    ds = v3(m_max(ds.x, 0.0f), m_max(ds.y, 0.0f), m_max(ds.z, 0.0f));
    store_planar3(deficit, n, p, lerp3(planar3(deficit, n, p), ds, bc));
    moments[p] = lerpf(moments[p], l, bm);
    moments[n + p] = lerpf(moments[n + p], l * l, bm);
    len[p] = N_cut;
}
