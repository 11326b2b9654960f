"""Ground truth from a synthetic world: 360 deg elevation masks, obstacle descriptors, blockage.

* :func:`true_masks`: for antenna positions along the track (every 10 m by default), the highest
  L-band-blocking elevation in every azimuth bin, exact to well under 0.1 deg. Thin structures
  (wires, cantilever tubes) block where the first Fresnel zone rule says so at their distance
  from the antenna (:class:`FresnelCaster`, :mod:`predisat.gnss.fresnel`), the rule the
  reconstruction applies.
* :func:`obstacle_descriptors`: distance and height of the nearest blocking obstacle on each
  side of the track (the reflection-risk descriptors of a segment map).
* :func:`is_blocked`: whether given satellite directions are blocked (a direct ray cast).
* :func:`ideal_sky_mask`: a camera frame's sky mask without segmentation error (each pixel's
  centre ray cast against the L-band-blocking scene), to test reconstruction alone.

Elevations are relative to the ellipsoid normal at each antenna, azimuths clockwise from true
north; the method and its limits are in ``docs/synthetic-world.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from predisat.camera.models import CameraModel, Mount
from predisat.geodesy import azel_to_enu
from predisat.gnss.fresnel import L1_WAVELENGTH_M, TRANSPARENT_FRACTION, transparent
from predisat.masks.truth import TrueMasks
from predisat.synth.materials import MATERIALS
from predisat.synth.raycast import Caster, Hits, SceneMesh, make_caster
from predisat.synth.render import camera_pose
from predisat.synth.world import World

if TYPE_CHECKING:  # the type only: the reconstruction (numba) is imported where it is used
    from predisat.reconstruct.carving import FrameView

__all__ = [
    "FresnelCaster",
    "ideal_frames",
    "ideal_sky_mask",
    "is_blocked",
    "obstacle_descriptors",
    "scan_levels_deg",
    "true_masks",
]


def scan_levels_deg(rel_step: float = 0.1, min_step_deg: float = 0.05) -> NDArray:
    """Elevations (ascending, from 0 to below 90 deg) of the coarse scan before bisection.

    The step is ``rel_step`` times the elevation (at least ``min_step_deg``, at most 2 deg):
    a slab of thickness ``t`` whose top is ``dh`` above the antenna subtends about
    ``(t / dh) * el`` near elevation ``el``, so a relative step catches bridge decks and canopy
    roofs (``t / dh`` >= 0.25) at any distance.
    """
    out = [0.0]
    while True:
        nxt = out[-1] + min(max(min_step_deg, rel_step * out[-1]), 2.0)
        if nxt >= 90.0:
            return np.array(out)
        out.append(nxt)


_LEVELS = scan_levels_deg()


def _local_rotations(world: World, enu_m: NDArray) -> NDArray:
    """Rotations (..., 3, 3) from the local ENU at points (frame ENU) into the frame."""
    lat, lon, _ = world.frame.to_geodetic(enu_m)
    return world.frame.rotation_from(lat, lon)


@dataclass(frozen=True)
class _ThinScene:
    """A world seen through its thin faces only (a :class:`~predisat.synth.raycast.SceneMesh`
    whose "blocking" faces are the thin ones, for a caster of them alone)."""

    vertices_m: NDArray
    faces: NDArray
    face_material: NDArray
    blocking_faces: NDArray


_THIN = np.array([m.thin for m in MATERIALS])
_WIDTH_M = np.array([m.width_m for m in MATERIALS])
_MAX_THIN_HITS = 16  # thin faces crossed by one ray near the antenna (two per beam)
# a ray goes on this far past a transparent hit: float32 casters (Embree) can hit the same
# face again from a point 0.1 mm past it; the thinnest structure is 12 mm
_STEP_PAST_M = 0.005


class FresnelCaster:
    """L-band visibility with the physical thin-structure rule.

    A ray is blocked when it meets an L-band-blocking face (the wrapped caster), or a thin
    face (wire, cantilever tube) of a material whose ``width_m`` is not transparent at the hit's
    distance from the ray's origin (:func:`predisat.gnss.fresnel.transparent`: no wider than a
    tenth of the first Fresnel zone radius at ``wavelength_m``). Thin faces beyond
    :attr:`reach_m` are transparent whatever they are. ``cast`` is the wrapped caster's.

    Parameters
    ----------
    world : World
    lband : Caster
        ``make_caster(world, backend, lband_only=True)``.
    wavelength_m : float
        Default L1, the shortest (the safe side).
    """

    def __init__(
        self, world: SceneMesh, lband: Caster, wavelength_m: float = L1_WAVELENGTH_M
    ) -> None:
        self.lband = lband
        self.backend = lband.backend
        self.wavelength_m = float(wavelength_m)
        mat = np.asarray(world.face_material)
        thin = _THIN[mat]
        self.face_width_m = np.where(thin, _WIDTH_M[mat], np.inf)
        widest = float(self.face_width_m[thin].max()) if thin.any() else 0.0
        self.reach_m = (widest / TRANSPARENT_FRACTION) ** 2 / self.wavelength_m
        """Distance beyond which every thin face is transparent."""
        self.face_reach_m = np.where(thin, (self.face_width_m / TRANSPARENT_FRACTION) ** 2
                                     / self.wavelength_m, 0.0)  # fmt: skip
        self._thin: Caster | None = None
        if thin.any():
            scene = _ThinScene(np.asarray(world.vertices_m), np.asarray(world.faces), mat, thin)
            self._thin = make_caster(scene, self.backend, lband_only=True)

    def cast(self, origins_m: ArrayLike, directions: ArrayLike) -> Hits:
        """The L-band-blocking caster's first hits."""
        return self.lband.cast(origins_m, directions)

    def occluded(self, origins_m: ArrayLike, directions: ArrayLike) -> NDArray:
        """Whether each ray (n, 3) is blocked, shape (n,) bool (see the class)."""
        out = np.array(self.lband.occluded(origins_m, directions), bool)
        if self._thin is None or out.all():
            return out
        o, d = np.broadcast_arrays(np.asarray(origins_m, float), np.asarray(directions, float))
        o, d = o.reshape(-1, 3), d.reshape(-1, 3)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        todo = np.flatnonzero(~out)
        start = np.zeros(todo.size)
        for _ in range(_MAX_THIN_HITS):
            if todo.size == 0:
                return out
            hits = self._thin.cast(o[todo] + start[:, None] * d[todo], d[todo])
            dist = start + hits.distance_m
            near = hits.hit & (dist < self.reach_m)
            width = self.face_width_m[np.maximum(hits.face_id, 0)]
            opaque = near & ~transparent(width, dist, self.wavelength_m)
            out[todo[opaque]] = True
            go = near & ~opaque
            todo, start = todo[go], dist[go] + _STEP_PAST_M
        out[todo] = True  # still crossing thin faces near the antenna: blocked (safe side)
        return out


