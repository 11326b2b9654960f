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
        ref = np.array([_reference_deg(dem, lat[i], lon[i], h0[i], a, 6000.0, 100.0)
                        for a in az])  # fmt: skip
        # never below the dense bilinear horizon; above it by at most the terrain within a
        # cell of the ray (the code takes the highest post of the 3 x 3 at every sample: the
        # hill's flank 100 m away rises 2.7 deg more that way)
        assert np.all(hz[i] >= ref - 1e-9)
        assert np.all(hz[i] - ref < 3.0) and np.median(hz[i] - ref) < 0.5
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


def _flat_dem(path: Path, n: int = 601, spikes=(), voids=(), crs: str = "EPSG:4326",
              north_deg: float = 44.5) -> Path:  # fmt: skip
    """A 100 m plain of n x n posts of 3 arc-seconds from ``north_deg`` N 6.5 E (north-west
    post), with single-post spikes ``(row, col, height)`` and void posts ``(row, col)``."""
    z = np.full((n, n), 100.0, np.float32)
    for r, c, h in spikes:
        z[r, c] = h
    for r, c in voids:
        z[r, c] = -32768.0
    tr = from_origin(6.5 - CELL_DEG / 2, north_deg + CELL_DEG / 2, CELL_DEG, CELL_DEG)
    with rasterio.open(path, "w", driver="GTiff", height=n, width=n, count=1, dtype="float32",
                       crs=crs, transform=tr, nodata=-32768.0) as ds:  # fmt: skip
        ds.write(z, 1)
    return path


@pytest.mark.parametrize("north_deg", [44.5, 60.5, 70.5])
def test_a_single_post_peak_far_away_is_never_missed(tmp_path: Path, north_deg: float) -> None:
    """A review: at the Var's mouth a 1 108 m post 24.4 km away fell between two samples
    243 m apart and the horizon came out 42 m low, beyond the 16 m error; another: north of
    50 N the rays, placed on the tangent plane, turned by up to 0.3 deg at 24 km and peaks
    fell out of their own bins (19 of 300 at 80 N). Here: 60 single-post peaks 5-20 km from
    the antenna, 0.05 deg from a bin's edge, each bin's horizon against the peak's own
    elevation from pyproj's geodesic
    (distance and azimuth), curvature and refraction."""
    from predisat.masks.terrain import bin_horizon_deg

    rng = np.random.default_rng(5)  # fixed peaks: the truth below is computed, not recorded
    lat0, lon0 = north_deg - 500 * CELL_DEG, 6.5 + 500 * CELL_DEG  # the middle of 1001 x 1001
    spikes = []
    geod = Geod(ellps="WGS84")
    for _ in range(60):
        # near a bin's edge (bins centred on whole degrees): a ray turned by the plane
        # loses the peak to the next bin
        d = rng.uniform(5000.0, 20000.0)
        a = float(rng.integers(0, 360)) + 0.5 + float(rng.choice([-0.05, 0.05]))
        lo, la, _ = geod.fwd(lon0, lat0, a, d)
        r, c = round((north_deg - la) / CELL_DEG), round((lo - 6.5) / CELL_DEG)
        if 2 <= r <= 998 and 2 <= c <= 998:
            spikes.append((r, c, float(rng.uniform(150.0, 700.0))))
    assert len(spikes) >= 40
    dem = Dem.from_files([_flat_dem(tmp_path / "spikes.tif", n=1001, spikes=spikes,
                                    north_deg=north_deg)], vertical_error_m=0)  # fmt: skip
    masks = _masks_at(lat0, lon0)
    hz = bin_horizon_deg(masks, dem, antenna_above_ground_m=4.0, max_range_m=20_000.0)
    r_eff = EARTH_RADIUS_M / (1 - REFRACTION_K)
    for r, c, h in spikes:
        la, lo = north_deg - r * CELL_DEG, 6.5 + c * CELL_DEG
        az, _, d = geod.inv(lon0, lat0, lo, la)
        el = np.degrees(np.arctan2(h - 104.0 - d**2 / (2 * r_eff), d))
        k = int(np.floor(np.mod(az + 0.5, 360.0))) % 360  # 1 deg bins centred on whole degrees
        assert hz[0, k] >= el - 1e-6, (r, c, h, d, az, hz[0, k], el)


def _masks_at(lat: float, lon: float):
    """One position's mask set of 360 one-degree bins at 5 deg (ASSUMED)."""
    from predisat.masks.maskset import BinSource, MaskSet

    return MaskSet(
        chainage_m=np.array([0.0]), lat_deg=np.array([lat]), lon_deg=np.array([lon]),
        h_m=np.array([100.0]), heading_deg=np.array([0.0]), az_step_deg=1.0,
        mask_el_deg=np.full((1, 360), 5.0, np.float32),
        source=np.full((1, 360), BinSource.ASSUMED, np.uint8),
        margin_deg=np.zeros((1, 360), np.float32),
    )  # fmt: skip


