"""Predicted length of the SATHIA confidence interval from satellite-pair geometry.

SATHIA (the LOCOPROL 1-D algorithm, ``docs/availability.md``) removes the receiver clock by
differencing two pseudoranges, ``K = rho_i - rho_j``, and intersects the hyperboloid
``|p - S_i| - |p - S_j| = K`` with the track. Along the track (chainage ``s``, unit tangent
``t``), with ``u`` the unit vectors antenna -> satellite::

    dK/ds = -(u_i - u_j) . t = -(g_i - g_j),        g = u . t  (along-track component)

so an error ``e`` on ``K`` moves the intersection by ``e / |g_i - g_j|``. The source adds
``+-2 xi`` to the measured ``K`` (xi: the spread of the pseudorange errors, learned from data);
here ``+-k sigma_K`` with ``sigma_K**2 = sigma_i**2 + sigma_j**2`` and ``k = k_sigma``, so one
pair gives an interval of half length::

    h_ij = k * sigma_K / |g_i - g_j|

The interval of an epoch depends on how many satellites are trusted (:class:`IntervalMode`):

* >= 6: three *independent* pairs (six distinct satellites); the interval is the union of the
  three pair intervals, i.e. ``2 * max(h)`` of the three (all are centred on the truth when
  predicting). The pairs are chosen to make that short: each satellite is ranked by the
  interval it would give with an ideal partner on the other side (``g = +1`` or ``-1`` and the
  epoch's smallest sigma); a pool of :data:`POOL_SIZE` (8) satellites - the 4 best "low" and
  the 4 best "high" - is searched exhaustively (420 sets of three disjoint pairs). Against
  the exhaustive search over all satellites this is exact in about 95 % of random skies and
  at most 1.4 times longer (``docs/availability.md``);
* 4 or 5: no three independent pairs; the source uses every pair combination: the union of
  all pairs, ``2 * max(h)`` over all pairs (blunt pairs lengthen it: passive integrity);
* 2 or 3: the best single pair, ``2 * min(h)``: a position, but **no safety claim**;
* < 2: no interval (NaN).

The pair choice is public and vectorised over epochs (:func:`pair_pool`,
:func:`three_independent_pairs` returning the pairs' indices, :func:`best_pair`), so that the
locator (``locator.intervals``) solves the very pairs that were predicted.
:func:`predicted_interval` gets the same lengths without the indices by a faster, exact subset
recursion (``docs/availability.md``, Engine).

The pseudorange error model (:class:`predisat.gnss.errormodel.ErrorModel`) is a placeholder with
stated defaults, to be learned from data by ``locator calibrate``.

``k`` is either one constant for every mode or follows from an integrity budget
(:class:`predisat.gnss.integrity.IntegrityBudget`): each mode's union needs
:data:`INDEPENDENT_PAIRS` disjoint pairs to miss on one side together, so each mode has its
own ``k`` (:func:`mode_k_sigma`; ``docs/locator.md``, "Integrity budget").
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from enum import IntEnum
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.gnss.integrity import IntegrityBudget
from predisat.readonly import readonly_array

__all__ = [
    "DEFAULT_MAP_DOUBT",
    "INDEPENDENT_PAIRS",
    "POOL_SIZE",
    "IntervalMode",
    "MapDoubt",
    "along_track_components",
    "best_pair",
    "interval_mode",
    "matching_table",
    "mode_k_sigma",
    "pair_half_length_m",
    "pair_pool",
    "predicted_interval",
    "three_independent_pairs",
    "width_text",
]


class IntervalMode(IntEnum):
    """How the interval of an epoch is formed (by the number of trusted satellites)."""

    NONE = 0  # fewer than 2 satellites
    BEST_PAIR = 1  # 2-3 satellites: best pair, no safety claim
    ALL_PAIRS = 2  # 4-5 satellites: union of all pairs
    THREE_PAIRS = 3  # >= 6 satellites: union of three independent pairs


INDEPENDENT_PAIRS = {
    IntervalMode.BEST_PAIR: 1,
    IntervalMode.ALL_PAIRS: 2,  # every pair of 4-5 satellites holds two disjoint pairs
    IntervalMode.THREE_PAIRS: 3,
}
"""Disjoint pairs each mode's union holds (:func:`predisat.gnss.integrity.disjoint_pairs`)."""


