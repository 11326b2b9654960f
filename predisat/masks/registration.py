"""Masks made on one map of a line, used on another: re-registered by position, never by
chainage.

A mask set's chainages are those of the map it was made on; its positions (``lat_deg``,
``lon_deg``) are where the masks hold. Two maps of the same line rarely agree on chainage: the
Infrabel axis of line 144 simplified at 1 m and at 10 m differ by up to 13 m of chainage and
9 m of position over 14 km (``docs/mask-format.md``, "Masks on another map of the line"). A
mask looked up by the other map's chainage would be the sky of a place metres away.

:func:`register_on_track` projects every mask position onto the map in use, takes the foot
point's chainage as the position's, carries each position's cell over the same way, and widens
it where the maps turn apart: a place off one map projects onto the other a little along the
track when the two are at an angle.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from predisat.masks.maskset import BinSource, MaskError, MaskSet
from predisat.track.map import TrackMap

__all__ = [
    "MAX_TRACK_OFFSET_M",
    "SAME_MAP_TOL_M",
    "Registration",
    "register_on_track",
]

MAX_TRACK_OFFSET_M = 25.0
"""Mask positions farther than this from the map (metres) are on another track."""

SAME_MAP_TOL_M = 0.1
"""Chainages and positions within this (metres) of the map's: the masks were made on it."""

_WIDEN_SLACK_M = 0.5  # the maps' curvature between positions, and the cell edges' midpoints
_EDGE_TOL_M = 0.001  # projections are good to a micrometre
_MAP_DOUBT_M = 1.0  # the train may stand off both maps by their disagreement and this much


@dataclass(frozen=True)
class Registration:
    """How a mask set was put on a track map.

    Attributes
    ----------
    masks : MaskSet
        The masks indexed by the map's chainage (the input itself when it was made on it).
    same_map : bool
        Every position within :data:`SAME_MAP_TOL_M` of the map's point at its own chainage.
    shift_m : float
        Largest chainage change, metres (0 on the same map).
    offset_m : float
        Largest distance between a mask position and the map, metres.
    widen_m : float
        Largest widening of a mask's stretch (its cell) at either end, metres (0 on the same
        map).
    beyond : int
        Positions past the map's ends, left out (the map never reaches them).
    """

    masks: MaskSet
    same_map: bool
    shift_m: float
    offset_m: float
    widen_m: float
    beyond: int = 0

    def describe(self, masks_label: str, track_name: str) -> str:
        """One sentence for a warning or a report."""
        if self.same_map:
            return f"masks {masks_label} were made on track {track_name!r}"
        return (
            f"masks {masks_label} were made on another map of this line than {track_name!r}: "
            f"chainages differ by up to {self.shift_m:.1f} m and positions by up to "
            f"{self.offset_m:.1f} m; they are re-registered by position, each mask's stretch "
            f"widened by up to {self.widen_m:.1f} m to the worst of its neighbours (where the "
            "maps turn apart)"
            + (f", {self.beyond} positions past the map's ends left out" if self.beyond else "")
            + "; give the map the masks were made on for the sky they hold"
        )


