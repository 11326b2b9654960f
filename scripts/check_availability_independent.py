"""Independent recomputation of PREDISAT's availability figures.

Imports neither predisat nor locator. Inputs: a RINEX 3 navigation file (GPS records), a
PREDISAT mask file (read with pyarrow as docs/mask-format.md describes), a window.

GPS orbits: IS-GPS-200 Table 20-IV Keplerian propagation, geometric positions at the epoch
(no light time, as docs/availability.md states), ECEF WGS84.
Record choice (docs/ephemerides.md, GPS): nearest toe (tie: the newest), not trusted when
health != 0, URA index value >= 6144 m, or |t - toe| > 2 h (half the fit interval when > 4 h).
The consistency check between records is not redone (reported separately).
Positions: the mask file's lat/lon/h_m + provenance antenna height, ENU by pyproj ECEF.
Trust: el > float32(mask + margin) of bin floor((az + step/2) / step) mod n_az, strict.
Intervals: docs/availability.md "Interval model", by number of trusted satellites.

Usage: python scripts/check_availability_independent.py NAV.rnx[.gz] MASKS.parquet OUTDIR
       [--start GPS_S] [--n 2880]
       [--step 30] [--every 10] [--risk 1e-12 | --kall K] [--a 2 --b 2] [--lat 1.5 --vert 1.0]
       [--nomask | --cutoff DEG] [--light-time] [--no-interval] [--report AVAILABILITY_DIR]
"""
from __future__ import annotations

import argparse
import gzip
import itertools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
from pyproj import Transformer
from scipy.stats import norm

MU = 3.986005e14
OMEGA_E = 7.2921151467e-5
C = 299792458.0
F_REL = -4.442807633e-10


def _f(s: str) -> float:
    s = s.strip().replace("D", "E").replace("d", "e")
    return float(s) if s else 0.0


def read_gps_nav(path: str) -> list[dict]:
    op = gzip.open if str(path).endswith(".gz") else open
    with op(path, "rt") as fh:
        lines = fh.read().splitlines()
    i = next(k for k, ln in enumerate(lines) if "END OF HEADER" in ln) + 1
    recs = []
    while i < len(lines):
        ln = lines[i]
        if not ln or ln[0] == " ":
            i += 1
            continue
        sys = ln[0]
        nlines = {"G": 8, "E": 8, "C": 8, "J": 8, "I": 8, "R": 4, "S": 4}.get(sys, 8)
        if sys != "G":
            i += nlines
            continue
        block = lines[i:i + 8]
        i += 8
        prn = int(ln[1:3])
        vals = [_f(ln[23 + 19 * k:23 + 19 * (k + 1)]) for k in range(3)]
        for b in block[1:]:
            b = b.ljust(80)
            vals += [_f(b[4 + 19 * k:4 + 19 * (k + 1)]) for k in range(4)]
        names = ["af0", "af1", "af2", "iode", "crs", "dn", "m0", "cuc", "e", "cus", "sqrta",
                 "toe", "cic", "omega0", "cis", "i0", "crc", "omega", "omegadot", "idot",
                 "l2codes", "week", "l2p", "ura", "health", "tgd", "iodc", "ttm", "fit",
                 "spare1", "spare2"]
        r = dict(zip(names, vals, strict=False))  # short records: the spares absent
        r["prn"] = prn
        r["toe_abs"] = r["week"] * 604800.0 + r["toe"]
        # transmission time: handle week roll against toe
        ttm_abs = r["week"] * 604800.0 + r["ttm"]
        if ttm_abs - r["toe_abs"] > 302400:
            ttm_abs -= 604800
        r["ttm_abs"] = ttm_abs
        recs.append(r)
    return recs


