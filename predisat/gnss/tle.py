"""Two-line elements (TLE) for coarse planning: reader and SGP4 propagation to ECEF.

Propagation uses the ``sgp4`` package (the reference implementation of Vallado et al., vectorised
with ``SatrecArray``). Its TEME output is rotated to the Earth-fixed frame by Greenwich mean
sidereal time (IAU 1982, as in the TEME definition) with UT1 taken as UTC and polar motion
neglected; the resulting directions agree with skyfield's to about 0.01 deg. TLE orbits of GNSS
satellites are good to a few kilometres near their epoch: use them to plan, never to locate.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sgp4.api import Satrec, SatrecArray

from predisat.fileerror import FileLineError
from predisat.gnss.timescale import gps_minus_utc_s, gps_s_to_utc_datetime64
from predisat.readonly import freeze_array_fields

__all__ = ["TleError", "TleSet", "read_tle", "satellite_id_from_name", "teme_to_ecef"]

_JD_UNIX_EPOCH = 2440587.5
_ID = re.compile(r"^([GRECJIS])(\d{2})$")
_PRN = re.compile(r"\bPRN\s*([0-9]{1,3})\b", re.IGNORECASE)
_NAME_SYSTEM = (
    ("GPS", "G"),
    ("NAVSTAR", "G"),
    ("GSAT", "E"),
    ("GALILEO", "E"),
    ("BEIDOU", "C"),
    ("QZS", "J"),
    ("IRNSS", "I"),
)


class TleError(FileLineError):
    """A TLE file that cannot be read; the message names the file, the line and the fix."""


def satellite_id_from_name(name: str) -> str | None:
    """GNSS satellite id (``"G05"``) from a TLE title line, or None if it names none.

    Understands RTKLIB-style titles (``"G32"``, ``"C02 # Beidou G6"``) and CelesTrak titles
    (``"GPS BIIR-2  (PRN 13)"``, ``"GSAT0101 (PRN E11)"``, ``"BEIDOU-3 M1 (C19)"``). GLONASS
    titles carry no slot number: map those with ``names=`` in :func:`read_tle`.
    """
    text = name.split("#")[0].strip().upper()
    m = _ID.match(text)
    if m:
        return f"{m[1]}{m[2]}"
    m = re.search(r"\((?:PRN\s*)?([GRECJI])(\d{1,2})\)", text)
    if m:
        return f"{m[1]}{int(m[2]):02d}"
    m = _PRN.search(text)
    if m:
        for key, letter in _NAME_SYSTEM:
            if key in text:
                return f"{letter}{int(m[1]):02d}"
    return None


def _gmst1982_rad(jd_ut1: NDArray) -> NDArray:
    t = (jd_ut1 - 2451545.0) / 36525.0
    g = 67310.54841 + (8640184.812866 + (0.093104 + (-6.2e-6) * t) * t) * t
    return np.mod(np.mod(jd_ut1, 1.0) + g / 86400.0, 1.0) * 2.0 * np.pi


def teme_to_ecef(teme_m: ArrayLike, jd_ut1: ArrayLike) -> NDArray:
    """Rotate TEME vectors to the Earth-fixed frame (GMST 1982, no polar motion).

    Parameters
    ----------
    teme_m : array_like, shape (..., 3)
    jd_ut1 : array_like, shape broadcastable to (...)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    v = np.asarray(teme_m, float)
    th = _gmst1982_rad(np.asarray(jd_ut1, float))
    c, s = np.cos(th), np.sin(th)
    x, y = v[..., 0], v[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y, v[..., 2]], axis=-1)


def _jd_utc(gps_s: NDArray) -> NDArray:
    utc = gps_s_to_utc_datetime64(gps_s)
    unix_s = (utc - np.datetime64("1970-01-01T00:00:00", "ns")) / np.timedelta64(1, "s")
    return _JD_UNIX_EPOCH + unix_s / 86400.0


