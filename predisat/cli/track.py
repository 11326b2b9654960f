"""``predisat track``: look at a track map before using it, and write the chosen line alone.

Every command takes ``--track FILE`` with ``--track-name``, ``--chain`` and ``--where`` to pick
one line of an Infrabel or OpenStreetMap file; this one says what that choice gives (length,
ends, fit, heights, kilometre posts, stations, tunnels, bridges), draws it
(:func:`predisat.track.figure.track_figure`) and writes it as a one-line GeoJSON that every
command reads without the selection options (:func:`predisat.track.readers.write_geojson`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from predisat.cli.args import add_command, existing_file, output_file, positive_float
from predisat.cli.common import CliError, add_track_selection, track_option

if TYPE_CHECKING:
    from predisat.track import TrackMap

__all__ = ["add_parser", "summary_lines"]

# the command's line in `predisat --help`
HELP = "show a track map (the line a --track selection gives) and write it alone"

_MAX_LISTED = 12  # tunnels, bridges or stations listed one by one; beyond, the count


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``track`` subcommand on the ``predisat`` subparsers."""
    p = add_command(
        sub, "track", HELP,
        "Read a track map as every command does (GeoJSON or CSV; --track-name, --chain and "
        "--where pick one line of a file holding several), print what it gives: length, "
        "ends, how close the fitted axis stays to the source vertices, heights, kilometre "
        "posts, stations, tunnels and bridges with their chainages; --figure draws its plan, "
        "heights and curve radii; --out writes the chosen line as a GeoJSON that other "
        "commands read with --track alone (docs/track-map.md).",
    )  # fmt: skip
    p.add_argument("track", type=existing_file("a track map (GeoJSON or CSV)"), metavar="FILE",
                   help="track map file")
    add_track_selection(p)
    p.add_argument("--tolerance", type=positive_float, metavar="M",
                   help="how far the smooth fit may leave the source vertices, metres: a coarse "
                   "source (simplified to 10 m) needs 3-10, or its kinks read as sharp curves; "
                   "--out keeps it (default: the file's own, else 1)")  # fmt: skip
    p.add_argument("--posts-from", type=existing_file("Infrabel line sections (GeoJSON)"),
                   metavar="SECTIONS",
                   help="kilometre posts from Infrabel line sections (LineStrings with mfrom/mto, "
                   "metres) projected onto the line; --out keeps them (default: the map's own)",
                   )  # fmt: skip
    p.add_argument("--out", type=output_file, metavar="GEOJSON",
                   help="write the chosen line (with its posts, stations, tunnels, bridges) here "
                   "(default: not written)")
    p.add_argument("--figure", type=output_file, metavar="PNG",
                   help="draw the plan, the heights and the curve radii here (default: not drawn)")
    p.set_defaults(func=cmd_track)


def _spans(spans: Sequence[tuple[float, float]]) -> str:
    text = ", ".join(f"{lo:,.0f}-{hi:,.0f} m" for lo, hi in spans[:_MAX_LISTED])
    more = f", ... ({len(spans) - _MAX_LISTED} more)" if len(spans) > _MAX_LISTED else ""
    return f"{len(spans)}: {text}{more}" if spans else "none in the map"


def _station(name: str, chainage_m: float, offset_m: float, along_m: float, length_m: float) -> str:
    """A station's place: its chainage and distance from the axis, or how far beyond an end
    of the map it lies (GEMBLOUX, 540 m before line 144's start, read "0 m, 41 m beside")."""
    if along_m > 1.0:
        end = "before the start" if chainage_m < 0.5 * length_m else "past the end"
        return f"{name} (off the map: {math.hypot(along_m, offset_m):,.0f} m {end})"
    return f"{name} ({chainage_m:,.0f} m, {abs(offset_m):.0f} m beside)"


_SHARP_RADIUS_M = 150.0  # under this a main line's curve is suspect (sidings go to ~100 m)


def _curves(track: TrackMap) -> str:
    """The smallest curve radius and where; a warning when it is sharp enough to be the
    source's kinks (Infrabel's 10 m simplification read 88 m where the 1 m file has 399 m)."""
    import numpy as np

    s = track.sample(2.0)
    k = np.abs(np.asarray(track.curvature_at(s), float))
    if not k.size or float(k.max()) < 1e-6:
        return "curves: none (straight)"
    i = int(np.argmax(k))
    r_m = 1.0 / float(k[i])
    under_m = 2.0 * int((k > 1.0 / 300.0).sum())
    text = (f"curves: smallest radius {r_m:,.0f} m at {s[i]:,.0f} m; {under_m:,.0f} m of the "
            "line under R 300 m")  # fmt: skip
    if r_m < _SHARP_RADIUS_M:
        text += (f" (warning: under {_SHARP_RADIUS_M:g} m is sharp for a main line: if the "
                 "source is coarsely simplified, its kinks read as curves: look at the figure "
                 f"and try --tolerance {max(3.0, 3.0 * track.tolerance_m):g})")  # fmt: skip
    return text


