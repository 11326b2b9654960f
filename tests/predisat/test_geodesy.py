"""Tests for predisat.geodesy against closed-form WGS84 formulas and pyproj's geodesic."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Geod

from predisat.geodesy import (
    LocalFrame,
    azel_to_enu,
    ecef_to_geodetic,
    enu_rotation,
    enu_to_azel,
    geodetic_to_ecef,
)

A_M = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
GEOD = Geod(ellps="WGS84")
RNG = np.random.default_rng(7)


def closed_form_ecef(lat_deg, lon_deg, h_m):
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    n = A_M / np.sqrt(1 - E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h_m) * np.cos(lat) * np.cos(lon),
            (n + h_m) * np.cos(lat) * np.sin(lon),
            (n * (1 - E2) + h_m) * np.sin(lat),
        ],
        axis=-1,
    )


def test_geodetic_to_ecef_matches_closed_form():
    lat = RNG.uniform(-89, 89, 200)
    lon = RNG.uniform(-180, 180, 200)
    h = RNG.uniform(-100, 9000, 200)
    np.testing.assert_allclose(geodetic_to_ecef(lat, lon, h), closed_form_ecef(lat, lon, h),
                               atol=1e-6)


def test_ecef_round_trip():
    lat = RNG.uniform(-89, 89, 100)
    lon = RNG.uniform(-179, 179, 100)
    h = RNG.uniform(-100, 20000, 100)
    la, lo, hh = ecef_to_geodetic(closed_form_ecef(lat, lon, h))
    np.testing.assert_allclose(la, lat, atol=1e-9)
    np.testing.assert_allclose(lo, lon, atol=1e-9)
    np.testing.assert_allclose(hh, h, atol=1e-5)


def test_ecef_to_geodetic_rejects_bad_shape():
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        ecef_to_geodetic(np.zeros((4, 2)))


def test_enu_rotation_is_orthonormal_and_up_is_the_ellipsoid_normal():
    lat, lon = np.array([50.5, -33.0, 0.0]), np.array([4.7, 151.2, -70.0])
    r = enu_rotation(lat, lon)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-12)
    # The normal is the direction of increasing height at fixed lat/lon.
    normal = closed_form_ecef(lat, lon, 1.0) - closed_form_ecef(lat, lon, 0.0)
    np.testing.assert_allclose(r[:, 2, :], normal, atol=1e-9)
    # North points toward increasing latitude.
    north = closed_form_ecef(lat + 1e-6, lon, 0.0) - closed_form_ecef(lat, lon, 0.0)
    north /= np.linalg.norm(north, axis=-1, keepdims=True)
    np.testing.assert_allclose(r[:, 1, :], north, atol=1e-6)


def test_enu_azimuth_matches_geodesic_azimuth_at_short_range():
    lat0, lon0 = 50.5, 4.7
    frame = LocalFrame(lat0, lon0)
    az_true = RNG.uniform(0, 360, 50)
    lon1, lat1, _ = GEOD.fwd(np.full(50, lon0), np.full(50, lat0), az_true, np.full(50, 500.0))
    az, el, rng = enu_to_azel(frame.to_enu(lat1, lon1, 0.0))
    np.testing.assert_allclose(((az - az_true + 180) % 360) - 180, 0.0, atol=1e-4)
    # A point on the ellipsoid 500 m away lies below the horizontal by about d / 2R.
    np.testing.assert_allclose(el, -np.degrees(500.0 / (2 * 6.37e6)), atol=5e-4)
    np.testing.assert_allclose(rng, 500.0, atol=1e-3)


def test_azel_to_enu_inverts_enu_to_azel():
    az = RNG.uniform(0, 360, 100)
    el = RNG.uniform(-89, 89, 100)
    v = azel_to_enu(az, el)
    np.testing.assert_allclose(np.linalg.norm(v, axis=-1), 1.0, atol=1e-12)
    az2, el2, _ = enu_to_azel(v)
    np.testing.assert_allclose(((az2 - az + 180) % 360) - 180, 0.0, atol=1e-9)
    np.testing.assert_allclose(el2, el, atol=1e-9)
    assert np.all((az2 >= 0) & (az2 < 360))


def test_local_frame_round_trip_and_origin():
    frame = LocalFrame(50.567496, 4.695464, 150.0)
    np.testing.assert_allclose(frame.to_enu(50.567496, 4.695464, 150.0), 0.0, atol=1e-6)
    lat = 50.567496 + RNG.uniform(-0.2, 0.2, 50)
    lon = 4.695464 + RNG.uniform(-0.2, 0.2, 50)
    h = RNG.uniform(0, 300, 50)
    la, lo, hh = frame.to_geodetic(frame.to_enu(lat, lon, h))
    np.testing.assert_allclose(la, lat, atol=1e-10)
    np.testing.assert_allclose(lo, lon, atol=1e-10)
    np.testing.assert_allclose(hh, h, atol=1e-5)


def test_rotation_from_carries_a_remote_elevation_exactly():
    """A direction at elevation el in a remote point's own ENU keeps el there after rotation."""
    frame = LocalFrame(50.56, 4.69)
    lat1, lon1 = 50.45, 4.66  # ~13 km away
    r = frame.rotation_from(lat1, lon1)
    v_local = azel_to_enu(123.0, 30.0)
    v_frame = r @ v_local
    # Independent: the remote up (ellipsoid normal) in ECEF, rotated into the frame.
    up_ecef = closed_form_ecef(lat1, lon1, 1.0) - closed_form_ecef(lat1, lon1, 0.0)
    up_frame = frame.rotation @ up_ecef
    el = np.degrees(np.arcsin(v_frame @ up_frame))
    assert el == pytest.approx(30.0, abs=1e-6)
    # In the frame's own ENU the elevation differs by up to the ~0.12 deg angle between normals.
    _, el_frame, _ = enu_to_azel(v_frame)
    assert abs(el_frame - 30.0) > 1e-3


