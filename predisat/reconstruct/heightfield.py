"""A conservative 2.5-D corridor height field carved free by sky rays.

The corridor around the track is a raster of square cells in the track frame's horizontal
plane (cell edges at multiples of ``cell_m`` in frame east/north, the same for every chunk, so
chunks agree exactly). Each cell holds an *upper bound* of the height (frame ``z``, metres) of
anything standing in it; ``+inf`` means nothing is known. Under the 2.5-D model every obstacle is
a column standing on the ground, so a sky ray that passes over a point proves that the column
there is lower than the ray. Each frame contributes, for each cell, the *highest* skyline-ray
height over the whole cell (so thin obstacles are never carved away between rays), and the cell
keeps the lowest contribution of all frames.

Overhangs (bridge decks, canopies, crowns) become solid columns: safe, since sky seen under an
overhang is never used (see :mod:`predisat.reconstruct.skyline`). The space between the two cameras
is never
seen by a side camera; a prior fills it (see :func:`apply_clearance_prior`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numba import njit
from numpy.typing import NDArray

from predisat.reconstruct.skyline import SkyProfile
from predisat.track import TrackMap

__all__ = [
    "HeightField",
    "LowestBounds",
    "RangeMax1D",
    "ThinRule",
    "UnseenRule",
    "apply_clearance_prior",
    "carve_box",
    "carve_profile",
    "corridor_grid",
    "sweep_along_track",
]


class RangeMax1D:
    """Maximum over index ranges ``[lo, hi]`` of a 1-D array, O(1) per query (sparse table).

    NaN entries propagate (``np.fmax`` is *not* used) so that a range touching an unknown
    entry is unknown.
    """

    def __init__(self, values: NDArray) -> None:
        v = np.asarray(values, float)
        levels = [v]
        k = 1
        while 2 * k <= v.size:
            prev = levels[-1]
            levels.append(np.maximum(prev[: prev.size - k], prev[k:]))
            k *= 2
        self._levels = levels
        self.size = v.size

    def query(self, lo: NDArray, hi: NDArray) -> NDArray:
        """Maximum over ``values[lo:hi + 1]`` (``lo <= hi``, both within the array)."""
        lo = np.asarray(lo, np.int64)
        hi = np.asarray(hi, np.int64)
        n = hi - lo + 1
        k = np.floor(np.log2(np.maximum(n, 1))).astype(np.int64)
        out = np.empty(lo.shape, float)
        for level in np.unique(k):
            sel = k == level
            tab = self._levels[int(level)]
            out[sel] = np.maximum(tab[lo[sel]], tab[hi[sel] - (1 << int(level)) + 1])
        return out


@dataclass(frozen=True, eq=False)
class HeightField:
    """Upper bounds of obstacle height over a corridor raster.

    Attributes
    ----------
    cell_m : float
        Cell size; cell ``(row, col)`` covers frame ``x`` in ``[(ix0 + col) * cell_m, +cell_m)``
        and ``y`` in ``[(iy0 + row) * cell_m, +cell_m)``.
    ix0, iy0 : int
        Global index of the raster's first column and row.
    bound_m : ndarray of float32, shape (ny, nx)
        Upper bound of the obstacle top, frame ``z`` metres; ``+inf`` unknown.
    region : ndarray of bool, shape (ny, nx)
        Cells within ``half_width_m`` of the track axis in the modelled chainage range.
    chainage_m, offset_m : ndarray of float32, shape (ny, nx)
        Track chainage and left offset of each cell centre (NaN outside the region).
    rail_z_m : ndarray of float32, shape (ny, nx)
        Frame ``z`` of the rail at the cell's chainage.
    overhead_m : ndarray of float, shape (k, 2)
        Chainage intervals where an overhead structure was detected.
    camera_ceilings : ndarray of float, shape (m, 4)
        The ``camera_ceilings`` rows :func:`apply_clearance_prior` was given (none: empty).
    views : ndarray of int32, shape (ny, nx), or None
        Independent views (frames, or frames sharing a view group) whose rays bounded each
        cell's carved bound; 0 where no view did or where a prior set the bound (``None``:
        not counted).
    resolved : ndarray of bool, shape (ny, nx), or None
        Cells the mast rule raised (``ReconstructionParams.resolve_width_m``,
        :func:`predisat.reconstruct.carving._resolving_bounds`): far frames' sky passed over
        them, frames near enough to see a mast there bounded them higher; the far field's cap
        leaves them (up to a mast's height). ``None``: the rule did not apply.
    """

    cell_m: float
    ix0: int
    iy0: int
    bound_m: NDArray = field(repr=False)
    region: NDArray = field(repr=False)
    chainage_m: NDArray = field(repr=False)
    offset_m: NDArray = field(repr=False)
    rail_z_m: NDArray = field(repr=False)
    overhead_m: NDArray = field(default_factory=lambda: np.zeros((0, 2)))
    camera_ceilings: NDArray = field(default_factory=lambda: np.zeros((0, 4)))
    views: NDArray | None = field(default=None, repr=False)
    resolved: NDArray | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        ny, nx = self.bound_m.shape
        return int(ny), int(nx)

    def index(self, x_m: NDArray, y_m: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """Row, column and in-raster flag of frame points ``(x_m, y_m)``."""
        col = np.floor(np.asarray(x_m) / self.cell_m).astype(np.int64) - self.ix0
        row = np.floor(np.asarray(y_m) / self.cell_m).astype(np.int64) - self.iy0
        ny, nx = self.shape
        ok = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
        return np.where(ok, row, 0), np.where(ok, col, 0), ok


def corridor_grid(
    track: TrackMap,
    lo_m: float,
    hi_m: float,
    half_width_m: float,
    cell_m: float,
    seg_m: float = 2.0,
) -> HeightField:
    """An empty (all unknown) height field over the corridor ``[lo_m, hi_m]`` x ``+-half_width``.

    The track axis is cut in ``seg_m`` pieces; each piece's quadrilateral is rasterised with its
    index, which gives every cell its chainage and offset by a local projection.
    """
    lo, hi = max(0.0, float(lo_m)), min(float(track.length_m), float(hi_m))
    if not hi > lo:
        raise ValueError(f"corridor [{lo_m}, {hi_m}] m does not overlap the track")
    s = np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / seg_m)) + 1))
    p = np.asarray(track.enu_at(s), float)
    t = np.asarray(track.tangent_at(s), float)[:, :2]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    left = np.stack([-t[:, 1], t[:, 0]], axis=1)
    w = float(half_width_m)
    # extend the ends a little so that end cells are covered
    ends = np.concatenate([p[:, :2] + w * left, p[:, :2] - w * left])
    ix0 = int(np.floor(ends[:, 0].min() / cell_m)) - 2
    iy0 = int(np.floor(ends[:, 1].min() / cell_m)) - 2
    nx = int(np.ceil(ends[:, 0].max() / cell_m)) + 2 - ix0
    ny = int(np.ceil(ends[:, 1].max() / cell_m)) + 2 - iy0
    label = np.full((ny, nx), -1, np.int32)
    shift = 4
    scale = float(1 << shift)

    def px(xy: NDArray) -> NDArray:  # frame metres -> cv2 fixed-point pixel coordinates
        return np.round(
            (np.stack([xy[..., 0] / cell_m - ix0 - 0.5, xy[..., 1] / cell_m - iy0 - 0.5], -1))
            * scale
        ).astype(np.int32)

    quads = np.stack(
        [
            p[:-1, :2] + w * left[:-1],
            p[1:, :2] + w * left[1:],
            p[1:, :2] - w * left[1:],
            p[:-1, :2] - w * left[:-1],
        ],
        axis=1,
    )
    q_px = px(quads)
    for k in range(q_px.shape[0]):
        cv2.fillConvexPoly(label, q_px[k], int(k), lineType=cv2.LINE_8, shift=shift)
    region = label >= 0
    rows, cols = np.nonzero(region)
    seg = label[rows, cols]
    cx = (ix0 + cols + 0.5) * cell_m
    cy = (iy0 + rows + 0.5) * cell_m
    d = np.stack([cx - p[seg, 0], cy - p[seg, 1]], axis=1)
    ch = s[seg] + np.sum(d * t[seg], axis=1)
    off = np.sum(d * left[seg], axis=1)
    keep = (np.abs(off) <= w) & (ch >= lo) & (ch <= hi)
    region[rows[~keep], cols[~keep]] = False
    chain = np.full((ny, nx), np.nan, np.float32)
    offset = np.full((ny, nx), np.nan, np.float32)
    chain[rows, cols] = ch
    offset[rows, cols] = off
    rail = np.full((ny, nx), np.nan, np.float32)
    rail[rows, cols] = np.interp(ch, s, p[:, 2])
    chain[~region] = np.nan
    offset[~region] = np.nan
    bound = np.full((ny, nx), np.inf, np.float32)
    return HeightField(float(cell_m), ix0, iy0, bound, region, chain, offset, rail)


def carve_box(hf: HeightField, camera_m: NDArray, range_m: float) -> tuple[int, int, int, int]:
    """Rows ``[r0, r1)`` and columns ``[c0, c1)`` of ``hf``'s raster that :func:`carve_profile`
    may lower for a camera at ``camera_m`` (track frame, metres) carving to ``range_m``
    (empty when ``r1 <= r0`` or ``c1 <= c0``)."""
    c = hf.cell_m
    ny, nx = hf.shape
    cx, cy = float(camera_m[0]), float(camera_m[1])
    c0 = max(int(np.floor((cx - range_m) / c)) - hf.ix0, 0)
    c1 = min(int(np.ceil((cx + range_m) / c)) - hf.ix0, nx)
    r0 = max(int(np.floor((cy - range_m) / c)) - hf.iy0, 0)
    r1 = min(int(np.ceil((cy + range_m) / c)) - hf.iy0, ny)
    return r0, r1, c0, c1


class LowestBounds:
    """Fault-tolerant fusion of the frames' bounds: per cell, the ``rank`` lowest bounds of
    independent views, the view being a frame or a group of frames (``docs/reconstruction.md``,
    section 2, fault model).

    A view's bound is a view's own lowest bound over the cell (a group's frames may share a
    fault, such as dirt on one camera's lens: their lowest counts once). The fused bound of a
    cell is the ``min(rank, n)``-th lowest of the ``n`` views that bounded it: the highest of
    them when fewer than ``rank`` did. It is an upper bound of the true top whenever fewer
    than ``min(rank, n)`` of those views are below the truth; ``rank = 1`` is the lowest
    bound, the plain carving.

    Parameters
    ----------
    shape : (int, int)
        The raster's ``(ny, nx)``.
    rank : int
        Views that must agree before a cell is lowered (>= 1).
    """

    def __init__(self, shape: tuple[int, int], rank: int) -> None:
        if rank < 1:
            raise ValueError(f"rank must be >= 1 (1: the lowest bound), got {rank}")
        self.rank = int(rank)
        self._low = np.full((self.rank, *shape), np.inf, np.float32)
        self._views = np.zeros(shape, np.int32)

    def add(self, view_bound: NDArray, box: tuple[int, int, int, int]) -> None:
        """Add one view: ``view_bound`` (the raster's shape, ``+inf`` where the view bounded
        nothing) within the rows and columns ``box = (r0, r1, c0, c1)``; elsewhere it must
        be ``+inf``."""
        r0, r1, c0, c1 = box
        if r1 > r0 and c1 > c0:
            _insert_lowest(self._low, self._views, view_bound, r0, r1, c0, c1)

    @property
    def views(self) -> NDArray:
        """Number of views that bounded each cell (int32, the raster's shape)."""
        return self._views.copy()

    def lowest(self, k: int) -> NDArray:
        """The ``k``-th lowest bound of every cell (``1 <= k <= rank``; float32, ``+inf``
        where fewer than ``k`` views bounded it)."""
        if not 1 <= k <= self.rank:
            raise ValueError(f"k must lie in [1, {self.rank}], got {k}")
        return self._low[k - 1].copy()

    def fused(self) -> NDArray:
        """The fused bound of every cell (float32, ``+inf`` where no view bounded it)."""
        k = np.minimum(self._views, self.rank) - 1
        out = np.take_along_axis(self._low, np.maximum(k, 0)[None], axis=0)[0]
        return np.where(k >= 0, out, np.float32(np.inf)).astype(np.float32)


@njit(cache=True, nogil=True)
def _insert_lowest(
    low: NDArray, views: NDArray, value: NDArray, r0: int, r1: int, c0: int, c1: int
) -> None:
    """Insert each finite ``value[r, c]`` of the box into the sorted ``low[:, r, c]`` (the
    ``rank`` lowest so far) and count it in ``views``."""
    k = low.shape[0]
    for r in range(r0, r1):
        for c in range(c0, c1):
            v = value[r, c]
            if not v < np.inf:
                continue
            views[r, c] += 1
            if v >= low[k - 1, r, c]:
                continue
            i = k - 1
            while i > 0 and low[i - 1, r, c] > v:
                low[i, r, c] = low[i - 1, r, c]
                i -= 1
            low[i, r, c] = v


def carve_profile(
    hf: HeightField,
    bound: NDArray,
    profile: SkyProfile,
    camera_m: NDArray,
    local_to_frame: NDArray,
    range_m: float,
    seen: NDArray | None = None,
    solid: SkyProfile | None = None,
    thin_rule: ThinRule | None = None,
    unseen_rule: UnseenRule | None = None,
    position_doubt_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> int:
    """Lower the bounds of ``bound`` (``hf``'s raster, updated in place) with one frame.

    Parameters
    ----------
    hf : HeightField
        Geometry of the raster (``bound`` is its working copy).
    bound : ndarray of float32, shape ``hf.shape``
        Working bounds, lowered in place.
    profile : SkyProfile
        The frame's sky profile.
    camera_m : ndarray, shape (3,)
        Camera centre in the track frame.
    local_to_frame : ndarray, shape (3, 3)
        Rotation from the local ENU at the frame into the track frame.
    range_m : float
        Cells beyond this horizontal distance from the camera are left alone.
    seen : ndarray of bool, shape ``hf.shape``, optional
        Set True (in place) at every cell the frame bounded.
    solid : SkyProfile, optional
        The frame's profile with its thin-structure pixels as obstacles (``profile`` counts
        them as sky). With ``thin_rule``, a cell takes ``profile``'s bound only where every
        thin feature the rays to it may cross is transparent (:class:`ThinRule`), else
        ``solid``'s.
    thin_rule : ThinRule, optional
    unseen_rule : UnseenRule, optional
        The frame bounds no clearance cell where an arm its sky may hide unflagged could be
        opaque (:class:`UnseenRule`).
    position_doubt_m : tuple of 3 float
        How far the true camera centre may be from ``camera_m`` along the frame's x, y and z
        (an attitude known only within a doubt, :func:`~predisat.camera.models.tilt_doubt_m`),
        metres. Each cell then takes the highest ray over the cell grown by the first two on
        its sides, raised by the third: a bound that holds from every centre within the doubt
        (``docs/reconstruction.md``, section 16).

    Returns
    -------
    int
        Number of cells the frame bounded.
    """
    c = hf.cell_m
    cx, cy, cz = (float(v) for v in camera_m)
    r0, r1, c0, c1 = carve_box(hf, camera_m, range_m)
    if c1 <= c0 or r1 <= r0:
        return 0
    rot = np.asarray(local_to_frame, float)
    xl = (hf.ix0 + np.arange(c0, c1 + 1)) * c - cx  # lattice (cell corners)
    yl = (hf.iy0 + np.arange(r0, r1 + 1)) * c - cy
    region = hf.region[r0:r1, c0:c1]
    b_axis = profile.rel_az_deg
    # Azimuth and range only of the corners that can matter: those of modelled cells, neither
    # clearly beyond range_m nor clearly outside the profile's azimuths (1 deg and a column
    # of margin), typically a quarter of the lattice. Every other corner of a modelled cell
    # makes the kernel skip that cell whatever its azimuth; it gets an infinite range, which
    # makes the kernel skip it too. The azimuths and ranges computed are the same numpy
    # operations on the same values, element for element.
    half_deg = max(abs(float(b_axis[0])), abs(float(b_axis[-1]))) + abs(
        float(b_axis[1] - b_axis[0])
    ) + 1.0
    look = np.radians(profile.look_az_deg)
    pads = np.asarray(position_doubt_m, float)
    if pads.shape != (3,) or not np.all(np.isfinite(pads) & (pads >= 0.0)):
        raise ValueError(
            f"position_doubt_m must be three distances >= 0 metres (x, y, z), got {pads}"
        )
    pad_x, pad_y, pad_z = (float(v) for v in pads)
    region_c = np.ascontiguousarray(region)

    def lattice(dx: float, dy: float) -> tuple[NDArray, NDArray]:
        idx, e, n = _carve_corners(
            xl + dx, yl + dy, region_c, float(rot[0, 0]), float(rot[1, 0]),
            float(rot[0, 1]), float(rot[1, 1]), float(np.sin(look)), float(np.cos(look)),
            float(np.cos(np.radians(half_deg))) if half_deg < 180.0 else -2.0, float(range_m),
        )  # fmt: skip
        # arctan2 and hypot stay numpy's (its vectorised arctan2 differs from libm's in the
        # last bit); degrees, offset and modulo are exact arithmetic, done where corners land
        return _corner_lattice(
            idx, np.arctan2(e, n), np.hypot(e, n), float(profile.look_az_deg), yl.size, xl.size
        )

    # With a doubt, the corners of each grown cell come from four shifted lattices: its low
    # x and y edges moved by -pad_x and -pad_y, its high edges by +pad_x and +pad_y.
    same = pad_x == 0.0 and pad_y == 0.0
    beta, rho = lattice(-pad_x, -pad_y)
    beta_x, rho_x = (beta, rho) if same else lattice(pad_x, -pad_y)
    beta_y, rho_y = (beta, rho) if same else lattice(-pad_x, pad_y)
    beta_xy, rho_xy = (beta, rho) if same else lattice(pad_x, pad_y)
    tan_sky = np.tan(np.radians(np.where(np.isfinite(profile.sky_el_deg), profile.sky_el_deg, 0.0)))
    tan_sky = np.where(np.isfinite(profile.sky_el_deg), tan_sky, np.inf)
    tan_solid = tan_sky
    rule = (0.0, 0.0, 0.0, 0.0)
    if solid is not None and thin_rule is not None and thin_rule.width_rad > 0:
        el = solid.sky_el_deg
        tan_solid = np.where(np.isfinite(el), np.tan(np.radians(np.where(np.isfinite(el), el,
                                                                         0.0))), np.inf)
        rule = (thin_rule.width_rad, thin_rule.k2_m, thin_rule.clearance_m,
                thin_rule.camera_offset_m)  # fmt: skip
    with np.errstate(invalid="ignore"):
        off = np.ascontiguousarray(np.nan_to_num(hf.offset_m[r0:r1, c0:c1], nan=0.0), np.float64)
    up = rot[:, 2]
    # the local horizontal plane is tilted in the frame (far from its origin): a centre moved
    # by (pad_x, pad_y) moves the kernel's tilt term too
    pad_z += (abs(float(up[0])) * pad_x + abs(float(up[1])) * pad_y) / float(up[2])
    marks = np.zeros((r1 - r0, c1 - c0), np.bool_) if seen is None else seen[r0:r1, c0:c1]
    return int(_carve_cells(
        beta, rho, beta_x, rho_x, beta_y, rho_y, beta_xy, rho_xy, pad_x, pad_y, pad_z, region,
        bound[r0:r1, c0:c1], float(b_axis[0]), float(b_axis[1] - b_axis[0]), float(range_m),
        np.ascontiguousarray(tan_sky, np.float64), xl, yl, float(c), cz,
        float(up[0]), float(up[1]), float(up[2]), marks,
        np.ascontiguousarray(tan_solid, np.float64), off, *rule,
        *((0.0, 0.0, 0.0, 0.0) if unseen_rule is None else (
            unseen_rule.width_rad, unseen_rule.k2_m, unseen_rule.clearance_m,
            unseen_rule.half_width_m)),
    ))  # fmt: skip


@njit(cache=True, nogil=True)
def _carve_corners(
    xl: NDArray, yl: NDArray, region: NDArray, r00: float, r10: float, r01: float, r11: float,
    sin_look: float, cos_look: float, cos_half: float, range_m: float,
) -> tuple[NDArray, NDArray, NDArray]:  # fmt: skip
    """Lattice corners whose azimuth and range :func:`_carve_cells` may need: flat indices
    into the ``(yl.size, xl.size)`` lattice and the corners' local east and north.

    A corner is needed when it is a corner of a ``region`` cell, not beyond ``range_m`` (by
    more than a rounding margin) and not at more than the angle of cosine ``cos_half`` from
    the look direction ``(sin_look, cos_look)``. ``e`` and ``n`` are computed as numpy
    computes ``r00 * dx + r10 * dy`` and ``r01 * dx + r11 * dy`` on the meshgrid.
    """
    n_r, n_c = region.shape
    used = np.zeros((n_r + 1, n_c + 1), np.bool_)
    for i in range(n_r):
        for j in range(n_c):
            if region[i, j]:
                used[i, j] = True
                used[i, j + 1] = True
                used[i + 1, j] = True
                used[i + 1, j + 1] = True
    size = (n_r + 1) * (n_c + 1)
    idx = np.empty(size, np.int64)
    e_out = np.empty(size)
    n_out = np.empty(size)
    far2 = (range_m * (1.0 + 1e-9)) ** 2
    k = 0
    for i in range(n_r + 1):
        y = yl[i]
        for j in range(n_c + 1):
            if not used[i, j]:
                continue
            x = xl[j]
            e = r00 * x + r10 * y
            n = r01 * x + r11 * y
            d2 = e * e + n * n
            if d2 > far2:
                continue
            f = e * sin_look + n * cos_look  # along the look direction
            if (f < 0.0 or cos_half > 0.0) and f < cos_half * np.sqrt(d2):
                continue
            idx[k] = i * (n_c + 1) + j
            e_out[k] = e
            n_out[k] = n
            k += 1
    return idx[:k], e_out[:k], n_out[:k]


@njit(cache=True, nogil=True)
def _corner_lattice(
    idx: NDArray, atan: NDArray, dist: NDArray, look_deg: float, n_rows: int, n_cols: int
) -> tuple[NDArray, NDArray]:
    """Relative azimuth (deg) and range lattices of :func:`_carve_cells` from the needed
    corners (flat ``idx``, ``arctan2(e, n)`` and ``hypot(e, n)``); the other corners get
    azimuth 0 and an infinite range.

    The azimuth is numpy's ``np.mod(np.degrees(atan) - look_deg + 180.0, 360.0) - 180.0``, bit
    for bit: ``degrees`` multiplies by ``180 / pi`` and ``mod`` is the C ``fmod`` moved into
    the divisor's sign (Python's convention), as numpy's float loops do.
    """
    beta = np.zeros((n_rows, n_cols))
    rho = np.full((n_rows, n_cols), np.inf)
    b = beta.ravel()
    d = rho.ravel()
    to_deg = 180.0 / np.pi
    for k in range(idx.size):
        x = atan[k] * to_deg - look_deg + 180.0
        m = np.fmod(x, 360.0)
        if m != 0.0:
            if m < 0.0:  # the divisor is positive
                m += 360.0
        else:
            m = 0.0  # +0.0, numpy's sign for a zero remainder
        b[idx[k]] = m - 180.0
        d[idx[k]] = dist[k]
    return beta, rho


@njit(cache=True, nogil=True)
def _carve_cells(
    beta: NDArray, rho: NDArray, beta_x: NDArray, rho_x: NDArray, beta_y: NDArray,
    rho_y: NDArray, beta_xy: NDArray, rho_xy: NDArray, pad_x: float, pad_y: float, pad_z: float,
    region: NDArray, bound: NDArray, b0: float, step: float,
    range_m: float, tan_sky: NDArray, xl: NDArray, yl: NDArray, c: float, cz: float,
    up_x: float, up_y: float, up_z: float, seen: NDArray, tan_solid: NDArray, off: NDArray,
    theta: float, k2: float, clearance: float, cam_off: float,
    u_theta: float, u_k2: float, u_clearance: float, u_half: float,
) -> int:  # fmt: skip
    """Lower ``bound`` (n_r, n_c), in place, with the rays of one frame; returns the cells bounded
    and marks them in ``seen`` (n_r, n_c).

    ``tan_solid``: the skyline with the thin features as obstacles; where it is higher over a
    cell than ``tan_sky``, the cell takes ``tan_sky`` only when the thin-structure rule
    (:class:`ThinRule`: ``theta``, ``k2``, ``clearance``, ``cam_off``; ``off`` the cells'
    offsets from the track axis) holds along the rays to it, else ``tan_solid``. ``theta = 0``:
    no rule (``tan_sky`` everywhere).

    ``u_theta > 0`` (:class:`UnseenRule`): a cell whose centre is within ``u_half`` of the
    axis is left alone when a feature ``u_theta`` wide at the distance of its far corner (at
    the bound's height) would not be transparent from the antenna path (``u_k2``, at least
    ``u_clearance`` and the cell's nearest offset away).

    ``beta`` and ``rho`` (n_r + 1, n_c + 1) are the relative azimuth (deg) and horizontal range
    of the cell corners, ``tan_sky`` the tangent of the profile's skyline (``+inf`` where the
    column saw no sky). A cell takes the highest skyline ray over the azimuth span of its
    corners, at its farthest corner (at its nearest point for a downward ray).

    ``pad_x, pad_y > 0`` (a centre known within ``pad_x`` in x and ``pad_y`` in y): the cell
    grown by them on its sides takes its place, its corners read from the lattices shifted by
    ``(-pad_x, -pad_y)`` (``beta``), ``(+pad_x, -pad_y)`` (``beta_x``), ``(-pad_x, +pad_y)``
    (``beta_y``) and ``(+pad_x, +pad_y)`` (``beta_xy``); with no doubt the four are one lattice.
    Every bound is raised by ``pad_z`` (the centre's vertical doubt).
    """
    n_r, n_c = region.shape
    n_b = tan_sky.size
    count = 0
    for r in range(n_r):
        y_a = yl[r] - pad_y
        ny_ = max(max(y_a, 0.0), -(y_a + c + 2.0 * pad_y))
        for q in range(n_c):
            if not region[r, q]:
                continue
            # the range test first: it skips most cells (every test only skips)
            rho_far = max(max(rho[r, q], rho_x[r, q + 1]), max(rho_y[r + 1, q],
                                                               rho_xy[r + 1, q + 1]))
            if not rho_far <= range_m:
                continue
            b1, b2 = beta[r, q], beta_x[r, q + 1]
            b3, b4 = beta_y[r + 1, q], beta_xy[r + 1, q + 1]
            bmin = min(min(b1, b2), min(b3, b4))
            bmax = max(max(b1, b2), max(b3, b4))
            if not bmax - bmin < 90.0:
                continue
            i_lo = np.int64(np.floor((bmin - b0) / step))
            i_hi = np.int64(np.ceil((bmax - b0) / step))
            if i_lo < 0 or i_hi > n_b - 1:
                continue
            t_max = tan_sky[i_lo]
            for i in range(i_lo + 1, i_hi + 1):
                if tan_sky[i] > t_max:
                    t_max = tan_sky[i]
            if not np.isfinite(t_max):
                continue
            x_a = xl[q] - pad_x
            if theta > 0.0:
                t_s = tan_solid[i_lo]
                for i in range(i_lo + 1, i_hi + 1):
                    if tan_solid[i] > t_s:
                        t_s = tan_solid[i]
                if t_s > t_max:
                    if not np.isfinite(t_s) or not _thin_ok(
                        rho_far, t_s, theta, k2, clearance, cam_off, off[r, q],
                        c + 2.0 * max(pad_x, pad_y),
                    ):
                        t_max = t_s  # a thin feature on the way may block: solid
                    if not np.isfinite(t_max):
                        continue
            if u_theta > 0.0 and abs(off[r, q]) < u_half:
                # an arm over the track the sky may hide unflagged (section 11)
                w_u = u_theta * np.sqrt(rho_far * rho_far * (1.0 + t_max * t_max))
                d_u = max(u_clearance, abs(off[r, q]) - 0.7072 * c)
                if w_u * w_u > u_k2 * d_u:
                    continue
            if t_max >= 0.0:
                h = rho_far * t_max
            else:  # nearest point of the cell to the camera (for downward-looking bounds)
                h = np.hypot(max(max(x_a, 0.0), -(x_a + c + 2.0 * pad_x)), ny_) * t_max
            # local height -> frame z: the local horizontal plane is tilted in the frame
            tilt = -(up_x * (x_a + pad_x + c / 2) + up_y * (y_a + pad_y + c / 2)) / up_z
            z = np.float32(cz + tilt + h / up_z + pad_z)
            if z < bound[r, q]:
                bound[r, q] = z
            seen[r, q] = True
            count += 1
    return count


@njit(cache=True, nogil=True)
def _thin_ok(
    rho_far: float, t_solid: float, theta: float, k2: float, clearance: float, cam_off: float,
    cell_off: float, c: float,
) -> bool:  # fmt: skip
    """Whether every feature at most ``theta`` (rad) wide on the rays from the camera to the cell
    (up to the solid skyline's height over its far corner) is transparent (:class:`ThinRule`).

    A feature at ray distance ``t L`` is at most ``theta t L`` wide; it is transparent when that
    is at most ``sqrt(k2 d)``, ``d`` its distance from the antenna path, at least
    ``clearance`` and at least its offset from the track axis (the path runs along the axis).
    The offset is linear along the ray between the camera's and the cell's (same sign, the
    cell's nearest point): the first condition holds for ``t <= sqrt(k2 clearance) / (theta
    L)``, the second, convex in ``t`` and true at ``t = 0``, wherever it holds at ``t = 1``;
    both sets start at 0, so the segment is transparent when either holds at its end.
    """
    h = rho_far * t_solid
    length = np.sqrt(rho_far * rho_far + h * h)
    w = theta * length
    if w * w <= k2 * clearance:
        return True
    near = abs(cell_off) - 0.7072 * c
    if cam_off * cell_off <= 0.0 or near <= 0.0:
        return False
    return w * w <= k2 * near


@dataclass(frozen=True)
class ThinRule:
    """The thin-structure rule of one frame for :func:`carve_profile`
    (``docs/reconstruction.md``, section 8).

    Attributes
    ----------
    width_rad : float
        Widest feature the frame's thin mask may hold, radians (0: no rule).
    k2_m : float
        ``(TRANSPARENT_FRACTION)^2 * wavelength``: a feature of width ``w`` at distance ``d``
        from the antenna is transparent when ``w^2 <= k2_m * d``.
    clearance_m : float
        Least distance of any structure from the antenna path.
    camera_offset_m : float
        The camera's lateral offset from the track axis, shrunk toward the axis by its
        uncertainty (0: unknown, the offset term is not used).
    """

    width_rad: float
    k2_m: float
    clearance_m: float
    camera_offset_m: float


@dataclass(frozen=True)
class UnseenRule:
    """What the sky of a frame may hide without its segmentation flagging it, over the track
    (:func:`carve_profile`, ``docs/reconstruction.md`` section 11).

    A catenary cantilever or registration arm (5-8 cm tubes) 1-2 m over the antenna is about
    a pixel wide a few metres from a camera: a segmentation labels it sky without a thin mask,
    and that sky would carve the cells it hangs in. Over the track (the clearance) a frame
    therefore bounds a cell only where a feature ``width_rad`` wide there would be transparent
    (the Fresnel rule of :class:`ThinRule`), elsewhere not at all.

    Attributes
    ----------
    width_rad : float
        Widest feature the frame's sky may hide, radians.
    k2_m : float
        As :attr:`ThinRule.k2_m`.
    clearance_m : float
        Least distance of any structure from the antenna path.
    half_width_m : float
        The clearance's half-width: cells whose centre is nearer the axis are checked.
    """

    width_rad: float
    k2_m: float
    clearance_m: float
    half_width_m: float


def _window_max(values: NDArray, radius: int, fill: Any) -> NDArray:
    """Maximum of ``values`` (1-D) over ``+-radius`` neighbours, ``fill`` beyond the ends."""
    padded = np.pad(values, radius, constant_values=fill)
    return np.asarray(np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1).max(axis=1))


def apply_clearance_prior(
    hf: HeightField,
    bound: NDArray,
    clearance_half_width_m: float,
    clearance_floor_m: float,
    band_m: tuple[float, float],
    overhead_height_m: float,
    bin_m: float = 1.0,
    spread_m: float = 2.0,
    extra_overhead_m: NDArray | None = None,
    camera_ceilings: NDArray | None = None,
) -> NDArray:
    """Fill the space between the cameras, where side cameras never look (in place).

    Cells within ``clearance_half_width_m`` of the axis are free (bounded at
    ``clearance_floor_m`` above the rail) unless something may hang over the track there:

    * chainages where *every* cell of the lateral bands ``band_m`` on *both* sides is bounded
      above ``overhead_height_m`` above the rail (a deck or a tunnel spans the track; open track
      always has some low-bounded band cell);
    * the intervals ``extra_overhead_m`` (k, 2), e.g. where a camera saw an obstacle near its
      zenith (a crown or a canopy reaching over the track from one side).

    There, a clearance cell is bounded by the highest bound of the band cells of its chainage
    (both sides, within ``spread_m``): whatever spans the track also stands over the bands
    beside it, and is no taller over the track than the sky rays passing over those bands
    prove. A band cell still unknown leaves the clearance unknown (blocked), unless the
    cameras bound it (below).

    ``camera_ceilings`` (m, 4), rows ``(chainage_m, z_m, tan_ahead, tan_behind)``: a position
    whose left *and* right cameras, at height at most ``z_m``, saw sky straight along the track
    down to the elevation of tangent ``tan_ahead`` (towards increasing chainage) and
    ``tan_behind``. Anything spanning the track spans the lines of both cameras too, so over
    the track it stands at most at ``z_m + d * tan`` at a chainage distance ``d`` (to the far
    end of each cell, half its diagonal beyond its centre); an overhead
    clearance cell takes the lowest of these ceilings when it is lower than the band bound (a
    street between facades, a slot between rock walls: the band cells are bounded by the walls,
    the sky along the track is open). ``inf`` tangents bound nothing (a camera saw no sky
    there: a deck, a tunnel).

    Returns
    -------
    ndarray of float, shape (k, 2)
        The overhead chainage intervals.
    """
    reg = hf.region
    ch = hf.chainage_m
    off = hf.offset_m
    # bins aligned on multiples of bin_m, so that overlapping windows agree
    lo = float(np.floor(np.nanmin(ch) / bin_m) * bin_m)
    n_bins = int(np.ceil((float(np.nanmax(ch)) - lo) / bin_m)) + 1
    above = bound - hf.rail_z_m
    b0, b1 = band_m
    tall_both: NDArray = np.ones(n_bins, bool)
    # highest band bound per bin, both sides (-inf: no band cell in the bin)
    band_top = np.full(n_bins, -np.inf)
    for sign in (1.0, -1.0):
        sel = reg & (sign * off >= b0) & (sign * off <= b1)
        k = np.floor((ch[sel] - lo) / bin_m).astype(np.int64)
        low = np.full(n_bins, np.inf)
        np.minimum.at(low, k, above[sel])
        np.maximum.at(band_top, k, above[sel])
        tall_both &= low > overhead_height_m
    radius = round(spread_m / bin_m)
    if radius > 0:
        tall_both = _window_max(tall_both, radius, False)
        band_top = _window_max(band_top, radius, -np.inf)
    # a bin without band cells proves nothing
    band_top = np.where(np.isfinite(band_top), band_top, np.inf)
    centres = lo + (np.arange(n_bins) + 0.5) * bin_m
    extra = np.zeros((0, 2)) if extra_overhead_m is None else extra_overhead_m
    for a, b in np.asarray(extra, float).reshape(-1, 2):
        tall_both |= (centres >= a) & (centres <= b)
    tall_any = tall_both
    sel = reg & (np.abs(off) < clearance_half_width_m)
    k = np.floor((ch[sel] - lo) / bin_m).astype(np.int64)
    free = ~tall_any[k]
    rows, cols = np.nonzero(sel)
    rail = hf.rail_z_m[rows, cols]
    over_top = band_top[k]
    if camera_ceilings is not None and len(camera_ceilings) and not free.all():
        # only overhead cells use it; a cell spans at most half its diagonal either side of
        # its centre's chainage
        over = ~free
        cam_top = _camera_ceiling(camera_ceilings, ch[sel][over], hf.cell_m * np.sqrt(0.5))
        over_top[over] = np.minimum(over_top[over], cam_top - rail[over])
    # free clearance: the floor; under an overhead structure: the highest band bound beside it,
    # or the cameras' ceiling when lower
    above_rail = np.where(free, clearance_floor_m, over_top)
    ceiling = (rail + above_rail).astype(np.float32)
    bound[rows, cols] = np.minimum(bound[rows, cols], ceiling)
    # overhead intervals, for the record
    edges = np.diff(np.concatenate([[0], tall_any.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return np.stack([lo + starts * bin_m, lo + stops * bin_m], axis=1).astype(float)


def _camera_ceiling(ceilings: NDArray, chainage_m: NDArray, half_extent_m: float) -> NDArray:
    """Lowest camera ceiling (absolute z) over cells centred at ``chainage_m`` that reach
    ``half_extent_m`` either side, taken at each cell's far end from each position (``+inf``
    where none bounds it). Memory: cells x positions, in blocks of positions."""
    c = np.asarray(ceilings, float).reshape(-1, 4)
    s = np.asarray(chainage_m, float)[:, None]
    out = np.full(s.shape[0], np.inf)
    for b in range(0, c.shape[0], 64):
        ch, z, t_ahead, t_behind = (c[b : b + 64, i][None, :] for i in range(4))
        rel = s - ch
        d = np.abs(rel) + half_extent_m
        straddles = np.abs(rel) < half_extent_m
        tan = np.where(rel > 0, t_ahead, t_behind)
        tan = np.where(straddles, np.maximum(t_ahead, t_behind), tan)
        with np.errstate(invalid="ignore"):
            top = np.where(np.isfinite(tan), z + d * tan, np.inf)
        out = np.minimum(out, top.min(axis=1))
    return out


def sweep_along_track(
    hf: HeightField, track: TrackMap, half_m: float, skip_offset_m: float = 0.0
) -> HeightField:
    """The height field as an antenna at a position sees it from anywhere within ``half_m``
    along the track: each cell takes the highest bound of the cells it becomes when the
    track moves it by up to ``half_m`` (a dilation along the local track direction).

    The horizon of the result from a position is then the highest horizon of ``hf`` from any
    point within ``half_m`` of it along the track, exactly for a straight, evenly graded
    track: moving the antenna by ``d`` along the track is moving every obstacle by ``-d``
    (``docs/reconstruction.md``, section 12). Each shift of at most half a cell takes the
    2 x 2 cells under the shifted cell's footprint, so nothing between two shifts is missed
    (it over-reaches by up to a cell); a source's top is moved with the rail's height, so a
    grade shifts it too. Unknown cells (``+inf``) spread like any other; cells outside the
    corridor region are not sources. ``views`` follows the cell that gave each bound.

    Parameters
    ----------
    hf : HeightField
    track : TrackMap
    half_m : float
        Half-length of the sweep, metres (``0``: ``hf`` itself).
    skip_offset_m : float
        Cells nearer the track axis than this are left as they are (neither swept nor
        sources): the clearance band, whose overhead structures the 2.5-D model would turn
        into columns over the antenna (``docs/reconstruction.md``, section 12).

    Returns
    -------
    HeightField
        ``hf`` with ``bound_m`` (and ``views``) swept; never lower than ``hf``'s.
    """
    if not (np.isfinite(half_m) and half_m >= 0):
        raise ValueError(f"half_m must be a finite length >= 0 metres, got {half_m}")
    if half_m == 0:
        return hf
    c = hf.cell_m
    ny, nx = hf.shape
    with np.errstate(invalid="ignore"):
        region = np.asarray(hf.region, bool) & ~(np.abs(hf.offset_m) < skip_offset_m)
    rows, cols = np.nonzero(region)
    if rows.size == 0:
        return hf
    t = np.asarray(track.tangent_at(hf.chainage_m[rows, cols].astype(float)), float)[:, :2]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    x = (hf.ix0 + cols + 0.5) * c
    y = (hf.iy0 + rows + 0.5) * c
    bound = np.asarray(hf.bound_m, np.float64)
    rail = np.asarray(hf.rail_z_m, np.float64)
    views = None if hf.views is None else np.asarray(hf.views)
    rail_t = rail[rows, cols]
    out = bound[rows, cols].copy()
    out_views = None if views is None else views[rows, cols].copy()
    n = int(np.ceil(half_m / (0.5 * c)))
    for d in np.linspace(-half_m, half_m, 2 * n + 1):
        sx, sy = x + d * t[:, 0], y + d * t[:, 1]
        # the cells under a cell-sized square centred on the shifted centre
        for cx in (np.floor((sx - 0.5 * c) / c), np.floor((sx + 0.5 * c) / c - 1e-9)):
            for cy in (np.floor((sy - 0.5 * c) / c), np.floor((sy + 0.5 * c) / c - 1e-9)):
                col = cx.astype(np.int64) - hf.ix0
                row = cy.astype(np.int64) - hf.iy0
                ok = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
                rr, cc = np.where(ok, row, 0), np.where(ok, col, 0)
                ok &= region[rr, cc]
                with np.errstate(invalid="ignore"):
                    val = bound[rr, cc] - (rail[rr, cc] - rail_t)
                up = ok & (val > out)
                out[up] = val[up]
                if out_views is not None and views is not None:
                    out_views[up] = views[rr[up], cc[up]]
    new_bound = np.array(hf.bound_m, np.float32)
    new_bound[rows, cols] = np.maximum(out, bound[rows, cols]).astype(np.float32)
    new_bound.setflags(write=False)
    new_views = None
    if views is not None and out_views is not None:
        new_views = np.array(views)
        new_views[rows, cols] = out_views
        new_views.setflags(write=False)
    return replace(hf, bound_m=new_bound, views=new_views)


@njit(cache=True, nogil=True)
def contradicted_raise(
    low: NDArray, cap: NDArray, code: NDArray, ix0: int, iy0: int, cell_m: float,
    cam: NDArray, rot: NDArray, look_az_deg: float, rel_az_deg: NDArray, sky_el_deg: NDArray,
    below_deg: float, min_el_deg: float, max_rel_az_deg: float, from_m: float, range_m: float,
    step_m: float, out: NDArray,
) -> int:  # fmt: skip
    """One view's obstacle rays against the fused bounds ``low`` (the consistency check,
    ``docs/reconstruction.md``, section 6, clause 6).

    For each profile column within ``max_rel_az_deg`` of the look direction whose skyline
    stands above ``min_el_deg``, the ray ``below_deg`` under the skyline ends on an obstacle.
    It is marched from the camera ``cam`` (track frame; ``rot``: local ENU to track frame) in
    steps of ``step_m``, from ``from_m`` out to ``range_m`` horizontally or until it leaves
    the cells of ``code`` (0: not modelled, 1: checked, 2: the clearance, passed over: its
    bound is the prior's, set afterwards). A
    cell whose ``low`` stands at or above the ray stops it: the view's obstacle may stand
    there. A ray that no cell stops contradicts the cells it crossed: each one it crossed
    whose ``cap`` stands at or above the ray is raised in ``out`` (max-accumulated) to the
    ray's height where it leaves the cell, at most to ``cap``. Returns the rays that
    contradicted ``low``.
    """
    ny, nx = low.shape
    n_steps = int(range_m / step_m) + 1
    rows = np.empty(n_steps, np.int64)
    cols = np.empty(n_steps, np.int64)
    hs = np.empty(n_steps)
    n_bad = 0
    for j in range(rel_az_deg.size):
        el = sky_el_deg[j]
        if not (el > min_el_deg and el < 89.0) or abs(rel_az_deg[j]) > max_rel_az_deg:
            continue
        e = np.radians(el - below_deg)
        az = np.radians(look_az_deg + rel_az_deg[j])
        de, dn, du = np.sin(az) * np.cos(e), np.cos(az) * np.cos(e), np.sin(e)
        dx = rot[0, 0] * de + rot[0, 1] * dn + rot[0, 2] * du
        dy = rot[1, 0] * de + rot[1, 1] * dn + rot[1, 2] * du
        dz = rot[2, 0] * de + rot[2, 1] * dn + rot[2, 2] * du
        hor = np.sqrt(dx * dx + dy * dy)
        if hor < 1e-6:
            continue
        stopped = False
        k = 0
        for s in range(1, n_steps):
            t = s * step_m / hor
            col = int(np.floor((cam[0] + t * dx) / cell_m)) - ix0
            row = int(np.floor((cam[1] + t * dy) / cell_m)) - iy0
            if col < 0 or col >= nx or row < 0 or row >= ny or code[row, col] == 0:
                if k > 0:
                    break
                continue
            if code[row, col] == 2 or s * step_m < from_m:
                continue
            z = cam[2] + t * dz
            if low[row, col] >= z:
                stopped = True
                break
            rows[k] = row
            cols[k] = col
            hs[k] = z
            k += 1
        if stopped or k == 0:
            continue
        n_bad += 1
        rise = step_m * dz / hor if dz > 0.0 else 0.0
        for q in range(k):
            r, c = rows[q], cols[q]
            if cap[r, c] < hs[q]:
                continue  # the views up to the cap's rank see the ray pass over it
            v = min(cap[r, c], hs[q] + rise)
            if v > out[r, c]:
                out[r, c] = v
    return n_bad
