#!/usr/bin/env python
"""An independent synthetic world for held-out checks of the PREDISAT pipeline.

Written without reading the project's own generator (predisat/synth): scenery, materials, sky,
shading, camera projection and ground-truth ray casting are all in this file. From predisat it
uses only the track map (``predisat.track.map.demo_track``: chainage -> position, heading) and
``predisat.masks.truth.TrueMasks`` to save the truth in the format ``predisat evaluate`` reads.

Commands (run from the repository root, ``PYTHONPATH=.``)::

    python scripts/independent_world.py build  OUT --seed 1 --sky cloudy    # survey + truth
    python scripts/independent_world.py check  OUT                           # truth self-checks
    python scripts/independent_world.py attribute OUT MASKS                  # false trust by object
    python scripts/independent_world.py thumbs OUT --frames 0,50,100         # PNG contact sheet

``build`` writes a survey in format version 1 (survey.yaml, manifest.csv, images/, calib/, a
copy of the line 144 track file in track/) and truth/true_masks.npz (0.5 deg bins; obstacle
descriptors are NaN: this generator does not compute them) plus truth/truth_objects.npz (the
object and class setting every bin) and world/ (the mesh and the object table).

World frame: local east-north-up at the middle of the stretch, from the track's ECEF
positions; each antenna's own local vertical is used for its truth (the Earth's curvature).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import yaml

A_WGS = 6378137.0
E2_WGS = 6.69437999014e-3
R_EARTH = 6371000.0

CLASSES = [
    "ground",
    "ballast",
    "house",
    "glass_block",
    "white_facade",
    "lamp_post",
    "footbridge",
    "church",
    "tree",
    "mast_cantilever",
    "canopy",
    "platform",
    "wet_ground",
    "far_woods",
]
CLS = {n: i for i, n in enumerate(CLASSES)}

# ---------------------------------------------------------------------------------------------
# geodesy (own, WGS84)


def ecef_from_geodetic(lat, lon, h):
    lat, lon = np.radians(lat), np.radians(lon)
    n = A_WGS / np.sqrt(1 - E2_WGS * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1 - E2_WGS) + h) * np.sin(lat),
        ],
        -1,
    )


def enu_rotation(lat, lon):
    """Rows east, north, up of the local frame at (lat, lon) in ECEF, shape (..., 3, 3)."""
    la, lo = np.radians(lat), np.radians(lon)
    sl, cl, so, co = np.sin(la), np.cos(la), np.sin(lo), np.cos(lo)
    e = np.stack([-so, co, np.zeros_like(so)], -1)
    n = np.stack([-sl * co, -sl * so, cl], -1)
    u = np.stack([cl * co, cl * so, sl], -1)
    return np.stack([e, n, u], -2)


# ---------------------------------------------------------------------------------------------
# the track in the world frame


class Track:
    def __init__(self, s0: float, s1: float, mid: float):
        from predisat.track.map import demo_track

        self.tm = demo_track()
        lat0, lon0, h0 = (float(np.asarray(v).ravel()[0]) for v in self.tm.position_at([mid]))
        self.X0 = ecef_from_geodetic(lat0, lon0, h0)
        self.R0 = enu_rotation(lat0, lon0)
        self.lat0, self.lon0 = lat0, lon0
        self.s = np.arange(s0, s1 + 0.5, 1.0)
        lat, lon, h = self.tm.position_at(self.s)
        self.p = self.world_from_geo(lat, lon, h)
        self.hdg = np.asarray(self.tm.heading_at(self.s), float)

    def world_from_geo(self, lat, lon, h):
        X = ecef_from_geodetic(np.asarray(lat), np.asarray(lon), np.asarray(h))
        return (X - self.X0) @ self.R0.T

    def local_to_world(self, lat, lon):
        """(..., 3, 3): a direction in the local ENU at (lat, lon) -> world frame (columns)."""
        return self.R0 @ np.swapaxes(enu_rotation(lat, lon), -1, -2)

    def pose(self, s):
        """Track point at chainage s: lat, lon, h and the vehicle axes (3, 3) in the world
        frame, columns forward, left, up (driving toward increasing chainage)."""
        s = float(s)
        lat, lon, h = (float(np.asarray(v).ravel()[0]) for v in self.tm.position_at([s]))
        hd = math.radians(float(np.asarray(self.tm.heading_at([s])).ravel()[0]))
        M = self.local_to_world(lat, lon)
        fwd = M @ np.array([math.sin(hd), math.cos(hd), 0.0])
        left = M @ np.array([-math.cos(hd), math.sin(hd), 0.0])
        up = M @ np.array([0.0, 0.0, 1.0])
        return lat, lon, h, np.stack([fwd, left, up], 1)

    def at(self, s):
        """Point (3,), forward (3,), left (3,), up (3,) in the world frame at chainage s."""
        lat, lon, h, Rv = self.pose(s)
        return self.world_from_geo(lat, lon, h), Rv[:, 0], Rv[:, 1], Rv[:, 2]

    def place(self, s, offset, height=0.0):
        p, f, lv, u = self.at(s)
        return p + offset * lv + height * u, f, lv, u


# ---------------------------------------------------------------------------------------------
# geometry builders: every triangle carries an object id


@dataclass
class Obj:
    cls: str
    mat: str
    origin: np.ndarray
    axes: np.ndarray  # columns: local x (along), y (across), z (up) in world
    params: dict = field(default_factory=dict)


class MeshBuilder:
    def __init__(self):
        self.V: list[np.ndarray] = []
        self.F: list[np.ndarray] = []
        self.tri_obj: list[np.ndarray] = []
        self.nv = 0
        self.objs: list[Obj] = []

    def new_obj(self, cls, mat, origin, axes, **params) -> int:
        self.objs.append(Obj(cls, mat, np.asarray(origin, float), np.asarray(axes, float), params))
        return len(self.objs) - 1

    def add(self, V, F, oid):
        V = np.asarray(V, float)
        F = np.asarray(F, np.int64)
        self.V.append(V)
        self.F.append(F + self.nv)
        self.tri_obj.append(np.full(len(F), oid, np.int32))
        self.nv += len(V)

    def box(self, oid, centre, axes, size):
        """Box with half sizes along the columns of axes; centre of the bottom face at centre."""
        a, b, c = np.asarray(size, float) / 2.0
        loc = np.array([[x, y, z] for z in (0, 2 * c) for y in (-b, b) for x in (-a, a)])
        V = centre + loc @ np.asarray(axes).T
        F = [
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ]
        self.add(V, F, oid)

    def gable_roof(self, oid, centre, axes, length, width, base_z, ridge_h, overhang=0.4):
        ax = np.asarray(axes)
        a, b = length / 2 + overhang, width / 2 + overhang
        loc = np.array(
            [
                [-a, -b, base_z],
                [a, -b, base_z],
                [a, b, base_z],
                [-a, b, base_z],
                [-a, 0, base_z + ridge_h],
                [a, 0, base_z + ridge_h],
            ]
        )
        V = centre + loc @ ax.T
        F = [[0, 1, 5], [0, 5, 4], [2, 3, 4], [2, 4, 5], [0, 4, 3], [1, 2, 5], [0, 3, 2], [0, 2, 1]]
        self.add(V, F, oid)

    def cylinder(self, oid, p0, p1, r, n=8, cap=True):
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        d = p1 - p0
        d /= np.linalg.norm(d)
        t = np.cross(d, [0, 0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0, 0])
        t /= np.linalg.norm(t)
        w = np.cross(d, t)
        ang = np.arange(n) * 2 * np.pi / n
        ring = r * (np.cos(ang)[:, None] * t + np.sin(ang)[:, None] * w)
        V = np.vstack([p0 + ring, p1 + ring, p0, p1])
        F = []
        for i in range(n):
            j = (i + 1) % n
            F += [[i, j, n + i], [j, n + j, n + i]]
            if cap:
                F += [[2 * n, j, i], [2 * n + 1, n + i, n + j]]
        self.add(V, F, oid)

    def cone(self, oid, base, apex, r, n=12):
        base, apex = np.asarray(base, float), np.asarray(apex, float)
        ang = np.arange(n) * 2 * np.pi / n
        ring = base + r * np.stack([np.cos(ang), np.sin(ang), 0 * ang], -1)
        V = np.vstack([ring, apex, base])
        F = [[i, (i + 1) % n, n] for i in range(n)] + [[n + 1, (i + 1) % n, i] for i in range(n)]
        self.add(V, F, oid)

    def pyramid(self, oid, centre, axes, half, apex_h):
        ax = np.asarray(axes)
        loc = np.array(
            [[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0], [0, 0, apex_h]]
        )
        V = centre + loc @ ax.T
        F = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4], [0, 2, 1], [0, 3, 2]]
        self.add(V, F, oid)

    def blob(self, oid, centre, radii, rng, rough=0.25):
        V, F = icosphere(2)
        # irregular canopy: low-frequency radial noise on a unit sphere
        k = rng.normal(size=(6, 3))
        ph = rng.uniform(0, 2 * np.pi, 6)
        bump = sum(np.sin(V @ k[i] * 1.7 + ph[i]) for i in range(6)) / 6.0
        V = V * (1 + rough * bump)[:, None] * np.asarray(radii)
        self.add(centre + V, F, oid)

    def quad(self, oid, p00, p10, p11, p01):
        self.add(np.array([p00, p10, p11, p01]), [[0, 1, 2], [0, 2, 3]], oid)

    def arrays(self):
        return (np.vstack(self.V), np.vstack(self.F), np.concatenate(self.tri_obj))


_ICO: dict[int, tuple] = {}


def icosphere(level):
    if level in _ICO:
        return _ICO[level]
    t = (1 + 5**0.5) / 2
    V = [
        [-1, t, 0],
        [1, t, 0],
        [-1, -t, 0],
        [1, -t, 0],
        [0, -1, t],
        [0, 1, t],
        [0, -1, -t],
        [0, 1, -t],
        [t, 0, -1],
        [t, 0, 1],
        [-t, 0, -1],
        [-t, 0, 1],
    ]
    F = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    for _ in range(level):
        cache: dict = {}
        nf = []

        def mid(a, b, cache=cache):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = V[a] + V[b]
                V.append(m / np.linalg.norm(m))  # type: ignore[operator]
                cache[key] = len(V) - 1
            return cache[key]

        for a, b, c in F:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        F = nf
    _ICO[level] = (np.array(V), np.array(F))
    return _ICO[level]


# ---------------------------------------------------------------------------------------------
# the world: layout per seed


@dataclass
class Wire:
    pts: np.ndarray  # (n, 3) polyline in world
    radius: float = 0.006


def frame_axes(f, lv, u):
    return np.stack([f, lv, u], 1)


def build_world(track: Track, seed: int, s0: float, s1: float):
    rng = np.random.default_rng(seed)
    mb = MeshBuilder()
    wires: list[Wire] = []
    I3 = np.eye(3)
    layout: list[dict] = []

    # ground: a large height field, curvature-corrected, gentle undulation away from the track
    g = mb.new_obj("ground", "grass", np.zeros(3), I3)
    xs = np.concatenate(
        [np.linspace(-4000, -800, 9)[:-1], np.arange(-800, 801, 8.0), np.linspace(800, 4000, 9)[1:]]
    )
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    from scipy.spatial import cKDTree

    kd = cKDTree(track.p[:, :2])
    dist, _ = kd.query(np.stack([X.ravel(), Y.ravel()], -1))
    dist = dist.reshape(X.shape)
    und = (np.sin(X / 97.0 + seed) * np.cos(Y / 131.0 - seed) + 0.5 * np.sin((X + Y) / 53.0)) * 0.8
    w = np.clip((dist - 30.0) / 70.0, 0, 1)
    Z = -(X**2 + Y**2) / (2 * R_EARTH) - 0.35 + und * w
    n1, n2 = X.shape
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], -1)
    idx = np.arange(n1 * n2).reshape(n1, n2)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
        idx[:-1, 1:].ravel(),
    )
    mb.add(V, np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]), g)

    # ballast strips under both tracks (track A at 0, track B at -4.2 m)
    bal = mb.new_obj("ballast", "ballast", np.zeros(3), I3)
    ss = np.arange(s0 - 150, s1 + 151, 5.0)
    for off in (0.0, -4.2):
        P = [track.place(s, off) for s in ss]
        for (p0, _f0, l0, u0), (p1, _f1, l1, u1) in itertools.pairwise(P):
            mb.quad(
                bal,
                p0 - 1.7 * l0 - 0.05 * u0,
                p1 - 1.7 * l1 - 0.05 * u1,
                p1 + 1.7 * l1 - 0.05 * u1,
                p0 + 1.7 * l0 - 0.05 * u0,
            )

    # --- special places
    s_station = rng.uniform(s0 + 150, s1 - 250)
    st_len = rng.uniform(90, 140)
    s_church = rng.uniform(s0 + 50, s1 - 50)
    church_side = rng.choice([1, -1])
    s_bridges = [s_station + st_len + 15]
    if rng.random() < 0.7:
        s_bridges.append(rng.uniform(s0 + 50, s1 - 50))
    layout.append(
        {
            "station": [s_station, s_station + st_len],
            "church": [s_church, int(church_side)],
            "footbridges": s_bridges,
        }
    )

    def in_station(s):
        return s_station - 10 <= s <= s_station + st_len + 10

    # --- catenary: masts every ~55-63 m on both outer sides, cantilevers, wires
    s = s0 - 150
    spans = []
    while s < s1 + 150:
        spans.append(s)
        s += rng.uniform(52, 63)
    zig = 0.25
    for k, sm in enumerate(spans):  # noqa: B007
        for side_off, tracks in ((3.1, [0.0]), (-7.3, [-4.2])):
            if in_station(sm):  # no mast on the platform: the right mast carries both tracks
                if side_off > 0:
                    continue
                tracks = [-4.2, 0.0]
            p, f, lv, u = track.place(sm, side_off)
            ax = frame_axes(f, lv, u)
            m = mb.new_obj("mast_cantilever", "galv", p, ax)
            mb.box(m, p, ax, (0.30, 0.25, 8.6))
            sgn = -np.sign(side_off)
            for toff in tracks:
                reach = toff - side_off + sgn * 0.6
                top = p + 7.3 * u
                end = p + reach * lv + 7.3 * u
                mb.cylinder(m, top, end, 0.03, n=6)  # upper tube
                mb.cylinder(m, p + 5.8 * u, p + (reach * 0.85) * lv + 7.0 * u, 0.03, n=6)  # stay
                reg = p + (toff - side_off) * lv + 5.75 * u
                mb.cylinder(m, p + 5.9 * u, reg, 0.025, n=6)  # registration arm
    for toff in (0.0, -4.2):
        for k in range(len(spans) - 1):
            sa, sb = spans[k], spans[k + 1]
            n = 24
            tt = np.linspace(0, 1, n + 1)
            cw, ms = [], []
            for t in tt:
                p, f, lv, u = track.place(sa + t * (sb - sa), toff)
                zz = zig * (1 - 2 * t) * (1 if k % 2 else -1)
                cw.append(p + zz * lv + 5.6 * u)
                ms.append(p + zz * lv + (7.1 - 1.6 * t * (1 - t)) * u)
            wires.append(Wire(np.array(cw)))
            wires.append(Wire(np.array(ms)))
            for t in np.arange(0.1, 0.95, 0.12):  # droppers
                i = round(t * n)
                wires.append(Wire(np.array([cw[i], ms[i]]), 0.003))

    # --- station: platform, canopy on the left of track A
    pf = mb.new_obj("platform", "concrete", np.zeros(3), I3)
    cano = mb.new_obj("canopy", "canopy", np.zeros(3), I3)
    for sx in np.arange(s_station, s_station + st_len, 5.0):
        p, f, lv, u = track.place(sx + 2.5, 0.0)
        ax = frame_axes(f, lv, u)
        mb.box(pf, p + 6.3 * lv - 0.35 * u, ax, (5.05, 5.6, 1.1))
        mb.box(cano, p + 6.4 * lv + 5.0 * u, ax, (5.05, 5.4, 0.25))
        if int((sx - s_station) / 5) % 2 == 0:
            mb.cylinder(cano, p + 7.0 * lv + 0.7 * u, p + 7.0 * lv + 5.0 * u, 0.12)
    # station building behind the platform
    p, f, lv, u = track.place(s_station + st_len / 2, 14.0)
    sb_ = mb.new_obj("white_facade", "white", p, frame_axes(f, lv, u), floors=3.2, win=2.8)
    mb.box(sb_, p, frame_axes(f, lv, u), (30, 9, 8.5))

    # --- footbridges over both tracks
    for sb in s_bridges:
        p, f, lv, u = track.place(sb, -2.1)
        ax = frame_axes(f, lv, u)
        fb = mb.new_obj("footbridge", "steel", p, ax)
        mb.box(fb, p + 7.0 * u, ax, (3.0, 30.0, 0.6))
        mb.box(fb, p + 1.4 * f + 7.6 * u, ax, (0.12, 30.0, 1.3))
        mb.box(fb, p - 1.4 * f + 7.6 * u, ax, (0.12, 30.0, 1.3))
        for side in (-1, 1):
            mb.box(fb, p + side * 17.0 * lv, ax, (4.0, 4.0, 9.0))
            mb.gable_roof(fb, p + side * 17.0 * lv, ax, 4.0, 4.0, 9.0, 1.2, 0.2)

    # --- church
    p, f, lv, u = track.place(s_church, church_side * rng.uniform(28, 55))
    ax = frame_axes(f, lv, u)
    ch = mb.new_obj("church", "stone", p, ax)
    mb.box(ch, p, ax, (26, 12, 11))
    mb.gable_roof(ch, p, ax, 26, 12, 11, 6.5, 0.3)
    tw = p + 15 * f
    mb.box(ch, tw, ax, (6.5, 6.5, 27))
    spire = mb.new_obj("church", "slate", tw, ax)
    mb.pyramid(spire, tw + 27 * u, ax, 3.4, rng.uniform(14, 22))

    # --- zones on each side
    reserved = (
        [(s_station - 20, s_station + st_len + 20, 1)]
        + [(sb - 25, sb + 25, 0) for sb in s_bridges]
        + [(s_church - 30, s_church + 30, church_side)]
    )

    def blocked(sa, sb, side, near):
        for ra, rb, rs in reserved:
            if sb > ra and sa < rb and ((rs == 0 and near) or rs == side):
                return True
        return False

    kinds = ["open", "houses", "glass", "white", "trees"]
    wts = np.array([0.18, 0.26, 0.14, 0.18, 0.24])
    wts = wts * rng.uniform(0.6, 1.4, len(wts))
    wts /= wts.sum()
    for side in (1, -1):
        base = 6.5 if side > 0 else -10.0
        s = s0 - 150
        while s < s1 + 150:
            L = rng.uniform(50, 160)
            kind = rng.choice(kinds, p=wts)
            layout.append({"side": int(side), "s": [s, s + L], "kind": str(kind)})
            x = s
            while x < s + L:
                if kind == "open":
                    if rng.random() < 0.3:
                        _tree(mb, track, rng, x, base + side * rng.uniform(10, 40))
                    x += rng.uniform(15, 40)
                    continue
                if kind == "trees":
                    n = rng.integers(3, 9)  # type: ignore[assignment]
                    for _ in range(n):
                        o = base + side * rng.uniform(0, 25)
                        if blocked(x - 5, x + 5, side, abs(o) < 20):
                            continue
                        _tree(mb, track, rng, x + rng.uniform(-6, 6), o)
                    x += rng.uniform(12, 25)
                    continue
                if kind == "houses":
                    lx, wy = rng.uniform(8, 12), rng.uniform(7, 9.5)
                    o = base + side * (rng.uniform(1.5, 14) + wy / 2)
                    if not blocked(x, x + lx, side, True):
                        p, f, lv, u = track.place(x + lx / 2, o)
                        ax = frame_axes(f, lv, u)
                        eave = rng.uniform(5, 6.8)
                        hs = mb.new_obj(
                            "house", rng.choice(["brick", "render"]), p, ax, floors=2.8, win=3.0
                        )
                        mb.box(hs, p, ax, (lx, wy, eave))
                        rf = mb.new_obj("house", rng.choice(["tiles", "slate"]), p, ax)
                        mb.gable_roof(rf, p, ax, lx, wy, eave, rng.uniform(3, 4.8))
                        if rng.random() < 0.5:
                            _tree(mb, track, rng, x + lx + 2, o + side * rng.uniform(-3, 6))
                    x += lx + rng.uniform(3, 10)
                    continue
                if kind in ("glass", "white"):
                    lx = rng.uniform(20, 45)
                    wy = rng.uniform(12, 20)
                    hz = rng.uniform(12, 32) if kind == "glass" else rng.uniform(10, 20)
                    o = base + side * (rng.uniform(4, 18) + wy / 2)
                    if not blocked(x, x + lx, side, True):
                        p, f, lv, u = track.place(x + lx / 2, o)
                        ax = frame_axes(f, lv, u)
                        bl = mb.new_obj(
                            "glass_block" if kind == "glass" else "white_facade",
                            "glass" if kind == "glass" else rng.choice(["white", "pale"]),
                            p,
                            ax,
                            floors=3.5 if kind == "glass" else 3.1,
                            win=1.6 if kind == "glass" else rng.uniform(2.4, 3.4),
                        )
                        mb.box(bl, p, ax, (lx, wy, hz))
                    # lamp posts along built-up zones
                    x += lx + rng.uniform(5, 15)
                    continue
            s += L
    # lamp posts with arms over the track: in the station and the built-up zones near it
    for sx in np.arange(s0 - 100, s1 + 100, rng.uniform(28, 40)):
        near_st = in_station(sx) or rng.random() < 0.35
        if not near_st:
            continue
        side = 1 if rng.random() < 0.6 else -1
        off = 4.3 if side > 0 else -9.0
        if side > 0 and in_station(sx):
            off = 8.8
        p, f, lv, u = track.place(sx + rng.uniform(-3, 3), off)
        lp = mb.new_obj("lamp_post", "dark_metal", p, frame_axes(f, lv, u))
        hgt = rng.uniform(7.0, 8.5)
        mb.cylinder(lp, p, p + hgt * u, 0.09)
        reach = rng.uniform(2.5, 4.5)
        end = p - np.sign(off) * reach * lv + (hgt + 0.3) * u
        mb.cylinder(lp, p + hgt * u, end, 0.05, n=6)
        mb.box(lp, end - 0.5 * u, frame_axes(f, lv, u), (0.35, 0.6, 0.25))

    # far woods: bounding the horizon 250-700 m away
    fw = mb.new_obj("far_woods", "tree", np.zeros(3), I3)
    mid_p = track.p[len(track.p) // 2]
    for _ in range(int(rng.integers(10, 20))):
        ang = rng.uniform(0, 2 * np.pi)
        r = rng.uniform(250, 700)
        c = mid_p + np.array([r * math.cos(ang), r * math.sin(ang), 0.0])
        if kd.query(c[:2])[0] < 150:
            continue
        c[2] = -(c[0] ** 2 + c[1] ** 2) / (2 * R_EARTH)
        for _ in range(int(rng.integers(4, 10))):
            cc = c + np.array([rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(5, 12)])
            mb.blob(fw, cc, (rng.uniform(10, 20), rng.uniform(10, 20), rng.uniform(5, 9)), rng)

    # wet patches (mirror-like puddles / wet asphalt), just above the ground
    wet = mb.new_obj("wet_ground", "wet", np.zeros(3), I3)
    for _ in range(int(rng.integers(8, 18))):
        sx = rng.uniform(s0, s1)
        o = rng.choice([-1, 1]) * rng.uniform(2.5, 25) - (4.2 if rng.random() < 0.3 else 0)
        if abs(o) < 2.2 or abs(o + 4.2) < 2.2:
            continue
        p, f, lv, u = track.place(sx, o)
        a_, b_ = rng.uniform(1.5, 8), rng.uniform(1, 4)
        z = -(p[0] ** 2 + p[1] ** 2) / (2 * R_EARTH) - 0.33
        q = p.copy()
        q[2] = z
        mb.quad(
            wet,
            q - a_ * f - b_ * lv,
            q + a_ * f - b_ * lv,
            q + a_ * f + b_ * lv,
            q - a_ * f + b_ * lv,
        )
    return mb, wires, layout


def _tree(mb, track, rng, s, off):
    p, f, lv, u = track.place(s, off)
    h = rng.uniform(7, 18)
    t = mb.new_obj("tree", "tree", p, np.stack([f, lv, u], 1))
    mb.cylinder(t, p - 0.3 * u, p + 0.55 * h * u, rng.uniform(0.12, 0.3), n=6)
    rad = rng.uniform(2.0, 5.0) * (h / 12) ** 0.5
    for _ in range(int(rng.integers(3, 7))):
        c = (
            p
            + (h - rad + rng.uniform(-0.4, 0.2) * rad) * u
            + rng.normal(0, 0.45 * rad, 3) * [1, 1, 0.6]
        )
        mb.blob(t, c, rad * rng.uniform(0.55, 0.95, 3), rng, rough=0.35)


# ---------------------------------------------------------------------------------------------
# noise


def _hash(ix, iy, iz, seed):
    h = (
        (ix.astype(np.int64) * 73856093)
        ^ (iy.astype(np.int64) * 19349663)
        ^ (iz.astype(np.int64) * 83492791)
        ^ (seed * 2654435761)
    )
    h = h & 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 0x5BD1E995) & 0xFFFFFFFF
    h ^= h >> 15
    return h.astype(np.float64) / 4294967295.0


def value_noise3(p, seed=0):
    fl = np.floor(p)
    fr = p - fl
    i = fl.astype(np.int64)
    w = fr * fr * (3 - 2 * fr)
    out = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                h = _hash(i[..., 0] + dx, i[..., 1] + dy, i[..., 2] + dz, seed)
                wx = w[..., 0] if dx else 1 - w[..., 0]
                wy = w[..., 1] if dy else 1 - w[..., 1]
                wz = w[..., 2] if dz else 1 - w[..., 2]
                out = out + h * wx * wy * wz
    return out


def fbm3(p, octaves=3, seed=0, lac=2.03, gain=0.5):
    tot, amp, norm = 0.0, 1.0, 0.0
    for o in range(octaves):
        tot = tot + amp * value_noise3(p, seed + 17 * o)
        norm += amp
        amp *= gain
        p = p * lac + 11.3
    return tot / norm


# ---------------------------------------------------------------------------------------------
# sky


class Sky:
    def __init__(self, mode: str, rng, world_up=None):
        world_up = np.array([0, 0, 1.0]) if world_up is None else world_up
        self.mode = mode
        self.sun_az = rng.uniform(0, 360)
        self.sun_el = rng.uniform(28, 50)
        a, e = math.radians(self.sun_az), math.radians(self.sun_el)
        self.sun = np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])
        self.seed = int(rng.integers(0, 10000))
        self.wind = rng.uniform(-2000, 2000, 2)
        if mode == "cloudy":
            self.cover = rng.uniform(0.45, 0.65)
            self.sun_E = 3.0
            self.amb = np.array([0.55, 0.62, 0.75])
        else:
            self.cover = 1.0
            self.sun_E = 0.0
            self.amb = np.array([0.95, 0.95, 0.97])

    def radiance(self, d):
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        z = np.clip(d[..., 2], -1, 1)
        el = np.arcsin(z)
        up = np.clip(z, 0.0, 1.0)
        cosg = d @ self.sun
        if self.mode == "cloudy":
            zen = np.array([0.18, 0.34, 0.78])
            hor = np.array([0.70, 0.80, 0.95])
            t = (1 - up) ** 4
            col = zen * (1 - t[..., None]) + hor * t[..., None]
            glow = 0.6 * np.exp((cosg - 1) * 8.0) + 30.0 * (cosg > math.cos(math.radians(0.6)))
            col = col + glow[..., None] * np.array([1.0, 0.95, 0.85])
            zz = np.maximum(z, 0.03)
            uv = d[..., :2] / zz[..., None] * 1200.0 + self.wind
            n = fbm3(
                np.concatenate([uv / 900.0, np.full((*uv.shape[:-1], 1), 0.5)], -1), 5, self.seed
            )
            dens = np.clip((n - (0.60 - 0.22 * self.cover)) / 0.16, 0, 1)
            dens *= np.clip(z / 0.05, 0, 1) ** 0.5
            shade = fbm3(
                np.concatenate([uv / 300.0, np.full((*uv.shape[:-1], 1), 3.5)], -1),
                3,
                self.seed + 5,
            )
            lit = 0.75 + 0.5 * shade + 0.35 * np.exp((cosg - 1) * 3.0)
            cloud = np.array([0.92, 0.92, 0.94]) * lit[..., None] * (1 - 0.35 * dens[..., None])
            col = col * (1 - dens[..., None]) + cloud * dens[..., None]
            # haze at the horizon
            hz = np.exp(-np.maximum(el, 0) / 0.05)[..., None]
            col = col * (1 - 0.5 * hz) + 0.5 * hz * np.array([0.85, 0.87, 0.9])
        else:
            L = (1 + 2 * up) / 3.0
            zz = np.maximum(z, 0.03)
            uv = d[..., :2] / zz[..., None] * 800.0 + self.wind
            n = fbm3(
                np.concatenate([uv / 700.0, np.full((*uv.shape[:-1], 1), 0.5)], -1), 4, self.seed
            )
            L = L * (0.82 + 0.3 * n)
            col = L[..., None] * np.array([0.93, 0.94, 0.97]) * 1.1
        below = z < 0
        col[below] = np.array([0.35, 0.35, 0.33])
        return col


# ---------------------------------------------------------------------------------------------
# camera: OpenCV fisheye (Kannala-Brandt), own implementation


@dataclass
class Fisheye:
    width: int = 1024
    height: int = 1024
    fov_deg: float = 185.0
    circle_px: float = 500.0
    k: tuple = (-0.012, 0.0015, -0.0004, 0.00003)

    def __post_init__(self):
        tmax = math.radians(self.fov_deg / 2)
        self.theta_max = tmax
        self.f = self.circle_px / self.thetad(tmax)
        self.cx = (self.width - 1) / 2.0
        self.cy = (self.height - 1) / 2.0
        th = np.linspace(0, 2.6, 20001)
        td = self.thetad(th)
        dd = np.gradient(td, th)
        self._lim = th[np.argmax(dd <= 0)] if (dd <= 0).any() else th[-1]
        ok = th <= self._lim
        self._td, self._th = td[ok], th[ok]

    def thetad(self, th):
        k1, k2, k3, k4 = self.k
        t2 = th * th
        return th * (1 + k1 * t2 + k2 * t2**2 + k3 * t2**3 + k4 * t2**4)

    def pixel_rays(self):
        u, v = np.meshgrid(np.arange(self.width, dtype=float), np.arange(self.height, dtype=float))
        x, y = (u - self.cx) / self.f, (v - self.cy) / self.f
        r = np.hypot(x, y)
        th = np.interp(r, self._td, self._th)
        for _ in range(3):  # Newton polish
            k1, k2, k3, k4 = self.k
            t2 = th * th
            der = 1 + 3 * k1 * t2 + 5 * k2 * t2**2 + 7 * k3 * t2**3 + 9 * k4 * t2**4
            th = th - (self.thetad(th) - r) / der
        phi = np.arctan2(y, x)
        rays = np.stack([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th)], -1)
        valid = th <= self.theta_max
        return rays, valid, th

    def project(self, X):
        """Camera-frame points (..., 3) -> pixels (..., 2), NaN beyond the field of view."""
        rxy = np.hypot(X[..., 0], X[..., 1])
        th = np.arctan2(rxy, X[..., 2])
        td = self.thetad(th)
        sc = np.where(rxy > 0, td / np.maximum(rxy, 1e-12), 0.0)
        u = self.f * X[..., 0] * sc + self.cx
        v = self.f * X[..., 1] * sc + self.cy
        bad = th > self.theta_max
        return np.where(bad, np.nan, u), np.where(bad, np.nan, v)

    def write_calib(self, path, name):
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("format", "predisat-camera")
        fs.write("version", 1)
        fs.write("camera_name", name)
        fs.write("model", "fisheye")
        fs.write("image_width", self.width)
        fs.write("image_height", self.height)
        K = np.array([[self.f, 0, self.cx], [0, self.f, self.cy], [0, 0, 1.0]])
        fs.write("camera_matrix", K)
        fs.write("distortion_coefficients", np.array([list(self.k)], float))
        fs.release()


MOUNTS = {
    "left": dict(yaw_deg=90.0, pitch_deg=45.0, roll_deg=0.0, lever_arm_m=[0.35, 1.45, -0.65]),
    "right": dict(yaw_deg=-90.0, pitch_deg=45.0, roll_deg=0.0, lever_arm_m=[0.35, -1.45, -0.65]),
}


def cam_to_vehicle(m):
    """Camera (x right, y down, z optical axis) -> vehicle (x fwd, y left, z up), columns =
    the camera axes in the vehicle frame. Built from the mount's meaning (docs/camera-model.md):
    optical axis at azimuth yaw from x toward y, pitched up by pitch; roll about the optical
    axis, positive lowering the image's right side."""
    y, p, r = (math.radians(m[k]) for k in ("yaw_deg", "pitch_deg", "roll_deg"))
    zc = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), math.sin(p)])
    xc0 = np.array([math.sin(y), -math.cos(y), 0.0])  # level, right of the optical axis
    yc0 = np.cross(zc, xc0)  # image down
    xc = math.cos(r) * xc0 + math.sin(r) * yc0
    yc = np.cross(zc, xc)
    return np.stack([xc, yc, zc], 1)


