"""``predisat availability``: its options, mapped onto
:func:`predisat.availability.run.run_availability`."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from predisat.availability.run import AvailabilityRun, run_availability
from predisat.cli.args import (
    TIME_HELP,
    add_map_doubt,
    antenna_height_m,
    constellation,
    constellation_label,
    constellation_letters,
    cutoff_deg,
    existing_file,
    existing_path,
    finite_float,
    integrity_budget,
    integrity_options,
    map_doubt_arg,
    output_dir,
    positive_float,
    positive_int,
    scheduler_options,
    storage_options,
    url_or,
)
from predisat.cli.common import add_masks_same_track
from predisat.gnss.errormodel import ErrorModelFileError, IntervalModel, read_error_model_file
from predisat.gnss.integrity import IntegrityBudget
from predisat.track import TrackMap

__all__ = ["add_arguments", "run"]

_MASKS = "a mask file (masks.parquet) or a `predisat process` output folder"


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``predisat availability`` options to a (sub)parser; returns it."""
    p = parser
    p.add_argument("--masks", required=True, type=url_or(existing_path(_MASKS)), metavar="MASKS",
                   help="mask file, or the output folder of predisat process: a path or an "
                   "fsspec URL (http(s)://, s3://...; docs/cluster.md)")
    p.add_argument("--track", metavar="FILE",
                   help="track map the masks were made on, GeoJSON/CSV: the line's name, "
                   "kilometre posts and geometry (default: none, segments straight between "
                   "positions)")
    add_masks_same_track(p)
    p.add_argument(
        "--antenna-height", type=antenna_height_m, default=None, metavar="M",
        help="the train antenna's height above the track axis: masks made for an antenna more "
        "than 0.2 m higher are refused (from lower down the near obstacles stand higher), a "
        "lower one is said (default: not checked)",
    )  # fmt: skip
    p.add_argument(
        "--nav", nargs="+", type=existing_file("RINEX navigation, SP3 or TLE files"),
        metavar="FILE",
        help="RINEX navigation, SP3 or TLE file(s) (default: the embedded day 2020-06-25)",
    )  # fmt: skip
    p.add_argument(
        "--start", metavar="TIME",
        help=f"window start: {TIME_HELP} (default: the start of the navigation data's first "
        "hour)",
    )  # fmt: skip
    p.add_argument("--end", metavar="TIME",
                   help="window end (excluded), same forms as --start (default: 24 h after the "
                   "start, or the data's end)")
    p.add_argument("--step", type=positive_float, default=30.0, metavar="S",
                   help="epoch spacing, seconds")
    p.add_argument("--out", required=True, type=url_or(output_dir), metavar="DIR",
                   help="output folder, a path or a writable fsspec URL; rerun a killed run "
                   "with the same folder to resume it (its blocks/ keeps the finished blocks)")
    p.add_argument(
        "--constellation", type=constellation, metavar="SYSTEMS", default="gps",
        help="systems counted: gps (as LOCOPROL and `locator run`), gps+galileo, all, or system "
        "letters such as GE",
    )  # fmt: skip
    p.add_argument(
        "--cutoff", type=cutoff_deg, nargs="+", default=[15.0], metavar="DEG",
        help="flat cut-off(s) compared with the masks, degrees",
    )  # fmt: skip
    p.add_argument("--from-km", type=finite_float, metavar="KM",
                   help="stretch start, chainage km, not the line's kilometre posts (default: the "
                   "masks' first position)")
    p.add_argument("--to-km", type=finite_float, metavar="KM",
                   help="stretch end, chainage km (default: the masks' last position)")
    p.add_argument(
        "--sky-km", type=finite_float, nargs="+", metavar="KM",
        help="line kilometres (kilometre posts) of the sky plots (default: 4 evenly spaced)",
    )  # fmt: skip
    p.add_argument(
        "--interval-every", type=positive_int, default=10, metavar="N",
        help="predict the interval at every N-th epoch (1 is slow)",
    )  # fmt: skip
    p.add_argument(
        "--error-model", type=existing_file("a pseudorange error model JSON written by "
        "`locator calibrate`"), metavar="JSON",
        help="pseudorange error model of the predicted intervals, from `locator calibrate` "
        "(default a = b = 2 m; its k_sigma is not used: see --integrity-risk)",
    )  # fmt: skip
    integrity_options(p)
    add_map_doubt(p)
    scheduler_options(p, "the blocks of positions", threads=True)
    p.add_argument(
        "--basemap", type=existing_file("a GeoJSON of lines (railways, roads, rivers) in "
                                        "WGS84 longitude/latitude"), metavar="GEOJSON",
        help="offline background of the report's map, e.g. an OpenStreetMap extract around the "
        "line (default: none)",
    )  # fmt: skip
    p.add_argument("--counts", action="store_true", help="also write counts.parquet (large)")
    p.add_argument(
        "--storage-options", type=storage_options, metavar="JSON",
        help="options of the fsspec file system of URL masks and outputs, a JSON object such "
        "as '{\"anon\": true}' (docs/cluster.md; default: none, the file system's own defaults)",
    )  # fmt: skip
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return p


