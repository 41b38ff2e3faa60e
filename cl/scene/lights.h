/* lights.h: emitters. Each is LIGHT_STRIDE floats in the `lights` buffer, written
 * by pyclpt/light_buffers.py (offsets mirrored there):
 *
 *   LIGHT_TRIANGLE  an emissive triangle (one-sided area light, Mitsuba `area`)
 *   LIGHT_POINT     an isotropic point light (Mitsuba `point`): a delta light
 *   LIGHT_CONSTANT  the constant environment (Mitsuba `constant`)
 *   LIGHT_ENVMAP    a lat-long environment map (Mitsuba `envmap`; sunsky is baked into one)
 *   LIGHT_DIRECTIONAL  a distant light (Mitsuba `directional`): a delta light
 *   LIGHT_SPOT      a spot light (Mitsuba `spot`): a delta light
 *
 * One emitter is chosen by the cumulative `cdf` column (proportional to an
 * estimate of emitted power). Emitters whose data do not fit a record keep it
 * in `light_data`, at the offset in LIGHT_PRIM:
 *
 *   point light   position (3 floats)
 *   directional   the direction the light travels (3 floats, unit)
 *   spot          position (3), axis (3, unit), cos(cutoff), cos(beam width), cutoff (radians),
 *                 1 / (cutoff - beam width), and with a texture world-to-light (9) and tan(cutoff)
 *                 (SPOT_* offsets below)
 *   envmap        ENV_HEADER floats (below), then the sampling tables: each row's
 *                 alias table (R = H - 1 rows of W entries of 4 floats: env_alias_pick),
 *                 the marginal CDF over cell rows (R floats), solid angle of one cell
 *                 of each row (R), cos(theta) of each texel row (H), then the marginal
 *                 CDF's guide table (G_R + 1 ints; cdf_search_guided). The block starts
 *                 at a multiple of 16 floats, so no alias entry straddles a cache line.
 *
 * Environment-map convention (Mitsuba 3, src/emitters/envmap.cpp): a direction d
 * in the map's frame (to_world^-1 applied; +y is up) has
 *     u = atan2(d.x, -d.z) / 2pi,  v = acos(d.y) / pi,
 * and the radiance is the bilinear interpolation of the texels at
 *     x = u W - 1/2 (periodic),  y = v (H - 1),
 * so texel column i is centred on phi = 2pi (i + 1/2) / W and texel row j (row 0
 * at the top of the image) on theta = pi j / (H - 1): the first and last rows sit
 * on the poles.
 *
 * Importance sampling of an envmap: the sphere is cut into W x (H - 1) cells
 * between texel centres (cell (r, c) spans x in [c, c+1), y in [r, r+1)), each
 * chosen with probability proportional to the mean luminance of its 4 corner
 * texels times its solid angle, then a direction uniform in solid angle inside
 * the cell (uniform in phi and cos theta). The density is piecewise constant:
 * pdf(d) = P(cell of d) / solid angle of that cell, exactly what sampling does,
 * and positive wherever the bilinear radiance is. */
#ifndef PYCLPT_LIGHTS_H
#define PYCLPT_LIGHTS_H

#include "scene/scene.h"

#define LIGHT_STRIDE 12
#define LIGHT_PRIM 0     /* int bits: triangle: leaf-order triangle; point, envmap: offset in light_data */
#define LIGHT_PMF 1      /* probability of choosing this emitter */
#define LIGHT_AREA 2     /* triangle area */
#define LIGHT_RADIANCE 3 /* rgb: triangle and constant environment: radiance; point, spot: intensity (W/sr);
                            directional: irradiance (W/m^2) */
#define LIGHT_CDF 6      /* inclusive cumulative pmf */
#define LIGHT_TYPE 7     /* LIGHT_TRIANGLE ... */
#define LIGHT_TEXTURE 8  /* int bits: triangle: its radiance texture (radiance x texture at the uv); spot: its
                            texture, projected over the cone; -1 none. Read only with
                            -DSCENE_HAS_EMITTER_TEXTURES (pyclpt/buffers/lights.py) */

