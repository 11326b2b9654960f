"""Digital elevation models on a latitude/longitude grid, read with rasterio.

SRTM tiles (``.hgt``, GDAL's SRTMHGT driver) and GeoTIFFs in EPSG:4326 are read by
:meth:`Dem.from_files`; several tiles are mosaicked with :func:`rasterio.merge.merge`. Heights
are those of the file (SRTM: metres above the EGM96 geoid); voids are NaN. Why rasterio: it
is the maintained reader of every raster format GDAL knows, with the geo-transform and nodata
handled, so nothing here parses a tile format by hand.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import maximum_filter

from predisat.geodesy import WGS84
from predisat.readonly import freeze_array_fields

__all__ = ["SRTM_VERTICAL_ERROR_M", "Dem", "DemError"]

#: SRTM's absolute vertical error, 90 % linear error (Rodriguez et al. 2006, the SRTM mission's
#: global assessment: 16 m is the mission specification; measured 6-9 m over Eurasia). The
#: horizon adds it to every terrain height: the mask errs high, never low.
SRTM_VERTICAL_ERROR_M = 16.0


_A, _E2 = WGS84.a, WGS84.es


def _is_wgs84_degrees(crs: Any) -> bool:
    """Geographic, on the WGS84 ellipsoid, longitudes from Greenwich, in degrees: a tile in
    another datum or from the Paris meridian would be read at the wrong place (a review: a
    Paris-meridian tile landed 2.34 deg west, an ED50 one about 100 m off)."""
    if crs is None or not crs.is_geographic:
        return False
    from pyproj import CRS

    c = CRS.from_user_input(crs.to_wkt())
    # the horizontal part only: a 3-D CRS (EPSG:4979) or a compound one with a vertical datum
    # (EPSG:4326+5773, SRTM's EGM96 heights) places the posts the same; the heights' datum
    # does not matter, the antenna's ground being read from the same tile
    if c.is_compound:
        c = c.sub_crs_list[0]
    if c.is_geographic and len(c.axis_info) == 3:
        c = c.to_2d()
    if c.equals(CRS.from_epsg(4326), ignore_axis_order=True):
        return True
    ell, pm = c.ellipsoid, c.prime_meridian
    # a datum shift given to WGS84 moves the tile; zeros (ETRS89's usual) do not
    with warnings.catch_warnings():  # pyproj: a PROJ string loses information (not this)
        warnings.simplefilter("ignore", UserWarning)
        proj4 = c.to_proj4() or ""
    shift = re.search(r"\+towgs84=([-0-9.,e]+)", proj4)
    shifted = shift is not None and any(float(v) != 0.0 for v in shift.group(1).split(","))
    return bool(
        ell is not None and pm is not None and pm.longitude == 0.0 and not shifted
        # WGS84 or GRS80 (ETRS89, NAD83: within about a metre of WGS84, a DEM cell's 1 %)
        and abs(ell.semi_major_metre - _A) < 1e-3
        and abs(ell.inverse_flattening - 1.0 / WGS84.f) < 1e-5
        and all(a.unit_name in ("degree", "degree minute second hemisphere")
                for a in c.axis_info)
    )  # fmt: skip


class DemError(ValueError):
    """An elevation file that cannot be used; the message names the file and the fix."""


@dataclass(frozen=True, eq=False)
class Dem:
    """Heights on a regular latitude/longitude grid.

    Attributes
    ----------
    height_m : ndarray of float32, shape (n_lat, n_lon)
        Heights, row 0 the northernmost; NaN where void.
    lat0_deg, lon0_deg : float
        Latitude and longitude of the centre of cell ``[0, 0]`` (north-west corner cell).
    dlat_deg, dlon_deg : float
        Cell size (positive; latitude decreases with the row).
    vertical_error_m : float
        Stated vertical error of the heights (added by the horizon, the safe side).
    source : str
        The files it was read from.
    """

    height_m: NDArray[np.float32]
    lat0_deg: float
    lon0_deg: float
    dlat_deg: float
    dlon_deg: float
    vertical_error_m: float = SRTM_VERTICAL_ERROR_M
    source: str = ""

    def __post_init__(self) -> None:
        if np.asarray(self.height_m).ndim != 2 or min(np.shape(self.height_m)) < 2:
            raise DemError(f"height_m must be a 2-D grid of at least 2 x 2, got "
                           f"{np.shape(self.height_m)}")  # fmt: skip
        if not (self.dlat_deg > 0 and self.dlon_deg > 0):
            raise DemError("dlat_deg and dlon_deg must be positive (row 0 is the north edge)")
        if not self.vertical_error_m >= 0:
            raise DemError(f"vertical_error_m must be >= 0, got {self.vertical_error_m}")
        freeze_array_fields(self)

    @classmethod
    def from_files(
        cls,
        paths: Sequence[str | os.PathLike[str]],
        *,
        vertical_error_m: float = SRTM_VERTICAL_ERROR_M,
    ) -> Dem:
        """Read and mosaic elevation tiles (SRTM ``.hgt`` or GeoTIFF, EPSG:4326).

        Parameters
        ----------
        paths : sequence of path-like
            Tiles; adjacent tiles share their edge row/column (SRTM) or abut.
        vertical_error_m : float
            The heights' stated vertical error, m (default SRTM's 16 m).

        Raises
        ------
        DemError
            A missing or unreadable file, a coordinate system other than geographic WGS84, or
            no tile; the message names the file.
        """
        import rasterio
        from rasterio.errors import RasterioIOError
        from rasterio.merge import merge

        files = [Path(p) for p in paths]
        if not files:
            raise DemError("no elevation tile given: pass SRTM .hgt or GeoTIFF files")
        datasets = []
        try:
            for f in files:
                if not f.is_file():
                    raise DemError(f"{f}: no such elevation tile")
                try:
                    ds = rasterio.open(f)
                except RasterioIOError as exc:
                    raise DemError(f"{f}: not a readable elevation raster ({exc}); give SRTM "
                                   ".hgt or GeoTIFF tiles") from None  # fmt: skip
                datasets.append(ds)
                if not _is_wgs84_degrees(ds.crs):
                    raise DemError(f"{f}: coordinate system {ds.crs} is not geographic WGS84 "
                                   "in degrees from Greenwich (EPSG:4326); reproject the tile "
                                   "(gdalwarp -t_srs EPSG:4326)")  # fmt: skip
                if ds.count < 1:
                    raise DemError(f"{f}: no raster band")
            data, transform = merge(datasets, nodata=np.nan, dtype="float32")
            nodata = [ds.nodata for ds in datasets]
        finally:
            for ds in datasets:
                ds.close()
        h = np.asarray(data[0], np.float32)
        for nd in nodata:
            if nd is not None and np.isfinite(nd):
                h[h == nd] = np.nan
        if transform.b != 0 or transform.d != 0 or transform.e >= 0:
            raise DemError(f"{files[0]}: rotated or south-up grids are not supported")
        return cls(
            h,
            lat0_deg=float(transform.f + transform.e / 2),
            lon0_deg=float(transform.c + transform.a / 2),
            dlat_deg=float(-transform.e),
            dlon_deg=float(transform.a),
            vertical_error_m=vertical_error_m,
            source=", ".join(str(f) for f in files),
        )

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_lat, n_lon)``."""
        return (int(self.height_m.shape[0]), int(self.height_m.shape[1]))

    @property
    def bounds_deg(self) -> tuple[float, float, float, float]:
        """``(lon_min, lat_min, lon_max, lat_max)`` of the cell centres."""
        n_lat, n_lon = self.shape
        return (self.lon0_deg, self.lat0_deg - (n_lat - 1) * self.dlat_deg,
                self.lon0_deg + (n_lon - 1) * self.dlon_deg, self.lat0_deg)  # fmt: skip

    def cell_m(self, lat_deg: float) -> tuple[float, float]:
        """Cell size at a latitude, ``(north-south, east-west)`` metres (WGS84 radii)."""
        phi = np.radians(lat_deg)
        w = np.sqrt(1.0 - _E2 * np.sin(phi) ** 2)
        return (float(np.radians(self.dlat_deg) * _A * (1.0 - _E2) / w**3),
                float(np.radians(self.dlon_deg) * _A / w * np.cos(phi)))  # fmt: skip

    @cached_property
    def _max3_m(self) -> NDArray[np.float64]:
        # NaN where any post of the 3 x 3 is void or beyond the grid's edge (unknown terrain,
        # not low): maximum_filter would otherwise pass over it
        z = np.asarray(self.height_m, np.float64)
        void = maximum_filter(~np.isfinite(z), size=3, mode="constant", cval=True)
        top = maximum_filter(np.where(np.isfinite(z), z, -np.inf), size=3, mode="nearest")
        out = np.where(void, np.nan, top)
        out.setflags(write=False)
        return out

    def max_height_near(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray[np.float64]:
        """Highest post of the 3 x 3 around the nearest post, m: a bound of the terrain within
        a cell of the point, where bilinear heights flatten a peak between posts.

        NaN outside the grid or where one of those posts is void or beyond the grid's edge
        (the terrain is unknown there, not low).

        Parameters
        ----------
        lat_deg, lon_deg : array_like, broadcastable
            Geographic coordinates (WGS84 degrees).

        Returns
        -------
        ndarray of float64, the broadcast shape
        """
        r, c, inside = self._grid_index(lat_deg, lon_deg)
        ri = np.where(inside, np.rint(r), 0).astype(np.intp)
        ci = np.where(inside, np.rint(c), 0).astype(np.intp)
        return np.where(inside, self._max3_m[ri, ci], np.nan)

    def _grid_index(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> tuple[NDArray, ...]:
        """Fractional row and column of points, and whether they lie within the posts."""
        lat, lon = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
        r = (self.lat0_deg - lat) / self.dlat_deg
        c = (lon - self.lon0_deg) / self.dlon_deg
        n_lat, n_lon = self.shape
        return r, c, (r >= 0) & (r <= n_lat - 1) & (c >= 0) & (c <= n_lon - 1)

    def height_at(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray[np.float64]:
        """Bilinear height at points, m; NaN outside the grid or next to a void.

        Parameters
        ----------
        lat_deg, lon_deg : array_like, broadcastable
            Geographic coordinates (WGS84 degrees).

        Returns
        -------
        ndarray of float64, the broadcast shape
        """
        r, c, inside = self._grid_index(lat_deg, lon_deg)
        n_lat, n_lon = self.shape
        r = np.where(inside, r, 0.0)
        c = np.where(inside, c, 0.0)
        r0 = np.minimum(np.floor(r).astype(np.intp), n_lat - 2)
        c0 = np.minimum(np.floor(c).astype(np.intp), n_lon - 2)
        fr, fc = r - r0, c - c0
        z = self.height_m
        top = z[r0, c0] * (1 - fc) + z[r0, c0 + 1] * fc
        bottom = z[r0 + 1, c0] * (1 - fc) + z[r0 + 1, c0 + 1] * fc
        out = (top * (1 - fr) + bottom * fr).astype(np.float64)
        return np.where(inside, out, np.nan)
