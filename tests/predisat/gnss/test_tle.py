"""TLE reader and SGP4 propagation against skyfield."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from predisat.gnss.ephemeris import Ephemeris
from predisat.gnss.timescale import calendar_to_gps_s
from predisat.gnss.tle import TleError, read_tle, satellite_id_from_name


def test_names_to_ids() -> None:
    assert satellite_id_from_name("G32") == "G32"
    assert satellite_id_from_name("C02 # Beidou G6") == "C02"
    assert satellite_id_from_name("GPS BIIR-2  (PRN 13)") == "G13"
    assert satellite_id_from_name("GSAT0101 (PRN E11)") == "E11"
    assert satellite_id_from_name("BEIDOU-3 M1 (C19)") == "C19"
    assert satellite_id_from_name("COSMOS 2456 (730)") is None


def test_read_rtklib_tle(test_data: Path) -> None:
    tle = read_tle(test_data / "gnss/TLE_GNSS_20121101.txt")
    assert len(tle.sats) == 93  # 95 sets minus the two commented out
    assert "G32" in tle.sats and "E11" in tle.sats and "C01" in tle.sats
    assert "R17" in tle.sats and "R17:28915" in tle.sats  # two sets named R17
    i = tle.sats.index("G32")
    # "1 20959U 90103A   12305.07451262": day 305.07451262 of 2012 (UTC) + 16 leap seconds
    expected = calendar_to_gps_s(2012, 10, 31) + 0.07451262 * 86400.0 + 16.0
    assert tle.epochs_gps_s[i] == pytest.approx(expected, abs=1e-3)


def test_azel_matches_skyfield(test_data: Path) -> None:
    sf = pytest.importorskip("skyfield.api")
    path = test_data / "gnss/TLE_GNSS_20121101.txt"
    eph = Ephemeris.from_tle(path)
    assert eph.tle is not None
    lat, lon, h = 50.5616, 4.6928, 160.0
    hours = np.arange(0.0, 24.0, 2.0)
    t = calendar_to_gps_s(2012, 11, 1) + hours * 3600.0 + 16.0  # 00:00 UTC + leap seconds
    az, el = eph.azel(t, lat, lon, h)
    ts = sf.load.timescale(builtin=True)
    tt = ts.utc(2012, 11, 1, hours)
    site = sf.wgs84.latlon(lat, lon, elevation_m=h)
    n_visible = 0
    for j in range(0, len(eph.satellites), 3):  # every third satellite keeps the test fast
        sat = sf.EarthSatellite(eph.tle.line1[j], eph.tle.line2[j], ts=ts)
        alt, azs, _ = (sat - site).at(tt).altaz()
        vis = alt.degrees > 0
        n_visible += int(vis.sum())
        daz = (az[vis, j] - azs.degrees[vis] + 180.0) % 360.0 - 180.0
        assert np.all(np.abs(el[vis, j] - alt.degrees[vis]) < 0.05)
        assert np.all(np.abs(daz * np.cos(np.radians(alt.degrees[vis]))) < 0.05)
    assert n_visible > 50


def test_errors_name_file_and_line(tmp_path: Path, test_data: Path) -> None:
    lines = (test_data / "gnss/TLE_GNSS_20121101.txt").read_text().splitlines()
    p = tmp_path / "bad.txt"
    bad = list(lines[:8])
    bad[5] = bad[5][:30] + ("1" if bad[5][30] != "1" else "2") + bad[5][31:]  # checksum breaks
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(TleError, match=r"bad.txt, line 6: checksum"):
        read_tle(p)
    p.write_text("\n".join(lines[:6]) + "\n")  # line 1 without its line 2
    with pytest.raises(TleError, match="line 6: line 1 of an element set"):
        read_tle(p)
    with pytest.raises(TleError, match="no such file"):
        read_tle(tmp_path / "none.txt")
