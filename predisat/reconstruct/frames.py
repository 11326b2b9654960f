"""Reading a frame's image with its checks, and segmenting it into the cache.

:func:`read_image` refuses missing, empty, truncated (:func:`truncation`), internally corrupt
(:func:`jpeg_corruption`), undecodable and blank (:func:`blank_image`: all black, all white or
one flat grey) files with the problem and its fix; :func:`segment_frame` checks the size
against the calibration, runs the segmenter (:func:`default_segmenter`, or a user's
function) and records the result or the failure in the cache. One bad frame never stops a
run: its problem is returned.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from predisat.reconstruct.framecache import FrameJob, write_cache
from predisat.sky.network import SkyNet, classifier_with_net
from predisat.sky.panorama import segment_panorama
from predisat.sky.segment import SkyOptions, segment_sky
from predisat.storage import StorageError, StorageOptions, location, read_bytes
from predisat.survey.images import decode_frame

__all__ = [
    "BLANK_SPREAD_LEVELS",
    "Segmenter",
    "blank_image",
    "default_segmenter",
    "jpeg_corruption",
    "read_image",
    "segment_frame",
    "truncation",
]


Segmenter = Callable[[NDArray], tuple[NDArray | None, ...]]
"""Image (H, W, 3) BGR uint8 -> (sky mask (H, W) bool, per-column confidence (W,) or None),
optionally followed by the thin-structure pixels (H, W) bool or None (the pixels of the sky
mask that are sky only by the thin-structure policy; ``FrameView.thin_mask``)."""



def default_segmenter(
    image_bgr: NDArray,
    method: str | None = None,
    sky_net: str | None = None,
    thin_px: int | None = None,
    panorama: bool = False,
) -> tuple[NDArray, NDArray | None, NDArray | None]:
    """:func:`predisat.sky.segment.segment_sky`: sky mask, per-column confidence and the sky
    the thin-structure policy made (:func:`predisat.sky.panorama.segment_panorama` for a
    360-degree ``panorama``).

    ``method`` is one of :data:`predisat.sky.segment.METHODS` (default: ``SkyOptions``'s);
    ``sky_net`` a network file replacing the shipped one (``PipelineParams.sky_net``);
    ``thin_px`` the thin-structure width (default ``SkyOptions``'s; the pipeline gives each
    camera's, ``PipelineParams.thin_px``). Returns the sky mask, the confidence and the
    thin-structure pixels.
    """
    opt = SkyOptions() if method is None else SkyOptions(method=method)
    if thin_px is not None:
        opt = replace(opt, thin_px=int(thin_px))
    classifier = None
    if sky_net is not None:
        # the files' versions are part of the key: a network retrained or copied over
        # since is read again, not served from the cache
        try:
            stamps = tuple(
                (st.st_mtime_ns, st.st_size, st.st_ino)
                for st in (os.stat(sky_net), os.stat(Path(sky_net).with_suffix(".json")))
            )
        except OSError:  # SkyNet.load names the missing file and its fix
            stamps = ()
        classifier = _candidate_classifier(opt.method, sky_net, stamps)
    if panorama:
        seg = segment_panorama(image_bgr, opt, classifier=classifier)
    else:
        seg = segment_sky(image_bgr, opt, classifier=classifier)
    return seg.sky_mask, seg.confidence, seg.thin_mask



@functools.lru_cache(maxsize=4)
def _candidate_classifier(method: str, sky_net: str, stamps: tuple[tuple[int, ...], ...]) -> Any:
    # read once per process and file version, not once per frame
    return classifier_with_net(method, SkyNet.load(sky_net))



def read_image(
    path: str, storage_options: StorageOptions | None = None
) -> tuple[NDArray | None, str | None]:
    """The BGR image at ``path`` (a local path or a URL, :mod:`predisat.storage`), or None and
    the problem with the file and its fix."""
    try:
        loc = location(path)
        data = loc.read_bytes() if isinstance(loc, Path) else read_bytes(loc, storage_options)
    except FileNotFoundError:
        return None, f"image {path} is missing; restore it or drop the frame"
    except StorageError as exc:
        return None, f"image {exc}"
    except OSError as exc:
        return None, f"image {path} cannot be read ({exc.strerror}); check the file"
    if not data:
        return None, (
            f"image {path} is empty (0 bytes): copy it again from the camera or drop the frame"
        )
    cut = truncation(data)
    if cut is not None and cut.startswith("no JPEG marker"):  # bytes overwritten in the header
        return None, (
            f"image {path} is damaged ({cut}): copy it again from the camera or drop the frame"
        )
    if cut is not None:
        return None, (
            f"image {path} is truncated ({cut}): the file was cut short, "
            "copy it again from the camera or drop the frame"
        )
    img, problem = decode_frame(data, path)
    if img is None:
        return None, problem
    corrupt = jpeg_corruption(data)
    if corrupt is not None:
        return None, (
            f"image {path} is corrupt inside (libjpeg: {corrupt}): part of the picture is "
            "lost and would be filled with grey, which can read as overcast sky; copy it again "
            "from the camera or drop the frame"
        )
    flat = blank_image(img)
    if flat is not None:
        return None, (
            f"image {path} is {flat}: a covered lens, a dead or overexposed sensor or a "
            "blank export shows no skyline; check the camera and drop the frame"
        )
    return img, None



def segment_frame(job: FrameJob, segmenter: Segmenter) -> tuple[str, str | None]:
    """Segment one frame into the cache; returns (frame_id, problem or None)."""
    result = None
    img, problem = read_image(job.image_path, job.storage_options)
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
                out = segmenter(img)
            elif job.panorama:
                out = segmenter(img, thin_px=job.thin_px, panorama=True)  # type: ignore[call-arg]
            else:
                out = segmenter(img, thin_px=job.thin_px)  # type: ignore[call-arg]
            sky, conf = np.asarray(out[0], bool), out[1]
            thin = np.asarray(out[2], bool) if len(out) > 2 and out[2] is not None else None
            if sky.shape != img.shape[:2] or (thin is not None and thin.shape != sky.shape):
                raise ValueError(f"segmenter returned a {sky.shape} mask for a {img.shape} image")
            result = (sky, None if conf is None else np.asarray(conf, np.float32), thin)
        except Exception as exc:  # any failure of one frame must not stop a long run
            # one line: OpenCV's messages end in a newline, which split the printed line and
            # the bad_frames.csv field ("... 'forwardGraph'\n) - skipped", a user trial)
            problem = f"segmentation failed ({type(exc).__name__}: {' '.join(str(exc).split())})"
            # not cached: a failure of the run, not of the image (memory, a worker's threads
            # sharing one network, a user trial), is tried again by the next run
            return job.frame_id, problem
    write_cache(job, result, problem)
    return job.frame_id, problem



BLANK_SPREAD_LEVELS = 4
"""A frame whose grey levels (0.5 to 99.5 percentile) span at most this many levels is blank."""


def blank_image(image_bgr: NDArray) -> str | None:
    """What makes ``image_bgr`` blank (all black, all white, one flat grey), or None.

    The grey levels of every 4th pixel in each direction are taken; when their 0.5 and 99.5
    percentiles are within :data:`BLANK_SPREAD_LEVELS` of each other the frame shows nothing
    (a real side-camera frame has at least the skyline's edge in it).

    Parameters
    ----------
    image_bgr : ndarray of uint8, shape (H, W, 3)

    Returns
    -------
    str or None
        e.g. ``"all black (grey level 0 to 2 of 255)"``.
    """
    grey = np.asarray(image_bgr[::4, ::4], np.float32).mean(axis=-1)
    if grey.size == 0:
        return "empty (0 pixels)"
    lo, hi = (float(v) for v in np.percentile(grey, [0.5, 99.5]))
    if hi - lo > BLANK_SPREAD_LEVELS:
        return None
    kind = "all black" if hi <= 32 else "all white" if lo >= 223 else "one flat grey"
    return f"{kind} (grey level {lo:.0f} to {hi:.0f} of 255)"


def jpeg_corruption(data: bytes) -> str | None:
    """libjpeg's complaint about the JPEG file ``data``, or None when it decodes cleanly (or is
    not a JPEG).

    libjpeg treats corrupt entropy-coded data (bytes overwritten or zeroed inside the scan) as
    a *warning*: ``cv2.imdecode`` and Pillow both hand back an image with the lost part filled
    with grey, and only print "Corrupt JPEG data" on stderr. ``simplejpeg`` (libjpeg-turbo)
    with ``strict=True`` turns those warnings into errors; the image it decodes is discarded
    (OpenCV's stays the one segmented).
    """
    if data[:2] != b"\xff\xd8":
        return None
    import simplejpeg

    try:
        simplejpeg.decode_jpeg(data, colorspace="BGR", strict=True)
    except ValueError as exc:
        return str(exc).strip() or type(exc).__name__
    return None


_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})  # markers without a length field



def truncation(data: bytes) -> str | None:
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