@dataclass(frozen=True)
class MapDoubt:
    """How far the antenna may be from the point of the track map a pair is solved at.

    The map's accuracy, the antenna's lateral lever arm, the cant's sway, a train on a loop
    beside the mapped track: moving the antenna by ``delta`` changes a pair's range difference
    by ``-(u_i - u_j) . delta``, so each pair's band grows from ``k sigma_K`` to ``k sigma_K +
    lateral_m |(u_i - u_j)_level| + vertical_m |(u_i - u_j)_up|`` ("beside" in any level
    direction: the locator's search window turns with the curves; ``locator.fde.
    map_doubt_bias_m``, docs/locator.md). The locator widens the pairs it solves by it, and the
    availability prediction the pairs it predicts, so both state one interval.

    Attributes
    ----------
    lateral_m, vertical_m : float
        Metres beside and above or below the map. Default 1.5 and 1: a map good to a metre, a
        centred roof antenna, cant; 0 and 0 give the source's pairs.
    """

    lateral_m: float = 1.5
    vertical_m: float = 1.0

    def __post_init__(self) -> None:
        for name in ("lateral_m", "vertical_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"MapDoubt.{name} must be finite and >= 0 metres, got {v}")
            # floats: MapDoubt(1.5, 1) and MapDoubt(1.5, 1.0) are one doubt, and one resume key
            object.__setattr__(self, name, float(v))

    @property
    def is_zero(self) -> bool:
        """No doubt: the source's pair intervals."""
        return self.lateral_m == 0 and self.vertical_m == 0

    def bias_m(self, unit_i: ArrayLike, unit_j: ArrayLike) -> NDArray:
        """Largest range-difference bias of pairs, metres.

        Parameters
        ----------
        unit_i, unit_j : array_like, shape (..., 3)
            East, north, up unit vectors antenna -> satellite of each pair's two satellites.

        Returns
        -------
        ndarray, shape (...)
        """
        du = np.asarray(unit_i) - np.asarray(unit_j)
        return self.lateral_m * np.hypot(du[..., 0], du[..., 1]) + self.vertical_m * np.abs(
            du[..., 2]
        )

    def describe(self) -> str:
        """The doubt in words, for captions and run records."""
        if self.is_zero:
            return "no map doubt"
        return (f"widened for an antenna up to {self.lateral_m:g} m beside and "
                f"{self.vertical_m:g} m above or below the map")  # fmt: skip


DEFAULT_MAP_DOUBT = MapDoubt()
"""The locator's and the availability prediction's default doubt (1.5 m beside, 1 m up)."""


def mode_k_sigma(k_sigma: float | IntegrityBudget) -> NDArray:
    """``k`` of each :class:`IntervalMode`, shape (4,), indexed by the mode (NaN for NONE).

    A float is one ``k`` for every mode; a budget gives each mode the ``k`` of its
    :data:`INDEPENDENT_PAIRS`.
    """
    out = np.full(len(IntervalMode), np.nan)
    for mode, m in INDEPENDENT_PAIRS.items():
        out[mode] = k_sigma.k_sigma(m) if isinstance(k_sigma, IntegrityBudget) else k_sigma
    return out


def width_text(k_sigma: float | IntegrityBudget) -> str:
    """The pair-interval width in words, for captions: the budget and each mode's ``k``, or
    the one ``k`` and the risk per epoch it amounts to."""
    if isinstance(k_sigma, IntegrityBudget):
        return k_sigma.describe()
    from predisat.gnss.integrity import union_risk

    return (
        f"k = {k_sigma:g} in every mode, no integrity budget (risk per epoch "
        f"{union_risk(k_sigma, 3):.2g} with three pairs, {union_risk(k_sigma, 2):.2g} with "
        f"all pairs of 4-5, {union_risk(k_sigma, 1):.2g} with one pair)"
    )


def along_track_components(unit_m: ArrayLike, tangent: ArrayLike) -> NDArray:
    """``g = u . t`` of unit vectors antenna -> satellite (..., m, 3) and tangents (..., 3)."""
    u = np.asarray(unit_m, float)
    t = np.asarray(tangent, float)
    return np.einsum("...mi,...i->...m", u, t)


def pair_half_length_m(
    g_i: ArrayLike, g_j: ArrayLike, sigma_i_m: ArrayLike, sigma_j_m: ArrayLike, k_sigma: float
) -> NDArray:
    """Half length ``k sqrt(sigma_i^2 + sigma_j^2) / |g_i - g_j|`` of one pair (inf if 0)."""
    dg = np.abs(np.asarray(g_i) - np.asarray(g_j))
    sk = np.sqrt(np.asarray(sigma_i_m) ** 2 + np.asarray(sigma_j_m) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dg > 0, k_sigma * sk / dg, np.inf)


def interval_mode(count: ArrayLike) -> NDArray:
    """:class:`IntervalMode` values (uint8) of trusted-satellite counts."""
    n = np.asarray(count)
    return np.select([n >= 6, n >= 4, n >= 2], [3, 2, 1], 0).astype(np.uint8)


def predicted_interval(
    g: ArrayLike,
    sigma_m: ArrayLike,
    trusted: ArrayLike,
    k_sigma: float | IntegrityBudget = 2.0,
    *,
    unit_enu: ArrayLike | None = None,
    map_doubt: MapDoubt | None = None,
) -> tuple[NDArray, NDArray]:
    """Predicted SATHIA interval length per epoch (see the module docstring for the rule).

    Parameters
    ----------
    g : array_like, shape (..., m)
        Along-track components ``u . t`` of the candidate satellites.
    sigma_m : array_like, shape (..., m)
        Pseudorange sigmas, metres.
    trusted : array_like of bool, shape (..., m)
    k_sigma : float or IntegrityBudget
        One ``k`` for every mode, or the budget giving each mode its own (:func:`mode_k_sigma`).
    unit_enu : array_like, shape (..., m, 3), optional
        East, north, up unit vectors antenna -> satellite; needed with a ``map_doubt``.
    map_doubt : MapDoubt, optional
        Widen each pair as the locator does (:class:`MapDoubt`). Default None: the source's
        pairs. The pairs are chosen as without it (the locator's choice), then widened.

    Returns
    -------
    length_m : ndarray of float32, shape (...)
        Full interval length (twice the half length); NaN with fewer than two satellites.
    mode : ndarray of uint8, shape (...)
        :class:`IntervalMode`.

    Notes
    -----
    With >= 6 satellites the length is that of :func:`three_independent_pairs` (the same
    pool, the same matchings), computed without the indices by a subset recursion; with a map
    doubt, from those indices.
    """
    g_a, sig, ok = _prepare(g, sigma_m, trusted)
    lead, m = g_a.shape[:-1], g_a.shape[-1]
    g2, s2, ok2 = g_a.reshape(-1, m), sig.reshape(-1, m), ok.reshape(-1, m)
    if not (np.isfinite(g2).all() and np.isfinite(s2).all()):
        # untrusted entries may be anything; the fast path needs them finite
        g2, s2 = np.where(ok2, g2, 0.0), np.where(ok2, s2, 1.0)
    u2 = None
    if map_doubt is not None and not map_doubt.is_zero:
        if unit_enu is None:
            raise ValueError("predicted_interval: a map_doubt needs unit_enu, the (..., m, 3) "
                             "unit vectors antenna -> satellite")  # fmt: skip
        u_a = np.asarray(unit_enu)
        if u_a.shape != (*g_a.shape, 3):
            raise ValueError(f"unit_enu must have shape {(*g_a.shape, 3)} (g's and 3), got "
                             f"{u_a.shape}")  # fmt: skip
        u2 = np.where(ok2[..., None], u_a.reshape(-1, m, 3), 0.0).astype(g_a.dtype, copy=False)
    out = np.empty(len(g2), g_a.dtype)
    mode = np.empty(len(g2), np.uint8)
    ks = mode_k_sigma(k_sigma)
    k = (float(ks[IntervalMode.BEST_PAIR]), float(ks[IntervalMode.ALL_PAIRS]),
         float(ks[IntervalMode.THREE_PAIRS]))  # fmt: skip
    for a in range(0, len(g2), _BLOCK_ROWS):  # blocks that stay in the CPU cache
        b = slice(a, a + _BLOCK_ROWS)
        if u2 is None or map_doubt is None:
            out[b], mode[b] = _interval_rows(g2[b], s2[b], ok2[b], k)
        else:
            out[b], mode[b] = _widened_rows(g2[b], s2[b], ok2[b], u2[b], k, map_doubt)
    return out.reshape(lead).astype(np.float32), mode.reshape(lead)


def _widened_half(
    g: NDArray, s: NDArray, unit: NDArray, pairs: NDArray, k: float, doubt: MapDoubt
) -> NDArray:
    """Half lengths of ``pairs`` (n, p, 2) of rows (n, m), each band widened by ``doubt``."""
    gi, gj = (np.take_along_axis(g, pairs[..., c], axis=-1) for c in (0, 1))
    si, sj = (np.take_along_axis(s, pairs[..., c], axis=-1) for c in (0, 1))
    ui, uj = (np.take_along_axis(unit, pairs[..., c, None], axis=1) for c in (0, 1))
    dg = np.abs(gi - gj)
    band = k * np.sqrt(si * si + sj * sj) + doubt.bias_m(ui, uj)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dg > 0, band / dg, np.inf)


