"""Renderer checks on a small hand-built scene: labels against an independent Embree ray cast,
cast shadows against analytic shadow geometry, determinism of the camera model per seed."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh
from scipy import ndimage
from shapely.geometry import MultiPoint, Point

from predisat.camera.models import CameraModel
from predisat.synth.materials import MATERIALS, material_id
from predisat.synth.render import (
    LABEL_OBSTACLE,
    LABEL_SKY,
    LABEL_THIN,
    Casters,
    RenderOptions,
    SensorState,
    expose,
    render_frame,
    render_radiance,
)
from predisat.synth.sky import SkyModel

GRASS, CONCRETE, WIRE = material_id("grass"), material_id("concrete"), material_id("wire")
BOX = (8.0, 14.0, -3.0, 3.0, 0.0, 8.0)  # x0, x1, y0, y1, z0, z1 (m)


@dataclass(frozen=True)
class _Scene:
    """Stand-in for predisat.synth.world.World with the attributes the renderer uses."""

    vertices_m: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray
    seed: int = 0

    @property
    def blocking_faces(self) -> np.ndarray:
        return np.array([m.blocks_lband for m in MATERIALS])[self.face_material]


def _scene() -> _Scene:
    ground = trimesh.creation.box(extents=(400.0, 400.0, 1.0))
    ground.apply_translation((0.0, 0.0, -0.5))
    x0, x1, y0, y1, z0, z1 = BOX
    box = trimesh.creation.box(extents=(x1 - x0, y1 - y0, z1 - z0))
    box.apply_translation(((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))
    # a 6 cm wire (half a pixel at 160 x 120) across the view, 6 m in front of the camera,
    # sloping so that it crosses pixel rows
    wire = trimesh.creation.cylinder(radius=0.03, height=60.0, sections=8)
    wire.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    wire.apply_transform(trimesh.transformations.rotation_matrix(0.15, (1, 0, 0)))
    wire.apply_translation((6.0, 0.0, 9.0))
    meshes = [(ground, GRASS), (box, CONCRETE), (wire, WIRE)]
    v, f, m, off = [], [], [], 0
    for mesh, mat in meshes:
        v.append(mesh.vertices)
        f.append(mesh.faces + off)
        m.append(np.full(len(mesh.faces), mat, np.int16))
        off += len(mesh.vertices)
    return _Scene(np.vstack(v), np.vstack(f).astype(np.int32), np.concatenate(m))


def _look(az_deg: float, pitch_deg: float) -> np.ndarray:
    """Camera-to-ENU rotation of a level camera looking at an azimuth and pitch."""
    a, p = np.radians(az_deg), np.radians(pitch_deg)
    fwd = np.array([np.sin(a) * np.cos(p), np.cos(a) * np.cos(p), np.sin(p)])
    right = np.array([np.cos(a), -np.sin(a), 0.0])
    down = np.cross(fwd, right)
    return np.column_stack([right, down, fwd])


CAM = CameraModel.pinhole_from_fov(160, 120, 74.0, dist=(-0.08, 0.02, 0.0, 0.0, 0.0))
POS = np.array([0.0, 0.0, 3.0])


@pytest.fixture(scope="module")
def scene() -> _Scene:
    return _scene()


@pytest.fixture(scope="module")
def casters(scene: _Scene) -> Casters:
    return Casters.for_world(scene, "open3d")


def _embree_first(mesh: trimesh.Trimesh, o: np.ndarray, d: np.ndarray):
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    loc, ray, tri = RayMeshIntersector(mesh).intersects_location(o, d, multiple_hits=False)
    face = np.full(len(o), -1)
    point = np.full((len(o), 3), np.nan)
    face[ray], point[ray] = tri, loc
    return face, point


def test_label_matches_independent_embree_cast(scene: _Scene, casters: Casters) -> None:
    rot = _look(90.0, 45.0)
    sky = SkyModel.clear(200.0, 40.0)
    _, label = render_radiance(
        scene,
        casters,
        CAM,
        (POS, rot),
        sky,
        np.random.default_rng(0),
        RenderOptions(supersample=1, ambient_rays=0),
    )
    # expected: per pixel centre ray through trimesh + Embree on the raw mesh
    u, v = CAM.pixel_grid()
    d = CAM.pixel_to_ray(u, v).reshape(-1, 3) @ rot.T
    o = np.broadcast_to(POS, d.shape)
    full = trimesh.Trimesh(scene.vertices_m, scene.faces, process=False)
    face, _ = _embree_first(full, o, d)
    thick = scene.face_material != WIRE
    solid = trimesh.Trimesh(scene.vertices_m, scene.faces[thick], process=False)
    face_solid, _ = _embree_first(solid, o, d)
    expected = np.full(d.shape[0], LABEL_SKY, np.uint8)
    hit = face >= 0
    expected[hit] = LABEL_OBSTACLE
    on_wire = hit & (scene.face_material[np.maximum(face, 0)] == WIRE)
    expected[on_wire & (face_solid < 0)] = LABEL_THIN
    expected = expected.reshape(label.shape)
    assert (expected == LABEL_THIN).sum() > 20  # the wire is in view
    assert (expected == LABEL_OBSTACLE).sum() > 1000 and (expected == LABEL_SKY).sum() > 1000
    equal = label == expected
    assert equal.mean() >= 0.995
    # every disagreement sits on a boundary between labels
    edges = np.zeros_like(equal)
    for val in (LABEL_SKY, LABEL_THIN, LABEL_OBSTACLE):
        m = expected == val
        edges |= ndimage.binary_dilation(m) & ~m
        edges |= m & ~ndimage.binary_erosion(m)
    assert np.all(edges[~equal])


def test_box_shadow_is_darker_than_sunlit_ground(scene: _Scene, casters: Casters) -> None:
    sun_az, sun_el = 250.0, 35.0  # the sun in the west-south-west: shadow east of the box
    sky = SkyModel.clear(sun_az, sun_el)
    pos = np.array([10, -14, 16])
    rot = _look(20, -50)  # looking down at the ground east of the box
    rad, _ = render_radiance(
        scene,
        casters,
        CAM,
        (pos, rot),
        sky,
        np.random.default_rng(1),
        RenderOptions(supersample=1, ambient_rays=0),
    )
    # analytic shadow: the box's base and its top corners projected along the sun onto z = 0
    s = sky.sun_direction
    x0, x1, y0, y1, _, z1 = BOX
    corners = np.array([(x, y) for x in (x0, x1) for y in (y0, y1)])
    top = corners - s[:2] * (z1 / s[2])
    shadow = MultiPoint(np.vstack([corners, top]).tolist()).convex_hull
    box_fp = MultiPoint(corners.tolist()).convex_hull
    u, v = CAM.pixel_grid()
    d = CAM.pixel_to_ray(u, v).reshape(-1, 3) @ rot.T
    full = trimesh.Trimesh(scene.vertices_m, scene.faces, process=False)
    face, gp = _embree_first(full, np.broadcast_to(pos, d.shape), d)
    ground = (face >= 0) & (scene.face_material[np.maximum(face, 0)] == GRASS)
    lum = rad.reshape(-1, 3) @ np.array([0.2126, 0.7152, 0.0722])
    inside, lit = [], []
    for k in np.flatnonzero(ground):
        pt = Point(gp[k, 0], gp[k, 1])
        if box_fp.buffer(0.5).contains(pt):
            continue  # ambient occlusion is strong at the foot of the box
        dist = shadow.exterior.distance(pt)
        if dist < 0.5:
            continue
        (inside if shadow.contains(pt) else lit).append(lum[k])
    assert len(inside) > 100 and len(lit) > 100
    assert np.mean(inside) < 0.5 * np.mean(lit)


def test_frames_are_deterministic_per_seed(scene: _Scene, casters: Casters) -> None:
    rot = _look(90.0, 45.0)
    sky = SkyModel.cloudy(120.0, 50.0, seed=3)
    opt = RenderOptions(supersample=2, ambient_rays=1)
    a, la = render_frame(scene, casters, CAM, (POS, rot), sky, np.random.default_rng(7), opt)
    b, lb = render_frame(scene, casters, CAM, (POS, rot), sky, np.random.default_rng(7), opt)
    c, lc = render_frame(scene, casters, CAM, (POS, rot), sky, np.random.default_rng(8), opt)
    assert a.dtype == np.uint8 and a.shape == (CAM.height_px, CAM.width_px, 3)
    assert np.array_equal(a, b) and np.array_equal(la, lb)
    assert not np.array_equal(a, c)  # noise, jitter and exposure differ
    assert np.array_equal(la, lc)  # the label does not depend on the camera's randomness
    opt = RenderOptions()
    s1 = SensorState.draw(np.random.default_rng(3), opt)
    s2 = SensorState.draw(np.random.default_rng(3), opt)
    s3 = SensorState.draw(np.random.default_rng(4), opt)
    assert s1 == s2 and s1 != s3


def test_wire_thinner_than_a_pixel_shows_as_a_faint_line(scene: _Scene, casters: Casters) -> None:
    rot = _look(90.0, 45.0)
    sky = SkyModel.overcast(200.0, 40.0)
    rad, label = render_radiance(
        scene,
        casters,
        CAM,
        (POS, rot),
        sky,
        np.random.default_rng(2),
        RenderOptions(supersample=4, ambient_rays=0),
    )
    lum = rad @ np.array([0.2126, 0.7152, 0.0722])
    rows, cols = np.nonzero(label == LABEL_THIN)
    assert rows.size > 10
    on = lum[rows, cols]
    above = lum[np.maximum(rows - 3, 0), cols]  # sky three pixels above the wire
    wire_alone = float(MATERIALS[WIRE].albedo_rgb[1]) * float(
        sky.ambient_radiance(np.array([0.0, 0.0, 1.0])) @ np.array([0.2126, 0.7152, 0.0722])
    )
    # partial coverage: darker than the sky, brighter than a pixel filled by the wire
    assert np.median(on) < 0.97 * np.median(above)
    assert np.median(on) > 1.5 * wire_alone


def test_auto_exposure_compensates_scene_brightness() -> None:
    rng = np.random.default_rng(0)
    base = rng.uniform(0.5, 3.0, (CAM.height_px, CAM.width_px, 3))
    state = SensorState(0.0, 0.5, (1.0, 1.0, 1.0), 11)
    opt = RenderOptions(glare=0.0)
    a = expose(base, CAM, state, opt).astype(float)
    b = expose(base * 4.0, CAM, state, opt).astype(float)
    assert abs(a.mean() - b.mean()) < 1.0
    brighter = SensorState(1.0, 0.5, (1.0, 1.0, 1.0), 11)
    assert expose(base, CAM, brighter, opt).mean() > a.mean() + 10


def test_more_full_well_means_less_noise() -> None:
    flat = np.full((CAM.height_px, CAM.width_px, 3), 2.0)
    state = SensorState(0.0, 0.0, (1.0, 1.0, 1.0), 5)
    centre = (slice(40, 80), slice(60, 100))  # away from vignetting
    noisy = expose(flat, CAM, state, RenderOptions(full_well_e=300.0, glare=0.0))[centre]
    clean = expose(flat, CAM, state, RenderOptions(full_well_e=30000.0, glare=0.0))[centre]
    assert noisy.std() > 3.0 * clean.std()


def test_bad_pose_is_rejected(scene: _Scene, casters: Casters) -> None:
    with pytest.raises(ValueError, match="rotation"):
        render_radiance(
            scene,
            casters,
            CAM,
            (POS, np.eye(3) * 2),
            SkyModel.clear(0, 30),
            np.random.default_rng(0),
        )
