"""A recorded log against a simulated run (locator.odometry.simulated.odometer_from_log)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.logfile import OdometerLogError, read_odometer_log
from locator.odometry.simulated import check_log_against_run, odometer_from_log

T0_S = 1277107200.0
SUBSET041 = OdometerAccuracy.subset041()


def _run(direction: int = 1):
    # a run at 10 m/s for 30 s, epochs 1 s apart (what odometer_from_log reads of a SimRun)
    t = T0_S + np.arange(31.0)
    chainage_m = 1000.0 + direction * 10.0 * (t - T0_S)
    return SimpleNamespace(gps_s=t, chainage_m=chainage_m, speed_mps=np.full(len(t), 10.0),
                           meta={"direction": direction})  # fmt: skip


def _log(tmp_path, t0_s=T0_S, duration_s=30.0, sign=1, scale=1.0):
    t = np.arange(0.0, duration_s + 0.05, 0.1)
    df = pd.DataFrame({"t_s": t0_s + t, "dist_m": sign * scale * 10.0 * t,
                       "speed_mps": scale * 10.0, "direction": sign})  # fmt: skip
    p = tmp_path / "odo.csv"
    df.to_csv(p, index=False, float_format="%.17g")
    return read_odometer_log(p)


def test_a_matching_log_gives_the_run_distance(tmp_path):
    so = odometer_from_log(_run(), _log(tmp_path))
    np.testing.assert_allclose(so.epoch_odo_m, 10.0 * np.arange(31.0), atol=1e-6)


def test_a_log_running_backward_on_a_forward_run_is_refused(tmp_path):
    log = _log(tmp_path, sign=-1)  # consistent in itself: direction -1, distance decreasing
    with pytest.raises(OdometerLogError, match=r"odo\.csv: over the run its dist_m runs backward "
                       r"\(-300\.0 m.*negate dist_m and direction"):  # fmt: skip
        odometer_from_log(_run(), log)


@pytest.mark.parametrize(
    ("t0_s", "duration_s", "match"),
    [
        (0.0, 30.0, r"its times look relative .* add the GPS time of its first row"),
        (T0_S, 20.0, r"it ends 10\.0 s before the run"),
        # a user trial read "ends 0.0 s before the run" for a log 32 microseconds short
        (T0_S - 3.2e-5, 30.0, r"it ends 3\.2e-05 s before the run"),
        (T0_S + 86400.0, 30.0, r"it starts 1 day\(s\) after the run"),
        (T0_S - 18.0, 30.0, r"GPS-UTC leap seconds.*GPS = UTC \+ 18 s on the run.s date"),
    ],
)
def test_a_log_not_covering_the_run_says_why(tmp_path, t0_s, duration_s, match):
    log = _log(tmp_path, t0_s, duration_s)
    with pytest.raises(OdometerLogError, match=match) as exc:
        odometer_from_log(_run(), log)
    assert str(tmp_path / "odo.csv") in str(exc.value)


@pytest.mark.parametrize(
    ("scale", "shift_s", "match"),
    [
        (3.28084, 0.0, r"3\.28 times the train's distance: feet\?"),
        (1.2, 0.0, r"1\.2 times the train's distance\)"),
        (0.5, 0.0, r"0\.5 times"),
        (0.0, 0.0, r"no movement logged"),
        (1.0, 3.0, r"at t_s .* has run .* the train"),
    ],
)
def test_a_log_off_its_accuracy_is_refused(tmp_path, scale, shift_s, match):
    """A user trial: a log in feet, scaled, standing still or 3 s late put the true front outside
    the safe fronts at 18-30 of 41 epochs, and nothing said so."""
    run = _run()
    log = _log(tmp_path, T0_S - 5.0, 40.0, scale=scale)
    if shift_s:  # a train accelerating from a stop, and its log 3 s late
        t = T0_S + np.arange(31.0)
        run = SimpleNamespace(gps_s=t, chainage_m=1000.0 + 0.25 * (t - T0_S) ** 2,
                              speed_mps=0.5 * (t - T0_S), meta={"direction": 1})  # fmt: skip
        tl = T0_S + np.arange(0.0, 30.05, 0.1)
        late = np.clip(tl - T0_S - shift_s, 0.0, None)
        p = tmp_path / "odo.csv"
        pd.DataFrame({"t_s": tl, "dist_m": 0.25 * late**2, "speed_mps": 0.5 * late,
                      "direction": 1}).to_csv(p, index=False, float_format="%.17g")  # fmt: skip
        check_log_against_run(run, _log_of(tmp_path, run), SUBSET041)  # on time: passes
        log = read_odometer_log(p)
    with pytest.raises(OdometerLogError, match=match) as exc:
        check_log_against_run(run, log, SUBSET041)
    assert str(tmp_path / "odo.csv") in str(exc.value) and "--odometer-accuracy" in str(exc.value)


def test_a_log_within_its_accuracy_passes(tmp_path):
    # 4 % long (within 5 m + 5 %), and the exact one
    for scale in (1.04, 1.0):
        check_log_against_run(_run(), _log(tmp_path, T0_S - 5.0, 40.0, scale=scale), SUBSET041)


def _over_read_log(tmp_path, over=0.04, start_s=200.0, length_s=20.0):
    """A log at 20 m/s for 300 s that over-reads by ``over`` from ``start_s`` for ``length_s``
    (distance and speed alike: consistent in itself, only the truth shows it)."""
    t = np.arange(0.0, 300.05, 0.1)
    v = 20.0 * np.where((t >= start_s) & (t < start_s + length_s), 1.0 + over, 1.0)
    dist = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.1)])
    p = tmp_path / "odo.csv"
    pd.DataFrame({"t_s": T0_S + t, "dist_m": dist, "speed_mps": v,
                  "direction": 1}).to_csv(p, index=False, float_format="%.17g")  # fmt: skip
    return read_odometer_log(p)


def _run_20mps():
    t = T0_S + np.arange(301.0)
    return SimpleNamespace(gps_s=t, chainage_m=100.0 + 20.0 * (t - T0_S),
                           speed_mps=np.full(len(t), 20.0), meta={"direction": 1})  # fmt: skip


def test_an_over_read_between_anchors_is_refused(tmp_path):
    """A user trial: a 4 % over-read for 20 s (416 m read for 400 m run) passed against
    1 m + 2 % because only the displacement since the first epoch was checked (16 m against
    89 m at 220 s); every epoch may anchor the run's bounds, so it is refused from 200 s on."""
    acc = OdometerAccuracy(1.0, 0.02, 0.02)
    with pytest.raises(OdometerLogError) as exc:
        check_log_against_run(_run_20mps(), _over_read_log(tmp_path), acc)
    msg = str(exc.value)
    assert str(tmp_path / "odo.csv") in msg
    assert ("at t_s 1277107420.0 (epoch 220) its dist_m has run 416.0 m since t_s 1277107400.0 "
            "(epoch 200), the train 400.0 m" in msg and "by 6.7 m" in msg), msg
    assert "unmarked slip or slide" in msg and "--odometer-accuracy" in msg
    # the same log against bounds that hold 4 %, and a healthy log at 1 m + 2 %, pass
    check_log_against_run(_run_20mps(), _over_read_log(tmp_path), OdometerAccuracy(1.0, 0.045,
                                                                                  0.045))
    check_log_against_run(_run_20mps(), _over_read_log(tmp_path, over=0.015), acc)


