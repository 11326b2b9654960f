"""Cant and roll bounds, against worked figures and the physical model they must contain."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.track.cant import (
    CantLimits,
    CantTable,
    body_roll_deg,
    cant_angle_deg,
    equilibrium_cant_mm,
    inside_roll_sign,
    roll_bounds_deg,
)


def test_equilibrium_cant_against_a_hand_computation() -> None:
    # v^2 / (g R) of the track plane times 1500 mm: 90 km/h on R = 400 m
    v_mps, r_m, g = 90 / 3.6, 400.0, 9.81
    hand = 1500.0 * v_mps**2 / (g * r_m)
    assert equilibrium_cant_mm(1 / r_m, 90.0) == pytest.approx(hand, rel=0.01)
    assert equilibrium_cant_mm(-1 / r_m, 90.0) == equilibrium_cant_mm(1 / r_m, 90.0)
    assert cant_angle_deg(150.0) == pytest.approx(np.degrees(np.arcsin(0.1)))


def test_the_vehicle_leans_toward_the_inside_of_the_curve() -> None:
    # a left-hand curve (positive curvature) lowers the left side: roll negative
    assert inside_roll_sign(1e-3) == -1 and inside_roll_sign(-1e-3) == 1
    assert inside_roll_sign(1e-3, reverse=True) == 1  # driven the other way, it turns right
    assert inside_roll_sign(0.0) == 0
    roll = body_roll_deg(1 / 500, 150.0, 40.0)
    assert roll < -cant_angle_deg(150.0)  # slower than equilibrium: further in


def test_bounds_contain_every_vehicle_the_line_allows() -> None:
    lim = CantLimits()
    rng = np.random.default_rng(4)
    k = rng.uniform(-1 / 250, 1 / 250, 4000)
    lo, hi = roll_bounds_deg(k, lim)
    d_eq = equilibrium_cant_mm(k, lim.line_speed_kmh)
    # any cant the line's design allows, any speed up to the line speed, within the deficiency
    cant = rng.uniform(0, 1, k.size) * np.minimum(d_eq, lim.max_cant_mm)
    speed = rng.uniform(0, lim.line_speed_kmh, k.size)
    ok = equilibrium_cant_mm(k, speed) - cant <= lim.max_deficiency_mm
    roll = body_roll_deg(k, cant, speed, flexibility=lim.flexibility)
    inward = roll * inside_roll_sign(k)
    assert ok.sum() > 2000
    assert np.all(inward[ok] >= lo[ok] + lim.track_roll_deg - 1e-9)
    assert np.all(inward[ok] <= hi[ok] - lim.track_roll_deg + 1e-9)
    # straight track: only the track's own roll
    lo0, hi0 = roll_bounds_deg(0.0, lim)
    assert (lo0, hi0) == (-lim.track_roll_deg, lim.track_roll_deg)


def test_bad_limits_are_refused() -> None:
    with pytest.raises(ValueError, match="line_speed_kmh"):
        CantLimits(line_speed_kmh=0.0)
    with pytest.raises(ValueError, match="flexibility"):
        CantLimits(flexibility=-0.1)
    # unit slips are refused, naming the unit (a user trial's metres narrowed the bound)
    for kwargs, what in (({"max_cant_mm": 0.18}, "metres"), ({"line_speed_kmh": 2000.0}, "km/h"),
                         ({"max_cant_mm": 1000.0}, "millimetres")):  # fmt: skip
        with pytest.raises(ValueError, match=what):
            CantLimits(**kwargs)


def test_a_known_cant_and_speed_narrow_the_bounds_and_still_contain_the_vehicle() -> None:
    lim = CantLimits()
    rng = np.random.default_rng(9)
    k = rng.uniform(1 / 2000, 1 / 300, 3000) * rng.choice([-1, 1], 3000)
    d_eq = equilibrium_cant_mm(k, lim.line_speed_kmh)
    cant = np.round(rng.uniform(0, 1, k.size) * np.minimum(d_eq, lim.max_cant_mm) / 5) * 5
    speed = rng.uniform(0, lim.line_speed_kmh, k.size)
    ok = equilibrium_cant_mm(k, speed) - cant <= lim.max_deficiency_mm
    for s in (0.0, 0.1, lim.flexibility):  # any vehicle up to the flexibility limit
        inward = body_roll_deg(k, cant, speed, flexibility=s) * inside_roll_sign(k)
        for known_speed in (speed, None):
            lo, hi = roll_bounds_deg(k, lim, cant_mm=cant, speed_kmh=known_speed)
            assert np.all(inward[ok] >= lo[ok] - 1e-9) and np.all(inward[ok] <= hi[ok] + 1e-9)
    lo_c, hi_c = roll_bounds_deg(k, lim)
    lo_t, hi_t = roll_bounds_deg(k, lim, cant_mm=cant, speed_kmh=speed)
    assert np.median((hi_t - lo_t) / (hi_c - lo_c)) < 0.4  # the table narrows it
    # a NaN cant (outside the table) falls back to the curvature's bounds
    lo_n, hi_n = roll_bounds_deg(k, lim, cant_mm=np.nan, speed_kmh=np.nan)
    np.testing.assert_allclose(lo_n, lo_c)
    np.testing.assert_allclose(hi_n, hi_c)


def test_cant_table_reads_interpolates_and_names_bad_rows(tmp_path) -> None:
    p = tmp_path / "cant.csv"
    p.write_text("# line 144, track A\nchainage_m,cant_mm,note\n100,0,\n200,150,curve\n300,150,\n")
    t = CantTable.from_csv(p)
    np.testing.assert_allclose(t.cant_mm_at([150.0, 250.0]), [75.0, 150.0])
    assert np.isnan(t.cant_mm_at([50.0, 301.0])).all()
    t.to_csv(tmp_path / "back.csv")
    back = CantTable.from_csv(tmp_path / "back.csv")
    assert np.array_equal(back.chainage_m, t.chainage_m) and np.array_equal(back.cant_mm, t.cant_mm)
    for text, match in (
        ("chainage,cant\n0,0\n", "must name chainage_m and cant_mm"),
        ("chainage_m,cant_mm\n0,0\n0,10\n", "line 3: chainage_m 0 does not increase"),
        ("chainage_m,cant_mm\n0,0\n10,16\n20,1600\n", "cant_mm 1600 is not within"),
        ("chainage_m,cant_mm\n0,0\n10,0.16\n", "line 3: cant_mm 0.16 reads as metres"),
        ("# a comment\nchainage_m,cant_mm\n0,0\n10,x\n", "line 4:"),
        ("chainage_m,cant_mm\n0,0\n", "at least two rows"),
    ):
        p.write_text(text)
        with pytest.raises(ValueError, match=match) as info:
            CantTable.from_csv(p)
        assert str(p) in str(info.value)


def test_a_train_faster_than_the_curve_was_canted_for_stays_inside() -> None:
    # a line canted for 100 km/h, run at up to 160 km/h (review case): R = 1000 m
    lim = CantLimits(line_speed_kmh=100.0)
    k = 1 / 1000
    lo, hi = roll_bounds_deg(k, lim)
    for c in np.linspace(0, min(float(equilibrium_cant_mm(k, 100.0)), 180.0), 30):
        lt, ht = roll_bounds_deg(k, lim, cant_mm=c)
        for v in np.linspace(0, 160, 33):
            if equilibrium_cant_mm(k, v) - c > lim.max_deficiency_mm:
                continue
            for s in (0.0, 0.2, lim.flexibility):
                inward = -body_roll_deg(k, c, v, s)  # a left-hand curve leans left
                assert lo - 1e-9 <= inward <= hi + 1e-9
                assert lt - 1e-9 <= inward <= ht + 1e-9
