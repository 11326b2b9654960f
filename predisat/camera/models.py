"""Camera models, camera mounts and the vehicle frame.

Three intrinsic models (see ``docs/camera-model.md``):

* ``"pinhole"``: pinhole with radial-tangential ("plumb bob") distortion, coefficients
  ``(k1, k2, p1, p2[, k3])`` as in ``cv2.projectPoints``;
* ``"fisheye"``: the OpenCV fisheye (Kannala-Brandt / equidistant) model, ``(k1, k2, k3, k4)`` as
  in ``cv2.fisheye.projectPoints``;
* ``"equirect"``: a stitched 360-degree panorama in equirectangular projection: ``u`` is the
  longitude about the camera's y axis (0 on the optical axis, positive toward camera x), ``v``
  the latitude (positive toward camera y, down), ``u = cx + fx * lon``, ``v = cy + fy * lat``;
  no distortion.

Frames: camera frame is OpenCV's (x right, y down, z forward); vehicle frame is x forward
(direction of travel), y left, z up; the world is local east-north-up. Pixel coordinates follow
OpenCV: the centre of the top-left pixel is ``(0, 0)``, ``u`` grows to the right and ``v``
downwards, so the image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.atomic import atomic_path
from predisat.camera.calibfile import (
    CANONICAL_FORMAT,
    CANONICAL_VERSION,
    CalibrationError,
    read_calibration,
)
from predisat.jsontypes import JsonDict

__all__ = [
    "POSITIONS",
    "CalibrationError",
    "CameraModel",
    "Mount",
    "Position",
    "default_camera",
    "tilt_doubt_m",
    "tilt_shift_m",
    "vehicle_to_enu",
]

_NEWTON_ITERATIONS = 20
_NEWTON_TOL = 1e-12  # in normalised image units (about 1e-9 px)
_LUT_SIZE = 4097

# Camera axes expressed in the vehicle frame when the camera looks straight ahead, level:
# camera z (forward) -> vehicle x, camera x (right) -> -y, camera y (down) -> -z.
_CAMERA_TO_VEHICLE_LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _smallest_positive_root(coeffs_high_first: NDArray) -> float:
    """Smallest real positive root of a polynomial, ``inf`` if there is none."""
    c = np.trim_zeros(np.asarray(coeffs_high_first, float), "f")
    if c.size <= 1:
        return np.inf
    roots = np.roots(c)
    real = roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots))].real
    real = real[real > 0]
    return float(real.min()) if real.size else np.inf


@dataclass(frozen=True)
class CameraModel:
    """Intrinsic calibration of one camera (pinhole + radial-tangential, or OpenCV fisheye).

    Parameters
    ----------
    name : str
        Free label (``camera_name`` in the YAML file).
    model : {"pinhole", "fisheye", "equirect"}
    width_px, height_px : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point in pixels (OpenCV camera matrix, no skew); for
        ``"equirect"`` pixels per radian of longitude and latitude and the pixel of the
        optical axis.
    dist : tuple of float
        Pinhole: ``(k1, k2, p1, p2)`` or ``(k1, k2, p1, p2, k3)``; fisheye: ``(k1, k2, k3, k4)``;
        equirect: ``()``.

    Notes
    -----
    A distortion polynomial is only meaningful up to the radius where it stops increasing
    (beyond it, it folds back and several rays share a pixel). :meth:`ray_to_pixel` returns NaN
    for rays beyond that radius and :meth:`pixel_to_ray` for pixels beyond its image, so
    neither ever returns a ghost solution. The fisheye model accepts rays more than 90 deg off
    the optical axis (behind the image plane) up to that limit, as wide fisheye lenses see them.
    """

    name: str
    model: Literal["pinhole", "fisheye", "equirect"]
    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.model not in ("pinhole", "fisheye", "equirect"):
            raise ValueError(
                f"camera {self.name!r}: model must be 'pinhole', 'fisheye' or 'equirect', got "
                f"{self.model!r}"
            )
        if int(self.width_px) != self.width_px or int(self.height_px) != self.height_px:
            raise ValueError(f"camera {self.name!r}: width_px and height_px must be integers")
        if self.width_px <= 0 or self.height_px <= 0:
            raise ValueError(
                f"camera {self.name!r}: image size must be positive, "
                f"got {self.width_px}x{self.height_px}"
            )
        values = (self.fx, self.fy, self.cx, self.cy, *self.dist)
        if not all(np.isfinite(float(v)) for v in values):
            raise ValueError(f"camera {self.name!r}: intrinsics and distortion must be finite")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(
                f"camera {self.name!r}: focal lengths must be positive, "
                f"got fx={self.fx}, fy={self.fy}"
            )
        allowed = {"pinhole": (4, 5), "fisheye": (4,), "equirect": (0,)}[self.model]
        if len(self.dist) not in allowed:
            expected = {
                "pinhole": "(k1, k2, p1, p2[, k3])", "fisheye": "(k1, k2, k3, k4)",
                "equirect": "() (a stitched panorama has no distortion)",
            }[self.model]  # fmt: skip
            raise ValueError(
                f"camera {self.name!r}: {self.model} distortion must be {expected}, "
                f"got {len(self.dist)} coefficients"
            )
        object.__setattr__(self, "width_px", int(self.width_px))
        object.__setattr__(self, "height_px", int(self.height_px))
        object.__setattr__(self, "dist", tuple(float(d) for d in self.dist))
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))

    # ------------------------------------------------------------------ constructors and I/O

    @classmethod
    def pinhole_from_fov(
        cls,
        width_px: int,
        height_px: int,
        vfov_deg: float,
        dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0),
        name: str = "pinhole",
    ) -> CameraModel:
        """Square-pixel pinhole camera with a given vertical field of view.

        The principal point is the image centre and the focal length is chosen so that the
        top and bottom edges of the centre column see ``+-vfov_deg / 2`` through the radial
        part of ``dist`` (tangential terms are ignored for the fit).
        """
        if not 0.0 < vfov_deg < 180.0:
            raise ValueError(f"vfov_deg must be in (0, 180), got {vfov_deg}")
        return cls._centred(name, "pinhole", width_px, height_px, vfov_deg, dist)

    @classmethod
    def fisheye_from_fov(
        cls,
        width_px: int,
        height_px: int,
        vfov_deg: float,
        dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0),
        name: str = "fisheye",
    ) -> CameraModel:
        """Square-pixel OpenCV fisheye camera with a given vertical field of view.

        As :meth:`pinhole_from_fov`: centred principal point, focal length such that the top
        and bottom edges of the centre column are ``vfov_deg / 2`` off the optical axis.
        """
        if not 0.0 < vfov_deg < 360.0:
            raise ValueError(f"vfov_deg must be in (0, 360), got {vfov_deg}")
        return cls._centred(name, "fisheye", width_px, height_px, vfov_deg, dist)

    @classmethod
    def equirect(
        cls, width_px: int, height_px: int | None = None, name: str = "equirect"
    ) -> CameraModel:
        """A full-sphere equirectangular panorama (360 x 180 deg) of ``width_px`` columns.

        ``height_px`` defaults to ``width_px / 2`` (square pixels); the optical axis is the
        image centre, the image's left and right edges are the direction behind it.
        """
        h = width_px // 2 if height_px is None else height_px
        if width_px < 4 or h < 2:
            raise ValueError(
                f"equirect width_px must be >= 4 and height_px >= 2, got {width_px}x{h}"
            )
        return cls(
            name, "equirect", width_px, h, width_px / (2.0 * np.pi), h / np.pi,
            (width_px - 1) / 2.0, (h - 1) / 2.0, (),
        )  # fmt: skip

    @classmethod
    def _centred(
        cls,
        name: str,
        model: Literal["pinhole", "fisheye"],
        width_px: int,
        height_px: int,
        vfov_deg: float,
        dist: tuple[float, ...],
    ) -> CameraModel:
        """The ``*_from_fov`` camera: centred principal point, focal length from the fov."""
        probe = cls(name, model, width_px, height_px, 1.0, 1.0, 0.0, 0.0, tuple(dist))
        # undistorted radius of the edge ray: tan(theta) on the pinhole plane, theta for fisheye
        half = np.radians(vfov_deg) / 2.0
        r = np.tan(half) if model == "pinhole" else half
        if r > probe._max_radius:
            raise ValueError(
                f"vfov_deg={vfov_deg} reaches beyond the "
                f"{'radius' if model == 'pinhole' else 'angle'} where distortion {dist} folds "
                "back; use a smaller field of view or milder distortion"
            )
        f = (height_px / 2.0) / float(probe._radial(np.asarray(r)))
        return cls(
            name, model, width_px, height_px, f, f,
            (width_px - 1) / 2.0, (height_px - 1) / 2.0, tuple(dist),
        )  # fmt: skip

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> CameraModel:
        """Read a calibration file.

        The canonical layout is the one written by :meth:`to_yaml` (OpenCV FileStorage YAML with
        ``camera_matrix`` and ``distortion_coefficients``). Also read, tolerantly: ROS
        ``camera_info`` YAML, OpenCV's calibration sample output, camodocal (VINS-Fusion/GVINS)
        ``PINHOLE`` and ``KANNALA_BRANDT``, Kalibr camchains (``pinhole`` with ``radtan`` or
        ``equidistant``) and ORB-SLAM2/3 ``PinHole`` and ``KannalaBrandt8``. Other models (MEI
        omnidirectional, double sphere, ...) raise :class:`CalibrationError`.
        """
        p = Path(path)
        fields = read_calibration(p)
        try:
            return cls(**fields)
        except ValueError as exc:
            raise CalibrationError(f"{p}: {exc}") from None

    def resized(self, width_px: int, height_px: int) -> CameraModel:
        """The same lens and field of view on a sensor of another resolution.

        Focal lengths and principal point scale with the image (pixel centres at integer
        coordinates, so ``c' = (c + 0.5) * scale - 0.5``); distortion acts on normalised
        coordinates and is unchanged.
        """
        if width_px < 2 or height_px < 2:
            raise ValueError(f"width_px and height_px must be >= 2, got {width_px}x{height_px}")
        sx, sy = width_px / self.width_px, height_px / self.height_px
        return replace(
            self,
            width_px=int(width_px),
            height_px=int(height_px),
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
        )

    def to_yaml(self, path: str | os.PathLike[str]) -> Path:
        """Write the canonical calibration file with ``cv2.FileStorage`` (atomically)."""
        p = Path(path)
        if p.suffix.lower() not in (".yaml", ".yml"):
            raise ValueError(f"{p}: calibration files must end in .yaml or .yml")
        p.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(p) as tmp:
            fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
            fs.writeComment("PREDISAT camera calibration (see docs/camera-model.md)")
            fs.write("format", CANONICAL_FORMAT)
            fs.write("version", CANONICAL_VERSION)
            fs.write("camera_name", self.name)
            fs.write("model", self.model)
            fs.write("image_width", self.width_px)
            fs.write("image_height", self.height_px)
            fs.write("camera_matrix", self.camera_matrix)
            if self.dist:  # an equirect panorama has none
                fs.write("distortion_coefficients", np.asarray(self.dist, float).reshape(1, -1))
            fs.release()
        return p

    # ------------------------------------------------------------------ properties

    @property
    def camera_matrix(self) -> NDArray:
        """OpenCV camera matrix ``K``, shape (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def centre_pixel_deg(self) -> float:
        """Angle subtended by one pixel at the principal point (horizontally), degrees."""
        cx, cy = self.cx, self.cy  # the principal point
        rays = np.asarray(self.pixel_to_ray(np.array([cx - 0.5, cx + 0.5]), np.array([cy, cy])))
        a, b = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
        return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))

    @cached_property
    def widest_pixel_deg(self) -> float:
        """Largest angle one pixel subtends, horizontally or vertically, over the image (deg).

        The 1-px steps right and down from a 129 x 97 grid spanning the image, edges
        included (the widest pixel of a wide lens may lie inside, short of the edge). With it,
        a width in pixels stays within its angle anywhere in the frame, whatever the
        distortion (for the shipped cameras it is within 3 % of ``centre_pixel_deg``; for a
        lens seeing past 180 deg it may be several times that).
        """
        return float(np.degrees(np.arccos(np.nanmin(self._pixel_step_cos()))))

    @cached_property
    def narrowest_pixel_deg(self) -> float:
        """Smallest angle a one-pixel step in any direction subtends over the image (deg), on
        the grid of :attr:`widest_pixel_deg`: the smallest singular value of the pixel-to-ray
        Jacobian (a distorted lens's diagonal steps may subtend less than its horizontal or
        vertical ones), so that a distance in pixels from it covers that angle anywhere in
        the frame. (A panorama's rows near the poles subtend almost nothing horizontally; its
        rows' own scale serves better there.)"""
        r0, ru, rv = self._pixel_steps()
        du, dv = ru - r0, rv - r0  # chords of small angles: the Jacobian's columns, rad / px
        a = np.sum(du * du, axis=-1)
        c = np.sum(dv * dv, axis=-1)
        b = np.sum(du * dv, axis=-1)
        smallest = np.sqrt(np.maximum((a + c) / 2 - np.sqrt(((a - c) / 2) ** 2 + b * b), 0.0))
        return float(np.degrees(np.nanmin(smallest)))

    def _pixel_steps(self) -> tuple[NDArray, NDArray, NDArray]:
        """Unit rays on a 129 x 97 grid spanning the image and at its 1-px steps right and
        down (NaN where a pixel has no ray)."""
        u = np.linspace(0.0, self.width_px - 2.0, 129)
        v = np.linspace(0.0, self.height_px - 2.0, 97)
        uu, vv = (a.ravel() for a in np.meshgrid(u, v))

        def unit(u_px: NDArray, v_px: NDArray) -> NDArray:
            rays = np.asarray(self.pixel_to_ray(u_px, v_px), float)
            return rays / np.linalg.norm(rays, axis=-1, keepdims=True)

        return unit(uu, vv), unit(uu + 1.0, vv), unit(uu, vv + 1.0)

    def _pixel_step_cos(self) -> NDArray:
        """Cosines of the angles of the 1-px steps right and down on a 129 x 97 grid."""
        r0, ru, rv = self._pixel_steps()
        cos = np.concatenate([np.sum(r0 * ru, axis=-1), np.sum(r0 * rv, axis=-1)])
        return np.clip(cos, -1.0, 1.0)

    @cached_property
    def has_ray(self) -> NDArray:
        """Pixels whose centre has a ray (a fisheye's outside its lens circle has none), bool
        of shape ``camera.shape``, read-only."""
        rays = self.pixel_to_ray(*self.pixel_grid())
        out = np.all(np.isfinite(rays), axis=-1)
        out.setflags(write=False)
        return out

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height_px, width_px)`` as numpy orders it."""
        return (self.height_px, self.width_px)

    @cached_property
    def _max_radius(self) -> float:
        """Largest undistorted radius (pinhole: tan of the off-axis angle; fisheye: the angle
        in radians) up to which the radial distortion function is increasing."""
        d = self.dist
        if self.model == "equirect":
            return float(np.pi)  # no radial model: every direction is imaged
        if self.model == "pinhole":
            k3 = d[4] if len(d) == 5 else 0.0
            # d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] in s = r^2
            s = _smallest_positive_root(np.array([7 * k3, 5 * d[1], 3 * d[0], 1.0]))
            return float(np.sqrt(s))
        s = _smallest_positive_root(np.array([9 * d[3], 7 * d[2], 5 * d[1], 3 * d[0], 1.0]))
        return float(min(np.sqrt(s), np.pi))

    def _radial(self, r: NDArray) -> NDArray:
        """Distorted radius of undistorted radius ``r`` (pinhole radial factor times r, or the
        fisheye theta_d)."""
        d = self.dist
        r2 = r * r
        if self.model == "pinhole":
            k3 = d[4] if len(d) == 5 else 0.0
            return r * (1 + r2 * (d[0] + r2 * (d[1] + r2 * k3)))
        return r * (1 + r2 * (d[0] + r2 * (d[1] + r2 * (d[2] + r2 * d[3]))))

    def _radial_prime(self, r: NDArray) -> NDArray:
        d = self.dist
        r2 = r * r
        if self.model == "pinhole":
            k3 = d[4] if len(d) == 5 else 0.0
            return 1 + r2 * (3 * d[0] + r2 * (5 * d[1] + r2 * 7 * k3))
        return 1 + r2 * (3 * d[0] + r2 * (5 * d[1] + r2 * (7 * d[2] + r2 * 9 * d[3])))

    @cached_property
    def _inverse_lut(self) -> tuple[NDArray, NDArray]:
        """Tabulated (distorted, undistorted) radius pairs covering the whole image, used as
        the starting point of the Newton iterations."""
        corners_u = np.array([-0.5, self.width_px - 0.5])
        corners_v = np.array([-0.5, self.height_px - 0.5])
        xd = (corners_u - self.cx) / self.fx
        yd = (corners_v - self.cy) / self.fy
        rd_image = float(np.hypot(np.abs(xd).max(), np.abs(yd).max()))
        r_end = self._max_radius
        if not np.isfinite(r_end):
            # monotonic everywhere: grow the table until it covers the image generously
            r_end = max(rd_image, 1.0)
            while float(self._radial(np.asarray(r_end))) < 2.0 * rd_image:
                r_end *= 2.0
        r = np.linspace(0.0, r_end, _LUT_SIZE)
        return self._radial(r), r

    # ------------------------------------------------------------------ projection

    def ray_to_pixel(self, rays: ArrayLike) -> tuple[NDArray, NDArray]:
        """Project camera-frame directions to pixel coordinates.

        Parameters
        ----------
        rays : array_like, shape (..., 3)
            Directions in the camera frame (OpenCV axes); need not be unit length.

        Returns
        -------
        u_px, v_px : ndarray, shape (...)
            Pixel coordinates (may fall outside the image). NaN for rays the model cannot
            image: behind the camera (pinhole: ``z <= 0``) or beyond the radius where the
            distortion folds back.
        """
        v = np.asarray(rays, float)
        if v.shape[-1:] != (3,):
            raise ValueError(f"rays must have shape (..., 3), got {v.shape}")
        x, y, z = v[..., 0], v[..., 1], v[..., 2]
        if self.model == "equirect":
            return self._equirect_to_pixel(x, y, z)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if self.model == "pinhole":
                valid = z > 0
                a, b = x / z, y / z
                r = np.hypot(a, b)
                valid &= r <= self._max_radius
                xd, yd = self._distort_pinhole(a, b)
            else:
                rho = np.hypot(x, y)
                theta = np.arctan2(rho, z)
                valid = (theta <= self._max_radius) & (rho + np.abs(z) > 0)
                scale = np.where(rho > 0, self._radial(theta) / np.where(rho > 0, rho, 1.0), 0.0)
                xd, yd = x * scale, y * scale
            u = np.where(valid, self.fx * xd + self.cx, np.nan)
            w = np.where(valid, self.fy * yd + self.cy, np.nan)
        return u, w

    def _equirect_to_pixel(self, x: NDArray, y: NDArray, z: NDArray) -> tuple[NDArray, NDArray]:
        """Equirectangular projection; NaN for a zero or non-finite ray only."""
        with np.errstate(divide="ignore", invalid="ignore"):
            norm = np.sqrt(x * x + y * y + z * z)
            valid = np.isfinite(norm) & (norm > 0)
            lon = np.arctan2(x, z)
            lat = np.arcsin(np.clip(y / np.where(valid, norm, 1.0), -1.0, 1.0))
            u = np.where(valid, self.fx * lon + self.cx, np.nan)
            w = np.where(valid, self.fy * lat + self.cy, np.nan)
        return u, w

    def _distort_pinhole(self, a: NDArray, b: NDArray) -> tuple[NDArray, NDArray]:
        k1, k2, p1, p2 = self.dist[:4]
        k3 = self.dist[4] if len(self.dist) == 5 else 0.0
        r2 = a * a + b * b
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = a * radial + 2 * p1 * a * b + p2 * (r2 + 2 * a * a)
        yd = b * radial + p1 * (r2 + 2 * b * b) + 2 * p2 * a * b
        return xd, yd

    def pixel_to_ray(self, u_px: ArrayLike, v_px: ArrayLike) -> NDArray:
        """Unit camera-frame rays through pixel coordinates.

        Undistortion is solved by Newton iterations to about 1e-9 px, started from a tabulated
        inverse of the radial distortion, so it is accurate over the whole image, corners
        included.

        Parameters
        ----------
        u_px, v_px : array_like, shape (...)
            Pixel coordinates (OpenCV convention: pixel centres at integers).

        Returns
        -------
        ndarray, shape (..., 3)
            Unit rays in the camera frame; NaN where the pixel lies beyond the distortion
            model's valid radius or the iteration did not converge.
        """
        u, w = np.broadcast_arrays(np.asarray(u_px, float), np.asarray(v_px, float))
        if self.model == "equirect":
            lon = (u - self.cx) / self.fx
            lat = (w - self.cy) / self.fy
            # a half pixel of slack: the image edges are the direction behind / the poles
            ok = (np.abs(lon) <= np.pi + 0.5 / self.fx) & (np.abs(lat) <= np.pi / 2 + 0.5 / self.fy)
            lat = np.clip(lat, -np.pi / 2, np.pi / 2)
            ray = np.stack([np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)], -1)
            return np.where(ok[..., None], ray, np.nan)
        xd = (u - self.cx) / self.fx
        yd = (w - self.cy) / self.fy
        rd = np.hypot(xd, yd)
        lut_rd, lut_r = self._inverse_lut
        in_table = rd <= lut_rd[-1]
        r0 = np.where(in_table, np.interp(rd, lut_rd, lut_r), rd)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            if self.model == "fisheye":
                theta, ok = self._solve_radial(rd, r0)
                ok &= theta <= self._max_radius
                s = np.where(rd > 0, np.sin(theta) / np.where(rd > 0, rd, 1.0), 0.0)
                ray = np.stack([xd * s, yd * s, np.cos(theta)], axis=-1)
            else:
                a, b, ok = self._undistort_pinhole(xd, yd, rd, r0)
                ok &= np.hypot(a, b) <= self._max_radius
                ray = np.stack([a, b, np.ones_like(a)], axis=-1)
                ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
            if np.isfinite(self._max_radius):
                ok &= in_table
        return np.where(ok[..., None], ray, np.nan)

    def _solve_radial(self, rd: NDArray, r0: NDArray) -> tuple[NDArray, NDArray]:
        r = r0.copy()
        for _ in range(_NEWTON_ITERATIONS):
            step = (self._radial(r) - rd) / self._radial_prime(r)
            r = r - step
            if np.all(~np.isfinite(step) | (np.abs(step) < _NEWTON_TOL)):
                break
        ok = np.abs(self._radial(r) - rd) < 1e-10 * np.maximum(1.0, rd)
        return r, ok & np.isfinite(r) & (r >= 0)

    def _undistort_pinhole(
        self, xd: NDArray, yd: NDArray, rd: NDArray, r0: NDArray
    ) -> tuple[NDArray, NDArray, NDArray]:
        k1, k2, p1, p2 = self.dist[:4]
        k3 = self.dist[4] if len(self.dist) == 5 else 0.0
        scale = np.where(rd > 0, r0 / np.where(rd > 0, rd, 1.0), 1.0)
        a, b = xd * scale, yd * scale
        for _ in range(_NEWTON_ITERATIONS):
            fx_, fy_ = self._distort_pinhole(a, b)
            ex, ey = fx_ - xd, fy_ - yd
            r2 = a * a + b * b
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dradial = k1 + r2 * (2 * k2 + r2 * 3 * k3)  # d radial / d r2
            j11 = radial + 2 * a * a * dradial + 2 * p1 * b + 6 * p2 * a
            j12 = 2 * a * b * dradial + 2 * p1 * a + 2 * p2 * b
            j22 = radial + 2 * b * b * dradial + 6 * p1 * b + 2 * p2 * a
            det = j11 * j22 - j12 * j12
            da = (j22 * ex - j12 * ey) / det
            db = (j11 * ey - j12 * ex) / det
            a, b = a - da, b - db
            if np.all(~np.isfinite(da) | (np.hypot(da, db) < _NEWTON_TOL)):
                break
        fx_, fy_ = self._distort_pinhole(a, b)
        err = np.hypot(fx_ - xd, fy_ - yd)
        ok = (err < 1e-10 * np.maximum(1.0, rd)) & np.isfinite(a) & np.isfinite(b)
        return a, b, ok

    def pixel_grid(self) -> tuple[NDArray, NDArray]:
        """Coordinates of all pixel centres, ``u_px`` and ``v_px`` each of shape (H, W)."""
        v, u = np.mgrid[0 : self.height_px, 0 : self.width_px]
        return u.astype(float), v.astype(float)

    def contains(self, u_px: ArrayLike, v_px: ArrayLike) -> NDArray:
        """True where pixel coordinates fall inside the image (NaN counts as outside)."""
        u, v = np.asarray(u_px, float), np.asarray(v_px, float)
        with np.errstate(invalid="ignore"):
            return (
                (u >= -0.5) & (u <= self.width_px - 0.5) & (v >= -0.5) & (v <= self.height_px - 0.5)
            )


def default_camera(kind: Literal["pinhole", "fisheye"] = "pinhole") -> CameraModel:
    """The default side-camera calibration shipped with PREDISAT.

    ``"pinhole"``: 800x600, 74 deg vertical field of view, mild barrel distortion.
    ``"fisheye"``: 800x600 OpenCV fisheye, 120 deg vertical field of view (sees the horizon
    from a 45 deg pitch). See ``docs/camera-model.md`` for their provenance.
    """
    names = {"pinhole": "side_pinhole.yaml", "fisheye": "side_fisheye.yaml"}
    if kind not in names:
        raise ValueError(f"kind must be 'pinhole' or 'fisheye', got {kind!r}")
    ref = resources.files("predisat") / "data" / "cameras" / names[kind]
    with resources.as_file(ref) as path:
        return CameraModel.from_yaml(path)


# ---------------------------------------------------------------------- mounts and frames


def _rot_x(angle_rad: float) -> NDArray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(angle_rad: float) -> NDArray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _vehicle_attitude(roll_deg: float, pitch_deg: float) -> NDArray:
    """Level frame from a rolled and pitched vehicle's: ``Ry(-pitch) @ Rx(roll)``."""
    return _rot_y(-np.radians(pitch_deg)) @ _rot_x(np.radians(roll_deg))


