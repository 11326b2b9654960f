"""Masks raised to the terrain: the DEM horizon as a floor of every bin.

Beyond the surveyed corridor a mask rests on what the cameras saw of the far field, or, where
they saw nothing, on a flat default (``ReconstructionParams.far_default_deg``). A digital
elevation model bounds the far field from below: :func:`raise_to_terrain` computes the terrain
horizon of each position (:func:`predisat.terrain.terrain_horizon_deg`, the model's vertical
error added, Earth curvature and refraction, the antenna on the lowest ground nearby) as the
highest terrain elevation within each bin's azimuth span, and raises every bin below it,
flagging it ``TERRAIN``. It never lowers a bin: where the DEM and a camera disagree, the
higher one stands (the safe side), and the flag says which bins the DEM decided.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from predisat.masks.maskset import BinSource, MaskSet
from predisat.terrain import Dem, antenna_height_m, terrain_horizon_deg

__all__ = ["bin_horizon_deg", "raise_to_terrain"]

#: Largest azimuth spacing of the terrain samples, deg: a bin's highest terrain is the max
#: over samples this close, both bin edges included (a hill's flank rises steeply in azimuth).
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
    step, n_az = masks.az_step_deg, masks.n_az
    n_sub = max(1, int(np.ceil(step / _MAX_SPACING_DEG - 1e-9)))
    # one ring of samples from the first bin's left edge; bin i spans samples i n_sub ..
    # (i + 1) n_sub, both edges included
    az = np.mod(-step / 2.0 + np.arange(n_az * n_sub) * (step / n_sub), 360.0)
    h0 = antenna_height_m(dem, masks.lat_deg, masks.lon_deg, antenna_above_ground_m)
    ring = terrain_horizon_deg(dem, masks.lat_deg, masks.lon_deg, h0, az,
                               min_range_m=min_range_m, max_range_m=max_range_m)  # fmt: skip
    idx = (np.arange(n_az)[:, None] * n_sub + np.arange(n_sub + 1)[None, :]) % (n_az * n_sub)
    hz = ring[:, idx]  # (n_pos, n_az, n_sub + 1)
    # fmax ignores NaN, NaN where the DEM covers none of the bin: no "All-NaN slice" warning
    return np.asarray(np.fmax.reduce(hz, axis=2), float)


def raise_to_terrain(
    masks: MaskSet, horizon_deg: NDArray[np.float64], *, dem_source: str = ""
) -> MaskSet:
    """Copy of ``masks`` with every bin below the terrain horizon raised to it (``TERRAIN``).

    Parameters
    ----------
    masks : MaskSet
    horizon_deg : ndarray, shape (n_pos, n_az)
        From :func:`bin_horizon_deg`; NaN (no DEM) leaves the bin as it is.
    dem_source : str
        Recorded in the provenance (``terrain``).

    Returns
    -------
    MaskSet
        Margins unchanged (the DEM's vertical error is in the horizon already).
    """
    hz = np.asarray(horizon_deg, float)
    if hz.shape != masks.mask_el_deg.shape:
        raise ValueError(f"horizon_deg has shape {hz.shape}, expected {masks.mask_el_deg.shape}")
    with np.errstate(invalid="ignore"):
        up = np.isfinite(hz) & (hz > masks.mask_el_deg)
    el = np.where(up, np.clip(hz, 0.0, 90.0), masks.mask_el_deg).astype(np.float32)
    src = np.where(up, np.uint8(BinSource.TERRAIN), masks.source).astype(np.uint8)
    prov = {**masks.provenance, "terrain": {
        "dem": dem_source, "raised_bins": int(up.sum()),
        "covered_bins": int(np.isfinite(hz).sum()), "rule": "bins below the DEM horizon raised",
    }}  # fmt: skip
    return replace(masks, mask_el_deg=el, source=src, provenance=prov)
