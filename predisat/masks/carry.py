"""Where the places of a mask set's cells lie on another track map: the geometry that carries
masks from one map to another (:mod:`predisat.masks.registration`, another map of the same
track; :mod:`predisat.masks.merge`, another track beside it).

A position of a mask set stands for its cell: the places between the normals to its own map at
the cell's edges (the midpoints between positions), within a reach of that map. Projected onto
another map, those places cover a stretch of its chainage, which :func:`cell_stretches_on`
bounds; :func:`cells_reached` pairs each stretch with the cells on that map it overlaps.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from predisat.masks.maskset import MaskSet
from predisat.track.map import TrackMap

__all__ = ["cell_edges_enu", "cell_stretches_on", "cells_reached"]

_WIDEN_SLACK_M = 0.5  # the maps' curvature between a cell's corners
_NORMAL_SAMPLES = 9  # along each edge's normal, its ends included
_EDGE_TOL_M = 0.001  # projections are good to a micrometre
_MAP_DOUBT_M = 1.0  # the train may stand off both maps by their disagreement and this much


def _reach_m(offset_m: NDArray) -> NDArray:
    """How far from the masks' map a place may be, metres, at each cell edge (``offset_m``,
    (n + 1,), the maps' disagreement there): the train is on neither map exactly; taken as
    anywhere between them, or beyond either by half their disagreement and a metre."""
    return 1.5 * offset_m + _MAP_DOUBT_M


def cell_stretches_on(
    track: TrackMap, masks: MaskSet, offset_m: NDArray
) -> tuple[NDArray, NDArray, float, float, NDArray, NDArray]:
    """Where the places of each position's cell project on ``track``: per position the
    lowest and highest chainage (n,), where the places just beyond the masks' first and
    last cell edge may reach (the registered coverage must start above the first, end below
    the second), and the lowest and highest of the cell's own axis (no reach off it; (n,)),
    metres.

    A cell's places lie between the normals to the masks' map at its edges (the midpoints of
    the chords between positions; the ends half a chord out, as
    :attr:`MaskSet.cell_bounds_m`) and within :func:`_reach_m` of the map; their projections
    are bounded by those of the corners, widened by ``_WIDEN_SLACK_M`` for the maps'
    curvature between them.
    """
    enu, chord, edge = cell_edges_enu(track, masks)
    along = chord[:, :2] / np.linalg.norm(chord[:, :2], axis=1, keepdims=True)
    normal = np.column_stack([-along[:, 1], along[:, 0], np.zeros(len(along))])
    off_edge = np.concatenate([[offset_m[0]], np.maximum(offset_m[1:], offset_m[:-1]),
                               [offset_m[-1]]])  # fmt: skip
    # the maps may part more between positions than at them (offsets at the edges too)
    on_edge = track.project_enu(edge)
    at_edge = np.abs(np.asarray(on_edge.offset_m, float))
    reach_m = _reach_m(np.maximum(off_edge, at_edge))[:, None]
    # the cell's boundary: the normal at each edge (sampled), and the offset lines through the
    # position (a map's bend between samples is what the slack is for)
    frac = np.linspace(-1.0, 1.0, _NORMAL_SAMPLES)[None, :, None]
    across = edge[:, None, :] + frac * reach_m[:, :, None] * normal[:, None, :]
    at = np.asarray(track.project_enu(across).chainage_m, float)  # (n + 1, samples)
    mean_along = along[:-1] + along[1:]  # (n, 2): the chords on either side of a position
    n_pos = np.column_stack([-mean_along[:, 1], mean_along[:, 0]])
    n_pos /= np.linalg.norm(n_pos, axis=1, keepdims=True)
    side = np.column_stack([n_pos, np.zeros(len(n_pos))])
    r_pos = np.minimum(reach_m[1:], reach_m[:-1])
    beside = np.stack([enu, enu - r_pos * side, enu + r_pos * side], axis=1)
    own = np.asarray(track.project_enu(beside).chainage_m, float)  # (n, 3)
    lo = np.minimum.reduce([at[:-1].min(axis=1), at[1:].min(axis=1), own.min(axis=1)])
    hi = np.maximum.reduce([at[:-1].max(axis=1), at[1:].max(axis=1), own.max(axis=1)])
    axis = np.asarray(on_edge.chainage_m, float)  # the edges themselves, and the positions
    lo_own = np.minimum.reduce([axis[:-1], axis[1:], own[:, 0]])
    hi_own = np.maximum.reduce([axis[:-1], axis[1:], own[:, 0]])
    s = _WIDEN_SLACK_M
    return (lo - s, hi + s, float(at[0].max()) + s, float(at[-1].min()) - s, lo_own - s,
            hi_own + s)  # fmt: skip


def cells_reached(bounds_m: NDArray, lo_m: NDArray, hi_m: NDArray) -> tuple[NDArray, NDArray]:
    """Every (stretch, cell) pair where a stretch ``[lo, hi]`` ((k,) each) overlaps a cell
    (``bounds_m``, (n + 1,)) by more than a millimetre (a cell whose edge meets the
    stretch's is a neighbour, not an overlap: both maps put the edge at the same place to
    well under that): the stretch indices and the cell indices, int64, shape (pairs,)."""
    lo, hi = lo_m + _EDGE_TOL_M, hi_m - _EDGE_TOL_M
    first = np.searchsorted(bounds_m[1:], lo, side="right")
    last = np.where(hi > lo, np.searchsorted(bounds_m[:-1], hi, side="left") - 1, first - 1)
    span = np.maximum(last - first + 1, 0)
    src = np.repeat(np.arange(len(first), dtype=np.int64), span)
    dst = np.concatenate([np.arange(a, b + 1) for a, b in zip(first, last, strict=True)]
                         + [np.zeros(0, np.int64)]).astype(np.int64)  # fmt: skip
    return src, dst


def cell_edges_enu(track: TrackMap, masks: MaskSet) -> tuple[NDArray, NDArray, NDArray]:
    """The positions (n, 3), the chords at the cells' edges (n + 1, 3: the ends repeat the
    first and last chord) and the edges themselves (n + 1, 3: the midpoints between
    positions, the ends half a chord out, as :attr:`MaskSet.cell_bounds_m`), ENU metres in
    ``track``'s frame."""
    enu = np.asarray(track.frame.to_enu(masks.lat_deg, masks.lon_deg, masks.h_m), float)
    chord = np.diff(enu, axis=0)
    chord = np.vstack([chord[:1], chord, chord[-1:]])
    edge = np.vstack([enu[:1] - 0.5 * chord[0], 0.5 * (enu[1:] + enu[:-1]),
                      enu[-1:] + 0.5 * chord[-1]])  # fmt: skip
    return enu, chord, edge
