"""The terrain horizon at antenna positions: the far field of a GNSS mask from a DEM.

Per position and azimuth, the terrain is sampled along the ray from ``min_range_m`` to
``max_range_m`` (every half cell near the antenna, then every 1 % of the distance) and the
horizon is the highest apparent elevation of a terrain point at distance ``d``:

``el = atan2(h_terrain + vertical_error - h_antenna - d^2 / (2 R_eff), d)``,
``R_eff = R / (1 - k)``

with the Earth's curvature (``R`` = 6 371 km) and standard atmospheric refraction
(``k`` = :data:`REFRACTION_K`, the coefficient of geodetic levelling: light bends down, so the
far terrain looks higher than the straight line says). Every terrain height is raised by the
model's stated vertical error and the antenna stands on the lowest ground of its cell's
neighbourhood (:func:`antenna_height_m`): both push the horizon up, the safe side for a mask.
The ray point is placed on the local tangent plane (north and east metres over the meridian
and prime-vertical radii): under 0.1 % of the distance at 20 km, below a DEM cell.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.geodesy import WGS84
from predisat.terrain.dem import Dem

__all__ = ["EARTH_RADIUS_M", "REFRACTION_K", "antenna_height_m", "ray_ranges_m",
           "terrain_horizon_deg"]  # fmt: skip

#: Mean Earth radius, m.
EARTH_RADIUS_M = 6_371_000.0
#: Standard refraction coefficient (ratio of the Earth's radius to the light path's).
REFRACTION_K = 0.13
_A, _E2 = WGS84.a, WGS84.es  # the ellipsoid of predisat.geodesy


def ray_ranges_m(min_range_m: float, max_range_m: float, cell_m: float) -> NDArray[np.float64]:
    """Sample distances along a ray: every half cell, growing to 1 % of the distance, m."""
    if not 0 < min_range_m < max_range_m:
        raise ValueError(f"need 0 < min_range_m < max_range_m, got {min_range_m}, {max_range_m}")
    if not cell_m > 0:
        raise ValueError(f"cell_m must be positive, got {cell_m}")
    out = [float(min_range_m)]
    while out[-1] < max_range_m:
        out.append(out[-1] + max(cell_m / 2.0, 0.01 * out[-1]))
    out[-1] = float(max_range_m)
    return np.asarray(out)


def antenna_height_m(
    dem: Dem, lat_deg: ArrayLike, lon_deg: ArrayLike, above_ground_m: float, radius_cells: int = 1
) -> NDArray[np.float64]:
    """Antenna height in the DEM's datum: the lowest ground within ``radius_cells`` cells plus
    ``above_ground_m``.

    A 90 m cell averages a valley's floor with its slopes, so the cell's own height may stand
    above a track in the valley bottom; the lowest neighbour errs low, which raises the
    horizon (safe). NaN outside the DEM.
    """
    lat, lon = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
    k = int(radius_cells)
    if k < 0:
        raise ValueError(f"radius_cells must be >= 0, got {radius_cells}")
    lows = [dem.height_at(lat + i * dem.dlat_deg, lon + j * dem.dlon_deg)
            for i in range(-k, k + 1) for j in range(-k, k + 1)]  # fmt: skip
    # fmin ignores NaN and leaves NaN where every neighbour is off the DEM, without
    # nanmin's "All-NaN slice" RuntimeWarning (a DEM that misses the line is reported once,
    # by the caller, in words)
    low = np.fmin.reduce(np.stack(lows), axis=0)  # k >= 0: at least the point's own cell
    return np.asarray(low + above_ground_m, float)


def terrain_horizon_deg(
    dem: Dem,
    lat_deg: ArrayLike,
    lon_deg: ArrayLike,
    antenna_h_m: ArrayLike,
    az_deg: ArrayLike,
    *,
    min_range_m: float = 200.0,
    max_range_m: float = 25_000.0,
    refraction_k: float = REFRACTION_K,
) -> NDArray[np.float64]:
    """Terrain horizon per position and azimuth.

    Parameters
    ----------
    dem : Dem
    lat_deg, lon_deg, antenna_h_m : array_like, shape (n_pos,)
        Antenna positions; ``antenna_h_m`` in the DEM's height datum (see
        :func:`antenna_height_m`).
    az_deg : array_like, shape (n_az,)
        Azimuths, degrees clockwise from true north.
    min_range_m, max_range_m : float
        The ray's extent: the far field begins where the surveyed corridor ends.
    refraction_k : float
        Refraction coefficient (0: no refraction).

    Returns
    -------
    ndarray, shape (n_pos, n_az)
        Highest apparent elevation of the terrain (deg; may be negative), NaN where no sample
        of the ray lies on the DEM. Samples off the DEM or on voids are skipped: the result
        is then a lower bound of the terrain's horizon.
    """
    lat = np.atleast_1d(np.asarray(lat_deg, float))
    lon = np.atleast_1d(np.asarray(lon_deg, float))
    h0 = np.atleast_1d(np.asarray(antenna_h_m, float))
    az = np.radians(np.atleast_1d(np.asarray(az_deg, float)))
    if not lat.shape == lon.shape == h0.shape or lat.ndim != 1:
        raise ValueError("lat_deg, lon_deg and antenna_h_m must be 1-D of one length")
    if not 0.0 <= refraction_k < 1.0:
        raise ValueError(f"refraction_k must lie in [0, 1), got {refraction_k}")
    cell_m = dem.dlat_deg * np.pi / 180.0 * _A
    d = ray_ranges_m(min_range_m, max_range_m, cell_m)
    r_eff = EARTH_RADIUS_M / (1.0 - refraction_k)
    drop = d**2 / (2.0 * r_eff)
    out = np.full((lat.size, az.size), np.nan)
    north, east = np.cos(az)[:, None] * d, np.sin(az)[:, None] * d  # (n_az, n_d)
    for i in range(lat.size):  # one position at a time: (n_az, n_d) samples
        phi = np.radians(lat[i])
        w = np.sqrt(1.0 - _E2 * np.sin(phi) ** 2)
        m_radius, n_radius = _A * (1.0 - _E2) / w**3, _A / w
        plat = lat[i] + np.degrees(north / m_radius)
        plon = lon[i] + np.degrees(east / (n_radius * np.cos(phi)))
        h = dem.height_at(plat, plon) + dem.vertical_error_m
        el = np.degrees(np.arctan2(h - h0[i] - drop, d))
        ok = np.isfinite(el)
        best = np.max(np.where(ok, el, -np.inf), axis=1)
        out[i] = np.where(ok.any(axis=1), best, np.nan)
    return out
