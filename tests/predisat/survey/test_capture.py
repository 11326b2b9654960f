"""Capture times: a camera's clock fitted over a survey tells which images are rows off."""

from __future__ import annotations

import io

import cv2
import numpy as np
import pytest
from PIL import Image

from predisat.camera.models import Mount, default_camera
from predisat.survey import SurveyWriter
from predisat.survey.capture import (
    MIN_TIMED_FRAMES,
    capture_time_s,
    check_rows,
    exif_time_bytes,
    fit_clock,
    read_capture_time_s,
)

_UNIX_2024 = 1718957702.0  # 2024-06-21 08:15:02 UTC


def _rows(n: int, varying: bool, seed: int = 0) -> np.ndarray:
    """A camera's row times every 10 m at 20 m/s, or at a speed swinging 12-28 m/s."""
    speed = 20.0 + (8.0 * np.sin(np.arange(n) / 40.0) if varying else 0.0)
    return 1.4e9 + np.cumsum(10.0 / np.broadcast_to(speed, (n,)))


def _stamps(gps_s, source, seed=0, offset_s=3617.25, drift_ppm=35.0, jitter_s=0.002,
            digits=3):  # fmt: skip
    """The camera's EXIF times of images taken at the rows ``source`` (clock offset, drift,
    stamping scatter, rounded to ``digits``)."""
    rng = np.random.default_rng(seed)
    g = np.asarray(gps_s)
    taken = g[np.asarray(source)]
    t = taken + offset_s + drift_ppm * 1e-6 * (taken - g[0]) + rng.normal(0, jitter_s, g.size)
    return np.round(t, digits)


def test_exif_time_round_trips_through_a_written_jpeg(tmp_path) -> None:
    cam = default_camera("fisheye").resized(64, 48)
    with SurveyWriter(tmp_path / "s", {"left": (cam, Mount.default("left"))}) as w:
        w.add_frame(np.zeros((48, 64, 3), np.uint8), "left", 10.0, chainage_m=0.0,
                    capture_time_s=_UNIX_2024 + 0.125)  # fmt: skip
        w.add_frame(np.zeros((48, 64, 3), np.uint8), "left", 11.0, chainage_m=10.0)
    t, res = read_capture_time_s(tmp_path / "s" / "images" / "left_000000.jpg")
    assert t == pytest.approx(_UNIX_2024 + 0.125, abs=1e-6) and res == pytest.approx(0.001)
    # PIL reads the same clock text the writer put there
    with Image.open(tmp_path / "s" / "images" / "left_000000.jpg") as im:
        assert im.getexif().get_ifd(0x8769)[0x9003] == "2024:06:21 08:15:02"
    assert np.isnan(read_capture_time_s(tmp_path / "s" / "images" / "left_000001.jpg")[0])
    assert np.isnan(read_capture_time_s(tmp_path / "s" / "missing.jpg")[0])
    # the pixels are those of the JPEG without the EXIF block
    a = cv2.imread(str(tmp_path / "s" / "images" / "left_000000.jpg"))
    b = cv2.imread(str(tmp_path / "s" / "images" / "left_000001.jpg"))
    assert np.array_equal(a, b)


def test_whole_second_stamps_have_a_one_second_resolution() -> None:
    buf = io.BytesIO()
    Image.new("RGB", (8, 8)).save(buf, "JPEG", exif=exif_time_bytes(_UNIX_2024 + 0.7, 0))
    with Image.open(io.BytesIO(buf.getvalue())) as im:
        t, res = capture_time_s(im)
    assert t == _UNIX_2024 + 1.0 and res == 1.0
    with pytest.raises(ValueError, match="digits"):
        exif_time_bytes(0.0, 7)


@pytest.mark.parametrize("varying", [False, True])
def test_the_clock_is_found_through_offset_drift_and_jitter(varying) -> None:
    g = _rows(800, varying)
    e = _stamps(g, np.arange(g.size))
    fit = fit_clock(e, g)
    assert fit is not None and fit.fitted == fit.timed == g.size
    assert fit.offset_s == pytest.approx(3617.25, abs=0.003)
    assert fit.drift_ppm == pytest.approx(35.0, abs=5.0)
    assert 0.005 < fit.tol_s < 0.03 and not fit.ambiguous
    assert not check_rows(e, g, fit).off.any()