def sat_pos(r: dict, t: np.ndarray) -> np.ndarray:
    """ECEF position (m) of record r at GPS seconds t (array)."""
    a = r["sqrta"] ** 2
    n0 = math.sqrt(MU / a ** 3)
    tk = t - r["toe_abs"]
    n = n0 + r["dn"]
    M = r["m0"] + n * tk
    E = M.copy()
    for _ in range(30):
        E = E - (E - r["e"] * np.sin(E) - M) / (1 - r["e"] * np.cos(E))
    nu = np.arctan2(np.sqrt(1 - r["e"] ** 2) * np.sin(E), np.cos(E) - r["e"])
    phi = nu + r["omega"]
    du = r["cus"] * np.sin(2 * phi) + r["cuc"] * np.cos(2 * phi)
    dr = r["crs"] * np.sin(2 * phi) + r["crc"] * np.cos(2 * phi)
    di = r["cis"] * np.sin(2 * phi) + r["cic"] * np.cos(2 * phi)
    u = phi + du
    rr = a * (1 - r["e"] * np.cos(E)) + dr
    inc = r["i0"] + di + r["idot"] * tk
    xp, yp = rr * np.cos(u), rr * np.sin(u)
    Om = r["omega0"] + (r["omegadot"] - OMEGA_E) * tk - OMEGA_E * r["toe"]
    x = xp * np.cos(Om) - yp * np.cos(inc) * np.sin(Om)
    y = xp * np.sin(Om) + yp * np.cos(inc) * np.cos(Om)
    z = yp * np.sin(inc)
    return np.stack([x, y, z], axis=-1)


def gps_positions(recs: list[dict], t: np.ndarray):
    prns = sorted({r["prn"] for r in recs})
    pos = np.full((len(t), len(prns), 3), np.nan)
    ok = np.zeros((len(t), len(prns)), bool)
    reason = np.full((len(t), len(prns)), "", dtype=object)
    for j, p in enumerate(prns):
        rs = [r for r in recs if r["prn"] == p]
        toes = np.array([r["toe_abs"] for r in rs])
        ttm = np.array([r["ttm_abs"] for r in rs])
        # nearest toe; tie -> newest (largest transmission time)
        d = np.abs(t[:, None] - toes[None, :])
        best = np.empty(len(t), int)
        for ie in range(len(t)):
            m = d[ie] == d[ie].min()
            cand = np.nonzero(m)[0]
            best[ie] = cand[np.argmax(ttm[cand])] if len(cand) > 1 else cand[0]
        for k in np.unique(best):
            r = rs[k]
            sel = best == k
            pos[sel, j] = sat_pos(r, t[sel])
            half = 7200.0 if r["fit"] <= 4 else r["fit"] * 3600 / 2
            valid = np.abs(t[sel] - r["toe_abs"]) <= half
            healthy = r["health"] == 0 and r["ura"] < 6144
            ok[sel, j] = valid & healthy
            ok_text = np.where(valid, "OK", "OUTSIDE_VALIDITY")
            reason[sel, j] = np.where(not healthy, "UNHEALTHY", ok_text)
    return prns, pos, ok, reason


def read_masks(path: str):
    t = pq.read_table(path)
    meta = json.loads(t.schema.metadata[b"predisat"])
    step = float(meta["az_step_deg"])
    n_az = int(meta["n_az"])
    prov = meta.get("provenance", {})
    if isinstance(prov, str):
        prov = json.loads(prov)
    mask = np.stack(t.column("mask_el_deg").to_numpy(zero_copy_only=False)).astype(np.float32)
    margin = np.stack(t.column("margin_deg").to_numpy(zero_copy_only=False)).astype(np.float32)
    assert mask.shape[1] == n_az
    names = ("chainage_m", "lat_deg", "lon_deg", "h_m", "heading_deg")
    cols = {c: t.column(c).to_numpy() for c in names}
    return cols, (mask + margin).astype(np.float32), step, n_az, prov, meta


def enu_rot(lat, lon):
    la, lo = np.radians(lat), np.radians(lon)
    e = np.stack([-np.sin(lo), np.cos(lo), np.zeros_like(lo)], -1)
    n = np.stack([-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)], -1)
    u = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)
    return np.stack([e, n, u], 1)  # (n_pos, 3, 3)


