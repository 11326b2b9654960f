"""RINEX 2 and 3 broadcast navigation files: GPS, Galileo, BeiDou, QZSS, IRNSS and GLONASS.

A small hand-written reader (see ``docs/ephemerides.md`` for why not georinex): it keeps every
record's raw values in one float table per orbit family, converts every epoch to ``gps_s``, and
rejects a malformed or truncated file with a :class:`RinexError` naming the file, the line and
what is wrong. SBAS records are counted and skipped (they are not used for ranging here).

Supported: RINEX 2.x GPS (``N``), GLONASS (``G``) and QZSS (2.12 ``N``/``J``) navigation files,
RINEX 3.00-3.05 mixed or single-system navigation files, plain or gzip-compressed (``.gz``).

Raw values keep the units of the file (RINEX: s, m, rad, rad/s; GLONASS: km, km/s, km/s^2);
:mod:`predisat.gnss.orbits` turns them into positions.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from predisat.fileerror import FileLineError, read_text_lines
from predisat.gnss.timescale import (
    BDT_MINUS_GPST_S,
    SECONDS_PER_WEEK,
    calendar_to_gps_s,
    gps_minus_utc_s,
)

__all__ = [
    "GLONASS_FIELDS",
    "KEPLER_FIELDS",
    "KEPLER_SYSTEMS",
    "NavRecords",
    "RinexError",
    "RinexNav",
    "read_rinex_nav",
]

KEPLER_SYSTEMS = "GECJI"
"""Systems whose broadcast orbit is Keplerian: GPS, Galileo, BeiDou, QZSS, IRNSS (NavIC)."""

# Column names of the raw Keplerian table, in file order (RINEX 3 "BROADCAST ORBIT" lines).
# Columns whose meaning depends on the system carry both names: GPS/QZSS "iode", Galileo
# "IODnav", BeiDou "AODE"; "aux20" = codes on L2 (GPS) / data sources (Galileo); "aux26" = IODC
# (GPS/QZSS) / BGD E5b-E1 (Galileo) / TGD2 (BeiDou); "fit" = fit interval (GPS h, QZSS flag) /
# AODC (BeiDou).
KEPLER_FIELDS: tuple[str, ...] = (
    "af0_s", "af1_sps", "af2_sps2",
    "iode", "crs_m", "delta_n_radps", "m0_rad",
    "cuc_rad", "e", "cus_rad", "sqrt_a_sqrtm",
    "toe_sow_s", "cic_rad", "omega0_rad", "cis_rad",
    "i0_rad", "crc_m", "omega_rad", "omega_dot_radps",
    "idot_radps", "aux20", "week", "aux22",
    "accuracy_m", "health", "tgd_s", "aux26",
    "transmit_sow_s", "fit", "spare29", "spare30",
)  # fmt: skip

# GLONASS (RINEX 2/3): -TauN, +GammaN, message frame time, then X/Y/Z blocks in km, km/s,
# km/s^2 with health, frequency number and age; RINEX 3.05 adds a fifth line.
GLONASS_FIELDS: tuple[str, ...] = (
    "minus_tau_n_s", "gamma_n", "frame_time_s",
    "x_km", "vx_kmps", "ax_kmps2", "health",
    "y_km", "vy_kmps", "ay_kmps2", "freq_num",
    "z_km", "vz_kmps", "az_kmps2", "age_d",
    "status_flags", "delay_l1l2_s", "urai", "health_flags",
)  # fmt: skip

_N_LINES = {"G": 8, "E": 8, "C": 8, "J": 8, "I": 8, "R": 4, "S": 4}
_REQUIRED_KEPLER = (*tuple(range(0, 20)), 24)
_REQUIRED_GLONASS = tuple(range(0, 15))
_EXPONENT = re.compile(r"[dD]")
# Fortran drops the exponent letter when the exponent has three digits: "0.499063314480-269"
_FORTRAN_3DIGIT = re.compile(r"^([+-]?\d*\.\d*)([+-]\d{3})$")


class RinexError(FileLineError):
    """A RINEX file that cannot be read; the message names the file, the line and the fix."""


@dataclass(frozen=True)
class NavRecords:
    """Broadcast records of one orbit family (Keplerian or GLONASS), one row per record.

    Attributes
    ----------
    kind : {"kepler", "glonass"}
    sat : ndarray of str, shape (n,)
        Satellite ids such as ``"G05"``, ``"C01"``, ``"R07"``.
    epoch_gps_s : ndarray, shape (n,)
        Clock reference epoch (toc; GLONASS tb) converted to ``gps_s``.
    ref_gps_s : ndarray, shape (n,)
        Orbit reference epoch in ``gps_s``: toe for Keplerian records (BeiDou converted from
        BDT), tb for GLONASS.
    values : ndarray, shape (n, len(fields))
        Raw values as written in the file (NaN where blank), columns named by ``fields``.
    fields : tuple of str
    source : ndarray of str, shape (n,)
        ``"file:line"`` of each record, for reports.
    """

    kind: str
    sat: NDArray
    epoch_gps_s: NDArray
    ref_gps_s: NDArray
    values: NDArray
    fields: tuple[str, ...]
    source: NDArray

    def __len__(self) -> int:
        return int(self.sat.shape[0])

    def col(self, name: str) -> NDArray:
        """Column ``name`` of :attr:`values`, shape (n,)."""
        return self.values[:, self.fields.index(name)]

    def take(self, index: NDArray) -> NavRecords:
        """The records at ``index`` (integer or boolean array)."""
        return NavRecords(
            self.kind,
            self.sat[index],
            self.epoch_gps_s[index],
            self.ref_gps_s[index],
            self.values[index],
            self.fields,
            self.source[index],
        )

    @classmethod
    def empty(cls, kind: str) -> NavRecords:
        fields = KEPLER_FIELDS if kind == "kepler" else GLONASS_FIELDS
        return cls(
            kind,
            np.zeros(0, "<U3"),
            np.zeros(0),
            np.zeros(0),
            np.zeros((0, len(fields))),
            fields,
            np.zeros(0, object),
        )

    @classmethod
    def concat(cls, parts: Iterable[NavRecords]) -> NavRecords:
        """Records of several files, sorted by satellite then epoch, exact duplicates dropped."""
        parts = list(parts)
        if not parts:
            raise ValueError("concat needs at least one NavRecords")
        kind = parts[0].kind
        if any(p.kind != kind for p in parts):
            raise ValueError("cannot concatenate Keplerian and GLONASS records")
        sat = np.concatenate([p.sat for p in parts]).astype("<U3")
        epoch = np.concatenate([p.epoch_gps_s for p in parts])
        ref = np.concatenate([p.ref_gps_s for p in parts])
        values = np.concatenate([p.values for p in parts])
        source = np.concatenate([p.source for p in parts])
        order = np.lexsort((epoch, sat))
        sat, epoch, ref, values, source = (a[order] for a in (sat, epoch, ref, values, source))
        # the same message received by several stations or listed in several files
        same = np.zeros(len(sat), bool)
        if len(sat) > 1:
            v = np.where(np.isnan(values), 0.0, values)
            same[1:] = (sat[1:] == sat[:-1]) & (epoch[1:] == epoch[:-1])
            same[1:] &= np.all(v[1:] == v[:-1], axis=1)
        keep = ~same
        return cls(
            kind, sat[keep], epoch[keep], ref[keep], values[keep], parts[0].fields, source[keep]
        )


@dataclass(frozen=True)
class RinexNav:
    """Contents of one RINEX navigation file.

    Attributes
    ----------
    path : str
    version : float
    kepler : NavRecords
        GPS, Galileo, BeiDou, QZSS and IRNSS records.
    glonass : NavRecords
    leap_seconds : int or None
        Value of the header's LEAP SECONDS line, if any (the built-in table of
        :mod:`predisat.gnss.timescale` is what converts GLONASS epochs).
    skipped : dict
        Count of records skipped per system letter (SBAS).
    """

    path: str
    version: float
    kepler: NavRecords
    glonass: NavRecords
    leap_seconds: int | None = None
    skipped: dict[str, int] = field(default_factory=dict)

    @classmethod
    def read(cls, path: str | Path) -> RinexNav:
        """Read a RINEX 2 or 3 navigation file (plain or ``.gz``); see :func:`read_rinex_nav`."""
        return read_rinex_nav(path)


def _open_lines(path: Path) -> list[str]:
    return read_text_lines(path, RinexError)


def _parse_header(path: Path, lines: list[str]) -> tuple[float, str, int | None, int]:
    """Version, default system letter, leap seconds and the index of the first data line."""
    if not lines or "RINEX VERSION / TYPE" not in lines[0]:
        raise RinexError(path, 1, "first line is not a 'RINEX VERSION / TYPE' header line")
    head = lines[0]
    try:
        version = float(head[:9])
    except ValueError:
        raise RinexError(path, 1, f"unreadable RINEX version {head[:9]!r}") from None
    ftype = head[20:21].upper()
    sys_letter = head[40:41].upper()
    if version >= 4.0:
        raise RinexError(path, 1, f"RINEX {version} navigation is not supported; use RINEX 2 or 3")
    if version < 3.0:
        if ftype == "G":
            default = "R"
        elif ftype == "H":
            default = "S"
        elif ftype == "N":
            default = sys_letter if sys_letter in "JE" and sys_letter.strip() else "G"
        else:
            raise RinexError(path, 1, f"file type {ftype!r} is not a navigation file (N, G, H)")
    else:
        if ftype != "N":
            raise RinexError(path, 1, f"file type {ftype!r} is not a navigation file ('N')")
        default = sys_letter if sys_letter.strip() else "G"
    leap: int | None = None
    for i, line in enumerate(lines):
        label = line[60:].strip()
        if label == "LEAP SECONDS":
            try:
                leap = int(line[:6])
            except ValueError:
                raise RinexError(path, i + 1, "unreadable LEAP SECONDS value") from None
        elif label == "END OF HEADER":
            return version, default, leap, i + 1
    raise RinexError(
        path, len(lines), "no 'END OF HEADER' line: the file is truncated; copy or download it"
    )


def _fields(path: Path, lineno: int, text: str, start: int, n: int) -> list[float]:
    stripped = text.rstrip()
    if len(stripped) > start and (len(stripped) - start) % 19 != 0:
        raise RinexError(
            path,
            lineno,
            f"line ends inside a 19-character data field (length {len(stripped)}): the line is"
            " cut short or misaligned; copy or download the file again",
        )
    out = []
    for k in range(n):
        s = stripped[start + 19 * k : start + 19 * (k + 1)].strip()
        if not s:
            out.append(np.nan)
            continue
        try:
            m = _FORTRAN_3DIGIT.match(s)
            out.append(float(f"{m[1]}E{m[2]}" if m else _EXPONENT.sub("E", s)))
        except ValueError:
            col = start + 19 * k + 1
            raise RinexError(path, lineno, f"column {col}: {s!r} is not a number") from None
    return out


def _epoch(path: Path, lineno: int, text: str, v3: bool) -> tuple[int, ...]:
    try:
        if v3:
            y, mo, d, h, mi = (int(text[p : p + 3]) for p in (3, 8, 11, 14, 17))
            y = int(text[4:8])
            s = float(text[20:23])
        else:
            y, mo, d, h, mi = (int(text[p : p + 3]) for p in (2, 5, 8, 11, 14))
            s = float(text[17:22])
            y += 1900 if y >= 80 else 2000
    except ValueError:
        raise RinexError(path, lineno, f"unreadable epoch in {text[:23]!r}") from None
    if not (1 <= mo <= 12 and 1 <= d <= 31 and 0 <= h <= 24 and 0 <= mi <= 59 and 0 <= s < 61):
        raise RinexError(path, lineno, f"epoch out of range in {text[:23]!r}")
    return y, mo, d, h, mi, round(s * 1e6)


def read_rinex_nav(path: str | Path) -> RinexNav:
    """Read a RINEX 2 or 3 navigation file.

    Parameters
    ----------
    path : str or Path
        Plain or gzip-compressed RINEX navigation file.

    Returns
    -------
    RinexNav

    Raises
    ------
    RinexError
        If the file is missing, is not navigation data, or has a malformed or truncated record;
        the message names the file and line.
    """
    path = Path(path)
    lines = _open_lines(path)
    version, default_sys, leap, first = _parse_header(path, lines)
    n = len(lines)
    rows: dict[str, list] = {"kepler": [], "glonass": []}
    skipped: dict[str, int] = {}
    i = first
    while i < n:
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        if not line[:3].strip():
            raise RinexError(path, i + 1, "continuation line found where a record should start")
        rec = _record_start(path, line, i + 1, default_sys, version >= 3.0)
        j, n_lines = _record_extent(path, lines, i, rec, version)
        if rec.sys_letter == "S":
            skipped["S"] = skipped.get("S", 0) + 1
            i = j
            continue
        kind, row = _record_row(path, lines, i, rec, n_lines, version >= 3.0)
        rows[kind].append(row)
        i = j
    return RinexNav(
        str(path),
        version,
        _to_records(rows["kepler"], "kepler"),
        _to_records(rows["glonass"], "glonass"),
        leap,
        skipped,
    )


@dataclass(frozen=True)
class _RecordStart:
    """The first line of a navigation record: satellite, where its epoch and fields are."""

    lineno: int  # 1-based
    sys_letter: str
    prn: int
    t_line: str  # the line from the satellite number on (the epoch's columns)
    body_start1: int  # first column of the first line's fields
    body_startn: int  # first column of the continuation lines' fields


def _record_start(
    path: Path, line: str, lineno: int, default_sys: str, v3: bool
) -> _RecordStart:
    """Satellite and field columns of a record's first line (RINEX 3 or 2)."""
    start1, startn = (23, 4) if v3 else (22, 3)
    if v3:
        sys_letter = line[0].upper()
        prn_text = line[1:3]
        t_line = line
        body_start1 = start1
        offset = 0
    else:
        sys_letter = default_sys
        offset = 1 if line[0].isalpha() else 0  # RINEX 2.12 QZSS writes "J 1"
        if offset:
            sys_letter = line[0].upper()
        prn_text = line[offset : offset + 2]
        t_line = line[offset:]
        body_start1 = start1 + offset
    body_startn = startn + offset
    try:
        prn = int(prn_text)
    except ValueError:
        raise RinexError(path, lineno, f"unreadable satellite number {line[:3]!r}") from None
    if sys_letter not in _N_LINES:
        raise RinexError(path, lineno, f"unknown satellite system {sys_letter!r}")
    return _RecordStart(lineno, sys_letter, prn, t_line, body_start1, body_startn)


