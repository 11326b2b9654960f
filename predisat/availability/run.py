"""The ``predisat availability`` run: masks + track + navigation data -> report and tables.

:func:`run_availability` loads a mask file (or takes a :class:`~predisat.masks.maskset.MaskSet`),
the
navigation data (RINEX, SP3 or TLE, told apart by content; the embedded navigation day when
none is given) and a time window, counts trusted satellites along the line under three kinds
of rule - the surveyed masks (with their margin), no mask (horizon) and flat cut-offs - and
writes into an output folder:

* ``report.html`` - the self-contained report (:mod:`predisat.availability.report`);
* ``summary.csv`` / ``summary.json`` - one row per rule (line-wide figures);
* ``positions.csv`` / ``positions.parquet`` - one row per rule and position;
* ``epochs.csv`` / ``epochs.parquet`` - one row per rule and epoch;
* ``availability.geojson`` - the line cut into one segment per position, coloured by the share
  of time with >= 4 trusted satellites under the masks (QGIS: style on ``share_ge4`` or use the
  ``stroke`` colour);
* optionally ``counts.parquet`` - every count, long format (rule, chainage_m, gps_s, count).

While it runs, ``blocks/<rule>/`` holds the finished blocks of positions
(:class:`~predisat.availability.engine.BlockCheckpoint`): a killed run, rerun with the same
inputs and output folder, takes them instead of computing them again; the folder is deleted
once every output is written. The mask input and the output folder may be fsspec URLs
(:mod:`predisat.storage`): remote outputs are written locally first and then each is
uploaded atomically.

The command line (:mod:`predisat.cli.availability`) maps its options onto it. See
``docs/report.md``.
"""

from __future__ import annotations

import contextlib
import gzip
import math
import os
import re
import shutil
import tempfile
import time
import warnings
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import NoReturn

import numpy as np
import pandas as pd
import yaml
from numpy.typing import NDArray
from tqdm import tqdm

from predisat import __version__
from predisat.atomic import exclusive_folder, staged_folder
from predisat.availability.engine import (
    Availability,
    BlockCheckpoint,
    compute_availability,
    longest_run,
)
from predisat.availability.interval import (
    DEFAULT_MAP_DOUBT,
    INDEPENDENT_PAIRS,
    MapDoubt,
    width_text,
)
from predisat.availability.satellites import (
    DEFAULT_NAV_FILE,
    SYSTEM_NAMES,
    LinePositions,
    SatellitePositions,
    TrustRule,
    default_ephemeris,
    default_window,
    select_satellites,
    system_letters,
)
from predisat.clock import pinned_utc, utc_stamp
from predisat.codeversion import code_fingerprint
from predisat.geodesy import enu_rotation, enu_to_azel, geodetic_to_ecef
from predisat.gnss.ephemeris import Ephemeris, Reason
from predisat.gnss.errormodel import IntervalModel
from predisat.gnss.integrity import DEFAULT_BUDGET, IntegrityBudget
from predisat.gnss.timescale import datetime64_to_gps_s, utc_datetime64_to_gps_s
from predisat.gnss.timescale import gps_s_to_text as _iso
from predisat.jsontypes import JsonDict
from predisat.masks.antenna import check_antenna_height, masks_antenna_height_m
from predisat.masks.fileformat import (
    MaskFileWarning,
    mask_file_path,
    read_masks,
    unfinished_run_error,
)
from predisat.masks.gaps import close_gaps
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.merge import merged_tracks_note
from predisat.masks.registration import beside_track_notes, register_on_track
from predisat.scheduler import Scheduler, TaskRunner
from predisat.storage import (
    Location,
    StorageOptions,
    absolute,
    exists,
    input_path,
    is_remote,
    join,
    location,
    name_of,
    remove,
    remove_tree,
    write_atomic,
)
from predisat.track import TrackMap, TrackMapError, load_track

__all__ = [
    "AvailabilityRun",
    "assumed_sky_notes",
    "attitude_text",
    "far_field_text",
    "lacking_side_notes",
    "lens_notes",
    "load_navigation",
    "nav_span_gps_s",
    "navigation_doubts",
    "navigation_holes",
    "open_sky_in_tunnels_notes",
    "parse_time",
    "positioning_text",
    "rig_text",
    "run_availability",
    "sampling_notes",
    "side_swap_notes",
    "sparse_navigation",
    "step_notes",
    "survey_check_notes",
    "synthetic_notes",
]

_DEFAULT_WINDOW_S = 86400.0


@dataclass(frozen=True)
class AvailabilityRun:
    """What :func:`run_availability` wrote and computed.

    Attributes
    ----------
    out_dir : Path or str
        A local folder or a URL (:mod:`predisat.storage`).
    report_html : Path or str
    files : dict of str to Path or str
        Every file written, by kind (``"report"``, ``"summary_csv"``, ``"positions_parquet"``,
        ``"geojson"``, ...).
    summary : pandas.DataFrame
        One row per rule (line-wide figures).
    results : tuple of Availability
        One per rule, masks first.
    elapsed_s : float
    """

    out_dir: Location
    report_html: Location
    files: dict[str, Location]
    summary: pd.DataFrame
    results: tuple[Availability, ...]
    elapsed_s: float = 0.0
    info: JsonDict = field(default_factory=dict)


# ------------------------------------------------------------------------- inputs
# an ISO time of day followed by a UTC offset: "T08:00+02:00", "T08:00:30.5-0100"
_UTC_OFFSET = re.compile(r"T\d{2}:\d{2}(:\d{2}(\.\d+)?)?[+-]\d{2}(:?\d{2})?$")


def parse_time(value: float | str | np.datetime64 | datetime | None, name: str) -> float | None:
    """``gps_s`` of a time given as ``gps_s`` (number), ISO 8601 text or a datetime.

    Text such as ``"2020-06-25T06:00"`` is GPS time (as every time in PREDISAT; UTC is 18 s
    behind since 2017); with a ``Z`` or ``UTC`` suffix (``"2020-06-25T06:00Z"``) it is UTC and
    the leap seconds are added; with an offset (``"2020-06-25T08:00+02:00"``, local time) it
    is that UTC instant. A bare number (also as text) is ``gps_s``. Timezone-aware
    datetimes are UTC instants, naive ones and ``numpy.datetime64`` GPS time. ``None`` stays
    ``None``.
    """
    if value is None:
        return None
    if isinstance(value, (int, float, np.floating, np.integer)):
        out = float(value)
    elif isinstance(value, str):
        text = value.strip()
        try:
            out = float(text)
        except ValueError:
            if _UTC_OFFSET.search(text.replace(" ", "T")):
                # an explicit offset (local time, +02:00, +02): an instant in UTC, not GPS time
                iso = text.replace(" ", "T")
                if re.search(r"[+-]\d{2}$", iso):
                    iso += ":00"
                return parse_time(datetime.fromisoformat(iso), name)
            utc = text.upper().endswith(("Z", "UTC"))
            if utc:
                text = text[: -1 if text.upper().endswith("Z") else -3]
            text = text.strip().replace(" ", "T")
            try:
                with warnings.catch_warnings():  # numpy's notice on zones: the error says it
                    warnings.simplefilter("ignore")
                    t = np.datetime64(text, "ns")
            except ValueError:
                raise ValueError(
                    f"{name} {value!r} is not a time: give GPS time as 2020-06-25T06:00, UTC "
                    "as 2020-06-25T06:00Z, local time with its offset as 2020-06-25T08:00+02:00, "
                    "or gps_s seconds (zone names such as CEST are not read)"
                ) from None
            out = float(utc_datetime64_to_gps_s(t) if utc else datetime64_to_gps_s(t))
    elif isinstance(value, datetime):
        if value.tzinfo is not None:
            naive = value.astimezone(UTC).replace(tzinfo=None)
            out = float(utc_datetime64_to_gps_s(np.datetime64(naive, "ns")))
        else:
            out = float(datetime64_to_gps_s(np.datetime64(value, "ns")))
    else:
        out = float(datetime64_to_gps_s(np.asarray(value, "datetime64[ns]")))
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return out


def _nav_kind(path: Path) -> str:
    """``"sp3"``, ``"tle"`` or ``"rinex"`` from a file's first lines."""
    opener = gzip.open if path.suffix.lower() == ".gz" else open
    try:
        with opener(path, "rt", encoding="ascii", errors="replace") as fh:
            head = [fh.readline() for _ in range(40)]
    except OSError as exc:
        raise ValueError(f"nav file {path} (--nav): cannot be read ({exc})") from None
    first = head[0]
    if first[:2] in ("#a", "#b", "#c", "#d"):
        return "sp3"
    if "RINEX VERSION" in "".join(head[:3]):
        return "rinex"
    lines = [ln for ln in head if ln.strip() and not ln.startswith("#")]
    if any(ln.startswith("1 ") for ln in lines) and any(ln.startswith("2 ") for ln in lines):
        return "tle"
    raise ValueError(
        f"nav file {path} (--nav): not a RINEX navigation, SP3 or TLE file (first line "
        f"{first.strip()!r}); "
        "give broadcast RINEX (*.rnx, *.YYn/g/l), precise SP3 or two-line elements"
    )


