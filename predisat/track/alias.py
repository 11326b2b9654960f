"""Where a track passes beside itself: places a 1-D position cannot tell apart.

A balloon (reversing) loop, the two legs of a switchback, a spiral's turns: the track comes
back within metres of a stretch it left hundreds of metres of chainage earlier. A satellite
fix constrained to the track is then equally good on either stretch (the pair hyperbolae cut
both), and only where the train came from tells them apart. A user trial: a start on the
other leg of a balloon loop 15 m away gave 59 claims of 111 off the train, the median 1.9 km
away, with the heading check passing (``docs/locator.md``, "Track aliases").

:class:`TrackAliases` lists, for every sample of the track, the chainages of the other
stretches within ``near_m`` horizontally (heights left out: a fix's height is its worst axis,
and a spiral's turns pass over each other). A stretch is another one when the chainage between
the two places is at least twice their distance (and four sampling steps); a curve's own
neighbours (chord about the arc) are not aliases, a circle's points only after about 3.8
radii of arc.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from predisat.readonly import freeze_array_fields
from predisat.track.map import TrackMap

__all__ = ["TrackAliases"]


@dataclass(frozen=True)
class TrackAliases:
    """The track's self-approaches, sampled every ``step_m``.

    Attributes
    ----------
    near_m : float
        Horizontal distance below which two stretches are aliases, metres.
    step_m : float
        Sampling step along the track, metres.
    at_m : ndarray, shape (n,)
        Chainage of each alias pair's first place, ascending, metres.
    alias_m : ndarray, shape (n,)
        Chainage of the other stretch's place, metres (each pair appears both ways).
    distance_m : ndarray, shape (n,)
        Their horizontal distance, metres.
    """

    near_m: float
    step_m: float
    at_m: NDArray
    alias_m: NDArray
    distance_m: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @classmethod
    def of(cls, track: TrackMap, near_m: float = 100.0, step_m: float = 5.0) -> TrackAliases:
        """The aliases of ``track``.

        Parameters
        ----------
        track : TrackMap
        near_m : float
            Horizontal distance, metres (> 0).
        step_m : float
            Sampling step, metres (> 0; a stretch closer than ``near_m`` over less than a step
            may be missed, so keep it well below ``near_m``).
        """
        if not (np.isfinite(near_m) and near_m > 0):
            raise ValueError(f"near_m must be a positive distance in metres, got {near_m}")
        if not (np.isfinite(step_m) and 0 < step_m <= near_m / 4):
            raise ValueError(f"step_m must be in (0, near_m / 4], got {step_m} (near_m {near_m})")
        n = max(2, int(np.ceil(track.length_m / step_m)) + 1)
        s = np.linspace(0.0, track.length_m, n)
        xy = np.asarray(track.enu_at(s), float)[:, :2]
        pairs = cKDTree(xy).query_pairs(near_m, output_type="ndarray")
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            d = np.linalg.norm(xy[i] - xy[j], axis=1)
            gap = np.abs(s[i] - s[j])
            # no floor of near_m: a switchback's apex (legs metres apart, chainages tens of
            # metres) was left out, and a start on the wrong leg there claimed 40 of 40 epochs
            # off the train (a review); four steps keep a sample's own neighbours out
            keep = (gap >= 2.0 * d) & (gap >= 4.0 * step_m)
            i, j, d = i[keep], j[keep], d[keep]
        else:
            i = j = np.zeros(0, np.intp)
            d = np.zeros(0)
        at = np.concatenate([s[i], s[j]])
        other = np.concatenate([s[j], s[i]])
        dist = np.concatenate([d, d])
        order = np.argsort(at, kind="stable")
        return cls(float(near_m), float(step_m), at[order], other[order], dist[order])

    def __bool__(self) -> bool:
        return bool(self.at_m.size)

    def within(self, lo_m: float, hi_m: float) -> NDArray:
        """Chainages of the other stretches beside ``[lo_m, hi_m]`` (widened by a step, so a
        short interval between samples is covered), metres; empty where there are none."""
        a = int(np.searchsorted(self.at_m, lo_m - self.step_m, side="left"))
        b = int(np.searchsorted(self.at_m, hi_m + self.step_m, side="right"))
        return self.alias_m[a:b]

    def excluded_by(self, lo_m: float, hi_m: float, pred_lo_m: float, pred_hi_m: float) -> bool:
        """True when every alias of ``[lo_m, hi_m]`` lies outside ``[pred_lo_m, pred_hi_m]``
        (widened by a step): a prediction carried from an unambiguous place rules the other
        stretches out."""
        other = self.within(lo_m, hi_m)
        pad = self.step_m
        return not bool(np.any((other >= pred_lo_m - pad) & (other <= pred_hi_m + pad)))
