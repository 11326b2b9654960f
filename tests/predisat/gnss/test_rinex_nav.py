"""RINEX navigation reader: values against hand-read records, and error reporting."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from predisat.gnss.rinex_nav import RinexError, read_rinex_nav

GPS_DAY_S = 86400.0
WEEK_S = 604800.0


def test_rinex2_gps_record_matches_hand_read(test_data: Path) -> None:
    nav = read_rinex_nav(test_data / "gnss/brdc1820_G01G02G05.10n")
    k = nav.kepler
    assert sorted(set(k.sat.tolist())) == ["G01", "G02", "G05"]
    assert len(nav.glonass) == 0
    first = int(np.nonzero(k.sat == "G01")[0][0])
    # hand-read from line 9-16 of the file: " 1 10  7  1  0  0  0.0-0.136290676892D-03 ..."
    assert k.col("af0_s")[first] == pytest.approx(-0.136290676892e-03, rel=1e-12)
    assert k.col("crs_m")[first] == pytest.approx(-89.75)
    assert k.col("sqrt_a_sqrtm")[first] == pytest.approx(5154.80139732)
    assert k.col("health")[first] == 63.0
    # toe: week 1590 (line 14) and 345600 s of week (line 12)
    assert k.ref_gps_s[first] == 1590 * WEEK_S + 345600.0
    # toc 2010-07-01 00:00 GPST = Thursday of week 1590
    assert k.epoch_gps_s[first] == 1590 * WEEK_S + 4 * GPS_DAY_S
    assert k.source[first].endswith(":9")


def test_rinex2_glonass_record_utc_epoch(test_data: Path) -> None:
    nav = read_rinex_nav(test_data / "gnss/brdc0910_R02R08.09g")
    g = nav.glonass
    assert len(nav.kepler) == 0
    i = int(np.nonzero(g.sat == "R02")[0][0])
    # " 2 09  4  1  0 15  0.0" is UTC; GPST-UTC was 15 s in 2009 (header LEAP SECONDS 15)
    assert nav.leap_seconds == 15
    expected = 1525 * WEEK_S + 3 * GPS_DAY_S + 15 * 60.0 + 15.0  # 2009-04-01 is a Wednesday
    assert g.epoch_gps_s[i] == pytest.approx(expected)
    assert g.col("x_km")[i] == pytest.approx(0.936473925781e04)
    assert g.col("freq_num")[i] == 1.0
    assert g.col("minus_tau_n_s")[i] == pytest.approx(0.206762924790e-04)


def test_rinex3_mixed_all_systems(test_data: Path) -> None:
    nav = read_rinex_nav(test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx")
    assert nav.version == pytest.approx(3.04)
    systems = {s[0] for s in nav.kepler.sat.tolist()}
    assert systems == {"G", "E", "C", "J", "I"}
    assert set(nav.glonass.sat.tolist()) == {"R01", "R02"}
    assert nav.skipped == {"S": 6}
    k = nav.kepler
    # line 175: "C01 2023 03 14 00 00 00 9.046400664374e-04" in BDT = GPST - 14 s
    i = int(np.nonzero(k.sat == "C01")[0][0])
    assert k.col("af0_s")[i] == pytest.approx(9.046400664374e-04)
    e = 2253 * WEEK_S + 2 * GPS_DAY_S  # 2023-03-14 is a Tuesday of GPS week 2253
    assert k.epoch_gps_s[i] == pytest.approx(e + 14.0)
    j = int(np.nonzero(k.sat == "E01")[0][0])
    assert k.epoch_gps_s[j] == pytest.approx(e)


@pytest.mark.shared
def test_rinex212_qzss_prefixed_prn(shared_data: Path) -> None:
    nav = read_rinex_nav(shared_data / "gnss/rtklib/brdc3050.12q")
    assert set(nav.kepler.sat.tolist()) == {"J01"}
    assert nav.kepler.col("sqrt_a_sqrtm")[0] == pytest.approx(6.493972862244e03)


def test_fortran_three_digit_exponent(tmp_path: Path, test_data: Path) -> None:
    text = (test_data / "gnss/brdc1820_G01G02G05.10n").read_text().splitlines()
    # RINEX 2 writers drop the 'D' for 3-digit exponents (seen in brdc3050.12n)
    text[15] = text[15][:41] + " 0.499063314480-269"
    p = tmp_path / "odd.10n"
    p.write_text("\n".join(text) + "\n")
    nav = read_rinex_nav(p)
    assert nav.kepler.col("spare29")[0] == pytest.approx(0.499063314480e-269)


def test_gzip_is_read(tmp_path: Path, test_data: Path) -> None:
    src = test_data / "gnss/brdc0910_R02R08.09g"
    p = tmp_path / "x.09g.gz"
    p.write_bytes(gzip.compress(src.read_bytes()))
    assert len(read_rinex_nav(p).glonass) == len(read_rinex_nav(src).glonass)


def _write(tmp_path: Path, lines: list[str]) -> Path:
    p = tmp_path / "bad.10n"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_truncated_file_names_file_and_line(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/brdc1820_G01G02G05.10n").read_text().splitlines()
    p = _write(tmp_path, lines[:-3])  # last record loses 3 of its 8 lines
    with pytest.raises(RinexError) as exc:
        read_rinex_nav(p)
    msg = str(exc.value)
    assert "bad.10n" in msg
    assert f"line {len(lines) - 7}" in msg
    assert "truncated" in msg and "download it again" in msg


def test_line_cut_inside_field(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/brdc1820_G01G02G05.10n").read_text().splitlines()
    lines[10] = lines[10][:50]
    with pytest.raises(RinexError, match=r"line 11: .*cut short.*download the file again"):
        read_rinex_nav(_write(tmp_path, lines))


def test_bad_number_names_column(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/brdc1820_G01G02G05.10n").read_text().splitlines()
    lines[11] = lines[11][:22] + "   0.1x9260351870D+01"[-19:] + lines[11][41:]
    with pytest.raises(RinexError, match=r"line 12: column 23: .* is not a number: .*download"):
        read_rinex_nav(_write(tmp_path, lines))


def test_missing_end_of_header_and_wrong_type(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/brdc1820_G01G02G05.10n").read_text().splitlines()
    head = [ln for ln in lines[:8] if "END OF HEADER" not in ln]
    with pytest.raises(RinexError, match="END OF HEADER"):
        read_rinex_nav(_write(tmp_path, head))
    obs = ["     2.11           OBSERVATION DATA    G (GPS)             RINEX VERSION / TYPE"]
    with pytest.raises(RinexError, match="line 1: file type 'O'"):
        read_rinex_nav(_write(tmp_path, obs))
    with pytest.raises(RinexError, match="no such file"):
        read_rinex_nav(tmp_path / "absent.10n")


@pytest.mark.shared
def test_every_shared_nav_file_reads(shared_data: Path) -> None:
    gnss = shared_data / "gnss"
    files = sorted(gnss.glob("rtklib/*.[0-9][0-9][ngq]")) + sorted(gnss.glob("*/*nav*.rnx"))
    files.append(gnss / "georust_rinex/ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    for f in files:
        nav = read_rinex_nav(f)
        assert len(nav.kepler) + len(nav.glonass) > 0, f
    big = read_rinex_nav(files[-1])
    # counts from the file's own header statistics (B_SUM lines)
    assert len(big.glonass) == 510
    assert big.skipped["S"] == 2130
    by_sys = {s: int(np.sum(big.kepler.sat.astype("<U1") == s)) for s in "GECJ"}
    assert by_sys == {"G": 257, "E": 1602, "C": 357, "J": 15}


NAV4 = "gnss/KMS300DNK_R_20221591000_01H_MN.rnx.gz"


def _v4_text(test_data: Path) -> list[str]:
    return gzip.decompress((test_data / NAV4).read_bytes()).decode().splitlines()


def test_rinex4_legacy_records_and_counts(test_data: Path) -> None:
    """KMS3 (sbf2rin, RINEX 4.00): every '> EPH' record of a legacy message is read, the others
    are counted; the counts come from the file's own '>' lines, values from hand-read lines."""
    text = _v4_text(test_data)
    heads = [ln.split() for ln in text if ln.startswith("> ")]
    n = {(h[1], h[2][0], h[3]): 0 for h in heads}
    for h in heads:
        n[(h[1], h[2][0], h[3])] += 1
    nav = read_rinex_nav(test_data / NAV4)
    assert nav.version == 4.0 and nav.leap_seconds == 18
    kep = nav.kepler.sat.astype("<U1")
    assert int(np.sum(kep == "G")) == n[("EPH", "G", "LNAV")]
    assert int(np.sum(kep == "J")) == n.get(("EPH", "J", "LNAV"), 0)
    assert int(np.sum(kep == "E")) == n[("EPH", "E", "INAV")] + n[("EPH", "E", "FNAV")]
    assert int(np.sum(kep == "C")) == n[("EPH", "C", "D1")] + n[("EPH", "C", "D2")]
    assert len(nav.glonass) == n[("EPH", "R", "FDMA")]
    assert nav.skipped["S"] == n[("EPH", "S", "SBAS")]
    assert nav.skipped["STO E IFNV"] == n[("STO", "E", "IFNV")]
    # "> EPH G02 LNAV" / "G02 2022 06 08 10 00 00-6.528543308377E-04 3.410605131648E-13 ..."
    i = int(np.nonzero(nav.kepler.sat == "G02")[0][0])
    line = next(k for k, t in enumerate(text) if t.startswith("G02 2022 06 08 10 00 00"))
    assert nav.kepler.source[i] == f"{NAV4[5:]}:{line + 1}"
    assert nav.kepler.col("af0_s")[i] == -6.528543308377e-04
    assert nav.kepler.col("sqrt_a_sqrtm")[i] == 5.153679471970e03
    assert nav.kepler.col("toe_sow_s")[i] == 2.952e05
    # Galileo I/NAV and F/NAV of E01 keep their data-source words (517, 258)
    e01 = nav.kepler.col("aux20")[nav.kepler.sat == "E01"]
    assert {517.0, 258.0} <= set(e01.tolist())
    # GLONASS FDMA: five lines, channel of R03 is 5 (its record and the obs header agree)
    r03 = nav.glonass.col("freq_num")[nav.glonass.sat == "R03"]
    assert set(r03.tolist()) == {5.0}


