"""Narrow obstacles lost to the working resolution, found again at full resolution.

The learned methods classify a frame at a working size (longest side 160 px) and the classical
one at ``work_size_px``; a feature a few full-resolution pixels wide is then a pixel or less
and the upsampled mask calls it plain sky. A feature up to ``thin_px`` wide loses only its
thin-structure flag (the policy would have made it sky, flagged, and the reconstruction's
Fresnel rule would judge it by its distance); a wider one is lost as an obstacle: a catenary
cantilever tube 1-3 m over a roof antenna, 3-5 px in a half-resolution panorama, opaque under
the first Fresnel zone rule, came out as plain sky, and the reconstruction carved through it
(``docs/reconstruction.md``, section 13).

:func:`lost_line_obstacles` looks for them in the full-resolution lightness, inside the sky the
classifier gave: a morphological black top-hat (closing minus image, with a square element
about as wide as what the working size loses) keeps only dark features narrower than the
element, whatever their direction; steps (a cloud's edge, a skyline) and smooth gradients give
nothing. A component of the response is a lost obstacle when it is

* contrasted (``contrast`` lightness units below its closed surroundings),
* line-like (longer than ``min_elongation`` times its width, and than twice the element): cloud
  texture gives short blobs,
* not bluer than its surroundings: a channel of blue sky between bright clouds is dark and
  may be long, but it is sky-coloured,
* and attached: within the element of an obstacle the classifier did see (a mast, a building) or
  of the edge of the image: an arm is held by something; a wire hanging free in the sky
  is left to the classifier (it is transparent, and flagging every span would take its
  whole arc out of the far field).

Of such features only the parts wider than the thin-structure policy's width (plus a pixel of
blur) become obstacles again (:func:`predisat.sky.segment.restore_lines`). A shorter feature
(at least the element long) that stands upright on an obstacle, a pole or a far mast a pixel
wide on the skyline (:attr:`LostLines.standing`), comes back whole before the policy runs, so
that the policy flags it thin and the reconstruction's Fresnel rule decides by its distance
(a 0.3 m mast 33 m away is opaque, though it is a pixel in a half-resolution panorama). The
step only removes sky.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky.morphology import RunComponents

__all__ = ["LostLines", "line_width_px", "lost_line_obstacles"]

_BLUER_MAX = 8
"""How much bluer than its surroundings (Lab b, 8-bit units) a dark feature may be and still
be a structure: more, and it is blue sky between clouds."""


@dataclass(frozen=True)
class LostLines:
    """Dark line features inside the classified sky (:func:`lost_line_obstacles`).

    Attributes
    ----------
    held : ndarray of bool, shape (H, W)
        Long features (at least twice the element) held by an obstacle or the image edge.
    standing : ndarray of bool, shape (H, W)
        Upright features (at least the element long) whose lowest row rests on an obstacle:
        poles and far masts on the skyline (empty unless asked for).
    """

    held: NDArray[np.bool_]
    standing: NDArray[np.bool_]


def line_width_px(shape: tuple[int, int], work_side_px: int) -> int:
    """Side of the black top-hat's square element for a frame classified at a working size.

    Parameters
    ----------
    shape : (H, W)
        The frame, pixels.
    work_side_px : int
        Longest side of the working image, pixels.

    Returns
    -------
    int
        Three working pixels in full-resolution pixels, odd, at least 5.
    """
    if work_side_px < 1:
        raise ValueError(f"work_side_px must be >= 1, got {work_side_px}")
    scale = max(int(shape[0]), int(shape[1])) / float(work_side_px)
    return max(5, 2 * round(1.5 * scale) + 1)


def lost_line_obstacles(
    image_bgr: ArrayLike,
    sky_mask: ArrayLike,
    valid_mask: ArrayLike,
    width_px: int,
    contrast: float = 25.0,
    min_elongation: float = 5.0,
    edges_hold: bool = True,
    standing: bool = False,
) -> LostLines:
    """Pixels of ``sky_mask`` that belong to narrow dark line features held by an obstacle.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3) uint8
    sky_mask, valid_mask : array_like of bool, shape (H, W)
        The classifier's sky, and the segmented pixels (a fisheye's image circle).
    width_px : int
        Side of the closing's square element, full-resolution pixels (odd, >= 3): features narrower
        than it are found (:func:`line_width_px`).
    contrast : float
        Least depth of a feature below its closed surroundings, OpenCV 8-bit Lab lightness
        (0-255).
    min_elongation : float
        Least ratio of a feature's length (its bounding box's longer side) to its width (twice
        the largest distance from its border, less a pixel).
    edges_hold : bool
        Whether the image's edges hold a feature (its holder may be out of the picture);
        False for a panorama's band, whose edges are the seam and the zenith.
    standing : bool
        Also return shorter features (at least ``width_px`` long) that stand upright on an
        obstacle: a pole or a far mast a pixel or two wide rising from the skyline of an
        upright frame (its lowest row rests on an obstacle pixel just below it).

    Returns
    -------
    LostLines
        Both masks subsets of ``sky_mask & valid_mask``.
    """
    img = np.asarray(image_bgr)
    sky = np.asarray(sky_mask, bool)
    valid = np.asarray(valid_mask, bool)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image_bgr must be an (H, W, 3) uint8 BGR image, got {img.shape}")
    if sky.shape != img.shape[:2] or valid.shape != img.shape[:2]:
        raise ValueError(
            f"sky_mask {sky.shape} and valid_mask {valid.shape} must match the image "
            f"{img.shape[:2]}"
        )
    if width_px < 3 or width_px % 2 == 0:
        raise ValueError(f"width_px must be odd and >= 3, got {width_px}")
    if contrast <= 0 or min_elongation < 1:
        raise ValueError(
            f"contrast must be > 0 and min_elongation >= 1, got {contrast} and {min_elongation}"
        )
    out = LostLines(np.zeros(sky.shape, bool), np.zeros(sky.shape, bool))
    cand_sky = sky & valid
    seen_obstacle = valid & ~sky
    if not cand_sky.any() or not (edges_hold or seen_obstacle.any()):
        return out  # nothing can hold a feature
    lab3 = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2LAB)
    light = lab3[..., 0]
    # a square element is separable (a disc costs 25x more at the sizes of a 12 Mpx photo)
    # and still catches a diagonal line up to width_px / sqrt(2) across
    elem = cv2.getStructuringElement(cv2.MORPH_RECT, (width_px, width_px))
    depth = cv2.morphologyEx(light, cv2.MORPH_BLACKHAT, elem)
    # blue-yellow (OpenCV 8-bit Lab b: 128 neutral, lower bluer), its own narrow valleys: a
    # channel of blue sky between bright clouds is dark too, but bluer than its surroundings
    bluer = cv2.morphologyEx(lab3[..., 2], cv2.MORPH_BLACKHAT, elem)
    resp = ((depth >= contrast) & (bluer <= _BLUER_MAX) & cand_sky).astype(np.uint8)
    if not resp.any():
        return out
    # what may hold a feature: a seen obstacle, or the image's (or circle's) edge
    holder = seen_obstacle.astype(np.uint8)
    if edges_hold:
        holder[0, :] = holder[-1, :] = holder[:, 0] = holder[:, -1] = 1
    if edges_hold and not valid.all():
        holder |= (cv2.dilate((~valid).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0) & valid
    near_holder = cv2.dilate(holder, elem) > 0
    cc = RunComponents.of(resp.astype(bool), connectivity=8)
    w_box, h_box = cc.right - cc.left, cc.bottom - cc.top
    length = np.maximum(w_box, h_box)
    upright = h_box >= 2 * w_box
    cand = (length >= 2 * width_px) | (standing & upright & (length >= width_px))
    cand &= cc.touching(near_holder)  # held
    if not cand.any():
        return out
    dist = cv2.distanceTransform(resp, cv2.DIST_L2, cv2.DIST_MASK_5)
    # the distance to the nearest background pixel is half the width plus half a pixel (exact
    # for odd widths; an even width reads a pixel less)
    width = 2.0 * cc.maxes(dist, cand) - 1.0
    cand &= length >= min_elongation * np.maximum(width, 1.0)
    keep = cand & (length >= 2 * width_px)
    below = np.zeros(sky.shape, bool)
    below[:-1] = seen_obstacle[1:]  # a seen obstacle right under each pixel (not the edge)
    lowest = cc.row == cc.bottom[cc.label] - 1  # the runs of each component's lowest row
    stand = cand & upright & cc.touching(below, lowest) if standing else np.zeros(cc.n, bool)
    held_mask, stand_mask = np.zeros(sky.shape, bool), np.zeros(sky.shape, bool)
    cc.paint(held_mask, keep, True)
    cc.paint(stand_mask, stand, True)
    return LostLines(held_mask, stand_mask)
