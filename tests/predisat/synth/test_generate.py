"""End-to-end: a tiny synthetic survey loads as a valid survey and has matching ground truth."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from predisat.camera.models import CameraModel
from predisat.gnss.sun import sun_azel
from predisat.masks.truth import TrueMasks
from predisat.survey import Survey
from predisat.synth.generate import (
    contact_sheet,
    daytime_gps_s,
    generate_survey,
    sky_schedule,
)
from predisat.synth.render import RenderOptions
from predisat.synth.world import World
from predisat.track.map import demo_track

CAM = CameraModel.pinhole_from_fov(160, 120, 74.0, dist=(-0.05, 0.01, 0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("synth")
    track = demo_track()
    res = generate_survey(
        track,
        2000.0,
        2060.0,
        sky="cloudy",
        seed=3,
        out_dir=out,
        camera=CAM,
        progress=False,
        options=RenderOptions(supersample=2, ambient_rays=1),
    )
    return track, res


def test_survey_loads_and_matches_positions(tiny) -> None:
    track, res = tiny
    survey = Survey.load(res.survey_dir)
    n_pos = 7  # 2000, 2010, ..., 2060
    assert res.n_positions == n_pos and res.n_frames == 2 * n_pos
    assert len(survey.frames) == 2 * n_pos
    assert sorted(set(survey.frames.side)) == ["left", "right"]
    ch = np.sort(np.unique(survey.frames.chainage_m))
    assert np.allclose(ch, np.arange(2000.0, 2061.0, 10.0))
    # the manifest positions are the antennas: on the track axis, 4 m up
    proj = track.project(survey.frames.lat_deg, survey.frames.lon_deg)
    assert np.allclose(proj.chainage_m, survey.frames.chainage_m, atol=0.05)
    assert np.all(np.abs(proj.offset_m) < 0.05)
    img = survey.read_image(0)
    assert img.shape == (CAM.height_px, CAM.width_px, 3)


def test_truth_labels_and_masks_match_the_frames(tiny) -> None:
    _, res = tiny
    survey = Survey.load(res.survey_dir)
    labels = sorted((res.truth_dir / "labels").glob("*.png"))
    assert [p.stem for p in labels] == sorted(str(f) for f in survey.frames.frame_id)
    for p in labels:
        lab = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        assert lab.shape == (CAM.height_px, CAM.width_px) and lab.dtype == np.uint8
        assert set(np.unique(lab).tolist()) <= {0, 128, 255}
    masks = TrueMasks.load(res.truth_dir / "true_masks.npz")
    assert np.allclose(masks.chainage_m, np.arange(2000.0, 2061.0, 10.0))
    assert masks.mask_el_deg.shape[0] == res.n_positions
    world = World.load(res.truth_dir / "world.npz")
    assert world.faces.shape[0] > 0
    with open(res.truth_dir / "frames.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == res.n_frames and {r["sky"] for r in rows} == {"cloudy"}
    assert (res.truth_dir / "README.txt").read_text().count("labels/") >= 1


def test_label_sky_agrees_with_image_brightness(tiny) -> None:
    # not a segmentation benchmark: only that labels and images are the same frame (sky pixels
    # of a cloudy-sky frame are on average brighter than obstacle pixels)
    _, res = tiny
    survey = Survey.load(res.survey_dir)
    checked = 0
    for k, fid in enumerate(survey.frames.frame_id):
        lab = cv2.imread(str(res.truth_dir / "labels" / f"{fid}.png"), cv2.IMREAD_UNCHANGED)
        sky, obst = lab == 255, lab == 0
        if sky.mean() < 0.1 or obst.mean() < 0.1:
            continue
        grey = cv2.cvtColor(survey.read_image(k), cv2.COLOR_BGR2GRAY).astype(float)
        assert grey[sky].mean() > grey[obst].mean()
        checked += 1
    assert checked >= 1


def test_contact_sheet(tiny, tmp_path: Path) -> None:
    _, res = tiny
    out = contact_sheet(
        res.survey_dir, tmp_path / "sheet.png", n_frames=6, columns=3, tile_width_px=120
    )
    sheet = cv2.imread(str(out))
    assert sheet.shape == (2 * 90, 3 * 120, 3)


def test_daytime_start_has_the_sun_up() -> None:
    lon = 4.7
    gps = daytime_gps_s(lon, "2024-06-21", 12.0)
    az, el = sun_azel(gps, 50.5, lon)
    # local solar noon in June at 50.5 N: sun due south at about 90 - 50.5 + 23.4 deg
    assert abs(((az - 180.0 + 180.0) % 360.0) - 180.0) < 5.0
    assert el == pytest.approx(90.0 - 50.5 + 23.44, abs=0.6)


def test_sky_schedule() -> None:
    s = np.arange(0.0, 2000.0, 10.0)
    cond, ids = sky_schedule("mixed", s, seed=1)
    assert cond.shape == s.shape and len(set(cond.tolist())) >= 2
    changes = np.flatnonzero(cond[1:] != cond[:-1])
    assert changes.size >= 3
    assert np.all(np.diff(s[changes]) >= 150.0)  # each condition lasts 150-400 m
    assert np.all(np.diff(ids) >= 0)
    assert set(sky_schedule("overcast", s[:5])[0].tolist()) == {"overcast"}
    with pytest.raises(ValueError, match="sky"):
        sky_schedule("foggy", s)


def test_rejects_range_outside_track(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="track length"):
        generate_survey(demo_track(), 100.0, 1e7, out_dir=tmp_path, progress=False)


def test_output_does_not_depend_on_worker_count(tiny, tmp_path: Path) -> None:
    track, res = tiny
    par = generate_survey(
        track,
        2000.0,
        2060.0,
        sky="cloudy",
        seed=3,
        out_dir=tmp_path,
        camera=CAM,
        progress=False,
        options=RenderOptions(supersample=2, ambient_rays=1),
        workers=2,
    )
    serial_images = sorted((res.survey_dir / "images").glob("*.jpg"))
    assert [p.name for p in serial_images] == sorted(
        p.name for p in (par.survey_dir / "images").glob("*.jpg")
    )
    for p in serial_images:
        assert p.read_bytes() == (par.survey_dir / "images" / p.name).read_bytes(), p.name
    for p in sorted((res.truth_dir / "labels").glob("*.png")):
        assert p.read_bytes() == (par.truth_dir / "labels" / p.name).read_bytes(), p.name


def test_rig_renders_every_camera_with_labels_matching_the_ideal_masks(tmp_path: Path) -> None:
    from predisat.camera.models import Mount
    from predisat.camera.rigs import Rig
    from predisat.synth.truth import ideal_sky_mask

    pano = CameraModel.equirect(128)
    cab = CameraModel.fisheye_from_fov(64, 48, 120.0)
    rig = Rig("test", (("roof", pano, Mount.default("roof")),
                       ("front", cab, Mount.default("front"))))  # fmt: skip
    res = generate_survey(
        demo_track(), 2000.0, 2010.0, sky="clear", seed=4, out_dir=tmp_path, rig=rig,
        progress=False, options=RenderOptions(supersample=1, ambient_rays=0),
    )  # fmt: skip
    survey = Survey.load(res.survey_dir)
    assert res.n_frames == 4 and sorted(set(survey.frames.side)) == ["front", "roof"]
    assert survey.cameras["roof"].camera == pano
    assert survey.metadata["rig"] == "test"
    world = World.load(res.truth_dir / "world.npz")
    for k, fid in enumerate(survey.frames.frame_id):
        side = str(survey.frames.side[k])
        cam, mount = rig.as_mapping()[side]
        lab = cv2.imread(str(res.truth_dir / "labels" / f"{fid}.png"), cv2.IMREAD_UNCHANGED)
        ideal = ideal_sky_mask(world, [float(survey.frames.chainage_m[k])], cam, mount)[0]
        # the renderer's label and the truth module's mask: the same rays, thin wires aside
        assert float(np.mean((lab > 0) == ideal)) > 0.99
        assert survey.read_image(k).shape == (cam.height_px, cam.width_px, 3)
    with pytest.raises(ValueError, match="either rig or camera"):
        generate_survey(demo_track(), 2000.0, 2010.0, out_dir=tmp_path / "x", rig=rig,
                        camera=cab, progress=False)  # fmt: skip


def test_a_recipe_short_of_the_survey_is_said(tmp_path: Path) -> None:
    """A user trial: a scenery recipe ending 100 m before the survey rendered those frames on
    bare ground and cut the line's tunnel at the recipe's end, in silence."""
    from predisat.synth.world import Stretch, WorldSpec

    spec = WorldSpec((Stretch("open", 1900.0, 2005.0),))
    with pytest.warns(UserWarning, match=r"covers chainage 1900-2005 m, not all of the "
                      r"survey's 2000-2010 m"):  # fmt: skip
        generate_survey(demo_track(), 2000.0, 2010.0, spec=spec, out_dir=tmp_path, camera=CAM,
                        progress=False, options=RenderOptions(supersample=1, ambient_rays=0))