@dataclass(frozen=True)
class TleSet:
    """Satellites of a TLE file.

    Attributes
    ----------
    sats : tuple of str
        Satellite ids (``"G05"``) or, where the title names none, the title itself.
    names : tuple of str
        Title lines as written.
    line1, line2 : tuple of str
    epochs_gps_s : ndarray, shape (n_sat,)
        TLE epochs in ``gps_s``.
    path : str
    """

    sats: tuple[str, ...]
    names: tuple[str, ...]
    line1: tuple[str, ...]
    line2: tuple[str, ...]
    epochs_gps_s: NDArray
    path: str

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @classmethod
    def read(cls, path: str | Path, names: Mapping[str, str] | None = None) -> TleSet:
        """Read a TLE file (see :func:`read_tle`)."""
        return read_tle(path, names)

    def position_ecef(
        self, gps_s: ArrayLike, sats: Sequence[str] | None = None
    ) -> tuple[NDArray, NDArray]:
        """SGP4 positions in the Earth-fixed frame.

        Parameters
        ----------
        gps_s : array_like, shape (n_epoch,)
        sats : sequence of str, optional
            Default: all of :attr:`sats`. Unknown ids give NaN.

        Returns
        -------
        pos_ecef_m : ndarray, shape (n_epoch, n_sat, 3)
            NaN where SGP4 reports an error or the satellite is unknown.
        sgp4_error : ndarray of int, shape (n_epoch, n_sat)
            SGP4's error code (0 = fine; -1 for an unknown satellite).
        """
        t = np.atleast_1d(np.asarray(gps_s, float))
        want = list(self.sats) if sats is None else list(sats)
        lookup = {s: i for i, s in enumerate(self.sats)}
        idx = np.array([lookup.get(s, -1) for s in want], np.intp)
        pos = np.full((len(t), len(want), 3), np.nan)
        err = np.full((len(t), len(want)), -1, np.int16)
        known = np.nonzero(idx >= 0)[0]
        if len(known) and len(t):
            arr = SatrecArray([Satrec.twoline2rv(self.line1[i], self.line2[i]) for i in idx[known]])
            jd = _jd_utc(t)
            jd_int = np.floor(jd)
            e, r, _ = arr.sgp4(jd_int, jd - jd_int)  # (n_sat, n_epoch[, 3]) km TEME
            ecef = teme_to_ecef(np.transpose(r, (1, 0, 2)) * 1000.0, jd[:, None])
            e = e.T
            ok = e == 0
            ecef[~ok] = np.nan
            pos[:, known] = ecef
            err[:, known] = e
        return pos, err


def read_tle(path: str | Path, names: Mapping[str, str] | None = None) -> TleSet:
    """Read a file of two- or three-line element sets.

    Lines starting with ``#`` are comments. A title line before the two element lines names
    the satellite; ``names`` maps titles or NORAD catalogue numbers (as strings) to ids where
    :func:`satellite_id_from_name` cannot tell (GLONASS).

    Raises
    ------
    TleError
        If the file is missing, a line 1 is not followed by its line 2, or a checksum or element
        is wrong (message names the file and line).
    """
    path = Path(path)
    if not path.is_file():
        raise TleError(path, None, "no such file; check the path")
    lines = path.read_text(encoding="ascii", errors="replace").splitlines()
    names = dict(names or {})
    out: dict[str, list] = {"sats": [], "names": [], "l1": [], "l2": [], "ep": []}
    title = ""
    i = 0
    while i < len(lines):
        raw = lines[i].rstrip()
        if not raw.strip() or raw.startswith("#"):
            i += 1
            continue
        if raw.startswith("1 ") and len(raw) >= 64:
            if i + 1 >= len(lines) or not lines[i + 1].startswith("2 "):
                raise TleError(path, i + 1, "line 1 of an element set is not followed by line 2")
            l1, l2 = raw, lines[i + 1].rstrip()
            for k, ln in ((i + 1, l1), (i + 2, l2)):
                if len(ln) < 68:
                    raise TleError(path, k, f"element line has {len(ln)} of 69 characters")
                if len(ln) >= 69 and ln[68].isdigit():
                    digits = sum(int(c) for c in ln[:68] if c.isdigit())
                    total = (digits + ln[:68].count("-")) % 10
                    if total != int(ln[68]):
                        raise TleError(path, k, f"checksum {ln[68]} does not match ({total})")
            if l1[2:7] != l2[2:7]:
                raise TleError(path, i + 2, "lines 1 and 2 carry different catalogue numbers")
            try:
                sat = Satrec.twoline2rv(l1, l2)
            except (ValueError, IndexError) as exc:
                raise TleError(path, i + 1, f"unreadable elements ({exc})") from None
            norad = l1[2:7].strip()
            sid = names.get(title) or names.get(norad) or satellite_id_from_name(title)
            sid = sid or title or norad
            if sid in out["sats"]:
                # two sets under one id (a replaced satellite): the later one keeps the id, as
                # in files appended over time; the earlier becomes "R17:28915"
                k = out["sats"].index(sid)
                out["sats"][k] = f"{sid}:{out['l1'][k][2:7].strip()}"
            out["sats"].append(sid)
            out["names"].append(title)
            out["l1"].append(l1)
            out["l2"].append(l2)
            epoch_unix_s = (sat.jdsatepoch + sat.jdsatepochF - _JD_UNIX_EPOCH) * 86400.0
            utc_s = epoch_unix_s - 315964800.0  # 1980-01-06 in Unix seconds
            out["ep"].append(utc_s + float(gps_minus_utc_s(utc_s)))
            title = ""
            i += 2
            continue
        if raw.startswith(("1 ", "2 ")) and len(raw) >= 60:
            raise TleError(path, i + 1, "element line out of order (line 2 without line 1)")
        title = raw.strip()
        i += 1
    if not out["sats"]:
        raise TleError(path, None, "no element sets found")
    return TleSet(
        tuple(out["sats"]),
        tuple(out["names"]),
        tuple(out["l1"]),
        tuple(out["l2"]),
        np.array(out["ep"]),
        str(path),
    )
