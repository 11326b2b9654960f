"""Held-out evaluation on synthetic worlds with the segmenter's out-of-distribution failures
(issue 30, item 3; ``docs/synthetic-world.md``, "Out-of-distribution worlds").

Per seed (41, 42, 43 by default: never used to fit the segmenter or the margin), a world along
the demo track with a glass curtain-wall street, a white-facade street, a station, water beside
the track, signal gantries and a power line of lattice pylons along the whole run (in a
seed-shuffled order, open track between; :func:`ood_spec`), under the seed's sky and sun
(:data:`SETUPS`: a low morning sun in a cloudy sky, an overcast day after rain with wet
platforms and ballast, a mixed sky with a low evening sun). Each rig (side fisheye, side
pinhole; resolution scaled by ``--scale``) renders it once; ``process_survey`` runs with the
defaults (serial); the masks are scored against the ray-cast true masks at margin 0:

* false trust (trusted directions truly blocked / trusted) overall and at the worst position;
* sky lost across and along the track;
* frames per CPU-second of ``process_survey``;
* where the false trust is: per stretch kind, side, sector and elevation band of the missed
  skyline (``failures``).

``faults`` then injects the real-photo operating point (``predisat.reconstruct.faults``:
whole-frame failures at 4 % per frame and 2.56 local faults per frame in
``FaultRates.mix``, ``docs/reconstruction.md`` section 6) and 2x and 3x that into the ideal
masks of the same worlds' fisheye frames (a segmenter without error followed by the pipeline's
thin-structure policy, ``ideal_frames(thin_deg=THIN_DEG)``; factor 0 is that base without
faults), reconstructs with the default parameters and scores the same way.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_ood_world.py run --seeds 41 42 43 \\
        --length-m 1000 --scale 0.5 --rigs fisheye --work /tmp/ood --out /tmp/ood/fisheye.json
    PYTHONPATH=. .venv/bin/python scripts/eval_ood_world.py faults --seeds 41 42 43 \\
        --work /tmp/ood --out /tmp/ood/faults.json
    PYTHONPATH=. .venv/bin/python scripts/eval_ood_world.py sheet --work /tmp/ood \\
        --out docs/figures/ood_worst_frames.png
    # where the false trust and the lost sky are, from the runs above (no processing)
    PYTHONPATH=. .venv/bin/python scripts/eval_ood_world.py score --work /tmp/ood --out -
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from eval_rigs import _reusable, pooled

from predisat.camera.models import default_camera
from predisat.camera.rigs import Rig
from predisat.cli.demo import DEMO_CANT_SPEED_KMH
from predisat.masks.fileformat import read_masks
from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.evaluate import compare, load_truth, trust_counts
from predisat.synth.generate import daytime_gps_s, generate_survey
from predisat.synth.world import Stretch, WorldSpec
from predisat.track.map import demo_track

_MARGIN_M = 150.0
SETUPS = {41: ("cloudy", 6.5, False), 42: ("overcast", 10.0, True), 43: ("mixed", 17.8, False)}
"""Seed -> (sky, local solar hour on 2024-06-21, wet); other seeds cycle through these."""
_PIECES = (("glass_street", 180.0), ("white_street", 180.0), ("station", 200.0),
           ("water", 150.0), ("trees", 100.0))  # fmt: skip
OPERATING_LOCAL = 2.56  # local faults per frame at the real street photos' unsafe columns
OPERATING_WHOLE = 0.04  # whole-frame failures per frame (4 % of the real street photos)


def setup_of(seed: int) -> tuple[str, float, bool]:
    """Sky, solar hour and wetness of a seed (:data:`SETUPS`)."""
    keys = sorted(SETUPS)
    return SETUPS.get(seed, SETUPS[keys[seed % len(keys)]])


def ood_spec(lo_m: float, hi_m: float, seed: int) -> WorldSpec:
    """The pieces of :data:`_PIECES` once each in a seed-shuffled order over ``[lo_m, hi_m]``
    (open track between), a lattice-pylon power line on one side of the whole run and a signal
    gantry every 250-400 m; wet after rain when :func:`setup_of` says so."""
    rng = np.random.default_rng([seed, 30])
    order = [_PIECES[i] for i in rng.permutation(len(_PIECES))]
    slot = (hi_m - lo_m) / len(order)
    out = [Stretch("open", lo_m - _MARGIN_M, lo_m)]
    a = lo_m
    for i, (kind, length) in enumerate(order):
        length = min(length, slot - 10.0)
        start = lo_m + i * slot + float(rng.uniform(2.0, slot - length - 2.0))
        out.append(Stretch("open", a, start))
        side = "both" if kind != "water" else ("left", "right")[int(rng.integers(0, 2))]
        out.append(Stretch(kind, start, start + length, side))
        a = start + length
    out.append(Stretch("open", a, hi_m + _MARGIN_M))
    out.append(Stretch("pylons", lo_m - _MARGIN_M, hi_m + _MARGIN_M,
                       ("left", "right")[int(rng.integers(0, 2))]))  # fmt: skip
    g = lo_m + float(rng.uniform(50.0, 200.0))
    while g < hi_m:
        out.append(Stretch("gantry", g, g + 1.2))
        g += float(rng.uniform(250.0, 400.0))
    return WorldSpec(tuple(out), wet=setup_of(seed)[2])


def rig_of(name: str, scale: float) -> Rig:
    """``fisheye``: the shipped side fisheyes; ``pinhole``: the shipped side pinholes."""
    if name == "fisheye":
        return Rig.preset("side-fisheye").scaled(scale)
    return Rig.preset("side-fisheye", side_camera=default_camera("pinhole")).scaled(scale)


def kind_at(spec: WorldSpec, chainage_m: np.ndarray) -> np.ndarray:
    """The scenery kind of each chainage (the OOD piece or station covering it, else open)."""
    out = np.full(np.shape(chainage_m), "open", dtype=object)
    for st in spec.stretches:
        if st.kind in ("open", "pylons", "gantry"):
            continue
        sel = (chainage_m >= st.start_m - 20.0) & (chainage_m <= st.end_m + 20.0)
        out[sel] = st.kind
    for st in spec.stretches:  # a gantry within 30 m wins
        if st.kind == "gantry":
            out[np.abs(chainage_m - st.start_m) <= 30.0] = "gantry"
    return out


def failures(comp: Any, spec: WorldSpec) -> dict[str, dict[str, float]]:
    """False-trust directions binned by stretch kind, side, sector and elevation band."""
    trusted, good, los = trust_counts(comp.mask_el_deg, comp.truth_el_deg, 0.0)
    false = (trusted - good).astype(float)
    lost = (los - good).astype(float)
    kind = np.broadcast_to(kind_at(spec, comp.chainage_m)[:, None], false.shape)
    rel = np.mod(comp.az_deg[None, :] - comp.heading_deg[:, None], 360.0)
    side = np.where(rel > 180.0, "left", "right")
    band = np.digitize(comp.truth_el_deg, [10.0, 20.0, 30.0, 45.0, 60.0])
    names = np.array(["<10", "10-20", "20-30", "30-45", "45-60", ">=60"])[band]
    out: dict[str, dict[str, float]] = {}
    for label, arr in (("kind", kind), ("side", side), ("sector", comp.sector),
                       ("truth_el_deg", names)):  # fmt: skip
        acc: dict[str, float] = defaultdict(float)
        for v in np.unique(arr):
            acc[str(v)] = float(false[arr == v].sum())
        out[label] = dict(acc)
    out["sky_lost_by_kind"] = {
        str(v): float(lost[kind == v].sum() / max(float(los[kind == v].sum()), 1.0))
        for v in np.unique(kind)
    }
    total_trusted = float(trusted.sum())
    out["kind_share_of_trusted"] = {
        k: v / max(total_trusted, 1.0) for k, v in out["kind"].items()
    }
    return out


def _score(masks_path: Path, truth_dir: Path, spec: WorldSpec) -> dict[str, Any]:
    comp = compare(read_masks(masks_path), load_truth(truth_dir))
    trusted, good, los = trust_counts(comp.mask_el_deg, comp.truth_el_deg, 0.0)
    out: dict[str, Any] = {}
    for name, sel in (("cross", comp.sector == "cross"), ("along", comp.sector == "along"),
                      ("all", np.ones(comp.sector.shape, bool))):  # fmt: skip
        t, g, v = (float(a[sel].sum()) for a in (trusted, good, los))
        out[f"sky_lost_{name}"] = 1.0 - g / max(v, 1.0)
        out[f"false_trust_{name}"] = (t - g) / max(t, 1.0)
        out[f"n_trusted_{name}"], out[f"n_false_{name}"] = t, t - g
        out[f"n_visible_{name}"], out[f"n_kept_{name}"] = v, g
        out[f"ideal_n_visible_{name}"] = out[f"ideal_n_kept_{name}"] = 0.0
        out[f"ideal_n_trusted_{name}"] = out[f"ideal_n_false_{name}"] = 0.0
    per_pos = (trusted - good).sum(1) / np.maximum(trusted.sum(1), 1)
    out["worst_position_false_trust"] = float(per_pos.max())
    out["worst_position_m"] = float(comp.chainage_m[int(np.argmax(per_pos))])
    out["positions_with_false_trust"] = int((per_pos > 0).sum())
    out["n_positions_scored"] = int(per_pos.size)
    out["failures"] = failures(comp, spec)
    return out


def _run_lo(seed: int, length_m: float) -> float:
    track = demo_track()
    span = float(track.length_m) - 2 * _MARGIN_M - length_m - 1000.0
    return round(500.0 + float(np.random.default_rng([seed, 7]).uniform(0.0, span)), -1)


def spec_of_run(truth_dir: Path, seed: int) -> WorldSpec:
    """The world spec a finished run was rendered with: its span from the true masks' positions
    (every 10 m from ``lo`` to ``lo + --length-m``), not an assumed 1000 m, whose ``_run_lo``
    and piece layout differ from those of any other length."""
    from predisat.masks.truth import TrueMasks

    s = TrueMasks.load(truth_dir / "true_masks.npz").chainage_m
    return ood_spec(float(s[0]), float(s[-1]), seed)


def run_one(rig_name: str, seed: int, length_m: float, scale: float, work: Path,
            reuse: bool) -> dict[str, Any]:  # fmt: skip
    """Render (or reuse), process with the defaults and score one rig on one seed's world."""
    lo = _run_lo(seed, length_m)
    hi = lo + length_m
    spec = ood_spec(lo, hi, seed)
    sky, hour, wet = setup_of(seed)
    out = work / f"{rig_name}_s{seed}"
    res = _reusable(out) if reuse else None
    if res is not None and spec_of_run(out / "synth" / "truth", seed) != spec:
        # a render of another --length-m: its span and scenery layout are another world's (m2)
        print(f"{out}: rendered for another span than {lo:.0f}-{hi:.0f} m: rendered again",
              flush=True)  # fmt: skip
        res = None
    render_cpu = 0.0
    track = demo_track()
    if res is None:
        if out.exists():
            shutil.rmtree(out)
        lon = float(track.position_at(lo)[1])
        c0 = time.process_time()
        # a canted vehicle, as `predisat synth` and the demo render (eval_rigs.py says why)
        res = generate_survey(
            track, lo, hi, sky=sky, seed=seed, out_dir=out / "synth", spec=spec,
            rig=rig_of(rig_name, scale), progress=False,
            start_gps_s=daytime_gps_s(lon, solar_hour=hour), cant_speed_kmh=DEMO_CANT_SPEED_KMH,
        )  # fmt: skip
        render_cpu = time.process_time() - c0
    else:
        for item in (out / "proc").glob("*"):
            if item.name != "cache":
                shutil.rmtree(item) if item.is_dir() else item.unlink()
    c0 = time.process_time()
    proc = process_survey(res.survey_dir, out / "proc", scheduler="serial", progress=False)
    cpu = time.process_time() - c0
    row: dict[str, Any] = {
        "rig": rig_name, "seed": seed, "from_m": lo, "to_m": hi, "sky": sky,
        "solar_hour": hour, "wet": wet, "n_positions": res.n_positions,
        "n_frames": res.n_frames, "render_cpu_s": round(render_cpu, 1),
        "process_cpu_s": round(cpu, 1), "frames_per_cpu_s": res.n_frames / cpu,
        "positions_per_cpu_s": res.n_positions / cpu,
    }  # fmt: skip
    row |= _score(Path(proc.masks_path), res.truth_dir, spec)
    return row


