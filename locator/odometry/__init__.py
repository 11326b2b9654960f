"""Odometry: the ETCS odometer (wheel sensor, radar), its confidence interval and safe ends,
and its fusion with the satellite interval. See ``docs/odometry.md``.

* :mod:`locator.odometry.odometer` - sensor simulation (:func:`simulate_odometer`);
* :mod:`locator.odometry.confidence` - ``D_DOUBTOVER`` / ``D_DOUBTUNDER``, safe front and rear
  ends, references, expectation windows (:func:`safe_fronts`);
* :mod:`locator.odometry.fusion` - odometry interval and satellite claims
  (:func:`fuse_intervals`, :func:`predict_interval`);
* :mod:`locator.odometry.logfile` - odometer logs on disk, validated.
"""

from locator.odometry.confidence import (
    BalisePassage,
    OdometerAccuracy,
    SafeFronts,
    in_expectation_window,
    safe_fronts,
)
from locator.odometry.fusion import (
    Fused,
    FusionStatus,
    fuse_intervals,
    motion_bound,
    predict_interval,
)
from locator.odometry.logfile import OdometerLogError, read_odometer_log, write_odometer_log
from locator.odometry.odometer import (
    OdometerConfig,
    OdometerLog,
    RadarConfig,
    decode_quadrature,
    quadrature_levels,
    simulate_odometer,
    true_distance_m,
)

__all__ = [
    "BalisePassage",
    "Fused",
    "FusionStatus",
    "OdometerAccuracy",
    "OdometerConfig",
    "OdometerLog",
    "OdometerLogError",
    "RadarConfig",
    "SafeFronts",
    "decode_quadrature",
    "fuse_intervals",
    "in_expectation_window",
    "motion_bound",
    "predict_interval",
    "quadrature_levels",
    "read_odometer_log",
    "safe_fronts",
    "simulate_odometer",
    "true_distance_m",
    "write_odometer_log",
]
