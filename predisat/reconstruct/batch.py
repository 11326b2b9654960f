"""The ``predisat process`` batch pipeline: survey folder -> mask file, chunked and resumable.

:func:`process_survey` turns a survey folder (``docs/survey-format.md``) into a mask file
(``docs/mask-format.md``) in two stages (``docs/pipeline.md``):

1. **Segmentation** of every frame a pending chunk needs (:func:`predisat.sky.segment.
   segment_sky` by default), each result cached on disk under ``out/cache/`` (packed sky mask
   plus per-column confidence), so overlapping chunks and resumed runs never segment a frame
   twice. A frame whose image is missing, undecodable, of the wrong size or fails to segment is
   a *bad frame*: reported, listed in ``bad_frames.csv`` and skipped (``strict=True`` stops at
   the first instead). Frames the survey loader rejects are bad frames too.
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

:func:`add_process_arguments` / :func:`process_from_args` give the command line.
"""

from __future__ import annotations

import argparse
import csv
import functools
import hashlib
import io
import json
import math
import os
import sys
import time
import zipfile
import zlib
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from predisat.atomic import write_bytes_atomic
from predisat.camera.models import CameraModel, Mount
from predisat.cli.args import output_dir, positive_float, positive_int
from predisat.masks.fileformat import read_masks, write_masks
from predisat.masks.maskset import BinSource, MaskError, MaskSet
from predisat.reconstruct.carving import FrameView, ReconstructionParams, Reconstructor

__all__ = [
    "BadFrame",
    "BadFrameError",
    "PipelineParams",
    "ProcessResult",
    "RunStopped",
    "add_process_arguments",
    "code_fingerprint",
    "concat_masksets",
    "default_segmenter",
    "process_from_args",
    "process_survey",
    "sky_net_sha256",
    "survey_hash",
]

Segmenter = Callable[[NDArray], tuple[NDArray, NDArray | None]]
"""Image (H, W, 3) BGR uint8 -> (sky mask (H, W) bool, per-column confidence (W,) or None)."""

CACHE_VERSION = 1
# chosen by measurement (docs/segmentation.md); the demo and `predisat process` use it
DEFAULT_SEGMENTER = "ensemble"
_CHAINAGE_DECIMALS = 3  # positions closer than 1 mm are one position
THIN_DEG = 0.7  # docs/segmentation.md, "Thin-structure policy": wires and cables, not masts


class BadFrameError(ValueError):
    """A bad frame met with ``strict=True``; the message names the frame and the fix."""


@dataclass(frozen=True)
class BadFrame:
    """A frame skipped by the pipeline.

    Attributes
    ----------
    frame_id : str
    message : str
        What is wrong (and how to fix it).
    stage : str
        ``"load"`` (rejected by the survey loader) or ``"segment"`` (image unreadable or
        segmentation failed).
    """

    frame_id: str
    message: str
    stage: str = "segment"


@dataclass(frozen=True)
class PipelineParams:
    """Settings of :func:`process_survey`.

    Attributes
    ----------
    chunk_m : float
        Chainage length of a chunk; chunk ``k`` holds the positions in
        ``[k * chunk_m, (k + 1) * chunk_m)``. A chunk is reconstructed from the frames within
        ``reconstruction.overlap_m`` (315 m) of it, so short chunks carve frames many times
        over (200 m: ~4x); 1000 m (~1.6x) keeps a resumed run's loss under a minute.
    reconstruction : ReconstructionParams
    segmenter : str
        Segmentation method of :func:`default_segmenter` (one of
        :data:`predisat.sky.segment.METHODS`), recorded in the provenance and the cache key;
        with a custom segmenter function, its own distinct name.
    sky_net : str, optional
        A sky network file (ONNX, with its ``.json`` card beside it, as written by
        ``scripts/train_sky_cnn.py``) used instead of the shipped one by the ``cnn`` and
        ``ensemble`` methods, to try a candidate. Its files' SHA-256 goes into the provenance,
        the resume key and the segmentation cache key, so no result of another network is
        reused.
    thin_deg : float
        The thin-structure policy of the default segmenter in angle: obstacle features at most
        this wide are L-band transparent (``docs/segmentation.md``). Each camera gets
        ``SkyOptions.thin_px = max(1, round(thin_deg / camera.widest_pixel_deg))`` (3 px on the
        demo's 640x480 fisheye): the widest pixel of the frame, so that no feature much wider
        than ``thin_deg`` anywhere in it is made transparent; 0 disables the policy. Custom
        segmenters apply their own.
    """

    chunk_m: float = 1000.0
    reconstruction: ReconstructionParams = field(default_factory=ReconstructionParams)
    segmenter: str = DEFAULT_SEGMENTER
    sky_net: str | None = None
    thin_deg: float = THIN_DEG

    def __post_init__(self) -> None:
        if not (math.isfinite(self.chunk_m) and self.chunk_m > 0):
            raise ValueError(f"chunk_m must be a positive number of metres, got {self.chunk_m}")
        if not (math.isfinite(self.thin_deg) and 0.0 <= self.thin_deg < 10.0):
            raise ValueError(f"thin_deg must lie in [0, 10) degrees (0 disables the "
                             f"thin-structure policy), got {self.thin_deg}")  # fmt: skip
        if self.sky_net is not None:
            from predisat.sky.network import NET_METHODS

            if self.segmenter not in NET_METHODS:
                raise ValueError(
                    f"sky_net {self.sky_net} is used by the segmenters {NET_METHODS}, not by "
                    f"{self.segmenter!r}; choose one of them (CLI: --segmenter ensemble)"
                )

    def thin_px(self, camera: CameraModel) -> int:
        """``SkyOptions.thin_px`` for frames of ``camera`` (see ``thin_deg``)."""
        if self.thin_deg == 0.0:
            return 0
        return max(1, round(self.thin_deg / camera.widest_pixel_deg))

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (recorded in every chunk's provenance)."""
        rec = {
            k: (list(v) if isinstance(v, tuple) else v)
            for k, v in asdict(self.reconstruction).items()
        }
        out: dict[str, Any] = {
            "chunk_m": self.chunk_m, "segmenter": self.segmenter, "reconstruction": rec,
            "thin_deg": self.thin_deg,
        }  # fmt: skip
        if self.sky_net is not None:
            # absent for the shipped network, so the run keys of earlier runs stay valid
            out["sky_net"] = {"path": str(self.sky_net), "sha256": sky_net_sha256(self.sky_net)}
        return out


def sky_net_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a sky network: its ONNX file and its card (the card sets the input size).

    Raises
    ------
    FileNotFoundError
        Naming the missing file.
    """
    from predisat.sky.network import SkyNet

    net = SkyNet.load(path)  # checks both files and the card
    h = hashlib.sha256()
    for f in (net.path, net.path.with_suffix(".json")):
        h.update(f.read_bytes())
    return h.hexdigest()


@dataclass(frozen=True)
class ProcessResult:
    """What :func:`process_survey` did.

    Attributes
    ----------
    out_dir, masks_path : Path
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

    out_dir: Path
    masks_path: Path
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
        ) + (f"; bad frames listed in {self.out_dir / 'bad_frames.csv'}" if self.bad_frames else "")


