"""SATHIA pair intersections: roots, intervals, ambiguous and empty cases."""

from __future__ import annotations

import numpy as np
import pytest

from locator.sathia import AntennaPath, PairStatus, all_pairs, range_difference_m, solve_pairs
from tests.locator._scene import arc_path, random_sky, ranges, sky, straight_path


@pytest.fixture(scope="module")
def straight() -> AntennaPath:
    return straight_path(60.0, 4000.0)


def _scene(path, s_true, seed=0, n=8):
    rng = np.random.default_rng(seed)
    x = path.ecef_at(s_true)
    sat = sky(x, *random_sky(rng, n))
    return x, sat


def test_clean_roots_hit_truth(straight):
    s_true = 1733.3
    x, sat = _scene(straight, s_true)
    sol = solve_pairs(straight, sat, ranges(sat, x), np.full(8, 3.0), prior_m=1500.0)
    assert sol.n_pairs == 28
    np.testing.assert_allclose(sol.root_m, s_true, atol=1e-3)
    assert np.all(sol.status == PairStatus.OK)
    assert np.all(sol.n_roots == 1)
    # slope against a central finite difference of the exact range difference
    h = 0.5
    d_plus = range_difference_m(straight.ecef_at(s_true + h), sat[sol.i], sat[sol.j])
    d_minus = range_difference_m(straight.ecef_at(s_true - h), sat[sol.i], sat[sol.j])
    np.testing.assert_allclose(sol.slope, (d_plus - d_minus) / (2 * h), atol=1e-6)


def test_interval_half_length_is_linearised_bound(straight):
    s_true = 900.0
    x, sat = _scene(straight, s_true, seed=3)
    sig = np.linspace(2.0, 6.0, 8)
    sol = solve_pairs(straight, sat, ranges(sat, x), sig, prior_m=800.0, k_sigma=2.5)
    ok = np.abs(sol.slope) > 0.1
    expected = 2.5 * np.hypot(sig[sol.i], sig[sol.j]) / np.abs(sol.slope)
    np.testing.assert_allclose((sol.hi_m - s_true)[ok], expected[ok], rtol=1e-3)
    np.testing.assert_allclose((s_true - sol.lo_m)[ok], expected[ok], rtol=1e-3)


def test_pair_coverage_matches_k_sigma(straight):
    """k = 2: a pair interval holds the truth 95.45 % of the time (Gaussian errors)."""
    rng = np.random.default_rng(42)
    s_true = 2000.0
    x = straight.ecef_at(s_true)
    hits, total = 0, 0
    for _ in range(150):
        sat = sky(x, *random_sky(rng, 7))
        sig = rng.uniform(1.0, 5.0, 7)
        rho = ranges(sat, x, sig, rng)
        sol = solve_pairs(
            straight,
            sat,
            rho,
            sig,
            prior_m=s_true + rng.normal(0, 50),
            window_m=1500.0,
            k_sigma=2.0,
        )
        ok = sol.valid
        hits += int(sol.contains(s_true)[ok].sum())
        total += int(ok.sum())
    rate = hits / total
    assert total > 2500
    assert abs(rate - 0.9545) < 0.02, rate


def test_curved_track_recovers_truth():
    path = arc_path(400.0, 120.0, heading_deg=30.0, lead_m=200.0)
    rng = np.random.default_rng(7)
    for s_true in (150.0, 420.0, 700.0):
        x = path.ecef_at(s_true)
        sat = sky(x, *random_sky(rng, 6))
        sol = solve_pairs(
            path, sat, ranges(sat, x, 1.0, rng), np.ones(6), prior_m=s_true + 60.0, window_m=300.0
        )
        good = sol.valid & (np.abs(sol.slope) > 0.3)
        assert good.sum() >= 5
        err = np.abs(sol.root_m[good] - s_true)
        bound = 4.0 * np.sqrt(2.0) / np.abs(sol.slope[good])  # 4 sigma of K along the track
        assert np.all(err < bound)


@pytest.fixture(scope="module")
def u_turn() -> AntennaPath:
    # semicircle, radius 300 m, starting east-bound and turning left through north
    return arc_path(300.0, 180.0, heading_deg=90.0, height_m=0.0)


