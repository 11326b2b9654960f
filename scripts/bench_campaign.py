"""Benchmark: ``locator campaign``'s grid serial against a local Dask cluster of 1 and 2
workers (:func:`locator.campaign.run_campaign`), same jobs, fresh output folders.

Prints per scheduler the wall time (cluster start included), runs and located epochs (all
rules) per second, the ratio to serial, and whether the final tables are byte-identical to the
serial ones. The worlds and the error model come from ``--cache`` (built there when absent;
``/tmp/b34/cache`` holds the campaign's). One job is run first, untimed, to load the compiled
kernels.

Usage::

    .venv/bin/python scripts/bench_campaign.py [--cache /tmp/b34/cache] [--world canyon]
        [--runs 6] [--configs masks none cutoff15 masks_k2 masks_budget]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

from locator.campaign import (
    WORLDS,
    CampaignSetup,
    calibrate,
    jobs_for,
    load_world,
    run_campaign,
    run_job,
)
from predisat.scheduler import Scheduler

_FILES = ("epochs.parquet", "summary.csv", "summary.json")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("/tmp/b34/cache"))
    ap.add_argument("--world", default="canyon", choices=[w.name for w in WORLDS])
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--configs", nargs="+",
                    default=["masks", "none", "cutoff15", "masks_k2", "masks_budget"])  # fmt: skip
    args = ap.parse_args(argv)
    spec = next(w for w in WORLDS if w.name == args.world)
    setup = CampaignSetup(
        calibrate(args.cache), tuple(args.configs), 1e-12,
        {spec.name: load_world(spec, args.cache)},
    )  # fmt: skip
    jobs = jobs_for([spec.name], args.runs)
    run_job(setup, jobs_for([spec.name], args.runs + 1)[-1])  # warm-up, not in the grid
    schedulers = [Scheduler.serial(), Scheduler.local(1), Scheduler.local(2)]
    tmp = Path(tempfile.mkdtemp(prefix="bench_campaign_"))
    try:
        print(f"{len(jobs)} runs of world {spec.name}, rules {' '.join(args.configs)}")
        print(f"{'scheduler':<34} {'wall s':>7} {'runs/s':>7} {'epochs/s':>9} "
              f"{'vs serial':>9}  tables")  # fmt: skip
        base_s = 0.0
        for k, sch in enumerate(schedulers):
            out = tmp / f"out{k}"
            res = run_campaign(out, setup, jobs, sch)
            same = "(reference)"
            if k == 0:
                base_s = res.wall_s
            elif all((out / f).read_bytes() == (tmp / "out0" / f).read_bytes() for f in _FILES):
                same = "identical"
            else:
                same = "DIFFERENT"
            wall = res.wall_s
            print(f"{sch.describe():<34} {wall:7.1f} {len(jobs) / wall:7.2f} "
                  f"{len(res.frames) / wall:9.0f} {base_s / wall:8.2f}x  {same}")  # fmt: skip
    finally:
        shutil.rmtree(tmp)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
