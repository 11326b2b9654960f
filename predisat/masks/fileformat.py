"""Mask file (GeoParquet, versions 1-3) reader and writer, and exporters to other tools' masks.

The mask file is a GeoParquet 1.1 file: one row per position, a WKB ``Point`` geometry column
(longitude, latitude; CRS ``OGC:CRS84``) so QGIS and geopandas open it as points along the
line, plain scalar columns, and the per-bin arrays as fixed-size list columns. The full
specification is ``docs/mask-format.md``.

Exporters (all conservative: a resampled value is the maximum of every bin its sample may
stand for, see ``docs/mask-format.md``):

* :func:`to_urbannav_csv` - UrbanNav-style sky-mask CSV, ``lat, lon, h`` then 361 elevations
  at azimuths 0, 1, ..., 360 deg, one row per position.
* :func:`to_rtklib_mask` - RTKLIB elevation mask file (``AZ EL`` lines) for one position.
* :func:`to_pvgis_horizon` - PVGIS horizon table or PVGIS "user horizon" upload file for one
  position.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import shapely
from numpy.typing import NDArray
from pyproj import CRS

from predisat.atomic import atomic_path
from predisat.jsontypes import JsonDict
from predisat.masks.binops import conservative_resample
from predisat.masks.gaps import close_gaps
from predisat.masks.maskset import REQUIRED_DESCRIPTORS, BinSource, MaskError, MaskSet

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "METADATA_KEY",
    "SPARSE_SPACING_M",
    "MaskFileError",
    "MaskFileWarning",
    "MaskHoleWarning",
    "MaskSpacingWarning",
    "MaskUnitWarning",
    "mask_file_path",
    "read_masks",
    "to_pvgis_horizon",
    "to_rtklib_mask",
    "to_urbannav_csv",
    "unfinished_run_error",
    "write_mask_table",
    "write_masks",
]

FORMAT_NAME = "predisat-masks"
FORMAT_VERSION = 3
"""The newest version: 2 adds source code 3 (``terrain``), 3 the per-bin ``support`` column
(independent views behind each bin). A file is written with the lowest version that holds
it: version 1 without terrain bins or support, 2 with terrain bins and no support, so that
older readers still read what they can."""
_READ_VERSIONS = (1, 2, 3)
_SUPPORT = "support"  # the version 3 column
METADATA_KEY = b"predisat"
"""Parquet file key-value metadata key holding the PREDISAT JSON header."""
GEOPARQUET_VERSION = "1.1.0"

_SCALARS = ("chainage_m", "lat_deg", "lon_deg", "h_m", "heading_deg")
_BINNED = {"mask_el_deg": pa.float32(), "source": pa.uint8(), "margin_deg": pa.float32()}
_DERIVED = ("opening_angle_deg", "assumed_bins")
_COLUMN_DOC = {
    "geometry": "WKB Point (lon_deg, lat_deg), OGC:CRS84",
    "chainage_m": "distance along the track axis from the track map origin, m",
    "lat_deg": "WGS84 latitude of the position, deg",
    "lon_deg": "WGS84 longitude of the position, deg",
    "h_m": "WGS84 ellipsoidal height of the position, m",
    "heading_deg": "azimuth of increasing chainage, deg clockwise from true north",
    "mask_el_deg": "skyline elevation per azimuth bin, deg in [0, 90]",
    "source": "per-bin origin: 0 observed, 1 reconstructed, 2 assumed, 3 terrain (version 2)",
    "support": "per-bin number of independent views behind the bound, 0 = rests on an "
    "assumption, weakly supported below 2 (version 3)",
    "margin_deg": "per-bin margin added to the mask before the trust test, deg >= 0",
    "opening_angle_deg": "derived, informative: 180 - effective mask left - right (cross-track)",
    "assumed_bins": "derived, informative: number of bins with source = 2 (assumed)",
}
_RTKLIB_STEP_DEG = 0.1  # RTKLIB stores the mask as int16 tenths of a degree, truncated
# Rounding up treats values within this of a step as on it: float32 storage puts 12.3 at
# 12.3000002, which must export as 12.3, not 12.4.
_ROUND_TOL_DEG = 1e-5


class MaskFileError(MaskError):
    """A mask file cannot be read or written; the message names the file, column and row."""


class MaskFileWarning(UserWarning):
    """Something read in a mask file that is allowed but suspicious; the report lists it."""


class MaskHoleWarning(MaskFileWarning):
    """A mask file has holes between its positions; they were closed on reading."""


class MaskUnitWarning(MaskFileWarning):
    """Every mask value of a file, or of some of its positions, is at most pi/2: radians
    written as degrees?"""


class MaskSpacingWarning(MaskFileWarning):
    """A mask file's positions lie farther apart than a survey's frames."""


SPARSE_SPACING_M = 25.0
"""Median spacing of positions (metres) beyond which a mask file is said to be sparse: a
survey's frames are 10 m apart, and each position stands for half the spacing either side."""


