"""A synthetic DEM written as a GeoTIFF with rasterio (shared by the terrain and mask tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rasterio
from rasterio.transform import from_origin

CELL_DEG = 1.0 / 1200.0  # SRTM3's 3 arc-seconds


def surface_m(lat, lon):
    """100 m plain, a 600 m plateau north of 45.02 N and a round 900 m hill at (45.0, 6.03)."""
    plateau = 100.0 + 500.0 / (1.0 + np.exp(-(lat - 45.02) / 0.001))
    hill = 800.0 * np.exp(-(((lat - 45.0) / 0.004) ** 2 + ((lon - 6.03) / 0.005) ** 2))
    return np.maximum(plateau, 100.0 + hill)


def write_synthetic_dem(path: Path) -> Path:
    """45.05 N 5.95 E (north-west cell centre), 121 x 242 cells of 3 arc-seconds."""
    n = 121
    lats = 45.05 - np.arange(n) * CELL_DEG  # row 0 north
    lons = 5.95 + np.arange(2 * n) * CELL_DEG
    z = surface_m(lats[:, None], lons[None, :]).astype(np.float32)
    tr = from_origin(lons[0] - CELL_DEG / 2, lats[0] + CELL_DEG / 2, CELL_DEG, CELL_DEG)
    with rasterio.open(path, "w", driver="GTiff", height=n, width=2 * n, count=1,
                       dtype="float32", crs="EPSG:4326", transform=tr) as ds:  # fmt: skip
        ds.write(z, 1)
    return path
