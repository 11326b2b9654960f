"""Figure of partitioned trust at one epoch of the demo's run (docs/locator.md).

Re-locates the simulated run of a ``predisat demo`` folder with the pipeline masks and
partitioned trust, takes the first claimed epoch whose predicted interval splits into
stretches of which at least two claim, with a claim shorter than 80 % of the prediction, and
draws over the predicted interval which satellites each mask position trusts, the stretches,
each stretch's fix (its claim, the part kept; without the heading check) and the claim::

    .venv/bin/python scripts/partition_figure.py --demo /tmp/fresh13/main/demo_out \\
        --out docs/figures/locator_partition.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from locator.fde import LocatorConfig, locate
from locator.partition import combine_stretches, trust_stretches
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.selection import direction_at
from locator.sim.simfile import SimRun
from locator.sources import SimSource
from predisat.masks.fileformat import read_masks
from predisat.synth.world import World
from predisat.track.map import demo_track


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--demo", required=True, type=Path, help="a `predisat demo --out` folder")
    p.add_argument("--out", required=True, type=Path, help="PNG to write")
    args = p.parse_args()

    sim_dir = args.demo / "locator" / "simulation"
    sim = SimRun.read(sim_dir)
    world = World.load(args.demo / "truth" / "world.npz", demo_track())
    path = AntennaPath(world.track, float(sim.meta["antenna_height_m"]))
    masks = read_masks(args.demo / "masks")
    cfg = RunConfig(LocatorConfig(), trust="masks", trust_stretches=3)
    source = SimSource(sim, constellation="gps")
    ep = run_locator(path, source, start_chainage_m=float(sim.chainage_m[0]), config=cfg,
                     masks=masks)  # fmt: skip
    for k in np.flatnonzero(ep["claim"].to_numpy()):
        lo, hi = float(ep["pred_lo_m"].iloc[k]), float(ep["pred_hi_m"].iloc[k])
        centre = 0.5 * (lo + hi)
        data = source.observe(int(k), path.ecef_at(centre))
        az, el = direction_at(path, centre, data.sat_ecef_m)
        st = trust_stretches(masks, lo, hi, az, el, sats=data.sats)
        if len(st) < 2:
            continue
        fixes = []
        for s in st:
            idx = np.flatnonzero(s.selection.trusted)
            fixes.append(None if len(idx) < 2 else locate(
                path, data.sat_ecef_m[idx], data.pseudorange_m[idx], el[idx],
                prior_m=0.5 * (s.lo_m + s.hi_m), config=cfg.locator,
                sats=[data.sats[i] for i in idx],
            ))  # fmt: skip
        claimed = [f is not None and f.safety_claim for f in fixes]
        f_lo = [np.nan if f is None else f.lo_m for f in fixes]
        f_hi = [np.nan if f is None else f.hi_m for f in fixes]
        est = [np.nan if f is None else f.chainage_m for f in fixes]
        comb = combine_stretches([s.lo_m for s in st], [s.hi_m for s in st], claimed, f_lo, f_hi,
                                 est)  # fmt: skip
        if comb.claim and sum(claimed) >= 2 and comb.hi_m - comb.lo_m < 0.8 * (hi - lo):
            break
    else:
        raise SystemExit("no epoch of this run with two claimed stretches and a short claim")
    truth = float(sim.chainage_m[k])

    # which satellites each mask position in the prediction trusts
    ch = masks.chainage_m[(masks.chainage_m >= lo - 5.0) & (masks.chainage_m <= hi + 5.0)]
    eff = masks.mask_at(ch[:, None], az[None, :])
    vis = el[None, :] > eff  # (cells, n_sat)
    keep = vis.any(axis=0)
    fig = Figure(figsize=(9, 5.2), layout="constrained")
    ax, bx = fig.subplots(2, 1, sharex=True, height_ratios=[3, 2])
    names = np.asarray(data.sats)[keep]
    for row, _name in enumerate(names):
        ax.scatter(ch[vis[:, keep][:, row]], np.full(vis[:, keep][:, row].sum(), row), s=14,
                   marker="s", color="#2166ac")  # fmt: skip
    ax.set_yticks(range(len(names)), names, fontsize=7)
    ax.set_ylabel("satellite (trusted at the mask position)")
    for s in st[1:]:
        ax.axvline(s.lo_m, color="k", lw=0.8, ls="--")
    ax.set_title(f"epoch {k}: predicted interval {lo:.0f}-{hi:.0f} m, {len(st)} stretches "
                 f"(trusted {', '.join(str(int(s.selection.trusted.sum())) for s in st)}; "
                 f"the single set: {int(vis.all(axis=0).sum())})", fontsize=9)  # fmt: skip
    y = 0
    bx.plot([lo, hi], [y, y], color="0.6", lw=6, solid_capstyle="butt", label="prediction")
    for j, (s, f) in enumerate(zip(st, fixes, strict=True)):
        y = j + 1
        bx.plot([s.lo_m, s.hi_m], [y, y], color="0.85", lw=8, solid_capstyle="butt")
        if f is not None:
            bx.plot([f.lo_m, f.hi_m], [y, y], color="#ef8a62" if claimed[j] else "#bbbbbb", lw=2,
                    label="stretch fix's claim" if j == 0 else None)  # fmt: skip
            a, b = max(s.lo_m, f.lo_m), min(s.hi_m, f.hi_m)
            if claimed[j] and a <= b:
                bx.plot([a, b], [y, y], color="#b2182b", lw=5, solid_capstyle="butt",
                        label="part kept" if j == 0 else None)  # fmt: skip
    y = len(st) + 1
    bx.plot([comb.lo_m, comb.hi_m], [y, y], color="#1b7837", lw=6, solid_capstyle="butt",
            label=f"claim ({comb.hi_m - comb.lo_m:.0f} m)")  # fmt: skip
    bx.axvline(truth, color="k", lw=1, label="truth")
    bx.set_yticks(range(len(st) + 2), ["prediction", *(f"stretch {j + 1}" for j in range(len(st))),
                                       "epoch"])  # fmt: skip
    bx.set_xlim(lo - 0.3 * (hi - lo), hi + 0.3 * (hi - lo))
    bx.set_xlabel("chainage (m)")
    bx.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.savefig(args.out, dpi=110)
    print(f"epoch {k}: {len(st)} stretches, claim {comb.lo_m:.1f}-{comb.hi_m:.1f} m, "
          f"truth {truth:.1f} m -> {args.out}")


if __name__ == "__main__":
    main()
