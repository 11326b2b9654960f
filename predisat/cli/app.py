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
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from predisat import __version__
from predisat.cli import demo, track
from predisat.cli.args import (
    HelpFormatter,
    Parser,
    add_checks,
    add_command,
    chainage_hint,
    existing_file,
    existing_path,
    finite_float,
    needs,
    output_dir,
    output_file,
    pitch_deg,
    positive_float,
    positive_int,
    seed_value,
)
from predisat.cli.common import (
    CliError,
    add_track_selection,
    command_parser,
    km_range,
    run_main,
    stretch_text,
    track_option,
)
from predisat.cli.demo import (
    DEMO_CAMERA,
    DEMO_CANT_SPEED_KMH,
    availability_table,
    default_workers,
)

if TYPE_CHECKING:
    from predisat.camera.models import CameraModel
    from predisat.camera.rigs import Rig
    from predisat.masks.maskset import MaskSet
    from predisat.synth.world import WorldSpec

__all__ = ["main"]

# the choices of `synth --sky` (predisat.synth.generate.SKY_CHOICES, which loads the renderer)
SKY_CHOICES = ("clear", "cloudy", "overcast", "mixed")
# the choices of `synth --rig` (predisat.camera.rigs.RIG_NAMES, kept in step by a test)
RIG_CHOICES = ("side-fisheye", "side-fisheye+cab", "360")
_MASKS = "a mask file (masks.parquet) or a `predisat process` output folder"

# each command's line in `predisat --help`; a command's arguments are built only when it runs
# (they import its library: seconds), the others are listed with this line alone
COMMAND_HELP = {
    "synth": "render a synthetic survey with exact ground truth",
    "availability": "mask-aware satellite availability report along a line",
    "process": "turn a survey's side-camera frames into elevation masks (resumable)",
    "network": "process a network line by line into one mask dataset, with reports",
    "evaluate": "compare masks with synthetic ground truth; calibrate the trust margin",
    "export": "write a mask file as UrbanNav CSV, an RTKLIB elevation mask or a PVGIS horizon",
    "merge": "merge the masks of parallel tracks (passing loops, sidings) worst-case onto one "
    "track",
    "evaluate-sky": "score sky segmentation on a folder of photos with ground-truth sky masks",
    "track": track.HELP,
    "demo": demo.HELP,
}

def _camera(kind: str | None, calibration: Path | None) -> CameraModel:
    from predisat.camera import models as camera

    if calibration is not None:
        return camera.CameraModel.from_yaml(calibration)
    return camera.default_camera("pinhole" if (kind or DEMO_CAMERA) == "pinhole" else "fisheye")


def _rig(
    name: str, kind: str | None, calibration: Path | None, pitch: float | None
) -> Rig:
    """The ``--rig`` preset, its side cameras set by ``--camera`` / ``--calibration`` /
    ``--pitch-deg``."""
    from predisat.camera.rigs import Rig

    if name == "360":
        if kind is not None or calibration is not None or pitch is not None:
            raise CliError(
                "--rig 360 has no side cameras: drop --camera, --calibration and --pitch-deg"
            )
        return Rig.preset(name)
    side = _camera(kind, calibration)
    return Rig.preset(name, side_camera=side, side_pitch_deg=45.0 if pitch is None else pitch)


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
    rig = _rig(args.rig, args.camera, args.calibration, args.pitch_deg)
    spec = _scenery(args.scenery)

    from predisat.synth.generate import daytime_gps_s, generate_survey

    start_gps_s = None
    if args.solar_hour is not None:
        if not 0.0 <= args.solar_hour < 24.0:
            raise CliError(f"--solar-hour {args.solar_hour}: give an hour in [0, 24), e.g. 6.5 "
                           "for a low morning sun")  # fmt: skip
        lon = float(track.position_at(from_m)[1])
        start_gps_s = daytime_gps_s(lon, solar_hour=args.solar_hour)
    t0 = time.perf_counter()
    result = generate_survey(
        track,
        from_m,
        to_m,
        sky=args.sky,
        seed=args.seed,
        out_dir=Path(args.out),
        spacing_m=args.spacing_m,
        rig=rig,
        spec=spec,
        progress=not args.quiet,
        workers=args.workers,
        start_gps_s=start_gps_s,
        cant_speed_kmh=None if args.no_cant else args.cant_speed_kmh,
        max_cant_mm=args.max_cant_mm,
        write_attitude=not args.no_imu,
    )
    dt = time.perf_counter() - t0
    print(
        f"synth: {result.n_frames} frames at {result.n_positions} positions, "
        f"{stretch_text(track, from_m, to_m)}, in {dt:.1f} s "
        f"({result.n_frames / dt:.2f} frames/s); survey {result.survey_dir}, "
        f"ground truth {result.truth_dir}"
    )
    return 0


