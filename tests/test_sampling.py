"""Random numbers, warping routines and BSDFs (cl/core/rng.h, cl/core/sampling.h, cl/scene/bsdf.h) on the device.

Small test kernels call the device functions; the host checks them statistically
(chi-square goodness of fit in the spirit of Mitsuba's ``chi2`` tests, with the
expected cell counts integrated numerically from the device's own pdfs) and
against numpy references (Philox known answers, complex Fresnel equations).
Every random input comes from a fixed seed, so every p-value is deterministic.
"""
from __future__ import annotations

import numpy as np
import pytest

cl = pytest.importorskip("pyopencl")
stats = pytest.importorskip("scipy.stats")

from pyclpt.buffers.materials import pack_material  # noqa: E402
from pyclpt.device.program import build_program  # noqa: E402
from pyclpt.scene.mitsuba_dict import METALS  # noqa: E402
from pyclpt.scene.model import Conductor, Dielectric, Diffuse  # noqa: E402

KERNELS = r"""
#include "core/rng.h"
#include "scene/bsdf.h"

__kernel void philox_kat(__global const uint* ctr, __global const uint* key, __global uint* out) {
    int i = get_global_id(0);
    vstore4(philox4x32_10(vload4(i, ctr), vload2(i, key)), i, out);
}

/* keys: (seed, pixel, sample, bounce, dim) per item */
__kernel void rng_eval(__global const uint* keys, __global float* out1, __global float* out2) {
    int i = get_global_id(0);
    __global const uint* k = keys + 5 * i;
    RngKey key = rng_key(k[0], k[1], k[2]);
    out1[i] = rng_1d(key, k[3], k[4]);
    vec2 r = rng_2d(key, k[3], k[4]);
    out2[2 * i] = r.x;
    out2[2 * i + 1] = r.y;
}

/* keys: (seed, pixel, sample, bounce) per item; out: rng_light's 3 numbers, then rng_bsdf's 4 */
__kernel void rng_bounce_blocks(__global const uint* keys, __global float* out) {
    int i = get_global_id(0);
    __global const uint* k = keys + 5 * i;
    RngKey key = rng_key(k[0], k[1], k[2]);
    float sel, lobe, rr;
    vec2 lu, bu;
    rng_light(key, k[3], &sel, &lu);
    rng_bsdf(key, k[3], &lobe, &bu, &rr);
    __global float* o = out + 7 * i;
    o[0] = sel; o[1] = lu.x; o[2] = lu.y;
    o[3] = lobe; o[4] = bu.x; o[5] = bu.y; o[6] = rr;
}

__kernel void warp_eval(__global const float* u, __global float* hemi, __global float* sphere,
                        __global float* tri) {
    int i = get_global_id(0);
    vec2 uu = v2(u[2 * i], u[2 * i + 1]);
    vec3 h = square_to_cosine_hemisphere(uu);
    store3(hemi + 4 * i, 0, h);
    hemi[4 * i + 3] = cosine_hemisphere_pdf(h);
    vec3 s = square_to_uniform_sphere(uu);
    store3(sphere + 4 * i, 0, s);
    sphere[4 * i + 3] = UNIFORM_SPHERE_PDF;
    vec2 t = square_to_triangle(uu);
    tri[2 * i] = t.x;
    tri[2 * i + 1] = t.y;
}

__kernel void warp_pdf(__global const float* w, __global float* out) {
    int i = get_global_id(0);
    vec3 v = load3(w, i);
    out[2 * i] = cosine_hemisphere_pdf(v);
    out[2 * i + 1] = UNIFORM_SPHERE_PDF;
}

/* wi_stride 0: one wi for every item */
__kernel void bsdf_eval_k(__global const float* mat, __global const float* wi, int wi_stride,
                          __global const float* wo, __global float* out) {
    int i = get_global_id(0);
    float pdf = -1.0f;
    Bsdf b = bsdf_from(mat, 1);
    vec3 v = bsdf_eval(&b, load3(wi, i * wi_stride), load3(wo, i), &pdf);
    store3(out + 4 * i, 0, v);
    out[4 * i + 3] = pdf;
}

/* out per item: wo[3] weight[3] pdf eta delta ok eval_value[3] eval_pdf is_delta pad */
__kernel void bsdf_sample_k(__global const float* mat, __global const float* wi, int wi_stride,
                            __global const float* u, __global float* out) {
    int i = get_global_id(0);
    vec3 w = load3(wi, i * wi_stride);
    BsdfSample s;
    s.wo = v3_splat(0.0f);
    s.weight = v3_splat(0.0f);
    s.pdf = 0.0f;
    s.eta = 0.0f;
    s.delta = false;
    Bsdf b = bsdf_from(mat, 1);
    bool ok = bsdf_sample(&b, w, u[3 * i], v2(u[3 * i + 1], u[3 * i + 2]), &s);
    float pdf = -1.0f;
    vec3 v = bsdf_eval(&b, w, s.wo, &pdf);
    __global float* o = out + 16 * i;
    store3(o, 0, s.wo);
    store3(o, 1, s.weight);
    o[6] = s.pdf;
    o[7] = s.eta;
    o[8] = s.delta ? 1.0f : 0.0f;
    o[9] = ok ? 1.0f : 0.0f;
    store3(o + 10, 0, v);
    o[13] = pdf;
    o[14] = bsdf_is_delta(&b) ? 1.0f : 0.0f;
    o[15] = 0.0f;
}

/* Quadrature of bsdf_eval's value and pdf over (cos theta, phi) cells, one listed cell per work-item:
 * nodes (sin, cos, weight) in theta per cos-row and (cos, sin, weight) in phi per column. */
__kernel void bsdf_cells_k(__global const float* mat, __global const float* wi_p, int n_phi, int q_t,
                           int q_p, __global const float* tnodes, __global const float* pnodes,
                           __global const int* cells, __global float* out) {
    int cell = cells[get_global_id(0)];
    int i = cell / n_phi, j = cell % n_phi;
    vec3 wi = load3(wi_p, 0);
    Bsdf bsdf = bsdf_from(mat, 1);
    float4 acc = (float4)(0.0f);
    for (int a = 0; a < q_t; ++a) {
        vec3 t = load3(tnodes, i * q_t + a);
        float4 row = (float4)(0.0f);
        for (int b = 0; b < q_p; ++b) {
            vec3 p = load3(pnodes, j * q_p + b);
            float pdf;
            vec3 v = bsdf_eval(&bsdf, wi, v3(t.x * p.x, t.x * p.y, t.y), &pdf);
            row += p.z * (float4)(v.x, v.y, v.z, pdf);
        }
        acc += t.z * row;
    }
    vstore4(acc, get_global_id(0), out);
}

__kernel void fresnel_dielectric_k(__global const float* cos_i, __global const float* eta,
                                   __global float* out) {
    int i = get_global_id(0);
    float ct = -2.0f, eti = -2.0f;
    float f = fresnel_dielectric(cos_i[i], eta[i], &ct, &eti);
    vstore3((float3)(f, ct, eti), i, out);
}

/* per item (m[3], v[3], alpha, beckmann) -> (D(m), G1(v, m), pdf_visible(v, m)) */
__kernel void microfacet_k(__global const float* in, __global float* out) {
    int i = get_global_id(0);
    __global const float* p = in + 8 * i;
    Microfacet d;
    d.alpha = p[6];
#ifdef SCENE_HAS_ANISOTROPY
    d.alpha_v = p[6];
#endif
    d.beckmann = p[7] != 0.0f;
    vec3 m = load3(p, 0), v = load3(p, 1);
    vstore3((float3)(mf_d(d, m), mf_g1(d, v, m), mf_pdf_visible(d, v, m)), i, out);
}

/* per item (wi[3], alpha, beckmann, u[2]) -> sampled visible normal */
__kernel void microfacet_sample_k(__global const float* in, __global float* out) {
    int i = get_global_id(0);
    __global const float* p = in + 8 * i;
    Microfacet d;
    d.alpha = p[3];
#ifdef SCENE_HAS_ANISOTROPY
    d.alpha_v = p[3];
#endif
    d.beckmann = p[4] != 0.0f;
    store3(out, i, mf_sample_visible(d, load3(p, 0), v2(p[5], p[6])));
}

__kernel void erfinv_k(__global const float* x, __global float* out) {
    int i = get_global_id(0);
    out[i] = erfinv_f(x[i]);
}

__kernel void fresnel_conductor_k(__global const float* cos_i, __global const float* ek,
                                  __global float* out) {
    int i = get_global_id(0);
    store3(out, i, fresnel_conductor(cos_i[i], load3(ek, 2 * i), load3(ek, 2 * i + 1)));
}
"""


