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
    "MIN_STEP_M",
    "STRETCH_MIN_DISAGREE",
    "STRETCH_WINDOW",
    "SWAP_RATIO",
    "SideVotes",
    "expected_flow_sign",
    "moving_on",
    "pair_votes",
    "profile_shift_px",
    "side_votes",
    "sky_profile",
    "stretches_the_other_way",
]

MIN_CORRELATION = 0.5
"""Correlation of two profiles at their best shift below which the pair does not vote
(a stop, a frame of sky only, a segmentation that changed)."""
SWAP_RATIO = 1.5
"""Pairs the other way over pairs the mount's way above which a camera is reported."""
MIN_SHIFT_SHARE = 0.005
"""Smallest shift that votes, as a share of the image width (a train standing still)."""
MIN_STEP_M = 0.25
"""Chainage step along the direction of travel below which a pair of frames does not vote."""
STRETCH_WINDOW = 8
"""Consecutive voting pairs over which a stretch of a camera's frames is judged."""
STRETCH_MIN_DISAGREE = 6
"""Pairs of such a window that slid the other way above which its frames are taken for
another camera's (a copy of the other side's images over a stretch: a user trial's 150 m of
right frames that were the left camera's trusted 1.44 % of the survey's directions falsely,
16 % at one position, while the camera as a whole voted 23 / 11 its mount's way; correct
cameras: at most 4 pairs the other way in any 8 on the demo's survey, 2 on a 400 m one)."""


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


def moving_on(chainage_m: ArrayLike, reverse: bool, least_m: float = MIN_STEP_M) -> NDArray:
    """Per pair of consecutive frames (in time order), whether the vehicle moved on in its
    direction of travel by more than ``least_m`` between them: a pair that stood or backed
    (a slow reversal keeps its frames at load when each step back is under 2 m) sees its
    scenery slide the other way or not at all, and must not vote."""
    steps = np.diff(np.asarray(chainage_m, float)) * (-1.0 if reverse else 1.0)
    return steps > least_m


def pair_votes(
    profiles: Sequence[NDArray], expected: int, moved: Sequence[bool] | NDArray | None = None
) -> list[int]:
    """The vote of each pair of consecutive frames (``profiles`` in time order): +1 slid the
    way ``expected`` (:func:`expected_flow_sign`) says, -1 the other way, 0 no vote (a stop, a
    poor match, a camera that does not vote, a pair whose ``moved`` (:func:`moving_on`) is
    False)."""
    votes = [0] * max(len(profiles) - 1, 0)
    w = int(np.asarray(profiles[0]).size) if profiles else 0
    if expected != 0 and len(profiles) > 1 and w >= 8:
        reach = max(int(0.25 * w), 1)
        least = max(round(MIN_SHIFT_SHARE * w), 1)
        for k, (a, b) in enumerate(itertools.pairwise(profiles)):
            if moved is not None and not moved[k]:
                continue
            s, c = profile_shift_px(a, b, reach)
            if c < MIN_CORRELATION or abs(s) < least:
                continue
            votes[k] = 1 if np.sign(s) == expected else -1
    return votes


def side_votes(
    side: str,
    profiles: Sequence[NDArray],
    expected: int,
    moved: Sequence[bool] | NDArray | None = None,
) -> SideVotes:
    """Votes of a camera's consecutive frames (``profiles`` in time order) against the sign
    :func:`expected_flow_sign` gives; no vote for a camera that gives 0, nor for a pair that
    did not move on (``moved``, :func:`pair_votes`)."""
    votes = pair_votes(profiles, expected, moved)
    return SideVotes(side, votes.count(1), votes.count(-1), max(len(profiles) - 1, 0))


def stretches_the_other_way(votes: Sequence[int]) -> list[tuple[int, int]]:
    """The stretches of a camera's frames whose scenery slid the other way from its mount's.

    A window of :data:`STRETCH_WINDOW` consecutive voting pairs (pairs that do not vote are
    passed over) with more than :data:`STRETCH_MIN_DISAGREE` - 1 of them the other way marks
    its pairs; overlapping windows join, and each stretch runs from the first to the last
    pair of its windows that went the other way.

    Parameters
    ----------
    votes : sequence of int
        :func:`pair_votes` of one camera.

    Returns
    -------
    list of (first, last)
        Frame indices (in the order of ``profiles``), inclusive: pair ``k`` joins frames ``k``
        and ``k + 1``, so a stretch of pairs ``a..b`` is frames ``a..b + 1``.
    """
    voting = [k for k, v in enumerate(votes) if v != 0]
    marked = np.zeros(len(votes), bool)
    for i in range(max(len(voting) - STRETCH_WINDOW + 1, 0)):
        window = voting[i : i + STRETCH_WINDOW]
        if sum(votes[k] < 0 for k in window) >= STRETCH_MIN_DISAGREE:
            marked[[k for k in window if votes[k] < 0]] = True
            # the pairs between the window's first and last "other way" pair belong to it
            other = [k for k in window if votes[k] < 0]
            marked[other[0] : other[-1] + 1] = True
    out: list[tuple[int, int]] = []
    for k in np.flatnonzero(marked):
        if out and k == out[-1][1]:
            out[-1] = (out[-1][0], int(k) + 1)
        else:
            out.append((int(k), int(k) + 1))
    return out
