"""Synthetic surveys: a corridor world rendered into a survey folder with exact ground truth.

:func:`generate_survey` builds a :class:`~predisat.synth.world.World` along a track, renders the
cameras of a rig (:class:`~predisat.camera.rigs.Rig`; by default the left and right 45 deg side
cameras) at every position (antenna every ``spacing_m``), writes them with
:class:`~predisat.survey.SurveyWriter` and writes the ground truth beside them::

    out_dir/
      survey/                the survey (format v1): survey.yaml, manifest.csv, images/, calib/,
                             track.geojson
      truth/
        README.txt           what is here
        labels/<frame_id>.png  per-frame sky label: 255 sky, 128 thin L-band-transparent
                             structure against the sky, 0 obstacle
        frames.csv           per frame: side, chainage, time, sky condition, sun position
        true_masks.npz       per-position true 360 deg masks (predisat.masks.truth.TrueMasks)
        world.npz            the world mesh and recipe (World.load)

:func:`contact_sheet` tiles sample frames of a survey into one captioned PNG.
"""

from __future__ import annotations

import csv
import io
import multiprocessing as mp
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NoReturn

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from predisat.atomic import atomic_path, write_bytes_atomic
from predisat.camera.models import CameraModel, Mount, default_camera
from predisat.camera.rigs import Rig
from predisat.geodesy import enu_to_azel, unwrap_lon_deg, wrap_lon_deg
from predisat.gnss.sun import sun_azel, sun_direction_enu
from predisat.gnss.timescale import calendar_to_gps_s, gps_minus_utc_at_gps_s, gps_minus_utc_s
from predisat.survey import Survey, SurveyWriter
from predisat.synth.render import Casters, RenderOptions, camera_pose, render_frame
from predisat.synth.sky import SKY_CONDITIONS, SkyModel
from predisat.synth.truth import true_masks
from predisat.synth.world import Stretch, World, WorldSpec
from predisat.track import TrackMap
from predisat.track.cant import CantTable, body_roll_deg, equilibrium_cant_mm
from predisat.track.readers import write_geojson

__all__ = [
    "SKY_CHOICES",
    "SynthResult",
    "camera_clock_s",
    "contact_sheet",
    "daytime_gps_s",
    "default_scenery",
    "design_cant_mm",
    "generate_survey",
    "sky_schedule",
]

SKY_CHOICES = (*SKY_CONDITIONS, "mixed")
_MARGIN_M = 150.0
_SHORT_KINDS = ("open", "station", "town", "trees", "cutting", "rock_walls")


@dataclass(frozen=True)
class SynthResult:
    """Where :func:`generate_survey` wrote its output (``str()`` gives ``out_dir``)."""

    out_dir: Path
    survey_dir: Path
    truth_dir: Path
    n_positions: int
    n_frames: int

    def __str__(self) -> str:
        return str(self.out_dir)


def daytime_gps_s(lon_deg: float, date: str = "2024-06-21", solar_hour: float = 10.0) -> float:
    """``gps_s`` of a local mean solar time on a date at a longitude (default mid-morning).

    Parameters
    ----------
    lon_deg : float
        Longitude, east positive.
    date : str
        ISO date ``YYYY-MM-DD`` (UTC day).
    solar_hour : float
        Local mean solar time in hours (UTC + longitude / 15).
    """
    y, m, d = (int(x) for x in date.split("-"))
    utc_s = float(calendar_to_gps_s(y, m, d)) + (solar_hour - lon_deg / 15.0) * 3600.0
    return utc_s + float(gps_minus_utc_s(utc_s))


def sky_schedule(sky: str, chainage_m: ArrayLike, seed: int = 0) -> tuple[NDArray, NDArray]:
    """Sky condition and sky-pattern id per position.

    ``"mixed"`` changes the condition every 150-400 m of chainage (each stretch keeps its own
    clouds); a single condition keeps one sky for the whole run.

    Parameters
    ----------
    sky : {"clear", "cloudy", "overcast", "mixed"}
    chainage_m : array_like, shape (n,)
        Positions, increasing.
    seed : int

    Returns
    -------
    condition : ndarray of str, shape (n,)
    sky_id : ndarray of int, shape (n,)
        Index of the stretch sharing one :class:`SkyModel` seed.
    """
    if sky not in SKY_CHOICES:
        raise ValueError(f"sky must be one of {SKY_CHOICES}, got {sky!r}")
    s = np.atleast_1d(np.asarray(chainage_m, float))
    if sky != "mixed" or s.size == 0:
        return np.full(s.size, sky, dtype=object), np.zeros(s.size, int)
    rng = np.random.default_rng([seed, 17])
    edges, conds = [float(s[0])], []
    prev = ""
    while edges[-1] <= s[-1]:
        prev = str(rng.choice([c for c in SKY_CONDITIONS if c != prev]))
        conds.append(prev)
        edges.append(edges[-1] + float(rng.uniform(150.0, 400.0)))
    ids = np.clip(np.searchsorted(np.asarray(edges), s, side="right") - 1, 0, len(conds) - 1)
    return np.asarray(conds, dtype=object)[ids], ids