def _log_of(tmp_path, run):
    """The exact log of an accelerating ``run`` (chainage 1000 + 0.25 t^2)."""
    tl = T0_S + np.arange(0.0, 30.05, 0.1)
    q = tl - T0_S
    p = tmp_path / "exact.csv"
    pd.DataFrame({"t_s": tl, "dist_m": 0.25 * q**2, "speed_mps": 0.5 * q,
                  "direction": 1}).to_csv(p, index=False, float_format="%.17g")  # fmt: skip
    return read_odometer_log(p)


def test_a_run_going_back_is_refused_not_clamped():
    """The simulated odometer follows one direction; a reversing run was clamped to a
    standstill and its odometer read 557 m against a true 236 m (a trial)."""
    from locator.odometry.odometer import OdometerConfig
    from locator.odometry.simulated import odometer_along_run

    run = _run()
    back = SimpleNamespace(**{**vars(run), "chainage_m": np.concatenate(
        [run.chainage_m[:16], run.chainage_m[14::-1]]),
        "speed_mps": np.concatenate([np.full(16, 10.0), np.full(15, -10.0)])})  # fmt: skip
    with pytest.raises(ValueError, match=r"goes back .* split the run at its reversals"):
        odometer_along_run(back, OdometerConfig())
    assert odometer_along_run(run, OdometerConfig()).epoch_odo_m[-1] > 250.0