# --------------------------------------------------------------------------
# Host side of the test kernels


class Out:
    """An output argument: a device buffer of this shape read back after the kernel."""

    def __init__(self, *shape: int, dtype=np.float32) -> None:
        self.shape, self.dtype = shape, np.dtype(dtype)


class Kit:
    def __init__(self, device, defines: dict | None = None, extra: str = "") -> None:
        """The test kernels (and ``extra`` ones) built with ``defines`` (test_bsdf: -DSCENE_HAS_ANISOTROPY)."""
        self.ctx, self.queue = device.context, device.queue
        self.prg = build_program(device, source=KERNELS + extra, defines=defines, name="test_sampling")
        self.kernels: dict[str, cl.Kernel] = {}
        self.cache: dict = {}

    def run(self, name: str, n: int, *args):
        mf = cl.mem_flags
        knl = self.kernels.get(name)
        if knl is None:
            knl = self.kernels[name] = cl.Kernel(self.prg, name)
        cl_args, outs = [], []
        for a in args:
            if isinstance(a, Out):
                host = np.empty(a.shape, a.dtype)
                buf = cl.Buffer(self.ctx, mf.WRITE_ONLY, max(host.nbytes, 4))
                outs.append((host, buf))
                cl_args.append(buf)
            elif isinstance(a, np.ndarray):
                a = np.ascontiguousarray(a)
                cl_args.append(cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a))
            else:
                cl_args.append(a)
        knl(self.queue, (n,), None, *cl_args)
        for host, buf in outs:
            cl.enqueue_copy(self.queue, host, buf)
        self.queue.finish()
        res = [h for h, _ in outs]
        return res[0] if len(res) == 1 else res

    # convenience wrappers --------------------------------------------------
    def rng(self, keys: np.ndarray):
        keys = np.ascontiguousarray(keys, np.uint32)
        n = keys.shape[0]
        return self.run("rng_eval", n, keys, Out(n), Out(n, 2))

    def eval(self, mat: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        wo = np.ascontiguousarray(wo, np.float32).reshape(-1, 3)
        wi = np.ascontiguousarray(wi, np.float32).reshape(-1, 3)
        stride = 0 if wi.shape[0] == 1 else 1
        assert stride == 0 or wi.shape == wo.shape
        return self.run("bsdf_eval_k", wo.shape[0], mat, wi, np.int32(stride), wo, Out(wo.shape[0], 4))

    def cells(self, mat: np.ndarray, wi: np.ndarray, cells=None, sub_t: int = 8, sub_p: int = 4,
              cos_lo: float = 0.0, n_cos: int | None = None):
        """Integrals of bsdf_eval's (value rgb, pdf) over (cos theta, phi) cells, cos theta in [cos_lo, 1]
        (0: the upper hemisphere, -1: the sphere) in n_cos rows of N_PHI cells.

        Composite 2-point Gauss-Legendre with sub_t x sub_p pieces per cell; returns (len(cells), 4)."""
        n_cos = N_COS if n_cos is None else n_cos
        if cells is None:
            cells = np.arange(n_cos * N_PHI)
        cells = np.ascontiguousarray(cells, np.int32)
        th, wt, ph, wp = cell_nodes(cos_lo, n_cos, N_PHI, sub_t, sub_p)
        tn = np.stack([np.sin(th), np.cos(th), wt * np.sin(th)], axis=-1).astype(np.float32)
        pn = np.stack([np.cos(ph), np.sin(ph), wp], axis=-1).astype(np.float32)
        n = len(cells)
        out = self.run("bsdf_cells_k", n, mat, np.ascontiguousarray(wi, np.float32).reshape(3), np.int32(N_PHI),
                       np.int32(th.shape[1]), np.int32(ph.shape[1]), tn, pn, cells, Out(n, 4))
        return out.astype(np.float64)

    def adaptive_cells(self, mat: np.ndarray, wi: np.ndarray, n_samples: int, cos_lo: float = 0.0,
                       n_cos: int | None = None) -> np.ndarray:
        """Per-cell integrals (n_cos, N_PHI, 4), refined where the coarse quadrature is not yet converged
        at the resolution n_samples samples can see (narrow GGX lobes at grazing incidence)."""
        n_cos = N_COS if n_cos is None else n_cos
        kw = dict(cos_lo=cos_lo, n_cos=n_cos)
        a = self.cells(mat, wi, sub_t=4, sub_p=2, **kw)
        b = self.cells(mat, wi, sub_t=8, sub_p=4, **kw)
        diff = n_samples * np.abs(a[:, 3] - b[:, 3])
        todo = np.flatnonzero(diff > 0.05 * np.sqrt(np.maximum(n_samples * b[:, 3], 1.0)))
        if len(todo):
            b[todo] = self.cells(mat, wi, todo, sub_t=64, sub_p=32, **kw)
        return b.reshape(n_cos, N_PHI, 4)

    def sample(self, mat: np.ndarray, wi: np.ndarray, u: np.ndarray) -> dict[str, np.ndarray]:
        u = np.ascontiguousarray(u, np.float32).reshape(-1, 3)
        wi = np.ascontiguousarray(wi, np.float32).reshape(-1, 3)
        stride = 0 if wi.shape[0] == 1 else 1
        n = u.shape[0]
        o = self.run("bsdf_sample_k", n, mat, wi, np.int32(stride), u, Out(n, 16))
        return {"wo": o[:, 0:3], "weight": o[:, 3:6], "pdf": o[:, 6], "eta": o[:, 7],
                "delta": o[:, 8] > 0.5, "ok": o[:, 9] > 0.5, "value": o[:, 10:13], "eval_pdf": o[:, 13],
                "is_delta": o[:, 14] > 0.5}


@pytest.fixture(scope="module")
def kit(device) -> Kit:
    return Kit(device)


def uniform(seed: int, *shape: int) -> np.ndarray:
    """float32 uniforms in [0, 1) from a fixed seed."""
    return np.random.default_rng(seed).random(shape, dtype=np.float32)


def direction(cos_theta: float, phi: float) -> np.ndarray:
    s = np.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    return np.array([s * np.cos(phi), s * np.sin(phi), cos_theta], np.float32)


def random_directions(seed: int, n: int, hemisphere: bool = True) -> np.ndarray:
    """Uniform directions on the upper hemisphere (or the sphere), float32, |z| bounded away from 0."""
    u = np.random.default_rng(seed).random((n, 2))
    z = 0.01 + 0.99 * u[:, 0] if hemisphere else 1.0 - 2.0 * u[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1).astype(np.float32)


# --------------------------------------------------------------------------
# Chi-square machinery (Mitsuba style: cells in (cos theta, phi), low-expectation cells pooled)

N_COS, N_PHI = 40, 80


def chi2_pvalue(observed: np.ndarray, expected: np.ndarray, min_expected: float = 5.0) -> tuple[float, str]:
    """p-value of observed counts against expected counts; cells with expected < min_expected pooled.

    Returns (p, diagnostic). A cell with (numerically) zero expectation but samples in it fails outright."""
    obs = np.asarray(observed, np.float64).ravel()
    exp = np.asarray(expected, np.float64).ravel()
    stray = (exp <= 1e-12 * max(exp.sum(), 1.0)) & (obs > 0)
    if stray.any():
        return 0.0, f"{int(obs[stray].sum())} samples in {int(stray.sum())} cells of zero expectation"
    low = exp < min_expected
    o = list(obs[~low])
    e = list(exp[~low])
    po, pe = obs[low].sum(), exp[low].sum()
    if pe >= min_expected:
        o.append(po)
        e.append(pe)
    elif pe > 0 or po > 0:  # too small to stand alone: merge into the smallest remaining cell
        k = int(np.argmin(e))
        o[k] += po
        e[k] += pe
    o, e = np.array(o), np.array(e)
    if len(o) < 2:
        return 1.0, "a single cell"
    chi2 = float(((o - e) ** 2 / e).sum())
    dof = len(o) - 1
    p = float(stats.chi2.sf(chi2, dof))
    worst = np.argsort(-((o - e) ** 2 / e))[:3]
    diag = f"chi2={chi2:.1f} dof={dof}; worst cells obs/exp: " + ", ".join(f"{o[k]:.0f}/{e[k]:.1f}" for k in worst)
    return p, diag


def histogram_sphere(w: np.ndarray, cos_lo: float, n_cos: int = N_COS, n_phi: int = N_PHI) -> np.ndarray:
    """Counts of directions in (cos theta, phi) cells; cos theta in [cos_lo, 1], phi in [0, 2 pi)."""
    w = np.asarray(w, np.float64)
    c = (w[:, 2] - cos_lo) / (1.0 - cos_lo)
    phi = np.mod(np.arctan2(w[:, 1], w[:, 0]), 2.0 * np.pi)
    i = np.clip(np.floor(c * n_cos).astype(np.int64), 0, n_cos - 1)
    j = np.clip(np.floor(phi / (2.0 * np.pi) * n_phi).astype(np.int64), 0, n_phi - 1)
    return np.bincount(i * n_phi + j, minlength=n_cos * n_phi).reshape(n_cos, n_phi)


def _gauss_composite(a: np.ndarray, b: np.ndarray, sub: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of composite 2-point Gauss-Legendre on each interval [a_k, b_k] (sub pieces)."""
    g = np.array([0.5 - 0.5 / np.sqrt(3.0), 0.5 + 0.5 / np.sqrt(3.0)])
    t = (np.arange(sub)[:, None] + g[None, :]).ravel() / sub  # (2 sub,) in (0, 1)
    h = (b - a)[:, None]
    return a[:, None] + h * t[None, :], np.broadcast_to(h / (2 * sub), (len(a), 2 * sub))


def cell_nodes(cos_lo: float, n_cos: int, n_phi: int, sub_t: int, sub_p: int):
    """Quadrature nodes/weights in theta per cos-row (n_cos, q_t) and in phi per column (n_phi, q_p).

    Integrates in theta (sin theta d theta d phi) so that peaked lobes near the pole are resolved."""
    c_edges = np.linspace(cos_lo, 1.0, n_cos + 1)
    t_edges = np.arccos(np.clip(c_edges, -1.0, 1.0))
    th, wt = _gauss_composite(t_edges[1:], t_edges[:-1], sub_t)
    p_edges = np.linspace(0.0, 2.0 * np.pi, n_phi + 1)
    ph, wp = _gauss_composite(p_edges[:-1], p_edges[1:], sub_p)
    return th, wt, ph, wp


def sphere_quadrature(cos_lo: float, n_cos: int = N_COS, n_phi: int = N_PHI, sub_t: int = 8, sub_p: int = 4):
    """Directions and solid-angle weights integrating over every (cos theta, phi) cell.

    Returns dirs (n_cos, q_t, n_phi, q_p, 3) and weights (n_cos, q_t, n_phi, q_p)."""
    th, wt, ph, wp = cell_nodes(cos_lo, n_cos, n_phi, sub_t, sub_p)
    st, ct = np.sin(th), np.cos(th)
    dirs = np.empty(th.shape + ph.shape + (3,))
    dirs[..., 0] = st[:, :, None, None] * np.cos(ph)[None, None]
    dirs[..., 1] = st[:, :, None, None] * np.sin(ph)[None, None]
    dirs[..., 2] = ct[:, :, None, None]
    weights = (wt * st)[:, :, None, None] * wp[None, None]
    return dirs.astype(np.float32), weights


def integrate_cells(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per-cell integrals from values at the quadrature nodes, shape (n_cos, n_phi)."""
    v = np.asarray(values, np.float64).reshape(weights.shape)
    return (v * weights).sum(axis=(1, 3))


# --------------------------------------------------------------------------
# 1. Random numbers


def philox_ref(c, k):
    M0, M1, W0, W1 = 0xD2511F53, 0xCD9E8D57, 0x9E3779B9, 0xBB67AE85
    c, k = [int(x) for x in c], [int(x) for x in k]
    for _ in range(10):
        p0, p1 = M0 * c[0], M1 * c[2]
        c = [(p1 >> 32) ^ c[1] ^ k[0], p1 & 0xFFFFFFFF, (p0 >> 32) ^ c[3] ^ k[1], p0 & 0xFFFFFFFF]
        k = [(k[0] + W0) & 0xFFFFFFFF, (k[1] + W1) & 0xFFFFFFFF]
    return c


def test_philox_known_answers(kit):
    # Random123's kat_vectors for philox4x32_10.
    cases = [
        ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
        ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
        ((0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344), (0xA4093822, 0x299F31D0),
         (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1)),
    ]
    rng = np.random.default_rng(7)
    extra_c = rng.integers(0, 2**32, (16, 4), dtype=np.uint64)
    extra_k = rng.integers(0, 2**32, (16, 2), dtype=np.uint64)
    ctr = np.array([c for c, _, _ in cases] + extra_c.tolist(), np.uint32)
    key = np.array([k for _, k, _ in cases] + extra_k.tolist(), np.uint32)
    want = np.array([r for _, _, r in cases] + [philox_ref(c, k) for c, k in zip(extra_c, extra_k)], np.uint32)
    got = kit.run("philox_kat", len(ctr), ctr, key, Out(len(ctr), 4, dtype=np.uint32))
    np.testing.assert_array_equal(got, want)


def make_keys(seed=0, pixel=0, sample=0, bounce=0, dim=0) -> np.ndarray:
    cols = np.broadcast_arrays(*(np.asarray(x, np.uint64) for x in (seed, pixel, sample, bounce, dim)))
    return np.stack([c.ravel() for c in cols], axis=1).astype(np.uint32)


def test_rng_same_key_same_value(kit):
    rng = np.random.default_rng(1)
    n = 50_000
    keys = np.stack([rng.integers(0, 2**32, n), rng.integers(0, 2**22, n), rng.integers(0, 2**16, n),
                     rng.integers(0, 64, n), rng.integers(0, 9, n)], axis=1).astype(np.uint32)
    a1, a2 = kit.rng(keys)
    perm = rng.permutation(n)
    b1, b2 = kit.rng(keys[perm])
    np.testing.assert_array_equal(b1, a1[perm])  # independent of work-item id / batch order
    np.testing.assert_array_equal(b2, a2[perm])
    c1, c2 = kit.rng(keys[:7])  # and of the batch size
    np.testing.assert_array_equal(c1, a1[:7])
    np.testing.assert_array_equal(c2, a2[:7])
    # Changing any single key component changes the value (up to 24-bit ties).
    for col in range(5):
        k = keys.copy()
        k[:, col] += np.uint32(1)
        d1, _ = kit.rng(k)
        assert np.mean(d1 == a1) < 1e-3, f"key component {col} barely changes rng_1d"


def test_rng_range(kit):
    n = 200_000
    keys = make_keys(seed=3, pixel=np.arange(n) % 977, sample=np.arange(n) // 977, bounce=np.arange(n) % 13,
                     dim=np.arange(n) % 9)
    v1, v2 = kit.rng(keys)
    for v in (v1, v2.ravel()):
        assert v.dtype == np.float32
        assert v.min() >= 0.0 and v.max() < 1.0
    # 24-bit resolution: every value is a multiple of 2^-24
    assert np.all(v1 * np.float32(2**24) == np.floor(v1 * np.float32(2**24)))


RNG_STREAMS = {
    "samples": dict(seed=11, pixel=5, sample=np.arange(1_000_000), bounce=0, dim=0),
    "pixels": dict(seed=12, pixel=np.arange(1_000_000), sample=3, bounce=2, dim=4),
    "seeds": dict(seed=np.arange(1_000_000), pixel=17, sample=0, bounce=0, dim=7),
    "bounce-dim": dict(seed=13, pixel=99, sample=np.arange(1000)[:, None, None],
                       bounce=np.arange(111)[None, :, None], dim=np.arange(9)[None, None, :]),
}


@pytest.mark.parametrize("stream", list(RNG_STREAMS))
def test_rng_uniform(kit, stream):
    v1, v2 = kit.rng(make_keys(**RNG_STREAMS[stream]))
    for name, v in (("rng_1d", v1), ("rng_2d.x", v2[:, 0]), ("rng_2d.y", v2[:, 1])):
        counts = np.bincount(np.floor(v * 64).astype(np.int64), minlength=64)
        p = stats.chisquare(counts).pvalue
        assert p > 1e-3, f"{name} over {stream} not uniform on 64 bins: p={p:.2e}, counts {counts}"
        assert abs(v.mean() - 0.5) < 5 * np.sqrt(1 / 12 / len(v))
    # jointly uniform on an 8x8 grid
    cell = np.floor(v2[:, 0] * 8).astype(np.int64) * 8 + np.floor(v2[:, 1] * 8).astype(np.int64)
    p = stats.chisquare(np.bincount(cell, minlength=64)).pvalue
    assert p > 1e-3, f"rng_2d over {stream} not jointly uniform: p={p:.2e}"


def test_rng_uncorrelated(kit):
    n = 200_000
    s = np.arange(n)
    base = dict(seed=21, pixel=1234, sample=s, bounce=3, dim=4)
    ref1, ref2 = kit.rng(make_keys(**base))
    limit = 5.0 / np.sqrt(n)
    variants = {
        "dim+1": dict(base, dim=5), "bounce+1": dict(base, bounce=4), "sample+1": dict(base, sample=s + 1),
        "pixel+1": dict(base, pixel=1235), "seed+1": dict(base, seed=22), "dim 0 vs 8": dict(base, dim=8),
    }
    for name, kw in variants.items():
        v1, v2 = kit.rng(make_keys(**kw))
        for a, b, what in ((ref1, v1, "1d"), (ref2[:, 0], v2[:, 0], "2d.x"), (ref2[:, 1], v2[:, 1], "2d.y"),
                           (ref2[:, 0], v2[:, 1], "2d.x-y")):
            r = np.corrcoef(a, b)[0, 1]
            assert abs(r) < limit, f"rng {what} correlated across {name}: r={r:.4f}"
    r = np.corrcoef(ref2[:, 0], ref2[:, 1])[0, 1]
    assert abs(r) < limit, f"rng_2d components correlated: r={r:.4f}"
    # consecutive samples of one stream (lag-1 autocorrelation)
    r = np.corrcoef(ref1[:-1], ref1[1:])[0, 1]
    assert abs(r) < limit, f"rng_1d lag-1 autocorrelation {r:.4f}"


def test_bounce_blocks_are_the_philox_words(kit):
    """A bounce draws two blocks (cl/core/rng.h): rng_light the words 0-2 of block DIM_LIGHT = 0 (selection, u, v),
    rng_bsdf the words 0-3 of block DIM_BSDF = 3 (lobe, u, v, roulette), each word's top 24 bits over 2^24."""
    rng = np.random.default_rng(3)
    n = 64
    keys = make_keys(seed=rng.integers(0, 2**32, n), pixel=rng.integers(0, 2**22, n),
                     sample=rng.integers(0, 2**16, n), bounce=rng.integers(0, 64, n))
    got = kit.run("rng_bounce_blocks", n, keys, Out(n, 7))
    for (seed, pixel, sample, bounce, _), row in zip(keys, got):
        light = philox_ref((sample, bounce, 0, 0), (seed, pixel))[:3]
        bsdf = philox_ref((sample, bounce, 3, 0), (seed, pixel))
        want = np.array([(w >> 8) * 2.0**-24 for w in light + bsdf], np.float32)
        np.testing.assert_array_equal(row, want)


def test_bounce_block_numbers_are_uncorrelated_and_jointly_uniform(kit):
    """The seven numbers of a bounce, over many samples of one pixel: no pair correlated, each pair uniform on an
    8x8 grid (the roulette's number beside the BSDF sample's (u, v), from one block)."""
    n = 200_000
    out = kit.run("rng_bounce_blocks", n, make_keys(seed=21, pixel=1234, sample=np.arange(n), bounce=2), Out(n, 7))
    c = np.corrcoef(out.T)
    off = np.abs(c[~np.eye(7, dtype=bool)])
    assert off.max() < 5.0 / np.sqrt(n), f"bounce numbers correlated: {c.round(4)}"
    for i in range(7):
        for j in range(i + 1, 7):
            cell = np.floor(out[:, i] * 8).astype(np.int64) * 8 + np.floor(out[:, j] * 8).astype(np.int64)
            p = stats.chisquare(np.bincount(cell, minlength=64)).pvalue
            assert p > 1e-4, f"numbers {i}, {j} of a bounce not jointly uniform: p={p:.2e}"


# --------------------------------------------------------------------------
# 2. Warping routines against their pdfs

N_WARP = 1_000_000


@pytest.fixture(scope="module")
def warped(kit):
    u = uniform(101, N_WARP, 2)
    hemi, sphere, tri = kit.run("warp_eval", N_WARP, u, Out(N_WARP, 4), Out(N_WARP, 4), Out(N_WARP, 2))
    return u, hemi, sphere, tri


def test_cosine_hemisphere_chi2(kit, warped):
    _, hemi, _, _ = warped
    w = hemi[:, :3]
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-5)
    assert np.all(w[:, 2] >= 0.0)
    # the pdf returned alongside equals cosine_hemisphere_pdf's closed form
    np.testing.assert_allclose(hemi[:, 3], np.where(w[:, 2] > 0, w[:, 2] / np.pi, 0.0), rtol=1e-5, atol=1e-7)
    dirs, weights = sphere_quadrature(0.0)
    pdf = kit.run("warp_pdf", dirs.size // 3, dirs.reshape(-1, 3), Out(dirs.size // 3, 2))[:, 0]
    cells = integrate_cells(pdf, weights)
    assert abs(cells.sum() - 1.0) < 1e-4, f"cosine_hemisphere_pdf integrates to {cells.sum()}"
    # the device pdf integrated per cell agrees with the analytic integral (c_hi^2 - c_lo^2) / 2 * dphi / pi
    c = np.linspace(0.0, 1.0, N_COS + 1)
    exact = np.repeat(((c[1:] ** 2 - c[:-1] ** 2) / 2 * (2 * np.pi / N_PHI) / np.pi)[:, None], N_PHI, axis=1)
    np.testing.assert_allclose(cells, exact, rtol=1e-4, atol=1e-9)
    p, diag = chi2_pvalue(histogram_sphere(w, 0.0), N_WARP * cells)
    assert p > 0.01, f"square_to_cosine_hemisphere vs cosine_hemisphere_pdf: p={p:.2e} ({diag})"


def test_uniform_sphere_chi2(kit, warped):
    _, _, sphere, _ = warped
    w = sphere[:, :3]
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(sphere[:, 3], 1.0 / (4.0 * np.pi), rtol=1e-6)
    dirs, weights = sphere_quadrature(-1.0)
    pdf = kit.run("warp_pdf", dirs.size // 3, dirs.reshape(-1, 3), Out(dirs.size // 3, 2))[:, 1]
    cells = integrate_cells(pdf, weights)
    assert abs(cells.sum() - 1.0) < 1e-5
    p, diag = chi2_pvalue(histogram_sphere(w, -1.0), N_WARP * cells)
    assert p > 0.01, f"square_to_uniform_sphere vs UNIFORM_SPHERE_PDF: p={p:.2e} ({diag})"


def test_triangle_chi2(warped):
    _, _, _, tri = warped
    b1, b2 = tri[:, 0].astype(np.float64), tri[:, 1].astype(np.float64)
    assert np.all(b1 >= 0) and np.all(b2 >= 0) and np.all(b1 + b2 <= 1 + 1e-6)
    n = 32  # cells of the unit square; density 2 on the triangle b1 + b2 <= 1
    i = np.clip(np.floor(b1 * n).astype(np.int64), 0, n - 1)
    j = np.clip(np.floor(b2 * n).astype(np.int64), 0, n - 1)
    observed = np.bincount(i * n + j, minlength=n * n).reshape(n, n)
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    area = np.where(ii + jj < n - 1, 1.0, np.where(ii + jj == n - 1, 0.5, 0.0)) / n**2
    p, diag = chi2_pvalue(observed, N_WARP * 2.0 * area)
    assert p > 0.01, f"square_to_triangle is not uniform: p={p:.2e} ({diag})"
    # the third barycentric is uniform too (a symmetric check of the mapping)
    b0 = 1.0 - b1 - b2
    assert abs(b0.mean() - 1 / 3) < 5 * np.sqrt(1 / 18 / N_WARP)
    assert abs(b1.mean() - 1 / 3) < 5 * np.sqrt(1 / 18 / N_WARP)


POWER_HEURISTIC_KERNEL = r"""
#include "core/sampling.h"
__kernel void power_heuristic_k(__global const float* a, __global const float* b, __global float* out) {
    int i = get_global_id(0);
    out[i] = power_heuristic(a[i], b[i]);
}
"""


def test_power_heuristic(device):
    """Veach's power heuristic (beta = 2), w = a^2 / (a^2 + b^2), 0 where a = 0: exact values, so
    that the balance heuristic (unbiased, so no render can see it) or swapped arguments fail here."""
    cases = [(1, 2, 0.2), (2, 1, 0.8), (0, 5, 0.0), (5, 0, 1.0), (0, 0, 0.0), (3, 3, 0.5), (3, 4, 9 / 25),
             (1, 3, 0.1), (1e-20, 1, 0.0), (1e15, 1, 1.0), (0.25, 0.5, 0.2), (7, 1, 49 / 50)]
    a, b, want = (np.array(c, np.float32) for c in zip(*cases))
    ctx, queue, mf = device.context, device.queue, cl.mem_flags
    prg = build_program(device, source=POWER_HEURISTIC_KERNEL, name="test_power_heuristic")
    bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x) for x in (a, b)]
    out = np.empty(len(cases), np.float32)
    obuf = cl.Buffer(ctx, mf.WRITE_ONLY, out.nbytes)
    cl.Kernel(prg, "power_heuristic_k")(queue, (len(cases),), None, *bufs, obuf)
    cl.enqueue_copy(queue, out, obuf)
    queue.finish()
    np.testing.assert_allclose(out, want, rtol=1e-6, atol=1e-30)
    # the weights of the two techniques sum to 1 wherever either pdf is positive
    np.testing.assert_allclose(out[[0, 2]] + out[[1, 3]], 1.0, rtol=1e-6)


# --------------------------------------------------------------------------
# 3. BSDF sampling against evaluation

N_BSDF = 500_000
PHI_I = 0.7  # azimuth of wi: not aligned with the frame's axes

BSDF_CASES = {
    "diffuse-normal": (Diffuse(reflectance=(0.8, 0.5, 0.2)), 1.0),
    "diffuse-grazing": (Diffuse(reflectance=(0.8, 0.5, 0.2)), 0.1),
}
for _alpha in (0.05, 0.3, 0.8):
    for _cos in (1.0, 0.6, 0.1):
        BSDF_CASES[f"roughcu-a{_alpha}-cos{_cos}"] = (Conductor(*METALS["Cu"], alpha=_alpha,
                                                                specular_reflectance=(0.9, 1.0, 0.8)), _cos)


def bsdf_run(kit, case: str):
    """Samples, their eval, and the per-cell integrals of eval pdf and value (cached per case)."""
    key = ("bsdf", case)
    if key not in kit.cache:
        mat_obj, cos_i = BSDF_CASES[case]
        mat = pack_material(mat_obj)
        wi = direction(cos_i, PHI_I)
        seed = 1000 + list(BSDF_CASES).index(case)
        s = kit.sample(mat, wi, uniform(seed, N_BSDF, 3))
        cells = kit.adaptive_cells(mat, wi, N_BSDF)
        pdf_cells, value_cells = cells[..., 3], cells[..., :3]
        kit.cache[key] = (mat_obj, wi, s, pdf_cells, value_cells)
    return kit.cache[key]


@pytest.mark.parametrize("case", list(BSDF_CASES))
def test_bsdf_chi2(kit, case):
    _, _, s, pdf_cells, _ = bsdf_run(kit, case)
    ok = s["ok"]
    assert np.all(s["wo"][ok, 2] > 0), "a sampled reflection below the surface"
    total = pdf_cells.sum()
    assert total <= 1.0 + 1e-3, f"eval pdf integrates to {total} > 1"
    observed = np.append(histogram_sphere(s["wo"][ok], 0.0).ravel(), np.count_nonzero(~ok))
    expected = np.append(N_BSDF * pdf_cells.ravel(), max(N_BSDF * (1.0 - total), 0.0))
    p, diag = chi2_pvalue(observed, expected)
    assert p > 0.01, f"{case}: sampled wo vs bsdf_eval pdf: p={p:.2e} ({diag}); pdf integral {total:.5f}"


@pytest.mark.parametrize("case", list(BSDF_CASES))
def test_bsdf_sample_matches_eval(kit, case):
    _, _, s, _, _ = bsdf_run(kit, case)
    ok = s["ok"]
    assert ok.mean() > 0.5
    assert not s["delta"][ok].any()
    np.testing.assert_array_equal(s["eta"][ok], 1.0)
    pdf, epdf = s["pdf"][ok].astype(np.float64), s["eval_pdf"][ok].astype(np.float64)
    assert np.all(pdf > 0) and np.all(np.isfinite(pdf))
    np.testing.assert_allclose(pdf, epdf, rtol=1e-3, err_msg=f"{case}: bs.pdf vs bsdf_eval pdf")
    weight = s["weight"][ok].astype(np.float64)
    expect = s["value"][ok].astype(np.float64) / epdf[:, None]
    assert np.all(np.isfinite(weight))
    np.testing.assert_allclose(weight, expect, rtol=1e-3, atol=1e-6,
                               err_msg=f"{case}: bs.weight vs bsdf_eval value / pdf")


# --------------------------------------------------------------------------
# 4. Energy: white furnace and the delta materials


@pytest.mark.parametrize("case", list(BSDF_CASES))
def test_bsdf_albedo_sampled_vs_integrated(kit, case):
    """Mean sampled weight (failed samples count 0) = quadrature of bsdf_eval's value over the hemisphere."""
    mat_obj, _, s, _, value_cells = bsdf_run(kit, case)
    w = np.where(s["ok"][:, None], s["weight"], 0.0).astype(np.float64)
    mean, err = w.mean(axis=0), w.std(axis=0) / np.sqrt(N_BSDF)
    integral = value_cells.sum(axis=(0, 1))
    assert np.all(np.abs(mean - integral) <= 5 * err + 2e-3 * integral), \
        f"{case}: sampled albedo {mean} vs integrated {integral} (+-{err})"
    if isinstance(mat_obj, Diffuse):
        np.testing.assert_allclose(mean, mat_obj.reflectance, rtol=0.01)
        np.testing.assert_allclose(integral, mat_obj.reflectance, rtol=0.01)


@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.8])
@pytest.mark.parametrize("cos_i", [1.0, 0.6, 0.1])
def test_roughconductor_furnace(kit, alpha, cos_i):
    """Metal 'none' (eta 0, k 1: F = 1) loses energy only to single-scattering masking."""
    mat = pack_material(Conductor(*METALS["none"], alpha=alpha))
    n = 200_000
    seed = 3000 + int(alpha * 100) + int(cos_i * 10)
    s = kit.sample(mat, direction(cos_i, PHI_I), uniform(seed, n, 3))
    w = np.where(s["ok"][:, None], s["weight"], 0.0).astype(np.float64)
    mean, err = w.mean(axis=0), w.std(axis=0) / np.sqrt(n)
    assert np.all(mean <= 1.0 + 5 * err + 1e-6), f"albedo {mean} > 1"
    assert np.all(s["weight"][s["ok"]] <= 1.0 + 1e-5), "a single sample with weight > 1 (G1 <= 1, F = 1)"
    if alpha <= 0.05:
        lower = 0.99 if cos_i >= 0.5 else 0.9
        assert np.all(mean > lower), f"smooth-ish metal albedo {mean} (alpha {alpha}, cos {cos_i})"
    if cos_i == 1.0:
        # At normal incidence a visible normal is an ordinary GGX normal (pdf D(h) h.z): the reflection
        # stays above the horizon iff tan(theta_h) < 1, which happens with probability 1 / (1 + alpha^2).
        frac, want = s["ok"].mean(), 1.0 / (1.0 + alpha**2)
        assert abs(frac - want) < 5 * np.sqrt(want * (1 - want) / n) + 1e-6, f"{frac} of samples valid, not {want}"