def _widened_rows(
    g: NDArray, s: NDArray, ok: NDArray, unit: NDArray, k: tuple[float, float, float],
    doubt: MapDoubt,
) -> tuple[NDArray, NDArray]:  # fmt: skip
    """:func:`_interval_rows` with each chosen pair widened by ``doubt``: the pairs of each
    mode chosen as the locator does (:func:`best_pair`, every pair, :func:`three_independent_
    pairs`), their bands then grown by the bias (``locator.fde``: plan, then widen)."""
    count = ok.sum(-1)
    out = np.full(len(count), np.nan, g.dtype)
    mode = interval_mode(count)
    six = np.nonzero(count >= 6)[0]
    if len(six):
        pairs, _ = three_independent_pairs(g[six], s[six], ok[six], k[2])
        out[six] = 2.0 * _widened_half(g[six], s[six], unit[six], pairs, k[2], doubt).max(-1)
    few = np.nonzero((count >= 2) & (count < 6))[0]
    if len(few):
        # the trusted first (as _few): every pair of all m candidates (m ~ 50-110 with every
        # constellation) cost 40-70 times the plain rows, and (rows, m(m-1)/2, 3) gathers of
        # hundreds of megabytes
        valid, (gg, ss, uu) = _trusted_first(ok[few], count[few], g[few], s[few], unit[few])
        n_few = count[few]
        four = np.nonzero(n_few >= 4)[0]
        if len(four):
            i, j = np.triu_indices(valid.shape[-1], 1)
            every = np.broadcast_to(np.stack([i, j], axis=-1), (len(four), len(i), 2))
            h = _widened_half(gg[four], ss[four], uu[four], every, k[1], doubt)
            both = valid[four][:, i] & valid[four][:, j]
            out[few[four]] = 2.0 * np.where(both, h, -np.inf).max(-1)
        two = np.nonzero(n_few < 4)[0]
        if len(two):
            pair, _ = best_pair(gg[two], ss[two], valid[two], k[0])
            half = _widened_half(gg[two], ss[two], uu[two], pair[:, None], k[0], doubt)
            out[few[two]] = 2.0 * half[:, 0]
    return out, mode