# ---------------------------------------------------------------------- GeoParquet
def write_masks(masks: MaskSet, path: str | os.PathLike[str]) -> Path:
    """Write a mask set as a mask file (GeoParquet; the lowest version that holds it), atomically.

    The file is written beside ``path`` under a temporary name and moved into place with
    :func:`os.replace`, so a crash never leaves a half-written mask file.

    Parameters
    ----------
    masks : MaskSet
    path : path-like
        Destination, conventionally ``*.masks.parquet``.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    n_az = masks.n_az
    points = shapely.points(masks.lon_deg, masks.lat_deg)
    cols: dict[str, pa.Array] = {
        "geometry": pa.array(shapely.to_wkb(points, byte_order=1), type=pa.binary()),
    }
    for name in _SCALARS:
        cols[name] = pa.array(getattr(masks, name), type=pa.float64())
    for name, typ in _BINNED.items():
        flat = pa.array(np.ascontiguousarray(getattr(masks, name)).ravel(), type=typ)
        cols[name] = pa.FixedSizeListArray.from_arrays(flat, n_az)
    for name, values in masks.descriptors.items():
        cols[name] = pa.array(values, type=pa.float64(), from_pandas=False)
    if masks.support is not None:
        flat = pa.array(np.ascontiguousarray(masks.support).ravel(), type=pa.uint8())
        cols[_SUPPORT] = pa.FixedSizeListArray.from_arrays(flat, n_az)
    cols["opening_angle_deg"] = pa.array(masks.opening_angle_deg(), type=pa.float64())
    cols["assumed_bins"] = pa.array(
        (masks.source == BinSource.ASSUMED).sum(axis=1).astype(np.int32), type=pa.int32()
    )

    header = {
        "format": FORMAT_NAME,
        "format_version": _version_for(masks),
        "az_step_deg": masks.az_step_deg,
        "n_az": n_az,
        "azimuth_bins": "bin k is centred on k * az_step_deg (deg clockwise from true north) "
        "and covers [centre - az_step_deg / 2, centre + az_step_deg / 2)",
        "source_codes": {str(int(s)): s.name.lower() for s in BinSource},
        "trust_rule": "trusted when elevation > mask_el_deg + margin_deg of the bin",
        "descriptors": list(masks.descriptors),
        "derived_columns": list(_DERIVED),
        "columns": {
            **{k: v for k, v in _COLUMN_DOC.items() if k != _SUPPORT or _SUPPORT in cols},
            **{d: "obstacle descriptor (NaN = none)" for d in masks.descriptors},
        },
        "provenance": masks.provenance,
    }
    geo = {
        "version": GEOPARQUET_VERSION,
        "primary_column": "geometry",
        "columns": {
            "geometry": {
                "encoding": "WKB",
                "geometry_types": ["Point"],
                "crs": _crs84_projjson(),
                "edges": "planar",
                "bbox": [
                    float(masks.lon_deg.min()),
                    float(masks.lat_deg.min()),
                    float(masks.lon_deg.max()),
                    float(masks.lat_deg.max()),
                ],
            }
        },
    }
    table = pa.table(cols).replace_schema_metadata(
        {METADATA_KEY: json.dumps(header, allow_nan=False), b"geo": json.dumps(geo)}
    )
    with _atomic(path, binary=True) as tmp:
        write_mask_table(table, tmp)
    return path


def write_mask_table(table: pa.Table, path: str | os.PathLike[str] | IO[Any]) -> None:
    """Write a mask table as Parquet with a CRC-32 on every data page, which
    :func:`read_masks` verifies: a mask file decides which satellites a train trusts, and a
    flipped bit in a data page could lower a mask silently (a user trial: 8 of 25 random
    single-bit flips lowered a bin, by up to 45 deg)."""
    pq.write_table(table, path, compression="zstd", write_page_checksum=True)


def _version_for(masks: MaskSet) -> int:
    """The lowest format version that holds ``masks``."""
    if masks.support is not None:
        return 3
    return 2 if (masks.source == BinSource.TERRAIN).any() else 1


def mask_file_path(path: str | os.PathLike[str]) -> Path:
    """``path`` itself, or ``path / "masks.parquet"`` when it is a folder (the output folder of
    ``predisat process``), which must then hold its run's record (``provenance.json``: else
    the run did not finish and the masks may be an earlier run's; :class:`MaskFileError`)."""
    p = Path(path)
    if not p.is_dir():
        return p
    if (p / "masks.parquet").is_file() and not (p / "provenance.json").is_file():
        raise unfinished_run_error(p)
    return p / "masks.parquet"


