"""A lens that is not the calibration's, for a stretch: the sun and the horizon tell."""

from __future__ import annotations

import numpy as np


def _fisheye():
    from predisat.camera.models import default_camera

    return default_camera("fisheye").resized(400, 300)


def _zoom(img: np.ndarray, s: float) -> np.ndarray:
    import cv2

    h, w = img.shape[:2]
    m = np.float32([[s, 0, (1 - s) * (w - 1) / 2], [0, s, (1 - s) * (h - 1) / 2]])
    return cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_LINEAR)


def _sky_with_sun(cam, sun_cam: np.ndarray, radius_px: float = 4.0) -> np.ndarray:
    import cv2

    img = np.full((cam.height_px, cam.width_px, 3), (200, 150, 110), np.uint8)
    u, v = cam.ray_to_pixel(sun_cam[None])
    cv2.circle(img, (round(float(u[0])), round(float(v[0]))), int(radius_px),
               (255, 255, 255), -1)  # fmt: skip
    return img


def test_the_sun_is_found_on_its_place_and_off_it_through_a_longer_lens() -> None:
    from predisat.reconstruct.sunsight import SUN_TOLERANCE_DEG, locate_sun, sun_in_image

    cam = _fisheye()
    th = np.radians(30.0)
    sun = np.array([np.sin(th) * np.cos(0.5), np.sin(th) * np.sin(0.5), np.cos(th)])
    assert sun_in_image(cam, sun)
    img = _sky_with_sun(cam, sun)
    seen = locate_sun(img, cam, sun)
    assert seen is not None and seen.residual_deg < 0.5, seen
    zoomed = locate_sun(_zoom(img, 1.25), cam, sun)
    # about (1.25 - 1) * 30 deg off, radially
    assert zoomed is not None and zoomed.residual_deg > SUN_TOLERANCE_DEG + 4.0, zoomed
    assert abs(zoomed.radial_scale - 1.25) < 0.03, zoomed
    # a sun half behind a roof is not round and is not taken; no sun, nothing found
    half = img.copy()
    _, v = cam.ray_to_pixel(sun[None])
    half[round(float(v[0])) :, :] = (60, 60, 60)
    assert locate_sun(half, cam, sun) is None
    assert locate_sun(np.full_like(img, 120), cam, sun) is None
    # a sun out of the image is not looked for
    assert not sun_in_image(cam, np.array([0.0, -1.0, 0.0]))


def test_stretches_off_their_place_are_widened_to_the_sightings_on_it() -> None:
    from predisat.reconstruct.sunsight import off_stretches

    nan = np.nan
    # on place, hidden, off x3 (one hidden between), hidden, on place
    r = [0.1, nan, 6.0, 6.2, nan, 6.1, nan, 0.2, 0.1]
    assert off_stretches(r, 1.5) == [(1, 6)]
    # a single sighting off its place (a reflection) marks nothing
    assert off_stretches([0.1, 6.0, 0.1, nan, 0.2], 1.5) == []
    # off to the camera's end; off from its start; per-frame tolerances
    assert off_stretches([0.1, 5.0, 5.0, nan], 1.5) == [(1, 3)]
    assert off_stretches([nan, 5.0, 5.0, 0.1], 1.5) == [(0, 2)]
    assert off_stretches([0.1, 5.0, 5.0, 0.1], [1.5, 6.0, 1.5, 1.5]) == []
    # the horizon check's evidence: +inf under, 0 on its place
    assert off_stretches([0.0, np.inf, nan, np.inf, 0.0], 3.0) == [(1, 3)]


