/* reproject: SVGF's temporal pass (Schied et al. 2017; Falcor's SVGFReproject), with the fast
 * history of NRD's RELAX. One work-item per pixel, 2D range; after demodulate.
 *
 * 1. The frame's sample (demodulate's illumination) firefly-clamped: its luminance is scaled down to
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
 *    if inside the image, holding a history (length >= 1) and the same surface (consistent(): same
 *    material id; both background, or both surfaces with |z - z_prev| <= depth_threshold x (GEO_GRAD
 *    + 0.01 z) and normals with cos >= min(normal_threshold, cos_spread), cos_spread the smallest
 *    normal cosine from p to its surface neighbours, as Falcor scales its normal test by fwidth);
 *    the bilinear weights renormalised over the
 *    accepted taps (accepted if their weight sums to more than 0.01). Else the 3x3 pixels around the
 *    rounded previous position (itself inside the image), equally weighted (Falcor's fallback: a
 *    branch, taken at disocclusions only). Else a disocclusion: the history restarts.
 * 3. The emission history (the emitted part of the colour, demodulate, kept apart from the filtered
 *    illumination and added back by modulate): the reprojected one clipped into the [min, max] box of
 *    this frame's emission over the 3x3 pixels around p inside the image (an emitter is noise-free, so
 *    its box is tight inside it and spans [dark, bright] on its jittered edges; a light that changes
 *    leaves the box at once) where it lies outside the box widened by EMISSION_MARGIN x its width
 *    (emission_clip), then blended with weight max(alpha_min, 1/N), as the long history: a
 *    static emitter's edge converges to the plain average of its frames.
 * 4. History length N = min(N_prev + 1, max_history) (N_prev: the accepted taps' weighted mean,
 *    rounded), 1 at a disocclusion; moments of luminance blended with max(moments_alpha_min, 1/N),
 *    the fast history with max(fast_alpha, 1/N). The long history is blended by clip_history. Where
 *    the lighting changed, the antilag pass (cl/denoise/antilag.cl) cuts N, the moments and the
 *    fast, long and emission histories in this same frame (it used to be done here, one frame
 *    late, from the previous frame's statistic).
 * The depth gradient GEO_GRAD: |dz/dx| + |dz/dy|, each the smaller of the one-sided differences to
 * the surface neighbours (a depth edge on one side does not count).
 *
 * Consumes: sample (demodulate: illumination, luminance); emission (demodulate: the emitted part); geo (this frame's record from demodulate:
 *           depth, normal, material); aovs[c * pixels + p] (cl/film/aovs.h: the motion); the
 *           previous frame's geo_prev (GEO_*), hist_prev (long history colour, channels 0..2),
 *           fast_prev (3), moments_prev (2), len_prev (history length; 0 = none, after a reset),
 *           emis_prev (3, the emission history), deficit_prev (3, the clamp's deficit history of
 *           clip_history).
 *           All but aovs padded (svgf.h, PAD).
 * Produces: geo[GEO_GRAD]; temporal[0..2] the sample clamped, temporal[3..5] the long history
 *           reprojected (0 at a disocclusion); fast (the fast history accumulated), moments
 *           (luminance mean and mean of squares), len (N, a float), emis (the emission history),
 *           deficit (the clamp's deficit history reprojected with the same taps, blended by
 *           clip_history); all padded. */
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

/* The emission history is clipped into this frame's 3x3 [min, max] box only where it lies outside the
 * box widened by EMISSION_MARGIN x the box's width on either side; then into the box itself. A
 * changed light leaves the widened box at once (a noise-free emitter's box has no width); what stays
 * inside it is the jitter of a pixel that shows an emitter only in part (the living room's windows:
 * the sky in one frame, a window bar in the next, whose box is then [0, 0] around a sky history),
 * which the plain box clipped towards the frame: 0.3 to 0.4 % of the room's light at 32 frames
 * (0.9817 / 0.9875 / 0.9951 of the plain average's; 0.9849 / 0.9902 / 0.9961 with a margin of 0.5,
 * 0.9856 / 0.9904 / 0.9961 unclipped; docs/denoising.md, "Energy at 32 frames"). */
#define EMISSION_MARGIN 0.5f

static inline float emission_clip(float h, float lo, float hi) {
    float m = EMISSION_MARGIN * (hi - lo);
    bool out = h < lo - m || h > hi + m;
    return out ? m_clamp(h, lo, hi) : h;
}

/* |z - zn| for a surface neighbour, INFINITY for a background one. */
static inline float depth_step(float z, float zn) { return zn > 0.0f ? m_abs(z - zn) : INFINITY; }

/* The previous frame's history, summed over accepted taps with their weights. */
typedef struct {
    vec3 color, fast, emis, dfc;
    float m1, m2, len, weight;
} history_t;

