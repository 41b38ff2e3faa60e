/* aovs.h: the G-buffer (arbitrary output variables) the integrators record beside the radiance,
 * when the program is built with -DAOVS (pyclpt/film/aovs.py: Renderer(aovs=...)).
 *
 * Layout: planar floats, channel c of record i at aovs[c * n + i]. The integrators write one record
 * per film slot (n = the batch's slots, cl/film/aov_accumulate.cl then averages a pixel's samples in
 * sample order into a per-pixel buffer of the same layout with n = pixels). The channels:
 *   AOV_ALBEDO    3  albedo of the first non-specular (non-delta) vertex, times the throughput of the
 *                    specular chain before it; 0 where the path leaves the scene first
 *   AOV_NORMAL    3  world-space shading normal at the first hit (0 on a miss)
 *   AOV_ROUGHNESS 1  linear roughness (microfacet alpha) at the first hit: 1 diffuse, 0 smooth
 *   AOV_DEPTH     1  view-space depth (viewZ: distance along the camera's forward axis) of the first hit,
 *                    0 on a miss
 *   AOV_HITDIST   1  length of the second ray (bounce 1) to its hit; 0 if it missed or was not traced
 *   AOV_MOTION    2  screen-space motion in pixels, x right, y down: where the first hit point (a miss: its
 *                    direction, a point at infinity) was in the previous frame (previous camera) minus
 *                    where it is now; AOV_OFFSCREEN (both) when it was behind the previous camera
 *   AOV_EMISSION  3  radiance emitted towards the camera at the first hit (an emitter seen directly; a miss:
 *                    the environment along the camera ray): the part of the pixel's radiance a denoiser
 *                    must not filter, exactly what the path gathers at its first vertex
 *   AOV_PRIM      1  triangle of the first hit, BVH leaf order, as int bits (as_float); -1 on a miss
 *   AOV_MATERIAL  1  material index of the first hit, as int bits; -1 on a miss
 * Averaged per pixel: all but the two ids, which are the pixel's first sample's. */
#ifndef PYCLPT_AOVS_H
#define PYCLPT_AOVS_H

#define AOV_ALBEDO 0
#define AOV_NORMAL 3
#define AOV_ROUGHNESS 6
#define AOV_DEPTH 7
#define AOV_HITDIST 8
#define AOV_MOTION 9
#define AOV_EMISSION 11
#define AOV_PRIM 14
#define AOV_MATERIAL 15
#define AOV_COUNT 16
#define AOV_FLOATS 14 /* channels 0 .. AOV_FLOATS - 1 are averaged; the rest are ids */
#define AOV_OFFSCREEN 1.0e6f

#endif
