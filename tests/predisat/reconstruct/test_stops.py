"""The frames of a stop merged into one view (``predisat.reconstruct.stops``).

Safety on a ray-cast scene is in ``test_fusion.py`` (a stop beside the wall); here the rules:
which frames are one stop, and what the merged frame says.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from predisat.camera.models import CameraModel, Mount
from predisat.reconstruct.carving import FrameView
from predisat.reconstruct.params import PipelineParams
from predisat.reconstruct.stops import merge_stop_frames, stop_counts, stop_groups, stop_ids

CAM = CameraModel.fisheye_from_fov(40, 30, 185.0)


def _frame(s_m: float, side: str = "left", fid: str = "", **kw) -> FrameView:
    sky = np.zeros(CAM.shape, bool)
    sky[:10] = True
    args = dict(
        chainage_m=s_m, sky_mask=sky, camera=CAM, mount=Mount.default(side),
        antenna_enu_m=np.array([0.0, s_m, 4.0]), heading_deg=0.0, frame_id=fid or f"{s_m}{side}",
    )
    return FrameView(**{**args, **kw})


def test_frames_of_one_camera_within_the_gap_are_one_stop() -> None:
    fr = [_frame(0.0), _frame(10.0), _frame(10.0), _frame(10.3), _frame(10.7), _frame(20.0),
          _frame(10.1, "right"), _frame(10.1, "right"), _frame(10.2, view_group="lens")]
    # 10.0-10.7 chain (steps <= 0.5 m), spreading 0.7 m: within a span of 1 m, one stop
    whole = [[0], [1, 2, 3, 4], [5], [6, 7], [8]]
    assert sorted(map(sorted, stop_groups(fr, 0.5, 1.0))) == whole
    # over the default span of 0.5 m: cut in two slices of 0.35 m
    groups = stop_groups(fr, 0.5)
    assert sorted(map(sorted, groups)) == [[0], [1, 2, 3], [4], [5], [6, 7], [8]]
    # 0: the same chainage only
    assert sorted(map(sorted, stop_groups(fr, 0.0))) == [[0], [1, 2], [3], [4], [5], [6, 7], [8]]
    # a window that lacks the stop's neighbours or its first frames splits nothing else
    part = [fr[i] for i in (2, 3, 4, 5)]
    assert sorted(map(sorted, stop_groups(part, 0.5, 1.0))) == [[0, 1, 2], [3]]
    with pytest.raises(ValueError, match="gap_m"):
        stop_groups(fr, -1.0)
    with pytest.raises(ValueError, match="span_m"):
        stop_groups(fr, 0.5, 0.4)
    # the same chains from a survey's columns, counted for the run's report
    side = [f.mount.side for f in fr[:8]]
    s = [f.chainage_m for f in fr[:8]]
    assert stop_counts(side, s, 0.5, 1.0) == {"left": (4, 1), "right": (2, 1)}
    assert stop_counts(side, s, 0.5) == {"left": (3, 1), "right": (2, 1)}
    assert stop_counts(side, s, 0.0) == {"left": (2, 1), "right": (2, 1)}
    assert stop_counts(["left"], [3.0], 0.5) == {}


def test_a_merged_frame_is_sky_only_where_every_frame_saw_sky() -> None:
    rng = np.random.default_rng(0)
    skies = [rng.random(CAM.shape) < 0.7 for _ in range(3)]
    thins = [rng.random(CAM.shape) < 0.1 for _ in range(3)]
    confs = [rng.random(CAM.shape[1]) for _ in range(3)]
    fr = [_frame(50.0 + 0.1 * k, fid=f"f{k}", sky_mask=skies[k], thin_mask=thins[k] & skies[k],
                 confidence=confs[k], attitude_doubt_deg=0.1 * k, along_doubt_m=0.2)
          for k in range(3)]
    before = [f.sky_mask.copy() for f in fr]
    (m,) = merge_stop_frames(fr, 0.5)
    np.testing.assert_array_equal(m.sky_mask, skies[0] & skies[1] & skies[2])
    thin = (thins[0] & skies[0]) | (thins[1] & skies[1]) | (thins[2] & skies[2])
    np.testing.assert_array_equal(m.thin_mask, thin & m.sky_mask)
    np.testing.assert_array_equal(m.confidence, np.minimum(np.minimum(confs[0], confs[1]),
                                                           confs[2]))
    # it stands at the middle frame (section 24: about the first, its box reached 0.2 m behind
    # where no frame stood)
    assert m.chainage_m == 50.1 and m.frame_id == "f0..f2 (stop, 3 frames)"
    # the antennas 0.1 m either side of it along the track, the mounts equal: the along doubt
    # grows by 0.1 m, the across and height doubts not at all
    assert m.along_doubt_m == pytest.approx(0.3)
    assert m.across_doubt_m == pytest.approx(0.0) and m.height_doubt_m == pytest.approx(0.0)
    assert m.attitude_doubt_deg == pytest.approx(0.2)
    assert all(np.array_equal(f.sky_mask, b) for f, b in zip(fr, before, strict=True))
    # single frames come back as they are
    lone = [_frame(0.0), _frame(10.0)]
    assert all(a is b for a, b in zip(merge_stop_frames(lone, 0.5), lone, strict=True))


def test_the_attitude_doubt_grows_by_the_turn_between_the_poses() -> None:
    left = Mount.default("left")
    a = _frame(5.0, fid="a")
    b = _frame(5.0, fid="b", mount=left.on_vehicle(1.5, -0.8), heading_deg=0.7)
    (m,) = merge_stop_frames([a, b], 0.5)
    ra = left.camera_to_enu(0.0)
    rb = b.mount.camera_to_enu(0.7)
    turn = np.degrees(Rotation.from_matrix(ra.T @ rb).magnitude())
    assert turn > 1.0
    assert m.attitude_doubt_deg == pytest.approx(turn, abs=1e-6)
    # the cameras' centres moved with the turn (the lever arm): the position doubts too, per
    # axis of the first frame's level vehicle frame (x the heading, y left)
    ca = left.camera_position_enu(a.antenna_enu_m, 0.0)
    cb = b.mount.camera_position_enu(b.antenna_enu_m, 0.7)
    off = np.abs([cb[1] - ca[1], -(cb[0] - ca[0]), cb[2] - ca[2]])  # heading 0: north, west, up
    assert off.max() > 0.01
    assert [m.along_doubt_m, m.across_doubt_m, m.height_doubt_m] == pytest.approx(off)


def test_frames_driven_the_other_way_are_not_one_stop() -> None:
    """Two passes over one place, one in each direction: the left camera looks at the other
    side of the track on the second; merged, the 180 deg turn eroded all of its sky (a
    review)."""
    fr = [_frame(100.0), _frame(100.2, reverse=True)]
    assert sorted(map(sorted, stop_groups(fr, 0.5))) == [[0], [1]]
    assert all(a is b for a, b in zip(merge_stop_frames(fr, 0.5), fr, strict=True))


def test_a_crawl_on_a_curve_holds_every_frames_own_box() -> None:
    """A crawl of 200 frames 0.45 m apart turning 0.05 deg a frame, each frame's chainage known
    within 3 m: the merged box holds every frame's camera centre with its own box turned into
    the reference (middle) frame's axes (checked on the corners of each box); nothing moved
    up."""
    def at(k: int) -> FrameView:
        hd = 0.05 * k
        # on a circle of radius 0.45 / radians(0.05) m: heading hd, a point every 0.45 m
        r = 0.45 / np.radians(0.05)
        pos = np.array([r * (1 - np.cos(np.radians(hd))), r * np.sin(np.radians(hd)), 4.0])
        return _frame(100.0 + 0.45 * k, fid=f"c{k}", heading_deg=hd, antenna_enu_m=pos,
                      along_doubt_m=3.0, across_doubt_m=0.2, height_doubt_m=0.1)

    fr = [at(k) for k in range(200)]
    (m,) = merge_stop_frames(fr, 0.5, 100.0)  # a span that holds the whole crawl
    ref = next(f for f in fr if f.frame_id == f"c{round((m.chainage_m - 100.0) / 0.45)}")
    assert ref.chainage_m == m.chainage_m and abs(m.chainage_m - (100.0 + 0.45 * 99.5)) < 0.3
    h0 = np.radians(ref.heading_deg)
    fwd, left = np.array([np.sin(h0), np.cos(h0), 0.0]), np.array([-np.cos(h0), np.sin(h0), 0.0])
    c0 = ref.mount.camera_position_enu(ref.antenna_enu_m, ref.heading_deg)
    half = np.array([m.along_doubt_m, m.across_doubt_m, m.height_doubt_m])
    for f in fr:
        h = np.radians(f.heading_deg)
        fw, lf = np.array([np.sin(h), np.cos(h), 0.0]), np.array([-np.cos(h), np.sin(h), 0.0])
        c = f.mount.camera_position_enu(f.antenna_enu_m, f.heading_deg)
        for sa, sc, sh in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T:
            corner = c + sa * 3.0 * fw + sc * 0.2 * lf + sh * 0.1 * np.array([0, 0, 1.0]) - c0
            got = np.abs([corner @ fwd, corner @ left, corner[2]])
            assert np.all(got <= half + 1e-9), (f.frame_id, got, half)
    assert m.height_doubt_m == pytest.approx(0.1)
    assert m.across_doubt_m < 0.3 * m.along_doubt_m


def test_a_crawl_is_cut_into_slices_and_a_standstill_stays_whole() -> None:
    """A chain spreading over more than the span (a crawl into a stop and out of it) is cut
    into equal slices spreading at most the span; the frames of the standstill stay one view,
    also when their chainages jitter by a decimetre (a projected GNSS position's noise: a
    review found a span equal to the 0.2 m gap cut such a stop of 60 frames into 6 views)."""
    approach = [9.0, 9.3, 9.55, 9.75, 9.9]
    stand = [10.0, 10.0, 10.01, 10.02, 10.0]
    leave = [10.2, 10.45, 10.75, 11.1]
    s = approach + stand + leave
    fr = [_frame(x, fid=f"f{k}") for k, x in enumerate(s)]
    for span in (0.5, 1.0):
        groups = stop_groups(fr, 0.5, span)
        assert sorted(i for g in groups for i in g) == list(range(len(s)))
        assert all(np.ptp([s[i] for i in g]) <= span for g in groups)
        (home,) = [g for g in groups if 5 in g]
        assert set(range(5, 10)) <= set(home)  # the standstill whole
    # a crawl, steps under the gap: no piece spreads over the span, none merged whole
    crawl = [_frame(0.15 * k, fid=f"c{k}") for k in range(40)]
    pieces = stop_groups(crawl, 0.2)
    assert all(np.ptp([0.15 * i for i in g]) <= 1.0 for g in pieces) and len(pieces) >= 6
    # a stop of 60 frames whose chainages jitter (a projected GNSS position): by default one
    # view at 5 cm (sigma), at most two large ones at 10 cm; cutting at the widest steps had
    # shaved its outliers off as single frames, views of their own again
    p = PipelineParams()
    for seed in range(20):
        for sigma, most in ((0.05, 1), (0.1, 2)):
            jitter = np.random.default_rng(seed).normal(500.0, sigma, 60)
            stop = [_frame(float(x), fid=f"j{k}") for k, x in enumerate(jitter)]
            groups = stop_groups(stop, p.stop_gap_m, p.stop_span_m)
            assert len(groups) <= most and min(map(len, groups)) >= 5, (seed, sigma)


def test_a_window_merges_a_crawl_as_the_whole_survey_does() -> None:
    """A review: a chunk's window holding part of a crawl sliced it otherwise than the whole
    survey (equal slices of the part's spread), so a position's views depended on where the
    chunks fell. Given the survey's view ids, a window's groups are the survey's."""
    s = [0.1 * k for k in range(40)]  # 3.9 m of crawl: eight slices of 0.4875 m
    crawl = [_frame(x, fid=f"c{k}") for k, x in enumerate(s)]
    ids = stop_ids(["left"] * len(s), s, 0.2)
    whole = stop_groups(crawl, 0.2)
    assert [sorted(g) for g in whole] == [sorted(np.flatnonzero(ids == v)) for v in np.unique(ids)]
    part = list(range(13, 40))  # a window from 1.3 m: 2.6 m, chained alone in six slices
    alone = stop_groups([crawl[i] for i in part], 0.2)
    given = stop_groups([crawl[i] for i in part], 0.2, view_ids=ids[part].tolist())
    in_survey = [[i for i in g if i in part] for g in whole]
    assert sorted([part[i] for i in g] for g in given) == sorted(g for g in in_survey if g)
    assert sorted([part[i] for i in g] for g in alone) != sorted(g for g in in_survey if g)
    merged = merge_stop_frames([crawl[i] for i in part], 0.2, view_ids=ids[part].tolist())
    assert len(merged) == len([g for g in in_survey if g])
    with pytest.raises(ValueError, match="view_ids"):
        stop_groups(crawl, 0.2, view_ids=[0, 1])


def test_process_takes_the_stop_gap_and_refuses_one_too_long(tmp_path) -> None:
    from predisat.cli.app import build_parser
    from predisat.cli.process import attitude_params

    parser = build_parser()
    cmd = ["process", str(tmp_path), "--out", str(tmp_path / "o")]
    args = parser.parse_args([*cmd, "--stop-gap-m", "1.5"])
    assert attitude_params(args)["stop_gap_m"] == 1.5
    assert attitude_params(parser.parse_args(cmd))["stop_gap_m"] == PipelineParams().stop_gap_m
    with pytest.raises(SystemExit):
        parser.parse_args([*cmd, "--stop-gap-m", "7"])
    # the span: the library's by default, the gap's when that is larger, never under it
    assert attitude_params(args)["stop_span_m"] == 1.5
    got = attitude_params(parser.parse_args(cmd))["stop_span_m"]
    assert got == PipelineParams().stop_span_m
    assert attitude_params(parser.parse_args([*cmd, "--stop-span-m", "2"]))["stop_span_m"] == 2.0
    from predisat.cli.common import CliError

    with pytest.raises(CliError, match=r"--stop-span-m 0\.1 is under --stop-gap-m 0\.2"):
        attitude_params(parser.parse_args([*cmd, "--stop-span-m", "0.1"]))
    PipelineParams(stop_gap_m=1.5, stop_span_m=1.5)
    with pytest.raises(ValueError, match="stop_span_m"):
        PipelineParams(stop_gap_m=1.5, stop_span_m=1.0)


def test_a_camera_frozen_through_a_crawl_is_caught(tmp_path) -> None:
    """A review: frames within stop_gap_m of the one before were never compared by the frozen
    check (a stop's frames are merged), but a crawl is cut into views of their own: a camera
    frozen through a crawl 0.15 m a frame gave its stale picture to 24 views over 6 m. Now
    only frames of one stop go uncompared; after a frozen frame, every frame is compared."""
    from types import SimpleNamespace

    import cv2

    from predisat.reconstruct.batch import _frozen_frames

    pic = np.random.default_rng(0).integers(0, 256, (120, 160, 3), np.uint8)
    cv2.imwrite(str(tmp_path / "a.png"), pic)
    n = 40
    frames = SimpleNamespace(
        side=np.array(["left"] * n), chainage_m=1000.0 + 0.15 * np.arange(n),
        image=np.array(["a.png"] * n), frame_id=np.array([f"f{i}" for i in range(n)]),
        row=np.arange(2, n + 2),
    )  # fmt: skip
    plan = SimpleNamespace(survey=SimpleNamespace(frames=frames, root=tmp_path,
                                                  storage_options=None),
                           params=PipelineParams())  # fmt: skip
    p = PipelineParams()
    stop = stop_ids(frames.side, frames.chainage_m, p.stop_gap_m, p.stop_span_m)
    assert 1 < int((stop == 0).sum()) <= 1 + p.stop_span_m / 0.15  # the first stop: fine
    assert sorted(_frozen_frames(plan, np.arange(n))) == np.flatnonzero(stop != 0).tolist()
    # a standing train's frames (one stop) show one picture and are not frozen
    frames.chainage_m = 1000.0 + 0.01 * (np.arange(n) % 3)
    assert _frozen_frames(plan, np.arange(n)) == {}
    # a train that stops 10 m on, its camera frozen since the stop before: the second stop's
    # frames are all frozen, whichever of them a (resumed) run still needs (a review: a
    # pending chunk holding only the stop's later frames never compared them)
    frames.chainage_m = np.where(np.arange(n) < 20, 1000.0, 1010.0) + 0.01 * (np.arange(n) % 3)
    whole = _frozen_frames(plan, np.arange(n))
    assert sorted(whole) == list(range(20, n))
    assert sorted(_frozen_frames(plan, np.arange(30, n))) == list(range(30, n))
    assert _frozen_frames(plan, np.arange(30, n)) == {i: whole[i] for i in range(30, n)}


def test_a_frame_off_the_track_stands_alone() -> None:
    """A review: a NaN chainage (a frame off the track) made the equal slices' count NaN and
    stop_ids / stop_counts raised (before the cut, it stood alone)."""
    s = [1000.0, 1000.1, float("nan"), float("nan"), 1005.0]
    assert stop_ids(["left"] * 5, s, 0.2).tolist() == [0, 0, 2, 3, 4]
    assert stop_counts(["left"] * 5, s, 0.2) == {"left": (2, 1)}


def test_the_frozen_check_slices_a_crawl_as_the_chunks_merge_it(tmp_path) -> None:
    """A review (hW): the chunks merge frames by stop_ids of the run's chainages, rounded to
    the millimetre (process_survey's ``ch``, ChunkFrame.view_id), but the frozen check sliced
    the manifest's unrounded ones. On this crawl (0.05-0.2 m a frame) the two slicings differ
    (a step of 0.1995 m rounds to 0.2000000000000455 > stop_gap_m, and every slice moves):
    frames 3 and 4 start a view of their own in the merge, yet the check took them for frames
    of frame 0's stop and never compared them, so a camera frozen since frame 0 gave its stale
    picture to that view."""
    from types import SimpleNamespace

    import cv2

    from predisat.reconstruct.batch import _frozen_frames

    pic = np.random.default_rng(0).integers(0, 256, (120, 160, 3), np.uint8)
    cv2.imwrite(str(tmp_path / "a.png"), pic)
    s = np.array([1000.1101962429958, 1000.2837493220619, 1000.394526048275, 1000.5001240718589,
                  1000.5700273057664, 1000.7503270423688, 1000.8507420195306, 1000.9977458118068,
                  1001.1253212517541, 1001.3248472408441, 1001.41319089998, 1001.545915478074])
    n = s.size
    frames = SimpleNamespace(
        side=np.array(["left"] * n), chainage_m=s, image=np.array(["a.png"] * n),
        frame_id=np.array([f"f{i}" for i in range(n)]), row=np.arange(2, n + 2),
    )  # fmt: skip
    ch = np.round(s, 3)  # as process_survey gives the plan and the chunks
    plan = SimpleNamespace(survey=SimpleNamespace(frames=frames, root=tmp_path,
                                                  storage_options=None),
                           params=PipelineParams(), chainage_m=ch)  # fmt: skip
    p = PipelineParams()
    merged = stop_ids(frames.side, ch, p.stop_gap_m, p.stop_span_m)  # the chunks' view ids
    assert merged.tolist() != stop_ids(frames.side, s, p.stop_gap_m, p.stop_span_m).tolist()
    # every frame after the merge's first view shows frame 0's picture: all are frozen
    assert sorted(_frozen_frames(plan, np.arange(n))) == np.flatnonzero(merged != 0).tolist()


def test_the_frozen_check_keeps_no_picture_of_a_stop_it_has_left(tmp_path, monkeypatch) -> None:
    """A review (hW): the frozen check keeps each decoded picture for the next frame's
    comparison, but the next frame of a stop is not compared, so the picture of every stop's
    first frame stayed in memory to the end of the check: one quarter-size picture per stop
    (1440 x 720 bytes for a 5.7K 360 camera; 10 000 stops, 10 GB)."""
    from types import SimpleNamespace

    import cv2

    from predisat.reconstruct import batch

    rng = np.random.default_rng(0)
    n_stops, per = 30, 3
    n = n_stops * per
    for i in range(n):
        cv2.imwrite(str(tmp_path / f"{i}.png"), rng.integers(0, 256, (40, 40, 3), np.uint8))
    frames = SimpleNamespace(
        side=np.array(["left"] * n),
        chainage_m=1000.0 + 10.0 * (np.arange(n) // per) + 0.01 * (np.arange(n) % per),
        image=np.array([f"{i}.png" for i in range(n)]),
        frame_id=np.array([f"f{i}" for i in range(n)]), row=np.arange(2, n + 2),
    )  # fmt: skip
    plan = SimpleNamespace(survey=SimpleNamespace(frames=frames, root=tmp_path,
                                                  storage_options=None),
                           params=PipelineParams(), chainage_m=frames.chainage_m)  # fmt: skip
    held = []
    real = batch._same_picture

    def spy(a, b, thumbs, opts):
        held.append(len(thumbs))
        return real(a, b, thumbs, opts)

    monkeypatch.setattr(batch, "_same_picture", spy)
    assert batch._frozen_frames(plan, np.arange(n)) == {}
    assert len(held) == n_stops - 1  # each stop's first frame against the stop before
    assert max(held) <= 1, held  # at most the picture the next comparison needs
    # two cameras, frames interleaved, no stop: each camera's previous picture is kept for
    # its next comparison (decoded once), and no more than one per camera
    frames.side = np.array(["left", "right"] * (n // 2))
    frames.chainage_m = 1000.0 + 10.0 * (np.arange(n) // 2)
    ready = []

    def spy2(a, b, thumbs, opts):
        ready.append((b in thumbs, len(thumbs)))
        return real(a, b, thumbs, opts)

    monkeypatch.setattr(batch, "_same_picture", spy2)
    assert batch._frozen_frames(plan, np.arange(n)) == {}
    assert len(ready) == n - 2 and all(r for r, _ in ready[2:])  # the first per camera aside
    assert max(k for _, k in ready) <= 2
