"""Train-run view: the satellites a train may trust along its way.

A train leaves chainage ``start_chainage_m`` at ``t0_gps_s`` and runs with a speed profile
(:class:`SpeedProfile`: a function of time, a (time, speed) table, or the line's speed limits
with acceleration and braking); every ``step_s`` the run gives its chainage, speed, the trusted
satellites (ephemeris OK and the :class:`~predisat.availability.satellites.TrustRule` at that
chainage), their
number and the predicted SATHIA interval (:mod:`predisat.availability.interval`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from predisat.availability.interval import (
    DEFAULT_MAP_DOUBT,
    MapDoubt,
    along_track_components,
    predicted_interval,
)
from predisat.availability.satellites import LinePositions, SatellitePositions, TrustRule, azel
from predisat.gnss.ephemeris import Ephemeris
from predisat.gnss.errormodel import IntervalModel
from predisat.gnss.integrity import DEFAULT_BUDGET, IntegrityBudget
from predisat.readonly import freeze_array_fields
from predisat.track import TrackMap

__all__ = ["SpeedProfile", "TrainRun", "trainrun"]


@dataclass(frozen=True)
class SpeedProfile:
    """Speed of a train as a function of time since departure or of distance run.

    Build with :meth:`constant`, :meth:`from_function`, :meth:`from_time_table` or
    :meth:`from_limits`. :meth:`distance_at` gives the distance run (>= 0) at times since
    departure.
    """

    kind: str
    func: Callable[[NDArray], NDArray] | None = None
    table_s: NDArray | None = None
    table_mps: NDArray | None = None
    grid_m: NDArray | None = None
    grid_t_s: NDArray | None = None

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @classmethod
    def constant(cls, speed_mps: float) -> SpeedProfile:
        if not speed_mps > 0:
            raise ValueError(f"speed_mps must be positive, got {speed_mps}")
        return cls.from_time_table([0.0, 1.0], [speed_mps, speed_mps])

    @classmethod
    def from_function(cls, speed_mps: Callable[[NDArray], ArrayLike]) -> SpeedProfile:
        """Speed (m/s, >= 0) as a vectorised function of time since departure (s)."""
        return cls("function", func=lambda t: np.asarray(speed_mps(t), float))

    @classmethod
    def from_time_table(cls, time_s: ArrayLike, speed_mps: ArrayLike) -> SpeedProfile:
        """Speeds at times since departure, linearly interpolated (held beyond the ends)."""
        t = np.asarray(time_s, float)
        v = np.asarray(speed_mps, float)
        if t.ndim != 1 or t.shape != v.shape or len(t) < 1:
            raise ValueError("time_s and speed_mps must be 1-D of one length")
        if np.any(np.diff(t) <= 0) or np.any(v < 0):
            raise ValueError("time_s must increase strictly and speed_mps be >= 0")
        return cls("table", table_s=t, table_mps=v)

    @classmethod
    def from_limits(
        cls,
        distance_m: ArrayLike,
        limit_mps: ArrayLike,
        accel_mps2: float = 0.5,
        decel_mps2: float = 0.7,
        v0_mps: float = 0.0,
        step_m: float = 1.0,
    ) -> SpeedProfile:
        """Fastest run under speed limits with bounded acceleration and braking.

        Parameters
        ----------
        distance_m, limit_mps : array_like, shape (n,)
            Limit in force from each distance run (step function; the first from 0).
        accel_mps2, decel_mps2 : float
            Largest acceleration and braking (the train brakes early to meet lower limits
            and stops at the end of the table's last entry when that limit is 0).
        v0_mps : float
            Speed at departure.
        """
        d = np.asarray(distance_m, float)
        lim = np.asarray(limit_mps, float)
        if d.ndim != 1 or d.shape != lim.shape or len(d) < 1 or d[0] != 0:
            raise ValueError("distance_m must be 1-D, start at 0, and match limit_mps")
        if np.any(np.diff(d) <= 0) or np.any(lim < 0) or accel_mps2 <= 0 or decel_mps2 <= 0:
            raise ValueError("distance_m must increase; limits >= 0; accel/decel > 0")
        end = d[-1] if lim[-1] == 0 else d[-1] + 1.0e5
        x = np.arange(0.0, end + step_m, step_m)
        vlim = lim[np.searchsorted(d, x, side="right") - 1]
        v = np.empty_like(x)
        v[0] = min(v0_mps, vlim[0])
        for i in range(1, len(x)):  # forward: acceleration
            v[i] = min(vlim[i], np.sqrt(v[i - 1] ** 2 + 2 * accel_mps2 * step_m))
        for i in range(len(x) - 2, -1, -1):  # backward: braking
            v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * decel_mps2 * step_m))
        v_mid = np.maximum((v[1:] + v[:-1]) / 2.0, 1e-9)
        t = np.concatenate([[0.0], np.cumsum(step_m / v_mid)])
        return cls("limits", grid_m=x, grid_t_s=t, table_mps=v)

    def distance_at(self, t_s: ArrayLike) -> NDArray:
        """Distance run at times since departure, metres, shape of ``t_s``."""
        t = np.asarray(t_s, float)
        if self.kind == "limits":
            assert self.grid_m is not None and self.grid_t_s is not None
            return np.interp(t, self.grid_t_s, self.grid_m)
        t_max = max(float(np.max(t, initial=0.0)), 1e-9)
        grid = np.linspace(0.0, t_max, int(min(max(t_max / 0.25, 2), 1e6)) + 1)
        v = self._speed_of_time(grid)
        dist = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2.0 * np.diff(grid))])
        return np.interp(t, grid, dist)

    def speed_at(self, t_s: ArrayLike) -> NDArray:
        """Speed at times since departure, m/s."""
        t = np.asarray(t_s, float)
        if self.kind == "limits":
            assert self.grid_t_s is not None and self.table_mps is not None
            return np.interp(t, self.grid_t_s, self.table_mps)
        return self._speed_of_time(t)

    def _speed_of_time(self, t: NDArray) -> NDArray:
        if self.kind == "function":
            assert self.func is not None
            v = np.broadcast_to(self.func(t), t.shape).astype(float)
            if np.any(v < 0) or not np.all(np.isfinite(v)):
                raise ValueError("speed function returned negative or non-finite speeds")
            return v
        assert self.table_s is not None and self.table_mps is not None
        return np.interp(t, self.table_s, self.table_mps)


@dataclass(frozen=True)
class TrainRun:
    """A train run, one row per step.

    Attributes
    ----------
    gps_s, chainage_m, speed_mps : ndarray, shape (n_step,)
    sats : tuple of str, length n_sat
    trusted : ndarray of bool, shape (n_step, n_sat)
    az_deg, el_deg : ndarray, shape (n_step, n_sat)
        NaN where the ephemeris does not trust the satellite.
    count : ndarray of int, shape (n_step,)
    interval_m : ndarray, shape (n_step,)
        Predicted SATHIA interval length (NaN with < 2 satellites).
    interval_mode : ndarray of uint8, shape (n_step,)
        :class:`~predisat.availability.interval.IntervalMode`.
    """

    gps_s: NDArray
    chainage_m: NDArray
    speed_mps: NDArray
    sats: tuple[str, ...]
    trusted: NDArray
    az_deg: NDArray
    el_deg: NDArray
    count: NDArray
    interval_m: NDArray
    interval_mode: NDArray

    def trusted_sats(self, step: int) -> list[str]:
        """Satellite ids trusted at one step."""
        return [s for s, ok in zip(self.sats, self.trusted[step], strict=True) if ok]

    def to_frame(self) -> pd.DataFrame:
        """One row per step; ``sats`` is a space-separated list of the trusted satellites."""
        return pd.DataFrame(
            {
                "gps_s": self.gps_s,
                "chainage_m": self.chainage_m,
                "speed_mps": self.speed_mps,
                "count": self.count,
                "interval_m": self.interval_m,
                "interval_mode": self.interval_mode,
                "sats": [" ".join(self.trusted_sats(i)) for i in range(len(self.gps_s))],
            }
        )


def trainrun(
    track: TrackMap,
    ephemeris: Ephemeris,
    rule: TrustRule,
    start_chainage_m: float,
    t0_gps_s: float,
    speed: SpeedProfile,
    *,
    step_s: float = 1.0,
    duration_s: float | None = None,
    direction: int = +1,
    constellation: str | Sequence[str] = "all",
    antenna_height_m: float = 0.0,
    interval_model: IntervalModel | None = None,
    integrity: IntegrityBudget | None = DEFAULT_BUDGET,
    map_doubt: MapDoubt | None = DEFAULT_MAP_DOUBT,
) -> TrainRun:
    """Run a train along a track and list the satellites it may trust at each step.

    Parameters
    ----------
    track : TrackMap
    ephemeris : Ephemeris
    rule : TrustRule
        Masks (looked up at the train's chainage), flat cut-off, or horizon.
    start_chainage_m, t0_gps_s : float
        Departure place and time.
    speed : SpeedProfile
    step_s : float
        Time step of the output.
    duration_s : float, optional
        Default: until the train reaches the end of the track (or the end of a speed-limit
        profile), at most 24 h.
    direction : {+1, -1}
        Towards increasing (+1) or decreasing (-1) chainage.
    constellation : str
    antenna_height_m : float
        Antenna height above the track axis (ignored when masks give the positions).
    interval_model : IntervalModel, optional
    integrity : IntegrityBudget or None
        Each interval mode's ``k`` follows from it and ``interval_model.k_sigma`` is not used;
        default :data:`predisat.gnss.integrity.DEFAULT_BUDGET`. None: ``interval_model.k_sigma``
        in every mode.
    map_doubt : MapDoubt or None
        Each predicted pair widened as the locator widens it (default its 1.5 m beside and 1
        m above or below the map); None: the source's pairs.

    Returns
    -------
    TrainRun
    """
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 or -1, got {direction}")
    if step_s <= 0:
        raise ValueError(f"step_s must be positive, got {step_s}")
    if not 0.0 <= start_chainage_m <= track.length_m:
        raise ValueError(
            f"start_chainage_m {start_chainage_m} is off the track [0, {track.length_m:.1f}] m"
        )
    room = track.length_m - start_chainage_m if direction > 0 else start_chainage_m
    if duration_s is None:
        t_all = np.arange(0.0, 86400.0 + step_s, step_s)
        dist = speed.distance_at(t_all)
        done = dist >= room - 1e-6
        if speed.kind == "limits":
            assert speed.grid_t_s is not None
            done |= t_all >= speed.grid_t_s[-1]
        stop = np.nonzero(done)[0]
        n = int(stop[0]) + 1 if len(stop) else len(t_all)
        t_rel = t_all[:n]
    else:
        t_rel = np.arange(0.0, duration_s + step_s / 2, step_s)
    dist = np.minimum(speed.distance_at(t_rel), room)
    chain = start_chainage_m + direction * dist
    gps = t0_gps_s + t_rel

    pos = LinePositions.from_track(track, chain, antenna_height_m)
    sat = SatellitePositions.from_ephemeris(ephemeris, gps, constellation)
    # one epoch per position: the (n_step, n_sat) diagonal of the az/el cube
    az, el = azel(pos.ecef_m[:, None, :], pos.enu_rotation[:, None], sat.pos_ecef_m[:, None])
    az, el = az[:, 0, 0], el[:, 0, 0]
    trusted = rule.trusted(chain[:, None], az, el)
    model = interval_model or IntervalModel()
    u = _unit_enu(az, el)
    g = along_track_components(np.nan_to_num(u), pos.tangent_enu)
    sigma = model.error.sigma_m(np.nan_to_num(el, nan=90.0))
    length, mode = predicted_interval(
        g, sigma, trusted, model.k_sigma if integrity is None else integrity,
        unit_enu=np.nan_to_num(u), map_doubt=map_doubt,
    )  # fmt: skip
    return TrainRun(
        gps, chain, speed.speed_at(t_rel), sat.sats, trusted, az, el, trusted.sum(axis=1),
        length.astype(float), mode,
    )  # fmt: skip


def _unit_enu(az_deg: NDArray, el_deg: NDArray) -> NDArray:
    a, e = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