# ---------------------------------------------------------------------------------------------
# canted vehicle (build --cant-speed-kmh): the body's roll on a curve and its pitch on a grade

EQ_CANT_MM = 11.8  # EN 13803 equilibrium cant, standard gauge: mm per (km/h)^2 per (1/m)
CANT_BASE_MM = 1500.0  # cant angle = asin(cant / 1500 mm), the rail heads' contact points


def survey_speed_mps(step_m):
    """The survey vehicle's speed: consecutive positions are ``step_m`` apart along the track
    and ``survey_rows_time(1) - survey_rows_time(0)`` seconds apart in the manifest (15 m/s,
    54 km/h, at the standard 10 m step)."""
    return step_m / (survey_rows_time(1) - survey_rows_time(0))


def track_curvature(track, s, half=10.0):
    """Signed horizontal curvature (1/m) at chainage s, positive when the track turns LEFT
    toward increasing chainage: the direction of the track's world-frame positions (1 m
    samples, ``Track.p``; x east, y north, z up) differenced over s +- ``half`` m, its angle
    counted anticlockwise seen from above (a left turn increases it)."""

    def ang(x):
        xs = np.array([x - 1.0, x + 1.0])
        px = np.interp(xs, track.s, track.p[:, 0])
        py = np.interp(xs, track.s, track.p[:, 1])
        return math.atan2(py[1] - py[0], px[1] - px[0])

    d = ang(s + half) - ang(s - half)
    d = (d + math.pi) % (2 * math.pi) - math.pi
    return d / (2 * half)