def cmd_availability(args: argparse.Namespace) -> int:
    from predisat.cli import availability

    track = None
    if args.track is not None:
        track = track_option(args.track, args.track_name, args.chain, args.where)
    run = availability.run(args, track=track)  # prints the run's warnings
    # what the navigation data held of the constellation asked (info: "gps+galileo: GPS (31
    # satellites)"), not only what was asked
    print(f"satellites counted: {run.info['constellation'].split(': ', 1)[-1]} (--constellation "
          f"{args.constellation})")
    print(availability_table(run.summary))
    resumed = sum(r.provenance.get("blocks_resumed", 0) for r in run.results)
    if resumed:
        # said even with --quiet (no bar, hence no resume line): a log must tell a resumed
        # run from a fresh one
        blocks = sum(r.provenance.get("blocks", 0) for r in run.results)
        print(f"availability: {resumed} of {blocks} blocks of positions resumed from an "
              "interrupted run's checkpoint, the others computed now")
    print(f"availability: report {run.report_html} ({run.elapsed_s:.1f} s); every figure in "
          f"{Path(run.report_html).parent / 'summary.csv'}")  # fmt: skip
    return 0


def cmd_evaluate_sky(args: argparse.Namespace) -> int:
    from predisat.sky.photoeval import evaluate_folder, safety_table

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
        print(f"{data} ({result.layout}): safety first, percent (trusted_: the sky the "
              "pipeline keeps, above the skyline); the naive baseline beside the default")
        print(safety_table(result.summary).to_string(index=False, float_format="{:.2f}".format))
        s = result.summary.iloc[-1]
        print(f"  throughput: {s['frames_per_cpu_s']:.2f} frames per CPU-second "
              f"(JPEG decode alone: {s['decode_frames_per_cpu_s']:.0f})")
        if out is not None:
            print(f"  per-image table and worst cases in {out}")
    return 0


def cmd_process(args: argparse.Namespace) -> int:
    from predisat.cli import process

    result = process.run(args)
    print(f"process: {result}")
    refused = [b for b in result.bad_frames if b.stage != "load"]
    if result.n_frames and len({b.frame_id for b in refused}) >= result.n_frames:
        # safe (every bin assumed) but no camera's evidence at all: not a finished survey
        print(f"error: every one of the {result.n_frames} frames was refused, so the masks "
              f"written are all assumed (safe, and of no use); the first: {refused[0].message}",
              file=sys.stderr)  # fmt: skip
        return 2
    return 0


def cmd_network(args: argparse.Namespace) -> int:
    from predisat.cli import network

    result, files = network.run(args)
    print(f"network: {result}")
    for r in result.lines:
        if r.status in ("no survey", "failed"):
            print(f"  line {r.line_id} part {r.part}: {r.status}: {r.message}")
        elif r.message:  # the processing's warnings, with their line
            print(f"  line {r.line_id} part {r.part}: {r.status}, warning: {r.message}")
    if result.unmatched_surveys:
        print(f"  survey folders matching no line: {', '.join(result.unmatched_surveys)}")
    print(f"network: summary {files['html']} ({files['csv']}, map {files['map']})")
    return 0


