"""Cameras out of step: what two cameras both see must match at the same position."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from predisat.camera.models import Mount, default_camera
from predisat.reconstruct.params import PipelineParams
from predisat.reconstruct.step import (
    MIN_OVERLAP_DIRECTIONS,
    OffStep,
    comparable,
    lag_disagreement,
    off_step,
    overlap_pixels,
    step_lags,
    widen,
)


def _vehicle_rays(camera, mount, pix):
    rows, cols = pix
    rays = camera.pixel_to_ray(cols.astype(float), rows.astype(float))
    rays = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    return rays @ mount.camera_to_vehicle().T


def test_side_fisheyes_share_the_sky_above_the_track() -> None:
    cam = default_camera("fisheye").resized(320, 240)
    left, right = Mount.default("left"), Mount.default("right")
    pa, pb = overlap_pixels(cam, left, cam, right)
    assert pa[0].size >= MIN_OVERLAP_DIRECTIONS and pa[0].size == pb[0].size
    # each pair of pixels looks the same way (the inverse projection, not the forward one
    # the function used): within about two pixels' angle
    ra, rb = _vehicle_rays(cam, left, pa), _vehicle_rays(cam, right, pb)
    angle = np.degrees(np.arccos(np.clip((ra * rb).sum(axis=1), -1, 1)))
    assert np.max(angle) < 2.5 * cam.widest_pixel_deg
    # above the vehicle's horizon, and over the track (between the two cameras' sides)
    assert np.all(ra[:, 2] > 0.3)


def test_pinhole_side_cameras_share_nothing() -> None:
    cam = default_camera("pinhole")
    pa, _ = overlap_pixels(cam, Mount.default("left"), cam, Mount.default("right"))
    assert pa[0].size < MIN_OVERLAP_DIRECTIONS


def test_overlap_pixels_refuses_bad_parameters() -> None:
    cam = default_camera("fisheye")
    with pytest.raises(ValueError, match="edge_deg"):
        overlap_pixels(cam, Mount.default("left"), cam, Mount.default("right"), edge_deg=50)
    with pytest.raises(ValueError, match="n_directions"):
        overlap_pixels(cam, Mount.default("left"), cam, Mount.default("right"), n_directions=0)


def test_disagreement_is_zero_at_the_lag_of_a_late_camera() -> None:
    rng = np.random.default_rng(3)
    scene = [rng.random(40) < 0.5 for _ in range(12)]
    a = list(scene)
    b = [*scene[1:], None]  # b's images one position late against its rows
    d = lag_disagreement(a, b, max_lag=2)
    assert d.shape == (12, 5)
    # a[i] is b[i - 1]: lag -1 agrees everywhere it is defined
    assert np.all(d[1:, 1] == 0.0) and np.isnan(d[0, 1])
    # by hand at one position and lag
    assert d[5, 3] == np.count_nonzero(scene[5] != scene[7]) / 40
    assert np.isnan(d[11, 2]) and np.all(np.isnan(d[:2, 0]))
    with pytest.raises(ValueError, match="one length"):
        lag_disagreement(a, b[:-1])


def _cost(per_lag: np.ndarray, lags: tuple[int, ...], switch: float) -> float:
    centre = per_lag.shape[1] // 2
    total = switch * (lags[0] != 0)
    total += sum(per_lag[i, centre + g] for i, g in enumerate(lags))
    return total + switch * sum(x != y for x, y in itertools.pairwise(lags))


def test_the_lags_are_the_least_cost_sequence() -> None:
    """Against every sequence of lags of a short survey (enumerated)."""
    rng = np.random.default_rng(7)
    for cap in (1.0, 0.05):
        for _ in range(30):
            d = rng.random((7, 3)) * 0.2
            lags = step_lags(d, switch_cost=0.1, position_cap=cap)
            capped = np.minimum(d, d.min(axis=1, keepdims=True) + cap)
            best = min(_cost(capped, s, 0.1) for s in itertools.product((-1, 0, 1), repeat=7))
            assert _cost(capped, tuple(int(g) for g in lags), 0.1) == pytest.approx(best)


def test_a_late_stretch_is_found_and_noise_is_not() -> None:
    rng = np.random.default_rng(11)
    noise = 0.03 + 0.01 * rng.random((120, 7))
    assert not np.any(step_lags(noise, 0.3))
    late = noise.copy()
    late[60:, np.arange(7) != 2] += 0.03  # from position 60 on, lag -1 agrees 3 points better
    lags = step_lags(late, 0.3)
    # one stretch, holding every late position; where the noise alone cannot tell (zero mean
    # difference between the lags) the change may come earlier: more frames set aside
    assert off_step(lags) == [OffStep(int(np.argmax(lags != 0)), 119, -1)]
    assert np.all(lags[60:] == -1)
    # an advantage too small to pay for two changes: in step
    slight = noise.copy()
    slight[60:70, np.arange(7) != 2] += 0.02
    assert not np.any(step_lags(slight, 0.3))
    # positions without evidence (NaN: open sky, missing frames) carry the lag on
    gap = late.copy()
    gap[80:100] = np.nan
    assert np.all(step_lags(gap, 0.3)[61:] == -1)
    # a few positions of strong evidence alone (a tunnel mouth, where lags pairing frames
    # inside the tunnel agree trivially) do not make a stretch
    mouth = noise.copy()
    mouth[50:55, 1:] += 0.15  # lag -3 best by 0.15 at five positions
    mouth[80:100, np.arange(7) != 3] += 0.03  # in step further on
    assert not np.any(step_lags(mouth, 0.3))
    assert np.any(step_lags(mouth, 0.3, position_cap=1.0))
    with pytest.raises(ValueError, match="switch_cost"):
        step_lags(noise, 0.0)


def test_cameras_far_apart_along_the_vehicle_are_not_compared() -> None:
    left, right = Mount.default("left"), Mount.default("right")
    assert comparable(left, right, 10.0)
    front = Mount("front", 0.0, 30.0, 0.0, (3.0, 0.0, -1.5))
    rear = Mount("rear", 180.0, 30.0, 0.0, (-3.0, 0.0, -1.5))
    assert comparable(front, left, 10.0) and not comparable(front, rear, 10.0)
    assert comparable(front, rear, 12.0)
    with pytest.raises(ValueError, match="spacing_m"):
        comparable(left, right, 0.0)


def test_off_step_groups_the_runs() -> None:
    assert off_step([0, 0, -1, -1, 0, 2, 2, 2]) == [OffStep(2, 3, -1), OffStep(5, 7, 2)]
    assert off_step([]) == [] and off_step([0, 0]) == []


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A rendered survey of town under catenary with two overbridges, at positions 6-7 and
    15-16 (fisheyes 240x180, 31 positions): the only things the two cameras' shared sky sees
    change from one position to the next, so a dropped image before the first is seen over
    the whole survey, and one between them from the first on."""
    from predisat.synth.generate import generate_survey
    from predisat.synth.world import Stretch, WorldSpec
    from predisat.track import demo_track

    out = tmp_path_factory.mktemp("step")
    spec = WorldSpec((Stretch("town", 3000, 3300), Stretch("overbridge", 3060, 3070),
                      Stretch("overbridge", 3150, 3160)), hills=False)  # fmt: skip
    generate_survey(demo_track(), 3000.0, 3300.0, sky="clear", seed=5, out_dir=out,
                    spec=spec, camera=default_camera("fisheye").resized(240, 180),
                    progress=False)  # fmt: skip
    return out / "survey"


