"""Frames whose chainage is known within a doubt: where their cameras may stand, the attitude
read over the doubt, and masks that stay above the ray-cast truth at the stated chainages."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from predisat.camera.models import Mount, vehicle_to_enu
from predisat.masks.maskset import BinSource
from predisat.reconstruct.attitude import frame_attitudes
from predisat.reconstruct.carving import Reconstructor
from predisat.reconstruct.placement import chainage_placement_doubt
from predisat.synth.truth import true_masks
from predisat.track import demo_track
from tests.predisat.reconstruct.test_carving import FISHEYE, PARAMS, frames_for, street_world

ARM = np.array(Mount.default("left").lever_arm_m, float)


def _centre(track, s: np.ndarray, offset: np.ndarray, h: float, reverse: bool) -> np.ndarray:
    """The camera centre at chainages ``s`` (n,), ENU: the pipeline's placement."""
    rot = vehicle_to_enu(track.heading_at(s), reverse)
    return track.enu_at(s) + h * track.up_at(s) + rot @ offset


@pytest.mark.parametrize("reverse", [False, True])
def test_the_box_holds_every_place_within_the_doubt_and_is_tight(reverse: bool) -> None:
    track = demo_track()
    # on the sharpest curves of the line, on straight track, and near its start
    stated = np.array([1.0, 480.0, 1000.0, 2040.0, 3300.0, 5000.0, 5480.0])
    doubt = 3.0
    got = chainage_placement_doubt(track, stated, ARM, 4.0, reverse, doubt)
    for k, s in enumerate(stated):
        # every centimetre of the doubt, against the sampled box and its slack
        e = np.linspace(-doubt, doubt, 601)
        at = np.clip(s + e, 0.0, track.length_m)
        move = (_centre(track, at, ARM, 4.0, reverse) - _centre(track, np.array([s]), ARM,
                                                                 4.0, reverse))  # fmt: skip
        level = move @ vehicle_to_enu(track.heading_at(s), reverse)  # into the vehicle frame
        worst = np.abs(level).max(axis=0)
        box = np.array([got.along_m[k], got.across_m[k], got.up_m[k]])
        assert np.all(worst <= box), (s, worst, box)
        assert np.all(box <= worst + 0.02), (s, worst, box)  # the slack is small
        turn = np.abs((track.heading_at(at) - track.heading_at(s) + 180.0) % 360.0 - 180.0)
        assert turn.max() <= got.yaw_deg[k] <= turn.max() + 0.05


def test_no_doubt_moves_nothing_and_bad_doubts_are_refused() -> None:
    track = demo_track()
    got = chainage_placement_doubt(track, [100.0, 200.0], ARM, 4.0, False, 0.0)
    for part in (got.along_m, got.across_m, got.up_m, got.yaw_deg):
        assert np.all(part == 0.0)
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="chainage_doubt_m"):
            chainage_placement_doubt(track, [100.0], ARM, 4.0, False, bad)
    with pytest.raises(ValueError, match="chainage_doubt_m"):
        frame_attitudes(track, [100.0], [np.nan], [np.nan], False, chainage_doubt_m=-2.0)