def fresnel_ref(cos_i, n) -> np.ndarray:
    """Unpolarised Fresnel reflectance for light hitting a medium of relative complex IOR n (cos_i >= 0)."""
    cos_i = np.asarray(cos_i, np.float64)
    n = np.asarray(n, np.complex128)
    s2 = 1.0 - cos_i**2
    nct = np.sqrt(n * n - s2 + 0j)  # n cos_t, principal branch (decaying wave / TIR)
    rs = (cos_i - nct) / (cos_i + nct)
    rp = (n * n * cos_i - nct) / (n * n * cos_i + nct)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def test_fresnel_dielectric_reference(kit):
    etas = np.array([1.000277, 1.333, 1.5046, 2.419, 1 / 1.5, 1.0 + 1e-3])
    cos = np.concatenate([np.linspace(-1, 1, 401), [-1e-3, 1e-3, -0.05, 0.05]])
    E, C = np.meshgrid(etas, cos, indexing="ij")
    E, C = E.ravel().astype(np.float32), C.ravel().astype(np.float32)
    out = kit.run("fresnel_dielectric_k", len(C), C, E, Out(len(C), 3)).astype(np.float64)
    c, e = C.astype(np.float64), E.astype(np.float64)
    outside = c >= 0
    eta_it = np.where(outside, e, 1.0 / e)
    want_f = fresnel_ref(np.abs(c), eta_it)
    # Near the critical angle F is ill-conditioned in float32: allow the spread the reference shows when
    # its inputs move by float32 rounding.
    spread = [fresnel_ref(np.abs(c) * (1 + dc), np.where(outside, e * (1 + de), 1.0 / (e * (1 + de))))
              for dc in (-3e-7, 0, 3e-7) for de in (-3e-7, 0, 3e-7)]
    lo, hi = np.min(spread, axis=0), np.max(spread, axis=0)
    tol = 2e-6 + 1e-4 * want_f
    bad = (out[:, 0] < lo - tol) | (out[:, 0] > hi + tol)
    assert not bad.any(), f"fresnel_dielectric off at cos {c[bad]}, eta {e[bad]}: {out[bad, 0]} vs {want_f[bad]}"
    assert np.abs(out[:, 0] - want_f).max() < 5e-4
    np.testing.assert_allclose(out[np.abs(c) > 0.3, 0], want_f[np.abs(c) > 0.3], atol=2e-6, rtol=1e-4)
    np.testing.assert_allclose(out[:, 2], 1.0 / eta_it, rtol=1e-6)
    sin_t2 = (1.0 - c * c) / eta_it**2
    tir = sin_t2 >= 1.0
    want_ct = np.where(tir, 0.0, -np.sign(np.where(outside, 1.0, -1.0)) * np.sqrt(np.maximum(0.0, 1.0 - sin_t2)))
    np.testing.assert_allclose(out[:, 1], want_ct, atol=1e-5)
    assert np.all(out[tir & (sin_t2 > 1.0 + 1e-4), 0] == 1.0)
    # Known values: normal incidence ((n-1)/(n+1))^2, zero p-reflectance at Brewster's angle.
    f0 = kit.run("fresnel_dielectric_k", 2, np.array([1.0, -1.0], np.float32), np.float32([1.5, 1.5]), Out(2, 3))
    np.testing.assert_allclose(f0[:, 0], 0.04, rtol=1e-5)
    cb = np.float32(np.cos(np.arctan(1.5)))
    fb = kit.run("fresnel_dielectric_k", 1, np.array([cb], np.float32), np.float32([1.5]), Out(1, 3))[0, 0]
    rs = (cb - 1.5 * np.sqrt(1 - (1 - cb * cb) / 2.25)) / (cb + 1.5 * np.sqrt(1 - (1 - cb * cb) / 2.25))
    np.testing.assert_allclose(fb, 0.5 * rs * rs, rtol=1e-4)