def test_two_roots_on_a_u_turn(u_turn):
    quarter = np.pi * 300.0 / 2.0  # easternmost point
    s_true = quarter - 100.0
    x = u_turn.ecef_at(s_true)
    # pair 0-1: east-west, its range difference peaks at the easternmost point -> two roots;
    # satellites 2, 3: north/south-ish, monotonic along the semicircle
    sat = sky(x, [270.0, 90.0, 0.0, 180.0], [30.0, 30.0, 20.0, 60.0])
    rho = ranges(sat, x)
    sol = solve_pairs(u_turn, sat, rho, np.ones(4), prior_m=quarter + 60.0, window_m=470.0)
    ew = int(np.flatnonzero((sol.i == 0) & (sol.j == 1))[0])
    assert sol.n_roots[ew] == 2
    assert sol.status[ew] & PairStatus.MULTIPLE_ROOTS
    # the prior is nearer the wrong root (quarter + 100), the unambiguous pairs decide
    assert abs(sol.root_m[ew] - s_true) < 1e-3
    # the interval is the component around the chosen root: it stops short of the peak
    assert sol.lo_m[ew] < s_true < sol.hi_m[ew] < quarter


def test_ambiguous_pair_alone_takes_root_nearest_prior(u_turn):
    quarter = np.pi * 300.0 / 2.0
    x = u_turn.ecef_at(quarter - 100.0)
    sat = sky(x, [270.0, 90.0], [30.0, 30.0])
    rho = ranges(sat, x)
    sol = solve_pairs(u_turn, sat, rho, np.ones(2), prior_m=quarter + 80.0, window_m=470.0)
    assert sol.n_roots[0] == 2
    assert abs(sol.root_m[0] - (quarter + 100.0)) < 0.5  # the mirror root (symmetry)


def test_no_root_when_range_is_faulty(straight):
    s_true = 1000.0
    x, sat = _scene(straight, s_true, seed=5, n=5)
    rho = ranges(sat, x)
    rho[2] += 5000.0  # no point of a 2 x 300 m window explains this difference
    sol = solve_pairs(straight, sat, rho, np.full(5, 3.0), prior_m=s_true, window_m=300.0)
    bad = (sol.i == 2) | (sol.j == 2)
    assert np.all(sol.status[bad] & PairStatus.NO_ROOT)
    assert np.all(sol.status[bad] & PairStatus.EMPTY)
    assert np.all(np.isnan(sol.root_m[bad])) and np.all(np.isnan(sol.lo_m[bad]))
    assert np.all(sol.misfit_m[bad] > 3000.0)
    np.testing.assert_allclose(sol.root_m[~bad], s_true, atol=1e-3)


def test_unbounded_inside_track_and_bounded_at_track_end(straight):
    x, sat = _scene(straight, 20.0, seed=1, n=4)
    sig = np.full(4, 50.0)  # wide intervals
    sol = solve_pairs(straight, sat, ranges(sat, x), sig, prior_m=40.0, window_m=60.0)
    # lower side: the window reaches chainage 0, the track end bounds the interval
    assert np.all(sol.lo_m >= 0.0)
    assert np.all(sol.status & PairStatus.UNBOUNDED_HIGH)
    assert np.all(np.isposinf(sol.hi_m))


def test_pairs_argument_and_validation(straight):
    x, sat = _scene(straight, 500.0, n=4)
    rho = ranges(sat, x)
    sol = solve_pairs(straight, sat, rho, np.ones(4), [[0, 3], [1, 2]], prior_m=500.0)
    assert sol.i.tolist() == [0, 1] and sol.j.tolist() == [3, 2]
    assert all_pairs(4).shape == (6, 2)
    with pytest.raises(ValueError, match="distinct"):
        solve_pairs(straight, sat, rho, np.ones(4), [[1, 1]], prior_m=500.0)
    with pytest.raises(ValueError, match="satellite 2"):
        solve_pairs(
            straight, sat, np.where(np.arange(4) == 2, np.nan, rho), np.ones(4), prior_m=500.0
        )
    with pytest.raises(ValueError, match="shape"):
        solve_pairs(straight, sat[:, :2], rho, np.ones(4), prior_m=500.0)


def test_no_root_but_band_meets_window(straight):
    """A root beyond the window: the pair still bounds the train by its k-sigma band."""
    s_true = 1000.0
    x, sat = _scene(straight, s_true, seed=8, n=6)
    rho = ranges(sat, x)
    sig = np.full(6, 50.0)
    ref = solve_pairs(straight, sat, rho, sig, prior_m=s_true, window_m=2000.0)
    sol = solve_pairs(straight, sat, rho, sig, prior_m=1200.0, window_m=100.0)
    reach = s_true + 2.0 * ref.sigma_k_m / np.abs(ref.slope)  # upper band edge, linearised
    pick = (reach > 1110.0) & (reach < 1290.0)
    assert pick.sum() >= 2
    assert np.all(sol.status[pick] & PairStatus.NO_ROOT)
    assert not np.any(sol.status[pick] & PairStatus.EMPTY)
    assert np.all(np.isneginf(sol.lo_m[pick]))
    np.testing.assert_allclose(sol.hi_m[pick], reach[pick], atol=0.05)
    assert not np.any(sol.valid[pick])


