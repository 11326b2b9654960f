"""A chainage chunk of a batch run: its frames, its reconstruction, its files and its marker.

Chunk ``k`` holds the positions in ``[k * chunk_m, (k + 1) * chunk_m)`` and is reconstructed
from the cached segmentations of the frames within ``overlap_m`` of it (:func:`run_chunk`). It
is written atomically as ``chunks/<lo>_<hi>.parquet`` (a mask file), then ``<lo>_<hi>.json``
(its provenance, the completion marker); :func:`chunk_finished` decides whether a marker left
by an earlier run may be kept.
"""

from __future__ import annotations

import io
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from numpy.typing import NDArray

from predisat.camera.models import (
    CameraModel,
    Mount,
    tilt_shift_m,
    vehicle_to_enu,
)
from predisat.clock import utc_stamp
from predisat.jsontypes import JsonDict
from predisat.masks.fileformat import write_masks
from predisat.reconstruct.attitude import frame_attitudes
from predisat.reconstruct.badframes import BadFrame
from predisat.reconstruct.carving import (
    FrameView,
    ReconstructionParams,
    Reconstructor,
    side_cameras,
)
from predisat.reconstruct.framecache import decode_cache
from predisat.reconstruct.params import PipelineParams
from predisat.reconstruct.placement import chainage_placement_doubt
from predisat.reconstruct.stops import merge_stop_frames
from predisat.storage import (
    Location,
    StorageOptions,
    exists,
    join,
    location,
    output_path,
    read_bytes,
    write_atomic,
)
from predisat.track import TrackMap

__all__ = [
    "ChunkFrame",
    "ChunkInputs",
    "ChunkJob",
    "chunk_finished",
    "chunk_inputs",
    "chunk_name",
    "load_cached",
    "reconstructor_for",
    "run_chunk",
]


@dataclass(frozen=True)
class ChunkFrame:
    frame_id: str
    side: str
    chainage_m: float
    cache_path: str
    # the vehicle's measured attitude (the manifest's), NaN when not given
    roll_deg: float = float("nan")
    pitch_deg: float = float("nan")
    speed_kmh: float = float("nan")  # the survey vehicle's, from the frames' times
    # the view (stop_ids over the whole survey) it is merged into; -1: the chunk chains its
    # own frames (a window may then slice a crawl otherwise than the survey)
    view_id: int = -1


@dataclass(frozen=True)
class ChunkJob:
    name: str
    lo_m: float
    hi_m: float
    positions_m: NDArray
    frames: tuple[ChunkFrame, ...]
    cameras: dict[str, tuple[CameraModel, Mount]]
    reverse: bool
    antenna_height_m: float
    track: TrackMap
    params: PipelineParams
    provenance: JsonDict
    chunk_dir: str
    # the chunk's frames found bad before it ran: recorded in its marker, so that a resumed
    # run that skips the chunk still lists them
    known_bad: tuple[BadFrame, ...] = ()
    frames_key: str = ""  # frames_key of every frame the chunk may use, bad ones included
    # the run's pinned time (SOURCE_DATE_EPOCH, predisat.clock), read by the client and passed
    # on so that the workers need not have it; else None
    pinned_utc: str | None = None
    # of the file system of chunk_dir and the cache paths when they are URLs
    storage_options: StorageOptions = field(default_factory=dict)
    # the survey's two attitude verdicts (IMU, cant table set aside; frame_attitudes'
    # verdicts), so that every chunk rectifies a frame alike; None: the chunk decides
    attitude_verdicts: tuple[bool, bool] | None = None


def _fmt_m(x: float) -> str:
    text = f"{x:.3f}".rstrip("0").rstrip(".")
    return text if text != "-0" else "0"


def chunk_name(lo_m: float, hi_m: float) -> str:
    """File stem of the chunk ``[lo_m, hi_m)``: ``"3000_4000"`` (metres, up to mm)."""
    return f"{_fmt_m(lo_m)}_{_fmt_m(hi_m)}"


def _jitter_m(params: PipelineParams) -> float:
    """How far each frame may be from the others' common error, metres: the jitter, else
    the doubt (:func:`~predisat.reconstruct.batch.process_survey` resolves both)."""
    doubt = params.chainage_doubt_m or 0.0
    return doubt if params.chainage_jitter_m is None else min(params.chainage_jitter_m, doubt)


def reconstructor_for(job: ChunkJob, previous: Reconstructor | None) -> Reconstructor:
    """``previous`` when it has the job's parameters, else a new one."""
    p = job.params.reconstruction
    return previous if previous is not None and previous.params == p else Reconstructor(p)


