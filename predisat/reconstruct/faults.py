"""Fault injection: realistic segmentation faults in the sky masks of a survey (issue 30).

The reconstruction trusts a satellite where the masks say sky. Real segmenters fail in known
ways (``docs/reconstruction.md``, fault model); :func:`inject_faults` reproduces them on
correct masks (a synthetic survey's ideal masks), at per-frame rates, so that a fusion can be
measured against faults whose truth is known:

=================  ==========================================================================
class              what is labelled sky although it is not
=================  ==========================================================================
``facade_band``    the top band of a facade under the skyline (pale facade, a row of windows
                   against an overcast sky), over a span of columns
``glass_mirror``   a facade from its top down to its foot over a span of columns (a glass
                   curtain wall mirroring the sky)
``wet_ground``     the ground under the horizon (water, a wet platform mirroring the sky)
``whole_frame``    a whole-frame failure: over-exposure (every obstacle above a row) or flare
                   (a large disc)
``lens_drop``      a drop on the lens (a disc of sky) on several frames in a row of one camera
``thin_lost``      every obstacle feature at most a few pixels wide (masts, poles, lamp arms)
``skyline_shift``  the whole skyline a few pixels too low
=================  ==========================================================================

Only false *sky* is injected: missed sky is the safe side and only costs availability. Each
class strikes a frame independently with its rate (``lens_drop``: a drop starts with its rate
and stays on the next frames of that camera). The per-pixel scene classes that the facade and
ground faults need (:data:`LABEL_BUILDING`, :data:`LABEL_GROUND`) come with the masks (a
synthetic world knows them).

:func:`false_sky_stats` measures a mask against its truth the way the issue measures real
segmenters: the false-sky rate (non-sky labelled sky / all non-sky) and the share of unsafe
columns (false sky joined to the true sky over at least 1 % of the image height).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from predisat.sky.photoeval import UNSAFE_COLUMN_FRACTION, sky_safety_counts

__all__ = [
    "FAULT_CLASSES",
    "LABEL_BUILDING",
    "LABEL_GROUND",
    "LABEL_NONE",
    "LABEL_OTHER",
    "LABEL_SKY",
    "FaultRates",
    "InjectedFault",
    "false_sky_stats",
    "inject_faults",
]

FAULT_CLASSES = (
    "facade_band", "glass_mirror", "wet_ground", "whole_frame", "lens_drop", "thin_lost",
    "skyline_shift",
)  # fmt: skip
"""The fault classes of :func:`inject_faults`."""

LABEL_NONE = -1  # not imaged (outside a fisheye's circle)
LABEL_SKY = 0  # sky, and L-band-transparent thin structure
LABEL_BUILDING = 1  # facades, roofs, walls of buildings
LABEL_GROUND = 2  # ground, ballast, platforms
LABEL_OTHER = 3  # everything else that blocks: trees, rock, masts, bridges



@dataclass(frozen=True)
class FaultRates:
    """Per-frame probability of each fault class (:data:`FAULT_CLASSES`).

    Attributes
    ----------
    rates : dict of str to float
        Class -> probability that a frame has that fault, in [0, 1].
    """

    rates: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for k, v in self.rates.items():
            if k not in FAULT_CLASSES:
                raise ValueError(f"unknown fault class {k!r}; known: {FAULT_CLASSES}")
            if not 0.0 <= float(v) <= 1.0:
                raise ValueError(f"fault rate of {k} must lie in [0, 1], got {v}")

    @classmethod
    def mix(cls, total: float, whole_frame: float | None = None) -> FaultRates:
        """Rates in the mix the issue attributes false trust to (half facades and glass, a
        third thin structures, the rest frame, lens, ground and skyline faults), ``total``
        being their sum (expected faults per frame; each rate capped at 1). ``whole_frame``:
        that class's rate given apart (a measured one), ``total`` then shared by the others.
        """
        weights = {
            "facade_band": 0.25, "glass_mirror": 0.20, "thin_lost": 0.30, "wet_ground": 0.05,
            "whole_frame": 0.05, "lens_drop": 0.05, "skyline_shift": 0.10,
        }  # fmt: skip
        if not total >= 0:
            raise ValueError(f"total fault rate must be >= 0, got {total}")
        if whole_frame is not None:
            rest = 1.0 - weights.pop("whole_frame")
            weights = {k: w / rest for k, w in weights.items()}
        out = {k: min(1.0, w * float(total)) for k, w in weights.items()}
        if whole_frame is not None:
            out["whole_frame"] = min(1.0, float(whole_frame))
        return cls(out)

    def scaled(self, factor: float) -> FaultRates:
        """Every rate times ``factor`` (capped at 1)."""
        return FaultRates({k: min(1.0, float(v) * factor) for k, v in self.rates.items()})

    @property
    def total(self) -> float:
        return float(sum(self.rates.values()))


@dataclass(frozen=True)
class InjectedFault:
    """One fault put into one frame: frame index, class, pixels turned to sky."""

    frame: int
    kind: str
    pixels: int


def inject_faults(
    masks: Sequence[NDArray],
    labels: Sequence[NDArray],
    cameras: Sequence[str],
    rates: FaultRates,
    seed: int = 0,
) -> tuple[list[NDArray], list[InjectedFault]]:
    """Corrupt sky masks with realistic segmentation faults.

    Parameters
    ----------
    masks : sequence of ndarray of bool, shape (H, W) each
        Correct sky masks (True = sky), in survey order (each camera's frames in time order).
    labels : sequence of ndarray of int8, shape (H, W) each
        Scene class per pixel (``LABEL_*``); sky pixels of ``masks`` are ignored.
    cameras : sequence of str
        Camera of each frame (a lens drop stays on the next frames of its camera).
    rates : FaultRates
    seed : int

    Returns
    -------
    masks : list of ndarray of bool
        Corrupted copies (the inputs are not modified).
    faults : list of InjectedFault
    """
    if not (len(masks) == len(labels) == len(cameras)):
        raise ValueError(
            f"masks, labels and cameras must have one entry per frame, got {len(masks)}, "
            f"{len(labels)} and {len(cameras)}"
        )
    rng = np.random.default_rng([int(seed), 30])
    out: list[NDArray] = []
    faults: list[InjectedFault] = []
    drops: dict[str, tuple[int, int, int, int]] = {}  # camera -> (x, y, r, frames left)
    for i, (m, lab, cam) in enumerate(zip(masks, labels, cameras, strict=True)):
        sky = np.asarray(m, bool)
        lab = np.asarray(lab)
        if sky.shape != lab.shape:
            raise ValueError(f"frame {i}: mask {sky.shape} and labels {lab.shape} differ")
        imaged = lab != LABEL_NONE
        new = sky.copy()
        for kind in FAULT_CLASSES:
            if kind == "lens_drop":
                continue
            if rng.uniform() < float(rates.rates.get(kind, 0.0)):
                add = _FAULTS[kind](sky, lab, rng) & imaged & ~sky
                if add.any():
                    faults.append(InjectedFault(i, kind, int(add.sum())))
                new |= add
        # a drop on the lens: starts with its rate, stays for a few frames of that camera
        if cam not in drops and rng.uniform() < float(rates.rates.get("lens_drop", 0.0)):
            h, w = sky.shape
            drops[cam] = (int(rng.integers(0, w)), int(rng.integers(0, h // 2)),
                          int(rng.uniform(0.03, 0.08) * w), int(rng.integers(3, 11)))  # fmt: skip
        if cam in drops:
            x, y, r, left = drops[cam]
            disc = np.zeros(sky.shape, np.uint8)
            cv2.circle(disc, (x, y), r, 1, -1)
            add = disc.astype(bool) & imaged & ~sky
            if add.any():
                faults.append(InjectedFault(i, "lens_drop", int(add.sum())))
            new |= add
            if left <= 1:
                del drops[cam]
            else:
                drops[cam] = (x, y, r, left - 1)
        out.append(new)
    return out, faults


def _top_run_below(sky: NDArray) -> NDArray:
    """Row of the first non-sky pixel under each column's top sky run (H where the column is
    sky to the bottom, -1 where its top pixel is not sky)."""
    h = sky.shape[0]
    not_sky = ~sky
    first = np.where(not_sky.any(axis=0), np.argmax(not_sky, axis=0), h)
    return np.where(sky[0], first, -1)


def _span(rng: np.random.Generator, ok: NDArray, lo: float, hi: float) -> NDArray:
    """A random run of columns (``lo``-``hi`` of the width) centred on an ``ok`` column."""
    w = ok.size
    out = np.zeros(w, bool)
    cand = np.flatnonzero(ok)
    if cand.size == 0:
        return out
    c = int(cand[rng.integers(0, cand.size)])
    half = max(1, int(rng.uniform(lo, hi) * w / 2))
    out[max(0, c - half) : c + half + 1] = True
    return out & ok


def _under_skyline(
    sky: NDArray, lab: NDArray, rng: np.random.Generator, label: int, depth_px: NDArray | int,
    span: tuple[float, float],
) -> NDArray:  # fmt: skip
    """Pixels of class ``label`` from each skyline down (``depth_px`` rows, contiguous in that
    class), over a random span of the columns whose skyline stands on that class."""
    h, w = sky.shape
    first = _top_run_below(sky)
    col = np.arange(w)
    on = (first >= 0) & (first < h)
    on[on] = lab[first[on], col[on]] == label
    cols = _span(rng, on, *span)
    rows = np.arange(h)[:, None]
    depth = np.broadcast_to(np.asarray(depth_px), (w,))
    band = (rows >= first[None, :]) & (rows < first[None, :] + depth[None, :]) & cols[None, :]
    # stop at the first pixel of another class below the skyline
    other = (lab != label) & (rows >= first[None, :])
    stop = np.where(other.any(axis=0), np.argmax(other, axis=0), h)
    return band & (rows < stop[None, :])


def _facade_band(sky: NDArray, lab: NDArray, rng: np.random.Generator) -> NDArray:
    h = sky.shape[0]
    return _under_skyline(sky, lab, rng, LABEL_BUILDING, max(1, int(rng.uniform(0.02, 0.06) * h)),
                          (0.05, 0.3))  # fmt: skip


def _glass_mirror(sky: NDArray, lab: NDArray, rng: np.random.Generator) -> NDArray:
    return _under_skyline(sky, lab, rng, LABEL_BUILDING, sky.shape[0], (0.05, 0.25))


def _wet_ground(sky: NDArray, lab: NDArray, rng: np.random.Generator) -> NDArray:
    h = sky.shape[0]
    return _under_skyline(sky, lab, rng, LABEL_GROUND, max(1, int(rng.uniform(0.01, 0.05) * h)),
                          (0.1, 0.5))  # fmt: skip


def _whole_frame(sky: NDArray, lab: NDArray, rng: np.random.Generator) -> NDArray:
    h, w = sky.shape
    if rng.uniform() < 0.5:  # over-exposure: everything bright above a row
        out = np.zeros((h, w), bool)
        out[: int(rng.uniform(0.3, 0.7) * h)] = True
        return out
    disc = np.zeros((h, w), np.uint8)  # flare
    r = int(rng.uniform(0.1, 0.25) * np.hypot(h, w))
    cv2.circle(disc, (int(rng.integers(0, w)), int(rng.integers(0, h // 2))), r, 1, -1)
    return disc.astype(bool)


def _thin_lost(sky: NDArray, lab: NDArray, rng: np.random.Generator) -> NDArray:
    # features at most 2-8 px wide: an opening with an odd (centred) kernel one wider
    width = 2 * int(rng.integers(1, 5)) + 1
    solid = (~sky).astype(np.uint8)
    kept = cv2.morphologyEx(solid, cv2.MORPH_OPEN, np.ones((1, width), np.uint8))
    return (solid > 0) & (kept == 0)


def _skyline_shift(sky: NDArray, lab: NDArray, rng: np.random.Generator) -> NDArray:
    d = int(rng.integers(1, 5))
    kernel = np.zeros((2 * d + 1, 1), np.uint8)
    kernel[: d + 1] = 1  # grows the sky downwards only
    return cv2.dilate(sky.astype(np.uint8), kernel, anchor=(0, d)) > 0


_FAULTS = {
    "facade_band": _facade_band,
    "glass_mirror": _glass_mirror,
    "wet_ground": _wet_ground,
    "whole_frame": _whole_frame,
    "thin_lost": _thin_lost,
    "skyline_shift": _skyline_shift,
}


def false_sky_stats(pred: NDArray, truth: NDArray, valid: NDArray | None = None) -> dict[str, int]:
    """Counts for the false-sky rate and the unsafe-column share of one mask.

    Parameters
    ----------
    pred, truth : ndarray of bool, shape (H, W)
        Predicted and true sky.
    valid : ndarray of bool, shape (H, W), optional
        Pixels imaged (default all).

    Returns
    -------
    dict
        ``false_sky_px`` (non-sky labelled sky), ``non_sky_px``, ``unsafe_columns`` (columns
        with false sky over at least 1 % of the height, the issue's measure),
        ``unsafe_joined_columns`` (the same counting only the false sky joined to the top sky
        run, i.e. what lowers the skyline the reconstruction reads), ``columns`` (columns with
        a valid pixel).
    """
    p = np.asarray(pred, bool)
    v = np.ones_like(p) if valid is None else np.asarray(valid, bool)
    # the rates shared with `predisat evaluate-sky` (one definition: photoeval's)
    c = sky_safety_counts(p, truth, v)
    false = p & ~np.asarray(truth, bool) & v
    # false sky joined to the top sky run of the prediction: what moves the skyline down
    top = np.logical_and.accumulate(p | ~v, axis=0) & v
    joined = (false & top).sum(axis=0)
    return {
        "false_sky_px": c["false_sky_px"],
        "non_sky_px": c["non_sky_px"],
        "unsafe_columns": c["unsafe_columns"],
        "unsafe_joined_columns": int((joined >= UNSAFE_COLUMN_FRACTION * p.shape[0]).sum()),
        "columns": c["n_columns"],
    }
