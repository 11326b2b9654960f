"""Capture of virtual balises against closed-form motion (locator.balises.capture).

The fixes are a constant-speed truth plus known offsets, so the expected capture decision,
passage time, delay and errors follow from arithmetic, not from the code under test.
"""

from __future__ import annotations

import numpy as np
import pytest

from locator.balises.balisefile import BaliseList
from locator.balises.capture import CaptureConfig, capture_balises, score_captures
from locator.odometry.confidence import OdometerAccuracy


def balises(chainages):
    c = np.asarray(chainages, float)
    n = len(c)
    return BaliseList(
        tuple(f"B{k}" for k in range(n)),
        c,
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        tuple("T" for _ in range(n)),
        np.ones(n, bool),
        np.ones(n),
    )


def fixes(rate_hz, speed_mps, duration_s, start_m=0.0, offset_m=0.0, orientation=1):
    t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    truth = start_m + orientation * speed_mps * t
    est = truth + offset_m
    return t, truth, est, est - 10.0, est + 10.0


def test_exact_fixes_capture_with_interpolated_time_and_fix_rate_delay():
    t, truth, est, lo, hi = fixes(1.0, 22.0, 20.0)
    bl = balises([105.0, 230.0])
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(25.0), orientation=1)
    assert cap["captured"].all() and (cap["zone"] == "capture").all()
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=25.0)
    np.testing.assert_allclose(sc["t_true_s"], [105 / 22, 230 / 22])
    np.testing.assert_allclose(sc["timing_error_s"], 0.0, atol=1e-12)  # linear motion
    # emitted at the first fix past the balise: 5 s and 11 s
    np.testing.assert_allclose(sc["t_emit_s"], [5.0, 11.0])
    np.testing.assert_allclose(sc["delay_s"], [5 - 105 / 22, 11 - 230 / 22])
    assert not sc["false"].any() and not sc["missed"].any()


def test_capture_rate_rises_with_the_radius_as_the_fix_spacing_says():
    # fixes every 22 m; balises at every 0.5 m phase: a radius r catches the balises whose
    # nearer bracketing fix is within r, i.e. a share min(1, 2 r / 22)
    t, _truth, est, lo, hi = fixes(1.0, 22.0, 60.0)
    bl = balises(50.0 + np.arange(0.0, 22.0, 0.25))
    for r, share in [(2.0, 4.0 / 22.0), (5.5, 11.0 / 22.0), (11.0, 1.0), (25.0, 1.0)]:
        cap = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(r), orientation=1)
        assert cap["captured"].mean() == pytest.approx(share, abs=0.025), r


def test_arm_zone_recovers_jumped_balises():
    t, _truth, est, lo, hi = fixes(1.0, 32.5, 10.0)  # 117 km/h at 1 Hz
    bl = balises([16.25])  # halfway between fixes 0 and 32.5
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(5.0), orientation=1)
    assert not cap["captured"].any()
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(5.0, 25.0), orientation=1)
    assert cap["zone"].tolist() == ["arm"]
    assert cap["t_pass_s"].iloc[0] == pytest.approx(0.5)


def test_offset_fixes_give_the_expected_timing_and_false_captures():
    # the estimate runs 3 m ahead: the reported time is early by 3 m / v
    t, truth, est, lo, hi = fixes(10.0, 22.0, 10.0, offset_m=3.0)
    bl = balises([50.0, 100.0])
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(2.0), orientation=1)
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=2.0)
    np.testing.assert_allclose(sc["timing_error_s"], -3.0 / 22.0, atol=1e-9)
    np.testing.assert_allclose(sc["position_error_m"], -3.0, atol=1e-9)
    assert sc["false"].all()  # 3 m off with a 2 m capture zone
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=5.0)
    assert not sc["false"].any()


