"""The sun and sky baked into a lat-long :class:`~pyclpt.scene.model.Envmap`, as Mitsuba 0.5's
``sunsky`` does (and, for Mitsuba 3's analytic ``sunsky``, evaluated the same way at the map's texels).

The map has ``resolution`` x ``resolution / 2`` texels in pyclpt's envmap convention (Mitsuba 3's:
column i at phi = 2 pi (i + 1/2) / W, row j at theta = pi j / (H - 1); direction (sin phi sin theta,
cos theta, -cos phi sin theta), +y up). The sky is point-sampled at texel centres; the sun disk is
rasterised with per-texel supersampling of its footprint and normalised so that the bilinearly
reconstructed map holds the sun's power exactly.
"""
from __future__ import annotations

import numpy as np

from pyclpt.scene.model import Envmap
from pyclpt.scene.sky.hosek_wilkie import CIE_Y_INTEGRAL_05, CIE_Y_INTEGRAL_3, sky_radiance, sky_state
from pyclpt.scene.sky.sun import (
    SUN_HALF_APERTURE,
    SUN_RADIUS_DEG,
    complex_sun_radiance_rgb_3,
    sun_radiance_rgb_05,
    sun_radiance_rgb_3,
)
from pyclpt.scene.sky.sun_position import SunTime, local_sun_direction

CONVENTIONS = ("mitsuba0.5", "mitsuba3")
#: Mitsuba 3's sky frame (+z up) from the map's (+y up): local = _M3_FROM_MAP @ map.
_M3_FROM_MAP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
DEFAULT_ALBEDO = {"mitsuba0.5": 0.2, "mitsuba3": 0.3}  # sky.cpp (0.5), sunsky.cpp (3)
DEFAULT_RESOLUTION = {"mitsuba0.5": 512, "mitsuba3": 1024}


def texel_directions(width: int, height: int) -> np.ndarray:
    """Unit directions (H, W, 3) of the texel centres in the map's frame (pyclpt's envmap convention)."""
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    return np.stack([np.sin(phi)[None] * st, np.broadcast_to(ct, (height, width)), -np.cos(phi)[None] * st],
                    axis=-1)


def row_hat_solid_angle(height: int) -> np.ndarray:
    """Integral of each texel row's bilinear hat function times sin(theta) d theta: the weight of a
    texel row (times 2 pi / W for one texel) in the integral of the reconstructed map."""
    d = np.pi / (height - 1)
    t = d * np.arange(height)
    # rising part on [t - d, t]: -cos(t) + (sin t - sin(t - d)) / d ; falling part on [t, t + d]
    rise = -np.cos(t) + (np.sin(t) - np.sin(t - d)) / d
    fall = np.cos(t) - (np.sin(t + d) - np.sin(t)) / d
    rise[0], fall[-1] = 0.0, 0.0
    return rise + fall


def _sun_footprints(width: int, height: int, sun: np.ndarray, radius: float, value):
    """Texels near the sun (flat indices), their footprints' solid angles, and the mean over each
    footprint (half a texel either side of its centre in phi and theta, uniform in solid angle) of
    ``value(dirs (m, n, n, 3), inside (m, n, n)) -> (m, n, n, C)``."""
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
    box = dphi * (c0 - c1)
    cos_radius = np.cos(radius)
    out = []
    for k in range(0, len(near), 64):  # bounded memory
        sl = slice(k, k + 64)
        ct = c0[sl, None] + s[None, :] * (c1[sl] - c0[sl])[:, None]  # (m, n) uniform in cos theta
        st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
        phi = 2.0 * np.pi * (i[sl, None] + s[None, :]) / width  # (m, n) across the footprint
        d = np.stack(np.broadcast_arrays(np.sin(phi)[:, None, :] * st[:, :, None],
                                         np.broadcast_to(ct[:, :, None], (len(ct), n, n)),
                                         -np.cos(phi)[:, None, :] * st[:, :, None]), axis=-1)
        out.append(value(d, d @ sun >= cos_radius).mean(axis=(1, 2)))
    values = np.concatenate(out) if out else np.zeros((0, 1))
    return near, box, values