def track_grade(track, s, half=10.0):
    """dh/ds of the track's ellipsoidal heights over s +- half. The demo track's file is 2-D:
    its heights are conversion residue (0 to -6.5 cm over the whole line, slopes < 6e-5), so a
    track whose heights span less than 0.1 m over the stretch counts as level (grade 0)."""
    if not hasattr(track, "_has_heights"):
        _, _, hs = track.tm.position_at(track.s)
        track._has_heights = float(np.ptp(np.asarray(hs, float))) > 0.1
    if not track._has_heights:
        return 0.0
    _, _, h = track.tm.position_at([s - half, s + half])
    h = np.asarray(h, float).ravel()
    return float(h[1] - h[0]) / (2 * half)


def vehicle_attitude(track, s, design_kmh, survey_kmh, max_cant_mm=160.0, flexibility=0.25):
    """(kappa 1/m, design cant mm, roll_deg, pitch_deg) of the survey vehicle at chainage s.

    The design cant is the equilibrium cant at ``design_kmh`` (capped, rounded to 5 mm); the
    body leans toward the curve's inside by theta_c + flexibility * (theta_c - theta_eq),
    theta_eq the equilibrium cant angle at the survey speed (a slower train leans further
    in on its suspension). Sign: roll positive raises the vehicle's LEFT side (driving toward
    increasing chainage). On a left-hand curve (kappa > 0) the inside is the left, so the
    left side goes down: roll negative. Pitch positive raises the nose: atan(grade)."""
    kappa = track_curvature(track, s)
    c = min(max_cant_mm, EQ_CANT_MM * design_kmh**2 * abs(kappa))
    c = 5.0 * math.floor(c / 5.0 + 0.5)
    th_c = math.asin(c / CANT_BASE_MM)
    th_eq = math.asin(min(EQ_CANT_MM * survey_kmh**2 * abs(kappa), CANT_BASE_MM) / CANT_BASE_MM)
    lean_in = th_c + flexibility * (th_c - th_eq)
    roll = -math.copysign(lean_in, kappa) if kappa != 0.0 else 0.0
    pitch = math.atan(track_grade(track, s))
    return kappa, c, math.degrees(roll), math.degrees(pitch)


