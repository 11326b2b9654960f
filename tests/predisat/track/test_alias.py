"""Tests of predisat.track.alias against distances worked out from the drawn geometry."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.geodesy import LocalFrame
from predisat.track.alias import TrackAliases
from predisat.track.map import TrackMap

FRAME = LocalFrame(50.45, 4.45, 150.0)
LEG_M, GAP_M = 600.0, 40.0
TURN_M = np.pi * GAP_M / 2.0  # the half circle of radius GAP_M / 2 joining the legs


def _track(enu: np.ndarray) -> TrackMap:
    lat, lon, h = FRAME.to_geodetic(enu)
    return TrackMap.from_latlon(lat, lon, h, name="t", tolerance_m=0.05)


def _hairpin() -> TrackMap:
    """East along y = 0, a half circle, west along y = GAP_M."""
    x = np.arange(0.0, LEG_M + 1e-9, 5.0)
    a = np.linspace(0.0, np.pi, 40)[1:-1]
    r = GAP_M / 2.0
    turn = np.stack([LEG_M + r * np.sin(a), r - r * np.cos(a)], axis=-1)
    xy = np.concatenate([np.stack([x, 0 * x], -1), turn, np.stack([x[::-1], GAP_M + 0 * x], -1)])
    return _track(np.column_stack([xy, np.zeros(len(xy))]))


def test_the_other_leg_of_a_hairpin_is_the_alias_of_each_place() -> None:
    """At x = 200 m on the outgoing leg, the return leg lies within 100 m for |x' - 200| <=
    sqrt(100^2 - 40^2), at chainage LEG + TURN + (LEG - x')."""
    t = _hairpin()
    assert t.length_m == pytest.approx(2 * LEG_M + TURN_M, abs=0.5)
    got = TrackAliases.of(t, near_m=100.0, step_m=2.0).within(200.0, 200.0)
    half = np.sqrt(100.0**2 - GAP_M**2)
    want = (LEG_M + TURN_M + LEG_M - (200.0 + half), LEG_M + TURN_M + LEG_M - (200.0 - half))
    assert got.min() == pytest.approx(want[0], abs=5.0)
    assert got.max() == pytest.approx(want[1], abs=5.0)
    # the turn's own neighbours are not aliases: its chords are about its arcs
    assert TrackAliases.of(t, near_m=100.0).within(LEG_M + TURN_M / 2, LEG_M + TURN_M / 2).size == 0
    assert TrackAliases.of(t, near_m=30.0).within(200.0, 200.0).size == 0  # 40 m apart


def test_a_straight_line_and_a_wide_curve_have_none() -> None:
    d = np.linspace(0.0, 3000.0, 7)
    straight = _track(np.stack([d, 0.5 * d, 0 * d], -1))
    a = np.linspace(0.0, np.pi, 200)
    curve = _track(np.stack([300 * np.sin(a), 300 - 300 * np.cos(a), 0 * a], -1))
    for t in (straight, curve):
        found = TrackAliases.of(t)
        assert not found and found.within(0.0, t.length_m).size == 0


def test_a_prediction_rules_the_other_leg_out_only_when_it_misses_it() -> None:
    found = TrackAliases.of(_hairpin())
    other = LEG_M + TURN_M + LEG_M - 200.0
    assert found.excluded_by(195.0, 205.0, 150.0, 250.0)
    assert not found.excluded_by(195.0, 205.0, 150.0, other)


@pytest.mark.parametrize(("near_m", "step_m", "match"), [
    (0.0, 1.0, "near_m"), (float("nan"), 1.0, "near_m"), (100.0, 0.0, "step_m"),
    (100.0, 30.0, "step_m"),
])  # fmt: skip
def test_guards(near_m: float, step_m: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TrackAliases.of(_hairpin(), near_m=near_m, step_m=step_m)


def test_the_apex_of_a_switchback_is_an_alias_of_the_other_leg() -> None:
    """A review: the legs of a V (10 deg apart) are metres apart near the apex, where the
    chainage between two places is only tens of metres; those places were left out."""
    s = np.arange(0.0, 500.0 + 1e-9, 2.0)
    a = np.radians(10.0)
    leg2 = np.stack([500.0 - s[1:] * np.cos(a), s[1:] * np.sin(a)], -1)
    xy = np.concatenate([np.stack([s, 0 * s], -1), leg2])
    found = TrackAliases.of(_track(np.column_stack([xy, np.zeros(len(xy))])))
    near = found.within(485.0, 485.0)  # 15 m before the apex: the other leg 15 m past it
    assert near.size and near.min() <= 515.0 <= near.max()
