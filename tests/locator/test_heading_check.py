"""Heading check against a virtual beacon (2024 patent)."""

from __future__ import annotations

import numpy as np
import pytest

from locator.heading_check import HeadingStatus, check_heading, delay_model_m
from predisat.geodesy import ecef_to_geodetic, enu_rotation, enu_to_azel
from tests.locator._scene import arc_path, random_sky, ranges, sky, straight_path

HDG_A = 30.0
HDG_B = 55.0  # a track diverging from A at 25 deg


@pytest.fixture(scope="module")
def tracks():
    return straight_path(HDG_A, 1500.0, 0.0), straight_path(HDG_B, 1500.0, 0.0)


def _sats(x, seed, n=9):
    return sky(x, *random_sky(np.random.default_rng(seed), n, 15.0))


def test_right_track_passes(tracks):
    a, _ = tracks
    rng = np.random.default_rng(0)
    beacon = a.ecef_at(600.0)
    for s_true in (700.0, 450.0):  # ahead of and behind the beacon
        x = a.ecef_at(s_true)
        sat = _sats(x, 1)
        sig = np.full(len(sat), 1.0)
        chk = check_heading(beacon, HDG_A, sat, ranges(sat, x, sig, rng), sig)
        assert chk.status == HeadingStatus.PASS and chk.reliable
        assert chk.along_m == pytest.approx(s_true - 600.0, abs=5.0)
        assert abs(chk.difference_deg) < chk.threshold_deg
        assert chk.sigma_heading_deg < 3.0


def test_wrong_track_fails(tracks):
    a, b = tracks
    rng = np.random.default_rng(1)
    x = a.ecef_at(700.0)  # the train is on track A ...
    beacon = b.ecef_at(600.0)  # ... but the estimate named a beacon on track B
    sat = _sats(x, 2)
    sig = np.full(len(sat), 1.0)
    chk = check_heading(beacon, HDG_B, sat, ranges(sat, x, sig, rng), sig)
    assert chk.status == HeadingStatus.FAIL and not chk.reliable
    assert abs(chk.difference_deg) > 30.0


def test_curved_segment_within_tolerance():
    path = arc_path(2000.0, 10.0, heading_deg=0.0, lead_m=0.0, height_m=0.0)
    rng = np.random.default_rng(3)
    beacon = path.ecef_at(50.0)
    x = path.ecef_at(200.0)  # 150 m on, the chord turns by about 2 deg
    sat = _sats(x, 4)
    sig = np.full(len(sat), 1.0)
    chk = check_heading(
        beacon,
        float(path.track.heading_at(50.0)),
        sat,
        ranges(sat, x, sig, rng),
        sig,
        tolerance_deg=3.0,
    )
    assert chk.status == HeadingStatus.PASS


def test_unobservable_near_the_beacon(tracks):
    a, _ = tracks
    rng = np.random.default_rng(5)
    x = a.ecef_at(600.5)
    sat = _sats(x, 6)
    sig = np.full(len(sat), 2.0)
    chk = check_heading(a.ecef_at(600.0), HDG_A, sat, ranges(sat, x, sig, rng), sig)
    assert chk.status == HeadingStatus.UNOBSERVABLE and not chk.reliable


def test_delay_model_is_the_first_order_range_change(tracks):
    a, _ = tracks
    b1 = a.ecef_at(500.0)
    x = a.ecef_at(540.0)  # 40 m along heading HDG_A (+ tiny grade of the frame-straight line)
    sat = _sats(b1, 7)
    lat, lon, _ = ecef_to_geodetic(b1)
    az, el, _ = enu_to_azel((sat - b1) @ enu_rotation(lat, lon).T)
    exact = np.linalg.norm(sat - x, axis=-1) - np.linalg.norm(sat - b1, axis=-1)
    model = delay_model_m(az, el, float(a.track.heading_at(520.0)), 40.0)
    np.testing.assert_allclose(model, exact, atol=0.02)


def test_validation(tracks):
    a, _ = tracks
    with pytest.raises(ValueError, match="at least 3"):
        check_heading(a.ecef_at(0.0), 0.0, np.ones((2, 3)) * 2e7, np.ones(2), np.ones(2))


def test_given_rotation_is_the_beacon_frame(tracks):
    a, b = tracks
    rng = np.random.default_rng(1)
    x, beacon = a.ecef_at(700.0), b.ecef_at(600.0)
    sat = _sats(x, 2)
    sig = np.full(len(sat), 1.0)
    rho = ranges(sat, x, sig, rng)
    lat, lon, _ = ecef_to_geodetic(beacon)
    given = check_heading(beacon, HDG_B, sat, rho, sig, rotation=enu_rotation(lat, lon))
    assert given == check_heading(beacon, HDG_B, sat, rho, sig)
    # another frame (the one of a point 50 km away) changes the answer
    far = check_heading(beacon, HDG_B, sat, rho, sig, rotation=enu_rotation(lat + 0.5, lon))
    assert far.heading_deg != given.heading_deg
    with pytest.raises(ValueError, match="rotation"):
        check_heading(beacon, HDG_B, sat, rho, sig, rotation=np.eye(2))
