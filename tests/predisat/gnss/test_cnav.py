"""GPS CNAV ephemerides of RINEX 4 (IS-GPS-200 30.3.3.1) against the same satellites' LNAV.

The excerpt (IGS BRUX, 2026-07-23, tests/data/gnss/SOURCE.md) holds G04 and G05 both as LNAV
and as CNAV records: two broadcasts of the same orbit and clock, uploaded separately, whose
positions agree within decimetres where both are fitted; an orbit ignoring CNAV's semi-major
axis rate or mean-motion rate is metres off.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predisat.gnss.ephemeris import Ephemeris, Reason, ValidityPolicy
from predisat.gnss.orbits import kepler_state
from predisat.gnss.rinex_nav import NavRecords, RinexError, read_rinex_nav
from predisat.gnss.timescale import calendar_to_gps_s

BRUX = "gnss/rinex4_nav_BRUX_20260723_G04G05_LNAV_CNAV.rnx"


@pytest.fixture(scope="module")
def kep(test_data: Path) -> NavRecords:
    return read_rinex_nav(test_data / BRUX).kepler


def _row(kep: NavRecords, line: int) -> int:
    return int(np.flatnonzero([s.endswith(f":{line}") for s in kep.source])[0])


def test_cnav_record_fields_are_the_printed_values(test_data: Path, kep: NavRecords) -> None:
    nav = read_rinex_nav(test_data / BRUX)
    assert nav.skipped == {}  # every record read, none skipped
    assert len(kep) == 6 and int(np.sum(kep.col("cnav") == 1.0)) == 4
    r = kep.values[_row(kep, 24)]  # "G04 2026 07 23 01 30 00", the first G04 CNAV record
    f = kep.fields.index
    printed = {
        "af0_s": 6.285309791565e-05, "af1_sps": 6.785683126509e-13, "af2_sps2": 0.0,
        "adot_mps": 6.146430969238e-04, "crs_m": -3.851171875000e01,
        "delta_n_radps": 4.214104105780e-09, "m0_rad": -1.510318025048e00,
        "cuc_rad": -2.031214535236e-06, "e": 3.831180627458e-03, "cus_rad": 8.182600140572e-06,
        "sqrt_a_sqrtm": 5.153676388784e03, "top_sow_s": 2.979e05, "cic_rad": 4.936009645462e-08,
        "omega0_rad": 2.688795239709e00, "cis_rad": -2.235174179077e-08,
        "i0_rad": 9.724859845162e-01, "crc_m": 2.278085937500e02,
        "omega_rad": -2.901340507426e00, "omega_dot_radps": -7.762766871021e-09,
        "idot_radps": 4.664480008601e-10, "delta_n_dot_radps2": -1.842030550511e-14,
        "urai_ned0": -2.0, "urai_ned1": 3.0, "urai_ed": -2.0, "health": 1.0,
        "tgd_cnav_s": -4.656612873077e-09, "urai_ned2": 7.0,
        "isc_l1ca_s": -2.037268131971e-10, "isc_l2c_s": 3.317836672068e-09,
        "isc_l5i5_s": -1.426087692380e-09, "isc_l5q5_s": -1.396983861923e-09,
        "transmit_sow_s": 3.471300e05, "wn_op": 2428.0,
        "toe_sow_s": 4 * 86400.0 + 1.5 * 3600.0,  # toe = toc, Thursday 01:30
    }  # fmt: skip
    for name, value in printed.items():
        assert r[f(name)] == value, name
    # toc and toe are the record's epoch; the legacy-only columns are left empty
    assert kep.epoch_gps_s[_row(kep, 24)] == calendar_to_gps_s(2026, 7, 23, 1, 30, 0)
    assert kep.ref_gps_s[_row(kep, 24)] == kep.epoch_gps_s[_row(kep, 24)]
    for name in ("iode", "tgd_s", "aux26", "accuracy_m", "fit", "week"):
        assert np.isnan(r[f(name)]), name
    # the LNAV records carry no CNAV value
    lnav = kep.values[_row(kep, 6)]
    assert np.all(np.isnan(lnav[f("cnav") :]))


def _without(kep: NavRecords, row: int, name: str) -> NavRecords:
    v = kep.values.copy()
    v[row, kep.fields.index(name)] = 0.0
    return NavRecords(kep.kind, kep.sat, kep.epoch_gps_s, kep.ref_gps_s, v, kep.fields, kep.source)


@pytest.mark.parametrize(("sat", "lnav_line", "cnav_line"), [("G04", 6, 24), ("G05", 15, 34)])
def test_cnav_orbit_and_clock_agree_with_lnav(
    kep: NavRecords, sat: str, lnav_line: int, cnav_line: int
) -> None:
    il, ic = _row(kep, lnav_line), _row(kep, cnav_line)
    assert kep.sat[il] == kep.sat[ic] == sat
    # every 5 min over +-1 h around the CNAV record's toe (within the LNAV record's fit too)
    t = kep.ref_gps_s[ic] + np.arange(-3600.0, 3601.0, 300.0)
    p_l, c_l = kepler_state(kep, np.full(t.size, il), t)
    p_c, c_c = kepler_state(kep, np.full(t.size, ic), t)
    d = np.linalg.norm(p_l - p_c, axis=1)
    assert d.max() < 0.6  # measured 0.49 m (G04), 0.41 m (G05)
    assert np.abs(c_l - c_c).max() < 0.3e-9  # measured 0.18 ns, 0.11 ns (5 cm, 3 cm)
    # the CNAV terms matter: without the mean-motion rate G04 and G05 are 2.3-3.6 m off, and
    # without A-dot G04 (Adot 0.6 mm/s; G05's is 0.1 mm/s) 2.3 m off
    p_nodn, _ = kepler_state(_without(kep, ic, "delta_n_dot_radps2"), np.full(t.size, ic), t)
    assert np.linalg.norm(p_l - p_nodn, axis=1).max() > 2.0
    if sat == "G04":
        p_noa, _ = kepler_state(_without(kep, ic, "adot_mps"), np.full(t.size, ic), t)
        assert np.linalg.norm(p_l - p_noa, axis=1).max() > 2.0


def test_lnav_rows_unchanged_by_the_cnav_terms(kep: NavRecords) -> None:
    """The LNAV records' positions are those of the same records alone (no CNAV row present)."""
    lnav = np.flatnonzero(np.isnan(kep.col("cnav")))
    alone = kep.take(lnav)
    t = kep.ref_gps_s[lnav[0]] + np.arange(-7200.0, 7201.0, 600.0)
    for k, row in enumerate(lnav):
        p1, c1 = kepler_state(kep, np.full(t.size, row), t)
        p2, c2 = kepler_state(alone, np.full(t.size, k), t)
        np.testing.assert_array_equal(p1, p2)
        np.testing.assert_array_equal(c1, c2)


