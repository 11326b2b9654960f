"""Tests of predisat.storage: local paths and fsspec URLs (memory://, http:// on loopback)."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import fsspec
import pytest

from predisat.storage import (
    StorageError,
    exists,
    input_path,
    is_remote,
    join,
    list_names,
    location,
    name_of,
    output_path,
    read_bytes,
    remove,
    remove_tree,
    stamp,
    write_atomic,
)
from tests.predisat.http_folder import serve_folder


@pytest.fixture
def mem() -> Iterator[str]:
    """A fresh memory:// folder, removed afterwards (the memory file system is global)."""
    root = f"memory://predisat-test-{uuid.uuid4().hex[:8]}"
    yield root
    fs = fsspec.filesystem("memory")
    path = root.removeprefix("memory://")
    if fs.exists(path):
        fs.rm(path, recursive=True)


def test_local_paths_and_file_urls_are_paths_other_urls_stay_text(tmp_path: Path) -> None:
    assert location(str(tmp_path / "a")) == tmp_path / "a"
    assert location(f"file://{tmp_path}/a") == tmp_path / "a"
    assert location("s3://bucket/run/") == "s3://bucket/run"
    assert not is_remote(location("rel/dir")) and is_remote(location("http://h:1/x"))
    assert join("s3://bucket/run", "chunks", "a.json") == "s3://bucket/run/chunks/a.json"
    assert join(tmp_path, "chunks", "a.json") == tmp_path / "chunks" / "a.json"
    assert name_of("http://h:1/x/survey.yaml") == "survey.yaml"


def test_memory_round_trip_atomic_listing_and_removal(mem: str) -> None:
    target = join(mem, "out", "chunks", "a.json")
    write_atomic(target, b"one")
    write_atomic(target, b"two")  # replaced, and no temporary object left beside it
    assert read_bytes(target) == b"two"
    assert list_names(join(mem, "out", "chunks")) == ["a.json"]
    first = stamp(target)
    assert first is not None and first[0] == 3
    with output_path(join(mem, "out", "m.bin")) as tmp:
        tmp.write_bytes(b"\x00" * 10)
    assert read_bytes(join(mem, "out", "m.bin")) == b"\x00" * 10
    with pytest.raises(RuntimeError), output_path(join(mem, "out", "never.bin")) as tmp:
        tmp.write_bytes(b"x")
        raise RuntimeError("writer failed")
    assert not exists(join(mem, "out", "never.bin"))  # nothing published on an error
    remove(target)
    assert not exists(target) and stamp(target) is None
    remove_tree(join(mem, "out"))
    assert not exists(join(mem, "out"))


def test_a_missing_remote_file_names_the_url_and_the_fix(mem: str, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="check the URL") as err:
        read_bytes(join(mem, "nothing.csv"))
    assert f"{mem}/nothing.csv" in str(err.value)
    (tmp_path / "here.txt").write_text("hello")
    with serve_folder(tmp_path) as url:
        assert read_bytes(join(url, "here.txt")) == b"hello"
        with input_path(join(url, "here.txt")) as local:
            assert local.read_text() == "hello" and local.name == "here.txt"
        with pytest.raises(FileNotFoundError) as err:
            read_bytes(join(url, "gone.txt"))
        assert f"{url}/gone.txt: no such file" in str(err.value)
        with pytest.raises(StorageError, match="read only"):
            write_atomic(join(url, "new.txt"), b"x")


def test_a_head_read_gives_the_first_bytes_only(mem: str, tmp_path: Path) -> None:
    data = bytes(range(256)) * 8
    write_atomic(join(mem, "img.jpg"), data)
    (tmp_path / "img.jpg").write_bytes(data)
    for loc in (join(mem, "img.jpg"), tmp_path / "img.jpg"):
        assert read_bytes(loc, head_bytes=100) == data[:100]
        assert read_bytes(loc, head_bytes=10**6) == data
    with serve_folder(tmp_path) as url:
        assert read_bytes(join(url, "img.jpg"), head_bytes=300) == data[:300]
    with pytest.raises(ValueError, match="head_bytes"):
        read_bytes(tmp_path / "img.jpg", head_bytes=-1)


def test_an_error_about_a_local_copy_names_the_url(mem: str) -> None:
    write_atomic(join(mem, "calib.yaml"), b"x")
    with pytest.raises(ValueError) as err, input_path(join(mem, "calib.yaml")) as local:
        raise ValueError(f"{local}: not a calibration")
    assert str(err.value) == f"{mem}/calib.yaml: not a calibration"


def test_unknown_protocol_names_the_package_to_install() -> None:
    with pytest.raises(StorageError, match="install its fsspec package"):
        read_bytes("nosuchprotocol://bucket/key")
