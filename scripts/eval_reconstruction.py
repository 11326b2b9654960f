"""Evaluate the mask reconstruction against synthetic ground truth (issue 3).

A synthetic world (``WorldSpec.mixed``) is built along the demo track; ideal sky masks are
ray cast for side cameras at every frame position (sky = no L-band-blocking hit, so wires count
as sky), masks are reconstructed chunk by chunk and compared with ``true_masks``:

* signed error (reconstructed - true) elevation: median and 95th percentile, split into
  cross-track (relative azimuth within +-45 deg of +-90) and along-track sectors, and by source
  flag;
* unsafe share: bins where reconstructed < true - 0.1 deg (without any margin);
* visible sky lost: share of the truly visible sky (solid angle above the true mask) that the
  reconstructed mask hides;
* speed: frames per second of the reconstruction (profiles + carving + ray casting).

Usage::

    .venv/bin/python scripts/eval_reconstruction.py --from 2000 --to 6000 --camera both \\
        --out eval_reconstruction.json

Prints a table and writes the JSON (and an error figure with ``--figure``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from predisat.camera.models import default_camera
from predisat.masks.maskset import BinSource
from predisat.reconstruct.carving import Reconstruction, ReconstructionParams, Reconstructor
from predisat.synth.raycast import make_caster
from predisat.synth.truth import ideal_frames, true_masks
from predisat.synth.world import World, WorldSpec
from predisat.track.map import demo_track


def sectors(heading_deg: np.ndarray, az_deg: np.ndarray) -> np.ndarray:
    """True where a bin is cross-track (relative azimuth within 45 deg of +-90)."""
    rel = np.mod(az_deg[None, :] - heading_deg[:, None], 180.0)
    return np.abs(rel - 90.0) <= 45.0


def visible_sky_lost(true_el: np.ndarray, rec_el: np.ndarray) -> float:
    """Share of the truly visible solid angle (above the true mask) hidden by ``rec_el``."""
    vis = 1.0 - np.sin(np.radians(true_el))
    kept = 1.0 - np.sin(np.radians(np.maximum(rec_el, true_el)))
    return float(1.0 - kept.sum() / max(vis.sum(), 1e-12))


def stats(err: np.ndarray, true_el: np.ndarray, rec_el: np.ndarray) -> dict[str, float]:
    if err.size == 0:
        return {"n_bins": 0}
    return {
        "n_bins": int(err.size),
        "median_err_deg": float(np.median(err)),
        "p95_err_deg": float(np.percentile(err, 95)),
        "p05_err_deg": float(np.percentile(err, 5)),
        "unsafe_share": float(np.mean(err < -0.1)),
        "sky_lost_share": visible_sky_lost(true_el, rec_el),
    }


def run_camera(
    world: World,
    caster,
    kind: str,
    s_pos: np.ndarray,
    tm,
    params: ReconstructionParams,
    chunk_m: float,
) -> tuple[dict, Reconstruction | None, list]:
    """Reconstruct with one camera kind over ``s_pos`` in chunks; returns the figures."""
    camera = default_camera(kind)  # type: ignore[arg-type]
    lo, hi = float(s_pos.min()), float(s_pos.max())
    ov = params.overlap_m
    f_s = np.arange(max(world.extent_m[0], lo - ov), min(world.extent_m[1], hi + ov) + 1e-9, 10.0)
    t0 = time.perf_counter()
    frames = ideal_frames(world, f_s, camera, caster=caster)
    t_frames = time.perf_counter() - t0
    rec = Reconstructor(params)
    parts = []
    t0 = time.perf_counter()
    n_used = 0
    for a in np.arange(lo, hi + 1e-9, chunk_m):
        sel = s_pos[(s_pos >= a) & (s_pos < a + chunk_m)]
        if sel.size == 0:
            continue
        near = [f for f in frames if sel.min() - ov <= f.chainage_m <= sel.max() + ov]
        n_used += len(near)
        parts.append(rec.run(near, sel, world.track))
    t_rec = time.perf_counter() - t0
    mask = np.concatenate([p.mask_el_deg for p in parts]).astype(float)
    grid = np.concatenate([p.grid_el_deg for p in parts]).astype(float)
    src = np.concatenate([p.source for p in parts])
    truth = tm.mask_el_deg
    err = mask - truth
    cross = sectors(tm.heading_deg, tm.az_deg)
    out: dict = {
        "camera": kind,
        "n_positions": int(s_pos.size),
        "n_frames": len(frames),
        "ideal_label_s": round(t_frames, 2),
        "reconstruction_s": round(t_rec, 2),
        "frames_per_s": round(2 * s_pos.size / t_rec, 1),
        "frames_per_s_note": "2 frames per position; carving of overlap frames counted in time",
        "all": stats(err, truth, mask),
        "cross_track": stats(err[cross], truth[cross], mask[cross]),
        "along_track": stats(err[~cross], truth[~cross], mask[~cross]),
        "by_source": {},
        "source_share": {},
        "grid_only_along_track": stats(
            (grid - truth)[~cross], truth[~cross], np.clip(grid, 0, 90)[~cross]
        ),
    }
    for code in BinSource:
        sel = src == int(code)
        out["source_share"][code.name] = float(sel.mean())
        out["by_source"][code.name] = stats(err[sel], truth[sel], mask[sel])
    # lowest along-track elevation reached in open bins: 10-deg relative sectors
    rel = np.mod(tm.az_deg[None, :] - tm.heading_deg[:, None] + 180.0, 360.0) - 180.0
    off_axis = np.minimum(np.abs(rel), 180.0 - np.abs(rel))
    open_truth = truth < 0.5
    lows = {}
    for lo_a in (0, 5, 10, 20, 30, 45):
        band = (off_axis >= lo_a) & (off_axis < lo_a + 5) & open_truth
        if band.any():
            lows[f"{lo_a}-{lo_a + 5}"] = {
                "median_mask_deg": float(np.median(mask[band])),
                "median_grid_deg": float(np.median(np.clip(grid[band], 0, 90))),
            }
    out["open_truth_by_off_axis_deg"] = lows
    return out, parts[0] if parts else None, [mask, grid, src]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--from", dest="lo", type=float, default=2000.0)
    ap.add_argument("--to", dest="hi", type=float, default=6000.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--step", type=float, default=10.0, help="position spacing, m")
    ap.add_argument("--camera", choices=("pinhole", "fisheye", "both"), default="both")
    ap.add_argument("--chunk", type=float, default=250.0, help="positions per chunk, m")
    ap.add_argument("--cell", type=float, default=0.5)
    ap.add_argument("--reach", type=float, default=120.0)
    ap.add_argument("--out", type=Path, default=Path("eval_reconstruction.json"))
    ap.add_argument("--figure", type=Path, default=None)
    args = ap.parse_args()

    track = demo_track()
    spec = WorldSpec.mixed(args.lo, args.hi, seed=args.seed)
    t0 = time.perf_counter()
    world = World.build(track, spec, seed=args.seed)
    caster = make_caster(world, "open3d", lband_only=True)
    margin = 300.0
    s_pos = np.arange(args.lo + margin, args.hi - margin + 1e-9, args.step)
    tm = true_masks(world, s_pos, caster=caster)
    print(f"world + truth: {time.perf_counter() - t0:.1f} s, {s_pos.size} positions")
    params = ReconstructionParams(cell_m=args.cell, reach_m=args.reach)
    kinds = ("pinhole", "fisheye") if args.camera == "both" else (args.camera,)
    report: dict[str, Any] = {
        "world": {"track": track.name, "from_m": args.lo, "to_m": args.hi, "seed": args.seed,
                  "stretches": [s.to_dict() for s in spec.stretches]},
        "params": {k: (list(v) if isinstance(v, tuple) else v) for k, v in params.__dict__.items()},
        "results": [],
    }  # fmt: skip
    curves = {}
    for kind in kinds:
        res, _, arrays = run_camera(world, caster, kind, s_pos, tm, params, args.chunk)
        report["results"].append(res)
        curves[kind] = arrays
        print(f"\n== {kind}: {res['n_positions']} positions, {res['frames_per_s']} frames/s")
        head = f"{'subset':<16}{'bins':>9}{'median':>9}{'p95':>9}{'unsafe':>10}{'sky lost':>10}"
        print(head)
        rows = [("all", res["all"]), ("cross-track", res["cross_track"]),
                ("along-track", res["along_track"])]  # fmt: skip
        rows += [(k.lower(), v) for k, v in res["by_source"].items()]
        for name, st in rows:
            if st.get("n_bins", 0) == 0:
                continue
            print(
                f"{name:<16}{st['n_bins']:>9}{st['median_err_deg']:>9.2f}{st['p95_err_deg']:>9.2f}"
                f"{st['unsafe_share']:>10.5f}{st['sky_lost_share']:>10.3f}"
            )
        print("source share:", {k: round(v, 3) for k, v in res["source_share"].items()})
        print("open-truth bins, median mask by off-axis angle:", res["open_truth_by_off_axis_deg"])
    args.out.write_text(json.dumps(report, indent=1))
    print(f"\nwritten {args.out}")
    if args.figure is not None:
        _figure(args.figure, tm, curves)


def _figure(path: Path, tm, curves: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(6 * len(curves), 4), squeeze=False)
    rel = np.mod(tm.az_deg[None, :] - tm.heading_deg[:, None], 360.0)
    i = tm.mask_el_deg.shape[0] // 2
    order = np.argsort(rel[i])
    for ax, (kind, (mask, grid, _)) in zip(axes[0], curves.items(), strict=True):
        ax.plot(rel[i][order], tm.mask_el_deg[i][order], "k-", lw=1, label="truth")
        ax.plot(rel[i][order], mask[i][order], "r-", lw=1, label="reconstructed")
        ax.plot(rel[i][order], np.clip(grid[i][order], 0, 90), "b:", lw=1, label="height field")
        ax.set_title(f"{kind}: chainage {tm.chainage_m[i]:.0f} m")
        ax.set_xlabel("azimuth relative to track heading, deg")
        ax.set_ylabel("mask elevation, deg")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    print(f"written {path}")


if __name__ == "__main__":
    main()
