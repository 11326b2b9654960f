"""Single-bounce specular reflections in a synthetic world, signal strength and code multipath.

The simulator (:mod:`locator.sim.simulate`) asks, for every antenna position and satellite, whether
a signal reflected once off an L-band-blocking surface (facade, rock wall, bridge abutment)
reaches the antenna. With the satellite at infinity (unit vector ``u`` from the antenna) and a
planar reflector of unit normal ``n``, the mirror law fixes the direction in which the antenna
sees the reflection point: ``r = u - 2 (u . n) n``. Casting a ray from the antenna ``A`` along
``r`` finds the reflection point ``P = A + t r``; the reflection is valid when the ray hits a
face whose normal is within ``specular_tolerance_deg`` of ``n`` and the leg from ``P`` to the
satellite is free. The reflected path exceeds the direct one by::

    extra = t + |S - P| - |S - A|  ->  t (1 - u . r) = 2 h (u . n)   (satellite at infinity)

with ``h = t (u . n)`` the distance from the antenna to the reflector's plane: twice the
distance to the plane times the sine of the grazing angle (the image method). The simulator
uses the exact first form with the satellite's true position.

Candidate normals ``n`` come from the blocking faces near each antenna position: faces within
``max_distance_m`` are grouped by orientation (``normal_bin_deg`` bins) and a group counts when
its area reaches ``min_area_m2`` (a first Fresnel zone is a few square metres at 10-30 m). Its
area-weighted mean normal is the candidate; a planar wall gives its exact normal, a rough rock
face its mean plane. Reflections arriving from below the antenna's horizon are dropped: the
train roof shades the antenna from the ground.

Signal strength (:class:`SignalModel`): ``C/N0(el) = horizon + (zenith - horizon) sin(el)`` for
a direct signal; a reflected one has the C/N0 of its arrival elevation minus a reflection loss
(material Fresnel loss plus the antenna's rejection of the left-hand polarisation a single
bounce produces). A signal is tracked when its C/N0 reaches ``threshold_dbhz``.

Code multipath of a direct signal with one reflection (:func:`dll_error_m`): the tracking error
of a coherent early-minus-late delay-lock loop with an ideal BPSK correlation triangle, the
classical multipath error envelope sampled at the reflection's carrier phase.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from predisat.readonly import freeze_array_fields
from predisat.synth.materials import MATERIALS, material_id
from predisat.synth.raycast import Caster, make_caster

if TYPE_CHECKING:
    from predisat.synth.world import World

__all__ = [
    "REFLECTING_MATERIALS",
    "SIGNALS",
    "Reflections",
    "ReflectorIndex",
    "ReflectorSearch",
    "SignalModel",
    "dll_error_m",
    "find_reflections",
]

SIGNALS: dict[str, tuple[float, float]] = {
    "G": (293.052, 0.190294),  # GPS L1 C/A: 1.023 Mchip/s, 1575.42 MHz
    "E": (293.052, 0.190294),  # Galileo E1 (BOC(1,1) treated as BPSK(1))
    "J": (293.052, 0.190294),  # QZSS L1 C/A
    "S": (293.052, 0.190294),  # SBAS L1
    "I": (293.052, 0.254828),  # NavIC L5 SPS
    "R": (586.104, 0.187136),  # GLONASS L1OF: 0.511 Mchip/s, 1602 MHz (channel 0)
    "C": (146.526, 0.192039),  # BeiDou B1I: 2.046 Mchip/s, 1561.098 MHz
}
"""Chip length and carrier wavelength (metres) of the simulated signal of each system."""

REFLECTING_MATERIALS = (
    "platform", "brick", "plaster", "roof_tiles", "canopy", "steel", "rock", "concrete",
    "glass", "white_facade", "water",
)  # fmt: skip
"""Materials that reflect L-band specularly (building faces, metal, rock, glass and still
water); foliage, bark and the ground scatter or absorb."""


@dataclass(frozen=True)
class SignalModel:
    """Carrier-to-noise density of direct and reflected signals, tracking and the correlator.

    Attributes
    ----------
    cn0_zenith_dbhz, cn0_horizon_dbhz : float
        C/N0 of a direct signal at 90 and 0 deg elevation (linear in ``sin(el)`` between).
    reflection_loss_db : float
        Loss of one reflection: Fresnel loss of concrete or rock plus the antenna's rejection
        of the left-hand circular polarisation a single bounce produces.
    threshold_dbhz : float
        Lowest C/N0 the receiver tracks; weaker signals are lost.
    min_arrival_el_deg : float
        Reflections arriving from below this elevation are not received (train roof).
    correlator_spacing_chip : float
        Early-late spacing of the delay-lock loop, chips (0.1: narrow correlator).
    reflection_phase_rad : float
        Carrier phase shift at the reflection (pi for a good conductor or a dielectric at
        grazing incidence).
    """

    cn0_zenith_dbhz: float = 48.0
    cn0_horizon_dbhz: float = 34.0
    reflection_loss_db: float = 8.0
    threshold_dbhz: float = 28.0
    min_arrival_el_deg: float = 0.0
    correlator_spacing_chip: float = 0.1
    reflection_phase_rad: float = float(np.pi)

    def __post_init__(self) -> None:
        if self.reflection_loss_db < 0:
            raise ValueError(f"reflection_loss_db must be >= 0, got {self.reflection_loss_db}")
        if not 0 < self.correlator_spacing_chip <= 1:
            raise ValueError(
                f"correlator_spacing_chip must be in (0, 1], got {self.correlator_spacing_chip}"
            )

    def cn0_direct_dbhz(self, el_deg: ArrayLike) -> NDArray:
        """C/N0 of a direct signal arriving from elevation ``el_deg`` (clipped to [0, 90])."""
        s = np.sin(np.radians(np.clip(np.asarray(el_deg, float), 0.0, 90.0)))
        return self.cn0_horizon_dbhz + (self.cn0_zenith_dbhz - self.cn0_horizon_dbhz) * s

    def cn0_reflected_dbhz(self, arrival_el_deg: ArrayLike) -> NDArray:
        """C/N0 of a singly reflected signal arriving from ``arrival_el_deg``."""
        return self.cn0_direct_dbhz(arrival_el_deg) - self.reflection_loss_db


@dataclass(frozen=True)
class ReflectorSearch:
    """Parameters of the reflector search of :func:`find_reflections`.

    Attributes
    ----------
    max_distance_m : float
        Reflectors farther than this from the antenna are ignored.
    normal_bin_deg : float
        Orientation bin width when grouping nearby faces into candidate planes.
    min_area_m2 : float
        Least total area of a group of faces to count as a reflector.
    specular_tolerance_deg : float
        Largest angle between the hit face's normal and the candidate plane's normal for a
        specular reflection (facets of a rough surface smaller than the Fresnel zone).
    materials : tuple of str
        Names of the :data:`~predisat.synth.world.MATERIALS` that reflect (a ray meeting any
        other blocking surface first is absorbed or scattered).
    """

    max_distance_m: float = 100.0
    normal_bin_deg: float = 5.0
    min_area_m2: float = 4.0
    specular_tolerance_deg: float = 10.0
    materials: tuple[str, ...] = REFLECTING_MATERIALS

    def __post_init__(self) -> None:
        if self.max_distance_m <= 0 or self.normal_bin_deg <= 0 or self.min_area_m2 < 0:
            raise ValueError(
                f"ReflectorSearch needs max_distance_m > 0, normal_bin_deg > 0 and "
                f"min_area_m2 >= 0: {self}"
            )
        if not 0 <= self.specular_tolerance_deg < 90:
            raise ValueError(
                f"specular_tolerance_deg must be in [0, 90), got {self.specular_tolerance_deg}"
            )
        object.__setattr__(self, "materials", tuple(self.materials))
        _material_ids(self.materials)  # raises, naming the known materials

    @property
    def reflects(self) -> NDArray:
        """Boolean lookup by material id: does the material reflect."""
        n_materials, ids = _material_ids(self.materials)
        out = np.zeros(n_materials, bool)
        out[ids] = True
        return out


def _material_ids(names: Sequence[str]) -> tuple[int, list[int]]:
    """Number of materials of the synthetic world and the ids of ``names`` (KeyError naming
    the known materials at the first unknown name)."""
    return len(MATERIALS), [material_id(m) for m in names]


@dataclass(frozen=True)
class Reflections:
    """The chosen single-bounce reflection of each (epoch, satellite), NaN / -1 where none.

    Among several valid reflections the strongest (highest arrival elevation, hence C/N0)
    is kept, then the shortest.

    Attributes
    ----------
    extra_m : ndarray, shape (n_epoch, n_sat)
        Reflected path minus direct path, metres (>= 0).
    face_id : ndarray of int64, shape (n_epoch, n_sat)
        Reflecting face (index into ``world.faces``).
    point_enu_m : ndarray, shape (n_epoch, n_sat, 3)
        Reflection point in the world's frame.
    arrival_el_deg : ndarray, shape (n_epoch, n_sat)
        Elevation from which the reflection reaches the antenna.
    """

    extra_m: NDArray
    face_id: NDArray
    point_enu_m: NDArray
    arrival_el_deg: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def found(self) -> NDArray:
        """Boolean (n_epoch, n_sat): a valid reflection exists."""
        return self.face_id >= 0


_BIG_FACE_M = 20.0  # faces larger than this (terrain cells) are tested without the k-d tree


class ReflectorIndex:
    """The L-band-blocking faces of a world, indexed for the per-position reflector search.

    Parameters
    ----------
    world : World
    caster : Caster, optional
        An L-band ray caster of ``world`` (``make_caster(world, lband_only=True)``); built
        with ``backend`` when not given.
    backend : {"open3d", "trimesh"}
    """

    def __init__(
        self, world: World, caster: Caster | None = None, backend: str = "open3d"
    ) -> None:
        self.caster = caster or make_caster(world, backend, lband_only=True)
        keep = np.flatnonzero(world.blocking_faces)
        tri = np.asarray(world.vertices_m, float)[np.asarray(world.faces)[keep]]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(cross, axis=-1)
        ok = norm > 1e-9
        keep, tri, cross, norm = keep[ok], tri[ok], cross[ok], norm[ok]
        self.face_id = keep
        self.face_material = np.asarray(world.face_material)
        self.material = self.face_material[keep]
        self.area_m2 = 0.5 * norm
        nrm = cross / norm[:, None]
        # a plane's normal up to sign: one canonical sign so both sides group together
        flip = (nrm[:, 2] < -1e-6) | (
            (np.abs(nrm[:, 2]) <= 1e-6) & ((nrm[:, 1] < -1e-9) | ((np.abs(nrm[:, 1]) <= 1e-9)
                                           & (nrm[:, 0] < 0)))
        )  # fmt: skip
        self.normal = np.where(flip[:, None], -nrm, nrm)
        self.centroid_m = tri.mean(axis=1)
        self.radius_m = np.linalg.norm(tri - self.centroid_m[:, None], axis=-1).max(axis=1)
        small = self.radius_m <= _BIG_FACE_M
        self._small = np.flatnonzero(small)
        self._big = np.flatnonzero(~small)
        self._tree = cKDTree(self.centroid_m[self._small])
        # all-face normal lookup by world face id, for the specular test of hit faces
        self._normal_of_world_face = np.zeros((len(world.faces), 3))
        self._normal_of_world_face[keep] = self.normal

    def near(self, point_m: NDArray, distance_m: float) -> NDArray:
        """Indices (into this index's arrays) of faces reaching within ``distance_m``."""
        near = np.asarray(
            self._tree.query_ball_point(point_m, distance_m + _BIG_FACE_M), dtype=np.intp
        )
        cand = np.concatenate([self._small[near], self._big])
        d = np.linalg.norm(self.centroid_m[cand] - point_m, axis=-1) - self.radius_m[cand]
        return cand[d <= distance_m]

    def candidate_normals(self, point_m: NDArray, search: ReflectorSearch) -> NDArray:
        """Candidate reflector plane normals near one point, shape (k, 3) (sign arbitrary)."""
        idx = self.near(np.asarray(point_m, float), search.max_distance_m)
        idx = idx[search.reflects[self.material[idx]]]
        if not len(idx):
            return np.zeros((0, 3))
        n = self.normal[idx]
        a = self.area_m2[idx]
        el = np.degrees(np.arcsin(np.clip(n[:, 2], -1.0, 1.0)))
        az = np.degrees(np.arctan2(n[:, 0], n[:, 1])) % 360.0
        step = search.normal_bin_deg
        i_el = np.floor(el / step).astype(np.int64)
        ring = np.maximum(np.cos(np.radians((i_el + 0.5) * step)), 1e-3)
        i_az = np.floor(az * ring / step).astype(np.int64)
        key = i_el * 1_000_000 + i_az
        uniq, inv = np.unique(key, return_inverse=True)
        area = np.bincount(inv, a, len(uniq))
        summed = np.stack([np.bincount(inv, a * n[:, k], len(uniq)) for k in range(3)], -1)
        good = area >= search.min_area_m2
        s = summed[good]
        return s / np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-300)

    def normal_of(self, face_id: NDArray) -> NDArray:
        """Unit normals (canonical sign) of world faces, shape ``face_id.shape + (3,)``."""
        return self._normal_of_world_face[np.asarray(face_id)]


