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

__all__ = ["atomic_path", "write_bytes_atomic"]


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
