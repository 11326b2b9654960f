"""Command line of the 1-D locator (``locator``): simulate, run, evaluate, calibrate, demo,
balises, place-balises, campaign.

Errors from bad input are printed as one message naming the file and the fix (exit code 2).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from predisat.clock import pinned_utc

try:  # before anything imports scipy: numpy's f2py reads it with int() and crashes unclearly
    pinned_utc()
except ValueError as exc:
    sys.exit(f"error: {exc}")

from predisat.cli.args import caused_by_interrupt

try:  # a Ctrl-C here ends as an interrupt, not a traceback
    from locator.cliopts import add_map_doubt, map_doubt_of
    from locator.modelcheck import deepest_k, model_use, sim_profile
    from predisat import __version__
    from predisat.cli.args import (
        TIME_HELP,
        HelpFormatter,
        Parser,
        add_checks,
        add_command,
        antenna_height_m,
        chainage_hint,
        constellation,
        constellation_label,
        cutoff_deg,
        existing_dir,
        existing_file,
        existing_path,
        finite_float,
        given,
        integrity_budget,
        integrity_options,
        integrity_risk,
        needs,
        non_negative_float,
        output_dir,
        output_file,
        positive_float,
        positive_int,
        rate_hz,
        requires,
        seed_value,
        speed_mps,
    )
    from predisat.cli.common import (
        CliError,
        add_masks_same_track,
        add_track_selection,
        command_parser,
        km_range,
        run_main,
        stretch_text,
        track_option,
    )
    from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH
except (KeyboardInterrupt, ImportError, RuntimeError) as _exc:
    # Ctrl-C in a C extension's import comes as an ImportError caused by it, and in a
    # dataclass's class body as a RuntimeError from __set_name__ (as in predisat.cli.app)
    if not caused_by_interrupt(_exc):
        raise
    print("\nlocator: interrupted before the command started; nothing was written: rerun "
          "the same command", file=sys.stderr)  # fmt: skip
    sys.exit(130)

if TYPE_CHECKING:
    from locator.sim.simfile import SimRun

__all__ = ["main"]

# each command's line in `locator --help`; a command's arguments are built only when it runs
# (`balises`, `run` and `demo` import the locator and the track map: seconds), the others are
# listed with this line alone
COMMAND_HELP = {
    "simulate": "simulate a train run's pseudoranges in a synthetic world",
    "run": "locate the train at every epoch (simulated or RINEX)",
    "evaluate": "score a run against the true chainage",
    "calibrate": "learn sigma(el) from data with known truth",
    "demo": "a simulated run on the demo line under several trust rules",
    "balises": "virtual balises: locate a simulated run with odometry and capture its balises",
    "place-balises": "virtual balises: place them along a track map where the placement rule "
    "allows",
    "campaign": "simulated campaign: worlds x start times x rules, on Dask, resumable",
}


def _masks(args: argparse.Namespace) -> Any:
    if args.masks is None:
        return None
    from predisat.masks.fileformat import read_masks

    return read_masks(args.masks)


def _config(args: argparse.Namespace, profile: Any = None) -> tuple[Any, dict[str, Any]]:
    """The run configuration and the error model's record for ``run.json``
    (:func:`locator.modelcheck.model_use`); with the data's ``profile`` (a ReceiverProfile), the
    error model must apply to it for a safety claim (else every epoch is flagged
    ``NO_ERROR_MODEL``)."""
    from locator.fde import LocatorConfig
    from locator.partition import MAX_STRETCHES
    from locator.run import RunConfig
    from predisat.gnss.errormodel import IntervalModel, default_model_file, read_error_model_file

    mf = read_error_model_file(args.error_model) if args.error_model else default_model_file()
    model = mf.model if profile is None else mf.for_systems(profile.systems)
    if args.k_sigma is not None:
        model = IntervalModel(model.error, args.k_sigma)
    locator = LocatorConfig(model=model, budget=integrity_budget(args), **map_doubt_of(args))
    use, record = "calibrated", dict[str, Any]()
    if profile is not None:
        use, record = model_use(mf, profile, args, deepest_k(locator))
    trust = "masks" if args.masks else ("cutoff" if args.cutoff is not None else "none")
    cfg = RunConfig(
        locator,
        integrity=args.integrity,
        trust=trust,
        cutoff_deg=args.cutoff if args.cutoff is not None else 15.0,
        extra_margin_deg=args.extra_margin or 0.0,
        trust_stretches=args.trust_stretches or MAX_STRETCHES,
        start_uncertainty_m=args.start_uncertainty,
        heading_check=not args.no_heading_check,
        error_model_applies=use != "none",
        error_model_caveat=use if use in ("forced", "gaussian_tail") else "",
        model_el_min_deg=mf.el_min_deg,
        model_el_max_deg=mf.el_max_deg,
    )
    return cfg, record


def _split_text(cfg: Any) -> str:
    """`` in at most N stretches`` for a partitioned masks rule (docs/locator.md)."""
    n = cfg.trust_stretches if cfg.trust == "masks" else 1
    return f" in at most {n} stretches" if n > 1 else ""


def _progress(total: int, quiet: bool, desc: str) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="epoch", disable=quiet, mininterval=0.5)


# The default world of `locator simulate` (line 144 km 4.0-6.3, as the locator demo's) and the
# shortest: a run starts and ends 15 m inside the world.
_SIM_FROM_KM, _SIM_TO_KM = 4.0, 6.3
# a receiver's median height disagreement is said beyond the map's vertical doubt plus this
# (the fixes' own vertical error), m
_HEIGHT_SLACK_M = 2.0
_MIN_WORLD_M = 100.0


def _warn_height(
    dh_m: float, path: Any, label: str, args: argparse.Namespace, unmodelled: Sequence[str] = ()
) -> None:
    """Say when the receiver's own fixes stand off the antenna on the track by more than the
    intervals allow for, or could not tell. ``unmodelled``: systems whose fixes carried their
    ionospheric delay (no broadcast model): their height is metres high by it."""
    from predisat.availability.interval import MapDoubt

    if not math.isfinite(dh_m):
        # a user trial (2026-12-07): pseudoranges ten times too long gave no fix, and the
        # check passed without a word
        print(f"locator run: warning: {label}: none within 200 m of the track, so the "
              "track's heights and the antenna height could not be checked against them; "
              "check the observations and --track", file=sys.stderr)  # fmt: skip
        return
    vertical_m = map_doubt_of(args).get("map_doubt_vertical_m", MapDoubt().vertical_m)
    if unmodelled and abs(dh_m) > vertical_m + _HEIGHT_SLACK_M:
        # a review (2026-12-07): NYA1 with Galileo-only navigation, its own fixes 3.9 m high
        # from the ionosphere alone, and the warning blamed a correct map
        print(f"locator run: note: {label} lie {abs(dh_m):.1f} m "
              f"{'above' if dh_m > 0 else 'below'} the antenna on the track (median), but they "
              f"are single-frequency without a broadcast ionosphere model for "
              f"{', '.join(unmodelled)}, which lifts them by metres: the track's heights were "
              f"checked only against the {args.max_height_offset:g} m bound (add a GPS "
              "navigation file of the day to --nav for a finer check)",
              file=sys.stderr)  # fmt: skip
    elif abs(dh_m) > vertical_m + _HEIGHT_SLACK_M:
        # a user trial: 15-19 m accepted without a word; another (2026-12-07): 4.4 m below, the
        # intervals widened for 1 m, nothing said
        print(f"locator run: warning: {label} lie {abs(dh_m):.1f} m "
              f"{'above' if dh_m > 0 else 'below'} the antenna on the track (median; "
              f"--antenna-height {path.antenna_height_m:g} m), beyond the {vertical_m:g} m of "
              "vertical map doubt the intervals are widened for: the track map's heights or the "
              "antenna height are off (a static station on a track at its own height: "
              "--antenna-height 0); claims whose 3-D fix shows it are voided (OFF_TRACK); give "
              "WGS84 ellipsoidal heights (docs/track-map.md)", file=sys.stderr)  # fmt: skip


def _track_arg(args: argparse.Namespace) -> Any:
    """``--track`` with ``--track-name``, ``--chain`` and ``--where`` (an OpenStreetMap
    extract needs the last two, as in ``predisat synth`` and ``availability``)."""
    return track_option(args.track, args.track_name, args.chain, args.where)


def cmd_simulate(args: argparse.Namespace) -> int:
    from locator.workflow import simulate_to_folder, stop_and_go
    from predisat.availability.run import load_navigation, parse_time
    from predisat.synth.world import World, WorldSpec

    if args.world:
        track = _track_arg(args) if args.track else None
        world = World.load(args.world, track)
    else:
        track = _track_arg(args)
        seed = 0 if args.world_seed is None else args.world_seed
        if args.scenery:
            import yaml

            try:
                spec = WorldSpec.from_dict(yaml.safe_load(Path(args.scenery).read_text()) or {})
            except (yaml.YAMLError, ValueError, TypeError, KeyError) as exc:
                raise CliError(f"--scenery {args.scenery}: not a valid scenery recipe ({exc}); "
                               "see docs/synthetic-world.md") from None  # fmt: skip
        else:
            from predisat.synth.generate import default_scenery

            if args.track and (args.from_km is None or args.to_km is None):
                raise CliError(
                    f"--track {args.track}: give the stretch of it to build (--from-km and "
                    f"--to-km); the defaults ({_SIM_FROM_KM:g}-{_SIM_TO_KM:g} km) are the demo "
                    "line 144's"
                )
            from_km = _SIM_FROM_KM if args.from_km is None else args.from_km
            to_km = _SIM_TO_KM if args.to_km is None else args.to_km
            lo_m, hi_m = km_range(track, from_km, to_km)
            if hi_m - lo_m < _MIN_WORLD_M:
                raise CliError(
                    f"--from-km {from_km:g} --to-km {to_km:g}: a world of {hi_m - lo_m:.0f} m is "
                    f"too short; give at least {_MIN_WORLD_M / 1000:g} km (the run starts and "
                    "ends 15 m inside it)"
                )
            spec = default_scenery(lo_m, hi_m, seed)
        lo_m, hi_m = spec.extent_m
        print(f"building the world ({stretch_text(track, lo_m, hi_m)})")
        world = World.build(track, spec, seed)
    if args.start_chainage is not None:
        lo_m, hi_m = world.spec.extent_m
        if not lo_m <= args.start_chainage <= hi_m:
            raise CliError(
                f"--start-chainage {args.start_chainage:g} m is outside the world ({lo_m:.0f}-"
                f"{hi_m:.0f} m of chainage)"
                + chainage_hint(args.start_chainage, lo_m, hi_m, "--start-chainage")
            )
    eph = load_navigation(args.nav)
    t0 = parse_time(args.start, "--start")
    t0 = _simulation_start(eph, t0, args.nav)
    sim, folder = simulate_to_folder(
        world, eph, args.out, t0_gps_s=t0, start_chainage_m=args.start_chainage,
        direction=args.direction, profile=stop_and_go(cruise_mps=args.speed),
        duration_s=args.duration, rate_hz=args.rate, seed=args.seed,
        constellation=args.constellation, fmt=args.format, masks_out=not args.no_true_masks,
    )  # fmt: skip
    world.save(folder / "world.npz")
    c = sim.counts().mean()
    print(
        f"simulated {sim.n_epoch} epochs, chainage {sim.chainage_m[0]:.0f} -> "
        f"{sim.chainage_m[-1]:.0f} m; per epoch: {c['los']:.1f} LOS, {c['nlos']:.1f} NLOS, "
        f"{c['lost']:.1f} lost -> {folder}"
    )
    return 0


def _simulation_start(eph: Any, t0: float | None, nav: Sequence[str] | None) -> float:
    """The first epoch of a simulation: ``t0``, else 08:00 of the embedded day, or of the
    navigation data's first day when it does not cover that; refused outside the data (a
    user trial: a 2010 file simulated the embedded 2020 day with no satellite, exit 0)."""
    import numpy as np

    from predisat.availability.run import nav_span_gps_s
    from predisat.availability.satellites import default_window
    from predisat.gnss.timescale import gps_s_to_text as day

    lo, hi = nav_span_gps_s(eph)
    if t0 is None:
        t0 = float(default_window()[0] + 8 * 3600.0)
        if not lo - _NAV_REACH_S <= t0 <= hi + _NAV_REACH_S:
            t0 = float(np.floor(lo / 86400.0) * 86400.0 + 8 * 3600.0)
            t0 = t0 if t0 >= lo - _NAV_REACH_S else lo
    if not lo - _NAV_REACH_S <= t0 <= hi + _NAV_REACH_S:
        raise CliError(
            f"--start {day(t0)} GPS lies outside the navigation data of "
            f"{', '.join(map(str, nav or ['the embedded day']))} ({day(lo)} - {day(hi)}): no "
            "satellite could be placed; give a time inside it, or the navigation files of that day"
        )
    return t0


def cmd_run(args: argparse.Namespace) -> int:
    from locator.run import claim_label
    from locator.sathia import AntennaPath
    from locator.sources import RinexSource, SimSource
    from locator.workflow import (
        check_track,
        check_track_height,
        run_to_folder,
        sim_on_track,
        static_truth,
    )
    from predisat.atomic import check_writable

    source: Any
    own_track = False
    if args.sim:
        from locator.sim.simfile import SimRun

        sim = SimRun.read(args.sim)
        stored = Path(args.sim) / "world.npz"
        own_track = args.track is None and stored.is_file()
        if own_track:  # the simulation's own track
            from predisat.synth.world import World

            track = World.load(stored).track
        else:
            track = _track_arg(args)
        # the simulation states its antenna: the default, not a guess of 4 m
        path = AntennaPath(track, _antenna_height(args, sim.meta))
        check_track(path, sim.antenna_ecef_m, args.sim)
        if not own_track:  # the start, odometer and truth in this map's chainage
            sim = sim_on_track(sim, track, args.sim)
            # another map metres off the simulated line: beyond the map doubt (a trial: the
            # 10 m network map of line 144, 4.6 m off, was taken without a word)
            _warn_off_map(path, sim.antenna_ecef_m, str(args.sim),
                          "its true antenna positions")  # fmt: skip
        # another map of the line (--track) must carry the simulated world's heights too
        check_track_height(path, sim.antenna_ecef_m, f"{args.sim} (its true antenna positions)",
                           args.max_height_offset)  # fmt: skip
        source = SimSource(sim, constellation=args.constellation)
        start = sim.chainage_m[0] if args.start_chainage is None else args.start_chainage
        header, sim_chainage = None, sim.chainage_m
    elif args.device_gnss:
        import numpy as np

        from locator.devicegnss import DeviceGnssSource, read_device_gnss

        path = AntennaPath(_track_arg(args), _antenna_height(args))
        dev = read_device_gnss(args.device_gnss)
        _report_problems(args.device_gnss, dev.problems)
        source = DeviceGnssSource(dev, args.constellation)
        _warn_no_iono(source, [args.device_gnss])
        start = args.start_chainage
        # the phone's own first fix (Google's WLS) stands for the RINEX header position
        fixes = dev.wls_ecef_m[np.all(np.isfinite(dev.wls_ecef_m), axis=1)]
        header = fixes[0] if len(fixes) else None
        # not _warn_height: the phones' own (WLS) fixes stand 10-12 m above the truth on the
        # GSDC logs (docs/locator.md), a warning would blame the map for the phone
        check_track_height(path, fixes, f"{args.device_gnss} (the phone's own fixes)",
                           args.max_height_offset)  # fmt: skip
        _warn_off_map(path, fixes, f"{args.device_gnss} (the phone's own fixes)")
        sim_chainage = None
        if start is None:
            if header is None:
                raise CliError(f"{args.device_gnss}: no WlsPosition*EcefMeters in any row; pass "
                               "--start-chainage")  # fmt: skip
            check_track(path, header, f"{args.device_gnss} (the phone's first fix)",
                        _MAX_HEADER_OFFSET_M, " (or --start-chainage if that fix is wrong)")
            start = static_truth(header, path)
    else:
        from locator.corrections import RangeModel
        from locator.observations import Observations
        from locator.timetag import MIN_EVIDENCE_EPOCHS, check_time_tags

        path = AntennaPath(_track_arg(args), _antenna_height(args))
        obs = Observations.from_rinex(args.obs)
        _report_problems(args.obs, obs.problems)
        _report_no_code(args.obs, obs, args.constellation)
        model = RangeModel.from_rinex_nav(_broadcast_nav(args.nav))
        _nav_covers(model.ephemeris, obs, args.nav)
        model = model.with_iono_near(float(obs.gps_s[len(obs.gps_s) // 2]))  # the obs' day
        source = RinexSource(model, obs, args.constellation,
                             dual_frequency=args.dual_frequency)  # fmt: skip
        source = _keep_calibrated_codes(source, args)
        _one_clock(source, args.obs)
        _warn_no_iono(source, args.nav)
        # before the heights: a cause of theirs
        tags = check_time_tags(model, obs, str(args.obs), constellation=args.constellation)
        if len(tags.offset_s) < MIN_EVIDENCE_EPOCHS:
            print(f"locator run: warning: {args.obs}: its time tags could not be checked against "
                  f"its pseudoranges ({len(tags.offset_s)} of the sampled epochs had two ranges "
                  "beyond a fix's unknowns and no fault): a converter's shifted tags would "
                  "go unseen (docs/observations.md)", file=sys.stderr)  # fmt: skip
        own = _sample_fixes(model, obs)
        label = f"{args.obs} (its epochs' own fixes)"
        dh = check_track_height(path, own, label, args.max_height_offset)
        _warn_height(dh, path, label, args,
                     [s for s in source.systems if model.iono.klobuchar(s) is None])  # fmt: skip
        _warn_off_map(path, own, f"{args.obs} (its epochs' own fixes)")
        start = args.start_chainage
        hx = obs.header.approx_position_ecef_m
        header = hx if (hx == hx).all() and abs(hx).sum() > 0 else None  # RINEX: 0 0 0 if unknown
        sim_chainage = None
        if start is None:
            if header is None:
                raise CliError(
                    f"{args.obs}: no approximate position in the header; pass --start-chainage"
                )
            check_track(path, header, f"{args.obs} (its header's approximate position)",
                         _MAX_HEADER_OFFSET_M, " (or --start-chainage if that position is wrong)")
            start = static_truth(header, path)
    cfg, model_record = _config(args, _profile(source, args))
    masks = _masks(args)
    if masks is not None:
        from predisat.masks.registration import register_on_track

        reg = register_on_track(masks, path.track, str(args.masks),
                                same_track=args.masks_same_track)  # fmt: skip
        if not reg.same_map:
            print(f"warning: {reg.describe(str(args.masks), path.track.name)}", file=sys.stderr)
        masks = reg.masks
        from predisat.masks.antenna import AntennaHeightError, check_antenna_height

        try:
            note = check_antenna_height(masks, path.antenna_height_m, f"masks {args.masks}")
        except AntennaHeightError as exc:
            raise CliError(f"{exc} (--antenna-height)") from None
        if note is not None:
            print(f"locator run: warning: {note}", file=sys.stderr)
        unstated = _unstated_antenna_note(masks, path, args.masks)
        if args.antenna_height is None and not args.sim and unstated is not None:
            print(f"locator run: warning: {unstated}", file=sys.stderr)
        from predisat.availability.run import (
            assumed_sky_notes,
            open_sky_in_tunnels_notes,
            survey_check_notes,
        )

        # as predisat availability says it: a trial's all-ASSUMED masks claimed 71 % in silence;
        # a review's masks from a survey with swapped cameras (their provenance said so) ran in
        # silence too, trusting 8.6 % of the demo run's directions falsely (0.10 % unswapped)
        for note in survey_check_notes(masks.provenance):
            print(f"locator run: warning: masks {args.masks}: {note}", file=sys.stderr)
        for note in open_sky_in_tunnels_notes(masks, path.track, str(args.masks)):
            print(f"locator run: warning: {note}", file=sys.stderr)
        for note in assumed_sky_notes(masks):
            print(f"locator run: warning: masks {args.masks}: {note}", file=sys.stderr)
    _check_start(float(start), path, masks, args, header, sim_chainage)
    check_writable(args.out)  # before the epochs, not after them
    print(f"locator run: {source.gps_s.size} epochs, constellation {args.constellation} "
          f"({constellation_label(args.constellation)}), trust rule {cfg.trust}"
          f"{_split_text(cfg)}; pair intervals: {cfg.locator.width_text()}")
    with _progress(len(source.gps_s), args.quiet, "locating") as bar:
        # a simulation's truth on another map is its antenna projected there: evaluate needs
        # that map again (run.json says so, also when the simulation has no world.npz)
        sim_truth = {} if not args.sim else {"sim_chainage": "own" if own_track else "projected"}
        epochs, folder = run_to_folder(
            path, source, args.out, start_chainage_m=float(start), config=cfg,
            masks=masks, fmt=args.format, progress=bar.update,
            meta={"error_model": model_record, **sim_truth},
        )  # fmt: skip
    claim = epochs["claim"].mean()
    length = epochs.loc[epochs["claim"], "length_m"]
    lengths = (
        f"interval median {length.median():.1f} m, p95 {length.quantile(0.95):.1f} m"
        if len(length)
        else "no interval claimed"
    )
    what = claim_label(cfg.error_model_caveat, cfg.locator.fixed_k_sigma)
    print(f"{len(epochs)} epochs: {what} "
          f"{100 * claim:.1f} %, "
          f"{lengths} -> {folder}")
    print(_losses_text(epochs), end="")
    _say_assumed_claims(epochs)
    _say_track_end(epochs, cfg.odometer.max_speed_mps)
    _say_start_conflict(epochs, float(start), args.start_chainage is not None, cfg.cutoff_deg)
    return 0


def _say_assumed_claims(epochs: Any) -> None:
    """How many claims used a satellite trusted on an ASSUMED bin (flag ``ASSUMED_MASK``)."""
    from locator.run import RunFlag

    if "flags" not in epochs or not epochs["claim"].any():
        return
    claimed = epochs.loc[epochs["claim"], "flags"].to_numpy().astype(int)
    on = int(((claimed & int(RunFlag.ASSUMED_MASK)) != 0).sum())
    if on:
        print(f"claims on an assumption: {on} of {len(claimed)} "
              f"({100.0 * on / len(claimed):.1f} %) used a satellite trusted on an ASSUMED bin "
              "(no view saw the sky there: the far field's stated default; flag ASSUMED_MASK, "
              "column n_used_assumed)")  # fmt: skip


def _say_start_conflict(epochs: Any, start_m: float, given: bool, cutoff_deg: float) -> None:
    """Warn when the satellites contradicted the start (flag ``START_CONFLICT``,
    ``RunConfig.start_check_m``): a trial's start 300 m off chose satellites by the masks of a
    place the train was not at, for the whole run, without a word."""
    import numpy as np

    from locator.run import RunFlag

    if "flags" not in epochs or "start_check_m" not in epochs or len(epochs) == 0:
        return
    hit = (epochs["flags"].to_numpy().astype(int) & int(RunFlag.START_CONFLICT)) != 0
    if not hit.any():
        return
    k = int(np.flatnonzero(hit)[0])
    seen = epochs["start_check_m"].to_numpy(float)[: k + 1]
    seen = seen[np.isfinite(seen)]
    claims = np.flatnonzero(epochs["claim"].to_numpy(bool) & hit)
    after = (f"until fixes agreed with it (a claim located the run at epoch {int(claims[0])})"
             if len(claims) else "to the end: no claim located the run")  # fmt: skip
    lo, hi = (float(epochs[c].iloc[k]) if c in epochs else float("nan")
              for c in ("lo_m", "hi_m"))  # fmt: skip
    if len(seen) and not lo <= float(seen[-1]) <= hi:
        by = (f"a fix of every satellite above {cutoff_deg:g} deg put the train at "
              f"{float(seen[-1]):.0f} m")  # fmt: skip
    elif np.isfinite(lo) and np.isfinite(hi):
        # the trusted satellites' claimed interval missed the start's (RunConfig.start_check_m)
        by = f"the trusted satellites' fix put the train at {lo:.0f}-{hi:.0f} m"
    else:
        by = "the satellites' fixes put the train elsewhere"
    what = "--start-chainage" if given else "the start taken from the data's own position"
    print(f"locator run: warning: the start chainage {start_m:.0f} m (or the odometry since) "
          f"contradicts the satellites: {by} (epoch {k}, gps_s "
          f"{float(epochs['gps_s'].iloc[k]):.0f}), beyond the predicted interval; it was "
          "widened over both places (with masks, the satellites were trusted for both: the "
          f"worst case, or each stretch's own) and {int(hit.sum())} epochs are "
          f"flagged START_CONFLICT, without a claim {after}; check {what}",
          file=sys.stderr)  # fmt: skip


def _say_track_end(epochs: Any, max_speed_mps: float) -> None:
    """Why many epochs are flagged ``TRACK_END``: without odometry the predicted interval
    grows by the largest speed times the time between epochs, and reaches past a short map's
    ends (a user trial on 30 s RINEX with a 2 km virtual track: 18 of 19 epochs, no claim
    voided; the flag looked like a defect)."""
    import numpy as np

    from locator.run import RunFlag

    if "flags" not in epochs or len(epochs) == 0:
        return
    flags = epochs["flags"].to_numpy().astype(int)
    at_end = int(((flags & int(RunFlag.TRACK_END)) != 0).sum())
    if at_end < 0.25 * len(flags):
        return
    voided = int(((flags & int(RunFlag.CLAIM_AT_TRACK_END)) != 0).sum())
    gap_s = float(np.median(np.diff(epochs["gps_s"].to_numpy()))) if len(flags) > 1 else 0.0
    print(f"note: the predicted interval reached past an end of the track map in {at_end} of "
          f"{len(flags)} epochs (flag TRACK_END; {voided} claims voided, CLAIM_AT_TRACK_END): "
          f"between fixes it grows by {max_speed_mps:g} m/s times the time between epochs "
          f"({gap_s:g} s here: {max_speed_mps * gap_s:.0f} m); give a map that reaches well "
          "past the run, or data at a higher rate")  # fmt: skip


def _antenna_reference_point(marker_ecef_m: Any, delta_hen_m: Any, path: Any) -> Any:
    """The antenna's reference point: the marker (the header's or ``--station`` position, as
    RINEX gives it) plus the header's ANTENNA: DELTA H/E/N. A user trial: a 1.5 m DELTA H was
    ignored and the model calibrated at the marker, without a word."""
    import numpy as np

    d = np.asarray(delta_hen_m, float)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.any(d):
        return marker_ecef_m
    from predisat.geodesy import ecef_to_geodetic, enu_rotation

    lat, lon, _ = ecef_to_geodetic(np.asarray(marker_ecef_m, float))
    rot = enu_rotation(lat, lon)  # ECEF -> ENU rows
    up, east, north = d
    print(f"locator calibrate: {path}: the antenna stands {up:g} m up, {east:g} m east and "
          f"{north:g} m north of the marker (ANTENNA: DELTA H/E/N): residuals taken there",
          file=sys.stderr)  # fmt: skip
    return np.asarray(marker_ecef_m, float) + np.array([east, north, up]) @ rot


def _refuse_moved_station(obs: Any, path: Any) -> None:
    """Calibration takes every epoch at one station position (the header's or ``--station``,
    plus ANTENNA: DELTA H/E/N): a file whose event records say the antenna moved - flag 2
    "start moving antenna", flag 3 "new site occupation", or a later MARKER NAME, APPROX
    POSITION XYZ or ANTENNA: DELTA H/E/N other than the header's (RINEX 3.04 table A3, 6.6) -
    is refused, naming the line (until 2026-12-07 the residuals of the epochs after it were
    taken at the first position, without a word)."""
    import numpy as np

    head = obs.header
    first = int(obs.epoch_line[0]) if len(obs.epoch_line) else 0
    for e in obs.events:
        why = {2: "flag 2, start moving antenna", 3: "flag 3, new site occupation"}.get(e.flag)
        if e.flag == 3 and e.line < first:
            # a new site occupied before any epoch: every epoch is at that site, which its
            # records (compared below) must not move from the header's (a review: a file
            # opening with flag 3 and the header's own MARKER NAME was refused, told to split
            # it at a line before its first epoch)
            why = None
        for r in e.records:
            label, text = r[60:].strip(), r[:60]
            try:
                if label == "MARKER NAME" and text.strip() != head.marker_name:
                    why = why or f"MARKER NAME {text.strip()!r}"
                elif label in ("APPROX POSITION XYZ", "ANTENNA: DELTA H/E/N"):
                    v = np.array([float(text[k : k + 14] or 0) for k in (0, 14, 28)])
                    was = (head.approx_position_ecef_m if label.startswith("APPROX")
                           else head.antenna_delta_hen_m)  # fmt: skip
                    if not np.allclose(v, was, rtol=0, atol=1e-4):
                        why = why or f"{label} {' '.join(text.split())}"
            except ValueError:
                why = why or f"an unreadable {label} record"
        if why:
            raise CliError(
                f"{path}, line {e.line}: the antenna moved ({why}), but calibration takes every "
                "epoch at one station position; split the file at that line (by time, e.g. "
                "with gfzrnx or teqc) and calibrate each part with its own --station"
            )


def _refuse_phone_as_geodetic(header: Any, declared: str, path: Any) -> None:
    """A file a phone wrote (its receiver or program name) is not a geodetic receiver's: a
    phone declared geodetic got a geodetic model's claims (a user trial, `--device-gnss`; the
    same through RINEX, another)."""
    from locator.errorfit import guess_receiver_class

    if declared == "geodetic" and guess_receiver_class(
        header.receiver_type, header.program
    ) == "phone":
        raise CliError(
            f"{path}: written by a phone ({header.receiver_type or '?'} / {header.program or '?'}"
            "): --receiver-class geodetic would take a geodetic receiver's error model for it; "
            "leave --receiver-class out (phone) or give phone, with a model calibrated on phones"
        )


def _refuse_unproven_as_geodetic(header: Any, declared: str, path: Any) -> None:
    """A geodetic-class model applies to any receiver declared geodetic by its class alone: a
    file whose receiver type is blank, ``Unknown`` or a mass-market chip's took a reference
    station's model (a user trial: 100 % claims under a one-station class model)."""
    from locator.errorfit import not_geodetic_evidence

    why = not_geodetic_evidence(header.receiver_type) if declared == "geodetic" else ""
    if why:
        raise CliError(
            f"{path}: {why}: --receiver-class geodetic would take a reference station's error "
            "model for it; calibrate a model on this receiver and antenna (leave "
            "--receiver-class out; the header's REC # / TYPE must name the receiver)"
        )


