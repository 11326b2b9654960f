"""The demo's locator rows with one trusted set against partitioned trust, side by side.

Re-locates the simulated run of a ``predisat demo`` folder (``DEMO/locator/simulation``, GPS,
as the demo's locator step) under its four trust rules (pipeline masks, true masks, no masks,
15 deg cut-off), for each pair-interval width (the integrity budget, ``k = 2``) and each
``RunConfig.trust_stretches`` asked, and prints claim share, interval median / p95 and HMI /
MI per row (``docs/locator.md``, "Partitioned trust")::

    .venv/bin/python scripts/partitioned_trust.py --demo /tmp/fresh13/main/demo_out \\
        --stretches 1 3
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from locator.evaluate import score_run, summarise
from locator.fde import LocatorConfig
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.sim.simfile import SimRun
from locator.sources import SimSource
from predisat.gnss.errormodel import IntervalModel
from predisat.gnss.integrity import IntegrityBudget
from predisat.masks.fileformat import read_masks
from predisat.synth.world import World
from predisat.track.map import demo_track


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--demo", required=True, type=Path, help="a `predisat demo --out` folder")
    p.add_argument(
        "--stretches",
        type=int,
        nargs="+",
        default=[1, 3],
        help="RunConfig.trust_stretches values to compare (1: one trusted set)",
    )
    p.add_argument("--risk", type=float, default=1e-12, help="integrity risk per epoch")
    args = p.parse_args()

    sim_dir = args.demo / "locator" / "simulation"
    sim = SimRun.read(sim_dir)
    world = World.load(args.demo / "truth" / "world.npz", demo_track())
    path = AntennaPath(world.track, float(sim.meta["antenna_height_m"]))
    rules = {
        "pipeline masks": ("masks", read_masks(args.demo / "masks")),
        "true masks": ("masks", read_masks(sim_dir / "true_masks.parquet")),
        "no masks": ("none", None),
        "15 deg cut-off": ("cutoff", None),
    }
    widths = {
        f"budget {args.risk:g}": LocatorConfig(budget=IntegrityBudget(args.risk)),
        "k = 2": LocatorConfig(model=IntervalModel(k_sigma=2.0), budget=None),
    }
    rows = []
    for wname, loc in widths.items():
        for rule, (trust, masks) in rules.items():
            for n in args.stretches if trust == "masks" else [1]:
                cfg = RunConfig(loc, trust=trust, trust_stretches=n)
                src = SimSource(sim, constellation="gps")
                ep = run_locator(path, src, config=cfg, masks=masks,
                                 start_chainage_m=float(sim.chainage_m[0]))  # fmt: skip
                s = summarise(score_run(ep, sim.chainage_m))
                # a claim that tightens the prediction (fused interval > 1 m shorter)
                fused = ep["fused_hi_m"] - ep["fused_lo_m"]
                tight = ep["claim"] & (fused < ep["pred_hi_m"] - ep["pred_lo_m"] - 1.0)
                rows.append({"width": wname, "rule": rule, "stretches": n,
                             "claim %": 100 * s["claim_share"],
                             "tightens %": 100 * float(tight.mean()),
                             "len med m": s["length_median_m"], "len p95 m": s["length_p95_m"],
                             "|err| p95 m": s["abs_error_p95_m"], "HMI": int(s["hmi"]),
                             "HMI fix": int(s["hmi_fix"]), "MI": int(s["mi"]),
                             "epochs": int(s["epochs"])})  # fmt: skip
    print(pd.DataFrame(rows).round(1).to_string(index=False))


if __name__ == "__main__":
    main()
