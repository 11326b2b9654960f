"""A failed Doppler radar through a tunnel: safe fronts with and without the disputed distance.

The ETCS odometer believes its radar where wheel and radar disagree (slip and slide). A radar
that loses its echo (reads 0), freezes, or reads a wrong scale is then believed too; in a
tunnel no satellite corrects it. The odometer keeps the distance between the two sensors on
those cycles as a *disputed* distance (``OdometerLog.extra_ahead_m`` / ``extra_behind_m``)
and the locator widens its interval by it. This trial runs the locator campaign's worlds that
hold a tunnel, with the radar failing from 200 m before the tunnel to its end, and counts the
epochs whose true front end lies outside the safe fronts, with the disputed distance used and
with it dropped (the behaviour before it existed), side by side.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/radar_fault_trial.py --cache /tmp/rf_cache \\
        [--runs 2] [--speed-kmh 80] [--profile cruise|stopgo]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from locator.balises.campaign import locate_with_odometry, safe_front_check
from locator.campaign import PROFILE_T_S, PROFILE_V_MPS, WORLDS, calibrate, load_world
from locator.fde import LocatorConfig
from locator.odometry.odometer import OdometerConfig, RadarFault
from locator.odometry.simulated import odometer_along_run
from locator.run import RunConfig
from locator.sathia import AntennaPath
from locator.sim.multipath import ReflectorIndex
from locator.sim.simulate import simulate_run
from predisat.availability.satellites import default_ephemeris, default_window
from predisat.availability.trainrun import SpeedProfile
from predisat.gnss.errormodel import IntervalModel

FAULTS = {
    "zero": lambda a, b: RadarFault(a, b, "zero"),
    "frozen": lambda a, b: RadarFault(a, b, "frozen"),
    "scaled 0.5": lambda a, b: RadarFault(a, b, "scaled", 0.5),
    "scaled 1.3": lambda a, b: RadarFault(a, b, "scaled", 1.3),
}
ODOMETERS = {"trailer-radar": OdometerConfig(), "motor-radar": OdometerConfig.motor_axle()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--runs", type=int, default=2, help="runs per tunnel")
    ap.add_argument("--speed-kmh", type=float, default=80.0, help="cruise speed")
    ap.add_argument("--profile", choices=("cruise", "stopgo"), default="cruise",
                    help="constant speed, or the locator campaign's stop-and-go profile (a "
                    "frozen radar matters where the speed changes)")  # fmt: skip
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    eph = default_ephemeris()
    model = calibrate(args.cache)
    rows = []
    for spec in WORLDS:
        data = load_world(spec, args.cache)
        world = data.world
        tunnels = [s for s in world.spec.stretches if s.kind == "tunnel"]
        if not tunnels:
            continue
        index = ReflectorIndex(world)
        path = AntennaPath(world.track, 4.0)
        for tun in tunnels:
            for run in range(args.runs):
                start = max(world.extent_m[0] + 15.0, tun.start_m - 600.0)
                v = args.speed_kmh / 3.6
                if args.profile == "cruise":
                    profile = SpeedProfile.constant(v)
                else:
                    profile = SpeedProfile.from_time_table(list(PROFILE_T_S), list(PROFILE_V_MPS))
                span = min(tun.end_m + 300.0, world.extent_m[1] - 15.0) - start
                grid = np.arange(0.0, 3000.0, 0.5)
                reached = profile.distance_at(grid)
                duration = float(np.floor(np.interp(span, reached, grid)))
                t0 = default_window()[0] + (0.137 + 0.618 * run) % 1.0 * 86400.0
                sim = simulate_run(world, eph, start, t0, profile, duration, 1.0, direction=1,
                                   seed=run, reflectors=index)  # fmt: skip
                loc = LocatorConfig(model=IntervalModel.for_risk(1e-4, model.error), budget=None)
                cfg = RunConfig(loc, trust="masks")
                # the radar fails from 200 m before the tunnel to its end
                fail_s = t0 + float(np.interp(tun.start_m - 200.0 - start, reached, grid))
                end_s = t0 + float(np.interp(tun.end_m - start, reached, grid))
                for oname, ocfg in ODOMETERS.items():
                    for fname, make in FAULTS.items():
                        log = odometer_along_run(sim, ocfg, run, make(fail_s, end_s)).log
                        dropped = replace(
                            log,
                            extra_ahead_m=np.zeros(len(log.t_s)),
                            extra_behind_m=np.zeros(len(log.t_s)),
                        )
                        for variant, lg in (("disputed", log), ("dropped", dropped)):
                            t1 = time.perf_counter()
                            r = locate_with_odometry(
                                sim, path, cfg, masks=data.masks, odometer=ocfg, log=lg
                            )
                            sf = safe_front_check(r)
                            ep = r.epochs
                            inside = (ep["truth_m"] >= tun.start_m) & (ep["truth_m"] < tun.end_m)
                            length = (ep["fused_hi_m"] - ep["fused_lo_m"])[inside]
                            rows.append({
                                "world": spec.name,
                                "tunnel_m": f"{tun.start_m:.0f}-{tun.end_m:.0f}",
                                "run": run, "odometer": oname, "fault": fname,
                                "variant": variant, "epochs": int(sf["epochs"]),
                                "front_outside": int(sf["front_outside"]),
                                "front_outside_flagged": int(sf["front_outside_flagged"]),
                                "worst_miss_m": float(np.max(np.maximum.reduce([
                                    (ep["fused_lo_m"] - ep["truth_m"]).to_numpy(float),
                                    (ep["truth_m"] - ep["fused_hi_m"]).to_numpy(float),
                                    np.zeros(len(ep))]))),
                                "tunnel_len_p50_m": float(np.median(length)) if len(length)
                                else np.nan,
                                "claims": float(ep["claim"].mean()),
                                "s": time.perf_counter() - t1,
                            })  # fmt: skip
                            print(rows[-1], flush=True)
    df = pd.DataFrame(rows)
    out = args.cache / f"radar_fault_trial_{args.profile}.csv"
    df.to_csv(out, index=False)
    summary = df.groupby(["odometer", "fault", "variant"]).agg(
        runs=("run", "size"),
        epochs=("epochs", "sum"),
        front_outside=("front_outside", "sum"),
        flagged=("front_outside_flagged", "sum"),
        worst_miss_m=("worst_miss_m", "max"),
        tunnel_len_p50_m=("tunnel_len_p50_m", "median"),
        claims=("claims", "mean"),
    )
    print(summary.to_string())
    print(f"rows: {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