def _rot_z(angle_rad: float) -> NDArray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


Position = Literal["left", "right", "front", "rear", "roof"]

#: Where a camera may sit on the vehicle: the two sides, the cabs at the front and the rear (of
#: the direction of travel), and the roof (a 360-degree camera).
POSITIONS: tuple[Position, ...] = ("left", "right", "front", "rear", "roof")

# (yaw, pitch, lever arm) of each position's default mount: side cameras 45 deg up, square to
# the track; cab cameras 30 deg up along the track, 3 m ahead of / behind the antenna and 1.5 m
# below it (behind the windscreen); the 360-degree camera level, 0.5 m behind and 0.5 m below
# the antenna (the antenna on a short mast above it), optical axis (its image centre) forward.
# Every camera sits below the antenna: sky rays prove cells free only below the camera, so a
# camera above the antenna would leave the cells around the antenna above its horizon.
_DEFAULT_MOUNT: dict[str, tuple[float, float, tuple[float, float, float]]] = {
    "left": (90.0, 45.0, (0.0, 1.5, -0.5)),
    "right": (-90.0, 45.0, (0.0, -1.5, -0.5)),
    "front": (0.0, 30.0, (3.0, 0.0, -1.5)),
    "rear": (180.0, 30.0, (-3.0, 0.0, -1.5)),
    "roof": (0.0, 0.0, (-0.5, 0.0, -0.5)),
}


