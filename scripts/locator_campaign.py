"""Campaign of simulated train runs: what the masks buy the 1-D locator.

Synthetic worlds along Belgian line 144 (four ``WorldSpec.mixed`` stretches and the
Nice-Digne canyon recipe), trains with a station stop running both ways at start times spread
over the embedded navigation day (all constellations), 1 Hz. Every simulated run (LOS, code
multipath, NLOS through reflections, loss) is located with active integrity under:

* ``masks``   - the world's true masks (a perfect survey) with a 1 deg margin;
* ``pipeline``- on the demo world only, when ``--demo DIR`` is given: the masks that
  ``predisat process`` made from its rendered frames;
* ``none``    - every received signal;
* ``cutoff15``- a flat 15 deg elevation cut-off.

The error model is learned first (``locator.errorfit``) from six runs in a separate
calibration world (``WorldSpec.mixed`` over km 12.3-14.1, seed 99), direct signals only, and
used by every configuration. Pair intervals are ``+- k sigma_K`` with ``k = 3.89`` (a 1e-4
two-sided Gaussian risk per pair, the risk the source claims for its ``+- 2 xi``); ``masks_k2``
repeats the masks rule with the source's ``k = 2``, ``masks_budget`` with the default integrity
budget (:class:`predisat.gnss.integrity.IntegrityBudget`, ``locator run``'s default: each
epoch's ``k`` from 1e-12 per epoch and the disjoint pairs united; ``pipeline_budget`` the same
with the pipeline masks). ``--configs`` runs a subset
(job files then hold only those; give another ``--out``).

Per configuration: epochs, share of epochs per integrity mode, share with a safety claim,
interval length (median, 95th percentile, max) on claimed epochs, absolute error, and HMI
(truth outside a claimed interval), also before the heading/odometry checks (``hmi_fix``), the
epochs in each region of the Stanford diagram (``stanford_*``), and that diagram per
configuration (``stanford_<config>.png``, :func:`locator.plots.stanford_diagram`).

Jobs are written one Parquet file each under ``--out``; a rerun skips finished jobs.

Usage::

    .venv/bin/python scripts/locator_campaign.py --out campaign [--runs-per-world 88]
        [--workers 2] [--demo demo_out] [--configs masks masks_budget masks_k2]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from locator.errorfit import sim_residuals
from locator.evaluate import score_run, summarise
from locator.fde import LocatorConfig
from locator.intervals import fit_error_model
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.sim.multipath import ReflectorIndex
from locator.sim.simfile import SignalState
from locator.sim.simulate import simulate_run
from locator.sources import SimSource
from predisat.availability.satellites import default_ephemeris, default_window
from predisat.availability.trainrun import SpeedProfile
from predisat.gnss.errormodel import IntervalModel, read_error_model, write_error_model
from predisat.gnss.integrity import IntegrityBudget
from predisat.masks.maskset import MaskSet
from predisat.masks.truth import TrueMasks
from predisat.synth.truth import true_masks
from predisat.synth.world import World, WorldSpec
from predisat.track.map import demo_track

REPO = Path(__file__).resolve().parents[1]
MARGIN_DEG = 1.0
# (name, start m, end m, seed, recipe) on line 144 track A
WORLDS = [
    ("mixed-1", 1000.0, 3300.0, 11, None),
    ("mixed-2", 4000.0, 6300.0, 12, None),
    ("mixed-3", 7000.0, 9300.0, 13, None),
    ("mixed-4", 10000.0, 12300.0, 14, None),
    ("canyon", 0.0, 1300.0, 7, "surveys/nice_digne_canyon.yaml"),
]
# 0 -> 20 m/s in 40 s, cruise 30 s, brake to a stop in 30 s, dwell 60 s, go again
PROFILE_T_S = [0.0, 40.0, 70.0, 100.0, 160.0, 200.0, 1.0e4]
PROFILE_V_MPS = [0.0, 20.0, 20.0, 0.0, 0.0, 20.0, 20.0]


@dataclass(frozen=True)
class Job:
    world: str
    run: int
    t0_gps_s: float
    direction: int


CALIB_WORLD = ("calib", 12300.0, 14100.0, 99, None)


def calibrate(cache: Path) -> IntervalModel:
    """Learn the error model on the calibration world (cached in ``error_model.json``)."""
    path = cache / "error_model.json"
    if path.exists():
        return read_error_model(path)
    world = World.build(demo_track(), WorldSpec.mixed(*CALIB_WORLD[1:3], seed=CALIB_WORLD[3]), 99)
    eph, day = default_ephemeris(), default_window()[0]
    els, ress = [], []
    for r in range(6):
        sim = simulate_run(
            world, eph, world.extent_m[0] + 10.0, day + r * 4 * 3600 + 1800,
            SpeedProfile.constant(12.0), 140.0, 1.0, seed=500 + r,
        )  # fmt: skip
        e, res = sim_residuals(sim)
        els.append(e)
        ress.append(res)
    n = max(x.shape[1] for x in els)
    el = np.concatenate(
        [np.pad(x, ((0, 0), (0, n - x.shape[1])), constant_values=np.nan) for x in els]
    )
    res = np.concatenate(
        [np.pad(x, ((0, 0), (0, n - x.shape[1])), constant_values=np.nan) for x in ress]
    )
    model = IntervalModel(fit_error_model(el, res), k_sigma=2.0)
    write_error_model(path, model, {"data": "6 simulated runs of the calibration world, LOS only"})
    return model


def _world(name: str, cache: Path) -> tuple[World, MaskSet, MaskSet | None]:
    spec_row = next(w for w in WORLDS if w[0] == name) if name != "demo" else None
    wfile, mfile = cache / f"{name}_world.npz", cache / f"{name}_truth.npz"
    track = demo_track()
    if wfile.exists():
        world = World.load(wfile, track)
    else:
        assert spec_row is not None
        _, a, b, seed, recipe = spec_row
        if recipe:
            spec = WorldSpec.from_dict(yaml.safe_load((REPO / recipe).read_text()))
        else:
            spec = WorldSpec.mixed(a, b, seed=seed)
        world = World.build(track, spec, seed)
        world.save(wfile)
    if mfile.exists():
        tm = TrueMasks.load(mfile)
    else:
        tm = true_masks(world)
        tm.save(mfile)
    masks = MaskSet.from_arrays(
        tm.chainage_m, tm.lat_deg, tm.lon_deg, tm.h_m, tm.heading_deg, tm.mask_el_deg,
        margin_deg=MARGIN_DEG, provenance={"source": f"true masks of world {name}"},
    )  # fmt: skip
    return world, masks, None


_STATE: dict = {}


CONFIGS = ("masks", "none", "cutoff15", "masks_k2", "masks_budget", "pipeline", "pipeline_budget")


def _init(cache: str, demo: str | None, configs: tuple[str, ...] = CONFIGS) -> None:
    _STATE.update(cache=Path(cache), demo=demo, worlds={}, eph=default_ephemeris(),
                  model=read_error_model(Path(cache) / "error_model.json"),
                  configs=configs)  # fmt: skip


def _get_world(name: str) -> tuple[World, MaskSet, MaskSet | None, ReflectorIndex]:
    if name not in _STATE["worlds"]:
        w: tuple[World, MaskSet, MaskSet | None]
        if name == "demo":
            from predisat.masks.fileformat import read_masks

            d = Path(_STATE["demo"])
            world = World.load(d / "truth" / "world.npz", demo_track())
            tm = TrueMasks.load(d / "truth" / "true_masks.npz")
            masks = MaskSet.from_arrays(
                tm.chainage_m, tm.lat_deg, tm.lon_deg, tm.h_m, tm.heading_deg, tm.mask_el_deg,
                margin_deg=MARGIN_DEG,
            )  # fmt: skip
            w = (world, masks, read_masks(d / "masks" / "masks.parquet"))
        else:
            w = _world(name, _STATE["cache"])
        _STATE["worlds"][name] = (*w, ReflectorIndex(w[0]))
    return _STATE["worlds"][name]


def run_job(job: Job) -> pd.DataFrame:
    world, masks, pipeline, index = _get_world(job.world)
    lo, hi = world.extent_m
    start = lo + 15.0 if job.direction > 0 else hi - 15.0
    profile = SpeedProfile.from_time_table(PROFILE_T_S, PROFILE_V_MPS)
    span = hi - lo - 30.0
    duration = float(
        np.interp(span, profile.distance_at(np.arange(0, 2000.0)), np.arange(0, 2000.0))
    )
    seed = zlib.crc32(job.world.encode()) % 10007 * 1000 + job.run
    sim = simulate_run(
        world, _STATE["eph"], start, job.t0_gps_s, profile, np.floor(duration), 1.0,
        direction=job.direction, seed=seed, reflectors=index,
    )  # fmt: skip
    path = AntennaPath(world.track, 4.0)
    src = SimSource(sim)
    learned = _STATE["model"]
    # k for a 1e-4 two-sided Gaussian risk per pair (the risk the source states for its +-2 xi)
    loc = LocatorConfig(model=IntervalModel.for_risk(1e-4, learned.error))
    configs = {
        "masks": (RunConfig(loc, trust="masks"), masks),
        "none": (RunConfig(loc, trust="none"), None),
        "cutoff15": (RunConfig(loc, trust="cutoff", cutoff_deg=15.0), None),
        "masks_k2": (RunConfig(LocatorConfig(model=learned), trust="masks"), masks),
        "masks_budget": (
            RunConfig(LocatorConfig(model=learned, budget=IntegrityBudget()), trust="masks"),
            masks,
        ),
    }
    if pipeline is not None:
        configs["pipeline"] = (RunConfig(loc, trust="masks"), pipeline)
        configs["pipeline_budget"] = (
            RunConfig(LocatorConfig(model=learned, budget=IntegrityBudget()), trust="masks"),
            pipeline,
        )
    configs = {k: v for k, v in configs.items() if k in _STATE.get("configs", CONFIGS)}
    state = {s: sim.state[:, k] for k, s in enumerate(sim.sats)}
    out = []
    for name, (cfg, ms) in configs.items():
        ep = run_locator(path, src, start_chainage_m=start, config=cfg, masks=ms)
        sc = score_run(ep, sim.chainage_m)
        n_nlos = [
            sum(state[s][k] == SignalState.NLOS for s in used.split())
            for k, used in enumerate(sc["used"])
        ]
        sc = sc.drop(columns=["used", "excluded", "flag_names"])
        sc["n_nlos_used"] = n_nlos
        sc["config"] = name
        out.append(sc)
    df = pd.concat(out, ignore_index=True)
    df["world"] = job.world
    df["run"] = job.run
    df["direction"] = job.direction
    df["n_los"] = np.tile((sim.state == SignalState.LOS).sum(1), len(configs))
    df["n_nlos"] = np.tile((sim.state == SignalState.NLOS).sum(1), len(configs))
    return df


def _do(args: tuple[Job, str]) -> tuple[str, int, float]:
    job, out = args
    t = time.perf_counter()
    df = run_job(job)
    tmp = Path(out + ".tmp")
    df.to_parquet(tmp)
    tmp.replace(out)
    return out, len(df), time.perf_counter() - t


_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


def jobs_for(worlds: list[str], runs_per_world: int) -> list[Job]:
    """Run ``r`` of world ``w`` starts at the fraction ``frac(offset_w + r * golden ratio)`` of
    the day: spread evenly for any number of runs, and independent of that number and of the
    other worlds, so that adding runs keeps the finished ones and a subset reproduces them."""
    day = default_window()[0]
    jobs = []
    for w in worlds:
        offset = (zlib.crc32(w.encode()) % 1000) / 1000.0
        for r in range(runs_per_world):
            t0 = day + np.mod(offset + r * _GOLDEN, 1.0) * 86400.0
            jobs.append(Job(w, r, float(t0), +1 if r % 2 == 0 else -1))
    return jobs


def report(frames: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for cfg, g in frames.groupby("config", sort=False):
        s = dict(summarise(g))
        s["nlos_used_share"] = float((g["n_nlos_used"] > 0).mean())
        rows.append({"config": cfg, **s})
    return pd.DataFrame(rows).set_index("config")


def figure(frames: pd.DataFrame, table: pd.DataFrame, paths: list[Path]) -> None:
    """Interval length distributions (claimed epochs) and the outcome shares of ``table``
    (:func:`report`) per configuration, written to every path of ``paths``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax, bx = fig.subplots(1, 2, width_ratios=[3, 2])
    colours = {"masks": "#1b7837", "pipeline": "#762a83", "none": "#b2182b", "cutoff15": "#ef8a62",
               "masks_k2": "#7fbf7b", "masks_budget": "#2166ac",
               "pipeline_budget": "#c2a5cf"}  # fmt: skip
    bins = np.geomspace(3.0, 3000.0, 60)
    for cfg, g in frames.groupby("config", sort=False):
        length = g.loc[g["claim"], "length_m"].to_numpy(float)
        ax.hist(length, bins=bins, histtype="step", lw=1.5, color=colours.get(str(cfg)),
                label=f"{cfg} (median {np.median(length):.0f} m)")  # fmt: skip
    for v in (70.0, 600.0):
        ax.axvline(v, color="k", ls="--", lw=0.8)
    ax.text(70.0, ax.get_ylim()[1] * 0.95, " LOCOPROL typical", fontsize=8)
    ax.text(600.0, ax.get_ylim()[1] * 0.85, " LOCOPROL max", fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("interval length, claimed epochs (m)")
    ax.set_ylabel("epochs")
    ax.legend(fontsize=8)
    names = list(table.index)
    x = np.arange(len(names))
    six = table["mode_three_pairs_share"].to_numpy(float) * 100
    bx.bar(x - 0.2, six, 0.4, color="#9ecae1", label="three-pair mode (>= 6 satellites)")
    bx.bar(x + 0.2, table["claim_share"].to_numpy(float) * 100, 0.4, color="#3182bd",
           label="safety claim")  # fmt: skip
    for k, h in enumerate(table["hmi"].astype(int)):
        bx.text(k, 102, f"HMI {h}", ha="center", fontsize=9, color="#b2182b" if h else "k")
    bx.axhline(60.0, color="k", ls="--", lw=0.8)
    bx.text(len(names) - 0.5, 61.0, "LOCOPROL: 6 sats 60 %", ha="right", fontsize=8)
    bx.set_xticks(x, names)
    bx.set_ylim(0, 112)
    bx.set_ylabel("% of epochs")
    bx.legend(fontsize=8, loc="lower right")
    fig.suptitle("Locator campaign, epochs per rule: "
                 + ", ".join(f"{c} {int(n):,}" for c, n in table["epochs"].items()))  # fmt: skip
    for path in paths:
        fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--runs-per-world", type=int, default=88)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--worlds", nargs="*", default=[w[0] for w in WORLDS])
    ap.add_argument("--demo", type=Path, help="a `predisat demo --out` folder (pipeline masks)")
    ap.add_argument("--figure", type=Path, help="write the summary figure (PNG) here too")
    ap.add_argument("--configs", nargs="+", choices=CONFIGS, default=list(CONFIGS),
                    help="configurations to run (default all)")
    args = ap.parse_args(argv)
    out = args.out
    (out / "jobs").mkdir(parents=True, exist_ok=True)
    (out / "cache").mkdir(exist_ok=True)
    worlds = list(args.worlds) + (["demo"] if args.demo else [])
    jobs = jobs_for(worlds, args.runs_per_world)
    # the start time is in the name: a job file of another time grid is never taken for this one
    paths = [str(out / "jobs" / f"{j.world}_{j.run:04d}_{j.t0_gps_s:.0f}.parquet") for j in jobs]
    todo = [(j, p) for j, p in zip(jobs, paths, strict=True) if not Path(p).exists()]
    print(f"{len(jobs)} jobs, {len(todo)} to do", flush=True)
    # learn the error model, build worlds and truth once, serially, before the pool starts
    model = calibrate(out / "cache")
    print(f"error model: {model}", flush=True)
    for w in worlds:
        if w != "demo":
            t = time.perf_counter()
            _world(w, out / "cache")
            print(f"world {w} ready ({time.perf_counter() - t:.0f} s)", flush=True)
    t0 = time.perf_counter()
    done = 0
    with mp.get_context("fork").Pool(
        args.workers, _init,
        (str(out / "cache"), str(args.demo) if args.demo else None, tuple(args.configs)),
    ) as pool:
        for path, n, dt in pool.imap_unordered(_do, todo):
            done += 1
            el = time.perf_counter() - t0
            print(f"[{done}/{len(todo)}] {Path(path).name}: {n} rows, {dt:.1f} s "
                  f"(elapsed {el:.0f} s)", flush=True)  # fmt: skip
    frames = pd.concat([pd.read_parquet(p) for p in paths])
    table = report(frames)
    per_world = {
        w: report(g).to_dict(orient="index") for w, g in frames.groupby("world", sort=False)
    }
    pd.set_option("display.width", 200)
    print(table.T.to_string(float_format=lambda v: f"{v:.4g}"))
    (out / "summary.json").write_text(
        json.dumps({"all": table.to_dict(orient="index"), "per_world": per_world}, indent=1)
    )
    table.to_csv(out / "summary.csv")
    figure(frames, table, [out / "campaign.png", *([args.figure] if args.figure else [])])
    stanford(frames, out)
    return 0


def stanford(frames: pd.DataFrame, out: Path) -> list[Path]:
    """One Stanford integrity diagram per configuration, ``out/stanford_<config>.png``."""
    from locator.plots import stanford_diagram

    paths = []
    for cfg, g in frames.groupby("config", sort=False):
        fig = stanford_diagram(g, title=f"Stanford diagram, rule {cfg} ({len(g):,} epochs)")
        paths.append(out / f"stanford_{cfg}.png")
        fig.savefig(paths[-1], dpi=110)
    return paths


if __name__ == "__main__":
    sys.exit(main())
