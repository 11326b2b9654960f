"""Survey format v1: constants, problems and errors, and the frame table.

See ``docs/survey-format.md``. ``side`` in survey files is the camera's place on the *vehicle*
(a side, a cab or the roof, :data:`SIDES`); with ``direction_of_travel: decreasing`` the left
camera looks at the right side of the track and the front camera toward decreasing chainage
(``Frames.track_side``).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import POSITIONS, CameraModel, Mount, Position
from predisat.storage import Location, location

if TYPE_CHECKING:
    import pandas as pd


__all__ = [
    "ATTITUDE_LIMITS_DEG",
    "DIRECTIONS",
    "FORMAT",
    "MANIFEST_COLUMNS",
    "REQUIRED_COLUMNS",
    "SIDES",
    "VERSION",
    "Frames",
    "SurveyCamera",
    "SurveyError",
    "SurveyProblem",
]

FORMAT = "predisat-survey"
VERSION = 1
SIDES = POSITIONS  # left, right, front, rear, roof: v1 readers of two-camera surveys still read

DIRECTIONS = ("increasing", "decreasing")
REQUIRED_COLUMNS = ("frame_id", "image", "side", "gps_s")
MANIFEST_COLUMNS = (
    "frame_id", "image", "side", "gps_s", "chainage_m", "lat_deg", "lon_deg", "h_m",
    "roll_deg", "pitch_deg",
)  # fmt: skip
ATTITUDE_LIMITS_DEG = {"roll_deg": 20.0, "pitch_deg": 10.0}
"""Largest vehicle roll and pitch a manifest may give, degrees: a rail vehicle on 180 mm of
cant rolls 6.9 deg plus a degree or two on its springs, and a 100 per mille rack grade is
5.7 deg; beyond, the IMU's axes or units are wrong."""
FRAME_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
# the track side a camera looks at when the vehicle drives toward decreasing chainage
OTHER_SIDE = {"left": "right", "right": "left", "front": "rear", "rear": "front", "roof": "roof"}


@dataclass(frozen=True)
class SurveyProblem:
    """One problem found while loading a survey.

    Attributes
    ----------
    message : str
        What is wrong and how to fix it.
    frame_id : str or None
        The frame concerned (None for survey-level problems).
    row : int or None
        Line number in ``manifest.csv`` (the header is line 1).
    """

    message: str
    frame_id: str | None = None
    row: int | None = None

    def __str__(self) -> str:
        where = []
        if self.row is not None:
            where.append(f"manifest line {self.row}")
        if self.frame_id:
            where.append(f"frame {self.frame_id!r}")
        return f"{', '.join(where)}: {self.message}" if where else self.message


class SurveyError(ValueError):
    """A survey that cannot be loaded; ``problems`` lists every problem found."""

    def __init__(self, path: str | os.PathLike[str], problems: Sequence[SurveyProblem]) -> None:
        self.path = location(path)
        self.problems = tuple(problems)
        shown = "\n".join(f"  - {p}" for p in self.problems[:50])
        more = len(self.problems) - 50
        tail = f"\n  ... and {more} more" if more > 0 else ""
        super().__init__(f"{self.path}: {len(self.problems)} problem(s):\n{shown}{tail}")


@dataclass(frozen=True)
class SurveyCamera:
    """A camera of the survey: calibration and mount (``side`` is its place on the vehicle)."""

    side: Position
    camera: CameraModel
    mount: Mount
    calibration_path: Location  # a local path, or the URL of a remote survey's file


def _readonly(a: ArrayLike, dtype: Any) -> NDArray:
    out = np.array(a, dtype=dtype)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)  # numpy columns: compare explicitly
class Frames:
    """The frames of a survey as a read-only column table, shape (n,) per column.

    ``side`` is the camera's place on the vehicle (:data:`SIDES`), ``track_side`` the side of
    the track it looks at (left / right of increasing chainage; ``front`` looks toward
    increasing chainage, ``rear`` toward decreasing, ``roof`` all round): left and right, front
    and rear swap when the survey runs toward decreasing chainage. ``chainage_m`` comes from the
    manifest or from projecting the position on the track (NaN when neither is possible);
    ``lat_deg, lon_deg, h_m`` are NaN when the manifest gave only chainage; ``offset_m`` is the
    antenna's cross-track offset (left positive) when positions were projected, else NaN.
    ``roll_deg, pitch_deg`` are the vehicle's measured attitude (an IMU's; roll positive
    raising the vehicle's left side, pitch positive raising its nose), NaN when not given.
    ``row`` is the manifest line number.
    """

    frame_id: NDArray
    image: NDArray
    side: NDArray
    track_side: NDArray
    gps_s: NDArray
    chainage_m: NDArray
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    offset_m: NDArray
    row: NDArray
    roll_deg: NDArray
    pitch_deg: NDArray

    def __post_init__(self) -> None:
        n = len(self.frame_id)
        for name in self.__dataclass_fields__:
            col = getattr(self, name)
            if len(col) != n:
                raise ValueError(f"Frames column {name!r} has {len(col)} rows, expected {n}")
            dtype = (
                str
                if name in ("frame_id", "image", "side", "track_side")
                else (np.int64 if name == "row" else float)
            )
            object.__setattr__(self, name, _readonly(col, dtype))

    def __len__(self) -> int:
        return len(self.frame_id)

    def index_of(self, frame_id: str) -> int:
        """Position of a frame in the table; KeyError naming the frame when absent."""
        hits = np.flatnonzero(self.frame_id == frame_id)
        if hits.size == 0:
            raise KeyError(f"no frame {frame_id!r} in this survey")
        return int(hits[0])

    def subset(self, which: ArrayLike) -> Frames:
        """The frames selected by a boolean mask or an index array."""
        idx = np.asarray(which)
        return Frames(**{name: getattr(self, name)[idx] for name in self.__dataclass_fields__})

    def to_dataframe(self) -> pd.DataFrame:
        """A pandas copy of the table."""
        # lazy: pandas takes 0.7 s to import and only this export needs it
        import pandas as pd

        return pd.DataFrame({name: getattr(self, name) for name in self.__dataclass_fields__})


def empty_frames() -> Frames:
    return Frames(**{name: np.array([]) for name in Frames.__dataclass_fields__})