def _refuse_other_as_phone(header: Any, declared: str, path: Any) -> None:
    """A phone-class model applies to any phone log by its class alone (no receiver or antenna
    to match): made of a receiver not recognised as a phone, its sigma is not a phone's (a
    user trial: two geodetic stations declared phone, the model claimed on a phone's log and
    gave a hazardous epoch, 1.0 m outside a 1e-12 interval)."""
    from locator.errorfit import guess_receiver_class

    if declared == "phone" and guess_receiver_class(
        header.receiver_type, header.program
    ) != "phone":
        raise CliError(
            f"{path}: receiver {header.receiver_type or '?'!r} (program "
            f"{header.program or '?'!r}) is not recognised as a phone: --receiver-class phone "
            "would apply its error model to every phone log; calibrate a phone-class model on "
            "phone logs (--device-gnss with --truth, or RINEX a phone wrote), or leave "
            "--receiver-class out (a model for this receiver and antenna only)"
        )


def _refuse_station_as_automotive(header: Any, declared: str, path: Any) -> None:
    """An automotive-class model applies to every automotive receiver by its class alone: made
    of a reference station's residuals (a fixed antenna in the open, often a choke ring), its
    sigma is tighter than a car or train unit's (a review: `calibrate --receiver-class
    automotive` on a geodetic station was accepted)."""
    from locator.errorfit import station_evidence

    why = station_evidence(header.receiver_type) if declared else ""
    if declared == "automotive" and why:
        raise CliError(
            f"{path}: a reference station's observations ({why}): --receiver-class automotive "
            "would apply their error model to every automotive receiver, whose errors are "
            "larger; calibrate an automotive-class model on automotive receivers' data, or give "
            "--receiver-class geodetic, or leave --receiver-class out (a model for this receiver "
            "and antenna only)"
        )


