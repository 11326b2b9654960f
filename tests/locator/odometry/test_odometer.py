"""Odometer sensor simulation against closed-form kinematics (locator.odometry.odometer)."""

from __future__ import annotations

import numpy as np
import pytest

from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.odometer import (
    OdometerConfig,
    RadarConfig,
    RadarFault,
    decode_quadrature,
    quadrature_levels,
    simulate_odometer,
    true_distance_m,
)

DT = 0.1


def accel_cruise_brake(t):
    """0 -> 20 m/s at 0.5 m/s^2 (40 s), cruise 30 s, brake at 2/3 m/s^2 to a stop (30 s)."""
    t = np.asarray(t, float)
    x1 = 0.25 * np.minimum(t, 40.0) ** 2
    x2 = 20.0 * np.clip(t - 40.0, 0.0, 30.0)
    tb = np.clip(t - 70.0, 0.0, 30.0)
    x3 = 20.0 * tb - tb**2 / 3.0
    return x1 + x2 + x3


def speed(t):
    t = np.asarray(t, float)
    return np.where(t < 40, 0.5 * t, np.where(t < 70, 20.0, np.maximum(0.0, 20 - (t - 70) / 1.5)))


def test_quadrature_decoder_counts_edges_with_the_direction():
    # forward 3.3 periods, then back 1.1 periods, sampled 20 times per period
    phase = np.concatenate([np.linspace(0, 3.3, 67), np.linspace(3.3, 2.2, 23)[1:]])
    a, b = quadrature_levels(phase)
    count = decode_quadrature(a, b)
    # closed form: edges are at multiples of a quarter period
    assert count[66] == np.floor(4 * 3.3) - np.floor(4 * 0.0)
    assert count[-1] == np.floor(4 * 2.2)
    assert np.all(np.diff(count[:67]) >= 0) and np.all(np.diff(count[66:]) <= 0)


def test_quadrature_decoder_refuses_undersampled_channels():
    a, b = quadrature_levels(np.array([0.0, 0.6]))  # half a period between samples
    with pytest.raises(ValueError, match="four times per pulse period"):
        decode_quadrature(a, b)


def test_true_distance_integrates_the_speed():
    t = np.arange(0.0, 100.0 + DT / 2, DT)
    assert np.abs(true_distance_m(speed, t) - accel_cruise_brake(t)).max() < 1e-3


def test_ideal_odometer_reads_the_distance_within_one_edge():
    t = np.arange(0.0, 100.0 + DT / 2, DT)
    x = accel_cruise_brake(t)
    cfg = OdometerConfig.ideal()
    log = simulate_odometer(t, x, cfg)
    assert np.abs(log.dist_m - x).max() <= cfg.edge_m + 1e-9
    # speed from the pulse frequency: the mean speed over the cycle, within one edge per cycle
    v_mean = np.diff(x) / DT
    assert np.abs(log.wheel_speed_mps[1:] - v_mean).max() <= cfg.edge_m / DT + 1e-9
    assert set(np.unique(log.direction[1:-30])) <= {0, 1}


def test_reverse_motion_reads_negative_with_backward_direction():
    t = np.arange(0.0, 50.0, DT)
    x = -accel_cruise_brake(t)  # the train backs along its forward axis
    log = simulate_odometer(t, x, OdometerConfig.ideal())
    assert np.abs(log.dist_m - x).max() <= OdometerConfig.ideal().edge_m + 1e-9
    assert np.all(log.direction[5:] == -1)


def test_diameter_error_scales_the_reading():
    t = np.arange(0.0, 200.0, DT)
    x = 25.0 * t  # constant speed: no slip, no slide
    cfg = OdometerConfig(calibration_error=0.01, wear=0.0, braked=False, radar=None)
    for seed in range(4):
        log = simulate_odometer(t, x, cfg, seed=seed)
        # the wheel is ratio times the configured one: each turn covers ratio x more
        expected = x[-1] / log.diameter_ratio
        assert abs(log.dist_m[-1] - expected) <= cfg.edge_m + 1e-6
        assert abs(log.diameter_ratio - 1.0) <= 0.01


