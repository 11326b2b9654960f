"""ETCS confidence interval and safe ends (locator.odometry.confidence), closed-form truths."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from locator.odometry.confidence import (
    BalisePassage,
    OdometerAccuracy,
    in_expectation_window,
    safe_fronts,
)
from locator.odometry.odometer import OdometerConfig, simulate_odometer

ACC = OdometerAccuracy(abs_error_m=2.0, over_rel=0.04, under_rel=0.02)


def test_doubts_grow_linearly_from_the_reference():
    odo = np.arange(0.0, 1001.0, 100.0)
    sf = safe_fronts(odo, [BalisePassage(0, 5000.0, accuracy_m=1.0)], ACC, orientation=1)
    np.testing.assert_allclose(sf.doubt_over_m, 1.0 + 2.0 + 0.04 * odo)
    np.testing.assert_allclose(sf.doubt_under_m, 1.0 + 2.0 + 0.02 * odo)
    np.testing.assert_allclose(sf.est_front_m, 5000.0 + odo)
    np.testing.assert_allclose(sf.max_safe_front_m, 5000.0 + odo + sf.doubt_under_m)
    np.testing.assert_allclose(sf.min_safe_front_m, 5000.0 + odo - sf.doubt_over_m)
    np.testing.assert_allclose(sf.dist_since_ref_m, odo)


def test_after_a_reversal_the_doubts_grow_with_both_legs_not_the_net_displacement():
    # 1000 m forward, 940 m back (a shunting move), each leg read at the worst of its relative
    # bound: forward the wheels under-read by 2 % (the train ran 1020 m), back they over-read
    # by 4 % (it ran 902.4 m): the true end lies 117.6 m ahead of the reference, not 60 m
    true_fwd, true_back = 1000.0 * (1.0 + 0.02), 940.0 * (1.0 - 0.04)
    odo = np.concatenate([np.arange(0.0, 1001.0, 10.0), 1000.0 - np.arange(10.0, 941.0, 10.0)])
    truth_end = true_fwd - true_back
    sf = safe_fronts(odo, [BalisePassage(0, 5000.0, accuracy_m=0.0)], ACC, orientation=1)
    assert sf.dist_since_ref_m[-1] == pytest.approx(1940.0)
    assert sf.min_safe_front_m[-1] <= 5000.0 + truth_end <= sf.max_safe_front_m[-1]
    # the net displacement's doubt (2 m + 2 % of 60 m) would have missed it by 54 m
    assert 5000.0 + 60.0 + ACC.doubt_under_m(60.0) < 5000.0 + truth_end
    lo, hi = ACC.displacement_bounds_m(60.0, 1940.0)
    assert lo <= truth_end <= hi and hi - lo == pytest.approx(2 * (2.0 + 0.04 * 1940.0))
    # without a reversal nothing changes
    assert ACC.displacement_bounds_m(60.0, 60.0) == ACC.displacement_bounds_m(60.0)


def test_orientation_minus_one_mirrors_the_fronts():
    odo = np.arange(0.0, 501.0, 50.0)
    sf = safe_fronts(odo, [BalisePassage(0, 5000.0)], ACC, orientation=-1,
                     antenna_to_front_m=10.0)  # fmt: skip
    np.testing.assert_allclose(sf.est_front_m, 5000.0 - odo - 10.0)
    assert np.all(sf.max_safe_front_m < sf.est_front_m)  # furthest ahead = lowest chainage
    assert np.all(sf.min_safe_front_m > sf.est_front_m)


def test_reference_resets_non_reference_does_not_known_distance_falls_back():
    odo = np.arange(0.0, 3001.0, 10.0)  # samples every 10 m
    passages = [
        BalisePassage(0, 1000.0, accuracy_m=1.0),  # A: reference
        BalisePassage(100, 2000.0, q_reference=False),  # B at 1000 m: no reset
        BalisePassage(200, 3000.0, q_reference=False, known_from=1),  # C: known distance to B
        BalisePassage(250, 3500.0, q_reference=True),  # D: reference
    ]
    sf = safe_fronts(odo, passages, ACC)
    assert sf.accepted.all()
    over_at_b = 1.0 + 2.0 + 0.04 * 1000.0
    assert sf.doubt_over_m[100] == pytest.approx(over_at_b)
    assert sf.doubt_over_m[150] == pytest.approx(1.0 + 2.0 + 0.04 * 1500.0)  # kept growing
    # at C the doubt falls back to its value at B, then grows again from C
    assert sf.doubt_over_m[200] == pytest.approx(over_at_b + 2.0)
    assert sf.doubt_over_m[240] == pytest.approx(over_at_b + 2.0 + 0.04 * 400.0)
    assert sf.est_front_m[200] == pytest.approx(3000.0)
    assert sf.doubt_over_m[250] == pytest.approx(1.0 + 2.0)  # D resets
    assert sf.dist_since_ref_m[260] == pytest.approx(100.0)


def test_expectation_window_accepts_only_between_max_and_min_safe_front():
    # estimate 1000 m with doubts 20 m: max safe 1020, min safe 980; accuracy 1 m
    assert in_expectation_window(1015.0, 1.0, 1020.0, 980.0, 1)
    assert not in_expectation_window(1025.0, 1.0, 1020.0, 980.0, 1)  # not reachable yet
    assert not in_expectation_window(975.0, 1.0, 1020.0, 980.0, 1)  # already passed
    assert in_expectation_window(985.0, 1.0, 980.0, 1020.0, -1)


def test_linked_balise_outside_its_window_is_rejected_and_does_not_reset():
    odo = np.arange(0.0, 2001.0, 10.0)
    passages = [BalisePassage(0, 0.0), BalisePassage(100, 1200.0)]  # read 200 m too early
    sf = safe_fronts(odo, passages, ACC)
    assert not sf.accepted[1]
    assert sf.est_front_m[150] == pytest.approx(1500.0)  # still dead-reckoned from A
    ok = safe_fronts(odo, [BalisePassage(0, 0.0), BalisePassage(100, 1010.0)], ACC)
    assert ok.accepted[1] and ok.est_front_m[150] == pytest.approx(1510.0)


def test_rear_needs_train_integrity():
    odo = np.arange(0.0, 100.0, 10.0)
    conf = np.arange(10) < 5
    sf = safe_fronts(odo, [BalisePassage(0, 0.0)], ACC, train_length_m=80.0,
                     integrity_confirmed=conf)  # fmt: skip
    assert np.isnan(sf.est_rear_m[5:]).all() and np.isfinite(sf.est_rear_m[:5]).all()
    np.testing.assert_allclose(sf.max_safe_rear_m[:5], sf.max_safe_front_m[:5] - 80.0)


def test_true_front_stays_between_the_safe_fronts_of_a_simulated_odometer():
    dt = 0.1
    t = np.arange(0.0, 300.0, dt)
    truth = 0.5 * np.minimum(t, 40.0) ** 2 / 2 + 20.0 * np.maximum(t - 40.0, 0.0)  # 0.5 m/s^2
    cfg = OdometerConfig.motor_axle(radar=True)
    acc = OdometerAccuracy.from_config(cfg)
    for seed in range(5):
        log = simulate_odometer(t, truth, cfg, seed=seed)
        refs = [BalisePassage(int(k), 100.0 + truth[k], accuracy_m=1.0)
                for k in (0, 1500, 2500)]  # fmt: skip
        sf = safe_fronts(log.dist_m, refs, acc, antenna_to_front_m=5.0)
        true_front = 100.0 + truth + 5.0
        assert np.all((sf.min_safe_front_m <= true_front) & (true_front <= sf.max_safe_front_m))


def test_guards():
    with pytest.raises(ValueError, match="first passage must be a reference"):
        safe_fronts(np.zeros(3), [BalisePassage(0, 0.0, q_reference=False)], ACC)
    with pytest.raises(ValueError, match="orientation"):
        safe_fronts(np.zeros(3), [BalisePassage(0, 0.0)], ACC, orientation=0)
    with pytest.raises(ValueError, match="over_rel"):
        OdometerAccuracy(over_rel=1.5)


def test_the_disputed_distance_widens_the_fronts_from_the_reference_on():
    odo = np.arange(0.0, 1001.0, 100.0)
    ahead = np.linspace(0.0, 50.0, len(odo))
    behind = np.linspace(0.0, 20.0, len(odo))
    passages = [BalisePassage(0, 5000.0, accuracy_m=1.0), BalisePassage(5, 5500.0, accuracy_m=1.0)]
    plain = safe_fronts(odo, passages, ACC, orientation=1)
    sf = safe_fronts(odo, passages, ACC, orientation=1, extra_ahead_m=ahead,
                     extra_behind_m=behind)  # fmt: skip
    since = np.where(np.arange(len(odo)) < 5, 0, 5)  # the reference in force
    da, db = ahead - ahead[since], behind - behind[since]
    d = odo - odo[since]
    # the doubts grow over the distance used and the disputed one (the wheel that ran on has
    # its own error), the larger rate both ways (more run than moved: as after a reversal),
    # and the disputed distance is added on its side
    wide = 2.0 + 0.04 * (d + da + db)
    np.testing.assert_allclose(sf.doubt_under_m, 1.0 + wide + da)
    np.testing.assert_allclose(sf.doubt_over_m, 1.0 + wide + db)
    assert np.all(sf.doubt_under_m - plain.doubt_under_m >= da)
    with pytest.raises(ValueError, match="one value per odo_m"):
        safe_fronts(odo, passages, ACC, extra_ahead_m=ahead[:3])


def test_a_rejected_linked_balise_widens_the_interval_to_cover_it_and_raises_the_alarm():
    # the odometer under-read by 10 % over its first 1000 m (beyond ACC's 2 %: a slide): the
    # balise at 1100 m is read when the odometer says 1000 m, outside its window
    odo = np.arange(0.0, 2001.0, 10.0)
    truth = np.where(odo <= 1000.0, 1.1 * odo, odo + 100.0)
    passages = [BalisePassage(0, 0.0, accuracy_m=1.0), BalisePassage(100, 1100.0),
                BalisePassage(180, 1900.0, linked=False)]  # a reference, accepted
    sf = safe_fronts(odo, passages, ACC)
    assert list(sf.accepted) == [True, False, True]
    assert not sf.linking_alarm[:100].any() and sf.linking_alarm[100:180].all()
    assert not sf.linking_alarm[180:].any()  # cleared by the next accepted reference
    # from the reading on, both the old interval and the balise's location are covered
    assert sf.max_safe_front_m[100] >= 1101.0 and sf.min_safe_front_m[100] <= 1000.0 - 42.0
    inside = (sf.min_safe_front_m <= truth + 1e-9) & (truth <= sf.max_safe_front_m + 1e-9)
    assert inside[100:].all()
    assert not inside[60:100].all()  # the under-read broke the bound before the reading
    assert sf.est_front_m[150] == pytest.approx(1500.0)  # no reset: still dead-reckoned
    # the distance since the reference still counts from the last accepted one
    assert sf.dist_since_ref_m[150] == pytest.approx(1500.0)


def test_a_list_misplacing_every_balise_is_not_accepted_through_the_widened_window():
    # the balise list 50 m off (another chainage origin, a survey error), the odometer right:
    # the first linked balise is rejected and the interval widened to cover it; the second,
    # as misplaced, lies inside that widened interval but not in the window of the interval
    # the odometer supports. Accepting it reset the fronts 49 m off the truth and cleared
    # the alarm (a user trial, 2026-12-07: 28.9 m with a list 30 m off)
    odo = np.arange(0.0, 2001.0, 10.0)
    truth = odo.copy()
    passages = [BalisePassage(0, 0.0, accuracy_m=1.0)] + [
        BalisePassage(k, odo[k] + 50.0, accuracy_m=1.0) for k in (50, 100, 150)]
    sf = safe_fronts(odo, passages, ACC)
    assert list(sf.accepted) == [True, False, False, False]
    inside = (sf.min_safe_front_m <= truth + 1e-9) & (truth <= sf.max_safe_front_m + 1e-9)
    assert inside.all()
    assert sf.linking_alarm[50:].all()
    # a balise where the odometer puts the train is accepted and clears the alarm
    ok = safe_fronts(odo, [*passages, BalisePassage(180, 1800.0)], ACC)
    assert ok.accepted[-1] and not ok.linking_alarm[180:].any()


def test_a_known_distance_balise_keeps_its_own_location_accuracy():
    odo = np.arange(0.0, 2001.0, 10.0)
    passages = [BalisePassage(0, 0.0, accuracy_m=1.0),
                BalisePassage(50, 500.0, q_reference=False),
                BalisePassage(100, 1000.0, accuracy_m=20.0, q_reference=False, known_from=1)]
    sf = safe_fronts(odo, passages, ACC)
    # the doubt held at B (1 + 2 + 4 % of 500 m = 23 m over) and C's own 20 m: the larger;
    # under: B's 1 + 2 + 2 % of 500 m = 13 m is below C's 20 m
    assert sf.doubt_over_m[100] == pytest.approx(23.0 + 2.0)
    assert sf.doubt_under_m[100] == pytest.approx(20.0 + 2.0)
    # C really 15 m further than its list says: the truth stays inside
    truth = odo + 15.0 * (odo >= 1000.0)
    assert np.all(sf.max_safe_front_m[100:] >= truth[100:])


def _brute_excess(acc, true_m, odo_m, ahead_m, behind_m):
    """Per j, the largest excess over every anchor i <= j by displacement_bounds_m itself."""
    n = len(true_m)
    ran = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(odo_m)))]) + ahead_m + behind_m
    out = np.full(n, -np.inf)
    for i in range(n):
        d, tr = odo_m[i:] - odo_m[i], ran[i:] - ran[i]
        lo, hi = acc.displacement_bounds_m(d, tr)
        lo, hi = lo - (behind_m[i:] - behind_m[i]), hi + (ahead_m[i:] - ahead_m[i])
        moved = true_m[i:] - true_m[i]
        out[i:] = np.maximum(out[i:], np.maximum(lo - moved, moved - hi))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_the_excess_from_every_anchor_is_the_pairwise_bounds_check(seed):
    """anchor_excess_m (O(n)) against every pair checked with displacement_bounds_m: forward,
    standing, backward legs, disputed steps, and errors both ways."""
    rng = np.random.default_rng(seed)
    n = 300
    legs = np.repeat(rng.choice([-1.0, 0.0, 1.0, 1.0], 12), n // 12)[: n - 1]
    step = legs * rng.uniform(5.0, 15.0, n - 1)
    true_m = np.concatenate([[0.0], np.cumsum(step)])
    odo_m = np.concatenate([[0.0], np.cumsum(step * (1 + rng.normal(0.0, 0.05, n - 1)))])
    disputed = rng.random(n - 1) < 0.05
    ahead = np.concatenate([[0.0], np.cumsum(disputed * rng.uniform(0.0, 3.0, n - 1))])
    behind = np.concatenate([[0.0], np.cumsum(disputed * rng.uniform(0.0, 3.0, n - 1))])
    acc = OdometerAccuracy(1.0, 0.04, 0.02)
    excess, anchor = acc.anchor_excess_m(true_m, odo_m, ahead, behind)
    np.testing.assert_allclose(excess, _brute_excess(acc, true_m, odo_m, ahead, behind),
                               atol=1e-9)  # fmt: skip
    assert np.all(anchor <= np.arange(n)) and (excess > 0).any() and (excess <= 0).any()


def test_an_over_read_over_a_stretch_exceeds_the_bound_from_where_it_began():
    """A 4 % over-read for 400 m after 4 km at 1 m + 2 %: inside from the start (16 m against
    1 + 2 % of 4416 m = 89 m), outside from where it began (416 m read for 400 m run)."""
    true_m = np.arange(0.0, 4401.0, 20.0)
    odo_m = true_m + 0.04 * np.clip(true_m - 4000.0, 0.0, None)
    acc = OdometerAccuracy(1.0, 0.02, 0.02)
    lo, hi = acc.displacement_bounds_m(odo_m)
    assert np.all((lo <= true_m) & (true_m <= hi))  # the first epoch's check passes
    excess, anchor = acc.anchor_excess_m(true_m, odo_m)
    assert excess[-1] == pytest.approx(416.0 - 1.0 - 0.02 * 416.0 - 400.0)
    assert true_m[anchor[-1]] == 4000.0
    assert np.all(excess[true_m <= 4000.0] <= 0)


def test_a_braked_axle_sliding_at_its_limit_stays_within_the_stated_under_reading():
    # the odometer's own model (locator.odometry.odometer): the wheel's surface runs
    # (1 + creep) times the train's distance and the distance read is the surface over the
    # wheel's ratio, at most 1 + calibration_error; a slide is creep -slide_max. So the
    # worst under-read of a train run d is d (1 - slide_max) / (1 + cal): the bound must
    # reach d from it (the first-order sum cal + slide fell 2.7 % of the reading short)
    cfg = OdometerConfig.motor_axle(radar=False)
    acc = OdometerAccuracy.from_config(cfg)
    true_m = np.array([100.0, 1000.0, 5000.0])
    read_m = true_m * (1.0 - cfg.slide_max) / (1.0 + cfg.calibration_error)
    _, hi = acc.displacement_bounds_m(read_m, read_m)
    assert np.all(hi >= true_m - 1e-9), hi - true_m
    # and a wheel spinning at its slip limit with the smallest ratio: the over-read side
    read_m = true_m * (1.0 + cfg.slip_max) / ((1.0 - cfg.calibration_error) * (1.0 - cfg.wear))
    lo, _ = acc.displacement_bounds_m(read_m, read_m)
    assert np.all(lo <= true_m + 1e-9), true_m - lo


def test_a_simulated_braked_axle_sliding_for_long_stays_within_its_bounds():
    # slide episodes under every braking: 30 m/s down to a stop at 0.5 m/s^2 (60 s, 900 m)
    dt = 0.1
    t = np.arange(0.0, 80.0, dt)
    v = np.clip(30.0 - 0.5 * t, 0.0, None)
    truth = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    cfg = replace(OdometerConfig.motor_axle(radar=False), episode_rate_hz=5.0, episode_s=60.0)
    acc = OdometerAccuracy.from_config(cfg)
    for seed in range(20):
        log = simulate_odometer(t, truth, cfg, seed=seed)
        d = np.asarray(log.dist_m, float) - log.dist_m[0]
        lo, hi = acc.displacement_bounds_m(d, np.abs(d))
        assert np.all((lo <= truth + 1e-6) & (truth <= hi + 1e-6)), (seed, (truth - hi).max())


@pytest.mark.parametrize("jitter", ["backward", "disputed"])
def test_a_sub_millimetre_jitter_hides_no_violation_of_the_directional_bounds(jitter):
    """displacement_bounds_m takes a pair whose wheels ran under 1e-6 (1 + ran) beyond its
    displacement as no reversal (directional rates): a 4 % over-read over 100 m at
    1 m + 2 % over / 5 % under is 0.92 m out across a 0.01 mm backward step (or a 0.1 um
    disputed step) in its middle, which anchor_excess_m took as a reversal (wide rate 5 %)
    and passed (m8)."""
    true_m = np.concatenate([np.arange(0.0, 51.0, 10.0), np.arange(50.0, 101.0, 10.0)])
    odo_m = 1.04 * true_m
    ahead = np.zeros(len(true_m))
    if jitter == "backward":
        odo_m[6:] -= 1e-5
    else:
        ahead[6:] = 1e-7
    acc = OdometerAccuracy(1.0, 0.02, 0.05)
    zero = np.zeros(len(true_m))
    brute = _brute_excess(acc, true_m, odo_m, ahead, zero)
    assert brute.max() > 0.9
    excess, _ = acc.anchor_excess_m(true_m, odo_m, ahead, zero)
    assert excess.max() >= brute.max() - 1e-6, (excess.max(), brute.max())


@pytest.mark.parametrize("seed", range(4))
def test_the_excess_is_never_below_the_pairwise_check_with_jitter(seed):
    """Random logs with sub-millimetre backward and disputed jitter: never below brute force
    (a missed violation). Above it is allowed: a pair across a jitter that
    displacement_bounds_m counts as a reversal (its own tolerance is relative to the pair's
    distance) may be checked at the directional rates, the stricter side."""
    rng = np.random.default_rng(100 + seed)
    n = 200
    step = rng.choice([-1.0, 0.0, 1.0, 1.0], n - 1) * rng.uniform(0.0, 20.0, n - 1)
    step = np.where(rng.random(n - 1) < 0.2, rng.normal(0.0, 1e-4, n - 1), step)
    true_m = np.concatenate([[0.0], np.cumsum(step)])
    odo_m = np.concatenate([[0.0], np.cumsum(step * (1 + rng.normal(0.0, 0.05, n - 1)))])
    ahead = np.concatenate([[0.0], np.cumsum((rng.random(n - 1) < 0.1) * 1e-5)])
    behind = np.zeros(n)
    acc = OdometerAccuracy(1.0, 0.02, 0.06)
    excess, _ = acc.anchor_excess_m(true_m, odo_m, ahead, behind)
    brute = _brute_excess(acc, true_m, odo_m, ahead, behind)
    assert np.all(excess >= brute - 1e-6), (brute - excess).max()


def test_a_non_finite_sample_is_refused_not_passed():
    """One NaN made the excess of every later sample NaN, which no ``> 0`` test flags: a 50 %
    over-read passed from there on (m8)."""
    true_m = np.arange(10.0) * 10.0
    true_m[3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        OdometerAccuracy(1.0, 0.02, 0.02).anchor_excess_m(true_m, 1.5 * np.arange(10.0) * 10.0)


def test_anchor_excess_keeps_the_directional_bound_from_a_stop_after_a_reversal():
    """Back 10 m, standing two cycles (the truth drifts back 0.8 m, within the fixed part),
    then forward 100 m: from the first standing sample the pair has run 100 m one way
    (displacement_bounds_m: no reversal, lo = 100 - 1 - 4 %), and the truth short of it by
    0.5 m is outside. The forward stretch began at the last standing sample only and left
    the earlier ones to the wide rate (6 %): the excess was missed (m9)."""
    acc = OdometerAccuracy(1.0, 0.04, 0.06)
    d = np.array([0.0, -10.0, -10.0, -10.0, 90.0])
    r = np.array([0.0, -10.0, -10.0, -10.8, 84.5])
    lo, _ = acc.displacement_bounds_m(d[4] - d[1], 100.0)
    assert lo[()] - (r[4] - r[1]) == pytest.approx(0.5)
    excess, anchor = acc.anchor_excess_m(r, d)
    assert excess[4] == pytest.approx(0.5) and anchor[4] in (1, 2)
