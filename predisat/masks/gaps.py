"""Holes in a survey: positions inserted where nothing may be trusted."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from predisat.geodesy import WGS84
from predisat.masks.maskset import BinSource, MaskSet
from predisat.track.map import TrackMap

__all__ = [
    "GAP_FACTOR",
    "close_gaps",
]

# A step this many times the survey's usual spacing is a hole (a camera dropout, frames lost
# or all bad), not a sparser stretch: nothing may be trusted in it.
GAP_FACTOR = 1.5



def close_gaps(
    masks: MaskSet, track: TrackMap | None = None
) -> tuple[MaskSet, list[tuple[float, float]]]:
    """Closed positions inside the survey's holes, so no neighbour's mask is trusted there.

    A mask position stands for the cell between the midpoints to its neighbours, so a hole
    between two surveyed positions would silently be covered by them. Wherever consecutive
    positions are more than :data:`GAP_FACTOR` times the median spacing apart, positions are
    inserted at that spacing with a 90 deg mask (nothing trusted), source ``ASSUMED`` and NaN
    obstacle descriptors. The holes are added to ``provenance["gaps_closed_m"]``.

    Parameters
    ----------
    masks : MaskSet
        The merged masks, n_pos >= 3 (fewer give no spacing to compare with).
    track : TrackMap, optional
        Gives the inserted positions' lat / lon / h and heading. Without it (a mask file read
        on its own) a position closes each hole one spacing past its start and, when the hole
        is longer than 2.5 spacings, a second one spacing before its end, placed along the
        heading of the surveyed position beside them (a chord across a long hole would leave
        the track on a curve); their cells cover the hole between them (the far neighbour's
        cell reaches at most 0.75 spacing into it, as across an unclosed gap of 1.5).

    Returns
    -------
    masks : MaskSet
        With the inserted positions (the input when there is no hole).
    gaps : list of (float, float)
        Chainages (m) of the surveyed positions on either side of each hole.
    """
    ch = np.asarray(masks.chainage_m, float)
    if len(ch) < 3:
        return masks, []
    step = np.diff(ch)
    spacing = float(np.median(step))
    holes = np.flatnonzero(step > GAP_FACTOR * spacing)
    # the gap between the two positions that closed a hole without a track (one read before:
    # a file read, written and read again, or a set read and closed once more in memory) is
    # no new hole: both trust nothing and their cells meet; closing it again added two
    # positions and a hole that never was to gaps_closed_m at every pass (m8)
    done = [tuple(map(float, g)) for g in masks.provenance.get("gaps_closed_m", [])]
    if done:
        eff = np.asarray(masks.effective_mask_deg, float)
        filler = (eff >= 90.0).all(axis=1) & (np.asarray(masks.source) == BinSource.ASSUMED).all(
            axis=1
        )
        holes = np.array([
            i for i in holes
            if not (filler[i] and filler[i + 1]
                    and any(a <= ch[i] and ch[i + 1] <= b for a, b in done))
        ], dtype=np.int64)  # fmt: skip
    if not len(holes):
        return masks, []
    if track is not None:
        new_ch = np.concatenate([
            np.arange(ch[i] + spacing, ch[i + 1] - spacing / 2, spacing) for i in holes
        ])  # fmt: skip
        lat, lon, h = track.position_at(new_ch)
        heading = track.heading_at(new_ch)
    else:
        new_ch, lat, lon, h, heading = _hole_ends(masks, holes, spacing)
    n_new, n_az = len(new_ch), masks.n_az
    order = np.argsort(np.concatenate([ch, new_ch]), kind="stable")

    def cat(old: NDArray, new: NDArray) -> NDArray:
        return np.concatenate([np.asarray(old), np.asarray(new, dtype=np.asarray(old).dtype)])[
            order
        ]

    closed = MaskSet.from_arrays(
        cat(ch, new_ch), cat(masks.lat_deg, lat), cat(masks.lon_deg, lon), cat(masks.h_m, h),
        cat(masks.heading_deg, heading),
        cat(masks.mask_el_deg, np.full((n_new, n_az), 90.0)),
        az_step_deg=masks.az_step_deg,
        source=cat(masks.source, np.full((n_new, n_az), int(BinSource.ASSUMED))),
        margin_deg=cat(np.broadcast_to(masks.margin_deg, masks.mask_el_deg.shape),
                       np.zeros((n_new, n_az))),
        descriptors={k: cat(v, np.full(n_new, np.nan)) for k, v in masks.descriptors.items()},
        # recorded with the set, wherever it was closed (on reading too: a trial found a file
        # read and written again with filler positions and no word of them)
        provenance={**masks.provenance, "gaps_closed_m": [
            *[list(g) for g in masks.provenance.get("gaps_closed_m", [])],
            *[[float(ch[i]), float(ch[i + 1])] for i in holes]]},
        support=None if masks.support is None else cat(masks.support, np.zeros((n_new, n_az))),
    )  # fmt: skip
    return closed, [(float(ch[i]), float(ch[i + 1])) for i in holes]


def _hole_ends(
    masks: MaskSet, holes: NDArray, spacing: float
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """Chainage, lat, lon, h and heading of the positions closing each hole without a track:
    one spacing after the surveyed position before it and one before the one after it (one
    position when the hole holds no more)."""
    ch = np.asarray(masks.chainage_m, float)
    src, dist = [], []
    for i in holes:
        src.append(int(i))
        dist.append(spacing)
        if ch[i + 1] - ch[i] > 2.5 * spacing:  # room for a second position of its own
            src.append(int(i) + 1)
            dist.append(-spacing)
    k, d = np.asarray(src), np.asarray(dist)
    hdg = np.asarray(masks.heading_deg, float)[k]
    lon0, lat0 = np.asarray(masks.lon_deg, float)[k], np.asarray(masks.lat_deg, float)[k]
    lon, lat, _ = WGS84.fwd(lon0, lat0, np.where(d > 0, hdg, hdg + 180.0), np.abs(d))
    return ch[k] + d, np.asarray(lat), np.asarray(lon), np.asarray(masks.h_m, float)[k], hdg