def default_scenery(lo_m: float, hi_m: float, seed: int = 0) -> WorldSpec:
    """The scenery recipe drawn for chainages ``[lo_m, hi_m]`` (metres) when none is given:
    ``WorldSpec.mixed`` (every kind of stretch) from 800 m, a shorter random recipe below."""
    if not hi_m > lo_m:
        raise ValueError(f"scenery extent {lo_m:g}-{hi_m:g} m: the start must be below the end")
    if hi_m - lo_m >= 800.0:
        return WorldSpec.mixed(lo_m, hi_m, seed)
    return _short_spec(lo_m, hi_m, seed)


def _short_spec(lo_m: float, hi_m: float, seed: int) -> WorldSpec:
    """A varied recipe for runs too short for ``WorldSpec.mixed`` (under 800 m)."""
    rng = np.random.default_rng([seed, 23])
    out, a = [], lo_m
    while a < hi_m - 1e-6:
        b = min(hi_m, a + float(rng.uniform(60.0, 160.0)))
        if hi_m - b < 40.0:
            b = hi_m
        kind = str(rng.choice(_SHORT_KINDS))
        side = "both" if rng.uniform() < 0.5 else ("left", "right")[int(rng.integers(0, 2))]
        out.append(Stretch(kind, a, b, side))
        a = b
    return WorldSpec(tuple(out))


