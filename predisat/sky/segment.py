"""Sky segmentation of camera frames: a sky mask, the skyline per column, confidence.

Four methods (``SkyOptions.method``, :data:`METHODS`); the default was chosen by measurement
(``docs/segmentation.md``).

**ensemble** (default): the mean of two models' sky probabilities, the per-pixel classifier
of :mod:`predisat.sky.perceptron` (features of :mod:`predisat.sky.features`, trained by
``scripts/train_sky.py`` on synthetic frames only) and the U-Net of :mod:`predisat.sky.network`
(trained on procedural photos and rendered frames). **learned** and **cnn** run the same steps
on one model's probability.

1. Sky probability at a working resolution (longest side 160 px); upsampled and sharpened on
   the frame's edges by a guided filter. An upward fisheye photo is unwrapped to polar
   coordinates first (zenith on top), classified, and wrapped back.
2. ``p >= 0.5``, then connected-component rules: in an upright frame sky must touch the top
   edge (and not be a speck) or be a large region (sky under a bridge deck); obstacle specks
   enclosed by sky, and small hanging regions the classifier hesitated on (dark cloud bases),
   become sky. Fisheye photos: sky gaps in foliage (step 4 below).
3. Thin-structure policy and skyline as below; the per-column confidence comes from the
   probability margins on either side of the skyline (:func:`probability_confidence`).

**grabcut** (classical, about 1 s per frame, no model; internals in
:mod:`predisat.sky.grabcut`):

1. **Features** at a working resolution (longest side ``work_size_px``): CIELAB lightness and
   blue-yellow axis, and a texture energy (box-filtered gradient magnitude of the lightness).
2. **Seeds**: connected regions that are smooth and bright or blue. For a side (or any upright
   perspective) camera a seed must touch the top of the image, and every pixel above the first
   strong edge of a seeded column is a probable-sky seed too. For an upward fisheye every large
   smooth bright region inside the lens circle is a seed.
3. **GrabCut** (:func:`cv2.grabCut`) on a feature image (lightness, blueness, log-texture)
   rather than on BGR: facades that are as white as an overcast sky still differ in texture.
4. **Sky gaps** (optional): pixels outside the GrabCut sky that match the sky colour model
   and are brighter than their surroundings (a white top-hat): sky seen through foliage.
5. **Thin-structure policy** (:func:`remove_thin_obstacles`): obstacle features narrower than
   ``thin_px`` pixels in the vertical *or* the horizontal direction, between sky on both sides,
   are catenary and power wires, cables and twigs, which do not block an L-band signal. They
   are counted as sky. Masts, poles and posts wider than ``thin_px`` stay obstacles. The
   test uses morphological openings with line elements, which remove thin features but leave
   the corners of large obstacles intact (a square element would shave them).
6. **Skyline** (:func:`skyline_from_mask`): per column, the boundary above the highest
   obstacle pixel (see below), and a **confidence** (:func:`skyline_confidence`) from the
   colour contrast across it and the share of sky gaps just below it.

Skyline convention (side cameras)
---------------------------------
Rows grow downward and pixel ``r`` covers ``[r - 0.5, r + 0.5]``. For a camera pitched up with
no large roll, elevation increases upward along every image column. The mask must give the
highest obstructed elevation, so ``skyline_row[c]`` is the *upper edge of the highest obstacle
pixel* of column ``c``: ``min{r : obstacle} - 0.5``. Everything above it is sky; sky holes
below it (gaps in trees, the sky under a bridge deck) are conservatively treated as blocked
(:func:`mask_above_skyline`), and obstacles floating above sky (canopies, overhangs, bridge
decks) pull the skyline up to themselves. Special values: a column with no obstacle has
``skyline_row = H - 0.5`` (the bottom edge: nothing seen blocks it; what lies below the image is
unseen and is the caller's business), a column that is obstacle up to the top has ``-0.5``.
Pixels outside the valid region (the fisheye circle) are neither sky nor obstacle for the
skyline: a column with no valid pixel has ``nan``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "METHODS",
    "SkyOptions",
    "SkySegmentation",
    "confidence_window_px",
    "fisheye_valid_mask",
    "mask_above_skyline",
    "probability_confidence",
    "remove_thin_obstacles",
    "segment_sky",
    "skyline_confidence",
    "skyline_from_mask",
]

METHODS = ("ensemble", "cnn", "learned", "grabcut")


@dataclass(frozen=True)
class SkyOptions:
    """Parameters of :func:`segment_sky` (defaults suit 45 deg side cameras and street photos).

    Attributes
    ----------
    fisheye : bool
        Upward-looking fisheye: only pixels inside the lens circle are segmented, seeds may lie
        anywhere inside it (not only at the top), and sky gaps are searched by default.
    circle_px : tuple of float, optional
        Lens circle ``(cx, cy, radius)`` in full-resolution pixels; default: the inscribed
        circle of the image shrunk by ``circle_margin``.
    circle_margin : float
        Fraction of the default radius trimmed off (the dark vignetted rim of the lens).
    work_size_px : int
        Longest side of the working image for seeds and GrabCut; the mask is upsampled.
    texture_quantile : float
        Quantile of the texture energy below which a pixel is "smooth" (clipped to
        ``texture_min``..``texture_max``, in Lab lightness units per pixel).
    texture_min, texture_max : float
    texture_weight : float
        Scale of the log-texture channel of the GrabCut feature image (higher: texture counts
        more against colour).
    grabcut_iterations : int
    min_seed_fraction : float
        Smallest seed region, as a fraction of the valid area (unless it is at least 30 % of the
        largest candidate).
    detect_gaps : bool, optional
        Search sky gaps in obstacles (foliage). Default: True for fisheye, False otherwise (in
        side-camera use gaps below the skyline are blocked anyway, and on street photos the
        search confuses white window frames with sky).
    gap_max_mahalanobis : float
        Colour distance (Mahalanobis, Lab) to the sky model below which a gap pixel may be sky.
    gap_min_tophat : float
        How much brighter (Lab lightness) than its surroundings a gap pixel must be.
    thin_px : int
        Thin-structure width in full-resolution pixels: obstacle features at most this wide,
        against the sky, are L-band transparent and counted as sky (0 disables the policy).
    refine_band_px : int
        Half-width of the band around the boundary re-decided at full resolution by a colour
        GrabCut (0 disables the refinement).
    min_sky_lightness : float
        Darkest (OpenCV 8-bit Lab lightness, 0-255) non-blue region taken as a sky seed: a dark
        tunnel or wall filling the frame yields no seed, hence no sky.
    method : {"learned", "ensemble", "cnn", "grabcut"}
        ``"ensemble"`` (default, chosen by measurement, see ``docs/segmentation.md``): the
        mean of both probabilities below (the safest masks, the best on real photos);
        ``"learned"``: the per-pixel classifier of :mod:`predisat.sky.perceptron`; ``"cnn"``: the
        network of :mod:`predisat.sky.network`; ``"grabcut"``: the classical seeds + GrabCut
        method. The GrabCut parameters above apply to ``"grabcut"`` only (``thin_px``,
        ``circle_*``, ``fisheye`` to all); the "Learned method" ones below to the three
        learned methods.
    refine_guided : bool
        Learned method: sharpen the upsampled probability on the image edges (guided filter).
    min_island_fraction : float
        Learned method: a sky region that does not touch the top of an upright frame is kept
        only if it covers this share of the valid area (sky under a bridge deck); in a fisheye
        photo every sky region is kept (sky gaps in foliage).
    min_sky_fraction : float
        Learned method, upright frames: sky specks touching the top smaller than this share of
        the valid area are dropped (noise on a dark tunnel wall).
    max_hole_fraction : float
        Learned method: obstacle specks enclosed by sky and smaller than this share of the
        valid area are classifier noise and become sky.
    uncertain_hole_fraction, uncertain_hole_probability : float
        Learned method: obstacle regions enclosed by sky (touching no frame edge; in a fisheye
        photo any region), smaller than this share of the valid area, whose mean sky
        probability is at least ``uncertain_hole_probability``, become sky (dark cloud
        bases). A region cut by the frame edge stays an obstacle: it may be a mast, a wall or
        the opposite rock face whose rest is out of the picture.
    """

    fisheye: bool = False
    circle_px: tuple[float, float, float] | None = None
    circle_margin: float = 0.04
    work_size_px: int = 400
    texture_quantile: float = 0.4
    texture_min: float = 4.0
    texture_max: float = 20.0
    texture_weight: float = 25.0
    grabcut_iterations: int = 3
    min_seed_fraction: float = 0.01
    detect_gaps: bool | None = None
    gap_max_mahalanobis: float = 2.5
    gap_min_tophat: float = 20.0
    thin_px: int = 3
    refine_band_px: int = 6
    min_sky_lightness: float = 100.0
    method: str = "ensemble"
    refine_guided: bool = True
    min_island_fraction: float = 0.01
    min_sky_fraction: float = 0.002
    max_hole_fraction: float = 0.0005
    uncertain_hole_fraction: float = 0.05
    uncertain_hole_probability: float = 0.25

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        fractions = (self.min_island_fraction, self.min_sky_fraction, self.max_hole_fraction,
                     self.uncertain_hole_fraction, self.uncertain_hole_probability)
        if not all(0.0 <= f <= 1.0 for f in fractions):
            raise ValueError(
                "min_island_fraction, min_sky_fraction, max_hole_fraction, "
                "uncertain_hole_fraction and uncertain_hole_probability must lie in [0, 1]"
            )
        if self.work_size_px < 32:
            raise ValueError(f"work_size_px must be >= 32, got {self.work_size_px}")
        if not 0.0 < self.texture_quantile < 1.0:
            raise ValueError(f"texture_quantile must lie in (0, 1), got {self.texture_quantile}")
        if not 0.0 < self.texture_min <= self.texture_max:
            raise ValueError("need 0 < texture_min <= texture_max")
        if self.grabcut_iterations < 1:
            raise ValueError(f"grabcut_iterations must be >= 1, got {self.grabcut_iterations}")
        if self.thin_px < 0:
            raise ValueError(f"thin_px must be >= 0 (0 disables the policy), got {self.thin_px}")
        if not 0.0 <= self.circle_margin < 1.0:
            raise ValueError(f"circle_margin must lie in [0, 1), got {self.circle_margin}")
        if self.circle_px is not None and (len(self.circle_px) != 3 or self.circle_px[2] <= 0):
            raise ValueError("circle_px must be (cx, cy, radius) with radius > 0")

    @property
    def gaps(self) -> bool:
        """Whether sky gaps are searched (``detect_gaps`` resolved against ``fisheye``)."""
        return self.fisheye if self.detect_gaps is None else bool(self.detect_gaps)


@dataclass(frozen=True)
class SkySegmentation:
    """Result of :func:`segment_sky` for one image of ``H x W`` pixels.

    Attributes
    ----------
    sky_mask : ndarray of bool, shape (H, W)
        Pixel-level sky (True), thin L-band-transparent structures included, sky gaps included.
    skyline_row : ndarray of float, shape (W,)
        Per column, the upper edge of the highest obstacle pixel (module docstring): ``H - 0.5``
        when the column has no obstacle, ``-0.5`` when the obstacle reaches the top, ``nan``
        when the column has no valid pixel.
    confidence : ndarray of float, shape (W,)
        0-1 per column: contrast across the skyline, lowered by sky gaps just below it.
    valid_mask : ndarray of bool, shape (H, W)
        Pixels that were segmented (all of them, except outside a fisheye circle).
    """

    sky_mask: NDArray[np.bool_]
    skyline_row: NDArray[np.float64]
    confidence: NDArray[np.float64]
    valid_mask: NDArray[np.bool_]

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` in pixels."""
        return (int(self.sky_mask.shape[0]), int(self.sky_mask.shape[1]))

    @property
    def sky_fraction(self) -> float:
        """Share of valid pixels that are sky."""
        n = int(self.valid_mask.sum())
        return float((self.sky_mask & self.valid_mask).sum() / n) if n else 0.0

    def conservative_mask(self) -> NDArray[np.bool_]:
        """Sky only above the skyline (gaps below it blocked): what a GNSS mask may trust."""
        return mask_above_skyline(self.skyline_row, self.shape[0]) & self.valid_mask


