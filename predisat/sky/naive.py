"""The naive sky baseline of the evaluations: Otsu's threshold on the blue channel.

The yardstick the default segmenter is judged against (``predisat evaluate-sky`` reports both
side by side, ``docs/segmentation.md``): what an engineer would write in ten minutes with
OpenCV. The sky is bright in the blue channel, so Otsu's threshold (:func:`cv2.threshold` with
``THRESH_OTSU``) over the valid pixels splits it from the rest; in an upright frame a sky region
must touch the top edge, in an upward fisheye photo it must cover 1 % of the lens circle. No
model, no texture, no thin-structure rule. It is never used by the pipeline.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky.grabcut import working_image
from predisat.sky.morphology import RunComponents

__all__ = ["naive_sky_mask"]

#: Smallest sky region of an upward fisheye photo, as a share of the valid pixels.
_MIN_REGION_FRACTION = 0.01


def naive_sky_mask(
    image_bgr: ArrayLike, valid_mask: ArrayLike, *, upright: bool, work_size_px: int = 400
) -> NDArray[np.bool_]:
    """Sky by Otsu's threshold on the blue channel.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3) uint8
        BGR image as ``cv2.imread`` gives it.
    valid_mask : array_like of bool, shape (H, W)
        Pixels to segment (the lens circle of a fisheye photo; all otherwise).
    upright : bool
        True for side cameras and street photos (sky must touch the top edge); False for
        upward fisheye photos (any region of at least 1 % of the valid pixels).
    work_size_px : int
        Longest side of the working image; the mask is upsampled to ``(H, W)``.

    Returns
    -------
    ndarray of bool, shape (H, W)
        True where sky, False elsewhere and outside ``valid_mask``.
    """
    img = np.ascontiguousarray(np.asarray(image_bgr))
    valid = np.asarray(valid_mask, bool)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image_bgr must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
    if valid.shape != img.shape[:2]:
        raise ValueError(f"valid_mask shape {valid.shape} differs from the image's {img.shape[:2]}")
    if work_size_px < 32:
        raise ValueError(f"work_size_px must be >= 32, got {work_size_px}")
    h, w = img.shape[:2]
    small, _ = working_image(img, work_size_px)
    sh, sw = small.shape[:2]
    vs = cv2.resize(valid.astype(np.uint8), (sw, sh), interpolation=cv2.INTER_NEAREST) > 0
    if not vs.any():
        return np.zeros((h, w), bool)
    blue = np.ascontiguousarray(small[..., 0])
    t, _ = cv2.threshold(blue[vs].reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    sky = (blue > t) & vs
    if sky.any():
        cc = RunComponents.of(sky, connectivity=8)
        keep = cc.top == 0 if upright else cc.area >= _MIN_REGION_FRACTION * int(vs.sum())
        if not keep.all():
            cc.paint(sky, ~keep, False)
    up = cv2.resize(sky.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
    return np.asarray(up >= 0.5) & valid
