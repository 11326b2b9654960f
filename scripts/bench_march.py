"""Benchmark: the horizon ray march (``predisat.reconstruct.carving._march_rays``) against its
baseline.

Usage::

    python scripts/bench_march.py SURVEY PROCESSED [--from-m 4000] [--to-m 5000] [--repeat 7]
        [--json bench_march.json]

``PROCESSED`` is a ``predisat process SURVEY --out PROCESSED`` folder: its segmentation cache
(``cache/seg-*/``) gives the sky masks, so no frame is segmented here. The positions of the
survey within ``[from_m, to_m)`` are reconstructed once (one window, as one pipeline chunk)
while the inputs of every ``_march_rays`` call are recorded: the real height field, antennas
and caps. Both kernels then march the same inputs, ``--repeat`` times, interleaved (the
machine is shared: the best time of each counts), and must agree bit for bit on every ray.

Baseline: the kernel as it was until 2026-12-02 (commit 3645ffc), kept verbatim as the
reference of the tests (``tests/regression/reference_march.py``).
One thread: BLAS, OpenMP and numba are pinned before numpy loads.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests' reference kernel

import predisat.reconstruct.carving as rc  # noqa: E402
from predisat.reconstruct.carving import FrameView, ReconstructionParams, Reconstructor  # noqa: E402
from predisat.reconstruct.framecache import decode_cache  # noqa: E402
from predisat.survey import Survey  # noqa: E402
from tests.regression.reference_march import reference_march  # noqa: E402


# ---------------------------------------------------------------------- inputs
def _cache_dir(processed: Path, frame_ids: list[str]) -> Path:
    """The newest segmentation cache of ``processed`` holding every frame."""
    dirs = sorted((processed / "cache").glob("seg-*"), key=lambda p: p.stat().st_mtime)
    for d in reversed(dirs):
        if all((d / f"{fid}.npz").is_file() for fid in frame_ids):
            return d
    raise SystemExit(f"{processed}/cache holds no segmentation of all frames: run predisat process")


def record_inputs(
    survey_dir: Path, processed: Path, lo_m: float, hi_m: float
) -> list[tuple[Any, ...]]:
    """Arguments of every ``_march_rays`` call of one window over ``[lo_m, hi_m)``."""
    sv = Survey.load(survey_dir, check_images=False, on_error="skip")
    if sv.track is None:
        raise SystemExit(f"survey {survey_dir} names no track file")
    p = ReconstructionParams()
    fr = sv.frames
    ch = np.round(np.asarray(fr.chainage_m, float), 3)
    pos = np.unique(ch[np.isfinite(ch) & (ch >= lo_m) & (ch < hi_m)])
    if not pos.size:
        raise SystemExit(f"no position of {survey_dir} in [{lo_m}, {hi_m}) m")
    idx = np.flatnonzero((ch >= pos.min() - p.overlap_m) & (ch <= pos.max() + p.overlap_m))
    cache = _cache_dir(processed, [str(fr.frame_id[i]) for i in idx])
    s = ch[idx]
    track: Any = sv.track
    ant = np.asarray(track.enu_at(s), float)
    ant += float(sv.antenna_height_m) * np.asarray(track.up_at(s), float)
    heading = np.asarray(track.heading_at(s), float)
    views = []
    for k, i in enumerate(idx):
        fid = str(fr.frame_id[i])
        with np.load(cache / f"{fid}.npz", allow_pickle=False) as z:
            seg = decode_cache(z, json.loads(str(z["meta"])), fid)
        if isinstance(seg, tuple):
            cam = sv.cameras[str(fr.side[i])]
            views.append(
                FrameView(float(ch[i]), seg[0], cam.camera, cam.mount, ant[k],
                          float(heading[k]), bool(sv.reverse), seg[1], fid)
            )  # fmt: skip
    calls: list[tuple[Any, ...]] = []
    kernel: Any = rc._march_rays

    def recorder(*args: Any) -> tuple[Any, ...]:
        calls.append(args)
        return kernel(*args)

    # _horizon_parts looks the kernel up at call time
    rc._march_rays = recorder  # type: ignore[assignment]
    try:
        Reconstructor(p).run(views, pos, track)
    finally:
        rc._march_rays = kernel
    return calls


# ---------------------------------------------------------------------- timing
def _run(fn: Callable[..., tuple[Any, Any]], calls: list[tuple[Any, ...]]) -> tuple[float, list]:
    t0 = time.perf_counter()
    out = [fn(*a) for a in calls]
    return time.perf_counter() - t0, out


def _identical(a: list, b: list) -> bool:
    """Bit-for-bit equality of every ray's near and far values (NaN payloads included)."""
    return all(
        np.array_equal(x.view(np.int32), y.view(np.int32))
        for pa, pb in zip(a, b, strict=True)
        for x, y in zip(pa, pb, strict=True)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("survey", type=Path)
    ap.add_argument("processed", type=Path, help="predisat process output (segmentation cache)")
    ap.add_argument("--from-m", type=float, default=4000.0, help="first position chainage (m)")
    ap.add_argument("--to-m", type=float, default=5000.0, help="positions below this (m)")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()

    t0 = time.perf_counter()
    calls = record_inputs(args.survey, args.processed, args.from_m, args.to_m)
    n_pos, n_rays = len(calls), int(calls[0][0].shape[0])
    ny, nx = int(calls[0][5]), int(calls[0][4])
    print(f"{n_pos} positions x {n_rays} rays, height field {ny} x {nx} cells "
          f"(inputs recorded in {time.perf_counter() - t0:.1f} s)")  # fmt: skip
    # the current kernel also returns the support of each ray (its last argument is the
    # views raster the reference does not take): only the values are compared and timed alike
    def baseline(*a: Any) -> tuple[Any, Any]:
        return reference_march(*a[:-1])

    def current(*a: Any) -> tuple[Any, ...]:
        return rc._march_rays(*a)[:2]

    kernels: dict[str, Callable[..., Any]] = {"baseline": baseline, "current": current}
    for fn in kernels.values():
        fn(*calls[0])  # compile or load from the numba cache
    best = dict.fromkeys(kernels, np.inf)
    outs: dict[str, list] = {}
    for _ in range(args.repeat):
        for name, fn in kernels.items():
            dt, outs[name] = _run(fn, calls)
            best[name] = min(best[name], dt)
    same = _identical(outs["baseline"], outs["current"])
    speedup = best["baseline"] / best["current"]
    for name, dt in best.items():
        print(f"{name:<9s}: {1e3 * dt / n_pos:7.2f} ms/position "
              f"({n_pos * n_rays / dt / 1e6:.2f} M rays/s), best of {args.repeat}")  # fmt: skip
    print(f"speed-up: {speedup:.2f}x; bit-identical on every ray: {'yes' if same else 'NO'}")
    if args.json is not None:
        args.json.write_text(json.dumps({
            "survey": str(args.survey), "from_m": args.from_m, "to_m": args.to_m,
            "positions": n_pos, "rays_per_position": n_rays, "grid_cells": [ny, nx],
            "repeat": args.repeat,
            "ms_per_position": {k: 1e3 * v / n_pos for k, v in best.items()},
            "speedup": speedup, "bit_identical": same,
        }, indent=1))  # fmt: skip
    if not same:
        raise SystemExit("the current kernel differs from the baseline")


if __name__ == "__main__":
    main()