def test_rinex4_ionosphere_messages(test_data: Path) -> None:
    nav = read_rinex_nav(test_data / NAV4)
    by = {(m.system, m.message): m for m in nav.iono}
    assert set(by) == {("G", "LNAV"), ("E", "IFNV"), ("C", "D1D2")}
    # "> ION G29 LNAV" / "    2022 06 08 09 59 48 1.024454832077E-08 ..." (hand-read)
    g = by[("G", "LNAV")]
    assert g.sat == "G29" and g.epoch_gps_s == 2213 * WEEK_S + 3 * GPS_DAY_S + 35988.0
    np.testing.assert_array_equal(
        g.coefficients,
        [1.024454832077e-08, 2.235174179077e-08, -5.960464477539e-08, -1.192092895508e-07,
         9.6256e04, 1.31072e05, -6.5536e04, -5.89824e05],
    )  # fmt: skip
    np.testing.assert_array_equal(
        by[("E", "IFNV")].coefficients, [7.85e01, 5.390625e-01, 2.713012695312e-02]
    )
    c = by[("C", "D1D2")]  # BDT 09:59:50 = GPST 10:00:04
    assert c.epoch_gps_s == 2213 * WEEK_S + 3 * GPS_DAY_S + 36004.0


def test_rinex4_same_orbits_as_its_rinex3_form(test_data: Path, tmp_path: Path) -> None:
    """The RINEX 4 legacy records are RINEX 3.05 records behind a '> EPH' line: rewritten as a
    3.05 file (the RINEX 3 path of the reader, tested against SP3), the positions are equal."""
    from predisat.gnss.ephemeris import Ephemeris

    text = _v4_text(test_data)
    out, k = [], 0
    legacy = {"LNAV", "INAV", "FNAV", "D1", "D2", "FDMA"}
    out.append("     3.05" + text[0][9:])
    k = 1
    while k < len(text):
        t = text[k]
        if t.startswith("> "):
            j = k + 1
            while j < len(text) and not text[j].startswith(">"):
                j += 1
            if t.split()[1] == "EPH" and t.split()[3] in legacy:
                out += text[k + 1 : j]
            k = j
        else:
            out.append(t)
            k += 1
    v3 = tmp_path / "KMS3_v305.rnx"
    v3.write_text("\n".join(out) + "\n")
    from predisat.gnss.ephemeris import ValidityPolicy

    # an hour's file: most satellites hold one record, which only measurements can check (the
    # default leaves them UNCHECKED); the readers are compared on every record
    trusting = ValidityPolicy(trust_unchecked=True)
    e4 = Ephemeris.from_rinex(test_data / NAV4, trusting)
    e3 = Ephemeris.from_rinex(v3, trusting)
    sats = sorted(set(e4.kepler.sat.tolist()) | set(e4.glonass.sat.tolist()))
    t = 2213 * WEEK_S + 3 * GPS_DAY_S + 36000.0 + np.arange(0.0, 3600.0, 300.0)
    p4, c4, _ = e4.evaluate(t, sats)
    p3, c3, _ = e3.evaluate(t, sats)
    assert np.isfinite(p4).any(axis=(0, 2)).sum() >= 60
    np.testing.assert_array_equal(p4, p3)
    np.testing.assert_array_equal(c4, c3)


