"""Tests of error-model learning (locator.errorfit) on real and synthetic residuals."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from locator.corrections import RangeModel
from locator.errorfit import (
    Residuals,
    binned_sigma,
    calibration_figure,
    fit_systems,
    guess_receiver_class,
    model_file_parts,
    not_geodetic_evidence,
    static_residuals,
    station_evidence,
    station_residuals,
)
from locator.intervals import fit_error_model, overbound_error_model
from locator.observations import read_rinex_obs
from locator.sources import RinexSource
from predisat.gnss.errormodel import ErrorModel, ReceiverProfile

STATION = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # GEONET 0759, SOURCE.md


def test_static_residuals_of_a_geodetic_station(test_data):
    obs = read_rinex_obs(test_data / "gnss_obs" / "07590920_10ep.05o")
    model = RangeModel.from_rinex_nav(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    src = RinexSource(model, obs, "G")
    el, res = static_residuals(src, STATION, min_el_deg=10.0)
    assert el.shape == res.shape == (len(obs.gps_s), len(obs.sats))
    ok = np.isfinite(res)
    assert ok.sum(axis=1).min() >= 5 and (el[ok] >= 10.0).all()
    # at the GEONET position, residuals minus the per-epoch clock are at the metre level
    clock_free = res - np.nanmedian(res, axis=1, keepdims=True)
    assert np.sqrt(np.nanmean(clock_free**2)) < 2.0
    # the receiver clock is common: one value per epoch, far larger than the noise
    assert np.nanstd(np.nanmedian(res, axis=1)) >= 0.0


def test_binned_sigma_and_fit_recover_a_known_model():
    rng = np.random.default_rng(7)
    truth = ErrorModel(a_m=0.8, b_m=1.5)
    n_ep, n_sat = 3000, 10
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(5)), 1.0, (n_ep, n_sat))))
    clock = rng.normal(0, 1e4, (n_ep, 1))
    res = clock + rng.normal(size=el.shape) * truth.sigma_m(el)
    table = binned_sigma(el, res)
    expected = truth.sigma_m(table["el_mid_deg"].to_numpy())
    # the median clock removal leaves (1 + ~1/n) of the variance; 5 deg bins average sigma
    assert np.allclose(table["sigma_m"], expected, rtol=0.15)
    fit = fit_error_model(el, res)
    # a is weakly identified (b / sin el dominates everywhere): over seeds it scatters by ~0.1
    assert fit.a_m == pytest.approx(truth.a_m, abs=0.25)
    assert fit.b_m == pytest.approx(truth.b_m, rel=0.05)
    grid = np.linspace(10.0, 90.0, 17)
    assert np.allclose(fit.sigma_m(grid), truth.sigma_m(grid), rtol=0.05)
    fig = calibration_figure(table, fit)
    assert len(fig.axes[0].lines) == 2


def test_receiver_profiles_from_rinex_headers(test_data):
    obs = read_rinex_obs(test_data / "gnss_obs" / "07590920_10ep.05o")
    model = RangeModel.from_rinex_nav(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    r = station_residuals(RinexSource(model, obs, "G"), STATION, min_el_deg=10.0)
    # the header says TRIMBLE 5700 / TRM29659.00 and the file holds C1 (RINEX 2) for GPS
    assert r.profile == ReceiverProfile("TRIMBLE 5700", "TRM29659.00", {"G": ("C1",)})
    assert r.sats == obs.sats and r.el_deg.shape == (10, len(obs.sats))
    assert guess_receiver_class(r.profile.receiver_type) == ""
    phone = read_rinex_obs(test_data / "gnss_obs" / "android_rinex_obs_pixel6_6ep.23o")
    assert guess_receiver_class(phone.header.receiver_type, phone.header.program) == "phone"
    # what only reference stations carry, for the calibration's class check; a phone says none
    assert "reference-station" in station_evidence(r.profile.receiver_type)
    assert station_evidence(phone.header.receiver_type) == ""
    assert station_evidence("SEPT  POLARX5") and station_evidence("UBLOX ZED-F9P") == ""
    assert guess_receiver_class("SAMSUNG SM-G998B") == "phone"
    assert guess_receiver_class("MOTOROLA ONCORE") == ""  # a receiver, not a phone


def _synthetic(rng, n_ep, models, name="rx"):
    """Residuals of 8 satellites per system (shared clock) drawn from each system's model."""
    sats = tuple(f"{s}{k + 1:02d}" for s in models for k in range(8))
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(5.0)), 1.0, (n_ep, len(sats)))))
    sd = np.concatenate([np.broadcast_to(m.sigma_m(el[:, 8 * i : 8 * i + 8]), (n_ep, 8))
                         for i, m in enumerate(models.values())], axis=1)  # fmt: skip
    res = rng.normal(size=el.shape) * sd + rng.normal(0.0, 300.0, (n_ep, 1))
    prof = ReceiverProfile(name.upper(), "ANT", {s: ("C1C",) for s in models})
    return Residuals(el, res, sats, prof, name)


