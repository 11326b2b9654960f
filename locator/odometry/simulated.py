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

from locator.odometry.odometer import OdometerConfig, OdometerLog, simulate_odometer
from locator.sim.simfile import SimRun

__all__ = ["SimOdometer", "odometer_along_run", "odometer_from_log"]


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
    """

    log: OdometerLog
    orientation: int
    epoch_odo_m: NDArray
    truth_t_s: NDArray
    truth_chainage_m: NDArray


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
            f"cycle ({cycle_s:g} s); choose cycle_s dividing the epoch interval"
        )
    dist = o * (np.asarray(sim.chainage_m, float) - float(sim.chainage_m[0]))
    spline = CubicHermiteSpline(t - t[0], dist, np.asarray(sim.speed_mps, float))
    n = round((t[-1] - t[0]) / cycle_s) + 1
    tc = np.arange(n) * cycle_s
    true_d = np.asarray(spline(tc), float)
    return o, tc, np.maximum.accumulate(true_d)  # a simulated train never runs backward


def odometer_along_run(sim: SimRun, config: OdometerConfig, seed: int = 0) -> SimOdometer:
    """Simulate the odometer of a simulated run.

    Parameters
    ----------
    sim : SimRun
        Needs at least two epochs; its epochs must be multiples of ``config.cycle_s`` apart.
    config : OdometerConfig
    seed : int

    Returns
    -------
    SimOdometer
    """
    t0 = float(sim.gps_s[0])
    o, tc, true_d = _truth_grid(sim, config.cycle_s)
    log = simulate_odometer(t0 + tc, true_d, config, seed)
    epoch_odo = o * np.interp(sim.gps_s, log.t_s, log.dist_m)
    return SimOdometer(log, o, epoch_odo, t0 + tc, float(sim.chainage_m[0]) + o * true_d)


def odometer_from_log(sim: SimRun, log: OdometerLog, cycle_s: float = 0.1) -> SimOdometer:
    """A recorded (or separately simulated) odometer log for a simulated run.

    The log's times are the run's GPS seconds and its distance runs along the train's forward
    axis, which points in the run's direction of travel; it must cover every epoch of the run.
    The truth is the run's, on a ``cycle_s`` grid.
    """
    t = np.asarray(sim.gps_s, float)
    if log.t_s[0] > t[0] + 1e-6 or log.t_s[-1] < t[-1] - 1e-6:
        raise ValueError(
            f"the odometer log covers {log.t_s[0]:.1f}-{log.t_s[-1]:.1f} s but the run "
            f"{t[0]:.1f}-{t[-1]:.1f} s; give the log recorded with the run"
        )
    o, tc, true_d = _truth_grid(sim, cycle_s)
    d = log.at(t)
    epoch_odo = o * (d - d[0])
    return SimOdometer(log, o, epoch_odo, t[0] + tc, float(sim.chainage_m[0]) + o * true_d)
