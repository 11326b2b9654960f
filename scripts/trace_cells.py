"""Which frames bound the height-field cells along one ray from an antenna (false-trust tracing).

For a mask bin trusted where the truth is blocked, the question is which cells the antenna's
ray crosses, how high each is bounded, and which frame carved each one that low. This script
rebuilds the height field around a position from a processed world's cached segmentations
(the layout of ``scripts/eval_rigs.py``: ``RUN/synth/survey`` and ``RUN/proc/cache``), marches
the ray at one azimuth, prints every cell it crosses (distance, offset from the track axis,
chainage, bound over the antenna and the elevation it means), then, for the cells between two
distances, every frame whose carving alone bounds the cell within 3 deg of its final value.

Usage::

    .venv/bin/python scripts/trace_cells.py RUN TRUTH CHAINAGE_M AZIMUTH_DEG \\
        [--from-m 3 --to-m 8] [--max-m 30]

``TRUTH``: a truth folder with ``world.npz`` (the world's track). Example (docs/reconstruction.md,
section 13): ``scripts/trace_cells.py /tmp/eval_rigs_full/360_s12
/tmp/eval_rigs_full/side-fisheye_s12/synth/truth 5510 189 --from-m 3.9 --to-m 4.5``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from predisat.reconstruct import carving as cv
from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
from predisat.reconstruct.heightfield import carve_profile
from predisat.synth.world import World

sys.path.insert(0, str(Path(__file__).resolve().parent))
from along_attribution import pipeline_frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="world folder with synth/survey and proc/cache")
    ap.add_argument("truth", type=Path, help="truth folder with world.npz")
    ap.add_argument("chainage_m", type=float)
    ap.add_argument("azimuth_deg", type=float, help="from north, degrees")
    ap.add_argument("--from-m", type=float, default=0.0, help="trace frames from this distance")
    ap.add_argument("--to-m", type=float, default=0.0, help="... to this one (0: no tracing)")
    ap.add_argument("--max-m", type=float, default=30.0, help="march the ray this far")
    args = ap.parse_args()
    if not (args.truth / "world.npz").exists():
        raise SystemExit(f"{args.truth}: no world.npz there; give the world's truth folder")
    world = World.load(args.truth / "world.npz")
    frames = pipeline_frames(args.run, world.track)
    p = ReconstructionParams()
    rc = Reconstructor(p)
    s = args.chainage_m
    keep = [f for f in frames if abs(f.chainage_m - s) <= p.used_m]
    if not keep:
        raise SystemExit(f"no frame within {p.used_m} m of {s} m; check the chainage")
    profs = rc.profiles(keep)
    margin = p.reach_m + cv._WINDOW_MARGIN_M
    hf = rc.height_field(keep, world.track, s - margin, s + margin, profs)
    ant, rot = cv._antennas(world.track, np.array([s]), p.antenna_height_m)
    a, r = ant[0], rot[0]
    az = np.radians(args.azimuth_deg)
    d = r @ np.array([np.sin(az), np.cos(az), 0.0])
    c = hf.cell_m
    cells: list[tuple[float, int, int]] = []
    for t in np.arange(0.25, args.max_m, c / 5):
        row = int(np.floor((a[1] + t * d[1]) / c)) - hf.iy0
        col = int(np.floor((a[0] + t * d[0]) / c)) - hf.ix0
        inside = 0 <= row < hf.shape[0] and 0 <= col < hf.shape[1]
        if inside and all((row, col) != (q[1], q[2]) for q in cells):
            cells.append((float(t), row, col))

    def elevation(bound: float, t: float) -> float:
        return float(np.degrees(np.arctan2(bound - a[2], t))) if np.isfinite(bound) else 90.0

    print(f"antenna at {s} m, azimuth {args.azimuth_deg} deg: {len(cells)} cells")
    for t, row, col in cells:
        top = float(hf.bound_m[row, col])
        print(f"t {t:5.1f} m  cell ({row}, {col})  offset {hf.offset_m[row, col]:6.2f} m  "
              f"chainage {hf.chainage_m[row, col]:8.2f} m  bound {top - a[2]:7.2f} m over the "
              f"antenna -> {elevation(top, t):5.1f} deg")  # fmt: skip
    if args.to_m <= args.from_m:
        return
    cams, rots = cv._camera_geometry(keep, world.track)
    solids = rc.solid_profiles(keep, profs)
    rules = cv._thin_rules(hf, keep, cams, p)
    unseen = cv._unseen_rules(keep, p)
    alone = []
    for i in range(len(keep)):  # each frame's carving on its own
        b = np.full(hf.shape, np.inf, np.float32)
        carve_profile(hf, b, profs[i], cams[i], rots[i], p.carve_range_m, solid=solids[i],
                      thin_rule=rules[i], unseen_rule=unseen[i])  # fmt: skip
        alone.append(b)
    for t, row, col in cells:
        if not args.from_m <= t <= args.to_m:
            continue
        final = elevation(float(hf.bound_m[row, col]), t)
        print(f"cell ({row}, {col}) at {t:.1f} m: {final:.1f} deg, set by")
        for f, b in zip(keep, alone, strict=True):
            el = elevation(float(b[row, col]), t)
            if np.isfinite(b[row, col]) and el < final + 3.0:
                print(f"    frame {f.frame_id} at {f.chainage_m:.0f} m: {el:.1f} deg")


if __name__ == "__main__":
    main()
