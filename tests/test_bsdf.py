"""The materials of the Mitsuba importer on the device (cl/scene/bsdf.h): the Beckmann distribution, the rough
dielectric, the thin dielectric and the smooth and rough plastics.

Built on the harness of test_sampling.py (small kernels calling bsdf_sample / bsdf_eval, chi-square tests
against cell integrals of the device's own pdf). Per material and parameter set:

* chi-square of sampled directions against bsdf_eval's pdf (the whole sphere for the rough dielectric;
  delta and failed samples pooled into one extra cell whose expectation is 1 - the pdf's integral);
* sample weight == eval value / pdf and sample pdf == eval pdf;
* sampled albedo == quadrature of bsdf_eval's value;
* energy: white furnaces, and the rough dielectric's reflected / transmitted energy against the independent
  host integrals of pyclpt/microfacet.py;
* reference formulas (numpy, after Mitsuba 3's plastic.cpp / roughplastic.cpp / thindielectric.cpp);
* reciprocity, one- and two-sidedness, and finite output at extreme inputs;
* anisotropic roughness (alpha_u != alpha_v, -DSCENE_HAS_ANISOTROPY, with which this file's kernels are
  built): D, G1 and the visible-normal pdf against closed forms, chi-square of the visible normals and of
  the anisotropic rough conductor and dielectric, Mitsuba 3's eval / pdf, and isotropic materials giving
  the same bits with and without the define.

Every random input comes from a fixed seed, so every p-value is deterministic.
"""
from __future__ import annotations

from functools import partial

import numpy as np
import pytest

cl = pytest.importorskip("pyopencl")
pytest.importorskip("scipy.stats")  # test_sampling needs it
special = pytest.importorskip("scipy.special")

from test_sampling import (  # noqa: E402
    N_COS,
    PHI_I,
    RECIPROCITY_MATERIALS,
    Kit,
    Out,
    chi2_pvalue,
    direction,
    fresnel_ref,
    histogram_sphere,
    integrate_cells,
    random_directions,
    sphere_quadrature,
    uniform,
)

from pyclpt.buffers.materials import MAT_FDR_INT, MAT_RP_TRANS, fresnel_dielectric, pack_material  # noqa: E402
from pyclpt.buffers.microfacet import RP_KNOTS, rough_reflectance, rough_transmittance  # noqa: E402
from pyclpt.scene.mitsuba_dict import METALS  # noqa: E402
from pyclpt.scene.model import Conductor, Dielectric, Plastic, ThinDielectric  # noqa: E402

FLIP = np.float32([1, 1, -1])
# Significance of each chi-square test: about 0.01 for the whole file after Sidak's correction for its ~60
# chi-square tests (as Mitsuba's chi2 tests correct for their number); a broken lobe scores p < 1e-20.
P_MIN = 1e-4


ANISO_KERNELS = r"""
/* per item (m[3], v[3], alpha_u, alpha_v, beckmann, pad[3]) -> (D(m), G1(v, m), pdf_visible(v, m)) */
__kernel void mf_aniso_k(__global const float* in, __global float* out) {
    int i = get_global_id(0);
    __global const float* p = in + 12 * i;
    Microfacet d;
    d.alpha = p[6];
    d.alpha_v = p[7];
    d.beckmann = p[8] != 0.0f;
    vec3 m = load3(p, 0), v = load3(p, 1);
    vstore3((float3)(mf_d(d, m), mf_g1(d, v, m), mf_pdf_visible(d, v, m)), i, out);
}

/* per item (wi[3], alpha_u, alpha_v, beckmann, u[2]) -> sampled visible normal */
__kernel void mf_aniso_sample_k(__global const float* in, __global float* out) {
    int i = get_global_id(0);
    __global const float* p = in + 8 * i;
    Microfacet d;
    d.alpha = p[3];
    d.alpha_v = p[4];
    d.beckmann = p[5] != 0.0f;
    store3(out, i, mf_sample_visible(d, load3(p, 0), v2(p[6], p[7])));
}
"""


@pytest.fixture(scope="module")
def kit(device) -> Kit:
    """The test kernels with anisotropic roughness compiled in (isotropic materials give the same bits:
    test_isotropic_unchanged_by_the_anisotropy_define)."""
    return Kit(device, defines={"SCENE_HAS_ANISOTROPY": 1}, extra=ANISO_KERNELS)


# --------------------------------------------------------------------------
# numpy references (float64)


fresnel = fresnel_dielectric  # the host's float64 Fresnel (pyclpt/material_buffers.py)


def ndf(m, alpha, beckmann):
    """D(m) of GGX or Beckmann."""
    c2 = m[..., 2] ** 2
    xy2 = m[..., 0] ** 2 + m[..., 1] ** 2
    a2 = alpha * alpha
    if beckmann:
        d = np.exp(-xy2 / (a2 * c2)) / (np.pi * a2 * c2 * c2)
    else:
        d = 1.0 / (np.pi * a2 * (xy2 / a2 + c2) ** 2)
    return np.where(m[..., 2] > 0, d, 0.0)


def g1_exact(v, m, alpha, beckmann):
    """Smith G1 with scipy's erfc (the device's closed forms checked independently of pyclpt.buffers.microfacet)."""
    xy = np.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.abs(v[..., 2]) / (alpha * xy)
        if beckmann:
            lam = 0.5 * (np.exp(-a * a) / (a * np.sqrt(np.pi)) - special.erfc(a))
        else:
            lam = 0.5 * (np.sqrt(1.0 + 1.0 / (a * a)) - 1.0)
        g = np.where(xy == 0, 1.0, 1.0 / (1.0 + lam))
    return np.where((v * m).sum(-1) * v[..., 2] <= 0, 0.0, g)


def ndf_aniso(m, au, av, beckmann):
    """D(m) of anisotropic GGX or Beckmann (Mitsuba's MicrofacetDistribution::eval)."""
    c2 = m[..., 2] ** 2
    q = (m[..., 0] / au) ** 2 + (m[..., 1] / av) ** 2
    if beckmann:
        d = np.exp(-q / c2) / (np.pi * au * av * c2 * c2)
    else:
        d = 1.0 / (np.pi * au * av * (q + c2) ** 2)
    return np.where(m[..., 2] > 0, d, 0.0)


