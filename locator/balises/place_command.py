"""The ``locator place-balises`` sub-command: the placement rule along a track map.

:func:`add_parser` registers the sub-command on the ``locator`` command line
(:mod:`locator.cli` calls it), :func:`cmd_place_balises` runs
:func:`locator.balises.placement.place_balises` and writes the placed balises as the list
``locator balises --balises`` reads (``docs/odometry.md``, "Placement rule").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from locator.balises.command import (
    DEFAULT_ODOMETER,
    DEFAULT_SPACING_M,
    ODOMETER_KINDS,
    odometer_accuracy_check,
)
from predisat.cli.args import (
    add_checks,
    add_command,
    existing_file,
    finite_float,
    non_negative_float,
    output_file,
    positive_float,
    requires,
)
from predisat.cli.common import CliError, add_track_selection, km_range, track_option

if TYPE_CHECKING:
    import pandas as pd

    from predisat.track import TrackMap

__all__ = ["add_parser", "cmd_place_balises", "not_placeable_stretches"]

# defaults stated in the help and applied in cmd_place_balises
# the open-sky p95 reach of the fused interval at satellite claims, trailer axle with radar,
# 1 Hz, the campaign of docs/odometry.md ("Placement rule"): a p95, not a worst case
_ENTRY_REACH_M = 25.6


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Add ``place-balises`` to the sub-parsers of the ``locator`` command line."""
    p = add_command(
        sub, "place-balises",
        "virtual balises: place them along a track map where the placement rule allows",
        "Candidate virtual balises every --spacing metres along a track map, kept where the "
        "placement rule predicts a telegram accuracy within Q_LOCACC (63 m): the reach of the "
        "fused interval where a satellite outage begins plus the odometer's doubt since. "
        "Writes the placed balises as the list `locator balises --balises` reads "
        "(docs/odometry.md, Placement rule).",
    )  # fmt: skip
    t = p.add_mutually_exclusive_group()
    t.add_argument("--track", metavar="FILE",
                   help="track GeoJSON/CSV; its tagged tunnels are outages (default: the demo "
                   "line, line 144)")  # fmt: skip
    t.add_argument("--world", type=existing_file("a synthetic world (world.npz, written by "
                   "`predisat synth` or `locator simulate`)"), metavar="NPZ",
                   help="a synthetic world: its track and its recipe's tunnels as outages "
                   "(default: --track's map, its tagged tunnels only)")  # fmt: skip
    add_track_selection(p)
    p.add_argument("--from-km", type=finite_float, metavar="KM",
                   help="first candidate's chainage, km (default: the map's start)")
    p.add_argument("--to-km", type=finite_float, metavar="KM",
                   help="last chainage a candidate may have, km (default: the map's end)")
    p.add_argument("--spacing", type=positive_float, metavar="M",
                   help=f"a candidate every M metres (default {DEFAULT_SPACING_M:g}, GADEROS)")
    p.add_argument("--outage", nargs=2, type=non_negative_float, action="append",
                   metavar=("START_M", "END_M"),
                   help="a stretch without satellite claims (chainage, metres), besides the "
                   "map's tunnels (and --world's); repeat for several (default: none besides "
                   "those)")  # fmt: skip
    o = p.add_mutually_exclusive_group()
    o.add_argument("--odometer", choices=ODOMETER_KINDS,
                   help=f"the odometer whose bounds carry the interval through an outage "
                   f"(default {DEFAULT_ODOMETER})")  # fmt: skip
    o.add_argument("--odometer-accuracy", nargs=3, type=non_negative_float,
                   metavar=("ABS_M", "OVER", "UNDER"),
                   help="bounds of the odometer instead: fixed part (m), relative over- and "
                   "under-reading (fractions: 5 0.05 0.05 is SUBSET-041; default: --odometer's "
                   "bounds)")  # fmt: skip
    p.add_argument("--entry-reach", type=non_negative_float, metavar="M",
                   help="reach of the fused interval about the estimate where an outage begins, "
                   f"metres (default {_ENTRY_REACH_M:g}: the campaign's open-sky p95 at claims, "
                   "1 Hz, trailer axle with radar; a p95, not a worst case: give your own "
                   "measured or worst-case value)")  # fmt: skip
    p.add_argument("--accuracy", type=non_negative_float, default=1.0, metavar="M",
                   help="survey accuracy of each balise's position, metres (its accuracy_m; "
                   "default 1)")  # fmt: skip
    p.add_argument("--max-locacc", type=positive_float, default=63.0, metavar="M",
                   help="largest telegram accuracy accepted, metres (default 63: Q_LOCACC; "
                   "smaller: the capture radius, to place only where the zone holds the train)")
    p.add_argument("--prefix", default="VB", metavar="TEXT",
                   help="balise ids: TEXT and the candidate's number (default VB)")
    p.add_argument("--table", type=output_file, metavar="CSV",
                   help="also write every candidate with its predicted accuracy and whether it "
                   "is placed (default: none)")  # fmt: skip
    p.add_argument("--out", required=True, type=output_file, metavar="CSV",
                   help="the placed balise list (CSV, as `locator balises --balises` reads)")
    add_checks(
        p,
        requires("--track-name", "track_name", "--track FILE", "track"),
        requires("--where", "where", "--track FILE", "track"),
        odometer_accuracy_check,
    )
    p.set_defaults(func=cmd_place_balises)
    return p


