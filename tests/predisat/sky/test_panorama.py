"""Sky segmentation of 360-degree panoramas: the sky band above a drawn skyline, across the
seam where the image's edges meet."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.sky.panorama import PANORAMA_BAND_SHARE, segment_panorama
from predisat.sky.segment import SkyOptions

H, W = 180, 360  # 1 deg per pixel, full sphere


def _panorama() -> tuple[np.ndarray, np.ndarray]:
    """A drawn panorama (BGR) and its true sky: a blue sky graded toward the horizon above a
    rolling green skyline, and a grey building standing across the seam (columns 340 to 19)."""
    rng = np.random.default_rng(5)
    rows = np.arange(H)[:, None]
    cols = np.arange(W)[None, :]
    skyline = 70.0 + 12.0 * np.sin(2 * np.pi * cols / W * 3)
    seam = (cols >= 340) | (cols < 20)
    skyline = np.where(seam, 30.0, skyline)
    sky = rows < skyline
    t = rows / H
    img = np.empty((H, W, 3), float)
    img[..., 0] = 235 - 60 * t  # B
    img[..., 1] = 190 - 20 * t
    img[..., 2] = 150 + 40 * t  # R
    green = np.stack([40 + 25 * rng.random((H, W)), 95 + 40 * rng.random((H, W)),
                      45 + 25 * rng.random((H, W))], -1)  # fmt: skip
    grey = np.stack([100 + 30 * rng.random((H, W))] * 3, -1)
    obstacle = np.where(seam[..., None], grey, green)
    img = np.where(sky[..., None], img + rng.normal(0, 2, img.shape), obstacle)
    return np.clip(img, 0, 255).astype(np.uint8), sky


@pytest.mark.parametrize("method", ["learned", "ensemble"])
def test_panorama_sky_band_follows_the_skyline_across_the_seam(method: str) -> None:
    img, truth = _panorama()
    seg = segment_panorama(img, SkyOptions(method=method))
    assert seg.sky_mask.shape == (H, W) and seg.confidence.shape == (W,)
    band = round(PANORAMA_BAND_SHARE * H)
    assert not seg.sky_mask[band:].any()  # below the band: never sky
    assert float(np.mean(seg.sky_mask == truth)) > 0.97
    # the building across the seam is an obstacle on both edges of the image
    for cols in (slice(342, 360), slice(0, 18)):
        assert not seg.sky_mask[35:60, cols].any()
        assert seg.skyline_row[cols] == pytest.approx(29.5, abs=3.0)


def test_panorama_bad_arguments_are_named() -> None:
    img, _ = _panorama()
    with pytest.raises(ValueError, match="not an upward fisheye"):
        segment_panorama(img, SkyOptions(fisheye=True))
    with pytest.raises(ValueError, match="band_rows"):
        segment_panorama(img, band_rows=4)
    with pytest.raises(ValueError, match="uint8"):
        segment_panorama(img.astype(float))


def test_panorama_keeps_the_sky_the_thin_policy_made() -> None:
    """A 1 px wire across the sky: the panorama's thin mask is the policy's sky (so that the
    reconstruction's Fresnel rule sees it), and empty without the policy."""
    img, _ = _panorama()
    wired = img.copy()
    wired[20, 60:300] = (40, 40, 40)  # a dark wire 1 px thick, well inside the sky band
    seg = segment_panorama(wired, SkyOptions(method="learned"))
    raw = segment_panorama(wired, SkyOptions(method="learned", thin_px=0))
    assert seg.thin_mask is not None
    assert np.array_equal(seg.thin_mask, seg.sky_mask & ~raw.sky_mask)
    assert seg.thin_mask[19:22, 60:300].any(axis=0).mean() > 0.9
    assert raw.thin_mask is None or not raw.thin_mask.any()