def _profile(source: Any, args: argparse.Namespace) -> Any:
    """The receiver profile of a run's source (a simulation: the simulated receiver)."""
    from locator.errorfit import receiver_profile
    from locator.sources import SimSource

    if isinstance(source, SimSource):
        return sim_profile(source.sim, source.constellation)
    from locator.devicegnss import DeviceGnssSource, device_profile

    if isinstance(source, DeviceGnssSource):  # a smartphone's log: class phone unless told
        declared = args.receiver_class or "phone"
        if declared == "geodetic":
            # a user trial: a phone declared geodetic got "safety claim 100 %" from a model of
            # two geodetic stations, which gave 2 HMI on phones (docs/errormodel.md)
            raise CliError(
                f"{args.device_gnss} is an Android GNSS log, which no geodetic receiver writes: "
                "--receiver-class geodetic would apply a geodetic receiver's error model to a "
                "phone or car unit; leave --receiver-class out (phone) or give automotive for "
                "an Android Automotive unit, with a model calibrated on that class"
            )
        if declared != "phone":
            print(f"locator run: warning: {args.device_gnss} taken as a {declared} receiver "
                  "(--receiver-class), not a phone", file=sys.stderr)  # fmt: skip
        return device_profile(source, receiver_class=declared)
    obs = getattr(source, "obs", None)
    if obs is not None:
        _refuse_phone_as_geodetic(obs.header, args.receiver_class or "", args.obs)
        _refuse_unproven_as_geodetic(obs.header, args.receiver_class or "", args.obs)
    return receiver_profile(source, args.receiver_class)


