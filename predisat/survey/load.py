"""Loading and validating a survey folder (format v1, see ``docs/survey-format.md``)."""

from __future__ import annotations

import csv
import io
import itertools
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from types import MappingProxyType
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError

from predisat.camera.models import CalibrationError, CameraModel, Mount
from predisat.geodesy import WGS84
from predisat.jsontypes import JsonDict
from predisat.storage import (
    Location,
    StorageOptions,
    exists,
    input_path,
    is_remote,
    join,
    location,
    name_of,
    read_bytes,
)
from predisat.survey.format import (
    ATTITUDE_LIMITS_DEG,
    DIRECTIONS,
    FORMAT,
    MANIFEST_COLUMNS,
    OTHER_SIDE,
    REQUIRED_COLUMNS,
    SIDES,
    VERSION,
    Frames,
    SurveyCamera,
    SurveyError,
    SurveyProblem,
    empty_frames,
)
from predisat.survey.images import (
    decode_frame,
    exif_orientation,
    on_disk_spelling,
    orientation_problem,
)
from predisat.track import TrackMap, load_track

__all__ = [
    "MAX_ANTENNA_HEIGHT_M",
    "TRACK_AGREE_DEG",
    "TRACK_AGREE_M",
    "Survey",
    "check_calibration_sizes",
    "check_survey_track",
]

MAX_ANTENNA_HEIGHT_M = 8.0
"""Highest antenna above the track axis a survey may state, metres: a rail vehicle's roof
stands at most 4.65 m (UIC gauge) plus a mast."""

_POSITIONS_HINT = (
    "'left' or 'right' (vehicle side), 'front' or 'rear' (cab) or 'roof' (360-degree camera)"
)


@dataclass(frozen=True, eq=False)  # numpy columns: compare explicitly
class Survey:
    """A validated survey folder; build with :meth:`load`.

    Attributes
    ----------
    root : Path or str
        The survey folder: a local path, or a URL (a str) of a survey on shared or object
        storage (:mod:`predisat.storage`).
    direction_of_travel : {"increasing", "decreasing"}
        Chainage direction the vehicle drove.
    antenna_height_m : float
        GNSS antenna above the track axis.
    cameras : Mapping[str, SurveyCamera]
        Per vehicle side.
    frames : Frames
        The valid frames, in manifest order.
    problems : tuple of SurveyProblem
        Problems found (frames skipped in ``on_error="skip"`` mode); empty otherwise.
    track : TrackMap or None
        The track the frames were checked and mapped against (given or named in survey.yaml).
    chainage_doubt_m : float or None
        The survey's stated positioning accuracy along the track (survey.yaml
        ``chainage_doubt_m``): no frame's true chainage is further from its stated one,
        metres. None: the survey does not say.
    chainage_jitter_m : float or None
        survey.yaml ``chainage_jitter_m``: how far frames a few hundred metres apart may be
        off from each other's error (the positioning's relative accuracy), metres; None: not
        stated.
    """

    root: Location
    direction_of_travel: Literal["increasing", "decreasing"]
    antenna_height_m: float
    cameras: Mapping[str, SurveyCamera]
    frames: Frames
    track_name: str | None = None
    track_path: Location | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)
    problems: tuple[SurveyProblem, ...] = ()
    version: int = VERSION
    track: TrackMap | None = field(default=None, repr=False)
    storage_options: StorageOptions = field(default_factory=dict, repr=False)
    chainage_doubt_m: float | None = None
    chainage_jitter_m: float | None = None

    @property
    def reverse(self) -> bool:
        """True when the vehicle drove toward decreasing chainage."""
        return self.direction_of_travel == "decreasing"

    @property
    def chainage_m(self) -> NDArray:
        """Chainage of every frame, shape (n,)."""
        return self.frames.chainage_m

    def camera(self, side: str) -> SurveyCamera:
        """The camera on a vehicle side."""
        if side not in self.cameras:
            raise KeyError(
                f"survey {self.root} has no {side!r} camera; it has {sorted(self.cameras)}"
            )
        return self.cameras[side]

    def image_path(self, frame: int | str) -> Location:
        """Location of a frame's image (absolute path, or URL), by table index or frame_id."""
        i = self.frames.index_of(frame) if isinstance(frame, str) else int(frame)
        return join(self.root, str(self.frames.image[i]))

    def read_image(self, frame: int | str) -> NDArray:
        """A frame's image as a BGR uint8 array (H, W, 3)."""
        path = self.image_path(frame)
        if is_remote(path):
            data = read_bytes(path, self.storage_options)
        else:
            data = Path(path).read_bytes()
        img, problem = decode_frame(data, str(path))
        if img is None:
            raise OSError(problem)
        return img

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        track: TrackMap | None = None,
        check_images: bool = True,
        max_offset_m: float = 10.0,
        on_error: Literal["raise", "skip"] = "raise",
        max_speed_mps: float = 100.0,
        storage_options: StorageOptions | None = None,
    ) -> Survey:
        """Read and validate a survey folder.

        Parameters
        ----------
        path : path-like or str
            The survey folder (or its ``survey.yaml``): a local path, or an fsspec URL
            (``file://``, ``http(s)://``, ``s3://``..., :mod:`predisat.storage`).
        track : TrackMap, optional
            Track to map positions on and to check them against; by default the track file
            named in ``survey.yaml`` when there is one.
        check_images : bool
            Check that every image exists and has its camera's size (reads headers only).
        max_offset_m : float
            Largest accepted distance from the track axis (GNSS positions) or beyond its ends.
        on_error : {"raise", "skip"}
            ``"raise"``: any problem raises :class:`SurveyError` listing all of them.
            ``"skip"``: bad frames are dropped and listed in :attr:`problems`; survey-level
            problems (survey.yaml, calibrations, manifest columns) still raise.
        max_speed_mps : float
            Fastest plausible survey speed: a frame whose chainage is further from both
            neighbours on its side than this speed allows in their time apart (while the two
            neighbours agree) contradicts the run and is a bad frame. Default 100 m/s
            (360 km/h).
        storage_options : mapping, optional
            Options of the URL's fsspec file system (credentials, endpoint...).

        Raises
        ------
        SurveyError
        """
        if on_error not in ("raise", "skip"):
            raise ValueError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
        root = location(path)
        if name_of(root) == "survey.yaml":
            root = root.parent if isinstance(root, Path) else root.rsplit("/", 1)[0]
        opts = dict(storage_options or {})
        header = _read_header(root, opts)
        if track is None and header["track_path"] is not None:
            track = _load_track(root, header["track_path"], header["track_name"], opts)
        elif track is not None and header["track_path"] is not None:
            # before any frame is read against it: a track that runs the other way from the
            # survey's own sent a user round between "increasing" and "decreasing"
            own = _load_track(root, header["track_path"], header["track_name"], opts)
            _check_same_way(root, own, track)
        rows, frame_problems = _read_manifest(
            root, header, track, check_images, max_offset_m, max_speed_mps, opts
        )
        if frame_problems and on_error == "raise":
            raise SurveyError(root, frame_problems)
        return cls(
            root=root,
            direction_of_travel=header["direction"],
            antenna_height_m=header["antenna_height_m"],
            cameras=MappingProxyType(header["cameras"]),
            frames=rows,
            track_name=header["track_name"],
            track_path=header["track_path"],
            metadata=MappingProxyType(header["metadata"]),
            problems=tuple(frame_problems),
            version=header["version"],
            track=track,
            storage_options=opts,
            chainage_doubt_m=header["chainage_doubt_m"],
            chainage_jitter_m=header["chainage_jitter_m"],
        )


