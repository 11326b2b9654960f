"""Tests of predisat.masks.dataset: the mask dataset partitioned by line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from predisat.masks.dataset import (
    partition_path,
    partitions,
    read_dataset_table,
    read_partition,
    write_partition,
)
from predisat.masks.fileformat import MaskFileError, read_masks
from tests.predisat.masks.test_fileformat import make_set


def test_partitions_round_trip_and_keep_exact_line_ids(tmp_path: Path) -> None:
    sets = {("01", 1): make_set(5, seed=1), ("1", 1): make_set(4, seed=2),
            ("50A/3", 2): make_set(3, seed=3)}  # fmt: skip
    for (lid, part), m in sets.items():
        write_partition(m, tmp_path, lid, part)
    assert partition_path(tmp_path, "50A/3", 2) == tmp_path / "line=50A%2F3/part=2/masks.parquet"
    assert [(lid, k) for lid, k, _ in partitions(tmp_path)] == sorted(sets)
    for (lid, part), m in sets.items():
        got = read_partition(tmp_path, lid, part)  # each file is a mask file on its own
        assert np.array_equal(got.mask_el_deg, m.mask_el_deg.astype(np.float32))
        assert np.array_equal(got.chainage_m, m.chainage_m)
        cols = pq.read_table(partition_path(tmp_path, lid, part), columns=["line_id", "line_part"])
        assert set(cols.column("line_id").to_pylist()) == {lid}
        assert set(cols.column("line_part").to_pylist()) == {part}
    t = read_dataset_table(tmp_path)
    assert t.num_rows == sum(m.n_pos for m in sets.values())
    lines = t.column("line").to_pylist()
    assert [lines.count(lid) for lid in ("01", "1", "50A/3")] == [5, 4, 3]  # "01" is not 1
    assert t.column("line_id").to_pylist() == lines
    rows = [i for i, x in enumerate(lines) if x == "50A/3"]
    assert set(t.column("part").take(rows).to_pylist()) == {2}
    got_m = t.column("chainage_m").take(rows).to_numpy()
    assert np.array_equal(got_m, sets[("50A/3", 2)].chainage_m)


def test_bad_dataset_folders(tmp_path: Path) -> None:
    with pytest.raises(MaskFileError, match="no such mask dataset folder"):
        partitions(tmp_path / "nothing")
    with pytest.raises(MaskFileError, match="holds no partition"):
        read_dataset_table(tmp_path)
    stray = tmp_path / "x" / "y" / "masks.parquet"
    stray.parent.mkdir(parents=True)
    stray.write_bytes(b"")
    with pytest.raises(MaskFileError, match=r"not in a line=<id>/part=<k> folder; move it out"):
        partitions(tmp_path)
    with pytest.raises(ValueError, match="part must be >= 1"):
        partition_path(tmp_path, "1", 0)
    with pytest.raises(MaskFileError):
        read_masks(tmp_path / "line=1/part=1/masks.parquet")