# What a user can do about satellites left out for a reason (locator.selection.Exclusion names,
# predisat.gnss.ephemeris.Reason names, "fde").
_EXCLUSION_HINTS = {
    "outside_coverage": "the masks do not cover where the train is",
    "NO_DATA": "no navigation record: give --nav files holding every satellite of the day",
    "OUTSIDE_VALIDITY": "navigation records too far in time: give the files covering the "
                        "observations (at the start of a day, the day before's too)",
}


def _losses_text(epochs: Any) -> str:
    """Why epochs have no claim and which satellites were left out (lines, or "")."""
    from locator.evaluate import claim_losses, exclusions

    lines = ""
    losses = claim_losses(epochs)
    if losses:
        parts = ", ".join(f"{cause} {100 * share:.1f} %" for cause, share in losses.items())
        lines += f"no claim: {parts}\n"
    left = {k: v for k, v in exclusions(epochs).items() if k != "below the horizon"}
    if left:
        parts = ", ".join(
            f"{why} {len(sats)}" + (f" ({hint})" if (hint := _EXCLUSION_HINTS.get(why)) else "")
            for why, sats in sorted(left.items(), key=lambda kv: -len(kv[1]))
        )
        lines += f"satellites left out at least once: {parts}\n"
    return lines


DEFAULT_ANTENNA_HEIGHT_M = 4.0
"""The train antenna's height above the rail when neither ``--antenna-height`` nor a
simulation states it, metres."""


def _antenna_height(args: argparse.Namespace, sim_meta: Any = None) -> float:
    """``--antenna-height``, else the simulation's (``meta.json``), else the default."""
    if args.antenna_height is not None:
        return float(args.antenna_height)
    if sim_meta is not None and sim_meta.get("antenna_height_m") is not None:
        return float(sim_meta["antenna_height_m"])
    return DEFAULT_ANTENNA_HEIGHT_M


def _unstated_antenna_note(masks: Any, path: Any, label: Any) -> str | None:
    """What the masks were checked against when the train's antenna height was not given."""
    from predisat.masks.antenna import ANTENNA_TOLERANCE_M, masks_antenna_height_m

    h = masks_antenna_height_m(masks)
    if h is None:  # check_antenna_height's own note says it
        return None
    return (f"the train antenna's height was not given (--antenna-height): taken as "
            f"{path.antenna_height_m:g} m, so masks {label} made for an antenna {h:g} m above "
            "the track axis were checked against that "
            f"default, not the train's; masks made for an antenna more than "
            f"{ANTENNA_TOLERANCE_M:g} m above the train's trust near obstacles too low (a "
            "trial: 1.0 m lower trusted 0.027 % of the directions falsely, 1.5 m lower "
            "0.27 %): give --antenna-height")  # fmt: skip


# A start this far beyond the surveyed positions has no mask to trust any satellite with.
_MASK_REACH_M = 50.0


def _check_start(
    start_m: float,
    path: Any,
    masks: Any,
    args: argparse.Namespace,
    header_ecef_m: Any,
    sim_chainage_m: Any,
) -> None:
    """The start chainage must be on the track; a simulated train must enter the masks (a
    start outside them is told). ``header_ecef_m``: the RINEX header position, or None."""
    if not 0.0 <= start_m <= path.length_m:
        raise CliError(
            f"start chainage {start_m:.0f} m is off track {path.track.name!r} "
            f"(0-{path.length_m:.0f} m); give --start-chainage in metres along this track"
        )
    if args.start_chainage is not None and sim_chainage_m is not None:
        lo_m, hi_m = float(sim_chainage_m.min()), float(sim_chainage_m.max())
        hint = chainage_hint(start_m, lo_m - _MASK_REACH_M, hi_m + _MASK_REACH_M,
                             "--start-chainage")  # fmt: skip
        if hint:
            raise CliError(f"--start-chainage {start_m:g} m: the simulated train runs "
                           f"{lo_m:.0f}-{hi_m:.0f} m{hint}")  # fmt: skip
    if masks is not None:
        lo_m, hi_m = float(masks.chainage_m.min()), float(masks.chainage_m.max())
        lo, hi = lo_m - _MASK_REACH_M, hi_m + _MASK_REACH_M
        where = f"the masks of {args.masks} ({lo_m:.0f}-{hi_m:.0f} m)"
        if sim_chainage_m is not None and not (
            (sim_chainage_m >= lo) & (sim_chainage_m <= hi)
        ).any():
            raise CliError(
                f"the simulated train ({sim_chainage_m.min():.0f}-{sim_chainage_m.max():.0f} m) "
                f"never enters {where}: no satellite could be trusted; give the masks of "
                "this stretch"
            )
        if not lo <= start_m <= hi:
            print(
                f"locator run: warning: start chainage {start_m:.0f} m is outside {where}: "
                "no satellite is trusted until the train is inside them"
                + chainage_hint(start_m, lo_m, hi_m, "--start-chainage"),
                file=sys.stderr,
            )
    if args.start_chainage is not None and header_ecef_m is not None:
        # The given start overrides the header, but a header far from the line usually means
        # the wrong observation file or track: say so rather than run silently.
        from locator.workflow import check_track

        try:
            check_track(path, header_ecef_m, f"{args.obs} (its header's approximate position)",
                         _MAX_HEADER_OFFSET_M)  # fmt: skip
        except ValueError as exc:
            print(f"locator run: warning: {exc}; running from --start-chainage as asked",
                  file=sys.stderr)  # fmt: skip


def _sample_fixes(model: Any, obs: Any, n: int = 30) -> Any:
    """Single point positions (ECEF m, shape (k, 3)) at up to ``n`` epochs spread over ``obs``,
    those that solved."""
    import numpy as np

    from locator.spp import solve_observations

    idx = np.unique(np.linspace(0, len(obs.gps_s) - 1, min(n, len(obs.gps_s))).astype(int))
    table, _ = solve_observations(model, obs, epochs=idx)
    if "x_m" not in table:
        return np.zeros((0, 3))
    ok = table["status"].eq("ok").to_numpy()
    return table.loc[ok, ["x_m", "y_m", "z_m"]].to_numpy(float)


# The header's approximate position is a rough fix (tens of metres), so the bound is looser
# than the 5 m of simulated antennas; a receiver on another line is kilometres away.
_MAX_HEADER_OFFSET_M = 200.0


# Broadcast records are used up to 2 h from their reference epoch (ValidityPolicy).
_NAV_REACH_S = 7200.0


def _broadcast_nav(paths: Sequence[str]) -> Sequence[str]:
    """``paths``, refused when one is an SP3 orbit file or TLEs: the pseudoranges need the
    broadcast clocks, group delays and ionosphere (a user trial read a RINEX header error)."""
    import gzip
    import itertools

    for path in paths:
        try:
            opener = gzip.open if str(path).endswith(".gz") else open
            with opener(path, "rt", errors="replace") as fh:
                lines = [fh.readline() for _ in range(40)]
        except (OSError, EOFError):
            continue  # the reader says what is wrong with it
        body = [s for s in lines if s.strip() and not s.startswith("#")]
        tle = any(a.startswith("1 ") and b.startswith("2 ") for a, b in itertools.pairwise(body))
        kind = ("an SP3 orbit file" if lines[0][:2] in ("#a", "#b", "#c", "#d")
                else "two-line elements (TLE)" if tle else "")  # fmt: skip
        if kind:
            raise CliError(
                f"{path}: {kind}: `run` and `calibrate` correct the pseudoranges with the "
                "broadcast clocks, group delays and ionosphere, which only broadcast RINEX "
                "navigation carries; give the day's RINEX navigation files (*N.rnx, *.yyn)"
            )
    return paths


def _one_clock(source: Any, obs_path: str) -> None:
    """Refuse a RINEX run over several systems: the pairs difference one receiver clock away,
    and each system keeps its own (a user trial: GPS + Galileo at NYA1, 2.6 m apart, gave a
    hazardous misleading interval that neither system alone gave)."""
    if len(source.systems) > 1:
        raise CliError(
            f"{obs_path}: --constellation uses {len(source.systems)} systems "
            f"({', '.join(source.systems)}); the locator differences pseudoranges in pairs, "
            "which cancels one receiver clock, and each system has its own (an inter-system "
            "bias of metres the locator does not estimate); run one system (--constellation "
            "gps, or galileo). A phone's device_gnss log has the bias removed (IsrbMeters) and "
            "may mix them"
        )


def _nav_covers(ephemeris: Any, obs: Any, nav: Sequence[str]) -> None:
    """Observations outside the navigation data's span cannot be positioned at all."""
    from predisat.availability.run import nav_span_gps_s
    from predisat.gnss.timescale import gps_s_to_text as day

    lo, hi = nav_span_gps_s(ephemeris)
    t0, t1 = float(obs.gps_s.min()), float(obs.gps_s.max())
    if t1 < lo - _NAV_REACH_S or t0 > hi + _NAV_REACH_S:
        raise CliError(
            f"{obs.path}: its epochs ({day(t0)} - {day(t1)} GPS) lie outside the navigation "
            f"data of {', '.join(map(str, nav))} ({day(lo)} - {day(hi)}); give the broadcast "
            "navigation files of the observation day"
        )


