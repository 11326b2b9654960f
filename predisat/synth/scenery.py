"""Procedural scenery along a track: the geometry behind :class:`predisat.synth.world.World`.

Everything is placed in *corridor coordinates* ``(s, y, z)``: chainage ``s`` along the smooth track
axis, ``y`` horizontal offset to the left of increasing chainage and ``z`` height above the rail
along the local vertical (ellipsoid normal). :class:`Corridor` maps them into the track's ENU
frame, so long objects (platforms, walls, cuttings, wires) follow curves and grades, while compact
objects (buildings, masts, trees, bridges) are rigid and set in the corridor's local axes at their
centre. Closed solids are built with outward-facing triangles so that rays from outside hit them
and renderers can shade them.

Each stretch builder takes its own ``numpy.random.Generator``; nothing here uses global state.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from predisat.geodesy import LocalFrame
from predisat.readonly import freeze_array_fields

if TYPE_CHECKING:  # world imports this module: the type only, no import at run time
    from predisat.synth.world import Stretch

__all__ = [
    "Context",
    "Corridor",
    "MeshBuilder",
    "build_catenary",
    "build_stretch",
]

_GROUND_Z = -0.5  # formation level below the rail top, metres
_H_BEAM = ((-0.14, 0.14, -0.14, -0.12), (-0.14, 0.14, 0.12, 0.14), (-0.01, 0.01, -0.14, 0.14))
"""Mast section (a0, a1, b0, b1) in metres: two flanges across the track and a web."""
_SIDES = {"left": (1.0,), "right": (-1.0,), "both": (1.0, -1.0)}


class _TrackLike(Protocol):
    @property
    def frame(self) -> LocalFrame: ...
    @property
    def length_m(self) -> float: ...

    def enu_at(self, chainage_m: ArrayLike) -> NDArray: ...
    def heading_at(self, chainage_m: ArrayLike) -> NDArray: ...
    def position_at(self, chainage_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]: ...


@dataclass(frozen=True)
class Corridor:
    """The track axis sampled densely with its local horizontal tangent, left normal and up.

    Attributes
    ----------
    s_m : ndarray, shape (k,)
        Sample chainages, metres, increasing.
    point_m, tangent, left, up : ndarray, shape (k, 3)
        Axis point (rail level) and unit vectors in the track frame's ENU. ``tangent`` is the
        horizontal direction of increasing chainage in the local ENU at the point (from
        ``heading_at``), ``up`` the local ellipsoid normal, ``left = up x tangent``.
    h_m : ndarray, shape (k,)
        Ellipsoidal height of the axis, metres.
    """

    s_m: NDArray
    point_m: NDArray
    tangent: NDArray
    left: NDArray
    up: NDArray
    h_m: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @classmethod
    def from_track(
        cls, track: _TrackLike, start_m: float, end_m: float, step_m: float = 1.0
    ) -> Corridor:
        """Sample ``track`` every ``step_m`` over ``[start_m, end_m]`` clipped to the track."""
        lo, hi = max(0.0, float(start_m)), min(float(track.length_m), float(end_m))
        if not hi > lo:
            raise ValueError(
                f"corridor [{start_m}, {end_m}] m does not overlap the track [0, "
                f"{track.length_m:.1f}] m; choose stretches inside the track"
            )
        s = np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / step_m)) + 1))
        lat, lon, h = track.position_at(s)
        rot = track.frame.rotation_from(lat, lon)  # local ENU -> frame
        hd = np.radians(np.asarray(track.heading_at(s), float))
        t_local = np.stack([np.sin(hd), np.cos(hd), np.zeros_like(hd)], axis=-1)
        tangent = np.einsum("kij,kj->ki", rot, t_local)
        up = rot[:, :, 2]
        left = np.cross(up, tangent)
        return cls(s, np.asarray(track.enu_at(s), float), tangent, left, up, np.asarray(h))

    def basis(self, s_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """Axis point, tangent, left and up at chainages ``s_m`` (...), each (..., 3).

        Linear between samples; beyond the ends the axis continues straight along the end
        tangent (so scenery may overhang the sampled range).
        """
        s = np.asarray(s_m, float)
        flat = s.ravel()
        idx = np.clip(np.searchsorted(self.s_m, flat) - 1, 0, self.s_m.size - 2)
        s0, s1 = self.s_m[idx], self.s_m[idx + 1]
        w = np.clip((flat - s0) / (s1 - s0), 0.0, 1.0)[:, None]
        out = []
        for arr in (self.point_m, self.tangent, self.left, self.up):
            v = arr[idx] * (1.0 - w) + arr[idx + 1] * w
            if arr is not self.point_m:
                v /= np.linalg.norm(v, axis=-1, keepdims=True)
            out.append(v)
        beyond = np.where(flat < self.s_m[0], flat - self.s_m[0], 0.0)
        beyond = np.where(flat > self.s_m[-1], flat - self.s_m[-1], beyond)
        out[0] = out[0] + beyond[:, None] * out[1]
        p, t, left, up = (v.reshape((*s.shape, 3)) for v in out)
        return p, t, left, up

    def place(self, s_m: ArrayLike, y_m: ArrayLike, z_m: ArrayLike) -> NDArray:
        """Frame ENU points (..., 3) of corridor coordinates (broadcast together)."""
        s, y, z = np.broadcast_arrays(*(np.asarray(a, float) for a in (s_m, y_m, z_m)))
        p, _, left, up = self.basis(s)
        return p + y[..., None] * left + z[..., None] * up

    def place_local(self, s_c: float, local_m: ArrayLike) -> NDArray:
        """Rigid placement: points ``(a, b, c)`` (..., 3) in the axes at chainage ``s_c``
        (``a`` along the tangent, ``b`` to the left, ``c`` up) to frame ENU (..., 3)."""
        p, t, left, up = self.basis(np.array([s_c], float))
        axes = np.stack([t[0], left[0], up[0]])  # rows: a, b, c directions
        return p[0] + np.asarray(local_m, float) @ axes


class MeshBuilder:
    """Accumulates triangle meshes (vertices in frame ENU) with one material id per face."""

    def __init__(self) -> None:
        self._vertices: list[NDArray] = []
        self._faces: list[NDArray] = []
        self._materials: list[NDArray] = []
        self._count = 0

    def add(self, vertices_m: ArrayLike, faces: ArrayLike, material: int | ArrayLike) -> None:
        """Append a mesh: vertices (n, 3) metres, faces (m, 3) indexing them, and one material
        id or one per face (m,)."""
        v = np.asarray(vertices_m, float).reshape(-1, 3)
        f = np.asarray(faces, np.int64).reshape(-1, 3)
        self._vertices.append(v)
        self._faces.append(f + self._count)
        self._materials.append(np.broadcast_to(np.asarray(material, np.int16), f.shape[:1]))
        self._count += v.shape[0]

    def result(self) -> tuple[NDArray, NDArray, NDArray]:
        """``(vertices_m (n, 3) float64, faces (m, 3) int32, face_material (m,) int16)``."""
        if not self._faces:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int16)
        return (
            np.concatenate(self._vertices),
            np.concatenate(self._faces).astype(np.int32),
            np.concatenate(self._materials).astype(np.int16),
        )


# --------------------------------------------------------------------------------------------
# Primitives (vertices in whatever coordinates; callers map them)
# --------------------------------------------------------------------------------------------

_BOX_FACES = np.array(
    [
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ]
)


def _box(a0: float, a1: float, b0: float, b1: float, c0: float, c1: float) -> NDArray:
    """8 corners of an axis-aligned box in the order used by ``_BOX_FACES`` (outward)."""
    return np.array(
        [
            [a0, b0, c0],
            [a1, b0, c0],
            [a1, b1, c0],
            [a0, b1, c0],
            [a0, b0, c1],
            [a1, b0, c1],
            [a1, b1, c1],
            [a0, b1, c1],
        ]
    )


def _outward(vertices: NDArray, faces: NDArray) -> NDArray:
    """Faces of a solid star-shaped about its vertex mean, wound to face outward."""
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    inward = np.sum((tri.mean(1) - vertices.mean(0)) * normal, axis=-1) < 0
    return np.where(inward[:, None], faces[:, ::-1], faces)


def _beam(p0: NDArray, p1: NDArray, width_m: float) -> NDArray:
    """8 corners of a square-section beam from ``p0`` to ``p1`` (frame points), box order."""
    d = p1 - p0
    d = d / np.linalg.norm(d)
    helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(helper, d)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    h = width_m / 2
    corners = _box(0.0, 1.0, -h, h, -h, h)
    a, b, c = corners[:, :1], corners[:, 1:2], corners[:, 2:]
    return p0 + a * (p1 - p0) + b * e1 + c * e2


def _polyline_beams(points: NDArray, width_m: float) -> tuple[NDArray, NDArray]:
    """Closed square beams along consecutive points (k, 3): vertices and faces."""
    verts = [_beam(points[i], points[i + 1], width_m) for i in range(len(points) - 1)]
    faces = [_BOX_FACES + 8 * i for i in range(len(verts))]
    return np.concatenate(verts), np.concatenate(faces)


def extrude(
    corridor: Corridor,
    s_m: ArrayLike,
    profiles: ArrayLike,
    cap: str = "fan",
) -> tuple[NDArray, NDArray, NDArray]:
    """Closed solid swept along the track through cross-sections ``(y, z)``.

    Parameters
    ----------
    s_m : array_like, shape (k,)
        Chainages of the cross-sections, increasing.
    profiles : array_like, shape (k, p, 2) or (p, 2)
        Closed polygon ``(y, z)`` at each chainage (same vertex count, any orientation).
        ``cap="fan"`` needs polygons star-shaped about their vertex mean; ``cap="strip"``
        takes an outer polyline followed by an inner one of equal length (an arch band) and
        joins vertex ``i`` with vertex ``p - 1 - i``.

    Returns
    -------
    vertices_m (n, 3), faces (m, 3), is_cap (m,) bool
    """
    s = np.asarray(s_m, float)
    prof = np.broadcast_to(np.asarray(profiles, float), (s.size, *np.shape(profiles)[-2:]))
    y, z = prof[..., 0], prof[..., 1]
    area = 0.5 * np.sum(y * np.roll(z, -1, axis=1) - np.roll(y, -1, axis=1) * z, axis=1)
    if np.mean(area) < 0:  # make counter-clockwise in (y, z) so side faces point outward
        prof = prof[:, ::-1]
    k, p = prof.shape[:2]
    verts = corridor.place(s[:, None], prof[..., 0], prof[..., 1]).reshape(-1, 3)
    i = np.arange(p)
    j = (i + 1) % p
    ks = np.arange(k - 1)[:, None] * p
    a, b, c, d = ks + i, ks + j, ks + p + j, ks + p + i
    sides = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], 0).reshape(-1, 3)
    last = (k - 1) * p
    if cap == "fan":
        centres = corridor.place(
            s[[0, -1]], prof[[0, -1], :, 0].mean(1), prof[[0, -1], :, 1].mean(1)
        )
        c0, c1 = k * p, k * p + 1
        verts = np.concatenate([verts, centres])
        caps = np.concatenate(
            [
                np.stack([np.full(p, c0), j, i], -1),
                np.stack([np.full(p, c1), last + i, last + j], -1),
            ]
        )
    elif cap == "strip":
        half = p // 2
        u, v = np.arange(half - 1), p - 1 - np.arange(half - 1)
        quad0 = [np.stack([u, v - 1, v], -1), np.stack([u, u + 1, v - 1], -1)]
        start = np.concatenate(quad0)[:, ::-1]
        caps = np.concatenate([start, last + np.concatenate(quad0)])
    else:
        raise ValueError(f"cap must be 'fan' or 'strip', got {cap!r}")
    faces = np.concatenate([sides, caps])
    is_cap = np.zeros(len(faces), bool)
    is_cap[len(sides) :] = True
    return verts, faces, is_cap


def _blob(
    rng: np.random.Generator, radius_m: float, subdivisions: int = 1
) -> tuple[NDArray, NDArray]:
    """A perturbed icosphere (outward faces) centred at the origin."""
    ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.asarray(ico.vertices)
    bump = 1.0 + 0.25 * rng.uniform(-1, 1, len(v))
    return v * (radius_m * bump)[:, None], np.asarray(ico.faces)


def _sides(stretch: Stretch) -> tuple[float, ...]:
    return _SIDES[stretch.side]


def _taper(s: NDArray, s0: float, s1: float, ramp_m: float) -> NDArray:
    """1 inside ``[s0, s1]``, falling smoothly to 0 over ``ramp_m`` inside each end."""
    r = max(min(ramp_m, (s1 - s0) / 2), 1e-6)
    x = np.clip(np.minimum(s - s0, s1 - s) / r, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _param(stretch: Stretch, name: str, rng: np.random.Generator, lo: float, hi: float) -> float:
    """A stretch parameter: the recipe's value if given, else uniform in ``[lo, hi]``."""
    draw = float(rng.uniform(lo, hi))  # always draw, so overrides do not shift other draws
    return float(stretch.params.get(name, draw))