def cmd_run(args: argparse.Namespace) -> None:
    rows: list[dict[str, Any]] = []
    for seed in args.seeds:
        for rig in args.rigs:
            row = run_one(rig, seed, args.length_m, args.scale, args.work, args.reuse)
            rows.append(row)
            print(f"{rig} seed {seed} ({row['sky']}, solar hour {row['solar_hour']}, wet "
                  f"{row['wet']}) km {row['from_m'] / 1000:.2f}: false trust "
                  f"{100 * row['false_trust_all']:.4f} %, worst position "
                  f"{100 * row['worst_position_false_trust']:.3f} % at "
                  f"{row['worst_position_m']:.0f} m ({row['positions_with_false_trust']} of "
                  f"{row['n_positions_scored']} positions), sky lost across "
                  f"{100 * row['sky_lost_cross']:.1f} % along {100 * row['sky_lost_along']:.1f}"
                  f" %, {row['frames_per_cpu_s']:.2f} frames/CPU-s; false directions by kind "
                  f"{row['failures']['kind']}", flush=True)  # fmt: skip
            args.out.write_text(json.dumps({"runs": rows}, indent=1))
    summary: dict[str, Any] = {}
    for rig in args.rigs:
        rr = [r for r in rows if r["rig"] == rig]
        p: dict[str, Any] = {k: v for k, v in pooled(rr).items() if not k.startswith("ideal_")}
        p["worst_position_false_trust"] = max(r["worst_position_false_trust"] for r in rr)
        p["positions_with_false_trust"] = sum(r["positions_with_false_trust"] for r in rr)
        p["n_positions_scored"] = sum(r["n_positions_scored"] for r in rr)
        kinds: dict[str, float] = defaultdict(float)
        for r in rr:
            for k, v in r["failures"]["kind"].items():
                kinds[k] += v
        p["false_directions_by_kind"] = dict(kinds)
        summary[rig] = p
        print(f"{rig}: false trust {100 * p['false_trust_all']:.4f} % (worst position "
              f"{100 * p['worst_position_false_trust']:.3f} %, {p['positions_with_false_trust']}"
              f" of {p['n_positions_scored']} positions), sky lost across "
              f"{100 * p['sky_lost_cross']:.1f} % along {100 * p['sky_lost_along']:.1f} % all "
              f"{100 * p['sky_lost_all']:.1f} %, {p['frames_per_cpu_s']:.2f} frames/CPU-s")
    args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()
                                             if k != "func"}, "runs": rows,
                                    "pooled": summary}, indent=1))  # fmt: skip
    print(f"written {args.out}")


