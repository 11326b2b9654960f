"""RINEX observation reader: values against hand-read lines, events, and error reporting."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from locator.observations import Observations, RinexObsError, read_rinex_obs
from predisat.gnss.timescale import calendar_to_gps_s

OBS2 = "gnss_obs/07590920_10ep.05o"
SEPT = "gnss_obs/rinex_obs_z_tracking.rnx"
PIXEL = "gnss_obs/android_rinex_obs_pixel6_6ep.23o"
MIXED = "gnss_obs/rinex_obs_rinex_obs_mixed_types.20o"


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines(keepends=True)


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("".join(lines))
    return path


def test_rinex2_values_match_hand_read_lines(test_data: Path) -> None:
    obs = read_rinex_obs(test_data / OBS2)
    h = obs.header
    assert h.version == pytest.approx(2.10) and h.marker_name == "0759"
    assert h.receiver_type == "TRIMBLE 5700" and h.interval_s == 30.0
    assert h.obs_types["G"] == ("L1", "C1", "L2", "P2")
    np.testing.assert_allclose(
        h.approx_position_ecef_m, [-3976219.5082, 3382372.5671, 3652512.9849]
    )
    assert obs.problems == () and len(obs.gps_s) == 10
    # line 18: " 05  4  2  0  0  0.0000000  0  8G 3G ..." on the GPS scale, then 30 s steps
    t0 = calendar_to_gps_s(2005, 4, 2)
    np.testing.assert_allclose(obs.gps_s, t0 + 30.0 * np.arange(10))
    j = obs.sats.index("G03")
    # line 19: "  55923622.160    24767686.375    43647388.2424   24767684.8224"
    assert obs.obs("L1")[0, j] == 55923622.160
    assert obs.obs("C1")[0, j] == 24767686.375
    # the "4" after P2 and L2 sits in column 15: loss-of-lock bit 2, "under anti-spoofing"
    assert obs.obs("P2")[0, j] == 24767684.822 and obs.lli["P2"][0, j] == 4
    assert obs.lli["L2"][0, j] == 4 and obs.snr["P2"][0, j] == 0 and obs.lli["L1"][0, j] == 0
    # the first epoch's list on line 18 (8 satellites)
    seen = {s for s, v in zip(obs.sats, obs.obs("C1")[0], strict=True) if np.isfinite(v)}
    assert seen == {"G03", "G07", "G08", "G11", "G19", "G20", "G24", "G28"}
    assert obs.where(0).endswith("line 18, epoch 2005-04-02T00:00:00.000 GPST")


def test_pseudorange_priority(test_data: Path) -> None:
    sept = read_rinex_obs(test_data / SEPT)
    sel = sept.pseudorange()
    c01, g04 = sept.sats.index("C01"), sept.sats.index("G04")
    # line 49: "C01  36675141.169 7 ..." is the C2I column, the first BeiDou code
    assert sel.code[0, c01] == "C2I" and sel.pseudorange_m[0, c01] == 36675141.169
    assert sel.code[0, g04] == "C1C" and sel.pseudorange_m[0, g04] == 24546598.364
    # SBAS has no priority: no pseudorange
    s_cols = [k for k, s in enumerate(sept.sats) if s[0] == "S"]
    assert s_cols and np.all(np.isnan(sel.pseudorange_m[:, s_cols]))
    custom = sept.pseudorange({"G": ("C2W",)})
    assert custom.code[0, g04] == "C2W" and custom.pseudorange_m[0, g04] == 24546602.458
    assert np.all(np.isnan(custom.pseudorange_m[:, c01]))


def test_rinex3_septentrio_header_and_values(test_data: Path) -> None:
    obs = read_rinex_obs(test_data / SEPT)
    h = obs.header
    assert h.version == pytest.approx(3.04) and h.file_system == "M"
    assert len(h.obs_types["G"]) == 18 and h.obs_types["C"][:2] == ("C2I", "L2I")
    assert h.glonass_slots["R02"] == -4 and h.glonass_slots["R24"] == 2
    assert obs.problems == ()
    # "> 2023 09 06 00 00  0.0000000  0 45"
    assert obs.gps_s[0] == calendar_to_gps_s(2023, 9, 6)
    assert np.isfinite(np.vstack([obs.obs(c)[0] for c in obs.codes])).any(axis=0).sum() == 45
    c01 = obs.sats.index("C01")
    assert obs.obs("L2I")[0, c01] == 190977074.183 and obs.lli["L2I"][0, c01] == 0
    assert obs.snr["L2I"][0, c01] == 7 and obs.obs("S2I")[0, c01] == 45.5


def test_smartphone_lli_snr_and_fractional_epoch(test_data: Path) -> None:
    obs = read_rinex_obs(test_data / PIXEL)
    assert obs.problems == () and len(obs.gps_s) == 6
    # "> 2023 11 07 23 43 15.0002755  0 19"
    assert obs.gps_s[0] == pytest.approx(calendar_to_gps_s(2023, 11, 7, 23, 43, 15.0002755))
    g04 = obs.sats.index("G04")
    # "G04  23440243.75725 ..." value 23440243.757, LLI 2, strength 5
    assert obs.obs("C1C")[0, g04] == 23440243.757
    assert obs.lli["C1C"][0, g04] == 2 and obs.snr["C1C"][0, g04] == 5
    assert obs.sats[0].startswith("E") and "R21" in obs.sats


def test_mixed_types_file_parses(test_data: Path) -> None:
    obs = read_rinex_obs(test_data / MIXED)
    assert obs.problems == () and len(obs.gps_s) == 5
    assert set(obs.header.obs_types) == {"G", "R", "E"}
    assert np.isfinite(obs.pseudorange().pseudorange_m).sum() > 50


def test_codes_subset_and_gzip(test_data: Path, tmp_path: Path) -> None:
    gz = tmp_path / "x.05o.gz"
    gz.write_bytes(gzip.compress((test_data / OBS2).read_bytes()))
    obs = read_rinex_obs(gz, codes=["C1"])
    assert obs.codes == ("C1",)
    ref = read_rinex_obs(test_data / OBS2)
    np.testing.assert_array_equal(obs.obs("C1"), ref.obs("C1"))
    with pytest.raises(KeyError, match="no observation code 'L1'"):
        obs.obs("L1")


def test_truncated_file_lenient_and_strict(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / OBS2)
    # the 10th epoch starts on line 18 + 9 * 9 = 99; keep it and two of its satellites
    assert lines[98].startswith(" 05  4  2  0  4 30.0")
    cut = _write(tmp_path / "cut.05o", lines[:101])
    obs = read_rinex_obs(cut)
    assert len(obs.gps_s) == 9
    (p,) = obs.problems
    assert p.line == 99 and "truncated" in p.what
    assert p.epoch_gps_s == calendar_to_gps_s(2005, 4, 2, 0, 4, 30.0)
    assert "cut.05o, line 99, epoch 2005-04-02T00:04:30.000 GPST" in str(p)
    with pytest.raises(RinexObsError, match=r"cut\.05o, line 99: .*truncated.*00:04:30"):
        read_rinex_obs(cut, strict=True)


def test_line_cut_inside_a_field(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / OBS2)
    lines[-1] = lines[-1][:40] + "\n"  # "...    43647..." ends inside the third field
    obs = read_rinex_obs(_write(tmp_path / "cut.05o", lines))
    assert any(
        p.line == len(lines) and "inside a 16-character field" in p.what for p in obs.problems
    )
    with pytest.raises(RinexObsError, match=f"line {len(lines)}"):
        read_rinex_obs(tmp_path / "cut.05o", strict=True)


def test_rinex3_truncated_epoch(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / PIXEL)
    starts = [i for i, s in enumerate(lines) if s.startswith(">")]
    cut = _write(tmp_path / "cut.23o", lines[: starts[-1] + 5])  # last epoch: 4 of 20 lines
    obs = read_rinex_obs(cut)
    assert len(obs.gps_s) == 5
    (p,) = obs.problems
    assert p.line == starts[-1] + 1 and "4 of 20" in p.what


def test_unknown_code_reported_by_header_line_and_epoch(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / OBS2)
    k = next(i for i, s in enumerate(lines) if "TYPES OF OBSERV" in s)
    lines[k] = lines[k].replace("P2", "Q2")
    obs = read_rinex_obs(_write(tmp_path / "q.05o", lines))
    head, first = obs.problems
    assert head.line == k + 1 and "Q2" in head.what and head.epoch_gps_s is None
    assert first.line == 18 and first.epoch_gps_s == calendar_to_gps_s(2005, 4, 2)
    assert "10 epoch(s)" in first.what
    assert obs.obs("Q2")[0, obs.sats.index("G03")] == 24767684.822  # kept, not dropped
    with pytest.raises(RinexObsError, match=f"line {k + 1}: .*Q2"):
        read_rinex_obs(tmp_path / "q.05o", strict=True)


def test_unknown_rinex3_code_and_unknown_system(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / MIXED)
    k = next(i for i, s in enumerate(lines) if s.startswith("E    8"))
    lines[k] = lines[k].replace("C5X", "C9X")  # Galileo has no band 9
    obs = read_rinex_obs(_write(tmp_path / "u.20o", lines))
    assert any(p.line == k + 1 and "C9X" in p.what for p in obs.problems)
    assert "C9X" in obs.codes


def test_event_flags_and_type_redefinition(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / OBS2)
    ep2 = 18 + 9 * 2 - 1  # index of the third epoch line
    event = [
        "                            4  2\n",
        "     2    C1    L1                                          # / TYPES OF OBSERV\n",
        "site visit                                                  COMMENT\n",
    ]
    third = lines[ep2 : ep2 + 9]
    # the third epoch rewritten with the new types: C1 then L1 on one line per satellite
    new = [third[0].replace("  0  8G", "  1  8G")]
    for s in third[1:]:
        new.append(s[16:32] + s[:16].rstrip() + "\n")
    moved = lines[:ep2] + event + new
    obs = read_rinex_obs(_write(tmp_path / "ev.05o", moved))
    assert obs.problems == ()
    assert len(obs.gps_s) == 3 and obs.epoch_flag.tolist() == [0, 0, 1]
    (ev,) = obs.events
    assert ev.flag == 4 and ev.line == ep2 + 1 and np.isnan(ev.epoch_gps_s)
    j = obs.sats.index("G03")
    ref = read_rinex_obs(test_data / OBS2)
    assert obs.obs("C1")[2, j] == ref.obs("C1")[2, j]
    assert obs.obs("L1")[2, j] == ref.obs("L1")[2, j]
    assert np.isnan(obs.obs("P2")[2, j]) and obs.obs("P2")[1, j] == ref.obs("P2")[1, j]


def test_more_than_twelve_satellites_continuation(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / OBS2)
    head = lines[:17]
    sats = [f"G{p:2d}" for p in range(1, 15)]
    epoch = [
        " 05  4  2  0  0  0.0000000  0 14" + "".join(sats[:12]) + "\n",
        " " * 32 + "".join(sats[12:]) + "\n",
    ]
    body = []
    for p in range(1, 15):
        v = 20000000.0 + 1000.0 * p
        body.append(f"{v + 0.125:14.3f}  {v:14.3f}  {v + 0.5:14.3f}  {v + 0.25:14.3f}  \n")
    obs = read_rinex_obs(_write(tmp_path / "many.05o", head + epoch + body))
    assert obs.problems == ()
    assert obs.sats == tuple(f"G{p:02d}" for p in range(1, 15))
    np.testing.assert_array_equal(obs.obs("C1")[0], 20000000.0 + 1000.0 * np.arange(1, 15))
    np.testing.assert_array_equal(obs.obs("P2")[0], 20000000.25 + 1000.0 * np.arange(1, 15))


def test_time_system_glonass_is_utc(test_data: Path, tmp_path: Path) -> None:
    lines = _lines(test_data / MIXED)
    k = next(i for i, s in enumerate(lines) if "TIME OF FIRST OBS" in s)
    lines[k] = lines[k][:48] + "GLO" + lines[k][51:]
    glo = read_rinex_obs(_write(tmp_path / "g.20o", lines))
    gps = read_rinex_obs(test_data / MIXED)
    np.testing.assert_allclose(glo.gps_s - gps.gps_s, 18.0)  # GPST - UTC in 2020


def test_errors_name_the_file(test_data: Path, tmp_path: Path) -> None:
    with pytest.raises(RinexObsError, match="no such file"):
        read_rinex_obs(tmp_path / "missing.05o")
    with pytest.raises(RinexObsError, match="line 1: not an observation file"):
        read_rinex_obs(test_data / "gnss_obs/07590920_0000_0200.05n")
    v5 = _lines(test_data / OBS2)
    v5[0] = "     5.00" + v5[0][9:]
    with pytest.raises(RinexObsError, match=r"line 1: RINEX 5.0 .* convert the file to RINEX 3"):
        read_rinex_obs(_write(tmp_path / "v5.rnx", v5))
    lines = _lines(test_data / OBS2)
    with pytest.raises(RinexObsError, match="END OF HEADER"):
        read_rinex_obs(_write(tmp_path / "h.05o", lines[:10]))
    lines[19] = "  garbage line that is not data\n"
    obs = read_rinex_obs(_write(tmp_path / "g.05o", lines))
    assert any(p.line == 20 for p in obs.problems)


@pytest.mark.shared
def test_every_shared_observation_file_parses(shared_data: Path) -> None:
    d = shared_data / "gnss"
    expect = {
        "rtklib/07590920.05o": 120,
        "rtklib/30400920.05o": 120,
        "gnss_lib_py/rinex_obs_z_tracking.rnx": 2,
        "gnss_lib_py/rinex_obs_rinex_obs_mixed_types.20o": 5,
        "gnss_lib_py/android_rinex_obs_pixel6.23o": 48,
    }
    for name, n in expect.items():
        obs = read_rinex_obs(d / name, strict=True)
        assert len(obs.gps_s) == n, name
        assert np.all(np.diff(obs.gps_s) > 0), name
        assert np.isfinite(obs.pseudorange().pseudorange_m).any(axis=1).all(), name
    # teqc splice markers: flag-4 events without a date, not mistaken for data
    full = read_rinex_obs(d / "rtklib/07590920.05o")
    assert [e.line for e in full.events] == [855, 1058, 1090]
    assert all(e.flag == 4 and "SPLICE" in e.records[0] for e in full.events)


def _same_observations(a: Observations, b: Observations) -> None:
    assert a.sats == b.sats and a.codes == b.codes
    np.testing.assert_array_equal(a.gps_s, b.gps_s)
    np.testing.assert_array_equal(a.epoch_line, b.epoch_line)
    for c in a.codes:
        np.testing.assert_array_equal(a.values[c], b.values[c], err_msg=c)
        np.testing.assert_array_equal(a.lli[c], b.lli[c], err_msg=c)
        np.testing.assert_array_equal(a.snr[c], b.snr[c], err_msg=c)


@pytest.mark.parametrize("name", [OBS2, SEPT, PIXEL])
@pytest.mark.parametrize("compression", ["none", "gz"])
def test_hatanaka_round_trip(test_data: Path, tmp_path: Path, name: str, compression: str) -> None:
    """A file compressed by the hatanaka package (RNXCMP) reads as the plain file does."""
    import hatanaka

    plain = test_data / name
    crx = tmp_path / "site.crx"
    crx.write_bytes(hatanaka.compress(plain.read_bytes(), compression=compression))
    assert (
        b"COMPACT RINEX"
        in (gzip.decompress if compression == "gz" else bytes)(crx.read_bytes())[:80]
    )
    ref, got = read_rinex_obs(plain), read_rinex_obs(crx)
    _same_observations(ref, got)
    assert got.crinex == ("1.0" if ref.header.version < 3 else "3.0") and ref.crinex == ""


def test_real_rinex4_hatanaka_file(test_data: Path, tmp_path: Path) -> None:
    """KMS3 (Septentrio, RINEX 4.00 in CRINEX 3.0): the reader's expansion equals the hatanaka
    package's, and the values equal the expanded text's lines, read by hand."""
    import hatanaka

    crx = test_data / "gnss_obs/KMS300DNK_R_20221591000_01H_30S_MO.crx"
    obs = read_rinex_obs(crx, strict=True)
    h = obs.header
    assert h.version == 4.0 and obs.crinex == "3.0" and h.receiver_type == "SEPT POLARX5"
    xyz = [3516213.4380, 781859.8595, 5246037.9660]  # the header line, read by hand
    np.testing.assert_array_equal(h.approx_position_ecef_m, xyz)
    assert h.obs_types["E"][:3] == ("C1C", "C5Q", "C6C") and h.glonass_slots["R03"] == 5
    expanded = tmp_path / "KMS3.rnx"
    expanded.write_bytes(hatanaka.decompress(crx.read_bytes()))
    _same_observations(read_rinex_obs(expanded, strict=True), obs)
    lines = expanded.read_text().splitlines()
    first = next(i for i, t in enumerate(lines) if t.startswith("> 2022 06 08 10 00 00"))
    assert obs.epoch_line[0] == first + 1 and len(obs.gps_s) == 19
    np.testing.assert_array_equal(np.diff(obs.gps_s), 30.0)
    g = next(t for t in lines[first:] if t.startswith("G"))
    sat, c1c = g[:3], float(g[3:17])
    assert obs.obs("C1C")[0, obs.sats.index(sat)] == c1c


def test_damaged_hatanaka_file_names_file_and_fix(test_data: Path, tmp_path: Path) -> None:
    crx = (test_data / "gnss_obs/KMS300DNK_R_20221591000_01H_30S_MO.crx").read_text()
    lines = crx.splitlines(keepends=True)
    i = next(k for k, t in enumerate(lines) if t.startswith(">"))  # first epoch
    bad = tmp_path / "bad.crx"
    bad.write_text("".join([*lines[: i + 5], "&&garbage\n", *lines[i + 6 :]]))
    with pytest.raises(RinexObsError, match=r"bad\.crx, line \d+: .*download it again") as err:
        read_rinex_obs(bad)
    assert err.value.line is not None and err.value.line >= i + 6  # at or after the damage
    cut = tmp_path / "cut.crx.gz"
    cut.write_bytes(gzip.compress("".join(lines[: i + 300]).encode() + lines[i + 300][:5].encode()))
    with pytest.raises(RinexObsError, match=r"cut\.crx\.gz.*truncated.*download it again"):
        read_rinex_obs(cut)


@pytest.mark.shared
def test_shared_hatanaka_day(shared_data: Path) -> None:
    """A full IGS day in .crx.gz (Ny-Alesund, RINEX 3.05): 2880 epochs at 30 s, no anomaly."""
    path = shared_data / "gnss/georust_rinex/NYA100NOR_S_20241240000_01D_30S_MO.crx.gz"
    obs = read_rinex_obs(path, codes=["C1C", "C2I"], strict=True)
    assert obs.crinex == "3.0" and obs.header.version == 3.05
    assert len(obs.gps_s) == 2880 and np.all(np.diff(obs.gps_s) == 30.0)
    assert np.isfinite(obs.pseudorange().pseudorange_m).any(axis=1).all()


def test_an_epoch_not_after_the_one_before_is_dropped_and_said(test_data, tmp_path):
    """A user trial's repeated epoch was "skipped ... kept": located, and the run's table out of
    time order."""
    src = test_data / "gnss_obs" / "07590920_10ep.05o"
    obs = read_rinex_obs(src)
    lines = src.read_text().splitlines(keepends=True)
    starts = [int(x) - 1 for x in obs.epoch_line] + [len(lines)]
    third = lines[starts[2]:starts[3]]
    # the third epoch's block again after the fifth: time goes back
    edited = lines[:starts[5]] + third + lines[starts[5]:]
    p = tmp_path / "repeat.05o"
    p.write_text("".join(edited))
    got = read_rinex_obs(p)
    assert got.gps_s.size == obs.gps_s.size and np.all(np.diff(got.gps_s) > 0)
    np.testing.assert_array_equal(got.gps_s, obs.gps_s)
    assert any("dropped" in pr.what and "time going back" in pr.what
               for pr in got.problems)  # fmt: skip


def test_a_time_system_rinex_does_not_have_is_refused(test_data: Path, tmp_path: Path) -> None:
    """'UTC' in TIME OF FIRST OBS (not a RINEX observation time system) was read as GPS time
    without a word (a user trial: the epochs 18 s off)."""
    lines = _lines(test_data / OBS2)
    k = next(i for i, ln in enumerate(lines) if "TIME OF FIRST OBS" in ln)
    assert lines[k][48:51] == "GPS"
    lines[k] = lines[k][:48] + "UTC" + lines[k][51:]
    with pytest.raises(RinexObsError, match=rf"line {k + 1}: time system 'UTC'.*GPS, GLO"):
        read_rinex_obs(_write(tmp_path / "utc.05o", lines))
    lines[k] = lines[k][:48] + "GLO" + lines[k][51:]
    assert read_rinex_obs(_write(tmp_path / "glo.05o", lines)).header.time_system == "GLO"


def test_sys_scale_factor_divides_the_stored_values(test_data, tmp_path):
    """RINEX 3.05 5.5 / SYS / SCALE FACTOR: the stored values were multiplied by the factor and
    are divided before use. A user trial (2026-12-07) stored KMS3's GPS C1C times 10 with the
    record: the reader ignored it, `locator run` gave no position at any epoch with exit 0,
    and `locator calibrate` blamed the station position."""
    import hatanaka

    crx = test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx"
    text = hatanaka.decompress(crx.read_bytes()).decode()
    out, head = [], True
    for line in text.splitlines(keepends=True):
        if head and "END OF HEADER" in line:
            out.append("G   10   1 C1C".ljust(60) + "SYS / SCALE FACTOR\n")
            out.append("E  100   0".ljust(60) + "SYS / SCALE FACTOR\n")  # every type of E
            head = False
        elif not head and line[:1] in "GE" and line[3:17].strip():
            f = 10.0 if line[0] == "G" else 100.0
            line = line[:3] + f"{float(line[3:17]) * f:14.3f}" + line[17:]
        out.append(line)
    scaled = tmp_path / "scaled.rnx"
    scaled.write_text("".join(out))
    a, b = read_rinex_obs(crx), read_rinex_obs(scaled)
    assert b.header.scale_factors == {"G": {"C1C": 10.0}, "E": {"*": 100.0}}
    assert a.sats == b.sats
    g = [k for k, s in enumerate(a.sats) if s[0] in "GE"]
    np.testing.assert_allclose(b.obs("C1C")[:, g], a.obs("C1C")[:, g], rtol=0, atol=1e-3)
    c = [k for k, s in enumerate(a.sats) if s[0] == "C"]  # other systems untouched
    np.testing.assert_array_equal(b.obs("C2I")[:, c], a.obs("C2I")[:, c])


def test_qzss_l1c_is_not_ranged_with_the_l1_ca_group_delay(test_data, tmp_path):
    """QZSS ``C1X`` is L1C (data + pilot), whose group delay needs CNAV-2's inter-signal
    corrections, not L1 C/A's TGD alone (a user trial, 2026-12-07): like GPS's C1X it gets no
    single-frequency pseudorange. KMS3's J04 with its C1C declared as C1X."""
    import hatanaka

    crx = test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx"
    text = hatanaka.decompress(crx.read_bytes()).decode()
    lines = text.splitlines(keepends=True)
    (k,) = [i for i, line in enumerate(lines)
            if line.startswith("J") and "SYS / # / OBS TYPES" in line]  # fmt: skip
    lines[k] = lines[k].replace(" C1C ", " C1X ", 1)
    renamed = tmp_path / "l1c.rnx"
    renamed.write_text("".join(lines))
    a, b = read_rinex_obs(crx), read_rinex_obs(renamed)
    j = a.sats.index("J04")
    assert np.isfinite(a.pseudorange().pseudorange_m[:, j]).all()  # C1C: ranged
    assert np.isfinite(b.obs("C1X")[:, j]).all()  # the same values, read as L1C
    assert np.isnan(b.pseudorange().pseudorange_m[:, j]).all()


