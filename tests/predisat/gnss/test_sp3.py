"""SP3 reader and interpolation against hand-read records and held-out epochs."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from predisat.gnss.sp3 import Sp3Error, read_sp3

WEEK_S = 604800.0


@pytest.fixture(scope="module")
def igs(test_data: Path):
    return read_sp3(test_data / "gnss/igs15904_G01G02G05.sp3")


def test_values_match_hand_read(igs) -> None:
    assert igs.sats == ("G01", "G02", "G05")
    assert igs.time_system == "GPS"
    assert igs.coord_system == "IGS05"
    assert len(igs.epochs_gps_s) == 32
    # "## 1590 345600.00000000   900.00000000" and "*  2010  7  1  0  0  0.00000000"
    assert igs.epochs_gps_s[0] == 1590 * WEEK_S + 345600.0
    assert igs.interval_s == 900.0
    # "PG02 -14889.160729  -5131.952946 -21416.801336    269.108429"
    np.testing.assert_allclose(igs.pos_ecef_m[0, 1], [-14889160.729, -5131952.946, -21416801.336])
    assert igs.clock_s[0, 1] == pytest.approx(269.108429e-6)
    # "PG01 ... 999999.999999" is a missing clock
    assert np.isnan(igs.clock_s[0, 0])
    assert np.all(np.isfinite(igs.pos_ecef_m[0, 0]))


def test_interpolation_reproduces_held_out_epochs(igs) -> None:
    # keep every other epoch (30 min spacing) and predict the dropped ones
    kept = dataclasses.replace(
        igs,
        epochs_gps_s=igs.epochs_gps_s[::2],
        pos_ecef_m=igs.pos_ecef_m[::2],
        clock_s=igs.clock_s[::2],
    )
    held = igs.epochs_gps_s[1::2][3:-3]  # away from the ends, where the window is centred
    truth = igs.pos_ecef_m[1::2][3:-3]
    # at 30-min spacing degree 12 is needed for centimetres (degree 10 gives ~0.1 m); the
    # 15-min files reach a few millimetres with the default 11 points (shared test below)
    err = np.linalg.norm(kept.position_at(held, n_points=13) - truth, axis=-1)
    assert np.max(err) < 0.03
    err11 = np.linalg.norm(kept.position_at(held) - truth, axis=-1)
    assert np.max(err11) < 0.2
    # exact at tabulated epochs (Lagrange property)
    np.testing.assert_allclose(
        igs.position_at(igs.epochs_gps_s[5:8]), igs.pos_ecef_m[5:8], atol=1e-6
    )


def test_nan_outside_span_and_unknown_sat(igs) -> None:
    t = np.array([igs.epochs_gps_s[0] - 1.0, igs.epochs_gps_s[-1] + 1.0, igs.epochs_gps_s[3]])
    p = igs.position_at(t, ["G02", "G99"])
    assert np.all(np.isnan(p[:2]))
    assert np.all(np.isnan(p[:, 1]))
    assert np.all(np.isfinite(p[2, 0]))


def test_clock_linear_between_epochs(igs) -> None:
    t = igs.epochs_gps_s[2] + 300.0
    c = igs.clock_at([t], ["G02"])[0, 0]
    expected = igs.clock_s[2, 1] + (igs.clock_s[3, 1] - igs.clock_s[2, 1]) / 3.0
    assert c == pytest.approx(expected, rel=1e-12)
    assert np.isnan(igs.clock_at([t], ["G01"])[0, 0])


def test_multignss_sp3c(test_data: Path) -> None:
    s = read_sp3(test_data / "gnss/sp3_COD0OPSRAP_20230730000_01D_05M_ORB.SP3")
    assert len(s.sats) == 78
    assert {x[0] for x in s.sats} == {"G", "R", "E"}
    assert s.epochs_gps_s[0] == 2253 * WEEK_S + 172800.0
    assert s.coord_system == "IGS20"


def test_merge_consecutive_files(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/igs15904_G01G02G05.sp3").read_text().splitlines()
    first_epoch = next(i for i, ln in enumerate(lines) if ln.startswith("*"))
    cut = first_epoch + 4 * 16  # 16 epochs in the first part
    a = tmp_path / "a.sp3"
    b = tmp_path / "b.sp3"
    a.write_text("\n".join([*lines[:cut], "EOF"]) + "\n")
    b.write_text("\n".join(lines[:first_epoch] + lines[cut - 4 :]) + "\n")  # 1 epoch overlap
    merged = read_sp3([a, b])
    whole = read_sp3(test_data / "gnss/igs15904_G01G02G05.sp3")
    np.testing.assert_array_equal(merged.epochs_gps_s, whole.epochs_gps_s)
    np.testing.assert_array_equal(merged.pos_ecef_m, whole.pos_ecef_m)


def test_truncated_and_malformed(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/igs15904_G01G02G05.sp3").read_text().splitlines()
    p = tmp_path / "cut.sp3"
    p.write_text("\n".join(lines[:-3]) + "\n")  # last epoch loses two records and EOF
    with pytest.raises(Sp3Error) as exc:
        read_sp3(p)
    assert "cut.sp3" in str(exc.value)
    assert f"line {len(lines) - 4}" in str(exc.value)
    assert "truncated" in str(exc.value)
    # cut inside a record: the record is unreadable and the message says the file was cut
    p.write_text("\n".join(lines[:-3]) + "\n" + lines[-3][:6] + "\n")
    with pytest.raises(Sp3Error, match=f"line {len(lines) - 2}: .*cut short, download it again"):
        read_sp3(p)
    bad = list(lines)
    k = next(i for i, ln in enumerate(lines) if ln.startswith("PG02"))
    bad[k] = bad[k][:20] + "x" + bad[k][21:]
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(Sp3Error, match=f"line {k + 1}: unreadable position record.*damaged"):
        read_sp3(p)
    p.write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(Sp3Error, match="no 'EOF' line"):
        read_sp3(p)
    p.write_text("hello\n")
    with pytest.raises(Sp3Error, match="line 1"):
        read_sp3(p)


@pytest.mark.shared
def test_mgex_15min_held_out(shared_data: Path) -> None:
    # 15-min tabulation (every third epoch of the 5-min CODE MGEX file) against the two
    # held-out 5-min epochs in between: G, R, E (incl. eccentric E14/E18), C and J orbits
    mgx = read_sp3(shared_data / "gnss/gnss_lib_py/sp3_COD0MGXFIN_20211180000_01D_05M_ORB.SP3")
    sub = dataclasses.replace(
        mgx, epochs_gps_s=mgx.epochs_gps_s[::3], pos_ecef_m=mgx.pos_ecef_m[::3],
        clock_s=mgx.clock_s[::3],
    )  # fmt: skip
    t = mgx.epochs_gps_s[15:-15]
    err2 = np.linalg.norm(sub.position_at(t) - mgx.pos_ecef_m[15:-15], axis=-1)
    assert np.nanpercentile(err2, 99) < 0.02
    assert np.nanmax(err2) < 0.05


def test_sp3b_placeholder_time_system_is_gps(tmp_path: Path, test_data: Path) -> None:
    """SP3-a/b leave the '%c' time system as the placeholder 'ccc' (GPS time): read so; an
    unknown system names the line and the columns (a user trial: refused without either)."""
    src = test_data / "gnss/igs15904_G01G02G05.sp3"
    lines = src.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("%c"))
    b = list(lines)
    b[0] = "#b" + b[0][2:]
    b[k] = "%c cc cc ccc" + b[k][12:]
    p = tmp_path / "b.sp3"
    p.write_text("\n".join(b) + "\n")
    got, want = read_sp3(p), read_sp3(src)
    assert np.array_equal(got.epochs_gps_s, want.epochs_gps_s)
    b[k] = "%c G  cc XYZ" + b[k][12:]
    p.write_text("\n".join(b) + "\n")
    with pytest.raises(Sp3Error, match=rf"line {k + 1}: unknown time system 'XYZ'.*columns 10-12"):
        read_sp3(p)