def test_rays_leaving_the_tiles_or_meeting_voids_are_not_terrain_bounds(tmp_path: Path) -> None:
    """A review: tiles ending 3.5 km north of a station gave TERRAIN bins 4.6-7.7 deg below the
    truth, and a void at the track left a position without any horizon, both silently."""
    from predisat.masks.maskset import BinSource
    from predisat.masks.terrain import bin_terrain, coverage_notes, raise_to_terrain

    # a 500 m ridge 3 km east; the grid's north edge 2.5 km from the antenna; voids on the
    # ridge to the south-east
    lat0, lon0 = 44.5 - 90 * CELL_DEG, 6.75
    ridge = [(r, 300 + 46, 600.0) for r in range(0, 601)]
    voids = [(r, 346) for r in range(110, 140)]  # where the south-east rays cross the ridge
    dem = Dem.from_files([_flat_dem(tmp_path / "edge.tif", spikes=ridge, voids=voids)])
    masks = _masks_at(lat0, lon0)
    got = bin_terrain(masks, dem, max_range_m=10_000.0)
    assert not got.complete[0, 0] and not got.complete[0, 10]  # north: off the grid
    assert not got.complete[0, 135]  # south-east: the ridge's void
    assert got.complete[0, 90] and got.complete[0, 250]  # east (ridge) and west: covered
    raised = raise_to_terrain(masks, got)
    assert raised.source[0, 90] == BinSource.TERRAIN and raised.mask_el_deg[0, 90] > 5.0
    assert raised.source[0, 0] == BinSource.ASSUMED and raised.source[0, 135] == (
        BinSource.ASSUMED)  # fmt: skip
    assert np.all(raised.mask_el_deg >= masks.mask_el_deg)
    (note,) = coverage_notes(raised, got, "edge.tif")
    assert "1 of 1 positions" in note and "N" in note.split("toward ")[1]
    # both remedies (a trial: voids inside a tile were told to add the neighbouring tiles)
    assert "neighbouring tiles where they end" in note and "void-filled model" in note
    assert raised.provenance["terrain"]["partly_covered_bins"] > 0
    # a void at the antenna's posts: ground is found nearby and the horizon still raises the
    # bins, but it bounds none (a review: past a void along a gorge floor the ground found
    # stood on the walls, 200 m above the track, and TERRAIN bins were 28 deg low)
    at = [(90 + i, 300 + j) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    dem2 = Dem.from_files([_flat_dem(tmp_path / "void.tif", spikes=ridge, voids=voids + at)])
    got2 = bin_terrain(masks, dem2, max_range_m=10_000.0)
    assert np.isfinite(got2.el_deg).all() and not got2.complete.any()
    assert got2.el_deg[0, 90] > 5.0


def test_tiles_in_another_datum_or_meridian_are_refused(tmp_path: Path) -> None:
    """A review: a Paris-meridian tile was read 2.34 deg west of its place."""
    paris = _flat_dem(tmp_path / "paris.tif", n=8,
                      crs="+proj=longlat +ellps=clrk80ign +pm=paris +no_defs")  # fmt: skip
    with pytest.raises(DemError, match="Greenwich"):
        Dem.from_files([paris])
    ed50 = _flat_dem(tmp_path / "ed50.tif", n=8,
                     crs="+proj=longlat +ellps=intl +towgs84=-87,-98,-121 +no_defs")  # fmt: skip
    with pytest.raises(DemError, match="not geographic WGS84"):
        Dem.from_files([ed50])
    etrs = _flat_dem(tmp_path / "etrs.tif", n=8, crs="EPSG:4258")  # within a metre of WGS84
    assert Dem.from_files([etrs]).shape == (8, 8)
    # a 3-D WGS84 CRS, or WGS84 with a vertical datum (SRTM's EGM96 heights): the posts are
    # where the 2-D one puts them (they used to be refused); a compound in another datum is not
    flat = Dem.from_files([_flat_dem(tmp_path / "flat.tif", n=8)])
    for name, crs in (("3d", "EPSG:4979"), ("egm96", "EPSG:4326+5773"),
                      ("etrs_egg", "EPSG:4258+3855")):  # fmt: skip
        dem = Dem.from_files([_flat_dem(tmp_path / f"{name}.tif", n=8, crs=crs)])
        assert (dem.lat0_deg, dem.lon0_deg, dem.shape) == (flat.lat0_deg, flat.lon0_deg, (8, 8))
    ed50_egm = _flat_dem(tmp_path / "ed50_egm.tif", n=8, crs="EPSG:4230+5773")
    with pytest.raises(DemError, match="not geographic WGS84"):
        Dem.from_files([ed50_egm])