def test_a_zero_observation_is_missing(test_data, tmp_path):
    """RINEX writes a missing observation as blanks or 0.0 (3.05, 5.7); NYA1's 2024 day has
    thousands of 0.000 second-frequency pseudoranges, read as ranges until 2026-12-07."""
    import hatanaka

    crx = test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx"
    text = hatanaka.decompress(crx.read_bytes()).decode()
    lines = text.splitlines(keepends=True)
    body = lines.index(next(x for x in lines if "END OF HEADER" in x)) + 1
    k = next(i for i in range(body, len(lines)) if lines[i].startswith("G"))
    sat = lines[k][:3]
    lines[k] = lines[k][:3] + f"{0.0:14.3f}" + lines[k][17:]  # the first type, C1C
    zeroed = tmp_path / "zero.rnx"
    zeroed.write_text("".join(lines))
    a, b = read_rinex_obs(crx), read_rinex_obs(zeroed)
    j = a.sats.index(sat)
    assert np.isfinite(a.obs("C1C")[0, j]) and np.isnan(b.obs("C1C")[0, j])
    np.testing.assert_array_equal(np.isnan(a.obs("C1C")).sum() + 1, np.isnan(b.obs("C1C")).sum())
    assert b.pseudorange().code[0, j] != "C1C"  # the next code of the priority, or none