def test_each_constellation_is_fitted_apart():
    rng = np.random.default_rng(2)
    truth = {"G": ErrorModel(0.3, 0.5), "E": ErrorModel(1.5, 1.0)}
    data = [_synthetic(rng, 800, truth, "a"), _synthetic(rng, 800, truth, "b")]
    fits = fit_systems(data)
    assert set(fits) == {"G", "E"}
    for s, m in truth.items():
        f = fits[s]
        # the estimate of each system is its own law's (sigma at 30 deg within 10 %)
        assert float(f.estimate.sigma_m(30.0)) == pytest.approx(float(m.sigma_m(30.0)), rel=0.1)
        assert f.n_residuals == 2 * 800 * 8 and f.codes == ("C1C",)
        assert f.overbound is not None and f.overbound.factor >= 1.0
        sm = f.system_model()
        assert sm.n_independent <= sm.n_residuals and 0 < sm.tail_probability < 0.05
    model, systems, app = model_file_parts(fits, data, k_sigma=2.0, receiver_class="geodetic")
    assert app.receivers == ("A", "B") and app.receiver_class == "geodetic"
    assert 5.0 <= app.el_min_deg < 6.0 and app.sources == ("a", "b")
    assert model.error.a_m == max(systems["G"].error.a_m, systems["E"].error.a_m)
    # pooled (a simulation's systems share one law): one fit given to both
    pooled = fit_systems(data, pool_systems=True)
    assert pooled["G"].estimate == pooled["E"].estimate and pooled["G"].system == "EG"
    # a system with satellites in the data but no residual (never in view) is not covered
    dark = [dataclasses.replace(d, residual_m=np.where(np.array([s[0] == "E" for s in d.sats]),
                                                       np.nan, d.residual_m)) for d in data]
    assert set(fit_systems(dark, pool_systems=True)) == {"G"}
    with pytest.raises(ValueError, match="bound"):
        fit_systems(data, bound="maybe")


def test_a_pooled_overbound_also_bounds_each_pair_on_its_own():
    """A review (stops 49-50): a pooled tail check counted mostly the larger station, so a
    smaller one with errors three times larger stood under a bound its own residuals exceed,
    and the model applied to it by name. Each pair is now checked on its own."""
    rng = np.random.default_rng(5)
    big_law, small_law = ErrorModel(0.3, 0.5), ErrorModel(0.9, 1.5)
    big = _synthetic(rng, 3000, {"G": big_law}, "a")
    small = _synthetic(rng, 300, {"G": small_law}, "b")
    (fit,) = fit_systems([big, small]).values()
    factors = {r: g for r, _, g in fit.pair_factors}
    assert factors["A"] == 1.0 and factors["B"] > 1.5
    # the model bounds the small station's own tails (a check of its own, at the same
    # confidence), and its sigma is about the small station's law, not the pool's
    el, res = small.el_deg, small.residual_m
    # (to rounding: the model is the pool's times a factor; 1 + 8e-15 on one machine)
    own = overbound_error_model(el, res, fit.model, confidence=0.95).factor
    assert own == pytest.approx(1.0, abs=1e-9)
    assert float(fit.model.sigma_m(30.0)) >= 0.9 * float(small_law.sigma_m(30.0))
    # one pair (however many files) is checked by the pool itself
    (alone,) = fit_systems([big, _synthetic(rng, 3000, {"G": big_law}, "a")]).values()
    assert alone.pair_factors == ()