def test_a_train_stopping_on_a_balise_passes_it_on_arrival():
    """10 m/s to the balise at 100 m, 60 s standing on it, then on: the true passage is the
    arrival at 10 s (np.interp over the repeated positions took the departure at 70 s, and a
    user trial's telegram emitted 62 s late was scored 1.5 s)."""
    t = np.arange(0.0, 90.0 + 1e-9, 1.0)
    truth = np.where(t < 10, 10.0 * t, np.where(t < 70, 100.0, 100.0 + 10.0 * (t - 70)))
    cap = capture_balises(t, truth, truth - 5, truth + 5, balises([50.0, 100.0, 150.0]),
                          CaptureConfig(12.0), orientation=1)  # fmt: skip
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=12.0)
    np.testing.assert_allclose(sc["t_true_s"], [5.0, 10.0, 75.0])


def test_reverse_direction_and_window_zone():
    t, _truth, est, lo, hi = fixes(1.0, 10.0, 30.0, start_m=500.0, orientation=-1)
    bl = balises([255.0, 395.0])
    cfg = CaptureConfig.window(before_m=2.0, after_m=6.0)
    cap = capture_balises(t, est, lo, hi, bl, cfg, orientation=-1)
    # 395: fixes at 400 (5 m before: outside) and 390 (5 m after: inside)
    # 255: fixes at 260 (5 m before) and 250 (5 m after): captured by the fix after
    assert cap["captured"].tolist() == [True, True]
    np.testing.assert_allclose(cap["t_pass_s"], [24.5, 10.5])


def test_long_fused_intervals_do_not_capture_and_a_balise_not_reached_is_false():
    t, _truth, est, lo, hi = fixes(1.0, 20.0, 10.0)
    wide_lo, wide_hi = lo - 200.0, hi + 200.0
    bl = balises([55.0])
    cap = capture_balises(t, est, wide_lo, wide_hi, bl, CaptureConfig(25.0), orientation=1)
    assert not cap["captured"].any()
    # the estimate runs 40 m ahead of a train that stops at 180 m: balise at 200 m captured
    t2 = np.arange(0.0, 20.0)
    truth2 = np.minimum(20.0 * t2, 180.0)
    est2 = truth2 + 40.0
    cap = capture_balises(t2, est2, est2 - 45, est2 + 45, balises([200.0]),
                          CaptureConfig(25.0), orientation=1)  # fmt: skip
    sc = score_captures(cap, t2, truth2, orientation=1, false_tolerance_m=25.0)
    assert sc["captured"].all() and sc["false"].all() and not sc["passed"].any()


def test_predicted_emission_cuts_the_fix_rate_delay():
    t, truth, est, lo, hi = fixes(1.0, 32.5, 10.0)
    bl = balises([40.0])  # fixes at 32.5 (7.5 m before) and 65
    speed = np.full(len(t), 32.5)
    cfg = CaptureConfig(capture_radius_m=10.0, emit="predicted")
    cap = capture_balises(t, est, lo, hi, bl, cfg, orientation=1, speed_mps=speed)
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=10.0)
    assert sc["delay_s"].iloc[0] == pytest.approx(0.0, abs=1e-9)
    at_fix = capture_balises(t, est, lo, hi, bl, CaptureConfig(10.0), orientation=1)
    sc2 = score_captures(at_fix, t, truth, orientation=1, false_tolerance_m=10.0)
    assert sc2["delay_s"].iloc[0] == pytest.approx(2.0 - 40.0 / 32.5)


def test_predicted_emission_is_causal_and_sends_for_a_train_stopping_short():
    """At the fix 10 m short at 20 m/s the arrival is predicted 0.5 s later, before the next fix:
    the telegram goes out then, whatever follows. Here the train brakes to a stop 3 m short and
    never reaches the balise; the rule used to be applied only to balises a later fix was seen
    to cross (hindsight), so this emission never showed."""
    t = np.arange(0.0, 20.0 + 1e-9, 1.0)
    truth = np.where(t <= 9, 10.0 + 20.0 * t, 197.0)
    speed = np.where(t <= 9, 20.0, 0.0)
    bl = balises([200.0])
    cfg = CaptureConfig(capture_radius_m=12.0, emit="predicted")
    cap = capture_balises(t, truth, truth - 5, truth + 5, bl, cfg, orientation=1,
                          speed_mps=speed)  # fmt: skip
    assert cap["captured"].iloc[0] and cap["t_emit_s"].iloc[0] == pytest.approx(9.5)
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=12.0)
    assert not sc["passed"].iloc[0] and np.isnan(sc["t_true_s"].iloc[0])  # never reached
    # emitted at the crossing fix, the at_fix rule never sends it
    assert not capture_balises(t, truth, truth - 5, truth + 5, bl, CaptureConfig(12.0),
                               orientation=1)["captured"].any()  # fmt: skip


