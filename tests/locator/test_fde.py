"""Passive and active integrity with fault detection and exclusion."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from locator.fde import FixFlag, LocatorConfig, locate
from locator.sathia import AntennaPath
from locator.selection import direction_at
from predisat.availability.interval import IntervalMode
from predisat.gnss.errormodel import ErrorModel, IntervalModel
from tests.locator._scene import random_sky, ranges, sky, straight_path

CFG = LocatorConfig(
    model=IntervalModel(ErrorModel(1.0, 1.0), k_sigma=2.0), budget=None, window_m=500.0
)


@pytest.fixture(scope="module")
def path() -> AntennaPath:
    return straight_path(45.0, 4000.0)


def _epoch(path, s_true, n, seed, bias=None):
    rng = np.random.default_rng(seed)
    x = path.ecef_at(s_true)
    az, el = random_sky(rng, n, 20.0)
    sat = sky(x, az, el)
    sig = CFG.model.error.sigma_m(el)
    rho = ranges(sat, x, sig, rng)
    if bias is not None:
        rho[bias[0]] += bias[1]
    return sat, rho, el


def test_clean_epoch_three_pairs_with_claim(path):
    s_true = 1800.0
    sat, rho, el = _epoch(path, s_true, 8, 1)
    fix = locate(path, sat, rho, el, prior_m=s_true + 120.0, config=CFG)
    assert fix.flags == FixFlag.NONE and fix.safety_claim
    assert fix.mode == IntervalMode.THREE_PAIRS and fix.pairs is not None
    assert fix.pairs.n_pairs == 3 and len(set(np.r_[fix.pairs.i, fix.pairs.j])) == 6
    assert fix.contains(s_true)
    assert fix.wls is not None and abs(fix.wls.chainage_m - fix.chainage_m) < 5.0


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_active_excludes_a_100_m_bias(path, seed):
    s_true = 2500.0
    sat, rho, el = _epoch(path, s_true, 8, seed, bias=(2, 100.0))
    fix = locate(
        path, sat, rho, el, prior_m=s_true - 80.0, config=CFG, sats=[f"G{k:02d}" for k in range(8)]
    )
    assert fix.excluded == (2,) and fix.excluded_sats == ("G02",)
    assert fix.flags & FixFlag.EXCLUDED and not fix.flags & FixFlag.FAULT_DETECTED
    assert not fix.used[2] and fix.used.sum() == 7
    assert fix.contains(s_true) and fix.safety_claim
    passive = locate(path, sat, rho, el, prior_m=s_true - 80.0, config=CFG, integrity="passive")
    assert passive.excluded == () and passive.flags & FixFlag.FAULT_DETECTED
    assert not passive.safety_claim


def test_few_satellites_no_claim_and_too_few(path):
    s_true = 1000.0
    sat, rho, el = _epoch(path, s_true, 3, 7)
    fix = locate(path, sat, rho, el, prior_m=s_true, config=CFG)
    assert fix.mode == IntervalMode.BEST_PAIR
    assert fix.flags & FixFlag.NO_SAFETY_CLAIM and not fix.safety_claim
    assert fix.contains(s_true) or fix.flags & FixFlag.BLUNT
    one = locate(path, sat[:1], rho[:1], el[:1], prior_m=s_true, config=CFG)
    assert one.flags & FixFlag.TOO_FEW and np.isnan(one.chainage_m)


def test_blunt_pairs_dropped_in_all_pairs_mode(path):
    s_true = 1500.0
    x = path.ecef_at(s_true)
    # satellites 0 and 1 nearly at the same along-track component: a blunt pair
    sat = sky(x, [45.0, 48.0, 225.0, 135.0], [40.0, 41.0, 35.0, 60.0])
    el = np.array([40.0, 41.0, 35.0, 60.0])
    rho = ranges(sat, x)
    active = locate(path, sat, rho, el, prior_m=s_true, config=CFG)
    assert active.mode == IntervalMode.ALL_PAIRS and active.flags & FixFlag.BLUNT
    assert active.pairs is not None
    used_pairs = set(zip(active.pairs.i.tolist(), active.pairs.j.tolist(), strict=True))
    assert (0, 1) not in used_pairs and len(used_pairs) == 5
    passive = locate(path, sat, rho, el, prior_m=s_true, config=CFG, integrity="passive")
    assert passive.pairs is not None and passive.pairs.n_pairs == 6
    assert passive.length_m > active.length_m  # the blunt pair only lengthens it
    assert active.contains(s_true) and passive.contains(s_true)


def test_passive_uses_all_pairs_and_is_wider(path):
    s_true = 3000.0
    sat, rho, el = _epoch(path, s_true, 7, 21)
    act = locate(path, sat, rho, el, prior_m=s_true, config=CFG)
    pas = locate(path, sat, rho, el, prior_m=s_true, config=CFG, integrity="passive")
    assert pas.pairs is not None and act.pairs is not None
    assert pas.pairs.n_pairs == 21 and act.pairs.n_pairs == 3
    assert pas.lo_m <= act.lo_m and pas.hi_m >= act.hi_m


def test_real_constellation_from_embedded_day(path):
    from predisat.availability.satellites import default_ephemeris, default_window

    eph = default_ephemeris()
    t = default_window(3600.0)[[5, 17]]
    pos, _, status = eph.evaluate(t, [s for s in eph.satellites if s[0] == "G"])
    s_true = 2000.0
    rng = np.random.default_rng(0)
    for k in range(len(t)):
        ok = status.valid[k]
        _, el = direction_at(path, s_true, pos[k, ok])
        up = el > 10.0
        sat = pos[k, ok][up]
        sig = CFG.model.error.sigma_m(el[up])
        rho = ranges(sat, path.ecef_at(s_true), sig, rng)
        fix = locate(path, sat, rho, el[up], prior_m=s_true + 200.0, config=CFG)
        assert len(sat) >= 6 and fix.mode == IntervalMode.THREE_PAIRS
        assert fix.contains(s_true) and fix.length_m < 150.0


def test_validation(path):
    sat, rho, el = _epoch(path, 100.0, 4, 0)
    with pytest.raises(ValueError, match="integrity"):
        locate(path, sat, rho, el, prior_m=100.0, integrity="none")
    with pytest.raises(ValueError, match="el_deg"):
        locate(path, sat, rho, el[:2], prior_m=100.0)
    with pytest.raises(ValueError, match="min_slope"):
        LocatorConfig(min_slope=3.0)


def test_an_integrity_budget_sets_k_by_the_independent_pairs_united(path):
    from scipy.stats import norm

    from predisat.gnss.integrity import IntegrityBudget

    risk = 1e-9
    # the widths of k alone: no map doubt (its bias bound adds to k sigma, not in ratio)
    cfg = LocatorConfig(model=CFG.model, window_m=500.0, budget=IntegrityBudget(risk),
                        map_doubt_lateral_m=0.0, map_doubt_vertical_m=0.0)  # fmt: skip
    bare = dataclasses.replace(CFG, map_doubt_lateral_m=0.0, map_doubt_vertical_m=0.0)

    def k_of(m: int) -> float:  # Q^-1((T / 2)^(1 / m)), independently of the module
        return float(norm.isf((risk / 2) ** (1 / m)))

    s_true = 2200.0
    for n, mode, m in ((8, IntervalMode.THREE_PAIRS, 3), (5, IntervalMode.ALL_PAIRS, 2),
                       (3, IntervalMode.BEST_PAIR, 1)):  # fmt: skip
        sat, rho, el = _epoch(path, s_true, n, 11 + n)
        fix = locate(path, sat, rho, el, prior_m=s_true, config=cfg)
        fixed = locate(path, sat, rho, el, prior_m=s_true, config=bare)  # k = 2
        assert fix.mode == mode and fix.pairs is not None
        assert fix.pairs.k_sigma == pytest.approx(k_of(m))
        # the same pairs, wider: the k = 2 interval lies inside
        assert fix.lo_m <= fixed.lo_m and fix.hi_m >= fixed.hi_m
        assert fixed.pairs is not None and fix.length_m > fixed.length_m
        # each pair interval widens by the ratio of the k (to the curvature of the track)
        ratio = (fix.pairs.hi_m - fix.pairs.lo_m) / (fixed.pairs.hi_m - fixed.pairs.lo_m)
        np.testing.assert_allclose(ratio, k_of(m) / 2.0, rtol=0.02)
    # three satellites nearly in one along-track direction: their pairs are blunt and dropped,
    # the pairs left all share satellite 3 (a star): one independent pair, the widest k
    x = path.ecef_at(s_true)
    az, el = np.array([45.0, 48.0, 51.0, 225.0]), np.array([40.0, 41.0, 40.5, 35.0])
    sat = sky(x, az, el)
    fix = locate(path, sat, ranges(sat, x), el, prior_m=s_true, config=cfg)
    assert fix.mode == IntervalMode.ALL_PAIRS and fix.flags & FixFlag.BLUNT
    assert fix.pairs is not None and set(fix.pairs.j.tolist()) == {3}
    assert fix.pairs.k_sigma == pytest.approx(k_of(1))
    # without a budget the model's k, whatever the pairs
    assert CFG.k_sigma_for(np.array([[0, 1], [2, 3], [4, 5]])) == 2.0
    assert cfg.k_sigma_for(np.array([[0, 1], [2, 3], [4, 5]])) == pytest.approx(k_of(3))
    assert "integrity risk 1e-09 per epoch" in cfg.width_text() and CFG.width_label() == "k = 2"


def test_the_map_doubt_widens_each_pair_by_its_bias_bound(path) -> None:
    """Every pair's band grows by the bound of ``map_doubt_bias_m`` (its interval holds the
    bare one); the width text names the doubt; a negative doubt is refused."""
    from locator.fde import map_doubt_bias_m

    s_true = 2200.0
    sat, rho, el = _epoch(path, s_true, 8, 19)
    bare_cfg = dataclasses.replace(CFG, map_doubt_lateral_m=0.0, map_doubt_vertical_m=0.0)
    doubt_cfg = dataclasses.replace(CFG, map_doubt_lateral_m=3.0, map_doubt_vertical_m=1.0)
    bare = locate(path, sat, rho, el, prior_m=s_true, config=bare_cfg)
    wide = locate(path, sat, rho, el, prior_m=s_true, config=doubt_cfg)
    assert bare.pairs is not None and wide.pairs is not None
    assert np.array_equal(bare.pairs.i, wide.pairs.i) and np.array_equal(bare.pairs.j, wide.pairs.j)
    assert np.all(wide.pairs.lo_m <= bare.pairs.lo_m) and np.all(wide.pairs.hi_m >= bare.pairs.hi_m)
    assert wide.lo_m <= bare.lo_m and wide.hi_m >= bare.hi_m and wide.length_m > bare.length_m
    bound = map_doubt_bias_m(path, bare.chainage_m, sat[bare.used], np.stack(
        [np.searchsorted(np.flatnonzero(bare.used), bare.pairs.i),
         np.searchsorted(np.flatnonzero(bare.used), bare.pairs.j)], -1), 3.0, 1.0)  # fmt: skip
    # each pair's half width grew by its bound over the slope (to the track's curvature)
    grow = 0.5 * ((wide.pairs.hi_m - wide.pairs.lo_m) - (bare.pairs.hi_m - bare.pairs.lo_m))
    np.testing.assert_allclose(grow, bound / np.abs(bare.pairs.slope), rtol=0.05, atol=0.05)
    assert "3 m beside and 1 m above or below" in doubt_cfg.width_text()
    assert "no map doubt" in bare_cfg.width_text()
    with pytest.raises(ValueError, match="map_doubt_lateral_m"):
        LocatorConfig(map_doubt_lateral_m=-1.0)


def test_the_map_doubt_bound_holds_over_a_curved_search_window() -> None:
    """A reviewer's case: a 300 m radius curve; the bound taken at the window's centre must
    cover the bias of an antenna beside the track (across it there) anywhere in a 1000 m
    window, where the heading turns by more than 90 deg."""
    from locator.fde import map_doubt_bias_m
    from predisat.geodesy import ecef_to_geodetic, enu_rotation
    from tests.locator._scene import arc_path, random_sky, sky

    path = arc_path(300.0, 300.0, lead_m=100.0)
    centre = 0.5 * path.length_m
    rng = np.random.default_rng(7)
    sat = sky(path.ecef_at(centre), *random_sky(rng, 10, 5.0))
    pairs = np.stack(np.triu_indices(10, 1), -1)
    bound = map_doubt_bias_m(path, centre, sat, pairs, 1.5, 1.0)
    for s in np.linspace(max(centre - 500.0, 0.0), min(centre + 500.0, path.length_m), 41):
        x = path.ecef_at(float(s))
        t = path.tangent_ecef_at(np.array([s]))[0]
        up = enu_rotation(*ecef_to_geodetic(x)[:2])[2]
        n = np.cross(up, t) / np.linalg.norm(np.cross(up, t))
        u = (sat - x) / np.linalg.norm(sat - x, axis=1)[:, None]
        du = u[pairs[:, 0]] - u[pairs[:, 1]]
        exact = 1.5 * np.abs(du @ n) + 1.0 * np.abs(du @ up)  # the worst corner of the box
        assert np.all(exact <= bound + 1e-3), s


def test_the_locator_and_the_availability_prediction_widen_a_pair_alike(path) -> None:
    """The locator's bound (ECEF, the ellipsoid normal at the path) and the availability
    prediction's (:class:`MapDoubt` on east-north-up unit vectors) are one number per pair,
    and the locator's default doubt is the prediction's."""
    from locator.fde import map_doubt_bias_m
    from predisat.availability.interval import MapDoubt
    from predisat.geodesy import ecef_to_geodetic, enu_rotation

    s = 1800.0
    sat, _, _ = _epoch(path, s, 8, 23)
    pairs = np.stack(np.triu_indices(len(sat), 1), -1)
    x = path.ecef_at(s)
    unit_enu = (enu_rotation(*ecef_to_geodetic(x)[:2]) @ (sat - x).T).T
    unit_enu /= np.linalg.norm(unit_enu, axis=1)[:, None]
    doubt = MapDoubt(2.5, 0.7)
    np.testing.assert_allclose(
        doubt.bias_m(unit_enu[pairs[:, 0]], unit_enu[pairs[:, 1]]),
        map_doubt_bias_m(path, s, sat, pairs, 2.5, 0.7), rtol=1e-6,
    )  # fmt: skip (the locator's normal from the ellipsoid's axes: 1e-8 rad from the geodetic)
    cfg = LocatorConfig()
    assert (cfg.map_doubt_lateral_m, cfg.map_doubt_vertical_m) == (
        MapDoubt().lateral_m, MapDoubt().vertical_m)  # fmt: skip
    assert cfg.map_doubt == MapDoubt()
