"""Reconstruction with cab and 360-degree cameras on small synthetic scenes with ideal sky
labels (ray cast); ground truth from ray casting the world (``true_masks``) and geometry."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.camera.models import CameraModel, Mount
from predisat.masks.maskset import BinSource
from predisat.reconstruct.carving import ReconstructionParams, Reconstructor
from predisat.reconstruct.skyline import Rectifier
from predisat.synth.raycast import make_caster
from predisat.synth.truth import ideal_frames, true_masks
from predisat.synth.world import World
from tests.predisat.reconstruct.test_carving import open_world, wall_world  # noqa: F401

PANO = CameraModel.equirect(360)  # 1 deg per pixel
FISHEYE = CameraModel.fisheye_from_fov(200, 150, 110.0)
PARAMS = ReconstructionParams(reach_m=150.0, carve_range_m=50.0)


def _frames(world: World, cams: dict[str, tuple[CameraModel, Mount]], s: np.ndarray) -> list:
    caster = make_caster(world, "open3d", lband_only=True)
    out = []
    for pos, (cam, mount) in cams.items():
        out += ideal_frames(world, s, cam, {pos: mount}, caster=caster)
    return out


def _off_axis(world: World, az_deg: np.ndarray, s_m: float) -> np.ndarray:
    rel = np.mod(az_deg - float(world.track.heading_at(s_m)) + 180.0, 360.0) - 180.0
    return np.minimum(np.abs(rel), 180.0 - np.abs(rel))


def test_panorama_rectifies_all_round_with_elevation_from_the_row() -> None:
    rect = Rectifier.build(PANO, Mount.default("roof"), az_step_deg=1.0, el_step_deg=0.5)
    assert rect.rel_az_deg.size == 360
    assert rect.rel_az_deg[[0, -1]] == pytest.approx([-179.5, 179.5])
    # sky above row 60 of a level 1-deg panorama: above 90 - 60 = 30 deg elevation
    sky = np.zeros(PANO.shape, bool)
    sky[:60] = True
    prof = rect.profile(sky, heading_deg=0.0)
    assert np.isfinite(prof.sky_el_deg).all()
    # conservative: never below 30 deg, above it by the obstacle growth (1 px = 1 deg) and
    # half a grid step at most
    assert rect.grow_px[1] == 1
    assert (prof.sky_el_deg >= 30.0).all() and (prof.sky_el_deg <= 31.5).all()
    assert np.nanmin(prof.seen_hi_deg) > 89.0


def test_panorama_and_cab_cameras_open_the_sky_along_the_track(open_world: World) -> None:  # noqa: F811
    s = np.array([350.0])
    pos = np.arange(250.0, 451.0, 10.0)
    side = {p: (FISHEYE, Mount.default(p)) for p in ("left", "right")}
    rigs = {
        "cab": side | {p: (FISHEYE, Mount.default(p)) for p in ("front", "rear")},
        "360": {"roof": (PANO, Mount.default("roof"))},
    }
    # (side cameras alone see nothing straight along the track there and keep the far-field
    # default: test_carving.test_open_country_fisheye_opens_along_track)
    for k, cams in rigs.items():
        rec = Reconstructor(PARAMS).run(_frames(open_world, cams, pos), s, open_world.track)
        axis = _off_axis(open_world, rec.az_deg, 350.0) < 2.0
        # the flat open country's true horizon along the track is ~0 deg
        assert np.median(rec.mask_el_deg[0, axis]) < 3.0, k
        assert (rec.source[0, axis] != BinSource.ASSUMED).all(), k
        # and all round (the panorama sees every azimuth, the cab pair the rest with the sides)
        assert np.median(rec.mask_el_deg[0]) < 3.0, k


def test_panorama_masks_never_fall_below_the_truth_at_a_wall(wall_world: World) -> None:  # noqa: F811
    s = np.array([340.0, 350.0, 360.0])
    fr = _frames(wall_world, {"roof": (PANO, Mount.default("roof"))}, np.arange(250.0, 451.0, 10.0))
    rec = Reconstructor(PARAMS).run(fr, s, wall_world.track)
    tm = true_masks(wall_world, s)
    assert (rec.mask_el_deg - tm.mask_el_deg).min() >= -0.5  # 1-deg pixels
    # the wall (30 m high, 10 m left) is found: the left bins are at least its elevation
    left = np.argmin(np.abs(np.mod(rec.az_deg - tm.heading_deg[0] + 90.0 + 180.0, 360.0) - 180.0))
    wall_el = np.degrees(np.arctan2(26.0, 10.0))
    assert rec.mask_el_deg[1, left] == pytest.approx(wall_el, abs=8.0)


def _reached(rect: Rectifier) -> np.ndarray:
    """Pixels (shape ``camera.shape``) from which a single obstacle pixel, grown as
    ``Rectifier._grown_sky`` grows it (vertically by ``grow_px[1]``, then each row by its own
    reach, longitude wrapping), lands on a pixel some grid sample reads: counted from the
    samples' side, each marking the pixels whose growth covers it."""
    h, w = rect.camera.shape
    gy = rect.grow_px[1]
    idx = np.unique(rect.pixel_index[rect.pixel_index >= 0])
    rs, cs = np.divmod(idx, w)
    reach = rect.grow_row_px[rs]
    diff = np.zeros((h, 3 * w + 1), np.int64)  # three turns of longitude, folded after
    for dr in range(-gy, gy + 1):
        r = rs + dr
        ok = (r >= 0) & (r < h)
        lo = cs[ok] - np.minimum(reach[ok], w) + w
        hi = lo + np.minimum(2 * reach[ok] + 1, w)
        np.add.at(diff, (r[ok], lo), 1)
        np.add.at(diff, (r[ok], hi), -1)
    run = np.cumsum(diff, axis=1)[:, : 3 * w]
    return (run[:, :w] + run[:, w : 2 * w] + run[:, 2 * w :]) > 0