def summary_lines(track: TrackMap) -> list[str]:
    """What a track map holds, one line per item, chainages in metres."""
    import numpy as np

    lat, lon, _ = track.position_at([0.0, track.length_m])
    lines = [
        f"{track.name}: {track.length_m:,.1f} m of chainage from {len(track.lat_deg)} source "
        f"vertices; the fitted axis stays within {track.max_deviation_m:.2f} m of them "
        f"(tolerance {track.tolerance_m:g} m)",
        f"ends: {lat[0]:.6f} N {lon[0]:.6f} E (0 m) -> {lat[1]:.6f} N {lon[1]:.6f} E "
        f"({track.length_m:,.0f} m)",
    ]
    if np.any(track.h_m != 0.0):
        lines.append(f"heights: {float(track.h_m.min()):.1f} to {float(track.h_m.max()):.1f} m "
                     "above the ellipsoid")  # fmt: skip
    else:
        lines.append("heights: none (h = 0): fine for synthetic worlds; `locator run` refuses "
                     "it on real data (docs/locator.md, track heights)")  # fmt: skip
    posts = track.kilometre_posts
    at = [f"km {p.km_m / 1000 + 0.0:g} at {p.chainage_m:,.0f} m" for p in posts[:1] + posts[-1:]]
    if len(posts) > 1:
        lines.append(f"kilometre posts: {len(posts)}, {at[0]} to {at[1]}")
    elif posts:
        lines.append(f"kilometre posts: 1, {at[0]} (it labels the kilometre around it only)")
    else:
        lines.append("kilometre posts: none (chainage is the distance from the first vertex; "
                     "Infrabel line sections give them: --posts-from SECTIONS.geojson)")
    if track.stations:
        ch = track.project([st.lat_deg for st in track.stations],
                           [st.lon_deg for st in track.stations])  # fmt: skip
        named = sorted(zip(ch.chainage_m, ch.offset_m, ch.along_m,
                           (st.name for st in track.stations), strict=True))  # fmt: skip
        items = ", ".join(_station(name, c, off, along, track.length_m)
                          for c, off, along, name in named[:_MAX_LISTED])  # fmt: skip
        more = f", ... ({len(named) - _MAX_LISTED} more)" if len(named) > _MAX_LISTED else ""
        lines.append(f"stations: {len(named)}: {items}{more}")
    else:
        lines.append("stations: none in the map")
    lines.append(_curves(track))
    lines.append(f"tunnels: {_spans(track.tunnels_m)}")
    lines.append(f"bridges: {_spans(track.bridges_m)}")
    return lines


def cmd_track(args: argparse.Namespace) -> int:
    """``predisat track``: print the map's summary, write the figure and the one-line map."""
    track = track_option(str(args.track), args.track_name, args.chain, args.where,
                         tolerance_m=args.tolerance, option="FILE")  # fmt: skip
    if args.posts_from is not None:
        from predisat.track import TrackMapError
        from predisat.track.readers import kilometre_posts_from_sections

        try:
            posts = kilometre_posts_from_sections(track, args.posts_from)
        except TrackMapError as exc:
            raise CliError(f"--posts-from {exc}") from None
        if not posts:
            raise CliError(f"--posts-from {args.posts_from}: no line section (LineString with "
                           "mfrom/mto) lies along the line within 50 m")  # fmt: skip
        track = track.with_metadata(kilometre_posts=posts)
    for line in summary_lines(track):
        print(line)
    if args.out is not None:
        from predisat.track.readers import write_geojson

        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_geojson(track, args.out)
        print(f"-> {args.out} (read it with --track {args.out}, no selection options)")
    if args.figure is not None:
        from predisat.atomic import write_bytes_atomic
        from predisat.availability.plots import figure_to_png
        from predisat.track.figure import track_figure

        args.figure.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(args.figure, figure_to_png(track_figure(track), dpi=110))
        print(f"-> {args.figure}")
    return 0