def generate_survey(
    track: TrackMap,
    from_m: float,
    to_m: float,
    sky: str = "mixed",
    seed: int = 0,
    out_dir: str | os.PathLike[str] = "synth_out",
    spacing_m: float = 10.0,
    camera: CameraModel | None = None,
    pitch_deg: float = 45.0,
    antenna_height_m: float = 4.0,
    speed_mps: float = 12.0,
    start_gps_s: float | None = None,
    spec: WorldSpec | None = None,
    progress: bool = True,
    backend: str = "open3d",
    options: RenderOptions | None = None,
    overwrite: bool = False,
    workers: int = 1,
    rig: Rig | None = None,
    cant_speed_kmh: float | None = None,
    max_cant_mm: float = 160.0,
    write_attitude: bool = True,
) -> SynthResult:
    """Render a synthetic survey of a track stretch and write it with its ground truth.

    Parameters
    ----------
    track : TrackMap
    from_m, to_m : float
        Chainage interval of the antenna positions, metres (``0 <= from_m < to_m <= length``).
    sky : {"clear", "cloudy", "overcast", "mixed"}
        Sky condition; ``"mixed"`` varies it along the run.
    seed : int
        Fixes scenery, skies and camera noise: the same inputs give the same survey.
    out_dir : path-like
        Output folder (``survey/`` and ``truth/`` are created in it).
    spacing_m : float
        Distance between antenna positions.
    camera : CameraModel, optional
        Both cameras' calibration (default: :func:`predisat.camera.models.default_camera`).
    pitch_deg : float
        Camera pitch above the horizontal.
    antenna_height_m, speed_mps : float
        Antenna above the rail; train speed (sets frame times).
    start_gps_s : float, optional
        Time of the first position; default 10:00 local solar time on 2024-06-21.
    spec : WorldSpec, optional
        Scenery recipe; default ``WorldSpec.mixed`` over the run plus 150 m each side (a
        shorter random recipe when that is under 800 m).
    progress : bool
        Show a tqdm progress bar.
    backend : {"open3d", "trimesh"}
        Ray caster.
    options : RenderOptions, optional
    overwrite : bool
        Allow writing into a folder that already holds a survey.
    workers : int
        Rendering processes (frames are written in order whatever the count; the output does
        not depend on it).
    rig : Rig, optional
        The cameras to render (e.g. ``Rig.preset("360")``); its name goes to survey.yaml
        (``rig``). Default: ``camera`` on both sides, pitched up ``pitch_deg``; give either
        the rig or ``camera`` / ``pitch_deg``.
    cant_speed_kmh : float, optional
        Cant the curves for this line speed (their equilibrium cant, at most
        ``max_cant_mm``, in 5 mm steps): the vehicle body rolls toward each curve's inside
        by the cant and a quarter of the cant excess at ``speed_mps``
        (:func:`predisat.track.cant.body_roll_deg`), and it pitches with the grade. None: a
        level vehicle, as before.
    max_cant_mm : float
        The largest cant the curves get.
    write_attitude : bool
        Write the vehicle's roll and pitch in the manifest (as an IMU would); False leaves
        them out, as a survey without an IMU (the pipeline then bounds them from the track).

    Returns
    -------
    SynthResult
    """
    length = float(track.length_m)
    _check_request(from_m, to_m, length, workers, spacing_m, speed_mps)
    out = Path(out_dir)
    survey_dir, truth_dir = out / "survey", out / "truth"
    (truth_dir / "labels").mkdir(parents=True, exist_ok=True)
    survey_dir.mkdir(parents=True, exist_ok=True)
    if rig is not None and (camera is not None or pitch_deg != 45.0):
        raise ValueError("give either rig or camera / pitch_deg: the rig sets the cameras")
    cams = (
        rig.as_mapping()
        if rig is not None
        else _side_cameras(camera if camera is not None else default_camera("pinhole"), pitch_deg)
    )
    opt = options or RenderOptions()

    lo, hi = max(0.0, from_m - _MARGIN_M), min(length, to_m + _MARGIN_M)
    if spec is None:
        spec = default_scenery(lo, hi, seed)
    elif spec.extent_m[0] > from_m or spec.extent_m[1] < to_m:
        import warnings

        warnings.warn(
            f"the scenery recipe covers chainage {spec.extent_m[0]:.0f}-{spec.extent_m[1]:.0f} m, "
            f"not all of the survey's {from_m:.0f}-{to_m:.0f} m: frames outside it see bare "
            "ground, and the track's tunnels are cut at the recipe's ends; extend the recipe's "
            "stretches or the --from-km/--to-km",
            stacklevel=2,
        )
    world = World.build(track, spec, seed)
    with atomic_path(truth_dir / "world.npz") as tmp:
        world.save(tmp)
    casters = Casters.for_world(world, backend)

    s = np.arange(from_m, to_m + 1e-9, spacing_m)
    truth = true_masks(world, s, antenna_height_m, backend=backend, caster=casters.lband)
    with atomic_path(truth_dir / "true_masks.npz") as tmp:
        truth.save(tmp)

    run = _Positions.along(world, s, antenna_height_m, speed_mps, start_gps_s, sky, seed)
    if cant_speed_kmh is not None:
        if not (np.isfinite(cant_speed_kmh) and 0 < cant_speed_kmh <= 400 and
                0 <= max_cant_mm <= 250):  # fmt: skip
            raise ValueError(
                f"cant_speed_kmh must be a line speed in (0, 400] km/h and max_cant_mm a cant in "
                f"[0, 250] mm, got {cant_speed_kmh}, {max_cant_mm}"
            )
        if 0 < max_cant_mm < 1:
            raise ValueError(f"max_cant_mm {max_cant_mm:g} reads as metres: give millimetres "
                             f"({1000 * max_cant_mm:g})")  # fmt: skip
        run = run.canted(track, cant_speed_kmh, max_cant_mm, speed_mps * 3.6)
        # the line's cant as its infrastructure records would give it (process --cant-table)
        CantTable(s, design_cant_mm(track, s, cant_speed_kmh, max_cant_mm),
                  "synthetic").to_csv(truth_dir / "cant.csv")  # fmt: skip
    with atomic_path(survey_dir / "track.geojson") as tmp:
        write_geojson(track, tmp)
    context = _RenderContext(world, backend, cams, opt, antenna_height_m, seed)
    rows: list[dict[str, str]] = []
    with SurveyWriter(
        survey_dir,
        cams,
        antenna_height_m=antenna_height_m,
        track_name=getattr(track, "name", None),
        track_path="track.geojson",
        chainage_doubt_m=0.0,  # the renderer places every frame exactly
        metadata={
            "description": f"synthetic survey, seed {seed}, sky {sky}",
            "generator": "predisat.synth.generate",
            **({"rig": rig.name} if rig is not None else {}),
        },
        overwrite=overwrite,
    ) as writer:
        for job, frames in _render_all(context, run.jobs, workers, casters, progress):
            rows += [_write_frame(writer, truth_dir, run, job, frame, write_attitude, seed)
                     for frame in frames]  # fmt: skip
    _write_frames_csv(truth_dir / "frames.csv", rows)
    write_bytes_atomic(
        truth_dir / "README.txt",
        _readme(track, from_m, to_m, sky, seed, world.spec, s.size, len(rows)).encode(),
    )
    return SynthResult(out, survey_dir, truth_dir, int(s.size), len(rows))


