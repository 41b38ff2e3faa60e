/* texture.h: textures looked up at a surface's uv (Mitsuba ``bitmap`` and
 * ``checkerboard``), written by pyclpt/textures.py.
 *
 * Each texture is TEX_STRIDE floats in `textures`; bitmap texels are RGBA,
 * either 8-bit (`texels8`, 4 uchar per texel: sRGB-encoded or linear) or float
 * (`texels32`, 4 floats per texel, linear: HDR files and environment maps).
 * 8-bit sRGB texels are decoded to linear before filtering (through the table
 * below), as Mitsuba does. Alpha is always linear.
 *
 * uv convention: OBJ/OpenGL, v pointing up: uv (0, 0) is the bottom-left of
 * the image and row 0 of the texel array is its top (Mitsuba's v runs down:
 * v_mitsuba = 1 - v; the loaders convert). The texture's uv transform applies
 * first: (s, t) = M (u, v, 1) with the 2x3 matrix M at TEX_UV (row by row),
 * Mitsuba's to_uv conjugated into this convention by the loader. */
#ifndef PYCLPT_TEXTURE_H
#define PYCLPT_TEXTURE_H

#include "core/common.h"

#define TEX_STRIDE 20
#define TEX_KIND 0      /* TEX_BITMAP or TEX_CHECKER */
#define TEX_FORMAT 1    /* bitmap: TEXF_SRGB8, TEXF_LINEAR8 or TEXF_FLOAT */
#define TEX_WIDTH 2
#define TEX_HEIGHT 3
#define TEX_OFFSET 4    /* int bits: first texel in texels8 or texels32 */
#define TEX_WRAP 5      /* TEX_WRAP_* */
#define TEX_FILTER 6    /* 0 nearest, 1 bilinear */
#define TEX_CHANNELS 7  /* channels in the file: 4 (or 2) means it has alpha */
#define TEX_UV 8        /* 6 floats: the uv transform [a b c; d e f], s = a u + b v + c, t = d u + e v + f */
#define TEX_SCALE 14    /* rgb: multiplier of a bitmap; color0 of a checkerboard */
#define TEX_COLOR1 17   /* rgb: color1 of a checkerboard */

#define TEX_BITMAP 0
#define TEX_CHECKER 1
#define TEXF_SRGB8 0
#define TEXF_LINEAR8 1
#define TEXF_FLOAT 2
#define TEX_WRAP_REPEAT 0
#define TEX_WRAP_MIRROR 1
#define TEX_WRAP_CLAMP 2
#define TEX_WRAP_BLACK 3

/* The texture buffers of a scene. */
typedef struct {
    __global const float* info;
    __global const uchar* texels8;
    __global const float* texels32;
    int unit; /* 1: the stride of record reads (rgb_at, core/common.h) */
} Textures;

