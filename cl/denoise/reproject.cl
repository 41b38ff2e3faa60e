/* reproject: SVGF's temporal pass (Schied et al. 2017; Falcor's SVGFReproject), with the fast
 * history of NRD's RELAX. One work-item per pixel, 2D range; after demodulate.
 *
 * 1. The frame's sample (demodulate's illumination, demodulated by the footprint's albedo, 4.)
 *    firefly-clamped: its luminance is scaled down to
 *    at most sqrt(N) x the largest of firefly_ratio x a spatial reference (the largest of the mean
 *    luminance of its neighbours in the 3x3 around p inside the image, centre excluded, the mean of
 *    their temporal means (the moments' m1 over the same 3x3 as the neighbourhood's sigma below)
 *    and, where the history is valid, the reprojected history's luminance) and, where the history is
 *    valid, the pixel's own temporal moments, mean + firefly_sigma x sigma (NRD RELAX's idea), and
 *    its mean + POOLED_SIGMA x firefly_sigma x the neighbourhood's sigma (the previous frame's
 *    variances averaged over the 3x3 around the previous position, same material, histories no
 *    longer than p's): a pixel that has not drawn the rare bright samples of its neighbourhood's
 *    1-sample distribution yet is not clamped when it does (the clamp against its own moments alone
 *    took 0.2 to 0.4 % of the cornell-box's energy at frame 8, all of it from the bright tail). N is
 *    the history length after this frame: the clamp relaxes as the history grows, so that what it
 *    removes vanishes against the accumulated mean (firefly_ratio 0: no clamp; no reference at all,
 *    a pixel without neighbours or history: no clamp). The fast history takes the same clamped
 *    sample as the long one: clamped without the neighbourhood's terms, it held less of the 1-sample
 *    tail than the long history, and where that tail carries the light (the living room's window
 *    light, a few bright samples among black ones) the anti-lag read the difference as a change of
 *    the lighting and restarted 38 % of the static room's histories by frame 8 (docs/denoising.md,
 *    "Sparse light"). The neighbours' temporal means in the reference are for a pixel whose own
 *    history and whose neighbours in this frame are black: without them its rare bright sample was
 *    clamped to 0 and its light lost. The moments take the sample clamped without the neighbourhood's sigma
 *    where the history is valid, else the sample's own (an isolated pixel whose neighbours are black
 *    is clamped to 0 on its first frame, but its moments keep it, and it converges).
 * 2. The previous frame's history at p + motion: the 2x2 bilinear taps around it, each accepted only
 *    if inside the image, holding a history (length >= 1) and either the same surface (consistent():
 *    same material id; both background, or both surfaces with |z - z_prev| <= depth_threshold x
 *    (GEO_GRAD + 0.01 z) and normals with cos >= min(normal_threshold, cos_spread), cos_spread the
 *    smallest normal cosine from p to its surface neighbours, as Falcor scales its normal test by
 *    fwidth) or a sample that moves with p's (moves_with: their motions within MOTION_TOLERANCE of
 *    a pixel; the same footprint, whatever surface each jittered sample hit); the bilinear weights
 *    renormalised over the accepted taps (accepted if their weight sums to more than 0.01). Else the
 *    3x3 pixels around the rounded previous position (itself inside the image), equally weighted
 *    (Falcor's fallback: a branch, taken at disocclusions only). Else a disocclusion: the history restarts.
 * 3. The emission history (the emitted part of the colour, demodulate, kept apart from the filtered
 *    illumination and added back by modulate): where an emitter changed (emitter_moved: the emitting
 *    samples of one material in this frame's 3x3 around p and in the previous frame's 3x3 around the
 *    rounded previous position, their ranges apart, or most of one 3x3 emitting and none of the
 *    other), the reprojected one clipped into the [min, max] box of this frame's emission over the
 *    3x3 pixels around p inside the image (an emitter is noise-free, so its box is tight inside it);
 *    then blended with weight max(alpha_min, 1/N), as the long history: a static emitter's edge,
 *    or a window's sky behind a bar, converges to the plain average of its frames.
 * 4. The footprint's albedo A (the divisors of the pixel's samples blended as the long history):
 *    the sample is demodulated by A, not by its own divisor, and the histories reprojected in units
 *    of the previous A rescaled to this one, so that A x the long history is the colour's moving
 *    average, exactly (below; modulate, conserve and deficit multiply by A).
 * 5. History length N = min(N_prev + 1, max_history) (N_prev: the accepted taps' weighted mean,
 *    rounded), 1 at a disocclusion; moments of luminance blended with max(moments_alpha_min, 1/N),
 *    the fast history with max(fast_alpha, 1/N). The long history is blended by clip_history. Where
 *    the lighting changed, the antilag pass (cl/denoise/antilag.cl) cuts N, the moments and the
 *    fast, long and emission histories in this same frame (it used to be done here, one frame
 *    late, from the previous frame's statistic).
 * The depth gradient GEO_GRAD: |dz/dx| + |dz/dy|, each the smaller of the one-sided differences to
 * the surface neighbours (a depth edge on one side does not count).
 *
 * Consumes: sample (demodulate: illumination, luminance); emission, emission_prev (demodulate, this
 *           frame's and the previous one's: the emitted part); geo (this frame's record from
 *           demodulate: depth, normal, motion, material); aovs[c * pixels + p] (cl/film/aovs.h: the
 *           motion, the albedo); the
 *           previous frame's geo_prev (GEO_*), hist_prev (long history colour, channels 0..2),
 *           fast_prev (3), moments_prev (2), len_prev (history length; 0 = none, after a reset),
 *           emis_prev (3, the emission history), deficit_prev (3, the clamp's deficit history of
 *           clip_history), albedo_prev (3, the footprint albedo A).
 *           All but aovs padded (svgf.h, PAD).
 * Produces: geo[GEO_GRAD]; temporal[0..2] the sample clamped, temporal[3..5] the long history
 *           reprojected (0 at a disocclusion); fast (the fast history accumulated), moments
 *           (luminance mean and mean of squares), len (N, a float), emis (the emission history),
 *           deficit (the clamp's deficit history reprojected with the same taps, blended by
 *           clip_history), albedo (A); sample[0..2] (p's own, in place: the sample demodulated by A,
 *           before the clamp, as clip_history and antilag read it); all padded; lit[p] (uchar, not
 *           padded: 1 where a light changed and the history holds, for light_change). */