def _check(value, name: str, lo: float | None = None, hi: float | None = None) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"sunsky: {name} must be a number, got {value!r}") from None
    if not np.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f" in [{lo}, {hi}]" if hi is not None else (f" >= {lo}" if lo is not None else "")
        raise ValueError(f"sunsky: {name} must be a finite number{rng}, got {value!r}")
    return v


def _sun_in_map(sun_direction, time: SunTime | None, to_world, convention: str) -> tuple[np.ndarray, np.ndarray]:
    """The sun's unit direction in the map's frame (+y up) and the map's to_world, from ``sun_direction``
    (world space) or ``time`` (in the sky's frame); ValueError for bad input or a sun below the horizon."""
    m = np.eye(4) if to_world is None else np.asarray(to_world, np.float64).reshape(4, 4)
    if not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise ValueError("sunsky: to_world must be a finite, invertible transform")
    if sun_direction is not None:
        if time is not None:
            raise ValueError("sunsky: give sun_direction or a time and place (latitude, longitude, ...), not both")
        d = np.asarray(sun_direction, np.float64).reshape(-1)
        if d.size != 3 or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
            raise ValueError(f"sunsky: sun_direction must be 3 finite numbers, not all zero, got {sun_direction!r}")
        local = np.linalg.solve(m[:3, :3], d)
    else:
        local = local_sun_direction(time or SunTime(), convention)
    local = local / np.linalg.norm(local)
    if convention == "mitsuba0.5":
        sun, env_to_world = local, m
    else:
        sun = _M3_FROM_MAP.T @ local
        env_to_world = m.copy()
        env_to_world[:3, :3] = m[:3, :3] @ _M3_FROM_MAP
    if sun[1] < 0.0:
        where = f"sun_direction {list(sun_direction)}" if sun_direction is not None else f"{time or SunTime()}"
        raise ValueError(f"sunsky: the sun is below the horizon ({where} gives an elevation of "
                         f"{np.degrees(np.arcsin(np.clip(sun[1], -1.0, 1.0))):.2f} degrees); the sky model "
                         "does not support it")
    return sun, env_to_world


def directional_sun_05(sun_direction=None, *, time: SunTime | None = None, turbidity: float = 3.0,
                       sun_scale: float = 1.0, to_world=None, stretch: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba 0.5's sun as a directional light (its ``sunRadiusScale = 0``): the direction the light
    travels in (world space) and its irradiance (linear sRGB): the real disk's radiance x solid angle
    x ``sun_scale``. Parameters as :func:`sunsky_envmap`'s."""
    turbidity = _check(turbidity, "turbidity", 1.0, 10.0)
    sun_scale = _check(sun_scale, "sun_scale", 0.0)
    stretch = _check(stretch, "stretch", 1.0, 2.0)
    sun, env_to_world = _sun_in_map(sun_direction, time, to_world, "mitsuba0.5")
    zenith = float(np.arccos(np.clip(sun[1], -1.0, 1.0)))
    azimuth = float(np.arctan2(sun[0], -sun[2]))
    centre = _direction(zenith * stretch, azimuth)
    world = env_to_world[:3, :3] @ centre
    solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(SUN_RADIUS_DEG)))
    return -world / np.linalg.norm(world), sun_radiance_rgb_05(zenith, turbidity) * sun_scale * solid_angle


def _direction(zenith: float, azimuth: float) -> np.ndarray:
    """The map-frame direction of a zenith angle and an azimuth (Mitsuba 0.5's toSphere)."""
    st = np.sin(zenith)
    return np.array([np.sin(azimuth) * st, np.cos(zenith), -np.cos(azimuth) * st])


