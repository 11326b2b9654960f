"""Which frames bound the height-field cells along one ray from an antenna (false-trust tracing).

For a mask bin trusted where the truth is blocked, the question is which cells the antenna's
ray crosses, how high each is bounded, and which frame carved each one that low. This script
runs the reconstruction at one position from a processed world's cached segmentations (the
layout of ``scripts/eval_rigs.py``: ``RUN/synth/survey`` and ``RUN/proc/cache``; the survey's
side cameras passed as ``predisat process`` does) with its trace
(``Reconstructor.run(..., trace=True)``, :class:`~predisat.reconstruct.carving.
ReconstructionTrace`), and takes the height field, the antenna and the frames from it: it
marches the ray at one azimuth through the run's height field, prints every cell it crosses
(distance, offset from the track axis, chainage, bound over the antenna and the elevation it
means, seen from the sample's distance), marks the cell the run names for the azimuth's bin
and prints the bin's mask and the part that sets it; then, for the cells between two
distances, every frame whose carving alone (:meth:`~predisat.reconstruct.carving.
Reconstructor.frame_bounds`) bounds the cell within 3 deg of its final value.

The frames, track, side cameras and parameters are those of the run's chunk holding the
position, rebuilt as ``predisat process`` built them (``along_attribution.pipeline_frames``:
the vehicle's attitude, the doubts, the stops merged), so the mask at the position is the one
the process wrote (``RUN/proc/masks.parquet``, before its margins); the script says so.

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

from predisat.masks.fileformat import read_masks
from predisat.reconstruct.carving import BinPart, Reconstructor

sys.path.insert(0, str(Path(__file__).resolve().parent))
from along_attribution import pipeline_frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="world folder with synth/survey and proc/cache")
    ap.add_argument("truth", type=Path, help="truth folder with world.npz (not read: the "
                    "run's own track is used; kept for the command lines of the docs)")  # fmt: skip
    ap.add_argument("chainage_m", type=float)
    ap.add_argument("azimuth_deg", type=float, help="from north, degrees")
    ap.add_argument("--from-m", type=float, default=0.0, help="trace frames from this distance")
    ap.add_argument("--to-m", type=float, default=0.0, help="... to this one (0: no tracing)")
    ap.add_argument("--max-m", type=float, default=30.0, help="march the ray this far")
    args = ap.parse_args()
    s = args.chainage_m
    chunks = pipeline_frames(args.run, s, s)
    if not chunks:
        raise SystemExit(f"no chunk of the run holds {s} m; check the chainage")
    inp = chunks[0][1]
    frames, track, sides, p = list(inp.views), inp.track, list(inp.side_cameras), inp.params
    rc = Reconstructor(p)
    if not any(abs(f.chainage_m - s) <= p.used_m for f in frames):
        raise SystemExit(f"no frame within {p.used_m} m of {s} m; check the chainage")
    rec = rc.run(frames, [s], track, side_cameras=sides, trace=True)
    tr = rec.trace
    assert tr is not None
    hf = tr.height_field
    a, r = tr.antenna_m[0], tr.local_to_frame[0]
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

    # the mask the process run wrote there, if any: this run's frames are the chunk's own
    out = args.run / "proc" / "masks.parquet"
    if out.exists():
        written = read_masks(out, close_holes=False)
        at = np.flatnonzero(np.abs(written.chainage_m - s) < 1e-3)
        if at.size:
            dif = rec.mask_el_deg[0] - written.mask_el_deg[at[0]]
            how = (f"{np.count_nonzero(dif)} bins differ, by up to {np.abs(dif).max():.2f} deg"
                   if dif.any() else "the same")  # fmt: skip
            print(f"the process run's mask at {s} m: {how} (this run: the frames of "
                  "along_attribution.pipeline_frames)")  # fmt: skip
    # the azimuth's bin and what the run says of it
    j = int(np.round(args.azimuth_deg / p.az_step_deg)) % p.n_az
    part = BinPart(int(tr.part[0, j]))
    k = int(tr.cell[0, j])
    named = divmod(k, hf.shape[1]) if k >= 0 else None
    print(f"antenna at {s} m, azimuth {args.azimuth_deg} deg: {len(cells)} cells")
    print(f"bin {j} ({rec.az_deg[j]:.1f} deg): mask {rec.mask_el_deg[0, j]:.2f} deg, set by "
          f"{part.name.lower()}{' (unknown cell)' if tr.unknown[0, j] else ''}"
          + (f", cell {named}" if named is not None else ""))  # fmt: skip
    for t, row, col in cells:
        top = float(hf.bound_m[row, col])
        mark = "  <- the bin's cell" if named == (row, col) else ""
        print(f"t {t:5.1f} m  cell ({row}, {col})  offset {hf.offset_m[row, col]:6.2f} m  "
              f"chainage {hf.chainage_m[row, col]:8.2f} m  bound {top - a[2]:7.2f} m over the "
              f"antenna -> {elevation(top, t):5.1f} deg{mark}")  # fmt: skip
    if named is not None and all(named != (q[1], q[2]) for q in cells):
        print(f"the bin's cell {named} is off this ray (another ray of the bin, or a cell at "
              "a corner the ray crosses)")  # fmt: skip
    if args.to_m <= args.from_m:
        return
    keep = tr.frames
    alone = rc.frame_bounds(keep, track, hf, tr.profiles)  # each frame's carving alone
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
