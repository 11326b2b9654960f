"""Whether each camera sees the sun and the horizon where its calibration puts them: a lens
swapped for a stretch.

A spare camera with a lens 1.25 times longer swapped in on one side over 150 m of a 400 m
survey (the images zoomed 1.25x, same size, same calibration file) passed every other check,
and the masks trusted 0.228 % of their directions falsely, 1.35 % at the worst position
(``docs/reconstruction.md``, section 19). The frames' geometry is wrong, and two things in
them say so.

*The sun.* Its direction is known from the frame's time and place (the ephemeris,
:func:`predisat.gnss.sun.sun_azel`, about 0.01 deg); the track's heading, the vehicle's
attitude and the camera's mount carry it into the camera, and the calibration into a pixel.
A camera whose lens is not its calibration's images it elsewhere: a focal length ``s`` times
the calibration's moves a direction ``theta`` from the optical axis to about ``s * theta``
(6.5 deg off for the sun 26 deg from the axis and ``s = 1.25``; 2.6 deg for ``s = 1.1``; but
only 0.5-2.5 deg for a sun 2-10 deg from the axis). A turned mount, a wrong clock or a wrong
heading move it too, and are as wrong for the masks. Per frame whose predicted sun lies
inside the image, the sun is looked for: round spots of saturated (white) pixels, the one
nearest the prediction (:func:`locate_sun`).

*The horizon.* No sky lies under it (its dip is 0.06 deg from 4 m up). A side camera pitched
up through a longer lens shows the horizon lower than its calibration says: 45 deg from the
axis becomes 56 deg, the horizon reads -11 deg. A frame whose lowest sky reaches under the
horizon, beyond the attitude's doubt, over a tenth of its columns is *under*
(:func:`horizon_residual`, from the segmentation). A shorter lens, which raises the horizon,
is not seen this way.

A frame whose sun is found further than the tolerance from the prediction, or whose sky is
under the horizon, is *off* (:func:`off_stretches`): a run of at least
:data:`MIN_OFF_SIGHTINGS` such frames with no frame on its place between them marks a stretch
of the camera's frames, widened to the frames on their place on either side (the frames
between, where the sun was hidden or the horizon not seen, cannot be shown to be the
calibration's camera). A camera that never sees the sun nor the horizon is not checked."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import CameraModel

__all__ = [
    "EDGE_PX",
    "HORIZON_TOLERANCE_DEG",
    "MAX_SEARCH_DEG",
    "MIN_OFF_SIGHTINGS",
    "MIN_SPOT_PX",
    "MIN_UNDER_SHARE",
    "SATURATED",
    "SUN_CLEAR_DEG",
    "SUN_CLEAR_SHARE",
    "SUN_TOLERANCE_DEG",
    "Sighting",
    "horizon_residual",
    "locate_sun",
    "lowest_sky_deg",
    "off_stretches",
    "sun_in_image",
]

SATURATED = 250
"""Smallest value, in every colour channel, of a pixel taken for the sun's disc (8-bit)."""
MIN_SPOT_PX = 12
"""Smallest spot of saturated pixels taken for the sun (a glint, a lamp are smaller)."""
EDGE_PX = 12
"""A predicted sun within this many pixels of the image's edge is not looked for (its disc and
glare would be cut by the edge, their centre biased)."""
MAX_SEARCH_DEG = 25.0
"""A saturated spot further than this from the predicted sun is not taken for it (a lens
1.35 times longer moves the sun 21 deg at 60 deg from the axis; flare ghosts and white
objects lie anywhere)."""
SUN_TOLERANCE_DEG = 1.5
"""How far the sun may be found from its prediction with a lens that is its calibration's,
beyond the attitude's and the mount's stated doubts: the spot's centre (a disc partly
behind an edge is not round and not taken), the ephemeris (0.01 deg), the clock (0.25 deg a
minute). Rendered surveys: at most 0.04 deg on its place, 2.6 deg for a lens 1.1 times
longer."""
SUN_CLEAR_DEG = 2.0
"""A spot is taken for the sun only with sky all around it, this far beyond its own extent
(given the frame's segmentation): a sun behind a facade or a roof leaves its glare in the gap
beside it, a saturated blob whose centre is not the sun's though its bounding box may be square
(held-out worlds, fisheye_s41 and s43: glare clipped by a glass or white facade found 9-18 deg
off; 4 of 233 sightings on their place had an obstacle this near)."""
SUN_CLEAR_SHARE = 0.01
"""Largest share of non-sky pixels within :data:`SUN_CLEAR_DEG` of a spot taken for the sun
(the segmentation's edge noise)."""
MIN_OFF_SIGHTINGS = 2
"""Consecutive sightings off their place that mark a stretch (one may be a reflection)."""