# --------------------------------------------------------------------------------------------
# Stretch builders
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Context:
    """What a builder needs: the corridor, its random generator, material ids, the output."""

    corridor: Corridor
    rng: np.random.Generator
    mat: dict[str, int]
    mb: MeshBuilder

    def solid(self, s_c: float, corners: ArrayLike, faces: NDArray, material: str) -> None:
        """Add a rigid solid given in the local axes ``(a, b, c)`` at chainage ``s_c``."""
        self.mb.add(self.corridor.place_local(s_c, corners), faces, self.mat[material])

    def box(self, s_c: float, ab_c: tuple[float, ...], material: str) -> None:
        """Add a local box ``(a0, a1, b0, b1, c0, c1)`` (b may be given in either order)."""
        a0, a1, b0, b1, c0, c1 = ab_c
        self.solid(s_c, _box(a0, a1, min(b0, b1), max(b0, b1), c0, c1), _BOX_FACES, material)

    def sweep(self, s_m: ArrayLike, profiles: ArrayLike, material: str, cap: str = "fan") -> None:
        """Add the solid :func:`extrude` sweeps through ``profiles`` at chainages ``s_m``."""
        v, f, _ = extrude(self.corridor, s_m, profiles, cap)
        self.mb.add(v, f, self.mat[material])