static __constant float SRGB8_TO_LINEAR[256] = {
    0.00000000e+00f, 3.03526984e-04f, 6.07053967e-04f, 9.10580951e-04f, 1.21410793e-03f, 1.51763492e-03f,
    1.82116190e-03f, 2.12468888e-03f, 2.42821587e-03f, 2.73174285e-03f, 3.03526984e-03f, 3.34653576e-03f,
    3.67650732e-03f, 4.02471702e-03f, 4.39144204e-03f, 4.77695348e-03f, 5.18151670e-03f, 5.60539162e-03f,
    6.04883302e-03f, 6.51209079e-03f, 6.99541019e-03f, 7.49903204e-03f, 8.02319299e-03f, 8.56812562e-03f,
    9.13405870e-03f, 9.72121732e-03f, 1.03298230e-02f, 1.09600940e-02f, 1.16122452e-02f, 1.22864884e-02f,
    1.29830323e-02f, 1.37020830e-02f, 1.44438436e-02f, 1.52085144e-02f, 1.59962934e-02f, 1.68073758e-02f,
    1.76419545e-02f, 1.85002201e-02f, 1.93823610e-02f, 2.02885631e-02f, 2.12190104e-02f, 2.21738848e-02f,
    2.31533662e-02f, 2.41576324e-02f, 2.51868596e-02f, 2.62412219e-02f, 2.73208916e-02f, 2.84260395e-02f,
    2.95568344e-02f, 3.07134437e-02f, 3.18960331e-02f, 3.31047666e-02f, 3.43398068e-02f, 3.56013149e-02f,
    3.68894504e-02f, 3.82043716e-02f, 3.95462353e-02f, 4.09151969e-02f, 4.23114106e-02f, 4.37350293e-02f,
    4.51862044e-02f, 4.66650863e-02f, 4.81718242e-02f, 4.97065660e-02f, 5.12694584e-02f, 5.28606470e-02f,
    5.44802764e-02f, 5.61284900e-02f, 5.78054302e-02f, 5.95112382e-02f, 6.12460542e-02f, 6.30100177e-02f,
    6.48032667e-02f, 6.66259386e-02f, 6.84781698e-02f, 7.03600957e-02f, 7.22718507e-02f, 7.42135684e-02f,
    7.61853815e-02f, 7.81874218e-02f, 8.02198203e-02f, 8.22827071e-02f, 8.43762115e-02f, 8.65004620e-02f,
    8.86555863e-02f, 9.08417112e-02f, 9.30589628e-02f, 9.53074666e-02f, 9.75873471e-02f, 9.98987282e-02f,
    1.02241733e-01f, 1.04616484e-01f, 1.07023103e-01f, 1.09461711e-01f, 1.11932428e-01f, 1.14435374e-01f,
    1.16970668e-01f, 1.19538428e-01f, 1.22138772e-01f, 1.24771818e-01f, 1.27437680e-01f, 1.30136477e-01f,
    1.32868322e-01f, 1.35633330e-01f, 1.38431615e-01f, 1.41263291e-01f, 1.44128471e-01f, 1.47027266e-01f,
    1.49959790e-01f, 1.52926152e-01f, 1.55926464e-01f, 1.58960835e-01f, 1.62029376e-01f, 1.65132195e-01f,
    1.68269400e-01f, 1.71441101e-01f, 1.74647404e-01f, 1.77888416e-01f, 1.81164244e-01f, 1.84474995e-01f,
    1.87820772e-01f, 1.91201683e-01f, 1.94617830e-01f, 1.98069320e-01f, 2.01556254e-01f, 2.05078736e-01f,
    2.08636870e-01f, 2.12230757e-01f, 2.15860500e-01f, 2.19526200e-01f, 2.23227957e-01f, 2.26965874e-01f,
    2.30740049e-01f, 2.34550582e-01f, 2.38397574e-01f, 2.42281122e-01f, 2.46201327e-01f, 2.50158285e-01f,
    2.54152094e-01f, 2.58182853e-01f, 2.62250658e-01f, 2.66355605e-01f, 2.70497791e-01f, 2.74677312e-01f,
    2.78894263e-01f, 2.83148740e-01f, 2.87440838e-01f, 2.91770650e-01f, 2.96138271e-01f, 3.00543794e-01f,
    3.04987314e-01f, 3.09468923e-01f, 3.13988713e-01f, 3.18546778e-01f, 3.23143209e-01f, 3.27778098e-01f,
    3.32451536e-01f, 3.37163615e-01f, 3.41914425e-01f, 3.46704056e-01f, 3.51532600e-01f, 3.56400144e-01f,
    3.61306780e-01f, 3.66252596e-01f, 3.71237680e-01f, 3.76262123e-01f, 3.81326011e-01f, 3.86429434e-01f,
    3.91572478e-01f, 3.96755231e-01f, 4.01977780e-01f, 4.07240212e-01f, 4.12542613e-01f, 4.17885071e-01f,
    4.23267670e-01f, 4.28690497e-01f, 4.34153636e-01f, 4.39657174e-01f, 4.45201195e-01f, 4.50785783e-01f,
    4.56411023e-01f, 4.62077000e-01f, 4.67783796e-01f, 4.73531496e-01f, 4.79320183e-01f, 4.85149940e-01f,
    4.91020850e-01f, 4.96932995e-01f, 5.02886458e-01f, 5.08881321e-01f, 5.14917665e-01f, 5.20995573e-01f,
    5.27115126e-01f, 5.33276404e-01f, 5.39479489e-01f, 5.45724461e-01f, 5.52011402e-01f, 5.58340390e-01f,
    5.64711506e-01f, 5.71124829e-01f, 5.77580440e-01f, 5.84078418e-01f, 5.90618841e-01f, 5.97201788e-01f,
    6.03827339e-01f, 6.10495571e-01f, 6.17206562e-01f, 6.23960392e-01f, 6.30757136e-01f, 6.37596874e-01f,
    6.44479682e-01f, 6.51405637e-01f, 6.58374817e-01f, 6.65387298e-01f, 6.72443157e-01f, 6.79542470e-01f,
    6.86685312e-01f, 6.93871761e-01f, 7.01101892e-01f, 7.08375780e-01f, 7.15693501e-01f, 7.23055129e-01f,
    7.30460740e-01f, 7.37910409e-01f, 7.45404210e-01f, 7.52942217e-01f, 7.60524505e-01f, 7.68151147e-01f,
    7.75822218e-01f, 7.83537792e-01f, 7.91297940e-01f, 7.99102738e-01f, 8.06952258e-01f, 8.14846572e-01f,
    8.22785754e-01f, 8.30769877e-01f, 8.38799012e-01f, 8.46873232e-01f, 8.54992608e-01f, 8.63157213e-01f,
    8.71367119e-01f, 8.79622397e-01f, 8.87923118e-01f, 8.96269353e-01f, 9.04661174e-01f, 9.13098652e-01f,
    9.21581856e-01f, 9.30110858e-01f, 9.38685728e-01f, 9.47306537e-01f, 9.55973353e-01f, 9.64686248e-01f,
    9.73445290e-01f, 9.82250550e-01f, 9.91102097e-01f, 1.00000000e+00f};

