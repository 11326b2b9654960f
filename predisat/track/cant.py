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
* :func:`roll_bounds_deg` - the vehicle's roll when no IMU measured it: the interval every
  vehicle on the line lies in, from the curvature alone, or from the cant of a
  :class:`CantTable` (the infrastructure's own records) and the survey's speed.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "RAIL_CENTRES_MM",
    "CantLimits",
    "CantTable",
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
        The highest speed the line's curves were canted for: a design cant does not exceed
        that speed's equilibrium cant (it would be all excess for every train), so it bounds
        each curve's cant from its curvature. A line slowed since keeps its cant, so give the
        speed it was built for; the default, 200 km/h, is above any conventional line's.
    max_cant_mm : float
        The largest cant on the line: EN 13803 allows 180 mm on ballasted standard-gauge track
        (160 mm is the usual limit).
    flexibility : float
        The body's extra roll on its springs per unit of uncompensated cant angle (the UIC's
        flexibility coefficient ``s``, 0.1 to 0.4 for passenger vehicles; the upper end): at a
        standstill on a canted curve the body leans ``s`` times the cant further in, at speed
        with cant deficiency ``s`` times the deficiency out. A tilting vehicle's active tilt is
        not bounded here: survey with it tilt locked, or give its measured roll.
    max_deficiency_mm : float
        The largest cant deficiency trains run with (EN 13803: 150 mm for conventional
        vehicles).
    track_roll_deg : float
        Roll from track twist, rail wear and the suspension's play, on straight track too.
    top_speed_kmh : float
        The fastest the survey vehicle may run where its speed is not known (the pipeline
        knows it from the frames' times): with the deficiency limit, it bounds the body's lean
        outward.
    """

    line_speed_kmh: float = 200.0
    max_cant_mm: float = 180.0
    flexibility: float = 0.4
    max_deficiency_mm: float = 150.0
    track_roll_deg: float = 0.5
    top_speed_kmh: float = 250.0

    def __post_init__(self) -> None:
        for name in ("line_speed_kmh", "max_cant_mm", "top_speed_kmh"):
            if not getattr(self, name) > 0:
                raise ValueError(f"CantLimits.{name} must be > 0, got {getattr(self, name)}")
        for name in ("flexibility", "max_deficiency_mm", "track_roll_deg"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"CantLimits.{name} must be >= 0, got {getattr(self, name)}")
        # a unit slip narrows the roll's bound below the true cant: refused (a user trial's
        # --max-cant-mm 0.18, metres, cut the doubt from 7.6 to 3.1 deg)
        for name, lo, hi, hint in _PLAUSIBLE:
            v = float(getattr(self, name))
            if not lo <= v <= hi:
                raise ValueError(f"CantLimits.{name} {v:g} is outside [{lo:g}, {hi:g}]: {hint}")


_PLAUSIBLE = (
    ("max_cant_mm", 20.0, 250.0, "a line's largest cant in millimetres (EN 13803: 180; 0.18 "
     "is metres)"),
    ("line_speed_kmh", 5.0, 400.0, "a speed in km/h (m/s? multiply by 3.6)"),
    ("top_speed_kmh", 5.0, 500.0, "a speed in km/h (m/s? multiply by 3.6)"),
    ("max_deficiency_mm", 0.0, 400.0, "millimetres of cant deficiency (EN 13803: 150; tilting "
     "trains up to 300)"),
    ("flexibility", 0.0, 1.0, "the UIC flexibility coefficient, 0.1-0.4"),
    ("track_roll_deg", 0.0, 5.0, "degrees of roll from the track's twist and the suspension"),
)  # fmt: skip


def roll_bounds_deg(
    curvature_per_m: ArrayLike,
    limits: CantLimits | None = None,
    cant_mm: ArrayLike | None = None,
    speed_kmh: ArrayLike | None = None,
) -> tuple[NDArray, NDArray]:
    """Interval of the body roll toward the curve's inside when no IMU measured it.

    Parameters
    ----------
    curvature_per_m : array_like, shape (...)
        Horizontal curvature at the vehicle, 1/m (sign ignored).
    limits : CantLimits, optional
    cant_mm : array_like, broadcastable, optional
        The cant where it is known (a :class:`CantTable`), NaN where not.
    speed_kmh : array_like, broadcastable, optional
        The survey vehicle's speed where known (from the frames' times), NaN where not.

    Returns
    -------
    lo_deg, hi_deg : ndarray, shape (...)
        Roll toward the inside, degrees (negative: leaning out), ``track_roll_deg`` either
        way included. Unknown cant: it lies in ``[0, min(max_cant, D_eq(line speed))]``.
        The body adds ``s`` times the uncompensated cant (cant minus the equilibrium cant of
        its speed), ``s`` in ``[0, flexibility]``: with the speed known that is one signed
        amount; unknown, anything from the deficiency at ``top_speed_kmh`` (at most
        ``max_deficiency_mm``) outward to the cant inward.
    """
    lim = limits or CantLimits()
    k = np.abs(np.asarray(curvature_per_m, float))
    d_eq = equilibrium_cant_mm(k, lim.line_speed_kmh)
    c_lo = np.zeros_like(k)
    c_hi = np.minimum(d_eq, lim.max_cant_mm)
    if cant_mm is not None:
        known = np.broadcast_to(np.asarray(cant_mm, float), k.shape)
        c_lo = np.where(np.isfinite(known), known, c_lo)
        c_hi = np.where(np.isfinite(known), known, c_hi)
    th_lo, th_hi = cant_angle_deg(c_lo), cant_angle_deg(c_hi)
    s = lim.flexibility
    # speed unknown: from the deficiency limit outward (a train may run faster than the curve
    # was canted for) to the cant inward; in angles, as the body leans by them
    d_top = equilibrium_cant_mm(k, lim.top_speed_kmh)
    out = cant_angle_deg(np.clip(d_top, c_lo, c_lo + lim.max_deficiency_mm)) - th_lo
    extra_lo, extra_hi = -s * out, s * th_hi
    if speed_kmh is not None:
        v = np.broadcast_to(np.asarray(speed_kmh, float), k.shape)
        th_eq = cant_angle_deg(equilibrium_cant_mm(k, np.where(np.isfinite(v), v, 0.0)))
        # s * (cant - eq) over s in [0, flexibility] and the cant in [c_lo, c_hi]
        u_lo, u_hi = th_lo - th_eq, th_hi - th_eq
        extra_lo = np.where(np.isfinite(v), np.minimum(0.0, s * u_lo), extra_lo)
        extra_hi = np.where(np.isfinite(v), np.maximum(0.0, s * u_hi), extra_hi)
    return th_lo + extra_lo - lim.track_roll_deg, th_hi + extra_hi + lim.track_roll_deg


_MAX_TABLE_CANT_MM = 250.0  # beyond any standard-gauge limit: a unit or column mistake


@dataclass(frozen=True, eq=False)
class CantTable:
    """The cant along a track, from the infrastructure's records: linear between rows.

    Attributes
    ----------
    chainage_m : ndarray, shape (n,)
        Strictly increasing chainage of the rows, metres (the track map's chainage).
    cant_mm : ndarray, shape (n,)
        Cant there, millimetres, >= 0 (which rail is raised follows from the curve: the
        outer one).
    source : str
        Where it was read from.
    """

    chainage_m: NDArray
    cant_mm: NDArray
    source: str = field(default="")

    def __post_init__(self) -> None:
        s = np.array(self.chainage_m, float)
        c = np.array(self.cant_mm, float)
        where = f"cant table {self.source}" if self.source else "cant table"
        if s.ndim != 1 or s.shape != c.shape or s.size < 2:
            raise ValueError(
                f"{where}: needs at least two rows of chainage_m and cant_mm (the cant at "
                "the ends of each curve and transition at least)"
            )
        if not (np.all(np.isfinite(s)) and np.all(np.diff(s) > 0)):
            raise ValueError(
                f"{where}: chainage_m must be finite and strictly increasing; sort the rows by "
                "chainage and drop repeated ones"
            )
        if not (np.all(np.isfinite(c)) and np.all((c >= 0) & (c <= _MAX_TABLE_CANT_MM))):
            raise ValueError(f"{where}: cant_mm must lie in [0, {_MAX_TABLE_CANT_MM:g}] mm (the "
                             "cant's size; the raised rail follows from the curve)")  # fmt: skip
        for a in (s, c):
            a.setflags(write=False)
        object.__setattr__(self, "chainage_m", s)
        object.__setattr__(self, "cant_mm", c)

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str]) -> CantTable:
        """Read a CSV with a header naming ``chainage_m`` and ``cant_mm`` (other columns
        ignored; lines starting with ``#`` skipped). Errors name the file, line and fix."""
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"cant table {p}: cannot be read ({exc}); give a UTF-8 CSV") from None
        numbered = [
            (n, row)
            for n, ln in enumerate(text.replace("\r\n", "\n").split("\n"), start=1)
            if ln.strip() and not ln.lstrip().startswith("#")
            for row in csv.reader([ln])
        ]
        header = [h.strip() for h in numbered[0][1]] if numbered else []
        if "chainage_m" not in header or "cant_mm" not in header:
            raise ValueError(
                f"cant table {p}: the header must name chainage_m and cant_mm, separated by "
                f"commas (got {header})"
            )
        i_s, i_c = header.index("chainage_m"), header.index("cant_mm")
        s_m: list[float] = []
        c_mm: list[float] = []
        for n, row in numbered[1:]:
            try:
                s_v, c_v = float(row[i_s]), float(row[i_c])
            except (IndexError, ValueError):
                raise ValueError(
                    f"cant table {p}, line {n}: {','.join(row)!r} needs numbers in "
                    "chainage_m and cant_mm"
                ) from None
            if not (math.isfinite(s_v) and math.isfinite(c_v)):
                raise ValueError(
                    f"cant table {p}, line {n}: chainage_m and cant_mm must be finite numbers, "
                    f"got {s_v!r} and {c_v!r}"
                )
            if s_m and s_v <= s_m[-1]:
                raise ValueError(
                    f"cant table {p}, line {n}: chainage_m {s_v:g} does not increase "
                    f"(previous {s_m[-1]:g}); sort the rows by chainage"
                )
            if 0.0 < c_v < 1.0:
                raise ValueError(
                    f"cant table {p}, line {n}: cant_mm {c_v:g} reads as metres; give the cant "
                    f"in millimetres ({1000 * c_v:g})"
                )
            if not 0.0 <= c_v <= _MAX_TABLE_CANT_MM:
                raise ValueError(
                    f"cant table {p}, line {n}: cant_mm {c_v:g} is not within [0, "
                    f"{_MAX_TABLE_CANT_MM:g}]; give the cant's size in millimetres (the raised "
                    "rail follows from the curve)"
                )
            s_m.append(s_v)
            c_mm.append(c_v)
        return cls(np.array(s_m), np.array(c_mm), str(p))

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write the table as read by :meth:`from_csv` (17 significant digits)."""
        rows = "".join(f"{s!r},{c!r}\n" for s, c in zip(self.chainage_m.tolist(),
                                                        self.cant_mm.tolist(), strict=True))
        Path(path).write_text("chainage_m,cant_mm\n" + rows, encoding="utf-8")

    def cant_mm_at(self, chainage_m: ArrayLike) -> NDArray:
        """Cant at chainages, mm, linear between rows; NaN outside the table."""
        s = np.asarray(chainage_m, float)
        out = np.interp(s, self.chainage_m, self.cant_mm)
        return np.where((s >= self.chainage_m[0]) & (s <= self.chainage_m[-1]), out, np.nan)