def test_the_attitude_over_a_doubt_holds_the_attitude_of_every_place_within_it() -> None:
    track = demo_track()
    # unmeasured frames where the curves' bounds change (curve ends, cant ramps), and a
    # measured one
    k = np.abs(track.curvature_at(np.arange(0.0, track.length_m, 1.0)))
    # where the curvature crosses the thresholds of straight (R 10 km) and sharp (R 1 km)
    edges = np.flatnonzero(np.diff((k > 1e-4).astype(int) + (k > 1e-3)))
    # (12240.37: the roll's lower bound peaks 1.5 m before a threshold jump, between two
    # readings; a review found it 0.02 deg past the union before the slope's slack)
    s = np.concatenate([edges[:: max(edges.size // 12, 1)] + 0.5,
                        [330.0, 2650.0, 12240.37, 5300.0]])  # fmt: skip
    roll = np.full(s.shape, np.nan)
    pitch = np.full(s.shape, np.nan)
    roll[-1], pitch[-1] = 1.0, 0.2
    doubt = 8.0
    wide = frame_attitudes(track, s, roll, pitch, False, chainage_doubt_m=doubt,
                           imu_doubt_deg=0.1)  # fmt: skip
    rd, pd = wide.roll_doubt_deg, wide.pitch_doubt_deg
    assert rd is not None and pd is not None
    for e in np.linspace(-doubt, doubt, 801):
        a = frame_attitudes(track, s + e, roll, pitch, False, imu_doubt_deg=0.1)
        assert a.roll_doubt_deg is not None and a.pitch_doubt_deg is not None
        assert np.all(a.roll_deg - a.roll_doubt_deg >= wide.roll_deg - rd - 1e-9), e
        assert np.all(a.roll_deg + a.roll_doubt_deg <= wide.roll_deg + rd + 1e-9), e
        assert np.all(a.pitch_deg - a.pitch_doubt_deg >= wide.pitch_deg - pd - 1e-9), e
        assert np.all(a.pitch_deg + a.pitch_doubt_deg <= wide.pitch_deg + pd + 1e-9), e
    np.testing.assert_allclose(wide.doubt_deg, rd + pd)
    # the measured frame keeps its angles; nothing was widened where the track is the same
    assert wide.measured[-1] and wide.roll_deg[-1] == pytest.approx(1.0)
    exact = frame_attitudes(track, s, roll, pitch, False, imu_doubt_deg=0.1)
    assert np.all(wide.doubt_deg >= exact.doubt_deg - 1e-9)


def _placed(world, stated: np.ndarray, error_m: np.ndarray, doubt_m: float):
    """Ideal frames taken at ``stated + error_m`` and placed, as the pipeline places them, at
    ``stated``, with the doubt of ``doubt_m``."""
    track = world.track
    frames = frames_for(world, stated + error_m, FISHEYE)
    truly = stated + error_m
    out = []
    for f in frames:
        k = int(np.argmin(np.abs(truly - f.chainage_m)))
        s = float(stated[k])
        arm = np.asarray(f.mount.lever_arm_m, float)
        d = chainage_placement_doubt(track, [s], arm, 4.0, False, doubt_m)
        out.append(replace(
            f, chainage_m=s, heading_deg=float(track.heading_at(s)),
            antenna_enu_m=track.enu_at(s) + 4.0 * track.up_at(s),
            along_doubt_m=float(d.along_m[0]), across_doubt_m=float(d.across_m[0]),
            height_doubt_m=float(d.up_m[0]), attitude_doubt_deg=float(d.yaw_deg[0]),
        ))  # fmt: skip
    return out


@pytest.mark.parametrize("case", ["bias", "scatter"])
def test_masks_from_misplaced_frames_stay_above_the_truth_with_the_doubt(case: str) -> None:
    """A street with facades and a deck at 400-412 m; the frames' chainages are 3 m off (all
    the same way, or scattered): taken as exact, the masks at the stated chainages fall below
    the ray-cast truth there by degrees; with each frame bounded within the doubt, nowhere.
    A shared error is also bounded as a shift of the whole window (a jitter of 0), for less
    sky lost (scattered errors are not a shift: nothing proves that bound safe for them)."""
    world = street_world([(400.0, 412.0)], catenary=False, seed=3)
    stated = np.arange(250.0, 561.0, 10.0)
    rng = np.random.default_rng(5)
    error = (np.full(stated.shape, 3.0) if case == "bias"
             else rng.choice([-3.0, 3.0], stated.size))  # fmt: skip
    s = np.arange(370.0, 451.0, 10.0)
    truth = true_masks(world, s).mask_el_deg
    under, lost = {}, {}
    for name, frame_doubt, shift in (("exact", 0.0, 0.0), ("frames", 3.0, 0.0),
                                     ("shift", 0.0, 3.0)):  # fmt: skip
        rec = Reconstructor(replace(PARAMS, chainage_shift_m=shift)).run(
            _placed(world, stated, error, frame_doubt), s, world.track
        )
        supported = rec.source != BinSource.ASSUMED
        under[name] = float((truth - rec.mask_el_deg)[supported].max())
        visible = np.clip(90.0 - truth, 0.0, None).sum()
        trusted = np.clip(90.0 - np.maximum(rec.mask_el_deg, truth), 0.0, None).sum()
        lost[name] = 1.0 - trusted / visible
    assert under["exact"] > 2.0, under  # taken as exact: degrees of false trust
    assert under["frames"] <= 0.1, under
    if case == "bias":
        assert under["shift"] <= 0.1, under
        assert lost["shift"] < lost["frames"], lost


def test_process_takes_the_survey_statement_warns_without_one_and_says_so(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    import yaml

    from predisat.availability.run import positioning_text
    from predisat.camera.models import CameraModel
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.params import PipelineParams
    from predisat.synth.generate import generate_survey

    camera = CameraModel.pinhole_from_fov(160, 120, 74.0)
    generate_survey(demo_track(), 3000.0, 3060.0, sky="clear", seed=2, out_dir=tmp_path,
                    camera=camera, progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    doc = yaml.safe_load((survey / "survey.yaml").read_text())
    assert doc["chainage_doubt_m"] == 0.0  # a rendered survey places its frames exactly
    exact = process_survey(survey, tmp_path / "exact", progress=False).masks
    assert "chainage_doubt_m" not in capsys.readouterr().err
    assert positioning_text(exact.provenance).startswith("chainages taken as exact")
    # the survey states its doubt and a jitter under it: bounded as a shift of the survey
    doc.update(chainage_doubt_m=2.0, chainage_jitter_m=0.1)
    (survey / "survey.yaml").write_text(yaml.safe_dump(doc))
    shift = process_survey(survey, tmp_path / "shift", progress=False, replace=True).masks
    params = shift.provenance["params"]
    assert params["chainage_doubt_m"] == 2.0 and params["chainage_jitter_m"] == 0.1
    assert params["reconstruction"]["chainage_shift_m"] == 2.0
    assert "within 0.1 m of the others'" in positioning_text(shift.provenance)
    assert shift.mask_el_deg.mean() > exact.mask_el_deg.mean()
    # the command line's doubt wins over the survey's; without a jitter each frame alone
    own = process_survey(survey, tmp_path / "own", PipelineParams(chainage_doubt_m=0.5,
                                                                  chainage_jitter_m=0.5),
                         progress=False).masks  # fmt: skip
    assert own.provenance["params"]["reconstruction"]["chainage_shift_m"] == 0.0
    assert "bounded on its own" in positioning_text(own.provenance)
    # not stated: taken as exact, and process says so
    del doc["chainage_doubt_m"], doc["chainage_jitter_m"]
    (survey / "survey.yaml").write_text(yaml.safe_dump(doc))
    process_survey(survey, tmp_path / "unstated", progress=False)
    err = capsys.readouterr().err
    assert "states no chainage_doubt_m" in err and "--chainage-doubt-m" in err


def test_the_masks_hold_at_the_survey_antenna_height(tmp_path) -> None:
    """A user trial: a survey stating a 3.0 m antenna (cameras placed from it) was carved at
    the 4.0 m default, bit-identical to the 4.0 m survey's masks, and the file said 3.0 m: its
    cutting and canopy trusted 0.027 % of the directions falsely. Now the survey's height is
    the masks' reference: a lower antenna sees the same obstacles higher."""
    import yaml

    from predisat.camera.models import CameraModel
    from predisat.reconstruct.batch import process_survey
    from predisat.synth.generate import generate_survey

    camera = CameraModel.pinhole_from_fov(160, 120, 74.0)
    generate_survey(demo_track(), 3000.0, 3060.0, sky="clear", seed=2, out_dir=tmp_path,
                    camera=camera, progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    doc = yaml.safe_load((survey / "survey.yaml").read_text())
    at4 = process_survey(survey, tmp_path / "at4", progress=False).masks
    assert at4.provenance["params"]["reconstruction"]["antenna_height_m"] == 4.0
    # the same frames, the antenna stated 1 m lower and the cameras' lever arms 1 m higher:
    # the cameras stay where they were
    doc["antenna_height_m"] = 3.0
    for cam in doc["cameras"].values():
        cam["mount"]["lever_arm_m"][2] += 1.0
    (survey / "survey.yaml").write_text(yaml.safe_dump(doc))
    at3 = process_survey(survey, tmp_path / "at3", progress=False).masks
    assert at3.provenance["antenna_height_m"] == 3.0
    assert at3.provenance["params"]["reconstruction"]["antenna_height_m"] == 3.0
    closed = at4.mask_el_deg < 90.0
    diff = at3.mask_el_deg[closed] - at4.mask_el_deg[closed]
    assert diff.max() > 1.0 and np.mean(diff) > 0.0


def test_chainages_that_disagree_with_their_own_positions_raise_the_doubt(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A user trial moved every manifest chainage 5 m and kept the positions: accepted under a
    stated doubt of 0 (the load refuses beyond 10 m) and 1.14 % of the directions trusted
    falsely. Now the doubt is raised to the disagreement, bounded as a shift (every frame off
    alike), and process says so."""
    import pandas as pd

    from predisat.camera.models import CameraModel
    from predisat.reconstruct.batch import process_survey
    from predisat.synth.generate import generate_survey

    camera = CameraModel.pinhole_from_fov(160, 120, 74.0)
    generate_survey(demo_track(), 3000.0, 3060.0, sky="clear", seed=2, out_dir=tmp_path,
                    camera=camera, progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    exact = process_survey(survey, tmp_path / "exact", progress=False).masks
    assert exact.provenance["params"]["chainage_doubt_m"] == 0.0
    assert "disagree with their own" not in capsys.readouterr().err
    manifest = pd.read_csv(survey / "manifest.csv")
    manifest["chainage_m"] += 5.0
    manifest.to_csv(survey / "manifest.csv", index=False, float_format="%.17g")
    moved = process_survey(survey, tmp_path / "moved", progress=False).masks
    err = capsys.readouterr().err
    assert "disagree with their own lat_deg/lon_deg by up to 5.00 m" in err
    assert "the doubt is raised to 5 m" in err
    params = moved.provenance["params"]
    assert params["chainage_doubt_m"] == 5.0 and params["chainage_jitter_m"] < 1.0
    assert params["reconstruction"]["chainage_shift_m"] == 5.0


def test_a_mount_doubt_erodes_every_frames_sky(tmp_path) -> None:
    """A user trial pitched one camera 2 deg off its calibration: 0.056 % of the directions
    trusted falsely, no check noticing; stated as --mount-doubt-deg 2, none (26.7 -> 28.4 %
    of the sky lost). Here: the masks with the doubt are nowhere lower, higher on average, and
    the doubt is recorded."""
    from predisat.camera.models import CameraModel
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.params import PipelineParams
    from predisat.synth.generate import generate_survey

    camera = CameraModel.pinhole_from_fov(160, 120, 74.0)
    generate_survey(demo_track(), 3000.0, 3060.0, sky="clear", seed=2, out_dir=tmp_path,
                    camera=camera, progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    exact = process_survey(survey, tmp_path / "exact", progress=False).masks
    doubted = process_survey(survey, tmp_path / "doubt", PipelineParams(mount_doubt_deg=2.0),
                             progress=False).masks  # fmt: skip
    assert doubted.provenance["params"]["attitude"]["mount_doubt_deg"] == 2.0
    assert "mount_doubt_deg" not in exact.provenance["params"]["attitude"]  # run keys as before
    assert np.all(doubted.mask_el_deg >= exact.mask_el_deg - 1e-9)
    assert doubted.mask_el_deg.mean() > exact.mask_el_deg.mean()
    with pytest.raises(ValueError, match="mount_doubt_deg must be an angle"):
        PipelineParams(mount_doubt_deg=12.0)


def test_a_survey_whose_positions_lie_beside_the_track_is_said_and_recorded(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A review: a survey whose own positions all lay 4 m right of the map (the survey train
    on the other track of a double line) was processed in silence, its masks written on the
    map's axis, where the locator's other-track check cannot see them. Now process says so,
    the provenance records it, and the masks' readers (availability, locator) say it again."""
    import re

    import pandas as pd

    from predisat.availability.run import survey_check_notes
    from predisat.camera.models import CameraModel
    from predisat.reconstruct.batch import process_survey
    from predisat.synth.generate import generate_survey

    camera = CameraModel.pinhole_from_fov(160, 120, 74.0)
    generate_survey(demo_track(), 3000.0, 3060.0, sky="clear", seed=2, out_dir=tmp_path,
                    camera=camera, progress=False)  # fmt: skip
    survey = tmp_path / "survey"
    on = process_survey(survey, tmp_path / "on", progress=False).masks
    assert "survey_beside_track" not in on.provenance
    assert "beside" not in capsys.readouterr().err
    manifest = pd.read_csv(survey / "manifest.csv")
    tr = demo_track()
    ch = manifest["chainage_m"].to_numpy(float)
    lat, lon, _ = tr.position_at(ch)
    hd = np.radians(tr.heading_at(ch))  # 4 m to the right of increasing chainage
    manifest["lat_deg"] = lat - 4.0 * np.sin(hd) / 111_200.0
    manifest["lon_deg"] = lon + 4.0 * np.cos(hd) / (111_200.0 * np.cos(np.radians(lat)))
    manifest.to_csv(survey / "manifest.csv", index=False, float_format="%.17g")
    aside = process_survey(survey, tmp_path / "aside", progress=False).masks
    err = capsys.readouterr().err
    said = re.search(r"frames' own positions lie ([\d.]+) m right of the track", err)
    assert said and abs(float(said[1]) - 4.0) < 0.1, err
    rec = aside.provenance["survey_beside_track"]
    assert rec["side"] == "right" and abs(rec["median_offset_m"] - 4.0) < 0.1
    assert any("m right of the track" in n for n in survey_check_notes(aside.provenance))
