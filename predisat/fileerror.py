"""The common error of the text-file readers (RINEX, SP3, TLE): file, line, what and the fix."""

from __future__ import annotations

from pathlib import Path

__all__ = ["FileLineError"]


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