def load_navigation(paths: Sequence[str | Path] | None) -> Ephemeris:
    """An :class:`~predisat.gnss.ephemeris.Ephemeris` from navigation files (kind told by content).

    ``None`` or empty: the embedded navigation day (:func:`~predisat.availability.satellites.
    default_ephemeris`). Several RINEX or several SP3 files are merged; kinds cannot be mixed
    and only one TLE file is read.
    """
    if not paths:
        return default_ephemeris()
    files = [Path(p) for p in paths]
    for p in files:
        if not p.is_file():
            raise FileNotFoundError(
                f"nav file {p} (--nav): no such file; give RINEX navigation, SP3 or TLE files, "
                "or none (leave --nav out) to use the embedded navigation day (2020-06-25)"
            )
    kinds = {p: _nav_kind(p) for p in files}
    found = sorted(set(kinds.values()))
    if len(found) > 1:
        raise ValueError(
            "nav (--nav) mixes kinds of navigation data ("
            + ", ".join(f"{p.name}: {k}" for p, k in kinds.items())
            + "); give only RINEX, only SP3 or one TLE file"
        )
    if found[0] == "sp3":
        return Ephemeris.from_sp3(files)
    if found[0] == "tle":
        if len(files) > 1:
            raise ValueError("nav (--nav): give a single TLE file (several were given)")
        return Ephemeris.from_tle(files[0])
    return Ephemeris.from_rinex(files)


def nav_span_gps_s(
    ephemeris: Ephemeris, systems: Collection[str] | None = None
) -> tuple[float, float]:
    """Time span the navigation data covers, ``(first, last)`` in ``gps_s``.

    Broadcast: the first and last reference epoch (toe, tb) of any record; with ``systems``
    (RINEX letters such as ``{"G", "E"}``) the span every one of them held covers (a Galileo
    file's records of the day before must not start a GPS report's window, nor a report
    counting both). SP3: the first and last tabulated epoch; TLE: the element-set epochs
    widened by the validity age.
    """
    if ephemeris.kind == "sp3" and ephemeris.sp3 is not None:
        ep = ephemeris.sp3.epochs_gps_s
        return float(ep[0]), float(ep[-1])
    if ephemeris.kind == "tle" and ephemeris.tle is not None:
        ep = ephemeris.tle.epochs_gps_s
        age = ephemeris.policy.tle_max_age_s
        return float(np.min(ep) - age), float(np.max(ep) + age)
    recs = [r for r in (ephemeris.kepler, ephemeris.glonass) if r is not None and len(r)]
    if not recs:
        raise ValueError(f"navigation data {list(ephemeris.sources)} holds no record")
    ref = np.concatenate([r.ref_gps_s for r in recs])
    letter = np.concatenate([[str(s)[:1].upper() for s in r.sat] for r in recs])
    spans = [(float(ref[letter == s].min()), float(ref[letter == s].max()))
             for s in sorted(set(systems or ())) if (letter == s).any()]  # fmt: skip
    if not spans:
        return float(np.min(ref)), float(np.max(ref))
    # the span every counted system covers: a report counting GPS and Galileo from a window
    # where one has no records yet would count the other alone
    lo, hi = max(a for a, _ in spans), min(b for _, b in spans)
    return (lo, hi) if lo < hi else (min(a for a, _ in spans), max(b for _, b in spans))


def _window(
    ephemeris: Ephemeris,
    embedded: bool,
    start: float | None,
    end: float | None,
    step_s: float,
    systems: Collection[str] | None = None,
) -> NDArray:
    if not (math.isfinite(step_s) and step_s > 0):
        raise ValueError(
            f"step_s (--step) must be a positive number of seconds, got {step_s}"
        )
    if start is None:
        start = _default_start(ephemeris, embedded, systems)
    if end is None:
        hi = nav_span_gps_s(ephemeris, systems)[1]
        if ephemeris.kind == "sp3":  # precise orbits are interpolated, never extrapolated
            last_s = hi + 1e-3
        else:  # broadcast records stay valid about an hour after the last reference epoch
            extra = 3600.0 if ephemeris.kind == "broadcast" else 0.0
            last_s = math.ceil((hi + extra) / 3600.0) * 3600.0
        end = min(start + _DEFAULT_WINDOW_S, max(last_s, start + step_s))
    if end <= start:
        raise ValueError(
            f"end ({_iso(end)}, --end) must be after start ({_iso(start)}, --start); give a "
            "later end"
        )
    t = np.arange(start, end, step_s)
    if len(t) > 20000:
        raise ValueError(
            f"the window {_iso(start)} - {_iso(end)} at {step_s:g} s has {len(t)} epochs "
            "(more than 20 000); use a larger step_s (--step) or a shorter window"
        )
    return t


def _default_start(
    ephemeris: Ephemeris, embedded: bool, systems: Collection[str] | None = None
) -> float:
    """Start of the default window: the embedded day, else the data's first (whole) hour (of
    the counted ``systems``' records)."""
    if embedded:
        return float(default_window(3600.0)[0])
    if ephemeris.kind == "tle" and ephemeris.tle is not None:
        # element sets are valid for days: the day of the median set's epoch
        return math.floor(float(np.median(ephemeris.tle.epochs_gps_s)) / 86400.0) * 86400.0
    lo, _ = nav_span_gps_s(ephemeris, systems)
    if ephemeris.kind == "sp3":
        return math.ceil(lo / 3600.0) * 3600.0
    # a daily broadcast file starts with records of about 00:00 (some from the previous day)
    return round(lo / 3600.0) * 3600.0


def _check_window(sats: SatellitePositions, ephemeris: Ephemeris, nav_label: str) -> None:
    """Fail when the window is (partly) outside the navigation data: no satellite at all."""
    ok = sats.valid.any(axis=1)
    if ok.all():
        return
    reason = sats.status.reason[~ok]
    if (reason == Reason.UNCHECKED).any() and not (reason == Reason.OK).any():
        raise ValueError(
            f"{nav_label}: at {int((~ok).sum())} of {ok.size} epochs every satellite's record "
            "in force is its only one within a day, which nothing can cross-check (a corrupted "
            "record, as G01's of 2010-07-01, puts a satellite thousands of kilometres from the "
            "real one), so none is counted: give the day's full broadcast navigation file (e.g. "
            "IGS BRDC00IGS_R_YYYYDDD0000_01D_MN.rnx) rather than an hour of a receiver's"
        )
    lo, hi = nav_span_gps_s(ephemeris)
    t = sats.gps_s
    bad = np.flatnonzero(~ok)
    what = "the window lies" if len(bad) == len(t) else (
        f"{len(bad)} of {len(t)} epochs ({_iso(t[bad[0]])} - {_iso(t[bad[-1]])}) "
        + ("lies" if len(bad) == 1 else "lie")
    )  # fmt: skip
    counted = {x[0] for x in sats.sats}
    each = [(SYSTEM_NAMES.get(k, k), a, b) for k, (a, b) in
            sorted(_system_spans(ephemeris).items()) if k in counted]  # fmt: skip
    if len(each) > 1 and max(a for _, a, _ in each) > min(b for _, _, b in each):
        raise ValueError(
            f"{what} without any trusted satellite in the navigation data {nav_label}, whose "
            "systems' records cover different times ("
            + "; ".join(f"{n} {_iso(a)} - {_iso(b)} GPST" for n, a, b in each)
            + "): give navigation files of the same days, or a window (--start/--end) and "
            "constellation (--constellation) that one of them covers"
        )
    inside = (t[bad] > lo) & (t[bad] < hi)
    if inside.any():  # not the data's ends: a hole in them
        g = t[bad][inside]
        raise ValueError(
            f"{what} in a gap of the navigation data {nav_label}: no trusted satellite "
            f"{_iso(g[0])} - {_iso(g[-1])} GPST, inside the data's span {_iso(lo)} - {_iso(hi)} "
            "(precise orbits are interpolated from samples on both sides, so an SP3 gap costs "
            "about an hour more at each end); give navigation data without the gap, or a "
            "window (--start/--end) beside it"
        )
    raise ValueError(
        f"{what} outside the navigation data {nav_label} (no trusted satellite; the data "
        f"span {_iso(lo)} - {_iso(hi)} GPST); choose start/end (--start/--end) inside it "
        "or give navigation files (--nav) covering the window"
    )


# Satellites of a constellation in full service (GPS's 24-slot baseline of the SPS performance
# standard, GLONASS's 24 slots less spares in maintenance, Galileo and BeiDou-3 MEO in 2020):
# navigation data with fewer usually is a partial file, and every figure is then understated.
_FULL_CONSTELLATION = {"G": 24, "R": 22, "E": 22, "C": 24}
# ... from when, and what a whole file held before: GLONASS had 16-20 in service until its 24
# again in late 2011, Galileo 12 or more from its initial services (12-2016) to its full MEO
# (2020), BeiDou-2 10 or more from its regional service (12-2012) to BeiDou-3 (2020)
_EARLIER = {
    "R": (("1990-01-01", 16), ("2011-12-01", 22)),
    "E": (("2016-12-15", 12), ("2020-01-01", 22)),
    "C": (("2012-12-27", 10), ("2020-07-31", 24)),
}


def _full_count(system: str, gps_s: float) -> int:
    """Satellites a whole file of ``system`` held at ``gps_s`` (0: no rule then)."""
    steps = _EARLIER.get(system)
    if steps is None:
        return _FULL_CONSTELLATION[system]
    full = 0
    for since, n in steps:
        if gps_s >= float(datetime64_to_gps_s(np.datetime64(since, "ns"))):
            full = n
    return full


