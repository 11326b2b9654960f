"""Tests of predisat.camera.models and predisat.camera.calibfile against OpenCV and analytic
geometry."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from predisat.camera.models import (
    CalibrationError,
    CameraModel,
    Mount,
    default_camera,
    vehicle_to_enu,
)
from predisat.geodesy import enu_to_azel

# Realistic intrinsics (numbers from published calibrations: EuRoC cam0, a PointGrey 800x600,
# the RealSense T265 and TUM-VI fisheyes), typed in as test values.
PINHOLES = [
    CameraModel("euroc", "pinhole", 752, 480, 458.654, 457.296, 367.215, 248.375,
                (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05)),
    CameraModel("pointgrey", "pinhole", 800, 600, 538.63, 539.723, 457.698, 297.003,
                (-0.30678, 0.0825017, 0.0028784, -0.00015829, 0.0)),
    CameraModel("k3", "pinhole", 640, 480, 400.0, 401.0, 322.0, 236.0,
                (-0.2, 0.05, 0.001, -0.0005, -0.004)),
    default_camera("pinhole"),
]  # fmt: skip
FISHEYES = [
    CameraModel("t265", "fisheye", 848, 800, 284.9501953125, 285.115295410156, 420.500213623047,
                400.738098144531,
                (-0.00530046410858631, 0.0423333682119846, -0.03949885815382, 0.00682387687265873)),
    CameraModel("tumvi", "fisheye", 512, 512, 190.978477, 190.973307, 254.931706, 256.897442,
                (0.003482389402, 0.000715034845, -0.002053236141, 0.000202936736)),
    default_camera("fisheye"),
]  # fmt: skip
ALL = PINHOLES + FISHEYES


def _random_rays(n: int, max_angle_deg: float, seed: int = 0) -> np.ndarray:
    """Unit rays within a cone about +z."""
    rng = np.random.default_rng(seed)
    theta = np.radians(max_angle_deg) * np.sqrt(rng.random(n))
    phi = rng.uniform(0, 2 * np.pi, n)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def _rays_in_image(cam: CameraModel, n: int = 3000) -> np.ndarray:
    """Random rays whose OpenCV projection lands in the image (found via our unprojection of
    random pixels, then re-checked against OpenCV below)."""
    rng = np.random.default_rng(1)
    u = rng.uniform(-0.5, cam.width_px - 0.5, n)
    v = rng.uniform(-0.5, cam.height_px - 0.5, n)
    rays = cam.pixel_to_ray(u, v)
    return rays[np.isfinite(rays[:, 0]) & (rays[:, 2] > 0.05)]


# ---------------------------------------------------------------------- projection vs OpenCV


@pytest.mark.parametrize("cam", PINHOLES, ids=lambda c: c.name)
def test_pinhole_projection_matches_cv2(cam: CameraModel) -> None:
    rays = np.concatenate([_random_rays(2000, 50.0), _rays_in_image(cam)])
    expected, _ = cv2.projectPoints(
        rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix, np.array(cam.dist)
    )
    u, v = cam.ray_to_pixel(rays * 7.3)  # scale must not matter
    assert np.all(np.isfinite(u))
    err = np.hypot(u - expected[:, 0, 0], v - expected[:, 0, 1])
    assert err.max() < 0.01


@pytest.mark.parametrize("cam", FISHEYES, ids=lambda c: c.name)
def test_fisheye_projection_matches_cv2(cam: CameraModel) -> None:
    rays = np.concatenate([_random_rays(2000, 85.0), _rays_in_image(cam)])
    expected, _ = cv2.fisheye.projectPoints(
        rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.camera_matrix, np.array(cam.dist)
    )
    u, v = cam.ray_to_pixel(rays)
    err = np.hypot(u - expected[:, 0, 0], v - expected[:, 0, 1])
    assert err.max() < 0.01


@pytest.mark.parametrize("cam", PINHOLES, ids=lambda c: c.name)
def test_pinhole_unprojection_matches_cv2_undistort(cam: CameraModel) -> None:
    rng = np.random.default_rng(2)
    pts = np.stack(
        [rng.uniform(0, cam.width_px - 1, 500), rng.uniform(0, cam.height_px - 1, 500)], -1
    )
    und = cv2.undistortPoints(
        pts.reshape(-1, 1, 2), cam.camera_matrix, np.array(cam.dist),
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14),
    )[:, 0, :]  # fmt: skip
    rays = cam.pixel_to_ray(pts[:, 0], pts[:, 1])
    xy = rays[:, :2] / rays[:, 2:]
    # compare as pixels of an undistorted image with the same focal length
    assert np.max(np.abs(xy - und) * cam.fx) < 0.01


@pytest.mark.parametrize("cam", FISHEYES, ids=lambda c: c.name)
def test_fisheye_unprojection_matches_cv2_undistort(cam: CameraModel) -> None:
    rays = _random_rays(500, 80.0, seed=3)
    expected = rays[:, :2] / rays[:, 2:]
    u, v = cam.ray_to_pixel(rays)
    und = cv2.fisheye.undistortPoints(
        np.stack([u, v], -1).reshape(-1, 1, 2), cam.camera_matrix, np.array(cam.dist),
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14),
    )[:, 0, :]  # fmt: skip
    ours = cam.pixel_to_ray(u, v)
    assert np.allclose(und, expected, atol=1e-6)  # OpenCV agrees with the analytic rays...
    assert np.allclose(ours, rays, atol=1e-9)  # ...and so do we


# ---------------------------------------------------------------------- round trips, analytics


@pytest.mark.parametrize("cam", ALL, ids=lambda c: c.name)
def test_round_trip_over_full_image_including_corners(cam: CameraModel) -> None:
    u, v = cam.pixel_grid()
    assert u.shape == v.shape == (cam.height_px, cam.width_px)
    assert u[0, 0] == 0 and v[0, 0] == 0 and u[0, -1] == cam.width_px - 1
    # every pixel centre plus the outer corners of the corner pixels
    uu = np.concatenate([u.ravel(), [-0.5, cam.width_px - 0.5, -0.5, cam.width_px - 0.5]])
    vv = np.concatenate([v.ravel(), [-0.5, -0.5, cam.height_px - 0.5, cam.height_px - 0.5]])
    rays = cam.pixel_to_ray(uu, vv)
    assert np.all(np.isfinite(rays)), "these calibrations are valid over the whole image"
    assert np.allclose(np.linalg.norm(rays, axis=-1), 1.0)
    u2, v2 = cam.ray_to_pixel(rays)
    assert np.max(np.hypot(u2 - uu, v2 - vv)) < 0.01


def test_principal_point_looks_along_the_optical_axis() -> None:
    for cam in ALL:
        ray = cam.pixel_to_ray(cam.cx, cam.cy)
        assert np.allclose(ray, [0, 0, 1], atol=1e-12)
        assert ray.shape == (3,)


def test_undistorted_pinhole_is_the_textbook_projection() -> None:
    cam = CameraModel("ideal", "pinhole", 640, 480, 500.0, 510.0, 320.0, 240.0, (0, 0, 0, 0))
    u, v = cam.ray_to_pixel(np.array([[0.3, -0.2, 2.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]))
    assert u[0] == pytest.approx(500 * 0.15 + 320) and v[0] == pytest.approx(510 * -0.1 + 240)
    assert np.isnan(u[1]) and np.isnan(v[1]), "behind the camera"
    assert np.isnan(u[2]), "in the image plane"


def test_equidistant_fisheye_is_f_theta_even_behind_the_image_plane() -> None:
    f = 200.0
    cam = CameraModel("fe", "fisheye", 900, 900, f, f, 449.5, 449.5, (0, 0, 0, 0))
    theta = np.radians([0.0, 30.0, 89.0, 100.0, 110.0])  # > 90 deg: wide fisheye lenses see it
    rays = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], -1)
    u, v = cam.ray_to_pixel(rays)
    assert np.allclose(u - 449.5, f * theta) and np.allclose(v, 449.5)
    assert np.allclose(cam.pixel_to_ray(u, v), rays, atol=1e-12)


def test_folding_distortion_gives_nan_not_ghosts() -> None:
    # r (1 - 0.5 r^2) peaks at r = sqrt(2/3): beyond it, rays would fold back into the image
    cam = CameraModel("fold", "pinhole", 800, 600, 400.0, 400.0, 399.5, 299.5, (-0.5, 0, 0, 0))
    r_max = np.sqrt(2 / 3)
    u, _ = cam.ray_to_pixel(np.array([[0.99 * r_max, 0, 1], [1.5 * r_max, 0, 1]]))
    assert np.isfinite(u[0]) and np.isnan(u[1])
    rd_max = r_max * (1 - 0.5 * r_max**2)  # largest distorted radius the lens can produce
    inside, outside = cam.cx + 400 * rd_max * 0.99, cam.cx + 400 * rd_max * 1.01
    rays = cam.pixel_to_ray(np.array([inside, outside]), np.array([cam.cy, cam.cy]))
    assert np.isfinite(rays[0]).all() and np.isnan(rays[1]).all()
    # the corner lies beyond the fold: unimageable, hence NaN
    assert np.isnan(cam.pixel_to_ray(-0.5, -0.5)).all()


def test_vertical_fov_of_pinhole_from_fov_checked_with_cv2() -> None:
    dist = (-0.12, 0.03, 0.0, 0.0, 0.0)
    cam = CameraModel.pinhole_from_fov(800, 600, 74.0, dist=dist)
    half = np.radians(37.0)
    edge = np.array([[0.0, -np.sin(half), np.cos(half)], [0.0, np.sin(half), np.cos(half)]])
    img, _ = cv2.projectPoints(edge, np.zeros(3), np.zeros(3), cam.camera_matrix, np.array(dist))
    assert img[:, 0, 1] == pytest.approx([-0.5, 599.5], abs=1e-6)
    assert cam.cx == 399.5 and cam.fx == cam.fy


def test_fisheye_from_fov_edge_angle() -> None:
    cam = CameraModel.fisheye_from_fov(800, 600, 110.0, dist=(0.01, -0.002, 0.0, 0.0))
    ray = cam.pixel_to_ray(cam.cx, -0.5)
    assert np.degrees(np.arccos(ray[2])) == pytest.approx(55.0, abs=1e-9)


def test_default_cameras() -> None:
    pin, fe = default_camera("pinhole"), default_camera("fisheye")
    assert (pin.model, pin.width_px, pin.height_px) == ("pinhole", 800, 600)
    assert fe.model == "fisheye"
    top = pin.pixel_to_ray(pin.cx, -0.5)
    assert 2 * np.degrees(np.arccos(top[2])) == pytest.approx(74.0, abs=0.5)
    assert 0 < abs(pin.dist[0]) < 0.2, "mild distortion"
    corner = fe.pixel_to_ray(-0.5, -0.5)
    assert np.degrees(np.arccos(corner[2])) < 97.5, "inside a 195 deg fisheye lens"
    with pytest.raises(ValueError, match="kind"):
        default_camera("omni")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"model": "omni"}, "model"),
        ({"dist": (0.1, 0.2, 0.3)}, "distortion"),
        ({"fx": -1.0}, "focal"),
        ({"width_px": 0}, "size"),
        ({"model": "fisheye", "dist": (0, 0, 0, 0, 0)}, "k1, k2, k3, k4"),
    ],
)
def test_bad_intrinsics_are_rejected(kwargs: dict, match: str) -> None:
    base = dict(name="c", model="pinhole", width_px=10, height_px=10, fx=5.0, fy=5.0, cx=5.0,
                cy=5.0, dist=(0, 0, 0, 0))  # fmt: skip
    with pytest.raises(ValueError, match=match):
        CameraModel(**{**base, **kwargs})


def test_contains() -> None:
    cam = default_camera("pinhole")
    inside = cam.contains([-0.5, 799.5, 0.0, np.nan, 800.0], [-0.5, 599.5, 600.0, 1.0, 1.0])
    assert inside.tolist() == [True, True, False, False, False]


# ---------------------------------------------------------------------- calibration files


@pytest.mark.parametrize("cam", ALL, ids=lambda c: c.name)
def test_yaml_round_trip_and_cv2_can_read_it(cam: CameraModel, tmp_path: Path) -> None:
    path = cam.to_yaml(tmp_path / "cam.yaml")
    assert CameraModel.from_yaml(path) == cam
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert np.array_equal(fs.getNode("camera_matrix").mat(), cam.camera_matrix)
    assert np.array_equal(fs.getNode("distortion_coefficients").mat().ravel(), cam.dist)
    assert fs.getNode("model").string() == cam.model
    assert int(fs.getNode("image_width").real()) == cam.width_px
    assert not [p.name for p in tmp_path.iterdir() if p.name != "cam.yaml"], "temp file left"


OPENCV_OLD_HEADER = """%YAML:1.0
camera_name: old
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 500., 0., 320., 0., 501., 240., 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -1e-1, 1.0e-2, 0, 0, 0 ]
"""

LAYOUTS = {
    "ros.yml": (
        "image_width: 800\nimage_height: 600\ncamera_name: ros\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [510, 0, 401, 0, 512, 299, 0, 0, 1]\n"
        "distortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n"
        "  data: [-0.25, 0.07, 0.001, -0.0002, 0]\n",
        ("pinhole", 800, 600, 510, 512, 401, 299, (-0.25, 0.07, 0.001, -0.0002, 0)),
    ),
    "ros_equidistant.yml": (
        "image_width: 640\nimage_height: 480\n"
        "camera_matrix: {rows: 3, cols: 3, data: [280, 0, 320, 0, 281, 240, 0, 0, 1]}\n"
        "distortion_model: equidistant\n"
        "distortion_coefficients: {rows: 1, cols: 4, data: [0.01, -0.02, 0.003, -0.0004]}\n",
        ("fisheye", 640, 480, 280, 281, 320, 240, (0.01, -0.02, 0.003, -0.0004)),
    ),
    "opencv_old.yaml": (
        OPENCV_OLD_HEADER,
        ("pinhole", 640, 480, 500, 501, 320, 240, (-0.1, 0.01, 0, 0, 0)),
    ),
    "camodocal_pinhole.yaml": (
        "%YAML:1.0\n---\nmodel_type: PINHOLE\ncamera_name: camera\nimage_width: 752\n"
        "image_height: 480\ndistortion_parameters:\n   k1: -3.0e-01\n   k2: 9.0e-02\n"
        "   p1: -1.2e-04\n   p2: -7.5e-05\nprojection_parameters:\n   fx: 4.69e+02\n"
        "   fy: 4.70e+02\n   cx: 3.53e+02\n   cy: 2.30e+02\n",
        ("pinhole", 752, 480, 469, 470, 353, 230, (-0.3, 0.09, -1.2e-4, -7.5e-5)),
    ),
    "camodocal_kb.yaml": (
        "%YAML:1.0\n---\nmodel_type: KANNALA_BRANDT\ncamera_name: camera\nimage_width: 848\n"
        "image_height: 800\nprojection_parameters:\n   k2: -0.007\n   k3: 0.042\n   k4: -0.04\n"
        "   k5: 0.0066\n   mu: 286.2\n   mv: 286.5\n   u0: 421.5\n   v0: 400.8\n",
        ("fisheye", 848, 800, 286.2, 286.5, 421.5, 400.8, (-0.007, 0.042, -0.04, 0.0066)),
    ),
    "kalibr.yaml": (
        "cam0:\n  camera_model: pinhole\n  distortion_model: equidistant\n"
        "  distortion_coeffs: [0.0035, 0.0007, -0.002, 0.0002]\n"
        "  intrinsics: [190.9, 190.8, 254.9, 256.8]\n  resolution: [512, 512]\n"
        "  rostopic: /cam0/image_raw\n",
        ("fisheye", 512, 512, 190.9, 190.8, 254.9, 256.8, (0.0035, 0.0007, -0.002, 0.0002)),
    ),
    "orbslam3_pinhole.yaml": (
        '%YAML:1.0\nFile.version: "1.0"\nCamera.type: "PinHole"\nCamera1.fx: 458.6\n'
        "Camera1.fy: 457.3\nCamera1.cx: 367.2\nCamera1.cy: 248.4\nCamera1.k1: -0.28\n"
        "Camera1.k2: 0.074\nCamera1.p1: 0.00019\nCamera1.p2: 1.7e-05\nCamera.width: 752\n"
        "Camera.height: 480\nCamera.fps: 20\n",
        ("pinhole", 752, 480, 458.6, 457.3, 367.2, 248.4, (-0.28, 0.074, 0.00019, 1.7e-5)),
    ),
    "orbslam3_kb8.yaml": (
        '%YAML:1.0\nCamera.type: "KannalaBrandt8"\nCamera1.fx: 285.0\nCamera1.fy: 285.1\n'
        "Camera1.cx: 420.5\nCamera1.cy: 400.7\nCamera1.k1: -0.0053\nCamera1.k2: 0.0423\n"
        "Camera1.k3: -0.0395\nCamera1.k4: 0.0068\nCamera.width: 848\nCamera.height: 800\n",
        ("fisheye", 848, 800, 285.0, 285.1, 420.5, 400.7, (-0.0053, 0.0423, -0.0395, 0.0068)),
    ),
    "orbslam2.yaml": (
        "%YAML:1.0\nCamera.fx: 517.3\nCamera.fy: 516.5\nCamera.cx: 318.6\nCamera.cy: 255.3\n"
        "Camera.k1: 0.26\nCamera.k2: -0.95\nCamera.p1: -0.005\nCamera.p2: 0.002\n"
        "Camera.k3: 1.16\nCamera.width: 640\nCamera.height: 480\n",
        ("pinhole", 640, 480, 517.3, 516.5, 318.6, 255.3, (0.26, -0.95, -0.005, 0.002, 1.16)),
    ),
}


@pytest.mark.parametrize("filename", sorted(LAYOUTS))
def test_tolerant_readers(filename: str, tmp_path: Path) -> None:
    text, expected = LAYOUTS[filename]
    path = tmp_path / filename
    path.write_text(text)
    cam = CameraModel.from_yaml(path)
    model, w, h, fx, fy, cx, cy, dist = expected
    assert (cam.model, cam.width_px, cam.height_px) == (model, w, h)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((fx, fy, cx, cy))
    assert cam.dist == pytest.approx(dist)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("model_type: MEI\nimage_width: 752\nimage_height: 480\n", "MEI.*not supported"),
        ("cam0:\n  camera_model: omni\n  intrinsics: [1, 1, 1, 1, 1]\n", "omni.*not supported"),
        ('Camera.type: "Rectified"\nCamera1.fx: 1\nCamera1.fy: 1\nCamera1.cx: 1\nCamera1.cy: 1\n'
         "Camera.width: 2\nCamera.height: 2\n", "Rectified"),
        ("foo: 1\n", "unknown calibration layout"),
        ("camera_matrix: [1, 2]\ndistortion_coefficients: [0, 0, 0, 0]\nimage_width: 2\n"
         "image_height: 2\n", "3x3"),
        ("format: predisat-camera\nversion: 7\n", "version 7"),
        ("image_width: 10\nimage_height: 10\ncamera_matrix: [[5, 0, 5], [0, 5, 5], [0, 0, 1]]\n"
         "distortion_coefficients: [0, 0, 0, 0, 0, 0.1, 0, 0]\n", "rational"),
        ("model_type: PINHOLE\nimage_width: 10\nimage_height: 10\nprojection_parameters:\n"
         "  fx: abc\n", "'fx' must be a number"),
        ("[1, 2", "not valid"),
        ("image_width: 2\nimage_height: 2\ncamera_matrix: !!opencv-matrix\n  rows: 2\n  cols: 3\n"
         "  dt: d\n  data: [1, 0, 1, 0, 1, 1, 0, 0, 1]\n", r"(?s)matrix: cannot reshape.*line 3"),
        ("camera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n", r"no 'data' field"),
    ],
)  # fmt: skip
def test_rejected_calibrations_name_the_file(text: str, match: str, tmp_path: Path) -> None:
    path = tmp_path / "bad_calib.yaml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=match) as info:
        CameraModel.from_yaml(path)
    assert "bad_calib.yaml" in str(info.value)


def test_missing_calibration_file(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match=r"nope\.yaml.*check the path"):
        CameraModel.from_yaml(tmp_path / "nope.yaml")


@pytest.mark.shared
def test_real_calibrations(shared_data: Path) -> None:
    folder = shared_data / "camera_calib"
    files = sorted(folder.glob("*.y*ml"))
    assert len(files) >= 8
    loaded = {}
    for path in files:
        if "mei" in path.name:
            with pytest.raises(CalibrationError, match=r"MEI.*not supported") as info:
                CameraModel.from_yaml(path)
            assert path.name in str(info.value)
            continue
        cam = CameraModel.from_yaml(path)
        loaded[path.name] = cam
        u, v = cam.pixel_grid()
        rays = cam.pixel_to_ray(u[::7, ::7], v[::7, ::7])
        assert np.isfinite(rays).all()
        u2, v2 = cam.ray_to_pixel(rays)
        assert np.nanmax(np.hypot(u2 - u[::7, ::7], v2 - v[::7, ::7])) < 0.01
    assert len(loaded) == 6
    # independent reader: OpenCV's own FileStorage on the ORB-SLAM3 files
    for name in ("orbslam3_EuRoC_pinhole_radtan.yaml", "orbslam3_TUM-VI_KannalaBrandt8.yaml"):
        fs = cv2.FileStorage(str(folder / name), cv2.FILE_STORAGE_READ)
        cam = loaded[name]
        assert cam.fx == fs.getNode("Camera1.fx").real()
        assert cam.cy == fs.getNode("Camera1.cy").real()
        assert cam.dist[1] == fs.getNode("Camera1.k2").real()
        assert cam.width_px == int(fs.getNode("Camera.width").real())
    ros = loaded["ros_camera_info_pointgrey_800x600_mekabot.yml"]
    assert (ros.model, ros.fx, ros.cx, ros.dist[2]) == ("pinhole", 538.63, 457.698, 0.0028784)
    kb = loaded["vinsfusion_realsense_t265_left_KANNALA_BRANDT.yaml"]
    assert kb.model == "fisheye" and kb.dist[0] == pytest.approx(-0.00703547615557909)
    assert kb.fx == pytest.approx(286.2373962402344)


# ---------------------------------------------------------------------- mounts and frames


def test_level_forward_camera_axes() -> None:
    r = Mount("left", yaw_deg=0.0, pitch_deg=0.0).camera_to_vehicle()
    assert np.allclose(r @ [0, 0, 1], [1, 0, 0])  # optical axis -> forward
    assert np.allclose(r @ [1, 0, 0], [0, -1, 0])  # image right -> vehicle right (-y)
    assert np.allclose(r @ [0, 1, 0], [0, 0, -1])  # image down -> down


@pytest.mark.parametrize("side", ["left", "right"])
@pytest.mark.parametrize("heading_deg", [0.0, 37.0, 200.0, 359.0])
def test_side_camera_looks_square_to_the_track_45_deg_up(side: str, heading_deg: float) -> None:
    mount = Mount.default(side)  # type: ignore[arg-type]
    r = mount.camera_to_enu(heading_deg)
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    az, el, _ = enu_to_azel(r @ [0, 0, 1])
    expected_az = (heading_deg - 90.0 if side == "left" else heading_deg + 90.0) % 360.0
    assert float(el) == pytest.approx(45.0)
    assert (float(az) - expected_az + 180) % 360 - 180 == pytest.approx(0.0, abs=1e-9)
    # driving the other way the vehicle's left camera looks at the track's right side
    az_rev, _, _ = enu_to_azel(mount.camera_to_enu(heading_deg, reverse=True) @ [0, 0, 1])
    assert (float(az_rev) - expected_az) % 360.0 == pytest.approx(180.0)


def test_image_top_sees_higher_elevation_and_right_is_forward_for_left_camera() -> None:
    cam = default_camera("pinhole")
    r = Mount.default("left").camera_to_enu(0.0)  # track heading north; left camera looks west
    rays = cam.pixel_to_ray(
        [cam.cx, cam.cx, 799.5, -0.5, -0.5], [-0.5, 599.5, cam.cy, cam.cy, 599.5]
    )
    az, el, _ = enu_to_azel(rays @ r.T)
    # top and bottom edges: pitch +- half the vertical FOV (tangential terms shift them a bit)
    assert el[0] == pytest.approx(45 + 37, abs=0.05)
    assert el[1] == pytest.approx(45 - 37, abs=0.05)  # ~8 deg, as DESIGN.md says
    assert 3.0 < el[4] < el[1]  # bottom corners see lower still
    # left camera facing west from a northbound train: image right is the forward side (north)
    assert 270 < az[2] <= 360 and 180 <= az[3] < 270


def test_roll_lowers_the_right_side_of_the_image() -> None:
    r = Mount("left", yaw_deg=0.0, pitch_deg=0.0, roll_deg=10.0).camera_to_vehicle()
    right_edge = r @ [1.0, 0.0, 1.0]
    assert right_edge[2] < 0 and np.degrees(np.arcsin(r @ [1, 0, 0])[2]) == pytest.approx(-10.0)


def test_vehicle_to_enu() -> None:
    r = vehicle_to_enu([0.0, 90.0, 90.0], [False, False, True])
    assert r.shape == (3, 3, 3)
    assert np.allclose(r[0] @ [1, 0, 0], [0, 1, 0]) and np.allclose(r[0] @ [0, 1, 0], [-1, 0, 0])
    assert np.allclose(r[1] @ [1, 0, 0], [1, 0, 0]) and np.allclose(r[1] @ [0, 1, 0], [0, 1, 0])
    assert np.allclose(r[2] @ [1, 0, 0], [-1, 0, 0]) and np.allclose(r[2] @ [0, 1, 0], [0, -1, 0])
    assert np.allclose(r[:, :, 2], [0, 0, 1])


def test_lever_arm_in_enu() -> None:
    mount = Mount("left", 90.0, 45.0, 0.0, (0.3, 1.5, -0.5))
    pos = mount.camera_position_enu([[10.0, 20.0, 4.0]], heading_deg=90.0)  # heading east
    assert np.allclose(pos, [[10.3, 21.5, 3.5]])  # forward = east, left = north


def test_mount_from_dict() -> None:
    m = Mount.from_dict("right", {"pitch_deg": 40})
    assert (m.yaw_deg, m.pitch_deg, m.lever_arm_m) == (-90.0, 40.0, (0.0, -1.5, -0.5))
    assert Mount.from_dict("right", m.to_dict()) == m
    with pytest.raises(ValueError, match="unknown mount keys"):
        Mount.from_dict("left", {"tilt_deg": 3})
    with pytest.raises(ValueError, match="side"):
        Mount("up", 0.0)  # type: ignore[arg-type]


def test_mount_pitch_beyond_the_vertical_is_refused_with_its_equivalent() -> None:
    with pytest.raises(ValueError, match=r"pitch_deg must be within \[-90, 90\].*145"):
        Mount.from_dict("left", {"pitch_deg": 145})
    # the equivalent the message names is the same rotation (checked on matrices built by hand)
    def rot(yaw: float, pitch: float, roll: float) -> np.ndarray:
        y, p, r = np.radians([yaw, -pitch, roll])
        rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
        ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
        rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
        return rz @ ry @ rx

    assert np.allclose(rot(90.0, 145.0, 0.0), rot(270.0, 35.0, 180.0))
    assert np.allclose(
        Mount("left", 270.0, 35.0, 180.0).camera_to_vehicle()
        @ Mount("left", 0.0, 0.0, 0.0).camera_to_vehicle().T,
        rot(270.0, 35.0, 180.0),
    )
    Mount("left", 90.0, 90.0)  # straight up is a valid mount


@pytest.mark.parametrize("kind", ["pinhole", "fisheye"])
def test_resized_keeps_the_rays_of_the_same_image_points(kind: str) -> None:
    cam = default_camera(kind)  # type: ignore[arg-type]
    small = cam.resized(640, 480)
    assert (small.width_px, small.height_px) == (640, 480)
    # the same point of the image (corners and centre of the frame, in relative coordinates)
    rel_u = np.array([0.0, 0.5, 1.0, 0.25])
    rel_v = np.array([0.0, 0.5, 1.0, 0.75])
    u_big, v_big = rel_u * cam.width_px - 0.5, rel_v * cam.height_px - 0.5
    u_small, v_small = rel_u * small.width_px - 0.5, rel_v * small.height_px - 0.5
    np.testing.assert_allclose(
        small.pixel_to_ray(u_small, v_small), cam.pixel_to_ray(u_big, v_big), atol=1e-9
    )
    with pytest.raises(ValueError, match="width_px"):
        cam.resized(1, 480)


def test_centre_pixel_angle_of_an_ideal_pinhole() -> None:
    cam = CameraModel.pinhole_from_fov(640, 480, 74.0)
    # one pixel centred on the principal point of an undistorted pinhole: 2 atan(0.5 / fx)
    want = np.degrees(2.0 * np.arctan(0.5 / cam.fx))
    assert cam.centre_pixel_deg == pytest.approx(want, rel=1e-9)
    assert cam.resized(320, 240).centre_pixel_deg == pytest.approx(2 * want, rel=1e-3)


def _unit_rays_independent(cam: CameraModel, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit rays of pixels without CameraModel: cv2.undistortPoints for a pinhole; for a
    fisheye its polynomial solved by numpy.roots (cv2.fisheye.undistortPoints returns pinhole
    coordinates, which fold past 90 deg off-axis)."""
    k = cam.camera_matrix
    if cam.model == "pinhole":
        pts = np.stack([u, v], -1)[:, None, :].astype(np.float64)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
        xy = cv2.undistortPoints(pts, k, np.asarray(cam.dist), criteria=crit)[:, 0]
        rays = np.column_stack([xy, np.ones(len(xy))])
    else:
        xd, yd = (u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1]
        k1, k2, k3, k4 = cam.dist
        theta = np.array([
            np.min([r.real for r in np.roots([k4, 0, k3, 0, k2, 0, k1, 0, 1.0, -td])
                    if abs(r.imag) < 1e-9 and r.real >= 0])
            for td in np.hypot(xd, yd)
        ])  # fmt: skip
        phi = np.arctan2(yd, xd)
        rays = np.column_stack(
            [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
        )
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


@pytest.mark.parametrize("cam", ALL, ids=lambda c: c.name)
def test_widest_pixel_angle_matches_an_independent_inversion(cam: CameraModel) -> None:
    u, v = np.linspace(0, cam.width_px - 2, 41), np.linspace(0, cam.height_px - 2, 31)
    uu, vv = (a.ravel() for a in np.meshgrid(u, v))
    r0 = _unit_rays_independent(cam, uu, vv)
    cos = np.concatenate([np.sum(r0 * _unit_rays_independent(cam, uu + 1.0, vv), axis=1),
                          np.sum(r0 * _unit_rays_independent(cam, uu, vv + 1.0), axis=1)])
    want = np.degrees(np.arccos(np.clip(np.nanmin(cos), -1.0, 1.0)))
    # a coarser grid than the property's: it may miss the widest pixel by a little
    assert cam.widest_pixel_deg == pytest.approx(want, rel=0.025)
    assert cam.widest_pixel_deg >= 0.99 * want


def test_widest_pixel_of_a_barrel_pinhole_is_off_centre() -> None:
    cam = CameraModel.pinhole_from_fov(640, 480, 74.0, dist=(-0.4, 0.12, 0.0, 0.0, 0.0))
    # barrel distortion outweighs the pinhole's shrinking pixels towards the sides
    side = _unit_rays_independent(cam, np.array([55.0, 56.0]), np.array([239.0, 239.0]))
    side_deg = np.degrees(np.arccos(side[0] @ side[1]))
    assert side_deg > 1.2 * cam.centre_pixel_deg
    assert cam.widest_pixel_deg >= side_deg


# ---------------------------------------------------------------------- vehicle attitude


@pytest.mark.parametrize("side", ["left", "right", "front", "rear", "roof"])
@pytest.mark.parametrize(("roll", "pitch"), [(6.9, 0.0), (-7.6, 1.5), (2.0, -3.0), (0.0, 4.0)])
def test_mount_on_a_tilted_vehicle_matches_scipy(side: str, roll: float, pitch: float) -> None:
    from scipy.spatial.transform import Rotation

    m = Mount.default(side)
    tilted = m.on_vehicle(roll, pitch)
    # intrinsic pitch (about y, nose up is -y) then roll about the new x
    att = Rotation.from_euler("YX", [-pitch, roll], degrees=True).as_matrix()
    np.testing.assert_allclose(tilted.camera_to_vehicle(), att @ m.camera_to_vehicle(), atol=1e-12)
    np.testing.assert_allclose(tilted.lever_arm_m, att @ np.array(m.lever_arm_m), atol=1e-12)
    assert tilted.side == side


def test_raising_the_left_side_raises_the_left_camera_and_lowers_the_right() -> None:
    # the optical axis of a 45-deg side camera rises by the roll on its side, falls on the other
    for side, sign in (("left", 1.0), ("right", -1.0)):
        axis = Mount.default(side).on_vehicle(5.0, 0.0).camera_to_vehicle() @ [0.0, 0.0, 1.0]
        assert np.degrees(np.arcsin(axis[2])) == pytest.approx(45.0 + sign * 5.0)
    # nose up raises the front camera's axis and lowers the rear one's
    front = Mount.default("front").on_vehicle(0.0, 2.0).camera_to_vehicle() @ [0.0, 0.0, 1.0]
    rear = Mount.default("rear").on_vehicle(0.0, 2.0).camera_to_vehicle() @ [0.0, 0.0, 1.0]
    assert np.degrees(np.arcsin(front[2])) == pytest.approx(32.0)
    assert np.degrees(np.arcsin(rear[2])) == pytest.approx(28.0)


def test_a_level_vehicle_keeps_the_mount_and_wild_attitudes_are_refused() -> None:
    m = Mount.default("left")
    assert m.on_vehicle(0.0, 0.0) is m
    with pytest.raises(ValueError, match="roll_deg"):
        m.on_vehicle(60.0, 0.0)
    with pytest.raises(ValueError, match="pitch_deg"):
        m.on_vehicle(0.0, float("nan"))


def test_a_zenith_camera_on_a_tilted_vehicle_keeps_its_rotation() -> None:
    from scipy.spatial.transform import Rotation

    m = Mount("roof", 0.0, 90.0, 0.0, (0.0, 0.0, 0.5))
    tilted = m.on_vehicle(0.0, 0.0 + 1e-13)  # gimbal lock: yaw and roll share an axis
    att = Rotation.from_euler("YX", [-1e-13, 0.0], degrees=True).as_matrix()
    np.testing.assert_allclose(tilted.camera_to_vehicle(), att @ m.camera_to_vehicle(), atol=1e-9)


def test_pixel_angles_bracket_the_centre_pixel() -> None:
    for cam in (default_camera("pinhole"), default_camera("fisheye")):
        # the grid steps from near the centre, not from it: a part in a million of slack
        assert cam.narrowest_pixel_deg <= cam.centre_pixel_deg <= cam.widest_pixel_deg * 1.000001
        assert cam.narrowest_pixel_deg > 0.3 * cam.widest_pixel_deg  # no degenerate pixel


def test_a_tilted_vehicle_carries_its_antenna_toward_the_low_side() -> None:
    from predisat.camera.models import tilt_shift_m

    # left side up (a right-hand curve's cant): the roof moves right, by height * sin(roll)
    shift = tilt_shift_m(6.9, 0.0, 4.0)
    assert shift[1] == pytest.approx(-4.0 * np.sin(np.radians(6.9)))
    assert shift[2] == pytest.approx(4.0 * (np.cos(np.radians(6.9)) - 1.0))
    # nose up: the antenna stays at its chainage (measured) and drops a little
    np.testing.assert_allclose(tilt_shift_m(0.0, 2.0, 4.0)[:2], 0.0)
    assert tilt_shift_m(0.0, 2.0, 4.0)[2] == pytest.approx(4.0 * (np.cos(np.radians(2.0)) - 1))
    np.testing.assert_allclose(tilt_shift_m(0.0, 0.0, 4.0), 0.0)


def test_the_tilt_doubt_bounds_how_far_every_attitude_within_it_moves_the_camera() -> None:
    from scipy.spatial.transform import Rotation

    from predisat.camera.models import tilt_doubt_m

    rng = np.random.default_rng(3)
    cases = [  # lever arm, nominal roll and pitch, their doubts (deg)
        ((0.0, 1.4, -0.8), 5.0, 0.0, 5.3, 2.35),  # a side camera, unmeasured roll on a curve
        ((0.5, -1.4, -0.8), -7.0, 1.5, 3.0, 0.5),
        ((9.0, 0.0, -1.5), 0.0, -2.0, 0.7, 2.35),  # a cab camera: pitch moves it up and down
        ((0.0, 0.0, 0.3), 2.0, 0.0, 0.0, 0.0),  # an attitude taken as exact
    ]
    for arm, r0, p0, a, b in cases:
        along, across, vertical = tilt_doubt_m(arm, 4.0, r0, p0, a, b)
        grid = np.array([(r, p) for r in np.linspace(r0 - a, r0 + a, 41)
                         for p in np.linspace(p0 - b, p0 + b, 41)])  # fmt: skip
        rand = np.column_stack([rng.uniform(r0 - a, r0 + a, 2000),
                                rng.uniform(p0 - b, p0 + b, 2000)])  # fmt: skip
        att = np.vstack([grid, rand])

        def moves(point: np.ndarray, r0: float = r0, p0: float = p0,
                  att: np.ndarray = att) -> np.ndarray:  # fmt: skip
            # scipy's extrinsic "xy": roll about x, then pitch (nose up: -y) about y
            nominal = Rotation.from_euler("xy", [r0, -p0], degrees=True).apply(point)
            true = Rotation.from_euler("xy", np.column_stack([att[:, 0], -att[:, 1]]),
                                       degrees=True).apply(point)  # fmt: skip
            return np.abs(true - nominal).max(axis=0)  # level frame: x along, y across, z up

        # along the track the antenna is at its measured chainage: the lever arm turns; across
        # and up the whole body turns about the rails (the pivot, 4 m under the antenna)
        got = np.array([moves(np.asarray(arm, float))[0],
                        *moves(np.asarray(arm) + np.array([0.0, 0.0, 4.0]))[1:]])  # fmt: skip
        bound = np.array([along, across, vertical])
        assert np.all(got <= bound + 1e-12), (arm, r0, p0, got, bound)
        if a + b > 0:  # tight, not a loose bound: each part reached to 60 %
            assert np.all(got >= 0.6 * bound), (arm, r0, p0, got, bound)
        else:
            assert along == across == vertical == 0.0
    with pytest.raises(ValueError, match="roll_doubt_deg"):
        tilt_doubt_m((0.0, 1.0, 0.0), 4.0, 0.0, 0.0, -1.0, 0.0)
    with pytest.raises(ValueError, match="lever_arm_m"):
        tilt_doubt_m([0.0, 1.0], 4.0, 0.0, 0.0, 1.0, 1.0)
