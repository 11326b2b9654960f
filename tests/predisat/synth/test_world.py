"""Tests of the synthetic corridor world: recipes, reproducibility, realistic geometry, I/O."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh
import yaml

from predisat.geodesy import WGS84
from predisat.synth.materials import MATERIALS, material_id
from predisat.synth.scenery import Corridor, extrude
from predisat.synth.world import MIXED_KINDS, OOD_KINDS, STRETCH_KINDS, Stretch, World, WorldSpec
from predisat.terrain import DemError
from predisat.track.map import TrackMap

LAT0, LON0, H0 = 50.55, 4.70, 150.0


def straight_track(length_m: float = 1500.0, azimuth_deg: float = 60.0, **kw) -> TrackMap:
    """A geodesic (locally straight) track, vertices every 50 m."""
    d = np.arange(0.0, length_m + 1e-9, 50.0)
    lon, lat, _ = WGS84.fwd(
        np.full(d.size, LON0), np.full(d.size, LAT0), np.full(d.size, azimuth_deg), d
    )
    return TrackMap.from_latlon(lat, lon, H0, name="straight", **kw)


def curved_track(radius_m: float = 600.0, length_m: float = 1200.0) -> TrackMap:
    """A circular arc turning left, vertices every 10 m."""
    a = np.arange(0.0, length_m + 1e-9, 10.0) / radius_m
    e, n = radius_m * np.sin(a), radius_m * (1 - np.cos(a))  # heading east, turning north
    lon, lat, _ = WGS84.fwd(
        np.full(a.size, LON0), np.full(a.size, LAT0), np.degrees(np.arctan2(e, n)), np.hypot(e, n)
    )
    return TrackMap.from_latlon(lat, lon, H0, name="arc", tolerance_m=0.05)


@pytest.fixture(scope="module")
def track() -> TrackMap:
    return straight_track(2600.0)


@pytest.fixture(scope="module")
def mixed_world(track: TrackMap) -> World:
    return World.build(track, WorldSpec.mixed(100.0, 2600.0, seed=3), seed=3)


def _project(world: World, material: str):
    """Projection (chainage, left offset, height above the axis) of a material's vertices."""
    faces = world.faces[world.face_material == material_id(material)]
    return world.track.project_enu(world.vertices_m[np.unique(faces)])


def test_mixed_has_every_kind_in_2km() -> None:
    for seed in range(6):
        spec = WorldSpec.mixed(0.0, 2000.0, seed=seed)
        assert spec.kinds == set(MIXED_KINDS)
        assert spec.extent_m == pytest.approx((0.0, 2000.0))
        base = sorted(
            (s for s in spec.stretches if s.kind != "overbridge"), key=lambda s: s.start_m
        )
        # the base stretches tile the interval; the tunnel is neither first nor last
        assert all(a.end_m == pytest.approx(b.start_m) for a, b in itertools.pairwise(base))
        assert base[0].kind != "tunnel" and base[-1].kind != "tunnel"
        bridge = next(s for s in spec.stretches if s.kind == "overbridge")
        assert 8.0 <= bridge.end_m - bridge.start_m <= 15.0


def test_same_seed_same_mesh_different_seed_different(track: TrackMap, mixed_world: World) -> None:
    again = World.build(track, WorldSpec.mixed(100.0, 2600.0, seed=3), seed=3)
    assert np.array_equal(again.vertices_m, mixed_world.vertices_m)
    assert np.array_equal(again.faces, mixed_world.faces)
    assert np.array_equal(again.face_material, mixed_world.face_material)
    other = World.build(track, WorldSpec.mixed(100.0, 2600.0, seed=3), seed=4)
    assert other.vertices_m.shape != mixed_world.vertices_m.shape or not np.allclose(
        other.vertices_m, mixed_world.vertices_m
    )


def test_editing_one_stretch_leaves_the_others(track: TrackMap) -> None:
    a = WorldSpec.from_stretches([("trees", 100, 300, "left"), ("town", 400, 600)], catenary=False)
    b = WorldSpec.from_stretches([("trees", 100, 300, "left"), ("town", 400, 700)], catenary=False)
    wa, wb = World.build(track, a, seed=1), World.build(track, b, seed=1)
    fa = wa.vertices_m[np.unique(wa.faces[wa.face_material == material_id("foliage")])]
    fb = wb.vertices_m[np.unique(wb.faces[wb.face_material == material_id("foliage")])]
    assert np.array_equal(fa, fb)


