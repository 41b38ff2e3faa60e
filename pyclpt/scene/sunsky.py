"""Sun and sky baked into a lat-long environment map (Mitsuba 0.5's ``sunsky``,
``sky`` and ``sun`` emitters).

Mitsuba 0.5's ``sunsky`` plugin itself rasterises the sky model and the sun disk
into one environment map and hands it to its ``envmap`` emitter; this module
does the same, producing a :class:`pyclpt.scene.model.Envmap` (``resolution`` x
``resolution / 2`` texels, in the texel convention of pyclpt's envmap, which is
Mitsuba 3's: column i at phi = 2 pi (i + 1/2) / W, row j at theta = pi j / (H - 1)).

What is faithful to Mitsuba 0.5
  * The frame: +y is up, direction (sin phi sin theta, cos theta, -cos phi sin theta);
    ``sun_direction`` is a world-space vector, brought into the map's frame by
    ``to_world^-1`` as Mitsuba does; the map carries ``to_world``.
  * The sun (Mitsuba's ``sun``, after Preetham et al. 1999, appendix, with the
    atmospheric data of Iqbal 1983): the extraterrestrial solar spectral radiance
    attenuated by Rayleigh and aerosol scattering (Angstrom's formula with
    beta = 0.04608 T - 0.04586, alpha = 1.3), ozone (0.35 cm), mixed gases and
    water vapour (2 cm) over the relative optical mass of the sun's zenith angle,
    350-800 nm in 5 nm steps; units W / (m^2 sr nm), as Mitsuba's.
  * The sun's angular radius is Mitsuba's (0.5358 / 2 = 0.2679 degrees) times
    ``sun_radius_scale``, and, as in Mitsuba, the *power* of the sun is kept when
    its radius is scaled: the disk's radiance is divided by the growth of its
    solid angle. The disk is rasterised with per-texel supersampling of its
    coverage and normalised so that the bilinearly reconstructed map holds
    exactly radiance x solid angle of the real sun (x ``sun_scale``).
  * The sky is black below the horizon (Mitsuba's default); ``extend=True`` is
    Mitsuba's ``extend`` mode (the horizon's radiance continued downwards, faded
    out by smoothstep(0, 1, 2 - 2 theta / pi)).

What is approximated
  * The sky model is Preetham, Shirley & Smits 1999 ("A Practical Analytic
    Model for Daylight": Perez distributions of luminance Y and chromaticity
    x, y, with the paper's turbidity-linear coefficients and zenith formulas),
    not Mitsuba 0.5's Hosek & Wilkie 2012 model, whose fitted data tables pyclpt
    does not ship. Both are fits to the same kind of simulated clear skies; the
    Preetham sky is known to be somewhat brighter and less saturated near the
    horizon, and it has no ground-albedo parameter: ``albedo`` is validated and
    ignored. It is a fit for turbidity 2-10 (values 1-10 are accepted, as in
    Mitsuba); its 1 / cos(theta) term is evaluated with cos(theta) >= 0.01.
    Measured against Mitsuba 3.9's Hosek-Wilkie ``sunsky`` for the classroom
    scene's sun (turbidity 3, elevation 24.6 degrees): this sky is 2.3-2.9x
    brighter at the zenith, ~1.8x at mid elevation, ~1.6x near the sun and
    0.5-0.7x (and warmer) at the horizon opposite the sun, so sky-lit absolute
    levels are approximate; the sun (which dominates sunlit scenes) follows
    Mitsuba 0.5's own model.
  * Units of the sky: Preetham's luminance (kcd / m^2) is turned into the
    y-bar-weighted mean spectral radiance that Mitsuba's RGB mode uses, i.e.
    divided by 683 lm/W x 106.857 nm (the integral of y-bar), then xyY -> XYZ
    -> linear sRGB (Mitsuba's matrix).
  * Spectral -> RGB of the sun: XYZ by integration against the CIE 1931
    colour-matching functions as approximated by the multi-lobe Gaussian fit of
    Wyman, Sloan & Shirley 2013 (within a few percent of the tabulated
    functions), normalised by the integral of y-bar as Mitsuba's
    ``Spectrum::fromContinuousSpectrum`` does, then linear sRGB.
  * The sky is point-sampled at texel centres (as Mitsuba does) and the sun is
    not clipped by the horizon (as in Mitsuba).
  * Not supported: the time/location parameters (the caller gives
    ``sun_direction``), ``stretch``, and ``sun_radius_scale = 0`` (Mitsuba's
    directional sun): that case falls back to the real sun radius with a warning.
  * A sun below the horizon is an error, as in Mitsuba's sky.
"""
from __future__ import annotations

