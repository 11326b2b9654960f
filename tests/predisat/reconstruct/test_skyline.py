"""Tests of skyline directions and sky profiles against analytic camera geometry."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from predisat.camera.models import CameraModel, Mount, default_camera
from predisat.reconstruct.skyline import (
    LOW_CONFIDENCE_WINDOW_DEG,
    Rectifier,
    _raise_skyline,
    _raise_skyline_deg,
    erode_sky_deg,
    leading_sky_rows,
    skyline_directions,
)
from predisat.sky.segment import confidence_window_px, fisheye_valid_mask

PITCH = 45.0
VFOV = 74.0


@pytest.fixture(scope="module")
def pinhole() -> CameraModel:
    """Undistorted 400x300 pinhole with a 74 deg vertical field of view."""
    return CameraModel.pinhole_from_fov(400, 300, VFOV)


def elevation_sky(camera: CameraModel, mount: Mount, heading_deg: float, el_deg: float):
    """Sky mask of a world whose skyline is the elevation ``el_deg`` at every azimuth,
    built from the camera model's own rays (not from the module under test)."""
    u, v = camera.pixel_grid()
    ray = camera.pixel_to_ray(u, v) @ mount.camera_to_enu(heading_deg).T
    el = np.degrees(np.arcsin(np.clip(ray[..., 2], -1, 1)))
    return el > el_deg


def test_leading_sky_rows_counts_sky_above_the_highest_obstacle() -> None:
    m = np.ones((6, 4), bool)
    m[3:, 0] = False  # obstacle from row 3
    m[0, 1] = False  # obstacle in the top row
    m[2, 2] = False
    m[4:, 2] = False  # sky below an overhang does not count
    np.testing.assert_array_equal(leading_sky_rows(m), [3, 0, 2, 6])


def test_centre_column_direction_matches_pinhole_geometry(pinhole: CameraModel) -> None:
    mount = Mount.default("left")
    heading = 30.0
    rows = np.full(pinhole.width_px, 100)
    sk = skyline_directions(rows, pinhole, mount, heading)
    c = pinhole.width_px // 2
    # boundary at v = 99.5: angle above the optical axis is atan((cy - v) / f)
    expected_el = PITCH + np.degrees(np.arctan((pinhole.cy - 99.5) / pinhole.fy))
    u_off = np.degrees(np.arctan((c - pinhole.cx) / pinhole.fx))
    assert sk.el_deg[c] == pytest.approx(expected_el, abs=0.05)
    # the left camera looks at heading - 90; a column right of centre is further clockwise
    assert np.mod(sk.az_deg[c] - (heading - 90.0) + 180, 360) - 180 == pytest.approx(u_off, abs=0.3)
    assert not sk.valid[rows == 0].any()


def test_profile_recovers_an_elevation_skyline(pinhole: CameraModel) -> None:
    mount = Mount.default("right")
    rect = Rectifier.build(pinhole, mount)
    prof = rect.profile(elevation_sky(pinhole, mount, 200.0, 20.0), heading_deg=200.0)
    seen = np.isfinite(prof.seen_lo_deg) & (prof.seen_lo_deg < 19.0)
    assert seen.sum() > 100
    err = prof.sky_el_deg[seen] - 20.0
    # conservative: never below the skyline, by at most a sample and the obstacle growth
    assert err.min() >= -1e-9 and err.max() <= 0.6
    assert prof.look_az_deg == pytest.approx(np.mod(200.0 + 90.0, 360.0))


def test_profile_field_of_view_matches_analytic_pinhole(pinhole: CameraModel) -> None:
    rect = Rectifier.build(pinhole, Mount.default("left"))
    prof = rect.profile(np.ones(pinhole.shape, bool), heading_deg=0.0)
    j = np.argmin(np.abs(prof.rel_az_deg))
    # straight out, the image spans pitch -+ half the vertical field of view
    assert prof.seen_lo_deg[j] == pytest.approx(PITCH - VFOV / 2, abs=0.2)
    assert prof.seen_hi_deg[j] == pytest.approx(PITCH + VFOV / 2, abs=0.2)
    # all sky: the skyline is the bottom of the view
    assert prof.sky_el_deg[j] == pytest.approx(prof.seen_lo_deg[j])
    # nothing is seen along the track
    assert np.isnan(prof.seen_lo_deg[np.abs(prof.rel_az_deg) > 85]).all()


def test_sky_under_an_overhang_is_ignored(pinhole: CameraModel) -> None:
    mount = Mount.default("left")
    sky = elevation_sky(pinhole, mount, 0.0, 15.0)
    band = ~elevation_sky(pinhole, mount, 0.0, 40.0) & elevation_sky(pinhole, mount, 0.0, 30.0)
    prof = Rectifier.build(pinhole, mount).profile(sky & ~band, 0.0)
    j = np.argmin(np.abs(prof.rel_az_deg))
    assert prof.sky_el_deg[j] >= 40.0 - 1e-9
    assert prof.sky_el_deg[j] <= 40.6