def _drop_right_image(survey, first: int = 5):
    """The manifest whose right camera's rows from the ``first + 1``-th on give the next row's
    image (a dropped image); the moved rows' frame ids."""
    import pandas as pd

    man = pd.read_csv(survey / "manifest.csv")
    right = man.index[man.side == "right"][np.argsort(man.gps_s[man.side == "right"])]
    late = right[first:]
    man.loc[late[:-1], "image"] = man.loc[late[1:], "image"].to_numpy()
    man.drop(index=late[-1:]).to_csv(survey / "manifest.csv", index=False)
    return set(man.frame_id[late[:-1]])


def test_process_sets_aside_the_frames_of_a_camera_out_of_step(rendered, tmp_path,
                                                               capsys) -> None:  # fmt: skip
    """The rendered survey with its images' capture times removed, and the same whose right
    camera dropped an image before the first overbridge: process finds the first in step, and
    in the second the whole survey out of step, and stops saying why."""
    import shutil

    from predisat.availability.run import step_notes
    from predisat.reconstruct.batch import process_survey

    survey = tmp_path / "survey"
    shutil.copytree(rendered, survey)
    for image in (survey / "images").iterdir():  # no capture times: the other check is blind
        image.write_bytes(_without_exif(image.read_bytes()))
    ok = process_survey(survey, tmp_path / "ok", progress=False)
    assert not any(v["checked"] for v in ok.masks.provenance["capture_check"].values())
    assert ok.masks.provenance["step_check"]["left/right"]["off_step"] == []
    assert not any(b.stage == "step" for b in ok.bad_frames)
    assert "out of step" not in capsys.readouterr().err

    _drop_right_image(survey)
    # the stretch out of step takes in the whole of this 300 m survey: no frame is left, and
    # the run stops saying why instead of publishing masks all assumed (since 2026-12-07)
    with pytest.raises(ValueError, match=r"every one of its (\d+) frames was set aside "
                       r"\(\1 at stage step; .*out of step.*fix the manifest"):  # fmt: skip
        process_survey(survey, tmp_path / "late", progress=False)
    assert not (tmp_path / "late" / "masks.parquet").exists()
    err = capsys.readouterr().err
    assert "cameras are out of step from chainage" in err and "fix the manifest" in err
    assert "capture times were not compared" in err
    assert step_notes(ok.masks.provenance) == []


