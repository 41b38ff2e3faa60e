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
            vec3 le = light_emitted(&sc, s.light, s.ng, ps.dir, s.uv);
            if (!v3_is_zero(le)) {
                float w = 1.0f;
                if (!(ps.flags & PATH_PREV_DELTA))
                    w = power_heuristic(ps.prev_pdf, light_pdf_area(&sc, s.light, hit.t, -m_dot(s.ng, ps.dir)));
                vec3 dle = tangent_emitter(&sc, &tg, s.light, ps.dir);
                dL = v3_add(dL, v3_scale(v3_add(v3_mul(dbeta, le), v3_mul(ps.beta, dle)), w));
            }
            if (!depth_allows(ps.depth + 1, max_depth)) break;
            Bsdf b = bsdf_at(&sc, &s);
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
                dL = v3_add(dL, dC);
            }
            vec3 beta = ps.beta;
            if (!path_sample_bsdf(key, &s, &b, &ps, max_depth)) break;
            /* beta' = beta * weight / q: dbeta' = dbeta * (beta' / beta) + beta' * df / f */
            vec3 df_f = bsdf_tangent_ratio(&tg, &s, &b, wi, to_local(s.sh, ps.dir), (ps.flags & PATH_PREV_DELTA) != 0, &db);
            dbeta = v3_add(v3_mul(dbeta, safe_div3(ps.beta, beta)), v3_mul(ps.beta, df_f));
        }
    }
    film_commit(frame, drop_marks, f, dL);
}