def _read_header(root: Location, opts: StorageOptions) -> dict[str, Any]:
    """Parse survey.yaml and the calibrations; raise SurveyError listing every problem."""
    doc = _read_yaml(root, opts)
    probs: list[SurveyProblem] = []

    def bad(msg: str) -> None:
        probs.append(SurveyProblem(f"survey.yaml: {msg}"))

    version, direction = _check_format(doc, bad)
    antenna_height_m = _antenna_height_m(doc, bad)
    chainage_doubt_m = _chainage_doubt_m(doc, bad, "chainage_doubt_m")
    chainage_jitter_m = _chainage_doubt_m(doc, bad, "chainage_jitter_m")
    track_name, track_path = _track_spec(root, doc, bad)
    cameras = _read_cameras(root, doc, bad, opts)
    if probs:
        raise SurveyError(root, probs)
    known = {"format", "version", "direction_of_travel", "antenna_height_m", "track", "cameras",
             "chainage_doubt_m", "chainage_jitter_m"}  # fmt: skip
    return {
        "version": version,
        "direction": direction,
        "antenna_height_m": antenna_height_m,
        "chainage_doubt_m": chainage_doubt_m,
        "chainage_jitter_m": chainage_jitter_m,
        "track_name": None if track_name is None else str(track_name),
        "track_path": track_path,
        "cameras": cameras,
        "metadata": {k: v for k, v in doc.items() if k not in known},
    }


def _read_yaml(root: Location, opts: StorageOptions) -> JsonDict:
    """The mapping of ``root/survey.yaml``; SurveyError if the folder or file is unreadable."""
    yaml_path = join(root, "survey.yaml")
    if isinstance(root, Path) and not root.is_dir():
        raise SurveyError(root, [SurveyProblem("not a folder; give the survey folder")])
    if isinstance(root, Path) and isinstance(yaml_path, Path) and not yaml_path.is_file():
        # `predisat synth --out DIR` writes the survey into DIR/survey (a user trial gave DIR)
        inner = sorted(p.parent for p in root.glob("*/survey.yaml"))
        hint = f": the survey is in {inner[0]}; give that folder" if inner else ""
        raise SurveyError(
            root, [SurveyProblem(f"survey.yaml is missing{hint}; see docs/survey-format.md")]
        )
    try:
        if isinstance(yaml_path, Path):
            text = yaml_path.read_text(encoding="utf-8")
        else:
            text = read_bytes(yaml_path, opts).decode("utf-8")
        doc = yaml.safe_load(text)
    except FileNotFoundError as exc:  # a URL: the folder cannot be listed everywhere (HTTP)
        raise SurveyError(root, [SurveyProblem(
            f"survey.yaml is missing ({exc}); see docs/survey-format.md"
        )]) from None  # fmt: skip
    except (OSError, yaml.YAMLError) as exc:
        raise SurveyError(root, [SurveyProblem(f"survey.yaml cannot be parsed: {exc}")]) from None
    except UnicodeDecodeError as exc:
        raise SurveyError(root, [SurveyProblem(
            f"survey.yaml is not UTF-8 text (byte {exc.start}: {exc.reason}); save it as UTF-8"
        )]) from None  # fmt: skip
    if not isinstance(doc, dict):
        raise SurveyError(root, [SurveyProblem("survey.yaml must be a mapping of fields")])
    return doc


def _check_format(doc: JsonDict, bad: Callable[[str], None]) -> tuple[Any, Any]:
    """The ``version`` and ``direction_of_travel`` (as written), checked with ``format``.

    ``Any``: values as the YAML gives them, reported through ``bad`` when wrong.
    """
    if doc.get("format") != FORMAT:
        bad(f"format must be {FORMAT!r}, got {doc.get('format')!r}")
    version = doc.get("version")
    if version != VERSION:
        bad(
            f"version {version!r} is not supported (this PREDISAT reads version {VERSION}); "
            "upgrade predisat or convert the survey"
        )
    direction = doc.get("direction_of_travel")
    if direction not in DIRECTIONS:
        bad(f"direction_of_travel must be 'increasing' or 'decreasing' chainage, got {direction!r}")
    return version, direction