def body_rotation(roll_deg, pitch_deg):
    """(3, 3): the body's axes (columns x fwd, y left, z up) in the LEVEL vehicle frame,
    pitched about the level left axis, then rolled about the pitched forward axis."""
    r, p = math.radians(roll_deg), math.radians(pitch_deg)
    # roll about x: the left axis y -> (0, cos r, sin r), i.e. up when r > 0 (left raised)
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    # pitch: the forward axis x -> (cos p, 0, sin p), i.e. the nose up when p > 0
    Rp = np.array([[math.cos(p), 0, -math.sin(p)], [0, 1, 0], [math.sin(p), 0, math.cos(p)]])
    return Rp @ Rx


def camera_pose(track, s, h_ant, side, roll_deg=None, pitch_deg=None):
    """Camera centre (3,) and R_cw (columns = camera axes in world) for the ``side`` camera at
    chainage s, and the antenna (3,). Without an attitude: the level vehicle (the original
    code path). With one: the whole vehicle rotated by the body rotation about the point of
    the track axis at rail level, so the antenna moves ~h_ant * sin(roll) toward the side
    going down and the cameras' optical axes turn with the body."""
    lat, lon, h, Rv = track.pose(s)  # Rv: level vehicle -> world
    mt = MOUNTS[side]
    ant = track.world_from_geo(lat, lon, h + h_ant)
    if roll_deg is None:
        R_cw = Rv @ cam_to_vehicle(mt)
        c_pos = ant + Rv @ np.array(mt["lever_arm_m"])
        return c_pos, R_cw, ant
    rail = track.world_from_geo(lat, lon, h)
    Rb = Rv @ body_rotation(roll_deg, pitch_deg or 0.0)  # body -> world
    Rrot = Rb @ Rv.T  # the rotation about the rail point, in the world frame
    ant_b = rail + Rrot @ (ant - rail)
    c_pos = ant_b + Rb @ np.array(mt["lever_arm_m"])
    R_cw = Rb @ cam_to_vehicle(mt)
    return c_pos, R_cw, ant_b