def test_low_confidence_columns_have_their_skyline_raised(pinhole: CameraModel) -> None:
    mount = Mount.default("left")
    rect = Rectifier.build(pinhole, mount)
    sky = elevation_sky(pinhole, mount, 0.0, 20.0)
    w, h = pinhole.width_px, pinhole.height_px
    low = np.zeros(w, bool)
    low[180:220] = True  # the centre columns
    conf = np.where(low, 0.0, 1.0)
    prof = rect.profile(sky, 0.0, confidence=conf)
    ref = rect.profile(sky, 0.0)
    # expected: the centre column's boundary moves up by two windows of 300 // 30 + 300 // 120
    # rows, at the elevation the camera model gives that pixel edge
    c = w // 2
    row = int(np.argmin(sky[:, c])) - 2 * (h // 30 + h // 120)
    ray = pinhole.pixel_to_ray(np.array([float(c)]), np.array([row - 0.5]))
    enu = ray @ mount.camera_to_enu(0.0).T
    expected = np.degrees(np.arcsin(enu[0, 2]))
    j = np.argmin(np.abs(prof.rel_az_deg))
    assert expected > ref.sky_el_deg[j] + 3.0
    assert prof.sky_el_deg[j] == pytest.approx(expected, abs=0.6)
    # bins that read no low-confidence column are untouched
    read = rect.pixel_index
    for k in range(prof.rel_az_deg.size):
        cols = read[read[:, k] >= 0, k] % w
        if cols.size and not low[cols].any():
            assert prof.sky_el_deg[k] == ref.sky_el_deg[k]
    # windows = inf: low-confidence columns clear nothing
    void = rect.profile(sky, 0.0, confidence=np.zeros(w), low_confidence_windows=np.inf)
    assert np.isinf(void.sky_el_deg).all()
    with pytest.raises(ValueError, match="confidence"):
        rect.profile(sky, 0.0, confidence=np.ones(3))
    for bad in (-1.0, np.nan):
        with pytest.raises(ValueError, match="low_confidence_windows"):
            rect.profile(sky, 0.0, confidence=conf, low_confidence_windows=bad)
    # NaN confidence counts as low; a huge window voids the column like inf
    nan_conf = np.where(low, np.nan, 1.0)
    assert np.array_equal(rect.profile(sky, 0.0, confidence=nan_conf).sky_el_deg, prof.sky_el_deg)
    huge = rect.profile(sky, 0.0, confidence=np.zeros(w), low_confidence_windows=1e20)
    assert np.isinf(huge.sky_el_deg).all()


@pytest.mark.parametrize(
    ("column", "raise_px", "expected"),
    [
        ("0110110", 1, "0100000"),  # the top run loses its last row, the lower run goes
        ("0011100", 1, "0011000"),
        ("0011100", 5, "0000000"),  # a run shorter than the raise goes entirely
        ("1111111", 2, "1111100"),  # all sky: raised from the bottom edge
        ("0000000", 3, "0000000"),
        ("0110110", 0, "0110000"),  # no raise: still no sky below the top run
    ],
)
def test_raise_skyline_on_hand_written_columns(column: str, raise_px: int, expected: str) -> None:
    sky = np.array([[c == "1", True] for c in column])  # column 1 is confident: untouched
    before = sky.copy()
    out = _raise_skyline(sky, np.array([0]), raise_px)
    assert "".join("1" if v else "0" for v in out[:, 0]) == expected
    assert out[:, 1].all()
    assert np.array_equal(sky, before)  # the input is not modified


@pytest.mark.parametrize(
    ("column", "raise_deg", "expected"),
    [
        # elevations 60, 50, ..., 0 deg down the rows (10 deg per row)
        # the edge is at 15 deg; the sky rows' centres 5, 15, 25 and 35 deg above it
        ("0111100", 4.0, "0111100"),
        ("0111100", 6.0, "0111000"),
        ("0111100", 25.1, "0100000"),
        ("0111100", 35.1, "0000000"),  # the whole run
        ("0110110", 1.0, "0110000"),  # still no sky below the top run
        ("1111111", 15.0, "1111100"),  # all sky: the edge is the last row's centre
        ("0111100", np.inf, "0000000"),
    ],
)
def test_raise_skyline_deg_on_hand_written_columns(
    column: str, raise_deg: float, expected: str
) -> None:
    sky = np.array([[c == "1", True] for c in column])
    el = np.repeat((60.0 - 10.0 * np.arange(len(column)))[:, None], 2, axis=1)
    before = sky.copy()
    out = _raise_skyline_deg(sky, np.array([0]), raise_deg, el)
    assert "".join("1" if v else "0" for v in out[:, 0]) == expected
    assert out[:, 1].all()
    assert np.array_equal(sky, before)


def test_raise_skyline_deg_counts_a_pixel_without_a_ray_as_within() -> None:
    """A NaN elevation (no ray) never stops the raise: the safe side."""
    sky = np.array([[c == "1"] for c in "0111100"])
    el = (60.0 - 10.0 * np.arange(7))[:, None].copy()
    el[3, 0] = np.nan  # 30 deg: the second sky row up
    out = _raise_skyline_deg(sky, np.array([0]), 4.0, el)
    assert "".join("1" if v else "0" for v in out[:, 0]) == "0111100"  # 5 deg up: kept
    out = _raise_skyline_deg(sky, np.array([0]), 6.0, el)
    # the 5 deg row goes, the NaN row too, the 25 deg row stops the raise
    assert "".join("1" if v else "0" for v in out[:, 0]) == "0110000"


def test_raise_skyline_leaves_the_rows_above_the_grid_alone() -> None:
    """Rows above ``from_row`` are never read by the grid (a side fisheye's view past the
    zenith): the run is searched below them and they are left as they are."""
    col = "1100111"
    sky = np.array([[c == "1"] for c in col])
    out = _raise_skyline(sky, np.array([0]), 1, np.array([3]))
    assert "".join("1" if v else "0" for v in out[:, 0]) == "1100110"
    assert "".join("1" if v else "0" for v in _raise_skyline(sky, np.array([0]), 1)[:, 0]) == (
        "1000000"  # searched from the top, the sliver is the run and the sky below goes
    )


def _reference_raise(
    sky: np.ndarray, cols: np.ndarray, raise_px: int, from_row: np.ndarray | None
) -> np.ndarray:
    """:func:`_raise_skyline` as written with numpy column gathers (before 2026-12-03)."""
    sub = sky[:, cols]
    n = sub.shape[0]
    rows = np.arange(n)[:, None]
    top = np.zeros(len(cols), np.int64) if from_row is None else np.asarray(from_row)[cols]
    reach = rows >= top
    cand = sub & reach
    start = np.where(cand.any(axis=0), np.argmax(cand, axis=0), n)
    after = ~sub & (rows >= start)
    end = np.where(after.any(axis=0), np.argmax(after, axis=0), n)
    out = sky.copy()
    out[:, cols] = sub & (~reach | (rows < np.maximum(end - int(raise_px), start)))
    return out


def test_raise_skyline_matches_the_column_gathers_on_random_masks() -> None:
    rng = np.random.default_rng(9)
    for k in range(300):
        h, w = (int(v) for v in rng.integers(1, 30, 2))
        sky = rng.random((h, w)) < rng.uniform(0.2, 0.95)
        sky[: int(rng.integers(0, h + 1))] |= k % 2 == 0  # often a long top run
        cols = rng.choice(w, int(rng.integers(0, w + 1)), replace=True)  # repeats too
        from_row = None if k % 3 == 0 else rng.integers(0, h + 2, w)
        raise_px = int(rng.integers(0, h + 3))
        before = sky.copy()
        got = _raise_skyline(sky, cols, raise_px, from_row)
        np.testing.assert_array_equal(got, _reference_raise(sky, cols, raise_px, from_row))
        np.testing.assert_array_equal(sky, before)


def test_an_obstacle_past_the_zenith_does_not_void_the_own_half_space() -> None:
    """A side fisheye sees the far side of the track above its zenith line. A wall there,
    under a sliver of sky at the top edge, in low-confidence columns, must not take the sky
    of the camera's own half-space below it: the profile is the one without that wall."""
    cam = default_camera("fisheye")
    mount = Mount.default("left")
    rect = Rectifier.build(cam, mount)
    first = rect.first_read_px_row
    w = cam.width_px
    cols = np.flatnonzero((first >= 20) & (first < cam.height_px))
    assert cols.size > 10  # columns with pixels past the zenith at their top
    sky = np.ones(cam.shape, bool)
    sky[int(0.8 * cam.height_px) :] = False  # the ground
    wall = sky.copy()
    for c in cols:  # sky on the top rows, then the far wall, ending 6 rows above the grid
        wall[3 : first[c] - 6, c] = False
    conf = np.ones(w)
    conf[cols] = 0.0
    ref = rect.profile(sky, 0.0, confidence=conf)
    got = rect.profile(wall, 0.0, confidence=conf)
    assert np.isfinite(ref.sky_el_deg).mean() > 0.9
    assert np.array_equal(got.sky_el_deg, ref.sky_el_deg)


def test_a_fuzzy_horizon_does_not_void_a_fisheye_zenith() -> None:
    """Every azimuth's top sky run starts at the zenith, which a side fisheye sees in its
    centre column: a fuzzy tree top on the horizon there must not void them all."""
    cam = default_camera("fisheye")
    mount = Mount.default("left")
    rect = Rectifier.build(cam, mount)
    # the corners outside the lens circle are no sky: runs start below them
    sky = elevation_sky(cam, mount, 0.0, 5.0) & fisheye_valid_mask(cam.shape, None, 0.04)
    w = cam.width_px
    conf = np.ones(w)
    conf[w // 2 - 3 : w // 2 + 3] = 0.0
    ref = rect.profile(sky, 0.0)
    seen = np.isfinite(ref.sky_el_deg)
    assert seen.mean() > 0.5
    void = rect.profile(sky, 0.0, confidence=conf, low_confidence_windows=np.inf)
    assert np.isinf(void.sky_el_deg[seen]).mean() > 0.9  # the whole-column gate voids them
    prof = rect.profile(sky, 0.0, confidence=conf)
    assert np.isfinite(prof.sky_el_deg[seen]).all()
    assert (prof.sky_el_deg[seen] >= ref.sky_el_deg[seen]).all()
    assert (prof.sky_el_deg[seen] != ref.sky_el_deg[seen]).mean() < 0.1


def test_wrong_mask_shape_is_rejected(pinhole: CameraModel) -> None:
    with pytest.raises(ValueError, match="camera image shape"):
        Rectifier.build(pinhole, Mount.default("left")).profile(np.ones((10, 10), bool), 0.0)


@pytest.mark.parametrize(
    ("camera", "side"),
    [
        (CameraModel.pinhole_from_fov(400, 300, VFOV), "right"),
        (CameraModel.fisheye_from_fov(200, 150, 110.0), "left"),
        (CameraModel.pinhole_from_fov(64, 48, 10.0), "right"),  # misses most grid columns
    ],
)
def test_profile_equals_the_top_sky_run_of_the_full_rectified_grid(
    camera: CameraModel, side: str
) -> None:
    """The profile walks each column only down to its sky run's end; the whole grid resampled
    by ``cv2.remap`` (:meth:`Rectifier.rectify`) must give the same run ends."""
    mount = Mount.default(side)
    rect = Rectifier.build(camera, mount)
    rng = np.random.default_rng(3)
    sky = elevation_sky(camera, mount, 10.0, 25.0 if camera.height_px > 48 else 44.0)
    sky[rng.random(sky.shape) < 0.002] = False  # specks: runs end at varied rows
    w = camera.width_px
    sky[:, int(0.37 * w) : int(0.42 * w)] = False  # a mast from top to bottom
    prof = rect.profile(sky, heading_deg=10.0)
    lab = rect.rectify(sky)
    n_e = lab.shape[0]
    for j in range(lab.shape[1]):
        seen = np.flatnonzero(lab[:, j] != 128)
        if seen.size == 0:
            assert np.isnan(prof.seen_lo_deg[j]) and np.isinf(prof.sky_el_deg[j])
            continue
        top = seen[0]
        not_sky = np.flatnonzero(lab[top:, j] != 255)
        end = top + (not_sky[0] if not_sky.size else n_e - top)
        expected = rect.el_deg[end - 1] if end > top else np.inf
        assert prof.sky_el_deg[j] == expected
        assert prof.seen_hi_deg[j] == rect.el_deg[top]
        assert prof.seen_lo_deg[j] == rect.el_deg[seen[-1]]


def test_sky_run_end_by_pixel_runs_matches_a_walk_down_the_grid() -> None:
    """The top sky run's end, searched run of equal pixels by run (since 2026-12-03): the
    first grid row at or below ``top`` whose pixel is unseen or not sky, as a row walk."""
    from predisat.reconstruct.skyline import _index_runs, _top_sky_run_end

    rng = np.random.default_rng(6)
    for _ in range(200):
        n_e, n_b, n_px = (int(v) for v in rng.integers(1, 40, 3))
        # columns that read each pixel over a few rows, with unseen (-1) stretches
        base = rng.integers(-1, n_px, (n_e, n_b))
        rows = np.sort(rng.integers(0, n_e, (n_e, n_b)), axis=0)
        pix = np.take_along_axis(base, rows, axis=0).astype(np.int32)
        top = rng.integers(0, n_e, n_b)
        grown = np.where(rng.random(n_px) < 0.85, 1, 0).astype(np.uint8)
        got = _top_sky_run_end(grown, *_index_runs(pix, top), top, n_e, 1)
        ref = np.empty(n_b, np.int64)
        for b in range(n_b):
            r = top[b]
            while r < n_e and pix[r, b] >= 0 and grown[pix[r, b]] == 1:
                r += 1
            ref[b] = r
        np.testing.assert_array_equal(got, ref)


def _equirect_sky(camera: CameraModel, el_deg: float) -> np.ndarray:
    """Level equirectangular panorama whose skyline is ``el_deg`` everywhere, from the
    format's definition (row ``v`` centre at ``90 - (v + 0.5) * 180 / H`` deg), not from the
    camera model."""
    h = camera.height_px
    el = 90.0 - (np.arange(h) + 0.5) * 180.0 / h
    return np.repeat((el > el_deg)[:, None], camera.width_px, axis=1)


@pytest.mark.parametrize("width_px", [720, 1440])
def test_a_panorama_raises_low_confidence_columns_by_an_angle(width_px: int) -> None:
    """Half and full resolution panoramas lose the same angle of sky above a low-confidence
    skyline: the sky pixels whose centre lies less than windows x window_deg above it."""
    cam = CameraModel.equirect(width_px)
    mount = Mount.default("roof")
    rect = Rectifier.build(cam, mount)
    h, w = cam.height_px, cam.width_px
    step = 180.0 / h
    sky_el = 10.0  # a pixel edge at both resolutions
    sky = _equirect_sky(cam, sky_el)
    low = np.zeros(w, bool)
    low[w // 2 - w // 16 : w // 2 + w // 16] = True  # 45 deg of azimuth around the look
    conf = np.where(low, 0.1, 0.9)
    ref = rect.profile(sky, 0.0)
    for windows, window_deg in ((2.0, 4.6), (1.0, 3.0), (3.0, 1.1)):
        raise_deg = windows * window_deg
        prof = rect.profile(sky, 0.0, confidence=conf, low_confidence_windows=windows,
                            low_confidence_window_deg=window_deg)  # fmt: skip
        # sky pixels k = 0, 1, ... above the edge have their centre (k + 0.5) step above it
        n_lost = int(np.ceil(raise_deg / step - 0.5))
        expected_raise = n_lost * step
        j = np.argmin(np.abs(prof.rel_az_deg))
        assert prof.sky_el_deg[j] - ref.sky_el_deg[j] == pytest.approx(expected_raise, abs=0.13)
        assert expected_raise == pytest.approx(raise_deg, abs=step / 2 + 1e-9)
        # azimuths well away from the low columns are untouched
        far = np.abs(prof.rel_az_deg) > 30.0
        assert np.array_equal(prof.sky_el_deg[far], ref.sky_el_deg[far])
    # inf voids the low columns, a NaN window size is refused
    void = rect.profile(sky, 0.0, confidence=conf, low_confidence_windows=np.inf)
    assert np.isinf(void.sky_el_deg[np.abs(void.rel_az_deg) < 15.0]).all()
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="low_confidence_window_deg"):
            rect.profile(sky, 0.0, confidence=conf, low_confidence_window_deg=bad)


def test_the_panorama_window_is_the_side_fisheyes_window_in_degrees() -> None:
    """LOW_CONFIDENCE_WINDOW_DEG against the shipped side fisheye, through OpenCV's own
    fisheye model (not the camera module): one confidence window of rows in the centre column,
    at skylines 0 to 45 deg up, spans at most the constant and no less than 0.3 deg under it."""
    cam = default_camera("fisheye")
    spans = []
    for scale in (0.5, 1.0):
        h, w = round(cam.height_px * scale), round(cam.width_px * scale)
        k = np.array([[cam.fx * scale, 0.0, (w - 1) / 2.0], [0.0, cam.fy * scale, (h - 1) / 2.0],
                      [0.0, 0.0, 1.0]])  # fmt: skip
        band, gap = confidence_window_px(h)
        rows = np.arange(h, dtype=np.float64)
        pts = np.stack([np.full(h, (w - 1) / 2.0), rows], axis=-1)[:, None, :]
        und = cv2.fisheye.undistortPoints(pts, k, np.array(cam.dist))[:, 0, :]
        # centre column of a camera 45 deg up: elevation 45 deg minus the angle below the axis
        el = PITCH - np.degrees(np.arctan(und[:, 1]))
        win = el[: h - band - gap] - el[band + gap :]  # rows r vs r + window, at row r + window
        at = el[band + gap :]
        spans.append(win[(at >= 0.0) & (at <= 45.0)])
    top = max(float(s.max()) for s in spans)
    assert top <= LOW_CONFIDENCE_WINDOW_DEG
    assert top >= LOW_CONFIDENCE_WINDOW_DEG - 0.3


def test_frame_cameras_keep_windows_of_rows(pinhole: CameraModel) -> None:
    """The angular window is for panoramas only: a pinhole or fisheye profile does not
    depend on it (the side rigs' masks stay bit for bit what they were)."""
    for cam in (pinhole, default_camera("fisheye").resized(400, 300)):
        mount = Mount.default("left")
        rect = Rectifier.build(cam, mount)
        sky = elevation_sky(cam, mount, 0.0, 20.0)
        conf = np.ones(cam.width_px)
        conf[cam.width_px // 3 : cam.width_px // 2] = 0.0
        a = rect.profile(sky, 0.0, confidence=conf)
        b = rect.profile(sky, 0.0, confidence=conf, low_confidence_window_deg=1.0)
        c = rect.profile(sky, 0.0, confidence=conf, low_confidence_window_deg=30.0)
        assert np.array_equal(a.sky_el_deg, b.sky_el_deg)
        assert np.array_equal(a.sky_el_deg, c.sky_el_deg)
        assert not np.array_equal(a.sky_el_deg, rect.profile(sky, 0.0).sky_el_deg)


def test_a_column_whose_sky_reaches_under_the_horizon_is_voided() -> None:
    # the demo's fisheye at 45 deg sees 15 deg under the horizon; where the segmentation took
    # an obstacle for sky down to its foot (a white pier on the ground), the sky reaches -12 deg
    cam = default_camera("fisheye")
    mount = Mount.default("left")
    u, v = cam.pixel_grid()
    ray = cam.pixel_to_ray(u, v) @ mount.camera_to_enu(0.0).T
    el = np.degrees(np.arcsin(np.clip(ray[..., 2], -1, 1)))
    az = np.degrees(np.arctan2(ray[..., 0], ray[..., 1])) % 360.0  # the camera looks at 270
    pier = np.abs(az - 260.0) < 3.0
    sky = np.where(pier, el > -12.0, el > 20.0)
    rect = Rectifier.build(cam, mount)
    plain = rect.profile(sky, heading_deg=0.0)
    checked = rect.profile(sky, heading_deg=0.0, min_sky_el_deg=-8.0)
    in_pier = np.abs(plain.az_deg - 260.0) < 2.0
    assert in_pier.any() and np.all(plain.sky_el_deg[in_pier] < -10.0)
    assert np.all(np.isinf(checked.sky_el_deg[in_pier]))  # the column clears nothing
    rest = np.abs(plain.az_deg - 260.0) > 4.0
    np.testing.assert_array_equal(checked.sky_el_deg[rest], plain.sky_el_deg[rest])


# ---------------------------------------------------------------------- attitude doubt


def _blobs(camera: CameraModel, seed: int) -> np.ndarray:
    """A sky mask of random obstacle discs and a ragged horizon."""
    rng = np.random.default_rng(seed)
    h, w = camera.shape
    sky = np.ones((h, w), np.uint8)
    cut = (h * (0.55 + 0.1 * np.sin(np.arange(w) / 37.0))).astype(int)
    for c in range(w):
        sky[cut[c]:, c] = 0
    for _ in range(25):
        cv2.circle(sky, (int(rng.integers(w)), int(rng.integers(h))), int(rng.integers(2, 30)),
                   0, -1)
    return sky.astype(bool)


@pytest.mark.parametrize(
    "camera",
    [CameraModel.pinhole_from_fov(320, 240, 74.0, dist=(-0.12, 0.03, 0.0, 0.0)),
     default_camera("fisheye"), CameraModel.equirect(720)],
    ids=["pinhole", "fisheye", "equirect"],
)
def test_eroded_sky_holds_whatever_rotation_within_the_doubt(camera: CameraModel) -> None:
    """Safety of the erosion, checked through the camera model: every pixel still sky after
    eroding by ``doubt`` sees sky under any rotation of the camera up to ``doubt``."""
    from scipy.spatial.transform import Rotation

    doubt = 2.5
    sky = _blobs(camera, 7)
    sure = erode_sky_deg(sky, camera, doubt)
    assert sure.sum() > 0.1 * sky.sum() and not (sure & ~sky).any()
    v, u = np.nonzero(sure)
    pick = np.random.default_rng(1).choice(u.size, 4000, replace=False)
    ray = camera.pixel_to_ray(u[pick].astype(float), v[pick].astype(float))
    rng = np.random.default_rng(2)
    for _ in range(12):
        axis = rng.normal(size=3)
        rot = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.radians(doubt)).as_matrix()
        pu, pv = camera.ray_to_pixel(ray @ rot.T)
        ok = np.isfinite(pu) & np.isfinite(pv)
        iu = np.rint(np.where(ok, pu, -1)).astype(int)
        iv = np.rint(np.where(ok, pv, -1)).astype(int)
        if camera.model == "equirect":  # longitude wraps
            iu = iu % camera.width_px
        # above the top edge the carving takes the sky as going on; anywhere else off the
        # image (sides, bottom, outside a lens circle) nothing was seen: a failure
        above = ok & (iv < 0) & (iu >= 0) & (iu < camera.width_px)
        inside = ok & (iu >= 0) & (iu < camera.width_px) & (iv >= 0) & (iv < camera.height_px)
        assert np.all(inside | above)
        assert sky[iv[inside], iu[inside]].all()
        assert camera.has_ray[iv[inside], iu[inside]].all()


def test_erosion_by_nothing_is_the_mask_and_a_bad_angle_is_refused() -> None:
    cam = default_camera("fisheye")
    sky = _blobs(cam, 3)
    assert np.array_equal(erode_sky_deg(sky, cam, 0.0), sky)
    with pytest.raises(ValueError, match="angle_deg"):
        erode_sky_deg(sky, cam, -1.0)


@pytest.mark.parametrize("wire_side", [1.0, -1.0])
@pytest.mark.parametrize("roll_deg", [-6.5, 7.0])
def test_a_canted_panorama_keeps_its_zenith_under_a_low_confidence_wire(
    roll_deg: float, wire_side: float
) -> None:
    """A panorama on a canted vehicle (docs/rigs.md): its image columns near the zenith rise to
    it and fall on its far side, so a contact wire 6 deg from the zenith cuts such a column's
    top sky run within the low-confidence raise. Raised per image column, that run went
    whole, the zenith pixel with it, and every grid column (all start at the zenith) lost its
    sky: the frame cleared nothing. Raised per grid column, only the columns whose own run
    the wire ends within the raise of the zenith are voided; the others keep their sky down
    to the raised skyline, and no column's skyline comes lower than the raise demands."""
    cam = CameraModel.equirect(720)
    mount = Mount.default("roof").on_vehicle(roll_deg, 0.0)
    rect = Rectifier.build(cam, mount)
    u, v = cam.pixel_grid()
    d = cam.pixel_to_ray(u.ravel(), v.ravel()) @ mount.camera_to_vehicle().T
    el = np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0)))
    # a wire along the track, 0.15 m aside and 1.5 m up (84.3 deg across), 1 deg thick
    w = np.array([0.0, 0.15 * wire_side, 1.5])
    n = np.cross([1.0, 0.0, 0.0], w)
    n /= np.linalg.norm(n)
    wire = (np.abs(d @ n) < np.sin(np.radians(0.5))) & (d @ w > 0.0)
    sky = ((el > 20.0) & ~wire).reshape(cam.shape)
    ref = rect.profile(sky, 0.0)
    raise_deg = 2.0 * LOW_CONFIDENCE_WINDOW_DEG
    # the default raise, down the image columns, voids the whole frame (the safe side, kept
    # as the default: docs/rigs.md); the opt-in raise on the grid keeps it
    image = rect.profile(sky, 0.0, confidence=np.zeros(cam.width_px))
    assert np.isinf(image.sky_el_deg).all()
    prof = rect.profile(sky, 0.0, confidence=np.zeros(cam.width_px), panorama_raise="grid")
    # the grid columns the wire does not cross reach the ground skyline at 20 deg; raised,
    # they keep their sky from the zenith down to their skyline plus the raise (give or take
    # a pixel of the tilted image)
    open_cols = ref.sky_el_deg < 21.0
    assert open_cols.mean() > 0.4
    got = prof.sky_el_deg[open_cols]
    assert np.isfinite(got).all(), f"{np.isinf(got).sum()} of {got.size} open columns voided"
    step = 180.0 / cam.height_px
    lift = got - ref.sky_el_deg[open_cols]
    assert lift.min() >= raise_deg - step
    # a few columns beside the wire's low ends also take the doubt of the image columns
    # leaning over them (test_a_canted_panoramas_grid_trusts_no_doubt_along_a_low_image_column)
    assert np.mean(lift <= raise_deg + 2.0 * step) > 0.99
    # never lower than the raise asks, anywhere; columns the wire ends within it are voided
    fin = np.isfinite(prof.sky_el_deg)
    assert (prof.sky_el_deg[fin] >= ref.sky_el_deg[fin] + raise_deg - 0.5).all()
    assert np.isinf(prof.sky_el_deg[ref.sky_el_deg > 90.0 - raise_deg + 0.5]).all()


