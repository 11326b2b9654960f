"""Availability engine: counts vs a brute-force PROJ computation, interval vs a per-position
reference, shares, stretches, writers."""

from __future__ import annotations

import json
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pyproj import Transformer

from predisat.availability.engine import (
    Availability,
    compute_availability,
    longest_run,
    reference_counts,
)
from predisat.availability.interval import best_pair, three_independent_pairs
from predisat.availability.satellites import (
    LinePositions,
    SatellitePositions,
    TrustRule,
    azel,
    default_ephemeris,
    default_window,
)
from predisat.gnss.errormodel import IntervalModel
from predisat.masks.maskset import MaskSet
from predisat.track.map import TrackMap

N_AZ = 180


@pytest.fixture(scope="module")
def sats() -> SatellitePositions:
    return SatellitePositions.from_ephemeris(default_ephemeris(), default_window()[::40], "all")


@pytest.fixture(scope="module")
def masks() -> MaskSet:
    # a line of 60 km (so that the candidate pre-filter's slack matters), positions 5 km apart
    track = TrackMap.from_latlon(np.linspace(50.30, 50.70, 9), np.linspace(4.3, 4.9, 9), 150.0)
    s = np.arange(0.0, track.length_m, 5000.0)
    rng = np.random.default_rng(5)
    az = np.arange(N_AZ) * 2.0
    mask = 8.0 + 25.0 * (np.sin(np.radians(az))[None] > 0.6) + rng.uniform(0, 4, (len(s), N_AZ))
    return MaskSet.from_track(track, s, mask, margin_deg=1.5)


def _brute(sats: SatellitePositions, pos: LinePositions, threshold) -> np.ndarray:
    """Counts with PROJ topocentric coordinates, one position and one satellite at a time."""
    out = np.zeros((pos.n_pos, len(sats.gps_s)), int)
    near = np.zeros_like(out, bool)
    for i in range(pos.n_pos):
        topo = Transformer.from_pipeline(
            "+proj=pipeline +step +proj=topocentric +ellps=WGS84 "
            f"+lat_0={pos.lat_deg[i]} +lon_0={pos.lon_deg[i]} +h_0={pos.h_m[i]}"
        )
        x = sats.pos_ecef_m
        e, n, u = topo.transform(x[..., 0], x[..., 1], x[..., 2])
        az = np.mod(np.degrees(np.arctan2(e, n)), 360.0)
        el = np.degrees(np.arctan2(u, np.hypot(e, n)))
        thr = threshold(i, az)
        ok = np.isfinite(el) & (np.nan_to_num(el, nan=-99) > thr)
        out[i] = ok.sum(axis=1)
        near[i] = np.any(np.abs(np.nan_to_num(el, nan=-99) - thr) < 1e-3, axis=1)
    return out, near


def test_counts_with_masks_match_brute_force(sats, masks) -> None:
    pos = LinePositions.from_masks(masks)
    res = compute_availability(sats, pos, TrustRule.mask(masks), chunk_positions=4, workers=2)
    eff = masks.mask_el_deg + masks.margin_deg

    def thr(i, az):  # bin k covers [2k - 1, 2k + 1) deg
        return eff[i][np.floor(np.nan_to_num(az) / 2.0 + 0.5).astype(int) % N_AZ]

    want, near = _brute(sats, pos, thr)
    assert res.count.shape == want.shape and res.count.dtype == np.uint8
    np.testing.assert_array_equal(res.count[~near], want[~near])
    assert np.mean(near) < 0.05
    assert res.count.min() < res.count.max()  # the masks do cut satellites


@pytest.mark.parametrize("cut", [0.0, 15.0])
def test_counts_flat_cutoff_match_brute_force(sats, masks, cut) -> None:
    pos = LinePositions.from_masks(masks)
    rule = TrustRule.none() if cut == 0 else TrustRule.cutoff(cut)
    res = compute_availability(sats, pos, rule, with_interval=False)
    want, near = _brute(sats, pos, lambda i, az: cut)
    np.testing.assert_array_equal(res.count[~near], want[~near])
    assert res.interval_m is None


def test_constellation_selection_reduces_counts(masks) -> None:
    t = default_window()[::120]
    eph = default_ephemeris()
    pos = LinePositions.from_masks(masks)
    counts = {}
    for c in ("gps", "gps+galileo", "all"):
        sp = SatellitePositions.from_ephemeris(eph, t, c)
        counts[c] = compute_availability(sp, pos, TrustRule.cutoff(10), with_interval=False).count
    assert np.all(counts["gps"] <= counts["gps+galileo"])
    assert np.all(counts["gps+galileo"] <= counts["all"])
    assert counts["gps"].mean() < counts["gps+galileo"].mean() < counts["all"].mean()


