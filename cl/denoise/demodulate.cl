/* demodulate: the frame's input as the other passes read it. One work-item per pixel, 2D range.
 *
 * The colour with NaN/inf replaced by 0 (all three channels; marked), less its emitted part (svgf.h,
 * emitted3: the emission AOV, written to `emission` for reproject's emission history), divided by the albedo per
 * channel (svgf.h, albedo_divisors: a finite channel as at least ALBEDO_REL x the largest channel
 * above ALBEDO_MIN; 1 where no channel is above it, or the channel is not finite; a non-finite
 * albedo is marked too), clamped to +-MAX_RADIANCE: the illumination that the history accumulates, and its
 * luminance. The geometry record of this frame (svgf.h, GEO_*) but its depth gradient: depth
 * (non-finite or <= 0: 0, the background; +inf, the sky convention, too), the unit normal (0 where
 * unknown), the motion (AOV_OFFSCREEN in both where not seen or not finite), the material id.
 * A pass of its own, without neighbours, so that it vectorizes and reproject reads its
 * neighbours' values from padded planes instead of demodulating each of them again.
 *
 * Consumes: color[3 p + c] (interleaved RGB, read through the opaque stride unit = 1); aovs[c *
 *           pixels + p] (cl/film/aovs.h: albedo, normal, depth, material, emission).
 * Produces: sample[c * pixels + p] (padded, svgf.h): c < 3 the illumination, c = 3 its luminance;
 *           emission[c * pixels + p] (padded, c < 3): the emitted part of the colour;
 *           geo[GEO_DEPTH, GEO_NORMAL.., GEO_MOTION.., GEO_MATERIAL] (padded); marks[p] = 1 if the colour was
 *           not finite + 1 if the albedo was not + 1 each for a NaN/-inf depth, a non-finite normal,
 *           a non-finite motion (a plain store, summed by film/count_dropped.cl). */
#include "denoise/svgf.h"

__kernel void demodulate(__global const float* color, __global const float* aovs, __global float* sample,
                         __global float* geo, __global float* emission, __global uchar* marks, int width, int height,
                         int unit) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    sample += PAD;
    geo += PAD;
    emission += PAD;

    bool bad_color;
    vec3 c = load_color(color, p, unit, &bad_color);
    vec3 albedo = planar3(aovs + AOV_ALBEDO * n, n, p);
    bool bad_albedo = !all_finite3(albedo);
    vec3 e = emitted3(c, planar3(aovs + AOV_EMISSION * n, n, p));
    store_planar3(emission, n, p, e);
    vec3 s = clamp_radiance(v3_div(v3_sub(c, e), albedo_divisors(albedo)));
    store_planar3(sample, n, p, s);
    sample[3 * n + p] = luminance(s);

    float z = aovs[AOV_DEPTH * n + p];
    vec3 nrm = planar3(aovs + AOV_NORMAL * n, n, p);
    float l2 = m_dot(nrm, nrm);
    geo[GEO_DEPTH * n + p] = (z > 0.0f && z < INFINITY) ? z : 0.0f;
    store_planar3(geo + GEO_NORMAL * n, n, p,
                  (l2 > 1e-20f && l2 < INFINITY) ? v3_scale(nrm, m_rsqrt(l2)) : v3_splat(0.0f));
    geo[GEO_MATERIAL * n + p] = aovs[AOV_MATERIAL * n + p];
    /* the G-buffer's non-finite values, counted here and sanitized where read (this record; reproject
     * reads the motion: a NaN/inf one is "not seen"): a NaN or -inf depth, a normal or motion with a
     * NaN/inf channel (+inf depth is the sky convention: the background, not counted) */
    float mx = aovs[AOV_MOTION * n + p], my = aovs[(AOV_MOTION + 1) * n + p];
    bool bad_depth = m_isnan(z) || z == -INFINITY;
    bool bad_normal = !all_finite3(nrm);
    bool bad_motion = !(m_isfinite(mx) && m_isfinite(my));
    bool seen = !bad_motion && m_abs(mx) < 0.5f * AOV_OFFSCREEN && m_abs(my) < 0.5f * AOV_OFFSCREEN;
    geo[GEO_MOTION * n + p] = seen ? mx : AOV_OFFSCREEN;
    geo[(GEO_MOTION + 1) * n + p] = seen ? my : AOV_OFFSCREEN;
    marks[p] = (uchar)((bad_color ? 1 : 0) + (bad_albedo ? 1 : 0) + (bad_depth ? 1 : 0) + (bad_normal ? 1 : 0)
                       + (bad_motion ? 1 : 0));
}