def _antenna_height_m(doc: JsonDict, bad: Callable[[str], None]) -> float:
    """``antenna_height_m``, metres (nan, reported through ``bad``, when not a finite number)."""
    antenna_height_m = math.nan
    try:
        antenna_height_m = float(doc.get("antenna_height_m"))  # type: ignore[arg-type]
        if not math.isfinite(antenna_height_m):
            raise ValueError
    except (TypeError, ValueError):
        bad(
            "antenna_height_m must be a number (metres above the track axis), "
            f"got {doc.get('antenna_height_m')!r}"
        )
        return math.nan
    if not 0.0 < antenna_height_m <= MAX_ANTENNA_HEIGHT_M:
        # a user trial: -4 trusted blocked directions, 400 (centimetres) lost all the sky
        bad(
            f"antenna_height_m {antenna_height_m:g} is not a height above the track axis in "
            f"metres: it must lie in (0, {MAX_ANTENNA_HEIGHT_M:g}] (a railcar's roof antenna "
            "stands 3.5-4.5 m up, a trolley's 1-2 m); centimetres or a negative sign?"
        )
        return math.nan
    return antenna_height_m


def _chainage_doubt_m(doc: JsonDict, bad: Callable[[str], None], key: str) -> float | None:
    """``chainage_doubt_m`` or ``chainage_jitter_m`` (``key``), metres, None when absent
    (reported through ``bad`` when not a finite length >= 0)."""
    value = doc.get(key)
    if value is None:
        return None
    try:
        if isinstance(value, bool):
            raise TypeError
        out = float(value)
        if not (math.isfinite(out) and out >= 0.0):
            raise ValueError
    except (TypeError, ValueError):
        what = ("how far any frame's true chainage may be from the manifest's: 0.05 for RTK, "
                "3-5 for plain GNSS" if key == "chainage_doubt_m" else
                "how far frames a few hundred metres apart may be off from each other's error")
        bad(f"{key} must be a length >= 0 in metres ({what}), got {value!r}")  # fmt: skip
        return None
    return out


def _track_spec(
    root: Location, doc: JsonDict, bad: Callable[[str], None]
) -> tuple[Any, Location | None]:  # Any: the name as the YAML gives it
    """The ``track`` mapping's ``name`` and ``path`` (relative to ``root``, None if absent)."""
    track_doc = doc.get("track") or {}
    if not isinstance(track_doc, dict):
        bad("track must be a mapping with 'name' and optional 'path'")
        track_doc = {}
    track_path = join(root, str(track_doc["path"])) if track_doc.get("path") else None
    return track_doc.get("name"), track_path


def _read_cameras(
    root: Location, doc: JsonDict, bad: Callable[[str], None], opts: StorageOptions
) -> dict[str, SurveyCamera]:
    """The cameras by side, their calibrations read; each problem reported through ``bad``."""
    cameras: dict[str, SurveyCamera] = {}
    cams = doc.get("cameras")
    if not isinstance(cams, dict) or not cams:
        bad(
            "cameras must map 'left' and/or 'right' (or 'front', 'rear', 'roof') to "
            "{calibration: <yaml path>, mount: {...}}"
        )
        cams = {}
    for side, spec in cams.items():
        if side not in SIDES:
            bad(f"camera side {side!r} is unknown; use {_POSITIONS_HINT}")
            continue
        if not isinstance(spec, dict) or "calibration" not in spec:
            bad(f"cameras.{side} needs a 'calibration' path (e.g. calib/{side}.yaml)")
            continue
        calib_path = join(root, str(spec["calibration"]))
        try:
            if is_remote(calib_path) and not exists(calib_path, opts):
                raise CalibrationError(f"{calib_path}: no such file; check the path")
            with input_path(calib_path, opts) as local_calib:  # OpenCV reads local files
                model = CameraModel.from_yaml(local_calib)
        except CalibrationError as exc:
            bad(f"cameras.{side}.calibration: {exc}")
            continue
        raw_mount = spec.get("mount") or {}
        mount_doc = dict(raw_mount) if isinstance(raw_mount, dict) else raw_mount
        # a near-level side camera (pitch 0.17-1.57 deg) reads as a mount in radians: the
        # survey says so with ``angles_in_degrees: true`` (a review: pitch_deg 1.0 was refused)
        stated_degrees = (
            isinstance(mount_doc, dict) and mount_doc.pop("angles_in_degrees", False) is True
        )
        try:
            mount = Mount.from_dict(side, mount_doc)
        except (TypeError, ValueError) as exc:
            bad(f"cameras.{side}.mount: {exc}")
            continue
        radians = None if stated_degrees else _mount_in_radians(mount)
        if radians:
            bad(f"cameras.{side}.mount: {radians}")
            continue
        cameras[side] = SurveyCamera(side, model, mount, calib_path)
    return cameras


# how far a given track may leave the track a survey names where its frames are: the frames
# were taken there, and a pose off by more misplaces what they see (a 2 deg mount error
# already costs 0.2 % false trust, docs/survey-format.md)
TRACK_AGREE_M = 1.0
TRACK_AGREE_DEG = 0.5


def check_survey_track(survey: Survey, track: TrackMap) -> None:
    """Refuse ``track`` for a survey whose own track (named in its survey.yaml) it leaves, at
    the survey's frames, by more than :data:`TRACK_AGREE_M` or :data:`TRACK_AGREE_DEG`:
    processed on it, the frames would be posed where they were not taken.

    Raises
    ------
    ValueError
        Naming the survey, both tracks, the chainage and the gap.
    """
    if survey.track_path is None:
        return
    own = Survey.load(survey.root, check_images=False, on_error="skip",
                      storage_options=survey.storage_options).track  # fmt: skip
    if own is None:
        return
    ch = np.asarray(survey.frames.chainage_m, float)
    ch = ch[np.isfinite(ch) & (ch >= 0.0) & (ch <= min(track.length_m, own.length_m))]
    if not len(ch):
        return
    lat_a, lon_a, _ = own.position_at(ch)
    lat_b, lon_b, _ = track.position_at(ch)
    off_m = np.asarray(WGS84.inv(lon_a, lat_a, lon_b, lat_b)[2], float)
    turn = np.abs((own.heading_at(ch) - track.heading_at(ch) + 180.0) % 360.0 - 180.0)
    i = int(np.argmax(np.maximum(off_m / TRACK_AGREE_M, turn / TRACK_AGREE_DEG)))
    if off_m[i] > TRACK_AGREE_M or turn[i] > TRACK_AGREE_DEG:
        raise ValueError(
            f"{survey.root}: the track given ({track.name!r}) leaves the survey's own track "
            f"({survey.track_path}) by {off_m[i]:.1f} m and {turn[i]:.1f} deg at chainage "
            f"{ch[i]:.0f} m, where frames were taken (limits {TRACK_AGREE_M:g} m, "
            f"{TRACK_AGREE_DEG:g} deg): processed on it, the frames would be posed where they "
            "were not; leave --track out to use the survey's own, or give a track that "
            "follows it (for `predisat network`, the survey's own geometry and --tolerance-m)"
        )


