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

__all__ = ["SimOdometer", "odometer_along_run"]


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
    t = np.asarray(sim.gps_s, float)
    if len(t) < 2:
        raise ValueError("the simulated run needs at least two epochs for an odometer")
    o = int(sim.meta.get("direction", 1))
    if o not in (1, -1):
        raise ValueError(f"the run's meta direction must be +1 or -1, got {o}")
    ratio = (t[1] - t[0]) / config.cycle_s
    if abs(ratio - round(ratio)) > 1e-6:
        raise ValueError(
            f"the run's epochs ({t[1] - t[0]:g} s apart) are not a multiple of the odometer "
            f"cycle ({config.cycle_s:g} s); choose cycle_s dividing the epoch interval"
        )
    dist = o * (np.asarray(sim.chainage_m, float) - float(sim.chainage_m[0]))
    spline = CubicHermiteSpline(t - t[0], dist, np.asarray(sim.speed_mps, float))
    n = round((t[-1] - t[0]) / config.cycle_s) + 1
    tc = np.arange(n) * config.cycle_s
    true_d = np.asarray(spline(tc), float)
    true_d = np.maximum.accumulate(true_d)  # the train never runs backward in a simulated run
    log = simulate_odometer(t[0] + tc, true_d, config, seed)
    epoch_odo = o * np.interp(t, log.t_s, log.dist_m)
    return SimOdometer(log, o, epoch_odo, t[0] + tc, float(sim.chainage_m[0]) + o * true_d)
