/* conserve_gain: the a-trous filter's energy balance that modulate applies, per tile. One work-item
 * per tile of CONSERVE_TILE x CONSERVE_TILE pixels (svgf.h), 2D range; after conserve.
 *
 * A tile's gain G (conserve.cl) is given as 1 + e, e = G - 1 limited to CONSERVE_OUTLIER x the robust
 * mean of the same sign's e over the 3x3 tiles around it inside the image (the largest left out, as
 * deficit_gain does), and 0 where |e| is under CONSERVE_EPS (a noise-free tile's rounding). What one
 * pixel's outlier, a lone firefly, loses in the filter is then not given to its tile: it is that
 * tile's alone (tests/test_denoise.py::test_firefly_is_confined_and_fades: its excess 2.7 x the
 * pixel's luminance with the tile's own gain, 3.8 x when it was just disoccluded, against 1.5 and 0.2
 * allowed); a light's edge loses in a row of tiles. With fewer than two tiles, e = 0.
 *
 * Consumes: tiles[c * tile_count + t] (conserve: c < 3 the tile's gain G).
 * Produces: gains[c * tile_count + t], c < 3: the gain modulate applies. */
#include "denoise/svgf.h"

__kernel void conserve_gain(__global const float* tiles, __global float* gains, int width, int height) {
    int tx = get_global_id(0), ty = get_global_id(1);
    int ntx = conserve_tiles(width), nty = conserve_tiles(height);
    if (tx >= ntx || ty >= nty) return;
    int count = ntx * nty, t = ty * ntx + tx;
    for (int c = 0; c < 3; ++c) {
        __global const float* plane = tiles + c * count;
        float up = 0.0f, down = 0.0f, top_up = 0.0f, top_down = 0.0f, used = 0.0f;
        for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
                int qx = tx + dx, qy = ty + dy;
                if (qx < 0 || qx >= ntx || qy < 0 || qy >= nty) continue;
                float e = plane[qy * ntx + qx] - 1.0f;
                float eu = e > CONSERVE_EPS ? e : 0.0f, ed = -e > CONSERVE_EPS ? -e : 0.0f;
                up += eu;
                down += ed;
                top_up = m_max(top_up, eu);
                top_down = m_max(top_down, ed);
                used += 1.0f;
            }
        }
        float e = plane[t] - 1.0f;
        float inv = used > 1.5f ? 1.0f / (used - 1.0f) : 0.0f;
        float lim_up = CONSERVE_OUTLIER * m_max(up - top_up, 0.0f) * inv;
        float lim_down = CONSERVE_OUTLIER * m_max(down - top_down, 0.0f) * inv;
        e = e > CONSERVE_EPS ? m_min(e, lim_up) : (-e > CONSERVE_EPS ? -m_min(-e, lim_down) : 0.0f);
        gains[c * count + t] = 1.0f + e;
    }
}
