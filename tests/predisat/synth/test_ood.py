"""The out-of-distribution scenery (issue 30): mirrors, pale facades, water, wet ground, lattice
pylons, signal gantries and a low sun's flare.

* A glass pane's radiance is computed here by hand: the mirrored ray ``d - 2 (d.n) n`` of a
  vertical wall, Schlick's reflectance ``f0 + (1 - f0) (1 - cos)^5`` and the sky model's
  radiance of that direction.
* Reflectivity never changes the ground truth: the same world with dull materials in place of
  the mirrors has the same true masks and the same labels.
* Pylon legs block only within the first Fresnel zone rule's distance, ``(w / 0.1)^2 /
  0.1903`` m for a leg of width ``w`` (21 m for 0.2 m), computed here.
* The flare of a low sun stays inside the image (a fisheye's corners stay black) and leaves
  the label alone.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from predisat.camera.models import CameraModel, Mount
from predisat.gnss.fresnel import L1_WAVELENGTH_M
from predisat.synth.materials import MATERIAL_IDS, MATERIALS, material_id
from predisat.synth.render import (
    GLASS_PANE_M,
    Casters,
    RenderOptions,
    camera_pose,
    render_frame,
    render_radiance,
)
from predisat.synth.sky import SkyModel
from predisat.synth.truth import true_masks
from predisat.synth.world import MIXED_KINDS, OOD_KINDS, Stretch, World, WorldSpec
from tests.predisat.synth.test_world import straight_track


@dataclass(frozen=True)
class _Scene:
    vertices_m: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    seed: int = 0

    @property
    def blocking_faces(self) -> np.ndarray:
        return np.array([m.blocks_lband for m in MATERIALS])[self.face_material]


def _look(az_deg: float, pitch_deg: float) -> np.ndarray:
    a, p = np.radians(az_deg), np.radians(pitch_deg)
    fwd = np.array([np.sin(a) * np.cos(p), np.cos(a) * np.cos(p), np.sin(p)])
    right = np.array([np.cos(a), -np.sin(a), 0.0])
    return np.column_stack([right, np.cross(fwd, right), fwd])


WALL_Y = 20.0


def _glass_wall_scene() -> _Scene:
    """Grass ground and a glass wall in the plane y = 20 m facing the camera (south)."""
    ground = trimesh.creation.box(extents=(400.0, 400.0, 1.0))
    ground.apply_translation((0.0, 0.0, -0.5))
    wall = trimesh.creation.box(extents=(80.0, 2.0, 60.0))
    wall.apply_translation((0.0, WALL_Y + 1.0, 30.0))
    v = np.vstack([ground.vertices, wall.vertices])
    f = np.vstack([ground.faces, wall.faces + len(ground.vertices)]).astype(np.int32)
    m = np.concatenate([np.full(len(ground.faces), material_id("grass")),
                        np.full(len(wall.faces), material_id("glass"))]).astype(np.int16)
    return _Scene(v, f, m)


def test_glass_pane_shows_the_sky_of_the_mirrored_ray() -> None:
    scene = _glass_wall_scene()
    casters = Casters.for_world(scene, "open3d")
    cam = CameraModel.pinhole_from_fov(120, 90, 70.0)
    pos = np.array([0.0, 0.0, 3.0])
    rot = _look(0.0, 25.0)  # looking north at the wall, up into its reflection of the sky
    sky = SkyModel.cloudy(0.0, 40.0, seed=4)  # sun behind the wall: no direct sun on it
    opt = RenderOptions(supersample=1, ambient_rays=0, shadows=False, visibility_m=1e15)
    rad, label = render_radiance(scene, casters, cam, (pos, rot), sky, np.random.default_rng(0),
                                 opt, elapsed_s=0.0)  # fmt: skip
    u, v = cam.pixel_grid()
    d = cam.pixel_to_ray(u, v).reshape(-1, 3) @ rot.T
    t = WALL_Y / d[:, 1]
    p = pos + d * t[:, None]
    # pane pixels: well inside a pane of the documented curtain-wall module
    fu, fv = np.mod(p[:, 0], GLASS_PANE_M[0]), np.mod(p[:, 2], GLASS_PANE_M[1])
    pane = (fu > 0.3) & (fu < 1.2) & (fv > 1.2) & (fv < 3.3) & (d[:, 2] > 0.05) & (p[:, 2] < 59)
    assert pane.sum() > 500
    n = np.array([0.0, -1.0, 0.0])
    mirrored = d - 2.0 * (d @ n)[:, None] * n
    cos = -(d @ n)
    glass = MATERIALS[material_id("glass")]
    r = glass.f0 + (1.0 - glass.f0) * (1.0 - cos) ** 5
    sky_refl = sky.radiance(mirrored[pane], p[pane], 0.0)
    diffuse = np.asarray(glass.albedo_rgb) * sky.ambient_radiance(n[None, :])
    expected = (1 - r[pane, None]) * diffuse + r[pane, None] * np.asarray(glass.tint_rgb) * sky_refl
    got = rad.reshape(-1, 3)[pane]
    np.testing.assert_allclose(got, expected, rtol=2e-3, atol=1e-4)
    # the mirror carries the clouds: the reflected part varies as much as the sky does
    assert np.std(sky_refl[:, 0]) > 0.05 * np.mean(sky_refl[:, 0])
    # the label says obstacle: a mirror of the sky is no sky
    assert np.all(label.ravel()[pane] == 0)


def _ood_world(wet: bool, seed: int = 5) -> World:
    track = straight_track(1500.0)
    spec = WorldSpec.from_stretches(
        [("open", 100, 300), ("glass_street", 300, 500), ("white_street", 500, 650, "left"),
         ("water", 500, 650, "right"), ("station", 650, 850), ("gantry", 700, 701.2),
         ("pylons", 100, 900, "left"), ("open", 850, 900)], wet=wet, hills=False,
    )  # fmt: skip
    return World.build(track, spec, seed=seed)


@pytest.fixture(scope="module")
def wet_world() -> World:
    return _ood_world(wet=True)


def test_ood_kinds_build_with_their_materials(wet_world: World) -> None:
    used = {MATERIALS[i].name for i in np.unique(wet_world.face_material)}
    assert {"glass", "white_facade", "water", "wet_platform", "wet_ballast", "lattice_leg",
            "lattice", "conductor"} <= used  # fmt: skip
    assert "platform" not in used and "ballast" not in used  # all wet after rain
    dry = _ood_world(wet=False)
    assert np.array_equal(dry.vertices_m, wet_world.vertices_m)  # wetness is paint only
    assert set(OOD_KINDS).isdisjoint(MIXED_KINDS)
    for seed in range(4):  # the fitted-on worlds never draw them
        assert WorldSpec.mixed(0.0, 2000.0, seed=seed).kinds.isdisjoint(OOD_KINDS)
    assert WorldSpec.from_dict(wet_world.spec.to_dict()) == wet_world.spec


_DULL = {"glass": "brick", "white_facade": "plaster", "water": "grass",
         "wet_platform": "platform", "wet_ballast": "ballast"}  # fmt: skip


def test_reflectivity_never_changes_the_truth(wet_world: World) -> None:
    remap = np.arange(len(MATERIALS), dtype=np.int16)
    for shiny, dull in _DULL.items():
        remap[MATERIAL_IDS[shiny]] = MATERIAL_IDS[dull]
    dull_world = replace(wet_world, face_material=remap[wet_world.face_material])
    s = np.array([400.0, 580.0, 760.0])
    a = true_masks(wet_world, s, az_step_deg=2.0)
    b = true_masks(dull_world, s, az_step_deg=2.0)
    np.testing.assert_array_equal(a.mask_el_deg, b.mask_el_deg)
    # the glass and white blocks are solid: the street's skyline is high on both sides
    assert np.percentile(a.mask_el_deg[0], 90) > 25.0
    cam = CameraModel.pinhole_from_fov(96, 72, 80.0)
    sky = SkyModel.clear(120.0, 8.0)
    for world in (wet_world, dull_world):
        labels = []
        for s_m, side in ((400.0, "left"), (580.0, "right"), (760.0, "left")):
            pose = camera_pose(world, s_m, Mount.default(side))
            _, lab = render_frame(world, Casters.for_world(world), cam, pose, sky,
                                  np.random.default_rng(1))  # fmt: skip
            labels.append(lab)
        if world is wet_world:
            first = labels
    for x, y in zip(first, labels, strict=True):
        np.testing.assert_array_equal(x, y)


def _leg_limit_m(width_m: float) -> float:
    """Distance within which a structure of ``width_m`` blocks: w = 0.1 sqrt(lambda d)."""
    return (width_m / 0.1) ** 2 / L1_WAVELENGTH_M


def test_pylon_members_are_no_wider_than_their_truth_widths() -> None:
    track = straight_track(1500.0)
    spec = WorldSpec.from_stretches([("pylons", 200, 800, "left")], catenary=False, hills=False)
    world = World.build(track, spec, seed=2)
    for name in ("lattice_leg", "lattice", "conductor"):
        faces = world.faces[world.face_material == material_id(name)]
        # every beam is 12 faces over 8 corners; its cross-section edges are the shortest
        corners = world.vertices_m[np.unique(faces)].reshape(-1, 8, 3)
        side = np.linalg.norm(corners[:, 0] - corners[:, 3], axis=-1)  # across, at one end
        assert side.max() <= MATERIALS[material_id(name)].width_m + 1e-9
        assert side.min() > 0.02


@pytest.mark.parametrize("dist_m, blocks", [(12.0, True), (40.0, False)])
def test_pylon_legs_block_only_within_the_fresnel_distance(dist_m: float, blocks: bool) -> None:
    assert (dist_m < _leg_limit_m(0.2)) == blocks  # 21.0 m for a 0.2 m leg
    track = straight_track(1500.0)
    spec = WorldSpec.from_stretches(
        [Stretch("pylons", 200, 800, "left", {"pylon_distance_m": dist_m, "span_m": 250.0,
                                              "pylon_height_m": 30.0})],
        catenary=False, hills=False,
    )  # fmt: skip
    world = World.build(track, spec, seed=2)
    leg_faces = world.faces[world.face_material == material_id("lattice_leg")]
    legs = world.vertices_m[np.unique(leg_faces)]
    proj = track.project_enu(legs)
    s_tower = float(np.median(proj.chainage_m[np.abs(proj.chainage_m - 200) < 200]))
    tm = true_masks(world, np.array([s_tower]), az_step_deg=1.0)
    el = tm.mask_el_deg[0]
    if blocks:  # the near leg rises far above the antenna: a high skyline toward it
        assert el.max() > 30.0
    else:  # every member is transparent: only the flat ground's horizon
        assert el.max() < 1.0


def test_low_sun_flare_stays_in_the_image_and_leaves_the_label() -> None:
    scene = _glass_wall_scene()
    casters = Casters.for_world(scene, "open3d")
    cam = CameraModel.fisheye_from_fov(128, 96, 240.0)  # a circle: its corners see nothing
    pos = np.array([0.0, 0.0, 3.0])
    rot = _look(180.0, 20.0)  # away from the wall, toward a low sun in the south
    sky = SkyModel.clear(175.0, 6.0)
    with_flare = render_frame(scene, casters, cam, (pos, rot), sky, np.random.default_rng(3))
    without = render_frame(scene, casters, cam, (pos, rot), sky, np.random.default_rng(3),
                           RenderOptions(glare=0.0))  # fmt: skip
    np.testing.assert_array_equal(with_flare[1], without[1])
    rays = cam.pixel_to_ray(*cam.pixel_grid())
    outside = ~np.all(np.isfinite(rays), axis=-1)
    assert outside.any() and np.all(with_flare[0][outside] == 0)
    diff = with_flare[0].astype(float).sum(-1) - without[0].astype(float).sum(-1)
    assert diff.max() > 60.0  # the veil and bloom are there
    # strongest near the sun's image
    su, sv = cam.ray_to_pixel((rot.T @ sky.sun_direction)[None, :])
    vv, uu = np.unravel_index(np.argmax(diff), diff.shape)
    assert np.hypot(uu - float(su[0]), vv - float(sv[0])) < 0.25 * cam.width_px


def test_the_shipped_recipe_has_every_ood_kind() -> None:
    import yaml

    recipe = Path(__file__).resolve().parents[3] / "surveys" / "ood_city.yaml"
    spec = WorldSpec.from_dict(yaml.safe_load(recipe.read_text()))
    assert set(OOD_KINDS) <= spec.kinds and "station" in spec.kinds and spec.wet
