"""Single-frequency model: every term against published values or an independent computation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from locator.corrections import (
    OMEGA_E_RADPS,
    BroadcastIono,
    RangeModel,
    carrier_frequency_hz,
    cnav_group_delay_s,
    group_delay_s,
    klobuchar_bds_delay_m,
    klobuchar_delay_m,
    niell_mapping,
    saastamoinen_zenith_m,
    troposphere_delay_m,
)
from locator.observations import read_rinex_obs
from predisat.geodesy import ecef_to_geodetic
from predisat.gnss.rinex_nav import read_rinex_nav
from predisat.gnss.timescale import calendar_to_gps_s

C = 299792458.0
NAV = "gnss_obs/07590920_0000_0200.05n"
OBS = "gnss_obs/07590920_10ep.05o"
STATION = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # GEONET 0759, SOURCE.md

# RTKLIB test/utest/t_atmos.c (v2.4.2): ionmodel(), tropmodel(), tropmapf() reference values
RTK_ION = ([0.2e-7, -0.8e-8, -0.5e-7, 0.1e-6], [0.2e6, 0.2e6, -0.1e6, -0.1e7])
RTK_IONO_CASES = [
    # (hour of 2007-01-16, lat, lon, az, el, delay m)
    (1, 35, 140, 60, 75, 6.73590532099438),
    (1, -80, -170, 60, 75, 3.56895382197387),
    (1, 10, 30, 60, 75, 3.80716435655161),
    (13, 35, 140, 60, 75, 5.21796954585452),
    (22, 35, 140, 60, 75, 5.90190539264777),
    (1, 35, 140, 190, 3, 21.6345415123632),
    (1, 35, 140, 350, 60, 7.33844278822561),
    (1, 35, 140, 0, 90, 6.58339711400694),
]


@pytest.fixture(scope="module")
def model(test_data: Path) -> RangeModel:
    return RangeModel.from_rinex_nav(test_data / NAV)


@pytest.mark.parametrize(("hour", "lat", "lon", "az", "el", "expected"), RTK_IONO_CASES)
def test_klobuchar_matches_rtklib(hour, lat, lon, az, el, expected) -> None:
    t = calendar_to_gps_s(2007, 1, 16, hour)
    got = klobuchar_delay_m(t, lat, lon, az, el, *RTK_ION)
    assert got == pytest.approx(expected, abs=1e-8)


def test_klobuchar_vectorised_and_zero_below_horizon() -> None:
    t = calendar_to_gps_s(2007, 1, 16, 1)
    cases = np.array([c[1:5] for c in RTK_IONO_CASES if c[0] == 1], float)
    got = klobuchar_delay_m(t, cases[:, 0], cases[:, 1], cases[:, 2], cases[:, 3], *RTK_ION)
    want = [c[5] for c in RTK_IONO_CASES if c[0] == 1]
    np.testing.assert_allclose(got, want, atol=1e-8)
    assert klobuchar_delay_m(t, 35, 140, 60, -5, *RTK_ION) == 0.0


def test_saastamoinen_matches_rtklib_and_zenith_magnitude() -> None:
    # RTKLIB tropmodel maps with 1/sin(el): 2.44799870144088 m at el 75, lat 35, h 100, 50 %
    zhd, zwd = saastamoinen_zenith_m(35.0, 100.0, humidity=0.5)
    assert (zhd + zwd) / np.sin(np.radians(75.0)) == pytest.approx(2.44799870144088, abs=1e-8)
    zhd, zwd = saastamoinen_zenith_m(-80.0, 1000.0, humidity=0.5)
    assert (zhd + zwd) / np.sin(np.radians(75.0)) == pytest.approx(2.17295817298152, abs=1e-8)
    # standard atmosphere at sea level: about 2.3 m hydrostatic plus 0.1-0.2 m wet
    zhd, zwd = saastamoinen_zenith_m(45.0, 0.0)
    assert 2.25 < zhd < 2.35 and 0.05 < zwd < 0.25 and 2.3 < zhd + zwd < 2.5


@pytest.mark.parametrize(
    ("date", "lat", "h", "el", "dry", "wet"),
    [
        ((2007, 1, 16, 6), 35, 100, 75, 1.035184526466435, 1.035233787448654),
        ((2007, 1, 16, 6), 35, 100, 3, 14.643271711748200, 16.455045694559484),
        ((2007, 1, 16, 6), 35, 100, 60, 1.154226397147367, 1.154481126139610),
        ((2007, 1, 16, 6), 35, 100, 90, 1.0, 1.0),
        ((2030, 12, 31, 23, 59, 59), 35, 100, 75, 1.035184415128022, 1.035233787448654),
        ((2007, 1, 16, 6), -80, 1000, 75, 1.035186155749051, 1.035230548304367),
        ((2007, 1, 16, 6), 10, 0, 75, 1.035181919429758, 1.035233200318210),
    ],
)
def test_niell_matches_rtklib(date, lat, h, el, dry, wet) -> None:
    m_dry, m_wet = niell_mapping(calendar_to_gps_s(*date), lat, h, el)
    assert m_dry == pytest.approx(dry, abs=1e-8) and m_wet == pytest.approx(wet, abs=1e-8)


def test_troposphere_slant_grows_and_is_nan_below_horizon() -> None:
    t = calendar_to_gps_s(2020, 6, 1)
    d = troposphere_delay_m(t, 50.0, 200.0, np.array([90.0, 30.0, 10.0, 5.0, -1.0]))
    assert np.all(np.diff(d[:4]) > 0) and np.isnan(d[4])
    assert d[1] == pytest.approx(d[0] / np.sin(np.radians(30.0)), rel=0.01)


def test_iono_coefficients_from_rinex2_and_rinex3_headers(test_data: Path) -> None:
    r2 = BroadcastIono.from_rinex_nav(test_data / NAV)
    # lines 8-9: "1.1180D-08  1.4900D-08 -5.9600D-08 -5.9600D-08" and "8.8060D+04 ..."
    np.testing.assert_array_equal(r2.gps_alpha, [1.118e-8, 1.49e-8, -5.96e-8, -5.96e-8])
    np.testing.assert_array_equal(r2.gps_beta, [8.806e4, 1.638e4, -1.966e5, -1.311e5])
    assert r2.source.endswith(":8") and r2.bds_alpha is None
    r3 = BroadcastIono.from_rinex_nav(
        test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx"
    )
    np.testing.assert_array_equal(r3.gps_alpha, [2.6077e-08, 7.4506e-09, -1.1921e-07, 0.0])
    np.testing.assert_array_equal(r3.bds_beta, [1.1878e05, 3.2768e04, 7.8643e05, -7.8643e05])
    np.testing.assert_array_equal(r3.gal_ai, [1.3875e02, 1.2891e-01, 1.8494e-02])
    coef_c = r3.coefficients("C")
    coef_e = r3.coefficients("E")
    assert coef_c is not None and coef_e is not None
    assert coef_c[0] is r3.bds_alpha and coef_e[0] is r3.gps_alpha
    assert BroadcastIono().coefficients("G") is None


def test_carrier_frequencies() -> None:
    assert carrier_frequency_hz("G05", "C1C") == 1575.42e6
    assert carrier_frequency_hz("G05", "P2") == 1227.60e6
    assert carrier_frequency_hz("C11", "C2I") == 1561.098e6
    assert carrier_frequency_hz("C11", "C1I") == 1561.098e6  # RINEX 3.01 name of B1I
    assert carrier_frequency_hz("R02", "C1C", glonass_k=-4) == 1602e6 - 4 * 0.5625e6
    assert np.isnan(carrier_frequency_hz("R02", "C1C"))
    assert np.isnan(carrier_frequency_hz("G05", "C7Q"))


def test_group_delay_rules() -> None:
    tgd, aux26 = 2e-9, 3e-9
    assert group_delay_s("G01", "C1C", tgd, np.nan, np.nan) == tgd
    assert group_delay_s("G01", "C2W", tgd, np.nan, np.nan) == pytest.approx(
        (1575.42 / 1227.60) ** 2 * tgd
    )
    inav, fnav = 517.0, 258.0  # data-source words: I/NAV E1-B (bits 0, 9) / F/NAV (bits 1, 8)
    assert group_delay_s("E11", "C1C", tgd, aux26, inav) == aux26  # BGD E1/E5b
    assert group_delay_s("E11", "C1C", tgd, aux26, fnav) == tgd  # BGD E1/E5a
    assert group_delay_s("E11", "C5Q", tgd, aux26, fnav) == pytest.approx(
        (1575.42 / 1176.45) ** 2 * tgd
    )
    assert np.isnan(group_delay_s("E11", "C5Q", tgd, aux26, inav))
    assert group_delay_s("C11", "C2I", tgd, aux26, np.nan) == tgd  # TGD1 on B1I
    assert group_delay_s("C11", "C7I", tgd, aux26, np.nan) == aux26  # TGD2 on B2I
    assert group_delay_s("C11", "C6I", tgd, aux26, np.nan) == 0.0  # B3I is the reference
    assert group_delay_s("R01", "C1C", np.nan, np.nan, np.nan) == 0.0
    # L1 P(Y) and RINEX 2 C1 / P1 share the TGD reference; L1C and QZSS L1S do not
    for code in ("C1W", "C1P", "C1", "P1"):
        assert group_delay_s("G01", code, tgd, np.nan, np.nan) == tgd
    for sat, code in (("G01", "C1L"), ("G01", "C1X"), ("J02", "C1X"), ("J02", "C1Z")):
        assert np.isnan(group_delay_s(sat, code, tgd, np.nan, np.nan)), code


def _first_epoch(test_data: Path):
    obs = read_rinex_obs(test_data / OBS)
    sel = obs.pseudorange()
    have = np.isfinite(sel.pseudorange_m[0])
    sats = [s for s, h in zip(obs.sats, have, strict=True) if h]
    return float(obs.gps_s[0]), sats, sel.pseudorange_m[0, have], list(sel.code[0, have])


def test_clock_split_relativity_and_tgd(model: RangeModel, test_data: Path) -> None:
    t, sats, pr, codes = _first_epoch(test_data)
    st = model.states(t, sats, pr, codes)
    assert np.all(st.reason == "")
    # the split is exact: clock polynomial + relativity = the ephemeris clock
    _, clk, _ = model.ephemeris.evaluate(st.transmit_gps_s, sats)
    np.testing.assert_allclose(st.sat_clock_m + st.relativity_m, C * np.diagonal(clk), atol=1e-6)
    # transmission time: receiver tag minus the travel time read by the satellite clock
    np.testing.assert_allclose(st.transmit_gps_s, t - pr / C - np.diagonal(clk), atol=1e-12)
    # relativity against the ICD formula F e sqrt(A) sin(E), Kepler solved here by bisection
    nav = read_rinex_nav(test_data / NAV).kepler
    mu, f_rel = 3.986005e14, -4.442807633e-10
    for j, s in enumerate(sats):
        rows = np.nonzero(nav.sat == s)[0]
        r = rows[np.argmin(np.abs(nav.ref_gps_s[rows] - st.transmit_gps_s[j]))]
        e, sqrt_a = nav.col("e")[r], nav.col("sqrt_a_sqrtm")[r]
        n = np.sqrt(mu / sqrt_a**6) + nav.col("delta_n_radps")[r]
        m = nav.col("m0_rad")[r] + n * (st.transmit_gps_s[j] - nav.ref_gps_s[r])
        lo, hi = m - 1.0, m + 1.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if mid - e * np.sin(mid) < m else (lo, mid)
        icd = C * f_rel * e * sqrt_a * np.sin(0.5 * (lo + hi))
        assert st.relativity_m[j] == pytest.approx(icd, abs=0.02), s
    assert np.max(np.abs(st.relativity_m)) > 1.0  # metres, eccentricities ~0.01
    # G07: TGD -2.328306436540D-09 s on line 51 of the excerpt
    g07 = sats.index("G07")
    assert st.group_delay_m[g07] == pytest.approx(C * -2.328306436540e-09, abs=1e-9)


def test_earth_rotation_matches_first_order_sagnac(model: RangeModel, test_data: Path) -> None:
    t, sats, pr, codes = _first_epoch(test_data)
    cr = model.correct(t, sats, pr, STATION, codes)
    pos = cr.states.pos_ecef_m
    sagnac = OMEGA_E_RADPS * (pos[:, 0] * STATION[1] - pos[:, 1] * STATION[0]) / C
    np.testing.assert_allclose(cr.earth_rotation_m, sagnac, atol=0.01)
    assert 10.0 < np.max(np.abs(cr.earth_rotation_m)) < 40.0
    # the rotated position is the satellite at transmission seen in the reception frame
    np.testing.assert_allclose(np.linalg.norm(cr.sat_ecef_m, axis=1), np.linalg.norm(pos, axis=1))
    np.testing.assert_allclose(cr.sat_ecef_m[:, 2], pos[:, 2])


def test_corrected_ranges_close_the_budget(model: RangeModel, test_data: Path) -> None:
    t, sats, pr, codes = _first_epoch(test_data)
    cr = model.correct(t, sats, pr, STATION, codes)
    assert np.all(cr.iono_m > 0.5) and np.all(cr.iono_m < 30.0)
    assert np.all(cr.tropo_m > 2.3) and np.all(cr.tropo_m < 30.0)
    b = cr.breakdown()
    total = b["pseudorange_m"] + b["sat_clock_m"] + b["relativity_m"] - b["group_delay_m"]
    np.testing.assert_allclose(total - b["iono_m"] - b["tropo_m"], cr.corrected_m)
    # at the known station every satellite above 10 deg shows the same receiver clock
    res = cr.corrected_m - cr.range_m
    high = cr.el_deg > 10.0
    assert np.ptp(res[high]) < 3.0
    # without atmosphere the spread is larger (the terms point the right way)
    raw = model.correct(t, sats, pr, STATION, codes, atmosphere=False)
    assert np.ptp((raw.corrected_m - raw.range_m)[high]) > np.ptp(res[high]) + 2.0


def test_iono_and_group_delay_scale_with_the_signal(model: RangeModel, test_data: Path) -> None:
    t, sats, pr, _ = _first_epoch(test_data)
    l1 = model.correct(t, sats, pr, STATION, "C1C")
    l2 = model.correct(t, sats, pr, STATION, "C2W")
    gamma = (1575.42 / 1227.60) ** 2
    np.testing.assert_allclose(l2.iono_m, gamma * l1.iono_m, rtol=1e-12)
    np.testing.assert_allclose(l2.states.group_delay_m, gamma * l1.states.group_delay_m)


def test_missing_navigation_and_unknown_signal_are_flagged(
    model: RangeModel, test_data: Path
) -> None:
    t, sats, pr, codes = _first_epoch(test_data)
    cr = model.correct(
        t, [*sats, "G31", "E11"], [*pr, pr[0], pr[1]], STATION, [*codes, "C1", "C1C"]
    )
    assert cr.reason[-2] == "NO_DATA" and cr.reason[-1] == "NO_DATA"
    assert not cr.usable[-2:].any() and cr.usable[:-2].sum() == len(sats)
    odd = model.states(t, sats[:1], pr[:1], "C7Q")
    assert "group delay" in odd.reason[0]
    gone = model.states(t + 86400.0 * 3, sats[:1], pr[:1], "C1")
    assert gone.reason[0] == "OUTSIDE_VALIDITY"
    with pytest.raises(ValueError, match="atmosphere=False"):
        model.correct(t, sats, pr, np.zeros(3), codes)


NAV4 = "gnss/KMS300DNK_R_20221591000_01H_MN.rnx.gz"


def test_iono_coefficients_from_rinex4_ion_records(test_data: Path) -> None:
    iono = BroadcastIono.from_rinex_nav(test_data / NAV4)
    # "> ION G29 LNAV" / "    2022 06 08 09 59 48 1.024454832077E-08 2.235174179077E-08 ..."
    np.testing.assert_array_equal(
        iono.gps_alpha,
        [1.024454832077e-08, 2.235174179077e-08, -5.960464477539e-08, -1.192092895508e-07],
    )
    np.testing.assert_array_equal(iono.gps_beta, [9.6256e04, 1.31072e05, -6.5536e04, -5.89824e05])
    np.testing.assert_array_equal(iono.bds_beta, [1.20832e05, 1.47456e05, -1.31072e05, -6.5536e04])
    np.testing.assert_array_equal(iono.gal_ai, [7.85e01, 5.390625e-01, 2.713012695312e-02])
    assert set(iono.sources) == {"GPS", "BDS", "GAL"} and iono.source == iono.sources["GPS"]
    k = iono.klobuchar("E")
    assert k is not None and k[2] == "GPS"  # Galileo broadcasts no Klobuchar set: GPS's is used


def test_klobuchar_from_another_system_when_gps_has_none(test_data: Path, tmp_path: Path) -> None:
    """A navigation file without GPS coefficients: every system uses whatever Klobuchar set
    exists (here BeiDou's), never none."""
    src = test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx"
    lines = src.read_text().splitlines(keepends=True)
    no_gps = tmp_path / "no_gps_iono.rnx"
    no_gps.write_text("".join(t for t in lines if not t.startswith("GPS")))
    iono = BroadcastIono.from_rinex_nav(no_gps)
    # header line 11: "QZSA   2.9802e-08 -2.2352e-08 -3.5763e-07 -2.3842e-07"
    k = iono.klobuchar("G")
    assert iono.gps_alpha is None and k is not None and k[2] == "QZS"
    np.testing.assert_array_equal(k[0], [2.9802e-08, -2.2352e-08, -3.5763e-07, -2.3842e-07])
    only_bds = tmp_path / "only_bds_iono.rnx"
    only_bds.write_text("".join(t for t in lines if not t.startswith(("GPS", "QZS"))))
    iono = BroadcastIono.from_rinex_nav(only_bds)
    for system in "GECJR":
        k = iono.klobuchar(system)
        assert k is not None and k[2] == "BDS" and k[0] is iono.bds_alpha, system
    assert BroadcastIono().klobuchar("G") is None


def test_uncorrected_iono_sigma_scales_with_obliquity_and_frequency() -> None:
    from locator.corrections import UNCORRECTED_IONO_SIGMA_M, uncorrected_iono_sigma_m

    assert uncorrected_iono_sigma_m(90.0) == pytest.approx(UNCORRECTED_IONO_SIGMA_M)
    s = uncorrected_iono_sigma_m(np.array([90.0, 45.0, 20.0, 5.0]))
    assert np.all(np.diff(s) > 0) and 2.5 < s[-1] / s[0] < 3.2  # thin-shell factor, ~3 at 5 deg
    l5 = uncorrected_iono_sigma_m(90.0, 1176.45e6)
    assert l5 == pytest.approx(UNCORRECTED_IONO_SIGMA_M * (1575.42 / 1176.45) ** 2)


def test_epochs_without_any_iono_model_are_flagged_and_inflated(test_data: Path) -> None:
    """KMS3 Galileo: with the RINEX 4 file's GPS Klobuchar set every satellite is corrected;
    without any set the source reports every satellite uncorrected with the inflated sigma."""
    from locator.observations import read_rinex_obs
    from locator.sources import RinexSource

    model = RangeModel.from_rinex_nav(test_data / NAV4)
    obs = read_rinex_obs(test_data / "gnss_obs/KMS300DNK_R_20221591000_01H_30S_MO.crx")
    x = obs.header.approx_position_ecef_m
    with_iono = RinexSource(model, obs, "E")
    bare = RinexSource(RangeModel.from_ephemeris(model.ephemeris, BroadcastIono()), obs, "E")
    assert with_iono.iono_missing == () and bare.iono_missing == ("E",)
    a, b = with_iono.observe(0, x), bare.observe(0, x)
    assert a.sats == b.sats and len(a.sats) >= 4
    assert a.extra_sigma_m is not None and np.all(a.extra_sigma_m == 0.0)
    assert b.extra_sigma_m is not None and np.all(b.extra_sigma_m >= 5.0)
    cr = model.correct(float(obs.gps_s[0]), a.sats, np.full(len(a.sats), 2.3e7), x, "C1C")
    assert set(cr.iono_model.tolist()) == {"GPS"} and not cr.iono_uncorrected.any()


def test_iono_sets_of_the_observation_day_whatever_the_file_order(test_data: Path) -> None:
    """A 2005 RINEX 2 file listed before a 2022 RINEX 4 file: the 2022 observations take the
    2022 coefficients (a user trial: the first file's set moved the ranges by 2-5 m), the 2005
    ones the 2005 coefficients, and a time far from both takes none (stale, said)."""
    r2, r4 = test_data / NAV, test_data / NAV4
    own2, own4 = BroadcastIono.from_rinex_nav(r2), BroadcastIono.from_rinex_nav(r4)
    model = RangeModel.from_rinex_nav([r2, r4])
    assert model.iono.source == own2.source  # without a time: the first file wins, as before
    at_2022 = model.with_iono_near(calendar_to_gps_s(2022, 6, 8, 10, 30))
    np.testing.assert_array_equal(at_2022.iono.gps_alpha, own4.gps_alpha)
    assert at_2022.iono.source == own4.source and not at_2022.iono.stale
    at_2005 = RangeModel.from_rinex_nav([r4, r2]).with_iono_near(calendar_to_gps_s(2005, 4, 2))
    np.testing.assert_array_equal(at_2005.iono.gps_beta, own2.gps_beta)
    assert at_2005.iono.bds_alpha is None  # the 2022 BeiDou set is of another day
    assert set(at_2005.iono.stale) == {"BDS", "GAL"}
    at_2015 = model.with_iono_near(calendar_to_gps_s(2015, 1, 1))
    assert at_2015.iono.klobuchar("G") is None
    assert at_2015.iono.stale["GPS"] == f"{own4.source} (2022-06-08)"  # the nearest, named
    # a set the caller gave, not read from the model's files, stays
    given = RangeModel.from_ephemeris(model.ephemeris, BroadcastIono(own2.gps_alpha, own2.gps_beta))
    assert given.with_iono_near(calendar_to_gps_s(2022, 6, 8)).iono is given.iono


# the BeiDou set of KMS300DNK 2022-06-08 (RINEX 4 "> ION C.. D1D2")
BDS_ALPHA = np.array(
    [2.142041921616e-08, 1.192092895508e-07, -1.013278961182e-06, 1.549720764160e-06]
)
BDS_BETA = np.array([1.20832e05, 1.47456e05, -1.31072e05, -6.5536e04])


def test_beidou_klobuchar_follows_its_icd_clauses() -> None:
    """BDS-SIS-ICD-B1I 5.2.4.7 clause by clause: 5 ns at night times the 375 km shell's
    obliquity; at the zenith at 14:00 local time (BDT) 5 ns plus the amplitude of the pierce
    point's |geographic latitude|; the same north and south."""
    day0 = calendar_to_gps_s(2022, 6, 8)
    # local time 14:00 at longitude 0 is 14:00 BDT = 14:00:14 GPST
    noon = day0 + 14 * 3600.0 + 14.0
    lat = 50.0
    x = lat / 180.0
    amp = BDS_ALPHA @ np.array([1.0, x, x**2, x**3])
    zen = klobuchar_bds_delay_m(noon, lat, 0.0, 0.0, 90.0, BDS_ALPHA, BDS_BETA)
    assert zen == pytest.approx(C * (5e-9 + amp), rel=1e-12)
    south = klobuchar_bds_delay_m(noon, -lat, 0.0, 0.0, 90.0, BDS_ALPHA, BDS_BETA)
    assert south == pytest.approx(zen)
    # 02:00 local: night; at 20 deg the obliquity of the 375 km shell, Earth radius 6378 km
    night = day0 + 2 * 3600.0 + 14.0
    el = 20.0
    obl = 1.0 / np.sqrt(1.0 - (6378.0 / 6753.0 * np.cos(np.radians(el))) ** 2)
    d = klobuchar_bds_delay_m(night, lat, 0.0, 90.0, el, BDS_ALPHA, BDS_BETA)
    assert d == pytest.approx(C * 5e-9 * obl, rel=1e-12)
    assert klobuchar_bds_delay_m(night, lat, 0.0, 90.0, -1.0, BDS_ALPHA, BDS_BETA) == 0.0
    # the GPS form with these coefficients is another model (a user trial: up to 1.2 m)
    gps_form = klobuchar_delay_m(noon, lat, 0.0, 0.0, 15.0, BDS_ALPHA, BDS_BETA) * (
        1575.42 / 1561.098
    ) ** 2
    bds = klobuchar_bds_delay_m(noon, lat, 0.0, 0.0, 15.0, BDS_ALPHA, BDS_BETA)
    assert abs(float(gps_form - bds)) > 0.3


def test_beidou_satellites_take_the_beidou_form_on_their_carrier(test_data: Path) -> None:
    model = RangeModel.from_rinex_nav(test_data / NAV4)
    t = calendar_to_gps_s(2022, 6, 8, 10, 30)
    rx = np.array([3512889.0, 778259.0, 5248296.0])  # KMS3, Copenhagen (approx.)
    sats = [s for s in model.ephemeris.satellites if s.startswith("C")]
    cr = model.correct(t, sats, np.full(len(sats), 2.2e7), rx, "C2I")
    ok = np.isfinite(cr.el_deg) & (cr.el_deg > 0)
    assert ok.sum() >= 3 and set(cr.iono_model[ok]) == {"BDS"}
    lat, lon, _ = (float(v) for v in ecef_to_geodetic(rx))
    want = klobuchar_bds_delay_m(t, lat, lon, cr.az_deg[ok], cr.el_deg[ok], BDS_ALPHA, BDS_BETA)
    np.testing.assert_allclose(cr.iono_m[ok], want, rtol=1e-9)  # B1I: no frequency scaling


def test_an_all_zero_klobuchar_set_is_no_model(test_data: Path, tmp_path: Path) -> None:
    """A header whose ION ALPHA / BETA are zeros (a receiver that had not decoded them) gives
    the algorithm's night-time 5 ns at any hour: taken as a model, it left 2-9 m of GEONET
    0759's delay in the ranges at 09:30 local time, unflagged and uninflated (a user trial,
    2026-12-07). It is left out with a warning, so the satellites count as uncorrected."""
    src = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    lines = src.read_text().splitlines(keepends=True)
    zero = "  " + "".join(f"{0.0:12.4E}" for _ in range(4)) + " " * 10
    lines = [zero + ln[60:] if ln[60:].startswith(("ION ALPHA", "ION BETA")) else ln
             for ln in lines]  # fmt: skip
    nav = tmp_path / "zero.05n"
    nav.write_text("".join(lines))
    with pytest.warns(UserWarning, match="Klobuchar coefficients are all zero"):
        iono = BroadcastIono.from_rinex_nav(nav)
    assert iono.klobuchar("G") is None and "GPS" not in iono.sources
    # the file's real set is still read, and a zero set does not hide another file's
    assert BroadcastIono.from_rinex_nav(src).klobuchar("G") is not None
    with pytest.warns(UserWarning, match="all zero"):
        both = BroadcastIono.from_rinex_nav([nav, src])
    assert both.sources["GPS"].startswith(src.name)


BRUX = "gnss/rinex4_nav_BRUX_20260723_G04G05_LNAV_CNAV.rnx"


def test_cnav_group_delays_follow_is_gps_200(test_data: Path, tmp_path: Path) -> None:
    """A CNAV record's group delay (IS-GPS-200 30.3.3.3.1.1): L1 C/A TGD - ISC_L1CA, L2C
    TGD - ISC_L2C, P(Y) as LNAV; L5 and L1C are not given (the satellite is left out)."""
    tgd, l1ca, l2c = -4.656612873077e-09, -2.037268131971e-10, 3.317836672068e-09  # G04 CNAV
    assert cnav_group_delay_s("C1C", tgd, l1ca, l2c) == tgd - l1ca
    assert cnav_group_delay_s("C1", tgd, l1ca, l2c) == tgd - l1ca  # RINEX 2 C/A
    assert cnav_group_delay_s("C2L", tgd, l1ca, l2c) == tgd - l2c
    assert cnav_group_delay_s("C1W", tgd, l1ca, l2c) == tgd
    assert cnav_group_delay_s("P1", tgd, l1ca, l2c) == tgd
    assert cnav_group_delay_s("C2W", tgd, l1ca, l2c) == pytest.approx((77 / 60) ** 2 * tgd)
    for code in ("C5Q", "C1L", "C1X"):
        assert np.isnan(cnav_group_delay_s(code, tgd, l1ca, l2c)), code
    assert np.isnan(cnav_group_delay_s("C1C", tgd, np.nan, l2c))
    # through the range model: a file whose G04 and G05 have CNAV records only
    lines = (test_data / BRUX).read_text().splitlines()
    keep, drop = [], False
    for line in lines:
        drop = line.endswith("LNAV") if line.startswith(">") else drop
        if not drop:
            keep.append(line)
    (tmp_path / "cnav.rnx").write_text("\n".join(keep) + "\n")
    t = calendar_to_gps_s(2026, 7, 23, 1, 30, 0)
    pr = np.full(3, 2.2e7)
    st = RangeModel.from_rinex_nav(tmp_path / "cnav.rnx").states(
        t, ["G04", "G05", "G04"], pr, ["C1C", "C2L", "C5Q"]
    )
    g05_tgd, g05_l2c = -1.071020960808e-08, 5.733454599977e-09
    np.testing.assert_allclose(st.group_delay_m[:2], C * np.array([tgd - l1ca, g05_tgd - g05_l2c]))
    assert list(st.reason[:2]) == ["", ""] and "no broadcast group delay" in st.reason[2]
    # with LNAV records too, LNAV (and its TGD) is used
    both = RangeModel.from_rinex_nav(test_data / BRUX).states(t, ["G04"], pr[:1], "C1C")
    assert both.group_delay_m[0] == C * tgd


def test_a_record_trusted_at_transmission_but_not_half_a_second_later_gives_a_range(model):
    """A user trial (n8): NYA1 E33 at 15:30:00 and E02 at 17:40:00 left out as "not usable"
    with no reason: the record was trusted at transmission, not 0.5 s later, and the central
    difference of the velocity (relativistic term) came out NaN."""
    end = 796449600.0  # G01's record of this file is trusted up to here (2005-04-02 04:00)
    _, _, st = model.ephemeris.evaluate(np.array([end - 0.3, end + 0.3]), ["G01"])
    assert list(st.reason[:, 0]) == [0, 2]  # the premise: the record's validity ends there
    pr = 2.2e7
    edge = model.states(end - 0.2 + pr / C, ["G01"], [pr], "C1C")
    inside = model.states(end - 1.5 + pr / C, ["G01"], [pr], "C1C")  # central difference
    assert edge.reason[0] == "" and np.isfinite(edge.sat_clock_m[0])
    # the one-sided difference over 0.5 s: the relativistic term within a few centimetres
    assert edge.relativity_m[0] == pytest.approx(inside.relativity_m[0], abs=0.05)
    below = edge.pos_ecef_m[0] / np.linalg.norm(edge.pos_ecef_m[0]) * 6.371e6  # G01 overhead
    cr = model.correct(end - 0.2 + pr / C, ["G01"], [pr], below, "C1C")
    assert cr.usable[0] and np.isfinite(cr.corrected_m[0])
