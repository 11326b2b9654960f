"""When each image was taken, by its camera's own clock: whether images sit on their rows.

A manifest pairs each image with a row's time and place. When one camera's image column is a
row or more off (a dropped image, a renumbering, a camera that missed a trigger), every later
image of that camera is carved at another frame's place: a user trial's such survey trusted
1.05 % of its directions falsely, and neither the images nor the flow check showed it.

Cameras stamp each picture with their own clock (EXIF ``DateTimeOriginal`` with
``SubSecTimeOriginal``). That clock is offset from GPS time (a time zone, a clock never set)
and drifts (tens of ppm), but over a survey it is one straight line against GPS time, while an
image a row off carries the time of another row: a frame gap away (0.4-1 s at 10 m spacing),
far beyond a camera's stamping jitter (milliseconds). :func:`fit_clock` finds that line,
:func:`check_rows` the row each image's time belongs to (``docs/reconstruction.md``,
section 22).

Unlike the comparison of two cameras' overlap (:mod:`predisat.reconstruct.step`), this needs
no overlap and says *which* camera is off; it needs capture times to a fraction of a frame gap
(frames extracted from video, or written by software that drops EXIF, have none).
"""

from __future__ import annotations

import datetime as dt
import io
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image, UnidentifiedImageError

from predisat.storage import Location, StorageOptions, read_bytes
from predisat.survey.images import exif_of

__all__ = [
    "HEADER_BYTES",
    "MAX_DRIFT_PPM",
    "MAX_LAG",
    "MIN_FIT_SHARE",
    "MIN_TIMED_FRAMES",
    "ClockFit",
    "RowCheck",
    "capture_time_s",
    "check_rows",
    "exif_time_bytes",
    "fit_clock",
    "read_capture_time_s",
]

MAX_LAG = 3
"""Largest offset between an image and its row that is told apart from a foreign time, rows."""
MAX_DRIFT_PPM = 200.0
"""Largest camera clock drift searched, ppm: quartz clocks keep 20-50 ppm, 100 over
temperature."""
MIN_TIMED_FRAMES = 10
"""Fewest frames with a capture time for a camera to be checked."""
MIN_FIT_SHARE = 0.5
"""Least share of a camera's timed frames that one clock must explain (at some lag) for the
camera to be checked: below, the times do not follow the rows (rewritten by software, or a
clock that jumped) and say nothing about the rows."""
HEADER_BYTES = 131072
"""Bytes of an image read for its capture time: a JPEG's EXIF segment is at most 64 KiB and
comes before the pixels (a remote image is not downloaded whole)."""
_TOL_MIN_S = 0.002
_TOL_START_S = 0.02
_JITTER_SIGMAS = 6.0
_REFINE_ROUNDS = 8
_GRID_FRAMES = 4000
_EXIF_IFD = 0x8769
_DATETIME_ORIGINAL = 0x9003
_SUBSEC_ORIGINAL = 0x9291
_EPOCH = dt.datetime(1970, 1, 1)


def capture_time_s(im: Image.Image) -> tuple[float, float]:
    """An opened image's capture time by its camera's clock, and the time's resolution.

    Parameters
    ----------
    im : PIL.Image.Image
        Opened (headers read, pixels not needed).

    Returns
    -------
    time_s : float
        EXIF ``DateTimeOriginal`` plus ``SubSecTimeOriginal``, seconds since 1970-01-01 of
        the camera's clock (no time zone applied: only differences are used); NaN when the
        image has none or it cannot be read.
    resolution_s : float
        Its last digit's step: 1 s with no sub-seconds, 0.01 s for two digits; NaN with no time.
    """
    try:
        exif = exif_of(im)
        if exif is None:
            return math.nan, math.nan
        ifd = exif.get_ifd(_EXIF_IFD)
        text, sub = ifd.get(_DATETIME_ORIGINAL), ifd.get(_SUBSEC_ORIGINAL)
        when = dt.datetime.strptime(str(text).strip("\x00 "), "%Y:%m:%d %H:%M:%S")
    except (TypeError, ValueError, OSError, SyntaxError, KeyError):
        return math.nan, math.nan
    digits = "".join(ch for ch in str(sub or "").strip("\x00 ") if ch.isdigit())[:9]
    frac = int(digits) / 10 ** len(digits) if digits else 0.0
    step = 10.0 ** -len(digits) if digits else 1.0
    return (when - _EPOCH).total_seconds() + frac, step


