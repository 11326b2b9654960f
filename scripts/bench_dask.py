"""Throughput of ``predisat process`` serial and on a local Dask cluster of 1 and 2 workers,
and what a national network would take.

Usage::

    python scripts/bench_dask.py SURVEY_DIR [--workers 1,2] [--chunk-m 100] [--json out.json]

Runs the whole pipeline from scratch (segmentation, reconstruction, chunk files, merge) into
fresh folders: serially in this process (the baseline) twice - cold (imports done, but the
models, the numba kernels and the caches load on first use) and warm - then on a local
cluster of each number of workers, twice: cold (fresh worker processes, the cluster's start
included) and warm (the same workers again, as on a long-lived cluster: the throughput of a
long run, where the start is paid once).
Checks that every run wrote the serial run's bytes (``SOURCE_DATE_EPOCH`` pinned), and prints
frames per second, the ratio to the serial run, the scaling efficiency
``fps(N) / (N * fps(1 worker))``, and a projection for the Belgian network (about 3 600 km)
and a 30 000 km network surveyed every 10 m by two cameras: frames, CPU-hours, wall time on N
workers (at the measured 2-worker efficiency) and storage (images at the survey's JPEG size,
segmentation cache, chunk and mask files at the measured bytes per frame and position).

One thread per worker: OpenCV, BLAS, OpenMP and numba are pinned to one thread each (before
numpy loads; the variables reach the workers), so that N workers use N cores.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "OPENCV_FOR_THREADS_NUM"):
    os.environ[_var] = "1"
os.environ["SOURCE_DATE_EPOCH"] = "1700000000"

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from predisat.reconstruct.batch import process_survey  # noqa: E402
from predisat.reconstruct.params import PipelineParams  # noqa: E402
from predisat.scheduler import Scheduler  # noqa: E402
from predisat.survey import Survey  # noqa: E402

NETWORKS_KM = {"Belgian network": 3600.0, "30 000 km network": 30000.0}
SPACING_M, CAMERAS = 10.0, 2


def published(out: Path) -> dict[str, bytes]:
    files = [out / "masks.parquet", out / "bad_frames.csv", *sorted((out / "chunks").iterdir())]
    return {str(f.relative_to(out)): f.read_bytes() for f in files if not f.name.startswith(".")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("survey", type=Path)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--chunk-m", type=float, default=100.0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    survey = Survey.load(args.survey, check_images=False, on_error="skip")
    n_frames = len(survey.frames.frame_id)
    image_bytes = sum((args.survey / str(p)).stat().st_size for p in survey.frames.image)
    params = PipelineParams(chunk_m=args.chunk_m)
    print(f"{args.survey}: {n_frames} frames, chunks of {args.chunk_m:g} m; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (shared)")  # fmt: skip
    rows: list[dict] = []
    want: dict[str, bytes] = {}
    sizes: dict[str, float] = {}

    def run(label: str, where: Scheduler | str, out: Path, extra_s: float = 0.0) -> None:
        t0 = time.perf_counter()
        res = process_survey(args.survey, out, params, scheduler=where, progress=False)
        wall = time.perf_counter() - t0
        files = published(out)
        if not want:
            want.update(files)
            sizes.update({
                "cache": sum(p.stat().st_size for p in (out / "cache").rglob("*.npz")),
                "chunks": sum(p.stat().st_size for p in (out / "chunks").iterdir()),
                "masks": (out / "masks.parquet").stat().st_size, "n_pos": res.masks.n_pos,
            })  # fmt: skip
        differing = sorted(k for k in want.keys() | files.keys() if want.get(k) != files.get(k))
        rows.append({"run": label, "wall_s": wall + extra_s, "fps": n_frames / (wall + extra_s),
                     "identical": not differing, "differing": differing,
                     "timings_s": res.timings_s, "load_avg": os.getloadavg()[0]})  # fmt: skip
        print(f"{label:22s}: {wall + extra_s:6.1f} s, {rows[-1]['fps']:6.2f} frames/s, stages "
              f"{({k: round(v, 1) for k, v in res.timings_s.items()})}, load "
              f"{rows[-1]['load_avg']:.1f}, identical to serial: {not differing}"
              f"{'' if not differing else f' (differ: {differing})'}", flush=True)  # fmt: skip

    from distributed import LocalCluster

    with tempfile.TemporaryDirectory(prefix="bench_dask_") as tmp:
        run("serial cold", Scheduler.serial(), Path(tmp) / "serial-cold")
        run("serial warm", Scheduler.serial(), Path(tmp) / "serial-warm")
        for n in (int(w) for w in args.workers.split(",")):
            t0 = time.perf_counter()
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                              host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster:
                start_s = time.perf_counter() - t0
                address = cluster.scheduler_address
                run(f"dask {n}w cold (+start)", address, Path(tmp) / f"d{n}-cold", start_s)
                run(f"dask {n}w warm", address, Path(tmp) / f"d{n}-warm")  # fmt: skip
    by = {r["run"]: r for r in rows}
    serial = by["serial warm"]
    print("\nrun                     frames/s  ratio to serial warm  scaling efficiency")
    one = by.get("dask 1w warm")
    for r in rows:
        eff = ""
        n = int(r["run"].split()[1][:-1]) if r["run"].startswith("dask") else 0
        if n and one is not None and "warm" in r["run"]:
            eff = f"{r['fps'] / (n * one['fps']):.0%}"
        print(f"{r['run']:22s}  {r['fps']:8.2f}  {r['fps'] / serial['fps']:20.2f}  {eff:>18s}")
    two = by.get("dask 2w warm")
    eff2 = two["fps"] / (2 * one["fps"]) if one and two else 1.0
    per_worker_fps = one["fps"] if one else serial["fps"]
    per_frame = {k: sizes[k] / n_frames for k in ("cache", "chunks")}
    per_pos_masks = sizes["masks"] / sizes["n_pos"]
    print(f"\nprojection: {CAMERAS} cameras every {SPACING_M:g} m, {per_worker_fps:.2f} frames/s "
          f"per worker (1 warm worker), {eff2:.0%} efficiency at 2 workers (assumed for N); "
          f"images {image_bytes / n_frames / 1e3:.0f} kB/frame, cache "
          f"{per_frame['cache'] / 1e3:.1f} kB/frame, chunks {per_frame['chunks'] / 1e3:.1f} "
          f"kB/frame, masks {per_pos_masks / 1e3:.2f} kB/position")  # fmt: skip
    projection = {}
    for name, km in NETWORKS_KM.items():
        frames = km * 1000.0 / SPACING_M * CAMERAS
        cpu_h = frames / per_worker_fps / 3600.0
        walls = {n: cpu_h / (n * eff2) for n in (2, 16, 64, 256)}
        storage_gb = {
            "images": frames * image_bytes / n_frames / 1e9,
            "cache": frames * per_frame["cache"] / 1e9,
            "chunks": frames * per_frame["chunks"] / 1e9,
            "masks": frames / CAMERAS * per_pos_masks / 1e9,
        }
        projection[name] = {"km": km, "frames": frames, "cpu_hours": cpu_h,
                            "wall_hours": walls, "storage_gb": storage_gb}  # fmt: skip
        print(f"{name} ({km:,.0f} km): {frames:,.0f} frames, {cpu_h:,.0f} CPU-hours; wall "
              + ", ".join(f"{h:,.1f} h on {n}" for n, h in walls.items())
              + "; storage " + ", ".join(f"{k} {v:,.1f} GB" for k, v in storage_gb.items()))
    if args.json:
        args.json.write_text(json.dumps({"runs": rows, "projection": projection}, indent=1))
    if not all(r["identical"] for r in rows):
        raise SystemExit("a Dask run wrote other bytes than the serial run")


if __name__ == "__main__":
    main()
