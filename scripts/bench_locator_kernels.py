"""The locator's compiled pair solver and WLS beside the numpy code they replaced.

``locator.sathia.solve_pairs`` and ``locator.wls.solve_wls`` (compiled, ``locator.kernels``)
against ``tests/regression/reference_locator.py`` (the numpy code until 2026-12-04, verbatim),
alternately, on one epoch of ``--sats`` satellites (random sky above 10 deg) on a curved track
(a 300 m lead and an 800 m radius arc): every pair (passive integrity, the all-pairs mode),
three pairs (active integrity with >= 6 satellites) and the WLS. Both give the same bits
(checked here too). Prints microseconds per call (best of ``--repeat``) and the ratio.

Usage::

    .venv/bin/python scripts/bench_locator_kernels.py [--sats 30] [--repeat 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests' reference code

from locator.sathia import solve_pairs
from locator.wls import solve_wls
from tests.locator._scene import arc_path, random_sky, ranges, sky
from tests.regression.reference_locator import (
    reference_solve_pairs,
    reference_solve_wls,
)


def per_call_us(fn: Callable[[], object], seconds: float = 0.5) -> float:
    fn()
    n, t = 0, time.perf_counter()
    while time.perf_counter() - t < seconds:
        fn()
        n += 1
    return (time.perf_counter() - t) / n * 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sats", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    path = arc_path(800.0, 170.0, lead_m=300.0)
    x = path.ecef_at(1200.0)
    sat = sky(x, *random_sky(rng, args.sats, 10.0))
    sig = rng.uniform(1.0, 5.0, args.sats)
    rho = ranges(sat, x, sig, rng)
    three = np.array([[0, 1], [2, 3], [4, 5]])
    cases = {
        f"solve_pairs, all {args.sats * (args.sats - 1) // 2} pairs": (
            lambda: solve_pairs(path, sat, rho, sig, prior_m=1210.0),
            lambda: reference_solve_pairs(path, sat, rho, sig, prior_m=1210.0),
        ),
        "solve_pairs, 3 pairs": (
            lambda: solve_pairs(path, sat, rho, sig, three, prior_m=1210.0),
            lambda: reference_solve_pairs(path, sat, rho, sig, three, prior_m=1210.0),
        ),
        f"solve_wls, {args.sats} satellites": (
            lambda: solve_wls(path, sat, rho, sig, prior_m=1210.0),
            lambda: reference_solve_wls(path, sat, rho, sig, prior_m=1210.0),
        ),
    }
    print(f"{'call':<32} {'compiled us':>12} {'numpy us':>10} {'ratio':>7}  same bits")
    for label, (new, old) in cases.items():
        a, b = new(), old()
        same = all(
            np.array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f)), equal_nan=True)
            for f in a.__dataclass_fields__  # type: ignore[attr-defined]
        )
        tn = to = np.inf
        for _ in range(args.repeat):  # alternate so that both see the same machine load
            tn = min(tn, per_call_us(new))
            to = min(to, per_call_us(old))
        print(f"{label:<32} {tn:>12.1f} {to:>10.1f} {to / tn:>6.1f}x  {same}")
    print(f"ratio = numpy time / compiled time (best of {args.repeat}, one epoch per call)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
