"""Left and right swapped: the way each side camera's scenery slides from frame to frame."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.camera.models import Mount
from predisat.reconstruct.sides import (
    SideVotes,
    expected_flow_sign,
    profile_shift_px,
    side_votes,
    sky_profile,
)


def _skyline(x: np.ndarray, seed: int) -> np.ndarray:
    """A rough skyline (sky share per column): buildings and trees of random widths."""
    rng = np.random.default_rng(seed)
    edges = np.cumsum(rng.integers(5, 40, 200))
    heights = rng.uniform(0.2, 0.9, 200)
    return heights[np.searchsorted(edges, x % edges[-1])]


def test_the_shift_of_a_moved_profile_is_found() -> None:
    x = np.arange(400.0)
    earlier = _skyline(x, 1)
    for shift in (-37, -5, 0, 12, 80):
        later = _skyline(x + shift, 1)  # later(x) = earlier(x + shift)
        s, c = profile_shift_px(earlier, later, 100)
        assert s == shift and c > 0.99
    with pytest.raises(ValueError, match="max_shift_px"):
        profile_shift_px(earlier, earlier, 300)


def test_a_camera_looking_left_sees_its_scenery_slide_left() -> None:
    assert expected_flow_sign(Mount.default("left")) == 1
    assert expected_flow_sign(Mount.default("right")) == -1
    # a cab camera looks along the travel: it does not vote
    assert expected_flow_sign(Mount.default("front")) == 0
    assert expected_flow_sign(Mount.default("rear")) == 0
    # mounted upside down (rolled 180 deg): its image is turned, so is the slide
    left = Mount.default("left")
    upside = Mount("left", left.yaw_deg, left.pitch_deg, 180.0, left.lever_arm_m)
    assert expected_flow_sign(upside) == -1


def test_votes_count_the_pairs_that_moved_and_tell_a_swap() -> None:
    x = np.arange(320.0)
    # a left camera moving on: each frame's scenery 9 px further left than the one before
    moving = [_skyline(x + 9 * k, 4) for k in range(30)]
    ok = side_votes("left", moving, expected=1)
    assert ok == SideVotes("left", 29, 0, 29) and not ok.swapped
    # the same frames filed as the right camera's: every pair the other way
    assert side_votes("right", moving, expected=-1).swapped
    # standing still (a station stop): no pair votes
    still = side_votes("left", [_skyline(x, 4)] * 12, expected=1)
    assert still.agree == still.disagree == 0 and not still.swapped
    # a camera that does not vote
    assert side_votes("front", moving, expected=0).pairs == 29


def test_the_profile_is_the_sky_share_of_each_column() -> None:
    sky = np.zeros((4, 3), bool)
    sky[:1, 0] = sky[:3, 2] = True
    np.testing.assert_allclose(sky_profile(sky), [0.25, 0.0, 0.75])


def test_process_tells_a_survey_whose_sides_are_swapped(tmp_path, capsys) -> None:
    """A rendered survey, and the same with the manifest's side column swapped (cables on the
    wrong inputs): process finds every camera's frames moving its mount's way in the first,
    the other way in the second, says so and records it in the masks."""
    import csv

    from predisat.camera.models import default_camera
    from predisat.reconstruct.batch import process_survey
    from predisat.synth.generate import generate_survey
    from predisat.track import demo_track

    generate_survey(demo_track(), 3000.0, 3200.0, sky="clear", seed=5, out_dir=tmp_path,
                    camera=default_camera("fisheye").resized(240, 180), progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    ok = process_survey(survey, tmp_path / "ok", progress=False).masks.provenance["side_check"]
    assert set(ok) == {"left", "right"}
    for v in ok.values():
        assert not v["swapped"] and v["agree"] >= 12 and v["agree"] >= 4 * v["disagree"], ok
    assert "slides the other way" not in capsys.readouterr().err
    rows = list(csv.DictReader(open(survey / "manifest.csv", newline="")))
    for r in rows:
        r["side"] = {"left": "right", "right": "left"}[r["side"]]
    with open(survey / "manifest.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    swapped = process_survey(survey, tmp_path / "swapped", progress=False).masks
    check = swapped.provenance["side_check"]
    assert all(v["swapped"] for v in check.values()), check
    err = capsys.readouterr().err
    assert "the left camera's scenery slides the other way" in err and "swapped" in err


def test_the_report_warns_of_masks_made_from_a_swapped_survey() -> None:
    from predisat.availability.run import side_swap_notes

    check = {"left": {"agree": 2, "disagree": 30, "pairs": 40, "swapped": True},
             "right": {"agree": 31, "disagree": 1, "pairs": 40, "swapped": False}}  # fmt: skip
    notes = side_swap_notes({"side_check": check})
    assert len(notes) == 1 and "left camera's frames slid the other way" in notes[0]
    assert "in 30 of 32 frame pairs" in notes[0]
    assert side_swap_notes({}) == []


def test_a_stretch_of_pairs_the_other_way_is_found_and_scattered_ones_are_not() -> None:
    from predisat.reconstruct.sides import pair_votes, stretches_the_other_way

    def votes(s: str) -> list[int]:
        return [{"+": 1, "X": -1, ".": 0}[c] for c in s]

    # a user trial's right camera: frames 10-25 were the left camera's images (copied over),
    # the camera as a whole 23 / 11 its mount's way, not swapped
    assert stretches_the_other_way(votes("++++++.++.XXXXXXX+X.X.X.X++++++++.++++++")) == [(10, 25)]
    # the same trial's left camera, correct: pairs the other way here and there
    assert stretches_the_other_way(votes("++X+++X++.+++++++X+.+.+.+X++.++X..++.X++")) == []
    # the demo survey's left camera: at most 4 of any 8 voting pairs the other way
    demo = ("++..........++.XX+++++X+++..+X+....X+...+X+..++X...+X+...+X++++++......"
            "................++.++++X+.....X+X..+X+..X..++++.X+.+.++XX+.XX+.++.X.X++...+++"
            "+++++++.++.++X+++++++...++++++++++++++++++X++...+X+.")  # fmt: skip
    assert stretches_the_other_way(votes(demo)) == []
    assert stretches_the_other_way([]) == [] and stretches_the_other_way(votes("XXXXX")) == []
    # the pairs' votes come from the profiles: a left camera moving on, then 12 frames of a
    # camera looking right (its scenery sliding the other way), then the left camera again
    x = np.arange(320.0)
    prof = [_skyline(x + 9 * k, 4) for k in range(15)]
    prof += [_skyline(x - 9 * k, 7) for k in range(12)]
    prof += [_skyline(x + 9 * k, 9) for k in range(15)]
    v = pair_votes(prof, expected=1)
    assert side_votes("left", prof, expected=1) == SideVotes("left", v.count(1), v.count(-1), 41)
    assert not side_votes("left", prof, expected=1).swapped
    (a, b), *rest = stretches_the_other_way(v)
    assert not rest and 14 <= a <= 16 and 25 <= b <= 27, (a, b)


def test_process_sets_aside_a_stretch_of_the_other_cameras_images(tmp_path, capsys) -> None:
    """A rendered survey whose right images over 70 m are the left camera's (a copy script
    that took the wrong folder; EXIF dropped): the camera as a whole votes its mount's way, so
    the swap check said nothing and a user trial's such stretch trusted 16 % of a position's
    directions falsely. Now those frames are set aside (stage "side") and named."""
    import csv

    import cv2

    from predisat.camera.models import default_camera
    from predisat.reconstruct.batch import process_survey
    from predisat.synth.generate import generate_survey
    from predisat.track import demo_track

    generate_survey(demo_track(), 3000.0, 3200.0, sky="clear", seed=5, out_dir=tmp_path,
                    camera=default_camera("fisheye").resized(240, 180), progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    rows = list(csv.DictReader(open(survey / "manifest.csv", newline="")))
    left = {r["chainage_m"]: r["image"] for r in rows if r["side"] == "left"}
    copied = []
    for r in rows:
        if r["side"] == "right" and 3060.0 <= float(r["chainage_m"]) <= 3130.0:
            im = cv2.imread(str(survey / left[r["chainage_m"]]))
            (survey / r["image"]).write_bytes(cv2.imencode(".jpg", im)[1].tobytes())
            copied.append(r["frame_id"])
    res = process_survey(survey, tmp_path / "out", progress=False)
    side_bad = {b.frame_id for b in res.bad_frames if b.stage == "side"}
    # every copied frame, and at most a few of the right camera's own beside them (a pair
    # across the stretch's ends, a stray vote the other way within the window)
    assert set(copied) <= side_bad and len(side_bad) <= len(copied) + 4, (copied, side_bad)
    assert all(b.frame_id.startswith("right_") for b in res.bad_frames), res.bad_frames
    assert not res.masks.provenance["side_check"]["right"]["swapped"]
    assert "the right camera's scenery slides the other way from its mount's from" in (
        capsys.readouterr().err
    )


def test_a_slow_reversal_is_not_taken_for_another_camera_s_images() -> None:
    """A train backing 1.5 m a frame for 10 frames (steps under the 2 m that the loader drops,
    so its frames reach `process`): its scenery slides the other way, which the window took
    for another camera's images and set aside (a review). Pairs that did not move on in the
    direction of travel do not vote; a copied stretch while moving on still does."""
    from predisat.reconstruct.sides import moving_on, pair_votes, stretches_the_other_way

    x = np.arange(320.0)
    ch = [100.0 + 10 * k for k in range(15)]
    ch += [ch[-1] - 1.5 * (k + 1) for k in range(10)]
    ch += [ch[-1] + 10 * (k + 1) for k in range(15)]
    prof = [_skyline(x + 9 * k, 4) for k in range(15)]
    prof += [_skyline(x + 9 * 14 - 3 * (k + 1), 4) for k in range(10)]  # backing
    prof += [_skyline(x + 9 * 14 - 30 + 9 * (k + 1), 4) for k in range(15)]
    assert stretches_the_other_way(pair_votes(prof, expected=1)) != []  # the old reading
    moved = moving_on(ch, reverse=False)
    assert moved.sum() == 29 and not moved[14:24].any()
    assert stretches_the_other_way(pair_votes(prof, expected=1, moved=moved)) == []
    # toward decreasing chainage the same steps are the other way round
    assert not moving_on(ch, reverse=True)[:14].any()
    # images of the other camera while moving on: still found
    other = [_skyline(x + 9 * k, 4) for k in range(15)] + [
        _skyline(x - 9 * k, 7) for k in range(12)] + [_skyline(x + 9 * k, 9) for k in range(15)]
    steps = moving_on(100.0 + 10.0 * np.arange(len(other)), reverse=False)
    assert stretches_the_other_way(pair_votes(other, expected=1, moved=steps)) != []
