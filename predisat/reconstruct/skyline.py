"""From a frame's sky mask to skyline directions in the local frame (issue 3, item 3).

Two views of the same information:

* :func:`skyline_directions`: per *image column*, the direction (azimuth, elevation) of the
  boundary between the column's top sky run and the highest obstacle pixel below it, using the
  camera model, the mount, the track heading and the direction of travel;
* :class:`Rectifier` / :class:`SkyProfile`: the sky mask resampled on a regular grid of
  *relative azimuth* (from the camera's horizontal look direction) and elevation, and per
  azimuth the lowest elevation of the top sky run. A tilted camera's image columns are not
  vertical planes (the edge columns of a 45 deg pinhole sweep 40 deg of azimuth from bottom to
  top), so the reconstruction works on the rectified profile, whose columns are.

Policy (conservative): only the sky *above the highest obstacle* of a column counts, so sky seen
below an overhang (a bridge deck, a canopy, foliage) never clears anything; obstacle pixels are
grown by a pixel or two before resampling so that thin obstacles are not lost between samples.
Pixels labelled as thin L-band-transparent structure (wires) must be passed as sky.

Elevations are above the local horizontal at the frame, azimuths clockwise from true north;
the vehicle's z is taken as the local vertical (grade and cant neglected, as in
:func:`predisat.camera.models.vehicle_to_enu`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import CameraModel, Mount
from predisat.geodesy import enu_to_azel
from predisat.sky.segment import confidence_window_px

__all__ = [
    "LOW_CONFIDENCE_WINDOW_DEG",
    "ColumnSkyline",
    "Rectifier",
    "SkyProfile",
    "erode_sky_deg",
    "leading_sky_rows",
    "skyline_directions",
]

_SKY, _UNSEEN = 255, 128  # grid labels; obstacle 0

LOW_CONFIDENCE_WINDOW_DEG = 4.6
"""Angular size of one confidence window for a panoramic (``"equirect"``) camera, degrees of
elevation: what one window of rows (:func:`predisat.sky.segment.confidence_window_px`) spans
in the centre column of the shipped side fisheye 45 deg up, at skylines 0 to 45 deg up (4.40
deg at half resolution, 300 rows; 4.59 deg at full resolution, 600 rows; the larger, rounded
up). Off-centre columns of the fisheye are tilted and span less elevation per row, so a
panorama's margin is at least the side fisheye's (``docs/rigs.md``)."""


def _as_sky_mask(sky: ArrayLike, camera: CameraModel, name: str = "sky_mask") -> NDArray:
    m = np.asarray(sky)
    if m.shape != camera.shape:
        raise ValueError(
            f"{name} has shape {m.shape}, expected the camera image shape {camera.shape} "
            f"(height_px, width_px) of camera {camera.name!r}"
        )
    return m.astype(bool) if m.dtype != bool else m


def leading_sky_rows(sky_mask: ArrayLike) -> NDArray:
    """Number of sky pixels above the highest obstacle pixel of each column.

    Parameters
    ----------
    sky_mask : array_like of bool, shape (H, W)
        True for sky (and for thin L-band-transparent structure).

    Returns
    -------
    ndarray of int, shape (W,)
        ``n`` such that rows ``0 .. n-1`` are sky and row ``n`` is not (``H`` for an all-sky
        column, 0 when the top pixel is already an obstacle).
    """
    m = np.asarray(sky_mask, bool)
    if m.ndim != 2:
        raise ValueError(f"sky_mask must be 2-D (H, W), got shape {m.shape}")
    obstacle = ~m
    first = np.argmax(obstacle, axis=0)
    return np.where(obstacle.any(axis=0), first, m.shape[0]).astype(np.int64)


@dataclass(frozen=True)
class ColumnSkyline:
    """Skyline direction of every image column of one frame.

    Attributes
    ----------
    sky_rows : ndarray of int, shape (W,)
        Leading sky rows per column (see :func:`leading_sky_rows`).
    ray_enu : ndarray, shape (W, 3)
        Unit direction in the local ENU at the frame of the boundary between the last sky pixel
        and the first obstacle pixel (the top edge of the obstacle pixel, ``v = n - 0.5``); the
        bottom edge of the image for an all-sky column; NaN for a column without sky.
    az_deg, el_deg : ndarray, shape (W,)
        Azimuth and elevation of ``ray_enu`` (NaN for a column without sky).
    """

    sky_rows: NDArray
    ray_enu: NDArray
    az_deg: NDArray
    el_deg: NDArray

    @property
    def valid(self) -> NDArray:
        """Columns with a sky run (finite direction), shape (W,)."""
        return np.isfinite(self.el_deg)


def skyline_directions(
    sky: ArrayLike,
    camera: CameraModel,
    mount: Mount,
    heading_deg: float,
    reverse: bool = False,
) -> ColumnSkyline:
    """Skyline direction of each image column in the local ENU frame.

    Parameters
    ----------
    sky : array_like
        Either the sky mask (bool, ``camera.shape``) or the leading sky rows per column
        (int, shape ``(width_px,)``), e.g. from a segmentation's skyline.
    camera : CameraModel
    mount : Mount
    heading_deg : float
        Track heading at the frame (azimuth of increasing chainage), degrees.
    reverse : bool
        True when the train drives toward decreasing chainage.

    Returns
    -------
    ColumnSkyline
    """
    s = np.asarray(sky)
    if s.ndim == 2:
        rows = leading_sky_rows(_as_sky_mask(s, camera))
    elif s.shape == (camera.width_px,):
        rows = s.astype(np.int64)
        if rows.min() < 0 or rows.max() > camera.height_px:
            raise ValueError(f"sky rows must lie in [0, {camera.height_px}] (camera height_px)")
    else:
        raise ValueError(
            f"sky must be a ({camera.height_px}, {camera.width_px}) mask or ({camera.width_px},) "
            f"sky rows for camera {camera.name!r}, got shape {s.shape}"
        )
    u = np.arange(camera.width_px, dtype=float)
    v = rows.astype(float) - 0.5
    ray_cam = camera.pixel_to_ray(u, v)
    ray = ray_cam @ mount.camera_to_enu(heading_deg, reverse).T
    ray = np.where((rows > 0)[:, None], ray, np.nan)
    az, el, _ = enu_to_azel(ray)
    return ColumnSkyline(rows, ray, az, el)


def erode_sky_deg(sky_mask: ArrayLike, camera: CameraModel, angle_deg: float) -> NDArray:
    """The sky of a mask whose every pixel within ``angle_deg`` is sky, shape ``camera.shape``.

    A frame whose pose is known only within a rotation of ``angle_deg`` (a vehicle roll or
    pitch not measured) may take a direction for sky only where the whole cone of that
    half-angle around it is sky: the true direction of each pixel lies within it. Frame
    cameras (pinhole, fisheye) keep the pixels farther than ``angle / narrowest pixel`` pixels
    (rounded up, plus one: a direction in reach may fall in the next pixel's area) from every
    obstacle pixel, pixel without a ray and the image's sides and bottom (the top is carried
    up: the carving takes the sky above a column's top as going on); a panorama
    row by row, its horizontal reach widening as ``1 / cos(latitude)`` toward the
    poles (the whole row at a pole).

    Parameters
    ----------
    sky_mask : array_like of bool, shape ``camera.shape``
    camera : CameraModel
    angle_deg : float
        Half-angle of the cone, degrees (>= 0; 0 returns a copy).

    Returns
    -------
    ndarray of bool, shape ``camera.shape``
    """
    m = np.ascontiguousarray(_as_sky_mask(sky_mask, camera), np.bool_)
    if not (np.isfinite(angle_deg) and angle_deg >= 0):
        raise ValueError(f"angle_deg must be a finite angle >= 0 degrees, got {angle_deg}")
    if angle_deg == 0:
        return m.copy()
    img = m.view(np.uint8)
    h, w = camera.shape
    if camera.model != "equirect":
        # one pixel more: a direction within the angle may fall in the next pixel's area
        r = int(np.ceil(angle_deg / camera.narrowest_pixel_deg)) + 1
        # Beyond the sides and the bottom nothing was observed: obstacle. Above the top the
        # carving already takes the sky as going on (a column's top sky run clears every
        # elevation above its skyline), so the top row is carried up instead; so are pixels
        # without a ray (obstacle).
        pad = np.zeros((h + 2 * r, w + 2 * r), np.uint8)
        pad[r : r + h, r : r + w] = img & camera.has_ray
        pad[:r, r : r + w] = pad[r, r : r + w]
        # the exact Euclidean distance to the nearest obstacle pixel: a disc of any radius at
        # the cost of one pass (8x faster than eroding by a 113 px disc)
        dist = cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        return np.asarray(dist[r : r + h, r : r + w] > r)
    a = np.radians(angle_deg)
    ry = int(np.ceil(a * camera.fy)) + 1
    # vertical first, then each row horizontally with its own reach (a box holds the cone)
    col = cv2.erode(img, np.ones((2 * ry + 1, 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    lat = np.abs((np.arange(h) - camera.cy) / camera.fy)  # row centres
    # the row's pixels nearest the pole set its reach; within a of the pole, every longitude
    near = np.minimum(lat + a + 0.5 / camera.fy, np.pi / 2)
    cos = np.cos(near)
    reach = np.where(cos > 1e-9, np.ceil(a * camera.fx / np.maximum(cos, 1e-9)) + 1, w)
    reach = np.minimum(reach, w).astype(np.int64)
    out = np.empty_like(col)
    for rx in np.unique(reach):
        rows = np.flatnonzero(reach == rx)
        if rx >= w // 2:
            out[rows] = col[rows].min(axis=1, keepdims=True)
            continue
        k = np.ones((1, 2 * int(rx) + 1), np.uint8)
        # longitude wraps: pad with the other edge before eroding
        band = np.concatenate([col[rows][:, -rx:], col[rows], col[rows][:, :rx]], axis=1)
        out[rows] = cv2.erode(band, k, borderType=cv2.BORDER_REPLICATE)[:, rx : rx + w]
    return out.astype(bool)


@dataclass(frozen=True)
class SkyProfile:
    """One frame's sky on a regular grid of relative azimuth.

    Attributes
    ----------
    rel_az_deg : ndarray, shape (n_b,)
        Azimuth relative to the camera's horizontal look direction, clockwise, ascending,
        within [-90, 90] (the camera's own half-space; a fisheye's view past the zenith is left
        to the camera on the other side), or within [-180, 180] for a 360-degree panorama
        (``equirect``), which sees every azimuth.
    sky_el_deg : ndarray, shape (n_b,)
        Lowest elevation of the top sky run: every observed direction above it is sky. ``+inf``
        where the top of the observed column is not sky or nothing is observed.
    seen_lo_deg, seen_hi_deg : ndarray, shape (n_b,)
        Elevation range the image covers at that azimuth; NaN where it covers none.
    look_az_deg : float
        Azimuth of the camera's horizontal look direction (local ENU at the frame).
    voided : ndarray of bool, shape (n_b,), optional
        Columns whose sky reached under the horizon check's elevation and were voided
        (``sky_el_deg`` set to ``+inf``): a mislabelled column, not a column without sky.
    """

    rel_az_deg: NDArray
    sky_el_deg: NDArray
    seen_lo_deg: NDArray
    seen_hi_deg: NDArray
    look_az_deg: float
    voided: NDArray | None = None

    @property
    def az_deg(self) -> NDArray:
        """Absolute azimuths of the profile columns, degrees in [0, 360)."""
        return np.mod(self.look_az_deg + self.rel_az_deg, 360.0)


@dataclass(frozen=True, eq=False)
class Rectifier:
    """Resamples a camera's sky masks on a (relative azimuth, elevation) grid.

    Build once per camera and mount with :meth:`build`; the map does not depend on the heading
    (relative azimuths are taken from the camera's horizontal look direction).

    Attributes
    ----------
    camera : CameraModel
    mount : Mount
    rel_az_deg : ndarray, shape (n_b,)
    el_deg : ndarray, shape (n_e,)
        Descending (row 0 is the highest elevation).
    map_u, map_v : ndarray of float32, shape (n_e, n_b)
        Pixel coordinates of each grid direction; -10 where the camera does not see it.
    pixel_index : ndarray of int32, shape (n_e, n_b)
        Flat index (``row * width_px + col``) of the pixel that ``cv2.remap`` (nearest) reads
        for each grid direction; -1 where the camera does not see it or the remap rounds the
        map off the image (the samples :meth:`rectify` labels unseen).
    first_seen_row, last_seen_row : ndarray of int64, shape (n_b,)
        Highest and lowest grid row the camera sees per column (0 and ``n_e - 1`` in a column
        it does not see at all).
    grow_px : tuple of int
        Obstacle growth (horizontal, vertical) in pixels before resampling.
    first_read_px_row : ndarray of int64, shape (width_px,)
        Topmost image row per image column that can change what the grid reads: the rows it
        reads, widened by the obstacle growth ``grow_px`` (``height_px`` in a column that never
        matters). A side fisheye sees past the zenith, into the other camera's half-space,
        above it.
    grow_row_px : ndarray of int64, shape (height_px,), optional
        A panorama's (``equirect``) horizontal obstacle growth per image row, longitude
        wrapping: the widest gap between neighbouring samples reading that row. Near the image's
        pole (a rolled or pitched panorama puts it in the grid) neighbouring samples read pixels
        far apart in longitude but close in true angle; one growth for the whole image, sized
        there (and across the longitude seam, 719 px), erased every row holding an obstacle
        pixel. None: ``grow_px`` everywhere (frame cameras).
    """

    camera: CameraModel
    mount: Mount
    rel_az_deg: NDArray
    el_deg: NDArray
    map_u: NDArray = field(repr=False)
    map_v: NDArray = field(repr=False)
    pixel_index: NDArray = field(repr=False)
    first_seen_row: NDArray = field(repr=False)
    last_seen_row: NDArray = field(repr=False)
    grow_px: tuple[int, int] = (2, 1)
    first_read_px_row: NDArray | None = field(default=None, repr=False)
    grow_row_px: NDArray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.first_read_px_row is None:
            h, w = self.camera.height_px, self.camera.width_px
            idx = self.pixel_index[self.pixel_index >= 0].astype(np.int64)
            read = np.full(w, h, np.int64)
            np.minimum.at(read, idx % w, idx // w)
            # an obstacle pixel reaches a read one through the erosion by grow_px
            gx, gy = self.grow_px
            pad = np.concatenate([np.full(gx, h), read, np.full(gx, h)])
            near = np.min([pad[k : k + w] for k in range(2 * gx + 1)], axis=0)
            first = np.where(near < h, np.maximum(near - gy, 0), h).astype(np.int64)
            first.setflags(write=False)
            object.__setattr__(self, "first_read_px_row", first)

    @classmethod
    def build(
        cls,
        camera: CameraModel,
        mount: Mount,
        az_step_deg: float = 0.25,
        el_step_deg: float = 0.125,
        el_min_deg: float = -20.0,
        span_deg: float | None = None,
    ) -> Rectifier:
        """Precompute the resampling map.

        The obstacle growth is chosen from the sampling steps so that an obstacle one pixel
        wide always reaches a sample (the image scale is measured over the map). The grid
        spans the camera's half-space (relative azimuths -90 to 90), all round for a
        360-degree panorama (``equirect``: -180 to 180), or ``span_deg`` centred on the look
        direction (a side fisheye sees past the zenith, beyond its half-space).
        """
        if not (0 < az_step_deg <= 2 and 0 < el_step_deg <= 2):
            raise ValueError("az_step_deg and el_step_deg must be in (0, 2] degrees")
        if camera.model == "equirect" and az_step_deg > 1.0:
            # a review: at 2 deg, pitched 10 deg, pixels of the rows nearest the image's pole
            # reached no sample through the per-row growth (every step to 1 deg was checked)
            raise ValueError(
                f"az_step_deg must be <= 1 degree for a panorama (equirect), got {az_step_deg}"
            )
        if span_deg is not None and not 0.0 < span_deg <= 360.0:
            raise ValueError(f"span_deg must be in (0, 360] degrees, got {span_deg}")
        if span_deg is not None:
            span = float(span_deg)
        else:
            span = 360.0 if camera.model == "equirect" else 180.0
        n_b = round(span / az_step_deg)
        beta = -span / 2.0 + az_step_deg * (np.arange(n_b) + 0.5)
        el = np.arange(90.0 - el_step_deg / 2, el_min_deg, -el_step_deg)
        b, e = np.meshgrid(np.radians(beta), np.radians(el))
        # vehicle frame (x forward, y left, z up); compass angle from forward is beta - yaw
        gam = b - np.radians(mount.yaw_deg)
        d_veh = np.stack([np.cos(e) * np.cos(gam), -np.cos(e) * np.sin(gam), np.sin(e)], -1)
        d_cam = d_veh @ mount.camera_to_vehicle()  # (R^T d) row-wise
        u, v = camera.ray_to_pixel(d_cam)
        inside = camera.contains(u, v)
        u = np.where(inside, u, -10.0)
        v = np.where(inside, v, -10.0)
        # pixels between neighbouring samples, to size the obstacle growth
        du = np.abs(np.diff(u, axis=1))
        dv = np.abs(np.diff(v, axis=0))
        ok_u = inside[:, 1:] & inside[:, :-1]
        ok_v = inside[1:] & inside[:-1]
        grow_row = None
        if camera.model == "equirect":
            # longitude wraps: samples either side of the seam are neighbours; the gap in
            # pixels is taken per image row (the samples of both rows of a pair), for the
            # vertical neighbours too (near the image's pole they read far-apart columns)
            h_px, w_px = camera.shape
            du = np.minimum(du, w_px - du)
            dv_u = np.abs(np.diff(u, axis=0))
            dv_u = np.minimum(dv_u, w_px - dv_u)
            row = np.clip(np.floor(v + 0.5), 0, h_px - 1).astype(np.int64)
            gap_row = np.zeros(h_px)
            for gap, ok, ra, rb in ((du, ok_u, row[:, 1:], row[:, :-1]),
                                    (dv_u, ok_v, row[1:], row[:-1])):  # fmt: skip
                for r in (ra, rb):
                    np.maximum.at(gap_row, r[ok], gap[ok])
            grow_row = np.minimum(np.ceil(gap_row / 2.0), w_px).astype(np.int64)
            grow_row.setflags(write=False)
        gap_u = float(np.nanmax(np.where(ok_u, du, 0.0))) if ok_u.any() else 1.0
        gap_v = float(np.nanmax(np.where(ok_v, dv, 0.0))) if ok_v.any() else 1.0
        grow = (int(np.ceil(gap_u / 2.0)), int(np.ceil(gap_v / 2.0)))
        map_u, map_v = u.astype(np.float32), v.astype(np.float32)
        index = _remap_index(camera.shape, map_u, map_v)
        seen = index >= 0
        first = np.argmax(seen, axis=0)
        last = seen.shape[0] - 1 - np.argmax(seen[::-1], axis=0)
        for a in (index, first, last):
            a.setflags(write=False)
        return cls(
            camera, mount, beta, el, map_u, map_v, index, first, last, grow, grow_row_px=grow_row,
        )  # fmt: skip

    @property
    def look_offset_deg(self) -> float:
        """Azimuth of the look direction relative to the direction of travel (clockwise)."""
        return -self.mount.yaw_deg

    def _grown_labels(self, sky: NDArray) -> NDArray:
        """uint8 labels of a boolean sky mask (sky / obstacle), obstacles grown by ``grow_px``."""
        # the erosion is a minimum filter: eroding 0 / 1 and scaling gives the 0 / 255 erosion
        return self._grown_sky(sky) * np.uint8(_SKY)

    @cached_property
    def pixel_el_deg(self) -> NDArray:
        """Elevation above the local horizontal of every pixel centre's ray, degrees, shape
        ``camera.shape`` (camera model and mount; the vehicle's z is the vertical, so it does
        not depend on the heading). NaN for a pixel without a ray."""
        h, w = self.camera.shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        ray = self.camera.pixel_to_ray(u.ravel(), v.ravel()) @ self.mount.camera_to_vehicle().T
        el = np.degrees(np.arcsin(np.clip(ray[:, 2], -1.0, 1.0))).reshape(h, w)
        el.setflags(write=False)
        return el

    @cached_property
    def _pixel_el_flat(self) -> NDArray:
        """:attr:`pixel_el_deg` flattened (the grid's :attr:`pixel_index` indexes it)."""
        return np.ascontiguousarray(self.pixel_el_deg, np.float64).ravel()

    @cached_property
    def _pixel_runs(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """:attr:`pixel_index` down each grid column as runs of one pixel: the runs' first
        grid rows and pixels (flat, column after column), each column's first run (n_b + 1
        offsets) and the run holding its :attr:`first_seen_row`.

        Neighbouring grid rows often read the same pixel (1.8 rows per pixel on the demo's
        fisheye cameras): the top sky run's end is searched pixel by pixel.
        """
        return _index_runs(self.pixel_index, self.first_seen_row)

    def _grown_sky(self, sky: NDArray) -> NDArray:
        """A boolean sky mask as uint8 1 (sky) / 0, C-contiguous, obstacles grown by
        ``grow_px`` (a view of ``sky`` when nothing grows)."""
        img = np.ascontiguousarray(sky, np.bool_).view(np.uint8)
        gx, gy = self.grow_px
        if self.grow_row_px is None:
            return cv2.erode(img, np.ones((2 * gy + 1, 2 * gx + 1), np.uint8)) if gx or gy else img
        # a panorama: vertically by gy, then each row by its own reach, longitude wrapping
        col = cv2.erode(img, np.ones((2 * gy + 1, 1), np.uint8)) if gy else img.copy()
        w = img.shape[1]
        out = np.empty_like(col)
        for rx in np.unique(self.grow_row_px):
            rows = np.flatnonzero(self.grow_row_px == rx)
            rx = int(rx)
            if rx == 0:
                out[rows] = col[rows]
            elif 2 * rx + 1 >= w:
                out[rows] = col[rows].min(axis=1, keepdims=True)
            else:
                band = np.concatenate([col[rows][:, -rx:], col[rows], col[rows][:, :rx]], axis=1)
                k = np.ones((1, 2 * rx + 1), np.uint8)
                out[rows] = cv2.erode(band, k, borderType=cv2.BORDER_REPLICATE)[:, rx : rx + w]
        return out

    def rectify(self, sky_mask: ArrayLike) -> NDArray:
        """Grid labels (n_e, n_b) uint8: 255 sky, 0 obstacle, 128 not seen by the camera."""
        grown = self._grown_labels(_as_sky_mask(sky_mask, self.camera))
        return cv2.remap(
            grown, self.map_u, self.map_v, cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT, borderValue=_UNSEEN,
        )  # fmt: skip

    def profile(
        self,
        sky_mask: ArrayLike,
        heading_deg: float,
        reverse: bool = False,
        confidence: ArrayLike | None = None,
        min_confidence: float = 0.5,
        low_confidence_windows: float = 2.0,
        low_confidence_window_deg: float = LOW_CONFIDENCE_WINDOW_DEG,
        min_sky_el_deg: float = -np.inf,
        panorama_raise: str = "image",
    ) -> SkyProfile:
        """The frame's :class:`SkyProfile`.

        Parameters
        ----------
        sky_mask : array_like of bool, shape ``camera.shape``
        heading_deg : float
            Track heading at the frame, degrees.
        reverse : bool
            Train driving toward decreasing chainage.
        confidence : array_like, shape (width_px,), optional
            Per image column confidence of the segmentation (of its skyline).
        min_confidence : float
            Columns below it have their skyline raised: the lowest ``low_confidence_windows``
            confidence windows (:func:`predisat.sky.segment.confidence_window_px`, the rows
            either side of the skyline that the learned methods' confidence speaks for) of
            their top sky run become obstacle, with everything below. The sky above still
            clears: a fuzzy tree top on the horizon must not void a fisheye column through the
            zenith, which every azimuth's top sky run starts from.
        low_confidence_windows : float
            ``inf`` voids low-confidence columns from top to bottom (they clear nothing).
        low_confidence_window_deg : float
            For a panoramic (``"equirect"``) camera, a window is this angle of elevation
            instead of rows: a low-confidence column loses the sky pixels whose ray (camera
            model and mount) lies less than ``low_confidence_windows *
            low_confidence_window_deg`` above its skyline. A panorama's rows are a fixed angle
            each and its confidence comes from tiles (:func:`predisat.sky.panorama
            .segment_panorama`), not from its own height; frame cameras (pinhole, fisheye)
            keep windows of their own rows, where their confidence was computed.
        min_sky_el_deg : float
            A column whose top sky run reaches below this elevation is voided (clears
            nothing): no sky lies under the horizon, so the segmentation took an obstacle
            down to its foot for sky there (a white pier, a pale mast on a bright sky).
        panorama_raise : {"image", "grid"}
            Where a panorama's raise is taken. ``"image"`` (the default): down its image
            columns. On a canted vehicle those near the zenith rise to it and fall beyond it,
            and raising one whose top sky run a contact wire cut short near the zenith takes
            the zenith pixels, that every grid column starts from, with it: the whole frame
            clears nothing. ``"grid"``: on the grid's columns (level azimuths): a grid column
            is raised when a pixel it reads at its skyline or within the raise above it lies
            in a low image column (or within the obstacle growth of one), and each low image
            column's band within the raise above its own skyline, below 90 deg less the raise
            and away from the image's pole, ends the sky of every grid column that reads it
            (the doubt lies along the image columns). It keeps the zenith and recovers much of
            the panorama's sky, but the frames it no longer voids let a camera half a metre
            behind the antenna see past a cantilever over it (``docs/rigs.md``: one position
            trusted 6.8 % of its directions falsely), so it is opt-in. Frame cameras ignore it.
        """
        m = _as_sky_mask(sky_mask, self.camera)
        low_px = doubt_px = None
        if confidence is not None:
            c = np.asarray(confidence, float)
            if c.shape != (self.camera.width_px,):
                raise ValueError(
                    f"confidence must have shape ({self.camera.width_px},) (one per column)"
                )
            if not low_confidence_windows >= 0:
                raise ValueError(
                    f"low_confidence_windows must be >= 0 (inf voids the column), got "
                    f"{low_confidence_windows}"
                )
            if not low_confidence_window_deg > 0:
                raise ValueError(
                    f"low_confidence_window_deg must be > 0 degrees, got "
                    f"{low_confidence_window_deg}"
                )
            if panorama_raise not in ("image", "grid"):
                raise ValueError(
                    f"panorama_raise must be 'image' or 'grid', got {panorama_raise!r}"
                )
            low = np.flatnonzero(~(c >= min_confidence))  # NaN confidence counts as low
            if low.size and self.camera.model == "equirect" and panorama_raise == "image":
                m = _raise_skyline_deg(
                    m, low, low_confidence_windows * low_confidence_window_deg,
                    self.pixel_el_deg, self.first_read_px_row,
                )  # fmt: skip
            elif low.size and self.camera.model == "equirect":
                # raised below, on the grid's columns (a canted panorama's image columns cross
                # the zenith that every grid column starts from); the low columns grown as the
                # obstacles are, as the raised sky was when the image itself was raised
                conf_ok = np.broadcast_to(c >= min_confidence, self.camera.shape)
                low_px = (self._grown_sky(conf_ok) == 0).ravel()
                # the segmenter's doubt lies along its image columns (its tiles' confidence is
                # measured down them): the band of each low column's top sky run within the
                # raise above its own skyline is no sky either, for the grid columns that read
                # it at other azimuths of a canted panorama (a review: 7 843 such grid cells
                # trusted at roll 7 deg); below 90 deg less the raise only, where a level
                # azimuth's raise voids its column anyway and the zenith is not taken with it
                raise_deg = float(low_confidence_windows * low_confidence_window_deg)
                doubt_px = _doubt_band(m, low, raise_deg, self.pixel_el_deg,
                                       self.first_read_px_row, 90.0 - raise_deg).ravel()
            elif low.size:
                h = self.camera.height_px
                band, gap = confidence_window_px(h)
                m = _raise_skyline(
                    m, low, round(min(low_confidence_windows * (band + gap), h)),
                    self.first_read_px_row,
                )  # fmt: skip
        # The top sky run, read through the remap's own pixel choice (the same grid labels as
        # :meth:`rectify`, as 1 sky / 0 obstacle) down to its end only, instead of resampling
        # the whole grid.
        grown = self._grown_sky(m)
        top, last_seen = self.first_seen_row, self.last_seen_row
        any_seen = self.pixel_index[top, np.arange(top.size)] >= 0
        n_e = self.el_deg.size
        end = _top_sky_run_end(grown.ravel(), *self._pixel_runs, top, n_e, 1)
        if low_px is not None:
            end = _raise_grid_runs(
                end, top, self.pixel_index, self._pixel_el_flat, low_px,
                float(low_confidence_windows * low_confidence_window_deg),
            )  # fmt: skip
            assert doubt_px is not None
            end = _stop_at_pixels(end, top, self.pixel_index, doubt_px)
        has_sky = any_seen & (end > top)
        sky_el = np.where(has_sky, self.el_deg[np.clip(end - 1, 0, n_e - 1)], np.inf)
        voided = sky_el < min_sky_el_deg  # sky under the horizon: a mislabelled column
        sky_el[voided] = np.inf
        lo = np.where(any_seen, self.el_deg[last_seen], np.nan)
        hi = np.where(any_seen, self.el_deg[top], np.nan)
        fwd = float(heading_deg) + (180.0 if reverse else 0.0)
        look = float(np.mod(fwd + self.look_offset_deg, 360.0))
        return SkyProfile(self.rel_az_deg, sky_el, lo, hi, look, voided)


def _raise_skyline(
    sky: NDArray, cols: NDArray, raise_px: int, from_row: NDArray | None = None
) -> NDArray:
    """Copy of ``sky`` whose columns ``cols`` lose the lowest ``raise_px`` rows of their top
    sky run, and every sky pixel below it.

    The run is searched from ``from_row`` (per image column, default 0) down: the rows above
    it, which the rectification grid never reads (a side fisheye's view past the zenith), are
    left as they are. Otherwise a sliver of sky above an obstacle seen past the zenith would
    be "the top run", and the whole sky below it in the camera's own half-space would go.
    """
    out = np.array(sky, np.bool_)  # a C-contiguous copy
    c = np.unique(np.asarray(cols, np.int64))
    top = np.zeros(c.size, np.int64) if from_row is None else np.asarray(from_row, np.int64)[c]
    _raise_columns(out, c, top, int(raise_px))
    return out


def _raise_skyline_deg(
    sky: NDArray,
    cols: NDArray,
    raise_deg: float,
    el_deg: NDArray,
    from_row: NDArray | None = None,
) -> NDArray:
    """As :func:`_raise_skyline` with the raise as an angle: the top sky run of each column
    of ``cols`` loses its lowest pixels whose elevation ``el_deg`` (H, W) lies less than
    ``raise_deg`` above the skyline's (the top edge of the first obstacle pixel, halfway
    between the two pixels' elevations; the last sky pixel's for a column sky to the bottom),
    and every sky pixel below. ``inf`` voids the whole run; ``from_row`` as there."""
    out = np.array(sky, np.bool_)
    c = np.unique(np.asarray(cols, np.int64))
    top = np.zeros(c.size, np.int64) if from_row is None else np.asarray(from_row, np.int64)[c]
    _raise_columns_deg(out, c, top, np.asarray(el_deg, np.float64), float(raise_deg))
    return out


@njit(cache=True, nogil=True)
def _top_run(sky: NDArray, el_deg: NDArray, c: int, from_row: int) -> tuple[int, int, float]:
    """Column ``c``'s top sky run searched from ``from_row``: its first and past-the-last
    rows, and its skyline's elevation (halfway between the last sky pixel's and the first
    obstacle pixel's; the last sky pixel's for a run to the bottom; NaN without a run)."""
    n = sky.shape[0]
    start = max(from_row, 0)
    while start < n and not sky[start, c]:
        start += 1
    end = start
    while end < n and sky[end, c]:
        end += 1
    if end == start:
        return start, end, np.nan
    e0 = el_deg[end - 1, c]
    return start, end, 0.5 * (e0 + el_deg[end, c]) if end < n else e0


@njit(cache=True, nogil=True)
def _raise_columns_deg(
    sky: NDArray, cols: NDArray, top: NDArray, el_deg: NDArray, raise_deg: float
) -> None:
    """:func:`_raise_skyline_deg` in place (pixels up the run while within the angle)."""
    n = sky.shape[0]
    for k in range(cols.size):
        c = cols[k]
        start, end, base = _top_run(sky, el_deg, c, top[k])
        if end == start:  # no sky run: only sky below, which goes
            cut = start
        else:
            cut = end
            # a NaN elevation counts as within the angle (the safe side: more goes)
            while cut > start and not el_deg[cut - 1, c] - base >= raise_deg:
                cut -= 1
        for r in range(cut, n):
            sky[r, c] = False


def _doubt_band(
    sky: NDArray, cols: NDArray, raise_deg: float, el_deg: NDArray, from_row: NDArray | None,
    cap_deg: float,
) -> NDArray:  # fmt: skip
    """A panorama's doubt down its low image columns: the pixels of each column of ``cols``'
    top sky run (searched from ``from_row``) less than ``raise_deg`` above the run's skyline
    both in elevation (as the raise down an image column was taken until 2026-12-07) and in
    arc along the column (its rows), under ``cap_deg`` of elevation and at least twice the
    raise from the image's pole (there the columns converge and turn across every azimuth,
    and the level azimuths' raise alone speaks): bool, ``sky``'s shape."""
    out = np.zeros(np.shape(sky), np.bool_)
    c = np.unique(np.asarray(cols, np.int64))
    top = np.zeros(c.size, np.int64) if from_row is None else np.asarray(from_row, np.int64)[c]
    _doubt_columns(np.ascontiguousarray(sky, np.bool_), out, c, top,
                   np.asarray(el_deg, np.float64),
                   float(raise_deg), float(cap_deg))  # fmt: skip
    return out


@njit(cache=True, nogil=True)
def _doubt_columns(
    sky: NDArray, out: NDArray, cols: NDArray, top: NDArray, el_deg: NDArray,
    raise_deg: float, cap_deg: float,
) -> None:  # fmt: skip
    n = sky.shape[0]
    row_deg = 180.0 / n  # an equirectangular image's rows
    for k in range(cols.size):
        c = cols[k]
        start, end, base = _top_run(sky, el_deg, c, top[k])
        if end == start:
            continue
        r = end
        # within the angle of elevation and of arc along the column (a column turning over
        # near the zenith stays within the angle of elevation far beyond it)
        while r > start and not el_deg[r - 1, c] - base >= raise_deg and (
                (end - r + 0.5) * row_deg < raise_deg):
            r -= 1
            # NaN counts as under the cap; near the image's pole the columns converge and turn
            # across every azimuth: the level azimuths' raise alone speaks there
            if not el_deg[r, c] >= cap_deg and (r + 0.5) * row_deg >= 2.0 * raise_deg:
                out[r, c] = True


@njit(cache=True, nogil=True)
def _stop_at_pixels(end: NDArray, top: NDArray, pixel_index: NDArray, stop_px: NDArray) -> NDArray:
    """``end`` (per grid column) moved up to the first row from ``top`` reading a pixel of
    ``stop_px`` (flat bool)."""
    out = end.copy()
    for b in range(end.size):
        for r in range(top[b], end[b]):
            k = pixel_index[r, b]
            if k >= 0 and stop_px[k]:
                out[b] = r
                break
    return out


@njit(cache=True, nogil=True)
def _raise_grid_runs(
    end: NDArray, top: NDArray, pixel_index: NDArray, el_flat: NDArray, low_px: NDArray,
    raise_deg: float,
) -> NDArray:  # fmt: skip
    """A panorama's low-confidence raise on the grid's columns: ``end`` (per grid column, the
    first grid row after the top sky run, which starts at ``top``) moved up past the rows
    whose pixel's elevation (``el_flat``, by the flat ``pixel_index``) lies less than
    ``raise_deg`` above the skyline (halfway between the last sky pixel's and the first
    obstacle pixel's elevations; the last sky pixel's where the run reaches the grid's bottom
    or an unseen sample), as :func:`_raise_columns_deg` does down an image column. Only the
    grid columns whose skyline pixels, or a pixel within the raise above them, are low
    (``low_px``, flat bool per pixel) move; ``end <= top`` then: no sky."""
    n_e, n_b = pixel_index.shape
    out = end.copy()
    for b in range(n_b):
        t, e = top[b], end[b]
        if e <= t:
            continue
        k_sky = pixel_index[e - 1, b]
        if k_sky < 0:
            continue
        e0 = el_flat[k_sky]
        low = low_px[k_sky]
        base = e0
        if e < n_e:
            k_obs = pixel_index[e, b]
            if k_obs >= 0:
                base = 0.5 * (e0 + el_flat[k_obs])
                low = low or low_px[k_obs]
        cut = e
        # a NaN elevation counts as within the angle (the safe side: more goes)
        while cut > t:
            k = pixel_index[cut - 1, b]
            if k >= 0 and el_flat[k] - base >= raise_deg:
                break
            if k >= 0 and low_px[k]:
                low = True
            cut -= 1
        if low:
            out[b] = cut
    return out


@njit(cache=True, nogil=True)
def _raise_columns(sky: NDArray, cols: NDArray, top: NDArray, raise_px: int) -> None:
    """:func:`_raise_skyline` in place: in each column ``cols[k]``, the top sky run searched
    from row ``top[k]`` loses its lowest ``raise_px`` rows, and every row below it its sky."""
    n = sky.shape[0]
    for k in range(cols.size):
        c = cols[k]
        start = max(top[k], 0)  # first sky row read
        while start < n and not sky[start, c]:
            start += 1
        end = start  # first obstacle row after it
        while end < n and sky[end, c]:
            end += 1
        for r in range(max(end - raise_px, start), n):
            sky[r, c] = False


def _remap_index(shape: tuple[int, int], map_u: NDArray, map_v: NDArray) -> NDArray:
    """Flat pixel index ``cv2.remap`` (nearest) reads at each map entry; -1 outside the image."""
    h, w = shape
    cols, rows = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    # float32 holds pixel coordinates exactly (below 2**24)
    src = np.ascontiguousarray(np.stack([cols, rows], axis=-1))
    got = cv2.remap(
        src, map_u, map_v, cv2.INTER_NEAREST,
        borderMode=cv2.BORDER_CONSTANT, borderValue=(-1.0, -1.0, 0.0, 0.0),
    )  # fmt: skip
    idx = got[..., 1].astype(np.int64) * w + got[..., 0].astype(np.int64)
    return np.where(got[..., 0] >= 0, idx, -1).astype(np.int32)


def _index_runs(pixel_index: NDArray, top: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Runs of equal entries down each column of ``pixel_index`` (n_e, n_b): their first rows
    and values (flat, column after column), the columns' run offsets (n_b + 1) and, per
    column, the run holding row ``top[b]``."""
    cols = np.ascontiguousarray(np.asarray(pixel_index).T)  # (n_b, n_e)
    start = np.ones(cols.shape, bool)
    start[:, 1:] = cols[:, 1:] != cols[:, :-1]
    b, r = np.nonzero(start)  # column by column, rows ascending
    offsets = np.concatenate([[0], np.cumsum(start.sum(axis=1))]).astype(np.int64)
    upto = start & (np.arange(cols.shape[1])[None, :] <= np.asarray(top)[:, None])
    top_run = offsets[:-1] + upto.sum(axis=1) - 1  # the last run starting at or above it
    return r.astype(np.int64), cols[b, r].astype(np.int64), offsets, top_run


@njit(cache=True, nogil=True)
def _top_sky_run_end(
    grown: NDArray, run_row: NDArray, run_pixel: NDArray, offsets: NDArray, top_run: NDArray,
    top: NDArray, n_e: int, sky_label: int = _SKY,
) -> NDArray:  # fmt: skip
    """First grid row at or below ``top`` (per column) whose label is not sky; ``n_e`` if none.

    ``grown`` is the flattened label image (sky ``sky_label``); the grid's pixel index comes
    as runs (:attr:`Rectifier._pixel_runs`): column ``b``'s runs are ``offsets[b]`` to
    ``offsets[b + 1]``, run ``top_run[b]`` holds row ``top[b]``, pixel -1 is unseen (not sky).
    A run's rows read one pixel, so the first run that is not sky ends the sky run at its
    first row (at ``top`` itself for the run holding it).
    """
    n_b = top.size
    end = np.empty(n_b, np.int64)
    for b in range(n_b):
        e = n_e
        for j in range(top_run[b], offsets[b + 1]):
            k = run_pixel[j]
            if k < 0 or grown[k] != sky_label:
                e = max(run_row[j], top[b])
                break
        end[b] = e
    return end
