"""Satellite selection, az/el against PROJ's topocentric conversion, and the trust rules."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Transformer

from predisat.availability.satellites import (
    LinePositions,
    SatellitePositions,
    TrustRule,
    azel,
    default_ephemeris,
    default_window,
    select_satellites,
)
from predisat.gnss.ephemeris import Ephemeris
from predisat.masks.maskset import MaskSet

SATS = ("C05", "E01", "G02", "G10", "J01", "R07", "E11")


@pytest.fixture(scope="module")
def eph() -> Ephemeris:
    return default_ephemeris()


def test_select_satellites_by_name_and_letters() -> None:
    assert select_satellites(SATS, "gps") == ("G02", "G10")
    assert select_satellites(SATS, "gps+galileo") == ("E01", "G02", "G10", "E11")
    assert select_satellites(SATS, "GE") == select_satellites(SATS, "gps+galileo")
    assert select_satellites(SATS, ["R", "C"]) == ("C05", "R07")
    assert select_satellites(SATS, "all") == SATS
    with pytest.raises(ValueError, match="constellation"):
        select_satellites(SATS, "beidou-only")


def test_default_day_and_window(eph: Ephemeris) -> None:
    t = default_window()
    assert len(t) == 2880 and np.all(np.diff(t) == 30.0)
    systems = {s[0] for s in eph.satellites}
    assert {"G", "R", "E", "C", "J"} <= systems
    sp = SatellitePositions.from_ephemeris(eph, t[::120], "gps")
    assert set(sp.systems) == {"G"}
    assert sp.pos_ecef_m.shape == (24, len(sp.sats), 3)
    # GPS orbits: 26 560 km from the centre of the Earth, eccentricity below 0.03
    r = np.linalg.norm(sp.pos_ecef_m[sp.valid], axis=-1)
    assert np.all(np.abs(r - 26.56e6) < 0.03 * 26.56e6)


def test_azel_matches_proj_topocentric(eph: Ephemeris) -> None:
    lat, lon, h = 50.55, 4.70, 160.0
    sp = SatellitePositions.from_ephemeris(eph, default_window()[::240], "all")
    pos = LinePositions(np.array([0.0]), lat, lon, h, 90.0)
    az, el = azel(pos.ecef_m[0], pos.enu_rotation[0], sp.pos_ecef_m)
    topo = Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=topocentric +ellps=WGS84 +lat_0={lat} +lon_0={lon} +h_0={h}"
    )
    ok = sp.valid
    x = sp.pos_ecef_m[ok]
    e, n, u = topo.transform(x[:, 0], x[:, 1], x[:, 2])
    az_ref = np.mod(np.degrees(np.arctan2(e, n)), 360.0)
    el_ref = np.degrees(np.arctan2(u, np.hypot(e, n)))
    np.testing.assert_allclose(el[ok], el_ref, atol=1e-7)
    d_az = np.abs((az[ok] - az_ref + 180.0) % 360.0 - 180.0)
    assert d_az.max() < 1e-7
    assert np.all(np.isnan(el[~ok]))


def test_cutoff_and_horizon_rules() -> None:
    el = np.array([-1.0, 0.0, 0.5, 14.9, 15.0, 15.1, np.nan])
    az = np.zeros_like(el)
    np.testing.assert_array_equal(
        TrustRule.none().trusted(0.0, az, el), [False, False, True, True, True, True, False]
    )
    np.testing.assert_array_equal(
        TrustRule.cutoff(15).trusted(0.0, az, el), [False] * 5 + [True, False]
    )
    assert TrustRule.cutoff(15).opening_angle_deg(3).tolist() == [150.0] * 3
    with pytest.raises(ValueError, match="masks"):
        TrustRule("mask")


def test_mask_rule_follows_the_mask_set() -> None:
    n_az = 72
    mask = np.tile(np.where(np.arange(n_az) < 36, 30.0, 5.0), (3, 1))
    ms = MaskSet.from_arrays(
        [0.0, 10.0, 20.0], [50.0] * 3, [4.0] * 3, 100.0, [0.0] * 3, mask, margin_deg=2.0
    )
    rule = TrustRule.mask(ms)
    # bins of 5 deg centred on multiples of 5: az 100 is in the 30-deg half, az 200 in the other
    assert rule.trusted(10.0, 100.0, 32.1) and not rule.trusted(10.0, 100.0, 32.0)
    assert rule.trusted(10.0, 200.0, 7.5) and not rule.trusted(10.0, 200.0, 6.9)
    table = rule.threshold_table([0.0, 20.0])
    assert table.shape == (2, n_az) and table[0, 0] == 32.0 and table[0, -1] == 7.0
    rng = np.random.default_rng(3)
    az, el = rng.uniform(0, 360, 500), rng.uniform(0, 60, 500)
    np.testing.assert_array_equal(rule.trusted(10.0, az, el), ms.trusted(10.0, az, el))