def test_motor_axle_without_radar_over_reads_in_traction_and_bounds_hold():
    t = np.arange(0.0, 100.0 + DT / 2, DT)
    x = accel_cruise_brake(t)
    cfg = OdometerConfig.motor_axle(radar=False)
    cfg = OdometerConfig(**{**cfg.__dict__, "episode_rate_hz": 0.5})  # slippery rail
    acc = OdometerAccuracy.from_config(cfg)
    over_seen = False
    for seed in range(6):
        log = simulate_odometer(t, x, cfg, seed=seed)
        lo, hi = acc.displacement_bounds_m(log.dist_m)
        assert np.all((lo <= x) & (x <= hi)), seed
        over_seen |= bool(log.slip.any())
    assert over_seen


def test_radar_detects_slip_and_keeps_the_distance():
    t = np.arange(0.0, 100.0 + DT / 2, DT)
    x = accel_cruise_brake(t)
    base = OdometerConfig.motor_axle(radar=True)
    cfg = OdometerConfig(**{**base.__dict__, "episode_rate_hz": 0.5})
    no_radar = OdometerConfig(**{**cfg.__dict__, "radar": None, "max_accel_mps2": 50.0})
    err_radar, err_wheel = [], []
    for seed in range(4):
        err_radar.append(abs(simulate_odometer(t, x, cfg, seed=seed).dist_m[-1] - x[-1]))
        err_wheel.append(abs(simulate_odometer(t, x, no_radar, seed=seed).dist_m[-1] - x[-1]))
    assert np.mean(err_radar) < 0.5 * np.mean(err_wheel)
    acc = OdometerAccuracy.from_config(cfg)
    assert acc.over_rel < 0.05 and acc.under_rel < 0.05  # radar: a few percent at most


@pytest.mark.parametrize("profile", ["slow start", "crawl and stop"])
def test_radar_bounds_hold_at_low_speed(profile):
    """Below tolerance_mps / tolerance the radar's absolute tolerance let a creep of 15 % pass
    unseen: a user trial's slow start on low adhesion (0.06 m/s2 over 18.75 m) broke
    D_DOUBTOVER in 8 of 2000 runs, by up to 0.2 m. The truth is the profile itself."""
    if profile == "slow start":
        t = np.arange(0.0, 25.0 + DT / 2, DT)
        x = 0.5 * 0.06 * t**2
    else:  # 1.5 m/s, a stop of 20 s, 3 m/s: shunting
        t = np.arange(0.0, 80.0 + DT / 2, DT)
        v = np.where(t < 30, 1.5, np.where(t < 50, 0.0, 3.0))
        x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * DT)])
    cfg = OdometerConfig.motor_axle(radar=True)
    cfg = OdometerConfig(**{**cfg.__dict__, "episode_rate_hz": 0.5})  # slippery rail
    acc = OdometerAccuracy.from_config(cfg)
    for seed in range(300):
        log = simulate_odometer(t, x, cfg, seed=seed)
        err = log.dist_m - x
        assert np.all(err <= acc.doubt_over_m(log.dist_m)), seed
        assert np.all(-err <= acc.doubt_under_m(log.dist_m)), seed


@pytest.mark.parametrize("v_mps", [0.02, 0.06, 0.1, 0.5, 2.0])
def test_a_crawl_reads_its_distance_with_a_radar(v_mps):
    """The first low-speed radar rule dropped the distance of slow cycles between two wheel
    edges (a crawl at 0.02 m/s under-read by 57 %), then over-read a 0.1 m/s crawl by 12 % by
    choosing the radar on its own reading (a review): within the bounds, and a few percent."""
    cfg = OdometerConfig()
    acc = OdometerAccuracy.from_config(cfg)
    t = 1e9 + np.arange(0.0, 120.0, cfg.cycle_s)
    x = v_mps * (t - t[0])
    for seed in range(3):
        log = simulate_odometer(t, x, cfg, seed=seed)
        assert abs(log.dist_m[-1] / x[-1] - 1.0) < 0.03, seed
        err = log.dist_m - x
        assert np.all(err <= acc.doubt_over_m(log.dist_m)) and np.all(
            -err <= acc.doubt_under_m(log.dist_m)
        ), seed