def sparse_navigation(sats: SatellitePositions, nav_label: str) -> list[str]:
    """Warnings for constellations with fewer satellites in the navigation data than a full
    one.

    A satellite counts when it has a usable record in the window, or records out of their
    validity there: a station's file lacks records while its satellites are below the
    station's horizon, which is no gap in a short window (:func:`station_file_gaps` says
    whether such satellites stand above the line; a user trial: an hour's report said
    "every count is understated" of 10 satellites all below the horizon).

    Parameters
    ----------
    sats : SatellitePositions
        The satellites of the run (``valid`` and ``status.reason`` of shape (n_epoch, n_sat)).
    nav_label : str
        How the warning names the navigation data.

    Returns
    -------
    list of str
        One sentence per sparse constellation (empty when none is).
    """
    held = np.asarray(sats.valid.any(axis=0), bool)
    held |= (np.asarray(sats.status.reason, int) == int(Reason.OUTSIDE_VALIDITY)).any(axis=0)
    used = [s for j, s in enumerate(sats.sats) if held[j]]
    out = []
    t0 = float(sats.gps_s[0]) if len(sats.gps_s) else math.inf
    for system in _FULL_CONSTELLATION:
        n = sum(s[0] == system for s in used)
        full = _full_count(system, t0)
        if 0 < n < full:
            out.append(
                f"{nav_label} holds {n} {SYSTEM_NAMES[system]} satellites with records "
                f"(a full constellation has {full} or more): every count, share and interval is "
                "understated; give the day's full broadcast navigation file (e.g. IGS "
                "BRDC00IGS_R_YYYYDDD0000_01D_MN.rnx)"
            )
    return out


_NAV_HOLE_S = 3600.0  # a satellite without usable records this long inside the window


def navigation_doubts(sats: SatellitePositions, ephemeris: Ephemeris, nav_label: str) -> list[str]:
    """Warnings for what the navigation data leave unsaid in the window: records nothing can
    cross-check, a counted system without any usable satellite, a window reaching past a
    system's records (user trials: a phantom satellite from an hour's file; figures of GPS
    alone labelled GPS + GLONASS; a window past the day's file with 4 satellites of 12, all
    without a word).

    Parameters
    ----------
    sats : SatellitePositions
        The satellites of the run.
    ephemeris : Ephemeris
        Their source.
    nav_label : str
        How the warnings name the navigation data.

    Returns
    -------
    list of str
        One sentence per case (empty when none).
    """
    out = []
    t, valid = sats.gps_s, np.asarray(sats.valid, bool)
    reason = np.asarray(sats.status.reason)
    unchecked = [s for j, s in enumerate(sats.sats) if (reason[:, j] == Reason.UNCHECKED).any()]
    if unchecked and valid.any():
        names = ", ".join(unchecked[:10]) + (f" and {len(unchecked) - 10} more"
                                             if len(unchecked) > 10 else "")  # fmt: skip
        out.append(
            f"{nav_label}: the records of {len(unchecked)} satellite(s) ({names}) are their only "
            "ones within a day, which nothing can cross-check (a corrupted record, as G01's of "
            "2010-07-01, puts a satellite thousands of kilometres from the real one): they are "
            "not counted while those records are in force, which understates the shares; give "
            "the day's full broadcast navigation file (e.g. IGS "
            "BRDC00IGS_R_YYYYDDD0000_01D_MN.rnx)"
        )
    if t.size == 0:
        return out
    spans = _system_spans(ephemeris)
    sat_spans = _system_spans(ephemeris, per_satellite=True)
    for system in sorted({s[0] for s in sats.sats}):
        cols = [j for j, s in enumerate(sats.sats) if s[0] == system]
        name = SYSTEM_NAMES.get(system, system)
        span = spans.get(system)
        held = f" (its records: {_iso(span[0])} - {_iso(span[1])} GPST)" if span else ""
        if not valid[:, cols].any():
            out.append(
                f"{nav_label} holds no usable {name} satellite anywhere in the window"
                f"{held}: every count is of the other systems only, though {name} is asked; "
                f"give {name} navigation data of the window's days"
            )
            continue
        if span is None or ephemeris.kind != "broadcast" or system in ("J", "I"):
            continue
        for beyond, edge, way, after in (
            (t[-1] - span[1], span[1], "after the last", True),
            (span[0] - t[0], span[0], "before the first", False),
        ):
            # said only where satellites do drop out there: records stay valid up to 2 h
            # beyond their reference epoch (a user trial's day from 00:00 with records from
            # 02:00 was warned of, every satellite counted). Each satellite past its own
            # records, out or not elsewhere in the window: one satellite's next-day record
            # moves the system's span, and the others, out all through a window past their
            # own, went uncounted and unsaid (a review)
            dropped = 0
            for j in cols:
                own = sat_spans.get(str(sats.sats[j]).upper())
                if own is None:
                    continue
                past = t > own[1] if after else t < own[0]
                dropped += bool((reason[past, j] == Reason.OUTSIDE_VALIDITY).any())
            if beyond > 0 and dropped:
                out.append(
                    f"the window reaches {beyond / 3600.0:.1f} h {way} {name} records of "
                    f"{nav_label} ({_iso(edge)} GPST): {dropped} of its satellites drop out "
                    "there as the records in force age beyond their validity, which "
                    "understates the shares; give the navigation file of the adjacent day "
                    "too, or a window inside the records (--start/--end)"
                )
    return out


def _system_spans(
    ephemeris: Ephemeris, per_satellite: bool = False
) -> dict[str, tuple[float, float]]:
    """First and last reference epoch of each system's broadcast records (empty for SP3 and
    TLE), ``gps_s``; of each satellite's with ``per_satellite``."""
    out: dict[str, tuple[float, float]] = {}
    for rec in (ephemeris.kepler, ephemeris.glonass):
        if rec is None or not len(rec):
            continue
        letter = np.array([str(x).upper() if per_satellite else str(x)[:1].upper()
                           for x in rec.sat])  # fmt: skip
        for system in np.unique(letter).tolist():
            ref = rec.ref_gps_s[letter == system]
            out[system] = (float(ref.min()), float(ref.max()))
    return out


STATION_GAP_SHARE = 0.05
"""Share of the satellite-epochs above 10 deg at the line without a usable record beyond
which :func:`station_file_gaps` warns."""


def station_file_gaps(
    ephemeris: Ephemeris,
    sats: SatellitePositions,
    lat_deg: float,
    lon_deg: float,
    h_m: float,
    nav_label: str,
) -> list[str]:
    """A warning when broadcast records are missing while their satellites stand above the
    line: a station's navigation file holds the records of the satellites it tracked, so one
    far from the line lacks many the line sees (a user trial: a Japanese station's file on
    line 144 gave 3.3 satellites above 10 deg with a record where a merged file gave 7.0, and
    the share of time with 6 or more fell from 100 % to 37 %, with no warning).

    The satellites whose records exist but are not valid at an epoch are placed by their
    nearest record, extrapolated up to a day and a half (hundreds of metres to kilometres off:
    enough for an elevation); those above 10 deg at ``(lat_deg, lon_deg, h_m)`` are counted
    against all the satellite-epochs above 10 deg there.

    Returns
    -------
    list of str
        One sentence when more than :data:`STATION_GAP_SHARE` of them have no usable record,
        else empty.
    """
    if ephemeris.kind != "broadcast" or not ephemeris.sources:
        return []
    lost = np.asarray(sats.status.reason, int) == int(Reason.OUTSIDE_VALIDITY)
    if not lost.any():
        return []
    relaxed = replace(ephemeris.policy, max_age_s={k: 1.5 * 86400.0 for k in
                                                   ephemeris.policy.max_age_s},
                      use_fit_interval=False, consistency_m=None, trust_unchecked=True)  # fmt: skip
    rough = Ephemeris.from_rinex(ephemeris.sources, relaxed)
    pos = np.array(sats.pos_ecef_m, float)
    cols = [j for j, s in enumerate(sats.sats) if lost[:, j].any()]
    guess, _, _ = rough.evaluate(sats.gps_s, [sats.sats[j] for j in cols])
    for n, j in enumerate(cols):
        pos[lost[:, j], j] = guess[lost[:, j], n]
    x = geodetic_to_ecef(lat_deg, lon_deg, h_m)
    enu = (pos - x) @ enu_rotation(lat_deg, lon_deg).T
    _, el, _ = enu_to_azel(enu)
    up = np.nan_to_num(el, nan=-90.0) > 10.0
    valid = np.asarray(sats.valid, bool)
    missing = up & lost
    seen = up & (valid | lost)
    if not seen.any() or missing.sum() <= STATION_GAP_SHARE * seen.sum():
        return []
    share = float(missing.sum() / seen.sum())
    return [
        f"{nav_label} has no usable record for {100 * share:.0f} % of the satellite-epochs "
        "above 10 deg at the line (their satellites placed by their nearest record): a "
        "station's file holds the satellites that station tracked, and this one's are not "
        "the line's; the counts understate; give a merged broadcast file of the day (IGS "
        "BRDC / BRDM) or one of a station near the line"
    ]


