"""Tests of predisat.sky.lines: narrow obstacles a working-resolution classifier lost.

The scenes are drawn here with their truth; the classifier stand-in sees the frame only at a
working size (area-averaged), so a feature a few pixels wide disappears from its map exactly
as it does from the shipped models'. The grey-pixel rule (``SkyOptions.grey_sky_probability``,
tested in test_segment.py) is off here: the stand-in's probabilities are not a model's, and
the step under test is the lines'.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from predisat.sky.lines import line_width_px, lost_line_obstacles
from predisat.sky.panorama import segment_panorama
from predisat.sky.segment import SkyOptions, segment_sky, skyline_from_mask

H, W = 240, 320


def _opt(**kw: object) -> SkyOptions:
    """The learned method with the grey-pixel rule off (module docstring)."""
    return SkyOptions(method="learned", grey_sky_probability=0.5, **kw)  # type: ignore[arg-type]


class _CoarseClassifier:
    """Sky where the area-averaged working image is blue-bright: what a model at
    ``max_side_px`` sees of a frame (features narrower than a working pixel average away)."""

    def __init__(self, max_side_px: int = 48) -> None:
        self.max_side_px = max_side_px

    def predict_image(self, image_bgr: np.ndarray) -> np.ndarray:
        h, w = image_bgr.shape[:2]
        f = self.max_side_px / max(h, w)
        size = (max(1, round(w * f)), max(1, round(h * f)))
        small = cv2.resize(image_bgr, size, interpolation=cv2.INTER_AREA).astype(float)
        blue = small[..., 0] - small[..., 2]
        return np.asarray(np.clip((blue - 5.0) / 20.0, 0.0, 1.0), np.float32)


def _scene(seed: int, arm_px: int = 5, clouds: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Blue sky, a ground band, a mast with an arm of ``arm_px`` over the sky, and a free 2 px
    wire; truth: True where an obstacle is."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, H)[:, None, None]
    img = np.array([210.0, 150.0, 95.0]) + np.array([20.0, 55.0, 80.0]) * t + np.zeros((1, W, 1))
    if clouds:  # soft cloud texture: grey-white blobs a few to tens of pixels across
        noise = cv2.GaussianBlur(rng.normal(0.0, 1.0, (H, W)), (0, 0), 6.0)
        noise = cv2.GaussianBlur(noise, (0, 0), 2.0)
        cloud = np.clip((noise - noise.mean()) / noise.std(), 0, None)[..., None]
        img = img + cloud * (np.array([235.0, 235.0, 235.0]) - img) * 0.5
    img = img + rng.normal(0.0, 1.5, img.shape)
    obstacle = np.zeros((H, W), bool)
    obstacle[170:, :] = True  # ground
    obstacle[40:, 250:262] = True  # mast
    obstacle[50 : 50 + arm_px, 120:250] = True  # the arm, held by the mast
    grey = np.array([70.0, 72.0, 75.0])
    img[obstacle] = grey + rng.normal(0.0, 2.0, (int(obstacle.sum()), 3))
    img[100:102, 20:200] = grey  # a free wire: held by nothing, not an obstacle in the truth
    return np.clip(img, 0, 255).astype(np.uint8), obstacle


def test_an_arm_the_working_size_lost_comes_back_as_an_obstacle() -> None:
    img, obstacle = _scene(0)
    arm = np.zeros_like(obstacle)
    arm[50:55, 120:250] = True
    clf = _CoarseClassifier()
    off = segment_sky(img, _opt(line_contrast=0.0), clf)
    assert off.sky_mask[arm].mean() > 0.8  # the failure: the arm is sky at working size
    on = segment_sky(img, _opt(), clf)
    assert not on.sky_mask[arm].mean() > 0.1  # the arm is an obstacle again
    assert on.thin_mask is not None and not on.thin_mask[arm].any()  # and not called thin
    # its columns' skyline is the arm's top edge (row 50 - 0.5), as the truth's
    truth_line = skyline_from_mask(~obstacle)
    cols = np.arange(125, 245)
    assert np.all(on.skyline_row[cols] <= truth_line[cols] + 1.0)
    # nothing but the arm changed: the free wire and the open sky are as they were
    changed = off.sky_mask & ~on.sky_mask
    grown = cv2.dilate(obstacle.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert not (changed & ~grown).any()
    assert on.sky_mask[100:102, 30:190].all()


def test_a_free_wire_cloud_texture_and_a_thin_arm_stay_as_the_classifier_said() -> None:
    """Only lost features held by an obstacle and wider than the policy's width (plus a pixel
    of blur) come back: cloud texture, a free wire and an arm the policy calls thin do not."""
    clf = _CoarseClassifier()
    for seed in range(3):
        img, obstacle = _scene(seed, arm_px=2, clouds=True)
        off = segment_sky(img, _opt(line_contrast=0.0), clf)
        on = segment_sky(img, _opt(), clf)
        changed = off.sky_mask & ~on.sky_mask
        solid = obstacle.copy()
        solid[50:52, :250] = False  # the thin arm is no solid obstacle for the policy
        grown = cv2.dilate(solid.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        assert not (changed & ~grown).any()  # at most the mast's edge the classifier shaved
        assert off.thin_mask is not None and on.thin_mask is not None
        assert np.array_equal(on.thin_mask[48:54, 120:248], off.thin_mask[48:54, 120:248])


def test_restored_pixels_are_obstacles_of_rendered_frames(test_data) -> None:
    """On rendered frames with their renderer's labels (clouds, masts, wires), every pixel the
    step turns back into an obstacle is an obstacle (or a thin structure) of the label."""
    for stem in ("cloudy_right_000006", "cloudy_right_000012"):
        img = cv2.imread(str(test_data / "sky_synth" / f"{stem}.jpg"), cv2.IMREAD_COLOR)
        label = cv2.imread(str(test_data / "sky_synth" / f"{stem}_label.png"), 0)
        off = segment_sky(img, SkyOptions(line_contrast=0.0))
        on = segment_sky(img)
        restored = off.sky_mask & ~on.sky_mask
        near_obstacle = cv2.dilate((label < 255).astype(np.uint8), np.ones((3, 3), np.uint8))
        assert not (restored & (near_obstacle == 0)).any()


def test_a_panorama_gets_its_lost_arm_back_and_keeps_its_free_wires() -> None:
    """The 360-degree case that found the class: a cantilever arm over the antenna a few pixels
    wide in a half-resolution panorama; tiles' edges hold nothing."""
    h, w = 180, 360
    rng = np.random.default_rng(3)
    img = np.zeros((h, w, 3))
    img[:] = np.array([215.0, 160.0, 100.0]) + rng.normal(0.0, 1.5, (h, w, 3))
    obstacle = np.zeros((h, w), bool)
    obstacle[95:, :] = True  # ground below the horizon
    obstacle[30:, 100:106] = True  # a mast
    obstacle[32:36, 106:200] = True  # its arm, 4 px (2 deg), near the zenith
    grey = np.array([70.0, 72.0, 75.0])
    img[obstacle] = grey
    img[20:23, 220:350] = grey  # a free wire 3 px wide
    img = np.clip(img, 0, 255).astype(np.uint8)
    clf = _CoarseClassifier(48)
    # 1 deg per pixel: the pipeline's 0.7 deg thin width is one pixel (PipelineParams.thin_px)
    opt = _opt(thin_px=1)
    off = segment_panorama(img, replace(opt, line_contrast=0.0), clf)
    on = segment_panorama(img, opt, clf)
    arm = np.zeros_like(obstacle)
    arm[32:36, 110:196] = True
    assert off.sky_mask[arm].mean() > 0.8
    assert on.sky_mask[arm].mean() < 0.1
    assert np.array_equal(on.sky_mask[18:24, 225:345], off.sky_mask[18:24, 225:345])


