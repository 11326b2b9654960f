"""Measure the demo track map against pyproj and draw the figure of ``docs/track-map.md``.

On ``predisat.track.map.demo_track()`` (Belgian line 144, track A) it measures: the time to build
the map (fit, arc length, projection index); the length of the smooth axis against the WGS84
geodesic length of the source polyline (pyproj); the largest horizontal deviation between fit
and polyline; the round trip ``project(position_at(s))`` on 10 001 chainages (largest chainage
error and time); the heading at curved-stretch vertices against the tangent of the arc through
the neighbouring vertices (pyproj azimuths); the heading against pyproj azimuths of 1 m chords
of the fit; and the smallest radius of curvature. Ground truth comes from pyproj, never from the
code under test.

Usage::

    .venv/bin/python scripts/track_figures.py [--out-figure docs/figures/track_line144.png]
                                              [--out-json track_figures.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: the figure goes to a file

import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray
from pyproj import Geod

from predisat.track.map import TrackMap, demo_track

GEOD = Geod(ellps="WGS84")
N_ROUND_TRIP = 10001
# Vertices used for the heading check: both neighbouring segments shorter than this (a curve,
# where Douglas-Peucker keeps vertices densely) and a kink larger than MIN_KINK_DEG.
MAX_SEGMENT_M = 120.0
MIN_KINK_DEG = 1.0
CURVATURE_STEP_M = 2.0
WINDOW_M = (600.0, 2600.0)  # the two curves shown in the right panel


def wrap180(x: NDArray) -> NDArray:
    """Angle difference wrapped to [-180, 180) degrees."""
    return (np.asarray(x) + 180.0) % 360.0 - 180.0


def vertex_tangents(tm: TrackMap) -> dict[str, NDArray]:
    """Chord azimuths of the source and the arc tangent at each interior vertex (pyproj).

    The tangent at a vertex of a circular arc through it and its neighbours splits the turn
    between the two chords in proportion to their lengths.
    """
    az, _, dist = GEOD.inv(tm.lon_deg[:-1], tm.lat_deg[:-1], tm.lon_deg[1:], tm.lat_deg[1:])
    az, dist = np.asarray(az), np.asarray(dist)
    turn = wrap180(np.diff(az))
    tangent = az[:-1] + turn * dist[:-1] / (dist[:-1] + dist[1:])
    curved = (
        (dist[:-1] < MAX_SEGMENT_M) & (dist[1:] < MAX_SEGMENT_M) & (np.abs(turn) > MIN_KINK_DEG)
    )
    return {"chord_az_deg": az, "turn_deg": turn, "tangent_deg": tangent, "curved": curved}


def measure(tm: TrackMap, build_s: float) -> dict[str, Any]:
    """The figures quoted in ``docs/track-map.md``, keyed with their units."""
    geodesic_m = float(GEOD.line_length(tm.lon_deg, tm.lat_deg))

    s = np.linspace(0.0, tm.length_m, N_ROUND_TRIP)
    t0 = time.perf_counter()
    lat, lon, h = tm.position_at(s)
    pr = tm.project(lat, lon, h)
    round_trip_s = time.perf_counter() - t0

    vt = vertex_tangents(tm)
    ok = vt["curved"]
    foot = tm.project(tm.lat_deg[1:-1][ok], tm.lon_deg[1:-1][ok])
    err = wrap180(tm.heading_at(foot.chainage_m) - vt["tangent_deg"][ok])

    # 1 m chords of the fit: pyproj azimuth from s to s + 1 m against the heading at s + 0.5 m.
    sc = np.arange(0.0, tm.length_m - 1.0, 10.0)
    la0, lo0, _ = tm.position_at(sc)
    la1, lo1, _ = tm.position_at(sc + 1.0)
    chord_az, _, _ = GEOD.inv(lo0, la0, lo1, la1)
    chord_err = wrap180(tm.heading_at(sc + 0.5) - np.asarray(chord_az))

    k = tm.curvature_at(np.arange(0.0, tm.length_m, CURVATURE_STEP_M))
    return {
        "track": tm.name,
        "n_vertices": int(tm.lat_deg.size),
        "build_s": build_s,
        "length_m": tm.length_m,
        "geodesic_length_m": geodesic_m,
        "length_rel_diff_pct": 100.0 * (tm.length_m - geodesic_m) / geodesic_m,
        "max_deviation_m": tm.max_deviation_m,
        "tolerance_m": tm.tolerance_m,
        "round_trip_n": N_ROUND_TRIP,
        "round_trip_max_err_m": float(np.max(np.abs(pr.chainage_m - s))),
        "round_trip_s": round_trip_s,
        "vertex_heading_n": int(np.count_nonzero(ok)),
        "vertex_heading_rms_deg": float(np.sqrt(np.mean(err**2))),
        "vertex_heading_max_deg": float(np.max(np.abs(err))),
        "polyline_kink_median_deg": float(np.median(np.abs(vt["turn_deg"][ok]))),
        "chord_heading_max_deg": float(np.max(np.abs(chord_err))),
        "min_radius_m": float(1.0 / np.max(np.abs(k))),
    }


def report(m: dict[str, Any]) -> str:
    """The measured figures as text, one quantity a line."""
    return "\n".join(
        [
            f"track: {m['track']} ({m['n_vertices']} vertices)",
            f"build (fit + arc length + projection index): {m['build_s']:.2f} s",
            f"length: {m['length_m']:.3f} m; pyproj geodesic of the source "
            f"{m['geodesic_length_m']:.3f} m; difference {m['length_rel_diff_pct']:+.4f} %",
            f"max deviation fit <-> polyline: {m['max_deviation_m']:.3f} m "
            f"(tolerance {m['tolerance_m']:g} m)",
            f"projection round trip, {m['round_trip_n']} chainages: max error "
            f"{m['round_trip_max_err_m']:.1e} m in {m['round_trip_s']:.2f} s",
            f"heading at curved vertices vs arc tangent (pyproj): rms "
            f"{m['vertex_heading_rms_deg']:.3f} deg, max {m['vertex_heading_max_deg']:.3f} deg "
            f"(n={m['vertex_heading_n']}); polyline kink median "
            f"{m['polyline_kink_median_deg']:.2f} deg",
            f"heading vs pyproj azimuth of 1 m chords of the fit: max "
            f"{m['chord_heading_max_deg']:.4f} deg",
            f"min radius: {m['min_radius_m']:.0f} m",
        ]
    )


def _post_label(label: str) -> str:
    """Place names as they are; "km 12.000" as "12"."""
    return label[3:].split(".")[0] if label.startswith("km") else label


def plot(tm: TrackMap, out: Path) -> None:
    """Map with kilometre posts (left); polyline vs smooth heading on two curves (right)."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.6), gridspec_kw={"width_ratios": [1, 1.6]})

    enu = tm.enu_at(np.arange(0.0, tm.length_m, 5.0))
    a1.plot(enu[:, 0] / 1000, enu[:, 1] / 1000, "k-", lw=1)
    for p in tm.kilometre_posts:
        e = tm.enu_at(p.chainage_m) / 1000
        a1.plot(e[0], e[1], "o", color="tab:red", ms=3)
        a1.annotate(
            _post_label(p.label),
            (e[0], e[1]),
            xytext=(4, 0),
            textcoords="offset points",
            fontsize=7,
            va="center",
        )
    a1.set_aspect("equal")
    a1.set_xlabel("east (km)")
    a1.set_ylabel("north (km)")
    a1.set_title("line 144 track A, kilometre posts", fontsize=9)

    vt = vertex_tangents(tm)
    az = vt["chord_az_deg"]
    s_vertex = tm.project(tm.lat_deg, tm.lon_deg).chainage_m
    w0, w1 = WINDOW_M
    ss = np.linspace(w0, w1, 2000)
    idx = np.interp(ss, s_vertex, np.arange(s_vertex.size))  # fractional vertex index
    seg = np.clip(np.floor(idx).astype(int), 0, az.size - 1)
    a2.plot(
        ss, np.mod(az[seg], 360), color="tab:gray", lw=1, label="source polyline (chord azimuth)"
    )
    a2.plot(ss, tm.heading_at(ss), color="tab:blue", lw=1.5, label="smooth fit heading_at")
    inner = s_vertex[1:-1]
    sel = vt["curved"] & (inner > w0) & (inner < w1)
    a2.plot(
        inner[sel],
        np.mod(vt["tangent_deg"][sel], 360),
        "x",
        color="tab:red",
        ms=5,
        label="arc tangent at vertex (pyproj)",
    )
    a2.set_xlabel("chainage (m)")
    a2.set_ylabel("heading (deg)")
    a2.legend(fontsize=7)
    a2.set_title("heading: 1 m-simplified polyline vs smooth fit", fontsize=9)

    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out-figure",
        type=Path,
        default=Path("docs/figures/track_line144.png"),
        help="PNG to write (default: %(default)s)",
    )
    parser.add_argument("--out-json", type=Path, help="also write the figures to this JSON file")
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    tm = demo_track()
    build_s = time.perf_counter() - t0
    m = measure(tm, build_s)
    print(report(m))
    plot(tm, args.out_figure)
    print(f"figure: {args.out_figure}")
    if args.out_json is not None:
        args.out_json.write_text(json.dumps(m, indent=1) + "\n", encoding="utf-8")
        print(f"json: {args.out_json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
