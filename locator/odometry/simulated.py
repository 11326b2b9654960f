"""An odometer simulated along a simulated train run (:class:`locator.sim.simfile.SimRun`).

The run's true chainage and speed at its epochs are interpolated onto the odometer's cycle grid
by a cubic Hermite spline (position and its derivative, the speed, at every epoch: exact for
constant speed and constant acceleration between epochs); the odometer
(:func:`locator.odometry.odometer.simulate_odometer`) reads that motion, and its distance is
sampled back at the receiver's epochs, signed toward increasing chainage as the epoch loop
(:func:`locator.run.run_locator`) wants it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicHermiteSpline

from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.logfile import OdometerLogError
from locator.odometry.odometer import OdometerConfig, OdometerLog, RadarFault, simulate_odometer
from locator.sim.simfile import SimRun
from predisat.gnss.timescale import gps_minus_utc_s
from predisat.readonly import freeze_array_fields

__all__ = ["SimOdometer", "check_log_against_run", "odometer_along_run", "odometer_from_log"]


@dataclass(frozen=True)
class SimOdometer:
    """A simulated odometer and the truth it was simulated from.

    Attributes
    ----------
    log : OdometerLog
        On the cycle grid; distances along the train's forward axis (= direction of travel).
    orientation : int
        +1 when the train runs toward increasing chainage.
    epoch_odo_m : ndarray, shape (n_epoch,)
        Odometer distance at the run's epochs, signed toward increasing chainage, m.
    truth_t_s, truth_chainage_m : ndarray, shape (n_cycle,)
        True antenna chainage on the cycle grid (GPS seconds, m).
    epoch_extra_m : ndarray, shape (n_epoch, 2)
        The odometer's disputed distance since the first epoch, toward lower and toward higher
        chainage, m (:class:`OdometerLog`'s ``extra_behind_m`` / ``extra_ahead_m``).
    """

    log: OdometerLog
    orientation: int
    epoch_odo_m: NDArray
    truth_t_s: NDArray
    truth_chainage_m: NDArray
    epoch_extra_m: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)


def _epoch_extra(log: OdometerLog, t_s: NDArray, orientation: int) -> NDArray:
    """The log's disputed distance at the epochs since the first, in the chainage frame."""
    ahead, behind = log.extra_at(t_s)
    lower, higher = (behind, ahead) if orientation > 0 else (ahead, behind)
    return np.column_stack([lower - lower[0], higher - higher[0]])


# a log running backward by more than this while the train moved forward as much is refused
_DIRECTION_CHECK_M = 1.0
# GPS seconds before this (1983) are no time of a recorded run: relative times
_EARLIEST_GPS_S = 1e8


def _coverage_hint(log_t_s: NDArray, run_t_s: NDArray) -> str:
    """What to do about a log whose times do not cover the run's."""
    if log_t_s[0] < _EARLIEST_GPS_S:
        return (f"its times look relative (seconds since the log started), not GPS seconds: add "
                f"the GPS time of its first row (e.g. {run_t_s[0]:.1f} if it started with the "
                "run) to t_s")  # fmt: skip
    shift = float(log_t_s[0] - run_t_s[0])
    days = shift / 86400.0
    if abs(days) >= 0.5 and abs(days - round(days)) < 0.01:
        return (f"it starts {abs(round(days))} day(s) {'after' if days > 0 else 'before'} the "
                "run: give the log of the run's day (or correct its date)")  # fmt: skip
    if 10.0 <= abs(shift) <= 20.0:
        leap = float(gps_minus_utc_s(run_t_s[0]))  # the run's date's, not today's 18 s
        return (f"it is offset by about the GPS-UTC leap seconds: give its times in GPS seconds "
                f"(GPS = UTC + {leap:.0f} s on the run's date)")  # fmt: skip
    if log_t_s[0] <= run_t_s[0] + 1e-6:
        return (f"it ends {_seconds(run_t_s[-1] - log_t_s[-1])} s before the run: give the whole "
                "recording")  # fmt: skip
    if log_t_s[-1] >= run_t_s[-1] - 1e-6:
        return (f"it starts {_seconds(log_t_s[0] - run_t_s[0])} s after the run: give the whole "
                "recording")  # fmt: skip
    return "give the log recorded with the run, covering every epoch"


def _seconds(dt_s: float) -> str:
    """``"10.0"``, and a few significant digits below a tenth (a user trial read "ends 0.0 s
    before the run" for a log 32 microseconds short)."""
    return f"{dt_s:.1f}" if abs(dt_s) >= 0.05 else f"{dt_s:.2g}"


def _truth_grid(sim: SimRun, cycle_s: float) -> tuple[int, NDArray, NDArray]:
    """Orientation, cycle times (s since the first epoch) and true distance along the travel."""
    t = np.asarray(sim.gps_s, float)
    if len(t) < 2:
        raise ValueError("the simulated run needs at least two epochs for an odometer")
    o = int(sim.meta.get("direction", 1))
    if o not in (1, -1):
        raise ValueError(f"the run's meta direction must be +1 or -1, got {o}")
    ratio = (t[1] - t[0]) / cycle_s
    if abs(ratio - round(ratio)) > 1e-6:
        raise ValueError(
            f"the run's epochs ({t[1] - t[0]:g} s apart) are not a multiple of the odometer "
            f"cycle ({cycle_s:g} s); choose cycle_s dividing the epoch interval, or simulate "
            f"the run at a receiver rate whose epoch interval is a multiple of {cycle_s:g} s "
            f"(with the ETCS-like 0.1 s cycle of `locator balises`: 1, 2, 5 or 10 Hz, not 4 "
            "or 20 Hz)"
        )
    dist = o * (np.asarray(sim.chainage_m, float) - float(sim.chainage_m[0]))
    spline = CubicHermiteSpline(t - t[0], dist, np.asarray(sim.speed_mps, float))
    n = round((t[-1] - t[0]) / cycle_s) + 1
    tc = np.arange(n) * cycle_s
    true_d = np.asarray(spline(tc), float)
    # the simulator's trains run one way; the spline may wobble back a little at a stop,
    # but a run that goes back (a reversal built by hand) must not be clamped to a standstill
    back = float((np.maximum.accumulate(true_d) - true_d).max())
    if back > 1.0:  # a reversal; not the spline's wobble at a stop
        raise ValueError(
            f"the run goes back {back:.2f} m against its direction ({o:+d}): the simulated "
            "odometer follows runs in one direction; split the run at its reversals"
        )
    return o, tc, np.maximum.accumulate(true_d)


def check_log_against_run(sim: SimRun, log: OdometerLog, accuracy: OdometerAccuracy) -> None:
    """Refuse a log whose distance leaves its stated accuracy over the run it is paired with.

    The confidence interval bounds the true displacement from the logged one
    (:meth:`~locator.odometry.confidence.OdometerAccuracy.displacement_bounds_m`, the bounds
    ``--odometer-accuracy`` states) **from its anchor**, and every epoch may be one (the run
    loop re-anchors each bound where the satellites tighten it): the bounds must hold between
    every two epochs (:meth:`~locator.odometry.confidence.OdometerAccuracy.anchor_excess_m`),
    not only since the first. A log further off than that (a log in feet, scaled, shifted in
    time, or standing still) puts the train outside its own safe fronts: a user trial measured
    18-30 of 41 epochs with the true front outside, with no error. Checked from the first
    epoch only, a 4 % over-read for 20 s against 1 m + 2 % passed once the run was long
    enough (a user trial, 2026-12-07).

    Raises
    ------
    OdometerLogError
        Naming the worst pair of epochs (times, epoch numbers), the two distances, the bounds,
        the first epoch out of bounds and the likely cause (the whole log, or a stretch).
    """
    t = np.asarray(sim.gps_s, float)
    name = log.source or "the odometer log"
    _, tc, true_d = _truth_grid(sim, _cycle_of(t))
    run_m = np.interp(t - t[0], tc, true_d)
    d = log.at(t)
    logged_m = d - d[0]
    ahead, behind = log.extra_at(t)
    ahead, behind = ahead - ahead[0], behind - behind[0]
    excess, anchor = accuracy.anchor_excess_m(run_m, logged_m, ahead, behind)
    bad = np.flatnonzero(excess > 1e-9)
    if bad.size == 0:
        return
    k = int(np.argmax(excess))  # the worst pair: its ratio says the most about the cause
    i = int(anchor[k])
    pair = slice(i, k + 1)
    logged, moved = logged_m[pair] - logged_m[i], run_m[pair] - run_m[i]
    ran = (np.concatenate([[0.0], np.cumsum(np.abs(np.diff(logged)))])
           + ahead[pair] - ahead[i] + behind[pair] - behind[i])  # fmt: skip
    lo, hi = accuracy.displacement_bounds_m(logged[-1:], ran[-1:])
    lo, hi = lo[0] - (behind[k] - behind[i]), hi[0] + (ahead[k] - ahead[i])
    ratio = float(logged[-1] / moved[-1]) if moved[-1] > 1.0 else float("nan")
    since = "the run's first epoch" if i == 0 else f"t_s {t[i]:.1f} (epoch {i})"
    # out of bounds from the first epoch too: the whole log is off (unit, times, scale);
    # otherwise a stretch of it
    ran0 = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(logged_m)))]) + ahead + behind
    lo0, hi0 = accuracy.displacement_bounds_m(logged_m, ran0)
    whole = bool(np.any((run_m < lo0 - behind - 1e-9) | (run_m > hi0 + ahead + 1e-9)))
    fix = (
        "check the log's unit, its times (GPS seconds of the run) and its scale, or state its "
        "accuracy (--odometer-accuracy)"
        if whole
        else "within the bounds from the run's first epoch, the log is off over a stretch: an "
        "unmarked slip or slide (mark it in the slip column and give the disputed distance, "
        "extra_ahead_m / extra_behind_m), a corrupt stretch (cut it out), or bounds too tight "
        "for the odometer (state its accuracy: --odometer-accuracy)"
    )
    f = int(bad[0])
    raise OdometerLogError(
        f"{name}: at t_s {t[k]:.1f} (epoch {k}) its dist_m has run {logged[-1]:.1f} m since "
        f"{since}, the train {moved[-1]:.1f} m: outside the odometer's bounds for that reading "
        f"({lo:.1f}-{hi:.1f} m, by {excess[k]:.1f} m), so safe fronts anchored there would not "
        f"hold the train ({bad.size} of {t.size} epochs out of bounds from an earlier one, the "
        f"first at t_s {t[f]:.1f} from t_s {t[anchor[f]]:.1f}){_scale_hint(ratio)}; {fix}"
    )