def test_longitudes_across_the_antimeridian_interpolate_on_the_line() -> None:
    """A plain mean of 179.99 and -179.99 is 0: the other side of the Earth (a geometry
    review found it in the registration, the report's map, the km posts and the synthetic
    world's start time)."""
    from predisat.geodesy import unwrap_lon_deg, wrap_lon_deg

    lon = np.array([179.98, 179.99, -179.99, -179.98])
    mid = wrap_lon_deg(0.5 * (unwrap_lon_deg(lon)[1:] + unwrap_lon_deg(lon)[:-1]))
    np.testing.assert_allclose(np.abs(mid), [179.985, 180.0, 179.985], atol=1e-9)
    wrapped = wrap_lon_deg([180.0, 540.0, -180.0, 190.0])
    np.testing.assert_allclose(wrapped, [-180, -180, -180, -170])


def test_kilometre_posts_of_a_section_across_the_antimeridian_are_found(tmp_path) -> None:
    import json

    from pyproj import Geod

    from predisat.track.map import TrackMap
    from predisat.track.readers import kilometre_posts_from_sections

    geod = Geod(ellps="WGS84")
    n = 61  # vertices every 330 m eastward from 179.9 E, across 180 deg at about 10.6 km
    lon, lat, _ = geod.fwd(np.full(n, 179.9), np.full(n, -16.8), np.full(n, 90.0),
                           np.arange(n) * 330.0)  # fmt: skip
    track = TrackMap.from_latlon(lat, lon, 0.0, "A", tolerance_m=0.05)
    feats = []
    for k in range(5):  # sections of 12 segments, km from 0.35 (P0) on
        sl = slice(k * 12, k * 12 + 13)
        feats.append({"type": "Feature",
                      "properties": {"mfrom": k * 3960.0 + 350.0, "mto": (k + 1) * 3960.0 + 350.0},
                      "geometry": {"type": "LineString",
                                   "coordinates": np.c_[lon[sl], lat[sl]].tolist()}})  # fmt: skip
    path = tmp_path / "sections.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    posts = {round(p.km_m): p.chainage_m for p in kilometre_posts_from_sections(track, path)}
    for km in range(1000, 20001, 1000):  # km 11 lies in the section across 180 deg
        assert posts[km] == pytest.approx(km - 350.0, abs=1.0)
