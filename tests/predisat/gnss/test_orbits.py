"""Broadcast orbit computation against analytic orbits, an independent integrator and SP3."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from predisat.geodesy import ecef_to_geodetic
from predisat.gnss.orbits import KEPLER_CONSTANTS, glonass_state, kepler_state
from predisat.gnss.rinex_nav import KEPLER_FIELDS, NavRecords, read_rinex_nav
from predisat.gnss.sp3 import read_sp3


def _nearest(rec: NavRecords, sat: str, t: np.ndarray) -> np.ndarray:
    rows = np.nonzero(rec.sat == sat)[0]
    return rows[np.argmin(np.abs(t[:, None] - rec.ref_gps_s[rows][None, :]), axis=1)]


def _compare(rec: NavRecords, sp3, sats, state, max_age_s):
    errs = []
    for sat in sats:
        j = sp3.sats.index(sat)
        t = sp3.epochs_gps_s
        idx = _nearest(rec, sat, t)
        ok = (np.abs(t - rec.ref_gps_s[idx]) <= max_age_s) & np.isfinite(sp3.pos_ecef_m[:, j, 0])
        pos, _ = state(rec, idx[ok], t[ok])
        errs.append(np.linalg.norm(pos - sp3.pos_ecef_m[ok, j], axis=-1))
    return np.concatenate(errs)


def test_kepler_circular_equatorial_orbit_is_analytic() -> None:
    sqrt_a = 5153.7
    toe_sow = 345600.0
    vals = np.zeros((1, len(KEPLER_FIELDS)))
    f = KEPLER_FIELDS.index
    vals[0, f("sqrt_a_sqrtm")] = sqrt_a
    vals[0, f("toe_sow_s")] = toe_sow
    vals[0, f("m0_rad")] = 0.3
    vals[0, f("af0_s")] = 1e-4
    vals[0, f("af1_sps")] = 1e-11
    ref = 1590 * 604800.0 + toe_sow
    rec = NavRecords(
        "kepler", np.array(["G01"]), np.array([ref]), np.array([ref]), vals, KEPLER_FIELDS,
        np.array(["x:1"], object),
    )  # fmt: skip
    tk = np.array([-3600.0, 0.0, 1800.0, 7200.0])
    pos, clk = kepler_state(rec, np.zeros(4, int), ref + tk)
    mu, we = KEPLER_CONSTANTS["G"]
    a = sqrt_a**2
    lon = 0.3 + np.sqrt(mu / a**3) * tk - we * (tk + toe_sow)
    np.testing.assert_allclose(pos[:, 0], a * np.cos(lon), atol=1e-4)
    np.testing.assert_allclose(pos[:, 1], a * np.sin(lon), atol=1e-4)
    np.testing.assert_allclose(pos[:, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(clk, 1e-4 + 1e-11 * tk, rtol=1e-12)


def _pz90_rhs(_t, s, acc):
    # written out separately from predisat.gnss.orbits, from the GLONASS ICD 5.1 (A.3.1.2)
    mu, ae, j2, w = 398600.4418e9, 6378136.0, 1082625.75e-9, 7.292115e-5
    x, y, z, vx, vy, vz = s
    r = np.sqrt(x * x + y * y + z * z)
    c = 1.5 * j2 * mu * ae**2 / r**5
    return [
        vx,
        vy,
        vz,
        -mu * x / r**3 - c * x * (1 - 5 * z * z / r**2) + w * w * x + 2 * w * vy + acc[0],
        -mu * y / r**3 - c * y * (1 - 5 * z * z / r**2) + w * w * y - 2 * w * vx + acc[1],
        -mu * z / r**3 - c * z * (3 - 5 * z * z / r**2) + acc[2],
    ]


def test_glonass_rk4_matches_scipy_dop853(test_data: Path) -> None:
    rec = read_rinex_nav(test_data / "gnss/brdc0910_R02R08.09g").glonass
    i = 0
    v = dict(zip(rec.fields, rec.values[i], strict=True))
    s0 = [v[k] * 1e3 for k in ("x_km", "y_km", "z_km", "vx_kmps", "vy_kmps", "vz_kmps")]
    acc = [v[k] * 1e3 for k in ("ax_kmps2", "ay_kmps2", "az_kmps2")]
    for dt in (-900.0, 450.0, 900.0):
        sol = solve_ivp(_pz90_rhs, (0.0, dt), s0, args=(acc,), method="DOP853", rtol=1e-12,
                        atol=1e-6)  # fmt: skip
        pos, clk = glonass_state(rec, [i], [rec.ref_gps_s[i] + dt])
        assert np.linalg.norm(pos[0] - sol.y[:3, -1]) < 1e-3
        assert clk[0] == pytest.approx(v["minus_tau_n_s"] + v["gamma_n"] * dt)


def test_gps_2010_against_igs_final(test_data: Path) -> None:
    rec = read_rinex_nav(test_data / "gnss/brdc1820_G01G02G05.10n").kepler
    sp3 = read_sp3(test_data / "gnss/igs15904_G01G02G05.sp3")
    err = _compare(rec, sp3, ["G02", "G05"], kepler_state, 7200.0)  # G01 is unhealthy
    assert len(err) == 64
    assert np.sqrt(np.mean(err**2)) <= 3.0
    assert err.max() < 6.0


def test_gps_galileo_2023_against_code_rapid(test_data: Path) -> None:
    rec = read_rinex_nav(test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx").kepler
    sp3 = read_sp3(test_data / "gnss/sp3_COD0OPSRAP_20230730000_01D_05M_ORB.SP3")
    for sats in (["G01", "G02"], ["E01", "E02"]):
        err = _compare(rec, sp3, sats, kepler_state, 7200.0)
        assert len(err) == 6
        assert np.sqrt(np.mean(err**2)) <= 3.0


def test_glonass_2009_against_igs_final(test_data: Path) -> None:
    rec = read_rinex_nav(test_data / "gnss/brdc0910_R02R08.09g").glonass
    sp3 = read_sp3(test_data / "gnss/igl15253_R02R08.sp3")
    err = _compare(rec, sp3, ["R02", "R08"], glonass_state, 900.0)
    assert len(err) >= 50
    # 2009 GLONASS broadcast orbits were good to a few metres (plus ~2 m antenna offset)
    assert np.sqrt(np.mean(err**2)) <= 5.0


def test_beidou_geo_is_geostationary(test_data: Path) -> None:
    rec = read_rinex_nav(test_data / "gnss/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx").kepler
    for sat in ("C01", "C02"):
        row = np.nonzero(rec.sat == sat)[0][0]
        # the elements are given in a frame tilted by 5 deg (i0 ~ 5.2 deg); only with the GEO
        # rotation does the latitude stay near 0 over a whole orbit
        assert np.degrees(rec.col("i0_rad")[row]) > 4.0
        t = rec.ref_gps_s[row] + np.arange(-12 * 3600.0, 12 * 3600.0 + 1, 1800.0)
        pos, _ = kepler_state(rec, np.full(len(t), row), t)
        lat, lon, _ = ecef_to_geodetic(pos)
        assert np.all(np.abs(lat) < 2.0)
        assert np.ptp(lon) < 1.0
        np.testing.assert_allclose(np.linalg.norm(pos, axis=-1), 42164e3, atol=100e3)


@pytest.mark.shared
def test_beidou_geo_over_nominal_slot(shared_data: Path) -> None:
    nav = read_rinex_nav(shared_data / "gnss/georust_rinex/ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    rec = nav.kepler
    row = np.nonzero(rec.sat == "C05")[0][0]
    pos, _ = kepler_state(rec, [row], [rec.ref_gps_s[row]])
    lat, lon, _ = ecef_to_geodetic(pos)
    assert abs(lon[0] - 58.75) < 0.5  # BeiDou-2 G6 (C05), slot 58.75 E
    assert abs(lat[0]) < 2.0


@pytest.mark.shared
def test_full_files_against_sp3(shared_data: Path) -> None:
    g = shared_data / "gnss"
    rec = read_rinex_nav(g / "gnss_lib_py/rinex_nav_brdc1180.21n").kepler
    sp3 = read_sp3(g / "gnss_lib_py/sp3_COD0MGXFIN_20211180000_01D_05M_ORB.SP3")
    sats = sorted({s for s in rec.sat.tolist() if s in sp3.sats})
    err = _compare(rec, sp3, sats, kepler_state, 7200.0)
    assert len(err) > 2000
    assert np.sqrt(np.mean(err**2)) <= 3.0
