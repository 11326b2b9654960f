"""Odometer logs on disk (CSV) and their validation.

Columns (one row per odometer cycle, in time order; ``docs/odometry.md``):

| column | unit | meaning |
|---|---|---|
| ``t_s`` | s | cycle time (GPS seconds, the receiver's time scale) |
| ``dist_m`` | m | distance since the first row, signed along the train's forward axis |
| ``speed_mps`` | m/s | speed (>= 0) |
| ``direction`` | - | +1 forward, -1 backward, 0 standstill |
| ``slip`` | - | optional: 1 where the odometer marked slip / slide |
| ``extra_ahead_m``, ``extra_behind_m`` | m | optional: disputed distance since the first row |

The disputed distance (non-decreasing, >= 0) is how much further ahead / behind the other
sensor put the train on marked cycles; the confidence interval adds it. Absent, it is 0: the
stated accuracy must then cover the odometer's slip handling.

Rejected with :class:`OdometerLogError` naming the file, the line and the fix: missing
columns, non-finite values, time not increasing, **gaps** (a step longer than ``max_gap_s``),
a **reversed direction** (the distance running against the direction column, or the direction
flipping while the train moves), distance **moving under a standstill** (direction 0 over
unmarked cycles), **impossible accelerations** (speed changing faster than the
configured maximum acceleration plus a tolerance, over at least a second, outside the cycles
the log marks as slip or slide).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from locator.csvinput import CsvTable, read_csv_table
from locator.odometry.odometer import OdometerLog

__all__ = ["OdometerLogError", "read_odometer_log", "validate_odometer_log", "write_odometer_log"]

COLUMNS = ("t_s", "dist_m", "speed_mps", "direction")
_EXTRA = ("extra_ahead_m", "extra_behind_m")
# column names of other loggers and the column each probably is
_ALIASES = {"time": "t_s", "t": "t_s", "time_s": "t_s", "gps_s": "t_s", "dist": "dist_m",
            "distance": "dist_m", "distance_m": "dist_m", "speed": "speed_mps",
            "v_mps": "speed_mps", "dir": "direction", "slide": "slip", "slip_flag": "slip",
            "slipping": "slip"}  # fmt: skip
# a distance step agrees with speed x dt when it lies within the two speeds of its cycle times
# dt, widened by this much (speed quantised, or filtered over a few cycles)
STEP_TOLERANCE_M = 0.1
STEP_TOLERANCE_REL = 0.1
# and over a longer window, where a creep of a few percent a cycle adds up
DRIFT_WINDOW_S = 10.0
DRIFT_TOLERANCE_M = 1.0
DRIFT_TOLERANCE_REL = 0.03
DRIFT_LAG_S = 1.0
DRIFT_SPEED_MPS = 0.14  # half of 1 km/h: a speed logged in whole km/h, even when constant


class OdometerLogError(ValueError):
    """An odometer log that cannot be used; the message names the file, the line and the fix."""


def write_odometer_log(log: OdometerLog, path: str | Path) -> Path:
    """Write a log as CSV (17 significant digits: the floats round-trip exactly)."""
    p = Path(path)
    df = pd.DataFrame({"t_s": log.t_s, "dist_m": log.dist_m, "speed_mps": log.speed_mps,
                       "direction": log.direction, "slip": log.slip.astype(int),
                       "extra_ahead_m": log.extra_ahead_m,
                       "extra_behind_m": log.extra_behind_m})  # fmt: skip
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
    table = read_csv_table(p, COLUMNS, what="odometer log", error=OdometerLogError,
                           doc="docs/odometry.md", aliases=_ALIASES,
                           optional=("slip", *_EXTRA))  # fmt: skip
    t = table.numbers("t_s", "give the cycle time in GPS seconds")
    dist = table.numbers("dist_m", "give the distance in metres since the first row")
    speed = table.numbers("speed_mps", "give the speed in m/s (>= 0)")
    direction = table.numbers("direction", "give +1 (forward), -1 (backward) or 0 (standstill)")
    slip = np.zeros(len(t))
    if "slip" in table.frame.columns:
        slip = table.numbers("slip", "give 1 where the odometer marked slip or slide, 0 or "
                             "nothing elsewhere")  # fmt: skip
        bad = np.flatnonzero(~np.isnan(slip) & ~np.isin(slip, (0.0, 1.0)))
        if len(bad):
            raise OdometerLogError(f"{p}, line {table.line(bad[0])}: slip {slip[bad[0]]:g} must "
                                   "be 1 (slip or slide marked), 0 or empty")  # fmt: skip
        slip = np.nan_to_num(slip)
    extra = {name: _disputed(table, name, p) for name in _EXTRA}
    validate_odometer_log(
        t,
        dist,
        speed,
        direction,
        str(p),
        max_accel_mps2=max_accel_mps2,
        max_gap_s=max_gap_s,
        accel_tolerance_mps2=accel_tolerance_mps2,
        lines=table.lines,
        slip=slip.astype(bool),
    )
    return OdometerLog(
        t_s=t, dist_m=dist, speed_mps=speed, wheel_speed_mps=speed.copy(),
        direction=direction.astype(np.int8), edges=np.zeros(len(t), np.int64),
        slip=slip.astype(bool), diameter_ratio=float("nan"), radar_scale=float("nan"),
        source=str(p), **extra,
    )  # fmt: skip


def _disputed(table: CsvTable, name: str, path: Path) -> NDArray:
    """An optional disputed-distance column, checked: >= 0, finite, non-decreasing (zeros
    when absent)."""
    if name not in table.frame.columns:
        return np.zeros(len(table.frame))
    a = table.numbers(name, "give the disputed distance in metres since the first row (0 "
                      "where the sensors agreed)")  # fmt: skip
    bad = np.flatnonzero(~np.isfinite(a) | (a < 0))
    if len(bad):
        raise OdometerLogError(f"{path}, line {table.line(bad[0])}: {name} {a[bad[0]]} must be a "
                               "distance >= 0 in metres")  # fmt: skip
    bad = np.flatnonzero(np.diff(a) < 0)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{path}, line {table.line(i)}: {name} falls from {a[i - 1]:g} to {a[i]:g} m; it "
            "counts the disputed distance since the first row and never decreases (a per-cycle "
            "value? give its running sum)"
        )
    return np.asarray(a, float)


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
    lines: NDArray | None = None,
    slip: NDArray | None = None,
    accel_window_s: float = 1.0,
) -> None:
    """Raise :class:`OdometerLogError` at the first bad row (file line numbers in ``label``).

    Parameters
    ----------
    t_s, dist_m, speed_mps, direction : ndarray, shape (n,)
        The log's columns: cycle times (s), distance (m), speed (m/s), direction (+1/-1/0).
    label : str
        The file, named in the errors.
    max_accel_mps2, accel_tolerance_mps2 : float
        Accelerations beyond their sum are refused, m/s^2.
    max_gap_s : float
        Longest cycle step, s.
    lines : ndarray of int, optional
        The file line of each row (default: row ``i`` on line ``i + 2``, below a header).
    slip : ndarray of bool, optional
        Cycles the odometer marked as slip or slide.
    accel_window_s : float
        Accelerations are the speed change over at least this long (a speed counted from
        wheel-sensor edges is quantised per cycle); windows within a window of a marked cycle
        are not checked.
    """
    n = len(t_s)

    def line(i: int | np.integer) -> int:
        return int(lines[i]) if lines is not None else int(i) + 2

    if n < 2:
        raise OdometerLogError(f"{label}: {n} rows; an odometer log needs at least two cycles")
    for name, a in (("t_s", t_s), ("dist_m", dist_m), ("speed_mps", speed_mps),
                    ("direction", direction)):  # fmt: skip
        bad = np.flatnonzero(~np.isfinite(a))
        if len(bad):
            raise OdometerLogError(
                f"{label}, line {line(bad[0])}: {name} is empty or not a number; fill it in "
                "or drop the row (a dropped row must not leave a gap)"
            )
    bad = np.flatnonzero(speed_mps < 0)
    if len(bad):
        raise OdometerLogError(f"{label}, line {line(bad[0])}: speed_mps {speed_mps[bad[0]]} "
                               "< 0; speed is unsigned, the sign goes in direction")  # fmt: skip
    bad = np.flatnonzero(~np.isin(direction, (-1, 0, 1)))
    if len(bad):
        raise OdometerLogError(f"{label}, line {line(bad[0])}: direction {direction[bad[0]]} "
                               "must be +1, -1 or 0")  # fmt: skip
    dt = np.diff(t_s)
    bad = np.flatnonzero(dt <= 0)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {line(i)}: t_s {t_s[i]:.3f} does not follow {t_s[i - 1]:.3f}; sort "
            "the rows by time and remove duplicates"
        )
    bad = np.flatnonzero(dt > max_gap_s)
    if len(bad) and 0.01 <= np.median(dt) / 1000.0 <= max_gap_s:
        raise OdometerLogError(
            f"{label}, line {line(1)}: the rows are {np.median(dt):g} s apart: t_s looks like "
            "milliseconds; give seconds (divide by 1000)"
        )
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {line(i)}: gap of {dt[bad[0]]:.2f} s after t_s {t_s[i - 1]:.3f} "
            f"(more than {max_gap_s:g} s); recover the missing cycles from the recorder, or split "
            f"the log at line {line(i)} and start the second part from a new reference"
        )
    step = np.diff(dist_m)
    _check_steps(step, dist_m, speed_mps, dt, label, line)
    marked = np.zeros(len(t_s), bool) if slip is None else np.asarray(slip, bool)
    _check_drift(step, speed_mps, t_s, marked[1:] | marked[:-1], label, line)
    tol = 1e-6 + 0.02 * np.abs(step)
    moving_dir = direction[1:]
    against = ((moving_dir > 0) & (step < -tol)) | ((moving_dir < 0) & (step > tol))
    bad = np.flatnonzero(against)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {line(i)}: dist_m changes by {step[bad[0]]:+.3f} m but direction "
            f"is {int(direction[i]):+d} (reversed direction); check the sign convention "
            "(dist_m along the train's forward axis) or the channel order of the wheel sensor"
        )
    # at standstill over a whole run of direction-0 cycles, not per cycle: a crawl at 0.9 m/s
    # logged as standstill moves 0.09 m a 0.1 s cycle, under the step tolerance (a review);
    # cycles marked as slip or slide may move with direction 0 and are left out of the sum
    still = moving_dir == 0
    run = np.cumsum(~still)  # one id per run of consecutive direction-0 cycles
    net = np.where(still & ~(marked[1:] | marked[:-1]), step, 0.0)
    _, first, inverse = np.unique(run, return_index=True, return_inverse=True)
    moved = np.cumsum(net) - (np.cumsum(net) - net)[first][inverse]  # net distance so far
    bad = np.flatnonzero(still & (np.abs(moved) > STEP_TOLERANCE_M))
    if len(bad):
        i, g = bad[0] + 1, int(first[inverse[bad[0]]])
        since = g if still[g] else g + 1  # the row the standstill starts from
        raise OdometerLogError(
            f"{label}, line {line(i)}: dist_m has moved {moved[bad[0]]:+.3f} m since line "
            f"{line(since)} while direction is 0 (standstill); give the direction of the motion "
            "(+1 forward, -1 backward), or mark slip and slide cycles in a slip column"
        )
    flip = (direction[1:] * direction[:-1] < 0) & (np.minimum(speed_mps[1:], speed_mps[:-1]) > 0.5)
    bad = np.flatnonzero(flip)
    if len(bad):
        i = bad[0] + 1
        raise OdometerLogError(
            f"{label}, line {line(i)}: direction reverses at {speed_mps[i]:.1f} m/s; a train "
            "reverses only through a standstill: check the wheel sensor's channels (swapped or "
            "a lost channel) or cut out the faulty stretch"
        )
    # over at least accel_window_s: a speed counted from wheel-sensor edges in one cycle is
    # quantised by an edge over the cycle (0.2-0.3 m/s at 0.1 s), which alone reads as several
    # m/s^2 from one cycle to the next; a one-row spike still shows at either end of a window
    window_s = min(accel_window_s, float(t_s[-1] - t_s[0]))
    j = np.searchsorted(t_s, t_s + window_s - 1e-9)
    full = j < n  # windows running past the log's end are covered by the last full one
    j = np.minimum(j, n - 1)
    span = t_s[j] - t_s
    with np.errstate(invalid="ignore", divide="ignore"):
        acc = np.where(full & (span > 0), (speed_mps[j] - speed_mps) / span, 0.0)
    if slip is not None and np.any(slip):
        # a window within a window of a marked cycle is the odometer's business: it marks a
        # slip or slide once its own check fires, a cycle or more after the onset
        ts = t_s[np.asarray(slip, bool)]
        lo = np.searchsorted(ts, t_s - window_s, side="left")
        hi = np.searchsorted(ts, t_s[j] + window_s, side="right")
        acc = np.where(hi > lo, 0.0, acc)
    bad = np.flatnonzero(np.abs(acc) > max_accel_mps2 + accel_tolerance_mps2)
    if len(bad):
        i, k = int(bad[0]), int(j[bad[0]])
        raise OdometerLogError(
            f"{label}, line {line(k)}: speed {speed_mps[k]:.2f} m/s, {speed_mps[i]:.2f} m/s "
            f"{span[i]:.2f} s earlier (line {line(i)}): an acceleration of {acc[i]:+.2f} m/s^2, "
            f"beyond the maximum {max_accel_mps2:g} m/s^2 (+{accel_tolerance_mps2:g}); an "
            "unmarked slip or slide (mark it in a slip column), a corrupt row, or a wrong "
            "max_accel_mps2: correct the rows or the configuration"
        )


def _check_drift(
    step_m: NDArray,
    speed_mps: NDArray,
    t_s: NDArray,
    marked: NDArray,
    label: str,
    line: Callable[[int], int],
) -> None:
    """Over every :data:`DRIFT_WINDOW_S` the distance run must agree with the speed integrated
    (trapezoids) within :data:`DRIFT_TOLERANCE_REL` + :data:`DRIFT_TOLERANCE_M`, the cycles
    ``marked`` as slip or slide left out: a distance running 12 % ahead of the speed passed
    the per-cycle check (10 % + 0.1 m) of a user trial, and its telegrams went out 1.25 s
    early, 20-30 m short."""
    keep = ~marked
    ran = np.concatenate([[0.0], np.cumsum(np.abs(step_m) * keep)])
    trapezoid = 0.5 * (speed_mps[1:] + speed_mps[:-1]) * np.diff(t_s)
    moved = np.concatenate([[0.0], np.cumsum(trapezoid * keep)])
    start = np.searchsorted(t_s, t_s - DRIFT_WINDOW_S)  # each row's window start
    d_ran, d_moved = ran - ran[start], moved - moved[start]
    # what a genuine log's speed may owe its distance: a speed filtered late by up to
    # DRIFT_LAG_S integrates to lag x (the speed change across the window) less or more, and
    # a speed logged to a step (whole km/h) to half a step a cycle (a review: a braking
    # train's speed averaged over 1 s, and a 0.7 m/s creep logged in km/h, were refused)
    steps = np.diff(np.unique(speed_mps))
    half_step = max(0.5 * float(steps.min()) if len(steps) else 0.0, DRIFT_SPEED_MPS)
    allowed = (
        DRIFT_TOLERANCE_REL * d_moved + DRIFT_TOLERANCE_M
        + DRIFT_LAG_S * np.abs(speed_mps - speed_mps[start])
        + half_step * (t_s - t_s[start])
    )  # fmt: skip
    off = np.abs(d_ran - d_moved) > allowed
    bad = np.flatnonzero(off)
    if not len(bad):
        return
    i = int(bad[0])
    k = int(start[i])
    raise OdometerLogError(
        f"{label}, lines {line(k)}-{line(i)}: dist_m runs {d_ran[i]:.2f} m in "
        f"{t_s[i] - t_s[k]:.1f} s while speed_mps integrates to {d_moved[i]:.2f} m (tolerance "
        f"{allowed[i]:.2f} m: {100 * DRIFT_TOLERANCE_REL:g} % + {DRIFT_TOLERANCE_M:g} m, and the "
        f"speed's lag and resolution, over {DRIFT_WINDOW_S:g} s): "
        "the distance and the speed of the log disagree (unmarked slip or slide in one of them, "
        "pulses counted twice, a speed in another unit or filtered late): mark the slip, "
        "correct the rows or cut out the stretch"
    )


def _check_steps(
    step_m: NDArray,
    dist_m: NDArray,
    speed_mps: NDArray,
    dt_s: NDArray,
    label: str,
    line: Callable[[int], int],
) -> None:
    """Each distance step must agree with the speed: ``|step|`` within ``[min, max]`` of the
    speeds at the cycle's two rows times ``dt``, widened by :data:`STEP_TOLERANCE_M` +
    :data:`STEP_TOLERANCE_REL` of it; the message names the likely cause."""
    lo = np.minimum(speed_mps[1:], speed_mps[:-1]) * dt_s
    hi = np.maximum(speed_mps[1:], speed_mps[:-1]) * dt_s
    size = np.abs(step_m)
    off = (size < lo * (1 - STEP_TOLERANCE_REL) - STEP_TOLERANCE_M) | (
        size > hi * (1 + STEP_TOLERANCE_REL) + STEP_TOLERANCE_M
    )
    bad = np.flatnonzero(off)
    if not len(bad):
        return
    k = int(bad[0])
    i = k + 1
    expected = 0.5 * (speed_mps[i] + speed_mps[k]) * dt_s[k]
    ratio = size[k] / expected if expected > 0 else np.inf
    # back to within one cycle's run of 0: a counter reset during the cycle (an odometer that
    # counts from the last balise or reference restarts mid-cycle; a user trial's log wrapped
    # to 1.4 m and was told "pulses counted twice")
    one_cycle = hi[k] * (1 + STEP_TOLERANCE_REL) + STEP_TOLERANCE_M
    if abs(dist_m[i]) <= one_cycle < abs(dist_m[k]):
        add = dist_m[k] + expected - dist_m[i]
        cause = (f"the distance counter was reset (dist_m back to {dist_m[i]:g}; a distance "
                 "since the last balise or reference? give the running distance since the first "
                 f"row): split the log at line {line(i)}, or add {add:.3f} m to dist_m from "
                 "there on")  # fmt: skip
    elif 0.5e-3 <= ratio <= 2e-3:
        cause = "dist_m looks like kilometres (1000 times too small): give metres"
    elif 1 / 4.5 <= ratio <= 1 / 2.9:
        cause = "speed_mps looks like km/h (3.6 times too large): give m/s (km/h / 3.6)"
    elif 3.1 <= ratio <= 3.45:
        cause = "dist_m looks like feet (3.28 times too large): give metres (feet x 0.3048)"
    elif 50.0 <= ratio <= 70.0:
        cause = "t_s looks like minutes (60 times too small): give seconds"
    elif ratio > 1:
        cause = (f"a jump of {size[k] - expected:.2f} m in one cycle (pulses counted twice, a "
                 "corrupt or merged record, a reset to another reference): correct the row or "
                 "cut out the stretch")  # fmt: skip
    else:
        cause = ("the distance stands still while the speed says the train moves (a lost "
                 "wheel-sensor channel, a frozen counter, or speed in another unit): correct the "
                 "row or cut out the stretch")  # fmt: skip
    raise OdometerLogError(
        f"{label}, line {line(i)}: dist_m changes by {step_m[k]:+.4g} m in {dt_s[k]:.3f} s, but "
        f"speed_mps x dt is {expected:.3f} m (speeds {speed_mps[k]:g} and {speed_mps[i]:g} m/s; "
        f"tolerance {STEP_TOLERANCE_M:g} m + {100 * STEP_TOLERANCE_REL:g} %); likely {cause}"
    )
