"""Scoring a locator run against the true chainage.

An epoch's outcome, with ``truth`` the true antenna chainage:

* **inside**: ``lo <= truth <= hi``;
* **HMI** (hazardously misleading information): a safety claim (``claim``) and truth outside
  the interval, with no alarm - the event the masks exist to prevent;
* **MI** (misleading, alarmed): truth outside an interval that carries no claim (the flags
  warned the user);
* **fix-level HMI** (``hmi_fix``): truth outside an interval the fix itself claimed, before the
  heading and odometry checks of :mod:`locator.run` - what SATHIA and FDE alone would have
  let through.

:func:`score_run` adds these columns to the epoch table; :func:`summarise` reduces a table to
the figures of the issue: shares of epochs per integrity mode and with a claim, interval length
percentiles (claimed epochs), absolute error percentiles and the HMI counts.

**Stanford integrity diagram** (:func:`stanford_points`, :func:`stanford_counts`; drawn by
:func:`locator.plots.stanford_diagram`): each epoch with an estimate and a bounded interval is
a point ``(|error|, protection level)``. The protection level is the interval's extent from the
estimate toward the truth (``estimate - lo`` when the truth lies below the estimate, ``hi -
estimate`` above it: the half-interval on the error's side, the half length of a symmetric
interval), so that the truth lies outside the interval exactly when ``|error| > protection``
(the estimate, a weighted mean of pair roots, lies inside the interval). The regions:

* **normal**: a safety claim, ``|error| <= protection`` (<= the alert limit, when one is
  given);
* **HMI**: a safety claim and ``|error| > protection``: the truth outside a claimed interval
  (the ``hmi`` count of :func:`score_run`);
* **unavailable**: no safety claim (or a protection level above the alert limit) and ``|error|
  <= protection``: the locator said it could not vouch for the interval;
* **MI**: no claim (or above the alert limit) and ``|error| > protection``: misleading, but
  flagged (the ``mi`` count of :func:`score_run` without an alert limit);
* **no interval**: no estimate or an unbounded interval (not drawn).

Unlike the aviation diagram, whose alert limit separates MI (the error inside the alert limit)
from HMI, a claimed interval here *is* the protection: any claimed miss is hazardous.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from predisat.availability.interval import IntervalMode

__all__ = [
    "STANFORD_REGIONS",
    "claim_losses",
    "exclusions",
    "score_run",
    "stanford_counts",
    "stanford_points",
    "summarise",
]

STANFORD_REGIONS = ("normal", "hmi", "unavailable", "mi", "no_interval")
"""Regions of the Stanford diagram, in the order of :func:`stanford_counts` (module docstring)."""


def score_run(epochs: pd.DataFrame, truth_chainage_m: ArrayLike) -> pd.DataFrame:
    """The epoch table with truth, errors and outcome columns added (a new frame).

    Parameters
    ----------
    epochs : pandas.DataFrame
        :func:`locator.run.run_locator` output (``chainage_m``, ``lo_m``, ``hi_m``,
        ``wls_chainage_m``, ``claim``, ``claim_fix``).
    truth_chainage_m : array_like, shape (n_epoch,)
        True antenna chainage per row, metres.

    Returns
    -------
    pandas.DataFrame
        With ``truth_m``, ``error_m`` (estimate - truth), ``wls_error_m``, ``inside``,
        ``hmi``, ``hmi_fix``, ``mi``.
    """
    truth = np.asarray(truth_chainage_m, float)
    if truth.shape != (len(epochs),):
        raise ValueError(
            f"truth_chainage_m has shape {truth.shape} for {len(epochs)} epochs; give one true "
            "chainage per epoch (same order)"
        )
    out = epochs.copy()
    lo = out["lo_m"].to_numpy(float)
    hi = out["hi_m"].to_numpy(float)
    has = np.isfinite(lo) & np.isfinite(hi)
    inside = has & (lo <= truth) & (truth <= hi)
    claim = out["claim"].to_numpy(bool)
    out["truth_m"] = truth
    out["error_m"] = out["chainage_m"].to_numpy(float) - truth
    out["wls_error_m"] = out["wls_chainage_m"].to_numpy(float) - truth
    out["inside"] = inside
    out["hmi"] = claim & ~inside
    out["hmi_fix"] = out["claim_fix"].to_numpy(bool) & has & ~inside
    out["mi"] = has & ~claim & ~inside
    return out


def summarise(scored: pd.DataFrame) -> Mapping[str, float]:
    """Figures of a scored table (:func:`score_run`).

    Returns
    -------
    dict
        ``epochs``; ``claim_share``; ``mode_<name>_share`` per :class:`IntervalMode`;
        ``length_median_m`` / ``length_p95_m`` / ``length_max_m`` over claimed epochs;
        ``abs_error_median_m`` / ``abs_error_p95_m`` over epochs with an estimate (and the same
        for the WLS reference); ``hmi``, ``hmi_fix``, ``mi`` counts; ``inside_share`` of
        claimed epochs.
    """
    n = len(scored)
    den = max(n, 1)
    claim = scored["claim"].to_numpy(bool)
    out: dict[str, float] = {"epochs": float(n), "claim_share": float(claim.sum() / den)}
    mode = scored["mode"].to_numpy(str)
    for m in IntervalMode:
        out[f"mode_{m.name.lower()}_share"] = float((mode == m.name.lower()).sum() / den)
    length = scored["length_m"].to_numpy(float)[claim]
    length = length[np.isfinite(length)]
    q = np.percentile(length, [50, 95]) if len(length) else [np.nan, np.nan]
    out.update(
        length_median_m=float(q[0]),
        length_p95_m=float(q[1]),
        length_max_m=float(length.max()) if len(length) else np.nan,
    )
    for col, name in (("error_m", "abs_error"), ("wls_error_m", "wls_abs_error")):
        if col in scored:
            e = np.abs(scored[col].to_numpy(float))
            e = e[np.isfinite(e)]
            p = np.percentile(e, [50, 95]) if len(e) else [np.nan, np.nan]
            out[f"{name}_median_m"], out[f"{name}_p95_m"] = float(p[0]), float(p[1])
    for col in ("hmi", "hmi_fix", "mi"):
        if col in scored:
            out[col] = float(scored[col].to_numpy(bool).sum())
    if "inside" in scored:
        inside = scored["inside"].to_numpy(bool)
        out["inside_share"] = float(inside[claim].mean()) if claim.any() else np.nan
    if "truth_m" in scored:
        out.update({f"stanford_{k}": float(v) for k, v in stanford_counts(scored).items()})
    return out


def stanford_points(scored: pd.DataFrame, alert_limit_m: float | None = None) -> pd.DataFrame:
    """Each epoch's point and region of the Stanford diagram (module docstring).

    Parameters
    ----------
    scored : pandas.DataFrame
        :func:`score_run` output (``chainage_m``, ``lo_m``, ``hi_m``, ``truth_m``, ``claim``).
    alert_limit_m : float, optional
        Protection levels above it count as unavailable, claimed or not. Default: none.

    Returns
    -------
    pandas.DataFrame
        One row per epoch, same index: ``abs_error_m``, ``protection_m`` (NaN without an
        interval), ``region`` (one of :data:`STANFORD_REGIONS`).
    """
    if alert_limit_m is not None and not alert_limit_m > 0:
        raise ValueError(f"alert_limit_m must be positive, got {alert_limit_m}")
    missing = {"chainage_m", "lo_m", "hi_m", "truth_m", "claim"} - set(scored.columns)
    if missing:
        raise ValueError(
            f"stanford_points needs a scored table (locator.evaluate.score_run); missing "
            f"columns {sorted(missing)}"
        )
    est = scored["chainage_m"].to_numpy(float)
    lo = scored["lo_m"].to_numpy(float)
    hi = scored["hi_m"].to_numpy(float)
    truth = scored["truth_m"].to_numpy(float)
    err = est - truth  # > 0: the truth lies below the estimate, toward lo
    ok = np.isfinite(est) & np.isfinite(lo) & np.isfinite(hi) & np.isfinite(truth)
    pl = np.where(ok, np.where(err >= 0.0, est - lo, hi - est), np.nan)
    ae = np.abs(err)
    available = scored["claim"].to_numpy(bool) & ok
    if alert_limit_m is not None:
        available &= pl <= alert_limit_m
    miss = ok & (ae > pl)
    region = np.select(
        [~ok, available & ~miss, available & miss, ~miss],
        ["no_interval", "normal", "hmi", "unavailable"],
        "mi",
    )  # fmt: skip
    return pd.DataFrame(
        {"abs_error_m": ae, "protection_m": pl, "region": region}, index=scored.index
    )


def stanford_counts(scored: pd.DataFrame, alert_limit_m: float | None = None) -> dict[str, int]:
    """Epochs per region of the Stanford diagram, in :data:`STANFORD_REGIONS` order."""
    region = stanford_points(scored, alert_limit_m)["region"].to_numpy(str)
    return {r: int((region == r).sum()) for r in STANFORD_REGIONS}


# Why an epoch has no safety claim, first matching cause first: the flag bits of
# locator.fde.FixFlag and locator.run.RunFlag, by name.
_LOSS_CAUSES = (
    ("NO_ERROR_MODEL", "no calibrated error model applies to the data and the risk claimed "
     "(`locator calibrate`)"),
    ("TOO_FEW", "fewer than 2 trusted satellites"),
    ("FAULT_DETECTED", "fault detected and not isolated (NLOS, or an error model tighter than "
     "the ranges)"),
    ("INCONSISTENT_PAIRS", "pair intervals without a common point"),
    ("EMPTY_PAIR", "a pair contradicting the search window"),
    ("HEADING_FAIL", "heading check failed"),
    ("ODOMETRY_CONFLICT", "interval missing the odometry prediction"),
    ("START_CONFLICT", "start chainage contradicted by the satellites (prediction widened "
     "over both places), until fixes agree with it"),
    ("ODOMETRY_SUSPECT", "odometry suspect after a conflict, until fixes agree with it again"),
    ("OFF_TRACK", "the trusted satellites' 3-D fix beside the map beyond its doubt (a track "
     "the map lacks, or a reflected signal)"),
    ("TRACK_ALIAS", "the track passes beside the interval elsewhere (a loop's other leg) and "
     "nothing located the run where it is alone"),
    ("CLAIM_AT_TRACK_END", "interval bounded by an end of the track map (the train may be "
     "past it)"),
    ("UNBOUNDED", "interval reaching the search window's end"),
    ("AMBIGUOUS", "a pair cutting the track twice"),
    ("NO_ROOT", "a pair not cutting the track"),
)
# first: the row of such an epoch carries one stretch's fix (the longest's), whose own flags
# (a pair cutting the track twice, 2-3 satellites) say nothing of the other stretches
_STRETCH_CAUSE = ("NO_STRETCH_CLAIM", "no stretch of the predicted interval with a claim of "
                  "its own (partitioned trust)")  # fmt: skip


def claim_losses(epochs: pd.DataFrame) -> dict[str, float]:
    """Share of all epochs without a safety claim, by cause.

    Parameters
    ----------
    epochs : pandas.DataFrame
        :func:`locator.run.run_locator` output (``claim``, ``flag_names``, ``n_used``).

    Returns
    -------
    dict
        Cause (plain words) to share of epochs, largest first; each epoch without a claim
        counts once: partitioned trust without a stretch claiming inside itself
        (``NO_STRETCH_CLAIM``), else its first cause in :data:`_LOSS_CAUSES` order, or "2-3
        satellites (a fix without claim)" / "other" when no listed flag is set. Empty when
        every epoch has a claim.
    """
    n = max(len(epochs), 1)
    lost = epochs.loc[~epochs["claim"].to_numpy(bool)]
    counts: dict[str, int] = {}
    for names, n_used in zip(lost["flag_names"].astype(str), lost["n_used"], strict=True):
        flags = set(names.split("|"))
        cause = _STRETCH_CAUSE[1] if _STRETCH_CAUSE[0] in flags else None
        if cause is None:
            cause = next((text for flag, text in _LOSS_CAUSES if flag in flags), None)
        if cause is None:
            cause = "2-3 satellites (a fix without claim)" if n_used < 4 else "other"
        counts[cause] = counts.get(cause, 0) + 1
    return {k: v / n for k, v in sorted(counts.items(), key=lambda kv: -kv[1])}


_EXCLUDED = re.compile(r"([A-Z]\d{2}):(.*?)(?= [A-Z]\d{2}:|$)")


def exclusions(epochs: pd.DataFrame) -> dict[str, set[str]]:
    """Satellites kept out of the solution, by reason, over a whole run.

    Parameters
    ----------
    epochs : pandas.DataFrame
        With the ``excluded`` column of :func:`locator.run.run_locator` (``"G03:below_mask
        G08:fde ..."``).

    Returns
    -------
    dict
        Reason to the set of satellite ids excluded for it at least once.
    """
    out: dict[str, set[str]] = {}
    for text in epochs["excluded"].astype(str):
        for sat, why in _EXCLUDED.findall(text.strip()):
            out.setdefault(why.strip(), set()).add(sat)
    return out