@pytest.mark.parametrize("metal", list(METALS))
def test_fresnel_conductor_reference(kit, metal):
    eta, k = np.array(METALS[metal][0]), np.array(METALS[metal][1])
    cos = np.concatenate([np.linspace(0.0, 1.0, 501), [1e-4, 1e-3, 0.999]]).astype(np.float32)
    ek = np.tile(np.concatenate([eta, k]).astype(np.float32), (len(cos), 1))
    out = kit.run("fresnel_conductor_k", len(cos), cos, ek, Out(len(cos), 3)).astype(np.float64)
    want = np.stack([fresnel_ref(cos.astype(np.float64), eta[c] + 1j * k[c]) for c in range(3)], axis=1)
    np.testing.assert_allclose(out, want, atol=2e-5, rtol=1e-4, err_msg=f"fresnel_conductor for {metal}")
    assert np.all((out >= 0) & (out <= 1 + 1e-6))
    if metal == "none":
        np.testing.assert_allclose(out, 1.0, atol=1e-6)


@pytest.mark.parametrize("metal", ["Au", "Cr", "none"])
def test_smooth_conductor_sample(kit, metal):
    spec = (0.9, 0.7, 0.5)
    mat = pack_material(Conductor(*METALS[metal], alpha=0.0, specular_reflectance=spec))
    wi = random_directions(41, 2000)
    s = kit.sample(mat, wi, uniform(42, 2000, 3))
    assert np.all(s["ok"]) and np.all(s["delta"])
    np.testing.assert_allclose(s["wo"], wi * np.float32([-1, -1, 1]), atol=1e-7)
    np.testing.assert_array_equal(s["pdf"], 1.0)
    np.testing.assert_array_equal(s["eta"], 1.0)
    eta, k = np.array(METALS[metal][0]), np.array(METALS[metal][1])
    f = np.stack([fresnel_ref(wi[:, 2].astype(np.float64), eta[c] + 1j * k[c]) for c in range(3)], axis=1)
    np.testing.assert_allclose(s["weight"], f * np.array(spec), atol=2e-5, rtol=1e-4)
    # delta lobes evaluate to zero
    np.testing.assert_array_equal(s["value"], 0.0)
    np.testing.assert_array_equal(s["eval_pdf"], 0.0)
    # a one-sided conductor seen from behind reflects nothing
    back = kit.sample(mat, wi * np.float32([1, 1, -1]), uniform(43, 2000, 3))
    assert not back["ok"].any()


