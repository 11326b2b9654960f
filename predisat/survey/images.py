"""Decoding a survey frame's bytes into the pixels its calibration describes.

One decoder for every reader of frames (the segmentation, :meth:`Survey.read_image`, the frozen
camera check), so that they agree with the loader's checks:

* **stored pixels**: an EXIF Orientation tag is not applied (OpenCV's default turns or mirrors
  the picture); the loader refuses tagged frames (:mod:`predisat.survey.load`), since which way
  a calibration was made cannot be told;
* **16-bit files** (PNG, TIFF of machine-vision cameras) are scaled to 8 bits over the full
  16-bit range, as OpenCV does; one whose values stay below 4096 holds 12-bit (or fewer) sensor
  data: read so, it is nearly black (a user trial's frames read as a "frozen camera" and lost
  93-99.98 % of the sky), so it is refused naming the fix.
"""

from __future__ import annotations

import io
import os
import unicodedata
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError

__all__ = [
    "FULL_RANGE_MIN_16BIT",
    "decode_frame",
    "decode_thumbnail",
    "exif_of",
    "exif_orientation",
    "on_disk_spelling",
    "orientation_problem",
]

FULL_RANGE_MIN_16BIT = 4096
"""A 16-bit frame whose brightest value is below this holds 12-bit or fewer sensor data."""

_FLAGS = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_IGNORE_ORIENTATION
_EXIF_ORIENTATION = 0x0112
_TURNS = MappingProxyType({
    2: "mirrored left-right", 3: "turned 180 deg", 4: "mirrored top-bottom",
    5: "mirrored and turned 90 deg", 6: "turned 90 deg clockwise",
    7: "mirrored and turned 90 deg", 8: "turned 90 deg anticlockwise",
})  # fmt: skip


def exif_of(im: Image.Image) -> Image.Exif | None:
    """The EXIF tags of an opened image, None when it has none.

    Read from the header alone: ``Image.getexif`` made PIL read a whole PNG (decoding frames
    1.9 times as long as OpenCV, ``scripts/bench_decode.py``); a PNG's eXIf chunk after its
    pixels is not seen (cameras write JPEG or TIFF).
    """
    if im.format == "TIFF":  # its tags are the header
        return im.getexif()
    raw = im.info.get("exif")
    if not raw:
        return None
    exif = Image.Exif()
    exif.load(raw)
    return exif


def exif_orientation(im: Image.Image) -> int:
    """The EXIF Orientation of an opened image (1, "as stored", when it has none)."""
    exif = exif_of(im)
    turn = 1 if exif is None else exif.get(_EXIF_ORIENTATION, 1)
    return int(turn) if isinstance(turn, int) else 1


def orientation_problem(turn: int, label: str, calibration: str = "") -> str | None:
    """Why a frame tagged with EXIF Orientation ``turn`` is refused (None for 1: as stored).

    Viewers and OpenCV's calibration tools show the picture turned; PREDISAT reads the stored
    pixels. Which of the two a calibration describes cannot be told (a square fisheye passes
    every size check turned): a mirror tag gave 0.58 % false trust at every position in a user
    trial.
    """
    if turn == 1:
        return None
    what = _TURNS.get(turn, "an unknown turn")
    cal = f"calibration {calibration!r}" if calibration else "the camera's calibration"
    return (
        f"image {label} carries EXIF Orientation {turn} ({what} for display): whether {cal} "
        "is of the stored or the turned picture cannot be told; check it is of the stored "
        "pixels and remove the tag (exiftool -n -Orientation=1), or save the frames turned, "
        "without the tag"
    )


def on_disk_spelling(root: str | os.PathLike[str], rel: str) -> str | None:
    """How the file ``rel`` (relative to the folder ``root``) is spelled on disk: ``rel``, or
    its other Unicode normalisation when only that one exists; None when neither does.

    A folder copied from a Mac keeps accented names decomposed (NFD) while a manifest written
    elsewhere spells them composed (NFC): every frame was "missing" while ``ls`` showed it (a
    user trial).
    """
    base = Path(root)
    if (base / rel).exists():
        return rel
    for form in ("NFC", "NFD"):
        other = unicodedata.normalize(form, rel)
        if other != rel and (base / other).exists():
            return other
    return None


def _to_8bit(img: NDArray, label: str) -> tuple[NDArray | None, str | None]:
    if img.dtype == np.uint8:
        return img, None
    if img.dtype != np.uint16:
        return None, (
            f"image {label} holds {img.dtype} samples; save it as 8-bit (or 16-bit) JPEG or PNG"
        )
    peak = int(img.max()) if img.size else 0
    if peak < FULL_RANGE_MIN_16BIT:
        return None, (
            f"image {label} is 16-bit with values only up to {peak}: 12-bit (or fewer) sensor "
            "data in a 16-bit file, nearly black when read over the 16-bit range; scale it to "
            "the full range (x16 for 12-bit) or save it as 8-bit"
        )
    return cv2.convertScaleAbs(img, alpha=1.0 / 256.0), None


def decode_frame(data: bytes | NDArray, label: str) -> tuple[NDArray | None, str | None]:
    """A frame's stored pixels as BGR ``uint8``, shape (H, W, 3).

    Parameters
    ----------
    data : bytes or ndarray of uint8
        The encoded file.
    label : str
        The file, for the messages.

    Returns
    -------
    image : ndarray or None
    problem : str or None
        Why there is no image, naming the file and the fix (None when decoded).
    """
    buf = np.frombuffer(data, np.uint8) if isinstance(data, bytes) else data
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR | _FLAGS) if buf.size else None
    except cv2.error:
        img = None
    if img is None:
        return None, f"image {label} cannot be decoded; re-export it as JPEG or PNG"
    try:
        raw = data if isinstance(data, bytes) else buf.tobytes()
        with Image.open(io.BytesIO(raw)) as im:  # the header only
            problem = orientation_problem(exif_orientation(im), label)
    except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError):
        problem = None  # OpenCV decoded it: a format PIL lacks carries no EXIF it reads
    if problem:
        return None, problem
    return _to_8bit(img, label)


def decode_thumbnail(data: bytes | NDArray) -> NDArray | None:
    """A frame's quarter-size grey picture, ``uint8`` (None when it cannot be decoded or is not
    a frame :func:`decode_frame` takes: the segmentation says why)."""
    buf = np.frombuffer(data, np.uint8) if isinstance(data, bytes) else data
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_REDUCED_GRAYSCALE_4 | _FLAGS) if buf.size else None
    except cv2.error:
        return None
    return None if img is None else _to_8bit(img, "")[0]
