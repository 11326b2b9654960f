"""Scoring of sky segmentation against reference masks: IoU, skyline error, tables, contact sheet.

:func:`evaluate_folder` finds image/mask pairs in a folder, runs
:func:`predisat.sky.segment.segment_sky` on each image and scores it. Recognised layouts:

* ``ade20k``: ``original/*.jpg`` + ``mask/*.png`` (soft masks, sky where >= 128);
* ``fisheye_hk``: ``raw_images/*.jpg`` + ``mask_images/*.png`` (upward fisheye; segmented with
  ``SkyOptions(fisheye=True)``; the mask is 0 outside the lens circle, which does not change the
  sky IoU since those pixels are non-sky in both);
* ``generic``: ``images/*`` + ``masks/*.png`` (same stem);
* ``synthetic``: a folder written by :func:`predisat.synth.generate.generate_survey`
  (``survey/images`` + ``truth/labels/<frame_id>.png``, labels 255 sky, 128 thin
  L-band-transparent structure, 0 obstacle: sky where >= 128, per the thin-structure policy),
  scored per sky condition and also by skyline elevation error through the survey's cameras,
  with the columns whose skyline is read more than :data:`UNSAFE_LOW_DEG` too low (the unsafe
  side: a mask built from them would trust satellites behind the obstacle).

The sky IoU of one image is ``|pred & true| / |pred | true|`` over sky pixels (1 when both are
empty). Summaries give the mean over images and the pooled IoU (sums over all pixels).

Safety first (:func:`sky_safety_counts`): the **false-sky rate** (non-sky pixels labelled sky,
over all non-sky pixels: what would let a blocked satellite be trusted), the share of **unsafe
columns** (columns with false sky over at least :data:`UNSAFE_COLUMN_FRACTION` of the image
height) and the **missed-sky rate** (true sky labelled obstacle: availability lost), for the
default segmenter and, beside it, the naive baseline of :mod:`predisat.sky.naive`; each also
for the sky the pipeline keeps in an upright frame (``trusted_``: above the skyline, sky holes
below it blocked; a fisheye photo keeps every region). Summaries pool them (sums over the
images), and give the throughput in frames per CPU-second beside the JPEG decode's.
"""

from __future__ import annotations

import csv
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from tqdm import tqdm

from predisat.camera.models import CameraModel
from predisat.jsontypes import JsonDict
from predisat.sky.naive import naive_sky_mask
from predisat.sky.perceptron import SkyModel
from predisat.sky.segment import SkyOptions, mask_above_skyline, segment_sky, skyline_from_mask
from predisat.survey import Survey

__all__ = [
    "UNSAFE_COLUMN_FRACTION",
    "UNSAFE_LOW_DEG",
    "SkyEvaluation",
    "SkyPair",
    "confusion_overlay",
    "evaluate_folder",
    "find_pairs",
    "safety_table",
    "sky_iou",
    "sky_safety_counts",
    "skyline_elevation_deg",
    "worst_cases_sheet",
]

#: A column's skyline more than this below the truth counts as unsafe (``skyline_low_1deg_*``).
UNSAFE_LOW_DEG = 1.0
#: A column is unsafe when its false sky covers at least this share of the image height.
UNSAFE_COLUMN_FRACTION = 0.01
#: The two segmentations scored side by side: the default (no prefix) and the naive baseline.
_METHODS = ("", "naive_")
_COUNTS = ("false_sky_px", "non_sky_px", "unsafe_columns", "n_columns", "missed_sky_px",
           "true_sky_px")  # fmt: skip

_IMAGE_EXT = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")
_LAYOUTS = (
    ("ade20k", "original", "mask", False),
    ("fisheye_hk", "raw_images", "mask_images", True),
    ("generic", "images", "masks", False),
)


@dataclass(frozen=True)
class SkyPair:
    """One image with its reference mask; ``group`` is the summary group (set or sky)."""

    name: str
    image_path: Path
    mask_path: Path
    group: str
    side: str | None = None