# ---------------------------------------------------------------------------------------------
# materials and shading

MATS = {
    # albedo rgb, noise amplitude, reflectance (mirror share at normal incidence), windows
    "grass": ((0.16, 0.22, 0.08), 0.5, 0.0),
    "ballast": ((0.30, 0.27, 0.24), 0.6, 0.0),
    "brick": ((0.42, 0.20, 0.14), 0.35, 0.0),
    "render": ((0.70, 0.64, 0.52), 0.2, 0.0),
    "tiles": ((0.45, 0.18, 0.12), 0.3, 0.0),
    "slate": ((0.17, 0.18, 0.21), 0.25, 0.0),
    "glass": ((0.10, 0.16, 0.18), 0.1, 0.55),
    "white": ((0.86, 0.86, 0.84), 0.12, 0.0),
    "pale": ((0.80, 0.77, 0.68), 0.15, 0.0),
    "dark_metal": ((0.10, 0.11, 0.12), 0.1, 0.05),
    "steel": ((0.35, 0.40, 0.42), 0.2, 0.0),
    "stone": ((0.56, 0.51, 0.43), 0.35, 0.0),
    "tree": ((0.07, 0.14, 0.05), 0.9, 0.0),
    "galv": ((0.50, 0.52, 0.52), 0.25, 0.0),
    "canopy": ((0.75, 0.76, 0.78), 0.1, 0.0),
    "concrete": ((0.55, 0.54, 0.50), 0.3, 0.0),
    "wet": ((0.08, 0.08, 0.08), 0.3, 0.55),
}