def sunsky_envmap(sun_direction=None, *, convention: str = "mitsuba0.5", time: SunTime | None = None,
                  turbidity: float = 3.0, albedo=None, sky_scale: float = 1.0, sun_scale: float = 1.0,
                  sun_radius_scale: float = 1.0, sun_aperture: float = 0.5358, complex_sun: bool = False,
                  resolution: int | None = None, to_world=None, extend: bool = False, stretch: float = 1.0,
                  name: str = "sunsky") -> Envmap:
    """Bake a Hosek-Wilkie sky (x ``sky_scale``) and a sun disk (x ``sun_scale``) into an envmap.

    ``convention`` is the Mitsuba version whose ``sunsky`` to reproduce:

    * ``"mitsuba0.5"`` (0.5/0.6 files, and the ``sky``/``sun`` plug-ins): the sky's frame is +y up; the
      sun is Mitsuba 0.5's (Preetham/Iqbal) with radius 0.2679 deg x ``sun_radius_scale`` at constant
      power (0: a directional sun, left out of the map: see :func:`directional_sun_05`); ``extend``,
      ``stretch`` and ``resolution`` (default 512) as Mitsuba 0.5; albedo default 0.2.
    * ``"mitsuba3"``: the frame is +z up; the sun is Mitsuba 3's (Hosek-Wilkie 2013) with aperture
      ``sun_aperture`` degrees (constant power), limb-darkened with ``complex_sun``, clipped at the
      horizon; albedo default 0.3; ``resolution`` default 1024.

    The sun's position is ``sun_direction`` (world space, towards the sun; brought into the sky's frame
    by ``to_world^-1``) or, when that is None, ``time`` (a place and date, default Mitsuba's) in the
    sky's own frame. ``albedo`` is a grey level or an RGB triple in [0, 1]. ``to_world`` (4x4, a
    rotation) orients the sky in the world. Raises ValueError (message "sunsky: <parameter> ...") on
    bad parameters, and for a sun below the horizon."""
    if convention not in CONVENTIONS:
        raise ValueError(f"sunsky: convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    legacy = convention == "mitsuba0.5"
    turbidity = _check(turbidity, "turbidity", 1.0, 10.0)
    sky_scale = _check(sky_scale, "sky_scale", 0.0)
    sun_scale = _check(sun_scale, "sun_scale", 0.0)
    stretch = _check(stretch, "stretch", 1.0, 2.0)
    alb = np.asarray(DEFAULT_ALBEDO[convention] if albedo is None else albedo, np.float64).reshape(-1)
    if alb.size not in (1, 3) or not np.all(np.isfinite(alb)) or np.any((alb < 0) | (alb > 1)):
        raise ValueError(f"sunsky: albedo must be one or three numbers in [0, 1], got {albedo!r}")
    res = _check(DEFAULT_RESOLUTION[convention] if resolution is None else resolution, "resolution", 8, 16384)
    if res != int(res) or int(res) % 2:
        raise ValueError(f"sunsky: resolution must be an even integer, got {resolution!r}")
    width, height = int(res), int(res) // 2
    if legacy:
        sun_radius_scale = _check(sun_radius_scale, "sun_radius_scale", 0.0)
        if sun_radius_scale == 0.0:  # a directional sun (directional_sun_05), not in the map
            sun_scale = 0.0
        radius = np.radians(SUN_RADIUS_DEG) * (sun_radius_scale or 1.0)
        if radius >= 0.5 * np.pi:
            raise ValueError(f"sunsky: sun_radius_scale {sun_radius_scale} makes the sun wider than a hemisphere")
    else:
        aperture = _check(sun_aperture, "sun_aperture")
        if not 0.0 < aperture < 180.0:
            raise ValueError(f"sunsky: sun_aperture must be in ]0, 180[ degrees, got {sun_aperture!r}")
        radius = np.radians(0.5 * aperture)
    sun, env_to_world = _sun_in_map(sun_direction, time, to_world, convention)
    sun_zenith = float(np.arccos(np.clip(sun[1], -1.0, 1.0)))
    sun_azimuth = float(np.arctan2(sun[0], -sun[2]))

    dirs = texel_directions(width, height)
    pixels = np.zeros((height, width, 3))
    if sky_scale > 0:
        theta_map = np.pi * np.arange(height) / (height - 1)
        phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
        theta = theta_map / stretch
        up = np.cos(theta) > 0.0 if legacy else np.cos(theta) >= -1e-12
        if extend and legacy:  # Mitsuba 0.5's "extend": the horizon's radiance continued downwards
            theta = np.where(up, theta, 0.5 * np.pi - 1e-4)
        cos_gamma = (np.cos(theta)[:, None] * np.cos(sun_zenith) + np.sin(theta)[:, None] * np.sin(sun_zenith)
                     * np.cos(phi[None, :] - sun_azimuth))
        gamma = np.arccos(np.clip(cos_gamma, -1.0, 1.0))
        state = sky_state(turbidity, alb, 0.5 * np.pi - sun_zenith)
        sky = sky_radiance(state, np.broadcast_to(np.maximum(np.cos(theta), 0.0)[:, None], gamma.shape), gamma)
        sky = np.maximum(sky / (CIE_Y_INTEGRAL_05 if legacy else CIE_Y_INTEGRAL_3), 0.0) * sky_scale
        if extend and legacy:
            x = np.clip(2.0 - 2.0 * theta_map / np.pi, 0.0, 1.0)
            sky *= (x * x * (3.0 - 2.0 * x))[:, None, None]
        else:
            sky *= up[:, None, None]
        pixels += sky
    if sun_scale > 0:
        real_solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(SUN_RADIUS_DEG) if legacy else SUN_HALF_APERTURE))
        if legacy:
            centre = _direction(sun_zenith * stretch, sun_azimuth)
            level_rgb = sun_radiance_rgb_05(sun_zenith, turbidity) * sun_scale
        else:
            centre = sun
            level_rgb = sun_radiance_rgb_3(0.5 * np.pi - sun_zenith, turbidity) * sun_scale
        hat = row_hat_solid_angle(height) * (2.0 * np.pi / width)
        if legacy or not complex_sun:
            def value(d, inside):
                above = inside & (d[..., 1] >= 0.0)
                return np.stack([inside, inside if legacy else above], axis=-1).astype(np.float64)

            near, box, cover = _sun_footprints(width, height, centre, radius, value)
            if not cover[:, 0].any():  # a disk far below texel size missed by every subsample
                near = np.array([int(np.argmax(dirs.reshape(-1, 3) @ centre))])
                cover = np.ones((1, 2))
            level = real_solid_angle / float((cover[:, 0] * hat[near // width]).sum())
            add = cover[:, 1:2] * (level * level_rgb)[None, :]
        else:
            area_ratio = real_solid_angle / (2.0 * np.pi * (1.0 - np.cos(radius)))

            def value(d, inside):
                g = np.arccos(np.clip(d @ centre, -1.0, 1.0))
                rad = complex_sun_radiance_rgb_3(d[..., 1], g, turbidity, radius)
                return rad * (inside & (d[..., 1] >= 0.0))[..., None]

            near, box, mean_l = _sun_footprints(width, height, centre, radius, value)
            power = (mean_l * box[:, None]).sum(0)
            hat_power = (mean_l * hat[near // width][:, None]).sum(0)
            level = np.where(hat_power > 0, power / np.maximum(hat_power, 1e-300), 0.0) * (area_ratio * sun_scale)
            add = np.maximum(mean_l * level, 0.0)  # the RGB fit dips below 0 for low suns (Mitsuba 3 keeps that)
        flat = pixels.reshape(-1, 3)
        flat[near] += add
    if not np.all(np.isfinite(pixels)):
        raise ValueError("sunsky: the sky model produced non-finite values for these parameters")
    return Envmap(pixels.astype(np.float32), env_to_world, 1.0, name)
