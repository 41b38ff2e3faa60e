/* forward: forward-mode derivative of the image along one direction in parameter space.
 *
 * Consumes: the film slots [offset, offset + count) of a batch of frames starting at sample
 *           first_sample (as the megakernel's), and the tangent: a direction in parameter space laid
 *           out as the scene buffers (params.h: GRAD_PARAMS, read only here).
 * Produces: each path's derivative dL along the tangent in frame[f] (3 floats; the film averages
 *           them into the gradient image), 0 for a NaN/inf one, which adds 1 to drop_marks[f].
 *
 * One work-item per path: the estimator of path.h, carrying next to the throughput beta its tangent
 * dbeta, and next to each contribution C = beta * (factors) its tangent
 *   dC = dbeta * (factors) + beta * d(factors),
 * where d(factors) is the tangent of an emitter's radiance (params.h) or of a BSDF value (df / f,
 * bsdf_derivative.h). Sampling decisions (pdfs, MIS weights, Russian roulette) are held fixed. */
#include "gradients/bsdf_derivative.h"
#ifdef GRAD_GEOMETRY
#include "gradients/geometry.h"

/* The log-derivative (per channel) of a visible light sample's contribution at vertex gc (reached along
 * dir_in from gb, r_bc away) from moving geometry (geometry.h; backward.cl's geo_nee in forward mode). */
static inline vec3 geo_nee_tangent(const Scene* sc, const Grads* tg, RngKey key, int depth, const Surface* s,
                                   const Bsdf* b, const NeeSample* n, vec3 dir_in, const GeoVertex* gb,
                                   const GeoVertex* gc, float r_bc) {
    vec3 wi_w = v3_neg(dir_in), dwi = v3_neg(gc->dd), dwo = v3_splat(0.0f); /* dd: the camera ray's turn */
    if (gc->kind == GEO_ATTACHED && r_bc > 0.0f) dwi = geo_direction_tangent(gc, gb, wi_w, r_bc);
    float r = n->ls.dist, scalar = 0.0f;
    GeoVertex gy;
    if (geo_light_end(sc, key, depth, n, gc, &gy)) {
        geo_motion(sc, tg, &gy);
        dwo = geo_direction_tangent(gc, &gy, n->ls.wi, r);
        if (gy.kind == GEO_ATTACHED) {
            scalar = geo_area_segment_tangent(gc, &gy, n->ls.wi, r, dwo); /* cosine, 1/r^2, area */
        } else { /* a point: 1 / r^2, and a spot's falloff F(c), c = -wi . axis */
            vec3 axis;
            float k = geo_spot_falloff(sc, n->ls.light, n->ls.wi, &axis);
            vec3 daxis = tangent3(tg->lightpos + GEO_LIGHT_STRIDE * n->ls.light + 3);
            scalar = -2.0f * m_dot(n->ls.wi, v3_sub(gy.dx, gc->dx)) / r
                     - k * (m_dot(dwo, axis) + m_dot(n->ls.wi, daxis));
        }
    }
    vec3 df = geo_bsdf_tangent(b, to_local(s->sh, wi_w), n->wo, geo_local_tangent(s->sh, wi_w, dwi, gc->ds),
                               geo_local_tangent(s->sh, n->ls.wi, dwo, gc->ds));
    df = v3_add(df, geo_bsdf_bary_tangent(sc, s, gc, to_local(s->sh, wi_w), n->wo)); /* its textures sliding */
    return v3_add(safe_div3(df, n->f), v3_splat(scalar));
}
#endif