def design_cant_mm(
    track: TrackMap, chainage_m: ArrayLike, line_speed_kmh: float, max_cant_mm: float
) -> NDArray:
    """The synthetic line's cant: each curve's equilibrium cant at the line speed, at most
    ``max_cant_mm``, in 5 mm steps (mm, shape of ``chainage_m``)."""
    k = np.asarray(track.curvature_at(np.asarray(chainage_m, float)), float)
    return np.round(np.minimum(equilibrium_cant_mm(k, line_speed_kmh), max_cant_mm) / 5.0) * 5.0


def _check_request(
    from_m: float, to_m: float, length_m: float, workers: int, spacing_m: float, speed_mps: float
) -> None:
    """Raise ValueError for a chainage interval off the track or a non-positive setting."""
    if not (0.0 <= from_m < to_m <= length_m + 1e-6):
        raise ValueError(
            f"chainage interval [{from_m}, {to_m}] m must satisfy 0 <= from_m < to_m <= "
            f"{length_m:.1f} (the track length); choose a stretch inside the track"
        )
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if spacing_m <= 0 or speed_mps <= 0:
        raise ValueError(f"spacing_m and speed_mps must be positive, got {spacing_m}, {speed_mps}")


def _side_cameras(camera: CameraModel, pitch_deg: float) -> dict[str, tuple[CameraModel, Mount]]:
    """The left and right cameras looking square to the track, pitched up ``pitch_deg``."""
    return {
        side: (camera, Mount(
            side, 90.0 if side == "left" else -90.0, pitch_deg, 0.0, Mount.default(side).lever_arm_m
        ))
        for side in ("left", "right")
    }  # fmt: skip


@dataclass(frozen=True)
class _PositionJob:
    """One antenna position to render: both side frames share its sky and time."""

    index: int
    chainage_m: float
    elapsed_s: float
    sky: SkyModel
    roll_deg: float = 0.0  # the vehicle's attitude (Mount.on_vehicle)
    pitch_deg: float = 0.0


@dataclass(frozen=True)
class _Positions:
    """The antenna positions of a run: where, when, the sun, and the render job of each.

    Arrays have shape (n,): geodetic position (deg, deg, m), time (GPS s), sun azimuth and
    elevation (deg, local ENU at the antenna).
    """

    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    gps_s: NDArray
    sun_az_deg: NDArray
    sun_el_deg: NDArray
    jobs: list[_PositionJob]

    @classmethod
    def along(
        cls,
        world: World,
        chainage_m: NDArray,
        antenna_height_m: float,
        speed_mps: float,
        start_gps_s: float | None,
        sky: str,
        seed: int,
    ) -> _Positions:
        """Positions at ``chainage_m`` (the first at ``start_gps_s``, default mid-morning)."""
        s = chainage_m
        ant = world.antenna_enu(s, antenna_height_m)
        lat, lon, h = world.frame.to_geodetic(ant)
        if start_gps_s is None:
            start_gps_s = daytime_gps_s(float(wrap_lon_deg(np.mean(unwrap_lon_deg(lon)))))
        gps = start_gps_s + (s - s[0]) / speed_mps
        sun_az, sun_el = sun_azel(gps, lat, lon)
        rot = world.frame.rotation_from(lat, lon)
        sun_frame = np.einsum(
            "nij,nj->ni",
            rot,
            np.stack([sun_direction_enu(a, e) for a, e in zip(sun_az, sun_el, strict=True)]),
        )
        f_az, f_el, _ = enu_to_azel(sun_frame)
        cond, sky_id = sky_schedule(sky, s, seed)
        jobs = [
            _PositionJob(
                index=i,
                chainage_m=float(s[i]),
                elapsed_s=float(gps[i] - start_gps_s),
                sky=SkyModel.of(
                    str(cond[i]), float(f_az[i]), float(f_el[i]), seed=seed * 1000 + int(sky_id[i])
                ),
            )
            for i in range(s.size)
        ]
        return cls(lat, lon, h, gps, sun_az, sun_el, jobs)

    def canted(
        self, track: TrackMap, line_speed_kmh: float, max_cant_mm: float, speed_kmh: float
    ) -> _Positions:
        """The run with the vehicle rolled by each curve's cant and pitched by the grade."""
        s = np.array([j.chainage_m for j in self.jobs])
        k = np.asarray(track.curvature_at(s), float)
        roll = body_roll_deg(k, design_cant_mm(track, s, line_speed_kmh, max_cant_mm), speed_kmh)
        pitch = np.degrees(np.arctan(np.asarray(track.grade_at(s), float)))
        jobs = [
            replace(j, roll_deg=float(r), pitch_deg=float(p))
            for j, r, p in zip(self.jobs, roll, pitch, strict=True)
        ]
        return replace(self, jobs=jobs)