@pytest.mark.parametrize("roll_deg,pitch_deg", [(0.0, 0.0), (-6.5, 0.0), (7.3, 1.5)])
def test_rolled_panorama_grows_obstacles_locally_and_still_samples_every_pixel(
    roll_deg: float, pitch_deg: float
) -> None:
    """A panorama rectified in a rolled vehicle's attitude (a canted curve) has the image's
    pole inside the grid and the longitude seam crossed by neighbouring samples: one obstacle
    growth sized there (half the image width) erased every row holding an obstacle pixel, so a
    contact wire near the zenith ended every column's top sky run (docs/rigs.md). The growth
    per row keeps the guarantee that any obstacle pixel in the grid's view reaches a sample:
    checked for every such pixel."""
    rect = Rectifier.build(PANO, Mount.default("roof").on_vehicle(roll_deg, pitch_deg),
                           az_step_deg=1.0, el_step_deg=0.5)  # fmt: skip
    sky = np.ones(PANO.shape, bool)
    sky[60, 100] = False  # one obstacle pixel 30 deg up
    prof = rect.profile(sky, heading_deg=0.0)
    # only the columns near the pixel's azimuth stop there; the others see sky to the bottom
    assert np.mean(prof.sky_el_deg < 0.0) > 0.95
    need = rect.pixel_el_deg > rect.el_deg[-1] + 1.0
    assert need.sum() > 0.5 * need.size
    missed = need & ~_reached(rect)
    assert not missed.any(), np.argwhere(missed)[:5]
    # steps coarser than the checked ones are refused for a panorama
    with pytest.raises(ValueError, match="az_step_deg"):
        Rectifier.build(PANO, Mount.default("roof"), az_step_deg=2.0)
    # and the count from the samples' side agrees with rectifying one obstacle pixel
    rng = np.random.default_rng(0)
    rows, cols = np.nonzero(need)
    for k in [*rng.choice(rows.size, 40, replace=False), *np.flatnonzero(rows < 2)[:10]]:
        one = np.ones(PANO.shape, bool)
        one[rows[k], cols[k]] = False
        assert (rect.rectify(one) == 0).any(), (rows[k], cols[k])
