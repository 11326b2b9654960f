"""Tests of predisat.segmentation on scenes drawn here with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.segmentation import (
    SkyOptions,
    fisheye_valid_mask,
    mask_above_skyline,
    remove_thin_obstacles,
    segment_sky,
    skyline_confidence,
    skyline_from_mask,
)

H, W = 240, 320


def _sky_gradient(rng: np.random.Generator) -> np.ndarray:
    """A blue sky brightening toward the horizon (bottom), with mild sensor noise (BGR)."""
    t = np.linspace(0.0, 1.0, H)[:, None, None]
    top = np.array([200.0, 140.0, 90.0])  # B, G, R: deep blue
    bottom = np.array([235.0, 215.0, 190.0])  # pale
    img = top + (bottom - top) * t + np.zeros((1, W, 1))
    return img + rng.normal(0.0, 1.5, img.shape)


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Sky, a textured building, a textured mast and a 1 px wire; truth: wire counts as sky."""
    rng = np.random.default_rng(seed)
    img = _sky_gradient(rng)
    obstacle = np.zeros((H, W), bool)
    obstacle[150:, :] = True  # ground / wall band
    obstacle[80:, 40:130] = True  # building
    obstacle[30:, 220:232] = True  # mast, 12 px wide
    tex = 60 + 40 * rng.random((H, W, 3))
    img[obstacle] = tex[obstacle]
    img[60, :] = (40, 40, 40)  # a 1 px catenary wire across the sky
    img[60, 220:232] = tex[60, 220:232]
    return np.clip(img, 0, 255).astype(np.uint8), ~obstacle


def test_segment_synthetic_scene_iou_and_thin_wire() -> None:
    img, truth = _scene()
    seg = segment_sky(img)
    iou = (seg.sky_mask & truth).sum() / (seg.sky_mask | truth).sum()
    assert iou > 0.98
    # the wire (1 px) is L-band transparent: counted as sky away from the mast
    assert seg.sky_mask[60, 150:210].mean() > 0.95
    # the 12 px mast stays an obstacle
    assert not seg.sky_mask[40:140, 222:230].any()


def test_skyline_rows_match_drawn_obstacles() -> None:
    img, truth = _scene(1)
    seg = segment_sky(img)
    expected = skyline_from_mask(truth)
    assert seg.skyline_row.shape == (W,)
    err = np.abs(seg.skyline_row - expected)
    assert np.median(err) <= 1.0
    assert np.percentile(err, 95) <= 2.0
    assert np.all((seg.confidence >= 0) & (seg.confidence <= 1))
    # a sharp blue/grey boundary is confident
    assert np.median(seg.confidence[140:200]) > 0.8


def test_skyline_convention_on_hand_built_mask() -> None:
    sky = np.ones((10, 4), bool)
    sky[6:, 0] = False  # obstacle from row 6 down
    sky[2:4, 1] = False  # floating deck above sky: skyline is its top
    sky[:, 2] = False  # all obstacle
    # column 3 all sky
    s = skyline_from_mask(sky)
    np.testing.assert_array_equal(s, [5.5, 1.5, -0.5, 9.5])
    above = mask_above_skyline(s, 10)
    assert above[:6, 0].all() and not above[6:, 0].any()
    # the sky under the deck in column 1 is conservatively blocked
    assert above[:2, 1].all() and not above[2:, 1].any()
    assert not above[:, 2].any() and above[:, 3].all()


def test_skyline_ignores_invalid_pixels() -> None:
    sky = np.ones((6, 3), bool)
    valid = np.ones((6, 3), bool)
    valid[:2, 0] = False
    sky[:2, 0] = False  # outside the lens circle: neither sky nor obstacle
    valid[:, 2] = False
    s = skyline_from_mask(sky, valid)
    assert s[0] == 5.5 and s[1] == 5.5 and np.isnan(s[2])


def test_thin_policy_removes_wires_keeps_masts_and_corners() -> None:
    sky = np.ones((60, 60), bool)
    sky[40:, :] = False  # ground
    sky[10:40, 5:25] = False  # a block with sharp corners
    sky[20:22, 25:60] = False  # 2 px horizontal wire
    sky[0:40, 45:47] = False  # 2 px vertical pole
    sky[0:40, 33:41] = False  # 8 px mast
    diag = np.zeros_like(sky)
    for i in range(0, 10):
        diag[i, 48 + i] = diag[i, 49 + i] = True
    sky &= ~diag
    out = remove_thin_obstacles(sky, 3)
    assert out[20:22, 42:44].all()  # wire gone
    assert out[5:15, 45:47].all()  # thin pole gone
    assert out[diag].all()  # diagonal wire gone
    assert not out[0:40, 33:41].any()  # mast kept
    assert not out[10:40, 5:25].any()  # block kept, corners included
    assert not out[40:, :].any()
    np.testing.assert_array_equal(remove_thin_obstacles(sky, 0), sky)


def test_fisheye_valid_mask_and_option() -> None:
    m = fisheye_valid_mask((101, 101), margin=0.0)
    yy, xx = np.mgrid[:101, :101]
    np.testing.assert_array_equal(m, (xx - 50) ** 2 + (yy - 50) ** 2 < 50.5**2)
    rng = np.random.default_rng(3)
    img = np.full((200, 200, 3), 255, np.uint8)  # white outside the circle, like fisheye_hk
    inside = fisheye_valid_mask((200, 200), margin=0.0)
    yy, xx = np.mgrid[:200, :200]
    r = np.hypot(yy - 99.5, xx - 99.5)
    sky = inside & (r < 60)
    img[inside] = (90 + 50 * rng.random((int(inside.sum()), 3))).astype(np.uint8)  # buildings
    img[sky] = (230, 190, 150)
    seg = segment_sky(img, SkyOptions(fisheye=True))
    assert not (seg.sky_mask & ~seg.valid_mask).any()
    iou = (seg.sky_mask & sky).sum() / (seg.sky_mask | sky).sum()
    assert iou > 0.95


def test_confidence_low_for_grey_on_grey() -> None:
    sky = np.ones((60, 40), bool)
    sky[30:, :] = False
    img = np.full((60, 40, 3), 200, np.uint8)
    img[30:, :20] = 30  # strong contrast on the left half, none on the right
    conf = skyline_confidence(img, sky, skyline_from_mask(sky))
    assert conf[:20].min() > 0.9 and conf[20:].max() < 0.1


def test_segment_rejects_bad_input_and_does_not_mutate() -> None:
    with pytest.raises(ValueError, match="image_bgr"):
        segment_sky(np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        segment_sky(np.zeros((20, 20, 3), np.float32))
    with pytest.raises(ValueError, match="thin_px"):
        SkyOptions(thin_px=-1)
    img, _ = _scene(2)
    before = img.copy()
    segment_sky(img)
    np.testing.assert_array_equal(img, before)


def test_all_obstacle_frame() -> None:
    rng = np.random.default_rng(4)
    img = (30 + 60 * rng.random((80, 100, 3))).astype(np.uint8)  # a dark tunnel wall
    seg = segment_sky(img)
    assert seg.sky_fraction < 0.05
    assert np.mean(seg.skyline_row == -0.5) > 0.9
