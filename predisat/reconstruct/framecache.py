"""The segmentation cache of a run, and the fingerprints that decide what may be reused.

Each frame's segmentation (packed sky mask plus per-column confidence, or the recorded failure)
is kept in ``out/cache/seg-<method>-<code>/<frame_id>.npz`` and reused while the image keeps
its size and modification time (:func:`read_cache`, :func:`write_cache`). The cache folder is
keyed by :func:`code_fingerprint` of :data:`SEGMENTATION_CODE`; a run's resume key by the
whole package's fingerprint, the survey's description (:func:`survey_hash`) and, for a
candidate network, its files (:func:`sky_net_sha256`). :func:`frames_key` stamps the images a
chunk reads, so that replacing one redoes that chunk.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.lib.npyio import NpzFile
from numpy.typing import NDArray

from predisat.codeversion import code_fingerprint
from predisat.jsontypes import JsonDict
from predisat.reconstruct.badframes import BadFrame
from predisat.sky.network import SkyNet
from predisat.storage import (
    StorageOptions,
    exists,
    is_remote,
    join,
    location,
    name_of,
    npz_bytes,
    read_bytes,
    stamp,
    write_atomic,
)

if TYPE_CHECKING:
    from predisat.survey import Survey

__all__ = [
    "CACHE_VERSION",
    "SEGMENTATION_CODE",
    "FrameJob",
    "code_fingerprint",
    "decode_cache",
    "frames_key",
    "read_cache",
    "sky_net_sha256",
    "stat_key",
    "survey_hash",
    "write_cache",
]


CACHE_VERSION = 1


# The files the segmentation depends on (its cache is kept while they do not change).
SEGMENTATION_CODE = (
    "sky/__init__.py", "sky/segment.py", "sky/options.py", "sky/morphology.py",
    "sky/skyline.py", "sky/perceptron.py", "sky/features.py", "sky/grabcut.py",
    "sky/network.py", "sky/panorama.py", "sky/lines.py", "data/models",
    # reading the image: its checks (corrupt, blank) decide whether a frame is segmented
    "reconstruct/frames.py", "survey/images.py",
)



@dataclass(frozen=True)
class FrameJob:
    """One frame to segment: its image and its cache entry, each a local path or a URL
    (opened by the task with ``storage_options``, wherever it runs)."""

    frame_id: str
    image_path: str
    width_px: int
    height_px: int
    cache_path: str
    thin_px: int | None = None  # given to the default segmenter only
    storage_options: StorageOptions = field(default_factory=dict)
    panorama: bool = False  # a 360-degree equirectangular frame (the default segmenter tiles it)



def stat_key(path: str, storage_options: StorageOptions | None = None) -> list[Any] | None:
    """Size and modification stamp of a file (local: ``[size, mtime_ns]``), None when missing
    (:func:`predisat.storage.stamp`)."""
    return stamp(location(path), storage_options)



def frames_key(
    frame_ids: Iterable[str],
    image_paths: Iterable[str],
    storage_options: StorageOptions | None = None,
    known: Mapping[str, list[Any] | None] | None = None,
) -> str:
    """Hash of a chunk's frames and their images' size and modification time (None when
    missing), so that a finished chunk is redone once one of its images is replaced.
    ``known``: stamps already taken (:func:`stat_key`), by image path."""
    given = known or {}
    stamps = [
        [fid, given[path] if path in given else stat_key(path, storage_options)]
        for fid, path in zip(frame_ids, image_paths, strict=True)
    ]
    return hashlib.sha256(json.dumps(stamps).encode()).hexdigest()[:16]



def read_cache(
    job: FrameJob,
) -> tuple[NDArray, NDArray | None, NDArray | None] | BadFrame | None:
    """Cached result of a frame (None when absent or stale: the image changed)."""
    path, opts = location(job.cache_path), job.storage_options
    if not (path.is_file() if isinstance(path, Path) else exists(path, opts)):
        return None
    try:
        source = path if isinstance(path, Path) else io.BytesIO(read_bytes(path, opts))
        with np.load(source, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if (
                meta.get("version") != CACHE_VERSION
                or meta.get("thin_px") != job.thin_px
                or bool(meta.get("panorama", False)) != job.panorama
            ):
                return None
            if meta.get("image_stat") != stat_key(job.image_path, opts):
                return None
            return decode_cache(z, meta, job.frame_id)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
        return None  # a damaged cache entry (e.g. emptied by a power cut) is recomputed



def decode_cache(
    z: NpzFile, meta: JsonDict, frame_id: str
) -> tuple[NDArray, NDArray | None, NDArray | None] | BadFrame:
    """The segmentation (or the recorded failure) of an opened cache entry.

    Parameters
    ----------
    z : numpy.lib.npyio.NpzFile
        The opened entry (``sky``: packed bits of the (h, w) sky mask; ``confidence``:
        optional (w,) float32; ``thin``: optional packed bits of the thin-structure pixels).
    meta : dict
        The entry's JSON header (``shape`` (h, w), ``bad``: the failure or None).
    frame_id : str

    Returns
    -------
    (sky, confidence, thin) or BadFrame
        ``sky`` of shape (h, w), bool; ``confidence`` of shape (w,) or None; ``thin`` (h, w)
        bool or None (:attr:`predisat.reconstruct.carving.FrameView.thin_mask`).
    """
    if meta.get("bad"):
        return BadFrame(frame_id, str(meta["bad"]))
    h, w = meta["shape"]
    sky = np.unpackbits(z["sky"], count=h * w).reshape(h, w).view(bool)  # 0 / 1: no copy
    conf = z["confidence"] if "confidence" in z.files else None
    thin = None
    if "thin" in z.files:
        thin = np.unpackbits(z["thin"], count=h * w).reshape(h, w).view(bool)
    return sky, conf, thin



def write_cache(
    job: FrameJob,
    result: tuple[NDArray, NDArray | None] | tuple[NDArray, NDArray | None, NDArray | None]
    | None,
    bad: str | None,
) -> None:
    stat = stat_key(job.image_path, job.storage_options)
    meta: JsonDict = {
        "version": CACHE_VERSION, "image_stat": stat, "bad": bad, "thin_px": job.thin_px,
        "panorama": job.panorama,
    }  # fmt: skip
    arrays: dict[str, Any] = {}
    if result is not None:
        sky, conf = result[0], result[1]
        thin = result[2] if len(result) > 2 else None
        meta["shape"] = list(sky.shape)
        arrays["sky"] = np.packbits(sky.ravel())
        if conf is not None:
            arrays["confidence"] = np.asarray(conf, np.float32)
        if thin is not None and np.any(thin):
            arrays["thin"] = np.packbits(np.asarray(thin, bool).ravel())
    payload = npz_bytes({"meta": np.array(json.dumps(meta)), **arrays})
    write_atomic(location(job.cache_path), payload, job.storage_options)



def survey_hash(survey: Survey) -> str:
    """SHA-256 of the survey's description: ``survey.yaml``, ``manifest.csv``, calibrations.

    Image content is not hashed (too slow for a resume check); the segmentation cache checks
    each image's size and modification time instead.
    """
    root, opts = survey.root, survey.storage_options
    h = hashlib.sha256()
    files = [join(root, "survey.yaml"), join(root, "manifest.csv")]
    calibrations = {c.calibration_path for c in survey.cameras.values()}
    # local paths in the order of Path (by parts), as they always were
    files += sorted(calibrations, key=lambda p: p.parts if isinstance(p, Path) else (p,))
    for p in files:
        h.update(name_of(p).encode() + b"\0")
        if is_remote(p):
            h.update(read_bytes(p, opts) if exists(p, opts) else b"<missing>")
        else:
            q = Path(p)
            h.update(q.read_bytes() if q.is_file() else b"<missing>")
    return h.hexdigest()



def sky_net_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a sky network: its ONNX file and its card (the card sets the input size).

    Raises
    ------
    FileNotFoundError
        Naming the missing file.
    """
    net = SkyNet.load(path)  # checks both files and the card
    h = hashlib.sha256()
    for f in (net.path, net.path.with_suffix(".json")):
        h.update(f.read_bytes())
    return h.hexdigest()