#define LIGHT_TRIANGLE 0
#define LIGHT_POINT 1
#define LIGHT_CONSTANT 2
#define LIGHT_ENVMAP 3
#define LIGHT_DIRECTIONAL 4
#define LIGHT_SPOT 5

/* spot block in light_data */
#define SPOT_POSITION 0
#define SPOT_AXIS 3
#define SPOT_COS_CUTOFF 6
#define SPOT_COS_BEAM 7
#define SPOT_CUTOFF 8
#define SPOT_INV_TRANSITION 9
#define SPOT_TO_LOCAL 10  /* with a texture: world -> the light's frame (3x3, row-major; +z the axis) */
#define SPOT_UV_FACTOR 19 /* tan(cutoff): uv = 1/2 + d_xy / (2 d_z tan(cutoff)), as Mitsuba's spot */

/* -DSCENE_LIGHTS=mask (pyclpt/buffers/lights.py) lists the emitter kinds a scene has (bit LIGHT_*): only
 * those are compiled (no branch on a kind the scene lacks). Without it every kind is compiled. */
#ifdef SCENE_LIGHTS
#define HAS_LIGHT(t) ((bool)(((SCENE_LIGHTS) >> (t)) & 1))
#else
#define HAS_LIGHT(t) true
#endif

/* An environment sample's radiance, deferred (light_sample_emitter with env_radiance false): where the scene has an
 * environment (an envmap or constant) and no other light at infinity (no directional light), a shadow ray with
 * an infinite tmax is an environment sample, so its radiance can wait until the ray is found unoccluded
 * (path_lit: env_eval along the ray). An envmap's bilinear lookup (and its atan2, acos) is then paid for the
 * samples that reach the sky alone: 3 % of the living room's (docs/benchmarks.md, "The living room's
 * environment"). Scenes without an environment compile as before. */
#if defined(SCENE_LIGHTS) && ((SCENE_LIGHTS) & ((1 << LIGHT_CONSTANT) | (1 << LIGHT_ENVMAP))) && \
    !((SCENE_LIGHTS) & (1 << LIGHT_DIRECTIONAL))
#define ENV_DEFERRED 1
#else
#define ENV_DEFERRED 0
#endif

/* envmap block in light_data */
#define ENV_TO_WORLD 0 /* 3x3 rotation, row-major, map frame -> world */
#define ENV_WIDTH 9    /* texels */
#define ENV_HEIGHT 10
#define ENV_TEXTURE 11 /* texture id of the texels (float RGBA, row 0 at the top) */
#define ENV_SCALE 12   /* Mitsuba's `scale` */
#define ENV_GUIDE_ROWS 13 /* G_R: the marginal CDF's guide intervals (a power of two) */
#define ENV_HEADER 16
#define ENV_ALIAS ENV_HEADER /* the rows' alias tables: entry (r, c) at ENV_ALIAS + 4 (r W + c) */

typedef struct {
    vec3 wi;         /* unit direction from the shading point to the emitter */
    float dist;      /* distance to the sampled point (INF for the environment) */
    vec3 radiance;   /* radiance arriving at the shading point (point light: I / dist^2) */
    float pdf;       /* solid-angle pdf, emitter choice included; for a delta light the choice alone */
    bool delta;      /* a delta light (point, directional, spot): no BSDF sample can hit it, so no MIS */
    int light;       /* the emitter chosen (its index in `lights`) */
} LightSample;

static inline int num_lights(const Scene* sc) { return (int)sc->consts[CONST_NUM_LIGHTS]; }