# ---------------------------------------------------------------------- segmentation + cache
def default_segmenter(
    image_bgr: NDArray,
    method: str | None = None,
    sky_net: str | None = None,
    thin_px: int | None = None,
) -> tuple[NDArray, NDArray | None]:
    """:func:`predisat.sky.segment.segment_sky`: sky mask and per-column confidence.

    ``method`` is one of :data:`predisat.sky.segment.METHODS` (default: ``SkyOptions``'s);
    ``sky_net`` a network file replacing the shipped one (``PipelineParams.sky_net``);
    ``thin_px`` the thin-structure width (default ``SkyOptions``'s; the pipeline gives each
    camera's, ``PipelineParams.thin_px``).
    """
    from predisat.sky.segment import SkyOptions, segment_sky

    opt = SkyOptions() if method is None else SkyOptions(method=method)
    if thin_px is not None:
        opt = replace(opt, thin_px=int(thin_px))
    classifier = None if sky_net is None else _candidate_classifier(opt.method, sky_net)
    seg = segment_sky(image_bgr, opt, classifier=classifier)
    return seg.sky_mask, seg.confidence


@functools.lru_cache(maxsize=4)
def _candidate_classifier(method: str, sky_net: str) -> Any:
    # read once per process and file, not once per frame
    from predisat.sky.network import SkyNet, classifier_with_net

    return classifier_with_net(method, SkyNet.load(sky_net))


@dataclass(frozen=True)
class _FrameJob:
    frame_id: str
    image_path: str
    width_px: int
    height_px: int
    cache_path: str
    thin_px: int | None = None  # given to the default segmenter only


def _stat_key(path: str) -> list[int]:
    st = os.stat(path)
    return [int(st.st_size), int(st.st_mtime_ns)]


def _frames_key(frame_ids: Iterable[str], image_paths: Iterable[str]) -> str:
    """Hash of a chunk's frames and their images' size and modification time (None when
    missing), so that a finished chunk is redone once one of its images is replaced."""
    stamps = [
        [fid, _stat_key(path) if os.path.exists(path) else None]
        for fid, path in zip(frame_ids, image_paths, strict=True)
    ]
    return hashlib.sha256(json.dumps(stamps).encode()).hexdigest()[:16]


def _read_cache(job: _FrameJob) -> tuple[NDArray, NDArray | None] | BadFrame | None:
    """Cached result of a frame (None when absent or stale: the image changed)."""
    path = Path(job.cache_path)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("version") != CACHE_VERSION or meta.get("thin_px") != job.thin_px:
                return None
            if os.path.exists(job.image_path):
                if meta.get("image_stat") != _stat_key(job.image_path):
                    return None
            elif meta.get("image_stat") is not None:
                return None
            return _decode_cache(z, meta, job.frame_id)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
        return None  # a damaged cache entry (e.g. emptied by a power cut) is recomputed


def _decode_cache(
    z: Any, meta: dict[str, Any], frame_id: str
) -> tuple[NDArray, NDArray | None] | BadFrame:
    """The segmentation (or the recorded failure) of an opened cache entry."""
    if meta.get("bad"):
        return BadFrame(frame_id, str(meta["bad"]))
    h, w = meta["shape"]
    sky = np.unpackbits(z["sky"], count=h * w).reshape(h, w).view(bool)  # 0 / 1: no copy
    conf = z["confidence"] if "confidence" in z.files else None
    return sky, conf


def _write_cache(
    job: _FrameJob, result: tuple[NDArray, NDArray | None] | None, bad: str | None
) -> None:
    stat = _stat_key(job.image_path) if os.path.exists(job.image_path) else None
    meta: dict[str, Any] = {
        "version": CACHE_VERSION, "image_stat": stat, "bad": bad, "thin_px": job.thin_px,
    }  # fmt: skip
    arrays: dict[str, Any] = {}
    if result is not None:
        sky, conf = result
        meta["shape"] = list(sky.shape)
        arrays["sky"] = np.packbits(sky.ravel())
        if conf is not None:
            arrays["confidence"] = np.asarray(conf, np.float32)
    payload = _npz_bytes({"meta": np.array(json.dumps(meta)), **arrays})
    write_bytes_atomic(Path(job.cache_path), payload)


