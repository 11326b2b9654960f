"""Morphology of sky masks: the thin-structure policy and connected components on row runs.

* :func:`remove_thin_obstacles` - obstacle features at most ``thin_px`` wide (wires, cables,
  twigs) become sky (module docstring of :mod:`predisat.sky.segment`, step 5 of the GrabCut
  method).
* :class:`RunComponents` - connected components of a boolean mask as horizontal runs: the
  regions, areas and bounding boxes of ``cv2.connectedComponentsWithStats`` at a tenth of its
  cost on sky masks (the region rules of the learned methods).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = ["RunComponents", "remove_thin_obstacles"]


def remove_thin_obstacles(sky_mask: ArrayLike, thin_px: int) -> NDArray[np.bool_]:
    """Apply the thin-structure policy: obstacle features at most ``thin_px`` wide become sky.

    An obstacle pixel is kept only if it belongs to a vertical run *and* to a horizontal run of
    at least ``thin_px + 1`` obstacle pixels (morphological openings with line elements).
    Wires and cables (thin across, whatever their direction), thin twigs and thin fringes are
    removed; masts, poles and buildings wider than ``thin_px`` and the corners of every large
    obstacle are kept.

    Parameters
    ----------
    sky_mask : array_like of bool, shape (H, W)
    thin_px : int
        Largest width, in pixels, of a structure counted as L-band transparent (0: no change).

    Returns
    -------
    ndarray of bool, shape (H, W)
        A new mask (the input is not modified).
    """
    sky = np.asarray(sky_mask, bool)
    if sky.ndim != 2:
        raise ValueError(f"sky_mask must be 2-D (H, W), got shape {sky.shape}")
    if thin_px < 0:
        raise ValueError(f"thin_px must be >= 0, got {thin_px}")
    if thin_px == 0:
        return sky.copy()
    obstacle = (~sky).astype(np.uint8)
    k = int(thin_px) + 1
    # Pad with obstacle so that features touching the border are judged on their visible part
    # as if they continued (a wall cut by the image edge is not thin).
    pad = k
    ob = cv2.copyMakeBorder(obstacle, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    vert = _line_opening(ob, k, vertical=True)
    horz = _line_opening(ob, k, vertical=False)
    kept = (vert & horz)[pad:-pad, pad:-pad].astype(bool)
    return np.asarray(sky | (obstacle.astype(bool) & ~kept))


def _line_opening(binary: NDArray, length: int, vertical: bool) -> NDArray:
    """Opening with a line of ``length`` pixels: keeps pixels in runs of at least ``length``.

    Explicit anchors (first pixel for the erosion, last for the dilation) make it exact for
    even lengths too, where ``cv2.morphologyEx`` would shift the result by one pixel.
    """
    kernel = np.ones((length, 1) if vertical else (1, length), np.uint8)
    first, last = (0, 0), ((0, length - 1) if vertical else (length - 1, 0))
    eroded = cv2.erode(binary, kernel, anchor=first, borderType=cv2.BORDER_REPLICATE)
    return np.asarray(cv2.dilate(eroded, kernel, anchor=last, borderType=cv2.BORDER_CONSTANT,
                                 borderValue=0))


@dataclass(frozen=True)
class RunComponents:
    """Connected components of a boolean mask, as horizontal runs of True pixels.

    The same regions, areas and bounding boxes as ``cv2.connectedComponentsWithStats`` (here
    numbered from 0 in the raster order of their first pixel; there is no background
    label), but no label image: the masks here hold a few large regions, a few hundred runs
    per frame, so the union-find works on runs and the rules paint or sum only the runs of
    the components they select.

    Attributes
    ----------
    row, start, stop : ndarray of int32, shape (n_runs,)
        Run ``k`` covers pixels ``row[k], start[k]:stop[k]``; runs in raster order.
    label : ndarray of int32, shape (n_runs,)
        Component of each run, ``0 .. n - 1``.
    area : ndarray of int64, shape (n,)
        Pixels per component.
    top, bottom, left, right : ndarray of int64, shape (n,)
        Bounding box per component, pixels: rows ``top:bottom``, columns ``left:right``.
    """

    row: NDArray[np.int32]
    start: NDArray[np.int32]
    stop: NDArray[np.int32]
    label: NDArray[np.int32]
    area: NDArray[np.int64]
    top: NDArray[np.int64]
    bottom: NDArray[np.int64]
    left: NDArray[np.int64]
    right: NDArray[np.int64]

    @classmethod
    def of(cls, mask: NDArray[np.bool_], connectivity: int = 8) -> RunComponents:
        """Components of the True pixels of a 2-D mask, 4- or 8-connected."""
        if connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
        m = np.ascontiguousarray(mask, np.bool_)
        if m.ndim != 2:
            raise ValueError(f"mask must be 2-D, got shape {m.shape}")
        return cls(*_run_components(m, connectivity == 8))

    @property
    def n(self) -> int:
        """Number of components."""
        return int(self.area.size)

    def paint(self, mask: NDArray[np.bool_], select: NDArray[np.bool_], value: bool) -> None:
        """Set the pixels of the selected components (``select``, shape (n,)) of ``mask``
        (C-contiguous, the shape the components came from) to ``value``, in place."""
        if not (mask.flags.c_contiguous and mask.dtype == np.bool_):
            raise ValueError("mask must be a C-contiguous bool array")
        _paint_runs(mask, self.row, self.start, self.stop, self.label,
                    np.asarray(select, np.bool_), bool(value))  # fmt: skip

    def sums(self, values: NDArray, select: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Sum of ``values`` (2-D, float32 or float64) over each selected component, in float64
        and raster order (what ``np.bincount(labels, values)`` gives, bit for bit); 0 for the
        others."""
        v = np.ascontiguousarray(values)
        return np.asarray(_sum_runs(v, self.row, self.start, self.stop, self.label,
                                    np.asarray(select, np.bool_)))  # fmt: skip

    def maxes(self, values: NDArray, select: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Largest of ``values`` (2-D, the shape the components came from) over each selected
        component, as float64; ``-inf`` for the others."""
        v = np.ascontiguousarray(values)
        return np.asarray(_max_runs(v, self.row, self.start, self.stop, self.label,
                                    np.asarray(select, np.bool_)))  # fmt: skip

    def touching(self, mask: NDArray[np.bool_], runs: NDArray[np.bool_] | None = None) -> NDArray:
        """Per component, whether any of its pixels (of the runs ``runs`` selects, shape
        (n_runs,); default all) is True in ``mask`` (2-D, the shape the components came
        from); shape (n,) of bool."""
        cs = np.cumsum(np.asarray(mask, bool), axis=1, dtype=np.int32)
        before = np.where(self.start > 0, cs[self.row, np.maximum(self.start - 1, 0)], 0)
        hit = cs[self.row, self.stop - 1] > before
        if runs is not None:
            hit &= np.asarray(runs, bool)
        return np.bincount(self.label, weights=hit, minlength=self.n) > 0


@njit(cache=True, nogil=True)
def _find_root(parent: NDArray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit(cache=True, nogil=True)
def _run_components(mask: NDArray, eight: bool) -> tuple[NDArray, ...]:
    """Runs of True pixels, their component labels and the components' areas and boxes
    (see :class:`RunComponents`). Two runs on neighbouring rows touch when their columns
    overlap (4-connectivity) or come within one column (8-connectivity)."""
    h, w = mask.shape
    cap = h * ((w + 1) // 2)
    row = np.empty(cap, np.int32)
    start = np.empty(cap, np.int32)
    stop = np.empty(cap, np.int32)
    parent = np.empty(cap, np.int32)
    ext = 1 if eight else 0
    n = 0
    prev0 = 0
    for r in range(h):
        line = mask[r]
        first = n
        c = 0
        while c < w:
            if line[c]:
                s = c
                c += 1
                while c < w and line[c]:
                    c += 1
                row[n] = r
                start[n] = s
                stop[n] = c
                parent[n] = n
                n += 1
            else:
                c += 1
        # merge with the runs of the row above (both lists sorted by column)
        j = prev0
        for i in range(first, n):
            lo = start[i] - ext
            hi = stop[i] + ext
            while j < first and stop[j] <= lo:
                j += 1
            k = j
            while k < first and start[k] < hi:
                a = _find_root(parent, i)
                b = _find_root(parent, k)
                if a < b:
                    parent[b] = a
                elif b < a:
                    parent[a] = b
                k += 1
        prev0 = first
    # every root is its component's first run in raster order
    label = np.empty(n, np.int32)
    n_comp = 0
    for i in range(n):
        p = _find_root(parent, i)
        if p == i:
            label[i] = n_comp
            n_comp += 1
        else:
            label[i] = label[p]
    area = np.zeros(n_comp, np.int64)
    top = np.full(n_comp, h, np.int64)
    bottom = np.zeros(n_comp, np.int64)
    left = np.full(n_comp, w, np.int64)
    right = np.zeros(n_comp, np.int64)
    for i in range(n):
        q = label[i]
        area[q] += stop[i] - start[i]
        top[q] = min(top[q], row[i])
        bottom[q] = max(bottom[q], row[i] + 1)
        left[q] = min(left[q], start[i])
        right[q] = max(right[q], stop[i])
    return row[:n], start[:n], stop[:n], label, area, top, bottom, left, right


@njit(cache=True, nogil=True)
def _paint_runs(
    mask: NDArray, row: NDArray, start: NDArray, stop: NDArray, label: NDArray,
    select: NDArray, value: bool,
) -> None:  # fmt: skip
    for i in range(row.size):
        if select[label[i]]:
            line = mask[row[i]]
            for c in range(start[i], stop[i]):
                line[c] = value


@njit(cache=True, nogil=True)
def _max_runs(
    values: NDArray, row: NDArray, start: NDArray, stop: NDArray, label: NDArray,
    select: NDArray,
) -> NDArray:  # fmt: skip
    out = np.full(select.size, -np.inf)
    for i in range(row.size):
        q = label[i]
        if select[q]:
            line = values[row[i]]
            for c in range(start[i], stop[i]):
                v = np.float64(line[c])
                if v > out[q]:
                    out[q] = v
    return out


@njit(cache=True, nogil=True)
def _sum_runs(
    values: NDArray, row: NDArray, start: NDArray, stop: NDArray, label: NDArray,
    select: NDArray,
) -> NDArray:  # fmt: skip
    out = np.zeros(select.size)
    for i in range(row.size):  # runs in raster order: each sum adds its pixels in that order
        q = label[i]
        if select[q]:
            line = values[row[i]]
            acc = out[q]
            for c in range(start[i], stop[i]):
                acc += np.float64(line[c])
            out[q] = acc
    return out
