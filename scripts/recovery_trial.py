"""The odometry recovery (``RunConfig.odometry_recover_s``) on healthy and faulty runs.

A recovery sets a suspect odometer aside for the motion bound, so that a lasting odometer
fault or a wrong start claims again; it must not let a lasting satellite fault claim either.
Runs of the locator campaign's worlds (both directions, cruise and stop-and-go, the simulated
trailer-axle odometer, masks trusted, k for 1e-4 per pair) with the recovery off and on, side
by side, under four conditions: a healthy run; a start 300 or 600 m off (beyond the +-50 m of
the start uncertainty, as a restart from a stored position the train has left; they straddle
the sky check's 300 m margin); an odometer whose direction channel is stuck backward. The
campaign's multipath is always on (NLOS signals given to the locator). Counts the satellite
claims, the claims whose interval misses the truth (HMI) and the epochs whose fused interval
misses it unflagged.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/recovery_trial.py --cache /tmp/rf [--runs 2]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from locator.campaign import PROFILE_T_S, PROFILE_V_MPS, WORLDS, calibrate, load_world
from locator.fde import LocatorConfig
from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.odometer import OdometerConfig
from locator.odometry.simulated import odometer_along_run
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.sim.multipath import ReflectorIndex
from locator.sim.simulate import simulate_run
from locator.sources import SimSource
from predisat.availability.satellites import default_ephemeris, default_window
from predisat.availability.trainrun import SpeedProfile
from predisat.gnss.errormodel import IntervalModel

CONDITIONS = ("healthy", "start 300 m off", "start 600 m off", "stuck direction")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--runs", type=int, default=2, help="runs per world, profile and direction")
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    eph = default_ephemeris()
    model = calibrate(args.cache)
    loc = LocatorConfig(model=IntervalModel.for_risk(1e-4, model.error), budget=None)
    ocfg = OdometerConfig()
    acc = OdometerAccuracy.from_config(ocfg)
    rows = []
    for spec in WORLDS:
        data = load_world(spec, args.cache)
        world = data.world
        index = ReflectorIndex(world)
        path = AntennaPath(world.track, 4.0)
        lo, hi = world.extent_m
        for prof in ("cruise", "stopgo"):
            profile = (SpeedProfile.constant(80.0 / 3.6) if prof == "cruise" else
                       SpeedProfile.from_time_table(list(PROFILE_T_S), list(PROFILE_V_MPS)))
            grid = np.arange(0.0, 3000.0, 0.5)
            duration = float(np.floor(np.interp(hi - lo - 30.0, profile.distance_at(grid), grid)))
            for run in range(args.runs):
                for direction in (1, -1):
                    seed = 1000 * run + (7 if direction > 0 else 3) + 50 * (prof == "cruise")
                    t0 = default_window()[0] + (0.29 + 0.618 * seed) % 1.0 * 86400.0
                    start = lo + 15.0 if direction > 0 else hi - 15.0
                    sim = simulate_run(world, eph, start, t0, profile, duration, 1.0,
                                       direction=direction, seed=seed, reflectors=index)
                    so = odometer_along_run(sim, ocfg, seed)
                    for cond in CONDITIONS:
                        # a stuck direction channel: the distance counted backward
                        odo = -so.epoch_odo_m if cond == "stuck direction" else so.epoch_odo_m
                        off = {"start 300 m off": 300.0, "start 600 m off": 600.0}.get(cond, 0.0)
                        start_err = -off * direction
                        for recover in (None, 20.0):
                            cfg = RunConfig(loc, trust="masks", odometry_recover_s=recover,
                                            odometer=acc)
                            source = SimSource(sim, odometer=odo, odometer_extra=so.epoch_extra_m)
                            start_m = float(np.clip(sim.chainage_m[0] + start_err, 0.0,
                                                    path.length_m))
                            ep = run_locator(path, source, start_chainage_m=start_m, config=cfg,
                                             masks=data.masks)
                            ep["truth_m"] = np.asarray(sim.chainage_m, float)
                            truth = ep["truth_m"].to_numpy(float)
                            claim = ep["claim"].to_numpy(bool)
                            miss = ~((ep["lo_m"] <= truth + 1e-9) & (truth <= ep["hi_m"] + 1e-9))
                            f_miss = ~((ep["fused_lo_m"] <= truth + 1e-9)
                                       & (truth <= ep["fused_hi_m"] + 1e-9))
                            doubtful = ep["fusion"].isin(["conflict", "suspect"]).to_numpy()
                            rows.append({
                                "world": spec.name, "profile": prof, "run": run,
                                "direction": direction, "condition": cond,
                                "recover_s": recover, "epochs": len(ep),
                                "claims": int(claim.sum()),
                                "hmi": int((claim & miss.to_numpy()).sum()),
                                "fused_outside_unflagged": int((f_miss.to_numpy()
                                                                & ~doubtful).sum()),
                                "odometer_aside": int((~ep["odometer_used"]).sum()),
                            })  # fmt: skip
                            print(rows[-1], flush=True)
    df = pd.DataFrame(rows)
    df["recover_s"] = df["recover_s"].fillna(0.0)
    out = args.cache / "recovery_trial.csv"
    df.to_csv(out, index=False)
    summary = df.groupby(["condition", "recover_s"]).agg(
        runs=("run", "size"), epochs=("epochs", "sum"), claims=("claims", "sum"),
        hmi=("hmi", "sum"), fused_outside_unflagged=("fused_outside_unflagged", "sum"),
        odometer_aside=("odometer_aside", "sum"))
    summary["claim_share"] = summary["claims"] / summary["epochs"]
    print(summary.to_string())
    print(f"rows: {out} (recover_s 0 = off)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
