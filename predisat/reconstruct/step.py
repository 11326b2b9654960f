"""Whether two cameras' frames are in step: one camera's images a frame or more off its rows.

A manifest whose image column for one camera lost a row (a dropped frame, a renumbering) pairs
every later image of that camera with the next frame's place: each skyline is carved 10 m from
where it was seen. A user trial's such survey trusted 1.05 % of its directions falsely (11.9 %
at the worst position) and nothing said so: frame to frame the images look right, and the
flow check (:mod:`predisat.reconstruct.sides`) cannot see a constant offset of the labels.

Two cameras of one rig do see it where their fields overlap. A side fisheye pitched 45 deg up
images the sky above the track that the other side's images too (elevations above about 25 deg
across the track), so at one frame both must label those directions alike: an overbridge, a
tunnel mouth, a catenary portal, branches and station roofs over the track cross the overlap at
the same frame in both. :func:`overlap_pixels` finds the vehicle-frame directions both cameras
image, :func:`lag_disagreement` the share of them the two label differently at each position
when the second camera's frame is taken ``lag`` positions later, and
:func:`step_lags` the lag that explains each stretch best (0 where the cameras are in step;
``docs/reconstruction.md``, section 21).

Segmentation error and parallax (the cameras are a metre or two apart) make the two disagree
somewhat even in step; at a wrong lag the scene's own change from one position to the next
adds to it. Open sky gives no evidence either way (both label it sky at every lag).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import CameraModel, Mount

__all__ = [
    "EDGE_DEG",
    "MAX_LAG",
    "MIN_OVERLAP_DIRECTIONS",
    "POSITION_CAP",
    "SWITCH_COST",
    "OffStep",
    "comparable",
    "lag_disagreement",
    "off_step",
    "overlap_pixels",
    "step_lags",
    "widen",
]

MIN_OVERLAP_DIRECTIONS = 50
"""Fewest shared directions (of :func:`overlap_pixels`'s 4000 over the upper hemisphere) for a
pair of cameras to be compared (pinhole side cameras share none)."""
EDGE_DEG = 4.0
"""A shared direction lies at least this far inside both images (the edge of a fisheye's
circle is where calibration and vignetting are worst)."""
MAX_LAG = 3
"""Largest offset tried either way, frames."""
POSITION_CAP = 0.1
"""A position's disagreement at any lag counts at most this much above its best lag's in
:func:`step_lags`: a few positions cannot carry a stretch (at a tunnel mouth the lags that
pair frames inside the tunnel agree trivially, and a cab rig's overcast survey had five such
positions call its left and right cameras 3 frames off); a change of lag needs at least 6
positions of clear evidence. 0.05 missed a dropped image inside a tunnel whose only evidence
was the tunnel's exit."""
SWITCH_COST = 0.3
"""Cost of a change of lag in :func:`step_lags`, summed shares of the shared directions: a
stretch is called off step only where another lag agrees better by 0.6 in all (60 positions
better by a percent, or 6 by ten). In step, held-out surveys' stretches of town under
noisy segmentation reach 0.2 at most (a cost of 0.1 called 26 positions of a town off step);
one image late over 40-170 positions with a tunnel or overbridge in them is found at any cost
up to 0.8 (docs/reconstruction.md, section 21)."""


@dataclass(frozen=True)
class OffStep:
    """A stretch of positions where the second camera agrees best at a lag other than 0.

    Attributes
    ----------
    first, last : int
        Position indices (time order), inclusive.
    lag : int
        The second camera's frame ``lag`` positions later matches the first camera's: its
        images are ``-lag`` frames late against their rows (or the first camera's ``lag``).
    """

    first: int
    last: int
    lag: int


def comparable(mount_a: Mount, mount_b: Mount, spacing_m: float) -> bool:
    """Whether two cameras sit close enough along the vehicle for their frames of one
    position to see the same things above the track: their lever arms at most half the
    spacing between positions apart along it. A cab rig's front and rear cameras 6 m apart
    see an overbridge 0.6 of a 10 m step apart, and were called off step in a survey in step."""
    if not spacing_m > 0.0:
        raise ValueError(f"spacing_m must be > 0, got {spacing_m}")
    return abs(mount_a.lever_arm_m[0] - mount_b.lever_arm_m[0]) <= 0.5 * spacing_m


def off_step(lags: ArrayLike) -> list[OffStep]:
    """The stretches of :func:`step_lags`'s result whose lag is not 0, in position order."""
    g = np.asarray(lags, int)
    out = []
    start = 0
    for i in range(1, g.size + 1):
        if i == g.size or g[i] != g[start]:
            if g[start] != 0:
                out.append(OffStep(start, i - 1, int(g[start])))
            start = i
    return out


def _hemisphere(n: int) -> NDArray:
    """``n`` near-uniform unit directions over the upper hemisphere (Fibonacci lattice), (n, 3)."""
    k = np.arange(n) + 0.5
    z = k / n
    phi = np.pi * (1.0 + np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def _imaged(camera: CameraModel, mount: Mount, dirs: NDArray, edge_deg: float) -> NDArray:
    """Which vehicle-frame ``dirs`` (n, 3) ``camera`` images, ``edge_deg`` inside its edge."""
    # rows of ``dirs @ R`` are ``R.T @ v``: vehicle directions in the camera frame
    to_camera = mount.camera_to_vehicle()
    ok = np.ones(len(dirs), bool)
    e = np.radians(edge_deg)
    probes = [dirs] + [dirs + s * e * np.cross(dirs, ax) for ax in np.eye(3) for s in (-1, 1)]
    for p in probes:
        u, v = camera.ray_to_pixel(p @ to_camera)
        ok &= np.isfinite(u) & camera.contains(u, v)
    return ok


def _pixels(camera: CameraModel, mount: Mount, dirs: NDArray) -> tuple[NDArray, NDArray]:
    u, v = camera.ray_to_pixel(dirs @ mount.camera_to_vehicle())
    rows = np.clip(np.round(v), 0, camera.height_px - 1).astype(np.intp)
    cols = np.clip(np.round(u), 0, camera.width_px - 1).astype(np.intp)
    return rows, cols


def overlap_pixels(
    camera_a: CameraModel,
    mount_a: Mount,
    camera_b: CameraModel,
    mount_b: Mount,
    n_directions: int = 4000,
    edge_deg: float = EDGE_DEG,
) -> tuple[tuple[NDArray, NDArray], tuple[NDArray, NDArray]]:
    """The pixels of two cameras that image the same directions above the vehicle's horizon.

    The mounts' lever arms are ignored: directions, not points, are matched (the parallax of
    a metre or two is part of the in-step disagreement).

    Parameters
    ----------
    camera_a, camera_b : CameraModel
    mount_a, mount_b : Mount
        Their mounts on the level vehicle.
    n_directions : int
        Directions tried over the upper hemisphere.
    edge_deg : float
        How far inside both images a direction must lie, degrees.

    Returns
    -------
    (rows_a, cols_a), (rows_b, cols_b) : tuple of ndarray, each shape (m,)
        Integer pixel indices in each image of the ``m`` shared directions, in the same order
        (``m`` may be 0).
    """
    if n_directions < 1:
        raise ValueError(f"n_directions must be >= 1, got {n_directions}")
    if not 0.0 <= edge_deg < 45.0:
        raise ValueError(f"edge_deg must be in [0, 45) degrees, got {edge_deg}")
    dirs = _hemisphere(n_directions)
    both = _imaged(camera_a, mount_a, dirs, edge_deg) & _imaged(camera_b, mount_b, dirs, edge_deg)
    shared = dirs[both]
    return _pixels(camera_a, mount_a, shared), _pixels(camera_b, mount_b, shared)


def lag_disagreement(
    labels_a: Sequence[NDArray | None],
    labels_b: Sequence[NDArray | None],
    match_b: ArrayLike | None = None,
    max_lag: int = MAX_LAG,
) -> NDArray:
    """Share of the shared directions two cameras label differently, per frame and lag.

    Parameters
    ----------
    labels_a, labels_b : sequence of (m,) bool arrays or None
        Each camera's sky labels of the shared directions (:func:`overlap_pixels`) for its
        frames in time order; None where a frame is unusable.
    match_b : array_like of int, shape (len(labels_a),), optional
        The index in ``labels_b`` of the frame taken with each of the first camera's
        (-1: none); default ``arange`` (the two lists pair one to one).
    max_lag : int
        Largest lag tried either way.

    Returns
    -------
    ndarray, shape (len(labels_a), 2 * max_lag + 1)
        Column ``max_lag + lag`` holds, for the first camera's frame ``i``, the share of
        directions where ``labels_a[i]`` and ``labels_b[match_b[i] + lag]`` differ; NaN where
        either is missing.
    """
    n = len(labels_a)
    match = np.arange(n) if match_b is None else np.asarray(match_b, int)
    if match.shape != (n,):
        raise ValueError(f"match_b must have one entry per frame of labels_a ({n}), got "
                         f"shape {match.shape}")  # fmt: skip
    if match_b is None and len(labels_b) != n:
        raise ValueError(
            f"labels_a and labels_b must be of one length, got {n} and {len(labels_b)}"
        )
    if max_lag < 1:
        raise ValueError(f"max_lag must be >= 1, got {max_lag}")
    out = np.full((n, 2 * max_lag + 1), np.nan)
    for i, a in enumerate(labels_a):
        if a is None or a.size == 0 or match[i] < 0:
            continue
        for k, lag in enumerate(range(-max_lag, max_lag + 1)):
            j = int(match[i]) + lag
            b = labels_b[j] if 0 <= j < len(labels_b) else None
            if b is not None and b.size == a.size:
                out[i, k] = np.count_nonzero(a != b) / a.size
    return out


def _costs(per_lag: NDArray, position_cap: float) -> NDArray:
    """Each position's cost at each lag: its disagreement, a lag it cannot test (the survey's
    ends, a missing frame) at the mean of those it can (no evidence either way), at most
    ``position_cap`` above its best lag's."""
    d = np.asarray(per_lag, float)
    ok = np.isfinite(d)
    n_ok = ok.sum(axis=1)
    mean = np.where(n_ok > 0, np.where(ok, d, 0.0).sum(axis=1) / np.maximum(n_ok, 1), 0.0)
    cost = np.where(ok, d, mean[:, None])
    return np.minimum(cost, cost.min(axis=1, keepdims=True) + position_cap)


def _check_per_lag(per_lag: NDArray) -> NDArray:
    d = np.asarray(per_lag, float)
    if d.ndim != 2 or d.shape[1] % 2 != 1 or d.shape[1] < 3:
        raise ValueError(f"per_lag must have shape (n, 2 * max_lag + 1), got {d.shape}")
    return d


def step_lags(
    per_lag: NDArray, switch_cost: float = SWITCH_COST, position_cap: float = POSITION_CAP
) -> NDArray:
    """The lag of the second camera at each position: the piecewise-constant offset that
    explains the disagreement best.

    A dropped or extra image shifts every later image of its camera, so the offset holds over
    stretches and changes rarely. Each position costs its disagreement at the chosen lag, each
    change of lag costs ``switch_cost``, and the least total is found by dynamic programming
    (Viterbi) from lag 0 at the start. A stretch changes lag only where the other lag's
    summed advantage over it exceeds twice ``switch_cost``; positions with no evidence (open
    sky, missing frames: NaN) cost nothing at any lag and carry the lag on.

    Parameters
    ----------
    per_lag : ndarray, shape (n, 2 * max_lag + 1)
        :func:`lag_disagreement`'s result.
    switch_cost : float
        Cost of a change of lag, in summed shares of the shared directions (> 0).
    position_cap : float
        Each position's cost at a lag is at most this above its cost at its best lag (> 0).

    Returns
    -------
    ndarray of int, shape (n,)
        The lag at each position (0: in step).
    """
    d = _check_per_lag(per_lag)
    if not switch_cost > 0.0 or not position_cap > 0.0:
        raise ValueError(
            f"switch_cost and position_cap must be > 0, got {switch_cost} and {position_cap}"
        )
    n, k = d.shape
    centre = k // 2
    if n == 0:
        return np.zeros(0, int)
    cost = _costs(d, position_cap)
    total = np.full(k, switch_cost)
    total[centre] = 0.0
    back = np.zeros((n, k), np.intp)
    for i in range(n):
        stay_or_switch = total[None, :] + switch_cost * (1.0 - np.eye(k))
        back[i] = np.argmin(stay_or_switch, axis=1)
        total = stay_or_switch[np.arange(k), back[i]] + cost[i]
    lags = np.empty(n, np.intp)
    state = int(np.argmin(total)) if total.min() < total[centre] else centre
    for i in range(n - 1, -1, -1):
        lags[i] = state
        state = int(back[i, state])
    return lags - centre


def widen(
    per_lag: NDArray,
    runs: Sequence[OffStep],
    switch_cost: float = SWITCH_COST,
    position_cap: float = POSITION_CAP,
) -> list[OffStep]:
    """Each stretch widened both ways until lag 0 is confirmed beside it.

    Where nothing crosses the shared directions every lag costs about the same, so where a
    stretch begins and ends is arbitrary (a reviewer's dropped image was set aside only from
    the first structure over the track on, 14 positions after the drop, and those frames
    trusted 0.46 % falsely). Each end moves outward over the positions whose summed
    advantage of lag 0 over the stretch's lag is still below ``switch_cost``: the evidence a
    change of lag needs.

    Parameters
    ----------
    per_lag : ndarray, shape (n, 2 * max_lag + 1)
        :func:`lag_disagreement`'s result.
    runs : sequence of OffStep
        :func:`off_step`'s stretches.
    switch_cost, position_cap : float
        As :func:`step_lags`.

    Returns
    -------
    list of OffStep
        The widened stretches (they may overlap), in the order given.
    """
    d = _check_per_lag(per_lag)
    cost = _costs(d, position_cap)
    centre = d.shape[1] // 2
    out = []
    for r in runs:
        gain = cost[:, centre + r.lag] - cost[:, centre]  # lag 0's advantage at each position
        first, total = r.first, 0.0
        while first > 0 and total + gain[first - 1] < switch_cost:
            total += gain[first - 1]
            first -= 1
        last, total = r.last, 0.0
        while last < len(d) - 1 and total + gain[last + 1] < switch_cost:
            total += gain[last + 1]
            last += 1
        out.append(OffStep(first, last, r.lag))
    return out