def _check_same_way(root: Location, own: TrackMap, track: TrackMap) -> None:
    """Refuse ``track`` when it runs the other way from the survey's ``own`` track where they
    overlap (chainage increasing the other way): the frames' chainages and directions of
    travel would all read reversed on it."""
    s = np.arange(0.0, own.length_m, 10.0)
    lat, lon, _ = own.position_at(s)
    proj = track.project(lat, lon)
    on = ~np.asarray(proj.clamped, bool) & (np.abs(np.asarray(proj.offset_m, float)) < 50.0)
    if on.sum() < 3:
        return  # they hardly overlap: the frames' own checks will say so
    ch = np.asarray(proj.chainage_m, float)[on]
    step = np.diff(ch)[np.diff(np.flatnonzero(on)) == 1]  # between neighbouring samples
    # the usual way of a step (a loop's wrap, or a stretch off the track, is one step)
    if step.size >= 2 and np.median(step) < 0.0:
        name = getattr(track, "name", "track")
        raise SurveyError(root, [SurveyProblem(
            f"the track given ({name!r}) runs the other way from the survey's own track "
            f"({own.name!r}): its chainage {ch[0]:.0f} m is the survey track's {s[on][0]:.0f} m "
            f"and decreases along it; reverse the track's line (or, for `predisat network`, its "
            "feature in the network file), or process the survey on its own track"
        )])  # fmt: skip


def _load_track(root: Location, path: Location, name: str | None, opts: StorageOptions) -> TrackMap:
    try:
        with input_path(path, opts) as local_track:
            return load_track(local_track, name)
    except (OSError, ValueError) as exc:
        raise SurveyError(
            root,
            [
                SurveyProblem(
                    f"survey.yaml: track.path {path} cannot be loaded ({exc}); fix the "
                    "path or give another track (CLI: --track FILE; Python: Survey.load(track=...))"
                )
            ],
        ) from None


def _parse_float(text: str, column: str, fid: str, row: int, probs: list[SurveyProblem]) -> float:
    """Float of a manifest cell; NaN when empty; a problem when not a finite number."""
    text = text.strip()
    if text == "":
        return math.nan
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        probs.append(
            SurveyProblem(
                f"{column} {text!r} is not a finite number; write a decimal number", fid, row
            )
        )
    return value


@dataclass
class _Row:
    row: int
    frame_id: str
    image: str
    side: str
    gps_s: float = math.nan
    chainage_m: float = math.nan
    lat_deg: float = math.nan
    lon_deg: float = math.nan
    h_m: float = math.nan
    offset_m: float = math.nan
    roll_deg: float = math.nan
    pitch_deg: float = math.nan
    probs: list[SurveyProblem] = field(default_factory=list)

    def bad(self, message: str) -> None:
        self.probs.append(SurveyProblem(message, self.frame_id or None, self.row))


def _same_row(a: _Row, b: _Row) -> bool:
    """Whether two manifest rows state the same frame in every field (NaN equal to NaN)."""
    for name in ("frame_id", "image", "side", "gps_s", "chainage_m", "lat_deg", "lon_deg",
                 "h_m", "offset_m", "roll_deg", "pitch_deg"):  # fmt: skip
        x, y = getattr(a, name), getattr(b, name)
        if x != y and not (isinstance(x, float) and isinstance(y, float)
                           and math.isnan(x) and math.isnan(y)):  # fmt: skip
            return False
    return True


def _check_image(
    root: Location, rel: str, cam: CameraModel, opts: StorageOptions
) -> tuple[str | None, tuple[int, int] | None]:
    """The image's problem (None if none) and, when only its size disagrees with the
    calibration, that size ``(width, height)``."""
    path = join(root, rel)
    if not exists(path, opts) or (isinstance(path, Path) and not path.is_file()):
        return f"image {rel} is missing; copy it into the survey folder or remove the row", None
    try:
        source = path if isinstance(path, Path) else io.BytesIO(read_bytes(path, opts))
        with Image.open(source) as im:  # lazy: reads the header only
            w, h = im.size
            turn = exif_orientation(im)
    except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError) as exc:
        return f"image {rel} cannot be read ({exc}); re-export it as JPEG or PNG", None
    turned = orientation_problem(turn, rel, cam.name)
    if turned:
        return turned, None
    if (w, h) != (cam.width_px, cam.height_px):
        return (
            f"image {rel} is {w}x{h} px but calibration {cam.name!r} is "
            f"{cam.width_px}x{cam.height_px}; use the calibration of the camera that took it"
        ), (w, h)
    return None, None


