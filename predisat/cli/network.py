"""``predisat network``: a network file and a folder of surveys -> one mask dataset partitioned
by line, one availability report per line and the network summary.

Maps onto :class:`predisat.track.network.Network`,
:func:`predisat.reconstruct.network.process_network`,
:func:`predisat.availability.network.network_availability` and
:func:`~predisat.availability.network.write_network_summary` (``docs/network.md``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from predisat.cli.args import (
    TIME_HELP,
    add_map_doubt,
    constellation,
    cutoff_deg,
    existing_dir,
    existing_file,
    integrity_budget,
    integrity_options,
    map_doubt_arg,
    output_dir,
    positive_float,
    positive_int,
    scheduler_options,
)
from predisat.cli.common import CliError, parse_where
from predisat.cli.process import add_attitude_arguments, attitude_params

if TYPE_CHECKING:
    from predisat.reconstruct.network import NetworkResult

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``predisat network``."""
    from predisat.reconstruct.params import DEFAULT_SEGMENTER
    from predisat.sky.segment import METHODS

    p.add_argument("network", type=existing_file("a network GeoJSON: line features with a line "
                   "id (docs/network.md)"), metavar="NETWORK",
                   help="network file: GeoJSON lines, each with its line id")  # fmt: skip
    p.add_argument("--surveys", required=True, type=existing_dir("a folder of survey folders "
                   "named by line id (docs/network.md)"), metavar="DIR",
                   help="folder of surveys, one folder per line named by its id")  # fmt: skip
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR",
                   help="output folder (masks/ dataset, lines/, availability/, summary); rerun "
                   "with the same folder to resume")  # fmt: skip
    p.add_argument("--lines", nargs="+", metavar="ID",
                   help="only these line ids (default: every line of the network)")
    p.add_argument("--id-key", metavar="KEY",
                   help="the property holding the line id (default: the first of line_id, "
                   "line, linecalfa, ref that every line feature has)")  # fmt: skip
    p.add_argument("--track-name", metavar="NAME",
                   help="reference track of every line (default: A, else E/U, else the first)")
    p.add_argument("--where", nargs="+", metavar="KEY=VALUE",
                   help="GeoJSON property filters (KEY=: property absent; default: none)")
    p.add_argument("--tolerance-m", type=positive_float, default=1.0, metavar="M",
                   help="the file's simplification tolerance (Infrabel's simpl10m file: 10; a "
                   "tolerance_m member of the file wins)")  # fmt: skip
    p.add_argument("--max-gap-m", type=positive_float, default=10.0, metavar="M",
                   help="pieces of a track closer than this are one part")
    scheduler_options(p, "the line tasks")
    p.add_argument("--chunk-m", type=positive_float, default=1000.0, metavar="M",
                   help="chainage per chunk inside a line, metres")
    p.add_argument("--segmenter", choices=METHODS, default=DEFAULT_SEGMENTER,
                   help="sky segmentation method (docs/segmentation.md)")
    p.add_argument("--margins", type=existing_file("a margin table (margins.json of `predisat "
                   "evaluate --calibrate`)"), metavar="JSON",
                   help="calibrated trust margins for every line (default: 0 deg)")  # fmt: skip
    p.add_argument("--strict", action="store_true",
                   help="stop at the first bad frame or failed line instead of listing it")
    p.add_argument("--no-availability", action="store_true",
                   help="masks only: no availability reports, the summary without figures")
    p.add_argument("--nav", nargs="+", type=existing_file("RINEX navigation, SP3 or TLE "
                   "files"), metavar="FILE",
                   help="navigation data (default: the embedded day 2020-06-25)")  # fmt: skip
    p.add_argument("--start", metavar="TIME", help=f"window start: {TIME_HELP} (default: the "
                   "navigation data's first hour)")  # fmt: skip
    p.add_argument("--end", metavar="TIME", help="window end (default: 24 h after the start)")
    p.add_argument("--step", type=positive_float, default=30.0, metavar="S",
                   help="epoch spacing, seconds")
    p.add_argument("--constellation", type=constellation, default="gps", metavar="SYSTEMS",
                   help="systems counted: gps, gps+galileo, all, or letters such as GE")
    p.add_argument("--cutoff", type=cutoff_deg, nargs="+", default=[15.0], metavar="DEG",
                   help="flat cut-off(s) compared with the masks, degrees")
    p.add_argument("--interval-every", type=positive_int, default=10, metavar="N",
                   help="predict the interval at every N-th epoch")
    integrity_options(p)
    add_map_doubt(p)
    add_attitude_arguments(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> tuple[NetworkResult, dict[str, Path]]:
    """Run ``predisat network``; returns the processing result and the summary's files."""
    import pandas as pd

    from predisat.availability.network import (
        AvailabilityOptions,
        LineInput,
        network_availability,
        write_network_summary,
    )
    from predisat.reconstruct.network import process_network
    from predisat.reconstruct.params import PipelineParams
    from predisat.track import TrackMapError
    from predisat.track.network import Network, overlapping_parts

    try:
        network = Network.from_file(
            args.network, lines=args.lines, id_key=args.id_key, track=args.track_name,
            where=parse_where(args.where), tolerance_m=args.tolerance_m,
            max_gap_m=args.max_gap_m, on_bad_line="skip",
        )  # fmt: skip
    except TrackMapError as exc:
        raise CliError(f"network {exc}") from None
    # a line whose track data is bad is left out and the others go on: said before the work,
    # not only in the summary (a user trial found a line with swapped coordinates gone, exit 0)
    routine = ("another track of the line", "out of service", "no track ")
    for s in network.skipped:
        if not s.reason.startswith(routine):
            print(f"predisat network: warning: {s.what} left out: {s.reason}", file=sys.stderr)
    for said in overlapping_parts(network):
        print(f"predisat network: warning: {said}", file=sys.stderr)
    out = Path(args.out)
    result = process_network(
        network, args.surveys, out, PipelineParams(chunk_m=args.chunk_m,
                                                   segmenter=args.segmenter,
                                                   **attitude_params(args)),
        scheduler=args.scheduler, workers=args.workers, strict=args.strict,
        progress=not args.quiet, margins=args.margins,
    )  # fmt: skip
    by_key = {(ln.line_id, k): tm for ln in network.lines for k, tm in enumerate(ln.parts, 1)}
    reports = []
    if not args.no_availability:
        inputs = [
            LineInput(r.line_id, r.part, r.key, str(r.masks_path), by_key[(r.line_id, r.part)])
            for r in result.lines
            if r.masks_path is not None
        ]
        budget = integrity_budget(args)
        opts = AvailabilityOptions(
            nav=None if args.nav is None else tuple(str(n) for n in args.nav),
            start=args.start, end=args.end, step_s=args.step, constellation=args.constellation,
            cutoff_deg=tuple(args.cutoff), interval_every=args.interval_every,
            integrity_risk=None if budget is None else budget.risk_per_epoch,
            k_sigma=args.k_sigma, map_doubt=map_doubt_arg(args),
        )  # fmt: skip
        reports = network_availability(inputs, out / "availability", opts,
                                       scheduler=args.scheduler, workers=args.workers,
                                       progress=not args.quiet)  # fmt: skip
    table = pd.DataFrame(
        [{"line_id": r.line_id, "part": r.part, "key": r.key, "status": r.status,
          "length_m": r.length_m, "from_m": r.from_m, "to_m": r.to_m, "n_pos": r.n_pos,
          "n_frames": r.n_frames,
          "n_bad_frames": r.n_bad_frames, "message": r.message} for r in result.lines]
    )  # fmt: skip
    files = write_network_summary(network, table, reports, out)
    return result, files
