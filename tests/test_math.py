"""cl/core/math.h on the device against numpy in float64: every function over its range, special values included.

Each function runs in both of the header's modes: the clang builtins PoCL gets (``INLINE_MATH``, added by
build_program on PoCL) and the standard OpenCL builtins (``STANDARD_MATH`` forces them). The bounds are the
ones the header's docstring states.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from pyclpt.device.program import build_program

UNARY = ["m_sqrt", "m_rsqrt", "m_abs", "m_floor", "m_ceil", "m_rint", "m_sin", "m_cos", "m_exp", "m_log", "m_acos",
         "m_isfinite", "m_isnan", "m_isinf"]
BINARY = ["m_min", "m_max", "m_copysign", "m_atan2"]

SOURCE = '#include "core/common.h"\n' + "\n".join(
    f"__kernel void k_{f}(__global const float* x, __global float* y) {{ int i = get_global_id(0); "
    f"y[i] = (float){f}(x[i]); }}" for f in UNARY) + "\n" + "\n".join(
    f"__kernel void k_{f}(__global const float* a, __global const float* b, __global float* y) {{ "
    f"int i = get_global_id(0); y[i] = {f}(a[i], b[i]); }}" for f in BINARY) + """
__kernel void k_m_fma(__global const float* a, __global const float* b, __global const float* c, __global float* y) {
    int i = get_global_id(0); y[i] = m_fma(a[i], b[i], c[i]); }
__kernel void k_m_clamp(__global const float* a, __global const float* b, __global const float* c, __global float* y) {
    int i = get_global_id(0); y[i] = m_clamp(a[i], b[i], c[i]); }
__kernel void k_vec(__global const float* a, __global const float* b, __global float* y) {
    int i = get_global_id(0);
    vec3 u = v3(a[3 * i], a[3 * i + 1], a[3 * i + 2]), v = v3(b[3 * i], b[3 * i + 1], b[3 * i + 2]);
    vec3 c = m_cross(u, v), n = m_normalize(u);
    y[8 * i + 0] = m_dot(u, v); y[8 * i + 1] = m_length(u);
    y[8 * i + 2] = c.x; y[8 * i + 3] = c.y; y[8 * i + 4] = c.z;
    y[8 * i + 5] = n.x; y[8 * i + 6] = n.y; y[8 * i + 7] = n.z; }
