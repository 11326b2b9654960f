"""Surveys with cab and 360-degree cameras: written, read back, sides mapped to the track."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predisat.camera.models import CameraModel, Mount
from predisat.survey import Survey, SurveyError, SurveyWriter

FISHEYE = CameraModel.fisheye_from_fov(40, 30, 120.0)
PANO = CameraModel.equirect(64)


def _write(root: Path, direction: str) -> None:
    cams = {
        "left": (FISHEYE, Mount.default("left")),
        "front": (FISHEYE, Mount.default("front")),
        "rear": (FISHEYE, Mount.default("rear")),
        "roof": (PANO, Mount.default("roof")),
    }
    step_m = -10.0 if direction == "decreasing" else 10.0  # the run moves that way in time
    with SurveyWriter(root, cams, direction_of_travel=direction) as w:  # type: ignore[arg-type]
        for k in range(3):
            for pos, (cam, _) in cams.items():
                img = np.full((cam.height_px, cam.width_px, 3), 40 * k, np.uint8)
                w.add_frame(img, pos, 1.4e9 + k, chainage_m=100.0 + step_m * k)


@pytest.mark.parametrize(
    ("direction", "track_sides"),
    [
        ("increasing", {"left": "left", "front": "front", "rear": "rear", "roof": "roof"}),
        ("decreasing", {"left": "right", "front": "rear", "rear": "front", "roof": "roof"}),
    ],
)
def test_cab_and_roof_cameras_round_trip(
    tmp_path: Path, direction: str, track_sides: dict[str, str]
) -> None:
    _write(tmp_path / "s", direction)
    sv = Survey.load(tmp_path / "s")
    assert set(sv.cameras) == {"left", "front", "rear", "roof"}
    assert sv.cameras["roof"].camera == PANO
    assert sv.cameras["front"].mount == Mount.default("front")
    assert len(sv.frames) == 12
    for side, track_side in zip(sv.frames.side, sv.frames.track_side, strict=True):
        assert track_sides[str(side)] == str(track_side)
    assert sv.read_image(int(np.flatnonzero(sv.frames.side == "roof")[0])).shape == (32, 64, 3)


def test_a_camera_position_that_does_not_exist_is_named_with_the_choices(tmp_path: Path) -> None:
    _write(tmp_path / "s", "increasing")
    yaml_path = tmp_path / "s" / "survey.yaml"
    yaml_path.write_text(yaml_path.read_text().replace("  roof:", "  bonnet:"))
    expected = (r"camera side 'bonnet' is unknown; use 'left' or 'right' \(vehicle side\), "
                r"'front' or 'rear' \(cab\) or 'roof'")  # fmt: skip
    with pytest.raises(SurveyError, match=expected):
        Survey.load(tmp_path / "s")
