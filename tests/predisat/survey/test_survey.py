"""Tests of the survey format v1: writer -> loader round trips and every validation error."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from predisat.camera.models import CameraModel, Mount
from predisat.geodesy import WGS84
from predisat.survey import MANIFEST_COLUMNS, Survey, SurveyError, SurveyProblem, SurveyWriter

CAM = CameraModel.pinhole_from_fov(32, 24, 74.0, dist=(-0.1, 0.02, 0.0, 0.0), name="tiny")
CAMERAS = {"left": (CAM, Mount.default("left")), "right": (CAM, Mount("right", -85.0, 40.0))}
GPS0 = 1_400_000_000.25
LAT0, LON0 = 50.5, 4.6  # start of a straight northbound test track


def _image(i: int) -> np.ndarray:
    img = np.zeros((24, 32, 3), np.uint8)
    img[:, :, 0] = 20 * i
    img[: 4 + i, :, 2] = 200  # a band whose height encodes the frame
    return img


def _write(root: Path, n: int = 3, positions: bool = False, **kwargs: object) -> Path:
    """n frames per side, 10 m and 1 s apart, by chainage or by GNSS position (towards
    decreasing chainage when ``direction_of_travel="decreasing"``)."""
    step_m = -10.0 if kwargs.get("direction_of_travel") == "decreasing" else 10.0
    with SurveyWriter(root, CAMERAS, metadata={"description": "unit test"}, **kwargs) as w:  # type: ignore[arg-type]
        for i in range(n):
            for side in ("left", "right"):
                if positions:
                    lon, lat, _ = WGS84.fwd(LON0, LAT0, 0.0, 100.0 + step_m * i)
                    w.add_frame(_image(i), side, GPS0 + i, lat_deg=lat, lon_deg=lon, h_m=150.0)
                else:
                    w.add_frame(_image(i), side, GPS0 + i, chainage_m=100.0 + step_m * i)
    return root


def _rows(root: Path) -> list[dict[str, str]]:
    with open(root / "manifest.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _save_rows(
    root: Path, rows: list[dict[str, str]], columns: tuple[str, ...] = MANIFEST_COLUMNS
) -> None:
    with open(root / "manifest.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(columns), extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def _edit_yaml(root: Path, **changes: object) -> None:
    doc = yaml.safe_load((root / "survey.yaml").read_text())
    doc.update(changes)
    (root / "survey.yaml").write_text(yaml.safe_dump(doc))


def _problems(root: Path, **kwargs: object) -> tuple[SurveyProblem, ...]:
    with pytest.raises(SurveyError) as info:
        Survey.load(root, **kwargs)  # type: ignore[arg-type]
    assert str(root) in str(info.value)
    return info.value.problems


def _straight_track():  # -> TrackMap
    track = pytest.importorskip("predisat.track.map")
    lon, lat, _ = WGS84.fwd(
        np.full(11, LON0), np.full(11, LAT0), np.zeros(11), np.arange(11) * 100.0
    )
    return track.TrackMap.from_latlon(lat, lon, 150.0, name="straight")


# ---------------------------------------------------------------------- round trip


def test_round_trip_by_chainage(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=4)
    survey = Survey.load(root)
    f = survey.frames
    assert len(f) == 8 and survey.problems == ()
    assert list(f.side) == ["left", "right"] * 4
    assert list(f.track_side) == list(f.side)
    assert np.allclose(f.gps_s, GPS0 + np.repeat(np.arange(4), 2), rtol=0, atol=1e-9)
    assert np.array_equal(f.chainage_m, 100.0 + 10.0 * np.repeat(np.arange(4), 2))
    assert np.isnan(f.lat_deg).all() and np.isnan(f.offset_m).all()
    assert list(f.row) == list(range(2, 10))
    assert survey.direction_of_travel == "increasing" and not survey.reverse
    assert survey.antenna_height_m == 4.0
    assert survey.metadata["description"] == "unit test"
    assert survey.camera("left").camera == CAM and survey.camera("left").mount == Mount.default(
        "left"
    )
    assert survey.camera("right").mount == Mount("right", -85.0, 40.0)
    # the images come back (JPEG: approximately); the band height identifies the frame
    for i in range(4):
        img = survey.read_image(f"right_{i:06d}")
        assert img.shape == (24, 32, 3)
        assert np.abs(img.astype(int) - _image(i)).mean() < 8
        assert survey.image_path(2 * i + 1) == root / "images" / f"right_{i:06d}.jpg"
    assert f.to_dataframe().shape == (8, 13)
    # nothing half-written remains
    assert not [p for p in root.rglob(".*")]


def test_frames_table_is_read_only(tmp_path: Path) -> None:
    survey = Survey.load(_write(tmp_path / "s", n=2))
    with pytest.raises(ValueError, match="read-only"):
        survey.frames.gps_s[0] = 0.0
    left = survey.frames.subset(survey.frames.side == "left")
    assert list(left.frame_id) == ["left_000000", "left_000001"]
    assert survey.frames.index_of("right_000001") == 3
    with pytest.raises(KeyError, match="nope"):
        survey.frames.index_of("nope")


def test_positions_are_mapped_on_the_track(tmp_path: Path) -> None:
    track = _straight_track()
    root = _write(tmp_path / "s", n=3, positions=True)
    survey = Survey.load(root, track=track)
    # ground truth from the geodesic construction: 100, 110, 120 m along a straight meridian
    assert np.allclose(survey.chainage_m, np.repeat([100.0, 110.0, 120.0], 2), atol=0.05)
    assert np.allclose(survey.frames.offset_m, 0.0, atol=0.05)
    assert np.allclose(survey.frames.h_m, 150.0)
    # without a track the chainage is unknown, not invented
    assert np.isnan(Survey.load(root).chainage_m).all()


def _survey_on_own_track(tmp_path: Path, track) -> Path:
    """Two frames per side on ``track``, written as ``tmp_path/track.csv`` and named in the
    survey's survey.yaml."""
    with open(tmp_path / "track.csv", "w") as fh:
        fh.write("lat_deg,lon_deg,h_m\n")
        for la, lo in zip(track.lat_deg, track.lon_deg, strict=True):
            fh.write(f"{float(la)!r},{float(lo)!r},150.0\n")
    return _write(
        tmp_path / "s", n=2, positions=True, track_name="straight", track_path="../track.csv"
    )


