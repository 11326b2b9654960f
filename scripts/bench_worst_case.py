"""Benchmark: MaskSet.worst_case (block sparse table) against a plain per-query maximum.

Both answer the same queries (the bin-wise maximum effective mask over every position whose
cell touches ``[lo, hi]``) on a 3 000-position mask set; the baseline slices the cells of each
query and takes numpy's max. Prints both times, the ratio and whether the answers agree.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/bench_worst_case.py [--queries 20000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from predisat.masks.maskset import MaskSet


def _mask_set(n_pos: int, seed: int) -> MaskSet:
    rng = np.random.default_rng(seed)
    ch = np.arange(n_pos) * 10.0
    el = rng.uniform(0.0, 40.0, (n_pos, 360))
    return MaskSet.from_arrays(ch, np.full(n_pos, 50.0), np.full(n_pos, 4.0), 100.0,
                               np.zeros(n_pos), el, margin_deg=1.0)  # fmt: skip


def _baseline(m: MaskSet, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    b, eff = m.cell_bounds_m, m.effective_mask_deg
    i0 = np.searchsorted(b[1:], lo, side="left")  # first cell whose upper edge reaches lo
    i1 = np.searchsorted(b[:-1], hi, side="right")  # past the last cell starting <= hi
    return np.stack([eff[a:z].max(axis=0) for a, z in zip(i0, i1, strict=True)])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--queries", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    m = _mask_set(3000, 1)
    rng = np.random.default_rng(2)
    lo = rng.uniform(0.0, 29_000.0, args.queries)
    hi = lo + rng.uniform(0.0, 600.0, lo.size)
    m.worst_case(lo[:10], hi[:10])  # build the tables once, as the engine does
    t_new, t_base = [], []
    for _ in range(args.repeat):  # alternate, so that the machine's load hits both
        t = time.perf_counter()
        new = m.worst_case(lo, hi)
        t_new.append(time.perf_counter() - t)
        t = time.perf_counter()
        base = _baseline(m, lo, hi)
        t_base.append(time.perf_counter() - t)
    same = bool(np.array_equal(new, base))
    print(f"{args.queries} queries over {m.n_pos} positions x {m.n_az} bins")
    print(f"worst_case {min(t_new):.3f} s, per-query max {min(t_base):.3f} s, "
          f"ratio {min(t_base) / min(t_new):.1f}x, same answers: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
