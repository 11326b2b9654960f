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

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.geodesy import unwrap_lon_deg, wrap_lon_deg
from predisat.masks.carry import cell_stretches_on, cells_reached
from predisat.masks.maskset import BinSource, MaskError, MaskSet
from predisat.track.map import TrackMap
from predisat.track.network import track_key

__all__ = [
    "MAX_TRACK_OFFSET_M",
    "OTHER_TRACK_OFFSET_M",
    "SAME_MAP_TOL_M",
    "OtherTrackError",
    "Registration",
    "beside_track_notes",
    "first_stretch_aside",
    "register_on_track",
]

MAX_TRACK_OFFSET_M = 25.0
"""Mask positions farther than this from the map (metres) are on another track."""

SAME_MAP_TOL_M = 0.1
"""Chainages and positions within this (metres) of the map's: the masks were made on it."""

OTHER_TRACK_OFFSET_M = 1.75
"""Mask positions lying this far (metres, the median) beside the map may be those of another
track: half the narrowest spacing of a double line's track centres (3.5 m). Two maps of one
track can disagree by more (9 m between two simplifications of line 144's axis), so beyond it
the caller must say the maps are of the same track (``same_track``): the masks of the other
track are not this track's sky (a trial: 8.8 % of the satellites they trusted were blocked 4 m
across)."""


OTHER_TRACK_STRETCH = (3.5, 50.0)
"""(offset m, length m): positions lying more than the offset beside the map over at least the
length of chainage may be another track's over that stretch (a branch, a passing loop's track)
even where the median stays near the map: a user trial's masks followed a branch up to 23 m
aside over 0.45 of their 1.2 km, median 0.0 m, and gave 2.4 % false trust there against 0.1 %
for the track's own. 3.5 m: the narrowest spacing of two tracks' centres."""


def beside_track_notes(provenance: Mapping[str, Any]) -> list[str]:
    """The warning for masks made from a survey whose frames' own positions lay beside the
    track as another track's would (``predisat process``'s ``survey_beside_track``): the masks
    are written on this track's axis, yet they may hold another track's sky."""
    b = provenance.get("survey_beside_track")
    if not isinstance(b, dict):
        return []
    stretch = b.get("stretch_m")
    where = (f", more than {OTHER_TRACK_STRETCH[0]:g} m from chainage {stretch[0]} to "
             f"{stretch[1]} m" if isinstance(stretch, list) and len(stretch) == 2 else "")
    doubt = b.get("position_doubt_m")
    if isinstance(doubt, (int, float)) and doubt > OTHER_TRACK_STRETCH[0] / 2:
        # a review: plain GNSS positions (3-5 m, as the survey format allows) wandering 3 m
        # aside fired the other-track wording in 11 of 20 surveys of the right track
        return [
            f"the masks were made from a survey whose frames' own positions lie "
            f"{b.get('median_offset_m')} m {b.get('side')} of the track (the median; up to "
            f"{b.get('max_offset_m')} m{where}), within the {doubt:g} m the survey states for "
            "them: positions that coarse cannot tell this track from one beside it, and the "
            "masks of another track are not this track's (a trial: 8.8 % false trust 4 m "
            "across); confirm from the survey's route that it ran on this track"
        ]
    return [
        f"the masks were made from a survey whose frames' own positions lie "
        f"{b.get('median_offset_m')} m {b.get('side')} of the track (the median; up to "
        f"{b.get('max_offset_m')} m{where}): the survey train may have run on another track "
        "(the other track of a double line, a loop, over a crossover), whose sky is not this "
        "track's, yet the masks are written on this track's axis (a trial: masks of the other "
        "track 4 m across trusted 8.8 % of the directions falsely); check the survey's route, "
        "or its positions and the track map"
    ]


class OtherTrackError(ValueError):
    """Masks lying beside the map as another track's would, without ``same_track``."""


