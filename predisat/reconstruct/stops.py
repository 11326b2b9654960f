"""The frames of a stop merged into one view (``docs/reconstruction.md``, section 24).

A survey camera that captures on time, not on distance (a 360-degree camera's time lapse, a
video), takes many frames where the train stands or crawls: a minute at a platform at one
frame a second is sixty frames of one scene from one place. They are not independent views:
the same segmenter on the same scene under the same light makes the same faults (a mirrored
sky in a glass facade, a pale wall under overcast), so counted one by one they defeat any
fusion rank and inflate the support; and one of them with a fault of its own (a flare, a
passer-by's reflection) carves at the default rank, where the others saw the obstacle.

So the frames of one camera whose chainages lie within ``gap_m`` of the next, and span at most
``span_m`` (a crawl is cut into such pieces), are merged, before anything is carved, into one
frame that calls sky only what every one of them saw as sky: it adds no sky a single frame
would not have given, and each frame's own fault is outvoted by the others. The merged frame
stands at the place and pose of its frame nearest the middle of their chainages; the others'
are within its doubts (its attitude doubt grows by the largest angle between the poses, its
position doubts hold every frame's camera centre with its own doubts), so every direction it
calls sky is sky from wherever the camera really stood.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import vehicle_to_enu
from predisat.reconstruct.carving import FrameView

__all__ = ["STOP_SPAN_M", "merge_stop_frames", "stop_counts", "stop_groups", "stop_ids"]

STOP_SPAN_M = 0.5
"""Longest chainage spread, metres, of the frames merged into one view: a standing train's
chainages jitter by decimetres (a projected GNSS position's noise), a crawl's keep advancing;
a longer chain is cut (:func:`_chains`). The view's position doubt spans its frames, which
costs sky near the track, so the cut keeps it short."""


def stop_groups(
    frames: Sequence[FrameView],
    gap_m: float,
    span_m: float = STOP_SPAN_M,
    view_ids: Sequence[int] | None = None,
) -> list[list[int]]:
    """Indices of the frames of each stop, in chainage order; single frames alone.

    Frames of one camera (same ``mount.side``, camera model and image size), driven the same
    way (``reverse``: a side camera of a train running the other way looks at the other side
    of the track) and with no ``view_group`` are chained in chainage order while the next lies
    within ``gap_m`` of the previous; a chain spreading over more than ``span_m`` (a crawl) is
    cut into equal slices spreading at most ``span_m``. A window of a survey would slice a
    crawl it holds part of otherwise than the whole survey does: ``view_ids`` then gives each
    frame its view as the survey's :func:`stop_ids` found it, and frames are grouped by it
    (``gap_m`` and ``span_m`` are still checked).

    Parameters
    ----------
    frames : sequence of FrameView
    gap_m : float
        Largest chainage step, metres, between two frames of one stop (>= 0; 0 merges frames
        at the same chainage only).
    span_m : float
        Largest chainage spread of one stop's frames, metres (>= ``gap_m``).
    view_ids : sequence of int, optional
        Per frame, its view in the whole survey (:func:`stop_ids` of the survey's rows);
        frames of one camera with the same id form a group.

    Returns
    -------
    list of list of int
        Every index of ``frames`` exactly once; groups of one for frames not merged. Ordered by
        the first index of each group.
    """
    _check_gap(gap_m, span_m)
    if view_ids is not None and len(view_ids) != len(frames):
        raise ValueError(f"view_ids: {len(view_ids)} ids for {len(frames)} frames; give one "
                         "per frame (stop_ids of the survey's rows)")  # fmt: skip
    cams: dict[tuple[str, str, tuple[int, int], str, bool], list[int]] = {}
    groups: list[list[int]] = []
    for i, f in enumerate(frames):
        if f.view_group:  # the caller grouped it already: left as it is
            groups.append([i])
            continue
        key = (f.mount.side, f.camera.name, f.camera.shape, f.camera.model, bool(f.reverse))
        cams.setdefault(key, []).append(i)
    for idx in cams.values():
        if view_ids is not None:
            by_id: dict[int, list[int]] = {}
            for i in idx:
                by_id.setdefault(int(view_ids[i]), []).append(i)
            # in chainage order within a view, as the chains give them
            groups.extend(sorted(g, key=lambda i: (frames[i].chainage_m, i))
                          for g in by_id.values())  # fmt: skip
            continue
        s = np.array([frames[i].chainage_m for i in idx], float)
        groups.extend([idx[k] for k in run] for run in _chains(s, gap_m, span_m))
    return sorted(groups, key=lambda g: min(g))


def stop_ids(
    side: ArrayLike, chainage_m: ArrayLike, gap_m: float, span_m: float = STOP_SPAN_M
) -> NDArray:
    """The stop each row of a survey's columns is merged into: per camera (``Frames.side``),
    the chains of :func:`stop_groups` from ``Frames.chainage_m`` (shape (n,) each).

    Returns
    -------
    ndarray of int, shape (n,)
        Per row, the smallest row index of its stop (its own index when it stands alone).
    """
    _check_gap(gap_m, span_m)
    sides, s = np.asarray(side, str), np.asarray(chainage_m, float)
    if sides.shape != s.shape or s.ndim != 1:
        raise ValueError(f"side and chainage_m must be 1-D of one length, got {sides.shape} "
                         f"and {s.shape}")  # fmt: skip
    out = np.arange(s.size)
    for name in np.unique(sides):
        idx = np.flatnonzero(sides == name)
        for run in _chains(s[idx], gap_m, span_m):
            out[idx[run]] = idx[run].min()
    return out


def stop_counts(
    side: ArrayLike, chainage_m: ArrayLike, gap_m: float, span_m: float = STOP_SPAN_M
) -> dict[str, tuple[int, int]]:
    """Per camera, the frames at stops and the stops: ``{side: (n_frames, n_stops)}``, from
    :func:`stop_ids`, for a run's report; cameras without a stop are left out."""
    ids = stop_ids(side, chainage_m, gap_m, span_m)
    sides = np.asarray(side, str)
    out = {}
    for name in np.unique(sides):
        _, n = np.unique(ids[sides == name], return_counts=True)
        if (n > 1).any():
            out[str(name)] = (int(n[n > 1].sum()), int((n > 1).sum()))
    return out


def _chains(s: NDArray, gap_m: float, span_m: float = STOP_SPAN_M) -> list[list[int]]:
    """Indices into ``s`` (one camera's chainages) chained in chainage order while the next
    lies within ``gap_m`` of the previous (ties in index order), each chain spreading over
    more than ``span_m`` then cut into the fewest equal slices of its spread that each spread
    at most ``span_m``.

    The cut keeps a crawl from chaining into one view: frames 0.1-0.4 m apart over a whole
    approach (or a video's) chained into a view whose position doubt spanned it, and every
    position of it lost all its sky (an ideal-mask trial, 2026-12-07: 100 % sky lost against
    17 % unmerged). A standing train's frames (their chainages jittering by a decimetre or
    two) stay one view or a few large ones, while the crawl's go to short views of their own.
    """
    order = np.lexsort((np.arange(s.size), s))
    runs: list[list[int]] = []
    for k in order:
        if not np.isfinite(s[k]):  # off the track (NaN): a view of its own, not a crash
            runs.append([int(k)])
        elif runs and s[k] - s[runs[-1][-1]] <= gap_m:
            runs[-1].append(int(k))
        else:
            runs.append([int(k)])
    out: list[list[int]] = []
    for run in runs:
        spread = float(s[run[-1]] - s[run[0]])
        if not spread > span_m:  # NaN: a frame alone
            out.append(run)
            continue
        # equal slices of the spread, as few as hold it: cutting at the widest steps instead
        # shaved a jittered stop's outliers off one by one, single frames each a view again
        n = math.ceil(spread / span_m)
        piece = np.minimum(((s[run] - s[run[0]]) * (n / spread)).astype(int), n - 1)
        out.extend(list(np.asarray(run)[piece == k].tolist()) for k in np.unique(piece))
    return out


def _check_gap(gap_m: float, span_m: float) -> None:
    if not (np.isfinite(gap_m) and gap_m >= 0):
        raise ValueError(f"gap_m must be a finite distance >= 0 metres, got {gap_m}")
    if not (np.isfinite(span_m) and span_m >= gap_m):
        raise ValueError(f"span_m must be a finite distance >= gap_m ({gap_m} m), got {span_m}")


def merge_stop_frames(
    frames: Sequence[FrameView],
    gap_m: float,
    span_m: float = STOP_SPAN_M,
    view_ids: Sequence[int] | None = None,
) -> list[FrameView]:
    """The frames with each stop's frames merged into one (:func:`stop_groups`).

    A merged frame's sky is the pixels every one of its frames saw as sky; its thin pixels
    those of them any frame took for sky by the thin-structure policy only; its confidence the
    lowest per column. It keeps the place, pose and ``reverse`` of the frame nearest the middle
    of their chainages (the reference); its ``attitude_doubt_deg`` is the largest over the
    frames of their own doubt plus the angle between their pose and the reference's; its
    position doubts (a box along, across and up in the reference's level vehicle frame) hold
    every frame's own box, turned with the frame's heading, about every frame's camera centre.
    Its ``frame_id`` names the first and last frames and the count. Frames alone are returned
    as they are (the same objects); the inputs are not modified.

    Parameters
    ----------
    frames : sequence of FrameView
    gap_m, span_m : float
    view_ids : sequence of int, optional
        See :func:`stop_groups`.

    Returns
    -------
    list of FrameView
        In the order of each group's first frame in ``frames``.
    """
    out: list[FrameView] = []
    for g in stop_groups(frames, gap_m, span_m, view_ids):
        if len(g) == 1:
            out.append(frames[g[0]])
            continue
        out.append(_merged([frames[i] for i in g]))
    return out


def _merged(group: list[FrameView]) -> FrameView:
    # the view stands at the frame nearest the middle of the group's chainages (the first of
    # equals): its doubts about that frame reach about half the spread each way; about the
    # first frame they reached the whole spread both ways, half of it where no frame stood
    # (a crawl's 0.4 m slice had a 0.4 m along doubt; docs/reconstruction.md, section 24)
    ch = np.array([f.chainage_m for f in group], float)
    ref = group[int(np.argmin(np.abs(ch - 0.5 * (ch.min() + ch.max()))))]
    sky = np.logical_and.reduce([np.asarray(f.sky_mask, bool) for f in group])
    thins = [np.asarray(f.thin_mask, bool) for f in group if f.thin_mask is not None]
    thin = sky & np.logical_or.reduce(thins) if thins else None
    confs = [np.asarray(f.confidence, float) for f in group if f.confidence is not None]
    conf = np.minimum.reduce(confs) if confs else None
    r0 = ref.mount.camera_to_enu(ref.heading_deg, ref.reverse)
    c0 = ref.mount.camera_position_enu(ref.antenna_enu_m, ref.heading_deg, ref.reverse)
    # the position doubts are a box in the reference frame's level vehicle frame
    # (FrameView.along/across/height_doubt_m): each frame's box, turned into it, about its
    # centre's offset; the exact bounding box of a turned box is |M| times its half-sizes
    to_ref = vehicle_to_enu(ref.heading_deg, ref.reverse).T
    turn_deg, box = 0.0, np.zeros(3)
    for f in group:
        r = f.mount.camera_to_enu(f.heading_deg, f.reverse)
        cos = np.clip((np.trace(r0.T @ r) - 1.0) / 2.0, -1.0, 1.0)
        turn_deg = max(turn_deg, float(np.degrees(np.arccos(cos))))
        c = f.mount.camera_position_enu(f.antenna_enu_m, f.heading_deg, f.reverse)
        turned = np.abs(to_ref @ vehicle_to_enu(f.heading_deg, f.reverse))
        own = turned @ np.array([f.along_doubt_m, f.across_doubt_m, f.height_doubt_m])
        box = np.maximum(box, np.abs(to_ref @ (np.asarray(c, float) - c0)) + own)
    a, b = group[0], group[-1]
    ids = f"{a.frame_id or a.chainage_m}..{b.frame_id or b.chainage_m}"
    return replace(
        ref,
        sky_mask=sky,
        confidence=conf,
        frame_id=f"{ids} (stop, {len(group)} frames)",
        thin_mask=thin,
        thin_width_deg=max(f.thin_width_deg for f in group),
        attitude_doubt_deg=max(f.attitude_doubt_deg for f in group) + turn_deg,
        along_doubt_m=float(box[0]),
        across_doubt_m=float(box[1]),
        height_doubt_m=float(box[2]),
    )
