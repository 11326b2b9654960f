"""Sky segmentation of a 360-degree equirectangular panorama (``docs/rigs.md``).

In a level panorama the sky is a band across the whole width above the horizon (the middle
row), not a fisheye disc: each column is an azimuth, the top row the zenith. Segmenting the
whole 2:1 frame at once would shrink it to the learned methods' working size (160 px wide for
the perceptron: 2.25 deg per pixel) and feed them the ground half they never saw in side
frames. :func:`segment_panorama` therefore segments the band above ``band_rows`` in
near-square tiles (each about 90 degrees of azimuth for a full-sphere panorama, a view like a
side camera's), each widened by wrapped columns of its neighbours so that no tile edge falls
on a column it reports, and stitches masks and confidences; rows below the band are obstacle
(the ground, which the masks never trust).

The thin-structure policy is applied once to the stitched panorama, in true angles on the
sphere (:func:`remove_thin_obstacles_equirect`), not per tile in pixels: a pixel of row ``r``
spans ``cos(lat_r)`` times its nominal angle across (along its parallel), so near the zenith a
wire a third of a pixel wide covers several columns and the pixel policy kept it as an
obstacle (the catenary over the track cut the top sky run of whole sectors; ``docs/rigs.md``).
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.sky.perceptron import SkyModel
from predisat.sky.segment import (
    SkyOptions,
    SkySegmentation,
    resolve_model,
    restore_lines,
    segment_sky,
    working_side_px,
)
from predisat.sky.skyline import skyline_from_mask

__all__ = ["PANORAMA_BAND_SHARE", "equirect_row_lat_deg", "remove_thin_obstacles_equirect",
           "segment_panorama"]  # fmt: skip

PANORAMA_BAND_SHARE = 0.6
"""Default band: the top 60 % of the rows (to 18 deg below the horizon in a level full-sphere
panorama, below any skyline a train's antenna can use)."""


def segment_panorama(
    image_bgr: ArrayLike,
    options: SkyOptions | None = None,
    classifier: SkyModel | None = None,
    band_rows: int | None = None,
    overlap_share: float = 0.25,
) -> SkySegmentation:
    """Segment the sky of an equirectangular panorama in tiles of its upper band.

    Parameters
    ----------
    image_bgr : array_like, shape (H, W, 3) uint8
        The panorama, 360 degrees wide with the top row at the zenith and ``H <= W / 2``
        (columns wrap around: column 0 follows column W - 1).
    options, classifier
        As for :func:`predisat.sky.segment.segment_sky` (``fisheye`` must be False);
        ``options.thin_px`` is counted in pixels of the equator
        (:func:`remove_thin_obstacles_equirect`).
    band_rows : int, optional
        Rows segmented from the top; default ``round(PANORAMA_BAND_SHARE * H)``.
    overlap_share : float
        Columns added on each side of a tile from its neighbours, as a share of the tile
        width.

    Returns
    -------
    SkySegmentation
        For the whole image: rows at and below ``band_rows`` are obstacle; confidence per
        column from its tile.
    """
    opt = options or SkyOptions()
    if opt.fisheye:
        raise ValueError("a panorama is not an upward fisheye: give SkyOptions(fisheye=False)")
    img = np.asarray(image_bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image_bgr must be an (H, W, 3) uint8 BGR image, got {img.shape}")
    h, w = img.shape[:2]
    rows = round(PANORAMA_BAND_SHARE * h) if band_rows is None else int(band_rows)
    if not 8 <= rows <= h:
        raise ValueError(f"band_rows must lie in [8, {h}] (the image height), got {rows}")
    if not 0.0 <= overlap_share <= 1.0:
        raise ValueError(f"overlap_share must lie in [0, 1], got {overlap_share}")
    n_tiles = max(1, round(w / rows))
    edges = np.linspace(0, w, n_tiles + 1).round().astype(int)
    pad = round(overlap_share * w / n_tiles) if n_tiles > 1 else 0
    band = img[:rows]
    sky = np.zeros((h, w), bool)
    conf = np.zeros(w, float)
    # narrow obstacles the tiles' working size lost are looked for once, on the whole band: a
    # tile's edges hold nothing (a free wire crossing one is no arm)
    tile_opt = replace(opt, line_contrast=0.0)
    model = resolve_model(opt, classifier)
    for a, b in itertools.pairwise(edges):
        cols = np.arange(a - pad, b + pad) % w
        tile_img = np.ascontiguousarray(band[:, cols])
        seg = segment_sky(tile_img, tile_opt, model)
        # the tile's mask before its own (pixel) thin policy: the policy runs once, on the
        # sphere (below); the confidence stays the tile's (measured at its skyline)
        tile = seg.sky_mask if seg.thin_mask is None else seg.sky_mask & ~seg.thin_mask
        sky[:rows, a:b] = tile[:, pad : pad + (b - a)]
        conf[a:b] = seg.confidence[pad : pad + (b - a)]
    if opt.line_contrast > 0:
        # the band's width at the tiles' scale: each tile was classified at work_side across
        tile_w = int(edges[1] - edges[0]) + 2 * pad
        band_sky = restore_lines(
            band, sky[:rows], np.ones((rows, w), bool), opt,
            round(working_side_px(opt, model) * max(rows, w) / max(rows, tile_w)),
            edges_hold=False, wrap=True,
            thin_policy=lambda m: remove_thin_obstacles_equirect(
                np.concatenate([m, np.ones((h - rows, w), bool)]), opt.thin_px + 1
            )[:rows],
        )  # fmt: skip
        sky = np.concatenate([band_sky, sky[rows:]])
    thin = None
    if opt.thin_px > 0:
        raw = sky
        sky = remove_thin_obstacles_equirect(raw, opt.thin_px)
        thin = sky & ~raw  # sky the thin-structure policy made (docs/reconstruction.md)
    valid = np.ones((h, w), bool)
    return SkySegmentation(
        sky_mask=sky, skyline_row=skyline_from_mask(sky, valid), confidence=conf,
        valid_mask=valid, thin_mask=thin,
    )  # fmt: skip


def equirect_row_lat_deg(height_px: int, width_px: int) -> NDArray[np.float64]:
    """Latitude of each row's centre of a 360-degree equirectangular panorama, degrees.

    Square pixels of ``360 / width_px`` degrees, the top edge at the zenith (as
    :meth:`predisat.camera.models.CameraModel.equirect` with its default height); rows of a
    panorama cropped at the bottom keep their latitude.

    Returns
    -------
    ndarray, shape (height_px,)
        ``90 - (r + 0.5) * 360 / width_px``.
    """
    if height_px < 1 or width_px < 4 or height_px > width_px // 2:
        raise ValueError(f"an equirectangular panorama needs width_px >= 4 and 1 <= height_px "
                         f"<= width_px / 2, got {height_px}x{width_px}")  # fmt: skip
    return np.asarray(90.0 - (np.arange(height_px) + 0.5) * 360.0 / width_px, float)


def remove_thin_obstacles_equirect(sky_mask: ArrayLike, thin_px: int) -> NDArray[np.bool_]:
    """The thin-structure policy of :func:`predisat.sky.morphology.remove_thin_obstacles`
    measured in true angles on the sphere, for a 360-degree equirectangular panorama.

    An obstacle pixel stays an obstacle only if it belongs to a run of obstacle wider than
    ``thin_px`` pixels *of the equator* (``thin_px * 360 / W`` degrees) both along its column
    and across it:

    * along its column, a meridian (rows are true angles): a run reaching the zenith goes on
      down the opposite meridian, a run reaching the bottom edge counts as continuing (as for
      a frame);
    * across, along the great circle through the pixel perpendicular to its meridian (the
      east-west geodesic, not the parallel: near the zenith a parallel is a small circle, and
      a large obstacle's edge cut by it would look thin), sampled every ``360 / W`` degrees at
      the nearest pixel, with the columns wrapping round the seam. At the equator this is the
      row itself, pixel by pixel: the frame policy.

    A feature removed is therefore at most ``thin_px * 360 / W`` degrees across (as many
    equator pixels as the frame policy allows pixels), whatever its latitude: near the zenith
    a wire a third of a pixel wide, which covers several columns of a row there, is thin
    again, and the reconstruction's ``thin_width_deg`` (the policy's width times the widest
    pixel, the equator's) still bounds every thin feature's angular width.

    Parameters
    ----------
    sky_mask : array_like of bool, shape (H, W)
        A full-width panorama, the top row at the zenith (``H <= W / 2``).
    thin_px : int
        Largest width, in pixels of the equator, of a structure counted as L-band transparent
        (0: no change).

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
    h, w = sky.shape
    lat = np.radians(equirect_row_lat_deg(h, w))
    if thin_px == 0:
        return sky.copy()
    ob = ~sky
    px = 2.0 * np.pi / w
    # across: the obstacle at the samples j = -thin_px .. thin_px along the east-west
    # geodesic (distance j * px; latitude asin(sin(lat) cos t), longitude step
    # atan2(sin t, cos(lat) cos t) from the pixel's)
    cols = np.arange(w)[None, :]
    samples = []
    for j in range(-thin_px, thin_px + 1):
        t = j * px
        lat_j = np.arcsin(np.sin(lat) * np.cos(t))
        row_j = np.clip(np.round((np.pi / 2 - lat_j) / px - 0.5), 0, h - 1).astype(int)
        dcol = np.round(np.arctan2(np.sin(t), np.cos(lat) * np.cos(t)) / px).astype(int)
        samples.append(ob[row_j[:, None], (cols + dcol[:, None]) % w])
    keep_h = np.zeros_like(ob)
    for start in range(thin_px + 1):  # windows of thin_px + 1 samples holding the pixel
        keep_h |= np.logical_and.reduce(samples[start : start + thin_px + 1])
    # along the meridians: a run from the top edge goes on down the opposite column
    run_v, top, bottom = _column_runs(ob)
    opposite = (np.arange(w) + w // 2) % w
    through_pole = top & top[0][opposite][None, :]  # both columns' runs reach the zenith row
    run_v = np.where(through_pole, run_v + run_v[0][opposite][None, :], run_v)
    keep_v = bottom | (run_v > thin_px)
    return np.asarray(sky | (ob & ~(keep_h & keep_v)))


def _runs_1d(ob: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Length of the run of True along the last axis that each True pixel lies in (0 at False
    pixels), rows independent and not wrapped."""
    n, m = ob.shape
    padded = np.zeros((n, m + 2), bool)
    padded[:, 1:-1] = ob
    d = np.diff(padded.ravel().astype(np.int8))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    lengths = stops - starts
    out = np.zeros(n * (m + 2), np.int64)
    out[np.flatnonzero(padded.ravel())] = np.repeat(lengths, lengths)
    return out.reshape(n, m + 2)[:, 1:-1]


def _column_runs(
    ob: NDArray[np.bool_],
) -> tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.bool_]]:
    """Run lengths down the columns, and whether each pixel's run reaches the top / bottom
    row."""
    run = _runs_1d(np.ascontiguousarray(ob.T)).T
    h = ob.shape[0]
    r = np.arange(h)[:, None]
    # a run reaching the top row holds rows 0 .. run - 1 there; one reaching the bottom,
    # rows h - run .. h - 1
    top = ob & ob[0][None, :] & (r < run[0][None, :])
    bottom = ob & ob[-1][None, :] & (r >= h - run[-1][None, :])
    return run, top, bottom