def _npz_bytes(arrays: dict[str, Any]) -> bytes:
    """An ``.npz`` archive of ``arrays`` (what ``np.load`` reads), deflated at level 1.

    ``np.savez_compressed`` deflates at level 6: 0.32 ms per 640x480 frame's entry against
    0.19 ms here, for 4.0 instead of 3.7 kB (2026-12-02).
    """
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        for name, arr in arrays.items():
            npy = io.BytesIO()
            np.lib.format.write_array(npy, np.asanyarray(arr), allow_pickle=False)
            zf.writestr(f"{name}.npy", npy.getvalue())
    return buf.getvalue()


def _read_image(path: str) -> tuple[NDArray | None, str | None]:
    """The BGR image at ``path``, or None and the problem with the file and its fix."""
    import cv2

    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return None, f"image {path} is missing; restore it or drop the frame"
    except OSError as exc:
        return None, f"image {path} cannot be read ({exc.strerror}); check the file"
    if not data:
        return None, (
            f"image {path} is empty (0 bytes): copy it again from the camera or drop the frame"
        )
    cut = _truncation(data)
    if cut is not None:
        return None, (
            f"image {path} is truncated ({cut}): the file was cut short, "
            "copy it again from the camera or drop the frame"
        )
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:
        img = None
    if img is None:
        return None, f"image {path} cannot be decoded; re-export it as JPEG or PNG"
    return img, None


def _segment_frame(job: _FrameJob, segmenter: Segmenter) -> tuple[str, str | None]:
    """Segment one frame into the cache; returns (frame_id, problem or None)."""
    result = None
    img, problem = _read_image(job.image_path)
    if img is None:
        pass  # the problem says why
    elif img.shape[:2] != (job.height_px, job.width_px):
        problem = (
            f"image {job.image_path} is {img.shape[1]}x{img.shape[0]} px, the calibration "
            f"says {job.width_px}x{job.height_px}; fix the calibration or the image"
        )
    else:
        try:
            if job.thin_px is None:
                sky, conf = segmenter(img)
            else:
                sky, conf = segmenter(img, thin_px=job.thin_px)  # type: ignore[call-arg]
            sky = np.asarray(sky, bool)
            if sky.shape != img.shape[:2]:
                raise ValueError(f"segmenter returned a {sky.shape} mask for a {img.shape} image")
            result = (sky, None if conf is None else np.asarray(conf, np.float32))
        except Exception as exc:  # any failure of one frame must not stop a long run
            problem = f"segmentation failed ({type(exc).__name__}: {exc})"
    _write_cache(job, result, problem)
    return job.frame_id, problem


_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})  # markers without a length field


def _truncation(data: bytes) -> str | None:
    """Why the image file ``data`` is cut short, or None when it is whole (or not JPEG / PNG).

    libjpeg decodes a truncated JPEG with a warning only and fills the missing rows with grey,
    which ``cv2.imread`` (OpenCV 5.1) returns as a good image: such a frame would be segmented
    with a flat grey band. ``cv2.imdecode`` refuses it, but says only that it cannot decode.
    A whole JPEG has its end-of-image marker after the scan data, where byte stuffing keeps
    the two bytes from occurring by chance; the header segments are skipped by their
    lengths, so an EXIF thumbnail's own marker does not count.
    """
    if data[:2] == b"\xff\xd8":
        i, n = 2, len(data)
        while i + 4 <= n:
            if data[i] != 0xFF:
                return f"no JPEG marker at byte {i} of the header"
            marker = data[i + 1]
            if marker == 0xFF:  # fill byte
                i += 1
            elif marker == 0xDA:  # start of scan: the compressed pixels follow
                if data.rfind(b"\xff\xd9") < i:
                    return f"no JPEG end-of-image marker after the scan data, {n} bytes"
                return None
            elif marker in _JPEG_STANDALONE:
                i += 2
            else:
                i += 2 + int.from_bytes(data[i + 2 : i + 4], "big")
        return f"the JPEG header ends at byte {n} before the scan data"
    if data[:8] == b"\x89PNG\r\n\x1a\n" and b"IEND" not in data[-12:]:
        return f"no PNG IEND chunk at the end, {len(data)} bytes"
    return None


_WORKER: dict[str, Any] = {}  # per-process segmenter set by the pool initialiser


def _pool_init(segmenter: Segmenter) -> None:
    _WORKER["segmenter"] = segmenter


def _pool_segment(jobs: Sequence[_FrameJob]) -> list[tuple[str, str | None]]:
    return [_segment_frame(j, _WORKER["segmenter"]) for j in jobs]


def _pool_chunk(job: _ChunkJob) -> tuple[str, list[BadFrame]]:
    # one Reconstructor per worker process: its camera rectifiers are reused across chunks
    rec = _WORKER["reconstructor"] = _reconstructor_for(job, _WORKER.get("reconstructor"))
    return _run_chunk(job, rec)


def _reconstructor_for(job: _ChunkJob, previous: Reconstructor | None) -> Reconstructor:
    """``previous`` when it has the job's parameters, else a new one."""
    p = job.params.reconstruction
    return previous if previous is not None and previous.params == p else Reconstructor(p)


