"""The sky network's forward pass against the floor of decoding the frames (issue 3's 3x target).

Usage::

    python scripts/bench_network.py SURVEY_DIR [--frames 60] [--repeat 5] [--int8]
        [--json bench_network.json]

Times, per frame and on one thread, interleaved and best of ``--repeat`` (the least disturbed
run on a shared machine):

* ``decode``: ``cv2.imread`` of the frame (the floor);
* ``input``: the network's input blob (``predisat.sky.network.network_input``);
* ``cv2.dnn forward, 1 pass``: the shipped network's forward pass on that blob;
* ``SkyNet, 1 pass``: ``SkyNet.probability_tile`` with ``mirror=False`` (input, forward,
  sigmoid);
* ``SkyNet, frame + mirror``: the shipped ``SkyNet.default()`` (a batch of two);

and, when ONNX Runtime is installed (it is not a PREDISAT dependency), the same forward pass in
ONNX Runtime at float32 and, with ``--int8``, after static int8 quantization (QDQ, per-channel
weights, calibrated on the frames not timed), with the share of pixels whose sky decision
differs from float32. Each row is printed as milliseconds and as a multiple of the decode.

The point: the 3x target leaves ~2 decodes for segmentation and reconstruction together, and
one forward pass of the network alone takes many more (``docs/pipeline.md``, Throughput).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "OPENCV_FOR_THREADS_NUM"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from predisat.sky.network import SkyNet, network_input  # noqa: E402
from predisat.survey import Survey  # noqa: E402


def _read(path: str) -> np.ndarray:
    image = cv2.imread(path, cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"{path} cannot be decoded; `predisat process` reports and skips such "
                         "frames, this benchmark needs every frame it times")
    return np.asarray(image)


def _forward(net: Any, blob: np.ndarray) -> Any:
    net.setInput(blob)
    return net.forward()


def _best_ms(fns: dict[str, Callable[[int], Any]], n: int, repeat: int) -> dict[str, float]:
    """Best-of-``repeat`` time per item of each function, the functions interleaved."""
    best = dict.fromkeys(fns, np.inf)
    names = list(fns)
    for r in range(repeat):
        for name in names if r % 2 == 0 else names[::-1]:
            t0 = time.perf_counter()
            for i in range(n):
                fns[name](i)
            best[name] = min(best[name], (time.perf_counter() - t0) / n * 1e3)
    return best


def _onnxruntime_rows(
    net: SkyNet, blobs: list[np.ndarray], calib: list[np.ndarray], int8: bool, repeat: int
) -> tuple[dict[str, Callable[[int], Any]], dict[str, float]]:
    try:
        import onnxruntime as ort
    except ImportError:
        print("onnxruntime not installed: its rows are skipped (pip install onnxruntime onnx)")
        return {}, {}
    so = ort.SessionOptions()
    so.intra_op_num_threads = so.inter_op_num_threads = 1
    f32 = ort.InferenceSession(str(net.path), so)
    name = f32.get_inputs()[0].name
    fns: dict[str, Callable[[int], Any]] = {
        "onnxruntime float32, 1 pass": lambda i: f32.run(None, {name: blobs[i]})
    }
    agreement: dict[str, float] = {}
    if int8:
        try:
            from onnxruntime.quantization import (
                CalibrationDataReader,
                QuantFormat,
                QuantType,
                quantize_static,
            )
        except ImportError as exc:
            raise SystemExit(f"--int8 needs ONNX Runtime's quantization tools ({exc}): "
                             "pip install onnx") from None

        class _Reader(CalibrationDataReader):
            def __init__(self) -> None:
                self._it = iter([{name: b} for b in calib])

            def get_next(self) -> dict[str, np.ndarray] | None:
                return next(self._it, None)

        tmp = Path(tempfile.mkdtemp(prefix="bench_network_"))
        q_path = tmp / "sky_unet_int8.onnx"
        quantize_static(str(net.path), str(q_path), _Reader(), quant_format=QuantFormat.QDQ,
                        per_channel=True, activation_type=QuantType.QUInt8,
                        weight_type=QuantType.QInt8)
        q8 = ort.InferenceSession(str(q_path), so)
        fns["onnxruntime int8, 1 pass"] = lambda i: q8.run(None, {name: blobs[i]})
        flips = [
            float(np.mean((f32.run(None, {name: b})[0] > 0) != (q8.run(None, {name: b})[0] > 0)))
            for b in blobs
        ]
        agreement["int8_decision_differs_share"] = float(np.mean(flips))
    return fns, agreement


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("survey", type=Path)
    ap.add_argument("--frames", type=int, default=60, help="frames timed (default 60)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--int8", action="store_true",
                    help="also time an int8 quantization in ONNX Runtime")
    ap.add_argument("--json", type=Path, default=Path("bench_network.json"))
    args = ap.parse_args()
    if args.frames < 1 or args.repeat < 1:
        raise SystemExit("--frames and --repeat must be at least 1")
    cv2.setNumThreads(1)

    survey = Survey.load(args.survey, check_images=False, on_error="skip")
    n_all = len(survey.frames)
    # timed frames spread over the survey; calibration frames (int8) are the others
    timed = np.unique(np.linspace(0, n_all - 1, min(args.frames, n_all)).round().astype(int))
    paths = [str(survey.image_path(int(i))) for i in timed]
    calib_idx = np.setdiff1d(np.arange(n_all), timed)[:: max(1, (n_all - timed.size) // 30)][:30]
    images = [_read(p) for p in paths]

    shipped = SkyNet.default()
    single = dataclasses.replace(shipped, mirror=False)
    s = shipped.input_px
    blobs = [network_input(im, s) for im in images]
    calib = [network_input(_read(str(survey.image_path(int(i)))), s) for i in calib_idx]
    n = len(images)
    dnn = cv2.dnn.readNetFromONNX(str(shipped.path))
    fns: dict[str, Callable[[int], Any]] = {
        "decode": lambda i: cv2.imread(paths[i], cv2.IMREAD_COLOR),
        "input": lambda i: network_input(images[i], s),
        "cv2.dnn forward, 1 pass": lambda i: _forward(dnn, blobs[i]),
        "SkyNet, 1 pass (input + forward)": lambda i: single.probability_tile(images[i]),
        "SkyNet, frame + mirror (shipped)": lambda i: shipped.probability_tile(images[i]),
    }
    ort_fns, agreement = _onnxruntime_rows(shipped, blobs, calib, args.int8, args.repeat)
    fns.update(ort_fns)
    ms = _best_ms(fns, n, args.repeat)

    h, w = images[0].shape[:2]
    print(f"{n} frames of {w}x{h}, network input {s}x{s}, one thread, best of {args.repeat}")
    print(f"{'stage':36s} {'ms/frame':>9s} {'x decode':>9s}")
    for name, v in ms.items():
        print(f"{name:36s} {v:9.2f} {v / ms['decode']:9.1f}")
    for k, v in agreement.items():
        print(f"{k}: {v:.5f}")
    print(f"issue 3 target: the whole pipeline within 3 x decode = {3 * ms['decode']:.2f} ms/frame")
    args.json.write_text(json.dumps({
        "survey": str(args.survey), "frames": n, "width_px": w, "height_px": h,
        "input_px": s, "repeat": args.repeat, "ms_per_frame": ms,
        "ratio_to_decode": {k: v / ms["decode"] for k, v in ms.items()}, **agreement,
    }, indent=1) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