def _building(ctx: Context, s_c: float, side: float, y_near: float, size: tuple, wall: str,
              roof: str | None) -> None:  # fmt: skip
    """A box building (``size`` = length along the track, depth, height) with a gable roof."""
    length, depth, height = size
    b0, b1 = sorted((side * y_near, side * (y_near + depth)))
    ctx.box(s_c, (-length / 2, length / 2, b0, b1, _GROUND_Z, height), wall)
    if roof is not None:  # ridge along the track
        prof = [[b0, height], [b1, height], [(b0 + b1) / 2, height + 0.25 * depth]]
        pts = np.array([[a, y, z] for a in (-length / 2, length / 2) for y, z in prof])
        faces = np.array([[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4],
                          [2, 0, 3], [2, 3, 5]])  # fmt: skip
        ctx.solid(s_c, pts, _outward(pts, faces), roof)


def _station(ctx: Context, st: Stretch) -> None:
    rng, (s0, s1) = ctx.rng, (st.start_m, st.end_m)
    edge = 1.65  # platform edge from the axis (loading gauge), 0.76 m high
    for side in _sides(st):
        width = _param(st, "platform_width_m", rng, 4.0, 7.0)
        ss = np.linspace(s0, s1, max(2, int((s1 - s0) / 5) + 1))
        plat = [[edge, _GROUND_Z], [edge + width, _GROUND_Z], [edge + width, 0.76], [edge, 0.76]]
        ctx.sweep(ss, np.array(plat) * [side, 1], "platform")
        with_canopy = rng.uniform() < 0.9
        if st.params.get("canopy", with_canopy):  # a roof overhanging the platform edge
            c_len = min(s1 - s0 - 10, _param(st, "canopy_length_m", rng, 40.0, 90.0))
            c_mid = (s0 + s1) / 2 + rng.uniform(-0.2, 0.2) * (s1 - s0 - c_len)
            y_edge = _param(st, "canopy_edge_m", rng, 2.0, 3.0)
            z_roof = 0.76 + _param(st, "canopy_height_m", rng, 3.0, 4.0)
            cs = np.linspace(c_mid - c_len / 2, c_mid + c_len / 2, max(2, int(c_len / 5) + 1))
            back = edge + width + 0.5
            prof = [[y_edge, z_roof], [back, z_roof + 0.4], [back, z_roof + 0.7],
                    [y_edge, z_roof + 0.3]]  # fmt: skip
            ctx.sweep(cs, np.array(prof) * [side, 1], "canopy")
            y_col = side * (edge + 0.6 * width)
            for sc in np.arange(cs[0] + 2, cs[-1] - 1, 8.0):
                ctx.box(sc, (-0.15, 0.15, y_col - 0.15, y_col + 0.15, 0.76, z_roof + 0.2), "steel")
        n_b = 1 if side > 0 or st.side != "both" else int(rng.integers(0, 2))
        for _ in range(n_b):  # station buildings behind the platform
            length = min(s1 - s0 - 4, float(rng.uniform(15.0, 40.0)))
            s_c = float(rng.uniform(s0 + length / 2 + 1, s1 - length / 2 - 1))
            y_near = max(edge + width + 0.3, _param(st, "building_distance_m", rng, 6.0, 15.0))
            size = (length, float(rng.uniform(8, 14)), _param(st, "building_height_m", rng, 4, 9))
            _building(ctx, s_c, side, y_near, size, "brick", "roof_tiles")