def exif_time_bytes(time_s: float, digits: int = 3) -> bytes:
    """An EXIF block (``Exif\\0\\0`` and its TIFF structure) holding a capture time.

    Parameters
    ----------
    time_s : float
        Seconds since 1970-01-01 of the camera's clock.
    digits : int
        Sub-second digits written (0: whole seconds, as many cameras).

    Returns
    -------
    bytes
        The payload of a JPEG APP1 segment.
    """
    if not math.isfinite(time_s):
        raise ValueError(f"time_s must be finite, got {time_s}")
    if not 0 <= digits <= 6:
        raise ValueError(f"digits must be 0-6, got {digits}")
    scale = 10**digits
    ticks = round(time_s * scale)
    whole, frac = divmod(ticks, scale)
    exif = Image.Exif()
    ifd = exif.get_ifd(_EXIF_IFD)
    ifd[_DATETIME_ORIGINAL] = (_EPOCH + dt.timedelta(seconds=whole)).strftime("%Y:%m:%d %H:%M:%S")
    if digits:
        ifd[_SUBSEC_ORIGINAL] = f"{frac:0{digits}d}"
    return bytes(exif.tobytes())


@dataclass(frozen=True)
class ClockFit:
    """A camera's clock against GPS time: ``image_s = gps_s + offset_s + drift (gps_s - t0)``.

    Attributes
    ----------
    offset_s : float
        Camera time minus GPS time at the first row, seconds.
    drift_ppm : float
        Rate of the camera clock against GPS time, parts per million.
    tol_s : float
        Largest residual of an image at its own row, seconds (six robust sigmas of the fitted
        frames' residuals, at least two resolution steps).
    fitted : int
        Timed frames whose time matches some row within ``MAX_LAG`` at ``tol_s``.
    timed : int
        Frames with a capture time.
    ambiguous : bool
        Another clock a whole number of frame gaps away explains nearly as many frames with
        other rows in step: at constant speed the times cannot tell a shift of every image from
        a clock offset, and the first timed frames were taken as on their own rows.
    reliable : bool
        False when the times' scatter about the best straight clock reaches a quarter of the
        frames' median gap, or its drift leaves the searched range: images several rows off,
        a clock that jumped, or stamps too coarse (then ``fitted`` is 0).
    """

    offset_s: float
    drift_ppm: float
    tol_s: float
    fitted: int
    timed: int
    ambiguous: bool
    reliable: bool = True

    @property
    def share(self) -> float:
        """Share of the timed frames the clock explains."""
        return self.fitted / self.timed if self.timed else 0.0


@dataclass(frozen=True, eq=False)
class RowCheck:
    """Each frame's row by its capture time, shape (n,) per array.

    Attributes
    ----------
    checked : ndarray of bool
        The frame has a time and its neighbouring rows are more than twice ``tol_s`` from
        its own (a row off could be told).
    lag : ndarray of int
        The image's time is that of the row ``lag`` later (0: its own row; only meaningful
        where ``checked`` and ``fits``).
    fits : ndarray of bool
        Its time matches a row within ``MAX_LAG``.
    """

    checked: NDArray
    lag: NDArray
    fits: NDArray

    @property
    def off(self) -> NDArray:
        """Checked frames whose time is not their own row's."""
        return self.checked & (~self.fits | (self.lag != 0))


def _row_times(gps_s: NDArray, max_lag: int) -> NDArray:
    """``gps_s[i + lag]`` for each frame and lag -max_lag..max_lag, NaN beyond the ends, (n, k)."""
    n = gps_s.size
    idx = np.arange(n)[:, None] + np.arange(-max_lag, max_lag + 1)[None, :]
    ok = (idx >= 0) & (idx < n)
    return np.where(ok, gps_s[np.clip(idx, 0, max(n - 1, 0))], np.nan)


def _residuals(image_s: NDArray, gps_s: NDArray, offset_s: float, drift_ppm: float,
               max_lag: int) -> NDArray:  # fmt: skip
    t = gps_s - gps_s[0]
    clock = image_s - drift_ppm * 1e-6 * t
    return clock[:, None] - _row_times(gps_s, max_lag) - offset_s


def _lags(res: NDArray, tol_s: float, max_lag: int) -> tuple[NDArray, NDArray]:
    a = np.where(np.isfinite(res), np.abs(res), np.inf)
    best = np.argmin(a, axis=1)
    fits = a[np.arange(a.shape[0]), best] <= tol_s
    return best - max_lag, fits