def g1_aniso(v, m, au, av, beckmann):
    """Smith G1 of the anisotropic distribution: the isotropic one at the projected roughness
    sqrt(au^2 cos^2 phi + av^2 sin^2 phi) of v's azimuth."""
    xy2 = v[..., 0] ** 2 + v[..., 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.sqrt(np.where(xy2 > 0, ((au * v[..., 0]) ** 2 + (av * v[..., 1]) ** 2) / xy2, au * av))
    return g1_exact(v, m, a, beckmann)


def spec_weight(mat_obj) -> float:
    """Mitsuba's m_specular_sampling_weight for constant colours."""
    s, d = np.mean(mat_obj.specular_reflectance), np.mean(mat_obj.diffuse_reflectance)
    return s / (s + d)


def knots_of(rec) -> np.ndarray:
    return np.asarray(rec[MAT_RP_TRANS:MAT_RP_TRANS + RP_KNOTS // 2], np.float32).view(np.float16).astype(np.float64)


def knot_lerp(knots, cos_theta):
    """The device's interpolation of the rough coating's transmittance, linear in sqrt(cos)."""
    x = np.sqrt(np.clip(cos_theta, 0.0, 1.0)) * (RP_KNOTS - 1)
    return np.interp(x, np.arange(RP_KNOTS), knots)


# --------------------------------------------------------------------------
# 1. Microfacet distributions


@pytest.mark.parametrize("beckmann", [False, True], ids=["ggx", "beckmann"])
def test_microfacet_functions(kit, beckmann):
    """D against its closed form and its normalisation, G1 against scipy, the visible-normal pdf's
    normalisation (Smith's identity) for several incident directions."""
    dirs, weights = sphere_quadrature(0.0, sub_t=8, sub_p=4)
    m = dirs.reshape(-1, 3)
    for alpha in (0.05, 0.3, 0.8):
        for cos_i in (1.0, 0.4, 0.02):
            wi = np.broadcast_to(direction(cos_i, PHI_I), m.shape)
            rec = np.zeros((len(m), 8), np.float32)
            rec[:, 0:3], rec[:, 3:6], rec[:, 6], rec[:, 7] = m, wi, alpha, float(beckmann)
            out = kit.run("microfacet_k", len(m), rec, Out(len(m), 3)).astype(np.float64)
            md, wid = m.astype(np.float64), wi.astype(np.float64)
            if cos_i == 1.0:
                np.testing.assert_allclose(out[:, 0], ndf(md, alpha, beckmann), rtol=2e-5, atol=1e-18)
                norm = integrate_cells(out[:, 0] * md[:, 2], weights).sum()
                assert abs(norm - 1.0) < 2e-3, f"integral of D cos = {norm} (alpha {alpha})"
            np.testing.assert_allclose(out[:, 1], g1_exact(wid, md, alpha, beckmann), rtol=2e-5, atol=2e-6)
            vis = integrate_cells(out[:, 2], weights).sum()
            assert abs(vis - 1.0) < 3e-3, f"visible normals of cos_i {cos_i}, alpha {alpha} integrate to {vis}"


@pytest.mark.parametrize("beckmann", [False, True], ids=["ggx", "beckmann"])
@pytest.mark.parametrize("alpha,cos_i", [(0.05, 0.3), (0.3, 1.0), (0.3, 0.05), (0.8, 0.6)])
def test_visible_normal_sampling_chi2(kit, beckmann, alpha, cos_i):
    """mf_sample_visible against mf_pdf_visible, in the space of normals."""
    n = 100_000
    wi = direction(cos_i, PHI_I)
    u = uniform(7000 + int(alpha * 100) + int(cos_i * 10) + 1000 * beckmann, n, 2)
    rec = np.zeros((n, 8), np.float32)
    rec[:, 0:3], rec[:, 3], rec[:, 4], rec[:, 5:7] = wi, alpha, float(beckmann), u
    m = kit.run("microfacet_sample_k", n, rec, Out(n, 3))
    assert np.all(np.isfinite(m)) and np.all(m[:, 2] > 0)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1.0, atol=1e-5)
    dirs, weights = sphere_quadrature(0.0, sub_t=16, sub_p=4)
    q = dirs.reshape(-1, 3)
    rq = np.zeros((len(q), 8), np.float32)
    rq[:, 0:3], rq[:, 3:6], rq[:, 6], rq[:, 7] = q, wi, alpha, float(beckmann)
    pdf = kit.run("microfacet_k", len(q), rq, Out(len(q), 3))[:, 2]
    cells = integrate_cells(pdf, weights)
    p, diag = chi2_pvalue(histogram_sphere(m, 0.0), n * cells / cells.sum())
    assert abs(cells.sum() - 1.0) < 5e-3
    assert p > P_MIN, f"visible normals (alpha {alpha}, cos {cos_i}): p={p:.2e} ({diag})"


ANISO = [(0.05, 0.4), (0.5, 0.1)]


@pytest.mark.parametrize("beckmann", [False, True], ids=["ggx", "beckmann"])
def test_anisotropic_microfacet_functions(kit, beckmann):
    """Anisotropic D against its closed form and its normalisation, G1 against scipy at the projected
    roughness, the visible-normal pdf's normalisation."""
    dirs, weights = sphere_quadrature(0.0, sub_t=8, sub_p=4)
    m = dirs.reshape(-1, 3)
    for au, av in ANISO:
        for cos_i in (1.0, 0.4, 0.05):
            wi = np.broadcast_to(direction(cos_i, PHI_I), m.shape)
            rec = np.zeros((len(m), 12), np.float32)
            rec[:, 0:3], rec[:, 3:6], rec[:, 6], rec[:, 7], rec[:, 8] = m, wi, au, av, float(beckmann)
            out = kit.run("mf_aniso_k", len(m), rec, Out(len(m), 3)).astype(np.float64)
            md, wid = m.astype(np.float64), wi.astype(np.float64)
            if cos_i == 1.0:
                np.testing.assert_allclose(out[:, 0], ndf_aniso(md, au, av, beckmann), rtol=2e-5, atol=1e-18)
                norm = integrate_cells(out[:, 0] * md[:, 2], weights).sum()
                assert abs(norm - 1.0) < 2e-3, f"integral of D cos = {norm} (alpha {au}, {av})"
            np.testing.assert_allclose(out[:, 1], g1_aniso(wid, md, au, av, beckmann), rtol=2e-5, atol=2e-6)
            vis = integrate_cells(out[:, 2], weights).sum()
            assert abs(vis - 1.0) < 3e-3, f"visible normals of cos_i {cos_i}, alpha ({au}, {av}) integrate to {vis}"


@pytest.mark.parametrize("beckmann", [False, True], ids=["ggx", "beckmann"])
@pytest.mark.parametrize("au,av,cos_i", [(0.05, 0.4, 0.3), (0.5, 0.1, 0.8), (0.3, 0.05, 0.05)])
def test_anisotropic_visible_normal_sampling_chi2(kit, beckmann, au, av, cos_i):
    """mf_sample_visible against mf_pdf_visible for alpha_u != alpha_v, in the space of normals."""
    n = 100_000
    wi = direction(cos_i, PHI_I)
    u = uniform(7500 + int(au * 100) + int(cos_i * 10) + 1000 * beckmann, n, 2)
    rec = np.zeros((n, 8), np.float32)
    rec[:, 0:3], rec[:, 3], rec[:, 4], rec[:, 5], rec[:, 6:8] = wi, au, av, float(beckmann), u
    m = kit.run("mf_aniso_sample_k", n, rec, Out(n, 3))
    assert np.all(np.isfinite(m)) and np.all(m[:, 2] > 0)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1.0, atol=1e-5)
    dirs, weights = sphere_quadrature(0.0, sub_t=16, sub_p=8)
    q = dirs.reshape(-1, 3)
    rq = np.zeros((len(q), 12), np.float32)
    rq[:, 0:3], rq[:, 3:6], rq[:, 6], rq[:, 7], rq[:, 8] = q, wi, au, av, float(beckmann)
    pdf = kit.run("mf_aniso_k", len(q), rq, Out(len(q), 3))[:, 2]
    cells = integrate_cells(pdf, weights)
    p, diag = chi2_pvalue(histogram_sphere(m, 0.0), n * cells / cells.sum())
    assert abs(cells.sum() - 1.0) < 5e-3
    assert p > P_MIN, f"visible normals (alpha {au}, {av}, cos {cos_i}): p={p:.2e} ({diag})"


def test_isotropic_unchanged_by_the_anisotropy_define(device, kit):
    """Isotropic rough materials evaluate and sample to the same bits with -DSCENE_HAS_ANISOTROPY as
    without it (the scenes without anisotropic materials compile without it)."""
    plain = Kit(device)
    # A GPU compiler contracts a * b + c into FMAs per program, so two programs can differ in the last bits
    # there (NVIDIA's OpenCL: 2.4e-7 at most); CPU devices give the same bits.
    same = np.testing.assert_array_equal if device.is_cpu else partial(np.testing.assert_allclose, rtol=4e-6,
                                                                         atol=1e-7)
    n = 5000
    wi = random_directions(161, n, hemisphere=False)
    wo = random_directions(162, n, hemisphere=False)
    u = uniform(163, n, 3)
    for obj in (Conductor(*METALS["Cu"], alpha=0.2), Conductor(*METALS["Au"], alpha=0.5, distribution="beckmann"),
                _glass(0.3, "ggx"), _glass(0.1, "beckmann"), Plastic(alpha=0.3, distribution="beckmann"),
                Conductor(*METALS["Cu"], alpha=0.2, alpha_v=0.2)):
        mat = pack_material(obj)
        same(kit.eval(mat, wi, wo), plain.eval(mat, wi, wo))
        a, b = kit.sample(mat, wi, u), plain.sample(mat, wi, u)
        for key in a:
            same(a[key], b[key], err_msg=f"{obj}: {key}")


def test_erfinv(kit):
    x = np.concatenate([np.linspace(-0.999999, 0.999999, 20001), [0.0, 1e-7, -1e-7, 0.9999, -0.99999]])
    x = x.astype(np.float32)
    got = kit.run("erfinv_k", len(x), x, Out(len(x))).astype(np.float64)
    want = special.erfinv(x.astype(np.float64))
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-7)


