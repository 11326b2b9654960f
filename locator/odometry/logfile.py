"""Odometer logs on disk (CSV) and their validation.

Columns (one row per odometer cycle, in time order; ``docs/odometry.md``):

| column | unit | meaning |
|---|---|---|
| ``t_s`` | s | cycle time (GPS seconds, the receiver's time scale) |
| ``dist_m`` | m | distance since the first row, signed along the train's forward axis |
| ``speed_mps`` | m/s | speed (>= 0) |
| ``direction`` | - | +1 forward, -1 backward, 0 standstill |
| ``slip`` | - | optional: 1 where the odometer marked slip / slide |

Rejected with :class:`OdometerLogError` naming the file, the line and the fix: missing
columns, non-finite values, time not increasing, **gaps** (a step longer than ``max_gap_s``),
a **reversed direction** (the distance running against the direction column, or the direction
flipping while the train moves), **impossible accelerations** (speed changing faster than the
configured maximum acceleration plus a tolerance).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from locator.odometry.odometer import OdometerLog

__all__ = ["OdometerLogError", "read_odometer_log", "validate_odometer_log", "write_odometer_log"]

COLUMNS = ("t_s", "dist_m", "speed_mps", "direction")


class OdometerLogError(ValueError):
    """An odometer log that cannot be used; the message names the file, the line and the fix."""


def write_odometer_log(log: OdometerLog, path: str | Path) -> Path:
    """Write a log as CSV (17 significant digits: the floats round-trip exactly)."""
    p = Path(path)
    df = pd.DataFrame({"t_s": log.t_s, "dist_m": log.dist_m, "speed_mps": log.speed_mps,
                       "direction": log.direction, "slip": log.slip.astype(int)})  # fmt: skip
    df.to_csv(p, index=False, float_format="%.17g")
    return p


def read_odometer_log(
    path: str | Path,
    *,
    max_accel_mps2: float = 1.5,
    max_gap_s: float = 0.5,
    accel_tolerance_mps2: float = 0.5,
) -> OdometerLog:
    """Read and validate an odometer log (CSV).

    Parameters
    ----------
    path : str or Path
    max_accel_mps2 : float
        The odometer's configured maximum acceleration, m/s^2.
    max_gap_s : float
        Longest step allowed between rows, s.
    accel_tolerance_mps2 : float
        Added to ``max_accel_mps2`` before a row is refused (speed quantisation).

    Returns
    -------
    OdometerLog
        Truth fields (``diameter_ratio``, ``radar_scale``) NaN; ``wheel_speed_mps`` is the
        logged speed and ``edges`` zero (not logged).
    """
    p = Path(path)
    try:
        df = pd.read_csv(p)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise OdometerLogError(f"{p}: cannot read the odometer log ({exc}); give a CSV file "
                               f"with columns {', '.join(COLUMNS)}") from exc  # fmt: skip
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        raise OdometerLogError(
            f"{p}: missing columns {missing}; an odometer log needs {', '.join(COLUMNS)} "
            "(docs/odometry.md)"
        )
    t = df["t_s"].to_numpy(float)
    dist = df["dist_m"].to_numpy(float)
    speed = df["speed_mps"].to_numpy(float)
    direction = df["direction"].to_numpy(float)
    slip = df["slip"].to_numpy(float) if "slip" in df.columns else np.zeros(len(t))
    validate_odometer_log(
        t,
        dist,
        speed,
        direction,
        str(p),
        max_accel_mps2=max_accel_mps2,
        max_gap_s=max_gap_s,
        accel_tolerance_mps2=accel_tolerance_mps2,
    )
    return OdometerLog(
        t_s=t, dist_m=dist, speed_mps=speed, wheel_speed_mps=speed.copy(),
        direction=direction.astype(np.int8), edges=np.zeros(len(t), np.int64),
        slip=slip.astype(bool), diameter_ratio=float("nan"), radar_scale=float("nan"),
    )  # fmt: skip


def _line(i: int) -> int:
    """File line of data row ``i`` (the header is line 1)."""
    return int(i) + 2


def validate_odometer_log(
    t_s: np.ndarray,
    dist_m: np.ndarray,
    speed_mps: np.ndarray,
    direction: np.ndarray,
    label: str,
    *,
    max_accel_mps2: float = 1.5,
    max_gap_s: float = 0.5,
    accel_tolerance_mps2: float = 0.5,
) -> None:
    """Raise :class:`OdometerLogError` at the first bad row (file line numbers in ``label``)."""
    n = len(t_s)
    if n < 2:
        raise OdometerLogError(f"{label}: {n} rows; an odometer log needs at least two cycles")
    for name, a in (("t_s", t_s), ("dist_m", dist_m), ("speed_mps", speed_mps),
                    ("direction", direction)):  # fmt: skip
        bad = np.flatnonzero(~np.isfinite(a))
        if len(bad):
            raise OdometerLogError(
                f"{label}, line {_line(bad[0])}: {name} is empty or not a number; fill it in "
                "or drop the row (a dropped row must not leave a gap)"
            )
    bad = np.flatnonzero(speed_mps < 0)
    if len(bad):
        raise OdometerLogError(f"{label}, line {_line(bad[0])}: speed_mps {speed_mps[bad[0]]} "
                               "< 0; speed is unsigned, the sign goes in direction")  # fmt: skip
    bad = np.flatnonzero(~np.isin(direction, (-1, 0, 1)))
    if len(bad):
        raise OdometerLogError(f"{label}, line {_line(bad[0])}: direction {direction[bad[0]]} "
                               "must be +1, -1 or 0")  # fmt: skip
    dt = np.diff(t_s)
    bad = np.flatnonzero(dt <= 0)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {_line(i)}: t_s {t_s[i]:.3f} does not follow {t_s[i - 1]:.3f}; sort "
            "the rows by time and remove duplicates"
        )
    bad = np.flatnonzero(dt > max_gap_s)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {_line(i)}: gap of {dt[bad[0]]:.2f} s after t_s {t_s[i - 1]:.3f} "
            f"(more than {max_gap_s:g} s); recover the missing cycles from the recorder, or split "
            f"the log at line {_line(i)} and start the second part from a new reference"
        )
    step = np.diff(dist_m)
    tol = 1e-6 + 0.02 * np.abs(step)
    moving_dir = direction[1:]
    against = ((moving_dir > 0) & (step < -tol)) | ((moving_dir < 0) & (step > tol))
    bad = np.flatnonzero(against)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {_line(i)}: dist_m changes by {step[bad[0]]:+.3f} m but direction "
            f"is {int(direction[i]):+d} (reversed direction); check the sign convention "
            "(dist_m along the train's forward axis) or the channel order of the wheel sensor"
        )
    flip = (direction[1:] * direction[:-1] < 0) & (np.minimum(speed_mps[1:], speed_mps[:-1]) > 0.5)
    bad = np.flatnonzero(flip)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {_line(i)}: direction reverses at {speed_mps[i]:.1f} m/s; a train "
            "reverses only through a standstill: check the wheel sensor's channels (swapped or "
            "a lost channel) or cut out the faulty stretch"
        )
    acc = np.diff(speed_mps) / dt
    bad = np.flatnonzero(np.abs(acc) > max_accel_mps2 + accel_tolerance_mps2)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {_line(i)}: acceleration {acc[bad[0]]:+.2f} m/s^2 exceeds the "
            f"maximum {max_accel_mps2:g} m/s^2 (+{accel_tolerance_mps2:g}); an unfiltered slip "
            "or slide, or a wrong max_accel_mps2: correct the row or the configuration"
        )
