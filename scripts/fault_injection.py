"""Fault injection: false trust and sky lost of the min and robust fusions against the fault
rate (issue 30, item 2; ``docs/reconstruction.md``, section 6).

Three steps, each reusing the previous one's files::

    # 1. the operating point: false-sky rate and unsafe columns of the default segmenter on
    #    real photos (read from ../shared, never copied)
    .venv/bin/python scripts/fault_injection.py measure \\
        --data ../shared/data/sky/ade20k ../shared/data/sky/fisheye_hk --out /tmp/fi/real.json
    # 2. a small synthetic survey: ideal masks, scene classes per pixel, true masks (cached)
    .venv/bin/python scripts/fault_injection.py build --out /tmp/fi/survey.npz
    # 3. faults at multiples of the operating point, both fusions on the same faults
    .venv/bin/python scripts/fault_injection.py curve --survey /tmp/fi/survey.npz \\
        --real /tmp/fi/real.json --out /tmp/fi/curve.json --figure docs/figures/fault_injection.png
    # each class alone at 3x its operating rate
    .venv/bin/python scripts/fault_injection.py classes --survey /tmp/fi/survey.npz \
        --curve /tmp/fi/curve.json --factor 3
    # the survey's true masks with thin structures never blocking (the truth the ideal masks'
    # thin policy agrees with; `curve --truth` scores against it)
    .venv/bin/python scripts/fault_injection.py truth --survey /tmp/fi/survey.npz \
        --out /tmp/fi/truth_thin_transparent.npy
    # the table and the figure again, from the JSON
    .venv/bin/python scripts/fault_injection.py plot --curve /tmp/fi/curve.json \
        --figure docs/figures/fault_injection.png

The operating point: per-class rates cannot be measured on the real photos (they carry sky
masks, not fault classes). Whole-frame failures strike at the share of real street photos
with false sky over at least a fifth of their non-sky pixels; the local classes are injected
in the mix of :meth:`FaultRates.mix <predisat.reconstruct.faults.FaultRates.mix>` at the total
rate whose unsafe-column share on the survey's frames equals the one measured on the real
street photos.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from predisat.reconstruct.faults import (
    LABEL_BUILDING,
    LABEL_GROUND,
    LABEL_NONE,
    LABEL_OTHER,
    LABEL_SKY,
    FaultRates,
    false_sky_stats,
    inject_faults,
)

POSITIONS_M = (2250.0, 2600.0)  # mask positions: town, station, trees
STEP_M = 10.0
REACH_M = 120.0


def measure(data: list[Path], out: Path) -> None:
    """False-sky rate and unsafe-column share of the default segmenter per real photo set."""
    from predisat.sky.photoeval import find_pairs
    from predisat.sky.segment import SkyOptions, segment_sky

    res: dict[str, Any] = {}
    for d in data:
        layout, pairs = find_pairs(d)
        opt = SkyOptions(fisheye=layout == "fisheye_hk")
        tot = {"false_sky_px": 0, "non_sky_px": 0, "unsafe_columns": 0, "columns": 0,
               "unsafe_joined_columns": 0}  # fmt: skip
        whole = 0
        t0 = time.process_time()
        for pair in pairs:
            img = cv2.imread(str(pair.image_path), cv2.IMREAD_COLOR)
            m = cv2.imread(str(pair.mask_path), cv2.IMREAD_GRAYSCALE)
            if img is None or m is None:
                raise OSError(f"{pair.image_path} or {pair.mask_path} unreadable")
            if m.shape != img.shape[:2]:
                m = cv2.resize(m, img.shape[1::-1], interpolation=cv2.INTER_NEAREST)
            seg = segment_sky(img, opt)
            st = false_sky_stats(seg.sky_mask, (m >= 128) & seg.valid_mask, seg.valid_mask)
            for k in tot:
                tot[k] += st[k]
            whole += st["false_sky_px"] >= 0.2 * max(st["non_sky_px"], 1)
        res[d.name] = {
            "layout": layout, "n_images": len(pairs),
            "false_sky_rate": tot["false_sky_px"] / max(tot["non_sky_px"], 1),
            "unsafe_column_share": tot["unsafe_columns"] / max(tot["columns"], 1),
            "unsafe_joined_column_share": tot["unsafe_joined_columns"] / max(tot["columns"], 1),
            "whole_frame_share": whole / max(len(pairs), 1),
            "cpu_s": round(time.process_time() - t0, 1),
        }  # fmt: skip
        print(d.name, json.dumps(res[d.name]))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1))


def _world() -> Any:
    from predisat.synth.world import Stretch, World, WorldSpec
    from predisat.track.map import demo_track

    spec = WorldSpec((
        Stretch("open", 1900.0, 2150.0), Stretch("town", 2150.0, 2450.0, "both"),
        Stretch("station", 2450.0, 2560.0, "both"), Stretch("trees", 2560.0, 2700.0, "left"),
        Stretch("open", 2700.0, 2950.0),
    ))  # fmt: skip
    return World.build(demo_track(), spec, seed=3)


def build(out: Path, camera_kind: str) -> None:
    """Ideal masks, scene classes per pixel and true masks of a small survey (npz)."""
    from predisat.camera.models import Mount, default_camera
    from predisat.synth.materials import MATERIALS
    from predisat.synth.raycast import make_caster
    from predisat.synth.render import camera_pose
    from predisat.synth.truth import ideal_sky_mask, true_masks

    t0 = time.perf_counter()
    world = _world()
    lband = make_caster(world, "open3d", lband_only=True)
    full = make_caster(world, "open3d", lband_only=False)
    cam = default_camera(camera_kind)  # type: ignore[arg-type]
    cam = cam.resized(640, 480)  # the demo surveys' frame size
    lo, hi = POSITIONS_M
    margin = REACH_M + 60.0 + 5.0 + 25.0
    f_s = np.arange(lo - margin, hi + margin + 1e-9, STEP_M)
    s_pos = np.arange(lo, hi + 1e-9, STEP_M)
    cls_of = np.full(len(MATERIALS), LABEL_OTHER, np.int8)
    for i, m in enumerate(MATERIALS):
        if m.name in ("brick", "plaster", "roof_tiles", "concrete", "canopy"):
            cls_of[i] = LABEL_BUILDING
        elif m.name in ("grass", "ballast", "platform", "hills"):
            cls_of[i] = LABEL_GROUND
    rays = cam.pixel_to_ray(*cam.pixel_grid())
    good = np.all(np.isfinite(rays), axis=-1)
    sky, lab, side, ch = [], [], [], []
    for s in f_s:
        for sd in ("left", "right"):
            mount = Mount.default(sd)
            m = ideal_sky_mask(world, [s], cam, mount, caster=lband)[0]
            pos, rot = camera_pose(world, float(s), mount, 4.0, False)
            d = rays[good] @ rot.T
            hits = full.cast(np.broadcast_to(pos, d.shape), d)
            mat = hits.material_id(world.face_material)
            lb = np.full(cam.shape, LABEL_NONE, np.int8)
            lb[good] = np.where(mat >= 0, cls_of[np.maximum(mat, 0)], LABEL_SKY)
            lb[m] = LABEL_SKY
            sky.append(m)
            lab.append(lb)
            side.append(sd)
            ch.append(s)
    tm = true_masks(world, s_pos, caster=lband)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out, sky=np.array(sky), labels=np.array(lab), side=np.array(side),
        chainage_m=np.array(ch), positions_m=s_pos, truth_el_deg=tm.mask_el_deg,
        camera=camera_kind,
    )  # fmt: skip
    dt = time.perf_counter() - t0
    print(f"{len(sky)} frames {cam.shape}, {s_pos.size} positions: {dt:.0f} s")


def _frames(data: Any, masks: list[np.ndarray], camera_kind: str) -> list[Any]:
    from predisat.camera.models import Mount, default_camera
    from predisat.reconstruct.carving import FrameView
    from predisat.track.map import demo_track

    track = demo_track()
    cam = default_camera(camera_kind)  # type: ignore[arg-type]
    cam = cam.resized(640, 480)  # the demo surveys' frame size
    ch = data["chainage_m"]
    axis = np.asarray(track.enu_at(ch), float)
    ant = axis + 4.0 * np.asarray(track.up_at(ch), float)
    hd = np.asarray(track.heading_at(ch), float)
    mounts = {"left": Mount.default("left"), "right": Mount.default("right")}
    return [
        FrameView(float(ch[i]), masks[i], cam, mounts[str(data["side"][i])], ant[i],
                  float(hd[i]), frame_id=f"{ch[i]:.0f}{str(data['side'][i])[0]}")
        for i in range(len(masks))
    ]  # fmt: skip


def _score(mask: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    from predisat.reconstruct.evaluate import trust_counts

    trusted, trusted_los, los = trust_counts(mask, truth)
    false = trusted - trusted_los
    per_pos = false.sum(axis=1) / np.maximum(trusted.sum(axis=1), 1)
    return {
        "false_trust": float(false.sum() / max(trusted.sum(), 1)),
        "worst_position_false_trust": float(per_pos.max()),
        "positions_with_false_trust": int((per_pos > 0).sum()),
        "sky_lost": float(1.0 - trusted_los.sum() / max(los.sum(), 1)),
    }


def _fault_stats(clean: np.ndarray, faulty: list[np.ndarray], labels: np.ndarray) -> dict:
    tot = {"false_sky_px": 0, "non_sky_px": 0, "unsafe_columns": 0, "columns": 0,
           "unsafe_joined_columns": 0}  # fmt: skip
    for c, f, lb in zip(clean, faulty, labels, strict=True):
        st = false_sky_stats(f, c, lb != LABEL_NONE)
        for k in tot:
            tot[k] += st[k]
    return {
        "false_sky_rate": tot["false_sky_px"] / max(tot["non_sky_px"], 1),
        "unsafe_column_share": tot["unsafe_columns"] / max(tot["columns"], 1),
        "unsafe_joined_column_share": tot["unsafe_joined_columns"] / max(tot["columns"], 1),
    }


def calibrate(data: Any, target: float, whole: float, seed: int) -> float:
    """Total rate of the local fault classes (mix of FaultRates.mix, whole-frame failures at
    the measured ``whole``) whose unsafe-column share is ``target`` (bisection on the survey's
    frames, faults of one seed)."""
    lo, hi = 0.0, 8.0
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        faulty, _ = inject_faults(list(data["sky"]), list(data["labels"]), list(data["side"]),
                                  FaultRates.mix(mid, whole), seed)  # fmt: skip
        share = _fault_stats(data["sky"], faulty, data["labels"])["unsafe_column_share"]
        lo, hi = (mid, hi) if share < target else (lo, mid)
    return 0.5 * (lo + hi)


def thin_transparent_truth(survey: Path, out: Path) -> None:
    """The survey's true masks with thin structures transparent at any distance
    (``true_masks(..., thin_rule=False)``), saved for ``curve --truth``: since the Fresnel rule
    became the truth's default, the ideal masks' thin policy (thin structures are sky) puts a
    floor of false trust under every fusion against the survey's own truth."""
    from predisat.synth.raycast import make_caster
    from predisat.synth.truth import true_masks

    world = _world()
    data = np.load(survey, allow_pickle=False)
    caster = make_caster(world, "open3d", lband_only=True)
    tm = true_masks(world, data["positions_m"], caster=caster, thin_rule=False)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.save(out, tm.mask_el_deg)
    lower = int((tm.mask_el_deg < data["truth_el_deg"]).sum())
    print(f"{out}: {tm.mask_el_deg.shape}, {lower} bins below the survey's own truth")