#include "denoise/svgf.h"

/* The firefly clamp's neighbourhood term is mean + POOLED_SIGMA x firefly_sigma x the pooled sigma:
 * at 1 (6 sigma) the living room's light change was followed a frame later (the clamp let more of
 * the 1-sample tail into the fast histories, which loosened the anti-lag's test); 0.5 keeps its lag
 * (docs/denoising.md, "Energy at 8 frames"). */
#define POOLED_SIGMA 0.5f

/* Whether pixel q of the previous frame is the surface that the current pixel (depth z, unit
 * normal nrm, material mat; z = 0: background) shows. */
static inline bool consistent(__global const float* geo_prev, int n, int q, float z, vec3 nrm, int mat,
                              float ztol, float cos_min) {
    float zq = geo_prev[GEO_DEPTH * n + q];
    int mq = as_int(geo_prev[GEO_MATERIAL * n + q]);
    vec3 nq = planar3(geo_prev + GEO_NORMAL * n, n, q);
    bool surface = z > 0.0f, surface_q = zq > 0.0f;
    bool same = (m_abs(z - zq) <= ztol) & (normal_agreement(nrm, nq) >= cos_min);
    return (mq == mat) & (surface == surface_q) & (!surface | same);
}

/* The emission history is clipped into this frame's 3x3 [min, max] box of emission only where an
 * emitter changed (emitter_moved): like with like, the emission of one material's emitting samples in
 * the two frames' 3x3, their ranges apart by more than EMISSION_MARGIN x the wider one's width +
 * EMISSION_REL x the higher top (an environment map's sky varies across a 3x3: each previous sample's
 * emission tested against this frame's range, with 0.01 to 0.1 for EMISSION_REL, left the room's
 * temporal accumulation 0.2 to 0.4 % off; rounding), or at least EMITTER_MOST of one 3x3 emitting and
 * none of the other's (switched on or off). A light that changes leaves its range at once (the
 * light-change tests: the cornell-box's emitter shares its material with the walls, so a material's
 * non-emitting samples do not count); a pixel that shows an emitter only in part (the living room's
 * windows: the sky in one frame, a window's bar in the next) keeps its history, the plain average of
 * what it drew. The box alone, widened by half its width, clipped such a history to [0, 0] when its
 * 3x3 drew only bars and to the sky's when it drew none: 0.3 to 0.4 % of the room's light at 32 frames
 * and more beside thinner bars (docs/denoising.md, "Energy at 32 frames"). A change under EMISSION_REL
 * is followed by the blend alone. */
