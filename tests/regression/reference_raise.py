"""A panorama's low-confidence raise as it was taken until 2026-12-07: down each image column.

On a canted panorama it voided whole frames (``docs/rigs.md``, "The panorama's low-confidence
raise taken on the grid's columns"); ``predisat.reconstruct.skyline`` now raises per grid
column. Kept as the reference that, on a level panorama, the grid's raise is never lower than
(``tests/predisat/reconstruct/test_skyline.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["reference_raise_skyline_deg"]


def reference_raise_skyline_deg(
    sky: NDArray,
    cols: NDArray,
    raise_deg: float,
    el_deg: NDArray,
    from_row: NDArray | None = None,
) -> NDArray:
    """The raise as an angle: the top sky run of each column of ``cols`` loses its lowest
    pixels whose elevation ``el_deg`` (H, W) lies less than ``raise_deg`` above the skyline's
    (the top edge of the first obstacle pixel, halfway between the two pixels' elevations;
    the last sky pixel's for a column sky to the bottom), and every sky pixel below. ``inf``
    voids the whole run; ``from_row``: the row each column's search starts from."""
    out = np.array(sky, np.bool_)
    c = np.unique(np.asarray(cols, np.int64))
    top = np.zeros(c.size, np.int64) if from_row is None else np.asarray(from_row, np.int64)[c]
    _raise_columns_deg(out, c, top, np.asarray(el_deg, np.float64), float(raise_deg))
    return out


@njit(nogil=True)
def _raise_columns_deg(
    sky: NDArray, cols: NDArray, top: NDArray, el_deg: NDArray, raise_deg: float
) -> None:
    """:func:`reference_raise_skyline_deg` in place (pixels up the run while within the angle)."""
    n = sky.shape[0]
    for k in range(cols.size):
        c = cols[k]
        start = max(top[k], 0)
        while start < n and not sky[start, c]:
            start += 1
        end = start
        while end < n and sky[end, c]:
            end += 1
        if end == start:  # no sky run: only sky below, which goes
            cut = start
        else:
            e0 = el_deg[end - 1, c]
            base = 0.5 * (e0 + el_deg[end, c]) if end < n else e0
            cut = end
            # a NaN elevation counts as within the angle (the safe side: more goes)
            while cut > start and not el_deg[cut - 1, c] - base >= raise_deg:
                cut -= 1
        for r in range(cut, n):
            sky[r, c] = False