def _cycle_of(t: NDArray) -> float:
    """A cycle dividing the run's epoch interval (the truth grid's step)."""
    return float(t[1] - t[0]) / max(round(float(t[1] - t[0]) / 0.1), 1)


def _scale_hint(ratio: float) -> str:
    """What a distance ratio log/run between the two epochs of the message suggests."""
    if not np.isfinite(ratio):
        return ""
    if abs(ratio) < 1e-4:
        return (" (no movement logged between them: a log of another run, or a stuck "
                "sensor?)")  # fmt: skip
    for factor, what in ((3.28084, "feet"), (1e-3, "kilometres"), (1e3, "millimetres")):
        if abs(ratio - factor) < 0.05 * factor:
            return f" (between them {ratio:.3g} times the train's distance: {what}?)"
    return f" (between them {ratio:.3g} times the train's distance)"


def odometer_along_run(
    sim: SimRun, config: OdometerConfig, seed: int = 0, radar_fault: RadarFault | None = None
) -> SimOdometer:
    """Simulate the odometer of a simulated run.

    Parameters
    ----------
    sim : SimRun
        Needs at least two epochs; its epochs must be multiples of ``config.cycle_s`` apart.
    config : OdometerConfig
    seed : int
    radar_fault : RadarFault, optional
        A radar failure to inject (:func:`simulate_odometer`).

    Returns
    -------
    SimOdometer
    """
    t0 = float(sim.gps_s[0])
    o, tc, true_d = _truth_grid(sim, config.cycle_s)
    log = simulate_odometer(t0 + tc, true_d, config, seed, radar_fault)
    epoch_odo = o * np.interp(sim.gps_s, log.t_s, log.dist_m)
    return SimOdometer(log, o, epoch_odo, t0 + tc, float(sim.chainage_m[0]) + o * true_d,
                       _epoch_extra(log, np.asarray(sim.gps_s, float), o))  # fmt: skip


