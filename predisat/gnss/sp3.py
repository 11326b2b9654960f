"""SP3-c and SP3-d precise orbit files: reader and interpolation.

Positions are interpolated with a Lagrange polynomial (default 11 points, degree 10) over the
file's epochs in ECEF, which reproduces held-out 15-minute IGS epochs to the centimetre level;
clocks are interpolated linearly between neighbouring epochs (clock noise makes higher orders
useless). Nothing is extrapolated: outside the file's first and last epoch, across gaps, or
where a satellite has no data in the interpolation window, the result is NaN.

SP3 positions refer to the satellite's centre of mass (broadcast ephemerides refer to the
antenna phase centre; the difference is 0.5-2.5 m for GPS and GLONASS, mostly radial).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.fileerror import FileLineError, read_text_lines
from predisat.gnss.timescale import calendar_to_gps_s, gps_minus_utc_s
from predisat.readonly import freeze_array_fields

__all__ = ["Sp3", "Sp3Error", "read_sp3"]

_BAD_CLOCK_US = 999999.0


class Sp3Error(FileLineError):
    """An SP3 file that cannot be read; the message names the file, the line and the fix."""


@dataclass(frozen=True)
class Sp3:
    """Precise orbits and clocks of one or more SP3 files.

    Attributes
    ----------
    sats : tuple of str, length n_sat
        Satellite ids (``"G01"``, ``"R07"``, ...).
    epochs_gps_s : ndarray, shape (n_epoch,)
        Tabulated epochs, strictly increasing, in ``gps_s``.
    pos_ecef_m : ndarray, shape (n_epoch, n_sat, 3)
        Centre-of-mass positions, NaN where the file has none.
    clock_s : ndarray, shape (n_epoch, n_sat)
        Clock offsets, NaN where the file marks them bad (999999.999999) or has none.
    time_system : str
        The files' time system (``"GPS"``, ``"UTC"``, ...), already converted to GPST.
    coord_system : str
        Reference frame named in the header (``"IGS05"``, ``"IGS20"``, ...).
    paths : tuple of str
    """

    sats: tuple[str, ...]
    epochs_gps_s: NDArray
    pos_ecef_m: NDArray
    clock_s: NDArray
    time_system: str
    coord_system: str
    paths: tuple[str, ...]

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @classmethod
    def read(cls, paths: str | Path | Sequence[str | Path]) -> Sp3:
        """Read and merge SP3 files (see :func:`read_sp3`)."""
        return read_sp3(paths)

    @property
    def interval_s(self) -> float:
        """Median spacing of the tabulated epochs."""
        if len(self.epochs_gps_s) < 2:
            return float("nan")
        return float(np.median(np.diff(self.epochs_gps_s)))

    def _sat_index(self, sats: Sequence[str] | None) -> NDArray:
        if sats is None:
            return np.arange(len(self.sats))
        lookup = {s: i for i, s in enumerate(self.sats)}
        return np.array([lookup.get(s, -1) for s in sats], np.intp)

    def position_at(
        self, gps_s: ArrayLike, sats: Sequence[str] | None = None, n_points: int = 11
    ) -> NDArray:
        """Interpolated centre-of-mass positions.

        Parameters
        ----------
        gps_s : array_like, shape (n_epoch,)
        sats : sequence of str, optional
            Satellites (default: all of :attr:`sats`); unknown ids give NaN.
        n_points : int
            Lagrange interpolation points (degree ``n_points - 1``).

        Returns
        -------
        ndarray, shape (n_epoch, n_sat, 3)
            ECEF metres; NaN outside the tabulated span, across gaps and where data are missing.
        """
        t = np.atleast_1d(np.asarray(gps_s, float))
        isat = self._sat_index(sats)
        n_ep = len(self.epochs_gps_s)
        out = np.full((len(t), len(isat), 3), np.nan)
        if n_points < 2:
            raise ValueError(f"n_points must be at least 2, got {n_points}")
        k = min(n_points, n_ep)
        if k < 2:
            return out
        ep = self.epochs_gps_s
        pos = np.concatenate([self.pos_ecef_m, np.full((n_ep, 1, 3), np.nan)], axis=1)[:, isat]
        inside = (t >= ep[0]) & (t <= ep[-1])
        i = np.searchsorted(ep, t)
        start = np.clip(i - k // 2, 0, n_ep - k)
        max_span = (k - 1) * self.interval_s * 1.001
        for s0 in np.unique(start[inside]):
            q = np.nonzero(inside & (start == s0))[0]
            tw = ep[s0 : s0 + k]
            if tw[-1] - tw[0] > max_span:
                continue  # a gap in the tabulation: refuse rather than interpolate badly
            scale = tw[-1] - tw[0]
            x = (tw - tw[0]) / scale
            xq = (t[q] - tw[0]) / scale
            diff = xq[:, None] - x[None, :]  # (nq, k)
            w = np.ones((len(q), k))
            for j in range(k):
                others = np.delete(np.arange(k), j)
                w[:, j] = np.prod(diff[:, others], axis=1) / np.prod(x[j] - x[others])
            block = pos[s0 : s0 + k].reshape(k, -1)
            out[q] = (w @ block).reshape(len(q), len(isat), 3)
        return out

    def clock_at(self, gps_s: ArrayLike, sats: Sequence[str] | None = None) -> NDArray:
        """Linearly interpolated clock offsets, shape (n_epoch, n_sat), seconds (NaN if none)."""
        t = np.atleast_1d(np.asarray(gps_s, float))
        isat = self._sat_index(sats)
        n_ep = len(self.epochs_gps_s)
        out = np.full((len(t), len(isat)), np.nan)
        if n_ep < 2:
            return out
        ep = self.epochs_gps_s
        clk = np.concatenate([self.clock_s, np.full((n_ep, 1), np.nan)], axis=1)[:, isat]
        inside = (t >= ep[0]) & (t <= ep[-1])
        i1 = np.clip(np.searchsorted(ep, t), 1, n_ep - 1)
        i0 = i1 - 1
        gap = (ep[i1] - ep[i0]) > 1.001 * self.interval_s
        f = ((t - ep[i0]) / (ep[i1] - ep[i0]))[:, None]
        val = clk[i0] * (1.0 - f) + clk[i1] * f
        ok = inside & ~gap
        out[ok] = val[ok]
        return out


def _read_text(path: Path) -> list[str]:
    return read_text_lines(path, Sp3Error)


def _sat_id(text: str) -> str:
    s = text.strip()
    if len(s) <= 2:  # SP3-a style GPS ids without a letter
        return f"G{int(s):02d}"
    return f"{s[0] if s[0] != ' ' else 'G'}{int(s[1:]):02d}"


_TIME_SYSTEMS = ("GPS", "GAL", "QZS", "IRN", "UTC", "GLO", "TAI", "BDT")

_Calendar = tuple[int, int, int, int, int, float]


@dataclass(frozen=True)
class _Body:
    """The epochs of one SP3 file: calendar, positions (NaN: none) and clocks per epoch line."""

    calendar: list[_Calendar]
    pos: list[NDArray]
    clk: list[NDArray]
    epoch_line: list[int]


def _read_one(path: Path) -> tuple[list[str], NDArray, NDArray, NDArray, str, str]:
    """Satellites, epochs (gps_s), positions (m), clocks (s), time system and frame of a file."""
    lines = _read_text(path)
    if not lines or not lines[0].startswith("#") or lines[0][1:2] not in ("c", "d", "a", "b"):
        raise Sp3Error(path, 1, "first line must start with '#c' or '#d' (SP3-c/d)")
    coord = lines[0][46:51].strip()
    sats, time_system, i = _read_header(path, lines)
    body = _read_body(path, lines, i, sats)
    ep = np.array(body.calendar)
    cal_s = calendar_to_gps_s(ep[:, 0], ep[:, 1], ep[:, 2], ep[:, 3], ep[:, 4], ep[:, 5])
    t = _to_gps_s(cal_s, time_system)
    if np.any(np.diff(t) <= 0):
        bad = int(np.nonzero(np.diff(t) <= 0)[0][0]) + 1
        raise Sp3Error(path, body.epoch_line[bad], "epochs are not strictly increasing")
    return sats, t, np.array(body.pos), np.array(body.clk), time_system, coord


def _read_header(path: Path, lines: list[str]) -> tuple[list[str], str, int]:
    """The header's satellites and time system, and the index of the first epoch line."""
    n_sats_header = None
    sats: list[str] = []
    time_system = "GPS"
    ts_line = None
    seen_pct_c = False
    i = 1
    n = len(lines)
    while i < n and not lines[i].startswith("*"):
        line = lines[i]
        if line.startswith("+ "):
            if n_sats_header is None:
                try:
                    n_sats_header = int(line[3:6])
                except ValueError:
                    raise Sp3Error(path, i + 1, "unreadable number of satellites") from None
            _add_header_sats(path, i + 1, line, sats, n_sats_header)
        elif line.startswith("%c") and not seen_pct_c:
            seen_pct_c = True
            # SP3-a/b leave the field as the placeholder 'ccc' (their epochs are GPS time)
            time_system = line[9:12].strip().replace("ccc", "") or "GPS"
            ts_line = i + 1
        elif line.startswith("EOF"):
            break
        i += 1
    if i >= n or not lines[i].startswith("*"):
        raise Sp3Error(path, n, "no epoch line ('*  YYYY ...'): the file is truncated")
    if n_sats_header is None or len(sats) != n_sats_header:
        raise Sp3Error(path, 3, f"header lists {len(sats)} satellites, expected {n_sats_header}")
    if time_system not in _TIME_SYSTEMS:
        raise Sp3Error(path, ts_line, f"unknown time system {time_system!r} in the first '%c' "
                       f"line (columns 10-12: one of {', '.join(_TIME_SYSTEMS)}); correct it")
    return sats, time_system, i