def _peaks(values: NDArray, width_s: float, count: int) -> list[tuple[int, float]]:
    """The ``count`` densest windows ``2 width_s`` wide of ``values``, one per cluster:
    (number inside, their median)."""
    out = []
    v = np.sort(values[np.isfinite(values)])
    for _ in range(count):
        if v.size == 0:
            break
        hi = np.searchsorted(v, v + 2.0 * width_s, side="right")
        n_in = hi - np.arange(v.size)
        k = int(np.argmax(n_in))
        inside = v[k : hi[k]]
        centre = float(np.median(inside))
        out.append((int(n_in[k]), centre))
        v = v[np.abs(v - centre) > 2.0 * width_s]
    return out


def fit_clock(
    image_s: ArrayLike,
    gps_s: ArrayLike,
    resolution_s: float = 0.001,
    max_lag: int = MAX_LAG,
    max_drift_ppm: float = MAX_DRIFT_PPM,
) -> ClockFit | None:
    """A camera's clock: the offset and drift that put most images' times on some row.

    Each image's time is compared with the rows up to ``max_lag`` either side of its own, so
    that a stretch of images a row off does not pull the clock: the line explaining the most
    frames at any lag is the camera's clock (a clock a frame gap off explains only the frames
    taken at the speed of that gap). At constant speed such clocks explain nearly as many; the
    one that puts the first timed frames on their own rows is taken (``ambiguous``).

    Parameters
    ----------
    image_s : array_like, shape (n,)
        The camera's capture times of its frames in time order, seconds (NaN: none).
    gps_s : array_like, shape (n,)
        The manifest rows' times of the same frames, increasing, seconds.
    resolution_s : float
        The capture times' resolution, seconds (> 0).
    max_lag : int
        Largest row offset tried either way (>= 1).
    max_drift_ppm : float
        Largest clock drift searched, ppm (>= 0).

    Returns
    -------
    ClockFit or None
        None when fewer than ``MIN_TIMED_FRAMES`` frames have a time.
    """
    e, g = np.asarray(image_s, float), np.asarray(gps_s, float)
    if e.shape != g.shape or e.ndim != 1:
        raise ValueError(f"image_s and gps_s must be 1-D of one length, got {e.shape} and "
                         f"{g.shape}")  # fmt: skip
    if g.size and not (np.all(np.isfinite(g)) and np.all(np.diff(g) > 0)):
        raise ValueError("gps_s must be finite and increasing (the camera's rows in time order)")
    if not resolution_s > 0.0 or max_lag < 1 or not max_drift_ppm >= 0.0:
        raise ValueError(f"resolution_s must be > 0, max_lag >= 1 and max_drift_ppm >= 0, got "
                         f"{resolution_s}, {max_lag}, {max_drift_ppm}")  # fmt: skip
    timed = int(np.count_nonzero(np.isfinite(e)))
    if timed < MIN_TIMED_FRAMES:
        return None
    span_s = float(g[-1] - g[0])
    tol = max(_TOL_START_S, 2.0 * resolution_s)
    step_ppm = max(0.5 * tol / max(span_s, 1e-9) * 1e6, 0.5)
    n_drift = math.ceil(max_drift_ppm / step_ppm)
    best = (-1, 0.0, 0.0)
    # the drift search on at most _GRID_FRAMES timed frames spread over the survey (the
    # refinement below uses them all): 10^5 frames took 67 s on every frame (a review)
    timed_at = np.flatnonzero(np.isfinite(e))
    sub = timed_at[np.linspace(0, timed_at.size - 1, min(timed_at.size, _GRID_FRAMES)).astype(int)]
    rows_sub = _row_times(g, max_lag)[sub]
    t_sub = g[sub] - g[0]
    for drift in np.arange(-n_drift, n_drift + 1) * step_ppm:
        r = (e[sub] - drift * 1e-6 * t_sub)[:, None] - rows_sub
        count, offset = _peaks(r.ravel(), tol, 1)[0]
        if count > best[0] or (count == best[0] and abs(drift) < abs(best[1])):
            best = (count, float(drift), offset)
    _, drift, offset = best
    # refine on the frames the guess explains: a straight line through their residuals, and
    # the tolerance from their scatter; repeated, as a tolerance narrower than the jitter
    # keeps only the frames that happen to stamp near the line
    rows = np.arange(e.size)
    t = g - g[0]
    # beyond a quarter of a frame gap the rows cannot be told apart: no clock
    cap = 0.25 * float(np.median(np.diff(g))) if g.size > 1 else math.inf
    for _ in range(_REFINE_ROUNDS):
        res = _residuals(e, g, offset, drift, max_lag)
        lag, fits = _lags(res, tol, max_lag)
        if np.count_nonzero(fits) < 3:
            break
        r = res[rows, lag + max_lag][fits]
        slope, icpt = np.polyfit(t[fits], r, 1)
        drift += slope * 1e6
        offset += icpt
        r = r - (slope * t[fits] + icpt)
        sigma = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        wider = max(_JITTER_SIGMAS * sigma, 2.0 * resolution_s, _TOL_MIN_S)
        if abs(wider - tol) <= 0.05 * tol:
            tol = wider
            break
        tol = wider
    if tol > cap or abs(drift) > max_drift_ppm:
        return ClockFit(offset, drift, tol, 0, timed, False, reliable=False)
    candidates = []
    for _, centre in _peaks(_residuals(e, g, offset, drift, max_lag).ravel(), tol,
                            2 * max_lag + 1):  # fmt: skip
        lag, fits = _lags(_residuals(e, g, offset + centre, drift, max_lag), tol, max_lag)
        candidates.append((int(np.count_nonzero(fits)), offset + centre, lag, fits))
    top = max(c[0] for c in candidates)
    near_tie = [c for c in candidates if c[0] >= top - max(3, 0.02 * timed)]
    in_step = [c for c in near_tie if np.count_nonzero(c[3] & (c[2] == 0)) > 0]
    timed_idx = np.flatnonzero(np.isfinite(e))

    def lead_in_step(c: tuple[int, float, NDArray, NDArray]) -> int:
        """How many of the first timed frames (up to 5) sit on their own rows: a clock a gap
        off leaves a speed-up's frames on no row, so its first *fitted* frames would."""
        ok = c[3][timed_idx] & (c[2][timed_idx] == 0)
        return min(int(np.argmin(ok)) if not ok.all() else ok.size, 5)

    chosen = max(near_tie, key=lambda c: (lead_in_step(c),
                                          np.count_nonzero(c[3] & (c[2] == 0)), c[0]))  # fmt: skip
    zero = chosen[3] & (chosen[2] == 0)
    ambiguous = any(
        c is not chosen and not np.array_equal(c[3] & (c[2] == 0), zero) for c in in_step
    )
    return ClockFit(chosen[1], drift, tol, chosen[0], timed, ambiguous)


