"""True elevation masks: the reference that masks are scored against, and its file.

:class:`TrueMasks` holds, for antenna positions along a track, the exact highest blocking
elevation of every azimuth bin and the nearest obstacles on each side. The synthetic world
computes it by ray casting (:func:`predisat.synth.truth.true_masks`); the evaluation
(:mod:`predisat.reconstruct.evaluate`) and the locator campaign read it. It lives here, with the
masks, so that scoring a mask file needs no renderer.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.jsontypes import JsonDict
from predisat.readonly import freeze_array_fields

__all__ = ["SIDES", "TRUTH_FORMAT", "TrueMasks"]

TRUTH_FORMAT = "predisat.synth.truemasks/1"
SIDES = ("left", "right")


@dataclass(frozen=True)
class TrueMasks:
    """True elevation masks and obstacle descriptors at antenna positions along a track.

    Attributes
    ----------
    chainage_m : ndarray, shape (n,)
    lat_deg, lon_deg, h_m : ndarray, shape (n,)
        Geodetic antenna positions.
    heading_deg : ndarray, shape (n,)
        Track heading (azimuth of increasing chainage) at each position.
    az_deg : ndarray, shape (n_az,)
        Bin centres ``k * az_step_deg``; bin ``k`` covers ``+- az_step_deg / 2``.
    mask_el_deg : ndarray, shape (n, n_az)
        Highest blocking elevation over the bin, degrees in [0, 90] (90 when the zenith is
        blocked: tunnel, under a deck).
    mask_min_el_deg : ndarray, shape (n, n_az)
        Lowest of the per-azimuth masks sampled in the bin (equals ``mask_el_deg`` where the
        mask is flat across the bin; lower at building edges and masts).
    covered : ndarray of bool, shape (n,)
        The zenith is blocked.
    obstacle_distance_m, obstacle_height_m : ndarray, shape (n, 2)
        Per side (:data:`SIDES`), see :func:`obstacle_descriptors`; NaN when none.
    antenna_height_m, az_step_deg : float
    backend : str
        Ray-casting backend used.
    """

    chainage_m: NDArray
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    heading_deg: NDArray
    az_deg: NDArray
    mask_el_deg: NDArray
    mask_min_el_deg: NDArray
    covered: NDArray
    obstacle_distance_m: NDArray
    obstacle_height_m: NDArray
    antenna_height_m: float = 4.0
    az_step_deg: float = 0.5
    backend: str = "open3d"

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    def bin_index(self, az_deg: ArrayLike) -> NDArray:
        """Index of the azimuth bin containing each azimuth (degrees), same shape."""
        n = self.az_deg.size
        return np.mod(np.floor(np.asarray(az_deg, float) / self.az_step_deg + 0.5), n).astype(int)

    def mask_at(self, az_deg: ArrayLike) -> NDArray:
        """Mask elevation of the bins containing ``az_deg`` at every position, (n, *az.shape)."""
        return self.mask_el_deg[:, self.bin_index(az_deg)]

    def save(self, path: str | Path) -> None:
        """Write to a compressed ``.npz`` (arrays by field name plus a JSON ``meta``)."""
        arrays: dict[str, Any] = {}
        meta: JsonDict = {"format": TRUTH_FORMAT, "sides": list(SIDES)}
        for f in fields(self):
            val = getattr(self, f.name)
            if isinstance(val, np.ndarray):
                arrays[f.name] = val
            else:
                meta[f.name] = val
        with open(path, "wb") as fh:
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | Path) -> TrueMasks:
        """Read a file written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.pop("format", None) != TRUTH_FORMAT:
                raise ValueError(f"{path}: not a true-mask file ({TRUTH_FORMAT})")
            meta.pop("sides", None)
            names = [f.name for f in fields(cls)]
            missing = [n for n in names if n not in z.files and n not in meta]
            if missing:
                raise ValueError(f"{path}: missing fields {missing}; rewrite it with save()")
            return cls(**{n: (z[n] if n in z.files else meta[n]) for n in names})
