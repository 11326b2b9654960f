"""``predisat process``: its options, mapped onto
:func:`predisat.reconstruct.batch.process_survey`."""

from __future__ import annotations

import argparse
from typing import Any

from predisat.cli.args import (
    add_checks,
    antenna_height_m,
    existing_dir,
    existing_file,
    needs,
    non_negative_float,
    output_dir,
    positive_float,
    scheduler_options,
    storage_options,
    url_or,
)
from predisat.cli.common import CliError, add_track_selection, track_option
from predisat.reconstruct.batch import ProcessResult, process_survey
from predisat.reconstruct.carving import ReconstructionParams
from predisat.reconstruct.params import DEFAULT_SEGMENTER, THIN_DEG, PipelineParams
from predisat.sky.network import NET_METHODS
from predisat.sky.segment import METHODS
from predisat.track.cant import CantLimits, CantTable

__all__ = ["add_arguments", "add_attitude_arguments", "attitude_params", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``predisat process``."""
    parser.add_argument("survey", type=url_or(existing_dir("a survey folder (survey.yaml, "
                        "manifest.csv, the frames; docs/survey-format.md)")), metavar="SURVEY",
                        help="survey folder (with survey.yaml): a path or an fsspec URL "
                        "(http(s)://, s3://...; docs/cluster.md)")  # fmt: skip
    parser.add_argument(
        "--out", type=url_or(output_dir), required=True, metavar="DIR",
        help="output folder (masks.parquet, chunks/, cache/, bad_frames.csv), a path or a "
        "writable fsspec URL (s3://...); rerun with the same folder to resume",
    )  # fmt: skip
    parser.add_argument(
        "--storage-options", type=storage_options, metavar="JSON",
        help="options of the fsspec file system of URL inputs and outputs, a JSON object "
        "such as '{\"anon\": true}' or '{\"endpoint_url\": \"http://...\"}' (docs/cluster.md; "
        "default: none, the file system's own defaults)",
    )  # fmt: skip
    scheduler_options(parser, "the chunks")
    parser.add_argument(
        "--replace", action="store_true",
        help="replace the chunks another survey (or another version of this one) left in --out "
        "(without it such a folder is refused)",
    )  # fmt: skip
    parser.add_argument("--track", type=existing_file("a track map: GeoJSON line(s) or a "
                        "lat,lon[,h] CSV (docs/track-map.md)"), metavar="FILE",
                        help="track file (default: the survey's own)")  # fmt: skip
    add_track_selection(parser)
    parser.add_argument(
        "--chunk-m", type=positive_float, default=1000.0, metavar="M",
        help="chainage per chunk, metres",
    )
    parser.add_argument(
        "--strict", action="store_true", help="stop at the first bad frame instead of skipping"
    )
    parser.add_argument(
        "--segmenter", choices=METHODS, default=DEFAULT_SEGMENTER,
        help="sky segmentation method (docs/segmentation.md)",
    )  # fmt: skip
    parser.add_argument(
        "--sky-net", metavar="ONNX",
        help="a candidate sky network (with its .json card) for --segmenter cnn or ensemble; "
        "recorded in the provenance (default: the shipped one)",
    )  # fmt: skip
    parser.add_argument(
        "--thin-deg", type=non_negative_float, default=THIN_DEG, metavar="DEG",
        help="thin-structure width, degrees: narrower obstacle features (wires, cables) are "
        "L-band transparent (0 disables; docs/segmentation.md)",
    )  # fmt: skip
    parser.add_argument(
        "--margins", type=existing_file("a margin table (margins.json of `predisat evaluate "
        "--calibrate`)"), metavar="JSON",
        help="calibrated trust margins written into the mask file (default: 0 deg; "
        "margins.json of `predisat evaluate --calibrate`)",
    )  # fmt: skip
    parser.add_argument(
        "--dem", nargs="+", type=existing_file("elevation tiles: SRTM .hgt or GeoTIFF in "
        "WGS84 longitude/latitude (docs/terrain.md)"), metavar="TILE",
        help="elevation tiles bounding the far field from below: bins under the terrain "
        "horizon are raised to it and flagged terrain (default: none, a flat far field)",
    )  # fmt: skip
    parser.add_argument(
        "--cell-sweep", action="store_true",
        help="make each position's mask hold the worst over its whole cell (half-way to the "
        "neighbouring positions), not its centre: safer for a train between survey "
        "positions, at a large cost in sky (docs/reconstruction.md, section 12; default: the "
        "mask at the position)",
    )  # fmt: skip
    parser.add_argument(
        "--panorama-raise", choices=("image", "grid"), default="image",
        help="where a 360-degree panorama's low-confidence raise is taken: image (down its "
        "image columns; on a canted vehicle a wire near the zenith voids whole frames) or grid "
        "(per level azimuth: much more sky, but a camera behind the antenna may see past a "
        "cantilever over it; docs/rigs.md; default: image)",
    )  # fmt: skip
    parser.add_argument(
        "--half-space-only", action="store_true",
        help="side cameras carve with their half-space only (relative azimuths -90 to 90), not "
        "past it along their own line (docs/reconstruction.md, section 17; default: 20 deg "
        "past it, where a camera sees the column from the zenith down)",
    )  # fmt: skip
    parser.add_argument(
        "--antenna-height", type=antenna_height_m, default=None, metavar="M",
        help="height above the track axis of the train antenna the masks are for (default: "
        "the survey's antenna_height_m); the cameras stay where the survey's rig puts them. "
        "A train antenna lower than the masks' sees near obstacles higher: locator run refuses "
        "masks made for an antenna more than 0.2 m above its own",
    )  # fmt: skip
    add_attitude_arguments(parser)
    parser.add_argument(
        "-q", "--quiet", action="store_true",
        help="no progress bars nor progress lines, the final 'mask bins: ...' share of "
        "observed, reconstructed, terrain and assumed bins included (bad frames and warnings "
        "are still printed)",
    )  # fmt: skip
    add_checks(
        parser,
        needs("--sky-net", "sky_net", lambda a: a.segmenter in NET_METHODS,
              f"--segmenter {' or '.join(NET_METHODS)} (the segmenters that run a network)"),
        needs("--track-name", "track_name", lambda a: a.track is not None,
              "a --track file (it selects a line in it)"),
        needs("--where", "where", lambda a: a.track is not None,
              "a --track file (it selects a line in it)"),
    )  # fmt: skip


def add_attitude_arguments(parser: argparse.ArgumentParser) -> None:
    """The options bounding the survey vehicle's attitude (``process`` and ``network``)."""
    parser.add_argument(
        "--line-speed-kmh", type=positive_float, default=CantLimits.line_speed_kmh,
        metavar="KMH",
        help="the highest speed the line's curves were canted for (default %(default)s, above "
        "any conventional line's; a line slowed since keeps its cant): where the manifest has "
        "no measured roll, a curve's cant is bounded by this speed's equilibrium cant, and "
        "each frame's sky is eroded by the roll it leaves unknown (docs/reconstruction.md, "
        "section 16)",
    )  # fmt: skip
    parser.add_argument(
        "--cant-table", type=existing_file("a CSV with columns chainage_m and cant_mm (the "
        "cant of the line's curves, docs/reconstruction.md section 16)"), metavar="CSV",
        help="the line's cant along the track's chainage, from the infrastructure's records: "
        "where the manifest has no measured roll, the roll is bounded around it and the "
        "survey's speed, not the curves' whole range (default: none)",
    )  # fmt: skip
    parser.add_argument(
        "--max-cant-mm", type=positive_float, default=CantLimits.max_cant_mm, metavar="MM",
        help="the largest cant on the line (default %(default)s, EN 13803's limit)",
    )  # fmt: skip
    parser.add_argument(
        "--grade-doubt-deg", type=non_negative_float, default=PipelineParams.grade_doubt_deg,
        metavar="DEG",
        help="where the manifest has no measured pitch, the track map's grade is taken give "
        "or take this angle (default %(default)s; a map without heights reads level)",
    )  # fmt: skip
    parser.add_argument(
        "--imu-doubt-deg", type=non_negative_float, default=PipelineParams.imu_doubt_deg,
        metavar="DEG",
        help="accuracy of the manifest's measured roll and pitch, each (default %(default)s: "
        "taken as exact, as the mount is; give your GNSS/INS's, e.g. 0.1 for a MEMS unit)",
    )  # fmt: skip
    parser.add_argument(
        "--mount-doubt-deg", type=non_negative_float, default=0.0, metavar="DEG",
        help="how far each camera's mounting (pitch, roll, yaw) may be from its calibration "
        "(default 0: taken as exact); every frame's sky is eroded by it. A camera 2 deg off "
        "trusted 0.056 %% of the directions falsely in a user trial",
    )  # fmt: skip
    parser.add_argument(
        "--chainage-doubt-m", type=non_negative_float, default=None, metavar="M",
        help="how far any frame's true chainage may be from the manifest's (the survey's "
        "positioning accuracy along the track; default: survey.yaml's chainage_doubt_m, else "
        "0, taken as exact, with a warning); 0.05 for RTK, 3-5 for plain GNSS",
    )  # fmt: skip
    parser.add_argument(
        "--chainage-jitter-m", type=non_negative_float, default=None, metavar="M",
        help="how far frames a few hundred metres apart may be off from each other's error "
        "(the positioning's relative accuracy; default: survey.yaml's chainage_jitter_m, else "
        "the doubt): below the doubt, the masks bound the shift of the whole survey instead of "
        "each frame's, which costs less sky (docs/reconstruction.md, section 18)",
    )  # fmt: skip
    parser.add_argument(
        "--stop-gap-m", type=_stop_gap_m, default=PipelineParams.stop_gap_m, metavar="M",
        help="frames of one camera within this of the next (a stop or a crawl captured on "
        "time) are merged into one view: sky only where all of them saw it (default "
        "%(default)s; 0: frames at one chainage only; docs/reconstruction.md, section 24)",
    )  # fmt: skip
    parser.add_argument(
        "--stop-span-m", type=_stop_gap_m, default=None, metavar="M",
        help="a stop's frames spread over at most this; a longer chain (a slow crawl) is cut "
        f"into pieces (default {PipelineParams.stop_span_m:g}, a standing train's chainage "
        "jitter, or --stop-gap-m if larger)",
    )  # fmt: skip


def _stop_gap_m(text: str) -> float:
    v = non_negative_float(text)
    if v > 5.0:
        raise argparse.ArgumentTypeError(
            f"{text}: at most 5 m (frames farther apart see different scenes: separate views)"
        )
    return v


def attitude_params(args: argparse.Namespace) -> dict[str, Any]:
    """:class:`PipelineParams` keywords from :func:`add_attitude_arguments`' options."""
    table = None
    if args.cant_table is not None:
        try:
            table = CantTable.from_csv(args.cant_table)
        except ValueError as exc:
            raise CliError(f"--cant-table: {exc}") from None
    try:
        limits = CantLimits(line_speed_kmh=args.line_speed_kmh, max_cant_mm=args.max_cant_mm)
    except ValueError as exc:
        option = "--max-cant-mm" if "max_cant_mm" in str(exc) else "--line-speed-kmh"
        raise CliError(f"{option}: {exc}") from None
    return {
        "cant": limits,
        "grade_doubt_deg": args.grade_doubt_deg,
        "imu_doubt_deg": args.imu_doubt_deg,
        "mount_doubt_deg": args.mount_doubt_deg,
        "cant_table": table,
        "chainage_doubt_m": args.chainage_doubt_m,
        "chainage_jitter_m": args.chainage_jitter_m,
        "stop_gap_m": args.stop_gap_m,
        "stop_span_m": _stop_span_m(args),
    }


def _stop_span_m(args: argparse.Namespace) -> float:
    """``--stop-span-m``, by default the library's or ``--stop-gap-m`` if larger."""
    if args.stop_span_m is None:
        return max(PipelineParams.stop_span_m, args.stop_gap_m)
    if args.stop_span_m < args.stop_gap_m:
        raise CliError(f"--stop-span-m {args.stop_span_m:g} is under --stop-gap-m "
                       f"{args.stop_gap_m:g}: a stop spreads at least as far as one step")
    return float(args.stop_span_m)


def run(args: argparse.Namespace) -> ProcessResult:
    """Run ``predisat process`` from parsed arguments."""
    track = None
    if args.track is not None:
        track = track_option(str(args.track), args.track_name, args.chain, args.where)
    dem = None
    if args.dem:
        from predisat.terrain import Dem

        dem = Dem.from_files(args.dem)
    return process_survey(
        args.survey,
        args.out,
        PipelineParams(chunk_m=args.chunk_m, segmenter=args.segmenter, sky_net=args.sky_net,
                       thin_deg=args.thin_deg, antenna_height_m=args.antenna_height,
                       reconstruction=ReconstructionParams(
                           cell_sweep_m=None if args.cell_sweep else 0.0,
                           carve_past_deg=None if args.half_space_only
                           else ReconstructionParams.carve_past_deg,
                           panorama_raise=args.panorama_raise),
                       **attitude_params(args)),
        track=track,
        workers=args.workers,
        scheduler=args.scheduler,
        strict=args.strict,
        progress=not args.quiet,
        margins=args.margins,
        replace=args.replace,
        dem=dem,
        storage_options=args.storage_options,
    )