def test_a_pole_standing_on_the_skyline_comes_back_flagged_thin() -> None:
    """A far pole a pixel wide rising from the ground, lost at the working size, comes back so
    that the thin-structure policy flags it (the reconstruction's Fresnel rule then decides
    by its distance); a squat dark blob on the ground does not, nor any pole in an upward
    fisheye photo, which has no "below"."""
    img, _ = _scene(4)
    grey = np.array([70, 72, 75], np.uint8)
    img[140:170, 60] = grey  # a pole 1 px wide, 30 px tall, on the ground at row 170
    img[164:170, 90:96] = grey  # a squat blob 6 x 6 on the ground
    clf = _CoarseClassifier()
    off = segment_sky(img, _opt(line_contrast=0.0), clf)
    on = segment_sky(img, _opt(), clf)
    assert off.sky_mask[140:168, 60].all() and off.thin_mask is not None
    assert not off.thin_mask[140:168, 60].any()  # the failure: plain sky, not flagged
    assert on.sky_mask[140:168, 60].all()  # still sky (thin) ...
    assert on.thin_mask is not None and on.thin_mask[140:168, 60].mean() > 0.9  # ... flagged
    assert np.array_equal(on.sky_mask[150:168, 85:100], off.sky_mask[150:168, 85:100])
    lost = lost_line_obstacles(img, off.sky_mask, off.valid_mask, 21, standing=False)
    assert not lost.standing.any()