def curve(survey: Path, real: Path, out: Path, figure: Path | None, seeds: int,
          factors: list[float], ranks: list[int], suspect: float | None,
          consistency: Sequence[int] = (), truth_npy: Path | None = None) -> None:  # fmt: skip
    from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
    from predisat.track.map import demo_track

    data = dict(np.load(survey, allow_pickle=False))
    kind = str(data["camera"])
    measured = json.loads(real.read_text())
    street = next(v for v in measured.values() if v["layout"] != "fisheye_hk")
    target = float(street["unsafe_column_share"])
    whole = float(street["whole_frame_share"])
    total = calibrate(data, target, whole, 0)
    print(f"operating point: local faults {total:.3f} per frame, whole-frame failures {whole:.3f} "
          f"(unsafe columns {target:.3f} and whole-frame share as measured on the real street "
          "photos)")  # fmt: skip
    track = demo_track()
    pos = data["positions_m"]
    truth = data["truth_el_deg"] if truth_npy is None else np.load(truth_npy)
    settings = {"min": ReconstructionParams(reach_m=REACH_M)}
    for k in consistency:
        settings[f"min+check{k}"] = ReconstructionParams(reach_m=REACH_M, consistency_rank=k)
    for k in ranks:
        settings[f"rank{k}"] = ReconstructionParams(reach_m=REACH_M, fusion_rank=k)
        if suspect is not None:
            settings[f"rank{k}+suspect"] = ReconstructionParams(
                reach_m=REACH_M, fusion_rank=k, suspect_share=suspect
            )
    recs = {name: Reconstructor(p) for name, p in settings.items()}
    rows = []
    for factor in factors:
        for seed in range(seeds if factor > 0 else 1):
            rates = FaultRates.mix(total * factor, whole * factor)
            faulty, faults = inject_faults(list(data["sky"]), list(data["labels"]),
                                           list(data["side"]), rates, seed)  # fmt: skip
            fs = _fault_stats(data["sky"], faulty, data["labels"])
            frames = _frames(data, faulty, kind)
            for name, rec in recs.items():
                t0 = time.process_time()
                r = rec.run(frames, pos, track)
                row = {"factor": factor, "seed": seed, "fusion": name, "n_faults": len(faults),
                       **fs, **_score(r.mask_el_deg.astype(float), truth),
                       "suspect_frames": len(r.suspect_frames),
                       "cpu_s": round(time.process_time() - t0, 1)}  # fmt: skip
                rows.append(row)
                print(json.dumps(row))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"operating_total_rate": total, "operating_whole_frame": whole,
                               "target_unsafe_columns": target,
                               "measured": measured, "rows": rows}, indent=1))  # fmt: skip
    _table(rows)
    if figure is not None:
        _figure(rows, figure)