def test_rinex4_damage_names_file_line_and_fix(test_data: Path, tmp_path: Path) -> None:
    text = _v4_text(test_data)
    g02 = next(k for k, t in enumerate(text) if t.startswith("G02 2022"))
    cut = [*text[: g02 + 3], *text[g02 + 4 :]]  # one orbit line missing
    with pytest.raises(RinexError, match=rf"line {g02 + 1}: record of G02 has 7 of 8 lines"):
        read_rinex_nav(_write(tmp_path, cut))
    bad = list(text)
    bad[g02 - 1] = "> XYZ G02 LNAV"
    with pytest.raises(RinexError, match=rf"line {g02}: unknown record line"):
        read_rinex_nav(_write(tmp_path, bad))
    ion = next(k for k, t in enumerate(text) if t.startswith("> ION G29"))
    short = [*text[: ion + 3], *text[ion + 4 :]]  # the beta3 line missing
    with pytest.raises(RinexError, match=rf"line {ion + 1}: ION LNAV record of G29 has 7 of 8"):
        read_rinex_nav(_write(tmp_path, short))
    v5 = ["     4.05" + text[0][9:], *text[1:]]
    with pytest.raises(RinexError, match=r"line 1: RINEX 4\.05 navigation is not supported"):
        read_rinex_nav(_write(tmp_path, v5))