CAMERA_CLOCK_JITTER_S = 0.002
"""Scatter of the synthetic cameras' capture stamps about their clock, seconds."""


def camera_clock_s(gps_s: float, side: str, start_gps_s: float, index: int, seed: int) -> float:
    """A synthetic camera's capture time of a frame, seconds since 1970 by its own clock.

    Each camera's clock keeps local time one hour ahead of UTC, is set within half a minute
    and drifts by up to 30 ppm (both drawn from ``seed`` and the camera's place), and stamps
    each frame with a 2 ms scatter (drawn from ``seed``, place and frame index), as a
    camera's EXIF ``DateTimeOriginal`` (:mod:`predisat.survey.capture`).
    """
    place = sorted(_CAMERA_PLACES).index(side) if side in _CAMERA_PLACES else 0
    rng = np.random.default_rng([seed, place])
    set_s, drift = rng.uniform(-30.0, 30.0), rng.uniform(-30e-6, 30e-6)
    jitter = np.random.default_rng([seed, place, index]).normal(0.0, CAMERA_CLOCK_JITTER_S)
    utc_s = gps_s - float(gps_minus_utc_at_gps_s(gps_s)) + _GPS_TO_UNIX_S
    return utc_s + 3600.0 + set_s + drift * (gps_s - start_gps_s) + float(jitter)


_CAMERA_PLACES = ("front", "left", "rear", "right", "roof")
_GPS_TO_UNIX_S = 315964800.0  # 1980-01-06 in seconds since 1970-01-01


def _write_frame(
    writer: SurveyWriter,
    truth_dir: Path,
    run: _Positions,
    job: _PositionJob,
    frame: _Frame,
    write_attitude: bool = True,
    seed: int = 0,
) -> dict[str, str]:
    """Add one rendered frame to the survey, write its label; its row of ``frames.csv``."""
    i = job.index
    side, img, label, quality = frame
    fid = writer.add_frame(
        img,
        side,
        float(run.gps_s[i]),
        chainage_m=job.chainage_m,
        lat_deg=float(run.lat_deg[i]),
        lon_deg=float(run.lon_deg[i]),
        h_m=float(run.h_m[i]),
        jpeg_quality=quality,
        roll_deg=job.roll_deg if write_attitude else None,
        pitch_deg=job.pitch_deg if write_attitude else None,
        capture_time_s=camera_clock_s(float(run.gps_s[i]), side, float(run.gps_s[0]), i, seed),
    )
    ok, buf = cv2.imencode(".png", label)
    if not ok:
        raise OSError(f"PNG encoding of the label of frame {fid} failed")
    write_bytes_atomic(truth_dir / "labels" / f"{fid}.png", buf.tobytes())
    return {
        "frame_id": fid, "side": side, "chainage_m": repr(job.chainage_m),
        "gps_s": repr(float(run.gps_s[i])), "sky": job.sky.condition,
        "cloud_cover": f"{job.sky.cloud_cover:.3f}",
        "sun_az_deg": f"{run.sun_az_deg[i]:.4f}", "sun_el_deg": f"{run.sun_el_deg[i]:.4f}",
        "sky_fraction": f"{float(np.mean(label == 255)):.4f}",
        "roll_deg": repr(job.roll_deg), "pitch_deg": repr(job.pitch_deg),
    }  # fmt: skip


