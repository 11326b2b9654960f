"""Per-pixel features for the learned sky classifier (:mod:`predisat.sky.perceptron`).

The features are computed on a *working image* whose longest side is ``max_side_px`` (default
160 px): a sky/obstacle decision needs context more than detail, the classifier then costs a
few milliseconds, and the feature scales are fractions of the frame whatever its resolution
(the model is trained on 320x240 frames and applied to photos of any size). The image is
assumed upright (sky at the top); an upward fisheye photo is first unwrapped to polar
coordinates by :mod:`predisat.sky.segment` so that the zenith is its top row.

Features (``FEATURE_NAMES``, all float32, roughly 0-1 or a few units):

* colour: CIELAB ``L, a, b``; HSV saturation and value; blueness ``(B - R) / (B + G + R)``;
  the dark channel (min of RGB over 3x3, low in haze and sky, high only in bright white);
* brightness relative to the frame: ``L`` over the frame's 99th percentile of ``L``, and the
  Lab distance to a *sky reference* colour (the median of the smoothest bright pixels of the
  top quarter of the frame, where sky usually is);
* texture at three scales: log gradient energy (Gaussian sigma 1, 2, 4 px), log local standard
  deviation of ``L`` (5 and 11 px windows), log Laplacian energy;
* context: ``L`` and ``b`` blurred over sigma 8 px, the large-scale vertical gradient of ``L``
  (sky brightens or darkens smoothly), the row position (0 top, 1 bottom), and, per column, the
  mean and maximum texture *above* the pixel (sky has nothing textured above it; an obstacle
  usually does, or is the first textured thing).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "FEATURE_NAMES",
    "image_features",
    "working_image",
    "working_size",
]

FEATURE_NAMES: tuple[str, ...] = (
    "lab_l", "lab_a", "lab_b", "hsv_s", "hsv_v", "blueness", "dark_channel",
    "l_rel_p99", "de_sky_ref",
    "grad_s1", "grad_s2", "grad_s4", "std_5", "std_11", "laplacian",
    "l_blur8", "b_blur8", "dl_dy_s4", "row_frac", "tex_above_mean", "tex_above_max",
)  # fmt: skip


def working_size(shape: tuple[int, ...], max_side_px: int = 160) -> tuple[int, int]:
    """``(width, height)`` of the working image of an image of ``shape`` ``(H, W, ...)``.

    The longest side becomes ``max_side_px`` (images are never enlarged).
    """
    h, w = int(shape[0]), int(shape[1])
    if max_side_px < 16:
        raise ValueError(f"max_side_px must be >= 16, got {max_side_px}")
    s = min(1.0, max_side_px / max(h, w))
    return max(1, round(w * s)), max(1, round(h * s))


def working_image(image_bgr: ArrayLike, max_side_px: int = 160) -> NDArray[np.uint8]:
    """The image resized (area averaging) to :func:`working_size`; a copy when not resized."""
    img = np.asarray(image_bgr)
    size = working_size(img.shape, max_side_px)
    if size == (img.shape[1], img.shape[0]):
        return np.array(img, np.uint8)
    return np.asarray(cv2.resize(img, size, interpolation=cv2.INTER_AREA), np.uint8)


def _log_energy(x: NDArray, sigma: float) -> NDArray:
    return np.log1p(cv2.GaussianBlur(x, (0, 0), sigma))


def image_features(small_bgr: ArrayLike) -> NDArray[np.float32]:
    """Feature image of an (already working-size) BGR image.

    Parameters
    ----------
    small_bgr : array_like, shape (h, w, 3), uint8
        Usually :func:`working_image` of the frame.

    Returns
    -------
    ndarray of float32, shape (h, w, len(FEATURE_NAMES))
    """
    img = np.ascontiguousarray(np.asarray(small_bgr))
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(
            f"small_bgr must be an (h, w, 3) uint8 BGR image, got {img.shape} {img.dtype}"
        )
    h, w = img.shape[:2]
    lab = cv2.cvtColor(img, cv2.COLOR_BGR2LAB).astype(np.float32)
    # Every channel as its own contiguous array: OpenCV copies a strided channel view at each
    # call, numpy loops over it slower; the values are the same.
    lum, lab_a, lab_b = cv2.split(lab)
    _, sat, val = cv2.split(cv2.cvtColor(img, cv2.COLOR_BGR2HSV))
    # channel sums and minima of integers: exact in any order
    chan = cv2.split(img)
    blue, green, red = (c.astype(np.float32) for c in chan)
    total = blue + green + red + 1.0
    blueness = (blue - red) / total
    darkest = cv2.min(cv2.min(chan[0], chan[1]), chan[2])
    dark = cv2.erode(darkest, np.ones((3, 3), np.uint8)).astype(np.float32) / 255.0

    p99 = float(np.percentile(lum, 99)) + 1.0
    gx = cv2.Sobel(lum, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(lum, cv2.CV_32F, 0, 1, ksize=3)
    grad = np.hypot(gx, gy)
    g1, g2, g4 = (_log_energy(grad, s) for s in (1.0, 2.0, 4.0))
    stds = []
    for k in (5, 11):
        m = cv2.blur(lum, (k, k))
        m2 = cv2.blur(lum * lum, (k, k))
        stds.append(np.log1p(np.sqrt(np.maximum(m2 - m * m, 0.0))))
    lap = _log_energy(np.abs(cv2.Laplacian(lum, cv2.CV_32F, ksize=3)), 1.0)

    # Sky reference: smooth bright pixels of the top quarter (the frame's likeliest sky).
    top = max(1, h // 4)
    cand_l, cand_g = lum[:top], g2[:top]
    smooth = cand_g <= np.quantile(cand_g, 0.3)
    bright = cand_l >= np.quantile(cand_l[smooth], 0.5) if smooth.any() else smooth
    pick = smooth & bright
    ref = np.median(lab[:top][pick], axis=0) if pick.any() else lab[:top].reshape(-1, 3).mean(0)
    de_ref = np.sqrt((lum - ref[0]) ** 2 + (lab_a - ref[1]) ** 2 + (lab_b - ref[2]) ** 2) / 100.0

    lb8 = cv2.GaussianBlur(lum, (0, 0), 8.0)
    bb8 = cv2.GaussianBlur(lab_b, (0, 0), 8.0)
    dl_dy = cv2.Sobel(cv2.GaussianBlur(lum, (0, 0), 4.0), cv2.CV_32F, 0, 1, ksize=3) / 8.0
    rows = np.broadcast_to(np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None], (h, w))
    # Texture above each pixel in its column (exclusive of the pixel's own neighbourhood).
    tex = g1
    shifted = np.vstack([np.zeros((3, w), np.float32), tex[:-3]]) if h > 3 else tex * 0
    above_mean = np.cumsum(shifted, axis=0) / np.arange(1, h + 1, dtype=np.float32)[:, None]
    above_max = np.maximum.accumulate(cv2.GaussianBlur(shifted, (0, 0), 1.0), axis=0)

    feats = [
        lum / 255.0, (lab_a - 128.0) / 64.0, (lab_b - 128.0) / 64.0,
        sat.astype(np.float32) / 255.0, val.astype(np.float32) / 255.0, blueness, dark,
        lum / p99, de_ref,
        g1, g2, g4, stds[0], stds[1], lap,
        lb8 / 255.0, (bb8 - 128.0) / 64.0, dl_dy / 255.0 * 8.0, rows, above_mean, above_max,
    ]  # fmt: skip
    out = cv2.merge([np.asarray(f, np.float32) for f in feats])  # interleaves in one pass
    return np.ascontiguousarray(out, np.float32)
