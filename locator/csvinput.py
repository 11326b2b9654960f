"""CSV inputs of the locator (balise lists, odometer logs) read with errors that name the file,
the line and the fix.

:func:`read_csv_table` reads a comma-separated text file with a header into a
:class:`CsvTable`; it refuses a binary file (naming the line of the first byte that is not
UTF-8 text), a file whose columns are separated by ``;`` or tabs, and missing columns; spaces
after the commas are ignored (``id, chainage_m``). :meth:`CsvTable.numbers` converts a column
and names the line of the first value that is not a number.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from predisat.readonly import freeze_array_fields

__all__ = ["CsvTable", "read_csv_table"]

# how a value a person leaves empty or unknown may be written (read as NaN, not as text)
_MISSING = frozenset({"", "nan", "NaN", "NAN", "NA", "N/A", "n/a", "null", "NULL", "None"})


@dataclass(frozen=True, eq=False)
class CsvTable:
    """A CSV file read as text columns, with the file line of each row.

    Attributes
    ----------
    frame : pandas.DataFrame
        The rows (column names stripped of spaces), every cell as read.
    lines : ndarray of int, shape (n_row,)
        File line (1-based, the header is the first non-empty line) of each row.
    label : str
        The file, as named in messages.
    error : callable
        Builds the exception raised for a bad value (from its message).
    """

    frame: pd.DataFrame
    lines: NDArray
    label: str
    error: Callable[[str], Exception]

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    def __len__(self) -> int:
        return len(self.frame)

    def line(self, row: int) -> int:
        """File line of row ``row`` (0-based)."""
        return int(self.lines[row])

    def numbers(self, column: str, fix: str) -> NDArray:
        """Column ``column`` as floats; empty cells (and ``nan``, ``NA``) are NaN.

        Raises ``error`` at the first cell that is text rather than a number, naming the file,
        its line, the column, the value and ``fix`` (what the column should hold).
        """
        cells = self.frame[column]
        text = cells.astype(str).str.strip()
        missing = cells.isna().to_numpy() | text.isin(_MISSING).to_numpy()
        values = pd.to_numeric(text.where(~missing), errors="coerce").to_numpy(float)
        bad = np.flatnonzero(np.isnan(values) & ~missing)
        if len(bad):
            i = int(bad[0])
            raise self.error(
                f"{self.label}, line {self.line(i)}: {column} {text.iloc[i]!r} is not a number; "
                f"{fix}"
            )
        return values


def _a(noun: str) -> str:
    """The indefinite article of ``noun``."""
    return "an" if noun[:1].lower() in "aeiou" else "a"


def _undecodable(raw: bytes, label: str, what: str, columns: str) -> str | None:
    """The message for a file that is not UTF-8 text (None when it is)."""
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        kind = " (a zip archive, e.g. an .npz)" if raw[:2] == b"PK" else ""
        if not kind and b"\0" not in raw[:4096] and b"," in raw[:4096]:
            # text in a Windows code page (an accented name, an en dash from Excel)
            return (
                f"{label}, line {line}: byte 0x{raw[exc.start]:02x} is not UTF-8: the {what} "
                "was saved in another encoding (Windows-1252 or Latin-1 from a spreadsheet); "
                "save it as CSV UTF-8"
            )
        return (
            f"{label}, line {line}: byte 0x{raw[exc.start]:02x} is not text: this is not a CSV "
            f"file{kind}; give the {what} as a comma-separated text file with columns {columns}"
        )
    return None


def read_csv_table(
    path: str | Path,
    required: Sequence[str],
    *,
    what: str,
    error: Callable[[str], Exception],
    doc: str,
    aliases: Mapping[str, str] | None = None,
    optional: Sequence[str] = (),
) -> CsvTable:
    """Read a CSV file with a header line; refuse what cannot be one, naming the fix.

    Every cell is read as text (empty cells as ``""``); convert numeric columns with
    :meth:`CsvTable.numbers`.

    Parameters
    ----------
    path : str or Path
    required : sequence of str
        Columns that must be present.
    what : str
        What the file holds, for messages (``"balise list"``).
    error : callable
        The exception to raise, built from its message (e.g. ``BaliseFileError``).
    doc : str
        Where the format is described (``"docs/odometry.md"``).
    aliases : mapping of str to str, optional
        Unused column name -> the required or optional column it probably means (compared
        without case): for the message of a missing required column, and to refuse a file
        whose optional column is given under another name (its default would be used).
    optional : sequence of str
        Columns read when present (with a default otherwise). A column that names one of
        them, or a required one, in other letter case or by an alias is refused: its values
        would be silently replaced by the default.

    Returns
    -------
    CsvTable
    """
    p = Path(path)
    label = str(p)
    columns = ", ".join(required)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise error(f"{label}: cannot read the {what} ({exc}); check the path") from exc
    if raw.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte-order mark (spreadsheet export)
        raw = raw[3:]
    message = _undecodable(raw, label, what, columns)
    if message:
        raise error(message)
    # CR alone ends the lines of Excel's "CSV (Macintosh)": csv.reader met it inside a row
    # and failed with a traceback naming no file (a user trial)
    text = raw.decode("utf-8").replace("\r\n", "\n").replace("\r", "\n")
    numbered = [(k + 1, s) for k, s in enumerate(text.split("\n")) if s.strip()]
    if not numbered:
        raise error(f"{label}: the file is empty; {_a(what)} {what} starts with the header line "
                    f"{','.join(required)} ({doc})")  # fmt: skip
    header_line, header = numbered[0]
    comments = [k for k, line in numbered if line.lstrip().startswith("#")]
    if comments:  # read as the header or as a row: "8 fields where the header has 2" (a trial)
        raise error(
            f"{label}, line {comments[0]}: a comment line ('#'); {_a(what)} {what} has none: "
            f"remove {'it' if len(comments) == 1 else f'the {len(comments)} comment lines'} "
            f"(the first line is the header {','.join(required)}; {doc})"
        )
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if "," not in header and sep in header:
            raise error(
                f"{label}, line {header_line}: the columns are separated by {name}, not commas; "
                f"save the {what} as comma-separated values (CSV with ',' and '.' for decimals)"
            )
    names = [c.strip() for c in next(csv.reader([header], skipinitialspace=True))]
    twice = sorted({c for c in names if c and names.count(c) > 1})
    if twice:  # pandas would rename the second one and read the first: which one is meant?
        raise error(f"{label}, line {header_line}: the header names {twice} twice; keep one "
                    f"column of each ({doc})")  # fmt: skip
    text = _without_trailing_commas(text, len(names), label, what, error)
    try:
        frame = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False,
                            skipinitialspace=True)  # fmt: skip
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise error(f"{label}: cannot read the {what} ({exc}); give a comma-separated file "
                    f"with columns {columns} ({doc}): a row with more fields than the header "
                    "holds a comma inside a value (a thousands separator: 4195, not 4,195; a "
                    "decimal comma: 4.5, not 4,5)") from exc  # fmt: skip
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in required if c not in frame.columns]
    if missing:
        hint = ""
        meant = {a: c for a, c in (aliases or {}).items() if c in missing and a in frame.columns}
        if meant:
            hint = "; rename " + ", ".join(f"{a!r} to {c!r}" for a, c in meant.items())
        raise error(
            f"{label}: missing columns {missing} (the header has {list(frame.columns)}); "
            f"{_a(what)} {what} needs {columns} ({doc}){hint}"
        )
    _refuse_misnamed(list(frame.columns), [*required, *optional], aliases or {}, label,
                     header_line, what, doc, error)  # fmt: skip
    lines = np.array([k for k, _ in numbered[1:]], int)
    if len(lines) != len(frame):  # a quoted cell across lines: count rows after the header
        lines = header_line + 1 + np.arange(len(frame))
    # rows of empty cells (",,,": the formatted but empty rows a spreadsheet saves) hold nothing
    filled = (frame != "").any(axis=1).to_numpy()
    if not filled.all():
        frame, lines = frame[filled].reset_index(drop=True), lines[filled]
    return CsvTable(frame, lines, label, error)


def _refuse_misnamed(
    names: Sequence[str],
    known: Sequence[str],
    aliases: Mapping[str, str],
    label: str,
    header_line: int,
    what: str,
    doc: str,
    error: Callable[[str], Exception],
) -> None:
    """Refuse a column that is a known one under another name (case, an alias) while the
    known one is absent: an optional column's default would silently stand in for it (a
    user trial: ``accuracy`` of 20 m read as the default 1 m)."""
    lower = {a.lower(): c for a, c in aliases.items()}
    lower.update({c.lower(): c for c in known})
    for name in names:
        meant = lower.get(name.lower())
        if meant is None or name == meant or meant in names:
            continue
        raise error(
            f"{label}, line {header_line}: column {name!r} is not read; if it holds "
            f"{meant}, rename it to {meant!r} ({doc}); otherwise rename it to a name the "
            f"{what} does not use"
        )


def _without_trailing_commas(
    text: str, n_fields: int, label: str, what: str, error: Callable[[str], Exception]
) -> str:
    """``text`` with the empty last field dropped when every data row has one more field than
    the header and that field is empty: a spreadsheet export's trailing comma, which pandas
    would read as a shift of every column (a user trial's "h_m '005A00' is not a number").
    Any other file is returned as it is (pandas refuses a row longer than the header)."""
    rows = list(_rows_with_lines(text))
    data = [(row, line) for row, line in rows[1:] if any(c.strip() for c in row)]
    if not data or not all(len(r) == n_fields + 1 and not r[-1].strip() for r, _ in data):
        # pandas takes a first data row one field longer for an index column: every value of
        # the file shifted; a longer row anywhere is refused here, with its line
        for row, line in data:
            if len(row) > n_fields:
                raise error(
                    f"{label}, line {line}: {len(row)} fields where the header has {n_fields}: "
                    "a comma inside a value (a thousands separator: 4195, not 4,195; a decimal "
                    f"comma: 4.5, not 4,5), or a quote missing; fix that row of the {what}"
                )
        return text
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    for k, (row, _) in enumerate(rows):
        writer.writerow(row if k == 0 or not any(c.strip() for c in row) else row[:-1])
    return out.getvalue()


def _rows_with_lines(text: str) -> Iterator[tuple[list[str], int]]:
    """The CSV rows of ``text`` (spaces after the commas skipped, as pandas reads them) with
    the line each starts on (1 = the first line)."""
    reader = csv.reader(io.StringIO(text), skipinitialspace=True)
    start = 1
    for row in reader:
        yield row, start
        start = reader.line_num + 1
