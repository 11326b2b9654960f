"""Throughput of ``predisat process`` on local folders against fsspec URLs.

Usage::

    python scripts/bench_storage.py [--work DIR] [--rounds 3] [--segmenter blue|ensemble]

Makes (once, in ``--work``) a small synthetic survey (200 m of line 144, 42 frames of
320 x 240), then runs the whole pipeline from scratch, serially in this process, with:

* ``local``: the survey and the output folder on the local disk (the baseline);
* ``memory``: the survey on the local disk, the outputs in ``memory://`` (every write of the
  cache, chunks and merge through fsspec: a temporary name, then a move);
* ``http``: the survey served over HTTP by a ``http.server`` thread on 127.0.0.1 (every
  read of survey.yaml, the manifest, the calibrations, the track and the frames through
  fsspec's HTTPFileSystem and aiohttp), the outputs in ``memory://``.

Each configuration runs ``--rounds`` times (alternating, after one warm-up run of the local
one, so that the models and kernels are loaded for all); the best wall time of each gives
frames per second and the ratio to the local run. Every run's masks are checked against the
local run's (the data columns bit for bit). ``--segmenter blue`` (default) is a cheap colour
threshold, so that the storage's share of the time shows (the worst case for the URLs);
``ensemble`` is the default segmentation of ``predisat process``.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import io
import os
import shutil
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import fsspec
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.params import PipelineParams


def blue_sky(image: np.ndarray) -> tuple[np.ndarray, None]:
    """A cheap segmenter: blue or bright pixels are sky."""
    b, g, r = (image[..., k].astype(int) for k in range(3))
    return (b > r + 10) | ((b + g + r) > 600), None


def make_survey(work: Path) -> Path:
    """A small synthetic survey (200 m of line 144, 320x240 pinhole cameras)."""
    from predisat.camera.models import CameraModel
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    out = work / "synth"
    if not (out / "survey" / "manifest.csv").is_file():
        generate_survey(
            demo_track(), 3000.0, 3200.0, sky="mixed", seed=5, out_dir=out,
            camera=CameraModel.pinhole_from_fov(320, 240, 74.0), progress=False,
        )  # fmt: skip
    return out / "survey"


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: Any) -> None:
        pass


def _columns(data: bytes) -> bytes:
    """The mask file's columns as Arrow IPC bytes (no metadata: it names the survey)."""
    table = pq.read_table(io.BytesIO(data)).replace_schema_metadata(None)
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as writer:
        writer.write_table(table)
    return sink.getvalue().to_pybytes()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "bench_storage")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--segmenter", choices=("blue", "ensemble"), default="blue")
    args = ap.parse_args()
    os.environ["SOURCE_DATE_EPOCH"] = "1700000000"
    survey = make_survey(args.work)
    n_frames = sum(1 for _ in open(survey / "manifest.csv")) - 1
    params = PipelineParams(chunk_m=50.0, segmenter=args.segmenter)
    seg = blue_sky if args.segmenter == "blue" else None
    memory = fsspec.filesystem("memory")

    handler = functools.partial(_Quiet, directory=str(survey))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}"

    def run(kind: str, k: int) -> tuple[float, bytes]:
        local_out = args.work / f"out-{kind}-{k}"
        shutil.rmtree(local_out, ignore_errors=True)
        src: Any = url if kind == "http" else survey
        out: Any = local_out if kind == "local" else f"memory://bench/{kind}-{k}"
        t0 = time.perf_counter()
        res = process_survey(src, out, params, progress=False, segmenter=seg,
                             scheduler="serial")  # fmt: skip
        took = time.perf_counter() - t0
        assert res.frames_segmented == n_frames, res
        if kind == "local":
            data = (local_out / "masks.parquet").read_bytes()
            shutil.rmtree(local_out)
        else:
            data = memory.cat_file(f"/bench/{kind}-{k}/masks.parquet")
            memory.rm(f"/bench/{kind}-{k}", recursive=True)
        return took, _columns(data)

    run("local", -1)  # warm-up: models, kernels
    kinds = ("local", "memory", "http")
    times: dict[str, list[float]] = {k: [] for k in kinds}
    want = None
    for r in range(args.rounds):
        for kind in kinds:
            took, cols = run(kind, r)
            want = cols if want is None else want
            assert cols == want, f"{kind}: the masks differ from the local run's"
            times[kind].append(took)
    server.shutdown()
    load = os.getloadavg()
    print(f"survey {survey}: {n_frames} frames, segmenter {args.segmenter}, "
          f"best of {args.rounds}; load average {load[0]:.1f}")  # fmt: skip
    base = min(times["local"])
    print(f"{'run':<8s} {'best s':>7s} {'all s':>22s} {'frames/s':>9s} {'ratio':>6s}")
    for kind in kinds:
        best = min(times[kind])
        every = ", ".join(f"{t:.2f}" for t in times[kind])
        print(f"{kind:<8s} {best:7.2f} {every:>22s} {n_frames / best:9.1f} "
              f"{base / best:6.2f}")  # fmt: skip
    print("every run's masks: the local run's columns, bit for bit")


if __name__ == "__main__":
    main()
