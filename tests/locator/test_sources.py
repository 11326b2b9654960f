"""The checks every epoch source makes of the odometer it is given."""

from __future__ import annotations

import numpy as np
import pytest

from locator.sources import check_odometer


def test_an_odometer_with_one_value_per_epoch_and_its_disputed_distance_pass() -> None:
    odo = np.arange(5.0)
    extra = np.column_stack([np.linspace(0, 1, 5), np.zeros(5)])
    check_odometer(odo, extra, 5)
    check_odometer(odo, None, 5)
    check_odometer(None, None, 5)


@pytest.mark.parametrize(
    ("odometer", "extra", "message"),
    [
        (np.arange(4.0), None, r"one value per epoch \(\(5,\)\), got \(4,\)"),
        (np.zeros((5, 1)), None, r"one value per epoch"),
        (None, np.zeros((5, 2)), "needs odometer"),
        (np.arange(5.0), np.zeros((5, 3)), r"shape \(5, 2\), got \(5, 3\)"),
        (np.arange(5.0), np.array([[0, 0], [1, 0], [0.5, 0], [2, 0], [3, 0]]), "non-decreasing"),
        (np.arange(5.0), np.full((5, 2), -1.0), ">= 0"),
        (np.arange(5.0), np.full((5, 2), np.nan), "finite"),
    ],
)
def test_a_bad_odometer_is_refused_naming_the_problem(
    odometer: np.ndarray | None, extra: np.ndarray | None, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        check_odometer(odometer, extra, 5)


# ---------------------------------------------------------------------- dual frequency


@pytest.fixture(scope="module")
def kms3(test_data):
    from locator.corrections import RangeModel
    from locator.observations import read_rinex_obs

    obs = read_rinex_obs(test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx")
    model = RangeModel.from_rinex_nav(test_data / "gnss" / "KMS300DNK_R_20221591000_01H_MN.rnx.gz")
    return obs, model


def test_the_ionosphere_free_range_is_the_icd_combination_without_group_delay(kms3) -> None:
    """GPS L1/L2 (Septentrio KMS3: C1C with C2W, or C2L where P(Y) is not tracked): the
    broadcast clock refers to the ionosphere-free combination of L1 and L2 P(Y), so
    IS-GPS-200 20.3.3.3.3.2 needs no TGD there (L2C's ISC neglected, as L1 C/A's is): the
    combined range is ``(f1^2 P1 - f2^2 P2) / (f1^2 - f2^2)`` plus the satellite clock and
    relativity, less the troposphere, with no group delay and no ionosphere model.
    Computed here from the raw observations."""
    from locator.sources import RinexSource

    obs, model = kms3
    src = RinexSource(model, obs, "G", dual_frequency=True)
    x = np.asarray(obs.header.approx_position_ecef_m, float)
    f1, f2 = 1575.42e6, 1227.60e6
    for epoch in (0, len(obs.gps_s) - 1):
        d = src.observe(epoch, x)
        assert len(d.sats) >= 5 and not np.any(d.extra_sigma_m)
        cols = [obs.sats.index(s) for s in d.sats]
        codes = src.codes(epoch, np.array(cols))
        assert "C1C+C2W" in codes and all(c in ("C1C+C2W", "C1C+C2L") for c in codes)
        p1 = obs.obs("C1C")[epoch, cols]
        p2 = np.array([obs.obs(c[4:])[epoch, k] for c, k in zip(codes, cols, strict=True)])
        single = model.correct(float(obs.gps_s[epoch]), d.sats, p1, x, "C1C")
        st = single.states
        want = ((f1**2 * p1 - f2**2 * p2) / (f1**2 - f2**2) + st.sat_clock_m + st.relativity_m
                - single.tropo_m)  # fmt: skip
        np.testing.assert_allclose(d.pseudorange_m, want, rtol=0, atol=1e-4)
        # and it is not the single-frequency range: the ionosphere and the TGD differ
        assert np.all(np.abs(d.pseudorange_m - single.corrected_m) > 0.01)


def test_dual_frequency_needs_no_ionosphere_model_and_leaves_out_single_code_satellites(
    kms3,
) -> None:
    import dataclasses

    from locator.corrections import BroadcastIono
    from locator.sources import RinexSource

    obs, model = kms3
    bare = dataclasses.replace(model, iono=BroadcastIono())  # no Klobuchar set at all
    single = RinexSource(bare, obs, "G")
    dual = RinexSource(bare, obs, "G", dual_frequency=True)
    assert single.iono_missing == ("G",) and dual.iono_missing == ()
    assert dual.frequency == "dual" and dual.describe()["frequency"] == "dual"
    used = RinexSource(model, obs, "G", dual_frequency=True).describe()
    assert used["iono_sources"] == {} and RinexSource(model, obs, "G").describe()["iono_sources"]
    # a satellite without any L2 code: left out of the combination, with the reason
    x = np.asarray(obs.header.approx_position_ecef_m, float)
    k = obs.sats.index(RinexSource(model, obs, "G", dual_frequency=True).observe(0, x).sats[0])
    values = dict(obs.values)
    for code in ("C2W", "C2L"):
        values[code] = values[code].copy()
        values[code][:, k] = np.nan
    cut = dataclasses.replace(obs, values=values)
    d = RinexSource(model, cut, "G", dual_frequency=True).observe(0, x)
    assert obs.sats[k] not in d.sats and "second frequency" in d.rejected[obs.sats[k]]
    assert obs.sats[k] in RinexSource(model, cut, "G").observe(0, x).sats  # single: kept


@pytest.mark.parametrize("system", ["C", "E"])
def test_the_ionosphere_free_range_of_beidou_and_galileo_is_the_icd_combination(
    kms3, system
) -> None:
    """BeiDou B1I / B3I: B3I is the D1/D2 clock's reference, so B1I is corrected by TGD1 and
    B3I by nothing before combining (the combination keeps 2.94 TGD1, metres). Galileo E1 /
    E5b with the I/NAV clock: BGD(E1,E5b) on E1 and (f1/f7)^2 BGD on E5b cancel, as GPS's
    TGD does. Computed here from the raw observations; the group delay of the first code is
    the single-frequency path's (tested on its own in test_corrections)."""
    from locator.sources import RinexSource

    obs, model = kms3
    src = RinexSource(model, obs, system, dual_frequency=True)
    x = np.asarray(obs.header.approx_position_ecef_m, float)
    f1 = {"C": 1561.098e6, "E": 1575.42e6}[system]
    f2 = {"C": 1268.52e6, "E": 1207.14e6}[system]
    pair = {"C": ("C2I", "C6I"), "E": ("C1C", "C7Q")}[system]
    checked = 0
    for epoch in (0, len(obs.gps_s) - 1):
        d = src.observe(epoch, x)
        cols = [obs.sats.index(s) for s in d.sats]
        codes = src.codes(epoch, np.array(cols, int))
        keep = [i for i, c in enumerate(codes) if c == "+".join(pair)]
        assert len(keep) >= 4, codes
        sats = [d.sats[i] for i in keep]
        p1 = obs.obs(pair[0])[epoch, [cols[i] for i in keep]]
        p2 = obs.obs(pair[1])[epoch, [cols[i] for i in keep]]
        single = model.correct(float(obs.gps_s[epoch]), sats, p1, x, pair[0])
        st = single.states
        gd1 = st.group_delay_m if system == "C" else np.zeros(len(sats))
        want = ((f1**2 * (p1 - gd1) - f2**2 * p2) / (f1**2 - f2**2) + st.sat_clock_m
                + st.relativity_m - single.tropo_m)  # fmt: skip
        np.testing.assert_allclose(d.pseudorange_m[keep], want, rtol=0, atol=1e-3)
        if system == "C":  # TGD1 is metres here: leaving it out would show
            assert np.all(np.abs(st.group_delay_m) > 0.05)
        checked += len(keep)
    assert checked >= 8
