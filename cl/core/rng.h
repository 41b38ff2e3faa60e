/* rng.h: counter-based random numbers (Philox4x32-10).
 *
 * Every random number is a pure function of (seed, pixel, sample index, bounce,
 * dimension): the key is (seed, pixel), the counter (sample, bounce, dimension, 0).
 * Nothing depends on work-item ids or queue slots, so every integrator draws the
 * same numbers for the same path whatever order its atomics produce. */
#ifndef PYCLPT_RNG_H
#define PYCLPT_RNG_H

/* Dimensions used at each bounce (the camera's at bounce 0 only). */
#define DIM_LIGHT_SELECT 0
#define DIM_LIGHT_U 1
#define DIM_LIGHT_V 2
#define DIM_BSDF_LOBE 3
#define DIM_BSDF_U 4
#define DIM_BSDF_V 5
#define DIM_ROULETTE 6
#define DIM_CAMERA_X 7
#define DIM_CAMERA_Y 8
#define DIM_MASK_CLOSEST 9 /* opacity tests of the path's ray (4th counter word: triangle) */
#define DIM_MASK_SHADOW 10 /* opacity tests of the shadow ray */

static inline uint4 philox4x32_10(uint4 c, uint2 k) {
    const uint M0 = 0xD2511F53u, M1 = 0xCD9E8D57u;
    const uint W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
    for (int r = 0; r < 10; ++r) {
        uint hi0 = mul_hi(M0, c.x), lo0 = M0 * c.x;
        uint hi1 = mul_hi(M1, c.z), lo1 = M1 * c.z;
        c = (uint4)(hi1 ^ c.y ^ k.x, lo1, hi0 ^ c.w ^ k.y, lo0);
        k.x += W0;
        k.y += W1;
    }
    return c;
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

/* Uniform float in [0, 1) for one (bounce, dimension) of a path. */
static inline float rng_1d(RngKey key, uint bounce, uint dim) {
    uint4 r = philox4x32_10((uint4)(key.sample, bounce, dim, 0u), (uint2)(key.seed, key.pixel));
    return (float)(r.x >> 8) * 0x1.0p-24f;
}

/* As rng_1d, with a fourth counter word (e.g. the triangle of an opacity test). */
static inline float rng_1d_at(RngKey key, uint bounce, uint dim, uint extra) {
    uint4 r = philox4x32_10((uint4)(key.sample, bounce, dim, extra), (uint2)(key.seed, key.pixel));
    return (float)(r.x >> 8) * 0x1.0p-24f;
}

static inline float2 rng_2d(RngKey key, uint bounce, uint dim) {
    uint4 r = philox4x32_10((uint4)(key.sample, bounce, dim, 0u), (uint2)(key.seed, key.pixel));
    return (float2)((float)(r.x >> 8) * 0x1.0p-24f, (float)(r.y >> 8) * 0x1.0p-24f);
}

#endif
