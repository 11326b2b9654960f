"""Evaluate broadcast and TLE orbits against precise orbits and skyfield.

Broadcast-derived positions (RINEX nav -> predisat.gnss.orbits) are compared with SP3 precise orbits
at the SP3 epochs, for every matched file pair of ``../shared/data/gnss``, per constellation:
3-D RMS and maximum, mean radial difference and clock RMS after removing each epoch's common
offset (the SP3 reference clock). Only pairs the ephemeris trusts (healthy, inside the validity
window) are compared; distrusted satellites are counted.

Broadcast orbits refer to the antenna phase centre (APC), SP3 to the centre of mass (CoM). Each
figure is given twice: raw (APC vs CoM) and PCO-corrected, the broadcast position moved to the
CoM with the IGS ANTEX block offsets of ``predisat.gnss.antenna_offsets`` in the nominal
yaw-steering
attitude (sun from ``predisat.synth.sky``). Satellites of a block without a published offset in
that table (GPS IIIA, GLONASS-K) are left uncorrected and listed. The mean radial difference per
satellite block shows which antenna offsets the broadcast orbits really refer to.

GLONASS detail: per-satellite RMS, radial / along-track / cross-track decomposition (RTN, with
the inertial velocity), and the error as a function of the time from the record's reference
epoch tb, also beyond the +-15 min validity window (every healthy record evaluated directly).

TLE-derived azimuth/elevation (predisat.gnss.tle, sgp4) are compared with skyfield's for the same
TLEs, and with the broadcast orbits of the same day (to show what "coarse" means).

``--figure PNG`` draws the broadcast-minus-SP3 error over a whole day of GPS (2010-07-01) and of
GLONASS (2009-04-01) (``docs/figures/ephemerides_orbits.png``).

Usage::

    .venv/bin/python scripts/eval_orbits.py [--data ../shared/data/gnss] [--out results.md|.json]
        [--figure docs/figures/ephemerides_orbits.png]
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from predisat.geodesy import enu_rotation, enu_to_azel, geodetic_to_ecef
from predisat.gnss.antenna_offsets import (
    BLOCK_PCO_M,
    block_pco_m,
    com_from_apc,
    satellite_block,
    sun_direction_ecef,
)
from predisat.gnss.ephemeris import Ephemeris, Reason
from predisat.gnss.orbits import glonass_state
from predisat.gnss.timescale import calendar_to_gps_s, gps_s_to_utc_datetime64

PAIRS = [
    # (label, nav files, sp3 files)
    ("GPS 2010-07-01 IGS final", ["rtklib/brdc1820.10n"], ["rtklib/igs15904.sp3"]),
    ("GPS 2010-07-02 IGS final", ["rtklib/brdc1830.10n"], ["rtklib/igs15905.sp3"]),
    ("GLONASS 2009-04-01 IGS (igl)", ["rtklib/brdc0910.09g"], ["rtklib/igl15253.sp3"]),
    ("GLONASS 2009-04-01 ESA", ["rtklib/brdc0910.09g"], ["rtklib/esa15253.sp3"]),
    (
        "G/R/E 2023-03-14 BRDC00WRD vs CODE rapid",
        ["gnss_lib_py/rinex_nav_BRDC00WRD_S_20230730000_01D_MN.rnx"],
        ["gnss_lib_py/sp3_COD0OPSRAP_20230730000_01D_05M_ORB.SP3"],
    ),
    (
        "G/R/E 2023-03-14 BRDM00DLR vs CODE rapid",
        ["gnss_lib_py/rinex_nav_BRDM00DLR_S_20230730000_01D_MN.rnx"],
        ["gnss_lib_py/sp3_COD0OPSRAP_20230730000_01D_05M_ORB.SP3"],
    ),
    (
        "GPS 2021-04-28 vs CODE MGEX final",
        ["gnss_lib_py/rinex_nav_brdc1180.21n"],
        ["gnss_lib_py/sp3_COD0MGXFIN_20211180000_01D_05M_ORB.SP3"],
    ),
]

SITE = (50.5616, 4.6928, 160.0)  # Gembloux (line 144), for the TLE az/el comparison


OMEGA_EARTH_RADPS = 7.2921151467e-5
AGE_BINS_S = (0.0, 300.0, 600.0, 900.0, 1200.0, 1800.0, 2700.0)


def _radial(pos_a: np.ndarray, pos_b: np.ndarray) -> np.ndarray:
    r = pos_b / np.linalg.norm(pos_b, axis=-1, keepdims=True)
    return np.sum((pos_a - pos_b) * r, axis=-1)


def _rtn(diff_m: np.ndarray, pos_m: np.ndarray, vel_ecef_mps: np.ndarray) -> np.ndarray:
    """Radial, along-track, cross-track components (..., 3) of ECEF differences.

    The along-track axis follows the inertial velocity (ECEF velocity + omega x r): the ECEF
    velocity of a 64-deg orbit is tilted by up to 25 deg from it.
    """
    v_inertial = vel_ecef_mps + np.cross([0.0, 0.0, OMEGA_EARTH_RADPS], pos_m)
    e_r = pos_m / np.linalg.norm(pos_m, axis=-1, keepdims=True)
    e_c = np.cross(pos_m, v_inertial)
    e_c = e_c / np.linalg.norm(e_c, axis=-1, keepdims=True)
    e_a = np.cross(e_c, e_r)
    return np.stack([np.sum(diff_m * e, axis=-1) for e in (e_r, e_a, e_c)], axis=-1)


def _stats(err_m: np.ndarray, radial_m: np.ndarray) -> dict:
    return {
        "rms_m": float(np.sqrt(np.mean(err_m**2))),
        "max_m": float(err_m.max()),
        "mean_radial_m": float(radial_m.mean()),
    }


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def compare_pair(data: Path, label: str, navs: list[str], sp3s: list[str]) -> dict:
    """Broadcast vs SP3 for one file pair: per-system rows, per-block radials, GLONASS detail."""
    brdc = Ephemeris.from_rinex([data / f for f in navs])
    prec = Ephemeris.from_sp3([data / f for f in sp3s])
    assert prec.sp3 is not None
    t = prec.sp3.epochs_gps_s
    sats = [s for s in prec.satellites if s in brdc.satellites]
    pb, cb, st = brdc.evaluate(t, sats)
    pp, cp, _ = prec.evaluate(t, sats)
    blocks = satellite_block(sats, t)
    pco = block_pco_m(blocks)
    # blocks without a published offset stay at the APC (listed in the report)
    pc = com_from_apc(pb, np.nan_to_num(pco, nan=0.0), sun_direction_ecef(t)[:, None, :])
    ok_all = np.all(np.isfinite(pb), -1) & np.all(np.isfinite(pp), -1)
    rows = []
    for system in sorted({s[0] for s in sats}):
        cols = [j for j, s in enumerate(sats) if s[0] == system]
        a, ac, b = pb[:, cols], pc[:, cols], pp[:, cols]
        ok = ok_all[:, cols]
        n_bad = {
            Reason(r).name: sorted(
                {sats[cols[j]] for j in np.nonzero((st.reason[:, cols] == r).any(0))[0]}
            )
            for r in (Reason.UNHEALTHY, Reason.INCONSISTENT, Reason.OUTSIDE_VALIDITY)
        }
        if not ok.any():
            rows.append({"pair": label, "system": system, "n": 0, "distrusted": n_bad})
            continue
        err = np.linalg.norm(a - b, axis=-1)
        err_c = np.linalg.norm(ac - b, axis=-1)
        # clocks: remove each epoch's common offset (reference clock of the SP3 solution)
        dc = (cb[:, cols] - cp[:, cols]) * 299792458.0
        dc = np.where(ok, dc, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN epochs stay NaN
            dc = dc - np.nanmedian(dc, axis=1, keepdims=True)
        dc = dc[np.isfinite(dc)]
        no_pco = np.isnan(pco[:, cols, 2]) & ok
        rows.append(
            {
                "pair": label,
                "system": system,
                "n_sat": int(ok.any(0).sum()),
                "n": int(ok.sum()),
                "raw": _stats(err[ok], _radial(a, b)[ok]),
                "pco": _stats(err_c[ok], _radial(ac, b)[ok]),
                "worst_sat": sats[cols[int(np.argmax(np.where(ok, err, -1)) % len(cols))]],
                "worst_sat_pco": sats[cols[int(np.argmax(np.where(ok, err_c, -1)) % len(cols))]],
                "no_pco": sorted(
                    {
                        f"{sats[cols[j]]} ({blocks[:, cols][:, j][no_pco[:, j]][0] or 'unknown'})"
                        for j in np.nonzero(no_pco.any(0))[0]
                    }
                ),
                "clock_rms_m": float(np.sqrt(np.mean(dc**2))) if dc.size else float("nan"),
                "distrusted": n_bad,
            }
        )
    by_block = []
    for block in sorted(set(blocks[ok_all].tolist())):
        sel = ok_all & (blocks == block)
        by_block.append(
            {
                "pair": label,
                "block": block or "unknown",
                "n_sat": int(sel.any(0).sum()),
                "n": int(sel.sum()),
                "pco_z_m": BLOCK_PCO_M[block][2] if block in BLOCK_PCO_M else float("nan"),
                "mean_radial_raw_m": float(_radial(pb, pp)[sel].mean()),
                "mean_radial_pco_m": float(_radial(pc, pp)[sel].mean()),
            }
        )
    out: dict = {"rows": rows, "by_block": by_block}
    glo = [j for j, s in enumerate(sats) if s[0] == "R"]
    if glo and ok_all[:, glo].any():
        glo_sats = [sats[j] for j in glo]
        out["glonass"] = glonass_detail(
            brdc, t, glo_sats, pb[:, glo], pc[:, glo], pp[:, glo], ok_all[:, glo]
        )
        out["glonass"]["age_profile"] = glonass_age_profile(brdc, prec, glo_sats)
    return out


def glonass_detail(
    brdc: Ephemeris,
    t: np.ndarray,
    sats: list[str],
    apc: np.ndarray,
    com: np.ndarray,
    sp3: np.ndarray,
    ok: np.ndarray,
) -> dict:
    """Per-satellite RMS, RTN decomposition and error vs time from tb of trusted GLONASS pairs."""
    # velocity by a 1-s central difference of the same broadcast evaluation
    vel = brdc.position_ecef(t + 0.5, sats) - brdc.position_ecef(t - 0.5, sats)
    rtn = _rtn(com - sp3, sp3, vel)
    good = ok & np.all(np.isfinite(rtn), -1)
    err_raw = np.linalg.norm(apc - sp3, axis=-1)
    err = np.linalg.norm(com - sp3, axis=-1)
    per_sat = []
    for j, sat in enumerate(sats):
        m = good[:, j]
        if m.any():
            per_sat.append(
                {
                    "sat": sat,
                    "n": int(m.sum()),
                    "rms_raw_m": _rms(err_raw[m, j]),
                    "rms_pco_m": _rms(err[m, j]),
                    "mean_rtn_m": [float(x) for x in rtn[m, j].mean(0)],
                }
            )
    v = rtn[good]
    assert brdc.glonass is not None
    rec = brdc.glonass
    age = np.full(ok.shape, np.nan)
    for j, sat in enumerate(sats):
        ref = np.unique(rec.ref_gps_s[rec.sat == sat])
        if len(ref):
            age[:, j] = np.min(np.abs(t[:, None] - ref[None, :]), axis=1)
    bins = []
    for lo, hi in itertools.pairwise(AGE_BINS_S[:4]):  # inside the +-15 min window
        m = good & (age >= lo) & (age < hi)
        bins.append({"age_s": [lo, hi], "n": int(m.sum()), "rms_pco_m": _rms(err[m])})
    return {
        "n": int(good.sum()),
        "rtn_rms_m": [_rms(v[:, k]) for k in range(3)],
        "rtn_mean_m": [float(v[:, k].mean()) for k in range(3)],
        "per_sat": per_sat,
        "by_age": bins,
    }


def glonass_age_profile(brdc: Ephemeris, prec: Ephemeris, sats: list[str]) -> list[dict]:
    """PCO-corrected error of every healthy GLONASS record at the SP3 epochs within 45 min of tb.

    This ignores the +-15 min validity window on purpose: an integration error grows with
    |t - tb|, an error of the broadcast state vector does not. Also reported: the mean
    along-track error and the time offset along the ECEF velocity that best explains the
    differences (a time-scale error would shift every satellite by the same time).
    """
    assert brdc.glonass is not None and prec.sp3 is not None
    rec, sp3 = brdc.glonass, prec.sp3
    t = sp3.epochs_gps_s
    # one healthy record per (satellite, tb): merged files repeat records station by station
    healthy = rec.col("health") == 0
    rows: list[int] = []
    for sat in sats:
        cand = np.nonzero((rec.sat == sat) & healthy)[0]
        rows.extend(cand[np.unique(rec.ref_gps_s[cand], return_index=True)[1]])
    if not rows:
        return []
    rec_i, ep_j = np.nonzero(np.abs(t[None, :] - rec.ref_gps_s[rows][:, None]) < AGE_BINS_S[-1])
    idx, ts = np.asarray(rows)[rec_i], t[ep_j]
    sat_of = rec.sat[idx]
    ref = np.full((len(idx), 3), np.nan)
    blocks = np.full(len(idx), "", dtype="<U16")
    for sat in sats:
        m = sat_of == sat
        ref[m] = sp3.position_at(ts[m], [sat])[:, 0]
        blocks[m] = satellite_block([sat], ts[m])[:, 0]
    fin = np.isfinite(ref[:, 0])
    idx, ts, ref, blocks = idx[fin], ts[fin], ref[fin], blocks[fin]
    if not len(idx):
        return []
    # one vectorised integration for every (record, epoch) pair
    apc, _ = glonass_state(rec, idx, ts)
    vel = glonass_state(rec, idx, ts + 0.5)[0] - glonass_state(rec, idx, ts - 0.5)[0]
    pco = np.nan_to_num(block_pco_m(blocks), nan=0.0)
    d = com_from_apc(apc, pco, sun_direction_ecef(ts)) - ref
    age = ts - rec.ref_gps_s[idx]
    rtn = _rtn(d, ref, vel)
    out = []
    for lo, hi in itertools.pairwise(AGE_BINS_S):
        m = (np.abs(age) >= lo) & (np.abs(age) < hi)
        if not m.any():
            continue
        out.append(
            {
                "age_s": [lo, hi],
                "n": int(m.sum()),
                "rms_pco_m": _rms(np.linalg.norm(d[m], axis=-1)),
                "rtn_rms_m": [_rms(rtn[m, k]) for k in range(3)],
                "mean_along_m": float(rtn[m, 1].mean()),
                "time_offset_ms": float(np.sum(d[m] * vel[m]) / np.sum(vel[m] ** 2) * 1e3),
            }
        )
    return out


def compare_tle(data: Path) -> dict:
    out: dict = {}
    tle = Ephemeris.from_tle(data / "rtklib/TLE_GNSS_20121101.txt")
    t = calendar_to_gps_s(2012, 11, 1) + np.arange(0.0, 86400.0, 600.0)
    az, el = tle.azel(t, *SITE)
    try:
        from skyfield.api import EarthSatellite, load, wgs84
    except ImportError:
        out["skyfield"] = "skyfield not installed: comparison skipped"
    else:
        assert tle.tle is not None
        ts = load.timescale(builtin=True)
        utc = gps_s_to_utc_datetime64(t)
        sec = (utc - utc.astype("datetime64[D]")) / np.timedelta64(1, "s")
        days = utc.astype("datetime64[D]").astype(object)
        tt = ts.utc(
            [d.year for d in days], [d.month for d in days], [d.day for d in days], 0, 0, sec
        )
        site = wgs84.latlon(SITE[0], SITE[1], elevation_m=SITE[2])
        d_az, d_el = [], []
        for j, (l1, l2) in enumerate(zip(tle.tle.line1, tle.tle.line2, strict=True)):
            alt, azs, _ = (EarthSatellite(l1, l2, ts=ts) - site).at(tt).altaz()
            vis = el[:, j] > 0
            daz = (az[:, j] - azs.degrees + 180.0) % 360.0 - 180.0
            d_az.append(np.abs(daz * np.cos(np.radians(el[:, j])))[vis])
            d_el.append(np.abs(el[:, j] - alt.degrees)[vis])
        out["skyfield_max_daz_cos_el_deg"] = float(np.max(np.concatenate(d_az)))
        out["skyfield_max_del_deg"] = float(np.max(np.concatenate(d_el)))
        out["skyfield_n"] = int(sum(len(x) for x in d_el))
    # TLE vs broadcast of the same day, angle between directions from the site
    brdc = Ephemeris.from_rinex([data / "rtklib/brdc3050.12n", data / "rtklib/brdc3050.12g"])
    t2 = calendar_to_gps_s(2012, 10, 31, 12) + np.arange(0.0, 6 * 3600.0, 600.0)
    sats = [s for s in tle.satellites if s in brdc.satellites]
    rx = geodetic_to_ecef(*SITE)
    rot = enu_rotation(SITE[0], SITE[1])
    a = tle.position_ecef(t2, sats) - rx
    b = brdc.position_ecef(t2, sats) - rx
    _, el_b, _ = enu_to_azel(b @ rot.T)
    cosang = np.sum(a * b, -1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
    ang = np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    ok = np.isfinite(ang) & (el_b > 0)
    for system in sorted({s[0] for s in sats}):
        cols = np.array([s[0] == system for s in sats])
        v = ang[:, cols][ok[:, cols]]
        if v.size:
            out[f"tle_vs_broadcast_{system}_rms_deg"] = float(np.sqrt(np.mean(v**2)))
            out[f"tle_vs_broadcast_{system}_max_deg"] = float(v.max())
    return out


def speed(data: Path) -> dict:
    eph = Ephemeris.from_rinex(data / "georust_rinex/ESBC00DNK_R_20201770000_01D_MN.rnx.gz")
    t = calendar_to_gps_s(2020, 6, 25) + np.arange(0.0, 86400.0, 30.0)
    res = {}
    for name, sats in (
        ("kepler", [s for s in eph.satellites if s[0] != "R"]),
        ("glonass", [s for s in eph.satellites if s[0] == "R"]),
    ):
        t0 = time.perf_counter()
        pos, _, _ = eph.evaluate(t, sats)
        dt = time.perf_counter() - t0
        res[name] = {
            "pairs": int(pos.shape[0] * pos.shape[1]),
            "evaluated": int(np.isfinite(pos[..., 0]).sum()),
            "seconds": round(dt, 3),
        }
    return res


def _orbit_lines(pairs: list[dict]) -> list[str]:
    rows = [r for p in pairs for r in p["rows"]]
    lines = [
        "# Broadcast orbits vs SP3 precise orbits",
        "",
        "Each figure raw (broadcast APC vs SP3 CoM) / PCO-corrected (broadcast moved to the CoM).",
        "",
        "| pair | sys | sats | n | RMS 3D m | max m | worst | mean radial m | clock RMS m |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["n"] == 0:
            lines.append(f"| {r['pair']} | {r['system']} | 0 | 0 | - | - | - | - | - |")
            continue
        raw, cor = r["raw"], r["pco"]
        lines.append(
            f"| {r['pair']} | {r['system']} | {r['n_sat']} | {r['n']} | "
            f"{raw['rms_m']:.2f} / {cor['rms_m']:.2f} | {raw['max_m']:.2f} / {cor['max_m']:.2f} | "
            f"{r['worst_sat']} / {r['worst_sat_pco']} | "
            f"{raw['mean_radial_m']:+.2f} / {cor['mean_radial_m']:+.2f} | {r['clock_rms_m']:.2f} |"
        )
    lines += ["", "Left at the APC (no published offset in predisat.gnss.antenna_offsets):", ""]
    lines += [
        f"* {r['pair']} {r['system']}: {', '.join(r['no_pco'])}" for r in rows if r.get("no_pco")
    ]
    lines += ["", "Distrusted satellites (never compared):", ""]
    for r in rows:
        for reason, sats in r["distrusted"].items():
            if sats:
                lines.append(f"* {r['pair']} {r['system']}: {reason} {', '.join(sats)}")
    lines += [
        "",
        "# Mean radial difference (broadcast - SP3) per satellite block",
        "",
        "| pair | block | sats | n | PCO z m | mean radial raw m | mean radial corrected m |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in pairs:
        for b in p["by_block"]:
            lines.append(
                f"| {b['pair']} | {b['block']} | {b['n_sat']} | {b['n']} | {b['pco_z_m']:.3f} | "
                f"{b['mean_radial_raw_m']:+.2f} | {b['mean_radial_pco_m']:+.2f} |"
            )
    for p in pairs:
        if "glonass" not in p:
            continue
        g = p["glonass"]
        label = p["rows"][0]["pair"]
        r, a, c = g["rtn_rms_m"]
        mr, ma, mc = g["rtn_mean_m"]
        lines += [
            "",
            f"# GLONASS detail: {label}",
            "",
            f"PCO-corrected, {g['n']} trusted pairs: RMS radial {r:.2f} m, along-track {a:.2f} m, "
            f"cross-track {c:.2f} m; mean radial {mr:+.2f} m, along-track {ma:+.2f} m, "
            f"cross-track {mc:+.2f} m.",
            "",
            "| sat | n | RMS raw m | RMS corrected m | mean R m | mean A m | mean C m |",
            "|---|---|---|---|---|---|---|",
        ]
        for s in g["per_sat"]:
            mr, ma, mc = s["mean_rtn_m"]
            lines.append(
                f"| {s['sat']} | {s['n']} | {s['rms_raw_m']:.2f} | {s['rms_pco_m']:.2f} | "
                f"{mr:+.2f} | {ma:+.2f} | {mc:+.2f} |"
            )
        lines += [
            "",
            "Trusted pairs by |t - tb| (PCO-corrected RMS 3D): "
            + "; ".join(
                f"{int(b['age_s'][0]) // 60}-{int(b['age_s'][1]) // 60} min: "
                f"{b['rms_pco_m']:.2f} m (n={b['n']})"
                for b in g["by_age"]
                if b["n"]
            ),
            "",
            "Every healthy record vs SP3 within 45 min of tb, ignoring the validity window:",
            "",
            "| abs(t - tb) min | n | RMS 3D m | RMS R / A / C m | mean along m | time offset ms |",
            "|---|---|---|---|---|---|",
        ]
        for b in g["age_profile"]:
            lo, hi = (int(x) // 60 for x in b["age_s"])
            rr, aa, cc = b["rtn_rms_m"]
            lines.append(
                f"| {lo}-{hi} | {b['n']} | {b['rms_pco_m']:.2f} | {rr:.2f} / {aa:.2f} / {cc:.2f} | "
                f"{b['mean_along_m']:+.2f} | {b['time_offset_ms']:+.3f} |"
            )
    return lines


# whole days of a whole constellation (the 2023 multi-GNSS files are excerpts of 2 satellites)
FIGURE_PANELS = ((PAIRS[0], "G"), (PAIRS[2], "R"))
SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS"}


def orbit_error_figure(data: Path, out: Path) -> None:
    """Broadcast (PCO-corrected to the centre of mass) minus SP3, 3-D, per satellite and epoch
    over a day, one panel per constellation; the epochs the ephemeris distrusts are gaps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(FIGURE_PANELS), figsize=(6.0 * len(FIGURE_PANELS), 3.8),
                             sharey=True)  # fmt: skip
    for ax, ((label, navs, sp3s), system) in zip(axes, FIGURE_PANELS, strict=True):
        brdc = Ephemeris.from_rinex([data / f for f in navs])
        prec = Ephemeris.from_sp3([data / f for f in sp3s])
        assert prec.sp3 is not None
        t = prec.sp3.epochs_gps_s
        sats = [s for s in prec.satellites if s in brdc.satellites and s[0] == system]
        pb, _, _ = brdc.evaluate(t, sats)
        pp, _, _ = prec.evaluate(t, sats)
        pco = block_pco_m(satellite_block(sats, t))
        pc = com_from_apc(pb, np.nan_to_num(pco, nan=0.0), sun_direction_ecef(t)[:, None, :])
        e = np.linalg.norm(pc - pp, axis=-1)  # NaN where either is not trusted
        hours = (t - t[0]) / 3600.0
        ax.plot(hours, e, color="0.65", lw=0.4)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # epochs with no trusted satellite
            ax.plot(hours, np.nanmedian(e, axis=1), color="k", lw=1.5, label="median")
            ax.plot(hours, np.nanmax(e, axis=1), color="#d7301f", lw=1, label="worst")
        ok = np.isfinite(e)
        ax.set_title(f"{SYSTEM_NAMES.get(system, system)}, {label}: {ok.any(0).sum()} "
                     f"satellites\nRMS {_rms(e[ok]):.2f} m, max {e[ok].max():.1f} m "
                     "(PCO-corrected)", fontsize=9)  # fmt: skip
        ax.set_yscale("log")
        ax.set_xlabel("hours from the first SP3 epoch")
        ax.set_xlim(0, 24)
        ax.set_xticks([0, 6, 12, 18, 24])
    axes[0].set_ylabel("3-D orbit error, broadcast - SP3 (m)")
    axes[0].legend(fontsize=8)
    fig.suptitle("Broadcast orbits against precise orbits: grey, one line per satellite "
                 "(gaps: distrusted by the ephemeris)")  # fmt: skip
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"written {out}")


