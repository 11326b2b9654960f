"""The integrity budget: a stated risk per epoch and the pair-interval width ``k`` it implies.

A SATHIA interval is the **union** (outermost bounds) of satellite-pair intervals
(``docs/locator.md``). The union ``[min lo_i, max hi_i]`` misses the true position ``s`` only
if *every* pair interval lies on the same side of ``s`` (all ``lo_i > s``, or all
``hi_i < s``). Under the model (fault-free Gaussian pseudorange errors, independent between
satellites, ``sigma`` a bound of their spread, a monotone pair function near ``s``) a pair
interval ``K +- k sigma_K`` lies wholly above ``s`` with probability ``Q(k)`` and wholly below
with ``Q(k)``, ``Q`` the Gaussian upper tail: its two-sided risk is ``p = 2 Q(k)``. Pairs of
distinct satellites have independent errors, so with ``m`` disjoint pairs among those united::

    P(miss) <= P(the m disjoint pairs all miss on one side) = 2 Q(k)**m = 2 (p / 2)**m

(more pairs, sharing satellites, only shrink the event). A target ``T`` per epoch therefore
sets::

    Q(k) = (T / 2)**(1 / m),    k = Q^-1((T / 2)**(1 / m)),    p = 2 (T / 2)**(1 / m)

The source's anchor (seeds digest 000): ``1e-4`` per pair and ``1e-12`` for three independent
pairs is ``p**3``; the same-side argument gives ``2 (p / 2)**3 = 2.5e-13`` for ``p = 1e-4``
(``k = 3.89``), four times lower: the source's product is on the safe side. The source's own
``+-2 xi`` (``k = 2``) is ``p = 4.6e-2`` per pair and ``2.2e-4`` for three pairs.

:class:`IntegrityBudget` holds the target; :meth:`IntegrityBudget.k_sigma` gives ``k`` for the
number of disjoint pairs the combination rule guarantees (three for ``THREE_PAIRS``, two for
``ALL_PAIRS`` of 4-5 satellites, one for a single pair; never more than
:data:`MAX_INDEPENDENT_PAIRS` are credited). :func:`disjoint_pairs` counts them in a set of
pairs; :func:`union_risk` is the inverse (the risk bound of a given ``k``).

The budget covers the fault-free case only: faults (a wrong ephemeris, NLOS, multipath beyond
the model) are the trust decision's and FDE's share, not bounded here.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "DEFAULT_BUDGET",
    "DEFAULT_RISK_PER_EPOCH",
    "MAX_INDEPENDENT_PAIRS",
    "IntegrityBudget",
    "disjoint_pairs",
    "union_risk",
]

DEFAULT_RISK_PER_EPOCH = 1e-12
"""The source's SIL-4 figure for the union of three independent pairs (seeds digest 000)."""

MAX_INDEPENDENT_PAIRS = 3
"""The most disjoint pairs credited in an epoch: the source's rule (three independent pairs).
More would lean further on the independence of the satellites' errors."""

_MAX_RISK = 0.1  # a risk per epoch above 10 % is no integrity target (percent given?)
_EXACT_MATCHING_PAIRS = 15  # up to this many pairs the disjoint count is exact