def first_stretch_aside(chainage_m: ArrayLike, offset_m: ArrayLike) -> tuple[int, int] | None:
    """The first run of positions lying as another track's would (:data:`OTHER_TRACK_STRETCH`:
    more than 3.5 m beside the map over 50 m or more), as indices ``(first, last)``, inclusive.

    Parameters
    ----------
    chainage_m, offset_m : array_like, shape (n,)
        Positions in chainage order, m, and their distance beside the map (its sign ignored), m.
    """
    aside_m, long_m = OTHER_TRACK_STRETCH
    ch = np.asarray(chainage_m, float)
    far = np.abs(np.asarray(offset_m, float)) > aside_m
    edges = np.diff(np.concatenate([[0], far.astype(np.int8), [0]]))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True):
        if ch[b] - ch[a] >= long_m:
            return int(a), int(b)
    return None


def _check_stretches(
    masks: MaskSet, label: str, track: TrackMap, kept: NDArray, off_m: NDArray, side_m: NDArray
) -> None:
    """:data:`OTHER_TRACK_STRETCH`: the first run of positions beside the map long enough."""
    aside_m = OTHER_TRACK_STRETCH[0]
    ch = np.asarray(masks.chainage_m, float)[kept]
    found = first_stretch_aside(ch, off_m)
    if found is None:
        return
    a, b = found
    worst = a + int(np.argmax(off_m[a : b + 1]))
    side = "left of" if side_m[worst] > 0 else "right of"
    made_on = str(masks.provenance.get("track", "")) or "a map it does not name"
    raise OtherTrackError(
        f"masks {label} (made on {made_on!r}): the positions at chainages {ch[a]:.1f}-"
        f"{ch[b]:.1f} m lie more than {aside_m:g} m beside track {track.name!r}, up to "
        f"{off_m[worst]:.1f} m {side} it: over that stretch they may be the sky of another "
        "track (a branch, a passing loop's track), not this track's. Give masks surveyed on "
        "this track, or the map they were made on; if both maps are of the same physical "
        "track (another survey or simplification of its axis), say so: --masks-same-track "
        "(same_track=True from Python)"
    )



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
    median_offset_m : float
        Median distance between a mask position and the map, metres.
    """

    masks: MaskSet
    same_map: bool
    shift_m: float
    offset_m: float
    widen_m: float
    beyond: int = 0
    median_offset_m: float = 0.0

    def describe(self, masks_label: str, track_name: str) -> str:
        """One sentence for a warning or a report."""
        if self.same_map:
            return f"masks {masks_label} were made on track {track_name!r}"
        return (
            f"masks {masks_label} were made on another map of this line than {track_name!r}: "
            f"chainages differ by up to {self.shift_m:.1f} m and positions by up to "
            f"{self.offset_m:.1f} m; they are re-registered by position: each stretch takes "
            "the worst of the masks whose places may project onto it (up to "
            f"{self.widen_m:.1f} m past their own, where the maps part; a position added "
            "between each two), and the coverage ends short of the masks' own "
            "(docs/mask-format.md)"
            + (f", {self.beyond} positions past the map's ends left out" if self.beyond else "")
            + (f"; their positions lie {self.median_offset_m:.1f} m beside it (the median): "
               "taken as the same physical track, as asked"
               if self.median_offset_m > OTHER_TRACK_OFFSET_M else "")
            + "; give the map the masks were made on for the sky they hold"
        )


def register_on_track(
    masks: MaskSet, track: TrackMap, masks_label: str, *, same_track: bool = False
) -> Registration:
    """Put ``masks`` on ``track`` by position.

    Parameters
    ----------
    masks : MaskSet
    track : TrackMap
        The map the masks will be looked up on.
    masks_label : str
        How errors name the masks (usually their file).
    same_track : bool
        The caller knows ``track`` is a map of the physical track the masks were surveyed on
        (another survey or simplification of its axis): masks lying more than
        :data:`OTHER_TRACK_OFFSET_M` beside it are then registered, not refused.

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
    OtherTrackError
        Without ``same_track``, when the positions lie more than :data:`OTHER_TRACK_OFFSET_M`
        beside the map (the median), or a stretch of them more than
        :data:`OTHER_TRACK_STRETCH` beside it: the masks may be those of another track of the
        line there.
    ValueError
        A position farther than :data:`MAX_TRACK_OFFSET_M` beside the map (another track), no
        position between its ends, or positions that do not follow the map in order (the map
        runs the other way, or folds back); naming the position and the fix. Positions past
        the map's ends are left out.
    """
    proj = track.project(masks.lat_deg, masks.lon_deg)
    ch_all = np.asarray(proj.chainage_m, float)
    off_all = np.abs(np.asarray(proj.offset_m, float))
    inside = ~np.asarray(proj.clamped, bool)
    if not inside.any():
        far = float(np.min(np.hypot(off_all, np.asarray(proj.along_m, float))))
        raise ValueError(
            f"masks {masks_label} do not fit track {track.name!r}: every position lies past "
            f"its ends, the nearest {far:.0f} m from it; give the track map the masks were "
            "made on"
        )
    # past the map's ends the offset is across its end's tangent: no measure of another track
    i = int(np.argmax(np.where(inside, off_all, -1.0)))
    if off_all[i] > MAX_TRACK_OFFSET_M:
        raise ValueError(
            f"masks {masks_label} do not fit track {track.name!r}: the position at chainage "
            f"{masks.chainage_m[i]:.1f} m lies {off_all[i]:.0f} m beside the track (at its "
            f"chainage {ch_all[i]:.1f} m); give the track map the masks were made on"
        )
    shift_all = np.abs(ch_all - masks.chainage_m)
    made_key = str(masks.provenance.get("track_key", ""))
    if made_key and made_key == track_key(track):
        worst = int(np.argmax(np.where(inside, shift_all, -1.0)))
        if shift_all[worst] > SAME_MAP_TOL_M or off_all[worst] > SAME_MAP_TOL_M:
            # the file names this very map, so its positions and chainages contradict each
            # other there; which is right cannot be told (a user trial: 4.8 % false trust if
            # the chainages were)
            raise ValueError(
                f"masks {masks_label} were made on this very map of track {track.name!r} (its "
                f"geometry's key {made_key}), yet the position at chainage "
                f"{masks.chainage_m[worst]:.1f} m lies at its chainage {ch_all[worst]:.1f} m, "
                f"{off_all[worst]:.1f} m beside it: the file's positions and chainages disagree "
                "(edited, or written by another tool); make the masks again with `predisat "
                "process`"
            )
    if inside.all() and float(shift_all.max()) <= SAME_MAP_TOL_M and (
        float(off_all.max()) <= SAME_MAP_TOL_M
    ):
        return Registration(masks, True, 0.0, float(off_all.max()), 0.0)
    kept = np.flatnonzero(inside)
    if kept.size != kept[-1] - kept[0] + 1:
        raise ValueError(
            f"masks {masks_label} leave track {track.name!r} between its ends (the position at "
            f"chainage {masks.chainage_m[~inside][0]:.1f} m); give the track map the masks "
            "were made on"
        )
    if kept.size < 2:
        raise ValueError(
            f"only one position of masks {masks_label} (chainage "
            f"{masks.chainage_m[kept[0]]:.1f} m) lies on track {track.name!r}; give the track "
            "map the masks were made on, or masks of the stretch it covers"
        )
    median_off = float(np.median(off_all[kept]))
    if median_off > OTHER_TRACK_OFFSET_M and not same_track:
        side = np.sign(np.median(np.asarray(proj.offset_m, float)[kept]))
        made_on = str(masks.provenance.get("track", "")) or "a map it does not name"
        raise OtherTrackError(
            f"masks {masks_label} (made on {made_on!r}) lie {median_off:.1f} m "
            f"{'left of' if side > 0 else 'right of' if side < 0 else 'beside'} track "
            f"{track.name!r} (the median of {kept.size} positions; up to "
            f"{OTHER_TRACK_OFFSET_M:g} m is taken as two maps of one track): they may be the "
            "sky of another track of the line, which is not this track's (a trial: 8.8 % of "
            "the satellites they trusted 4 m across were blocked). Give masks surveyed on this "
            "track, or the map they were made on; if both maps are of the same physical track "
            "(another survey or simplification of its axis), say so: --masks-same-track "
            "(same_track=True from Python)"
        )
    if not same_track:
        _check_stretches(masks, masks_label, track, kept, off_all[kept],
                         np.asarray(proj.offset_m, float)[kept])  # fmt: skip
    ch = ch_all[kept]
    if not np.all(np.diff(ch) > 0.0):
        k = int(np.flatnonzero(np.diff(ch) <= 0.0)[0])
        way = "runs the other way" if ch[-1] < ch[0] else "folds back"
        a, b = masks.chainage_m[kept[k]], masks.chainage_m[kept[k + 1]]
        raise ValueError(
            f"masks {masks_label} do not follow track {track.name!r} in order: the positions "
            f"at chainages {a:.1f} and {b:.1f} m lie at its chainages {ch[k]:.1f} and "
            f"{ch[k + 1]:.1f} m (the map {way}); give the track map the masks were made on"
        )
    # each position's cell on the masks' map, carried onto this one: the places of the cell
    # (between the normals at its edges, the midpoints between positions, and within the maps'
    # disagreement and a metre of the masks' map) project onto a stretch of this map, bounded
    # by its corners' projections. Positions past the map's ends are not looked up on it, but
    # their cells may reach it.
    lo_m, hi_m, first_m, last_m, lo_own, hi_own = cell_stretches_on(track, masks, off_all)
    # how much each stretch reaches past its own cell's, at either end (the larger)
    widen = np.maximum(np.maximum(lo_own - lo_m, hi_m - hi_own), 0.0)[kept]
    beyond = masks.n_pos - kept.size
    # a position added half-way between each two: the strip about each edge, where either
    # neighbour's places may project, gets its own cell and the worst of the stretches there;
    # the rest of each cell keeps its own mask (without it each cell took the worst of three
    # positions)
    target = _with_edges(
        masks.subset(float(masks.chainage_m[kept[0]]), float(masks.chainage_m[kept[-1]])), ch
    )
    # where the masks end on their own map nothing is known beyond: the registered coverage
    # must stop short of the projection of the places past their end. The end positions move
    # inward, or give way to the next (their stretches still count in the worst below).
    first, last = 0, target.n_pos
    if kept[0] == 0:
        first = _end_inside(target.chainage_m, first_m)
    if kept[-1] == masks.n_pos - 1:
        last = target.n_pos - _end_inside(-target.chainage_m[::-1], -last_m)
    if last - first < 2:
        raise ValueError(
            f"masks {masks_label} lie within the maps' disagreement of their own ends on track "
            f"{track.name!r}: no stretch of it is surely covered; give the track map the masks "
            "were made on"
        )
    target = _moved_ends(target, first, last, first_m if kept[0] == 0 else None,
                         last_m if kept[-1] == masks.n_pos - 1 else None)  # fmt: skip
    out = _worst_over(target, masks, lo_m, hi_m)
    shift, off = shift_all[kept], off_all[kept]
    prov = dict(masks.provenance)
    prov["registered_on"] = {
        "track": track.name,
        "made_on": str(masks.provenance.get("track", "")),
        "max_chainage_shift_m": round(float(shift.max()), 3),
        "max_offset_m": round(float(off.max()), 3),
        "max_widen_m": round(float(widen.max()), 3),
        "positions_beyond_track": int(beyond),
        "median_offset_m": round(median_off, 3),
        "same_track_confirmed": bool(same_track),
    }
    try:
        registered = replace(out, provenance=prov)
    except MaskError as e:  # pragma: no cover - the arrays come from a valid set
        raise ValueError(f"masks {masks_label}: {e}") from e
    return Registration(registered, False, float(shift.max()), float(off.max()),
                        float(widen.max()), int(beyond), median_off)  # fmt: skip


def _with_edges(masks: MaskSet, chainage_m: NDArray) -> MaskSet:
    """``masks`` at ``chainage_m`` with a position added half-way between each two, to be
    filled by :func:`_worst_over` (its mask, margin and flags start at 0, OBSERVED and
    support 255): geodetic midpoint, the mean heading, the nearer obstacle and the higher."""
    n = masks.n_pos

    def mid(a: NDArray) -> NDArray:
        out = np.empty((2 * n - 1, *a.shape[1:]), a.dtype)
        out[0::2] = a
        out[1::2] = 0.5 * (a[1:] + a[:-1])
        return out

    def fill(a: NDArray, value: float) -> NDArray:
        out = np.full((2 * n - 1, *a.shape[1:]), value, a.dtype)
        out[0::2] = a
        return out

    lon = wrap_lon_deg(mid(unwrap_lon_deg(masks.lon_deg)))  # across 180 deg too
    heading = mid(np.asarray(masks.heading_deg, float))
    turn = np.mod(masks.heading_deg[1:] - masks.heading_deg[:-1] + 180.0, 360.0) - 180.0
    heading[1::2] = np.mod(masks.heading_deg[:-1] + 0.5 * turn, 360.0)
    desc = {}
    for key, v in masks.descriptors.items():
        pair = np.stack([v[1:], v[:-1]])
        near = np.fmin.reduce(pair) if key.endswith("distance_m") else np.fmax.reduce(pair)
        d = mid(np.asarray(v, float))
        d[1::2] = near
        desc[key] = d
    margin = np.broadcast_to(masks.margin_deg, masks.mask_el_deg.shape).astype(np.float32)
    return replace(
        masks, chainage_m=mid(chainage_m), lat_deg=mid(masks.lat_deg),
        lon_deg=lon, h_m=mid(masks.h_m), heading_deg=heading,
        mask_el_deg=fill(masks.mask_el_deg, 0.0), margin_deg=fill(margin, 0.0),
        source=fill(masks.source, float(BinSource.OBSERVED)), descriptors=desc,
        support=None if masks.support is None else fill(masks.support, 255.0),
    )  # fmt: skip


def _end_inside(chainage_m: NDArray, limit_m: float) -> int:
    """How many positions at the start of ``chainage_m`` must give way so that the first
    left can move up until its cell's lower edge (``c0 - (c1 - c0) / 2``) reaches
    ``limit_m``: the edge rises by 1.5 times the move, which must leave it below ``c1``."""
    for k in range(chainage_m.size - 1):
        c0, c1 = float(chainage_m[k]), float(chainage_m[k + 1])
        edge = c0 - 0.5 * (c1 - c0)
        if edge >= limit_m or c0 + (limit_m - edge) / 1.5 < c1 - 1e-6:
            return k
    return chainage_m.size


def _moved_ends(
    masks: MaskSet, first: int, last: int, lo_limit_m: float | None, hi_limit_m: float | None
) -> MaskSet:
    """``masks`` from position ``first`` to ``last - 1``, its end positions moved inward until
    its coverage lies within ``[lo_limit_m, hi_limit_m]`` (None: that end stays)."""
    ch = masks.chainage_m
    kept = masks.subset(float(ch[first]), float(ch[last - 1]))
    c = kept.chainage_m.copy()
    if lo_limit_m is not None:
        edge = c[0] - 0.5 * (c[1] - c[0])
        if edge < lo_limit_m:
            c[0] += (lo_limit_m - edge) / 1.5
    if hi_limit_m is not None:
        edge = c[-1] + 0.5 * (c[-1] - c[-2])
        if edge > hi_limit_m:
            c[-1] -= (edge - hi_limit_m) / 1.5
    return replace(kept, chainage_m=c)


def _worst_over(target: MaskSet, source: MaskSet, lo_m: NDArray, hi_m: NDArray) -> MaskSet:
    """``target`` with each cell's bins the worst over the ``source`` positions whose
    stretches ``[lo_m, hi_m]`` (on the target's chainage) overlap it: the highest mask and
    margin, ASSUMED where any is, the weakest support."""
    src, dst = cells_reached(target.cell_bounds_m, lo_m, hi_m)  # position carried, cell
    mask = target.mask_el_deg.copy()
    np.maximum.at(mask, dst, source.mask_el_deg[src])
    margin_src = np.broadcast_to(source.margin_deg, source.mask_el_deg.shape)
    margin = np.broadcast_to(target.margin_deg, mask.shape).astype(np.float32)
    np.maximum.at(margin, dst, margin_src[src].astype(np.float32))
    assumed = target.source == BinSource.ASSUMED
    np.logical_or.at(assumed, dst, source.source[src] == BinSource.ASSUMED)
    support = None
    if target.support is not None and source.support is not None:
        support = target.support.copy()
        np.minimum.at(support, dst, source.support[src])
    # a cell no stretch reached (none should be: the stretches cover the masks' own cells)
    # is closed and ASSUMED, never left open
    unreached = np.bincount(dst, minlength=target.n_pos) == 0
    mask[unreached] = 90.0
    assumed[unreached] = True
    flags = np.where(assumed, np.uint8(BinSource.ASSUMED), target.source).astype(np.uint8)
    return replace(target, mask_el_deg=mask, margin_deg=margin, source=flags,
                   support=support)  # fmt: skip