# --------------------------------------------------------------------------
# 2. Sampling against evaluation, per material and parameter set

N_S = 200_000
SPHERE = (-1.0, 2 * N_COS)  # cos_lo, rows: the rough dielectric's cells cover the sphere
HEMI = (0.0, N_COS)


def _glass(alpha, dist, int_ior=1.5, ext_ior=1.0):
    return Dielectric(int_ior, ext_ior, (0.9, 0.8, 0.7), (0.6, 0.7, 0.8), alpha=alpha, distribution=dist)


CASES: dict[str, tuple] = {}
for _d in ("ggx", "beckmann"):
    for _a, _co, _ci in ((0.05, 0.7, -0.85), (0.3, 0.4, -0.5), (0.8, 0.15, -0.3)):
        # from outside (eta 1.5) and from inside (eta 1 / 1.5: beyond the smooth critical angle for
        # -0.5 and -0.3, where only the roughness lets light out)
        CASES[f"roughglass-{_d}-a{_a}-out{_co}"] = (_glass(_a, _d), _co, SPHERE)
        CASES[f"roughglass-{_d}-a{_a}-in{-_ci}"] = (_glass(_a, _d), _ci, SPHERE)
# an interface with int_ior < ext_ior (an air bubble in water) seen from outside
CASES["roughbubble-ggx-a0.3-out0.6"] = (_glass(0.3, "ggx", 1.0, 1.333), 0.6, SPHERE)
CASES["roughbubble-beckmann-a0.3-out0.9"] = (_glass(0.3, "beckmann", 1.0, 1.333), 0.9, SPHERE)
for _d in ("ggx", "beckmann"):
    for _a, _c, _nl in ((0.05, 0.8, False), (0.3, 0.5, True), (0.8, 0.1, _d == "ggx")):
        CASES[f"roughplastic-{_d}-a{_a}-cos{_c}-{'nl' if _nl else 'lin'}"] = (
            Plastic((0.7, 0.4, 0.2), (1.0, 0.9, 0.8), 1.5, 1.0, alpha=_a, distribution=_d, nonlinear=_nl), _c, HEMI)
for _c, _nl in ((0.8, False), (0.3, True), (0.05, False)):
    CASES[f"plastic-cos{_c}-{'nl' if _nl else 'lin'}"] = (
        Plastic((0.7, 0.4, 0.2), (1.0, 0.9, 0.8), 1.5, 1.0, nonlinear=_nl), _c, HEMI)
for _a, _c in ((0.05, 0.6), (0.05, 0.1), (0.3, 1.0), (0.8, 0.1)):
    CASES[f"roughcu-beckmann-a{_a}-cos{_c}"] = (
        Conductor(*METALS["Cu"], alpha=_a, specular_reflectance=(0.9, 1.0, 0.8), distribution="beckmann"), _c, HEMI)
# anisotropic: alpha (alpha_u) along x, alpha_v along y; wi at azimuth PHI_I sees both
for _d, (_au, _av), _c in (("ggx", (0.05, 0.4), 0.6), ("beckmann", (0.05, 0.4), 0.3), ("ggx", (0.6, 0.1), 0.1),
                           ("beckmann", (0.5, 0.15), 0.9)):
    CASES[f"roughal-{_d}-a{_au}x{_av}-cos{_c}"] = (
        Conductor(*METALS["Al"], alpha=_au, alpha_v=_av, distribution=_d), _c, HEMI)
for _d, (_au, _av), _c in (("ggx", (0.1, 0.5), 0.7), ("beckmann", (0.4, 0.05), -0.6), ("ggx", (0.3, 0.08), -0.3),
                           ("beckmann", (0.08, 0.3), 0.4)):
    CASES[f"roughglass-{_d}-a{_au}x{_av}-{'out' if _c > 0 else 'in'}{abs(_c)}"] = (
        Dielectric(1.5, 1.0, (0.9, 0.8, 0.7), (0.6, 0.7, 0.8), alpha=_au, distribution=_d, alpha_v=_av), _c, SPHERE)


def run_case(kit, case: str):
    """Samples, their eval, and the cell integrals of eval's pdf and value (cached per case)."""
    key = ("bsdf-new", case)
    if key not in kit.cache:
        mat_obj, cos_i, (cos_lo, n_cos) = CASES[case]
        mat = pack_material(mat_obj)
        wi = direction(abs(cos_i), PHI_I) * (FLIP if cos_i < 0 else np.float32(1))
        seed = 5000 + list(CASES).index(case)
        s = kit.sample(mat, wi, uniform(seed, N_S, 3))
        cells = kit.adaptive_cells(mat, wi, N_S, cos_lo=cos_lo, n_cos=n_cos)
        kit.cache[key] = (mat_obj, mat, wi, s, cells[..., 3], cells[..., :3])
    return kit.cache[key]


@pytest.mark.parametrize("case", list(CASES))
def test_chi2(kit, case):
    mat_obj, _, wi, s, pdf_cells, _ = run_case(kit, case)
    cos_lo, n_cos = CASES[case][2]
    smooth = s["ok"] & ~s["delta"]
    if cos_lo == 0.0:
        assert np.all(s["wo"][s["ok"], 2] > 0), "a reflective material sampled below the surface"
    total = pdf_cells.sum()
    assert total <= 1.0 + 1e-3, f"eval pdf integrates to {total} > 1"
    observed = np.append(histogram_sphere(s["wo"][smooth], cos_lo, n_cos).ravel(), np.count_nonzero(~smooth))
    expected = np.append(N_S * pdf_cells.ravel(), max(N_S * (1.0 - total), 0.0))
    p, diag = chi2_pvalue(observed, expected)
    assert p > P_MIN, f"{case}: sampled wo vs bsdf_eval pdf: p={p:.2e} ({diag}); pdf integral {total:.5f}"


