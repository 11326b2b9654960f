"""Availability of trusted satellites along a line over a time window.

:func:`compute_availability` counts, for every position of a line and every epoch, the
satellites a train may trust (ephemeris status ``OK`` and the
:class:`~predisat.availability.satellites.
TrustRule`: mask plus margin, flat cut-off, or horizon), and predicts the SATHIA confidence
interval (:mod:`predisat.availability.interval`). :class:`Availability` holds the result and
derives the
figures of a report: shares of time with >= 2, >= 4, >= 6 satellites per position and over the
line, the longest stretches below 4 satellites (in metres at one epoch, in seconds at one
position), interval statistics and the cross-track opening angle, with CSV, Parquet and GeoJSON
writers.

The dense problem, ``(n_pos, n_epoch, n_sat)`` (line 144 for a day at 30 s with every
constellation: 1 400 x 2 880 x 110), is never materialised. Satellite positions depend on the
epoch only; each chunk of positions turns them into local east/north/up components with three
small matrix products in float32 (coordinates taken relative to the line's centre, so float32
keeps elevations to about 1e-5 deg), compares ``up`` with ``sin(threshold) * range`` instead of
computing elevations, and reduces to counts on the fly. Satellite-epoch pairs that are below the
lowest threshold everywhere on the line (checked at the line's centre with a bound on how much
a direction can change across the line) are dropped first. Blocks of consecutive positions are
the tasks (:func:`block_task`), run by a :class:`~predisat.scheduler.TaskRunner`: in this
process, in threads (numpy releases the GIL in these operations), or on a Dask cluster; each
block cuts its positions into the same chunks as a serial run, so the results are the same
bits wherever they ran. With a :class:`BlockCheckpoint` every finished block is saved (as it
arrives, in this process) and a rerun loads the blocks whose inputs are unchanged instead of
computing them again: a killed run resumes. See ``docs/availability.md``,
``docs/cluster.md`` and ``scripts/bench_availability.py``.
"""

from __future__ import annotations

import hashlib
import io
import json
import sys
import time
import zipfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from tqdm import tqdm

from predisat.availability.interval import DEFAULT_MAP_DOUBT, MapDoubt, predicted_interval
from predisat.availability.satellites import LinePositions, SatellitePositions, TrustRule, azel
from predisat.geodesy import ecef_to_geodetic, enu_rotation, unwrap_lon_deg, wrap_lon_deg
from predisat.gnss.errormodel import IntervalModel
from predisat.gnss.integrity import DEFAULT_BUDGET, IntegrityBudget
from predisat.gnss.timescale import gps_s_to_utc_text
from predisat.jsontypes import JsonDict
from predisat.readonly import freeze_array_fields
from predisat.scheduler import Scheduler, TaskRunner
from predisat.storage import (
    Location,
    StorageOptions,
    exists,
    join,
    npz_bytes,
    read_bytes,
    remove_tree,
    write_atomic,
)
from predisat.track import TrackMap

__all__ = [
    "CHECKPOINT_BLOCK_CHUNKS",
    "THRESHOLDS",
    "Availability",
    "BlockCheckpoint",
    "block_task",
    "compute_availability",
    "longest_run",
    "reference_counts",
    "write_counts",
]

THRESHOLDS = (2, 4, 6)
"""Satellite counts whose shares of time are reported (>= 2, >= 4, >= 6)."""

CHECKPOINT_BLOCK_CHUNKS = 32
"""Chunks per block (64 positions) when blocks are saved (:class:`BlockCheckpoint`): the
same blocks on every scheduler, so that a run resumes on another."""

_EARTH_RADIUS_M = 6.371e6
_MIN_SAT_RANGE_M = 1.9e7  # a GNSS satellite (MEO/GEO) above the horizon is at least this far