def test_config_guards_name_the_parameter():
    with pytest.raises(ValueError, match="cycle_s"):
        OdometerConfig(cycle_s=0.0)
    with pytest.raises(ValueError, match="slip_max"):
        OdometerConfig(slip_max=0.7)
    with pytest.raises(ValueError, match="tolerance"):
        RadarConfig(tolerance=0.0)
    with pytest.raises(ValueError, match="cycle_s"):
        simulate_odometer(np.arange(0, 5, 0.2), np.zeros(25), OdometerConfig())


@pytest.mark.parametrize("config", [OdometerConfig(), OdometerConfig.motor_axle()],
                         ids=["trailer-radar", "motor-radar"])  # fmt: skip
@pytest.mark.parametrize(
    "fault",
    [
        RadarFault(10.0, 90.0, "zero"),  # lost echo through cruise and braking
        RadarFault(65.0, 95.0, "frozen"),  # frozen at 20 m/s before braking
        RadarFault(20.0, 60.0, "scaled", 0.6),  # reading 40 % low
        RadarFault(20.0, 60.0, "scaled", 1.5),  # reading 50 % high
    ],
    ids=lambda f: f"{f.mode}{f.factor:g}",
)
def test_a_failed_radar_is_disputed_and_the_bounds_hold_the_truth(config, fault):
    """Over 20 seeds (a review found the first version holding on its one seed only: the
    wheel that ran on while a zero radar was believed has its own relative error, so the
    doubts must grow with the disputed distance too, not only add it)."""
    t = np.arange(0.0, 100.0 + DT / 2, DT)
    x = accel_cruise_brake(t)
    acc = OdometerAccuracy.from_config(config)
    worst_plain = 0.0
    for seed in range(20):
        log = simulate_odometer(t, x, config, seed=seed, radar_fault=fault)
        lo, hi = acc.displacement_bounds_m(log.dist_m)
        worst_plain = max(worst_plain, float(np.max(np.maximum(lo - x, x - hi))))
        # the doubts over the distance used and the disputed one, plus the disputed one
        ran = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(log.dist_m)))])
        ran = ran + log.extra_ahead_m + log.extra_behind_m
        lo, hi = acc.displacement_bounds_m(log.dist_m, ran)
        assert np.all(lo - log.extra_behind_m <= x + 1e-9), seed
        assert np.all(x <= hi + log.extra_ahead_m + 1e-9), seed
        assert np.all(np.diff(log.extra_ahead_m) >= 0) and np.all(np.diff(log.extra_behind_m) >= 0)
    # the failed radar is believed in the cycles it disagrees with the wheel: the stated
    # bounds alone miss the truth by far (tens to hundreds of metres)
    assert worst_plain > 20.0


def test_a_healthy_radar_disputes_little():
    t = np.arange(0.0, 100.0 + DT / 2, DT)
    x = accel_cruise_brake(t)
    # slow cycles and genuine slip/slide only: under 1 % of the 1.3 km on a braked trailer
    # axle; a motor axle both slips and slides, and a cycle where wheel and radar disagree
    # cannot tell a creeping wheel from a failed radar, nor traction from braking: its wheel
    # side spans both creeps (since 2026-12-07), under 2 %
    # (m9: every slow cycle disputes the whole creep, a failed radar agrees within the slow
    # tolerance: 0.35 -> 2.5 % median over 20 seeds on the trailer axle, 1.8 -> 4.9 % motor)
    for config, share in ((OdometerConfig(), 0.03), (OdometerConfig.motor_axle(), 0.13)):
        log = simulate_odometer(t, x, config, seed=5)
        assert log.extra_ahead_m[-1] + log.extra_behind_m[-1] < share * x[-1]
    no_radar = simulate_odometer(t, x, OdometerConfig.motor_axle(radar=False), seed=5)
    assert not no_radar.extra_ahead_m.any() and not no_radar.extra_behind_m.any()


def test_radar_fault_is_checked():
    with pytest.raises(ValueError, match="mode must be zero, frozen or scaled"):
        RadarFault(0.0, mode="stuck")
    with pytest.raises(ValueError, match="end_s > start_s"):
        RadarFault(5.0, 5.0)
    t = np.arange(0.0, 10.0, DT)
    with pytest.raises(ValueError, match="radar_fault needs an odometer with a radar"):
        simulate_odometer(t, 10.0 * t, OdometerConfig.motor_axle(radar=False),
                          radar_fault=RadarFault(1.0))  # fmt: skip


