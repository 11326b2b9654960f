"""Memory of ``predisat availability`` per (position, epoch) cell, on a long synthetic line.

Builds a winding line of ``--km`` kilometres with a mask position every ``--spacing`` metres
(the scale trial's inputs: 8-38 deg masks, an ASSUMED bin every 17th azimuth), then runs, each
in its own process and one after the other:

* the baseline: a process that imports the command's modules and reads the same inputs
  (mask file, track, navigation, satellite positions of the window), and computes nothing;
* the project: ``python -m predisat availability --masks M --track T --scheduler serial``
  (three rules: masks, no mask, 15 deg cut-off; ``--counts`` with ``--counts``).

It prints both peak RSS (``wait4``), the bytes per cell the command holds above the baseline,
and that figure's ratio to the payload: one uint8 count per rule and cell (3 bytes), plus the
intervals' two float32 per rule at every ``--interval-every``-th epoch. Wall times are printed
for information only (a loaded machine changes them, not the memory).

    PYTHONPATH=. .venv/bin/python scripts/bench_availability_memory.py --km 40 --spacing 4
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_BASELINE = """
import sys
import predisat.availability.report, predisat.availability.run  # the command's imports
from predisat.availability.satellites import SatellitePositions, default_ephemeris, default_window
from predisat.masks.fileformat import read_masks
from predisat.track.map import load_track
masks = read_masks(sys.argv[1])
track = load_track(sys.argv[2])
window = default_window(float(sys.argv[3]))
sats = SatellitePositions.from_ephemeris(default_ephemeris(), window, "gps")
print(masks.n_pos, len(sats.gps_s))
"""


def build_inputs(folder: Path, km: float, spacing_m: float) -> tuple[Path, Path]:
    """A winding line at 50.5 N, 4.7 E and its masks (mask file, GeoJSON track)."""
    import json

    from predisat.masks.fileformat import write_masks
    from predisat.masks.maskset import BinSource, MaskSet
    from predisat.track.map import TrackMap

    # heading 60 +- 30 deg with a 3 km wavelength, a vertex every 10 m
    s = np.arange(0.0, km * 1000.0 + 10.0, 10.0)
    heading = np.radians(60.0 + 30.0 * np.sin(2 * np.pi * s / 3000.0))
    east = np.concatenate([[0.0], np.cumsum(np.sin(heading[1:]) * 10.0)])
    north = np.concatenate([[0.0], np.cumsum(np.cos(heading[1:]) * 10.0)])
    lat = 50.5 + north / 111_200.0
    lon = 4.7 + east / (111_200.0 * np.cos(np.radians(50.5)))
    track_path = folder / "track.geojson"
    coords = [[float(a), float(b), 150.0] for a, b in zip(lon, lat, strict=True)]
    track_path.write_text(json.dumps({"type": "FeatureCollection", "features": [{
        "type": "Feature", "properties": {"line": "bench"},
        "geometry": {"type": "LineString", "coordinates": coords},
    }]}))  # fmt: skip
    track = TrackMap.from_latlon(lat, lon, np.full(len(lat), 150.0))
    ch = np.arange(0.0, track.length_m, spacing_m)
    az = np.arange(360.0)
    mask = 8.0 + 30.0 * (0.5 + 0.5 * np.sin(np.radians(az)[None] * 3 + ch[:, None] / 500.0))
    source = np.zeros(mask.shape, np.uint8)
    source[:, ::17] = BinSource.ASSUMED
    masks = MaskSet.from_track(track, ch, mask.astype(np.float32), source=source, margin_deg=1.0)
    mask_path = write_masks(masks, folder / "bench.masks.parquet")
    return mask_path, track_path


def peak_rss(cmd: list[str]) -> tuple[float, float, str]:
    """Peak RSS (MB) and wall time (s) of a command, with its last line of output."""
    t = time.perf_counter()
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        out = log.read().decode(errors="replace").strip().splitlines()
    if proc.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n" + "\n".join(out[-20:]))
    return usage.ru_maxrss / 1024.0, time.perf_counter() - t, out[-1] if out else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--km", type=float, default=10.0, help="line length, km (default 10)")
    ap.add_argument("--spacing", type=float, default=4.0, help="mask spacing, m (default 4)")
    ap.add_argument("--step", type=int, default=30, help="epoch step, s (default 30)")
    ap.add_argument("--interval-every", type=int, default=10, help="as the command (10)")
    ap.add_argument("--counts", action="store_true", help="also write counts.parquet")
    ap.add_argument("--work", type=Path, help="keep the inputs and outputs here")
    args = ap.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_av_mem_"))
    work.mkdir(parents=True, exist_ok=True)
    masks, track = build_inputs(work, args.km, args.spacing)
    py = sys.executable
    base_mb, base_s, dims = peak_rss(
        [py, "-c", _BASELINE, str(masks), str(track), str(args.step)]
    )
    n_pos, n_ep = (int(x) for x in dims.split())
    cmd = [py, "-m", "predisat", "availability", "--masks", str(masks), "--track", str(track),
           "--out", str(work / "out"), "--scheduler", "serial", "--step", str(args.step),
           "--interval-every", str(args.interval_every), "--quiet"]  # fmt: skip
    if args.counts:
        cmd.append("--counts")
    run_mb, run_s, _ = peak_rss(cmd)
    cells = n_pos * n_ep
    per_cell = (run_mb - base_mb) * 1024 * 1024 / cells
    payload = 3 * (1 + 8 / args.interval_every)
    print(f"line {args.km:g} km, a position every {args.spacing:g} m: {n_pos} positions x "
          f"{n_ep} epochs = {cells / 1e6:.1f} M cells")  # fmt: skip
    print(f"baseline (read the inputs): {base_mb:8.0f} MB  {base_s:6.1f} s")
    print(f"predisat availability:      {run_mb:8.0f} MB  {run_s:6.1f} s"
          f"{'  (--counts)' if args.counts else ''}")  # fmt: skip
    print(f"above the baseline: {per_cell:.1f} B per cell; payload {payload:.1f} B per cell "
          f"(ratio {per_cell / payload:.2f})")  # fmt: skip


if __name__ == "__main__":
    main()