def _parse_rows(
    root: Location, header: dict[str, Any], check_images: bool, opts: StorageOptions
) -> list[_Row]:
    path = join(root, "manifest.csv")
    if isinstance(path, Path) and not path.is_file():
        raise SurveyError(
            root, [SurveyProblem("manifest.csv is missing; see docs/survey-format.md")]
        )
    try:
        if isinstance(path, Path):
            text = path.read_text(encoding="utf-8-sig")
        else:
            text = read_bytes(path, opts).decode("utf-8-sig")
    except FileNotFoundError as exc:
        raise SurveyError(
            root, [SurveyProblem(f"manifest.csv is missing ({exc}); see docs/survey-format.md")]
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SurveyError(
            root, [SurveyProblem(f"manifest.csv cannot be read ({exc}); save it as UTF-8 CSV")]
        ) from None
    reader = csv.reader(io.StringIO(text))
    columns = [c.strip() for c in next(reader, [])]
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if len(columns) == 1 and sep in columns[0]:
            raise SurveyError(root, [SurveyProblem(
                f"manifest.csv: the columns are separated by {name}, not commas; save it as "
                "comma-separated values (',' between columns and '.' for decimals)"
            )])  # fmt: skip
    while columns and not columns[-1]:  # a spreadsheet's empty columns after the last one
        columns.pop()
    misnamed = {c: k for c in columns for k in MANIFEST_COLUMNS
                if c != k and c.lower() == k and k not in columns}  # fmt: skip
    if misnamed:  # read by name: Roll_deg was ignored without a word (a user trial)
        renames = ", ".join(f"{c!r} to {k!r}" for c, k in misnamed.items())
        raise SurveyError(root, [SurveyProblem(
            f"manifest.csv: column names are read as written, in lower case; rename {renames}"
        )])  # fmt: skip
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if "chainage_m" not in columns and not {"lat_deg", "lon_deg"} <= set(columns):
        missing.append("chainage_m (or lat_deg and lon_deg)")
    doubled = sorted({c for c in columns if columns.count(c) > 1})
    if missing or doubled:
        msg = f"manifest.csv: missing column(s) {missing}" if missing else ""
        msg += (
            f"{'; ' if msg else 'manifest.csv: '}duplicate column(s) {doubled}" if doubled else ""
        )
        raise SurveyError(
            root, [SurveyProblem(f"{msg}; the header must name {list(MANIFEST_COLUMNS)}")]
        )
    cameras: Mapping[str, SurveyCamera] = header["cameras"]
    rows: list[_Row] = []
    checked: dict[str, list[tuple[int, int] | None]] = {}  # per camera: wrong sizes
    for fields in reader:
        line = reader.line_num
        if not any(f.strip() for f in fields):
            continue
        if len(fields) > len(columns) and not any(f.strip() for f in fields[len(columns):]):
            fields = fields[: len(columns)]  # the empty cells of those empty columns
        cells = dict(zip(columns, (f.strip() for f in fields), strict=False))
        r = _Row(line, cells.get("frame_id", ""), cells.get("image", ""), cells.get("side", ""))
        rows.append(r)
        if len(fields) != len(columns):
            r.bad(
                f"has {len(fields)} fields but the header has {len(columns)}; fix the row's commas"
            )
            continue
        if not r.frame_id:
            r.bad("frame_id is empty; give every frame a unique id")
        if r.side not in SIDES:
            r.bad(f"side {r.side!r} is unknown; use {_POSITIONS_HINT}")
        elif r.side not in cameras:
            r.bad(
                f"side {r.side!r} has no camera in survey.yaml; "
                f"add cameras.{r.side} or fix the side"
            )
        if cells["gps_s"] == "":
            r.bad("gps_s is empty; give the GPS time in seconds since 1980-01-06")
        r.gps_s = _parse_float(cells["gps_s"], "gps_s", r.frame_id, line, r.probs)
        for col in ("chainage_m", "lat_deg", "lon_deg", "h_m"):
            setattr(r, col, _parse_float(cells.get(col, ""), col, r.frame_id, line, r.probs))
        for col, limit in ATTITUDE_LIMITS_DEG.items():
            value = _parse_float(cells.get(col, ""), col, r.frame_id, line, r.probs)
            setattr(r, col, value)
            if abs(value) > limit:
                r.bad(
                    f"{col} {value:g} is beyond +-{limit:g} deg for a rail vehicle; give the "
                    "vehicle's roll (left side up positive) and pitch (nose up positive) in "
                    "degrees, and check the IMU's axes and units"
                )
        if (cells.get("roll_deg", "") == "") != (cells.get("pitch_deg", "") == ""):
            r.bad("roll_deg and pitch_deg must be given together (or both left empty)")
        has_lat, has_lon = cells.get("lat_deg", "") != "", cells.get("lon_deg", "") != ""
        if has_lat != has_lon:
            r.bad("lat_deg and lon_deg must be given together")
        elif cells.get("chainage_m", "") == "" and not has_lat:
            r.bad("no position: give chainage_m or lat_deg and lon_deg (GNSS antenna)")
        if abs(r.lat_deg) > 90 or abs(r.lon_deg) > 180:
            r.bad(f"lat_deg/lon_deg ({r.lat_deg}, {r.lon_deg}) out of range; use WGS84 degrees")
        if r.image and not r.image.isascii() and isinstance(root, Path):
            # an accented name stored in the other Unicode normalisation: the spelling on disk
            # is the frame's, for every reader and for the cache keys alike
            r.image = on_disk_spelling(root, r.image) or r.image
        image = PurePosixPath(r.image)
        if not r.image:
            r.bad("image is empty; give the image path relative to the survey folder")
        elif image.is_absolute() or ".." in image.parts or "\\" in r.image:
            r.bad(f"image {r.image!r} must be a relative path inside the survey folder, with '/'")
        elif check_images and r.side in cameras:
            image_problem, wrong_size = _check_image(root, r.image, cameras[r.side].camera, opts)
            if image_problem:
                r.bad(image_problem)
            checked.setdefault(r.side, []).append(wrong_size)
    _check_calibration_sizes(root, cameras, checked)
    return rows


def _check_calibration_sizes(
    root: Location, cameras: Mapping[str, SurveyCamera],
    checked: dict[str, list[tuple[int, int] | None]],
) -> None:  # fmt: skip
    """Refuse a camera whose every image has the same size other than its calibration's
    (``checked``: per camera, each image's wrong size or None): the calibration is of another
    camera (or another resolution), not a few bad frames; skipping them all would leave masks
    from the other cameras alone, silently."""
    for side, sizes in sorted(checked.items()):
        if len(sizes) >= 2 and None not in sizes and len(set(sizes)) == 1:
            first = sizes[0]
            assert first is not None  # checked above
            w, h = first
            cam = cameras[side].camera
            raise SurveyError(root, [SurveyProblem(
                f"survey.yaml: camera {side!r}: all {len(sizes)} of its images are {w}x{h} px "
                f"but its calibration {cam.name!r} is {cam.width_px}x{cam.height_px}: the "
                "calibration is of another camera or resolution; give the calibration of the "
                "camera that took them"
            )])  # fmt: skip


def _mount_in_radians(mount: Mount) -> str | None:
    """What reads as a side camera's mount angle written in radians, or None.

    A side camera (left, right) looks across the track, so its yaw lies near +-90 deg, and up
    at the sky: a pitch of 10-90 deg written in radians (0.17-1.57) would look at the
    horizon. A user trial's survey.yaml with ``pitch_deg: 0.785398`` (45 deg) was taken as a
    camera looking level: every skyline stood 45 deg too low, 26.8 % of the trusted directions
    were blocked (43.7 % at the worst position), exit 0. Cab cameras and panoramas are not
    judged (a cab camera may look nearly level)."""
    if mount.side not in ("left", "right"):
        return None
    for key, value, lo, hi in (
        ("yaw_deg", mount.yaw_deg, 45.0, 135.0),
        ("pitch_deg", mount.pitch_deg, 10.0, 90.0),
    ):
        deg = math.degrees(abs(value))
        if value != 0.0 and lo <= deg <= hi:
            return (
                f"{key} {value:g} reads as radians ({math.copysign(deg, value):.1f} deg): give "
                "the mount's angles in degrees (a side camera looks across the track, yaw near "
                "+-90, and up at the sky; skylines read with a mount in radians stand tens of "
                "degrees off and a user trial's trusted 26.8 % of its directions falsely); a "
                f"camera that really is mounted {key[:-4]} {value:g} deg: add "
                "'angles_in_degrees: true' to its mount"
            )
    return None


def check_calibration_sizes(survey: Survey) -> None:
    """The survey-level check of :meth:`Survey.load` with ``check_images=True`` for a survey
    loaded without it (``predisat process``): refuse a camera whose every image (at least
    two) has one size other than its calibration's, reading image headers only.

    A user trial's left calibration for 640x480 beside 800x600 images passed ``process`` with
    exit 0: each of the 41 frames was a bad frame of its own, and the masks came out 100 %
    assumed. The first and the last image of each camera are read; the others only when
    both are of one wrong size, so a correct survey costs two header reads per camera.

    Raises
    ------
    SurveyError
        Naming the camera, the images' size, the calibration's and the fix.
    """
    frames, opts = survey.frames, survey.storage_options
    for side, sc in sorted(survey.cameras.items()):
        idx = np.flatnonzero(np.asarray(frames.side) == side)
        if idx.size < 2:
            continue

        def size(i: int, cam: CameraModel = sc.camera) -> tuple[int, int] | None:
            return _check_image(survey.root, str(frames.image[i]), cam, opts)[1]

        ends = {size(int(idx[0])), size(int(idx[-1]))}
        if len(ends) != 1 or None in ends:
            continue
        _check_calibration_sizes(survey.root, {side: sc}, {side: [size(int(i)) for i in idx]})


def _check_track(rows: list[_Row], track: TrackMap, max_offset_m: float) -> None:
    with_pos = [r for r in rows if abs(r.lat_deg) <= 90 and abs(r.lon_deg) <= 180]  # NaN: False
    name = getattr(track, "name", "track")
    if with_pos:
        proj = track.project(
            np.array([r.lat_deg for r in with_pos]), np.array([r.lon_deg for r in with_pos])
        )
        offset = np.asarray(proj.offset_m, float)
        along = np.asarray(getattr(proj, "along_m", np.zeros_like(offset)), float)
        chain = np.asarray(proj.chainage_m, float)
        for r, off, alo, ch in zip(with_pos, offset, along, chain, strict=True):
            r.offset_m = float(off)
            dist = math.hypot(off, alo)
            if not dist <= max_offset_m:
                # off the track: its chainage there means nothing (a user trial's survey in
                # another line's folder was told its chainage disagreed at the track's end)
                r.bad(
                    f"position is {dist:.1f} m from track {name!r} (limit max_offset_m="
                    f"{max_offset_m:g}); check the GNSS fix, the track map or the survey's track"
                )
                continue
            if not math.isfinite(r.chainage_m):
                r.chainage_m = float(ch)
            elif abs(r.chainage_m - ch) > max_offset_m:
                # an odometer typo or drift would put the frame's skyline elsewhere on the line
                r.bad(
                    f"chainage_m {r.chainage_m:.1f} disagrees with lat_deg/lon_deg, which lie at "
                    f"chainage {ch:.1f} m of track {name!r} (limit max_offset_m="
                    f"{max_offset_m:g}); correct one of them, or leave chainage_m empty to "
                    "take it from the position"
                )
    length = float(track.length_m)
    for r in rows:
        if (
            math.isfinite(r.chainage_m)
            and not -max_offset_m <= r.chainage_m <= length + max_offset_m
        ):
            r.bad(
                f"chainage_m {r.chainage_m:.1f} is outside track {name!r} (0 to {length:.1f} m); "
                "check the chainage or the track map"
            )


def _next_on_side(rows: list[_Row]) -> dict[int, _Row]:
    """For each row (by id), the next row on its side without a problem yet."""
    after: dict[int, _Row] = {}
    last: dict[str, _Row] = {}
    for r in rows:
        if not r.probs:
            if r.side in last:
                after[id(last[r.side])] = r
            last[r.side] = r
    return after


def _late_spike(stack: list[_Row], r: _Row, nxt: _Row | None) -> bool:
    """Whether the last accepted frame of ``stack`` has a time ahead of the run: later than
    both ``r`` and the frame after it, which are in order and after the frame before it."""
    prev = stack[-1]
    return (
        nxt is not None
        and r.gps_s < prev.gps_s
        and nxt.gps_s < prev.gps_s
        and r.gps_s < nxt.gps_s
        and (len(stack) < 2 or stack[-2].gps_s < r.gps_s)
    )


def _speed_mps(a: _Row, b: _Row) -> float:
    """Speed implied by two frames of one side (inf when their time is the same)."""
    dt = abs(b.gps_s - a.gps_s)
    dist = abs(b.chainage_m - a.chainage_m)
    return dist / dt if dt > 0 else (math.inf if dist > 0 else 0.0)


def _positioned(rows: list[_Row], side: str) -> list[_Row]:
    """The rows of one camera with a chainage, in their order."""
    return [r for r in rows if r.side == side and math.isfinite(r.chainage_m)]


def _drop_position_jumps(accepted: list[_Row], max_speed_mps: float) -> list[_Row]:
    """``accepted`` less the frames whose chainage contradicts the run: per side, a frame
    further from both its neighbours than ``max_speed_mps`` allows in their time apart, while
    the neighbours agree with each other (at the ends: the first or last frame too far from the
    next two, which agree). Each dropped frame gets its problem and fix."""
    dropped: set[int] = set()
    for side in {r.side for r in accepted}:
        seq = _positioned(accepted, side)
        for k, r in enumerate(seq):
            if len(seq) < 3:
                break
            if k == 0 or k == len(seq) - 1:
                near = [seq[1], seq[2]] if k == 0 else [seq[-2], seq[-3]]
                spike = (_speed_mps(r, near[0]) > max_speed_mps
                         and _speed_mps(near[0], near[1]) <= max_speed_mps)  # fmt: skip
            else:
                near = [seq[k - 1], seq[k + 1]]
                spike = (
                    _speed_mps(near[0], r) > max_speed_mps
                    and _speed_mps(r, near[1]) > max_speed_mps
                    and _speed_mps(near[0], near[1]) <= max_speed_mps
                )
            if spike:
                v = _speed_mps(near[0], r)
                r.bad(
                    f"chainage_m {r.chainage_m:.1f} contradicts the run: reaching it from frame "
                    f"{near[0].frame_id!r} (line {near[0].row}, {near[0].chainage_m:.1f} m) "
                    f"takes {v:.0f} m/s, over max_speed_mps={max_speed_mps:g}, while the "
                    "neighbouring frames agree; fix the chainage, position or gps_s"
                )
                dropped.add(id(r))
    return [r for r in accepted if id(r) not in dropped]


# A frame this far behind the one before it, against the direction of travel, contradicts it
# (a projected position's noise at a standstill is a few decimetres).
_BACK_STEP_TOL_M = 2.0


# A camera whose frames move one way at a median pace below this has not moved: its chainages
# are kilometres (a km-post export) if, read a thousand times larger, they move at a survey
# vehicle's pace (a trolley's 1 km/h to 360 km/h)
_CREEP_MPS = 0.1
_TRAIN_MPS = (0.3, 100.0)


def _check_chainage_unit(root: Location, accepted: list[_Row]) -> None:
    """Refuse chainages given in kilometres: read as metres, a survey of km 4.00-4.04 was
    published at 4 m, and its masks, made with frames 1 cm apart, trusted 0.96 % of the
    directions falsely (a user trial). Only frames without a GNSS position are judged (a
    position would contradict such a chainage)."""
    for side in sorted({r.side for r in accepted}):
        seq = [r for r in _positioned(accepted, side) if not math.isfinite(r.lat_deg)]
        if len(seq) < 3:
            continue
        ch = np.array([r.chainage_m for r in seq])
        dt = np.diff([r.gps_s for r in seq])
        step = np.diff(ch)
        moving = (step != 0) & (dt > 0)
        if moving.sum() < 2:
            continue
        # the median: one typo row or a jump does not hide it; one way: a standing train's
        # odometer jitters back and forth
        pace = float(np.median(np.abs(step[moving]) / dt[moving]))
        one_way = abs(float(np.mean(np.sign(step[moving])))) >= 0.8
        lo, hi = _TRAIN_MPS
        if one_way and pace < _CREEP_MPS and lo <= 1000.0 * pace <= hi:
            a, b = seq[0], seq[-1]
            raise SurveyError(root, [SurveyProblem(
                f"manifest.csv: the {side} frames' chainage_m reads as kilometres: "
                f"{a.chainage_m:g} at line {a.row} to {b.chainage_m:g} at line {b.row}, moving "
                f"at {pace:.4f} m/s between frames in the median (in metres: "
                f"{3.6 * 1000.0 * pace:.0f} km/h); give chainage_m in metres"
            )])  # fmt: skip


def _check_direction(root: Location, accepted: list[_Row], reverse: bool) -> None:
    """Refuse a survey whose frames move against ``direction_of_travel``: the camera sides
    and the along-track directions would be swapped, and the masks wrong on both sides."""
    for side in sorted({r.side for r in accepted}):
        seq = _positioned(accepted, side)
        if len(seq) < 3:
            continue
        steps = np.diff([r.chainage_m for r in seq]) * (-1.0 if reverse else 1.0)
        moving = np.abs(steps) > _BACK_STEP_TOL_M
        if moving.sum() >= 2 and (steps[moving] < 0).mean() > 0.5:
            a, b = seq[0], seq[-1]
            declared = "decreasing" if reverse else "increasing"
            other = "increasing" if reverse else "decreasing"
            raise SurveyError(root, [SurveyProblem(
                f"survey.yaml: direction_of_travel is {declared}, but the {side} frames' "
                f"chainage runs the other way in time ({a.chainage_m:.1f} m at line {a.row}, "
                f"{b.chainage_m:.1f} m at line {b.row}, {int((steps[moving] < 0).sum())} of "
                f"{int(moving.sum())} moves backwards): with the wrong direction the sides and "
                f"the along-track view are swapped; set direction_of_travel: {other}, or fix "
                "the chainages or positions"
            )])  # fmt: skip


def _drop_backward_steps(accepted: list[_Row], reverse: bool) -> list[_Row]:
    """``accepted`` less the frames whose chainage steps back against the direction of travel
    by more than ``_BACK_STEP_TOL_M`` from the frame before them on their side, and that frame
    (which of the two is wrong cannot be told: two swapped chainages in a manifest without
    positions). Leaving frames out only removes sky evidence."""
    dropped: set[int] = set()
    for side in {r.side for r in accepted}:
        seq = _positioned(accepted, side)
        for a, b in itertools.pairwise(seq):
            back = (a.chainage_m - b.chainage_m) * (-1.0 if reverse else 1.0)
            if back > _BACK_STEP_TOL_M:
                for r, other in ((a, b), (b, a)):
                    if id(r) not in dropped:
                        r.bad(
                            f"chainage_m {r.chainage_m:.1f} and {other.chainage_m:.1f} of frame "
                            f"{other.frame_id!r} (line {other.row}) run {back:.1f} m backwards "
                            f"in time on the {side} side, against the direction of travel: one "
                            "is wrong (swapped chainages?); both are left out, fix the chainage "
                            "or position"
                        )
                        dropped.add(id(r))
    return [r for r in accepted if id(r) not in dropped]


def _read_manifest(
    root: Location,
    header: dict[str, Any],
    track: TrackMap | None,
    check_images: bool,
    max_offset_m: float,
    max_speed_mps: float = 100.0,
    opts: StorageOptions | None = None,
) -> tuple[Frames, list[SurveyProblem]]:
    rows = _parse_rows(root, header, check_images, opts or {})
    if not rows:
        raise SurveyError(root, [SurveyProblem("manifest.csv has no frames")])
    if track is not None:
        _check_track(rows, track, max_offset_m)
    first_id: dict[str, int] = {}
    first_row: dict[str, _Row] = {}
    first_image: dict[str, int] = {}
    seen_time: dict[tuple[str, float], _Row] = {}
    kept: dict[str, list[_Row]] = {}  # per side, the accepted frames in order
    accepted: list[_Row] = []
    after = _next_on_side(rows)
    for r in rows:
        twin_row = first_row.get(r.frame_id)
        if twin_row is not None and _same_row(twin_row, r):
            # the same frame listed twice (a manifest written twice over, a copy appended):
            # the repeat goes, the frame stays (as a duplicate id, both rows were left out and
            # a user trial's doubled manifest gave masks 100 % assumed)
            r.probs.append(SurveyProblem(
                f"repeats manifest line {twin_row.row} exactly (frame {r.frame_id!r} listed "
                "twice): the repeat is left out; remove the repeated row", None, r.row,
            ))  # fmt: skip
            continue
        if r.frame_id in first_id:
            r.bad(
                f"duplicate frame_id (first at manifest line {first_id[r.frame_id]}); "
                "make ids unique (until then both rows are left out: a bad frame is known by "
                "its id)"
            )
        first_id.setdefault(r.frame_id, r.row)
        first_row.setdefault(r.frame_id, r)
        key = str(PurePosixPath(r.image))
        if r.image and key in first_image:
            r.bad(
                f"image {r.image} is also listed at manifest line {first_image[key]}; "
                "remove the duplicate"
            )
        first_image.setdefault(key, r.row)
        if r.probs:
            continue
        twin = seen_time.get((r.side, r.gps_s))
        stack = kept.setdefault(r.side, [])
        prev = stack[-1] if stack else None
        if twin is None and prev is not None and _late_spike(stack, r, after.get(id(r))):
            # one frame's time far ahead: it is wrong, not every frame after it
            nxt = after[id(r)]
            prev.bad(
                f"gps_s {prev.gps_s!r} is later than the next two frames on the {r.side} side "
                f"({r.frame_id!r} at line {r.row} has {r.gps_s!r}, {nxt.frame_id!r} at line "
                f"{nxt.row} has {nxt.gps_s!r}), which agree with the frames before; fix the time"
            )
            stack.pop()
            accepted.remove(prev)
            seen_time.pop((prev.side, prev.gps_s), None)
            prev = stack[-1] if stack else None
        if twin is not None:
            r.bad(
                f"same side and gps_s as frame {twin.frame_id!r} (line {twin.row}): "
                "a duplicate frame; remove one"
            )
        elif prev is not None and r.gps_s < prev.gps_s:
            r.bad(
                f"gps_s {r.gps_s!r} goes back in time on the {r.side} side (frame "
                f"{prev.frame_id!r} at line {prev.row} has {prev.gps_s!r}); order the manifest "
                "by time or fix the time"
            )
        if r.probs:
            continue
        seen_time[(r.side, r.gps_s)] = r
        stack.append(r)
        accepted.append(r)
    _check_chainage_unit(root, accepted)
    accepted = _drop_position_jumps(accepted, max_speed_mps)
    reverse = header["direction"] == "decreasing"
    _check_direction(root, accepted, reverse)
    accepted = _drop_backward_steps(accepted, reverse)
    problems = sorted((p for r in rows for p in r.probs), key=lambda p: p.row or 0)
    if not accepted:
        return empty_frames(), problems

    def col(name: str) -> list[Any]:
        return [getattr(r, name) for r in accepted]

    frames = Frames(
        frame_id=np.array(col("frame_id"), str),
        image=np.array(col("image"), str),
        side=np.array(col("side"), str),
        track_side=np.array([OTHER_SIDE[r.side] if reverse else r.side for r in accepted], str),
        gps_s=np.array(col("gps_s"), float),
        chainage_m=np.array(col("chainage_m"), float),
        lat_deg=np.array(col("lat_deg"), float),
        lon_deg=np.array(col("lon_deg"), float),
        h_m=np.array(col("h_m"), float),
        offset_m=np.array(col("offset_m"), float),
        row=np.array(col("row"), np.int64),
        roll_deg=np.array(col("roll_deg"), float),
        pitch_deg=np.array(col("pitch_deg"), float),
    )
    return frames, problems
