"""Figure of docs/reconstruction.md section 13: a panorama's lost cantilever arms, before and
after the step of :mod:`predisat.sky.lines`.

Segments one equirectangular frame of a rendered survey with the step off and on (the
pipeline's thin-structure width for it) and draws a crop of each: sky tinted, thin-structure
pixels green, pixels the step turned back into obstacles red.

Usage::

    .venv/bin/python scripts/lost_lines_figure.py IMAGE --thin-px 1 --cols 180 540 \\
        --out docs/figures/lost_lines_panorama.png

The figure in the docs: frame ``roof_000077`` of the 360-degree rig's held-out world, seed 12
(``scripts/eval_rigs.py --rigs 360 --seeds 12 --length-m 1000 --scale 0.5``).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from predisat.sky.panorama import segment_panorama
from predisat.sky.segment import SkyOptions, SkySegmentation


def _overlay(img: np.ndarray, seg: SkySegmentation, restored: np.ndarray) -> np.ndarray:
    out = img[..., ::-1].astype(float) / 255.0
    thin = seg.thin_mask if seg.thin_mask is not None else np.zeros(seg.shape, bool)
    sky = seg.sky_mask & ~thin
    out[sky] = 0.55 * out[sky] + 0.45 * np.array([0.85, 0.2, 0.85])
    out[thin] = (0.1, 0.9, 0.1)
    out[restored] = (0.95, 0.1, 0.1)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("image", type=Path, help="an equirectangular frame (JPEG or PNG)")
    ap.add_argument("--thin-px", type=int, default=1, help="the pipeline's width for it")
    ap.add_argument("--cols", type=int, nargs=2, default=(0, 0), help="crop columns (0 0: all)")
    ap.add_argument("--rows", type=float, default=0.35, help="share of the rows shown from top")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    img = cv2.imread(str(args.image))
    if img is None:
        raise SystemExit(f"{args.image}: not a readable image")
    opt = SkyOptions(thin_px=args.thin_px)
    off = segment_panorama(img, replace(opt, line_contrast=0.0))
    on = segment_panorama(img, opt)
    restored = off.sky_mask & ~on.sky_mask
    h, w = img.shape[:2]
    c0, c1 = (0, w) if args.cols[1] <= args.cols[0] else args.cols
    r1 = round(args.rows * h)
    fig, axes = plt.subplots(2, 1, figsize=(8.0, 5.2), constrained_layout=True)
    for ax, seg, title in (
        (axes[0], off, "before: the arms are plain sky (the working size lost them)"),
        (axes[1], on, "after: found again at full resolution (red) and kept as obstacles"),
    ):
        shown = restored if seg is on else np.zeros_like(restored)
        ax.imshow(_overlay(img, seg, shown)[:r1, c0:c1])
        ax.set_title(title, fontsize=9)
        ax.set_axis_off()
    fig.suptitle(f"{args.image.name}: sky (magenta), thin-structure pixels (green), restored "
                 "obstacles (red)", fontsize=9)  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"{args.out}: {int(restored.sum())} pixels restored")


if __name__ == "__main__":
    main()
