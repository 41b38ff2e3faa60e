"""The film's reconstruction filter -> the -DSCENE_FILTER specialisation and the CONST_FILTER_* constants of
``cl/scene/scene.h``, which ``cl/film/rfilter.h`` samples the camera ray's offset in the pixel from.

Filter importance sampling (``ReconstructionFilter(kind, estimator="importance")``): each camera ray's offset
from its pixel's centre is drawn, per axis, from the normalised filter w(x) / integral(w), and its sample
weight is 1, so the plain average of a pixel's samples estimates integral(w L) / integral(w), what Mitsuba's
film converges to when it splats every sample with weight w(x) w(y) and divides by the sum of the weights.
(``estimator="splat"``, the default: that splatting film itself, pyclpt/film/splat.py; the camera ray then
gets the box's jitter.)

- ``box``: uniform in [-0.5, 0.5) (the jitter as it always was; no -D, the same code);
- ``tent`` (radius r): the inverse of its CDF, closed form;
- ``gaussian`` (stddev s, cut off at R = 4 s, minus its value there): |x| from a table of the inverse
  CDF of the half filter, tabulated in t = (1 - v)^(1/4) (v = |2u - 1| the half filter's CDF value) at
  :data:`FILTER_TABLE` + 1 nodes, interpolated linearly. In t the inverse is smooth at both ends and
  the tails get nodes (in t = sqrt(1 - v) a third of the nodes would fall within 0.1% of the mass):
  the sampled density is within 0.15% of the filter's in bins of 1/64 of the radius over 99.99% of the
  mass, 1.5% in the outermost bins (2e-6 of the mass), for any stddev (measured against the exact CDF).
"""
from __future__ import annotations

import math

import numpy as np

from pyclpt.scene.model import ReconstructionFilter

FILTER_KINDS = {"box": 0, "tent": 1, "gaussian": 2}  # FILTER_* of cl/scene/scene.h
FILTER_TABLE = 128  # cells of the gaussian's inverse-CDF table (FILTER_TABLE in cl/scene/scene.h)
CONST_FILTER_RADIUS = 34  # the tent's radius (CONST_* of cl/scene/scene.h)
CONST_FILTER_TABLE = 35  # FILTER_TABLE + 1 floats: the gaussian's |offset| at t = k / FILTER_TABLE
FILTER_CONSTS = 1 + FILTER_TABLE + 1


def filter_kind(rfilter: ReconstructionFilter) -> int:
    """The FILTER_* the kernels compile for (-DSCENE_FILTER; 0, the box, is the default). A splatting filter
    (``estimator="splat"``) compiles the box's uniform jitter: the film applies the filter
    (pyclpt/film/splat.py)."""
    return 0 if rfilter.estimator == "splat" else FILTER_KINDS[rfilter.kind]


def filter_eval(rfilter: ReconstructionFilter, x: np.ndarray) -> np.ndarray:
    """w(x) as Mitsuba defines it (src/rfilters/{box,tent,gaussian}.cpp), in float64."""
    x = np.asarray(x, np.float64)
    if rfilter.kind == "box":
        return ((x >= -0.5) & (x < 0.5)).astype(np.float64)
    if rfilter.kind == "tent":
        return np.maximum(0.0, 1.0 - np.abs(x) / rfilter.radius)
    alpha = -1.0 / (2.0 * rfilter.stddev ** 2)
    return np.maximum(0.0, np.exp(alpha * x * x) - math.exp(alpha * (4.0 * rfilter.stddev) ** 2))


def gaussian_half_cdf(stddev: float, x: np.ndarray) -> np.ndarray:
    """The CDF of |offset| under the truncated gaussian filter, for 0 <= x <= 4 stddev (float64)."""
    x = np.minimum(np.asarray(x, np.float64), 4.0 * stddev)
    k = stddev * math.sqrt(math.pi / 2.0)
    bias = math.exp(-8.0)
    erf = np.vectorize(math.erf, otypes=[np.float64])
    total = k * math.erf(4.0 / math.sqrt(2.0)) - bias * 4.0 * stddev
    return (k * erf(x / (stddev * math.sqrt(2.0))) - bias * x) / total


def gaussian_table(stddev: float) -> np.ndarray:
    """(FILTER_TABLE + 1,) float32: |offset| at t = k / FILTER_TABLE, where the half filter's CDF is
    1 - t^4 (bisection on the CDF in float64)."""
    t = np.arange(FILTER_TABLE + 1, dtype=np.float64) / FILTER_TABLE
    target = 1.0 - t ** 4
    lo, hi = np.zeros_like(t), np.full_like(t, 4.0 * stddev)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        below = gaussian_half_cdf(stddev, mid) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    x = 0.5 * (lo + hi)
    x[0], x[-1] = 4.0 * stddev, 0.0
    return x.astype(np.float32)


def filter_consts(rfilter: ReconstructionFilter) -> np.ndarray:
    """The CONST_FILTER_* block (FILTER_CONSTS floats): the tent's radius, the gaussian's table."""
    c = np.zeros(FILTER_CONSTS, np.float32)
    if rfilter.kind == "tent":
        c[0] = rfilter.radius
    elif rfilter.kind == "gaussian":
        c[0] = 4.0 * rfilter.stddev
        c[1:] = gaussian_table(rfilter.stddev)
    return c


def sample_offsets(rfilter: ReconstructionFilter, u: np.ndarray) -> np.ndarray:
    """The offsets from the pixel's centre that cl/film/rfilter.h draws for uniform numbers ``u``, in
    numpy (float64 arithmetic on the float32 table; for tests and figures)."""
    u = np.asarray(u, np.float64)
    if rfilter.kind == "box":
        return u - 0.5
    if rfilter.kind == "tent":
        return rfilter.radius * np.where(u < 0.5, np.sqrt(2.0 * u) - 1.0, 1.0 - np.sqrt(2.0 - 2.0 * u))
    table = gaussian_table(rfilter.stddev).astype(np.float64)
    t = np.sqrt(np.sqrt(1.0 - np.abs(2.0 * u - 1.0))) * FILTER_TABLE
    k = np.minimum(t.astype(np.int64), FILTER_TABLE - 1)
    f = t - k
    x = table[k] + f * (table[k + 1] - table[k])
    return np.where(u < 0.5, -x, x)