def test_guards():
    with pytest.raises(ValueError, match="capture_radius_m"):
        CaptureConfig(capture_radius_m=0.0)
    with pytest.raises(ValueError, match="window_after_m"):
        CaptureConfig(window_before_m=3.0)
    with pytest.raises(ValueError, match="speed_mps"):
        capture_balises([0, 1], [0, 1], [0, 1], [0, 1], balises([0.5]),
                        CaptureConfig(emit="predicted"), orientation=1)  # fmt: skip


def test_expectation_window_on_the_fused_interval():
    # 117 km/h at 1 Hz, intervals +-10 m: the crossing fix at 65 m is 25 m past a balise at
    # 40 m, so its min safe front (55 m) has passed the balise's last position (41 m)
    t, _truth, est, lo, hi = fixes(1.0, 32.5, 10.0)
    bl = balises([40.0, 70.0])  # 70: crossing fix at 97.5, min safe 87.5 > 71: outside too
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig(capture_radius_m=10.0),
                          orientation=1)  # fmt: skip
    assert cap["captured"].tolist() == [True, True] and not cap["in_window"].any()
    strict = CaptureConfig(capture_radius_m=10.0, require_window=True)
    assert not capture_balises(t, est, lo, hi, bl, strict, orientation=1)["captured"].any()
    # intervals +-30 m: inside the window, accepted
    ok = capture_balises(t, est, est - 30.0, est + 30.0, bl, strict, orientation=1)
    assert ok["captured"].all() and ok["in_window"].all()


def test_no_capture_across_a_gap_of_voided_fixes():
    # fixes voided (interval too long) from 3 s to 8 s while the train stops at 60 m for 4 s:
    # interpolating across the gap would time the passage of a balise at 50 m wrongly
    t = np.arange(0.0, 15.0)
    truth = np.array([0, 20, 40, 55, 60, 60, 60, 60, 65, 80, 100, 120, 140, 160, 180.0])
    lo, hi = truth - 10.0, truth + 10.0
    hi[3:8] += 300.0
    bl = balises([50.0, 110.0])
    cap = capture_balises(t, truth, lo, hi, bl, CaptureConfig(25.0), orientation=1)
    assert cap["captured"].tolist() == [False, True]
    wide = CaptureConfig(25.0, max_gap_s=10.0)
    cap = capture_balises(t, truth, lo, hi, bl, wide, orientation=1)
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=25.0)
    # across the gap the interpolated time (2 + 10/25 * 6 = 4.4 s) is 1.7 s after the true 2.67
    assert sc["timing_error_s"].iloc[0] == pytest.approx(4.4 - (2 + 10 / 15))


def test_telegram_accuracy_states_the_interval_reach_and_gates_at_q_locacc():
    # intervals reaching 10 m either side of the estimate, balise surveyed to 1 m, and what
    # a train at 1.5 m/s^2 may leave the linear interpolation by over the 1 s between two
    # fixes (1.5 / 8 = 0.19 m): Q_LOCACC 12
    t, _truth, est, lo, hi = fixes(1.0, 20.0, 10.0)
    bl = balises([55.0])
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig(25.0), orientation=1)
    assert cap["q_locacc_m"].tolist() == [12.0]
    # a lopsided interval: the longer side counts
    cap = capture_balises(t, est, est - 4.0, est + 30.0, bl, CaptureConfig(25.0), orientation=1)
    assert cap["q_locacc_m"].tolist() == [32.0]
    # 61.5 + 0.19 + 1 m rounds up to 63 (the largest Q_LOCACC): captured; 62.5 -> 64: not
    ok = capture_balises(t, est, est - 61.5, est + 61.5, bl, CaptureConfig(25.0), orientation=1)
    assert ok["captured"].all() and ok["q_locacc_m"].iloc[0] == 63.0
    no = capture_balises(t, est, est - 62.5, est + 62.5, bl, CaptureConfig(25.0), orientation=1)
    assert not no["captured"].any()
    with pytest.raises(ValueError, match="Q_LOCACC"):
        CaptureConfig(25.0, max_locacc_m=64.0)


