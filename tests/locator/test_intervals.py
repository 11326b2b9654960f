"""Pair plans by integrity mode, union of intervals, along-track geometry, error-model fit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.stats import norm

from locator.intervals import (
    along_track_g,
    best_pair,
    fit_error_model,
    overbound_error_model,
    plan_pairs,
    three_independent_pairs,
    union_interval,
)
from locator.sathia import PairSolution, solve_pairs
from predisat.availability.interval import IntervalMode
from predisat.gnss.errormodel import ErrorModel
from tests.locator._scene import random_sky, ranges, sky, straight_path


def _half(g, s, i, j, k=2.0):
    return k * np.hypot(s[i], s[j]) / abs(g[i] - g[j])


def _brute_three(g, s):
    """Smallest max half-length over every set of three disjoint pairs (independent search)."""

    def matchings(rest):
        if not rest:
            yield []
            return
        for k in range(1, len(rest)):
            for m in matchings(rest[1:k] + rest[k + 1 :]):
                yield [(rest[0], rest[k]), *m]

    return min(
        max(_half(g, s, a, b) for a, b in m)
        for six in itertools.combinations(range(len(g)), 6)
        for m in matchings(six)
    )


@pytest.mark.parametrize("n", [6, 7, 8])
def test_three_pairs_exact_for_small_skies(n):
    rng = np.random.default_rng(n)
    for _ in range(3):
        g = rng.uniform(-0.9, 0.9, n)
        s = rng.uniform(1.0, 5.0, n)
        pr = three_independent_pairs(g, s)
        assert pr.shape == (3, 2) and len(set(pr.ravel().tolist())) == 6
        got = max(_half(g, s, a, b) for a, b in pr)
        assert got == pytest.approx(_brute_three(g, s), rel=1e-12)


def test_three_pairs_from_a_larger_sky_are_disjoint_and_good():
    rng = np.random.default_rng(1)
    g = rng.uniform(-0.9, 0.9, 12)
    s = np.full(12, 3.0)
    pr = three_independent_pairs(g, s)
    assert len(set(pr.ravel().tolist())) == 6
    # equal sigmas: the pool heuristic is exact (docs/availability.md), check by brute force
    # on the 8-satellite pool of the extremes
    got = max(_half(g, s, a, b) for a, b in pr)
    assert got == pytest.approx(_brute_three(g, s), rel=1e-9)


def test_best_pair_and_plans_by_count():
    g = np.array([-0.8, 0.1, 0.7, 0.2, -0.1, 0.5, 0.0])
    s = np.full(7, 2.0)
    assert best_pair(g, s).tolist() == [[0, 2]]
    for n, mode, n_pairs in [
        (2, IntervalMode.BEST_PAIR, 1),
        (3, IntervalMode.BEST_PAIR, 1),
        (4, IntervalMode.ALL_PAIRS, 6),
        (5, IntervalMode.ALL_PAIRS, 10),
        (6, IntervalMode.THREE_PAIRS, 3),
        (7, IntervalMode.THREE_PAIRS, 3),
    ]:
        pr, m = plan_pairs(g[:n], s[:n])
        assert m == mode and len(pr) == n_pairs
    pr, m = plan_pairs(g, s, scheme="all")
    assert m == IntervalMode.ALL_PAIRS and len(pr) == 21
    pr, m = plan_pairs(g[:1], s[:1])
    assert m == IntervalMode.NONE and len(pr) == 0
    with pytest.raises(ValueError, match="scheme"):
        plan_pairs(g, s, scheme="some")


def test_union_interval_rules():
    def sol(lo, hi, root, slope, sk):
        n = len(lo)
        z = np.zeros(n, int)
        return PairSolution(
            z,
            z + 1,
            np.zeros(n),
            np.asarray(sk, float),
            2.0,
            np.asarray(root, float),
            np.asarray(lo, float),
            np.asarray(hi, float),
            np.asarray(slope, float),
            z + 1,
            np.zeros(n),
            z.astype(np.uint8),
        )

    u = union_interval(
        sol([0, 5, 2], [10, 12, 8], [5, 8, 5], [1.0, 0.5, 1.0], [1, 1, 2]), IntervalMode.THREE_PAIRS
    )
    assert (u.lo_m, u.hi_m) == (0.0, 12.0)
    w = np.array([1.0, 0.25, 0.25])
    assert u.estimate_m == pytest.approx(np.sum(w * [5, 8, 5]) / w.sum())
    assert u.consistent and u.safety_claim and u.contains(11.0) and not u.contains(12.5)
    apart = union_interval(
        sol([0, 11], [10, 12], [5, 11.5], [1, 1], [1, 1]), IntervalMode.ALL_PAIRS
    )
    assert not apart.consistent and not apart.safety_claim
    few = union_interval(sol([0], [10], [5], [1], [1]), IntervalMode.BEST_PAIR)
    assert few.lo_m == 0 and not few.safety_claim
    open_ = union_interval(
        sol([0, -np.inf], [10, 3], [5, 1], [1, 1], [1, 1]), IntervalMode.ALL_PAIRS
    )
    assert not open_.safety_claim


def test_along_track_g_analytic():
    path = straight_path(60.0)
    x = path.ecef_at(1000.0)
    sat = sky(x, [60.0, 150.0, 240.0], [30.0, 45.0, 0.0])
    g = along_track_g(path, 1000.0, sat)
    # straight in the frame's ENU: a slight grade relative to the local horizontal at 1 km
    tilt = np.arctan(path.track.grade_at(1000.0))
    dh = np.radians(path.track.heading_at(1000.0) - 60.0)
    el = np.radians([30.0, 45.0, 0.0])
    daz = np.radians([0.0, 90.0, 180.0]) - dh
    expected = np.cos(el) * np.cos(daz) * np.cos(tilt) + np.sin(el) * np.sin(tilt)
    np.testing.assert_allclose(g, expected, atol=1e-6)
    assert abs(g[1]) < 1e-3 and g[0] == pytest.approx(np.cos(np.radians(30.0)), abs=1e-3)


def test_three_pair_union_holds_truth():
    """Union of three independent k=2 pairs misses with probability about 0.046**3."""
    path = straight_path(10.0)
    rng = np.random.default_rng(11)
    s_true = 1500.0
    x = path.ecef_at(s_true)
    misses = 0
    lengths = []
    for _ in range(80):
        sat = sky(x, *random_sky(rng, 8))
        sig = np.full(8, 3.0)
        rho = ranges(sat, x, sig, rng)
        pr, mode = plan_pairs(along_track_g(path, s_true, sat), sig)
        u = union_interval(solve_pairs(path, sat, rho, sig, pr, prior_m=s_true), mode)
        misses += not u.contains(s_true)
        lengths.append(u.length_m)
    assert mode == IntervalMode.THREE_PAIRS
    assert misses <= 1
    assert 5.0 < np.median(lengths) < 200.0


def test_fit_error_model_recovers_parameters():
    rng = np.random.default_rng(5)
    n_ep, n_sat = 400, 9
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(8.0)), 1.0, (n_ep, n_sat))))
    a, b = 1.5, 3.0
    sd = np.sqrt(a**2 + (b / np.sin(np.radians(el))) ** 2)
    res = rng.normal(0.0, 1.0, el.shape) * sd + rng.normal(0, 300.0, (n_ep, 1))  # + clock
    el[rng.random(el.shape) < 0.1] = np.nan  # missing observations
    model = fit_error_model(el, res)
    assert model.a_m == pytest.approx(a, rel=0.25)
    assert model.b_m == pytest.approx(b, rel=0.1)
    with pytest.raises(ValueError, match="at least"):
        fit_error_model(el[:2], res[:2])


def _residuals(rng, n_ep, sigma_of_el):
    """Residuals of ``n_ep`` epochs of 9 satellites with a large common clock (returned)."""
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(5.0)), 1.0, (n_ep, 9))))
    clock = rng.normal(0.0, 300.0, (n_ep, 1))
    return el, rng.normal(size=el.shape) * sigma_of_el(el) + clock, clock


def test_overbound_of_a_true_model_stays_close():
    truth = ErrorModel(a_m=0.5, b_m=1.0)
    el, res, _ = _residuals(np.random.default_rng(11), 3000, truth.sigma_m)
    ob = overbound_error_model(el, res)
    # sampling noise only: the bound is the fit, inflated by little, never deflated
    assert 1.0 <= ob.factor < 1.2
    assert ob.bin_n.sum() == np.isfinite(res).sum() and len(ob.bin_factor) == 6
    assert (np.diff(ob.bin_el_lo_deg) > 0).all()


def test_overbound_covers_every_bin_where_the_fit_does_not():
    # errors that are not of the fitted form: twice the model above 60 deg (orbit errors of the
    # overhead satellites, say); coverage is scored on fresh draws with the true clock removed
    base = ErrorModel(a_m=0.3, b_m=0.4)

    def sigma(el):
        return base.sigma_m(el) * np.where(el > 60.0, 2.0, 1.0)

    rng = np.random.default_rng(3)
    el, res, _ = _residuals(rng, 2000, sigma)
    fit = fit_error_model(el, res)
    ob = overbound_error_model(el, res, fit)
    assert ob.fitted == fit and ob.factor > 1.3
    el2, res2, clock2 = _residuals(rng, 4000, sigma)
    err = np.abs(res2 - clock2)
    high = el2 > 60.0
    k = 2.0  # Gaussian: 4.55 % outside
    outside_fit = np.mean(err[high] > k * fit.sigma_m(el2[high]))
    assert outside_fit > 0.10
    # bounded per bin of the overbound (an excess on part of a bin is bounded on its average)
    for lo, hi in zip(ob.bin_el_lo_deg, ob.bin_el_hi_deg, strict=True):
        sel = (el2 >= lo) & (el2 <= hi)
        bound = ob.model.sigma_m(el2[sel])
        # 2 sigma: 4.55 % for a Gaussian, 3.0-4.9 % in the top bin over seeds 0-5
        assert np.mean(err[sel] > 2.0 * bound) < 0.055, (lo, hi)
        # 3 sigma: 0.27 %; about 16 errors expected in the top bin, so a factor 2 of room
        assert np.mean(err[sel] > 3.0 * bound) < 2 * 0.0027, (lo, hi)


def test_overbound_guards():
    el, res, _ = _residuals(np.random.default_rng(1), 50, ErrorModel(0.5, 1.0).sigma_m)
    with pytest.raises(ValueError, match="n_bins"):
        overbound_error_model(el, res, n_bins=0)
    with pytest.raises(ValueError, match="max_tail_share"):
        overbound_error_model(el, res, max_tail_share=0.9)
    with pytest.raises(ValueError, match="tail"):
        overbound_error_model(el, res, min_tail=10_000)


def test_confident_overbound_counts_independent_samples():
    # AR(1) errors of known lag-1 correlation 0.9 (per satellite, along the epochs): n residuals
    # are worth n (1 - 0.9) / (1 + 0.9) independent ones
    truth = ErrorModel(a_m=0.5, b_m=1.0)
    rng = np.random.default_rng(7)
    n_ep, rho = 3000, 0.9
    el = np.full((n_ep, 9), np.nan)
    el[:] = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(5.0)), 1.0, (1, 9))))
    w = rng.normal(size=(n_ep, 9))
    u = np.empty_like(w)
    u[0] = w[0]
    for t in range(1, n_ep):
        u[t] = rho * u[t - 1] + np.sqrt(1 - rho**2) * w[t]
    res = u * truth.sigma_m(el) + rng.normal(0.0, 300.0, (n_ep, 1))
    ob = overbound_error_model(el, res, truth, confidence=0.95)
    assert ob.lag1_correlation == pytest.approx(rho, abs=0.03)
    assert ob.independent_share == pytest.approx((1 - rho) / (1 + rho), rel=0.3)
    white = overbound_error_model(*_residuals(rng, n_ep, truth.sigma_m)[:2], truth,
                                  confidence=0.95)  # fmt: skip
    assert white.lag1_correlation < 0.05 and white.independent_share > 0.9
    # the deepest tail checked lies beyond the 10 residuals' share (a confidence bound) and far
    # deeper with independent samples than with correlated ones
    n_bin = white.bin_n.min()
    assert 2 * 10 / n_bin < white.tail_probability < 2 * 25 / n_bin
    assert ob.tail_probability > 5 * white.tail_probability
    # without confidence: the empirical two-sided share of before, no sample size
    legacy = overbound_error_model(el, res, truth)
    assert np.isnan(legacy.tail_probability) and legacy.independent_share == 1.0


def test_confident_overbound_bounds_a_one_sided_tail():
    # errors with a heavy right tail (a reflected path only ever adds length): the pooled
    # two-sided check averages it with the light left tail; the one-sided check does not
    base = ErrorModel(a_m=0.5, b_m=1.0)
    rng = np.random.default_rng(4)

    def draw(n_ep):
        el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(5.0)), 1.0, (n_ep, 9))))
        z = rng.normal(size=el.shape)
        z = np.where(rng.random(el.shape) < 0.02, np.abs(z) * 5.0, z)  # 2 %: 5x, positive
        clock = rng.normal(0.0, 300.0, (n_ep, 1))
        return el, z * base.sigma_m(el) + clock, clock

    el, res, _ = draw(3000)
    legacy = overbound_error_model(el, res, base)
    sided = overbound_error_model(el, res, base, confidence=0.95)
    assert sided.factor > legacy.factor
    el2, res2, clock2 = draw(6000)
    e2 = res2 - clock2 - np.mean(res2 - clock2, axis=1, keepdims=True)  # as clock-free as fitted
    z_side = e2 / sided.model.sigma_m(el2)
    # the heavy right tail of fresh errors stays within the Gaussian's one-sided tail at 2, 2.5
    # and 3 sigma (0.15, 0.28, 0.56 of it with seed 4; the two-sided check's bound: 0.19, 0.41,
    # 1.06, past the Gaussian at 3 sigma)
    for k in (2.0, 2.5, 3.0):
        assert np.mean(z_side > k) < norm.sf(k), k
    with pytest.raises(ValueError, match="confidence"):
        overbound_error_model(el, res, base, confidence=1.0)
