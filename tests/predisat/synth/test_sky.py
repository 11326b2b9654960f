"""Sun position against published and independently computed values; sky appearance checks."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.geodesy import azel_to_enu
from predisat.gnss.sun import sun_azel, sun_direction_enu
from predisat.gnss.timescale import calendar_to_gps_s
from predisat.synth.sky import SkyModel, fbm


def test_sun_matches_spa_published_example() -> None:
    # Reda & Andreas (2004), NREL/TP-560-34302, table A5.1: 2003-10-17 12:30:30 at UTC-7,
    # 39.742476 N 105.1786 W: topocentric azimuth 194.34024, zenith 50.11162 deg (refracted
    # for 820 mbar, 11 C; the standard atmosphere used here refracts 0.003 deg more).
    gps = float(calendar_to_gps_s(2003, 10, 17, 19, 30, 30)) + 13.0  # GPS-UTC = 13 s in 2003
    az, el = sun_azel(gps, 39.742476, -105.1786)
    assert az == pytest.approx(194.34024, abs=0.01)
    assert 90.0 - el == pytest.approx(50.11162, abs=0.01)


def _michalsky(jd: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray):
    """The Astronomical Almanac's low-precision sun (Michalsky 1988), written independently."""
    n = jd - 2451545.0
    mean_lon = np.mod(280.460 + 0.9856474 * n, 360.0)
    g = np.radians(np.mod(357.528 + 0.9856003 * n, 360.0))
    ecl = np.radians(mean_lon + 1.915 * np.sin(g) + 0.020 * np.sin(2 * g))
    eps = np.radians(23.439 - 0.0000004 * n)
    ra = np.arctan2(np.cos(eps) * np.sin(ecl), np.cos(ecl))
    dec = np.arcsin(np.sin(eps) * np.sin(ecl))
    ut_h = np.mod(jd - 0.5, 1.0) * 24.0
    gmst_h = 6.697375 + 0.0657098242 * n + ut_h
    ha = np.radians(np.mod(gmst_h * 15.0 + lon_deg, 360.0)) - ra
    lat = np.radians(lat_deg)
    el = np.arcsin(np.sin(dec) * np.sin(lat) + np.cos(dec) * np.cos(lat) * np.cos(ha))
    az = np.arctan2(
        -np.cos(dec) * np.sin(ha),
        np.sin(dec) * np.cos(lat) - np.cos(dec) * np.sin(lat) * np.cos(ha),
    )
    return np.mod(np.degrees(az), 360.0), np.degrees(el)


def test_sun_matches_independent_almanac_algorithm() -> None:
    rng = np.random.default_rng(0)
    n = 400
    days = rng.uniform(0, 365.25 * 12, n)  # 2018-2029: GPS - UTC = 18 s throughout
    jd = 2458119.5 + days  # 2018-01-01T00:00 UTC
    lat = rng.uniform(-60, 70, n)
    lon = rng.uniform(-180, 180, n)
    utc_s = (jd - 2444244.5) * 86400.0  # seconds since 1980-01-06 on the UTC scale
    az, el = sun_azel(utc_s + 18.0, lat, lon, refraction=False)
    az_ref, el_ref = _michalsky(jd, lat, lon)
    up = el_ref > 3.0
    assert up.sum() > 100
    assert np.max(np.abs(el[up] - el_ref[up])) < 0.03
    daz = (az - az_ref + 180.0) % 360.0 - 180.0
    # azimuth error scales with 1 / cos(el); compare the angle on the sky
    assert np.max(np.abs(daz[up] * np.cos(np.radians(el_ref[up])))) < 0.03


def test_refraction_follows_bennett() -> None:
    # Bennett (1982): R = cot(h + 7.31 / (h + 4.4)) arcmin for apparent elevation h (deg)
    t0 = float(calendar_to_gps_s(2024, 6, 21, 3, 36, 0)) + 18.0  # sunrise in Belgium
    gps = t0 + np.arange(0, 4 * 3600, 600.0)
    _, el_geo = sun_azel(gps, 50.5, 4.7, refraction=False)
    _, el_app = sun_azel(gps, 50.5, 4.7)
    bennett = 1.0 / np.tan(np.radians(el_app + 7.31 / (el_app + 4.4))) / 60.0
    assert el_app[0] - el_geo[0] > 0.4  # near the horizon
    assert np.allclose(el_app - el_geo, bennett, atol=0.02)


