"""``predisat evaluate``: masks against synthetic ground truth, and margin calibration.

Issue 3, item 5: a satellite is trusted when its elevation exceeds the mask of its azimuth bin
plus a margin. :func:`calibrate_margin` finds, per group of bins (azimuth sector relative to the
track, bin source), the smallest margin such that the share of *trusted directions* that are
truly in line of sight reaches a target (0.999). A direction is a triple (position, azimuth
bin, elevation) with the elevation on a regular grid (``el_step_deg``, cell centres from 0 to
90 deg); it is trusted when ``el > mask + margin`` and truly in line of sight when
``el > truth`` (the true mask of the bin, :mod:`predisat.synth.truth`). Counting is analytic
per bin (number of grid elevations above a threshold), so no grid is materialised.

:func:`evaluate_masks` reports, per sector and source: median and 95th percentile of the
elevation error ``mask - truth`` (signed and absolute), the unsafe share of bins (``mask <
truth - 0.1 deg``), and with a margin table the false-trust rate (trusted but truly blocked,
among trusted directions) and the sky lost (truly visible directions not trusted, among truly
visible ones). Calibrate on one synthetic survey and evaluate on another made with a different
seed (``docs/pipeline.md``).

Sectors: ``cross`` when the azimuth is within 45 deg of ``heading +- 90`` (the cameras' look
directions), else ``along``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from predisat.jsontypes import JsonDict
from predisat.masks.margins import (
    EL_STEP_DEG,
    MARGIN_GROUP_OF,
    MARGIN_SOURCES,
    SECTORS,
    MarginTable,
    sector_of,
)
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.truth import TrueMasks

__all__ = [
    "UNSAFE_TOL_DEG",
    "Comparison",
    "applied_margins",
    "calibrate_margin",
    "compare",
    "count_above",
    "evaluate_masks",
    "format_table",
    "load_truth",
    "position_false_trust",
    "trust_counts",
]

UNSAFE_TOL_DEG = 0.1
"""A bin is unsafe when its mask is more than this below the truth."""
_SOURCE_NAMES = {int(s): s.name.lower() for s in BinSource}


def count_above(threshold_deg: ArrayLike, el_step_deg: float = EL_STEP_DEG) -> NDArray:
    """Number of grid elevations ``(k + 0.5) * step`` in (0, 90) strictly above a threshold."""
    n = round(90.0 / el_step_deg)
    grid = (np.arange(n) + 0.5) * el_step_deg
    # searchsorted on the grid itself: exact at thresholds equal to a grid elevation
    return (n - np.searchsorted(grid, np.asarray(threshold_deg, float), side="right")).astype(
        np.int64
    )


def trust_counts(
    mask_el_deg: ArrayLike,
    truth_el_deg: ArrayLike,
    margin_deg: ArrayLike = 0.0,
    el_step_deg: float = EL_STEP_DEG,
) -> tuple[NDArray, NDArray, NDArray]:
    """Per bin: trusted directions, trusted and truly visible, truly visible.

    Returns
    -------
    trusted, trusted_los, los : ndarray of int64, broadcast shape of the inputs
    """
    m = np.asarray(mask_el_deg, float) + np.asarray(margin_deg, float)
    t = np.asarray(truth_el_deg, float)
    return (
        count_above(m, el_step_deg),
        count_above(np.maximum(m, t), el_step_deg),
        count_above(t, el_step_deg) + np.zeros(np.broadcast(m, t).shape, np.int64),
    )


@dataclass(frozen=True, eq=False)
class Comparison:
    """Masks and truth on common positions and bins, flattened to one row per bin.

    Attributes
    ----------
    chainage_m : ndarray, shape (n_pos,)
        The matched positions.
    mask_el_deg, truth_el_deg : ndarray, shape (n_pos, n_az)
        The mask (without margin) and the true mask, on the truth's azimuth bins.
    source : ndarray of uint8, shape (n_pos, n_az)
    sector : ndarray of str, shape (n_pos, n_az)
    az_deg : ndarray, shape (n_az,)
    unmatched : int
        Mask positions with no truth position within the tolerance (left out).
    heading_deg : ndarray, shape (n_pos,), optional
        Track heading at the positions (direction of increasing chainage), degrees.
    margin_deg : ndarray, shape (n_pos, n_az), optional
        The mask file's own margins on the same bins, degrees (None: no margin).
    support : ndarray of uint8, shape (n_pos, n_az), optional
        The mask file's support (independent views per bin; None: a file without it).
    """

    chainage_m: NDArray
    mask_el_deg: NDArray
    truth_el_deg: NDArray
    source: NDArray
    sector: NDArray
    az_deg: NDArray
    unmatched: int = 0
    heading_deg: NDArray | None = None
    margin_deg: NDArray | None = None
    support: NDArray | None = None

    @property
    def error_deg(self) -> NDArray:
        """``mask - truth`` per bin, degrees."""
        return self.mask_el_deg - self.truth_el_deg


def load_truth(path: str | os.PathLike[str]) -> TrueMasks:
    """:class:`~predisat.masks.truth.TrueMasks` from a generator output folder, its ``truth/``
    folder or the ``true_masks.npz`` file itself."""
    p = Path(path)
    for cand in (p, p / "true_masks.npz", p / "truth" / "true_masks.npz"):
        if cand.is_file():
            return TrueMasks.load(cand)
    raise FileNotFoundError(
        f"{p}: no true_masks.npz there (give the generator's output folder, its truth/ "
        "folder or the .npz file)"
    )


def compare(masks: MaskSet, truth: TrueMasks, tol_m: float = 0.5) -> Comparison:
    """Pair each mask position with the truth position at the same chainage.

    Parameters
    ----------
    masks : MaskSet
    truth : TrueMasks
        ``chainage_m`` (n,), ``az_deg`` (n_az,), ``mask_el_deg`` (n, n_az).
    tol_m : float
        Largest chainage difference of a pair.

    Raises
    ------
    ValueError
        When no position pairs up (wrong truth folder or track).
    """
    ts = np.asarray(truth.chainage_m, float)
    order = np.argsort(ts)
    ts_sorted = ts[order]
    j = np.clip(np.searchsorted(ts_sorted, masks.chainage_m), 1, max(ts.size - 1, 1))
    cand = np.stack([j - 1, np.minimum(j, ts.size - 1)])
    dist = np.abs(ts_sorted[cand] - masks.chainage_m)
    best = cand[np.argmin(dist, axis=0), np.arange(masks.n_pos)]
    ok = np.abs(ts_sorted[best] - masks.chainage_m) <= tol_m
    if not ok.any():
        raise ValueError(
            f"no mask position (chainage {masks.chainage_m[0]:.1f}..{masks.chainage_m[-1]:.1f} "
            f"m) has a truth position within {tol_m} m (truth covers {ts.min():.1f}.."
            f"{ts.max():.1f} m); evaluate masks against the truth of the same survey"
        )
    ti = order[best[ok]]
    az = np.asarray(truth.az_deg, float)
    k = masks.bin_index(az)
    mi = np.flatnonzero(ok)
    mask = masks.mask_el_deg[mi][:, k].astype(float)
    heading = masks.heading_deg[mi]
    return Comparison(
        chainage_m=masks.chainage_m[mi],
        mask_el_deg=mask,
        truth_el_deg=np.asarray(truth.mask_el_deg, float)[ti],
        source=masks.source[mi][:, k],
        sector=sector_of(az[None, :], heading[:, None]),
        az_deg=az,
        unmatched=int((~ok).sum()),
        heading_deg=np.asarray(heading, float),
        margin_deg=np.broadcast_to(masks.margin_deg, masks.mask_el_deg.shape)[mi][:, k].astype(
            float
        ),
        support=None if masks.support is None else masks.support[mi][:, k],
    )


def calibrate_margin(
    comparison: Comparison,
    target: float = 0.999,
    by: Sequence[str] = ("sector", "source"),
    candidates_deg: ArrayLike | None = None,
    el_step_deg: float = EL_STEP_DEG,
    confidence: float | None = None,
    n_boot: int = 400,
    seed: int = 0,
    block_m: float = 200.0,
    min_positions: int = 10,
) -> MarginTable:
    """Smallest margin per group making trusted directions truly in line of sight >= target.

    Parameters
    ----------
    comparison : Comparison
    target : float
        Required share of trusted directions that are truly in line of sight.
    by : sequence of {"sector", "source"}
        Grouping; an empty sequence gives one margin for every bin.
    candidates_deg : array_like, optional
        Margins tried in increasing order (default 0 to 30 deg by 0.1 deg). A group whose
        target is not met at the last one gets 90 deg (nothing trusted) and ``reached=False``.
    el_step_deg : float
    confidence : float, optional
        When given, the margin must reach the target not only on this survey but on surveys
        like it: the line is resampled (``n_boot`` times, generator ``seed``) as blocks of
        consecutive positions ``block_m`` long, drawn with replacement (a moving-block
        bootstrap: neighbouring positions share their scenery), and each group gets the
        ``confidence`` quantile of the resamples' smallest margins. Without it the margin is
        the in-sample point estimate, which on another survey may fall short of the target
        (``docs/pipeline.md``: 0.12-0.23 % false trust out of sample for a 0.1 % target).
    n_boot, seed : int
        Resamples and their generator seed (``confidence`` only).
    block_m : float
        Block length of the resampling, metres of chainage (``confidence`` only).
    min_positions : int
        A group whose bins come from fewer positions is too small to calibrate on its own
        (``sampled = False``): it gets the largest margin of its own estimate and of the
        sampled groups of its sector (90 deg when there is none).

    Returns
    -------
    MarginTable
    """
    _check_calibration(target, by, confidence, n_boot)
    cands = (
        np.round(np.arange(0.0, 30.0 + 1e-9, 0.1), 6)
        if candidates_deg is None
        else np.sort(np.asarray(candidates_deg, float))
    )
    m = comparison.mask_el_deg.ravel()
    t = comparison.truth_el_deg.ravel()
    sec = comparison.sector.ravel() if "sector" in by else np.full(m.size, "*")
    src_names = np.array([_SOURCE_NAMES[MARGIN_GROUP_OF[c]] for c in range(len(BinSource))])[
        comparison.source.ravel()
    ]
    src = src_names if "source" in by else np.full(m.size, "*")
    n_pos = comparison.mask_el_deg.shape[0]
    pos = np.repeat(np.arange(n_pos), comparison.mask_el_deg.shape[1])
    weights = (
        _block_weights(comparison.chainage_m, block_m, n_boot, seed)
        if confidence is not None
        else None
    )
    rows: list[JsonDict] = []
    sels: list[NDArray] = []
    los_all = count_above(t, el_step_deg)
    for s_name in ("cross", "along") if "sector" in by else ("*",):
        for c_name in MARGIN_SOURCES if "source" in by else ("*",):
            sel = (sec == s_name) & (src == c_name)
            margin, reached, share = 90.0, False, float("nan")
            if sel.any():
                margin, reached, share = _group_margin(
                    m[sel], t[sel], pos[sel], cands, target, el_step_deg, weights, confidence
                )
                # masks raised to the terrain: their TERRAIN bins share the ASSUMED group's
                # margin, but the DEM bounds them and their line of sight would dilute the
                # bins still assumed (a user trial's canyon: 0.118 % of the assumed bins
                # trusted falsely, 0.045 % pooled with the terrain bins, margin 0); the
                # group's margin must hold for the assumed bins alone as well
                own = sel & (comparison.source.ravel() != BinSource.TERRAIN)
                if own.any() and not own[sel].all() and (
                        np.unique(pos[own]).size >= min_positions):  # fmt: skip
                    m2, r2, s2 = _group_margin(
                        m[own], t[own], pos[own], cands, target, el_step_deg, weights, confidence
                    )
                    if m2 > margin:
                        margin, reached, share = m2, r2, s2
            n_group_pos = int(np.unique(pos[sel]).size)
            sels.append(sel)
            rows.append({
                "sector": s_name, "source": c_name, "margin_deg": margin,
                "n_bins": int(sel.sum()), "n_positions": n_group_pos,
                "sampled": n_group_pos >= min_positions, "reached": reached,
                "los_share": share,
            })  # fmt: skip
    _settle_groups(rows, sels, m, t, el_step_deg)
    table = pd.DataFrame(rows)
    meta = {"n_positions": int(comparison.chainage_m.size), "by": list(by),
            "truly_visible_directions": int(los_all.sum()), "confidence": confidence,
            "n_boot": n_boot if confidence is not None else 0, "seed": seed,
            "block_m": block_m, "min_positions": min_positions}  # fmt: skip
    return MarginTable(_expand(table, by), float(target), el_step_deg, meta)


def _check_calibration(
    target: float, by: Sequence[str], confidence: float | None, n_boot: int
) -> None:
    """Fail on a target, grouping, confidence or resample count :func:`calibrate_margin`
    cannot use."""
    if not 0.0 < target <= 1.0:
        raise ValueError(f"target must be in (0, 1], got {target}")
    if confidence is not None and not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1) (e.g. 0.95), got {confidence}")
    if confidence is not None and n_boot < 10:
        raise ValueError(f"n_boot must be at least 10, got {n_boot}")
    bad = set(by) - {"sector", "source"}
    if bad:
        raise ValueError(f"by may hold 'sector' and 'source' only, got {sorted(bad)}")


def _group_margin(
    mask_el: NDArray,
    truth_el: NDArray,
    pos: NDArray,
    cands: NDArray,
    target: float,
    el_step_deg: float,
    weights: NDArray | None,
    confidence: float | None,
) -> tuple[float, bool, float]:
    """Margin, target reached, line-of-sight share of one group's bins, shape (n_bins,) each.

    The smallest candidate reaching ``target`` (with ``weights``: the ``confidence`` quantile
    of the resamples' smallest); (90, False, NaN) when none does.
    """
    mm, tt = mask_el[None, :], truth_el[None, :]
    trusted, good, _ = trust_counts(mm, tt, cands[:, None], el_step_deg)
    n_tr, n_good = trusted.sum(axis=1), good.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(n_tr > 0, n_good / np.maximum(n_tr, 1), 1.0)
    ok = np.flatnonzero(ratio >= target)
    if ok.size and weights is not None and confidence is not None:
        firsts = _bootstrap_index(trusted, good, pos, weights, target)
        first = min(int(np.ceil(np.quantile(firsts, confidence))), cands.size)
        ok = np.arange(first, cands.size)
    if ok.size:
        return float(cands[ok[0]]), True, float(ratio[ok[0]])
    return 90.0, False, float("nan")


def _settle_groups(
    rows: list[JsonDict], sels: list[NDArray], m: NDArray, t: NDArray, el_step_deg: float
) -> None:
    """Give the unsampled groups their sector's largest margin and every group its sky lost.

    ``rows`` (modified in place) and ``sels`` (bin selections) are one per group.
    """
    for r, sel in zip(rows, sels, strict=True):
        if not r["sampled"]:
            peers = [q["margin_deg"] for q in rows if q["sampled"] and q["sector"] == r["sector"]]
            r["margin_deg"] = max([r["margin_deg"], *peers]) if peers else 90.0
        if sel.any():
            tr1, good1, los1 = trust_counts(m[sel], t[sel], r["margin_deg"], el_step_deg)
            r["sky_lost"] = float(1.0 - good1.sum() / max(int(los1.sum()), 1))
            if not r["sampled"] and tr1.sum() > 0:
                r["los_share"] = float(good1.sum() / tr1.sum())
        else:
            r["sky_lost"] = float("nan")


def _block_weights(chainage_m: NDArray, block_m: float, n_boot: int, seed: int) -> NDArray:
    """Multiplicity of every position in ``n_boot`` moving-block resamples, (n_boot, n_pos).

    Blocks of ``L`` consecutive positions (``L`` = ``block_m`` over the median spacing),
    wrapped around the end of the line, start at uniformly drawn positions until the resample
    holds as many positions as the line.
    """
    s = np.asarray(chainage_m, float)
    n = s.size
    if not block_m > 0:
        raise ValueError(f"block_m must be positive metres, got {block_m}")
    step = float(np.median(np.diff(s))) if n > 1 else block_m
    length = int(min(n, max(1, round(block_m / step)))) if step > 0 else 1
    n_blocks = int(np.ceil(n / length))
    starts = np.random.default_rng(seed).integers(0, n, (n_boot, n_blocks))
    idx = (starts[..., None] + np.arange(length)).reshape(n_boot, -1)[:, :n] % n
    w = np.zeros((n_boot, n), np.int64)
    np.add.at(w, (np.arange(n_boot)[:, None], idx), 1)
    return w


def _bootstrap_index(
    trusted: NDArray, good: NDArray, pos: NDArray, weights: NDArray, target: float
) -> NDArray:
    """Index of the smallest candidate reaching ``target`` in each position resample.

    ``trusted``, ``good``: (n_cand, n_bins) counts of one group; ``pos``: (n_bins,) position
    index of each bin, non-decreasing; ``weights``: (n_boot, n_pos) resample multiplicities.
    A resample where no candidate reaches the target gets ``n_cand``.
    """
    uniq, starts = np.unique(pos, return_index=True)
    t_pos = np.add.reduceat(trusted, starts, axis=1).astype(float)  # (n_cand, n_u)
    g_pos = np.add.reduceat(good, starts, axis=1).astype(float)
    w = weights[:, uniq].astype(float)  # (n_boot, n_u)
    n_tr, n_good = w @ t_pos.T, w @ g_pos.T  # (n_boot, n_cand)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(n_tr > 0, n_good / np.maximum(n_tr, 1.0), 1.0)
    ok = ratio >= target
    return np.where(ok.any(axis=1), ok.argmax(axis=1), trusted.shape[0])


def _expand(table: pd.DataFrame, by: Sequence[str]) -> pd.DataFrame:
    """Spell out wildcard groups so that ``margin_for`` looks up (sector, source) pairs."""
    rows = []
    for r in table.to_dict(orient="records"):
        secs = SECTORS if r["sector"] == "*" else (r["sector"],)
        srcs = MARGIN_SOURCES if r["source"] == "*" else (r["source"],)
        for s in secs:
            for c in srcs:
                rows.append({**r, "sector": s, "source": c})
    return pd.DataFrame(rows)


def applied_margins(comparison: Comparison, margins: MarginTable | None) -> NDArray | None:
    """The margin of every bin that an evaluation scores, shape (n_pos, n_az), degrees:
    ``margins``' when given, else the mask file's own when any is above 0, else None."""
    if margins is not None:
        return margins.margin_for(comparison.sector, comparison.source)
    own = comparison.margin_deg
    if own is not None and bool((own > 0).any()):
        return np.asarray(own, float)
    return None


def evaluate_masks(
    comparison: Comparison, margins: MarginTable | None = None, el_step_deg: float = EL_STEP_DEG
) -> pd.DataFrame:
    """Accuracy table per sector and source (plus ``all`` rows).

    Columns: ``sector``, ``source``, ``n_bins``, ``median_error_deg``, ``p95_error_deg``
    (signed ``mask - truth``), ``median_abs_error_deg``, ``p95_abs_error_deg``,
    ``unsafe_share`` (bins with ``mask < truth - 0.1``), and for margin 0 and for ``margins``
    (when given; else the mask file's own margins, when any is above 0):
    ``false_trust[_margin]`` (trusted directions truly blocked / trusted),
    ``sky_lost[_margin]`` (truly visible directions not trusted / truly visible).
    """
    err = comparison.error_deg.ravel()
    m = comparison.mask_el_deg.ravel()
    t = comparison.truth_el_deg.ravel()
    sec = comparison.sector.ravel()
    src = np.array([_SOURCE_NAMES[c] for c in range(len(BinSource))])[comparison.source.ravel()]
    applied = applied_margins(comparison, margins)
    marg = None if applied is None else applied.ravel()
    rows = []
    groups = [(s, c) for s in (*SECTORS, "all") for c in (*_SOURCE_NAMES.values(), "all")]
    for s_name, c_name in groups:
        sel = np.ones(m.size, bool)
        if s_name != "all":
            sel &= sec == s_name
        if c_name != "all":
            sel &= src == c_name
        n = int(sel.sum())
        row: JsonDict = {"sector": s_name, "source": c_name, "n_bins": n}
        if n:
            e = err[sel]
            row |= {
                "median_error_deg": float(np.median(e)),
                "p95_error_deg": float(np.percentile(e, 95)),
                "median_abs_error_deg": float(np.median(np.abs(e))),
                "p95_abs_error_deg": float(np.percentile(np.abs(e), 95)),
                "unsafe_share": float(np.mean(e < -UNSAFE_TOL_DEG)),
            }
            for suffix, mg in (("", 0.0), ("_margin", marg)):
                if mg is None:
                    continue
                mg_sel = mg if np.isscalar(mg) else np.asarray(mg)[sel]
                tr, good, los = trust_counts(m[sel], t[sel], mg_sel, el_step_deg)
                row[f"false_trust{suffix}"] = (
                    float(1.0 - good.sum() / tr.sum()) if tr.sum() else 0.0
                )
                # no direction truly visible (a tunnel): no sky to lose, not 0 % lost
                row[f"sky_lost{suffix}"] = (
                    float(1.0 - good.sum() / los.sum()) if los.sum() else float("nan")
                )
        rows.append(row)
    return pd.DataFrame(rows)


POSITION_LIMIT = 0.001
"""The per-position false trust limit of the project's targets (0.1 % of a position's trusted
directions)."""


def position_false_trust(
    comparison: Comparison, margin_deg: ArrayLike = 0.0, el_step_deg: float = EL_STEP_DEG
) -> NDArray:
    """False trust of each position: its trusted directions truly blocked over its trusted
    directions (0 where nothing is trusted).

    Parameters
    ----------
    comparison : Comparison
    margin_deg : array_like
        Added to the masks, broadcast to ``(n_pos, n_az)``, degrees.
    el_step_deg : float
        The elevation grid's step, degrees.

    Returns
    -------
    ndarray, shape (n_pos,)
        Shares in [0, 1].
    """
    tr, good, _ = trust_counts(comparison.mask_el_deg, comparison.truth_el_deg, margin_deg,
                               el_step_deg)  # fmt: skip
    n_tr = tr.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n_tr > 0, (n_tr - good.sum(axis=1)) / np.maximum(n_tr, 1), 0.0)


# ---------------------------------------------------------------------- command line
def format_table(table: pd.DataFrame) -> str:
    """Text of an :func:`evaluate_masks` table for people: shares in percent.

    The share columns (``sky_lost``, ``false_trust``, ``unsafe_share`` and their ``_margin``
    variants, fractions in the table and its CSV) are printed in percent under a ``_%`` name
    (``sky_lost_%``): ``sky_lost`` with 2 decimals, the rare-event shares in scientific
    notation, which 2 decimals would print as 0 (the target is 0.1 %, the pipeline reaches
    ~1e-4 %); other numbers with 4 decimals."""
    rare = [c for c in table.columns if c.startswith(("unsafe_share", "false_trust"))]
    shares = rare + [c for c in table.columns if c.startswith("sky_lost")]
    shown = table.copy()
    shown[shares] = 100.0 * shown[shares]
    shown = shown.round({c: 4 for c in table.columns if c not in shares})
    shown = shown.round({c: 2 for c in shares if c not in rare})
    formatters = {f"{c}_%": "{:.2e}".format for c in rare}
    shown = shown.rename(columns={c: f"{c}_%" for c in shares})
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        # NaN: a share of nothing (no visible sky to lose in a tunnel)
        return str(shown.to_string(index=False, formatters=formatters, na_rep="n/a"))
