"""Tests of error-model learning (locator.errorfit) on real and synthetic residuals."""

from __future__ import annotations

import numpy as np
import pytest

from locator.corrections import RangeModel
from locator.errorfit import binned_sigma, calibration_figure, static_residuals
from locator.intervals import fit_error_model
from locator.observations import read_rinex_obs
from locator.sources import RinexSource
from predisat.gnss.errormodel import ErrorModel

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
