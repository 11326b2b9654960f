"""Mask-aware satellite selection over the current confidence interval.

The locator picks satellites before it knows exactly where it is: a satellite is trusted only
if it is above the effective mask (mask + margin, plus an optional extra margin) in its azimuth
bin at *every* position of the current interval ``[lo, hi]``, i.e. above
:meth:`predisat.masks.maskset.MaskSet.worst_case` of that stretch (`../shared/docs/DESIGN.md`, "The
trust decision").

Approximation: the satellite's azimuth and elevation are taken at one point of the interval
(its centre, or wherever the caller computed them). Seen from two points ``d`` apart, a
satellite 20 000 km away changes direction by about ``d / 20 000 km`` rad plus the tilt of the
local vertical, ``d / 6 371 km`` rad: under 0.004 deg over 400 m, far below mask bins of
0.5-1 deg and the margins. For long intervals (kilometres, e.g. after a tunnel) call
:func:`direction_at` at both ends and pass the lower elevation.

An interval reaching outside the masks' coverage trusts nothing there (``+inf`` mask) unless
``clip=True``; an unbounded interval (``-inf``/``+inf``) therefore trusts nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.sathia import AntennaPath
from predisat.availability.satellites import azel
from predisat.geodesy import enu_rotation
from predisat.masks.maskset import MaskSet
from predisat.readonly import freeze_array_fields

__all__ = ["Exclusion", "Selection", "direction_at", "select_satellites"]


class Exclusion(IntEnum):
    """Why a satellite is not trusted (0 = trusted)."""

    TRUSTED = 0
    EPHEMERIS_INVALID = 1  # ephemeris status not OK (unhealthy, stale, missing, inconsistent)
    NO_DIRECTION = 2  # azimuth or elevation is NaN
    OUTSIDE_COVERAGE = 3  # the interval reaches where no mask exists
    BELOW_MASK = 4  # at or below the worst-case effective mask over the interval


@dataclass(frozen=True)
class Selection:
    """Trusted satellites of one or more epochs.

    Attributes
    ----------
    trusted : ndarray of bool, shape (..., n_sat)
    reason : ndarray of uint8, shape (..., n_sat)
        :class:`Exclusion` codes (the first reason that applies, in code order).
    threshold_deg : ndarray of float32, shape (..., n_sat)
        Worst-case effective mask (+ extra margin) in each satellite's bin over the interval;
        ``inf`` outside coverage, NaN without a direction.
    el_deg : ndarray, shape (..., n_sat)
    sats : tuple of str
        Satellite ids (empty when not given).
    """

    trusted: NDArray
    reason: NDArray
    threshold_deg: NDArray
    el_deg: NDArray
    sats: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def count(self) -> NDArray:
        """Trusted satellites per epoch, shape (...)."""
        return self.trusted.sum(axis=-1)

    def report(self) -> pd.DataFrame:
        """One row per excluded (epoch, satellite): index, satellite, reason, el, threshold."""
        idx = np.argwhere(~self.trusted)
        names = np.array(self.sats or [str(k) for k in range(self.trusted.shape[-1])])
        cells = tuple(idx.T)
        return pd.DataFrame(
            {
                "epoch": [tuple(int(v) for v in r[:-1]) for r in idx],
                "sat": names[idx[:, -1]] if len(idx) else np.array([], str),
                "reason": [Exclusion(int(c)).name.lower() for c in self.reason[cells]],
                "el_deg": self.el_deg[cells],
                "threshold_deg": self.threshold_deg[cells],
            }
        )


def direction_at(
    path: AntennaPath, chainage_m: ArrayLike, sat_ecef_m: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Azimuth and elevation of satellites from the antenna at chainages (geometric).

    Parameters
    ----------
    path : AntennaPath
    chainage_m : array_like, shape (...)
    sat_ecef_m : array_like, shape (n_sat, 3) or (n_epoch, n_sat, 3)

    Returns
    -------
    az_deg, el_deg : ndarray, shape ``chainage_m.shape + sat_ecef_m.shape[:-1]``
    """
    s = np.asarray(chainage_m, float)
    sat = np.asarray(sat_ecef_m, float)
    squeeze = sat.ndim == 2
    sat3 = sat[None] if squeeze else sat
    lat, lon, _ = path.track.position_at(s)
    az, el = azel(path.ecef_at(s), enu_rotation(lat, lon), sat3)
    if squeeze:
        az, el = az[..., 0, :], el[..., 0, :]
    return az, el