/* The bin of u in an inclusive CDF that ends at 1: the first index i with u < cdf[i] (the last when none),
 * found by a binary search between the entries of the CDF's guide table for u's interval
 * (pyclpt/buffers/lights.py, cdf_guide): guide[k] is the bin of u = k / g, g a power of two, so u * g is
 * exact and u's bin lies in [guide[k], guide[k + 1]]. The same bin as a search of the whole CDF in a few
 * steps (the envmap's marginal CDF over its rows; each row's cell is its alias table's, env_alias_pick). */
static inline int cdf_search_guided(__global const float* cdf, __global const float* guide, int g, float u) {
    int k = m_imax(m_imin((int)(u * (float)g), g - 1), 0);
    int lo = as_int(guide[k]), hi = as_int(guide[k + 1]);
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (u < cdf[mid]) hi = mid;
        else lo = mid + 1;
    }
    return lo;
}

static inline float cdf_pmf(__global const float* cdf, int i) { return cdf[i] - (i > 0 ? cdf[i - 1] : 0.0f); }

static inline int light_choose(const Scene* sc, float u) {
    int lo = 0, hi = num_lights(sc) - 1;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (u < sc->lights[LIGHT_STRIDE * mid + LIGHT_CDF]) hi = mid;
        else lo = mid + 1;
    }
    return lo;
}

/* Solid-angle pdf that light sampling gives the point y on emissive triangle `light`,
 * seen from distance dist with cosine cos_l at the emitter. */
static inline float light_pdf_area(const Scene* sc, int light, float dist, float cos_l) {
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    if (cos_l <= 0.0f) return 0.0f;
    return l[LIGHT_PMF] * dist * dist / (l[LIGHT_AREA] * cos_l);
}

/* ---- environment map -------------------------------------------------------- */

static inline vec3 env_to_local(__global const float* e, vec3 d) { return mat3_tmul(e, d); }

static inline vec3 env_to_world(__global const float* e, vec3 v) { return mat3_mul(e, v); }

/* Continuous texel coordinates (x in [0, W), y in [0, H - 1]) of a unit direction in the map's frame. */
static inline vec2 env_texel_coords(__global const float* e, vec3 d) {
    float w = e[ENV_WIDTH], h = e[ENV_HEIGHT];
    float u = m_atan2(d.x, -d.z) * INV_2PI_F;
    float v = m_acos(m_clamp(d.y, -1.0f, 1.0f)) * INV_PI_F;
    float x = u * w - 0.5f;
    x -= w * m_floor(x / w);
    if (!(x >= 0.0f && x < w)) x = 0.0f; /* rounding onto w, or NaN */
    float y = m_clamp(v * (h - 1.0f), 0.0f, h - 1.0f);
    if (!(y >= 0.0f)) y = 0.0f;
    return v2(x, y);
}

/* The bilinear cell of texel coordinates xy: columns i0, i1 (periodic), rows j0, j0 + 1, fractions f. */
typedef struct {
    int i0, i1, j0;
    float fx, fy;
} EnvCell;

static inline EnvCell env_cell(__global const float* e, vec2 xy) {
    int w = (int)e[ENV_WIDTH], h = (int)e[ENV_HEIGHT];
    EnvCell c;
    c.i0 = m_imin((int)xy.x, w - 1);
    c.j0 = m_imin((int)xy.y, h - 2);
    c.fx = xy.x - (float)c.i0;
    c.fy = xy.y - (float)c.j0;
    c.i1 = c.i0 + 1 == w ? 0 : c.i0 + 1;
    return c;
}

/* The map's radiance (scale applied) at texel coordinates xy: bilinear, periodic in x. */
static inline vec3 env_lookup(const Scene* sc, __global const float* e, vec2 xy) {
    EnvCell c = env_cell(e, xy);
    __global const float* t = sc->tex.info + TEX_STRIDE * (int)e[ENV_TEXTURE];
    vec4 c00 = tex_texel(&sc->tex, t, c.i0, c.j0), c10 = tex_texel(&sc->tex, t, c.i1, c.j0);
    vec4 c01 = tex_texel(&sc->tex, t, c.i0, c.j0 + 1), c11 = tex_texel(&sc->tex, t, c.i1, c.j0 + 1);
    return v3_scale(v4_xyz(tex_bilerp(c00, c10, c01, c11, c.fx, c.fy)), e[ENV_SCALE]);
}

