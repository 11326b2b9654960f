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

The pseudorange error model (:class:`ErrorModel`) is a placeholder with stated defaults, to be
learned from data by ``locator calibrate``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from enum import IntEnum
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "POOL_SIZE",
    "ErrorModel",
    "IntervalMode",
    "IntervalModel",
    "along_track_components",
    "interval_mode",
    "pair_half_length_m",
    "predicted_interval",
]


class IntervalMode(IntEnum):
    """How the interval of an epoch is formed (by the number of trusted satellites)."""

    NONE = 0  # fewer than 2 satellites
    BEST_PAIR = 1  # 2-3 satellites: best pair, no safety claim
    ALL_PAIRS = 2  # 4-5 satellites: union of all pairs
    THREE_PAIRS = 3  # >= 6 satellites: union of three independent pairs


@dataclass(frozen=True)
class ErrorModel:
    """Elevation-dependent pseudorange error, ``sigma(el)**2 = a**2 + (b / sin(el))**2``.

    The form is RTKLIB's code/phase variance model; the defaults (a = b = 2 m: 2.8 m at the
    zenith, 3.5 m at 45 deg, 8.0 m at 15 deg, 11.7 m at 10 deg) are of the order of
    single-frequency code errors with broadcast orbits, clocks and ionosphere. They are a
    **model to be learned** (``locator calibrate``), not measured values.

    Attributes
    ----------
    a_m, b_m : float
        Constant and elevation-dependent parts, metres.
    min_el_deg : float
        Elevations below this are treated as this (keeps sigma finite at the horizon).
    """

    a_m: float = 2.0
    b_m: float = 2.0
    min_el_deg: float = 1.0

    def __post_init__(self) -> None:
        if self.a_m < 0 or self.b_m < 0 or self.a_m + self.b_m <= 0:
            raise ValueError(f"ErrorModel a_m, b_m must be >= 0, not both 0: {self}")
        if not 0 < self.min_el_deg < 90:
            raise ValueError(f"ErrorModel.min_el_deg must be in (0, 90), got {self.min_el_deg}")

    def sigma_m(self, el_deg: ArrayLike) -> NDArray:
        """Pseudorange sigma in metres, shape of ``el_deg``."""
        el = np.maximum(np.asarray(el_deg, float), self.min_el_deg)
        return self.sigma_from_sin(np.sin(np.radians(el)))

    def sigma_from_sin(self, sin_el: ArrayLike) -> NDArray:
        """The same from ``sin(el)`` (any float dtype, kept), for the vectorised engine."""
        s = np.asarray(sin_el)
        lo = np.sin(np.radians(self.min_el_deg))
        s = np.maximum(s, np.asarray(lo, s.dtype))
        return np.sqrt(self.a_m**2 + (self.b_m / s) ** 2)


