"""The terrain horizon at antenna positions: the far field of a GNSS mask from a DEM.

Per position and azimuth, the terrain is sampled along the ray from ``min_range_m`` to
``max_range_m`` every half of the DEM's smaller cell side, each sample taking the highest post
of the 3 x 3 around it (no peak between posts or samples is flattened), and the horizon is the
highest apparent elevation of a terrain point at distance ``d``:

``el = atan2(h_terrain + vertical_error - h_antenna - d^2 / (2 R_eff), d)``,
``R_eff = R / (1 - k)``

with the Earth's curvature (``R`` = 6 371 km) and standard atmospheric refraction
(``k`` = :data:`REFRACTION_K`, the coefficient of geodetic levelling: light bends down, so the
far terrain looks higher than the straight line says). Every terrain height is raised by the
model's stated vertical error and the antenna stands on the lowest ground of its cell's
neighbourhood (:func:`antenna_height_m`): both push the horizon up, the safe side for a mask.
The ray point is placed from its north and east metres over the meridian and prime-vertical
radii, with the second-order terms of the latitude's change (on the tangent plane alone a ray
turns by ``d tan(lat) / 2R``: 0.3 deg at 24 km and 70 N). A ray that
leaves the tiles or meets a void before its full range gives only a lower bound of the
horizon, and :func:`terrain_horizon` says which rays those are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.geodesy import WGS84
from predisat.readonly import freeze_array_fields
from predisat.terrain.dem import Dem

__all__ = ["EARTH_RADIUS_M", "REFRACTION_K", "TerrainHorizon", "antenna_height_m",
           "ray_ranges_m", "terrain_horizon", "terrain_horizon_deg"]  # fmt: skip

#: Mean Earth radius, m.
EARTH_RADIUS_M = 6_371_000.0
#: Standard refraction coefficient (ratio of the Earth's radius to the light path's).
REFRACTION_K = 0.13
_A, _E2 = WGS84.a, WGS84.es  # the ellipsoid of predisat.geodesy


def ray_ranges_m(min_range_m: float, max_range_m: float, cell_m: float) -> NDArray[np.float64]:
    """Sample distances along a ray, every half cell (``cell_m``: the smaller side), m.

    A constant step: a step growing with the distance (1 %, 2.6 cells at 24 km) passed over a
    peak between samples and, with bilinear heights, left the horizon 42 m low at the Var's
    mouth beyond the 16 m error margin (a review).
    """
    if not 0 < min_range_m < max_range_m:
        raise ValueError(f"need 0 < min_range_m < max_range_m, got {min_range_m}, {max_range_m}")
    if not cell_m > 0:
        raise ValueError(f"cell_m must be positive, got {cell_m}")
    n = int(np.ceil((max_range_m - min_range_m) / (cell_m / 2.0)))
    return np.linspace(float(min_range_m), float(max_range_m), n + 1)


def antenna_height_m(
    dem: Dem,
    lat_deg: ArrayLike,
    lon_deg: ArrayLike,
    above_ground_m: float,
    radius_cells: int = 1,
    max_radius_cells: int = 10,
) -> NDArray[np.float64]:
    """Antenna height in the DEM's datum: the lowest ground within ``radius_cells`` cells plus
    ``above_ground_m``; where voids leave no ground there, within the first larger radius that
    has some, up to ``max_radius_cells``.

    A 90 m cell averages a valley's floor with its slopes, so the cell's own height may stand
    above a track in the valley bottom; the lowest neighbour errs low, which raises the
    horizon (safe). It cannot see a gorge narrower than a cell whose floor no post samples
    (docs/terrain.md, limits). NaN outside the DEM.
    """
    lat, lon = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
    k = int(radius_cells)
    if k < 0:
        raise ValueError(f"radius_cells must be >= 0, got {radius_cells}")
    if max_radius_cells < k:
        raise ValueError(f"max_radius_cells ({max_radius_cells}) must be >= radius_cells ({k})")
    low = np.full(lat.shape, np.nan)
    # a void at the track (radar shadow: narrow valleys, where lines run) left the whole
    # position without a horizon (a review): the search widens until it finds ground, the
    # lowest ground found standing for the track's (the safe side)
    for r in range(k, int(max_radius_cells) + 1):
        todo = ~np.isfinite(low)
        if not todo.any():
            break
        ring = [dem.height_at(lat[todo] + i * dem.dlat_deg, lon[todo] + j * dem.dlon_deg)
                for i in range(-r, r + 1) for j in range(-r, r + 1)]  # fmt: skip
        # fmin ignores NaN and leaves NaN where every neighbour is off the DEM, without
        # nanmin's "All-NaN slice" RuntimeWarning
        low[todo] = np.fmin.reduce(np.stack(ring), axis=0)
    return np.asarray(low + above_ground_m, float)


@dataclass(frozen=True)
class TerrainHorizon:
    """Terrain horizon per position and azimuth, and whether the DEM covered each ray.

    Attributes
    ----------
    el_deg : ndarray, shape (n_pos, n_az)
        Highest apparent elevation of the terrain sampled (deg; may be negative), NaN where no
        sample of the ray lies on known terrain.
    complete : ndarray of bool, shape (n_pos, n_az)
        True where every sample of the ray, out to its full range, lies on known terrain (in
        the tiles, away from voids): only then is ``el_deg`` the terrain's horizon; elsewhere
        it is a lower bound of it (a review: rays leaving the tiles 3.5 km out were taken for
        bounds, 4.6-7.7 deg below the truth).
    """

    el_deg: NDArray[np.float64]
    complete: NDArray[np.bool_]

    def __post_init__(self) -> None:
        freeze_array_fields(self)


def terrain_horizon(
    dem: Dem,
    lat_deg: ArrayLike,
    lon_deg: ArrayLike,
    antenna_h_m: ArrayLike,
    az_deg: ArrayLike,
    *,
    min_range_m: float = 200.0,
    max_range_m: float = 25_000.0,
    refraction_k: float = REFRACTION_K,
) -> TerrainHorizon:
    """Terrain horizon per position and azimuth, with the rays the DEM covered.

    Each ray is sampled every half of the DEM's smaller cell side, and the terrain at a sample
    is the highest post of the 3 x 3 around it (:meth:`Dem.max_height_near`) raised by the
    model's vertical error: every post within a cell of the ray counts, so no peak between
    samples or posts is flattened.

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
    TerrainHorizon
    """
    lat = np.atleast_1d(np.asarray(lat_deg, float))
    lon = np.atleast_1d(np.asarray(lon_deg, float))
    h0 = np.atleast_1d(np.asarray(antenna_h_m, float))
    az = np.radians(np.atleast_1d(np.asarray(az_deg, float)))
    if not lat.shape == lon.shape == h0.shape or lat.ndim != 1:
        raise ValueError("lat_deg, lon_deg and antenna_h_m must be 1-D of one length")
    if not 0.0 <= refraction_k < 1.0:
        raise ValueError(f"refraction_k must lie in [0, 1), got {refraction_k}")
    far = float(np.max(np.abs(lat))) if lat.size else 0.0
    d = ray_ranges_m(min_range_m, max_range_m, min(dem.cell_m(min(far, 89.0))))
    r_eff = EARTH_RADIUS_M / (1.0 - refraction_k)
    drop = d**2 / (2.0 * r_eff)
    out = np.full((lat.size, az.size), np.nan)
    complete = np.zeros((lat.size, az.size), bool)
    north, east = np.cos(az)[:, None] * d, np.sin(az)[:, None] * d  # (n_az, n_d)
    for i in range(lat.size):  # one position at a time: (n_az, n_d) samples
        phi = np.radians(lat[i])
        w = np.sqrt(1.0 - _E2 * np.sin(phi) ** 2)
        m_radius, n_radius = _A * (1.0 - _E2) / w**3, _A / w
        # second-order terms: on the tangent plane alone a ray turns by d tan(phi) / 2R
        # (0.3 deg at 24 km and 70 N: peaks fell out of their bins, a review)
        tphi = np.tan(phi)
        plat = lat[i] + np.degrees(north / m_radius
                                   - east**2 * tphi / (2.0 * m_radius * n_radius))  # fmt: skip
        plon = lon[i] + np.degrees(east / (n_radius * np.cos(phi))
                                   * (1.0 + north * tphi / n_radius))  # fmt: skip
        h = dem.max_height_near(plat, plon) + dem.vertical_error_m
        el = np.degrees(np.arctan2(h - h0[i] - drop, d))
        ok = np.isfinite(el)
        best = np.max(np.where(ok, el, -np.inf), axis=1)
        out[i] = np.where(ok.any(axis=1), best, np.nan)
        complete[i] = ok.all(axis=1)  # a NaN antenna height leaves every sample NaN
    return TerrainHorizon(out, complete)


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
    """Terrain horizon per position and azimuth, deg, shape (n_pos, n_az):
    :func:`terrain_horizon`'s ``el_deg`` (a lower bound of the horizon where a ray left the
    tiles or met a void; that function says where). Parameters as there.
    """
    return terrain_horizon(dem, lat_deg, lon_deg, antenna_h_m, az_deg, min_range_m=min_range_m,
                           max_range_m=max_range_m, refraction_k=refraction_k).el_deg