/* The four texels env_lookup blends at xy (indices into the texels of the map's texture, as TexTaps
 * in texture.h) and their bilinear weights, the map's scale not included: for gradients. */
static inline TexTaps env_taps(const Scene* sc, __global const float* e, vec2 xy) {
    EnvCell c = env_cell(e, xy);
    int w = (int)e[ENV_WIDTH];
    __global const float* t = sc->tex.info + TEX_STRIDE * (int)e[ENV_TEXTURE];
    TexTaps k;
    k.n = 4;
    k.is_float = (int)t[TEX_FORMAT] == TEXF_FLOAT;
    int base = as_int(t[TEX_OFFSET]);
    k.at[0] = base + c.j0 * w + c.i0;
    k.at[1] = base + c.j0 * w + c.i1;
    k.at[2] = base + (c.j0 + 1) * w + c.i0;
    k.at[3] = base + (c.j0 + 1) * w + c.i1;
    k.w[0] = (1.0f - c.fx) * (1.0f - c.fy);
    k.w[1] = c.fx * (1.0f - c.fy);
    k.w[2] = (1.0f - c.fx) * c.fy;
    k.w[3] = c.fx * c.fy;
    return k;
}

/* The marginal CDF and the tables after it (the block's layout above). */
typedef struct {
    __global const float* alias;    /* R x W entries of 4 floats */
    __global const float* marginal; /* R */
    __global const float* cell_omega; /* R */
    __global const float* row_cos;  /* H */
    __global const float* guide;    /* G_R + 1 ints */
    int w, rows;
} EnvTables;

static inline EnvTables env_tables(__global const float* e) {
    EnvTables t;
    t.w = (int)e[ENV_WIDTH];
    t.rows = (int)e[ENV_HEIGHT] - 1;
    t.alias = e + ENV_ALIAS;
    t.marginal = t.alias + 4 * t.rows * t.w;
    t.cell_omega = t.marginal + t.rows;
    t.row_cos = t.cell_omega + t.rows;
    t.guide = t.row_cos + t.rows + 1;
    return t;
}

/* Solid-angle density with which env_sample produces the map-frame direction at xy. */
static inline float env_pdf_at(__global const float* e, vec2 xy) {
    EnvTables t = env_tables(e);
    int c = m_imin((int)xy.x, t.w - 1), r = m_imin((int)xy.y, t.rows - 1);
    float omega = t.cell_omega[r];
    if (!(omega > 0.0f)) return 0.0f;
    return cdf_pmf(t.marginal, r) * t.alias[4 * (r * t.w + c) + 2] / omega;
}

/* Inverse of a cdf choice: where u falls inside bin i, in [0, 1). */
static inline float cdf_remap(__global const float* cdf, int i, float u) {
    float lo = i > 0 ? cdf[i - 1] : 0.0f;
    float p = cdf[i] - lo;
    float t = p > 0.0f ? (u - lo) / p : 0.5f;
    return m_clamp(t, 0.0f, 0x1.fffffep-1f);
}

/* A cell of a row of n by its alias table (Walker; pyclpt/buffers/lights.py alias_tables): u n = i + f picks
 * cell i where f < q (entry i's first float), else entry i's alias. Entry i is (q, alias bits, pmf of cell i,
 * pmf of the alias): one 16-byte read, where the row's CDF search read a guide entry and a line of the CDF.
 * Returns the cell, with its pmf and where f fell inside the part of [0, 1) that picked it (*u_in, in [0, 1)). */