def test_hazardous_only_when_the_truth_leaves_the_stated_accuracy():
    # the estimate runs 30 m ahead: 30 m off is false with a 25 m zone; with an interval
    # reaching 40 m the telegram's accuracy (41 m) still holds the train; with 20 m it does not
    t, truth, est, _lo, _hi = fixes(1.0, 20.0, 10.0, offset_m=30.0)
    bl = balises([95.0])
    for reach_m, hazardous in ((40.0, False), (20.0, True)):
        cap = capture_balises(t, est, est - reach_m, est + reach_m, bl, CaptureConfig(25.0),
                              orientation=1)  # fmt: skip
        sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=25.0)
        np.testing.assert_allclose(sc["position_error_m"], -30.0, atol=1e-9)
        assert sc["false"].tolist() == [True]
        assert sc["hazardous"].tolist() == [hazardous]


def test_a_recording_ending_just_short_of_the_balise_is_judged_by_position():
    # the truth stops being recorded 2 m before the balise; the estimate, 2.5 m ahead, has
    # crossed it: the train was 2.5 m from the balise at the reported time, not "never there"
    t, truth, est, lo, hi = fixes(1.0, 20.0, 5.0, offset_m=2.5)  # truth ends at 100 m
    bl = balises([102.0])
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig(12.0), orientation=1)
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=12.0)
    assert sc["captured"].all() and not sc["passed"].any()
    np.testing.assert_allclose(sc["position_error_m"], -2.5, atol=1e-9)
    assert not sc["false"].any() and not sc["hazardous"].any()


def test_a_correction_jump_is_not_motion_the_odometer_times_the_passage():
    # 20 m/s; the estimate lags 15 m (carried from a wrong start) until a satellite fix at
    # t = 5 s corrects it; a balise at 95 m is crossed by the jump between the fixes at 4 s
    # (estimate 65 m) and 5 s (100 m): the train truly passed it at 4.75 s
    t, truth, est, _lo, _hi = fixes(1.0, 20.0, 10.0)
    est = np.where(t < 5.0, truth - 15.0, truth)
    bl = balises([95.0])
    plain = capture_balises(t, est, est - 20, est + 20, bl, CaptureConfig(25.0), orientation=1)
    # interpolating across the jump: 4 + 30/35 s, 0.11 s late
    assert plain["t_pass_s"].iloc[0] == pytest.approx(4.0 + 30.0 / 35.0)
    odo = truth - truth[0]  # an exact odometer
    cap = capture_balises(t, est, est - 20, est + 20, bl, CaptureConfig(25.0), orientation=1,
                          odo_m=odo)  # fmt: skip
    assert cap["t_pass_s"].iloc[0] == pytest.approx(95.0 / 20.0)
    # reverse direction: the same along decreasing chainage
    t2, truth2, est2, _lo, _hi = fixes(1.0, 20.0, 10.0, start_m=200.0, orientation=-1)
    est2 = np.where(t2 < 5.0, truth2 + 15.0, truth2)
    cap2 = capture_balises(t2, est2, est2 - 20, est2 + 20, balises([105.0]), CaptureConfig(25.0),
                           orientation=-1, odo_m=truth2 - truth2[0])  # fmt: skip
    assert cap2["t_pass_s"].iloc[0] == pytest.approx(95.0 / 20.0)


def test_fixes_not_yet_located_by_the_satellites_do_not_capture():
    t, _truth, est, lo, hi = fixes(1.0, 20.0, 10.0)
    bl = balises([50.0, 150.0])
    located = t >= 4.0  # the first satellite claim at 4 s (80 m)
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig(25.0), orientation=1, located=located)
    assert cap["captured"].tolist() == [False, True]
    with pytest.raises(ValueError, match="located"):
        capture_balises(t, est, lo, hi, bl, CaptureConfig(25.0), orientation=1,
                        located=located[:3])  # fmt: skip


