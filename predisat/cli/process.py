"""``predisat process``: its options, mapped onto
:func:`predisat.reconstruct.batch.process_survey`."""

from __future__ import annotations

import argparse
from pathlib import Path

from predisat.cli.args import output_dir, positive_float, positive_int
from predisat.reconstruct.batch import ProcessResult, process_survey
from predisat.reconstruct.params import DEFAULT_SEGMENTER, THIN_DEG, PipelineParams
from predisat.sky.segment import METHODS
from predisat.track.map import load_track

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``predisat process``."""
    parser.add_argument("survey", type=Path, help="survey folder (with survey.yaml)")
    parser.add_argument(
        "--out", type=output_dir, required=True,
        help="output folder (masks.parquet, chunks/, cache/, bad_frames.csv); "
        "rerun with the same folder to resume",
    )  # fmt: skip
    parser.add_argument("--track", type=Path, help="track file instead of the survey's own")
    parser.add_argument(
        "--scheduler", default="local", metavar="local|serial|ADDRESS",
        help="where the chunks run: a local Dask cluster (default), this process alone "
        "(serial), or an existing Dask cluster by its scheduler's address (tcp://HOST:8786)",
    )  # fmt: skip
    parser.add_argument(
        "--workers", type=positive_int, metavar="N",
        help="worker processes of the local cluster (default: the machine's cores)",
    )  # fmt: skip
    parser.add_argument(
        "--chunk-m", type=positive_float, default=1000.0,
        help="chainage per chunk, metres (default 1000)",
    )
    parser.add_argument(
        "--strict", action="store_true", help="stop at the first bad frame instead of skipping"
    )
    parser.add_argument(
        "--segmenter", choices=METHODS,
        default=DEFAULT_SEGMENTER,
        help=f"sky segmentation method (default {DEFAULT_SEGMENTER}; docs/segmentation.md)",
    )  # fmt: skip
    parser.add_argument(
        "--sky-net", metavar="ONNX",
        help="a candidate sky network (with its .json card) instead of the shipped one, for "
        "--segmenter cnn or ensemble; recorded in the provenance",
    )  # fmt: skip
    parser.add_argument(
        "--thin-deg", type=float, default=THIN_DEG, metavar="DEG",
        help=f"thin-structure width, degrees: narrower obstacle features (wires, cables) are "
        f"L-band transparent (default {THIN_DEG}; 0 disables; docs/segmentation.md)",
    )  # fmt: skip
    parser.add_argument(
        "--margins", type=Path, metavar="FILE",
        help="calibrated trust margins (margins.json of `predisat evaluate --calibrate`) "
        "written into the mask file; default 0 deg",
    )  # fmt: skip
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> ProcessResult:
    """Run ``predisat process`` from parsed arguments."""
    track = None if args.track is None else load_track(args.track)
    return process_survey(
        args.survey,
        args.out,
        PipelineParams(chunk_m=args.chunk_m, segmenter=args.segmenter, sky_net=args.sky_net,
                       thin_deg=args.thin_deg),
        track=track,
        workers=args.workers,
        scheduler=args.scheduler,
        strict=args.strict,
        progress=not args.quiet,
        margins=args.margins,
    )
