"""Throughput of ``predisat process`` against the floor of merely decoding the JPEG frames.

Usage::

    python scripts/bench_pipeline.py SURVEY_DIR [--workers 1] [--chunk-m 1000] [--segmenter M]
        [--json out.json]

Decodes every frame of the survey once (``cv2.imread``, the floor), then runs the whole
pipeline (segmentation, reconstruction, chunk files, merge) from scratch in a temporary folder,
and prints frames per second per core for both, the time per frame of each stage and the ratio
pipeline / decode (issue 3 target: within 3x).

Per core means one thread: OpenCV, BLAS and OpenMP are pinned to one thread each (before numpy
loads), so that the figure does not borrow the second core of the machine.
"""

from __future__ import annotations

import os

# OPENCV_FOR_THREADS_NUM reaches the spawned workers of --workers N, where the parent's
# cv2.setNumThreads does not
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "OPENCV_FOR_THREADS_NUM"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402

from predisat.reconstruct.batch import process_survey  # noqa: E402
from predisat.reconstruct.params import DEFAULT_SEGMENTER, PipelineParams  # noqa: E402
from predisat.survey import Survey  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("survey", type=Path)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--chunk-m", type=float, default=1000.0)
    ap.add_argument("--segmenter", default=DEFAULT_SEGMENTER,
                    help=f"segmentation method (default {DEFAULT_SEGMENTER})")
    ap.add_argument("--json", type=Path, default=Path("bench_pipeline.json"))
    args = ap.parse_args()
    cv2.setNumThreads(1)

    survey = Survey.load(args.survey, check_images=False, on_error="skip")
    n = len(survey.frames)
    t0 = time.perf_counter()
    for i in range(n):
        if cv2.imread(str(survey.image_path(i)), cv2.IMREAD_COLOR) is None:
            raise SystemExit(f"frame {survey.frames.frame_id[i]} cannot be decoded")
    decode_s = time.perf_counter() - t0

    with tempfile.TemporaryDirectory() as tmp:
        res = process_survey(
            args.survey, Path(tmp) / "out",
            PipelineParams(chunk_m=args.chunk_m, segmenter=args.segmenter),
            workers=args.workers, progress=False,
        )  # fmt: skip
    cores = args.workers
    out = {
        "survey": str(args.survey),
        "frames": n,
        "positions": res.masks.n_pos,
        "image_px": [int(c.camera.width_px * c.camera.height_px) for c in survey.cameras.values()],
        "workers": cores,
        "segmenter": args.segmenter,
        "decode_s": decode_s,
        "pipeline_s": res.elapsed_s,
        "stage_s": res.timings_s,
        "decode_fps_per_core": n / decode_s,
        "pipeline_fps_per_core": n / res.elapsed_s / cores,
        "ratio_pipeline_to_decode": res.elapsed_s * cores / decode_s,
    }
    print(f"{n} frames, {res.masks.n_pos} positions, {cores} worker(s)")
    print(f"decode only : {out['decode_fps_per_core']:8.1f} frames/s/core ({decode_s:.2f} s)")
    fps = out["pipeline_fps_per_core"]
    print(f"pipeline    : {fps:8.1f} frames/s/core ({res.elapsed_s:.2f} s)")
    for stage, s in res.timings_s.items():
        print(f"  {stage:<12s}{1000 * s / n:8.1f} ms/frame")
    print(f"ratio pipeline / decode: {out['ratio_pipeline_to_decode']:.1f}x (target <= 3x)")
    args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
