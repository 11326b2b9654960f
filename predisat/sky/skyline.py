"""The skyline of a sky mask and its per-column confidence.

The skyline convention (rows, half-pixel edges, special values) is in the module docstring of
:mod:`predisat.sky.segment`: ``skyline_row[c]`` is the upper edge of the highest obstacle pixel
of column ``c``.

* :func:`skyline_from_mask` and :func:`mask_above_skyline` - mask to skyline and back.
* :func:`skyline_confidence` - confidence from the colour contrast across the skyline (GrabCut).
* :func:`probability_confidence` - confidence from a classifier's probability margins (learned
  methods), over the window of :func:`confidence_window_px`.
"""

from __future__ import annotations

import cv2
import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "confidence_window_px",
    "mask_above_skyline",
    "probability_confidence",
    "skyline_confidence",
    "skyline_from_mask",
]


def skyline_from_mask(
    sky_mask: ArrayLike, valid_mask: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Per-column skyline row of a sky mask (convention in :mod:`predisat.sky.segment`).

    Parameters
    ----------
    sky_mask : array_like of bool, shape (H, W)
    valid_mask : array_like of bool, shape (H, W), optional
        Pixels that count; invalid pixels are ignored (neither sky nor obstacle).

    Returns
    -------
    ndarray of float, shape (W,)
        ``min{r : valid obstacle} - 0.5``; ``H - 0.5`` for columns without obstacle, ``nan``
        for columns without a valid pixel.
    """
    sky = np.asarray(sky_mask, bool)
    if sky.ndim != 2:
        raise ValueError(f"sky_mask must be 2-D (H, W), got shape {sky.shape}")
    valid = sky if valid_mask is None else np.asarray(valid_mask, bool)
    if valid.shape != sky.shape:
        raise ValueError(f"valid_mask shape {valid.shape} differs from sky_mask {sky.shape}")
    # one pass from the top, stopping once every column has met its obstacle (the skyline is
    # usually in the upper half): the same rows as argmax over the whole frame
    return _first_obstacle_rows(sky, valid, valid_mask is None)


@njit(cache=True, nogil=True)
def _first_obstacle_rows(sky: NDArray, valid: NDArray, all_valid: bool) -> NDArray:
    """:func:`skyline_from_mask` of 2-D bool masks (``valid`` is not read when ``all_valid``)."""
    h, w = sky.shape
    first = np.full(w, -1, np.int64)  # first valid obstacle row; -1: none yet
    seen = np.zeros(w, np.bool_)  # the column has a valid pixel
    left = w  # columns still without an obstacle
    for r in range(h):
        for c in range(w):
            if first[c] < 0 and (all_valid or valid[r, c]):
                seen[c] = True
                if not sky[r, c]:
                    first[c] = r
                    left -= 1
        if left == 0:
            break
    out = np.empty(w)
    for c in range(w):
        if first[c] >= 0:
            out[c] = first[c] - 0.5
        elif seen[c]:
            out[c] = h - 0.5
        else:
            out[c] = np.nan
    return out


def mask_above_skyline(skyline_row: ArrayLike, height_px: int) -> NDArray[np.bool_]:
    """The conservative sky mask: True above the skyline of each column, False below.

    Parameters
    ----------
    skyline_row : array_like, shape (W,)
        As returned by :func:`skyline_from_mask` (``nan`` columns give no sky).
    height_px : int

    Returns
    -------
    ndarray of bool, shape (height_px, W)
    """
    s = np.asarray(skyline_row, float)
    rows = np.arange(int(height_px), dtype=float)[:, None]
    with np.errstate(invalid="ignore"):
        return np.asarray(rows < s[None, :])


def skyline_confidence(
    image_bgr: ArrayLike,
    sky_mask: ArrayLike,
    skyline_row: ArrayLike,
    valid_mask: ArrayLike | None = None,
    band_px: int | None = None,
    contrast_scale: float = 12.0,
) -> NDArray[np.float64]:
    """Per-column confidence of a skyline, in [0, 1].

    For a column with a boundary, the Lab colour difference ``dE`` between the ``band_px``
    pixels just above and just below it gives ``1 - exp(-(dE / contrast_scale)^2)`` (a sharp,
    contrasted skyline is trusted; a grey facade against a grey sky is not), multiplied by the
    share of obstacle in the band below (sky gaps just under the skyline mean a ragged,
    uncertain boundary such as foliage). A column that is all sky compares its lowest band with
    the image's mean sky colour (``exp(-(dE / contrast_scale)^2)``: a sky-coloured bottom means
    open sky); a column that is all obstacle compares its top band with the mean sky colour
    (``1 - exp(...)``), or gets 0.5 when the image has no sky. Columns with no valid pixel get 0.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3), uint8
    sky_mask : array_like of bool, shape (H, W)
    skyline_row : array_like, shape (W,)
    valid_mask : array_like of bool, shape (H, W), optional
    band_px : int, optional
        Band height; default ``max(3, H // 60)``.
    contrast_scale : float
        Lab difference giving a confidence of ``1 - 1/e``.

    Returns
    -------
    ndarray of float, shape (W,)
    """
    img = np.asarray(image_bgr)
    sky = np.asarray(sky_mask, bool)
    s = np.asarray(skyline_row, float)
    h, w = sky.shape
    if img.shape[:2] != (h, w) or s.shape != (w,):
        raise ValueError("image_bgr (H, W, 3), sky_mask (H, W) and skyline_row (W,) must agree")
    valid = np.ones_like(sky) if valid_mask is None else np.asarray(valid_mask, bool)
    band = max(3, h // 60) if band_px is None else int(band_px)
    lab = cv2.cvtColor(np.ascontiguousarray(img, np.uint8), cv2.COLOR_BGR2LAB).astype(float)
    # Column-wise cumulative sums give every band mean in O(H W).
    cum = np.concatenate([np.zeros((1, w, 3)), np.cumsum(lab * valid[..., None], axis=0)])
    cnt = np.concatenate([np.zeros((1, w)), np.cumsum(valid, axis=0)])
    obst = np.concatenate([np.zeros((1, w)), np.cumsum(valid & ~sky, axis=0)])
    cols = np.arange(w)

    def band_mean(a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
        n = cnt[b, cols] - cnt[a, cols]
        m = (cum[b, cols] - cum[a, cols]) / np.maximum(n, 1)[:, None]
        return m, n

    b0 = np.where(np.isfinite(s), s + 0.5, 0).astype(int)  # first obstacle row (or H)
    above_a, above_b = np.clip(b0 - band, 0, h), np.clip(b0, 0, h)
    below_a, below_b = np.clip(b0, 0, h), np.clip(b0 + band, 0, h)
    m_above, n_above = band_mean(above_a, above_b)
    m_below, n_below = band_mean(below_a, below_b)
    sky_px = sky & valid
    sky_mean = lab[sky_px].mean(axis=0) if sky_px.any() else None

    conf = np.zeros(w)
    both = (n_above > 0) & (n_below > 0)
    de = np.linalg.norm(m_above - m_below, axis=-1)
    solid = (obst[below_b, cols] - obst[below_a, cols]) / np.maximum(n_below, 1)
    conf[both] = (1.0 - np.exp(-((de / contrast_scale) ** 2)) * 1.0)[both] * solid[both]

    all_sky = (n_above > 0) & (n_below == 0)
    all_obst = (n_above == 0) & (n_below > 0)
    if sky_mean is not None:
        de_sky = np.linalg.norm(m_above - sky_mean, axis=-1)
        conf[all_sky] = np.exp(-((de_sky / contrast_scale) ** 2))[all_sky] * 0.5 + 0.5
        de_obst = np.linalg.norm(m_below - sky_mean, axis=-1)
        conf[all_obst] = (1.0 - np.exp(-((de_obst / contrast_scale) ** 2)))[all_obst]
    else:
        conf[all_obst] = 0.5
    conf[~np.isfinite(s)] = 0.0
    return np.clip(conf, 0.0, 1.0)


def confidence_window_px(height_px: int) -> tuple[int, int]:
    """Default band height and skipped margin of :func:`probability_confidence`, pixels.

    The confidence of a column speaks for the ``gap + band`` rows on either side of its
    skyline: ``(max(3, H // 30), max(1, H // 120))`` for a frame ``H`` pixels high.
    """
    h = int(height_px)
    return max(3, h // 30), max(1, h // 120)


def probability_confidence(
    prob: ArrayLike,
    skyline_row: ArrayLike,
    valid_mask: ArrayLike | None = None,
    band_px: int | None = None,
    gap_px: int | None = None,
) -> NDArray[np.float64]:
    """Per-column confidence of a skyline from the classifier's probability margins, in [0, 1].

    For a column with a boundary: the smaller of the mean margins ``2 p - 1`` over the band
    just above the skyline (sky side) and ``1 - 2 p`` over the band just below it (obstacle
    side), skipping ``gap_px`` pixels next to the boundary where ``p`` crosses 0.5 anyway.
    An all-sky column uses its lowest band, an all-obstacle column its top band. A column
    without valid pixels gets 0.

    Parameters
    ----------
    prob : array_like, shape (H, W)
        Sky probability.
    skyline_row : array_like, shape (W,)
    valid_mask : array_like of bool, shape (H, W), optional
    band_px, gap_px : int, optional
        Band height and skipped margin (default :func:`confidence_window_px`).

    Returns
    -------
    ndarray of float, shape (W,)
    """
    p = np.asarray(prob)  # read only in the bands, in float64 there
    s = np.asarray(skyline_row, float)
    h, w = p.shape
    if s.shape != (w,):
        raise ValueError(f"skyline_row must have shape ({w},), got {s.shape}")
    valid = np.ones((1, 1), bool) if valid_mask is None else np.asarray(valid_mask, bool)
    if valid_mask is not None and valid.shape != (h, w):
        raise ValueError(f"valid_mask shape {valid.shape} differs from prob {(h, w)}")
    band_default, gap_default = confidence_window_px(h)
    band = band_default if band_px is None else int(band_px)
    gap = gap_default if gap_px is None else int(gap_px)
    b0 = np.where(np.isfinite(s), s + 0.5, 0).astype(int)
    # only the two bands are read (band x W pixels), not the whole frame
    up, n_up = _band_means(p, valid, valid_mask is None, b0 - gap - band, b0 - gap, band)
    dn, n_dn = _band_means(p, valid, valid_mask is None, b0 + gap, b0 + gap + band, band)
    conf = np.zeros(w)
    both = (n_up > 0) & (n_dn > 0)
    conf[both] = np.minimum(up, -dn)[both]
    only_up, only_dn = (n_up > 0) & (n_dn == 0), (n_up == 0) & (n_dn > 0)
    conf[only_up], conf[only_dn] = up[only_up], -dn[only_dn]
    conf[~np.isfinite(s)] = 0.0
    return np.clip(conf, 0.0, 1.0)


@njit(cache=True, nogil=True)
def _band_means(
    p: NDArray, valid: NDArray, all_valid: bool, a: NDArray, b: NDArray, band: int
) -> tuple[NDArray, NDArray]:
    """Per column ``c``, the mean of ``2 p - 1`` (float64) over the valid rows ``a[c] + k``,
    ``0 <= k < band``, inside the frame and below ``b[c]``, and their number.

    The sum runs over ``k`` in order, a skipped row adding 0.0: what numpy's
    ``np.where(ok, 2.0 * p - 1.0, 0.0).sum(axis=0)`` over the (band, W) gather gives, bit for
    bit (``valid`` is not read when ``all_valid``).
    """
    h, w = p.shape
    mean = np.empty(w)
    count = np.zeros(w, np.int64)
    for c in range(w):
        total = 0.0
        for k in range(band):
            r = a[c] + k
            v = 0.0
            if 0 <= r < h and r < b[c] and (all_valid or valid[r, c]):
                v = 2.0 * np.float64(p[r, c]) - 1.0
                count[c] += 1
            total = v if k == 0 else total + v
        mean[c] = total / max(count[c], 1)
    return mean, count