__kernel SCALAR_KERNEL void forward(SCENE_PARAMS, __global float* frame, __global uchar* drop_marks, uint seed,
                                    uint first_sample, int offset, int count, int max_depth, GRAD_PARAMS) {
    int i = get_global_id(0);
    if (i >= count) return;
    Scene sc = SCENE_INIT;
    Grads tg = GRAD_INIT;
    int f = offset + i;
    int pixel = film_pixel(&sc, f);
    RngKey key = rng_key(seed, (uint)pixel, film_sample(&sc, first_sample, f));
    PathState ps;
    camera_path(&sc, key, pixel, &ps);
    vec3 dbeta = v3_splat(0.0f), dL = v3_splat(0.0f);
#ifdef GRAD_GEOMETRY
    /* gb: the vertex that made the ray (at first the camera); an area-form segment's BSDF Jacobian in wo's local
       coordinates waits for its far end (seg_jac, in gb's frame seg_frame) */
    GeoVertex gb = geo_fixed(ps.org), gc = gb;
    bool seg_area = false;
    float r_bc = 0.0f;
    vec3 seg_jac[3];
    Frame seg_frame = frame_from(v3(0.0f, 0.0f, 1.0f));
#endif
    if (max_depth != 0) {
        for (;;) {
            Hit hit;
            if (!scene_closest(&sc, key, ps.depth, ps.org, ps.dir, &hit)) {
                bool mis = !(ps.flags & PATH_PREV_DELTA);
                float light_pdf;
                vec3 le = env_eval(&sc, ps.dir, mis, &light_pdf);
                if (!v3_is_zero(le)) {
                    float w = mis ? power_heuristic(ps.prev_pdf, light_pdf) : 1.0f;
                    vec3 dle = tangent_emitter(&sc, &tg, env_light(&sc), ps.dir);
                    dL = v3_add(dL, v3_scale(v3_add(v3_mul(dbeta, le), v3_mul(ps.beta, dle)), w));
                }
                break;
            }
            Surface s = surface_hit(&sc, hit.prim, hit.u, hit.v, ps.dir);
#ifdef GRAD_GEOMETRY
            Bsdf b = bsdf_at(&sc, &s); /* here already: a delta vertex is a moving mirror's or held still */
            {
                int mirror;
                int kind = geo_hit_kind(&b, seg_area, &gb, &mirror);
                gc = geo_on_triangle(&sc, hit.prim, hit.u, hit.v, s.p, kind, ps.dir);
                gc.mirror = mirror;
                geo_motion(&sc, &tg, &gc);
#ifdef GRAD_CAMERA
                if (ps.depth == 0) {
                    geo_camera_hit(&sc, &gc, camera_film_position(&sc, key, pixel), gb.p);
                    geo_camera_motion(&sc, &tg, &gc);
                }
#endif
                geo_mirror_ray(&gc, &gb); /* on the ray a moving mirror reflected: its motion */
                geo_ray_motion(&sc, &gc, &gb);
                geo_shading_motion(&sc, &tg, &gc);
                r_bc = m_length(v3_sub(gc.p, gb.p));
                if (seg_area && r_bc > 0.0f) { /* the segment's factors, now that its far end is known */
                    vec3 dw = geo_direction_tangent(&gb, &gc, ps.dir, r_bc), dwl = to_local(seg_frame, dw);
                    vec3 dlog = v3_add(v3_add(v3_scale(seg_jac[0], dwl.x), v3_scale(seg_jac[1], dwl.y)),
                                       v3_scale(seg_jac[2], dwl.z));
                    dlog = v3_add(dlog, v3_splat(geo_area_segment_tangent(&gb, &gc, ps.dir, r_bc, dw)));
                    dbeta = v3_add(dbeta, v3_mul(ps.beta, dlog));
                }
            }
#endif
            vec3 le = light_emitted(&sc, s.light, s.ng, ps.dir, s.uv);
            if (!v3_is_zero(le)) {
                float w = 1.0f;
                if (!(ps.flags & PATH_PREV_DELTA))
                    w = power_heuristic(ps.prev_pdf, light_pdf_area(&sc, s.light, hit.t, -m_dot(s.ng, ps.dir)));
                vec3 dle = tangent_emitter(&sc, &tg, s.light, ps.dir);
                dL = v3_add(dL, v3_scale(v3_add(v3_mul(dbeta, le), v3_mul(ps.beta, dle)), w));
            }
            if (!depth_allows(ps.depth + 1, max_depth)) break;
#ifndef GRAD_GEOMETRY
            Bsdf b = bsdf_at(&sc, &s);
#endif
            BsdfTangent db = tangent_bsdf(&sc, &tg, &s);
            vec3 wi = to_local(s.sh, v3_neg(ps.dir));
            NeeSample n;
            if (path_nee(&sc, key, &s, &b, &ps, &n) && !scene_occluded(&sc, key, ps.depth, n.sr.org, n.sr.dir, n.sr.tmax)) {
                /* C = beta f Le weight */
                vec3 df_f = bsdf_tangent_ratio(&tg, &s, &b, wi, n.wo, false, &db);
                vec3 dle = tangent_emitter(&sc, &tg, n.ls.light, n.ls.wi);
                vec3 unit = v3_scale(n.f, n.weight); /* C / (beta Le) */
                vec3 dC = v3_add(v3_mul(v3_add(dbeta, v3_mul(ps.beta, df_f)), v3_mul(unit, n.ls.radiance)),
                                 v3_mul(v3_mul(ps.beta, unit), dle));
#ifdef GRAD_GEOMETRY
                dC = v3_add(dC, v3_mul(n.sr.contrib, geo_nee_tangent(&sc, &tg, key, ps.depth, &s, &b, &n, ps.dir, &gb,
                                                                      &gc, r_bc)));
#endif
                dL = v3_add(dL, dC);
            }
            vec3 beta = ps.beta;
#ifdef GRAD_GEOMETRY
            vec3 dir_in = ps.dir;
#endif
            if (!path_sample_bsdf(key, &s, &b, &ps, max_depth)) break;
            /* beta' = beta * weight / q: dbeta' = dbeta * (beta' / beta) + beta' * df / f */
            vec3 df_f = bsdf_tangent_ratio(&tg, &s, &b, wi, to_local(s.sh, ps.dir), (ps.flags & PATH_PREV_DELTA) != 0, &db);
            dbeta = v3_add(v3_mul(dbeta, safe_div3(ps.beta, beta)), v3_mul(ps.beta, df_f));
#ifdef GRAD_GEOMETRY
            seg_area = !(ps.flags & PATH_PREV_DELTA);
            if (gc.mirror) dbeta = v3_add(dbeta, v3_mul(ps.beta, geo_fresnel_tangent(&sc, &b, &gc))); /* F turns */
            if (seg_area) { /* the BSDF's derivative through wi and the frame now, through wo when the hit is known */
                vec3 wi_w = v3_neg(dir_in), wo = to_local(s.sh, ps.dir);
                vec3 dwi = gc.kind == GEO_ATTACHED && r_bc > 0.0f ? geo_direction_tangent(&gc, &gb, wi_w, r_bc)
                                                                  : v3_neg(gc.dd);
                float pdf;
                vec3 f = bsdf_eval(&b, wi, wo, &pdf);
                vec3 df = geo_bsdf_tangent(&b, wi, wo, geo_local_tangent(s.sh, wi_w, dwi, gc.ds),
                                           geo_local_tangent(s.sh, ps.dir, v3_splat(0.0f), gc.ds));
                df = v3_add(df, geo_bsdf_bary_tangent(&sc, &s, &gc, wi, wo)); /* its textures sliding */
                dbeta = v3_add(dbeta, v3_mul(ps.beta, safe_div3(df, f)));
                geo_bsdf_wo_jacobian(&b, wi, wo, f, seg_jac);
                seg_frame = s.sh;
            }
            gb = gc;
#endif
        }
    }
    film_commit(frame, drop_marks, f, dL);
}