# --------------------------------------------------------------------------- result
@dataclass(frozen=True)
class Availability:
    """Trusted satellites along a line over a time window.

    Attributes
    ----------
    positions : LinePositions
        ``n_pos`` antenna positions.
    gps_s : ndarray, shape (n_epoch,)
    sats : tuple of str
        The satellites considered (after constellation selection).
    rule : str
        The trust rule's label (``"masks"``, ``"cutoff 15 deg"``, ``"no mask"``).
    count : ndarray of uint8, shape (n_pos, n_epoch)
        Number of trusted satellites.
    interval_m : ndarray of float32, shape (n_pos, n_interval), or None
        Predicted SATHIA interval length at the epochs :attr:`interval_gps_s` (every
        ``interval_every``-th epoch; NaN with < 2 satellites), when computed.
    sensitivity : ndarray of float32, shape (n_pos, n_interval), or None
        Along-track geometry of the best pair at the same epochs: ``max |g_i - g_j|`` over
        trusted pairs, where ``g = u . t`` (unit vector to the satellite dotted with the track
        tangent); metres of range difference per metre of chainage, in [0, 2]. NaN with < 2
        satellites.
    opening_angle_deg : ndarray, shape (n_pos,)
        Cross-track opening angle: 180 deg minus the left and right mask elevations.
    provenance : dict
        Sources, options and timings.
    interval_every : int
        The intervals are predicted at every ``interval_every``-th epoch, from the first
        (``n_interval = ceil(n_epoch / interval_every)``): only those are stored, so that a
        line-day's result holds about 1 + 8 / ``interval_every`` bytes per (position, epoch).

    Notes
    -----
    The reductions a report asks for several times (:meth:`summary`, :meth:`position_table`)
    are computed once per result, and every reduction over the (n_pos, n_epoch) grid runs
    over blocks of positions or epochs, so that no temporary the size of the grid is made
    (``docs/availability.md``, "Memory").
    """

    positions: LinePositions
    gps_s: NDArray
    sats: tuple[str, ...]
    rule: str
    count: NDArray
    interval_m: NDArray | None
    sensitivity: NDArray | None
    opening_angle_deg: NDArray
    provenance: JsonDict = field(default_factory=dict)
    interval_every: int = 1

    def __post_init__(self) -> None:
        if self.interval_every < 1:
            raise ValueError(f"interval_every must be >= 1, got {self.interval_every}")
        n_iv = -(-len(self.gps_s) // self.interval_every)
        for name in ("interval_m", "sensitivity"):
            arr = getattr(self, name)
            if arr is not None and np.shape(arr) != (np.shape(self.count)[0], n_iv):
                raise ValueError(
                    f"{name} has shape {np.shape(arr)}, expected (n_pos, ceil(n_epoch / "
                    f"interval_every)) = ({np.shape(self.count)[0]}, {n_iv}): store the "
                    "intervals at the predicted epochs only"
                )
        freeze_array_fields(self)

    @property
    def interval_gps_s(self) -> NDArray:
        """Epochs of :attr:`interval_m` (every ``interval_every``-th), (n_interval,)."""
        return self.gps_s[:: self.interval_every]

    @property
    def interval_count(self) -> NDArray:
        """``count`` at the epochs of :attr:`interval_m`, (n_pos, n_interval) (a view)."""
        return self.count[:, :: self.interval_every]

    @property
    def chainage_m(self) -> NDArray:
        return self.positions.chainage_m

    @property
    def step_s(self) -> float:
        """Epoch spacing (median), seconds."""
        return float(np.median(np.diff(self.gps_s))) if len(self.gps_s) > 1 else 0.0

    @property
    def cell_length_m(self) -> NDArray:
        """Length of line each position stands for (half-way to its neighbours), (n_pos,)."""
        return _cell_extent(self.chainage_m)[1] - _cell_extent(self.chainage_m)[0]

    # ------------------------------------------------------------------ shares
    def share_at_least(self, n: int) -> NDArray:
        """Share of epochs with at least ``n`` trusted satellites, per position, (n_pos,)."""
        n_ep = self.count.shape[1]
        return _per_row(self.count, lambda c: np.count_nonzero(c >= n, axis=1) / max(n_ep, 1))

    def line_share_at_least(self, n: int) -> float:
        """Share of (place, time) with >= ``n`` satellites over the line (length-weighted)."""
        w = self.cell_length_m
        return float(np.sum(self.share_at_least(n) * w) / np.sum(w))

    # ------------------------------------------------------------------ stretches
    def longest_below_m(self, n: int = 4) -> NDArray:
        """Longest contiguous chainage run with fewer than ``n`` satellites, per epoch, metres.

        A run of positions stands for their cells (half-way to the neighbours), shape
        (n_epoch,).
        """
        lo, hi = _cell_extent(self.chainage_m)
        # blocks of epochs: the runs go along positions
        return _per_row(self.count.T, lambda c: longest_run(c < n, lo, hi))

    def longest_below_s(self, n: int = 4) -> NDArray:
        """Longest contiguous time run with fewer than ``n`` satellites, per position, seconds.

        Each epoch stands for one step (shape (n_pos,)).
        """
        t = self.gps_s
        half = self.step_s / 2.0
        return _per_row(self.count, lambda c: longest_run(c < n, t - half, t + half))

    # ------------------------------------------------------------------ interval
    def interval_quantiles(self, q: tuple[float, ...] = (0.5, 0.95), min_count: int = 4) -> NDArray:
        """Quantiles of the interval length per position over epochs with >= ``min_count``.

        Returns
        -------
        ndarray, shape (n_pos, len(q)), metres (NaN where no such epoch)
        """
        out = np.full((len(self.chainage_m), len(q)), np.nan)
        if self.interval_m is None:
            return out
        iv, cnt = self.interval_m, self.interval_count
        for a, b in _row_slices(iv.shape):
            x = np.where(cnt[a:b] >= min_count, iv[a:b], np.nan).astype(float)
            has = np.any(np.isfinite(x), axis=1)
            if np.any(has):
                out[a:b][has] = np.nanquantile(x[has], q, axis=1).T
        return out

    # ------------------------------------------------------------------ tables
    def summary(self) -> JsonDict:
        """Line-wide figures (JSON-serialisable; a new dict at each call)."""
        return dict(self._summary)

    @cached_property
    def _summary(self) -> JsonDict:
        by_epoch = self.longest_below_m(4)
        by_pos = self.longest_below_s(4)
        e, p = int(np.argmax(by_epoch)), int(np.argmax(by_pos))
        out: JsonDict = {
            "rule": self.rule,
            "n_pos": len(self.chainage_m),
            "n_epoch": len(self.gps_s),
            "n_sat": len(self.sats),
            "line_length_m": float(np.sum(self.cell_length_m)),
            "step_s": self.step_s,
        }
        for n in THRESHOLDS:
            out[f"share_ge{n}"] = self.line_share_at_least(n)
        out["mean_count"] = float(self.count.mean())
        out["longest_below4_m"] = float(by_epoch[e])
        out["longest_below4_m_at_gps_s"] = float(self.gps_s[e])
        out["longest_below4_m_at_utc"] = gps_s_to_utc_text(float(self.gps_s[e]))
        out["longest_below4_s"] = float(by_pos[p])
        out["longest_below4_s_at_chainage_m"] = float(self.chainage_m[p])
        out["opening_angle_median_deg"] = float(np.median(self.opening_angle_deg))
        if self.interval_m is not None:
            x = self.interval_m[self.interval_count >= 4]
            x = x[np.isfinite(x)]
            out["interval_median_m"] = float(np.median(x)) if len(x) else float("nan")
            out["interval_p95_m"] = float(np.quantile(x, 0.95)) if len(x) else float("nan")
        return out

    def position_table(self) -> pd.DataFrame:
        """One row per position: place, shares, longest time below 4, interval, opening.

        A new frame at each call (the columns are computed once per result).
        """
        return self._position_table.copy()

    @cached_property
    def _position_table(self) -> pd.DataFrame:
        pos = self.positions
        df = pd.DataFrame(
            {
                "chainage_m": pos.chainage_m,
                "lat_deg": pos.lat_deg,
                "lon_deg": pos.lon_deg,
                "h_m": pos.h_m,
                "heading_deg": pos.heading_deg,
            }
        )
        for n in THRESHOLDS:
            df[f"share_ge{n}"] = self.share_at_least(n)
        df["mean_count"] = _per_row(self.count, lambda c: c.mean(axis=1))
        df["min_count"] = self.count.min(axis=1)
        df["longest_below4_s"] = self.longest_below_s(4)
        q = self.interval_quantiles()
        df["interval_median_m"] = q[:, 0]
        df["interval_p95_m"] = q[:, 1]
        df["opening_angle_deg"] = self.opening_angle_deg
        return df

    def epoch_table(self) -> pd.DataFrame:
        """One row per epoch: line-wide shares and the longest stretch below 4 (metres)."""
        w = self.cell_length_m
        df = pd.DataFrame({"gps_s": self.gps_s})
        for n in THRESHOLDS:
            # length with >= n per epoch, summed position after position as the whole-grid
            # np.sum(axis=0) does: the same bits, block by block
            covered = np.zeros(len(self.gps_s))
            for a, b in _row_slices(self.count.shape):
                part = (self.count[a:b] >= n) * w[a:b, None]
                covered = np.add.reduce(np.concatenate([covered[None], part]), axis=0)
            df[f"share_ge{n}"] = covered / np.sum(w)
        df["min_count"] = self.count.min(axis=0)
        df["longest_below4_m"] = self.longest_below_m(4)
        return df

    def to_csv(self, path: str | Path) -> Path:
        """Write :meth:`position_table` as CSV (``.csv``); returns the path."""
        path = Path(path)
        self.position_table().to_csv(path, index=False, float_format="%.12g")
        return path

    def to_parquet(self, path: str | Path, counts: bool = False) -> Path:
        """Write :meth:`position_table` as Parquet, with the summary in the file metadata.

        With ``counts=True`` the file holds the full ``count`` array instead, long format
        (:func:`write_counts`: ``rule, chainage_m, gps_s, count``; before the line-day memory
        work it had no ``rule`` column and pandas metadata).
        """
        # lazy: pyarrow only for this writer, not for the engine's computations
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = Path(path)
        info = {b"predisat.availability.engine": json.dumps(
            {"summary": self.summary(), "provenance": _jsonable(self.provenance)}
        ).encode()}  # fmt: skip
        if counts:
            return write_counts(path, [self], info)
        table = pa.Table.from_pandas(self.position_table(), preserve_index=False)
        meta = dict(table.schema.metadata or {}) | info
        pq.write_table(table.replace_schema_metadata(meta), path)
        return path

    def to_geojson_lines(
        self, track: TrackMap | None = None, path: str | Path | None = None
    ) -> JsonDict:
        """The line cut into one segment per position, coloured by availability (for QGIS).

        Each LineString covers the position's cell (half-way to its neighbours), following the
        ``track`` (a :class:`~predisat.track.map.TrackMap`) when given, else straight between the
        positions. Properties: the :meth:`position_table` columns plus ``class`` ("ge6",
        "ge4", "ge2", "lt2": the highest count available at least 95 % of the time).
        """
        df = self.position_table()
        lo, hi = _cell_extent(self.chainage_m)
        feats = []
        for i, row in enumerate(df.to_dict("records")):
            s = np.linspace(lo[i], hi[i], 5)
            if track is not None:
                lat, lon, _ = track.position_at(s)
            else:
                lat = np.interp(s, self.chainage_m, self.positions.lat_deg)
                lon = wrap_lon_deg(np.interp(s, self.chainage_m,
                                             unwrap_lon_deg(self.positions.lon_deg)))
            props = {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                     for k, v in row.items()}  # fmt: skip
            props["class"] = _class_of(row)
            feats.append(
                {
                    "type": "Feature",
                    "geometry": {
                        "type": "LineString",
                        "coordinates": [
                            [float(a), float(b)] for a, b in zip(lon, lat, strict=True)
                        ],
                    },
                    "properties": _jsonable(props),
                }
            )
        fc = {"type": "FeatureCollection", "features": feats}
        if path is not None:
            Path(path).write_text(json.dumps(fc))
        return fc


_BLOCK_CELLS = 1 << 22
"""Cells of the (n_pos, n_epoch) grid a reduction takes at once: its temporaries stay at a
few tens of MB, whatever the line and the day."""


def _row_slices(shape: tuple[int, ...]) -> list[tuple[int, int]]:
    """Slices of whole rows of an array of ``shape`` holding about :data:`_BLOCK_CELLS`."""
    n_rows = shape[0]
    per = max(1, _BLOCK_CELLS // max(int(np.prod(shape[1:])), 1))
    return [(a, min(a + per, n_rows)) for a in range(0, n_rows, per)]


def _per_row(arr: NDArray, fn: Callable[[NDArray], NDArray]) -> NDArray:
    """``fn`` of blocks of whole rows of ``arr`` (about :data:`_BLOCK_CELLS` cells each; ``fn``
    gives one value per row), joined: the per-row reduction without a grid-sized temporary."""
    parts = [fn(arr[a:b]) for a, b in _row_slices(arr.shape)]
    return np.concatenate(parts) if parts else np.zeros(0)


_COUNTS_ROWS = 1 << 20
"""Rows of ``counts.parquet`` built at once (about 25 MB with Arrow's copy): the long table
of a line-day is written in pieces, never held whole."""


def write_counts(
    path: str | Path, results: Sequence[Availability], metadata: Mapping[bytes, bytes] | None = None
) -> Path:
    """Write every count of every rule as one long table (``counts.parquet``).

    Columns ``rule`` (dictionary-encoded), ``chainage_m``, ``gps_s``, ``count``: one row per
    (rule, position, epoch), positions in order and epochs in order within each. Written in
    row groups of whole positions (:data:`_COUNTS_ROWS` rows), so that memory stays at a few
    tens of MB whatever the line and the day.

    Parameters
    ----------
    path : Path
        The file to write.
    results : sequence of Availability
        One per rule, on the same positions and epochs.
    metadata : mapping of bytes to bytes, optional
        Key-value metadata of the file's schema.

    Returns
    -------
    Path
    """
    # lazy: pyarrow only for the writers, not for the engine's computations
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pa.schema([
        ("rule", pa.dictionary(pa.int32(), pa.string())), ("chainage_m", pa.float64()),
        ("gps_s", pa.float64()), ("count", pa.uint8()),
    ], metadata=dict(metadata or {}))  # fmt: skip
    path = Path(path)
    with pq.ParquetWriter(path, schema) as writer:
        for r in results:
            n_pos, n_ep = r.count.shape
            per = max(1, _COUNTS_ROWS // max(n_ep, 1))
            label = pa.array([r.rule], pa.string())
            for a in range(0, n_pos, per):
                b = min(a + per, n_pos)
                rows = (b - a) * n_ep
                writer.write_table(pa.table({
                    "rule": pa.DictionaryArray.from_arrays(
                        pa.array(np.zeros(rows, np.int32)), label),
                    "chainage_m": np.repeat(r.chainage_m[a:b], n_ep),
                    "gps_s": np.tile(r.gps_s, b - a),
                    "count": r.count[a:b].ravel(),
                }, schema=schema))  # fmt: skip
    return path


def _class_of(row: dict) -> str:
    for n in (6, 4, 2):
        if row[f"share_ge{n}"] >= 0.95:
            return f"ge{n}"
    return "lt2"


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x


def _cell_extent(chainage_m: NDArray) -> tuple[NDArray, NDArray]:
    """Cell bounds of positions: half-way to each neighbour, half a spacing at the ends."""
    s = np.asarray(chainage_m, float)
    if len(s) == 1:
        return s.copy(), s.copy()
    mid = (s[1:] + s[:-1]) / 2.0
    lo = np.concatenate([[s[0] - (mid[0] - s[0])], mid])
    hi = np.concatenate([mid, [s[-1] + (s[-1] - mid[-1])]])
    return lo, hi


def longest_run(flag: NDArray, lo: NDArray, hi: NDArray) -> NDArray:
    """Longest contiguous run of True along the last axis, measured with cell bounds.

    Parameters
    ----------
    flag : ndarray of bool, shape (..., n)
    lo, hi : ndarray, shape (n,)
        Bounds of each cell (consecutive cells are assumed contiguous).

    Returns
    -------
    ndarray, shape (...)
        ``hi[last] - lo[first]`` of the longest run (0 where none).
    """
    f = np.asarray(flag, bool)
    n = f.shape[-1]
    f2 = f.reshape(-1, n)
    pad = np.zeros((len(f2), 1), bool)
    d = np.diff(np.concatenate([pad, f2, pad], axis=1).astype(np.int8), axis=1)
    out = np.zeros(len(f2))
    r_start, c_start = np.nonzero(d == 1)
    _r_end, c_end = np.nonzero(d == -1)  # same order: runs are nested row-major
    if len(r_start):
        length = np.asarray(hi)[c_end - 1] - np.asarray(lo)[c_start]
        np.maximum.at(out, r_start, length)
    return out.reshape(f.shape[:-1])


# --------------------------------------------------------------------------- engine
def compute_availability(
    satellites: SatellitePositions,
    positions: LinePositions,
    rule: TrustRule,
    *,
    interval_model: IntervalModel | None = None,
    integrity: IntegrityBudget | None = DEFAULT_BUDGET,
    map_doubt: MapDoubt | None = DEFAULT_MAP_DOUBT,
    with_interval: bool = True,
    interval_every: int = 1,
    chunk_positions: int = 2,
    workers: int = 1,
    progress: bool = False,
    runner: TaskRunner | None = None,
    checkpoint: BlockCheckpoint | None = None,
) -> Availability:
    """Trusted satellites at every (position, epoch), with interval predictions.

    Parameters
    ----------
    satellites : SatellitePositions
        Satellite ECEF positions over the window (NaN where the ephemeris does not trust).
    positions : LinePositions
        Antenna positions (``LinePositions.from_masks(masks)`` for the mask positions).
    rule : TrustRule
    interval_model : IntervalModel, optional
        Default :class:`~predisat.availability.interval.IntervalModel()`.
    integrity : IntegrityBudget or None
        Each interval mode's ``k`` follows from it
        (:func:`predisat.availability.interval.mode_k_sigma`) and ``interval_model.k_sigma``
        is not used; default :data:`predisat.gnss.integrity.DEFAULT_BUDGET`. None:
        ``interval_model.k_sigma`` in every mode.
    map_doubt : MapDoubt or None
        Widen each predicted pair by how far the antenna may be from the map, as the locator
        does (:class:`~predisat.availability.interval.MapDoubt`). Default the locator's
        (:data:`~predisat.availability.interval.DEFAULT_MAP_DOUBT`); None: the source's pairs.
    with_interval : bool
        Also predict interval lengths and pair geometry.
    interval_every : int
        Predict the interval at every ``interval_every``-th epoch only (the only ones stored:
        :attr:`Availability.interval_gps_s`); the interval is the costly part, and its
        statistics need fewer epochs than the counts.
    chunk_positions : int
        Positions per chunk; memory is about ``chunk_positions * n_epoch * n_visible * 60``
        bytes (2 positions, a day at 30 s, 40 candidates: 14 MB per worker). Small chunks
        keep the work in the CPU cache (2 was fastest; 4-16 ran 2-3x slower). Use an even
        number: ``g`` is a float32 BLAS product whose last bit can depend on the chunk's
        parity (``docs/availability.md``).
    workers : int
        Threads in this process (when no ``runner`` is given).
    progress : bool
        Show a tqdm bar.
    runner : predisat.scheduler.TaskRunner, optional
        Where the blocks of positions run (a Dask cluster, for instance); default this
        process with ``workers`` threads.
    checkpoint : BlockCheckpoint, optional
        Save every finished block there, and take the blocks saved by an earlier run with
        the same inputs instead of computing them (blocks of
        :data:`CHECKPOINT_BLOCK_CHUNKS` chunks, whatever the scheduler). The result is the
        same bits either way.

    Returns
    -------
    Availability
    """
    if chunk_positions < 1 or workers < 1 or interval_every < 1:
        raise ValueError("chunk_positions, workers and interval_every must be >= 1")
    if rule.mode == "mask" and len(rule.masks.az_deg) * float(rule.masks.az_step_deg) != 360.0:
        raise ValueError("masks: n_az * az_step_deg must be 360 (the bins must cover the circle)")
    model = interval_model or IntervalModel()
    t_start = time.perf_counter()
    n_pos, n_ep = positions.n_pos, len(satellites.gps_s)

    rx = positions.ecef_m
    centre = rx.mean(axis=0)
    thr_table = rule.threshold_table(positions.chainage_m)  # (n_pos, n_az)
    cand, cand_sat = _candidates(satellites, rx, centre, float(np.min(thr_table)))
    m = cand.shape[1]
    s32 = (cand.reshape(-1, 3) - centre).astype(np.float32).T.copy()  # (3, n_ep * m)

    count = np.zeros((n_pos, n_ep), np.uint8)
    n_iv = -(-n_ep // interval_every)
    interval = np.full((n_pos, n_iv), np.nan, np.float32) if with_interval else None
    sens = np.full((n_pos, n_iv), np.nan, np.float32) if with_interval else None
    rot = positions.enu_rotation
    tan_ecef = np.einsum("pi,pij->pj", positions.tangent_enu, rot)  # t_enu @ R
    # thresholds at or above 90 deg (or +inf: no coverage) can never be passed: u <= range
    sin_thr = np.where(
        thr_table < 90.0, np.sin(np.radians(np.minimum(thr_table, 90.0))), 2.0
    ).astype(np.float32)
    bin_scale = 0.0
    if sin_thr.shape[1] > 1:
        step = float(rule.masks.az_step_deg)
        bin_scale = float(np.degrees(1.0) / step)
        sin_thr = np.concatenate([sin_thr, sin_thr[:, :1]], axis=1)  # 360 deg wraps to bin 0

    width = model.k_sigma if integrity is None else integrity
    doubt = None if map_doubt is None or map_doubt.is_zero else map_doubt
    shared = _BlockShared(s32, bin_scale, n_ep, m, model if with_interval else None, width,
                          interval_every, chunk_positions, doubt)  # fmt: skip
    own = runner is None
    run_on = TaskRunner(Scheduler.serial(workers)) if runner is None else runner
    blocks = _blocks(n_pos, chunk_positions, run_on, checkpoint is not None)
    items = [
        _Block(a, b, rx[a:b] - centre, rot[a:b], tan_ecef[a:b], sin_thr[a:b]) for a, b in blocks
    ]
    keys: dict[int, str] = {}
    todo = items
    if checkpoint is not None:
        base = _shared_key(shared)
        keys = {it.a: _block_key(base, it) for it in items}
        todo = []
        for it in items:
            saved = checkpoint.load(it.a, it.b, keys[it.a], n_ep, n_iv if with_interval else None)
            if saved is None:
                todo.append(it)
                continue
            count[it.a : it.b] = saved[0]
            if interval is not None and sens is not None:
                interval[it.a : it.b], sens[it.a : it.b] = saved[1], saved[2]
    if progress and len(todo) < len(items):
        print(f"availability{', ' + rule.label if rule.label else ''}: "
              f"{len(items) - len(todo)} of {len(items)} blocks resumed from the checkpoint, "
              f"{len(todo)} to compute", file=sys.stderr)  # fmt: skip
    bar = _progress(n_pos, progress, rule.label)
    bar.update(sum(it.b - it.a for it in items) - sum(it.b - it.a for it in todo))
    try:
        for a, b, c, iv, se in run_on.map_unordered(block_task, shared, todo, "availability"):
            count[a:b] = c
            if interval is not None and sens is not None:
                interval[a:b], sens[a:b] = iv, se
            if checkpoint is not None:
                checkpoint.save(a, b, keys[a], c, iv, se)
            bar.update(b - a)
    finally:
        bar.close()
        if own:
            run_on.close()

    prov = {
        "n_candidates_per_epoch": m,
        "candidate_share": float(np.mean(cand_sat >= 0)) * m / max(len(satellites.sats), 1),
        "chunk_positions": chunk_positions,
        "blocks": len(items),
        "blocks_resumed": len(items) - len(todo),
        "workers": workers if runner is None else run_on.scheduler.describe(),
        "interval_model": repr(model) if with_interval else None,
        "integrity": repr(integrity) if with_interval and integrity is not None else None,
        "map_doubt": repr(doubt) if with_interval and doubt is not None else None,
        "interval_every": interval_every,
        "elapsed_s": time.perf_counter() - t_start,
    }
    return Availability(
        positions, satellites.gps_s, satellites.sats, rule.label, count, interval, sens,
        rule.opening_angle_deg(n_pos), prov, interval_every,
    )  # fmt: skip


def _progress(total: int, on: bool, label: str = "") -> Any:
    desc = f"availability, {label}" if label else "availability"
    # a bar below the run's own one moves the cursor up: only on a terminal (redirected, it
    # leaves blank lines and escape codes in the log); a log gets a line every tenth
    if on and sys.stderr.isatty():
        return tqdm(total=total, desc=desc, unit="position", leave=False, file=sys.stderr)
    return _LogProgress(total, desc if on else "")


class _LogProgress:
    """Progress as plain lines in a log: one at every tenth of the positions (a user trial's
    batch log showed nothing for a whole rule, 4-5 minutes on a 160 km line). Silent without
    a ``desc``."""

    def __init__(self, total: int, desc: str) -> None:
        self.total, self.desc, self.done, self.tenth = total, desc, 0, 0
        self.t0 = time.perf_counter()

    def update(self, n: int) -> None:
        self.done += n
        tenth = (10 * self.done) // max(self.total, 1)
        # the last line too once a line was printed: a log ending on "64/71 positions (90 %)"
        # reads as a run that stopped short (a 71-position stretch, blocks of 64)
        if self.desc and tenth > self.tenth and (self.done < self.total or self.tenth > 0):
            self.tenth = tenth
            share = 100 * self.done // max(self.total, 1)
            took = time.perf_counter() - self.t0
            print(f"{self.desc}: {self.done}/{self.total} positions ({share} %, {took:.0f} s)",
                  file=sys.stderr, flush=True)  # fmt: skip

    def close(self) -> None:
        pass


def _candidates(
    sat: SatellitePositions, rx: NDArray, centre: NDArray, min_thr_deg: float
) -> tuple[NDArray, NDArray]:
    """Satellite positions that may be above a threshold somewhere, padded per epoch.

    Returns ``cand`` (n_epoch, m, 3) ECEF (padding: a point straight below the line's
    centre, never above any threshold) and ``cand_sat`` (n_epoch, m) satellite index (-1 pad).
    """
    lat_c, lon_c = _geodetic_of(centre)
    el_c = azel(centre, enu_rotation(lat_c, lon_c), sat.pos_ecef_m)[1]  # (n_ep, n_sat)
    # a direction's elevation changes by at most the tilt of the vertical plus the parallax
    d_max = float(np.max(np.linalg.norm(rx - centre, axis=1))) if len(rx) else 0.0
    slack = np.degrees(d_max / _EARTH_RADIUS_M + d_max / _MIN_SAT_RANGE_M) + 0.05
    keep = np.isfinite(el_c) & (el_c > min_thr_deg - slack)
    m = max(int(keep.sum(axis=1).max(initial=0)), 1)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :m]
    taken = np.take_along_axis(keep, order, axis=1)
    cand_sat = np.where(taken, order, -1)
    pos = np.take_along_axis(sat.pos_ecef_m, order[:, :, None], axis=1)
    below = centre - 3.0e7 * centre / np.linalg.norm(centre)
    cand = np.where(taken[:, :, None], pos, below)
    return cand, cand_sat


def _geodetic_of(xyz: NDArray) -> tuple[float, float]:
    lat, lon, _ = ecef_to_geodetic(xyz)
    return float(lat), float(lon)


@dataclass(frozen=True)
class _BlockShared:
    """What every block of positions needs: the candidates and the options."""

    s32: NDArray  # (3, n_ep * m) float32, relative to the line's centre
    bin_scale: float
    n_ep: int
    m: int
    model: IntervalModel | None
    width: float | IntegrityBudget  # k of every mode, or the budget giving each mode its k
    every: int
    chunk_positions: int
    map_doubt: MapDoubt | None = None  # None: the source's pairs


@dataclass(frozen=True)
class _Block:
    """Positions ``[a, b)`` of a line and their geometry (relative to the line's centre)."""

    a: int
    b: int
    rx_rel: NDArray
    rot: NDArray
    tan_ecef: NDArray
    sin_thr: NDArray


def _blocks(
    n_pos: int, chunk_positions: int, runner: TaskRunner, saved: bool = False
) -> list[tuple[int, int]]:
    """Blocks of positions, each a whole number of chunks (so that every block cuts its
    positions into the chunks of a serial run): one chunk in this process, at least 4 blocks
    per worker on a cluster; :data:`CHECKPOINT_BLOCK_CHUNKS` chunks everywhere when the blocks
    are ``saved`` (a run resumed on another scheduler finds the same blocks)."""
    per = chunk_positions
    if saved:
        per = chunk_positions * CHECKPOINT_BLOCK_CHUNKS
    elif runner.scheduler.kind != "serial":
        workers = max(runner.scheduler.workers, 4)
        n_chunks = -(-n_pos // chunk_positions)
        per = chunk_positions * max(1, min(256, n_chunks // (4 * workers)))
    return [(a, min(a + per, n_pos)) for a in range(0, n_pos, per)]


# the modules whose code decides a block's numbers: a block saved by other code is redone
_ENGINE_CODE = (
    "availability/engine.py", "availability/interval.py", "gnss/errormodel.py",
    "gnss/integrity.py",
)


def _code_key() -> bytes:
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for part in _ENGINE_CODE:
        h.update(part.encode() + b"\0" + (root / part).read_bytes())
    return h.digest()


def _shared_key(shared: _BlockShared) -> bytes:
    """Hash of what every block of a computation shares: code, candidates, options."""
    h = hashlib.sha256(_code_key())
    h.update(np.ascontiguousarray(shared.s32).tobytes())
    h.update(repr((shared.bin_scale, shared.n_ep, shared.m, shared.model, shared.width,
                   shared.every, shared.chunk_positions, shared.s32.shape,
                   shared.map_doubt)).encode())  # fmt: skip
    return h.digest()


def _block_key(base: bytes, block: _Block) -> str:
    """Hash of everything a block's numbers depend on (``base``: :func:`_shared_key`)."""
    h = hashlib.sha256(base)
    h.update(repr((block.a, block.b)).encode())
    for arr in (block.rx_rel, block.rot, block.tan_ecef, block.sin_thr):
        h.update(repr((arr.dtype.str, arr.shape)).encode())
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()[:32]


@dataclass(frozen=True)
class BlockCheckpoint:
    """The folder where the finished blocks of one availability computation are kept.

    Each block is a file ``<a>_<b>.npz`` (positions ``[a, b)``) holding its counts (and
    intervals, pair geometry at the predicted epochs) and the hash of its inputs (the engine's
    code, the candidate satellites, the options, the block's positions, geometry and
    thresholds); it is written atomically (:func:`predisat.storage.write_atomic`). A block is
    taken back only when its hash is the one of the computation asking for it; a torn or
    foreign file is computed again.

    Attributes
    ----------
    folder : Path or str
        A local folder or a URL (:mod:`predisat.storage`).
    storage_options : mapping
        Options of the URL's file system.
    """

    folder: Location
    storage_options: StorageOptions = field(default_factory=dict)

    def path(self, a: int, b: int) -> Location:
        """The file of the block of positions ``[a, b)``."""
        return join(self.folder, f"{a}_{b}.npz")

    def load(
        self, a: int, b: int, key: str, n_epoch: int, n_interval: int | None
    ) -> tuple[NDArray, NDArray | None, NDArray | None] | None:
        """The saved ``(count, interval_m, sensitivity)`` of a block, or None when absent,
        torn or made from other inputs.

        ``count`` is (b - a, n_epoch); the other two (b - a, n_interval), None when
        ``n_interval`` is None (no intervals asked for)."""
        with_interval = n_interval is not None
        loc, opts = self.path(a, b), self.storage_options
        if not exists(loc, opts):
            return None
        try:
            with np.load(io.BytesIO(read_bytes(loc, opts)), allow_pickle=False) as z:
                if str(z["key"]) != key:
                    return None
                count = np.asarray(z["count"])
                iv = np.asarray(z["interval_m"]) if with_interval else None
                se = np.asarray(z["sensitivity"]) if with_interval else None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
            return None
        if count.shape != (b - a, n_epoch) or count.dtype != np.uint8:
            return None
        for arr in (iv, se):
            if arr is not None and (arr.shape != (b - a, n_interval) or arr.dtype != np.float32):
                return None
        return count, iv, se

    def save(
        self, a: int, b: int, key: str, count: NDArray, interval_m: NDArray | None,
        sensitivity: NDArray | None,
    ) -> None:  # fmt: skip
        """Save a finished block (atomically)."""
        arrays: dict[str, NDArray] = {"key": np.array(key), "count": count}
        if interval_m is not None and sensitivity is not None:
            arrays |= {"interval_m": interval_m, "sensitivity": sensitivity}
        write_atomic(self.path(a, b), npz_bytes(arrays), self.storage_options)

    def clear(self) -> None:
        """Delete every saved block and the folder (once the run's outputs are written)."""
        remove_tree(self.folder, self.storage_options)


def block_task(
    shared: _BlockShared, block: _Block
) -> tuple[int, int, NDArray, NDArray | None, NDArray | None]:
    """Counts (and intervals, pair geometry) of a block of positions, chunk after chunk.

    Returns
    -------
    tuple
        ``(a, b, count, interval_m, sensitivity)``: ``count`` of shape (b - a, n_epoch), the
        others (b - a, n_interval), at every ``every``-th epoch.
    """
    parts = []
    for lo in range(0, block.b - block.a, shared.chunk_positions):
        sl = slice(lo, min(lo + shared.chunk_positions, block.b - block.a))
        parts.append(_chunk(
            shared.s32, block.rx_rel[sl], block.rot[sl], block.tan_ecef[sl], block.sin_thr[sl],
            shared.bin_scale, shared.n_ep, shared.m, shared.model, shared.width, shared.every,
            shared.map_doubt,
        ))  # fmt: skip
    count = np.concatenate([p[0] for p in parts])
    if shared.model is None:
        return block.a, block.b, count, None, None
    iv = np.concatenate([p[1] for p in parts if p[1] is not None])
    se = np.concatenate([p[2] for p in parts if p[2] is not None])
    return block.a, block.b, count, iv, se


def _chunk(
    s32: NDArray,
    rx_rel: NDArray,
    rot: NDArray,
    tan_ecef: NDArray,
    sin_thr: NDArray,
    bin_scale: float,
    n_ep: int,
    m: int,
    model: IntervalModel | None,
    width: float | IntegrityBudget,
    every: int,
    map_doubt: MapDoubt | None = None,
) -> tuple[NDArray, NDArray | None, NDArray | None]:
    p = len(rx_rel)
    enu = rot.astype(np.float32) @ s32  # (p, 3, K)
    enu -= np.einsum("pij,pj->pi", rot, rx_rel).astype(np.float32)[:, :, None]
    e, n, u = enu[:, 0], enu[:, 1], enu[:, 2]
    rng = e * e
    rng += n * n
    rng += u * u
    np.sqrt(rng, out=rng)
    if sin_thr.shape[1] == 1:
        trusted = u > sin_thr * rng
    else:
        # MaskSet bins: bin k covers [k - 1/2, k + 1/2) steps; sin_thr has bin 0 repeated last
        az = np.arctan2(e, n)
        az *= np.float32(bin_scale)
        az += np.float32(0.5)
        bins = np.floor(az, out=az).astype(np.int32)
        n_col = sin_thr.shape[1]
        bins += (bins < 0) * np.int32(n_col - 1)
        bins += (np.arange(p, dtype=np.int32) * np.int32(n_col))[:, None]  # flat index
        trusted = u > np.take(sin_thr.reshape(-1), bins) * rng
        del az, bins
    tr3 = trusted.reshape(p, n_ep, m)
    count = tr3.sum(axis=-1, dtype=np.uint8)
    if model is None:
        return count, None, None
    # interval at every `every`-th epoch
    tr_i = tr3[:, ::every]
    n_iv = tr_i.shape[1]
    s_i = s32.reshape(3, n_ep, m)[:, ::every].reshape(3, -1)
    rng_i = rng.reshape(p, n_ep, m)[:, ::every].reshape(p, -1)
    g = tan_ecef.astype(np.float32) @ s_i  # (p, K_iv)
    g -= np.einsum("pi,pi->p", tan_ecef, rx_rel).astype(np.float32)[:, None]
    g /= rng_i
    sin_el = u.reshape(p, n_ep, m)[:, ::every].reshape(p, -1) / rng_i
    sigma = model.error.sigma_from_sin(sin_el)
    g3 = g.reshape(p, n_iv, m)
    unit = None
    if map_doubt is not None:  # east, north, up of each candidate at the predicted epochs
        unit = np.stack([x.reshape(p, n_ep, m)[:, ::every] for x in (e, n, u)], axis=-1)
        unit /= rng_i.reshape(p, n_iv, m)[..., None]
    length, _ = predicted_interval(g3, sigma.reshape(p, n_iv, m), tr_i, width,
                                   unit_enu=unit, map_doubt=map_doubt)  # fmt: skip
    # max/min over the trusted: push the others out of [-1, 1] (adding 0 keeps g exact)
    pen = (~tr_i) * np.float32(4.0)
    gmax = (g3 - pen).max(axis=-1)
    gmin = (g3 + pen).min(axis=-1)
    sens = np.where(count[:, ::every] >= 2, gmax - gmin, np.nan).astype(np.float32)
    return count, np.asarray(length, np.float32), sens


# --------------------------------------------------------------------------- reference
def reference_counts(
    satellites: SatellitePositions, positions: LinePositions, rule: TrustRule
) -> NDArray:
    """Straightforward per-position count (float64 az/el, ``TrustRule.trusted``), (n_pos, n_ep).

    The independent check of the engine, used by the tests and the benchmark.
    """
    out = np.zeros((positions.n_pos, len(satellites.gps_s)), np.uint8)
    rot = positions.enu_rotation
    rx = positions.ecef_m
    for i in range(positions.n_pos):
        az, el = azel(rx[i], rot[i], satellites.pos_ecef_m)
        ok = rule.trusted(positions.chainage_m[i], az, el)
        out[i] = ok.sum(axis=-1)
    return out