@dataclass(frozen=True)
class Mount:
    """How a camera is mounted on the vehicle.

    Parameters
    ----------
    side : {"left", "right", "front", "rear", "roof"}
        Where the camera is on the vehicle (:data:`POSITIONS`, relative to the direction of
        travel): a side, a cab (front or rear) or the roof (a 360-degree camera). The name
        ``side`` is kept from format v1, which knew the two sides only.
    yaw_deg : float
        Rotation about vehicle z, from x-forward toward y-left: +90 looks left, -90 right.
    pitch_deg : float
        Optical axis above the vehicle's horizontal plane (up positive), default 45.
    roll_deg : float
        Rotation about the optical axis; positive lowers the image's right side (like an
        aircraft rolling right), default 0.
    lever_arm_m : tuple of 3 float
        Camera centre minus GNSS antenna phase centre, in the vehicle frame (x, y, z) metres.

    Notes
    -----
    ``camera_to_vehicle = Rz(yaw) @ Ry(-pitch) @ Rx(roll) @ R0`` where ``R0`` maps camera z to
    vehicle x, camera x to -y and camera y to -z (a level camera looking ahead).
    """

    side: Position
    yaw_deg: float
    pitch_deg: float = 45.0
    roll_deg: float = 0.0
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.side not in POSITIONS:
            raise ValueError(f"Mount side must be one of {POSITIONS}, got {self.side!r}")
        arm = tuple(float(x) for x in self.lever_arm_m)
        if len(arm) != 3:
            raise ValueError(f"Mount lever_arm_m must be (x, y, z) metres, got {self.lever_arm_m}")
        angles = (self.yaw_deg, self.pitch_deg, self.roll_deg)
        if not all(np.isfinite(float(a)) for a in (*angles, *arm)):
            raise ValueError("Mount angles and lever arm must be finite numbers")
        if not -90.0 <= float(self.pitch_deg) <= 90.0:
            # 135 deg up is a camera turned backwards and upside down, which yaw and roll
            # must say; accepted, a typo (145 for 45) would silently swap the sides
            raise ValueError(
                f"Mount pitch_deg must be within [-90, 90] (the optical axis above the "
                f"horizontal), got {self.pitch_deg}; the same rotation is yaw_deg + 180, "
                f"pitch_deg = 180 - pitch, roll_deg + 180"
            )
        object.__setattr__(self, "lever_arm_m", arm)
        for name in ("yaw_deg", "pitch_deg", "roll_deg"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @classmethod
    def default(cls, side: Position) -> Mount:
        """The position's usual mount.

        Sides: 45 deg up, square to the track, 1.5 m to the side of and 0.5 m below the
        antenna. Cabs (front, rear): 30 deg up along the track, 3 m ahead of (behind) and
        1.5 m below the antenna. Roof: level, looking ahead, 0.5 m behind and 0.5 m below the
        antenna.
        """
        if side not in _DEFAULT_MOUNT:
            raise ValueError(f"side must be one of {POSITIONS}, got {side!r}")
        yaw, pitch, arm = _DEFAULT_MOUNT[side]
        return cls(side, yaw, pitch, 0.0, arm)

    @classmethod
    def from_dict(cls, side: Position, data: JsonDict) -> Mount:
        """Build from a survey.yaml ``mount`` mapping (missing keys take the side's defaults)."""
        base = cls.default(side)
        unknown = set(data) - {"yaw_deg", "pitch_deg", "roll_deg", "lever_arm_m", "side"}
        if unknown:
            raise ValueError(
                f"unknown mount keys {sorted(unknown)}; allowed: yaw_deg, pitch_deg, roll_deg, "
                "lever_arm_m"
            )
        if "side" in data and data["side"] != side:
            raise ValueError(f"mount side {data['side']!r} does not match camera key {side!r}")
        return cls(
            side,
            float(data.get("yaw_deg", base.yaw_deg)),
            float(data.get("pitch_deg", base.pitch_deg)),
            float(data.get("roll_deg", base.roll_deg)),
            tuple(data.get("lever_arm_m", base.lever_arm_m)),
        )

    def to_dict(self) -> JsonDict:
        """The survey.yaml ``mount`` mapping (angles in degrees, lever arm in metres)."""
        return {
            "yaw_deg": self.yaw_deg,
            "pitch_deg": self.pitch_deg,
            "roll_deg": self.roll_deg,
            "lever_arm_m": list(self.lever_arm_m),
        }

    def camera_to_vehicle(self) -> NDArray:
        """Rotation ``R`` (3, 3) with ``v_vehicle = R @ v_camera``."""
        return (
            _rot_z(np.radians(self.yaw_deg))
            @ _rot_y(-np.radians(self.pitch_deg))
            @ _rot_x(np.radians(self.roll_deg))
            @ _CAMERA_TO_VEHICLE_LEVEL
        )

    def on_vehicle(self, roll_deg: float = 0.0, pitch_deg: float = 0.0) -> Mount:
        """This mount seen from the *level* vehicle frame of a vehicle with an attitude.

        The vehicle frame of :meth:`camera_to_vehicle` rolls with the body on a canted curve
        and pitches with the grade; everything downstream (rectification, carving) takes it
        as level. The mount returned has the same camera axes and lever arm expressed in the
        level frame (x the horizontal projection of forward, z up), so that the downstream
        code stays exact (``docs/reconstruction.md``, section 16).

        Parameters
        ----------
        roll_deg : float
            Vehicle roll about its forward axis, degrees; positive raises the left side (on a
            canted curve turning right the vehicle leans right: roll positive).
        pitch_deg : float
            Vehicle pitch, degrees; positive raises the nose (uphill in the direction of
            travel).

        Returns
        -------
        Mount
            ``camera_to_vehicle()`` equals ``Ry(-pitch) @ Rx(roll) @ self.camera_to_vehicle()``
            and the lever arm is rotated alike. ``self`` when both angles are 0.
        """
        for name, v in (("roll_deg", roll_deg), ("pitch_deg", pitch_deg)):
            if not (np.isfinite(v) and abs(v) <= 45.0):
                raise ValueError(
                    f"{name} must be a vehicle attitude within [-45, 45] degrees, got {v}"
                )
        if roll_deg == 0.0 and pitch_deg == 0.0:
            return self
        att = _vehicle_attitude(roll_deg, pitch_deg)
        m = att @ self.camera_to_vehicle() @ _CAMERA_TO_VEHICLE_LEVEL.T  # Rz Ry(-p) Rx
        sin_p = float(np.clip(m[2, 0], -1.0, 1.0))  # Ry(-p) puts +sin(p) at [2, 0]
        if abs(sin_p) < 1.0 - 1e-12:
            yaw = np.arctan2(m[1, 0], m[0, 0])
            roll = np.arctan2(m[2, 1], m[2, 2])
        else:  # looking straight up or down: yaw and roll share one axis, roll taken 0
            yaw, roll = np.arctan2(-m[0, 1], m[1, 1]), 0.0
        arm = att @ np.asarray(self.lever_arm_m, float)
        return Mount(
            self.side, float(np.degrees(yaw)), float(np.degrees(np.arcsin(sin_p))),
            float(np.degrees(roll)), (float(arm[0]), float(arm[1]), float(arm[2])),
        )  # fmt: skip

    def camera_to_enu(self, heading_deg: ArrayLike, reverse: ArrayLike = False) -> NDArray:
        """Rotation(s) ``(..., 3, 3)`` from camera frame to local ENU for a track heading.

        See :func:`vehicle_to_enu` for ``heading_deg`` and ``reverse``.
        """
        return vehicle_to_enu(heading_deg, reverse) @ self.camera_to_vehicle()

    def camera_position_enu(
        self, antenna_enu_m: ArrayLike, heading_deg: ArrayLike, reverse: ArrayLike = False
    ) -> NDArray:
        """Camera centre(s) ``(..., 3)`` in ENU from antenna position(s) ``(..., 3)``."""
        r = vehicle_to_enu(heading_deg, reverse)
        arm = r @ np.asarray(self.lever_arm_m, float)
        return np.asarray(antenna_enu_m, float) + arm


def tilt_shift_m(roll_deg: float, pitch_deg: float, height_m: float) -> NDArray:
    """Where the antenna, ``height_m`` above the rail, moves when the vehicle tilts, (3,) metres.

    A canted track tilts the whole vehicle about the rails, not about its antenna: the antenna
    ``height_m`` above the track axis (4 m up) moves toward the curve's inside by about
    ``height_m * sin(roll)`` (0.48 m for 6.9 deg). Along the track it stays where it is: a
    frame's chainage is the antenna's (docs/survey-format.md), measured, so a pitch moves it
    down only. The result is in the level vehicle frame of :meth:`Mount.on_vehicle` (x forward,
    y left, z up; its x is 0); add ``vehicle_to_enu(...) @`` it to the antenna's level
    position. Roll and pitch as there; the pivot is the track axis at rail level (with the low
    rail as the pivot the antenna also rises by half the cant, 90 mm for 180 mm: not modelled).
    """
    up = np.array([0.0, 0.0, float(height_m)])
    att = _vehicle_attitude(roll_deg, pitch_deg)
    shift = att @ up - up
    shift[0] = 0.0  # the chainage is the antenna's
    return shift


def tilt_doubt_m(
    lever_arm_m: ArrayLike,
    height_m: float,
    roll_deg: float,
    pitch_deg: float,
    roll_doubt_deg: float,
    pitch_doubt_deg: float,
) -> tuple[float, float, float]:
    """How far a camera may stand from where a nominal attitude puts it, metres.

    The vehicle's true roll lies within ``roll_doubt_deg`` of ``roll_deg`` and its pitch
    within ``pitch_doubt_deg`` of ``pitch_deg``; the body turns about the pivot of
    :func:`tilt_shift_m` (the track axis at rail level), across the track and up, while
    along the track the antenna stays at its measured chainage and the camera moves with its
    lever arm only. The rectification's erosion covers the turn of the camera's rays; this
    covers the move of its centre (``docs/reconstruction.md``, section 16).

    Parameters
    ----------
    lever_arm_m : array_like, shape (3,)
        Camera centre minus antenna, vehicle frame (x forward, y left, z up), metres.
    height_m : float
        Antenna height above the rail, metres.
    roll_deg, pitch_deg : float
        Nominal attitude, degrees (as :meth:`Mount.on_vehicle`).
    roll_doubt_deg, pitch_doubt_deg : float
        Half-widths of the true attitude's intervals, degrees (>= 0).

    Returns
    -------
    along_m, across_m, vertical_m : float
        Upper bounds of the distance between the true and the nominal camera centre along
        the vehicle (level frame x), across it (y) and vertically (z); ``hypot(along_m,
        across_m)`` bounds the horizontal distance.

    Notes
    -----
    With ``A(r, p) = Ry(-p) Rx(r)`` and ``P`` the camera from the pivot (across and up) or
    from the antenna (along: the lever arm), the move ``A(r, p) P - A(r0, p0) P`` splits into
    ``U = Ry(-p) (Rx(r) - Rx(r0)) P`` (a chord in the vehicle's y-z plane, then pitched) and
    ``V = (Ry(-p) - Ry(-p0)) Rx(r0) P`` (a chord in the x-z plane). Each chord's length is
    ``2 sin(doubt / 2)`` times its circle's radius, and each component is that times the
    largest of the matching coordinate over the half-angles swept, found exactly (a sinusoid's
    extremes over an interval): no sampling, no linearisation.
    """
    arm = np.asarray(lever_arm_m, float)
    if arm.shape != (3,) or not np.all(np.isfinite(arm)):
        raise ValueError(f"lever_arm_m must be finite (x, y, z) metres, got {lever_arm_m!r}")
    for name, v in (("roll_doubt_deg", roll_doubt_deg), ("pitch_doubt_deg", pitch_doubt_deg)):
        if not (np.isfinite(v) and 0.0 <= v <= 45.0):
            raise ValueError(f"{name} must be an angle in [0, 45] degrees, got {v}")
    r0, p0 = np.radians(float(roll_deg)), np.radians(float(pitch_deg))
    a, b = np.radians(float(roll_doubt_deg)), np.radians(float(pitch_doubt_deg))
    along = _chord_parts(arm, r0, p0, a, b)[0]
    _, across, vertical = _chord_parts(arm + np.array([0.0, 0.0, float(height_m)]), r0, p0, a, b)
    return along, across, vertical


def _chord_parts(
    point: NDArray, r0: float, p0: float, a: float, b: float
) -> tuple[float, float, float]:
    """Bounds of ``|A(r, p) P - A(r0, p0) P|`` along x, y and z over ``|r - r0| <= a`` and
    ``|p - p0| <= b`` (radians), :func:`tilt_doubt_m`'s notes."""
    px, py, pz = (float(v) for v in point)
    # roll: the chord's y and z parts (z and y of the point at the mid-angle)
    uy = 2.0 * np.sin(a / 2.0) * _sinusoid_max(pz, py, r0 - a / 2.0, r0 + a / 2.0)
    uz = 2.0 * np.sin(a / 2.0) * _sinusoid_max(py, -pz, r0 - a / 2.0, r0 + a / 2.0)
    # pitch, acting on the rolled point Q = Rx(r0) P
    qx, qz = px, py * np.sin(r0) + pz * np.cos(r0)
    vx = 2.0 * np.sin(b / 2.0) * _sinusoid_max(qz, qx, p0 - b / 2.0, p0 + b / 2.0)
    vz = 2.0 * np.sin(b / 2.0) * _sinusoid_max(qx, -qz, p0 - b / 2.0, p0 + b / 2.0)
    # U's x part is -sin(p) times its z part, its y part the chord's; V has no y part
    ux = np.sin(min(abs(p0) + b, np.pi / 2.0)) * uz
    return float(ux + vx), float(uy), float(uz + vz)


def _sinusoid_max(c: float, s: float, lo_rad: float, hi_rad: float) -> float:
    """``max |c cos t + s sin t|`` over ``t`` in ``[lo_rad, hi_rad]``."""
    amp, phase = float(np.hypot(c, s)), float(np.arctan2(s, c))
    # the extremes are the ends and the peaks t = phase + k pi inside the interval
    k = np.arange(np.ceil((lo_rad - phase) / np.pi), np.floor((hi_rad - phase) / np.pi) + 1)
    if k.size:
        return amp
    return float(max(abs(c * np.cos(lo_rad) + s * np.sin(lo_rad)),
                     abs(c * np.cos(hi_rad) + s * np.sin(hi_rad))))  # fmt: skip


def vehicle_to_enu(heading_deg: ArrayLike, reverse: ArrayLike = False) -> NDArray:
    """Rotation(s) from the vehicle frame to local east-north-up.

    Parameters
    ----------
    heading_deg : array_like, shape (...)
        Track heading (azimuth of increasing chainage), degrees.
    reverse : bool or array_like of bool, shape (...)
        True when the vehicle drives toward decreasing chainage: vehicle x then points at
        ``heading_deg + 180``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R`` with ``v_enu = R @ v_vehicle``; columns are vehicle x (forward), y (left) and
        z (up) in ENU for a level vehicle; a rolled or pitched one (cant, grade) goes through
        :meth:`Mount.on_vehicle` first.
    """
    h = np.asarray(heading_deg, float)
    rev = np.asarray(reverse, bool)
    h, rev = np.broadcast_arrays(h, rev)
    az = np.radians(np.where(rev, h + 180.0, h))
    s, c = np.sin(az), np.cos(az)
    zero, one = np.zeros_like(az), np.ones_like(az)
    forward = np.stack([s, c, zero], axis=-1)
    left = np.stack([-c, s, zero], axis=-1)  # azimuth - 90 deg
    up = np.stack([zero, zero, one], axis=-1)
    return np.stack([forward, left, up], axis=-1)