def register_on_track(masks: MaskSet, track: TrackMap, masks_label: str) -> Registration:
    """Put ``masks`` on ``track`` by position.

    Parameters
    ----------
    masks : MaskSet
    track : TrackMap
        The map the masks will be looked up on.
    masks_label : str
        How errors name the masks (usually their file).

    Returns
    -------
    Registration
        On the same map (every position within :data:`SAME_MAP_TOL_M`), the input unchanged.
        Otherwise a copy at the foot points' chainages. Each position's cell is carried
        over (its edges, the midpoints between positions, projected) and widened at both ends
        by ``0.5 m + (offset + 1 m) sin(turn)``, ``turn`` the angle between the maps there (a
        place off a map by ``d`` projects ``d sin(turn)`` apart on maps at an angle); each bin
        is then the worst over the positions whose widened cells touch the position's cell on
        ``track`` (the highest mask and margin, ASSUMED where any is, the weakest support).
        ``registered_on`` in the provenance says so.

    Raises
    ------
    ValueError
        A position farther than :data:`MAX_TRACK_OFFSET_M` beside the map (another track), no
        position between its ends, or positions that do not follow the map in order (the map
        runs the other way, or folds back); naming the position and the fix. Positions past
        the map's ends are left out.
    """
    proj = track.project(masks.lat_deg, masks.lon_deg)
    off = np.abs(np.asarray(proj.offset_m, float))
    i = int(np.argmax(off))
    if off[i] > MAX_TRACK_OFFSET_M:
        raise ValueError(
            f"masks {masks_label} do not fit track {track.name!r}: the position at chainage "
            f"{masks.chainage_m[i]:.1f} m lies {off[i]:.0f} m beside the track (at its "
            f"chainage {float(proj.chainage_m[i]):.1f} m); give the track map the masks were "
            "made on"
        )
    ch = np.asarray(proj.chainage_m, float)
    shift = np.abs(ch - masks.chainage_m)
    if float(shift.max()) <= SAME_MAP_TOL_M and float(off.max()) <= SAME_MAP_TOL_M:
        return Registration(masks, True, 0.0, float(off.max()), 0.0)
    inside = ~np.asarray(proj.clamped, bool)
    if not inside.any():
        raise ValueError(
            f"masks {masks_label} lie beyond the ends of track {track.name!r}; give the track "
            "map the masks were made on"
        )
    kept = np.flatnonzero(inside)
    if kept.size != kept[-1] - kept[0] + 1:
        raise ValueError(
            f"masks {masks_label} leave track {track.name!r} between its ends (the position at "
            f"chainage {masks.chainage_m[~inside][0]:.1f} m); give the track map the masks "
            "were made on"
        )
    beyond = masks.n_pos - kept.size  # positions past the map's ends: never looked up on it
    masks = masks.subset(float(masks.chainage_m[kept[0]]), float(masks.chainage_m[kept[-1]]))
    ch, off, shift = ch[kept], off[kept], shift[kept]
    if masks.n_pos > 1 and not np.all(np.diff(ch) > 0.0):
        k = int(np.flatnonzero(np.diff(ch) <= 0.0)[0])
        way = "runs the other way" if ch[-1] < ch[0] else "folds back"
        raise ValueError(
            f"masks {masks_label} do not follow track {track.name!r} in order: the positions "
            f"at chainages {masks.chainage_m[k]:.1f} and {masks.chainage_m[k + 1]:.1f} m lie at "
            f"its chainages {ch[k]:.1f} and {ch[k + 1]:.1f} m (the map {way}); give the track "
            "map the masks were made on"
        )
    # each position's cell on the masks' map, carried onto this one: its edges (the midpoints
    # between positions) projected, widened by how far a place's chainage on one map may be
    # from its projection's on the other (a place off a map by d, maps at an angle: d sin)
    edges = _edges_on(track, masks, ch)
    turn = np.radians(np.abs(np.mod(masks.heading_deg - track.heading_at(ch) + 180.0, 360.0)
                             - 180.0))  # fmt: skip
    turn = np.maximum.reduce([turn, np.roll(turn, 1), np.roll(turn, -1)])
    widen = _widening_m(off, turn)
    moved = replace(masks, chainage_m=ch)
    lo, hi = _cells_touching(moved.cell_bounds_m, edges[:-1] - widen, edges[1:] + widen)
    out = _worst_over(moved, lo, hi)
    prov = dict(masks.provenance)
    prov["registered_on"] = {
        "track": track.name,
        "made_on": str(masks.provenance.get("track", "")),
        "max_chainage_shift_m": round(float(shift.max()), 3),
        "max_offset_m": round(float(off.max()), 3),
        "max_widen_m": round(float(widen.max()), 3),
        "positions_beyond_track": int(beyond),
    }
    try:
        registered = replace(out, provenance=prov)
    except MaskError as e:  # pragma: no cover - the arrays come from a valid set
        raise ValueError(f"masks {masks_label}: {e}") from e
    return Registration(registered, False, float(shift.max()), float(off.max()),
                        float(widen.max()), int(beyond))  # fmt: skip