POOL_SIZE = 8
"""Satellites kept per epoch for the exhaustive three-pair search (see the module docstring)."""

_BLOCK_ROWS = 4096


def _interval_rows(
    g: NDArray, s: NDArray, ok: NDArray, k: tuple[float, float, float]
) -> tuple[NDArray, NDArray]:
    """Full length and mode of rows (n, m) with finite ``g`` and ``s``; ``k`` of the best-pair,
    all-pairs and three-pair modes."""
    count = ok.sum(-1)
    out = np.full(len(count), np.nan, g.dtype)
    mode = interval_mode(count)
    six = count >= 6
    if six.all():
        out[:] = 2.0 * _three_pairs_half(g, s, ok, k[2])
    elif six.any():
        out[six] = 2.0 * _three_pairs_half(g[six], s[six], ok[six], k[2])
    few = np.nonzero((count >= 2) & (count < 6))[0]
    if len(few):
        out[few] = _few(g[few], s[few], ok[few], count[few], k)
    return out, mode


def _prepare(
    g: ArrayLike, sigma_m: ArrayLike, trusted: ArrayLike | None
) -> tuple[NDArray, NDArray, NDArray]:
    """``g``, ``sigma_m``, ``trusted`` as arrays of one shape (float32 kept, else float64)."""
    g_a = np.asarray(g)
    dtype = np.float32 if g_a.dtype == np.float32 else np.float64
    g_a = g_a.astype(dtype, copy=False)
    sig = np.asarray(sigma_m).astype(dtype, copy=False)
    ok = np.ones(g_a.shape, bool) if trusted is None else np.asarray(trusted, bool)
    if not g_a.shape == sig.shape == ok.shape or g_a.ndim < 1:
        raise ValueError(
            f"g, sigma_m and trusted must share one shape (..., m): {g_a.shape}, {sig.shape}, "
            f"{ok.shape}"
        )
    return g_a, sig, ok