def _thin_spheres(world: SceneMesh, fc: FresnelCaster, ant: NDArray) -> tuple[NDArray, ...] | None:
    """The thin faces that may block from ``ant`` (nearer than their own reach), as
    :func:`_triangle_spheres` gives the blocking ones; None when there is none."""
    mat = np.asarray(world.face_material)
    idx = np.flatnonzero(_THIN[mat])
    if idx.size == 0:
        return None
    faces = np.asarray(world.faces)[idx]
    tri = np.asarray(world.vertices_m)[faces]
    centre = tri.mean(1)
    off = tri - centre[:, None]
    r_3d = np.linalg.norm(off, axis=-1).max(1)
    near = np.linalg.norm(centre - ant, axis=1) - r_3d < fc.face_reach_m[idx]
    if not near.any():
        return None
    return (faces[near], centre[near], np.hypot(off[near, :, 0], off[near, :, 1]).max(1),
            r_3d[near])  # fmt: skip


def _caster(world: World, backend: str, caster: Caster | None) -> Caster:
    return caster if caster is not None else make_caster(world, backend, lband_only=True)


def _triangle_spheres(world: World) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Blocking faces (m, 3), their centroids (m, 3), the largest horizontal (frame) and 3-D
    distances from the centroid to a vertex (m,) each."""
    faces = np.asarray(world.faces)[world.blocking_faces]
    tri = np.asarray(world.vertices_m)[faces]
    centre = tri.mean(1)
    off = tri - centre[:, None]
    return (
        faces,
        centre,
        np.hypot(off[..., 0], off[..., 1]).max(1),
        np.linalg.norm(off, axis=-1).max(1),
    )


def _sector_bounds(
    world: World, ant: NDArray, rot: NDArray, spheres: tuple[NDArray, ...], n_sector: int
) -> NDArray:
    """Upper bound (n_sector,) of the blocking elevation in equal azimuth sectors.

    Per triangle: its highest vertex above the antenna over the smallest horizontal distance to
    a circle around it, spread over the azimuths the circle covers. Scanning starts below it.
    """
    faces, centre, r_h, r_3d = spheres
    dz = ((np.asarray(world.vertices_m) - ant) @ rot[:, 2])[faces].max(1)
    keep = dz > 0
    # horizontal radius in the local frame: the frame's, plus what the tilt between the two
    # verticals (1 mrad per 6.4 km from the origin) can add
    tilt = np.sqrt(max(1.0 - rot[2, 2] ** 2, 0.0))
    dz, r = dz[keep], r_h[keep] + r_3d[keep] * tilt + 1e-6
    c = (centre[keep] - ant) @ rot[:, :2]  # horizontal, local ENU at the antenna
    dist = np.hypot(c[:, 0], c[:, 1])
    ub = np.degrees(np.arctan2(dz, np.maximum(dist - r, 0.0)))
    half = np.degrees(np.arcsin(np.clip(r / np.maximum(dist, 1e-9), 0.0, 1.0)))
    half = np.where(r >= dist, 180.0, half)
    caz = np.degrees(np.arctan2(c[:, 0], c[:, 1]))
    width = 360.0 / n_sector
    first = np.floor((caz - half) / width).astype(int)
    count = np.minimum(np.floor((caz + half) / width).astype(int) - first + 1, n_sector)
    rep = np.repeat(np.arange(first.size), count)
    offs = np.arange(rep.size) - np.repeat(np.cumsum(count) - count, count)
    out = np.zeros(n_sector)
    np.maximum.at(out, np.mod(first[rep] + offs, n_sector), ub[rep])
    return out


def _scan(
    caster: Caster, ant: NDArray, rot: NDArray, az: NDArray, ub: NDArray, n_bisect: int = 12
) -> NDArray:
    """Transition elevation (m,) for rays from antennas ``ant`` (m, 3) with local rotations
    ``rot`` (m, 3, 3) at azimuths ``az`` (m,), scanning down from the bound ``ub`` (m,)."""
    levels = _LEVELS
    n = az.size
    top = np.searchsorted(levels, np.minimum(ub, 90.0), side="left")  # levels[:top] < ub
    cur = top - 1
    lo = np.full(n, np.nan)
    hi = np.zeros(n)
    done = cur < 0
    az_rad = np.radians(az)
    sin_az, cos_az = np.sin(az_rad), np.cos(az_rad)

    def occluded(idx: NDArray, el_deg: NDArray) -> NDArray:
        e = np.radians(el_deg)
        d_loc = np.stack([np.cos(e) * sin_az[idx], np.cos(e) * cos_az[idx], np.sin(e)], -1)
        d = np.einsum("nij,nj->ni", rot[idx], d_loc)
        return caster.occluded(ant[idx], d)

    block = 4
    while not np.all(done):
        act = np.flatnonzero(~done)
        k = cur[act][:, None] - np.arange(block)[None, :]  # descending level indices
        valid = k >= 0
        idx = np.broadcast_to(act[:, None], k.shape)[valid]
        blocked = np.zeros(k.shape, bool)
        blocked[valid] = occluded(idx, levels[k[valid]])
        any_b = blocked.any(1)
        first = np.argmax(blocked, axis=1)
        kb = k[np.arange(act.size), first]
        res = act[any_b]
        kb = kb[any_b]
        lo[res] = levels[kb]
        hi[res] = np.where(kb + 1 < top[res], levels[np.minimum(kb + 1, levels.size - 1)], ub[res])
        done[res] = True
        cur[act] -= block
        exhausted = act[~any_b & (cur[act] < 0)]
        done[exhausted] = True  # never blocked at or above 0 deg: mask 0 (hi stays 0)
    sel = np.flatnonzero(np.isfinite(lo))
    hi_s, lo_s = np.minimum(hi[sel], 90.0), lo[sel]
    for _ in range(n_bisect):
        mid = 0.5 * (lo_s + hi_s)
        b = occluded(sel, mid)
        lo_s, hi_s = np.where(b, mid, lo_s), np.where(b, hi_s, mid)
    out = np.zeros(n)
    out[sel] = hi_s
    return out


def true_masks(
    world: World,
    chainage_m: ArrayLike | None = None,
    antenna_height_m: float = 4.0,
    az_step_deg: float = 0.5,
    backend: str = "open3d",
    *,
    n_sub: int = 4,
    caster: Caster | None = None,
    progress: bool = False,
    thin_rule: bool = True,
) -> TrueMasks:
    """True 360 deg elevation masks of the L-band-blocking scene at antenna positions.

    Parameters
    ----------
    world : World
    chainage_m : array_like, shape (n,), optional
        Positions; default every 10 m over the world's extent.
    antenna_height_m : float
        Antenna height above the rail along the local vertical.
    az_step_deg : float
        Bin width; must divide 360.
    backend : {"open3d", "trimesh"}
        Ray caster (ignored when ``caster`` is given).
    n_sub : int
        Azimuth samples per bin (edges shared with the neighbours); the bin's mask is their
        maximum, so masts narrower than ``az_step_deg / n_sub`` can be missed.
    caster : Caster, optional
        A prebuilt ``make_caster(world, backend, lband_only=True)``.
    progress : bool
        Show a tqdm progress bar.
    thin_rule : bool
        Thin structures block where the first Fresnel zone rule says so at their distance
        from the antenna (:class:`FresnelCaster`, L1); False: they never block (the rule
        before 2026-12-05).

    Returns
    -------
    TrueMasks
    """
    n_az = round(360.0 / az_step_deg)
    if n_az < 1 or abs(n_az * az_step_deg - 360.0) > 1e-9 or n_sub < 1:
        raise ValueError(f"az_step_deg must divide 360 (got {az_step_deg}) and n_sub >= 1")
    if chainage_m is None:
        lo, hi = world.extent_m
        chainage_m = np.arange(np.ceil(lo / 10.0) * 10.0, hi + 1e-9, 10.0)
    s = np.atleast_1d(np.asarray(chainage_m, float))
    cst = _caster(world, backend, caster)
    ant = world.antenna_enu(s, antenna_height_m)
    rot = _local_rotations(world, ant)
    spheres = _triangle_spheres(world)
    # "covered" means under a roof (every bin 90 deg): the L-band-blocking scene decides it; a
    # thin structure straight overhead blocks only the directions through it
    covered = cst.occluded(ant, rot[:, :, 2])
    fc = FresnelCaster(world, cst) if thin_rule else None
    scan_cst: Caster = fc if fc is not None else cst
    az_sub = np.mod(np.arange(n_az * n_sub) * (az_step_deg / n_sub) - az_step_deg / 2, 360.0)
    n_sector = 720
    sector = np.floor(az_sub / (360.0 / n_sector)).astype(int) % n_sector
    mask = np.full((s.size, n_az), 90.0)
    mask_min = np.full((s.size, n_az), 90.0)
    todo = np.flatnonzero(~covered)
    it: Iterable[int] = tqdm(todo, desc="true masks", unit="pos") if progress else todo
    chunk: list[int] = []
    for j, p in enumerate(it):
        chunk.append(int(p))
        if len(chunk) < 8 and j < todo.size - 1:
            continue
        idx = np.array(chunk)
        ub = np.stack([_sector_bounds(world, ant[q], rot[q], _with_thin(world, fc, ant[q], spheres),
                                      n_sector) for q in idx])  # fmt: skip
        pos = np.repeat(idx, az_sub.size)
        el = _scan(scan_cst, ant[pos], rot[pos], np.tile(az_sub, idx.size), ub[:, sector].ravel())
        v = np.clip(el, 0.0, 90.0).reshape(idx.size, n_az, n_sub)
        right_edge = np.roll(v[:, :, 0], -1, axis=1)
        mask[idx] = np.maximum(v.max(2), right_edge)
        mask_min[idx] = np.minimum(v.min(2), right_edge)
        chunk = []
    dist, height = obstacle_descriptors(world, s, antenna_height_m, caster=cst)
    lat, lon, h = world.frame.to_geodetic(ant)
    return TrueMasks(
        chainage_m=s,
        lat_deg=np.asarray(lat),
        lon_deg=np.asarray(lon),
        h_m=np.asarray(h),
        heading_deg=np.asarray(world.track.heading_at(s), float),
        az_deg=np.arange(n_az) * az_step_deg,
        mask_el_deg=mask,
        mask_min_el_deg=mask_min,
        covered=covered,
        obstacle_distance_m=dist,
        obstacle_height_m=height,
        antenna_height_m=float(antenna_height_m),
        az_step_deg=float(az_step_deg),
        backend=getattr(cst, "backend", backend),
    )


def _with_thin(
    world: World, fc: FresnelCaster | None, ant: NDArray, spheres: tuple[NDArray, ...]
) -> tuple[NDArray, ...]:
    """``spheres`` and the thin faces that may block from ``ant``: the scan starts above
    them too."""
    thin = None if fc is None else _thin_spheres(world, fc, ant)
    if thin is None:
        return spheres
    return tuple(np.concatenate([a, b]) for a, b in zip(spheres, thin, strict=True))


def obstacle_descriptors(
    world: World,
    chainage_m: ArrayLike,
    antenna_height_m: float = 4.0,
    backend: str = "open3d",
    *,
    caster: Caster | None = None,
    max_range_m: float = 100.0,
    depth_m: float = 30.0,
) -> tuple[NDArray, NDArray]:
    """Distance and height of the nearest L-band-blocking obstacle on each side of the track.

    Both are measured in the vertical plane through the track axis point, perpendicular to the
    track (local horizontal azimuth ``heading - 90`` for left, ``heading + 90`` for right):

    * distance: horizontal distance from the axis to the first blocking surface met by
      horizontal rays at 1 m, 2 m, ... up to the antenna height above the rail, within
      ``max_range_m``;
    * height: height above the rail of the highest blocking surface in that plane between the
      distance and ``depth_m`` beyond it (vertical rays cast down every 0.25 m), i.e. the top
      of a facade or rock wall, or the crest of a cutting.

    Returns
    -------
    distance_m, height_m : ndarray, shape (n, 2)
        Columns in :data:`SIDES` order; NaN where no obstacle lies within range.
    """
    s = np.atleast_1d(np.asarray(chainage_m, float))
    cst = _caster(world, backend, caster)
    axis = np.asarray(world.track.enu_at(s), float)
    rot = _local_rotations(world, axis)
    hd = np.radians(np.asarray(world.track.heading_at(s), float))
    up = rot[:, :, 2]
    heights = np.arange(1.0, antenna_height_m + 1e-9, 1.0)
    behind = np.arange(0.0, depth_m + 1e-9, 0.25) + 0.01
    dist = np.full((s.size, 2), np.nan)
    top = np.full((s.size, 2), np.nan)
    z0 = 500.0  # start of the downward rays above the rail
    for k, sign in enumerate((-1.0, 1.0)):  # left = heading - 90
        a = hd + sign * np.pi / 2
        d = np.einsum("nij,nj->ni", rot, np.stack([np.sin(a), np.cos(a), 0 * a], -1))
        o = axis[:, None] + heights[None, :, None] * up[:, None]
        t = cst.cast(o.reshape(-1, 3), np.repeat(d, heights.size, 0)).distance_m
        t = t.reshape(s.size, heights.size).min(1)
        ok = t <= max_range_m
        dist[ok, k] = t[ok]
        t = np.where(ok, t, 0.0)
        src = axis[:, None] + (t[:, None] + behind)[..., None] * d[:, None] + z0 * up[:, None]
        down = np.repeat(-up, behind.size, 0)
        tt = cst.cast(src.reshape(-1, 3), down).distance_m.reshape(s.size, behind.size)
        best = z0 - np.min(tt, axis=1)  # nearest hit from above = highest surface
        top[ok, k] = best[ok]
    return dist, top


def is_blocked(
    world: World,
    antenna_enu: ArrayLike,
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    backend: str = "open3d",
    *,
    caster: Caster | None = None,
) -> NDArray:
    """Whether satellite directions are blocked by L-band-blocking geometry (direct ray cast).

    Parameters
    ----------
    antenna_enu : array_like, shape (*P, 3)
        Antenna positions in the world frame.
    az_deg, el_deg : array_like, shape (*P, ...) broadcastable
        Directions in the local ENU at each antenna (positions first, e.g. (n_pos, n_sat)).

    Returns
    -------
    ndarray of bool, shape of the broadcast directions
    """
    ant = np.asarray(antenna_enu, float)
    az, el = np.broadcast_arrays(np.asarray(az_deg, float), np.asarray(el_deg, float))
    pshape = ant.shape[:-1]
    extra = max(az.ndim - len(pshape), 0)  # positions first: align antennas on the left
    rot = _local_rotations(world, ant).reshape((*pshape, *(1,) * extra, 3, 3))
    d = np.einsum("...ij,...j->...i", rot, azel_to_enu(az, el))
    o = np.broadcast_to(ant.reshape((*pshape, *(1,) * extra, 3)), d.shape)
    out = _caster(world, backend, caster).occluded(o.reshape(-1, 3), d.reshape(-1, 3))
    return out.reshape(d.shape[:-1])


def ideal_sky_mask(
    world: World,
    chainage_m: ArrayLike,
    camera: CameraModel,
    mount: Mount,
    antenna_height_m: float = 4.0,
    reverse: bool = False,
    backend: str = "open3d",
    *,
    caster: Caster | None = None,
) -> NDArray:
    """Sky masks of frames with no segmentation error: no L-band-blocking hit on each pixel's
    centre ray.

    Thin L-band-transparent structures (wires, masts) are sky, as the thin-structure policy
    wants; pixels outside a fisheye's image circle are not sky.

    Parameters
    ----------
    world : World
    chainage_m : array_like, shape (*S)
        Frame positions along the track, metres.
    camera : CameraModel
    mount : Mount
        The camera's mount on the vehicle (lever arm from the antenna included).
    antenna_height_m : float
        Antenna height above the rail, metres.
    reverse : bool
        The vehicle runs towards decreasing chainage.
    caster : Caster, optional
        A ready L-band-only caster of the world (saves building one per call).

    Returns
    -------
    ndarray of bool, shape (*S, H, W)
    """
    s = np.asarray(chainage_m, float)
    cast = _caster(world, backend, caster)
    rays = camera.pixel_to_ray(*camera.pixel_grid())  # once for every frame
    good = np.all(np.isfinite(rays), axis=-1)
    sky = np.zeros((s.size, *camera.shape), bool)
    for k, sk in enumerate(s.ravel()):
        pos, rot = camera_pose(world, float(sk), mount, antenna_height_m, reverse)
        d = rays[good] @ rot.T
        sky[k][good] = ~cast.occluded(np.broadcast_to(pos, d.shape), d)
    return sky.reshape(*s.shape, *camera.shape)


def ideal_frames(
    world: World,
    chainage_m: ArrayLike,
    camera: CameraModel,
    mounts: Mapping[str, Mount] | None = None,
    antenna_height_m: float = 4.0,
    reverse: bool = False,
    backend: str = "open3d",
    *,
    caster: Caster | None = None,
    thin_deg: float | None = None,
) -> list[FrameView]:
    """Frames with ideal sky masks (:func:`ideal_sky_mask`) at chainages, for the reconstruction.

    Parameters
    ----------
    world : World
    chainage_m : array_like, shape (n,)
        Frame positions along the track, metres.
    camera : CameraModel
    mounts : dict of str to Mount, optional
        Cameras by side; default ``Mount.default`` for ``"left"`` and ``"right"``.
    antenna_height_m, reverse, backend, caster
        As for :func:`ideal_sky_mask`.
    thin_deg : float, optional
        The pipeline's thin-structure policy (``PipelineParams.thin_deg``): the masks are then
        those of a segmenter without error followed by that policy, with its
        ``FrameView.thin_mask`` (every face a camera sees is an obstacle, features at most
        ``max(1, round(thin_deg / camera.widest_pixel_deg))`` pixels wide become sky; for a
        panorama measured in true angles, as the pipeline's
        :func:`predisat.sky.panorama.remove_thin_obstacles_equirect`).
        None: every thin-material face (wire, cantilever) is sky, whatever its width and
        distance, and there is no thin mask (the reconstruction then applies no rule).

    Returns
    -------
    list of predisat.reconstruct.carving.FrameView
        ``n * len(mounts)`` frames, position by position, in the order of ``mounts``; frame id
        chainage and side initial (``"3000l"``).
    """
    # lazy: the reconstruction pulls numba, which the other truth functions do not need
    from predisat.reconstruct.carving import FrameView

    if mounts is None:
        mounts = {side: Mount.default(side) for side in ("left", "right")}
    s = np.asarray(chainage_m, float).ravel()
    cast = _caster(world, backend, caster)
    ant = world.antenna_enu(s, antenna_height_m)
    hd = np.asarray(world.track.heading_at(s), float)
    thin: dict[str, NDArray | None] = dict.fromkeys(mounts)
    width = 0.0
    if thin_deg is None:
        sky = {k: ideal_sky_mask(world, s, camera, m, antenna_height_m, reverse, caster=cast)
               for k, m in mounts.items()}  # fmt: skip
    else:
        from predisat.sky.morphology import remove_thin_obstacles
        from predisat.sky.panorama import remove_thin_obstacles_equirect

        # a panorama's policy measures widths in true angles on the sphere, as the pipeline's
        policy = remove_thin_obstacles_equirect if camera.model == "equirect" else (
            remove_thin_obstacles)  # fmt: skip
        full = make_caster(world, backend)  # every face: what a camera sees
        px = max(1, round(thin_deg / camera.widest_pixel_deg)) if thin_deg > 0 else 0
        width = px * camera.widest_pixel_deg
        valid = np.all(np.isfinite(camera.pixel_to_ray(*camera.pixel_grid())), axis=-1)
        sky = {}
        for k, m in mounts.items():
            raw = ideal_sky_mask(world, s, camera, m, antenna_height_m, reverse, caster=full)
            sky[k] = np.stack([policy(r, px) & valid for r in raw])
            thin[k] = sky[k] & ~raw
    return [
        FrameView(float(s[i]), sky[k][i], camera, m, ant[i], float(hd[i]), reverse,
                  frame_id=f"{s[i]:.0f}{k[0]}",
                  thin_mask=None if thin[k] is None else thin[k][i],  # type: ignore[index]
                  thin_width_deg=width)
        for i in range(s.size) for k, m in mounts.items()
    ]  # fmt: skip
