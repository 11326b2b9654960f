"""Evaluate broadcast and TLE orbits against precise orbits and skyfield.

Broadcast-derived positions (RINEX nav -> predisat.orbits) are compared with SP3 precise orbits
at the SP3 epochs, for every matched file pair of ``../shared/data/gnss``, per constellation:
3-D RMS and maximum, mean radial difference (the antenna phase centre offset, since broadcast
orbits refer to the antenna and SP3 to the centre of mass) and clock RMS after removing each
epoch's common offset (the SP3 reference clock). Only pairs the ephemeris trusts (healthy,
inside the validity window) are compared; distrusted satellites are counted.

TLE-derived azimuth/elevation (predisat.tle, sgp4) are compared with skyfield's for the same
TLEs, and with the broadcast orbits of the same day (to show what "coarse" means).

Usage::

    .venv/bin/python scripts/eval_orbits.py [--data ../shared/data/gnss] [--out results.md|.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from predisat.ephemeris import Ephemeris, Reason
from predisat.geodesy import enu_rotation, enu_to_azel, geodetic_to_ecef
from predisat.gnss_time import calendar_to_gps_s, gps_s_to_utc_datetime64

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


def _radial(pos_a: np.ndarray, pos_b: np.ndarray) -> np.ndarray:
    r = pos_b / np.linalg.norm(pos_b, axis=-1, keepdims=True)
    return np.sum((pos_a - pos_b) * r, axis=-1)


def compare_pair(data: Path, label: str, navs: list[str], sp3s: list[str]) -> list[dict]:
    brdc = Ephemeris.from_rinex([data / f for f in navs])
    prec = Ephemeris.from_sp3([data / f for f in sp3s])
    assert prec.sp3 is not None
    t = prec.sp3.epochs_gps_s
    sats = [s for s in prec.satellites if s in brdc.satellites]
    pb, cb, st = brdc.evaluate(t, sats)
    pp, cp, _ = prec.evaluate(t, sats)
    rows = []
    for system in sorted({s[0] for s in sats}):
        cols = [j for j, s in enumerate(sats) if s[0] == system]
        a, b = pb[:, cols], pp[:, cols]
        ok = np.all(np.isfinite(a), -1) & np.all(np.isfinite(b), -1)
        n_bad = {
            Reason(r).name: sorted(
                {sats[cols[j]] for j in np.nonzero((st.reason[:, cols] == r).any(0))[0]}
            )
            for r in (Reason.UNHEALTHY, Reason.INCONSISTENT, Reason.OUTSIDE_VALIDITY)
        }
        if not ok.any():
            rows.append({"pair": label, "system": system, "n": 0, "distrusted": n_bad})
            continue
        err = np.linalg.norm(a - b, axis=-1)[ok]
        rad = _radial(a, b)[ok]
        # clocks: remove each epoch's common offset (reference clock of the SP3 solution)
        dc = (cb[:, cols] - cp[:, cols]) * 299792458.0
        dc = np.where(ok, dc, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN epochs stay NaN
            dc = dc - np.nanmedian(dc, axis=1, keepdims=True)
        dc = dc[np.isfinite(dc)]
        worst = int(np.argmax(np.where(ok, np.linalg.norm(a - b, axis=-1), -1)) % len(cols))
        rows.append(
            {
                "pair": label,
                "system": system,
                "n_sat": int(ok.any(0).sum()),
                "n": int(ok.sum()),
                "rms_m": float(np.sqrt(np.mean(err**2))),
                "max_m": float(err.max()),
                "worst_sat": sats[cols[worst]],
                "mean_radial_m": float(rad.mean()),
                "clock_rms_m": float(np.sqrt(np.mean(dc**2))) if dc.size else float("nan"),
                "distrusted": n_bad,
            }
        )
    return rows


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


def to_markdown(rows: list[dict], tle: dict, spd: dict) -> str:
    lines = [
        "# Broadcast orbits vs SP3 precise orbits",
        "",
        "| pair | sys | sats | n | RMS 3D m | max m | worst | mean radial m | clock RMS m |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["n"] == 0:
            lines.append(f"| {r['pair']} | {r['system']} | 0 | 0 | - | - | - | - | - |")
            continue
        lines.append(
            f"| {r['pair']} | {r['system']} | {r['n_sat']} | {r['n']} | {r['rms_m']:.2f} | "
            f"{r['max_m']:.2f} | {r['worst_sat']} | {r['mean_radial_m']:+.2f} | "
            f"{r['clock_rms_m']:.2f} |"
        )
    lines += ["", "Distrusted satellites (never compared):", ""]
    for r in rows:
        for reason, sats in r["distrusted"].items():
            if sats:
                lines.append(f"* {r['pair']} {r['system']}: {reason} {', '.join(sats)}")
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
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(
            f"--data {args.data} is not a folder; pass the shared gnss data folder", file=sys.stderr
        )
        return 2
    rows = [r for label, n, s in PAIRS for r in compare_pair(args.data, label, n, s)]
    tle = compare_tle(args.data)
    spd = speed(args.data)
    md = to_markdown(rows, tle, spd)
    print(md)
    if args.out:
        if args.out.suffix == ".json":
            args.out.write_text(json.dumps({"orbits": rows, "tle": tle, "speed": spd}, indent=2))
        else:
            args.out.write_text(md)
        print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
