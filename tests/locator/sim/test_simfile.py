"""Tests of the simulated-run file format (locator.sim.simfile)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from locator.sim.simfile import SIMRUN_FORMAT, SignalState, SimRun, SimRunError
from predisat.geodesy import LocalFrame, ecef_to_geodetic
from predisat.synth.materials import material_id

FRAME = LocalFrame(44.0, 6.2, 600.0)
SATS = ("G01", "E11", "C05", "R07")


def make_run(n_ep: int = 6, seed: int = 0) -> SimRun:
    """A hand-made run with every state, NaN where the format says so."""
    rng = np.random.default_rng(seed)
    n_sat = len(SATS)
    state = rng.integers(0, 4, (n_ep, n_sat)).astype(np.int8)
    state[0] = [SignalState.LOS, SignalState.NLOS, SignalState.LOST, SignalState.NOT_VISIBLE]
    state[:, 3] = SignalState.NOT_VISIBLE  # a satellite never visible stays listed
    vis = state != SignalState.NOT_VISIBLE
    rec = (state == SignalState.LOS) | (state == SignalState.NLOS)
    enu = np.stack([rng.normal(0, 5, n_ep), 100 + 10.0 * np.arange(n_ep), np.full(n_ep, 4.0)], -1)

    def field(mask, scale=1.0, shift=0.0):
        return np.where(mask, shift + scale * rng.normal(size=(n_ep, n_sat)), np.nan)

    has_refl = vis & (rng.uniform(size=(n_ep, n_sat)) < 0.6)
    has_refl[0, 1] = True
    sat = np.where(vis[..., None], rng.normal(0, 2e7, (n_ep, n_sat, 3)), np.nan)
    return SimRun(
        gps_s=1.277e9 + np.arange(n_ep) * 0.5,
        chainage_m=100.0 + 10.0 * np.arange(n_ep),
        speed_mps=np.full(n_ep, 20.0),
        heading_deg=np.full(n_ep, 12.5),
        antenna_ecef_m=FRAME.enu_to_ecef(enu),
        antenna_enu_m=enu,
        clock_bias_m=1e4 + np.arange(n_ep) * 15.0,
        clock_drift_mps=np.full(n_ep, 30.0),
        sats=SATS,
        state=state,
        sat_ecef_m=sat,
        az_deg=field(vis, 90, 180),
        el_deg=field(vis, 20, 40),
        range_m=field(vis, 1e6, 2.2e7),
        corrected_m=field(rec, 1e6, 2.2e7),
        sigma_m=field(rec, 1, 5),
        cn0_dbhz=field(vis, 5, 40),
        noise_m=field(rec, 3),
        multipath_m=np.where(rec, np.where(has_refl & (state == 1), 0.7, 0.0), np.nan),
        nlos_extra_m=np.where(rec, np.where(state == 2, 12.25, 0.0), np.nan),
        reflection_delay_m=np.where(has_refl, 12.25, np.nan),
        reflector_face=np.where(has_refl, rng.integers(0, 5000, (n_ep, n_sat)), -1),
        reflector_material=np.where(has_refl, material_id("rock"), -1).astype(np.int16),
        reflection_point_enu_m=np.where(has_refl[..., None], rng.normal(size=sat.shape), np.nan),
        meta={"seed": 3, "error_model": {"a_m": 2.0, "b_m": 2.0}},
    )  # fmt: skip


def assert_same(a: SimRun, b: SimRun) -> None:
    assert a.sats == b.sats
    for name in SimRun.__dataclass_fields__:
        va, vb = getattr(a, name), getattr(b, name)
        if isinstance(va, np.ndarray):
            assert va.shape == vb.shape, name
            np.testing.assert_array_equal(va, vb, err_msg=name)  # NaN == NaN here
    assert dict(b.meta) == dict(a.meta)


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_round_trip(tmp_path, fmt):
    run = make_run()
    folder = run.write(tmp_path / "run", fmt=fmt)
    assert (folder / f"signals.{fmt}").is_file() and (folder / "meta.json").is_file()
    assert_same(run, SimRun.read(folder))


def test_rewrite_in_other_format_replaces_tables(tmp_path):
    run = make_run()
    run.write(tmp_path / "r", fmt="csv")
    run.write(tmp_path / "r", fmt="parquet")
    assert not (tmp_path / "r" / "signals.csv").exists()
    assert_same(run, SimRun.read(tmp_path / "r"))


def test_tables_are_documented_long_form(tmp_path):
    run = make_run()
    run.write(tmp_path / "r", fmt="csv")
    sig = pd.read_csv(tmp_path / "r" / "signals.csv", keep_default_na=False, na_values=[""])
    vis = run.state != SignalState.NOT_VISIBLE
    assert len(sig) == vis.sum()
    assert set(sig["state"]) <= {"los", "nlos", "lost"}
    assert "R07" not in set(sig["sat"])  # never visible: no row
    row = sig[(sig.epoch == 0) & (sig.sat == "E11")].iloc[0]
    assert row.state == "nlos" and row.reflector_material == "rock"
    assert row.nlos_extra_m == 12.25
    ep = pd.read_csv(tmp_path / "r" / "epochs.csv")
    lat, lon, h = ecef_to_geodetic(run.antenna_ecef_m)
    np.testing.assert_allclose(ep[["lat_deg", "lon_deg", "h_m"]].to_numpy(),
                               np.stack([lat, lon, h], -1))  # fmt: skip
    meta = json.loads((tmp_path / "r" / "meta.json").read_text())
    assert meta["format"] == SIMRUN_FORMAT and meta["sats"] == list(SATS)


def test_views():
    run = make_run()
    obs = run.observations(0)
    assert obs.sats == ("G01", "E11")
    assert run.observations(0, include_nlos=False).sats == ("G01",)
    np.testing.assert_array_equal(obs.corrected_m, run.corrected_m[0, :2])
    c = run.counts()
    assert list(c.columns) == ["los", "nlos", "lost"]
    np.testing.assert_array_equal(c["lost"], (run.state == SignalState.LOST).sum(1))
    np.testing.assert_allclose(
        run.error_m[run.received],
        (run.corrected_m - run.range_m - run.clock_bias_m[:, None])[run.received],
    )


def test_arrays_are_read_only():
    run = make_run()
    with pytest.raises(ValueError):
        run.corrected_m[0, 0] = 1.0


def test_shape_mismatch_is_refused():
    run = make_run()
    kw = {n: getattr(run, n) for n in SimRun.__dataclass_fields__}
    kw["noise_m"] = kw["noise_m"][:, :2]
    with pytest.raises(ValueError, match="noise_m"):
        SimRun(**kw)


def test_read_errors_name_the_problem(tmp_path):
    with pytest.raises(SimRunError, match=r"no meta\.json"):
        SimRun.read(tmp_path)
    folder = make_run().write(tmp_path / "r")
    meta = json.loads((folder / "meta.json").read_text())
    (folder / "meta.json").write_text(json.dumps({**meta, "format": "other/9"}))
    with pytest.raises(SimRunError, match="format"):
        SimRun.read(folder)
    (folder / "meta.json").write_text(json.dumps({**meta, "sats": ["G01"]}))
    with pytest.raises(SimRunError, match="not listed"):
        SimRun.read(folder)
    # a direction of 0 was named by nothing but the odometer, without the file
    (folder / "meta.json").write_text(json.dumps({**meta, "direction": 0}))
    with pytest.raises(SimRunError, match=r"meta\.json: direction 0 must be 1 .* or -1"):
        SimRun.read(folder)
    (folder / "meta.json").write_text(json.dumps(meta))
    sig = pd.read_parquet(folder / "signals.parquet").drop(columns=["range_m"])
    sig.to_parquet(folder / "signals.parquet")
    with pytest.raises(SimRunError, match="range_m"):
        SimRun.read(folder)
    # a copy cut short: named, with the fix
    data = (folder / "epochs.parquet").read_bytes()
    (folder / "signals.parquet").write_bytes(data[: len(data) // 2])
    damaged = r"signals\.parquet: not a readable.*rerun `locator simulate`"
    with pytest.raises(SimRunError, match=damaged):
        SimRun.read(folder)
    (folder / "signals.parquet").unlink()
    with pytest.raises(SimRunError, match="signals"):
        SimRun.read(folder)


def test_bad_format_argument(tmp_path):
    with pytest.raises(ValueError, match="fmt"):
        make_run().write(tmp_path / "x", fmt="rinex")
