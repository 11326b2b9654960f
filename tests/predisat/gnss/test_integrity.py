"""The integrity budget: k from the risk per epoch and the union of independent pairs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from predisat.gnss.integrity import (
    DEFAULT_RISK_PER_EPOCH,
    MAX_INDEPENDENT_PAIRS,
    IntegrityBudget,
    disjoint_pairs,
    union_risk,
)


@pytest.mark.parametrize(
    ("risk", "m", "k"),
    [
        # k = Q^-1((T/2)^(1/m)), computed by hand from tabulated Gaussian quantiles
        (1e-4, 1, 3.890592),  # Q(k) = 5e-5: the source's 1e-4 per pair
        (0.0455002638, 1, 2.0),  # the source's +-2 xi as a one-pair risk
        (2.5e-13, 3, 3.890592),  # three pairs of 1e-4: 2 (5e-5)^3
        (2e-12, 2, 4.753424),  # Q(k) = 1e-6
    ],
)
def test_k_sigma_matches_the_gaussian_quantile(risk: float, m: int, k: float) -> None:
    assert IntegrityBudget(risk).k_sigma(m) == pytest.approx(k, abs=2e-6)


def test_k_against_scipy_for_the_default_budget() -> None:
    b = IntegrityBudget()
    assert b.risk_per_epoch == DEFAULT_RISK_PER_EPOCH == 1e-12
    for m in (1, 2, 3):
        q = (1e-12 / 2) ** (1 / m)
        assert b.k_sigma(m) == pytest.approx(norm.ppf(1 - q) if q > 1e-10 else norm.isf(q))
        assert b.pair_risk(m) == pytest.approx(2 * q)
    # more pairs than the source's three are credited as three (safe side)
    assert b.k_sigma(5) == b.k_sigma(3)
    assert MAX_INDEPENDENT_PAIRS == 3
    assert b.k_sigma(3) < b.k_sigma(2) < b.k_sigma(1)


def test_the_source_anchor() -> None:
    # 1e-4 per pair over three independent pairs: the same-side bound is 2 (5e-5)^3
    b = IntegrityBudget.from_pair_risk(1e-4, 3)
    assert b.risk_per_epoch == pytest.approx(2.5e-13)
    assert b.pair_risk(3) == pytest.approx(1e-4)
    assert union_risk(b.k_sigma(3), 3) == pytest.approx(2.5e-13)
    # the source's k = 2: 2 Q(2)^3
    assert union_risk(2.0, 3) == pytest.approx(2 * 0.02275013194817921**3)


@pytest.mark.parametrize("bad", [0.0, -1e-9, 0.5, 1.0, 5.0, math.nan, math.inf])
def test_bad_risk_is_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="risk_per_epoch"):
        IntegrityBudget(bad)


def test_bad_pair_counts_are_refused() -> None:
    with pytest.raises(ValueError, match="independent_pairs"):
        IntegrityBudget().k_sigma(0)
    with pytest.raises(ValueError, match="independent_pairs"):
        IntegrityBudget().k_sigma(2.5)  # type: ignore[arg-type]


def test_disjoint_pairs() -> None:
    assert disjoint_pairs(np.zeros((0, 2), int)) == 0
    assert disjoint_pairs([[0, 1]]) == 1
    assert disjoint_pairs([[0, 1], [0, 2], [0, 3]]) == 1  # a star shares satellite 0
    assert disjoint_pairs([[0, 1], [1, 2], [2, 3]]) == 2  # a path of four: (0,1), (2,3)
    assert disjoint_pairs([[0, 1], [2, 3], [4, 5]]) == 3
    i, j = np.triu_indices(4, 1)
    assert disjoint_pairs(np.stack([i, j], -1)) == 2  # all pairs of 4
    i, j = np.triu_indices(5, 1)
    assert disjoint_pairs(np.stack([i, j], -1)) == 2  # all pairs of 5
    i, j = np.triu_indices(12, 1)  # 66 pairs: greedy, capped at 3
    assert disjoint_pairs(np.stack([i, j], -1)) == 3
    with pytest.raises(ValueError, match="shape"):
        disjoint_pairs([0, 1, 2])


def _union_misses(
    k: float,
    pairs: list[tuple[int, int]],
    n_sat: int,
    n: int,
    seed: int,
    sig: np.ndarray | None = None,
    slopes: np.ndarray | None = None,
) -> float:
    """Monte Carlo share of epochs whose union of pair intervals misses the truth.

    Independent of the module: satellite errors ``xi ~ N(0, sigma_i)``, a pair's along-track
    error ``(xi_i - xi_j) / slope`` with a random slope sign, its interval ``+- k sigma_K /
    |slope|`` around that, the union the outermost bounds.
    """
    rng = np.random.default_rng(seed)
    sig = rng.uniform(0.5, 3.0, n_sat) if sig is None else sig
    if slopes is None:
        slopes = rng.choice([-1.0, 1.0], len(pairs)) * rng.uniform(0.2, 1.5, len(pairs))
    xi = rng.normal(0.0, 1.0, (n, n_sat)) * sig
    lo = np.full(n, np.inf)
    hi = np.full(n, -np.inf)
    for (a, b), slope in zip(pairs, slopes, strict=True):
        err = (xi[:, a] - xi[:, b]) / slope
        half = k * math.hypot(sig[a], sig[b]) / abs(slope)
        lo = np.minimum(lo, err - half)
        hi = np.maximum(hi, err + half)
    return float(np.mean((lo > 0) | (hi < 0)))


@pytest.mark.parametrize(
    ("n_sat", "pairs", "m"),
    [
        (6, [(0, 1), (2, 3), (4, 5)], 3),  # THREE_PAIRS
        (4, [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)], 2),  # ALL_PAIRS of 4
        (5, [(i, j) for i in range(5) for j in range(i + 1, 5)], 2),  # ALL_PAIRS of 5
        (4, [(0, 1), (0, 2), (0, 3)], 1),  # blunt pairs dropped: a star, one independent
    ],
)
def test_union_miss_rate_stays_within_a_loose_target(
    n_sat: int, pairs: list[tuple[int, int]], m: int
) -> None:
    target = 1e-2
    assert disjoint_pairs(pairs) == m
    k = IntegrityBudget(target).k_sigma(m)
    n = 400_000
    rate = _union_misses(k, pairs, n_sat, n, seed=n_sat + len(pairs))
    # within the target with 4 binomial sigmas of room for the simulation's own noise
    assert rate <= target + 4 * math.sqrt(target / n)
    if m == 3:
        # for disjoint pairs the bound is exact: 2 Q(k)^3 = target
        assert rate == pytest.approx(target, rel=0.05)


def test_pairs_sharing_a_satellite_are_not_independent() -> None:
    # a star whose common satellite dominates, all slopes of one sign: the three pairs move
    # together, so crediting them as two independent pairs would miss the target
    target, n = 1e-2, 400_000
    star = [(0, 1), (0, 2), (0, 3)]
    sig = np.array([5.0, 0.3, 0.3, 0.3])
    slopes = np.array([0.5, 0.6, 0.7])
    k_right = IntegrityBudget(target).k_sigma(disjoint_pairs(star))
    k_wrong = IntegrityBudget(target).k_sigma(2)
    assert _union_misses(k_right, star, 4, n, 3, sig, slopes) <= target
    assert _union_misses(k_wrong, star, 4, n, 3, sig, slopes) > 2 * target