#define EMISSION_MARGIN 0.5f
#define EMISSION_REL 0.01f
#define EMITTER_MOST 5
#define NOT_EMITTING INT_MIN /* a material id below every real one (-1 is the background) */

static inline bool apart(float lo, float hi, float lo_p, float hi_p) {
    float m = EMISSION_MARGIN * m_max(hi - lo, hi_p - lo_p) + EMISSION_REL * m_max(hi, hi_p);
    return lo > hi_p + m || hi < lo_p - m;
}

static inline bool emitting(vec3 e) { return e.x > 0.0f || e.y > 0.0f || e.z > 0.0f; }

/* Whether the emitting samples of one material in this frame's 3x3 (count, their range [lo, hi]) and
 * in the previous frame's (count_p, [lo_p, hi_p]) tell of a change: both there and their ranges apart,
 * or at least EMITTER_MOST of the 9 in one frame and none in the other (a light switched on or off). */
static inline bool emitter_moved(vec3 lo, vec3 hi, int count, vec3 lo_p, vec3 hi_p, int count_p) {
    if (count == 0 || count_p == 0) return count + count_p >= EMITTER_MOST;
    return apart(lo.x, hi.x, lo_p.x, hi_p.x) || apart(lo.y, hi.y, lo_p.y, hi_p.y) || apart(lo.z, hi.z, lo_p.z, hi_p.z);
}

/* Whether the same emitting samples tell that a light itself changed, for the anti-lag (light_change.cl):
 * both frames' ranges there and apart by more than LIGHT_CHANGE_RATIO in every channel that emits
 * (a light turned up or down), not a range that only shifted (a jittered edge, a sky that varies across
 * a window: the static living room's emission flags 0.4 % of its pixels a frame, none of them so). */
#define LIGHT_CHANGE_RATIO 1.5f

static inline bool light_changed(vec3 lo, vec3 hi, int count, vec3 lo_p, vec3 hi_p, int count_p) {
    if (count == 0 || count_p == 0) return false;
    bool down = true, up = true;
    float l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z}, lp[3] = {lo_p.x, lo_p.y, lo_p.z};
    float hp[3] = {hi_p.x, hi_p.y, hi_p.z};
    for (int c = 0; c < 3; ++c) {
        if (!(h[c] > 0.0f || hp[c] > 0.0f)) continue;
        down &= LIGHT_CHANGE_RATIO * h[c] < lp[c];
        up &= l[c] > LIGHT_CHANGE_RATIO * hp[c];
    }
    return down || up;
}

/* The largest difference, per axis in pixels, between the motions of two samples that reproject still
 * takes for the same footprint when their surfaces differ (moves_with). */
#define MOTION_TOLERANCE 0.25f

/* Whether the current pixel's sample (motion mx, my, seen) moves with the sample that the previous
 * frame's pixel q showed: then q's footprint has moved with p's, whatever surface each of the two
 * jittered samples hit, and q's history is that footprint's mean. The G-buffer is one sample a frame,
 * so a pixel on an edge, a texture boundary or a hole shows one side in one frame and the other in
 * the next: rejecting the history then depends on the sample drawn, which biases the mean (the living
 * room's temporal accumulation alone, without albedo or emission: 0.991 / 0.990 / 0.989 of the plain
 * average's at 32 frames, 1.0000 with this test: the 3x3 fallback gave a quarter of the pixels their
 * neighbours' histories of the side drawn, and a hole's or a thin bar's rare sample restarted them).
 * A disocclusion is where the two surfaces move apart (an occluder over its background, parallax). */
static inline bool moves_with(__global const float* geo_prev, int n, int q, float mx, float my, bool seen) {
    float dx = m_abs(mx - geo_prev[GEO_MOTION * n + q]), dy = m_abs(my - geo_prev[(GEO_MOTION + 1) * n + q]);
    return seen & (dx <= MOTION_TOLERANCE) & (dy <= MOTION_TOLERANCE);
}

/* |z - zn| for a surface neighbour, INFINITY for a background one. */
static inline float depth_step(float z, float zn) { return zn > 0.0f ? m_abs(z - zn) : INFINITY; }

