"""A recorded log against a simulated run (locator.odometry.simulated.odometer_from_log)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from locator.odometry.logfile import OdometerLogError, read_odometer_log
from locator.odometry.simulated import odometer_from_log

T0_S = 1277107200.0


def _run(direction: int = 1):
    # a run at 10 m/s for 30 s, epochs 1 s apart (what odometer_from_log reads of a SimRun)
    t = T0_S + np.arange(31.0)
    chainage_m = 1000.0 + direction * 10.0 * (t - T0_S)
    return SimpleNamespace(gps_s=t, chainage_m=chainage_m, speed_mps=np.full(len(t), 10.0),
                           meta={"direction": direction})  # fmt: skip


def _log(tmp_path, t0_s=T0_S, duration_s=30.0, sign=1):
    t = np.arange(0.0, duration_s + 0.05, 0.1)
    df = pd.DataFrame({"t_s": t0_s + t, "dist_m": sign * 10.0 * t, "speed_mps": 10.0,
                       "direction": sign})  # fmt: skip
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
        (T0_S + 86400.0, 30.0, r"it starts 1 day\(s\) after the run"),
        (T0_S - 18.0, 30.0, r"GPS-UTC leap seconds"),
    ],
)
def test_a_log_not_covering_the_run_says_why(tmp_path, t0_s, duration_s, match):
    log = _log(tmp_path, t0_s, duration_s)
    with pytest.raises(OdometerLogError, match=match) as exc:
        odometer_from_log(_run(), log)
    assert str(tmp_path / "odo.csv") in str(exc.value)