def test_track_file_named_in_survey_yaml_is_used(tmp_path: Path) -> None:
    pytest.importorskip("predisat.track.readers")  # the CSV reader (written in parallel)
    track = _straight_track()
    root = _survey_on_own_track(tmp_path, track)
    survey = Survey.load(root)
    assert survey.track_name == "straight"
    assert np.allclose(survey.chainage_m, np.repeat([100.0, 110.0], 2), atol=0.05)


def test_a_track_running_the_other_way_from_the_survey_s_own_is_refused(
    tmp_path: Path,
) -> None:
    """A user trial: a network's line reversed against the survey's own track was refused
    frame by frame, and "increasing" and "decreasing" each sent the user to the other."""
    track = _straight_track()
    root = _survey_on_own_track(tmp_path, track)
    back = type(track).from_latlon(track.lat_deg[::-1], track.lon_deg[::-1], 150.0, name="back")
    with pytest.raises(SurveyError, match=r"runs the other way from the survey's own track"):
        Survey.load(root, track=back)
    assert Survey.load(root, track=track).frames.chainage_m.size == 4  # the same way: fine


def test_reverse_survey_swaps_track_sides(tmp_path: Path) -> None:
    survey = Survey.load(_write(tmp_path / "s", n=2, direction_of_travel="decreasing"))
    assert survey.reverse
    assert list(survey.frames.track_side) == ["right", "left"] * 2


def test_writer_keeps_finished_frames_when_the_run_fails(tmp_path: Path) -> None:
    root = tmp_path / "s"
    with pytest.raises(RuntimeError, match="boom"), SurveyWriter(root, CAMERAS) as w:
        w.add_frame(_image(0), "left", GPS0, chainage_m=0.0)
        raise RuntimeError("boom")
    assert list(Survey.load(root).frames.frame_id) == ["left_000000"]


def test_writer_flushes_periodically(tmp_path: Path) -> None:
    w = SurveyWriter(tmp_path / "s", CAMERAS, flush_every=2)
    for i in range(3):
        w.add_frame(_image(i), "left", GPS0 + i, chainage_m=float(i))
    assert len(_rows(tmp_path / "s")) == 2  # flushed after the second frame, not yet closed
    w.close()
    assert len(_rows(tmp_path / "s")) == 3 and len(w) == 3
    with pytest.raises(RuntimeError, match="closed"):
        w.add_frame(_image(0), "left", GPS0 + 9, chainage_m=0.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"image_bgr": np.zeros((10, 10, 3), np.uint8)}, "shape"),
        ({"image_bgr": np.zeros((24, 32, 3), np.float32)}, "uint8"),
        ({"side": "top"}, "side"),
        ({"gps_s": GPS0 - 1}, "after the previous"),
        ({"chainage_m": None}, "chainage_m or lat_deg"),
        ({"frame_id": "left_000000"}, "unique"),
        ({"frame_id": "a/b"}, "letters"),
    ],
)
def test_writer_rejects_bad_frames(tmp_path: Path, kwargs: dict, match: str) -> None:
    with SurveyWriter(tmp_path / "s", CAMERAS) as w:
        w.add_frame(_image(0), "left", GPS0, chainage_m=0.0)
        args = {"image_bgr": _image(1), "side": "left", "gps_s": GPS0 + 1, "chainage_m": 10.0}
        with pytest.raises(ValueError, match=match):
            w.add_frame(**{**args, **kwargs})


