"""Figures of the format and method docs that no other script draws.

* ``mask``: what a mask file holds, drawn from a published ``masks.parquet`` (the demo's):
  the effective mask, the source code and the support of every bin along a stretch, and one
  position's mask on a sky plot (``docs/figures/mask_file.png``, docs/mask-format.md).
* ``conventions``: chainage, heading, azimuth from north, the vehicle frame, left and right,
  and the side cameras' mounts, on the demo's line 144 (``docs/figures/conventions.png``,
  docs/conventions.md).
* ``terrain``: the terrain horizon of the SRTM tiles against the flat far-field assumption at
  three places of the Nice - Digne line (``docs/figures/terrain_horizon.png``,
  docs/terrain.md).

Both read real outputs or real data and draw them with the library's own readers; nothing is
computed here that the pipeline does not compute.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/docs_figures.py mask demo_out/masks/masks.parquet \
        --from-m 1000 --to-m 1400 --at-m 1200 --out docs/figures/mask_file.png
    PYTHONPATH=. .venv/bin/python scripts/docs_figures.py conventions \
        --out docs/figures/conventions.png
    PYTHONPATH=. .venv/bin/python scripts/docs_figures.py terrain \
        ../shared/data/terrain/srtm3_nice --out docs/figures/terrain_horizon.png
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any, Literal

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap

from predisat.camera.models import Mount
from predisat.masks.fileformat import read_masks
from predisat.masks.maskset import WEAK_SUPPORT, BinSource
from predisat.terrain import Dem, antenna_height_m, terrain_horizon
from predisat.track.map import demo_track

# Nice - Digne line: the valley floor, a town in the upper valley, the Nice terminus
# (docs/terrain.md quotes the horizons of these three places)
PLACES = (
    ("Var valley (43.86 N, 7.19 E)", 43.86, 7.19),
    ("Puget-Theniers (43.955 N, 6.894 E)", 43.955, 6.894),
    ("Nice Gare du Sud (43.708 N, 7.262 E)", 43.708, 7.262),
)
ANTENNA_ABOVE_GROUND_M = 4.0  # bin_terrain's default
FAR_DEFAULT_DEG = 5.0  # ReconstructionParams.far_default_deg, the flat assumption
SOURCE_COLOURS = ("#2b8cbe", "#a6bddb", "#fdae61", "#8c6d31")  # observed, reconstructed, ...


def _mask_figure(path: Path, lo_m: float, hi_m: float, at_m: float, out: Path) -> None:
    masks = read_masks(path)
    sel = (masks.chainage_m >= lo_m) & (masks.chainage_m <= hi_m)
    if not sel.any():
        sys.exit(f"{path}: no position in [{lo_m:g}, {hi_m:g}] m; covered "
                 f"{masks.chainage_m[0]:.0f}-{masks.chainage_m[-1]:.0f} m")  # fmt: skip
    ch = masks.chainage_m[sel]
    eff = (masks.mask_el_deg + masks.margin_deg)[sel]
    src = masks.source[sel]
    n_az = eff.shape[1]
    az = np.arange(n_az) * masks.az_step_deg
    extent = (-masks.az_step_deg / 2, 360 - masks.az_step_deg / 2, ch[-1], ch[0])
    fig = plt.figure(figsize=(13, 5.2))
    axes = [fig.add_subplot(1, 4, k + 1) for k in range(3)]
    im = axes[0].imshow(eff, aspect="auto", extent=extent, cmap="viridis", vmin=0, vmax=90,
                        interpolation="nearest")  # fmt: skip
    fig.colorbar(im, ax=axes[0], orientation="horizontal", pad=0.12,
                 label="mask_el_deg + margin_deg (deg)")  # fmt: skip
    axes[0].set_ylabel("chainage_m (m)")
    cmap = ListedColormap(SOURCE_COLOURS)
    norm = BoundaryNorm(np.arange(-0.5, 4.5), cmap.N)
    im = axes[1].imshow(src, aspect="auto", extent=extent, cmap=cmap, norm=norm,
                        interpolation="nearest")  # fmt: skip
    cb = fig.colorbar(im, ax=axes[1], orientation="horizontal", pad=0.12, ticks=range(4))
    cb.ax.set_xticklabels([f"{s.value} {s.name.lower()}" for s in BinSource], fontsize=7,
                          rotation=25)  # fmt: skip
    cb.set_label("source (uint8 code)")
    if masks.support is None:
        axes[2].text(0.5, 0.5, "no support column\n(format version < 3)", ha="center",
                     transform=axes[2].transAxes)  # fmt: skip
    else:
        sup = np.minimum(masks.support[sel], 6)
        im = axes[2].imshow(sup, aspect="auto", extent=extent, cmap="Greys", vmin=0, vmax=6,
                            interpolation="nearest")  # fmt: skip
        cb = fig.colorbar(im, ax=axes[2], orientation="horizontal", pad=0.12)
        cb.set_label(f"support: views (6 = 6 or more); < {WEAK_SUPPORT} weak")
    for ax, title in zip(axes, ("effective mask", "source", "support"), strict=True):
        ax.set_xlabel("azimuth bin centre (deg from north)")
        ax.set_xticks([0, 90, 180, 270])
        ax.set_title(title)
        ax.axhline(at_m, color="red", lw=0.8, ls="--")
    i = int(np.argmin(np.abs(masks.chainage_m - at_m)))
    sky: Any = fig.add_subplot(1, 4, 4, projection="polar")  # PolarAxes: untyped in matplotlib
    sky.set_theta_zero_location("N")
    sky.set_theta_direction(-1)
    e = (masks.mask_el_deg + masks.margin_deg)[i]
    # a bin covers [centre - step/2, centre + step/2): draw it as a step of that width
    edges = np.radians(np.append(az - masks.az_step_deg / 2, 360 - masks.az_step_deg / 2))
    sky.fill_between(edges, 90 - np.append(e, e[0]), 90, step="post", color="0.55",
                    label="masked (no trust)")  # fmt: skip
    if masks.support is not None:
        weak = np.flatnonzero(masks.support[i] < WEAK_SUPPORT)
        for k in weak:
            # a band over the skyline: the sky above it is trusted on one view's word
            band = min(8.0, 90 - e[k])
            sky.bar(np.radians(az[k]), band, width=np.radians(masks.az_step_deg),
                   bottom=90 - e[k] - band, color="none", edgecolor="#d7301f", hatch="////",
                   lw=0)  # fmt: skip
    heading = float(masks.heading_deg[i])
    sky.annotate("", xy=(np.radians(heading), 80), xytext=(0, 0),
                arrowprops={"arrowstyle": "->", "color": "k"})  # fmt: skip
    sky.set_rlim(0, 90)
    sky.set_yticks([30, 60, 90])
    sky.set_yticklabels(["60", "30", "0"], fontsize=7)
    sky.set_title(f"position {masks.chainage_m[i]:.0f} m\n(arrow: heading; hatched over the "
                 f"skyline:\nsupport < {WEAK_SUPPORT}, one view's word)", fontsize=9)  # fmt: skip
    fig.suptitle(f"{path.name}: {ch.size} positions, {n_az} bins of {masks.az_step_deg:g} deg "
                 f"({'with' if masks.support is not None else 'no'} support column)")  # fmt: skip
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


def _xy(v: np.ndarray) -> tuple[float, float]:
    return float(v[0]), float(v[1])


SIDES: tuple[tuple[Literal["left", "right"], str], ...] = (("left", "#2b8cbe"),
                                                          ("right", "#d7301f"))  # fmt: skip


def _conventions_figure(at_m: float, out: Path) -> None:
    track = demo_track()
    enu = np.asarray(track.enu_at(np.arange(at_m - 400, at_m + 401, 5.0)))
    here = np.asarray(track.enu_at(np.array([at_m])))[0]
    heading = float(track.heading_at(at_m))
    fig = plt.figure(figsize=(12.5, 5.6))
    top = fig.add_subplot(1, 2, 1)
    top.plot(enu[:, 0] - here[0], enu[:, 1] - here[1], color="0.3", lw=2)
    for c in range(int(at_m - 400) // 100 * 100 + 100, int(at_m + 400), 100):
        p = np.asarray(track.enu_at(np.array([float(c)])))[0] - here
        top.plot(p[0], p[1], "o", color="0.3", ms=3)
        top.annotate(f"chainage {c} m", _xy(p), textcoords="offset points", xytext=(8, -3),
                     fontsize=7)  # fmt: skip
    h = np.radians(heading)
    fwd, left = np.array([np.sin(h), np.cos(h)]), np.array([-np.cos(h), np.sin(h)])
    top.annotate("", xy=_xy(60 * fwd), xytext=(0, 0),
                 arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 1.5})  # fmt: skip
    top.text(*_xy(60 * fwd - 22 * left), "x: forward\n(increasing chainage)", fontsize=8,
             ha="center")  # fmt: skip
    for name, colour in SIDES:
        mount = Mount.default(name)
        yaw = np.radians(mount.yaw_deg)
        look = np.cos(yaw) * fwd + np.sin(yaw) * left
        off = mount.lever_arm_m[1] * left * 8  # the 1.5 m lever arm, drawn 8x
        top.annotate("", xy=_xy(off + 40 * look), xytext=_xy(off),
                     arrowprops={"arrowstyle": "-|>", "color": colour})  # fmt: skip
        axis = "y: left" if name == "left" else "-y: right"
        top.text(*_xy(off + 55 * look), f"{axis}\n{name} camera, yaw {mount.yaw_deg:+.0f} deg",
                 color=colour, fontsize=7, ha="center", va="center")  # fmt: skip
    top.annotate("", xy=(0, 95), xytext=(0, 0),
                 arrowprops={"arrowstyle": "-|>", "color": "0.5"})  # fmt: skip
    top.text(0, 99, "true north (az_deg 0)", ha="center", fontsize=8, color="0.4")
    arc = np.radians(np.linspace(0, heading, 50))
    top.plot(22 * np.sin(arc), 22 * np.cos(arc), color="0.4", lw=1)
    top.text(25, 12, f"heading_deg = {heading:.1f}\n(az_deg: clockwise from north)", fontsize=8)
    top.set_aspect("equal")
    top.set_xlim(-130, 130)
    top.set_ylim(-120, 120)
    top.set_xlabel("east of the antenna (m)")
    top.set_ylabel("north of the antenna (m)")
    top.set_title(f"Seen from above: {track.name}, chainage {at_m:.0f} m\n(camera offsets "
                  "drawn 8x)", fontsize=9)  # fmt: skip
    cut = fig.add_subplot(1, 2, 2)
    cut.axhline(0, color="0.7", lw=0.8)
    cut.plot(0, 0, "k^", ms=9)
    cut.text(-0.1, -0.3, "GNSS antenna:\nvehicle origin", fontsize=8, ha="right")
    for name, colour in SIDES:
        mount = Mount.default(name)
        y, z = mount.lever_arm_m[1], mount.lever_arm_m[2]
        pitch = np.radians(mount.pitch_deg)
        sgn = 1.0 if y > 0 else -1.0
        # looking along increasing chainage: the left side is drawn on the left
        cut.plot(-y, z, "s", color=colour, ms=7)
        cut.annotate("", xy=(-y - sgn * 1.6 * np.cos(pitch), z + 1.6 * np.sin(pitch)),
                     xytext=(-y, z), arrowprops={"arrowstyle": "->", "color": colour})  # fmt: skip
        cut.text(-y, z - 0.5, f"{name}: {abs(y):g} m {name}, {abs(z):g} m below\n"
                 f"the antenna, pitch {mount.pitch_deg:g} deg up", color=colour, fontsize=7,
                 ha="center")  # fmt: skip
    cut.annotate("", xy=(0, 1.4), xytext=(0, 0), arrowprops={"arrowstyle": "-|>"})
    cut.text(0.05, 1.45, "z: up (ellipsoid normal)", fontsize=8)
    el = np.radians(30.0)
    cut.plot([0, 2.8 * np.cos(el)], [0, 2.8 * np.sin(el)], color="0.4", ls=":")
    cut.text(1.0, 0.15, "el_deg: above the local horizontal", fontsize=8, color="0.3",
             rotation=30)  # fmt: skip
    cut.set_aspect("equal")
    cut.set_xlim(-3.3, 3.3)
    cut.set_ylim(-1.5, 2.0)
    cut.set_xlabel("to the right of the track (m), looking along increasing chainage")
    cut.set_ylabel("height above the antenna (m)")
    cut.set_title("Seen along the track: the default side-camera mounts (Mount.default)",
                  fontsize=9)  # fmt: skip
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


def _terrain_figure(tiles: Path, out: Path) -> None:
    files = sorted(tiles.glob("*.hgt")) + sorted(tiles.glob("*.tif"))
    if not files:
        sys.exit(f"{tiles}: no .hgt or .tif tile; give the folder of the SRTM tiles")
    dem = Dem.from_files(files)
    az = np.arange(0.0, 360.0, 0.5)
    fig, axes = plt.subplots(1, len(PLACES), figsize=(13, 3.8), sharey=True)
    for ax, (name, lat, lon) in zip(axes, PLACES, strict=True):
        h0 = antenna_height_m(dem, [lat], [lon], ANTENNA_ABOVE_GROUND_M)
        hz = terrain_horizon(dem, [lat], [lon], h0, az)
        bare = dataclasses.replace(dem, vertical_error_m=0.0)
        hz0 = terrain_horizon(bare, [lat], [lon], h0, az)
        el, el0, ok = hz.el_deg[0], hz0.el_deg[0], hz.complete[0]
        ax.fill_between(az, el0, el, color="#fdae61", alpha=0.6,
                        label=f"stated vertical error ({dem.vertical_error_m:g} m)")  # fmt: skip
        ax.plot(az, el, color="#8c6d31", lw=1.2, label="terrain horizon (used)")
        ax.axhline(FAR_DEFAULT_DEG, color="k", ls="--", lw=1, label="flat far-field default")
        above = el > FAR_DEFAULT_DEG
        ax.fill_between(az, FAR_DEFAULT_DEG, el, where=above, facecolor="none",
                        edgecolor="#d7301f", hatch="///", lw=0,
                        label="the flat default would trust this")  # fmt: skip
        if not ok.all():
            ax.plot(az[~ok], el[~ok], "x", color="#d7301f", ms=3, label="ray left the tiles")
        ax.set_title(f"{name}\nhighest {np.nanmax(el):.1f} deg; above 5 deg in "
                     f"{100 * above.mean():.0f} % of azimuths", fontsize=9)  # fmt: skip
        ax.set_xlabel("azimuth (deg from north)")
        ax.set_xticks([0, 90, 180, 270, 360])
        ax.set_xlim(0, 360)
    axes[0].set_ylabel("elevation (deg)")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Terrain horizon from {', '.join(f.name for f in files)} "
                 "(200 m - 25 km, curvature and refraction k = 0.13)")  # fmt: skip
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="figure", required=True)
    m = sub.add_parser("mask", help="what a mask file holds (docs/mask-format.md)")
    m.add_argument("masks", type=Path, help="a masks.parquet")
    m.add_argument("--from-m", type=float, default=1000.0, help="stretch start, chainage m")
    m.add_argument("--to-m", type=float, default=1400.0, help="stretch end, chainage m")
    m.add_argument("--at-m", type=float, default=1200.0, help="the position drawn on the sky")
    m.add_argument("--out", type=Path, default=Path("docs/figures/mask_file.png"))
    c = sub.add_parser("conventions", help="the frames and angles (docs/conventions.md)")
    c.add_argument("--at-m", type=float, default=5200.0, help="chainage of the vehicle, m")
    c.add_argument("--out", type=Path, default=Path("docs/figures/conventions.png"))
    t = sub.add_parser("terrain", help="terrain horizon against the flat default")
    t.add_argument("tiles", type=Path, help="folder of SRTM .hgt or GeoTIFF tiles")
    t.add_argument("--out", type=Path, default=Path("docs/figures/terrain_horizon.png"))
    args = p.parse_args(argv)
    if args.figure == "mask":
        _mask_figure(args.masks, args.from_m, args.to_m, args.at_m, args.out)
    elif args.figure == "conventions":
        _conventions_figure(args.at_m, args.out)
    else:
        _terrain_figure(args.tiles, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