def unfinished_run_error(folder: object) -> MaskFileError:
    """The error for a process folder whose masks have no run record (local or a URL)."""
    return MaskFileError(_NO_RECORD.format(folder=folder))


_NO_RECORD = (
    "{folder}: masks.parquet without provenance.json: the `predisat process` run that writes "
    "them did not finish (interrupted, or stopped by an error), so the masks may be an "
    "earlier run's; rerun the same process command to finish it (or give the mask file "
    "itself if you know it is the one you want)"
)


def _check_record(folder: Path, record: Path, masks: MaskSet) -> None:
    """The folder's run record and its mask file name one run (``run_key``)."""
    try:
        key = json.loads(record.read_text(encoding="utf-8")).get("run_key")
    except (OSError, ValueError, AttributeError) as exc:
        raise MaskFileError(f"{record}: not a readable run record ({exc}); rerun the same "
                            "`predisat process` command to write it again") from None  # fmt: skip
    own = masks.provenance.get("run_key")
    if key and own and key != own:
        raise MaskFileError(
            f"{folder}: masks.parquet (run {own}) and provenance.json (run {key}) are of two "
            "runs: a run stopped between them; rerun the same `predisat process` command"
        )


def read_masks(path: str | os.PathLike[str], *, close_holes: bool = True) -> MaskSet:
    """Read and validate a mask file (version 1, 2 or 3).

    Checks the format name and version, the presence and types of every column, list lengths,
    nulls, value ranges, monotonic chainage, and that the geometry points agree with
    ``lat_deg`` / ``lon_deg``.

    A position's mask stands for the cell up to the midpoints to its neighbours, so a hole in
    the chainages (a file not written by ``predisat process``, which closes them, e.g. two
    surveys joined) would be covered by the positions either side. Such holes are closed with
    positions that trust nothing (:func:`predisat.masks.gaps.close_gaps`), with a warning.

    Parameters
    ----------
    path : path-like
        The mask file, or the output folder of ``predisat process`` (its ``masks.parquet``).
    close_holes : bool
        False reads the positions as they are (the batch run's chunks, closed after merging
        with the track's coordinates).

    Raises
    ------
    MaskFileError
        Naming the file, the column and the first bad row, and what would fix it.
    """
    given = Path(path)
    path = mask_file_path(given)  # a folder without its run's record: refused there
    if given.is_dir() and not path.is_file():
        unfinished = (given / "chunks").is_dir()  # a run stopped or still going (a user trial)
        raise MaskFileError(
            f"{given}: a folder without masks.parquet; give a mask file or the output "
            "folder of a finished `predisat process` run"
            + ("; this one holds chunks of a run that has not finished: rerun the same "
               "`predisat process` command to finish it" if unfinished else "")
        )  # fmt: skip
    record = given / "provenance.json" if given.is_dir() else None
    if not path.is_file():
        raise MaskFileError(
            f"{path}: no such mask file; give a mask file (written by `predisat process` "
            "or predisat.masks.fileformat.write_masks) or the output folder of `predisat process`"
        )
    try:
        # the pages' CRC-32 (files written before them have none, and read as before)
        table = pq.read_table(path, page_checksum_verification=True)
    except (pa.ArrowException, OSError) as exc:
        damaged = "CRC" in str(exc) or "checksum" in str(exc).lower()
        raise MaskFileError(
            f"{path}: "
            + ("damaged: a data page fails its checksum, so its values cannot be trusted "
               f"({exc}); copy the file again from its source, or rerun the process command"
               if damaged else
               f"not a readable Parquet file ({exc}); a mask file is the masks.parquet that "
               "`predisat process` writes (an interrupted copy is cut short: copy it again, "
               "or rerun the process command, which resumes)")
        ) from None
    header = _read_header(path, table.schema.metadata or {})
    n_az = header["n_az"]

    def fail(msg: str) -> MaskFileError:
        return MaskFileError(f"{path}: {msg}")

    try:
        names = set(table.column_names)
    except UnicodeDecodeError as exc:
        raise fail(
            f"a column name is not UTF-8 ({exc.reason} at byte {exc.start}): the file is "
            "damaged; copy it again, or rerun the process command"
        ) from None

    version = header["format_version"]
    binned = (*_BINNED, _SUPPORT) if version >= 3 else tuple(_BINNED)
    missing = [
        c for c in ("geometry", *_SCALARS, *binned, *header["descriptors"]) if c not in names
    ]
    if missing:
        raise fail(
            f"missing column(s) {missing}; the file was not written by predisat.masks.fileformat."
            "write_masks or a tool dropped columns - rewrite it from the MaskSet"
        )
    absent = [d for d in REQUIRED_DESCRIPTORS if d not in header["descriptors"]]
    if absent:
        raise fail(f"required descriptor column(s) {absent} are not listed in the header")

    arrays: dict[str, NDArray] = {}
    for name in _SCALARS:
        arrays[name] = _scalar_column(table, name, fail, allow_null=False)
    descriptors = {
        d: _scalar_column(table, d, fail, allow_null=True) for d in header["descriptors"]
    }
    for name in binned:
        arrays[name] = _binned_column(table, name, n_az, fail)
    _check_geometry(table, arrays["lon_deg"], arrays["lat_deg"], fail)
    if header["format_version"] == 1 and np.any(arrays["source"] == BinSource.TERRAIN):
        raise fail(f"source code {int(BinSource.TERRAIN)} (terrain) appears in a version 1 file, "
                   "which has no such code; rewrite the file with write_masks")  # fmt: skip
    try:
        masks = MaskSet(
            chainage_m=arrays["chainage_m"],
            lat_deg=arrays["lat_deg"],
            lon_deg=arrays["lon_deg"],
            h_m=arrays["h_m"],
            heading_deg=arrays["heading_deg"],
            az_step_deg=header["az_step_deg"],
            mask_el_deg=arrays["mask_el_deg"],
            source=arrays["source"],
            margin_deg=arrays["margin_deg"],
            descriptors=descriptors,
            provenance=header["provenance"],
            support=arrays.get(_SUPPORT),
        )
    except MaskError as exc:
        raise fail(str(exc)) from None
    if record is not None:
        _check_record(given, record, masks)
    # Arrow's pool keeps the file's buffers (4-6x the masks) for the rest of the run otherwise
    del table, arrays
    pa.default_memory_pool().release_unused()
    el = masks.mask_el_deg
    top = float(np.max(el)) if el.size else 0.0
    if 0.0 < top <= np.pi / 2 + 1e-6 and not np.all(el == np.round(el)):
        # a user trial's masks in radians trusted like no mask at all (75.6 % claims, 24.4 %
        # with the degrees); an open flat stretch can be this low, so it is said, not refused
        warnings.warn(
            f"{path}: every mask value is at most {top:.3f} deg, below pi/2: if they are "
            "radians, write the file in degrees (mask_el_deg); masks this low trust almost the "
            "whole sky",
            MaskUnitWarning,
            stacklevel=2,
        )
    _warn_mixed_units(path, masks)
    _warn_sparse(path, masks)
    if not close_holes:
        return masks
    closed, holes = close_gaps(masks)
    if holes:
        where = ", ".join(f"{a:.0f}-{b:.0f} m" for a, b in holes[:5])
        warnings.warn(
            f"{path}: {len(holes)} hole(s) between its positions ({where}"
            f"{', ...' if len(holes) > 5 else ''}): closed with positions that trust nothing "
            "(90 deg masks, source ASSUMED), not covered by the positions either side; survey "
            "the holes, or join mask files only where they meet",
            MaskHoleWarning,
            stacklevel=2,
        )
    return closed