def fisheye_valid_mask(
    shape: tuple[int, int],
    circle_px: tuple[float, float, float] | None = None,
    margin: float = 0.04,
) -> NDArray[np.bool_]:
    """Pixels inside a fisheye lens circle.

    Parameters
    ----------
    shape : (H, W)
    circle_px : (cx, cy, radius), optional
        Circle in pixels; default the inscribed circle centred on the image, radius
        ``min(H, W) / 2 * (1 - margin)``.
    margin : float
        Fraction of the default radius trimmed off (ignored when ``circle_px`` is given).

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    h, w = int(shape[0]), int(shape[1])
    if circle_px is None:
        cx, cy, r = (w - 1) / 2.0, (h - 1) / 2.0, min(h, w) / 2.0 * (1.0 - margin)
    else:
        cx, cy, r = (float(v) for v in circle_px)
    yy, xx = np.ogrid[:h, :w]
    return np.asarray((xx - cx) ** 2 + (yy - cy) ** 2 < r * r)


def remove_thin_obstacles(sky_mask: ArrayLike, thin_px: int) -> NDArray[np.bool_]:
    """Apply the thin-structure policy: obstacle features at most ``thin_px`` wide become sky.

    An obstacle pixel is kept only if it belongs to a vertical run *and* to a horizontal run of
    at least ``thin_px + 1`` obstacle pixels (morphological openings with line elements).
    Wires and cables (thin across, whatever their direction), thin twigs and thin fringes are
    removed; masts, poles and buildings wider than ``thin_px`` and the corners of every large
    obstacle are kept.

    Parameters
    ----------
    sky_mask : array_like of bool, shape (H, W)
    thin_px : int
        Largest width, in pixels, of a structure counted as L-band transparent (0: no change).

    Returns
    -------
    ndarray of bool, shape (H, W)
        A new mask (the input is not modified).
    """
    sky = np.asarray(sky_mask, bool)
    if sky.ndim != 2:
        raise ValueError(f"sky_mask must be 2-D (H, W), got shape {sky.shape}")
    if thin_px < 0:
        raise ValueError(f"thin_px must be >= 0, got {thin_px}")
    if thin_px == 0:
        return sky.copy()
    obstacle = (~sky).astype(np.uint8)
    k = int(thin_px) + 1
    # Pad with obstacle so that features touching the border are judged on their visible part
    # as if they continued (a wall cut by the image edge is not thin).
    pad = k
    ob = cv2.copyMakeBorder(obstacle, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    vert = _line_opening(ob, k, vertical=True)
    horz = _line_opening(ob, k, vertical=False)
    kept = (vert & horz)[pad:-pad, pad:-pad].astype(bool)
    return np.asarray(sky | (obstacle.astype(bool) & ~kept))


def _line_opening(binary: NDArray, length: int, vertical: bool) -> NDArray:
    """Opening with a line of ``length`` pixels: keeps pixels in runs of at least ``length``.

    Explicit anchors (first pixel for the erosion, last for the dilation) make it exact for
    even lengths too, where ``cv2.morphologyEx`` would shift the result by one pixel.
    """
    kernel = np.ones((length, 1) if vertical else (1, length), np.uint8)
    first, last = (0, 0), ((0, length - 1) if vertical else (length - 1, 0))
    eroded = cv2.erode(binary, kernel, anchor=first, borderType=cv2.BORDER_REPLICATE)
    return np.asarray(cv2.dilate(eroded, kernel, anchor=last, borderType=cv2.BORDER_CONSTANT,
                                 borderValue=0))


def skyline_from_mask(
    sky_mask: ArrayLike, valid_mask: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Per-column skyline row of a sky mask (convention in the module docstring).

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


def segment_sky(
    image_bgr: ArrayLike, options: SkyOptions | None = None, classifier: Any = None
) -> SkySegmentation:
    """Segment the sky of one frame: pixel mask, skyline per column, per-column confidence.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3) uint8 (BGR, as ``cv2.imread`` gives), or (H, W)
        A grey image is accepted (colour cues are then absent).
    options : SkyOptions, optional
        Defaults to ``SkyOptions()`` (side camera / upright perspective photo). Use
        ``SkyOptions(fisheye=True)`` for upward fisheye photos.
    classifier : object, optional
        Probability model of the learned methods (``predict_image`` and ``max_side_px``: a
        :class:`predisat.sky.perceptron.SkyClassifier`, :class:`predisat.sky.network.SkyNet` or
        :class:`predisat.sky.network.SkyEnsemble`); default the shipped one of ``method``.

    Returns
    -------
    SkySegmentation
        Thin L-band-transparent structures (``thin_px``) are sky in ``sky_mask``; the skyline
        follows the convention of the module docstring.
    """
    opt = options or SkyOptions()
    img = np.asarray(image_bgr)
    if img.ndim == 2:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_GRAY2BGR)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 8 or img.shape[1] < 8:
        raise ValueError(
            f"image_bgr must be an (H, W, 3) BGR image of at least 8x8 pixels, got {img.shape}"
        )
    if img.dtype != np.uint8:
        raise ValueError(f"image_bgr must be uint8 (as cv2.imread gives), got {img.dtype}")
    img = np.ascontiguousarray(img)
    h, w = img.shape[:2]
    if opt.fisheye:
        valid = fisheye_valid_mask((h, w), opt.circle_px, opt.circle_margin)
    else:
        valid = np.ones((h, w), bool)

    from predisat.sky import grabcut as gc

    if opt.method in ("learned", "cnn", "ensemble"):
        if classifier is None and opt.method != "learned":
            from predisat.sky.network import SkyEnsemble, SkyNet

            classifier = SkyNet.default() if opt.method == "cnn" else SkyEnsemble.default()
        sky, conf = _learned_sky(img, valid, opt, classifier)
        skyline = skyline_from_mask(sky, valid)
        return SkySegmentation(
            sky_mask=sky, skyline_row=skyline,
            confidence=probability_confidence(conf, skyline, valid), valid_mask=valid,
        )
    small, scale = gc.working_image(img, opt.work_size_px)
    sh, sw = small.shape[:2]
    valid_small = (
        cv2.resize(valid.astype(np.uint8), (sw, sh), interpolation=cv2.INTER_NEAREST) > 0
    )
    sky_small = gc.grabcut_sky(small, valid_small, opt)
    if scale < 1.0:
        # Linear interpolation of the 0/1 mask then 0.5 cut: a smooth boundary, not blocks.
        up = cv2.resize(sky_small.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
        sky = np.asarray(up >= 0.5)
    else:
        sky = sky_small.copy()
    sky &= valid
    if opt.refine_band_px > 0 and sky.any() and (valid & ~sky).any():
        sky = gc.refine_boundary(img, sky, valid, opt.refine_band_px)
    if opt.gaps and sky.any():
        sky |= gc.sky_gaps(img, sky, valid, opt)
    sky = remove_thin_obstacles(sky, opt.thin_px) & valid
    skyline = skyline_from_mask(sky, valid)
    conf = skyline_confidence(img, sky, skyline, valid)
    return SkySegmentation(sky_mask=sky, skyline_row=skyline, confidence=conf, valid_mask=valid)


def _learned_sky(
    img: NDArray, valid: NDArray, opt: SkyOptions, classifier: Any
) -> tuple[NDArray, NDArray]:
    """Sky mask and probability map of the learned method (see ``docs/segmentation.md``)."""
    from predisat.sky.grabcut import sky_gaps
    from predisat.sky.perceptron import sky_probability

    h, w = img.shape[:2]
    circle = None
    if opt.fisheye:
        circle = opt.circle_px or (
            (w - 1) / 2.0, (h - 1) / 2.0, min(h, w) / 2.0 * (1.0 - opt.circle_margin)
        )
    prob = sky_probability(img, classifier, circle, refine=opt.refine_guided)
    all_valid = bool(valid.all())
    if not all_valid:
        prob = np.where(valid, prob, 0.0).astype(np.float32)
    sky = prob >= 0.5
    if not all_valid:
        sky &= valid
    n_valid = valid.size if all_valid else max(int(valid.sum()), 1)
    # The region rules below need each region's area and bounding box (and, for a few holes,
    # their mean probability): connected components on row runs (_Components) give exactly
    # what cv2.connectedComponentsWithStats gives, at a tenth of its cost on these masks.
    if sky.any() and not opt.fisheye:
        # Sky must be reachable from the top edge, or be a large region (sky under a deck).
        cc = _Components.of(sky, connectivity=8)
        keep = ((cc.top == 0) & (cc.area >= opt.min_sky_fraction * n_valid)) | (
            cc.area >= opt.min_island_fraction * n_valid
        )
        if not keep.all():
            cc.paint(sky, ~keep, False)
    obstacle = ~sky if all_valid else ~sky & valid
    if opt.max_hole_fraction > 0 and obstacle.any():
        cc = _Components.of(obstacle, connectivity=4)
        # A region enclosed by sky is a hole; one cut by the frame edge may be a mast, a wall
        # or the opposite rock face whose rest is out of the picture, so it stays an obstacle
        # (a fisheye's rim is no edge: every region may be a hole).
        if opt.fisheye:
            inner = np.ones(cc.n, bool)
        else:
            inner = (cc.left > 0) & (cc.top > 0) & (cc.right < w) & (cc.bottom < h)
        # Enclosed specks are noise; larger holes the classifier hesitated on are dark cloud
        # bases (a real bridge deck or canopy scores near 0).
        small_hole = inner & (cc.area < opt.max_hole_fraction * n_valid)
        uncertain = inner & (cc.area < opt.uncertain_hole_fraction * n_valid)
        if uncertain.any():  # the mean probability per region only when it can matter
            mean_p = cc.sums(prob, uncertain) / np.maximum(cc.area, 1)
            small_hole |= uncertain & (mean_p >= opt.uncertain_hole_probability)
        if small_hole.any():
            cc.paint(sky, small_hole, True)
    if opt.gaps and sky.any():
        sky |= sky_gaps(img, sky, valid, opt)
    sky = remove_thin_obstacles(sky, opt.thin_px) & valid
    return sky, prob


@dataclass(frozen=True)
class _Components:
    """Connected components of a boolean mask, as horizontal runs of True pixels.

    The same regions, areas and bounding boxes as ``cv2.connectedComponentsWithStats`` (here
    numbered from 0 in the raster order of their first pixel; there is no background
    label), but no label image: the masks here hold a few large regions, a few hundred runs
    per frame, so the union-find works on runs and the rules paint or sum only the runs of
    the components they select.

    Attributes
    ----------
    row, start, stop : ndarray of int32, shape (n_runs,)
        Run ``k`` covers pixels ``row[k], start[k]:stop[k]``; runs in raster order.
    label : ndarray of int32, shape (n_runs,)
        Component of each run, ``0 .. n - 1``.
    area : ndarray of int64, shape (n,)
        Pixels per component.
    top, bottom, left, right : ndarray of int64, shape (n,)
        Bounding box per component, pixels: rows ``top:bottom``, columns ``left:right``.
    """

    row: NDArray[np.int32]
    start: NDArray[np.int32]
    stop: NDArray[np.int32]
    label: NDArray[np.int32]
    area: NDArray[np.int64]
    top: NDArray[np.int64]
    bottom: NDArray[np.int64]
    left: NDArray[np.int64]
    right: NDArray[np.int64]

    @classmethod
    def of(cls, mask: NDArray[np.bool_], connectivity: int = 8) -> _Components:
        """Components of the True pixels of a 2-D mask, 4- or 8-connected."""
        if connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
        m = np.ascontiguousarray(mask, np.bool_)
        if m.ndim != 2:
            raise ValueError(f"mask must be 2-D, got shape {m.shape}")
        return cls(*_run_components(m, connectivity == 8))

    @property
    def n(self) -> int:
        """Number of components."""
        return int(self.area.size)

    def paint(self, mask: NDArray[np.bool_], select: NDArray[np.bool_], value: bool) -> None:
        """Set the pixels of the selected components (``select``, shape (n,)) of ``mask``
        (C-contiguous, the shape the components came from) to ``value``, in place."""
        if not (mask.flags.c_contiguous and mask.dtype == np.bool_):
            raise ValueError("mask must be a C-contiguous bool array")
        _paint_runs(mask, self.row, self.start, self.stop, self.label,
                    np.asarray(select, np.bool_), bool(value))  # fmt: skip

    def sums(self, values: NDArray, select: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Sum of ``values`` (2-D, float32 or float64) over each selected component, in float64
        and raster order (what ``np.bincount(labels, values)`` gives, bit for bit); 0 for the
        others."""
        v = np.ascontiguousarray(values)
        return np.asarray(_sum_runs(v, self.row, self.start, self.stop, self.label,
                                    np.asarray(select, np.bool_)))  # fmt: skip