def test_modest_triangle_count(mixed_world: World) -> None:
    # 2.5 km of every kind of scenery stays well under 2 million triangles
    assert 10_000 < len(mixed_world.faces) < 2_000_000
    assert mixed_world.faces.dtype == np.int32 and mixed_world.face_material.dtype == np.int16
    assert mixed_world.faces.max() < len(mixed_world.vertices_m)
    # every material but those of the out-of-distribution kinds (tests/.../test_ood.py)
    ood = {"glass", "white_facade", "water", "wet_platform", "wet_ballast", "lattice_leg",
           "lattice", "conductor"}  # fmt: skip
    assert set(np.unique(mixed_world.face_material)) == {
        i for i, m in enumerate(MATERIALS) if m.name not in ood
    }


def test_lband_policy() -> None:
    for m in MATERIALS:
        assert m.blocks_lband != m.thin  # thin structures never block, everything else does
        assert len(m.albedo_rgb) == 3 and all(0.0 <= c <= 1.0 for c in m.albedo_rgb)
    assert {m.name for m in MATERIALS if m.thin} == {
        "wire", "cantilever", "lattice_leg", "lattice", "conductor"
    }
    assert STRETCH_KINDS == MIXED_KINDS + OOD_KINDS


def test_catenary_dimensions(mixed_world: World) -> None:
    masts = _project(mixed_world, "steel")
    cat = np.abs(masts.offset_m) < 4.0  # station canopy columns stand further out
    off = np.abs(masts.offset_m[cat])
    assert 2.3 < off.min() and off.max() < 3.7
    assert 7.0 <= masts.height_m[cat].max() <= 8.0
    # mast spacing ~60 m: one group of vertices per mast
    s = np.unique(np.round(masts.chainage_m[cat] / 5.0))
    gaps = np.diff(np.sort(s)) * 5.0
    assert np.median(gaps[gaps > 20]) == pytest.approx(60.0, abs=6.0)
    wires = _project(mixed_world, "wire")
    z = wires.height_m
    contact, messenger = z[z < 5.8], z[z >= 5.8]
    assert np.all(np.abs(contact - 5.5) < 0.02)  # contact wire 5.5 m above the rail
    assert 6.5 <= messenger.max() <= 6.92 and messenger.min() > 6.0
    assert np.abs(wires.offset_m).max() < 0.25  # staggered +-0.2 m about the axis


def test_station_and_town_dimensions(track: TrackMap) -> None:
    spec = WorldSpec.from_stretches(
        [("station", 200, 450, "both"), ("town", 600, 1000, "both")], catenary=False
    )
    w = World.build(track, spec, seed=5)
    canopy = _project(w, "canopy")
    assert 2.0 - 1e-6 <= np.abs(canopy.offset_m).min() <= 3.0 + 1e-6  # overhanging edge
    assert 3.7 <= canopy.height_m.min() and canopy.height_m.max() <= 4.76 + 0.7 + 1e-6
    plaster_brick = [_project(w, m) for m in ("brick", "plaster")]
    town = [p for p in plaster_brick if np.any(p.chainage_m > 550)]
    off = np.concatenate([np.abs(p.offset_m[p.chainage_m > 550]) for p in town])
    hgt = np.concatenate([p.height_m[p.chainage_m > 550] for p in town])
    assert off.min() >= 5.0 - 1e-6 and off.min() <= 8.0
    assert 6.0 <= hgt.max() <= 25.0 + 1e-6
    station = plaster_brick[0]
    st = station.chainage_m < 500
    assert np.abs(station.offset_m[st]).min() >= 6.0 - 1e-6
    assert 4.0 <= station.height_m[st].max() <= 9.0 + 0.25 * 14 + 1e-6  # wall + gable roof


def test_rock_walls_and_tunnel_dimensions(track: TrackMap) -> None:
    spec = WorldSpec.from_stretches(
        [
            Stretch("rock_walls", 200, 500, "both", {"height_m": 60.0, "distance_m": 7.0}),
            Stretch("tunnel", 700, 950),
        ],
        catenary=False,
    )
    w = World.build(track, spec, seed=2)
    rock = _project(w, "rock")
    assert np.abs(rock.offset_m).min() >= 7.0 - 1e-6
    assert rock.height_m.max() == pytest.approx(60 * 1.15, rel=0.02)
    lining = _project(w, "concrete")
    inside = (lining.chainage_m > 710) & (lining.chainage_m < 940)
    assert lining.height_m[inside].max() > 7.5  # crown clears the messenger wire
    assert np.abs(lining.offset_m[inside]).max() < 5.0 + 1e-6


