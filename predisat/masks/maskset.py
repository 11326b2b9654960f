"""Per-position GNSS elevation masks along a line, and the trust queries built on them.

A :class:`MaskSet` holds, for every surveyed position (chainage) along a track, the elevation of
the skyline in ``n_az`` equal azimuth bins, where each bin's value came from (:class:`BinSource`),
a per-bin safety margin, obstacle descriptors per side and the provenance of the whole set.
The file format is in :mod:`predisat.masks.fileformat` and ``docs/mask-format.md``.

Conventions
-----------
* Azimuth bin ``k`` is centred on ``k * az_step_deg`` (bin 0 is centred on north) and covers
  ``[k * step - step / 2, k * step + step / 2)``, so ``n_az = 360 / az_step_deg`` exactly.
* Position ``i`` stands for the chainage *cell* between the midpoints to its neighbours; the
  first and last cells reach half of the adjacent spacing beyond the end positions. Chainages
  outside every cell are *outside coverage* and nothing is trusted there.
* The *effective* mask is ``mask_el_deg + margin_deg``; a satellite is trusted when its
  elevation is strictly above the effective mask of the bin holding its azimuth.
"""

from __future__ import annotations

import bisect
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from enum import IntEnum
from functools import cached_property
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat import __version__
from predisat.jsontypes import JsonDict
from predisat.masks.binops import RangeMax, conservative_resample

__all__ = [
    "CHECKED_PROVENANCE_KEYS",
    "REQUIRED_DESCRIPTORS",
    "WEAK_SUPPORT",
    "BinSource",
    "MaskError",
    "MaskSet",
    "concat_masksets",
]

REQUIRED_DESCRIPTORS: tuple[str, ...] = (
    "left_obstacle_distance_m",
    "left_obstacle_height_m",
    "right_obstacle_distance_m",
    "right_obstacle_height_m",
)
"""Descriptor columns every mask set carries (NaN where there is no obstacle on that side)."""

WEAK_SUPPORT = 2
"""Bins whose :attr:`MaskSet.support` is below this are *weakly supported*: no second
independent view backs their bound, so one wrong segmentation can make them too low (the
figures hatch them; ``docs/reconstruction.md``, section 7)."""

_CORE_NAMES = frozenset(
    {
        "chainage_m",
        "lat_deg",
        "lon_deg",
        "h_m",
        "heading_deg",
        "mask_el_deg",
        "source",
        "margin_deg",
        "geometry",
        "support",
    }
)
_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")


class MaskError(ValueError):
    """Invalid mask data; the message names the field, the row/bin and the fix."""


class BinSource(IntEnum):
    """Where a bin's mask elevation came from."""

    OBSERVED = 0
    """Seen by a camera in a frame at this position."""
    RECONSTRUCTED = 1
    """Not seen here; filled from the 3-D reconstruction of neighbouring frames."""
    ASSUMED = 2
    """Neither seen nor reconstructed: the value rests on an unknown cell (an obstacle up to its
    bound) or on the stated far-field default (``ReconstructionParams.far_default_deg``), and
    is flagged so that a margin, or the user, can treat it apart."""
    TERRAIN = 3
    """Raised to the horizon of a digital elevation model (its stated vertical error added):
    the terrain beyond the surveyed corridor stood higher than what the frames or the far-field
    default gave (:func:`predisat.masks.terrain.raise_to_terrain`)."""


class _Track(Protocol):  # the part of predisat.track.map.TrackMap used here
    @property
    def name(self) -> str: ...

    def position_at(self, chainage_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]: ...

    def heading_at(self, chainage_m: ArrayLike) -> NDArray: ...