@pytest.mark.parametrize("int_ior,ext_ior", [(1.5046, 1.000277), (1.333, 1.0), (2.419, 1.0)])
def test_dielectric_sample(kit, int_ior, ext_ior):
    spec_r, spec_t = (0.9, 0.8, 0.7), (0.6, 0.5, 0.4)
    mat = pack_material(Dielectric(int_ior, ext_ior, spec_r, spec_t))
    eta = np.float32(int_ior / ext_ior)
    n = 4000
    up = random_directions(51, n)
    wi = np.concatenate([up, up * np.float32([1, 1, -1])])  # from outside, then from inside
    inside = wi[:, 2] < 0
    # u_lobe = 0 always picks reflection; just below 1 picks refraction unless F = 1
    r = kit.sample(mat, wi, np.column_stack([np.zeros(2 * n), uniform(52, 2 * n, 2)]))
    t = kit.sample(mat, wi, np.column_stack([np.full(2 * n, np.float32(1) - np.float32(2**-24)),
                                             uniform(53, 2 * n, 2)]))
    assert r["ok"].all() and t["ok"].all() and r["delta"].all() and t["delta"].all()
    eta_it = np.where(inside, 1.0 / eta, eta)
    cos_i = np.abs(wi[:, 2]).astype(np.float64)
    F = fresnel_ref(cos_i, eta_it)
    tir = (1.0 - cos_i**2) / eta_it**2 >= 1.0  # total internal reflection expected
    assert not tir[~inside].any()
    crit = np.sqrt(1.0 - 1.0 / eta**2)  # |cos| of the critical angle from inside
    assert tir.sum() > 100, "no direction beyond the critical angle was tested"
    # the device agrees on which side of the critical angle each direction lies (away from it)
    clear = np.abs(cos_i - crit) > 1e-4
    dev_tir = t["wo"][:, 2] * wi[:, 2] > 0  # u_lobe ~ 1 still reflected
    np.testing.assert_array_equal(dev_tir[clear], tir[clear])
    # reflection: mirror direction, probability F, weight = specular_reflectance
    np.testing.assert_allclose(r["wo"], wi * np.float32([-1, -1, 1]), atol=1e-7)
    np.testing.assert_allclose(r["pdf"][clear], F[clear], atol=2e-6, rtol=1e-4)
    np.testing.assert_allclose(r["weight"], np.broadcast_to(spec_r, (2 * n, 3)), rtol=1e-6)
    np.testing.assert_array_equal(r["eta"], 1.0)
    # total internal reflection: even u_lobe ~ 1 reflects, with probability 1
    tir &= clear
    np.testing.assert_allclose(t["wo"][tir], r["wo"][tir], atol=0)
    np.testing.assert_array_equal(t["pdf"][tir], 1.0)
    np.testing.assert_allclose(t["weight"][tir], np.broadcast_to(spec_r, (tir.sum(), 3)), rtol=1e-6)
    # refraction: probability 1 - F (so reflection + transmission = 1), Snell's law, radiance scaling
    tr = ~tir & clear
    np.testing.assert_allclose(r["pdf"][tr] + t["pdf"][tr], 1.0, atol=1e-6)
    wo = t["wo"][tr].astype(np.float64)
    w = wi[tr].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=1), 1.0, atol=1e-5)
    assert np.all(np.sign(wo[:, 2]) == -np.sign(w[:, 2])), "refraction must cross the surface"
    sin_i, sin_t = np.linalg.norm(w[:, :2], axis=1), np.linalg.norm(wo[:, :2], axis=1)
    np.testing.assert_allclose(sin_i, eta_it[tr] * sin_t, rtol=1e-5, atol=1e-6, err_msg="Snell's law")
    # in the plane of incidence, on the other side of the normal
    np.testing.assert_allclose(wo[:, :2] * sin_i[:, None], -w[:, :2] * sin_t[:, None], atol=1e-5)
    eta_ti = 1.0 / eta_it[tr]
    np.testing.assert_allclose(t["weight"][tr], np.array(spec_t)[None, :] * (eta_ti**2)[:, None], rtol=1e-5)
    np.testing.assert_allclose(t["eta"][tr], eta_it[tr], rtol=1e-6)
    # dielectric eval is zero (delta only)
    np.testing.assert_array_equal(t["value"], 0.0)
    # random u_lobe: the fraction of reflections is F
    wi1 = direction(0.3, PHI_I)
    m = 200_000
    s = kit.sample(mat, wi1, uniform(54, m, 3))
    f1 = fresnel_ref(0.3, eta)
    frac = np.mean(s["wo"][:, 2] > 0)
    assert abs(frac - f1) < 5 * np.sqrt(f1 * (1 - f1) / m), f"reflected fraction {frac} vs F {f1}"