def _town(ctx: Context, st: Stretch) -> None:
    rng = ctx.rng
    for side in _sides(st):
        setback = _param(st, "facade_distance_m", rng, 5.0, 15.0)
        s = st.start_m + rng.uniform(0, 4)
        while s < st.end_m - 6:
            length = min(float(rng.uniform(8.0, 30.0)), st.end_m - s)
            if rng.uniform() < 0.2:  # side street
                s += rng.uniform(6.0, 15.0)
                continue
            height = _param(st, "facade_height_m", rng, 6.0, 25.0)
            y_near = float(np.clip(setback + rng.uniform(-1.0, 1.0), 5.0, 20.0))
            wall = ("plaster", "brick")[int(rng.integers(0, 2))]
            roof = "roof_tiles" if rng.uniform() < 0.5 else None
            size = (length, float(rng.uniform(10, 20)), height)
            _building(ctx, s + length / 2, side, y_near, size, wall, roof)
            s += length + (rng.uniform(0.0, 1.0) if rng.uniform() < 0.7 else 0.0)


def _tree(ctx: Context, s_c: float, y: float, height: float) -> None:
    """A trunk and an irregular crown of perturbed icospheres, with holes."""
    rng = ctx.rng
    trunk_top = float(rng.uniform(2.5, 4.0))
    r_crown = float(rng.uniform(0.22, 0.32)) * height
    tw = float(rng.uniform(0.15, 0.25))
    ctx.box(s_c, (-tw, tw, y - tw, y + tw, _GROUND_Z, trunk_top + r_crown), "bark")
    centre = np.array([0.0, y, height - r_crown])
    for k in range(int(rng.integers(3, 7))):
        if k > 0 and rng.uniform() < 0.15:
            continue
        c = centre + (rng.normal(0, 0.45 * r_crown, 3) * [1, 1, 0.6] if k else 0.0)
        c[2] = max(c[2], trunk_top + 0.5 * r_crown)
        v, f = _blob(rng, r_crown * float(rng.uniform(0.5, 0.8)))
        ctx.solid(s_c, v + c, f, "foliage")


def _trees(ctx: Context, st: Stretch) -> None:
    rng = ctx.rng
    for side in _sides(st):
        y_row = _param(st, "row_distance_m", rng, 6.0, 12.0)
        s = st.start_m + rng.uniform(0, 5)
        while s < st.end_m:
            if rng.uniform() > 0.15:  # gaps in the row
                h = _param(st, "tree_height_m", rng, 8.0, 18.0)
                _tree(ctx, s, side * (y_row + rng.uniform(-1.0, 1.0)), h)
            s += rng.uniform(5.0, 11.0)