def test_writer_refuses_to_overwrite(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=1)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        SurveyWriter(root, CAMERAS)
    with pytest.raises(ValueError, match="reserved"):
        SurveyWriter(tmp_path / "t", CAMERAS, metadata={"cameras": 1})


# ---------------------------------------------------------------------- per-frame problems


def _only(problems: tuple[SurveyProblem, ...], frame_id: str, match: str) -> SurveyProblem:
    hits = [p for p in problems if p.frame_id == frame_id]
    assert len(hits) == 1, problems
    assert match in hits[0].message, hits[0]
    return hits[0]


def test_missing_unreadable_and_wrong_size_images(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=3)
    (root / "images" / "left_000001.jpg").unlink()
    (root / "images" / "right_000001.jpg").write_bytes(b"not an image at all")
    _, buf = cv2.imencode(".png", np.zeros((30, 40, 3), np.uint8))
    (root / "images" / "left_000002.jpg").write_bytes(buf.tobytes())  # PNG content, 40x30
    problems = _problems(root)
    assert len(problems) == 3
    p = _only(problems, "left_000001", "missing")
    assert p.row == 4 and "manifest line 4" in str(p) and "left_000001" in str(p)
    _only(problems, "right_000001", "cannot be read")
    _only(problems, "left_000002", "40x30 px")
    # check_images=False trusts the files
    assert len(Survey.load(root, check_images=False).frames) == 6


def test_image_check_reads_headers_only(tmp_path: Path) -> None:
    from PIL import Image

    root = _write(tmp_path / "s", n=1)
    path = root / "images" / "left_000000.jpg"
    data = path.read_bytes()
    path.write_bytes(data[: data.index(b"\xff\xda") + 16])  # header intact, pixels gone
    with Image.open(path) as im, pytest.raises(OSError):
        im.load()  # the image cannot be decoded...
    assert len(Survey.load(root).frames) == 2  # ...and loading did not try


def test_unknown_side_bad_numbers_and_missing_position(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=4)
    rows = _rows(root)
    rows[0]["side"] = "bonnet"
    rows[1]["gps_s"] = "12:00:01"
    rows[2]["chainage_m"] = "1O0.0"
    rows[3]["chainage_m"] = ""
    rows[4]["gps_s"] = ""
    rows[5]["lat_deg"] = "50.5"
    _save_rows(root, rows)
    problems = _problems(root)
    _only(problems, "left_000000", "side 'bonnet' is unknown")
    _only(problems, "right_000000", "gps_s '12:00:01' is not a finite number")
    _only(problems, "left_000001", "chainage_m '1O0.0'")
    _only(problems, "right_000001", "no position")
    _only(problems, "left_000002", "gps_s is empty")
    _only(problems, "right_000002", "lat_deg and lon_deg must be given together")
    assert [p.row for p in problems] == sorted(p.row for p in problems)  # type: ignore[type-var]


def test_side_without_camera(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=2)
    doc = yaml.safe_load((root / "survey.yaml").read_text())
    del doc["cameras"]["right"]
    (root / "survey.yaml").write_text(yaml.safe_dump(doc))
    problems = _problems(root)
    assert {p.frame_id for p in problems} == {"right_000000", "right_000001"}
    assert "add cameras.right" in problems[0].message


def test_time_going_backwards_per_side(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=4)
    rows = _rows(root)
    rows[4]["gps_s"] = repr(GPS0 + 0.5)  # left_000002 earlier than left_000001 (GPS0 + 1)
    rows[7]["gps_s"] = repr(GPS0 + 2.5)  # right_000003 still after right_000002: fine
    _save_rows(root, rows)
    problems = _problems(root)
    assert len(problems) == 1
    p = _only(problems, "left_000002", "goes back in time on the left side")
    assert "left_000001" in p.message and p.row == 6


@pytest.mark.parametrize(
    ("column", "value", "match"),
    [
        ("frame_id", "left_000000",
         "duplicate frame_id (first at manifest line 2); make ids unique (until then both rows"),
        ("image", "images/left_000000.jpg", "also listed at manifest line 2"),
        ("gps_s", repr(GPS0), "same side and gps_s as frame 'left_000000'"),
    ],
)
def test_duplicates(tmp_path: Path, column: str, value: str, match: str) -> None:
    root = _write(tmp_path / "s", n=2)
    rows = _rows(root)
    rows[2][column] = value  # the second left frame
    _save_rows(root, rows)
    problems = _problems(root)
    assert len(problems) == 1 and problems[0].row == 4 and match in problems[0].message


def test_image_paths_must_stay_inside_the_survey(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=2)
    rows = _rows(root)
    rows[0]["image"] = "../elsewhere.jpg"
    rows[1]["image"] = str(root / "images" / "right_000000.jpg")
    _save_rows(root, rows)
    problems = _problems(root)
    assert {p.frame_id for p in problems} == {"left_000000", "right_000000"}
    assert all("relative path" in p.message for p in problems)