@dataclass(frozen=True)
class IntervalModel:
    """Error model plus the width factor of each pair interval.

    Attributes
    ----------
    error : ErrorModel
    k_sigma : float
        Half width of a pair interval in sigmas of ``K``. Default 2 as in the source
        (``+-2 xi``). Note: for Gaussian errors 2 sigma leaves 4.6e-2 outside per pair, not
        the 1e-4 the source claims (that needs 3.89 sigma: :meth:`for_risk`).
    """

    error: ErrorModel = field(default_factory=ErrorModel)
    k_sigma: float = 2.0

    def __post_init__(self) -> None:
        if not self.k_sigma > 0:
            raise ValueError(f"IntervalModel.k_sigma must be positive, got {self.k_sigma}")

    @classmethod
    def for_risk(cls, risk_per_pair: float, error: ErrorModel | None = None) -> IntervalModel:
        """``k_sigma`` giving a two-sided Gaussian risk per pair (1e-4 -> 3.89)."""
        from scipy.stats import norm

        if not 0 < risk_per_pair < 1:
            raise ValueError(f"risk_per_pair must be in (0, 1), got {risk_per_pair}")
        return cls(error or ErrorModel(), float(norm.isf(risk_per_pair / 2.0)))


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
    g: ArrayLike, sigma_m: ArrayLike, trusted: ArrayLike, k_sigma: float = 2.0
) -> tuple[NDArray, NDArray]:
    """Predicted SATHIA interval length per epoch (see the module docstring for the rule).

    Parameters
    ----------
    g : array_like, shape (..., m)
        Along-track components ``u . t`` of the candidate satellites.
    sigma_m : array_like, shape (..., m)
        Pseudorange sigmas, metres.
    trusted : array_like of bool, shape (..., m)
    k_sigma : float

    Returns
    -------
    length_m : ndarray of float32, shape (...)
        Full interval length (twice the half length); NaN with fewer than two satellites.
    mode : ndarray of uint8, shape (...)
        :class:`IntervalMode`.
    """
    g_a = np.asarray(g)
    dtype = np.float32 if g_a.dtype == np.float32 else np.float64
    g_a = g_a.astype(dtype, copy=False)
    sig = np.asarray(sigma_m).astype(dtype, copy=False)
    ok = np.asarray(trusted, bool)
    if not g_a.shape == sig.shape == ok.shape:
        raise ValueError(
            f"g, sigma_m and trusted must share one shape (..., m): {g_a.shape}, {sig.shape}, "
            f"{ok.shape}"
        )
    lead = g_a.shape[:-1]
    m = g_a.shape[-1]
    g2, s2, ok2 = g_a.reshape(-1, m), sig.reshape(-1, m), ok.reshape(-1, m)
    count = ok2.sum(-1)
    out = np.full(len(count), np.nan, dtype)
    mode = interval_mode(count)

    six = np.nonzero(count >= 6)[0]
    if len(six):
        out[six] = _three_pairs(g2[six], s2[six], ok2[six], k_sigma)
    few = np.nonzero((count >= 2) & (count < 6))[0]
    if len(few):
        out[few] = _few(g2[few], s2[few], ok2[few], count[few], k_sigma)
    return out.reshape(lead).astype(np.float32), mode.reshape(lead)


POOL_SIZE = 8
"""Satellites kept per epoch for the exhaustive three-pair search (see the module docstring)."""


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
    return i, j, np.array(sets, np.intp)


def _three_pairs(g: NDArray, s: NDArray, ok: NDArray, k: float) -> NDArray:
    rows = np.arange(len(g))[:, None]
    p = min(POOL_SIZE, g.shape[-1])
    # rank each satellite by its interval with an ideal partner (g = -+1, the smallest sigma
    # of the epoch); keep the best half of the pool as "low" and the rest as "high"
    s0 = np.where(ok, s, np.inf).min(axis=-1, keepdims=True)
    spread = np.sqrt(s * s + s0 * s0)
    with np.errstate(divide="ignore", invalid="ignore"):
        # untrusted: large but finite, so that the "low" picks (inf) are never taken twice
        rank_lo = np.where(ok, spread / (1.0 - g), 1e30)
        rank_hi = np.where(ok, spread / (1.0 + g), 1e30)
    n_lo = p // 2
    lo = np.argpartition(rank_lo, n_lo - 1, axis=-1)[:, :n_lo]
    np.put_along_axis(rank_hi, lo, np.inf, axis=-1)
    hi = np.argpartition(rank_hi, p - n_lo - 1, axis=-1)[:, : p - n_lo]
    pool = np.concatenate([lo, hi], axis=1)
    gp, sp, okp = g[rows, pool], s[rows, pool], ok[rows, pool]
    i, j, sets = _matching_table(p)
    h = pair_half_length_m(gp[:, i], gp[:, j], sp[:, i], sp[:, j], k)
    h = np.where(okp[:, i] & okp[:, j], h, np.inf)
    return 2.0 * h[:, sets].max(-1).min(-1)


def _few(g: NDArray, s: NDArray, ok: NDArray, count: NDArray, k: float) -> NDArray:
    w = min(5, g.shape[-1])
    order = np.argsort(~ok, axis=-1, kind="stable")[:, :w]  # trusted first
    rows = np.arange(len(g))[:, None]
    gg, ss = g[rows, order], s[rows, order]
    valid = np.arange(w)[None, :] < count[:, None]
    i, j = np.triu_indices(w, 1)
    h = pair_half_length_m(gg[:, i], gg[:, j], ss[:, i], ss[:, j], k)
    pair_ok = valid[:, i] & valid[:, j]
    worst = np.where(pair_ok, h, -np.inf).max(-1)
    best = np.where(pair_ok, h, np.inf).min(-1)
    return 2.0 * np.where(count >= 4, worst, best)