def select_satellites(
    masks: MaskSet,
    lo_m: ArrayLike,
    hi_m: ArrayLike,
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    *,
    valid: ArrayLike | None = None,
    extra_margin_deg: float = 0.0,
    clip: bool = False,
    sats: Sequence[str] = (),
) -> Selection:
    """Satellites above the worst-case mask of the interval ``[lo_m, hi_m]``.

    Parameters
    ----------
    masks : MaskSet
    lo_m, hi_m : array_like, shape (...)
        Current confidence interval per epoch, chainage metres, ``lo <= hi`` (may be
        infinite: nothing is then trusted unless ``clip``).
    az_deg, el_deg : array_like, shape (..., n_sat)
        Satellite directions at a point of the interval (module docstring).
    valid : array_like of bool, shape (..., n_sat), optional
        Ephemeris status OK (:attr:`predisat.gnss.ephemeris.EphemerisStatus.valid`); default all.
    extra_margin_deg : float
        Added to the masks' own margins, degrees >= 0.
    clip : bool
        Passed to :meth:`MaskSet.worst_case`: clip the interval to the coverage.
    sats : sequence of str
        Satellite ids, for :meth:`Selection.report`.

    Returns
    -------
    Selection
    """
    lo = np.asarray(lo_m, float)
    hi = np.asarray(hi_m, float)
    az = np.asarray(az_deg, float)
    el = np.asarray(el_deg, float)
    if az.shape != el.shape or az.ndim < 1:
        raise ValueError(
            f"az_deg and el_deg must share a shape (..., n_sat): {az.shape}, {el.shape}"
        )
    lo, hi = np.broadcast_arrays(lo, hi)
    if az.shape[:-1] != lo.shape:
        raise ValueError(
            f"lo_m/hi_m have shape {lo.shape} but az_deg/el_deg {az.shape}: give one interval "
            "per epoch, shape (...), and directions shaped (..., n_sat)"
        )
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise ValueError(
            "lo_m/hi_m contain NaN (no interval); use the prior +- its uncertainty instead"
        )
    if extra_margin_deg < 0:
        raise ValueError(f"extra_margin_deg must be >= 0, got {extra_margin_deg}")
    ok_eph = np.ones(az.shape, bool) if valid is None else np.asarray(valid, bool)
    if ok_eph.shape != az.shape:
        raise ValueError(f"valid must have shape {az.shape}, got {ok_eph.shape}")
    if sats and len(sats) != az.shape[-1]:
        raise ValueError(f"sats has {len(sats)} names but there are {az.shape[-1]} satellites")

    # an infinite bound reaches outside the coverage: clamp it there so worst_case sees it so
    b = masks.cell_bounds_m
    span = max(float(b[-1] - b[0]), 1.0)
    lo_c = np.clip(lo, b[0] - span, b[-1] + span)
    hi_c = np.clip(hi, b[0] - span, b[-1] + span)
    worst = masks.worst_case(lo_c, hi_c, clip=clip)  # (..., n_az)
    has_dir = np.isfinite(az) & np.isfinite(el)
    k = masks.bin_index(np.where(has_dir, az, 0.0))
    thr = np.take_along_axis(worst, k, axis=-1).astype(np.float32) + np.float32(extra_margin_deg)
    thr = np.where(has_dir, thr, np.float32(np.nan))

    reason = np.full(az.shape, Exclusion.TRUSTED, np.uint8)
    below = has_dir & ~(el > thr)
    reason[below] = Exclusion.BELOW_MASK
    reason[has_dir & np.isinf(thr)] = Exclusion.OUTSIDE_COVERAGE
    reason[~has_dir] = Exclusion.NO_DIRECTION
    reason[~ok_eph] = Exclusion.EPHEMERIS_INVALID
    return Selection(
        trusted=reason == Exclusion.TRUSTED,
        reason=reason,
        threshold_deg=thr,
        el_deg=el,
        sats=tuple(sats),
    )
