"""Tests of run folders and error-model files (locator.runio)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from locator.runio import RunFileError, read_run, write_figures, write_run
from predisat.gnss.errormodel import (
    ErrorModel,
    ErrorModelFileError,
    IntervalModel,
    read_error_model,
    write_error_model,
)


def epochs() -> pd.DataFrame:
    n = 30
    rng = np.random.default_rng(3)
    truth = 500.0 + 10.0 * np.arange(n)
    est = truth + rng.normal(0, 2, n)
    half = rng.uniform(5, 40, n)
    return pd.DataFrame(
        {
            "epoch": np.arange(n), "gps_s": 1e9 + np.arange(n), "chainage_m": est,
            "lo_m": est - half, "hi_m": est + half, "length_m": 2 * half,
            "claim": rng.uniform(size=n) > 0.2, "claim_fix": np.ones(n, bool),
            "mode": ["three_pairs"] * n, "n_received": 12, "n_trusted": 9, "n_used": 9,
            "used": ["G01 G02"] * n, "excluded": [""] * n, "truth_m": truth,
        }
    )  # fmt: skip


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_run_round_trip(tmp_path, fmt):
    ep = epochs()
    write_run(ep, tmp_path / "r", {"track": "t", "summary": {"x": 1.0}}, fmt)
    back, meta = read_run(tmp_path / "r")
    assert meta["track"] == "t" and meta["format"] == "locator-run/1"
    assert back["claim"].dtype == bool and back["claim"].tolist() == ep["claim"].tolist()
    assert np.allclose(back["chainage_m"], ep["chainage_m"])
    assert back["excluded"].tolist() == [""] * len(ep) or back["excluded"].isna().all()
    # rewriting in the other format leaves one table only
    other = "csv" if fmt == "parquet" else "parquet"
    write_run(ep, tmp_path / "r", {}, other)
    assert not (tmp_path / "r" / f"epochs.{fmt}").exists()


def test_a_rerun_removes_the_previous_runs_scoring(tmp_path):
    folder = tmp_path / "r"
    write_run(epochs(), folder, {})
    stale = ["scored.parquet", "scored.csv", "evaluation.json", "stanford.png"]
    for name in stale:  # as `locator evaluate` leaves them
        (folder / name).write_text("old")
    (folder / "notes.txt").write_text("mine")
    write_run(epochs(), folder, {})
    assert not any((folder / name).exists() for name in stale)
    assert (folder / "notes.txt").read_text() == "mine"  # what the run did not write stays


def test_run_json_is_strict_json(tmp_path):
    meta = {"summary": {"length_median_m": np.float64("nan"), "n": np.int64(3),
                        "bounds": [1.0, float("inf")]}}  # fmt: skip
    write_run(epochs(), tmp_path / "r", meta)

    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")

    doc = json.loads((tmp_path / "r" / "run.json").read_text(), parse_constant=refuse)
    assert doc["summary"] == {"length_median_m": None, "n": 3, "bounds": [1.0, None]}


def test_read_errors_name_the_fix(tmp_path):
    with pytest.raises(RunFileError, match="locator run --out"):
        read_run(tmp_path)
    (tmp_path / "run.json").write_text("{nope")
    with pytest.raises(RunFileError, match="not valid JSON"):
        read_run(tmp_path)
    (tmp_path / "run.json").write_text(json.dumps({"format": "other/9"}))
    with pytest.raises(RunFileError, match="is not 'locator-run/1'"):
        read_run(tmp_path)
    # a table cut short: named, with the fix
    write_run(pd.DataFrame({"gps_s": [1.0, 2.0]}), tmp_path / "cut", {})
    data = (tmp_path / "cut" / "epochs.parquet").read_bytes()
    (tmp_path / "cut" / "epochs.parquet").write_bytes(data[: len(data) // 2])
    with pytest.raises(RunFileError, match=r"epochs\.parquet: not a readable.*rerun `locator run`"):
        read_run(tmp_path / "cut")


def test_error_model_round_trip_and_errors(tmp_path):
    m = IntervalModel(ErrorModel(0.4, 1.3, 2.0), k_sigma=3.5)
    p = write_error_model(tmp_path / "m.json", m, {"data": "test"})
    assert read_error_model(p) == m
    with pytest.raises(ErrorModelFileError, match="locator calibrate"):
        read_error_model(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text(json.dumps({"format": "locator-error-model/1", "a_m": -1,
                                                   "b_m": 0}))  # fmt: skip
    with pytest.raises(ErrorModelFileError, match="bad error model"):
        read_error_model(tmp_path / "bad.json")


def test_figures_are_written(tmp_path):
    paths = write_figures(epochs().drop(columns="truth_m"), tmp_path)
    assert [p.name for p in paths] == ["interval_time.png", "interval_chainage.png",
                                       "interval_lengths.png"]  # fmt: skip
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000
    # with the truth (a scored table) the Stanford diagram too
    paths = write_figures(epochs(), tmp_path)
    assert paths[-1].name == "stanford.png" and paths[-1].stat().st_size > 5000
