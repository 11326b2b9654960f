"""The far field's elevation bound from a camera that stands away from the antenna: against
brute-force geometry, and masks over far walls from a survey shifted along the track against
the ray-cast truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import predisat.reconstruct.carving as carving
from predisat.masks.maskset import BinSource
from predisat.reconstruct.carving import Reconstructor, far_elevation_bound
from predisat.synth.materials import MATERIAL_IDS
from predisat.synth.truth import true_masks
from predisat.synth.world import Stretch, World, WorldSpec
from tests.predisat.reconstruct.test_carving import PARAMS
from tests.predisat.reconstruct.test_placement import _placed
from tests.predisat.synth.test_world import straight_track


def _views(seed: int):
    """A camera's offset, doubt and rise, far points (at least W = 40 m away from the antenna,
    every azimuth, heights from below the antenna to far above it) and, from cameras on the
    doubt's circle and at its centre, at the rise and below it: what each camera saw and the
    elevation from the antenna."""
    rng = np.random.default_rng(seed)
    w = 40.0
    offset = rng.uniform(-4.0, 4.0, 2)
    doubt = float(rng.choice([0.0, rng.uniform(0.0, 3.0)]))
    rise = float(rng.uniform(-1.0, 1.0))
    az = rng.uniform(0.0, 360.0, 4000)
    dist = w * np.exp(rng.uniform(0.0, 3.0, az.size)) ** rng.choice([0.0, 1.0], az.size)
    up = dist * np.tan(np.radians(rng.uniform(-20.0, 75.0, az.size)))
    obj = np.stack([dist * np.sin(np.radians(az)), dist * np.cos(np.radians(az)), up], axis=1)
    el_ant = np.degrees(np.arctan2(obj[:, 2], dist))
    ang = rng.uniform(0.0, 2.0 * np.pi, 24)
    places = offset + doubt * np.stack([np.sin(ang), np.cos(ang)], axis=1)
    places = np.vstack([places, offset])
    for xy in places:
        for z in (min(rise, 0.0) - 0.3, rise):
            rel = obj - np.array([xy[0], xy[1], z])
            el_cam = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
            yield el_cam, az, offset, rise, doubt, w, el_ant


@pytest.mark.parametrize("seed", range(6))
def test_the_bound_holds_every_far_object_from_every_place_within_the_doubt(seed: int) -> None:
    """Far points seen from every camera place within the doubt: the elevation from the
    antenna is never above the bound of what a camera saw, and somewhere it comes within 0.1
    deg of it (the bound is not loose)."""
    worst_gap = np.inf
    for el_cam, az, offset, rise, doubt, w, el_ant in _views(seed):
        bound = far_elevation_bound(el_cam, az, offset, rise, doubt, w)
        assert np.all(bound >= el_ant - 1e-9), float((el_ant - bound).max())
        worst_gap = min(worst_gap, float((bound - el_ant).min()))
    assert worst_gap < 0.1


def test_every_part_of_the_bound_is_needed() -> None:
    """The same cases: the skyline alone, the bound without the doubt, without the rise, each
    falls below some far point's elevation from the antenna."""
    variants = {
        "skyline": lambda el, az, o, r, d, w: np.asarray(el, float),
        "no doubt": lambda el, az, o, r, d, w: far_elevation_bound(el, az, o, r, 0.0, w),
        "no rise": lambda el, az, o, r, d, w: far_elevation_bound(el, az, o, min(r, 0.0), d, w),
    }
    for name, bound in variants.items():
        broken = any(
            np.any(bound(el_cam, az, offset, rise, doubt, w) < el_ant - 1e-6)
            for seed in range(6)
            for el_cam, az, offset, rise, doubt, w, el_ant in _views(seed)
        )
        assert broken, name


def test_the_bound_keeps_what_was_not_a_skyline_and_is_the_identity_at_the_antenna() -> None:
    el = np.array([-5.0, 0.0, 30.0, np.inf, np.nan])
    az = np.array([0.0, 90.0, 180.0, 270.0, 45.0])
    same = far_elevation_bound(el, az, [0.0, 0.0], 0.0, 0.0, 40.0)
    np.testing.assert_allclose(same[:3], el[:3], atol=1e-12)
    assert np.isposinf(same[3]) and np.isnan(same[4])
    with pytest.raises(ValueError, match="far_m"):
        far_elevation_bound(el, az, [0.0, 0.0], 0.0, -1.0, 40.0)


def _fin_world() -> World:
    """A straight track, open, with thin concrete walls 40 m high beyond the corridor: from 60
    to 160 m away at 45 deg to the track, ahead and behind on both sides of three chainages
    (a far object whose distance changes when the camera moves along the track)."""
    az = 60.0
    track = straight_track(900.0, az)
    base = World.build(track, WorldSpec((Stretch("open", 100.0, 800.0, "both"),), False, False),
                       seed=1)  # fmt: skip
    a = np.radians(az)
    along = np.array([np.sin(a), np.cos(a)])
    left = np.array([-np.cos(a), np.sin(a)])
    z0 = float(track.enu_at(400.0)[2]) - 1.0
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    sides = np.vstack([quad, quad + 4] + [np.array([[k, (k + 1) % 4, 4 + (k + 1) % 4],
                                                     [k, 4 + (k + 1) % 4, 4 + k]])
                                          for k in range(4)])  # fmt: skip
    verts, faces = [base.vertices_m], [base.faces]
    n = base.vertices_m.shape[0]
    for c0 in (300.0, 400.0, 500.0):
        o = np.asarray(track.enu_at(c0), float)[:2]
        for side in (left, -left):
            for sign in (1.0, -1.0):
                u = (sign * along + side) / np.sqrt(2.0)
                half = np.array([-u[1], u[0]]) * 0.3
                foot = [o + 60 * u - half, o + 60 * u + half, o + 160 * u + half,
                        o + 160 * u - half]  # fmt: skip
                v = np.array([[*q, z0] for q in foot] + [[*q, z0 + 40.0] for q in foot])
                verts.append(v)
                faces.append(sides + n)
                n += 8
    new = sum(len(f) for f in faces[1:])
    material = np.concatenate(
        [base.face_material, np.full(new, MATERIAL_IDS["concrete"], np.int16)]
    )
    faces_all = np.concatenate(faces).astype(np.int32)
    return replace(base, vertices_m=np.concatenate(verts), faces=faces_all,
                   face_material=material)  # fmt: skip


def test_far_walls_seen_from_a_shifted_survey_stay_under_the_mask(monkeypatch) -> None:
    """The survey's chainages 3 m off, bounded as a shift of the whole survey (section 18):
    without the elevation bound the far walls stand up to tenths of a degree above the mask
    (the azimuth allowance alone does not cover a camera farther from them); with it, no
    supported bin is below the ray-cast truth."""
    world = _fin_world()
    stated = np.arange(200.0, 601.0, 10.0)
    frames = _placed(world, stated, np.full(stated.shape, 3.0), 0.0)
    s = np.arange(290.0, 511.0, 10.0)
    truth = true_masks(world, s).mask_el_deg

    def worst_under() -> float:
        rec = Reconstructor(replace(PARAMS, chainage_shift_m=3.0)).run(frames, s, world.track)
        supported = rec.source != BinSource.ASSUMED
        return float((truth - rec.mask_el_deg)[supported].max())

    assert worst_under() <= 0.05
    monkeypatch.setattr(carving, "far_elevation_bound", lambda el, *a: np.asarray(el, float))
    assert worst_under() > 0.15