def test_first_located_fix_captures_the_balise_passed_in_its_last_step():
    # 20 m/s at 1 Hz; the estimate runs 30 m ahead (an unverified start position) until the
    # first satellite claim at 4 s (truth 80 m) corrects it. A balise at 75 m was passed at
    # 3.75 s, during the step that ended at the first located fix: no pair of located fixes
    # brackets it, but the located fix carried back 20 m along the odometer (to 60 m) does.
    t, truth, est, _lo, _hi = fixes(1.0, 20.0, 10.0)
    est = np.where(t < 4.0, truth + 30.0, truth)
    located = t >= 4.0
    odo = truth - truth[0]  # an exact odometer
    acc = OdometerAccuracy(1.0, 0.035, 0.032)
    bl = balises([55.0, 75.0, 150.0])
    kw = dict(orientation=1, odo_m=odo, located=located)
    plain = capture_balises(t, est, est - 10.0, est + 10.0, bl, CaptureConfig(25.0), **kw)
    assert plain["captured"].tolist() == [False, False, True]
    cap = capture_balises(t, est, est - 10.0, est + 10.0, bl, CaptureConfig(25.0), **kw,
                          odo_accuracy=acc)  # fmt: skip
    # 55 m was passed two steps before the first located fix (25 m back > one 20 m step)
    assert cap["captured"].tolist() == [False, True, True]
    assert cap["after_void"].tolist() == [False, True, False]
    assert cap["t_pass_s"].iloc[1] == pytest.approx(3.75)
    assert cap["t_emit_s"].iloc[1] == pytest.approx(4.0)  # emitted at the located fix
    # stated accuracy: reach 10 m + the odometer's doubt over the 5 m carried back
    # (1 + 3.5 % x 5 = 1.175 m) + the balise's 1 m, rounded up
    assert cap["q_locacc_m"].iloc[1] == 13.0
    sc = score_captures(cap, t, truth, orientation=1, false_tolerance_m=25.0)
    assert sc["position_error_m"].iloc[1] == pytest.approx(0.0, abs=1e-9)
    assert not sc["false"].any() and not sc["hazardous"].any()


def test_tunnel_exit_captures_the_balise_passed_in_the_last_step_reverse_too():
    # intervals too long to state from 2 s to 6 s (a tunnel), statable again from 7 s; a
    # balise at 130 m (truth 120 m at 6 s, 140 m at 7 s) passed at 6.5 s. The pair rule's
    # fixes (1 s and 7 s) are 6 s apart: no capture; the fix at 7 s carried back 20 m is.
    for o, start in ((1, 0.0), (-1, 300.0)):
        t, truth, est, lo, hi = fixes(1.0, 20.0, 12.0, start_m=start, orientation=o)
        hi = hi.copy()
        hi[2:7] += 200.0
        b = start + o * 130.0
        odo = truth - truth[0]
        bl = balises([b])
        cfg = CaptureConfig(12.0)
        assert not capture_balises(t, est, lo, hi, bl, cfg, orientation=o,
                                   odo_m=odo)["captured"].any()  # fmt: skip
        cap = capture_balises(t, est, lo, hi, bl, cfg, orientation=o, odo_m=odo,
                              odo_accuracy=OdometerAccuracy.subset041())  # fmt: skip
        assert cap["captured"].all() and cap["after_void"].all()
        assert cap["t_pass_s"].iloc[0] == pytest.approx(6.5)
        # reach 10 m + (5 m + 5 % of 10 m) + 1 m
        assert cap["q_locacc_m"].iloc[0] == 17.0


