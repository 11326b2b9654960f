"""Per-pair confidence intervals, the integrity modes and their union; the error-model fit.

Each SATHIA pair gives an interval from ``K +- k sigma_K`` (:func:`locator.sathia.solve_pairs`).
How the pairs are combined depends on how many satellites are trusted
(:class:`predisat.availability.interval.IntervalMode`, the same rule as the availability
prediction):

* >= 6 satellites, ``THREE_PAIRS``: three *independent* pairs (six distinct satellites) and the
  union (outermost bounds) of their intervals. The pairs are chosen from the geometry at the
  prior position (never from the measurements, so the choice cannot favour a fault) to make
  that union short: each satellite is ranked by the interval it would give with an ideal
  partner, a pool of the 4 best "low" (``g = u . t`` small) and 4 best "high" satellites is
  searched exhaustively (420 sets of three disjoint pairs). This is the heuristic of
  :mod:`predisat.availability.interval`, so predicted and actual intervals use the same pairs.
* 4-5, ``ALL_PAIRS``: every pair combination and their union.
* 2-3, ``BEST_PAIR``: the pair with the shortest interval; a position with **no safety claim**.
* < 2, ``NONE``: no interval.

The scheme ``"all"`` unites every pair instead (passive integrity: every measurement is used and
poor ones only lengthen the interval).

The error model ``sigma(el)**2 = a**2 + (b / sin el)**2`` is
:class:`predisat.availability.interval.ErrorModel`; :func:`fit_error_model` learns ``a`` and ``b``
from
pseudorange residuals at known positions and :func:`overbound_error_model` inflates it until
it bounds them in every elevation bin (``locator calibrate``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import nnls

from locator.kernels import along_track_kernel, three_pairs_kernel, union_kernel
from locator.sathia import AntennaPath, PairSolution
from predisat.availability import interval as _interval
from predisat.availability.interval import IntervalMode
from predisat.gnss.errormodel import ErrorModel

__all__ = [
    "PAIR_SCHEMES",
    "Overbound",
    "UnionInterval",
    "along_track_g",
    "best_pair",
    "fit_error_model",
    "overbound_error_model",
    "plan_pairs",
    "three_independent_pairs",
    "union_interval",
    "usable_residuals",
]

PAIR_SCHEMES = ("auto", "all")


@dataclass(frozen=True)
class UnionInterval:
    """The interval of one epoch: union of the pair intervals of its mode.

    Attributes
    ----------
    lo_m, hi_m : float
        Interval bounds, chainage metres (NaN when no pair has a root; ``-inf``/``+inf`` when
        a pair is unbounded in the search window).
    estimate_m : float
        Inverse-variance weighted mean of the pair roots (variance
        ``(sigma_K / slope)**2``), metres.
    mode : IntervalMode
    safety_claim : bool
        True only in ``THREE_PAIRS`` and ``ALL_PAIRS`` modes with every pair bounded.
    consistent : bool
        The pair intervals have a common point (``max lo <= min hi``).
    pairs : PairSolution
        The pairs united.
    """

    lo_m: float
    hi_m: float
    estimate_m: float
    mode: IntervalMode
    safety_claim: bool
    consistent: bool
    pairs: PairSolution

    @property
    def length_m(self) -> float:
        return self.hi_m - self.lo_m

    def contains(self, chainage_m: float) -> bool:
        return bool(self.lo_m <= chainage_m <= self.hi_m)


_NONE, _BEST, _ALL, _THREE = (IntervalMode.NONE, IntervalMode.BEST_PAIR, IntervalMode.ALL_PAIRS,
                              IntervalMode.THREE_PAIRS)  # fmt: skip


def along_track_g(path: AntennaPath, chainage_m: float, sat_ecef_m: ArrayLike) -> NDArray:
    """``g = u . t`` of each satellite at a chainage, shape (n_sat,).

    ``u`` is the unit vector antenna -> satellite and ``t`` the path's unit tangent; a pair's
    sensitivity is ``|g_i - g_j|`` metres of range difference per metre of chainage.
    """
    sat = np.ascontiguousarray(sat_ecef_m, float)
    if sat.ndim != 2 or sat.shape[1] != 3:
        raise ValueError(f"sat_ecef_m must have shape (n_sat, 3), got {sat.shape}")
    s = float(chainage_m)
    if not np.isfinite(s):
        raise ValueError("chainage_m contains NaN or infinite values")
    x, dx = path.hermite_table
    return along_track_kernel(x, dx, float(path.length_m), s, sat)  # compiled, bit for bit


def best_pair(g: ArrayLike, sigma_m: ArrayLike, k_sigma: float = 2.0) -> NDArray:
    """The pair with the shortest predicted interval, indices shape (1, 2).

    :func:`predisat.availability.interval.best_pair` (the rule of the availability prediction).
    """
    ga = np.asarray(g, float)
    if ga.size < 2:
        raise ValueError(f"best_pair needs at least 2 satellites, got {ga.size}")
    pair, _ = _interval.best_pair(ga, np.asarray(sigma_m, float), None, k_sigma)
    return pair[None, :]


def three_independent_pairs(g: ArrayLike, sigma_m: ArrayLike, k_sigma: float = 2.0) -> NDArray:
    """Three disjoint pairs making the union of their intervals short, indices shape (3, 2).

    Parameters
    ----------
    g : array_like, shape (n_sat,)
        Along-track components (:func:`along_track_g`), ``n_sat >= 6``.
    sigma_m : array_like, shape (n_sat,)
    k_sigma : float

    Notes
    -----
    :func:`predisat.availability.interval.three_independent_pairs`, the pool heuristic of the
    availability
    prediction (so predicted and actual intervals use the same pairs); exact for up to 8
    satellites.
    """
    ga = np.asarray(g, float)
    n = ga.size
    if n < 6:
        raise ValueError(f"three independent pairs need at least 6 satellites, got {n}")
    sig = np.ascontiguousarray(sigma_m, float)
    if sig.shape != ga.shape or not (np.isfinite(ga).all() and np.isfinite(sig).all()):
        raise ValueError(f"g and sigma_m must be finite of one shape: {ga.shape}, {sig.shape}")
    # compiled: the availability prediction's pool heuristic, bit for bit (its matching table)
    i, j, sets = _interval.matching_table(min(_interval.POOL_SIZE, n))
    return three_pairs_kernel(np.ascontiguousarray(ga), sig, float(k_sigma),
                              _interval.POOL_SIZE, i, j, sets).astype(np.intp)  # fmt: skip


def plan_pairs(
    g: ArrayLike, sigma_m: ArrayLike, k_sigma: float = 2.0, scheme: str = "auto"
) -> tuple[NDArray, IntervalMode]:
    """Pairs to solve for the trusted satellites of an epoch, and the mode.

    Parameters
    ----------
    g, sigma_m : array_like, shape (n_sat,)
        Along-track components and sigmas of the satellites kept.
    k_sigma : float
    scheme : {"auto", "all"}
        ``"auto"``: by count (module docstring); ``"all"``: every pair when ``n_sat >= 4``
        (passive integrity), best pair for 2-3.

    Returns
    -------
    pairs : ndarray of int, shape (p, 2)
    mode : IntervalMode
    """
    if scheme not in PAIR_SCHEMES:
        raise ValueError(f"scheme must be one of {PAIR_SCHEMES}, got {scheme!r}")
    ga = np.asarray(g, float)
    n = ga.size
    # interval_mode's rule on one count, without its array calls (enum members looked up
    # once: Python 3.11's Enum.__getattr__ costs microseconds per epoch)
    mode = _THREE if n >= 6 else _ALL if n >= 4 else _BEST if n >= 2 else _NONE
    if mode is _NONE:
        return np.zeros((0, 2), np.intp), mode
    if mode is _BEST:
        return best_pair(ga, sigma_m, k_sigma), mode
    if mode is _THREE and scheme == "auto":
        return three_independent_pairs(ga, sigma_m, k_sigma), mode
    return _every_pair(n), (_ALL if scheme == "all" else mode)


@functools.cache
def _every_pair(n: int) -> NDArray:
    """``np.stack(np.triu_indices(n, 1), axis=-1)``, made once per count (read-only)."""
    i, j = np.triu_indices(n, 1)
    out = np.stack([i, j], axis=-1)
    out.setflags(write=False)
    return out


def union_interval(pairs: PairSolution, mode: IntervalMode) -> UnionInterval:
    """Union (outermost bounds) of the pair intervals, with the weighted-mean estimate.

    A pair whose interval is empty (``PairStatus.EMPTY``: no point of the window within
    ``k sigma_K``) makes the whole union NaN: the measurements contradict the search window and
    nothing may be claimed (active integrity excludes the cause first). Pairs without a root
    but with a non-empty set count with their hull and do not enter the estimate.
    """
    if pairs.n_pairs == 0:
        return UnionInterval(np.nan, np.nan, np.nan, _NONE, False, False, pairs)
    if np.isnan(pairs.lo_m).any():
        return UnionInterval(np.nan, np.nan, np.nan, mode, False, False, pairs)
    # compiled: min/max of the bounds, the weights (slope / sigma_K)**2 of the pairs with a
    # root, their weighted mean (numpy's pairwise sums), bit for bit
    lo, hi, est, consistent = union_kernel(
        *(np.ascontiguousarray(v, float) for v in (pairs.lo_m, pairs.hi_m, pairs.root_m,
                                                    pairs.slope, pairs.sigma_k_m))
    )  # fmt: skip
    consistent = bool(consistent)
    claim = (
        mode in (_THREE, _ALL)
        and bool(np.isfinite(lo) and np.isfinite(hi))
        and consistent
    )
    return UnionInterval(lo, hi, est, mode, claim, consistent, pairs)


def usable_residuals(el_deg: ArrayLike, residual_m: ArrayLike) -> NDArray:
    """Which residuals an error-model fit can use, (n_epoch, n_sat) bool: finite, in epochs
    with at least 3 of them (removing the receiver clock needs redundancy).

    The one rule behind :func:`fit_error_model`, :func:`overbound_error_model` and the counts
    that :mod:`locator.errorfit` reports of them.
    """
    ok = np.isfinite(np.asarray(el_deg, float)) & np.isfinite(np.asarray(residual_m, float))
    return ok & (ok.sum(axis=1, keepdims=True) >= 3)


def _error_inputs(
    el_deg: ArrayLike, residual_m: ArrayLike, min_el_deg: float, n_bins: int, func: str
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Validated ``el, r``, the mask of usable residuals and ``q = 1 / sin(el)**2``."""
    el = np.asarray(el_deg, float)
    r = np.asarray(residual_m, float)
    if el.shape != r.shape or el.ndim != 2:
        raise ValueError(
            f"el_deg and residual_m must share a shape (n_epoch, n_sat): {el.shape}, {r.shape}"
        )
    ok = usable_residuals(el, r)
    if ok.sum() < 2 * n_bins:
        raise ValueError(
            f"{func} needs at least {2 * n_bins} residuals in epochs with >= 3 "
            f"satellites, got {int(ok.sum())}; give more epochs or fewer n_bins"
        )
    q = 1.0 / np.sin(np.radians(np.maximum(np.where(ok, el, 90.0), min_el_deg))) ** 2
    return el, r, ok, q