static inline int env_alias_pick(__global const float* row, int n, float u, float* pmf, float* u_in) {
    float x = u * (float)n;
    int i = m_imin((int)x, n - 1);
    float f = m_min(x - (float)i, 0x1.fffffep-1f);
    __global const float* a = row + 4 * i;
    float q = a[0];
    float t;
    int cell;
    if (f < q) {
        cell = i;
        *pmf = a[2];
        t = f / q;
    } else {
        cell = as_int(a[1]);
        *pmf = a[3];
        t = q < 1.0f ? (f - q) / (1.0f - q) : 0.5f;
    }
    *u_in = m_clamp(t, 0.0f, 0x1.fffffep-1f);
    return cell;
}

/* Sample a world direction from the map: returns it with its radiance and solid-angle pdf. */
static inline vec3 env_sample(const Scene* sc, __global const float* e, vec2 u, vec3* radiance,
                                float* pdf, bool want_radiance) {
    EnvTables t = env_tables(e);
    int r = cdf_search_guided(t.marginal, t.guide, (int)e[ENV_GUIDE_ROWS], u.x);
    float ur = cdf_remap(t.marginal, r, u.x);
    float pmf_c, uc;
    int c = env_alias_pick(t.alias + 4 * r * t.w, t.w, u.y, &pmf_c, &uc);
    float cos_t = t.row_cos[r] + ur * (t.row_cos[r + 1] - t.row_cos[r]);
    float sin_t = m_sqrt(m_max(0.0f, 1.0f - cos_t * cos_t));
    float phi = (2.0f * PI_F) * (((float)c + 0.5f + uc) / (float)t.w);
    float cos_phi, sin_phi = m_sincos(phi, &cos_phi);
    vec3 d = v3(sin_phi * sin_t, cos_t, -cos_phi * sin_t);
    float omega = t.cell_omega[r];
    *pdf = omega > 0.0f ? cdf_pmf(t.marginal, r) * pmf_c / omega : 0.0f;
    *radiance = want_radiance ? env_lookup(sc, e, env_texel_coords(e, d)) : v3_splat(1.0f);
    return m_normalize(env_to_world(e, d));
}

/* Radiance of the environment along the world direction dir (zero without one); with want_pdf,
 * *pdf is the solid-angle density with which light_sample produces dir, emitter choice included. */
static inline GPU_INLINE vec3 env_eval(const Scene* sc, vec3 dir, bool want_pdf, float* pdf) {
    *pdf = 0.0f;
#if defined(SCENE_LIGHTS) && !((SCENE_LIGHTS) & ((1 << LIGHT_CONSTANT) | (1 << LIGHT_ENVMAP)))
    return v3_splat(0.0f); /* no environment in the scene */
#endif
    int env = (int)sc->consts[CONST_ENV_LIGHT];
    if (env < 0) return v3_splat(0.0f);
    /* (env > 0 ? env : 0) is env here; it keeps the record's address in the buffer even where a compiler
     * hoists the loads below above the test (Intel's CPU OpenCL vectoriser does, in the megakernel,
     * and read lights[-8] as an address 16 GiB past the buffer: docs/devices.md). */
    __global const float* l = sc->lights + LIGHT_STRIDE * (env > 0 ? env : 0);
    if (!HAS_LIGHT(LIGHT_ENVMAP) || (int)l[LIGHT_TYPE] == LIGHT_CONSTANT) {
        if (want_pdf) *pdf = l[LIGHT_PMF] * UNIFORM_SPHERE_PDF;
        return rgb_at(l + LIGHT_RADIANCE, sc->unit);
    }
    __global const float* e = sc->light_data + as_int(l[LIGHT_PRIM]);
    vec2 xy = env_texel_coords(e, env_to_local(e, dir));
    if (want_pdf) *pdf = l[LIGHT_PMF] * env_pdf_at(e, xy);
    return env_lookup(sc, e, xy);
}

/* ---- emitter textures ----------------------------------------------------------- */

