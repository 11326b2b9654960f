"""Vectorised kernels on binned mask arrays: conservative azimuth resampling and range maxima.

Used by :mod:`predisat.masks.maskset` (trust queries) and :mod:`predisat.masks.fileformat`
(exporters). Bin ``k``
of an ``n_az``-bin mask is centred on ``k * az_step_deg`` and covers ``step`` degrees.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["RangeMax", "conservative_resample"]

# Closed-interval tests on bin edges tolerate this much rounding, always toward "touching".
_EDGE_TOL = 1e-9


def conservative_resample(
    mask_deg: ArrayLike, az_step_deg: float, az_deg: ArrayLike, half_width_deg: float
) -> NDArray:
    """Maximum of a binned mask over the bins touching a window around each azimuth.

    Bin ``k`` is the closed interval ``[k*step - step/2, k*step + step/2]``; the window is the
    closed interval ``[a - half_width_deg, a + half_width_deg]`` (circular). Touching at an
    edge counts, so the result is never below the mask anywhere in the window.

    Parameters
    ----------
    mask_deg : array_like, shape (..., n_az)
    az_step_deg : float
        ``360 / n_az``.
    az_deg : array_like, shape (k,) or shape (..., k)
        Sample azimuths, degrees; one row for all positions or one row per position.
    half_width_deg : float
        >= 0.

    Returns
    -------
    ndarray, shape (..., k), dtype of ``mask_deg``
    """
    m = np.asarray(mask_deg)
    n_az = m.shape[-1]
    if half_width_deg < 0:
        raise ValueError(f"half_width_deg must be >= 0, got {half_width_deg}")
    a = np.asarray(az_deg, float)
    k_lo = np.ceil((a - half_width_deg) / az_step_deg - 0.5 - _EDGE_TOL).astype(np.int64)
    k_hi = np.floor((a + half_width_deg) / az_step_deg + 0.5 + _EDGE_TOL).astype(np.int64)
    count = np.minimum(k_hi - k_lo + 1, n_az)
    lead = m.shape[:-1]
    k_lo = np.broadcast_to(k_lo, (*lead, a.shape[-1]))
    count = np.broadcast_to(count, k_lo.shape)
    out = np.take_along_axis(m, np.mod(k_lo, n_az), axis=-1)
    for off in range(1, int(count.max(initial=1))):
        vals = np.take_along_axis(m, np.mod(k_lo + off, n_az), axis=-1)
        out = np.where(off < count, np.maximum(out, vals), out)
    return out


class RangeMax:
    """Row-range maxima of a ``(n, m)`` array, for many ranges at once.

    A sparse table over blocks of ``block`` rows plus prefix/suffix maxima inside each block:
    memory about ``(2 + log2(n / block) / block)`` times the array, and each query costs a few
    row gathers (at most ``block`` for a range inside one block).

    Parameters
    ----------
    values : ndarray, shape (n, m)
        Not copied; must not change while the object is in use.
    block : int, optional
        Rows per block (default 16).
    """

    def __init__(self, values: NDArray, block: int = 16) -> None:
        n, m = values.shape
        self.block = block
        nb = -(-n // block)
        pad = np.full((nb * block - n, m), -np.inf, dtype=values.dtype)
        blocks = np.concatenate([values, pad]).reshape(nb, block, m)
        self.values = values
        self.prefix = np.maximum.accumulate(blocks, axis=1).reshape(nb * block, m)
        self.suffix = np.maximum.accumulate(blocks[:, ::-1], axis=1)[:, ::-1].reshape(-1, m)
        levels = [blocks.max(axis=1)]
        while 2 ** len(levels) <= nb:
            prev, w = levels[-1], 2 ** (len(levels) - 1)
            levels.append(np.maximum(prev[:-w], prev[w:]))
        self.levels = levels

    def query(self, i: NDArray, j: NDArray) -> NDArray:
        """Max of rows ``i[q]..j[q]`` (inclusive) for each q.

        Parameters
        ----------
        i, j : ndarray of int, shape (k,)
            ``0 <= i <= j < n``.

        Returns
        -------
        ndarray, shape (k, m)
        """
        bs = self.block
        if i.size == 1 and int(j[0]) - int(i[0]) < 4 * bs:  # one short range (a locator epoch)
            return self.values[int(i[0]) : int(j[0]) + 1].max(axis=0, keepdims=True)
        bi, bj = i // bs, j // bs
        out = np.empty((i.size, self.values.shape[1]), dtype=self.values.dtype)
        same = bi == bj
        if same.any():
            ii, jj = i[same], j[same]
            acc = self.values[ii]
            for off in range(1, int((jj - ii).max()) + 1):
                rows = np.minimum(ii + off, jj)  # past jj re-reads jj: harmless for a max
                acc = np.maximum(acc, self.values[rows])
            out[same] = acc
        cross = ~same
        if cross.any():
            ii, jj = i[cross], j[cross]
            acc = np.maximum(self.suffix[ii], self.prefix[jj])
            lo, hi = bi[cross] + 1, bj[cross] - 1
            full = lo <= hi
            if full.any():
                lo, hi = lo[full], hi[full]
                lev = np.floor(np.log2(hi - lo + 1)).astype(np.int64)
                mid = np.empty((lo.size, acc.shape[1]), dtype=acc.dtype)
                for L in np.unique(lev):
                    sel = lev == L
                    tab = self.levels[L]
                    mid[sel] = np.maximum(tab[lo[sel]], tab[hi[sel] - 2**L + 1])
                acc[full] = np.maximum(acc[full], mid)
            out[cross] = acc
        return out
