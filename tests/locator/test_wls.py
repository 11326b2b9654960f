"""1-D weighted least squares: exact on clean data, statistics on noisy data."""

from __future__ import annotations

import numpy as np
import pytest

from locator.intervals import along_track_g, plan_pairs, union_interval
from locator.sathia import solve_pairs
from locator.wls import solve_wls
from tests.locator._scene import CLOCK_M, arc_path, random_sky, ranges, sky, straight_path


def test_clean_data_exact_and_agrees_with_sathia():
    path = straight_path(120.0)
    rng = np.random.default_rng(2)
    s_true = 2222.2
    x = path.ecef_at(s_true)
    sat = sky(x, *random_sky(rng, 8))
    rho = ranges(sat, x)
    sig = np.full(8, 3.0)
    w = solve_wls(path, sat, rho, sig, prior_m=1900.0)
    assert w.converged and w.dof == 6
    assert w.chainage_m == pytest.approx(s_true, abs=1e-3)
    assert w.clock_m == pytest.approx(CLOCK_M, abs=1e-3)
    assert w.chi2 < 1e-6
    pr, mode = plan_pairs(along_track_g(path, s_true, sat), sig)
    u = union_interval(solve_pairs(path, sat, rho, sig, pr, prior_m=1900.0), mode)
    assert u.estimate_m == pytest.approx(w.chainage_m, abs=1e-3)


def test_curved_track_from_far_prior():
    path = arc_path(500.0, 90.0, heading_deg=200.0, lead_m=300.0)
    rng = np.random.default_rng(4)
    s_true = 600.0
    x = path.ecef_at(s_true)
    sat = sky(x, *random_sky(rng, 7))
    w = solve_wls(path, sat, ranges(sat, x), np.ones(7), prior_m=350.0)
    assert w.converged
    assert w.chainage_m == pytest.approx(s_true, abs=1e-3)


def test_noise_statistics_match_covariance():
    """Error spread ~ sigma_s, mean chi2 ~ dof, k=2 protection covers ~95 %."""
    path = straight_path(30.0)
    rng = np.random.default_rng(9)
    s_true = 1500.0
    x = path.ecef_at(s_true)
    sat = sky(x, *random_sky(rng, 9))
    sig = rng.uniform(1.0, 4.0, 9)
    errs, chi2, covered = [], [], 0
    n = 400
    for _ in range(n):
        w = solve_wls(path, sat, ranges(sat, x, sig, rng), sig, prior_m=s_true + 30.0)
        errs.append(w.chainage_m - s_true)
        chi2.append(w.chi2)
        covered += abs(w.chainage_m - s_true) <= w.protection_m(2.0)
    sd = w.sigma_chainage_m
    assert np.std(errs) == pytest.approx(sd, rel=0.12)
    assert abs(np.mean(errs)) < 4 * sd / np.sqrt(n)
    assert np.mean(chi2) == pytest.approx(7.0, rel=0.12)
    assert abs(covered / n - 0.9545) < 0.035


def test_normalised_residual_points_at_the_fault():
    path = straight_path(75.0)
    rng = np.random.default_rng(13)
    x = path.ecef_at(1000.0)
    sat = sky(x, *random_sky(rng, 8))
    rho = ranges(sat, x, 1.0, rng)
    rho[5] += 60.0
    w = solve_wls(path, sat, rho, np.ones(8), prior_m=1000.0)
    assert int(np.nanargmax(np.abs(w.normalised_residual))) == 5
    assert w.p_value() < 1e-6


def test_validation():
    path = straight_path()
    with pytest.raises(ValueError, match="at least 2"):
        solve_wls(path, np.zeros((1, 3)), np.ones(1), np.ones(1), prior_m=0.0)
    with pytest.raises(ValueError, match=r"shape|must be"):
        solve_wls(path, np.zeros((3, 3)), np.ones(2), np.ones(3), prior_m=0.0)