/* Texel index along one axis after wrapping; -1 outside for TEX_WRAP_BLACK. */
static inline int tex_wrap(int i, int n, int mode) {
    if (i >= 0 && i < n) return i;
    if (mode == TEX_WRAP_REPEAT) {
        int r = i % n;
        return r < 0 ? r + n : r;
    }
    if (mode == TEX_WRAP_MIRROR) {
        int period = 2 * n;
        int r = i % period;
        if (r < 0) r += period;
        return r < n ? r : period - 1 - r;
    }
    if (mode == TEX_WRAP_CLAMP) return i < 0 ? 0 : n - 1;
    return -1;
}

/* One texel, linear RGBA. */
static inline vec4 tex_texel(const Textures* tx, __global const float* t, int x, int y) {
    int w = (int)t[TEX_WIDTH], h = (int)t[TEX_HEIGHT], mode = (int)t[TEX_WRAP];
    x = tex_wrap(x, w, mode);
    y = tex_wrap(y, h, mode);
    if (x < 0 || y < 0) return v4(0.0f, 0.0f, 0.0f, 0.0f);
    int at = as_int(t[TEX_OFFSET]) + y * w + x;
    int format = (int)t[TEX_FORMAT];
    if (format == TEXF_FLOAT) {
        __global const float* p = tx->texels32 + 4 * at;
        return v4(p[0], p[1], p[2], p[3]);
    }
    __global const uchar* p = tx->texels8 + 4 * at;
    float a = (float)p[3] * (1.0f / 255.0f);
    if (format == TEXF_SRGB8)
        return v4(SRGB8_TO_LINEAR[p[0]], SRGB8_TO_LINEAR[p[1]], SRGB8_TO_LINEAR[p[2]], a);
    return v4_scale(v4((float)p[0], (float)p[1], (float)p[2], (float)p[3]), 1.0f / 255.0f);
}

