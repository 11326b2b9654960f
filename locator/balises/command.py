"""The ``locator balises`` sub-command: its arguments and its entry point.

:func:`add_parser` registers the sub-command on the ``locator`` command line
(:mod:`locator.cli` calls it), :func:`cmd_balises` runs it through
:func:`locator.balises.campaign.balises_to_folder`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from locator.cliopts import add_map_doubt, map_doubt_of
from predisat.cli.args import (
    add_checks,
    add_command,
    constellation,
    cutoff_deg,
    existing_dir,
    existing_file,
    existing_path,
    finite_float,
    given,
    integrity_budget,
    integrity_options,
    needs,
    non_negative_float,
    output_dir,
    positive_float,
    requires,
    seed_value,
)
from predisat.cli.common import add_masks_same_track, add_track_selection, track_option

if TYPE_CHECKING:
    from locator.balises.balisefile import BaliseList
    from locator.sim.simfile import SimRun
    from predisat.track import TrackMap

__all__ = [
    "DEFAULT_ODOMETER",
    "DEFAULT_SPACING_M",
    "ODOMETER_KINDS",
    "add_parser",
    "cmd_balises",
    "format_summary",
    "odometer_accuracy_check",
]

# defaults stated in the help and applied in cmd_balises (None in the parser: given or not);
# `locator place-balises` shares them
DEFAULT_SPACING_M = 120.0
"""Balises every this many metres without a list (GADEROS), m."""
DEFAULT_ODOMETER = "trailer-radar"
"""The simulated odometer without ``--odometer``: a braked trailer axle with a radar."""
ODOMETER_KINDS = ("trailer-radar", "motor-radar", "motor", "ideal")
"""The ``--odometer`` choices (``locator.balises.campaign.ODOMETERS``' keys, without
importing the campaign at start-up)."""
_MAX_ACCEL_MPS2 = 1.5


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Add ``balises`` to the sub-parsers of the ``locator`` command line."""
    p = add_command(
        sub, "balises",
        "virtual balises: locate a simulated run with odometry and capture its balises",
        "Locate a simulated run with the GNSS locator and the odometer between fixes, and "
        "capture virtual balises (a list, or one every --spacing metres): when each telegram "
        "is emitted, how late, and whether the balise was passed; writes the capture table "
        "and the per-epoch run (docs/odometry.md).",
    )  # fmt: skip
    p.add_argument("--sim", required=True, type=existing_dir("a `locator simulate` output "
                   "folder"), metavar="DIR", help="a `locator simulate` folder")  # fmt: skip
    p.add_argument("--track", metavar="FILE",
                   help="track GeoJSON/CSV (default: the simulation's world.npz)")  # fmt: skip
    add_track_selection(p)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--masks", type=existing_path("a mask file (e.g. the run's "
                   "true_masks.parquet) or a `predisat process` output folder"), metavar="MASKS",
                   help="trust rule: the satellites the masks say are in view")  # fmt: skip
    g.add_argument("--cutoff", type=cutoff_deg, metavar="DEG",
                   help="trust rule: a flat elevation cut-off, degrees")
    g.add_argument("--no-masks", action="store_true", help="trust rule: every received signal")
    add_masks_same_track(p)
    b = p.add_mutually_exclusive_group()
    b.add_argument("--balises", type=existing_file("a balise list CSV (docs/odometry.md)"),
                   metavar="CSV", help="balise list (default: one every --spacing metres)")
    b.add_argument(
        "--spacing",
        type=positive_float,
        metavar="M",
        help="without --balises: a balise every M metres of the run (default "
        f"{DEFAULT_SPACING_M:g}, GADEROS)",
    )
    p.add_argument(
        "--radius",
        type=positive_float,
        nargs="+",
        default=[12.0],
        metavar="M",
        help="capture radii, metres (one configuration each)",
    )
    p.add_argument("--arm-radius", type=non_negative_float, default=0.0, metavar="M",
                   help="arm zone radius, metres (0: none)")
    p.add_argument("--emit", choices=("at_fix", "predicted"), default="at_fix",
                   help="telegram at the first fix past the balise, or predicted from the last "
                   "fix before it with the odometer speed")  # fmt: skip
    o = p.add_mutually_exclusive_group()
    o.add_argument(
        "--odometer",
        choices=tuple(ODOMETER_KINDS),
        help=f"the simulated odometer (default {DEFAULT_ODOMETER}: braked trailer axle and radar)",
    )
    o.add_argument("--odometer-log", type=existing_file("an odometer log CSV (docs/odometry.md)"),
                   metavar="CSV",
                   help="a recorded odometer log of the run instead of the simulated odometer "
                   "(docs/odometry.md; its bounds: --odometer-accuracy; default: none)")
    p.add_argument("--odometer-accuracy", nargs=3, type=non_negative_float,
                   metavar=("ABS_M", "OVER", "UNDER"),
                   help="bounds of the odometer: fixed part (m), relative over- and under-reading "
                   "(default: the simulated odometer's; 5 0.05 0.05 for a log)")  # fmt: skip
    p.add_argument(
        "--max-accel",
        type=positive_float,
        metavar="MPS2",
        help="with --odometer-log: the odometer's configured maximum acceleration, m/s^2 "
        f"(default {_MAX_ACCEL_MPS2:g})",
    )
    p.add_argument("--error-model", type=existing_file("a pseudorange error model JSON written "
                   "by `locator calibrate`"), metavar="JSON",
                   help="from `locator calibrate` (default: a = b = 2 m, the simulator's: it "
                   "applies to simulated receivers only; a model calibrated for another receiver "
                   "gives no safety claim, as in `locator run`; its k_sigma is not used: see "
                   "--integrity-risk)")  # fmt: skip
    p.add_argument("--force-error-model", action="store_true",
                   help="intervals and captures under --error-model even when it does not apply "
                   "to the data (another receiver, antenna, code, or a locator-error-model/1 "
                   "file): not a safety claim; every epoch flagged FORCED_ERROR_MODEL, "
                   "summary.json records it")
    integrity_options(p)
    add_map_doubt(p)
    p.add_argument("--constellation", type=constellation, metavar="SYSTEMS", default="all",
                   help="systems located with: gps, gps+galileo, all, or system letters (default "
                   "all: every system the simulated run received, as a balise reader's receiver "
                   "would; `locator run` defaults to gps)")  # fmt: skip
    p.add_argument("--start-error", type=finite_float, default=0.0, metavar="M",
                   help="error of the stored position the run starts from, metres along the "
                   "track (+: ahead), within the 50 m start uncertainty (default 0: the true "
                   "chainage, which flatters every fix before the first satellite claim; the "
                   "campaigns draw it within +-50 m)")  # fmt: skip
    p.add_argument("--seed", type=seed_value, metavar="N", default=0, help="odometer seed")
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR", help="output folder")
    add_checks(
        p,
        needs("--max-accel", "max_accel", lambda a: given(a, "odometer_log"), "--odometer-log"),
        requires("--track-name", "track_name", "--track FILE", "track"),
        requires("--where", "where", "--track FILE", "track"),
        odometer_accuracy_check,
    )
    p.set_defaults(func=cmd_balises)
    return p