def navigation_holes(sats: SatellitePositions, nav_label: str, kind: str) -> list[str]:
    """Warnings for parts of the window the navigation data leaves uncovered: a constellation
    with no usable satellite over some epochs (the window starts before its records), and
    precise orbits without a satellite for an hour or more of the window (a user trial:
    an SP3 file with 5 satellites zeroed for 13 h, and a window where GPS and BeiDou had no
    records in the first hour, said only in the folded files section).

    Parameters
    ----------
    sats : SatellitePositions
        The satellites of the run (``valid`` of shape (n_epoch, n_sat)).
    nav_label : str
        How the warning names the navigation data.
    kind : str
        The navigation data's kind (``Ephemeris.kind``): a satellite's hole is looked for in
        precise orbits (``"sp3"``) only, which tabulate every satellite all day; a station's
        broadcast file holds the records of the satellites it saw, so each one's time below
        its horizon is a hole, of no consequence.

    Returns
    -------
    list of str
        One sentence per case (empty when the data cover the window).
    """
    t, valid = sats.gps_s, np.asarray(sats.valid, bool)

    if t.size < 2:
        return []
    out = []
    # regional systems (QZSS, NavIC) are out of sight of most lines for hours: not a hole
    for system in sorted({s[0] for s in sats.sats} - {"J", "I"}):
        cols = [j for j, s in enumerate(sats.sats) if s[0] == system]
        none = ~valid[:, cols].any(axis=1)
        if none.sum() >= 2 and not none.all():
            edges = np.diff(np.concatenate([[0], none.astype(np.int8), [0]]))
            a, b = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
            runs = "; ".join(f"{_iso(t[i])} - {_iso(t[j])}" for i, j in zip(a[:3], b[:3],
                                                                             strict=True))
            more = f" and {a.size - 3} more" if a.size > 3 else ""
            out.append(
                f"{nav_label} holds no usable {SYSTEM_NAMES.get(system, system)} satellite in "
                f"{int(none.sum())} of {t.size} epochs ({runs}{more} GPST): the counts there "
                "are of the other systems only; choose a window inside every system's data "
                "(--start/--end)"
            )
    half = 0.5 * float(np.median(np.diff(t)))
    # precise orbits tabulate every satellite all day: any gap of one seen in the window is
    # a hole (one never tabulated there is of another constellation)
    longest = longest_run((~valid).T, t - half, t + half)
    seen = valid.any(axis=0) & (longest >= _NAV_HOLE_S)
    holed = [(s, float(d)) for s, d, k in zip(sats.sats, longest, seen, strict=True)
             if k and kind == "sp3"]  # fmt: skip
    if holed:
        names = ", ".join(f"{s} ({d / 3600.0:.1f} h)" for s, d in holed[:8])
        more = f" and {len(holed) - 8} more" if len(holed) > 8 else ""
        out.append(
            f"{nav_label} has no usable record of {len(holed)} satellite(s) for an hour or more "
            f"inside the window: {names}{more}; they are not counted then, which understates "
            "the shares; give complete navigation data"
        )
    return out


def _load_masks(
    masks: str | Path | MaskSet, opts: StorageOptions | None = None
) -> tuple[MaskSet, str, list[str]]:
    """The masks, how to name them, and what reading them warned of (holes closed)."""
    if isinstance(masks, MaskSet):
        # a set built in memory (concat_masksets of two surveys) gets its holes closed as a
        # file's are on reading
        closed, holes = close_gaps(masks)
        notes = [
            f"masks in memory: {len(holes)} hole(s) between positions ("
            + ", ".join(f"{a:.0f}-{b:.0f} m" for a, b in holes[:5])
            + "): closed with positions that trust nothing"
        ] if holes else []  # fmt: skip
        return closed, "in memory", notes
    loc = location(masks)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MaskFileWarning)
        if not is_remote(loc):
            mask_set, label = read_masks(masks), str(mask_file_path(masks))
        else:
            # a URL: a mask file (.parquet), else the output folder of `predisat process`
            if not name_of(loc).endswith(".parquet"):
                folder, loc = loc, join(loc, "masks.parquet")
                if exists(loc, opts) and not exists(join(folder, "provenance.json"), opts):
                    raise unfinished_run_error(folder)
            with input_path(loc, opts) as local_file:
                mask_set, label = read_masks(local_file), str(loc)
    notes = []
    for w in caught:
        if issubclass(w.category, MaskFileWarning):
            notes.append(str(w.message))
        else:  # not ours to report: shown as it would have been
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return mask_set, label, notes


def _load_track(track: TrackMap | str | os.PathLike[str] | None) -> TrackMap | None:
    if track is None or isinstance(track, TrackMap):
        return track
    try:
        return load_track(track)
    except TrackMapError as exc:
        raise TrackMapError(f"track (--track): {exc}") from None


def _sky_chainages(
    masks: MaskSet, track: TrackMap | None, sky_km: Sequence[float] | None, n_sky: int
) -> NDArray:
    lo, hi = float(masks.chainage_m[0]), float(masks.chainage_m[-1])
    if sky_km is None or len(sky_km) == 0:
        if n_sky < 1:
            return np.zeros(0)
        frac = (np.arange(n_sky) + 0.5) / n_sky
        want = lo + frac * (hi - lo)
        return masks.chainage_m[masks.position_index(want)[0]]
    km_m = np.asarray(sky_km, float) * 1000.0
    if track is not None and track.kilometre_posts:
        grid = np.linspace(lo, hi, 2001)
        line_km = track.kilometre_at(grid)
        if np.all(np.diff(line_km) > 0):
            ch = np.interp(km_m, line_km, grid, left=np.nan, right=np.nan)
        elif np.all(np.diff(line_km) < 0):
            ch = np.interp(km_m, line_km[::-1], grid[::-1], left=np.nan, right=np.nan)
        else:
            ch = np.full(km_m.shape, np.nan)
        span = f"km {line_km.min() / 1000:.3f} - {line_km.max() / 1000:.3f}"
    else:
        ch = np.where((km_m >= lo) & (km_m <= hi), km_m, np.nan)
        span = f"chainage {lo / 1000:.3f} - {hi / 1000:.3f} km (the track has no kilometre posts)"
    if np.isnan(ch).any():
        bad = [k for k, c in zip(sky_km, ch, strict=True) if np.isnan(c)]
        raise ValueError(
            f"sky_km (--sky-km) {bad} outside the masks' stretch ({span}); give kilometres "
            "inside it"
        )
    return masks.chainage_m[masks.position_index(ch)[0]]