def _open(ctx: Context, st: Stretch) -> None:
    rng = ctx.rng  # sparse isolated trees and farm sheds well away from the track
    rate_per_km = st.params.get("objects_per_km", 8.0)
    for _ in range(rng.poisson((st.end_m - st.start_m) * rate_per_km / 1000.0)):
        side = _sides(st)[int(rng.integers(0, len(_sides(st))))]
        s_c = float(rng.uniform(st.start_m, st.end_m))
        if rng.uniform() < 0.75:
            _tree(ctx, s_c, side * rng.uniform(20, 80), rng.uniform(6, 14))
        else:
            size = (float(rng.uniform(10, 25)), float(rng.uniform(8, 15)), rng.uniform(4, 7))
            _building(ctx, s_c, side, float(rng.uniform(30, 120)), size, "plaster", "roof_tiles")


def _cutting(ctx: Context, st: Stretch) -> None:
    rng = ctx.rng
    ss = np.linspace(st.start_m, st.end_m, max(2, int((st.end_m - st.start_m) / 4) + 1))
    for side in _sides(st):
        depth = _param(st, "depth_m", rng, 5.0, 15.0)
        toe = _param(st, "toe_distance_m", rng, 3.8, 5.0)
        slope = _param(st, "slope", rng, 1.0, 2.0)  # horizontal run per metre of rise (1:n)
        ph = rng.uniform(0, 2 * np.pi, 2)
        wobble = 1 + 0.12 * np.sin(ss / 37.0 + ph[0]) * np.sin(ss / 91.0 + ph[1])
        wobble = wobble if "depth_m" not in st.params else 1.0
        d = np.maximum(depth * wobble * _taper(ss, st.start_m, st.end_m, 40.0), 0.3)
        crest, g = toe + slope * (d - _GROUND_Z), np.full_like(d, _GROUND_Z)
        pts = [(toe + 0 * d, g), (crest, d), (crest + 4.0, d), (crest + 6.0 + 3.0 * d, g)]
        prof = np.stack([np.stack(p, -1) for p in pts], 1)
        ctx.sweep(ss, prof * [side, 1], "grass")


def _rock_walls(ctx: Context, st: Stretch) -> None:
    rng = ctx.rng
    ss = np.linspace(st.start_m, st.end_m, max(2, int((st.end_m - st.start_m) / 3) + 1))
    t = np.linspace(0.0, 1.0, 10)
    for side in _sides(st):
        height = _param(st, "height_m", rng, 20.0, 80.0)
        dist = _param(st, "distance_m", rng, 4.0, 15.0)
        rough = _param(st, "roughness_m", rng, 0.3, 1.2)
        lean = _param(st, "batter", rng, 0.0, 0.15) * height  # outward lean over the height
        ph = rng.uniform(0, 2 * np.pi, 2)
        h = height * (1 + 0.15 * np.sin(ss / 23.0 + ph[0]) * np.sin(ss / 57.0 + ph[1]))
        h = h if rough > 0 else np.full_like(ss, height)
        z = _GROUND_Z + (h[:, None] - _GROUND_Z) * t[None, :]
        y_face = dist + lean * t[None, :] + rough * rng.uniform(0.0, 1.0, z.shape)  # >= dist
        y_back = np.full(ss.size, y_face.max() + 8.0)
        back = np.stack([np.stack([y_back, h], -1), np.stack([y_back, 0 * h + _GROUND_Z], -1)], 1)
        prof = np.concatenate([np.stack([y_face, z], -1), back], axis=1)
        ctx.sweep(ss, prof * [side, 1], "rock")


def _overbridge(ctx: Context, st: Stretch) -> None:
    rng = ctx.rng
    s_c, w = (st.start_m + st.end_m) / 2, st.end_m - st.start_m
    z_d = _param(st, "clearance_m", rng, 7.1, 7.6)
    z_top = z_d + _param(st, "deck_thickness_m", rng, 1.0, 1.5)
    b_ab = _param(st, "abutment_distance_m", rng, 5.0, 7.0)
    span = b_ab + 4.0
    ctx.box(s_c, (-w / 2, w / 2, -span, span, z_d, z_top), "concrete")
    for a0 in (-w / 2, w / 2 - 0.3):  # parapets
        ctx.box(s_c, (a0, a0 + 0.3, -span, span, z_top, z_top + 1.1), "concrete")
    for side in (1.0, -1.0):
        ctx.box(s_c, (-w / 2 - 1, w / 2 + 1, side * b_ab, side * (b_ab + 2), _GROUND_Z, z_d),
                "concrete")  # fmt: skip
        # road embankment falling away from the bridge
        near, far = side * (b_ab + 1.0), side * (b_ab + 1.0 + rng.uniform(40.0, 80.0))
        hw, g = w / 2 + 1.5 * (z_top - _GROUND_Z), _GROUND_Z
        corners = np.array([[-hw, near, g], [-w / 2 - 1, far, g], [w / 2 + 1, far, g],
                            [hw, near, g], [-w / 2, near, z_top], [-w / 2, far, g + 0.3],
                            [w / 2, far, g + 0.3], [w / 2, near, z_top]])  # fmt: skip
        ctx.solid(s_c, corners, _outward(corners, _BOX_FACES), "grass")