def _fronts_from_zero(log, acc):
    """The safe fronts from a reference at chainage 0 at the first cycle, with the disputes."""
    from locator.odometry.confidence import BalisePassage, safe_fronts

    ref = [BalisePassage(0, 0.0, 0.0)]
    return safe_fronts(log.dist_m, ref, acc, extra_ahead_m=log.extra_ahead_m,
                       extra_behind_m=log.extra_behind_m)  # fmt: skip


def _held_creep(monkeypatch, creep: float, t_on=None):
    """Replace the simulator's low-adhesion episodes by one creep held at ``creep`` (a ratio:
    negative for a slide) where ``t_on`` (bool per cycle; default always), as a fault injection:
    the simulator's own episodes are 4.5-15 % deep, always seen by the radar."""
    import locator.odometry.odometer as od

    real = od._episodes
    calls = {"n": 0}

    def held(active, dt, rate_hz, mean_s, rng):
        real(active, dt, rate_hz, mean_s, rng)  # the same random stream
        calls["n"] += 1
        traction = calls["n"] % 2 == 1  # each run draws traction, then braking episodes
        if traction != (creep > 0):
            return np.zeros(len(active))
        amp = abs(creep) / 0.15  # the configurations' slip_max and slide_max
        return np.full(len(active), amp) if t_on is None else np.where(t_on, amp, 0.0)

    monkeypatch.setattr(od, "_episodes", held)


@pytest.mark.parametrize("creep", [-0.037, 0.037, -0.042])
def test_a_creep_held_just_under_the_per_cycle_test_is_caught_and_bounded(monkeypatch, creep):
    """A review: a slide of 3.7 % held over 2 km at 10.3 m/s (just above the speed the wheel is
    trusted at) stayed under the per-cycle test (2 % + 0.2 m/s) and left D_DOUBTUNDER by up to
    4.6 m (seed 6 of these). The truth is the constant speed."""

    _held_creep(monkeypatch, creep)
    cfg = OdometerConfig(**{**OdometerConfig.motor_axle().__dict__, "wear": 0.0})
    acc = OdometerAccuracy.from_config(cfg)
    t = np.arange(0.0, 2000.0 / 10.3, DT)
    x = 10.3 * t
    for seed in range(8):
        log = simulate_odometer(t, x, cfg, seed=seed)
        assert log.slip[20:].mean() > 0.9, seed  # caught on the seconds' means
        sf = _fronts_from_zero(log, acc)
        assert np.all((sf.min_safe_front_m <= x + 1e-9) & (x <= sf.max_safe_front_m + 1e-9)), seed
    assert acc.over_rel < 0.05 and acc.under_rel < 0.05  # still within SUBSET-041's 5 %


@pytest.mark.parametrize("wheel_mps", [0.04, 0.14])
def test_a_wheel_turning_under_a_standing_train_is_disputed_to_standstill(wheel_mps):
    """A review: a wheel spinning at 0.14 m/s for 60 s under a standing train (radar at 0) was
    counted as motion, and the min safe front ran 7 m ahead of the train. The 'truth' passed
    to the simulator is the wheel's surface; the radar reads 0 (a standing train)."""

    cfg = OdometerConfig.motor_axle(radar=True)
    acc = OdometerAccuracy.from_config(cfg)
    t = np.arange(0.0, 60.0, cfg.cycle_s)
    log = simulate_odometer(t, wheel_mps * t, cfg, seed=1,
                            radar_fault=RadarFault(0.0, 1e9, "zero"))  # fmt: skip
    sf = _fronts_from_zero(log, acc)
    assert np.all(sf.min_safe_front_m <= 1e-9)  # the train stands at 0
    assert sf.max_safe_front_m[-1] >= log.dist_m[-1]  # and may have crawled what the wheel ran