def test_off_track_positions(tmp_path: Path) -> None:
    track = _straight_track()
    root = _write(tmp_path / "s", n=3, positions=True)
    rows = _rows(root)
    lon, lat, _ = WGS84.fwd(float(rows[3]["lon_deg"]), float(rows[3]["lat_deg"]), 90.0, 25.0)
    rows[3]["lat_deg"], rows[3]["lon_deg"] = repr(lat), repr(lon)  # 25 m east of the axis
    lon, lat, _ = WGS84.fwd(LON0, LAT0, 180.0, 60.0)  # 60 m before the start of the track
    rows[4]["lat_deg"], rows[4]["lon_deg"] = repr(lat), repr(lon)
    _save_rows(root, rows)
    problems = _problems(root, track=track)
    assert "25.0 m from track 'straight'" in _only(problems, "right_000001", "m from track").message
    _only(problems, "left_000002", "m from track")
    assert len(problems) == 2
    # left_000002 is then 110 m behind the frame 1 s before it: over max_speed_mps too, and
    # with both limits loosened still a run backwards in time: it and that frame are left out
    loose = Survey.load(root, track=track, max_offset_m=100.0, max_speed_mps=200.0,
                        on_error="skip")  # fmt: skip
    assert len(loose.frames) == 4 and "left_000002" not in loose.frames.frame_id


def test_chainage_disagreeing_with_the_position_is_refused(tmp_path: Path) -> None:
    track = _straight_track()
    root = _write(tmp_path / "s", n=3, positions=True)  # at 100, 110, 120 m (geodesic)
    rows = _rows(root)
    rows[2]["chainage_m"] = "150.0"  # left_000001 lies at 110 m: an odometer typo of 40 m
    rows[3]["chainage_m"] = "113.0"  # right_000001 at 110 m: 3 m, within the 10 m limit
    _save_rows(root, rows)
    problems = _problems(root, track=track)
    msg = _only(problems, "left_000001", "disagrees").message
    assert "chainage_m 150.0" in msg and "chainage 110.0 m" in msg
    assert len(problems) == 1
    # a frame off the track is told how far off, not that its chainage disagrees there (a
    # user trial's survey in another line's folder was told of a chainage at the track's end)
    lon, lat, _ = WGS84.fwd(LON0, LAT0, 0.0, 1600.0)  # 600 m past the end of the 1 km track
    rows[4]["lat_deg"], rows[4]["lon_deg"] = repr(lat), repr(lon)
    rows[4]["chainage_m"] = "120.0"
    _save_rows(root, rows)
    off = [p for p in _problems(root, track=track) if p.frame_id == "left_000002"]
    assert len(off) == 1 and "600.0 m from track" in off[0].message, off
    survey = Survey.load(root, track=track, on_error="skip")
    assert "left_000001" not in list(survey.frames.frame_id)
    assert survey.chainage_m[list(survey.frames.frame_id).index("right_000001")] == 113.0


def test_chainage_outside_the_track(tmp_path: Path) -> None:
    @dataclass(frozen=True)
    class StandInTrack:  # anything with length_m and project() will do
        name: str = "stand-in"
        length_m: float = 115.0

        def project(self, lat_deg, lon_deg, h_m=None):
            raise AssertionError("no positions in this survey")

    root = _write(tmp_path / "s", n=3)  # chainages 100, 110, 120
    problems = _problems(root, track=StandInTrack(length_m=105.0))
    assert {p.frame_id for p in problems} == {"left_000002", "right_000002"}
    assert "outside track 'stand-in'" in problems[0].message


def test_skip_mode_drops_bad_frames_and_reports_them(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=4)
    (root / "images" / "right_000002.jpg").unlink()
    rows = _rows(root)
    rows[2]["gps_s"] = "soon"
    _save_rows(root, rows)
    survey = Survey.load(root, on_error="skip")
    assert len(survey.frames) == 6
    assert "left_000001" not in survey.frames.frame_id
    assert "right_000002" not in survey.frames.frame_id
    assert {p.frame_id for p in survey.problems} == {"left_000001", "right_000002"}
    with pytest.raises(ValueError, match="on_error"):
        Survey.load(root, on_error="ignore")  # type: ignore[arg-type]


# ---------------------------------------------------------------------- survey-level problems


