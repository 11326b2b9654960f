"""A survey whose camera had another lens of the same image size over a stretch (a trial of the
lens check, docs/reconstruction.md section 19).

Copies a survey folder (images hard-linked, so the source is never touched) and replaces one
camera's images over a chainage range by the same images zoomed ``--scale`` times about their
centre (an affine zoom, JPEG quality 90, EXIF dropped): what a lens ``--scale`` times longer,
put on the camera without a new calibration, would have taken of the same scene to first
order. Then run ``predisat process`` and ``predisat evaluate`` on the copy::

    PYTHONPATH=. .venv/bin/python -m predisat synth --from-km 4.0 --to-km 4.4 --seed 3 \\
        --out /tmp/lens/synth -q
    PYTHONPATH=. .venv/bin/python scripts/lens_swap.py /tmp/lens/synth/survey \\
        /tmp/lens/zoom125 --scale 1.25 --side left --from-m 4100 --to-m 4250
    PYTHONPATH=. .venv/bin/python -m predisat process /tmp/lens/zoom125 --out /tmp/lens/o125 \\
        --scheduler serial -q
    PYTHONPATH=. .venv/bin/python -m predisat evaluate /tmp/lens/o125 --truth /tmp/lens/synth
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
import pandas as pd


def zoomed(image_bgr: np.ndarray, scale: float) -> np.ndarray:
    """``image_bgr`` zoomed ``scale`` times about its centre, same size (bilinear)."""
    h, w = image_bgr.shape[:2]
    m = np.array([[scale, 0.0, (1.0 - scale) * (w - 1) / 2.0],
                  [0.0, scale, (1.0 - scale) * (h - 1) / 2.0]], np.float32)  # fmt: skip
    return np.asarray(cv2.warpAffine(image_bgr, m, (w, h), flags=cv2.INTER_LINEAR))


def swap_lens(src: Path, dst: Path, scale: float, side: str, lo_m: float, hi_m: float) -> int:
    """Write the copy; return the number of images replaced."""
    if dst.exists():
        raise SystemExit(f"lens_swap: {dst} exists; give a new folder")
    shutil.copytree(src, dst, copy_function=os.link)
    manifest = pd.read_csv(dst / "manifest.csv", dtype={"frame_id": str})
    if side not in set(manifest["side"]):
        raise SystemExit(f"lens_swap: no camera {side!r} in {src}/manifest.csv; it has "
                         f"{sorted(set(manifest['side']))}")  # fmt: skip
    rows = manifest[(manifest["side"] == side) & (manifest["chainage_m"] >= lo_m)
                    & (manifest["chainage_m"] <= hi_m)]  # fmt: skip
    for rel in rows["image"]:
        path = dst / str(rel)
        image = cv2.imread(str(path))
        if image is None:
            raise SystemExit(f"lens_swap: {path} is not an image OpenCV reads")
        ok, data = cv2.imencode(".jpg", zoomed(image, scale), [cv2.IMWRITE_JPEG_QUALITY, 90])
        if not ok:
            raise SystemExit(f"lens_swap: could not encode {path}")
        path.unlink()  # a hard link: the source keeps its own image
        path.write_bytes(data.tobytes())
    return len(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("src", type=Path, help="survey folder (survey.yaml, manifest.csv)")
    parser.add_argument("dst", type=Path, help="new folder for the copy")
    parser.add_argument("--scale", type=float, default=1.25,
                        help="how many times longer the other lens is (default 1.25)")
    parser.add_argument("--side", default="left", help="camera (manifest side; default left)")
    parser.add_argument("--from-m", type=float, required=True, help="first chainage, m")
    parser.add_argument("--to-m", type=float, required=True, help="last chainage, m")
    args = parser.parse_args(argv)
    if not args.scale > 0:
        parser.error("--scale must be > 0")
    n = swap_lens(args.src, args.dst, args.scale, args.side, args.from_m, args.to_m)
    print(f"{args.dst}: {n} {args.side} images zoomed {args.scale:g}x over "
          f"{args.from_m:g}-{args.to_m:g} m", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
