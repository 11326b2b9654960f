"""Tests of the ground truth: analytic masks, tunnels, open ground, backend agreement,
blockage of satellite directions, obstacle descriptors, file round trip."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.geodesy import WGS84
from predisat.masks.truth import TrueMasks
from predisat.synth.raycast import make_caster
from predisat.synth.truth import (
    ideal_sky_mask,
    is_blocked,
    obstacle_descriptors,
    true_masks,
)
from predisat.synth.world import Stretch, World, WorldSpec
from tests.predisat.synth.test_world import LAT0, LON0, straight_track

AZIMUTH = 60.0  # of the straight test track
WALL = {"height_m": 30.0, "distance_m": 10.0, "roughness_m": 0.0, "batter": 0.0}
W0, W1 = 9100.0, 10100.0  # wall chainages, ~10 km from the frame origin: the local vertical
# there is tilted by 0.09 deg from the frame's, so a wrong vertical would show in the masks


@pytest.fixture(scope="module")
def wall_world() -> World:
    track = straight_track(10400.0, AZIMUTH)
    spec = WorldSpec((Stretch("rock_walls", W0, W1, "left", WALL),), catenary=False, hills=False)
    return World.build(track, spec, seed=0)


@pytest.fixture(scope="module")
def small_mixed() -> World:
    track = straight_track(1300.0, AZIMUTH)
    return World.build(track, WorldSpec.mixed(100.0, 1250.0, seed=5), seed=5)


def heading_deg(s_m: float) -> float:
    """Forward azimuth of the geodesic track at distance ``s_m`` (pyproj)."""
    _, _, back = WGS84.fwd(LON0, LAT0, AZIMUTH, s_m)
    return float(np.mod(back + 180.0, 360.0))


def wall_mask_deg(s0: float, az_deg: np.ndarray, ant_height_m: float = 4.0) -> np.ndarray:
    """Analytic elevation of the top edge of the wall (left, at 10 m, 30 m high, W0..W1)."""
    beta = np.radians(az_deg - heading_deg(s0))  # clockwise from the forward direction
    left = -np.sin(beta)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = WALL["distance_m"] / left
        along = r * np.cos(beta)
        hit = (left > 1e-12) & (s0 + along >= W0) & (s0 + along <= W1)
        return np.where(hit, np.degrees(np.arctan2(WALL["height_m"] - ant_height_m, r)), 0.0)


def test_wall_mask_matches_analytic_geometry(wall_world: World) -> None:
    s = np.array([9350.0, 9600.0, 9900.0])
    tm = true_masks(wall_world, s)
    assert tm.mask_el_deg.shape == (3, 720) and np.all(~tm.covered)
    for i, s0 in enumerate(s):
        # analytic bin maximum from 201 azimuths across each bin
        fine = tm.az_deg[:, None] + np.linspace(-0.25, 0.25, 201)[None, :]
        truth = wall_mask_deg(s0, fine).max(axis=1)
        # leave out the bins that contain a wall end (a jump inside the bin)
        ends = [np.degrees(np.arctan2(-10.0, e - s0)) + heading_deg(s0) for e in (W0, W1)]
        near_end = np.zeros(720, bool)
        for e in ends:
            d = np.abs((tm.az_deg - np.mod(e, 360.0) + 180.0) % 360.0 - 180.0)
            near_end |= d < 0.75
        err = np.abs(tm.mask_el_deg[i] - truth)[~near_end]
        assert err.max() < 0.01, (s0, err.max())  # measured: 0.0015 deg
        assert np.median(err) < 0.002
        assert tm.mask_el_deg[i].max() == pytest.approx(
            np.degrees(np.arctan2(26.0, 10.0)), abs=0.02
        )
    assert np.all(tm.mask_min_el_deg <= tm.mask_el_deg)


def test_wall_directions_below_are_blocked_above_are_free(wall_world: World) -> None:
    s0 = 9600.0
    ant = wall_world.antenna_enu(s0)
    rng = np.random.default_rng(3)
    az = rng.uniform(0, 360, 4000)
    truth = wall_mask_deg(s0, az)
    on_wall = truth > 0.5
    below = rng.uniform(0.0, 1.0, az.size) * (truth - 0.1)
    above = truth + 0.1 + rng.uniform(0.0, 1.0, az.size) * (90.0 - truth - 0.1)
    caster = make_caster(wall_world, "trimesh", lband_only=True)  # the independent backend
    assert np.all(is_blocked(wall_world, ant, az[on_wall], below[on_wall], caster=caster))
    assert not np.any(is_blocked(wall_world, ant, az, above, caster=caster))


def test_wall_obstacle_descriptors(wall_world: World) -> None:
    dist, height = obstacle_descriptors(wall_world, [9300.0, 9700.0])
    assert np.allclose(dist[:, 0], 10.0, atol=0.01)  # left: the wall face
    assert np.allclose(height[:, 0], 30.0, atol=0.01)  # its top above the rail
    assert np.all(np.isnan(dist[:, 1])) and np.all(np.isnan(height[:, 1]))  # right: open


def test_cutting_obstacle_descriptors() -> None:
    track = straight_track(1000.0, AZIMUTH)
    params = {"depth_m": 8.0, "toe_distance_m": 4.0, "slope": 1.5}
    spec = WorldSpec((Stretch("cutting", 200, 800, "right", params),), catenary=False, hills=False)
    world = World.build(track, spec, seed=0)
    dist, height = obstacle_descriptors(world, [400.0, 500.0])
    # the slope rises from the toe (4 m, 0.5 m below the rail); a horizontal ray 1 m above the
    # rail meets it 1.5 m higher, i.e. 1.5 * 1.5 m further out; the crest is 8 m above the rail
    assert np.allclose(dist[:, 1], 4.0 + 1.5 * 1.5, atol=0.01)
    assert np.allclose(height[:, 1], 8.0, atol=0.01)
    tm = true_masks(world, [500.0], az_step_deg=1.0)
    right = tm.mask_at(heading_deg(500.0) + 90.0)[0]
    crest = 4.0 + 1.5 * 8.5
    assert right == pytest.approx(np.degrees(np.arctan2(8.0 - 4.0, crest)), abs=0.05)


def test_tunnel_is_covered_and_open_ground_is_flat() -> None:
    track = straight_track(1000.0, AZIMUTH)
    spec = WorldSpec(
        (Stretch("open", 0, 300, params={"objects_per_km": 0}), Stretch("tunnel", 300, 700)),
        catenary=False,
        hills=False,
    )
    world = World.build(track, spec, seed=0)
    tm = true_masks(world, [50.0, 150.0, 305.0, 500.0, 695.0], az_step_deg=1.0)
    assert list(tm.covered) == [False, False, True, True, True]
    assert np.all(tm.mask_el_deg[2:] == 90.0)
    # open flat ground (the ellipsoid curves away): nothing above the horizon except the
    # tunnel hill ahead
    off_axis = np.abs((tm.az_deg - heading_deg(150.0) + 180.0) % 360.0 - 180.0)
    assert np.all(tm.mask_el_deg[:2, off_axis > 30.0] < 0.01)
    # the portal, 150 m ahead: a face 7.3 m above the antenna and +-18 m wide
    assert np.all(tm.mask_el_deg[1, off_axis < 5.0] > 2.0)


def test_hills_give_a_low_distant_horizon() -> None:
    track = straight_track(1000.0, AZIMUTH)
    spec = WorldSpec((Stretch("open", 0, 1000, params={"objects_per_km": 0}),), catenary=False)
    world = World.build(track, spec, seed=4)
    tm = true_masks(world, [300.0, 700.0], az_step_deg=2.0)
    assert 0.3 < np.median(tm.mask_el_deg) < 4.0
    assert tm.mask_el_deg.max() < 6.0


def test_backends_agree_on_a_mixed_world(small_mixed: World) -> None:
    s = np.linspace(130.0, 1230.0, 12)
    a = true_masks(small_mixed, s, backend="open3d")
    b = true_masks(small_mixed, s, backend="trimesh")
    close = np.abs(a.mask_el_deg - b.mask_el_deg) <= 0.1
    assert close.mean() >= 0.999
    assert a.mask_el_deg.max() > 20.0  # the world is not empty
    assert np.array_equal(a.covered, b.covered)


def test_directions_above_the_mask_are_free(small_mixed: World) -> None:
    s = np.linspace(130.0, 1230.0, 10)
    tm = true_masks(small_mixed, s)
    rng = np.random.default_rng(8)
    k = rng.integers(0, 720, (s.size, 200))
    az = tm.az_deg[k] + rng.uniform(-0.25, 0.25, k.shape)
    rows = np.arange(s.size)[:, None]
    el = np.minimum(tm.mask_el_deg[rows, k] + 0.05, 89.99)
    free = ~is_blocked(small_mixed, small_mixed.antenna_enu(s), az, el, backend="trimesh")
    open_rows = ~tm.covered
    assert free[open_rows].mean() >= 0.999
    # and a direction in the bin below the lowest sampled mask, when that one is a solid
    # face (not an overhang) is blocked: check the bins whose min and max agree
    flat = (tm.mask_el_deg[rows, k] - tm.mask_min_el_deg[rows, k] < 0.01) & (
        tm.mask_el_deg[rows, k] > 5.0
    )
    el_below = tm.mask_el_deg[rows, k] - 0.5
    blocked = is_blocked(small_mixed, small_mixed.antenna_enu(s), az, el_below, backend="trimesh")
    assert blocked[flat & open_rows[:, None]].mean() > 0.9


def test_is_blocked_shapes(wall_world: World) -> None:
    ant = wall_world.antenna_enu(np.array([9400.0, 9500.0]))
    az = np.array([[0.0, 90.0, 180.0], [10.0, 20.0, 30.0]])
    assert is_blocked(wall_world, ant, az, 45.0).shape == (2, 3)
    assert is_blocked(wall_world, ant[0], az[0], az[0] * 0 + 1.0).shape == (3,)
    assert is_blocked(wall_world, ant[0], 0.0, 89.0).shape == ()


def test_save_and_load(tmp_path, wall_world: World) -> None:
    tm = true_masks(wall_world, [9500.0, 9510.0], az_step_deg=2.0)
    path = tmp_path / "truth.npz"
    tm.save(path)
    back = TrueMasks.load(path)
    assert np.array_equal(back.mask_el_deg, tm.mask_el_deg)
    assert np.array_equal(back.obstacle_distance_m, tm.obstacle_distance_m, equal_nan=True)
    assert back.az_step_deg == 2.0 and back.backend == "open3d"
    assert back.bin_index(359.5) == 0 and back.bin_index(1.2) == 1
    np.savez(tmp_path / "other.npz", meta=np.array('{"format": "x"}'))
    with pytest.raises(ValueError, match="not a true-mask file"):
        TrueMasks.load(tmp_path / "other.npz")


def test_default_positions_every_10_m(small_mixed: World) -> None:
    with pytest.raises(ValueError, match="divide 360"):
        true_masks(small_mixed, [200.0], az_step_deg=0.7)
    tm = true_masks(small_mixed, None, az_step_deg=10.0, n_sub=1)
    assert tm.chainage_m[0] == 100.0 and tm.chainage_m[-1] == 1250.0
    assert np.allclose(np.diff(tm.chainage_m), 10.0)


def test_ideal_sky_mask_is_the_rendered_label(small_mixed: World) -> None:
    # the renderer labels frames through its own casters (thin structures are sky); the ideal
    # mask must agree pixel for pixel, for both sides and both directions of travel
    from predisat.camera.models import CameraModel, Mount
    from predisat.synth.render import Casters, RenderOptions, camera_pose, render_frame
    from predisat.synth.sky import SkyModel

    casters = Casters.for_world(small_mixed, "open3d")
    sky = SkyModel.cloudy(120.0, 50.0, seed=3)
    opt = RenderOptions(supersample=1, ambient_rays=1)
    seen_sky = seen_obstacle = 0
    for cam in (CameraModel.pinhole_from_fov(120, 90, 74.0),
                CameraModel.fisheye_from_fov(120, 90, 110.0)):
        for s, side, reverse in ((400.0, "left", False), (700.0, "right", True)):
            mount = Mount.default(side)  # type: ignore[arg-type]
            pose = camera_pose(small_mixed, s, mount, reverse=reverse)
            _, label = render_frame(small_mixed, casters, cam, pose, sky,
                                    np.random.default_rng(0), opt)
            ideal = ideal_sky_mask(small_mixed, s, cam, mount, reverse=reverse)
            assert ideal.shape == label.shape
            np.testing.assert_array_equal(ideal, label >= 128)
            seen_sky += int(ideal.sum())
            seen_obstacle += int((~ideal).sum())
    assert seen_sky > 1000 and seen_obstacle > 1000
