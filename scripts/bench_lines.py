"""``predisat network`` on a small network: serial against a local Dask cluster of 1 and 2
workers, the output layout and its storage per km.

Usage::

    python scripts/bench_lines.py [--network tests/data/track/network_gembloux.geojson]
        [--from-m 300] [--span-m 300] [--camera fisheye] [--workers 1,2] [--chunk-m 100]
        [--belgium ../shared/data/railway/infrabel/belgium_geovoies_simpl10m.geojson]
        [--synth DIR] [--keep DIR] [--json out.json]

Renders a synthetic survey of ``--span-m`` metres on every line of the network (not timed),
then runs :func:`predisat.reconstruct.network.process_network` from scratch into fresh folders:
serially in this process (the baseline), then with ``scheduler="local"`` and 1 and 2 workers
(the cluster's start included, as a user's run pays it). Checks that every run wrote the serial
run's partition files byte for byte (``SOURCE_DATE_EPOCH`` pinned) and prints wall time,
frames per second and the ratio to serial. Then one availability report per line
(:func:`predisat.availability.network.network_availability`, serial, the embedded day at
30 s) and the summary, timed; the size of every part of the output folder per km of surveyed
line and per position, projected to the Belgian network (3 600 km); with ``--belgium``, the
time to read Infrabel's whole network into track maps.

One thread per worker (OpenCV, BLAS, OpenMP, numba pinned before numpy loads).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "OPENCV_FOR_THREADS_NUM"):
    os.environ[_var] = "1"
os.environ["SOURCE_DATE_EPOCH"] = "1700000000"

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import pandas as pd  # noqa: E402

from predisat.availability.network import (  # noqa: E402
    LineInput,
    network_availability,
    write_network_summary,
)
from predisat.camera.models import default_camera  # noqa: E402
from predisat.reconstruct.network import NetworkResult, process_network  # noqa: E402
from predisat.reconstruct.params import PipelineParams  # noqa: E402
from predisat.track.network import Network  # noqa: E402

BELGIUM_KM = 3600.0


def _size(paths: Any) -> int:
    return sum(p.stat().st_size for p in paths if p.is_file())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    repo = Path(__file__).resolve().parents[1]
    ap.add_argument("--network", type=Path,
                    default=repo / "tests/data/track/network_gembloux.geojson")
    ap.add_argument("--from-m", type=float, default=300.0)
    ap.add_argument("--span-m", type=float, default=300.0)
    ap.add_argument("--camera", choices=("pinhole", "fisheye"), default="fisheye")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--chunk-m", type=float, default=100.0)
    ap.add_argument("--belgium", type=Path)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--synth", type=Path, help="render the surveys here, or reuse them")
    ap.add_argument("--keep", type=Path, help="copy the serial run's summary (map, tables) here")
    args = ap.parse_args()
    from predisat.synth.generate import generate_survey

    net = Network.from_file(args.network)
    report: dict[str, Any] = {"network": str(args.network), "lines": list(net.line_ids),
                              "span_m": args.span_m, "runs": []}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="bench_lines_") as tmp:
        root = Path(tmp)
        synth = args.synth or root / "synth"
        t0 = time.perf_counter()
        for k, ln in enumerate(net.lines):
            survey_dir = synth / ln.key / "survey"
            if not (survey_dir / "survey.yaml").is_file():
                generate_survey(ln.parts[0], args.from_m, args.from_m + args.span_m, sky="mixed",
                                seed=7 + k, out_dir=synth / ln.key,
                                camera=default_camera(args.camera), progress=False)  # fmt: skip
            (root / "surveys").mkdir(exist_ok=True)
            (root / "surveys" / ln.part_key(1)).symlink_to(survey_dir.resolve())
        print(f"{len(net.lines)} surveys of {args.span_m:g} m rendered (or found) in "
              f"{time.perf_counter() - t0:.0f} s (not timed below)", flush=True)  # fmt: skip
        params = PipelineParams(chunk_m=args.chunk_m)
        want: dict[str, bytes] = {}
        serial: NetworkResult | None = None
        runs = [("serial", "serial", None)] + [
            (f"dask {n}w (+start)", "local", int(n)) for n in args.workers.split(",")
        ]
        for label, where, workers in runs:
            out = root / (label.split()[0] + str(workers or ""))
            t1 = time.perf_counter()
            res = process_network(net, root / "surveys", out, params, scheduler=where,
                                  workers=workers, progress=False)  # fmt: skip
            wall = time.perf_counter() - t1
            files = {str(r.masks_path.relative_to(out)): r.masks_path.read_bytes()
                     for r in res.lines if r.masks_path is not None}  # fmt: skip
            if not want:
                want, serial = files, res
            frames = sum(r.n_frames for r in res.lines)
            differing = sorted(k for k in want.keys() | files.keys()
                               if want.get(k) != files.get(k))  # fmt: skip
            row = {"run": label, "wall_s": wall, "frames": frames, "fps": frames / wall,
                   "identical": not differing, "differing": differing,
                   "load_avg": os.getloadavg()[0]}  # fmt: skip
            report["runs"].append(row)
            print(f"{label:18s}: {wall:6.1f} s, {frames} frames, {row['fps']:.2f} frames/s, "
                  f"identical to serial: {row['identical']} {differing or ''}, load "
                  f"{row['load_avg']:.1f}",
                  flush=True)  # fmt: skip
        assert serial is not None
        base = report["runs"][0]["fps"]
        for r in report["runs"]:
            print(f"  {r['run']:18s} ratio to serial {r['fps'] / base:.2f}")
        out = serial.out_dir
        by_key = {(ln.line_id, 1): ln.parts[0] for ln in net.lines}
        inputs = [LineInput(r.line_id, r.part, r.key, str(r.masks_path),
                            by_key[(r.line_id, r.part)])
                  for r in serial.lines if r.masks_path is not None]  # fmt: skip
        t2 = time.perf_counter()
        reps = network_availability(inputs, out / "availability", scheduler="serial",
                                    progress=False)  # fmt: skip
        table = pd.DataFrame([{"line_id": r.line_id, "part": r.part, "key": r.key,
                               "status": r.status, "length_m": r.length_m,
                               "from_m": r.from_m, "to_m": r.to_m, "n_pos": r.n_pos,
                               "n_frames": r.n_frames, "n_bad_frames": r.n_bad_frames,
                               "message": r.message} for r in serial.lines])  # fmt: skip
        write_network_summary(net, table, reps, out)
        avail_s = time.perf_counter() - t2
        if args.keep is not None:
            args.keep.mkdir(parents=True, exist_ok=True)
            for f in [*out.glob("summary.*"), out / "network_map.png"]:
                shutil.copy2(f, args.keep / f.name)
        print(f"availability, {len(reps)} reports + summary (serial, 24 h at 30 s): "
              f"{avail_s:.1f} s", flush=True)  # fmt: skip
        km = len(inputs) * args.span_m / 1000.0
        n_pos = sum(r.n_pos for r in serial.lines)
        images = _size(p for d in (root / "surveys").iterdir()
                       for p in d.resolve().rglob("*.jpg"))  # fmt: skip
        sizes = {
            "survey images": images,
            "masks/ (the dataset)": _size((out / "masks").rglob("*.parquet")),
            "lines/*/cache": _size((out / "lines").rglob("cache/**/*")),
            "lines/*/chunks": _size((out / "lines").rglob("chunks/*")),
            "lines/*/masks.parquet": _size((out / "lines").glob("*/masks.parquet")),
            "availability/": _size((out / "availability").rglob("*")),
            "summary": _size(out.glob("summary.*")) + _size(out.glob("*.png")),
        }
        report.update(availability_s=avail_s, km=km, n_pos=n_pos, sizes=sizes)
        print(f"\nstorage, {km:g} km surveyed, {n_pos} positions: per km / per position / "
              f"projected to {BELGIUM_KM:.0f} km")  # fmt: skip
        for name, b in sizes.items():
            print(f"  {name:24s} {b / km / 1e3:9.1f} kB/km {b / n_pos / 1e3:7.2f} kB/pos "
                  f"{b / km * BELGIUM_KM / 1e9:7.2f} GB")  # fmt: skip
    if args.belgium is not None:
        t3 = time.perf_counter()
        whole = Network.from_file(args.belgium, tolerance_m=10.0, on_bad_line="skip")
        read_s = time.perf_counter() - t3
        refused = [s for s in whole.skipped if s.what.startswith("line ")]
        print(f"\n{args.belgium.name}: {len(whole.lines)} lines, "
              f"{sum(len(ln.parts) for ln in whole.lines)} parts, {whole.length_m / 1e3:.0f} km "
              f"read into track maps in {read_s:.1f} s; {len(refused)} lines refused")  # fmt: skip
        report["belgium"] = {"lines": len(whole.lines), "km": whole.length_m / 1e3,
                             "read_s": read_s, "refused": [s.reason for s in refused]}  # fmt: skip
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1, default=str))


if __name__ == "__main__":
    main()
