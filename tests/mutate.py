"""Mutation check of the kernel library: plant one plausible bug at a time and see the tests fail.

Each mutant is one line of cl/ (or of the host code that builds the kernels' tables, pyclpt/),
found by its text rather than by file and line number, so that the list survives files being
split or moved: ``original`` must occur on exactly one line of the tree (or, with ``after``, on
the first line after the one unique line holding ``after``, in the same file). The line gets
``original`` replaced by ``mutated``; then the pytest selection named with the mutant runs, and
the mutant is *killed* when it fails.

Everything happens in a copy of the source tree in a temporary folder (without .git and .venv):
the tree this script lives in is never written to. The copy's tests run with the copy's pyclpt
first on sys.path (checked: ``pyclpt.__file__`` and ``cl_dir()`` must point into the copy), with
a private PoCL kernel cache seeded from the user's, so that mutated kernels never land in it.

    python tests/mutate.py                 # every mutant; a table, the kill rate, exit 1 if any survived
    python tests/mutate.py --list          # the mutants and where their lines are now
    python tests/mutate.py --only mis roulette   # mutants whose name contains any of these
    python tests/mutate.py --only eta --tests tests/test_render.py   # other tests against some mutants
    python tests/mutate.py --json out.json --markdown out.md   # also write the results

Not named test_*.py: pytest does not collect it. See docs/testing.md.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ROOTS = {"cl": ("cl", (".h", ".cl")), "host": ("pyclpt", (".py",))}
IGNORE = shutil.ignore_patterns(".git", ".venv", "venv", "__pycache__", "*.egg-info", ".pytest_cache", "build",
                                ".ruff_cache", "*.pyc")


@dataclass(frozen=True)
class Mutant:
    name: str
    original: str  # text on the line to mutate (a substring of it)
    mutated: str  # what replaces ``original`` on that line
    tests: tuple[str, ...]  # pytest node ids (files or file::test) that should kill it
    why: str  # the bug it plants
    root: str = "cl"  # "cl" (kernels) or "host" (pyclpt/)
    after: str | None = None  # disambiguation: the first line holding ``original`` after this unique line
    issue: bool = False  # one of the mutants of issue 16 (must be killed)


T_INST = "tests/test_instance_gradients.py"
T_ANALYTIC_QUAD = "tests/test_analytic.py::test_direct_light_from_a_quad_matches_the_form_factor"
T_ANALYTIC_SKY = "tests/test_analytic.py::test_quad_light_and_sky_share_the_floor"
T_FRONT_ONLY = "tests/test_analytic.py::test_area_lights_emit_from_their_front_only"
T_BACK_BLACK = "tests/test_analytic.py::test_camera_behind_an_area_light_sees_its_back_black"
T_GLASS_INSIDE = "tests/test_analytic.py::test_camera_inside_glass_sphere_sees_eta_squared"
T_FURNACE = "tests/test_render.py::test_interior_furnace"
T_GPU_STEPS = "tests/test_gpu_layout.py::test_gpu_shading_steps_give_the_megakernels_image_and_gbuffer"
T_PIPELINED = "tests/test_wavefront.py::test_pipelined_schedule_waits_on_no_bounce"
T_SIMT_REGENERATION = "tests/test_simt.py::test_regeneration_keeps_the_pool_full_in_slot_order"
T_SIMT_GPU_BUILD = "tests/test_simt.py::test_the_gpu_builds_compaction_and_schedule"
T_ROULETTE = "tests/test_wavefront.py::test_roulette_keeps_paths_by_their_throughput_relative_to_the_first_bounce"
T_SKY_CUBE = "tests/test_render.py::test_diffuse_cube_under_constant_sky"
T_GRAD_FD = "tests/test_gradients.py::test_backward_matches_finite_differences"
T_UV_TRANSFORMS = "tests/test_plugins.py::test_plugin_matches_mitsuba[uv-transforms]"
T_EMITTER_TEXTURES = "tests/test_plugins.py::test_plugin_matches_mitsuba[emitter-textures]"
T_STAGE_DEFINES = "tests/test_gpu_isa.py::test_each_stage_is_built_with_the_defines_it_reads"
T_RFILTER_WAVEFRONT = "tests/test_rfilter.py::test_megakernel_equals_wavefront_and_gradient_primal"

MUTANTS: list[Mutant] = [
    # ---- the mutants of issue 16: each must be killed -------------------------------------------
    Mutant("balance-heuristic", "float a2 = pdf_a * pdf_a, b2 = pdf_b * pdf_b;", "float a2 = pdf_a, b2 = pdf_b;",
           ("tests/test_sampling.py::test_power_heuristic",),
           "the balance heuristic in place of the power heuristic (unbiased: only the unit test sees it)",
           issue=True),
    Mutant("mis-swapped-light-sample", "power_heuristic(n->ls.pdf, bsdf_pdf)", "power_heuristic(bsdf_pdf, n->ls.pdf)",
           (T_ANALYTIC_QUAD,), "the power heuristic's arguments swapped for the light sample", issue=True),
    Mutant("mis-swapped-emission-hit", "w = power_heuristic(ps->prev_pdf, light_pdf);",
           "w = power_heuristic(light_pdf, ps->prev_pdf);", (T_ANALYTIC_QUAD,),
           "the power heuristic's arguments swapped for emission found by a BSDF sample", issue=True,
           after="static inline void path_hit_emission("),
    Mutant("triangle-accepts-t-zero", "if (!(t > 0.0f && adet > 0.0f && t < tmax * adet)) return false;",
           "if (!(t >= 0.0f && adet > 0.0f && t < tmax * adet)) return false;",
           ("tests/test_bvh.py::test_ray_starting_on_a_triangle_ignores_it",),
           "the triangle test accepts t == 0 (a ray hits the surface it starts on)", issue=True),
    Mutant("roulette-from-bounce-1", "if (ps->depth >= RR_DEPTH) {", "if (ps->depth >= 1) {",
           ("tests/test_wavefront.py::test_no_path_ends_by_roulette_before_rr_depth",),
           "Russian roulette from bounce 1 instead of RR_DEPTH (unbiased: only the queue counts see it)",
           issue=True),
    Mutant("philox-9-rounds", "for (int r = 0; r < 10; ++r) {", "for (int r = 0; r < 9; ++r) {",
           ("tests/test_sampling.py::test_philox_known_answers",), "Philox4x32 with 9 rounds instead of 10",
           issue=True),
    Mutant("triangle-sampling-no-sqrt", "float su = m_sqrt(u.x);", "float su = u.x;",
           ("tests/test_sampling.py::test_triangle_chi2", T_ANALYTIC_QUAD),
           "uniform triangle sampling without its square root (points crowd a vertex)", issue=True),
    Mutant("area-light-emits-both-sides", "if (light < 0 || m_dot(ng, dir) >= 0.0f) return v3_splat(0.0f);",
           "if (light < 0) return v3_splat(0.0f);", (T_FRONT_ONLY, T_BACK_BLACK),
           "area lights emit from their back too (emission found by rays)", issue=True),
    Mutant("area-light-sampled-both-sides", "if (cos_l <= 0.0f) return 0.0f;", "cos_l = m_abs(cos_l);",
           (T_FRONT_ONLY,), "light sampling accepts points seen from the back of an area light", issue=True),
    Mutant("fresnel-eta-inverted", "float eta_it = outside ? eta : 1.0f / eta;",
           "float eta_it = outside ? 1.0f / eta : eta;", (T_GLASS_INSIDE,),
           "the dielectric Fresnel term with the relative IOR inverted", issue=True),
    Mutant("eta2-scaling-dropped", "s->weight = v3_scale(bsdf_trans(b), eta_ti * eta_ti);",
           "s->weight = bsdf_trans(b);", (T_GLASS_INSIDE,),
           "refraction through smooth glass without the eta^2 radiance scaling", issue=True,
           after="static inline bool dielectric_sample("),
    Mutant("envmap-cell-omega-no-sin-theta",
           "cell_omega = (2.0 * np.pi / w) * 2.0 * np.sin(mid) * np.sin(half)",
           "cell_omega = (2.0 * np.pi / w) * 2.0 * np.sin(half)",
           ("tests/test_lights.py::test_envmap_sampling_chi2",),
           "the envmap's cell solid angle without sin(theta) (host tables)", root="host", issue=True),
    # ---- more plausible single-line bugs across cl/ ------------------------------------------------
    Mutant("mis-swapped-environment", "if (mis) w = power_heuristic(ps->prev_pdf, light_pdf);",
           "if (mis) w = power_heuristic(light_pdf, ps->prev_pdf);", (T_ANALYTIC_SKY,),
           "the power heuristic's arguments swapped for the environment found by a BSDF sample"),
    Mutant("cosine-pdf-halved", "return v.z > 0.0f ? v.z * INV_PI_F : 0.0f;",
           "return v.z > 0.0f ? v.z * INV_2PI_F : 0.0f;",
           ("tests/test_sampling.py::test_cosine_hemisphere_chi2", T_ANALYTIC_QUAD),
           "the cosine-hemisphere pdf off by a factor 2"),
    Mutant("uniform-sphere-half", "float z = 1.0f - 2.0f * u.x;", "float z = 1.0f - u.x;",
           ("tests/test_sampling.py::test_uniform_sphere_chi2",), "uniform sphere sampling covers one hemisphere"),
    Mutant("uniform-sphere-pdf", "#define UNIFORM_SPHERE_PDF (0.25f * INV_PI_F)",
           "#define UNIFORM_SPHERE_PDF (0.5f * INV_PI_F)", (T_SKY_CUBE,),
           "the uniform-sphere pdf of a hemisphere (constant environment light samples)"),
    Mutant("concentric-disk-angle", "float theta = x_major ? (PI_F / 4.0f) * (oy / ox)",
           "float theta = x_major ? (PI_F / 2.0f) * (oy / ox)",
           ("tests/test_sampling.py::test_cosine_hemisphere_chi2",), "the concentric disk mapping's angle doubled"),
    Mutant("ray-origin-not-offset", "float_scale = 1.0f / 65536.0f, int_scale = 256.0f;",
           "float_scale = 0.0f, int_scale = 0.0f;", (T_FURNACE,),
           "new rays start exactly at the hit point (self-intersection)"),
    Mutant("light-pdf-distance-not-squared", "return l[LIGHT_PMF] * dist * dist / (l[LIGHT_AREA] * cos_l);",
           "return l[LIGHT_PMF] * dist / (l[LIGHT_AREA] * cos_l);", (T_ANALYTIC_QUAD,),
           "the area-to-solid-angle conversion of the light pdf with dist instead of dist^2"),
    Mutant("light-sample-cosine-sign", "float cos_l = -m_dot(ls->wi, ng);", "float cos_l = m_dot(ls->wi, ng);",
           (T_ANALYTIC_QUAD,), "the emitter's cosine taken on the wrong side"),
    Mutant("point-light-inverse-distance", "ls->radiance = v3_divs(rgb_at(l + LIGHT_RADIANCE, sc->unit), dist2);",
           "ls->radiance = v3_divs(rgb_at(l + LIGHT_RADIANCE, sc->unit), ls->dist);",
           ("tests/test_lights.py::test_point_light_analytic",), "a point light falling off as 1/d, not 1/d^2"),
    Mutant("environment-pdf-without-choice", "if (want_pdf) *pdf = l[LIGHT_PMF] * UNIFORM_SPHERE_PDF;",
           "if (want_pdf) *pdf = UNIFORM_SPHERE_PDF;", (T_ANALYTIC_SKY,),
           "the constant environment's MIS pdf without the probability of choosing it"),
    Mutant("envmap-sample-phi-shift", "float phi = (2.0f * PI_F) * (((float)c + 0.5f + uc) / (float)t.w);",
           "float phi = (2.0f * PI_F) * (((float)c + uc) / (float)t.w);",
           ("tests/test_lights.py::test_envmap_sampling_chi2",), "envmap samples shifted by half a cell in phi"),
    Mutant("envmap-pdf-times-omega", "return cdf_pmf(t.marginal, r) * t.alias[4 * (r * t.w + c) + 2] / omega;",
           "return cdf_pmf(t.marginal, r) * t.alias[4 * (r * t.w + c) + 2] * omega;",
           ("tests/test_lights.py::test_envmap_pdf_integrates_to_one",),
           "the envmap pdf multiplied by the cell's solid angle"),
    Mutant("envmap-alias-own-pmf-swapped", "        *pmf = a[2];", "        *pmf = a[3];",
           ("tests/test_lights.py::test_envmap_sampling_picks_the_cells_of_its_tables",),
           "an environment cell picked by its own alias entry priced at its alias's pmf"),
    Mutant("bvh-barycentric-bound", "if (!(v >= 0.0f && u + v <= adet)) return false;",
           "if (!(v >= 0.0f && v <= adet)) return false;",
           ("tests/test_bvh.py::test_single_triangle_and_tiny_meshes",), "the triangle test accepts u + v > 1"),
    Mutant("bvh-far-plane-unscaled", "bvh_min(tf.z, tmax)) * BVH_TFAR_SCALE;", "bvh_min(tf.z, tmax));",
           ("tests/test_bvh.py::test_traversal_matches_embree", "tests/test_bvh.py::test_tmax_limits_hits"),
           "the slab test without its rounding margin (may cull boxes the triangle test would hit)"),
    Mutant("bvh-packet-accepts-t-zero", "& (v >= zero) & (u + v <= adet) & (t > zero) & (adet > zero)",
           "& (v >= zero) & (u + v <= adet) & (t >= zero) & (adet > zero)",
           ("tests/test_bvh.py::test_ray_starting_on_a_triangle_ignores_it[w8-packets]",),
           "the leaf packets' triangle test (8-wide BVH, the default) accepts t == 0"),
    Mutant("bvh-packet-barycentric-bound", "& (v >= zero) & (u + v <= adet) & (t > zero) & (adet > zero)",
           "& (v >= zero) & (v <= adet) & (t > zero) & (adet > zero)",
           ("tests/test_bvh.py::test_single_triangle_and_tiny_meshes[w8-packets]",
            "tests/test_bvh.py::test_leaf_packets_match_scalar_leaves"),
           "the leaf packets' triangle test accepts u + v > 1"),
    Mutant("bvh-pop-order", "while (sp > 0 && !(stack_t[sp - 1] < best)) --sp;",
           "while (sp > 0 && (stack_t[sp - 1] < best)) --sp;",
           ("tests/test_bvh.py::test_single_triangle_and_tiny_meshes",),
           "closest-hit traversal (binary nodes) pops the wrong subtrees",
           after="bvh_node(nodes, cur, &r, best, &tl, &tr, &ll, &lr);"),
    Mutant("bvh-wide-pop-order", "while (sp > 0 && !(stack_t[sp - 1] < best)) --sp;",
           "while (sp > 0 && (stack_t[sp - 1] < best)) --sp;",
           ("tests/test_bvh.py::test_single_triangle_and_tiny_meshes",),
           "closest-hit traversal (wide nodes, the default) pops the wrong subtrees", after="#else /* wide nodes */"),
    Mutant("bvh-wide-far-plane-unscaled", "bvh_vmin(tfz, (BvhVf)(tmax))) * BVH_TFAR_SCALE;",
           "bvh_vmin(tfz, (BvhVf)(tmax)));",
           ("tests/test_bvh.py::test_traversal_matches_embree", "tests/test_bvh.py::test_tmax_limits_hits"),
           "the wide nodes' slab test without its rounding margin"),
    Mutant("rng-2d-same-word", "return v2(rng_unit(r0), rng_unit(r1));", "return v2(rng_unit(r0), rng_unit(r0));",
           ("tests/test_sampling.py::test_rng_uncorrelated",), "both coordinates of rng_2d from the same word"),
    Mutant("rng-roulette-from-the-lobe-word", "*u3 = rng_unit(r3);", "*u3 = rng_unit(r0);",
           ("tests/test_sampling.py::test_bounce_blocks_are_the_philox_words",
            "tests/test_sampling.py::test_bounce_block_numbers_are_uncorrelated_and_jointly_uniform"),
           "the roulette's number drawn from the word that picks the BSDF's lobe"),
    Mutant("depth-limit-off-by-one", "return max_depth < 0 || depth < max_depth;",
           "return max_depth < 0 || depth <= max_depth;", (T_FURNACE,), "max_depth allows one bounce too many"),
    Mutant("miss-always-mis", "bool mis = !(ps->flags & PATH_PREV_DELTA);", "bool mis = true;", (T_SKY_CUBE,),
           "the environment seen by camera rays and delta bounces weighted as if light sampling could find it"),
    Mutant("light-sample-times-pdf", "n->weight = w / n->ls.pdf;", "n->weight = w * n->ls.pdf;", (T_ANALYTIC_QUAD,),
           "a light sample multiplied by its pdf instead of divided"),
    Mutant("shadow-ray-reaches-light", "ls.dist * (1.0f - 1e-4f)", "ls.dist * (1.0f + 1e-4f)", (T_ANALYTIC_QUAD,),
           "shadow rays long enough to hit the light they test"),
    Mutant("bsdf-pdf-not-kept", "ps->prev_pdf = bs->pdf;", "ps->prev_pdf = 1.0f;", (T_ANALYTIC_QUAD,),
           "MIS weights of emission hits computed with a wrong BSDF pdf"),
    Mutant("wavefront-miss-not-committed", "film_commit(frame, drop_marks, f, ps.L);",
           "(void)frame;", ("tests/test_wavefront.py::test_every_pixel_is_committed_once_per_sample",),
           "the wavefront's miss stage ends paths without writing their pixel", after="path_miss(&sc, &ps);"),
    Mutant("finish-paths-depth-off-by-one", "PathState ps = path_load_ray(&P, slot, bounce);",
           "PathState ps = path_load_ray(&P, slot, bounce + 1);",
           ("tests/test_wavefront.py::test_finish_paths_gives_the_megakernels_image",),
           "the wavefront's tail runs its paths on one bounce ahead (depth limit, roulette, random numbers)"),
    Mutant("wavefront-committed-twice", "if (alive) path_store_ray(&P, slot, &ps);",
           "if (alive) { path_store_ray(&P, slot, &ps); "
           "film_commit(frame, drop_marks, path_get_film_slot(&P, slot), path_get_L(&P, slot)); }",
           ("tests/test_wavefront.py::test_every_pixel_is_committed_once_per_sample",),
           "the wavefront commits surviving paths too (the final commit overwrites it: the image is unchanged)",
           # the CPU class's single pass (the first such line, before it, is the GPU steps', which CPUs never build)
           after="bool alive = path_sample_bsdf(path_key(&P, &sc, slot, seed, first_sample), &s, &b, &ps, max_depth);"),
    Mutant("roulette-not-compensated", "ps->beta = v3_divs(ps->beta, q);", "ps->beta = v3_divs(ps->beta, 1.0f);",
           (T_FURNACE,),
           "surviving paths not divided by the survival probability"),
    Mutant("roulette-absolute-throughput", "if (ps->depth == 1 && beta_max < 1.0f) ps->rr_scale /= beta_max;",
           "if (false) ps->rr_scale /= beta_max;", (T_ROULETTE,),
           "the roulette weighs the throughput alone, not relative to the first bounce's (unbiased: only the "
           "queue counts see it)"),
    Mutant("roulette-factor-1", "float q = m_min(RR_FACTOR * beta_max * ps->rr_scale, 0.95f);",
           "float q = m_min(beta_max * ps->rr_scale, 0.95f);", (T_ROULETTE,),
           "the roulette without its factor 2 (unbiased: only the queue counts see it)"),
    Mutant("image-upside-down", "float sy = 1.0f - 2.0f * (y / c[CONST_HEIGHT]);",
           "float sy = 2.0f * (y / c[CONST_HEIGHT]) - 1.0f;",
           ("tests/test_render.py::test_depth_one_shows_only_emitters",), "the camera's image rows reversed"),
    Mutant("diffuse-without-1-over-pi", "return v3_scale(b->color, INV_PI_F * wo.z);",
           "return v3_scale(b->color, wo.z);",
           (T_ANALYTIC_QUAD,), "the Lambertian BRDF without its 1/pi (next-event estimation only)"),
    Mutant("fresnel-p-polarisation", "float a_p = (eta_it * ci - ct) / (eta_it * ci + ct);",
           "float a_p = (ci - eta_it * ct) / (ci + eta_it * ct);",
           ("tests/test_sampling.py::test_fresnel_dielectric_reference",), "the p-polarised Fresnel amplitude wrong"),
    Mutant("bump-gradient-halved", "vec3 pu = v3_add(v3_sub(dpdu, v3_scale(ns, m_dot(ns, dpdu))), v3_scale(ns, dhdu));",
           "vec3 pu = v3_add(v3_sub(dpdu, v3_scale(ns, m_dot(ns, dpdu))), v3_scale(ns, 0.5f * dhdu));",
           ("tests/test_textures.py::test_bump_map_tilts_the_shading_normal",), "the bump map's u slope halved"),
    Mutant("spawn-on-front-side", "return offset_ray_origin(s->p, m_dot(d, s->ng) >= 0.0f ? s->ng : v3_neg(s->ng));",
           "return offset_ray_origin(s->p, s->ng);", (T_GLASS_INSIDE,),
           "rays leaving through the back of a surface offset to its front"),
    Mutant("texture-rows-not-flipped", "float y = (1.0f - uv.y) * h - 0.5f;", "float y = uv.y * h - 0.5f;",
           ("tests/test_textures.py",), "bitmaps read with v upwards instead of Mitsuba's rows from the top"),
    Mutant("motion-vector-reversed", "return seen ? v2(prev.x - cur.x, prev.y - cur.y)",
           "return seen ? v2(cur.x - prev.x, cur.y - prev.y)",
           ("tests/test_aovs.py::test_motion_of_a_camera_translation",),
           "motion vectors pointing from the previous frame to this one instead of back"),
    Mutant("aov-ids-of-the-last-sample", "float id = first ? slots[c * n + f] : sum[c * pixels + p];",
           "float id = first ? slots[c * n + (frames - 1) * frame_pixels + f] : sum[c * pixels + p];",
           ("tests/test_aovs.py::test_aovs_average_the_samples_in_sample_order",),
           "a pixel's ids taken from the last sample of its first batch, not its first sample"),
    Mutant("reprojection-ignores-material", "return (mq == mat) & (surface == surface_q) & (!surface | same);",
           "return (surface == surface_q) & (!surface | same);",
           ("tests/test_denoise.py::test_known_camera_move_reprojects_the_history",),
           "the denoiser's reprojection accepts history from another material"),
    Mutant("conserve-full-gain", "float keep = e2 > 0.0f ? e2 / (e2 + sigma * sigma * sv[c]) : 0.0f;",
           "float keep = 1.0f;",
           ("tests/test_denoise.py::test_the_filters_balance_does_not_put_the_tiles_noise_back",),
           "the filter's energy balance gives every tile its whole loss, its noise included"),
    Mutant("light-change-never-seen", "age[0] = changed[0] >= least ? 0 : min(age[0] + 1, LIGHT_AGE_MAX);",
           "age[0] = LIGHT_AGE_MAX;",
           ("tests/test_denoise_quality.py::test_a_light_change_is_followed_in_its_own_frame",),
           "the anti-lag never learns that a light changed in view: the dim surfaces keep the old light"),
    Mutant("kahan-correction-lost", "return fpair_make(t, d - y);", "return fpair_make(t, 0.0f);",
           ("tests/test_accumulation.py",), "the compensated accumulator forgets its correction"),
    Mutant("ggx-g1-halved", "return 2.0f / (1.0f + m_sqrt(1.0f + tan2));",
           "return 1.0f / (1.0f + m_sqrt(1.0f + tan2));",
           ("tests/test_sampling.py::test_roughconductor_furnace",), "GGX's Smith G1 off by a factor 2"),
    Mutant("directional-light-reversed", "ls->wi = v3_neg(rgb_at(sc->light_data + as_int(l[LIGHT_PRIM]), sc->unit));",
           "ls->wi = rgb_at(sc->light_data + as_int(l[LIGHT_PRIM]), sc->unit);",
           ("tests/test_lights.py::test_directional_light_analytic",), "a directional light sampled from its far side"),
    Mutant("spot-falloff-linear-in-cosine",
           ": (s[SPOT_CUTOFF] - m_acos(m_clamp(cos_t, -1.0f, 1.0f))) * s[SPOT_INV_TRANSITION];",
           ": (cos_t - s[SPOT_COS_CUTOFF]) / (s[SPOT_COS_BEAM] - s[SPOT_COS_CUTOFF]);",
           ("tests/test_lights.py::test_spot_light_analytic",), "a spot's falloff linear in cosine, not in angle"),
    Mutant("thinlens-focus-ignored", "vec3 focus = v3_add(ps->org, v3_scale(plane, c[CONST_FOCUS_DISTANCE]));",
           "vec3 focus = v3_add(ps->org, plane);", ("tests/test_plugins.py::test_plugin_matches_mitsuba",),
           "a thin lens focused at distance 1 whatever its focus_distance"),
    # ---- reconstruction filters (issue 14) -----------------------------------------------------------
    Mutant("tent-filter-uniform", "float x = u < 0.5f ? m_sqrt(2.0f * u) - 1.0f : 1.0f - m_sqrt(2.0f - 2.0f * u);",
           "float x = 2.0f * u - 1.0f;", ("tests/test_rfilter.py::test_offsets_follow_mitsubas_filter",),
           "the tent's offsets uniform over its support instead of tent-distributed"),
    Mutant("gaussian-table-index-sqrt", "float t = m_sqrt(m_sqrt(1.0f - m_abs(2.0f * u - 1.0f)))",
           "float t = m_sqrt(1.0f - m_abs(2.0f * u - 1.0f))",
           ("tests/test_rfilter.py::test_offsets_follow_mitsubas_filter",),
           "the gaussian's table read at sqrt(1 - v) where it was tabulated at (1 - v)^(1/4)"),
    Mutant("gaussian-table-host-t-squared", "target = 1.0 - t ** 4", "target = 1.0 - t ** 2",
           ("tests/test_rfilter.py::test_offsets_follow_mitsubas_filter",),
           "the host tabulates the gaussian's inverse CDF at other nodes than the device reads", root="host"),
    Mutant("filter-only-along-x", "rfilter_position(c, j.y));", "j.y);",
           ("tests/test_rfilter.py::test_filter_matches_mitsuba",),
           "the filter applied along x only: rows keep the box's jitter"),
    # ---- differentiable rendering (issue 13) --------------------------------------------------------
    Mutant("gradient-ignores-gathered-radiance",
           "BsdfAdjoint g = bsdf_adjoint(&deferred[k].r, v3_mul(dL, v3_sub(L, deferred[k].gathered)));",
           "BsdfAdjoint g = bsdf_adjoint(&deferred[k].r, v3_mul(dL, L));",
           (f"{T_GRAD_FD}[diffuse]",), "a BSDF sample's adjoint uses the whole path's radiance, not what came after"),
    Mutant("gradient-delta-lobe-ratio", "r.spec = safe_div3(v3_splat(1.0f), b->spec);", "r.spec = b->spec;",
           (f"{T_GRAD_FD}[conductor-spec]",),
           "a delta lobe's derivative ratio spec instead of 1 / spec"),
    Mutant("gradient-texel-weights-swapped", "k.w[1] = ax * (1.0f - ay);", "k.w[1] = (1.0f - ax) * ay;",
           ("tests/test_gradients.py::test_each_texel_gets_its_bilinear_share_of_a_pixel",),
           "a bilinear texel's gradient weight taken from its neighbour"),
    Mutant("gradient-emission-without-mis", "grad_emitter(sc, gr, s.light, ps.dir, v3_scale(v3_mul(dL, ps.beta), w));",
           "grad_emitter(sc, gr, s.light, ps.dir, v3_mul(dL, ps.beta));", (f"{T_GRAD_FD}[area-light]",),
           "the gradient of emission found by a BSDF sample loses its MIS weight"),
    Mutant("gradient-replay-without-visibility", "if (ps.depth < VIS_BITS) *visible |= 1u << ps.depth;",
           "if (ps.depth < VIS_BITS) *visible |= 0u;",
           ("tests/test_gradients.py::test_replay_gives_the_gradients_of_the_deferred_pass",),
           "the replay sees every shadow ray occluded (its radiance bookkeeping goes wrong)"),
    Mutant("gradient-alpha-not-moved",
           'return dataclasses.replace(mat, alpha=alpha * factor, **({"alpha_v": alpha * factor} if iso else {}))',
           'return dataclasses.replace(mat, alpha=alpha, **({"alpha_v": alpha} if iso else {}))',
           (f"{T_GRAD_FD}[roughconductor-alpha]",), "the roughness records are not moved: no alpha gradient",
           root="host"),
    # ---- issue 25: the interior term of moving geometry (cl/gradients/geometry.h) --------------------------
    Mutant("geometry-far-cosine-dropped", "g_w = v3_add(g_w, v3_scale(b->n, a_w / cb));",
           "g_w = v3_add(g_w, v3_scale(b->n, 0.0f));", ("tests/test_interior.py::test_moving_lights",),
           "the cosine at a segment's far end does not see the segment turn (reverse mode)"),
    Mutant("geometry-first-hit-attached", "gp = nd != 0.0f ? v3_scale(n, m_dot(v->d, gx) / nd) : v3_splat(0.0f);",
           "gp = gx;", ("tests/test_interior.py::test_floor_moving_under_a_point_light",),
           "the camera ray's hit moves with the surface instead of sliding along the ray (reverse mode)"),
    Mutant("geometry-first-hit-attached-forward",
           "dp = nd != 0.0f ? v3_scale(v->d, m_dot(n, dp) / nd) : v3_splat(0.0f);", "dp = dp;",
           ("tests/test_interior.py::test_floor_moving_under_a_point_light",),
           "the same in forward mode"),
    Mutant("geometry-frame-does-not-turn",
           "*gn = v3_add(*gn, v3_sub(v3_scale(w, gl.z), v3_scale(v3_add(v3_scale(f.s, gl.x), "
           "v3_scale(f.t, gl.y)), nw)));", "*gn = *gn;",
           ("tests/test_interior.py::test_floor_moving_under_a_point_light",),
           "a BSDF's local frame stays put when its surface turns (reverse mode)"),
    Mutant("geometry-smooth-hit-does-not-slide",
           "g_slide = v3_divs(v3_add(v3_scale(m_cross(e2, n), g1), v3_scale(m_cross(n, e1), g2)), len);",
           "g_slide = v3_splat(0.0f);", ("tests/test_interior.py::test_smooth_shaded_floor",),
           "a sliding hit's shading normal keeps its barycentrics' vertex normals (reverse mode)"),
    Mutant("geometry-smooth-hit-does-not-slide-forward",
           "dm = v3_add(dm, v3_add(v3_scale(v3_sub(n1, n0), v->db1), v3_scale(v3_sub(n2, n0), v->db2)));", "dm = dm;",
           ("tests/test_interior.py::test_smooth_shaded_floor",), "the same in forward mode"),
    Mutant("geometry-vertex-normals-still",
           "exact = exact + _normals(p, table, gn, normals_backward).reshape(exact.shape)", "exact = exact",
           ("tests/test_interior.py::test_smooth_shaded_floor",),
           "the vertex normals that update() recomputes are held still (reverse mode)", root="host"),
    Mutant("geometry-vertex-normals-still-forward",
           'tangent["vnormals"][first:first + dp.size] = _normals(p, table, d, normals_forward).reshape(-1)',
           "pass", ("tests/test_interior.py::test_smooth_shaded_floor",), "the same in forward mode", root="host"),
    Mutant("geometry-spot-axis-still", "grad_put3(gr, gr->lightpos + GEO_LIGHT_STRIDE * n->ls.light + 3, "
           "v3_scale(n->ls.wi, -k));", "k = k;", ("tests/test_interior.py::test_spot_light_moving",),
           "a turning spot light's falloff does not see its axis turn (reverse mode)"),
    Mutant("geometry-spot-falloff-still-forward", "- k * (m_dot(dwo, axis) + m_dot(n->ls.wi, daxis));", "- 0.0f * k;",
           ("tests/test_interior.py::test_spot_light_moving",),
           "forward mode: a moving spot light's falloff is held still (only 1 / r^2 moves)"),
    Mutant("geometry-no-area-jacobian", "b->gj += a_w;", "b->gj += 0.0f;",
           ("tests/test_interior.py::test_moving_lights",),
           "a growing emitter's points spread out but its area Jacobian is left out"),
    Mutant("geometry-camera-ray-does-not-turn", "vec3 g_dd = v3_sub(v3_scale(q, v->t), v->gwi);",
           "vec3 g_dd = v3_scale(q, v->t);", ("tests/test_interior.py::test_moving_camera",),
           "a moving camera's rays turn, but the BSDF at their hits does not see its incident direction turn"),
    Mutant("geometry-camera-origin-fixed", "vec3 u = v3_add(tangent3(tg->camera), v3_scale(v->dd, v->t));",
           "vec3 u = v3_scale(v->dd, v->t);", ("tests/test_interior.py::test_moving_camera",),
           "forward mode: the camera's hits do not follow its origin"),
    # ---- issue 25: an orthographic camera's pose (cl/gradients/geometry.h: geo_camera_scatter / _motion) ----
    Mutant("geometry-ortho-origin-off-film", "grad_put3(gr, gr->camera + 6, v3_scale(q, v->sx));",
           "grad_put3(gr, gr->camera + 6, v3_splat(0.0f));",
           ("tests/test_interior.py::test_moving_orthographic_camera",),
           "reverse mode: an orthographic camera's ray origins do not move with the film coordinates (dR dropped)"),
    Mutant("geometry-ortho-origin-off-film-forward",
           "vec3 u = v3_add(v3_add(tangent3(tg->camera), v3_scale(tangent3(tg->camera + 6), v->sx)),",
           "vec3 u = v3_add(v3_add(tangent3(tg->camera), v3_scale(tangent3(tg->camera + 6), 0.0f)),",
           ("tests/test_interior.py::test_moving_orthographic_camera",),
           "forward mode: an orthographic camera's ray origins do not move with the film coordinates (dR dropped)"),
    Mutant("edges-ortho-velocity-perspective", "if self.orthographic:  # constant: the rows of B^-1", "if False:",
           ("tests/test_edges.py::test_orthographic_camera_moving_over_a_square",),
           "an orthographic camera's edge velocities through the perspective projection's Jacobian", root="host"),
    # ---- the shadows' boundary terms under an orthographic camera (pyclpt/gradients/shadows.py, edges.py) ----
    Mutant("shadows-ortho-camera-rays-pinhole", 'if cam.kind == "orthographic":', "if False:",
           ("tests/test_shadows.py::test_soft_shadow_under_an_orthographic_camera",),
           "the soft term's camera hits slide along a pinhole's rays from the orthographic camera's origin",
           root="host"),
    Mutant("shadows-ortho-view-from-pinhole", "if self.orthographic:", "if False:",
           ("tests/test_shadows.py::test_hard_shadow_under_an_orthographic_camera",),
           "a hard shadow's outline seen from the orthographic camera's origin, not along its parallel rays",
           root="host", after="def rays_to(self"),
    Mutant("shadows-ortho-film-pinhole", "if self.orthographic:", "if False:",
           ("tests/test_shadows.py::test_hard_shadow_under_an_orthographic_camera",),
           "a hard shadow's outline mapped to the film by the pinhole's projection under an orthographic camera",
           root="host", after="def film(self"),
    # ---- issue 25: a moving mirror in the interior term (cl/gradients/geometry.h: geo_mirror_ray) ----
    Mutant("geometry-mirror-normal-still-forward", "vec3 dns = m->ds; /* the mirror's normal turns */",
           "vec3 dns = v3_splat(0.0f);", ("tests/test_interior.py::test_moving_mirror_interior_term",),
           "forward mode: the reflected ray turns with the incoming ray but not with the mirror's normal"),
    Mutant("geometry-mirror-ray-origin-still", "vec3 u = v3_add(m->dx, v3_scale(x->dd, x->t));",
           "vec3 u = v3_scale(x->dd, x->t);", ("tests/test_interior.py::test_moving_mirror_interior_term",),
           "forward mode: the reflected ray turns but its origin (the mirror's sliding point) is held still"),
    Mutant("geometry-mirror-normal-adjoint-dropped",
           "m->gs = v3_sub(m->gs, v3_scale(v3_add(v3_scale(g_r, nsd), v3_scale(m->d, nsg)), 2.0f));",
           "(void)nsd;", ("tests/test_interior.py::test_moving_mirror_interior_term",),
           "reverse mode: the reflected ray's adjoint reaches the incoming ray but not the mirror's normal"),
    Mutant("geometry-mirror-fresnel-still-forward",
           "if (gc.mirror) dbeta = v3_add(dbeta, v3_mul(ps.beta, geo_fresnel_tangent(&sc, &b, &gc))); /* F turns */",
           "/* the Fresnel factor held */", ("tests/test_interior.py::test_moving_mirror_interior_term",),
           "forward mode: a turning mirror's reflection moves but its Fresnel reflectance keeps its angle"),
    Mutant("geometry-mirror-fresnel-adjoint-dropped",
           "if (gc.mirror) geo_fresnel_adjoint(sc, &b, dL, v3_sub(L_total, gathered), &gc); /* its Fresnel factor */",
           "/* the Fresnel factor's adjoint dropped */", ("tests/test_interior.py::test_moving_mirror_interior_term",),
           "reverse mode: the Fresnel reflectance's change with the mirror's angle left out"),
    # ---- issue 25: instances' to_world (cl/gradients/geometry.h -DGRAD_INSTANCES, pyclpt/gradients/flatten.py) ----
    Mutant("geometry-instance-points-translate-only",
           "vec3 x0 = geo_local_vertex(sc, v->id, 0), x1 = geo_local_vertex(sc, v->id, 1), x2 = "
           "geo_local_vertex(sc, v->id, 2);", "vec3 x0 = v3_splat(0.0f), x1 = x0, x2 = x0;",
           (f"{T_INST}::test_instance_to_world_interior",),
           "an instance's points move with its translation only, not by dA x (reverse mode)"),
    Mutant("geometry-instance-points-translate-only-forward",
           "d = v3_add(v3_add(d, geo_inst_apply(c, geo_local_vertex(sc, v->id, j))), tangent3(c + 9));",
           "d = v3_add(d, tangent3(c + 9));", (f"{T_INST}::test_instance_to_world_interior",),
           "the same in forward mode"),
    Mutant("geometry-instance-normals-still",
           "vec3 w0 = geo_vnormal(sc, v, vi[0]), w1 = geo_vnormal(sc, v, vi[1]), w2 = geo_vnormal(sc, v, vi[2]);",
           "vec3 w0 = v3_splat(0.0f), w1 = w0, w2 = w0;", (f"{T_INST}::test_instance_to_world_interior[smooth]",),
           "an instance's vertex normals do not turn with the inverse transpose of its to_world (reverse mode)"),
    Mutant("geometry-instance-normals-still-forward", "vec3 w = geo_vnormal(sc, v, k); /* -N dA^T w */",
           "vec3 w = v3_splat(0.0f);", (f"{T_INST}::test_instance_to_world_interior[smooth]",),
           "the same in forward mode"),
    Mutant("geometry-instance-mirror-ignored", "gn = v3_add(gn, v3_scale(v->gs, geo_flip(sc, v)));",
           "gn = v3_add(gn, v->gs);", (f"{T_INST}::test_instance_to_world_mirrored",),
           "a mirroring instance's flat shading normal taken along its world edges' cross product (reverse mode)"),
    Mutant("geometry-instance-mirror-ignored-forward", "v->ds = v3_scale(v->dn, geo_flip(sc, v));", "v->ds = v->dn;",
           (f"{T_INST}::test_instance_to_world_mirrored",), "the same in forward mode"),
    Mutant("geometry-instance-boundary-pose-identity", "poses[f\"{name}.to_world\"] = m.copy()",
           "poses[f\"{name}.to_world\"] = np.eye(4)",
           (f"{T_INST}::test_instanced_scene_gradients_equal_the_plain_scene",),
           "the flattened instance's outlines moved as world points (pose I), not by dT T^-1 x", root="host"),
    Mutant("geometry-instance-boundary-mirror-winding",
           "indices = self.indices[:, ::-1].copy() if np.linalg.det(m[:3, :3]) < 0 else self.indices",
           "indices = self.indices", (f"{T_INST}::test_mirrored_instance_outline",),
           "a flattened mirroring instance keeps its winding: its outline seen from its back", root="host"),
    Mutant("soft-boundary-occluder-side-counted", "if (on_plus) out_minus = side_radiance(",
           "out_plus = side_radiance(sc, key, s, &plus, depth, max_depth); if (true) out_minus = side_radiance(",
           ("tests/test_interior.py::test_receiver_moving_under_a_soft_shadow",),
           "the soft-shadow term traces the side that meets the occluder first as well (incident_sides): it counts "
           "the occluder's own radiance, which the interior term's area integral has"),
    Mutant("soft-boundary-still-edges-ignored", "if (moving != moving_part) continue;",
           "if (!moving) continue;",
           ("tests/test_shadows.py::test_the_floor_rising_under_a_hard_shadow_seen_after_a_bounce",),
           "a still shading point never picks a still mesh's edge: a still outline over a moving background is lost"),
    Mutant("soft-boundary-own-triangle-edges", "if (!off_a || !off_b) return 0.0f;", "if (false) return 0.0f;",
           ("tests/test_shadows.py::test_the_edge_pick_follows_the_angles_and_skips_the_occluders_side",),
           "edges whose face planes hold the shading point (its own triangle's, seen edge-on) are picked"),
    Mutant("geometry-texture-still", "return v3_scale(v3_sub(f[0], f[1]), 0.5f / GEO_UV_STEP);",
           "return v3_splat(0.0f);",
           ("tests/test_shadows.py::test_a_textured_floor_sliding_under_the_camera",
            "tests/test_shadows.py::test_the_camera_moving_over_a_textured_floor"),
           "a sliding point's texture coordinates stay where they are: a texture moving under the pixels is lost"),
    Mutant("delta-shadow-sides-swapped", "vec3 dir = m_normalize(v3_add(w, v3_scale(*n, k == 0 ? -eps : eps)));",
           "vec3 dir = m_normalize(v3_add(w, v3_scale(*n, k == 0 ? eps : -eps)));",
           ("tests/test_shadows.py::test_hard_shadows_after_a_bounce_against_finite_differences",),
           "the later hard-shadow term's two sides swapped: its jump changes sign"),
    Mutant("delta-shadow-receiver-fixed", "dx[r] -= np.einsum(", "dx[r] += 0 * np.einsum(",
           ("tests/test_shadows.py::test_the_floor_rising_under_a_hard_shadow_seen_after_a_bounce",),
           "the later hard-shadow outline does not slide over its moving receiver", root="host"),
    Mutant("soft-boundary-background-fixed", "return 1.0 - self.edge_dist / self.back_dist",
           "return 1.0 + 0.0 * self.back_dist", ("tests/test_interior.py::test_receiver_moving_under_a_soft_shadow",),
           "the outline moves against fixed directions, not against the (attached) background behind it",
           root="host"),
    Mutant("hard-shadow-receiver-still", "along = np.einsum(\"ni,nij,nj->n\", normal, jac, d) / dn",
           "along = 0.0 * dn", ("tests/test_interior.py::test_receiver_moving_under_a_hard_shadow",),
           "a hard shadow's outline stays put on a receiver that moves", root="host"),
    Mutant("mirror-edge-velocity-not-reflected", "velocity[m] = velocity[m] @ plane.matrix",
           "velocity[m] = velocity[m]", ("tests/test_edges.py::test_square_seen_in_a_mirror",
                                         "tests/test_edges.py::test_tilted_mirror_against_finite_differences"),
           "an outline seen in a planar mirror moves with its reflection's point, not through the reflection R",
           root="host"),
    Mutant("mirror-edge-camera-at-the-real-point", "es.seen_at, es.normal, name)  # the mirrors are still",
           "es.point, es.normal, name)", ("tests/test_edges.py::test_tilted_mirror_against_finite_differences",),
           "the camera's motion moves an outline seen in a mirror as if it saw the real point, not its reflection",
           root="host"),
    Mutant("mirror-edge-plane-offset-dropped", "by_point = 2.0 * vm * m  # n . d film/dc", "by_point = 0.0 * vm * m",
           ("tests/test_edges.py::test_moving_mirror_against_finite_differences",),
           "a mirror that moves along its normal leaves the outlines it shows where they are (its dc . m term lost)",
           root="host"),
    Mutant("mirror-edge-plane-turn-sign", "by_normal = -2.0 * (vm * d + h * v)  # n . d film/dm",
           "by_normal = 2.0 * (vm * d + h * v)",
           ("tests/test_edges.py::test_moving_mirror_against_finite_differences",),
           "a mirror that turns moves the outlines it shows the other way (the sign of its dm term)", root="host"),
    Mutant("mirror-edge-smooth-as-flat", "shading = None if mirror.normals is None else", "shading = None if True else",
           ("tests/test_edges.py::test_moving_mirror_vertices",),
           "a smooth-shaded mirror bent at a vertex reflects about its faces, not its recomputed vertex normals",
           root="host"),
    # ---- issue 14: texture-coordinate conventions ------------------------------------------------
    Mutant("checkerboard-on-flipped-v", "    float tm = 1.0f - st.y;", "    float tm = st.y;",
           (T_UV_TRANSFORMS, "tests/test_textures.py::test_checkerboard"),
           "the checkerboard decides its squares on pyclpt's v instead of Mitsuba's (colours swapped)"),
    Mutant("checkerboard-eval1-like-eval", "int at = tex_checker_color0(tex_st(t, uv)) ? TEX_COLOR1 : TEX_SCALE;",
           "int at = tex_checker_color0(tex_st(t, uv)) ? TEX_SCALE : TEX_COLOR1;", (T_UV_TRANSFORMS,),
           "a checkerboard used as a mask's opacity gives the colour of its eval (Mitsuba's eval_1 swaps)"),
    Mutant("to-uv-not-conjugated", "p = FLIP_V @ m @ FLIP_V", "p = m", (T_UV_TRANSFORMS,),
           "Mitsuba's to_uv applied to pyclpt's v-up coordinates as it is", root="host"),
    Mutant("spot-texture-v-not-flipped", "return light_texture(sc, l, v2(0.5f + d.x * k, 0.5f - d.y * k));",
           "return light_texture(sc, l, v2(0.5f + d.x * k, 0.5f + d.y * k));", (T_EMITTER_TEXTURES,),
           "a spot light's texture projected with Mitsuba's v taken as pyclpt's (mirrored)"),
    Mutant("area-light-texture-at-one-point", "sc->tri_info[2 * prim], b.x, b.y)));",
           "sc->tri_info[2 * prim], 0.0f, 0.0f)));",
           (T_EMITTER_TEXTURES,), "light sampling reads a textured area light's texture at one vertex"),
    Mutant("instance-drops-the-uv-frame", "    if (mat_flags(scene_material(sc, s.material)) & MAT_FLAG_UV_FRAME) {",
           "    if (false) {", ("tests/test_instances.py::test_instanced_scene_renders_as_flattened[False-True]",),
           "an instanced anisotropic material's tangent frame rebuilt from the normal, not turned with it",
           after="Surface s = surface_local(sc, surface_local_prim(sc, prim), u, v);"),
    # the GPU's shading stages in steps (docs/gpu.md, "The shading stages in steps"), run on PoCL with the GPU layout
    Mutant("gpu-kept-normal-unwritten", "    path_set_org(P, slot, path_hit_surface_whole(sc, P, slot).sh.n);",
           "    (void)P;", (T_GPU_STEPS,),
           "the wavefront's GPU steps rebuild the surface from a shading normal that was never kept"),
    Mutant("gpu-textures-not-applied", "    b.color = v3_mul(b.color, f.color);", "    (void)f;", (T_GPU_STEPS,),
           "the GPU steps' material without its looked-up texture (the diffuse reflectance or transmittance)",
           after="static inline GPU_INLINE Bsdf bsdf_textured("),
    Mutant("gpu-light-delta-sign-lost", "n.ls.delta = pdf < 0.0f;", "n.ls.delta = false;", (T_GPU_STEPS,),
           "the GPU steps forget that the kept light sample was a delta light's (MIS against BSDF sampling)"),
    Mutant("pipelined-bound-is-the-expected-count",
           "        return last, expected_rays(last, before)",
           "        return expected_rays(last, before), last", (T_PIPELINED,),
           "the pipelined schedule launches a bounce over the count it expects, which can be below the real one",
           root="host"),
    Mutant("simt-exit-warps-free",
           "    idle = np.full(max(0, -(-launched // width) - -(-slots.size // width)), c.exit)",
           "    idle = np.zeros(0)", (T_SIMT_GPU_BUILD,),
           "the SIMT model launches each stage over its own queue, not the bounce's bound as Wavefront does",
           root="host"),
    Mutant("simt-regeneration-queue-unsorted", "        queue = np.sort(np.concatenate([queue[going], new]))",
           "        queue = np.concatenate([queue[going], new])", (T_SIMT_REGENERATION,),
           "the regeneration design's ray queue keeps the new paths after the continuing ones, its order mixing "
           "bounce after bounce", root="host"),
    Mutant("stage-defines-path-init-without-filter",
           '    "path_init": frozenset({"SCENE_CAMERA", "SCENE_FILTER", "FILM_CROP"}),',
           '    "path_init": frozenset({"SCENE_CAMERA", "FILM_CROP"}),', (T_STAGE_DEFINES, T_RFILTER_WAVEFRONT),
           "path_init is built without the pixel filter's define, so its camera rays are the box filter's",
           root="host"),
]


# --------------------------------------------------------------------------------------------
# finding and applying


class MutantError(RuntimeError):
    pass


def source_files(tree: Path, root: str) -> list[Path]:
    folder, suffixes = ROOTS[root]
    return sorted(p for p in (tree / folder).rglob("*") if p.is_file() and p.suffix in suffixes)


def locate(tree: Path, m: Mutant) -> tuple[Path, int]:
    """(file, 0-based line index) of the line the mutant changes, in ``tree``."""
    if m.after is None:
        hits = [(p, i) for p in source_files(tree, m.root)
                for i, line in enumerate(p.read_text().splitlines()) if m.original in line]
        if len(hits) != 1:
            where = ", ".join(f"{p.relative_to(tree)}:{i + 1}" for p, i in hits) or "nowhere"
            raise MutantError(f"{m.name}: {m.original!r} must be on exactly one line, found {where}")
        return hits[0]
    anchors = [(p, i) for p in source_files(tree, m.root)
               for i, line in enumerate(p.read_text().splitlines()) if m.after in line]
    if len(anchors) != 1:
        raise MutantError(f"{m.name}: the anchor {m.after!r} must be on exactly one line, found {len(anchors)}")
    path, start = anchors[0]
    lines = path.read_text().splitlines()
    for i in range(start, len(lines)):
        if m.original in lines[i]:
            return path, i
    raise MutantError(f"{m.name}: {m.original!r} is not after {m.after!r} in {path.relative_to(tree)}")


def apply(tree: Path, m: Mutant, source: Path) -> tuple[Path, str]:
    """Plant the mutant in ``tree`` (a copy: refuses to write inside this repository or the tree it was
    copied from); returns the file and its original text, for :func:`restore`."""
    path, i = locate(tree, m)
    resolved = path.resolve()
    if resolved.is_relative_to(REPO) or resolved.is_relative_to(source) or not resolved.is_relative_to(tree.resolve()):
        raise MutantError(f"refusing to write {resolved}: mutants go into the copy only")
    text = path.read_text()
    lines = text.splitlines(keepends=True)
    lines[i] = lines[i].replace(m.original, m.mutated, 1)
    path.write_text("".join(lines))
    return path, text


def restore(path: Path, text: str) -> None:
    path.write_text(text)


# --------------------------------------------------------------------------------------------
# running


def copy_tree(source: Path, dest: Path) -> Path:
    tree = dest / "tree"
    shutil.copytree(source, tree, ignore=IGNORE)
    return tree


def child_env(tree: Path, tmp: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [env.get("PYTHONPATH")])])
    env["PYCLPT_CACHE_DIR"] = str(tmp / "pyclpt-cache")  # BVH and mesh caches, shared by the runs
    pocl = tmp / "pocl-cache"
    if not pocl.exists():
        user = Path(env.get("POCL_CACHE_DIR") or Path(env.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "pocl")
        if user.is_dir():
            shutil.copytree(user, pocl, symlinks=True, ignore_dangling_symlinks=True)
        pocl.mkdir(exist_ok=True)
    env["POCL_CACHE_DIR"] = str(pocl)
    env["PYOPENCL_NO_CACHE"] = "1"
    env.pop("PYTEST_ADDOPTS", None)
    return env


def check_copy_is_used(tree: Path, env: dict[str, str]) -> None:
    code = "import pyclpt; from pyclpt.device.program import cl_dir; print(pyclpt.__file__); print(cl_dir())"
    out = subprocess.run([sys.executable, "-c", code], cwd=tree, env=env, capture_output=True, text=True, check=True)
    paths = [Path(line).resolve() for line in out.stdout.split()]
    if len(paths) != 2 or not all(p.is_relative_to(tree.resolve()) for p in paths):
        raise MutantError(f"the copy's pyclpt is not the one imported: {out.stdout.strip()!r}")


def run_pytest(tree: Path, env: dict[str, str], tests: tuple[str, ...], timeout: float) -> tuple[str, str, float]:
    """('passed' | 'failed' | 'error' | 'timeout', first failing test or a hint, seconds)."""
    cmd = [sys.executable, "-m", "pytest", "-n", "0", "-x", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
           "--no-header", "-rfE", *tests]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "timeout", f"over {timeout:.0f} s", time.perf_counter() - t0
    seconds = time.perf_counter() - t0
    out = proc.stdout + proc.stderr
    failed = [line.split(" ", 1)[1].split(" - ")[0] for line in out.splitlines()
              if line.startswith(("FAILED ", "ERROR "))]
    if "KernelBuildError" in out:
        return "error", "the mutant does not compile", seconds
    if proc.returncode == 0:
        return "passed", "", seconds
    if proc.returncode == 1:
        return "failed", failed[0] if failed else "", seconds
    return "error", f"pytest exit {proc.returncode}: " + (failed[0] if failed else out.strip()[-300:]), seconds


def markdown(results: list[dict], seconds: float) -> str:
    killed = sum(r["verdict"] == "killed" for r in results)
    lines = [f"Killed {killed} of {len(results)} mutants ({100 * killed / max(len(results), 1):.0f} %) in "
             f"{seconds / 60:.1f} min.", "",
             "| mutant | bug | file | result | first failing test |", "|---|---|---|---|---|"]
    for r in results:
        name = f"**{r['name']}**" if r["issue"] else r["name"]
        test = r["detail"].replace("tests/", "").replace("|", "\\|")
        lines.append(f"| {name} | {r['why']} | `{r.get('file', '?')}` | {r['verdict']} | {test} |")
    return "\n".join(lines) + "\n"


def select(names: list[str] | None) -> list[Mutant]:
    if not names:
        return list(MUTANTS)
    chosen = [m for m in MUTANTS if any(n in m.name for n in names)]
    if not chosen:
        raise SystemExit(f"no mutant matches {names}")
    return chosen


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="list the mutants and where their lines are")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="mutants whose name contains one of these")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the first run of every selection on the unmutated copy")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per mutant (default 600)")
    ap.add_argument("--json", type=Path, help="write the results here")
    ap.add_argument("--markdown", type=Path, help="write the results here as a Markdown table")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copy")
    ap.add_argument("--source", type=Path, default=REPO, help="the tree to copy (default: this repository)")
    ap.add_argument("--tests", nargs="+", metavar="NODE", help="run these pytest node ids instead of each mutant's")
    args = ap.parse_args(argv)
    source = args.source.resolve()
    mutants = select(args.only)
    names = [m.name for m in MUTANTS]
    if len(set(names)) != len(names):
        raise SystemExit("mutant names must be unique")

    if args.list:
        for m in mutants:
            try:
                path, i = locate(source, m)
                where = f"{path.relative_to(source)}:{i + 1}"
            except MutantError as exc:
                where = f"NOT FOUND ({exc})"
            print(f"{m.name:34s} {where:40s} {m.why}")
        return 0

    tmp = Path(tempfile.mkdtemp(prefix="pyclpt-mutate-"))
    results = []
    t_start = time.perf_counter()
    try:
        tree = copy_tree(source, tmp)
        env = child_env(tree, tmp)
        check_copy_is_used(tree, env)
        print(f"copy of {source} in {tree}")
        if not args.no_baseline:
            tests = tuple(args.tests or dict.fromkeys(t for m in mutants for t in m.tests))
            verdict, detail, seconds = run_pytest(tree, env, tests, args.timeout * 4)
            print(f"baseline (unmutated): {verdict} in {seconds:.0f} s {detail}", flush=True)
            if verdict != "passed":
                print("the unmutated selections do not pass: fix that first")
                return 2
        for k, m in enumerate(mutants, 1):
            try:
                path, original = apply(tree, m, source)
            except MutantError as exc:
                results.append({**asdict(m), "verdict": "not found", "detail": str(exc), "seconds": 0.0})
                print(f"[{k}/{len(mutants)}] {m.name}: NOT FOUND: {exc}")
                continue
            try:
                verdict, detail, seconds = run_pytest(tree, env, tuple(args.tests or m.tests), args.timeout)
            finally:
                restore(path, original)
            state = {"failed": "killed", "passed": "SURVIVED"}.get(verdict, verdict)
            where = path.relative_to(tree).as_posix()
            results.append({**asdict(m), "file": where, "verdict": state, "detail": detail, "seconds": seconds})
            print(f"[{k}/{len(mutants)}] {m.name:34s} {state:9s} {seconds:6.1f} s  {where}  {detail}", flush=True)
    finally:
        if args.keep:
            print(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)

    killed = [r for r in results if r["verdict"] == "killed"]
    survived = [r for r in results if r["verdict"] == "SURVIVED"]
    other = [r for r in results if r["verdict"] not in ("killed", "SURVIVED")]
    total = time.perf_counter() - t_start
    print(f"\nkilled {len(killed)} of {len(results)} mutants ({100 * len(killed) / max(len(results), 1):.0f} %) "
          f"in {total / 60:.1f} min")
    for r in survived:
        print(f"  survived: {r['name']} ({r['why']})")
    for r in other:
        print(f"  {r['verdict']}: {r['name']}: {r['detail']}")
    issue_left = [r["name"] for r in results if r["issue"] and r["verdict"] != "killed"]
    if issue_left:
        print(f"  NOT KILLED among issue 16's mutants: {', '.join(issue_left)}")
    if args.json:
        args.json.write_text(json.dumps({"total_seconds": total, "results": results}, indent=1))
    if args.markdown:
        args.markdown.write_text(markdown(results, total))
    return 0 if not survived and not other else 1


if __name__ == "__main__":
    sys.exit(main())
