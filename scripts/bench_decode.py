"""Cost of reading a frame through the project's decoder against OpenCV's decode alone.

Usage::

    python scripts/bench_decode.py FOLDER [FOLDER ...] [--repeat 3]

``predisat.survey.images.decode_frame`` decodes the stored pixels (EXIF orientation not
applied), reads the EXIF header with PIL to refuse a tagged frame, and scales 16-bit files;
the baseline is ``cv2.imdecode(..., IMREAD_COLOR)`` of the same bytes. Both run on every
JPEG/PNG of the folders, interleaved, and the ratio of the medians is printed.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from predisat.survey.images import decode_frame


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    files = sorted(p for f in args.folders for p in f.rglob("*")
                   if p.suffix.lower() in (".jpg", ".jpeg", ".png"))  # fmt: skip
    if not files:
        raise SystemExit("no JPEG or PNG file in the folders")
    blobs = [p.read_bytes() for p in files]
    ours, base = [], []
    for _ in range(args.repeat):
        for data in blobs:
            t = time.perf_counter()
            cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
            base.append(time.perf_counter() - t)
            t = time.perf_counter()
            decode_frame(data, "bench")
            ours.append(time.perf_counter() - t)
    mb, mo = statistics.median(base), statistics.median(ours)
    print(f"{len(files)} files x {args.repeat}: OpenCV decode {1000 * mb:.2f} ms, "
          f"decode_frame {1000 * mo:.2f} ms (median per frame); ratio {mo / mb:.3f}")


if __name__ == "__main__":
    main()
