"""Processing a network line by line into one mask dataset, resumable, on the scheduler.

:func:`process_network` takes a :class:`~predisat.track.network.Network` and a folder of
surveys keyed by line (``SURVEYS/<part key>/``, :func:`predisat.track.network.part_key`: the
URI-encoded line id, ``.part<k>`` for a line in several parts) and runs one task per line
part on a :class:`predisat.scheduler.TaskRunner`: :func:`~predisat.reconstruct.batch.
process_survey` of that survey on the line's own track map (serially inside the task), into
``OUT/lines/<part key>/`` (its chunks, cache, bad frames), then the masks into the dataset
``OUT/masks/line=<id>/part=<k>/masks.parquet`` (:mod:`predisat.masks.dataset`).

* A line part without a survey folder is listed (status ``"no survey"``), never dropped in
  silence; a survey folder matching no line is listed too.
* A line whose survey cannot be processed (unusable survey, no frame on the track) is listed
  with the error (status ``"failed"``) and the others go on; ``strict=True`` stops there.
* **Resume.** A finished line part writes ``OUT/lines/<part key>/line.json`` last, with its
  key: survey hash, every image's size and modification time, the line's geometry, the
  parameters, the margins and the code. A rerun skips a part whose key and partition file
  are unchanged (status ``"resumed"``); an interrupted part resumes inside
  :func:`process_survey` from its finished chunks.

Every task runs the same serial code, so the dataset is the same bytes wherever the tasks ran
(with ``SOURCE_DATE_EPOCH`` pinning the timestamps). See ``docs/network.md``.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from predisat import __version__
from predisat.atomic import exclusive_folder, storage_errno, write_bytes_atomic
from predisat.clock import pinned_utc
from predisat.jsontypes import JsonDict
from predisat.masks.dataset import partition_path, write_partition
from predisat.reconstruct.batch import process_survey, source_report
from predisat.reconstruct.framecache import code_fingerprint, frames_key, survey_hash
from predisat.reconstruct.frames import Segmenter
from predisat.reconstruct.params import PipelineParams
from predisat.scheduler import Scheduler, TaskRunner
from predisat.storage import join
from predisat.survey import Survey, SurveyError
from predisat.track.map import TrackMap
from predisat.track.network import Network, track_key

__all__ = ["LineResult", "NetworkResult", "process_network"]

Status = Literal["done", "resumed", "no survey", "failed"]


@dataclass(frozen=True)
class LineResult:
    """What happened to one line part.

    Attributes
    ----------
    line_id : str
    part : int
        1-based part of the line.
    key : str
        Folder name of its survey and outputs (:func:`predisat.track.network.part_key`).
    status : {"done", "resumed", "no survey", "failed"}
    length_m : float
        Length of the part's track map.
    masks_path : Path or None
        Its partition file in the dataset (None unless done or resumed).
    n_pos, n_frames, n_bad_frames : int
    from_m, to_m : float
        Chainage of the first and last mask position on the part (NaN without masks).
    elapsed_s : float
    message : str
        The error of a failed part; where the survey was looked for when missing; the
        processing's warnings of a done or resumed one (assumed stretches, a raised horizon).
    """

    line_id: str
    part: int
    key: str
    status: Status
    length_m: float
    masks_path: Path | None = None
    n_pos: int = 0
    n_frames: int = 0
    n_bad_frames: int = 0
    from_m: float = float("nan")
    to_m: float = float("nan")
    elapsed_s: float = 0.0
    message: str = ""


@dataclass(frozen=True)
class NetworkResult:
    """What :func:`process_network` did.

    Attributes
    ----------
    out_dir, dataset_dir : Path
    lines : tuple of LineResult
        One per line part, in network order.
    unmatched_surveys : tuple of str
        Folders of the surveys folder that match no line part.
    elapsed_s : float
    scheduler : str
    """

    out_dir: Path
    dataset_dir: Path
    lines: tuple[LineResult, ...]
    unmatched_surveys: tuple[str, ...]
    elapsed_s: float
    scheduler: str

    def by_status(self, status: Status) -> tuple[LineResult, ...]:
        return tuple(r for r in self.lines if r.status == status)

    def __str__(self) -> str:
        counts = {s: len(self.by_status(s)) for s in ("done", "resumed", "no survey", "failed")}
        frames = sum(r.n_frames for r in self.lines if r.status == "done")
        return (
            f"{len(self.lines)} line part(s): {counts['done']} processed, {counts['resumed']} "
            f"already done, {counts['no survey']} without a survey, {counts['failed']} failed; "
            f"{frames} frames in {self.elapsed_s:.1f} s ({self.scheduler}) -> {self.dataset_dir}"
        )


@dataclass(frozen=True)
class _Unit:
    line_id: str
    part: int
    key: str
    track: TrackMap
    survey_dir: str


@dataclass(frozen=True)
class _Shared:
    out_dir: str
    params: PipelineParams
    margins: str | None
    margins_sha256: str
    strict: bool
    segmenter: Segmenter | None
    created_utc: str | None = None  # the client's SOURCE_DATE_EPOCH time, for every line


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _part_key(shared: _Shared, unit: _Unit, survey: Survey) -> JsonDict:
    fr = survey.frames
    frames = frames_key(
        (str(f) for f in fr.frame_id), (str(join(survey.root, str(i))) for i in fr.image)
    )
    return {
        "line_id": unit.line_id,
        "part": unit.part,
        "survey_hash": survey_hash(survey),
        "frames_key": frames,
        "track_key": track_key(unit.track),
        "params": shared.params.to_dict(),
        "margins_sha256": shared.margins_sha256,
        "software_version": str(__version__),
        "code_fingerprint": code_fingerprint(),
    }


def _withdraw(out: Path, line_id: str, part: int, key: str) -> str:
    """Move a line part's published masks and availability report of an earlier run out of
    the dataset (a user trial read them back as the line's after its survey had broken):
    ``OUT/masks/line=.../part=k``, ``OUT/lines/<key>/masks.parquet`` and
    ``OUT/availability/<key>`` go to ``OUT/withdrawn/<UTC time>/`` (kept, never deleted; the
    line's chunks and segmentation cache stay for a rerun). What to add to the part's
    message: where they went, how it failed, or "" when there was nothing."""
    part_dir = partition_path(out / "masks", line_id, part).parent
    sources = [part_dir, out / "lines" / key / "masks.parquet", out / "availability" / key]
    if not any(s.exists() for s in sources):
        return ""
    dest = out / "withdrawn" / time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    try:
        for src in sources:
            if src.exists():
                target = dest / src.relative_to(out)
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(src, target)
        line_dir = part_dir.parent
        if line_dir.is_dir() and not any(line_dir.iterdir()):
            line_dir.rmdir()  # no other part left: the line is gone from the dataset
    except OSError as exc:  # a part of the same line on another worker, a full disk
        return (f"; its masks of an earlier run could not all be withdrawn from the dataset "
                f"({exc}): remove {part_dir} before using the dataset")  # fmt: skip
    return (f"; the line's masks and report of an earlier run were withdrawn to {dest} "
            "(they no longer match its survey)")


def _process_unit(shared: _Shared, unit: _Unit) -> LineResult:
    """One line part: process its survey (serially), write its partition, then its marker."""
    t0 = time.perf_counter()
    length = float(unit.track.length_m)
    made = functools.partial(LineResult, unit.line_id, unit.part, unit.key, length_m=length)
    out = Path(shared.out_dir)
    line_out = out / "lines" / unit.key
    marker = line_out / "line.json"
    part_file = partition_path(out / "masks", unit.line_id, unit.part)
    try:
        survey = Survey.load(unit.survey_dir, track=unit.track, check_images=False,
                             on_error="skip")  # fmt: skip
        key = _part_key(shared, unit, survey)
        if marker.is_file() and part_file.is_file():
            old = json.loads(marker.read_text())
            if old.get("key") == key and old.get("masks_sha256") == _sha256(part_file):
                return made(status="resumed", masks_path=part_file,
                                  n_pos=int(old["n_pos"]), n_frames=int(old["n_frames"]),
                                  n_bad_frames=int(old["n_bad_frames"]),
                                  from_m=float(old["from_m"]), to_m=float(old["to_m"]),
                                  elapsed_s=time.perf_counter() - t0,
                                  message="; ".join(old.get("warnings", ())))  # fmt: skip
        res = process_survey(
            survey, line_out, shared.params, track=unit.track, scheduler="serial",
            strict=shared.strict, progress=False, segmenter=shared.segmenter,
            margins=shared.margins, replace=True, created_utc=shared.created_utc,
        )  # fmt: skip
    except (SurveyError, ValueError, OSError) as exc:
        if storage_errno(exc) is not None:  # the machine's storage, not this line: stop the run
            raise
        withdrawn = _withdraw(out, unit.line_id, unit.part, unit.key)
        if shared.strict:
            if withdrawn:
                exc.add_note(withdrawn.removeprefix("; "))
            raise
        return made(status="failed", message=str(exc) + withdrawn,
                          elapsed_s=time.perf_counter() - t0)  # fmt: skip
    path = write_partition(res.masks, out / "masks", unit.line_id, unit.part)
    done = {
        "key": key,
        "masks_sha256": _sha256(path),
        "n_pos": res.masks.n_pos,
        "n_frames": res.n_frames,
        "n_bad_frames": len(res.bad_frames),
        "from_m": float(res.masks.chainage_m[0]),
        "to_m": float(res.masks.chainage_m[-1]),
    }
    # the processing's warnings (assumed stretches, a raised horizon) named with their line
    # in the console and the summary: printed bare among the lines', they were lost
    notes = [ln.removeprefix("warning: ").replace(
        "(process --dem, docs/terrain.md)",
        "(`predisat network` takes none: process this line's survey with `predisat process "
        "--dem`, docs/terrain.md)")
        for ln in source_report(res.masks, track=unit.track) if ln.startswith("warning")]
    notes = [s.replace("give elevation tiles (--dem)", "give elevation tiles (`predisat "
                       "process --dem` of this line's survey)") for s in notes]  # fmt: skip
    done["warnings"] = notes
    write_bytes_atomic(marker, json.dumps(done, indent=1).encode())
    return made(status="done", masks_path=path, n_pos=res.masks.n_pos,
                      n_frames=res.n_frames, n_bad_frames=len(res.bad_frames),
                      from_m=float(res.masks.chainage_m[0]), to_m=float(res.masks.chainage_m[-1]),
                      elapsed_s=time.perf_counter() - t0,
                      message="; ".join(notes))  # fmt: skip


def process_network(
    network: Network,
    surveys_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    params: PipelineParams | None = None,
    *,
    lines: Sequence[str] | None = None,
    scheduler: Scheduler | str | None = None,
    workers: int | None = None,
    strict: bool = False,
    progress: bool = True,
    margins: str | os.PathLike[str] | None = None,
    segmenter: Segmenter | None = None,
) -> NetworkResult:
    """Process every line part with a survey into the mask dataset ``out_dir/masks``.

    Parameters
    ----------
    network : Network
    surveys_dir : path-like
        Folder of survey folders named by line part (:attr:`LineResult.key`).
    out_dir : path-like
        ``masks/`` (the dataset), ``lines/<key>/`` (each part's ``predisat process`` output
        and ``line.json``). Reusing it resumes.
    params : PipelineParams, optional
    lines : sequence of str, optional
        Only these line ids (default: every line of the network).
    scheduler, workers
        Where the line tasks run (:meth:`predisat.scheduler.Scheduler.parse`): ``"serial"``,
        ``"local"`` or a Dask scheduler's address; each task runs its line serially.
    strict : bool
        Stop at the first bad frame or failed line instead of listing it.
    progress : bool
        A progress bar of the line parts (tqdm, stderr).
    margins : path-like, optional
        A margin table (``margins.json``) applied to every line.
    segmenter : callable, optional
        As :func:`~predisat.reconstruct.batch.process_survey` (picklable on a cluster).

    Returns
    -------
    NetworkResult
    """
    from tqdm import tqdm

    t0 = time.perf_counter()
    where = scheduler if isinstance(scheduler, Scheduler) else Scheduler.parse(scheduler, workers)
    # a cluster's worker resolves a relative path in its own working folder
    base = Path(surveys_dir).absolute()
    out_dir = Path(out_dir).absolute()
    margins = None if margins is None else Path(margins).absolute()
    if not base.is_dir():
        raise FileNotFoundError(
            f"{base}: no such surveys folder; give the folder holding one survey folder per line "
            "(named by line id, docs/network.md)"
        )
    chosen = network.lines if lines is None else tuple(network.line(lid) for lid in lines)
    out = Path(out_dir)
    (out / "masks").mkdir(parents=True, exist_ok=True)
    margins_sha = "" if margins is None else _sha256(Path(margins))
    p = params or PipelineParams()
    shared = _Shared(str(out), p, None if margins is None else str(margins), margins_sha,
                     strict, segmenter, pinned_utc())  # fmt: skip
    units: list[_Unit] = []
    results: dict[str, LineResult] = {}
    order: list[str] = []
    for ln in chosen:
        for k, tm in enumerate(ln.parts, start=1):
            key = ln.part_key(k)
            order.append(key)
            folder = base / key
            if (folder / "survey.yaml").is_file():
                units.append(_Unit(ln.line_id, k, key, tm, str(folder)))
            else:
                why = (f"{folder} has no survey.yaml" if folder.is_dir()
                       else f"no survey at {folder}")  # fmt: skip
                why += _withdraw(out, ln.line_id, k, key)  # its survey gone: so are its masks
                results[key] = LineResult(ln.line_id, k, key, "no survey", float(tm.length_m),
                                          message=why)  # fmt: skip
    known = {ln.part_key(k) for ln in network.lines for k in range(1, len(ln.parts) + 1)}
    unmatched = tuple(sorted(d.name for d in base.iterdir() if d.is_dir() and d.name not in known))
    bar = tqdm(total=len(units), desc="network", unit="line", disable=not progress)
    try:
        with exclusive_folder(out), TaskRunner(where, code_version=code_fingerprint,
                                               paths=[str(base), str(out)]) as runner:  # fmt: skip
            for res in runner.map_unordered(_process_unit, shared, units, name="line"):
                results[res.key] = res
                bar.update(1)
    finally:
        bar.close()
    return NetworkResult(out, out / "masks", tuple(results[k] for k in order), unmatched,
                         time.perf_counter() - t0, where.describe())  # fmt: skip