def _warn_mixed_units(path: Path, masks: MaskSet) -> None:
    """Positions whose every value is at most pi/2 (and not whole degrees) beside positions
    above it: a file joined from a tool in radians and one in degrees (a trial's joined file
    lowered 47 % of the bins by up to 84 deg without a word)."""
    el = masks.mask_el_deg
    if el.size == 0:
        return
    top = np.max(el, axis=1)
    low = (top > 0.0) & (top <= np.pi / 2 + 1e-6) & ~np.all(el == np.round(el), axis=1)
    n_low = int(low.sum())
    if n_low < 3 or low.all() or not np.any(top > 5.0):  # all low: the file-wide check
        return
    first = float(masks.chainage_m[np.flatnonzero(low)[0]])
    warnings.warn(
        f"{path}: {n_low} of {masks.n_pos} positions (the first at chainage {first:.1f} m) hold "
        f"masks of at most pi/2 deg while others reach {float(top.max()):.1f} deg: if those "
        "are radians (a file joined from two tools), write them in degrees; read as they are, "
        "they trust almost their whole sky",
        MaskUnitWarning,
        stacklevel=3,
    )


def _warn_sparse(path: Path, masks: MaskSet) -> None:
    """Positions farther apart than :data:`SPARSE_SPACING_M` (the median): each mask stands
    for half the spacing either side (a trial's decimated files trusted up to 85 deg more)."""
    if masks.n_pos < 2:
        return
    spacing = float(np.median(np.diff(np.asarray(masks.chainage_m, float))))
    if spacing <= SPARSE_SPACING_M:
        return
    warnings.warn(
        f"{path}: its {masks.n_pos} positions lie {spacing:.0f} m apart (the median): each "
        f"mask stands for {spacing / 2:.0f} m of line either side, the ends included, and an "
        "obstacle between positions (a mast, a gantry, a bridge) is in none; a survey's frames "
        "are 10 m apart: give the masks of every frame",
        MaskSpacingWarning,
        stacklevel=3,
    )