def test_a_finished_run_out_of_step_is_repeated_by_the_availability_report(
    rendered, tmp_path, capsys
) -> None:
    """The survey without capture times whose right camera dropped an image between the two
    overbridges: the first confirms the cameras in step, so the run sets aside the frames from
    there on, keeps those before it and finishes; ``predisat availability`` on its output
    repeats the step note (the drop before the first overbridge is refused whole since
    2026-12-07, which left this untested)."""
    import html
    import shutil

    from predisat.availability.run import step_notes
    from predisat.cli.app import main
    from predisat.reconstruct.batch import process_survey

    survey = tmp_path / "survey"
    shutil.copytree(rendered, survey)
    for image in (survey / "images").iterdir():  # no capture times: the other check is blind
        image.write_bytes(_without_exif(image.read_bytes()))
    moved = _drop_right_image(survey, first=10)
    got = process_survey(survey, tmp_path / "late", progress=False)
    (run,) = got.masks.provenance["step_check"]["left/right"]["off_step"]
    # from the first overbridge (positions 6-7) on, not from the survey's start
    assert run["lag"] == -1 and 6 <= run["first_position"] <= 10 and run["last_position"] == 30
    set_aside = {b.frame_id for b in got.bad_frames if b.stage == "step"}
    assert set_aside == set(run["frames"])
    assert moved <= set_aside and any(f.startswith("left") for f in set_aside)
    assert {"left_000000", "right_000000", "left_000005"}.isdisjoint(set_aside)
    assert np.count_nonzero(got.masks.mask_el_deg[:5] < 89.9) > 0  # the kept start trusts sky
    err = capsys.readouterr().err
    assert "cameras are out of step from chainage" in err and "fix the manifest" in err
    (note,) = step_notes(got.masks.provenance)
    assert "were out of step from chainage" in note

    argv = ["availability", "--masks", str(tmp_path / "late"), "--out", str(tmp_path / "a"),
            "--start", "2020-06-25T06:00", "--end", "2020-06-25T06:30", "--step", "900",
            "--scheduler", "serial", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert f"predisat availability: warning: {note}" in err
    assert html.escape(note) in (tmp_path / "a" / "report.html").read_text()


def test_a_lost_frame_is_not_out_of_step(rendered, tmp_path, capsys) -> None:
    """A frame lost honestly: the right camera's 11th image gone with its manifest row, and
    the left camera's 21st image gone with its row kept. The frames pair by time, not by their
    index in each camera's list, so the cameras stay in step: nothing is set aside by the step
    check, only the missing image is a bad frame, and the two positions lacking a side
    camera's own frame trust nothing there (section 23)."""
    import shutil

    import pandas as pd

    from predisat.reconstruct.batch import process_survey

    survey = tmp_path / "survey"
    shutil.copytree(rendered, survey)
    for image in (survey / "images").iterdir():  # no capture times: the step check alone
        image.write_bytes(_without_exif(image.read_bytes()))
    man = pd.read_csv(survey / "manifest.csv")
    (survey / "images" / "right_000010.jpg").unlink()
    (survey / "images" / "left_000020.jpg").unlink()
    man[man.frame_id != "right_000010"].to_csv(survey / "manifest.csv", index=False)
    got = process_survey(survey, tmp_path / "out", progress=False)
    assert got.masks.provenance["step_check"]["left/right"]["off_step"] == []
    assert [b.frame_id for b in got.bad_frames] == ["left_000020"]
    assert got.bad_frames[0].stage != "step"
    assert "out of step" not in capsys.readouterr().err
    lost = man.chainage_m[man.frame_id.isin(["right_000010", "left_000020"])]
    assert got.masks.provenance["positions_lacking_side"] == pytest.approx(sorted(lost))


def test_capture_times_set_aside_exactly_the_images_off_their_rows(rendered, tmp_path,
                                                                   capsys) -> None:  # fmt: skip
    """The same survey with the cameras' capture times (EXIF, written by the renderer with
    a clock offset, drift and scatter): in step, both cameras are checked and nothing is set
    aside; with the dropped image, the moved rows of the right camera, and only those, are
    set aside before the segmentation, and process and the report say so."""
    import shutil

    import pandas as pd

    from predisat.availability.run import lacking_side_notes, step_notes
    from predisat.reconstruct.batch import process_survey

    survey = tmp_path / "survey"
    shutil.copytree(rendered, survey)
    ok = process_survey(survey, tmp_path / "ok", progress=False)
    assert all(v["checked"] and v["off"] == [] for v in
               ok.masks.provenance["capture_check"].values())  # fmt: skip
    assert ok.bad_frames == ()
    assert "capture" not in capsys.readouterr().err

    moved = _drop_right_image(survey)
    got = process_survey(survey, tmp_path / "late", progress=False)
    set_aside = {b.frame_id for b in got.bad_frames if b.stage == "capture"}
    assert set_aside == moved
    runs = got.masks.provenance["capture_check"]["right"]["off"]
    assert set().union(*(r["frames"] for r in runs)) == moved
    # the last moved row holds the image of the row the manifest lost: no row has its time
    assert [r["lag"] for r in runs] == [1, None] and len(runs[1]["frames"]) == 1
    assert got.masks.provenance["capture_check"]["left"]["off"] == []
    # the images set aside are not compared again, so the cameras are in step elsewhere
    assert got.masks.provenance["step_check"]["left/right"]["off_step"] == []
    err = capsys.readouterr().err
    assert "right camera's images from chainage" in err and "row 1 after its own" in err
    assert any("capture times" in n for n in step_notes(got.masks.provenance))
    # the positions of the frames set aside, and the last one whose right row the manifest
    # lost, lack the right camera's own frame: said, and they trust no satellite (section 23)
    man = pd.read_csv(survey / "manifest.csv")
    gone = sorted([*man.chainage_m[man.frame_id.isin(moved)], man.chainage_m.max()])
    lacking = got.masks.provenance["positions_lacking_side"]
    assert lacking == pytest.approx(gone)
    assert "lack a side camera's own frame" in err
    at = np.isin(np.round(got.masks.chainage_m, 3), np.round(gone, 3))
    assert np.all(got.masks.mask_el_deg[at] >= 89.9)
    assert lacking_side_notes(got.masks.provenance)
    assert lacking_side_notes(ok.masks.provenance) == []


def _without_exif(jpeg: bytes) -> bytes:
    """A JPEG's bytes without its APP1 (EXIF) segments."""
    out, at = [jpeg[:2]], 2
    while jpeg[at] == 0xFF and jpeg[at + 1] not in (0xDA, 0xD9):  # markers before the scan
        size = int.from_bytes(jpeg[at + 2 : at + 4], "big")
        if jpeg[at + 1] != 0xE1:
            out.append(jpeg[at : at + 2 + size])
        at += 2 + size
    return b"".join(out) + jpeg[at:]


def test_frames_pair_by_the_nearest_time_within_half_the_local_gap() -> None:
    from predisat.reconstruct.batch import nearest_in_time

    # slow then fast (a fourfold speed change): one tolerance for the survey merged the fast
    # frames; the other camera 0.3 gap late in the slow part and 10 ms in the fast part
    ta = np.concatenate([np.arange(0.0, 12.0, 1.2), 12.0 + np.arange(10) * 0.277])
    tb = np.concatenate([np.arange(0.0, 12.0, 1.2) + 0.36, 12.0 + np.arange(10) * 0.277 + 0.01])
    np.testing.assert_array_equal(nearest_in_time(ta, tb), np.arange(20))
    # the other camera missed frames 3 and 7: those have no partner, the rest keep theirs
    keep = np.setdiff1d(np.arange(20), [3, 7])
    got = nearest_in_time(ta, tb[keep])
    assert got[3] == -1 and got[7] == -1
    np.testing.assert_array_equal(keep[got[got >= 0]], np.setdiff1d(np.arange(20), [3, 7]))
    assert nearest_in_time(ta, np.zeros(0)).tolist() == [-1] * 20


def test_missing_frames_do_not_push_the_lag_off_zero() -> None:
    """A camera's frame missing (NaN at lag 0, the others defined) is no evidence against
    lag 0 (a review: the worst-of-the-rest fill called an honest survey missing every fifth
    frame off step)."""
    rng = np.random.default_rng(2)
    d = 0.03 + 0.01 * rng.random((150, 7))
    d[::5, 3] = np.nan
    assert not np.any(step_lags(d, 0.3))


def test_a_stretch_is_widened_until_lag_zero_is_confirmed() -> None:
    rng = np.random.default_rng(5)
    d = 0.05 + 0.002 * rng.random((100, 7))  # no evidence anywhere...
    d[:20, np.arange(7) != 3] += 0.03  # ... but in step (lag 0 clearly best) up to 20
    d[50:70, np.arange(7) != 4] += 0.03  # and 1 late clearly from 50 to 70
    runs = off_step(step_lags(d, 0.3))
    assert runs and all(r.lag == 1 for r in runs)
    (wide,) = {(r.first, r.last) for r in widen(d, runs, 0.3)}
    # back over the positions without evidence and into the in-step ones until they confirm
    # lag 0 by the change cost (0.3: ten positions 0.03 better), and on to the end (nothing
    # confirms lag 0 after the stretch)
    assert 9 <= wide[0] <= 11 and wide[1] == 99


def test_process_says_when_no_two_cameras_can_be_compared(capsys) -> None:
    from predisat.availability.run import step_notes
    from predisat.reconstruct.batch import _step_warnings

    pinhole = {"left/right": {"compared": False, "why": "0 shared directions (fewer than 50)"}}
    (line,) = _step_warnings(pinhole)
    assert "was not checked" in line
    assert _step_warnings({}) == [line]
    assert "could not be checked" in step_notes({"step_check": pinhole})[0]
    assert step_notes({}) == []


def test_process_merges_the_frames_of_a_stop(rendered, tmp_path, capsys) -> None:
    """A stop captured on time: two more frames per camera at one position (the same pictures,
    0.3 and 0.6 s later). ``process`` merges each camera's three into one view (section 24):
    the same masks and support as the survey without them; with ``stop_gap_m`` in the run's
    provenance (a resume key), and the chunk counting every frame it read."""
    import json
    import shutil

    import pandas as pd

    from predisat.reconstruct.batch import process_survey

    survey = tmp_path / "survey"
    shutil.copytree(rendered, survey)
    for image in (survey / "images").iterdir():  # the copies' capture times would be wrong
        image.write_bytes(_without_exif(image.read_bytes()))
    base = process_survey(survey, tmp_path / "base", progress=False)
    man = pd.read_csv(survey / "manifest.csv")
    at = man.chainage_m.unique()[len(man.chainage_m.unique()) // 2]
    extra = []
    for k, dt in ((1, 0.3), (2, 0.6)):
        rows = man[man.chainage_m == at].copy()
        for i in rows.index:
            src = survey / rows.at[i, "image"]
            dst = src.with_name(f"{src.stem}_stop{k}{src.suffix}")
            # the same picture (a stop) in a file of its own: a JPEG comment segment, as a
            # camera's frame counter would write; a byte-identical file reads as frozen
            jpeg = src.read_bytes()
            note = f"stop frame {k}".encode()
            com = b"\xff\xfe" + (len(note) + 2).to_bytes(2, "big") + note
            dst.write_bytes(jpeg[:2] + com + jpeg[2:])
            rows.at[i, "image"] = str(dst.relative_to(survey))
            rows.at[i, "frame_id"] = f"{rows.at[i, 'frame_id']}/stop{k}"
        rows["gps_s"] += dt
        extra.append(rows)
    pd.concat([man, *extra]).sort_values(["gps_s", "side"]).to_csv(
        survey / "manifest.csv", index=False
    )
    capsys.readouterr()
    got = process_survey(survey, tmp_path / "stop", progress=False)
    assert got.bad_frames == ()
    err = capsys.readouterr().err
    assert "the left camera has 3 frames merged into 1 view(s)" in err
    assert "the right camera has 3 frames merged into 1 view(s)" in err
    assert got.masks.provenance["params"]["stop_gap_m"] == PipelineParams().stop_gap_m
    np.testing.assert_array_equal(got.masks.mask_el_deg, base.masks.mask_el_deg)
    np.testing.assert_array_equal(got.masks.support, base.masks.support)
    markers = [json.loads(p.read_text()) for p in (tmp_path / "stop").rglob("*.json")
               if "n_frames" in p.read_text()]  # fmt: skip
    assert markers and sum(m["n_frames"] for m in markers) >= len(man) + 2 * len(extra[0])