def odometer_from_log(
    sim: SimRun,
    log: OdometerLog,
    cycle_s: float = 0.1,
    accuracy: OdometerAccuracy | None = None,
) -> SimOdometer:
    """A recorded (or separately simulated) odometer log for a simulated run.

    The log's times are the run's GPS seconds and its distance runs along the train's forward
    axis, which points in the run's direction of travel; it must cover every epoch of the run.
    The truth is the run's, on a ``cycle_s`` grid.

    Raises
    ------
    OdometerLogError
        The log does not cover the run (with a hint when its times look relative or off by a
        day or by the leap seconds), or its distance runs backward over a run that moves
        forward (more than 1 m each way).
    """
    t = np.asarray(sim.gps_s, float)
    name = log.source or "the odometer log"
    if log.t_s[0] > t[0] + 1e-6 or log.t_s[-1] < t[-1] - 1e-6:
        raise OdometerLogError(
            f"{name}: its t_s cover {log.t_s[0]:.6f}-{log.t_s[-1]:.6f} s but the run "
            f"{t[0]:.6f}-{t[-1]:.6f} s (GPS seconds); {_coverage_hint(log.t_s, t)}"
        )
    o, tc, true_d = _truth_grid(sim, cycle_s)
    d = log.at(t)
    moved_m, logged_m = float(true_d[-1]), float(d[-1] - d[0])
    if moved_m > _DIRECTION_CHECK_M and logged_m < -_DIRECTION_CHECK_M:
        raise OdometerLogError(
            f"{name}: over the run its dist_m runs backward ({logged_m:+.1f} m, direction -1) "
            f"while the train travels {moved_m:.1f} m forward: the log's forward axis must point "
            "in the direction of travel; if it was recorded from the other cab (or with the "
            "other sign convention), negate dist_m and direction"
        )
    if accuracy is not None:  # after the coverage and direction checks: their hints first
        check_log_against_run(sim, log, accuracy)
    epoch_odo = o * (d - d[0])
    return SimOdometer(log, o, epoch_odo, t[0] + tc, float(sim.chainage_m[0]) + o * true_d,
                       _epoch_extra(log, t, o))  # fmt: skip
