"""Draw the package and data-flow figure of ``docs/architecture.md``.

The middle column is the data flow from survey frames to the located train, each box naming
the package that owns the step; the side columns are the supporting packages, with dashed
arrows to the step they feed. matplotlib without pyplot state (``Figure`` and
``FigureCanvasAgg``, as :mod:`predisat.availability.plots`).

Usage::

    .venv/bin/python scripts/architecture_figure.py [--out docs/figures/architecture.png]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "figures" / "architecture.png"

WIDTH_IN = 15.0
HEIGHT_IN = 12.0
DPI = 100

FLOW_COLOUR = "#dbe9f6"  # the data flow
SUPPORT_COLOUR = "#eeeeee"  # supporting packages
LOCATOR_COLOUR = "#e3f1dc"  # the locator package
CLI_COLOUR = "#fbeed5"  # command lines
EDGE = "#404040"
PACKAGE_COLOUR = "#0b3d91"
DETAIL_COLOUR = "#333333"

BOX_H = 1.0
ROW_Y = (10.3, 8.85, 7.4, 5.95, 4.5, 3.05, 1.6)  # box centres of the data flow, top to bottom
MID_X = (4.85, 10.15)
LEFT_X = (0.35, 4.0)
RIGHT_X = (11.0, 14.65)


@dataclass(frozen=True)
class Box:
    """A rectangle in figure inches: left, right, centre height, height."""

    x0: float
    x1: float
    yc: float
    h: float = BOX_H

    @property
    def top(self) -> float:
        return self.yc + self.h / 2

    @property
    def bottom(self) -> float:
        return self.yc - self.h / 2

    @property
    def xc(self) -> float:
        return (self.x0 + self.x1) / 2


def draw_box(ax: Axes, box: Box, title: str, package: str, detail: str, colour: str) -> Box:
    """A rounded box with a title, its package (monospace) and one or two lines of detail."""
    ax.add_patch(
        FancyBboxPatch(
            (box.x0, box.bottom), box.x1 - box.x0, box.h,
            boxstyle="round,pad=0,rounding_size=0.08", facecolor=colour, edgecolor=EDGE,
            linewidth=1.2,
        )
    )  # fmt: skip
    lines = [(title, {"fontsize": 12.5, "fontweight": "bold", "color": "black"})]
    if package:
        lines.append((package, {"fontsize": 12, "family": "monospace", "color": PACKAGE_COLOUR}))
    for text in detail.split("\n") if detail else []:
        lines.append((text, {"fontsize": 9.5, "color": DETAIL_COLOUR}))
    step = min(0.25, (box.h - 0.12) / len(lines))
    y = box.yc + step * (len(lines) - 1) / 2
    for text, style in lines:
        ax.text(box.xc, y, text, ha="center", va="center", **style)  # type: ignore[arg-type]
        y -= step
    return box


def arrow(
    ax: Axes,
    start: tuple[float, float],
    end: tuple[float, float],
    label: str = "",
    dashed: bool = False,
    rad: float = 0.0,
    label_at: tuple[float, float] | None = None,
    connection: str = "",
) -> None:
    """An arrow from ``start`` to ``end`` (inches), solid for data flow, dashed for support."""
    ax.add_patch(
        FancyArrowPatch(
            start, end, arrowstyle="-|>", mutation_scale=18, linewidth=1.6,
            linestyle=(0, (5, 3)) if dashed else "-", color=EDGE,
            connectionstyle=connection or f"arc3,rad={rad}", shrinkA=0, shrinkB=0,
        )
    )  # fmt: skip
    if label:
        x, y = label_at or ((start[0] + end[0]) / 2, (start[1] + end[1]) / 2 + 0.17)
        ax.text(x, y, label, ha="center", va="center", fontsize=9.5, color=DETAIL_COLOUR)


def draw(fig: Figure) -> None:
    """Draw the whole figure on ``fig`` (axes in inches, origin bottom left)."""
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0, WIDTH_IN)
    ax.set_ylim(0, HEIGHT_IN)
    ax.set_axis_off()

    # The command line, on top of everything it drives.
    cli = Box(0.35, 14.65, 11.45, 0.75)
    draw_box(
        ax, cli, "the predisat command: synth, process, evaluate, export, availability, "
        "evaluate-sky, demo", "predisat.cli",
        "argparse only here and in locator/cli.py; predisat demo runs the locator's step "
        "through the entry-point group predisat.demo_steps, without importing locator",
        CLI_COLOUR,
    )  # fmt: skip

    flow = [
        ("survey folder: side-camera frames", "predisat.survey",
         "format, load (Survey), writer (SurveyWriter)", FLOW_COLOUR),
        ("sky masks", "predisat.sky",
         "segment (segment_sky): perceptron + network ensemble, grabcut", FLOW_COLOUR),
        ("skyline directions", "predisat.reconstruct",
         "skyline (skyline_directions)", FLOW_COLOUR),
        ("carving: full-360 masks per position", "predisat.reconstruct",
         "heightfield, carving; batch: predisat process (chunks, cache)",
         FLOW_COLOUR),
        ("per-position elevation masks", "predisat.masks",
         "maskset (MaskSet), fileformat (GeoParquet),\nmargins, gaps, truth (TrueMasks)",
         FLOW_COLOUR),
        ("availability and report", "predisat.availability",
         "satellites, engine, interval, trainrun, report + plots, run", FLOW_COLOUR),
        ("1-D train locator (SATHIA)", "locator",
         "selection, sathia, intervals, fde, run, sources, evaluate", LOCATOR_COLOUR),
    ]  # fmt: skip
    boxes = [
        draw_box(ax, Box(*MID_X, y), title, package, detail, colour)
        for y, (title, package, detail, colour) in zip(ROW_Y, flow, strict=True)
    ]
    for upper, lower in pairwise(boxes):
        arrow(ax, (upper.xc, upper.bottom), (lower.xc, lower.top))
    masks, avail, loc = boxes[4], boxes[5], boxes[6]
    # The locator reads the mask file itself (mask-aware selection), beside the report's use.
    arrow(
        ax, (masks.x1, masks.yc - 0.2), (loc.x1, loc.yc + 0.25), "mask file", rad=-0.45,
        label_at=(MID_X[1] + 0.75, avail.yc),
    )  # fmt: skip

    # Supporting packages on the left, each feeding the step beside it.
    track = draw_box(
        ax, Box(*LEFT_X, ROW_Y[0]), "track maps", "predisat.track",
        "TrackMap, load_track (the one loader),\nreaders, chain, smooth, posts", SUPPORT_COLOUR,
    )  # fmt: skip
    arrow(ax, (track.x1, track.yc), (boxes[0].x0, boxes[0].yc), "chainage", dashed=True)
    camera = draw_box(
        ax, Box(*LEFT_X, ROW_Y[2]), "cameras and mounts", "predisat.camera",
        "models (CameraModel, Mount), calibfile", SUPPORT_COLOUR,
    )  # fmt: skip
    arrow(ax, (camera.x1, camera.yc), (boxes[2].x0, boxes[2].yc), "pixel rays", dashed=True)
    gnss = draw_box(
        ax, Box(*LEFT_X, ROW_Y[5]), "GNSS: time, orbits, errors", "predisat.gnss",
        "timescale, rinex_nav, sp3, tle, orbits,\nephemeris, sun, errormodel", SUPPORT_COLOUR,
    )  # fmt: skip
    arrow(ax, (gnss.x1, gnss.yc + 0.2), (avail.x0, avail.yc + 0.2), "orbits", dashed=True)

    # Supporting packages on the right.
    synth = draw_box(
        ax, Box(*RIGHT_X, ROW_Y[0]), "synthetic corridor world", "predisat.synth",
        "world, scenery, raycast, truth, sky,\nrender, generate, photos", SUPPORT_COLOUR,
    )  # fmt: skip
    arrow(
        ax, (synth.x0, synth.yc), (boxes[0].x1, boxes[0].yc), "rendered frames", dashed=True
    )
    arrow(
        ax, (synth.xc, synth.bottom), (masks.x1, masks.yc + 0.2), dashed=True,
        connection="angle,angleA=-90,angleB=0,rad=0",
    )  # fmt: skip
    ax.text(
        synth.xc + 0.12, ROW_Y[2], "true masks\n(predisat evaluate)", ha="left", va="center",
        fontsize=9.5, color=DETAIL_COLOUR,
    )  # fmt: skip
    sim = draw_box(
        ax, Box(*RIGHT_X, ROW_Y[6]), "pseudorange simulator", "locator.sim",
        "simulate, multipath, simfile", LOCATOR_COLOUR,
    )  # fmt: skip
    arrow(ax, (sim.x0, sim.yc - 0.2), (loc.x1, loc.yc - 0.2), "simulated runs", dashed=True)

    # Legend and the basics every layer may import.
    ax.text(
        RIGHT_X[0] + 0.45, ROW_Y[5],
        "solid:  data flow\ndashed: a supporting package\n        feeding a step\n"
        "blue:   predisat data flow\ngrey:   supporting, predisat\ngreen:  locator",
        ha="left", va="center", fontsize=10, color=DETAIL_COLOUR, family="monospace",
    )  # fmt: skip
    basics = Box(0.35, 14.65, 0.55, 0.6)
    draw_box(
        ax, basics,
        "basics, importable from every layer: predisat.geodesy | atomic | fileerror | jsontypes",
        "", "", SUPPORT_COLOUR,
    )  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="PNG file to write")
    args = parser.parse_args(argv)
    fig = Figure(figsize=(WIDTH_IN, HEIGHT_IN), dpi=DPI)
    FigureCanvasAgg(fig)
    draw(fig)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=DPI)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
