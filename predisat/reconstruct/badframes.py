"""Bad frames: frames a run skips, with the reason and the fix; their list ``bad_frames.csv``."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable
from dataclasses import dataclass

from predisat.storage import Location, StorageOptions, write_atomic

__all__ = ["BadFrame", "BadFrameError", "write_bad_frames"]


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
        ``"load"`` (rejected by the survey loader), ``"segment"`` (image unreadable or
        segmentation failed) or ``"fusion"`` (a suspect frame: its sky contradicts both
        neighbouring frames of its camera, ``ReconstructionParams.suspect_share``; left out
        of the reconstruction) or ``"step"`` (its camera and another are out of step there:
        :mod:`predisat.reconstruct.step`) or ``"side"`` (a stretch of its camera's frames
        whose scenery slid the other way from the mount's: another camera's images,
        :func:`predisat.reconstruct.sides.stretches_the_other_way`) or ``"lens"`` (a
        stretch whose sun or horizon is not where the camera's calibration puts it: another
        lens, a moved mount; :mod:`predisat.reconstruct.sunsight`).
    """

    frame_id: str
    message: str
    stage: str = "segment"



def write_bad_frames(
    path: Location, bad: Iterable[BadFrame], storage_options: StorageOptions | None = None
) -> None:
    """Write ``bad_frames.csv`` (``frame_id, stage, message``) atomically, locally or at a
    URL (:func:`predisat.storage.write_atomic`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame_id", "stage", "message"])
    for b in bad:
        w.writerow([b.frame_id, b.stage, b.message])
    write_atomic(path, buf.getvalue().encode(), storage_options)
