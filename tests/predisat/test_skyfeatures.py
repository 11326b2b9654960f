"""Tests of predisat.skyfeatures on images drawn here with known properties."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.skyfeatures import FEATURE_NAMES, image_features, working_image, working_size

F = {name: i for i, name in enumerate(FEATURE_NAMES)}


def test_working_size_keeps_aspect_and_never_enlarges() -> None:
    assert working_size((480, 640), 160) == (160, 120)
    assert working_size((600, 400, 3), 160) == (107, 160)
    assert working_size((100, 120), 160) == (120, 100)
    img = np.zeros((480, 640, 3), np.uint8)
    assert working_image(img, 160).shape == (120, 160, 3)
    with pytest.raises(ValueError, match="max_side_px"):
        working_size((10, 10), 4)


def test_shape_dtype_and_row_position() -> None:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (40, 60, 3)).astype(np.uint8)
    f = image_features(img)
    assert f.shape == (40, 60, len(FEATURE_NAMES)) and f.dtype == np.float32
    assert np.isfinite(f).all()
    np.testing.assert_allclose(f[:, 7, F["row_frac"]], np.linspace(0, 1, 40), atol=1e-6)


def test_colour_features_of_uniform_patches() -> None:
    img = np.zeros((30, 40, 3), np.uint8)
    img[:, :20] = (230, 160, 90)  # BGR: blue sky
    img[:, 20:] = (128, 128, 128)  # neutral grey
    f = image_features(img)
    blue, grey = f[15, 5], f[15, 35]
    # blueness = (B - R) / (B + G + R + 1), computed by hand
    assert blue[F["blueness"]] == pytest.approx((230 - 90) / (230 + 160 + 90 + 1), rel=1e-5)
    assert grey[F["blueness"]] == pytest.approx(0.0, abs=1e-6)
    # dark channel: min of RGB (uniform patch, away from the edge)
    assert blue[F["dark_channel"]] == pytest.approx(90 / 255, rel=1e-5)
    assert grey[F["hsv_s"]] == pytest.approx(0.0, abs=1e-6)
    assert blue[F["hsv_s"]] == pytest.approx((230 - 90) / 230, abs=0.01)
    assert blue[F["lab_b"]] < 0 < blue[F["blueness"]]  # Lab b < 128: blue
    # flat patches have no texture away from the boundary
    for name in ("grad_s1", "std_5", "laplacian"):
        assert blue[F[name]] == pytest.approx(0.0, abs=1e-3)


def test_texture_grows_with_noise_and_texture_above_is_causal() -> None:
    rng = np.random.default_rng(1)
    h, w = 80, 60
    img = np.full((h, w, 3), 200, np.uint8)
    img[40:50] = rng.integers(0, 256, (10, w, 3)).astype(np.uint8)  # a textured band
    f = image_features(img)
    assert f[45, 30, F["grad_s1"]] > 1.0 and f[10, 30, F["grad_s1"]] < 0.1
    assert f[45, 30, F["std_11"]] > f[10, 30, F["std_11"]] + 1.0
    # nothing textured above row 30; the band lies above row 70
    assert f[30, 30, F["tex_above_max"]] < 0.05
    assert f[70, 30, F["tex_above_max"]] > 1.0
    assert f[70, 30, F["tex_above_mean"]] > f[30, 30, F["tex_above_mean"]] + 0.1


def test_sky_reference_distance_is_small_on_the_top_colour() -> None:
    img = np.zeros((60, 60, 3), np.uint8)
    img[:30] = (220, 180, 140)
    img[30:] = (40, 90, 60)  # green-dark ground
    f = image_features(img)
    assert f[5, 30, F["de_sky_ref"]] < 0.02
    assert f[50, 30, F["de_sky_ref"]] > 0.3


def test_rejects_bad_input_and_does_not_mutate() -> None:
    with pytest.raises(ValueError, match="small_bgr"):
        image_features(np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError, match="small_bgr"):
        image_features(np.zeros((10, 10, 3), np.float32))
    img = np.random.default_rng(2).integers(0, 256, (20, 30, 3)).astype(np.uint8)
    before = img.copy()
    image_features(img)
    working_image(img, 16)
    np.testing.assert_array_equal(img, before)
