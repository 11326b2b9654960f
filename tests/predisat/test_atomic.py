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


def test_a_staged_folder_is_published_whole_its_marker_last(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from predisat.atomic import staged_folder

    out = tmp_path / "run"
    out.mkdir()
    for name, text in (("run.json", "old"), ("epochs.csv", "old"), ("fig.png", "old")):
        (out / name).write_text(text)
    (out / ".staging-killed").mkdir()  # a killed run's
    (out / ".staging-killed" / "epochs.parquet").write_text("half")
    moves: list[str] = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (moves.append(Path(b).name), real(a, b)))
    with staged_folder(out, last=("run.json",), remove=("epochs.*",)) as stage:
        assert stage.parent == out and not (out / ".staging-killed").exists()
        for name in ("run.json", "epochs.parquet", "fig.png", "sub/x.txt"):
            (stage / name).parent.mkdir(exist_ok=True)
            (stage / name).write_text("new")
    assert moves[-1] == "run.json" and sorted(moves) == ["epochs.parquet", "fig.png", "run.json",
                                                          "x.txt"]  # fmt: skip
    # the old epochs.csv removed, no staging folder left; the lock file stays, as process's
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*")) == [
        ".predisat.lock", "epochs.parquet", "fig.png", "run.json", "sub", "sub/x.txt",
    ]  # fmt: skip
    assert all((out / n).read_text() == "new" for n in ("run.json", "epochs.parquet", "fig.png"))
    assert stat.S_IMODE((out / "fig.png").stat().st_mode) == 0o666 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_a_failure_while_staging_leaves_the_earlier_outputs_whole(tmp_path: Path) -> None:
    import errno

    from predisat.atomic import staged_folder

    out = tmp_path / "report"
    out.mkdir()
    (out / "summary.csv").write_text("a,b\n1,2\n3,4\n")
    (out / "report.html").write_text("<html>old</html>")
    with pytest.raises(OSError, match="No space"), staged_folder(out, last=("report.html",)) as s:
        (s / "summary.csv").write_text("a,b\n5,")  # the disk fills here
        raise OSError(errno.ENOSPC, "No space left on device", str(s / "report.html"))
    assert (out / "summary.csv").read_text() == "a,b\n1,2\n3,4\n"
    assert (out / "report.html").read_text() == "<html>old</html>"
    assert sorted(p.name for p in out.iterdir()) == [".predisat.lock", "report.html",
                                                      "summary.csv"]  # fmt: skip


def test_a_staged_folder_is_refused_while_another_run_writes_there(tmp_path: Path) -> None:
    from predisat.atomic import FolderInUseError, exclusive_folder, staged_folder

    with exclusive_folder(tmp_path), pytest.raises(FolderInUseError, match="another run"):
        with staged_folder(tmp_path):
            pass
    with exclusive_folder(tmp_path), staged_folder(tmp_path, lock=False) as stage:
        (stage / "a.txt").write_text("x")  # the caller holds the lock itself
    assert (tmp_path / "a.txt").read_text() == "x"


def test_storage_errors_name_the_file_meant_and_the_fix() -> None:
    import errno

    from predisat.atomic import storage_error_text

    full = OSError(errno.ENOSPC, "No space left on device", "/d/o/.masks.7qdmcq23.parquet")
    assert storage_error_text(full) == (
        "no space left on the disk (writing /d/o/masks.parquet): free space there, or give "
        "another output folder, and rerun the same command (a command that resumes keeps the "
        "work it had finished)"
    )
    staged = OSError(errno.EFBIG, "File too large", "/d/run/.staging-k2j4h5g6/.run.c30b2rvr.json")
    text = storage_error_text(staged)
    assert text is not None and "(writing /d/run/run.json)" in text and "ulimit -f" in text
    arrow = OSError("Error writing bytes to file. Detail: [errno 27] File too large")
    assert "file-size limit" in (storage_error_text(arrow) or "")
    assert storage_error_text(OSError(errno.ENOENT, "No such file", "x")) is None
    assert storage_error_text(ValueError("[errno 28]")) is None


def test_a_writer_s_full_disk_without_a_name_names_the_file_meant(tmp_path: Path) -> None:
    """A user trial: pyarrow's and the atomic writers' full-disk errors carried no file name,
    and the message named none; the atomic path now gives its own."""

    from predisat.atomic import storage_error_text

    target = tmp_path / "masks.parquet"
    with pytest.raises(OSError) as caught, atomic_path(target):
        raise OSError("Error writing bytes to file. Detail: [errno 28] No space left on device")
    assert caught.value.filename == str(target) and not target.exists()
    assert f"(writing {target})" in (storage_error_text(caught.value) or "")
    assert not list(tmp_path.iterdir())  # the temporary file is gone


def test_an_output_folder_that_cannot_be_written_is_refused_before_any_work(
    tmp_path: Path,
) -> None:
    from predisat.atomic import check_writable

    check_writable(tmp_path / "new" / "run")  # created
    assert (tmp_path / "new" / "run").is_dir() and not any((tmp_path / "new" / "run").iterdir())
    (tmp_path / "file").write_text("x")
    with pytest.raises(OSError, match=r"file/run: cannot write there \(.*\); give an output"):
        check_writable(tmp_path / "file" / "run")


def test_permission_and_file_kind_errors_name_the_path_meant_and_the_fix(tmp_path) -> None:
    """A trial's permission errors were Python's raw ``[Errno 13]`` on a temporary name."""
    import errno

    from predisat.atomic import access_error_text

    temp = tmp_path / ".masks.parquet.abcd1234"  # atomic_path's temporary name
    denied = PermissionError(errno.EACCES, "Permission denied", str(temp))
    text = access_error_text(denied)
    assert text is not None and text.startswith(f"{tmp_path / 'masks.parquet'}: permission")
    assert "check its permissions" in text
    exists = FileExistsError(errno.EEXIST, "File exists", str(tmp_path / "out"))
    text = access_error_text(exists)
    assert text is not None and "a file stands where a folder is needed" in text
    assert access_error_text(OSError(errno.EIO, "I/O error", "x")) is None
    assert access_error_text(ValueError("x")) is None
    assert access_error_text(PermissionError(errno.EACCES, "Permission denied")) is None
