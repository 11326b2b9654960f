"""GSDC device_gnss.csv reader and source: values against hand-read rows, the time scale against
the leap seconds, the residuals against Google's independent ground truth, and bad input."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from locator.devicegnss import (
    DeviceGnssError,
    DeviceGnssSource,
    device_profile,
    device_residuals,
    read_device_gnss,
    read_ground_truth,
)
from predisat.geodesy import geodetic_to_ecef

DEV = "gsdc/gdc2023_pixel7pro_device_gnss_2ep.csv"
GT = "gsdc/gdc2023_pixel7pro_ground_truth.csv"


def test_values_match_the_hand_read_row(test_data: Path) -> None:
    dev = read_device_gnss(test_data / DEV)
    assert len(dev.gps_s) == 2 and dev.utc_ms.tolist() == [1694113198000, 1694113199000]
    j = dev.sats.index("G02")
    s = dev.signals["C1C"]
    # line 2: G02 GPS_L1_CA, RawPseudorangeMeters 24567440.9145622, SvPositionX
    # -14916644.0877723, SvClockBiasMeters -166876.027810173, IsrbMeters 0,
    # IonosphericDelayMeters 9.27741292913443, TroposphericDelayMeters 8.64467820152944
    assert s["line"][0, j] == 2
    assert s["raw_pseudorange_m"][0, j] == 24567440.9145622
    assert s["sv_x_m"][0, j] == -14916644.0877723
    expect = 24567440.9145622 - 166876.027810173 - 0.0 - 9.27741292913443 - 8.64467820152944
    assert dev.corrected_m("C1C")[0, j] == pytest.approx(expect, abs=1e-6)
    # GPS L5 and Galileo E1 pilot become RINEX codes; QZSS rows without SignalType are reported
    assert set(dev.codes) == {"C1C", "C5Q"}
    assert "E07" in dev.sats and "R01" in dev.sats
    assert dev.problems and all("row left out" in p.what for p in dev.problems)
    assert {p.line for p in dev.problems} >= {26, 27}


def test_reception_time_is_utc_plus_18_leap_seconds(test_data: Path) -> None:
    dev = read_device_gnss(test_data / DEV)
    # 2023: GPS - UTC = 18 s; GPS epoch 1980-01-06 is Unix 315964800 s
    utc_as_gps = dev.utc_ms / 1000.0 - 315964800.0 + 18.0
    np.testing.assert_allclose(dev.gps_s, utc_as_gps, atol=2e-3)


def test_ground_truth_and_residuals_at_it(test_data: Path) -> None:
    dev = read_device_gnss(test_data / DEV)
    gt = read_ground_truth(test_data / GT)
    # first record: 37.692231, -122.0884199, 20.9736302800885 m above the ellipsoid
    np.testing.assert_allclose(gt.ecef_m[0], geodetic_to_ecef(37.692231, -122.0884199,
                                                              20.9736302800885), atol=1e-6)
    x = gt.at(dev.gps_s)
    # Google's own least-squares fix (independent of this code) lies within 20 m of the truth
    assert np.all(np.linalg.norm(dev.wls_ecef_m - x, axis=1) < 20.0)
    src = DeviceGnssSource(dev, "G")
    r = device_residuals(src, gt)
    assert r.profile.codes == {"G": ("C1C",)} and r.profile.receiver_class == "phone"
    e = r.residual_m - np.nanmedian(r.residual_m, axis=1, keepdims=True)
    ok = np.isfinite(e)
    assert ok.sum() >= 16  # 8-10 GPS satellites above 5 deg per epoch
    # a phone's clock-free errors: metres, one multipath outlier (G24 at 16 deg); a wrong
    # Earth-rotation sign or a missed satellite clock would make them tens to 1e5 m
    assert np.median(np.abs(e[ok])) < 3.0 and np.max(np.abs(e[ok])) < 40.0
    with pytest.raises(ValueError, match="no ground truth within"):
        gt.at(dev.gps_s + 100.0)


def test_source_rotates_into_the_frame_of_reception(test_data: Path) -> None:
    dev = read_device_gnss(test_data / DEV)
    gt = read_ground_truth(test_data / GT)
    x = gt.ecef_m[0]
    d = DeviceGnssSource(dev, "G").observe(0, x)
    j = dev.sats.index(d.sats[0])
    s = dev.signals["C1C"]
    tx = np.array([s["sv_x_m"][0, j], s["sv_y_m"][0, j], s["sv_z_m"][0, j]])
    # the satellite moves about 2.6 km along x-y in the frame of reception over tau ~ 0.07 s:
    # omega_E tau |r_xy| with |r_xy| ~ 26,000 km; z is unchanged
    tau = np.linalg.norm(d.sat_ecef_m[0] - x) / 299792458.0
    shift = np.linalg.norm(d.sat_ecef_m[0, :2] - tx[:2])
    assert shift == pytest.approx(7.2921151467e-5 * tau * np.linalg.norm(tx[:2]), rel=1e-6)
    assert d.sat_ecef_m[0, 2] == tx[2]
    assert d.extra_sigma_m is not None and np.all(d.extra_sigma_m == 0)  # iono given
    prof = device_profile(DeviceGnssSource(dev, "GE"))
    assert prof.codes == {"E": ("C1C",), "G": ("C1C",)} and prof.receiver_type == ""
    with pytest.raises(ValueError, match="no satellite of constellation 'C'"):
        DeviceGnssSource(dev, "C")


def _rewrite(src: Path, dst: Path, edit: Callable[[list[str]], list[str]]) -> Path:
    lines = src.read_text().splitlines(keepends=True)
    dst.write_text("".join(edit(lines)))
    return dst


def test_bad_input_names_file_line_and_fix(test_data: Path, tmp_path: Path) -> None:
    src = test_data / DEV
    gone = _rewrite(src, tmp_path / "a.csv",
                    lambda ls: [ls[0].replace("SvClockBiasMeters", "SvClock"), *ls[1:]])
    with pytest.raises(DeviceGnssError, match=r"a\.csv, line 1: no column SvClockBiasMeters"):
        read_device_gnss(gone)

    def damage(ls: list[str]) -> list[str]:
        k = ls[0].split(",").index("SvClockBiasMeters")
        cells = ls[5].split(",")
        cells[k] = "1.2.3"
        ls[5] = ",".join(cells)
        return ls

    bad = _rewrite(src, tmp_path / "b.csv", damage)
    with pytest.raises(DeviceGnssError, match=r"b\.csv, line 6: column SvClockBiasMeters holds "
                                              r"'1\.2\.3', not a number; fix or delete the row"):
        read_device_gnss(bad)
    twice = _rewrite(src, tmp_path / "c.csv", lambda ls: [*ls, ls[1]])
    with pytest.raises(DeviceGnssError, match=r"c\.csv, line 74: G02 C1C measured twice.*line 2"):
        read_device_gnss(twice)
    with pytest.raises(DeviceGnssError, match="not a GSDC ground truth"):
        read_ground_truth(src)


def test_locator_run_on_a_phone_log_makes_no_claim(
    test_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from locator.cli import main
    from predisat.geodesy import LocalFrame
    from predisat.track.map import TrackMap
    from predisat.track.readers import write_geojson

    # a straight virtual track through the truth, heading 45 deg
    frame = LocalFrame(37.692231, -122.0884199, 20.9736302800885)
    d = np.linspace(-2000.0, 2000.0, 41)
    enu_track = np.stack([d * np.sin(np.pi / 4), d * np.cos(np.pi / 4), np.zeros_like(d)], -1)
    track = TrackMap.from_latlon(*frame.to_geodetic(enu_track), name="virtual", tolerance_m=0.01)
    write_geojson(track, tmp_path / "t.geojson")
    rc = main(["-q", "run", "--device-gnss", str(test_data / DEV), "--track",
               str(tmp_path / "t.geojson"), "--no-masks", "--antenna-height", "0", "--out",
               str(tmp_path / "run")])  # fmt: skip
    assert rc == 0
    err = capsys.readouterr().err
    # the built-in model is the simulator's: it does not apply to a phone (class phone, C1C)
    assert "NO SAFETY CLAIM" in err and "(phone)" in err and "row left out" in err
    # a phone declared geodetic is refused (a user trial: a geodetic model then claimed 100 %)
    rc = main(["-q", "run", "--device-gnss", str(test_data / DEV), "--track",
               str(tmp_path / "t.geojson"), "--no-masks", "--antenna-height", "0",
               "--receiver-class", "geodetic", "--out", str(tmp_path / "geo")])  # fmt: skip
    assert rc == 2 and "Android GNSS log" in capsys.readouterr().err
    assert not (tmp_path / "geo").exists()
    from locator.runio import read_run

    epochs = read_run(tmp_path / "run")[0]
    assert len(epochs) == 2 and not epochs["claim"].any()
    # scored against the drive's ground truth positions, projected on the track: the truth
    # chainage is the along-track coordinate of the reference positions in the local frame
    gt = str(test_data / GT)
    assert main(["evaluate", str(tmp_path / "run"), "--truth-positions", gt, "--track",
                 str(tmp_path / "t.geojson")]) == 0  # fmt: skip
    scored = pd.read_parquet(tmp_path / "run" / "scored.parquet")
    truth = read_ground_truth(gt)
    enu = frame.ecef_to_enu(truth.at(epochs["gps_s"].to_numpy(float)))
    along = 2000.0 + enu[:, 0] * np.sin(np.pi / 4) + enu[:, 1] * np.cos(np.pi / 4)
    np.testing.assert_allclose(scored["truth_m"], along, atol=0.05)
    assert "no interval claimed" in capsys.readouterr().out
    # another track, or none, is refused before any scoring
    far = np.array([[5000.0, 0.0, 0.0], [5000.0, 4000.0, 0.0]])  # as long, 5 km east
    other = TrackMap.from_latlon(*frame.to_geodetic(far), name="far", tolerance_m=0.01)
    write_geojson(other, tmp_path / "far.geojson")
    assert main(["evaluate", str(tmp_path / "run"), "--truth-positions", gt, "--track",
                 str(tmp_path / "far.geojson")]) == 2  # fmt: skip
    ends = re.search(r"has its ends (\d+) m from the run's", capsys.readouterr().err)
    assert ends is not None and int(ends.group(1)) >= 5000  # moved 5 km east
    # a run folder that does not record its track's ends: the positions' offset tells
    from locator.workflow import truth_from_positions

    with pytest.raises(ValueError, match="beside track 'far'"):
        truth_from_positions(epochs, truth, other)
    assert main(["evaluate", str(tmp_path / "run"), "--truth-positions", gt]) == 2
    assert "needs the run's track" in capsys.readouterr().err
    # the same line the other way round would mirror every chainage: refused
    back = TrackMap.from_latlon(*frame.to_geodetic(enu_track[::-1]), name="virtual",
                                tolerance_m=0.01)  # fmt: skip
    write_geojson(back, tmp_path / "back.geojson")
    assert main(["evaluate", str(tmp_path / "run"), "--truth-positions", gt, "--track",
                 str(tmp_path / "back.geojson")]) == 2  # fmt: skip
    assert "runs the other way" in capsys.readouterr().err


def test_calibrate_on_a_phone_log(
    test_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from locator.cli import main

    dev, gt = str(test_data / DEV), str(test_data / GT)
    # two epochs support no fit (and no overbound): refused, saying what to give
    assert main(["calibrate", "--device-gnss", dev, "--truth", gt, "--receiver-class", "phone",
                 "--out", str(tmp_path / "m.json")]) == 2  # fmt: skip
    assert "--device-gnss inputs" in capsys.readouterr().err
    assert main(["calibrate", "--device-gnss", dev, "--truth", gt, gt, "--out",
                 str(tmp_path / "m.json")]) == 2  # fmt: skip
    assert "one ground-truth file per --device-gnss file" in capsys.readouterr().err


def test_google_satellite_states_match_the_broadcast_orbits(test_data: Path) -> None:
    """Google's SvPosition / SvClockBias (its own ephemeris code) against this project's
    IS-GPS-200 orbits from the IGS broadcast file of the same day: the columns are the
    satellite's state at transmission in the Earth-fixed frame of that instant, and
    SvClockBiasMeters is clock + relativity - group delay."""
    from locator.corrections import RangeModel

    dev = read_device_gnss(test_data / "gsdc/google_decimeter_2022_device_gnss_1ep.csv")
    model = RangeModel.from_rinex_nav(test_data / "gsdc/rinex_nav_brdc1190.21n.gz")
    s = dev.signals["C1C"]
    cols = [j for j, sat in enumerate(dev.sats) if sat[0] == "G"]
    assert len(cols) == 7
    st = model.states(float(dev.gps_s[0]), tuple(dev.sats[j] for j in cols),
                      s["raw_pseudorange_m"][0, cols], ["C1C"] * len(cols))  # fmt: skip
    google = np.stack([s["sv_x_m"][0, cols], s["sv_y_m"][0, cols], s["sv_z_m"][0, cols]], -1)
    assert np.max(np.linalg.norm(st.pos_ecef_m - google, axis=1)) < 0.01
    ours = st.sat_clock_m + st.relativity_m - st.group_delay_m
    np.testing.assert_allclose(ours, s["sv_clock_bias_m"][0, cols], atol=1e-3)


@pytest.mark.parametrize(("col", "value", "match"), [
    ("utcTimeMillis", "1e308", "utcTimeMillis 1e\\+308 is not a time between 1980 and 2100"),
    ("utcTimeMillis", "-5", "utcTimeMillis -5 is not a time"),
    ("ArrivalTimeNanosSinceGpsEpoch", "9" * 25, "ArrivalTimeNanosSinceGpsEpoch differs by "
     "1e\\+16 s within utcTimeMillis 1694113198000"),
    ("Svid", "1e308", "ConstellationType or Svid is out of range"),
])  # fmt: skip
def test_times_and_ids_out_of_range_are_refused(
    test_data: Path, tmp_path: Path, col: str, value: str, match: str
) -> None:
    """Values that once overflowed the int64 conversion (found by hand after the fuzzing)."""

    def damage(ls: list[str]) -> list[str]:
        cells = ls[3].split(",")
        cells[ls[0].split(",").index(col)] = value
        ls[3] = ",".join(cells)
        return ls

    bad = _rewrite(test_data / DEV, tmp_path / "d.csv", damage)
    with pytest.raises(DeviceGnssError, match=r"d\.csv, line 4: " + match):
        read_device_gnss(bad)


def test_arrival_time_must_agree_with_utc(test_data: Path, tmp_path: Path) -> None:
    def shift(ls: list[str]) -> list[str]:
        k = ls[0].split(",").index("ArrivalTimeNanosSinceGpsEpoch")
        cells = ls[1].split(",")
        cells[k] = repr(float(cells[k]) + 5e9)  # 5 s late
        return [ls[0], ",".join(cells)]

    bad = _rewrite(test_data / DEV, tmp_path / "s.csv", shift)
    with pytest.raises(DeviceGnssError, match=r"s\.csv, line 2: ArrivalTimeNanosSinceGpsEpoch lies "
                                              r"5 s from utcTimeMillis 1694113198000"):
        read_device_gnss(bad)


def test_ground_truth_out_of_range_is_refused(test_data: Path, tmp_path: Path) -> None:
    for k, (col, match) in enumerate([(8, "UnixTimeMillis 1e\\+308 is not a time"),
                                      (2, "position 1e\\+308, .* is not a latitude")]):
        def damage(ls: list[str], c: int = col) -> list[str]:
            cells = ls[2].split(",")
            cells[c] = "1e308"
            ls[2] = ",".join(cells)
            return ls

        bad = _rewrite(test_data / GT, tmp_path / f"g{k}.csv", damage)
        with pytest.raises(DeviceGnssError, match=rf"g{k}\.csv, line 3: {match}"):
            read_ground_truth(bad)