def test_a_pair_too_small_for_its_own_check_is_not_covered_by_name():
    """A review: a pair whose own tail check could not run (residuals in epochs of < 3
    satellites, or its files spelling its receiver two ways) was skipped, yet a run took the
    model for it by name, 2.3x under its errors."""
    import dataclasses

    rng = np.random.default_rng(5)
    big = _synthetic(rng, 3000, {"G": ErrorModel(0.3, 0.5)}, "a")
    small_law = ErrorModel(0.9, 1.5)
    prof = ReceiverProfile("B", "ANT", {"G": ("C1C",)})
    s = _synthetic(rng, 40, {"G": small_law}, "b")
    res = s.residual_m.copy()
    res[20:, 2:] = np.nan  # 200 finite residuals, 160 in epochs of >= 3 satellites
    data = [big, dataclasses.replace(s, residual_m=res)]
    fits = fit_systems(data)
    _, systems, app = model_file_parts(fits, data, k_sigma=2.0, receiver_class="geodetic")
    assert app.mismatches(prof, systems)
    s1, s2 = (_synthetic(rng, 15, {"G": small_law}, "b") for _ in range(2))
    s2 = dataclasses.replace(s2, profile=dataclasses.replace(s2.profile, receiver_type="b "))
    (fit,) = fit_systems([big, s1, s2]).values()
    assert {r: g for r, _, g in fit.pair_factors}["B"] > 1.5


def test_too_few_residuals_say_how_many_and_in_which_files():
    rng = np.random.default_rng(5)
    data = [_synthetic(rng, 6, {"R": ErrorModel(1.0, 1.0)}, "glonass_station")]
    with pytest.raises(ValueError) as err:
        fit_systems(data)
    msg = str(err.value)
    # 6 epochs of 8 GLONASS satellites: 48 residuals, counted here from the data itself
    n = int(np.isfinite(data[0].residual_m).sum())
    assert f"R {n} in 6 epochs" in msg and "glonass_station" in msg and "needed" in msg
    # systems the data do not hold are not named
    assert "C," not in msg and " S " not in msg


def test_a_pooled_file_records_each_receiver_antenna_pair_and_the_common_elevations():
    import dataclasses

    rng = np.random.default_rng(6)
    truth = {"G": ErrorModel(0.3, 0.5), "E": ErrorModel(1.5, 1.0)}
    a = _synthetic(rng, 800, truth, "a")
    b = _synthetic(rng, 800, truth, "b")
    b = dataclasses.replace(b, profile=ReceiverProfile("B", "ANT2", {"G": ("C1C",),
                                                                     "E": ("C1X",)}))
    # GPS seen below 60 deg only: the model's range is the one both systems were fitted on
    low = np.array([s[0] == "G" for s in a.sats]) & (a.el_deg > 60.0)
    a = dataclasses.replace(a, residual_m=np.where(low, np.nan, a.residual_m))
    b_low = np.array([s[0] == "G" for s in b.sats]) & (b.el_deg > 60.0)
    b = dataclasses.replace(b, residual_m=np.where(b_low, np.nan, b.residual_m))
    fits = fit_systems([a, b])
    _, _, app = model_file_parts(fits, [a, b], k_sigma=2.0)
    g_max = max(float(d.el_deg[np.isfinite(d.residual_m) & np.array([s[0] == "G" for s in
                                                                     d.sats])].max())
                for d in (a, b))  # fmt: skip
    assert app.el_max_deg == pytest.approx(g_max) and app.el_max_deg <= 60.0

    def count(d, sys_):  # residuals a tail check can use: epochs with >= 3 of the system
        cols = np.array([s[0] == sys_ for s in d.sats])
        ok = np.isfinite(d.residual_m[:, cols])
        return int((ok & (ok.sum(axis=1, keepdims=True) >= 3)).sum())

    assert app.pairs == (
        ("A", "ANT", (("E", ("C1C",), count(a, "E")), ("G", ("C1C",), count(a, "G")))),
        ("B", "ANT2", (("E", ("C1X",), count(b, "E")), ("G", ("C1C",), count(b, "G")))),
    )


