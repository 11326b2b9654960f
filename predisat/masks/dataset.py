"""A network's masks: one GeoParquet dataset partitioned by line (Hive layout).

::

    ROOT/line=144/part=1/masks.parquet
    ROOT/line=50A%2F3/part=1/masks.parquet        line "50A/3" (URI-encoded, as Hive does)
    ROOT/line=211/part=2/masks.parquet            the second connected part of line 211

Each file is a mask file (``docs/mask-format.md``, :func:`predisat.masks.fileformat.read_masks`
reads it alone, ``predisat availability --masks`` takes it) with two more columns, ``line_id``
(string) and ``line_part`` (int32): a reader that infers the folders' types (geopandas and
pyarrow read ``line=01`` as the integer 1, the same as line ``1``) still has the exact id.
Together they are one dataset that pyarrow, geopandas, DuckDB or QGIS open at ``ROOT``, with
``line`` and ``part`` from the folder names (:func:`read_dataset_table` reads them as string
and int32). Every file has the same
columns; chainage is per part (each part's track map starts at 0). See ``docs/network.md``.
"""

from __future__ import annotations

import os
from pathlib import Path
from urllib.parse import quote, unquote

import pyarrow as pa
import pyarrow.dataset as pads
import pyarrow.parquet as pq

from predisat.atomic import atomic_path
from predisat.masks.fileformat import MaskFileError, read_masks, write_mask_table, write_masks
from predisat.masks.maskset import MaskSet

__all__ = [
    "PARTITION_FILE",
    "partition_path",
    "partitions",
    "read_dataset_table",
    "read_partition",
    "write_partition",
]

PARTITION_FILE = "masks.parquet"


def partition_path(root: str | os.PathLike[str], line_id: str, part: int = 1) -> Path:
    """``ROOT/line=<line_id URI-encoded>/part=<part>/masks.parquet``."""
    if not line_id:
        raise ValueError("line_id must not be empty")
    if part < 1:
        raise ValueError(f"part must be >= 1 (parts are numbered from 1), got {part}")
    return Path(root) / f"line={quote(line_id, safe='')}" / f"part={part}" / PARTITION_FILE


def write_partition(
    masks: MaskSet, root: str | os.PathLike[str], line_id: str, part: int = 1
) -> Path:
    """Write one line part's masks into the dataset (atomically, replacing an older file): the
    mask file of :func:`~predisat.masks.fileformat.write_masks` with the ``line_id`` and
    ``line_part`` columns."""
    path = partition_path(root, line_id, part)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        write_masks(masks, tmp)
        table = pq.read_table(tmp)
        n = table.num_rows
        table = table.append_column("line_id", pa.array([line_id] * n, type=pa.string()))
        table = table.append_column("line_part", pa.array([part] * n, type=pa.int32()))
        write_mask_table(table, tmp)
    return path


def read_partition(root: str | os.PathLike[str], line_id: str, part: int = 1) -> MaskSet:
    """One line part's masks, validated (:func:`predisat.masks.fileformat.read_masks`)."""
    return read_masks(partition_path(root, line_id, part))


def partitions(root: str | os.PathLike[str]) -> list[tuple[str, int, Path]]:
    """``(line_id, part, path)`` of every partition file under ``root``, sorted by line id
    and part; MaskFileError for a folder that is not ``line=<id>/part=<k>``."""
    base = Path(root)
    if not base.is_dir():
        raise MaskFileError(f"{base}: no such mask dataset folder")
    out = []
    for f in sorted(base.glob(f"*/*/{PARTITION_FILE}")):
        line_dir, part_dir = f.parent.parent.name, f.parent.name
        if not (line_dir.startswith("line=") and part_dir.startswith("part=")):
            raise MaskFileError(
                f"{f}: not in a line=<id>/part=<k> folder; move it out of the dataset {base}"
            )
        try:
            part = int(part_dir[len("part="):])
        except ValueError:
            raise MaskFileError(f"{f}: part folder {part_dir!r} is not part=<integer>") from None
        out.append((unquote(line_dir[len("line="):]), part, f))
    return sorted(out, key=lambda t: (t[0], t[1]))


def read_dataset_table(root: str | os.PathLike[str]) -> pa.Table:
    """The whole dataset as one Arrow table with ``line`` (str) and ``part`` (int32) columns
    (Hive partitioning), rows sorted by line, part and chainage."""
    if not partitions(root):
        raise MaskFileError(f"{root}: the mask dataset holds no partition")
    schema = pa.schema([("line", pa.string()), ("part", pa.int32())])
    ds = pads.dataset(
        str(root), format="parquet", partitioning=pads.partitioning(schema, flavor="hive"),
        exclude_invalid_files=False,
    )  # fmt: skip
    table = ds.to_table()
    return table.sort_by([("line", "ascending"), ("part", "ascending"),
                          ("chainage_m", "ascending")])  # fmt: skip