@dataclass(frozen=True)
class SkyEvaluation:
    """Result of :func:`evaluate_folder`.

    Attributes
    ----------
    layout : str
        Detected layout (``ade20k``, ``fisheye_hk``, ``generic``, ``synthetic``).
    table : pandas.DataFrame
        One row per image (columns described in ``docs/segmentation.md``).
    summary : pandas.DataFrame
        One row per group (data set, or sky condition for synthetic surveys) and ``all``.
    files : dict
        What was written (``table``, ``summary``, ``sheet``) when ``out_dir`` was given.
    worst_cases : list of (name, iou, image_bgr, overlay_bgr)
        The ``n_worst`` lowest-IoU cases, lowest first, as :func:`worst_cases_sheet` takes them
        (overlays from :func:`confusion_overlay`).
    """

    layout: str
    table: pd.DataFrame
    summary: pd.DataFrame
    files: dict[str, Path] = field(default_factory=dict)
    worst_cases: list[tuple[str, float, NDArray, NDArray]] = field(default_factory=list)


def sky_iou(pred: ArrayLike, truth: ArrayLike, valid: ArrayLike | None = None) -> float:
    """Intersection over union of the sky class of two masks (1.0 when both have no sky).

    Parameters
    ----------
    pred, truth : array_like of bool, shape (H, W)
    valid : array_like of bool, shape (H, W), optional
        Only these pixels count.
    """
    p, t = np.asarray(pred, bool), np.asarray(truth, bool)
    if p.shape != t.shape:
        raise ValueError(f"pred shape {p.shape} differs from truth shape {t.shape}")
    if valid is not None:
        v = np.asarray(valid, bool)
        p, t = p & v, t & v
    union = int(np.count_nonzero(p | t))
    return 1.0 if union == 0 else float(np.count_nonzero(p & t) / union)


def sky_safety_counts(pred: ArrayLike, truth: ArrayLike, valid: ArrayLike) -> dict[str, int]:
    """Pixel and column counts of the safety figures of one image.

    Parameters
    ----------
    pred, truth, valid : array_like of bool, shape (H, W)
        Predicted sky, true sky, pixels that count (the lens circle of a fisheye photo).

    Returns
    -------
    dict
        ``false_sky_px`` (valid non-sky labelled sky), ``non_sky_px``, ``unsafe_columns``
        (columns with at least ``UNSAFE_COLUMN_FRACTION * H`` false-sky pixels), ``n_columns``
        (columns with a valid pixel), ``missed_sky_px`` (true sky labelled obstacle),
        ``true_sky_px``. Rates are ratios of sums, so images pool by adding the counts.
    """
    p, t, v = (np.asarray(a, bool) for a in (pred, truth, valid))
    if not p.shape == t.shape == v.shape or p.ndim != 2:
        raise ValueError(f"pred, truth and valid must be 2-D of one shape, got {p.shape}, "
                         f"{t.shape}, {v.shape}")  # fmt: skip
    t = t & v
    false_sky = p & ~t & v
    cols = v.any(axis=0)
    unsafe = (false_sky.sum(axis=0) >= UNSAFE_COLUMN_FRACTION * p.shape[0]) & cols
    return {
        "false_sky_px": int(false_sky.sum()), "non_sky_px": int((v & ~t).sum()),
        "unsafe_columns": int(unsafe.sum()), "n_columns": int(cols.sum()),
        "missed_sky_px": int((t & ~p).sum()), "true_sky_px": int(t.sum()),
    }  # fmt: skip


def safety_table(summary: pd.DataFrame) -> pd.DataFrame:
    """The safety-first view of a summary: per group, the default segmenter and the naive
    baseline side by side (percent), the sky the pipeline keeps beside the raw labels.

    Parameters
    ----------
    summary : pandas.DataFrame
        ``SkyEvaluation.summary``.

    Returns
    -------
    pandas.DataFrame
        One row per group and method (``default``, ``naive``): ``false_sky_pct``,
        ``unsafe_columns_pct``, ``missed_sky_pct``, the same of the kept sky (``trusted_``),
        and ``mean_iou``.
    """
    rows = []
    for r in summary.to_dict(orient="records"):
        for name, m in (("default", ""), ("naive", "naive_")):
            rows.append({
                "group": r["group"], "method": name,
                **{k: r[m + k] for k in ("false_sky_pct", "unsafe_columns_pct",
                                         "missed_sky_pct", "trusted_false_sky_pct",
                                         "trusted_unsafe_columns_pct", "trusted_missed_sky_pct")},
                "mean_iou": r[m + "mean_iou"],
            })  # fmt: skip
    return pd.DataFrame(rows)