def test_after_void_capture_keeps_the_accuracy_gate_and_the_zone():
    # the same tunnel exit with the located fix's interval reaching 57 m: 57 + 5.5 + 1 > 63,
    # the telegram could not state it; and a 5 m zone with the carried-back step (-10, +10 m)
    # straddling the balise: captured only in the capture zone of either end
    t, truth, est, lo, hi = fixes(1.0, 20.0, 12.0)
    hi = hi.copy()
    hi[2:7] += 200.0
    odo = truth - truth[0]
    acc = OdometerAccuracy.subset041()
    bl = balises([130.0])
    wide_lo, wide_hi = lo.copy(), hi.copy()
    wide_lo[7], wide_hi[7] = est[7] - 57.0, est[7] + 57.0
    cap = capture_balises(t, est, wide_lo, wide_hi, bl, CaptureConfig(25.0), orientation=1,
                          odo_m=odo, odo_accuracy=acc)  # fmt: skip
    assert not cap["captured"].any()
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig(5.0), orientation=1, odo_m=odo,
                          odo_accuracy=acc)  # fmt: skip
    assert not cap["captured"].any()  # 10 m either side of the step ends: outside 5 m
    cap = capture_balises(t, est, lo, hi, balises([136.0]), CaptureConfig(5.0), orientation=1,
                          odo_m=odo, odo_accuracy=acc)  # fmt: skip
    assert cap["captured"].all()  # 4 m short of the located fix: inside 5 m


def test_an_odometer_running_back_is_refused():
    """A reversing run's odometer, read one way by the passage timing, sent telegrams 555 m
    off (a trial): refused, naming the fix where it turns."""
    t, _, est, lo, hi = fixes(1.0, 10.0, 20.0)
    odo = np.concatenate([10.0 * t[:11], 10.0 * (20.0 - t[11:])])
    with pytest.raises(ValueError, match=r"odo_m runs back at fix 11.*each leg"):
        capture_balises(t, est, lo, hi, balises([55.0]), CaptureConfig.gaderos(25.0),
                        orientation=1, odo_m=odo)  # fmt: skip
    cap = capture_balises(t, est, lo, hi, balises([55.0]), CaptureConfig.gaderos(25.0),
                          orientation=1, odo_m=10.0 * t)  # fmt: skip
    assert cap["captured"].all()


def test_a_passage_the_odometer_puts_long_before_the_crossing_is_a_late_report():
    """A user trial: the radar read 0 and the estimate lagged; a satellite claim 70 s later
    moved it past the balise, and the telegram, 72 s late, was counted as a capture. At 20 m/s
    the odometer stalls from 2 s; the balise at 60 m is truly passed at 3 s; the estimate
    crosses it only with the correction at 41 s, and the odometer puts the passage at 2 s."""
    t, truth, _est, _lo, _hi = fixes(1.0, 20.0, 45.0)
    odo = np.minimum(truth, 40.0)  # stalled at 40 m from t = 2 s
    est = np.where(t < 41.0, odo, truth)
    bl = balises([60.0])
    cap = capture_balises(t, est, est - 20, est + 20, bl, CaptureConfig(25.0), orientation=1,
                          odo_m=odo)  # fmt: skip
    assert not cap["captured"].iloc[0]
    # the same correction 1 s after the stall is a passage between the fixes: captured
    est2 = np.where(t < 3.0, odo, truth)
    cap2 = capture_balises(t, est2, est2 - 20, est2 + 20, bl, CaptureConfig(25.0),
                           orientation=1, odo_m=odo)  # fmt: skip
    assert cap2["captured"].iloc[0]


