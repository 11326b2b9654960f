"""Tests of the equirectangular (360-degree) camera model, the cab / roof mounts and the rig
presets. Expected pixels and directions come from spherical trigonometry written out here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predisat.camera.calibfile import CalibrationError
from predisat.camera.models import CameraModel, Mount
from predisat.camera.rigs import RIG_NAMES, Rig

PANO = CameraModel.equirect(720)  # 0.5 deg per pixel


def _ray(lon_deg: float, lat_down_deg: float) -> np.ndarray:
    """Camera-frame ray (x right, y down, z forward) at a longitude right of the axis and a
    latitude below the horizontal."""
    lo, la = np.radians(lon_deg), np.radians(lat_down_deg)
    return np.array([np.cos(la) * np.sin(lo), np.sin(la), np.cos(la) * np.cos(lo)])


@pytest.mark.parametrize(
    ("lon_deg", "lat_deg", "u_px", "v_px"),
    [
        (0.0, 0.0, 359.5, 179.5),  # the optical axis: the image centre
        (90.0, 0.0, 539.5, 179.5),  # camera x: a quarter turn right
        (-90.0, 0.0, 179.5, 179.5),
        (0.0, -90.0, 359.5, -0.5),  # straight up (-y): the top edge
        (0.0, 90.0, 359.5, 359.5),  # straight down: the bottom edge
        (45.0, -30.0, 359.5 + 90.0, 179.5 - 60.0),  # 2 px per degree
    ],
)
def test_equirect_projects_longitude_and_latitude_linearly(
    lon_deg: float, lat_deg: float, u_px: float, v_px: float
) -> None:
    u, v = PANO.ray_to_pixel(3.0 * _ray(lon_deg, lat_deg))  # length does not matter
    assert float(u) == pytest.approx(u_px, abs=1e-9)
    assert float(v) == pytest.approx(v_px, abs=1e-9)
    back = PANO.pixel_to_ray(np.array(u_px), np.array(v_px))
    assert back == pytest.approx(_ray(lon_deg, lat_deg), abs=1e-9)


def test_equirect_sees_behind_at_the_side_edges_and_every_pixel_has_a_ray() -> None:
    u, v = PANO.ray_to_pixel(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]))
    assert abs(float(u[0]) - 359.5) == pytest.approx(360.0)  # at -0.5 or 719.5: the seam
    assert float(v[0]) == pytest.approx(179.5)
    assert np.isnan(u[1]) and np.isnan(v[1])  # a zero ray has no direction
    rays = PANO.pixel_to_ray(*PANO.pixel_grid())
    assert np.isfinite(rays).all()
    assert np.linalg.norm(rays, axis=-1) == pytest.approx(1.0)
    # one pixel of longitude on the horizon is 0.5 deg
    assert PANO.centre_pixel_deg == pytest.approx(0.5, rel=1e-6)


def test_equirect_calibration_round_trips_and_rejects_distortion(tmp_path: Path) -> None:
    path = PANO.to_yaml(tmp_path / "roof.yaml")
    text = path.read_text()
    assert "model: equirect" in text and "distortion_coefficients" not in text
    assert CameraModel.from_yaml(path) == PANO
    bad = tmp_path / "bad.yaml"
    bad.write_text(text + "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 4\n"
                   "   dt: d\n   data: [ 0.1, 0., 0., 0. ]\n")  # fmt: skip
    with pytest.raises(CalibrationError, match=r"bad\.yaml.*no distortion"):
        CameraModel.from_yaml(bad)
    with pytest.raises(ValueError, match="equirect distortion must be"):
        CameraModel("p", "equirect", 720, 360, 114.6, 114.6, 359.5, 179.5, (0.0,) * 4)


@pytest.mark.parametrize(
    ("position", "axis_vehicle"),
    [
        ("front", (np.cos(np.radians(30.0)), 0.0, np.sin(np.radians(30.0)))),
        ("rear", (-np.cos(np.radians(30.0)), 0.0, np.sin(np.radians(30.0)))),
        ("roof", (1.0, 0.0, 0.0)),
        ("left", (0.0, np.cos(np.radians(45.0)), np.sin(np.radians(45.0)))),
    ],
)
def test_default_mounts_look_where_the_docs_say(position: str, axis_vehicle: tuple) -> None:
    mount = Mount.default(position)  # type: ignore[arg-type]
    axis = mount.camera_to_vehicle() @ np.array([0.0, 0.0, 1.0])
    assert axis == pytest.approx(np.array(axis_vehicle), abs=1e-12)
    assert mount.lever_arm_m[2] < 0.0  # every camera below the antenna
    assert Mount.from_dict(position, mount.to_dict()) == mount  # type: ignore[arg-type]


def test_unknown_position_is_refused_with_the_choices() -> None:
    with pytest.raises(ValueError, match="roof"):
        Mount.default("bonnet")  # type: ignore[arg-type]


def test_rig_presets() -> None:
    rigs = {name: Rig.preset(name) for name in RIG_NAMES}
    assert rigs["side-fisheye"].positions == ("left", "right")
    assert rigs["side-fisheye+cab"].positions == ("left", "right", "front", "rear")
    assert rigs["360"].positions == ("roof",)
    assert rigs["360"].cameras[0][1].model == "equirect"
    for rig in rigs.values():
        assert all(pos == mount.side for pos, _, mount in rig.cameras)
        assert set(rig.as_mapping()) == set(rig.positions)
    with pytest.raises(ValueError, match="no side cameras"):
        Rig.preset("360", side_pitch_deg=30.0)
    with pytest.raises(ValueError, match="unknown rig"):
        Rig.preset("roof-fisheye")


def test_scaled_rig_keeps_the_field_of_view() -> None:
    full, half = Rig.preset("side-fisheye+cab"), Rig.preset("side-fisheye+cab").scaled(0.5)
    for (_, a, ma), (_, b, mb) in zip(full.cameras, half.cameras, strict=True):
        assert (b.width_px, b.height_px) == (a.width_px // 2, a.height_px // 2)
        assert ma == mb
        # the top-centre pixel's edge sees the same direction
        ra = a.pixel_to_ray(np.array((a.width_px - 1) / 2), np.array(-0.5))
        rb = b.pixel_to_ray(np.array((b.width_px - 1) / 2), np.array(-0.5))
        assert ra == pytest.approx(rb, abs=1e-9)


def test_rig_refuses_a_mount_of_another_position() -> None:
    cam = CameraModel.equirect(64)
    with pytest.raises(ValueError, match="mount for 'left'"):
        Rig("x", (("roof", cam, Mount.default("left")),))