"""

SPECIAL = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-45, -1e-45, 1e-40, 1.17549435e-38, 3.4028235e38,
                    -3.4028235e38, 1.0, -1.0, 0.5, 2.0], dtype=np.float32)


@pytest.fixture(scope="module", params=["inline", "standard"])
def run(device, request):
    defines = {"STANDARD_MATH": request.param == "standard"}
    prog = build_program(device, source=SOURCE, name="test_math", defines=defines)
    ctx, q = device.context, device.queue
    kernels: dict[str, cl.Kernel] = {}

    def call(name: str, *args: np.ndarray, out_per_item: int = 1) -> np.ndarray:
        arrs = [np.ascontiguousarray(a, dtype=np.float32) for a in args]
        n = len(arrs[0]) if name != "vec" else len(arrs[0]) // 3
        bufs = [cl.Buffer(ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=a) for a in arrs]
        out = np.empty(n * out_per_item, np.float32)
        ob = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
        kernel = kernels.setdefault(name, cl.Kernel(prog, f"k_{name}"))
        kernel(q, (n,), None, *bufs, ob)
        cl.enqueue_copy(q, out, ob)
        return out
    return call


def f32(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float32)


def ulp_error(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    """|got - want| in units of the float32 spacing at want (want in float64)."""
    spacing = np.spacing(np.abs(want).astype(np.float32)).astype(np.float64)
    return np.abs(got.astype(np.float64) - want) / spacing


def same_specials(got: np.ndarray, want: np.ndarray) -> None:
    """NaN where numpy gives NaN, the same infinities, elsewhere equal in float32 (signed zeros not checked)."""
    w = f32(want)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(w))
    fin = ~np.isnan(w)
    np.testing.assert_allclose(got[fin], w[fin], rtol=2.5e-7, atol=0)


@pytest.mark.parametrize("name,ref", [("m_sqrt", np.sqrt), ("m_abs", np.abs), ("m_floor", np.floor),
                                      ("m_ceil", np.ceil), ("m_rint", np.rint)])
def test_exact_unary(run, name, ref):
    rng = np.random.default_rng(1)
    x = np.concatenate([SPECIAL, f32(rng.uniform(-1e3, 1e3, 4000)),
                        f32(np.float32(2.0) ** rng.integers(-149, 127, 2000)), f32([2.5, -2.5, 3.5, 0.49999997, -0.5])])
    with np.errstate(invalid="ignore"):
        want = ref(x.astype(np.float64))
    got = run(name, x)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_array_equal(got[~np.isnan(want)], f32(want)[~np.isnan(want)])


def test_rsqrt(run):
    x = np.concatenate([f32([0.0, np.inf, 1.0, 4.0, 1e-40, 3.4e38]),
                        f32(np.random.default_rng(2).uniform(1e-6, 1e6, 4000))])
    with np.errstate(divide="ignore"):
        want = 1.0 / np.sqrt(x.astype(np.float64))
    got = run("m_rsqrt", x)
    assert got[0] == np.inf and got[1] == 0.0
    assert ulp_error(got[2:], want[2:]).max() <= 1.5  # two roundings


@pytest.mark.parametrize("name,ref", [("m_min", np.fmin), ("m_max", np.fmax), ("m_copysign", np.copysign)])
def test_exact_binary(run, name, ref):
    """fmin/fmax return the non-NaN operand (OpenCL's and numpy's fmin/fmax); copysign copies the sign of -0 and NaN."""
    a, b = np.meshgrid(SPECIAL, SPECIAL)
    a, b = a.ravel(), b.ravel()
    got = run(name, a, b)
    want = ref(a, b)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    ok = ~np.isnan(want)
    np.testing.assert_array_equal(got[ok], want[ok])
    if name == "m_copysign":
        np.testing.assert_array_equal(np.signbit(got[ok]), np.signbit(want[ok]))


def test_fma_is_fused(run):
    a = f32([1.0 + 2.0 ** -12, 3.0, np.inf, np.nan])
    b = f32([1.0 - 2.0 ** -12, 2.0, 0.0, 1.0])
    c = f32([-1.0, 1.0, 1.0, 1.0])
    got = run("m_fma", a, b, c)
    assert got[0] == np.float32(-(2.0 ** -24))  # exact product: a rounded product would give 0
    assert got[1] == 7.0 and np.isnan(got[2]) and np.isnan(got[3])


def test_clamp(run):
    x = f32([np.nan, -np.inf, np.inf, -2.0, 0.5, 2.0, -0.0])
    got = run("m_clamp", x, np.full(7, -1.0, np.float32), np.full(7, 1.0, np.float32))
    np.testing.assert_array_equal(got, f32([-1.0, -1.0, 1.0, -1.0, 0.5, 1.0, 0.0]))


@pytest.mark.parametrize("name,ref", [("m_isfinite", np.isfinite), ("m_isnan", np.isnan), ("m_isinf", np.isinf)])
def test_classification(run, name, ref):
    x = np.concatenate([SPECIAL, f32([-np.nan, np.float32(np.nan) * -1])])
    np.testing.assert_array_equal(run(name, x) != 0, ref(x))


def test_sin_cos(run):
    rng = np.random.default_rng(3)
    x = np.concatenate([f32(np.linspace(-2 * np.pi, 2 * np.pi, 20001)), f32(rng.uniform(-8192, 8192, 20000)),
                        f32([0.0, -0.0, 8192.0, -8192.0, 1e-40, np.pi / 4, np.pi / 2, np.pi])])
    xd = x.astype(np.float64)
    for name, ref in (("m_sin", np.sin), ("m_cos", np.cos)):
        err = np.abs(run(name, x).astype(np.float64) - ref(xd))
        assert err.max() <= 3e-7, (name, err.max(), x[err.argmax()])
    for name in ("m_sin", "m_cos"):
        got = run(name, f32([np.inf, -np.inf, np.nan]))
        assert np.isnan(got).all()


def test_exp(run):
    rng = np.random.default_rng(4)
    x = np.concatenate([f32(rng.uniform(-87.3, 88.7, 40000)), f32(np.linspace(-1, 1, 20001)),
                        f32([0.0, -0.0, 1e-40, -1e-40, 88.72, 88.73, -87.33, -103.0, -103.9, -104.0, -200.0, 200.0])])
    want = np.exp(x.astype(np.float64))
    got = run("m_exp", x)
    normal = want >= 1.17549435e-38
    assert np.all(np.isinf(got) == (want > 3.4028235e38)), "overflow"
    fin = normal & (want <= 3.4028235e38)
    assert ulp_error(got[fin], want[fin]).max() <= 1.5
    sub = ~normal  # denormal results: within one denormal step (2^-149) plus 2 ulp of the scaled value
    assert np.all(np.abs(got[sub] - want[sub]) <= 2.0 ** -148)
    same_specials(run("m_exp", f32([np.inf, -np.inf, np.nan])), np.array([np.inf, 0.0, np.nan]))


def test_log(run):
    rng = np.random.default_rng(5)
    x = np.concatenate([f32(2.0 ** rng.uniform(-149, 128, 40000)), f32(np.linspace(0.5, 2, 20001)),
                        f32([1.0, 2.0, 0.5, 1e-45, 1e-40, 1.17549435e-38, 3.4028235e38, 1 + 2**-23, 1 - 2**-24])])
    want = np.log(x.astype(np.float64))
    got = run("m_log", x)
    big = np.abs(want) > 1e-3
    assert ulp_error(got[big], want[big]).max() <= 1.5
    assert ulp_error(got[~big], want[~big]).max() <= 1.5
    same_specials(run("m_log", f32([0.0, -0.0, -1.0, -np.inf, np.inf, np.nan])),
                  np.array([-np.inf, -np.inf, np.nan, np.nan, np.inf, np.nan]))


def test_atan2(run):
    rng = np.random.default_rng(6)
    ang = rng.uniform(-np.pi, np.pi, 40000)
    r = 10.0 ** rng.uniform(-30, 30, 40000)
    y = np.concatenate([f32(r * np.sin(ang)), np.repeat(SPECIAL, len(SPECIAL))])
    x = np.concatenate([f32(r * np.cos(ang)), np.tile(SPECIAL, len(SPECIAL))])
    want = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    got = run("m_atan2", y, x)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    ok = ~np.isnan(want)
    assert np.abs(got[ok] - want[ok]).max() <= 3e-7


def test_acos(run):
    x = np.concatenate([f32(np.linspace(-1, 1, 40001)), f32([0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 1e-40])])
    want = np.arccos(x.astype(np.float64))
    assert np.abs(run("m_acos", x) - want).max() <= 3.5e-7
    assert np.isnan(run("m_acos", f32([1.0000001, -1.0000001, np.inf, -np.inf, np.nan]))).all()


def test_float3_helpers(run):
    rng = np.random.default_rng(7)
    a = f32(rng.normal(size=(1000, 3)) * 10.0 ** rng.uniform(-10, 10, (1000, 1)))
    b = f32(rng.normal(size=(1000, 3)))
    a[0] = 0.0
    y = run("vec", a.ravel(), b.ravel(), out_per_item=8).reshape(-1, 8).astype(np.float64)
    ad, bd = a.astype(np.float64), b.astype(np.float64)
    scale = np.linalg.norm(ad, axis=1) * np.linalg.norm(bd, axis=1)
    assert np.all(np.abs(y[:, 0] - np.sum(ad * bd, axis=1)) <= 4e-7 * scale)
    np.testing.assert_allclose(y[:, 1], np.linalg.norm(ad, axis=1), rtol=3e-7)
    assert np.all(np.abs(y[:, 2:5] - np.cross(ad, bd)) <= 4e-7 * scale[:, None])
    np.testing.assert_array_equal(y[0, 5:], 0.0)  # the zero vector normalizes to itself
    n = ad[1:] / np.linalg.norm(ad[1:], axis=1, keepdims=True)
    np.testing.assert_allclose(y[1:, 5:], n, atol=3e-7)
