"""The ``predisat process`` batch pipeline: survey folder -> mask file, chunked and resumable.

:func:`process_survey` turns a survey folder (``docs/survey-format.md``) into a mask file
(``docs/mask-format.md``) in two stages (``docs/pipeline.md``):

1. **Segmentation** of every frame a pending chunk needs (:func:`predisat.sky.segment.
   segment_sky` by default), each result cached on disk under ``out/cache/`` (packed sky mask
   plus per-column confidence), so overlapping chunks and resumed runs never segment a frame
   twice. A frame whose image is missing, truncated, corrupt inside, undecodable, blank (all
   black, all white), frozen (the same file as the camera's frame before), of the wrong size
   or fails to segment is a *bad frame*: reported with its manifest line, listed in
   ``bad_frames.csv`` and skipped (``strict=True`` stops at the first instead). Frames the
   survey loader rejects (times and positions that contradict the run) are bad frames too.
2. **Reconstruction** (:class:`predisat.reconstruct.carving.Reconstructor`) per chainage chunk
   ``[k * chunk_m, (k + 1) * chunk_m)`` from the frames within
   :attr:`~predisat.reconstruct.carving.ReconstructionParams.overlap_m` of it. Each finished chunk
   is
   written atomically as ``out/chunks/<lo>_<hi>.parquet`` (a mask file) and then
   ``<lo>_<hi>.json`` (its provenance, the completion marker). On start, a chunk whose JSON
   carries the same run key (survey hash, parameters, software version) and frames key (its
   images' sizes and modification times) is skipped: an interrupted run resumes without
   redoing finished chunks, and a replaced image redoes the chunks that read it.

At the end the chunks are merged into ``out/masks.parquet`` with the run's provenance
(``out/provenance.json`` too). Positions are the survey's distinct antenna chainages.

The parts live in their own modules: :mod:`~predisat.reconstruct.params` (settings),
:mod:`~predisat.reconstruct.frames` (reading and segmenting a frame),
:mod:`~predisat.reconstruct.framecache` (the cache and the fingerprints),
:mod:`~predisat.reconstruct.chunks` (one chunk), :mod:`~predisat.reconstruct.executor` (the
tasks, run by :mod:`predisat.scheduler` in this process or on a Dask cluster),
:mod:`~predisat.reconstruct.badframes`; the merge's gap closing is
:func:`predisat.masks.gaps.close_gaps`. The command line is :mod:`predisat.cli.process`.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import itertools
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import ParamSpec, TypeVar

import numpy as np
from numpy.typing import NDArray

from predisat import __version__
from predisat.atomic import LOCK_NAME, exclusive_folder
from predisat.camera.models import CameraModel, Mount
from predisat.clock import pinned_utc, utc_stamp
from predisat.gnss.sun import sun_azel, sun_direction_enu
from predisat.jsontypes import JsonDict
from predisat.masks.fileformat import MaskFileWarning, read_masks, write_masks
from predisat.masks.gaps import close_gaps
from predisat.masks.margins import MarginTable
from predisat.masks.maskset import BinSource, MaskSet, concat_masksets
from predisat.masks.registration import (
    OTHER_TRACK_OFFSET_M,
    beside_track_notes,
    first_stretch_aside,
)
from predisat.masks.terrain import bin_terrain, coverage_notes, raise_to_terrain
from predisat.reconstruct.attitude import (
    CANT_DEFICIENCY_TOL_MM,
    CANT_ON_SHARP_MM,
    CANT_TABLE_FLOOR_MM,
    STRAIGHT_PER_M,
    frame_attitudes,
    survey_speed_kmh,
)
from predisat.reconstruct.badframes import BadFrame, BadFrameError, write_bad_frames
from predisat.reconstruct.carving import lacking_side, side_cameras
from predisat.reconstruct.chunks import (
    ChunkFrame,
    ChunkJob,
    chunk_finished,
    chunk_name,
    load_cached,
)
from predisat.reconstruct.executor import run_chunks, run_segmentation
from predisat.reconstruct.framecache import (
    SEGMENTATION_CODE,
    FrameJob,
    code_fingerprint,
    frames_key,
    read_cache,
    stat_key,
    survey_hash,
)
from predisat.reconstruct.frames import Segmenter, default_segmenter, read_image
from predisat.reconstruct.params import THIN_DEG, PipelineParams
from predisat.reconstruct.sides import (
    expected_flow_sign,
    moving_on,
    pair_votes,
    side_votes,
    sky_profile,
    stretches_the_other_way,
)
from predisat.reconstruct.step import (
    MAX_LAG,
    MIN_OVERLAP_DIRECTIONS,
    comparable,
    lag_disagreement,
    off_step,
    overlap_pixels,
    step_lags,
    widen,
)
from predisat.reconstruct.stops import stop_counts, stop_ids
from predisat.reconstruct.sunsight import (
    HORIZON_TOLERANCE_DEG,
    SUN_TOLERANCE_DEG,
    horizon_residual,
    locate_sun,
    lowest_sky_deg,
    off_stretches,
    sun_in_image,
)
from predisat.scheduler import Scheduler, TaskRunner
from predisat.sky.segment import METHODS
from predisat.storage import (
    Location,
    StorageOptions,
    absolute,
    exists,
    input_path,
    is_remote,
    join,
    list_names,
    location,
    makedirs,
    output_path,
    read_bytes,
    remove,
    stamps,
    write_atomic,
)
from predisat.survey import Survey, check_survey_track
from predisat.survey.capture import MAX_LAG as CAPTURE_MAX_LAG
from predisat.survey.capture import (
    MIN_FIT_SHARE,
    MIN_TIMED_FRAMES,
    check_rows,
    fit_clock,
    read_capture_time_s,
)
from predisat.survey.format import Frames
from predisat.survey.images import decode_thumbnail
from predisat.survey.load import check_calibration_sizes
from predisat.terrain import Dem
from predisat.track.map import TrackMap
from predisat.track.network import track_key

__all__ = [
    "ASSUMED_STRETCH_M",
    "PAIR_FOCAL_TOL",
    "OutputInUseError",
    "ProcessResult",
    "RunStopped",
    "camera_pair_warnings",
    "finished_chunk_jobs",
    "process_survey",
    "source_report",
]

_CHAINAGE_DECIMALS = 3  # positions closer than 1 mm are one position
# a camera counts as checked by its capture times when this share of its frames could be
# told from the rows beside them (the rest: fast stretches, coarse stamps)
_MIN_CHECKED_SHARE = 0.95


@dataclass(frozen=True)
class ProcessResult:
    """What :func:`process_survey` did.

    Attributes
    ----------
    out_dir, masks_path : Path or str
        Local paths, or URLs (:mod:`predisat.storage`).
    masks : MaskSet
        The merged masks (as written to ``masks_path``).
    n_frames : int
        Frames in the survey (valid at load).
    chunks_done, chunks_skipped : int
        Chunks computed in this run / found finished from an earlier run.
    frames_segmented : int
        Frames segmented in this run (the others came from the cache).
    bad_frames : tuple of BadFrame
    elapsed_s : float
    timings_s : dict of str to float
        Wall time per stage (``"load"``, ``"segment"``, ``"reconstruct"``, ``"merge"``).
    """

    out_dir: Location
    masks_path: Location
    masks: MaskSet
    n_frames: int
    chunks_done: int
    chunks_skipped: int
    frames_segmented: int
    bad_frames: tuple[BadFrame, ...]
    elapsed_s: float
    timings_s: dict[str, float] = field(default_factory=dict)

    def __str__(self) -> str:
        return (
            f"{self.masks.n_pos} positions from {self.n_frames} frames -> {self.masks_path} "
            f"({self.chunks_done} chunks computed, {self.chunks_skipped} resumed, "
            f"{self.frames_segmented} frames segmented, {len(self.bad_frames)} bad frames, "
            f"{self.elapsed_s:.1f} s)"
        ) + (f"; bad frames listed in {join(self.out_dir, 'bad_frames.csv')}"
             if self.bad_frames else "")  # fmt: skip


class RunStopped(RuntimeError):
    """``max_chunks`` reached before every chunk was done; rerun to resume."""


class OutputInUseError(ValueError):
    """The output folder holds chunks of another survey (``replace=False``)."""


def _foreign_chunks(chunk_dir: Location, survey_hash: str, opts: StorageOptions) -> dict[str, str]:
    """Chunks in ``chunk_dir`` made from another survey description (their marker's
    ``survey_hash`` differs): chunk name -> the survey its marker names."""
    foreign: dict[str, str] = {}
    for name in list_names(chunk_dir, opts):
        if not name.endswith(".json"):
            continue
        try:
            done = json.loads(read_bytes(join(chunk_dir, name), opts).decode())
        except (OSError, ValueError):
            continue  # a torn marker: the chunk is redone (or removed as stale at the end)
        if isinstance(done, dict) and done.get("survey_hash") not in (None, survey_hash):
            foreign[name.removesuffix(".json")] = str(done.get("survey", "?"))
    return foreign


def _remove_chunks(chunk_dir: Location, names: set[str], opts: StorageOptions) -> None:
    """Delete the named chunks: marker first (a chunk without its marker is never reused)."""
    for name in sorted(names):
        for suffix in (".json", ".parquet"):
            remove(join(chunk_dir, f"{name}{suffix}"), opts)


def _stale_chunks(chunk_dir: Location, keep: set[str], opts: StorageOptions) -> set[str]:
    """Chunk files in ``chunk_dir`` that are not among ``keep`` (this run's chunks)."""
    names = list_names(chunk_dir, opts)
    return {Path(n).stem for n in names if Path(n).suffix in (".json", ".parquet")} - keep


@dataclass(frozen=True)
class _Plan:
    """What a run has to do: positions, chunks, the frames each chunk reads, bad frames."""

    survey: Survey
    track: TrackMap
    params: PipelineParams
    chainage_m: NDArray  # per frame, rounded; NaN off the track
    positions_m: NDArray
    chunks: list[tuple[str, float, float, NDArray]]  # name, lo, hi, positions
    frames_of: dict[str, NDArray]  # frame indices each chunk reads
    frames_key: dict[str, str]
    provenance: JsonDict
    chunk_dir: Location
    cache_dir: Location
    storage_options: StorageOptions

    @property
    def n_frames(self) -> int:
        return int(np.isfinite(self.chainage_m).sum())


def _report(msg: str, quiet: bool) -> None:
    # progress lines follow --quiet; bad frames are passed with quiet=False (always told)
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


def _bad(fid: str, message: str, strict: bool, before: str = "") -> None:
    """Report a bad frame, or stop there with ``strict``."""
    if strict:
        raise BadFrameError(
            f"bad frame {fid}: {message} (run without --strict, strict=False, to skip it)"
        )
    _report(f"bad frame {fid}: {message} - skipped{before}", quiet=False)


def _withdraw_published(out: Location, run_key: str, opts: StorageOptions) -> bool:
    """Withdraw the folder's published masks unless they are this very run's: a rerun that is
    stopped (Ctrl-C, a full disk) must not leave the previous run's masks looking finished (a
    user trial: a corrected survey's rerun, interrupted, left the wrong one's masks, 0.34 %
    false trust, read with exit 0). The record first, the masks after, as the merge writes
    them the other way round. Whether a finished run of other settings was withdrawn."""
    record = join(out, "provenance.json")
    try:
        published = json.loads(read_bytes(record, opts)).get("run_key")
    except (OSError, ValueError, AttributeError):
        published = None
    if published == run_key:
        return False
    for name in ("provenance.json", "masks.parquet", "bad_frames.csv"):
        remove(join(out, name), opts)
    return published is not None


def _run_key(provenance: JsonDict) -> str:
    # the track's geometry too, not only its name: a rerun on a corrected map with the same
    # name resumed every chunk of the wrong one (a user trial: 0.0124 % false trust)
    keys = ("survey_hash", "params", "software_version", "code_fingerprint", "track",
            "track_key")  # fmt: skip
    keep = {k: provenance[k] for k in keys}
    return hashlib.sha256(json.dumps(keep, sort_keys=True).encode()).hexdigest()[:16]


def _load_margins(
    margins: MarginTable | str | os.PathLike[str] | None,
) -> tuple[MarginTable | None, JsonDict]:
    """(MarginTable or None, its provenance record) from a table, a path or None; every check
    is made here, before any work, so that a bad table never stops a run at its merge."""
    if margins is None:
        return None, {}
    record: JsonDict
    if isinstance(margins, MarginTable):
        table, record = margins, {"file": None}
    else:
        path = Path(margins)
        if not path.is_file():
            raise FileNotFoundError(
                f"margins: {path} does not exist; write it with `predisat evaluate MASKS "
                "--truth DIR --calibrate --out DIR` (margins.json)"
            )
        try:
            table = MarginTable.from_json(path)
        except (json.JSONDecodeError, UnicodeDecodeError, TypeError, KeyError) as exc:
            raise ValueError(
                f"margins: {path} is not a margin table (JSON from `predisat evaluate "
                f"--calibrate`): {exc}"
            ) from exc
        record = {"file": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}
    # every check before any work: a missing or misspelt group would stop the run at its
    # merge, after hours of work (MarginTable.margin_for refuses bins it has no margin for)
    table.check(f"margins {record['file']}")
    # NaN (los_share of an empty group) becomes null: the provenance is strict JSON
    record |= {"target": table.target, "table": json.loads(table.table.to_json(orient="records"))}
    json.dumps(record, allow_nan=False)
    return table, record


def _segmenter_for(params: PipelineParams, segmenter: Segmenter | None) -> Segmenter:
    if segmenter is not None:
        return segmenter
    if params.segmenter not in METHODS:
        raise ValueError(
            f"params.segmenter {params.segmenter!r} is not a segmentation method {METHODS}; "
            "pass segmenter= with your own function for another name"
        )
    return functools.partial(default_segmenter, method=params.segmenter, sky_net=params.sky_net)


def _load_bad_frames(survey: Survey, chainage_m: NDArray, strict: bool) -> dict[str, BadFrame]:
    """The frames the survey loader rejected and those off the track, reported."""
    bad: dict[str, BadFrame] = {}
    for prob in survey.problems:
        fid = prob.frame_id or f"manifest line {prob.row}"
        bad.setdefault(fid, BadFrame(fid, str(prob), "load"))
    fr = survey.frames
    for i in np.flatnonzero(~np.isfinite(chainage_m)):
        fid = str(fr.frame_id[i])
        bad.setdefault(fid, BadFrame(
            fid, f"manifest line {fr.row[i]}: no chainage (not on the track): give chainage_m "
            "in the manifest, or a position near the survey's track", "load",
        ))  # fmt: skip
    if bad and strict:
        first = next(iter(bad.values()))
        raise BadFrameError(
            f"survey {survey.root}: bad frame {first.frame_id}: {first.message} "
            "(run without --strict, strict=False, to skip it)"
        )
    for b in bad.values():
        _report(f"bad frame {b.frame_id}: {b.message} - skipped", quiet=False)
    return bad


def camera_pair_warnings(survey: Survey) -> list[str]:
    """Lines for pairs of cameras (left and right, front and rear) whose calibrations differ
    in model or focal length: a rig of two kinds of camera, or the wrong calibration file for
    one of them, which only the image size is checked against (a user trial's other camera of
    the same size trusted 0.6 % of the directions falsely, and nothing said so)."""
    out = []
    for a, b in (("left", "right"), ("front", "rear")):
        if a not in survey.cameras or b not in survey.cameras:
            continue
        ca, cb = survey.cameras[a].camera, survey.cameras[b].camera
        focal = abs(ca.fx / cb.fx - 1.0) if cb.fx else 1.0
        if ca.model != cb.model or focal > PAIR_FOCAL_TOL:
            out.append(
                f"warning: the {a} and {b} cameras' calibrations differ ({a}: {ca.model}, "
                f"fx {ca.fx:.1f} px; {b}: {cb.model}, fx {cb.fx:.1f} px): two kinds of camera, or "
                "the wrong calibration file for one of them? Only the image size is checked "
                "against it, and a calibration of another camera of the same size trusted 0.6 % "
                "of the directions falsely; check survey.yaml's calibration paths"
            )
    return out


PAIR_FOCAL_TOL = 0.1
"""Relative difference of two paired cameras' focal lengths above which ``process`` says so
(two units of one camera model calibrate within a few percent)."""


def nearest_in_time(times_a: NDArray, times_b: NDArray) -> NDArray:
    """For each of a camera's frames (``times_a``, sorted), the index of the other camera's
    frame taken with it (``times_b``, sorted): the nearest in time within half the first
    camera's local gap between frames (the smaller of the gaps to its neighbours), else -1.
    Real rigs fire their cameras a few milliseconds apart, and a survey's speed varies: one
    tolerance for the whole survey merged the frames of a fast stretch into one position and
    split a camera offset by a quarter of a gap into two (a review)."""
    ta, tb = np.asarray(times_a, float), np.asarray(times_b, float)
    if ta.size == 0 or tb.size == 0:
        return np.full(ta.size, -1, np.intp)
    gaps = np.diff(ta)
    before = np.concatenate([[np.inf], gaps])
    after = np.concatenate([gaps, [np.inf]])
    local = np.minimum(before, after)
    local = np.where(np.isfinite(local) & (local > 0), local, np.inf)
    j = np.clip(np.searchsorted(tb, ta), 0, tb.size - 1)
    k = np.maximum(j - 1, 0)
    j = np.where(np.abs(tb[k] - ta) <= np.abs(tb[j] - ta), k, j)
    ok = np.abs(tb[j] - ta) < 0.5 * local
    return np.where(ok, j, -1).astype(np.intp)


def _frame_checks(plan: _Plan, bad: dict[str, BadFrame]) -> tuple[JsonDict, JsonDict]:
    """The side check and the step check from one pass over the segmentation cache.

    Side: votes of each side camera's consecutive frames on the way its scenery slides
    (:mod:`predisat.reconstruct.sides`); a camera none of whose frames is cached (or that
    does not look sideways) is left out. Step: for each pair of cameras sharing directions,
    the stretches where one's frames match the other's at a lag other than 0
    (:mod:`predisat.reconstruct.step`), with their chainages and frames.
    """
    fr, cams = plan.survey.frames, plan.survey.cameras
    usable = np.array([str(f) not in bad for f in fr.frame_id]) & np.isfinite(plan.chainage_m)
    chain_all = np.asarray(plan.chainage_m, float)
    steps = np.abs(np.diff(np.sort(chain_all[usable & (np.asarray(fr.side) == min(cams))])))
    steps = steps[steps > 0]
    spacing_m = float(np.median(steps)) if steps.size else 10.0
    pairs, step = {}, {}
    for a, b in itertools.combinations(sorted(cams), 2):
        if not comparable(cams[a].mount, cams[b].mount, spacing_m):
            step[f"{a}/{b}"] = {"compared": False, "why": (
                f"mounted more than half the {spacing_m:.1f} m spacing apart along the vehicle")}
            continue
        pa, pb = overlap_pixels(cams[a].camera, cams[a].mount, cams[b].camera, cams[b].mount)
        if pa[0].size >= MIN_OVERLAP_DIRECTIONS:
            pairs[(a, b)] = (pa, pb)
        else:
            step[f"{a}/{b}"] = {"compared": False, "why": (
                f"{pa[0].size} shared directions (fewer than {MIN_OVERLAP_DIRECTIONS})")}
    # per camera, its usable cached frames in time order: time, id, chainage, labels per pair
    seen: dict[str, list[tuple[float, str, float]]] = {side: [] for side in cams}
    labels: dict[tuple[tuple[str, str], str], list[NDArray]] = {
        (pair, side): [] for pair in pairs for side in pair
    }
    profiles: dict[str, list[NDArray]] = {side: [] for side in cams}
    for side in sorted(cams):
        idx = sorted(np.flatnonzero((fr.side == side) & usable), key=lambda i: float(fr.gps_s[i]))
        if expected_flow_sign(cams[side].mount) == 0 and not any(side in p for p in pairs):
            continue
        for i in idx:
            fid = str(fr.frame_id[i])
            frame = ChunkFrame(fid, side, float(chain_all[i]),
                               str(join(plan.cache_dir, f"{fid}.npz")))  # fmt: skip
            cached = load_cached(frame, plan.storage_options)
            if isinstance(cached, BadFrame):
                continue
            profiles[side].append(sky_profile(cached[0]))
            seen[side].append((float(fr.gps_s[i]), fid, float(chain_all[i])))
            for pair, (pa, pb) in pairs.items():
                if side in pair:
                    labels[(pair, side)].append(cached[0][pa if side == pair[0] else pb])
    sides = {}
    for side, sc in sorted(cams.items()):
        expected = expected_flow_sign(sc.mount)
        if expected == 0:
            continue
        # a pair that stood or backed (a slow reversal) sees the scenery the other way
        moved = moving_on([c for _, _, c in seen[side]], plan.survey.reverse)
        votes = side_votes(side, profiles[side], expected, moved)
        entry: JsonDict = {"agree": votes.agree, "disagree": votes.disagree,
                           "pairs": votes.pairs, "swapped": votes.swapped}  # fmt: skip
        sides[side] = entry
        if not votes.swapped:
            # a stretch of another camera's images (the other side's copied over, a cable
            # moved for a while), which the camera's votes as a whole outvote
            stretches = stretches_the_other_way(pair_votes(profiles[side], expected, moved))
            entry["other_way"] = [
                {
                    "from_m": seen[side][a][2],
                    "to_m": seen[side][b][2],
                    "frames": [f for _, f, _ in seen[side][a : b + 1]],
                }
                for a, b in stretches
            ]
    for (a, b), (pa, _) in pairs.items():
        ta = np.array([t for t, _, _ in seen[a]])
        tb = np.array([t for t, _, _ in seen[b]])
        match = nearest_in_time(ta, tb)
        per_lag = lag_disagreement(labels[((a, b), a)], labels[((a, b), b)], match)
        runs = widen(per_lag, off_step(step_lags(per_lag)))
        out = []
        for r in runs:
            js = match[r.first : r.last + 1]
            js = js[js >= 0]
            lo_b = int(js.min()) + min(r.lag, 0) - 1 if js.size else len(tb)
            hi_b = int(js.max()) + max(r.lag, 0) + 1 if js.size else -1
            frames = [f for _, f, _ in seen[a][r.first : r.last + 1]]
            frames += [f for _, f, _ in seen[b][max(lo_b, 0) : hi_b + 1]]
            out.append({
                "first_position": r.first, "last_position": r.last, "lag": r.lag,
                **_chainage_span(np.array([c for _, _, c in seen[a][r.first : r.last + 1]])),
                "frames": sorted(frames),
            })  # fmt: skip
        step[f"{a}/{b}"] = {"compared": True, "directions": int(pa[0].size),
                            "positions": len(ta), "off_step": out}  # fmt: skip
    return sides, step


def _set_aside(bad: dict[str, BadFrame], frames: dict[str, str], stage: str,
               strict: bool) -> None:  # fmt: skip
    """Add a survey check's ``frames`` (frame id -> reason) to ``bad`` at ``stage`` (a frame
    already bad keeps its first reason); with ``strict`` the first one raises instead."""
    if frames and strict:
        _bad(*next(iter(frames.items())), strict)
    for fid, message in frames.items():
        bad.setdefault(fid, BadFrame(fid, message, stage=stage))


def _lens_check(plan: _Plan, bad: dict[str, BadFrame]) -> JsonDict:
    """Per camera, whether its frames show the sun and the horizon where its calibration puts
    them (:mod:`predisat.reconstruct.sunsight`): how many frames the sun was looked for in,
    found in and found off its place in, how many showed the horizon and how many sky under
    it, and the stretches of frames off (with their chainages, frames and, from the sun, the
    median residual and ratio of the angles from the optical axis)."""
    fr, opts, p = plan.survey.frames, plan.survey.storage_options, plan.params
    ch = np.asarray(plan.chainage_m, float)
    ok = np.isfinite(ch) & np.isfinite(np.asarray(fr.gps_s, float))
    out: JsonDict = {}
    if not ok.any():
        return out
    at = np.flatnonzero(ok)
    # the attitude the chunks rectify the frames with (section 16), and its doubt
    att = frame_attitudes(
        plan.track, ch[ok], fr.roll_deg[ok], fr.pitch_deg[ok], plan.survey.reverse,
        cant=p.cant, grade_doubt_deg=p.grade_doubt_deg, imu_doubt_deg=p.imu_doubt_deg,
        cant_table=p.cant_table, speed_kmh=survey_speed_kmh(ch, fr.gps_s, fr.side)[ok],
        chainage_doubt_m=p.chainage_doubt_m or 0.0,
    )  # fmt: skip
    k_of = {int(i): k for k, i in enumerate(at)}
    heading = np.asarray(plan.track.heading_at(ch[ok]), float)
    lat, lon, _ = plan.track.position_at(ch[ok])
    az, el = sun_azel(np.asarray(fr.gps_s, float)[ok], lat, lon)
    for side, sc in sorted(plan.survey.cameras.items()):
        idx = [int(i) for i in at if fr.side[i] == side and str(fr.frame_id[i]) not in bad]
        idx.sort(key=lambda i: float(fr.gps_s[i]))
        if not idx:
            continue
        # the horizon on a grid of at most about 2e5 pixels (a 4K frame's rays: 200 MB)
        st = max(1, int(math.sqrt(sc.camera.width_px * sc.camera.height_px / 2e5)))
        u, v = sc.camera.pixel_grid()
        rays = sc.camera.pixel_to_ray(u[::st, ::st], v[::st, ::st])
        n_idx = len(idx)
        sun_r, scale = np.full(n_idx, np.nan), np.full(n_idx, np.nan)
        sun_off, hor_off = np.full(n_idx, np.nan), np.full(n_idx, np.nan)
        looked = 0
        for n, i in enumerate(idx):
            k = k_of[i]
            doubt = p.mount_doubt_deg + float(att.doubt_deg[k])
            rot = sc.mount.on_vehicle(float(att.roll_deg[k]), float(att.pitch_deg[k]))
            to_enu = rot.camera_to_enu(float(heading[k]), plan.survey.reverse)
            # the horizon, from the segmentation cache
            frame = ChunkFrame(str(fr.frame_id[i]), side, float(ch[i]),
                               str(join(plan.cache_dir, f"{fr.frame_id[i]}.npz")))  # fmt: skip
            cached = load_cached(frame, plan.storage_options)
            sky = None if isinstance(cached, BadFrame) else np.asarray(cached[0])
            if sky is not None:
                elev = np.degrees(np.arcsin(np.clip((rays @ to_enu.T)[..., 2], -1.0, 1.0)))
                low = lowest_sky_deg(sky[::st, ::st], elev)
                h = horizon_residual(low, HORIZON_TOLERANCE_DEG + doubt)
                hor_off[n] = np.nan if np.isnan(h) else float(np.isposinf(h))
            # the sun, from the image, where the ephemeris puts it in view
            if el[k] <= 0.0:
                continue
            sun = to_enu.T @ sun_direction_enu(float(az[k]), float(el[k]))
            if not sun_in_image(sc.camera, sun):
                continue
            img, _ = read_image(str(join(plan.survey.root, str(fr.image[i]))), opts)
            if img is None:
                continue
            looked += 1
            seen = locate_sun(img, sc.camera, sun, sky)
            if seen is not None:
                sun_r[n], scale[n] = seen.residual_deg, seen.radial_scale
                sun_off[n] = float(seen.residual_deg > SUN_TOLERANCE_DEG + doubt)
        # a frame is off when either shows it, on its place when one shows that and none off
        evidence = np.fmax(sun_off, hor_off)
        rec: JsonDict = {
            "frames": n_idx,
            "sun_looked": looked,
            "sun_found": int(np.isfinite(sun_r).sum()),
            "sun_off": int(np.nansum(sun_off)),
            "horizon_seen": int(np.isfinite(hor_off).sum()),
            "horizon_under": int(np.nansum(hor_off)),
            "checked_frames": int(np.isfinite(evidence).sum()),
        }
        if np.isfinite(sun_r).any():
            rec["sun_median_residual_deg"] = round(float(np.nanmedian(sun_r)), 3)
            rec["sun_max_residual_deg"] = round(float(np.nanmax(sun_r)), 3)
        stretches = []
        for a, b in off_stretches(evidence, 0.5):
            part = slice(a, b + 1)
            off_sun = sun_off[part] == 1.0
            r: JsonDict = {
                **_chainage_span(ch[idx[part]]),
                "frames": [str(fr.frame_id[i]) for i in idx[part]],
                "sun_off": int(off_sun.sum()),
                "horizon_under": int((hor_off[part] == 1.0).sum()),
            }
            if off_sun.any():
                r["sun_residual_deg"] = round(float(np.median(sun_r[part][off_sun])), 2)
                sc_ = scale[part][off_sun]
                has = np.isfinite(sc_).any()
                r["radial_scale"] = round(float(np.nanmedian(sc_)), 3) if has else None
            stretches.append(r)
        rec["off_stretches"] = stretches
        out[side] = rec
    return out


def _lens_what(r: JsonDict) -> str:
    """What a stretch of :func:`_lens_check` showed, in words."""
    parts = []
    if r.get("sun_off"):
        scale = r.get("radial_scale")
        ratio = (f", angles from the optical axis {scale:.2f} times the calibration's"
                 if scale is not None and abs(scale - 1.0) > 0.03 else "")  # fmt: skip
        parts.append(f"the sun {r['sun_residual_deg']:.1f} deg off its place in "
                     f"{r['sun_off']} frames{ratio}")  # fmt: skip
    if r.get("horizon_under"):
        parts.append(f"sky under the horizon in {r['horizon_under']} frames")
    return " and ".join(parts)


def _lens_warnings(check: JsonDict) -> list[str]:
    """The lines ``process`` prints for stretches whose sun or horizon is off its place."""
    return [
        f"warning: the {side} camera's frames {_span_text(r)} show {_lens_what(r)}, where its "
        "calibration, mount and the frames' time, place and attitude put them: another camera "
        "or lens (a lens 1.25 times longer over 150 m trusted 0.23 % of a user trial's "
        "directions falsely), a camera knocked on its mount, a wrong clock, or water mirroring "
        f"the sky. The {len(r['frames'])} frames there were set aside (bad_frames.csv); check "
        "the camera, and split the survey at a camera change, each part with its own "
        "calibration (docs/reconstruction.md, section 19)"
        for side, v in check.items()
        for r in v.get("off_stretches", [])
    ]


def _lens_bad_frames(check: JsonDict) -> dict[str, str]:
    """The frames the lens check sets aside, with the reason each gets in bad_frames.csv."""
    out: dict[str, str] = {}
    for side, v in check.items():
        for r in v.get("off_stretches", []):
            why = (f"the {side} camera's frames {_span_text(r)} show {_lens_what(r)}: another "
                   "camera or lens than its calibration's, or a moved mount; set aside, check "
                   "the camera and split the survey at the change (docs/reconstruction.md, "
                   "section 19)")  # fmt: skip
            for fid in r["frames"]:
                out.setdefault(fid, why)
    return out


def _capture_check(plan: _Plan, bad: dict[str, BadFrame]) -> JsonDict:
    """Per camera, whether its images' own capture times (EXIF) sit on their manifest rows
    (:mod:`predisat.survey.capture`): the camera's clock, and the stretches of frames whose
    time is another row's (with their chainages and frames), or why it was not checked."""
    fr, opts = plan.survey.frames, plan.survey.storage_options
    chain = np.asarray(plan.chainage_m, float)
    out: JsonDict = {}
    for side in sorted(plan.survey.cameras):
        mine = [i for i in np.flatnonzero(fr.side == side) if str(fr.frame_id[i]) not in bad]
        idx = sorted(mine, key=lambda i: float(fr.gps_s[i]))
        got = [read_capture_time_s(join(plan.survey.root, str(fr.image[i])), opts) for i in idx]
        e = np.array([t for t, _ in got], float).reshape(-1)
        res = np.array([r for _, r in got], float).reshape(-1)
        g = np.array([float(fr.gps_s[i]) for i in idx], float)
        timed = int(np.count_nonzero(np.isfinite(e)))
        rec: JsonDict = {"checked": False, "frames": len(idx), "timed": timed}
        out[side] = rec
        if timed < MIN_TIMED_FRAMES:
            rec["why"] = (f"{timed} of its {len(idx)} images carry a capture time (EXIF "
                          "DateTimeOriginal)")  # fmt: skip
            continue
        if not np.all(np.diff(g) > 0):
            rec["why"] = "two of its frames share a gps_s"
            continue
        # the usual resolution: an odd image stamped to the second counts as untimed, not
        # the whole camera as coarse (a review)
        resolution = float(np.nanmedian(res))
        e = np.where(res <= resolution, e, np.nan)
        gap = float(np.median(np.diff(g))) if g.size > 1 else math.inf
        fit = fit_clock(e, g, resolution)
        if fit is None or not fit.reliable or fit.share < MIN_FIT_SHARE:
            if fit is not None and 2.0 * resolution > 0.25 * gap:
                rec["why"] = (f"its capture times are to {resolution:g} s and its frames "
                              f"{gap:.2f} s apart: a row off cannot be told")  # fmt: skip
            elif fit is not None and not fit.reliable:
                rec["why"] = ("its capture times scatter by over a quarter of a frame gap about "
                              "any straight clock: images several rows off, a clock that "
                              "jumped, or stamps too coarse")  # fmt: skip
            else:
                share = 0.0 if fit is None else fit.share
                rec["why"] = (f"one clock puts only {100 * share:.0f} % of its capture times "
                              "on manifest rows: times rewritten by software, a clock that "
                              "jumped, or images more than 3 rows off")  # fmt: skip
            continue
        rows = check_rows(e, g, fit)
        n_checked = int(np.count_nonzero(rows.checked))
        rec.update({
            "offset_s": fit.offset_s, "drift_ppm": fit.drift_ppm, "tol_s": fit.tol_s,
            "resolution_s": resolution, "ambiguous": fit.ambiguous, "checked_frames": n_checked,
        })  # fmt: skip
        # checked only when nearly every frame could be told from its neighbours' rows; the
        # frames found off are set aside either way
        rec["checked"] = n_checked >= _MIN_CHECKED_SHARE * len(idx)
        if not rec["checked"]:
            rec["why"] = (f"only {n_checked} of its {len(idx)} frames could be told from the "
                          f"rows beside them (times known to {fit.tol_s:.3f} s, frames "
                          f"{gap:.2f} s apart)")  # fmt: skip
        off = rows.off
        lag = np.where(rows.fits, rows.lag, CAPTURE_MAX_LAG + 1)  # beyond: fits no row
        runs = []
        k = 0
        while k < len(idx):
            if not off[k]:
                k += 1
                continue
            first = k
            while k + 1 < len(idx) and off[k + 1] and lag[k + 1] == lag[first]:
                k += 1
            sel = np.asarray(idx[first : k + 1])
            runs.append({
                "lag": int(lag[first]) if rows.fits[first] else None,
                **_chainage_span(chain[sel]),
                "frames": [str(f) for f in fr.frame_id[sel]],
            })  # fmt: skip
            k += 1
        rec["off"] = runs
    return out


def _lacking_side_positions(
    plan: _Plan, positions_m: NDArray, bad: dict[str, BadFrame]
) -> list[float]:
    """The mask positions without a usable frame of some side camera within the position
    tolerance (:func:`predisat.reconstruct.carving.lacking_side`), chainages in metres."""
    fr = plan.survey.frames
    usable = np.array([str(f) not in bad for f in fr.frame_id], bool)
    chain = np.asarray(plan.chainage_m, float)
    sides = side_cameras({side: c.camera for side, c in plan.survey.cameras.items()})
    per_side = [chain[usable & (fr.side == side) & np.isfinite(chain)] for side in sides]
    if not sides or positions_m.size == 0:
        return []
    tol = plan.params.reconstruction.position_tol_m
    return [float(x) for x in positions_m[lacking_side(positions_m, per_side, tol)]]


def _with_provenance(masks: MaskSet, **fields: object) -> MaskSet:
    """``masks`` with ``fields`` added to its provenance."""
    return replace(masks, provenance={**masks.provenance, **fields})


def _spans_text(chainage_m: list[float], gap_m: float = 15.0) -> str:
    """Chainages as runs ``a-b m`` (consecutive ones within ``gap_m``), the first ten."""
    runs: list[list[float]] = []
    for c in sorted(chainage_m):
        if runs and c - runs[-1][1] <= gap_m:
            runs[-1][1] = c
        else:
            runs.append([c, c])
    text = ", ".join(f"{a:.0f} m" if a == b else f"{a:.0f}-{b:.0f} m" for a, b in runs[:10])
    return text + (f" and {len(runs) - 10} more stretches" if len(runs) > 10 else "")


def _capture_warnings(check: JsonDict) -> list[str]:
    """The lines ``process`` prints for cameras whose images' capture times are other rows',
    for cameras whose times could not be used, and a note for a survey none of whose
    cameras could be checked."""
    out = []
    for side, v in check.items():
        if not v.get("checked") and v.get("timed", 0) >= MIN_TIMED_FRAMES:
            out.append(
                f"warning: the {side} camera's images carry capture times but could not all "
                f"be checked against their manifest rows ({v.get('why')}); an image a row "
                "off there is seen only where two cameras' views overlap "
                "(docs/reconstruction.md, sections 21-22)"
            )
    if not any(v.get("checked") for v in check.values()):
        whys = "; ".join(f"{side}: {v.get('why')}" for side, v in check.items())
        out.append(
            "note: the images' capture times were not compared with their manifest rows "
            f"({whys}); an image a row off its row is then seen only where two cameras' "
            "views overlap (docs/reconstruction.md, sections 21-22)"
        )
    for side, v in check.items():
        if v.get("checked") and v.get("ambiguous") and v.get("off"):
            out.append(
                f"note: the {side} camera's frames were taken at one speed: its capture times "
                "cannot tell a clock set a frame gap off from every image a row off, so its "
                "first frames were taken as on their rows (docs/reconstruction.md, section 22)"
            )
        for r in v.get("off", []):
            n = len(r["frames"])
            if r["lag"] is None:
                out.append(
                    f"warning: the {side} camera's images {_span_text(r)} carry capture times "
                    f"that fit no row within {CAPTURE_MAX_LAG} of their own by the camera's "
                    "fitted clock: a late stamp, a step of the camera's clock, or images more "
                    f"rows off or from another run; their frames there ({n}) were set aside, "
                    "as an image off its row carves skylines where they were not seen; check "
                    "the images' times and the manifest (docs/reconstruction.md, section 22)"
                )
                continue
            out.append(
                f"warning: the {side} camera's images {_span_text(r)} were taken at the time "
                f"of {_row_text(r['lag'])} by the camera's own clock (EXIF DateTimeOriginal, "
                "fitted over the survey): a dropped or extra image, a renumbering, a camera "
                "that missed triggers. Carved there, each skyline would stand where it was "
                "not seen (a user trial's survey with one dropped image trusted 1.05 % of its "
                f"directions falsely); its frames there ({n}) were set aside; fix the manifest "
                "(docs/reconstruction.md, section 22)"
            )
    return out


def _capture_bad_frames(check: JsonDict) -> dict[str, str]:
    """The frames the capture-time check sets aside, with the reason each gets."""
    out: dict[str, str] = {}
    for side, v in check.items():
        for r in v.get("off", []):
            reason = (
                f"the {side} camera's image was taken at the time of {_row_text(r['lag'])} (EXIF "
                "capture time against the camera's fitted clock): "
                + ("a late stamp, a clock step, or an image more rows off?"
                   if r["lag"] is None else "a dropped or extra image in the manifest?")
                + "; set aside, check the image's time and the manifest "
                "(docs/reconstruction.md, section 22)"
            )  # fmt: skip
            for fid in r["frames"]:
                out.setdefault(fid, reason)
    return out


def _row_text(lag: int | None) -> str:
    if lag is None:
        return f"no row within {CAPTURE_MAX_LAG} of its own"
    return f"the row {abs(lag)} {'after' if lag > 0 else 'before'} its own"


def _chainage_span(chainage_m: NDArray) -> JsonDict:
    """``from_chainage_m`` and ``to_chainage_m`` of the finite values (None when none is)."""
    c = chainage_m[np.isfinite(chainage_m)]
    lo, hi = (float(c.min()), float(c.max())) if c.size else (None, None)
    return {"from_chainage_m": lo, "to_chainage_m": hi}


def _span_text(r: JsonDict) -> str:
    lo, hi = r.get("from_chainage_m"), r.get("to_chainage_m")
    if lo is None or hi is None:
        return f"at positions {r.get('first_position')}-{r.get('last_position')}"
    return f"from chainage {lo:.1f} to {hi:.1f} m"


def _step_warnings(step: JsonDict, capture: JsonDict | None = None) -> list[str]:
    """The lines ``process`` prints for cameras whose frames are out of step, or for a rig
    whose cameras could not be compared (unless every camera's capture times were checked
    against its rows: ``capture``, :func:`_capture_check`'s result)."""
    out = []
    timed = bool(capture) and all(v.get("checked") for v in (capture or {}).values())
    if not timed and not any(v.get("compared") for v in step.values()):
        out.append(
            "note: whether the cameras' images are in step with their manifest rows was not "
            "checked: no two cameras both image 50 directions above the track (pinhole side "
            "cameras, a single panorama) or they are mounted far apart along the vehicle; a "
            "dropped image in the manifest would go unseen (docs/reconstruction.md, section 21)"
        )
    for pair, v in step.items():
        a, b = pair.split("/")
        for r in v.get("off_step", []):
            n = abs(r["lag"])
            rows = f"at least {n}" if n >= MAX_LAG else f"{n}"
            out.append(
                f"warning: the {a} and {b} cameras are out of step {_span_text(r)}: what both "
                f"see above the track matches between the {a} camera's image of each frame and "
                f"the {b} camera's of the frame {rows} {'before' if r['lag'] < 0 else 'after'} "
                f"it (one camera's images {rows} row(s) off in the manifest: a dropped or extra "
                "image, a camera that missed triggers). That puts skylines where they were not "
                "seen (a user trial's survey with one dropped image trusted 1.05 % of its "
                f"directions falsely); the {len(r['frames'])} frames of both cameras there were "
                "set aside (the masks there rest on other frames or are ASSUMED); fix the "
                "manifest (docs/reconstruction.md, section 21)"
            )
    return out


def _step_bad_frames(step: JsonDict) -> dict[str, str]:
    """The frames the step check sets aside, with the reason each gets in bad_frames.csv."""
    out: dict[str, str] = {}
    for pair, v in step.items():
        for r in v.get("off_step", []):
            for fid in r["frames"]:
                out.setdefault(fid, f"out of step: the {pair.replace('/', ' and ')} cameras' "
                                    f"frames match {abs(r['lag'])} frame(s) apart here (a "
                                    "dropped or extra image in the manifest?); set aside, fix the "
                                    "manifest (docs/reconstruction.md, section 21)")  # fmt: skip
    return out


def _refuse_when_every_frame_is_bad(survey: Survey, bad: Mapping[str, BadFrame]) -> None:
    """Stop before the reconstruction when no frame of the survey is left: the masks would be
    all assumed, and a user trial's run published them and exited 0 (a manifest listing
    every frame twice). Names how many frames each stage set aside, the first reason and the
    fix."""
    ids = [str(f) for f in survey.frames.frame_id]
    if not ids or any(f not in bad for f in ids):
        return
    stages: dict[str, int] = {}
    for f in ids:
        stages[bad[f].stage] = stages.get(bad[f].stage, 0) + 1
    first = bad[ids[0]]
    raise ValueError(
        f"survey {survey.root}: every one of its {len(ids)} frames was set aside ("
        + ", ".join(f"{n} at stage {k}" for k, n in sorted(stages.items()))
        + f"; the first, {first.frame_id}: {first.message}); no masks were made: fix the "
        "frames or the manifest and run again"
    )


def _side_bad_frames(check: JsonDict) -> dict[str, str]:
    """The frames of stretches whose scenery slid the other way from their camera's mount,
    set aside with the reason each gets in bad_frames.csv."""
    out: dict[str, str] = {}
    for side, v in check.items():
        for r in v.get("other_way", []):
            why = (
                f"the {side} camera's scenery slides the other way from its mount's from "
                f"chainage {r['from_m']:.1f} to {r['to_m']:.1f} m: these images are probably "
                "another camera's (the other side's copied over, a cable moved); set aside, "
                "check them by eye and fix the image files or the manifest "
                "(docs/reconstruction.md, section 19)"
            )
            for fid in r["frames"]:
                out.setdefault(fid, why)
    return out


def _side_warnings(check: JsonDict) -> list[str]:
    """The lines ``process`` prints for cameras whose frames moved the other way."""
    stretches = [
        f"warning: the {side} camera's scenery slides the other way from its mount's from "
        f"chainage {r['from_m']:.1f} to {r['to_m']:.1f} m ({len(r['frames'])} frames), though "
        "not over the whole survey: those images are probably another camera's (the other "
        "side's copied over, a cable moved for a while), which trusted 1.4 % of a survey's "
        "directions falsely; they were set aside (bad_frames.csv); check them by eye "
        "(docs/reconstruction.md, section 19)"
        for side, v in check.items()
        for r in v.get("other_way", [])
    ]
    return stretches + [
        f"warning: the {side} camera's scenery slides the other way from its mount's in "
        f"{v['disagree']} of {v['agree'] + v['disagree']} pairs of consecutive frames: its "
        "frames are probably the other side's (left and right swapped: cables, file names, "
        "the manifest's side column), which trusted 5.7-8 % of a survey's directions falsely; "
        "check a few frames by eye and fix the manifest or survey.yaml (docs/reconstruction.md, "
        "section 19)"
        for side, v in check.items()
        if v.get("swapped")
    ]


def _with_chainage_doubt(
    params: PipelineParams, survey: Survey
) -> tuple[PipelineParams, str | None]:
    """``params`` with the run's chainage doubt and jitter resolved (the params', else the
    survey's statements; the doubt else 0, the jitter else the doubt) and the window's shift
    set (the doubt, when the jitter is below it: section 18), and the warning ``process``
    prints when nobody stated the doubt."""
    doubt = params.chainage_doubt_m
    doubt = survey.chainage_doubt_m if doubt is None else doubt
    jitter = params.chainage_jitter_m
    jitter = survey.chainage_jitter_m if jitter is None else jitter
    d = 0.0 if doubt is None else doubt
    j = d if jitter is None else min(jitter, d)
    try:
        resolved = replace(
            params, chainage_doubt_m=d, chainage_jitter_m=j,
            reconstruction=replace(params.reconstruction, chainage_shift_m=d if j < d else 0.0),
        )  # fmt: skip
    except ValueError as exc:
        raise ValueError(
            f"{survey.root}/survey.yaml: {exc}; a survey that knows its frames' places no "
            "better cannot bound the sky near the track: position it again (GNSS with RTK, or "
            "balises)"
        ) from None
    if doubt is not None:
        return resolved, None
    return resolved, (
        f"warning: {survey.root}/survey.yaml states no chainage_doubt_m: every frame's chainage "
        "is taken as exact. A survey positioned by plain GNSS is metres off, and 3 m along the "
        "track trusted 0.35-0.49 % of the demo's directions falsely; state the positioning's "
        "accuracy there (0.05 for RTK; chainage_jitter_m for its relative accuracy) or give "
        "--chainage-doubt-m (docs/reconstruction.md, section 18)"
    )


POSITION_SLACK_M = 0.5
"""How far a frame's manifest chainage may lie from its own position's on the track beyond the
stated chainage doubt before the doubt is raised, metres (an RTK fix's noise and the
projection's)."""


def _doubt_from_positions(
    params: PipelineParams, survey: Survey, track: TrackMap, ch: NDArray
) -> tuple[PipelineParams, str | None]:
    """``params`` with the chainage doubt raised to the largest disagreement between the
    frames' manifest chainages and their own positions projected on ``track``, when that
    exceeds the doubt by more than :data:`POSITION_SLACK_M`, and the warning saying so.

    A user trial moved every chainage 5 m and kept the positions: accepted in silence under a
    stated doubt of 0 (the load refuses beyond ``max_offset_m``, 10 m), 1.14 % of the directions
    trusted falsely, 14 % at the worst position. Either the chainages or the positions are
    wrong; the doubt covering the disagreement holds in both cases.
    """
    fr = survey.frames
    lat, lon = np.asarray(fr.lat_deg, float), np.asarray(fr.lon_deg, float)
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(ch)
    if not ok.any():
        return params, None
    signed = ch[ok] - np.asarray(track.project(lat[ok], lon[ok]).chainage_m, float)
    gap = np.abs(signed)
    doubt = params.chainage_doubt_m or 0.0
    worst = float(gap.max())
    if worst <= doubt + POSITION_SLACK_M:
        return params, None
    raised = math.ceil(worst * 10.0 - 1e-6) / 10.0  # up to the decimetre
    frame = str(np.asarray(fr.frame_id)[ok][int(np.argmax(gap))])
    n = int((gap > doubt + POSITION_SLACK_M).sum())
    # a common shift is bounded as one (section 18); frames off each their own way are not
    spread = float(np.max(np.abs(signed - np.median(signed)))) + POSITION_SLACK_M
    jitter = min(max(params.chainage_jitter_m or 0.0, spread), raised)
    out, _ = _with_chainage_doubt(
        replace(params, chainage_doubt_m=raised, chainage_jitter_m=jitter), survey
    )
    return out, (
        f"warning: {survey.root}: the chainage_m of {n} frame(s) disagree with their own "
        f"lat_deg/lon_deg by up to {worst:.2f} m along track {track.name!r} (frame {frame}), "
        f"more than the chainage doubt of {doubt:g} m: the doubt is raised to {raised:g} m for "
        "this run (a trial's 5 m under a doubt of 0 trusted 1.14 % of the directions "
        "falsely); correct the chainages or the positions, or state the doubt (--chainage-"
        "doubt-m, docs/reconstruction.md, section 18)"
    )


def _beside_track(survey: Survey, track: TrackMap) -> JsonDict | None:
    """How far the frames' own positions lie beside ``track`` when they lie there as another
    track's would (provenance ``survey_beside_track``), else None: the median beyond
    :data:`~predisat.masks.registration.OTHER_TRACK_OFFSET_M`, or a stretch beyond
    :data:`~predisat.masks.registration.OTHER_TRACK_STRETCH`, as the masks' registration
    refuses them.

    A review: a survey whose GNSS positions all lay 4 m right of the map (a survey train on
    the other track of a double line, or over a crossover) was processed in silence; its masks
    are written on this map's axis, so the locator's other-track check cannot see them (masks
    of the other track 4 m across trusted 8.8 % of the directions falsely in a user trial).
    """
    fr = survey.frames
    lat, lon = np.asarray(fr.lat_deg, float), np.asarray(fr.lon_deg, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if ok.sum() < 2:
        return None
    proj = track.project(lat[ok], lon[ok])
    inside = ~np.asarray(proj.clamped, bool)
    signed = np.asarray(proj.offset_m, float)[inside]
    ch = np.asarray(proj.chainage_m, float)[inside]
    if signed.size < 2:
        return None
    order = np.argsort(ch, kind="stable")
    signed, ch = signed[order], ch[order]
    median = float(np.median(np.abs(signed)))
    found = first_stretch_aside(ch, signed)
    stretch = None if found is None else (round(float(ch[found[0]]), 1),
                                          round(float(ch[found[1]]), 1))  # fmt: skip
    if median <= OTHER_TRACK_OFFSET_M and stretch is None:
        return None
    side = float(np.median(signed))
    return {
        "median_offset_m": round(median, 2),
        "side": "left" if side > 0 else "right",
        "max_offset_m": round(float(np.abs(signed).max()), 2),
        "stretch_m": None if stretch is None else list(stretch),
        # the positions' own stated doubt: plain GNSS (3-5 m) cannot tell two tracks apart
        "position_doubt_m": survey.chainage_doubt_m,
    }


def _at_survey_antenna(params: PipelineParams, survey: Survey) -> PipelineParams:
    """``params`` reconstructing for the antenna ``params.antenna_height_m`` states, else the
    survey's own (the height its cameras are placed from). A user trial: a 3.0 m survey's
    masks were carved at the 4.0 m default, bit-identical to a 4.0 m survey's, the file saying
    3.0 m, and its cutting and canopy trusted 0.027 % of the directions falsely."""
    h = params.antenna_height_m
    h = float(survey.antenna_height_m) if h is None else float(h)
    return replace(params, reconstruction=replace(params.reconstruction, antenna_height_m=h))


def _resolved_params(
    params: PipelineParams, survey: Survey, track: TrackMap
) -> tuple[PipelineParams, NDArray, tuple[str | None, ...]]:
    """``params`` as a run of ``survey`` along ``track`` takes them (the chainage doubt and
    jitter, the antenna height resolved), every frame's chainage as the run uses it
    (:func:`_rounded_chainage`) and the warnings the resolution gives."""
    p, chainage_note = _with_chainage_doubt(params, survey)
    p = _at_survey_antenna(p, survey)
    ch = _rounded_chainage(survey.frames)
    p, positions_note = _doubt_from_positions(p, survey, track, ch)
    return p, ch, (chainage_note, positions_note)


def _attitude_summary(
    survey: Survey, track: TrackMap, params: PipelineParams, ch: NDArray
) -> JsonDict:
    """How the frames' attitude is known (provenance ``attitude``; section 16 of
    docs/reconstruction.md): frames with a measured roll and pitch, and the largest doubt
    their sky is eroded by, and the largest distance their cameras may stand from where the
    nominal attitude puts them (``tilt_doubt_m``)."""
    fr, ok = survey.frames, np.isfinite(ch)
    speed = survey_speed_kmh(ch, fr.gps_s, fr.side)[ok]
    att = frame_attitudes(
        track, ch[ok], fr.roll_deg[ok], fr.pitch_deg[ok], survey.reverse, cant=params.cant,
        grade_doubt_deg=params.grade_doubt_deg, imu_doubt_deg=params.imu_doubt_deg,
        cant_table=params.cant_table, speed_kmh=speed,
        chainage_doubt_m=params.chainage_doubt_m or 0.0,
    )  # fmt: skip
    contradicted = att.contradicted if att.contradicted is not None else np.zeros(0, bool)
    height_m = float(survey.antenna_height_m)  # the rig's: its lever arms start there
    moved_m = 0.0
    for k, side in enumerate(fr.side[ok]):
        if att.doubt_deg[k] > 0.0 and side in survey.cameras:
            arm = survey.cameras[side].mount.lever_arm_m
            moved_m = max(moved_m, float(np.linalg.norm(att.camera_doubt_m(k, arm, height_m))))
    out: JsonDict = {
        "frames": int(ok.sum()),
        "measured_frames": int(att.measured.sum()),
        "contradicted_frames": int(contradicted.sum()),
        "max_doubt_deg": round(float(att.doubt_deg.max(initial=0.0)), 3),
        "max_camera_doubt_m": round(moved_m, 3),
        "max_abs_roll_deg": round(float(np.abs(att.roll_deg).max(initial=0.0)), 3),
        # taken once for the survey, and given to every chunk (frame_attitudes' verdicts)
        "imu_distrusted": bool(att.imu_distrusted),
        "cant_table_distrusted": bool(att.table_distrusted),
    }
    if contradicted.any():
        out["first_contradicted"] = str(fr.frame_id[ok][contradicted][0])
    if params.cant_table is not None:
        cant = params.cant_table.cant_mm_at(ch[ok])
        flat = np.abs(np.asarray(track.curvature_at(ch[ok]), float)) < STRAIGHT_PER_M
        out["cant_table_frames"] = int(np.isfinite(cant).sum())
        # cant where the map has no curve: the table's chainage is probably not the map's
        out["cant_off_curve_frames"] = int((flat & (cant >= _CANT_ON_CURVE_MM)).sum())
        ignored = att.table_ignored if att.table_ignored is not None else np.zeros(0, bool)
        out["cant_table_ignored_frames"] = int(ignored.sum())
        out["max_deficiency_mm"] = float(params.cant.max_deficiency_mm)
    return out


_CANT_ON_CURVE_MM = 20.0


def _attitude_warnings(summary: JsonDict) -> list[str]:
    """The lines ``process`` prints when frames lack a measured attitude, or a cant table
    does not fit the track."""
    out = []
    n = int(summary["frames"])
    bad = int(summary.get("contradicted_frames", 0))
    if bad:
        out.append(
            f"warning: {bad} of {n} frames give a roll the track rules out (first "
            f"{summary.get('first_contradicted', '?')}): the wrong sign (roll_deg is positive "
            "raising the vehicle's left side), radians, or a tilt sensor's apparent vertical "
            "(about level on a curve); they are bounded from the track instead "
            "(docs/reconstruction.md, section 16)"
        )
    if "cant_table_frames" in summary and int(summary["cant_table_frames"]) < n:
        out.append(
            f"warning: the cant table covers {summary['cant_table_frames']} of {n} frames: "
            "the others are bounded from the track's curves; check that its chainage is the "
            "track map's"
        )
    ignored = int(summary.get("cant_table_ignored_frames", 0))
    if ignored:
        out.append(
            f"warning: the cant table is ruled out at {ignored} frames: under "
            f"{CANT_ON_SHARP_MM:g} mm on curves sharper than R = 1 km, which carry cant, or so "
            "low that the survey vehicle would have run with more cant deficiency than trains "
            f"do ({summary.get('max_deficiency_mm', 150.0) + CANT_DEFICIENCY_TOL_MM:g} mm) at "
            f"its speed there, or never {CANT_TABLE_FLOOR_MM:g} mm on those curves: not used "
            "there, bounded from the curves instead (is it in millimetres, and the right "
            "track's?)"
        )
    off = int(summary.get("cant_off_curve_frames", 0))
    if off:
        out.append(
            f"warning: the cant table gives {_CANT_ON_CURVE_MM:g} mm or more at {off} frames "
            "where the track map has no curve (R > 10 km): check that its chainage is the "
            "track map's"
        )
    note = _attitude_warning(summary)
    return out if note is None else [*out, note]


def _attitude_warning(summary: JsonDict) -> str | None:
    """The line ``process`` prints when frames lack a measured attitude."""
    n, measured = int(summary["frames"]), int(summary["measured_frames"])
    n -= int(summary.get("contradicted_frames", 0))  # told apart
    if measured >= n:
        return None
    tabled = "cant_table_frames" in summary
    return (
        f"warning: {n - measured} of {n} frames have no measured roll and pitch (manifest "
        f"columns roll_deg, pitch_deg): their attitude is bounded from the track (its curves, "
        f"grade{' and cant table' if tabled else ''}), their sky eroded by up to "
        f"{summary['max_doubt_deg']:.1f} deg and their cameras placed within "
        f"{summary.get('max_camera_doubt_m', 0.0):.2f} m, which costs sky (up to 30-50 points "
        "on sharp curves); give the survey vehicle's IMU "
        f"attitude{'' if tabled else ' or the cant table of the line (--cant-table)'} "
        "(docs/reconstruction.md, section 16)"
    )


def _cache_dir(out: Location, params: PipelineParams, params_dict: JsonDict) -> Location:
    """The segmentation cache of a run of ``params`` into ``out`` (``params_dict``: their
    record, :meth:`PipelineParams.to_dict`): keyed by the segmentation's code, network and
    thin width."""
    seg_code = code_fingerprint(SEGMENTATION_CODE)[:8]
    if params.sky_net is not None:
        seg_code += "-net" + params_dict["sky_net"]["sha256"][:12]
    if params.thin_deg != THIN_DEG:
        # a folder per thin width: an entry holds one, and switching back must not redo all
        seg_code += f"-thin{params.thin_deg:g}"
    return join(out, "cache", f"seg-{params.segmenter}-{seg_code}")


def _chunk_windows(
    fr: Frames, ch: NDArray, positions: NDArray, params: PipelineParams
) -> tuple[list[tuple[str, float, float, NDArray]], dict[str, NDArray]]:
    """The chunks (name, lo, hi, positions) of ``positions`` and the frame indices each reads;
    ``ch`` is every frame's chainage, rounded (NaN off the track)."""
    finite = np.isfinite(ch)
    k = np.floor(positions / params.chunk_m).astype(np.int64)
    chunks = [
        (chunk_name(lo, hi), lo, hi, positions[k == kk])
        for kk in np.unique(k)
        for lo, hi in [(float(kk * params.chunk_m), float((kk + 1) * params.chunk_m))]
    ]
    # the frames each chunk reads: within overlap_m of its positions
    overlap = params.reconstruction.overlap_m
    frames_of = {
        name: np.flatnonzero(finite & (ch >= s.min() - overlap) & (ch <= s.max() + overlap))
        for name, _, _, s in chunks
    }
    # and every frame of a view it reads one frame of: a view cut by the window was merged
    # from part of its frames, and a crawl sliced otherwise than in the whole survey
    view = stop_ids(fr.side, ch, params.stop_gap_m, params.stop_span_m)
    frames_of = {name: np.flatnonzero(finite & np.isin(view, view[idx]))
                 for name, idx in frames_of.items()}  # fmt: skip
    return chunks, frames_of


def _plan(
    survey: Survey,
    track: TrackMap,
    params: PipelineParams,
    out: Location,
    ch: NDArray,
    opts: StorageOptions,
) -> _Plan:
    """Positions, chunks, the frames each chunk reads, the run's provenance and folders;
    ``ch`` is every frame's chainage, rounded (NaN off the track)."""
    fr = survey.frames
    finite = np.isfinite(ch)
    if not finite.any():
        if len(fr) == 0 and survey.problems:
            first = survey.problems[0]
            raise ValueError(
                f"survey {survey.root}: every frame was refused ({len(survey.problems)} "
                f"problems; the first, manifest line {first.row}: {first.message}); nothing "
                "to do"
            )
        raise ValueError(f"survey {survey.root} has no frame with a chainage; nothing to do")
    positions = np.unique(ch[finite])
    params_dict = params.to_dict()  # hashes a candidate network's files once, for both keys
    prov: JsonDict = {
        "software": "predisat",
        "software_version": str(__version__),
        "code_fingerprint": code_fingerprint(),
        "survey": str(survey.root),
        "survey_hash": survey_hash(survey),
        "track": str(getattr(track, "name", "")),
        "track_key": track_key(track) if isinstance(track, TrackMap) else "",
        "params": params_dict,
        "reverse": bool(survey.reverse),
        # the height the masks hold for (docs/mask-format.md), and the rig's
        "antenna_height_m": float(params.reconstruction.antenna_height_m),
        "survey_antenna_height_m": float(survey.antenna_height_m),
    }
    # the rig that made the frames (the report names it): camera model, size, mount per side
    prov["rig"] = {
        side: f"{c.camera.model} {c.camera.width_px}x{c.camera.height_px} px, yaw "
        f"{c.mount.yaw_deg:g} deg, pitch {c.mount.pitch_deg:g} deg"
        for side, c in sorted(survey.cameras.items())
    }
    # what made the frames (a synthetic survey says so): the report warns on synthetic masks
    for key in ("generator", "description"):
        if survey.metadata.get(key):
            prov[f"survey_{key}"] = str(survey.metadata[key])
    prov["run_key"] = _run_key(prov)
    prov["attitude"] = _attitude_summary(survey, track, params, ch)
    chunk_dir = join(out, "chunks")
    cache_dir = _cache_dir(out, params, params_dict)
    makedirs(chunk_dir, opts)
    makedirs(cache_dir, opts)
    chunks, frames_of = _chunk_windows(fr, ch, positions, params)
    # each image stamped once (a frame is read by up to three chunks), remote ones in parallel
    images = [join(survey.root, str(fr.image[i])) for i in np.flatnonzero(finite)]
    known = dict(zip(map(str, images), stamps(images, survey.storage_options), strict=True))
    keys = {
        name: frames_key(
            (str(fr.frame_id[i]) for i in idx),
            (str(join(survey.root, str(fr.image[i]))) for i in idx),
            survey.storage_options,
            known,
        )
        for name, idx in frames_of.items()
    }
    return _Plan(survey, track, params, ch, positions, chunks, frames_of, keys, prov,
                 chunk_dir, cache_dir, opts)  # fmt: skip


def _pending(
    plan: _Plan, strict: bool, max_chunks: int | None
) -> tuple[list[tuple[str, float, float, NDArray]], int]:
    """The chunks to compute (at most ``max_chunks``) and how many an earlier run finished."""
    pending, skipped = [], 0
    for c in plan.chunks:
        marker = chunk_finished(
            plan.chunk_dir, c[0], plan.provenance["run_key"], plan.frames_key[c[0]],
            plan.storage_options,
        )  # fmt: skip
        if marker is None or _retried_frames(plan, marker):
            pending.append(c)
            continue
        skipped += 1
        if strict and marker.get("bad_frames"):
            # a finished folder must not pass a --strict check on frames a run before skipped
            first = marker["bad_frames"][0]
            raise BadFrameError(
                f"bad frame {first['frame_id']}: {first['message']} (skipped by a run before in "
                f"chunk {c[0]}; fix the image and rerun: the chunk is redone; or run without "
                "--strict to skip it)"
            )
    if max_chunks is not None:
        pending = pending[:max_chunks]
    return pending, skipped


def _retried_frames(plan: _Plan, marker: JsonDict) -> list[str]:
    """The frames a finished chunk set aside because their segmentation raised: not cached
    (:func:`predisat.reconstruct.frames.segment_frame`: a failure of that run, not of the
    image), so the chunk is redone and they are segmented again; the verdicts on the images
    themselves (unreadable, blank, the wrong size) are cached and keep the chunk."""
    return [
        b["frame_id"] for b in marker.get("bad_frames", [])
        if "segmentation failed (" in str(b.get("message", ""))
        and not exists(join(plan.cache_dir, f"{b['frame_id']}.npz"), plan.storage_options)
    ]  # fmt: skip


def _cameras(plan: _Plan) -> dict[str, tuple[CameraModel, Mount]]:
    return {side: (sc.camera, sc.mount) for side, sc in plan.survey.cameras.items()}


def _at_line(plan: _Plan, i: int, message: str) -> str:
    """``message`` prefixed with frame ``i``'s manifest line (where the user fixes it)."""
    line = f"manifest line {plan.survey.frames.row[i]}: "
    return message if message.startswith(line) else line + message


#: A frame is the previous one re-encoded when their quarter-size grey pictures differ by less
#: than this on average (levels of 255) and by at most ``FROZEN_P99_LEVELS`` at the 99th
#: percentile: a JPEG re-encoding at quality 50-95 differs by 0.05-0.7 / 1-2 levels, two
#: consecutive frames of the demo's survey (10 m apart, a tunnel included) by at least
#: 1.9 / 11 (2026-12-04, 200 pairs).
FROZEN_MEAN_LEVELS = 1.0
FROZEN_P99_LEVELS = 4.0


def _thumbnail(path: Location, opts: StorageOptions) -> NDArray | None:
    """The quarter-size grey picture of an image file (None when it cannot be decoded: the
    segmentation reports it)."""
    try:
        data = path.read_bytes() if isinstance(path, Path) else read_bytes(path, opts)
    except OSError:
        return None
    return decode_thumbnail(data)


def _same_file(a: Location, b: Location, opts: StorageOptions) -> bool:
    """Whether two image files hold the same bytes (sizes compared first)."""
    if isinstance(a, Path) and isinstance(b, Path):
        return a.stat().st_size == b.stat().st_size and a.read_bytes() == b.read_bytes()
    sa, sb = stat_key(str(a), opts), stat_key(str(b), opts)
    if sa is None or sb is None:
        raise FileNotFoundError(a if sa is None else b)
    return sa[0] == sb[0] and read_bytes(a, opts) == read_bytes(b, opts)


def _same_picture(
    a: Location, b: Location, thumbs: dict[Location, NDArray | None], opts: StorageOptions
) -> str | None:
    """How the two image files show the same picture (``"the same file"``, or ``"the same
    picture re-encoded"``), or None. Files that cannot be read are None (reported when read).
    ``thumbs`` keeps the decoded pictures: each frame is compared as itself and as the next
    frame's predecessor, decoded once."""
    try:
        if _same_file(a, b, opts):
            return "the same file"
    except OSError:
        return None
    for path in (a, b):
        if path not in thumbs:
            thumbs[path] = _thumbnail(path, opts)
    pa, pb = thumbs[a], thumbs[b]
    if pa is None or pb is None or pa.shape != pb.shape:
        return None
    d = np.abs(pa.astype(np.int16) - pb.astype(np.int16))
    if float(d.mean()) < FROZEN_MEAN_LEVELS and float(np.percentile(d, 99)) <= FROZEN_P99_LEVELS:
        return "the same picture re-encoded"
    return None


def _rounded_chainage(frames: Frames) -> NDArray:
    """Every frame's chainage as a run uses it (``_Plan.chainage_m``): rounded to
    :data:`_CHAINAGE_DECIMALS`, NaN off the track; the views (:func:`stop_ids`) are sliced from
    these, by the chunks and by the frozen check alike."""
    return np.round(np.asarray(frames.chainage_m, float), _CHAINAGE_DECIMALS)


def _frozen_frames(plan: _Plan, need: NDArray) -> dict[int, str]:
    """Frames among ``need`` that show the picture of the frame before on the same side (a
    camera stuck on one picture: the same file, or the same picture re-encoded), with the
    problem and its fix. A frame of the same stop as the one before (merged into one view,
    section 24) is not compared: a train at a stop shows one picture. A crawl's frames, cut
    into views of their own, are (a review: a camera frozen through a crawl 0.15 m a frame
    was never compared, its stale picture used as 24 views over 6 m); so is a stop's frame
    after a frozen one.

    The answer for a frame does not depend on ``need``: the earlier frames of its stop are
    checked with it (a review: on a resumed run, a stop's first frame found frozen in a
    finished chunk left the stop's frames in a pending chunk uncompared)."""
    fr, root = plan.survey.frames, plan.survey.root
    p = plan.params
    # the views the chunks merge (ChunkFrame.view_id): of the rounded chainages, not the
    # manifest's (a review: a step of 0.1995 m rounds to 0.2000000000000455 > stop_gap_m, and
    # the crawl's slices moved, leaving a view's first frames uncompared)
    stop = stop_ids(fr.side, _rounded_chainage(fr), p.stop_gap_m, p.stop_span_m)
    prev_of: dict[int, int] = {}
    last: dict[str, int] = {}
    for i in range(len(fr.frame_id)):  # manifest order, increasing time per side
        side = str(fr.side[i])
        if side in last:
            prev_of[i] = last[side]
        last[side] = i
    wanted = {int(i) for i in need}
    checked = set(wanted)
    for i in wanted:  # back to the first frame of each needed frame's stop
        j = prev_of.get(i)
        while j is not None and stop[j] == stop[i] and j not in checked:
            checked.add(j)
            j = prev_of.get(j)
    frozen = {}
    thumbs: dict[Location, NDArray | None] = {}
    last_seen: dict[str, Location] = {}  # per camera, the picture its next frame may need
    opts = plan.survey.storage_options
    for i in sorted(checked):
        j = prev_of.get(int(i))
        if j is None or (stop[i] == stop[j] and int(j) not in frozen):
            continue
        image_i, image_j = join(root, str(fr.image[i])), join(root, str(fr.image[j]))
        # one picture per camera can serve again: a stop's first frame's, kept for a next
        # frame that was not compared, stayed to the end (one picture per stop; a review)
        keep = {*last_seen.values(), image_j}
        for old in [k for k in thumbs if k not in keep]:
            del thumbs[old]
        same = _same_picture(image_i, image_j, thumbs, opts)
        thumbs.pop(image_j, None)  # frame j is not compared again
        last_seen[str(fr.side[i])] = image_i
        if same is not None:
            frozen[int(i)] = (
                f"image {image_i} is frozen: {same} as the {fr.side[i]} "
                f"camera's frame before ({str(fr.frame_id[j])!r}, manifest line {fr.row[j]}), so "
                "the camera stopped updating its picture; check the camera and drop the frame"
            )
    return {i: message for i, message in frozen.items() if i in wanted}


def _frame_jobs(
    plan: _Plan,
    pending: list[tuple[str, float, float, NDArray]],
    custom_segmenter: bool,
    bad: dict[str, BadFrame],
    strict: bool,
) -> list[FrameJob]:
    """Segmentation jobs of the frames the pending chunks read and the cache does not hold;
    frames cached as bad are added to ``bad``."""
    fr, cams = plan.survey.frames, _cameras(plan)
    need = (
        np.unique(np.concatenate([plan.frames_of[c[0]] for c in pending]))
        if pending
        else np.array([], int)
    )
    # the angular thin-structure policy reaches the default segmenter only
    thin = {side: (None if custom_segmenter else plan.params.thin_px(c))
            for side, (c, _) in cams.items()}  # fmt: skip
    jobs = []
    frozen = _frozen_frames(plan, need)
    for i in need:
        fid = str(fr.frame_id[i])
        if fid in bad:  # set aside before the segmentation (the capture-time check)
            continue
        if int(i) in frozen:
            message = _at_line(plan, int(i), frozen[int(i)])
            _bad(fid, message, strict)
            bad.setdefault(fid, BadFrame(fid, message))
            continue
        cam = cams[str(fr.side[i])][0]
        job = FrameJob(
            fid, str(join(plan.survey.root, str(fr.image[i]))), int(cam.width_px),
            int(cam.height_px), str(join(plan.cache_dir, f"{fid}.npz")), thin[str(fr.side[i])],
            dict(plan.storage_options), cam.model == "equirect" and not custom_segmenter,
        )  # fmt: skip
        cached = read_cache(job)
        if cached is None:
            jobs.append(job)
        elif isinstance(cached, BadFrame):
            cached = replace(cached, message=_at_line(plan, int(i), cached.message))
            _bad(fid, cached.message, strict, " (as in a run before)")
            bad.setdefault(fid, cached)
    return jobs


def _chunk_jobs(
    plan: _Plan,
    pending: list[tuple[str, float, float, NDArray]],
    bad: dict[str, BadFrame],
    pinned: str | None,
) -> list[ChunkJob]:
    fr, ch, cams = plan.survey.frames, plan.chainage_m, _cameras(plan)
    speed = survey_speed_kmh(ch, fr.gps_s, fr.side)
    p = plan.params
    view = stop_ids(fr.side, ch, p.stop_gap_m, p.stop_span_m)  # as the survey slices them
    # the survey's attitude verdicts: a chunk deciding alone could set aside the IMU that its
    # neighbour trusts, and a frame both read be rectified two ways (a review)
    att = plan.provenance["attitude"]
    verdicts = (bool(att["imu_distrusted"]), bool(att["cant_table_distrusted"]))
    jobs = []
    for name, lo, hi, s in pending:
        idx = plan.frames_of[name]
        known_bad = tuple(
            bad[f] for f in dict.fromkeys(str(fr.frame_id[i]) for i in idx) if f in bad
        )
        frames = tuple(
            ChunkFrame(str(fr.frame_id[i]), str(fr.side[i]), float(ch[i]),
                       str(join(plan.cache_dir, f"{fr.frame_id[i]}.npz")),
                       float(fr.roll_deg[i]), float(fr.pitch_deg[i]), float(speed[i]),
                       int(view[i]))
            for i in idx
            if str(fr.frame_id[i]) not in bad
        )  # fmt: skip
        jobs.append(ChunkJob(
            name, lo, hi, s, frames, cams, bool(plan.survey.reverse),
            float(plan.survey.antenna_height_m), plan.track, plan.params, plan.provenance,
            str(plan.chunk_dir), known_bad, plan.frames_key[name], pinned,
            dict(plan.storage_options), verdicts,
        ))  # fmt: skip
    return jobs


def _merge(
    plan: _Plan,
    ran: set[str],
    bad: dict[str, BadFrame],
    margins: tuple[MarginTable | None, JsonDict],
    dem: Dem | None = None,
    antenna_height_m: float = 4.0,
    pinned: str | None = None,
) -> tuple[MaskSet, JsonDict]:
    """The chunks merged into one mask set (margins applied, holes closed, raised to the
    terrain) and its provenance; bad frames met by the chunks are added to ``bad``."""
    parts = []
    opts = plan.storage_options
    for name, *_ in plan.chunks:
        with input_path(join(plan.chunk_dir, f"{name}.parquet"), opts) as chunk_file:
            # this run's own chunks: a file's warnings (spacing, units) are for the merged
            # file's readers, once, not once per chunk (a review)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MaskFileWarning)
                parts.append(read_masks(chunk_file, close_holes=False))  # closed below
        marker = json.loads(read_bytes(join(plan.chunk_dir, f"{name}.json"), opts).decode())
        for b in marker.get("bad_frames", []):
            if b["frame_id"] not in bad:  # not reported yet: met by a chunk, or a run before
                bad[b["frame_id"]] = BadFrame(**b)
                when = "" if name in ran else " (as in a run before)"
                _report(f"bad frame {b['frame_id']}: {b['message']} - skipped{when}", quiet=False)
    final_prov = {
        **plan.provenance,
        "chunks": [c[0] for c in plan.chunks],
        "n_frames": plan.n_frames,
        "bad_frames": len(bad),
        "created_utc": utc_stamp(pinned),
    }
    table, record = margins
    if table is not None:
        final_prov["margins"] = record
    merged = concat_masksets(parts, final_prov)
    if table is not None:
        merged = table.apply(merged)
    merged, gaps = close_gaps(merged, plan.track)
    if gaps:
        holes = ", ".join(f"{a:.0f}-{b:.0f} m" for a, b in gaps)
        _report(
            f"warning: the survey has {len(gaps)} hole(s) between surveyed positions ({holes}): "
            "closed (90 deg mask, source ASSUMED), nothing is trusted there; survey them again "
            "or replace their bad frames",
            quiet=False,
        )
        merged = replace(merged, provenance={**merged.provenance, "gaps_closed_m": gaps})
        final_prov["gaps_closed_m"] = gaps
    if dem is not None:
        hz = bin_terrain(merged, dem, antenna_above_ground_m=antenna_height_m)
        merged = raise_to_terrain(merged, hz, dem_source=dem.source)
        final_prov["terrain"] = merged.provenance["terrain"]
        if not np.isfinite(hz.el_deg).any():
            _report(f"warning: the elevation tiles ({dem.source}) do not cover the line: no bin "
                    "was bounded by the terrain", quiet=False)  # fmt: skip
        for note in coverage_notes(merged, hz, dem.source):
            _report(f"warning: {note}", quiet=False)
    return merged, final_prov


#: A stretch of this length whose bins are mostly assumed is reported by :func:`source_report`.
ASSUMED_STRETCH_M = 200.0


def source_report(
    masks: MaskSet, *, stretch_m: float = ASSUMED_STRETCH_M, track: TrackMap | None = None
) -> list[str]:
    """Lines on where the bins' values come from: the share of observed, reconstructed,
    terrain and assumed bins, and a warning per stretch of ``stretch_m`` whose bins are more
    than half assumed (a guess: survey it again, or give elevation tiles). A stretch mostly in
    a tunnel of ``track`` (:meth:`TrackMap.in_tunnel`) is said to be one instead: no sky there
    to see, and neither a new survey nor a DEM would change its closed masks."""
    names = {int(c): c.name.lower() for c in BinSource}
    shares = ", ".join(f"{100.0 * float((masks.source == c).mean()):.1f} % {n}"
                       for c, n in names.items())  # fmt: skip
    lines = [f"mask bins: {shares}"]
    assumed = (masks.source == BinSource.ASSUMED).mean(axis=1)
    tunnel = (np.zeros(masks.n_pos, bool) if track is None
              else np.asarray(track.in_tunnel(masks.chainage_m), bool))  # fmt: skip
    edges = np.arange(masks.chainage_m[0], masks.chainage_m[-1] + stretch_m, stretch_m)
    k = np.clip(np.searchsorted(edges, masks.chainage_m, side="right") - 1, 0, None)
    for j in np.unique(k):
        share = float(assumed[k == j].mean())
        end = min(edges[j] + stretch_m, masks.chainage_m[-1])
        if share > 0.5 and track is not None and tunnel[k == j].mean() > 0.5:
            lines.append(
                f"chainage {edges[j]:.0f}-{end:.0f} m: in a tunnel of track {track.name!r} "
                f"({100 * share:.0f} % of the bins assumed): no sky to see, nothing is trusted "
                "there"
            )  # fmt: skip
        elif share > 0.5:
            fix = ("survey it again (the elevation tiles given bound none of these bins)"
                   if masks.provenance.get("terrain") else
                   "survey it again or give elevation tiles (--dem)")  # fmt: skip
            where = "" if track is None or track.tunnels_m else (
                f"; track {track.name!r} tags no tunnel: if this is one, give a track file "
                "with its tunnel=* ways (--track)")  # fmt: skip
            lines.append(
                f"warning: chainage {edges[j]:.0f}-{end:.0f} m: {100 * share:.0f} % of the bins "
                f"are assumed (no camera saw them); {fix}{where}"
            )
    raised = _raised_horizon_deg(masks)
    if raised is not None:
        head = (
            f"warning: the cameras saw no horizon lower than {raised[0]:.1f} deg at half the "
            f"positions (the 10th percentile of each position's observed bins), above the "
            f"{raised[1]:g} deg the far field is assumed at where no camera saw it "
            f"({100 * float(assumed.mean()):.1f} % of the bins)"
        )
        if (masks.source == BinSource.TERRAIN).any():
            # the tiles raised what they hold; what stays assumed stood above their terrain
            # only where the DEM cannot see it: walls, cuttings or buildings just beyond the
            # corridor (a user trial's canyon: a 40 m rock wall 250-300 m behind the train,
            # 0.118 % of the assumed bins trusted falsely, nothing said)
            lines.append(
                f"{head}: the elevation tiles bound the terrain, not walls, cuttings or "
                "buildings just beyond the corridor that a DEM's cells do not resolve, and "
                "these bins stay at the assumed value; calibrate a margin for them (predisat "
                "evaluate --calibrate, process --margins) or survey the stretch with a cab or "
                "360 rig (docs/rigs.md)"
            )
        else:
            lines.append(
                f"{head}: the horizon rises around the line (hills, or buildings beyond the "
                "corridor), and the assumed bins may stand below it; give elevation tiles "
                "(process --dem, docs/terrain.md), or survey the stretch with a cab or 360 rig "
                "(docs/rigs.md)"
            )
    return lines


RAISED_HORIZON_DEG = 3.0
"""How far above the assumed far field the lowest observed skylines (the 10th percentile of a
position's observed bins, the median over the positions) must stand for ``process`` to say the
land rises around the line: 9.4 deg over a 5 deg default in the Var valley world, where the
assumed bins trusted 0.097 % falsely without elevation tiles; 4.3 deg on the demo's flat
line."""


def _raised_horizon_deg(masks: MaskSet) -> tuple[float, float] | None:
    """(the lowest observed horizon, the far-field default) when the first stands more than
    :data:`RAISED_HORIZON_DEG` above the second at half the positions and some bins are
    assumed, still at the default (not raised to the terrain); else None."""
    src = masks.source
    params = masks.provenance.get("params")
    rec = params.get("reconstruction") if isinstance(params, dict) else None
    default = float(rec.get("far_default_deg", 5.0)) if isinstance(rec, dict) else 5.0
    at_default = (src == BinSource.ASSUMED) & (masks.mask_el_deg <= default + 0.01)
    if not at_default.any():
        return None
    seen = np.where(src == BinSource.OBSERVED, masks.mask_el_deg, np.nan)
    rows = np.isfinite(seen).sum(axis=1) >= 0.1 * masks.n_az
    if not rows.any():
        return None
    low = float(np.median(np.nanpercentile(seen[rows], 10, axis=1)))
    return (low, default) if low > default + RAISED_HORIZON_DEG else None


def _check_reachable(survey: Survey | str | os.PathLike[str], out: Location,
                     where: Scheduler) -> None:  # fmt: skip
    """Refuse ``memory://`` with worker processes: that file system is this process's
    memory, which a worker process does not see."""
    root = survey.root if isinstance(survey, Survey) else location(survey)
    for what, loc in (("survey", root), ("--out", out)):
        if is_remote(loc) and str(loc).startswith("memory://") and where.kind != "serial":
            raise ValueError(
                f"{what} {loc}: memory:// lives in this process, and the {where.describe()}'s "
                "worker processes cannot read it; use --scheduler serial, or shared storage"
            )


def _sky_net_absolute(params: PipelineParams) -> PipelineParams:
    """``params`` with its sky network's local path made absolute (a worker resolves a
    relative one in its own working folder)."""
    if params.sky_net is None:
        return params
    return replace(params, sky_net=absolute(params.sky_net))


_P = ParamSpec("_P")
_R = TypeVar("_R")


def _one_writer(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``fn`` (whose second argument is the output folder) holding the folder's lock
    (:func:`predisat.atomic.exclusive_folder`): a second run into the same local folder is
    refused at once instead of redoing the work and racing the first on its files (a user
    trial). A folder made here and left empty by a refusal is removed again."""

    @functools.wraps(fn)
    def locked(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        out = location(args[1] if len(args) > 1 else kwargs["out_dir"])  # type: ignore[arg-type]
        if not isinstance(out, Path):  # a URL: object stores have no lock
            return fn(*args, **kwargs)
        made = not out.exists()
        out.mkdir(parents=True, exist_ok=True)
        try:
            with exclusive_folder(out):
                return fn(*args, **kwargs)
        except BaseException:
            if made:
                (out / LOCK_NAME).unlink(missing_ok=True)
                with contextlib.suppress(OSError):
                    out.rmdir()  # only if nothing else was written
            raise

    return locked


@_one_writer
def process_survey(
    survey: Survey | str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    params: PipelineParams | None = None,
    *,
    track: TrackMap | None = None,
    workers: int | None = None,
    scheduler: Scheduler | str | None = None,
    strict: bool = False,
    progress: bool = True,
    segmenter: Segmenter | None = None,
    max_chunks: int | None = None,
    margins: MarginTable | str | os.PathLike[str] | None = None,
    replace: bool = False,
    dem: Dem | None = None,
    storage_options: StorageOptions | None = None,
    created_utc: str | None = None,
) -> ProcessResult:
    """Process a survey folder into masks, in resumable chainage chunks.

    Parameters
    ----------
    survey : path-like, str or predisat.survey.Survey
        The survey folder (loaded with ``on_error="skip"``; rejected frames are bad frames):
        a local path or an fsspec URL (``file://``, ``http(s)://``, ``s3://``...;
        :mod:`predisat.storage`).
    out_dir : path-like or str
        Output folder: ``masks.parquet``, ``provenance.json``, ``bad_frames.csv``,
        ``chunks/``, ``cache/``. Reusing it resumes an interrupted run. A local path or a
        writable fsspec URL (``s3://``, ``memory://`` with the serial scheduler...).
    params : PipelineParams, optional
    track : TrackMap, optional
        Track to use instead of the one named in ``survey.yaml``.
    workers : int, optional
        Worker processes of a local Dask cluster (``scheduler="local"``, or ``workers > 1``
        without ``scheduler``); default: the machine's cores with ``"local"``, else 1.
    scheduler : predisat.scheduler.Scheduler or str, optional
        Where the tasks (batches of frames, chainage chunks) run: ``"serial"`` (this process),
        ``"local"`` (a local Dask cluster) or a Dask scheduler's address; default serial when
        ``workers`` is None or 1, else local (:meth:`~predisat.scheduler.Scheduler.parse`).
        The results are the same byte for byte wherever they run.
    strict : bool
        Stop with :class:`BadFrameError` at the first bad frame instead of skipping it.
    progress : bool
        tqdm progress bars and console messages on stderr.
    segmenter : callable, optional
        Image -> (sky mask, confidence); default :func:`default_segmenter`. Must be
        picklable (a module-level function) on a Dask cluster. Give it a distinct
        ``params.segmenter`` name, which keys the cache.
    max_chunks : int, optional
        Compute at most this many pending chunks; when chunks remain, stop without merging by
        raising :class:`RunStopped` (simulates an interrupted run). ``None``: all.
    margins : predisat.masks.margins.MarginTable or path-like, optional
        Calibrated trust margins (``predisat evaluate --calibrate`` writes ``margins.json``),
        written per bin into the mask file's ``margin_deg`` and recorded in its provenance.
        They are applied at the merge, so changing them redoes no chunk. Default: 0 deg.
    replace : bool
        Whether chunks of another survey (or of another version of this survey's
        ``survey.yaml``, manifest or calibrations) found in ``out_dir/chunks`` are deleted;
        without it such a folder is refused before any work (:class:`OutputInUseError`). Either
        way, a finished run leaves only its own chunks there.
    dem : predisat.terrain.Dem, optional
        Elevation tiles bounding the far field from below: at the merge every bin below the
        terrain horizon is raised to it and flagged ``TERRAIN``
        (:func:`predisat.masks.terrain.raise_to_terrain`); like the margins, changing it redoes
        no chunk.
    storage_options : mapping, optional
        Options of the fsspec file system of the survey's and the output's URLs
        (credentials, endpoint...); handed to the tasks with the URLs.
    created_utc : str, optional
        The time stamped in the provenance (ISO 8601 UTC); default ``SOURCE_DATE_EPOCH``'s
        when set, else now. ``predisat network`` hands its own process's down, so that a
        line processed on a cluster's worker is stamped as a serial run would be.

    Returns
    -------
    ProcessResult

    Raises
    ------
    BadFrameError
        With ``strict=True``, naming the first bad frame.
    OutputInUseError
        ``out_dir`` holds another survey's chunks and ``replace`` is False.
    predisat.survey.SurveyError
        When the survey itself (survey.yaml, calibrations, manifest) is unusable.
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    pinned = created_utc if created_utc is not None else pinned_utc()
    p = params or PipelineParams()
    where = scheduler if isinstance(scheduler, Scheduler) else Scheduler.parse(scheduler, workers)
    if where.kind == "serial" and where.workers > 1:
        # the segmenters and reconstructors are not thread-safe (one OpenCV network each)
        raise ValueError(
            f"--scheduler serial runs in this process alone, not with --workers {where.workers}"
            "; leave --workers out, or use --scheduler local for worker processes"
        )
    if where.kind == "address":  # a worker resolves a relative path in its own folder
        if isinstance(survey, Survey):
            if isinstance(survey.root, Path) and not survey.root.is_absolute():
                raise ValueError(
                    f"survey {survey.root}: a relative folder on a cluster by address (its "
                    "workers would look for it in their own folders); load it by its absolute "
                    "path"
                )
        else:
            survey = absolute(survey)
        out_dir = absolute(out_dir)
        p = _sky_net_absolute(p)
    margin_table = _load_margins(margins)  # before hours of work, not after
    seg_fn = _segmenter_for(p, segmenter)
    quiet = not progress
    opts = dict(storage_options or {})
    out = location(out_dir)
    _check_reachable(survey, out, where)
    if where.kind == "address":
        # a mistyped address, or a cluster the tasks would go wrong on, is refused now: not
        # after the planning (hours on an object store) and the withdrawal of the finished
        # run's files (a user trial: a port where nothing listens deleted its masks.parquet)
        root = survey.root if isinstance(survey, Survey) else location(survey)
        seen = [str(root), str(out), *([] if p.sky_net is None else [p.sky_net])]
        with TaskRunner(where, code_version=code_fingerprint, paths=seen) as probe:
            probe.client()
    if not isinstance(survey, Survey):
        survey = Survey.load(survey, track=track, check_images=False, on_error="skip",
                             storage_options=opts)  # fmt: skip
    # a calibration of another resolution is the survey's problem, not every frame's
    check_calibration_sizes(survey)
    if track is not None:  # another track than the survey's own: it must follow it
        check_survey_track(survey, track)
    trk = track if track is not None else survey.track
    if trk is None:
        raise ValueError(
            f"survey {survey.root} names no track file; pass track= (CLI: --track FILE)"
        )
    p, ch, notes = _resolved_params(p, survey, trk)
    bad = _load_bad_frames(survey, ch, strict)
    plan = _plan(survey, trk, p, out, ch, opts)
    foreign = _foreign_chunks(plan.chunk_dir, plan.provenance["survey_hash"], opts)
    if foreign and not replace:
        others = sorted(set(foreign.values()))
        raise OutputInUseError(
            f"{out} holds {len(foreign)} chunk(s) of another survey ({', '.join(others)}; or of "
            f"an earlier version of {survey.root}: its survey.yaml, manifest or calibrations "
            "changed), which cannot be reused; give another output folder, or replace them "
            "(CLI: --replace)"
        )
    withdrawn = _withdraw_published(out, plan.provenance["run_key"], opts)
    _remove_chunks(plan.chunk_dir, set(foreign), opts)
    timings["load"] = time.perf_counter() - t0
    pending, skipped = _pending(plan, strict, max_chunks)
    if withdrawn:  # a user trial saw "(0 already done)" and no word of the finished run
        _report(
            f"note: {out} held the masks of a finished run with other settings, code or "
            "inputs: its masks.parquet, provenance.json and bad_frames.csv are withdrawn, and "
            "its chunks are redone where they differ",
            quiet=False,
        )
    _report(
        f"{survey.root}: {plan.n_frames} frames, {plan.positions_m.size} positions, "
        f"{len(plan.chunks)} chunks ({skipped} already done)",
        quiet,
    )
    for line in _attitude_warnings(plan.provenance["attitude"]):
        _report(line, quiet=False)
    for side, (n_frames, n_stops) in stop_counts(
        survey.frames.side, ch, p.stop_gap_m, p.stop_span_m
    ).items():
        _report(
            f"note: the {side} camera has {n_frames} frames merged into {n_stops} view(s) "
            f"(frames within {p.stop_gap_m:g} m of each other and {p.stop_span_m:g} m in all, "
            "captured on time: a stop, or a slice of a slow crawl): each view's frames give "
            "sky only where all of them saw it (docs/reconstruction.md, section 24)",
            quiet=False,
        )
    for line in camera_pair_warnings(survey):
        _report(line, quiet=False)
    for note in notes:
        if note is not None:
            _report(note, quiet=False)
    beside = _beside_track(survey, trk)
    if beside is not None:
        plan.provenance["survey_beside_track"] = beside
        for line in beside_track_notes(plan.provenance):
            _report(f"warning: {survey.root}: {line}", quiet=False)
    capture = _capture_check(plan, bad)
    plan.provenance["capture_check"] = capture
    for line in _capture_warnings(capture):
        _report(line, quiet=False)
    _set_aside(bad, _capture_bad_frames(capture), "capture", strict)
    jobs = _frame_jobs(plan, pending, segmenter is not None, bad, strict)

    # one runner for both stages (a cluster is started when there is work for it)
    seen = [str(survey.root), str(out), *([] if p.sky_net is None else [p.sky_net])]
    runner = TaskRunner(where, code_version=code_fingerprint, paths=seen)
    try:
        t1 = time.perf_counter()
        n_seg = 0
        index = {str(f): k for k, f in enumerate(survey.frames.frame_id)}
        for fid, problem in run_segmentation(jobs, runner, seg_fn, progress):
            n_seg += 1
            if problem is not None:
                problem = _at_line(plan, index[fid], problem)
                _bad(fid, problem, strict)
                bad.setdefault(fid, BadFrame(fid, problem))
        timings["segment"] = time.perf_counter() - t1
        check, step = _frame_checks(plan, bad)
        plan.provenance["side_check"], plan.provenance["step_check"] = check, step
        for line in _side_warnings(check) + _step_warnings(step, capture):
            _report(line, quiet=False)
        _set_aside(bad, _step_bad_frames(step), "step", strict)
        lens = _lens_check(plan, bad)
        plan.provenance["lens_check"] = lens
        for line in _lens_warnings(lens):
            _report(line, quiet=False)
        _set_aside(bad, _lens_bad_frames(lens), "lens", strict)
        _set_aside(bad, _side_bad_frames(check), "side", strict)
        _refuse_when_every_frame_is_bad(survey, bad)
        t2 = time.perf_counter()
        run_chunks(_chunk_jobs(plan, pending, bad, pinned), runner, progress)
        timings["reconstruct"] = time.perf_counter() - t2
    finally:
        runner.close()
    if max_chunks is not None and skipped + len(pending) < len(plan.chunks):
        raise RunStopped(f"stopped after {len(pending)} chunk(s) (max_chunks)")

    t3 = time.perf_counter()
    # the run's record withdrawn before the merge: margins and terrain, applied there, are not
    # in the run key, and a merge stopped with other margins left the old masks and record
    # looking finished (a review)
    remove(join(out, "provenance.json"), opts)
    merged, final_prov = _merge(plan, {c[0] for c in pending}, bad, margin_table, dem,
                                p.reconstruction.antenna_height_m, pinned)  # fmt: skip
    for line in source_report(merged, track=plan.track):
        _report(line, quiet=quiet and not line.startswith("warning"))
    bad_list = tuple(sorted(bad.values(), key=lambda b: b.frame_id))
    lacking = _lacking_side_positions(plan, np.asarray(merged.chainage_m, float), bad)
    if lacking:
        final_prov["positions_lacking_side"] = lacking
        merged = _with_provenance(merged, positions_lacking_side=lacking)
        _report(
            f"warning: {len(lacking)} position(s) lack a side camera's own frame within "
            f"{plan.params.reconstruction.position_tol_m:g} m at chainage "
            f"{_spans_text(lacking)} (frames set aside: bad_frames.csv; rows missing from the "
            "manifest; or side cameras that do not fire together): only the camera on a "
            "mast's side sees its cantilever over the antenna, so the clearance over the "
            "track there is taken as blocked and those positions trust little or no sky "
            "(docs/reconstruction.md, section 23); listed in the masks' provenance "
            "(positions_lacking_side)",
            quiet=False,
        )
    masks_path = join(out, "masks.parquet")
    # the record (withdrawn above) written last: a full disk between left the new mask file
    # beside the previous run's provenance.json (a user trial)
    if isinstance(masks_path, Path):
        write_masks(merged, masks_path)
    else:
        with output_path(masks_path, opts) as tmp:
            write_masks(merged, tmp)
    stale = _stale_chunks(plan.chunk_dir, {c[0] for c in plan.chunks}, opts)
    _remove_chunks(plan.chunk_dir, stale, opts)
    write_bad_frames(join(out, "bad_frames.csv"), bad_list, opts)
    timings["merge"] = time.perf_counter() - t3
    elapsed = time.perf_counter() - t0
    final_prov["bad_frame_list"] = [asdict(b) for b in bad_list]
    final_prov["timings_s"] = timings
    write_atomic(join(out, "provenance.json"), json.dumps(final_prov, indent=1).encode(), opts)
    return ProcessResult(
        out, masks_path, merged, plan.n_frames, len(pending), skipped, n_seg, bad_list,
        elapsed, timings,
    )  # fmt: skip


def _record_difference(record: object, now: object, key: str = "params") -> str | None:
    """The first entry where ``now`` (JSON-like) differs from ``record``, as ``key.sub``,
    else None; entries the record lacks (settings newer than the run) are not compared."""
    if isinstance(record, dict) and isinstance(now, dict):
        for k, v in record.items():
            if k in now:
                found = _record_difference(v, now[k], f"{key}.{k}")
                if found is not None:
                    return found
        return None
    return None if record == now else f"{key} (the run's {record!r}, now {now!r})"


def finished_chunk_jobs(
    out_dir: str | os.PathLike[str],
    survey: Survey | str | os.PathLike[str],
    *,
    params: PipelineParams | None = None,
    track: TrackMap | None = None,
    lo_m: float = -math.inf,
    hi_m: float = math.inf,
    storage_options: StorageOptions | None = None,
) -> list[ChunkJob]:
    """The chunk jobs of a finished :func:`process_survey` run whose chunks meet the chainage
    window ``[lo_m, hi_m]``, rebuilt as the run built them: the same frames (its bad frames left
    out, as the run left them out), the same resolved parameters and attitude verdicts, the
    same segmentation cache. :func:`~predisat.reconstruct.chunks.chunk_inputs` of a job gives
    the frames, positions and settings the run's reconstruction of that chunk ran on, so that a
    diagnosis reconstructs the published masks (``masks.parquet`` before its margins, terrain
    and closed gaps) rather than its own.

    Parameters
    ----------
    out_dir : path-like or str
        The run's output folder (its ``provenance.json`` and ``cache/``).
    survey : path-like, str or predisat.survey.Survey
        The survey the run processed (loaded as :func:`process_survey` loads it).
    params : PipelineParams, optional
        The parameters the run was given; default: those its ``provenance.json`` records (a run
        with a cant table needs them given). Checked against the record.
    track : TrackMap, optional
        The track the run was given instead of the survey's own.
    lo_m, hi_m : float
        The chainage window, metres; default: every chunk.
    storage_options : mapping, optional
        Options of the fsspec file system of URLs.

    Returns
    -------
    list of ChunkJob
        In chainage order; their ``chunk_dir`` is the run's, so do not run them
        (:func:`~predisat.reconstruct.chunks.run_chunk` would rewrite its chunks): take their
        :func:`~predisat.reconstruct.chunks.chunk_inputs`.

    Raises
    ------
    ValueError
        ``out_dir`` holds no finished run, or one of another survey, track, parameters or
        segmentation code; the message names the fix.

    Warns
    -----
    UserWarning
        When other code made the run (its ``code_fingerprint``): the frames are rebuilt, but
        today's reconstruction of them may differ from its masks (a panorama run made 3 hours
        earlier on the same day: by up to 87 deg); rerun ``predisat process`` into the folder (its
        segmentation cache is reused) to diagnose today's code.
    """
    if not lo_m <= hi_m:
        raise ValueError(f"lo_m ({lo_m}) must not exceed hi_m ({hi_m}); give the window in "
                         "increasing chainage")  # fmt: skip
    opts = dict(storage_options or {})
    out = location(out_dir)
    record_file = join(out, "provenance.json")
    try:
        record: JsonDict = json.loads(read_bytes(record_file, opts))
    except (OSError, ValueError) as exc:
        raise ValueError(
            f"{record_file} does not read ({exc}): out_dir must be the folder of a finished "
            "predisat process run; run it to the end first"
        ) from None
    if not isinstance(survey, Survey):
        survey = Survey.load(survey, track=track, check_images=False, on_error="skip",
                             storage_options=opts)  # fmt: skip
    if track is not None:
        check_survey_track(survey, track)
    trk = track if track is not None else survey.track
    if trk is None:
        raise ValueError(
            f"survey {survey.root} names no track file; pass track= (the track the run used)"
        )
    if record.get("survey_hash") != survey_hash(survey):
        raise ValueError(
            f"{out}: the run processed another survey, or an earlier version of {survey.root} "
            "(its survey.yaml, manifest or calibrations changed); give the survey it processed"
        )
    if isinstance(trk, TrackMap) and record.get("track_key", "") not in ("", track_key(trk)):
        raise ValueError(
            f"{out}: the run used another track than {trk.name!r}; pass track= (the one the "
            "run was given)"
        )
    if record.get("code_fingerprint") != code_fingerprint():
        warnings.warn(
            f"{out}: the run was made by other code (fingerprint {record.get('code_fingerprint')}"
            f", now {code_fingerprint()}): its frames are rebuilt, but today's reconstruction "
            "of them may differ from its masks; rerun predisat process into the folder (the "
            "segmentation cache is reused) to diagnose today's code",
            stacklevel=2,
        )
    if not isinstance(record.get("params"), dict):
        raise ValueError(f"{record_file} records no parameters: out_dir must be the folder of a "
                         "finished predisat process run; run it to the end first")  # fmt: skip
    given = (params if params is not None
             else PipelineParams.from_record(record["params"], str(record_file)))
    p, ch, _ = _resolved_params(given, survey, trk)
    params_dict = p.to_dict()
    differs = _record_difference(record["params"], json.loads(json.dumps(params_dict)))
    if differs is not None:
        raise ValueError(
            f"{out}: the run was made with other parameters: {differs}; pass params= as the "
            "run was given them"
        )
    cache_dir = _cache_dir(out, p, params_dict)
    if not exists(cache_dir, opts):
        raise ValueError(
            f"{cache_dir}: no segmentation cache of this code (the segmentation changed since "
            "the run, or its cache was removed); rerun predisat process into the folder"
        )
    finite = np.isfinite(ch)
    positions = np.unique(ch[finite])
    chunks, frames_of = _chunk_windows(survey.frames, ch, positions, p)
    # the frames the run set aside before its chunks ran; the fusion's suspects were not: the
    # reconstruction left them out itself
    bad = {
        str(b["frame_id"]): BadFrame(**b)
        for b in record.get("bad_frame_list", []) if b.get("stage") != "fusion"
    }  # fmt: skip
    plan = _Plan(survey, trk, p, ch, positions, chunks, frames_of,
                 {name: "" for name in frames_of}, record, join(out, "chunks"), cache_dir,
                 opts)  # fmt: skip
    window = [c for c in chunks if c[1] <= hi_m and c[2] > lo_m]
    # each chunk's own marker says which frames it set aside (a cache that did not read in one
    # chunk was read by its neighbour: the run's list would leave it out of both, m9)
    return [job for c in window
            for job in _chunk_jobs(plan, [c], _chunk_bad(out, c[0], opts, bad), None)]


def _chunk_bad(
    out: Location, name: str, opts: StorageOptions, fallback: dict[str, BadFrame]
) -> dict[str, BadFrame]:
    """The frames chunk ``name`` of a finished run set aside before its reconstruction (its
    marker's ``bad_frames``, the fusion's suspects left out), or ``fallback`` without one."""
    try:
        done = json.loads(read_bytes(join(out, "chunks", f"{name}.json"), opts))
    except (OSError, ValueError):
        return fallback
    return {str(b["frame_id"]): BadFrame(**b)
            for b in done.get("bad_frames", []) if b.get("stage") != "fusion"}  # fmt: skip
