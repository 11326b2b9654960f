"""Tests of predisat.sky.features on images drawn here with known properties."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.sky.features import FEATURE_NAMES, image_features, working_image, working_size

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


def _reference_features(img: np.ndarray) -> np.ndarray:
    """:func:`image_features` as written before 2026-12-03 (strided channel views)."""
    import cv2

    h, w = img.shape[:2]
    lab = cv2.cvtColor(img, cv2.COLOR_BGR2LAB).astype(np.float32)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV).astype(np.float32)
    bgr = img.astype(np.float32)
    lum = lab[..., 0]
    chan = cv2.split(img)
    total = bgr[..., 0] + bgr[..., 1] + bgr[..., 2] + 1.0
    blueness = (bgr[..., 0] - bgr[..., 2]) / total
    darkest = cv2.min(cv2.min(chan[0], chan[1]), chan[2])
    dark = cv2.erode(darkest, np.ones((3, 3), np.uint8)).astype(np.float32) / 255.0
    p99 = float(np.percentile(lum, 99)) + 1.0
    grad = np.hypot(cv2.Sobel(lum, cv2.CV_32F, 1, 0, ksize=3),
                    cv2.Sobel(lum, cv2.CV_32F, 0, 1, ksize=3))  # fmt: skip
    g1, g2, g4 = (np.log1p(cv2.GaussianBlur(grad, (0, 0), s)) for s in (1.0, 2.0, 4.0))
    stds = []
    for k in (5, 11):
        m, m2 = cv2.blur(lum, (k, k)), cv2.blur(lum * lum, (k, k))
        stds.append(np.log1p(np.sqrt(np.maximum(m2 - m * m, 0.0))))
    lap = np.log1p(cv2.GaussianBlur(np.abs(cv2.Laplacian(lum, cv2.CV_32F, ksize=3)), (0, 0), 1.0))
    top = max(1, h // 4)
    cand_l, cand_g = lum[:top], g2[:top]
    smooth = cand_g <= np.quantile(cand_g, 0.3)
    bright = cand_l >= np.quantile(cand_l[smooth], 0.5) if smooth.any() else smooth
    pick = smooth & bright
    ref = np.median(lab[:top][pick], axis=0) if pick.any() else lab[:top].reshape(-1, 3).mean(0)
    dlab = lab - ref
    de_ref = np.sqrt(dlab[..., 0] ** 2 + dlab[..., 1] ** 2 + dlab[..., 2] ** 2) / 100.0
    lb8 = cv2.GaussianBlur(lum, (0, 0), 8.0)
    bb8 = cv2.GaussianBlur(lab[..., 2], (0, 0), 8.0)
    dl_dy = cv2.Sobel(cv2.GaussianBlur(lum, (0, 0), 4.0), cv2.CV_32F, 0, 1, ksize=3) / 8.0
    rows = np.broadcast_to(np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None], (h, w))
    shifted = np.vstack([np.zeros((3, w), np.float32), g1[:-3]]) if h > 3 else g1 * 0
    above_mean = np.cumsum(shifted, axis=0) / np.arange(1, h + 1, dtype=np.float32)[:, None]
    above_max = np.maximum.accumulate(cv2.GaussianBlur(shifted, (0, 0), 1.0), axis=0)
    feats = [
        lum / 255.0, (lab[..., 1] - 128.0) / 64.0, (lab[..., 2] - 128.0) / 64.0,
        hsv[..., 1] / 255.0, hsv[..., 2] / 255.0, blueness, dark, lum / p99, de_ref,
        g1, g2, g4, stds[0], stds[1], lap,
        lb8 / 255.0, (bb8 - 128.0) / 64.0, dl_dy / 255.0 * 8.0, rows, above_mean, above_max,
    ]  # fmt: skip
    return np.asarray(cv2.merge([np.asarray(f, np.float32) for f in feats]), np.float32)


def test_features_are_those_of_the_strided_channel_code_bit_for_bit() -> None:
    """Contiguous channels since 2026-12-03: the same values as the strided views gave."""
    import cv2

    rng = np.random.default_rng(12)
    for k in range(30):
        h, w = (int(v) for v in rng.integers(2, 90, 2))
        img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        if k % 2:  # smooth regions and edges, as in a photo
            img = cv2.GaussianBlur(img, (0, 0), float(rng.uniform(1.0, 6.0)))
        np.testing.assert_array_equal(image_features(img), _reference_features(img))