import logging

import numpy as np

from pyclpt.scene.model import Envmap

log = logging.getLogger(__name__)

SUN_RADIUS_DEG = 0.5358 * 0.5  # Mitsuba 0.5's SUN_APP_RADIUS is the apparent diameter
CIE_Y_INTEGRAL = 106.856895  # nm: integral of the CIE 1931 y-bar function (Mitsuba's normalisation)
LUMINOUS_EFFICACY = 683.0  # lm / W
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])

# --- Atmospheric and solar data (Preetham et al. 1999, appendix; after Iqbal 1983) ---------------
# Ozone absorption coefficient k_o (1/cm)
_KO_WL = np.array([300, 305, 310, 315, 320, 325, 330, 335, 340, 345, 350, 355, 445, 450, 455, 460, 465, 470,
                   475, 480, 485, 490, 495, 500, 505, 510, 515, 520, 525, 530, 535, 540, 545, 550, 555, 560,
                   565, 570, 575, 580, 585, 590, 595, 600, 605, 610, 620, 630, 640, 650, 660, 670, 680, 690,
                   700, 710, 720, 730, 740, 750, 760, 770, 780, 790], float)
_KO = np.array([10.0, 4.8, 2.7, 1.35, .8, .380, .160, .075, .04, .019, .007, .0, .003, .003, .004, .006, .008,
                .009, .012, .014, .017, .021, .025, .03, .035, .04, .045, .048, .057, .063, .07, .075, .08,
                .085, .095, .103, .110, .12, .122, .12, .118, .115, .12, .125, .130, .12, .105, .09, .079,
                .067, .057, .048, .036, .028, .023, .018, .014, .011, .010, .009, .007, .004, .0, .0])
# Mixed-gas absorption coefficient k_g
_KG_WL = np.array([759, 760, 770, 771], float)
_KG = np.array([0.0, 3.0, 0.210, 0.0])
# Water-vapour absorption coefficient k_wa
_KWA_WL = np.array([689, 690, 700, 710, 720, 730, 740, 750, 760, 770, 780, 790, 800], float)
_KWA = np.array([0.0, 0.160e-1, 0.240e-1, 0.125e-1, 0.100e+1, 0.870, 0.610e-1, 0.100e-2, 0.100e-4,
                 0.100e-4, 0.600e-3, 0.175e-1, 0.360e-1])
# Extraterrestrial solar spectral radiance, W / (m^2 sr nm)
_SOL_WL = np.arange(380.0, 751.0, 10.0)
_SOL = np.array([16559.0, 16233.7, 21127.5, 25888.2, 25829.1, 24232.3, 26760.5, 29658.3, 30545.4, 30057.5,
                 30663.7, 28830.4, 28712.1, 27825.0, 27100.6, 27233.6, 26361.3, 25503.8, 25060.2, 25311.6,
                 25355.9, 25134.2, 24631.5, 24173.2, 23685.3, 23212.1, 22827.7, 22339.8, 21970.2, 21526.7,
                 21097.9, 20728.3, 20240.4, 19870.8, 19427.2, 19072.4, 18628.9, 18259.2])


def _interp(x, xp, fp):
    """Piecewise-linear, zero outside the table (Mitsuba's InterpolatedSpectrum)."""
    return np.interp(x, xp, fp, left=0.0, right=0.0)


