"""The compiled locator kernels' building blocks against independent arithmetic.

The kernels as a whole are pinned bit for bit on frozen outputs of the numpy code they
replaced (``tests/regression/test_locator_reference.py``); here the pieces whose exactness
that rests on: the fused multiply-add (exact rational arithmetic), numpy's pairwise sum, the
three-pair plan against the availability prediction's own numpy implementation, the union.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from locator.kernels import fma, pairwise_sum, three_pairs_kernel, union_kernel
from predisat.availability import interval as pred


def test_fma_rounds_once() -> None:
    rng = np.random.default_rng(0)
    a, b, c = (rng.normal(size=500) * 10.0 ** rng.uniform(-6, 8, 500) for _ in range(3))
    for x, y, z in zip(a, b, c, strict=True):
        assert fma(x, y, z) == float(Fraction(x) * Fraction(y) + Fraction(z))
    # a case where rounding the product first loses the answer
    e = 2.0**-30
    assert fma(1.0 + e, 1.0 - e, -1.0) == -(2.0**-60)
    assert (1.0 + e) * (1.0 - e) - 1.0 == 0.0


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 31, 128, 129, 300, 1000])
def test_pairwise_sum_is_numpy_sum(n: int) -> None:
    rng = np.random.default_rng(n)
    a = rng.normal(size=n) * 10.0 ** rng.uniform(-3, 9, n)
    assert pairwise_sum(a) == np.sum(a)
    # and it is not the naive left-to-right sum, which numpy's differs from on such data
    if n == 1000:
        naive = 0.0
        for v in a:
            naive += v
        assert naive != np.sum(a)


@pytest.mark.parametrize("m", [6, 7, 8, 9, 14, 30])
def test_three_pairs_kernel_is_the_prediction_rule(m: int) -> None:
    rng = np.random.default_rng(m)
    for _ in range(40):
        g = rng.uniform(-1.0, 1.0, m)
        if rng.random() < 0.3:  # ties: equal along-track components and sigmas
            g[1] = g[0]
        sig = rng.choice([1.5, 2.0, 3.0], m) if rng.random() < 0.5 else rng.uniform(0.5, 6, m)
        want, _ = pred.three_independent_pairs(g, sig, None, 3.89)
        i, j, sets = pred.matching_table(min(pred.POOL_SIZE, m))
        got = three_pairs_kernel(g, sig, 3.89, pred.POOL_SIZE, i, j, sets)
        np.testing.assert_array_equal(got, want)


def test_union_kernel() -> None:
    lo = np.array([10.0, 12.0, -np.inf])
    hi = np.array([30.0, 25.0, 40.0])
    root = np.array([20.0, np.nan, 21.0])
    slope = np.array([0.5, np.nan, 0.25])
    sk = np.array([2.0, 3.0, 1.0])
    a, b, est, consistent = union_kernel(lo, hi, root, slope, sk)
    w = np.array([(0.5 / 2.0) ** 2, 0.0, 0.25**2])
    assert (a, b) == (-np.inf, 40.0)
    assert est == pytest.approx((w[0] * 20.0 + w[2] * 21.0) / w.sum(), rel=1e-15)
    assert consistent
    _, _, _, consistent = union_kernel(lo, np.array([30.0, 11.0, 40.0]), root, slope, sk)
    assert not consistent  # 12 > 11: no common point
    _, _, est, _ = union_kernel(lo[1:2], hi[1:2], root[1:2], slope[1:2], sk[1:2])
    assert np.isnan(est)  # no pair with a root: no estimate