def pair_pool(
    g: ArrayLike, sigma_m: ArrayLike, trusted: ArrayLike | None = None, pool_size: int = POOL_SIZE
) -> NDArray:
    """Satellites searched for three independent pairs: the best "low" and "high" halves.

    Each trusted satellite is ranked by the interval it would give with an ideal partner on
    the other side (``g = -1`` or ``+1``, the epoch's smallest trusted sigma); the
    ``pool_size // 2`` best "low" ones and then the best "high" ones among the rest are kept.

    Parameters
    ----------
    g, sigma_m : array_like, shape (..., m)
        Along-track components and pseudorange sigmas (metres), finite where trusted.
    trusted : array_like of bool, shape (..., m), optional
        Default: all trusted. Untrusted satellites enter the pool only to fill it when fewer
        than ``pool_size`` are trusted.
    pool_size : int
        At most ``m`` are kept.

    Returns
    -------
    ndarray of intp, shape (..., min(pool_size, m))
        Satellite indices, ascending (the pool is a set; sorting fixes the pair order of
        :func:`three_independent_pairs`). With ``m <= pool_size``: every satellite.
    """
    g_a, s, ok = _prepare(g, sigma_m, trusted)
    if pool_size < 2:
        raise ValueError(f"pool_size must be >= 2, got {pool_size}")
    lead, m = g_a.shape[:-1], g_a.shape[-1]
    p = min(pool_size, m)
    if m <= p:
        return np.broadcast_to(np.arange(m), (*lead, m)).copy()
    g2, s2, ok2 = g_a.reshape(-1, m), s.reshape(-1, m), ok.reshape(-1, m)
    g2, s2 = np.where(ok2, g2, 0.0), np.where(ok2, s2, 1.0)
    return np.sort(_pool(g2, s2, ok2, p), axis=-1).reshape(*lead, p)


