"""Frames decoded as their calibration sees them: stored pixels, 16-bit files, EXIF tags.

The reference decodings are OpenCV's own (``cv2.imdecode`` with its defaults) and PIL's
(``ImageOps.exif_transpose``, the turn a viewer applies)."""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image, ImageOps

from predisat.survey import Survey
from predisat.survey.images import decode_frame, decode_thumbnail
from tests.predisat.survey.test_survey import _only, _problems, _rows, _save_rows, _write


def _scene(h: int = 48, w: int = 64) -> np.ndarray:
    rng = np.random.default_rng(4)
    img = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    img[: h // 3, : w // 4] = (250, 200, 120)  # an asymmetric patch: a turn moves it
    return img


def _jpeg(img_bgr: np.ndarray, orientation: int | None) -> bytes:
    im = Image.fromarray(img_bgr[:, :, ::-1])
    exif = Image.Exif()
    if orientation is not None:
        exif[0x0112] = orientation
    buf = io.BytesIO()
    im.save(buf, "JPEG", quality=95, exif=exif.tobytes())
    return buf.getvalue()


@pytest.mark.parametrize("orientation", [2, 3, 6, 8])
def test_a_frame_tagged_with_an_exif_turn_is_refused_and_its_stored_pixels_never_turned(
    orientation: int,
) -> None:
    img = _scene()
    plain, tagged = _jpeg(img, None), _jpeg(img, orientation)
    assert decode_frame(_jpeg(img, 1), "f.jpg")[1] is None  # 1: as stored
    got, problem = decode_frame(tagged, "images/f.jpg")
    assert got is None and problem is not None
    assert f"image images/f.jpg carries EXIF Orientation {orientation} (" in problem
    # OpenCV's default, and a viewer, turn the picture: what a calibration may or may not be of
    stored = decode_frame(plain, "f.jpg")[0]
    turned = cv2.imdecode(np.frombuffer(tagged, np.uint8), cv2.IMREAD_COLOR)
    viewer = np.asarray(ImageOps.exif_transpose(Image.open(io.BytesIO(tagged))))[:, :, ::-1]
    assert turned.shape == viewer.shape
    assert turned.shape != stored.shape or np.abs(turned.astype(int) - stored).mean() > 20
    # the frozen-camera check's thumbnail stays of the stored pixels
    thumb = decode_thumbnail(tagged)
    assert thumb is not None and thumb.shape == (12, 16)  # a quarter of the stored 64x48


@pytest.mark.parametrize("fmt", ["PNG", "TIFF"])
def test_a_turn_in_a_png_or_tiff_is_seen_too(fmt: str) -> None:
    im = Image.fromarray(_scene()[:, :, ::-1])
    exif = Image.Exif()
    exif[0x0112] = 6
    buf = io.BytesIO()
    im.save(buf, fmt, exif=exif.tobytes())
    problem = decode_frame(buf.getvalue(), "f")[1]
    assert problem is not None and "EXIF Orientation 6 (turned 90 deg clockwise" in problem


def test_the_loader_refuses_a_tagged_frame_naming_the_turn_and_the_fix(tmp_path: Path) -> None:
    root = _write(tmp_path / "s", n=3)
    path = root / "images" / "left_000001.jpg"
    stored = cv2.imread(str(path))
    path.write_bytes(_jpeg(stored, 2))  # same size: every size check passes
    ok = root / "images" / "right_000001.jpg"
    ok.write_bytes(_jpeg(cv2.imread(str(ok)), 1))  # "normal": no turn
    p = _only(_problems(root), "left_000001", "EXIF Orientation 2 (mirrored left-right")
    assert "exiftool -n -Orientation=1" in p.message
    assert len(Survey.load(root, on_error="skip").frames) == 5


def test_16_bit_frames_full_range_read_as_opencv_does_and_12_bit_data_refused() -> None:
    img8 = _scene()
    full = img8.astype(np.uint16) * 257 + 100  # spans the 16-bit range
    data = cv2.imencode(".png", full)[1].tobytes()
    ours = decode_frame(data, "f.png")[0]
    theirs = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)  # OpenCV's 16 -> 8
    assert ours is not None and ours.dtype == np.uint8
    assert np.abs(ours.astype(int) - theirs).max() <= 1
    twelve12 = img8.astype(np.uint16) * 16  # 12-bit sensor values
    twelve = cv2.imencode(".png", twelve12)[1].tobytes()
    img, problem = decode_frame(twelve, "images/f.png")
    assert img is None and problem is not None
    assert f"images/f.png is 16-bit with values only up to {twelve12.max()}" in problem
    assert "x16" in problem
    assert decode_thumbnail(twelve) is None


def test_8_bit_frames_decode_exactly_as_before() -> None:
    for ext in (".jpg", ".png"):
        data = cv2.imencode(ext, _scene())[1].tobytes()
        buf = np.frombuffer(data, np.uint8)
        np.testing.assert_array_equal(decode_frame(data, "f")[0], cv2.imdecode(buf, 1))
        np.testing.assert_array_equal(
            decode_thumbnail(data), cv2.imdecode(buf, cv2.IMREAD_REDUCED_GRAYSCALE_4)
        )
    assert decode_frame(b"not an image", "x.jpg") == (
        None, "image x.jpg cannot be decoded; re-export it as JPEG or PNG"
    )  # fmt: skip


def test_an_accented_frame_name_is_found_in_the_other_unicode_normalisation(
    tmp_path: Path,
) -> None:
    """A folder copied from a Mac keeps names decomposed (NFD) while the manifest spells them
    composed (NFC): every frame was "missing" although ls showed it (a user trial). The loader
    takes the spelling on disk, so that the readers and the cache keys see the same file (a
    review: a replaced image was never segmented again)."""
    import unicodedata

    from predisat.survey.images import on_disk_spelling

    root = _write(tmp_path / "s", n=2)
    rows = _rows(root)
    nfc = unicodedata.normalize("NFC", "images/Gembloux_é_left.jpg")
    nfd = unicodedata.normalize("NFD", nfc)
    assert nfc != nfd
    (root / rows[0]["image"]).rename(root / nfd)
    rows[0]["image"] = nfc
    _save_rows(root, rows)
    assert on_disk_spelling(root, nfc) == nfd and on_disk_spelling(root, "images/x.jpg") is None
    survey = Survey.load(root)
    assert survey.frames.image[0] == nfd
    img = survey.read_image(0)
    assert img.shape == (24, 32, 3)