def _keep_calibrated_codes(source: Any, args: argparse.Namespace) -> Any:
    """The source with only the codes its error model was calibrated on, where a system's
    data also hold others: a few epochs of another code (a C1C+C2L epoch in a C2W run)
    would otherwise take the safety claim from the whole run (a user trial, stop 56). A
    system none of whose codes was calibrated is left as it is (no claim, said by
    :func:`locator.modelcheck.model_use`)."""
    from dataclasses import replace

    import numpy as np

    from locator.errorfit import receiver_profile
    from predisat.gnss.errormodel import default_model_file, read_error_model_file

    mf = read_error_model_file(args.error_model) if args.error_model else default_model_file()
    profile = receiver_profile(source, args.receiver_class)
    kept = {}
    for sys_, codes in sorted(profile.codes.items()):
        m = mf.systems.get(sys_)
        if m is None or set(codes) <= set(m.codes) or not set(codes) & set(m.codes):
            continue
        kept[sys_] = tuple(m.codes)
    if not kept:
        return source
    out = replace(source, codes_kept=kept)
    table = source.code_table
    for sys_, by_code in sorted(out.left_out_codes().items()):
        n_sys = sum(int(np.count_nonzero(table[:, j] != "")) for j, sat in
                    enumerate(source.obs.sats) if sat[0] == sys_)  # fmt: skip
        n = sum(by_code.values())
        print(f"locator run: warning: {args.obs}: left out {n} of {n_sys} ranges of system "
              f"{sys_} ({100.0 * n / max(n_sys, 1):.2g} %), of code(s) "
              f"{', '.join(f'{c} ({k})' for c, k in sorted(by_code.items()))}, which "
              f"{args.error_model or 'the built-in error model'} was not calibrated on "
              f"(it holds {', '.join(kept[sys_])}): the other ranges keep their safety claim; "
              "calibrate on data with these codes to use them (recorded in run.json: "
              "source.codes_left_out)", file=sys.stderr)  # fmt: skip
    return out


def _warn_no_iono(source: Any, nav: Sequence[str], command: str = "run") -> None:
    """Told once: systems without any broadcast ionosphere model (their epochs are flagged)."""
    from locator.corrections import UNCORRECTED_IONO_SIGMA_M

    missing = source.iono_missing
    stale = getattr(source, "iono_stale", {})
    if command == "calibrate":
        # a user trial (2026-12-07): a Galileo-only --nav fitted the ionospheric delay into the
        # model (NYA1 E C1X: b 0.41 -> 1.16 m) without a word, and the file still read
        # "single: one code with the broadcast ionosphere"
        if missing:  # a stale set counts as none (BroadcastIono.stale)
            print(
                f"locator calibrate: warning: no broadcast ionosphere model for "
                f"{', '.join(missing)} in {', '.join(map(str, nav))}"
                " (no Klobuchar coefficients of the observation days; Galileo NeQuick-G is not "
                "applied): the ionospheric delay stays in these residuals and the model fits it "
                "as pseudorange error (recorded in the file: fitted.iono_uncorrected_systems); "
                "add the same day's GPS or mixed broadcast navigation file to --nav",
                file=sys.stderr,
            )
        return
    if stale:
        print(
            "locator run: warning: ionosphere coefficients of another day left out: "
            + "; ".join(f"{k} {v}" for k, v in sorted(stale.items()))
            + " (more than 2 days from the observations)",
            file=sys.stderr,
        )
    if missing:
        print(
            f"locator run: warning: no broadcast ionosphere model for {', '.join(missing)} in "
            f"{', '.join(map(str, nav))} (no GPS, QZSS or BeiDou Klobuchar coefficients of the "
            "observation days; "
            "Galileo NeQuick-G is not applied): the ionospheric delay stays in the pseudoranges,"
            " every epoch is flagged iono_uncorrected and its sigma inflated by "
            f"{UNCORRECTED_IONO_SIGMA_M:g} m at the zenith (x obliquity); add the same day's GPS"
            " or mixed broadcast navigation file to --nav",
            file=sys.stderr,
        )


def _warn_off_map(path: Any, fixes: Any, label: str,
                  whose: str = "the receiver's own fixes") -> None:
    """:func:`locator.workflow.check_track_offset`'s warning on stderr (its refusal raises)."""
    from locator.workflow import check_track_offset

    note = check_track_offset(path, fixes, label, whose)
    if note is not None:
        print(f"locator run: warning: {note}", file=sys.stderr)


def _report_problems(label: str, problems: Sequence[Any]) -> None:
    """Epochs or records the reader skipped are told, never dropped silently."""
    if problems:
        first = problems[0]
        where = f", line {first.line}" if first.line is not None else ""
        print(
            f"{label}: {len(problems)} record(s) skipped by the reader; first{where}: "
            f"{first.what}",
            file=sys.stderr,
        )


def _report_no_code(label: str, obs: Any, constellation: str) -> None:
    """Epochs left without any pseudorange the locator reads for the run's systems are told,
    with the header record that changed the observation types before them (a trial's file
    dropped C1 at an event flag 4: half the run had no fix, and no reason was given)."""
    import numpy as np

    from locator.observations import DEFAULT_PSEUDORANGE_PRIORITY
    from predisat.availability.satellites import select_satellites

    wanted = np.isin(np.asarray(obs.sats), select_satellites(obs.sats, constellation))
    if not wanted.any() or not len(obs.gps_s):
        return
    have = np.isfinite(obs.pseudorange().pseudorange_m[:, wanted]).any(axis=1)
    if have.all() or not have.any():  # none at all is refused by the source, naming the codes
        return
    first = int(np.flatnonzero(~have)[0])
    line = int(obs.epoch_line[first])
    changes = [e for e in obs.events if e.line < line
               and any("TYPES OF OBS" in r for r in e.records)]  # fmt: skip
    why = (f" after the header record at line {changes[-1].line} (event flag "
           f"{changes[-1].flag}) that changed the observation types"
           if changes else "")  # fmt: skip
    systems = sorted({s[0] for s, w in zip(obs.sats, wanted, strict=True) if w})
    codes = "; ".join(f"{c}: {', '.join(DEFAULT_PSEUDORANGE_PRIORITY.get(c, ()))}"
                      for c in systems)  # fmt: skip
    print(f"{label}: warning: {int((~have).sum())} of {len(have)} epochs (the first at line "
          f"{line}){why} have no pseudorange of the codes the locator reads ({codes}): they get "
          "no fix", file=sys.stderr)  # fmt: skip


# `evaluate --truth-chainage` this far from the run's median estimate, and a thousand times
# nearer, was given in km
_TRUTH_REACH_M = 500.0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from locator.run import fixed_k_of
    from locator.runio import read_run
    from locator.workflow import evaluate_folder, truth_for

    epochs, meta = read_run(args.run)
    length_m = meta.get("track_length_m")
    if args.truth_chainage is not None and length_m is not None:
        if not 0.0 <= args.truth_chainage <= float(length_m):
            raise CliError(
                f"--truth-chainage {args.truth_chainage:g} m is off track {meta.get('track')!r} "
                f"(0-{float(length_m):.0f} m of chainage); give the antenna's chainage in metres"
            )
    if args.truth_chainage is not None and "chainage_m" in epochs:
        # a static antenna given in km: the run's own estimates are a thousand times farther
        est_m = float(epochs["chainage_m"].median())
        hint = chainage_hint(args.truth_chainage, est_m - _TRUTH_REACH_M, est_m + _TRUTH_REACH_M,
                             "--truth-chainage")  # fmt: skip
        if hint:
            raise CliError(f"--truth-chainage {args.truth_chainage:g} m is far from the run's "
                           f"estimates (median {est_m:.0f} m){hint}")  # fmt: skip
    sim = None
    if args.sim:
        from locator.sim.simfile import SimRun

        sim = _sim_on_run_track(SimRun.read(args.sim), args, meta, length_m)
    if args.truth_positions:
        from locator.devicegnss import read_ground_truth
        from locator.workflow import truth_from_positions

        if args.track is None:
            raise CliError("--truth-positions needs the run's track (--track FILE, and "
                           "--track-name when the file holds several) to project them on")
        track = _run_track(args, meta, length_m)
        truth = truth_from_positions(epochs, read_ground_truth(args.truth_positions), track)
    else:
        if sim is None and (args.track is not None or args.track_name is not None or args.where):
            raise CliError("--track (--track-name, --where) is for --truth-positions and --sim "
                           "(the other truths are chainages already)")  # fmt: skip
        truth = truth_for(epochs, sim=sim, truth_csv=args.truth_csv,
                          chainage_m=args.truth_chainage)  # fmt: skip
    s = evaluate_folder(args.run, truth)
    config = meta.get("config") or {}
    print(_summary_text(s, str(config.get("error_model_caveat", "")), fixed_k_of(config)))
    print(f"-> {Path(args.run) / 'evaluation.json'}, scored table and figures")
    return 0


# A track whose ends lie farther than this from the run's is another track, or reversed.
_TRACK_END_TOL_M = 5.0


def _run_track(args: argparse.Namespace, meta: dict[str, Any], length_m: Any) -> Any:
    """``--track`` of `evaluate`, refused unless it is the run's (its length and ends)."""
    track = _track_arg(args)
    if length_m is not None and abs(track.length_m - float(length_m)) > 1.0:
        raise CliError(f"--track {args.track}: {track.length_m:.0f} m long, but the run was "
                       f"made on track {meta.get('track')!r} of {float(length_m):.0f} m; give "
                       "that track")  # fmt: skip
    _check_same_track(track, meta, str(args.track))
    return track


def _sim_on_run_track(
    sim: SimRun, args: argparse.Namespace, meta: dict[str, Any], length_m: Any
) -> SimRun:
    """The simulation with its truth in the chainage of the run's track: its own when the run
    was made on the simulation's world track, else projected on ``--track`` (required)."""
    from locator.workflow import sim_on_track
    from predisat.synth.world import World

    stored = Path(args.sim) / "world.npz"
    if args.track is None and meta.get("sim_chainage") == "projected":
        from predisat.track import demo_track

        try:  # made on the embedded line 144 (run --sim without --track nor world.npz)
            _check_same_track(demo_track(), meta, "(the embedded line 144)")
        except CliError:
            raise CliError(f"{args.run} was made on track {meta.get('track')!r}, another map "
                           "than the simulation's own, so the simulation's chainages are not "
                           "the run's: give the run's map as --track to project the simulated "
                           "antenna on it") from None  # fmt: skip
        try:
            return sim_on_track(sim, demo_track(), str(args.sim))
        except ValueError as exc:
            raise CliError(str(exc)) from None
    if args.track is None:
        if stored.is_file() and meta.get("track_ends_latlon_deg"):
            try:
                _check_same_track(World.load(stored).track, meta, str(stored))
            except CliError:
                raise CliError(f"{args.run} was made on track {meta.get('track')!r}, not on the "
                               f"simulation's world track ({stored}), so the simulation's "
                               "chainages are not the run's: give the run's map as --track to "
                               "project the simulated antenna on it") from None  # fmt: skip
        return sim
    track = _run_track(args, meta, length_m)
    try:
        return sim_on_track(sim, track, str(args.sim))
    except ValueError as exc:
        raise CliError(str(exc)) from None


def _check_same_track(track: Any, meta: dict[str, Any], label: str) -> None:
    """Refuse a track whose ends are not the run's (``run.json``'s ``track_ends_latlon_deg``;
    a run folder written before it records nothing to compare)."""
    import numpy as np

    from predisat.geodesy import WGS84

    ends = meta.get("track_ends_latlon_deg")
    if not ends:
        return
    lat, lon, _ = track.position_at([0.0, track.length_m])
    run_lat, run_lon = np.asarray(ends, float).T
    d = WGS84.inv(lon, lat, run_lon, run_lat)[2]
    if np.max(d) > _TRACK_END_TOL_M:
        flipped = WGS84.inv(lon, lat, run_lon[::-1], run_lat[::-1])[2]
        why = ("runs the other way (chainage 0 at the run's far end)"
               if np.max(flipped) <= _TRACK_END_TOL_M
               else f"has its ends {np.max(d):.0f} m from the run's")  # fmt: skip
        raise CliError(f"--track {label} {why}: give the track `locator run` used "
                       f"({meta.get('track')!r})")  # fmt: skip


