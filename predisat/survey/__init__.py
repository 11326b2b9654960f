"""Survey format v1: a folder of side-camera frames with a manifest, calibrations and mounts.

Layout (see ``docs/survey-format.md``)::

    survey.yaml      format, version, direction of travel, antenna height, track, cameras
    manifest.csv     one row per frame: frame_id, image, side, gps_s, chainage_m | lat/lon/h
    images/...       the frames (any format PIL and OpenCV read; the writer makes JPEG)
    calib/...        camera calibrations (OpenCV FileStorage YAML, see predisat.camera.models)

:meth:`Survey.load` validates everything and reports every problem with its frame and manifest
line; :class:`SurveyWriter` writes a survey frame by frame (used by the synthetic generator).
``side`` in the files is the *vehicle* side of the camera; with ``direction_of_travel:
decreasing`` the left camera looks at the right side of the track (``Frames.track_side``).
"""

from predisat.survey.format import (
    FORMAT,
    MANIFEST_COLUMNS,
    VERSION,
    Frames,
    SurveyCamera,
    SurveyError,
    SurveyProblem,
)
from predisat.survey.load import Survey, check_survey_track
from predisat.survey.writer import SurveyWriter

__all__ = [
    "FORMAT",
    "MANIFEST_COLUMNS",
    "VERSION",
    "Frames",
    "Survey",
    "SurveyCamera",
    "SurveyError",
    "SurveyProblem",
    "SurveyWriter",
    "check_survey_track",
]
