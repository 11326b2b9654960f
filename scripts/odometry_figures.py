"""Figure of the ETCS confidence interval along a simulated odometer (docs/odometry.md).

A train accelerates to 20 m/s, cruises, brakes to a stop, dwells and leaves again (the locator
campaign's stop-and-go profile) over about 4 km. The odometer sits on a driven and braked axle
(slip and slide) with a Doppler radar. Balise groups as in the source's figure: A (reference,
``Q_REFERENCE = 1``), B (not a reference), C (at a known distance from B), D (reference). The
figure shows the estimated front end and the max / min safe front ends minus the true front,
and prints the largest violation (there must be none).

Usage::

    PYTHONPATH=. .venv/bin/python scripts/odometry_figures.py \
        --out docs/figures/odometry_confidence.png
"""

from __future__ import annotations

import argparse

import numpy as np

from locator.odometry.confidence import BalisePassage, OdometerAccuracy, safe_fronts
from locator.odometry.odometer import OdometerConfig, simulate_odometer, true_distance_m
from predisat.availability.trainrun import SpeedProfile

PROFILE_T_S = [0.0, 40.0, 70.0, 100.0, 160.0, 200.0, 1.0e4]
PROFILE_V_MPS = [0.0, 20.0, 20.0, 0.0, 0.0, 20.0, 20.0]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=4)
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg = OdometerConfig.motor_axle(radar=True)
    acc = OdometerAccuracy.from_config(cfg)
    profile = SpeedProfile.from_time_table(PROFILE_T_S, PROFILE_V_MPS)
    t = np.arange(0.0, 330.0, cfg.cycle_s)
    truth = true_distance_m(profile.speed_at, t)
    log = simulate_odometer(t, truth, cfg, seed=args.seed)
    start = 1000.0
    at = {name: int(np.searchsorted(truth, d)) for name, d in
          (("A", 50.0), ("B", 1200.0), ("C", 2400.0), ("D", 3600.0))}  # fmt: skip
    passages = [
        BalisePassage(at["A"], start + truth[at["A"]], 1.0, q_reference=True),
        BalisePassage(at["B"], start + truth[at["B"]], 1.0, q_reference=False),
        BalisePassage(at["C"], start + truth[at["C"]], 1.0, q_reference=False, known_from=1),
        BalisePassage(at["D"], start + truth[at["D"]], 1.0, q_reference=True),
    ]
    sf = safe_fronts(log.dist_m, passages, acc, antenna_to_front_m=5.0)
    front = start + truth + 5.0
    ok = np.isfinite(sf.est_front_m)
    viol = np.maximum(sf.min_safe_front_m - front, front - sf.max_safe_front_m)[ok]
    print(f"odometer: over {100 * acc.over_rel:.2f} %, under {100 * acc.under_rel:.2f} % + "
          f"{acc.abs_error_m:g} m; slip/slide cycles {int(log.slip.sum())}; "
          f"largest violation {viol.max():+.2f} m (<= 0: none)")  # fmt: skip
    fig, ax = plt.subplots(figsize=(9, 4.2))
    x = truth[ok]
    ax.plot(x, (sf.est_front_m - front)[ok], "k", lw=1, label="estimated front - true front")
    ax.plot(x, (sf.max_safe_front_m - front)[ok], "--", color="tab:red",
            label="max safe front (D_DOUBTUNDER)")  # fmt: skip
    ax.plot(x, (sf.min_safe_front_m - front)[ok], "--", color="tab:blue",
            label="min safe front (D_DOUBTOVER)")  # fmt: skip
    for p, name in zip(passages, "ABCD", strict=True):
        ax.axvline(truth[p.index], color="grey", lw=0.6)
        ax.text(truth[p.index], ax.get_ylim()[1] * 0.9, f" {name}", fontsize=9)
    ax.set_xlabel("true distance run (m)")
    ax.set_ylabel("m, relative to the true front")
    ax.set_title("ETCS confidence interval: A, D reference; B not; C at a known distance from B")
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
