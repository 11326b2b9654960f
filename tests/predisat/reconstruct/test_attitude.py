"""Each frame's nominal attitude and doubt: measured, or bounded from the track's curves."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.camera.models import Mount
from predisat.reconstruct.attitude import ATTITUDE_STEP_DEG, frame_attitudes, survey_speed_kmh
from predisat.track import demo_track
from predisat.track.cant import (
    CantLimits,
    CantTable,
    body_roll_deg,
    cant_angle_deg,
    equilibrium_cant_mm,
)


@pytest.fixture(scope="module")
def track():  # -> TrackMap
    return demo_track()


def test_measured_attitudes_are_kept_rounded(track) -> None:
    att = frame_attitudes(track, [3300.0, 3310.0], [-0.912, 0.0], [0.33, 0.0], False,
                          imu_doubt_deg=0.1)  # fmt: skip
    assert att.measured.all()
    np.testing.assert_allclose(att.roll_deg, [-0.9, 0.0], atol=1e-12)
    np.testing.assert_allclose(att.pitch_deg, [0.35, 0.0], atol=1e-12)
    # the IMU's doubt for roll and pitch, and the rounding
    assert att.doubt_deg[1] == pytest.approx(0.2)
    assert att.doubt_deg[0] == pytest.approx(0.2 + 0.012 + 0.02)
    # its two parts: the roll's and the pitch's, each with its own rounding
    assert att.roll_doubt_deg is not None and att.pitch_doubt_deg is not None
    np.testing.assert_allclose(att.roll_doubt_deg, [0.1 + 0.012, 0.1])
    np.testing.assert_allclose(att.pitch_doubt_deg, [0.1 + 0.02, 0.1])
    np.testing.assert_allclose(att.roll_doubt_deg + att.pitch_doubt_deg, att.doubt_deg)
    exact = frame_attitudes(track, [3300.0], [-0.912], [0.33], False)
    assert exact.doubt_deg[0] == exact.roll_doubt_deg[0] == exact.pitch_doubt_deg[0] == 0.0
    assert np.all(np.abs(att.roll_deg / ATTITUDE_STEP_DEG - np.rint(att.roll_deg / 0.05)) < 1e-9)


def test_unmeasured_roll_is_centred_in_the_curve_and_its_doubt_covers_real_vehicles(track) -> None:
    s = np.arange(450.0, 1150.0, 10.0)  # a right-hand curve, R 420-640 m
    lim = CantLimits()
    nan = np.full(s.size, np.nan)
    att = frame_attitudes(track, s, nan, nan, False, cant=lim, grade_doubt_deg=0.0)
    assert not att.measured.any()
    assert np.all(att.roll_deg > 0)  # right-hand: the vehicle's left side up
    k = track.curvature_at(s)
    # a train at any speed up to the line's on any cant up to the design's stays in the doubt
    for cant_share in (0.0, 0.5, 1.0):
        cant = cant_share * np.minimum(equilibrium_cant_mm(k, lim.line_speed_kmh), lim.max_cant_mm)
        for speed in (0.0, 60.0, lim.line_speed_kmh):
            if np.any(equilibrium_cant_mm(k, speed) - cant > lim.max_deficiency_mm):
                continue
            true = body_roll_deg(k, cant, speed, lim.flexibility)
            assert np.all(np.abs(true - att.roll_deg) <= att.doubt_deg - lim.track_roll_deg + 1e-9)
    # driven the other way the same curve turns left: the roll changes sign
    back = frame_attitudes(track, s, nan, nan, True, cant=lim, grade_doubt_deg=0.0)
    np.testing.assert_allclose(back.roll_deg, -att.roll_deg, atol=1e-12)


def test_unmeasured_on_straight_track_is_level_give_or_take_the_track_and_grade(track) -> None:
    s = np.array([3300.0, 3400.0])  # straight
    assert np.all(np.abs(track.curvature_at(s)) < 1e-5)
    att = frame_attitudes(track, s, np.nan, np.nan, False, grade_doubt_deg=1.0)
    np.testing.assert_allclose(att.roll_deg, 0.0, atol=1e-12)
    assert np.all(att.doubt_deg < 0.5 + 1.0 + 0.1) and np.all(att.doubt_deg >= 1.5)
    # the grade's doubt is the pitch's, the track's play the roll's
    assert np.all(att.pitch_doubt_deg >= 1.0) and np.all(att.roll_doubt_deg >= 0.5)
    assert np.all(att.roll_doubt_deg < 0.6)


def test_a_cant_table_and_the_survey_speed_narrow_the_doubt_around_the_true_roll(track) -> None:
    s = np.arange(450.0, 1150.0, 10.0)
    k = track.curvature_at(s)
    cant = np.round(np.minimum(equilibrium_cant_mm(k, 100.0), 160.0) / 5) * 5
    table = CantTable(s, cant, "test")
    nan = np.full(s.size, np.nan)
    speed = np.full(s.size, 43.2)
    bounded = frame_attitudes(track, s, nan, nan, False, grade_doubt_deg=0.0)
    tabled = frame_attitudes(track, s, nan, nan, False, grade_doubt_deg=0.0, cant_table=table,
                             speed_kmh=speed)  # fmt: skip
    true = body_roll_deg(k, cant, 43.2)  # the synthetic world's vehicle (flexibility 0.25)
    assert np.all(np.abs(true - tabled.roll_deg) <= tabled.doubt_deg + 1e-9)
    assert np.all(tabled.doubt_deg < 0.5 * bounded.doubt_deg)
    # off the table's end: the curvature's bounds again
    far = frame_attitudes(track, [2000.0], np.nan, np.nan, False, cant_table=table)
    alone = frame_attitudes(track, [2000.0], np.nan, np.nan, False)
    assert far.doubt_deg[0] == alone.doubt_deg[0]


def test_a_cant_table_in_centimetres_is_ruled_out_by_the_survey_speed(track) -> None:
    """A table of the right cant divided by ten: the survey vehicle, at its speed there,
    would have run with far more cant deficiency than any train; the table is not used and
    the true roll stays within the doubt. Taken at its word it would not be."""
    s = np.arange(450.0, 1150.0, 10.0)
    k = track.curvature_at(s)
    cant = np.round(np.minimum(equilibrium_cant_mm(k, 120.0), 160.0) / 5) * 5
    nan = np.full(s.size, np.nan)
    speed = np.full(s.size, 110.0)
    true = body_roll_deg(k, cant, 110.0)
    right = frame_attitudes(track, s, nan, nan, False, cant_table=CantTable(s, cant, "mm"),
                            speed_kmh=speed)  # fmt: skip
    assert not right.table_ignored.any()
    cm = CantTable(s, cant / 10.0, "cm")
    wrong = frame_attitudes(track, s, nan, nan, False, cant_table=cm, speed_kmh=speed)
    assert wrong.table_ignored.all()  # the whole table, on the straights too
    assert np.all(np.abs(true - wrong.roll_deg) <= wrong.doubt_deg + 1e-9)
    # the check it replaces: bounded around the centimetres, the roll is out of the doubt
    import predisat.reconstruct.attitude as attitude

    taken = attitude._roll_interval(track, s, False, None, cm.cant_mm_at(s), speed)
    assert np.any((true < taken[0] - 0.5) | (true > taken[1] + 0.5))
    # without the survey's speed, or at a slow one, the deficiency cannot tell; the table's
    # largest cant on the sharp curves, 16 mm, tells its unit (a review found 60 km/h passed)
    for kmh in (None, 60.0):
        slow = None if kmh is None else np.full(s.size, kmh)
        blind = frame_attitudes(track, s, nan, nan, False, cant_table=cm, speed_kmh=slow)
        assert blind.table_ignored.all()
        roll = body_roll_deg(k, cant, 110.0 if kmh is None else kmh)
        assert np.all(np.abs(roll - blind.roll_deg) <= blind.doubt_deg + 1e-9)


def test_survey_speed_from_each_cameras_frames() -> None:
    t = np.array([0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 5.0])
    s = np.array([0.0, 0.0, 10.0, 10.0, 22.0, 22.0, 30.0])
    side = np.array(["left", "right"] * 3 + ["front"])
    v = survey_speed_kmh(s, t, side)
    np.testing.assert_allclose(v[:6], [36.0, 36.0, 39.6, 39.6, 43.2, 43.2])
    assert np.isnan(v[6])  # one frame of that camera: no speed


def test_bad_doubts_are_refused(track) -> None:
    with pytest.raises(ValueError, match="grade_doubt_deg"):
        frame_attitudes(track, [0.0], np.nan, np.nan, False, grade_doubt_deg=-1.0)


# ------------------------------------------------- a canted curve, end to end against the truth


@pytest.fixture(scope="module")
def canted(tmp_path_factory: pytest.TempPathFactory):  # -> (truth, {variant: masks})
    """A rendered survey on a right-hand curve (R 420-640 m, 160 mm of cant, the body rolled
    6-7 deg), processed five ways: the roll measured, not given, wrongly given as level (which
    the track rules out), not given but the line's cant table, and the attitude ignored (the
    pipeline before it knew of cant: every frame level and sure)."""
    import csv

    from predisat.camera.models import default_camera
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.evaluate import load_truth
    from predisat.reconstruct.params import PipelineParams
    from predisat.synth.generate import generate_survey

    base = tmp_path_factory.mktemp("cant")
    cam = default_camera("fisheye").resized(400, 300)
    generate_survey(demo_track(), 760.0, 900.0, sky="clear", seed=4, out_dir=base, camera=cam,
                    progress=False, cant_speed_kmh=100.0)  # fmt: skip
    survey = base / "survey"
    rows = list(csv.DictReader(open(survey / "manifest.csv", newline="")))
    assert all(5.0 < float(r["roll_deg"]) < 8.0 for r in rows)
    masks = {"measured": process_survey(survey, base / "measured", PipelineParams(),
                                        progress=False).masks}  # fmt: skip
    params = {"unknown": PipelineParams(), "level": PipelineParams(),
              "table": PipelineParams(cant_table=CantTable.from_csv(base / "truth" / "cant.csv"))}
    for variant, value in (("unknown", ""), ("level", "0.0"), ("table", "")):
        for r in rows:
            r["roll_deg"] = r["pitch_deg"] = value
        with open(survey / "manifest.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
            w.writeheader()
            w.writerows(rows)
        masks[variant] = process_survey(survey, base / variant, params[variant],
                                        progress=False).masks  # fmt: skip
    # the attitude ignored, in this process (serial): every frame level, no doubt
    import predisat.reconstruct.chunks as chunks
    from predisat.reconstruct.attitude import level_attitudes

    monkey = pytest.MonkeyPatch()
    monkey.setattr(chunks, "frame_attitudes", level_attitudes)
    try:
        masks["ignored"] = process_survey(survey, base / "ignored", PipelineParams(),
                                          progress=False, scheduler="serial").masks  # fmt: skip
    finally:
        monkey.undo()
    return load_truth(base / "truth"), masks


def _false_trust_and_lost(masks, truth) -> tuple[float, float]:
    from predisat.reconstruct.evaluate import compare, trust_counts

    c = compare(masks, truth)
    trusted, good, los = trust_counts(c.mask_el_deg, c.truth_el_deg)
    return 1 - good.sum() / trusted.sum(), 1 - good.sum() / los.sum()


def test_a_canted_curve_is_safe_with_the_roll_measured_or_bounded(canted) -> None:
    truth, masks = canted
    ft = {k: _false_trust_and_lost(m, truth) for k, m in masks.items()}
    # ignoring the roll trusts blocked directions on the curve's low side ...
    assert ft["ignored"][0] > 1e-3, ft
    # ... the measured roll, the bounded one and the one bounded around a cant table do not,
    # nor a roll declared level, which the track rules out on this curve
    for variant in ("measured", "unknown", "table", "level"):
        assert ft[variant][0] < 1e-4, (variant, ft)
    assert masks["level"].provenance["attitude"]["contradicted_frames"] == 30
    # knowing the roll costs no sky against the bound; the table recovers part of it
    assert ft["measured"][1] < ft["table"][1] < ft["unknown"][1], ft


def test_the_masks_say_how_the_attitude_was_known(canted) -> None:
    from predisat.availability.run import attitude_text

    _, masks = canted
    measured = masks["measured"].provenance["attitude"]
    assert measured["measured_frames"] == measured["frames"] > 0
    # taken as exact by default
    assert measured["max_doubt_deg"] == 0.0 and 5.0 < measured["max_abs_roll_deg"] < 8.0
    unknown = masks["unknown"].provenance["attitude"]
    assert unknown["measured_frames"] == 0 and unknown["max_doubt_deg"] > 5.0
    # the doubt moves the cameras: at least the shipped side camera's roll chord from the
    # rails (3.3 m), at most the chord of the whole doubt from there
    arm = np.array(Mount.default("left").lever_arm_m) + np.array([0.0, 0.0, 4.0])
    half = np.radians(unknown["max_doubt_deg"]) / 2.0
    assert measured["max_camera_doubt_m"] == 0.0
    assert 0.1 < unknown["max_camera_doubt_m"] <= 2.0 * np.linalg.norm(arm) * np.sin(half)
    assert attitude_text(masks["measured"].provenance).startswith("measured")
    assert "bounded from the track" in attitude_text(masks["unknown"].provenance)
    assert "cameras placed within" in attitude_text(masks["unknown"].provenance)
    assert attitude_text({}) == ""


def test_process_warns_when_the_attitude_is_not_measured(canted) -> None:
    from predisat.reconstruct.batch import _attitude_warning

    _, masks = canted
    assert _attitude_warning(masks["measured"].provenance["attitude"]) is None
    note = _attitude_warning(masks["unknown"].provenance["attitude"])
    assert note is not None and "no measured roll and pitch" in note and "roll_deg" in note


def test_a_straight_next_to_a_curve_is_bounded_by_the_curve(track) -> None:
    # the cant ramps in before the curve, where the smoothed map reads straight
    s_curve, s_before = np.array([1100.0]), np.array([1290.0])  # the curve ends near 1240 m
    assert abs(track.curvature_at(s_before)[0]) < 1e-4  # R > 10 km
    nan = np.array([np.nan])
    before = frame_attitudes(track, s_before, nan, nan, False, grade_doubt_deg=0.0)
    curve = frame_attitudes(track, s_curve, nan, nan, False, grade_doubt_deg=0.0)
    far = frame_attitudes(track, np.array([3350.0]), nan, nan, False, grade_doubt_deg=0.0)
    assert before.doubt_deg[0] > 0.8 * curve.doubt_deg[0] > 2 * far.doubt_deg[0]
    assert np.sign(before.roll_deg[0]) == np.sign(curve.roll_deg[0]) == 1


def test_near_curves_of_both_hands_the_roll_may_go_either_way(track) -> None:
    # km 10.3-10.9 of the demo line: a left-hand curve ends, a right-hand one begins (10.61)
    s = np.arange(10300.0, 10900.0, 10.0)
    k = track.curvature_at(s)
    nan = np.full(s.size, np.nan)
    att = frame_attitudes(track, s, nan, nan, False, grade_doubt_deg=0.0)
    lo, hi = att.roll_deg - att.doubt_deg, att.roll_deg + att.doubt_deg
    def within(x: float, limit: float) -> tuple[bool, bool]:
        kk = track.curvature_at(np.arange(x - 150, x + 151, 5.0))
        return bool((kk > limit).any()), bool((kk < -limit).any())

    # curves sharper than R = 1000 m of both hands within 150 m: 160 mm of cant (180 mm for
    # 200 km/h) either way
    sharp = np.array([all(within(x, 1e-3)) for x in s])
    both = np.array([all(within(x, 1e-4)) for x in s])
    assert sharp.any() and (~both).any()
    lean = float(cant_angle_deg(160.0))
    assert np.all((lo[sharp] <= -lean) & (hi[sharp] >= lean))
    # away from the other hand's curve, its own hand (a left-hand curve leans left)
    alone = ~both & (np.abs(k) > 1e-4)
    assert np.all(np.sign(att.roll_deg[alone]) == -np.sign(k[alone]))


def test_a_measured_roll_the_track_rules_out_is_bounded_instead(track) -> None:
    s = np.arange(800.0, 900.0, 10.0)  # a right-hand curve, R about 430 m: leans right (+)
    k = track.curvature_at(s)
    true = body_roll_deg(k, np.minimum(equilibrium_cant_mm(k, 100.0), 160.0), 43.0)
    assert np.all(true > 5.0)
    pitch = np.zeros(s.size)
    ok = frame_attitudes(track, s, true, pitch, False)
    assert ok.measured.all() and not ok.contradicted.any()
    bound = frame_attitudes(track, s, np.full(s.size, np.nan), pitch, False)
    for wrong in (-true, np.radians(true), np.zeros(s.size)):  # sign, units, a tilt sensor
        att = frame_attitudes(track, s, wrong, pitch, False)
        assert att.contradicted.all() and not att.measured.any()
        # bounded as if not measured, the pitch kept
        np.testing.assert_allclose(att.roll_deg, bound.roll_deg)
        assert np.all(np.abs(true - att.roll_deg) <= att.doubt_deg)
    # with an IMU doubt, a ruled-out roll keeps it on top of the bound: the roll's part is the
    # interval's half-width plus the IMU's, the pitch's the IMU's
    noisy = frame_attitudes(track, s, -true, pitch, False, imu_doubt_deg=0.3)
    # (the bound's roll part, its rounding included: the same nominal roll)
    np.testing.assert_allclose(noisy.roll_doubt_deg, bound.roll_doubt_deg + 0.3, atol=1e-9)
    np.testing.assert_allclose(noisy.doubt_deg - noisy.roll_doubt_deg, 0.3, atol=0.051)
    # a cant table saying 0 on a sharp curve reads as a mistake too, and is not used
    table = CantTable(s, np.zeros(s.size), "zeros")
    att = frame_attitudes(track, s, np.full(s.size, np.nan), pitch, False, cant_table=table)
    assert att.table_ignored.all()
    np.testing.assert_allclose(att.doubt_deg, bound.doubt_deg)


def test_process_says_which_rolls_the_track_ruled_out_and_what_a_table_missed() -> None:
    from predisat.reconstruct.batch import _attitude_warnings

    lines = _attitude_warnings({
        "frames": 10, "measured_frames": 6, "contradicted_frames": 4,
        "first_contradicted": "left_000003", "cant_table_frames": 7,
        "cant_table_ignored_frames": 2, "cant_off_curve_frames": 0, "max_doubt_deg": 3.0,
    })  # fmt: skip
    text = " ".join(lines)
    assert "4 of 10 frames give a roll the track rules out (first left_000003)" in text
    assert "the cant table covers 7 of 10 frames" in text
    assert "ruled out at 2 frames: under 5 mm" in text and "250 mm" in text
    # the 4 contradicted frames are told apart, not counted as unmeasured
    assert "have no measured roll" not in text


def test_an_imu_the_track_contradicts_on_its_curves_is_not_trusted_anywhere(track) -> None:
    # a level reading over a curve's body and its gentler ends: ruled out on the body, so the
    # ends, where a level roll is possible, are not trusted either
    s = np.arange(400.0, 1300.0, 10.0)
    zero = np.zeros(s.size)
    att = frame_attitudes(track, s, zero, zero, False)
    assert att.contradicted.all() and not att.measured.any()
    # one glitch on a good IMU stays one frame
    k = track.curvature_at(s)
    true = body_roll_deg(k, np.minimum(equilibrium_cant_mm(k, 100.0), 160.0), 43.0)
    glitch = true.copy()
    glitch[40] = -glitch[40]
    att = frame_attitudes(track, s, glitch, zero, False)
    assert att.contradicted.sum() == 1 and att.contradicted[40]


def test_a_window_takes_the_surveys_verdict_on_its_imu_and_cant_table(track) -> None:
    """A review (hW): the fifth-of-the-curve-frames rule was applied in each chunk's window, so
    a frame read by two chunks could keep its measured roll in one and get a bounded one in the
    other. The survey's verdicts, given, decide in every window, both ways."""
    s = np.arange(400.0, 1300.0, 10.0)
    zero = np.zeros(s.size)
    k = track.curvature_at(s)
    true = body_roll_deg(k, np.minimum(equilibrium_cant_mm(k, 100.0), 160.0), 43.0)
    # a good IMU with a bad stretch: 10 of 90 frames ruled out, not a fifth of the survey...
    roll = true.copy()
    roll[40:50] = -roll[40:50]
    whole = frame_attitudes(track, s, roll, zero, False)
    assert not whole.imu_distrusted and whole.contradicted.sum() == 10
    # ...but most of a window around it, which alone sets the whole IMU aside
    w = slice(35, 55)
    alone = frame_attitudes(track, s[w], roll[w], zero[w], False)
    assert alone.imu_distrusted and alone.contradicted.all()
    given = frame_attitudes(track, s[w], roll[w], zero[w], False,
                            verdicts=(whole.imu_distrusted, whole.table_distrusted))  # fmt: skip
    assert not given.imu_distrusted
    np.testing.assert_array_equal(given.contradicted, whole.contradicted[w])
    np.testing.assert_array_equal(given.roll_deg, whole.roll_deg[w])
    # the other way: a survey whose IMU is set aside keeps it aside in a window that agrees
    level = frame_attitudes(track, s, zero, zero, False)
    assert level.imu_distrusted
    good = slice(0, 8)  # frames where a level roll is possible
    mine = frame_attitudes(track, s[good], zero[good], zero[good], False, verdicts=(True, False))
    assert mine.contradicted.all() and not mine.measured.any()
    # and the cant table: a table in centimetres judged over the survey, given to a window
    cant = np.round(np.minimum(equilibrium_cant_mm(k, 120.0), 160.0) / 5) * 5
    nan = np.full(s.size, np.nan)
    cm = CantTable(s, cant / 10.0, "cm")
    survey = frame_attitudes(track, s, nan, nan, False, cant_table=cm)
    assert survey.table_distrusted
    part = frame_attitudes(track, s[good], nan[good], nan[good], False, cant_table=cm,
                           verdicts=(False, True))  # fmt: skip
    assert part.table_distrusted and part.table_ignored[np.isfinite(cm.cant_mm_at(s[good]))].all()
