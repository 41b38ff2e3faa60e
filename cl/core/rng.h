/* rng.h: counter-based random numbers (Philox4x32-10).
 *
 * Every random number is a pure function of (seed, pixel, sample index, bounce,
 * dimension): the key is (seed, pixel), the counter (sample, bounce, dimension, 0).
 * Nothing depends on work-item ids or queue slots, so every integrator draws the
 * same numbers for the same path whatever order its atomics produce. */
#ifndef PYCLPT_RNG_H
#define PYCLPT_RNG_H

#include "core/math.h"

/* Dimensions: each names one Philox block of a bounce, its counter (sample, bounce, dimension, extra). A block
 * gives four words, so a bounce draws its light sample from one block (rng_light) and its BSDF sample and
 * roulette from another (rng_bsdf): two ten-round blocks a bounce where five were drawn (docs/architecture.md,
 * "Random numbers"). Dimensions 1, 2, 4, 5 and 6 are not used. */
#define DIM_LIGHT 0 /* the light sample: selection, then the light's (u, v) */
#define DIM_BSDF 3  /* the BSDF sample: lobe, then (u, v), then the Russian roulette */
#define DIM_CAMERA_X 7
#define DIM_CAMERA_Y 8
#define DIM_MASK_CLOSEST 9 /* opacity tests of the path's ray (4th counter word: triangle) */
#define DIM_MASK_SHADOW 10 /* opacity tests of the shadow ray */
#define DIM_LENS_U 11 /* the thin lens's aperture sample (bounce 0) */
#define DIM_LENS_V 12
#define DIM_VERTEX_CHOICE 13 /* gradients/path_vertices.cl: which later vertex of a path its boundary term takes */

/* The high word of a 32 x 32-bit product: exact on every device, and inlined on PoCL, which calls
 * OpenCL's mul_hi out of line. */
static inline uint mulhi32(uint a, uint b) { return (uint)(((ulong)a * (ulong)b) >> 32); }

/* Philox4x32-10 on scalars, its ten rounds unrolled: no vector types and no loop, so a stage that
 * draws numbers can still be vectorized across work-items (a uint4 or a loop here stops it), and the
 * draws run 50x faster on PoCL than with a uint4, a loop and mul_hi (bench/rng_speed.py). The draws use the
 * first two output words; the compiler drops the work of the others. Always inlined: LLVM's inliner
 * finds the unrolled rounds too big for a stage's three or four draws, and a call stops PoCL's
 * vectorizer. */
static inline __attribute__((always_inline)) void philox4x32_10_words(uint c0, uint c1, uint c2, uint c3, uint k0, uint k1,
                                       uint* r0, uint* r1, uint* r2, uint* r3) {
    const uint M0 = 0xD2511F53u, M1 = 0xCD9E8D57u;
    const uint W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
#pragma unroll
    for (int r = 0; r < 10; ++r) {
        uint hi0 = mulhi32(M0, c0), lo0 = M0 * c0;
        uint hi1 = mulhi32(M1, c2), lo1 = M1 * c2;
        c0 = hi1 ^ c1 ^ k0;
        c1 = lo1;
        c2 = hi0 ^ c3 ^ k1;
        c3 = lo0;
        k0 += W0;
        k1 += W1;
    }
    *r0 = c0;
    *r1 = c1;
    *r2 = c2;
    *r3 = c3;
}

/* The vector form (the known-answer tests). */
static inline uint4 philox4x32_10(uint4 c, uint2 k) {
    uint r0, r1, r2, r3;
    philox4x32_10_words(c.x, c.y, c.z, c.w, k.x, k.y, &r0, &r1, &r2, &r3);
    return (uint4)(r0, r1, r2, r3);
}

typedef struct {
    uint seed;
    uint pixel;
    uint sample;
} RngKey;

static inline RngKey rng_key(uint seed, uint pixel, uint sample) {
    RngKey key = {seed, pixel, sample};
    return key;
}

/* The first two words of the block at counter (sample, bounce, dim, extra) under key (seed, pixel). */
static inline __attribute__((always_inline)) void rng_words(RngKey key, uint bounce, uint dim, uint extra, uint* r0, uint* r1) {
    uint r2, r3;
    philox4x32_10_words(key.sample, bounce, dim, extra, key.seed, key.pixel, r0, r1, &r2, &r3);
}

static inline float rng_unit(uint r) { return (float)(r >> 8) * 0x1.0p-24f; }

/* Uniform float in [0, 1) for one (bounce, dimension) of a path. */
static inline float rng_1d(RngKey key, uint bounce, uint dim) {
    uint r0, r1;
    rng_words(key, bounce, dim, 0u, &r0, &r1);
    return rng_unit(r0);
}

/* As rng_1d, with a fourth counter word (e.g. the triangle of an opacity test). */
static inline float rng_1d_at(RngKey key, uint bounce, uint dim, uint extra) {
    uint r0, r1;
    rng_words(key, bounce, dim, extra, &r0, &r1);
    return rng_unit(r0);
}

static inline vec2 rng_2d(RngKey key, uint bounce, uint dim) {
    uint r0, r1;
    rng_words(key, bounce, dim, 0u, &r0, &r1);
    return v2(rng_unit(r0), rng_unit(r1));
}

/* The four numbers of one block. */
static inline __attribute__((always_inline)) void rng_4d(RngKey key, uint bounce, uint dim, float* u0, float* u1,
                                                          float* u2, float* u3) {
    uint r0, r1, r2, r3;
    philox4x32_10_words(key.sample, bounce, dim, 0u, key.seed, key.pixel, &r0, &r1, &r2, &r3);
    *u0 = rng_unit(r0);
    *u1 = rng_unit(r1);
    *u2 = rng_unit(r2);
    *u3 = rng_unit(r3);
}

/* A bounce's light sample: the light's selection and its (u, v), the words 0, 1, 2 of block DIM_LIGHT. */
static inline void rng_light(RngKey key, uint bounce, float* u_select, vec2* u) {
    float x, y, unused;
    rng_4d(key, bounce, DIM_LIGHT, u_select, &x, &y, &unused);
    *u = v2(x, y);
}

/* A bounce's BSDF sample: the lobe, (u, v) and the Russian roulette's number, the words of block DIM_BSDF. */
static inline void rng_bsdf(RngKey key, uint bounce, float* u_lobe, vec2* u, float* u_roulette) {
    float x, y;
    rng_4d(key, bounce, DIM_BSDF, u_lobe, &x, &y, u_roulette);
    *u = v2(x, y);
}

#endif