@dataclass(frozen=True)
class ChunkInputs:
    """What a chunk's reconstruction runs on (:func:`chunk_inputs`): the arguments
    :func:`run_chunk` passes to :meth:`~predisat.reconstruct.carving.Reconstructor.run`.

    Attributes
    ----------
    views : tuple of FrameView
        The chunk's frames as the reconstruction takes them: on the mounts of the vehicle's
        attitude (measured or bounded from the track, section 16), shifted by its tilt, with
        their attitude, mount and position doubts (sections 16, 18), a stop's frames merged into
        one view (section 24).
    positions_m : ndarray, shape (n_pos,)
        The chunk's positions (chainages, metres).
    track : TrackMap
    side_cameras : tuple of str
        The rig's side cameras (:func:`~predisat.reconstruct.carving.side_cameras`).
    params : ReconstructionParams
        The run's reconstruction parameters (its chainage shift and antenna height resolved).
    bad : tuple of BadFrame
        The frames set aside before the reconstruction (the job's known bad ones and those whose
        cached segmentation does not read).
    n_frames : int
        Frames read, before a stop's frames are merged.
    """

    views: tuple[FrameView, ...]
    positions_m: NDArray
    track: TrackMap
    side_cameras: tuple[str, ...]
    params: ReconstructionParams
    bad: tuple[BadFrame, ...]
    n_frames: int


def chunk_inputs(job: ChunkJob) -> ChunkInputs:
    """The frames, positions and settings ``job``'s reconstruction runs on, built from its
    cached segmentations: :func:`run_chunk` reconstructs from these, and a diagnosis of a
    finished run (:func:`predisat.reconstruct.batch.finished_chunk_jobs`) rebuilds them.

    Parameters
    ----------
    job : ChunkJob

    Returns
    -------
    ChunkInputs
    """
    track = job.track
    bad: list[BadFrame] = list(job.known_bad)
    views: list[FrameView] = []
    ok_frames = []
    for f in job.frames:
        cached = load_cached(f, job.storage_options)
        if isinstance(cached, BadFrame):
            bad.append(cached)
            continue
        ok_frames.append((f, cached))
    if ok_frames:
        s = np.array([f.chainage_m for f, _ in ok_frames])
        axis = np.asarray(track.enu_at(s), float)
        ant = axis + job.antenna_height_m * np.asarray(track.up_at(s), float)
        heading = np.asarray(track.heading_at(s), float)
        p = job.params
        doubt_m, jitter_m = p.chainage_doubt_m or 0.0, _jitter_m(p)
        att = frame_attitudes(
            track, s, [f.roll_deg for f, _ in ok_frames], [f.pitch_deg for f, _ in ok_frames],
            job.reverse, cant=p.cant, grade_doubt_deg=p.grade_doubt_deg,
            imu_doubt_deg=p.imu_doubt_deg, cant_table=p.cant_table,
            speed_kmh=[f.speed_kmh for f, _ in ok_frames],
            chainage_doubt_m=doubt_m, verdicts=job.attitude_verdicts,
        )  # fmt: skip
        # the mounts in the level frame of the vehicle's attitude, which tilts about the
        # rails and carries the cameras with it (section 16)
        mounts = [
            job.cameras[f.side][1].on_vehicle(float(att.roll_deg[k]), float(att.pitch_deg[k]))
            for k, (f, _) in enumerate(ok_frames)
        ]
        tilts = [
            tilt_shift_m(float(att.roll_deg[k]), float(att.pitch_deg[k]), job.antenna_height_m)
            for k in range(len(ok_frames))
        ]
        # where the cameras stand if the chainages are off (section 18)
        offsets = [t + np.asarray(m.lever_arm_m, float) for t, m in zip(tilts, mounts, strict=True)]
        # each camera within the jitter of the others; turned as the track turns over the
        # whole doubt (the window's common shift is the reconstruction's)
        placed = chainage_placement_doubt(
            track, s, offsets, job.antenna_height_m, job.reverse, jitter_m
        )
        turned = placed.yaw_deg if jitter_m == doubt_m else chainage_placement_doubt(
            track, s, offsets, job.antenna_height_m, job.reverse, doubt_m
        ).yaw_deg
        for k, (f, (sky, conf, thin)) in enumerate(ok_frames):
            cam, vehicle_mount = job.cameras[f.side]
            mount = mounts[k]
            shift = vehicle_to_enu(float(heading[k]), job.reverse) @ tilts[k]
            # the widest feature the thin-structure policy removed: its width in pixels times
            # the camera's widest pixel (docs/reconstruction.md, section 8)
            width = job.params.thin_px(cam) * cam.widest_pixel_deg if thin is not None else 0.0
            # the camera's own mounting may be off its calibration too (a turn in place: only
            # the sky is eroded, the camera's centre stays)
            doubt = float(att.doubt_deg[k] + turned[k] + p.mount_doubt_deg)
            # the same doubt moves the camera's centre (the body turns about the rails)
            along_m, across_m, raised_m = np.add(
                att.camera_doubt_m(k, vehicle_mount.lever_arm_m, job.antenna_height_m),
                (placed.along_m[k], placed.across_m[k], placed.up_m[k]),
            )
            views.append(
                FrameView(
                    chainage_m=f.chainage_m, sky_mask=sky, camera=cam, mount=mount,
                    antenna_enu_m=ant[k] + shift, heading_deg=float(heading[k]),
                    reverse=job.reverse,
                    confidence=conf, frame_id=f.frame_id, thin_mask=thin, thin_width_deg=width,
                    attitude_doubt_deg=doubt,
                    along_doubt_m=along_m, across_doubt_m=across_m, height_doubt_m=raised_m,
                )
            )  # fmt: skip
    n_frames = len(views)
    # the frames of a stop are one view: sky only where all of them saw it (section 24)
    ids = [f.view_id for f, _ in ok_frames]
    views = merge_stop_frames(views, job.params.stop_gap_m, job.params.stop_span_m,
                              ids if ids and min(ids) >= 0 else None)  # fmt: skip
    # a side camera without its own frame at a position: the clearance there is overhead
    sides = side_cameras({side: cam for side, (cam, _) in job.cameras.items()})
    return ChunkInputs(tuple(views), job.positions_m, track, tuple(sides),
                       job.params.reconstruction, tuple(bad), n_frames)  # fmt: skip