class World:
    def __init__(self, mb: MeshBuilder, wires, sky: Sky, seed: int):
        self.V, self.F, self.tri_obj = mb.arrays()
        self.objs = mb.objs
        self.wires = wires
        self.sky = sky
        self.seed = seed
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor(self.V.astype(np.float32)), o3d.core.Tensor(self.F.astype(np.uint32))  # type: ignore[call-overload]
        )
        self.obj_cls = np.array([CLS[o.cls] for o in self.objs], np.int32)
        names = list(MATS)
        self.obj_mat = np.array([names.index(o.mat) for o in self.objs], np.int32)
        self.mat_alb = np.array([MATS[n][0] for n in names])
        self.mat_noise = np.array([MATS[n][1] for n in names])
        self.mat_refl = np.array([MATS[n][2] for n in names])
        self.obj_org = np.array([o.origin for o in self.objs])
        self.obj_ax = np.array([o.axes for o in self.objs])
        self.obj_floor = np.array([o.params.get("floors", 0.0) for o in self.objs])
        self.obj_win = np.array([o.params.get("win", 0.0) for o in self.objs])
        w_all = [w.pts for w in wires]
        self.wire_pts = w_all

    def cast(self, o, d):
        rays = np.concatenate([np.broadcast_to(o, d.shape), d], -1).astype(np.float32)
        ans = self.scene.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6)), nthreads=0)  # type: ignore[call-overload]
        t = ans["t_hit"].numpy().reshape(d.shape[:-1])
        pid = ans["primitive_ids"].numpy().reshape(d.shape[:-1]).astype(np.int64)
        nrm = ans["primitive_normals"].numpy().reshape(d.shape)
        hit = np.isfinite(t)
        obj = np.where(hit, self.tri_obj[np.where(hit, pid, 0)], -1)
        return t, obj, nrm.astype(float), hit

    def occluded(self, p, d):
        rays = np.concatenate([p, np.broadcast_to(d, p.shape)], -1).astype(np.float32)
        ans = self.scene.test_occlusions(
            o3d.core.Tensor(rays.reshape(-1, 6)), tnear=0.02, tfar=1e4, nthreads=0  # type: ignore[call-overload]
        )
        return ans.numpy().reshape(p.shape[:-1]).astype(bool)

    def shade(self, p, d, nrm, obj, shadows=True):
        """Lambertian + windows; returns colour and mirror reflectance per hit."""
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-9)
        flip = np.sum(nrm * d, -1) > 0
        nrm[flip] *= -1
        mat = self.obj_mat[obj]
        alb = self.mat_alb[mat].copy()
        na = self.mat_noise[mat]
        refl = self.mat_refl[mat].copy()
        n1 = fbm3(p * 1.7, 2, self.seed)
        n2 = value_noise3(p * 9.0, self.seed + 3)
        alb *= 1 + na[:, None] * ((n1 - 0.5) * 1.2 + (n2 - 0.5) * 0.5)[:, None]
        # windows / mullions on facades: local coordinates of the hit in the object's frame
        fl = self.obj_floor[obj]
        has = (fl > 0) & (np.abs(nrm @ np.array([0, 0, 1.0])) < 0.5)
        if has.any():
            ii = np.flatnonzero(has)
            ax = self.obj_ax[obj[ii]]
            loc = np.einsum("nij,ni->nj", ax, p[ii] - self.obj_org[obj[ii]])
            nl = np.abs(np.einsum("nij,ni->nj", ax, nrm[ii]))
            hcoord = np.where(nl[:, 0] > nl[:, 1], loc[:, 1], loc[:, 0])
            z = loc[:, 2]
            sp = self.obj_win[obj[ii]]
            fh = fl[ii]
            mi = self.obj_mat[obj[ii]]
            is_glass = mi == list(MATS).index("glass")
            fu, fz = np.mod(hcoord / sp, 1.0), np.mod(z / fh, 1.0)
            win = (fu > 0.2) & (fu < 0.8) & (fz > 0.3) & (fz < 0.85) & (z > 1.0)
            mull = (fu < 0.06) | (fz < 0.08)
            a = alb[ii]
            r = refl[ii]
            # glass curtain wall: glass everywhere but the mullion grid
            a[is_glass & mull] = (0.32, 0.33, 0.35)
            r[is_glass & mull] = 0.05
            w2 = ~is_glass & win
            a[w2] = (0.05, 0.06, 0.07)
            r[w2] = 0.35
            alb[ii], refl[ii] = a, r
        s = self.sky
        cos_s = np.clip(nrm @ s.sun, 0, None)
        direct = s.sun_E * cos_s
        if shadows and s.sun_E > 0:
            lit = cos_s > 0
            if lit.any():
                occ = self.occluded(p[lit] + nrm[lit] * 0.03, s.sun)
                dd = direct[lit]
                dd[occ] = 0
                direct[lit] = dd
        ambient = (0.55 + 0.45 * nrm[:, 2])[:, None] * s.amb
        col = alb * (direct[:, None] * np.array([1.0, 0.97, 0.9]) + ambient)
        return col, refl, nrm

    def render(self, cam: Fisheye, c_pos, R_cw, rays_cam, valid):
        """Linear RGB image and object-id buffer; R_cw columns = camera axes in world."""
        H, W = valid.shape
        img = np.zeros((H, W, 3))
        objbuf = np.full((H, W), -1, np.int32)
        tbuf = np.full((H, W), np.inf)
        d = rays_cam[valid] @ R_cw.T
        t, obj, nrm, hit = self.cast(c_pos, d)
        col = np.zeros(d.shape)
        col[~hit] = self.sky.radiance(d[~hit])
        ph = c_pos + d[hit] * t[hit, None]
        c, refl, nn = self.shade(ph, d[hit], nrm[hit], obj[hit])
        mir = refl > 0
        if mir.any():
            dh = d[hit][mir]
            nm = nn[mir]
            cosi = np.clip(-np.sum(dh * nm, -1), 0, 1)
            R = refl[mir] + (1 - refl[mir]) * 0.9 * (1 - cosi) ** 5
            rd = dh - 2 * np.sum(dh * nm, -1)[:, None] * nm
            po = ph[mir] + nm * 0.02
            rays = np.concatenate([po, rd], -1).astype(np.float32)
            ans = self.scene.cast_rays(o3d.core.Tensor(rays), nthreads=0)  # type: ignore[call-overload]
            t2 = ans["t_hit"].numpy()
            h2 = np.isfinite(t2)
            rc = np.zeros(rd.shape)
            rc[~h2] = self.sky.radiance(rd[~h2])
            if h2.any():
                p2 = po[h2] + rd[h2] * t2[h2, None]
                o2 = self.tri_obj[ans["primitive_ids"].numpy()[h2].astype(np.int64)]
                c2, _, _ = self.shade(
                    p2,
                    rd[h2],
                    ans["primitive_normals"].numpy()[h2].astype(float),
                    o2,
                    shadows=False,
                )
                rc[h2] = c2
            c[mir] = c[mir] * (1 - R[:, None]) + rc * R[:, None]
        col[hit] = c
        img[valid] = col
        ob = np.where(hit, obj, -1)
        objbuf[valid] = ob
        tbuf[valid] = np.where(hit, t, np.inf)
        img = self._wires(img, cam, c_pos, R_cw, tbuf)
        return img, objbuf, tbuf

    def _wires(self, img, cam, c_pos, R_cw, tbuf):
        """Thin wires: projected, sub-pixel coverage splatted, occluded by the depth buffer."""
        H, W = tbuf.shape
        cov = np.zeros((H, W))
        segs_a, segs_b, rad_a = [], [], []
        for w in self.wire_pts:
            if np.min(np.linalg.norm(w - c_pos, axis=1)) > 150:
                continue
            segs_a.append(w[:-1])
            segs_b.append(w[1:])
            rad_a.append(np.full(len(w) - 1, 0.006 if len(w) > 2 else 0.003))
        if not segs_a:
            return img
        A, B, rad = np.vstack(segs_a), np.vstack(segs_b), np.concatenate(rad_a)
        # subdivide every segment into pieces ~0.25 m
        L = np.linalg.norm(B - A, axis=1)
        n = np.maximum(1, np.ceil(L / 0.25)).astype(int)
        rep = np.repeat(np.arange(len(A)), n)
        frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 0.5) / np.repeat(n, n)
        P = A[rep] + (B[rep] - A[rep]) * frac[:, None]
        dl = L[rep] / n[rep]
        rr = rad[rep]
        Xc = (P - c_pos) @ R_cw  # camera frame
        dist = np.linalg.norm(Xc, axis=1)
        u, v = cam.project(Xc)
        ok = np.isfinite(u) & (dist > 0.5)
        # sub-sample in the image so the splats are < 0.5 px apart
        u, v, dist, dl, rr = u[ok], v[ok], dist[ok], dl[ok], rr[ok]
        seg_px = dl / dist * cam.f
        m = np.maximum(1, np.ceil(seg_px * 2)).astype(int)
        m = np.minimum(m, 400)
        rep = np.repeat(np.arange(len(u)), m)
        off = (np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m) + 0.5) / np.repeat(m, m) - 0.5
        # direction of the wire in the image: from neighbouring points (approximate by the
        # local gradient of consecutive samples)
        du = np.gradient(u)
        dv = np.gradient(v)
        nrm = np.hypot(du, dv) + 1e-9
        uu = u[rep] + off * seg_px[rep] * du[rep] / nrm[rep]
        vv = v[rep] + off * seg_px[rep] * dv[rep] / nrm[rep]
        width_px = 2 * rr[rep] / dist[rep] * cam.f
        wgt = width_px * seg_px[rep] / m[rep]
        iu, iv = np.floor(uu).astype(int), np.floor(vv).astype(int)
        fu, fv = uu - iu, vv - iv
        dd = dist[rep]
        for ox, oy, ww in (
            (0, 0, (1 - fu) * (1 - fv)),
            (1, 0, fu * (1 - fv)),
            (0, 1, (1 - fu) * fv),
            (1, 1, fu * fv),
        ):
            x, y = iu + ox, iv + oy
            k = (x >= 0) & (x < W) & (y >= 0) & (y < H)
            x, y, w_ = x[k], y[k], (wgt * ww)[k]
            vis = dd[k] < tbuf[y, x] - 0.3
            np.add.at(cov, (y[vis], x[vis]), w_[vis])
        a = np.clip(cov, 0, 1)[..., None]
        wire_col = np.array([0.05, 0.05, 0.05]) * (1 + self.sky.amb)
        return img * (1 - a) + wire_col * a


