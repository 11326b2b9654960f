"""The synthetic corridor world: a seeded procedural 3-D scene built along a track map.

A :class:`WorldSpec` is a recipe: a sequence of :class:`Stretch` es (open country, stations,
towns, tree rows, cuttings, rock walls, overbridges, tunnels; and the out-of-distribution kinds
:data:`OOD_KINDS`: glass and white-facade streets, water, lattice pylons, signal gantries),
catenary on or off, distant hills on or off, wet or dry. :meth:`World.build` turns it into one
triangle mesh in the track's local ENU frame, with a :class:`~predisat.synth.materials.Material`
per face. The same track, recipe and seed
always give the same mesh.

L-band policy: a structure blocks GNSS signals (``blocks_lband=True``) unless it is much thinner
than the L1 wavelength (19 cm) and its first Fresnel zone (about 1.5 m across at 10 m), such as
contact and messenger wires and cantilever tubes (``thin=True``): those are visible to a camera
but do not block or reflect a signal significantly. Masts, buildings, canopies, trees (foliage
attenuates L-band by 10-20 dB), rock, earth, bridges and tunnels block. See
``docs/synthetic-world.md``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeAlias, TypedDict, Unpack

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from predisat.geodesy import LocalFrame
from predisat.jsontypes import JsonDict
from predisat.readonly import freeze_array_fields
from predisat.synth.materials import MATERIAL_IDS, MATERIALS
from predisat.synth.scenery import Context, Corridor, MeshBuilder, build_catenary, build_stretch
from predisat.track import TrackMap

__all__ = [
    "MIXED_KINDS",
    "OOD_KINDS",
    "STRETCH_KINDS",
    "Stretch",
    "StretchTuple",
    "World",
    "WorldOptions",
    "WorldSpec",
]

WORLD_FORMAT = "predisat.synth.world/1"


MIXED_KINDS = (
    "open",
    "station",
    "town",
    "trees",
    "cutting",
    "rock_walls",
    "overbridge",
    "tunnel",
)
"""The kinds :meth:`WorldSpec.mixed` draws (the worlds the segmenter and margin were fitted on)."""
OOD_KINDS = (
    "glass_street",
    "white_street",
    "water",
    "pylons",
    "gantry",
)
"""Kinds with the segmenter's out-of-distribution failures (issue 30): glass curtain walls and
white facades with rows of windows, water beside the track, lattice pylons of a power line,
signal gantries. Only recipes ask for them; :meth:`WorldSpec.mixed` never draws them."""
STRETCH_KINDS = MIXED_KINDS + OOD_KINDS
_SPANNING = ("overbridge", "tunnel", "gantry")  # always cross the whole corridor
_WET = {"platform": "wet_platform", "ballast": "wet_ballast"}  # WorldSpec.wet


@dataclass(frozen=True)
class Stretch:
    """A chainage interval of one kind of scenery.

    Attributes
    ----------
    kind : str
        One of :data:`STRETCH_KINDS`.
    start_m, end_m : float
        Chainage interval, metres, ``0 <= start_m < end_m``. For an overbridge the interval is
        the deck's width along the track (8-15 m is realistic).
    side : {"both", "left", "right"}
        Which side(s) of the track carry the scenery; overbridges and tunnels span both.
    params : mapping of str to float
        Optional fixed values instead of random draws (e.g. ``{"height_m": 30,
        "distance_m": 8, "roughness_m": 0}`` for rock walls); see ``docs/synthetic-world.md``.
    """

    kind: str
    start_m: float
    end_m: float
    side: str = "both"
    params: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in STRETCH_KINDS:
            raise ValueError(f"stretch kind {self.kind!r} is unknown; use one of {STRETCH_KINDS}")
        if self.side not in ("both", "left", "right"):
            raise ValueError(f"stretch side {self.side!r} must be 'both', 'left' or 'right'")
        if self.kind in _SPANNING and self.side != "both":
            raise ValueError(f"a {self.kind} spans the track: give side='both', not {self.side!r}")
        if not 0.0 <= self.start_m < self.end_m:
            raise ValueError(
                f"{self.kind} stretch [{self.start_m}, {self.end_m}] m: need "
                "0 <= start_m < end_m (chainages in metres along the track)"
            )
        object.__setattr__(self, "start_m", float(self.start_m))
        object.__setattr__(self, "end_m", float(self.end_m))
        object.__setattr__(self, "params", {k: float(v) for k, v in dict(self.params).items()})

    def to_dict(self) -> JsonDict:
        """Plain dict (YAML/JSON-ready)."""
        out: JsonDict = {"kind": self.kind, "start_m": self.start_m, "end_m": self.end_m}
        out["side"] = self.side
        if self.params:
            out["params"] = dict(self.params)
        return out

    @classmethod
    def from_dict(cls, d: JsonDict) -> Stretch:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        extra = set(d) - {"kind", "start_m", "end_m", "side", "params"}
        if extra:
            raise ValueError(f"stretch {dict(d)!r} has unknown keys {sorted(extra)}")
        return cls(d["kind"], d["start_m"], d["end_m"], d.get("side", "both"), d.get("params", {}))


StretchTuple: TypeAlias = tuple[str, float, float] | tuple[str, float, float, str]
"""A stretch written as ``(kind, start_m, end_m[, side])``."""


class WorldOptions(TypedDict, total=False):
    """The optional fields of :class:`WorldSpec` besides the stretches (keyword arguments)."""

    catenary: bool
    hills: bool
    hill_height_m: float
    terrain_margin_m: float
    dem_files: tuple[str, ...]
    wet: bool


_MIXED_LENGTHS_M = {
    "open": (120.0, 300.0),
    "station": (200.0, 300.0),
    "town": (200.0, 400.0),
    "trees": (120.0, 250.0),
    "cutting": (150.0, 300.0),
    "rock_walls": (150.0, 300.0),
    "tunnel": (150.0, 300.0),
}


@dataclass(frozen=True)
class WorldSpec:
    """Recipe of a synthetic world.

    Attributes
    ----------
    stretches : tuple of Stretch
        May overlap (e.g. an overbridge inside a town); geometry is simply combined.
    catenary : bool
        Masts, cantilevers and wires over the whole extent (line 144 is electrified).
    hills : bool
        Gentle distant terrain giving a horizon of a few degrees; False for flat ground.
    hill_height_m : float
        Typical height of the distant hills above the track.
    terrain_margin_m : float
        How far the ground extends beyond the track, metres.
    dem_files : tuple of str
        Terrain mode: elevation tiles (SRTM ``.hgt`` or GeoTIFF, :class:`predisat.terrain.Dem`)
        that replace the hills beyond 400 m of the track (blended from 150 m), shifted so that
        the DEM meets the track's heights (the median difference along it: the geoid, or a
        track file without heights). The tiles must cover the track; give a
        ``terrain_margin_m`` of several km so that the far terrain is in the world.
    wet : bool
        After rain: platforms and ballast are wet (they mirror the sky and the scenery,
        rippled). The geometry and the ground truth are those of the dry world.
    """

    stretches: tuple[Stretch, ...]
    catenary: bool = True
    hills: bool = True
    hill_height_m: float = 70.0
    terrain_margin_m: float = 1500.0
    dem_files: tuple[str, ...] = ()
    wet: bool = False

    def __post_init__(self) -> None:
        if not self.stretches:
            raise ValueError(
                "a WorldSpec needs at least one stretch (e.g. Stretch('open', 0, 500))"
            )
        object.__setattr__(self, "stretches", tuple(self.stretches))
        object.__setattr__(self, "dem_files", tuple(str(f) for f in self.dem_files))

    @property
    def extent_m(self) -> tuple[float, float]:
        """Chainage interval covered by the stretches."""
        return min(s.start_m for s in self.stretches), max(s.end_m for s in self.stretches)

    @property
    def kinds(self) -> set[str]:
        """The stretch kinds the recipe uses."""
        return {s.kind for s in self.stretches}

    @classmethod
    def from_stretches(
        cls, items: Iterable[Stretch | JsonDict | StretchTuple], **kw: Unpack[WorldOptions]
    ) -> WorldSpec:
        """Spec from :class:`Stretch` es, dicts or ``(kind, start_m, end_m[, side])`` tuples."""
        out = []
        for it in items:
            if isinstance(it, Stretch):
                out.append(it)
            elif isinstance(it, Mapping):
                out.append(Stretch.from_dict(it))
            else:
                out.append(Stretch(*it))
        return cls(tuple(out), **kw)

    def to_dict(self) -> JsonDict:
        """Plain dict (YAML/JSON-ready); :meth:`from_dict` reads it back."""
        return {
            "stretches": [s.to_dict() for s in self.stretches],
            "catenary": self.catenary,
            "hills": self.hills,
            "hill_height_m": self.hill_height_m,
            "terrain_margin_m": self.terrain_margin_m,
            **({"dem_files": list(self.dem_files)} if self.dem_files else {}),
            **({"wet": True} if self.wet else {}),
        }

    @classmethod
    def from_dict(cls, d: JsonDict) -> WorldSpec:
        """Spec from a dict such as a YAML scenery recipe (see ``docs/synthetic-world.md``)."""
        if "stretches" not in d:
            raise ValueError("scenery recipe needs a 'stretches' list of {kind, start_m, end_m}")
        keys = ("catenary", "hills", "hill_height_m", "terrain_margin_m", "wet")
        kw = {k: d[k] for k in keys if k in d}
        if "dem_files" in d:
            files = d["dem_files"]
            if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
                raise ValueError("scenery recipe: 'dem_files' must be a list of tile paths")
            kw["dem_files"] = tuple(files)
        return cls.from_stretches(d["stretches"], **kw)

    @classmethod
    def mixed(
        cls, start_m: float, end_m: float, seed: int = 0, **kw: Unpack[WorldOptions]
    ) -> WorldSpec:
        """A varied run with every stretch kind (in a random order) over ``[start_m, end_m]``.

        Lengths are scaled to fill the interval; 2 km gives realistic sizes. A tunnel is never
        first or last, and one overbridge crosses an open or town stretch.
        """
        if end_m - start_m < 800.0:
            raise ValueError(
                f"mixed() needs at least 800 m to fit every kind, got {end_m - start_m}"
            )
        rng = np.random.default_rng([int(seed), 7])
        kinds = [k for k in _MIXED_LENGTHS_M if k != "tunnel"] + ["open"]  # MIXED_KINDS
        kinds = [kinds[i] for i in rng.permutation(len(kinds))]
        kinds.insert(int(rng.integers(1, len(kinds))), "tunnel")
        lengths = np.array([rng.uniform(*_MIXED_LENGTHS_M[k]) for k in kinds])
        edges = start_m + np.concatenate([[0.0], np.cumsum(lengths)]) * (
            (end_m - start_m) / lengths.sum()
        )
        out: list[Stretch] = []
        for k, a, b in zip(kinds, edges[:-1], edges[1:], strict=True):
            side = "both"
            if k in ("station", "trees", "cutting", "rock_walls", "town"):
                p_both = {"rock_walls": 0.6, "town": 0.8}.get(k, 0.4)
                side = "both" if rng.uniform() < p_both else ("left", "right")[rng.integers(0, 2)]
            out.append(Stretch(k, float(a), float(b), side))
        hosts = [s for s in out if s.kind in ("open", "town") and s.end_m - s.start_m > 60]
        host = hosts[int(rng.integers(0, len(hosts)))]
        width = rng.uniform(8.0, 15.0)
        centre = rng.uniform(host.start_m + 25, host.end_m - 25)
        out.append(Stretch("overbridge", centre - width / 2, centre + width / 2))
        return cls(tuple(out), **kw)

    def with_tunnels(self, tunnels_m: Sequence[tuple[float, float]]) -> WorldSpec:
        """This spec with tunnels at the given chainages, other stretches cut around them."""
        lo, hi = self.extent_m
        tun = [(max(a, lo), min(b, hi)) for a, b in tunnels_m if b > lo and a < hi]
        if not tun:
            return self
        out: list[Stretch] = []
        for st in self.stretches:
            if st.kind == "tunnel" or (st.kind == "overbridge" and _overlaps(st, tun)):
                continue
            pieces = [(st.start_m, st.end_m)]
            for a, b in tun:
                pieces = [q for p in pieces for q in ((p[0], min(p[1], a)), (max(p[0], b), p[1]))]
            out += [replace(st, start_m=a, end_m=b) for a, b in pieces if b - a >= 1.0]
        out += [Stretch("tunnel", a, b) for a, b in tun]
        return replace(self, stretches=tuple(sorted(out, key=lambda s: s.start_m)))


def _overlaps(st: Stretch, intervals: Sequence[tuple[float, float]]) -> bool:
    return any(st.start_m < b and st.end_m > a for a, b in intervals)


@dataclass(frozen=True, eq=False)
class World:
    """A built synthetic world: one triangle mesh in the track's local ENU frame.

    Attributes
    ----------
    track : TrackMap
    frame : LocalFrame
        ``track.frame``; vertices are ENU metres in it.
    spec : WorldSpec
    seed : int
    vertices_m : ndarray, shape (n, 3), float64
    faces : ndarray, shape (m, 3), int32
    face_material : ndarray, shape (m,), int16
        Index into :data:`predisat.synth.materials.MATERIALS`.
    """

    track: TrackMap
    frame: LocalFrame
    spec: WorldSpec
    seed: int
    vertices_m: NDArray
    faces: NDArray
    face_material: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @classmethod
    def build(cls, track: TrackMap, spec: WorldSpec, seed: int = 0) -> World:
        """Build the scene of ``spec`` along ``track`` (a TrackMap), deterministically.

        Tunnels tagged on the track (``track.tunnels_m``, e.g. from OpenStreetMap) are added to
        the recipe. Each stretch draws from its own generator seeded by ``(seed, stretch)``, so
        editing one stretch leaves the others unchanged.
        """
        spec = spec.with_tunnels(getattr(track, "tunnels_m", ()))
        lo, hi = spec.extent_m
        if hi > track.length_m + 1e-6:
            raise ValueError(
                f"the recipe reaches chainage {hi:.1f} m but the track is {track.length_m:.1f} m "
                "long; shorten the last stretch"
            )
        corridor = Corridor.from_track(track, lo - 100.0, hi + 100.0)
        mb = MeshBuilder()
        rng = np.random.default_rng([int(seed), 3])
        _add_terrain(mb, corridor, track.frame, spec, rng)
        ctx = Context(corridor, rng, MATERIAL_IDS, mb)
        ss = np.arange(corridor.s_m[0], corridor.s_m[-1] + 5.0, 5.0)
        bed = [[-3.0, -0.55], [3.0, -0.55], [1.7, -0.2], [-1.7, -0.2]]
        ctx.sweep(ss, bed, "ballast")
        for st in spec.stretches:
            ent = [int(seed), 1, STRETCH_KINDS.index(st.kind), round(st.start_m * 1e3)]
            build_stretch(replace(ctx, rng=np.random.default_rng(ent)), st)
        if spec.catenary:
            spans = [(s.start_m, s.end_m) for s in spec.stretches if s.kind in _SPANNING]
            build_catenary(replace(ctx, rng=np.random.default_rng([int(seed), 2])), lo, hi, spans)
        v, f, m = mb.result()
        if spec.wet:
            remap = np.arange(len(MATERIALS), dtype=np.int16)
            for dry, wet in _WET.items():
                remap[MATERIAL_IDS[dry]] = MATERIAL_IDS[wet]
            m = remap[m]
        return cls(track, track.frame, spec, int(seed), v, f, m)

    @property
    def extent_m(self) -> tuple[float, float]:
        """Chainage interval of the scenery."""
        return self.spec.extent_m

    @property
    def blocking_faces(self) -> NDArray:
        """Boolean (m,) mask of faces that block L-band signals."""
        return np.array([m.blocks_lband for m in MATERIALS])[self.face_material]

    def mesh(self) -> trimesh.Trimesh:
        """The scene as a ``trimesh.Trimesh`` (vertices in frame ENU, not merged)."""
        return trimesh.Trimesh(self.vertices_m, self.faces, process=False)

    def antenna_enu(self, chainage_m: ArrayLike, antenna_height_m: float = 4.0) -> NDArray:
        """Antenna positions ``antenna_height_m`` above the rail along the local vertical, in
        frame ENU, shape ``chainage_m.shape + (3,)``, metres."""
        s = np.asarray(chainage_m, float)
        lat, lon, _ = self.track.position_at(s)
        up = self.frame.rotation_from(lat, lon)[..., :, 2]
        return np.asarray(self.track.enu_at(s)) + antenna_height_m * up

    def save(self, path: str | Path) -> None:
        """Write the world (mesh, recipe, seed, track vertices) to a compressed ``.npz``."""
        tr = self.track
        meta = {
            "format": WORLD_FORMAT,
            "spec": self.spec.to_dict(),
            "seed": self.seed,
            "track_name": getattr(tr, "name", "track"),
            "track_tolerance_m": float(getattr(tr, "tolerance_m", 1.0)),
            "track_tunnels_m": [list(t) for t in getattr(tr, "tunnels_m", ())],
            "frame": [self.frame.lat_deg, self.frame.lon_deg, self.frame.h_m],
        }
        with open(path, "wb") as fh:
            np.savez_compressed(
                fh,
                meta=np.array(json.dumps(meta)),
                vertices_m=self.vertices_m,
                faces=self.faces,
                face_material=self.face_material,
                track_lat_deg=np.asarray(getattr(tr, "lat_deg", [])),
                track_lon_deg=np.asarray(getattr(tr, "lon_deg", [])),
                track_h_m=np.asarray(getattr(tr, "h_m", [])),
            )

    @classmethod
    def load(cls, path: str | Path, track: TrackMap | None = None) -> World:
        """Read a world written by :meth:`save`.

        Without ``track`` the track map is rebuilt from the stored vertices with
        ``TrackMap.from_latlon``; pass the original one to keep its metadata.
        """
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != WORLD_FORMAT:
                raise ValueError(
                    f"{path}: not a synthetic world file (format {meta.get('format')})"
                )
            arrays = {k: z[k] for k in z.files if k != "meta"}
        if track is None:
            if arrays["track_lat_deg"].size < 2:
                raise ValueError(f"{path}: the track was not stored; pass track= to World.load")
            track = TrackMap.from_latlon(
                arrays["track_lat_deg"], arrays["track_lon_deg"], arrays["track_h_m"],
                name=meta["track_name"], tolerance_m=meta["track_tolerance_m"],
                tunnels_m=[tuple(t) for t in meta["track_tunnels_m"]],
            )  # fmt: skip
        f = track.frame
        if not np.allclose([f.lat_deg, f.lon_deg, f.h_m], meta["frame"], rtol=0, atol=1e-9):
            raise ValueError(f"{path}: the given track's frame differs from the world's frame")
        return cls(
            track, f, WorldSpec.from_dict(meta["spec"]), int(meta["seed"]),
            arrays["vertices_m"], arrays["faces"], arrays["face_material"],
        )  # fmt: skip


def _axis_nodes(lo: float, hi: float, margin: float, step: float) -> NDArray:
    """1-D grid: ``step`` over ``[lo, hi]``, then widening by 25 % per cell out to ``margin``."""
    core = np.arange(lo, hi + step, step)
    out, d, x = [], step, 0.0
    while x < margin:
        d = min(d * 1.25, 250.0)
        x += d
        out.append(x)
    outer = np.array(out)
    return np.concatenate([core[0] - outer[::-1], core, core[-1] + outer])


def _add_terrain(
    mb: MeshBuilder,
    corridor: Corridor,
    frame: LocalFrame,
    spec: WorldSpec,
    rng: np.random.Generator,
) -> None:
    """Ground height field: flat 0.5 m below the rail near the track, rising to distant hills.

    Heights are ellipsoidal (each vertex goes through geodetic coordinates), so the ground
    follows the Earth's curvature away from the frame origin.
    """
    xy = corridor.point_m[:, :2]
    pad = 200.0
    xs = _axis_nodes(xy[:, 0].min() - pad, xy[:, 0].max() + pad, spec.terrain_margin_m, 20.0)
    ys = _axis_nodes(xy[:, 1].min() - pad, xy[:, 1].max() + pad, spec.terrain_margin_m, 20.0)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    lat, lon, _ = frame.to_geodetic(np.stack([gx, gy, np.zeros_like(gx)], -1))
    dist, idx = cKDTree(xy).query(np.stack([gx.ravel(), gy.ravel()], -1))
    h = corridor.h_m[idx].reshape(gx.shape) - 0.5
    if spec.dem_files:
        h = _dem_ground(h, lat, lon, dist.reshape(gx.shape), corridor, frame, spec.dem_files)
    elif spec.hills:
        ramp = np.clip((dist.reshape(gx.shape) - 150.0) / 1000.0, 0.0, 1.0)
        noise = np.zeros_like(gx)
        for _ in range(5):  # a few long random ripples
            wl, ang, ph = rng.uniform(300, 1500), rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)
            noise += np.cos(2 * np.pi * (gx * np.cos(ang) + gy * np.sin(ang)) / wl + ph)
        noise = (noise - noise.min()) / max(np.ptp(noise), 1e-9)
        h = h + spec.hill_height_m * ramp**2 * (3 - 2 * ramp) * (0.5 + 0.5 * noise)
    verts = frame.to_enu(lat, lon, h).reshape(-1, 3)
    nx, ny = gx.shape
    i = (np.arange(nx - 1)[:, None] * ny + np.arange(ny - 1)[None, :]).ravel()
    faces = np.concatenate(
        [np.stack([i, i + ny, i + ny + 1], -1), np.stack([i, i + ny + 1, i + 1], -1)]
    )
    far = dist[faces].max(1) > 300.0
    mb.add(verts, faces, np.where(far, MATERIAL_IDS["hills"], MATERIAL_IDS["grass"]))


def _dem_ground(
    near_h: NDArray,
    lat: NDArray,
    lon: NDArray,
    dist_m: NDArray,
    corridor: Corridor,
    frame: LocalFrame,
    dem_files: Sequence[str],
) -> NDArray:
    """The DEM's heights beyond 400 m of the track, the corridor's flat ground within 150 m,
    blended between (smoothstep); the DEM shifted onto the track's height datum."""
    from predisat.terrain import Dem

    dem = Dem.from_files(list(dem_files), vertical_error_m=0.0)
    t_lat, t_lon, _ = frame.to_geodetic(corridor.point_m)
    at_track = dem.height_at(t_lat, t_lon)
    if not np.isfinite(at_track).any():
        raise ValueError(f"the DEM ({dem.source}) does not cover the track: give tiles "
                         f"around {float(np.mean(t_lat)):.3f} N {float(np.mean(t_lon)):.3f} E")
    offset = float(np.nanmedian(corridor.h_m - at_track))
    far = dem.height_at(lat, lon) + offset
    w = np.clip((dist_m - 150.0) / 250.0, 0.0, 1.0)
    w = w * w * (3 - 2 * w)
    return np.where(np.isfinite(far), (1 - w) * near_h + w * far, near_h)