def test_the_step_never_adds_sky_even_through_the_sky_gaps() -> None:
    """The sky gaps' colour model is the classifier's sky: restoring dark arms must not shift
    it so that foliage gaps of a colour near its edge turn into sky (found in review: 432 such
    pixels when the gaps were searched after the step)."""
    rng = np.random.default_rng(0)
    img = np.zeros((H, W, 3))
    img[:] = (215, 160, 100)
    img += rng.normal(0.0, 1.5, img.shape)
    obstacle = np.zeros((H, W), bool)
    obstacle[170:] = True
    obstacle[20:, 290:302] = True
    for r in range(30, 160, 12):
        obstacle[r : r + 5, 40:290] = True  # a comb of arms held by the mast
    img[obstacle] = (70, 72, 75)
    img[175:235, 20:280] = (40, 90, 50)  # foliage with gaps of a near-sky colour
    for r in range(180, 230, 15):
        for c in range(30, 270, 20):
            img[r : r + 3, c : c + 3] = (208, 162, 96)
    img = np.clip(img, 0, 255).astype(np.uint8)
    clf = _CoarseClassifier()
    opt = _opt(detect_gaps=True)
    on = segment_sky(img, opt, clf)
    off = segment_sky(img, replace(opt, line_contrast=0.0), clf)
    assert (off.sky_mask & ~on.sky_mask).any()  # the step restored arms
    assert not (on.sky_mask & ~off.sky_mask).any()  # and added no sky


def test_only_a_feature_resting_on_a_seen_obstacle_stands() -> None:
    """Upright streaks floating in the sky, in the middle or at the frame's edge, do not
    stand; one resting on the ground does; a squat blob on the ground does not."""
    img = np.zeros((80, 120, 3), np.uint8)
    img[:] = (220, 160, 100)
    img[60:] = (70, 72, 75)
    sky = np.ones((80, 120), bool)
    sky[60:] = False
    grey = (70, 72, 75)
    img[20:41, 30] = grey  # floating, middle
    img[20:41, 0] = grey  # floating, at the edge
    img[35:60, 80] = grey  # standing on the ground
    img[55:60, 100:106] = grey  # squat blob on the ground
    lost = lost_line_obstacles(img, sky, np.ones_like(sky), 9, standing=True)
    assert lost.standing[36:59, 80].all()
    assert not lost.standing[:, :2].any() and not lost.standing[:, 25:35].any()
    assert not lost.standing[:, 95:110].any()
    before = (img.copy(), sky.copy())
    lost_line_obstacles(img, sky, np.ones_like(sky), 9, standing=True)
    assert np.array_equal(img, before[0]) and np.array_equal(sky, before[1])  # untouched


def test_a_panorama_arm_across_the_seam_is_looked_at_whole() -> None:
    """The band wraps round: an arm held by a mast just left of the seam keeps its part right
    of it (columns 0..)."""
    h, w = 180, 360
    rng = np.random.default_rng(5)
    img = np.zeros((h, w, 3))
    img[:] = np.array([215.0, 160.0, 100.0]) + rng.normal(0.0, 1.5, (h, w, 3))
    grey = np.array([70.0, 72.0, 75.0])
    img[95:] = grey
    img[30:95, w - 16 : w - 10] = grey  # a mast left of the seam
    img[32:36, w - 10 :] = grey  # its arm, to the seam ...
    img[32:36, :60] = grey  # ... and on past it
    img = np.clip(img, 0, 255).astype(np.uint8)
    opt = _opt(thin_px=1)
    on = segment_panorama(img, opt, _CoarseClassifier(48))
    off = segment_panorama(img, replace(opt, line_contrast=0.0), _CoarseClassifier(48))
    assert off.sky_mask[32:36, 5:55].mean() > 0.8
    assert on.sky_mask[32:36, 5:55].mean() < 0.1


def test_an_edge_holds_a_feature_only_when_told() -> None:
    """A line cut by the image edge may be held out of the picture (a frame); in a panorama's
    band the edges are the seam and the zenith, which hold nothing."""
    img = np.zeros((60, 120, 3), np.uint8)
    img[:] = (220, 160, 100)
    img[20:24, :80] = (70, 72, 75)  # from the left edge into the sky
    img[50:, :] = (70, 72, 75)  # ground: an obstacle in view, not touching the line
    sky = np.ones((60, 120), bool)
    sky[50:] = False
    held = lost_line_obstacles(img, sky, np.ones_like(sky), 9).held
    free = lost_line_obstacles(img, sky, np.ones_like(sky), 9, edges_hold=False).held
    assert held[20:24, 2:78].all() and not held[:18].any() and not held[26:50].any()
    assert not free.any()


def test_line_width_follows_the_working_scale_and_guards() -> None:
    assert line_width_px((480, 640), 160) == 13  # four full pixels per working pixel
    assert line_width_px((100, 100), 160) == 5  # never below 5
    with pytest.raises(ValueError, match="work_side_px"):
        line_width_px((10, 10), 0)
    img = np.zeros((20, 20, 3), np.uint8)
    sky = np.ones((20, 20), bool)
    with pytest.raises(ValueError, match="width_px"):
        lost_line_obstacles(img, sky, sky, 4)
    with pytest.raises(ValueError, match="must match"):
        lost_line_obstacles(img, sky[:10], sky, 5)
    with pytest.raises(ValueError, match="contrast"):
        lost_line_obstacles(img, sky, sky, 5, contrast=0.0)
    with pytest.raises(ValueError, match="line_contrast"):
        SkyOptions(line_contrast=-1.0)
    before = sky.copy()
    lost_line_obstacles(img, sky, sky, 5)
    assert np.array_equal(sky, before)  # inputs untouched
