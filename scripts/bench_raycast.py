"""Benchmark: open3d vs trimesh + Embree ray casting on the demo-sized synthetic world.

Builds a 2 km mixed world along Belgian line 144 (``predisat.track.map.demo_track``), then casts
the same rays with both backends:

* a side camera frame's worth of pixel rays (the default pinhole camera, left mount, 45 deg
  pitch) at several positions;
* a truth mask's worth of rays (720 bins x 4 sub-azimuths x a fan of elevations) at one
  position;

checks that they agree (same hit or miss, same distance to 1 mm), prints the rays per second of
each backend and their ratio, and compares the true masks computed with each backend on the
whole demo (every 10 m, 0.5 deg bins): the share of bins that agree within 0.1 deg.

Usage::

    python scripts/bench_raycast.py --out bench_raycast.json [--start-m 4000] [--length-m 2000]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from predisat.camera.models import Mount, default_camera
from predisat.geodesy import azel_to_enu
from predisat.synth.raycast import make_caster
from predisat.synth.truth import true_masks
from predisat.synth.world import World, WorldSpec
from predisat.track.map import demo_track


def _timed(fn, repeat: int = 3):
    """Best wall time over ``repeat`` runs (the machine is shared) and the last result."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def frame_rays(world: World, chainage_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel rays of the default left side camera at the given chainages (frame ENU)."""
    cam = default_camera("pinhole")
    u, v = cam.pixel_grid()
    rays_cam = cam.pixel_to_ray(u.ravel(), v.ravel())
    mount = Mount.default("left")
    origins, dirs = [], []
    for s in chainage_m:
        ant = world.antenna_enu(s)
        lat, lon, _ = world.frame.to_geodetic(ant)
        to_frame = world.frame.rotation_from(lat, lon)
        heading = float(world.track.heading_at(s))
        cam_enu = mount.camera_to_enu(heading)
        d_local = rays_cam @ cam_enu.T
        origins.append(np.broadcast_to(ant, d_local.shape))
        dirs.append(d_local @ to_frame.T)
    return np.concatenate(origins), np.concatenate(dirs)


def mask_rays(world: World, chainage_m: float) -> tuple[np.ndarray, np.ndarray]:
    """720 bins x 4 sub-azimuths x 24 elevations (0-60 deg) from one antenna (frame ENU)."""
    ant = world.antenna_enu(chainage_m)
    lat, lon, _ = world.frame.to_geodetic(ant)
    to_frame = world.frame.rotation_from(lat, lon)
    az, el = np.meshgrid(np.arange(2880) * 0.125, np.geomspace(0.05, 60.0, 24), indexing="ij")
    d = azel_to_enu(az.ravel(), el.ravel()) @ to_frame.T
    return np.broadcast_to(ant, d.shape), d


def compare(world: World, name: str, o: np.ndarray, d: np.ndarray) -> dict:
    res: dict = {"rays": len(o)}
    hits = {}
    for backend in ("open3d", "trimesh"):
        caster = make_caster(world, backend)
        caster.cast(o[:1000], d[:1000])  # warm-up (scene build)
        sec, hits[backend] = _timed(lambda c=caster: c.cast(o, d))
        res[f"{backend}_rays_per_s"] = len(o) / sec
        sec_occ, _ = _timed(lambda c=caster: c.occluded(o, d))
        res[f"{backend}_occlusion_rays_per_s"] = len(o) / sec_occ
    a, b = hits["open3d"], hits["trimesh"]
    both = a.hit & b.hit
    res["same_hit_or_miss"] = float(np.mean(a.hit == b.hit))
    res["same_distance_1mm"] = float(
        np.mean(np.abs(a.distance_m[both] - b.distance_m[both]) < 1e-3)
    )
    res["open3d_over_trimesh"] = res["open3d_rays_per_s"] / res["trimesh_rays_per_s"]
    print(
        f"{name:>12}: {len(o):>9d} rays  open3d {res['open3d_rays_per_s'] / 1e6:6.2f} Mray/s  "
        f"trimesh {res['trimesh_rays_per_s'] / 1e6:6.2f} Mray/s  "
        f"ratio {res['open3d_over_trimesh']:.2f}"
        f"  | agree: hit/miss {100 * res['same_hit_or_miss']:.3f} %  "
        f"distance {100 * res['same_distance_1mm']:.3f} %"
    )
    return res


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("bench_raycast.json"))
    ap.add_argument("--start-m", type=float, default=4000.0)
    ap.add_argument("--length-m", type=float, default=2000.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)

    track = demo_track()
    lo, hi = args.start_m, args.start_m + args.length_m
    t0 = time.perf_counter()
    world = World.build(track, WorldSpec.mixed(lo, hi, seed=args.seed), seed=args.seed)
    build_s = time.perf_counter() - t0
    print(f"world: line 144 {lo:.0f}-{hi:.0f} m, {len(world.faces)} triangles, {build_s:.2f} s")
    out: dict = {
        "machine": platform.platform(),
        "world": {"start_m": lo, "end_m": hi, "seed": args.seed, "triangles": len(world.faces),
                  "build_s": build_s},
    }  # fmt: skip
    s_frames = np.linspace(lo + 100, hi - 100, 5)
    out["frame_rays"] = compare(world, "frame x5", *frame_rays(world, s_frames))
    out["mask_rays"] = compare(world, "mask fan", *mask_rays(world, lo + 0.37 * (hi - lo)))

    s = np.arange(np.ceil(lo / 10) * 10, hi + 1e-9, 10.0)
    masks, times = {}, {}
    for backend in ("open3d", "trimesh"):
        t0 = time.perf_counter()
        masks[backend] = true_masks(world, s, backend=backend)
        times[backend] = time.perf_counter() - t0
    diff = np.abs(masks["open3d"].mask_el_deg - masks["trimesh"].mask_el_deg)
    agree = float(np.mean(diff <= 0.1))
    out["true_masks"] = {
        "positions": int(s.size),
        "bins": int(diff.size),
        "az_step_deg": 0.5,
        "open3d_s": times["open3d"],
        "trimesh_s": times["trimesh"],
        "agree_within_0p1_deg": agree,
        "max_abs_diff_deg": float(diff.max()),
    }
    print(
        f"true masks: {s.size} positions x 720 bins; open3d {times['open3d']:.1f} s, "
        f"trimesh {times['trimesh']:.1f} s; agreement within 0.1 deg: {100 * agree:.4f} % of "
        f"bins (target >= 99.9 %), max difference {diff.max():.2f} deg"
    )
    args.out.write_text(json.dumps(out, indent=2))
    print(f"wrote {args.out}")
    return out


if __name__ == "__main__":
    main()
