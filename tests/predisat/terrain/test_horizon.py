"""Terrain horizon against an independent computation: a synthetic GeoTIFF written with rasterio,
rays placed by pyproj's geodesic and sampled every metre through scipy's interpolator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rasterio
from pyproj import Geod
from rasterio.transform import from_origin
from scipy.interpolate import RegularGridInterpolator

from predisat.terrain import Dem, DemError, antenna_height_m, terrain_horizon_deg
from predisat.terrain.horizon import EARTH_RADIUS_M, REFRACTION_K
from tests.predisat.terrain._dem import CELL_DEG, write_synthetic_dem


@pytest.fixture(scope="module")
def tif(tmp_path_factory) -> Path:
    return write_synthetic_dem(tmp_path_factory.mktemp("dem") / "synthetic.tif")


def _reference_deg(dem: Dem, lat: float, lon: float, h0: float, az: float, d_max: float,
                   d_min: float) -> float:  # fmt: skip
    """Dense independent horizon: pyproj geodesic rays, scipy bilinear, every metre."""
    n_lat, n_lon = dem.shape
    lats = dem.lat0_deg - np.arange(n_lat) * dem.dlat_deg
    lons = dem.lon0_deg + np.arange(n_lon) * dem.dlon_deg
    interp = RegularGridInterpolator((lats[::-1], lons), dem.height_m[::-1].astype(float),
                                     bounds_error=False)  # fmt: skip
    d = np.arange(d_min, d_max, 1.0)
    plon, plat, _ = Geod(ellps="WGS84").fwd(np.full(d.size, lon), np.full(d.size, lat),
                                            np.full(d.size, az), d)  # fmt: skip
    h = interp(np.column_stack([plat, plon])) + dem.vertical_error_m
    r_eff = EARTH_RADIUS_M / (1 - REFRACTION_K)
    el = np.degrees(np.arctan2(h - h0 - d**2 / (2 * r_eff), d))
    return float(np.nanmax(el))


def test_horizon_matches_a_dense_geodesic_reference(tif: Path) -> None:
    dem = Dem.from_files([tif], vertical_error_m=10.0)
    lat, lon = np.array([44.995, 45.0]), np.array([6.0, 5.99])
    h0 = np.array([104.0, 104.0])
    az = np.arange(0.0, 360.0, 15.0)
    hz = terrain_horizon_deg(dem, lat, lon, h0, az, min_range_m=100.0, max_range_m=6000.0)
    for i in range(2):
        ref = [_reference_deg(dem, lat[i], lon[i], h0[i], a, 6000.0, 100.0) for a in az]
        # the reference samples every metre, the code every half cell (46 m) near the antenna
        np.testing.assert_allclose(hz[i], ref, atol=0.25)
    # towards the plateau (north, 500 m up 2.8 km away) the horizon is high; to the
    # south-west the plain is flat:
    # 10 m of stated vertical error less the 4 m antenna over 100 m at most 3.4 deg
    assert hz[0, 0] > 8.0 and hz[0, az.tolist().index(225.0)] < 3.5


def test_vertical_error_and_refraction_raise_the_horizon(tif: Path) -> None:
    dem0 = Dem.from_files([tif], vertical_error_m=0.0)
    dem16 = Dem.from_files([tif])
    args = (np.array([44.995]), np.array([6.0]), np.array([104.0]), np.array([0.0, 90.0]))
    a = terrain_horizon_deg(dem0, *args, refraction_k=0.0)
    b = terrain_horizon_deg(dem0, *args)
    c = terrain_horizon_deg(dem16, *args)
    assert np.all(b > a) and np.all(c > b)


def test_antenna_stands_on_the_lowest_ground_nearby(tif: Path) -> None:
    dem = Dem.from_files([tif])
    lat, lon = 45.0 + 0.3 * CELL_DEG, 6.03  # on the hill's flank, between cells
    cells = [dem.height_at(lat + i * CELL_DEG, lon + j * CELL_DEG)
             for i in (-1, 0, 1) for j in (-1, 0, 1)]  # fmt: skip
    assert antenna_height_m(dem, [lat], [lon], 4.0)[0] == pytest.approx(min(cells) + 4.0)


def test_off_the_dem_is_nan_and_bad_files_are_named(tif: Path, tmp_path: Path) -> None:
    dem = Dem.from_files([tif])
    assert np.isnan(terrain_horizon_deg(dem, [10.0], [10.0], [0.0], [0.0])).all()
    with pytest.raises(DemError, match="no such elevation tile"):
        Dem.from_files([tmp_path / "missing.hgt"])
    junk = tmp_path / "junk.tif"
    junk.write_bytes(b"not a raster")
    with pytest.raises(DemError, match=r"junk\.tif: not a readable"):
        Dem.from_files([junk])
    utm = tmp_path / "utm.tif"
    with rasterio.open(utm, "w", driver="GTiff", height=4, width=4, count=1, dtype="float32",
                       crs="EPSG:32631", transform=from_origin(0, 0, 30, 30)) as ds:  # fmt: skip
        ds.write(np.zeros((4, 4), np.float32), 1)
    with pytest.raises(DemError, match="EPSG:4326"):
        Dem.from_files([utm])


@pytest.mark.shared
def test_srtm_tiles_read_with_their_stated_heights(shared_data: Path) -> None:
    tiles = sorted((shared_data / "terrain" / "srtm3_nice").glob("*.hgt"))
    dem = Dem.from_files(tiles)
    assert dem.bounds_deg == pytest.approx((6.0, 43.0, 8.0, 44.0))
    # SOURCE.txt: Nice Gare du Sud 26 m (the station at 43.7105 N, 7.2620 E)
    assert dem.height_at(43.7105, 7.262) == pytest.approx(26.0, abs=4.0)
    # the two tiles meet at 7 E without a seam
    assert abs(dem.height_at(43.5, 6.9999) - dem.height_at(43.5, 7.0001)) < 20.0
