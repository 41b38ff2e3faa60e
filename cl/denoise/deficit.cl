/* deficit: the share of each tile's light that the firefly clamp took. One work-item per tile of
 * DEFICIT_TILE x DEFICIT_TILE pixels (svgf.h), 2D range; after antilag, before variance; read by
 * modulate.
 *
 * clip_history keeps, per pixel and channel, the clamp's deficit history D: the raw sample minus the
 * clamped one, accumulated with the long history's weights (shrunk where the clip lowered the long
 * history for a change of the lighting, joined by what the clip moved where that was noise, cut where
 * the anti-lag cut). Per tile and channel this writes the share sum d D / sum d H, H the long
 * history, d the footprint albedo (reproject; the sums weigh each pixel as its colour does), 0 under DEFICIT_EPS
 * (rounding), at most deficit_cap of the tile's mean history length (DEFICIT_MAX up to
 * DEFICIT_LONG_FROM frames, DEFICIT_MAX_LONG from DEFICIT_LONG_FULL on; svgf.h), and the tile's level
 * sum d H / sum d. modulate gives the shares
 * back, robustly: a lone firefly's deficit is one tile's outlier and is dropped (docs/denoising.md,
 * "The clamp's deficit given back").
 *
 * Consumes: accum[c * pixels + p] (c < 3: the long history, after antilag), deficit[c * pixels + p]
 *           (c < 3: the deficit history), albedo (reproject: the footprint albedo), len (N, after
 *           antilag), all padded (svgf.h, PAD).
 * Produces: tiles[c * tile_count + ty * tiles_x + tx]: c < 3 the tile's share, 3 <= c < 6 its level. */
#include "denoise/svgf.h"

__kernel void deficit(__global const float* accum, __global const float* deficit, __global const float* albedo,
                      __global const float* len, __global float* tiles, int width, int height) {
    int tx = get_global_id(0), ty = get_global_id(1);
    int ntx = deficit_tiles(width), nty = deficit_tiles(height);
    if (tx >= ntx || ty >= nty) return;
    int n = width * height;
    accum += PAD;
    deficit += PAD;
    albedo += PAD;
    len += PAD;
    float sn = 0.0f, cnt = 0.0f; /* the tile's history lengths: their sum and count */
    vec3 sh = v3_splat(0.0f), sd = v3_splat(0.0f), sw = v3_splat(0.0f);
    int x1 = min((tx + 1) * DEFICIT_TILE, width), y1 = min((ty + 1) * DEFICIT_TILE, height);
    for (int y = ty * DEFICIT_TILE; y < y1; ++y) {
        for (int x = tx * DEFICIT_TILE; x < x1; ++x) {
            int p = y * width + x;
            vec3 d = planar3(albedo, n, p);
            vec3 h = planar3(accum, n, p), f = planar3(deficit, n, p);
            sh = v3_add(sh, v3_mul(d, v3(m_max(h.x, 0.0f), m_max(h.y, 0.0f), m_max(h.z, 0.0f))));
            sd = v3_add(sd, v3_mul(d, f));
            sw = v3_add(sw, d);
            sn += len[p];
            cnt += 1.0f;
        }
    }
    int t = ty * ntx + tx, count = ntx * nty;
    float cap = deficit_cap(sn / m_max(cnt, 1.0f));
    vec3 share = v3(sh.x > 0.0f ? sd.x / sh.x : 0.0f, sh.y > 0.0f ? sd.y / sh.y : 0.0f,
                    sh.z > 0.0f ? sd.z / sh.z : 0.0f);
    tiles[t] = share.x > DEFICIT_EPS ? m_min(share.x, cap) : 0.0f;
    tiles[count + t] = share.y > DEFICIT_EPS ? m_min(share.y, cap) : 0.0f;
    tiles[2 * count + t] = share.z > DEFICIT_EPS ? m_min(share.z, cap) : 0.0f;
    tiles[3 * count + t] = sw.x > 0.0f ? sh.x / sw.x : 0.0f;
    tiles[4 * count + t] = sw.y > 0.0f ? sh.y / sw.y : 0.0f;
    tiles[5 * count + t] = sw.z > 0.0f ? sh.z / sw.z : 0.0f;
}
