"""Digital elevation models on a latitude/longitude grid, read with rasterio.

SRTM tiles (``.hgt``, GDAL's SRTMHGT driver) and GeoTIFFs in EPSG:4326 are read by
:meth:`Dem.from_files`; several tiles are mosaicked with :func:`rasterio.merge.merge`. Heights
are those of the file (SRTM: metres above the EGM96 geoid); voids are NaN. Why rasterio: it
is the maintained reader of every raster format GDAL knows, with the geo-transform and nodata
handled, so nothing here parses a tile format by hand.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.readonly import freeze_array_fields

__all__ = ["SRTM_VERTICAL_ERROR_M", "Dem", "DemError"]

#: SRTM's absolute vertical error, 90 % linear error (Rodriguez et al. 2006, the SRTM mission's
#: global assessment: 16 m is the mission specification; measured 6-9 m over Eurasia). The
#: horizon adds it to every terrain height: the mask errs high, never low.
SRTM_VERTICAL_ERROR_M = 16.0


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
                crs = ds.crs
                if crs is None or not crs.is_geographic or crs.to_epsg() not in (4326, None):
                    raise DemError(f"{f}: coordinate system {crs} is not geographic WGS84 "
                                   "(EPSG:4326); reproject the tile (gdalwarp -t_srs EPSG:4326)")
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
        lat, lon = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
        r = (self.lat0_deg - lat) / self.dlat_deg
        c = (lon - self.lon0_deg) / self.dlon_deg
        n_lat, n_lon = self.shape
        inside = (r >= 0) & (r <= n_lat - 1) & (c >= 0) & (c <= n_lon - 1)
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