def test_sun_direction_agrees_with_geodesy() -> None:
    assert np.allclose(sun_direction_enu(123.0, 34.0), azel_to_enu(123.0, 34.0))


def test_clear_sky_brighter_near_sun_and_bluer_at_zenith_than_horizon() -> None:
    sky = SkyModel.clear(sun_az_deg=150.0, sun_el_deg=40.0, seed=1)
    near = sky.radiance(azel_to_enu(150.0, 48.0))  # 8 deg from the sun
    opposite = sky.radiance(azel_to_enu(330.0, 48.0))
    lum = np.array([0.2126, 0.7152, 0.0722])
    assert near @ lum > 2.0 * (opposite @ lum)
    zenith = sky.radiance(azel_to_enu(330.0, 89.0))
    horizon = sky.radiance(azel_to_enu(330.0, 3.0))
    assert zenith[2] / zenith[0] > horizon[2] / horizon[0]
    assert zenith[2] > zenith[0]  # blue


def test_overcast_is_low_contrast_grey_without_sun() -> None:
    sky = SkyModel.overcast(sun_az_deg=150.0, sun_el_deg=40.0, seed=2)
    az, el = np.meshgrid(np.arange(0, 360, 7.0), np.arange(10, 90, 5.0))
    rad = sky.radiance(azel_to_enu(az, el))
    lum = rad @ np.array([0.2126, 0.7152, 0.0722])
    assert lum.max() / lum.min() < 3.5
    assert lum.std() / lum.mean() < 0.35
    chroma = rad.max(-1) / rad.min(-1)
    assert np.all(chroma < 1.2)  # grey
    clear = SkyModel.clear(150.0, 40.0, seed=2).radiance(azel_to_enu(az, el)) @ np.array(
        [0.2126, 0.7152, 0.0722]
    )
    assert lum.std() / lum.mean() < clear.std() / clear.mean()
    assert np.all(sky.sun_irradiance == 0)
    assert np.all(sky.sun_transmittance(np.zeros((3, 3))) == 0)


def test_cloud_shadows_cover_about_the_cloud_cover() -> None:
    sky = SkyModel.cloudy(sun_az_deg=200.0, sun_el_deg=50.0, seed=5)
    xy = np.random.default_rng(1).uniform(-20000, 20000, (20000, 2))
    pts = np.column_stack([xy, np.zeros(len(xy))])
    shade = sky.sun_transmittance(pts) < 0.5
    assert abs(shade.mean() - sky.cloud_cover) < 0.12


def test_ambient_matches_numerical_irradiance() -> None:
    sky = SkyModel.overcast(sun_az_deg=100.0, sun_el_deg=35.0, seed=3)
    # (1/pi) * integral of L cos over the upper hemisphere, midpoint rule in (az, el)
    d_el, d_az = 0.5, 1.0
    el = np.arange(d_el / 2, 90, d_el)
    az = np.arange(d_az / 2, 360, d_az)
    ee, aa = np.meshgrid(el, az, indexing="ij")
    rad = sky.radiance(azel_to_enu(aa, ee))
    w = np.sin(np.radians(ee)) * np.cos(np.radians(ee)) * np.radians(d_el) * np.radians(d_az)
    expected = (rad * w[..., None]).sum((0, 1)) / np.pi
    got = sky.ambient_radiance(np.array([0.0, 0.0, 1.0]))
    assert np.allclose(got, expected, rtol=0.08)


def test_fbm_is_deterministic_and_centred() -> None:
    x, y = np.random.default_rng(0).uniform(0, 300, (2, 50000))
    a, b = fbm(x, y, seed=4), fbm(x, y, seed=4)
    c = fbm(x, y, seed=5)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert abs(float(a.mean()) - 0.5) < 0.03
    assert a.shape == x.shape


def test_bad_parameters_are_rejected() -> None:
    with pytest.raises(ValueError, match="condition"):
        SkyModel("foggy", 0.0, 30.0)
    with pytest.raises(ValueError, match="cloud_cover"):
        SkyModel("cloudy", 0.0, 30.0, cloud_cover=1.5)
    with pytest.raises(ValueError, match="lat_deg"):
        sun_azel(0.0, 95.0, 0.0)