@dataclass(frozen=True)
class Sighting:
    """The sun found in a frame.

    Attributes
    ----------
    u_px, v_px : float
        The centre of its spot.
    residual_deg : float
        Angle between the direction of that pixel (through the calibration) and the sun's.
    radial_scale : float
        The spot's angle from the optical axis over the predicted sun's (about the focal
        length's ratio for a lens swap; NaN within 2 deg of the axis).
    """

    u_px: float
    v_px: float
    residual_deg: float
    radial_scale: float


def sun_in_image(camera: CameraModel, sun_cam: ArrayLike) -> bool:
    """Whether a camera-frame direction toward the sun lands inside the image, at least
    :data:`EDGE_PX` from its edges."""
    ray = np.asarray(sun_cam, float).reshape(1, 3)
    pu, pv = camera.ray_to_pixel(ray)
    u, v = float(np.asarray(pu).reshape(-1)[0]), float(np.asarray(pv).reshape(-1)[0])
    if not (np.isfinite(u) and np.isfinite(v)):
        return False
    return bool(EDGE_PX <= u <= camera.width_px - 1 - EDGE_PX
                and EDGE_PX <= v <= camera.height_px - 1 - EDGE_PX)  # fmt: skip


def locate_sun(
    image_bgr: NDArray, camera: CameraModel, sun_cam: ArrayLike, sky: ArrayLike | None = None
) -> Sighting | None:
    """The round spot of saturated pixels nearest the predicted sun, within
    :data:`MAX_SEARCH_DEG`, or None.

    A spot is round when its bounding box is nearly square (sides within 3:4) and it fills at
    least 3/4 of the ellipse inscribed in it: a sun partly behind a roof, a lit white wall or
    a sky band over-exposed along a skyline are not. Given the frame's ``sky``, a spot is also
    taken only with sky all around it (:data:`SUN_CLEAR_DEG`): the glare of a sun hidden
    behind a facade, clipped by it into a square blob, is not.

    Parameters
    ----------
    image_bgr : ndarray, shape (h, w, 3) or (h, w)
        The frame (8-bit), at the calibration's size.
    camera : CameraModel
    sun_cam : array_like, shape (3,)
        Unit direction toward the sun in the camera frame.
    sky : array_like of bool, shape (h, w), optional
        The frame's sky segmentation (default: no clearance test).
    """
    img = np.asarray(image_bgr)
    if img.shape[:2] != (camera.height_px, camera.width_px):
        return None
    sky_m = None if sky is None else np.asarray(sky, bool)
    if sky_m is not None and sky_m.shape != img.shape[:2]:
        sky_m = None
    white = (img.min(axis=2) if img.ndim == 3 else img) >= SATURATED
    n, labels, stats, centres = cv2.connectedComponentsWithStats(white.astype(np.uint8))
    d = np.asarray(sun_cam, float)
    d = d / np.linalg.norm(d)
    h, w = white.shape
    best: Sighting | None = None
    for k in range(1, n):
        x, y, bw, bh, area = (int(t) for t in stats[k])
        if area < MIN_SPOT_PX or x == 0 or y == 0 or x + bw >= w or y + bh >= h:
            continue
        if not (0.75 <= bw / bh <= 4 / 3 and area >= 0.75 * np.pi * bw * bh / 4):
            continue
        u, v = (float(c) for c in centres[k])
        ray = camera.pixel_to_ray(np.array([u]), np.array([v]))[0]
        if not np.all(np.isfinite(ray)):
            continue
        err = float(np.degrees(np.arccos(np.clip(ray @ d, -1.0, 1.0))))
        if err > MAX_SEARCH_DEG or (best is not None and err >= best.residual_deg):
            continue
        if sky_m is not None and not _clear(labels == k, sky_m, camera, ray, (x, y, bw, bh)):
            continue
        th_pred = float(np.degrees(np.arccos(np.clip(d[2], -1.0, 1.0))))
        th_obs = float(np.degrees(np.arccos(np.clip(ray[2], -1.0, 1.0))))
        best = Sighting(u, v, err, th_obs / th_pred if th_pred > 2.0 else float("nan"))
    return best