@pytest.mark.parametrize("case", list(CASES))
def test_sample_matches_eval(kit, case):
    mat_obj, _, wi, s, _, _ = run_case(kit, case)
    ok = s["ok"] & ~s["delta"]
    assert ok.mean() > 0.05
    pdf, epdf = s["pdf"][ok].astype(np.float64), s["eval_pdf"][ok].astype(np.float64)
    assert np.all(pdf > 0) and np.all(np.isfinite(pdf))
    np.testing.assert_allclose(pdf, epdf, rtol=2e-3, err_msg=f"{case}: bs.pdf vs bsdf_eval pdf")
    weight = s["weight"][ok].astype(np.float64)
    expect = s["value"][ok].astype(np.float64) / epdf[:, None]
    assert np.all(np.isfinite(weight)) and np.all(weight >= 0)
    np.testing.assert_allclose(weight, expect, rtol=2e-3, atol=1e-6,
                               err_msg=f"{case}: bs.weight vs bsdf_eval value / pdf")
    crossed = s["wo"][ok, 2] * wi[2] < 0
    if isinstance(mat_obj, Dielectric):
        eta = mat_obj.int_ior / mat_obj.ext_ior
        eta_it = eta if wi[2] > 0 else 1.0 / eta
        np.testing.assert_allclose(s["eta"][ok][crossed], eta_it, rtol=1e-6)
        assert crossed.any() and (~crossed).any(), "both lobes of the rough dielectric are sampled"
    else:
        assert not crossed.any()
    np.testing.assert_array_equal(s["eta"][ok][~crossed], 1.0)
    assert not s["is_delta"].any()


@pytest.mark.parametrize("case", list(CASES))
def test_albedo_sampled_vs_integrated(kit, case):
    """Mean weight of the non-delta samples (others count 0) = quadrature of bsdf_eval's value."""
    mat_obj, _, wi, s, _, value_cells = run_case(kit, case)
    smooth = s["ok"] & ~s["delta"]
    w = np.where(smooth[:, None], s["weight"], 0.0).astype(np.float64)
    mean, err = w.mean(axis=0), w.std(axis=0) / np.sqrt(N_S)
    integral = value_cells.sum(axis=(0, 1))
    assert np.all(np.abs(mean - integral) <= 5 * err + 2e-3 * integral), \
        f"{case}: sampled albedo {mean} vs integrated {integral} (+-{err})"
    if isinstance(mat_obj, Plastic) and mat_obj.alpha == 0:
        # the delta coating lobe: mean weight F(cos_i) * specular_reflectance
        d = np.where(s["delta"][:, None], s["weight"], 0.0).astype(np.float64)
        f_i = fresnel(wi[2], 1.5)
        np.testing.assert_allclose(d.mean(axis=0), f_i * np.array(mat_obj.specular_reflectance),
                                   atol=5 * d.std(axis=0).max() / np.sqrt(N_S) + 1e-6)


# --------------------------------------------------------------------------
# 3. Energy


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.8])
def test_roughdielectric_energy(kit, dist, alpha):
    """White rough glass: reflected + transmitted energy (the eta_ti^2 radiance scaling of the weights
    undone) <= 1, each equal to the host's single-scattering integrals (pyclpt/microfacet.py), and the
    transmitted radiance weight carries exactly eta_ti^2."""
    mat = pack_material(Dielectric(1.5, 1.0, alpha=alpha, distribution=dist))
    n = 100_000
    for k, cos_i in enumerate((1.0, 0.3, -0.9, -0.5)):
        wi = direction(abs(cos_i), PHI_I) * (FLIP if cos_i < 0 else np.float32(1))
        s = kit.sample(mat, wi, uniform(8000 + k + int(100 * alpha), n, 3))
        ok = s["ok"]
        crossed = ok & (s["wo"][:, 2] * wi[2] < 0)
        refl = ok & ~crossed
        eta_it = 1.5 if cos_i > 0 else 1 / 1.5
        w = s["weight"][:, 0].astype(np.float64)
        np.testing.assert_allclose(w[crossed] * eta_it**2, np.minimum(w[crossed] * eta_it**2, 1.0 + 1e-5))
        r = np.where(refl, w, 0.0)
        t = np.where(crossed, w * eta_it**2, 0.0)
        e = r + t
        tol = 5 * e.std() / np.sqrt(n)
        assert e.mean() <= 1.0 + tol + 1e-6, f"cos {cos_i}: energy {e.mean()} > 1"
        want_r = rough_reflectance([abs(cos_i)], alpha, eta_it, dist == "beckmann")[0]
        want_t = rough_transmittance([abs(cos_i)], alpha, eta_it, dist == "beckmann")[0]
        assert abs(r.mean() - want_r) < 5 * r.std() / np.sqrt(n) + 3e-3, f"cos {cos_i}: R {r.mean()} vs {want_r}"
        assert abs(t.mean() - want_t) < 5 * t.std() / np.sqrt(n) + 3e-3, f"cos {cos_i}: T {t.mean()} vs {want_t}"
        if alpha == 0.05 and abs(cos_i) >= 0.5 and not (cos_i < 0 and abs(cos_i) < 0.75):
            assert e.mean() > 0.99, f"near-smooth glass loses {1 - e.mean()} at cos {cos_i}"


@pytest.mark.parametrize("alpha,dist,nonlinear", [(0.0, "ggx", False), (0.0, "ggx", True), (0.05, "ggx", False),
                                                  (0.3, "beckmann", True), (0.8, "ggx", False),
                                                  (0.8, "beckmann", False)])
def test_plastic_furnace(kit, alpha, dist, nonlinear):
    """Diffuse 1 and specular 1: the plastic reflects at most everything. The smooth one reflects exactly
    everything (F_i + (1 - F_i) (1 - Fdr_ext) / (eta^2 (1 - Fdr_int)) = 1); the rough one what the host's
    single-scattering integrals predict, R(cos_i) + t(cos_i) T_ext / (eta^2 (1 - r_int)) with T_ext the
    cosine-weighted mean of t: less than 1, since Mitsuba's coating loses the light its single-scattering
    model does not follow (inside the coating too, where r_int undercounts total internal reflection)."""
    mat = pack_material(Plastic((1, 1, 1), (1, 1, 1), 1.5, 1.0, alpha=alpha, distribution=dist, nonlinear=nonlinear))
    if alpha > 0:
        mu = (np.arange(2000) + 0.5) / 2000
        t_ext = np.mean(knot_lerp(knots_of(mat), mu) * 2 * mu)
        diffuse_part = t_ext / (1.5**2 * (1 - float(mat[MAT_FDR_INT])))
    n = 100_000
    for k, cos_i in enumerate((1.0, 0.5, 0.1)):
        s = kit.sample(mat, direction(cos_i, PHI_I), uniform(8100 + k + int(100 * alpha), n, 3))
        w = np.where(s["ok"], s["weight"][:, 0], 0.0).astype(np.float64)
        mean, err = w.mean(), w.std() / np.sqrt(n)
        assert mean <= 1.0 + 5 * err + 1e-3, f"cos {cos_i}: albedo {mean} > 1"
        if alpha == 0.0:
            assert abs(mean - 1.0) < 5 * err + 1e-3, f"smooth white plastic albedo {mean} != 1"
        else:
            want = (rough_reflectance([cos_i], alpha, 1.5, dist == "beckmann")[0]
                    + knot_lerp(knots_of(mat), cos_i) * diffuse_part)
            assert abs(mean - want) < 5 * err + 3e-3, f"cos {cos_i}: albedo {mean}, host integrals {want}"


@pytest.mark.parametrize("alpha", [0.05, 0.8])
def test_beckmann_conductor_furnace(kit, alpha):
    """Metal 'none' (F = 1) with Beckmann: weights G1 <= 1, albedo <= 1, and ~1 when nearly smooth."""
    mat = pack_material(Conductor(*METALS["none"], alpha=alpha, distribution="beckmann"))
    n = 100_000
    for k, cos_i in enumerate((1.0, 0.6, 0.1)):
        s = kit.sample(mat, direction(cos_i, PHI_I), uniform(8200 + k, n, 3))
        w = np.where(s["ok"][:, None], s["weight"], 0.0).astype(np.float64)
        assert np.all(s["weight"][s["ok"]] <= 1.0 + 1e-5)
        mean, err = w.mean(axis=0), w.std(axis=0) / np.sqrt(n)
        assert np.all(mean <= 1.0 + 5 * err + 1e-6)
        if alpha == 0.05 and cos_i >= 0.5:
            assert np.all(mean > 0.99), f"albedo {mean}"