def per_class(survey: Path, curve_json: Path, factor: float, ranks: list[int]) -> None:
    """Each fault class alone at ``factor`` times its operating rate (from a curve's JSON),
    the fusions side by side (one seed)."""
    from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
    from predisat.track.map import demo_track

    data = dict(np.load(survey, allow_pickle=False))
    done = json.loads(curve_json.read_text())
    rates = FaultRates.mix(done["operating_total_rate"] * factor,
                           done["operating_whole_frame"] * factor)  # fmt: skip
    track = demo_track()
    settings = {"min": ReconstructionParams(reach_m=REACH_M)}
    settings |= {f"rank{k}": ReconstructionParams(reach_m=REACH_M, fusion_rank=k) for k in ranks}
    print(f"\n| class (x{factor:g} operating) | rate per frame | false-sky rate | unsafe columns | "
          + " | ".join(f"false trust {n} | sky lost {n}" for n in settings) + " |")
    print("|---|---|---|---|" + "---|---|" * len(settings))
    for kind, rate in rates.rates.items():
        faulty, _ = inject_faults(list(data["sky"]), list(data["labels"]), list(data["side"]),
                                  FaultRates({kind: rate}), 0)  # fmt: skip
        fs = _fault_stats(data["sky"], faulty, data["labels"])
        frames = _frames(data, faulty, str(data["camera"]))
        cells = []
        for p in settings.values():
            r = Reconstructor(p).run(frames, data["positions_m"], track)
            sc = _score(r.mask_el_deg.astype(float), data["truth_el_deg"])
            cells.append(f"{100 * sc['false_trust']:.4f} % | {100 * sc['sky_lost']:.1f} %")
        print(f"| {kind} | {rate:.2f} | {100 * fs['false_sky_rate']:.2f} % | "
              f"{100 * fs['unsafe_column_share']:.1f} % | " + " | ".join(cells) + " |")