def _twtf(test_data: Path) -> tuple[list[str], list[str], list[str], list[str]]:
    """TWTF's 2-epoch RINEX 3.04 excerpt: header, epoch 1, epoch 2 (lines without ends)."""
    lines = [x.rstrip("\r\n") for x in (test_data / SEPT).read_text().splitlines()]
    eoh = next(i for i, x in enumerate(lines) if "END OF HEADER" in x)
    ep2 = next(i for i, x in enumerate(lines) if x.startswith(">") and i > eoh + 1)
    return lines[: eoh + 1], lines[eoh + 1 : ep2], lines[ep2:], lines


def _times(record: str, k: int, f: float) -> str:
    """``record`` with its k-th 16-character field multiplied by ``f``."""
    a = 3 + 16 * k
    return record[:a] + f"{float(record[a : a + 14]) * f:14.3f}" + record[a + 14 :]


def _swap(record: str, k1: int, k2: int) -> str:
    a, b = 3 + 16 * k1, 3 + 16 * k2
    record = record.ljust(max(a, b) + 16)
    f1, f2 = record[a : a + 16], record[b : b + 16]
    record = record[:a] + f2 + record[a + 16 :]
    return record[:b] + f1 + record[b + 16 :]


def test_a_scale_factor_in_an_event_block_applies_to_the_epochs_after_it(test_data, tmp_path):
    """RINEX 3.04 6.6: "Each value remains valid until changed by an additional header record";
    flag 4 (table A3) is "header information follows". A SYS / SCALE FACTOR in a flag-4 block
    was ignored until 2026-12-07: the later epochs' values read 10 times too long (or short),
    without a word."""
    head, e1, e2, _ = _twtf(test_data)
    ref = read_rinex_obs(test_data / SEPT)
    g = [k for k, s in enumerate(ref.sats) if s[0] == "G"]
    sf = "SYS / SCALE FACTOR"
    # a factor first given in the block: epoch 2's GPS C1C stored times 10
    block = [">" + " " * 30 + "4  1", "G   10   1 C1C".ljust(60) + sf]
    body = e1 + block + e2[:1] + [_times(x, 0, 10) if x[0] == "G" else x for x in e2[1:]]
    a = read_rinex_obs(_write(tmp_path / "a.rnx", [x + "\n" for x in head + body]), strict=True)
    # the header's factor set back to 1 by the block: epoch 1 stored times 10, epoch 2 not
    h2 = [*head[:-1], "G   10   1 C1C".ljust(60) + sf, head[-1]]
    back = [">" + " " * 30 + "4  1", "G    1   0".ljust(60) + sf]
    body = e1[:1] + [_times(x, 0, 10) if x[0] == "G" else x for x in e1[1:]] + back + e2
    b = read_rinex_obs(_write(tmp_path / "b.rnx", [x + "\n" for x in h2 + body]), strict=True)
    for o in (a, b):
        np.testing.assert_allclose(o.obs("C1C")[:, g], ref.obs("C1C")[:, g], rtol=0, atol=1e-3)
        np.testing.assert_array_equal(o.obs("L1C"), ref.obs("L1C"))