def test_rinex4_modernised_messages_counted_with_a_warning(
    test_data: Path, tmp_path: Path
) -> None:
    """CNV1/CNV2 ephemerides (not in the KMS3 file: '> EPH G02 CNV2' and '> EPH C19 CNV2'
    blocks are added) are skipped, counted and told: their orbit model is not implemented
    (GPS/QZSS CNAV is read: test_cnav.py)."""
    text = _v4_text(test_data)
    g02 = next(k for k, t in enumerate(text) if t.startswith("> EPH G02 LNAV"))
    cnav = ["> EPH G02 CNV2", *(t for t in text[g02 + 1 : g02 + 9]), "     0.0"]
    cnv2 = ["> EPH C19 CNV2", *text[g02 + 1 : g02 + 9], "     0.0", "     0.0"]
    path = _write(tmp_path, [*text[:g02], *cnav, *cnv2, *text[g02:]])
    with pytest.warns(UserWarning, match=r"2 ephemeris record\(s\).*C CNV2 1, G CNV2 1.*not impl"):
        nav = read_rinex_nav(path)
    assert nav.skipped["G CNV2"] == 1 and nav.skipped["C CNV2"] == 1
    ref = read_rinex_nav(test_data / NAV4)
    np.testing.assert_array_equal(nav.kepler.values, ref.kepler.values)


def _glonass_with(test_data: Path, tmp_path: Path, year2: str, leap: str) -> Path:
    """The 2009 GLONASS excerpt with its records moved to year ``20<year2>`` and LEAP SECONDS
    set to ``leap``."""
    out = []
    body = False
    for line in (test_data / "gnss/brdc0910_R02R08.09g").read_text().splitlines():
        if line[60:].strip() == "LEAP SECONDS":
            line = f"{leap:>6}" + line[6:]
        elif body and line[:2].strip():
            line = line[:3] + year2 + line[5:]
        body = body or line[60:].strip() == "END OF HEADER"
        out.append(line)
    p = tmp_path / f"brdc0910.{year2}g"
    p.write_text("\n".join(out) + "\n")
    return p


def test_a_wrong_leap_header_within_the_table_warns_and_the_table_is_used(
    test_data: Path, tmp_path: Path
) -> None:
    good = read_rinex_nav(_glonass_with(test_data, tmp_path, "09", "15"))
    p = _glonass_with(test_data, tmp_path, "09", "14")
    with pytest.warns(UserWarning, match=rf"{p.name}:6: LEAP SECONDS gives GPST - UTC = 14 s.*"
                      r"gives 15 s.*the table is used"):  # fmt: skip
        nav = read_rinex_nav(p)
    np.testing.assert_array_equal(nav.glonass.epoch_gps_s, good.glonass.epoch_gps_s)


def test_a_leap_second_the_table_cannot_know_stops_the_read(
    test_data: Path, tmp_path: Path
) -> None:
    """Past the table's certain span a header one second ahead means a leap second announced
    later: GLONASS epochs would be a second off (about 4 km along the orbit)."""
    n = len(read_rinex_nav(test_data / "gnss/brdc0910_R02R08.09g").glonass)
    assert len(read_rinex_nav(_glonass_with(test_data, tmp_path, "27", "18")).glonass) == n
    with pytest.raises(RinexError, match=r"line 6: LEAP SECONDS gives GPST - UTC = 19 s.*gives "
                       r"18 s.*Add it to LEAP_SECONDS"):  # fmt: skip
        read_rinex_nav(_glonass_with(test_data, tmp_path, "27", "19"))


def test_a_leap_header_counted_from_bdt_is_converted(test_data: Path, tmp_path: Path) -> None:
    lines = (test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx").read_text()
    lines = lines.splitlines()
    k = next(i for i, s in enumerate(lines) if s[60:].strip() == "LEAP SECONDS")
    lines[k] = f"{4:6d}{4:6d}{2253 - 1356:6d}{7:6d}BDS".ljust(60) + "LEAP SECONDS"
    p = tmp_path / "bds_leap.rnx"
    p.write_text("\n".join(lines) + "\n")
    assert read_rinex_nav(p).leap_seconds == 18  # BDT - UTC 4 s, GPST - BDT 14 s