def _pool(g: NDArray, s: NDArray, ok: NDArray, p: int) -> NDArray:
    """Pool indices (n, p), unsorted, of rows (n, m) with m > p and finite ``g``, ``s``.

    Untrusted satellites get ranks of at least 1e30 (an addition: 0 leaves the trusted exact,
    and is cheaper than ``np.where``), picked satellites ``inf``, so no pick is repeated.
    """
    pen = (~ok) * np.asarray(1e30, g.dtype)
    s0 = (s + pen).min(axis=-1, keepdims=True)  # smallest trusted sigma
    spread = np.sqrt(s * s + s0 * s0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        rank_lo = spread / (1.0 - g)
        rank_lo += pen
        rank_hi = spread / (1.0 + g)
        rank_hi += pen
    # repeated argmin, not argpartition: several times faster on rows of a few tens
    n, m = g.shape
    flat = np.arange(n) * m
    lo_flat, hi_flat = rank_lo.reshape(-1), rank_hi.reshape(-1)
    out = np.empty((n, p), np.intp)
    n_lo = p // 2
    for c in range(p):
        k = np.argmin(rank_lo if c < n_lo else rank_hi, axis=-1)
        out[:, c] = k
        hi_flat[flat + k] = np.inf
        if c < n_lo:
            lo_flat[flat + k] = np.inf
    return out


def matching_table(pool_size: int) -> tuple[NDArray, NDArray, NDArray]:
    """The pairs ``(i, j)`` of a pool of ``pool_size`` satellites (``np.triu_indices`` order)
    and every set of three disjoint pairs, shape (n_sets, 3), as pair indices, in the order in
    which :func:`three_independent_pairs` breaks ties (the locator's compiled copy of the
    rule uses it)."""
    if pool_size < 6:
        raise ValueError(f"three disjoint pairs need a pool of at least 6, got {pool_size}")
    return _matching_table(int(pool_size))


@lru_cache(maxsize=8)
def _matching_table(p: int) -> tuple[NDArray, NDArray, NDArray]:
    """Pairs of a pool of ``p`` and every set of three disjoint pairs, as pair indices."""
    i, j = np.triu_indices(p, 1)
    index = {(int(a), int(b)): k for k, (a, b) in enumerate(zip(i, j, strict=True))}

    def perfect(rest: tuple[int, ...]) -> list[list[tuple[int, int]]]:
        if not rest:
            return [[]]
        a, out = rest[0], []
        for x in range(1, len(rest)):
            for m in perfect(rest[1:x] + rest[x + 1 :]):
                out.append([(a, rest[x]), *m])
        return out

    sets = [
        [index[pr] for pr in m] for six in itertools.combinations(range(p), 6) for m in perfect(six)
    ]
    return readonly_array(i), readonly_array(j), readonly_array(sets, np.intp)  # cached: shared


@lru_cache(maxsize=8)
def _bottleneck_program(p: int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Index tables of the subset recursion of :func:`_three_pairs_half`.

    ``f4[T] = min over the 3 perfect matchings {e1, e2} of T of max(h[e1], h[e2])`` for the
    4-sets ``T`` needed below, and ``f6[S] = min over x in S - {a} of max(h[a, x],
    f4[S - {a, x}])`` with ``a = min(S)``, for every 6-set ``S``; the answer is ``min f6``.
    Returns ``(e1, e2)`` of shape (n4, 3) and ``(ax, t)`` of shape (n6, 5).
    """
    i, j = np.triu_indices(p, 1)
    pair = {(int(a), int(b)): k for k, (a, b) in enumerate(zip(i, j, strict=True))}
    fours: dict[tuple[int, ...], int] = {}
    ax, t = [], []
    for six in itertools.combinations(range(p), 6):
        a = six[0]
        row_ax, row_t = [], []
        for x in six[1:]:
            rest = tuple(c for c in six[1:] if c != x)
            row_ax.append(pair[(a, x)])
            row_t.append(fours.setdefault(rest, len(fours)))
        ax.append(row_ax)
        t.append(row_t)
    e1, e2 = [], []
    for q in fours:  # insertion order = index
        e1.append([pair[(q[0], q[1])], pair[(q[0], q[2])], pair[(q[0], q[3])]])
        e2.append([pair[(q[2], q[3])], pair[(q[1], q[3])], pair[(q[1], q[2])]])
    arr = [readonly_array(x, np.intp) for x in (e1, e2, ax, t)]  # cached: shared
    return arr[0], arr[1], arr[2], arr[3]


def _pool_half_lengths(
    g: NDArray, s: NDArray, ok: NDArray, pool: NDArray, k: float, pairs_first: bool
) -> NDArray:
    """Half lengths of every pair of the pool, inf unless both are trusted.

    ``pairs_first``: shape (n_pairs, n) (contiguous rows for the recursion), else (n, n_pairs).
    """
    n, m = g.shape
    i, j, _ = _matching_table(pool.shape[-1])
    if pairs_first:
        idx = np.arange(n) * m + pool.T  # (p, n) flat indices
        gp, sp, okp = (x.reshape(-1)[idx] for x in (g, s, ok))
        h = pair_half_length_m(gp[i], gp[j], sp[i], sp[j], k)
        return np.where(okp[i] & okp[j], h, np.inf)
    gp, sp, okp = (np.take_along_axis(x, pool, axis=-1) for x in (g, s, ok))
    h = pair_half_length_m(gp[:, i], gp[:, j], sp[:, i], sp[:, j], k)
    return np.where(okp[:, i] & okp[:, j], h, np.inf)


def three_independent_pairs(
    g: ArrayLike, sigma_m: ArrayLike, trusted: ArrayLike | None = None, k_sigma: float = 2.0
) -> tuple[NDArray, NDArray]:
    """Three disjoint pairs making the union of their intervals short (module docstring).

    Parameters
    ----------
    g, sigma_m : array_like, shape (..., m)
        Along-track components and pseudorange sigmas (metres), finite where trusted.
    trusted : array_like of bool, shape (..., m), optional
        Default: all trusted.
    k_sigma : float

    Returns
    -------
    pairs : ndarray of intp, shape (..., 3, 2)
        Satellite indices (``i < j`` in each pair), -1 with fewer than 6 trusted satellites.
        Among sets of equal union length (the longest pair decides it, so ties are common),
        the one with the smallest sum of the three half lengths.
    half_length_m : ndarray, shape (...)
        Largest half length of the three pairs (the union's half length when predicting);
        NaN with fewer than 6 trusted.

    Notes
    -----
    Memory ``~ 420 * 4 * n_epoch`` floats; :func:`predicted_interval` computes the same length
    without the indices, faster.
    """
    g_a, s, ok = _prepare(g, sigma_m, trusted)
    lead, m = g_a.shape[:-1], g_a.shape[-1]
    g2, s2, ok2 = g_a.reshape(-1, m), s.reshape(-1, m), ok.reshape(-1, m)
    pairs = np.full((len(g2), 3, 2), -1, np.intp)
    half = np.full(len(g2), np.nan, g_a.dtype)
    rows = np.nonzero(ok2.sum(-1) >= 6)[0]
    if len(rows):
        g2, s2, ok2 = g2[rows], s2[rows], ok2[rows]
        g2, s2 = np.where(ok2, g2, 0.0), np.where(ok2, s2, 1.0)
        pool = pair_pool(g2, s2, ok2)
        h = _pool_half_lengths(g2, s2, ok2, pool, k_sigma, False)
        i, j, sets = _matching_table(pool.shape[-1])
        hs = h[:, sets]  # (n, n_sets, 3)
        worst = hs.max(-1)
        # among sets of the shortest union, the shortest sum: the other pairs tight too
        tie = worst == worst.min(axis=-1, keepdims=True)
        best = np.argmin(np.where(tie, hs.sum(-1), np.inf), axis=-1)
        chosen = sets[best]  # (n, 3) pair indices
        pairs[rows, :, 0] = np.take_along_axis(pool, i[chosen], axis=-1)
        pairs[rows, :, 1] = np.take_along_axis(pool, j[chosen], axis=-1)
        half[rows] = np.take_along_axis(worst, best[:, None], axis=-1)[:, 0]
    return pairs.reshape(*lead, 3, 2), half.reshape(lead)


def best_pair(
    g: ArrayLike, sigma_m: ArrayLike, trusted: ArrayLike | None = None, k_sigma: float = 2.0
) -> tuple[NDArray, NDArray]:
    """The trusted pair with the shortest interval.

    Parameters
    ----------
    g, sigma_m : array_like, shape (..., m)
    trusted : array_like of bool, shape (..., m), optional
        Default: all trusted.
    k_sigma : float

    Returns
    -------
    pair : ndarray of intp, shape (..., 2)
        Satellite indices ``i < j`` (the first in ``np.triu_indices`` order among equal
        lengths), -1 with fewer than 2 trusted satellites.
    half_length_m : ndarray, shape (...)
        Its half length; NaN with fewer than 2 trusted.
    """
    g_a, s, ok = _prepare(g, sigma_m, trusted)
    lead, m = g_a.shape[:-1], g_a.shape[-1]
    if m < 2:
        return np.full((*lead, 2), -1, np.intp), np.full(lead, np.nan, g_a.dtype)
    i, j = np.triu_indices(m, 1)
    h = pair_half_length_m(g_a[..., i], g_a[..., j], s[..., i], s[..., j], k_sigma)
    h = np.where(ok[..., i] & ok[..., j], h, np.inf)
    has = ok.sum(-1) >= 2
    k = np.argmin(h, axis=-1)
    pair = np.where(has[..., None], np.stack([i[k], j[k]], axis=-1), -1)
    half = np.where(has, np.take_along_axis(h, k[..., None], axis=-1)[..., 0], np.nan)
    return pair, half.astype(g_a.dtype, copy=False)


def _three_pairs_half(g: NDArray, s: NDArray, ok: NDArray, k: float) -> NDArray:
    """Half length of :func:`three_independent_pairs` of rows (n, m) with >= 6 trusted.

    Bit-identical to the minimum over the matching table (min and max are exact) in about a
    third of the operations and on contiguous rows (no (n, 420, 3) gather).
    """
    n, m = g.shape
    p = min(POOL_SIZE, m)
    pool = _pool(g, s, ok, p) if m > p else np.broadcast_to(np.arange(p), (n, p))
    h = _pool_half_lengths(g, s, ok, pool, k, True)  # (n_pairs, n)
    e1, e2, ax, t = _bottleneck_program(p)
    f4 = np.maximum(h[e1], h[e2]).min(axis=1)  # (n4, n)
    f6 = np.maximum(h[ax], f4[t]).min(axis=1)  # (n6, n)
    return f6.min(axis=0)


def _trusted_first(
    ok: NDArray, count: NDArray, *columns: NDArray
) -> tuple[NDArray, list[NDArray]]:
    """Rows (n, m) of at most 5 trusted: which of their first ``min(5, m)`` columns, the
    trusted moved first, are trusted (n, w), and ``columns`` (n, m, ...) in that order. The
    stable sort keeps the trusted in their order, so :func:`best_pair` picks the same pair
    among equal lengths."""
    w = min(5, ok.shape[-1])
    order = np.argsort(~ok, axis=-1, kind="stable")[:, :w]
    rows = np.arange(len(ok))[:, None]
    valid = np.arange(w)[None, :] < count[:, None]
    return valid, [c[rows, order] for c in columns]


def _few(
    g: NDArray, s: NDArray, ok: NDArray, count: NDArray, k: tuple[float, float, float]
) -> NDArray:
    """Full length of rows with 2-5 trusted: best pair (2-3) or union of all pairs (4-5)."""
    valid, (gg, ss) = _trusted_first(ok, count, g, s)
    i, j = np.triu_indices(valid.shape[-1], 1)
    h = pair_half_length_m(gg[:, i], gg[:, j], ss[:, i], ss[:, j], k[1])
    worst = np.where(valid[:, i] & valid[:, j], h, -np.inf).max(-1)
    best = best_pair(gg, ss, valid, k[0])[1]
    return 2.0 * np.where(count >= 4, worst, best)