def _clock_free(r: NDArray, ok: NDArray, var: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Residuals minus the per-epoch clock (mean weighted by ``1 / var``), weights, variance.

    ``e_k = r_k - sum(w r)`` has variance ``var_k (1 - 2 w_k) + sum(w**2 var)`` when ``var``
    is the truth.
    """
    w = np.where(ok, 1.0 / var, 0.0)
    w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-300)  # rows without data stay 0
    clock = np.sum(w * np.where(ok, r, 0.0), axis=1, keepdims=True)
    ev = var * (1.0 - 2.0 * w) + np.sum(w**2 * np.where(ok, var, 0.0), axis=1, keepdims=True)
    return r - clock, w, ev


def _clock_removed(
    r: NDArray, ok: NDArray, q: NDArray, a2: float, b2: float
) -> tuple[NDArray, NDArray, NDArray]:
    """:func:`_clock_free` under ``var = a2 + b2 q``, its variance as coefficients of ``(a2, b2)``.

    The variance of ``e_k`` is ``a2 ca_k + b2 cb_k``: linear in ``(a2, b2)``.
    """
    e, w, _ = _clock_free(r, ok, a2 + b2 * q)
    ca = (1.0 - 2.0 * w) + np.sum(w**2, axis=1, keepdims=True)
    cb = q * (1.0 - 2.0 * w) + np.sum(w**2 * np.where(ok, q, 0.0), axis=1, keepdims=True)
    return e, ca, cb


def fit_error_model(
    el_deg: ArrayLike, residual_m: ArrayLike, *, min_el_deg: float = 1.0, n_bins: int = 16
) -> ErrorModel:
    """Learn ``a`` and ``b`` of ``sigma(el)**2 = a**2 + (b / sin el)**2`` from residuals.

    This is the best estimate, not a bound: for an integrity model pass its result to
    :func:`overbound_error_model`.

    Parameters
    ----------
    el_deg : array_like, shape (n_epoch, n_sat)
        Satellite elevations, degrees; NaN where the satellite was not observed.
    residual_m : array_like, shape (n_epoch, n_sat)
        ``pseudorange - |x_true - S|`` at known antenna positions, metres; they still hold the
        receiver clock, which is removed per epoch (weighted mean) here.
    min_el_deg : float
        Passed to the model.
    n_bins : int
        Elevation bins (equal counts) whose variances are fitted.

    Returns
    -------
    ErrorModel

    Notes
    -----
    Per epoch the clock is estimated as the mean of the residuals weighted by a first
    ``1/sigma**2`` guess (``a = b``); removing it leaves ``e_k - mean``, whose variance is
    ``sigma_k**2 (1 - 2 w_k) + sum(w**2 sigma**2)`` with normalised weights ``w``; the fit is
    a non-negative least squares of the binned squared residuals on that linear form in
    ``(a**2, b**2)``, iterated twice (weights from the previous fit).
    """
    el, r, ok, q = _error_inputs(el_deg, residual_m, min_el_deg, n_bins, "fit_error_model")
    a2, b2 = 1.0, 1.0
    for _ in range(3):
        e, ca, cb = _clock_removed(r, ok, q, a2, b2)
        e2 = e**2
        order = np.argsort(el[ok])
        chunks = np.array_split(order, n_bins)
        design = np.array([[ca[ok][c].mean(), cb[ok][c].mean()] for c in chunks])
        target = np.array([e2[ok][c].mean() for c in chunks])
        # weight bins by their expected spread so the low elevations do not dominate
        scale = 1.0 / np.maximum(target, 1e-12)
        sol, _ = nnls(design * scale[:, None], target * scale)
        a2, b2 = max(float(sol[0]), 1e-12), max(float(sol[1]), 1e-12)
    return ErrorModel(a_m=float(np.sqrt(a2)), b_m=float(np.sqrt(b2)), min_el_deg=min_el_deg)


@dataclass(frozen=True)
class Overbound:
    """An error model inflated until it bounds the residuals' tails in every elevation bin.

    Attributes
    ----------
    model : ErrorModel
        ``fitted`` with ``a`` and ``b`` multiplied by ``factor``.
    fitted : ErrorModel
        The model that was inflated (usually :func:`fit_error_model`'s estimate).
    factor : float
        ``max(1, max(bin_factor))``.
    bin_el_lo_deg, bin_el_hi_deg : ndarray, shape (n_bins,)
        Elevation range of each bin (equal counts), degrees.
    bin_n : ndarray of int, shape (n_bins,)
        Residuals per bin.
    bin_factor : ndarray, shape (n_bins,)
        Smallest inflation of ``fitted`` whose Gaussian bounds the bin's two-sided tail.
    """

    model: ErrorModel
    fitted: ErrorModel
    factor: float
    bin_el_lo_deg: NDArray
    bin_el_hi_deg: NDArray
    bin_n: NDArray
    bin_factor: NDArray
    lag1_correlation: float = float("nan")
    independent_share: float = 1.0
    tail_probability: float = float("nan")

    @property
    def n_independent(self) -> int:
        """Independent samples the residuals amount to (``sum(bin_n) * independent_share``)."""
        return max(1, round(float(self.bin_n.sum()) * self.independent_share))


def overbound_error_model(
    el_deg: ArrayLike,
    residual_m: ArrayLike,
    fitted: ErrorModel | None = None,
    *,
    n_bins: int = 6,
    min_tail: int = 10,
    max_tail_share: float = 0.32,
    confidence: float | None = None,
) -> Overbound:
    """Inflate an error model until its Gaussian bounds the residual tails in every bin.

    A least-squares fit averages over elevations, so where the real errors do not follow
    ``a**2 + (b / sin el)**2`` (satellite orbit and clock errors, multipath at a site) it
    under-states them in some bins; a pair interval of ``k sigma`` is then not a bound there.

    Parameters
    ----------
    el_deg, residual_m : array_like, shape (n_epoch, n_sat)
        As for :func:`fit_error_model`.
    fitted : ErrorModel, optional
        The model to inflate; default ``fit_error_model(el_deg, residual_m)``.
    n_bins : int
        Elevation bins of equal counts, each of which must be bounded.
    min_tail : int
        The deepest tail point checked has this many residuals beyond it (fewer say nothing).
    max_tail_share : float
        Tail points from ``min_tail / n`` up to this share of a bin are checked (0.32: from
        about one sigma outwards, where the ``k sigma`` intervals live).
    confidence : float, optional
        With a confidence (0.95), each one-sided tail is checked on its own (an error biased
        to one side is not averaged with the other side's) against the Clopper-Pearson upper
        bound, at that confidence, of its share counted in *independent* samples: the
        residuals' lag-1 correlation ``rho`` (per satellite, consecutive epochs) makes ``n``
        residuals worth ``n (1 - rho) / (1 + rho)`` independent ones. None: the two-sided
        empirical share (before 2026-12-05).

    Returns
    -------
    Overbound

    Notes
    -----
    The residuals are made clock-free (per-epoch weighted mean, weights ``1 / var``) and
    normalised by their exact variance after that removal, ``z = e / sqrt(var_e)`` (as in
    :func:`fit_error_model`'s Notes). In each bin, for every sorted ``|z|_i`` with ``c_i``
    residuals at or beyond it, ``min_tail <= c_i <= max_tail_share * n``, the Gaussian
    ``N(0, f**2)`` bounds the point when ``2 Q(|z|_i / f) >= c_i / n``, i.e.
    ``f >= |z|_i / Q^-1(c_i / 2n)``: an empirical two-sided tail bound over those shares (not
    a full CDF overbound). A bin whose errors exceed the fit gets too much weight in the clock,
    which then absorbs part of its excess, so the bin factors are iterated: the variances
    inflated by them, the clock removed again, until every bin is bounded at factor 1. The
    model's factor is the largest bin factor, never below 1. An excess on part of a bin is
    bounded on the bin's average only, and residuals of one satellite pass are correlated in
    time, so an hour of data checks far fewer independent errors than it has residuals; tails
    beyond ``min_tail / n`` (for ``k = 3.89``: 1e-4) are extrapolated, not measured:
    calibrate on as many days and sites as the line will see.
    """
    if n_bins < 1:
        raise ValueError(f"n_bins must be >= 1, got {n_bins}")
    if min_tail < 1:
        raise ValueError(f"min_tail must be >= 1, got {min_tail}")
    if not 0.0 < max_tail_share <= 0.5:
        raise ValueError(f"max_tail_share must be in (0, 0.5], got {max_tail_share}")
    if confidence is not None and not 0.5 <= confidence < 1.0:
        raise ValueError(f"confidence must be in [0.5, 1) (0.95 typical), got {confidence}")
    min_el = 1.0 if fitted is None else fitted.min_el_deg
    el, r, ok, q = _error_inputs(el_deg, residual_m, min_el, n_bins, "overbound_error_model")
    fit = fit_error_model(el_deg, residual_m) if fitted is None else fitted
    el_ok = el[ok]
    order = np.argsort(el_ok, kind="stable")
    chunks = np.array_split(order, n_bins)
    bin_of = np.empty(len(order), int)
    for b, c in enumerate(chunks):
        bin_of[c] = b
    counts = np.array([len(c) for c in chunks])
    if counts.min() * max_tail_share < min_tail:
        raise ValueError(
            f"overbound_error_model: a bin of {counts.min()} residuals has fewer than "
            f"min_tail={min_tail} in its checked tail (max_tail_share={max_tail_share}); "
            "give more epochs or fewer n_bins"
        )
    sigma2 = np.where(ok, fit.a_m**2 + fit.b_m**2 * q, 1.0)
    factor_b = np.ones(n_bins)
    rho, share = float("nan"), 1.0
    if confidence is not None:
        e0, _, ev0 = _clock_free(r, ok, sigma2)
        rho = _lag1_correlation(np.where(ok, e0 / np.sqrt(np.maximum(ev0, 1e-300)), np.nan))
        share = float(np.clip((1.0 - rho) / (1.0 + rho), 1.0 / counts.min(), 1.0))
    # a bin whose errors exceed the fit also pulls the clock estimate (its weight is too
    # high), which hides part of its excess: iterate with the inflated variances until the
    # clock-free residuals are bounded at factor 1 in every bin
    for _ in range(30):
        var = sigma2.copy()
        var[ok] *= factor_b[bin_of] ** 2
        e, _, ev = _clock_free(r, ok, var)
        z = e[ok] / np.sqrt(np.maximum(ev[ok], 1e-300))
        if confidence is None:
            g = np.array([_tail_factor(np.abs(z[c]), min_tail, max_tail_share) for c in chunks])
        else:
            # the empirical two-sided check as well: a bin too short for any confident point
            # is still bounded on its own residuals (and its tail probability says 1)
            g = np.array([
                max(_tail_factor(np.abs(z[c]), min_tail, max_tail_share),
                    *(_sided_tail_factor(side * z[c], min_tail, max_tail_share, share,
                                         confidence) for side in (1.0, -1.0)))
                for c in chunks
            ])  # fmt: skip
        factor_b *= g
        if np.max(np.abs(g - 1.0)) < 1e-4:
            break
    factor = max(1.0, float(factor_b.max()))
    model = ErrorModel(a_m=fit.a_m * factor, b_m=fit.b_m * factor, min_el_deg=fit.min_el_deg)
    return Overbound(
        model=model,
        fitted=fit,
        factor=factor,
        bin_el_lo_deg=np.array([el_ok[c].min() for c in chunks]),
        bin_el_hi_deg=np.array([el_ok[c].max() for c in chunks]),
        bin_n=counts,
        bin_factor=factor_b,
        lag1_correlation=rho,
        independent_share=share,
        tail_probability=float("nan")
        if confidence is None
        else max(_deepest_tail(n, min_tail, max_tail_share, share, confidence) for n in counts),
    )


def _lag1_correlation(z: NDArray) -> float:
    """Correlation of ``z[t]`` and ``z[t + 1]`` over every satellite column (finite pairs),
    clipped to [0, 0.999]; 0 without pairs."""
    a, b = z[:-1], z[1:]
    both = np.isfinite(a) & np.isfinite(b)
    if both.sum() < 3:
        return 0.0
    x, y = a[both], b[both]
    c = float(np.corrcoef(x, y)[0, 1]) if x.std() > 0 and y.std() > 0 else 0.0
    return float(np.clip(c if np.isfinite(c) else 0.0, 0.0, 0.999))


def _upper_share(count: NDArray, n: float, share: float, confidence: float) -> NDArray:
    """Clopper-Pearson upper bound of a tail share seen ``count`` times in ``n`` residuals
    worth ``share`` independent samples each (continuous counts)."""
    from scipy.stats import beta  # lazy: slow import, calibration only

    n_eff = max(n * share, 1.0)
    c_eff = np.minimum(np.asarray(count, float) * share, n_eff - 1e-9)
    return np.asarray(beta.ppf(confidence, c_eff + 1.0, n_eff - c_eff), float)


def _checked_points(
    n: int, min_tail: int, max_tail_share: float, share: float, confidence: float
) -> tuple[NDArray, NDArray]:
    """Tail counts a one-sided check of a bin of ``n`` residuals uses and their upper shares:
    at least ``min_tail`` residuals and one independent sample beyond the point, and an upper
    share at most ``max_tail_share / 2`` (from about one sigma out)."""
    count = np.arange(n, 0, -1)
    p_up = _upper_share(count, n, share, confidence)
    use = (count >= min_tail) & (count * share >= 1.0) & (p_up <= 0.5 * max_tail_share)
    return count[use], p_up[use]


def _deepest_tail(
    n: int, min_tail: int, max_tail_share: float, share: float, confidence: float
) -> float:
    """Two-sided probability of the deepest tail point a bin of ``n`` residuals checks (1 when
    it checks none: too few independent samples)."""
    _, p_up = _checked_points(n, min_tail, max_tail_share, share, confidence)
    return float(min(1.0, 2.0 * p_up.min())) if len(p_up) else 1.0


def _sided_tail_factor(
    z: NDArray, min_tail: int, max_tail_share: float, share: float, confidence: float
) -> float:
    """Smallest ``f`` with ``Q(z_i / f)`` >= the upper bound of the share at or beyond ``z_i``
    (one side, ``z`` signed) at the points of :func:`_checked_points` (1 without any)."""
    from scipy.stats import norm

    zs = np.sort(z)
    n = len(zs)
    count, p_up = _checked_points(n, min_tail, max_tail_share, share, confidence)
    if not len(count):
        return 1.0
    x = zs[n - count]  # the value with `count` residuals at or beyond it
    return float(np.max(x / norm.isf(p_up)))


def _tail_factor(z: NDArray, min_tail: int, max_tail_share: float) -> float:
    """Smallest ``f`` with ``P(|N(0, f**2)| >= |z|_i)`` >= the share at or beyond ``|z|_i``."""
    # lazy: scipy.stats is slow to import and only calibration (overbounding) needs it
    from scipy.stats import norm

    zs = np.sort(z)
    n = len(zs)
    count = n - np.arange(n)  # residuals at or beyond zs[i]
    use = (count >= min_tail) & (count <= max_tail_share * n)
    return float(np.max(zs[use] / norm.isf(count[use] / (2.0 * n))))