# --------------------------------------------------------------------------
# 4. Reference formulas


@pytest.mark.parametrize("ior", [1.5046, 1.333, 1.0])
def test_thindielectric(kit, ior):
    """R' = 2R / (1 + R) (= R + T^2 R / (1 - R^2)), T' = 1 - R', straight through, both sides, eta 1."""
    spec_r, spec_t = (0.9, 0.8, 0.7), (0.6, 0.5, 0.4)
    mat = pack_material(ThinDielectric(ior, 1.0, spec_r, spec_t))
    n = 4000
    up = random_directions(91, n)
    wi = np.concatenate([up, up * FLIP])
    r0 = fresnel(np.abs(wi[:, 2]), ior)
    want_r = 2 * r0 / (1 + r0)
    np.testing.assert_allclose(want_r, r0 + (1 - r0) ** 2 * r0 / (1 - r0**2), rtol=1e-12)
    one = np.float32(1) - np.float32(2**-24)
    r = kit.sample(mat, wi, np.column_stack([np.zeros(2 * n), uniform(92, 2 * n, 2)]))
    t = kit.sample(mat, wi, np.column_stack([np.full(2 * n, one), uniform(93, 2 * n, 2)]))
    assert t["ok"].all() and t["delta"].all() and t["is_delta"].all()
    np.testing.assert_array_equal(t["wo"], -wi)
    np.testing.assert_allclose(t["pdf"], 1 - want_r, atol=2e-6)
    np.testing.assert_allclose(t["weight"], np.broadcast_to(spec_t, (2 * n, 3)), rtol=1e-6)
    np.testing.assert_array_equal(t["eta"], 1.0)
    np.testing.assert_array_equal(t["value"], 0.0)
    np.testing.assert_array_equal(t["eval_pdf"], 0.0)
    if ior == 1.0:  # R' is 0 up to float rounding: u_lobe = 0 may still pick a reflection of probability ~0
        refl = r["ok"] & (r["wo"][:, 2] * wi[:, 2] > 0)
        assert np.all(r["pdf"][refl] < 1e-6), "an index-matched sheet reflects"
        return
    assert r["ok"].all() and r["delta"].all()
    np.testing.assert_allclose(r["wo"], wi * np.float32([-1, -1, 1]), atol=1e-7)
    np.testing.assert_allclose(r["pdf"], want_r, atol=2e-6, rtol=1e-5)
    np.testing.assert_allclose(r["pdf"] + t["pdf"], 1.0, atol=1e-6)
    np.testing.assert_allclose(r["weight"], np.broadcast_to(spec_r, (2 * n, 3)), rtol=1e-6)
    np.testing.assert_array_equal(r["eta"], 1.0)
    # random u_lobe: the reflected fraction is R'
    m = 200_000
    s = kit.sample(mat, direction(0.3, PHI_I), uniform(94, m, 3))
    want = 2 * fresnel(0.3, ior) / (1 + fresnel(0.3, ior))
    frac = np.mean(s["wo"][:, 2] > 0)
    assert abs(frac - want) < 5 * np.sqrt(want * (1 - want) / m)


@pytest.mark.parametrize("nonlinear", [False, True], ids=["lin", "nl"])
@pytest.mark.parametrize("twosided", [False, True], ids=["one", "two"])
def test_plastic_reference(kit, nonlinear, twosided):
    """Smooth plastic against Mitsuba 3's plastic.cpp: the lobe probability F_i s / (F_i s + (1 - F_i)(1 - s)),
    the delta weight F_i spec / p_spec, the diffuse value diff / (1 - (nonlinear ? diff fdr : fdr)) / eta^2
    (1 - F_i)(1 - F_o) cos_o / pi and its pdf (1 - p_spec) cos_o / pi."""
    obj = Plastic((0.7, 0.4, 0.2), (1.0, 0.9, 0.6), 1.6, 1.1, nonlinear=nonlinear, twosided=twosided)
    mat = pack_material(obj)
    eta = 1.6 / 1.1
    fdr = float(mat[MAT_FDR_INT])
    n = 20_000
    wi, wo = random_directions(95, n), random_directions(96, n)
    f_i, f_o = fresnel(wi[:, 2], eta), fresnel(wo[:, 2], eta)
    sw = spec_weight(obj)
    ps = f_i * sw / (f_i * sw + (1 - f_i) * (1 - sw))
    diff = np.array(obj.diffuse_reflectance)
    base = diff / (1 - (diff * fdr if nonlinear else fdr)) / eta**2 / np.pi
    want = base[None, :] * ((1 - f_i) * (1 - f_o) * wo[:, 2])[:, None]
    sides = [(wi, wo)] + ([(wi * FLIP, wo * FLIP)] if twosided else [])
    for a, b in sides:
        out = kit.eval(mat, a, b)
        np.testing.assert_allclose(out[:, :3], want, rtol=2e-5, atol=1e-7)
        np.testing.assert_allclose(out[:, 3], (1 - ps) * wo[:, 2] / np.pi, rtol=2e-5, atol=1e-7)
        s = kit.sample(mat, a, np.column_stack([np.zeros(n), uniform(97, n, 2)]))  # u_lobe 0: specular
        spec = s["delta"]
        assert spec.all() and not s["is_delta"].any()
        np.testing.assert_allclose(s["pdf"], ps, rtol=2e-5)
        np.testing.assert_allclose(s["weight"], (f_i / ps)[:, None] * np.array(obj.specular_reflectance), rtol=2e-5)
        np.testing.assert_allclose(s["wo"], a * np.float32([-1, -1, 1]), atol=1e-7)
    if not twosided:
        assert not kit.sample(mat, wi * FLIP, uniform(98, n, 3))["ok"].any()
        np.testing.assert_array_equal(kit.eval(mat, wi * FLIP, wo * FLIP), 0.0)
        np.testing.assert_array_equal(kit.eval(mat, wi * FLIP, wo), 0.0)
    np.testing.assert_array_equal(kit.eval(mat, wi, wo * FLIP), 0.0)