def run_chunk(
    job: ChunkJob, reconstructor: Reconstructor | None = None
) -> tuple[str, list[BadFrame]]:
    """Reconstruct one chunk from cached segmentations and write it atomically.

    ``reconstructor`` (with ``job.params.reconstruction``) may be shared by the chunks of a run,
    so that its per-camera rectifiers are built once.
    """
    inputs = chunk_inputs(job)
    if reconstructor is None:
        reconstructor = Reconstructor(inputs.params)
    rec = reconstructor.run(list(inputs.views), inputs.positions_m, inputs.track,
                            side_cameras=list(inputs.side_cameras))  # fmt: skip
    bad = list(inputs.bad)
    # frames the fusion's consistency check left out (ReconstructionParams.suspect_share)
    bad.extend(BadFrame(fid, why, "fusion") for fid, why in rec.suspect_frames)
    prov = dict(job.provenance)
    prov["chunk"] = {"name": job.name, "lo_m": job.lo_m, "hi_m": job.hi_m}
    prov["created_utc"] = utc_stamp(job.pinned_utc)
    masks = rec.to_maskset(inputs.track, provenance=prov)
    chunk_dir, opts = location(job.chunk_dir), job.storage_options
    if isinstance(chunk_dir, Path):
        write_masks(masks, chunk_dir / f"{job.name}.parquet")
    else:
        with output_path(join(chunk_dir, f"{job.name}.parquet"), opts) as tmp:
            write_masks(masks, tmp)
    marker = {
        **prov,
        "frames_key": job.frames_key,
        "n_positions": int(masks.n_pos),
        "n_frames": inputs.n_frames,
        "bad_frames": [asdict(b) for b in bad],
        "finished_utc": utc_stamp(job.pinned_utc),
    }
    # the JSON is the completion marker: written last, so a half-done chunk is redone
    write_atomic(join(chunk_dir, f"{job.name}.json"), json.dumps(marker, indent=1).encode(), opts)
    return job.name, bad


def load_cached(
    f: ChunkFrame, opts: StorageOptions
) -> tuple[NDArray, NDArray | None, NDArray | None] | BadFrame:
    """A frame's cached segmentation (sky, confidence, thin), or its failure as a BadFrame."""
    path = location(f.cache_path)
    try:
        source = path if isinstance(path, Path) else io.BytesIO(read_bytes(path, opts))
        with np.load(source, allow_pickle=False) as z:
            return decode_cache(z, json.loads(str(z["meta"])), f.frame_id)
    except (OSError, ValueError, KeyError) as exc:
        return BadFrame(f.frame_id, f"segmentation cache {path} unreadable ({exc}); rerun")


def chunk_finished(
    chunk_dir: Location,
    name: str,
    run_key: str,
    frames_key: str,
    storage_options: StorageOptions | None = None,
) -> JsonDict | None:
    """The completion marker of a chunk that need not be redone, else None."""
    marker, data = join(chunk_dir, f"{name}.json"), join(chunk_dir, f"{name}.parquet")
    if isinstance(marker, Path) and isinstance(data, Path):
        if not (marker.is_file() and data.is_file()):
            return None
    elif not (exists(marker, storage_options) and exists(data, storage_options)):
        return None
    try:
        done = json.loads(read_bytes(marker, storage_options).decode())
        if done.get("run_key") != run_key or done.get("frames_key") != frames_key:
            return None
        # A power cut after the rename may leave an empty or torn file (no fsync, for speed):
        # a chunk whose Parquet footer does not read, or holds other than its rows, is redone.
        footer = data if isinstance(data, Path) else io.BytesIO(read_bytes(data, storage_options))
        rows = pq.read_metadata(footer).num_rows
        ok = rows > 0 and rows == done.get("n_positions", rows)
        return done if ok and isinstance(done, dict) else None
    except (OSError, ValueError, AttributeError):
        return None
