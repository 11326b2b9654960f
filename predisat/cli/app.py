"""Command line of the PREDISAT pipeline (``predisat``).

Each subcommand is a thin layer over the library: it parses arguments, checks them, calls one
public function and prints a short summary. Errors from bad input are printed as one clear
message (exit code 2), never as a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from predisat import __version__
from predisat.cli import demo
from predisat.cli.args import (
    finite_float,
    output_dir,
    output_file,
    positive_float,
    positive_int,
)
from predisat.cli.common import (
    CliError,
    add_track_selection,
    km_range,
    run_main,
    track_option,
)
from predisat.cli.demo import availability_table, default_workers

if TYPE_CHECKING:
    from predisat.camera.models import CameraModel
    from predisat.synth.world import WorldSpec

__all__ = ["main"]

def _camera(kind: str, calibration: str | None) -> CameraModel:
    from predisat.camera import models as camera

    if calibration is not None:
        return camera.CameraModel.from_yaml(calibration)
    return camera.default_camera("fisheye" if kind == "fisheye" else "pinhole")


def _scenery(path: str | None) -> WorldSpec | None:
    if path is None:
        return None
    import yaml

    from predisat.synth.world import WorldSpec

    p = Path(path)
    if not p.is_file():
        raise CliError(f"--scenery {path}: no such file (give a YAML scenery recipe)")
    try:
        recipe = yaml.safe_load(p.read_text())
        return WorldSpec.from_dict(recipe if isinstance(recipe, dict) else {})
    except (yaml.YAMLError, ValueError, TypeError, KeyError) as exc:
        raise CliError(
            f"--scenery {path}: not a valid scenery recipe ({exc}); see docs/synthetic-world.md"
        ) from None


def cmd_synth(args: argparse.Namespace) -> int:
    track = track_option(args.track, args.track_name, args.chain, args.where)
    from_m, to_m = km_range(track, args.from_km, args.to_km)
    cam = _camera(args.camera, args.calibration)
    spec = _scenery(args.scenery)

    from predisat.synth.generate import generate_survey

    t0 = time.perf_counter()
    result = generate_survey(
        track,
        from_m,
        to_m,
        sky=args.sky,
        seed=args.seed,
        out_dir=Path(args.out),
        spacing_m=args.spacing_m,
        camera=cam,
        pitch_deg=args.pitch_deg,
        spec=spec,
        progress=not args.quiet,
        workers=args.workers,
    )
    dt = time.perf_counter() - t0
    print(
        f"synth: {result.n_frames} frames at {result.n_positions} positions in {dt:.1f} s "
        f"({result.n_frames / dt:.2f} frames/s); survey {result.survey_dir}, "
        f"ground truth {result.truth_dir}"
    )
    return 0


def cmd_availability(args: argparse.Namespace) -> int:
    from predisat.cli import availability

    track = None
    if args.track is not None:
        track = track_option(args.track, args.track_name, args.chain, args.where)
    run = availability.run(args, track=track)
    for warning in run.info.get("warnings", ()):
        print(f"predisat availability: warning: {warning}", file=sys.stderr)
    print(availability_table(run.summary))
    print(f"availability: report {run.report_html} ({run.elapsed_s:.1f} s); every figure in "
          f"{Path(run.report_html).parent / 'summary.csv'}")  # fmt: skip
    return 0


def cmd_evaluate_sky(args: argparse.Namespace) -> int:
    from predisat.sky.photoeval import evaluate_folder

    for data in args.data:
        if not Path(data).is_dir():
            raise CliError(f"--data {data}: no such folder (give a folder of photos and masks)")
    classifier = None
    if args.sky_net is not None:
        from predisat.sky.network import SkyNet, classifier_with_net
        from predisat.sky.segment import SkyOptions

        method = args.method or SkyOptions().method
        classifier = classifier_with_net(method, SkyNet.load(args.sky_net))
    for data in args.data:
        out = None if args.out is None else Path(args.out) / Path(data).name
        result = evaluate_folder(data, out, progress=not args.quiet, method=args.method,
                                 classifier=classifier)
        print(f"{data} ({result.layout}):")
        print(result.summary.to_string(index=False))
        if out is not None:
            print(f"  per-image table and worst cases in {out}")
    return 0


def cmd_process(args: argparse.Namespace) -> int:
    from predisat.cli import process

    result = process.run(args)
    print(f"process: {result}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from predisat.masks import fileformat as maskio

    path = maskio.mask_file_path(args.masks)
    chainage_m: float | None = args.chainage
    if args.format == "urbannav":
        if chainage_m is not None:
            raise CliError("--chainage: urbannav exports every position; drop it, or choose "
                           "--format rtklib or pvgis for one position")
    elif chainage_m is None:
        raise CliError(f"--format {args.format} exports one position: give --chainage M")
    if args.header and args.format != "urbannav":
        raise CliError(f"--header is for --format urbannav, not {args.format}; drop it")
    if args.pvgis_layout != "table" and args.format != "pvgis":
        raise CliError(f"--pvgis-layout is for --format pvgis, not {args.format}; drop it")
    masks = maskio.read_masks(path)
    include = not args.bare
    if args.format == "urbannav":
        out = maskio.to_urbannav_csv(masks, args.out, include_margin=include, header=args.header)
        what = f"{masks.n_pos} positions"
    else:
        assert chainage_m is not None  # checked above
        ch_m = float(chainage_m)
        i, _ = masks.position_index(ch_m)
        what = f"position at chainage {float(masks.chainage_m[int(i)]):.2f} m"
        if args.format == "rtklib":
            out = maskio.to_rtklib_mask(masks, ch_m, args.out, include_margin=include)
        else:
            out = maskio.to_pvgis_horizon(masks, ch_m, args.out, layout=args.pvgis_layout,
                                          include_margin=include)  # fmt: skip
    kind = "bare mask" if args.bare else "mask + margin"
    print(f"export: {args.format} ({kind}, {what}) -> {out}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from predisat.cli import evaluate

    evaluate.run(args)
    return 0


def _add_synth(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "synth",
        help="render a synthetic side-camera survey with exact ground truth",
        description=(
            "Build a procedural corridor world along a track, render left and right 45-degree "
            "camera frames every SPACING metres, and write a survey folder plus ground truth."
        ),
    )
    p.add_argument("--track", metavar="FILE", help="GeoJSON or lat/lon/h CSV (default: line 144)")
    add_track_selection(p)
    p.add_argument("--from-km", type=finite_float, metavar="A",
                   help="start chainage in km (default 0)")
    p.add_argument("--to-km", type=finite_float, metavar="B",
                   help="end chainage in km (default: end)")
    p.add_argument(
        "--sky", choices=["clear", "cloudy", "overcast", "mixed"], default="mixed", help="sky"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of scenery and sky")
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR", help="output folder")
    p.add_argument("--spacing-m", type=positive_float, default=10.0,
                   help="distance between positions")
    p.add_argument("--camera", choices=["pinhole", "fisheye"], default="pinhole")
    p.add_argument("--calibration", metavar="YAML", help="OpenCV FileStorage calibration")
    p.add_argument("--pitch-deg", type=float, default=45.0, help="camera pitch above horizontal")
    p.add_argument(
        "--scenery", metavar="YAML", help="scenery recipe (default: mixed, every kind of stretch)"
    )
    p.add_argument("--workers", type=positive_int, default=default_workers(),
                   help="rendering processes")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_synth)


def _add_availability(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import availability

    p = sub.add_parser(
        "availability",
        help="mask-aware satellite availability report along a line",
        description=(
            "Which satellites a train may trust along the line over a time window, under the "
            "survey masks, with no mask and with flat cut-offs: an HTML report with plots, "
            "CSV/Parquet tables and a GeoJSON layer for QGIS."
        ),
    )
    availability.add_arguments(p)
    add_track_selection(p)
    p.set_defaults(func=cmd_availability)


def _add_process(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import process

    p = sub.add_parser(
        "process",
        help="turn a survey's side-camera frames into elevation masks (resumable)",
        description=(
            "Segment the sky in every frame, reconstruct full 360 deg masks along the line in "
            "chainage chunks written atomically (an interrupted run resumes), and write the "
            "mask file. Bad frames are reported and skipped (--strict: stop)."
        ),
    )
    process.add_arguments(p)
    p.set_defaults(func=cmd_process)


def _add_evaluate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import evaluate

    p = sub.add_parser(
        "evaluate",
        help="compare masks with synthetic ground truth; calibrate the trust margin",
        description=(
            "Mask error by sector and source against the true masks of a synthetic survey, "
            "false-trust rate and visible sky lost; --calibrate finds the margin meeting the "
            "target share of truly line-of-sight trusted directions."
        ),
    )
    evaluate.add_arguments(p)
    p.set_defaults(func=cmd_evaluate)


def _add_export(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "export",
        help="write a mask file as UrbanNav CSV, an RTKLIB elevation mask or a PVGIS horizon",
        description=(
            "Convert a mask file (or a `predisat process` output folder) for other tools: "
            "urbannav (every position: lat, lon, h and 361 elevations at 1 deg), rtklib (one "
            "position: 'AZ EL' lines for the file-elmaskfile option of the MALIB / MRTKLIB "
            "RTKLIB forks, RTKPLOT and simobs) or pvgis (one position: horizon table). Values "
            "are the mask plus its margin, never below the mask at any azimuth the reader may "
            "look up (docs/mask-format.md)."
        ),
    )
    p.add_argument("masks", type=Path, help="mask file, or a `predisat process` output folder")
    p.add_argument("--format", required=True, choices=("urbannav", "rtklib", "pvgis"))
    p.add_argument("--out", required=True, type=output_file, metavar="FILE", help="output file")
    p.add_argument("--chainage", type=float, metavar="M",
                   help="rtklib and pvgis: the position (nearest surveyed position), metres")
    p.add_argument("--bare", action="store_true", help="the mask without its margin")
    p.add_argument("--header", action="store_true", help="urbannav: a header row")
    p.add_argument("--pvgis-layout", choices=("table", "userhorizon"), default="table",
                   help="pvgis: the horizon-profile table (default) or PVGIS's upload file")
    p.set_defaults(func=cmd_export)


def _add_evaluate_sky(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.sky.segment import METHODS  # lazy: the segmenters load OpenCV models

    p = sub.add_parser(
        "evaluate-sky",
        help="score sky segmentation on a folder of photos with ground-truth sky masks",
        description=(
            "Segment every photo of a folder and compare with its sky mask: IoU per image and "
            "per set (layouts: ADE20K original/+mask/, fisheye_hk raw_images/+mask_images/, "
            "images/+masks/, or a predisat synth output folder)."
        ),
    )
    p.add_argument("--data", required=True, nargs="+", metavar="DIR", help="photo folder(s)")
    p.add_argument("--out", type=output_dir, metavar="DIR",
                   help="write per-image tables and worst-case sheets")
    p.add_argument("--method", choices=METHODS, help="segmentation method (default: the "
                   "library's default, see docs/segmentation.md)")
    p.add_argument("--sky-net", metavar="ONNX", help="a candidate sky network (with its .json "
                   "card) instead of the shipped one, for --method cnn or ensemble")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_evaluate_sky)


def build_parser() -> argparse.ArgumentParser:
    """The ``predisat`` parser: one subcommand per job."""
    parser = argparse.ArgumentParser(
        prog="predisat",
        description=(
            "PREDISAT: side-camera railway surveys to GNSS elevation masks. "
            "Run 'predisat demo' to build the demo survey on Belgian line 144."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_synth(sub)
    _add_availability(sub)
    _add_process(sub)
    _add_evaluate(sub)
    _add_export(sub)
    _add_evaluate_sky(sub)
    demo.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``predisat`` command line; returns the exit status."""
    resume = "; finished chunks and segmented frames are kept: rerun the same command to resume"
    try:
        parser = build_parser()  # imports the commands' modules: a second or more
    except KeyboardInterrupt:
        print("\npredisat: interrupted before the command started; nothing was written: rerun "
              "the same command", file=sys.stderr)  # fmt: skip
        return 130
    code = run_main(parser, argv, "predisat {command}", interrupted_note={"process": resume})
    if argv is None:  # the process's own command line: it ends now
        # a Ctrl-C while the interpreter shuts down (the cluster's threads stop) would end a
        # finished or reported command with a traceback and exit -2
        with contextlib.suppress(ValueError):  # not the main thread: nothing to do
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    sys.exit(main())