def check_rows(
    image_s: ArrayLike, gps_s: ArrayLike, fit: ClockFit, max_lag: int = MAX_LAG
) -> RowCheck:
    """The row each image's capture time belongs to, under a camera's clock.

    Parameters
    ----------
    image_s, gps_s : array_like, shape (n,)
        As :func:`fit_clock`.
    fit : ClockFit
        The camera's clock.
    max_lag : int
        Largest row offset tried either way.

    Returns
    -------
    RowCheck
    """
    e, g = np.asarray(image_s, float), np.asarray(gps_s, float)
    if e.shape != g.shape or e.ndim != 1:
        raise ValueError(f"image_s and gps_s must be 1-D of one length, got {e.shape} and "
                         f"{g.shape}")  # fmt: skip
    res = _residuals(e, g, fit.offset_s, fit.drift_ppm, max_lag)
    lag, fits = _lags(res, fit.tol_s, max_lag)
    gaps = np.diff(g)
    nearest = np.minimum(np.concatenate([[np.inf], gaps]), np.concatenate([gaps, [np.inf]]))
    checked = np.isfinite(e) & (nearest > 2.0 * fit.tol_s)
    return RowCheck(checked, np.where(checked, lag, 0), fits & checked)


def read_capture_time_s(
    path: Location, storage_options: StorageOptions | None = None
) -> tuple[float, float]:
    """:func:`capture_time_s` of an image file, read from its first ``HEADER_BYTES`` (NaN,
    NaN when the file cannot be opened: the loader and the segmentation report that)."""
    head_bytes: int | None = HEADER_BYTES
    for _ in range(2):  # the whole file when the header runs past the head (ICC profiles)
        data = b""
        try:
            data = read_bytes(path, storage_options, head_bytes=head_bytes)
            with Image.open(io.BytesIO(data)) as im:  # parses the markers before the pixels
                return capture_time_s(im)
        except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError):
            if head_bytes is None or len(data) < head_bytes:
                break
            head_bytes = None
    return math.nan, math.nan
