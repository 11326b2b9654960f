"""Writing a survey folder frame by frame (format v1, see ``docs/survey-format.md``)."""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from predisat.atomic import write_bytes_atomic
from predisat.camera.models import CameraModel, Mount
from predisat.survey.capture import exif_time_bytes
from predisat.survey.format import (
    ATTITUDE_LIMITS_DEG,
    DIRECTIONS,
    FORMAT,
    FRAME_ID_RE,
    MANIFEST_COLUMNS,
    SIDES,
    VERSION,
)

__all__ = ["SurveyWriter"]


def _with_exif(jpeg: bytes, exif: bytes) -> bytes:
    """A JPEG with an EXIF APP1 segment after its JFIF header (the pixels' bytes untouched)."""
    if len(exif) + 2 > 0xFFFF:
        raise ValueError(f"EXIF block of {len(exif)} bytes does not fit a JPEG segment")
    at = 2  # after SOI
    if jpeg[2:4] == b"\xff\xe0":  # APP0 (JFIF) stays first
        at = 4 + int.from_bytes(jpeg[4:6], "big")
    return jpeg[:at] + b"\xff\xe1" + (len(exif) + 2).to_bytes(2, "big") + exif + jpeg[at:]


def _fmt(value: float | None) -> str:
    return "" if value is None or not math.isfinite(value) else repr(float(value))