def test_a_frame_whose_sky_reaches_under_the_horizon_is_under() -> None:
    from predisat.reconstruct.sunsight import horizon_residual, lowest_sky_deg

    el = np.repeat(np.linspace(60.0, -20.0, 9)[:, None], 4, axis=1)  # rows: 60 .. -20 deg
    sky = el >= 0.0
    low = lowest_sky_deg(sky, el)
    assert np.allclose(low, 0.0)
    assert horizon_residual(low, 3.0) == 0.0
    assert np.isposinf(horizon_residual(lowest_sky_deg(el >= -10.0, el), 3.0))
    assert np.isnan(horizon_residual(lowest_sky_deg(el >= 30.0, el), 3.0))  # a town: not seen
    assert np.isnan(horizon_residual(lowest_sky_deg(np.zeros_like(sky), el), 3.0))


def test_process_sets_aside_a_stretch_seen_through_a_longer_lens(tmp_path, capsys) -> None:
    """A rendered survey whose left images over 70 m are zoomed 1.25x, same size and
    calibration (a spare camera with a longer lens): every other check passed, and a user
    trial's 150 m such stretch trusted 0.23 % of its directions falsely. The sun and the
    horizon are not where the calibration puts them: those frames are set aside and the
    right camera's are not."""
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
    zoomed = []
    for r in rows:
        if r["side"] == "left" and 3060.0 <= float(r["chainage_m"]) <= 3130.0:
            im = _zoom(cv2.imread(str(survey / r["image"])), 1.25)
            (survey / r["image"]).write_bytes(cv2.imencode(".jpg", im)[1].tobytes())
            zoomed.append(r["frame_id"])
    res = process_survey(survey, tmp_path / "out", progress=False)
    lens_bad = {b.frame_id for b in res.bad_frames if b.stage == "lens"}
    assert set(zoomed) <= lens_bad, (zoomed, sorted(lens_bad))
    # widened at most to the sightings on their place beside the stretch
    assert len(lens_bad) <= len(zoomed) + 6, sorted(lens_bad)
    assert all(f.startswith("left_") for f in lens_bad), sorted(lens_bad)
    assert "warning: the left camera" in capsys.readouterr().err


def test_the_glare_of_a_sun_hidden_behind_a_facade_is_not_taken_for_it() -> None:
    """Held-out worlds (fisheye_s41, s43, the demo's town): the sun behind a facade or a roof
    leaves a saturated glare in the sky beside it, clipped square by the wall; its centre lay
    9-18 deg off the prediction and was taken for a sun off its place. Given the frame's sky,
    a spot with an obstacle within SUN_CLEAR_DEG is not taken; a sun in open sky still is, on
    its place and through a longer lens."""
    from predisat.reconstruct.sunsight import SUN_TOLERANCE_DEG, locate_sun

    cam = _fisheye()
    th = np.radians(30.0)
    sun = np.array([np.sin(th) * np.cos(0.5), np.sin(th) * np.sin(0.5), np.cos(th)])
    u, v = (round(float(c[0])) for c in cam.ray_to_pixel(sun[None]))
    img = np.full((cam.height_px, cam.width_px, 3), (200, 150, 110), np.uint8)
    img[:, : u + 3] = (60, 60, 60)  # a facade over the sun
    img[v - 15 : v + 15, u + 3 : u + 33] = 255  # its glare, clipped square by the wall
    sky = np.ones(img.shape[:2], bool)
    sky[:, : u + 3] = False
    glare = locate_sun(img, cam, sun)
    assert glare is not None and glare.residual_deg > SUN_TOLERANCE_DEG  # taken without sky
    assert locate_sun(img, cam, sun, sky) is None
    # a sun in open sky: found on its place and off it through a longer lens, sky given
    clear = _sky_with_sun(cam, sun)
    open_sky = np.ones(clear.shape[:2], bool)
    seen = locate_sun(clear, cam, sun, open_sky)
    assert seen is not None and seen.residual_deg < 0.5, seen
    zoomed = locate_sun(_zoom(clear, 1.25), cam, sun, open_sky)
    assert zoomed is not None and zoomed.residual_deg > SUN_TOLERANCE_DEG + 4.0, zoomed
