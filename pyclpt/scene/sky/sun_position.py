"""The sun's position for a place and a time, as Mitsuba 0.5 and Mitsuba 3 compute it: the PSA
algorithm of Blanco-Muriel, Alarcon-Padilla, Lopez-Moratalla & Lara-Coira 2001, "Computing the Solar
Vector" (Solar Energy 70(5)), with its parallax correction, and each version's sky frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EARTH_MEAN_RADIUS = 6371.01  # km
ASTRONOMICAL_UNIT = 149597890.0  # km


@dataclass(frozen=True)
class SunTime:
    """A place (degrees; time zone in hours east of UTC) and a local date and time; the defaults are
    Mitsuba's (Tokyo, 10 July 2010, 15:00)."""
    latitude: float = 35.6894
    longitude: float = 139.6917
    timezone: float = 9.0
    year: int = 2010
    month: int = 7
    day: int = 10
    hour: float = 15.0
    minute: float = 0.0
    second: float = 0.0


def sun_coordinates(t: SunTime) -> tuple[float, float]:
    """(zenith angle, azimuth) of the sun in radians; the azimuth is measured from north towards
    east, in [0, 2 pi) (Mitsuba 0.5's computeSunCoordinates, Mitsuba 3's sun_coordinates before its
    shift by pi)."""
    dec_hours = t.hour - t.timezone + (t.minute + t.second / 60.0) / 60.0
    # integer arithmetic of the algorithm (C division truncates towards zero)
    def div(a: int, b: int) -> int:
        return int(a / b) if a * b >= 0 else -int(-a / b)

    aux1 = div(t.month - 14, 12)
    aux2 = (div(1461 * (t.year + 4800 + aux1), 4) + div(367 * (t.month - 2 - 12 * aux1), 12)
            - div(3 * div(t.year + 4900 + aux1, 100), 4) + t.day - 32075)
    elapsed = aux2 - 0.5 + dec_hours / 24.0 - 2451545.0
    omega = 2.1429 - 0.0010394594 * elapsed
    mean_longitude = 4.8950630 + 0.017202791698 * elapsed
    anomaly = 6.2400600 + 0.0172019699 * elapsed
    ecl_longitude = (mean_longitude + 0.03341607 * np.sin(anomaly) + 0.00034894 * np.sin(2 * anomaly)
                     - 0.0001134 - 0.0000203 * np.sin(omega))
    ecl_obliquity = 0.4090928 - 6.2140e-9 * elapsed + 0.0000396 * np.cos(omega)
    sin_l = np.sin(ecl_longitude)
    right_ascension = np.arctan2(np.cos(ecl_obliquity) * sin_l, np.cos(ecl_longitude))
    if right_ascension < 0.0:
        right_ascension += 2.0 * np.pi
    declination = np.arcsin(np.sin(ecl_obliquity) * sin_l)
    gmst = 6.6974243242 + 0.0657098283 * elapsed + dec_hours
    lmst = np.radians(gmst * 15.0 + t.longitude)
    lat = np.radians(t.latitude)
    hour_angle = lmst - right_ascension
    zenith = np.arccos(np.cos(lat) * np.cos(hour_angle) * np.cos(declination) + np.sin(declination) * np.sin(lat))
    azimuth = np.arctan2(-np.sin(hour_angle), np.tan(declination) * np.cos(lat) - np.sin(lat) * np.cos(hour_angle))
    if azimuth < 0.0:
        azimuth += 2.0 * np.pi
    zenith += EARTH_MEAN_RADIUS / ASTRONOMICAL_UNIT * np.sin(zenith)  # parallax correction
    return float(zenith), float(azimuth)


def local_sun_direction(t: SunTime, convention: str) -> np.ndarray:
    """The sun's unit direction in the sky's own frame: Mitsuba 0.5's (``"mitsuba0.5"``: +y up,
    (sin az sin z, cos z, -cos az sin z)) or Mitsuba 3's (``"mitsuba3"``: +z up,
    (sin z cos(az - pi), sin z sin(az - pi), cos z))."""
    zenith, azimuth = sun_coordinates(t)
    sz, cz = np.sin(zenith), np.cos(zenith)
    if convention == "mitsuba0.5":
        return np.array([np.sin(azimuth) * sz, cz, -np.cos(azimuth) * sz])
    if convention == "mitsuba3":
        return np.array([sz * np.cos(azimuth - np.pi), sz * np.sin(azimuth - np.pi), cz])
    raise ValueError(f"sunsky: unknown convention {convention!r} (mitsuba0.5 or mitsuba3)")