/* The emitter's texture at uv (pyclpt's v-up convention), or 1 (one compare) without one. */
static inline vec3 light_texture(const Scene* sc, __global const float* l, vec2 uv) {
#ifdef SCENE_HAS_EMITTER_TEXTURES
    int t = as_int(l[LIGHT_TEXTURE]);
    if (t >= 0) return tex_eval(&sc->tex, t, uv);
#endif
    return v3_splat(1.0f);
}

/* A spot light's texture in the direction wi (from the shading point to the light). */
static inline vec3 spot_texture(const Scene* sc, __global const float* l, __global const float* s, vec3 wi) {
#ifdef SCENE_HAS_EMITTER_TEXTURES
    if (as_int(l[LIGHT_TEXTURE]) < 0) return v3_splat(1.0f);
    vec3 d = mat3_mul(s + SPOT_TO_LOCAL, v3_neg(wi));
    float k = 0.5f / (d.z * s[SPOT_UV_FACTOR]);
    /* Mitsuba's uv (v down) -> pyclpt's (v up) */
    return light_texture(sc, l, v2(0.5f + d.x * k, 0.5f - d.y * k));
#else
    return v3_splat(1.0f);
#endif
}

/* ---- sampling any emitter ----------------------------------------------------- */

/* Sample a point on emitter `id` as seen from p (u: a 2D uniform; a delta light needs none); ls->pdf the
 * probability of choosing it times the point's density. False when the sample carries nothing. With
 * env_radiance false an environment sample's radiance is 1, to be looked up later (ENV_DEFERRED). */