def cell_bounds(s):
    mid = (s[1:] + s[:-1]) / 2
    lo = np.concatenate([[s[0] - (mid[0] - s[0])], mid])
    hi = np.concatenate([mid, [s[-1] + (s[-1] - mid[-1])]])
    return lo, hi


def longest(flag, lo, hi):
    best, start = 0.0, None
    for i, f in enumerate([*list(flag), False]):
        if f and start is None:
            start = i
        if not f and start is not None:
            best = max(best, hi[i - 1] - lo[start])
            start = None
    return best


_SETS: dict[int, np.ndarray] = {}


def three_pair_sets(n: int) -> np.ndarray:
    if n not in _SETS:
        out = []
        for six in itertools.combinations(range(n), 6):
            a = six[0]
            for b in six[1:]:
                rest = [x for x in six if x not in (a, b)]
                c = rest[0]
                for d in rest[1:]:
                    e, f = [x for x in rest if x not in (c, d)]
                    out.append(((a, b), (c, d), (e, f)))
        _SETS[n] = np.array(out, int)
    return _SETS[n]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("nav")
    ap.add_argument("masks")
    ap.add_argument("out")
    ap.add_argument("--start", type=float, default=1277078400.0)
    ap.add_argument("--n", type=int, default=2880)
    ap.add_argument("--step", type=float, default=30.0)
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--risk", type=float, default=1e-12)
    ap.add_argument("--a", type=float, default=2.0)
    ap.add_argument("--b", type=float, default=2.0)
    ap.add_argument("--lat", type=float, default=1.5)
    ap.add_argument("--vert", type=float, default=1.0)
    ap.add_argument("--light-time", action="store_true")
    ap.add_argument("--no-interval", action="store_true")
    ap.add_argument("--cutoff", type=float, default=None, help="flat cut-off instead of masks")
    ap.add_argument("--nomask", action="store_true")
    ap.add_argument("--kall", type=float, default=None, help="one k for every mode (--k-sigma)")
    ap.add_argument("--report", default=None,
                    help="a `predisat availability --counts` folder to compare with, cell by cell")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    t = args.start + args.step * np.arange(args.n)
    recs = read_gps_nav(args.nav)
    prns, sp, ok, reason = gps_positions(recs, t)
    cols, eff, step, n_az, prov, _meta = read_masks(args.masks)
    ant_h = float(prov.get("antenna_height_m", 0.0) or 0.0)
    to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    x, y, z = to_ecef.transform(cols["lon_deg"], cols["lat_deg"], cols["h_m"] + ant_h)
    P = np.stack([x, y, z], -1)
    R = enu_rot(cols["lat_deg"], cols["lon_deg"])
    n_pos, n_ep, n_sat = len(P), len(t), len(prns)
    if args.light_time:
        # satellite at transmission time, rotated by Earth rotation during flight
        sp2 = np.empty_like(sp)
        rng = np.linalg.norm(sp - P.mean(0), axis=-1)
        tau = rng / C
        for j in range(n_sat):
            # position at transmission time from the velocity (central differences)
            v = (np.roll(sp[:, j], -1, 0) - np.roll(sp[:, j], 1, 0)) / (2 * args.step)
            v[0] = (sp[1, j] - sp[0, j]) / args.step
            v[-1] = (sp[-1, j] - sp[-2, j]) / args.step
            s = sp[:, j] - v * tau[:, j, None]
            th = OMEGA_E * tau[:, j]
            sp2[:, j, 0] = np.cos(th) * s[:, 0] + np.sin(th) * s[:, 1]
            sp2[:, j, 1] = -np.sin(th) * s[:, 0] + np.cos(th) * s[:, 1]
            sp2[:, j, 2] = s[:, 2]
        sp = sp2
    # per position: ENU of every (epoch, sat)
    el = np.empty((n_pos, n_ep, n_sat))
    az = np.empty((n_pos, n_ep, n_sat))
    thr = np.empty((n_pos, n_ep, n_sat), np.float32)
    for p in range(n_pos):
        enu_p = (sp - P[p]) @ R[p].T
        r_p = np.linalg.norm(enu_p, axis=-1)
        el[p] = np.degrees(np.arcsin(enu_p[..., 2] / r_p))
        az[p] = np.degrees(np.arctan2(enu_p[..., 0], enu_p[..., 1])) % 360.0
        if args.nomask:
            thr[p] = 0.0
        elif args.cutoff is not None:
            thr[p] = args.cutoff
        else:
            kb = np.floor((az[p] + step / 2) / step).astype(int) % n_az
            thr[p] = eff[p][kb]
    trusted = ok[None, :, :] & np.isfinite(el) & (el > thr.astype(np.float64))
    count = trusted.sum(-1).astype(np.uint8)
    np.save(out / "count.npy", count)
    np.save(out / "el.npy", el.astype(np.float32))
    np.save(out / "az.npy", az.astype(np.float32))
    np.save(out / "thr.npy", thr.astype(np.float32))
    np.save(out / "ok.npy", ok)
    lo, hi = cell_bounds(cols["chainage_m"])
    w = hi - lo
    res: dict[str, Any] = {"n_pos": n_pos, "n_epoch": n_ep, "n_sat": n_sat,
                           "line_length_m": float(w.sum()), "antenna_height_m": ant_h}
    for nn in (2, 4, 6):
        res[f"share_ge{nn}"] = float(np.sum((count >= nn).mean(1) * w) / w.sum())
    res["mean_count"] = float(count.mean())
    by_ep = np.array([longest(count[:, e] < 4, lo, hi) for e in range(n_ep)])
    half = args.step / 2
    by_pos = np.array([longest(count[p] < 4, t - half, t + half) for p in range(n_pos)])
    res["longest_below4_m"] = float(by_ep.max())
    res["longest_below4_m_at_gps_s"] = float(t[np.argmax(by_ep)])
    res["longest_below4_s"] = float(by_pos.max())
    res["longest_below4_s_at_chainage_m"] = float(cols["chainage_m"][np.argmax(by_pos)])
    kinds, n_kind = np.unique(reason.astype(str), return_counts=True)
    res["status_counts"] = {k: int(v) for k, v in zip(kinds, n_kind, strict=True)}

    if not args.no_interval:
        k2 = norm.isf(args.risk / 2)                    # one pair, two-sided
        k45 = norm.isf(np.sqrt(args.risk / 2) * 2 / 2)  # 2 independent pairs: 2 (p/2)^2 = risk
        k3 = norm.isf((args.risk / 2) ** (1 / 3))       # 3 independent pairs: 2 (p/2)^3 = risk
        if args.kall is not None:
            k2 = k45 = k3 = args.kall
        res["k"] = {"best_pair": k2, "all_pairs": k45, "three_pairs": k3}
        ie = np.arange(0, n_ep, args.every)
        hdg = np.radians(cols["heading_deg"])
        tan = np.stack([np.sin(hdg), np.cos(hdg), np.zeros_like(hdg)], -1)
        L = np.full((n_pos, len(ie)), np.nan)
        L_opt = np.full((n_pos, len(ie)), np.nan)   # 3-pair optimum with the doubt (lower bound)
        for p in range(n_pos):
            for q, e in enumerate(ie):
                m = trusted[p, e]
                nm = int(m.sum())
                if nm < 2:
                    continue
                v = (sp[e, m] - P[p]) @ R[p].T
                u = v / np.linalg.norm(v, axis=-1)[:, None]
                g = u @ tan[p]
                e_el = np.radians(np.maximum(el[p, e, m], 1.0))
                sig2 = args.a ** 2 + (args.b / np.sin(e_el)) ** 2
                dg = np.abs(g[:, None] - g[None, :])
                du = u[:, None, :] - u[None, :, :]
                bias = args.lat * np.hypot(du[..., 0], du[..., 1]) + args.vert * np.abs(du[..., 2])
                sk = np.sqrt(sig2[:, None] + sig2[None, :])
                with np.errstate(divide="ignore", invalid="ignore"):
                    if nm >= 6:
                        kk = k3
                    elif nm >= 4:
                        kk = k45
                    else:
                        kk = k2
                    h0 = kk * sk / dg
                    hd = (kk * sk + bias) / dg
                np.fill_diagonal(h0, np.inf)
                np.fill_diagonal(hd, np.inf)
                if nm >= 6:
                    S = three_pair_sets(nm)
                    H0 = h0[S[..., 0], S[..., 1]]
                    HD = hd[S[..., 0], S[..., 1]]
                    mx = H0.max(1)
                    best = np.nonzero(mx == mx.min())[0]
                    b = best[np.argmin(H0[best].sum(1))]
                    L[p, q] = 2 * HD[b].max()
                    L_opt[p, q] = 2 * HD.max(1).min()
                elif nm >= 4:
                    iu = np.triu_indices(nm, 1)
                    L[p, q] = 2 * hd[iu].max()
                else:
                    iu = np.triu_indices(nm, 1)
                    b = np.argmin(h0[iu])
                    L[p, q] = 2 * hd[iu][b]
        np.save(out / "interval.npy", L)
        np.save(out / "interval_opt.npy", L_opt)
        np.save(out / "interval_epochs.npy", t[ie])
        c4 = count[:, ie] >= 4
        xx = L[c4]
        xx = xx[np.isfinite(xx)]
        res["interval_median_m"] = float(np.median(xx))
        res["interval_p95_m"] = float(np.quantile(xx, 0.95))
    json.dump(res, open(out / "summary.json", "w"), indent=1)
    print(json.dumps(res, indent=1))
    if args.report:
        edge = np.abs((az + step / 2) / step - np.round((az + step / 2) / step)) * step
        compare_report(Path(args.report), res, count, cols["chainage_m"], t, el, thr, ok, prns,
                       edge,
                       "no mask" if args.nomask else
                       f"cutoff {args.cutoff:g} deg" if args.cutoff is not None else "masks")