def cmd_score(args: argparse.Namespace) -> None:
    """Score the runs already in ``--work`` again (no rendering, no processing): per run the
    false trust and the sky lost per scenery kind."""
    for run in sorted(args.work.glob("*_s*")):
        masks = run / "proc" / "masks.parquet"
        if not masks.exists():
            continue
        seed = int(run.name.rsplit("_s", 1)[1])
        truth = run / "synth" / "truth"
        sc = _score(masks, truth, spec_of_run(truth, seed))
        f = sc["failures"]
        print(f"{run.name}: false trust {100 * sc['false_trust_all']:.4f} %, worst position "
              f"{100 * sc['worst_position_false_trust']:.3f} % at {sc['worst_position_m']:.0f} m")
        print("  false directions by kind " + ", ".join(f"{k} {v:.0f}" for k, v in
                                                        f["kind"].items()))  # fmt: skip
        print("  by side " + str(f["side"]) + ", sector " + str(f["sector"]) +
              ", true skyline " + str(f["truth_el_deg"]))  # fmt: skip
        print("  sky lost by kind " + ", ".join(f"{k} {100 * v:.1f} %" for k, v in
                                                f["sky_lost_by_kind"].items()))  # fmt: skip


def _classes(world: Any, frames: list[Any]) -> list[np.ndarray]:
    """Scene class per pixel (``predisat.reconstruct.faults`` labels) of ideal frames."""
    from predisat.reconstruct.faults import LABEL_BUILDING, LABEL_GROUND, LABEL_NONE, LABEL_OTHER
    from predisat.reconstruct.faults import LABEL_SKY as F_SKY
    from predisat.synth.materials import MATERIALS
    from predisat.synth.raycast import make_caster
    from predisat.synth.render import camera_pose

    full = make_caster(world, "open3d")
    cls_of = np.full(len(MATERIALS), LABEL_OTHER, np.int8)
    for i, m in enumerate(MATERIALS):
        if m.name in ("brick", "plaster", "roof_tiles", "concrete", "canopy", "glass",
                      "white_facade"):  # fmt: skip
            cls_of[i] = LABEL_BUILDING
        elif m.name in ("grass", "ballast", "platform", "hills", "water", "wet_platform",
                        "wet_ballast"):  # fmt: skip
            cls_of[i] = LABEL_GROUND
    out = []
    for f in frames:
        cam = f.camera
        rays = cam.pixel_to_ray(*cam.pixel_grid())
        good = np.all(np.isfinite(rays), axis=-1)
        pos, rot = camera_pose(world, f.chainage_m, f.mount, 4.0, f.reverse)
        d = rays[good] @ rot.T
        hits = full.cast(np.broadcast_to(pos, d.shape), d)
        mat = hits.material_id(world.face_material)
        lb = np.full(cam.shape, LABEL_NONE, np.int8)
        lb[good] = np.where(mat >= 0, cls_of[np.maximum(mat, 0)], F_SKY)
        lb[f.sky_mask] = F_SKY
        out.append(lb)
    return out