def test_objects_follow_a_curve() -> None:
    arc = curved_track(600.0, 1200.0)
    spec = WorldSpec.from_stretches(
        [Stretch("rock_walls", 100, 1100, "left", {"distance_m": 10.0, "roughness_m": 0.0,
                                                   "batter": 0.0, "height_m": 20.0})],
        catenary=False, hills=False,
    )  # fmt: skip
    w = World.build(arc, spec, seed=0)
    # the wall face stays 10 m from the axis all along the curve: its vertices at the face
    # lie on a circle of radius 600 - 10 m about the arc's centre (independent of the track fit)
    faces = w.faces[w.face_material == material_id("rock")]
    v = w.vertices_m[np.unique(faces)]
    centre = w.frame.to_enu(*WGS84.fwd(LON0, LAT0, 0.0, 600.0)[1::-1], H0)
    r = np.hypot(v[:, 0] - centre[0], v[:, 1] - centre[1])
    front, back = r[r > 589.0], r[r < 583.0]  # face at 10 m, back of the rock 8 m behind
    assert front.size > 100 and np.all(np.abs(front - 590.0) < 0.05)
    assert back.size > 100 and np.all(np.abs(back - 582.0) < 0.05)


def test_extrude_is_a_closed_solid_with_the_right_volume(track: TrackMap) -> None:
    cor = Corridor.from_track(track, 0.0, 400.0)
    prof = np.array([[2.0, 0.0], [5.0, 0.0], [5.0, 3.0], [2.0, 4.0]])  # area 10.5 m2
    for profile in (prof, prof[::-1]):
        v, f, is_cap = extrude(cor, np.linspace(50.0, 250.0, 41), profile)
        assert is_cap.sum() == 2 * 4  # two fan caps of four triangles
        mesh = trimesh.Trimesh(v, f, process=True)
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume == pytest.approx(10.5 * 200.0, rel=1e-4)  # positive: faces outward
    band = np.array([[-3.0, 0.0], [0.0, 3.0], [3.0, 0.0], [2.0, 0.0], [0.0, 2.0], [-2.0, 0.0]])
    v, f, _ = extrude(cor, np.linspace(0.0, 10.0, 3), band, cap="strip")
    mesh = trimesh.Trimesh(v, f, process=True)
    assert mesh.is_watertight and mesh.volume == pytest.approx(5.0 * 10.0, rel=1e-6)


def test_world_bodies_are_closed(mixed_world: World) -> None:
    keep = np.isin(mixed_world.face_material, [material_id(n) for n in ("rock", "brick", "steel")])
    mesh = trimesh.Trimesh(mixed_world.vertices_m, mixed_world.faces[keep], process=True)
    bodies = mesh.split(only_watertight=False)
    closed = np.mean([b.is_watertight and b.volume > 0 for b in bodies])
    assert closed == 1.0


def test_antenna_is_above_the_rail_along_the_local_vertical(mixed_world: World) -> None:
    s = np.array([150.0, 1300.0, 2500.0])
    ant = mixed_world.antenna_enu(s, 4.0)
    lat, lon, h = mixed_world.frame.to_geodetic(ant)
    lat0, lon0, h0 = mixed_world.track.position_at(s)
    assert np.allclose(h - h0, 4.0, atol=1e-6)
    _, _, dist = WGS84.inv(lon0, lat0, lon, lat)
    assert np.all(dist < 1e-4)


def test_spec_dict_round_trip_through_yaml() -> None:
    spec = WorldSpec.mixed(0.0, 1500.0, seed=9, hills=False)
    text = yaml.safe_dump(spec.to_dict())
    back = WorldSpec.from_dict(yaml.safe_load(text))
    assert back == spec
    recipe = yaml.safe_load(
        "stretches:\n- {kind: rock_walls, start_m: 0, end_m: 300, side: left,"
        " params: {height_m: 40}}\n- {kind: tunnel, start_m: 300, end_m: 500}\ncatenary: false\n"
    )
    spec = WorldSpec.from_dict(recipe)
    assert spec.stretches[0].params == {"height_m": 40.0} and not spec.catenary


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("canyon", 0, 10), "unknown"),
        (("tunnel", 0, 100, "left"), "spans the track"),
        (("town", 50, 50), "start_m < end_m"),
        (("town", 0, 50, "up"), "side"),
    ],
)
def test_bad_stretches_are_rejected(args, match) -> None:
    with pytest.raises(ValueError, match=match):
        Stretch(*args)


