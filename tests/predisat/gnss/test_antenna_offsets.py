"""Satellite antenna offsets: body-frame geometry by hand, block table, sun, real orbits."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from predisat.gnss.antenna_offsets import (
    BLOCK_PCO_M,
    PCO_SOURCES,
    SVN_TABLE,
    block_pco_m,
    body_axes_ecef,
    com_from_apc,
    satellite_block,
    sun_direction_ecef,
)
from predisat.gnss.timescale import calendar_to_gps_s, utc_datetime64_to_gps_s

R_GPS_M = 26_560_000.0


def test_axes_of_a_satellite_on_the_x_axis_with_the_sun_along_y() -> None:
    # z toward the Earth = -x; the sun along +y is in the satellite's x direction;
    # y = z cross x = (-1, 0, 0) x (0, 1, 0) = (0, 0, -1)
    axes = body_axes_ecef([R_GPS_M, 0.0, 0.0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(axes, [[0, 1, 0], [0, 0, -1], [-1, 0, 0]], atol=1e-15)


def test_com_from_apc_by_hand() -> None:
    # APC = CoM + 0.5 e_x + 0.2 e_y + 2.0 e_z = CoM + (-2.0, 0.5, -0.2) with the axes above
    com = com_from_apc([R_GPS_M, 0.0, 0.0], [0.5, 0.2, 2.0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(com, [R_GPS_M + 2.0, -0.5, 0.2], atol=1e-9)


def test_sun_length_does_not_matter_and_x_leans_toward_the_sun() -> None:
    pos = np.array([R_GPS_M, 0.0, 0.0])
    sun = np.array([0.3, 1.0, 0.4])
    a = body_axes_ecef(pos, sun)
    b = body_axes_ecef(pos, 1.496e11 * sun)
    np.testing.assert_allclose(a, b, atol=1e-15)
    # the sun lies in the x-z plane, on the +x side
    assert a[0] @ sun > 0.0
    assert abs(a[1] @ sun) < 1e-12


def test_axes_are_a_right_handed_orthonormal_triad_and_z_offset_is_radial() -> None:
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(50, 3)) * R_GPS_M
    sun = rng.normal(size=(50, 3))
    axes = body_axes_ecef(pos, sun)
    gram = axes @ np.swapaxes(axes, -1, -2)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), (50, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(axes), 1.0, atol=1e-12)
    pco = np.array([0.394, 0.05, 1.407])
    com = com_from_apc(pos, pco, sun)
    r_hat = pos / np.linalg.norm(pos, axis=-1, keepdims=True)
    # the CoM is z_pco farther from the Earth; x/y offsets are perpendicular to the radius
    np.testing.assert_allclose(np.sum((com - pos) * r_hat, axis=-1), 1.407, atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(com - pos, axis=-1), np.linalg.norm(pco), atol=1e-7)


def test_sun_on_the_z_axis_leaves_x_y_undefined_but_a_z_offset_works() -> None:
    pos = [0.0, 0.0, R_GPS_M]
    axes = body_axes_ecef(pos, [0.0, 0.0, 1.0])
    assert np.all(np.isnan(axes[:2]))
    com = com_from_apc(pos, [0.0, 0.0, 2.0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(com, [0.0, 0.0, R_GPS_M + 2.0])
    assert np.all(np.isnan(com_from_apc(pos, [0.5, 0.0, 2.0], [0.0, 0.0, 1.0])))


def test_inputs_without_three_components_are_refused() -> None:
    with pytest.raises(ValueError, match="last axis of 3"):
        body_axes_ecef([1.0, 2.0], [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="pco_m"):
        com_from_apc([R_GPS_M, 0.0, 0.0], [1.0, 2.0], [0.0, 1.0, 0.0])


def test_blocks_follow_the_prn_history() -> None:
    t_2010 = calendar_to_gps_s(2010, 7, 1)
    # G25: SVN 35 (IIA) until 2010-05-27, SVN 62 (the first IIF) from 2010-05-28
    t = np.array([calendar_to_gps_s(2010, 5, 27, 23, 59), calendar_to_gps_s(2010, 5, 28), t_2010])
    blocks = satellite_block(["G25"], t)[:, 0]
    np.testing.assert_array_equal(blocks, ["BLOCK IIA", "BLOCK IIF", "BLOCK IIF"])
    b = satellite_block(["R01", "R02", "E01", "E11", "C01", "G04"], calendar_to_gps_s(2009, 4, 1))
    assert b.tolist() == [["GLONASS", "GLONASS-M", "", "", "", "BLOCK IIA"]]
    b = satellite_block(["R01", "E01", "E11", "G04"], calendar_to_gps_s(2023, 3, 14))
    assert b.tolist() == [["GLONASS-M", "GALILEO-2", "GALILEO-1", "BLOCK IIIA"]]
    pco = block_pco_m(b)
    assert pco.shape == (1, 4, 3)
    np.testing.assert_array_equal(pco[0, 0], [-0.545, 0.0, 2.450])
    assert np.all(np.isnan(pco[0, 3]))  # no published GPS IIIA value in the table


def test_table_is_consistent() -> None:
    assert set(BLOCK_PCO_M) == set(PCO_SOURCES)
    known_without_values = {"BLOCK IIIA", "GLONASS-K1", "GLONASS-K2"}
    for prn in {row[0] for row in SVN_TABLE}:
        rows = sorted((r for r in SVN_TABLE if r[0] == prn), key=lambda r: r[3])
        for row in rows:
            assert row[2] in BLOCK_PCO_M or row[2] in known_without_values, row
            assert row[4] is None or row[4] >= row[3], row
        for prev, nxt in itertools.pairwise(rows):
            assert prev[4] is not None and prev[4] < nxt[3], (prev, nxt)  # no overlap


def test_sun_direction_at_equinox_and_solstice() -> None:
    # March equinox 2023-03-20 21:24 UTC: declination 0; June solstice 2021-06-21 03:32 UTC:
    # declination +23.44 deg (obliquity of the ecliptic)
    t = utc_datetime64_to_gps_s(
        np.array(["2023-03-20T21:24", "2021-06-21T03:32"], dtype="datetime64[ns]")
    )
    s = sun_direction_ecef(t)
    np.testing.assert_allclose(np.linalg.norm(s, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.degrees(np.arcsin(s[:, 2])), [0.0, 23.44], atol=0.02)
    # at 12:00 UTC on 2021-04-15 the equation of time is about zero: the sun is over Greenwich
    noon = sun_direction_ecef(utc_datetime64_to_gps_s(np.datetime64("2021-04-15T12:00", "ns")))
    assert abs(np.degrees(np.arctan2(noon[1], noon[0]))) < 0.5


def test_corrected_broadcast_meets_the_precise_centre_of_mass(shared_data: Path) -> None:
    """2021 GPS IIF and IIR-M: the radial difference drops from -1.5/-0.75 m to about 0."""
    from predisat.gnss.ephemeris import Ephemeris

    gnss = shared_data / "gnss" / "gnss_lib_py"
    brdc = Ephemeris.from_rinex(gnss / "rinex_nav_brdc1180.21n")
    prec = Ephemeris.from_sp3(gnss / "sp3_COD0MGXFIN_20211180000_01D_05M_ORB.SP3")
    sats = ["G01", "G03", "G05", "G07", "G12", "G24"]  # IIF, IIF, IIR-M, IIR-M, IIR-M, IIF
    assert prec.sp3 is not None
    t = prec.sp3.epochs_gps_s
    apc, ref = brdc.position_ecef(t, sats), prec.position_ecef(t, sats)
    com = com_from_apc(apc, block_pco_m(satellite_block(sats, t)), sun_direction_ecef(t)[:, None])
    r_hat = ref / np.linalg.norm(ref, axis=-1, keepdims=True)
    raw = np.nanmean(np.sum((apc - ref) * r_hat, axis=-1), axis=0)
    cor = np.nanmean(np.sum((com - ref) * r_hat, axis=-1), axis=0)
    assert np.all(raw < -0.6)
    assert np.all(np.abs(cor) < 0.3)