def _summary_text(
    s: dict[str, float], caveat: str = "", fixed_k_sigma: float | None = None
) -> str:
    from locator.run import claim_label

    lengths = (
        f"interval median {s['length_median_m']:.1f} m, p95 {s['length_p95_m']:.1f} m, "
        f"max {s['length_max_m']:.1f} m"
        if s["claim_share"] > 0
        else "no interval claimed"
    )
    return (
        f"epochs {s['epochs']:.0f}; modes: three pairs {100 * s['mode_three_pairs_share']:.1f} %, "
        f"all pairs {100 * s['mode_all_pairs_share']:.1f} %, best pair (no claim) "
        f"{100 * s['mode_best_pair_share']:.1f} %, none {100 * s['mode_none_share']:.1f} %\n"
        f"{claim_label(caveat, fixed_k_sigma)} {100 * s['claim_share']:.1f} % of epochs; "
        f"{lengths}\n"
        f"|error| median {s['abs_error_median_m']:.2f} m, p95 {s['abs_error_p95_m']:.2f} m; "
        f"HMI {s['hmi']:.0f} (before heading/odometry checks {s['hmi_fix']:.0f}); "
        f"alarmed misleading {s['mi']:.0f}"
    )


def cmd_calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from locator.errorfit import simulated_residuals, station_residuals
    from locator.workflow import ImplausibleFitError, calibrate_to_file

    if not (args.k_sigma > 0 and np.isfinite(args.k_sigma)):
        raise CliError(
            f"--k-sigma must be positive and finite, got {args.k_sigma} (the source's 2; 3.89 "
            "gives 1e-4 per pair)"
        )
    cls = args.receiver_class or ""
    if args.sim:
        from locator.sim.simfile import SimRun

        states = [s.strip() for s in (args.states or "los").split(",")]
        data = [simulated_residuals(SimRun.read(d), states, str(d)) for d in args.sim]
        fitted: dict[str, Any] = {"simulations": [str(d) for d in args.sim], "states": states}
        cls = cls or "simulated"
    elif args.device_gnss:
        from locator.devicegnss import (
            DeviceGnssSource,
            device_residuals,
            read_device_gnss,
            read_ground_truth,
        )

        if len(args.truth or ()) != len(args.device_gnss):
            raise CliError(
                f"--truth: give one ground-truth file per --device-gnss file, in the same order "
                f"({len(args.device_gnss)} device_gnss, {len(args.truth or ())} truth)"
            )
        data = []
        for dev_path, truth_path in zip(args.device_gnss, args.truth, strict=True):
            dev = read_device_gnss(dev_path)
            _report_problems(dev_path, dev.problems)
            try:
                data.append(device_residuals(
                    DeviceGnssSource(dev, args.constellation), read_ground_truth(truth_path),
                    min_el_deg=args.min_el, receiver_class="phone",
                ))  # fmt: skip
            except ValueError as exc:
                raise CliError(str(exc)) from None
        fitted = {"device_gnss": [str(f) for f in args.device_gnss],
                  "truth": [str(f) for f in args.truth]}  # fmt: skip
    else:
        seen = [Path(f).resolve() for f in args.obs]
        if len(set(seen)) < len(seen):
            raise CliError(
                "an --obs file is given twice; each file counts once (its residuals would weigh "
                "double in the tail check)"
            )
        from locator.corrections import RangeModel
        from locator.observations import Observations
        from locator.sources import RinexSource
        from locator.timetag import check_time_tags

        ranges = RangeModel.from_rinex_nav(_broadcast_nav(args.nav))
        data, stations = [], []
        no_iono: set[str] = set()
        seen_epochs: list[tuple[Any, Any]] = []
        for path in args.obs:
            obs = Observations.from_rinex(path)
            _refuse_phone_as_geodetic(obs.header, cls, path)
            _refuse_unproven_as_geodetic(obs.header, cls, path)
            _refuse_other_as_phone(obs.header, cls, path)
            _refuse_station_as_automotive(obs.header, cls, path)
            _refuse_moved_station(obs, path)
            head = obs.header.approx_position_ecef_m
            if args.station:
                x = _station_ecef_m(args.station, head, path)
            else:
                x = head
            if not np.all(np.isfinite(x)) or np.linalg.norm(x) < 6e6:
                fix = (
                    "pass --station X Y Z"
                    if len(args.obs) == 1
                    else "calibrate it alone with --station X Y Z, or leave it out"
                )
                raise CliError(f"{path}: no station position in the header; {fix}")
            x = _antenna_reference_point(x, obs.header.antenna_delta_hen_m, path)
            _report_problems(path, obs.problems)
            _nav_covers(ranges.ephemeris, obs, args.nav)
            day = ranges.with_iono_near(float(np.median(obs.gps_s)))  # the observations' day
            try:  # tags off their ranges would widen the model with errors of the file
                check_time_tags(day, obs, str(path), constellation=args.constellation)
            except ValueError as exc:
                raise CliError(str(exc)) from None
            # the same station's epochs twice (a copy, decompressed) is evidence counted twice:
            # a user trial's doubled the independent samples and deepened the tail check
            for prev, (x0, t0) in zip(args.obs, seen_epochs, strict=False):
                common = np.intersect1d(t0, obs.gps_s).size
                if np.linalg.norm(np.asarray(x0) - x) < 1.0 and common:
                    raise CliError(
                        f"{path} and {prev} hold {common} epochs of the same station: its "
                        "residuals would count twice in the tail check; give each "
                        "observation once"
                    )
            seen_epochs.append((x, np.asarray(obs.gps_s, float)))
            src = RinexSource(day, obs, args.constellation,
                              dual_frequency=args.dual_frequency)  # fmt: skip
            _warn_no_iono(src, args.nav, command="calibrate")
            no_iono.update(src.iono_missing)
            data.append(station_residuals(src, x, min_el_deg=args.min_el))
            stations.append(x.tolist())
        fitted = {"obs": [str(f) for f in args.obs], "nav": [str(f) for f in args.nav],
                  "station_ecef_m": stations,
                  "iono_uncorrected_systems": sorted(no_iono)}  # fmt: skip
    try:
        mf = calibrate_to_file(
            data, args.out, k_sigma=args.k_sigma, bound=args.bound, fitted=fitted,
            receiver_class=cls, pool_systems=bool(args.sim),
        )  # fmt: skip
    except ImplausibleFitError as exc:
        raise CliError(f"{exc}; check --station or the input's reference position") from None
    except ValueError as exc:
        raise CliError(
            f"{exc} (command line: give more or longer --obs / --sim / --device-gnss inputs, a few "
            "hundred "
            "residuals at least, or --bound estimate for the fit alone)"
        ) from None
    _check_calibration(mf, data, args.constellation)
    pairs = {(d.profile.receiver_type.upper().strip(), d.profile.antenna_type.upper().strip())
             for d in data}  # fmt: skip
    if args.obs and cls and len(pairs) < 2:
        print(f"locator calibrate: warning: --receiver-class {cls} from one receiver and antenna "
              f"({' / '.join(n or '?' for n in next(iter(pairs)))}): the model will apply to every "
              f"receiver declared {cls} by its class alone, and a class model bounds only "
              "receivers like those it saw; validate it leaving one receiver out on several of "
              "the class (docs/errormodel.md), or leave --receiver-class out",
              file=sys.stderr)  # fmt: skip
    what = "overbound" if args.bound == "overbound" else "least-squares estimate"
    app = mf.applicability
    assert app is not None
    named = [", ".join(n for n in names if n) or "not named" for names in
             (app.receivers, app.antennas)]  # a device log names neither (a user trial)
    print(f"{what} for receiver {named[0]} / antenna {named[1]}"
          + (f" (class {app.receiver_class})" if app.receiver_class else "")
          + f", elevations {app.el_min_deg:.1f}-{app.el_max_deg:.1f} deg:")  # fmt: skip
    for sys_, m in mf.systems.items():
        e = m.error
        tail = (
            f"tails checked to {m.tail_probability:.2g} (k {m.k_checked:.2f})"
            if m.tail_probability < 1
            else "too few samples to check any tail: `locator run` makes no claim under it; "
            "calibrate on more hours, days or receivers (about 200 independent samples per "
            "system, and at least about 650 residuals: 10 beyond a tail point in each of 6 "
            "elevation bins)"
        ) if np.isfinite(m.tail_probability) else "no bound (estimate)"  # fmt: skip
        print(f"  {sys_} {', '.join(m.codes)}: sigma(el)^2 = {e.a_m:.3f}^2 + ({e.b_m:.3f} / "
              f"sin el)^2 m^2 from {m.n_residuals} residuals ("
              + (f"{m.n_independent} independent" if np.isfinite(m.tail_probability)
                 else "independence not assessed")  # an estimate counts its residuals
              + f"); {tail}")  # fmt: skip
    print(f"k_sigma {mf.model.k_sigma} -> {args.out} (figure "
          f"{Path(args.out).with_suffix('.png')})")  # fmt: skip
    return 0


# A station given this far from the header's approximate position is likely a typo.
_STATION_HEADER_M = 100.0


def _station_ecef_m(station: Any, header_ecef_m: Any, path: str) -> Any:
    """``--station X Y Z`` checked: ECEF metres, near the header's position when it has one."""
    import numpy as np

    x = np.asarray(station, float)
    r = float(np.linalg.norm(x))
    if not 6.2e6 < r < 6.5e6:
        hint = ("; did you give kilometres? (multiply by 1000)" if 6.2e3 < r < 6.5e3
                else "")  # fmt: skip
        raise CliError(f"--station {' '.join(f'{v:g}' for v in x)}: {r / 1000:.1f} km from the "
                       "Earth's centre, not a position on it; give the antenna's ECEF X Y Z in "
                       f"metres{hint}")  # fmt: skip
    h = np.asarray(header_ecef_m, float)
    if np.all(np.isfinite(h)) and np.linalg.norm(h) > 6e6:
        d = float(np.linalg.norm(x - h))
        if d > _STATION_HEADER_M:
            print(f"locator calibrate: warning: --station is {d:.0f} m from the approximate "
                  f"position in {path}'s header; residuals at a wrong station are no error "
                  "model (check the coordinates)", file=sys.stderr)  # fmt: skip
    return x


def _check_calibration(mf: Any, data: Any, constellation: str = "all") -> None:
    """Say which systems of ``constellation`` the data held and the model left out (the
    systems ``--constellation`` did not choose are not "left out": a user trial)."""
    from predisat.availability.satellites import SYSTEM_NAMES, select_satellites

    seen = sorted({s[0] for d in data for s in select_satellites(list(d.sats), constellation)})
    left = [c for c in seen if c not in mf.systems]
    if left:
        print("locator calibrate: left out (too few residuals in epochs with 3 satellites of "
              f"it): {', '.join(SYSTEM_NAMES.get(c, c) for c in left)}; the model covers "
              f"{', '.join(SYSTEM_NAMES.get(c, c) for c in mf.systems)} only", file=sys.stderr)