def test_systems_fitted_on_elevations_with_nothing_in_common_are_refused():
    import dataclasses

    rng = np.random.default_rng(7)
    truth = {"G": ErrorModel(0.3, 0.5), "E": ErrorModel(1.5, 1.0)}
    d = _synthetic(rng, 800, truth, "a")
    g = np.array([s[0] == "G" for s in d.sats])
    # GPS seen only below 40 deg, Galileo only above 45
    keep = np.where(g, d.el_deg < 40.0, d.el_deg > 45.0)
    d = dataclasses.replace(d, residual_m=np.where(keep, d.residual_m, np.nan))
    fits = fit_systems([d])
    with pytest.raises(ValueError, match=r"nothing in common .*--constellation"):
        model_file_parts(fits, [d], k_sigma=2.0)


def test_a_systems_count_is_of_the_residuals_its_fit_used():
    """A review (hW): intervals.usable_residuals is the one rule for the residuals a fit can
    use (finite, in epochs with >= 3), and model_file_parts counts each pair by it, but
    SystemFit.n_residuals (the file's n_residuals, `locator calibrate`'s "from N residuals",
    n_independent of an estimate) and its elevation range counted every finite residual,
    those of epochs with 1-2 satellites of the system too."""
    from locator.intervals import usable_residuals

    rng = np.random.default_rng(5)
    d = _synthetic(rng, 600, {"G": ErrorModel(0.3, 0.5)}, "a")
    res = d.residual_m.copy()
    res[:200, 2:] = np.nan  # 200 epochs with 2 satellites: nothing for the clock's removal
    d = dataclasses.replace(d, residual_m=res)
    used = int(usable_residuals(d.el_deg, res).sum())
    assert used == 400 * 8
    for bound in ("overbound", "estimate"):
        (fit,) = fit_systems([d], bound=bound).values()
        assert fit.n_residuals == used, bound
        assert fit.system_model().n_independent <= used
    _, systems, _ = model_file_parts(fit_systems([d]), [d], k_sigma=2.0,
                                     receiver_class="geodetic")  # fmt: skip
    assert systems["G"].n_residuals == used


@pytest.mark.parametrize("receiver", ["ZED-F9P", "UBX-M8030", "NEO-M8T", "SkyTraq S1216F8",
                                      "Allystar TAU1202", "BCM47755", "N/A", "?",
                                      "UNKNOWN RECEIVER"])  # fmt: skip
def test_a_mass_market_module_or_an_unnamed_receiver_is_no_geodetic_evidence(receiver: str):
    """A u-blox module named without its maker (as RTKLIB writes it) or an unnamed receiver
    passed as geodetic (a review: 'ZED-F9P', 'UBX-M8030', 'N/A' were taken)."""
    assert not_geodetic_evidence(receiver)


@pytest.mark.parametrize("receiver", ["TRIMBLE 5700", "SEPT POLARX5", "LEICA GR50",
                                      "JAVAD TRE_3 DELTA", "TRIMBLE NETR9"])  # fmt: skip
def test_a_geodetic_receiver_is_not_refused(receiver: str):
    assert not_geodetic_evidence(receiver) == ""