def cie_xyz_bar(wavelength: np.ndarray) -> np.ndarray:
    """CIE 1931 2-degree colour-matching functions (n, 3), multi-lobe Gaussian fit of
    Wyman, Sloan & Shirley 2013, "Simple Analytic Approximations to the CIE XYZ Color Matching Functions"."""
    lam = np.asarray(wavelength, np.float64)

    def g(mu, s1, s2):
        s = np.where(lam < mu, s1, s2)
        return np.exp(-0.5 * ((lam - mu) / s) ** 2)

    x = 1.056 * g(599.8, 37.9, 31.0) + 0.362 * g(442.0, 16.0, 26.7) - 0.065 * g(501.1, 20.4, 26.2)
    y = 0.821 * g(568.8, 46.9, 40.5) + 0.286 * g(530.9, 16.3, 31.1)
    z = 1.217 * g(437.0, 11.8, 36.0) + 0.681 * g(459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


def spectrum_to_rgb(wavelengths: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear sRGB of a piecewise-linear spectrum (zero outside its samples), as Mitsuba's RGB mode:
    XYZ = average of S * (x, y, z)-bar over 360-830 nm / average of y-bar, then the sRGB matrix."""
    lam = np.arange(360.0, 830.5, 1.0)
    s = _interp(lam, wavelengths, values)
    cmf = cie_xyz_bar(lam)
    xyz = (s[:, None] * cmf).sum(axis=0) / cmf[:, 1].sum()
    return XYZ_TO_SRGB @ xyz


def sun_spectral_radiance(zenith: float, turbidity: float) -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths, radiance W/(m^2 sr nm)) of the sun seen through the atmosphere at a zenith
    angle (radians) and turbidity: Preetham et al. 1999, appendix (Mitsuba 0.5's computeSunRadiance)."""
    beta = 0.04608365822050 * turbidity - 0.04586025928522
    zenith_deg = np.degrees(zenith)
    m = 1.0 / (np.cos(zenith) + 0.15 * (93.885 - zenith_deg) ** -1.253)  # relative optical mass
    lam = np.arange(350.0, 800.5, 5.0)
    um = lam / 1000.0
    tau_r = np.exp(-m * 0.008735 * um ** -4.08)  # Rayleigh
    tau_a = np.exp(-m * beta * um ** -1.3)  # aerosols (Angstrom, alpha = 1.3)
    tau_o = np.exp(-m * _interp(lam, _KO_WL, _KO) * 0.35)  # ozone, 0.35 cm
    kg = _interp(lam, _KG_WL, _KG)
    tau_g = np.exp(-1.41 * kg * m / (1.0 + 118.93 * kg * m) ** 0.45)  # mixed gases
    kwa = _interp(lam, _KWA_WL, _KWA)
    w = 2.0  # precipitable water vapour, cm
    tau_wa = np.exp(-0.2385 * kwa * w * m / (1.0 + 20.07 * kwa * w * m) ** 0.45)
    return lam, _interp(lam, _SOL_WL, _SOL) * tau_r * tau_a * tau_o * tau_g * tau_wa


def sun_radiance_rgb(zenith: float, turbidity: float) -> np.ndarray:
    """Linear-sRGB radiance of the sun disk (Mitsuba 0.5 units), clamped at 0."""
    return np.maximum(spectrum_to_rgb(*sun_spectral_radiance(zenith, turbidity)), 0.0)


# --- Preetham sky ----------------------------------------------------------------------------------

def _perez(theta_cos, gamma, coeffs):
    a, b, c, d, e = coeffs
    return (1.0 + a * np.exp(b / theta_cos)) * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


def preetham_sky_xyY(cos_theta: np.ndarray, gamma: np.ndarray, sun_zenith: float,
                     turbidity: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chromaticity x, y and luminance Y (kcd/m^2) of the clear sky (Preetham et al. 1999) at view
    zenith cosines ``cos_theta`` (> 0) and angles ``gamma`` to the sun."""
    t, ts = turbidity, sun_zenith
    coef_Y = (0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251, 0.1206 * t - 2.5771,
              -0.0670 * t + 0.3703)
    coef_x = (-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125, -0.0641 * t - 0.8989,
              -0.0033 * t + 0.0452)
    coef_y = (-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102, -0.0441 * t - 1.6537,
              -0.0109 * t + 0.0529)
    chi = (4.0 / 9.0 - t / 120.0) * (np.pi - 2.0 * ts)
    Yz = (4.0453 * t - 4.9710) * np.tan(chi) - 0.2155 * t + 2.4192
    ts2, ts3 = ts * ts, ts * ts * ts
    xz = (t * t * (0.00166 * ts3 - 0.00375 * ts2 + 0.00209 * ts)
          + t * (-0.02903 * ts3 + 0.06377 * ts2 - 0.03202 * ts + 0.00394)
          + (0.11693 * ts3 - 0.21196 * ts2 + 0.06052 * ts + 0.25886))
    yz = (t * t * (0.00275 * ts3 - 0.00610 * ts2 + 0.00317 * ts)
          + t * (-0.04214 * ts3 + 0.08970 * ts2 - 0.04153 * ts + 0.00516)
          + (0.15346 * ts3 - 0.26756 * ts2 + 0.06670 * ts + 0.26688))
    ct = np.maximum(cos_theta, 0.01)
    out = []
    for zenith_value, coeffs in ((xz, coef_x), (yz, coef_y), (Yz, coef_Y)):
        out.append(zenith_value * _perez(ct, gamma, coeffs) / _perez(1.0, ts, coeffs))
    return out[0], out[1], out[2]


def preetham_sky_rgb(cos_theta: np.ndarray, gamma: np.ndarray, sun_zenith: float,
                     turbidity: float) -> np.ndarray:
    """Linear-sRGB sky radiance (..., 3) in Mitsuba 0.5's units (y-bar-weighted W/(m^2 sr nm))."""
    x, y, Y = preetham_sky_xyY(cos_theta, gamma, sun_zenith, turbidity)
    Y = np.maximum(Y, 0.0) * (1000.0 / (LUMINOUS_EFFICACY * CIE_Y_INTEGRAL))
    X = x / y * Y
    Z = (1.0 - x - y) / y * Y
    rgb = np.stack([X, Y, Z], axis=-1) @ XYZ_TO_SRGB.T
    return np.maximum(rgb, 0.0)


# --- baking ------------------------------------------------------------------------------------------

def texel_directions(width: int, height: int) -> np.ndarray:
    """Unit directions (H, W, 3) of the texel centres in the map's frame (pyclpt's envmap convention)."""
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    return np.stack([np.sin(phi)[None] * st, np.broadcast_to(ct, (height, width)), -np.cos(phi)[None] * st],
                    axis=-1)


def _row_hat_solid_angle(height: int) -> np.ndarray:
    """Integral of each texel row's bilinear hat function times sin(theta) d theta: the weight of a
    texel row (times 2 pi / W for one texel) in the integral of the reconstructed map."""
    d = np.pi / (height - 1)
    t = d * np.arange(height)
    # rising part on [t - d, t]: -cos(t) + (sin t - sin(t - d)) / d ; falling part on [t, t + d]
    rise = -np.cos(t) + (np.sin(t) - np.sin(t - d)) / d
    fall = np.cos(t) - (np.sin(t + d) - np.sin(t)) / d
    rise[0], fall[-1] = 0.0, 0.0
    return rise + fall


def _sun_coverage(width: int, height: int, sun: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Texels near the sun (flat indices) and the fraction of each texel's footprint (half a texel
    either side of its centre in phi and theta, uniform in solid angle) inside the sun's cone."""
    dirs = texel_directions(width, height).reshape(-1, 3)
    dtheta, dphi = np.pi / (height - 1), 2.0 * np.pi / width
    reach = radius + 0.75 * np.hypot(dtheta, dphi)
    near = np.flatnonzero(dirs @ sun >= np.cos(min(reach, np.pi)))
    n = int(np.clip(np.ceil(4.0 * max(dtheta, dphi) / radius), 16, 256))
    j, i = np.divmod(near, width)
    s = (np.arange(n) + 0.5) / n
    th0 = np.clip(np.pi * j / (height - 1) - 0.5 * dtheta, 0.0, np.pi)
    th1 = np.clip(np.pi * j / (height - 1) + 0.5 * dtheta, 0.0, np.pi)
    c0, c1 = np.cos(th0), np.cos(th1)
    cos_cosine = np.cos(radius)
    cover = np.zeros(len(near))
    for k in range(0, len(near), 256):  # bounded memory
        sl = slice(k, k + 256)
        ct = c0[sl, None] + s[None, :] * (c1[sl] - c0[sl])[:, None]  # (m, n) uniform in cos theta
        st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
        phi = 2.0 * np.pi * (i[sl, None] + s[None, :]) / width  # (m, n) across the footprint
        dot = (np.sin(phi)[:, None, :] * st[:, :, None] * sun[0] + ct[:, :, None] * sun[1]
               - np.cos(phi)[:, None, :] * st[:, :, None] * sun[2])
        cover[sl] = (dot >= cos_cosine).mean(axis=(1, 2))
    return near, cover


def _check(value, name: str, lo: float | None = None, hi: float | None = None) -> float:
    v = float(value)
    if not np.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f" in [{lo}, {hi}]" if hi is not None else (f" >= {lo}" if lo is not None else "")
        raise ValueError(f"sunsky: {name} must be a finite number{rng}, got {value!r}")
    return v


def sunsky_envmap(sun_direction, turbidity: float = 3.0, sky_scale: float = 1.0, sun_scale: float = 1.0,
                  sun_radius_scale: float = 1.0, resolution: int = 512, albedo: float = 0.15,
                  to_world=None, extend: bool = False, name: str = "sunsky") -> Envmap:
    """Bake a sky (``sky_scale`` x Preetham) and a sun disk (``sun_scale`` x Preetham/Iqbal sun,
    radius x ``sun_radius_scale`` at constant power) into a ``resolution`` x ``resolution // 2`` envmap.

    ``sun_direction`` points from the scene towards the sun, in world space; ``to_world`` (4x4, a
    rotation) orients the sky's frame (+y up) in the world, as Mitsuba's ``toWorld``. Raises
    ValueError (message starting with "sunsky:") on bad parameters or a sun below the horizon.
    See the module docstring for what is approximated."""
    d = np.asarray(sun_direction, np.float64).reshape(-1)
    if d.size != 3 or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
        raise ValueError(f"sunsky: sun_direction must be 3 finite numbers, not all zero, got {sun_direction!r}")
    turbidity = _check(turbidity, "turbidity", 1.0, 10.0)
    sky_scale = _check(sky_scale, "sky_scale", 0.0)
    sun_scale = _check(sun_scale, "sun_scale", 0.0)
    sun_radius_scale = _check(sun_radius_scale, "sun_radius_scale", 0.0)
    _check(albedo, "albedo", 0.0, 1.0)  # no effect on the Preetham sky
    res = _check(resolution, "resolution", 8, 16384)
    if res != int(res):
        raise ValueError(f"sunsky: resolution must be an integer, got {resolution!r}")
    width, height = int(res), int(res) // 2
    if sun_radius_scale == 0.0:
        log.warning("sunsky: sun_radius_scale = 0 (a directional sun) is not supported; "
                    "the sun keeps its real angular radius")
        sun_radius_scale = 1.0
    radius = np.radians(SUN_RADIUS_DEG) * sun_radius_scale
    if radius > 0.5 * np.pi:
        raise ValueError(f"sunsky: sun_radius_scale {sun_radius_scale} makes the sun wider than a hemisphere")
    m = np.eye(4) if to_world is None else np.asarray(to_world, np.float64).reshape(4, 4)
    if not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise ValueError("sunsky: to_world must be a finite, invertible transform")
    sun = np.linalg.solve(m[:3, :3], d)
    sun /= np.linalg.norm(sun)
    sun_zenith = float(np.arccos(np.clip(sun[1], -1.0, 1.0)))
    if sun[1] < 0.0:
        raise ValueError(f"sunsky: the sun is below the horizon (sun_direction {d.tolist()} has elevation "
                         f"{90.0 - np.degrees(sun_zenith):.2f} degrees); the sky model does not support it")

    dirs = texel_directions(width, height)
    pixels = np.zeros((height, width, 3))
    if sky_scale > 0:
        cos_t = dirs[..., 1]
        up = cos_t > 0.0
        view = dirs
        fade = np.ones((height, width))
        if extend:  # Mitsuba's "extend": the horizon's radiance continued downwards, faded out
            theta = np.arccos(np.clip(cos_t, -1.0, 1.0))
            horizon = dirs.copy()
            horizon[..., 1] = np.where(up, cos_t, np.cos(0.5 * np.pi - 1e-4))
            s = np.sqrt(np.maximum(0.0, 1.0 - horizon[..., 1] ** 2) / np.maximum(1.0 - cos_t**2, 1e-300))
            horizon[..., 0] = np.where(up, dirs[..., 0], dirs[..., 0] * s)
            horizon[..., 2] = np.where(up, dirs[..., 2], dirs[..., 2] * s)
            view = horizon
            x = np.clip(2.0 - 2.0 * theta / np.pi, 0.0, 1.0)
            fade = x * x * (3.0 - 2.0 * x)
            up = np.ones_like(up)
        gamma = np.arccos(np.clip(view @ sun, -1.0, 1.0))
        sky = preetham_sky_rgb(view[..., 1], gamma, sun_zenith, turbidity)
        pixels += np.where(up[..., None], sky * (sky_scale * fade)[..., None], 0.0)
    if sun_scale > 0:
        sun_rgb = sun_radiance_rgb(sun_zenith, turbidity) * sun_scale
        real_solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(SUN_RADIUS_DEG)))
        near, cover = _sun_coverage(width, height, sun, radius)
        if not cover.any():  # a disk far below texel size missed by every subsample
            near = np.array([int(np.argmax(dirs.reshape(-1, 3) @ sun))])
            cover = np.ones(1)
        weight = _row_hat_solid_angle(height)[near // width] * (2.0 * np.pi / width)  # texel solid angle
        level = real_solid_angle / float((cover * weight).sum())
        flat = pixels.reshape(-1, 3)
        flat[near] += cover[:, None] * (level * sun_rgb)[None, :]
    if not np.all(np.isfinite(pixels)):
        raise ValueError("sunsky: the sky model produced non-finite values for these parameters")
    return Envmap(pixels.astype(np.float32), np.eye(4) if to_world is None else m, 1.0, name)