def cmd_demo(args: argparse.Namespace) -> int:
    from locator.workflow import demo

    t0 = time.perf_counter()
    world = pipeline = None
    if args.from_predisat_demo:
        from predisat.masks.fileformat import read_masks
        from predisat.synth.world import World
        from predisat.track.map import demo_track

        d = Path(args.from_predisat_demo)
        world = World.load(d / "truth" / "world.npz", demo_track())
        pipeline = read_masks(d / "masks" / "masks.parquet")
    from predisat.gnss.integrity import IntegrityBudget

    budget = IntegrityBudget(args.integrity_risk)
    table = demo(args.out, world=world, pipeline_masks=pipeline, seed=args.seed, integrity=budget)
    # the runs' own constellation (run.json), and no availability report before it here
    systems = sorted({str(c).upper() for c in table.get("constellation", [])}) or ["GPS"]
    from locator.demostep import format_demo_table

    print(format_demo_table(table, "+".join(systems), report_above=False))
    print(f"locator demo: done in {time.perf_counter() - t0:.0f} s -> {args.out}")
    return 0


# What the input files hold, for the messages when one is missing.
_MASKS = ("a mask file (masks.parquet of `predisat process`, or a simulation's "
          "true_masks.parquet) or a `predisat process` output folder")
_SIM = "a `locator simulate` output folder (epochs, meta.json, world.npz)"
_ERROR_MODEL = "a pseudorange error model JSON written by `locator calibrate`"
_NAV = "RINEX navigation, SP3 or TLE files"
# run and calibrate correct the pseudoranges with the broadcast clocks, group delays and
# ionosphere: SP3 orbits or TLEs do not carry them (a user trial was told they would do)
_BROADCAST_NAV = "broadcast RINEX navigation files (not SP3 or TLE: the corrections need them)"
_TRACK = "a track map: GeoJSON line(s) or a lat,lon[,h] CSV (docs/track-map.md)"


def _run_arguments(p: argparse.ArgumentParser) -> None:
    from locator.workflow import MAX_HEIGHT_DISAGREEMENT_M  # the locator: seconds

    rule = p.add_mutually_exclusive_group(required=True)
    rule.add_argument("--masks", type=existing_path(_MASKS), metavar="MASKS",
                      help="trust rule: the satellites the masks say are in view")
    rule.add_argument("--cutoff", type=cutoff_deg, metavar="DEG",
                      help="trust rule: a flat elevation cut-off, degrees")
    rule.add_argument("--no-masks", action="store_true",
                      help="trust rule: every received signal")
    add_masks_same_track(p)
    p.add_argument("--integrity", choices=("active", "passive"), default="active",
                   help="active: fault detection and exclusion; passive: every measurement kept, "
                   "faults only flagged")
    p.add_argument("--error-model", type=existing_file(_ERROR_MODEL), metavar="JSON",
                   help="pseudorange error model from `locator calibrate` (default: a = b = 2 m, "
                   "the source's: it applies to simulated receivers only, so RINEX runs without a "
                   "calibrated model make no safety claim; the file's k_sigma is not used: see "
                   "--integrity-risk)")
    p.add_argument("--force-error-model", action="store_true",
                   help="intervals under --error-model even when it does not apply to the data "
                   "(another receiver, antenna, code, or a locator-error-model/1 file): not a "
                   "safety claim; every epoch is flagged FORCED_ERROR_MODEL")
    p.add_argument("--assume-gaussian-tail", action="store_true",
                   help="claim even where the integrity risk asks for pair intervals wider than "
                   "the model's tails were checked to (the Gaussian shape assumed beyond that "
                   "depth; every epoch flagged GAUSSIAN_TAIL, run.json records it; default: no "
                   "safety claim there)")
    p.add_argument("--receiver-class", choices=("geodetic", "automotive", "phone"),
                   help="the data's receiver class, for a model calibrated for a class "
                   "(default: guessed, phone for smartphone logs, otherwise none)")
    integrity_options(p)
    add_map_doubt(p)
    p.add_argument("--extra-margin", type=non_negative_float, metavar="DEG",
                   help="with --masks: degrees added to the mask file's margins before trusting "
                   "a satellite (default 0)")
    p.add_argument("--trust-stretches", type=positive_int, metavar="N",
                   help="with --masks: at most N stretches of the predicted interval, each with "
                   "its own trusted satellites and fix, one claim from all (default 16, "
                   "locator.partition.MAX_STRETCHES; 1: one set, the worst mask over the whole "
                   "interval; docs/locator.md, partitioned trust)")
    p.add_argument("--start-chainage", type=finite_float, metavar="M",
                   help="chainage of the first epoch, metres (default: the simulation's, or the "
                   "RINEX header position's)")
    p.add_argument("--start-uncertainty", type=non_negative_float, default=50.0, metavar="M",
                   help="half width of the first predicted interval around the start, metres")
    p.add_argument("--antenna-height", type=antenna_height_m, default=None, metavar="M",
                   help="antenna above the rail, metres (default: the simulation's, else "
                   f"{DEFAULT_ANTENNA_HEIGHT_M:g}, which masks made for a higher antenna are "
                   "checked against: give the train's; a static station on a virtual track "
                   "laid at its own height: 0)")
    p.add_argument("--max-height-offset", type=positive_float, metavar="M",
                   default=MAX_HEIGHT_DISAGREEMENT_M,
                   help="largest median height of the receiver's own fixes above or below its "
                   "antenna on the track before the run is refused as a map without ellipsoidal "
                   "heights; raise it only for a receiver whose own fixes are known to be "
                   "biased in height (a phone's WLS fixes lie about 11 m high)")
    p.add_argument("--constellation", type=constellation, metavar="SYSTEMS", default="gps",
                   help="systems used: gps (as `predisat availability` and LOCOPROL), "
                   "gps+galileo, all, or system letters such as GE")
    p.add_argument("--no-heading-check", action="store_true",
                   help="skip the heading-based integrity check")


def _add_simulate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "simulate", COMMAND_HELP["simulate"],
        "Build (or load) a synthetic world along the track, drive a stop-and-go train through "
        "it on the navigation day and write per-epoch pseudoranges with their true signal "
        "states (LOS, multipath, NLOS, lost), the true chainage and the true masks. A stretch "
        "under 0.8 km gets a short scenery recipe (not every kind of stretch fits); the "
        f"shortest is {_MIN_WORLD_M / 1000:g} km.",
    )  # fmt: skip
    w = p.add_mutually_exclusive_group()
    w.add_argument("--world", type=existing_file("a world.npz (a `predisat synth` truth/ folder "
                   "or a simulation's)"), metavar="NPZ",
                   help="a world saved before (default: build one)")  # fmt: skip
    w.add_argument("--scenery", type=existing_file("a YAML scenery recipe (surveys/*.yaml, "
                   "docs/synthetic-world.md)"), metavar="YAML",
                   help="scenery recipe of the world to build (default: drawn for --from-km "
                   "--to-km)")  # fmt: skip
    p.add_argument("--track", metavar="FILE",
                   help="track GeoJSON/CSV (default: the demo line 144, or the world's)")
    add_track_selection(p)
    p.add_argument("--from-km", type=finite_float, metavar="KM",
                   help=f"start of the world to build, chainage km (default {_SIM_FROM_KM})")
    p.add_argument("--to-km", type=finite_float, metavar="KM",
                   help=f"end of the world to build, chainage km (default {_SIM_TO_KM})")
    p.add_argument("--world-seed", type=int, metavar="N",
                   help="seed of the world to build (default 0)")
    p.add_argument("--nav", nargs="+", type=existing_file(_NAV), metavar="FILE",
                   help="navigation data (default: the embedded day, 2020-06-25)")
    p.add_argument("--start", metavar="TIME",
                   help=f"time of the first epoch: {TIME_HELP} (default: 08:00 GPS time of the "
                   "embedded day)")
    p.add_argument("--start-chainage", type=finite_float, metavar="M",
                   help="chainage of the first epoch, metres (default: 15 m inside the world "
                   "at the end --direction starts from)")
    p.add_argument("--direction", type=int, choices=(1, -1), default=1,
                   help="1: towards growing chainage, -1: towards falling chainage")
    p.add_argument("--speed", type=speed_mps, default=20.0, metavar="MPS",
                   help="cruise speed between stops, m/s (20 m/s = 72 km/h)")
    p.add_argument("--duration", type=positive_float, metavar="S",
                   help="length of the run, seconds (default: until 15 m before the world's end)")
    p.add_argument("--rate", type=rate_hz, default=1.0, metavar="HZ",
                   help="epochs per second, Hz")
    p.add_argument("--seed", type=seed_value, metavar="N", default=0,
                   help="seed of the signal errors")
    p.add_argument("--constellation", type=constellation, metavar="SYSTEMS", default="all",
                   help="systems simulated (`locator run --constellation` chooses the ones used): "
                   "gps, gps+galileo, all, or system letters")
    p.add_argument("--format", choices=("parquet", "csv"), default="parquet",
                   help="per-epoch table format")
    p.add_argument("--no-true-masks", action="store_true", help="skip true_masks.parquet")
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR", help="output folder")
    add_checks(
        p,
        needs("--from-km", "from_km", lambda a: not given(a, "world"), "building a world, "
              "not with --world (the world sets the stretch)"),
        needs("--to-km", "to_km", lambda a: not given(a, "world"), "building a world, not "
              "with --world (the world sets the stretch)"),
        needs("--from-km", "from_km", lambda a: not given(a, "scenery"), "the drawn scenery, "
              "not with --scenery (the recipe sets the stretch)"),
        needs("--to-km", "to_km", lambda a: not given(a, "scenery"), "the drawn scenery, not "
              "with --scenery (the recipe sets the stretch)"),
        needs("--world-seed", "world_seed", lambda a: not given(a, "world"),
              "building a world, not with --world"),
    )  # fmt: skip
    p.set_defaults(func=cmd_simulate)