@njit(cache=True, nogil=True)
def _find_root(parent: NDArray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit(cache=True, nogil=True)
def _run_components(mask: NDArray, eight: bool) -> tuple[NDArray, ...]:
    """Runs of True pixels, their component labels and the components' areas and boxes
    (see :class:`_Components`). Two runs on neighbouring rows touch when their columns
    overlap (4-connectivity) or come within one column (8-connectivity)."""
    h, w = mask.shape
    cap = h * ((w + 1) // 2)
    row = np.empty(cap, np.int32)
    start = np.empty(cap, np.int32)
    stop = np.empty(cap, np.int32)
    parent = np.empty(cap, np.int32)
    ext = 1 if eight else 0
    n = 0
    prev0 = 0
    for r in range(h):
        line = mask[r]
        first = n
        c = 0
        while c < w:
            if line[c]:
                s = c
                c += 1
                while c < w and line[c]:
                    c += 1
                row[n] = r
                start[n] = s
                stop[n] = c
                parent[n] = n
                n += 1
            else:
                c += 1
        # merge with the runs of the row above (both lists sorted by column)
        j = prev0
        for i in range(first, n):
            lo = start[i] - ext
            hi = stop[i] + ext
            while j < first and stop[j] <= lo:
                j += 1
            k = j
            while k < first and start[k] < hi:
                a = _find_root(parent, i)
                b = _find_root(parent, k)
                if a < b:
                    parent[b] = a
                elif b < a:
                    parent[a] = b
                k += 1
        prev0 = first
    # every root is its component's first run in raster order
    label = np.empty(n, np.int32)
    n_comp = 0
    for i in range(n):
        p = _find_root(parent, i)
        if p == i:
            label[i] = n_comp
            n_comp += 1
        else:
            label[i] = label[p]
    area = np.zeros(n_comp, np.int64)
    top = np.full(n_comp, h, np.int64)
    bottom = np.zeros(n_comp, np.int64)
    left = np.full(n_comp, w, np.int64)
    right = np.zeros(n_comp, np.int64)
    for i in range(n):
        q = label[i]
        area[q] += stop[i] - start[i]
        top[q] = min(top[q], row[i])
        bottom[q] = max(bottom[q], row[i] + 1)
        left[q] = min(left[q], start[i])
        right[q] = max(right[q], stop[i])
    return row[:n], start[:n], stop[:n], label, area, top, bottom, left, right


@njit(cache=True, nogil=True)
def _paint_runs(
    mask: NDArray, row: NDArray, start: NDArray, stop: NDArray, label: NDArray,
    select: NDArray, value: bool,
) -> None:  # fmt: skip
    for i in range(row.size):
        if select[label[i]]:
            line = mask[row[i]]
            for c in range(start[i], stop[i]):
                line[c] = value


@njit(cache=True, nogil=True)
def _sum_runs(
    values: NDArray, row: NDArray, start: NDArray, stop: NDArray, label: NDArray,
    select: NDArray,
) -> NDArray:  # fmt: skip
    out = np.zeros(select.size)
    for i in range(row.size):  # runs in raster order: each sum adds its pixels in that order
        q = label[i]
        if select[q]:
            line = values[row[i]]
            acc = out[q]
            for c in range(start[i], stop[i]):
                acc += np.float64(line[c])
            out[q] = acc
    return out


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
