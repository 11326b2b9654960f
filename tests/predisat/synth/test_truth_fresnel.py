"""The ground truth's thin-structure rule (synth.truth.FresnelCaster, true_masks): a thin face
blocks only where its material's width exceeds a tenth of the first Fresnel zone radius at the
hit's distance; the limits are computed here by hand (r_F = sqrt(0.1903 d))."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from predisat.synth.materials import MATERIAL_IDS
from predisat.synth.raycast import make_caster
from predisat.synth.truth import FresnelCaster, true_masks
from predisat.synth.world import Stretch, World, WorldSpec
from tests.predisat.synth.test_world import straight_track


@dataclass(frozen=True)
class _Scene:
    vertices_m: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    blocking_faces: np.ndarray


def _box(x0, x1, y0, y1, z0, z1):
    v = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(f)


def _scene(beam_z_m: float, material: str) -> _Scene:
    """A thin beam 0.06 m square along x at ``beam_z_m`` over the origin, and a blocking slab
    far below (a caster needs a blocking face)."""
    vb, fb = _box(-5.0, 5.0, -0.03, 0.03, beam_z_m - 0.03, beam_z_m + 0.03)
    vg, fg = _box(-50.0, 50.0, -50.0, 50.0, -20.0, -19.0)
    v = np.concatenate([vb, vg])
    f = np.concatenate([fb, fg + len(vb)])
    mat = np.array([MATERIAL_IDS[material]] * len(fb) + [MATERIAL_IDS["concrete"]] * len(fg))
    blocking = np.array([False] * len(fb) + [True] * len(fg))
    return _Scene(v, f, mat, blocking)


# the beam's lower face is hit at beam_z - 0.03 straight up, sqrt(2) times farther at 45 deg
# along the beam; the cantilever material is 0.06 m wide: opaque nearer than
# (0.06 / 0.1)^2 / 0.1903 = 1.892 m; the wire material (0.015 m), nearer than 0.118 m
@pytest.mark.parametrize("beam_z_m, material, up_blocked, slant_blocked", [
    (1.2, "cantilever", True, True), (1.5, "cantilever", True, False),
    (1.85, "cantilever", True, False), (1.95, "cantilever", False, False),
    (2.5, "cantilever", False, False), (0.5, "wire", False, False), (0.1, "wire", True, True),
])  # fmt: skip
def test_thin_face_blocks_by_its_distance(beam_z_m, material, up_blocked, slant_blocked) -> None:
    scene = _scene(beam_z_m, material)
    fc = FresnelCaster(scene, make_caster(scene, "open3d", lband_only=True))
    rays = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
    got = fc.occluded(np.zeros((3, 3)), rays)
    # straight up; 45 deg along the beam (through it); 45 deg across it (missed)
    assert got.tolist() == [up_blocked, slant_blocked, False]
    assert not fc.lband.occluded(np.zeros((3, 3)), rays).any()


def test_true_masks_raise_bins_only_near_a_cantilever() -> None:
    track = straight_track(400.0, 30.0)
    world = World.build(track, WorldSpec((Stretch("open", 0.0, 400.0),), True, False), seed=3)
    mat = np.asarray(world.face_material)
    cant = np.flatnonzero(mat == MATERIAL_IDS["cantilever"])
    assert cant.size
    # the chainage of the masts: cantilever vertices projected on the track
    verts = np.asarray(world.vertices_m)[np.asarray(world.faces)[cant].ravel()]
    s_cant = np.unique(np.round(track.project_enu(verts).chainage_m))
    s0 = float(np.median(s_cant[(s_cant > 100) & (s_cant < 300)]))
    pos = np.array([s0, s0 + 10.0, s0 + 25.0])
    cst = make_caster(world, "open3d", lband_only=True)
    new = true_masks(world, pos, caster=cst).mask_el_deg
    old = true_masks(world, pos, caster=cst, thin_rule=False).mask_el_deg
    # the rule only adds blocking (to the bisection's 1e-3 deg: the scan may start elsewhere)
    assert np.all(new >= old - 1e-3)
    assert (new[0] > old[0] + 1.0).sum() >= 3  # under the cantilever: its strut blocks
    np.testing.assert_allclose(new[1:], old[1:], atol=1e-3)  # 10 m away: beyond 1.9 m


def test_ideal_frames_under_the_policy_carry_their_thin_pixels() -> None:
    from predisat.camera.models import CameraModel
    from predisat.sky.morphology import remove_thin_obstacles
    from predisat.synth.truth import ideal_frames, ideal_sky_mask

    track = straight_track(400.0, 30.0)
    world = World.build(track, WorldSpec((Stretch("open", 0.0, 400.0),), True, False), seed=3)
    cam = CameraModel.fisheye_from_fov(200, 150, 185.0)
    s = np.array([200.0])
    plain = ideal_frames(world, s, cam)
    policy = ideal_frames(world, s, cam, thin_deg=0.7)
    px = max(1, round(0.7 / cam.widest_pixel_deg))
    assert all(f.thin_mask is None for f in plain)
    full = make_caster(world, "open3d")
    n_thin = 0
    for f in policy:
        raw = ideal_sky_mask(world, s, cam, f.mount, caster=full)[0]
        assert f.thin_width_deg == pytest.approx(px * cam.widest_pixel_deg)
        assert np.array_equal(f.thin_mask, f.sky_mask & ~raw)
        assert np.array_equal(f.sky_mask, remove_thin_obstacles(raw, px) & (
            np.all(np.isfinite(cam.pixel_to_ray(*cam.pixel_grid())), axis=-1)))
        n_thin += int(f.thin_mask.sum())
    assert n_thin > 0  # the wires


def test_ideal_frames_of_a_panorama_take_the_policy_on_the_sphere() -> None:
    """An equirect camera's ideal frames under the policy: the sphere's policy
    (remove_thin_obstacles_equirect) on the ray-cast mask, not the frame policy in pixels,
    which keeps more of the catenary over the track as obstacles."""
    from predisat.camera.rigs import Rig
    from predisat.sky.morphology import remove_thin_obstacles
    from predisat.sky.panorama import remove_thin_obstacles_equirect
    from predisat.synth.truth import ideal_frames, ideal_sky_mask

    track = straight_track(400.0, 30.0)
    world = World.build(track, WorldSpec((Stretch("open", 0.0, 400.0),), True, False), seed=3)
    ((pos, cam, mount),) = Rig.preset("360").scaled(0.5).cameras
    s = np.array([170.0, 200.0])
    frames = ideal_frames(world, s, cam, {pos: mount}, thin_deg=0.7)
    px = max(1, round(0.7 / cam.widest_pixel_deg))
    full = make_caster(world, "open3d")
    raws = ideal_sky_mask(world, s, cam, mount, caster=full)
    n_more = 0
    for f, raw in zip(frames, raws, strict=True):
        assert np.array_equal(f.sky_mask, remove_thin_obstacles_equirect(raw, px))
        assert f.thin_mask is not None and np.array_equal(f.thin_mask, f.sky_mask & ~raw)
        n_more += int((f.sky_mask & ~remove_thin_obstacles(raw, px)).sum())
    assert n_more > 0  # wire pixels near the zenith the frame policy kept
