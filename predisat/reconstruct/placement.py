"""Where a frame's camera may stand when the survey's chainage is known only within a doubt.

A survey's chainage comes from its positioning (GNSS, an odometer): off by a few metres
unless RTK-grade. The reconstruction places each camera on the track map at the chainage the
manifest states; a camera really ``e`` metres further along stands elsewhere and, on a curve,
looks a little elsewhere. :func:`chainage_placement_doubt` bounds both over
``|e| <= chainage_doubt_m``; the frame's doubt box and erosion angle take them in
(:class:`~predisat.reconstruct.carving.FrameView`), so that every bound it sets holds from its
true place (``docs/reconstruction.md``, section 18).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import vehicle_to_enu
from predisat.track import TrackMap

__all__ = ["PLACEMENT_STEP_M", "PlacementDoubt", "chainage_placement_doubt"]

PLACEMENT_STEP_M = 0.02
"""Step at which the offsets are sampled, metres (at most 400 steps over the doubt: coarser
for doubts over 4 m); the gap between samples is bounded from the track's curvature
(:func:`chainage_placement_doubt`, Notes)."""
_MAX_STEPS = 400


@dataclass(frozen=True, eq=False)
class PlacementDoubt:
    """How far each camera may be from its stated place, shape (n,) each.

    ``along_m``, ``across_m``, ``up_m`` are in the level vehicle frame at the stated chainage
    (x forward, y left, z up), metres; ``yaw_deg`` the largest turn of the track's heading,
    degrees (the camera turns with it).
    """

    along_m: NDArray
    across_m: NDArray
    up_m: NDArray
    yaw_deg: NDArray


def chainage_placement_doubt(
    track: TrackMap,
    chainage_m: ArrayLike,
    offset_m: ArrayLike,
    antenna_height_m: float,
    reverse: bool,
    chainage_doubt_m: float,
) -> PlacementDoubt:
    """Bound each camera's move and turn when its true chainage is within the doubt.

    Parameters
    ----------
    track : TrackMap
    chainage_m : array_like, shape (n,)
        Stated chainages of the frames' antenna, metres.
    offset_m : array_like, shape (n, 3) or (3,)
        The camera centre from the antenna, level vehicle frame (x forward, y left, z up),
        metres: the mount's lever arm in that frame plus the antenna's tilt shift.
    antenna_height_m : float
        Antenna above the track axis, metres.
    reverse : bool
        The vehicle drives toward decreasing chainage.
    chainage_doubt_m : float
        Largest ``|true - stated|`` chainage, metres.

    Returns
    -------
    PlacementDoubt
        Zeros for a doubt of 0.

    Notes
    -----
    The camera centre ``c(e) = axis(s+e) + h up(s+e) + V(psi(s+e)) offset`` is sampled every
    :data:`PLACEMENT_STEP_M` (or ``2 d / 400``) over ``[-d, d]`` and at both ends; each
    component of its move changes by at most ``L |de|`` between samples, with
    ``L = 1 + (|offset| + h) k`` and ``k`` the sharpest curvature sampled times 1.5 for what
    the samples miss, so half a step of that is added. The heading's turn gets ``k`` times
    half a step the same way. Chainages beyond the map's ends are read at the ends (the map
    says nothing further).
    """
    s = np.atleast_1d(np.asarray(chainage_m, float))
    if s.ndim != 1 or not np.all(np.isfinite(s)):
        raise ValueError("chainage_m must be a 1-D array of finite chainages (metres)")
    if not (np.isfinite(chainage_doubt_m) and chainage_doubt_m >= 0.0):
        raise ValueError(f"chainage_doubt_m must be a length >= 0 metres, got {chainage_doubt_m}")
    off = np.broadcast_to(np.asarray(offset_m, float), (s.size, 3))
    zero = np.zeros(s.size)
    if chainage_doubt_m == 0.0 or s.size == 0:
        return PlacementDoubt(zero, zero.copy(), zero.copy(), zero.copy())
    n_steps = min(max(int(np.ceil(2.0 * chainage_doubt_m / PLACEMENT_STEP_M)), 1), _MAX_STEPS)
    e = np.linspace(-chainage_doubt_m, chainage_doubt_m, n_steps + 1)
    step = 2.0 * chainage_doubt_m / n_steps
    at = np.clip(s[:, None] + np.concatenate([[0.0], e])[None, :], 0.0, track.length_m)
    flat = at.ravel()
    psi = np.asarray(track.heading_at(flat), float).reshape(at.shape)
    rot = vehicle_to_enu(psi, reverse)  # (n, m, 3, 3)
    centre = (
        np.asarray(track.enu_at(flat), float).reshape(*at.shape, 3)
        + antenna_height_m * np.asarray(track.up_at(flat), float).reshape(*at.shape, 3)
        + np.einsum("nmij,nj->nmi", rot, off)
    )
    # the move in the stated level vehicle frame (rot[:, 0] is the stated chainage's)
    move = np.einsum("nji,nmj->nmi", rot[:, 0], centre - centre[:, :1])
    turn = np.abs((psi - psi[:, :1] + 180.0) % 360.0 - 180.0)
    kappa = 1.5 * np.max(np.abs(np.asarray(track.curvature_at(flat), float)).reshape(at.shape),
                         axis=1)  # fmt: skip
    reach = np.linalg.norm(off, axis=1) + antenna_height_m
    slack = 0.5 * step * (1.0 + reach * kappa)
    box = np.max(np.abs(move), axis=1) + slack[:, None]
    yaw = np.max(turn, axis=1) + np.degrees(0.5 * step * kappa)
    return PlacementDoubt(box[:, 0], box[:, 1], box[:, 2], yaw)