def cmd_faults(args: argparse.Namespace) -> None:
    from dataclasses import replace

    from predisat.masks.margins import sector_of
    from predisat.masks.truth import TrueMasks
    from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
    from predisat.reconstruct.faults import FaultRates, inject_faults
    from predisat.reconstruct.params import THIN_DEG
    from predisat.synth.truth import ideal_frames
    from predisat.synth.world import World

    rows = []
    for seed in args.seeds:
        truth_dir = args.work / f"fisheye_s{seed}" / "synth" / "truth"
        world = World.load(truth_dir / "world.npz")
        tm = TrueMasks.load(truth_dir / "true_masks.npz")
        s = tm.chainage_m
        lo, hi = max(world.extent_m[0], s[0] - 150.0), min(world.extent_m[1], s[-1] + 150.0)
        rig = rig_of("fisheye", args.scale)
        t0 = time.process_time()
        frames, cams = [], []
        for pos_name, cam, mount in rig.cameras:  # each camera's frames in time order
            got = ideal_frames(world, np.arange(lo, hi + 1e-9, 10.0), cam, {pos_name: mount},
                               thin_deg=THIN_DEG)  # the pipeline's thin-structure policy
            frames += got
            cams += [pos_name] * len(got)
        labels = _classes(world, frames)
        print(f"seed {seed}: {len(frames)} ideal frames and classes in "
              f"{time.process_time() - t0:.0f} CPU-s", flush=True)
        sector = sector_of(tm.az_deg[None, :], tm.heading_deg[:, None])
        jobs: list[tuple[float, str, FaultRates]] = []
        for factor in args.factors:
            rates = FaultRates.mix(OPERATING_LOCAL * factor, OPERATING_WHOLE * factor)
            jobs.append((factor, "all", rates))
            if args.per_class and factor > 0:
                jobs += [(factor, k, FaultRates({k: r})) for k, r in rates.rates.items()]
        rec = Reconstructor(ReconstructionParams(fusion_rank=args.fusion_rank,
                                                 suspect_share=args.suspect_share))
        for factor, kind, rates in jobs:
            masks = [f.sky_mask for f in frames]
            faulty, faults = inject_faults(masks, labels, cams, rates, seed)
            fr = [replace(f, sky_mask=m) for f, m in zip(frames, faulty, strict=True)]
            res = rec.run(fr, s, world.track)
            trusted, good, los = trust_counts(res.mask_el_deg.astype(float), tm.mask_el_deg, 0.0)
            per_pos = (trusted - good).sum(1) / np.maximum(trusted.sum(1), 1)
            row = {"seed": seed, "factor": factor, "faults": kind, "n_faults": len(faults),
                   "fusion_rank": args.fusion_rank, "suspect_share": args.suspect_share,
                   "false_trust": float((trusted - good).sum() / max(trusted.sum(), 1)),
                   "worst_position_false_trust": float(per_pos.max()),
                   "worst_position_m": float(s[int(np.argmax(per_pos))]),
                   "positions_with_false_trust": int((per_pos > 0).sum()),
                   "n_positions": int(per_pos.size),
                   "n_trusted": int(trusted.sum()), "n_false": int((trusted - good).sum()),
                   "n_visible": int(los.sum()), "n_kept": int(good.sum())}  # fmt: skip
            for name in ("cross", "along"):
                sel = np.broadcast_to(sector == name, los.shape)
                row[f"sky_lost_{name}"] = 1.0 - float(good[sel].sum()) / max(
                    float(los[sel].sum()), 1.0)
            rows.append(row)
            print(json.dumps(row), flush=True)
            args.out.write_text(json.dumps({"rows": rows}, indent=1))
    pooled_rows = {}
    for factor in args.factors:
        rr = [r for r in rows if r["factor"] == factor and r["faults"] == "all"]
        pooled_rows[str(factor)] = {
            "false_trust": sum(r["n_false"] for r in rr) / max(sum(r["n_trusted"] for r in rr), 1),
            "worst_position_false_trust": max(r["worst_position_false_trust"] for r in rr),
            "sky_lost": 1.0 - sum(r["n_kept"] for r in rr) / max(sum(r["n_visible"] for r in rr),
                                                                  1),
        }  # fmt: skip
        p = pooled_rows[str(factor)]
        print(f"x{factor:g} operating point: false trust {100 * p['false_trust']:.4f} %, worst "
              f"position {100 * p['worst_position_false_trust']:.3f} %, sky lost "
              f"{100 * p['sky_lost']:.1f} %")
    args.out.write_text(json.dumps({"rows": rows, "pooled": pooled_rows}, indent=1))