def finish_image(img, valid, th, cam, rng):
    """Exposure, vignetting, noise, tone curve -> 8-bit BGR."""
    lum = img[..., 0] * 0.3 + img[..., 1] * 0.59 + img[..., 2] * 0.11
    ref = np.percentile(lum[valid], 96)
    x = img * (0.88 / max(ref, 1e-6))
    vig = 1 - 0.38 * np.clip(th / cam.theta_max, 0, 1) ** 2.5
    x = x * vig[..., None]
    x = np.clip(x, 0, None)
    x = x + rng.normal(0, 1, x.shape) * np.sqrt(0.0006 * x + 0.0025**2)
    x[~valid] = np.abs(rng.normal(0, 0.004, x[~valid].shape))
    x = np.clip(x, 0, 1)
    x = np.where(x < 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)[..., ::-1]


# ---------------------------------------------------------------------------------------------
# ground truth: highest blocked elevation per 0.5 deg bin, from each antenna


def true_masks(world: World, track: Track, chainages, h_ant, n_sub=5, az_step=0.5):
    """Per position and 0.5 deg bin: highest blocked elevation over ``n_sub`` sub-azimuths
    (max -> mask_el_deg, min -> mask_min_el_deg) and the object there. Elevations are scanned
    every 0.05 deg up to 30 deg (distant thin parts: cantilever tubes, lamp arms) and every
    0.1 deg above, then the highest blocked sample is refined by 5 bisections (< 0.004 deg)
    toward the next sample. Parts thinner than the scan step can be missed (section "Truth
    limits" in docs/synthetic-world.md)."""
    n_az = round(360 / az_step)
    sub = (np.arange(n_sub) - (n_sub - 1) / 2) * az_step / n_sub
    az = (np.arange(n_az)[:, None] * az_step + sub[None, :]).ravel()  # (n_az*n_sub,)
    el_c = np.concatenate([np.arange(0, 30, 0.05), np.arange(30, 90 + 1e-9, 0.1)])
    out_max = np.zeros((len(chainages), n_az))
    out_min = np.zeros((len(chainages), n_az))
    obj_top = np.full((len(chainages), n_az), -1, np.int32)
    covered = np.zeros(len(chainages), bool)
    ant = []
    for i, s in enumerate(chainages):
        lat, lon, h = (float(np.asarray(v).ravel()[0]) for v in track.tm.position_at([s]))
        M = track.local_to_world(lat, lon)
        o = track.world_from_geo(lat, lon, h + h_ant)
        ant.append((lat, lon, h + h_ant))
        a = np.radians(az)[:, None]
        e = np.radians(el_c)[None, :]
        dl = np.stack(
            [
                np.sin(a) * np.cos(e),
                np.cos(a) * np.cos(e),
                np.broadcast_to(np.sin(e), (len(az), len(el_c))),
            ],
            -1,
        )
        dw = dl @ M.T
        _t, obj, _, hit = world.cast(o, dw)
        anyhit = hit.any(1)
        top = np.where(anyhit, len(el_c) - 1 - np.argmax(hit[:, ::-1], 1), -1)
        lo = np.where(top >= 0, el_c[np.maximum(top, 0)], 0.0)
        top_obj = np.where(top >= 0, obj[np.arange(len(az)), np.maximum(top, 0)], -1)
        # bisection between the highest blocked coarse sample and the next one
        ref = (top >= 0) & (top < len(el_c) - 1)
        lo_r = lo[ref].copy()
        hi_r = el_c[np.minimum(top[ref] + 1, len(el_c) - 1)]
        azr = np.radians(az[ref])
        ob_r = top_obj[ref].copy()
        for _ in range(5):
            mid = 0.5 * (lo_r + hi_r)
            em = np.radians(mid)
            d = np.stack([np.sin(azr) * np.cos(em), np.cos(azr) * np.cos(em), np.sin(em)], -1) @ M.T
            _, ob, _, hh = world.cast(o, d)
            lo_r = np.where(hh, mid, lo_r)
            hi_r = np.where(hh, hi_r, mid)
            ob_r = np.where(hh, ob, ob_r)
        lo[ref] = lo_r
        top_obj[ref] = ob_r
        lo[top == len(el_c) - 1] = 90.0
        m = lo.reshape(n_az, n_sub)
        out_max[i] = m.max(1)
        out_min[i] = m.min(1)
        tob = top_obj.reshape(n_az, n_sub)
        obj_top[i] = tob[np.arange(n_az), m.argmax(1)]
        _, _, _, hz = world.cast(o, (M @ np.array([0, 0, 1.0]))[None])
        covered[i] = bool(hz[0])
    return out_max, out_min, obj_top, covered, np.array(ant)


# ---------------------------------------------------------------------------------------------
# build command


def survey_rows_time(i):
    return 1400000000.0 + i * 10.0 / 15.0