def _cnav_only(test_data: Path, tmp_path: Path) -> Path:
    lines = (test_data / BRUX).read_text().splitlines()
    keep, drop = [], False
    for line in lines:
        if line.startswith(">"):
            drop = line.endswith("LNAV")
        if not drop:
            keep.append(line)
    path = tmp_path / "brux_cnav_only.rnx"
    path.write_text("\n".join(keep) + "\n")
    return path


def test_a_satellite_with_cnav_records_only_gets_an_orbit(
    test_data: Path, tmp_path: Path, kep: NavRecords
) -> None:
    eph = Ephemeris.from_rinex(_cnav_only(test_data, tmp_path))
    t0 = calendar_to_gps_s(2026, 7, 23, 1, 30, 0)
    t = t0 + np.arange(-3600.0, 3601.0, 600.0)
    pos, clk, st = eph.evaluate(t, ["G04", "G05"])
    # the two CNAV records of each satellite (2 h apart) check each other
    assert np.all(st.reason == Reason.OK), st.report()
    assert st.record[0, 0].endswith(":6") and st.record[0, 1].endswith(":16")
    il = _row(kep, 6)  # G04's LNAV record, not in this file
    p_l, _ = kepler_state(kep, np.full(t.size, il), t)
    assert np.linalg.norm(pos[:, 0] - p_l, axis=1).max() < 0.6
    assert np.all(np.isfinite(clk))
    # a CNAV record is used up to 1.5 h from its toe: 00:00 is beyond (LNAV's would reach)
    early = eph.status(np.array([t0 - 5500.0]), ["G04"])
    assert early.reason[0, 0] == Reason.OUTSIDE_VALIDITY