def test_missing_columns_are_fatal_even_when_skipping(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=1)
    _save_rows(root, _rows(root), columns=("frame_id", "image", "side"))
    with pytest.raises(SurveyError, match=r"missing column\(s\) \['gps_s', 'chainage_m") as info:
        Survey.load(root, on_error="skip")
    assert info.value.problems[0].frame_id is None


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"version": 2}, "version 2 is not supported"),
        ({"format": "something-else"}, "format must be 'predisat-survey'"),
        ({"direction_of_travel": "north"}, "direction_of_travel"),
        ({"antenna_height_m": "tall"}, "antenna_height_m"),
        # a user trial: -4 trusted blocked directions, 400 (centimetres) lost the whole sky
        ({"antenna_height_m": -4.0}, r"antenna_height_m -4 is not a height .* \(0, 8\]"),
        ({"antenna_height_m": 400}, r"antenna_height_m 400 .* centimetres"),
        ({"chainage_doubt_m": -3}, r"chainage_doubt_m must be a length >= 0 .* got -3"),
        ({"chainage_doubt_m": "rtk"}, r"chainage_doubt_m must be a length"),
        ({"cameras": {"bonnet": {"calibration": "calib/left.yaml"}}}, "camera side 'bonnet'"),
        ({"cameras": {"left": {"calibration": "calib/nope.yaml"}}}, "nope.yaml"),
        ({"cameras": {"left": {"calibration": "calib/left.yaml", "mount": {"tilt": 1}}}}, "tilt"),
    ],
)
def test_bad_survey_yaml(tmp_path: Path, changes: dict, match: str) -> None:
    root = _write(tmp_path / "s", n=1)
    _edit_yaml(root, **changes)
    with pytest.raises(SurveyError, match=match):
        Survey.load(root, on_error="skip")


def test_the_survey_states_its_chainage_doubt(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=1)
    assert Survey.load(root).chainage_doubt_m is None  # not stated
    _edit_yaml(root, chainage_doubt_m=2.5)
    survey = Survey.load(root)
    assert survey.chainage_doubt_m == 2.5 and "chainage_doubt_m" not in survey.metadata


def test_the_writer_states_the_doubt_and_the_jitter(tmp_path: Path) -> None:
    """A docs audit: chainage_jitter_m could be read but not written (a keyword refused, the
    metadata key reserved)."""
    root = _write(tmp_path / "s", n=1, chainage_doubt_m=3.0, chainage_jitter_m=0.05)
    survey = Survey.load(root)
    assert (survey.chainage_doubt_m, survey.chainage_jitter_m) == (3.0, 0.05)
    with pytest.raises(ValueError, match="needs a chainage_doubt_m at least as large"):
        SurveyWriter(tmp_path / "t", CAMERAS, chainage_doubt_m=0.01, chainage_jitter_m=0.05)
    with pytest.raises(ValueError, match="chainage_jitter_m must be a length"):
        SurveyWriter(tmp_path / "u", CAMERAS, chainage_doubt_m=1.0, chainage_jitter_m=-1.0)


def test_unsupported_calibration_in_survey(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=1)
    (root / "calib" / "left.yaml").write_text(
        "model_type: MEI\nimage_width: 32\nimage_height: 24\n"
    )
    with pytest.raises(SurveyError, match=r"cameras\.left\.calibration: .*left\.yaml.*MEI"):
        Survey.load(root)


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(SurveyError, match="not a folder"):
        Survey.load(tmp_path / "nowhere")
    root = _write(tmp_path / "s", n=1)
    (root / "manifest.csv").unlink()
    with pytest.raises(SurveyError, match=r"manifest\.csv is missing"):
        Survey.load(root / "survey.yaml")  # the yaml path is accepted too
    (root / "survey.yaml").unlink()
    with pytest.raises(SurveyError, match=r"survey\.yaml is missing"):
        Survey.load(root)


def test_error_message_lists_every_problem(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=3)
    for p in (root / "images").iterdir():
        p.unlink()
    with pytest.raises(SurveyError) as info:
        Survey.load(root)
    text = str(info.value)
    assert "6 problem(s)" in text
    assert all(f"{side}_00000{i}" in text for side in ("left", "right") for i in range(3))


def test_chainage_jump_contradicting_the_run_is_refused(tmp_path: Path) -> None:
    """No position to check the chainage against: only the time tells an odometer typo."""
    root = _write(tmp_path / "s", n=5)  # 100..140 m, 1 s apart per side
    rows = _rows(root)
    rows[4]["chainage_m"] = "320.0"  # left_000002 at 120 m: a typo of 200 m in 1 s
    rows[9]["chainage_m"] = "900.0"  # right_000004, the last frame: 760 m in 1 s
    _save_rows(root, rows)
    problems = _problems(root)
    msg = _only(problems, "left_000002", "contradicts the run").message
    assert "chainage_m 320.0" in msg and "'left_000001' (line 4" in msg and "210 m/s" in msg
    _only(problems, "right_000004", "contradicts the run")
    assert len(problems) == 2 and problems[0].row == 6
    assert "manifest line 6, frame 'left_000002'" in str(problems[0])
    survey = Survey.load(root, on_error="skip")
    assert len(survey.frames) == 8
    # with a speed limit of 1000 m/s the last frame's jump ahead passes (the limit is the
    # caller's), but the typo still runs 190 m backwards to the next frame: both are left out
    back = Survey.load(root, max_speed_mps=1000.0, on_error="skip")
    assert len(back.frames) == 8 and "left_000002" not in back.frames.frame_id
    assert "left_000003" not in back.frames.frame_id and "right_000004" in back.frames.frame_id