@pytest.mark.parametrize("varying", [False, True])
@pytest.mark.parametrize("case", ["middle", "tail", "swap"])
def test_exactly_the_images_off_their_rows_are_found(varying, case) -> None:
    g = _rows(600, varying)
    src = np.arange(g.size)
    if case == "middle":  # a dropped image, then an extra one 60 rows later
        src[200:260] += 1
    elif case == "tail":  # a dropped image: every later image on the row before its own
        src[100:-1] += 1
    else:
        src[[300, 301]] = src[[301, 300]]
    e = _stamps(g, src, seed=3)
    fit = fit_clock(e, g)
    rows = check_rows(e, g, fit)
    moved = src != np.arange(g.size)
    assert np.array_equal(rows.off, moved)
    assert np.all(rows.lag[moved] == (src - np.arange(g.size))[moved])
    # at one speed, a clock a frame gap off (every other image a row off) explains as much
    assert fit.ambiguous == (not varying)


def test_a_survey_shifted_from_its_first_row_is_found_where_the_speed_varies() -> None:
    g = _rows(600, varying=True)
    src = np.minimum(np.arange(g.size) + 1, g.size - 1)
    rows = check_rows(e := _stamps(g, src), g, fit_clock(e, g))
    assert rows.off[:-1].all()


def test_times_that_cannot_tell_a_row_are_not_checked() -> None:
    g = _rows(300, varying=True)  # frames 0.36-0.83 s apart
    e = _stamps(g, np.arange(g.size), digits=0)
    fit = fit_clock(e, g, resolution_s=1.0)
    assert fit is not None and fit.tol_s >= 2.0
    rows = check_rows(e, g, fit)
    assert not rows.checked.any() and not rows.off.any()
    e50 = _stamps(g, np.arange(g.size), jitter_s=0.05)
    rows50 = check_rows(e50, g, fit_clock(e50, g))
    assert not rows50.off.any()  # a 50 ms scatter widens the tolerance, not the alarms


def test_times_that_do_not_follow_the_rows_fit_no_clock() -> None:
    g = _rows(300, varying=True)
    rewritten = np.sort(np.random.default_rng(1).uniform(0, 5000, g.size)) + 1.7e9
    fit = fit_clock(rewritten, g)
    assert fit is not None and fit.share < 0.5
    few = np.full(g.size, np.nan)
    few[: MIN_TIMED_FRAMES - 1] = g[: MIN_TIMED_FRAMES - 1]
    assert fit_clock(few, g) is None


def test_fit_clock_refuses_bad_input() -> None:
    with pytest.raises(ValueError, match="one length"):
        fit_clock(np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="increasing"):
        fit_clock(np.zeros(20), np.ones(20))
    with pytest.raises(ValueError, match="resolution_s"):
        fit_clock(np.zeros(20), np.arange(20.0), resolution_s=0.0)


def test_a_drop_among_the_first_frames_after_a_speed_up_is_found() -> None:
    """Speeding up over 15 frames, then 100 km/h: a clock one gap off explains every cruise
    frame and leaves the speed-up's on no row, so its first *fitted* frames sit on their own
    rows; the clock whose first timed frames do is the camera's (a review: every shifted frame
    was missed with a drop at frames 1-14)."""
    v = np.concatenate([np.linspace(8.0, 27.78, 15), np.full(1185, 27.78)])
    g = 1.4e9 + np.cumsum(10.0 / v)
    for k in (1, 2, 6, 14):
        src = np.arange(g.size)
        src[k:-1] += 1
        e = _stamps(g, src, seed=k)
        rows = check_rows(e, g, fit_clock(e, g))
        assert np.array_equal(rows.off[:-1], (src != np.arange(g.size))[:-1]), k


def test_times_several_rows_off_where_the_speed_varies_fit_no_reliable_clock() -> None:
    g = _rows(800, varying=True)
    src = np.minimum(np.arange(g.size) + 4, g.size - 1)  # 4 rows off, beyond the lags tried
    fit = fit_clock(_stamps(g, src), g)
    assert fit is not None and not fit.reliable and fit.share == 0.0
