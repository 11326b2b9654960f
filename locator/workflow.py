"""The jobs behind the ``locator`` command line: simulate, run, evaluate, calibrate, demo.

Each function reads its inputs, calls the library and writes a folder or file; the command
line (:mod:`locator.cli`) only parses arguments. Errors in the inputs raise ``ValueError``
subclasses whose message names the file and the fix.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.errorfit import (
    Residuals,
    binned_sigma,
    calibration_figure,
    fit_systems,
    model_file_parts,
)
from locator.evaluate import score_run, summarise
from locator.fde import LocatorConfig
from locator.run import RunConfig, claim_label, fixed_k_of, no_safety_banner, run_locator
from locator.runio import read_run, write_figures, write_run, write_table
from locator.sathia import AntennaPath
from locator.sim.simfile import SimRun
from locator.sim.simulate import SkySource, simulate_run
from locator.sources import EpochSource, SimSource
from predisat.availability.satellites import default_ephemeris, default_window
from predisat.availability.trainrun import SpeedProfile
from predisat.geodesy import ecef_to_geodetic
from predisat.gnss.errormodel import (
    ErrorModelFile,
    IntervalModel,
    read_error_model_file,
    write_error_model,
)
from predisat.gnss.integrity import IntegrityBudget
from predisat.jsontypes import JsonDict
from predisat.masks.fileformat import read_masks, write_masks
from predisat.masks.maskset import MaskSet
from predisat.track import demo_track

if TYPE_CHECKING:
    from locator.devicegnss import GroundTruth
    from predisat.synth.world import World  # the renderer's world: needs the [synth] extra
    from predisat.track import TrackMap

__all__ = [
    "DEMO_RANGE_M",
    "ImplausibleFitError",
    "calibrate_to_file",
    "check_track",
    "check_track_height",
    "check_track_offset",
    "demo",
    "evaluate_folder",
    "rule_folder",
    "run_to_folder",
    "sim_on_track",
    "simulate_to_folder",
    "static_truth",
    "stop_and_go",
    "truth_for",
    "truth_from_positions",
    "with_model",
]

DEMO_RANGE_M = (4000.0, 6300.0)  # line 144 km 4.0-6.3 (`predisat demo` renders km 4-6)
MAX_TRACK_OFFSET_M = 5.0
MAX_HEIGHT_DISAGREEMENT_M = 20.0
"""Largest median height, m, of a receiver's own 3-D fixes above its antenna on the track
(the track axis plus the antenna height) before a real run is refused: a map without heights
(h = 0) or with heights above the geoid misplaces the locator's fixes by tens of metres (a
geometry review, 2026-12-06: 45 m of height, 5.6 m median and 191 m worst error; 4 m, 0.4 m);
single-frequency fixes are good to a few metres in height over a sample of epochs."""


def stop_and_go(
    cruise_mps: float = 20.0,
    accel_s: float = 40.0,
    cruise_s: float = 30.0,
    brake_s: float = 30.0,
    dwell_s: float = 60.0,
) -> SpeedProfile:
    """Start from rest, cruise, stop at a station, dwell, and leave again at cruise speed."""
    if not cruise_mps > 0 or min(accel_s, cruise_s, brake_s, dwell_s) <= 0:
        raise ValueError("stop_and_go needs a positive cruise speed and positive durations")
    t = np.cumsum([0.0, accel_s, cruise_s, brake_s, dwell_s, accel_s])
    v = [0.0, cruise_mps, cruise_mps, 0.0, 0.0, cruise_mps]
    return SpeedProfile.from_time_table(t, v)


def check_track(
    path: AntennaPath,
    ecef_m: np.ndarray,
    label: str,
    max_offset_m: float = MAX_TRACK_OFFSET_M,
    hint: str = "",
) -> None:
    """The antenna positions of a run (first and last rows of ``ecef_m``) must lie on the
    given track within ``max_offset_m``."""
    ends = np.asarray(ecef_m, float).reshape(-1, 3)[[0, -1]]
    lat, lon, h = ecef_to_geodetic(ends)
    pr = path.track.project(lat, lon, h)
    off = float(np.max(np.hypot(pr.offset_m, pr.along_m)))
    if off > max_offset_m:
        # The projection's plane offsets are meaningless far from the line (a receiver on
        # another continent); the straight distance to the projected point is what to tell.
        near = path.ecef_at(np.clip(pr.chainage_m, 0.0, path.length_m))
        dist_m = float(np.max(np.linalg.norm(ends - near, axis=-1)))
        away = f"{dist_m / 1000:.1f} km" if dist_m >= 10_000 else f"{dist_m:.0f} m"
        raise ValueError(
            f"{label}: the antenna is {away} away from track {path.track.name!r}; pass the "
            f"--track the run was made on{hint}"
        )


def sim_on_track(
    sim: SimRun, track: TrackMap, label: str, max_offset_m: float = MAX_TRACK_OFFSET_M
) -> SimRun:
    """A simulated run with its true chainage measured on another map of its line.

    A simulation's ``chainage_m`` is the chainage on its own world's track. Another map of the
    same line (the GeoJSON of the real line, a survey's map) has its own origin, length and
    possibly sense, so the start, the odometer, the balises and the truth of a run on that map
    take the simulated antenna's positions projected on it.

    Parameters
    ----------
    sim : SimRun
    track : TrackMap
        The map the run is located on.
    label : str
        The simulation's folder, for the messages.
    max_offset_m : float
        Largest distance, m, of any simulated antenna position from ``track``.

    Returns
    -------
    SimRun
        ``sim`` with ``chainage_m`` replaced (the other fields are shared, read-only).

    Raises
    ------
    ValueError
        When an epoch lies farther than ``max_offset_m`` from the map (another line, or a map
        that stops short), or when the map's chainage folds back under the run.
    """
    lat, lon, h = ecef_to_geodetic(sim.antenna_ecef_m)
    pr = track.project(lat, lon, h)
    off = np.hypot(pr.offset_m, pr.along_m)
    worst = int(np.argmax(off))
    if off[worst] > max_offset_m:
        raise ValueError(
            f"{label}: the simulated antenna passes {off[worst]:.0f} m beside track "
            f"{track.name!r} (epoch {worst}, gps_s {sim.gps_s[worst]:.0f}; at most "
            f"{max_offset_m:g} m): the map is of another line or stops short of the run; pass "
            "the --track of the simulated line, or none (the simulation's world.npz)"
        )
    own = np.diff(np.asarray(sim.chainage_m, float))
    new = np.diff(pr.chainage_m)
    # a step of another size than the train's: a projection that jumped to a nearby leg of
    # the map (a review), stops included
    jump = np.abs(np.abs(new) - np.abs(own)) > 2.0 + 0.05 * np.abs(own)
    if jump.any():
        k = int(np.flatnonzero(jump)[0])
        raise ValueError(
            f"{label}: on track {track.name!r} the simulated train moves {abs(new[k]):.1f} m at "
            f"epoch {k + 1} (gps_s {sim.gps_s[k + 1]:.0f}) where it moved {abs(own[k]):.1f} m: "
            "the map runs close to itself there, or is of another line; pass a map of the "
            "simulated line alone"
        )
    moving = np.abs(own) > 1.0  # a stop's projection wanders by millimetres
    # the map's sense against the simulation's: from the whole run when no epoch moves a
    # metre (a crawl, or epochs at 10 Hz under 36 km/h), whose steps still outweigh a stop's
    # millimetres (a review: such a run on a reversed map kept its direction and was refused
    # as a reversal)
    sense = -1.0 if float(np.dot(new, own)) < 0.0 else 1.0
    if moving.any():
        sense = float(np.sign(np.median(new[moving] / own[moving])))
        back = moving & (new * own * sense <= 0.0)
        if back.any():
            k = int(np.flatnonzero(back)[0])
            raise ValueError(
                f"{label}: the chainage of track {track.name!r} runs back under the simulated "
                f"train at epoch {k + 1} (gps_s {sim.gps_s[k + 1]:.0f}): the map folds or "
                "overlaps itself there; pass a map of the line without the fold"
            )
    meta = dict(sim.meta)
    if sense < 0:
        # the map counts from the other end: the train runs the other way in its chainage
        # (a user trial's `locator balises --track` on a reversed map was refused as "the run
        # goes back 2464.88 m against its direction (+1)")
        meta["direction"] = -int(meta.get("direction", 1))
    return replace(sim, chainage_m=np.asarray(pr.chainage_m, float), meta=meta)


_NEAR_FOR_HEIGHT_M = 200.0


class _Near(NamedTuple):
    offset_m: NDArray  # beside the track, left positive
    height_m: NDArray  # above the track axis


def _near_fixes(path: AntennaPath, fixes_ecef_m: ArrayLike) -> _Near | None:
    """The receiver's own fixes projected on the track, those within 200 m of it (finite
    rows only); None when none is. Beside the line only: a receiver elsewhere is told so by
    :func:`check_track`, and a height or offset from a far projection means nothing."""
    fixes = np.asarray(fixes_ecef_m, float).reshape(-1, 3)
    fixes = fixes[np.all(np.isfinite(fixes), axis=1)]
    if not len(fixes):
        return None
    pr = path.track.project(*ecef_to_geodetic(fixes))
    near = np.hypot(pr.offset_m, pr.along_m) <= _NEAR_FOR_HEIGHT_M
    if not near.any():
        return None
    return _Near(np.asarray(pr.offset_m, float)[near], np.asarray(pr.height_m, float)[near])


OFF_MAP_WARN_M = 3.0
"""A run whose own fixes lie more than this beside the track map (the median, metres) is told:
the pair intervals take the antenna on the map (a trial: an antenna 4.5 m beside it, a passing
loop's, made hazardous misleading information with k = 2 on real stations)."""

OFF_MAP_REFUSE_M = 25.0
"""... and more than this is refused: another line, or the map of another track."""


def check_track_offset(
    path: AntennaPath, fixes_ecef_m: ArrayLike, label: str,
    whose: str = "the receiver's own fixes",
) -> str | None:
    """The receiver's own fixes must lie on the track map, not beside it.

    Parameters
    ----------
    path : AntennaPath
    fixes_ecef_m : array_like, shape (n, 3)
        The receiver's own position fixes, ECEF metres; rows with NaN and fixes more than
        200 m from the track are skipped.
    label : str
        What the fixes are, for the message.
    whose : str
        What the positions are, in the message (a simulation's true antenna positions).

    Returns
    -------
    str or None
        A warning when their median distance beside the track exceeds
        :data:`OFF_MAP_WARN_M`, else None.

    Raises
    ------
    ValueError
        When it exceeds :data:`OFF_MAP_REFUSE_M` (a trial's antenna 25-50 m beside the map ran
        without a word, every epoch blamed on NLOS).
    """
    near = _near_fixes(path, fixes_ecef_m)
    if near is None:
        return None
    off = float(np.median(near.offset_m))
    side = "left of" if off > 0 else "right of"
    what = (f"{label}: {whose} lie {abs(off):.1f} m {side} track "
            f"{path.track.name!r} (the median of {near.offset_m.size})")  # fmt: skip
    if abs(off) > OFF_MAP_REFUSE_M:
        raise ValueError(
            f"{what}: the antenna is on another track or line, or the map is of another; give "
            "the map of the track the train ran on (--track, --track-name)"
        )
    if abs(off) > OFF_MAP_WARN_M:
        return (
            f"{what}: the pair intervals take the antenna on the map, so a train on another "
            "track (a passing loop, the other track of a double line) or a map metres off "
            "makes errors they do not bound (docs/locator.md, limits); check the map and the "
            "track the train took"
        )
    return None


def check_track_height(
    path: AntennaPath,
    fixes_ecef_m: ArrayLike,
    label: str,
    max_m: float = MAX_HEIGHT_DISAGREEMENT_M,
) -> float:
    """The receiver's own 3-D fixes must lie at its antenna's height on the track.

    Parameters
    ----------
    path : AntennaPath
        The track and the antenna height above it.
    fixes_ecef_m : array_like, shape (n, 3)
        The receiver's own position fixes (single point positions), ECEF metres; rows with
        NaN, and fixes more than 200 m beside the track (:func:`check_track` tells those), are
        skipped.
    label : str
        What the fixes are, for the message (the file).
    max_m : float
        Largest median disagreement, m.

    Returns
    -------
    float
        The median height of the fixes above the antenna on the track, m (NaN without a
        fix).

    Raises
    ------
    ValueError
        When the median exceeds ``max_m``, naming the likely causes and the fix.
    """
    near = _near_fixes(path, fixes_ecef_m)
    if near is None:
        return float("nan")
    dh = float(np.median(near.height_m) - path.antenna_height_m)
    if abs(dh) > max_m:
        where = "above" if dh > 0 else "below"
        if np.all(np.abs(np.asarray(path.track.h_m)) < 1.0):  # smoothing leaves centimetres
            cause = "the track map has no heights (h = 0 everywhere)"
        elif dh > 0:
            cause = ("the track map's heights are too low: heights above the geoid (sea level) "
                     "read as ellipsoidal ones, or no heights")  # fmt: skip
        else:
            cause = "the track map's heights are too high (heights of another datum?)"
        raise ValueError(
            f"{label}: the receiver's own fixes lie {abs(dh):.1f} m {where} its antenna on "
            f"track {path.track.name!r} (the median of {near.height_m.size}; the track's height "
            f"plus --antenna-height {path.antenna_height_m:g} m; at most {max_m:g} m is accepted): "
            f"{cause}. The locator meets the satellites' ranges with the track in 3-D, so its "
            "fixes would be tens of metres off; give a track map with WGS84 ellipsoidal heights "
            "(docs/track-map.md), or correct --antenna-height"
        )
    return dh


def simulate_to_folder(
    world: World,
    ephemeris: SkySource,
    out: str | Path,
    *,
    t0_gps_s: float,
    start_chainage_m: float | None = None,
    direction: int = +1,
    profile: SpeedProfile | None = None,
    duration_s: float | None = None,
    rate_hz: float = 1.0,
    seed: int = 0,
    constellation: str = "all",
    fmt: str = "parquet",
    masks_out: bool = True,
    end_chainage_m: float | None = None,
) -> tuple[SimRun, Path]:
    """Simulate a run and write it (and the world's true masks, for ``--masks``) to ``out``.

    The run starts 15 m inside the world's scenery at the end chosen by ``direction`` unless
    ``start_chainage_m`` is given, and lasts until 15 m before the other end by default (until
    ``end_chainage_m`` when given and ``duration_s`` is not).
    """
    profile = profile or stop_and_go()
    lo, hi = world.extent_m
    start = (
        (lo + 15.0 if direction > 0 else hi - 15.0)
        if start_chainage_m is None
        else start_chainage_m
    )
    if duration_s is None:
        if end_chainage_m is not None:
            span = (end_chainage_m - start) * (1.0 if direction > 0 else -1.0)
        else:
            span = (hi - start - 15.0) if direction > 0 else (start - lo - 15.0)
        grid = np.arange(0.0, 3600.0, 0.5)
        duration_s = float(np.floor(np.interp(span, profile.distance_at(grid), grid)))
    sim = simulate_run(
        world, ephemeris, start, t0_gps_s, profile, duration_s, rate_hz,
        direction=direction, seed=seed, constellation=constellation,
    )  # fmt: skip
    folder = sim.write(out, fmt)
    if masks_out:
        # lazy: the world's true masks are ray cast by the renderer ([synth] extra)
        from predisat.synth.truth import true_masks

        h = float(sim.meta.get("antenna_height_m", 4.0))  # the run's antenna, as a mask file says
        tm = true_masks(world, antenna_height_m=h)
        ms = MaskSet.from_arrays(
            tm.chainage_m, tm.lat_deg, tm.lon_deg, tm.h_m, tm.heading_deg, tm.mask_el_deg,
            margin_deg=1.0, provenance={"source": "true masks of the simulated world",
                                        "margin": "1 deg", "antenna_height_m": h},
        )  # fmt: skip
        write_masks(ms, folder / "true_masks.parquet")
    return sim, folder


def run_to_folder(
    path: AntennaPath,
    source: EpochSource,
    out: str | Path,
    *,
    start_chainage_m: float,
    config: RunConfig,
    masks: MaskSet | None = None,
    fmt: str = "parquet",
    meta: Mapping[str, object] | None = None,
    progress: Callable[[int], object] | None = None,
) -> tuple[pd.DataFrame, Path]:
    """Run the locator over a source and write the run folder with its figures."""
    epochs = run_locator(
        path, source, start_chainage_m=start_chainage_m, config=config, masks=masks,
        progress=progress,
    )  # fmt: skip
    info = {
        "track": path.track.name,
        "track_length_m": path.length_m,
        # the ends (lat, lon, degrees), so that a truth projected later uses the same track
        # the same way round
        "track_ends_latlon_deg": [
            list(map(float, ll[:2]))
            for ll in zip(*path.track.position_at([0.0, path.track.length_m]), strict=True)
        ],
        "antenna_height_m": path.antenna_height_m,
        "start_chainage_m": start_chainage_m,
        "config": config.to_dict(),
        "interval_width": config.locator.width_text(),
        "source": source.describe(),
        "masks": None if masks is None else dict(masks.provenance),
        "summary": dict(summarise(epochs)),
        **dict(meta or {}),
    }
    title = f"{path.track.name}: trust {config.trust}, {config.locator.width_label()}"
    fixed_k = config.locator.fixed_k_sigma
    if config.error_model_caveat or fixed_k is not None:  # not a plain safety claim: said
        title += f"; {claim_label(config.error_model_caveat, fixed_k)}"
    folder = write_run(epochs, out, info, fmt, figures_title=title,
                       figures_banner=no_safety_banner(config.error_model_caveat, fixed_k))
    return epochs, folder


def truth_for(
    epochs: pd.DataFrame,
    *,
    sim: SimRun | None = None,
    truth_csv: str | Path | None = None,
    chainage_m: float | None = None,
) -> np.ndarray:
    """True chainage per epoch from a simulation, a ``gps_s,chainage_m`` CSV or a constant."""
    t = epochs["gps_s"].to_numpy(float)
    if sum(x is not None for x in (sim, truth_csv, chainage_m)) != 1:
        raise ValueError("give exactly one truth: a simulation, a truth CSV or a chainage")
    if chainage_m is not None:
        return np.full(len(t), float(chainage_m))
    if sim is not None:
        ts, cs = sim.gps_s, sim.chainage_m
        label = "the simulation"
    else:
        ts, cs = _truth_csv(str(truth_csv), epochs)
        label = str(truth_csv)
    if len(ts) == 0 or t.min() < ts.min() - 1e-6 or t.max() > ts.max() + 1e-6:
        raise ValueError(
            f"{label} does not cover the run's epochs ({t.min():.0f}-{t.max():.0f} gps_s)"
        )
    return np.interp(t, ts, cs)


def _truth_csv(path: str, epochs: pd.DataFrame) -> tuple[NDArray, NDArray]:
    """``gps_s`` and ``chainage_m`` of a truth file, refused naming the line where they cannot
    be a truth: read bare, rows in descending time and an empty cell turned into 6 and 1
    hazardous epochs that were not, and kilometres into 4 km errors (a user trial)."""
    from locator.csvinput import read_csv_table

    table = read_csv_table(path, ("gps_s", "chainage_m"), what="truth file", error=ValueError,
                           doc="docs/locator.md, `locator evaluate`")  # fmt: skip
    ts = table.numbers("gps_s", "give GPS seconds (since 1980-01-06 00:00:00 GPST)")
    cs = table.numbers("chainage_m", "give the antenna's true chainage in metres")
    for name, values in (("gps_s", ts), ("chainage_m", cs)):
        empty = np.flatnonzero(~np.isfinite(values))
        if len(empty):
            raise ValueError(f"{path}, line {table.line(int(empty[0]))}: {name} is empty; every "
                             "row of a truth gives both gps_s and chainage_m")  # fmt: skip
    back = np.flatnonzero(np.diff(ts) <= 0.0)
    if len(back):
        k = int(back[0]) + 1
        raise ValueError(f"{path}, line {table.line(k)}: gps_s {ts[k]:.3f} does not follow "
                         f"{ts[k - 1]:.3f}; sort the rows by time, one row per time")  # fmt: skip
    # kilometres: read a thousand times larger, the truth meets the run's own estimates far
    # better than as written (a review: comparing spans refused a standing train's RTK truth)
    if "chainage_m" in epochs and len(ts) >= 2:
        t = epochs["gps_s"].to_numpy(float)
        est = epochs["chainage_m"].to_numpy(float)
        ok = np.isfinite(est) & (t >= ts[0]) & (t <= ts[-1])
        if ok.sum() >= 3:
            truth = np.interp(t[ok], ts, cs)
            as_is = float(np.median(np.abs(truth - est[ok])))
            as_km = float(np.median(np.abs(1000.0 * truth - est[ok])))
            if as_is > 20.0 and 5.0 * as_km < as_is:
                raise ValueError(f"{path}: chainage_m reads as kilometres (the run's estimates "
                                 f"lie {as_is:.0f} m from it as written, {as_km:.0f} m from it "
                                 "read in kilometres, in the median); give metres")  # fmt: skip
    return ts, cs


def truth_from_positions(
    epochs: pd.DataFrame, truth: GroundTruth, track: TrackMap, max_offset_m: float = 20.0
) -> np.ndarray:
    """True chainage per epoch from reference antenna positions (a phone drive's ground truth),
    projected on ``track``.

    Parameters
    ----------
    epochs : pandas.DataFrame
        A run's epochs (``gps_s``).
    truth : GroundTruth
        Reference positions (:func:`locator.devicegnss.read_ground_truth`).
    track : TrackMap
        The track the run was made on.
    max_offset_m : float
        Largest median distance of the positions from the track.

    Returns
    -------
    ndarray, shape (n_epoch,)
        True chainage, metres.

    Raises
    ------
    ValueError
        Naming the file: when the truth does not cover an epoch (:meth:`GroundTruth.at`), or
        when its positions lie more than ``max_offset_m`` beside the track (the median: another
        track, or the truth of another drive).
    """
    ecef = truth.at(epochs["gps_s"].to_numpy(float))
    lat, lon, h = ecef_to_geodetic(ecef)
    proj = track.project(lat, lon, h)
    off = float(np.median(np.abs(proj.offset_m)))
    if off > max_offset_m:
        raise ValueError(
            f"{truth.path}: its positions lie {off:.0f} m beside track {track.name!r} (median); "
            "give the track the run was made on (--track, --track-name) or the ground truth of "
            "this drive"
        )
    return np.asarray(proj.chainage_m, float)


def evaluate_folder(
    run_dir: str | Path, truth: np.ndarray, fmt: str | None = None
) -> dict[str, float]:
    """Score a run folder against the truth; writes ``scored``, ``evaluation.json``, figures."""
    folder = Path(run_dir)
    epochs, meta = read_run(folder)
    scored = score_run(epochs, truth)
    config = meta.get("config")
    banner = (no_safety_banner(str(config.get("error_model_caveat", "")), fixed_k_of(config))
              if isinstance(config, dict) else None)  # fmt: skip
    if banner is not None:
        # no safety claims, as run.json says, whatever an older version wrote in the table
        # (safety_claim = claim at a fixed k before 029e738; no column before that): the
        # scored table is read alone, and its figures are drawn from it (a review)
        scored["safety_claim"] = False
    fmt = fmt or ("csv" if (folder / "epochs.csv").is_file() else "parquet")
    write_table(scored, folder, "scored", fmt)
    summary = dict(summarise(scored))
    # what the claims were drawn under, kept with the scores (a user trial's forced model read
    # as "claim_share 1.0" with nothing else)
    rules = _run_rules(meta)
    (folder / "evaluation.json").write_text(json.dumps({**summary, **rules}, indent=2) + "\n")
    caption = ", ".join(v for v in (rules["trust"], rules["interval_width"], rules["claims"]) if v)
    write_figures(scored, folder, title=f"{meta.get('track', '')}: against the truth; {caption}",
                  banner=banner)
    return summary


def _run_rules(meta: Mapping[str, Any]) -> dict[str, str]:
    """The trust rule, the interval width and what the claims are, from a run's ``run.json``
    (empty strings where an older run does not say)."""
    config = meta.get("config") or {}
    caveat = str(config.get("error_model_caveat", "")) if isinstance(config, dict) else ""
    trust = str(config.get("trust", "")) if isinstance(config, dict) else ""
    return {
        "trust": f"trust {trust}" if trust else "",
        "interval_width": str(meta.get("interval_width", "")),
        "claims": claim_label(caveat, fixed_k_of(config) if isinstance(config, dict) else None),
    }


class ImplausibleFitError(ValueError):
    """A fitted error model no receiver could have (:func:`calibrate_to_file`)."""


def calibrate_to_file(
    data: Sequence[Residuals],
    out: str | Path,
    *,
    k_sigma: float = 2.0,
    bound: str = "overbound",
    fitted: Mapping[str, object] | None = None,
    receiver_class: str = "",
    confidence: float | None = 0.95,
    pool_systems: bool = False,
    max_sigma_m: float = 50.0,
) -> ErrorModelFile:
    """Fit the error model per constellation, write it (JSON) and its figure (``.png``).

    ``bound="overbound"`` (default) writes each system's fit inflated until it bounds the
    residual tails in every elevation bin (:func:`locator.intervals.overbound_error_model`,
    with the sample-size confidence ``confidence``), ``"estimate"`` the least-squares fits. The
    file states what it applies to (receivers, antennas, ``receiver_class``, codes, elevations)
    and, per system, the independent samples and the tail probability checked.
    ``pool_systems``: one fit for every system (:func:`locator.errorfit.fit_systems`).

    Raises
    ------
    ImplausibleFitError
        When a system's ``a`` or ``b`` exceeds ``max_sigma_m`` (nothing is written): residuals
        that large come from a wrong reference position, not from a receiver.
    """
    fits = fit_systems(data, bound=bound, confidence=confidence, pool_systems=pool_systems)
    model, systems, app = model_file_parts(
        fits, data, k_sigma=k_sigma, receiver_class=receiver_class, method=bound
    )
    big = {c: max(m.error.a_m, m.error.b_m) for c, m in systems.items()
           if not max(m.error.a_m, m.error.b_m) <= max_sigma_m}  # fmt: skip
    if big:
        raise ImplausibleFitError(
            f"the fitted pseudorange sigma reaches {max(big.values()):.0f} m "
            f"({', '.join(sorted(big))}; above {max_sigma_m:g} m no receiver is that poor): the "
            "position the residuals were taken at is wrong (a station's coordinates, a header "
            f"position, a truth file); {out} was not written"
        )
    info: JsonDict = {**dict(fitted or {}), "bound": bound, "confidence": confidence}
    for sys_, f in fits.items():
        if f.system != sys_:  # pooled: stated once, under its letters
            info["pooled_systems"] = f.system
        entry: JsonDict = {"estimate": {"a_m": f.estimate.a_m, "b_m": f.estimate.b_m}}
        ob = f.overbound
        if ob is not None:
            entry.update(
                factor=ob.factor, lag1_correlation=ob.lag1_correlation,
                independent_share=ob.independent_share,
                bins=[{"el_lo_deg": lo, "el_hi_deg": hi, "n": int(n), "factor": g}
                      for lo, hi, n, g in zip(ob.bin_el_lo_deg.tolist(), ob.bin_el_hi_deg.tolist(),
                                              ob.bin_n.tolist(), ob.bin_factor.tolist(),
                                              strict=True)],
            )  # fmt: skip
        if f.pair_factors:  # each receiver x antenna pair's own tail check (1: bounded)
            entry["pair_factors"] = [{"receiver": r, "antenna": a, "factor": g}
                                     for r, a, g in f.pair_factors]  # fmt: skip
        info[f"system_{sys_}"] = entry
    el, res = _stack_residuals(data)
    table = binned_sigma(el, res)
    info["residuals"] = int(np.isfinite(res).sum())
    info["binned_sigma"] = table.to_dict(orient="records")
    p = write_error_model(out, model, info, systems=systems, applicability=app)
    estimate = None
    if bound == "overbound" and len(fits) == 1:
        estimate = next(iter(fits.values())).estimate
    fig = calibration_figure(table, model.error, estimate=estimate)
    fig.savefig(p.with_suffix(".png"), dpi=100)
    return read_error_model_file(p)


def _stack_residuals(data: Sequence[Residuals]) -> tuple[NDArray, NDArray]:
    """Every data set's residuals as one ``(n_epoch, n_sat)`` pair, padded with NaN."""
    n = max(d.el_deg.shape[1] for d in data)

    def wide(a: NDArray) -> NDArray:
        return np.pad(a, ((0, 0), (0, n - a.shape[1])), constant_values=np.nan)

    return (np.concatenate([wide(d.el_deg) for d in data]),
            np.concatenate([wide(d.residual_m) for d in data]))  # fmt: skip


def rule_folder(rule: str) -> str:
    """The run folder of a trust rule in :func:`demo` (``"15 deg cut-off"`` ->
    ``"15_deg_cutoff"``)."""
    return rule.replace(" ", "_").replace("-", "")


def demo(
    out: str | Path,
    *,
    world: World | None = None,
    pipeline_masks: MaskSet | None = None,
    seed: int = 1,
    hour_utc: float = 8.0,
    log: Callable[[str], object] = print,
    constellation: str = "gps",
    rate_hz: float = 1.0,
    stretch_m: tuple[float, float] | None = None,
    integrity: IntegrityBudget | None = None,
) -> pd.DataFrame:
    """A simulated run on the demo line located under several trust rules, scored.

    Builds (or takes) the demo world of line 144 km 4.0-6.3, simulates a stop-and-go run on
    the embedded navigation day, and locates it with the world's true masks, with the pipeline
    masks when given, with no masks, and with a 15 deg cut-off, using the satellites of
    ``constellation`` (default GPS, as ``predisat availability`` and the LOCOPROL figures; the
    simulation holds every system). ``rate_hz``: epochs per second of the simulated run;
    ``stretch_m``: the chainages it runs between (default: the world's, 15 m inside; the
    demo gives the pipeline masks' own, so that every rule is scored where it has masks).
    ``integrity``: the integrity risk per epoch the pair intervals are drawn for (default
    :class:`~predisat.gnss.integrity.IntegrityBudget()`, as ``locator run``).

    Returns
    -------
    pandas.DataFrame
        One row per rule with :func:`locator.evaluate.summarise` figures.
    """
    root = Path(out)
    if world is None:
        # lazy: building a world needs the renderer ([synth] extra)
        from predisat.synth.world import World, WorldSpec

        log("locator demo 1/3: building the synthetic world (line 144, km 4.0-6.3)")
        world = World.build(demo_track(), WorldSpec.mixed(*DEMO_RANGE_M, seed=0), 0)
    eph = default_ephemeris()
    t0 = float(default_window()[0] + hour_utc * 3600.0)
    log("locator demo 2/3: simulating the train run (LOS, multipath, NLOS, loss) and true masks")
    start_m, end_m = (None, None) if stretch_m is None else stretch_m
    sim, sim_dir = simulate_to_folder(
        world, eph, root / "simulation", t0_gps_s=t0, seed=seed, rate_hz=rate_hz,
        start_chainage_m=start_m, end_chainage_m=end_m,
    )  # fmt: skip
    truth_masks = read_masks(sim_dir / "true_masks.parquet")
    path = AntennaPath(world.track, float(sim.meta["antenna_height_m"]))
    rules: dict[str, tuple[str, MaskSet | None, float]] = {
        "true masks": ("masks", truth_masks, 0.0),
        "no masks": ("none", None, 0.0),
        "15 deg cut-off": ("cutoff", None, 15.0),
    }
    if pipeline_masks is not None:
        rules = {"pipeline masks": ("masks", pipeline_masks, 0.0), **rules}
    log(f"locator demo 3/3: locating {sim.n_epoch} epochs under {len(rules)} trust rules")
    budget = IntegrityBudget() if integrity is None else integrity
    log(f"  pair intervals: {LocatorConfig(budget=budget).width_text()}")
    rows = []
    for label, (trust, masks, cut) in rules.items():
        cfg = RunConfig(LocatorConfig(budget=budget), trust=trust, cutoff_deg=cut or 15.0)
        name = rule_folder(label)
        _, folder = run_to_folder(
            path, SimSource(sim, constellation=constellation), root / name,
            start_chainage_m=float(sim.chainage_m[0]), config=cfg, masks=masks,
            meta={"rule": label, "constellation": constellation},
        )  # fmt: skip
        summary = evaluate_folder(folder, sim.chainage_m)
        rows.append({"rule": label, "constellation": constellation,
                     "integrity_risk": budget.risk_per_epoch, **summary})  # fmt: skip
    table = pd.DataFrame(rows)
    # summarise() returns floats throughout; counts read better as integers
    counts = ["epochs", "hmi", "hmi_fix", "mi"]
    table[counts] = table[counts].astype(int)
    table.to_csv(root / "summary.csv", index=False, float_format="%.6g")
    return table


def with_model(config: RunConfig, model: IntervalModel | None) -> RunConfig:
    """``config`` with its locator's error model replaced (when given)."""
    if model is None:
        return config
    return replace(config, locator=replace(config.locator, model=model))


def static_truth(obs_header_ecef_m: ArrayLike, path: AntennaPath) -> float:
    """Chainage of a static antenna on ``path`` (its projection)."""
    lat, lon, h = ecef_to_geodetic(np.asarray(obs_header_ecef_m, float))
    return float(path.track.project(lat, lon, h).chainage_m)