def _arch(half_width: float, spring: float, n_arc: int) -> NDArray:
    """Horseshoe outline from the right foot over the crown to the left foot, (2 + n_arc, 2)."""
    ang = np.linspace(0.0, np.pi, n_arc)
    arc = np.stack([-half_width * np.cos(ang), spring + half_width * np.sin(ang)], -1)
    return np.concatenate([[[-half_width, _GROUND_Z]], arc, [[half_width, _GROUND_Z]]])


def _tunnel(ctx: Context, st: Stretch) -> None:
    s0, s1 = st.start_m, st.end_m
    ss = np.linspace(s0, s1, max(2, int((s1 - s0) / 4) + 1))
    half, spring, lining = 4.2, 3.5, 0.6
    outer = _arch(half + lining, spring, 17)
    ctx.sweep(ss, np.concatenate([outer, _arch(half, spring, 17)[::-1]]), "concrete", "strip")
    # the hill: an earth dome over the lining, low and narrow at the portals (portal faces
    # are its end caps, in concrete)
    grow = _taper(ss, s0, s1, 40.0)
    top = spring + half + lining + 3.0 + _param(st, "cover_m", ctx.rng, 12.0, 30.0) * grow
    u = np.linspace(-1.0, 1.0, outer.shape[0])
    dome_y = u[None, :] * (18.0 + 60.0 * grow)[:, None]
    dome_z = _GROUND_Z + (top[:, None] - _GROUND_Z) * np.cos(u * np.pi / 2)[None, :] ** 0.7
    dome = np.stack([dome_y, dome_z], -1)  # right to left, like the arch outline
    prof = np.concatenate([dome, np.broadcast_to(outer[::-1], dome.shape)], axis=1)
    v, f, cap = extrude(ctx.corridor, ss, prof, cap="strip")
    ctx.mb.add(v, f, np.where(cap, ctx.mat["concrete"], ctx.mat["grass"]))


def _glass_street(ctx: Context, st: Stretch) -> None:
    """Office blocks with glass curtain walls (share ``glass_share``) and white facades with
    rows of windows, flat roofs, closer and taller than a town's houses."""
    rng = ctx.rng
    for side in _sides(st):
        setback = _param(st, "facade_distance_m", rng, 6.0, 14.0)
        glass_share = float(st.params.get("glass_share", 0.6))
        s = st.start_m + rng.uniform(0, 3)
        while s < st.end_m - 10:
            length = min(float(rng.uniform(15.0, 45.0)), st.end_m - s)
            height = _param(st, "facade_height_m", rng, 12.0, 40.0)
            y_near = float(np.clip(setback + rng.uniform(-1.5, 1.5), 5.0, 25.0))
            wall = "glass" if rng.uniform() < glass_share else "white_facade"
            size = (length, float(rng.uniform(12, 25)), height)
            _building(ctx, s + length / 2, side, y_near, size, wall, None)
            s += length + (rng.uniform(4.0, 12.0) if rng.uniform() < 0.4 else 0.5)


def _white_street(ctx: Context, st: Stretch) -> None:
    """A street of pale rendered houses with rows of windows (the facade of an overcast sky's
    colour), gable roofs on half of them, some plastered ones between."""
    rng = ctx.rng
    for side in _sides(st):
        setback = _param(st, "facade_distance_m", rng, 5.0, 14.0)
        s = st.start_m + rng.uniform(0, 4)
        while s < st.end_m - 6:
            length = min(float(rng.uniform(8.0, 30.0)), st.end_m - s)
            height = _param(st, "facade_height_m", rng, 6.0, 22.0)
            y_near = float(np.clip(setback + rng.uniform(-1.0, 1.0), 5.0, 20.0))
            wall = "white_facade" if rng.uniform() < 0.8 else "plaster"
            roof = "roof_tiles" if rng.uniform() < 0.5 else None
            size = (length, float(rng.uniform(10, 18)), height)
            _building(ctx, s + length / 2, side, y_near, size, wall, roof)
            s += length + (rng.uniform(0.0, 1.0) if rng.uniform() < 0.8 else 8.0)