def test_header_records_after_a_new_site_flag_redefine_the_types(test_data, tmp_path):
    """Flag 3, new site occupation: "at least MARKER NAME record follows" (RINEX 3.04 table A3;
    its example #1 gives MARKER NUMBER and ANTENNA: DELTA H/E/N too): header records, as after
    flag 4. Its SYS / # / OBS TYPES were ignored until 2026-12-07: with GPS's C1C and C2W
    swapped, epoch 2's L2 P(Y) ranges were read as C1C (-0.5 to +6.0 m off), no problem said."""
    head, e1, e2, _ = _twtf(test_data)
    ref = read_rinex_obs(test_data / SEPT)
    g = [k for k, s in enumerate(ref.sats) if s[0] == "G"]
    types = [x for x in head if x.startswith("G   18") or x.startswith("       S2L")]
    swapped = types[0].replace(" C1C ", " XXX ").replace(" C2W ", " C1C ").replace(" XXX ", " C2W ")
    block = [">" + " " * 30 + "3  3", "TWTF".ljust(60) + "MARKER NAME", swapped, types[1]]
    body = e1 + block + e2[:1] + [_swap(x, 0, 6) if x[0] == "G" else x for x in e2[1:]]
    obs = read_rinex_obs(_write(tmp_path / "b.rnx", [x + "\n" for x in head + body]), strict=True)
    for c in ("C1C", "C2W"):
        np.testing.assert_array_equal(obs.obs(c)[:, g], ref.obs(c)[:, g])
    assert [e.flag for e in obs.events] == [3]


