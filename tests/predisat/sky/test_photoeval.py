"""Tests of predisat.sky.photoeval on tiny folders generated here."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from predisat.sky.naive import naive_sky_mask
from predisat.sky.photoeval import (
    UNSAFE_COLUMN_FRACTION,
    evaluate_folder,
    find_pairs,
    safety_table,
    sky_iou,
    sky_safety_counts,
    skyline_elevation_deg,
)


def test_sky_iou_against_numpy_sets() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.random((30, 40)) > 0.5, rng.random((30, 40)) > 0.3
    ia = {tuple(p) for p in np.argwhere(a)}
    ib = {tuple(p) for p in np.argwhere(b)}
    assert sky_iou(a, b) == pytest.approx(len(ia & ib) / len(ia | ib))
    valid = np.zeros((30, 40), bool)
    valid[:, :20] = True
    iv = {p for p in ia if p[1] < 20}, {p for p in ib if p[1] < 20}
    assert sky_iou(a, b, valid) == pytest.approx(len(iv[0] & iv[1]) / len(iv[0] | iv[1]))
    assert sky_iou(np.zeros((3, 3), bool), np.zeros((3, 3), bool)) == 1.0
    with pytest.raises(ValueError, match="shape"):
        sky_iou(a, b[:, :10])


class _Pinhole:
    """Distortion-free pinhole: analytic rays."""

    def __init__(self, f: float, cx: float, cy: float) -> None:
        self.f, self.cx, self.cy = f, cx, cy

    def pixel_to_ray(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        r = np.stack([(u - self.cx) / self.f, (v - self.cy) / self.f, np.ones_like(u)], -1)
        return r / np.linalg.norm(r, axis=-1, keepdims=True)


def test_skyline_elevation_of_level_camera() -> None:
    cam = _Pinhole(100.0, 2.0, 50.0)
    # camera x right, y down, z forward -> vehicle x forward, y left, z up
    r_cv = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    rows = np.array([50.0, -50.0, np.nan, 150.0, 50.0])
    el = skyline_elevation_deg(rows, cam, r_cv)
    u = np.arange(5.0) - 2.0
    expected = np.degrees(np.arctan2(-(rows - 50.0) / 100.0, np.hypot(1.0, u / 100.0)))
    np.testing.assert_allclose(el[[0, 1, 3, 4]], expected[[0, 1, 3, 4]], atol=1e-9)
    assert np.isnan(el[2])


def _write_folder(root: Path, img_dir: str, mask_dir: str, n: int) -> None:
    (root / img_dir).mkdir(parents=True)
    (root / mask_dir).mkdir(parents=True)
    rng = np.random.default_rng(1)
    for i in range(n):
        img = np.zeros((90, 120, 3), np.uint8)
        img[:] = (230, 180, 120)
        top = 40 + 5 * i
        img[top:] = (50 + 60 * rng.random((90 - top, 120, 3))).astype(np.uint8)
        mask = np.zeros((90, 120), np.uint8)
        mask[:top] = 250  # soft masks are cut at 128
        cv2.imwrite(str(root / img_dir / f"im{i}.jpg"), img)
        cv2.imwrite(str(root / mask_dir / f"im{i}.png"), mask)


def test_evaluate_generic_folder(tmp_path: Path) -> None:
    data = tmp_path / "toy"
    _write_folder(data, "images", "masks", 3)
    out = tmp_path / "out"
    ev = evaluate_folder(data, out_dir=out, progress=False)
    assert ev.layout == "generic"
    assert len(ev.table) == 3 and set(ev.table["name"]) == {"im0", "im1", "im2"}
    assert (ev.table["iou"] > 0.9).all()
    assert ev.summary.iloc[-1]["group"] == "all"
    assert ev.summary.iloc[-1]["n_images"] == 3
    for key in ("table", "summary", "sheet"):
        assert ev.files[key].is_file()
    sheet = cv2.imread(str(ev.files["sheet"]))
    assert sheet is not None
    # the legend strip under the cases shows the overlay's false-sky and missed-sky colours
    legend = sheet[-18:].reshape(-1, 3)
    for bgr in ((0, 0, 255), (255, 0, 0)):
        assert (legend == bgr).all(axis=1).sum() >= 50


class _AllSky:
    """A stand-in probability model that calls every pixel sky."""

    max_side_px = 32

    def predict_image(self, image_bgr: np.ndarray) -> np.ndarray:
        h, w = image_bgr.shape[:2]
        return np.ones((max(1, h * 32 // max(h, w)), max(1, w * 32 // max(h, w))), np.float32)


def test_evaluate_folder_uses_the_given_classifier(tmp_path: Path) -> None:
    data = tmp_path / "toy"
    _write_folder(data, "images", "masks", 2)
    ev = evaluate_folder(data, progress=False, method="learned", classifier=_AllSky())
    # all predicted sky: IoU = true sky share (rows 0..top of 90)
    assert np.allclose(ev.table["iou"], [40 / 90, 45 / 90], atol=1e-9)
    assert np.allclose(ev.table["pred_sky_fraction"], 1.0)


def test_find_pairs_layouts_and_errors(tmp_path: Path) -> None:
    _write_folder(tmp_path / "a", "original", "mask", 1)
    _write_folder(tmp_path / "b", "raw_images", "mask_images", 2)
    assert find_pairs(tmp_path / "a")[0] == "ade20k"
    layout, pairs = find_pairs(tmp_path / "b")
    assert layout == "fisheye_hk" and len(pairs) == 2
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="empty"):
        find_pairs(tmp_path / "empty")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        evaluate_folder(tmp_path / "missing", progress=False)


@pytest.mark.shared
def test_ade20k_excerpt_reaches_reasonable_iou(shared_data: Path) -> None:
    ev = evaluate_folder(shared_data / "sky" / "ade20k", progress=False, limit=5)
    assert len(ev.table) == 5
    assert ev.table["iou"].median() > 0.8


class _NoSky:
    """A stand-in probability model that calls every pixel obstacle."""

    max_side_px = 32

    def predict_image(self, image_bgr: np.ndarray) -> np.ndarray:
        return np.zeros_like(_AllSky().predict_image(image_bgr))


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    out = tmp_path_factory.mktemp("synth")
    generate_survey(demo_track(), 3000.0, 3020.0, sky="clear", seed=5, out_dir=out,
                    progress=False)
    return out


def _true_elevations_deg(root: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Per column: the true skyline's elevation and that of the frame's bottom edge (deg).

    Written out from the label image, the camera's rays and the mount's rotation, without
    ``skyline_from_mask`` or ``skyline_elevation_deg``.
    """
    from predisat.survey import Survey

    label = cv2.imread(str(root / "truth" / "labels" / f"{name}.png"), cv2.IMREAD_GRAYSCALE)
    h, w = label.shape
    obstacle = label < 128
    first = np.where(obstacle.any(0), obstacle.argmax(0), h).astype(float)
    side = Survey.load(root / "survey", check_images=False).cameras[name.split("_")[0]]
    r = side.mount.camera_to_vehicle()

    def elev(v: np.ndarray) -> np.ndarray:
        ray = side.camera.pixel_to_ray(np.arange(w, dtype=float), v) @ r.T
        return np.degrees(np.arcsin(ray[:, 2] / np.linalg.norm(ray, axis=1)))

    return elev(first - 0.5), elev(np.full(w, h - 0.5))