# ------------------------------------------------------------------------- run
def run_availability(
    masks: str | Path | MaskSet,
    track: TrackMap | str | os.PathLike[str] | None = None,
    nav: Sequence[str | Path] | None = None,
    *,
    out_dir: str | Path,
    start: float | str | None = None,
    end: float | str | None = None,
    step_s: float = 30.0,
    constellation: str = "gps",
    cutoff_deg: float | Sequence[float] = 15.0,
    from_m: float | None = None,
    to_m: float | None = None,
    sky_km: Sequence[float] | None = None,
    n_sky: int = 4,
    interval_every: int = 10,
    interval_model: IntervalModel | None = None,
    integrity: IntegrityBudget | None = DEFAULT_BUDGET,
    map_doubt: MapDoubt | None = DEFAULT_MAP_DOUBT,
    workers: int | None = None,
    scheduler: Scheduler | str | None = None,
    counts_table: bool = False,
    progress: bool = True,
    basemap: str | Path | None = None,
    storage_options: StorageOptions | None = None,
    notes: Sequence[str] = (),
    masks_same_track: bool = False,
    antenna_height_m: float | None = None,
) -> AvailabilityRun:
    """Availability of trusted satellites along a surveyed line: report, tables, GIS layer.

    Parameters
    ----------
    masks : path, str or MaskSet
        Mask file v1 (``*.masks.parquet``), the output folder of ``predisat process``
        (local or an fsspec URL), or a mask set.
    track : TrackMap or path, optional
        The track map the masks were made on (checked: mask positions within 25 m of it at
        their chainage). Supplies the line's name, kilometre posts and the GeoJSON geometry;
        without it segments are straight between positions.
    nav : sequence of paths, optional
        RINEX navigation, SP3 or one TLE file; default the embedded day (2020-06-25).
    out_dir : path or str
        Output folder (created): a local folder or a writable fsspec URL. Its ``blocks/``
        keeps the finished blocks while the run lasts: rerunning a killed run with the same
        inputs and folder resumes it.
    start, end : float or str, optional
        Window: ``gps_s``, or ISO text in GPS time (UTC with a ``Z`` suffix, see
        :func:`parse_time`); end excluded. Default: from the start of the data's
        first hour, 24 h or to the end of the data.
    step_s : float
        Epoch spacing, seconds.
    constellation : str
        ``"gps"`` (default, as the LOCOPROL figures), ``"gps+galileo"``, ``"all"`` or letters.
    cutoff_deg : float or sequence of float
        Flat cut-off(s) compared with the masks.
    from_m, to_m : float, optional
        Chainage stretch (default: the whole mask set).
    sky_km : sequence of float, optional
        Line kilometres (kilometre-post reference) of the sky plots; default ``n_sky`` places
        evenly along the stretch.
    n_sky : int
        Number of sky plots when ``sky_km`` is not given.
    interval_every : int
        Predict the interval at every n-th epoch (the costly part).
    interval_model : IntervalModel, optional
        Pseudorange error model and pair half width of the predicted intervals (for example
        from ``locator calibrate``, read with
        :func:`predisat.gnss.errormodel.read_error_model`); default
        ``IntervalModel()`` (``a = b = 2 m``; its ``k = 2`` is used only with
        ``integrity=None``).
    integrity : IntegrityBudget or None
        The integrity risk per epoch the predicted intervals are drawn for: each interval
        mode's ``k`` follows from it (:func:`predisat.availability.interval.mode_k_sigma`) and
        ``interval_model.k_sigma`` is not used; the report names it. Default
        :data:`predisat.gnss.integrity.DEFAULT_BUDGET` (1e-12 per epoch, as
        ``predisat availability --integrity-risk``); None: ``interval_model.k_sigma`` in every
        mode (``--k-sigma``).
    map_doubt : MapDoubt or None
        How far the antenna may be from the track map: each predicted pair is widened as
        ``locator run`` widens the pairs it solves (:class:`predisat.availability.interval.
        MapDoubt`); the report names it. Default ``MapDoubt()`` (1.5 m beside, 1 m above or
        below: the locator's default, ``--map-doubt``); None or zero: the source's pairs.
    workers : int, optional
        Threads of the availability engine in this process (default 1), or the worker
        processes of a local Dask cluster with ``scheduler="local"`` (default: the cores).
    scheduler : predisat.scheduler.Scheduler or str, optional
        Where the blocks of positions run: ``"serial"`` (this process, the default),
        ``"local"`` (a local Dask cluster) or a Dask scheduler's address. The results are the
        same bits wherever they run.
    counts_table : bool
        Also write ``counts.parquet`` with every count.
    progress : bool
        Show a tqdm progress bar.
    basemap : path, optional
        A GeoJSON of lines drawn under the map as an offline background (for example an
        OpenStreetMap extract of the railways and roads around the line).
    storage_options : mapping, optional
        Options of the fsspec file system of URL masks and outputs (credentials...).
    notes : sequence of str
        Warnings of the caller's own (the error model's, for example) that the report and
        ``summary.json`` carry with the run's.
    masks_same_track : bool
        ``track`` is a map of the physical track the masks were surveyed on: masks lying
        beside it as another track's would are registered, not refused
        (:func:`predisat.masks.registration.register_on_track`).

    antenna_height_m : float, optional
        The train antenna's height above the track axis: masks made for an antenna more than
        0.2 m higher are refused, a lower one is said (:mod:`predisat.masks.antenna`). None:
        not checked.
    Returns
    -------
    AvailabilityRun

    Raises
    ------
    FileNotFoundError
        Missing mask, track or navigation file (named).
    ValueError
        Window outside the navigation data, masks not on the track, bad options.
    """
    # lazy: the report's figures need matplotlib, which the module's other users do not
    from predisat.availability.report import (
        ReportInputs,
        basemap_from_geojson,
        build_report,
        write_tables,
    )

    t0 = time.perf_counter()
    cutoffs = (cutoff_deg,) if isinstance(cutoff_deg, (int, float)) else tuple(cutoff_deg)
    stages = 2 + (2 + len(cutoffs)) + 3  # masks, navigation; one per rule; tables, figures, report
    bar = tqdm(total=stages, desc="availability", unit="step", disable=not progress)
    held = contextlib.ExitStack()
    try:
        stage = bar.set_postfix_str

        stage("masks")
        opts = dict(storage_options or {})
        out = location(absolute(out_dir))  # a cluster's worker resolves a relative path in
        # its own working folder
        mask_set, masks_label, track, mask_notes = _masks_on_track(
            masks, track, from_m, to_m, opts, masks_same_track, antenna_height_m
        )
        sky_ch = _sky_chainages(mask_set, track, sky_km, n_sky)
        if interval_every < 1:
            raise ValueError(f"interval_every must be >= 1, got {interval_every}")
        model = IntervalModel() if interval_model is None else interval_model
        background = () if basemap is None else basemap_from_geojson(basemap)
        bar.update(1)

        stage("navigation")
        nav_data = _navigation(nav, start, end, step_s, constellation)
        positions = LinePositions.from_masks(mask_set)
        mask_notes += navigation_holes(nav_data.sats, nav_data.label, nav_data.ephemeris.kind)
        mid = len(mask_set.chainage_m) // 2
        mask_notes += station_file_gaps(
            nav_data.ephemeris, nav_data.sats, float(mask_set.lat_deg[mid]),
            float(mask_set.lon_deg[mid]), float(mask_set.h_m[mid]), nav_data.label,
        )  # fmt: skip
        bar.update(1)

        rules = [TrustRule.mask(mask_set), TrustRule.none()]
        rules += [TrustRule.cutoff(c) for c in cutoffs]
        # the block tasks read and write no file (this process saves them): no paths
        runner = held.enter_context(
            TaskRunner(_where(scheduler, workers), code_version=code_fingerprint)
        )
        # the cluster reached and checked before the folder is made: a mistyped --scheduler
        # address left an empty output folder holding a lock file
        runner.client()
        if isinstance(out, Path):  # one run writes a local folder at a time, from its blocks
            out.mkdir(parents=True, exist_ok=True)  # on (its inputs were checked: no folder
            held.enter_context(exclusive_folder(out))  # is made for a refused run)
        blocks = join(out, "blocks")
        try:
            results = _compute_rules(
                rules, nav_data.sats, positions, interval_every, model, integrity, runner, bar,
                (blocks, opts), map_doubt,
            )  # fmt: skip
        finally:
            runner.close()  # the cluster is not needed for the tables and figures

        stage("tables")
        # every output is written in a staging folder first, then published (_publish): in
        # place, a full disk or a size limit left cut tables that read as whole, or two runs'
        # files side by side (a user trial)
        staging = (
            staged_folder(out, last=("report.html",), remove=_OUTPUT_NAMES, lock=False)
            if isinstance(out, Path)
            else contextlib.nullcontext(Path(tempfile.mkdtemp(prefix="predisat-av-")))
        )  # fmt: skip
        with staging as work:
            work.mkdir(parents=True, exist_ok=True)
            sampling = sampling_notes(nav_data.sats.gps_s.size, step_s, interval_every)
            info = _run_info(
                mask_set, masks_label, track, nav_data, constellation, rules, step_s,
                interval_every, __version__, model, integrity,
                [*mask_notes, *notes, *sampling], antenna_height_m, map_doubt,
            )  # fmt: skip
            local_files, summary = write_tables(work, results, track, info, counts_table)
            local_files["ephemeris_status_csv"] = _write_ephemeris_status(work, nav_data.sats)
            bar.update(1)

            stage("figures")
            inputs = ReportInputs(
                results=tuple(results), masks=mask_set, satellites=nav_data.sats, track=track,
                info=info, sky_chainage_m=tuple(float(c) for c in sky_ch),
                files=dict(local_files), basemap_lonlat=background,
            )  # fmt: skip
            html = build_report(inputs)
            bar.update(1)

            stage("report")
            (work / "report.html").write_text(html, encoding="utf-8")
            local_files["report"] = work / "report.html"
            files = _publish(local_files, out, opts)
        remove_tree(blocks, opts)  # every output is written: the saved blocks are done with
        bar.update(1)
    finally:
        held.close()
        bar.close()  # also on an error: its message then starts on a line of its own
    return AvailabilityRun(
        out, files["report"], files, summary, tuple(results), time.perf_counter() - t0, info
    )


# every output a run may write: an earlier run's that this one does not write (its --counts
# table) must not stay beside the new report (a review)
_OUTPUT_NAMES = (
    "report.html", "summary.csv", "summary.json", "positions.csv", "positions.parquet",
    "epochs.csv", "epochs.parquet", "counts.parquet", "availability.geojson",
    "ephemeris_status.csv",
)  # fmt: skip


def _publish(
    local_files: dict[str, Path], out: Location, opts: StorageOptions
) -> dict[str, Location]:
    """The outputs where they belong: for a local ``out``, their names there (the staging
    folder's files are moved there when it closes), else each uploaded to ``out``
    (:func:`predisat.storage.write_atomic`) and the local copies deleted."""
    if isinstance(out, Path):  # staged_folder moves them there
        return {kind: out / path.name for kind, path in local_files.items()}
    published: dict[str, Location] = {}
    folders = set()
    # the report withdrawn first and uploaded last: a failure between left new tables beside
    # the previous run's whole report (a review)
    report = local_files.get("report")
    if report is not None:
        remove(join(out, report.name), opts)
    for kind, path in sorted(local_files.items(), key=lambda kv: kv[0] == "report"):
        published[kind] = join(out, path.name)
        write_atomic(published[kind], path.read_bytes(), opts)
        folders.add(path.parent)
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)
    return published