def _add_run(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "run", COMMAND_HELP["run"],
        "Locate the train along the track at every epoch (SATHIA satellite pairs intersected "
        "with the track), trusting satellites by the masks, a cut-off or not at all, with "
        "fault detection and the heading check; writes the per-epoch table (interval, claim, "
        "satellites used and left out) and the run's description.",
    )  # fmt: skip
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sim", type=existing_dir(_SIM), metavar="DIR",
                     help="a simulated run (`locator simulate` folder)")
    src.add_argument("--obs", type=existing_file("a RINEX 2, 3 or 4 observation file"),
                     metavar="FILE", help="a RINEX 2, 3 or 4 observation file, plain, "
                     "Hatanaka-compressed or gzipped (with --nav)")  # fmt: skip
    src.add_argument("--device-gnss", type=existing_file(_DEVICE_GNSS), metavar="CSV",
                     help=_DEVICE_GNSS + ": a smartphone log carrying its satellite positions "
                     "and corrections (no --nav)")
    p.add_argument("--nav", nargs="+", type=existing_file(_BROADCAST_NAV), metavar="FILE",
                   help="broadcast RINEX navigation files of the observation day (required with "
                   "--obs, no default; SP3 and TLE do not carry the clock and ionosphere "
                   "corrections)")
    p.add_argument("--dual-frequency", action="store_true",
                   help="with --obs: range with the ionosphere-free combination of two codes "
                   "(L1/L2, E1/E5b, B1I/B3I, G1/G2; no ionosphere model needed, about 3x the "
                   "code noise), with an error model calibrated the same way (`locator "
                   "calibrate --dual-frequency`); satellites without a second code are left out "
                   "(default: single frequency with the broadcast ionosphere)")
    p.add_argument("--track", metavar="FILE",
                   help="track GeoJSON/CSV (default: the simulation's, or line 144)")
    add_track_selection(p)
    _run_arguments(p)
    p.add_argument("--format", choices=("parquet", "csv"), default="parquet",
                   help="per-epoch table format")
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR", help="output folder")
    p.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="no progress bar (as `locator -q`)")
    add_checks(
        p,
        needs("--nav", "nav", lambda a: given(a, "obs"), "--obs runs (a simulation carries "
              "its satellites' positions)"),
        requires("--obs", "obs", "--nav FILES", "nav", "RINEX navigation with the same day"),
        needs("--dual-frequency", "dual_frequency", lambda a: given(a, "obs"),
              "--obs runs (a simulation has one frequency; a phone log's corrections are "
              "single-frequency)"),
        needs("--extra-margin", "extra_margin", lambda a: given(a, "masks"),
              "--masks runs (it widens the masks' margins)"),
        needs("--trust-stretches", "trust_stretches", lambda a: given(a, "masks"),
              "--masks runs (it cuts the interval where the masks change)"),
    )  # fmt: skip
    p.set_defaults(func=cmd_run)


def _add_evaluate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "evaluate", COMMAND_HELP["evaluate"],
        "Score a `locator run` folder against the true chainage (a simulation's, a CSV's or a "
        "static antenna's): interval lengths, errors, hazardously misleading epochs; writes "
        "evaluation.json, the scored table and figures into the run folder.",
    )  # fmt: skip
    p.add_argument("run", type=existing_dir("a `locator run` output folder"), metavar="RUN_DIR",
                   help="the run folder to score")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--sim", type=existing_dir(_SIM), metavar="DIR",
                   help="the simulation the run was made from")
    g.add_argument("--truth-csv", type=existing_file(_TRUTH_CSV), metavar="CSV", help=_TRUTH_CSV)
    g.add_argument("--truth-chainage", type=finite_float, metavar="M",
                   help="a static antenna's chainage, metres")
    g.add_argument("--truth-positions", type=existing_file(_TRUTH_POSITIONS), metavar="CSV",
                   help=f"{_TRUTH_POSITIONS}, projected on --track")
    p.add_argument("--track", metavar="FILE", help="with --truth-positions, or --sim when the "
                   "run was made on another map than the simulation's world, the run's track: "
                   + _TRACK + " (default: none; required there)")  # fmt: skip
    add_track_selection(p)
    p.set_defaults(func=cmd_evaluate)


_DEVICE_GNSS = "a Google Smartphone Decimeter Challenge device_gnss.csv"
_TRUTH_POSITIONS = ("reference antenna positions: a Google Smartphone Decimeter Challenge "
                    "ground_truth.csv (time, latitude, longitude, ellipsoidal height)")

_TRUTH_CSV = ("a CSV with columns gps_s (GPS seconds) and chainage_m (true chainage, metres) "
              "covering the run's epochs")


def _add_calibrate(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "calibrate", COMMAND_HELP["calibrate"],
        "Fit the pseudorange error model sigma(el)^2 = a^2 + (b / sin el)^2 to residuals at a "
        "known position (simulated runs, or static stations at their header position), "
        "inflated to bound the tails (--bound overbound); writes the JSON model and a figure.",
    )  # fmt: skip
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--sim", nargs="+", type=existing_dir(_SIM), metavar="DIR",
                     help="simulated runs")
    src.add_argument("--obs", nargs="+", type=existing_file("RINEX 2, 3 or 4 observation files"),
                     metavar="FILE", help="static station RINEX observations (several files: "
                     "several days or sites, each at its header position)")  # fmt: skip
    src.add_argument("--device-gnss", nargs="+", type=existing_file(_DEVICE_GNSS),
                     metavar="CSV", help="smartphone logs (" + _DEVICE_GNSS + ", with --truth); "
                     "the phones name no model: add --receiver-class phone for a usable model")
    p.add_argument("--truth", nargs="+", type=existing_file("a GSDC ground_truth.csv"),
                   metavar="CSV", help="with --device-gnss: the ground truth of each file, in "
                   "the same order (required with --device-gnss, no default)")
    p.add_argument("--states", metavar="LIST",
                   help="with --sim: signal states to learn from, comma separated, of los, "
                   "multipath, nlos (default: los)")
    p.add_argument("--nav", nargs="+", type=existing_file(_BROADCAST_NAV), metavar="FILE",
                   help="with --obs: broadcast RINEX navigation files covering every --obs file "
                   "(required, no default)")  # fmt: skip
    p.add_argument("--station", nargs=3, type=finite_float, metavar=("X", "Y", "Z"),
                   help="with one --obs file: station ECEF, metres (default: the RINEX header "
                   "position)")  # fmt: skip
    p.add_argument("--dual-frequency", action="store_true",
                   help="with --obs: calibrate the ionosphere-free combination of two codes (the "
                   "model then applies to `locator run --dual-frequency` only; default: single "
                   "frequency with the broadcast ionosphere)")
    p.add_argument("--constellation", type=constellation, metavar="SYSTEMS", default="gps",
                   help="systems used: gps, gps+galileo, all, or system letters")
    p.add_argument("--k-sigma", type=positive_float, default=2.0, metavar="K",
                   help="pair interval half width in sigmas written into the model")
    p.add_argument("--receiver-class", choices=("geodetic", "automotive", "phone"),
                   help="the class the model is to cover: any receiver of it may then use the "
                   "model (default: only the receivers and antennas of the data); name a class "
                   "only for a model validated on several receivers of it (docs/errormodel.md)")
    p.add_argument("--min-el", type=non_negative_float, default=5.0, metavar="DEG",
                   help="with --obs: lower elevations are left out (the model then does not "
                   "cover them: runs leave such satellites out)")
    p.add_argument("--bound", choices=("overbound", "estimate"), default="overbound",
                   help="overbound: the fit inflated until it bounds the residual tails in every "
                   "elevation bin; estimate: the least-squares fit")  # fmt: skip
    p.add_argument("--out", required=True, type=output_file, metavar="JSON",
                   help="the model file (its figure beside it, .png)")
    add_checks(
        p,
        needs("--states", "states", lambda a: given(a, "sim"), "--sim (a simulation knows each "
              "signal's state)"),
        needs("--nav", "nav", lambda a: given(a, "obs"), "--obs"),
        needs("--dual-frequency", "dual_frequency", lambda a: given(a, "obs"), "--obs"),
        requires("--obs", "obs", "--nav FILES", "nav", "covering every observation file's day"),
        needs("--truth", "truth", lambda a: given(a, "device_gnss"), "--device-gnss"),
        requires("--device-gnss", "device_gnss", "--truth FILES", "truth",
                 "the ground truth of each file"),
        needs("--station", "station", lambda a: given(a, "obs") and len(a.obs) == 1,
              "one --obs file (with several, each file's header position is used; calibrate "
              "one file at a time to give its position)"),
    )  # fmt: skip
    p.set_defaults(func=cmd_calibrate)


def _add_demo(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = add_command(
        sub, "demo", COMMAND_HELP["demo"],
        "Build the demo world of line 144 (km 4.0-6.3) or reuse a `predisat demo` folder's, "
        "simulate a stop-and-go run on the embedded navigation day and locate it under each "
        "trust rule (true masks, pipeline masks when reused, no masks, a 15 deg cut-off), GPS "
        "only as `predisat availability`; writes a run folder per rule and summary.csv.",
    )  # fmt: skip
    p.add_argument("--out", default="locator_demo", type=output_dir, metavar="DIR",
                   help="output folder")
    p.add_argument("--seed", type=seed_value, metavar="N", default=1,
                   help="seed of the signal errors")
    p.add_argument("--integrity-risk", type=integrity_risk, metavar="P",
                   default=DEFAULT_RISK_PER_EPOCH,
                   help="integrity risk per epoch the intervals are drawn for (docs/locator.md)")
    p.add_argument("--from-predisat-demo", type=existing_dir("a `predisat demo` output folder "
                   "(truth/world.npz, masks/masks.parquet)"), metavar="DIR",
                   help="reuse a `predisat demo` folder's world and pipeline masks (default: "
                   "build the world)")  # fmt: skip
    p.set_defaults(func=cmd_demo)


def _add_balises(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from locator.balises.command import add_parser  # the balise list reads the track map

    add_parser(sub)  # `locator balises`: arguments and job in locator.balises


def _add_place_balises(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from locator.balises.place_command import add_parser  # the candidates read the track map

    add_parser(sub)  # `locator place-balises`: arguments and job in locator.balises


def _add_campaign(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from locator.campaign_command import add_parser

    add_parser(sub)


def build_parser(only: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The ``locator`` parser: one subcommand per job.

    Parameters
    ----------
    only : collection of str, optional
        Build only these subcommands' arguments; the others are listed with their help line
        (as :func:`predisat.cli.app.build_parser`). None (default) builds every subcommand whole.
    """
    parser: argparse.ArgumentParser = Parser(  # subcommands inherit its class
        prog="locator",
        formatter_class=HelpFormatter,
        description=(
            "1-D track-constrained GNSS locator (satellite-pair hyperbolic intersection with "
            "the track, SATHIA) with mask-aware satellite selection and integrity checks."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    adders: dict[str, Callable[[argparse._SubParsersAction[argparse.ArgumentParser]], None]] = {
        "simulate": _add_simulate,
        "run": _add_run,
        "evaluate": _add_evaluate,
        "calibrate": _add_calibrate,
        "demo": _add_demo,
        "balises": _add_balises,
        "place-balises": _add_place_balises,
        "campaign": _add_campaign,
    }
    for name, add in adders.items():
        if only is None or name in only:
            add(sub)
        else:
            sub.add_parser(name, help=COMMAND_HELP[name])
    # -q after the subcommand too (a user trial's `locator run ... -q` was refused); SUPPRESS
    # leaves the main parser's value when it is not given there
    for command in sub.choices.values():
        if not {"-q", "--quiet"} & set(command._option_string_actions):
            command.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                                 help="no progress bars")  # fmt: skip
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``locator`` command line; returns the exit status."""
    notes = {"campaign": "; finished jobs are kept: rerun the same command to resume"}
    parser = command_parser(build_parser, COMMAND_HELP, argv, "locator")
    if parser is None:
        return 130
    return run_main(parser, argv, "locator", interrupted_note=notes)


if __name__ == "__main__":  # `python -m locator.cli`, as `python -m locator`
    sys.exit(main())
