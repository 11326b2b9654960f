"""Tests of the ray casters: analytic hits on a box, backend agreement, L-band filtering."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh
from numpy.typing import NDArray

from predisat.synth.materials import material_id
from predisat.synth.raycast import BACKENDS, Hits, make_caster
from predisat.synth.world import World, WorldSpec
from tests.predisat.synth.test_world import straight_track


@dataclass(frozen=True)
class Scene:
    """The part of a World that a caster reads."""

    vertices_m: NDArray
    faces: NDArray
    face_material: NDArray

    @property
    def blocking_faces(self) -> NDArray:
        return self.face_material == 0


def box_scene(centre_m=(0.0, 0.0, 0.0), extents_m=(2.0, 4.0, 6.0), thin_too: bool = False) -> Scene:
    box = trimesh.creation.box(extents=extents_m)
    v = np.asarray(box.vertices) + centre_m
    f = np.asarray(box.faces)
    m = np.zeros(len(f), np.int16)
    if thin_too:  # a thin sheet (material 1, not blocking) 1 m in front of the box's -x face
        x = centre_m[0] - extents_m[0] / 2 - 1.0
        y0, z0 = centre_m[1], centre_m[2]
        sheet = np.array([[x, y0 - 50, z0 - 50], [x, y0 + 50, z0 - 50], [x, y0 + 50, z0 + 50],
                          [x, y0 - 50, z0 + 50]])  # fmt: skip
        f = np.concatenate(
            [f, [[len(v), len(v) + 1, len(v) + 2], [len(v), len(v) + 2, len(v) + 3]]]
        )
        v = np.concatenate([v, sheet])
        m = np.concatenate([m, [1, 1]]).astype(np.int16)
    return Scene(v, f, m)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("centre", [(0.0, 0.0, 0.0), (9000.0, -7000.0, 300.0)])
def test_hits_on_a_box_are_exact(backend: str, centre) -> None:
    c = np.array(centre)
    caster = make_caster(box_scene(c), backend)
    rng = np.random.default_rng(0)
    # rays from points 20-50 m in -x of the box, aimed at random points of its -x face
    n = 500
    target = c + np.column_stack(
        [np.full(n, -1.0), rng.uniform(-1.9, 1.9, n), rng.uniform(-2.9, 2.9, n)]
    )
    origin = c + np.column_stack(
        [rng.uniform(-50, -20, n), rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)]
    )
    d = target - origin
    hits = caster.cast(origin, d)
    assert np.all(hits.hit)
    assert np.allclose(hits.distance_m, np.linalg.norm(d, axis=1), atol=1e-5)
    assert np.allclose(hits.normal, [-1.0, 0.0, 0.0], atol=1e-9)  # outward normal of that face
    # rays pointing away miss
    miss = caster.cast(origin, -d)
    assert not np.any(miss.hit) and np.all(np.isinf(miss.distance_m))
    assert np.all(miss.face_id == -1) and np.all(miss.normal == 0)
    assert np.array_equal(caster.occluded(origin, d), np.ones(n, bool))
    assert not np.any(caster.occluded(origin, -d))


@pytest.mark.parametrize("backend", BACKENDS)
def test_lband_only_drops_thin_faces_and_keeps_world_face_ids(backend: str) -> None:
    scene = box_scene(thin_too=True)
    o = np.array([[-20.0, 0.5, 0.5]])
    d = np.array([[1.0, 0.0, 0.0]])
    full = make_caster(scene, backend).cast(o, d)
    lband = make_caster(scene, backend, lband_only=True).cast(o, d)
    assert full.material_id(scene.face_material)[0] == 1
    assert full.distance_m[0] == pytest.approx(20.0 - 2.0, abs=1e-6)
    assert lband.material_id(scene.face_material)[0] == 0
    assert lband.distance_m[0] == pytest.approx(20.0 - 1.0, abs=1e-6)
    assert lband.face_id[0] < 12  # an index into the scene's faces: one of the box's


def test_backends_agree_on_a_mixed_world() -> None:
    track = straight_track(1300.0)
    world = World.build(track, WorldSpec.mixed(100.0, 1200.0, seed=11), seed=11)
    rng = np.random.default_rng(1)
    n = 20_000
    s = rng.uniform(120, 1180, n)
    origin = world.antenna_enu(s) + rng.normal(0, 1.0, (n, 3))
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) * 0.5
    a = make_caster(world, "open3d").cast(origin, d)
    b = make_caster(world, "trimesh").cast(origin, d)
    same_hit = a.hit == b.hit
    assert same_hit.mean() > 0.999
    both = a.hit & b.hit
    assert both.sum() > 0.3 * n
    close = np.abs(a.distance_m[both] - b.distance_m[both]) < 1e-3
    assert close.mean() > 0.999
    # wires are in the full scene: some rays end on them
    assert np.any(a.material_id(world.face_material) == material_id("wire"))


def test_bad_backend_and_rays_are_rejected() -> None:
    with pytest.raises(ValueError, match="backend"):
        make_caster(box_scene(), "optix")
    caster = make_caster(box_scene())
    with pytest.raises(ValueError, match="non-zero"):
        caster.cast(np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="shape"):
        caster.cast(np.zeros((1, 2)), np.ones((1, 2)))


def test_hits_material_helper() -> None:
    hits = Hits(np.array([1.0, np.inf]), np.array([2, -1]), np.zeros((2, 3)))
    assert list(hits.hit) == [True, False]
    assert list(hits.material_id(np.array([5, 6, 7]))) == [7, -1]