/* Bilinear blend of four texels at fractions (fx, fy): (1 - fy)((1 - fx) c00 + fx c10) + fy((1 - fx) c01 + fx c11). */
static inline vec4 tex_bilerp(vec4 c00, vec4 c10, vec4 c01, vec4 c11, float fx, float fy) {
    vec4 top = v4_add(v4_scale(c00, 1.0f - fx), v4_scale(c10, fx));
    vec4 bottom = v4_add(v4_scale(c01, 1.0f - fx), v4_scale(c11, fx));
    return v4_add(v4_scale(top, 1.0f - fy), v4_scale(bottom, fy));
}

/* A bitmap's linear RGBA at uv (after the uv transform), nearest or bilinear. */
static inline vec4 tex_bitmap(const Textures* tx, __global const float* t, vec2 uv) {
    float w = t[TEX_WIDTH], h = t[TEX_HEIGHT];
    float x = uv.x * w - 0.5f;
    float y = (1.0f - uv.y) * h - 0.5f;
    if (!(m_isfinite(x) && m_isfinite(y))) return v4(0.0f, 0.0f, 0.0f, 0.0f);
    /* keep far-away coordinates in int range; the wrap modes are periodic or saturating */
    x = m_clamp(x, -1.0e7f, 1.0e7f);
    y = m_clamp(y, -1.0e7f, 1.0e7f);
    float fx = m_floor(x), fy = m_floor(y);
    int x0 = (int)fx, y0 = (int)fy;
    if ((int)t[TEX_FILTER] == 0) {
        return tex_texel(tx, t, (int)m_floor(x + 0.5f), (int)m_floor(y + 0.5f));
    }
    float ax = x - fx, ay = y - fy;
    vec4 c00 = tex_texel(tx, t, x0, y0), c10 = tex_texel(tx, t, x0 + 1, y0);
    vec4 c01 = tex_texel(tx, t, x0, y0 + 1), c11 = tex_texel(tx, t, x0 + 1, y0 + 1);
    return tex_bilerp(c00, c10, c01, c11, ax, ay);
}

/* The texture record t's uv transform applied to uv. */
static inline vec2 tex_st(__global const float* t, vec2 uv) {
    return v2(t[TEX_UV] * uv.x + t[TEX_UV + 1] * uv.y + t[TEX_UV + 2],
              t[TEX_UV + 3] * uv.x + t[TEX_UV + 4] * uv.y + t[TEX_UV + 5]);
}

/* A checkerboard's square at st: true for color0 (Mitsuba's `eval`: the fractional parts of s and of
 * Mitsuba's t = 1 - st.y both below or both above one half). */
static inline bool tex_checker_color0(vec2 st) {
    float tm = 1.0f - st.y;
    return (st.x - m_floor(st.x) > 0.5f) == (tm - m_floor(tm) > 0.5f);
}

/* Texture `id` at uv: linear RGBA with the texture's scale applied to rgb. */
static inline GPU_INLINE vec4 tex_eval4(const Textures* tx, int id, vec2 uv) {
    __global const float* t = tx->info + TEX_STRIDE * id;
    vec2 st = tex_st(t, uv);
    vec3 scale = rgb_at(t + TEX_SCALE, tx->unit);
    if ((int)t[TEX_KIND] == TEX_CHECKER) {
        if (tex_checker_color0(st)) return v4(scale.x, scale.y, scale.z, 1.0f);
        return v4(t[TEX_COLOR1], t[TEX_COLOR1 + 1], t[TEX_COLOR1 + 2], 1.0f);
    }
    vec4 c = tex_bitmap(tx, t, st);
    return v4(c.x * scale.x, c.y * scale.y, c.z * scale.z, c.w);
}

static inline GPU_INLINE vec3 tex_eval(const Textures* tx, int id, vec2 uv) { return v4_xyz(tex_eval4(tx, id, uv)); }

