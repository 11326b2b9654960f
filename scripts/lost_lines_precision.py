"""What the lost-line step (:mod:`predisat.sky.lines`) turns back into obstacle on labelled
photos: how much of it the reference mask calls obstacle (right) or sky (sky lost by it).

For each image of a labelled set (the layouts ``predisat evaluate-sky`` reads), segments it
with the step off and on (the set's default options) and counts the pixels the step removed
from the sky, split by the reference mask, and the false sky (reference obstacle labelled sky)
before and after. The photos are read where they are; nothing is written.

Usage::

    .venv/bin/python scripts/lost_lines_precision.py ../shared/data/sky/ade20k \\
        ../shared/data/sky/fisheye_hk
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import cv2

from predisat.sky.photoeval import find_pairs
from predisat.sky.segment import SkyOptions, segment_sky


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sets", nargs="+", type=Path, help="labelled photo sets")
    args = ap.parse_args()
    for folder in args.sets:
        layout, pairs = find_pairs(folder)
        on = SkyOptions(fisheye=layout == "fisheye_hk")
        off = replace(on, line_contrast=0.0)
        removed_obstacle = removed_sky = false_before = false_after = obstacle = 0
        touched = 0
        for pair in pairs:
            img = cv2.imread(str(pair.image_path), cv2.IMREAD_COLOR)
            ref = cv2.imread(str(pair.mask_path), cv2.IMREAD_GRAYSCALE)
            if img is None or ref is None or ref.shape != img.shape[:2]:
                raise SystemExit(f"{pair.image_path}: image or reference mask unreadable")
            a, b = segment_sky(img, off), segment_sky(img, on)
            valid = a.valid_mask
            sky_ref = (ref >= 128) & valid
            obst_ref = ~(ref >= 128) & valid
            removed = a.sky_mask & ~b.sky_mask & valid
            touched += int(removed.any())
            removed_obstacle += int((removed & obst_ref).sum())
            removed_sky += int((removed & sky_ref).sum())
            false_before += int((a.sky_mask & obst_ref).sum())
            false_after += int((b.sky_mask & obst_ref).sum())
            obstacle += int(obst_ref.sum())
        total = removed_obstacle + removed_sky
        share = 100.0 * removed_obstacle / total if total else float("nan")
        before = 100 * false_before / max(obstacle, 1)
        after = 100 * false_after / max(obstacle, 1)
        print(f"{folder} ({layout}, {len(pairs)} images, {touched} changed): {total} pixels "
              f"turned back into obstacle, {share:.1f} % of them obstacles in the reference; "
              f"false sky {before:.3f} -> {after:.3f} % of the reference obstacle")  # fmt: skip


if __name__ == "__main__":
    main()