def _record_extent(
    path: Path, lines: list[str], i: int, rec: _RecordStart, version: float
) -> tuple[int, int]:
    """Index of the line after the record starting at ``lines[i]``, and its number of lines
    (checked against the system's)."""
    n = len(lines)
    n_lines = _N_LINES[rec.sys_letter]
    # a record runs until the next line whose first three columns are not blank
    j = i + 1
    while j < n and (not lines[j][:3].strip()) and lines[j].strip():
        j += 1
    got = j - i
    if rec.sys_letter == "R" and version >= 3.05 and got == 5:
        n_lines = 5
    sat = f"{rec.sys_letter}{rec.prn:02d}"
    if got < n_lines:
        where = "end of file" if j >= n else f"line {j + 1}"
        raise RinexError(
            path,
            rec.lineno,
            f"record of {sat} has {got} of {n_lines} lines (ends at {where}):"
            " the file is truncated or a line is missing; copy or download it again",
        )
    if got > n_lines:
        raise RinexError(path, i + n_lines + 1, f"record of {sat} has extra lines")
    return j, n_lines


def _record_row(
    path: Path, lines: list[str], i: int, rec: _RecordStart, n_lines: int, v3: bool
) -> tuple[str, tuple[str, tuple[int, ...], list[float], str]]:
    """The kind (``"kepler"`` or ``"glonass"``) and row (satellite, epoch, fields, source) of
    the record of ``n_lines`` lines starting at ``lines[i]``; its required fields checked."""
    lineno = rec.lineno
    epoch = _epoch(path, lineno, rec.t_line, v3)
    vals = _fields(path, lineno, lines[i], rec.body_start1, 3)
    for k in range(1, n_lines):
        vals += _fields(path, lineno + k, lines[i + k], rec.body_startn, 4)
    kind = "glonass" if rec.sys_letter == "R" else "kepler"
    required = _REQUIRED_GLONASS if kind == "glonass" else _REQUIRED_KEPLER
    missing = [idx for idx in required if np.isnan(vals[idx])]
    sat = f"{rec.sys_letter}{rec.prn:02d}"
    if missing:
        names = GLONASS_FIELDS if kind == "glonass" else KEPLER_FIELDS
        raise RinexError(
            path,
            lineno,
            f"record of {sat} lacks required field(s) " + ", ".join(names[m] for m in missing),
        )
    return kind, (sat, epoch, vals, f"{path.name}:{lineno}")