@pytest.mark.parametrize("lock_s", [20.0, 30.0])
def test_a_wheel_locked_beyond_the_configured_slide_keeps_the_truth_inside(monkeypatch, lock_s):
    """Without a radar a wheel locked by a failed slide protection (creep -99 %, beyond the
    configured 15 %) while the train brakes at 1 m/s^2 from 30 m/s: the clamp marked the
    cycles but nothing reached the bounds, and the train ran 74 m beyond its max safe front
    (a review; 20 s lock). The truth is the braking profile."""
    from locator.odometry.confidence import BalisePassage, safe_fronts

    cfg = OdometerConfig.motor_axle(radar=False)
    acc = OdometerAccuracy.from_config(cfg)
    t = np.arange(0.0, 60.0, cfg.cycle_s)
    v = np.where(t < 10.0, 30.0, np.maximum(30.0 - (t - 10.0), 0.0))
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * cfg.cycle_s)])
    _held_creep(monkeypatch, -0.99, t_on=(t >= 10.0) & (t < 10.0 + lock_s))
    log = simulate_odometer(t, x, cfg, seed=0)
    refs = [BalisePassage(0, 0.0, 0.0), BalisePassage(100, float(x[100]), 1.0, linked=False)]
    plain = safe_fronts(log.dist_m, refs, acc)  # a reference as the braking starts
    sf = safe_fronts(log.dist_m, refs, acc, extra_ahead_m=log.extra_ahead_m,
                     extra_behind_m=log.extra_behind_m)  # fmt: skip
    assert np.any(x > plain.max_safe_front_m)  # the hazard without the dispute
    assert np.all((sf.min_safe_front_m <= x + 1e-9) & (x <= sf.max_safe_front_m + 1e-9))


@pytest.mark.parametrize(("wheel_mps", "roll_mps", "dur_s"), [(0.14, 0.10, 60.0), (2.0, 0.5, 20.0)])
@pytest.mark.parametrize("orientation", [1, -1])
def test_a_train_rolling_back_under_a_wheel_spinning_forward_stays_inside(
    wheel_mps, roll_mps, dur_s, orientation
):
    """A review: the radar gives no direction, and the standing rule disputed a wheel spinning
    forward only down to standstill while the train rolled back (5-17 m outside). The 'truth'
    passed to the simulator is the wheel's surface; the radar is scaled to the roll's speed."""
    from locator.odometry.confidence import BalisePassage, safe_fronts

    cfg = OdometerConfig.motor_axle(radar=True)
    acc = OdometerAccuracy.from_config(cfg)
    t = np.arange(0.0, dur_s, cfg.cycle_s)
    fault = RadarFault(0.0, 1e9, "scaled", roll_mps / wheel_mps)
    log = simulate_odometer(t, wheel_mps * t, cfg, seed=1, radar_fault=fault)
    ref = [BalisePassage(0, 1000.0, 0.0)]
    sf = safe_fronts(log.dist_m, ref, acc, orientation=orientation, extra_ahead_m=log.extra_ahead_m,
                     extra_behind_m=log.extra_behind_m)  # fmt: skip
    truth = 1000.0 - orientation * roll_mps * t
    assert np.all((sf.front_lo_m <= truth + 1e-9) & (truth <= sf.front_hi_m + 1e-9))


def test_a_healthy_odometer_without_radar_at_20_hz_is_not_clamped_by_its_quantisation():
    """A review: at a 20 Hz cycle one edge (0.145 m/s) exceeded the clamp's step (0.075 m/s),
    39 % of the cycles were marked and the truth left the bounds by up to 1.45 m."""
    cfg = OdometerConfig.ideal(0.05)
    t = np.arange(0.0, 100.0 + 0.025, 0.05)
    x = accel_cruise_brake(t)
    log = simulate_odometer(t, x, cfg, seed=0)
    assert log.slip.mean() < 0.05
    sf = _fronts_from_zero(log, OdometerAccuracy.from_config(cfg))
    assert np.all((sf.min_safe_front_m <= x + 1e-9) & (x <= sf.max_safe_front_m + 1e-9))