def _masks_on_track(
    masks: str | Path | MaskSet,
    track: TrackMap | str | os.PathLike[str] | None,
    from_m: float | None,
    to_m: float | None,
    opts: StorageOptions | None = None,
    same_track: bool = False,
    antenna_height_m: float | None = None,
) -> tuple[MaskSet, str, TrackMap | None, list[str]]:
    """The masks of the stretch (checked to lie on ``track``), how to name them, the track, and
    the warnings for the report (holes closed, a stretch asked beyond the masks)."""
    mask_set, masks_label, notes = _load_masks(masks, opts)
    track_map = _load_track(track)
    if track_map is None:
        track_map = _embedded_track_of(mask_set, masks_label)
        made_on = str(mask_set.provenance.get("track", ""))
        if track_map is None and made_on:
            notes.append(
                f"masks {masks_label} say they were made on track {made_on!r}, but no map of it "
                "was given (--track) or they do not lie on the embedded one: places are named "
                "by the masks' own chainages, without kilometre posts; give --track"
            )
    if track_map is not None:
        # chainages are the track's from here on: --from-km / --to-km are too
        reg = register_on_track(mask_set, track_map, masks_label, same_track=same_track)
        if not reg.same_map:
            notes.append(reg.describe(masks_label, track_map.name))
        mask_set = reg.masks
    merged = merged_tracks_note(mask_set, masks_label)
    if merged is not None:
        notes.append(merged)
    if antenna_height_m is not None:
        note = check_antenna_height(mask_set, antenna_height_m, f"masks {masks_label}")
        if note is not None:
            notes.append(note)
    notes += _stretch_beyond(mask_set, masks_label, from_m, to_m)
    mask_set = _stretch(mask_set, masks_label, from_m, to_m)
    if mask_set.n_pos < 2:
        asked = from_m is not None or to_m is not None
        where = "in the stretch asked (--from-km/--to-km)" if asked else ""
        raise ValueError(
            f"masks {masks_label} hold one position (chainage {mask_set.chainage_m[0]:.1f} m) "
            f"{where}: a report covers a stretch; give masks of at least two positions, or a "
            "longer stretch"
        )
    if track_map is not None:
        notes += open_sky_in_tunnels_notes(mask_set, track_map, masks_label)
    return mask_set, masks_label, track_map, notes


_TUNNEL_PORTAL_M = 100.0  # a 6.5 m vault this far in leaves under 4 deg along the track


def open_sky_in_tunnels_notes(
    mask_set: MaskSet, track: TrackMap, masks_label: str
) -> list[str]:
    """A warning where the masks trust some sky at positions the map tags as tunnel, farther
    than :data:`_TUNNEL_PORTAL_M` from its portals (a user trial gave flat masks over 13 km of
    tunnels and read 100 % availability, unwarned). Near a portal the sky along the track is
    truly open, and a map's portals are metres off."""
    tunnels = getattr(track, "tunnels_m", ())
    if not tunnels:
        return []
    ch = mask_set.chainage_m
    inside = np.zeros(ch.shape, bool)
    for a, b in tunnels:
        inside |= (ch >= a + _TUNNEL_PORTAL_M) & (ch <= b - _TUNNEL_PORTAL_M)
    open_ = inside & (mask_set.effective_mask_deg < 90.0).any(axis=1)
    if not open_.any():
        return []
    return [
        f"masks {masks_label} trust some sky at {int(open_.sum())} of {int(inside.sum())} "
        f"positions that track {track.name!r} tags as tunnel, over {_TUNNEL_PORTAL_M:.0f} m "
        f"from a portal (chainage "
        f"{ch[open_][0] / 1000:.3f} - {ch[open_][-1] / 1000:.3f} km): the masks or the map are "
        "wrong there; check the survey of those stretches before trusting these figures"
    ]


def _stretch_beyond(
    mask_set: MaskSet, masks_label: str, from_m: float | None, to_m: float | None
) -> list[str]:
    """A warning when the stretch asked reaches beyond the masks' coverage: the report then
    covers less than was asked, and its shares are of that part only."""
    b = mask_set.cell_bounds_m
    out = []
    for name, v, beyond in (("--from-km", from_m, from_m is not None and from_m < b[0]),
                            ("--to-km", to_m, to_m is not None and to_m > b[-1])):  # fmt: skip
        if beyond and v is not None:
            out.append(
                f"{name} {v / 1000:g} (chainage km) lies beyond masks {masks_label}, which cover "
                f"chainage {b[0] / 1000:.3f} - {b[-1] / 1000:.3f} km: the report covers only the "
                "surveyed part, and its shares are of that part; survey the rest to report it"
            )
    return out


def _embedded_track_of(mask_set: MaskSet, masks_label: str) -> TrackMap | None:
    """The embedded line 144 map when the masks say they were made on it and lie on it (its
    kilometre posts then label the report, as with ``--track``); otherwise None."""
    from predisat.track.map import demo_track

    made_on = str(mask_set.provenance.get("track", ""))
    demo = demo_track()
    if made_on != demo.name:
        return None
    try:
        same = register_on_track(mask_set, demo, masks_label).same_map
    except ValueError:
        same = False
    return demo if same else None  # named like it, but another map: the masks' own positions


def _stretch(
    mask_set: MaskSet, masks_label: str, from_m: float | None, to_m: float | None
) -> MaskSet:
    """The masks of the chainage stretch ``[from_m, to_m]`` (all when neither is given)."""
    if from_m is None and to_m is None:
        return mask_set
    lo_m = -np.inf if from_m is None else from_m
    hi_m = np.inf if to_m is None else to_m
    ch_m = mask_set.chainage_m
    if not ((ch_m >= lo_m) & (ch_m <= hi_m)).any():
        given = " ".join(
            f"{name} {v:g} m ({flag} {v / 1000:g})"
            for name, flag, v in (("from_m", "--from-km", from_m), ("to_m", "--to-km", to_m))
            if v is not None
        )
        raise ValueError(
            f"{given}: no position of masks {masks_label}, which cover "
            f"{ch_m.min() / 1000:g}-{ch_m.max() / 1000:g} km (values are kilometres); "
            "choose a stretch inside"
        )
    return mask_set.subset(lo_m, hi_m)


@dataclass(frozen=True)
class _Navigation:
    """The navigation data of a run and the satellites it gives over the window."""

    ephemeris: Ephemeris
    label: str  # how messages name the navigation data
    sats: SatellitePositions
    warnings: list[str]


def _navigation(
    nav: Sequence[str | Path] | None,
    start: float | str | None,
    end: float | str | None,
    step_s: float,
    constellation: str,
) -> _Navigation:
    """Load the navigation data, build the window and the satellites' positions over it."""
    ephemeris = load_navigation(nav)
    names = ", ".join(Path(p).name for p in nav) if nav else ""
    nav_label = names or f"embedded {DEFAULT_NAV_FILE}"
    t0_gps, t1_gps = parse_time(start, "start (--start)"), parse_time(end, "end (--end)")
    t = _window(ephemeris, not nav, t0_gps, t1_gps, step_s, system_letters(constellation))
    if not select_satellites(ephemeris.satellites, constellation):
        raise ValueError(
            f"no satellite of constellation {constellation!r} in {nav_label}; choose another "
            "constellation (--constellation) or give navigation data for it"
        )
    sats = SatellitePositions.from_ephemeris(ephemeris, t, constellation)
    _check_window(sats, ephemeris, nav_label)
    warnings = sparse_navigation(sats, nav_label) + navigation_doubts(sats, ephemeris, nav_label)
    asked = system_letters(constellation)
    absent = sorted(asked - {s[0] for s in sats.sats}) if len(asked) > 1 else []
    if absent:
        names = ", ".join(SYSTEM_NAMES.get(c, c) for c in absent)
        warnings.append(
            f"--constellation {constellation} asks for {names}, of which {nav_label} holds no "
            "satellite: the counts are of the others only; give navigation data of "
            f"{names} to count them"
        )
    if ephemeris.kind in ("sp3", "tle"):
        warnings.append(
            f"{nav_label} ({ephemeris.kind}) carries no health flags: satellites the broadcast "
            "navigation message declares unhealthy, which a receiver rejects, are counted here, "
            "so the shares may be optimistic; give the day's broadcast navigation file to apply "
            "them"
        )
    return _Navigation(ephemeris, nav_label, sats, warnings)


def _compute_rules(
    rules: Sequence[TrustRule],
    sats: SatellitePositions,
    positions: LinePositions,
    interval_every: int,
    model: IntervalModel,
    integrity: IntegrityBudget | None,
    runner: TaskRunner,
    bar: tqdm[NoReturn],
    blocks: tuple[Location, StorageOptions],
    map_doubt: MapDoubt | None,
) -> list[Availability]:
    """The availability under every rule, in order; one step of ``bar`` each. Each rule's
    finished blocks are saved in its own folder under ``blocks`` (a folder and its storage
    options), where a rerun finds them."""
    results = []
    folder, opts = blocks
    for rule in rules:
        bar.set_postfix_str(rule.label)
        results.append(
            compute_availability(
                sats,
                positions,
                rule,
                interval_every=interval_every,
                interval_model=model,
                integrity=integrity,
                map_doubt=map_doubt,
                runner=runner,
                progress=not bar.disable,
                checkpoint=BlockCheckpoint(join(folder, _slug(rule.label)), opts),
            )
        )
        bar.update(1)
    return results


def _where(scheduler: Scheduler | str | None, workers: int | None) -> Scheduler:
    """The run's scheduler: serial with ``workers`` threads when none is named."""
    if isinstance(scheduler, Scheduler):
        return scheduler
    if scheduler is None:
        return Scheduler.serial(1 if workers is None else workers)
    return Scheduler.parse(scheduler, workers)


def _slug(label: str) -> str:
    """A rule's folder name: ``"cutoff 15 deg"`` -> ``"cutoff_15_deg"``."""
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in label.lower())


def _write_ephemeris_status(out: Path, sats: SatellitePositions) -> Path:
    """Write ``ephemeris_status.csv`` into ``out``; returns its path.

    Every run of epochs in which the ephemeris did not trust a satellite (unhealthy, outside
    its validity window, inconsistent, no data): such satellites count for no rule.
    """
    path = out / "ephemeris_status.csv"
    status = sats.status.report()
    status.to_csv(path, index=False, float_format="%.12g")
    return path


