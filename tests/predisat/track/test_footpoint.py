"""Tests for predisat.track.footpoint: the one-point projection is the array projection, bit
for bit (the reference is the array path of ``TrackMap.project_enu`` on two copies of the
point, and ``np.interp``), on the demo line and on a tight hilly curve."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Geod

from predisat.track.footpoint import interp_one
from predisat.track.map import TrackMap, demo_track

GEOD = Geod(ellps="WGS84")


def hairpin() -> TrackMap:
    """A 300 m radius curve of 150 deg climbing 30 m, between two straights."""
    n = 80
    az = np.linspace(0.0, 150.0, n)
    lon, lat, _ = GEOD.fwd(np.full(n, 7.2), np.full(n, 43.9), az, np.full(n, 300.0))
    h = np.linspace(200.0, 230.0, n)
    return TrackMap.from_latlon(lat, lon, h, tolerance_m=0.5)


@pytest.fixture(scope="module", params=["demo", "hairpin"])
def track(request) -> TrackMap:
    return demo_track() if request.param == "demo" else hairpin()


def points(tm: TrackMap, rng: np.random.Generator) -> np.ndarray:
    """Points beside, far from, beyond the ends of and exactly on the axis's nodes."""
    n = 600
    s = rng.uniform(-150.0, tm.length_m + 150.0, n)
    base = np.asarray(tm.enu_at(np.clip(s, 0.0, tm.length_m)))
    scale = rng.choice([0.0, 0.05, 2.0, 40.0, 400.0], (n, 1))
    on_nodes = tm._curve.node_enu_m[rng.integers(0, len(tm._curve.node_s_m), 60)]
    ends = np.asarray(tm.enu_at(np.array([0.0, tm.length_m])))
    beyond = ends + np.array([[-30.0, 5.0, 0.0], [40.0, -3.0, 1.0]])
    return np.vstack([base + rng.normal(0.0, 1.0, (n, 3)) * scale, on_nodes, ends, beyond])


def test_one_point_projection_is_the_array_projection_bit_for_bit(track):
    rng = np.random.default_rng(7)
    for p in points(track, rng):
        one = track.project_enu(p)
        two = track.project_enu(np.stack([p, p]))
        for name in ("chainage_m", "offset_m", "height_m", "along_m", "clamped"):
            got, ref = getattr(one, name), getattr(two, name)[0]
            assert got.shape == ()
            assert got.tobytes() == np.asarray(ref).tobytes(), (name, p, got, ref)


def test_one_point_projection_keeps_the_shape_of_its_input(track):
    p = np.asarray(track.enu_at(100.0))
    assert track.project_enu(p).chainage_m.shape == ()
    assert track.project_enu(p[None]).offset_m.shape == (1,)
    assert track.project_enu(p[None, None]).clamped.shape == (1, 1)
    assert track.project_enu(p[None, None]).clamped.dtype == bool


def test_interp_one_is_numpys_interp_bit_for_bit():
    rng = np.random.default_rng(3)
    xp = np.cumsum(rng.uniform(0.2, 1.5, 400))
    fp = rng.normal(0.0, 1.0, 400)
    x = np.concatenate([rng.uniform(xp[0] - 5, xp[-1] + 5, 3000), xp, [xp[0], xp[-1]]])
    xs, fs = xp.tolist(), fp.tolist()
    got = np.array([interp_one(float(v), xs, fs) for v in x])
    assert got.tobytes() == np.interp(x, xp, fp).tobytes()