static inline bool light_sample_emitter(const Scene* sc, int id, vec3 p, vec2 u, LightSample* ls, bool env_radiance) {
    __global const float* l = sc->lights + LIGHT_STRIDE * id;
    int type = (int)l[LIGHT_TYPE];
    ls->delta = false;
    ls->light = id;
    if (HAS_LIGHT(LIGHT_CONSTANT) && type == LIGHT_CONSTANT) {
        ls->wi = square_to_uniform_sphere(u);
        ls->dist = INF_F;
        ls->radiance = env_radiance ? rgb_at(l + LIGHT_RADIANCE, sc->unit) : v3_splat(1.0f);
        ls->pdf = l[LIGHT_PMF] * UNIFORM_SPHERE_PDF;
        return ls->pdf > 0.0f;
    }
    if (HAS_LIGHT(LIGHT_ENVMAP) && type == LIGHT_ENVMAP) {
        float pdf;
        ls->wi = env_sample(sc, sc->light_data + as_int(l[LIGHT_PRIM]), u, &ls->radiance, &pdf, env_radiance);
        ls->dist = INF_F;
        ls->pdf = l[LIGHT_PMF] * pdf;
        return ls->pdf > 0.0f;
    }
    if (HAS_LIGHT(LIGHT_DIRECTIONAL) && type == LIGHT_DIRECTIONAL) {
        ls->wi = v3_neg(rgb_at(sc->light_data + as_int(l[LIGHT_PRIM]), sc->unit));
        ls->dist = INF_F;
        ls->radiance = rgb_at(l + LIGHT_RADIANCE, sc->unit);
        ls->pdf = l[LIGHT_PMF];
        ls->delta = true;
        return ls->pdf > 0.0f;
    }
    if (HAS_LIGHT(LIGHT_SPOT) && type == LIGHT_SPOT) {
        __global const float* s = sc->light_data + as_int(l[LIGHT_PRIM]);
        vec3 d = v3_sub(rgb_at(s + SPOT_POSITION, sc->unit), p);
        float dist2 = m_dot(d, d);
        if (!(dist2 > 0.0f)) return false;
        ls->dist = m_sqrt(dist2);
        ls->wi = v3_divs(d, ls->dist);
        /* Mitsuba's falloff: 1 inside the beam, linear in angle to 0 at the cutoff */
        float cos_t = -m_dot(ls->wi, rgb_at(s + SPOT_AXIS, sc->unit));
        float falloff = cos_t >= s[SPOT_COS_BEAM] ? 1.0f
                                                  : (s[SPOT_CUTOFF] - m_acos(m_clamp(cos_t, -1.0f, 1.0f))) * s[SPOT_INV_TRANSITION];
        if (!(cos_t > s[SPOT_COS_CUTOFF] && falloff > 0.0f)) return false;
        ls->radiance = v3_scale(v3_mul(rgb_at(l + LIGHT_RADIANCE, sc->unit), spot_texture(sc, l, s, ls->wi)),
                                falloff / dist2);
        ls->pdf = l[LIGHT_PMF];
        ls->delta = true;
        return ls->pdf > 0.0f;
    }
    if (HAS_LIGHT(LIGHT_POINT) && type == LIGHT_POINT) {
        __global const float* pos = sc->light_data + as_int(l[LIGHT_PRIM]);
        vec3 d = v3_sub(rgb_at(pos, sc->unit), p);
        float dist2 = m_dot(d, d);
        if (!(dist2 > 0.0f)) return false;
        ls->dist = m_sqrt(dist2);
        ls->wi = v3_divs(d, ls->dist);
        ls->radiance = v3_divs(rgb_at(l + LIGHT_RADIANCE, sc->unit), dist2);
        ls->pdf = l[LIGHT_PMF];
        ls->delta = true;
        return ls->pdf > 0.0f;
    }
    int prim = as_int(l[LIGHT_PRIM]);
    __global const float* t = sc->tris + 9 * prim;
    vec3 v0 = rgb_at(t, sc->unit), e1 = rgb_at(t + 3, sc->unit), e2 = rgb_at(t + 6, sc->unit);
    vec2 b = square_to_triangle(u);
    vec3 y = v3_add(v3_add(v0, v3_scale(e1, b.x)), v3_scale(e2, b.y));
    vec3 ng = m_normalize(m_cross(e1, e2));
    vec3 d = v3_sub(y, p);
    float dist2 = m_dot(d, d);
    if (!(dist2 > 0.0f)) return false;
    ls->dist = m_sqrt(dist2);
    ls->wi = v3_divs(d, ls->dist);
    float cos_l = -m_dot(ls->wi, ng);
    ls->pdf = light_pdf_area(sc, id, ls->dist, cos_l);
    ls->radiance = rgb_at(l + LIGHT_RADIANCE, sc->unit);
#ifdef SCENE_HAS_EMITTER_TEXTURES
    ls->radiance = v3_mul(ls->radiance, light_texture(sc, l, tri_uv(sc->tri_vidx, sc->vuvs, prim,
                                                                    sc->tri_info[2 * prim], b.x, b.y)));
#endif
    return ls->pdf > 0.0f;
}

/* light_sample_emitter with every radiance looked up. */
static inline bool light_sample_id(const Scene* sc, int id, vec3 p, vec2 u, LightSample* ls) {
    return light_sample_emitter(sc, id, p, u, ls, true);
}

/* Sample an emitter and a point on it as seen from p; false when the sample carries nothing. With env_radiance
 * false an environment sample's radiance is left for later (ENV_DEFERRED, path_lit). */
static inline bool light_sample(const Scene* sc, vec3 p, float u_select, vec2 u, LightSample* ls, bool env_radiance) {
    if (num_lights(sc) == 0) return false;
    return light_sample_emitter(sc, light_choose(sc, u_select), p, u, ls, env_radiance);
}

/* Radiance an emissive triangle sends along -dir (one-sided: front faces only) from its point at uv. */
static inline vec3 light_emitted(const Scene* sc, int light, vec3 ng, vec3 dir, vec2 uv) {
    if (light < 0 || m_dot(ng, dir) >= 0.0f) return v3_splat(0.0f);
    __global const float* l = sc->lights + LIGHT_STRIDE * light;
    return v3_mul(rgb_at(l + LIGHT_RADIANCE, sc->unit), light_texture(sc, l, uv));
}

#endif
