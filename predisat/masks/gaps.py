"""Holes in a survey: positions inserted where nothing may be trusted."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

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
    obstacle descriptors.

    Parameters
    ----------
    masks : MaskSet
        The merged masks, n_pos >= 3 (fewer give no spacing to compare with).
    track : TrackMap, optional
        Gives the inserted positions' lat / lon / h and heading. Without it (a mask file read
        on its own) they are interpolated between the hole's two surveyed positions: they
        trust nothing, so their coordinates only label them.

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
    if not len(holes):
        return masks, []
    new_ch = np.concatenate([
        np.arange(ch[i] + spacing, ch[i + 1] - spacing / 2, spacing) for i in holes
    ])  # fmt: skip
    if track is not None:
        lat, lon, h = track.position_at(new_ch)
        heading = track.heading_at(new_ch)
    else:
        lat, lon, h = (np.interp(new_ch, ch, np.asarray(v, float))
                       for v in (masks.lat_deg, masks.lon_deg, masks.h_m))  # fmt: skip
        unwrapped = np.rad2deg(np.unwrap(np.deg2rad(np.asarray(masks.heading_deg, float))))
        heading = np.mod(np.interp(new_ch, ch, unwrapped), 360.0)
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
        provenance=masks.provenance,
        support=None if masks.support is None else cat(masks.support, np.zeros((n_new, n_az))),
    )  # fmt: skip
    return closed, [(float(ch[i]), float(ch[i + 1])) for i in holes]
