"""Survey.load from URLs: a survey served over HTTP (loopback) read as the local folder is."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from predisat.survey import Survey, SurveyError
from tests.predisat.http_folder import serve_folder
from tests.predisat.survey.test_survey import _straight_track, _write


def _frames_equal(a: Survey, b: Survey) -> None:
    for f in dataclasses.fields(a.frames):
        x, y = getattr(a.frames, f.name), getattr(b.frames, f.name)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f.name


def test_a_survey_over_http_loads_as_the_local_folder(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=4, positions=True)
    track = _straight_track()
    local = Survey.load(root, track=track)  # images checked (sizes from their headers)
    with serve_folder(root) as url:
        remote = Survey.load(f"{url}/survey.yaml", track=track)
        assert remote.root == url and remote.problems == ()
        _frames_equal(local, remote)
        assert remote.cameras["right"].camera == local.cameras["right"].camera
        assert remote.cameras["right"].mount == local.cameras["right"].mount
        assert remote.cameras["left"].calibration_path == f"{url}/calib/left.yaml"
        assert remote.image_path(1) == f"{url}/images/right_000000.jpg"
        assert np.array_equal(remote.read_image(3), local.read_image(3))


def test_missing_files_over_http_name_the_url(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=3)
    (root / "images" / "left_000001.jpg").unlink()
    doc = yaml.safe_load((root / "survey.yaml").read_text())
    doc["cameras"]["right"]["calibration"] = "calib/gone.yaml"
    (root / "survey.yaml").write_text(yaml.safe_dump(doc))
    with serve_folder(root) as url:
        with pytest.raises(SurveyError) as err:
            Survey.load(url)
        assert f"{url}/calib/gone.yaml: no such file" in str(err.value)
        (root / "calib" / "gone.yaml").write_bytes((root / "calib" / "right.yaml").read_bytes())
        survey = Survey.load(url, on_error="skip")
        (problem,) = survey.problems
        assert problem.frame_id == "left_000001"
        assert "image images/left_000001.jpg is missing" in str(problem)
