"""The Hosek-Wilkie clear-sky model, RGB version (Hosek & Wilkie 2012, "An Analytic Model for Full
Spectral Sky-Dome Radiance", ACM TOG 31(4)), as Mitsuba 0.5 (``sky``) and Mitsuba 3 (``sunsky``) use it.

The fitted data (``hosek_wilkie_rgb.npz`` beside this file, written by ``bench/tools/make_sky_tables.py``) are
the tables ``datasetRGB1-3`` / ``datasetRGBRad1-3`` of Hosek & Wilkie's ``ArHosekSkyModelData_RGB.h``
(3-clause BSD, ``HOSEK_WILKIE_LICENSE.txt``), stored as (turbidity 1-10, albedo 0/1, 6 control points,
R/G/B[, 9 coefficients]). :func:`sky_state` interpolates them as the model does: linearly in turbidity
and in the ground albedo (per channel), and along the sun's elevation eta by the quintic Bezier curve in
(eta / (pi/2))^(1/3). :func:`sky_radiance` is the model's radiance F(theta, gamma) x L_M in the units of
the RGB tables; Mitsuba divides it by the integral of the CIE y-bar curve (:data:`CIE_Y_INTEGRAL_05`,
:data:`CIE_Y_INTEGRAL_3`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

#: Mitsuba 0.5's divisor of the RGB model (sky.cpp: "sum of Spectrum::CIE_Y").
CIE_Y_INTEGRAL_05 = 106.856980
#: Mitsuba 3's (1 / MI_CIE_Y_NORMALIZATION).
CIE_Y_INTEGRAL_3 = 106.7502593994140625
_DATA = Path(__file__).with_name("hosek_wilkie_rgb.npz")


@lru_cache(maxsize=1)
def tables() -> dict[str, np.ndarray]:
    """The data tables (see ``bench/tools/make_sky_tables.py`` for their layout), read once."""
    with np.load(_DATA) as f:
        return {k: np.asarray(f[k], np.float64) for k in f.files}


@dataclass(frozen=True)
class SkyState:
    """The model for one sun elevation, turbidity and albedo: 9 coefficients A..I and the radiance
    scale L_M per channel."""
    coefficients: np.ndarray  # (3, 9)
    radiance: np.ndarray  # (3,)


def _interp_turbidity_albedo(table: np.ndarray, turbidity: float, albedo: np.ndarray) -> np.ndarray:
    """(turbidity, albedo, ctrl, channel, ...) -> (ctrl, channel, ...), linear in both."""
    t = float(np.clip(turbidity, 1.0, 10.0)) - 1.0
    lo = min(int(np.floor(t)), 8)
    f = t - lo
    by_t = (1.0 - f) * table[lo] + f * table[lo + 1]  # (2, ctrl, channel, ...)
    a = np.asarray(albedo, np.float64).reshape((1, 3) + (1,) * (table.ndim - 4))
    return (1.0 - a) * by_t[0] + a * by_t[1]


def _bezier(ctrl: np.ndarray, elevation: float) -> np.ndarray:
    """Quintic Bezier over the 6 control points (axis 0) at x = (elevation / (pi/2))^(1/3)."""
    x = min(float(np.cbrt(max(elevation, 0.0) / (0.5 * np.pi))), 1.0 - 2.0 ** -24)
    binom = np.array([1.0, 5.0, 10.0, 10.0, 5.0, 1.0])
    k = np.arange(6)
    w = binom * x ** k * (1.0 - x) ** (5 - k)
    return np.tensordot(w, ctrl, axes=(0, 0))


def sky_state(turbidity: float, albedo, sun_elevation: float) -> SkyState:
    """The model's state for a turbidity in [1, 10], an RGB (or grey) ground albedo in [0, 1] and the
    sun's elevation above the horizon (radians, >= 0)."""
    alb = np.broadcast_to(np.asarray(albedo, np.float64), (3,))
    t = tables()
    return SkyState(_bezier(_interp_turbidity_albedo(t["sky_params"], turbidity, alb), sun_elevation),
                    _bezier(_interp_turbidity_albedo(t["sky_rad"], turbidity, alb), sun_elevation))


def sky_radiance(state: SkyState, cos_theta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """(..., 3): F(theta, gamma) x L_M for view directions with zenith cosine ``cos_theta`` (>= 0) at
    angle ``gamma`` from the sun (Hosek & Wilkie's ArHosekSkyModel_GetRadianceInternal)."""
    c = state.coefficients
    ct = np.asarray(cos_theta, np.float64)[..., None]
    g = np.asarray(gamma, np.float64)[..., None]
    cg = np.cos(g)
    a, b, cc, d, e, f, gg, h, i = (c[:, k] for k in range(9))
    chi = (1.0 + cg * cg) / (1.0 + i * i - 2.0 * i * cg) ** 1.5
    value = (1.0 + a * np.exp(b / (ct + 0.01))) * (cc + d * np.exp(e * g) + f * cg * cg + gg * chi
                                                    + h * np.sqrt(np.maximum(ct, 0.0)))
    return value * state.radiance