def test_a_radar_without_absolute_tolerance_gives_a_budget_not_a_division_by_zero():
    cfg = OdometerConfig(radar=RadarConfig(tolerance_mps=0.0, tolerance_mean_mps=0.0))
    acc = OdometerAccuracy.from_config(cfg)
    # the creep let pass: tolerance 2 %, scale error 0.5 %, noise 0.5 %; exact under-read
    assert acc.under_rel == pytest.approx((1.0 + 0.002) / (1.0 - (0.02 + 0.005 + 0.005)) - 1.0)


@pytest.mark.parametrize("config", [OdometerConfig(), OdometerConfig.motor_axle()],
                         ids=["trailer-radar", "motor-radar"])  # fmt: skip
@pytest.mark.parametrize("fault", [RadarFault(65.0, 100.0, "zero"),
                                   RadarFault(65.0, 100.0, "scaled", 0.5),
                                   # a failed radar reading 85 % agrees with a wheel sliding
                                   # 15 %: no cycle disagrees, both under-read (m9: 30.2 m out)
                                   RadarFault(65.0, 100.0, "scaled", 0.85)],
                         ids=["zero", "half", "agrees-with-slide"])  # fmt: skip
def test_a_failed_radar_leaves_a_sliding_wheel_bounded_from_every_anchor(config, fault):
    """The radar fails before the braking, and the braked wheel slides (every braking cycle
    in an episode): with the radar's speed not to be trusted the wheel's creep is unchecked,
    so a disagreeing cycle's truth may lie beyond the wheel by its whole slide. The bounds
    must hold between any two cycles (the run re-anchors anywhere), checked pair by pair."""
    from dataclasses import replace

    t = np.arange(0.0, 100.0 + DT / 2, DT)
    x = accel_cruise_brake(t)
    cfg = replace(config, episode_rate_hz=5.0, episode_s=30.0)
    acc = OdometerAccuracy.from_config(cfg)
    worst = -np.inf
    for seed in range(10):
        log = simulate_odometer(t, x, cfg, seed=seed, radar_fault=fault)
        d = np.asarray(log.dist_m, float)
        a, b = np.asarray(log.extra_ahead_m, float), np.asarray(log.extra_behind_m, float)
        # every pair i <= j, at 1 s steps (brute force, independent of anchor_excess_m)
        k = np.arange(0, t.size, 10)
        ran = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(d)))]) + a + b
        for i in k:
            j = k[k >= i]
            lo, hi = acc.displacement_bounds_m(d[j] - d[i], ran[j] - ran[i])
            lo, hi = lo - (b[j] - b[i]), hi + (a[j] - a[i])
            moved = x[j] - x[i]
            worst = max(worst, float(np.max(np.maximum(lo - moved, moved - hi))))
    assert worst <= 1e-9, worst


def test_a_failed_radar_agreeing_within_the_slow_tolerance_leaves_the_truth_bounded():
    """Below ``tolerance_mps / tolerance`` (10 m/s) the radar's speed is used and a cycle
    "agrees" within 0.2 m/s: a radar failed to 88 % and a wheel sliding under a gentle
    braking agree there (12 % apart is 0.24 m/s at 2 m/s) and both read short, so the
    wheel's side as read does not reach the truth (m9: 2.8 m outside on a 731 m run, from
    anchors 6 s apart). Nothing tells such a cycle from a failed radar: its wheel side spans
    the whole creep like a disagreeing one."""
    t = np.arange(0.0, 300.0 + DT / 2, DT)
    ta, t0, v0 = 19.0, 20.0, 9.5  # 0 -> 9.5 m/s at 0.5 m/s^2, 20 s, then 0.1 m/s^2 to a stop
    braking = np.maximum(0.0, v0 - 0.1 * (t - ta - t0))
    v = np.where(t < ta, 0.5 * t, np.where(t < ta + t0, v0, braking))
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * DT)])
    cfg = OdometerConfig()
    acc = OdometerAccuracy.from_config(cfg)
    fault = RadarFault(0.0, 1e9, "scaled", 0.88)
    logs = [simulate_odometer(t, x, cfg, seed=s, radar_fault=fault) for s in range(4)]
    worst = max(
        float(acc.anchor_excess_m(x, log.dist_m, log.extra_ahead_m, log.extra_behind_m)[0].max())
        for log in logs
    )
    assert worst <= 0.0, worst