def _track_and_tunnels(args: argparse.Namespace) -> tuple[TrackMap, list[tuple[float, float]]]:
    """The track map and its outages: the map's tunnels, and ``--world``'s recipe tunnels."""
    if args.world:
        from predisat.synth.world import World  # lazy: the world needs the [synth] extra

        world = World.load(args.world)
        tunnels = [(float(s.start_m), float(s.end_m)) for s in world.spec.stretches
                   if s.kind == "tunnel"]  # fmt: skip
        return world.track, [*world.track.tunnels_m, *tunnels]
    track = track_option(args.track, args.track_name, args.chain, args.where)
    return track, list(track.tunnels_m)


def not_placeable_stretches(table: pd.DataFrame) -> list[tuple[float, float, float]]:
    """Runs of consecutive candidates the rule does not place: ``(first chainage, last
    chainage, largest predicted accuracy)``, m, from :func:`place_balises`'s table."""
    bad = ~table["placeable"].to_numpy(bool)
    c, q = table["chainage_m"].to_numpy(float), table["predicted_q_m"].to_numpy(float)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))
    return [(float(c[a]), float(c[b - 1]), float(q[a:b].max()))
            for a, b in zip(edges[::2], edges[1::2], strict=True)]  # fmt: skip


def cmd_place_balises(args: argparse.Namespace) -> int:
    """Run ``locator place-balises``; prints what was placed and where not."""
    from locator.balises.campaign import ODOMETERS
    from locator.balises.placement import place_balises
    from locator.odometry.confidence import OdometerAccuracy
    from predisat.atomic import atomic_path

    track, outages = _track_and_tunnels(args)
    for start, end in args.outage or []:
        if not start < end:
            raise CliError(f"--outage {start:g} {end:g}: START_M must be below END_M (chainage "
                           "in metres, increasing)")  # fmt: skip
        if start >= track.length_m:
            # metres, not km (--from-km / --to-km are km): 1e6 2e6 or a stretch of another line
            raise CliError(f"--outage {start:g} {end:g}: starts past the end of {track.name} "
                           f"({track.length_m:.0f} m); the values are chainages in metres")
        if end - start < 10.0:
            # an outage shorter than a train: km typed where metres are read (--from-km is km)
            print(f"locator place-balises: warning: --outage {start:g} {end:g} is "
                  f"{end - start:.2f} m long; the values are chainages in metres (km would be "
                  f"--outage {start * 1000:g} {end * 1000:g})", file=sys.stderr)  # fmt: skip
        outages.append((start, end))
    if "," in args.prefix:
        raise CliError(f"--prefix {args.prefix!r}: ids are text without commas (the balise list "
                       "and the captures' tables are CSV); give a prefix without one")
    lo_m, hi_m = km_range(track, args.from_km, args.to_km)
    spacing = DEFAULT_SPACING_M if args.spacing is None else args.spacing
    if hi_m - lo_m < spacing:
        raise CliError(f"--from-km/--to-km: the stretch {lo_m:.0f}-{hi_m:.0f} m is shorter than "
                       f"--spacing {spacing:g} m; give a longer stretch or a shorter spacing")
    if args.odometer_accuracy:
        a, over, under = args.odometer_accuracy
        accuracy, kind = OdometerAccuracy(a, over, under), "--odometer-accuracy"
    else:
        kind = args.odometer or DEFAULT_ODOMETER
        accuracy = OdometerAccuracy.from_config(ODOMETERS[kind]())
    reach = _ENTRY_REACH_M if args.entry_reach is None else args.entry_reach
    if args.accuracy >= args.max_locacc:
        raise CliError(f"--accuracy {args.accuracy:g}: a balise surveyed to {args.accuracy:g} m "
                       f"can never state an accuracy within --max-locacc {args.max_locacc:g} m; "
                       "give the survey accuracy in metres")  # fmt: skip
    placed, table = place_balises(track, lo_m, hi_m, spacing, outages, accuracy, reach,
                                  accuracy_m=args.accuracy, max_locacc_m=args.max_locacc,
                                  prefix=args.prefix)  # fmt: skip
    if not len(placed):
        raise CliError(
            f"{track.name}: no candidate is placeable between {lo_m:.0f} and {hi_m:.0f} m (the "
            f"predicted accuracy is {table['predicted_q_m'].min():g} m at best, over "
            f"--max-locacc {args.max_locacc:g} m): give a smaller --entry-reach if measured, "
            "the odometer's own bounds (--odometer-accuracy), or check the --outage stretches"
        )
    with atomic_path(args.out) as tmp:
        placed.to_csv(tmp)
    if args.table:
        with atomic_path(args.table) as tmp:
            table.to_csv(tmp, index=False, float_format="%.17g")
    where = ", ".join(f"{a:.0f}-{b:.0f} m" for a, b in outages) or "none"
    print(f"locator place-balises: {len(table)} candidates every {spacing:g} m on {track.name} "
          f"({lo_m:.0f}-{hi_m:.0f} m), outages {where}, odometer {kind} ({accuracy.abs_error_m:g} "
          f"m + {100 * accuracy.over_rel:.1f} / {100 * accuracy.under_rel:.1f} %), entry reach "
          f"{reach:g} m: {len(placed)} placed")  # fmt: skip
    for a, b, q in not_placeable_stretches(table):
        print(f"not placeable: {a:.0f}-{b:.0f} m (predicted accuracy up to {q:g} m > "
              f"{args.max_locacc:g} m)")  # fmt: skip
    print(f"-> {Path(args.out)}")
    return 0