def compare_report(rep: Path, res: dict, count, chainage, t, el, thr, ok, prns, edge,
                   rule: str) -> None:
    """Cell-by-cell counts and the line-wide figures against a report's folder."""
    tab = pq.read_table(rep / "counts.parquet").to_pandas()
    tab = tab[tab["rule"] == rule]
    theirs = tab.pivot(index="chainage_m", columns="gps_s", values="count")
    theirs = theirs.loc[chainage, t].to_numpy().astype(int)
    d = count.astype(int) - theirs
    print(f"{rule}: {np.count_nonzero(d)} of {d.size} cells differ "
          f"({np.count_nonzero(d < 0)} where the report trusts more)")
    for p, e in zip(*np.nonzero(d), strict=True):
        near = np.where(ok[e], np.abs(el[p, e] - thr[p, e]), np.inf)
        s = int(np.argmin(near))
        print(f"  chainage {chainage[p]:.1f} m, gps_s {t[e]:.0f}: report {theirs[p, e]}, here "
              f"{count[p, e]}; closest call G{prns[s]:02d}, elevation - threshold "
              f"{el[p, e, s] - thr[p, e, s]:+.2e} deg; closest to a bin edge "
              f"{edge[p, e][ok[e] & (el[p, e] > 0)].min():.1e} deg")
    summ = json.loads((rep / "summary.json").read_text())["summary"]
    row = next(r for r in summ if r["rule"] == rule)
    for key in ("share_ge2", "share_ge4", "share_ge6", "mean_count", "longest_below4_m",
                "longest_below4_s", "interval_median_m", "interval_p95_m"):
        if key in res:
            print(f"  {key}: report {row[key]:.6g}, here {res[key]:.6g}")


if __name__ == "__main__":
    main()