@pytest.mark.parametrize("emit", ["at_fix", "predicted"])
def test_the_stated_accuracy_holds_the_odometers_error_over_the_carried_distance(emit):
    """A review: 1 Hz fixes at 117 km/h whose fused intervals all hold the truth (at their
    edge, reach 2.85 m), an odometer over-reading by 3.5 % (inside its bound), and telegrams
    stating q = 3 m while the truth at the reported time was 3.9 m (pair rule) or 3.7 m
    (predicted) from the balise: hazardous with every input inside its bound."""
    v, over, reach = 32.5, 0.035, 2.85
    acc = OdometerAccuracy(abs_error_m=1.0, over_rel=0.0351, under_rel=0.0351)
    t = np.arange(0.0, 20.0, 1.0)
    truth = 100.0 + v * t
    odo = truth[0] + (truth - truth[0]) * (1 + over)
    side = -1.0 if emit == "at_fix" else 1.0  # the truth at the interval's far edge
    est = truth + side * reach
    b = est[8] + (0.5 if emit == "at_fix" else 24.9)  # crossed at fix 9 / scheduled at fix 8
    bl = BaliseList(("B0",), np.array([b]), np.zeros(1), np.zeros(1), np.zeros(1), ("T",),
                    np.ones(1, bool), np.array([0.1]))  # surveyed to 0.1 m  # fmt: skip
    cfg = CaptureConfig(25.0, emit=emit)
    cap = capture_balises(t, est, est - reach, est + reach, bl, cfg, orientation=1,
                          odo_m=odo, odo_accuracy=acc,
                          speed_mps=np.full(len(t), v * (1 + over)))  # fmt: skip
    tt = np.arange(0.0, 19.0, 0.01)
    sc = score_captures(cap, tt, 100.0 + v * tt, orientation=1, false_tolerance_m=25.0)
    row = sc.iloc[0]
    assert row.captured and not row.hazardous
    assert abs(row.position_error_m) > reach + 0.5  # the carried distance's error counts
    assert row.q_locacc_m >= abs(row.position_error_m)


def test_no_prediction_from_a_disputed_odometer_speed():
    """A review: a radar reading twice the speed was believed by the predicted emission (q = 5 m,
    the truth 12 m from the balise). Where the odometer's disputed distance grew in the last
    step, the pair rule times the balise instead."""
    t, truth, est, lo, hi = fixes(1.0, 30.0, 20.0)
    bl = balises([truth[8] + 20.0])
    cfg = CaptureConfig(25.0, emit="predicted")
    speed = np.full(len(t), 60.0)  # the failed radar's
    calm = capture_balises(t, est, lo, hi, bl, cfg, orientation=1, speed_mps=speed)
    assert calm.epoch.iloc[0] == 8  # scheduled ahead at fix 8 (at the wrong speed)
    extra = np.column_stack([np.zeros(len(t)), 30.0 * np.arange(len(t))])  # disputed each step
    cap = capture_balises(t, est, lo, hi, bl, cfg, orientation=1, speed_mps=speed,
                          odo_extra_m=extra)  # fmt: skip
    assert cap.captured.iloc[0] and cap.epoch.iloc[0] == 9  # the crossing fix: the pair rule


@pytest.mark.parametrize("gap_s", [1.0, 2.0])
def test_the_stated_accuracy_holds_the_interpolation_between_fixes(gap_s):
    """A review: fixes gap_s apart on a train braking at 1.5 m/s^2, both intervals honest: the
    time read linearly between them put the truth 3.65 m from the balise with q = 3 m."""
    a = 1.5
    t = np.arange(0.0, 20.0, gap_s)
    truth = 30.0 * t - 0.5 * a * t**2
    reach = 2.4
    est = truth - reach  # the truth at the interval's far edge
    k = int(np.searchsorted(t, 8.0))
    bl = BaliseList(("B0",), np.array([0.5 * (est[k] + est[k + 1])]), np.zeros(1), np.zeros(1),
                    np.zeros(1), ("T",), np.ones(1, bool), np.array([0.1]))  # fmt: skip
    cap = capture_balises(t, est, est - reach, est + reach, bl, CaptureConfig(25.0),
                          orientation=1)  # fmt: skip
    tt = np.arange(0.0, 19.0, 0.001)
    sc = score_captures(cap, tt, 30.0 * tt - 0.5 * a * tt**2, orientation=1,
                        false_tolerance_m=25.0)  # fmt: skip
    row = sc.iloc[0]
    assert row.captured and not row.hazardous
    assert row.q_locacc_m >= abs(row.position_error_m)


