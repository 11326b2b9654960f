"""Atomic writes: a failed write leaves the old file and no temporary behind."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from predisat.atomic import atomic_path, write_bytes_atomic


def test_write_replaces_content(tmp_path: Path) -> None:
    target = tmp_path / "a.json"
    target.write_bytes(b"old")
    write_bytes_atomic(target, b"new")
    assert target.read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_failure_keeps_old_file_and_cleans_up(tmp_path: Path) -> None:
    target = tmp_path / "masks.parquet"
    target.write_bytes(b"finished work")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".parquet"
        tmp.write_bytes(b"half")
        raise RuntimeError("interrupted")
    assert target.read_bytes() == b"finished work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["masks.parquet"]


@pytest.mark.parametrize("umask", [0o022, 0o027, 0o077])
def test_written_file_gets_the_umask_mode(tmp_path: Path, umask: int) -> None:
    # A new file made by open() under the same umask is the independent reference.
    old = os.umask(umask)
    try:
        reference = tmp_path / "reference.txt"
        reference.write_bytes(b"x")
        write_bytes_atomic(tmp_path / "masks.parquet", b"x")
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "masks.parquet").stat().st_mode)
    assert mode == stat.S_IMODE(reference.stat().st_mode)


def test_missing_folders_are_created(tmp_path: Path) -> None:
    target = tmp_path / "cal" / "2026" / "model.json"
    write_bytes_atomic(target, b"{}")
    assert target.read_bytes() == b"{}"
    assert [p.name for p in target.parent.iterdir()] == ["model.json"]


def test_directory_target_is_refused_with_a_file_suggestion(tmp_path: Path) -> None:
    with pytest.raises(IsADirectoryError, match=r"is a directory.*give a file path"):
        write_bytes_atomic(tmp_path, b"x")
    assert list(tmp_path.iterdir()) == []