def _write_frames_csv(path: Path, rows: list[dict[str, str]]) -> None:
    buf_csv = io.StringIO()
    wr = csv.DictWriter(buf_csv, fieldnames=list(rows[0]), lineterminator="\n")
    wr.writeheader()
    wr.writerows(rows)
    write_bytes_atomic(path, buf_csv.getvalue().encode())


@dataclass(frozen=True)
class _RenderContext:
    """Everything a rendering process needs besides the job (sent once per process)."""

    world: World
    backend: str
    cameras: dict[str, tuple[CameraModel, Mount]]  # by position, in rig order
    options: RenderOptions
    antenna_height_m: float
    seed: int


_Frame = tuple[str, NDArray, NDArray, int]  # side, image BGR, label, JPEG quality
_POSITION_KEY = {"left": 0, "right": 1, "front": 2, "rear": 3, "roof": 4}


def _render_position(context: _RenderContext, casters: Casters, job: _PositionJob) -> list[_Frame]:
    frames = []
    for side, (camera, mount) in context.cameras.items():
        # One generator per frame, keyed on (seed, position, camera): the output does not
        # depend on the order or the process a frame is rendered in (left 0, right 1, as before
        # there were other positions).
        rng = np.random.default_rng([context.seed, job.index, _POSITION_KEY[side]])
        pose = camera_pose(
            context.world, job.chainage_m, mount, context.antenna_height_m,
            roll_deg=job.roll_deg, pitch_deg=job.pitch_deg,
        )  # fmt: skip
        img, label = render_frame(
            context.world, casters, camera, pose, job.sky, rng, context.options,
            elapsed_s=job.elapsed_s,
        )  # fmt: skip
        frames.append((side, img, label, int(rng.integers(85, 93))))
    return frames


# Per-process state of the rendering pool: the context and the casters built from it once per
# worker (open3d scenes cannot be pickled, and rebuilding them per job would dominate).
_POOL_STATE: dict[str, Any] = {}  # Any: "context" a _RenderContext, "casters" its Casters


def _pool_init(context: _RenderContext) -> None:
    _POOL_STATE["context"] = context
    _POOL_STATE["casters"] = Casters.for_world(context.world, context.backend)


def _pool_render(job: _PositionJob) -> list[_Frame]:
    return _render_position(_POOL_STATE["context"], _POOL_STATE["casters"], job)


def _render_all(
    context: _RenderContext,
    jobs: list[_PositionJob],
    workers: int,
    casters: Casters,
    progress: bool,
) -> Iterator[tuple[_PositionJob, list[_Frame]]]:
    """Render every job, in order, serially or in a pool of ``workers`` processes."""
    bar: tqdm[NoReturn] | None = None
    if progress:
        bar = tqdm(total=len(jobs), desc="rendering", unit="pos")
    try:
        if workers == 1:
            for job in jobs:
                yield job, _render_position(context, casters, job)
                if bar is not None:
                    bar.update()
            return
        # spawn, not fork: open3d's thread pool does not survive a fork.
        with ProcessPoolExecutor(
            workers, mp_context=mp.get_context("spawn"), initializer=_pool_init,
            initargs=(context,),
        ) as pool:  # fmt: skip
            for job, frames in zip(jobs, pool.map(_pool_render, jobs), strict=True):
                yield job, frames
                if bar is not None:
                    bar.update()
    finally:
        if bar is not None:
            bar.close()