def _water(ctx: Context, st: Stretch) -> None:
    """A river or canal beside the track (from ``bank_distance_m``, ``width_m`` wide), its
    surface 0.3 m above the ground, a concrete quay at the near bank, houses and trees on the
    far bank to be mirrored."""
    rng = ctx.rng
    ss = np.linspace(st.start_m, st.end_m, max(2, int((st.end_m - st.start_m) / 5) + 1))
    for side in _sides(st):
        y0 = _param(st, "bank_distance_m", rng, 6.0, 12.0)
        width = _param(st, "width_m", rng, 25.0, 70.0)
        y1 = y0 + width
        g = _GROUND_Z
        ctx.sweep(ss, np.array([[y0, g], [y1, g], [y1, g + 0.3], [y0, g + 0.3]]) * [side, 1],
                  "water")  # fmt: skip
        ctx.sweep(ss, np.array([[y0 - 0.6, g], [y0, g], [y0, g + 0.4], [y0 - 0.6, g + 0.4]])
                  * [side, 1], "concrete")  # fmt: skip
        s = st.start_m + rng.uniform(0, 10)
        while s < st.end_m - 10:
            if rng.uniform() < 0.5:
                length = min(float(rng.uniform(10.0, 25.0)), st.end_m - s)
                wall = ("white_facade", "plaster", "brick")[int(rng.integers(0, 3))]
                size = (length, float(rng.uniform(8, 14)), float(rng.uniform(6.0, 15.0)))
                _building(ctx, s + length / 2, side, y1 + rng.uniform(3.0, 8.0), size, wall,
                          "roof_tiles" if rng.uniform() < 0.6 else None)  # fmt: skip
                s += length + rng.uniform(2.0, 8.0)
            else:
                _tree(ctx, s, side * (y1 + rng.uniform(2.0, 6.0)), float(rng.uniform(8, 16)))
                s += rng.uniform(6.0, 12.0)


_LEG_M, _BRACE_M, _CONDUCTOR_M = 0.18, 0.07, 0.03  # built widths (materials' width_m >= them)


def _pylon_members(
    height: float, base_half: float, top_half: float, arm: float
) -> tuple[list[tuple[NDArray, float, str]], NDArray]:
    """Members of a lattice tower in its local axes ``(a, b, c)`` (c up, arms along b): a list
    of ``(points (k, 3), width_m, material)`` polylines, and the arm tips (m, 3)."""
    waist = 0.72 * height
    levels = np.concatenate([np.linspace(_GROUND_Z, waist, 9), np.linspace(waist, height, 4)[1:]])
    half = np.interp(levels, [_GROUND_Z, waist, height], [base_half, top_half, top_half])
    corners = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], float)
    legs = [half[:, None] * corners[i][None, :] for i in range(4)]  # (levels, 2) each
    out: list[tuple[NDArray, float, str]] = []
    for i in range(4):
        out.append((np.column_stack([legs[i], levels]), _LEG_M, "lattice_leg"))
    for k in range(len(levels) - 1):
        for i in range(4):
            j = (i + 1) % 4
            a0 = np.append(legs[i][k], levels[k])
            b0 = np.append(legs[j][k], levels[k])
            a1 = np.append(legs[i][k + 1], levels[k + 1])
            b1 = np.append(legs[j][k + 1], levels[k + 1])
            out += [(np.stack([a0, b1]), _BRACE_M, "lattice"),
                    (np.stack([b0, a1]), _BRACE_M, "lattice"),
                    (np.stack([a0, b0]), _BRACE_M, "lattice")]  # fmt: skip
    tips = []
    for z_arm, reach in ((waist, arm), (0.5 * (waist + height), 0.75 * arm)):
        for sgn in (1.0, -1.0):
            root = [(-top_half, sgn * top_half), (top_half, sgn * top_half)]
            tip = np.array([0.0, sgn * (top_half + reach), z_arm])
            for a, b in root:
                lo = np.array([a, b, z_arm])
                hi = np.array([a, b, z_arm + 1.5])
                out += [(np.stack([lo, tip]), _BRACE_M, "lattice"),
                        (np.stack([hi, tip]), _BRACE_M, "lattice")]  # fmt: skip
            tips.append(tip - [0.0, 0.0, 2.0])  # insulator strings hang 2 m
    out.append((np.array([[0.0, 0.0, height], [0.0, 0.0, height + 2.0]]), _BRACE_M, "lattice"))
    return out, np.array(tips)


def _pylons(ctx: Context, st: Stretch) -> None:
    """A high-voltage line along the track: steel lattice towers (legs, cross bracing, arms
    across the line) every ``span_m`` at ``pylon_distance_m``, three conductors per arm pair
    sagging between towers."""
    rng = ctx.rng
    for side in _sides(st):
        dist = _param(st, "pylon_distance_m", rng, 12.0, 35.0)
        span = _param(st, "span_m", rng, 180.0, 300.0)
        height = _param(st, "pylon_height_m", rng, 25.0, 40.0)
        arm = float(rng.uniform(5.0, 8.0))
        towers = np.arange(st.start_m + rng.uniform(0.0, 0.5 * span), st.end_m, span)
        members, tips = _pylon_members(height, float(rng.uniform(2.5, 3.5)), 0.8, arm)
        placed_tips = []
        for s_c in towers:
            for pts, width, mat in members:
                local = pts + np.array([0.0, side * dist, 0.0])
                v, f = _polyline_beams(ctx.corridor.place_local(float(s_c), local), width)
                ctx.mb.add(v, f, ctx.mat[mat])
            shifted = tips + np.array([0.0, side * dist, 0.0])
            placed_tips.append(ctx.corridor.place_local(float(s_c), shifted))
        _, _, _, up = ctx.corridor.basis(towers)
        for k in range(len(placed_tips) - 1):
            t = np.linspace(0.0, 1.0, 31)[:, None]
            sag = (0.04 * span * 4 * t * (1 - t)) * up[k][None, :]
            for a, b in zip(placed_tips[k], placed_tips[k + 1], strict=True):
                v, f = _polyline_beams(a + t * (b - a) - sag, _CONDUCTOR_M)
                ctx.mb.add(v, f, ctx.mat["conductor"])


