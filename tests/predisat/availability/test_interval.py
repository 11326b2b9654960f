"""SATHIA interval: pair formula vs numeric hyperboloid intersection, pair selection vs search,
fast path vs the straightforward table implementation."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import brentq

from predisat.availability.interval import (
    IntervalMode,
    along_track_components,
    best_pair,
    interval_mode,
    pair_half_length_m,
    pair_pool,
    predicted_interval,
    three_independent_pairs,
)
from predisat.gnss.errormodel import ErrorModel, IntervalModel


def _hyperbolic_interval(sat_i, sat_j, p0, t, dk):
    """Chainages where |p - S_i| - |p - S_j| = K(0) -+ dk on the straight track p0 + s t."""

    def k_of(s):
        p = p0 + s * t
        return np.linalg.norm(p - sat_i) - np.linalg.norm(p - sat_j)

    k0 = k_of(0.0)
    ends = [brentq(lambda s, k=k0 + sgn * dk: k_of(s) - k, -5e4, 5e4, xtol=1e-9)
            for sgn in (-1, 1)]  # fmt: skip
    return abs(ends[1] - ends[0])


@pytest.mark.parametrize("seed", range(5))
def test_pair_length_matches_hyperboloid_intersection(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p0 = np.array([0.0, 0.0, 6.371e6])  # a point on a spherical Earth, local up = z
    t = np.array([np.cos(rng.uniform(0, 6.28)), np.sin(rng.uniform(0, 6.28)), 0.0])
    t /= np.linalg.norm(t)
    sats, units = [], []
    for _ in range(2):
        az, el = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(15, 85))
        u = np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
        sats.append(p0 + 2.2e7 * u)
        units.append(u)
    sigma_i, sigma_j = 3.0, 5.0
    model = IntervalModel(k_sigma=2.0)
    dk = model.k_sigma * np.hypot(sigma_i, sigma_j)
    g = along_track_components(np.array(units), t)
    half = pair_half_length_m(g[0], g[1], sigma_i, sigma_j, model.k_sigma)
    numeric = _hyperbolic_interval(sats[0], sats[1], p0, t, dk)
    # the linearisation is exact to second order: intervals of tens of metres at 22 000 km
    assert abs(2 * half - numeric) < 1e-3 * numeric + 1e-3


def _best_three_pairs(g, s, k):
    best = np.inf
    idx = range(len(g))

    def perfect(rest):
        if not rest:
            yield []
            return
        for x in range(1, len(rest)):
            for m in perfect(rest[1:x] + rest[x + 1 :]):
                yield [(rest[0], rest[x]), *m]

    for six in itertools.combinations(idx, 6):
        for m in perfect(list(six)):
            best = min(best, max(k * np.hypot(s[a], s[b]) / abs(g[a] - g[b]) for a, b in m))
    return 2 * best


def _random_sky(rng, n):
    az = rng.uniform(0, 360, n)
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(5)), 1, n)))
    return np.cos(np.radians(el)) * np.cos(np.radians(az)), el


def test_three_pairs_exact_with_equal_sigmas() -> None:
    rng = np.random.default_rng(7)
    for _ in range(40):
        n = int(rng.integers(6, 11))
        g, _ = _random_sky(rng, n)
        s = np.full(n, 4.0)
        length, mode = predicted_interval(g[None], s[None], np.ones((1, n), bool), 2.0)
        assert mode[0] == IntervalMode.THREE_PAIRS
        assert length[0] == pytest.approx(_best_three_pairs(g, s, 2.0), rel=1e-5)


def test_three_pairs_close_to_search_with_elevation_sigmas() -> None:
    rng = np.random.default_rng(11)
    em = ErrorModel()
    ratios = []
    for _ in range(120):
        n = int(rng.integers(6, 11))
        g, el = _random_sky(rng, n)
        s = em.sigma_m(el)
        # embed among untrusted padding to exercise the masking
        m = 14
        slots = rng.permutation(m)[:n]
        gg, ss, ok = np.zeros(m), np.ones(m), np.zeros(m, bool)
        gg[slots], ss[slots], ok[slots] = g, s, True
        length, _ = predicted_interval(gg[None], ss[None], ok[None], 2.0)
        ratios.append(length[0] / _best_three_pairs(g, s, 2.0))
    r = np.array(ratios)
    assert r.min() > 1 - 1e-5  # never shorter than the optimum: the sets are real
    assert np.mean(r < 1 + 1e-5) > 0.85 and np.quantile(r, 0.95) < 1.2 and r.max() < 2.0


def test_modes_by_count() -> None:
    g = np.array([[-0.9, 0.8, 0.1, 0.3, -0.2]])
    s = np.full((1, 5), 2.0)
    k = 2.0
    h = lambda a, b: k * np.hypot(2.0, 2.0) / abs(g[0, a] - g[0, b])  # noqa: E731
    cases = {
        1: (np.nan, IntervalMode.NONE),
        2: (2 * h(0, 1), IntervalMode.BEST_PAIR),
        3: (2 * min(h(0, 1), h(0, 2), h(1, 2)), IntervalMode.BEST_PAIR),
        4: (
            2 * max(h(a, b) for a, b in itertools.combinations(range(4), 2)),
            IntervalMode.ALL_PAIRS,
        ),
    }
    for n, (want, want_mode) in cases.items():
        ok = np.arange(5)[None] < n
        length, mode = predicted_interval(g, s, ok, k)
        assert mode[0] == want_mode
        np.testing.assert_allclose(length[0], want, rtol=1e-6)


def test_error_model_and_risk() -> None:
    em = ErrorModel(a_m=1.0, b_m=3.0)
    np.testing.assert_allclose(em.sigma_m([90.0, 30.0]), [np.hypot(1, 3), np.hypot(1, 6)])
    assert em.sigma_m(-5.0) == em.sigma_m(em.min_el_deg)
    assert IntervalModel.for_risk(1e-4).k_sigma == pytest.approx(3.8906, abs=1e-3)
    for k in (0.0, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="k_sigma"):
            IntervalModel(k_sigma=k)
    for a, b in ((float("nan"), 1.0), (1.0, float("inf")), (-1.0, 1.0)):
        with pytest.raises(ValueError, match="a_m, b_m"):
            ErrorModel(a_m=a, b_m=b)


# --------------------------------------------------------------------------- pair choice
def _table_reference(g, s, ok, k):
    """The pre-0.2 implementation, kept as a reference: argpartition pool + 420-set table.

    Straightforward and independent of the fast path (subset recursion, repeated argmin).
    """
    n, m = g.shape
    length = np.full(n, np.nan, g.dtype)
    count = ok.sum(-1)
    for r in range(n):
        gr, sr, okr = g[r], s[r], ok[r]
        if count[r] >= 6:
            p = min(8, m)
            s0 = sr[okr].min()
            spread = np.sqrt(sr * sr + s0 * s0)
            with np.errstate(divide="ignore"):
                rank_lo = np.where(okr, spread / (1.0 - gr), 1e30)
                rank_hi = np.where(okr, spread / (1.0 + gr), 1e30)
            lo = np.argpartition(rank_lo, p // 2 - 1)[: p // 2]
            rank_hi[lo] = np.inf
            hi = np.argpartition(rank_hi, p - p // 2 - 1)[: p - p // 2]
            pool = np.concatenate([lo, hi])
            best = np.inf
            for six in itertools.combinations(pool, 6):
                for a, b, c in _perfect(list(six)):
                    hs = [
                        pair_half_length_m(gr[x], gr[y], sr[x], sr[y], k)
                        if okr[x] and okr[y]
                        else np.inf
                        for x, y in (a, b, c)
                    ]
                    best = min(best, max(hs))
            length[r] = 2.0 * best
        elif count[r] >= 2:
            t = np.nonzero(okr)[0]
            hs = [pair_half_length_m(gr[x], gr[y], sr[x], sr[y], k)
                  for x, y in itertools.combinations(t, 2)]  # fmt: skip
            length[r] = 2.0 * (max(hs) if count[r] >= 4 else min(hs))
    return length.astype(np.float32)


def _perfect(rest):
    if not rest:
        yield []
        return
    for x in range(1, len(rest)):
        for m in _perfect(rest[1:x] + rest[x + 1 :]):
            yield [(rest[0], rest[x]), *m]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("m", [6, 7, 9, 20])
def test_fast_path_identical_to_table_reference(dtype, m) -> None:
    rng = np.random.default_rng(m)
    n = 60
    g = rng.uniform(-1, 1, (n, m)).astype(dtype)
    s = rng.uniform(2.0, 12.0, (n, m)).astype(dtype)
    ok = rng.random((n, m)) < rng.uniform(0.2, 1.0, (n, 1))
    length, mode = predicted_interval(g, s, ok, 2.0)
    want = _table_reference(g, s, ok, 2.0)
    np.testing.assert_array_equal(length, want)  # bit for bit, NaN where < 2
    np.testing.assert_array_equal(mode, interval_mode(ok.sum(-1)))
    # NaN/inf in untrusted entries change nothing
    g_bad = np.where(ok, g, np.nan).astype(dtype)
    s_bad = np.where(ok, s, np.inf).astype(dtype)
    np.testing.assert_array_equal(predicted_interval(g_bad, s_bad, ok, 2.0)[0], want)


def test_three_independent_pairs_vectorised() -> None:
    rng = np.random.default_rng(4)
    em = ErrorModel()
    n, m = 40, 12
    g, el = _random_sky(rng, n * m)
    g, s = g.reshape(n, m), em.sigma_m(el).reshape(n, m)
    ok = rng.random((n, m)) < 0.75
    ok[0] = [True] * 5 + [False] * 7  # too few
    ok[1] = [True] * 7 + [False] * 5  # the pool holds every trusted satellite: exact
    pairs, half = three_independent_pairs(g, s, ok, 2.0)
    assert pairs.shape == (n, 3, 2) and half.shape == (n,)
    length, _ = predicted_interval(g, s, ok, 2.0)
    for r in range(n):
        if ok[r].sum() < 6:
            assert np.all(pairs[r] == -1) and np.isnan(half[r])
            continue
        pr = pairs[r]
        assert len(set(pr.ravel().tolist())) == 6 and np.all(ok[r][pr])
        assert np.all(pr[:, 0] < pr[:, 1])
        hs = [2.0 * np.hypot(s[r, a], s[r, b]) / abs(g[r, a] - g[r, b]) for a, b in pr]
        assert half[r] == pytest.approx(max(hs), rel=1e-12)
        assert 2 * half[r] == pytest.approx(length[r], rel=1e-6)
        if ok[r].sum() <= 8:
            t = np.nonzero(ok[r])[0]
            assert 2 * half[r] == pytest.approx(_best_three_pairs(g[r, t], s[r, t], 2.0), rel=1e-12)
    assert np.all(pairs[0] == -1) and np.isnan(half[0])


def test_three_pairs_tie_break_prefers_tight_pairs() -> None:
    """The longest pair decides the union, so equal unions are common: the tighter sum wins."""
    rng = np.random.default_rng(8)
    differs = 0
    for _ in range(30):
        n = int(rng.integers(6, 9))
        g = rng.uniform(-0.9, 0.9, n)
        s = np.full(n, 3.0)
        pairs, half = three_independent_pairs(g, s)

        def h(a, b, g=g, s=s):
            return 2.0 * np.hypot(s[a], s[b]) / abs(g[a] - g[b])

        sets = [m for six in itertools.combinations(range(n), 6) for m in _perfect(list(six))]
        key = [(max(h(*p) for p in m), sum(h(*p) for p in m)) for m in sets]
        want = sets[min(range(len(sets)), key=key.__getitem__)]
        first = sets[min(range(len(sets)), key=lambda q: key[q][0])]
        assert {tuple(p) for p in pairs.tolist()} == set(want)
        assert half == pytest.approx(key[sets.index(want)][0], rel=1e-12)
        differs += set(first) != set(want)
    assert differs > 0  # the tie-break did matter in some skies


def test_best_pair_vectorised() -> None:
    rng = np.random.default_rng(9)
    n, m = 50, 7
    g = rng.uniform(-1, 1, (n, m))
    s = rng.uniform(2, 9, (n, m))
    ok = rng.random((n, m)) < 0.5
    pair, half = best_pair(g, s, ok, 2.0)
    for r in range(n):
        t = np.nonzero(ok[r])[0]
        if len(t) < 2:
            assert np.all(pair[r] == -1) and np.isnan(half[r])
            continue
        want = min(
            (2.0 * np.hypot(s[r, a], s[r, b]) / abs(g[r, a] - g[r, b]), a, b)
            for a, b in itertools.combinations(t, 2)
        )
        assert half[r] == pytest.approx(want[0], rel=1e-12)
        assert tuple(pair[r]) == (want[1], want[2])


def test_pair_pool_ranks() -> None:
    rng = np.random.default_rng(2)
    g = rng.uniform(-1, 1, (30, 15))
    s = rng.uniform(2, 9, (30, 15))
    ok = rng.random((30, 15)) < 0.8
    pool = pair_pool(g, s, ok)
    assert pool.shape == (30, 8) and np.all(np.diff(pool, axis=-1) > 0)
    for r in range(30):
        t = np.nonzero(ok[r])[0]
        s0 = s[r, t].min()
        spread = {i: np.hypot(s[r, i], s0) for i in t}
        lo = sorted(t, key=lambda i: spread[i] / (1 - g[r, i]))[:4]
        rest = [i for i in t if i not in lo]
        hi = sorted(rest, key=lambda i: spread[i] / (1 + g[r, i]))[:4]
        if len(t) >= 8:
            assert set(pool[r].tolist()) == set(lo) | set(hi)
        else:
            assert set(t.tolist()) <= set(pool[r].tolist())
    np.testing.assert_array_equal(pair_pool(g[:, :6], s[:, :6]), np.tile(np.arange(6), (30, 1)))


def test_an_integrity_budget_gives_each_mode_its_k() -> None:
    from scipy.stats import norm

    from predisat.availability.interval import INDEPENDENT_PAIRS, mode_k_sigma, width_text
    from predisat.gnss.integrity import IntegrityBudget

    risk = 1e-9
    budget = IntegrityBudget(risk)
    ks = mode_k_sigma(budget)
    assert np.isnan(ks[IntervalMode.NONE])
    for mode, m in ((IntervalMode.BEST_PAIR, 1), (IntervalMode.ALL_PAIRS, 2),
                    (IntervalMode.THREE_PAIRS, 3)):  # fmt: skip
        assert INDEPENDENT_PAIRS[mode] == m
        assert ks[mode] == pytest.approx(norm.isf((risk / 2) ** (1 / m)))
    np.testing.assert_array_equal(mode_k_sigma(2.5)[1:], [2.5, 2.5, 2.5])
    rng = np.random.default_rng(7)
    for n, m in ((2, 1), (3, 1), (4, 2), (5, 2)):
        g = rng.uniform(-0.9, 0.9, (50, n))
        s = rng.uniform(1.0, 4.0, (50, n))
        i, j = np.triu_indices(n, 1)
        unit = np.abs(np.sqrt(s[:, i] ** 2 + s[:, j] ** 2) / (g[:, i] - g[:, j]))
        # by hand: the best pair's (2-3) or the widest pair's (4-5) full length
        want = 2 * norm.isf((risk / 2) ** (1 / m)) * (unit.min(-1) if n < 4 else unit.max(-1))
        length, mode = predicted_interval(g, s, np.ones_like(g, bool), budget)
        assert (mode == (1 if n < 4 else 2)).all()
        np.testing.assert_allclose(length, want, rtol=1e-6)
    # six or more: the three-pair length at the budget's k equals that at a constant k of it
    g = rng.uniform(-0.9, 0.9, (50, 8))
    s = rng.uniform(1.0, 4.0, (50, 8))
    ok = np.ones_like(g, bool)
    got, mode = predicted_interval(g, s, ok, budget)
    assert (mode == 3).all()
    np.testing.assert_array_equal(got, predicted_interval(g, s, ok, float(ks[3]))[0])
    assert "integrity risk 1e-09 per epoch" in width_text(budget)
    assert "k = 2 in every mode" in width_text(2.0)


@pytest.mark.parametrize("seed", range(5))
def test_a_widened_pair_holds_an_antenna_anywhere_in_the_doubt_box(seed: int) -> None:
    """The antenna up to ``lateral_m`` beside (any level direction) and ``vertical_m`` above or
    below the map's point, the pair's difference off by up to ``k sigma_K``: where the
    hyperboloid of what it measures meets the track (solved numerically) stays inside the
    widened pair interval, and the worst corner reaches its end (the bound is tight)."""
    from predisat.availability.interval import MapDoubt

    rng = np.random.default_rng(100 + seed)
    p0 = np.array([0.0, 0.0, 6.371e6])  # local up = z
    heading = rng.uniform(0, 2 * np.pi)
    t = np.array([np.sin(heading), np.cos(heading), 0.0])
    units = []
    for _ in range(2):
        az, el = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(15, 85))
        units.append(np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)]))
    sats = [p0 + 2.2e7 * u for u in units]
    doubt, sigma, k = MapDoubt(3.0, 1.0), (3.0, 5.0), 2.0
    unit = np.array(units)
    g = along_track_components(unit, t)
    length, _ = predicted_interval(
        np.tile(np.r_[g, 0.0], (1, 1)), np.array([[*sigma, 1.0]]), np.array([[True, True, False]]),
        k, unit_enu=np.array([[*unit, [0.0, 0.0, 1.0]]]), map_doubt=doubt,
    )  # fmt: skip (a third, untrusted satellite: two trusted is the best-pair mode)

    def k_of(p):
        return np.linalg.norm(p - sats[0]) - np.linalg.norm(p - sats[1])

    reach = []
    for angle in np.linspace(0.0, 2 * np.pi, 721):
        for up in (-1.0, 1.0):
            for e in (-1.0, 1.0):
                delta = np.array([3.0 * np.cos(angle), 3.0 * np.sin(angle), up * 1.0])
                measured = k_of(p0 + delta) + e * k * np.hypot(*sigma)
                s = brentq(lambda s_, m=measured: k_of(p0 + s_ * t) - m, -5e4, 5e4, xtol=1e-9)
                reach.append(abs(s))
    half = float(length[0]) / 2.0
    assert max(reach) <= half * (1 + 1e-3) + 1e-3
    assert max(reach) >= 0.995 * half  # the worst corner reaches the end
    bare, _ = predicted_interval(np.r_[g, 0.0][None], np.array([[*sigma, 1.0]]),
                                 np.array([[True, True, False]]), k)  # fmt: skip
    assert float(bare[0]) < float(length[0])  # the bare pair would not hold it


def test_the_map_doubt_is_checked_and_zero_changes_nothing() -> None:
    from predisat.availability.interval import MapDoubt

    rng = np.random.default_rng(3)
    g = rng.uniform(-1, 1, (40, 9))
    s = rng.uniform(2.0, 9.0, (40, 9))
    ok = rng.random((40, 9)) < 0.7
    unit = rng.normal(size=(40, 9, 3))
    unit /= np.linalg.norm(unit, axis=-1, keepdims=True)
    plain = predicted_interval(g, s, ok, 2.0)
    for zero in (None, MapDoubt(0.0, 0.0)):
        for a, b in zip(predicted_interval(g, s, ok, 2.0, unit_enu=unit, map_doubt=zero), plain,
                        strict=True):  # fmt: skip
            np.testing.assert_array_equal(a, b)
    wide, mode = predicted_interval(g, s, ok, 2.0, unit_enu=unit, map_doubt=MapDoubt())
    np.testing.assert_array_equal(mode, plain[1])
    fin = np.isfinite(plain[0])
    assert np.array_equal(np.isfinite(wide), fin) and np.all(wide[fin] > plain[0][fin])
    with pytest.raises(ValueError, match="needs unit_enu"):
        predicted_interval(g, s, ok, 2.0, map_doubt=MapDoubt())
    with pytest.raises(ValueError, match="unit_enu must have shape"):
        predicted_interval(g, s, ok, 2.0, unit_enu=unit[..., :2], map_doubt=MapDoubt())
    with pytest.raises(ValueError, match="lateral_m must be finite and >= 0"):
        MapDoubt(-1.0, 1.0)
    assert repr(MapDoubt(1.5, 1)) == repr(MapDoubt(1.5, 1.0))  # one resume key
    assert MapDoubt(2.0, 0.5).describe() == (
        "widened for an antenna up to 2 m beside and 0.5 m above or below the map")


def test_a_widened_row_of_few_trusted_among_many_candidates_stays_small() -> None:
    """Rows of 2-5 trusted among every constellation's candidates (m ~ 110): the widened
    lengths are the pairs of the trusted alone, as the plain rows' (``_few``), not every pair of
    the m candidates ((rows, m(m-1)/2, 3) gathers: hundreds of megabytes, 40-70 times slower)."""
    import tracemalloc

    from predisat.availability.interval import MapDoubt

    rng = np.random.default_rng(11)
    n, m = 1000, 110
    g = rng.uniform(-1, 1, (n, m)).astype(np.float32)
    s = rng.uniform(2.0, 9.0, (n, m)).astype(np.float32)
    ok = np.zeros((n, m), bool)
    for r, c in enumerate(rng.integers(2, 6, n)):
        ok[r, rng.choice(m, c, replace=False)] = True
    unit = rng.normal(size=(n, m, 3)).astype(np.float32)
    unit /= np.linalg.norm(unit, axis=-1, keepdims=True)
    doubt = MapDoubt(1.5, 1.0)
    tracemalloc.start()
    try:
        wide, mode = predicted_interval(g, s, ok, 2.0, unit_enu=unit, map_doubt=doubt)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 20e6, f"{peak / 1e6:.0f} MB"
    # the same lengths as the trusted columns alone
    for r in range(0, n, 97):
        k = np.flatnonzero(ok[r])
        want, want_mode = predicted_interval(
            g[r, k][None], s[r, k][None], ok[r, k][None], 2.0, unit_enu=unit[r, k][None],
            map_doubt=doubt,
        )
        assert mode[r] == want_mode[0]
        np.testing.assert_allclose(wide[r], want[0], rtol=1e-6)