def test_one_time_far_ahead_is_that_frame_s_problem_not_every_later_one(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=5)
    rows = _rows(root)
    rows[4]["gps_s"] = repr(GPS0 + 86400.0 + 2)  # left_000002: a day ahead (a clock glitch)
    _save_rows(root, rows)
    problems = _problems(root)
    assert len(problems) == 1  # not left_000003 and left_000004 "going back in time"
    msg = _only(problems, "left_000002", "later than the next two frames on the left").message
    assert "'left_000003' at line 8" in msg and "fix the time" in msg
    survey = Survey.load(root, on_error="skip")
    assert "left_000002" not in list(survey.frames.frame_id) and len(survey.frames) == 9


def test_a_run_against_its_direction_of_travel_is_refused(tmp_path: Path) -> None:
    """``direction_of_travel`` says which camera is on which side of the track and which way
    is ahead: a survey whose chainage runs the other way in time would get every mask wrong
    (a user trial: 5.7 % false trust, silently). Refused, naming both ends and the fix."""
    root = _write(tmp_path / "s", n=5)  # 100..140 m, increasing in time
    yaml_path = root / "survey.yaml"
    yaml_path.write_text(yaml_path.read_text().replace("increasing", "decreasing"))
    with pytest.raises(SurveyError, match=r"direction_of_travel is decreasing, but the left "
                       r"frames' chainage runs the other way in time \(100.0 m at line 2, "
                       r"140.0 m at line 10.*set direction_of_travel: increasing"):  # fmt: skip
        Survey.load(root, on_error="skip")


def test_two_swapped_chainages_are_both_left_out(tmp_path: Path) -> None:
    """Without positions, two neighbouring chainages swapped in the manifest run backwards in
    time: which one is wrong cannot be told, so neither frame is used."""
    root = _write(tmp_path / "s", n=6)
    rows = _rows(root)
    rows[4]["chainage_m"], rows[6]["chainage_m"] = rows[6]["chainage_m"], rows[4]["chainage_m"]
    _save_rows(root, rows)
    problems = _problems(root)
    assert {p.frame_id for p in problems} == {"left_000002", "left_000003"}
    assert all("backwards in time" in p.message for p in problems)
    kept = Survey.load(root, on_error="skip").frames.frame_id
    assert len(kept) == 10 and "left_000002" not in kept and "left_000003" not in kept


def test_a_calibration_that_fits_none_of_its_camera_s_images_is_a_survey_problem(
    tmp_path: Path,
) -> None:
    """Every image of a camera of another size than its calibration: the calibration is
    another camera's, not a few bad frames; skipping them all would leave masks from the
    other camera alone (a user trial: exit 0 and one camera's masks). Refused even when bad
    frames are skipped; one bad image among good ones stays that frame's problem."""
    root = _write(tmp_path / "s", n=4)
    small = np.zeros((48, 64, 3), np.uint8)
    for f in sorted((root / "images").rglob("left_*")):
        cv2.imwrite(str(f), small)
    with pytest.raises(SurveyError, match=r"camera 'left': all 4 of its images are 64x48 px"):
        Survey.load(root, on_error="skip")
    root = _write(tmp_path / "t", n=4)
    cv2.imwrite(str(sorted((root / "images").rglob("left_*"))[0]), small)
    assert len(Survey.load(root, on_error="skip").frames) == 7


def test_a_side_camera_s_mount_in_radians_is_a_survey_problem(tmp_path: Path) -> None:
    """A mount's angles written in radians (``pitch_deg: 0.785398`` for 45 deg): a user
    trial's survey was read as cameras looking level, every skyline 45 deg too low, 26.8 % of
    the trusted directions blocked, exit 0. Refused, naming the value in degrees."""
    import yaml

    root = _write(tmp_path / "s", n=3)
    Survey.load(root)  # the right camera's -85 / 40 deg: degrees
    spec = yaml.safe_load((root / "survey.yaml").read_text())
    for key, value, deg in (("pitch_deg", 0.698132, "40.0"), ("yaw_deg", -1.48353, "-85.0")):
        bad = dict(spec, cameras=dict(spec["cameras"]))
        bad["cameras"]["right"] = dict(spec["cameras"]["right"])
        bad["cameras"]["right"]["mount"] = dict(spec["cameras"]["right"]["mount"], **{key: value})
        (root / "survey.yaml").write_text(yaml.safe_dump(bad))
        with pytest.raises(SurveyError, match=rf"cameras.right.mount: {key} {value:g} reads as "
                                              rf"radians \({deg} deg\)"):  # fmt: skip
            Survey.load(root, on_error="skip")
    # a level side camera (pitch 0) and a small roll are degrees as they stand
    bad["cameras"]["right"]["mount"] = dict(spec["cameras"]["right"]["mount"], pitch_deg=0.0,
                                            roll_deg=0.5)  # fmt: skip
    (root / "survey.yaml").write_text(yaml.safe_dump(bad))
    assert Survey.load(root).cameras["right"].mount.pitch_deg == 0.0


