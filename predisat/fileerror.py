"""Text-file input of the readers (RINEX, SP3, TLE): opening (plain or gzip) and the error
that names the file, the line, what is wrong and the fix."""

from __future__ import annotations

import gzip
from pathlib import Path

__all__ = ["FileLineError", "read_text_lines"]


class FileLineError(ValueError):
    """A file that cannot be read; the message names the file, the line and the fix.

    Parameters
    ----------
    path : path-like
        The file.
    line : int or None
        1-based line number, or None when the problem is not on one line (e.g. an empty file).
    what : str
        What is wrong and how to fix it.
    """

    def __init__(self, path: str | Path, line: int | None, what: str) -> None:
        where = f"{path}" if line is None else f"{path}, line {line}"
        super().__init__(f"{where}: {what}")
        self.path = str(path)
        self.line = line
        self.what = what


def read_text_lines(path: str | Path, error: type[FileLineError] = FileLineError) -> list[str]:
    """Lines of an ASCII text file, plain or gzip-compressed (by content, not by name).

    Parameters
    ----------
    path : path-like
    error : FileLineError subclass
        Raised (with the file named) for a missing, corrupt or ``.Z``-compressed file.
    """
    p = Path(path)
    if not p.is_file():
        raise error(p, None, "no such file; check the path")
    raw = p.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError) as exc:
            raise error(p, None, f"corrupt gzip data ({exc}); download it again") from exc
    elif raw[:2] == b"\x1f\x9d":
        raise error(p, None, "Unix-compressed (.Z) file; decompress it first (gunzip)")
    return raw.decode("ascii", errors="replace").splitlines()
