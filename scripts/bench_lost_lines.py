"""Cost of finding lost narrow obstacles (``predisat.sky.lines``) in the segmentation.

Segments the same frames with the step off (``SkyOptions.line_contrast = 0``, the baseline)
and on (the default), interleaved frame by frame so that the machine's load hits both alike,
and prints the frames per CPU-second of each and their ratio, with the share of frames whose
mask the step changed.

Usage::

    python scripts/bench_lost_lines.py IMAGES_DIR [IMAGES_DIR ...] [--panorama | --fisheye]
        [--limit N] [--thin-px N]

``IMAGES_DIR``: a survey's ``images`` folder (or any folder of JPEG/PNG frames); ``--panorama``
segments them as 360-degree equirectangular frames (``segment_panorama``).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from predisat.sky.panorama import segment_panorama
from predisat.sky.segment import SkyOptions, segment_sky


def _read(path: Path) -> np.ndarray:
    img = cv2.imread(str(path))
    if img is None:
        raise SystemExit(f"{path}: not a readable image; remove it from the folder")
    return img


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--panorama", action="store_true", help="360-degree equirectangular frames")
    ap.add_argument("--fisheye", action="store_true", help="upward fisheye photos")
    ap.add_argument("--limit", type=int, default=60, help="frames per folder (default 60)")
    ap.add_argument("--thin-px", type=int, default=None,
                    help="thin-structure width in pixels (default SkyOptions'; the pipeline "
                         "gives a half-resolution panorama 1)")  # fmt: skip
    args = ap.parse_args()
    files = []
    for folder in args.folders:
        found = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
        if not found:
            raise SystemExit(f"{folder}: no JPEG or PNG frames there; give a survey's images "
                             "folder")
        files += found[: args.limit]
    on = SkyOptions(fisheye=args.fisheye)
    if args.thin_px is not None:
        on = replace(on, thin_px=args.thin_px)
    off = replace(on, line_contrast=0.0)
    seg = segment_panorama if args.panorama else segment_sky
    seg(_read(files[0]), on)  # load the models once, outside the timing
    cpu = {"off": 0.0, "on": 0.0}
    changed = 0
    for path in files:
        img = _read(path)
        masks = {}
        for name, opt in (("off", off), ("on", on)):
            t0 = time.process_time()
            masks[name] = seg(img, opt).sky_mask
            cpu[name] += time.process_time() - t0
        changed += int(not np.array_equal(masks["off"], masks["on"]))
    n = len(files)
    print(f"{n} frames: step off {n / cpu['off']:.2f}, on {n / cpu['on']:.2f} frames per "
          f"CPU-second; ratio on / off {cpu['on'] / cpu['off']:.3f} (CPU time); "
          f"masks changed in {changed} frames ({100 * changed / n:.1f} %)")  # fmt: skip


if __name__ == "__main__":
    main()