@pytest.mark.parametrize("mat_obj", [Diffuse(), Conductor(*METALS["Au"], alpha=0.05),
                                     Conductor(*METALS["Al"], alpha=0.8), Conductor(*METALS["Cu"]),
                                     Dielectric()], ids=["diffuse", "rough0.05", "rough0.8", "smooth", "glass"])
def test_bsdf_sample_extremes_finite(kit, mat_obj):
    """Grazing and normal incidence, random numbers at the corners of [0, 1): no NaN, no Inf, no negative weight."""
    mat = pack_material(mat_obj)
    cos = np.array([1.0, 0.999999, 0.5, 1e-2, 1e-4, 1e-6], np.float32)
    corners = np.array([0.0, 0.5, np.float32(1) - np.float32(2**-24)], np.float32)
    u = np.array(np.meshgrid(corners, corners, corners, indexing="ij")).reshape(3, -1).T
    u = np.concatenate([u, uniform(81, 500, 3)])
    wi = np.array([direction(c, phi) for c in cos for phi in (0.0, PHI_I)], np.float32)
    wi = np.concatenate([wi, wi * np.float32([1, 1, -1])]) if isinstance(mat_obj, Dielectric) else wi
    WI = np.repeat(wi, len(u), axis=0)
    U = np.tile(u, (len(wi), 1))
    s = kit.sample(mat, WI, U)
    ok = s["ok"]
    assert ok.mean() > 0.5
    for key in ("wo", "weight", "pdf", "eta"):
        assert np.all(np.isfinite(s[key][ok])), f"non-finite {key}"
    assert np.all(s["weight"][ok] >= 0) and np.all(s["pdf"][ok] > 0)
    np.testing.assert_allclose(np.linalg.norm(s["wo"][ok], axis=1), 1.0, atol=1e-4)
    assert np.all(np.isfinite(s["value"])) and np.all(np.isfinite(s["eval_pdf"]))