def test_interval_every_and_threads(sats, masks) -> None:
    pos = LinePositions.from_masks(masks)
    rule = TrustRule.mask(masks)
    a = compute_availability(sats, pos, rule, interval_every=1, workers=1, chunk_positions=3)
    b = compute_availability(sats, pos, rule, interval_every=3, workers=2, chunk_positions=5)
    np.testing.assert_array_equal(a.count, b.count)
    # only the predicted epochs are stored: the first, then every third
    assert b.interval_m.shape == (pos.n_pos, -(-len(sats.gps_s) // 3))
    np.testing.assert_array_equal(b.interval_gps_s, sats.gps_s[::3])
    np.testing.assert_allclose(b.interval_m, a.interval_m[:, ::3], rtol=1e-6)
    np.testing.assert_allclose(b.sensitivity, a.sensitivity[:, ::3], rtol=1e-6)
    np.testing.assert_array_equal(b.interval_count, a.count[:, ::3])
    ok = a.count >= 2
    assert np.all(np.isfinite(a.interval_m[ok])) and np.all(a.interval_m[ok] > 0)
    assert np.all((a.sensitivity[ok] > 0) & (a.sensitivity[ok] <= 2.0))


def _hand_built(count: np.ndarray, chainage_m=None) -> Availability:
    n_pos, n_ep = count.shape
    s = np.arange(n_pos) * 10.0 if chainage_m is None else np.asarray(chainage_m, float)
    pos = LinePositions(s, 50.0, 4.0, 100.0, 0.0)
    return Availability(
        pos, 1e9 + 30.0 * np.arange(n_ep), ("G01",), "test", count.astype(np.uint8), None,
        None, np.full(n_pos, 170.0),
    )  # fmt: skip


def test_shares_and_longest_stretches_on_hand_built_counts() -> None:
    count = np.array(
        [
            [6, 6, 3, 3, 3, 6],
            [6, 5, 3, 2, 6, 6],
            [1, 4, 3, 6, 6, 6],
            [6, 6, 6, 6, 6, 6],
        ]
    )
    a = _hand_built(count)
    np.testing.assert_allclose(a.share_at_least(4), [3 / 6, 4 / 6, 4 / 6, 1.0])
    np.testing.assert_allclose(a.share_at_least(6), [3 / 6, 3 / 6, 3 / 6, 1.0])
    assert a.line_share_at_least(2) == pytest.approx(23 / 24)
    # time: position 0 has 3 epochs below 4 in a row (90 s), position 1 two (60 s)
    np.testing.assert_allclose(a.longest_below_s(4), [90.0, 60.0, 30.0, 0.0])
    # space: epoch 2 has positions 0-2 below 4: cells of 10 m each -> 30 m
    np.testing.assert_allclose(a.longest_below_m(4), [10.0, 0.0, 30.0, 20.0, 10.0, 0.0])
    summary = a.summary()
    assert summary["longest_below4_m"] == 30.0 and summary["longest_below4_s"] == 90.0
    assert summary["longest_below4_s_at_chainage_m"] == 0.0
    # epoch 2 is GPS 1e9 + 60 s; GPS - UTC was 15 s from 2009 to mid-2012 (IERS Bulletin C)
    utc = datetime(1980, 1, 6) + timedelta(seconds=1e9 + 60.0 - 15.0)
    assert summary["longest_below4_m_at_utc"] == utc.strftime("%Y-%m-%d %H:%M:%S UTC")


def _random_result(every: int) -> Availability:
    rng = np.random.default_rng(11)
    count = rng.integers(0, 9, (37, 53)).astype(np.uint8)
    n_iv = -(-53 // every)
    iv = rng.uniform(5.0, 80.0, (37, n_iv)).astype(np.float32)
    iv[count[:, ::every] < 2] = np.nan
    pos = LinePositions(np.cumsum(rng.uniform(5.0, 15.0, 37)), 50.0, 4.0, 100.0, 0.0)
    return Availability(
        pos, 1e9 + 30.0 * np.arange(53), ("G01",), "test", count, iv, iv / 40.0,
        np.full(37, 170.0), {}, every,
    )  # fmt: skip


def test_reductions_in_blocks_are_those_of_the_whole_grid(monkeypatch) -> None:
    from predisat.availability import engine

    a = _random_result(every=4)
    c, w = a.count.astype(int), a.cell_length_m
    # the whole-grid formulas, written out here
    full_iv = np.full(c.shape, np.nan)
    full_iv[:, ::4] = a.interval_m
    x = np.where(c >= 4, full_iv, np.nan)
    want_q = np.nanquantile(x, (0.5, 0.95), axis=1).T
    lo, hi = engine._cell_extent(a.chainage_m)
    t = a.gps_s
    want = {
        "share": [np.mean(c >= n, axis=1) for n in (2, 4, 6)],
        "epoch": [np.sum((c >= n) * w[:, None], axis=0) / np.sum(w) for n in (2, 4, 6)],
        "below_m": longest_run(c.T < 4, lo, hi),
        "below_s": longest_run(c < 4, t - 15.0, t + 15.0),
    }
    monkeypatch.setattr(engine, "_BLOCK_CELLS", 50)  # one row per block
    assert len(engine._row_slices(a.count.shape)) == 37
    for n, s_want, e_want in zip((2, 4, 6), want["share"], want["epoch"], strict=True):
        np.testing.assert_array_equal(a.share_at_least(n), s_want)
        np.testing.assert_array_equal(a.epoch_table()[f"share_ge{n}"], e_want)
    np.testing.assert_array_equal(a.longest_below_m(4), want["below_m"])
    np.testing.assert_array_equal(a.longest_below_s(4), want["below_s"])
    np.testing.assert_allclose(a.interval_quantiles(), want_q, rtol=1e-12)
    np.testing.assert_allclose(a.position_table()["mean_count"], c.mean(axis=1), rtol=1e-12)
    sm = a.summary()
    assert sm["interval_median_m"] == pytest.approx(float(np.nanmedian(x)))
    assert sm["interval_p95_m"] == pytest.approx(float(np.nanquantile(x, 0.95)))


def test_summary_and_tables_are_computed_once_and_handed_out_as_copies(monkeypatch) -> None:
    a = _random_result(every=1)
    calls = []
    original = Availability.longest_below_s

    def spy(self, n=4):
        calls.append(n)
        return original(self, n)

    monkeypatch.setattr(Availability, "longest_below_s", spy)
    for _ in range(3):
        a.summary()
        a.position_table()
    assert len(calls) == 2  # once for the summary, once for the table
    first = a.summary()
    first["share_ge4"] = -1.0
    assert a.summary()["share_ge4"] >= 0.0
    table = a.position_table()
    table["share_ge4"] = -1.0
    table.insert(0, "rule", "x")
    assert (a.position_table()["share_ge4"] >= 0.0).all()
    assert "rule" not in a.position_table()


def test_intervals_of_another_shape_than_the_predicted_epochs_are_refused() -> None:
    a = _random_result(every=4)
    with pytest.raises(ValueError, match="interval_m has shape"):
        Availability(a.positions, a.gps_s, a.sats, a.rule, a.count,
                     np.zeros(a.count.shape, np.float32), None, a.opening_angle_deg, {},
                     4)  # fmt: skip


def test_the_long_counts_table_is_written_in_pieces_with_every_count(
    tmp_path: Path, monkeypatch
) -> None:
    import pyarrow.parquet as pq

    from predisat.availability import engine

    a, b = _random_result(every=1), _random_result(every=2)
    b = Availability(b.positions, b.gps_s, b.sats, "other", b.count[:, ::-1], b.interval_m,
                     b.sensitivity, b.opening_angle_deg, {}, 2)  # fmt: skip
    monkeypatch.setattr(engine, "_COUNTS_ROWS", 200)  # 3 positions of 53 epochs per piece
    path = engine.write_counts(tmp_path / "c.parquet", [a, b], {b"k": b"v"})
    f = pq.ParquetFile(path)
    assert f.metadata.num_row_groups == 2 * 13 and f.schema_arrow.metadata[b"k"] == b"v"
    got = f.read().to_pandas()
    n_pos, n_ep = a.count.shape
    for i, r in enumerate((a, b)):
        part = got.iloc[i * n_pos * n_ep : (i + 1) * n_pos * n_ep]
        assert set(part["rule"]) == {r.rule}
        np.testing.assert_array_equal(part["chainage_m"], np.repeat(r.chainage_m, n_ep))
        np.testing.assert_array_equal(part["gps_s"], np.tile(r.gps_s, n_pos))
        np.testing.assert_array_equal(part["count"], r.count.ravel())


def test_longest_run_uses_cell_bounds() -> None:
    flag = np.array([[True, True, False, True], [False, False, False, False]])
    lo = np.array([0.0, 5.0, 20.0, 30.0])
    hi = np.array([5.0, 20.0, 30.0, 31.0])
    np.testing.assert_allclose(longest_run(flag, lo, hi), [20.0, 0.0])


def test_writers(tmp_path: Path, sats, masks) -> None:
    pos = LinePositions.from_masks(masks)
    a = compute_availability(sats, pos, TrustRule.mask(masks), interval_every=2)
    csv = pd.read_csv(a.to_csv(tmp_path / "a.csv"))
    assert len(csv) == pos.n_pos
    np.testing.assert_allclose(csv["share_ge4"], a.share_at_least(4), atol=1e-6)
    import pyarrow.parquet as pq

    table = pq.read_table(a.to_parquet(tmp_path / "a.parquet"))
    meta = json.loads(table.schema.metadata[b"predisat.availability.engine"])
    assert meta["summary"]["share_ge6"] == pytest.approx(a.line_share_at_least(6))
    long = pd.read_parquet(a.to_parquet(tmp_path / "c.parquet", counts=True))
    assert len(long) == a.count.size and long["count"].sum() == a.count.sum()
    fc = a.to_geojson_lines(path=tmp_path / "a.geojson")
    assert len(fc["features"]) == pos.n_pos
    first = fc["features"][0]
    assert first["geometry"]["type"] == "LineString"
    assert first["properties"]["class"] in {"ge6", "ge4", "ge2", "lt2"}
    json.loads((tmp_path / "a.geojson").read_text())
    np.testing.assert_allclose(a.opening_angle_deg, masks.opening_angle_deg())


def _reference_interval(sats, pos, rule, model, doubt=(0.0, 0.0)):
    """Per position and epoch, float64 az/el, the public pair functions on the trusted only;
    with a map doubt (lateral, vertical metres) each chosen pair's band grows by
    ``lat |du_level| + vert |du_up|``, written out here."""
    length = np.full((pos.n_pos, len(sats.gps_s)), np.nan)
    rot, rx, t_enu = pos.enu_rotation, pos.ecef_m, pos.tangent_enu
    lat, vert = doubt
    for i in range(pos.n_pos):
        az, el = azel(rx[i], rot[i], sats.pos_ecef_m)
        ok = rule.trusted(pos.chainage_m[i], az, el)
        a, e = np.radians(az), np.radians(el)
        u = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
        g = u @ t_enu[i]
        for t in range(len(sats.gps_s)):
            k = np.nonzero(ok[t])[0]
            gt, st, ut = g[t, k], model.error.sigma_m(el[t, k]), u[t, k]
            if len(k) >= 6:
                pairs = three_independent_pairs(gt, st, k_sigma=model.k_sigma)[0]
            elif len(k) >= 4:
                pairs = np.stack(np.triu_indices(len(k), 1), axis=-1)
            elif len(k) >= 2:
                pairs = best_pair(gt, st, k_sigma=model.k_sigma)[0][None]
            else:
                continue
            half = []
            for p_, q_ in pairs:
                du = ut[p_] - ut[q_]
                band = model.k_sigma * np.hypot(st[p_], st[q_])
                band += lat * np.hypot(du[0], du[1]) + vert * abs(du[2])
                half.append(band / abs(gt[p_] - gt[q_]))
            length[i, t] = 2 * max(half)
    return length


@pytest.mark.parametrize("doubt", [(0.0, 0.0), (1.5, 1.0), (4.5, 3.0)])
def test_interval_matches_per_position_reference(sats, masks, doubt) -> None:
    from predisat.availability.interval import MapDoubt

    pos = LinePositions.from_masks(masks)
    rule = TrustRule.mask(masks)
    model = IntervalModel()
    # the reference draws k = 2 (model.k_sigma) in every mode: fix it here too
    res = compute_availability(sats, pos, rule, interval_model=model, integrity=None, workers=2,
                               map_doubt=MapDoubt(*doubt))  # fmt: skip
    want = _reference_interval(sats, pos, rule, model, doubt)
    same_count = res.count == reference_counts(sats, pos, rule)
    assert np.mean(same_count) > 0.99
    x, y = res.interval_m[same_count].astype(float), want[same_count]
    np.testing.assert_array_equal(np.isnan(x), np.isnan(y))
    rel = np.abs(x - y)[np.isfinite(y)] / y[np.isfinite(y)]
    # float32 geometry vs float64: equal to float32 precision, but for the rare epoch where
    # two satellites' pool ranks are within rounding (then the pool, so the length, differs)
    assert np.mean(rel < 1e-5) > 0.99 and np.median(rel) < 1e-6
    if doubt != (0.0, 0.0):  # the doubt widens every interval
        plain = compute_availability(sats, pos, rule, interval_model=model, integrity=None,
                                     map_doubt=None)  # fmt: skip
        ok = np.isfinite(plain.interval_m)
        assert np.all(res.interval_m[ok] > plain.interval_m[ok])


def test_even_chunk_sizes_are_bit_identical(sats, masks) -> None:
    # chunks of an even number of positions take the same BLAS kernel for g (odd ones may
    # round g differently in the last bit); counts never depend on the chunking
    pos = LinePositions.from_masks(masks)
    rule = TrustRule.mask(masks)
    a = compute_availability(sats, pos, rule, chunk_positions=2, workers=2)
    b = compute_availability(sats, pos, rule, chunk_positions=4, workers=1)
    c = compute_availability(sats, pos, rule, chunk_positions=1, workers=1)
    np.testing.assert_array_equal(a.interval_m, b.interval_m)
    np.testing.assert_array_equal(a.sensitivity, b.sensitivity)
    np.testing.assert_array_equal(a.count, c.count)
    np.testing.assert_allclose(a.interval_m, c.interval_m, rtol=1e-5)


def test_blocks_on_a_dask_cluster_give_the_serial_bits(sats, masks) -> None:
    """The positions cut into blocks (tasks) on a cluster: every array bit-identical to a
    serial run (each block cuts its positions into the serial run's chunks)."""
    from distributed import LocalCluster

    from predisat.availability.engine import _blocks
    from predisat.scheduler import Scheduler, TaskRunner

    pos = LinePositions.from_masks(masks)
    rule = TrustRule.mask(masks)
    serial = compute_availability(sats, pos, rule, chunk_positions=2, interval_every=3)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
        runner = TaskRunner(Scheduler.at(cluster.scheduler_address))
        with runner:
            blocks = _blocks(pos.n_pos, 2, TaskRunner(Scheduler.local(2)))
            on_dask = compute_availability(sats, pos, rule, chunk_positions=2, interval_every=3,
                                           runner=runner)  # fmt: skip
    # several blocks, each a whole number of chunks, covering every position once
    assert len(blocks) > 1 and all(a % 2 == 0 for a, _ in blocks)
    assert np.array_equal(np.concatenate([np.arange(a, b) for a, b in blocks]),
                          np.arange(pos.n_pos))  # fmt: skip
    assert on_dask.count.tobytes() == serial.count.tobytes()
    assert on_dask.interval_m is not None and serial.interval_m is not None
    assert on_dask.interval_m.tobytes() == serial.interval_m.tobytes()
    assert on_dask.sensitivity is not None and serial.sensitivity is not None
    assert on_dask.sensitivity.tobytes() == serial.sensitivity.tobytes()
    assert "Dask cluster at" in on_dask.provenance["workers"]


def test_the_inner_progress_is_plain_lines_when_stderr_is_not_a_terminal(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Nested bars move the cursor up: redirected to a log they leave escape codes. A log gets
    a line at every tenth instead (a trial's batch log showed nothing for a whole rule)."""
    import sys

    from predisat.availability.engine import _progress

    monkeypatch.setattr(sys.stderr, "isatty", lambda: False)  # redirected (even under -s)
    bar = _progress(10, True, "masks")
    for _ in range(10):
        bar.update(1)
    bar.close()
    err = capsys.readouterr().err
    assert "\r" not in err and "\x1b" not in err
    lines = err.splitlines()
    assert len(lines) == 10 and lines[0].startswith("availability, masks: 1/10 positions (10 %,")
    # the last too: a log ending on "9/10 positions (90 %)" read as a run stopped short
    assert lines[-1].startswith("availability, masks: 10/10 positions (100 %,")
    quiet = _progress(10, False, "masks")
    quiet.update(10)
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    bar = _progress(10, True, "masks")
    bar.update(5)
    bar.close()
    assert "availability, masks" in capsys.readouterr().err