def _rates(counts: pd.DataFrame | dict[str, Any], prefix: str) -> dict[str, float]:
    """The three rates (percent) of summed ``sky_safety_counts`` columns under ``prefix``."""

    def ratio(a: str, b: str) -> float:
        den = float(np.sum(counts[prefix + b]))
        return 100.0 * float(np.sum(counts[prefix + a])) / den if den else float("nan")

    return {
        f"{prefix}false_sky_pct": ratio("false_sky_px", "non_sky_px"),
        f"{prefix}unsafe_columns_pct": ratio("unsafe_columns", "n_columns"),
        f"{prefix}missed_sky_pct": ratio("missed_sky_px", "true_sky_px"),
    }


def skyline_elevation_deg(
    skyline_row: ArrayLike, camera: CameraModel, camera_to_vehicle: ArrayLike
) -> NDArray[np.float64]:
    """Elevation (deg, vehicle frame, z up) of each column's skyline point.

    Parameters
    ----------
    skyline_row : array_like, shape (W,)
        Skyline rows (``nan`` stays ``nan``); the point is ``(u = column, v = skyline_row)``.
    camera : CameraModel
        Its ``pixel_to_ray(u_px, v_px) -> (..., 3)`` in the OpenCV camera frame is used.
    camera_to_vehicle : array_like, shape (3, 3)
        ``Mount.camera_to_vehicle()``.

    Returns
    -------
    ndarray, shape (W,)
        Elevation above the vehicle's horizontal plane (the local horizontal on level track).
    """
    v = np.asarray(skyline_row, float)
    u = np.arange(v.size, dtype=float)
    ok = np.isfinite(v)
    out = np.full(v.size, np.nan)
    if ok.any():
        rays = np.asarray(camera.pixel_to_ray(u[ok], v[ok]), float)
        vr = rays @ np.asarray(camera_to_vehicle, float).T
        out[ok] = np.degrees(np.arcsin(np.clip(vr[:, 2] / np.linalg.norm(vr, axis=1), -1, 1)))
    return out


def _pairs_in(data: Path, img_dir: str, mask_dir: str, group: str) -> list[SkyPair]:
    masks = {p.stem: p for p in (data / mask_dir).iterdir() if p.suffix.lower() == ".png"}
    pairs = []
    for p in sorted((data / img_dir).iterdir()):
        if p.suffix.lower() in _IMAGE_EXT and p.stem in masks:
            pairs.append(SkyPair(p.stem, p, masks[p.stem], group))
    return pairs


def _synthetic_pairs(root: Path) -> list[SkyPair]:
    survey, truth = root / "survey", root / "truth"
    sky_of: dict[str, str] = {}
    if (truth / "frames.csv").is_file():
        with open(truth / "frames.csv", newline="", encoding="utf-8") as f:
            sky_of = {r["frame_id"]: r.get("sky", "synthetic") for r in csv.DictReader(f)}
    pairs = []
    with open(survey / "manifest.csv", newline="", encoding="utf-8") as f:
        for row in csv.DictReader(f):
            fid = row["frame_id"]
            label = truth / "labels" / f"{fid}.png"
            if label.is_file():
                pairs.append(
                    SkyPair(fid, survey / row["image"], label, sky_of.get(fid, "synthetic"),
                            row.get("side"))
                )
    return pairs