def odometer_accuracy_check(args: argparse.Namespace) -> str | None:
    """``--odometer-accuracy``'s relative parts are fractions below 1 (5 % is 0.05)."""
    if not args.odometer_accuracy:
        return None
    abs_m, over, under = args.odometer_accuracy
    for name, value in (("OVER", over), ("UNDER", under)):
        if value >= 1.0:
            return (f"--odometer-accuracy {abs_m:g} {over:g} {under:g}: {name} {value:g} is no "
                    f"share of the distance (below 1); give a fraction: {value:g} % is "
                    f"{value / 100:g} (e.g. 5 0.05 0.05 for SUBSET-041)")  # fmt: skip
    return None


def format_summary(summary: pd.DataFrame) -> str:
    """The printed summary: one row per capture configuration, the capture rate in percent
    (a fraction in ``summary.json``), false and hazardous captures, the epochs whose true front
    end was outside the safe front interval (``front_outside``, when given), times in seconds
    with 3 decimals; ``not reached`` for a configuration without a passage, ``-`` for a time
    without a capture."""
    cols = ["config", "passages", "captured", "capture_rate", "false", "hazardous",
            "front_outside", "timing_abs_median_s", "delay_median_s", "delay_p95_s"]  # fmt: skip
    t = summary[[c for c in cols if c in summary.columns]].copy()
    rate = 100.0 * t["capture_rate"].to_numpy(float)
    reached = t["passages"].to_numpy() > 0
    t["capture_rate"] = [f"{r:.1f}" if ok else "not reached" for r, ok in zip(rate, reached,
                                                                                strict=True)]
    t = t.rename(columns={"capture_rate": "capture_%"})
    for c in ("timing_abs_median_s", "delay_median_s", "delay_p95_s"):
        t[c] = [f"{x:.3f}" if np.isfinite(x) else "-" for x in t[c].to_numpy(float)]
    return str(t.to_string(index=False))


