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
   become sky. Fisheye photos: sky gaps in foliage (step 5 of GrabCut below; searched on the
   classifier's sky, before the next step).
3. Narrow obstacles the working size lost (a cantilever arm a few pixels wide) are found
   again at full resolution and turned back into obstacles (:mod:`predisat.sky.lines`, all
   methods; ``SkyOptions.line_contrast``).
4. Thin-structure policy and skyline as below; the per-column confidence comes from the
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
4. **Narrow obstacles lost to the working size**, as for the learned methods
   (:mod:`predisat.sky.lines`).
5. **Sky gaps** (optional): pixels outside the GrabCut sky that match the sky colour model
   and are brighter than their surroundings (a white top-hat): sky seen through foliage
   (searched on the sky before step 4: that step only removes sky).
6. **Thin-structure policy** (:func:`remove_thin_obstacles`): obstacle features narrower than
   ``thin_px`` pixels in the vertical *or* the horizontal direction, between sky on both sides,
   are catenary and power wires, cables and twigs, which do not block an L-band signal. They
   are counted as sky. Masts, poles and posts wider than ``thin_px`` stay obstacles. The
   test uses morphological openings with line elements, which remove thin features but leave
   the corners of large obstacles intact (a square element would shave them).
7. **Skyline** (:func:`skyline_from_mask`): per column, the boundary above the highest
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

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky import grabcut as gc
from predisat.sky import perceptron  # perceptron.sky_probability: looked up at call time
from predisat.sky.lines import LostLines, line_width_px, lost_line_obstacles
from predisat.sky.morphology import RunComponents, remove_thin_obstacles
from predisat.sky.network import SkyEnsemble, SkyNet
from predisat.sky.options import METHODS, SkyOptions
from predisat.sky.perceptron import SkyModel
from predisat.sky.skyline import (
    confidence_window_px,
    mask_above_skyline,
    probability_confidence,
    skyline_confidence,
    skyline_from_mask,
)

# The options, the morphology and the skyline functions live in their own modules
# (predisat.sky.options, .morphology, .skyline) and are re-exported here: segment_sky's API.
__all__ = [
    "METHODS",
    "SkyOptions",
    "SkySegmentation",
    "confidence_window_px",
    "fisheye_valid_mask",
    "mask_above_skyline",
    "probability_confidence",
    "remove_thin_obstacles",
    "resolve_model",
    "restore_lines",
    "segment_sky",
    "skyline_confidence",
    "skyline_from_mask",
    "working_side_px",
]


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
    thin_mask : ndarray of bool, shape (H, W), or None
        The pixels of ``sky_mask`` that are sky only by the thin-structure policy (obstacle
        features at most ``thin_px`` wide): the reconstruction counts them transparent only
        where the first Fresnel zone rule allows (``docs/reconstruction.md``, section 8).
    """

    sky_mask: NDArray[np.bool_]
    skyline_row: NDArray[np.float64]
    confidence: NDArray[np.float64]
    valid_mask: NDArray[np.bool_]
    thin_mask: NDArray[np.bool_] | None = None

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


def segment_sky(
    image_bgr: ArrayLike, options: SkyOptions | None = None, classifier: SkyModel | None = None
) -> SkySegmentation:
    """Segment the sky of one frame: pixel mask, skyline per column, per-column confidence.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3) uint8 (BGR, as ``cv2.imread`` gives), or (H, W)
        A grey image is accepted (colour cues are then absent).
    options : SkyOptions, optional
        Defaults to ``SkyOptions()`` (side camera / upright perspective photo). Use
        ``SkyOptions(fisheye=True)`` for upward fisheye photos.
    classifier : SkyModel, optional
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

    if opt.method in ("learned", "cnn", "ensemble"):
        sky, conf, thin = _learned_sky(img, valid, opt, resolve_model(opt, classifier))
        skyline = skyline_from_mask(sky, valid)
        return SkySegmentation(
            sky_mask=sky, skyline_row=skyline,
            confidence=probability_confidence(conf, skyline, valid), valid_mask=valid,
            thin_mask=thin,
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
    # the gaps' sky colour model is the classifier's sky: the step only removes sky
    gaps = gc.sky_gaps(img, sky, valid, opt) if opt.gaps and sky.any() else None
    sky = restore_lines(img, sky, valid, opt, working_side_px(opt, None))
    if gaps is not None:
        sky |= gaps
    raw = sky
    sky = remove_thin_obstacles(sky, opt.thin_px) & valid
    skyline = skyline_from_mask(sky, valid)
    conf = skyline_confidence(img, sky, skyline, valid)
    return SkySegmentation(sky_mask=sky, skyline_row=skyline, confidence=conf, valid_mask=valid,
                           thin_mask=sky & ~raw)  # fmt: skip


def resolve_model(opt: SkyOptions, classifier: SkyModel | None) -> SkyModel | None:
    """The probability model :func:`segment_sky` uses.

    Parameters
    ----------
    opt : SkyOptions
    classifier : SkyModel or None
        A model given by the caller.

    Returns
    -------
    SkyModel or None
        ``classifier``, else the shipped model of ``opt.method``; None for ``"grabcut"``.
    """
    if opt.method == "grabcut":
        return None
    if classifier is not None:
        return classifier
    if opt.method == "learned":
        return perceptron.SkyClassifier.default()
    return SkyNet.default() if opt.method == "cnn" else SkyEnsemble.default()


def working_side_px(opt: SkyOptions, classifier: SkyModel | None) -> int:
    """Longest side, pixels, of the working image :func:`segment_sky` classifies a frame at:
    the model's ``max_side_px`` (:func:`resolve_model`), or ``opt.work_size_px`` for GrabCut."""
    model = resolve_model(opt, classifier)
    return opt.work_size_px if model is None else int(model.max_side_px)


def restore_lines(
    img: NDArray[np.uint8], sky: NDArray[np.bool_], valid: NDArray[np.bool_], opt: SkyOptions,
    work_side_px: int, edges_hold: bool = True,
    thin_policy: Callable[[NDArray[np.bool_]], NDArray[np.bool_]] | None = None,
    wrap: bool = False,
) -> NDArray[np.bool_]:
    """``sky`` without the narrow obstacles a classification at ``work_side_px`` lost
    (:mod:`predisat.sky.lines`; unchanged when ``opt.line_contrast`` is 0).

    Of the long features only the parts wider than the thin-structure policy allows come back:
    the policy would make the rest sky again, and a wire flagged thin would bound the far field
    (``docs/reconstruction.md``, section 13). Upright features standing on an obstacle (poles,
    far masts; not in an upward fisheye photo, which has no "below") come back whole, so that
    the policy flags their thin parts and the reconstruction's Fresnel rule decides. With the
    policy off (``opt.thin_px = 0``) every lost feature comes back.

    Parameters
    ----------
    img : ndarray, shape (H, W, 3) uint8
        The frame (BGR).
    sky, valid : ndarray of bool, shape (H, W)
        The classifier's sky and the segmented pixels.
    opt : SkyOptions
    work_side_px : int
        Longest side of the working image the frame was classified at (:func:`working_side_px`).
    edges_hold : bool
        Whether the image's edges hold a feature (False for a panorama's band).
    thin_policy : callable, optional
        Maps a sky mask to the same with thin obstacles removed; default
        :func:`remove_thin_obstacles` with ``opt.thin_px + 1`` (a feature's intensity profile is
        about a pixel wider than it).
    wrap : bool
        The columns wrap round (a 360-degree panorama's band): a feature across the seam is
        looked at whole.

    Returns
    -------
    ndarray of bool, shape (H, W)
        A new mask, a subset of ``sky``.
    """
    if opt.line_contrast <= 0:
        return sky
    width = line_width_px(img.shape[:2], work_side_px)
    pad = min(img.shape[1] // 2, 8 * width) if wrap else 0
    if pad:
        cols = np.arange(-pad, img.shape[1] + pad) % img.shape[1]
        img_w, sky_w, valid_w = img[:, cols], sky[:, cols], valid[:, cols]
    else:
        img_w, sky_w, valid_w = img, sky, valid
    lost = lost_line_obstacles(
        img_w, sky_w, valid_w, width, opt.line_contrast, opt.line_min_elongation, edges_hold,
        standing=not opt.fisheye,
    )  # fmt: skip
    if pad:
        lost = LostLines(lost.held[:, pad:-pad], lost.standing[:, pad:-pad])
    back = lost.standing
    if lost.held.any() and opt.thin_px == 0:
        back = back | lost.held  # no policy: every lost feature is an obstacle
    elif lost.held.any():
        # a feature's intensity profile spreads over about one pixel more than its width
        # (optics, anti-aliasing, JPEG): the policy is applied one pixel wider here
        policy = thin_policy or (lambda m: remove_thin_obstacles(m, opt.thin_px + 1))
        back = back | (lost.held & ~policy(~lost.held))  # what stays obstacle under it
    return sky & ~back if back.any() else sky


def grey_pixels(image_bgr: NDArray, max_chroma: float) -> NDArray[np.bool_]:
    """Pixels whose CIELAB chroma (OpenCV's 8-bit Lab, a and b centred on 128) is below
    ``max_chroma``: white and grey, as cloud and pale surfaces are; bool, shape (H, W)."""
    lab = cv2.cvtColor(np.ascontiguousarray(image_bgr), cv2.COLOR_BGR2LAB)
    a = lab[..., 1].astype(np.float32) - 128.0
    b = lab[..., 2].astype(np.float32) - 128.0
    return np.asarray(a * a + b * b < max_chroma * max_chroma)


def _learned_sky(
    img: NDArray, valid: NDArray, opt: SkyOptions, classifier: SkyModel | None
) -> tuple[NDArray, NDArray, NDArray]:
    """Sky mask, probability map and thin-structure pixels of the learned method (see
    ``docs/segmentation.md``)."""
    h, w = img.shape[:2]
    circle = None
    if opt.fisheye:
        circle = opt.circle_px or (
            (w - 1) / 2.0, (h - 1) / 2.0, min(h, w) / 2.0 * (1.0 - opt.circle_margin)
        )
    prob = perceptron.sky_probability(img, classifier, circle, refine=opt.refine_guided)
    all_valid = bool(valid.all())
    if not all_valid:
        prob = np.where(valid, prob, 0.0).astype(np.float32)
    sky = prob >= 0.5
    if opt.grey_sky_probability > 0.5:
        sky &= (prob >= opt.grey_sky_probability) | ~grey_pixels(img, opt.grey_chroma)
    if not all_valid:
        sky &= valid
    n_valid = valid.size if all_valid else max(int(valid.sum()), 1)
    # The region rules below need each region's area and bounding box (and, for a few holes,
    # their mean probability): connected components on row runs (RunComponents) give exactly
    # what cv2.connectedComponentsWithStats gives, at a tenth of its cost on these masks.
    if sky.any() and not opt.fisheye:
        # Sky must be reachable from the top edge, or be a large region (sky under a deck).
        cc = RunComponents.of(sky, connectivity=8)
        keep = ((cc.top == 0) & (cc.area >= opt.min_sky_fraction * n_valid)) | (
            cc.area >= opt.min_island_fraction * n_valid
        )
        if not keep.all():
            cc.paint(sky, ~keep, False)
    obstacle = ~sky if all_valid else ~sky & valid
    if opt.max_hole_fraction > 0 and obstacle.any():
        cc = RunComponents.of(obstacle, connectivity=4)
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
    # the gaps' sky colour model is the classifier's sky: the step only removes sky
    gaps = gc.sky_gaps(img, sky, valid, opt) if opt.gaps and sky.any() else None
    sky = restore_lines(img, sky, valid, opt, working_side_px(opt, classifier))
    if gaps is not None:
        sky |= gaps
    raw = sky
    sky = remove_thin_obstacles(sky, opt.thin_px) & valid
    return sky, prob, sky & ~raw