def test_synthetic_unsafe_columns(synth_dir: Path) -> None:
    all_sky = evaluate_folder(synth_dir, progress=False, method="learned", classifier=_AllSky())
    no_sky = evaluate_folder(synth_dir, progress=False, method="learned", classifier=_NoSky())
    assert all_sky.layout == "synthetic" and len(all_sky.table) >= 4
    # every skyline read at the bottom edge is too low wherever the true one is 1 deg higher
    for row in all_sky.table.itertuples():
        true_deg, bottom_deg = _true_elevations_deg(synth_dir, row.name)
        assert row.skyline_low_1deg_columns == np.count_nonzero(bottom_deg - true_deg < -1.0)
    total = all_sky.summary.set_index("group").loc["all"]
    assert total["skyline_low_1deg_columns"] == all_sky.table["skyline_low_1deg_columns"].sum()
    assert total["skyline_low_1deg_columns"] > 0
    assert total["skyline_low_1deg_share"] == pytest.approx(
        total["skyline_low_1deg_columns"] / total["n_skyline_columns"])
    # a skyline at the top edge is never too low
    assert (no_sky.table["skyline_low_1deg_columns"] == 0).all()
    assert no_sky.summary.set_index("group").loc["all"]["n_skyline_columns"] > 0


def test_safety_counts_against_loops() -> None:
    rng = np.random.default_rng(3)
    h, w = 200, 30
    truth = np.zeros((h, w), bool)
    truth[:80] = True
    pred = truth.copy()
    pred[80:82, :10] = True  # 2 rows of false sky: 1 % of 200 -> unsafe columns 0-9
    pred[80, 10:20] = True  # 1 row: below 1 %, not unsafe
    pred[:5, 25:] = False  # missed sky
    pred |= rng.random((h, w)) > 0.999  # a few specks
    valid = np.ones((h, w), bool)
    valid[:, -2:] = False  # two columns outside the lens
    c = sky_safety_counts(pred, truth, valid)
    fs = [(r, k) for r in range(h) for k in range(w - 2) if pred[r, k] and not truth[r, k]]
    assert c["false_sky_px"] == len(fs)
    assert c["non_sky_px"] == (h - 80) * (w - 2)
    per_col = [sum(1 for r, k in fs if k == col) for col in range(w - 2)]
    assert c["unsafe_columns"] == sum(n >= UNSAFE_COLUMN_FRACTION * h for n in per_col)
    assert c["unsafe_columns"] >= 10 and c["n_columns"] == w - 2
    missed = sum(1 for r in range(80) for k in range(w - 2) if truth[r, k] and not pred[r, k])
    assert c["missed_sky_px"] == missed and c["true_sky_px"] == 80 * (w - 2)
    with pytest.raises(ValueError, match="one shape"):
        sky_safety_counts(pred, truth[:10], valid)