def find_pairs(data_dir: str | os.PathLike[str]) -> tuple[str, list[SkyPair]]:
    """Detect the layout of ``data_dir`` and list its image/mask pairs (see module docstring).

    Raises
    ------
    FileNotFoundError
        When the folder does not exist or holds no recognised pair; the message names the
        folder and the layouts looked for.
    """
    data = Path(data_dir)
    if not data.is_dir():
        raise FileNotFoundError(f"sky evaluation folder {data} does not exist")
    if (data / "survey" / "manifest.csv").is_file() and (data / "truth" / "labels").is_dir():
        pairs = _synthetic_pairs(data)
        if pairs:
            return "synthetic", pairs
    for layout, img_dir, mask_dir, _ in _LAYOUTS:
        if (data / img_dir).is_dir() and (data / mask_dir).is_dir():
            pairs = _pairs_in(data, img_dir, mask_dir, data.name or layout)
            if pairs:
                return layout, pairs
    looked = ", ".join(f"{i}/ + {m}/" for _, i, m, _ in _LAYOUTS)
    raise FileNotFoundError(
        f"no image/mask pairs found in {data}: expected {looked} (images and PNG masks with the "
        "same file stem), or a synthetic output folder with survey/manifest.csv and truth/labels/"
    )


def confusion_overlay(pred: NDArray, truth: NDArray) -> NDArray:
    """BGR picture of a prediction: white true sky, red false sky, blue missed sky, black rest."""
    out = np.zeros((*pred.shape, 3), np.uint8)
    out[pred & truth] = (255, 255, 255)
    out[pred & ~truth] = (0, 0, 255)
    out[~pred & truth] = (255, 0, 0)
    return out


def worst_cases_sheet(
    items: Iterable[tuple[str, float, NDArray, NDArray]],
    path: str | os.PathLike[str],
    thumb_w_px: int = 200,
    per_row: int = 2,
    score_label: str = "IoU {:.3f}",
) -> Path:
    """Write a contact sheet: per case a thumbnail and its confusion overlay, captioned.

    Parameters
    ----------
    items : iterable of (name, score, image_bgr, overlay_bgr)
    path : path-like
        PNG to write.
    thumb_w_px : int
        Width of each thumbnail (height keeps a 3:4 box; images are letterboxed).
    per_row : int
        Cases per row.
    score_label : str
        Format of the score in each caption.
    """
    th = thumb_w_px * 3 // 4
    tiles = []
    for name, iou, img, ov in items:
        pair = []
        for pic, interp in ((img, cv2.INTER_AREA), (ov, cv2.INTER_NEAREST)):
            s = min(thumb_w_px / pic.shape[1], th / pic.shape[0])
            size = (max(1, round(pic.shape[1] * s)), max(1, round(pic.shape[0] * s)))
            small = cv2.resize(pic, size, interpolation=interp)
            box = np.full((th, thumb_w_px, 3), 64, np.uint8)
            y0, x0 = (th - small.shape[0]) // 2, (thumb_w_px - small.shape[1]) // 2
            box[y0:y0 + small.shape[0], x0:x0 + small.shape[1]] = small
            pair.append(box)
        cap = np.full((16, 2 * thumb_w_px, 3), 32, np.uint8)
        cv2.putText(cap, f"{name}  {score_label.format(iou)}", (4, 12),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(np.vstack([cap, np.hstack(pair)]))
    if not tiles:
        raise ValueError("worst_cases_sheet needs at least one case")
    blank = np.zeros_like(tiles[0])
    while len(tiles) % per_row:
        tiles.append(blank)
    sheet = np.vstack([np.hstack(tiles[i:i + per_row]) for i in range(0, len(tiles), per_row)])
    sheet = np.vstack([sheet, _legend(sheet.shape[1])])
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), sheet, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"could not write contact sheet {out}")
    return out


_LEGEND = (
    ((255, 255, 255), "sky, right"),
    ((0, 0, 255), "false sky (unsafe)"),
    ((255, 0, 0), "missed sky (lost)"),
    ((0, 0, 0), "obstacle, right"),
)