static inline void add_tap(history_t* h, __global const float* hist_prev, __global const float* fast_prev,
                           __global const float* moments_prev, __global const float* len_prev,
                           __global const float* emis_prev, __global const float* deficit_prev, int n, int q,
                           float w) {
    h->color = v3_add(h->color, v3_scale(planar3(hist_prev, n, q), w));
    h->fast = v3_add(h->fast, v3_scale(planar3(fast_prev, n, q), w));
    h->emis = v3_add(h->emis, v3_scale(planar3(emis_prev, n, q), w));
    h->dfc = v3_add(h->dfc, v3_scale(planar3(deficit_prev, n, q), w));
    h->m1 += w * moments_prev[q];
    h->m2 += w * moments_prev[n + q];
    h->len += w * len_prev[q];
    h->weight += w;
}

__kernel void reproject(__global const float* sample, __global const float* emission, __global float* geo,
                        __global const float* aovs,
                        __global const float* geo_prev, __global const float* hist_prev,
                        __global const float* fast_prev, __global const float* moments_prev,
                        __global const float* len_prev, __global const float* emis_prev,
                        __global const float* deficit_prev, __global float* temporal, __global float* deficit,
                        __global float* fast, __global float* moments, __global float* len, __global float* emis,
                        int width, int height, float depth_threshold, float normal_threshold, float firefly_ratio,
                        float firefly_sigma, float max_history, float alpha_min, float moments_alpha_min,
                        float fast_alpha) {
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= width || y >= height) return;
    int n = width * height, p = y * width + x;
    sample += PAD;
    emission += PAD;
    emis_prev += PAD;
    emis += PAD;
    deficit_prev += PAD;
    deficit += PAD;
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
    UNROLL for (int dy = -1; dy <= 1; ++dy) {
        UNROLL for (int dx = -1; dx <= 1; ++dx) {
            if (dx == 0 && dy == 0) continue;
            int tx = x + dx, ty = y + dy;
            float w = (tx >= 0 && tx < width && ty >= 0 && ty < height) ? 1.0f : 0.0f;
            int q = row_at(y, dy, width, height) + tx;
            around += w * sample[3 * n + q];
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
    history_t h = {v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), 0.0f, 0.0f, 0.0f, 0.0f};
    UNROLL for (int t = 0; t < 4; ++t) {
        int tx = x0 + (t & 1), ty = y0 + (t >> 1);
        bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
        int q = clampi(ty, 0, height - 1) * width + clampi(tx, 0, width - 1);
        bool ok = inside & (len_prev[q] >= 1.0f) & consistent(geo_prev, n, q, z, nrm, mat, ztol, cos_min);
        float bw = ((t & 1) ? fx : 1.0f - fx) * ((t >> 1) ? fy : 1.0f - fy);
        add_tap(&h, hist_prev, fast_prev, moments_prev, len_prev, emis_prev, deficit_prev, n, q, ok ? bw : 0.0f);
    }
    /* none (a weight below 0.01): Falcor's fallback, the 3x3 pixels around the rounded position,
     * equally weighted; a branch, taken at disocclusions only */
    if (!(h.weight > 0.01f)) {
        int rx = (int)m_floor(px + 0.5f), ry = (int)m_floor(py + 0.5f);
        history_t f = {v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), v3_splat(0.0f), 0.0f, 0.0f, 0.0f, 0.0f};
        if (rx >= 0 && rx < width && ry >= 0 && ry < height) {
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    int tx = rx + dx, ty = ry + dy;
                    bool inside = tx >= 0 && tx < width && ty >= 0 && ty < height;
                    int q = clampi(ty, 0, height - 1) * width + clampi(tx, 0, width - 1);
                    bool ok = inside & (len_prev[q] >= 1.0f)
                              & consistent(geo_prev, n, q, z, nrm, mat, ztol, cos_min);
                    add_tap(&f, hist_prev, fast_prev, moments_prev, len_prev, emis_prev, deficit_prev, n, q,
                            ok ? 1.0f : 0.0f);
                }
            }
        }
        h = f;
    }
    bool valid = h.weight > 0.01f;
    float inv = valid ? 1.0f / h.weight : 0.0f;
    vec3 hist = v3_scale(h.color, inv), hist_fast = v3_scale(h.fast, inv);
    float N = valid ? m_min(m_floor(h.len * inv + 0.5f) + 1.0f, max_history) : 1.0f;

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
            float lq = len_prev[q];
            bool use = inside & (lq >= 1.0f) & (lq <= N) & (as_int(geo_prev[GEO_MATERIAL * n + q]) == mat);
            float w = use ? 1.0f : 0.0f;
            float m1q = moments_prev[q];
            nvar += w * m_max(moments_prev[n + q] - m1q * m1q, 0.0f);
            nmean += w * m1q;
            nw += w;
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
    he = v3(emission_clip(he.x, e_lo.x, e_hi.x), emission_clip(he.y, e_lo.y, e_hi.y),
            emission_clip(he.z, e_lo.z, e_hi.z));
    vec3 e_out = lerp3(he, e, m_max(alpha_min, 1.0f / N)); /* N = 1 (a new history): e itself */
    store_planar3(emis, n, p, all_finite3(e_out) ? e_out : e);
    store_planar3(temporal, n, p, s);
    store_planar3(temporal + 3 * n, n, p, hist);
    store_planar3(deficit, n, p, v3_scale(h.dfc, inv)); /* clip_history blends it */
    geo[GEO_GRAD * n + p] = grad;
}
