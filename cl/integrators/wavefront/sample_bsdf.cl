/* sample_bsdf: next direction, throughput update and Russian roulette.
 * Consumes: the hit queue of this bounce (after hit processing and light contribution).
 * Produces: for survivors the next ray and flags[i] = 1 (compaction then builds the next
 *           bounce's ray queue); paths that end (depth limit, invalid sample, roulette) get
 *           flags[i] = 0 and commit their radiance to frame[film slot]. */
#include "integrators/wavefront/wavefront.h"

/* The path state path_bsdf_take updates (the ray is written afresh). */
static inline PathState sample_bsdf_state(const PathStore* P, int slot, int bounce) {
    PathState ps;
    ps.dir = path_get_dir(P, slot);
    ps.beta = path_get_beta(P, slot);
    ps.rr_scale = path_get_rr_scale(P, slot);
    ps.depth = bounce;
#ifdef AOVS
    ps.flags = path_get_flags(P, slot); /* PATH_ALBEDO_DONE carries on (PATH_KEPT_FLAGS, path.h) */
#endif
    return ps;
}

__kernel void sample_bsdf(SCENE_PARAMS, PATH_PARAMS, QUEUE_ARGS, __global const int* hit_queue,
                          __global uchar* flags, __global float* frame, __global uchar* drop_marks,
                          uint seed, uint first_sample, int max_depth) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_HIT)) return;
    Scene sc = SCENE_INIT;
    PathStore P = PATH_INIT;
    int slot = hit_queue[i];
#ifdef DEVICE_CLASS_GPU
    /* GPUs (-DDEVICE_CLASS_GPU): in steps (docs/gpu.md, "The shading stages in steps"): the textures; the BSDF's
     * sample, its random numbers drawn after the material is read; then, after a step boundary, the next ray from
     * the surface rebuilt and the path state read again (path_bsdf_take), so that neither the shading frame nor the
     * throughput is held in registers across the sampling (92 -> 64 registers on sm_90 in the classroom). The same
     * values as path_sample_bsdf (the random numbers, bsdf_sample, path_bsdf_take). The flag is then stored and the
     * slot read again for the stores' addresses (73 -> 58 registers on the box, before the steps). */
    BsdfSample bs;
    float u_lobe, u_roulette;
    vec2 u;
    bool alive = depth_allows(bounce + 1, max_depth);
    if (alive) {
        BsdfTextures tx = path_hit_textures(&sc, &P, flags, hit_queue, i, &slot); /* in a step of their own */
        Surface s = path_hit_surface(&sc, &P, slot);
        Bsdf b = bsdf_textured(&sc, &s, tx);
        vec3 wi = to_local(s.sh, v3_neg(path_get_dir(&P, slot)));
        rng_bsdf(path_key(&P, &sc, slot, seed, first_sample), bounce, &u_lobe, &u, &u_roulette);
        alive = bsdf_sample(&b, wi, u_lobe, u, &bs);
    }
    slot = queue_reread(flags, hit_queue, i);
    PathState ps = sample_bsdf_state(&P, slot, bounce);
    if (alive) {
        Surface s = path_hit_surface(&sc, &P, slot);
        alive = path_bsdf_take(&s, &bs, u_roulette, &ps);
    }
    flags[i] = alive ? 1 : 0;
    slot = hit_queue[i];
    if (alive) path_store_ray(&P, slot, &ps);
    else film_commit(frame, drop_marks, path_get_film_slot(&P, slot), path_get_L(&P, slot));
#else
    PathState ps = sample_bsdf_state(&P, slot, bounce);
    Surface s = surface_hit(&sc, path_get_hit_prim(&P, slot), path_get_hit_u(&P, slot), path_get_hit_v(&P, slot),
                            ps.dir);
    Bsdf b = bsdf_at(&sc, &s);
    bool alive = path_sample_bsdf(path_key(&P, &sc, slot, seed, first_sample), &s, &b, &ps, max_depth);
    if (alive) path_store_ray(&P, slot, &ps);
    else film_commit(frame, drop_marks, path_get_film_slot(&P, slot), path_get_L(&P, slot));
    flags[i] = alive ? 1 : 0;
#endif
}