def _make_parent(path: Path) -> None:
    """Create the folder of an output file, as the other commands create their ``--out``
    (:func:`predisat.cli.args.output_file` already refused a path under a file)."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)


def _swept(masks: MaskSet) -> bool:
    """Whether the masks were made to bound their whole cell (``--cell-sweep``; ``None`` there
    is half the largest gap)."""
    rec = masks.provenance.get("params", {}).get("reconstruction", {})
    if not isinstance(rec, dict) or "cell_sweep_m" not in rec:
        return False
    sweep = rec["cell_sweep_m"]
    return sweep is None or float(sweep) > 0.0


def cmd_export(args: argparse.Namespace) -> int:
    from predisat.masks import fileformat as maskio

    path = maskio.mask_file_path(args.masks)
    chainage_m: float | None = args.chainage
    masks = maskio.read_masks(path)
    include = not args.bare
    if args.format == "urbannav":
        _make_parent(args.out)
        out = maskio.to_urbannav_csv(masks, args.out, include_margin=include,
                                     header=not args.no_header)  # fmt: skip
        what = f"{masks.n_pos} positions"
    else:
        assert chainage_m is not None  # checked above
        ch_m = float(chainage_m)
        # the coverage the exporters take (the end cells), so that the refusal carries the hint
        lo_m, hi_m = float(masks.cell_bounds_m[0]), float(masks.cell_bounds_m[-1])
        if not lo_m <= ch_m <= hi_m:
            raise CliError(
                f"--chainage {ch_m:g} m is outside the masks of {path} ({lo_m:.1f}-{hi_m:.1f} m "
                "of chainage)" + chainage_hint(ch_m, lo_m, hi_m, "--chainage")
            )
        i, _ = masks.position_index(ch_m)
        at_m = float(masks.chainage_m[int(i)])
        what = f"position at chainage {at_m:.2f} m"
        if abs(at_m - ch_m) >= 0.005:
            # a mask holds at its position: one written for another place says so (a trial
            # asked for 4150 m and got 4160 m's mask without a word)
            what += (f", the nearest to the {ch_m:g} m asked, {abs(at_m - ch_m):.2f} m away: a "
                     "mask holds at its position" + ("" if _swept(masks) else
                     " (not made with --cell-sweep: not a bound over its cell)"))
        _make_parent(args.out)
        if args.format == "rtklib":
            out = maskio.to_rtklib_mask(masks, ch_m, args.out, include_margin=include)
        else:
            layout = args.pvgis_layout or "table"
            out = maskio.to_pvgis_horizon(masks, ch_m, args.out, layout=layout,
                                          include_margin=include)  # fmt: skip
    kind = "bare mask" if args.bare else "mask + margin"
    print(f"export: {args.format} ({kind}, {what}) -> {out}")
    return 0


def cmd_merge(args: argparse.Namespace) -> int:
    from predisat.masks import fileformat as maskio
    from predisat.masks.merge import merge_worst_case

    track = track_option(args.track, args.track_name, args.chain, args.where)
    base_path = maskio.mask_file_path(args.masks)
    paths = [maskio.mask_file_path(p) for p in args.other]
    out = Path(args.out)
    for p in (base_path, *paths):
        if out.exists() and out.resolve() == p.resolve():
            raise CliError(f"--out {out} is one of the mask files merged: write the merged masks "
                           "to a new file (the surveyed tracks' own masks are kept)")  # fmt: skip
    merge = merge_worst_case(
        maskio.read_masks(base_path), [maskio.read_masks(p) for p in paths], track,
        labels=[str(p) for p in paths], masks_label=str(base_path),
        max_offset_m=args.max_offset, same_track=args.masks_same_track,
    )  # fmt: skip
    _make_parent(out)
    written = maskio.write_masks(merge.masks, out)
    for t in merge.tracks:
        print(f"merge: {t.describe()}")
    unused = [t.label for t in merge.tracks if t.positions_used == 0 or t.cells_reached == 0]
    print(f"merge: {merge.masks.n_pos} positions of track {track.name!r}, worst case of "
          f"{len(merge.tracks) + 1} tracks -> {written}")
    if unused:
        print(f"predisat merge: warning: nothing of {', '.join(unused)} lies along track "
              f"{track.name!r} within {args.max_offset:g} m and the stretch of {base_path} "
              f"(chainage {merge.masks.cell_bounds_m[0]:.0f}-{merge.masks.cell_bounds_m[-1]:.0f} "
              "m): nothing of it was merged; check the files and the track map",
              file=sys.stderr)  # fmt: skip
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from predisat.cli import evaluate

    evaluate.run(args)
    return 0


def _add_synth(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "synth", COMMAND_HELP["synth"],
        "Build a procedural corridor world along a track, render the frames of a survey rig "
        "(default: left and right 45-degree side cameras) every SPACING metres, and write a "
        "survey folder plus ground truth (the world, the true masks, per-frame labels).",
    )  # fmt: skip
    p.add_argument("--track", metavar="FILE",
                   help="GeoJSON or lat/lon/h CSV (default: the demo line 144)")
    add_track_selection(p)
    p.add_argument("--from-km", type=finite_float, metavar="KM",
                   help="start, chainage km: metres along the map / 1000, not the line's kilometre "
                   "posts (default 0)")
    p.add_argument("--to-km", type=finite_float, metavar="KM",
                   help="end chainage, km (default: the track's end)")
    p.add_argument("--sky", choices=SKY_CHOICES, default="mixed",
                   help="sky condition of the frames (mixed: varies along the run)")
    p.add_argument("--seed", type=seed_value, metavar="N", default=0,
                   help="random seed of scenery and sky")
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR", help="output folder")
    p.add_argument("--spacing-m", type=positive_float, default=10.0, metavar="M",
                   help="distance between positions, metres")
    p.add_argument("--rig", choices=RIG_CHOICES, default="side-fisheye",
                   help="survey rig (docs/rigs.md): side cameras, side and cab cameras, or one "
                   "360-degree panoramic camera. On the held-out worlds (seeds 11-13) all three "
                   "trust under 0.0004 %% of their directions falsely; the cab rig loses the "
                   "least sky (21.8 / 25.9 %% across / along), the panorama twice as much "
                   "(50.7 / 56.1 %%: its tiles score overcast clouds as obstacles)")
    cam = p.add_mutually_exclusive_group()
    cam.add_argument("--camera", choices=["pinhole", "fisheye"],
                     help=f"built-in side camera model (default {DEMO_CAMERA}, the demo's rig: "
                     "pinhole side cameras lose 63-65 %% of the visible sky, docs/pipeline.md)")
    cam.add_argument("--calibration", type=existing_file("an OpenCV FileStorage camera "
                     "calibration YAML (docs/camera-model.md)"), metavar="YAML",
                     help="a camera calibration instead of a built-in model (default: none, "
                     "--camera)")  # fmt: skip
    p.add_argument("--pitch-deg", type=pitch_deg, metavar="DEG",
                   help="side camera pitch above horizontal, degrees (default 45)")
    p.add_argument(
        "--scenery", metavar="YAML",
        help="scenery recipe (default: drawn for the stretch, every kind of stretch from 0.8 km)",
    )  # fmt: skip
    p.add_argument("--solar-hour", type=finite_float, metavar="H",
                   help="local mean solar time of the first frame on 2024-06-21 (default 10: "
                   "mid-morning; 6-7 or 17.5-18.5 for a low sun with glare and lens flare)")
    cant = p.add_mutually_exclusive_group()
    cant.add_argument("--cant-speed-kmh", type=positive_float, metavar="KMH",
                      default=DEMO_CANT_SPEED_KMH,
                      help="cant the curves for this line speed (equilibrium cant, at most "
                      "--max-cant-mm): the vehicle rolls toward each curve's inside, as a real "
                      "one does (default %(default)s, as the demo)")  # fmt: skip
    cant.add_argument("--no-cant", action="store_true",
                      help="a line without cant: the vehicle stays level on its curves (process "
                      "takes a level roll on a sharp curve for an IMU mistake, as a real line's "
                      "curves carry cant, and bounds it from the track instead: up to 40 points "
                      "more sky lost)")  # fmt: skip
    p.add_argument("--max-cant-mm", type=positive_float, default=160.0, metavar="MM",
                   help="the largest cant the rendered line gets with --cant-speed-kmh (process's "
                   "own --max-cant-mm, 180, is the limit it assumes of an unknown line)")
    p.add_argument("--no-imu", action="store_true",
                   help="leave the manifest's roll_deg and pitch_deg columns empty (a survey "
                   "without an IMU; the pipeline then bounds them from the track's curves)")
    p.add_argument("--workers", type=positive_int, default=default_workers(), metavar="N",
                   help="rendering processes")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_synth)


def _add_availability(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import availability

    p = add_command(
        sub, "availability", COMMAND_HELP["availability"],
        "Which satellites a train may trust along the line over a time window, under the "
        "survey masks, with no mask and with flat cut-offs: an HTML report with plots, "
        "CSV/Parquet tables and a GeoJSON layer for QGIS. GPS only by default, as the LOCOPROL "
        "figures and `locator run` (--constellation).",
    )  # fmt: skip
    availability.add_arguments(p)
    add_track_selection(p)
    p.set_defaults(func=cmd_availability)


def _add_process(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import process

    p = add_command(
        sub, "process", COMMAND_HELP["process"],
        "Segment the sky in every frame, reconstruct full 360 deg masks along the line in "
        "chainage chunks written atomically (an interrupted run resumes), and write the "
        "mask file. Bad frames are reported and skipped (--strict: stop). An --out holding "
        "another survey's chunks is refused unless --replace.",
    )  # fmt: skip
    process.add_arguments(p)
    p.set_defaults(func=cmd_process)


def _add_network(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import network

    p = add_command(
        sub, "network", COMMAND_HELP["network"],
        "Read a network file (GeoJSON lines with line ids, e.g. Infrabel's whole Belgian "
        "network), process each line's survey (SURVEYS/<line id>/) on that line's track into "
        "one GeoParquet mask dataset partitioned by line (OUT/masks/line=ID/part=K/), one "
        "availability report per line and a network summary with a map. Lines without a "
        "survey are listed; a finished line is not redone (rerun to resume).",
    )  # fmt: skip
    network.add_arguments(p)
    p.set_defaults(func=cmd_network)


def _add_evaluate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli import evaluate

    p = add_command(
        sub, "evaluate", COMMAND_HELP["evaluate"],
        "Mask error by sector and source against the true masks of a synthetic survey, "
        "false-trust rate and visible sky lost; --calibrate finds the margin meeting the "
        "target share of truly line-of-sight trusted directions.",
    )  # fmt: skip
    evaluate.add_arguments(p)
    p.set_defaults(func=cmd_evaluate)


def _add_export(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "export", COMMAND_HELP["export"],
        "Convert a mask file (or a `predisat process` output folder) for other tools: "
        "urbannav (every position: lat, lon, h and 361 elevations at 1 deg), rtklib (one "
        "position: 'AZ EL' lines for the file-elmaskfile option of the MALIB / MRTKLIB "
        "RTKLIB forks, RTKPLOT and simobs) or pvgis (one position: horizon table). Values "
        "are the mask plus its margin, never below the mask at any azimuth the reader may "
        "look up (docs/mask-format.md).",
    )  # fmt: skip
    p.add_argument("masks", type=existing_path(_MASKS), metavar="MASKS",
                   help="mask file, or a `predisat process` output folder")
    p.add_argument("--format", required=True, choices=("urbannav", "rtklib", "pvgis"),
                   help="the reader's format")
    p.add_argument("--out", required=True, type=output_file, metavar="FILE", help="output file")
    p.add_argument("--chainage", type=finite_float, metavar="M",
                   help="rtklib and pvgis: the position's chainage, metres (the nearest "
                   "surveyed position is written; no default, required with these formats)")
    p.add_argument("--bare", action="store_true", help="the mask without its margin")
    p.add_argument("--header", action="store_true",
                   help="urbannav: a header row (the default; kept for old scripts)")
    p.add_argument("--no-header", action="store_true",
                   help="urbannav: no header row (UrbanNav's files have one; a reader written "
                   "for them would drop the first position)")
    p.add_argument("--pvgis-layout", choices=("table", "userhorizon"),
                   help="pvgis: the horizon-profile table or PVGIS's upload file (default table)")
    add_checks(
        p,
        needs("--chainage", "chainage", lambda a: a.format != "urbannav", "--format rtklib or "
              "pvgis (one position); urbannav exports every position"),
        lambda a: (f"--format {a.format} exports one position: give --chainage M"
                   if a.format != "urbannav" and a.chainage is None else None),
        needs("--header", "header", lambda a: a.format == "urbannav", "--format urbannav"),
        needs("--no-header", "no_header", lambda a: a.format == "urbannav", "--format urbannav"),
        lambda a: ("give --header or --no-header, not both"
                   if a.header and a.no_header else None),
        needs("--pvgis-layout", "pvgis_layout", lambda a: a.format == "pvgis", "--format pvgis"),
    )  # fmt: skip
    p.set_defaults(func=cmd_export)


def _add_merge(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.cli.common import add_masks_same_track
    from predisat.masks.registration import MAX_TRACK_OFFSET_M

    p = add_command(
        sub, "merge", COMMAND_HELP["merge"],
        "The locator follows one track map and cannot tell a train on a passing loop or the "
        "other track of a double line, 4-5 m beside it: it would take the surveyed track's "
        "masks, which are not that sky. Give the masks of the track the locator follows and "
        "those surveyed on every other track a train may take there: each bin of the result "
        "is the worst over the tracks whose places project onto it (highest mask and margin, "
        "ASSUMED where any is, weakest support); elsewhere the masks are unchanged "
        "(docs/mask-format.md, 'Passing loops and parallel tracks').",
    )  # fmt: skip
    p.add_argument("masks", type=existing_path(_MASKS), metavar="MASKS",
                   help="masks of the track the locator follows (made on --track)")
    p.add_argument("--other", required=True, nargs="+", type=existing_path(_MASKS),
                   metavar="MASKS", help="masks surveyed on the other tracks (each on its own "
                   "map, either direction)")
    p.add_argument("--track", metavar="FILE",
                   help="map of the track the locator follows, GeoJSON/CSV (default: the demo "
                   "line)")
    add_track_selection(p)
    p.add_argument("--out", required=True, type=output_file, metavar="FILE",
                   help="the merged mask file (never one of the inputs)")
    p.add_argument("--max-offset", type=positive_float, default=MAX_TRACK_OFFSET_M, metavar="M",
                   help="positions of --other farther than this beside the track are left out "
                   f"(metres, default {MAX_TRACK_OFFSET_M:g})")
    add_masks_same_track(p)
    p.set_defaults(func=cmd_merge)


def _add_evaluate_sky(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from predisat.sky.network import NET_METHODS
    from predisat.sky.segment import METHODS  # lazy: the segmenters load OpenCV models

    p = add_command(
        sub, "evaluate-sky", COMMAND_HELP["evaluate-sky"],
        "Segment every photo of a folder and compare with its sky mask: IoU per image and "
        "per set (layouts: ADE20K original/+mask/, fisheye_hk raw_images/+mask_images/, "
        "images/+masks/, or a predisat synth output folder).",
    )  # fmt: skip
    p.add_argument("--data", required=True, nargs="+", metavar="DIR", help="photo folder(s)")
    p.add_argument("--out", type=output_dir, metavar="DIR",
                   help="write per-image tables and worst-case sheets (default: print only)")
    p.add_argument("--method", choices=METHODS, help="segmentation method (default: the "
                   "library's default, see docs/segmentation.md)")
    p.add_argument("--sky-net", metavar="ONNX", help="a candidate sky network (with its .json "
                   "card) for --method cnn or ensemble (default: the shipped one)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    add_checks(
        p,
        needs("--sky-net", "sky_net", lambda a: a.method in (None, *NET_METHODS),
              f"--method {' or '.join(NET_METHODS)} (the segmenters that run a network)"),
    )  # fmt: skip
    p.set_defaults(func=cmd_evaluate_sky)


def build_parser(only: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The ``predisat`` parser: one subcommand per job.

    Parameters
    ----------
    only : collection of str, optional
        Build only these subcommands' arguments; the others are listed with their help line
        (their arguments import their library, which takes seconds). None (default) builds
        every subcommand whole.
    """
    parser: argparse.ArgumentParser = Parser(  # subcommands inherit its class
        prog="predisat",
        formatter_class=HelpFormatter,
        description=(
            "PREDISAT: side-camera railway surveys to GNSS elevation masks. "
            "Run 'predisat demo' to build the demo survey on Belgian line 144."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    adders: dict[str, Callable[[argparse._SubParsersAction[argparse.ArgumentParser]], None]] = {
        "synth": _add_synth,
        "availability": _add_availability,
        "process": _add_process,
        "network": _add_network,
        "evaluate": _add_evaluate,
        "export": _add_export,
        "merge": _add_merge,
        "evaluate-sky": _add_evaluate_sky,
        "track": track.add_parser,
        "demo": demo.add_parser,
    }
    for name, add in adders.items():
        if only is None or name in only:
            add(sub)
        else:
            sub.add_parser(name, help=COMMAND_HELP[name])
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``predisat`` command line; returns the exit status."""
    resume = "; finished chunks and segmented frames are kept: rerun the same command to resume"
    parser = command_parser(build_parser, COMMAND_HELP, argv, "predisat")
    if parser is None:
        return 130
    notes = {"process": resume, "network": resume,
             "availability": "; finished blocks are kept: rerun the same command to resume"}
    code = run_main(parser, argv, "predisat {command}", interrupted_note=notes)
    if argv is None:  # the process's own command line: it ends now
        # a Ctrl-C while the interpreter shuts down (the cluster's threads stop) would end a
        # finished or reported command with a traceback and exit -2
        with contextlib.suppress(ValueError):  # not the main thread: nothing to do
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    sys.exit(main())
