"""Masks of the tracks a train may take, merged worst-case onto the one the locator follows.

A single-track line crosses trains at passing loops; a station has sidings and platform
tracks; a double line has two. The locator follows one path, the track map it is given, and
looks the masks up there: a train on the loop, 4-5 m beside the surveyed track, is located at
the foot point of its position on that map and takes the masks of the wrong place (a trial:
8.8 % of the satellites that track A's exact masks trusted were blocked on track B, 4 m across;
``docs/mask-format.md``). Within a run nothing can tell which track the train is on.

:func:`merge_worst_case` makes masks safe for every track a train may take there: each
surveyed track's masks are carried onto the map the locator follows, by position as
:func:`predisat.masks.registration.register_on_track` does (each position's cell projected onto
the map, widened where the tracks turn apart), and every bin of the followed track's masks
becomes the worst over its own and those of every position of the other tracks whose cell
projects onto it: the highest mask and margin, ASSUMED where any is, the weakest support. Where
no other track runs, the masks are unchanged, bit for bit.

The cost is sky: the followed track loses what the loop's obstacles hide there, which is the
price of not knowing the route (``docs/mask-format.md``, "Passing loops and parallel tracks").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from predisat.jsontypes import JsonDict
from predisat.masks.antenna import masks_antenna_height_m
from predisat.masks.carry import cell_edges_enu, cell_stretches_on, cells_reached
from predisat.masks.gaps import close_gaps
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.registration import MAX_TRACK_OFFSET_M, SAME_MAP_TOL_M, register_on_track
from predisat.track.map import TrackMap

__all__ = ["Merge", "MergedTrack", "merge_worst_case", "merged_tracks_note"]


@dataclass(frozen=True)
class MergedTrack:
    """What one other track's masks did to the merged set.

    Attributes
    ----------
    label : str
        How the masks were named (usually their file).
    made_on : str
        The track the masks were made on (their provenance), ``""`` when they do not say.
    positions_used : int
        Positions lying along the map within ``max_offset_m``, merged.
    positions_left_out : int
        Positions past the map's ends or farther than ``max_offset_m`` beside it.
    chainage_lo_m, chainage_hi_m : float
        The stretch of the map their cells reach, metres (NaN when none is used).
    median_offset_m, max_offset_m : float
        Distance of the used positions from the map, metres.
    bins_raised : int
        Bins of the merged set whose mask or margin the other track raised.
    max_raise_deg : float
        The largest rise of a bin's effective mask (mask + margin), degrees.
    cells_reached : int
        Cells of the merged set (the followed track's positions) the other's cells reach: 0
        when they lie along the map but beside the merged coverage (nothing merged).
    """

    label: str
    made_on: str
    positions_used: int
    positions_left_out: int
    chainage_lo_m: float
    chainage_hi_m: float
    median_offset_m: float
    max_offset_m: float
    bins_raised: int
    max_raise_deg: float
    cells_reached: int = 0

    def describe(self) -> str:
        """One line for the console or a report."""
        if self.positions_used == 0:
            return f"{self.label}: no position lies along the track; nothing merged"
        left = (f", {self.positions_left_out} positions past the map's ends or farther than "
                "the limit left out" if self.positions_left_out else "")  # fmt: skip
        return (
            f"{self.label} ({self.positions_used} positions, {self.median_offset_m:.1f} m beside "
            f"the track, the median) over chainage {self.chainage_lo_m:.0f}-"
            f"{self.chainage_hi_m:.0f} m: {self.bins_raised} bins raised, by up to "
            f"{self.max_raise_deg:.1f} deg{left}"
        )


@dataclass(frozen=True)
class Merge:
    """The merged masks and what each other track did to them.

    Attributes
    ----------
    masks : MaskSet
        On the followed track's map, at its positions; ``merged_worst_case`` in the
        provenance lists the tracks merged.
    tracks : tuple of MergedTrack
        One per other mask set, in the order given.
    """

    masks: MaskSet
    tracks: tuple[MergedTrack, ...]


def merge_worst_case(
    masks: MaskSet,
    others: Sequence[MaskSet],
    track: TrackMap,
    *,
    labels: Sequence[str] | None = None,
    masks_label: str = "masks",
    max_offset_m: float = MAX_TRACK_OFFSET_M,
    same_track: bool = False,
) -> Merge:
    """The worst of ``masks`` and every other track's masks where those run beside ``track``.

    Parameters
    ----------
    masks : MaskSet
        Masks of the followed track, made on ``track`` (the map the locator and the
        availability report use); masks made on another map of it are re-registered on it
        first (:func:`~predisat.masks.registration.register_on_track`).
    others : sequence of MaskSet
        Masks surveyed on the other tracks a train may take (passing loops, sidings, the other
        track of a double line), each on its own map, in any direction of travel. Their
        azimuth bins must be those of ``masks``.
    track : TrackMap
        The followed track's map.
    labels : sequence of str, optional
        How errors and :class:`MergedTrack` name ``others`` (default ``other 1``, ...).
    masks_label : str
        How errors name ``masks``.
    max_offset_m : float
        Positions of ``others`` farther than this beside ``track`` (metres; default
        :data:`~predisat.masks.registration.MAX_TRACK_OFFSET_M`) are not on a route a train
        located on it may take, and are left out, as are those past the map's ends.
    same_track : bool
        ``masks`` were surveyed on the physical track ``track`` maps, though they lie beside
        it (as :func:`register_on_track`'s).

    Returns
    -------
    Merge
        Every bin of ``masks`` raised to the worst (highest mask, highest margin, ASSUMED where
        any is, weakest support) over the positions of ``others`` whose cells project onto its
        cell (the cell carried as in :func:`register_on_track`: between the normals at its
        edges, within the track's distance and a metre more, plus half a metre of slack). A
        raised bin takes the flag of the bin that raised it. Bins no other track reaches are
        unchanged.

    Raises
    ------
    predisat.masks.registration.OtherTrackError
        ``masks`` lie beside ``track`` as another track's would, without ``same_track``.
    ValueError
        ``others`` empty, a mask set with other azimuth bins or a single position,
        ``max_offset_m`` not positive and finite, or ``masks`` that do not fit ``track``
        (:func:`register_on_track`); naming the set and the fix.
    """
    if not others:
        raise ValueError("merge_worst_case: others is empty; give the masks of the other "
                         "tracks a train may take")  # fmt: skip
    if not (np.isfinite(max_offset_m) and max_offset_m > 0):
        raise ValueError(f"max_offset_m must be positive and finite, got {max_offset_m}")
    names = [f"other {k + 1}" for k in range(len(others))] if labels is None else list(labels)
    if len(names) != len(others):
        raise ValueError(f"labels: {len(names)} names for {len(others)} mask sets")
    base = register_on_track(masks, track, masks_label, same_track=same_track).masks
    mask = base.mask_el_deg.copy()
    margin = np.broadcast_to(base.margin_deg, mask.shape).astype(np.float32)
    flags = base.source.astype(np.uint8)
    assumed = flags == BinSource.ASSUMED
    support = None if base.support is None else base.support.copy()
    bounds = base.cell_bounds_m
    done: list[MergedTrack] = []
    kept: list[JsonDict] = []
    for other, name in zip(others, names, strict=True):
        if other.n_az != base.n_az:
            raise ValueError(
                f"masks {name} have {other.n_az} azimuth bins and {masks_label} {base.n_az}: "
                "process both surveys with the same azimuth step"
            )
        if other.n_pos < 2:
            raise ValueError(
                f"masks {name} hold a single position: its cell (the stretch it stands for) is "
                "unknown; give the masks of the whole track"
            )
        # a hole in the other survey trusts nothing, as read_masks, run_locator and
        # run_availability close it: never its neighbours' sky across it (in memory too)
        other = close_gaps(other)[0]
        kept.append(_kept_provenance(other.provenance))
        before = mask + margin
        pairs, info = _pairs_on(track, other, bounds, max_offset_m, name)
        reached = 0 if pairs is None else int(np.unique(pairs[1]).size)
        if pairs is not None:
            src, dst = pairs
            mask, margin, flags, assumed, support = _raise(
                (mask, margin, flags, assumed, support), other, src, dst
            )
        raise_deg = (mask + margin) - before
        done.append(MergedTrack(
            name, str(other.provenance.get("track", "")), *info,
            int(np.count_nonzero(raise_deg > 0)),
            float(raise_deg.max()) if raise_deg.size else 0.0, reached,
        ))  # fmt: skip
    out_flags = np.where(assumed, np.uint8(BinSource.ASSUMED), flags).astype(np.uint8)
    prov = dict(base.provenance)
    # the highest antenna any merged set holds for: a train lower than that is refused (a
    # review: 5.0 m masks merged into 3.0 m ones kept 3.0 m and passed the check)
    heights = [h for h in map(masks_antenna_height_m, [masks, *others]) if h is not None]
    if heights:
        prov["antenna_height_m"] = max(heights)
    earlier = base.provenance.get("merged_worst_case")
    prov["merged_worst_case"] = [*(earlier if isinstance(earlier, list) else []), *[
        {
            "masks": t.label,
            "made_on": t.made_on,
            "positions_used": t.positions_used,
            "positions_left_out": t.positions_left_out,
            "chainage_m": [None if np.isnan(t.chainage_lo_m) else round(t.chainage_lo_m, 3),
                           None if np.isnan(t.chainage_hi_m) else round(t.chainage_hi_m, 3)],
            "median_offset_m": None if np.isnan(t.median_offset_m) else round(t.median_offset_m, 3),
            "bins_raised": t.bins_raised,
            "provenance": p,
        }
        for t, p in zip(done, kept, strict=True)
    ]]  # fmt: skip
    merged = replace(base, mask_el_deg=mask, margin_deg=margin, source=out_flags,
                     support=support, provenance=prov)  # fmt: skip
    return Merge(merged, tuple(done))


def _pairs_on(
    track: TrackMap, other: MaskSet, bounds_m: NDArray, max_offset_m: float, name: str
) -> tuple[tuple[NDArray, NDArray] | None, tuple[int, int, float, float, float, float]]:
    """Which cells (``bounds_m``, (n + 1,)) each used position of ``other`` reaches: the
    (source, target) index pairs, None when none; and the counts, the stretch reached and the
    offsets of :class:`MergedTrack`."""
    proj = track.project(other.lat_deg, other.lon_deg)
    off = np.abs(np.asarray(proj.offset_m, float))
    if (not np.any(proj.clamped) and float(off.max()) <= SAME_MAP_TOL_M
            and float(np.abs(np.asarray(proj.chainage_m, float) - other.chainage_m).max())
            <= SAME_MAP_TOL_M):  # fmt: skip
        # made on this very map (register_on_track's test): looked up alone on it, as the
        # locator would, its cells are its own chainage cells, so each cell of the merged set
        # takes exactly the other's cells it shares chainage with; the carried cells' reach
        # and slack (for another map) would raise every cell to its neighbours' worst
        src, dst = _same_map_pairs(bounds_m, other)
        lo, hi = other.cell_bounds_m[0], other.cell_bounds_m[-1]
        info = (other.n_pos, 0, float(lo), float(hi), float(np.median(off)), float(off.max()))
        return ((src, dst) if src.size else None), info
    # a position stands for its cell: used when any of its cell (its edges, the midpoints to
    # its neighbours) lies along the map within max_offset_m, not only the position itself
    _, chord, edge = cell_edges_enu(track, other)
    flat = np.linalg.norm(chord[1:-1, :2], axis=1) < 1e-6
    if flat.any():
        # the cell's direction is that of the chord to the next position: none there (a
        # review: "enu_m contains NaN or infinite values", naming neither file nor row)
        row = int(np.flatnonzero(flat)[0])
        raise ValueError(
            f"masks {name}: the positions at chainages {other.chainage_m[row]:.3f} and "
            f"{other.chainage_m[row + 1]:.3f} m stand at the same place (latitude "
            f"{other.lat_deg[row]:.7f}, longitude {other.lon_deg[row]:.7f}): their cells have no "
            "direction along the track; give each position its own place on the track (as "
            "`predisat process` writes them), or drop the repeated row"
        )
    pe = track.project_enu(edge)
    e_in = ~np.asarray(pe.clamped, bool) & (
        np.abs(np.asarray(pe.offset_m, float)) <= max_offset_m)
    p_in = ~np.asarray(proj.clamped, bool) & (off <= max_offset_m)
    # the track comes at most a metre per metre closer between them (half a cell each way)
    half = 0.5 * np.linalg.norm(np.diff(edge, axis=0), axis=1)
    near = np.abs(np.asarray(proj.offset_m, float)) - half <= max_offset_m
    used = p_in | e_in[:-1] | e_in[1:] | (~np.asarray(proj.clamped, bool) & near)
    n_used = int(used.sum())
    nan = float("nan")
    if n_used == 0:
        return None, (0, other.n_pos, nan, nan, nan, nan)
    lo, hi = cell_stretches_on(track, other, off)[:2]
    lo, hi = lo[used], hi[used]
    k, dst = cells_reached(bounds_m, lo, hi)
    src = np.flatnonzero(used)[k]
    info = (n_used, other.n_pos - n_used, float(lo.min()), float(hi.max()),
            float(np.median(off[used])), float(off[used].max()))  # fmt: skip
    return ((src, dst) if src.size else None), info


def _same_map_pairs(bounds_m: NDArray, other: MaskSet) -> tuple[NDArray, NDArray]:
    """The (position of ``other``, cell of ``bounds_m``) pairs sharing a chainage, both sets
    looked up by chainage on one map (:meth:`MaskSet.position_index`: an edge belongs to the
    upper cell, the last cell holds its upper edge): every edge of either set within the
    merged coverage, and a point between each two, is looked up in both."""
    edges = np.union1d(bounds_m, other.cell_bounds_m)
    edges = edges[(edges >= bounds_m[0]) & (edges <= bounds_m[-1])]
    at = np.concatenate([edges, 0.5 * (edges[1:] + edges[:-1])])
    j, inside = other.position_index(at)
    i = np.clip(np.searchsorted(bounds_m[1:-1], at, side="right"), 0, bounds_m.size - 2)
    pairs = np.unique(np.column_stack([np.asarray(j)[inside], i[inside]]), axis=0)
    return pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)


_KEPT_KEYS = ("survey", "survey_hash", "code_fingerprint", "track", "track_key",
              "antenna_height_m", "side_check", "step_check", "capture_check", "lens_check",
              "positions_lacking_side", "gaps_closed_m", "registered_on", "merged_worst_case",
              "terrain", "survey_beside_track")  # fmt: skip
"""What a merged set keeps of each other set's provenance: where it came from, and the survey
checks whose warnings the availability report gives (a review: a survey with swapped cameras
merged in lost its warning)."""


def _kept_provenance(prov: JsonDict) -> JsonDict:
    return {k: prov[k] for k in _KEPT_KEYS if k in prov}


def _raise(
    state: tuple[NDArray, NDArray, NDArray, NDArray, NDArray | None],
    other: MaskSet,
    src: NDArray,
    dst: NDArray,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray | None]:
    """The merged arrays (mask, margin, flags, assumed, support) with ``other``'s positions
    ``src`` folded into the cells ``dst``; a new copy of each, the inputs untouched."""
    mask, margin, flags, assumed, support = (None if a is None else a.copy() for a in state)
    assert mask is not None and margin is not None and flags is not None and assumed is not None
    o_mask = other.mask_el_deg[src]
    np.maximum.at(mask, dst, o_mask)
    o_margin = np.broadcast_to(other.margin_deg, other.mask_el_deg.shape)[src]
    np.maximum.at(margin, dst, o_margin.astype(np.float32))
    o_flags = other.source[src]
    np.logical_or.at(assumed, dst, o_flags == BinSource.ASSUMED)
    # a bin raised takes the flag of a bin that raised it (the highest code among them)
    won = (o_mask > state[0][dst]) & (o_mask == mask[dst])
    raised_flag = np.zeros_like(flags)
    np.maximum.at(raised_flag, dst, np.where(won, o_flags, 0).astype(np.uint8))
    any_won = np.zeros(mask.shape, bool)
    np.logical_or.at(any_won, dst, won)
    flags = np.where(any_won, raised_flag, flags).astype(np.uint8)
    if support is not None:
        if other.support is None:
            # the other's evidence is not stated: no count is claimed where it reaches (0,
            # as for an assumption); the rest keeps its own (the column was dropped)
            support[dst] = 0
        else:
            np.minimum.at(support, dst, other.support[src])
    return mask, margin, flags, assumed, support


def merged_tracks_note(masks: MaskSet, masks_label: str) -> str | None:
    """One sentence for a report on masks :func:`merge_worst_case` made (None otherwise): which
    tracks, over which chainages."""
    merged = masks.provenance.get("merged_worst_case")
    if not isinstance(merged, list) or not merged:
        return None
    parts = []
    for t in merged:
        if not isinstance(t, dict):
            continue
        lo, hi = [*(t.get("chainage_m") or []), None, None][:2]
        where = (f" over chainage {lo:.0f}-{hi:.0f} m" if lo is not None and hi is not None
                 else " (nothing along this track)")  # fmt: skip
        parts.append(f"{t.get('masks', '?')}{where}")
    return (
        f"masks {masks_label} are the worst case of this track's and {len(merged)} other "
        f"track{'s' if len(merged) > 1 else ''}' masks (predisat merge: passing loops or "
        f"parallel tracks a train may take): {'; '.join(parts)}; the figures there are those of "
        "the worst of the tracks"
    )