def test_a_level_panoramas_raise_on_the_grid_is_no_lower_than_down_its_columns() -> None:
    """On a level panorama the grid's columns are the image's: raising on the grid keeps every
    skyline at least where raising down the image columns put it (then growing the raised
    sky as an obstacle), for any mask and confidence."""
    cam = CameraModel.equirect(720)
    rect = Rectifier.build(cam, Mount.default("roof"))
    rng = np.random.default_rng(3)
    h, w = cam.shape
    raise_deg = 2.0 * LOW_CONFIDENCE_WINDOW_DEG
    for _ in range(5):
        # a ragged skyline with overhead wires and holes, and runs of low columns
        sky_el = np.convolve(rng.uniform(-5.0, 60.0, w + 20), np.ones(21) / 21, "valid")
        el = 90.0 - (np.arange(h) + 0.5) * 180.0 / h
        sky = el[:, None] > sky_el[None, :w]
        sky[rng.integers(0, 40, 6)] = False
        sky &= rng.random(sky.shape) > 0.002
        conf = np.repeat(rng.random(w // 20), 20)
        low = np.flatnonzero(conf < 0.5)
        raised = _raise_skyline_deg(sky, low, raise_deg, rect.pixel_el_deg,
                                             rect.first_read_px_row)
        by_columns = rect.profile(raised, 0.0).sky_el_deg
        on_grid = rect.profile(sky, 0.0, confidence=conf, panorama_raise="grid").sky_el_deg
        assert np.all(on_grid >= by_columns)
        default = rect.profile(sky, 0.0, confidence=conf).sky_el_deg  # "image": the columns'
        np.testing.assert_array_equal(default, by_columns)
    with pytest.raises(ValueError, match="panorama_raise"):
        rect.profile(sky, 0.0, confidence=conf, panorama_raise="azimuth")


@pytest.mark.parametrize("roll_deg", [3.0, 7.0])
def test_a_canted_panoramas_grid_trusts_no_doubt_along_a_low_image_column(
    roll_deg: float,
) -> None:
    """The segmenter's confidence is measured down the image's columns (a panorama's tiles):
    a low column's skyline may lie up to the raise higher along that column. On a canted
    panorama those columns lean across level azimuths, so where the skyline falls away
    sideways the top of a low column's doubt lies more than the raise above the grid column
    that reads it (a review: 311 grid cells at roll 3 deg, 7 843 at 7 deg over five frames,
    28-48 deg up, 9-17 deg over their own skyline). Away from the image's pole (where the
    columns converge) and under 90 deg less the raise, none of it is trusted."""
    cam = CameraModel.equirect(720)
    mount = Mount.default("roof").on_vehicle(roll_deg, 0.0)
    rect = Rectifier.build(cam, mount)
    h, w = cam.shape
    u, v = cam.pixel_grid()
    d = cam.pixel_to_ray(u.ravel(), v.ravel()) @ mount.camera_to_vehicle().T
    el = np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0))).reshape(cam.shape)
    az = np.mod(np.degrees(np.arctan2(d[:, 1], d[:, 0])), 360.0).reshape(cam.shape)
    raise_deg = 2.0 * LOW_CONFIDENCE_WINDOW_DEG
    row_deg = 180.0 / h
    rng = np.random.default_rng(5)
    pi = rect.pixel_index
    for _ in range(3):
        # a smooth skyline of the world (level azimuths), seen by the canted camera
        sk = np.convolve(rng.uniform(-5.0, 60.0, 1460), np.ones(21) / 21, "valid")[:1440]
        sky = el > sk[np.clip((az / 0.25).astype(int), 0, 1439)]
        conf = np.repeat(rng.random(w // 20), 20)
        doubt = np.zeros(sky.shape, bool)
        for c in np.flatnonzero(conf < 0.5):
            r0 = int(rect.first_read_px_row[c])
            while r0 < h and not sky[r0, c]:
                r0 += 1
            e = r0
            while e < h and sky[e, c]:
                e += 1
            if e == r0:
                continue
            base = 0.5 * (el[e - 1, c] + el[e, c]) if e < h else el[e - 1, c]
            rows = np.arange(r0, e)
            near = ((el[rows, c] - base < raise_deg) & ((e - rows - 0.5) * row_deg < raise_deg)
                    & ((rows + 0.5) * row_deg >= 2.0 * raise_deg)
                    & (el[rows, c] < 90.0 - raise_deg))  # fmt: skip
            doubt[rows[near], c] = True
        prof = rect.profile(sky, 0.0, confidence=conf, panorama_raise="grid")
        reads = (pi >= 0) & doubt.ravel()[np.clip(pi, 0, None)]
        trusted = rect.el_deg[:, None] >= prof.sky_el_deg[None, :]
        assert not (trusted & reads).any(), f"{(trusted & reads).sum()} doubtful grid cells trusted"
