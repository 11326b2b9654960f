"""Odometer logs on disk: round trip and bad input (locator.odometry.logfile)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from locator.odometry.logfile import OdometerLogError, read_odometer_log, write_odometer_log
from locator.odometry.odometer import OdometerConfig, simulate_odometer


def good_frame():
    t = np.arange(0.0, 20.0, 0.1)
    v = np.minimum(0.5 * t, 5.0)
    d = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.1)])
    return pd.DataFrame({"t_s": 1e9 + t, "dist_m": d, "speed_mps": v,
                         "direction": (v > 0).astype(int)})  # fmt: skip


def test_round_trip(tmp_path):
    t = np.arange(0.0, 30.0, 0.1)
    log = simulate_odometer(t, 0.25 * t**2, OdometerConfig(), seed=3)
    back = read_odometer_log(write_odometer_log(log, tmp_path / "odo.csv"))
    np.testing.assert_array_equal(back.dist_m, log.dist_m)
    np.testing.assert_array_equal(back.direction, log.direction)
    np.testing.assert_array_equal(back.slip, log.slip)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda df: df.drop(columns="speed_mps"), "missing columns"),
        (lambda df: df.drop(index=range(50, 60)).reset_index(drop=True), "line 52: gap of 1.10 s"),
        (
            lambda df: df.assign(direction=np.where(df.index == 30, -1, df["direction"])),
            "line 32: dist_m changes",
        ),
        (
            lambda df: df.assign(speed_mps=np.where(df.index == 70, 9.0, df["speed_mps"])),
            "line 72: acceleration",
        ),
        (lambda df: df.iloc[[0, 2, 1, 3]], "line 4: t_s"),
        (
            lambda df: df.assign(speed_mps=np.where(df.index == 5, -1.0, df["speed_mps"])),
            "line 7: speed_mps",
        ),
    ],
)
def test_bad_logs_name_the_line_and_the_fix(tmp_path, edit, match):
    p = tmp_path / "odo.csv"
    edit(good_frame()).to_csv(p, index=False)
    with pytest.raises(OdometerLogError, match=match) as exc:
        read_odometer_log(p)
    assert str(p) in str(exc.value)


def test_reversal_while_moving_is_refused(tmp_path):
    df = good_frame()
    # a flipped channel order from row 120 on: direction -1 and the distance running back
    df.loc[120:, "direction"] = -1
    d119 = df.loc[119, "dist_m"]
    df.loc[120:, "dist_m"] = d119 - (df.loc[120:, "dist_m"] - d119)
    p = tmp_path / "odo.csv"
    df.to_csv(p, index=False)
    with pytest.raises(OdometerLogError, match=r"line 122: direction reverses at 5\.0 m/s"):
        read_odometer_log(p)