def _read_header(path: Path, metadata: dict[bytes, bytes]) -> JsonDict:
    raw = metadata.get(METADATA_KEY)
    if raw is None:
        raise MaskFileError(
            f"{path}: not a PREDISAT mask file (no '{METADATA_KEY.decode()}' key in the Parquet "
            "metadata); write mask files with predisat.masks.fileformat.write_masks"
        )
    try:
        header = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MaskFileError(
            f"{path}: the '{METADATA_KEY.decode()}' metadata is not JSON ({exc})"
        ) from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        got = header.get("format") if isinstance(header, dict) else header
        raise MaskFileError(f"{path}: metadata format is {got!r}, expected {FORMAT_NAME!r}")
    version = header.get("format_version")
    if version not in _READ_VERSIONS or isinstance(version, bool):
        hint = (
            "it was written by a newer PREDISAT: upgrade predisat to read it"
            if isinstance(version, int) and version > FORMAT_VERSION
            else "rewrite the file with predisat.masks.fileformat.write_masks"
        )
        raise MaskFileError(
            f"{path}: format_version {version!r} is not supported (this reader reads "
            f"{', '.join(map(str, _READ_VERSIONS))}); {hint}"
        )
    step, n_az = header.get("az_step_deg"), header.get("n_az")
    if not (
        isinstance(step, int | float)
        and isinstance(n_az, int)
        and n_az > 0
        and math.isclose(step * n_az, 360.0, abs_tol=1e-9)
    ):
        raise MaskFileError(
            f"{path}: header az_step_deg = {step!r}, n_az = {n_az!r} do not give 360 deg"
        )
    descriptors = header.get("descriptors", [])
    if not isinstance(descriptors, list) or not all(isinstance(d, str) for d in descriptors):
        raise MaskFileError(f"{path}: header 'descriptors' must be a list of column names")
    provenance = header.get("provenance", {})
    if not isinstance(provenance, dict):
        raise MaskFileError(f"{path}: header 'provenance' must be a JSON object")
    return {
        "format_version": version,
        "az_step_deg": float(step),
        "n_az": n_az,
        "descriptors": descriptors,
        "provenance": provenance,
    }


def _scalar_column(
    table: pa.Table, name: str, fail: Callable[[str], MaskFileError], allow_null: bool
) -> NDArray:
    col = table.column(name)
    if not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)):
        raise fail(f"column {name!r} has type {col.type}, expected a number (float64)")
    if not allow_null and col.null_count:
        row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
        raise fail(f"column {name!r} row {row} is null; every position needs a value")
    return np.asarray(col.to_numpy(zero_copy_only=False), dtype=float)


