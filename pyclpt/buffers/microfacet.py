"""Host-side microfacet integrals: the tables of Mitsuba 3's ``roughplastic``.

Mitsuba's rough plastic weights its diffuse base by the energy a rough dielectric
coating transmits, t(cos theta), and divides by one minus the coating's internal
reflectance (``RoughPlastic::parameters_changed`` with ``eval_transmittance`` /
``eval_reflectance`` of ``mitsuba/render/microfacet.h``): single scattering on a
Smith microsurface (Walter et al. 2007),

    t(wi) = integral over visible normals m of (1 - F(wi.m)) G1(wo_t, m),  wo_t refracted,
    r(wi) = integral over visible normals m of F(wi.m) G1(wo_r, m),        wo_r reflected,
    internal reflectance = 2 * mean over 64 cosines mu in [0, 1] of r(mu; 1/eta) * mu.

Mitsuba integrates over visible-normal samples at Gauss-Legendre nodes; here the
same integrals are taken over normals distributed as D(m) cos(m) (whose inverse
CDF is closed-form for both distributions), with the visible-normal density
D G1(wi) (wi.m) / cos(wi) written out as the ratio G1(wi) (wi.m) / (cos(wi) cos(m)).

Mitsuba keeps t in a 64-entry table; a material record has room for 5 floats, so
pyclpt keeps RP_KNOTS = 10 half-precision knots of t at cos = (k / 9)^2
(uniform in sqrt(cos), denser at grazing angles where t bends), interpolated
linearly in sqrt(cos) on the device (``roughplastic_transmittance`` in
cl/scene/bsdfs/roughplastic.h). Against the exact curve the interpolation is off by at most ~0.04 at
grazing angles for near-smooth coatings and by ~0.002 on cosine-weighted average.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

RP_KNOTS = 10  # knots of t(cos): cos_k = (k / (RP_KNOTS - 1))^2 (cl/scene/bsdf.h)
_QUAD = 96  # Gauss-Legendre nodes per dimension of the normal integrals (t to ~1e-3)
_R_INT_RES = 64  # Mitsuba's MI_ROUGH_TRANSMITTANCE_RES: the cosines of the internal reflectance average


def fresnel(cos_i: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dielectric Fresnel for a signed cos_i (negative: from inside), eta = int / ext.

    Returns (F, signed cos of the refracted direction, eta_ti) like cl/scene/bsdf.h."""
    outside = cos_i >= 0.0
    eta_it = np.where(outside, eta, 1.0 / eta)
    eta_ti = 1.0 / eta_it
    cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti
    ci = np.abs(cos_i)
    ct = np.sqrt(np.maximum(cos_t2, 0.0))
    a_s = (ci - eta_it * ct) / np.maximum(ci + eta_it * ct, 1e-300)
    a_p = (eta_it * ci - ct) / np.maximum(eta_it * ci + ct, 1e-300)
    f = np.where(cos_t2 <= 0.0, 1.0, 0.5 * (a_s * a_s + a_p * a_p))
    return f, np.where(outside, -ct, ct), eta_ti


def _erfc(x: np.ndarray) -> np.ndarray:
    """erfc for x >= 0, fractional error < 1.2e-7 (Numerical Recipes' Chebyshev fit ``erfcc``)."""
    t = 1.0 / (1.0 + 0.5 * x)
    poly = -1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (
        -0.18628806 + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (
            -0.82215223 + t * 0.17087277))))))))
    return t * np.exp(-x * x + poly)


def smith_g1(v: np.ndarray, m: np.ndarray, alpha: float, beckmann: bool) -> np.ndarray:
    """Smith's masking for direction(s) v and normal(s) m (exact Beckmann form, as on the device)."""
    xy2 = alpha * alpha * (v[..., 0] ** 2 + v[..., 1] ** 2)
    z = np.abs(v[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        if beckmann:
            a = z / np.sqrt(xy2)
            a_c = np.minimum(a, 30.0)
            lam = 0.5 * (np.exp(-a_c * a_c) / (a_c * np.sqrt(np.pi)) - _erfc(a_c))
            g = np.where(a >= 30.0, 1.0, 1.0 / (1.0 + lam))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + xy2 / (z * z)))
    g = np.where(xy2 == 0.0, 1.0, g)
    return np.where((v * m).sum(-1) * v[..., 2] <= 0.0, 0.0, g)