def find_reflections(
    index: ReflectorIndex,
    antenna_enu_m: ArrayLike,
    sat_enu_m: ArrayLike,
    valid: ArrayLike | None = None,
    search: ReflectorSearch | None = None,
    min_arrival_el_deg: float = 0.0,
    chunk_rays: int = 400_000,
    block_epochs: int = 200,
) -> Reflections:
    """Single-bounce specular reflections from satellites to antennas.

    Parameters
    ----------
    index : ReflectorIndex
    antenna_enu_m : array_like, shape (n_epoch, 3)
        Antenna positions in the world's frame, metres.
    sat_enu_m : array_like, shape (n_epoch, n_sat, 3)
        Satellite positions (signal emission points) in the same frame, metres.
    valid : array_like of bool, shape (n_epoch, n_sat), optional
        Pairs to search (default: every finite satellite position).
    search : ReflectorSearch, optional
    min_arrival_el_deg : float
        Reflections arriving from lower elevations are dropped (train roof).
    chunk_rays, block_epochs : int
        Rays cast per call and epochs searched together, to bound memory.

    Returns
    -------
    Reflections
        Shape (n_epoch, n_sat).
    """
    search = search or ReflectorSearch()
    ant = np.asarray(antenna_enu_m, float)
    sat = np.asarray(sat_enu_m, float)
    if ant.ndim != 2 or ant.shape[-1] != 3 or sat.shape[:1] + sat.shape[2:] != (len(ant), 3):
        raise ValueError(
            f"antenna_enu_m must be (n_epoch, 3) and sat_enu_m (n_epoch, n_sat, 3), got "
            f"{ant.shape} and {sat.shape}"
        )
    ok = np.all(np.isfinite(sat), axis=-1)
    if valid is not None:
        ok &= np.asarray(valid, bool)
    sin_min = float(np.sin(np.radians(min_arrival_el_deg)))
    parts = [
        _search_block(index, ant[b : b + block_epochs], sat[b : b + block_epochs],
                      ok[b : b + block_epochs], search, sin_min, chunk_rays)
        for b in range(0, max(len(ant), 1), block_epochs)
    ]  # fmt: skip
    return Reflections(
        *(np.concatenate([getattr(p, f) for p in parts]) for f in Reflections.__dataclass_fields__)
    )