def _binned_column(
    table: pa.Table, name: str, n_az: int, fail: Callable[[str], MaskFileError]
) -> NDArray:
    col = table.column(name).combine_chunks()
    typ = col.type
    if not (
        pa.types.is_list(typ) or pa.types.is_large_list(typ) or pa.types.is_fixed_size_list(typ)
    ):
        raise fail(f"column {name!r} has type {typ}, expected a list of {n_az} values per row")
    if col.null_count:
        row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
        raise fail(f"column {name!r} row {row} is null; every position needs {n_az} bins")
    lengths = np.asarray(pc.list_value_length(col).to_numpy(zero_copy_only=False))
    bad = np.flatnonzero(lengths != n_az)
    if bad.size:
        row = int(bad[0])
        raise fail(
            f"column {name!r} row {row} has {lengths[row]} bins, the header says n_az = {n_az}"
        )
    values = col.flatten()
    if values.null_count:
        flat = int(np.flatnonzero(values.is_null().to_numpy(zero_copy_only=False))[0])
        raise fail(f"column {name!r} row {flat // n_az} bin {flat % n_az} is null")
    if not (pa.types.is_floating(values.type) or pa.types.is_integer(values.type)):
        raise fail(f"column {name!r} holds {values.type}, expected numbers")
    return np.asarray(values.to_numpy(zero_copy_only=False)).reshape(len(col), n_az)


def _check_geometry(
    table: pa.Table, lon: NDArray, lat: NDArray, fail: Callable[[str], MaskFileError]
) -> None:
    try:
        geoms = shapely.from_wkb(table.column("geometry").to_numpy(zero_copy_only=False))
    except (shapely.errors.ShapelyError, TypeError, ValueError) as exc:
        raise fail(f"column 'geometry' is not valid WKB ({exc})") from None
    gx, gy = shapely.get_x(geoms), shapely.get_y(geoms)
    ok = (
        (shapely.get_type_id(geoms) == 0)
        & np.isclose(gx, lon, rtol=0, atol=1e-9)
        & np.isclose(gy, lat, rtol=0, atol=1e-9)
    )
    if not ok.all():
        row = int(np.flatnonzero(~ok)[0])
        raise fail(
            f"column 'geometry' row {row} is not the point (lon_deg, lat_deg) = "
            f"({lon[row]}, {lat[row]}); the geometry was edited - rewrite the file"
        )


def _crs84_projjson() -> JsonDict:
    crs: JsonDict = CRS("OGC:CRS84").to_json_dict()
    return crs


# ---------------------------------------------------------------------- exporters
def to_urbannav_csv(
    masks: MaskSet,
    path: str | os.PathLike[str],
    *,
    include_margin: bool = True,
    header: bool = True,
) -> Path:
    """Export every position as an UrbanNav-style sky-mask CSV row.

    Each row is ``lat_deg, lon_deg, h_m, e_0, e_1, ..., e_360``: 361 elevations (degrees) at
    azimuths 0..360 deg inclusive (``e_360 == e_0``). ``e_a`` is the maximum of the effective
    mask over every bin touching ``[a - 1, a + 1]`` deg, so any lookup a reader may use
    (nearest sample, floor, ceil, or linear interpolation between neighbours) never falls
    below the mask. Values are rounded up to 0.01 deg and capped at 90.

    Parameters
    ----------
    masks : MaskSet
    path : path-like
    include_margin : bool, optional
        Export ``mask + margin`` (default) or the bare mask.
    header : bool, optional
        Write a header row ``lat_deg,lon_deg,h_m,e_0,...,e_360`` (``e_a``: elevation at
        azimuth ``a``, degrees; default True). UrbanNav's published sky-mask tables start with
        one header line (``Latitude(deg)``, ``Longitude(deg)``, ``Altitude(m)``,
        ``Skymask(1*361,deg)``), so a reader written for them skips one line: without the
        header it would drop the first position silently and look up its neighbour's mask
        there. A header-less reader given the header fails loudly instead.
    """
    path = Path(path)
    mask = masks.effective_mask_deg if include_margin else masks.mask_el_deg
    az = np.arange(361.0)
    el = _ceil_to(conservative_resample(mask, masks.az_step_deg, az, 1.0), 0.01)
    with _atomic(path) as f:
        if header:
            f.write(",".join(["lat_deg", "lon_deg", "h_m", *(f"e_{a}" for a in range(361))]))
            f.write("\n")
        for i in range(masks.n_pos):
            lead = f"{masks.lat_deg[i]:.9f},{masks.lon_deg[i]:.9f},{masks.h_m[i]:.3f}"
            f.write(lead + "," + ",".join(f"{v:.2f}" for v in el[i]) + "\n")
    return path