@pytest.mark.parametrize("alpha,dist", [(0.05, "ggx"), (0.3, "beckmann"), (0.8, "ggx"), (0.5, "beckmann")])
@pytest.mark.parametrize("nonlinear", [False, True], ids=["lin", "nl"])
def test_roughplastic_reference(kit, alpha, dist, nonlinear):
    """Rough plastic against Mitsuba 3's roughplastic.cpp: F D G / (4 cos_i) spec + diff / (1 - (nonlinear ?
    diff r_int : r_int)) / eta^2 t_i t_o cos_o / pi, pdf p_spec D G1(wi) / (4 cos_i) + (1 - p_spec) cos_o / pi
    with p_spec from (1 - t_i) s : t_i (1 - s); t from the record's knots, r_int the record's."""
    obj = Plastic((0.7, 0.4, 0.2), (1.0, 0.9, 0.6), 1.5, 1.0, alpha=alpha, distribution=dist, nonlinear=nonlinear)
    mat = pack_material(obj)
    beck = dist == "beckmann"
    knots, r_int = knots_of(mat), float(mat[MAT_FDR_INT])
    n = 20_000
    wi, wo = random_directions(101, n).astype(np.float64), random_directions(102, n).astype(np.float64)
    k = n // 2  # half of the pairs near the mirror direction, where the coating lobe is large
    wo[:k] = wi[:k] * [-1, -1, 1] + 0.2 * alpha * random_directions(103, k, hemisphere=False)
    wo[:k, 2] = np.abs(wo[:k, 2]) + 1e-3
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi32, wo32 = wi.astype(np.float32), wo.astype(np.float32)
    wi, wo = wi32.astype(np.float64), wo32.astype(np.float64)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    d = ndf(h, alpha, beck)
    g1i, g1o = g1_exact(wi, h, alpha, beck), g1_exact(wo, h, alpha, beck)
    f = fresnel((wi * h).sum(1), 1.5)
    t_i, t_o = knot_lerp(knots, wi[:, 2]), knot_lerp(knots, wo[:, 2])
    sw = spec_weight(obj)
    ps = (1 - t_i) * sw / ((1 - t_i) * sw + t_i * (1 - sw))
    diff = np.array(obj.diffuse_reflectance)
    base = diff / (1 - (diff * r_int if nonlinear else r_int)) / 1.5**2 / np.pi
    want = (np.array(obj.specular_reflectance)[None, :] * (f * d * g1i * g1o / (4 * wi[:, 2]))[:, None]
            + base[None, :] * (t_i * t_o * wo[:, 2])[:, None])
    want_pdf = ps * d * g1i / (4 * wi[:, 2]) + (1 - ps) * wo[:, 2] / np.pi
    out = kit.eval(mat, wi32, wo32).astype(np.float64)
    np.testing.assert_allclose(out[:, :3], want, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(out[:, 3], want_pdf, rtol=2e-4, atol=1e-6)
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
@pytest.mark.parametrize("alpha", [0.05, 0.4])
def test_roughconductor_reference(kit, dist, alpha):
    """Rough conductor against F(wi.h) spec D G1(wi) G1(wo) / (4 cos_i) and pdf D G1(wi) / (4 cos_i) with the
    distribution the material names (roughconductor.cpp)."""
    spec = (0.9, 1.0, 0.8)
    mat = pack_material(Conductor(*METALS["Au"], alpha=alpha, specular_reflectance=spec, distribution=dist))
    beck = dist == "beckmann"
    n = 20_000
    wi = random_directions(161, n).astype(np.float64)
    wo = wi * [-1, -1, 1] + 0.5 * alpha * random_directions(162, n, hemisphere=False)
    wo[:, 2] = np.abs(wo[:, 2]) + 1e-3
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi32, wo32 = wi.astype(np.float32), wo.astype(np.float32)
    wi, wo = wi32.astype(np.float64), wo32.astype(np.float64)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    d, g1i, g1o = ndf(h, alpha, beck), g1_exact(wi, h, alpha, beck), g1_exact(wo, h, alpha, beck)
    eta, k = np.array(METALS["Au"][0]), np.array(METALS["Au"][1])
    f = np.stack([fresnel_ref((wi * h).sum(1), eta[c] + 1j * k[c]) for c in range(3)], axis=1)
    out = kit.eval(mat, wi32, wo32).astype(np.float64)
    np.testing.assert_allclose(out[:, :3], f * np.array(spec) * (d * g1i * g1o / (4 * wi[:, 2]))[:, None],
                               rtol=3e-4, atol=1e-6)
    np.testing.assert_allclose(out[:, 3], d * g1i / (4 * wi[:, 2]), rtol=3e-4, atol=1e-6)


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_roughplastic_tables(dist):
    """The host's rough-coating integrals: the knots follow t(cos) closely, t tends to the smooth 1 - F and
    the internal reflectance to the smooth Fdr as the coating gets smooth, and rougher coatings let more
    light in at grazing incidence."""
    from pyclpt.buffers.materials import fresnel_diffuse_reflectance
    beck = dist == "beckmann"
    cos = np.linspace(0.0, 1.0, 41)
    for alpha in (0.05, 0.3, 0.8):
        mat = pack_material(Plastic(alpha=alpha, int_ior=1.5, ext_ior=1.0, distribution=dist))
        exact = rough_transmittance(cos, alpha, 1.5, beck)
        approx = knot_lerp(knots_of(mat), cos)
        err = np.abs(approx - exact)
        assert err.max() < 0.05 and (err * 2 * cos).mean() < 0.005, f"alpha {alpha}: knots off by {err.max()}"
        assert np.all((exact >= 0) & (exact <= 1))
    smooth = pack_material(Plastic(alpha=1e-4, int_ior=1.5, ext_ior=1.0, distribution=dist))
    c = cos[cos >= 0.1]
    np.testing.assert_allclose(knot_lerp(knots_of(smooth), c), 1 - fresnel(c, 1.5), atol=0.02)
    assert abs(float(smooth[MAT_FDR_INT]) - fresnel_diffuse_reflectance(1 / 1.5)) < 0.01
    rough = pack_material(Plastic(alpha=0.5, int_ior=1.5, ext_ior=1.0, distribution=dist))
    assert knots_of(rough)[1] > knots_of(smooth)[1] + 0.2
    assert float(rough[MAT_FDR_INT]) < float(smooth[MAT_FDR_INT])  # single scattering loses internal light


# Mitsuba 3.9.1's own plug-ins (tests/data/make_bsdf_reference.py): name -> (pyclpt material, tolerance
# of eval's value and pdf relative to the larger of the reference and 1e-4, why not tighter).
MITSUBA_REFERENCE = {
    "roughglass-ggx-0.3": (Dielectric(1.5, 1.0, (0.9, 0.8, 0.7), (0.6, 0.7, 0.8), alpha=0.3), 1e-4, "float32"),
    "roughglass-beckmann-0.1": (Dielectric(1.5, 1.0, alpha=0.1, distribution="beckmann"), 8e-3,
                                "Mitsuba's rational Beckmann G1 (0.35% per G1)"),
    "roughbubble-ggx-0.8": (Dielectric(1.0, 1.333, alpha=0.8), 1e-4, "float32"),
    "thin-1.5": (ThinDielectric(1.5, 1.0, (0.9, 0.8, 0.7), (0.6, 0.7, 0.8)), 0.0, "delta only"),
    "plastic-lin": (Plastic((0.7, 0.4, 0.2), (1.0, 0.9, 0.6), 1.6, 1.1), 3e-3,
                    "Mitsuba's polynomial fit of Fdr; pyclpt integrates it"),
    "plastic-nl": (Plastic((0.7, 0.4, 0.2), int_ior=1.5, ext_ior=1.0, nonlinear=True), 3e-3, "as plastic-lin"),
    "roughplastic-ggx-0.3": (Plastic((0.7, 0.4, 0.2), alpha=0.3, int_ior=1.5, ext_ior=1.0), 5e-2,
                             "10 half-float knots of t instead of 64 floats"),
    "roughplastic-beckmann-0.1-nl": (Plastic((0.7, 0.4, 0.2), alpha=0.1, distribution="beckmann", int_ior=1.5,
                                             ext_ior=1.0, nonlinear=True), 5e-2, "as roughplastic-ggx-0.3"),
    "roughplastic-ggx-0.8": (Plastic((0.9, 0.9, 0.9), (0.5, 0.5, 0.5), 1.33, 1.0, alpha=0.8), 5e-2,
                             "as roughplastic-ggx-0.3"),
    "roughconductor-beckmann-0.3": (Conductor((0.2, 0.9, 1.1), (3.9, 2.4, 2.2), alpha=0.3, distribution="beckmann"),
                                    1e-2, "as roughglass-beckmann-0.1"),
    "roughconductor-ggx-0.05x0.4": (Conductor((0.2, 0.9, 1.1), (3.9, 2.4, 2.2), alpha=0.05, alpha_v=0.4), 1e-4,
                                    "float32"),
    "roughconductor-beckmann-0.4x0.1": (Conductor((0.2, 0.9, 1.1), (3.9, 2.4, 2.2), alpha=0.4, alpha_v=0.1,
                                                  distribution="beckmann"), 1e-2, "as roughglass-beckmann-0.1"),
    "roughglass-ggx-0.1x0.5": (Dielectric(1.5, 1.0, (0.9, 0.8, 0.7), (0.6, 0.7, 0.8), alpha=0.1, alpha_v=0.5), 1e-4,
                               "float32"),
    "roughglass-beckmann-0.3x0.05": (Dielectric(1.5, 1.0, alpha=0.3, alpha_v=0.05, distribution="beckmann"), 8e-3,
                                     "as roughglass-beckmann-0.1"),
}


@pytest.fixture(scope="module")
def mitsuba_reference():
    from pathlib import Path
    path = Path(__file__).parent / "data" / "bsdf-mitsuba3-eval.npz"
    if not path.is_file():
        pytest.skip(f"{path} is missing (tests/data/make_bsdf_reference.py makes it)")
    return np.load(path)


@pytest.mark.parametrize("name", list(MITSUBA_REFERENCE))
def test_mitsuba_reference(kit, mitsuba_reference, name):
    """bsdf_eval's value and pdf against Mitsuba 3's eval / pdf at the same direction pairs; samples against
    Mitsuba's sample at the same random numbers where both use the same warp (delta lobes, Beckmann's
    visible normals, the cosine hemisphere)."""
    obj, tol, _ = MITSUBA_REFERENCE[name]
    ref = {key: mitsuba_reference[f"{name}/{key}"] for key in ("wi", "wo", "u", "value", "pdf", "s_wo", "s_weight",
                                                                "s_pdf")}
    mat = pack_material(obj)
    e = kit.eval(mat, ref["wi"], ref["wo"]).astype(np.float64)
    v, p = ref["value"].astype(np.float64), ref["pdf"].astype(np.float64)
    assert v.max() > 0 or isinstance(obj, ThinDielectric)
    err_v = np.abs(e[:, :3] - v).max(axis=1) / np.maximum(v.max(axis=1), 1e-4)
    err_p = np.abs(e[:, 3] - p) / np.maximum(p, 1e-4)
    assert err_v.max() <= tol, f"{name}: value off Mitsuba's by {err_v.max():.2e} (median {np.median(err_v):.1e})"
    assert err_p.max() <= tol, f"{name}: pdf off Mitsuba's by {err_p.max():.2e} (median {np.median(err_p):.1e})"
    alpha = getattr(obj, "alpha", 0.0)
    if isinstance(obj, Plastic) and alpha > 0:
        assert np.median(err_v) < 1e-2 and np.median(err_p) < 1e-2
    same_warp = alpha == 0 or obj.distribution == "beckmann"
    if not same_warp:
        return
    s = kit.sample(mat, ref["wi"], ref["u"])
    valid = (ref["s_pdf"] > 0) & (ref["s_weight"].max(axis=1) > 0)
    agree = s["ok"] == valid
    assert agree.mean() >= 0.97, f"{name}: a sample exists for {agree.mean():.3f} of the inputs alike"
    both = s["ok"] & valid
    exact = alpha == 0
    np.testing.assert_allclose(s["wo"][both], ref["s_wo"][both], atol=1e-6 if exact else 2e-3)
    np.testing.assert_allclose(s["weight"][both], ref["s_weight"][both], rtol=max(tol, 1e-5), atol=1e-6)
    np.testing.assert_allclose(s["pdf"][both], ref["s_pdf"][both], rtol=max(tol, 1e-5 if exact else 2e-2))


# --------------------------------------------------------------------------
# 5. Reciprocity, sidedness


RECIPROCAL = {
    "roughglass-ggx-0.3": _glass(0.3, "ggx"),
    "roughglass-beckmann-0.1": _glass(0.1, "beckmann"),
    "roughplastic-ggx-0.2": Plastic((0.7, 0.4, 0.2), alpha=0.2, nonlinear=True),
    "roughplastic-beckmann-0.6": Plastic((0.7, 0.4, 0.2), alpha=0.6, distribution="beckmann"),
    "plastic": Plastic((0.7, 0.4, 0.2)),
    "roughcu-beckmann-0.3": Conductor(*METALS["Cu"], alpha=0.3, distribution="beckmann"),
    "roughal-ggx-0.1x0.5": Conductor(*METALS["Al"], alpha=0.1, alpha_v=0.5),
    "roughglass-beckmann-0.4x0.1": Dielectric(1.5, 1.0, alpha=0.4, alpha_v=0.1, distribution="beckmann"),
}


@pytest.mark.parametrize("name", list(RECIPROCAL))
def test_reciprocity(kit, name):
    """f(wi, wo) = f(wo, wi) for reflection; for refraction f(wi, wo) / eta_i^2 = f(wo, wi) / eta_o^2
    (Veach 1997, eq. 5.14, with Mitsuba's radiance-mode wi / wo)."""
    obj = RECIPROCAL[name]
    mat = pack_material(obj)
    n = 50_000
    wi = random_directions(111, n, hemisphere=False)
    wo = random_directions(112, n, hemisphere=False)
    if not isinstance(obj, Dielectric):
        wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.01, np.abs(wo[:, 2]) + 0.01
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    a, b = kit.eval(mat, wi, wo), kit.eval(mat, wo, wi)
    fa = a[:, :3].astype(np.float64) / np.abs(wo[:, 2:3])
    fb = b[:, :3].astype(np.float64) / np.abs(wi[:, 2:3])
    assert np.all(np.isfinite(fa)) and np.all(np.isfinite(fb))
    if isinstance(obj, Dielectric):
        crossed = wi[:, 2] * wo[:, 2] < 0
        eta = obj.int_ior / obj.ext_ior
        eta_i = np.where(wi[:, 2] > 0, 1.0, eta)[:, None]  # IOR on wi's side (outside = 1)
        eta_o = np.where(wo[:, 2] > 0, 1.0, eta)[:, None]
        assert fa[crossed].max() > 0 and fa[~crossed].max() > 0
        # Where wi or wo grazes the microfacet (the critical angle on the inside), 1 - F is ill-conditioned
        # in float32: such pairs only agree loosely.
        wi64, wo64 = wi.astype(np.float64), wo.astype(np.float64)
        hv = wi64 + wo64 * np.where(crossed, np.where(wi[:, 2] > 0, eta, 1.0 / eta), 1.0)[:, None]
        m = hv / np.linalg.norm(hv, axis=1, keepdims=True)
        good = np.minimum(np.abs((wi64 * m).sum(1)), np.abs((wo64 * m).sum(1))) > 0.02
        assert good.mean() > 0.95
        x, y = fa / eta_i**2, fb / eta_o**2
        np.testing.assert_allclose(x[good], y[good], rtol=1e-3, atol=1e-7, err_msg=f"{name}: generalized reciprocity")
        np.testing.assert_allclose(x, y, rtol=0.02, atol=1e-5, err_msg=f"{name}: generalized reciprocity")
    else:
        assert fa.max() > 0
        np.testing.assert_allclose(fa, fb, rtol=2e-4, atol=1e-7, err_msg=f"{name}: f(wi, wo) != f(wo, wi)")


@pytest.mark.parametrize("name", ["roughplastic-ggx-0.2", "roughplastic-beckmann-0.6", "plastic",
                                  "roughcu-beckmann-0.3", "diffuse", "roughau-0.3", "roughal-ggx-0.1x0.5"])
def test_one_sided_and_two_sided(kit, name):
    """Reflective materials are black from behind unless two-sided; two-sided mirrors the front."""
    base = {**RECIPROCITY_MATERIALS, **RECIPROCAL}[name]
    one = pack_material(base)
    two = pack_material(type(base)(**{**base.__dict__, "twosided": True}))
    assert (int(two[1]) & 1, int(one[1]) & 1) == (1, 0)  # MAT_FLAG_TWOSIDED
    n = 20_000
    wi, wo = random_directions(121, n), random_directions(122, n)
    front = kit.eval(one, wi, wo)
    assert np.all(front[:, 3] >= 0) and np.mean(front[:, 3] > 0) > 0.5 and front[:, :3].max() > 0
    np.testing.assert_array_equal(kit.eval(one, wi * FLIP, wo * FLIP), 0.0)
    np.testing.assert_array_equal(kit.eval(one, wi * FLIP, wo), 0.0)
    u = uniform(123, n, 3)
    assert not kit.sample(one, wi * FLIP, u)["ok"].any()
    np.testing.assert_array_equal(kit.eval(two, wi, wo), front)
    np.testing.assert_allclose(kit.eval(two, wi * FLIP, wo * FLIP), front, rtol=1e-6, atol=0)
    np.testing.assert_array_equal(kit.eval(two, wi * FLIP, wo)[:, :3], 0.0)
    np.testing.assert_array_equal(kit.eval(two, wi, wo * FLIP)[:, :3], 0.0)
    sf, sb = kit.sample(two, wi, u), kit.sample(two, wi * FLIP, u)
    np.testing.assert_array_equal(sb["ok"], sf["ok"])
    ok = sf["ok"]
    np.testing.assert_array_equal(sb["wo"][ok], sf["wo"][ok] * FLIP)
    np.testing.assert_array_equal(sb["weight"][ok], sf["weight"][ok])
    np.testing.assert_array_equal(sb["pdf"][ok], sf["pdf"][ok])
    np.testing.assert_array_equal(sb["delta"], sf["delta"])


def test_roughdielectric_both_sides(kit):
    """The rough dielectric ignores `twosided`: it reflects and refracts from either side, and its value
    from inside differs from outside (eta 1 / 1.5, total internal reflection for the smooth part)."""
    mat = pack_material(_glass(0.3, "ggx"))
    n = 20_000
    wi = random_directions(131, n)
    wo = random_directions(132, n, hemisphere=False)
    out, inside = kit.eval(mat, wi, wo), kit.eval(mat, wi * FLIP, wo * FLIP)
    for e in (out, inside):
        crossed = (wo[:, 2] < 0)
        assert e[crossed, :3].max() > 0 and e[~crossed, :3].max() > 0 and np.all(e[:, 3] >= 0)
    assert not np.allclose(out, inside)


def test_index_matched_roughdielectric(kit):
    """int_ior == ext_ior: an invisible interface, straight through with weight = transmittance (delta)."""
    mat = pack_material(Dielectric(1.33, 1.33, (0.9, 0.8, 0.7), (0.6, 0.5, 0.4), alpha=0.3))
    wi = random_directions(141, 1000, hemisphere=False)
    s = kit.sample(mat, wi, uniform(142, 1000, 3))
    assert s["ok"].all() and s["delta"].all() and s["is_delta"].all()
    np.testing.assert_array_equal(s["wo"], -wi)
    np.testing.assert_allclose(s["weight"], np.broadcast_to((0.6, 0.5, 0.4), (1000, 3)), rtol=1e-6)
    np.testing.assert_array_equal(s["value"], 0.0)


# --------------------------------------------------------------------------
# 6. Robustness

EXTREME = {
    "roughglass-ggx-1e-4": Dielectric(1.5, 1.0, alpha=1e-4),
    "roughglass-beckmann-1e-4": Dielectric(1.5, 1.0, alpha=1e-4, distribution="beckmann"),
    "roughglass-ggx-0.8": Dielectric(1.5, 1.0, alpha=0.8),
    "roughglass-beckmann-0.05": Dielectric(1.5, 1.0, alpha=0.05, distribution="beckmann"),
    "roughbubble-beckmann-0.8": Dielectric(1.0, 1.5, alpha=0.8, distribution="beckmann"),
    "roughglass-nearly-matched": Dielectric(1.0003, 1.0, alpha=0.3),
    "roughglass-matched": Dielectric(1.0, 1.0, alpha=0.3),
    "thin": ThinDielectric(1.5, 1.0),
    "thin-matched": ThinDielectric(1.0, 1.0),
    "plastic": Plastic(),
    "plastic-matched-nl": Plastic((1, 1, 1), int_ior=1.0, ext_ior=1.0, nonlinear=True),
    "plastic-black": Plastic((0, 0, 0)),
    "roughplastic-ggx-1e-4": Plastic(alpha=1e-4),
    "roughplastic-beckmann-1e-4": Plastic(alpha=1e-4, distribution="beckmann"),
    "roughplastic-beckmann-0.8": Plastic(alpha=0.8, distribution="beckmann", nonlinear=True),
    "roughplastic-matched": Plastic(alpha=0.3, int_ior=1.0, ext_ior=1.0),
    "roughcu-beckmann-1e-4": Conductor(*METALS["Cu"], alpha=1e-4, distribution="beckmann"),
    "roughcu-beckmann-0.8": Conductor(*METALS["Cu"], alpha=0.8, distribution="beckmann"),
    "roughcu-ggx-1e-4x0.8": Conductor(*METALS["Cu"], alpha=1e-4, alpha_v=0.8),
    "roughglass-beckmann-0.8x1e-4": Dielectric(1.5, 1.0, alpha=0.8, alpha_v=1e-4, distribution="beckmann"),
}


@pytest.mark.parametrize("name", list(EXTREME))
def test_extremes_finite(kit, name):
    """Normal, grazing, exactly tangent and denormal incidence from both sides, random numbers at the corners
    of [0, 1): no NaN, no Inf, no negative weight or pdf; eval finite everywhere on the sphere."""
    mat = pack_material(EXTREME[name])
    cos = np.array([1.0, 0.999999, 0.5, 1e-2, 1e-4, 1e-6, 1e-40, 0.0], np.float32)
    corners = np.array([0.0, 1e-7, 0.5, np.float32(1) - np.float32(2**-24)], np.float32)
    u = np.array(np.meshgrid(corners, corners, corners, indexing="ij")).reshape(3, -1).T
    u = np.concatenate([u, uniform(151, 300, 3)])
    wi = np.array([direction(c, phi) for c in cos for phi in (0.0, PHI_I)], np.float32)
    wi = np.concatenate([wi, wi * FLIP])
    WI, U = np.repeat(wi, len(u), axis=0), np.tile(u, (len(wi), 1))
    s = kit.sample(mat, WI, U)
    ok = s["ok"]
    front = WI[:, 2] > 1e-3
    assert ok[front].mean() > 0.5, f"only {ok[front].mean()} of the front-side samples succeed"
    for key in ("wo", "weight", "pdf", "eta", "value", "eval_pdf"):
        assert np.all(np.isfinite(s[key][ok])), f"non-finite {key}"
    assert np.all(np.isfinite(s["value"])) and np.all(np.isfinite(s["eval_pdf"]))
    assert np.all(s["weight"][ok] >= 0) and np.all(s["pdf"][ok] > 0) and np.all(s["eval_pdf"] >= 0)
    np.testing.assert_allclose(np.linalg.norm(s["wo"][ok], axis=1), 1.0, atol=1e-4)
    wo = random_directions(152, len(WI), hemisphere=False)
    wo[::7] = WI[::7] * np.float32([-1, -1, 1])  # mirror directions
    wo[3::7] = -WI[3::7]  # straight through
    e = kit.eval(mat, WI, wo)
    assert np.all(np.isfinite(e)) and np.all(e >= 0), f"eval: {e[~np.isfinite(e).all(1)][:3]}"