def cmd_build(args):
    out = Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    (out / "images").mkdir(parents=True)
    (out / "calib").mkdir()
    (out / "truth").mkdir()
    (out / "world").mkdir()
    (out / "track").mkdir()
    s0, s1 = args.start, args.start + args.length
    track = Track(s0 - 200, s1 + 200, (s0 + s1) / 2)
    t0 = time.time()
    mb, wires, layout = build_world(track, args.seed, s0, s1)
    rng = np.random.default_rng(args.seed + 1000)
    sky = Sky(args.sky, rng)
    world = World(mb, wires, sky, args.seed)
    print(
        f"world: {len(world.F)} triangles, {len(world.objs)} objects, {len(wires)} wires "
        f"({time.time() - t0:.1f} s)",
        flush=True,
    )
    np.savez_compressed(
        out / "world" / "mesh.npz",
        V=world.V,
        F=world.F,
        tri_obj=world.tri_obj,
        obj_cls=world.obj_cls,
    )
    (out / "world" / "objects.json").write_text(
        json.dumps(
            {
                "classes": CLASSES,
                "objects": [{"cls": o.cls, "mat": o.mat} for o in world.objs],
                "layout": layout,
                "frame_mid_chainage_m": (s0 + s1) / 2,
                "sky": {"mode": sky.mode, "sun_az": sky.sun_az, "sun_el": sky.sun_el},
                "wires": [w.pts.tolist() for w in wires],
            },
            default=float,
        )
    )

    cam = Fisheye()
    for side in ("left", "right"):
        cam.write_calib(out / "calib" / f"{side}.yaml", f"indep_fisheye_{side}")
    import predisat.track.map as tmmod
    from predisat.track.map import demo_track  # noqa: F401  (the same track the survey names)

    src = Path(tmmod.__file__).resolve().parent.parent / "data" / "line144_track_A.geojson"
    shutil.copy(src, out / "track" / "line144_track_A.geojson")

    chain = np.round(np.arange(s0, s1 + 1e-6, args.step), 3)
    if args.only:  # a preview: only these position indices
        chain = chain[[int(x) for x in args.only.split(",")]]
    rays_cam, valid, th = cam.pixel_rays()
    rows = []
    frng = np.random.default_rng(args.seed + 7)
    keep_obj = set(int(x) for x in args.keep_objbuf.split(",")) if args.keep_objbuf else set()
    cant = args.cant_speed_kmh is not None
    imu = cant and not args.no_imu
    att_rows = []
    if cant:
        v_kmh = survey_speed_mps(args.step) * 3.6
        print(
            f"canted vehicle: design speed {args.cant_speed_kmh:g} km/h, survey speed "
            f"{v_kmh:.1f} km/h, max cant {args.max_cant_mm:g} mm, flexibility "
            f"{args.flexibility:g}, IMU columns {'yes' if imu else 'no'}",
            flush=True,
        )
    for i, s in enumerate(chain):
        lat, lon, h, Rv = track.pose(s)  # Rv: vehicle -> world
        gps = survey_rows_time(i)
        roll = pitch = None
        if cant:
            kappa, c_mm, roll, pitch = vehicle_attitude(
                track, s, args.cant_speed_kmh, v_kmh, args.max_cant_mm, args.flexibility
            )
            _, _, ant_b = camera_pose(track, s, args.antenna_height, "left", roll, pitch)
            ant_n = track.world_from_geo(lat, lon, h + args.antenna_height)
            dlat = float((ant_b - ant_n) @ Rv[:, 1])
            att_rows.append((s, kappa, c_mm, roll, pitch, dlat))
        if args.no_images:
            continue
        for side in ("left", "right"):
            c_pos, R_cw, _ = camera_pose(track, s, args.antenna_height, side, roll, pitch)
            img, objbuf, tbuf = world.render(cam, c_pos, R_cw, rays_cam, valid)
            bgr = finish_image(img, valid, th, cam, frng)
            fid = f"{side}_{i:06d}"
            _ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 90])
            (out / "images" / f"{fid}.jpg").write_bytes(buf.tobytes())
            if i in keep_obj:
                np.savez_compressed(
                    out / "world" / f"objbuf_{fid}.npz", obj=objbuf, t=tbuf, c_pos=c_pos, R_cw=R_cw
                )
            rows.append(
                (
                    fid,
                    f"images/{fid}.jpg",
                    side,
                    f"{gps:.3f}",
                    f"{s:.3f}",
                    f"{lat:.9f}",
                    f"{lon:.9f}",
                    f"{h + args.antenna_height:.3f}",
                )
                + ((f"{roll:.4f}", f"{pitch:.4f}") if imu else ())
            )
        if i % 10 == 0:
            print(f"frame {i}/{len(chain)} at {s:.0f} m, {time.time() - t0:.0f} s", flush=True)

    with open(out / "manifest.csv", "w") as fh:
        fh.write(
            "frame_id,image,side,gps_s,chainage_m,lat_deg,lon_deg,h_m"
            + (",roll_deg,pitch_deg" if imu else "")
            + "\n"
        )
        for r in rows:
            fh.write(",".join(r) + "\n")
    sy = {
        "format": "predisat-survey",
        "version": 1,
        "direction_of_travel": "increasing",
        "antenna_height_m": float(args.antenna_height),
        # no track.name: the loader uses it to select a feature of the file, and the shipped
        # file's only feature is named "line 144 track A (...)"; "line144_track_A" (the
        # docs' example) is refused (format friction, see the report)
        "track": {"path": "track/line144_track_A.geojson"},
        "cameras": {
            side: {"calibration": f"calib/{side}.yaml", "mount": MOUNTS[side]}
            for side in ("left", "right")
        },
        "description": f"independent world, seed {args.seed}, sky {args.sky}",
        "generator": "scripts/independent_world.py",
    }
    if cant:  # metadata (extra survey.yaml keys are kept, not read)
        sy["canted_vehicle"] = {
            "design_speed_kmh": float(args.cant_speed_kmh),
            "survey_speed_kmh": round(v_kmh, 3),
            "max_cant_mm": float(args.max_cant_mm),
            "flexibility": float(args.flexibility),
            "imu_in_manifest": bool(imu),
        }
        with open(out / "truth" / "cant.csv", "w") as fh:
            fh.write("chainage_m,cant_mm\n")
            for a in att_rows:
                fh.write(f"{a[0]:.3f},{a[2]:.0f}\n")
        # the attitude every frame was rendered with (also with --no-imu), for the checks
        with open(out / "world" / "attitude.csv", "w") as fh:
            fh.write("chainage_m,kappa_per_m,cant_mm,roll_deg,pitch_deg,antenna_left_shift_m\n")
            for a in att_rows:
                fh.write(f"{a[0]:.3f},{a[1]:.7e},{a[2]:.0f},{a[3]:.6f},{a[4]:.6f},{a[5]:.4f}\n")
    (out / "survey.yaml").write_text(yaml.safe_dump(sy, sort_keys=False))

    print("truth ...", flush=True)
    mx, mn, ob, cov, ant = true_masks(world, track, chain, args.antenna_height)
    from predisat.masks.truth import TrueMasks

    n = len(chain)
    tm = TrueMasks(
        chainage_m=chain.astype(float),
        lat_deg=ant[:, 0],
        lon_deg=ant[:, 1],
        h_m=ant[:, 2],
        heading_deg=np.asarray(track.tm.heading_at(chain), float),
        az_deg=np.arange(720) * 0.5,
        mask_el_deg=mx,
        mask_min_el_deg=mn,
        covered=cov,
        obstacle_distance_m=np.full((n, 2), np.nan),
        obstacle_height_m=np.full((n, 2), np.nan),
        antenna_height_m=float(args.antenna_height),
        az_step_deg=0.5,
        backend="open3d (scripts/independent_world.py)",
    )
    tm.save(out / "truth" / "true_masks.npz")
    np.savez_compressed(
        out / "truth" / "truth_objects.npz",
        obj_top=ob,
        cls_top=np.where(ob >= 0, world.obj_cls[np.maximum(ob, 0)], -1),
    )
    print(f"done in {time.time() - t0:.0f} s", flush=True)


def load_world(out):
    out = Path(out)
    meta = json.loads((out / "world" / "objects.json").read_text())
    z = np.load(out / "world" / "mesh.npz")
    return meta, z


def main(argv=None):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="world, survey and truth")
    b.add_argument("out")
    b.add_argument("--seed", type=int, default=1)
    b.add_argument("--sky", choices=["cloudy", "overcast"], default="cloudy")
    b.add_argument("--start", type=float, default=6000.0)
    b.add_argument("--length", type=float, default=1000.0)
    b.add_argument("--step", type=float, default=10.0)
    b.add_argument("--antenna-height", type=float, default=4.0)
    b.add_argument(
        "--keep-objbuf", default="0,37,73", help="frame indices whose object-id buffer is kept"
    )
    b.add_argument("--no-images", action="store_true")
    b.add_argument("--only", default="", help="preview: only these position indices")
    b.add_argument(
        "--cant-speed-kmh",
        type=float,
        default=None,
        help="canted vehicle: the line's design speed (km/h) giving each curve's equilibrium "
        "cant; the body rolls toward the inside (default: a level vehicle)",
    )
    b.add_argument("--max-cant-mm", type=float, default=160.0)
    b.add_argument("--flexibility", type=float, default=0.25, help="suspension flexibility")
    b.add_argument(
        "--no-imu", action="store_true", help="canted, but no roll_deg/pitch_deg in the manifest"
    )
    from indep_checks import add_commands

    add_commands(sub)
    args = ap.parse_args(argv)
    if getattr(args, "cmd", "") == "build" and args.no_imu and args.cant_speed_kmh is None:
        ap.error("--no-imu needs --cant-speed-kmh (a level vehicle has no attitude columns)")
    return args.func(args) if hasattr(args, "func") else cmd_build(args)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main() or 0)