def _track(args: argparse.Namespace) -> tuple[TrackMap, bool]:
    """``--track`` through the one track loader; else the simulation's world's, or line 144;
    and whether it is the simulation's own track (its chainages are the simulation's)."""
    if args.track:
        return track_option(args.track, args.track_name, args.chain, args.where), False
    stored = Path(args.sim) / "world.npz"
    if stored.is_file():
        from predisat.synth.world import World  # lazy: the world needs the [synth] extra

        return World.load(stored).track, True
    return track_option(None), False


def cmd_balises(args: argparse.Namespace) -> int:
    """Run ``locator balises``; prints the capture table."""
    from tqdm import tqdm

    from locator.balises.balisefile import BaliseList
    from locator.balises.campaign import ODOMETERS, balises_to_folder, scenery_tunnel_epochs
    from locator.balises.capture import CaptureConfig
    from locator.fde import LocatorConfig
    from locator.modelcheck import deepest_k, model_use, sim_profile
    from locator.odometry.confidence import OdometerAccuracy
    from locator.run import RunConfig
    from locator.sathia import AntennaPath
    from locator.sim.simfile import SimRun
    from locator.workflow import check_track, check_track_height, check_track_offset, sim_on_track
    from predisat.gnss.errormodel import IntervalModel, default_model_file, read_error_model_file

    sim = SimRun.read(args.sim)
    tunnel_epochs = scenery_tunnel_epochs(sim)  # the world's own chainage, before any --track
    track, own_track = _track(args)
    path = AntennaPath(track, float(sim.meta.get("antenna_height_m", 4.0)))
    check_track(path, sim.antenna_ecef_m, args.sim)
    if not own_track:  # the start, odometer, balises and truth in this map's chainage
        sim = sim_on_track(sim, track, args.sim)
        note = check_track_offset(path, sim.antenna_ecef_m, str(args.sim),
                                  "its true antenna positions")  # fmt: skip
        if note is not None:  # a map metres off the simulated line: beyond the map doubt
            print(f"locator balises: warning: {note}", file=sys.stderr)
    check_track_height(path, sim.antenna_ecef_m, f"{args.sim} (its true antenna positions)")
    if args.balises:
        balises = BaliseList.from_csv(args.balises, track)
    else:
        lo, hi = sorted((float(sim.chainage_m[0]), float(sim.chainage_m[-1])))
        spacing = DEFAULT_SPACING_M if args.spacing is None else args.spacing
        if hi - lo < spacing:
            raise ValueError(
                f"{args.sim}: the run covers {hi - lo:.0f} m, less than --spacing "
                f"{spacing:g} m; give a shorter spacing or a --balises list"
            )
        balises = BaliseList.along_track(track, lo + 0.5 * spacing, hi, spacing)
    masks = None
    if args.masks:
        from predisat.masks.fileformat import read_masks
        from predisat.masks.registration import register_on_track

        # by position on the run's track, as `locator run` (masks of another map, or line)
        reg = register_on_track(read_masks(args.masks), path.track, str(args.masks),
                                same_track=args.masks_same_track)  # fmt: skip
        if not reg.same_map:
            print(f"warning: {reg.describe(str(args.masks), path.track.name)}", file=sys.stderr)
        masks = reg.masks
        from predisat.availability.run import (
            assumed_sky_notes,
            open_sky_in_tunnels_notes,
            survey_check_notes,
        )
        from predisat.masks.antenna import check_antenna_height

        # the simulation's antenna against the masks', as `locator run` checks it (masks made
        # for a 5.5 m antenna ran here with the demo's 4 m one in silence)
        note = check_antenna_height(masks, path.antenna_height_m, f"masks {args.masks}")
        if note is not None:
            print(f"locator balises: warning: {note}", file=sys.stderr)
        for note in survey_check_notes(masks.provenance):  # as `locator run` and availability
            print(f"locator balises: warning: masks {args.masks}: {note}", file=sys.stderr)
        for note in open_sky_in_tunnels_notes(masks, path.track, str(args.masks)):
            print(f"locator balises: warning: {note}", file=sys.stderr)
        for note in assumed_sky_notes(masks):  # as `locator run` and availability say it
            print(f"locator balises: warning: masks {args.masks}: {note}", file=sys.stderr)
    # the error model applies to the simulated receiver or gives no claim, as in `locator run`
    mf = read_error_model_file(args.error_model) if args.error_model else default_model_file()
    profile = sim_profile(sim, args.constellation)
    model = mf.for_systems(profile.systems)
    if args.k_sigma is not None:
        model = IntervalModel(model.error, args.k_sigma)
    locator = LocatorConfig(model=model, budget=integrity_budget(args), **map_doubt_of(args))
    use, model_record = model_use(mf, profile, args, deepest_k(locator), "locator balises")
    trust = "masks" if masks is not None else ("cutoff" if args.cutoff is not None else "none")
    cfg = RunConfig(locator, trust=trust,
                    cutoff_deg=args.cutoff if args.cutoff is not None else 15.0,
                    error_model_applies=use != "none",
                    error_model_caveat=use if use in ("forced", "gaussian_tail") else "",
                    model_el_min_deg=mf.el_min_deg, model_el_max_deg=mf.el_max_deg)  # fmt: skip
    log, accuracy = None, None
    odometer = ODOMETERS[args.odometer or DEFAULT_ODOMETER]()
    # the captures' prediction and interpolation bounds take the odometer's acceleration limit:
    # a log admitted at 2.5 m/s^2 but bounded at 1.5 would state a capture too precise
    max_accel = odometer.max_accel_mps2
    if args.odometer_log:
        from locator.odometry.logfile import read_odometer_log

        max_accel = _MAX_ACCEL_MPS2 if args.max_accel is None else args.max_accel
        log = read_odometer_log(args.odometer_log, max_accel_mps2=max_accel)
        accuracy = OdometerAccuracy.subset041()
    if args.odometer_accuracy:
        a, over, under = args.odometer_accuracy
        accuracy = OdometerAccuracy(a, over, under)
    if log is not None and accuracy is not None:
        from locator.odometry.simulated import odometer_from_log

        # before any work: the log's coverage, direction and bounds against the run
        odometer_from_log(sim, log, accuracy=accuracy)
    caps = {
        f"r{r:g}": CaptureConfig(capture_radius_m=r, arm_radius_m=args.arm_radius, emit=args.emit,
                                 max_accel_mps2=max_accel)
        for r in args.radius
    }
    quiet = bool(getattr(args, "quiet", False))
    kind = str(args.odometer_log or args.odometer or DEFAULT_ODOMETER)
    if not quiet:
        width = (locator.budget.label() if locator.budget is not None
                 else f"k = {locator.model.k_sigma:g} per pair interval")  # fmt: skip
        from predisat.availability.satellites import SYSTEM_NAMES, select_satellites

        # the systems the simulation holds, not all the option names (a user trial's GPS-only
        # run was announced as "GPS, GLONASS, Galileo, BeiDou, QZSS, NavIC")
        held = {str(x)[0] for x in select_satellites(sim.sats, args.constellation)}
        present = " + ".join(n for c, n in SYSTEM_NAMES.items() if c in held) or "none"
        print(f"locator balises: {sim.n_epoch} epochs, {len(balises)} balises, trust rule "
              f"{trust}, constellation {args.constellation} ({present} in the simulation), "
              f"{width}, odometer {kind}; locating (the first run also compiles the locator)",
              flush=True)  # fmt: skip
    with tqdm(total=sim.n_epoch, desc="locating", unit="epoch", disable=quiet,
              mininterval=0.5) as bar:  # fmt: skip
        summary, folder = balises_to_folder(
            sim, path, balises, args.out, config=cfg, masks=masks,
            odometer=odometer, captures=caps, seed=args.seed,
            log=log, accuracy=accuracy, progress=bar.update, constellation=args.constellation,
            tunnel_epochs=tunnel_epochs, start_error_m=args.start_error,
            meta={"sim": str(args.sim), "odometer_kind": kind, "error_model": model_record},
        )  # fmt: skip
    print(format_summary(summary))
    if not cfg.makes_safety_claims:
        # the table reads as capture figures like any other: a user trial's --k-sigma 1.7 run
        # printed 78.9 % captured, 0 hazardous, and only summary.json said it was no claim
        from locator.run import claim_label

        print(f"NOT A SAFETY CLAIM: the captures are a "
              f"{claim_label(cfg.error_model_caveat, cfg.locator.fixed_k_sigma)} (captures.csv, "
              "column safety_claim)")  # fmt: skip
    for line in _summary_notes(summary, balises, sim):
        print(line)
    for line in _truth_warnings(summary, folder):
        print(line, file=sys.stderr)
    print(f"-> {folder}")
    return 0


