"""Cant and the vehicle's attitude on a curve: what a side camera's horizon rolls with.

On a curve the outer rail is raised (the cant, in millimetres over the rail-head centres,
1500 mm apart on standard gauge) and the vehicle body leans toward the inside: by the cant's
angle, plus a little more on its springs when it runs slower than the curve's equilibrium
speed (cant excess), a little less when faster (cant deficiency). A camera on the body rolls
with it; its skyline reads low on one side and high on the other by about that angle
(``docs/reconstruction.md``, section 16).

* :func:`equilibrium_cant_mm` - the cant that balances a speed on a curve (EN 13803).
* :func:`cant_angle_deg` - the roll angle of a cant.
* :func:`inside_roll_sign` - which way "toward the inside" rolls the vehicle.
* :func:`body_roll_deg` - the roll of a body on a curve of known cant at a speed (the synthetic
  world's vehicle, :mod:`predisat.synth.generate`).
* :func:`roll_bounds_deg` - the vehicle's roll when neither the cant nor an IMU is known: the
  interval every vehicle on the line lies in, from the curvature alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "RAIL_CENTRES_MM",
    "CantLimits",
    "body_roll_deg",
    "cant_angle_deg",
    "equilibrium_cant_mm",
    "inside_roll_sign",
    "roll_bounds_deg",
]

RAIL_CENTRES_MM = 1500.0
"""Distance between the rail-head centres of standard gauge (1435 mm), over which cant is
measured."""

_EQUILIBRIUM_MM = 11.8  # D_eq = 11.8 V^2 / R (mm, km/h, m) on standard gauge, EN 13803


def equilibrium_cant_mm(curvature_per_m: ArrayLike, speed_kmh: ArrayLike) -> NDArray:
    """Cant that balances the centrifugal acceleration at a speed, millimetres.

    Parameters
    ----------
    curvature_per_m : array_like, shape (...)
        Horizontal curvature, 1/m (sign ignored).
    speed_kmh : array_like, broadcastable
        Speed, km/h.

    Returns
    -------
    ndarray, shape (...)
        ``11.8 V^2 / R`` (EN 13803 for standard gauge), >= 0.
    """
    k = np.abs(np.asarray(curvature_per_m, float))
    v = np.asarray(speed_kmh, float)
    return _EQUILIBRIUM_MM * v * v * k


def cant_angle_deg(cant_mm: ArrayLike) -> NDArray:
    """Roll angle of a cant, degrees (``asin(cant / 1500 mm)``, signed like the cant)."""
    c = np.asarray(cant_mm, float)
    return np.degrees(np.arcsin(np.clip(c / RAIL_CENTRES_MM, -1.0, 1.0)))


def inside_roll_sign(curvature_per_m: ArrayLike, reverse: ArrayLike = False) -> NDArray:
    """Sign of the vehicle roll (positive raises its left side) that leans it toward the
    inside of the curve: -1 on a curve turning left in the direction of travel, +1 turning
    right, 0 on straight track.

    Parameters
    ----------
    curvature_per_m : array_like, shape (...)
        Signed curvature of the track, positive turning left toward increasing chainage
        (:meth:`predisat.track.TrackMap.curvature_at`).
    reverse : bool or array_like of bool
        The vehicle drives toward decreasing chainage (a left turn becomes a right one).
    """
    k = np.asarray(curvature_per_m, float)
    turn_left = np.where(np.asarray(reverse, bool), -k, k)
    return -np.sign(turn_left)


def body_roll_deg(
    curvature_per_m: ArrayLike,
    cant_mm: ArrayLike,
    speed_kmh: ArrayLike,
    flexibility: float = 0.25,
    reverse: bool = False,
) -> NDArray:
    """Vehicle roll on a canted curve, degrees, positive raising the vehicle's left side.

    The body leans in by the cant's angle, plus ``flexibility`` times the uncompensated part
    (cant minus the speed's equilibrium cant: positive, further in, when slower).

    Parameters
    ----------
    curvature_per_m : array_like, shape (...)
        Signed curvature, positive turning left toward increasing chainage.
    cant_mm : array_like, broadcastable
        The curve's cant (>= 0).
    speed_kmh : array_like, broadcastable
    flexibility : float
        The UIC flexibility coefficient ``s`` (0.25: a typical passenger coach).
    reverse : bool
        The vehicle drives toward decreasing chainage.
    """
    k = np.asarray(curvature_per_m, float)
    cant = cant_angle_deg(cant_mm)
    uncompensated = cant - cant_angle_deg(equilibrium_cant_mm(k, speed_kmh))
    return inside_roll_sign(k, reverse) * (cant + flexibility * uncompensated)


@dataclass(frozen=True)
class CantLimits:
    """What bounds a vehicle's roll on a line whose cant is not known (standard gauge).

    Attributes
    ----------
    line_speed_kmh : float
        The fastest any train runs the line. Design cant never exceeds the equilibrium cant of
        that speed (a cant above it would be all excess for every train), so it bounds the
        cant of each curve from its curvature.
    max_cant_mm : float
        The largest cant on the line: EN 13803 allows 180 mm on ballasted standard-gauge track
        (160 mm is the usual limit).
    flexibility : float
        The body's extra roll on its springs per unit of uncompensated cant angle (the UIC's
        flexibility coefficient ``s``, 0.1 to 0.4 for passenger vehicles; the upper end): at a
        standstill on a canted curve the body leans ``s`` times the cant further in, at speed
        with cant deficiency ``s`` times the deficiency out.
    max_deficiency_mm : float
        The largest cant deficiency trains run with (EN 13803: 150 mm for conventional
        vehicles).
    track_roll_deg : float
        Roll from track twist, rail wear and the suspension's play, on straight track too.
    """

    line_speed_kmh: float = 160.0
    max_cant_mm: float = 180.0
    flexibility: float = 0.4
    max_deficiency_mm: float = 150.0
    track_roll_deg: float = 0.5

    def __post_init__(self) -> None:
        for name in ("line_speed_kmh", "max_cant_mm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"CantLimits.{name} must be > 0, got {getattr(self, name)}")
        for name in ("flexibility", "max_deficiency_mm", "track_roll_deg"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"CantLimits.{name} must be >= 0, got {getattr(self, name)}")


def roll_bounds_deg(
    curvature_per_m: ArrayLike, limits: CantLimits | None = None
) -> tuple[NDArray, NDArray]:
    """Interval of the body roll toward the curve's inside when the cant is not known.

    Parameters
    ----------
    curvature_per_m : array_like, shape (...)
        Horizontal curvature at the vehicle, 1/m (sign ignored).
    limits : CantLimits, optional

    Returns
    -------
    lo_deg, hi_deg : ndarray, shape (...)
        Roll toward the inside, degrees (negative: leaning out). The cant lies in ``[0,
        min(max_cant, D_eq(line speed))]``; the body adds up to ``flexibility`` times the cant
        inward (a standstill) or times the deficiency outward (the line speed on the least
        cant), and ``track_roll_deg`` either way.
    """
    lim = limits or CantLimits()
    k = np.abs(np.asarray(curvature_per_m, float))
    d_eq = equilibrium_cant_mm(k, lim.line_speed_kmh)
    cant_hi = cant_angle_deg(np.minimum(d_eq, lim.max_cant_mm))
    deficiency = cant_angle_deg(np.minimum(d_eq, lim.max_deficiency_mm))
    lo = -lim.flexibility * deficiency - lim.track_roll_deg
    hi = cant_hi * (1.0 + lim.flexibility) + lim.track_roll_deg
    return lo, hi