def to_rtklib_mask(
    masks: MaskSet,
    chainage_m: float,
    path: str | os.PathLike[str],
    *,
    include_margin: bool = True,
) -> Path:
    """Export the mask at one position as an RTKLIB-style ``AZ EL`` elevation mask file.

    Three readers of this format are known, and the file is conservative for each:
    ``readelmask`` / ``testelmask`` of the RTKLIB forks that take an azimuth-dependent mask
    (MALIB, MRTKLIB: option ``file-elmaskfile``; mainline RTKLIB 2.4.3 b34 and demo5 have no
    such option) keep the first 360 lines, ``EL_i`` for ``AZ_i <= az < AZ_{i+1}`` stored in
    truncated tenths of a degree and looked up at ``floor(az)``; RTKPLOT's elevation-mask
    overlay and ``simobs -m`` fill 361 slots and look up ``int(az + 0.5)``. The file has 361
    lines ``a EL`` for a = 0..360 where ``EL`` is the maximum of the effective mask over every
    bin touching ``[a - 0.5, a + 1]`` (both lookups; line 360 closes the circle for the
    rounding readers, which otherwise leave ``[359.5, 360)`` at 0), rounded up to the 0.1-deg
    storage and written so that truncation keeps it (``2.3 / 0.1`` is 22.999... and would be
    stored as 2.2, so it is written ``2.35``, stored as 2.3; ``12.3 / 0.1`` is exactly 123 and
    is written ``12.3``), capped at 90.

    Parameters
    ----------
    masks : MaskSet
    chainage_m : float
        Position (the nearest surveyed position is used; it must be covered).
    path : path-like
    include_margin : bool, optional
    """
    path = Path(path)
    i = _single_position(masks, chainage_m)
    mask = masks.effective_mask_deg if include_margin else masks.mask_el_deg
    el = conservative_resample(mask[i], masks.az_step_deg, np.arange(361) + 0.25, 0.75)
    with _atomic(path) as f:
        f.write(_comment_block("%", masks, i, include_margin))
        f.write("% AZ(deg) EL(deg): EL applies for AZ <= az < next AZ\n")
        for a, v in enumerate(el):
            f.write(f"{a:d} {_rtklib_value(float(v))}\n")
    return path


def to_pvgis_horizon(
    masks: MaskSet,
    chainage_m: float,
    path: str | os.PathLike[str],
    *,
    n_directions: int = 48,
    layout: str = "table",
    include_margin: bool = True,
) -> Path:
    """Export the mask at one position as a PVGIS horizon file.

    ``n_directions`` equidistant directions (PVGIS's own horizon tool uses 48, i.e. 7.5 deg).
    The height at direction ``a`` is the maximum of the effective mask over every bin touching
    ``[a - d, a + d]`` with ``d = 360 / n_directions``, conservative for nearest-sample and
    linear-interpolation readers; rounded up to 0.01 deg, capped at 90.

    Parameters
    ----------
    layout : {"table", "userhorizon"}
        ``"table"``: the layout of PVGIS's horizon-profile CSV: ``Latitude``/``Longitude``
        header lines, a blank line, ``A`` and ``H_hor`` columns separated by two tabs, with
        PVGIS's azimuth convention (0 = south, 90 = west, -90 = east, +-180 = north), from
        -180 to +180 inclusive. ``"userhorizon"``: the PVGIS 5 horizon upload file, one height
        per line, clockwise from north, equidistant (no azimuths written).
    """
    path = Path(path)
    if layout not in ("table", "userhorizon"):
        raise ValueError(f"layout must be 'table' or 'userhorizon', got {layout!r}")
    if int(n_directions) != n_directions or n_directions < 4:
        raise ValueError(f"n_directions must be an integer >= 4, got {n_directions!r}")
    i = _single_position(masks, chainage_m)
    mask = masks.effective_mask_deg if include_margin else masks.mask_el_deg
    step = 360.0 / n_directions
    az_north = np.arange(n_directions) * step
    h = _ceil_to(conservative_resample(mask[i], masks.az_step_deg, az_north, step), 0.01)
    with _atomic(path) as f:
        if layout == "userhorizon":
            f.writelines(f"{v:.2f}\n" for v in h)
            return path
        f.write(f"Latitude (decimal degrees):\t{masks.lat_deg[i]:.6f}\n")
        f.write(f"Longitude (decimal degrees):\t{masks.lon_deg[i]:.6f}\n\n")
        f.write("A\t\tH_hor\n")
        # PVGIS azimuth A = azimuth from north - 180; rows run A = -180 (north) .. +180.
        for k in range(n_directions + 1):
            f.write(f"{-180.0 + k * step:.1f}\t\t{h[k % n_directions]:.2f}\n")
        f.write("\nA: azimuth (deg, 0 = south, 90 = west, -90 = east)\n")
        what = "effective mask (mask + margin)" if include_margin else "mask without margin"
        f.write(f"H_hor: horizon height (deg) = PREDISAT {what}, conservative\n")
        f.write(_comment_block("", masks, i, include_margin))
    return path