@dataclass(frozen=True, eq=False)
class MaskSet:
    """Elevation masks at positions along a track, with per-bin source and margin.

    Build with :meth:`from_arrays` or :meth:`from_track`; read and write with
    :func:`predisat.masks.fileformat.read_masks` / :func:`predisat.masks.fileformat.write_masks`.
    Arrays are stored
    as read-only copies.

    Attributes
    ----------
    chainage_m : ndarray, shape (n_pos,), float64
        Strictly increasing chainage of each position, metres.
    lat_deg, lon_deg, h_m : ndarray, shape (n_pos,), float64
        WGS84 position of the antenna's track-axis point, degrees and metres (ellipsoidal).
    heading_deg : ndarray, shape (n_pos,), float64
        Track heading (azimuth of increasing chainage), degrees in [0, 360).
    az_step_deg : float
        Bin width; ``n_az = 360 / az_step_deg``.
    mask_el_deg : ndarray, shape (n_pos, n_az), float32
        Skyline elevation per bin, degrees in [0, 90].
    source : ndarray, shape (n_pos, n_az), uint8
        :class:`BinSource` code per bin.
    margin_deg : ndarray, shape (n_pos, n_az), float32
        Safety margin added to the mask, degrees >= 0.
    descriptors : dict of str to ndarray, shape (n_pos,), float64
        Obstacle descriptors; at least :data:`REQUIRED_DESCRIPTORS`. NaN = none.
    provenance : dict
        JSON-serialisable record of how the set was made (survey id, software version,
        parameters, creation time, track name, ...).
    support : ndarray, shape (n_pos, n_az), uint8, or None
        Evidence per bin: how many independent views (frames, or frames sharing a view group)
        bounded what sets the bin's value (``docs/reconstruction.md``, section 7); 0 where the
        value rests on an assumption (an unknown cell, the far-field default, the clearance
        prior); capped at 255. ``None`` when unknown (a mask file of version 1 or 2).
        A bin with support below :data:`WEAK_SUPPORT` is *weakly supported*.
    """

    chainage_m: NDArray
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    heading_deg: NDArray
    az_step_deg: float
    mask_el_deg: NDArray
    source: NDArray
    margin_deg: NDArray
    descriptors: dict[str, NDArray] = field(default_factory=dict)
    provenance: JsonDict = field(default_factory=dict)
    support: NDArray | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        ch = _chainage_vector(self.chainage_m)
        n = ch.size
        lat = _vector(self.lat_deg, "lat_deg", n)
        lon = _vector(self.lon_deg, "lon_deg", n)
        _check_range(lat, "lat_deg", -90.0, 90.0)
        _check_range(lon, "lon_deg", -180.0, 180.0)
        h = _vector(self.h_m, "h_m", n)
        hdg = np.mod(_vector(self.heading_deg, "heading_deg", n), 360.0)
        hdg[hdg >= 360.0] = 0.0  # np.mod(-1e-14, 360) rounds to 360

        step, n_az = _az_bins(self.az_step_deg)
        mask = _mask_array(self.mask_el_deg, n, n_az, step)
        src = _source_array(self.source, n, n_az)
        margin = _margin_array(self.margin_deg, n, n_az)
        desc = _descriptor_arrays(self.descriptors, n)
        prov = _json_provenance(self.provenance)
        sup = None if self.support is None else _support_array(self.support, n, n_az)

        for arr in (ch, lat, lon, h, hdg, mask, src, margin, *desc.values()):
            arr.setflags(write=False)
        if sup is not None:
            sup.setflags(write=False)
        set_(self, "chainage_m", ch)
        set_(self, "lat_deg", lat)
        set_(self, "lon_deg", lon)
        set_(self, "h_m", h)
        set_(self, "heading_deg", hdg)
        set_(self, "az_step_deg", step)
        set_(self, "mask_el_deg", mask)
        set_(self, "source", src)
        set_(self, "margin_deg", margin)
        set_(self, "descriptors", desc)
        set_(self, "provenance", prov)
        set_(self, "support", sup)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_arrays(
        cls,
        chainage_m: ArrayLike,
        lat_deg: ArrayLike,
        lon_deg: ArrayLike,
        h_m: ArrayLike,
        heading_deg: ArrayLike,
        mask_el_deg: ArrayLike,
        *,
        az_step_deg: float | None = None,
        source: ArrayLike | None = None,
        margin_deg: ArrayLike = 0.0,
        descriptors: Mapping[str, ArrayLike] | None = None,
        provenance: JsonDict | None = None,
        support: ArrayLike | None = None,
    ) -> MaskSet:
        """Mask set from plain arrays, validated.

        Parameters
        ----------
        chainage_m, lat_deg, lon_deg, h_m, heading_deg : array_like, shape (n_pos,)
            See the class attributes.
        mask_el_deg : array_like, shape (n_pos, n_az)
            Skyline elevation per bin, degrees in [0, 90].
        az_step_deg : float, optional
            Bin width; inferred as ``360 / n_az`` when omitted.
        source : array_like of int, shape (n_pos, n_az), optional
            :class:`BinSource` codes; all ``OBSERVED`` when omitted.
        margin_deg : float or array_like, shape (n_pos, n_az), optional
            Margin added to the mask, degrees >= 0 (default 0).
        descriptors : mapping of str to array_like (n_pos,), optional
            Obstacle descriptors; missing :data:`REQUIRED_DESCRIPTORS` are filled with NaN.
        provenance : mapping, optional
            JSON-serialisable; ``software`` / ``software_version`` / ``created_utc`` are added
            when absent.
        support : array_like of int, shape (n_pos, n_az), optional
            Independent views per bin, 0-255 (see the class attributes); ``None``: unknown.

        Raises
        ------
        MaskError
            On any shape, range or ordering problem, naming the field and the first bad row.
        """
        mask = np.asarray(mask_el_deg, dtype=np.float32)
        if mask.ndim != 2:
            raise MaskError(f"mask_el_deg must be 2-D (n_pos, n_az), got shape {mask.shape}")
        step = 360.0 / mask.shape[1] if az_step_deg is None else float(az_step_deg)
        if mask.shape[1] == 0:
            raise MaskError("mask_el_deg has no azimuth bins")
        src = np.zeros(mask.shape, np.uint8) if source is None else np.asarray(source)
        return cls(
            chainage_m=np.asarray(chainage_m),
            lat_deg=np.asarray(lat_deg),
            lon_deg=np.asarray(lon_deg),
            h_m=np.broadcast_to(np.asarray(h_m, float), np.shape(chainage_m)),
            heading_deg=np.asarray(heading_deg),
            az_step_deg=step,
            mask_el_deg=mask,
            source=src,
            margin_deg=np.asarray(margin_deg),
            descriptors={k: np.asarray(v) for k, v in (descriptors or {}).items()},
            provenance=_default_provenance(provenance),
            support=None if support is None else np.asarray(support),
        )

    @classmethod
    def from_track(
        cls,
        track: _Track,
        chainage_m: ArrayLike,
        mask_el_deg: ArrayLike,
        *,
        az_step_deg: float | None = None,
        source: ArrayLike | None = None,
        margin_deg: ArrayLike = 0.0,
        descriptors: Mapping[str, ArrayLike] | None = None,
        provenance: JsonDict | None = None,
        support: ArrayLike | None = None,
    ) -> MaskSet:
        """Mask set whose positions and headings come from a track map.

        Parameters
        ----------
        track : predisat.track.map.TrackMap
            Supplies ``position_at`` (lat, lon, h) and ``heading_at`` at each chainage.
        chainage_m : array_like, shape (n_pos,)
        mask_el_deg : array_like, shape (n_pos, n_az)
        az_step_deg, source, margin_deg, descriptors, support
            As in :meth:`from_arrays`.
        provenance : mapping, optional
            As in :meth:`from_arrays`; the track's name is recorded as ``track`` unless given.
        """
        ch = np.asarray(chainage_m, float)
        lat, lon, h = track.position_at(ch)
        prov = dict(provenance or {})
        prov.setdefault("track", getattr(track, "name", ""))
        return cls.from_arrays(
            ch, lat, lon, h, track.heading_at(ch), mask_el_deg, provenance=prov,
            az_step_deg=az_step_deg, source=source, margin_deg=margin_deg,
            descriptors=descriptors, support=support,
        )  # fmt: skip

    # ------------------------------------------------------------------ properties
    @property
    def n_pos(self) -> int:
        """Number of positions."""
        return int(self.chainage_m.size)

    @property
    def n_az(self) -> int:
        """Number of azimuth bins."""
        return int(self.mask_el_deg.shape[1])

    @property
    def az_deg(self) -> NDArray:
        """Bin centre azimuths, degrees, shape (n_az,)."""
        return np.arange(self.n_az) * self.az_step_deg

    @cached_property
    def effective_mask_deg(self) -> NDArray:
        """``mask_el_deg + margin_deg``, float32 (n_pos, n_az): what trust is decided on."""
        eff = self.mask_el_deg + self.margin_deg
        eff.setflags(write=False)
        return eff

    @cached_property
    def cell_bounds_m(self) -> NDArray:
        """Chainage cell edges, shape (n_pos + 1,): position ``i`` covers ``[b[i], b[i+1]]``."""
        ch = self.chainage_m
        if ch.size == 1:
            b = np.array([ch[0], ch[0]])
        else:
            mid = 0.5 * (ch[1:] + ch[:-1])
            b = np.concatenate(
                [[ch[0] - 0.5 * (ch[1] - ch[0])], mid, [ch[-1] + 0.5 * (ch[-1] - ch[-2])]]
            )
        b.setflags(write=False)
        return b

    # ------------------------------------------------------------------ lookups
    def bin_index(self, az_deg: ArrayLike) -> NDArray:
        """Azimuth bin holding each azimuth (any real value, wrapped), int array like ``az_deg``.

        Bin ``k`` covers ``[k*step - step/2, k*step + step/2)``.
        """
        az = np.asarray(az_deg, float)
        if not np.isfinite(az).all():
            raise MaskError("bin_index: az_deg contains NaN or inf; drop those azimuths first")
        k = np.floor(np.mod(az, 360.0) / self.az_step_deg + 0.5).astype(np.int64)
        return np.mod(k, self.n_az)

    def position_index(self, chainage_m: ArrayLike) -> tuple[NDArray, NDArray]:
        """Nearest position to each chainage, and whether the chainage is covered.

        Returns
        -------
        index : ndarray of int, shape like ``chainage_m``
            Index of the position whose cell holds the chainage (clipped to the ends).
        inside : ndarray of bool, shape like ``chainage_m``
            False beyond half a spacing outside the first/last position, or for NaN.
        """
        s = np.asarray(chainage_m, float)
        b = self.cell_bounds_m
        idx = np.clip(np.searchsorted(b[1:-1], s, side="right"), 0, self.n_pos - 1)
        inside = (s >= b[0]) & (s <= b[-1])
        return idx.astype(np.int64), inside

    def mask_at(self, chainage_m: ArrayLike, az_deg: ArrayLike) -> NDArray:
        """Effective mask (mask + margin) at chainages and azimuths, degrees.

        Parameters
        ----------
        chainage_m, az_deg : array_like, broadcastable shapes
            E.g. ``(n, 1)`` and ``(1, k)`` give ``(n, k)``.

        Returns
        -------
        ndarray, float64, broadcast shape
            ``+inf`` outside coverage and for non-finite azimuths (nothing is trusted there).
        """
        s, az = np.broadcast_arrays(np.asarray(chainage_m, float), np.asarray(az_deg, float))
        i, inside = self.position_index(s)
        ok = np.isfinite(az)
        out = self.effective_mask_deg[i, self.bin_index(np.where(ok, az, 0.0))].astype(float)
        return np.where(inside & ok, out, np.inf)

    def source_at(self, chainage_m: ArrayLike, az_deg: ArrayLike) -> NDArray:
        """:class:`BinSource` code at chainages and azimuths (nearest position), uint8."""
        s, az = np.broadcast_arrays(np.asarray(chainage_m, float), np.asarray(az_deg, float))
        i, _ = self.position_index(s)
        return self.source[i, self.bin_index(az)]

    def trusted(self, chainage_m: ArrayLike, az_deg: ArrayLike, el_deg: ArrayLike) -> NDArray:
        """Whether a satellite at (az, el) is trusted at each chainage.

        True when ``el_deg > mask + margin`` of the bin holding ``az_deg`` at the nearest
        position; False outside coverage and for NaN inputs. Broadcasts all three arguments.
        """
        s, az, el = np.broadcast_arrays(
            np.asarray(chainage_m, float), np.asarray(az_deg, float), np.asarray(el_deg, float)
        )
        return np.asarray(el > self.mask_at(s, az))

    def worst_case(
        self, chainage_lo_m: ArrayLike, chainage_hi_m: ArrayLike, *, clip: bool = False
    ) -> NDArray:
        """Bin-wise maximum effective mask over chainage intervals.

        Every position whose cell touches the closed interval ``[lo, hi]`` counts. A satellite
        above the result in its bin is trusted everywhere in the interval.

        Parameters
        ----------
        chainage_lo_m, chainage_hi_m : array_like, shape (...)
            Interval ends, metres; ``lo <= hi``.
        clip : bool, optional
            If False (default) an interval reaching outside the coverage gives ``+inf`` in
            every bin (the train may be where no mask exists). If True the interval is
            clipped to the coverage first (``+inf`` only when nothing is left).

        Returns
        -------
        ndarray, float32, shape (..., n_az)

        Notes
        -----
        A sparse table over blocks of positions plus in-block prefix/suffix maxima answers each
        query with a few gathers: 10^5 intervals over 3 000 positions take about 0.7 s.
        """
        if np.ndim(chainage_lo_m) == 0 and np.ndim(chainage_hi_m) == 0:
            lo_f, hi_f = float(np.asarray(chainage_lo_m)), float(np.asarray(chainage_hi_m))
            return self._worst_case_one(lo_f, hi_f, clip)
        lo, hi = np.broadcast_arrays(
            np.asarray(chainage_lo_m, float), np.asarray(chainage_hi_m, float)
        )
        if np.isnan(lo).any() or np.isnan(hi).any():
            raise MaskError("worst_case: chainage_lo_m / chainage_hi_m contain NaN")
        if (lo > hi).any():
            k = int(np.flatnonzero((lo > hi).ravel())[0])
            raise MaskError(
                f"worst_case: interval {k} has lo = {lo.ravel()[k]} > hi = {hi.ravel()[k]}; "
                "pass the lower chainage first"
            )
        b = self.cell_bounds_m
        outside = (lo < b[0]) | (hi > b[-1])
        empty = (hi < b[0]) | (lo > b[-1])
        # First cell whose upper edge reaches lo; last cell whose lower edge is <= hi.
        i = np.clip(np.searchsorted(b[1:], lo, side="left"), 0, self.n_pos - 1)
        j = np.clip(np.searchsorted(b[:-1], hi, side="right") - 1, 0, self.n_pos - 1)
        out = self._range_max.query(i.ravel(), np.maximum(i, j).ravel())
        bad = (empty if clip else outside).ravel()
        out[bad] = np.inf
        return out.reshape(*lo.shape, self.n_az)

    def _worst_case_one(self, lo: float, hi: float, clip: bool) -> NDArray:
        """:meth:`worst_case` of one interval (the locator's epoch): the same cells and values
        in Python scalars, without the array calls that cost more than the work."""
        if math.isnan(lo) or math.isnan(hi):
            raise MaskError("worst_case: chainage_lo_m / chainage_hi_m contain NaN")
        if lo > hi:
            raise MaskError(
                f"worst_case: interval 0 has lo = {lo} > hi = {hi}; pass the lower chainage first"
            )
        cells = self._cells_one(lo, hi, clip)
        if cells is None:
            return np.full(self.n_az, np.inf, self.effective_mask_deg.dtype)
        return self._range_max.query(np.array([cells[0]]), np.array([cells[1]]))[0]

    def _cells_one(self, lo: float, hi: float, clip: bool) -> tuple[int, int] | None:
        """First and last position whose cell touches ``[lo, hi]``; None outside the coverage
        (:meth:`worst_case`'s ``clip``)."""
        b = self._bounds_list
        last = self.n_pos - 1
        i = min(max(bisect.bisect_left(b, lo, 1), 1) - 1, last)  # searchsorted(b[1:], lo)
        j = min(max(bisect.bisect_right(b, hi, 0, len(b) - 1) - 1, 0), last)
        bad = (hi < b[0] or lo > b[-1]) if clip else (lo < b[0] or hi > b[-1])
        return None if bad else (i, max(i, j))

    def assumed_over(self, chainage_lo_m: float, chainage_hi_m: float) -> NDArray:
        """Bins whose mask somewhere over ``[lo, hi]`` rests on no view: the far field's
        assumption (source ``ASSUMED``), bool, shape (n_az,).

        Every position whose cell touches the interval counts, as in :meth:`worst_case`; an
        interval reaching outside the coverage gives True everywhere.
        """
        lo, hi = float(chainage_lo_m), float(chainage_hi_m)
        if math.isnan(lo) or math.isnan(hi) or lo > hi:
            raise MaskError(f"assumed_over: need lo <= hi, got {lo}, {hi}")
        cells = self._cells_one(lo, hi, clip=False)
        if cells is None:
            return np.ones(self.n_az, bool)
        hit = self._assumed_range.query(np.array([cells[0]]), np.array([cells[1]]))[0]
        return np.asarray(hit > 0.0)

    @cached_property
    def _assumed_range(self) -> RangeMax:
        return RangeMax((self.source == BinSource.ASSUMED).astype(np.float32))

    @cached_property
    def _bounds_list(self) -> list[float]:
        return [float(v) for v in self.cell_bounds_m]

    @cached_property
    def _range_max(self) -> RangeMax:
        return RangeMax(self.effective_mask_deg)

    def opening_angle_deg(
        self, *, include_margin: bool = True, half_width_deg: float = 0.0
    ) -> NDArray:
        """Cross-track opening angle at every position, degrees, shape (n_pos,).

        ``180 - left_el - right_el`` where ``left_el`` is the mask in the direction
        ``heading - 90`` (left of increasing chainage) and ``right_el`` at ``heading + 90``.
        Each is the maximum over the bins touching ``[dir - half_width_deg, dir +
        half_width_deg]`` (just the bin holding ``dir`` when 0), with the margin added unless
        ``include_margin`` is False. Can be negative when both sides exceed 45 deg plus margin.
        """
        mask = self.effective_mask_deg if include_margin else self.mask_el_deg
        dirs = np.stack([self.heading_deg - 90.0, self.heading_deg + 90.0], axis=-1)
        side = conservative_resample(mask, self.az_step_deg, dirs, half_width_deg)
        return 180.0 - side[:, 0].astype(float) - side[:, 1].astype(float)

    # ------------------------------------------------------------------ derived sets
    def with_margin(self, margin_deg: ArrayLike) -> MaskSet:
        """Copy with the margin replaced (scalar or (n_pos, n_az) degrees >= 0)."""
        return replace(self, margin_deg=np.asarray(margin_deg))

    def subset(self, chainage_lo_m: float, chainage_hi_m: float) -> MaskSet:
        """Copy restricted to positions with ``lo <= chainage_m <= hi``."""
        keep = (self.chainage_m >= chainage_lo_m) & (self.chainage_m <= chainage_hi_m)
        if not keep.any():
            raise MaskError(
                f"subset [{chainage_lo_m}, {chainage_hi_m}] m holds no position; the set covers "
                f"{self.chainage_m[0]} .. {self.chainage_m[-1]} m"
            )
        return replace(
            self,
            chainage_m=self.chainage_m[keep],
            lat_deg=self.lat_deg[keep],
            lon_deg=self.lon_deg[keep],
            h_m=self.h_m[keep],
            heading_deg=self.heading_deg[keep],
            mask_el_deg=self.mask_el_deg[keep],
            source=self.source[keep],
            margin_deg=self.margin_deg[keep],
            descriptors={k: v[keep] for k, v in self.descriptors.items()},
            support=None if self.support is None else self.support[keep],
        )

    def equals(self, other: MaskSet) -> bool:
        """Exact equality of every array, the step, the descriptors and the provenance."""
        arrays = (
            "chainage_m",
            "lat_deg",
            "lon_deg",
            "h_m",
            "heading_deg",
            "mask_el_deg",
            "source",
            "margin_deg",
        )
        return (
            self.az_step_deg == other.az_step_deg
            and all(np.array_equal(getattr(self, a), getattr(other, a)) for a in arrays)
            and self.descriptors.keys() == other.descriptors.keys()
            and all(
                np.array_equal(v, other.descriptors[k], equal_nan=True)
                for k, v in self.descriptors.items()
            )
            and self.provenance == other.provenance
            and _same_support(self.support, other.support)
        )