/* The texels a lookup of texture `id` at uv blends, with their weights: tex_eval4's value is
 * scale * sum_k w[k] * texel(at[k]) (before sRGB decoding of 8-bit texels: the weights apply to linear
 * values). at[k] indexes texels8 (is_float false) or texels32 (true) in texels, -1 for a texel outside a
 * TEX_WRAP_BLACK image (weight 0). n = 0 for a checkerboard (its colours are not texels). For
 * gradients with respect to texels (cl/gradients/). */
typedef struct {
    int at[4];
    float w[4];
    int n;
    bool is_float;
} TexTaps;

static inline int tex_texel_index(__global const float* t, int x, int y) {
    int w = (int)t[TEX_WIDTH], h = (int)t[TEX_HEIGHT], mode = (int)t[TEX_WRAP];
    x = tex_wrap(x, w, mode);
    y = tex_wrap(y, h, mode);
    if (x < 0 || y < 0) return -1;
    return as_int(t[TEX_OFFSET]) + y * w + x;
}

static inline TexTaps tex_taps(const Textures* tx, int id, vec2 uv) {
    TexTaps k;
    k.n = 0;
    k.is_float = false;
    __global const float* t = tx->info + TEX_STRIDE * id;
    if ((int)t[TEX_KIND] != TEX_BITMAP) return k;
    k.is_float = (int)t[TEX_FORMAT] == TEXF_FLOAT;
    vec2 st = tex_st(t, uv);
    float x = st.x * t[TEX_WIDTH] - 0.5f;
    float y = (1.0f - st.y) * t[TEX_HEIGHT] - 0.5f;
    if (!(m_isfinite(x) && m_isfinite(y))) return k;
    x = m_clamp(x, -1.0e7f, 1.0e7f);
    y = m_clamp(y, -1.0e7f, 1.0e7f);
    float fx = m_floor(x), fy = m_floor(y);
    if ((int)t[TEX_FILTER] == 0) {
        k.n = 1;
        k.at[0] = tex_texel_index(t, (int)m_floor(x + 0.5f), (int)m_floor(y + 0.5f));
        k.w[0] = 1.0f;
        return k;
    }
    int x0 = (int)fx, y0 = (int)fy;
    float ax = x - fx, ay = y - fy;
    k.n = 4;
    k.at[0] = tex_texel_index(t, x0, y0);
    k.at[1] = tex_texel_index(t, x0 + 1, y0);
    k.at[2] = tex_texel_index(t, x0, y0 + 1);
    k.at[3] = tex_texel_index(t, x0 + 1, y0 + 1);
    k.w[0] = (1.0f - ax) * (1.0f - ay);
    k.w[1] = ax * (1.0f - ay);
    k.w[2] = (1.0f - ax) * ay;
    k.w[3] = ax * ay;
    return k;
}

/* A scalar view of a texture (opacity, bump height): the mean of rgb, as Mitsuba's
 * `eval_1` of an RGB texture. A checkerboard's colours trade places here, as in Mitsuba 3.9's
 * `checkerboard.eval_1` (color1 where `eval` gives color0). */
static inline GPU_INLINE float tex_eval1(const Textures* tx, int id, vec2 uv) {
    __global const float* t = tx->info + TEX_STRIDE * id;
    vec3 c;
    if ((int)t[TEX_KIND] == TEX_CHECKER) {
        int at = tex_checker_color0(tex_st(t, uv)) ? TEX_COLOR1 : TEX_SCALE;
        c = v3(t[at], t[at + 1], t[at + 2]);
    } else {
        c = tex_eval(tx, id, uv);
    }
    return (c.x + c.y + c.z) * (1.0f / 3.0f);
}

/* Opacity (mask): the alpha channel of a bitmap that has one, else the mean of rgb. */
static inline float tex_opacity(const Textures* tx, int id, vec2 uv) {
    __global const float* t = tx->info + TEX_STRIDE * id;
    int ch = (int)t[TEX_CHANNELS];
    if ((int)t[TEX_KIND] == TEX_BITMAP && (ch == 2 || ch == 4)) return tex_eval4(tx, id, uv).w;
    return tex_eval1(tx, id, uv);
}

#endif