def _normals(alpha: float, beckmann: bool, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes of normals distributed as D(m) cos(m): (n, n, 3) normals, (n, n) weights."""
    x, w = np.polynomial.legendre.leggauss(n)
    q, wq = 0.5 * (x + 1.0), 0.5 * w
    phi, wp = np.pi * (x + 1.0), np.pi * w
    # inverse CDF of tan^2(theta_m) / alpha^2: GGX q / (1 - q), Beckmann -log(1 - q)
    r2 = -np.log1p(-q) if beckmann else q / (1.0 - q)
    tan = alpha * np.sqrt(r2)[:, None]
    m = np.stack(np.broadcast_arrays(tan * np.cos(phi)[None, :], tan * np.sin(phi)[None, :], 1.0), axis=-1)
    m = m / np.linalg.norm(m, axis=-1, keepdims=True)
    return m, np.outer(wq, wp) / (2.0 * np.pi)


def _single_scattering(mu: np.ndarray, alpha: float, eta: float, beckmann: bool, transmit: bool,
                       n: int = _QUAD) -> np.ndarray:
    """t(mu) (transmit) or r(mu) (reflect) of a rough dielectric interface seen from the side where
    the relative IOR across it is eta, for incident cosines mu."""
    alpha = max(float(alpha), 1e-4)  # Mitsuba's MicrofacetDistribution clamps alpha the same way
    m, weights = _normals(alpha, beckmann, n)
    c = np.maximum(np.asarray(mu, np.float64), 1e-6)[:, None, None]  # (K, 1, 1)
    wi = np.stack(np.broadcast_arrays(np.sqrt(np.maximum(0.0, 1.0 - c * c)), 0.0, c), axis=-1)  # (K, 1, 1, 3)
    dot = (m[None] * wi).sum(-1)  # (K, n, n)
    f, cos_t, eta_ti = fresnel(dot, eta)
    if transmit:
        wo = (dot * eta_ti + cos_t)[..., None] * m[None] - eta_ti[..., None] * wi
        val = (1.0 - f) * smith_g1(wo, m, alpha, beckmann) * (wo[..., 2] < 0.0)
    else:
        wo = 2.0 * dot[..., None] * m[None] - wi
        val = f * smith_g1(wo, m, alpha, beckmann) * (wo[..., 2] > 0.0)
    # the visible-normal density over the D(m) cos(m) density of the nodes
    vis = smith_g1(np.broadcast_to(wi, wo.shape), m, alpha, beckmann) * np.maximum(dot, 0.0) / (c * m[..., 2])
    return (val * vis * weights).sum(axis=(1, 2))


def rough_transmittance(mu, alpha: float, eta: float, beckmann: bool = False) -> np.ndarray:
    """Energy transmitted through a rough dielectric interface (no radiance scaling), Mitsuba's
    ``eval_transmittance``."""
    return _single_scattering(np.atleast_1d(mu), alpha, eta, beckmann, transmit=True)


def rough_reflectance(mu, alpha: float, eta: float, beckmann: bool = False, n: int = _QUAD) -> np.ndarray:
    """Energy reflected once by a rough dielectric interface, Mitsuba's ``eval_reflectance``."""
    return _single_scattering(np.atleast_1d(mu), alpha, eta, beckmann, transmit=False, n=n)


@lru_cache(maxsize=256)
def roughplastic_tables(alpha: float, eta: float, beckmann: bool) -> tuple[np.ndarray, float]:
    """(RP_KNOTS float16 knots of t at cos = (k / (RP_KNOTS - 1))^2, internal reflectance)."""
    cos_k = (np.arange(RP_KNOTS) / (RP_KNOTS - 1)) ** 2
    knots = np.clip(rough_transmittance(cos_k, alpha, eta, beckmann), 0.0, 1.0).astype(np.float16)
    knots.setflags(write=False)
    mu = np.linspace(0.0, 1.0, _R_INT_RES)
    internal = 2.0 * float(np.mean(rough_reflectance(mu, alpha, 1.0 / eta, beckmann, n=64) * np.maximum(mu, 1e-6)))
    return knots, internal