def _widening_m(offset_m: NDArray, turn_rad: NDArray) -> NDArray:
    """How far a place's chainage on one map may be from its projection's on the other,
    metres: off the maps by up to their disagreement ``offset_m`` and a metre, on maps at
    ``turn_rad`` to each other, plus the slack of the maps' curvature."""
    return _WIDEN_SLACK_M + (offset_m + _MAP_DOUBT_M) * np.sin(np.minimum(turn_rad, np.pi / 2))


def _edges_on(track: TrackMap, masks: MaskSet, chainage_m: NDArray) -> NDArray:
    """The masks' cell edges (midpoints between positions, the ends half a spacing out) on
    ``track``: projected, shape (n_pos + 1,), metres."""
    if masks.n_pos == 1:
        return np.array([chainage_m[0], chainage_m[0]])
    # midpoints of 10 m chords: within millimetres of the map's own, at these scales
    lat = 0.5 * (masks.lat_deg[1:] + masks.lat_deg[:-1])
    lon = 0.5 * (masks.lon_deg[1:] + masks.lon_deg[:-1])
    mid = np.asarray(track.project(lat, lon).chainage_m, float)
    first = chainage_m[0] - (mid[0] - chainage_m[0])
    last = chainage_m[-1] + (chainage_m[-1] - mid[-1])
    return np.concatenate([[first], mid, [last]])


def _cells_touching(bounds_m: NDArray, lo_m: NDArray, hi_m: NDArray) -> tuple[NDArray, NDArray]:
    """First and last position whose cell (``bounds_m``, (n + 1,)) overlaps each ``[lo, hi]``
    by more than a millimetre (a cell whose edge meets the interval's is a neighbour, not an
    overlap: both maps put the edge at the same place to well under that)."""
    n = bounds_m.size - 1
    first = np.clip(np.searchsorted(bounds_m[1:], lo_m + _EDGE_TOL_M, side="right"), 0, n - 1)
    last = np.clip(np.searchsorted(bounds_m[:-1], hi_m - _EDGE_TOL_M, side="left") - 1, 0, n - 1)
    return first, np.maximum(first, last)


def _worst_over(masks: MaskSet, first: NDArray, last: NDArray) -> MaskSet:
    """Each position's bins the worst over the positions ``i`` whose range ``first[i] ..
    last[i]`` holds it (the cells their widened stretches reach): the highest mask and margin,
    ASSUMED where any is, the weakest support."""
    span = last - first + 1
    src = np.repeat(np.arange(masks.n_pos), span)  # (pairs,): the position carried over
    dst = np.concatenate([np.arange(a, b + 1) for a, b in zip(first, last, strict=True)])
    mask = masks.mask_el_deg.copy()
    np.maximum.at(mask, dst, masks.mask_el_deg[src])
    margin = np.broadcast_to(masks.margin_deg, mask.shape).astype(np.float32)
    margin_out = margin.copy()
    np.maximum.at(margin_out, dst, margin[src])
    assumed = masks.source == BinSource.ASSUMED
    assumed_out = assumed.copy()
    np.logical_or.at(assumed_out, dst, assumed[src])
    support = None
    if masks.support is not None:
        support = masks.support.copy()
        np.minimum.at(support, dst, masks.support[src])
    source = np.where(assumed_out, np.uint8(BinSource.ASSUMED), masks.source).astype(np.uint8)
    return replace(masks, mask_el_deg=mask, margin_deg=margin_out, source=source,
                   support=support)  # fmt: skip
