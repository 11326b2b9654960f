"""Benchmark: frames per second of the synthetic frame renderer, open3d vs trimesh + Embree.

Builds the demo world (2 km of Belgian line 144, ``WorldSpec.mixed``, as ``predisat demo``),
then renders the same frames (left and right cameras at positions spread over the run, skies
cycling clear / cloudy / overcast) with each ray-casting backend, and prints frames per second
of each, their ratio, and the projected time for the whole demo (about 200 positions x 2
frames). Labels of the two backends are compared pixel by pixel. Writes the figures as JSON.

Usage::

    python scripts/bench_render.py --out bench_render.json [--frames 12] [--width 640 --height 480]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from predisat.camera.models import CameraModel, Mount, default_camera
from predisat.synth.render import Casters, RenderOptions, camera_pose, render_frame
from predisat.synth.sky import SKY_CONDITIONS, SkyModel
from predisat.synth.world import World, WorldSpec
from predisat.track.map import demo_track


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("bench_render.json"))
    ap.add_argument("--frames", type=int, default=12, help="frames per backend")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--default-camera", action="store_true", help="use the shipped 800x600 camera")
    ap.add_argument("--supersample", type=int, default=RenderOptions().supersample)
    ap.add_argument("--start-m", type=float, default=4000.0)
    ap.add_argument("--length-m", type=float, default=2000.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    track = demo_track()
    lo, hi = args.start_m, args.start_m + args.length_m
    t0 = time.perf_counter()
    world = World.build(track, WorldSpec.mixed(lo - 150.0, hi + 150.0, args.seed), args.seed)
    t_world = time.perf_counter() - t0
    if args.default_camera:
        cam = default_camera("pinhole")
    else:
        cam = CameraModel.pinhole_from_fov(
            args.width, args.height, 74.0, dist=(-0.05, 0.01, 0.0, 0.0, 0.0)
        )
    opt = RenderOptions(supersample=args.supersample)
    n = args.frames
    chain = np.linspace(lo, hi, n // 2 + n % 2 + 2)[1:-1]
    jobs = [(float(c), side) for c in chain for side in ("left", "right")][:n]
    mounts = {side: Mount.default(side) for side in ("left", "right")}

    results: dict[str, dict] = {}
    labels: dict[str, list[np.ndarray]] = {}
    for backend in ("open3d", "trimesh"):
        t0 = time.perf_counter()
        casters = Casters.for_world(world, backend)
        t_build = time.perf_counter() - t0
        render_frame(
            world,
            casters,
            cam,
            camera_pose(world, jobs[0][0], mounts["left"]),
            SkyModel.clear(150.0, 45.0),
            np.random.default_rng(0),
            opt,
        )  # warm-up
        labels[backend] = []
        t0 = time.perf_counter()
        for k, (c, side) in enumerate(jobs):
            cond = SKY_CONDITIONS[k % len(SKY_CONDITIONS)]
            sky = SkyModel.of(cond, 150.0, 45.0, seed=k)
            pose = camera_pose(world, c, mounts[side])
            _, lab = render_frame(world, casters, cam, pose, sky, np.random.default_rng(k), opt)
            labels[backend].append(lab)
        dt = time.perf_counter() - t0
        fps = len(jobs) / dt
        results[backend] = {
            "frames": len(jobs),
            "seconds": round(dt, 3),
            "frames_per_s": round(fps, 4),
            "scene_build_s": round(t_build, 3),
            "demo_400_frames_min": round(400.0 / fps / 60.0, 2),
        }
        print(
            f"{backend:8s}: {len(jobs)} frames {cam.width_px}x{cam.height_px} in {dt:.1f} s "
            f"-> {fps:.3f} frames/s (demo, 400 frames: {400 / fps / 60:.1f} min)"
        )
    agree = float(
        np.mean([np.mean(a == b) for a, b in zip(labels["open3d"], labels["trimesh"], strict=True)])
    )
    ratio = results["open3d"]["frames_per_s"] / results["trimesh"]["frames_per_s"]
    print(f"open3d / trimesh speed ratio: {ratio:.2f}; label pixels equal: {100 * agree:.3f} %")
    doc = {
        "benchmark": "render",
        "camera": {"width_px": cam.width_px, "height_px": cam.height_px, "model": cam.model},
        "supersample": opt.supersample,
        "ambient_rays": opt.ambient_rays,
        "world": {"from_m": lo, "to_m": hi, "faces": int(world.faces.shape[0]),
                  "build_s": round(t_world, 3)},
        "backends": results,
        "open3d_over_trimesh": round(ratio, 3),
        "label_agreement": agree,
        "machine": {"python": platform.python_version(), "processor": platform.processor(),
                    "machine": platform.machine()},
    }  # fmt: skip
    args.out.write_text(json.dumps(doc, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