def _to_records(rows: list, kind: str) -> NavRecords:
    if not rows:
        return NavRecords.empty(kind)
    fields = KEPLER_FIELDS if kind == "kepler" else GLONASS_FIELDS
    sat = np.array([r[0] for r in rows], "<U3")
    ep = np.array([r[1] for r in rows], np.int64)
    cal_s = calendar_to_gps_s(ep[:, 0], ep[:, 1], ep[:, 2], ep[:, 3], ep[:, 4], ep[:, 5] * 1e-6)
    values = np.full((len(rows), len(fields)), np.nan)
    for k, r in enumerate(rows):
        values[k, : len(r[2])] = r[2]
    source = np.array([r[3] for r in rows], object)
    system = np.array([s[0] for s in sat])
    if kind == "glonass":
        epoch = cal_s + gps_minus_utc_s(cal_s)  # RINEX gives GLONASS epochs in UTC
        ref = epoch
    else:
        # toc on the system's own scale; every system's week starts on Sunday 00:00 of its own
        # scale, so toe (seconds of week) is placed in the week nearest to toc, which is robust
        # against week-number conventions and rollovers in the week field
        bds = system == "C"
        toc_sys = cal_s
        toe_sow = values[:, fields.index("toe_sow_s")]
        toe = np.floor(toc_sys / SECONDS_PER_WEEK) * SECONDS_PER_WEEK + toe_sow
        toe = toe - np.round((toe - toc_sys) / SECONDS_PER_WEEK) * SECONDS_PER_WEEK
        shift = np.where(bds, -BDT_MINUS_GPST_S, 0.0)
        epoch = toc_sys + shift
        ref = toe + shift
    return NavRecords(kind, sat, epoch, ref, values, fields, source)
