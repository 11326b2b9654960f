"""Ephemeris facade: trust decisions, reasons, shapes, and broadcast vs SP3 per constellation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predisat.gnss.ephemeris import Ephemeris, Reason, ValidityPolicy
from predisat.gnss.timescale import calendar_to_gps_s

DAY0 = calendar_to_gps_s(2010, 7, 1)


@pytest.fixture(scope="module")
def brdc(test_data: Path) -> Ephemeris:
    return Ephemeris.from_rinex(test_data / "gnss/brdc1820_G01G02G05.10n")


def test_shapes_and_nan_where_not_trusted(brdc: Ephemeris) -> None:
    t = DAY0 + np.arange(0.0, 3600.0, 600.0)
    pos, clk, st = brdc.evaluate(t, ["G02", "G01", "G77"])
    assert pos.shape == (6, 3, 3) and clk.shape == (6, 3)
    assert np.all(np.isfinite(pos[:, 0])) and np.all(st.valid[:, 0])
    # G01 is flagged unhealthy (health 63 on line 15) and G77 does not exist
    assert np.all(st.reason[:, 1] == Reason.UNHEALTHY)
    assert np.all(st.reason[:, 2] == Reason.NO_DATA)
    assert np.all(np.isnan(pos[:, 1:])) and np.all(np.isnan(clk[:, 1:]))
    np.testing.assert_array_equal(brdc.valid(t, ["G02", "G01", "G77"]), st.valid)


def test_corrupt_healthy_record_is_not_trusted(brdc: Ephemeris) -> None:
    # G01's record at 06:00 (line 105) says healthy but its orbit is another satellite's
    t = np.array([DAY0 + 6 * 3600.0])
    st = brdc.status(t, ["G01"])
    assert st.reason[0, 0] == Reason.INCONSISTENT
    assert st.record[0, 0].endswith(":105")
    loose = Ephemeris.from_rinex(brdc.sources, ValidityPolicy(consistency_m=None))
    assert loose.status(t, ["G01"]).reason[0, 0] == Reason.OK


def test_validity_window(brdc: Ephemeris) -> None:
    # the file's last G02 record (line 313) has toe 424784 s of week 1590, valid +-2 h
    last = 1590 * 604800.0 + 424784.0
    t = np.array([last + 7199.0, last + 7201.0, DAY0 - 7201.0])
    st = brdc.status(t, ["G02"])
    assert st.reason[:, 0].tolist() == [Reason.OK, Reason.OUTSIDE_VALIDITY, Reason.OUTSIDE_VALIDITY]
    tight = Ephemeris.from_rinex(brdc.sources, ValidityPolicy(max_age_s={"G": 600.0}))
    st2 = tight.status(np.array([DAY0 + 3600.0]), ["G02"])  # records every 2 h
    assert st2.reason[0, 0] == Reason.OUTSIDE_VALIDITY


def test_report_lists_every_distrusted_run(brdc: Ephemeris) -> None:
    t = DAY0 + np.arange(0.0, 86400.0, 900.0)
    rep = brdc.status(t, ["G01", "G02", "G05"]).report()
    assert set(rep["sat"]) == {"G01"}
    assert set(rep["reason"]) == {"UNHEALTHY", "INCONSISTENT"}
    assert rep["n_epochs"].sum() == len(t)
    assert all(":" in r for r in rep["record"])


def test_glonass_window_and_sp3_facade(test_data: Path) -> None:
    glo = Ephemeris.from_rinex(test_data / "gnss/brdc0910_R02R08.09g")
    prec = Ephemeris.from_sp3(test_data / "gnss/igl15253_R02R08.sp3")
    assert prec.satellites == ("R02", "R08")
    t = prec.sp3.epochs_gps_s if prec.sp3 is not None else None
    pb, _, st = glo.evaluate(t, ["R02", "R08"])
    pp = prec.position_ecef(t, ["R02", "R08"])
    ok = st.valid
    assert ok.sum() >= 50
    err = np.linalg.norm(pb - pp, axis=-1)[ok]
    assert np.sqrt(np.mean(err**2)) <= 5.0
    # records are at hh:15 and hh:45 UTC: within +-15 min of every quarter hour except
    # outside the excerpt's 00:15-06:45 span
    assert np.all(st.reason[~ok] == Reason.OUTSIDE_VALIDITY)
    outside = prec.status(np.array([t[0] - 1.0]), ["R02"])
    assert outside.reason[0, 0] == Reason.OUTSIDE_VALIDITY


def test_multignss_2023_rms_per_constellation(test_data: Path) -> None:
    brdc = Ephemeris.from_rinex(test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx")
    prec = Ephemeris.from_sp3(test_data / "gnss/sp3_COD0OPSRAP_20230730000_01D_05M_ORB.SP3")
    assert prec.sp3 is not None
    t = prec.sp3.epochs_gps_s
    for sats, limit in ((["G01", "G02"], 3.0), (["E01", "E02"], 3.0), (["R01", "R02"], 5.0)):
        pb, _, st = brdc.evaluate(t, sats)
        pp = prec.position_ecef(t, sats)
        err = np.linalg.norm(pb - pp, axis=-1)[st.valid]
        assert err.size >= 4, sats
        assert np.sqrt(np.mean(err**2)) <= limit, sats


def test_galileo_inav_preferred(test_data: Path) -> None:
    # BKG's merged file carries I/NAV (data source 517) and F/NAV (258) records
    path = test_data / "gnss/rinex_nav_BRDC00WRD_S_20230730000_01D_MN_E01E02.rnx"
    inav = Ephemeris.from_rinex(path)
    fnav = Ephemeris.from_rinex(path, ValidityPolicy(galileo_message="fnav"))
    t = np.array([calendar_to_gps_s(2023, 3, 14, 0, 20)])
    rec_i = inav.status(t, ["E01"]).record[0, 0]
    rec_f = fnav.status(t, ["E01"]).record[0, 0]
    assert rec_i != rec_f
    assert inav.kepler is not None
    src = dict(zip(inav.kepler.source, inav.kepler.col("aux20"), strict=True))
    assert int(src[rec_i]) & 0b101 and int(src[rec_f]) & 0b010


def test_azel_shapes(brdc: Ephemeris) -> None:
    t = DAY0 + np.arange(0.0, 1800.0, 600.0)
    az, el = brdc.azel(t, [50.0, 51.0], [4.0, 5.0], 100.0, ["G02", "G05"])
    assert az.shape == (2, 3, 2) == el.shape
    assert np.all((az >= 0) & (az < 360)) and np.all(np.abs(el) <= 90)


@pytest.mark.shared
def test_full_day_speed_and_shared_pairs(shared_data: Path) -> None:
    g = shared_data / "gnss"
    eph = Ephemeris.from_rinex(g / "georust_rinex/ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    t = calendar_to_gps_s(2020, 6, 25) + np.arange(0.0, 86400.0, 30.0)
    kep = [s for s in eph.satellites if s[0] != "R"]
    pos = eph.position_ecef(t, kep)  # speed: scripts/bench_availability.py
    assert np.isfinite(pos[..., 0]).sum() > 1e5
    pairs = [
        (["rtklib/brdc1820.10n"], ["rtklib/igs15904.sp3"], {"G": 3.0}),
        (["rtklib/brdc0910.09g"], ["rtklib/igl15253.sp3"], {"R": 8.0}),
        (["gnss_lib_py/rinex_nav_brdc1180.21n"],
         ["gnss_lib_py/sp3_COD0MGXFIN_20211180000_01D_05M_ORB.SP3"], {"G": 3.0}),
    ]  # fmt: skip
    for navs, sp3s, limits in pairs:
        b = Ephemeris.from_rinex([g / n for n in navs])
        p = Ephemeris.from_sp3([g / s for s in sp3s])
        assert p.sp3 is not None
        sats = [s for s in p.satellites if s in b.satellites]
        pb, _, st = b.evaluate(p.sp3.epochs_gps_s, sats)
        pp = p.position_ecef(p.sp3.epochs_gps_s, sats)
        for system, limit in limits.items():
            cols = [j for j, s in enumerate(sats) if s[0] == system]
            err = np.linalg.norm(pb[:, cols] - pp[:, cols], axis=-1)[st.valid[:, cols]]
            # 2009 GLONASS: R03 broadcast was ~20 m off along-track; the others 3-6 m
            assert np.sqrt(np.mean(err**2)) <= limit, (navs, system)


def _records_at(src: Path, dst: Path, hours: set[int]) -> Path:
    """A copy of a RINEX 2 GPS navigation file keeping the records whose epoch is on the hour
    of ``hours`` (an hourly file, or two of them)."""
    lines = src.read_text().splitlines(keepends=True)
    head = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln) + 1
    out = lines[:head]
    for k in range(head, len(lines), 8):
        hour, minute = int(lines[k][12:15]), int(lines[k][15:18])
        if hour in hours and minute == 0:
            out += lines[k:k + 8]
    dst.write_text("".join(out))
    return dst


def test_a_record_nothing_can_check_is_not_trusted(test_data: Path, tmp_path: Path) -> None:
    """An hour's file holds one record per satellite: G01's healthy-flagged record of 06:00,
    another satellite's orbit, is then UNCHECKED, as are the honest ones; trusted only when
    asked (the locator, which checks ranges), and then it is thousands of kilometres from
    the precise orbit while the others are within metres."""
    src = test_data / "gnss/brdc1820_G01G02G05.10n"
    hourly = _records_at(src, tmp_path / "hour06.10n", {6})
    prec = Ephemeris.from_sp3(test_data / "gnss/igs15904_G01G02G05.sp3")
    t = DAY0 + 6 * 3600.0 + np.array([-1800.0, 0.0, 1800.0])
    sats = ["G01", "G02", "G05"]
    st = Ephemeris.from_rinex(hourly).status(t, sats)
    assert np.all(st.reason == Reason.UNCHECKED)
    trusting = Ephemeris.from_rinex(hourly, ValidityPolicy(trust_unchecked=True))
    pos, _, st2 = trusting.evaluate(t, sats)
    assert np.all(st2.reason == Reason.OK)
    err = np.linalg.norm(pos - prec.position_ecef(t, sats), axis=-1)
    assert np.all(err[:, 0] > 1e7) and np.all(err[:, 1:] < 10.0)
    # the check off: no record is called unchecked either
    off = Ephemeris.from_rinex(hourly, ValidityPolicy(consistency_m=None))
    assert np.all(off.status(t, sats).reason == Reason.OK)


def test_a_record_far_from_its_neighbours_is_compared_up_to_a_day(
    test_data: Path, tmp_path: Path
) -> None:
    """Records of 00:00 and 06:00 only: none within the other's reach (6 h apart), so each is
    compared with the other coarsely: G01's of 06:00 (another orbit) and its partner of 00:00
    are both distrusted, the evidence being contradictory; G02 and G05 pass, and agree with the
    precise orbit."""
    src = test_data / "gnss/brdc1820_G01G02G05.10n"
    two = _records_at(src, tmp_path / "hours00and06.10n", {0, 6})
    eph = Ephemeris.from_rinex(two)
    prec = Ephemeris.from_sp3(test_data / "gnss/igs15904_G01G02G05.sp3")
    t = DAY0 + 6 * 3600.0 + np.array([-1800.0, 0.0, 1800.0])
    pos, _, st = eph.evaluate(t, ["G01", "G02", "G05"])
    assert np.all(st.reason[:, 0] == Reason.INCONSISTENT)
    assert np.all(st.reason[:, 1:] == Reason.OK)
    err = np.linalg.norm(pos[:, 1:] - prec.position_ecef(t, ["G02", "G05"]), axis=-1)
    assert np.all(err < 10.0)
    t0 = DAY0 + np.array([0.0, 1800.0])
    st0 = eph.status(t0, ["G01", "G02"])
    assert np.all(st0.reason[:, 0] != Reason.OK) and np.all(st0.reason[:, 1] == Reason.OK)


def test_glonass_records_far_apart_are_compared_up_to_six_hours(
    test_data: Path, tmp_path: Path
) -> None:
    """Honest GLONASS records 20-22 h apart differ by up to 15 km (a review): a far comparison
    there would distrust them. Two of R02's records 5.5 h apart are compared and trusted; 6.5 h
    apart they are not compared: UNCHECKED, not INCONSISTENT."""
    src = test_data / "gnss/brdc0910_R02R08.09g"
    lines = src.read_text().splitlines(keepends=True)
    head = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln) + 1

    def keep(times: set[tuple[int, int]], name: str) -> Path:
        out = lines[:head]
        for k in range(head, len(lines), 4):
            f = lines[k].split()
            if int(f[0]) == 2 and (int(f[4]), int(f[5])) in times:
                out += lines[k:k + 4]
        (tmp_path / name).write_text("".join(out))
        return tmp_path / name

    t0 = calendar_to_gps_s(2009, 4, 1) + 15 * 60.0 + 15.0  # GPST at 00:15 UTC (15 leap s)
    near = Ephemeris.from_rinex(keep({(0, 15), (5, 45)}, "r02_near.09g"))
    assert near.status(np.array([t0]), ["R02"]).reason[0, 0] == Reason.OK
    far = Ephemeris.from_rinex(keep({(0, 15), (6, 45)}, "r02_far.09g"))
    assert far.status(np.array([t0]), ["R02"]).reason[0, 0] == Reason.UNCHECKED


@pytest.mark.parametrize(("health", "reason"), [(1, Reason.OK), (3, Reason.UNHEALTHY),
                                                (32, Reason.UNHEALTHY)])  # fmt: skip
def test_qzss_lowest_health_bit_is_a_signal_never_used(
    test_data: Path, tmp_path: Path, health: int, reason: Reason
) -> None:
    """QZSS LNAV health: the lowest bit is L1C/B (formerly LEX), not used here (IS-QZSS-PNT
    5.4.1); any other bit (L1 C/A is the highest) still makes the record unhealthy."""
    src = test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx"
    lines = src.read_text().splitlines(keepends=True)
    for i, line in enumerate(lines):
        if line.startswith("J02"):  # health: the 2nd field of the record's 7th line
            h = lines[i + 6]
            lines[i + 6] = h[:23] + f"{float(health):19.12e}" + h[42:]
    edited = tmp_path / "qzss_health.rnx"
    edited.write_text("".join(lines))
    t0 = calendar_to_gps_s(2023, 3, 14, 0, 30)
    assert Ephemeris.from_rinex(src).status(np.array([t0]), ["J02"]).reason[0, 0] == Reason.OK
    st = Ephemeris.from_rinex(edited).status(np.array([t0]), ["J02"])
    assert st.reason[0, 0] == reason
