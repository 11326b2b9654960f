"""Write ``predisat/data/land_0p1deg.npz``: where there is land, on a 0.1 deg grid.

Usage::

    pip install global-land-mask && python scripts/make_land_grid.py

The source is the 1 km (1/120 deg) land mask of ``global-land-mask`` (NOAA's GLOBE data, public
domain): 21 600 x 43 200 cells, 940 MB in memory and 1-2 s to load, which every track file's
load paid for a yes / no per 100 m. A 0.1 deg cell is land when any of its 12 x 12 source cells
is; packed to bits (1 800 x 3 600), rows from 90 N southwards, columns from 180 W eastwards.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from global_land_mask import globe

OUT = Path(__file__).resolve().parents[1] / "predisat" / "data" / "land_0p1deg.npz"
STEP = 12  # source cells per 0.1 deg


def main() -> None:
    # the package's grid marks water (is_land is its negation); row 0 at 90 N, column 0 at 180 W
    land = ~np.asarray(globe._mask, bool)
    assert land.shape == (180 * 10 * STEP, 360 * 10 * STEP), land.shape
    assert globe.is_land(50.55, 4.69) and not globe.is_land(4.69, 50.55)  # Belgium; the sea
    coarse = land.reshape(1800, STEP, 3600, STEP).any(axis=(1, 3))
    np.savez_compressed(OUT, land=np.packbits(coarse, axis=1), shape=np.array(coarse.shape))
    print(f"{OUT}: {coarse.mean():.3f} of the cells hold land, {OUT.stat().st_size} bytes")


if __name__ == "__main__":
    main()
