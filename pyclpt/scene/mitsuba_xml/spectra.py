"""Spectra to linear sRGB, as Mitsuba's RGB variants see them: the CIE 1931 colour-matching functions
(Wyman, Sloan and Shirley's fit), :func:`spectrum_to_rgb` for ``<spectrum>`` values and files, and
:func:`blackbody_to_rgb` for ``<blackbody>`` emitters.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np

_LAMBDA = np.arange(360.0, 831.0, 1.0)  # nm, 1 nm steps over the CIE range


def _lobe(x: np.ndarray, mu: float, s1: float, s2: float) -> np.ndarray:
    t = (x - mu) / np.where(x < mu, s1, s2)
    return np.exp(-0.5 * t * t)


def _cie_xyz(lam: np.ndarray) -> np.ndarray:
    """CIE 1931 2-degree colour-matching functions, Wyman, Sloan and Shirley's (2013) multi-lobe fit."""
    x = 1.056 * _lobe(lam, 599.8, 37.9, 31.0) + 0.362 * _lobe(lam, 442.0, 16.0, 26.7) \
        - 0.065 * _lobe(lam, 501.1, 20.4, 26.2)
    y = 0.821 * _lobe(lam, 568.8, 46.9, 40.5) + 0.286 * _lobe(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _lobe(lam, 437.0, 11.8, 36.0) + 0.681 * _lobe(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z])


_XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                         [-0.9692660, 1.8760108, 0.0415560],
                         [0.0556434, -0.2040259, 1.0572252]])
_CMF = _cie_xyz(_LAMBDA)  # (3, N)
_WHITE = _XYZ_TO_SRGB @ _CMF.sum(axis=1)  # linear sRGB of a constant spectrum of 1
_Y_NORM = float(_CMF[1].sum())  # Mitsuba's CIE_Y_NORMALIZATION: a constant 1 has Y = 1


def _sampled_to_rgb(values: np.ndarray, white_balanced: bool) -> list[float]:
    """Linear sRGB of a spectrum sampled on ``_LAMBDA``: integrated against the CIE curves, XYZ to
    linear sRGB, then divided channel-wise by the result for a constant 1 (``white_balanced``: a
    constant 1 maps to (1, 1, 1)) or by the integral of y-bar (colorimetric, as Mitsuba: Y is the
    ȳ-weighted mean, and the sRGB white, D65, maps to gray). Negative channels are clamped to 0."""
    rgb = _XYZ_TO_SRGB @ (_CMF @ values)
    rgb = rgb / _WHITE if white_balanced else rgb / _Y_NORM
    return [float(v) for v in np.maximum(rgb, 0.0)]


def spectrum_to_rgb(wavelengths: Iterable[float], values: Iterable[float]) -> list[float]:
    """Linear sRGB of a piecewise-linear spectrum (wavelengths in nm, increasing; zero outside
    them), normalised so that a constant spectrum of 1 over the visible range (360-830 nm) gives
    (1, 1, 1). Negative channels (out of gamut) are clamped to 0."""
    wl = np.asarray(list(wavelengths), np.float64)
    v = np.asarray(list(values), np.float64)
    s = np.interp(_LAMBDA, wl, v, left=0.0, right=0.0)
    return _sampled_to_rgb(s, white_balanced=True)


def blackbody_to_rgb(temperature: float, scale: float = 1.0) -> list[float]:
    """Linear sRGB of a black body, times ``scale``: Planck's spectral radiance in W/(m^2 sr nm), as
    Mitsuba's ``blackbody``, converted colorimetrically (XYZ with Y the ȳ-weighted mean radiance,
    then linear sRGB, without :func:`spectrum_to_rgb`'s white balance), so a 6500 K body is about
    neutral, about 4.2e4 per channel."""
    h, c, k = 6.62607015e-34, 299792458.0, 1.380649e-23
    lam = _LAMBDA * 1e-9
    with np.errstate(over="ignore"):
        radiance = 1e-9 * (2.0 * h * c * c) / lam**5 / np.expm1((h * c) / (lam * k * temperature))
    return [scale * v for v in _sampled_to_rgb(radiance, white_balanced=False)]