def test_a_near_level_side_camera_stated_in_degrees_loads(tmp_path: Path) -> None:
    """A side camera behind a window, pitched 1 deg up (or 1.2 deg down), reads as a mount in
    radians: refused with the way out named, and loaded once the mount says its angles are
    degrees (a review: there was no way to give such a camera but to falsify its pitch)."""
    import yaml

    root = _write(tmp_path / "s", n=3)
    spec = yaml.safe_load((root / "survey.yaml").read_text())
    right = dict(spec["cameras"]["right"]["mount"])
    for pitch in (1.0, -1.2):
        mount = dict(right, pitch_deg=pitch)
        spec["cameras"]["right"]["mount"] = mount
        (root / "survey.yaml").write_text(yaml.safe_dump(spec))
        with pytest.raises(SurveyError, match="angles_in_degrees: true"):
            Survey.load(root, on_error="skip")
        spec["cameras"]["right"]["mount"] = dict(mount, angles_in_degrees=True)
        (root / "survey.yaml").write_text(yaml.safe_dump(spec))
        assert Survey.load(root).cameras["right"].mount.pitch_deg == pitch


def test_process_refuses_a_calibration_that_fits_none_of_its_camera_s_images(
    tmp_path: Path,
) -> None:
    """``process`` loads a survey without reading its images (check_images=False), so the
    check above never ran there: a user trial's left calibration of 640x480 beside 800x600
    images made 41 bad frames, 100 % assumed masks and exit 0. It is now made on the image
    headers before any work; a correct survey or a few bad images pass."""
    from predisat.reconstruct.batch import process_survey
    from predisat.survey.load import check_calibration_sizes

    root = _write(tmp_path / "s", n=4)
    small = np.zeros((48, 64, 3), np.uint8)
    check_calibration_sizes(Survey.load(root, check_images=False, on_error="skip"))
    first = sorted((root / "images").rglob("left_*"))[0]
    cv2.imwrite(str(first), small)
    check_calibration_sizes(Survey.load(root, check_images=False, on_error="skip"))
    for f in sorted((root / "images").rglob("left_*")):
        cv2.imwrite(str(f), small)
    survey = Survey.load(root, check_images=False, on_error="skip")
    with pytest.raises(SurveyError, match=r"camera 'left': all 4 of its images are 64x48 px"):
        check_calibration_sizes(survey)
    with pytest.raises(SurveyError, match=r"camera 'left': all 4 of its images are 64x48 px"):
        process_survey(root, tmp_path / "out", progress=False)
    assert not (tmp_path / "out" / "masks.parquet").exists()


# ---------------------------------------------------------------------- vehicle attitude


def test_measured_attitude_round_trips_and_is_nan_when_not_given(tmp_path: Path) -> None:
    with SurveyWriter(tmp_path / "s", CAMERAS) as w:
        w.add_frame(_image(0), "left", GPS0, chainage_m=0.0, roll_deg=-6.25, pitch_deg=0.5)
        w.add_frame(_image(1), "left", GPS0 + 1, chainage_m=10.0)
    f = Survey.load(tmp_path / "s").frames
    assert f.roll_deg[0] == -6.25 and f.pitch_deg[0] == 0.5
    assert np.isnan(f.roll_deg[1]) and np.isnan(f.pitch_deg[1])


def test_a_manifest_without_attitude_columns_reads_as_not_measured(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=2)
    _save_rows(root, _rows(root), MANIFEST_COLUMNS[:8])  # a manifest written before them
    assert "roll_deg" not in (root / "manifest.csv").read_text().splitlines()[0]
    f = Survey.load(root).frames
    assert np.isnan(f.roll_deg).all() and np.isnan(f.pitch_deg).all()


def test_bad_attitudes_are_named_with_their_fix(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=2)
    rows = _rows(root)
    rows[0]["roll_deg"], rows[0]["pitch_deg"] = "35", "0"  # radians taken for degrees, or axes
    rows[1]["roll_deg"], rows[1]["pitch_deg"] = "1.0", ""
    rows[2]["roll_deg"], rows[2]["pitch_deg"] = "0", "-12"
    rows[3]["roll_deg"], rows[3]["pitch_deg"] = "nan", "0"
    _save_rows(root, rows)
    problems = _problems(root)
    _only(problems, "left_000000", "roll_deg 35 is beyond +-20 deg")
    _only(problems, "right_000000", "roll_deg and pitch_deg must be given together")
    _only(problems, "left_000001", "pitch_deg -12 is beyond +-10 deg")
    _only(problems, "right_000001", "roll_deg 'nan' is not a finite number")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"roll_deg": 1.0}, "together"),
        ({"roll_deg": 25.0, "pitch_deg": 0.0}, "roll_deg"),
        ({"roll_deg": 0.0, "pitch_deg": float("inf")}, "pitch_deg"),
    ],
)
def test_writer_rejects_bad_attitudes(tmp_path: Path, kwargs: dict, match: str) -> None:
    with SurveyWriter(tmp_path / "s", CAMERAS) as w:
        with pytest.raises(ValueError, match=match):
            w.add_frame(_image(0), "left", GPS0, chainage_m=0.0, **kwargs)