def _add_header_sats(
    path: Path, line_no: int, line: str, sats: list[str], n_sats_header: int
) -> None:
    """Append the satellite ids of a ``+`` header line to ``sats`` (up to ``n_sats_header``)."""
    body = line[9:60]
    for k in range(0, len(body) - 2, 3):
        tok = body[k : k + 3]
        if tok.strip() and tok.strip() != "0" and len(sats) < n_sats_header:
            try:
                sats.append(_sat_id(tok))
            except ValueError:
                raise Sp3Error(path, line_no, f"unreadable satellite id {tok!r}") from None


def _read_body(path: Path, lines: list[str], start: int, sats: list[str]) -> _Body:
    """The epochs from line index ``start`` (the first ``*`` line) to ``EOF``, checked complete."""
    col = {s: j for j, s in enumerate(sats)}
    body = _Body([], [], [], [])
    counts: list[int] = []
    eof = False
    for j in range(start, len(lines)):
        line = lines[j]
        if line.startswith("*"):
            body.calendar.append(_epoch_calendar(path, j + 1, line))
            body.pos.append(np.full((len(sats), 3), np.nan))
            body.clk.append(np.full(len(sats), np.nan))
            counts.append(0)
            body.epoch_line.append(j + 1)
        elif line.startswith("P"):
            sat, xyz, c_us = _position_record(path, lines, j)
            if sat not in col:
                raise Sp3Error(path, j + 1, f"satellite {sat} is not listed in the header")
            if any(v != 0.0 for v in xyz):
                body.pos[-1][col[sat]] = np.array(xyz) * 1000.0
            if abs(c_us) < _BAD_CLOCK_US:
                body.clk[-1][col[sat]] = c_us * 1e-6
            counts[-1] += 1
        elif line.startswith("EOF"):
            eof = True
            break
        elif line[:2] in ("EP", "EV") or line.startswith("V") or not line.strip():
            continue
        elif line.startswith(("/*", "%", "+", "#")):
            raise Sp3Error(path, j + 1, "header line after the first epoch: the file is malformed")
        else:
            raise Sp3Error(path, j + 1, f"unexpected record {line[:20]!r}")
    for k, c in enumerate(counts):
        if c != len(sats):
            raise Sp3Error(
                path,
                body.epoch_line[k],
                f"epoch has {c} position records, the header lists {len(sats)} satellites"
                + (": the file is truncated" if k == len(counts) - 1 else ""),
            )
    if not eof:
        raise Sp3Error(path, len(lines), "no 'EOF' line: the file is truncated")
    return body