def _search_block(
    index: ReflectorIndex,
    ant: NDArray,
    sat: NDArray,
    ok: NDArray,
    search: ReflectorSearch,
    sin_min: float,
    chunk_rays: int,
) -> Reflections:
    n_ep, n_sat = sat.shape[:2]
    with np.errstate(invalid="ignore", divide="ignore"):
        u = (sat - ant[:, None]) / np.linalg.norm(sat - ant[:, None], axis=-1, keepdims=True)
    # filled here, then frozen into the record
    fill = (
        np.full((n_ep, n_sat), np.nan),
        np.full((n_ep, n_sat), -1, np.int64),
        np.full((n_ep, n_sat, 3), np.nan),
        np.full((n_ep, n_sat), np.nan),
    )
    out = Reflections(*fill)
    rays = _candidate_rays(index, ant, u, ok, search, sin_min)
    if rays is None:
        return out
    pair, d, n_or = rays
    a = ant[pair // n_sat]
    t, face = _cast_chunked(index.caster, a, d, chunk_rays)
    cos_tol = np.cos(np.radians(search.specular_tolerance_deg))
    hit = (face >= 0) & (t <= search.max_distance_m)
    hit &= search.reflects[index.face_material[np.maximum(face, 0)]]
    spec = np.abs(np.sum(index.normal_of(np.maximum(face, 0)) * n_or, -1)) >= cos_tol
    sel = np.flatnonzero(hit & spec)
    if not len(sel):
        return out
    pair, d, n_or, a, t, face = pair[sel], d[sel], n_or[sel], a[sel], t[sel], face[sel]
    p = a + t[:, None] * d
    s = sat.reshape(-1, 3)[pair]
    us = u.reshape(-1, 3)[pair]
    # the leg reflection point -> satellite, started just in front of the surface
    free = _unoccluded(index.caster, p + 0.02 * n_or, us, chunk_rays)
    if not free.any():
        return out
    pair, d, a, t, face = pair[free], d[free], a[free], t[free], face[free]
    p, s = p[free], s[free]
    _keep_best(fill, n_sat, pair, d, a, t, face, p, s)
    return Reflections(*fill)


def _candidate_rays(
    index: ReflectorIndex,
    ant: NDArray,
    u: NDArray,
    ok: NDArray,
    search: ReflectorSearch,
    sin_min: float,
) -> tuple[NDArray, NDArray, NDArray] | None:
    """Rays (flat pair index, direction, plane normal toward the satellite), None if none.

    One ray per (pair, candidate plane) with the satellite in front of the plane.
    """
    n_sat = u.shape[1]
    pair_l, dir_l, nrm_l = [], [], []
    # a train standing at a platform repeats its position for every epoch of the dwell
    planes: dict[bytes, NDArray] = {}
    for e in range(len(u)):
        js = np.flatnonzero(ok[e])
        if not len(js):
            continue
        key = ant[e].tobytes()
        if key not in planes:
            planes[key] = index.candidate_normals(ant[e], search)
        cand = planes[key]
        if not len(cand):
            continue
        ue = u[e, js]  # (m, 3)
        dot = ue @ cand.T  # (m, k)
        n_or = np.sign(dot)[..., None] * cand[None]  # oriented toward the satellite
        r = ue[:, None] - 2.0 * np.abs(dot)[..., None] * n_or
        keep = (np.abs(dot) > 1e-6) & (r[..., 2] >= sin_min)
        jj, kk = np.nonzero(keep)
        pair_l.append(e * n_sat + js[jj])
        dir_l.append(r[jj, kk])
        nrm_l.append(n_or[jj, kk])
    if not pair_l:
        return None
    return np.concatenate(pair_l), np.concatenate(dir_l), np.concatenate(nrm_l)


def _cast_chunked(
    caster: Caster, origin: NDArray, direction: NDArray, chunk_rays: int
) -> tuple[NDArray, NDArray]:
    """Distance (m) and face id of the first hit of each ray, ``chunk_rays`` rays per call."""
    t = np.empty(len(origin))
    face = np.empty(len(origin), np.int64)
    for lo in range(0, len(origin), chunk_rays):
        h = caster.cast(origin[lo : lo + chunk_rays], direction[lo : lo + chunk_rays])
        t[lo : lo + chunk_rays] = h.distance_m
        face[lo : lo + chunk_rays] = h.face_id
    return t, face


def _unoccluded(caster: Caster, start: NDArray, direction: NDArray, chunk_rays: int) -> NDArray:
    """Boolean per ray: nothing blocks it (``chunk_rays`` rays per call)."""
    free = np.empty(len(start), bool)
    for lo in range(0, len(start), chunk_rays):
        free[lo : lo + chunk_rays] = ~caster.occluded(
            start[lo : lo + chunk_rays], direction[lo : lo + chunk_rays]
        )
    return free


def _keep_best(
    out: tuple[NDArray, NDArray, NDArray, NDArray],
    n_sat: int,
    pair: NDArray,
    d: NDArray,
    a: NDArray,
    t: NDArray,
    face: NDArray,
    p: NDArray,
    s: NDArray,
) -> None:
    """Write the best reflection of each pair into ``out``, the arrays of a
    :class:`Reflections` in its field order."""
    # |S - P| - |S - A| without cancellation: ((A - P) . (2S - A - P)) / (|S - P| + |S - A|)
    dsp = np.linalg.norm(s - p, axis=-1)
    dsa = np.linalg.norm(s - a, axis=-1)
    extra = t + np.sum((a - p) * (2.0 * s - a - p), -1) / (dsp + dsa)
    arrival = np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0)))
    # best per pair: highest arrival elevation (strongest), then shortest extra path
    order = np.lexsort((extra, -np.round(arrival, 6), pair))
    first = order[np.r_[True, pair[order][1:] != pair[order][:-1]]]
    pe, ps = np.divmod(pair[first], n_sat)
    extra_m, face_id, point_enu_m, arrival_el_deg = out
    extra_m[pe, ps] = extra[first]
    face_id[pe, ps] = face[first]
    point_enu_m[pe, ps] = p[first]
    arrival_el_deg[pe, ps] = arrival[first]