# --------------------------------------------------------------------------
# 5. Reciprocity, 6. sidedness

RECIPROCITY_MATERIALS = {
    "diffuse": Diffuse(reflectance=(0.8, 0.5, 0.2)),
    "roughcu-0.05": Conductor(*METALS["Cu"], alpha=0.05),
    "roughau-0.3": Conductor(*METALS["Au"], alpha=0.3),
    "roughal-0.8": Conductor(*METALS["Al"], alpha=0.8),
}


@pytest.mark.parametrize("name", list(RECIPROCITY_MATERIALS))
def test_reciprocity(kit, name):
    mat = pack_material(RECIPROCITY_MATERIALS[name])
    n = 100_000
    wi, wo = random_directions(61, n), random_directions(62, n)
    # also pairs close to the mirror configuration, where the glossy lobes are large
    k = n // 4
    wo[:k] = wi[:k] * np.float32([-1, -1, 1]) + 0.05 * (random_directions(63, k, hemisphere=False))
    wo[:k] /= np.linalg.norm(wo[:k], axis=1, keepdims=True)
    wo[:k, 2] = np.abs(wo[:k, 2]) + 1e-3
    wo[:k] /= np.linalg.norm(wo[:k], axis=1, keepdims=True)
    a = kit.eval(mat, wi, wo)
    b = kit.eval(mat, wo, wi)
    fa = a[:, :3].astype(np.float64) / np.abs(wo[:, 2:3])
    fb = b[:, :3].astype(np.float64) / np.abs(wi[:, 2:3])
    assert np.all(np.isfinite(fa)) and fa.max() > 0
    np.testing.assert_allclose(fa, fb, rtol=1e-4, atol=1e-7, err_msg=f"{name}: f(wi, wo) != f(wo, wi)")