def test_the_after_void_capture_states_the_interpolation_between_its_fixes_too():
    """The passage time at the first located fix after a voided epoch is read along the
    odometer, known at the fixes only, so linearly between them as the pair rule's: a train
    braking at 1.5 m/s^2 over a 2 s step is up to a gap^2 / 8 = 0.75 m off that line. The
    truth is the braking profile; the odometer exact at the fixes; the fix honest, the truth
    at its interval's far edge (2.8 m)."""
    a, reach = 1.5, 2.8
    t = np.arange(0.0, 20.0, 2.0)
    truth = 30.0 * t - 0.5 * a * t**2
    est = truth - reach
    located = t >= 10.0  # the fixes before are voided: the one at 10 s captures after them
    k = int(np.flatnonzero(located)[0])
    b = 0.5 * (truth[k - 1] + truth[k]) - reach  # the estimate was there at mid-step
    bl = BaliseList(("B0",), np.array([b]), np.zeros(1), np.zeros(1), np.zeros(1), ("T",),
                    np.ones(1, bool), np.array([0.1]))  # fmt: skip
    acc = OdometerAccuracy(0.01, 0.001, 0.001)
    cap = capture_balises(t, est, est - reach, est + reach, bl, CaptureConfig(25.0),
                          orientation=1, odo_m=truth - truth[0], located=located,
                          odo_accuracy=acc)  # fmt: skip
    assert cap.after_void.iloc[0]
    tt = np.arange(0.0, 19.0, 0.001)
    sc = score_captures(cap, tt, 30.0 * tt - 0.5 * a * tt**2, orientation=1,
                        false_tolerance_m=25.0)  # fmt: skip
    row = sc.iloc[0]
    assert abs(row.position_error_m) > 3.0 + 0.25  # the interpolation's part is 0.75 m
    assert row.captured and not row.hazardous
    assert row.q_locacc_m >= abs(row.position_error_m)


def test_every_miss_says_why():
    """A user trial's list with ``accuracy_m`` 50 (centimetres meant) missed 22 passages of 22
    and nothing said why: the capture rate read as "not reliable here"."""
    from locator.balises.capture import MISS_NO_PAIR, MISS_Q, MISS_ZONE

    t, _truth, est, lo, hi = fixes(1.0, 22.0, 20.0)
    bl = balises([105.0, 230.0])
    ok = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(12.0), orientation=1)
    assert ok["captured"].all() and (ok["miss_reason"] == "").all()
    # the balises' own accuracy leaves the telegram's over Q_LOCACC: 15 m reach + 50 m
    bl50 = BaliseList(bl.ids, bl.chainage_m, bl.lat_deg, bl.lon_deg, bl.h_m, bl.telegram,
                      bl.q_reference, np.full(2, 50.0))  # fmt: skip
    cap = capture_balises(t, est, est - 15.0, est + 15.0, bl50, CaptureConfig.gaderos(12.0),
                          orientation=1)  # fmt: skip
    assert not cap["captured"].any()
    assert cap["miss_reason"].str.startswith(MISS_Q).all(), cap["miss_reason"].tolist()
    assert cap["miss_reason"].str.contains(r"\(6\d m > 63 m\)").all()
    # a zone smaller than the step, and a balise before any valid pair of fixes
    r2 = capture_balises(t, est, lo, hi, balises([-5.0, 121.0]),
                         CaptureConfig.gaderos(2.0), orientation=1)  # fmt: skip
    assert r2["miss_reason"].tolist() == [MISS_NO_PAIR, MISS_ZONE]


def test_each_capture_row_carries_the_balise_q_reference():
    """A user trial: captures.csv did not say which telegrams may reset the odometer's
    interval (Q_REFERENCE): the list's 0/1 is carried to every row, captured or not."""
    t, _truth, est, lo, hi = fixes(1.0, 22.0, 20.0)
    bl = balises([105.0, 230.0, 500.0])  # the last is never reached
    bl = BaliseList(bl.ids, bl.chainage_m, bl.lat_deg, bl.lon_deg, bl.h_m, bl.telegram,
                    np.array([True, False, False]), bl.accuracy_m)  # fmt: skip
    cap = capture_balises(t, est, lo, hi, bl, CaptureConfig.gaderos(25.0), orientation=1)
    assert cap["q_reference"].tolist() == [1, 0, 0]
    assert cap["captured"].tolist() == [True, True, False]
    sc = score_captures(cap, t, _truth, orientation=1, false_tolerance_m=25.0)
    assert sc["q_reference"].tolist() == [1, 0, 0]