def _readme(
    track: TrackMap,
    from_m: float,
    to_m: float,
    sky: str,
    seed: int,
    spec: WorldSpec,
    n_pos: int,
    n_frames: int,
) -> str:
    kinds = ", ".join(
        f"{st.kind} {st.start_m:.0f}-{st.end_m:.0f} m ({st.side})" for st in spec.stretches
    )
    return f"""Ground truth of a synthetic PREDISAT survey (predisat.synth.generate)

track: {getattr(track, "name", "track")}; chainage {from_m:.1f}-{to_m:.1f} m; {n_pos} positions,
{n_frames} frames; sky: {sky}; seed: {seed}
scenery: {kinds}

labels/<frame_id>.png  8-bit sky label of each survey frame (same size as the image):
                       255 sky, 128 thin L-band-transparent structure (wire, cantilever tube)
                       with sky behind it, 0 obstacle (or outside a fisheye's image circle);
                       from the ray through each pixel centre.
frames.csv             per frame: frame_id, side, chainage_m, gps_s, sky condition, cloud cover,
                       sun azimuth/elevation (deg, local ENU at the antenna), sky fraction, the
                       vehicle's roll and pitch (deg; 0 unless the curves are canted).
cant.csv               with canted curves only: the line's cant (chainage_m, cant_mm), as
                       `predisat process --cant-table` reads it.
true_masks.npz         predisat.masks.truth.TrueMasks.load(): per position, the highest
                       L-band-blocking elevation in every azimuth bin, and obstacle descriptors.
world.npz              predisat.synth.world.World.load(): the scene mesh and recipe.

The survey itself is in ../survey (predisat.survey.Survey.load). Frames are JPEG (quality
85-92); labels are lossless PNG.
"""


def contact_sheet(
    survey_dir: str | os.PathLike[str],
    out_png: str | os.PathLike[str],
    n_frames: int = 12,
    columns: int = 4,
    tile_width_px: int = 320,
    frames: list[str] | None = None,
    notes: dict[str, str] | None = None,
) -> Path:
    """Tile sample frames of a survey into one image with captions (frame, side, km, sky).

    The image format follows the suffix of ``out_png`` (``.png``, or ``.jpg`` for a small file).

    Parameters
    ----------
    survey_dir : path-like
        A survey folder; the sky condition is read from ``../truth/frames.csv`` when present.
    out_png : path-like
    n_frames : int
        Frames spread evenly over the survey (ignored when ``frames`` is given).
    columns, tile_width_px : int
        Grid layout and tile width.
    frames : list of str, optional
        Frame ids to show.
    notes : dict, optional
        Extra caption text per frame id (e.g. the scenery).

    Returns
    -------
    Path
        ``out_png``.
    """
    survey = Survey.load(survey_dir, check_images=False)
    ids = [str(x) for x in survey.frames.frame_id]
    if not ids:
        raise ValueError(f"{survey_dir}: the survey has no frames")
    if frames is None:
        pick = np.unique(np.linspace(0, len(ids) - 1, max(1, n_frames)).round().astype(int))
        chosen = [ids[k] for k in pick]
    else:
        unknown = [f for f in frames if f not in ids]
        if unknown:
            raise KeyError(f"frames {unknown} are not in {survey_dir}")
        chosen = list(frames)
    sky_of: dict[str, str] = {}
    truth_csv = Path(survey_dir).parent / "truth" / "frames.csv"
    if truth_csv.exists():
        with open(truth_csv, newline="") as fh:
            sky_of = {r["frame_id"]: r["sky"] for r in csv.DictReader(fh)}
    tiles = []
    for fid in chosen:
        k = survey.frames.index_of(fid)
        img = survey.read_image(k)
        th = round(img.shape[0] * tile_width_px / img.shape[1])
        img = cv2.resize(img, (tile_width_px, th), interpolation=cv2.INTER_AREA)
        side = str(survey.frames.side[k])
        km = float(survey.frames.chainage_m[k]) / 1000.0
        note = (notes or {}).get(fid, "")
        text = f"{fid} {side} km {km:.3f} {sky_of.get(fid, '')} {note}".strip()
        cv2.rectangle(img, (0, th - 18), (tile_width_px, th), (0, 0, 0), -1)
        cv2.putText(
            img, text, (4, th - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1, cv2.LINE_AA
        )
        tiles.append(img)
    cols = max(1, min(columns, len(tiles)))
    blank = np.zeros_like(tiles[0])
    tiles += [blank] * (-len(tiles) % cols)
    sheet = np.vstack([np.hstack(tiles[r : r + cols]) for r in range(0, len(tiles), cols)])
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    suffix = out.suffix.lower() if out.suffix.lower() in (".png", ".jpg", ".jpeg") else ".png"
    params = [cv2.IMWRITE_JPEG_QUALITY, 88] if suffix != ".png" else []
    ok, buf = cv2.imencode(suffix, sheet, params)
    if not ok:
        raise OSError(f"encoding of the contact sheet {out} failed")
    write_bytes_atomic(out, buf.tobytes())
    return out