def _same_support(a: NDArray | None, b: NDArray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(a, b))


# ---------------------------------------------------------------------- validation
def _chainage_vector(values: ArrayLike) -> NDArray:
    """Chainages as a float64 copy, shape (n_pos,): non-empty, finite, strictly increasing."""
    ch = _vector(values, "chainage_m", None)
    if ch.size == 0:
        raise MaskError("chainage_m is empty: a mask set needs at least one position")
    bad = np.flatnonzero(np.diff(ch) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise MaskError(
            f"chainage_m must be strictly increasing: row {i} ({_num(ch[i])} m) follows row "
            f"{i - 1} ({_num(ch[i - 1])} m); sort the positions and drop duplicates"
        )
    return ch


def _az_bins(az_step_deg: float) -> tuple[float, int]:
    """Bin width (degrees, float) and number of bins; the width must divide 360 degrees."""
    step = float(az_step_deg)
    if not (math.isfinite(step) and step > 0):
        raise MaskError(f"az_step_deg must be a positive number of degrees, got {step!r}")
    n_az = round(360.0 / step)
    if n_az < 1 or abs(n_az * step - 360.0) > 1e-9:
        raise MaskError(
            f"az_step_deg = {step!r} does not divide 360 deg into a whole number of bins; "
            "use a step such as 0.5, 1, 2 or 5"
        )
    return step, n_az


def _mask_array(values: ArrayLike, n: int, n_az: int, step: float) -> NDArray:
    """Mask elevations as a float32 copy, shape (n, n_az), degrees in [0, 90]."""
    mask = np.array(values, dtype=np.float32)
    if mask.shape != (n, n_az):
        raise MaskError(
            f"mask_el_deg has shape {mask.shape}, expected (n_pos, n_az) = ({n}, {n_az}) "
            f"for {n} positions and az_step_deg = {step}"
        )
    _check_range(mask, "mask_el_deg", 0.0, 90.0)
    return mask


def _source_array(values: ArrayLike, n: int, n_az: int) -> NDArray:
    """:class:`BinSource` codes as uint8, shape (n, n_az)."""
    src = np.asarray(values)
    if src.shape != (n, n_az):
        raise MaskError(f"source has shape {src.shape}, expected ({n}, {n_az})")
    valid = [int(s) for s in BinSource]
    # the codes are 0..n-1: a range check, not np.isin (20x slower on a line's bins)
    if not np.issubdtype(src.dtype, np.integer) or (
        src.size and (int(src.min()) < 0 or int(src.max()) > max(valid))
    ):
        where = _first_bad((src < 0) | (src > max(valid))) if src.size else ""
        raise MaskError(
            f"source{where} holds a value that is not a BinSource code {valid} "
            "(0 observed, 1 reconstructed, 2 assumed, 3 terrain)"
        )
    return src.astype(np.uint8)


def _support_array(values: ArrayLike, n: int, n_az: int) -> NDArray:
    """Support counts as uint8, shape (n, n_az), integers in [0, 255]."""
    sup = np.asarray(values)
    if sup.shape != (n, n_az):
        raise MaskError(f"support has shape {sup.shape}, expected ({n}, {n_az}) or None")
    integer = np.issubdtype(sup.dtype, np.integer)
    bad = ((sup < 0) | (sup > 255)) if integer else np.ones(sup.shape, bool)
    if bad.any():
        raise MaskError(
            f"support{_first_bad(bad)} is not an integer in [0, 255]; it counts independent "
            "views (cap larger counts at 255)"
        )
    return sup.astype(np.uint8)


def _margin_array(values: ArrayLike, n: int, n_az: int) -> NDArray:
    """Margins as a float32 copy broadcast to shape (n, n_az), degrees >= 0."""
    margin = np.asarray(values, dtype=np.float32)
    try:
        margin = np.broadcast_to(margin, (n, n_az)).copy()
    except ValueError:
        raise MaskError(
            f"margin_deg has shape {margin.shape}, expected a scalar or ({n}, {n_az})"
        ) from None
    bad_margin = ~(np.isfinite(margin) & (margin >= 0))
    if bad_margin.any():
        raise MaskError(
            f"margin_deg{_first_bad(bad_margin)} is negative or not finite; "
            "margins are degrees >= 0"
        )
    return margin


def _descriptor_arrays(descriptors: Mapping[str, ArrayLike], n: int) -> dict[str, NDArray]:
    """Descriptors as float64 copies of shape (n,), the required ones filled with NaN."""
    desc = {}
    for name, values in dict(descriptors).items():
        if not isinstance(name, str) or not _NAME_RE.match(name) or name in _CORE_NAMES:
            raise MaskError(
                f"descriptor name {name!r} is not allowed: use a lower-case identifier "
                "with a unit suffix (e.g. 'left_obstacle_distance_m') that is not a core "
                "column name"
            )
        desc[name] = _vector(values, f"descriptors[{name!r}]", n, allow_nan=True)
    for name in REQUIRED_DESCRIPTORS:
        desc.setdefault(name, np.full(n, np.nan))
    return desc


def _json_provenance(provenance: Mapping[str, Any]) -> JsonDict:
    """A copy of the provenance, which must be JSON-serialisable."""
    prov = dict(provenance)
    try:
        json.dumps(prov, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise MaskError(
            f"provenance must be JSON-serialisable (str, numbers, lists, dicts): {exc}"
        ) from None
    return prov


# ---------------------------------------------------------------------- helpers
def _vector(values: ArrayLike, name: str, n: int | None, allow_nan: bool = False) -> NDArray:
    arr = np.array(values, dtype=float)
    if arr.ndim != 1 or (n is not None and arr.size != n):
        want = "(n_pos,)" if n is None else f"({n},)"
        raise MaskError(f"{name} has shape {arr.shape}, expected {want}")
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MaskError(f"{name}[{i}] = {_num(arr[i])} is not finite; fix or drop that row")
    return arr


def _check_range(arr: NDArray, name: str, lo: float, hi: float) -> None:
    bad = ~((arr >= lo) & (arr <= hi))
    if bad.any():
        idx = np.unravel_index(int(np.flatnonzero(bad)[0]), arr.shape)
        where = ", ".join(str(int(k)) for k in idx)
        what = "row, bin" if arr.ndim == 2 else "row"
        value = arr[idx]
        if np.isnan(value):
            raise MaskError(
                f"{name}[{where}] ({what}) is NaN; every bin needs a value in "
                f"[{lo:g}, {hi:g}] (90 for a direction that is never open)"
            )
        raise MaskError(
            f"{name}[{where}] ({what}) = {_num(value)} is outside [{lo:g}, {hi:g}]; "
            "clip or fix the value"
        )


def _num(x: Any) -> str:
    """A number for a message: ``123.5``, not ``np.float32(123.5)``."""
    return f"{float(x):.10g}"


def _first_bad(bad: NDArray) -> str:
    if not bad.any():
        return ""
    idx = np.unravel_index(int(np.flatnonzero(bad)[0]), bad.shape)
    return "[" + ", ".join(str(int(k)) for k in idx) + "] (row, bin)"


def _default_provenance(provenance: Mapping[str, Any] | None) -> JsonDict:
    prov = dict(provenance or {})
    prov.setdefault("software", "predisat")
    prov.setdefault("software_version", __version__)
    prov.setdefault("created_utc", datetime.now(UTC).isoformat(timespec="seconds"))
    return prov


CHECKED_PROVENANCE_KEYS = (
    "survey_hash", "track", "track_key", "antenna_height_m", "params", "side_check",
    "step_check", "capture_check", "lens_check", "positions_lacking_side",
    "survey_beside_track", "terrain", "registered_on", "merged_worst_case",
)  # fmt: skip
"""Provenance keys that readers act on (the antenna check, the survey checks' warnings, the
registration): :func:`concat_masksets` refuses parts that differ in one of them unless the
whole's provenance is given."""


def concat_masksets(parts: Sequence[MaskSet], provenance: JsonDict | None = None) -> MaskSet:
    """One mask set from parts covering disjoint, increasing chainage ranges.

    Parameters
    ----------
    parts : sequence of MaskSet
        Same ``az_step_deg``; positions strictly increasing across the parts.
    provenance : dict, optional
        Provenance of the result (default: that of the first part, when every part states
        the same of what readers check: :data:`CHECKED_PROVENANCE_KEYS`).

    Raises
    ------
    MaskError
        When the parts differ in azimuth step or overlap in chainage, or, without
        ``provenance``, in a checked provenance key.
    """
    if not parts:
        raise MaskError("concat_masksets: no parts given; process at least one chunk")
    step = parts[0].az_step_deg
    for k, p in enumerate(parts):
        if p.az_step_deg != step:
            raise MaskError(
                f"concat_masksets: part {k} has az_step_deg {p.az_step_deg}, part 0 has {step}; "
                "reprocess with one azimuth step"
            )
        # the first part's provenance would speak for all: a later part's survey warning or
        # higher antenna would be lost in silence (a review found it so)
        first = parts[0].provenance
        differ = [key for key in CHECKED_PROVENANCE_KEYS
                  if provenance is None and p.provenance.get(key) != first.get(key)]  # fmt: skip
        if differ:
            raise MaskError(
                f"concat_masksets: part {k} states another {', '.join(differ)} than part 0 in "
                "its provenance; pass provenance= stating the whole (or combine surveys of one "
                "place with `predisat merge`, which keeps each one's)"
            )
    names = sorted({n for p in parts for n in p.descriptors})

    def cat(attr: str) -> NDArray:
        return np.concatenate([getattr(p, attr) for p in parts])

    desc = {
        n: np.concatenate([p.descriptors.get(n, np.full(p.n_pos, np.nan)) for p in parts])
        for n in names
    }
    # support only when every part has it: a part without it would read as "no view"
    support = None
    if all(p.support is not None for p in parts):
        support = np.concatenate([np.asarray(p.support) for p in parts])
    return MaskSet.from_arrays(
        cat("chainage_m"), cat("lat_deg"), cat("lon_deg"), cat("h_m"), cat("heading_deg"),
        cat("mask_el_deg"), az_step_deg=step, source=cat("source"),
        margin_deg=cat("margin_deg"), descriptors=desc,
        provenance=dict(parts[0].provenance if provenance is None else provenance),
        support=support,
    )  # fmt: skip