def test_naive_baseline_is_otsu_on_blue_connected_to_the_top() -> None:
    img = np.full((60, 80, 3), 60, np.uint8)
    img[:25] = (230, 190, 150)  # bright blue-ish sky band
    img[40:48, 30:50] = (235, 195, 155)  # a sky-coloured patch not touching the top
    valid = np.ones((60, 80), bool)
    up = naive_sky_mask(img, valid, upright=True)
    assert up[:24].all() and not up[26:].any()  # the patch is cut off from the top
    fe = naive_sky_mask(img, valid, upright=False)
    assert fe[41:47, 31:49].all()  # a fisheye keeps any region of >= 1 % of the circle
    half = valid.copy()
    half[:, 40:] = False
    assert not naive_sky_mask(img, half, upright=True)[:, 40:].any()
    with pytest.raises(ValueError, match="valid_mask"):
        naive_sky_mask(img, valid[:10], upright=True)


def test_evaluation_reports_safety_beside_the_naive_baseline(tmp_path: Path) -> None:
    data = tmp_path / "toy"
    _write_folder(data, "images", "masks", 2)
    ev = evaluate_folder(data, out_dir=tmp_path / "out", progress=False, method="learned",
                         classifier=_AllSky())  # fmt: skip
    # every pixel sky: all non-sky is false sky, every column unsafe, no sky missed
    row = ev.summary.iloc[-1]
    assert row["false_sky_pct"] == pytest.approx(100.0)
    assert row["unsafe_columns_pct"] == pytest.approx(100.0)
    assert row["missed_sky_pct"] == pytest.approx(0.0)
    # the naive baseline finds the blue band of the toy images (no false sky there)
    assert row["naive_false_sky_pct"] < 5.0 and row["naive_missed_sky_pct"] < 5.0
    tab = safety_table(ev.summary)
    assert list(tab["method"][:2]) == ["default", "naive"]
    assert tab["false_sky_pct"].iloc[0] > tab["false_sky_pct"].iloc[1]
    assert row["frames_per_cpu_s"] > 0 and row["decode_frames_per_cpu_s"] > 0
    assert ev.files["unsafe_sheet"].is_file()
    assert "Safety first" in ev.files["summary"].read_text()
