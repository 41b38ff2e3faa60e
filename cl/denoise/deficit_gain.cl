/* deficit_gain: what modulate gives back per tile. One work-item per tile of DEFICIT_TILE x
 * DEFICIT_TILE pixels (svgf.h), 2D range; after deficit.
 *
 * A tile's share to give back, per channel, is its own share, at most DEFICIT_OUTLIER (svgf.h) x the
 * mean of the deficit pass's shares over the 3x3 tiles around it inside the image, the largest left
 * out: a lone firefly's deficit is one tile's outlier and gives nothing back (docs/denoising.md, "The
 * clamp's deficit given back"); with fewer than two tiles (an image of one tile), 0. The level is
 * copied as it is. The robust mean itself was given back before: where the deficit is uneven (the
 * cornell-bunny's ceiling beside the light, shares of 0.4 to 0.9 above tiles of 0.01 to 0.1) it gave
 * too little back to the tiles that lost most, and took the bunny's 32-frame means only to 0.9918 /
 * 0.9905 / 0.9907 of the plain average's with the conserve gain (0.9949 / 0.9932 / 0.9926 with its
 * own share; 5 gives all but the outliers back, 3 left 0.1 % more out; docs/denoising.md, "Energy at
 * 32 frames").
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
        float robust = used > 1.5f ? m_max(sum - top, 0.0f) / (used - 1.0f) : 0.0f;
        gains[c * count + t] = m_min(plane[t], DEFICIT_OUTLIER * robust);
        gains[(3 + c) * count + t] = tiles[(3 + c) * count + t];
    }
}
