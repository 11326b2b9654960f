"""Masks raised to the terrain: the DEM horizon as a floor of every bin.

Beyond the surveyed corridor a mask rests on what the cameras saw of the far field, or, where
they saw nothing, on a flat default (``ReconstructionParams.far_default_deg``). A digital
elevation model bounds the far field from below: :func:`raise_to_terrain` computes the terrain
horizon of each position (:func:`predisat.terrain.terrain_horizon_deg`, the model's vertical
error added, Earth curvature and refraction, the antenna on the lowest ground nearby) as the
highest terrain elevation within each bin's azimuth span, and raises every bin below it,
flagging it ``TERRAIN`` where the tiles covered every ray of the bin to its full range (a bin
whose rays leave the tiles or meet a void is raised to the terrain they hold but keeps its
source: the terrain beyond may stand higher). It never lowers a bin: where the DEM and a
camera disagree, the higher one stands (the safe side), and the flag says which bins the DEM
decided.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from predisat.masks.maskset import BinSource, MaskSet
from predisat.terrain import Dem, TerrainHorizon, antenna_height_m, terrain_horizon

__all__ = ["bin_horizon_deg", "bin_terrain", "coverage_notes", "raise_to_terrain"]

#: Largest azimuth spacing of the terrain rays, deg: a bin's highest terrain is the max over
#: rays this close, both bin edges included (a hill's flank rises steeply in azimuth); finer
#: where the DEM's cells need it (:func:`bin_terrain`).
_MAX_SPACING_DEG = 0.25


def bin_horizon_deg(
    masks: MaskSet,
    dem: Dem,
    *,
    antenna_above_ground_m: float = 4.0,
    min_range_m: float = 200.0,
    max_range_m: float = 25_000.0,
) -> NDArray[np.float64]:
    """Highest terrain elevation within each bin of a mask set, deg, shape (n_pos, n_az).

    :func:`bin_terrain` gives it with the bins whose rays the DEM covered in full.

    Parameters
    ----------
    masks : MaskSet
        Positions (``lat_deg``, ``lon_deg``) and bins (``az_deg``, ``az_step_deg``).
    dem : Dem
    antenna_above_ground_m : float
        Antenna height above the ground (rail), m: the DEM's own height at the track is the
        datum (the track's ellipsoidal heights and the DEM's geoid heights differ).
    min_range_m, max_range_m : float
        Ray extent: the far field begins where the surveyed corridor ends.

    Returns
    -------
    ndarray, shape (n_pos, n_az)
        NaN where the DEM does not cover the ray.
    """
    return bin_terrain(masks, dem, antenna_above_ground_m=antenna_above_ground_m,
                       min_range_m=min_range_m, max_range_m=max_range_m).el_deg  # fmt: skip


def bin_terrain(
    masks: MaskSet,
    dem: Dem,
    *,
    antenna_above_ground_m: float = 4.0,
    min_range_m: float = 200.0,
    max_range_m: float = 25_000.0,
) -> TerrainHorizon:
    """Highest terrain elevation within each bin, and whether the DEM covered all its rays.

    The rays stand at most :data:`_MAX_SPACING_DEG` apart and close enough that every DEM
    post lies within a cell of one of them out to ``max_range_m`` (two cells apart there),
    which the 3 x 3 maximum of each sample then takes in.

    Parameters
    ----------
    masks, dem, antenna_above_ground_m, min_range_m, max_range_m
        As for :func:`bin_horizon_deg`.

    Returns
    -------
    TerrainHorizon
        ``el_deg`` and ``complete`` of shape (n_pos, n_az): a bin is complete where every
        ray of it met known terrain out to ``max_range_m`` (elsewhere ``el_deg`` is a lower
        bound of its terrain).
    """
    step, n_az = masks.az_step_deg, masks.n_az
    far = float(np.max(np.abs(masks.lat_deg))) if masks.n_pos else 0.0
    spacing = min(_MAX_SPACING_DEG,
                  float(np.degrees(2.0 * min(dem.cell_m(min(far, 89.0))) / max_range_m)))
    n_sub = max(1, int(np.ceil(step / spacing - 1e-9)))
    # one ring of samples from the first bin's left edge; bin i spans samples i n_sub ..
    # (i + 1) n_sub, both edges included
    az = np.mod(-step / 2.0 + np.arange(n_az * n_sub) * (step / n_sub), 360.0)
    # ground found only past a void at the track (the widened search) may stand far above
    # the track (a gorge floor in radar shadow): a horizon, but not a bound
    h0 = antenna_height_m(dem, masks.lat_deg, masks.lon_deg, antenna_above_ground_m,
                          max_radius_cells=1)  # fmt: skip
    own = np.isfinite(h0)
    if not own.all():
        h0[~own] = antenna_height_m(dem, masks.lat_deg[~own], masks.lon_deg[~own],
                                    antenna_above_ground_m)  # fmt: skip
    ring = terrain_horizon(dem, masks.lat_deg, masks.lon_deg, h0, az,
                           min_range_m=min_range_m, max_range_m=max_range_m)  # fmt: skip
    idx = (np.arange(n_az)[:, None] * n_sub + np.arange(n_sub + 1)[None, :]) % (n_az * n_sub)
    # fmax ignores NaN, NaN where the DEM covers none of the bin: no "All-NaN slice" warning
    el = np.asarray(np.fmax.reduce(ring.el_deg[:, idx], axis=2), float)
    return TerrainHorizon(el, np.all(ring.complete[:, idx], axis=2) & own[:, None])


_COMPASS = ("N", "NE", "E", "SE", "S", "SW", "W", "NW")


def coverage_notes(masks: MaskSet, terrain: TerrainHorizon, dem_source: str) -> list[str]:
    """Warnings for positions whose terrain rays the tiles did not cover to their full range.

    Parameters
    ----------
    masks : MaskSet
    terrain : TerrainHorizon
        From :func:`bin_terrain` for ``masks``.
    dem_source : str
        How the warning names the tiles.

    Returns
    -------
    list of str
        None when every ray of every position was covered; else one sentence naming the
        positions (count and chainage span) and the directions (compass sectors).
    """
    bad = ~np.asarray(terrain.complete, bool)  # cut short, or not covered at all
    short = bad.any(axis=1)
    if not short.any() or not np.isfinite(terrain.el_deg).any():  # the caller's own warning
        return []
    s = masks.chainage_m[short]
    sector = np.floor(np.mod(masks.az_deg + 22.5, 360.0) / 45.0).astype(int) % 8
    dirs = [_COMPASS[k] for k in range(8) if bad[:, sector == k].any()]
    return [f"the elevation tiles ({dem_source}) end or have voids within "
            f"{int(short.sum())} of {masks.n_pos} positions' terrain rays (chainage "
            f"{s.min():.0f}-{s.max():.0f} m, toward {', '.join(dirs)}): those bins were raised to "
            "the terrain the tiles hold but not flagged TERRAIN (the terrain beyond may stand "
            "higher); add the neighbouring tiles where they end, or give a void-filled model "
            "where they hold voids (voids inside a tile: no neighbouring tile fills them)"]


def raise_to_terrain(
    masks: MaskSet,
    horizon_deg: NDArray[np.float64] | TerrainHorizon,
    *,
    dem_source: str = "",
) -> MaskSet:
    """Copy of ``masks`` with every bin below the terrain horizon raised to it.

    A raised bin whose rays the DEM covered in full is flagged ``TERRAIN``; one whose rays
    left the tiles or met a void keeps its source (``ASSUMED`` for the flat default): the
    partial horizon is real terrain and raises it, but the terrain beyond may stand higher,
    so the DEM did not bound it.

    Parameters
    ----------
    masks : MaskSet
    horizon_deg : TerrainHorizon, or ndarray of shape (n_pos, n_az)
        From :func:`bin_terrain`; NaN (no DEM) leaves the bin as it is. A bare array (from
        :func:`bin_horizon_deg`) says nothing of the rays' coverage: its bins are raised but
        none is flagged ``TERRAIN``.
    dem_source : str
        Recorded in the provenance (``terrain``).

    Returns
    -------
    MaskSet
        Margins unchanged (the DEM's vertical error is in the horizon already).
    """
    if isinstance(horizon_deg, TerrainHorizon):
        hz, complete = horizon_deg.el_deg, np.asarray(horizon_deg.complete, bool)
    else:
        hz = np.asarray(horizon_deg, float)
        complete = np.zeros(hz.shape, bool)
    if hz.shape != masks.mask_el_deg.shape:
        raise ValueError(f"horizon_deg has shape {hz.shape}, expected {masks.mask_el_deg.shape}")
    with np.errstate(invalid="ignore"):
        up = np.isfinite(hz) & (hz > masks.mask_el_deg)
    el = np.where(up, np.clip(hz, 0.0, 90.0), masks.mask_el_deg).astype(np.float32)
    src = np.where(up & complete, np.uint8(BinSource.TERRAIN), masks.source).astype(np.uint8)
    prov = {**masks.provenance, "terrain": {
        "dem": dem_source, "raised_bins": int(up.sum()),
        "terrain_bins": int((up & complete).sum()),
        "covered_bins": int((np.isfinite(hz) & complete).sum()),
        "partly_covered_bins": int((np.isfinite(hz) & ~complete).sum()),
        "rule": "bins below the DEM horizon raised; TERRAIN where the DEM covered every ray",
    }}  # fmt: skip
    return replace(masks, mask_el_deg=el, source=src, provenance=prov)
