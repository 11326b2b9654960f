"""WGS84 geodesy: geodetic and ECEF coordinates, local ENU frames, azimuth and elevation.

Conventions (see ``docs/conventions.md``): latitude/longitude in degrees, heights in metres
above the WGS84 ellipsoid, ECEF in metres, azimuth in degrees clockwise from true north in
[0, 360), elevation in degrees above the plane normal to the ellipsoid. Vectors are last-axis
3-vectors ``(..., 3)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pyproj import Geod, Transformer

__all__ = [
    "WGS84",
    "LocalFrame",
    "azel_to_enu",
    "ecef_to_geodetic",
    "enu_rotation",
    "enu_to_azel",
    "geodetic_to_ecef",
    "unwrap_lon_deg",
    "wrap_lon_deg",
]

WGS84 = Geod(ellps="WGS84")
"""pyproj geodesic on the WGS84 ellipsoid (lengths, forward and inverse problems)."""


def unwrap_lon_deg(lon_deg: ArrayLike, axis: int = -1) -> NDArray:
    """Longitudes along ``axis`` without the 360 deg jumps at the antimeridian, deg: what to
    interpolate or average (a plain mean of 179.99 and -179.99 is 0, the other side of the
    Earth). Turn the results back with :func:`wrap_lon_deg`."""
    return np.degrees(np.unwrap(np.radians(np.asarray(lon_deg, float)), axis=axis))


def wrap_lon_deg(lon_deg: ArrayLike) -> NDArray:
    """Longitudes in [-180, 180) deg."""
    return np.mod(np.asarray(lon_deg, float) + 180.0, 360.0) - 180.0


@lru_cache(maxsize=1)
def _to_ecef() -> Transformer:
    return Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


def geodetic_to_ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike = 0.0) -> NDArray:
    """Convert WGS84 geodetic coordinates to ECEF.

    Parameters
    ----------
    lat_deg, lon_deg : array_like, shape (...)
        Geodetic latitude and longitude in degrees.
    h_m : array_like, shape (...), optional
        Ellipsoidal height in metres (default 0).

    Returns
    -------
    ndarray, shape (..., 3)
        ECEF x, y, z in metres.
    """
    lat, lon, h = np.broadcast_arrays(
        np.asarray(lat_deg, float), np.asarray(lon_deg, float), np.asarray(h_m, float)
    )
    x, y, z = _to_ecef().transform(lon, lat, h)
    return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)


def ecef_to_geodetic(xyz_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    """Convert ECEF coordinates to WGS84 geodetic.

    Parameters
    ----------
    xyz_m : array_like, shape (..., 3)
        ECEF coordinates in metres.

    Returns
    -------
    lat_deg, lon_deg, h_m : ndarray, shape (...)
    """
    xyz = np.asarray(xyz_m, float)
    if xyz.shape[-1:] != (3,):
        raise ValueError(f"xyz_m must have shape (..., 3), got {xyz.shape}")
    lon, lat, h = _to_ecef().transform(xyz[..., 0], xyz[..., 1], xyz[..., 2], direction="INVERSE")
    return np.asarray(lat), np.asarray(lon), np.asarray(h)


def enu_rotation(lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray:
    """Rotation matrices from ECEF to local east-north-up.

    Parameters
    ----------
    lat_deg, lon_deg : array_like, shape (...)

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Rows are the east, north and up unit vectors in ECEF, so that
        ``enu = R @ (xyz - origin)``.
    """
    lat = np.radians(np.asarray(lat_deg, float))
    lon = np.radians(np.asarray(lon_deg, float))
    lat, lon = np.broadcast_arrays(lat, lon)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    # filled in place: four np.stack calls cost more than the trigonometry on one point
    out = np.empty((*lat.shape, 3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = -so, co, 0.0
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = -sl * co, -sl * so, cl
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = cl * co, cl * so, sl
    return out


def enu_to_azel(enu_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    """Azimuth, elevation and range of local ENU vectors.

    Parameters
    ----------
    enu_m : array_like, shape (..., 3)

    Returns
    -------
    az_deg : ndarray, shape (...)
        Clockwise from north, in [0, 360).
    el_deg : ndarray, shape (...)
    range_m : ndarray, shape (...)
    """
    v = np.asarray(enu_m, float)
    e, n, u = v[..., 0], v[..., 1], v[..., 2]
    horiz = np.hypot(e, n)
    az = np.mod(np.degrees(np.arctan2(e, n)), 360.0)
    el = np.degrees(np.arctan2(u, horiz))
    return az, el, np.sqrt(horiz**2 + u**2)


def azel_to_enu(az_deg: ArrayLike, el_deg: ArrayLike) -> NDArray:
    """Unit ENU vectors for given azimuths and elevations (degrees), shape (..., 3)."""
    az = np.radians(np.asarray(az_deg, float))
    el = np.radians(np.asarray(el_deg, float))
    az, el = np.broadcast_arrays(az, el)
    ce = np.cos(el)
    return np.stack([ce * np.sin(az), ce * np.cos(az), np.sin(el)], axis=-1)


@dataclass(frozen=True)
class LocalFrame:
    """A local east-north-up Cartesian frame tangent to the ellipsoid at an origin.

    Used as the world frame of a synthetic scene and for planar work on a track. Directions
    measured at another point (its own ENU) are carried into this frame with
    :meth:`rotation_from`, which keeps elevations exact away from the origin.
    """

    lat_deg: float
    lon_deg: float
    h_m: float = 0.0

    # Cached: every conversion needs them and pyproj calls are not free. cached_property stores
    # in the instance __dict__, which a frozen dataclass allows; the arrays are made read-only.
    @cached_property
    def origin_ecef_m(self) -> NDArray:
        """ECEF position of the origin, shape (3,), metres."""
        out = geodetic_to_ecef(self.lat_deg, self.lon_deg, self.h_m)
        out.setflags(write=False)
        return out

    @cached_property
    def rotation(self) -> NDArray:
        """ECEF-to-ENU rotation at the origin, shape (3, 3)."""
        out = enu_rotation(self.lat_deg, self.lon_deg)
        out.setflags(write=False)
        return out

    def ecef_to_enu(self, xyz_m: ArrayLike) -> NDArray:
        """ECEF points (..., 3) to this frame's ENU (..., 3), metres."""
        return (np.asarray(xyz_m, float) - self.origin_ecef_m) @ self.rotation.T

    def enu_to_ecef(self, enu_m: ArrayLike) -> NDArray:
        """This frame's ENU points (..., 3) to ECEF (..., 3), metres."""
        return np.asarray(enu_m, float) @ self.rotation + self.origin_ecef_m

    def to_enu(self, lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike = 0.0) -> NDArray:
        """Geodetic points to this frame's ENU, shape (..., 3), metres."""
        return self.ecef_to_enu(geodetic_to_ecef(lat_deg, lon_deg, h_m))

    def to_geodetic(self, enu_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
        """This frame's ENU points (..., 3) to geodetic ``(lat_deg, lon_deg, h_m)``."""
        return ecef_to_geodetic(self.enu_to_ecef(enu_m))

    def rotation_from(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray:
        """Rotations taking vectors from the local ENU at given points into this frame.

        Returns
        -------
        ndarray, shape (..., 3, 3)
            ``v_frame = R @ v_local``.
        """
        local = enu_rotation(lat_deg, lon_deg)  # ECEF -> local ENU
        return self.rotation @ np.swapaxes(local, -1, -2)
