"""Fusion of the odometry interval with the satellite interval.

Between satellite claims the odometry carries the train: the last fused interval (the anchor)
moved by the odometer's displacement and widened by its over- and under-reading bounds
(:meth:`locator.odometry.confidence.OdometerAccuracy.displacement_bounds_m`); without an
odometer, by a maximum speed times the elapsed time. Where a satellite claim and the odometry
interval are both valid the fused interval is their **intersection**: each holds the train
unless its own error bound fails, so the intersection fails only when one of them does (the
risks add; nothing is assumed independent). A claimed satellite interval that does **not meet**
the odometry interval (or, stricter, whose estimate lies outside it) is an **alarm**: the two
sources contradict each other, the claim is voided and the odometry interval goes on unchanged
(never reset by the contradicting source).

The **estimate** inside the fused interval is a one-dimensional Kalman filter: the odometer
moves it (:func:`predict_estimate`, variance growing with the distance: the odometer's bounds
taken as 3 sigma of independent steps) and each claimed fix pulls it by inverse-variance
weighting (:func:`blend_estimate`). The estimate only places the train inside the interval
(e.g. for a virtual balise's passage time); the safety bounds are the intervals, never the
estimate's variance.

All functions are pure and vectorised over epochs (chainages in metres).
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.odometry.confidence import OdometerAccuracy

__all__ = [
    "Fused",
    "FusionStatus",
    "blend_estimate",
    "fuse_intervals",
    "motion_bound",
    "predict_estimate",
    "predict_interval",
]


class FusionStatus(IntEnum):
    """Where the fused interval of an epoch comes from."""

    ODOMETRY = 0  # no satellite claim: the odometry interval alone
    FUSED = 1  # a satellite claim meeting the odometry interval: the intersection
    CONFLICT = 2  # a claim missing the odometry interval (or its estimate outside): alarm
    SUSPECT = 3  # after a conflict, until claims agree with the odometry again: not to be used


class Fused(NamedTuple):
    """Fused interval per epoch.

    Attributes
    ----------
    lo_m, hi_m : ndarray
        Chainage bounds, m.
    status : ndarray of int8
        :class:`FusionStatus`.
    """

    lo_m: NDArray
    hi_m: NDArray
    status: NDArray


def predict_interval(
    lo_m: ArrayLike,
    hi_m: ArrayLike,
    odo_m: ArrayLike,
    accuracy: OdometerAccuracy,
    travelled_m: ArrayLike | None = None,
) -> tuple[NDArray, NDArray]:
    """An interval moved by a measured displacement and widened by the odometer's bounds.

    Parameters
    ----------
    lo_m, hi_m : array_like
        Anchor interval (chainage), m.
    odo_m : array_like
        Odometer displacement since the anchor, signed toward increasing chainage, m.
    accuracy : OdometerAccuracy
    travelled_m : array_like, optional
        Distance the wheels ran since the anchor, either way, m (None: ``abs(odo_m)``);
        see :meth:`OdometerAccuracy.displacement_bounds_m`.

    Returns
    -------
    lo_m, hi_m : ndarray
        ``[lo + min true displacement, hi + max true displacement]``.
    """
    d_lo, d_hi = accuracy.displacement_bounds_m(odo_m, travelled_m)
    return np.asarray(lo_m, float) + d_lo, np.asarray(hi_m, float) + d_hi


def motion_bound(
    lo_m: ArrayLike, hi_m: ArrayLike, elapsed_s: ArrayLike, accuracy: OdometerAccuracy
) -> tuple[NDArray, NDArray]:
    """Without an odometer: the train moved at most ``max_speed_mps`` either way.

    Returns ``[lo - g, hi + g]`` with ``g = abs_error_m + max_speed_mps * elapsed_s``.
    """
    g = accuracy.abs_error_m + accuracy.max_speed_mps * np.abs(np.asarray(elapsed_s, float))
    return np.asarray(lo_m, float) - g, np.asarray(hi_m, float) + g


def fuse_intervals(
    odo_lo_m: ArrayLike,
    odo_hi_m: ArrayLike,
    gnss_lo_m: ArrayLike,
    gnss_hi_m: ArrayLike,
    gnss_claim: ArrayLike,
    gnss_est_m: ArrayLike | None = None,
) -> Fused:
    """Fuse the odometry interval with a satellite interval, epoch by epoch.

    Parameters
    ----------
    odo_lo_m, odo_hi_m : array_like, shape (n,)
        Odometry (predicted) interval.
    gnss_lo_m, gnss_hi_m : array_like, shape (n,)
        Satellite interval (ignored where ``gnss_claim`` is False; may be NaN there).
    gnss_claim : array_like of bool, shape (n,)
        The satellite interval carries a safety claim.
    gnss_est_m : array_like, shape (n,), optional
        The satellite estimate; when given, a claim whose estimate lies outside the odometry
        interval is a conflict too (the stricter rule of ``RunConfig.odometry_conflict``).

    Returns
    -------
    Fused
        Intersection where the claim meets the odometry interval (``FUSED``), the odometry
        interval where there is no claim (``ODOMETRY``) or where the claim misses it
        (``CONFLICT``: an alarm, not a reset).
    """
    olo, ohi = np.asarray(odo_lo_m, float), np.asarray(odo_hi_m, float)
    glo, ghi = np.asarray(gnss_lo_m, float), np.asarray(gnss_hi_m, float)
    claim = np.asarray(gnss_claim, bool)
    with np.errstate(invalid="ignore"):
        meet = claim & (ghi >= olo) & (glo <= ohi)
        if gnss_est_m is not None:
            est = np.asarray(gnss_est_m, float)
            meet &= (est >= olo) & (est <= ohi)
    conflict = claim & ~meet
    lo = np.where(meet, np.maximum(olo, glo), olo)
    hi = np.where(meet, np.minimum(ohi, ghi), ohi)
    status = np.where(meet, FusionStatus.FUSED, FusionStatus.ODOMETRY)
    status = np.where(conflict, FusionStatus.CONFLICT, status).astype(np.int8)
    return Fused(lo, hi, status)


def predict_estimate(
    est_m: ArrayLike,
    var_m2: ArrayLike,
    odo_step_m: ArrayLike,
    accuracy: OdometerAccuracy,
    floor_m: float = 0.05,
) -> tuple[NDArray, NDArray]:
    """Move an estimate by an odometer step and grow its variance.

    ``var += (max(over_rel, under_rel) / 3 * |step|)^2 + floor_m^2``: the odometer's bound
    read as 3 sigma, steps independent (a filter model, not a bound).

    Parameters
    ----------
    est_m, var_m2 : array_like
        Estimate (chainage, m) and its variance (m^2).
    odo_step_m : array_like
        Odometer step, signed toward increasing chainage, m.
    accuracy : OdometerAccuracy
    floor_m : float
        Standard deviation added per step (timing, quantisation), m.
    """
    d = np.asarray(odo_step_m, float)
    rel = max(accuracy.over_rel, accuracy.under_rel) / 3.0
    return np.asarray(est_m, float) + d, np.asarray(var_m2, float) + (rel * d) ** 2 + floor_m**2


def blend_estimate(
    pred_m: ArrayLike, pred_var_m2: ArrayLike, fix_m: ArrayLike, fix_var_m2: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Inverse-variance combination of a predicted estimate and a fix (the Kalman update).

    Returns the combined estimate and variance; where either variance is not finite and
    positive, the fix alone.
    """
    p, pv = np.asarray(pred_m, float), np.asarray(pred_var_m2, float)
    f, fv = np.asarray(fix_m, float), np.asarray(fix_var_m2, float)
    ok = np.isfinite(pv) & np.isfinite(fv) & (pv > 0) & (fv > 0) & np.isfinite(p)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(ok, pv / (pv + fv), 1.0)
    est = np.where(ok, p + gain * (np.where(ok, f, p) - p), f)
    return est, np.where(ok, (1.0 - gain) * pv, fv)
