"""Two measurements behind docs/segmentation.md, on folders of photos with sky masks.

Usage::

    python scripts/sky_ablations.py ceiling --data ../shared/data/sky/ade20k \
        --data ../shared/data/sky/fisheye_hk
    python scripts/sky_ablations.py flip --data ../shared/data/sky/ade20k \
        --data ../shared/data/sky/fisheye_hk

* ``ceiling``: the best mean IoU a classifier working at ``--side`` px (160 and 320 by
  default) could reach: the *true* mask is area-averaged to the working size, upsampled
  bilinearly, optionally sharpened by the same guided filter as :func:`segment_sky`, and cut at
  0.5. Fine structure (gaps in foliage) lost by the resampling bounds every learned method.
* ``flip``: the ensemble as shipped against the ensemble whose network averages its
  probability over the image and its mirror (test-time flip).

Folders use the layouts of :mod:`predisat.sky.photoeval`; nothing is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky.network import SkyEnsemble, SkyNet
from predisat.sky.perceptron import SkyClassifier, guided_filter
from predisat.sky.photoeval import find_pairs, sky_iou
from predisat.sky.segment import SkyOptions, segment_sky


def _pairs(data: Path) -> tuple[bool, list[tuple[np.ndarray, np.ndarray]]]:
    layout, pairs = find_pairs(data)
    out = []
    for p in pairs:
        img = cv2.imread(str(p.image_path), cv2.IMREAD_COLOR)
        mask = cv2.imread(str(p.mask_path), cv2.IMREAD_GRAYSCALE)
        if img is None or mask is None:
            raise SystemExit(f"cannot read {p.image_path} or {p.mask_path}")
        out.append((img, mask >= 128))
    return layout == "fisheye_hk", out


def ceiling(data: Path, sides: list[int]) -> None:
    _, pairs = _pairs(data)
    for side in sides:
        plain, guided = [], []
        for img, truth in pairs:
            h, w = truth.shape
            s = min(1.0, side / max(h, w))
            small = cv2.resize(truth.astype(np.float32), (round(w * s), round(h * s)),
                               interpolation=cv2.INTER_AREA)
            up = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
            grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32) / 255.0
            # as sky_probability does: the fast variant on frames >= 2x the working size
            sub = 2 if 1.0 / s >= 2.0 else 1
            g = guided_filter(grey, small if sub > 1 else up, max(2, round(1.5 / s)), 1e-3,
                              subsample=sub)
            plain.append(sky_iou(up >= 0.5, truth))
            guided.append(sky_iou(g >= 0.5, truth))
        print(f"{data.name}: ceiling at {side} px: mean IoU {np.mean(plain):.4f} "
              f"(guided filter {np.mean(guided):.4f}), {len(pairs)} images")


class _Flipped:
    """A probability model averaged over the image and its mirror."""

    def __init__(self, model: SkyNet) -> None:
        self.model, self.max_side_px = model, model.max_side_px

    def predict_image(self, image_bgr: ArrayLike) -> NDArray[np.float32]:
        image = np.asarray(image_bgr)
        mirror = np.ascontiguousarray(image[:, ::-1])
        return (0.5 * (self.model.predict_image(image)
                       + self.model.predict_image(mirror)[:, ::-1])).astype(np.float32)


def flip(data: Path) -> None:
    fisheye, pairs = _pairs(data)
    opt = SkyOptions(fisheye=fisheye, method="ensemble")
    plain = SkyEnsemble.default()
    flipped = SkyEnsemble((SkyClassifier.default(), _Flipped(SkyNet.default())), plain.weights)
    for name, model in (("ensemble", plain), ("ensemble, network flipped", flipped)):
        ious = [sky_iou(segment_sky(img, opt, classifier=model).sky_mask, truth)
                for img, truth in pairs]
        print(f"{data.name}: {name}: mean IoU {np.mean(ious):.4f}, {len(pairs)} images")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("ceiling", "flip"))
    ap.add_argument("--data", action="append", required=True, type=Path, metavar="DIR")
    ap.add_argument("--side", action="append", type=int, help="working sizes (ceiling)")
    args = ap.parse_args(argv)
    for data in args.data:
        if args.what == "ceiling":
            ceiling(data, args.side or [160, 320])
        else:
            flip(data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
