"""Atomic file writes: readers see the old file or the new one, never a part.

Every output of a batch run (frames, chunks, masks, reports) goes through here, so that an
interrupted run leaves only whole files behind and can resume.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["LOCK_NAME", "FolderInUseError", "atomic_path", "exclusive_folder", "write_bytes_atomic"]

LOCK_NAME = ".predisat.lock"


class FolderInUseError(OSError):
    """Another run is writing into the output folder; the message names it and the fix."""


@contextmanager
def exclusive_folder(folder: str | os.PathLike[str]) -> Iterator[None]:
    """Hold an exclusive advisory lock on an output folder while a run writes into it.

    A second run on the same folder is refused at once, naming the first (its process and
    start), instead of doing all the work again and racing the first on the same files (a
    user trial ran two at once without a word). The lock is ``flock`` on
    ``FOLDER/.predisat.lock``: released when the run ends or its process dies; on a network
    file system it may hold only between runs of one machine.

    Raises
    ------
    FolderInUseError
        Another process holds the lock.
    """
    import fcntl
    from datetime import UTC, datetime

    path = Path(folder) / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 200).decode("utf-8", "replace").strip() or "another process"
        os.close(fd)
        raise FolderInUseError(
            f"{folder}: another run is writing there ({holder}); wait for it to end, or give "
            "another output folder"
        ) from None
    try:
        os.ftruncate(fd, 0)
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        os.write(fd, f"process {os.getpid()}, since {stamp}".encode())
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside ``path``, moved onto it when the block succeeds.

    The temporary name keeps the suffix of ``path`` (writers such as ``cv2.FileStorage`` or
    ``numpy.savez`` choose their format from it); on an exception it is removed and ``path`` is
    left as it was.
    """
    p = Path(path)
    if p.is_dir():
        raise IsADirectoryError(
            f"{p}: is a directory, not a file to write; give a file path such as "
            f"{p / ('output' + p.suffix)}"
        )
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=p.suffix, dir=p.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file 0600; a published mask file must get the mode any new file
        # would get (others in the team read it).
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    """The process umask, read without changing it where the system allows."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