def _epoch_calendar(path: Path, line_no: int, line: str) -> _Calendar:
    """Year, month, day, hour, minute and second of an epoch (``*``) line."""
    try:
        y, mo, d, h, mi = (int(x) for x in line[3:31].split()[:5])
        s = float(line[3:31].split()[5])
    except (ValueError, IndexError):
        raise Sp3Error(path, line_no, f"unreadable epoch line {line.strip()!r}") from None
    return (y, mo, d, h, mi, s)


def _position_record(path: Path, lines: list[str], j: int) -> tuple[str, list[float], float]:
    """Satellite, X, Y, Z (km) and clock (microseconds) of the ``P`` record ``lines[j]``."""
    line = lines[j]
    try:
        sat = _sat_id(line[1:4])
        xyz = [float(line[4 + 14 * q : 18 + 14 * q]) for q in range(3)]
        c_text = line[46:60].strip()
        c_us = float(c_text) if c_text else _BAD_CLOCK_US
    except ValueError:
        cut = not any(x.strip() for x in lines[j + 1 :])
        fix = (
            "the file ends here without 'EOF': it was cut short, download it again"
            if cut
            else "a 'P' record holds the satellite and X, Y, Z in km in columns 5-46; "
            "the file is damaged, download it again"
        )
        raise Sp3Error(path, j + 1, f"unreadable position record {line[:60]!r}; {fix}") from None
    return sat, xyz, c_us