def _antenna_text(masks: MaskSet, antenna_height_m: float | None) -> str:
    """Which antenna the masks are for, and whether the train's was checked against it (a
    user trial: the report's figures named no antenna, and none was checked by default)."""
    h = masks_antenna_height_m(masks)
    if h is None:
        train = ("" if antenna_height_m is None
                 else f", taken as made for the train's ({antenna_height_m:g} m)")  # fmt: skip
        return f"the masks state no antenna height{train}: nothing could be checked"
    made = f"masks made for an antenna {h:g} m above the track axis"
    if antenna_height_m is None:
        return (f"{made}; the train's antenna not checked against them (give --antenna-height: "
                "masks made for a higher antenna are refused)")  # fmt: skip
    return f"{made}; the train's, {antenna_height_m:g} m, checked against them"


def _run_info(
    masks: MaskSet, masks_label: str, track: TrackMap | None, nav: _Navigation,
    constellation: str, rules: Sequence[TrustRule], step_s: float, interval_every: int,
    version: str, model: IntervalModel, integrity: IntegrityBudget | None = None,
    notes: Sequence[str] = (), antenna_height_m: float | None = None,
    map_doubt: MapDoubt | None = None,
) -> JsonDict:  # fmt: skip
    ephemeris, nav_label, sats = nav.ephemeris, nav.label, nav.sats
    systems = sorted({s[0] for s in sats.sats})
    line = track.name if track is not None else str(masks.provenance.get("track", "line"))
    chain = (
        f"chainage {masks.chainage_m[0] / 1000:.3f} - {masks.chainage_m[-1] / 1000:.3f} km"
    )
    km = (
        track.kilometre_at(masks.chainage_m[[0, -1]])
        if track is not None and track.kilometre_posts
        else None
    )
    stretch = (
        f"km {km[0] / 1000:.3f} - {km[1] / 1000:.3f} ({chain})"
        if km is not None and np.all(np.isfinite(km))
        else f"{chain} (the track has no kilometre posts)"
    )
    return {
        "line": line,
        "track": _track_text(track),
        "track_source": "" if track is None else track.source,
        "stretch": f"{stretch}, {masks.n_pos} positions",
        "window": f"{_iso(sats.gps_s[0])} - {_iso(sats.gps_s[-1] + step_s)} GPST, every "
        f"{step_s:g} s ({len(sats.gps_s)} epoch{'s' if len(sats.gps_s) != 1 else ''})",
        "synthetic": synthetic_notes(masks.provenance),
        "window_gps_s": [float(sats.gps_s[0]), float(sats.gps_s[-1] + step_s)],
        "navigation": f"{nav_label} ({ephemeris.kind})",
        "constellation": f"{constellation}: "
        + ", ".join(SYSTEM_NAMES[s] for s in systems)
        + f" ({len(sats.sats)} satellites)",
        "rules": [r.label for r in rules],
        "masks": masks_label,
        "rig": rig_text(masks.provenance),
        "attitude": attitude_text(masks.provenance),
        "positioning": positioning_text(masks.provenance),
        "far_field": far_field_text(masks),
        "antenna": _antenna_text(masks, antenna_height_m),
        "mask_provenance": dict(masks.provenance),
        "mask_margin_deg": [float(masks.margin_deg.min()), float(masks.margin_deg.max())],
        "interval_every": interval_every,
        "interval_model": (
            f"sigma(el)² = {model.error.a_m:.3f}² + ({model.error.b_m:.3f} / sin el)² m² "
            f"(elevations below {model.error.min_el_deg:g}° as {model.error.min_el_deg:g}°), "
            f"pair intervals ± k sigma"
        ),
        "interval_width": width_text(model.k_sigma if integrity is None else integrity) + ", "
        + (map_doubt or MapDoubt(0.0, 0.0)).describe(),
        "interval_model_params": {
            "a_m": model.error.a_m, "b_m": model.error.b_m,
            "min_el_deg": model.error.min_el_deg,
            "k_sigma": model.k_sigma if integrity is None else None,
            "integrity_risk_per_epoch": None if integrity is None else integrity.risk_per_epoch,
            "k_sigma_by_mode": None if integrity is None else {
                m.name: integrity.k_sigma(n) for m, n in INDEPENDENT_PAIRS.items()
            },
            "map_doubt_lateral_m": 0.0 if map_doubt is None else map_doubt.lateral_m,
            "map_doubt_vertical_m": 0.0 if map_doubt is None else map_doubt.vertical_m,
        },
        "software": f"predisat {version}",
        "created_utc": utc_stamp(pinned_utc()),
        "track_attribution": _track_credit(track),
        "interval_model_is_default": model.error == IntervalModel().error,
        "nav_is_embedded": nav_label.startswith("embedded"),
        "warnings": [*notes, *nav.warnings, *survey_check_notes(masks.provenance),
                     *assumed_sky_notes(masks)],
    }


def far_field_text(masks: MaskSet) -> str:
    """What the masks' far field rests on where no camera saw it: the elevation tiles they were
    raised to, or the assumed default, with the share of bins each holds (a user trial found
    no word of it in the report of a valley). Read from the bins' flags, the provenance naming
    the tiles and the default: a file whose flags and provenance disagree is said to."""
    src = masks.source
    assumed = src == BinSource.ASSUMED
    closed = assumed & (masks.effective_mask_deg >= 90.0)
    share = f"{100.0 * float(assumed.mean()):.1f} % of the bins assumed"
    if assumed.any():
        share += (f": {100.0 * float(closed.mean()):.1f} % closed to the zenith, "
                  f"{100.0 * float((assumed & ~closed).mean()):.1f} % open")  # fmt: skip
    raised = 100.0 * float((src == BinSource.TERRAIN).mean())
    terrain = masks.provenance.get("terrain")
    if isinstance(terrain, dict):
        if raised == 0.0:
            return (f"elevation tiles {terrain.get('dem', '?')} given, but no bin rests on them "
                    f"(do they cover the line?); {share}")  # fmt: skip
        return (f"raised to the elevation tiles {terrain.get('dem', '?')} in {raised:.1f} % of "
                f"the bins; {share}")  # fmt: skip
    if raised > 0.0:
        return (f"{raised:.1f} % of the bins flagged TERRAIN, but the masks do not name the "
                f"elevation tiles; {share}")  # fmt: skip
    params = masks.provenance.get("params")
    rec = params.get("reconstruction") if isinstance(params, dict) else None
    if not isinstance(rec, dict) or "far_default_deg" not in rec:
        return share if assumed.any() else ""  # true masks, older files: no default to name
    return (f"assumed at {float(rec['far_default_deg']):g}° where no camera saw it "
            f"({share}); no elevation tiles given")  # fmt: skip


_COARSE_STEP_S = 600.0  # a satellite's elevation changes by up to about 5 deg in 10 min
_FEW_EPOCHS = 30