/* The previous frame's history, summed over accepted taps with their weights. */
typedef struct {
    vec3 color, fast, emis, dfc, alb;
    float m1, m2, len, weight;
} history_t;

static inline void add_tap(history_t* h, __global const float* hist_prev, __global const float* fast_prev,
                           __global const float* moments_prev, __global const float* len_prev,
                           __global const float* emis_prev, __global const float* deficit_prev,
                           __global const float* albedo_prev, int n, int q, float w) {
    h->color = v3_add(h->color, v3_scale(planar3(hist_prev, n, q), w));
    h->fast = v3_add(h->fast, v3_scale(planar3(fast_prev, n, q), w));
    h->emis = v3_add(h->emis, v3_scale(planar3(emis_prev, n, q), w));
    h->dfc = v3_add(h->dfc, v3_scale(planar3(deficit_prev, n, q), w));
    h->alb = v3_add(h->alb, v3_scale(planar3(albedo_prev, n, q), w));
    h->m1 += w * moments_prev[q];
    h->m2 += w * moments_prev[n + q];
    h->len += w * len_prev[q];
    h->weight += w;
}

__kernel void reproject(__global float* sample, __global const float* emission,
                        __global const float* emission_prev, __global float* geo,
                        __global const float* aovs,
                        __global const float* geo_prev, __global const float* hist_prev,
                        __global const float* fast_prev, __global const float* moments_prev,
                        __global const float* len_prev, __global const float* emis_prev,
                        __global const float* deficit_prev, __global const float* albedo_prev,
                        __global float* temporal, __global float* deficit, __global float* albedo,
                        __global float* fast, __global float* moments, __global float* len, __global float* emis,
                        __global uchar* lit, int width, int height, float depth_threshold, float normal_threshold,
                        float firefly_ratio, float firefly_sigma, float max_history, float alpha_min,
                        float moments_alpha_min, float fast_alpha) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    sample += PAD;
    emission += PAD;
    emission_prev += PAD;
    emis_prev += PAD;
    emis += PAD;
    deficit_prev += PAD;
    deficit += PAD;
    albedo_prev += PAD;
    albedo += PAD;
    geo += PAD;
    geo_prev += PAD;
    hist_prev += PAD;
    fast_prev += PAD;
    moments_prev += PAD;
    len_prev += PAD;
    temporal += PAD;
    fast += PAD;
    moments += PAD;
    len += PAD;

    /* this frame's geometry and depth gradient */
    float z = geo[GEO_DEPTH * n + p];
    vec3 nrm = planar3(geo + GEO_NORMAL * n, n, p);
    int mat = as_int(geo[GEO_MATERIAL * n + p]);
    __global const float* depth = geo + GEO_DEPTH * n;
    float zl = depth[p - 1], zr = depth[p + 1]; /* in the padding at the ends: never out of bounds */
    float zu = depth[row_at(y, -1, width, height) + x], zd = depth[row_at(y, 1, width, height) + x];
    float gx = m_min(depth_step(z, x > 0 ? zl : 0.0f), depth_step(z, x < width - 1 ? zr : 0.0f));
    float gy = m_min(depth_step(z, y > 0 ? zu : 0.0f), depth_step(z, y < height - 1 ? zd : 0.0f));
    float grad = (gx < INFINITY ? gx : 0.0f) + (gy < INFINITY ? gy : 0.0f);

    /* the spread of the normals around p (as Falcor scales its normal test by fwidth): the smallest
     * cosine to the surface neighbours. A pixel on a crease sees both faces there, and as the film's
     * sample positions are jittered frame to frame, its previous sample may have been on the other
     * face: the test allows what its neighbours already show. (The depth test keeps the smaller
     * one-sided gradient: widened to the largest, as Falcor's fwidth does, it let the history leak
     * across depth edges and changed nothing on a jittered render, where the 3x3 fallback finds the
     * right side of a silhouette.) */
    int row[4] = {p - 1, p + 1, row_at(y, -1, width, height) + x, row_at(y, 1, width, height) + x};
    bool there[4] = {x > 0, x < width - 1, y > 0, y < height - 1};
    float cos_spread = 1.0f;
    UNROLL for (int k = 0; k < 4; ++k) {
        bool use = there[k] & (depth[row[k]] > 0.0f) & (z > 0.0f);
        cos_spread = m_min(cos_spread, use ? normal_agreement(nrm, planar3(geo + GEO_NORMAL * n, n, row[k])) : 1.0f);
    }

    /* the sample and its neighbours' mean luminance */
    vec3 s = planar3(sample, n, p);
    vec3 e = planar3(emission, n, p);
    vec3 e_lo = e, e_hi = e; /* the box of this frame's emission around p */
    float around = 0.0f, count = 0.0f;
    bool any_emitting = false; /* an emitting sample in the 3x3 around p or around the previous position */
    UNROLL for (int dy = -1; dy <= 1; ++dy) {
        UNROLL for (int dx = -1; dx <= 1; ++dx) {
            int tx = x + dx, ty = y + dy;
            float w = (tx >= 0 && tx < width && ty >= 0 && ty < height) ? 1.0f : 0.0f;
            int q = row_at(y, dy, width, height) + tx;
            any_emitting |= w > 0.0f && emitting(planar3(emission, n, q));
            if (dx == 0 && dy == 0) continue;
            around += w * sample[3 * n + (w > 0.0f ? q : p)]; /* outside the image: no read of another's sample */
            count += w;
            vec3 eq = planar3(emission, n, q);
            e_lo = w > 0.0f ? v3(m_min(e_lo.x, eq.x), m_min(e_lo.y, eq.y), m_min(e_lo.z, eq.z)) : e_lo;
            e_hi = w > 0.0f ? v3(m_max(e_hi.x, eq.x), m_max(e_hi.y, eq.y), m_max(e_hi.z, eq.z)) : e_hi;
        }
    }
    around = count > 0.0f ? around / count : 0.0f;

    /* the previous position (pixel-centre coordinates), far outside when it was not visible */
    float mx = aovs[AOV_MOTION * n + p], my = aovs[(AOV_MOTION + 1) * n + p];
    bool seen = m_abs(mx) < 0.5f * AOV_OFFSCREEN && m_abs(my) < 0.5f * AOV_OFFSCREEN; /* false for NaN */
    float px = seen ? m_clamp((float)x + mx, -2.0f, (float)width + 1.0f) : -2.0f;
    float py = seen ? m_clamp((float)y + my, -2.0f, (float)height + 1.0f) : -2.0f;
    float ztol = depth_threshold * (grad + 0.01f * z);
    float cos_min = m_min(normal_threshold, cos_spread);

    /* the 2x2 bilinear taps */
    float fx0 = m_floor(px), fy0 = m_floor(py);
    float fx = px - fx0, fy = py - fy0;
    int x0 = (int)fx0, y0 = (int)fy0;
    history_t h = {v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f),
                   0.0f, 0.0f, 0.0f, 0.0f};
    UNROLL for (int t = 0; t < 4; ++t) {
        int tx = x0 + (t & 1), ty = y0 + (t >> 1);
        bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
        int q = clampi(ty, 0, height - 1) * width + clampi(tx, 0, width - 1);
        bool ok = inside & (len_prev[q] >= 1.0f)
                  & (consistent(geo_prev, n, q, z, nrm, mat, ztol, cos_min) | moves_with(geo_prev, n, q, mx, my, seen));
        float bw = ((t & 1) ? fx : 1.0f - fx) * ((t >> 1) ? fy : 1.0f - fy);
        add_tap(&h, hist_prev, fast_prev, moments_prev, len_prev, emis_prev, deficit_prev, albedo_prev, n, q,
                ok ? bw : 0.0f);
    }
    /* none (a weight below 0.01): Falcor's fallback, the 3x3 pixels around the rounded position,
     * equally weighted; a branch, taken at disocclusions only */
    if (!(h.weight > 0.01f)) {
        int rx = (int)m_floor(px + 0.5f), ry = (int)m_floor(py + 0.5f);
        history_t f = {v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f),
                       0.0f, 0.0f, 0.0f, 0.0f};
        if (rx >= 0 && rx < width && ry >= 0 && ry < height) {
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    int tx = rx + dx, ty = ry + dy;
                    bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
                    int q = clampi(ty, 0, height - 1) * width + clampi(tx, 0, width - 1);
                    bool ok = inside & (len_prev[q] >= 1.0f)
                              & consistent(geo_prev, n, q, z, nrm, mat, ztol, cos_min);
                    add_tap(&f, hist_prev, fast_prev, moments_prev, len_prev, emis_prev, deficit_prev, albedo_prev,
                            n, q, ok ? 1.0f : 0.0f);
                }
            }
        }
        h = f;
    }
    bool valid = h.weight > 0.01f;
    float inv = valid ? 1.0f / h.weight : 0.0f;
    vec3 hist = v3_scale(h.color, inv), hist_fast = v3_scale(h.fast, inv);
    float N = valid ? m_min(m_floor(h.len * inv + 0.5f) + 1.0f, max_history) : 1.0f;

    /* the footprint's albedo: the divisors of the pixel's samples blended as its long history is
     * (weight max(alpha_min, 1/N)). The G-buffer is one jittered sample a frame: demodulated by each
     * frame's own divisor d_k and modulated by the last one's, the history came out at E[d] E[c / d],
     * not E[c], wherever the albedo (or the surface, or the sky's divisor 1) changes within a pixel
     * (the living room: 1.9 % of the red light at 32 frames, temporal accumulation alone). The sample
     * is demodulated by this albedo A instead, and the histories reprojected in units of the previous
     * A are rescaled to this one (A_prev / A), so that A x the long history is the colour's own moving
     * average, exactly (the filter sees each pixel's colour over its footprint's albedo, as from a
     * G-buffer of many samples a pixel). A depends on the albedos only, not on the light's noise. */
    vec3 d_k = aov_divisor(aovs, n, p);
    vec3 d_prev = v3_scale(h.alb, inv);
    bool d_ok = valid && d_prev.x > 0.0f && d_prev.y > 0.0f && d_prev.z > 0.0f && all_finite3(d_prev);
    vec3 A = d_ok ? lerp3(d_prev, d_k, m_max(alpha_min, 1.0f / N)) : d_k;
    vec3 rescale = d_ok ? v3_div(d_prev, A) : v3_splat(1.0f);
    hist = v3_mul(hist, rescale);
    hist_fast = v3_mul(hist_fast, rescale);
    h.dfc = v3_mul(h.dfc, rescale);
    s = v3_div(v3_mul(s, d_k), A);
    store_planar3(sample, n, p, s); /* the raw sample as clip_history and antilag read it (p's own) */

    /* the neighbourhood's temporal spread: the mean of the previous frame's luminance variances
     * (m2 - m1^2) over the 3x3 pixels around the rounded previous position that hold a history of
     * p's material no longer than p's (a history cut by a light change does not take its uncut
     * neighbours' spread); the spread of their means does not count. And the mean of their means
     * m1, part of the clamp's spatial reference. */
    float nvar = 0.0f, nmean = 0.0f, nw = 0.0f;
    int rx = (int)m_floor(px + 0.5f), ry = (int)m_floor(py + 0.5f);
    UNROLL for (int dy = -1; dy <= 1; ++dy) {
        UNROLL for (int dx = -1; dx <= 1; ++dx) {
            int tx = rx + dx, ty = ry + dy;
            bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
            int q = clampi(ty, 0, height - 1) * width + clampi(tx, 0, width - 1);
            any_emitting |= inside && emitting(planar3(emission_prev, n, q));
            float lq = len_prev[q];
            bool use = inside & (lq >= 1.0f) & (lq <= N) & (as_int(geo_prev[GEO_MATERIAL * n + q]) == mat);
            float w = use ? 1.0f : 0.0f;
            float m1q = moments_prev[q];
            nvar += w * m_max(moments_prev[n + q] - m1q * m1q, 0.0f);
            nmean += w * m1q;
            nw += w;
        }
    }
    /* an emitter changed (emitter_moved): the emitting samples of a material in the previous frame's
     * 3x3 around the previous position and in this frame's 3x3 around p, compared (a branch: taken
     * where an emitter is near) */
    bool emitter_changed = false, light_turned = false;
    if (any_emitting) { /* a branch: taken near an emitter */
        /* the emitting samples of the 3x3 around p (k < 9) and around the previous position: their
         * materials (NOT_EMITTING for the others and outside the image) and emissions */
        int emat[18];
        vec3 emits[18];
        for (int k = 0; k < 18; ++k) {
            bool now = k < 9;
            int tx = (now ? x : rx) + (k % 3) - 1, ty = (now ? y : ry) + (k % 9) / 3 - 1;
            bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
            int q = clampi(ty, 0, height - 1) * width + clampi(tx, 0, width - 1);
            vec3 ek = planar3(now ? emission : emission_prev, n, q);
            int mk = as_int((now ? geo : geo_prev)[GEO_MATERIAL * n + q]);
            emat[k] = inside && emitting(ek) ? mk : NOT_EMITTING;
            emits[k] = ek;
        }
        for (int j = 0; j < 18; ++j) {
            int m = emat[j];
            bool first = m != NOT_EMITTING; /* an emitting sample, its material not met before */
            for (int i = 0; i < j; ++i) first &= emat[i] != m;
            if (!first) continue;
            vec3 lo = v3_splat(INFINITY), hi = v3_splat(-INFINITY), lo_p = lo, hi_p = hi;
            int count = 0, count_p = 0;
            for (int k = 0; k < 9; ++k) {
                vec3 ek = emits[k], ep = emits[k + 9];
                bool on = emat[k] == m, on_p = emat[k + 9] == m;
                lo = on ? v3(m_min(lo.x, ek.x), m_min(lo.y, ek.y), m_min(lo.z, ek.z)) : lo;
                hi = on ? v3(m_max(hi.x, ek.x), m_max(hi.y, ek.y), m_max(hi.z, ek.z)) : hi;
                lo_p = on_p ? v3(m_min(lo_p.x, ep.x), m_min(lo_p.y, ep.y), m_min(lo_p.z, ep.z)) : lo_p;
                hi_p = on_p ? v3(m_max(hi_p.x, ep.x), m_max(hi_p.y, ep.y), m_max(hi_p.z, ep.z)) : hi_p;
                count += on ? 1 : 0;
                count_p += on_p ? 1 : 0;
            }
            emitter_changed |= emitter_moved(lo, hi, count, lo_p, hi_p, count_p);
            light_turned |= light_changed(lo, hi, count, lo_p, hi_p, count_p);
        }
    }
    float nsigma = m_sqrt(nvar / m_max(nw, 1.0f));
    nmean /= m_max(nw, 1.0f);

    /* firefly clamp */
    float l = luminance(s);
    float mu = h.m1 * inv, sigma = m_sqrt(m_max(h.m2 * inv - mu * mu, 0.0f));
    float reference = m_max(m_max(around, nmean), valid ? luminance(hist) : 0.0f);
    float own = valid ? mu + firefly_sigma * sigma : 0.0f;
    float pooled = valid ? mu + POOLED_SIGMA * firefly_sigma * nsigma : 0.0f;
    float cap_own = m_sqrt(N) * m_max(firefly_ratio * reference, own);
    float cap = m_sqrt(N) * m_max(firefly_ratio * reference, m_max(own, pooled));
    bool clamp_on = firefly_ratio > 0.0f && (count > 0.0f || valid);
    bool clamped = clamp_on && l > cap;
    s = v3_scale(s, clamped ? cap / l : 1.0f);
    /* the moments: clamped by the pixel's own cap but on a new history (nothing to compare with) */
    l = (valid && clamp_on) ? m_min(l, cap_own) : l;

    /* accumulation (N = 1: the sample alone) */
    float am = m_max(moments_alpha_min, 1.0f / N), af = m_max(fast_alpha, 1.0f / N);
    store_planar3(fast, n, p, lerp3(hist_fast, s, af));
    moments[p] = lerpf(h.m1 * inv, l, am);
    moments[n + p] = lerpf(h.m2 * inv, l * l, am);
    len[p] = N;
    vec3 he = v3_scale(h.emis, inv);
    he = emitter_changed
             ? v3(m_clamp(he.x, e_lo.x, e_hi.x), m_clamp(he.y, e_lo.y, e_hi.y), m_clamp(he.z, e_lo.z, e_hi.z))
             : he;
    vec3 e_out = lerp3(he, e, m_max(alpha_min, 1.0f / N)); /* N = 1 (a new history): e itself */
    store_planar3(emis, n, p, all_finite3(e_out) ? e_out : e);
    store_planar3(temporal, n, p, s);
    store_planar3(temporal + 3 * n, n, p, hist);
    store_planar3(deficit, n, p, v3_scale(h.dfc, inv)); /* clip_history blends it */
    store_planar3(albedo, n, p, A);
    geo[GEO_GRAD * n + p] = grad;
    lit[p] = light_turned && valid ? 1 : 0; /* a light that changed, not one that came into view */
}