class SurveyWriter:
    """Write a survey folder frame by frame (a context manager).

    Parameters
    ----------
    out_dir : path-like
        Survey folder to create.
    cameras : Mapping[str, tuple[CameraModel, Mount]]
        Camera and mount per place on the vehicle (``left``, ``right``, ``front``, ``rear``,
        ``roof``); calibrations go to ``calib/<side>.yaml``.
    direction_of_travel : {"increasing", "decreasing"}
    antenna_height_m : float
    track_name : str, optional
    track_path : str, optional
        Track file, relative to the survey folder (written as given).
    chainage_doubt_m : float, optional
        The survey's positioning accuracy along the track (survey.yaml ``chainage_doubt_m``,
        docs/survey-format.md), metres; None: not stated.
    chainage_jitter_m : float, optional
        The frames' relative accuracy along the track over a few hundred metres (survey.yaml
        ``chainage_jitter_m``), metres, at most ``chainage_doubt_m``; None: not stated (the
        doubt then bounds each frame).
    metadata : Mapping, optional
        Free fields for survey.yaml (description, vehicle, date, ...).
    overwrite : bool
        Allow writing into a folder that already holds a survey.
    flush_every : int
        Rewrite manifest.csv and survey.yaml every so many frames, so that a crash keeps
        the frames written so far.

    Notes
    -----
    Images are written as ``images/<frame_id>.jpg`` as soon as they are added; manifest.csv and
    survey.yaml are (re)written atomically on :meth:`flush` and :meth:`close`, including when the
    ``with`` block ends with an exception.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike[str],
        cameras: Mapping[str, tuple[CameraModel, Mount]],
        *,
        direction_of_travel: Literal["increasing", "decreasing"] = "increasing",
        antenna_height_m: float = 4.0,
        track_name: str | None = None,
        track_path: str | None = None,
        chainage_doubt_m: float | None = None,
        chainage_jitter_m: float | None = None,
        metadata: Mapping[str, Any] | None = None,
        overwrite: bool = False,
        flush_every: int = 500,
    ) -> None:
        self.root = Path(out_dir)
        if direction_of_travel not in DIRECTIONS:
            raise ValueError(
                f"direction_of_travel must be one of {DIRECTIONS}, got {direction_of_travel!r}"
            )
        if not cameras or any(side not in SIDES for side in cameras):
            raise ValueError(
                f"cameras must map positions {SIDES} to (CameraModel, Mount), got keys "
                f"{list(cameras)}"
            )
        for side, (_, mount) in cameras.items():
            if mount.side != side:
                raise ValueError(f"cameras[{side!r}] has a mount for side {mount.side!r}")
        clash = set(metadata or {}) & {
            "format",
            "version",
            "direction_of_travel",
            "antenna_height_m",
            "track",
            "cameras",
            "chainage_doubt_m",
            "chainage_jitter_m",
        }
        if clash:
            raise ValueError(
                f"metadata keys {sorted(clash)} are reserved survey.yaml fields; rename them"
            )
        if not overwrite and (
            (self.root / "survey.yaml").exists() or (self.root / "manifest.csv").exists()
        ):
            raise FileExistsError(
                f"{self.root} already holds a survey; pass overwrite=True or choose another folder"
            )
        self.cameras = dict(cameras)
        self.direction_of_travel = direction_of_travel
        self.antenna_height_m = float(antenna_height_m)
        for name, value in (("chainage_doubt_m", chainage_doubt_m),
                            ("chainage_jitter_m", chainage_jitter_m)):  # fmt: skip
            if value is not None and not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a length >= 0 metres, got {value}")
        if chainage_jitter_m is not None and (
            chainage_doubt_m is None or chainage_jitter_m > chainage_doubt_m
        ):
            raise ValueError(
                f"chainage_jitter_m ({chainage_jitter_m} m) needs a chainage_doubt_m at least as "
                f"large (got {chainage_doubt_m}): the frames' relative error is part of their "
                "error"
            )
        self.chainage_doubt_m = None if chainage_doubt_m is None else float(chainage_doubt_m)
        self.chainage_jitter_m = None if chainage_jitter_m is None else float(chainage_jitter_m)
        self.track_name, self.track_path = track_name, track_path
        self.metadata = dict(metadata or {})
        self.flush_every = int(flush_every)
        self._rows: list[dict[str, str]] = []
        self._ids: set[str] = set()
        self._last_gps: dict[str, float] = {}
        self._count: dict[str, int] = dict.fromkeys(self.cameras, 0)
        self._closed = False
        (self.root / "images").mkdir(parents=True, exist_ok=True)
        for side, (cam, _) in self.cameras.items():
            cam.to_yaml(self.root / "calib" / f"{side}.yaml")

    def __enter__(self) -> SurveyWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __len__(self) -> int:
        return len(self._rows)

    def add_frame(
        self,
        image_bgr: NDArray,
        side: str,
        gps_s: float,
        chainage_m: float | None = None,
        lat_deg: float | None = None,
        lon_deg: float | None = None,
        h_m: float | None = None,
        frame_id: str | None = None,
        jpeg_quality: int = 90,
        roll_deg: float | None = None,
        pitch_deg: float | None = None,
        capture_time_s: float | None = None,
    ) -> str:
        """Write one frame's image and record its manifest row; returns the frame_id.

        ``image_bgr`` is uint8 (H, W, 3) BGR (or (H, W) grey) with the side's calibrated size.
        Give ``chainage_m`` and/or ``lat_deg, lon_deg[, h_m]`` (antenna position), and the
        vehicle's measured attitude ``roll_deg, pitch_deg`` when known (both or neither).
        ``capture_time_s`` (seconds since 1970 by the camera's own clock) is written into the
        JPEG as EXIF ``DateTimeOriginal`` and ``SubSecTimeOriginal`` (milliseconds), as
        cameras stamp their pictures (:mod:`predisat.survey.capture`).
        """
        if self._closed:
            raise RuntimeError(f"SurveyWriter for {self.root} is closed")
        if side not in self.cameras:
            raise ValueError(
                f"side {side!r} has no camera in this writer; cameras: {sorted(self.cameras)}"
            )
        cam = self.cameras[side][0]
        img = np.asarray(image_bgr)
        if img.dtype != np.uint8 or img.shape[:2] != cam.shape or img.ndim not in (2, 3):
            raise ValueError(
                f"image_bgr must be uint8 of shape ({cam.height_px}, {cam.width_px}, 3) for the "
                f"{side} camera, got {img.dtype} {img.shape}"
            )
        gps = float(gps_s)
        if not math.isfinite(gps) or gps <= self._last_gps.get(side, -math.inf):
            raise ValueError(
                f"gps_s={gps_s!r} must be finite and after the previous {side} frame "
                f"({self._last_gps.get(side)})"
            )
        if chainage_m is None and (lat_deg is None or lon_deg is None):
            raise ValueError("give chainage_m or lat_deg and lon_deg for every frame")
        if (roll_deg is None) != (pitch_deg is None):
            raise ValueError("give roll_deg and pitch_deg together (the vehicle's attitude)")
        for name, value in (("roll_deg", roll_deg), ("pitch_deg", pitch_deg)):
            limit = ATTITUDE_LIMITS_DEG[name]
            if value is not None and not (math.isfinite(value) and abs(value) <= limit):
                raise ValueError(f"{name}={value!r} must be finite degrees within +-{limit:g}")
        fid = frame_id if frame_id is not None else f"{side}_{self._count[side]:06d}"
        if not FRAME_ID_RE.match(fid) or fid in self._ids:
            raise ValueError(
                f"frame_id {fid!r} must be unique and made of letters, digits, '_', '.', '-'"
            )
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        if not ok:
            raise OSError(f"JPEG encoding failed for frame {fid!r}")
        data = buf.tobytes()
        if capture_time_s is not None:
            data = _with_exif(data, exif_time_bytes(float(capture_time_s)))
        rel = f"images/{fid}.jpg"
        write_bytes_atomic(self.root / rel, data)
        self._rows.append({
            "frame_id": fid, "image": rel, "side": side, "gps_s": _fmt(gps),
            "chainage_m": _fmt(chainage_m), "lat_deg": _fmt(lat_deg),
            "lon_deg": _fmt(lon_deg), "h_m": _fmt(h_m),
            "roll_deg": _fmt(roll_deg), "pitch_deg": _fmt(pitch_deg),
        })  # fmt: skip
        self._ids.add(fid)
        self._last_gps[side] = gps
        self._count[side] += 1
        if self.flush_every > 0 and len(self._rows) % self.flush_every == 0:
            self.flush()
        return fid

    def flush(self) -> None:
        """Atomically (re)write manifest.csv and survey.yaml for the frames so far."""
        out = io.StringIO()
        writer = csv.DictWriter(out, fieldnames=MANIFEST_COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(self._rows)
        write_bytes_atomic(self.root / "manifest.csv", out.getvalue().encode("utf-8"))
        doc: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "direction_of_travel": self.direction_of_travel,
            "antenna_height_m": self.antenna_height_m,
        }
        track = {k: v for k, v in (("name", self.track_name), ("path", self.track_path)) if v}
        if track:
            doc["track"] = track
        if self.chainage_doubt_m is not None:
            doc["chainage_doubt_m"] = self.chainage_doubt_m
        if self.chainage_jitter_m is not None:
            doc["chainage_jitter_m"] = self.chainage_jitter_m
        doc["cameras"] = {
            side: {"calibration": f"calib/{side}.yaml", "mount": mount.to_dict()}
            for side, (_, mount) in self.cameras.items()
        }
        doc.update(self.metadata)
        text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
        write_bytes_atomic(self.root / "survey.yaml", text.encode("utf-8"))

    def close(self) -> None:
        """Write manifest.csv and survey.yaml; further frames are refused."""
        if not self._closed:
            self.flush()
            self._closed = True
