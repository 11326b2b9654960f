"""Low-precision solar position: NOAA / Meeus, about 0.01 deg from 1950 to 2050, vectorised.

Used by the satellite attitude (yaw) of :mod:`predisat.gnss.antenna_offsets` and by the
synthetic renderer's sky (:mod:`predisat.synth.sky`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.gnss.timescale import gps_s_to_utc_datetime64

__all__ = ["sun_azel", "sun_direction_enu"]

_J2000_UTC = np.datetime64("2000-01-01T12:00:00", "ns")


def sun_azel(
    gps_s: ArrayLike, lat_deg: ArrayLike, lon_deg: ArrayLike, refraction: bool = True
) -> tuple[NDArray, NDArray]:
    """Azimuth and elevation of the sun centre seen from places on the Earth.

    NOAA's low-precision algorithm (Meeus, *Astronomical Algorithms*, ch. 25, with the apparent
    sidereal time of ch. 12): about 0.01 deg between 1950 and 2050. Solar parallax (0.0024 deg)
    is ignored. UT1 is taken as UTC (under 0.9 s, i.e. 0.004 deg of hour angle).

    Parameters
    ----------
    gps_s : array_like, shape (...)
        GPS time, seconds since 1980-01-06T00:00:00 GPST (leap seconds are removed here).
    lat_deg, lon_deg : array_like, shape (...)
        Geodetic latitude and longitude (east positive) in degrees; broadcast with ``gps_s``.
    refraction : bool, optional
        Add standard atmospheric refraction to the elevation (NOAA's formula; what a camera
        sees). Default True.

    Returns
    -------
    az_deg, el_deg : ndarray, shape (...)
        Azimuth clockwise from true north in [0, 360) and elevation in degrees.
    """
    g, lat, lon = np.broadcast_arrays(
        np.asarray(gps_s, float), np.asarray(lat_deg, float), np.asarray(lon_deg, float)
    )
    if np.any(np.abs(lat) > 90.0):
        raise ValueError("lat_deg must lie in [-90, 90]")
    utc = gps_s_to_utc_datetime64(g)
    d = (utc - _J2000_UTC) / np.timedelta64(1, "D")  # days from J2000.0 (UT)
    t = d / 36525.0
    l0 = np.mod(280.46646 + t * (36000.76983 + t * 0.0003032), 360.0)
    m = np.radians(357.52911 + t * (35999.05029 - 0.0001537 * t))
    c = (
        np.sin(m) * (1.914602 - t * (0.004817 + 0.000014 * t))
        + np.sin(2 * m) * (0.019993 - 0.000101 * t)
        + np.sin(3 * m) * 0.000289
    )
    omega = np.radians(125.04 - 1934.136 * t)
    lam = np.radians(l0 + c - 0.00569 - 0.00478 * np.sin(omega))  # apparent longitude
    eps0 = 23.0 + (26.0 + (21.448 - t * (46.815 + t * (0.00059 - t * 0.001813))) / 60.0) / 60.0
    eps = np.radians(eps0 + 0.00256 * np.cos(omega))
    ra = np.arctan2(np.cos(eps) * np.sin(lam), np.cos(lam))
    dec = np.arcsin(np.sin(eps) * np.sin(lam))
    gmst = 280.46061837 + 360.98564736629 * d + t * t * (0.000387933 - t / 38710000.0)
    gast = gmst - 0.00478 * np.sin(omega) * np.cos(eps)  # nutation in longitude x cos(eps)
    ha = np.radians(gast + lon) - ra
    phi = np.radians(lat)
    east = -np.cos(dec) * np.sin(ha)
    north = np.cos(phi) * np.sin(dec) - np.sin(phi) * np.cos(dec) * np.cos(ha)
    up = np.sin(phi) * np.sin(dec) + np.cos(phi) * np.cos(dec) * np.cos(ha)
    az = np.mod(np.degrees(np.arctan2(east, north)), 360.0)
    el = np.degrees(np.arctan2(up, np.hypot(east, north)))
    if refraction:
        el = el + _refraction_deg(el)
    return az, el


def _refraction_deg(el_deg: NDArray) -> NDArray:
    """NOAA's piecewise standard refraction (Saemundsson/Bennett fits), degrees."""
    e = np.asarray(el_deg, float)
    te = np.tan(np.radians(np.clip(e, -89.0, 89.9)))
    with np.errstate(divide="ignore", invalid="ignore"):
        high = 58.1 / te - 0.07 / te**3 + 0.000086 / te**5
        mid = 1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)))
        low = -20.772 / te
    arcsec = np.where(e > 5.0, high, np.where(e > -0.575, mid, low))
    return np.where(e > 85.0, 0.0, arcsec / 3600.0)


def sun_direction_enu(az_deg: float, el_deg: float) -> NDArray:
    """Unit ENU vector (3,) toward the sun from its azimuth and elevation in degrees."""
    a, e = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])