def test_recipe_longer_than_the_track_is_rejected() -> None:
    short = straight_track(500.0)
    with pytest.raises(ValueError, match="track is"):
        World.build(short, WorldSpec.from_stretches([("open", 0, 800)]))


def test_track_tunnels_are_added_and_cut_the_other_stretches() -> None:
    tr = straight_track(1500.0, tunnels_m=[(600.0, 800.0)])
    w = World.build(tr, WorldSpec.from_stretches([("town", 100, 1400)], catenary=False), seed=1)
    kinds = [(s.kind, s.start_m, s.end_m) for s in w.spec.stretches]
    assert kinds == [("town", 100, 600), ("tunnel", 600, 800), ("town", 800, 1400)]
    lining = _project(w, "concrete")
    assert lining.chainage_m.min() == pytest.approx(600.0, abs=0.5)
    assert lining.chainage_m.max() == pytest.approx(800.0, abs=0.5)


def test_save_and_load(tmp_path, mixed_world: World) -> None:
    path = tmp_path / "world.npz"
    mixed_world.save(path)
    back = World.load(path, track=mixed_world.track)
    assert np.array_equal(back.vertices_m, mixed_world.vertices_m)
    assert np.array_equal(back.faces, mixed_world.faces)
    assert back.spec == mixed_world.spec and back.seed == mixed_world.seed
    rebuilt = World.load(path)  # track rebuilt from its stored vertices
    s = np.linspace(200, 2400, 7)
    assert np.allclose(rebuilt.track.enu_at(s), mixed_world.track.enu_at(s), atol=1e-6)
    with pytest.raises(ValueError, match="frame differs"):
        World.load(path, track=straight_track(800.0, azimuth_deg=10.0).__class__.from_latlon(
            [LAT0 + 0.01, LAT0 + 0.02], [LON0, LON0]))  # fmt: skip


def test_terrain_mode_lays_the_dem_beyond_the_corridor(tmp_path) -> None:
    from tests.predisat.terrain._dem import surface_m, write_synthetic_dem

    tif = write_synthetic_dem(tmp_path / "dem.tif")
    csv = tmp_path / "track.csv"
    # 400 m east-west across the plain at 100 m, the rails 2 m above it (the track's datum)
    csv.write_text("lat_deg,lon_deg,h_m\n44.990,5.990,102\n44.990,5.995,102\n44.990,6.000,102\n")
    track = TrackMap.from_csv(csv)
    spec = WorldSpec((Stretch("open", 0.0, 300.0),), catenary=False, terrain_margin_m=4000.0,
                     dem_files=(str(tif),))  # fmt: skip
    assert WorldSpec.from_dict(spec.to_dict()) == spec
    world = World.build(track, spec)
    ground = np.isin(world.face_material, [material_id("grass"), material_id("hills")])
    lat, lon, h = world.frame.to_geodetic(world.vertices_m[np.unique(world.faces[ground])])
    s_lat, s_lon, _ = track.position_at(np.linspace(0.0, 400.0, 50))  # the corridor: 0-400 m
    d_m = np.min(WGS84.inv(np.repeat(lon[:, None], 50, 1), np.repeat(lat[:, None], 50, 1),
                           np.broadcast_to(s_lon, (lon.size, 50)),
                           np.broadcast_to(s_lat, (lon.size, 50)))[2], axis=1)  # fmt: skip
    on_dem = (lat > 44.951) & (lat < 45.049) & (lon > 5.951) & (lon < 6.149)
    far = (d_m > 600.0) & on_dem  # on the DEM, off the corridor
    assert far.sum() > 50
    # the analytic surface the tile was made from, shifted by the track's 2 m over the plain;
    # 3" bilinear against the formula: within 15 m on the hill's flanks
    np.testing.assert_allclose(h[far], surface_m(lat[far], lon[far]) + 2.0, atol=15.0)
    assert h[far].max() > 500.0  # the plateau's rise is in the world, not a flat plain
    near = d_m < 100.0  # the corridor keeps its flat ground, 0.5 m under the rails
    assert np.all(np.abs(h[near] - 101.5) < 1.0)
    off = (d_m > 600.0) & ((lon < 5.949) | (lat < 44.949))  # off the tile: flat ground goes on
    assert off.any() and np.all(np.abs(h[off] - 101.5) < 1.0)
    bad = WorldSpec((Stretch("open", 0.0, 300.0),), dem_files=(str(tmp_path / "none.hgt"),))
    with pytest.raises(DemError, match=r"none\.hgt"):
        World.build(track, bad)