# ---------------------------------------------------------------------- chunks
@dataclass(frozen=True)
class _ChunkFrame:
    frame_id: str
    side: str
    chainage_m: float
    cache_path: str


@dataclass(frozen=True)
class _ChunkJob:
    name: str
    lo_m: float
    hi_m: float
    positions_m: NDArray
    frames: tuple[_ChunkFrame, ...]
    cameras: dict[str, tuple[CameraModel, Mount]]
    reverse: bool
    antenna_height_m: float
    track: Any
    params: PipelineParams
    provenance: dict[str, Any]
    chunk_dir: str
    # the chunk's frames found bad before it ran: recorded in its marker, so that a resumed
    # run that skips the chunk still lists them
    known_bad: tuple[BadFrame, ...] = ()
    frames_key: str = ""  # _frames_key of every frame the chunk may use, bad ones included


def _fmt_m(x: float) -> str:
    text = f"{x:.3f}".rstrip("0").rstrip(".")
    return text if text != "-0" else "0"


def _run_chunk(
    job: _ChunkJob, reconstructor: Reconstructor | None = None
) -> tuple[str, list[BadFrame]]:
    """Reconstruct one chunk from cached segmentations and write it atomically.

    ``reconstructor`` (with ``job.params.reconstruction``) may be shared by the chunks of a run,
    so that its per-camera rectifiers are built once.
    """
    track = job.track
    bad: list[BadFrame] = list(job.known_bad)
    views: list[FrameView] = []
    ok_frames = []
    for f in job.frames:
        cached = _load_cached(f)
        if isinstance(cached, BadFrame):
            bad.append(cached)
            continue
        ok_frames.append((f, cached))
    if ok_frames:
        s = np.array([f.chainage_m for f, _ in ok_frames])
        axis = np.asarray(track.enu_at(s), float)
        ant = axis + job.antenna_height_m * np.asarray(track.up_at(s), float)
        heading = np.asarray(track.heading_at(s), float)
        for k, (f, (sky, conf)) in enumerate(ok_frames):
            cam, mount = job.cameras[f.side]
            views.append(
                FrameView(
                    chainage_m=f.chainage_m, sky_mask=sky, camera=cam, mount=mount,
                    antenna_enu_m=ant[k], heading_deg=float(heading[k]), reverse=job.reverse,
                    confidence=conf, frame_id=f.frame_id,
                )
            )  # fmt: skip
    if reconstructor is None:
        reconstructor = Reconstructor(job.params.reconstruction)
    rec = reconstructor.run(views, job.positions_m, track)
    prov = dict(job.provenance)
    prov["chunk"] = {"name": job.name, "lo_m": job.lo_m, "hi_m": job.hi_m}
    masks = rec.to_maskset(track, provenance=prov)
    chunk_dir = Path(job.chunk_dir)
    write_masks(masks, chunk_dir / f"{job.name}.parquet")
    marker = {
        **prov,
        "frames_key": job.frames_key,
        "n_positions": int(masks.n_pos),
        "n_frames": len(views),
        "bad_frames": [asdict(b) for b in bad],
        "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    # the JSON is the completion marker: written last, so a half-done chunk is redone
    write_bytes_atomic(chunk_dir / f"{job.name}.json", json.dumps(marker, indent=1).encode())
    return job.name, bad


def _load_cached(f: _ChunkFrame) -> tuple[NDArray, NDArray | None] | BadFrame:
    path = Path(f.cache_path)
    try:
        with np.load(path, allow_pickle=False) as z:
            return _decode_cache(z, json.loads(str(z["meta"])), f.frame_id)
    except (OSError, ValueError, KeyError) as exc:
        return BadFrame(f.frame_id, f"segmentation cache {path} unreadable ({exc}); rerun")


# ---------------------------------------------------------------------- merging
def concat_masksets(parts: Sequence[MaskSet], provenance: dict[str, Any] | None = None) -> MaskSet:
    """One mask set from parts covering disjoint, increasing chainage ranges.

    Parameters
    ----------
    parts : sequence of MaskSet
        Same ``az_step_deg``; positions strictly increasing across the parts.
    provenance : dict, optional
        Provenance of the result (default: that of the first part).

    Raises
    ------
    MaskError
        When the parts differ in azimuth step or overlap in chainage.
    """
    if not parts:
        raise MaskError("concat_masksets: no parts given; process at least one chunk")
    step = parts[0].az_step_deg
    for k, p in enumerate(parts):
        if p.az_step_deg != step:
            raise MaskError(
                f"concat_masksets: part {k} has az_step_deg {p.az_step_deg}, part 0 has {step}; "
                "reprocess with one azimuth step"
            )
    names = sorted({n for p in parts for n in p.descriptors})

    def cat(attr: str) -> NDArray:
        return np.concatenate([getattr(p, attr) for p in parts])

    desc = {
        n: np.concatenate([p.descriptors.get(n, np.full(p.n_pos, np.nan)) for p in parts])
        for n in names
    }
    return MaskSet.from_arrays(
        cat("chainage_m"), cat("lat_deg"), cat("lon_deg"), cat("h_m"), cat("heading_deg"),
        cat("mask_el_deg"), az_step_deg=step, source=cat("source"),
        margin_deg=cat("margin_deg"), descriptors=desc,
        provenance=dict(parts[0].provenance if provenance is None else provenance),
    )  # fmt: skip


# A step this many times the survey's usual spacing is a hole (a camera dropout, frames lost
# or all bad), not a sparser stretch: nothing may be trusted in it.
GAP_FACTOR = 1.5


def close_gaps(masks: MaskSet, track: Any) -> tuple[MaskSet, list[tuple[float, float]]]:
    """Closed positions inside the survey's holes, so no neighbour's mask is trusted there.

    A mask position stands for the cell between the midpoints to its neighbours, so a hole
    between two surveyed positions would silently be covered by them. Wherever consecutive
    positions are more than :data:`GAP_FACTOR` times the median spacing apart, positions are
    inserted at that spacing with a 90 deg mask (nothing trusted), source ``ASSUMED`` and NaN
    obstacle descriptors.

    Parameters
    ----------
    masks : MaskSet
        The merged masks, n_pos >= 3 (fewer give no spacing to compare with).
    track : TrackMap
        Gives the inserted positions' lat / lon / h and heading.

    Returns
    -------
    masks : MaskSet
        With the inserted positions (the input when there is no hole).
    gaps : list of (float, float)
        Chainages (m) of the surveyed positions on either side of each hole.
    """
    ch = np.asarray(masks.chainage_m, float)
    if len(ch) < 3:
        return masks, []
    step = np.diff(ch)
    spacing = float(np.median(step))
    holes = np.flatnonzero(step > GAP_FACTOR * spacing)
    if not len(holes):
        return masks, []
    new_ch = np.concatenate([
        np.arange(ch[i] + spacing, ch[i + 1] - spacing / 2, spacing) for i in holes
    ])  # fmt: skip
    lat, lon, h = track.position_at(new_ch)
    n_new, n_az = len(new_ch), masks.n_az
    order = np.argsort(np.concatenate([ch, new_ch]), kind="stable")

    def cat(old: NDArray, new: NDArray) -> NDArray:
        return np.concatenate([np.asarray(old), np.asarray(new, dtype=np.asarray(old).dtype)])[
            order
        ]

    closed = MaskSet.from_arrays(
        cat(ch, new_ch), cat(masks.lat_deg, lat), cat(masks.lon_deg, lon), cat(masks.h_m, h),
        cat(masks.heading_deg, track.heading_at(new_ch)),
        cat(masks.mask_el_deg, np.full((n_new, n_az), 90.0)),
        az_step_deg=masks.az_step_deg,
        source=cat(masks.source, np.full((n_new, n_az), int(BinSource.ASSUMED))),
        margin_deg=cat(np.broadcast_to(masks.margin_deg, masks.mask_el_deg.shape),
                       np.zeros((n_new, n_az))),
        descriptors={k: cat(v, np.full(n_new, np.nan)) for k, v in masks.descriptors.items()},
        provenance=masks.provenance,
    )  # fmt: skip
    return closed, [(float(ch[i]), float(ch[i + 1])) for i in holes]


# ---------------------------------------------------------------------- the run
def survey_hash(survey: Any) -> str:
    """SHA-256 of the survey's description: ``survey.yaml``, ``manifest.csv``, calibrations.

    Image content is not hashed (too slow for a resume check); the segmentation cache checks
    each image's size and modification time instead.
    """
    root = Path(survey.root)
    h = hashlib.sha256()
    files = [root / "survey.yaml", root / "manifest.csv"]
    files += sorted({Path(c.calibration_path) for c in survey.cameras.values()})
    for p in files:
        h.update(str(p.name).encode() + b"\0")
        h.update(p.read_bytes() if p.is_file() else b"<missing>")
    return h.hexdigest()


# The files the segmentation depends on (its cache is kept while they do not change).
SEGMENTATION_CODE = (
    "sky/__init__.py", "sky/segment.py", "sky/perceptron.py", "sky/features.py",
    "sky/grabcut.py", "sky/network.py", "data/models",
)


def code_fingerprint(parts: Sequence[str] | None = None) -> str:
    """Hash of the package's own source, so results of changed code are never reused.

    A development install changes code without changing ``predisat.__version__``; the
    resume key and the segmentation cache therefore carry this fingerprint too.

    Parameters
    ----------
    parts : sequence of str, optional
        Files or folders relative to the package; default every ``.py`` file and the
        shipped models.

    Returns
    -------
    str
        16 hex digits of SHA-256 over the files' relative paths and contents.
    """
    root = Path(__file__).resolve().parents[1]  # the predisat package
    if parts is None:
        files = sorted(root.rglob("*.py")) + sorted((root / "data" / "models").glob("*"))
    else:
        files = []
        for part in parts:
            q = root / part
            if not q.exists():
                raise FileNotFoundError(f"code_fingerprint: {q} is not part of the package")
            files += sorted(f for f in q.rglob("*") if f.is_file()) if q.is_dir() else [q]
    h = hashlib.sha256()
    for f in files:
        if f.is_file() and "__pycache__" not in f.parts:
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def _run_key(provenance: dict[str, Any]) -> str:
    keys = ("survey_hash", "params", "software_version", "code_fingerprint", "track")
    keep = {k: provenance[k] for k in keys}
    return hashlib.sha256(json.dumps(keep, sort_keys=True).encode()).hexdigest()[:16]


def _load_margins(margins: Any) -> tuple[Any, dict[str, Any]]:
    """(MarginTable or None, its provenance record) from a table, a path or None; every check
    is made here, before any work, so that a bad table never stops a run at its merge."""
    from predisat.masks.margins import MarginTable

    if margins is None:
        return None, {}
    record: dict[str, Any]
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
    record |= {"target": table.target,
               "table": json.loads(table.table.to_json(orient="records"))}
    json.dumps(record, allow_nan=False)
    return table, record


def _report(msg: str, quiet: bool) -> None:
    # progress lines follow --quiet; bad frames are passed with quiet=False (always told)
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


def process_survey(
    survey: Any,
    out_dir: str | os.PathLike[str],
    params: PipelineParams | None = None,
    *,
    track: Any = None,
    workers: int = 1,
    strict: bool = False,
    progress: bool = True,
    segmenter: Segmenter | None = None,
    max_chunks: int | None = None,
    margins: Any = None,
) -> ProcessResult:
    """Process a survey folder into masks, in resumable chainage chunks.

    Parameters
    ----------
    survey : path-like or predisat.survey.Survey
        The survey folder (loaded with ``on_error="skip"``; rejected frames are bad frames).
    out_dir : path-like
        Output folder: ``masks.parquet``, ``provenance.json``, ``bad_frames.csv``,
        ``chunks/``, ``cache/``. Reusing it resumes an interrupted run.
    params : PipelineParams, optional
    track : TrackMap, optional
        Track to use instead of the one named in ``survey.yaml``.
    workers : int
        Processes (spawned) for segmentation and chunks; 1 runs everything in this process.
    strict : bool
        Stop with :class:`BadFrameError` at the first bad frame instead of skipping it.
    progress : bool
        tqdm progress bars and console messages on stderr.
    segmenter : callable, optional
        Image -> (sky mask, confidence); default :func:`default_segmenter`. Must be a
        module-level function when ``workers > 1``. Give it a distinct ``params.segmenter``
        name, which keys the cache.
    max_chunks : int, optional
        Compute at most this many pending chunks; when chunks remain, stop without merging by
        raising :class:`RunStopped` (simulates an interrupted run). ``None``: all.
    margins : predisat.reconstruct.evaluate.MarginTable or path-like, optional
        Calibrated trust margins (``predisat evaluate --calibrate`` writes ``margins.json``),
        written per bin into the mask file's ``margin_deg`` and recorded in its provenance.
        They are applied at the merge, so changing them redoes no chunk. Default: 0 deg.

    Returns
    -------
    ProcessResult

    Raises
    ------
    BadFrameError
        With ``strict=True``, naming the first bad frame.
    predisat.survey.SurveyError
        When the survey itself (survey.yaml, calibrations, manifest) is unusable.
    """
    from predisat.survey import Survey

    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    p = params or PipelineParams()
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    margin_table, margin_prov = _load_margins(margins)  # before hours of work, not after
    if segmenter is None:
        from predisat.sky.segment import METHODS

        if p.segmenter not in METHODS:
            raise ValueError(
                f"params.segmenter {p.segmenter!r} is not a segmentation method {METHODS}; "
                "pass segmenter= with your own function for another name"
            )
        seg_fn: Segmenter = functools.partial(default_segmenter, method=p.segmenter,
                                              sky_net=p.sky_net)
    else:
        seg_fn = segmenter
    quiet = not progress
    if not isinstance(survey, Survey):
        survey = Survey.load(survey, track=track, check_images=False, on_error="skip")
    trk = track if track is not None else survey.track
    if trk is None:
        raise ValueError(
            f"survey {survey.root} names no track file; pass track= (CLI: --track FILE)"
        )
    out = Path(out_dir)
    params_dict = p.to_dict()  # hashes a candidate network's files once, for both keys
    seg_code = code_fingerprint(SEGMENTATION_CODE)[:8]
    if p.sky_net is not None:
        seg_code += "-net" + params_dict["sky_net"]["sha256"][:12]
    chunk_dir, cache_dir = out / "chunks", out / "cache" / f"seg-{p.segmenter}-{seg_code}"
    chunk_dir.mkdir(parents=True, exist_ok=True)
    cache_dir.mkdir(parents=True, exist_ok=True)

    bad: dict[str, BadFrame] = {}
    for prob in survey.problems:
        fid = prob.frame_id or f"manifest line {prob.row}"
        bad.setdefault(fid, BadFrame(fid, str(prob), "load"))
    fr = survey.frames
    ch = np.round(np.asarray(fr.chainage_m, float), _CHAINAGE_DECIMALS)
    finite = np.isfinite(ch)
    for i in np.flatnonzero(~finite):
        fid = str(fr.frame_id[i])
        bad.setdefault(fid, BadFrame(
            fid, "no chainage (not on the track): give chainage_m in the manifest, or a "
            "position near the survey's track", "load",
        ))  # fmt: skip
    if bad and strict:
        first = next(iter(bad.values()))
        raise BadFrameError(
            f"survey {survey.root}: bad frame {first.frame_id}: {first.message} "
            "(run without --strict to skip it)"
        )
    for b in bad.values():
        _report(f"bad frame {b.frame_id}: {b.message} - skipped", quiet=False)
    if not finite.any():
        raise ValueError(f"survey {survey.root} has no frame with a chainage; nothing to do")
    positions = np.unique(ch[finite])
    prov: dict[str, Any] = {
        "software": "predisat",
        "software_version": _version(),
        "code_fingerprint": code_fingerprint(),
        "survey": str(survey.root),
        "survey_hash": survey_hash(survey),
        "track": str(getattr(trk, "name", "")),
        "params": params_dict,
        "reverse": bool(survey.reverse),
        "antenna_height_m": float(survey.antenna_height_m),
    }
    run_key = _run_key(prov)
    prov["run_key"] = run_key
    timings["load"] = time.perf_counter() - t0

    # chunks and their frame needs
    k = np.floor(positions / p.chunk_m).astype(np.int64)
    overlap = p.reconstruction.overlap_m
    chunks: list[tuple[str, float, float, NDArray]] = []
    for kk in np.unique(k):
        lo, hi = float(kk * p.chunk_m), float((kk + 1) * p.chunk_m)
        chunks.append((f"{_fmt_m(lo)}_{_fmt_m(hi)}", lo, hi, positions[k == kk]))
    # the frames each chunk reads: within overlap_m of its positions
    frames_of = {
        name: np.flatnonzero(finite & (ch >= s.min() - overlap) & (ch <= s.max() + overlap))
        for name, _, _, s in chunks
    }
    frames_key = {
        name: _frames_key(
            (str(fr.frame_id[i]) for i in idx), (str(survey.root / str(fr.image[i])) for i in idx)
        )
        for name, idx in frames_of.items()
    }
    pending, skipped = [], 0
    for c in chunks:
        marker = _chunk_finished(chunk_dir, c[0], run_key, frames_key[c[0]])
        if marker is None:
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
    _report(
        f"{survey.root}: {int(finite.sum())} frames, {positions.size} positions, "
        f"{len(chunks)} chunks ({skipped} already done)",
        quiet,
    )

    need = (
        np.unique(np.concatenate([frames_of[c[0]] for c in pending]))
        if pending
        else np.array([], int)
    )
    cams = {side: (sc.camera, sc.mount) for side, sc in survey.cameras.items()}
    # the angular thin-structure policy reaches the default segmenter only
    thin = {side: (p.thin_px(c) if segmenter is None else None) for side, (c, _) in cams.items()}
    jobs = []
    for i in need:
        fid = str(fr.frame_id[i])
        cam = cams[str(fr.side[i])][0]
        job = _FrameJob(
            fid, str(survey.root / str(fr.image[i])), int(cam.width_px), int(cam.height_px),
            str(cache_dir / f"{fid}.npz"), thin[str(fr.side[i])],
        )  # fmt: skip
        cached = _read_cache(job)
        if cached is None:
            jobs.append(job)
        elif isinstance(cached, BadFrame):
            if strict:
                raise BadFrameError(
                    f"bad frame {fid}: {cached.message} (run without --strict to skip it)"
                )
            _report(
                f"bad frame {fid}: {cached.message} - skipped (as in a run before)", quiet=False
            )
            bad.setdefault(fid, cached)

    # one pool of worker processes for both stages (with workers > 1, started when needed)
    pool = _Pool(workers, seg_fn)
    try:
        # stage 1: segmentation
        t1 = time.perf_counter()
        n_seg = 0
        for fid, problem in _run_segmentation(jobs, pool, progress):
            n_seg += 1
            if problem is not None:
                if strict:
                    raise BadFrameError(
                        f"bad frame {fid}: {problem} (run without --strict to skip it)"
                    )
                _report(f"bad frame {fid}: {problem} - skipped", quiet=False)
                bad.setdefault(fid, BadFrame(fid, problem))
        timings["segment"] = time.perf_counter() - t1

        # stage 2: reconstruction per chunk
        t2 = time.perf_counter()
        cjobs = []
        for name, lo, hi, s in pending:
            idx = frames_of[name]
            known_bad = tuple(
                bad[f] for f in dict.fromkeys(str(fr.frame_id[i]) for i in idx) if f in bad
            )
            frames = tuple(
                _ChunkFrame(
                    str(fr.frame_id[i]),
                    str(fr.side[i]),
                    float(ch[i]),
                    str(cache_dir / f"{fr.frame_id[i]}.npz"),
                )
                for i in idx
                if str(fr.frame_id[i]) not in bad
            )
            cjobs.append(
                _ChunkJob(
                    name,
                    lo,
                    hi,
                    s,
                    frames,
                    cams,
                    bool(survey.reverse),
                    float(survey.antenna_height_m),
                    trk,
                    p,
                    prov,
                    str(chunk_dir),
                    known_bad,
                    frames_key[name],
                )
            )
        _run_chunks(cjobs, pool, progress)
        timings["reconstruct"] = time.perf_counter() - t2
    finally:
        pool.close()

    if max_chunks is not None and skipped + len(pending) < len(chunks):
        raise RunStopped(f"stopped after {len(pending)} chunk(s) (max_chunks)")

    # merge
    t3 = time.perf_counter()
    parts = []
    ran = {c[0] for c in pending}
    for name, *_ in chunks:
        parts.append(read_masks(chunk_dir / f"{name}.parquet"))
        marker = json.loads((chunk_dir / f"{name}.json").read_text())
        for b in marker.get("bad_frames", []):
            if b["frame_id"] not in bad:  # not reported yet: met by a chunk, or a run before
                bad[b["frame_id"]] = BadFrame(**b)
                when = "" if name in ran else " (as in a run before)"
                _report(f"bad frame {b['frame_id']}: {b['message']} - skipped{when}", quiet=False)
    bad_list = tuple(sorted(bad.values(), key=lambda b: b.frame_id))
    final_prov = {
        **prov,
        "chunks": [c[0] for c in chunks],
        "n_frames": int(finite.sum()),
        "bad_frames": len(bad_list),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    if margin_table is not None:
        final_prov["margins"] = margin_prov
    merged = concat_masksets(parts, final_prov)
    if margin_table is not None:
        merged = margin_table.apply(merged)
    merged, gaps = close_gaps(merged, trk)
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
    masks_path = write_masks(merged, out / "masks.parquet")
    _write_bad_frames(out / "bad_frames.csv", bad_list)
    timings["merge"] = time.perf_counter() - t3
    elapsed = time.perf_counter() - t0
    final_prov["bad_frame_list"] = [asdict(b) for b in bad_list]
    final_prov["timings_s"] = timings
    write_bytes_atomic(out / "provenance.json", json.dumps(final_prov, indent=1).encode())
    result = ProcessResult(
        out, masks_path, merged, int(finite.sum()), len(pending), skipped, n_seg, bad_list,
        elapsed, timings,
    )  # fmt: skip
    return result


class RunStopped(RuntimeError):
    """``max_chunks`` reached before every chunk was done; rerun to resume."""


def _version() -> str:
    from predisat import __version__

    return str(__version__)


def _chunk_finished(
    chunk_dir: Path, name: str, run_key: str, frames_key: str
) -> dict[str, Any] | None:
    """The completion marker of a chunk that need not be redone, else None."""
    import pyarrow.parquet as pq

    marker, data = chunk_dir / f"{name}.json", chunk_dir / f"{name}.parquet"
    if not (marker.is_file() and data.is_file()):
        return None
    try:
        done = json.loads(marker.read_text())
        if done.get("run_key") != run_key or done.get("frames_key") != frames_key:
            return None
        # A power cut after the rename may leave an empty or torn file (no fsync, for speed):
        # a chunk whose Parquet footer does not read, or holds other than its rows, is redone.
        rows = pq.read_metadata(data).num_rows
        ok = rows > 0 and rows == done.get("n_positions", rows)
        return done if ok and isinstance(done, dict) else None
    except (OSError, ValueError, AttributeError):
        return None


def _write_bad_frames(path: Path, bad: Iterable[BadFrame]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame_id", "stage", "message"])
    for b in bad:
        w.writerow([b.frame_id, b.stage, b.message])
    write_bytes_atomic(path, buf.getvalue().encode())


def _progress(total: int, desc: str, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame" if "segment" in desc else "chunk",
                disable=not enabled or total == 0, file=sys.stderr)  # fmt: skip


class _Pool:
    """The worker processes of a run, started on first use and shared by both stages.

    Before 2026-12-02 each stage started its own pool, so every worker imported the package,
    loaded the models and the numba caches twice (about a second per worker and stage).
    """

    def __init__(self, workers: int, segmenter: Segmenter) -> None:
        self.workers = workers
        self.segmenter = segmenter
        self._pool: ProcessPoolExecutor | None = None

    def get(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                self.workers, mp_context=get_context("spawn"), initializer=_pool_init,
                initargs=(self.segmenter,),
            )  # fmt: skip
        return self._pool

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterable[Any]:
        """``fn`` of every item in the workers, results as they finish; on an error or Ctrl-C
        the queued items are dropped (finished chunks are already on disk)."""
        futures: set[Future[Any]] = {self.get().submit(fn, it) for it in items}
        try:
            while futures:
                done, futures = wait(futures, return_when=FIRST_COMPLETED)
                for fut in done:
                    yield fut.result()
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


def _run_segmentation(
    jobs: Sequence[_FrameJob], pool: _Pool, progress: bool
) -> Iterable[tuple[str, str | None]]:
    bar = _progress(len(jobs), "segmenting frames", progress)
    try:
        if pool.workers == 1 or len(jobs) < 4:
            for j in jobs:
                yield _segment_frame(j, pool.segmenter)
                bar.update(1)
            return
        batch = max(1, min(16, len(jobs) // (4 * pool.workers)))
        batches = [jobs[i : i + batch] for i in range(0, len(jobs), batch)]
        for res in pool.map_unordered(_pool_segment, batches):
            bar.update(len(res))
            yield from res
    finally:
        bar.close()


def _run_chunks(jobs: Sequence[_ChunkJob], pool: _Pool, progress: bool) -> None:
    bar = _progress(len(jobs), "reconstructing chunks", progress)
    try:
        if pool.workers == 1 or len(jobs) < 2:
            rec: Reconstructor | None = None
            for j in jobs:
                rec = _reconstructor_for(j, rec)
                _run_chunk(j, rec)
                bar.update(1)
            return
        for _ in pool.map_unordered(_pool_chunk, jobs):
            bar.update(1)
    finally:
        bar.close()


# ---------------------------------------------------------------------- command line
def add_process_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``predisat process``."""
    from predisat.sky.segment import METHODS

    parser.add_argument("survey", type=Path, help="survey folder (with survey.yaml)")
    parser.add_argument(
        "--out", type=output_dir, required=True,
        help="output folder (masks.parquet, chunks/, cache/, bad_frames.csv); "
        "rerun with the same folder to resume",
    )  # fmt: skip
    parser.add_argument("--track", type=Path, help="track file instead of the survey's own")
    parser.add_argument("--workers", type=positive_int, default=1, help="processes (default 1)")
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


def process_from_args(args: argparse.Namespace) -> ProcessResult:
    """Run ``predisat process`` from parsed arguments."""
    track = None
    if args.track is not None:
        from predisat.track.map import TrackMap

        suffix = args.track.suffix.lower()
        track = (
            TrackMap.from_csv(args.track) if suffix == ".csv" else TrackMap.from_geojson(args.track)
        )
    return process_survey(
        args.survey,
        args.out,
        PipelineParams(chunk_m=args.chunk_m, segmenter=args.segmenter, sky_net=args.sky_net,
                       thin_deg=args.thin_deg),
        track=track,
        workers=args.workers,
        strict=args.strict,
        progress=not args.quiet,
        margins=args.margins,
    )
