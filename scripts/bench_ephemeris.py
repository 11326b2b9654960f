"""Broadcast ephemeris evaluated one epoch at a time, as `locator run` does, against one call for
all the epochs (the same arithmetic batched), on a day's navigation file.

Usage::

    python scripts/bench_ephemeris.py NAV [NAV ...] [--epochs 2880] [--step 30]

Prints both times, their ratio, and checks that the per-epoch positions, clocks and reasons
equal the batched ones (bit for bit).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from predisat.gnss.ephemeris import Ephemeris


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("nav", nargs="+")
    ap.add_argument("--epochs", type=int, default=2880)
    ap.add_argument("--step", type=float, default=30.0)
    args = ap.parse_args()
    eph = Ephemeris.from_rinex(args.nav)
    t0 = float(np.median(eph.kepler.ref_gps_s)) - 0.5 * args.epochs * args.step  # type: ignore[union-attr]
    t = t0 + args.step * np.arange(args.epochs)
    sats = eph.satellites
    start = time.perf_counter()
    pos_b, clk_b, st_b = eph.evaluate(t, sats)
    batched = time.perf_counter() - start
    start = time.perf_counter()
    rows = [eph.evaluate(t[k : k + 1], sats) for k in range(len(t))]
    per_epoch = time.perf_counter() - start
    pos = np.concatenate([r[0] for r in rows])
    clk = np.concatenate([r[1] for r in rows])
    reasons = all(np.array_equal(r[2].reason, st_b.reason[k : k + 1]) for k, r in enumerate(rows))
    same = reasons and np.array_equal(pos, pos_b, equal_nan=True)
    same = same and np.array_equal(clk, clk_b, equal_nan=True)
    print(f"{len(eph.kepler or [])} Kepler records, {len(sats)} satellites, {len(t)} epochs: "
          f"batched {batched:.2f} s, one epoch at a time {per_epoch:.2f} s "
          f"({1000 * per_epoch / len(t):.2f} ms per epoch); ratio {per_epoch / batched:.1f}; "
          f"identical: {same}")


if __name__ == "__main__":
    main()
