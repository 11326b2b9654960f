"""Sky segmentation of 360-degree panoramas: the sky band above a drawn skyline, across the
seam where the image's edges meet."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.sky.morphology import remove_thin_obstacles
from predisat.sky.panorama import (
    PANORAMA_BAND_SHARE,
    equirect_row_lat_deg,
    remove_thin_obstacles_equirect,
    segment_panorama,
)
from predisat.sky.segment import SkyOptions

H, W = 180, 360  # 1 deg per pixel, full sphere


def _panorama() -> tuple[np.ndarray, np.ndarray]:
    """A drawn panorama (BGR) and its true sky: a blue sky graded toward the horizon above a
    rolling green skyline, and a grey building standing across the seam (columns 340 to 19)."""
    rng = np.random.default_rng(5)
    rows = np.arange(H)[:, None]
    cols = np.arange(W)[None, :]
    skyline = 70.0 + 12.0 * np.sin(2 * np.pi * cols / W * 3)
    seam = (cols >= 340) | (cols < 20)
    skyline = np.where(seam, 30.0, skyline)
    sky = rows < skyline
    t = rows / H
    img = np.empty((H, W, 3), float)
    img[..., 0] = 235 - 60 * t  # B
    img[..., 1] = 190 - 20 * t
    img[..., 2] = 150 + 40 * t  # R
    green = np.stack([40 + 25 * rng.random((H, W)), 95 + 40 * rng.random((H, W)),
                      45 + 25 * rng.random((H, W))], -1)  # fmt: skip
    grey = np.stack([100 + 30 * rng.random((H, W))] * 3, -1)
    obstacle = np.where(seam[..., None], grey, green)
    img = np.where(sky[..., None], img + rng.normal(0, 2, img.shape), obstacle)
    return np.clip(img, 0, 255).astype(np.uint8), sky


@pytest.mark.parametrize("method", ["learned", "ensemble"])
def test_panorama_sky_band_follows_the_skyline_across_the_seam(method: str) -> None:
    img, truth = _panorama()
    seg = segment_panorama(img, SkyOptions(method=method))
    assert seg.sky_mask.shape == (H, W) and seg.confidence.shape == (W,)
    band = round(PANORAMA_BAND_SHARE * H)
    assert not seg.sky_mask[band:].any()  # below the band: never sky
    assert float(np.mean(seg.sky_mask == truth)) > 0.97
    # the building across the seam is an obstacle on both edges of the image
    for cols in (slice(342, 360), slice(0, 18)):
        assert not seg.sky_mask[35:60, cols].any()
        assert seg.skyline_row[cols] == pytest.approx(29.5, abs=3.0)


def test_panorama_bad_arguments_are_named() -> None:
    img, _ = _panorama()
    with pytest.raises(ValueError, match="not an upward fisheye"):
        segment_panorama(img, SkyOptions(fisheye=True))
    with pytest.raises(ValueError, match="band_rows"):
        segment_panorama(img, band_rows=4)
    with pytest.raises(ValueError, match="uint8"):
        segment_panorama(img.astype(float))


def test_panorama_keeps_the_sky_the_thin_policy_made() -> None:
    """A 1 px wire across the sky: the panorama's thin mask is the policy's sky (so that the
    reconstruction's Fresnel rule sees it), and empty without the policy."""
    img, _ = _panorama()
    wired = img.copy()
    wired[20, 60:300] = (40, 40, 40)  # a dark wire 1 px thick, well inside the sky band
    seg = segment_panorama(wired, SkyOptions(method="learned"))
    raw = segment_panorama(wired, SkyOptions(method="learned", thin_px=0))
    assert seg.thin_mask is not None
    assert np.array_equal(seg.thin_mask, seg.sky_mask & ~raw.sky_mask)
    assert seg.thin_mask[19:22, 60:300].any(axis=0).mean() > 0.9
    assert raw.thin_mask is None or not raw.thin_mask.any()


# --- the thin-structure policy on the sphere ---------------------------------------------

PW, PH = 720, 360  # the 360 rig at half resolution: 0.5 deg per pixel, thin_px = 1


def _wire_mask(height_m: float, offset_m: float, width_m: float, shape: tuple[int, int] = (PH, PW),
               ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Obstacle pixels (True) of a straight cylinder along the track (the image centre's
    direction) ``height_m`` above and ``offset_m`` to the side of an equirect camera, sampled at
    the pixel centres, and the angle it subtends at each pixel (degrees); computed from the
    geometry alone: a ray hits the cylinder when its distance to the cylinder's axis is at most
    the radius, and the axis lies ``hypot(height, offset) / sin(ray, axis)`` away along it."""
    h, w = shape
    px_deg = 360.0 / w
    lat = np.radians(90.0 - (np.arange(h) + 0.5) * px_deg)[:, None]
    lon = np.radians((np.arange(w) - (w - 1) / 2.0) * px_deg)[None, :]
    dy, dz = np.cos(lat) * np.sin(lon), np.sin(lat) * np.ones_like(lon)
    # ray through the origin (dx, dy, dz), axis through (0, offset, height) along x
    sin_ray_axis = np.hypot(dy, dz)
    dist = np.abs(offset_m * dz - height_m * dy) / sin_ray_axis
    range_m = np.hypot(height_m, offset_m) / sin_ray_axis
    return (dist <= width_m / 2.0) & (dz > 0), np.degrees(width_m / range_m)


@pytest.mark.parametrize("offset_m", [0.0, 0.03, 0.2, 1.0])
def test_a_thin_wire_overhead_is_thin_all_the_way_to_the_zenith(offset_m: float) -> None:
    """A 12 mm contact wire 2 m above the camera subtends at most 0.34 deg, under the policy's
    0.5 deg (1 px of the equator): every pixel of it becomes sky, including near the zenith
    where it covers several columns of a row."""
    wire, width_deg = _wire_mask(2.0, offset_m, 0.012)
    assert wire.sum() > 200
    assert width_deg[wire].max() < 0.35
    out = remove_thin_obstacles_equirect(~wire, 1)
    assert out.all()


@pytest.mark.parametrize("offset_m", [0.0, 0.5, 1.5])
def test_a_wide_beam_overhead_stays_an_obstacle(offset_m: float) -> None:
    """A 0.1 m tube 2 m above the camera: wherever it subtends 1.2 deg or more (2.4 pixels of
    the equator; up to 2.9 deg overhead) nothing of it is thin, not even in the top rows it
    fills all round; far along the track, where it subtends less than 0.35 deg, it is."""
    beam, width_deg = _wire_mask(2.0, offset_m, 0.1)
    out = remove_thin_obstacles_equirect(~beam, 1)
    wide = beam & (width_deg >= 1.2)
    assert wide.sum() > 300
    assert not out[wide].any()
    assert out[beam & (width_deg < 0.35)].all()
    assert out[~beam].all()


def test_the_policy_is_the_frame_policy_away_from_the_poles_and_the_seam() -> None:
    """Within 45 deg of the equator the east-west geodesic steps one column per sample: with
    thin_px = 1 the runs it keeps are those of the frame policy (runs of 2 px and more),
    for obstacles that touch neither the top row nor the seam."""
    rng = np.random.default_rng(3)
    sky = np.ones((PH, PW), bool)
    band = rng.random((PH, PW)) < 0.35
    rows = slice(91, 270)  # latitudes 44.5 .. -44.5 deg
    sky[rows, 20:700] = ~band[rows, 20:700]
    want = remove_thin_obstacles(sky, 1)
    assert np.array_equal(remove_thin_obstacles_equirect(sky, 1), want)
    assert not np.array_equal(want, sky)  # the policy did something


def test_runs_wrap_around_the_seam_and_through_the_zenith() -> None:
    """A 3 px wide mast cut by the seam is kept (its run wraps); a cap of 2 deg across over
    the zenith (the top two rows all round) is kept (its runs go on down the opposite meridian
    and across the pole); the top row over half the circle (0.5 deg across) is thin."""
    sky = np.ones((PH, PW), bool)
    sky[150:200, [718, 719, 0]] = False
    out = remove_thin_obstacles_equirect(sky, 1)
    assert np.array_equal(out, sky)
    cap = np.ones((PH, PW), bool)
    cap[:2] = False
    assert np.array_equal(remove_thin_obstacles_equirect(cap, 1), cap)
    half = np.ones((PH, PW), bool)
    half[0, :360] = False
    assert remove_thin_obstacles_equirect(half, 1).all()


def test_equirect_policy_arguments_are_checked() -> None:
    with pytest.raises(ValueError, match="thin_px"):
        remove_thin_obstacles_equirect(np.ones((PH, PW), bool), -1)
    with pytest.raises(ValueError, match="width_px / 2"):
        remove_thin_obstacles_equirect(np.ones((PW, PW), bool), 1)
    assert np.array_equal(equirect_row_lat_deg(4, 8), [67.5, 22.5, -22.5, -67.5])


def test_segment_panorama_makes_a_wire_over_the_camera_thin() -> None:
    """A dark contact wire drawn where the geometry puts it (12 mm, 2 m over a camera at a
    1-deg-per-pixel panorama, 3 cm to the side: 0.34 deg wide, across several columns near
    the zenith): the segmentation sees much of it as obstacle, the sphere's policy at 1 px
    makes all of it sky, and marks it thin for the reconstruction's Fresnel rule."""
    img, sky_true = _panorama()
    wire, width_deg = _wire_mask(2.0, 0.03, 0.012, shape=(H, W))
    wire &= sky_true
    assert width_deg[wire].max() < 0.35 and wire[:10].sum() > 50
    wired = img.copy()
    wired[wire] = (40, 40, 40)
    raw = segment_panorama(wired, SkyOptions(method="learned", thin_px=0))
    seen = wire & ~raw.sky_mask
    assert seen.sum() > 0.5 * wire.sum()  # the classifier does see the wire
    seg = segment_panorama(wired, SkyOptions(method="learned", thin_px=1))
    assert seg.sky_mask[wire].all()
    assert seg.thin_mask is not None and seg.thin_mask[seen].all()
    assert np.array_equal(seg.thin_mask, seg.sky_mask & ~raw.sky_mask)