def cmd_sheet(args: argparse.Namespace) -> None:
    """Contact sheet of the frames with the most false sky (segmented sky where the truth has
    an obstacle) in the pipeline's own segmentation (its frame cache), over every run in
    ``--work``; prints the false-sky rate per scenery kind beside it."""
    import csv

    import cv2

    from predisat.reconstruct.framecache import decode_cache
    from predisat.survey import Survey

    scored: list[tuple[float, Path, str, str]] = []
    per_kind: dict[tuple[str, str], list[float]] = defaultdict(lambda: [0.0, 0.0])
    for run in sorted(args.work.glob("*_s*")):
        truth = run / "synth" / "truth"
        caches = sorted((run / "proc" / "cache").glob("seg-*"))
        if not caches or not (truth / "frames.csv").exists():
            continue
        seed = int(run.name.rsplit("_s", 1)[1])
        with open(truth / "frames.csv", newline="") as fh:
            chain = {r["frame_id"]: float(r["chainage_m"]) for r in csv.DictReader(fh)}
        spec = spec_of_run(truth, seed)
        rig = run.name.split("_s")[0]
        for entry in caches[-1].glob("*.npz"):
            fid = entry.stem
            lab = cv2.imread(str(truth / "labels" / f"{fid}.png"), cv2.IMREAD_GRAYSCALE)
            with np.load(entry, allow_pickle=False) as z:
                got = decode_cache(z, json.loads(str(z["meta"])), fid)
            if lab is None or not isinstance(got, tuple) or fid not in chain:
                continue
            sky = got[0]
            obstacle = lab == 0
            false = float(np.sum(sky & obstacle))
            kind = str(kind_at(spec, np.array([chain[fid]]))[0])
            scored.append((false / sky.size, run, fid, kind))
            acc = per_kind[(rig, kind)]
            acc[0] += false
            acc[1] += float(obstacle.sum())
    if not scored:
        raise SystemExit(f"no segmentation caches under {args.work}/*/proc/cache")
    print("false-sky rate of the pipeline's segmentation (non-sky labelled sky / non-sky):")
    for (rig, kind), (f, n) in sorted(per_kind.items()):
        print(f"  {rig:8s} {kind:13s} {100 * f / max(n, 1.0):6.2f} %")
    scored.sort(key=lambda x: -x[0])
    best: list[tuple[float, Path, str, str]] = []
    for item in scored:  # the worst frames, at most two of one rig and scenery kind
        rig_kind = (item[1].name.split("_s")[0], item[3])
        if sum((b[1].name.split("_s")[0], b[3]) == rig_kind for b in best) < 2:
            best.append(item)
        if len(best) == args.n:
            break
    tiles = []
    for v, run, fid, kind in best:  # the frame, its false sky tinted red, a caption
        survey = Survey.load(run / "synth" / "survey", check_images=False)
        img = survey.read_image(survey.frames.index_of(fid)).astype(float)
        lab = cv2.imread(str(run / "synth" / "truth" / "labels" / f"{fid}.png"),
                         cv2.IMREAD_GRAYSCALE)  # fmt: skip
        entry = next((run / "proc" / "cache").glob(f"seg-*/{fid}.npz"))
        with np.load(entry, allow_pickle=False) as z:
            got = decode_cache(z, json.loads(str(z["meta"])), fid)
        if isinstance(got, tuple) and lab is not None:
            false = got[0] & (lab == 0)
            img[false] = 0.45 * img[false] + 0.55 * np.array([40.0, 40.0, 255.0])
        th = round(img.shape[0] * args.tile / img.shape[1])
        tile = cv2.resize(img.astype(np.uint8), (args.tile, th), interpolation=cv2.INTER_AREA)
        cv2.rectangle(tile, (0, th - 16), (args.tile, th), (0, 0, 0), -1)
        text = f"{run.name} {kind} {fid[0]}{int(fid.split('_')[1])}: {100 * v:.1f} %"
        cv2.putText(tile, text, (3, th - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (255, 255, 255), 1,
                    cv2.LINE_AA)  # fmt: skip
        tiles.append(tile)
    h = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, h - t.shape[0]), (0, 0), (0, 0))) for t in tiles]
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % args.columns)
    tiles = [np.hstack(tiles[i : i + args.columns]) for i in range(0, len(tiles), args.columns)]
    w = max(t.shape[1] for t in tiles)
    sheet = np.vstack([np.pad(t, ((0, 0), (0, w - t.shape[1]), (0, 0))) for t in tiles])
    if args.out.suffix.lower() == ".png":  # a small PNG: 128 colours
        from PIL import Image

        rgb = Image.fromarray(np.ascontiguousarray(sheet[..., ::-1]))
        rgb.quantize(128, method=Image.Quantize.MEDIANCUT).save(args.out, optimize=True)
    else:
        ok, buf = cv2.imencode(args.out.suffix, sheet, [cv2.IMWRITE_JPEG_QUALITY, 80])
        if not ok:
            raise OSError(f"encoding {args.out} failed")
        args.out.write_bytes(buf.tobytes())
    print(f"written {args.out}: " + ", ".join(f"{r.name}/{f} ({k}) {100 * v:.1f} %"
                                               for v, r, f, k in best))  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(required=True)
    for name, func in (("run", cmd_run), ("faults", cmd_faults), ("sheet", cmd_sheet),
                       ("score", cmd_score)):  # fmt: skip
        p = sub.add_parser(name)
        p.set_defaults(func=func)
        p.add_argument("--work", type=Path, default=Path("/tmp/ood"))
        p.add_argument("--out", type=Path, required=True)
        p.add_argument("--seeds", nargs="+", type=int, default=[41, 42, 43])
        p.add_argument("--scale", type=float, default=0.5, help="camera resolution factor")
        if name == "run":
            p.add_argument("--rigs", nargs="+", choices=("fisheye", "pinhole"),
                           default=["fisheye", "pinhole"])  # fmt: skip
            p.add_argument("--length-m", type=float, default=1000.0)
            p.add_argument("--reuse", action="store_true",
                           help="keep the rendered surveys and segmentation caches in --work")
        if name == "faults":
            p.add_argument("--factors", nargs="+", type=float, default=[0.0, 1.0, 2.0, 3.0])
            p.add_argument("--fusion-rank", type=int, default=1,
                           help="ReconstructionParams.fusion_rank (1: the default, the minimum)")
            p.add_argument("--suspect-share", type=float, default=None,
                           help="ReconstructionParams.suspect_share (None: the default, no "
                                "suspect-frame check)")
            p.add_argument("--per-class", action="store_true",
                           help="also each fault class alone at its rate in the mix")
        if name == "sheet":
            p.add_argument("--n", type=int, default=8)
            p.add_argument("--tile", type=int, default=240)
            p.add_argument("--columns", type=int, default=4)
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    args.func(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