def run(args: argparse.Namespace, track: TrackMap | None = None) -> AvailabilityRun:
    """Run from parsed :func:`add_arguments` options (``track`` overrides ``--track``)."""
    if args.from_km is not None and args.to_km is not None and not args.from_km < args.to_km:
        raise ValueError(
            f"--from-km {args.from_km:g} --to-km {args.to_km:g}: the start must be below the end "
            "(chainage grows along the track)"
        )
    notes: list[str] = []  # the error model's warnings, for the report and the console
    model = _interval_model(args.error_model, args.k_sigma, args.constellation,
                            integrity_budget(args), notes)  # fmt: skip
    result = run_availability(
        args.masks,
        track if track is not None else args.track,
        args.nav,
        out_dir=args.out,
        start=args.start,
        end=args.end,
        step_s=args.step,
        constellation=args.constellation,
        cutoff_deg=tuple(args.cutoff),
        from_m=None if args.from_km is None else args.from_km * 1000.0,
        to_m=None if args.to_km is None else args.to_km * 1000.0,
        sky_km=args.sky_km,
        interval_every=args.interval_every,
        interval_model=model,
        integrity=integrity_budget(args),
        map_doubt=map_doubt_arg(args),
        workers=args.workers,
        scheduler=args.scheduler,
        counts_table=args.counts,
        progress=not args.quiet,
        basemap=args.basemap,
        storage_options=args.storage_options,
        notes=notes,
        masks_same_track=args.masks_same_track,
        antenna_height_m=args.antenna_height,
    )
    for warning in result.info.get("warnings", ()):
        print(f"predisat availability: warning: {warning}", file=sys.stderr)
    return result


def _interval_model(error_model: str | None, k_sigma: float | None,
                    constellation: str = "gps",
                    budget: IntegrityBudget | None = None,
                    notes: list[str] | None = None) -> IntervalModel:  # fmt: skip
    """``--error-model`` / ``--k-sigma``: the file's model of the counted systems (or the
    default), its k replaced. A file without a model of a counted system is refused; one that
    bounds no checked tail, or not as deep as the intervals' widest ``k`` (a single pair's
    under ``budget``), is used with a warning (appended to ``notes``, for the report and the
    console): `locator run` would make no claim under it."""
    notes = [] if notes is None else notes
    if error_model is not None:
        try:
            mf = read_error_model_file(error_model)
        except ErrorModelFileError as exc:
            raise ValueError(f"--error-model: {exc}") from None
        letters = constellation_letters(constellation)
        missing = [c for c in letters if mf.systems and c not in mf.systems]
        if missing:
            raise ValueError(
                f"--error-model {error_model}: no model of {constellation_label(''.join(missing))}"
                f" (the file holds {constellation_label(''.join(sorted(mf.systems)))}), which "
                f"--constellation {constellation} counts; calibrate those systems (`locator "
                "calibrate --constellation ...`) or count only the file's"
            )
        unbounded = sorted(c for c in letters if c in mf.systems
                           and not 0.0 < mf.systems[c].tail_probability < 1.0)  # fmt: skip
        if mf.applicability is None or mf.applicability.method == "estimate" or unbounded:
            what = (f"no tail of {constellation_label(''.join(unbounded))} was checked"
                    if unbounded else "it is not a checked overbound")  # fmt: skip
            notes.append(f"--error-model {error_model}: {what}; the predicted interval "
                         "lengths are not bounds (docs/errormodel.md)")  # fmt: skip
        if mf.applicability is not None and mf.applicability.frequency == "dual":
            # a review: the prediction counts every satellite in view, while `locator run
            # --dual-frequency` leaves out each one without the second code
            notes.append(f"--error-model {error_model}: a dual-frequency model (the "
                         "ionosphere-free combination): the prediction counts every satellite "
                         "in view, but a dual-frequency run leaves out those whose second code "
                         "the receiver does not give (GPS satellites without L2C on an L2C "
                         "receiver, QZSS without L2C, Galileo on E5a only): the counts and "
                         "intervals are those of a receiver tracking both codes of every "
                         "satellite (docs/observations.md)")  # fmt: skip
        k_max = k_sigma if k_sigma is not None else (budget or IntegrityBudget()).k_sigma(1)
        short = mf.depth_shortfall([c for c in letters if c in mf.systems], k_max)
        if short and not unbounded:
            notes.append(f"--error-model {error_model}: {'; '.join(short)}; the predicted "
                         "intervals rest on its Gaussian tail beyond that depth, and `locator "
                         "run` makes no safety claim under it unless told to assume that tail "
                         "(docs/errormodel.md)")  # fmt: skip
        model = mf.for_systems(list(letters))
    else:
        model = IntervalModel()
    if k_sigma is not None:
        if not (k_sigma > 0 and np.isfinite(k_sigma)):
            raise ValueError(
                f"--k-sigma must be positive and finite, got {k_sigma} (the source's 2; 3.89 "
                "gives 1e-4 per pair)"
            )
        model = IntervalModel(model.error, k_sigma)
    return model