def _to_gps_s(cal_s: NDArray, time_system: str) -> NDArray:
    """Calendar seconds of ``time_system`` converted to ``gps_s``."""
    if time_system in ("UTC", "GLO"):
        return np.asarray(cal_s + gps_minus_utc_s(cal_s))
    if time_system == "TAI":
        return np.asarray(cal_s - 19.0)
    if time_system == "BDT":
        return np.asarray(cal_s + 14.0)
    return cal_s


def read_sp3(paths: str | Path | Sequence[str | Path]) -> Sp3:
    """Read one or more SP3-c/d files (plain or ``.gz``) and merge them.

    Consecutive daily files are merged on the union of their satellites; an epoch present in
    several files (day boundaries) keeps the value of the later file.

    Raises
    ------
    Sp3Error
        If a file is missing, malformed or truncated (message names the file and line), or if
        the files mix time systems.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    parts = [(Path(p), _read_one(Path(p))) for p in paths]
    if not parts:
        raise ValueError("read_sp3 needs at least one path")
    systems = {p[1][4] for p in parts}
    if len(systems) > 1:
        raise Sp3Error(parts[0][0], None, f"files mix time systems {sorted(systems)}")
    all_sats = sorted({s for _, part in parts for s in part[0]})
    all_t = np.unique(np.concatenate([part[1] for _, part in parts]))
    pos = np.full((len(all_t), len(all_sats), 3), np.nan)
    clk = np.full((len(all_t), len(all_sats)), np.nan)
    for _, (sats, t, p, c, _, _) in parts:
        ti = np.searchsorted(all_t, t)
        si = np.array([all_sats.index(s) for s in sats])
        pos[np.ix_(ti, si)] = p
        clk[np.ix_(ti, si)] = c
    return Sp3(
        tuple(all_sats),
        all_t,
        pos,
        clk,
        parts[0][1][4],
        parts[0][1][5],
        tuple(str(p) for p, _ in parts),
    )