def to_markdown(pairs: list[dict], tle: dict, spd: dict) -> str:
    lines = _orbit_lines(pairs)
    lines += ["", "# TLE (sgp4)", ""]
    lines += [f"* {k}: {v:.4f}" if isinstance(v, float) else f"* {k}: {v}" for k, v in tle.items()]
    lines += ["", "# Speed (one full multi-GNSS day at 30 s)", ""]
    lines += [f"* {k}: {v}" for k, v in spd.items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=here.parent / "shared/data/gnss")
    ap.add_argument("--out", type=Path, help="write the results (.md or .json)")
    ap.add_argument("--figure", type=Path, help="draw a day's orbit errors into this PNG "
                    "and stop")  # fmt: skip
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(
            f"--data {args.data} is not a folder; pass the shared gnss data folder", file=sys.stderr
        )
        return 2
    if args.figure:
        orbit_error_figure(args.data, args.figure)
        return 0
    pairs = [compare_pair(args.data, label, n, s) for label, n, s in PAIRS]
    tle = compare_tle(args.data)
    spd = speed(args.data)
    md = to_markdown(pairs, tle, spd)
    print(md)
    if args.out:
        if args.out.suffix == ".json":
            args.out.write_text(json.dumps({"orbits": pairs, "tle": tle, "speed": spd}, indent=2))
        else:
            args.out.write_text(md)
        print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