def sampling_notes(n_epoch: int, step_s: float, interval_every: int) -> list[str]:
    """Warnings when the shares or the interval lengths rest on few instants (a user trial read
    one epoch as "51.2 % of the time", and a 1 h step turned a 15° cut-off's 95.8 % with 6 or
    more satellites into 100 %)."""
    out = []
    if n_epoch < _FEW_EPOCHS or step_s > _COARSE_STEP_S:
        out.append(
            f"{n_epoch} epoch{'s' if n_epoch != 1 else ''} {step_s:g} s apart: the shares of "
            "time are of these instants only, and satellites rise and set between them; for "
            f"figures to quote use --step 30-60 over a day (at most {_COARSE_STEP_S:g} s, at "
            f"least {_FEW_EPOCHS} epochs)"
        )
    n_interval = -(-n_epoch // max(interval_every, 1))
    if n_interval < _FEW_EPOCHS:
        out.append(
            f"the interval lengths rest on {n_interval} epochs (--interval-every "
            f"{interval_every}): their median and 95th percentile are rough; lower "
            "--interval-every"
        )
    return out


_ASSUMED_OPEN_WARN = 0.05  # share of the trusting bins that rests on an assumption


def assumed_sky_notes(masks: MaskSet) -> list[str]:
    """A warning when much of the sky the masks trust rests on an assumption: ASSUMED bins
    below 90° over more than 5 % of the bins below 90° (a user trial flagged every bin ASSUMED
    and got the surveyed file's figures, said in one header row)."""
    open_ = masks.effective_mask_deg < 90.0
    if not open_.any():
        return []
    share = float((open_ & (masks.source == BinSource.ASSUMED)).sum() / open_.sum())
    if share <= _ASSUMED_OPEN_WARN:
        return []
    return [
        f"{100.0 * share:.1f} % of the directions these masks leave open rest on an assumption "
        "(ASSUMED bins: nothing was seen there, the value is a stated default): every satellite "
        "trusted there is trusted on that assumption; give elevation tiles (--dem) or survey "
        "those stretches with a cab or 360 rig"
    ]


def survey_check_notes(provenance: JsonDict) -> list[str]:
    """The survey checks' warnings (:func:`side_swap_notes`, :func:`step_notes`,
    :func:`lacking_side_notes`) of the masks, and of every mask set ``predisat merge`` merged
    into them (their provenance under ``merged_worst_case``), each named."""
    out = [*side_swap_notes(provenance), *step_notes(provenance), *lens_notes(provenance),
           *lacking_side_notes(provenance), *beside_track_notes(provenance)]  # fmt: skip
    merged = provenance.get("merged_worst_case")
    for t in merged if isinstance(merged, list) else []:
        prov = t.get("provenance") if isinstance(t, dict) else None
        if isinstance(prov, dict):
            out += [f"merged masks {t.get('masks', '?')}: {n}" for n in survey_check_notes(prov)]
    return out


def side_swap_notes(provenance: JsonDict) -> list[str]:
    """The report's warnings for side cameras whose frames slid the other way from their
    mount's when the masks were made (``predisat process``'s ``side_check``; section 19 of
    docs/reconstruction.md)."""
    check = provenance.get("side_check")
    if not isinstance(check, dict):
        return []
    return [
        f"the masks were made from a survey whose {side} camera's frames slid the other way "
        f"from its mount's in {v.get('disagree')} of {v.get('agree', 0) + v.get('disagree', 0)} "
        "frame pairs: left and right are probably swapped, and such masks trusted 5.7-8 % of "
        "a survey's directions falsely; do not rely on them before the survey is checked"
        for side, v in sorted(check.items())
        if isinstance(v, dict) and v.get("swapped")
    ]


def lacking_side_notes(provenance: JsonDict) -> list[str]:
    """The report's warning for mask positions that lacked a side camera's own frame when the
    masks were made (``predisat process``'s ``positions_lacking_side``; section 23 of
    docs/reconstruction.md): they trust little or no sky."""
    lacking = provenance.get("positions_lacking_side")
    if not isinstance(lacking, list) or not lacking:
        return []
    return [
        f"the masks were made from a survey that lacked a side camera's own frame at "
        f"{len(lacking)} position(s) (from chainage {min(lacking):.0f} to {max(lacking):.0f} "
        "m): the clearance over the track was taken as blocked there, so those positions "
        "trust little or no sky; restore the frames (bad_frames.csv) or the manifest's rows, "
        "or trigger the side cameras together, and process the survey again"
    ]


def step_notes(provenance: JsonDict) -> list[str]:
    """The report's warnings for cameras found out of step with their manifest rows when the
    masks were made (``predisat process``'s ``capture_check`` and ``step_check``; sections
    21-22 of docs/reconstruction.md)."""
    check = provenance.get("step_check")
    capture = provenance.get("capture_check")
    out = []
    if isinstance(capture, dict):
        for side, v in sorted(capture.items()):
            for r in v.get("off", []) if isinstance(v, dict) else []:
                out.append(
                    f"the masks were made from a survey whose {side} camera's images from "
                    f"chainage {r.get('from_chainage_m')} to {r.get('to_chainage_m')} m carry "
                    "other rows' capture times (images rows off in the manifest); they were "
                    "set aside, so the masks there rest on other frames or on assumptions: fix "
                    "the survey's manifest and process it again"
                )
    if not isinstance(check, dict):
        return out
    timed = isinstance(capture, dict) and bool(capture) and all(
        isinstance(v, dict) and v.get("checked") for v in capture.values()
    )
    if not timed and not any(isinstance(v, dict) and v.get("compared") for v in check.values()):
        out.append("the masks' survey cameras could not be checked for images out of step with "
                   "their manifest rows (no two cameras share the sky above the track, and the "
                   "images carry no usable capture times): a dropped image there would have "
                   "gone unseen")  # fmt: skip
    for pair, v in sorted(check.items()):
        for r in v.get("off_step", []) if isinstance(v, dict) else []:
            out.append(
                f"the masks were made from a survey whose {pair.replace('/', ' and ')} cameras "
                f"were out of step from chainage {r.get('from_chainage_m')} to "
                f"{r.get('to_chainage_m')} m (one camera's images rows off in the manifest); "
                "their frames there were set aside, so the masks there rest on other frames or "
                "on assumptions: fix the survey's manifest and process it again"
            )
    return out


def lens_notes(provenance: JsonDict) -> list[str]:
    """The report's warnings for stretches whose sun or horizon was not where the camera's
    calibration puts them when the masks were made (``predisat process``'s ``lens_check``;
    section 19 of docs/reconstruction.md)."""
    check = provenance.get("lens_check")
    return [
        f"the masks were made from a survey whose {side} camera saw the sun or the horizon "
        f"off its calibration's place from chainage {r.get('from_chainage_m')} to "
        f"{r.get('to_chainage_m')} m (another camera or lens there, or a moved mount); those "
        "frames were set aside, so the masks there rest on other frames or on assumptions: "
        "split the survey at the change, give each part its own calibration and process them "
        "again"
        for side, v in (sorted(check.items()) if isinstance(check, dict) else [])
        for r in (v.get("off_stretches", []) if isinstance(v, dict) else [])
    ]


def _track_text(track: TrackMap | None) -> str:
    """The track's name (with the part chosen in a file of several) and its length."""
    if track is None:
        return "none given: the masks' own positions"
    return f"{track.name} ({track.length_m / 1000:.2f} km)"


def rig_text(provenance: JsonDict) -> str:
    """The survey rig that made the masks, from their provenance (``rig``, written by
    ``predisat process``): ``"left: fisheye 640x480 px, yaw 90 deg, pitch 45 deg; right: ..."``;
    "" when the masks do not say (true masks, older files)."""
    rig = provenance.get("rig")
    if not isinstance(rig, dict) or not rig:
        return ""
    return "; ".join(f"{side}: {what}" for side, what in rig.items())


def attitude_text(provenance: JsonDict) -> str:
    """How the survey vehicle's roll and pitch were known when the masks were made (the
    provenance's ``attitude``, written by ``predisat process``; docs/reconstruction.md,
    section 16); "" when the masks do not say."""
    att = provenance.get("attitude")
    if not isinstance(att, dict) or "frames" not in att:
        return ""
    n, measured = int(att["frames"]), int(att.get("measured_frames", 0))
    bad = int(att.get("contradicted_frames", 0))
    table = " and the cant table" if "cant_table_frames" in att else ""
    if measured == n:
        return f"measured (the manifest's IMU attitude) for all {n} frames"
    text = (
        f"bounded from the track's curves and grade{table} for {n - measured} of {n} frames "
        f"(their sky eroded by up to {float(att.get('max_doubt_deg', 0.0)):.1f}°"
        + (f", their cameras placed within {float(att['max_camera_doubt_m']):.2f} m"
           if "max_camera_doubt_m" in att else "")
        + f"), measured for {measured}"
    )  # fmt: skip
    return text + (f"; {bad} frames' measured roll contradicted the track" if bad else "")


def positioning_text(provenance: JsonDict) -> str:
    """How well the survey's chainages were known when the masks were made (``predisat
    process``'s resolved ``chainage_doubt_m`` and ``chainage_jitter_m``; docs/reconstruction.md
    section 18); "" for masks that do not say."""
    params = provenance.get("params")
    if not isinstance(params, dict) or params.get("chainage_doubt_m") is None:
        return ""
    doubt = float(params["chainage_doubt_m"])
    if doubt == 0.0:
        return "chainages taken as exact (the survey stated no doubt, or 0)"
    raw = params.get("chainage_jitter_m")
    jitter = doubt if raw is None else float(raw)
    return f"each frame's chainage within {doubt:g} m" + (
        f", within {jitter:g} m of the others' (bounded as a shift of the survey)"
        if jitter < doubt else " (each frame bounded on its own)"
    )


def synthetic_notes(provenance: JsonDict) -> list[str]:
    """Sentences for the report's banner when masks come from synthetic data.

    Recognised from the mask provenance: a survey made by ``predisat synth``
    (``survey_generator``, ``survey_description``, or the ``generator`` in the ``survey.yaml``
    of the ``survey`` folder when it still exists) and masks stated as a simulated or
    synthetic world's truth (``source``).

    Parameters
    ----------
    provenance : dict
        ``MaskSet.provenance``.

    Returns
    -------
    list of str
        Empty for masks from a real survey.
    """
    generator = str(provenance.get("survey_generator", ""))
    description = str(provenance.get("survey_description", ""))
    survey = provenance.get("survey")
    if not generator and isinstance(survey, str) and survey:
        yaml_path = Path(survey) / "survey.yaml"
        if yaml_path.is_file():
            try:
                doc = yaml.safe_load(yaml_path.read_text(encoding="utf-8")) or {}
            except (OSError, yaml.YAMLError):
                doc = {}
            if isinstance(doc, dict):
                generator = str(doc.get("generator", ""))
                description = description or str(doc.get("description", ""))
    source = str(provenance.get("source", "")).lower()
    if generator.startswith("predisat.synth") or "synthetic" in description.lower():
        return [
            "The masks were made from a synthetic survey (frames rendered from a procedural "
            f"world by {generator or 'predisat synth'}: {description or 'synthetic survey'}) "
            "laid on the real track. The obstructions (tunnels, cuttings, bridges, trees, "
            "buildings) are invented; the track geometry and the satellites (navigation "
            "data) are real. Do not read these figures as the line's real availability."
        ]
    if "simulated" in source or "synthetic" in source:
        return [
            f"The masks are the ground truth of a synthetic world ({provenance.get('source')}):"
            " the obstructions are invented; the track and the satellites are real."
        ]
    return []


def _track_credit(track: TrackMap | None) -> str:
    """The track named in the report's footer: its name, source and required attribution."""
    if track is None:
        return "none given (masks' own positions)"
    parts = [p for p in (track.name, track.source) if p]
    credit = ", ".join(dict.fromkeys(parts))  # a file named after its track says it once
    return f"{credit}. {track.attribution}" if track.attribution else credit


# ------------------------------------------------------------------------- command line
