"""Small synthetic scenes for the locator tests: tracks, skies and pseudoranges.

Ground truth comes from geometry: satellites are placed at chosen azimuth/elevation seen from
the true antenna position (local ENU of PROJ's ellipsoid normal), ranges are Euclidean
distances plus a known clock and Gaussian noise.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from locator.sathia import AntennaPath
from predisat.geodesy import LocalFrame, azel_to_enu, ecef_to_geodetic, enu_rotation
from predisat.synth.materials import material_id
from predisat.synth.world import Stretch, World, WorldSpec
from predisat.track.map import TrackMap

FRAME = LocalFrame(50.45, 4.45, 150.0)
SAT_DISTANCE_M = 2.2e7
CLOCK_M = 12345.0


def track_from_enu(enu: NDArray, name: str = "t") -> TrackMap:
    lat, lon, h = FRAME.to_geodetic(np.asarray(enu, float))
    return TrackMap.from_latlon(lat, lon, h, name=name, tolerance_m=0.05)


def straight_path(heading_deg: float = 60.0, length_m: float = 4000.0, height_m: float = 4.0):
    hd = np.radians(heading_deg)
    d = np.linspace(0.0, length_m, 9)
    enu = np.stack([d * np.sin(hd), d * np.cos(hd), np.zeros_like(d)], axis=-1)
    return AntennaPath(track_from_enu(enu, "straight"), height_m)


def arc_path(
    radius_m: float,
    turn_deg: float,
    heading_deg: float = 90.0,
    lead_m: float = 0.0,
    height_m: float = 4.0,
    step_m: float = 5.0,
):
    """A straight lead, then a left-turning arc of ``turn_deg`` from ``heading_deg``."""
    hd = np.radians(heading_deg)
    t0 = np.array([np.sin(hd), np.cos(hd), 0.0])
    left = np.array([-np.cos(hd), np.sin(hd), 0.0])
    lead = np.arange(0.0, lead_m, step_m)[:, None] * t0
    start = lead_m * t0
    centre = start + radius_m * left
    a = np.arange(0.0, np.radians(turn_deg) + 1e-9, step_m / radius_m)
    arc = centre - radius_m * (np.cos(a)[:, None] * left) + radius_m * (np.sin(a)[:, None] * t0)
    enu = np.concatenate([lead, arc]) if lead_m > 0 else arc
    return AntennaPath(track_from_enu(enu, "arc"), height_m)


def balloon_enu(gap_m: float, leg_m: float = 800.0, radius_m: float = 200.0, step_m: float = 2.0):
    """A balloon (reversing) loop: ``leg_m`` east, a racket-shaped loop of ``radius_m`` (right,
    left, right turns), ``leg_m`` back west with the return leg ``gap_m`` north of the outgoing
    one; ENU vertices (n, 3) every ``step_m``."""

    def trace(theta_deg: float) -> NDArray:
        hd = [90.0] * int(leg_m / step_m)
        for turn, ang in ((1, theta_deg), (-1, 180.0 + 2.0 * theta_deg), (1, theta_deg)):
            n = int(np.ceil(np.radians(ang) * radius_m / step_m))
            hd += list(hd[-1] + turn * ang / n * np.arange(1, n + 1))
        hd += [hd[-1]] * int(leg_m / step_m)
        h = np.radians(np.array(hd))
        e = np.concatenate([[0.0], np.cumsum(step_m * np.sin(h))])
        n_ = np.concatenate([[0.0], np.cumsum(step_m * np.cos(h))])
        return np.stack([e, n_, np.zeros_like(e)], axis=-1)

    lo, hi = 5.0, 89.0  # a wider opening brings the return leg closer: bisect on it
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if trace(mid)[-1, 1] > gap_m else (lo, mid)
    return trace(0.5 * (lo + hi))


def balloon_path(gap_m: float, height_m: float = 4.0) -> AntennaPath:
    """:func:`balloon_enu` as an antenna path."""
    return AntennaPath(track_from_enu(balloon_enu(gap_m)[::5], "balloon"), height_m)


def sky(x_ecef: NDArray, az_deg, el_deg) -> NDArray:
    """Satellites at ``SAT_DISTANCE_M`` seen at (az, el) from ``x_ecef``, shape (n, 3)."""
    lat, lon, _ = ecef_to_geodetic(np.asarray(x_ecef, float))
    rot = enu_rotation(lat, lon)  # ECEF -> ENU rows
    d = azel_to_enu(np.asarray(az_deg, float), np.asarray(el_deg, float)) @ rot
    return np.asarray(x_ecef, float) + SAT_DISTANCE_M * d


def random_sky(rng: np.random.Generator, n: int, min_el_deg: float = 15.0):
    az = rng.uniform(0.0, 360.0, n)
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(min_el_deg)), 1.0, n)))
    return az, el


def ranges(sat: NDArray, x_ecef: NDArray, sigma_m=0.0, rng=None, clock_m: float = CLOCK_M):
    r = np.linalg.norm(sat - np.asarray(x_ecef, float), axis=-1) + clock_m
    if rng is not None:
        r = r + rng.normal(0.0, 1.0, r.shape) * sigma_m
    return r


CANYON_FRAME = LocalFrame(44.0, 6.2, 600.0)
LEFT_X_M, LEFT_TOP_M = -10.0, 30.0  # wall west of a north-bound track: on its left
RIGHT_X_M, RIGHT_TOP_M = 10.0, 15.0


def canyon_track(length_m: float = 600.0) -> TrackMap:
    """A straight north-bound track from the canyon frame's origin."""
    y = np.linspace(0.0, length_m, 7)
    enu = np.stack([np.zeros_like(y), y, np.zeros_like(y)], -1)
    lat, lon, h = CANYON_FRAME.to_geodetic(enu)
    return TrackMap.from_latlon(lat, lon, h, name="straight", tolerance_m=0.01)


def _wall(x_m: float, top_m: float, y0: float = -100.0, y1: float = 700.0):
    v = np.array([[x_m, y0, -1.0], [x_m, y1, -1.0], [x_m, y1, top_m], [x_m, y0, top_m]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def canyon_world() -> World:
    """Two smooth vertical rock walls, 10 m left (30 m high) and 10 m right (15 m high)."""
    track = canyon_track()
    (vl, fl), (vr, fr) = _wall(LEFT_X_M, LEFT_TOP_M), _wall(RIGHT_X_M, RIGHT_TOP_M)
    verts = np.concatenate([vl, vr])
    faces = np.concatenate([fl, fr + 4]).astype(np.int32)
    mat = np.full(len(faces), material_id("rock"), np.int16)
    spec = WorldSpec((Stretch("rock_walls", 0.0, 600.0),), catenary=False, hills=False)
    return World(track, track.frame, spec, 0, verts, faces, mat)