# ---------------------------------------------------------------------- helpers
def _single_position(masks: MaskSet, chainage_m: float) -> int:
    idx, inside = masks.position_index(float(chainage_m))
    if not bool(inside):
        raise MaskError(
            f"chainage_m = {chainage_m} is outside the mask set's coverage "
            f"({masks.cell_bounds_m[0]:.1f} .. {masks.cell_bounds_m[-1]:.1f} m)"
        )
    return int(idx)


_COMMENT_WIDTH = 120
"""Longest comment line of the text exports, characters (RTKLIB reads at most 255)."""


def _comment_block(prefix: str, masks: MaskSet, i: int, include_margin: bool) -> str:
    src = masks.source[i]
    lines = [
        f"PREDISAT mask at chainage {masks.chainage_m[i]:.2f} m "
        f"(lat {masks.lat_deg[i]:.8f} deg, lon {masks.lon_deg[i]:.8f} deg, "
        f"h {masks.h_m[i]:.2f} m), heading {masks.heading_deg[i]:.2f} deg",
        f"values: {'mask + margin' if include_margin else 'mask without margin'}, conservative "
        f"(max over the {masks.az_step_deg:g}-deg bins each line covers)",
        f"bins: {int((src == BinSource.OBSERVED).sum())} observed, "
        f"{int((src == BinSource.RECONSTRUCTED).sum())} reconstructed, "
        f"{int((src == BinSource.ASSUMED).sum())} assumed of {masks.n_az}",
        f"provenance: {json.dumps(masks.provenance, sort_keys=True)}",
    ]
    lead = f"{prefix} " if prefix else ""
    # RTKLIB's readelmask reads 255-byte chunks (fgets into char[256]): the rest of a longer
    # comment line would be parsed as "AZ EL" data, so every line is cut well below that.
    # Continuation lines start with "+ " (never a number, even without a comment prefix);
    # dropping the lead and the "+ " and joining gives the line back exactly.
    width = _COMMENT_WIDTH - len(lead) - 2
    out = []
    for line in lines:
        parts = [line[k : k + width] for k in range(0, max(len(line), 1), width)]
        out.append(f"{lead}{parts[0]}\n")
        out.extend(f"{lead}+ {part}\n" for part in parts[1:])
    return "".join(out)


def _rtklib_value(el_deg: float) -> str:
    """Text for ``el_deg`` that RTKLIB's ``(int16_t)(el / 0.1)`` stores as >= ``el_deg``."""
    tenths = min(math.ceil((el_deg - _ROUND_TOL_DEG) / _RTKLIB_STEP_DEG), 900)
    for text in (f"{tenths / 10:.1f}", f"{tenths / 10 + 0.05:.2f}"):
        if int(float(text) / _RTKLIB_STEP_DEG) >= tenths and float(text) <= 90.0:
            return text
    return "90.0"  # unreachable in practice: 90.0 / 0.1 truncates to 900


def _ceil_to(values: NDArray, step: float) -> NDArray:
    """Round up to a multiple of ``step`` (within ``_ROUND_TOL_DEG``), cap at 90."""
    v = np.asarray(values, float)
    out = np.round(np.ceil((v - _ROUND_TOL_DEG) / step) * step, 6)
    return np.minimum(out, 90.0) + 0.0  # + 0.0: an exact 0 came out as -0.0, printed "-0.00"


@contextmanager
def _atomic(path: Path, binary: bool = False) -> Iterator[IO[Any]]:
    """Write to a temporary file beside ``path`` and move it into place on success."""
    if not path.parent.is_dir():
        raise MaskFileError(f"{path}: the folder {path.parent} does not exist; create it first")
    f: IO[Any]
    with atomic_path(path) as tmp, (
        open(tmp, "wb") if binary else open(tmp, "w", newline="\n")
    ) as f:
        yield f
