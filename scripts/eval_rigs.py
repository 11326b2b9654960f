"""Survey rigs side by side on held-out synthetic worlds (docs/rigs.md, issue 32 item 1).

Per seed, a world along the demo track with a town, a station, trees, a cutting, a tunnel and
an overbridge (in a seed-shuffled order, open track between) is rendered once per rig
(:class:`predisat.camera.rigs.Rig`, resolution scaled by ``--scale``), run through the whole
pipeline (``process_survey``: segmentation with the default method, reconstruction; serial, one
process) and scored against the ray-cast true masks (``predisat.reconstruct.evaluate``):

* sky lost across and along the track (truly visible directions not trusted / truly visible;
  sectors as ``predisat.masks.margins.sector_of``), with no margin;
* false trust (trusted directions truly blocked / trusted), with no margin;
* pipeline frames per CPU-second (``time.process_time`` of ``process_survey``) and positions
  per CPU-second (a rig's positions carry 1 to 4 frames);
* the same sky lost and false trust from the rig's *ideal* sky masks (ray cast, no
  segmentation error) through the same reconstruction: what the rig's geometry allows, apart
  from the segmentation.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_rigs.py --seeds 11 12 13 --length-m 1000 \\
        --scale 0.5 --work /tmp/eval_rigs --out eval_rigs.json

``--reuse`` keeps the rendered surveys and the segmentation caches of an earlier run in the
same ``--work`` folder and only reconstructs and scores again (a reconstruction change).

Prints a table per rig (and the pooled figures over the seeds) and writes the JSON.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from predisat.camera.rigs import RIG_NAMES, Rig
from predisat.cli.demo import DEMO_CANT_SPEED_KMH
from predisat.masks.fileformat import read_masks
from predisat.masks.margins import sector_of
from predisat.masks.truth import TrueMasks
from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
from predisat.reconstruct.evaluate import compare, load_truth, trust_counts
from predisat.reconstruct.params import PipelineParams
from predisat.synth.generate import SynthResult, generate_survey
from predisat.synth.render import Casters
from predisat.synth.truth import ideal_frames, true_masks
from predisat.synth.world import Stretch, World, WorldSpec
from predisat.track.map import demo_track

KINDS = ("town", "station", "trees", "cutting", "tunnel", "overbridge")
_MARGIN_M = 150.0  # generate_survey renders scenery this far beyond the run


def held_out_spec(lo_m: float, hi_m: float, seed: int) -> WorldSpec:
    """Every kind of :data:`KINDS` once over ``[lo_m, hi_m]`` in a seed-shuffled order, open
    track between and around them (short structures: tunnel 80 m, overbridge 25 m)."""
    rng = np.random.default_rng([seed, 32])
    order = [KINDS[i] for i in rng.permutation(len(KINDS))]
    slot = (hi_m - lo_m) / len(order)
    out = [Stretch("open", lo_m - _MARGIN_M, lo_m)]
    a = lo_m
    for i, kind in enumerate(order):
        length = min({"tunnel": 80.0, "overbridge": 25.0}.get(kind, 140.0), slot - 20.0)
        start = lo_m + i * slot + float(rng.uniform(5.0, slot - length - 5.0))
        out.append(Stretch("open", a, start))
        out.append(Stretch(kind, start, start + length, "both"))
        a = start + length
    out.append(Stretch("open", a, hi_m + _MARGIN_M))
    return WorldSpec(tuple(out))


def _counts(mask_el: np.ndarray, truth_el: np.ndarray, sector: np.ndarray,
            prefix: str = "") -> dict[str, float]:  # fmt: skip
    """Sky lost and false trust at margin 0 per sector, with their counts."""
    trusted, good, los = trust_counts(mask_el, truth_el, 0.0)
    out: dict[str, float] = {}
    for name, sel in (("cross", sector == "cross"), ("along", sector == "along"),
                      ("all", np.ones(sector.shape, bool))):  # fmt: skip
        t, g, v = (float(a[sel].sum()) for a in (trusted, good, los))
        out[f"{prefix}sky_lost_{name}"] = 1.0 - g / max(v, 1.0)
        out[f"{prefix}false_trust_{name}"] = (t - g) / max(t, 1.0)
        out[f"{prefix}n_trusted_{name}"] = t
        out[f"{prefix}n_false_{name}"] = t - g
        out[f"{prefix}n_visible_{name}"] = v
        out[f"{prefix}n_kept_{name}"] = g
    return out


def score(masks_path: Path, truth_dir: Path) -> dict[str, float]:
    """Sky lost across / along / all and false trust at margin 0 (shares) of a mask file."""
    comp = compare(read_masks(masks_path), load_truth(truth_dir))
    return _counts(comp.mask_el_deg, comp.truth_el_deg, comp.sector)


def score_ideal(rig: Rig, truth_dir: Path) -> dict[str, float]:
    """As :func:`score` for masks reconstructed from the rig's ideal (ray-cast) sky masks.

    The ideal masks are those of a segmenter without error followed by the pipeline's
    thin-structure policy (``PipelineParams().thin_deg``), as ``process`` applies it: until
    2026-12-07 they made every thin-material face sky whatever its width and distance, while
    the truth (since the Fresnel rule) keeps the ones that block; that alone gave this column
    0.37 % false trust on a side-fisheye stretch where the pipeline's policy gives 0.0001 %.
    """
    world = World.load(truth_dir / "world.npz")
    tm = TrueMasks.load(truth_dir / "true_masks.npz")
    s = tm.chainage_m
    lo, hi = max(world.extent_m[0], s[0] - 150.0), min(world.extent_m[1], s[-1] + 150.0)
    frames = []
    thin_deg = PipelineParams().thin_deg
    for pos, cam, mount in rig.cameras:
        frames += ideal_frames(world, np.arange(lo, hi + 1e-9, 10.0), cam, {pos: mount},
                               thin_deg=thin_deg)  # fmt: skip
    rec = Reconstructor().run(frames, s, world.track)
    sector = sector_of(tm.az_deg[None, :], tm.heading_deg[:, None])
    return _counts(rec.mask_el_deg.astype(float), tm.mask_el_deg, sector, "ideal_")


def truth_only(seed: int, lo_m: float, hi_m: float, out: Path) -> Path:
    """The world and true masks of a seed's stretch, as :func:`run_one` renders them, without
    the survey (for ``--ideal-only``); returns the truth folder."""
    truth = out / "truth"
    if (truth / "true_masks.npz").exists():
        return truth
    track = demo_track()
    world = World.build(track, held_out_spec(lo_m, hi_m, seed), seed)
    s = np.arange(lo_m, hi_m + 1e-9, 10.0)
    tm = true_masks(world, s, 4.0, caster=Casters.for_world(world, "open3d").lband)
    truth.mkdir(parents=True, exist_ok=True)
    world.save(truth / "world.npz")
    tm.save(truth / "true_masks.npz")
    return truth


def _reusable(out: Path) -> SynthResult | None:
    """The rendered survey of an earlier run in ``out`` (``None`` if it did not finish)."""
    synth = out / "synth"
    frames = synth / "truth" / "frames.csv"
    if not (frames.exists() and (synth / "truth" / "true_masks.npz").exists()):
        return None
    n_frames = sum(1 for _ in frames.open()) - 1  # a header line, one line per frame
    n_positions = int(TrueMasks.load(synth / "truth" / "true_masks.npz").chainage_m.size)
    return SynthResult(synth, synth / "survey", synth / "truth", n_positions, n_frames)


def run_one(rig: Rig, seed: int, lo_m: float, hi_m: float, work: Path,
            reuse: bool = False, panorama_raise: str = "image") -> dict[str, Any]:  # fmt: skip
    """Render, process and score one rig on one seed's world.

    ``reuse``: keep the rendered survey and the segmentation cache of an earlier run in the
    same ``work`` folder (same rig, seed, run and scale) and reconstruct again, e.g. after a
    change of the reconstruction only (the cache is keyed by the segmentation code).
    """
    out = work / f"{rig.name.replace('+', '_')}_s{seed}"
    res = _reusable(out) if reuse else None
    render_cpu = 0.0
    if res is None:
        if out.exists():
            shutil.rmtree(out)
        c0 = time.process_time()
        # a canted vehicle, as `predisat synth` and the demo render: a level one on line 144's
        # curves has its IMU roll taken for a mistake and bounded from the track (a review: 62.6
        # against 29.3 % sky lost on seed 11, km 7.05-7.35)
        res = generate_survey(
            demo_track(), lo_m, hi_m, seed=seed, out_dir=out / "synth",
            spec=held_out_spec(lo_m, hi_m, seed), rig=rig, progress=False,
            cant_speed_kmh=DEMO_CANT_SPEED_KMH,
        )  # fmt: skip
        render_cpu = time.process_time() - c0
    else:  # everything but the segmentation cache goes
        for item in (out / "proc").glob("*"):
            if item.name != "cache":
                shutil.rmtree(item) if item.is_dir() else item.unlink()
    c0 = time.process_time()
    params = PipelineParams(reconstruction=ReconstructionParams(panorama_raise=panorama_raise))
    proc = process_survey(res.survey_dir, out / "proc", params, scheduler="serial",
                          progress=False)  # fmt: skip
    cpu = time.process_time() - c0
    row: dict[str, Any] = {
        "rig": rig.name, "seed": seed, "from_m": lo_m, "to_m": hi_m,
        "n_positions": res.n_positions, "n_frames": res.n_frames,
        "render_cpu_s": round(render_cpu, 2), "process_cpu_s": round(cpu, 2),
        "frames_per_cpu_s": res.n_frames / cpu, "positions_per_cpu_s": res.n_positions / cpu,
    }  # fmt: skip
    row |= score(Path(proc.masks_path), res.truth_dir)
    row |= score_ideal(rig, Path(res.truth_dir))
    return row


def pooled(rows: list[dict[str, Any]], prefixes: tuple[str, ...] = ("", "ideal_")
           ) -> dict[str, float]:  # fmt: skip
    """Shares pooled over seeds (sums of counts), speeds over summed CPU time (where the rows
    have it: ``--ideal-only`` runs no pipeline)."""
    out: dict[str, float] = {}
    for name in ("cross", "along", "all"):
        for pre in prefixes:
            v = sum(r[f"{pre}n_visible_{name}"] for r in rows)
            g = sum(r[f"{pre}n_kept_{name}"] for r in rows)
            t = sum(r[f"{pre}n_trusted_{name}"] for r in rows)
            f = sum(r[f"{pre}n_false_{name}"] for r in rows)
            out[f"{pre}sky_lost_{name}"] = 1.0 - g / max(v, 1.0)
            out[f"{pre}false_trust_{name}"] = f / max(t, 1.0)
    if not all("process_cpu_s" in r for r in rows):
        return out
    cpu = sum(r["process_cpu_s"] for r in rows)
    out["frames_per_cpu_s"] = sum(r["n_frames"] for r in rows) / cpu
    out["positions_per_cpu_s"] = sum(r["n_positions"] for r in rows) / cpu
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rigs", nargs="+", choices=RIG_NAMES, default=list(RIG_NAMES))
    ap.add_argument("--seeds", nargs="+", type=int, default=[11, 12, 13])
    ap.add_argument("--length-m", type=float, default=1000.0, help="run length per seed")
    ap.add_argument("--scale", type=float, default=0.5, help="camera resolution factor")
    ap.add_argument("--work", type=Path, default=Path("/tmp/eval_rigs"))
    ap.add_argument("--out", type=Path, default=Path("eval_rigs.json"))
    ap.add_argument("--ideal-only", action="store_true",
                    help="only the ideal-mask columns: the world and its true masks, no "
                    "rendered survey and no pipeline (what each rig's geometry allows)")
    ap.add_argument("--reuse", action="store_true",
                    help="keep the rendered surveys and segmentation caches of an earlier run "
                    "in --work (same seeds, length and scale); reconstruct and score again "
                    "(in place: a copied folder has new file times and is segmented again)")
    ap.add_argument("--panorama-raise", choices=("image", "grid"), default="image",
                    help="where a panorama's low-confidence raise is taken "
                    "(ReconstructionParams.panorama_raise; docs/rigs.md)")
    args = ap.parse_args(argv)
    track = demo_track()
    rows: list[dict[str, Any]] = []
    for seed in args.seeds:
        # a different stretch of the line per seed, away from the ends
        span = float(track.length_m) - 2 * _MARGIN_M - args.length_m - 1000.0
        lo = 500.0 + float(np.random.default_rng([seed, 7]).uniform(0.0, span))
        lo = round(lo, -1)
        for name in args.rigs:
            if args.ideal_only:
                truth = truth_only(seed, lo, lo + args.length_m, args.work / f"truth_s{seed}")
                got = score_ideal(Rig.preset(name).scaled(args.scale), truth)
                print(f"{name:>17} seed {seed} km {lo / 1000:.2f}: ideal masks: across "
                      f"{100 * got['ideal_sky_lost_cross']:.2f} % along "
                      f"{100 * got['ideal_sky_lost_along']:.2f} %, false trust "
                      f"{100 * got['ideal_false_trust_all']:.4f} %", flush=True)  # fmt: skip
                rows.append({"rig": name, "seed": seed, "from_m": lo, **got})
                args.out.write_text(json.dumps({"runs": rows}, indent=1))
                continue
            row = run_one(Rig.preset(name).scaled(args.scale), seed, lo, lo + args.length_m,
                          args.work, args.reuse, args.panorama_raise)  # fmt: skip
            rows.append(row)
            print(f"{name:>17} seed {seed} km {lo / 1000:.1f}: sky lost across "
                  f"{100 * row['sky_lost_cross']:.2f} % along {100 * row['sky_lost_along']:.2f} %,"
                  f" false trust {100 * row['false_trust_all']:.4f} %, "
                  f"{row['frames_per_cpu_s']:.2f} frames/CPU-s; ideal masks: across "
                  f"{100 * row['ideal_sky_lost_cross']:.2f} % along "
                  f"{100 * row['ideal_sky_lost_along']:.2f} %, false trust "
                  f"{100 * row['ideal_false_trust_all']:.4f} %", flush=True)  # fmt: skip
            # every run kept as it ends: a long evaluation stopped early keeps its runs
            args.out.write_text(json.dumps({"runs": rows}, indent=1))
    if args.ideal_only:
        print("ideal sky masks (no segmentation error, the pipeline's thin-structure policy):")
        for name in args.rigs:
            p = pooled([r for r in rows if r["rig"] == name], ("ideal_",))
            print(f"{name:>17} pooled: across {100 * p['ideal_sky_lost_cross']:.2f} % along "
                  f"{100 * p['ideal_sky_lost_along']:.2f} %, false trust "
                  f"{100 * p['ideal_false_trust_all']:.4f} %")  # fmt: skip
        args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()},
                                        "runs": rows}, indent=1))  # fmt: skip
        return 0
    summary = {name: pooled([r for r in rows if r["rig"] == name]) for name in args.rigs}
    print(f"\n{'rig':>17} {'sky lost across %':>18} {'along %':>8} {'all %':>7} "
          f"{'false trust %':>14} {'frames/CPU-s':>13} {'positions/CPU-s':>16}")  # fmt: skip
    for name, s in summary.items():
        print(f"{name:>17} {100 * s['sky_lost_cross']:18.2f} {100 * s['sky_lost_along']:8.2f} "
              f"{100 * s['sky_lost_all']:7.2f} {100 * s['false_trust_all']:14.5f} "
              f"{s['frames_per_cpu_s']:13.2f} {s['positions_per_cpu_s']:16.2f}")  # fmt: skip
    print("ideal sky masks (no segmentation error), same reconstruction:")
    for name, s in summary.items():
        print(f"{name:>17} {100 * s['ideal_sky_lost_cross']:18.2f} "
              f"{100 * s['ideal_sky_lost_along']:8.2f} {100 * s['ideal_sky_lost_all']:7.2f} "
              f"{100 * s['ideal_false_trust_all']:14.5f}")  # fmt: skip
    args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()},
                                    "runs": rows, "pooled": summary}, indent=1))  # fmt: skip
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