def _mean_rows(rows: list[dict]) -> dict[tuple[float, str], dict[str, float]]:
    agg: dict[tuple[float, str], list[dict]] = {}
    for r in rows:
        agg.setdefault((r["factor"], r["fusion"]), []).append(r)
    return {
        k: {m: float(np.mean([r[m] for r in v])) for m in
            ("false_trust", "sky_lost", "worst_position_false_trust", "false_sky_rate",
             "unsafe_column_share", "suspect_frames", "positions_with_false_trust")}
        for k, v in agg.items()
    }  # fmt: skip


def _table(rows: list[dict]) -> None:
    mean = _mean_rows(rows)
    print("\n| x operating | fusion | false-sky rate | unsafe columns | false trust | worst "
          "position | positions with false trust | sky lost | suspect frames |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (f, name), v in sorted(mean.items()):
        print(f"| {f:g} | {name} | {100 * v['false_sky_rate']:.2f} % | "
              f"{100 * v['unsafe_column_share']:.1f} % | {100 * v['false_trust']:.4f} % | "
              f"{100 * v['worst_position_false_trust']:.3f} % | "
              f"{v['positions_with_false_trust']:.1f} | {100 * v['sky_lost']:.1f} % | "
              f"{v['suspect_frames']:.1f} |")


def _figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mean = _mean_rows(rows)
    names = sorted({k[1] for k in mean})
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for name in names:
        f = sorted(k[0] for k in mean if k[1] == name)
        ax[0].plot(f, [100 * mean[(x, name)]["false_trust"] for x in f], "o-", label=name)
        ax[1].plot(f, [100 * mean[(x, name)]["sky_lost"] for x in f], "o-", label=name)
    ax[0].set(xlabel="fault rate / operating point", ylabel="false trust (% of trusted)",
              title="false trust", yscale="log")  # fmt: skip
    ax[1].set(xlabel="fault rate / operating point", ylabel="visible sky lost (%)",
              title="sky lost")  # fmt: skip
    for a in ax:
        a.axvline(1.0, color="grey", lw=0.8, ls="--")
        a.grid(alpha=0.3)
        a.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"written {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("measure", help="false sky of the default segmenter on real photos")
    m.add_argument("--data", type=Path, nargs="+", required=True)
    m.add_argument("--out", type=Path, required=True)
    b = sub.add_parser("build", help="ideal masks, scene classes and truth of a small survey")
    b.add_argument("--out", type=Path, required=True)
    b.add_argument("--camera", choices=("fisheye", "pinhole"), default="fisheye")
    c = sub.add_parser("curve", help="false trust and sky lost against the fault rate")
    c.add_argument("--survey", type=Path, required=True)
    c.add_argument("--real", type=Path, required=True, help="JSON written by measure")
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--figure", type=Path)
    c.add_argument("--seeds", type=int, default=2)
    c.add_argument("--factors", type=float, nargs="+", default=[0.0, 0.5, 1.0, 2.0, 3.0])
    c.add_argument("--ranks", type=int, nargs="*", default=[2])
    c.add_argument("--consistency", type=int, nargs="*", default=[],
                   help="also rank 1 with the consistency check at these consistency_rank")
    c.add_argument("--truth", type=Path,
                   help="score against these true masks (.npy, positions x bins) instead of "
                        "the survey's")
    c.add_argument("--suspect", type=float, default=0.25,
                   help="suspect_share of the robust settings (negative: no check)")
    t = sub.add_parser("truth", help="the survey's truth with thin structures transparent")
    t.add_argument("--survey", type=Path, required=True)
    t.add_argument("--out", type=Path, required=True, help=".npy for curve --truth")
    g = sub.add_parser("plot", help="table and figure again from a curve's JSON")
    g.add_argument("--curve", type=Path, required=True)
    g.add_argument("--figure", type=Path, required=True)
    k = sub.add_parser("classes", help="each fault class alone, the fusions side by side")
    k.add_argument("--survey", type=Path, required=True)
    k.add_argument("--curve", type=Path, required=True, help="JSON written by curve")
    k.add_argument("--factor", type=float, default=3.0)
    k.add_argument("--ranks", type=int, nargs="+", default=[2, 3])
    a = ap.parse_args()
    if a.cmd == "classes":
        per_class(a.survey, a.curve, a.factor, a.ranks)
    elif a.cmd == "plot":
        rows = json.loads(a.curve.read_text())["rows"]
        _table(rows)
        _figure(rows, a.figure)
    elif a.cmd == "truth":
        thin_transparent_truth(a.survey, a.out)
    elif a.cmd == "measure":
        measure(a.data, a.out)
    elif a.cmd == "build":
        build(a.out, a.camera)
    else:
        curve(a.survey, a.real, a.out, a.figure, a.seeds, a.factors, a.ranks,
              None if a.suspect < 0 else a.suspect, a.consistency, a.truth)  # fmt: skip


if __name__ == "__main__":
    main()
