"""Ray casting against a synthetic world with open3d or with trimesh + Embree.

Both backends give the same :class:`Hits` so one checks the other. Both intersect in float32, so
the scene is re-centred on the middle of its bounding box before conversion (a few km of scene
keeps about 0.5 mm resolution); hit distances are then recomputed in float64 from the hit
triangle's plane, which makes the two backends agree to well below a millimetre.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.readonly import freeze_array_fields

__all__ = ["BACKENDS", "Caster", "Hits", "SceneMesh", "make_caster"]

BACKENDS = ("open3d", "trimesh")


@dataclass(frozen=True)
class Hits:
    """First intersections of rays with a world.

    Attributes
    ----------
    distance_m : ndarray, shape (n,)
        Distance from the ray origin along the unit direction, metres; ``inf`` for a miss.
    face_id : ndarray, shape (n,), int64
        Index into ``world.faces``; -1 for a miss.
    normal : ndarray, shape (n, 3)
        Unit geometric normal of the hit face in frame ENU (outward for closed solids, as
        stored, not flipped toward the ray); zeros for a miss.
    """

    distance_m: NDArray
    face_id: NDArray
    normal: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def hit(self) -> NDArray:
        """Boolean (n,) mask of rays that hit something."""
        return self.face_id >= 0

    def material_id(self, face_material: ArrayLike) -> NDArray:
        """Material id (n,) of the hit faces (``world.face_material``), -1 for a miss."""
        fm = np.asarray(face_material)
        return np.where(self.hit, fm[np.maximum(self.face_id, 0)], -1)


class SceneMesh(Protocol):
    """The part of a scene a caster reads (:class:`predisat.synth.world.World` is one).

    Attributes
    ----------
    vertices_m : ndarray, shape (n, 3)
        Vertices in frame ENU, metres.
    faces : ndarray, shape (m, 3), int
        Vertex indices of the triangles.
    face_material : ndarray, shape (m,), int
        Index into :data:`predisat.synth.world.MATERIALS` of each face.
    blocking_faces : ndarray, shape (m,), bool
        Faces that block L-band signals.
    """

    @property
    def vertices_m(self) -> NDArray: ...
    @property
    def faces(self) -> NDArray: ...
    @property
    def face_material(self) -> NDArray: ...
    @property
    def blocking_faces(self) -> NDArray: ...


class Caster(Protocol):
    """What :func:`make_caster` returns."""

    backend: str

    def cast(self, origins_m: ArrayLike, directions: ArrayLike) -> Hits:
        """First hits of rays (n, 3) from ``origins_m`` (frame ENU, metres) along ``directions``."""
        ...

    def occluded(self, origins_m: ArrayLike, directions: ArrayLike) -> NDArray:
        """Whether each ray (n, 3) hits anything, shape (n,) bool."""
        ...


def _rays(origins_m: ArrayLike, directions: ArrayLike) -> tuple[NDArray, NDArray]:
    o = np.asarray(origins_m, float)
    d = np.asarray(directions, float)
    o, d = np.broadcast_arrays(o, d)
    if o.shape[-1:] != (3,):
        raise ValueError(f"origins_m and directions must have shape (n, 3), got {o.shape}")
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(norm == 0) or not np.all(np.isfinite(o)):
        raise ValueError("directions must be non-zero and origins_m finite")
    return o, d / norm


class _Base:
    """Scene geometry shared by the backends: re-centred faces and float64 planes."""

    backend = ""

    def __init__(self, world: SceneMesh, lband_only: bool) -> None:
        keep = np.flatnonzero(world.blocking_faces) if lband_only else np.arange(len(world.faces))
        faces = np.asarray(world.faces)[keep]
        v = np.asarray(world.vertices_m, float)
        self.centre_m = 0.5 * (v.min(0) + v.max(0)) if len(v) else np.zeros(3)
        self.face_index = keep  # scene face -> world face
        self.vertices_local = v - self.centre_m
        self.faces = faces
        tri = self.vertices_local[faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.normals = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
        self.plane_point = tri[:, 0]

    def _hits(self, o_local: NDArray, d: NDArray, prim: NDArray, t_backend: NDArray) -> Hits:
        hit = prim >= 0
        p = np.maximum(prim, 0)
        nrm = self.normals[p]
        dn = np.sum(d * nrm, -1)
        grazing = np.abs(dn) < 1e-6
        t_plane = np.sum((self.plane_point[p] - o_local) * nrm, -1) / np.where(grazing, 1.0, dn)
        t = np.where(grazing | ~np.isfinite(t_plane) | (t_plane < 0), t_backend, t_plane)
        return Hits(
            distance_m=np.where(hit, t, np.inf),
            face_id=np.where(hit, self.face_index[p], -1).astype(np.int64),
            normal=np.where(hit[:, None], nrm, 0.0),
        )


class Open3dCaster(_Base):
    """Ray casting with ``open3d.t.geometry.RaycastingScene`` (Embree inside, multithreaded)."""

    backend = "open3d"

    def __init__(self, world: SceneMesh, lband_only: bool = False) -> None:
        # lazy: open3d is heavy and only this backend needs it
        import open3d

        super().__init__(world, lband_only)
        o3d: Any = open3d  # its stubs reject plain ndarrays that it accepts at run time
        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        if len(self.faces):
            self._scene.add_triangles(
                o3d.core.Tensor(self.vertices_local.astype(np.float32)),
                o3d.core.Tensor(self.faces.astype(np.uint32)),
            )

    def _tensor(self, o: NDArray, d: NDArray) -> Any:
        rays = np.concatenate([o - self.centre_m, d], axis=-1).astype(np.float32)
        return self._o3d.core.Tensor(rays)

    def cast(self, origins_m: ArrayLike, directions: ArrayLike) -> Hits:
        """First hits of rays (n, 3) from ``origins_m`` (frame ENU, metres) along ``directions``."""
        o, d = _rays(origins_m, directions)
        if not len(self.faces):
            return _no_hits(len(o))
        res = self._scene.cast_rays(self._tensor(o, d))
        t = res["t_hit"].numpy().astype(float)
        prim = np.where(np.isfinite(t), res["primitive_ids"].numpy().astype(np.int64), -1)
        return self._hits(o - self.centre_m, d, prim, t)

    def occluded(self, origins_m: ArrayLike, directions: ArrayLike) -> NDArray:
        """Whether each ray (n, 3) hits anything, shape (n,) bool (faster than :meth:`cast`)."""
        o, d = _rays(origins_m, directions)
        if not len(self.faces):
            return np.zeros(len(o), bool)
        return self._scene.test_occlusions(self._tensor(o, d)).numpy().astype(bool)


class EmbreeCaster(_Base):
    """Ray casting with trimesh's Embree wrapper (``embreex``), first hit only."""

    backend = "trimesh"

    def __init__(self, world: SceneMesh, lband_only: bool = False) -> None:
        # lazy: trimesh and embreex are needed by this backend only
        import trimesh
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        super().__init__(world, lband_only)
        mesh = trimesh.Trimesh(self.vertices_local, self.faces, process=False)
        self._rmi = RayMeshIntersector(mesh) if len(self.faces) else None

    def cast(self, origins_m: ArrayLike, directions: ArrayLike) -> Hits:
        """First hits of rays (n, 3) from ``origins_m`` (frame ENU, metres) along ``directions``."""
        o, d = _rays(origins_m, directions)
        if self._rmi is None:
            return _no_hits(len(o))
        o_local = o - self.centre_m
        prim = np.asarray(self._rmi.intersects_first(o_local, d), np.int64)
        # fallback distance for grazing hits: to the triangle centroid along the ray
        cen = self.vertices_local[self.faces[np.maximum(prim, 0)]].mean(1)
        return self._hits(o_local, d, prim, np.sum((cen - o_local) * d, -1))

    def occluded(self, origins_m: ArrayLike, directions: ArrayLike) -> NDArray:
        """Whether each ray (n, 3) hits anything, shape (n,) bool."""
        o, d = _rays(origins_m, directions)
        if self._rmi is None:
            return np.zeros(len(o), bool)
        return np.asarray(self._rmi.intersects_first(o - self.centre_m, d)) >= 0


def _no_hits(n: int) -> Hits:
    return Hits(np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros((n, 3)))


def make_caster(world: SceneMesh, backend: str = "open3d", lband_only: bool = False) -> Caster:
    """A ray caster for ``world``.

    Parameters
    ----------
    world : SceneMesh
        A :class:`~predisat.synth.world.World`, or any mesh with its faces' materials.
    backend : {"open3d", "trimesh"}
        ``open3d``: ``RaycastingScene``; ``trimesh``: ``RayMeshIntersector`` on Embree
        (``embreex``), the independent check.
    lband_only : bool
        Leave out faces that do not block L-band (thin wires and tubes), for GNSS visibility.
        Returned face ids still index ``world.faces``.
    """
    if backend == "open3d":
        return Open3dCaster(world, lband_only)
    if backend == "trimesh":
        return EmbreeCaster(world, lband_only)
    raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