def _summary_notes(summary: pd.DataFrame, balises: BaliseList, sim: SimRun) -> list[str]:
    """A line on the balises the run never reached (they have no capture figures)."""
    out = []
    # why the passages were missed: a rate alone read as "not reliable here" when every miss
    # was the list's own accuracy_m (a user trial's 50, centimetres meant)
    for _, row in summary.iterrows():
        if row.get("miss_reasons"):
            out.append(f"missed with {row['config']}: {row['miss_reasons']} (captures.csv, "
                       "column miss_reason)")  # fmt: skip
    acc = np.asarray(balises.accuracy_m, float)
    if len(acc) and acc.max() >= 10.0 and any(
            "Q_LOCACC" in str(r) for r in summary.get("miss_reasons", [])):  # fmt: skip
        out.append(f"note: accuracy_m reaches {acc.max():g} m in {balises.source} "
                   f"({int((acc >= 10.0).sum())} of {len(acc)} balises from 10 m): it is part of "
                   "every telegram's stated accuracy, which Q_LOCACC limits to 63 m; "
                   "centimetres meant?")  # fmt: skip
    n = int(summary["not_reached"].max()) if len(summary) else 0
    if n == 0:
        return out
    lo, hi = sorted((float(sim.chainage_m[0]), float(sim.chainage_m[-1])))
    return [*out, f"not reached: {n} of {len(balises)} balises lie outside the run ({lo:.0f}-"
                  f"{hi:.0f} m of chainage, less 30 m at each end): no passage, so no capture "
                  "figures"]  # fmt: skip


def _truth_warnings(summary: pd.DataFrame, folder: Path) -> list[str]:
    """Loud lines when the simulated truth shows the location unsafe: the true front end
    outside the safe front interval, or a hazardous capture."""
    out = []
    if len(summary) and int(summary["front_outside"].iloc[0]) > 0:
        out.append(
            f"locator balises: WARNING: the true front end was OUTSIDE the safe front interval "
            f"at {int(summary['front_outside'].iloc[0])} of {int(summary['epochs'].iloc[0])} "
            f"epochs ({folder / 'summary.json'}: safe_front): the location is not safe with "
            "these inputs; check the odometer log and its bounds (--odometer-accuracy)"
        )
    for _, row in summary[summary["hazardous"] > 0].iterrows():
        out.append(
            f"locator balises: WARNING: {int(row['hazardous'])} HAZARDOUS capture(s) with "
            f"{row['config']}: a telegram whose stated accuracy does not hold the true position "
            f"({folder / 'captures.csv'}, column hazardous)"
        )
    return out