@dataclass(frozen=True)
class IntegrityBudget:
    """The integrity risk allowed per epoch, and the pair-interval width it implies.

    Attributes
    ----------
    risk_per_epoch : float
        Probability that a claimed interval misses the true position in one epoch, under the
        fault-free Gaussian model (module docstring), in ``(0, 0.1]``.
    """

    risk_per_epoch: float = DEFAULT_RISK_PER_EPOCH

    def __post_init__(self) -> None:
        r = self.risk_per_epoch
        if not (isinstance(r, (int, float)) and math.isfinite(r) and 0 < r <= _MAX_RISK):
            raise ValueError(
                f"IntegrityBudget.risk_per_epoch must be a probability in (0, {_MAX_RISK:g}], "
                f"got {r!r}; give e.g. 1e-12 (the source's three pairs), not a percentage"
            )

    @classmethod
    def from_pair_risk(cls, risk_per_pair: float, independent_pairs: int) -> IntegrityBudget:
        """The budget whose ``independent_pairs``-pair union has ``risk_per_pair`` per pair.

        ``from_pair_risk(1e-4, 3)`` is the source's anchor: ``2 (1e-4 / 2)**3 = 2.5e-13``.
        """
        if not 0 < risk_per_pair < 1:
            raise ValueError(f"risk_per_pair must be in (0, 1), got {risk_per_pair}")
        return cls(2.0 * (risk_per_pair / 2.0) ** _credited(independent_pairs))

    def pair_risk(self, independent_pairs: int) -> float:
        """Two-sided risk of one pair interval, ``2 (T / 2)**(1 / m)``."""
        return 2.0 * (self.risk_per_epoch / 2.0) ** (1.0 / _credited(independent_pairs))

    def k_sigma(self, independent_pairs: int) -> float:
        """Half width of each pair interval in sigmas of ``K``, ``Q^-1((T / 2)**(1 / m))``.

        Parameters
        ----------
        independent_pairs : int
            Disjoint pairs among those united (:func:`disjoint_pairs`), >= 1; more than
            :data:`MAX_INDEPENDENT_PAIRS` count as that many.
        """
        return _k_sigma(float(self.risk_per_epoch), _credited(independent_pairs))

    def label(self) -> str:
        """``"integrity risk 1e-12 per epoch"``."""
        return f"integrity risk {self.risk_per_epoch:.3g} per epoch"

    def describe(self) -> str:
        """The risk and the ``k`` of one, two and three independent pairs, for captions."""
        ks = ", ".join(
            f"k = {self.k_sigma(m):.2f} ({name})"
            for m, name in ((3, "three pairs"), (2, "all pairs of 4-5"), (1, "one pair"))
        )
        return f"{self.label()}: {ks}"


DEFAULT_BUDGET = IntegrityBudget()
"""The library's one default (:data:`DEFAULT_RISK_PER_EPOCH` per epoch), as every command line's
``--integrity-risk``: ``locator.fde.LocatorConfig().budget`` and the ``integrity=`` default of
:func:`predisat.availability.run.run_availability`, ``compute_availability`` and ``trainrun``.
Pass ``None`` there (with an ``IntervalModel`` whose ``k_sigma`` is the width wanted) to fix
one ``k`` for every mode instead, e.g. the source's ``k = 2``."""


def union_risk(k_sigma: float, independent_pairs: int) -> float:
    """Risk bound per epoch of a union with ``k_sigma`` wide pairs: ``2 Q(k)**m``."""
    # lazy: scipy.stats is slow to import and only the budget needs it
    from scipy.stats import norm

    if not (k_sigma > 0 and math.isfinite(k_sigma)):
        raise ValueError(f"k_sigma must be positive and finite, got {k_sigma}")
    return float(2.0 * norm.sf(k_sigma) ** _credited(independent_pairs))


def disjoint_pairs(pairs: ArrayLike) -> int:
    """How many pairs of distinct satellites can be picked from ``pairs``, at most 3.

    Parameters
    ----------
    pairs : array_like of int, shape (p, 2)
        Satellite indices of each pair.

    Returns
    -------
    int
        The size of a largest matching, capped at :data:`MAX_INDEPENDENT_PAIRS`: exact for up
        to 15 pairs; beyond, a greedy matching (never more than the largest, so the width it
        implies errs on the safe side; a complete set of ``n`` satellites gets ``n // 2``).
    """
    pr = np.asarray(pairs)
    if pr.ndim != 2 or (pr.size and pr.shape[1] != 2):
        raise ValueError(f"pairs must have shape (p, 2), got {pr.shape}")
    edges = [(int(a), int(b)) for a, b in pr.reshape(-1, 2) if a != b]
    if not edges:
        return 0
    cap = MAX_INDEPENDENT_PAIRS
    if len(edges) <= _EXACT_MATCHING_PAIRS:
        for m in range(min(cap, len(edges)), 1, -1):
            for combo in itertools.combinations(edges, m):
                if len({s for e in combo for s in e}) == 2 * m:
                    return m
        return 1
    used: set[int] = set()
    m = 0
    for a, b in edges:
        if a not in used and b not in used:
            used |= {a, b}
            m += 1
            if m == cap:
                break
    return m


def _credited(independent_pairs: int) -> int:
    m = int(independent_pairs)
    if m != independent_pairs or m < 1:
        raise ValueError(f"independent_pairs must be an integer >= 1, got {independent_pairs}")
    return min(m, MAX_INDEPENDENT_PAIRS)


@lru_cache(maxsize=64)
def _k_sigma(risk: float, m: int) -> float:
    from scipy.stats import norm

    return float(norm.isf((risk / 2.0) ** (1.0 / m)))