def _legend(width_px: int) -> NDArray:
    """A strip naming the colours of :func:`confusion_overlay`."""
    strip = np.full((18, width_px, 3), 32, np.uint8)
    x = 4
    for colour, text in _LEGEND:
        if x + 140 > width_px:
            break
        cv2.rectangle(strip, (x, 4), (x + 10, 14), colour, -1)
        cv2.rectangle(strip, (x, 4), (x + 10, 14), (160, 160, 160), 1)
        cv2.putText(strip, text, (x + 14, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                    (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
        x += 140
    return strip


def _read_mask(path: Path, shape: tuple[int, int]) -> NDArray:
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise OSError(f"cannot read mask {path}")
    if m.shape != shape:
        raise ValueError(f"mask {path} is {m.shape[::-1]} px but its image is {shape[::-1]} px")
    return np.asarray(m >= 128)


def _cameras(root: Path) -> dict[str, tuple[CameraModel, NDArray]]:
    survey = Survey.load(root / "survey", check_images=False)
    # the level mount, whatever the vehicle's roll: the predicted and the true skylines go
    # through the same rotation, so a tilt changes their difference to second order only
    return {s: (c.camera, c.mount.camera_to_vehicle()) for s, c in survey.cameras.items()}


def _summarise(table: pd.DataFrame, skyline_err: dict[str, list[NDArray]]) -> pd.DataFrame:
    rows = []
    groups = [*sorted(table["group"].unique()), "all"]
    for g in groups:
        t = table if g == "all" else table[table["group"] == g]
        row: JsonDict = {
            "group": g,
            "n_images": len(t),
            "mean_iou": t["iou"].mean(),
            "median_iou": t["iou"].median(),
            "min_iou": t["iou"].min(),
            "pooled_iou": t["inter_px"].sum() / max(t["union_px"].sum(), 1),
            "mean_s": t["seconds"].mean(),
            "naive_mean_iou": t["naive_iou"].mean(),
        }
        for kind in ("", "trusted_"):
            for m in _METHODS:
                row.update(_rates(t, m + kind))
        cpu = float(t["cpu_s"].sum())
        row["frames_per_cpu_s"] = len(t) / cpu if cpu > 0 else float("nan")
        dec = float(t["decode_cpu_s"].sum())
        row["decode_frames_per_cpu_s"] = len(t) / dec if dec > 0 else float("nan")
        if skyline_err:
            parts = [e for k, v in skyline_err.items() if g in ("all", k) for e in v]
            err = np.abs(np.concatenate(parts)) if parts else np.zeros(0)
            err = err[np.isfinite(err)]
            row["skyline_el_err_median_deg"] = float(np.median(err)) if err.size else np.nan
            row["skyline_el_err_p95_deg"] = float(np.percentile(err, 95)) if err.size else np.nan
            row["n_skyline_columns"] = int(err.size)
            low = int(t["skyline_low_1deg_columns"].sum())
            row["skyline_low_1deg_columns"] = low
            row["skyline_low_1deg_share"] = low / err.size if err.size else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate_folder(
    data_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    progress: bool = True,
    options: SkyOptions | None = None,
    limit: int | None = None,
    n_worst: int = 8,
    method: str | None = None,
    classifier: SkyModel | None = None,
) -> SkyEvaluation:
    """Segment every image of a folder with reference masks and score it.

    Parameters
    ----------
    data_dir : path-like
        A folder in one of the layouts of the module docstring.
    out_dir : path-like, optional
        When given, writes ``<name>_per_image.csv``, ``<name>_summary.md`` (the safety table
        first), ``<name>_worst.png`` (the ``n_worst`` lowest-IoU cases) and
        ``<name>_worst_false_sky.png`` (the ``n_worst`` highest false-sky rates) there,
        ``<name>`` being the folder's name.
    progress : bool
        Show a tqdm progress bar.
    options : SkyOptions, optional
        Segmentation options; default ``SkyOptions(fisheye=True)`` for the fisheye layout and
        ``SkyOptions()`` otherwise.
    limit : int, optional
        Score only the first ``limit`` pairs (quick runs).
    n_worst : int
        Cases in the contact sheet.
    method : str, optional
        Segmentation method (:data:`predisat.sky.segment.METHODS`) when ``options`` is not
        given; default that of ``SkyOptions``.
    classifier : SkyModel, optional
        Probability model passed to :func:`predisat.sky.segment.segment_sky` (a candidate
        network or ensemble); default the shipped one of the method.

    Returns
    -------
    SkyEvaluation
    """
    data = Path(data_dir)
    layout, pairs = find_pairs(data)
    if limit is not None:
        pairs = pairs[: max(0, int(limit))]
    opt = _options_for(layout, options, method)
    cams = _cameras(data) if layout == "synthetic" else {}
    rows: list[JsonDict] = []
    worst: list[tuple[float, SkyPair, NDArray, NDArray]] = []
    unsafe: list[tuple[float, SkyPair, NDArray, NDArray]] = []  # highest false-sky rate first
    skyline_err: dict[str, list[NDArray]] = {}
    for pair in tqdm(pairs, desc=f"sky {data.name}", disable=not progress, unit="img"):
        row, pred, truth_v, err = _score_pair(pair, opt, classifier, cams)
        if err is not None:
            skyline_err.setdefault(pair.group, []).append(err)
        rows.append(row)
        worst.append((row["iou"], pair, pred, truth_v))
        worst = sorted(worst, key=lambda w: w[0])[:n_worst]  # keep only the few worst in memory
        unsafe.append((row["false_sky_pct"], pair, pred, truth_v))
        unsafe = sorted(unsafe, key=lambda w: -np.nan_to_num(w[0], nan=-1.0))[:n_worst]
    table = pd.DataFrame(rows)
    summary = _summarise(table, skyline_err)
    items, unsafe_items = _sheet_items(worst), _sheet_items(unsafe)
    files: dict[str, Path] = {}
    if out_dir is not None:
        stem = data.name or layout
        files = _write_outputs(Path(out_dir), stem, layout, table, summary, items)
        if unsafe_items:
            files["unsafe_sheet"] = worst_cases_sheet(
                unsafe_items, Path(out_dir) / f"{stem}_worst_false_sky.png",
                score_label="false sky {:.2f} %",
            )
    return SkyEvaluation(layout=layout, table=table, summary=summary, files=files,
                         worst_cases=items)  # fmt: skip


def _sheet_items(
    cases: list[tuple[float, SkyPair, NDArray, NDArray]],
) -> list[tuple[str, float, NDArray, NDArray]]:
    """(name, score, image, confusion overlay) of each case, as :func:`worst_cases_sheet` takes."""
    out = []
    for score, pair, pred, truth_v in cases:
        img = np.asarray(cv2.imread(str(pair.image_path), cv2.IMREAD_COLOR))
        out.append((pair.name, score, img, confusion_overlay(pred, truth_v)))
    return out


def _options_for(layout: str, options: SkyOptions | None, method: str | None) -> SkyOptions:
    """``options``, else the defaults of the layout (fisheye or not) with ``method``."""
    fisheye = layout == "fisheye_hk"
    if options is not None:
        return options
    if method is not None:
        return SkyOptions(fisheye=fisheye, method=method)
    return SkyOptions(fisheye=fisheye)


def _score_pair(
    pair: SkyPair,
    opt: SkyOptions,
    classifier: SkyModel | None,
    cams: dict[str, tuple[CameraModel, NDArray]],
) -> tuple[JsonDict, NDArray, NDArray, NDArray | None]:
    """Segment one image and score it: the table row, the predicted and (valid) true sky, and
    the skyline elevation errors (deg, seen columns) when the pair's camera is in ``cams``."""
    c0 = time.process_time()
    img = cv2.imread(str(pair.image_path), cv2.IMREAD_COLOR)
    decode_cpu = time.process_time() - c0
    if img is None:
        raise OSError(f"cannot read image {pair.image_path}")
    truth = _read_mask(pair.mask_path, img.shape[:2])
    t0, c0 = time.perf_counter(), time.process_time()
    seg = segment_sky(img, opt, classifier=classifier)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    pred, valid = seg.sky_mask, seg.valid_mask
    truth_v = truth & valid
    h = img.shape[0]
    naive = naive_sky_mask(img, valid, upright=not opt.fisheye)
    # what the pipeline keeps of an upright frame: sky above the skyline (holes blocked)
    kept = (lambda m: m) if opt.fisheye else (
        lambda m: mask_above_skyline(skyline_from_mask(m, valid), h) & valid
    )  # fmt: skip
    counts: dict[str, Any] = {}
    for prefix, mask in (("", pred), ("naive_", naive)):
        for kind, m in (("", mask), ("trusted_", kept(mask))):
            c = sky_safety_counts(m, truth_v, valid)
            counts.update({prefix + kind + k: v for k, v in c.items()})
    true_line = skyline_from_mask(truth_v, valid)
    seen = ((true_line > -0.5) & (true_line < h - 0.5)) | (
        (seg.skyline_row > -0.5) & (seg.skyline_row < h - 0.5)
    )
    row: JsonDict = {
        "name": pair.name,
        "group": pair.group,
        "width_px": img.shape[1],
        "height_px": h,
        "iou": sky_iou(pred, truth_v),
        "inter_px": int(np.count_nonzero(pred & truth_v)),
        "union_px": int(np.count_nonzero(pred | truth_v)),
        "true_sky_fraction": float(truth_v.sum() / max(valid.sum(), 1)),
        "pred_sky_fraction": seg.sky_fraction,
        "skyline_err_px_median": float(np.median(np.abs(seg.skyline_row - true_line)[seen]))
        if seen.any() else 0.0,
        "mean_confidence": float(np.nanmean(seg.confidence)),
        "seconds": dt,
        "cpu_s": cpu,
        "decode_cpu_s": decode_cpu,
        "naive_iou": sky_iou(naive, truth_v),
        **counts,
    }
    for m in _METHODS:
        row.update(_rates(counts, m))
    if pair.side not in cams:
        return row, pred, truth_v, None
    cam, r_cv = cams[pair.side]
    err = skyline_elevation_deg(seg.skyline_row, cam, r_cv) - skyline_elevation_deg(
        true_line, cam, r_cv
    )
    err = err[seen]
    row["skyline_el_err_median_deg"] = float(np.median(np.abs(err))) if err.size else 0.0
    row["skyline_el_err_max_deg"] = float(np.max(np.abs(err))) if err.size else 0.0
    # the unsafe side: a skyline read too low would let a blocked satellite be trusted
    row["skyline_low_1deg_columns"] = int(np.count_nonzero(err < -UNSAFE_LOW_DEG))
    return row, pred, truth_v, err


def _write_outputs(
    out: Path,
    stem: str,
    layout: str,
    table: pd.DataFrame,
    summary: pd.DataFrame,
    items: list[tuple[str, float, NDArray, NDArray]],
) -> dict[str, Path]:
    """Write ``<stem>_per_image.csv``, ``<stem>_summary.md`` and ``<stem>_worst.png``."""
    files: dict[str, Path] = {}
    out.mkdir(parents=True, exist_ok=True)
    files["table"] = out / f"{stem}_per_image.csv"
    table.to_csv(files["table"], index=False, float_format="%.5g")
    files["summary"] = out / f"{stem}_summary.md"
    files["summary"].write_text(
        f"# Sky segmentation on `{stem}` ({layout}, {len(table)} images)\n\n"
        "Safety first (percent; `trusted_`: the sky the pipeline keeps, above the skyline of "
        "an upright frame):\n\n" + _markdown(safety_table(summary)) + "\n\nAll figures:\n\n"
        + _markdown(summary) + "\n",
        encoding="utf-8",
    )
    if items:
        files["sheet"] = worst_cases_sheet(items, out / f"{stem}_worst.png")
    return files


def _markdown(df: pd.DataFrame) -> str:
    """A pipe table (no optional dependency such as tabulate)."""

    def cell(v: Any) -> str:
        return f"{v:.4f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in df.itertuples(index=False)]
    return "\n".join(lines)
