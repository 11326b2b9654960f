"""Mask-aware selection over the confidence interval."""

from __future__ import annotations

import numpy as np
import pytest

from locator.selection import Exclusion, direction_at, select_satellites
from predisat.masks.maskset import MaskSet
from tests.locator._scene import sky, straight_path


@pytest.fixture(scope="module")
def masks() -> MaskSet:
    path = straight_path(0.0, 1200.0)
    ch = np.arange(0.0, 1001.0, 10.0)
    m = np.full((len(ch), 360), 10.0)
    m[ch == 600.0, 40:51] = 40.0  # a building at chainage 600 toward azimuths 40-50
    return MaskSet.from_track(path.track, ch, m, margin_deg=1.0)


def test_below_worst_case_but_above_at_centre(masks):
    az, el = np.array([45.0, 200.0]), np.array([30.0, 30.0])
    assert masks.trusted(500.0, az, el).all()  # at the interval centre both are fine
    sel = select_satellites(masks, 420.0, 620.0, az, el, sats=["G01", "G02"])
    assert sel.trusted.tolist() == [False, True]
    assert sel.reason[0] == Exclusion.BELOW_MASK
    assert sel.threshold_deg.tolist() == [41.0, 11.0]
    rep = sel.report()
    assert rep["sat"].tolist() == ["G01"] and rep["reason"].tolist() == ["below_mask"]
    # an interval that stops short of the building trusts it
    assert select_satellites(masks, 420.0, 590.0, az, el).trusted.all()


def test_reasons_and_extra_margin(masks):
    az = np.array([100.0, np.nan, 100.0, 100.0])
    el = np.array([50.0, 50.0, 50.0, 11.5])
    valid = np.array([True, True, False, True])
    sel = select_satellites(masks, 100.0, 200.0, az, el, valid=valid)
    assert sel.reason.tolist() == [0, Exclusion.NO_DIRECTION, Exclusion.EPHEMERIS_INVALID, 0]
    sel2 = select_satellites(masks, 100.0, 200.0, az, el, valid=valid, extra_margin_deg=1.0)
    assert sel2.reason[3] == Exclusion.BELOW_MASK


def test_outside_coverage_and_unbounded(masks):
    az, el = np.array([100.0]), np.array([60.0])
    assert select_satellites(masks, 950.0, 1100.0, az, el).reason[0] == Exclusion.OUTSIDE_COVERAGE
    assert select_satellites(masks, 950.0, 1100.0, az, el, clip=True).trusted[0]
    inf = select_satellites(masks, -np.inf, 300.0, az, el)
    assert inf.reason[0] == Exclusion.OUTSIDE_COVERAGE
    with pytest.raises(ValueError, match="NaN"):
        select_satellites(masks, np.nan, 300.0, az, el)


def test_vectorised_over_epochs(masks):
    lo = np.array([0.0, 550.0, 700.0])
    hi = lo + 100.0
    az = np.tile([45.0, 300.0], (3, 1))
    el = np.tile([25.0, 25.0], (3, 1))
    sel = select_satellites(masks, lo, hi, az, el)
    assert sel.trusted.tolist() == [[True, True], [False, True], [True, True]]
    assert sel.count.tolist() == [2, 1, 2]
    with pytest.raises(ValueError, match="one interval per epoch"):
        select_satellites(masks, lo[:2], hi[:2], az, el)


def test_direction_at_recovers_geometry():
    path = straight_path(0.0, 1200.0)
    x = path.ecef_at(300.0)
    az0, el0 = np.array([10.0, 123.0, 359.5]), np.array([5.0, 45.0, 80.0])
    sat = sky(x, az0, el0)
    az, el = direction_at(path, 300.0, sat)
    np.testing.assert_allclose(az, az0, atol=1e-6)
    np.testing.assert_allclose(el, el0, atol=1e-6)
    # 400 m away the direction changes by far less than a mask bin
    az2, el2 = direction_at(path, np.array([100.0, 500.0]), sat)
    assert az2.shape == (2, 3)
    assert np.max(np.abs(el2 - el0)) < 0.01