def test_chainages_in_kilometres_are_refused_a_standstill_is_not(tmp_path: Path) -> None:
    """A km-post export read as metres put a survey of km 4.00-4.04 at 4 m, and its masks,
    made from frames 1 cm apart, trusted 0.96 % of directions falsely (a user trial)."""
    root = _write(tmp_path / "km", n=5)
    rows = _rows(root)
    for r in rows:
        r["chainage_m"] = f"{float(r['chainage_m']) / 1000.0:.3f}"  # 0.100 ... 0.140
    _save_rows(root, rows)
    (p,) = _problems(root)
    assert "left frames' chainage_m reads as kilometres: 0.1 at line 2 to 0.14" in p.message
    assert "in metres: 36 km/h" in p.message and "give chainage_m in metres" in p.message
    # one typo row, and a short survey of 3 frames per side, do not hide it (a review)
    rows[4]["chainage_m"] = "0.500"
    _save_rows(root, rows)
    assert any("reads as kilometres" in p.message for p in _problems(root))
    root = _write(tmp_path / "km3", n=3)
    rows = _rows(root)
    for r in rows:
        r["chainage_m"] = f"{float(r['chainage_m']) / 1000.0:.3f}"
    _save_rows(root, rows)
    assert any("reads as kilometres" in p.message for p in _problems(root))
    # a train standing still, its odometer jittering by centimetres, then moving on
    root = _write(tmp_path / "stand", n=6)
    rows = _rows(root)
    jitter = {0: 100.0, 1: 100.01, 2: 100.0, 3: 100.02, 4: 100.01, 5: 100.0}  # never moves on
    for r in rows:
        r["chainage_m"] = str(jitter[int(r["frame_id"].split("_")[-1])])
    _save_rows(root, rows)
    assert len(Survey.load(root).frames) == 12


def test_a_manifest_as_a_spreadsheet_saves_it(tmp_path: Path) -> None:
    """Semicolons were "missing columns", Excel's empty columns "duplicate column ['']", and
    Roll_deg in another case was ignored without a word (a user trial)."""
    root = _write(tmp_path / "s", n=3)
    text = (root / "manifest.csv").read_text()
    plain = Survey.load(root).frames
    (root / "manifest.csv").write_text(text.replace(",", ";"))
    (p,) = _problems(root)
    assert "separated by semicolons, not commas" in p.message
    lines = text.splitlines()
    (root / "manifest.csv").write_text("\n".join(line + ",,," for line in lines) + "\n")
    frames = Survey.load(root).frames
    np.testing.assert_array_equal(frames.chainage_m, plain.chainage_m)
    assert list(frames.frame_id) == list(plain.frame_id)
    head = lines[0].replace("roll_deg", "Roll_deg").replace("pitch_deg", "Pitch_deg")
    (root / "manifest.csv").write_text("\n".join([head, *lines[1:]]) + "\n")
    (p,) = _problems(root)
    assert "rename 'Roll_deg' to 'roll_deg', 'Pitch_deg' to 'pitch_deg'" in p.message


def test_the_folder_above_a_survey_points_to_it(tmp_path: Path) -> None:
    """A user trial gave `predisat synth`'s output folder, which holds the survey in its
    `survey/`; the message only said survey.yaml was missing."""
    _write(tmp_path / "synth" / "survey", n=1)
    (p,) = _problems(tmp_path / "synth")
    assert f"the survey is in {tmp_path / 'synth' / 'survey'}; give that folder" in p.message
    (tmp_path / "empty").mkdir()
    (q,) = _problems(tmp_path / "empty")
    assert q.message == "survey.yaml is missing; see docs/survey-format.md"


def test_a_manifest_listing_every_frame_twice_keeps_every_frame(tmp_path: Path) -> None:
    """A manifest written twice over (a user trial): each repeat is left out, the frames stay,
    and the problem names no frame (a frame is known by its id: a duplicate id leaves both
    rows out, and every frame was lost, the masks 100 % assumed)."""
    root = _write(tmp_path / "s", n=3)
    rows = _rows(root)
    _save_rows(root, rows + rows)
    survey = Survey.load(root, on_error="skip", check_images=False)
    assert list(survey.frames.frame_id) == [r["frame_id"] for r in rows]
    assert len(survey.problems) == len(rows)
    assert all(p.frame_id is None and "repeats manifest line" in p.message
               for p in survey.problems)  # fmt: skip
    # a repeat that differs in one field is still a duplicate id: both rows left out
    rows2 = [*rows, dict(rows[0], chainage_m="105.0")]
    _save_rows(root, rows2)
    probs = Survey.load(root, on_error="skip", check_images=False).problems
    assert {p.row for p in probs} == {len(rows2) + 1}
    assert any(p.frame_id == "left_000000" and "duplicate frame_id" in p.message for p in probs)
