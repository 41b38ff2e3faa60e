/* deficit_gain: what modulate gives back per tile. One work-item per tile of DEFICIT_TILE x
 * DEFICIT_TILE pixels (svgf.h), 2D range; after deficit.
 *
 * A tile's share to give back, per channel, is the mean of the deficit pass's shares over the 3x3
 * tiles around it inside the image, the largest left out: a lone firefly's deficit is one tile's
 * outlier and gives nothing back (docs/denoising.md, "The clamp's deficit given back"); with fewer
 * than two tiles (an image of one tile), 0. The level is copied as it is.
 *
 * Consumes: tiles[c * tile_count + t] (the deficit pass: c < 3 the tile's share, 3 <= c < 6 its level).
 * Produces: gains[c * tile_count + t]: c < 3 the share to give back, 3 <= c < 6 the level. */
#include "denoise/svgf.h"

__kernel void deficit_gain(__global const float* tiles, __global float* gains, int width, int height) {
    int tx = get_global_id(0), ty = get_global_id(1);
    int ntx = deficit_tiles(width), nty = deficit_tiles(height);
    if (tx >= ntx || ty >= nty) return;
    int count = ntx * nty, t = ty * ntx + tx;
    for (int c = 0; c < 3; ++c) {
        __global const float* plane = tiles + c * count;
        float sum = 0.0f, top = 0.0f, used = 0.0f;
        for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
                int qx = tx + dx, qy = ty + dy;
                if (qx < 0 || qx >= ntx || qy < 0 || qy >= nty) continue;
                float v = plane[qy * ntx + qx];
                sum += v;
                top = m_max(top, v);
                used += 1.0f;
            }
        }
        gains[c * count + t] = used > 1.5f ? m_max(sum - top, 0.0f) / (used - 1.0f) : 0.0f;
        gains[(3 + c) * count + t] = tiles[(3 + c) * count + t];
    }
}
