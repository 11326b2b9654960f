"""The classical sky segmentation (``SkyOptions(method="grabcut")``): seeds and GrabCut.

Internal to :func:`predisat.sky.segment.segment_sky`, which documents the method; moved here
to keep that module short. :func:`sky_gaps` also serves the learned method on fisheye photos.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from predisat.sky.morphology import remove_thin_obstacles
from predisat.sky.options import SkyOptions

__all__ = ["grabcut_sky", "refine_boundary", "sky_gaps", "sky_seeds", "texture", "working_image"]

# Lab values in OpenCV's 8-bit encoding: 128 is neutral on a and b; b < 128 is blue.
_NEUTRAL_B = 128.0
# Gap (working-resolution pixels) across which smooth candidate regions are joined.
_BRIDGE_PX = 15


def working_image(image: NDArray, work_size_px: int) -> tuple[NDArray, float]:
    h, w = image.shape[:2]
    scale = min(1.0, work_size_px / max(h, w))
    if scale >= 1.0:
        return image.copy(), 1.0
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA), scale


def texture(lightness: NDArray) -> NDArray:
    g = cv2.GaussianBlur(lightness, (0, 0), 0.8)
    grad = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1))
    return np.asarray(cv2.blur(grad, (5, 5)))


def sky_seeds(
    lab: NDArray, tex: NDArray, valid: NDArray, opt: SkyOptions
) -> tuple[NDArray, float]:
    """Smooth, bright-or-blue regions that may be sky, and the smoothness threshold."""
    h = lab.shape[0]
    lightness, blueness = lab[..., 0].astype(np.float32), lab[..., 2].astype(np.float32)
    t_tex = float(
        np.clip(np.quantile(tex[valid], opt.texture_quantile), opt.texture_min, opt.texture_max)
    )
    smooth = (tex < t_tex) & valid
    bright = (lightness > np.median(lightness[valid])) & (lightness >= opt.min_sky_lightness)
    blue = blueness < _NEUTRAL_B - 4.0
    cand = smooth & (bright | blue)
    # Wires cut the sky into strips (their texture footprint is ~11 px wide after filtering):
    # components are found on the candidates with thin gaps bridged, so that the sky below a
    # catenary wire is as much a seed as the sky above it.
    bridged = remove_thin_obstacles(cand, _BRIDGE_PX).astype(np.uint8)
    n, lbl, stats, _ = cv2.connectedComponentsWithStats(bridged, connectivity=4)
    if n <= 1:
        return np.zeros(valid.shape, bool), t_tex
    area = stats[1:, cv2.CC_STAT_AREA]
    big = (area >= opt.min_seed_fraction * valid.sum()) | (area >= 0.3 * area.max())
    if not opt.fisheye:
        big &= stats[1:, cv2.CC_STAT_TOP] <= 0.02 * h
    keep = np.concatenate([[False], big])
    return keep[lbl] & cand, t_tex


def grabcut_sky(small: NDArray, valid: NDArray, opt: SkyOptions) -> NDArray:
    """Sky at working resolution (bool), or all False when no seed is found."""
    h, w = small.shape[:2]
    lab = cv2.cvtColor(small, cv2.COLOR_BGR2LAB)
    tex = texture(lab[..., 0].astype(np.float32))
    seeds, t_tex = sky_seeds(lab, tex, valid, opt)
    if seeds.sum() < 20:
        return np.zeros((h, w), bool)
    ltex = np.clip(np.log1p(tex) * opt.texture_weight, 0, 255).astype(np.uint8)
    feat = np.ascontiguousarray(np.dstack([lab[..., 0], lab[..., 2], ltex]), np.uint8)
    gc = np.full((h, w), cv2.GC_PR_BGD, np.uint8)
    if not opt.fisheye:
        # In an upright frame whatever lies above a seeded column's first strong edge is
        # probably sky too (clouds have soft edges, buildings sharp ones).
        strong = tex > 3.0 * t_tex
        first = np.where(strong.any(axis=0), strong.argmax(axis=0), h)
        rows = np.arange(h)[:, None]
        above = (rows < first[None, :]) & np.asarray(seeds.any(axis=0))[None, :]
        gc[above] = cv2.GC_PR_FGD
    gc[seeds] = cv2.GC_PR_FGD
    core = cv2.erode(seeds.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    gc[core] = cv2.GC_FGD
    gc[~valid] = cv2.GC_BGD
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    try:
        cv2.grabCut(feat, gc, (0, 0, 0, 0), bgd, fgd, opt.grabcut_iterations, cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        # GrabCut refuses masks with no possible background (an all-sky frame): keep the seeds.
        return np.asarray(gc != cv2.GC_BGD) & (gc != cv2.GC_PR_BGD)
    return np.asarray((gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD))


def refine_boundary(image: NDArray, sky: NDArray, valid: NDArray, band_px: int) -> NDArray:
    """Re-decide a band around the sky boundary at full resolution, on colour alone.

    The working-resolution cut is biased toward the obstacle by the texture filter's support
    (a few pixels of "texture" leak into the sky beside every edge); a colour GrabCut with
    everything outside the band fixed removes that bias.
    """
    k = np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)
    sure_sky = cv2.erode(sky.astype(np.uint8), k).astype(bool)
    sure_obst = cv2.erode((~sky & valid).astype(np.uint8), k).astype(bool) | ~valid
    if not sure_sky.any() or not sure_obst.any():
        return sky
    gc = np.where(sky, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    gc[sure_sky] = cv2.GC_FGD
    gc[sure_obst] = cv2.GC_BGD
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    try:
        cv2.grabCut(image, gc, (0, 0, 0, 0), bgd, fgd, 2, cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        return sky
    return np.asarray((gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)) & valid


def sky_gaps(image: NDArray, sky: NDArray, valid: NDArray, opt: SkyOptions) -> NDArray:
    """Pixels outside ``sky`` with the sky's colour, brighter than their surroundings."""
    h, w = sky.shape
    core = cv2.erode(sky.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    if core.sum() < 50:
        return np.zeros_like(sky)
    lab = cv2.cvtColor(image, cv2.COLOR_BGR2LAB).astype(np.float32)
    px = lab[core]
    mu = px.mean(axis=0)
    icov = np.linalg.inv(np.cov(px.T) + 4.0 * np.eye(3))  # floor: JPEG noise on a flat sky
    d = lab - mu
    md2 = np.einsum("...i,ij,...j->...", d, icov, d)
    k = max(3, round(max(h, w) / 60) | 1)
    tophat = cv2.morphologyEx(
        lab[..., 0], cv2.MORPH_TOPHAT, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    )
    return np.asarray(
        (md2 < opt.gap_max_mahalanobis**2) & (tophat > opt.gap_min_tophat) & ~sky & valid
    )