@pytest.mark.parametrize("radius_m", [150.0, 1000.0])
def test_path_table_matches_the_track_spline(radius_m):
    """The interpolated antenna path agrees with the spline itself (tight curves included)."""
    path = arc_path(radius_m, 120.0, lead_m=200.0)
    s = np.random.default_rng(1).uniform(-10.0, path.length_m + 10.0, 5000)
    assert np.abs(path.ecef_at(s) - path.exact_ecef_at(s)).max() < 1e-5
    t_ref = path.track.tangent_at(s) @ path.track.frame.rotation
    assert np.abs(path.tangent_ecef_at(s) - t_ref).max() < 1e-5  # 3e-6 at R = 150 m
    # scalar fast path, 0-d and (n, m) shapes agree; beyond the ends the end point is returned
    for c in (0.0, 17.3, path.length_m, path.length_m + 50.0, -5.0):
        assert np.allclose(path.ecef_at(c), path.ecef_at(np.array(c)), rtol=0, atol=1e-9)
    assert np.allclose(path.ecef_at(-5.0), path.exact_ecef_at(0.0), rtol=0, atol=1e-6)
    assert path.ecef_at(np.zeros((2, 4))).shape == (2, 4, 3)
    with pytest.raises(ValueError, match="NaN"):
        path.ecef_at(np.nan)


def test_a_map_doubt_keeps_a_pair_around_an_antenna_beside_the_path() -> None:
    """The antenna 4.5 m left of the path (a passing loop; a map metres off): ranges from
    there, no noise. With a 0.3 m sigma and k = 3 every pair's interval misses the foot
    point's chainage; with the map doubt's bias bound (locator.fde.map_doubt_bias_m) each
    holds it. Without any doubt the pairs are those of the source, bit for bit."""
    from locator.fde import map_doubt_bias_m
    from tests.locator._scene import ranges, sky, straight_path

    path = straight_path(heading_deg=60.0, length_m=4000.0)
    s_true = 2000.0
    x = path.ecef_at(s_true)
    t = path.tangent_ecef_at(np.array([s_true]))[0]
    from predisat.geodesy import ecef_to_geodetic, enu_rotation

    up = enu_rotation(*ecef_to_geodetic(x)[:2])[2]  # the ellipsoid normal: across is level
    left = np.cross(up, t) / np.linalg.norm(np.cross(up, t))
    # low satellites ahead-left and behind-right: their difference vector crosses the track
    sat = sky(x, np.array([120.0, -60.0, 210.0, 30.0]), np.array([15.0, 15.0, 40.0, 60.0]))
    rho = ranges(sat, x + 4.5 * left)
    sig = np.full(4, 0.3)
    pairs = np.array([[0, 1], [2, 3], [0, 3]])
    bare = solve_pairs(path, sat, rho, sig, pairs, prior_m=s_true, k_sigma=3.0)
    assert not ((bare.lo_m <= s_true) & (s_true <= bare.hi_m)).any()
    bias = map_doubt_bias_m(path, s_true, sat, pairs, 4.5, 0.0)
    # the bound is the worst over the box: a pair's true bias from this displacement is below
    du = (sat[pairs[:, 0]] - x) / np.linalg.norm(sat[pairs[:, 0]] - x, axis=1)[:, None] - (
        sat[pairs[:, 1]] - x) / np.linalg.norm(sat[pairs[:, 1]] - x, axis=1)[:, None]
    assert np.all(np.abs(du @ (4.5 * left)) <= bias + 1e-6)  # to a micrometre
    wide = solve_pairs(path, sat, rho, sig, pairs, prior_m=s_true, k_sigma=3.0,
                       bias_bound_m=bias)  # fmt: skip
    assert ((wide.lo_m <= s_true) & (s_true <= wide.hi_m)).all()
    zero = solve_pairs(path, sat, rho, sig, pairs, prior_m=s_true, k_sigma=3.0,
                       bias_bound_m=np.zeros(3))  # fmt: skip
    for f in ("lo_m", "hi_m", "root_m", "status"):
        np.testing.assert_array_equal(getattr(zero, f), getattr(bare, f))
    with pytest.raises(ValueError, match="bias_bound_m"):
        solve_pairs(path, sat, rho, sig, pairs, prior_m=s_true, bias_bound_m=[1.0, -1.0, 0.0])
