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
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import ArrayLike

from predisat.sky.perceptron import SkyModel
from predisat.sky.segment import SkyOptions, SkySegmentation, segment_sky
from predisat.sky.skyline import skyline_from_mask

__all__ = ["PANORAMA_BAND_SHARE", "segment_panorama"]

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
        The panorama (columns wrap around: column 0 follows column W - 1).
    options, classifier
        As for :func:`predisat.sky.segment.segment_sky` (``fisheye`` must be False).
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
    thin = np.zeros((h, w), bool)  # sky the thin-structure policy made (docs/reconstruction.md)
    any_thin = False
    for a, b in itertools.pairwise(edges):
        cols = np.arange(a - pad, b + pad) % w
        seg = segment_sky(np.ascontiguousarray(band[:, cols]), opt, classifier)
        sky[:rows, a:b] = seg.sky_mask[:, pad : pad + (b - a)]
        conf[a:b] = seg.confidence[pad : pad + (b - a)]
        if seg.thin_mask is not None:
            thin[:rows, a:b] = seg.thin_mask[:, pad : pad + (b - a)]
            any_thin = True
    valid = np.ones((h, w), bool)
    return SkySegmentation(
        sky_mask=sky, skyline_row=skyline_from_mask(sky, valid), confidence=conf,
        valid_mask=valid, thin_mask=thin if any_thin else None,
    )  # fmt: skip