def test_lnav_stays_the_default_and_cnav_is_an_option(test_data: Path, kep: NavRecords) -> None:
    t = calendar_to_gps_s(2026, 7, 23, 1, 30, 0) + np.arange(-1800.0, 1801.0, 600.0)
    pol = ValidityPolicy(trust_unchecked=True)
    both = Ephemeris.from_rinex(test_data / BRUX, pol)
    _, _, st = both.evaluate(t, ["G04", "G05"])
    assert set(st.record[:, 0]) == {f"{Path(BRUX).name}:6"}  # G04's LNAV record throughout
    assert set(st.record[:, 1]) == {f"{Path(BRUX).name}:15"}
    pref = Ephemeris.from_rinex(test_data / BRUX, ValidityPolicy(cnav="prefer"))
    pos, _, st = pref.evaluate(t, ["G04"])
    assert set(st.record[:, 0]) == {f"{Path(BRUX).name}:24"} and np.all(st.valid)
    p_c, _ = kepler_state(kep, np.full(t.size, _row(kep, 24)), t)
    np.testing.assert_array_equal(pos[:, 0], p_c)
    never = Ephemeris.from_rinex(test_data / BRUX, ValidityPolicy(cnav="never"))
    assert set(never.status(t, ["G04"]).record[:, 0]) == {f"{Path(BRUX).name}:6"}
    with pytest.raises(ValueError, match="cnav must be"):
        ValidityPolicy(cnav="always")


def test_cnav_health_bits(test_data: Path, tmp_path: Path) -> None:
    """L1 or L2 flagged unhealthy distrusts the record; the L5 bit (set on every satellite
    while L5 is pre-operational, as in these records) does not."""
    lines = _cnav_only(test_data, tmp_path).read_text().splitlines()
    k = lines.index("> EPH G04 CNAV") + 7  # URAI_ED, health, TGD, URAI_NED2
    assert lines[k][23:42] == " 1.000000000000E+00"
    lines[k] = lines[k][:23] + " 3.000000000000E+00" + lines[k][42:]  # L2 and L5
    path = tmp_path / "l2_unhealthy.rnx"
    path.write_text("\n".join(lines) + "\n")
    t = np.array([calendar_to_gps_s(2026, 7, 23, 1, 30, 0)])
    st = Ephemeris.from_rinex(path).status(t, ["G04", "G05"])
    assert st.reason[0, 0] == Reason.UNHEALTHY and st.reason[0, 1] == Reason.OK


@pytest.mark.parametrize("message", ["LNAV", "CNAV"])
def test_damaged_satellite_on_the_record_line_names_the_line(
    test_data: Path, tmp_path: Path, message: str
) -> None:
    """'> EPH G0x ...' was a bare ValueError from int() (a fuzz run, 2026-12-07)."""
    text = (test_data / BRUX).read_text().replace(f"> EPH G05 {message}", f"> EPH G0x {message}")
    path = tmp_path / "damaged.rnx"
    path.write_text(text)
    with pytest.raises(RinexError, match=r"damaged\.rnx, line \d+: unreadable satellite 'G0x'"):
        read_rinex_nav(path)