def dll_error_m(
    delay_m: ArrayLike,
    amplitude: ArrayLike,
    phase_rad: ArrayLike,
    chip_m: ArrayLike,
    spacing_chip: float = 0.1,
) -> NDArray:
    """Code tracking error caused by one reflected replica of a direct signal.

    Coherent early-minus-late delay-lock loop, ideal (infinite bandwidth) BPSK correlation
    triangle, early-late spacing ``D`` chips. With ``a = amplitude * cos(phase)`` and the delay
    ``delta`` in chips, the discriminator's zero is (exact for the triangle)::

        delta <= (1 + a) D / 2            e = a delta / (1 + a)
        ... <= 1 - (1 - a) D / 2          e = a D / 2
        ... <  1 + D / 2                  e = a (1 + D / 2 - delta) / (2 - a)
        otherwise                         e = 0

    Parameters
    ----------
    delay_m : array_like
        Extra path of the reflection, metres (>= 0; NaN gives 0).
    amplitude : array_like
        Reflected over direct amplitude, in [0, 1).
    phase_rad : array_like
        Carrier phase of the reflection relative to the direct signal.
    chip_m : array_like
        Chip length of the code, metres.
    spacing_chip : float

    Returns
    -------
    ndarray
        Pseudorange error, metres, broadcast shape of the inputs.
    """
    delay, amp, phase, chip = np.broadcast_arrays(
        np.asarray(delay_m, float), np.asarray(amplitude, float),
        np.asarray(phase_rad, float), np.asarray(chip_m, float),
    )  # fmt: skip
    if np.any(amp >= 1) or np.any(amp < 0):
        raise ValueError("amplitude must be in [0, 1) (the direct signal is the stronger)")
    big_d = spacing_chip
    known = np.isfinite(delay)
    x = np.where(known, delay, 0.0) / chip
    a = np.where(known, amp * np.cos(phase), 0.0)
    e = np.where(
        x <= (1 + a) * big_d / 2,
        a * x / (1 + a),
        np.where(
            x <= 1 - (1 - a) * big_d / 2,
            a * big_d / 2,
            np.where(x < 1 + big_d / 2, a * (1 + big_d / 2 - x) / (2 - a), 0.0),
        ),
    )
    return np.where(known, e * chip, 0.0)