def _clear(
    spot: NDArray, sky: NDArray, camera: CameraModel, centre: NDArray, box: tuple[int, ...]
) -> bool:
    """Whether the pixels within :data:`SUN_CLEAR_DEG` of a spot (beyond its own extent from
    its centre's ray) are sky, but for :data:`SUN_CLEAR_SHARE` of them."""
    x, y, bw, bh = box
    h, w = spot.shape
    # a window about the spot wide enough for the margin at the camera's coarsest scale there
    ru, rv = camera.ray_to_pixel(centre[None])
    step = camera.pixel_to_ray(np.array([float(ru[0]), float(ru[0]) + 1.0]),
                               np.array([float(rv[0])] * 2))  # fmt: skip
    deg_px = float(np.degrees(np.arccos(np.clip(step[0] @ step[1], -1.0, 1.0))))
    pad = int(np.ceil(3.0 * SUN_CLEAR_DEG / max(deg_px, 1e-3))) + 2
    x0, y0 = max(0, x - pad), max(0, y - pad)
    x1, y1 = min(w, x + bw + pad), min(h, y + bh + pad)
    v, u = np.mgrid[y0:y1, x0:x1]
    rays = camera.pixel_to_ray(u.ravel().astype(float), v.ravel().astype(float))
    ang = np.degrees(np.arccos(np.clip(rays @ centre, -1.0, 1.0))).reshape(u.shape)
    inside = spot[y0:y1, x0:x1]
    reach = float(np.nanmax(np.where(inside, ang, np.nan)))
    ring = (ang <= reach + SUN_CLEAR_DEG) & ~inside & np.isfinite(ang)
    if not ring.any():
        return False
    return bool(np.mean(~sky[y0:y1, x0:x1][ring]) <= SUN_CLEAR_SHARE)


def off_stretches(
    residual_deg: Sequence[float] | NDArray, tolerance_deg: ArrayLike
) -> list[tuple[int, int]]:
    """The stretches of a camera's frames (in time order) whose sun is not where it should be.

    Parameters
    ----------
    residual_deg : sequence of float
        Per frame, its sighting's residual (:attr:`Sighting.residual_deg`); NaN where the sun
        was not looked for or not found.
    tolerance_deg : float or array_like
        Largest residual of a frame on its place (per frame or one for all).

    Returns
    -------
    list of (first, last)
        Frame indices, inclusive: from the frame after the last sighting on its place before
        a run of at least :data:`MIN_OFF_SIGHTINGS` sightings off their place, to the frame
        before the next sighting on its place (or the camera's first and last frames).
    """
    r = np.asarray(residual_deg, float)
    tol = np.broadcast_to(np.asarray(tolerance_deg, float), r.shape)
    seen = np.flatnonzero(~np.isnan(r))
    off = r[seen] > tol[seen]
    out: list[tuple[int, int]] = []
    i = 0
    while i < seen.size:
        if not off[i]:
            i += 1
            continue
        j = i
        while j + 1 < seen.size and off[j + 1]:
            j += 1
        if j - i + 1 >= MIN_OFF_SIGHTINGS:
            first = int(seen[i - 1]) + 1 if i > 0 else 0
            last = int(seen[j + 1]) - 1 if j + 1 < seen.size else r.size - 1
            out.append((first, last))
        i = j + 1
    return out


# --------------------------------------------------------------------------------------------
# the horizon: no sky lies under it
# --------------------------------------------------------------------------------------------

HORIZON_TOLERANCE_DEG = 3.0
"""How far under the horizon a frame's lowest sky may reach with a lens that is its
calibration's, beyond the attitude's and the mount's stated doubts: the horizon's dip (0.06
deg from 4 m, 0.3 deg from 100 m over a valley) and the segmentation's edge. Rendered
surveys: the lowest sky of a frame at +1.4 deg or higher; a lens 1.25 times longer on a
camera pitched 45 deg up puts the horizon at -11 to -13 deg."""
MIN_UNDER_SHARE = 0.1
"""Share of a frame's columns holding sky whose lowest sky pixel lies more than the tolerance
under the horizon above which the frame is *under* (a white object taken for sky reaches a
few columns; a lens of another focal length moves the whole horizon)."""


def lowest_sky_deg(sky: ArrayLike, elevation_deg: ArrayLike) -> NDArray:
    """Per image column, the elevation of its lowest sky pixel (NaN for a column without sky).

    Parameters
    ----------
    sky : array_like of bool, shape (h, w)
    elevation_deg : array_like, shape (h, w)
        Elevation of each pixel's ray (calibration, mount, attitude, heading); NaN where the
        pixel has no ray.
    """
    s = np.asarray(sky, bool) & np.isfinite(np.asarray(elevation_deg, float))
    e = np.where(s, np.asarray(elevation_deg, float), np.inf)
    low = e.min(axis=0)
    return np.where(np.isfinite(low), low, np.nan)


def horizon_residual(lowest_deg: ArrayLike, tolerance_deg: float) -> float:
    """A frame's evidence on its horizon, as a residual :func:`off_stretches` reads: +inf when
    at least :data:`MIN_UNDER_SHARE` of its columns with sky reach more than ``tolerance_deg``
    under the horizon (the frame is under), 0 when as many reach within the tolerance of it
    (the horizon on its place), NaN otherwise (no horizon seen)."""
    low = np.asarray(lowest_deg, float)
    low = low[np.isfinite(low)]
    if low.size == 0:
        return float("nan")
    if np.mean(low < -tolerance_deg) >= MIN_UNDER_SHARE:
        return float("inf")
    if np.mean(np.abs(low) <= tolerance_deg) >= MIN_UNDER_SHARE:
        return 0.0
    return float("nan")
