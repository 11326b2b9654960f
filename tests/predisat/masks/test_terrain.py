"""Masks raised to a DEM horizon (predisat.masks.terrain), against per-azimuth horizons of the
terrain module taken densely over each bin, and the mask file's version 2."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from predisat.masks.fileformat import read_masks, write_masks
from predisat.masks.margins import SECTORS, MarginTable
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.terrain import bin_horizon_deg, raise_to_terrain
from predisat.terrain import Dem, TerrainHorizon, antenna_height_m, terrain_horizon_deg
from tests.predisat.terrain._dem import write_synthetic_dem


def _masks(el_deg: float = 5.0) -> MaskSet:
    n, n_az = 3, 36
    return MaskSet(
        chainage_m=np.arange(n) * 10.0, lat_deg=np.full(n, 44.995),
        lon_deg=6.0 + np.arange(n) * 1e-4, h_m=np.full(n, 150.0), heading_deg=np.zeros(n),
        az_step_deg=10.0, mask_el_deg=np.full((n, n_az), el_deg),
        source=np.full((n, n_az), int(BinSource.ASSUMED)), margin_deg=np.full((n, n_az), 1.0),
    )  # fmt: skip


@pytest.fixture(scope="module")
def dem(tmp_path_factory) -> Dem:
    return Dem.from_files([write_synthetic_dem(tmp_path_factory.mktemp("d") / "s.tif")])


def test_bin_horizon_is_the_highest_terrain_over_the_bin(dem: Dem) -> None:
    m = _masks()
    hz = bin_horizon_deg(m, dem, min_range_m=100.0, max_range_m=5000.0)
    h0 = antenna_height_m(dem, m.lat_deg, m.lon_deg, 4.0)
    # dense reference: every 0.1 deg over each 10 deg bin centred on k * 10 deg, both edges
    # included (bin 9's edge at 85 deg is on the hill's flank: 1.4 deg above its inside)
    for k in (0, 8, 9, 18, 27):
        az = np.linspace(k * 10.0 - 5.0, k * 10.0 + 5.0, 101) % 360.0
        ref = terrain_horizon_deg(dem, m.lat_deg, m.lon_deg, h0, az, min_range_m=100.0,
                                  max_range_m=5000.0).max(axis=1)  # fmt: skip
        np.testing.assert_allclose(hz[:, k], ref, atol=0.3)


def test_raise_to_terrain_only_raises_and_flags(dem: Dem) -> None:
    m = _masks(5.0)
    hz = np.full(m.mask_el_deg.shape, np.nan)
    hz[:, 0] = 12.0  # above the mask: raised
    hz[:, 1] = 3.0  # below: kept
    # a bare array says nothing of the rays' coverage: raised, not flagged
    bare = raise_to_terrain(m, hz, dem_source="x.tif")
    assert np.all(bare.mask_el_deg[:, 0] == 12.0) and np.array_equal(bare.source, m.source)
    out = raise_to_terrain(m, TerrainHorizon(hz, np.isfinite(hz)), dem_source="x.tif")
    assert np.all(out.mask_el_deg[:, 0] == 12.0)
    assert np.all(out.source[:, 0] == BinSource.TERRAIN)
    assert np.all(out.mask_el_deg[:, 1:] == 5.0) and np.all(out.source[:, 1:] == m.source[:, 1:])
    assert np.array_equal(out.margin_deg, m.margin_deg)
    assert out.provenance["terrain"]["raised_bins"] == 3
    assert np.all(m.source == BinSource.ASSUMED)  # the input is not changed
    with pytest.raises(ValueError, match="shape"):
        raise_to_terrain(m, hz[:, :5])


def test_terrain_bins_make_a_version_2_file_and_take_the_assumed_margin(tmp_path) -> None:
    m = _masks()
    plain = write_masks(m, tmp_path / "plain.parquet")
    assert read_masks(plain).equals(m)
    hz = np.full(m.mask_el_deg.shape, np.nan)
    hz[0, :4] = 20.0
    raised = raise_to_terrain(m, TerrainHorizon(hz, np.isfinite(hz)))
    back = read_masks(write_masks(raised, tmp_path / "terrain.parquet"))
    assert back.equals(raised) and int((back.source == BinSource.TERRAIN).sum()) == 4
    meta = pq.read_schema(tmp_path / "terrain.parquet").metadata[b"predisat"]
    assert json.loads(meta)["format_version"] == 2
    assert json.loads(pq.read_schema(plain).metadata[b"predisat"])["format_version"] == 1
    # a margin table has no terrain rows: terrain bins take the assumed margin
    rows = [{"sector": s, "source": c, "margin_deg": {"assumed": 3.0}.get(c, 1.0)}
            for s in SECTORS for c in ("observed", "reconstructed", "assumed")]  # fmt: skip
    table = MarginTable(pd.DataFrame(rows), target=0.999)
    table.check()
    out = table.apply(raised)
    assert np.all(out.margin_deg[raised.source == BinSource.TERRAIN] == 3.0)


def test_a_dem_missing_the_line_gives_nan_without_numpy_warnings(dem: Dem) -> None:
    import warnings

    m = _masks()
    far = MaskSet(
        chainage_m=m.chainage_m, lat_deg=np.full(m.n_pos, 50.5), lon_deg=m.lon_deg - 1.3,
        h_m=m.h_m, heading_deg=m.heading_deg, az_step_deg=m.az_step_deg,
        mask_el_deg=m.mask_el_deg, source=m.source, margin_deg=m.margin_deg,
    )  # fmt: skip
    with warnings.catch_warnings():
        # before: numpy's "All-NaN slice encountered" from nanmin / nanmax, printed raw
        warnings.simplefilter("error", RuntimeWarning)
        hz = bin_horizon_deg(far, dem, min_range_m=100.0, max_range_m=5000.0)
        assert np.isnan(antenna_height_m(dem, far.lat_deg, far.lon_deg, 4.0)).all()
    assert hz.shape == (m.n_pos, m.n_az) and np.isnan(hz).all()
