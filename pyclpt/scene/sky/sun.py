"""The sun's radiance, as Mitsuba 0.5 and Mitsuba 3 model it, in linear sRGB.

Mitsuba 0.5 (``sun``, and the sun of ``sunsky``; :func:`sun_radiance_rgb_05`): Preetham, Shirley &
Smits 1999 (appendix), with the atmospheric data of Iqbal 1983: the extraterrestrial solar spectral
radiance attenuated by Rayleigh and aerosol scattering (Angstrom's formula with beta = 0.04608 T -
0.04586, alpha = 1.3), ozone (0.35 cm), mixed gases and water vapour (2 cm) over the relative optical
mass of the sun's zenith angle, 350-800 nm in 5 nm steps, W / (m^2 sr nm); turned into RGB by
integration against the CIE 1931 curves (the multi-lobe Gaussian fit of Wyman, Sloan & Shirley 2013,
within a few percent of the tables), normalised by the integral of y-bar as Mitsuba's
``Spectrum::fromContinuousSpectrum`` does. Uniform over the disk.

Mitsuba 3 (``sunsky``; :func:`sun_radiance_rgb_3`, :func:`complex_sun_radiance_rgb_3`): Hosek & Wilkie
2013, "Adding a Solar-Radiance Function to the Hosek-Wilkie Skylight Model" (IEEE CG&A 33(3)). By
default Mitsuba 3 uses a uniform disk whose power is the model's: the solar irradiance tabulated per
turbidity and sun elevation (2-89 degrees, 3 degree steps, 11 wavelengths 320-720 nm), interpolated
linearly in both, turned into RGB with Mitsuba 3's CIE curves at those wavelengths, divided by the
real sun's solid angle and multiplied by Mitsuba 3's constant 467.069 / 106.750 (sunsky.h,
SPEC_TO_RGB_SUN_CONV x MI_CIE_Y_NORMALIZATION). With ``complex_sun`` the radiance varies over the disk
(limb darkening, baked into Mitsuba 3's RGB fit: a polynomial in the view direction's elevation per
segment and in cos psi, psi the angle from the disk's centre as seen from the sun's surface).
"""
from __future__ import annotations

import numpy as np

from pyclpt.scene.sky.hosek_wilkie import CIE_Y_INTEGRAL_3, tables

SUN_RADIUS_DEG = 0.5358 * 0.5  # Mitsuba 0.5's SUN_APP_RADIUS is the apparent diameter
CIE_Y_INTEGRAL = 106.856895  # nm: integral of the CIE 1931 y-bar function (Mitsuba's normalisation)
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


def sun_radiance_rgb_05(zenith: float, turbidity: float) -> np.ndarray:
    """Linear-sRGB radiance of the sun disk (Mitsuba 0.5 units), clamped at 0."""
    return np.maximum(spectrum_to_rgb(*sun_spectral_radiance(zenith, turbidity)), 0.0)


# --- Mitsuba 3 -------------------------------------------------------------------------------------

SUN_HALF_APERTURE = np.radians(0.5 * 0.5358)  # Mitsuba 3's real sun, radians
SPEC_TO_RGB_SUN_CONV = 467.069280386  # Mitsuba 3's sunsky.h
_REAL_SUN_SOLID_ANGLE = 2.0 * np.pi * (1.0 - np.cos(SUN_HALF_APERTURE))


def _lerp_axis0(table: np.ndarray, x: float) -> np.ndarray:
    lo = min(int(np.floor(x)), table.shape[0] - 2)
    f = x - lo
    return (1.0 - f) * table[lo] + f * table[lo + 1]


def sun_radiance_rgb_3(sun_elevation: float, turbidity: float) -> np.ndarray:
    """Linear-sRGB radiance of the real-sized sun disk (uniform, Mitsuba 3's default ``complex_sun =
    false``) for the sun's elevation (radians) and turbidity; 0 for a sun below the horizon."""
    if sun_elevation < 0.0:
        return np.zeros(3)
    t = tables()
    irr = _lerp_axis0(t["sun_irradiance"], float(np.clip(turbidity, 1.0, 10.0)) - 1.0)  # (30, 11)
    idx = float(np.clip((np.degrees(sun_elevation) - 2.0) / 3.0, 0.0, 30.0 - (1.0 - 2.0 ** -24)))
    spectrum = _lerp_axis0(irr, idx)  # (11,)
    rgb = (t["srgb_rec"] * spectrum).mean(axis=1)
    return rgb / _REAL_SUN_SOLID_ANGLE * SPEC_TO_RGB_SUN_CONV / CIE_Y_INTEGRAL_3


def complex_sun_radiance_rgb_3(cos_theta: np.ndarray, gamma: np.ndarray, turbidity: float,
                               half_aperture: float) -> np.ndarray:
    """(..., 3) linear-sRGB radiance of the limb-darkened sun (Mitsuba 3's ``complex_sun``) for view
    directions with zenith cosine ``cos_theta`` at angle ``gamma`` (< ``half_aperture``) from the disk's
    centre, at the real sun's power per solid angle (the caller scales by the aperture's area ratio)."""
    data = _lerp_axis0(tables()["sun_rad_rgb"], float(np.clip(turbidity, 1.0, 10.0)) - 1.0)  # (45, 3, 4, 6)
    segments = data.shape[0]
    elevation = 0.5 * np.pi - np.arccos(np.clip(np.asarray(cos_theta, np.float64), -1.0, 1.0))
    pos = np.minimum(np.floor(np.cbrt(2.0 * np.maximum(elevation, 0.0) / np.pi) * segments), segments - 1)
    pos = pos.astype(np.int64)
    x = elevation - 0.5 * np.pi * (pos / segments) ** 3
    sin_g = np.sin(np.asarray(gamma, np.float64))
    cos_psi = np.sqrt(np.maximum(0.0, 1.0 - sin_g * sin_g / np.sin(half_aperture) ** 2))
    xk = x[..., None] ** np.arange(4)  # (..., 4)
    pj = cos_psi[..., None] ** np.arange(6)  # (..., 6)
    coef = data[pos]  # (..., 3, 4, 6)
    rad = np.einsum("...ckj,...k,...j->...c", coef, xk, pj)
    return rad * SPEC_TO_RGB_SUN_CONV / CIE_Y_INTEGRAL_3
