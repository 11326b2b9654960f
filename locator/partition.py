"""Partitioned trust: one trusted set per stretch of the predicted interval, one claim from all.

The trust rule of :func:`locator.selection.select_satellites` keeps a satellite only above the
worst mask over the *whole* predicted interval ``[lo, hi]``. A wall at one end of the interval
then removes a satellite everywhere, also where the sky is open; a wider interval removes more,
fewer pairs make the next claim wider, and the loop feeds itself (``docs/locator.md``,
"Partitioned trust").

Here the interval is cut into **stretches** of whole mask cells over which the trusted set is
constant (:func:`trust_stretches`; adjacent stretches are merged, each merged stretch taking the
worst mask of its cells, until at most ``max_stretches`` are left). Each stretch ``j`` gets its
own trusted set ``S_j`` and its own fix; :func:`combine_stretches` keeps, of each claimed fix,
the part of its interval inside its own stretch, takes a stretch whose fix made no claim as a
whole, and claims the hull of the parts.

**Why it is safe.** The train is somewhere in the predicted interval (the prediction's own risk,
``P_pred``), hence in one stretch ``j*``. There every satellite of ``S_j*`` is above the mask
(the stretch's worst case), so the fix of ``j*`` is a fix on line-of-sight satellites as the
single-set rule's, and its claim holds the train but with the integrity budget's risk ``T``.
The part ``claim_j* ∩ stretch_j*`` then holds the train, and so does the hull. The other
stretches' fixes may use satellites blocked at the train: they can only add parts, never remove
the true one, so ``P(miss) <= P_pred + T`` as with the single set. A stretch whose fix claims
nothing (too few satellites, heading check failed) cannot exclude the train: it is kept whole.
When every claimed part is empty and no stretch is kept whole the claims contradict the
prediction: the odometry conflict of the single-set rule (``conflict``).

Faults (NLOS the masks missed, a wrong ephemeris) stay the trust decision's and FDE's share;
the odometry check sees them less often here, since a fix whose interval misses its own stretch
is read as "the train is elsewhere" (``docs/locator.md``).

Boundaries: a stretch is a run of whole mask cells, ``[b_i, b_j]`` clipped to the interval
(:attr:`predisat.masks.maskset.MaskSet.cell_bounds_m`); a cell touching the interval at a
single point is not counted (the single-set rule counts it), a zero-probability chainage.
Parts of the interval outside the masks' coverage are stretches that trust nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.selection import Exclusion, Selection
from predisat.masks.maskset import MaskSet

__all__ = ["MAX_STRETCHES", "Combined", "Stretch", "combine_stretches", "trust_stretches"]

MAX_STRETCHES = 16
"""Stretches per epoch of the partitioned rule (``RunConfig.trust_stretches``): a fix each, so
the cost of an epoch grows up to this many times where the trusted set changes. Until
2026-12-05 it was 3: the pipeline's masks change a satellite's trust every few cells (15 runs
of cells per prediction on the demo), and merging them into 3 put one cell's dip on a whole
stretch; the demo's claims went from 12.5 to 32.4 % at 12, and no further at 16 or 30
(``docs/locator.md``, "Partitioned trust"). The safety argument holds for any number."""


@dataclass(frozen=True)
class Stretch:
    """A stretch of the predicted interval with its trusted satellites.

    Attributes
    ----------
    lo_m, hi_m : float
        Chainage bounds, metres (the interval's, or a mask cell edge).
    selection : Selection
        Trusted satellites over the stretch (worst mask of its cells), shape (n_sat,).
    """

    lo_m: float
    hi_m: float
    selection: Selection

    @property
    def length_m(self) -> float:
        return self.hi_m - self.lo_m


@dataclass(frozen=True)
class Combined:
    """The claim of a partitioned epoch (:func:`combine_stretches`).

    Attributes
    ----------
    lo_m, hi_m : float
        Hull of the parts (claimed intervals cut to their stretches, unclaimed stretches
        whole); on a conflict the hull of the claimed intervals themselves; NaN without any.
    claim : bool
        At least one claimed part is non-empty, no conflict, and the hull is shorter than the
        predicted interval (a hull equal to it says nothing the odometry does not).
    conflict : bool
        The claims contradict the prediction: every claimed part is empty and no stretch is
        kept whole, or (``estimate_inside``) every fix with a claimed part puts its estimate
        outside the predicted interval.
    chosen : int
        Stretch whose fix gives the estimate, mode and used satellites (-1 without a fix).
    parts : int
        Non-empty parts united.
    """

    lo_m: float
    hi_m: float
    claim: bool
    conflict: bool
    chosen: int
    parts: int


def trust_stretches(
    masks: MaskSet,
    lo_m: float,
    hi_m: float,
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    *,
    max_stretches: int = MAX_STRETCHES,
    valid: ArrayLike | None = None,
    extra_margin_deg: float = 0.0,
    sats: Sequence[str] = (),
) -> tuple[Stretch, ...]:
    """Cut ``[lo_m, hi_m]`` into at most ``max_stretches`` stretches of constant trusted set.

    Parameters
    ----------
    masks : MaskSet
    lo_m, hi_m : float
        Predicted interval, chainage metres, finite, ``lo <= hi``.
    az_deg, el_deg : array_like, shape (n_sat,)
        Satellite directions at a point of the interval (:mod:`locator.selection`).
    max_stretches : int
        At most this many stretches, >= 1. Adjacent runs of cells are merged while there are
        more, each time the pair whose merge loses the fewest satellite-metres (a satellite
        trusted over ``L`` metres of a stretch and not in the merged set loses ``L``).
    valid : array_like of bool, shape (n_sat,), optional
        Ephemeris status OK; default all.
    extra_margin_deg : float
        Added to the masks' own margins, degrees >= 0.
    sats : sequence of str

    Returns
    -------
    tuple of Stretch
        In chainage order, contiguous (each stretch starts where the previous ends), covering
        ``[lo_m, hi_m]``.
    """
    lo, hi = float(lo_m), float(hi_m)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"lo_m, hi_m must be finite with lo <= hi, got {lo_m}, {hi_m}")
    if int(max_stretches) != max_stretches or max_stretches < 1:
        raise ValueError(f"max_stretches must be an integer >= 1, got {max_stretches}")
    if extra_margin_deg < 0:
        raise ValueError(f"extra_margin_deg must be >= 0, got {extra_margin_deg}")
    az = np.asarray(az_deg, float)
    el = np.asarray(el_deg, float)
    if az.shape != el.shape or az.ndim != 1:
        raise ValueError(f"az_deg and el_deg must have one shape (n_sat,): {az.shape}, {el.shape}")
    ok_eph = np.ones(az.shape, bool) if valid is None else np.asarray(valid, bool)
    if ok_eph.shape != az.shape:
        raise ValueError(f"valid must have shape {az.shape}, got {ok_eph.shape}")
    if sats and len(sats) != az.size:
        raise ValueError(f"sats has {len(sats)} names but there are {az.size} satellites")

    has_dir = np.isfinite(az) & np.isfinite(el)
    k = masks.bin_index(np.where(has_dir, az, 0.0))
    bounds, thr = _cell_pieces(masks, lo, hi, k, extra_margin_deg)  # (p + 1,), (p, n_sat)
    ok = has_dir & ok_eph
    trusted = ok & (el > thr)  # (p, n_sat); inf thresholds (outside coverage) trust nothing
    # runs of equal trusted sets, then merges down to max_stretches
    new = np.ones(len(thr), bool)
    new[1:] = (trusted[1:] != trusted[:-1]).any(axis=1)
    starts = [*(int(s) for s in np.flatnonzero(new)), len(thr)]
    runs = [(starts[i], starts[i + 1]) for i in range(len(starts) - 1)]
    runs = _merge(runs, bounds, trusted, int(max_stretches))
    out = []
    for a, b in runs:
        t = thr[a:b].max(axis=0).astype(np.float32)
        out.append(Stretch(float(bounds[a]), float(bounds[b]),
                           _selection(t, el, has_dir, ok_eph, tuple(sats))))  # fmt: skip
    return tuple(out)


def combine_stretches(
    lo_m: ArrayLike,
    hi_m: ArrayLike,
    claimed: ArrayLike,
    fix_lo_m: ArrayLike,
    fix_hi_m: ArrayLike,
    estimate_m: ArrayLike,
    *,
    n_used: ArrayLike | None = None,
    estimate_inside: bool = True,
) -> Combined:
    """The claim of an epoch from one fix per stretch.

    Parameters
    ----------
    lo_m, hi_m : array_like, shape (n,)
        Stretch bounds (:func:`trust_stretches`), contiguous, in order.
    claimed : array_like of bool, shape (n,)
        Whether the stretch's fix makes a safety claim (after its own heading check).
    fix_lo_m, fix_hi_m, estimate_m : array_like, shape (n,)
        The fixes' intervals and estimates (NaN without a fix).
    n_used : array_like of int, shape (n,), optional
        Satellites each fix used. The estimate (``chosen``) comes from the claimed fix with a
        non-empty part that used the fewest, then whose estimate lies in its own part, then
        the shortest: where the stretches' sets nest (a wall at one end) the smallest set is
        the one on line-of-sight satellites wherever the train is among them, while a larger
        set may hold a satellite hidden at the train. Default: all equal.
    estimate_inside : bool
        The odometry rule ``"estimate"``: a claim needs a claimed, non-empty part whose fix
        puts its estimate inside the predicted interval (the single-set rule's test).

    Returns
    -------
    Combined
    """
    a, b = np.asarray(lo_m, float), np.asarray(hi_m, float)
    c = np.asarray(claimed, bool)
    fl, fh, est = (np.asarray(v, float) for v in (fix_lo_m, fix_hi_m, estimate_m))
    if not (a.shape == b.shape == c.shape == fl.shape == fh.shape == est.shape) or a.ndim != 1:
        raise ValueError("lo_m, hi_m, claimed, fix_lo_m, fix_hi_m, estimate_m: one shape (n,)")
    if c.any() and not (np.isfinite(fl[c]).all() and np.isfinite(fh[c]).all()):
        raise ValueError("a claimed stretch needs finite fix_lo_m / fix_hi_m")
    p_lo = np.where(c, np.maximum(a, fl), a)
    p_hi = np.where(c, np.minimum(b, fh), b)
    nonempty = p_lo <= p_hi
    claimed_part = c & nonempty
    in_prediction = (a.min() <= est) & (est <= b.max())
    candidates = claimed_part & in_prediction if estimate_inside else claimed_part
    length = np.where(c, fh - fl, np.inf)
    used = np.zeros(a.shape, np.int64) if n_used is None else np.asarray(n_used, np.int64)
    if used.shape != a.shape:
        raise ValueError(f"n_used must have shape {a.shape}, got {used.shape}")
    if candidates.any():
        # the estimate: the fewest satellites, then an estimate in its own part, then shortest
        own = (p_lo <= est) & (est <= p_hi)
        order = np.lexsort((length, ~own, used))
        chosen = int(order[candidates[order]][0])
        h_lo, h_hi = float(p_lo[nonempty].min()), float(p_hi[nonempty].max())
        tighter = h_lo > a.min() or h_hi < b.max()
        return Combined(h_lo, h_hi, tighter, False, chosen, int(nonempty.sum()))
    if claimed_part.any() or (c.any() and not (nonempty & ~c).any()):
        # estimates outside the prediction, or every claim misses its own stretch and nothing
        # is kept whole: the claims contradict the prediction
        chosen = int(np.flatnonzero(c)[np.argmin(length[c])])
        return Combined(float(fl[c].min()), float(fh[c].max()), False, True, chosen, 0)
    # no claim: the estimate of the longest stretch with a fix, the prediction as the interval
    has_fix = np.isfinite(est)
    chosen = int(np.argmax(np.where(has_fix, b - a, -1.0))) if has_fix.any() else -1
    return Combined(float(a.min()), float(b.max()), False, False, chosen, int(nonempty.sum()))


def _cell_pieces(
    masks: MaskSet, lo: float, hi: float, k: NDArray, margin: float
) -> tuple[NDArray, NDArray]:
    """Edges (p + 1,) and thresholds (p, n_sat) of the pieces of ``[lo, hi]``: one per mask
    cell overlapping it, ``+inf`` pieces where it leaves the coverage."""
    b = masks.cell_bounds_m
    edges: list[float] = [lo]
    rows: list[NDArray] = []
    inf = np.full(k.shape, np.inf)
    if lo < b[0]:
        edges.append(min(hi, float(b[0])))
        rows.append(inf)
    c_lo, c_hi = max(lo, float(b[0])), min(hi, float(b[-1]))
    if c_lo < c_hi or (c_lo == c_hi and lo == hi and b[0] <= lo <= b[-1]):
        # cells overlapping (c_lo, c_hi); a point interval takes every cell holding it
        i = int(np.searchsorted(b[1:], c_lo, side="right" if c_lo < c_hi else "left"))
        j = int(np.searchsorted(b[:-1], c_hi, side="left" if c_lo < c_hi else "right")) - 1
        i, j = min(max(i, 0), masks.n_pos - 1), min(max(j, i), masks.n_pos - 1)
        eff = masks.effective_mask_deg[i : j + 1][:, k].astype(float) + margin  # (cells, n_sat)
        if c_lo == c_hi:
            eff = eff.max(axis=0, keepdims=True)
            inner: list[float] = []
        else:
            inner = [float(x) for x in b[i + 1 : j + 1]]
        edges.extend([*inner, c_hi])
        rows.extend(eff)
    if hi > b[-1]:
        edges.append(hi)
        rows.append(inf)
    if not rows:  # [lo, hi] meets the coverage in one edge point only: nothing is trusted
        return np.array([lo, hi]), inf[None]
    return np.asarray(edges, float), np.asarray(rows, float)


def _merge(
    runs: list[tuple[int, int]], bounds: NDArray, trusted: NDArray, n_max: int
) -> list[tuple[int, int]]:
    """Merge adjacent runs of pieces, cheapest in lost satellite-metres first."""
    runs = list(runs)
    length = np.diff(bounds)
    sets = [trusted[a:b].all(axis=0) for a, b in runs]
    lens = [float(length[a:b].sum()) for a, b in runs]
    while len(runs) > n_max:
        costs = []
        for i in range(len(runs) - 1):
            both = sets[i] & sets[i + 1]
            costs.append(lens[i] * float((sets[i] & ~both).sum())
                         + lens[i + 1] * float((sets[i + 1] & ~both).sum()))  # fmt: skip
        i = int(np.argmin(costs))
        runs[i : i + 2] = [(runs[i][0], runs[i + 1][1])]
        sets[i : i + 2] = [sets[i] & sets[i + 1]]
        lens[i : i + 2] = [lens[i] + lens[i + 1]]
    return runs


def _selection(
    thr: NDArray, el: NDArray, has_dir: NDArray, ok_eph: NDArray, sats: tuple[str, ...]
) -> Selection:
    """A :class:`Selection` from thresholds, with :func:`select_satellites`'s reason codes."""
    thr = np.where(has_dir, thr, np.float32(np.nan)).astype(np.float32)
    reason = np.full(el.shape, Exclusion.TRUSTED, np.uint8)
    reason[has_dir & ~(el > thr)] = Exclusion.BELOW_MASK
    reason[has_dir & np.isinf(thr)] = Exclusion.OUTSIDE_COVERAGE
    reason[~has_dir] = Exclusion.NO_DIRECTION
    reason[~ok_eph] = Exclusion.EPHEMERIS_INVALID
    return Selection(trusted=reason == Exclusion.TRUSTED, reason=reason, threshold_deg=thr,
                     el_deg=el, sats=sats)  # fmt: skip
