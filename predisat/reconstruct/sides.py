"""Whether each side camera's frames move the way its mount says: left and right swapped.

A survey whose left and right frames are swapped (cables on the wrong inputs, files named the
wrong way) puts every skyline on the wrong side of the track: a user trial's trusted 5.7-8 % of
its directions falsely, and nothing in the images looked wrong frame by frame. Frame to frame
it does: as the vehicle moves forward the scenery of a camera looking left slides toward the
left of its image, and that of a camera looking right toward the right. :func:`check_sides`
finds, for each pair of consecutive frames of a side camera, the horizontal shift that best
aligns their sky-share profiles (the share of sky pixels in each image column) and counts the
pairs that moved the mount's way and the other way (``docs/reconstruction.md``, section 19).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import Mount

__all__ = [
    "MIN_CORRELATION",
    "MIN_SHIFT_SHARE",
    "SWAP_RATIO",
    "SideVotes",
    "expected_flow_sign",
    "profile_shift_px",
    "side_votes",
    "sky_profile",
]

MIN_CORRELATION = 0.5
"""Correlation of two profiles at their best shift below which the pair does not vote
(a stop, a frame of sky only, a segmentation that changed)."""
SWAP_RATIO = 1.5
"""Pairs the other way over pairs the mount's way above which a camera is reported."""
MIN_SHIFT_SHARE = 0.005
"""Smallest shift that votes, as a share of the image width (a train standing still)."""


@dataclass(frozen=True)
class SideVotes:
    """The pairs of consecutive frames of one camera that moved its mount's way or the other.

    Attributes
    ----------
    side : str
        The camera (``left`` or ``right``).
    agree, disagree : int
        Pairs whose scenery slid the way the mount says, and the other way.
    pairs : int
        Pairs compared (the others did not vote).
    """

    side: str
    agree: int
    disagree: int
    pairs: int

    @property
    def swapped(self) -> bool:
        """The other way more than 1.5 times as often, with at least ten pairs so (correct
        surveys of the independent generator: at most 0.48 times; the demo 0.25)."""
        return self.disagree >= 10 and self.disagree > SWAP_RATIO * self.agree


def expected_flow_sign(mount: Mount) -> int:
    """Which way the scenery of a camera slides in its image as the vehicle moves on.

    Returns
    -------
    int
        +1 when the direction of travel lies toward the image's right (x grows: a camera
        looking left of the travel, its roll near 0), so that the scenery slides left and a
        later frame's profile matches an earlier one's moved by a positive shift
        (:func:`profile_shift_px`); -1 the other way; 0 when the travel lies near the optical
        axis or behind (a cab camera, a panorama): such a camera does not vote.
    """
    # the vehicle's x is its direction of travel, whichever way along the chainage it drives
    x = float((mount.camera_to_vehicle().T @ np.array([1.0, 0.0, 0.0]))[0])
    return 0 if abs(x) < 0.5 else (1 if x > 0 else -1)


def sky_profile(sky: ArrayLike) -> NDArray:
    """Share of sky pixels in each column of a (h, w) sky mask, shape (w,)."""
    return np.asarray(sky, bool).mean(axis=0, dtype=float)


def profile_shift_px(earlier: ArrayLike, later: ArrayLike, max_shift_px: int) -> tuple[int, float]:
    """The shift ``s`` that best matches ``later(x)`` to ``earlier(x + s)``, and its correlation.

    Parameters
    ----------
    earlier, later : array_like, shape (w,)
        Sky-share profiles (:func:`sky_profile`) of two frames of one camera.
    max_shift_px : int
        Largest shift tried either way, pixels (under half the width).

    Returns
    -------
    shift_px : int
    correlation : float
        Pearson correlation of the overlapping parts at that shift (-1 when none varies).
    """
    a, b = np.asarray(earlier, float), np.asarray(later, float)
    n = a.size
    if b.size != n or not 0 < max_shift_px < n // 2:
        raise ValueError(f"profiles of one width and 0 < max_shift_px < {n // 2} needed")
    best, best_c = 0, -1.0
    for s in range(-max_shift_px, max_shift_px + 1):
        x, y = (b[: n - s], a[s:]) if s >= 0 else (b[-s:], a[: n + s])
        x, y = x - x.mean(), y - y.mean()
        d = float(np.sqrt((x * x).sum() * (y * y).sum()))
        c = float((x * y).sum()) / d if d > 0 else -1.0
        if c > best_c:
            best, best_c = s, c
    return best, best_c


def side_votes(side: str, profiles: Sequence[NDArray], expected: int) -> SideVotes:
    """Votes of a camera's consecutive frames (``profiles`` in time order) against the sign
    :func:`expected_flow_sign` gives; no vote for a camera that gives 0."""
    agree = disagree = 0
    w = int(np.asarray(profiles[0]).size) if profiles else 0
    if expected != 0 and len(profiles) > 1 and w >= 8:
        reach = max(int(0.25 * w), 1)
        least = max(round(MIN_SHIFT_SHARE * w), 1)
        for a, b in itertools.pairwise(profiles):
            s, c = profile_shift_px(a, b, reach)
            if c < MIN_CORRELATION or abs(s) < least:
                continue
            if np.sign(s) == expected:
                agree += 1
            else:
                disagree += 1
    return SideVotes(side, agree, disagree, max(len(profiles) - 1, 0))
