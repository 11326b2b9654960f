"""RINEX 2, 3 and 4 broadcast navigation files: GPS, Galileo, BeiDou, QZSS, IRNSS and GLONASS.

A small hand-written reader (see ``docs/ephemerides.md`` for why not georinex): it keeps every
record's raw values in one float table per orbit family, converts every epoch to ``gps_s``, and
rejects a malformed or truncated file with a :class:`RinexError` naming the file, the line and
what is wrong. SBAS records are counted and skipped (they are not used for ranging here).

Supported: RINEX 2.x GPS (``N``), GLONASS (``G``) and QZSS (2.12 ``N``/``J``) navigation files,
RINEX 3.00-3.05 mixed or single-system navigation files, and RINEX 4.00-4.02 files, plain or
gzip-compressed (``.gz``). RINEX 4 wraps every record in a ``> EPH``, ``> ION``, ``> STO`` or
``> EOP`` line naming the satellite and the message type. ``EPH`` records of the legacy messages
(GPS/QZSS/NavIC ``LNAV``, Galileo ``INAV``/``FNAV``, BeiDou ``D1``/``D2``, GLONASS ``FDMA``) have
the RINEX 3.05 layout and land in the same tables; the modernised messages (``CNAV``, ``CNV1``,
``CNV2``, ``CNV3``, ``L1NV``) use orbit models not implemented here and are counted in
:attr:`RinexNav.skipped` (key ``"C CNV1"``, ...) like SBAS (key ``"S"``), except GPS/QZSS
``CNAV`` (IS-GPS-200 30.3.3.1), read into the Keplerian table: its own columns (``cnav`` = 1,
A-dot, delta-n0-dot, the URA indices, TGD and ISCs; :data:`CNAV_FIELDS`) are NaN in every other
record, and the legacy-only columns (IODE, IODC, TGD, accuracy, fit) NaN in it. ``ION`` records
(Klobuchar of GPS/QZSS ``LNAV`` and BeiDou ``D1D2``, Galileo NeQuick-G ``IFNV``) are kept in
:attr:`RinexNav.iono`; ``STO`` and ``EOP`` records are counted and skipped.

Raw values keep the units of the file (RINEX: s, m, rad, rad/s; GLONASS: km, km/s, km/s^2);
:mod:`predisat.gnss.orbits` turns them into positions.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from predisat.fileerror import FileLineError, read_text_lines
from predisat.gnss.timescale import (
    BDT_MINUS_GPST_S,
    LEAP_TABLE_CERTAIN_UNTIL_UTC,
    SECONDS_PER_WEEK,
    calendar_to_gps_s,
    gps_minus_utc_at_gps_s,
    gps_minus_utc_s,
    gps_s_to_text,
    utc_datetime64_to_gps_s,
)
from predisat.readonly import freeze_array_fields

__all__ = [
    "CNAV_FIELDS",
    "GLONASS_FIELDS",
    "KEPLER_FIELDS",
    "KEPLER_SYSTEMS",
    "LEGACY_MESSAGES",
    "IonoMessage",
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
    # GPS/QZSS CNAV only (RINEX 4 "> EPH G.. CNAV"; NaN in every other record): "cnav" is 1.0
    # on a CNAV record; the CNAV record's TGD is kept in "tgd_cnav_s", its "tgd_s" is NaN
    "cnav", "adot_mps", "delta_n_dot_radps2", "top_sow_s",
    "urai_ned0", "urai_ned1", "urai_ned2", "urai_ed", "tgd_cnav_s",
    "isc_l1ca_s", "isc_l2c_s", "isc_l5i5_s", "isc_l5q5_s", "wn_op",
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

CNAV_FIELDS: tuple[str, ...] = (
    "af0_s", "af1_sps", "af2_sps2",
    "adot_mps", "crs_m", "delta_n_radps", "m0_rad",
    "cuc_rad", "e", "cus_rad", "sqrt_a_sqrtm",
    "top_sow_s", "cic_rad", "omega0_rad", "cis_rad",
    "i0_rad", "crc_m", "omega_rad", "omega_dot_radps",
    "idot_radps", "delta_n_dot_radps2", "urai_ned0", "urai_ned1",
    "urai_ed", "health", "tgd_cnav_s", "urai_ned2",
    "isc_l1ca_s", "isc_l2c_s", "isc_l5i5_s", "isc_l5q5_s",
    "transmit_sow_s", "wn_op",
)  # fmt: skip
"""A RINEX 4.01/4.02 GPS/QZSS ``CNAV`` record's values in file order (nine lines), each named
by the :data:`KEPLER_FIELDS` column it lands in. ``sqrt_a_sqrtm`` is sqrt(A0), A0 = A_REF + dA
(IS-GPS-200 30.3.3.1.1.1); ``omega_dot_radps`` is the full rate (not the difference to the
reference rate); toe equals toc (the epoch), so ``toe_sow_s`` is set from it."""

LEGACY_MESSAGES: dict[str, tuple[str, ...]] = {
    "G": ("LNAV",), "J": ("LNAV",), "I": ("LNAV",), "E": ("INAV", "FNAV"),
    "C": ("D1", "D2"), "R": ("FDMA",),
}  # fmt: skip
"""RINEX 4 ``EPH`` message types per system whose records have the RINEX 3.05 layout (read)."""

# RINEX 4 "> ION" records read: system, message -> number of coefficients (the rest skipped)
_ION_MESSAGES = {("G", "LNAV"): 8, ("J", "LNAV"): 8, ("C", "D1D2"): 8, ("E", "IFNV"): 3}
_MAX_VERSION = 4.03  # RINEX 4.00-4.02

_N_LINES = {"G": 8, "E": 8, "C": 8, "J": 8, "I": 8, "R": 4, "S": 4}
_REQUIRED_KEPLER = (*tuple(range(0, 20)), 24)
_REQUIRED_CNAV = (*tuple(range(0, 21)), 24)  # the orbit and clock, dn0-dot and the health
_CNAV_SYSTEMS = "GJ"
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

    def __post_init__(self) -> None:
        freeze_array_fields(self)

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
class IonoMessage:
    """A broadcast ionosphere message of a RINEX 4 ``> ION`` record.

    Attributes
    ----------
    system : str
        System letter of the transmitting satellite (``"G"``, ``"J"``, ``"C"``, ``"E"``).
    message : str
        ``"LNAV"`` (GPS/QZSS Klobuchar), ``"D1D2"`` (BeiDou Klobuchar) or ``"IFNV"`` (Galileo
        NeQuick-G).
    sat : str
        Transmitting satellite.
    epoch_gps_s : float
        Transmission time of the message (on the system's scale, converted to ``gps_s``).
    coefficients : ndarray, shape (8,) or (3,)
        Klobuchar alpha0-3 (s, s/sc, s/sc^2, s/sc^3) then beta0-3 (s, ...), or NeQuick-G
        ai0 (sfu), ai1 (sfu/deg), ai2 (sfu/deg^2), as written in the file.
    source : str
        ``"file:line"`` of the record.
    """

    system: str
    message: str
    sat: str
    epoch_gps_s: float
    coefficients: NDArray
    source: str

    def __post_init__(self) -> None:
        freeze_array_fields(self)


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
        GPST - UTC in s from the header's LEAP SECONDS line, if any (a value counted from BDT is
        converted). The built-in table of :mod:`predisat.gnss.timescale` is what converts
        GLONASS epochs; the header checks it (a disagreement after the table's certain span is
        an error).
    skipped : dict
        Count of records skipped: per system letter (SBAS, ``"S"``) and, in RINEX 4, per
        ``"<system> <message>"`` for modernised ephemerides (``"G CNV2"``) and per record type
        (``"STO"``, ``"EOP"``, ``"ION C CNVX"``, ...).
    iono : tuple of IonoMessage
        RINEX 4 ``> ION`` records, in file order (RINEX 2/3 keep them in the header: see
        :class:`locator.corrections.BroadcastIono`).
    """

    path: str
    version: float
    kepler: NavRecords
    glonass: NavRecords
    leap_seconds: int | None = None
    skipped: dict[str, int] = field(default_factory=dict)
    iono: tuple[IonoMessage, ...] = ()

    @classmethod
    def read(cls, path: str | Path) -> RinexNav:
        """Read a RINEX 2, 3 or 4 navigation file (plain or ``.gz``); see
        :func:`read_rinex_nav`."""
        return read_rinex_nav(path)


def _open_lines(path: Path) -> list[str]:
    return read_text_lines(path, RinexError)


def _parse_header(
    path: Path, lines: list[str]
) -> tuple[float, str, tuple[int, int] | None, int]:
    """Version, default system letter, (GPST - UTC from LEAP SECONDS, its line) and the index of
    the first data line."""
    if not any(line.strip() for line in lines):
        raise RinexError(path, 1, "the file is empty (a failed download or copy?); give the "
                         "navigation file itself")  # fmt: skip
    if "RINEX VERSION / TYPE" not in lines[0]:
        raise RinexError(path, 1, "first line is not a 'RINEX VERSION / TYPE' header line")
    head = lines[0]
    try:
        version = float(head[:9])
    except ValueError:
        raise RinexError(path, 1, f"unreadable RINEX version {head[:9]!r}") from None
    ftype = head[20:21].upper()
    sys_letter = head[40:41].upper()
    if version >= _MAX_VERSION:
        raise RinexError(
            path,
            1,
            f"RINEX {version} navigation is not supported (2.x-4.02); convert it to RINEX 3.05"
            " or 4.02 (e.g. gfzrnx -vo 3)",
        )
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
    leap: tuple[int, int] | None = None
    for i, line in enumerate(lines):
        label = line[60:].strip()
        if label == "LEAP SECONDS":
            try:
                n = int(line[:6])
            except ValueError:
                raise RinexError(path, i + 1, "unreadable LEAP SECONDS value") from None
            # RINEX 3.04+: "BDS" in columns 25-27 counts from BDT, 14 s behind GPST
            leap = (n + (14 if line[24:27].strip() == "BDS" else 0), i + 1)
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
            raise RinexError(
                path, lineno,
                f"column {col}: {s!r} is not a number: the record is damaged; download the "
                "file again (a broadcast file of the day from an IGS data centre), or delete "
                "this satellite's record (its lines from the epoch line on)",
            ) from None  # fmt: skip
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
    """Read a RINEX 2, 3 or 4 navigation file.

    Parameters
    ----------
    path : str or Path
        Plain or gzip-compressed RINEX navigation file (2.x, 3.00-3.05, 4.00-4.02).

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
    version, default_sys, leap_line, first = _parse_header(path, lines)
    leap = None if leap_line is None else leap_line[0]
    if version >= 4.0:
        nav = _read_v4_body(path, lines, version, leap, first)
    else:
        nav = _read_v2_v3_body(path, lines, version, default_sys, leap, first)
    if leap_line is not None:
        _check_leap(path, *leap_line, nav)
    return nav


def _check_leap(path: Path, leap_s: int, line: int, nav: RinexNav) -> None:
    """The header's GPST - UTC against the built-in table over the records' span.

    A leap second announced after the table would put GLONASS epochs (given in UTC) and every UTC
    time a second off: past the table's certain span a disagreement stops the read. Before it,
    IERS is right and the header wrong: a warning, and the table is used.
    """
    t = np.concatenate([nav.kepler.epoch_gps_s, nav.glonass.epoch_gps_s])
    t = t[np.isfinite(t)]
    if t.size == 0:
        return
    span = (float(t.min()), float(t.max()))
    table = {int(v) for v in gps_minus_utc_at_gps_s(np.array(span))}
    if leap_s in table:
        return
    certain = float(utc_datetime64_to_gps_s(np.datetime64(LEAP_TABLE_CERTAIN_UNTIL_UTC)))
    said = (f"LEAP SECONDS gives GPST - UTC = {leap_s} s, but the built-in table (IERS Bulletin C,"
            f" predisat.gnss.timescale.LEAP_SECONDS) gives {' or '.join(map(str, sorted(table)))}"
            f" s over the records ({gps_s_to_text(span[0])} - {gps_s_to_text(span[1])} GPST)")
    if span[1] >= certain:
        raise RinexError(path, line, f"{said}; the table is certain only before "
                         f"{LEAP_TABLE_CERTAIN_UNTIL_UTC}, so a leap second announced since is "
                         "likely missing: GLONASS orbits and UTC times would be seconds off. Add "
                         "it to LEAP_SECONDS, or correct the header if it is wrong")  # fmt: skip
    warnings.warn(f"{path}:{line}: {said}; the header is wrong (IERS holds for these dates) and "
                  "the table is used", stacklevel=3)  # fmt: skip


def _read_v2_v3_body(
    path: Path, lines: list[str], version: float, default_sys: str, leap: int | None, first: int
) -> RinexNav:
    """The records of a RINEX 2 or 3 file after its header."""
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


def _read_v4_body(
    path: Path, lines: list[str], version: float, leap: int | None, first: int
) -> RinexNav:
    """The records of a RINEX 4 file after its header (module docstring)."""
    n = len(lines)
    rows: dict[str, list] = {"kepler": [], "glonass": []}
    skipped: dict[str, int] = {}
    iono: list[IonoMessage] = []
    i = first
    while i < n:
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        if not line.startswith(">"):
            raise RinexError(
                path,
                i + 1,
                f"expected a '> EPH', '> ION', '> STO' or '> EOP' line, found {line[:30]!r}:"
                " a record has extra lines or the file is damaged; download it again",
            )
        rtype, sat, msg = line[2:5], line[6:9].strip(), line[10:].strip()
        j = i + 1
        while j < n and not lines[j].startswith(">"):
            j += 1
        if rtype not in ("EPH", "ION", "STO", "EOP") or len(sat) != 3:
            raise RinexError(
                path,
                i + 1,
                f"unknown record line {line.rstrip()!r}: RINEX 4 records start with"
                " '> EPH|ION|STO|EOP <satellite> <message>'",
            )
        if rtype == "EPH" and not sat[1:].isdigit():
            raise RinexError(path, i + 1, f"unreadable satellite {sat!r} in {line.rstrip()!r}: "
                             "the record line is damaged; download the file again")  # fmt: skip
        if rtype == "EPH" and msg in LEGACY_MESSAGES.get(sat[0], ()):
            if j == i + 1:
                raise RinexError(path, i + 1, f"EPH record of {sat} has no data line: the file is"
                                 " cut or damaged; download it again")  # fmt: skip
            rec = _record_start(path, lines[i + 1], i + 2, sat[0], True)
            if f"{rec.sys_letter}{rec.prn:02d}" != f"{sat[0]}{int(sat[1:]):02d}":
                raise RinexError(
                    path, i + 2, f"record of {line[6:9]} starts with {lines[i + 1][:3]!r}"
                )
            end, n_lines = _record_extent(path, lines, i + 1, rec, version)
            if end != j:
                raise RinexError(path, end + 1, f"record of {sat} has extra lines")
            kind, row = _record_row(path, lines, i + 1, rec, n_lines, True)
            rows[kind].append(row)
        elif rtype == "EPH" and msg == "CNAV" and sat[0] in _CNAV_SYSTEMS:
            rows["kepler"].append(_cnav_row(path, lines, i, j, sat))
        elif rtype == "ION" and (sat[0], msg) in _ION_MESSAGES:
            iono.append(_ion_record(path, lines, i, j, sat, msg))
        else:
            key = "S" if sat[0] == "S" and rtype == "EPH" else f"{rtype} {sat[0]} {msg}"
            key = f"{sat[0]} {msg}" if rtype == "EPH" and key != "S" else key
            skipped[key] = skipped.get(key, 0) + 1
        i = j
    modern = {k: v for k, v in skipped.items() if len(k.split()) == 2}
    if modern:
        warnings.warn(
            f"{path}: {sum(modern.values())} ephemeris record(s) of modernised messages skipped"
            f" ({', '.join(f'{k} {v}' for k, v in sorted(modern.items()))}): their orbit model"
            " is not implemented; the legacy messages (LNAV, INAV, FNAV, D1, D2, FDMA) and"
            " GPS/QZSS CNAV are used",
            stacklevel=2,
        )
    return RinexNav(
        str(path),
        version,
        _to_records(rows["kepler"], "kepler"),
        _to_records(rows["glonass"], "glonass"),
        leap,
        skipped,
        tuple(iono),
    )


def _ion_record(path: Path, lines: list[str], i: int, j: int, sat: str, msg: str) -> IonoMessage:
    """The ``> ION`` record at ``lines[i]`` (its body up to ``lines[j]``)."""
    need = _ION_MESSAGES[(sat[0], msg)]
    if j < i + 2:
        raise RinexError(path, i + 1, f"ION record of {sat} has no data line: the file is cut")
    epoch = _epoch(path, i + 2, lines[i + 1], True)
    vals = _fields(path, i + 2, lines[i + 1], 23, 3)
    for k in range(i + 2, j):
        vals += _fields(path, k + 1, lines[k], 4, 4)
    coef = np.array(vals[:need], float)
    if len(coef) < need or not np.all(np.isfinite(coef)):
        raise RinexError(
            path,
            i + 1,
            f"ION {msg} record of {sat} has {int(np.isfinite(coef).sum())} of {need}"
            " coefficients: a line is missing or cut; download the file again",
        )
    y, mo, d, h, mi, us = epoch
    cal = calendar_to_gps_s(y, mo, d, h, mi, us * 1e-6)
    t = float(cal) - (BDT_MINUS_GPST_S if sat[0] == "C" else 0.0)
    return IonoMessage(sat[0], msg, sat, t, coef, f"{path.name}:{i + 1}")


def _cnav_row(
    path: Path, lines: list[str], i: int, j: int, sat: str
) -> tuple[str, tuple[int, ...], list[float], str]:
    """The Keplerian-table row of the GPS/QZSS ``CNAV`` record at ``lines[i]`` (its nine data
    lines up to ``lines[j]``; :data:`CNAV_FIELDS`), its required fields checked."""
    got = j - i - 1
    if got != 9:
        what = "is cut short" if got < 9 else "has extra lines"
        raise RinexError(path, i + 1, f"CNAV record of {sat} has {got} of 9 data lines: the "
                         f"record {what}; download the file again")  # fmt: skip
    rec = _record_start(path, lines[i + 1], i + 2, sat[0], True)
    if f"{rec.sys_letter}{rec.prn:02d}" != f"{sat[0]}{int(sat[1:]):02d}":
        raise RinexError(path, i + 2, f"record of {sat} starts with {lines[i + 1][:3]!r}")
    epoch = _epoch(path, i + 2, rec.t_line, True)
    vals = _fields(path, i + 2, lines[i + 1], rec.body_start1, 3)
    for k in range(i + 2, i + 9):
        vals += _fields(path, k + 1, lines[k], rec.body_startn, 4)
    vals += _fields(path, i + 10, lines[i + 9], rec.body_startn, 2)  # t_tm, WN_op (4.02: more)
    missing = [CNAV_FIELDS[m] for m in _REQUIRED_CNAV if np.isnan(vals[m])]
    if missing:
        raise RinexError(path, i + 2, f"CNAV record of {sat} lacks required field(s) "
                         + ", ".join(missing))  # fmt: skip
    row = [np.nan] * len(KEPLER_FIELDS)
    for name, v in zip(CNAV_FIELDS, vals, strict=True):
        row[KEPLER_FIELDS.index(name)] = v
    row[KEPLER_FIELDS.index("cnav")] = 1.0
    return sat, epoch, row, f"{path.name}:{i + 2}"


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
        # CNAV: toe = toc (IS-GPS-200 30.3.3.1.1), written into the table for kepler_state
        cnav = values[:, fields.index("cnav")] == 1.0
        if np.any(cnav):
            toe_sow[cnav] = np.mod(toc_sys[cnav], SECONDS_PER_WEEK)
        toe = np.floor(toc_sys / SECONDS_PER_WEEK) * SECONDS_PER_WEEK + toe_sow
        toe = toe - np.round((toe - toc_sys) / SECONDS_PER_WEEK) * SECONDS_PER_WEEK
        shift = np.where(bds, -BDT_MINUS_GPST_S, 0.0)
        epoch = toc_sys + shift
        ref = toe + shift
    return NavRecords(kind, sat, epoch, ref, values, fields, source)