def _gantry(ctx: Context, st: Stretch) -> None:
    """A signal gantry over the track: two steel posts, a box girder across, signal heads
    hanging from it over the track and a handrail of thin tubes on its walkway."""
    rng = ctx.rng
    s_c = (st.start_m + st.end_m) / 2
    y_post = _param(st, "post_distance_m", rng, 4.0, 6.0)
    z0 = _param(st, "girder_height_m", rng, 7.6, 8.4)
    z1 = z0 + 0.8
    depth = min(1.2, st.end_m - st.start_m)
    for sgn in (1.0, -1.0):
        ctx.box(s_c, (-0.2, 0.2, sgn * y_post - 0.2, sgn * y_post + 0.2, _GROUND_Z, z1), "steel")
    ctx.box(s_c, (-depth / 2, depth / 2, -y_post - 0.3, y_post + 0.3, z0, z1), "steel")
    for y in rng.uniform(-1.5, 1.5, int(rng.integers(1, 4))):
        ctx.box(s_c, (-0.15, 0.15, y - 0.25, y + 0.25, z0 - 1.3, z0), "steel")
    for a in (-depth / 2, depth / 2):  # handrail: a top rail and posts every 1.5 m
        rail = ctx.corridor.place_local(s_c, [[a, -y_post, z1 + 1.0], [a, y_post, z1 + 1.0]])
        v, f = _polyline_beams(rail, 0.05)
        ctx.mb.add(v, f, ctx.mat["lattice"])
        for y in np.arange(-y_post, y_post + 1e-9, 1.5):
            post = ctx.corridor.place_local(s_c, [[a, y, z1], [a, y, z1 + 1.0]])
            v, f = _polyline_beams(post, 0.05)
            ctx.mb.add(v, f, ctx.mat["lattice"])


_BUILDERS = {
    "open": _open,
    "station": _station,
    "town": _town,
    "trees": _trees,
    "cutting": _cutting,
    "rock_walls": _rock_walls,
    "overbridge": _overbridge,
    "tunnel": _tunnel,
    "glass_street": _glass_street,
    "white_street": _white_street,
    "water": _water,
    "pylons": _pylons,
    "gantry": _gantry,
}


def build_stretch(ctx: Context, stretch: Stretch) -> None:
    """Add the scenery of one :class:`~predisat.synth.world.Stretch`."""
    _BUILDERS[stretch.kind](ctx, stretch)


def build_catenary(
    ctx: Context, start_m: float, end_m: float, no_mast_m: Sequence[tuple[float, float]] = ()
) -> None:
    """Masts, cantilevers, contact and messenger wires of a 3 kV DC single-track line.

    Masts (H-beams, L-band blocking) stand every ~60 m at 2.5-3.5 m on one side, except in the
    chainage intervals ``no_mast_m`` (tunnels, bridges); wires and cantilever tubes are thin.
    """
    rng = ctx.rng
    side = 1.0 if rng.uniform() < 0.5 else -1.0
    yc, mast_h = side * float(rng.uniform(2.5, 3.5)), float(rng.uniform(7.0, 8.0))
    z_cw, z_mw = 5.5, float(rng.uniform(6.5, 6.9))
    masts = [start_m + rng.uniform(0, 30)]
    while masts[-1] < end_m:
        masts.append(masts[-1] + rng.uniform(55.0, 65.0))
    m_s = np.array(masts)
    stagger = 0.2 * (-1.0) ** np.arange(m_s.size)
    for k, s_c in enumerate(m_s):
        if any(a - 8 <= s_c <= b + 8 for a, b in no_mast_m) or not start_m <= s_c <= end_m:
            continue
        h_beam = (
            (-0.14, 0.14, -0.14, -0.12),
            (-0.14, 0.14, 0.12, 0.14),
            (-0.01, 0.01, -0.14, 0.14),
        )
        for a0, a1, b0, b1 in h_beam:  # two flanges and a web
            ctx.box(s_c, (a0, a1, yc + b0, yc + b1, _GROUND_Z, mast_h), "steel")
        arm = [[0.0, yc, z_mw + 0.1], [0.0, -side * 0.4, z_mw + 0.1]]
        strut = [[0.0, yc, z_cw - 0.3], [0.0, stagger[k], z_cw + 0.05]]
        for line in (arm, strut):
            v, f = _polyline_beams(ctx.corridor.place_local(float(s_c), line), 0.06)
            ctx.mb.add(v, f, ctx.mat["cantilever"])
    ss = np.arange(start_m, end_m + 6.0, 6.0)
    y = np.interp(ss, m_s, stagger)
    span_pos = np.interp(ss, m_s, np.arange(m_s.size)) % 1.0
    sag = 0.4 * 4 * span_pos * (1 - span_pos)
    for zz, width in ((np.full(ss.size, z_cw), 0.012), (z_mw - sag, 0.015)):
        v, f = _polyline_beams(ctx.corridor.place(ss, y, zz), width)
        ctx.mb.add(v, f, ctx.mat["wire"])
