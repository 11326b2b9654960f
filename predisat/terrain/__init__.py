"""Terrain: digital elevation models and the horizon they cast (the far field of a mask).

:mod:`predisat.terrain.dem` reads elevation tiles (SRTM ``.hgt``, GeoTIFF) with rasterio;
:mod:`predisat.terrain.horizon` computes the terrain horizon per azimuth at antenna positions,
with the Earth's curvature, refraction and the model's stated vertical error.
"""

from predisat.terrain.dem import Dem, DemError
from predisat.terrain.horizon import (
    REFRACTION_K,
    TerrainHorizon,
    antenna_height_m,
    terrain_horizon,
    terrain_horizon_deg,
)

__all__ = [
    "REFRACTION_K",
    "Dem",
    "DemError",
    "TerrainHorizon",
    "antenna_height_m",
    "terrain_horizon",
    "terrain_horizon_deg",
]
