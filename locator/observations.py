"""RINEX 2.10-2.11, 3.00-3.05 and 4.00-4.02 observation files, plain, gzip or Hatanaka.

A small hand-written reader (the same choice as :mod:`predisat.gnss.rinex_nav`): every observable
becomes one ``(n_epoch, n_sat)`` float array with NaN where absent, epochs become ``gps_s``, and
nothing is dropped silently. Anomalies the reader can live with - an unknown observation code,
an unreadable value, an epoch cut short by the end of the file, a satellite of a system without
observation types - are listed in :attr:`Observations.problems` with the file, the line and the
epoch; ``strict=True`` turns the first of them into a :class:`RinexObsError`.

Supported: RINEX 2.10/2.11 (multi-line ``# / TYPES OF OBSERV``, satellite-list continuation
lines for more than 12 satellites, event flags 1-6), RINEX 3.00-3.05 (``SYS / # / OBS TYPES``,
``>`` epoch lines), RINEX 4.00-4.02 (read as 3.05: the body is unchanged, the new header records
are ignored), plain or gzip-compressed, and Hatanaka-compressed (CRINEX 1.0/3.0, ``.crx``,
``.crx.gz``, ``.YYd``), expanded in memory by the ``hatanaka`` package. Event records
(flags 2-5) are kept in :attr:`Observations.events`; header records among them (flag 4 "header
information follows", flag 3 "new site occupation") apply to the epochs that follow: the
observation types, ``SYS / SCALE FACTOR`` and GLONASS slots. Cycle-slip records (flag 6) are
skipped and reported as events; an epoch flag RINEX does not define (7-9) is reported and its
records skipped.

The pseudorange used for single-frequency ranging is chosen per system from
:data:`DEFAULT_PSEUDORANGE_PRIORITY`, the second of an ionosphere-free pair from
:data:`SECOND_FREQUENCY_PRIORITY` (see ``docs/observations.md``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from predisat.fileerror import FileLineError, read_text_lines
from predisat.gnss.timescale import (
    BDT_MINUS_GPST_S,
    calendar_to_gps_s,
    gps_minus_utc_s,
    gps_s_to_datetime64,
)

__all__ = [
    "DEFAULT_PSEUDORANGE_PRIORITY",
    "SECOND_FREQUENCY_PRIORITY",
    "ObsEvent",
    "ObsHeader",
    "ObsProblem",
    "Observations",
    "PseudorangeSelection",
    "RinexObsError",
    "read_rinex_obs",
]

# RINEX 3/4 observation time systems (TIME OF FIRST OBS, columns 49-51); UTC and TAI are not
_OBS_TIME_SYSTEMS = ("GPS", "GLO", "GAL", "QZS", "BDT", "IRN")

DEFAULT_PSEUDORANGE_PRIORITY: Mapping[str, tuple[str, ...]] = {
    "G": ("C1C", "C1", "C1W", "P1"),  # L1 C/A first; P(Y) on L1 shares the TGD reference
    # QZSS L1 C/A; not C1X, L1C (D+P), whose group delay is TGD plus the ISCs of CNAV-2, which
    # no record read here carries (a user trial, 2026-12-07: it got L1 C/A's TGD alone); GPS
    # leaves its C1X out for the same reason
    "J": ("C1C", "C1"),
    "E": ("C1C", "C1X", "C1B", "C1"),  # E1 (pilot, pilot+data, data; RINEX 2.11 "C1")
    "C": ("C2I", "C2X", "C1I"),  # B1I (RINEX 3.02+ band 2; 3.00-3.01 wrote it as band 1)
    "R": ("C1C", "C1"),  # G1 C/A
    "I": ("C5A", "C5X"),  # NavIC L5 SPS
}
"""Pseudorange codes tried, in order, for single-frequency ranging, per system letter."""

SECOND_FREQUENCY_PRIORITY: Mapping[str, tuple[str, ...]] = {
    # the second code of the ionosphere-free combination with the first (above); a code whose
    # broadcast group delay is not defined against the clock in use (GPS and QZSS L5: CNAV's
    # ISCs; Galileo E5a against an I/NAV clock) leaves the satellite out with the reason
    "G": ("C2W", "P2", "C2", "C2L", "C2X", "C2S"),  # L2 P(Y) first: LNAV's TGD reference
    "J": ("C2L", "C2X", "C2S"),  # QZSS L2C
    "E": ("C7Q", "C7X", "C7I", "C5Q", "C5X", "C5I"),  # E5b (the I/NAV clock's pair), then E5a
    "C": ("C6I", "C6X", "C6Q", "C7I", "C7X", "C7Q"),  # B3I (the clock's reference), then B2I
    "R": ("C2C", "C2P", "C2", "P2"),  # G2
}
"""Second pseudorange codes of the ionosphere-free combination, per system letter (NavIC has
none: its broadcast group delay covers L5 only)."""

_SYSTEMS = "GRECJSI"
# bands defined per system by RINEX 3.05 (table 4); attributes of the same table
_BANDS = {"G": "125", "R": "12346", "E": "15678", "C": "125678", "J": "1256", "S": "15", "I": "59"}
_ATTRIBUTES = set("ABCDEILMNPQSWXYZ")
_V2_TYPES = re.compile(r"^[CPLDS][125678]$")
# date (or blanks, allowed on event lines), two blanks, the flag, the satellite/record count
_V2_EPOCH = re.compile(
    r"^(?: [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d[ \d.]{11}| {26})  [0-6][ \d]{3}"
)
_MAX_VERSION = 4.03  # RINEX 4.00-4.02 observation files read as 3.05 (docs/observations.md)
_FIELD = 16  # F14.3 value, I1 loss-of-lock indicator, I1 signal strength
_GOOD_TAIL = {0, 14, 15}  # where a stripped line may end inside its last 16-character field


class RinexObsError(FileLineError):
    """A RINEX observation file that cannot be read; names the file, the line and the epoch."""


@dataclass(frozen=True)
class ObsProblem:
    """An anomaly tolerated by the reader (strict mode raises it instead).

    Attributes
    ----------
    path : str
    line : int or None
        1-based line number.
    epoch_gps_s : float or None
        The epoch concerned, when there is one.
    what : str
    """

    path: str
    line: int | None
    epoch_gps_s: float | None
    what: str

    @property
    def where(self) -> str:
        """``"file, line N, epoch YYYY-MM-DDThh:mm:ss.sss GPST"``."""
        where = self.path if self.line is None else f"{self.path}, line {self.line}"
        return where + _epoch_text(self.epoch_gps_s)

    def __str__(self) -> str:
        return f"{self.where}: {self.what}"


def _epoch_text(epoch_gps_s: float | None) -> str:
    if epoch_gps_s is None or not np.isfinite(epoch_gps_s):
        return ""
    return f", epoch {str(gps_s_to_datetime64(epoch_gps_s))[:23]} GPST"


@dataclass(frozen=True)
class ObsEvent:
    """An event record (epoch flags 2-6): moving, new site, header data, external event, slips.

    Attributes
    ----------
    line : int
    epoch_gps_s : float
        NaN when the event line carries no date (allowed for flags 2-5).
    flag : int
    records : tuple of str
        The special records that follow the event line, verbatim.
    """

    line: int
    epoch_gps_s: float
    flag: int
    records: tuple[str, ...]


@dataclass(frozen=True)
class ObsHeader:
    """What the header says about the station, receiver and observables.

    Attributes
    ----------
    version : float
    file_system : str
        ``"G"``, ``"R"``, ``"E"``, ``"C"``, ``"J"``, ``"S"``, ``"I"`` or ``"M"`` (mixed).
    marker_name, receiver_type, receiver_version, antenna_type, program : str
    marker_type : str
        RINEX 3's ``MARKER TYPE`` (``"GEODETIC"``, ``"GROUND_CRAFT"``, ...); ``""`` when absent.
    approx_position_ecef_m : ndarray, shape (3,)
        NaN when absent; all zeros in many smartphone files, meaning "unknown".
    antenna_delta_hen_m : ndarray, shape (3,)
        Antenna reference point above the marker: height, east, north.
    obs_types : mapping of system letter to tuple of str
        Observation codes per system, as declared (RINEX 2: the same list for every system).
    interval_s : float
        NaN when absent.
    time_system : str
        ``"GPS"``, ``"GLO"`` (UTC), ``"GAL"``, ``"BDT"``, ``"QZS"`` or ``"IRN"``.
    glonass_slots : mapping of satellite id to frequency number
    scale_factors : mapping of system letter to mapping of code to float
        RINEX 3/4 ``SYS / SCALE FACTOR``: the factor each listed observation type's stored
        values were multiplied by (code ``"*"``: every type of the system); the values of
        :class:`Observations` are divided by it, as the record asks.
    """

    version: float
    file_system: str
    marker_name: str = ""
    receiver_type: str = ""
    receiver_version: str = ""
    antenna_type: str = ""
    program: str = ""
    marker_type: str = ""
    approx_position_ecef_m: NDArray = field(default_factory=lambda: np.full(3, np.nan))
    antenna_delta_hen_m: NDArray = field(default_factory=lambda: np.zeros(3))
    obs_types: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    interval_s: float = float("nan")
    time_system: str = "GPS"
    glonass_slots: Mapping[str, int] = field(default_factory=dict)
    scale_factors: Mapping[str, Mapping[str, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class PseudorangeSelection:
    """One pseudorange per (epoch, satellite), chosen by a per-system priority list.

    Attributes
    ----------
    pseudorange_m : ndarray, shape (n_epoch, n_sat)
        NaN where none of the system's codes has a value.
    code : ndarray of str, shape (n_epoch, n_sat)
        The code used (``""`` where none).
    """

    pseudorange_m: NDArray
    code: NDArray


@dataclass(frozen=True)
class Observations:
    """Contents of one RINEX observation file.

    Attributes
    ----------
    path : str
    header : ObsHeader
    gps_s : ndarray, shape (n_epoch,)
        Receiver-clock epochs converted to ``gps_s``.
    sats : tuple of str
        Satellites with at least one observation, sorted (``"G05"``, ``"R07"``, ...).
    values : mapping of code to ndarray, shape (n_epoch, n_sat)
        Observables in the file's units (m, cycles, Hz, dB-Hz), NaN where absent.
    lli, snr : mapping of code to ndarray of int8, shape (n_epoch, n_sat)
        Loss-of-lock indicator and signal-strength digit, 0 where blank.
    epoch_flag : ndarray of int8, shape (n_epoch,)
        0 OK, 1 power failure since the previous epoch.
    rx_clock_offset_s : ndarray, shape (n_epoch,)
        Receiver clock offset written on the epoch line, NaN where absent.
    epoch_line : ndarray of int, shape (n_epoch,)
        Line of each epoch record, for reports.
    events : tuple of ObsEvent
    problems : tuple of ObsProblem
    crinex : str
        CRINEX version (``"1.0"``, ``"3.0"``) the file was expanded from; ``""`` for plain RINEX.
        Line numbers then count lines of the expanded text.
    """

    path: str
    header: ObsHeader
    gps_s: NDArray
    sats: tuple[str, ...]
    values: Mapping[str, NDArray]
    lli: Mapping[str, NDArray]
    snr: Mapping[str, NDArray]
    epoch_flag: NDArray
    rx_clock_offset_s: NDArray
    epoch_line: NDArray
    events: tuple[ObsEvent, ...] = ()
    problems: tuple[ObsProblem, ...] = ()
    crinex: str = ""

    @classmethod
    def from_rinex(
        cls, path: str | Path, codes: Sequence[str] | None = None, strict: bool = False
    ) -> Observations:
        """Read a RINEX 2, 3 or 4 observation file; see :func:`read_rinex_obs`."""
        return read_rinex_obs(path, codes, strict)

    @property
    def codes(self) -> tuple[str, ...]:
        """Observation codes held, in file order."""
        return tuple(self.values)

    def obs(self, code: str) -> NDArray:
        """Values of one observation code, shape (n_epoch, n_sat); KeyError names the codes."""
        if code not in self.values:
            raise KeyError(f"{self.path}: no observation code {code!r}; it has {self.codes}")
        return self.values[code]

    def where(self, i_epoch: int) -> str:
        """``"file, line N, epoch ... GPST"`` of epoch ``i_epoch``, for messages."""
        return ObsProblem(self.path, int(self.epoch_line[i_epoch]), self.gps_s[i_epoch], "").where

    def pseudorange(
        self, priority: Mapping[str, Sequence[str]] | None = None
    ) -> PseudorangeSelection:
        """The single-frequency pseudorange of each (epoch, satellite).

        Parameters
        ----------
        priority : mapping of system letter to codes, optional
            Codes tried in order (default :data:`DEFAULT_PSEUDORANGE_PRIORITY`); systems absent
            from the mapping get no pseudorange.
        """
        prio = DEFAULT_PSEUDORANGE_PRIORITY if priority is None else priority
        n_t, n_s = len(self.gps_s), len(self.sats)
        out = np.full((n_t, n_s), np.nan)
        code = np.full((n_t, n_s), "", "<U3")
        system = np.array([s[0] for s in self.sats])
        for letter, wanted in prio.items():
            cols = np.nonzero(system == letter)[0]
            for c in wanted:
                if c not in self.values or len(cols) == 0:
                    continue
                v = self.values[c][:, cols]
                take = np.isnan(out[:, cols]) & np.isfinite(v)
                out[:, cols] = np.where(take, v, out[:, cols])
                code[:, cols] = np.where(take, c, code[:, cols])
        return PseudorangeSelection(out, code)


def _is_crinex(first_line: str) -> bool:
    return "COMPACT RINEX" in first_line and "CRINEX VERS" in first_line


def _open_lines(path: Path) -> tuple[list[str], str]:
    """Lines of the RINEX text and the CRINEX version it was expanded from (``""`` if none).

    Hatanaka-compressed files (CRINEX 1.0 for RINEX 2, 3.0 for RINEX 3 and 4; plain or gzip)
    are expanded in memory by the ``hatanaka`` package (the GSI RNXCMP code); line numbers are
    then those of the expanded text, as ``crx2rnx`` would write it.
    """
    lines = read_text_lines(path, RinexObsError)
    if not lines or not _is_crinex(lines[0]):
        return lines, ""
    crinex = lines[0][:20].strip()
    import hatanaka  # only needed for compressed files

    try:
        text = hatanaka.decompress("\n".join(lines).encode("ascii") + b"\n")
    except hatanaka.HatanakaException as exc:
        # RNXCMP names the line of the compressed text: "ERROR at line 144 : ..."
        text = " ".join(str(exc).split())
        at = re.search(r"line (\d+)", text)
        raise RinexObsError(
            path,
            int(at[1]) if at else None,
            f"Hatanaka (CRINEX {crinex}) data cannot be expanded (crx2rnx: {text[:160]}):"
            " the file is damaged or truncated; download it again",
        ) from None
    return text.decode("ascii", errors="replace").splitlines(), crinex


def _float(text: str) -> float:
    s = text.strip()
    return float(s.replace("D", "E").replace("d", "E")) if s else float("nan")


def _known_code(system: str, code: str, v3: bool) -> bool:
    if not v3:
        return bool(_V2_TYPES.match(code))
    if len(code) != 3 or code[0] not in "CLDSX":
        return False
    if code[0] == "X":  # receiver channel numbers (RINEX 3.02+)
        return code[1:] == "1 " or code[1] == "1"
    return code[1] in _BANDS.get(system, "") and code[2] in _ATTRIBUTES


@dataclass(frozen=True)
class _Body:
    """What one pass over the body found, for :func:`_assemble`.

    Attributes
    ----------
    rows : list of (epoch index, satellite, system letter, record text, line)
    epochs : list of (gps_s, flag, receiver clock offset s, line)
    types_at : list of mapping of system letter to codes
        The observation types in force at each epoch.
    scale_at : list of mapping of system letter to mapping of code to factor
        The ``SYS / SCALE FACTOR`` values in force at each epoch (the header's, then those of
        event blocks).
    """

    rows: list[tuple[int, str, str, str, int]]
    epochs: list[tuple[float, int, float, int]]
    types_at: list[dict[str, list[str]]]
    scale_at: list[dict[str, dict[str, float]]]


class _HeaderScan:
    """What the header records say, gathered record by record (:meth:`take`)."""

    def __init__(self) -> None:
        self.kw: dict = {}
        self.types: dict[str, list[str]] = {}
        self.type_line: dict[str, int] = {}
        self.slots: dict[str, int] = {}
        self.v2_types: list[str] = []
        self.last_sys = ""
        self.time_sys = ""
        self.time_sys_line = 0
        self.scale: dict[str, dict[str, float]] = {}
        self.scale_last: tuple[str, float] | None = None

    def take(self, label: str, line: str, i: int, in_event: bool = False) -> None:
        """Record ``line`` (0-based line ``i``) of label ``label``; ValueError if unreadable.

        ``in_event``: a record of an event block (flags 2-5), which changes the values in force
        (RINEX 3.04 6.6): a scale factor for all of a system's types replaces the system's
        factors given before."""
        kw = self.kw
        if label == "MARKER NAME":
            kw["marker_name"] = line[:60].strip()
        elif label == "MARKER TYPE":
            kw["marker_type"] = line[:20].strip().upper()
        elif label == "REC # / TYPE / VERS":
            kw["receiver_type"] = line[20:40].strip()
            kw["receiver_version"] = line[40:60].strip()
        elif label == "ANT # / TYPE":
            kw["antenna_type"] = line[20:40].strip()
        elif label == "PGM / RUN BY / DATE":
            kw["program"] = line[:20].strip()
        elif label == "APPROX POSITION XYZ":
            kw["approx_position_ecef_m"] = np.array([_float(line[k : k + 14]) for k in (0, 14, 28)])
        elif label == "ANTENNA: DELTA H/E/N":
            kw["antenna_delta_hen_m"] = np.array([_float(line[k : k + 14]) for k in (0, 14, 28)])
        elif label == "INTERVAL":
            kw["interval_s"] = _float(line[:10])
        elif label == "TIME OF FIRST OBS":
            self.time_sys = line[48:51].strip()
            self.time_sys_line = i + 1
        elif label == "# / TYPES OF OBSERV":
            self.v2_types += [line[k : k + 6].strip() for k in range(6, 60, 6)]
            self.v2_types = [t for t in self.v2_types if t]
            self.type_line.setdefault("*", i + 1)
        elif label == "SYS / # / OBS TYPES":
            self._sys_types(line, i)
        elif label == "SYS / SCALE FACTOR":
            # A1, 1X, I4 factor, 2X, I2 number of types (0/blank: all), 12(1X,A3); continuation
            # lines 10X,12(1X,A3). A user trial (2026-12-07): ignored, a factor of 10 on C1C
            # gave pseudoranges ten times too long, and calibrate blamed the station position
            if line[0].strip():
                factor = float(int(line[2:6]))
                if factor <= 0:
                    raise ValueError(f"factor {factor:g}")
                self.scale_last = (line[0].upper(), factor)
                if not line[8:10].strip() or int(line[8:10]) == 0:
                    if in_event:
                        self.scale[line[0].upper()] = {}
                    self.scale.setdefault(line[0].upper(), {})["*"] = factor
            if self.scale_last is None:
                raise ValueError("continuation line before any system")
            system, factor = self.scale_last
            for k in range(10, 58, 4):
                code = line[k + 1 : k + 4].strip()
                if code:
                    self.scale.setdefault(system, {})[code] = factor
        elif label == "GLONASS SLOT / FRQ #":
            for k in range(4, 60, 7):
                sat = line[k : k + 3].strip()
                if sat:
                    self.slots[f"R{int(sat[1:]):02d}"] = int(line[k + 3 : k + 6])

    def _sys_types(self, line: str, i: int) -> None:
        types = self.types
        if line[0].strip():
            self.last_sys = line[0].upper()
            types[self.last_sys] = []
            self.type_line[self.last_sys] = i + 1
        if not self.last_sys:
            raise ValueError("continuation line before any system")
        last_sys = self.last_sys
        types[last_sys] += [line[k : k + 3].strip() for k in range(7, 59, 4)]
        types[last_sys] = [t for t in types[last_sys] if t]


class _Reader:
    """State of one pass over a file (problems are collected or raised)."""

    def __init__(
        self, path: Path, lines: list[str], codes: Sequence[str] | None, strict: bool
    ) -> None:
        self.path, self.lines, self.strict = path, lines, strict
        self.codes = None if codes is None else set(codes)
        self.problems: list[ObsProblem] = []
        self.events: list[ObsEvent] = []
        self.slots: dict[str, int] = {}  # GLONASS slots: the header's, then event blocks'
        self.new_slots: dict[str, int] = {}  # those event blocks added

    def problem(self, line: int | None, epoch: float | None, what: str) -> None:
        if self.strict:
            raise RinexObsError(
                self.path,
                line,
                what
                + _epoch_text(epoch).replace(",", " (at", 1)
                + (")" if _epoch_text(epoch) else ""),
            )
        self.problems.append(ObsProblem(str(self.path), line, epoch, what))

    # --------------------------------------------------------------------- header
    def header(self) -> tuple[ObsHeader, int, dict[str, int]]:
        lines, path = self.lines, self.path
        version, file_system = self._version_line()
        scan = _HeaderScan()
        for i, line in enumerate(lines):
            label = line[60:].strip()
            if label == "END OF HEADER":
                first = i + 1
                break
            try:
                scan.take(label, line, i)
            except ValueError as exc:
                raise RinexObsError(path, i + 1, f"unreadable {label!r} record ({exc})") from None
        else:
            raise RinexObsError(path, len(lines), "no 'END OF HEADER' line: the file is truncated")
        v3 = version >= 3.0
        types, type_line = self._obs_types(scan, v3, file_system, first)
        default_ts = {"R": "GLO", "E": "GAL", "C": "BDT", "J": "QZS", "I": "IRN"}
        if scan.time_sys and scan.time_sys not in _OBS_TIME_SYSTEMS:
            raise RinexObsError(
                path, scan.time_sys_line,
                f"time system {scan.time_sys!r} of 'TIME OF FIRST OBS' is not one of RINEX "
                f"observation files ({', '.join(_OBS_TIME_SYSTEMS)}): the epochs' scale is "
                "unknown (a receiver's tags are in its system's time, e.g. GPS); correct the "
                "header's columns 49-51",
            )  # fmt: skip
        scan.kw["time_system"] = scan.time_sys or default_ts.get(file_system, "GPS")
        head = ObsHeader(
            version,
            file_system,
            obs_types={s: tuple(t) for s, t in types.items()},
            glonass_slots=scan.slots,
            scale_factors={k: dict(v) for k, v in scan.scale.items()},
            **scan.kw,
        )
        self.check_codes(head.obs_types, type_line, v3)
        return head, first, type_line

    def _version_line(self) -> tuple[float, str]:
        """RINEX version and file system letter of the first line; raises when unsupported."""
        lines, path = self.lines, self.path
        if not any(line.strip() for line in lines):
            raise RinexObsError(path, 1, "the file is empty (a failed download or copy?); give "
                                "the observation file itself")  # fmt: skip
        if "RINEX VERSION / TYPE" not in lines[0]:
            hint = ""
            if any(k in "".join(lines[:5]) for k in ("utcTimeMillis", "# Raw", "Svid")):
                hint = ("; it looks like an Android GNSS log (device_gnss CSV): give it with "
                        "--device-gnss")  # fmt: skip
            raise RinexObsError(
                path, 1, f"first line is not a 'RINEX VERSION / TYPE' header line{hint}"
            )
        try:
            version = float(lines[0][:9])
        except ValueError:
            raise RinexObsError(path, 1, f"unreadable RINEX version {lines[0][:9]!r}") from None
        if lines[0][20:21].upper() != "O":
            raise RinexObsError(path, 1, "not an observation file (file type is not 'O')")
        if not 2.0 <= version < _MAX_VERSION:
            raise RinexObsError(
                path,
                1,
                f"RINEX {version} observation files are not supported (2.10-4.02);"
                " convert the file to RINEX 3 or 4.02 (e.g. gfzrnx -vo 3)",
            )
        return version, lines[0][40:41].upper().strip() or "G"

    def _obs_types(
        self, scan: _HeaderScan, v3: bool, file_system: str, first: int
    ) -> tuple[dict[str, list[str]], dict[str, int]]:
        """Observation types per system and their header lines (RINEX 2: one list for all)."""
        types, type_line = scan.types, scan.type_line
        if not v3:
            if not scan.v2_types:
                raise RinexObsError(
                    self.path, first, "no '# / TYPES OF OBSERV' record in the header"
                )
            letters = _SYSTEMS if file_system == "M" else file_system
            types = {s: list(scan.v2_types) for s in letters}
            type_line = {s: type_line["*"] for s in letters}
        elif not types:
            raise RinexObsError(self.path, first, "no 'SYS / # / OBS TYPES' record in the header")
        return types, type_line

    def check_codes(self, obs_types: Mapping[str, tuple[str, ...]], where: dict, v3: bool) -> None:
        for s, tt in obs_types.items():
            if s not in _SYSTEMS:
                self.problem(where.get(s), None, f"unknown satellite system {s!r} in the header")
            bad = [t for t in tt if not _known_code(s, t, v3)]
            if bad and (v3 or s == next(iter(obs_types))):
                self.problem(
                    where.get(s),
                    None,
                    f"unknown observation code(s) {', '.join(bad)} for system {s}: kept as"
                    " columns, never used for ranging; check the producer's RINEX version",
                )

    # --------------------------------------------------------------------- body
    def to_gps_s(self, cal: tuple[int, int, int, int, int, float], ts: str) -> float:
        t = float(calendar_to_gps_s(*cal))
        if ts == "GLO":
            return t + float(gps_minus_utc_s(t))
        if ts == "BDT":
            return t - BDT_MINUS_GPST_S
        return t

    def parse_epoch(self, line: str, v3: bool) -> tuple[tuple | None, int, int, float]:
        """(calendar or None, flag, count, clock offset); ValueError when malformed."""
        if v3:
            if not line.startswith(">"):
                raise ValueError("epoch line does not start with '>'")
            date, flag, count = line[2:29], int(line[31:32]), int(line[32:35] or 0)
            clock = _float(line[41:56]) if len(line) > 41 else float("nan")
            if flag > 6:
                raise ValueError(f"epoch flag {flag}, which RINEX does not define (0-6)")
        else:
            if not _V2_EPOCH.match(line):
                raise ValueError("not an epoch line")
            date, flag, count = line[1:26], int(line[28]), int(line[29:32] or 0)
            clock = _float(line[68:80]) if len(line) > 68 else float("nan")
        if not date.strip():
            if flag < 2:
                raise ValueError("epoch line without a date")
            return None, flag, count, clock
        parts = date.split()
        y, mo, d, h, mi = (int(p) for p in parts[:5])
        s = float(parts[5])
        if not v3:
            y += 1900 if y >= 80 else 2000
        if not (1 <= mo <= 12 and 1 <= d <= 31 and 0 <= h <= 23 and 0 <= mi <= 59 and s < 61):
            raise ValueError("date out of range")
        return (y, mo, d, h, mi, s), flag, count, clock

    def body(self, head: ObsHeader, first: int) -> _Body:
        lines, n = self.lines, len(self.lines)
        v3 = head.version >= 3.0
        types = {s: list(t) for s, t in head.obs_types.items()}
        scale = {s: dict(f) for s, f in head.scale_factors.items()}
        self.slots = dict(head.glonass_slots)
        ts = head.time_system
        default_sys = "G" if head.file_system == "M" else head.file_system
        rows: list[tuple[int, str, str, str, int]] = []  # epoch index, sat, system, text, line
        epochs: list[tuple[float, int, float, int]] = []  # gps_s, flag, clock, line
        types_at: list[dict[str, list[str]]] = []
        scale_at: list[dict[str, dict[str, float]]] = []
        i = first
        while i < n:
            line = lines[i]
            if not line.strip():
                i += 1
                continue
            try:
                cal, flag, count, clock = self.parse_epoch(line, v3)
            except (ValueError, IndexError) as exc:
                i = self._skip_to_epoch(i, v3, str(exc))
                continue
            t = float("nan") if cal is None else self.to_gps_s(cal, ts)
            if 2 <= flag <= 5:
                types, scale = self._event(i, t, flag, count, types, scale, v3, default_sys)
                i += 1 + count
                continue
            sats, j = self._sat_list(line, count, i, v3, default_sys, t)
            if sats is None:
                break  # truncated satellite list: reported, nothing more to read
            per_sat = (
                [1] * count if v3 else [max(1, -(-len(types.get(s[0], [])) // 5)) for s in sats]
            )
            need = sum(per_sat)
            cut = self._cut_record(i, j, need, t, v3)
            if cut is not None:
                i = cut
                continue
            if flag == 6:
                self.events.append(ObsEvent(i + 1, t, 6, tuple(lines[j : j + need])))
                i = j + need
                continue
            e = len(epochs)
            epochs.append((t, flag, clock, i + 1))
            types_at.append(types)
            scale_at.append(scale)
            sats_or_none = sats if not v3 else [None] * count
            new_rows, i = self._records(e, sats_or_none, per_sat, j, t, v3, default_sys)
            rows += new_rows
        return _Body(rows, epochs, types_at, scale_at)

    def _skip_to_epoch(self, i: int, v3: bool, why: str = "") -> int:
        """Report the stray line ``i`` and return the index of the next epoch line."""
        lines, n = self.lines, len(self.lines)
        self.problem(
            i + 1,
            None,
            f"epoch line with an {why}: its records skipped up to the next epoch line"
            if why.startswith("epoch flag")
            else f"expected an epoch line, found {lines[i][:40]!r}; skipped up to the next "
            "epoch line",
        )
        i += 1
        while i < n and not self._looks_like_epoch(lines[i], v3):
            i += 1
        return i

    def _event(
        self,
        i: int,
        t: float,
        flag: int,
        count: int,
        types: dict[str, list[str]],
        scale: dict[str, dict[str, float]],
        v3: bool,
        default_sys: str,
    ) -> tuple[dict[str, list[str]], dict[str, dict[str, float]]]:
        """Keep the event record at line ``i`` (flags 2-5); the observation types and scale
        factors after it.

        Its header records apply to the epochs that follow (RINEX 3.04 6.6: "Each value remains
        valid until changed by an additional header record"): flag 4 announces them, flag 3
        (new site) has at least MARKER NAME, and a header record is one in any event block. Until
        2026-12-07 only flag 4's observation types were taken: a scale factor, or types after
        flag 3, left the later values silently wrong (by a factor of 10, or C2W read as C1C).
        """
        recs = tuple(self.lines[i + 1 : i + 1 + count])
        if len(recs) < count:
            self.problem(
                i + 1,
                t,
                f"event record announces {count} lines, the file"
                f" ends after {len(recs)}: the file is truncated",
            )
        self.events.append(ObsEvent(i + 1, t, flag, recs))
        types = self._redefine(types, recs, i + 2, v3, default_sys)
        scan = _HeaderScan()
        scan.scale = {s: dict(f) for s, f in scale.items()}
        for k, r in enumerate(recs):
            label = r[60:].strip()
            if label not in ("SYS / SCALE FACTOR", "GLONASS SLOT / FRQ #"):
                continue
            try:
                scan.slots = {}
                scan.take(label, r, i + 1 + k, in_event=True)
            except (ValueError, IndexError) as exc:
                raise RinexObsError(
                    self.path, i + 2 + k,
                    f"unreadable {label!r} record in the event block of line {i + 1} ({exc}): "
                    "the values of the epochs after it cannot be read; correct the record",
                ) from None  # fmt: skip
            self._take_slots(scan.slots, i + 2 + k, t)
        return types, scan.scale

    def _take_slots(self, slots: Mapping[str, int], line: int, t: float) -> None:
        """GLONASS slots of an event block: a new one is taken; one that differs from the
        header's is reported (the file holds one channel per slot: the first is kept)."""
        for sat, k in slots.items():
            if sat not in self.slots:
                self.slots[sat] = self.new_slots[sat] = k
            elif self.slots[sat] != k:
                self.problem(
                    line, t,
                    f"GLONASS SLOT / FRQ # gives {sat} frequency channel {k}, the file's header "
                    f"{self.slots[sat]}: one channel per slot is kept (the first); split the "
                    "file at this event to use the new one",
                )  # fmt: skip

    def _cut_record(self, i: int, j: int, need: int, t: float, v3: bool) -> int | None:
        """Where to go on when the epoch at line ``i`` lacks some of its ``need`` observation
        lines from ``j`` on (reported, epoch dropped); None when it has them all."""
        lines, n = self.lines, len(self.lines)
        if j + need > n or (v3 and any(lines[k].startswith(">") for k in range(j, j + need))):
            got = sum(1 for k in range(j, min(n, j + need)) if not lines[k].startswith(">"))
            self.problem(
                i + 1,
                t,
                f"epoch record has {got} of {need} observation lines:"
                " the file is truncated or a line is missing; epoch dropped",
            )
            return j + got
        return None

    def _records(
        self,
        e: int,
        sats: Sequence[str | None],
        per_sat: list[int],
        j: int,
        t: float,
        v3: bool,
        default_sys: str,
    ) -> tuple[list[tuple[int, str, str, str, int]], int]:
        """Observation records of epoch ``e`` from line ``j``; rows and the next line index.

        ``sats`` are the satellites of the RINEX 2 epoch line (None in RINEX 3, where each
        record names its satellite); ``per_sat`` the lines of each record.
        """
        lines = self.lines
        rows = []
        k = j
        for s, m in zip(sats, per_sat, strict=True):
            if v3:
                s = self._sat_id(lines[k][:3], default_sys)
                text = lines[k][3:]
            else:
                text = "".join(lines[k + q][:80].ljust(80) for q in range(m))
                for q in range(m):
                    if len(lines[k + q].rstrip()) % _FIELD not in _GOOD_TAIL:
                        self.problem(
                            k + q + 1,
                            t,
                            f"observation line of {s} ends inside a"
                            " 16-character field: cut short or misaligned",
                        )
            if s is None:  # RINEX 3: the record's first 3 characters are no satellite id
                self.problem(
                    k + 1,
                    t,
                    f"observation record starts with {lines[k][:3]!r}, not a satellite id "
                    "(letter and two digits, e.g. G05): the line is damaged; record dropped",
                )
                k += m
                continue
            rows.append((e, s, s[0] if s else "", text, k + 1))
            k += m
        return rows, k

    def _looks_like_epoch(self, line: str, v3: bool) -> bool:
        return line.startswith(">") if v3 else bool(_V2_EPOCH.match(line))

    def _sat_id(self, text: str, default_sys: str) -> str | None:
        letter = text[0].upper() if text[:1].strip() else default_sys
        try:
            return f"{letter}{int(text[1:3]):02d}"
        except ValueError:
            return None

    def _sat_list(
        self, line: str, count: int, i: int, v3: bool, default_sys: str, t: float
    ) -> tuple[list[str] | None, int]:
        if v3:
            return [], i + 1
        lines, n = self.lines, len(self.lines)
        text = line[32:68]
        j = i + 1
        while len(text) < 3 * count:
            if j >= n:
                self.problem(
                    i + 1,
                    t,
                    "satellite list continues past the end of the file: the file is truncated",
                )
                return None, j
            text = text.ljust(36 * ((len(text) + 35) // 36)) + lines[j][32:68]
            j += 1
        sats = []
        for k in range(count):
            s = self._sat_id(text[3 * k : 3 * k + 3], default_sys)
            if s is None:
                self.problem(i + 1, t, f"unreadable satellite {text[3 * k : 3 * k + 3]!r}")
                s = "?00"
            sats.append(s)
        return sats, j

    def _redefine(
        self,
        types: dict[str, list[str]],
        recs: tuple[str, ...],
        line0: int,
        v3: bool,
        default_sys: str,
    ) -> dict[str, list[str]]:
        """Observation types after a flag-4 event whose header records redefine them."""
        found: dict[str, list[str]] = {}
        last = ""
        for r in recs:
            label = r[60:].strip()
            if label == "# / TYPES OF OBSERV":
                found.setdefault("*", [])
                found["*"] += [x for x in (r[q : q + 6].strip() for q in range(6, 60, 6)) if x]
            elif label == "SYS / # / OBS TYPES":
                if r[0].strip():
                    last = r[0].upper()
                    found[last] = []
                found.setdefault(last, [])
                found[last] += [x for x in (r[q : q + 3].strip() for q in range(7, 59, 4)) if x]
        if not found:
            return types
        new = {s: list(t) for s, t in types.items()}
        if "*" in found:
            new = {s: list(found["*"]) for s in (new or {default_sys: []})}
        new.update({s: v for s, v in found.items() if s != "*"})
        self.check_codes({s: tuple(v) for s, v in new.items()}, dict.fromkeys(new, line0), v3)
        return new


def _assemble(reader: _Reader, head: ObsHeader, parsed: _Body) -> Observations:
    rows, epochs, types_at = parsed.rows, parsed.epochs, parsed.types_at
    if reader.new_slots:
        head = replace(head, glonass_slots={**head.glonass_slots, **reader.new_slots})
    n_t = len(epochs)
    gps_s = np.array([e[0] for e in epochs], float)
    sats = tuple(sorted({r[1] for r in rows if r[1] and r[1][0] in _SYSTEMS}))
    col = {s: k for k, s in enumerate(sats)}
    v3 = head.version >= 3.0
    start_code_order = _code_order(reader, head, types_at)
    values = {c: np.full((n_t, len(sats)), np.nan) for c in start_code_order}
    lli = {c: np.zeros((n_t, len(sats)), np.int8) for c in start_code_order}
    snr = {c: np.zeros((n_t, len(sats)), np.int8) for c in start_code_order}
    reported_sys: set[str] = set()
    for e, sat, system, text, lineno in rows:
        t = gps_s[e]
        if sat not in col:
            if system not in reported_sys:
                reported_sys.add(system)
                reader.problem(
                    lineno,
                    t,
                    f"satellite {sat!r} of an unknown system; its observations are ignored",
                )
            continue
        tt = types_at[e].get(system)
        if tt is None:
            if system not in reported_sys:
                reported_sys.add(system)
                reader.problem(
                    lineno,
                    t,
                    f"satellite {sat} of system {system}, which has no"
                    " observation types in the header; its observations are ignored",
                )
            continue
        scale = parsed.scale_at[e].get(system, {})
        for c, f in _fields(reader, sat, tt, text, lineno, t, v3):
            if c not in values:
                continue
            try:
                # RINEX writes a missing observation as blanks or 0.0: NYA1's 2024 day has
                # 117 C2W and 7 676 C2X pseudoranges of 0.000, taken as ranges until
                # 2026-12-07 (a residual of 40 788 km in an ionosphere-free fit)
                if f[:14].strip() and float(f[:14]) != 0.0:
                    values[c][e, col[sat]] = float(f[:14]) / scale.get(c, scale.get("*", 1.0))
                if f[14:15].strip():
                    lli[c][e, col[sat]] = int(f[14])
                if f[15:16].strip():
                    snr[c][e, col[sat]] = int(f[15])
            except ValueError:
                reader.problem(lineno, t, f"{sat} {c}: unreadable field {f!r}; left empty")
    # an epoch not after the one before (repeated, or time going back) is dropped: kept, it
    # left the table out of time order, and the message contradicted itself (a user trial)
    keep = np.ones(len(gps_s), bool)
    last = -np.inf
    for k, tk in enumerate(gps_s):
        if tk <= last:
            keep[k] = False
            reader.problem(epochs[k][3], tk, "epoch not after the one before (repeated, or "
                           "time going back): dropped")  # fmt: skip
        else:
            last = tk
    if not keep.all():
        gps_s = gps_s[keep]
        epochs = [e for e, kept in zip(epochs, keep, strict=True) if kept]
        values = {c: v[keep] for c, v in values.items()}
        lli = {c: v[keep] for c, v in lli.items()}
        snr = {c: v[keep] for c, v in snr.items()}
    _report_unknown_values(reader, head, values, gps_s, epochs, v3)
    return Observations(
        str(reader.path),
        head,
        gps_s,
        sats,
        values,
        lli,
        snr,
        np.array([e[1] for e in epochs], np.int8),
        np.array([e[2] for e in epochs], float),
        np.array([e[3] for e in epochs], np.int64),
        tuple(reader.events),
        tuple(reader.problems),
    )


def _code_order(
    reader: _Reader, head: ObsHeader, types_at: list[dict[str, list[str]]]
) -> list[str]:
    """Codes kept (``reader.codes``), in order of first declaration (header, then events)."""
    start_code_order: list[str] = []
    for tt in [head.obs_types, *types_at]:
        for lst in tt.values():
            for c in lst:
                if c not in start_code_order and (reader.codes is None or c in reader.codes):
                    start_code_order.append(c)
    return start_code_order


def _fields(
    reader: _Reader, sat: str, tt: Sequence[str], text: str, lineno: int, t: float, v3: bool
) -> list[tuple[str, str]]:
    """(code, 16-character field) of one satellite's observation record, blank fields left
    out; a RINEX 3 line cut inside a field or too long is reported (its cut field dropped)."""
    stripped = text.rstrip() if v3 else text
    if v3:
        tail = len(stripped) % _FIELD
        if tail not in _GOOD_TAIL or len(stripped) > _FIELD * len(tt):
            reader.problem(
                lineno,
                t,
                f"observation line of {sat} ends inside a 16-character"
                " field or is too long: cut short or misaligned; kept the"
                " complete fields",
            )
    out = []
    for k, c in enumerate(tt):
        if v3:
            f = stripped[_FIELD * k : _FIELD * (k + 1)]
        else:
            q, r = divmod(k, 5)
            f = text[80 * q + _FIELD * r : 80 * q + _FIELD * (r + 1)]
        if not f.strip():
            continue
        if v3 and len(f) < 14 and k == len(stripped) // _FIELD:
            continue  # the cut field reported above
        out.append((c, f))
    return out


def _report_unknown_values(
    reader: _Reader,
    head: ObsHeader,
    values: Mapping[str, NDArray],
    gps_s: NDArray,
    epochs: list[tuple[float, int, float, int]],
    v3: bool,
) -> None:
    for s, tt in head.obs_types.items():
        for c in tt:
            if _known_code(s, c, v3) or c not in values:
                continue
            has = np.nonzero(np.any(np.isfinite(values[c]), axis=1))[0]
            if len(has):
                reader.problems.append(
                    ObsProblem(
                        str(reader.path),
                        int(epochs[has[0]][3]),
                        float(gps_s[has[0]]),
                        f"unknown code {c} ({s}) has values in {len(has)}"
                        " epoch(s), first here; not used for ranging",
                    )
                )


def read_rinex_obs(
    path: str | Path, codes: Sequence[str] | None = None, strict: bool = False
) -> Observations:
    """Read a RINEX 2, 3 or 4 observation file, plain, gzip or Hatanaka-compressed.

    Parameters
    ----------
    path : str or Path
        RINEX 2.10/2.11/3.0x/4.00-4.02 observation file: plain, gzip-compressed or
        Hatanaka-compressed (CRINEX, optionally gzipped), recognised by content, not by name.
    codes : sequence of str, optional
        Observation codes to keep (default: all); keeps memory small for long files.
    strict : bool
        Raise :class:`RinexObsError` at the first anomaly instead of listing it in
        :attr:`Observations.problems`.

    Returns
    -------
    Observations

    Raises
    ------
    RinexObsError
        If the file is missing, not an observation file, has an unreadable header, or (strict)
        any anomaly: truncated epoch, unknown code, unreadable value, stray line.
    """
    path = Path(path)
    lines, crinex = _open_lines(path)
    reader = _Reader(path, lines, codes, strict)
    try:
        head, first, _ = reader.header()
        parsed = reader.body(head, first)
        if not parsed.epochs:
            # raised, not only recorded: nothing could be done with the file (a user trial's
            # header-only file ended in a numpy message)
            raise RinexObsError(
                path, first + 1, "no complete observation epoch in the file: it holds a header "
                "only, or is cut short in its first epoch; give the whole file",
            )
    except RinexObsError as exc:
        if not crinex:
            raise
        raise RinexObsError(
            path, exc.line, exc.what + f" (CRINEX {crinex}: the line of the expanded RINEX text)"
        ) from None
    obs = _assemble(reader, head, parsed)
    return replace(obs, crinex=crinex) if crinex else obs