def test_an_unreadable_scale_factor_in_an_event_block_is_refused(test_data, tmp_path):
    head, e1, e2, _ = _twtf(test_data)
    block = [">" + " " * 30 + "4  1", "G   1x   1 C1C".ljust(60) + "SYS / SCALE FACTOR"]
    path = _write(tmp_path / "bad.rnx", [x + "\n" for x in head + e1 + block + e2])
    with pytest.raises(RinexObsError, match=r"line 95.*SYS / SCALE FACTOR"):
        read_rinex_obs(path)


def test_a_glonass_slot_in_an_event_block(test_data, tmp_path):
    """A slot the header lacks is taken; one changed from the header's is reported (the file
    holds one slot table: GLONASS SLOT / FRQ #)."""
    head, e1, e2, _ = _twtf(test_data)
    label = "GLONASS SLOT / FRQ #"
    block = [">" + " " * 30 + "4  1", "  2 R22 -3 R01  2".ljust(60) + label]
    obs = read_rinex_obs(_write(tmp_path / "s.rnx", [x + "\n" for x in head + e1 + block + e2]))
    assert obs.header.glonass_slots["R22"] == -3 and obs.header.glonass_slots["R01"] == 1
    assert any(p.line == 95 and "R01" in p.what for p in obs.problems)


def test_an_epoch_flag_rinex_does_not_define_is_not_read_as_data(test_data, tmp_path):
    """Epoch flags are 0-6 (RINEX 3.04 table A3; 6.7: unknown event flags are skipped and
    reported); a RINEX 3 epoch of flag 7 was read as an observation epoch."""
    head, e1, e2, _ = _twtf(test_data)
    bad = [e2[0][:31] + "7" + e2[0][32:], *e2[1:]]
    obs = read_rinex_obs(_write(tmp_path / "f7.rnx", [x + "\n" for x in head + e1 + bad]))
    assert len(obs.gps_s) == 1 and any(p.line == 94 for p in obs.problems)
