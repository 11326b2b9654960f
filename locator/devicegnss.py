"""Smartphone measurements in the Google Smartphone Decimeter Challenge format.

The GSDC 2022/2023 data sets (Kaggle "Google Smartphone Decimeter Challenge", Google's
``device_gnss.csv``) give, per Android ``GnssMeasurement``, the raw pseudorange *and* what Google
computed for it from broadcast navigation: the satellite position at the signal's transmission
time (``SvPositionX/Y/ZEcefMeters``, in the Earth-fixed frame of that instant), the satellite clock
with relativity and group delay (``SvClockBiasMeters``), the inter-signal range bias to GPS L1
(``IsrbMeters``) and the broadcast-model ionospheric and tropospheric delays. The corrected
pseudorange is, per the data set's description,

    ``rho = RawPseudorangeMeters + SvClockBiasMeters - IsrbMeters - IonosphericDelayMeters
    - TroposphericDelayMeters``

so a phone log of that format carries its own orbit and clock source: :class:`DeviceGnssSource`
feeds it to :func:`locator.run.run_locator` like :class:`locator.sources.RinexSource` (it only
rotates the satellite positions into the frame of reception, ``omega_E tau``). Ground truth
(``ground_truth.csv``, a NovAtel SPAN reference; GSDC 2021 ``*_ground_truth.csv`` too) is read by
:func:`read_ground_truth`, and :func:`device_residuals` gives the residuals at the truth for
``locator calibrate`` and the leave-one-receiver-out check.

Signals map to RINEX codes (:data:`SIGNAL_CODES`: ``GPS_L1`` is ``C1C``, ``GAL_E1`` ``C1C``,
``GPS_L5`` ``C5Q``, ...) so that error-model files name them the same way; the single-frequency
pseudorange is chosen per system by :data:`DEFAULT_SIGNAL_PRIORITY` (the L1 band). Rows of an
unknown constellation or signal are listed in :attr:`DeviceGnss.problems` with their line, never
dropped silently; a missing column or an unreadable number raises :class:`DeviceGnssError`
naming the file, the line and the fix.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.corrections import OMEGA_E_RADPS, uncorrected_iono_sigma_m
from locator.errorfit import Residuals
from locator.observations import ObsProblem
from locator.sources import EpochData, check_odometer
from predisat.availability.satellites import select_satellites
from predisat.fileerror import FileLineError, read_text_lines
from predisat.geodesy import ecef_to_geodetic, enu_rotation, enu_to_azel, geodetic_to_ecef
from predisat.gnss.errormodel import ReceiverProfile
from predisat.gnss.orbits import C_MPS
from predisat.gnss.timescale import utc_datetime64_to_gps_s
from predisat.jsontypes import JsonDict

__all__ = [
    "DEFAULT_SIGNAL_PRIORITY",
    "SIGNAL_CODES",
    "DeviceGnss",
    "DeviceGnssError",
    "DeviceGnssSource",
    "GroundTruth",
    "device_profile",
    "device_residuals",
    "read_device_gnss",
    "read_ground_truth",
]


class DeviceGnssError(FileLineError):
    """A ``device_gnss.csv`` or ground-truth file that cannot be read (file, line, fix)."""


# Android GnssStatus constellation types (android.location.GnssStatus.CONSTELLATION_*).
_CONSTELLATION = {1: "G", 3: "R", 4: "J", 5: "C", 6: "E", 7: "I"}

SIGNAL_CODES: Mapping[str, tuple[str, str]] = {
    "GPS_L1": ("G", "C1C"), "GPS_L1_CA": ("G", "C1C"), "GPS_L5": ("G", "C5Q"),
    "GPS_L5_Q": ("G", "C5Q"), "GAL_E1": ("E", "C1C"), "GAL_E1_C_P": ("E", "C1C"),
    "GAL_E5A": ("E", "C5Q"), "GAL_E5A_Q": ("E", "C5Q"), "GLO_G1": ("R", "C1C"),
    "GLO_G1_CA": ("R", "C1C"), "BDS_B1I": ("C", "C2I"), "BDS_B1C": ("C", "C1P"),
    "BDS_B1C_P": ("C", "C1P"), "BDS_B2A": ("C", "C5P"), "BDS_B2A_P": ("C", "C5P"),
    "QZS_J1": ("J", "C1C"), "QZS_J1_CA": ("J", "C1C"), "QZS_J5": ("J", "C5Q"),
    "QZS_J5_Q": ("J", "C5Q"), "IRN_S": ("I", "C9A"), "IRN_L5": ("I", "C5A"),
    "IRN_L5_A": ("I", "C5A"),
}  # fmt: skip
"""GSDC ``SignalType`` to (system letter, RINEX 3 pseudorange code): Android reports the pilot
(``Q``/``C``/``P``) components for L5, E1 and B1C (``CodeType``)."""

DEFAULT_SIGNAL_PRIORITY: Mapping[str, tuple[str, ...]] = {
    "G": ("C1C",), "E": ("C1C",), "R": ("C1C",), "C": ("C2I", "C1P"), "J": ("C1C",),
    "I": ("C5A",),
}  # fmt: skip
"""Codes tried, in order, for single-frequency ranging (the L1 band, as the RINEX default)."""

_COLUMNS = (
    "utcTimeMillis", "Svid", "ConstellationType", "SignalType", "ArrivalTimeNanosSinceGpsEpoch",
    "RawPseudorangeMeters", "SvPositionXEcefMeters", "SvPositionYEcefMeters",
    "SvPositionZEcefMeters", "SvClockBiasMeters", "IsrbMeters", "IonosphericDelayMeters",
    "TroposphericDelayMeters", "CarrierFrequencyHz", "Cn0DbHz",
)  # fmt: skip
_WLS = ("WlsPositionXEcefMeters", "WlsPositionYEcefMeters", "WlsPositionZEcefMeters")
# the per-signal quantities held as (n_epoch, n_sat) arrays
_FIELDS = ("raw_pseudorange_m", "sv_x_m", "sv_y_m", "sv_z_m", "sv_clock_bias_m", "isrb_m",
           "iono_m", "tropo_m", "carrier_hz", "cn0_dbhz")  # fmt: skip


def _sat_id(path: Path, line: int, ctype: int, svid: int) -> str | None:
    """``"G05"`` of an Android constellation type and svid (None: not a satellite we know)."""
    letter = _CONSTELLATION.get(ctype)
    if letter is None:
        return None
    if letter == "J" and 193 <= svid <= 202:
        svid -= 192  # QZSS PRN 193-202 are J01-J10 in RINEX
    if letter == "R" and svid > 24:
        return None  # 93-106: a frequency channel, the slot is not known
    if not 1 <= svid <= 99:
        raise DeviceGnssError(path, line, f"Svid {svid} is out of range for constellation "
                              f"{ctype}; the row is damaged (re-export the file)")  # fmt: skip
    return f"{letter}{svid:02d}"


@dataclass(frozen=True)
class DeviceGnss:
    """Contents of one ``device_gnss.csv`` file, per epoch and satellite.

    Attributes
    ----------
    path : str
    gps_s : ndarray, shape (n_epoch,)
        Reception time (``ArrivalTimeNanosSinceGpsEpoch``), GPS seconds.
    utc_ms : ndarray of int64, shape (n_epoch,)
        ``utcTimeMillis`` of the epoch (the key of the ground truth).
    sats : tuple of str, length n_sat
        Satellites, sorted (``"E11"``, ``"G02"``, ...).
    signals : mapping of code to mapping of field to ndarray, shape (n_epoch, n_sat)
        Per RINEX code (:data:`SIGNAL_CODES`) the fields ``raw_pseudorange_m``, ``sv_x_m``,
        ``sv_y_m``, ``sv_z_m`` (ECEF at transmission, metres), ``sv_clock_bias_m``, ``isrb_m``,
        ``iono_m``, ``tropo_m`` (metres), ``carrier_hz``, ``cn0_dbhz`` and ``line`` (the CSV
        line, 0 where absent); NaN where absent.
    wls_ecef_m : ndarray, shape (n_epoch, 3)
        The phone's own weighted-least-squares fix (Google's), NaN where absent.
    problems : tuple of ObsProblem
        Rows left out, with file, line and why.
    """

    path: str
    gps_s: NDArray
    utc_ms: NDArray
    sats: tuple[str, ...]
    signals: Mapping[str, Mapping[str, NDArray]]
    wls_ecef_m: NDArray
    problems: tuple[ObsProblem, ...] = field(default=())

    @classmethod
    def from_csv(cls, path: str | Path) -> DeviceGnss:
        """Read a GSDC ``device_gnss.csv``; see :func:`read_device_gnss`."""
        return read_device_gnss(path)

    @property
    def codes(self) -> tuple[str, ...]:
        """RINEX codes held, sorted."""
        return tuple(sorted(self.signals))

    def corrected_m(self, code: str) -> NDArray:
        """Corrected pseudoranges of one code (module docstring), shape (n_epoch, n_sat).

        A row without ``IonosphericDelayMeters`` keeps its delay (taken as 0 here;
        :class:`DeviceGnssSource` inflates its sigma); any other missing term gives NaN.
        """
        s = self.signals[code]
        iono = np.nan_to_num(s["iono_m"], nan=0.0)
        return s["raw_pseudorange_m"] + s["sv_clock_bias_m"] - s["isrb_m"] - iono - s["tropo_m"]

    def where(self, epoch: int) -> str:
        """``"file, lines A-B (epoch ... UTC)"`` of an epoch, for messages."""
        lines = np.concatenate([s["line"][epoch] for s in self.signals.values()])
        lines = lines[lines > 0]
        span = f"lines {lines.min()}-{lines.max()}" if lines.size else "no line"
        return f"{self.path}, {span} (utcTimeMillis {int(self.utc_ms[epoch])})"


def _number(path: Path, line: int, row: Mapping[str, str], col: str) -> float:
    text = (row.get(col) or "").strip()
    if text == "":
        return float("nan")
    try:
        return float(text)
    except ValueError:
        raise DeviceGnssError(path, line, f"column {col} holds {text!r}, not a number; fix or "
                              "delete the row") from None  # fmt: skip


def read_device_gnss(path: str | Path) -> DeviceGnss:
    """Read a Google Smartphone Decimeter Challenge ``device_gnss.csv`` (2022/2023 format).

    Parameters
    ----------
    path : path-like
        The CSV (plain or gzip), header row first, one ``Raw`` measurement per row.

    Returns
    -------
    DeviceGnss

    Raises
    ------
    DeviceGnssError
        Missing file or column, a non-numeric value, a satellite measured twice on one signal
        in one epoch, no usable row.
    """
    p = Path(path)
    lines = read_text_lines(p, DeviceGnssError)
    if not lines:
        raise DeviceGnssError(p, None, "empty file; give a device_gnss.csv with its header row")
    reader = csv.DictReader(lines)
    cols = reader.fieldnames or []
    missing = [c for c in _COLUMNS if c not in cols]
    if missing:
        raise DeviceGnssError(p, 1, f"no column {', '.join(missing)}: not a GSDC device_gnss.csv "
                              "(2022/2023 format; a GnssLogger raw log must be converted first)")
    problems: list[ObsProblem] = []
    rows: list[tuple[int, int, str, str, list[float], list[float]]] = []
    for k, row in enumerate(reader):
        line = k + 2
        if (row.get("MessageType") or "Raw") != "Raw":
            continue
        ms, ctype, svid = (_number(p, line, row, c) for c in
                           ("utcTimeMillis", "ConstellationType", "Svid"))  # fmt: skip
        if not (np.isfinite(ms) and np.isfinite(ctype) and np.isfinite(svid)):
            raise DeviceGnssError(p, line, "utcTimeMillis, ConstellationType and Svid must all be "
                                  "given; fix or delete the row")  # fmt: skip
        _check_ms(p, line, "utcTimeMillis", ms, _UTC_MS_RANGE)
        if not (abs(ctype) < 1e6 and abs(svid) < 1e6):
            raise DeviceGnssError(p, line, "ConstellationType or Svid is out of range; the row is "
                                  "damaged (re-export the file)")  # fmt: skip
        sat = _sat_id(p, line, int(ctype), int(svid))
        sig = (row.get("SignalType") or "").strip()
        code = SIGNAL_CODES.get(sig)
        if sat is None or code is None:
            why = ("no SignalType (Google's processing gave it no satellite position)" if not sig
                   else f"signal {sig!r} not supported" if sat is not None
                   else "constellation or svid not supported")  # fmt: skip
            problems.append(ObsProblem(str(p), line, None, f"constellation {int(ctype)} svid "
                                       f"{int(svid)}: {why}; row left out"))  # fmt: skip
            continue
        if code[0] != sat[0]:
            raise DeviceGnssError(p, line, f"SignalType {sig} is not of constellation "
                                  f"{int(ctype)} ({sat}); the row is damaged")  # fmt: skip
        vals = [_number(p, line, row, c) for c in _COLUMNS[5:]]
        fix = [_number(p, line, row, c) for c in _WLS if c in cols]
        t = _number(p, line, row, "ArrivalTimeNanosSinceGpsEpoch")
        rows.append((line, int(ms), sat, code[1], [t, *vals], fix))
    if not rows:
        raise DeviceGnssError(p, None, "no usable Raw measurement row; check the file")
    epochs = sorted({r[1] for r in rows})
    sats = tuple(sorted({r[2] for r in rows}))
    ie = {m: i for i, m in enumerate(epochs)}
    js = {s: j for j, s in enumerate(sats)}
    shape = (len(epochs), len(sats))
    signals: dict[str, dict[str, NDArray]] = {}
    t_rx = np.full(len(epochs), np.nan)
    wls = np.full((len(epochs), 3), np.nan)
    for line, ms, sat, rinex_code, vals, w in rows:
        s = signals.setdefault(rinex_code, {f: np.full(shape, np.nan) for f in _FIELDS}
                               | {"line": np.zeros(shape, np.int64)})  # fmt: skip
        i, j = ie[ms], js[sat]
        if s["line"][i, j]:
            raise DeviceGnssError(p, line, f"{sat} {rinex_code} measured twice at utcTimeMillis "
                                  f"{ms} (also line {s['line'][i, j]}); keep one row")
        s["line"][i, j] = line
        for f, v in zip(_FIELDS, vals[1:], strict=True):
            s[f][i, j] = v
        if np.isfinite(vals[0]):
            t = vals[0] * 1e-9
            if np.isfinite(t_rx[i]) and abs(t - t_rx[i]) > 1e-3:
                raise DeviceGnssError(p, line, f"ArrivalTimeNanosSinceGpsEpoch differs by "
                                      f"{abs(t - t_rx[i]):.3g} s within utcTimeMillis {ms}; the "
                                      "rows of one epoch must share a reception time")
            t_rx[i] = t
        if len(w) == 3 and np.all(np.isfinite(w)):
            wls[i] = w
    utc = np.array(epochs, np.int64)
    # no arrival time: the UTC epoch on the GPS scale (the leap seconds added)
    from_utc = _utc_ms_to_gps_s(utc)
    off = np.abs(t_rx - from_utc)
    bad = np.flatnonzero(np.isfinite(t_rx) & ~(off < 1.0))
    if bad.size:
        line = min(r[0] for r in rows if r[1] == epochs[int(bad[0])])
        raise DeviceGnssError(p, line, f"ArrivalTimeNanosSinceGpsEpoch lies {off[bad[0]]:.3g} s "
                              f"from utcTimeMillis {epochs[int(bad[0])]} (+ leap seconds); one "
                              "of them is damaged")  # fmt: skip
    gps = np.where(np.isfinite(t_rx), t_rx, from_utc)
    return DeviceGnss(str(p), gps, utc, sats, signals, wls, tuple(problems))


# plausible times, milliseconds: the GPS epoch (1980-01-06) to 2100-01-01
_UTC_MS_RANGE = (315964800000.0, 4102444800000.0)
_GPS_MS_RANGE = (0.0, 4102444800000.0 - 315964800000.0)


def _check_ms(path: Path, line: int, col: str, ms: float, span: tuple[float, float]) -> None:
    if not span[0] <= ms <= span[1]:
        raise DeviceGnssError(path, line, f"{col} {ms:g} is not a time between 1980 and 2100; "
                              "the row is damaged (re-export the file)")  # fmt: skip


def _utc_ms_to_gps_s(utc_ms: ArrayLike) -> NDArray:
    t = np.asarray(utc_ms, np.int64).astype("datetime64[ms]")
    return utc_datetime64_to_gps_s(t)


@dataclass(frozen=True)
class GroundTruth:
    """Reference antenna positions of a phone log.

    Attributes
    ----------
    path : str
    gps_s : ndarray, shape (n,)
        Increasing.
    ecef_m : ndarray, shape (n, 3)
    """

    path: str
    gps_s: NDArray
    ecef_m: NDArray

    def at(self, gps_s: ArrayLike, max_gap_s: float = 0.5) -> NDArray:
        """Positions at ``gps_s`` (linear between records), shape (..., 3).

        Raises ValueError naming the file when a time lies more than ``max_gap_s`` from every
        record (the truth does not cover it).
        """
        t = np.asarray(gps_s, float)
        k = np.clip(np.searchsorted(self.gps_s, t), 0, len(self.gps_s) - 1)
        gap = np.minimum(np.abs(self.gps_s[k] - t), np.abs(self.gps_s[np.maximum(k - 1, 0)] - t))
        if np.any(gap > max_gap_s):
            raise ValueError(
                f"{self.path}: no ground truth within {max_gap_s} s of GPS second "
                f"{float(t.flat[int(np.argmax(gap))]):.3f} (it covers {self.gps_s[0]:.3f} - "
                f"{self.gps_s[-1]:.3f}); give the ground truth of the same drive"
            )
        return np.stack([np.interp(t, self.gps_s, self.ecef_m[:, c]) for c in range(3)], -1)


# the two GSDC layouts: (time column, its kind, latitude, longitude, ellipsoidal height)
_TRUTH_LAYOUTS = (
    ("UnixTimeMillis", "utc_ms", "LatitudeDegrees", "LongitudeDegrees", "AltitudeMeters"),
    ("millisSinceGpsEpoch", "gps_ms", "latDeg", "lngDeg", "heightAboveWgs84EllipsoidM"),
)


def read_ground_truth(path: str | Path) -> GroundTruth:
    """Read a GSDC ground-truth CSV (2022/2023 ``UnixTimeMillis``, ``LatitudeDegrees``,
    ``LongitudeDegrees``, ``AltitudeMeters`` above the WGS84 ellipsoid; or 2021
    ``millisSinceGpsEpoch``, ``latDeg``, ``lngDeg``, ``heightAboveWgs84EllipsoidM``).

    Raises
    ------
    DeviceGnssError
        Neither layout, a non-numeric value, times not increasing.
    """
    p = Path(path)
    lines = read_text_lines(p, DeviceGnssError)
    reader = csv.DictReader(lines)
    cols = reader.fieldnames or []
    layout = next((lay for lay in _TRUTH_LAYOUTS if all(c in cols for c in
                                                        (lay[0], *lay[2:]))), None)  # fmt: skip
    if layout is None:
        raise DeviceGnssError(p, 1, "not a GSDC ground truth: it needs UnixTimeMillis, "
                              "LatitudeDegrees, LongitudeDegrees, AltitudeMeters (2022/2023) or "
                              "millisSinceGpsEpoch, latDeg, lngDeg, heightAboveWgs84EllipsoidM "
                              "(2021)")  # fmt: skip
    recs = []
    for k, row in enumerate(reader):
        v = [_number(p, k + 2, row, c) for c in (layout[0], *layout[2:])]
        if not all(np.isfinite(v)):
            need = ", ".join((layout[0], *layout[2:]))
            raise DeviceGnssError(p, k + 2, f"empty value among {need}; fix or delete the row")
        _check_ms(p, k + 2, layout[0], v[0], _UTC_MS_RANGE if layout[1] == "utc_ms"
                  else _GPS_MS_RANGE)  # fmt: skip
        if not (abs(v[1]) <= 90.0 and abs(v[2]) <= 360.0 and abs(v[3]) < 1e5):
            raise DeviceGnssError(p, k + 2, f"position {v[1]:g}, {v[2]:g}, {v[3]:g} m is not a "
                                  "latitude, longitude (degrees) and height; fix the row")
        recs.append(v)
    if not recs:
        raise DeviceGnssError(p, None, "no ground-truth record")
    a = np.array(recs)
    t = _utc_ms_to_gps_s(a[:, 0].astype(np.int64)) if layout[1] == "utc_ms" else a[:, 0] * 1e-3
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise DeviceGnssError(p, int(bad[0]) + 3, "times must increase; sort the file")
    return GroundTruth(str(p), t, geodetic_to_ecef(a[:, 1], a[:, 2], a[:, 3]))


def _rotate_z(pos: NDArray, theta: NDArray) -> NDArray:
    c, s = np.cos(theta), np.sin(theta)
    x, y = pos[..., 0], pos[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y, pos[..., 2]], axis=-1)


@dataclass(frozen=True, eq=False)
class DeviceGnssSource:
    """Epochs of a ``device_gnss.csv`` with the satellite positions and corrections it carries.

    Attributes
    ----------
    device : DeviceGnss
    constellation : str
        Systems used; one by default (pairs need one receiver clock; Google's ``IsrbMeters``
        aligns other signals to GPS L1, but the locator's models are per system).
    priority : mapping of system letter to codes, optional
        Default :data:`DEFAULT_SIGNAL_PRIORITY`.
    odometer : ndarray, shape (n_epoch,), optional
        Odometer distance per epoch, metres.
    odometer_extra : ndarray, shape (n_epoch, 2), optional
        The odometer's disputed distance per epoch (:class:`locator.sources.SimSource`).
    """

    device: DeviceGnss
    constellation: str = "G"
    priority: Mapping[str, Sequence[str]] | None = None
    odometer: NDArray | None = field(default=None)
    odometer_extra: NDArray | None = field(default=None)

    def __post_init__(self) -> None:
        check_odometer(self.odometer, self.odometer_extra, len(self.device.gps_s))
        if not self._columns.any():
            raise ValueError(
                f"{self.device.path}: no satellite of constellation {self.constellation!r}; it "
                f"has {sorted({s[0] for s in self.device.sats})}"
            )

    @property
    def gps_s(self) -> NDArray:
        return self.device.gps_s

    @property
    def odometer_m(self) -> NDArray | None:
        return None if self.odometer is None else np.asarray(self.odometer, float)

    @property
    def odometer_extra_m(self) -> NDArray | None:
        return None if self.odometer_extra is None else np.asarray(self.odometer_extra, float)

    @cached_property
    def _columns(self) -> NDArray:
        keep = set(select_satellites(self.device.sats, self.constellation))
        return np.array([s in keep for s in self.device.sats], bool)

    @cached_property
    def selection(self) -> tuple[NDArray, NDArray]:
        """``(code, corrected_m)``, shape (n_epoch, n_sat): the signal used per epoch and
        satellite (``""`` / NaN where none) by the priority."""
        dev = self.device
        prio = {**DEFAULT_SIGNAL_PRIORITY, **(self.priority or {})}
        shape = (len(dev.gps_s), len(dev.sats))
        code = np.full(shape, "", "<U3")
        pr = np.full(shape, np.nan)
        for j, sat in enumerate(dev.sats):
            if not self._columns[j]:
                continue
            for c in prio.get(sat[0], ()):
                if c not in dev.signals:
                    continue
                v = dev.corrected_m(c)[:, j]
                take = np.isfinite(v) & (code[:, j] == "")
                code[take, j] = c
                pr[take, j] = v[take]
        return code, pr

    @property
    def systems(self) -> tuple[str, ...]:
        """System letters of the satellites used, sorted."""
        return tuple(sorted({s[0] for s, c in zip(self.device.sats, self._columns, strict=True)
                             if c}))  # fmt: skip

    @property
    def iono_missing(self) -> tuple[str, ...]:
        """Systems used whose rows carry no ionospheric delay (their sigma is inflated)."""
        code, _ = self.selection
        out = []
        for letter in self.systems:
            cols = np.array([s[0] == letter for s in self.device.sats])
            used = code[:, cols]
            iono = [self.device.signals[c]["iono_m"][:, cols][used == c] for c in set(used.flat)
                    if c]  # fmt: skip
            if iono and not np.isfinite(np.concatenate(iono)).any():
                out.append(letter)
        return tuple(out)

    def observe(self, epoch: int, rx_ecef_m: NDArray) -> EpochData:
        dev = self.device
        code, pr = self.selection
        j = np.flatnonzero(code[epoch] != "")
        if not j.size:
            return EpochData((), np.zeros((0, 3)), np.zeros(0), {})
        sig = [dev.signals[c] for c in code[epoch, j]]
        pos = np.array([[s[f][epoch, k] for f in ("sv_x_m", "sv_y_m", "sv_z_m")]
                        for s, k in zip(sig, j, strict=True)])  # fmt: skip
        iono = np.array([s["iono_m"][epoch, k] for s, k in zip(sig, j, strict=True)])
        freq = np.array([s["carrier_hz"][epoch, k] for s, k in zip(sig, j, strict=True)])
        rx = np.asarray(rx_ecef_m, float).reshape(3)
        rot = pos
        for _ in range(3):  # transmission frame -> frame of reception (omega_E tau)
            rot = _rotate_z(pos, OMEGA_E_RADPS * np.linalg.norm(rot - rx, axis=-1) / C_MPS)
        lat, lon, _ = ecef_to_geodetic(rx)
        _, el, _ = enu_to_azel((rot - rx) @ enu_rotation(lat, lon).T)
        rho = pr[epoch, j]
        no_iono = ~np.isfinite(iono)  # Google gave no delay: kept, sigma inflated below
        ok = np.all(np.isfinite(pos), axis=1) & np.isfinite(rho) & (el > 0)
        reasons = np.where(~np.all(np.isfinite(pos), axis=1), "no satellite position",
                           np.where(el <= 0, "below the horizon", "no corrected pseudorange"))
        sats = [dev.sats[k] for k in j]
        rejected = {s: str(r) for s, r, u in zip(sats, reasons, ok, strict=True) if not u}
        extra = np.where(no_iono, uncorrected_iono_sigma_m(el, freq), 0.0)
        return EpochData(
            tuple(s for s, u in zip(sats, ok, strict=True) if u), rot[ok], rho[ok], rejected,
            extra[ok],
        )  # fmt: skip

    def where(self, epoch: int) -> str:
        """File, lines and epoch of ``epoch``, for messages."""
        return self.device.where(epoch)

    def describe(self) -> JsonDict:
        return {
            "source": "device_gnss",
            "obs": self.device.path,
            "nav": ["satellite positions and corrections of the device_gnss file"],
            "constellation": self.constellation,
            "odometer": self.odometer is not None,
            "marker": "",
            # systems whose ionospheric delay no broadcast model corrects (sigma inflated)
            "iono_uncorrected_systems": list(self.iono_missing),
        }


def device_profile(
    source: DeviceGnssSource, receiver_type: str = "", receiver_class: str = "phone"
) -> ReceiverProfile:
    """What a phone log is for an error model: the codes used per system, single frequency,
    class ``phone``. The file names no phone model: ``receiver_type`` "" (unknown) matches no
    calibrated receiver by name, only a class model."""
    code, _ = source.selection
    codes: dict[str, set[str]] = {}
    for j, sat in enumerate(source.device.sats):
        used = {str(c) for c in np.unique(code[:, j]) if c}
        if used:
            codes.setdefault(sat[0], set()).update(used)
    return ReceiverProfile(receiver_type, "", {k: tuple(sorted(v)) for k, v in codes.items()},
                           "single", receiver_class)  # fmt: skip


def device_residuals(
    source: DeviceGnssSource,
    truth: GroundTruth,
    *,
    min_el_deg: float = 5.0,
    receiver_type: str = "",
    receiver_class: str = "phone",
) -> Residuals:
    """Residuals ``rho - |x_true(t) - S|`` of a phone log at its ground truth, per epoch.

    Returns
    -------
    Residuals
        ``el_deg``, ``residual_m`` of shape (n_epoch, n_sat), NaN where absent or below
        ``min_el_deg``; the profile of :func:`device_profile`.
    """
    dev = source.device
    x = truth.at(dev.gps_s)
    col = {s: k for k, s in enumerate(dev.sats)}
    el = np.full((len(dev.gps_s), len(dev.sats)), np.nan)
    res = np.full_like(el, np.nan)
    for i in range(len(dev.gps_s)):
        d = source.observe(i, x[i])
        if not d.sats:
            continue
        lat, lon, _ = ecef_to_geodetic(x[i])
        _, e, _ = enu_to_azel((d.sat_ecef_m - x[i]) @ enu_rotation(lat, lon).T)
        j = [col[s] for s in d.sats]
        keep = e >= min_el_deg
        el[i, j] = np.where(keep, e, np.nan)
        res[i, j] = np.where(keep, d.pseudorange_m - np.linalg.norm(d.sat_ecef_m - x[i], axis=-1),
                             np.nan)  # fmt: skip
    prof = device_profile(source, receiver_type, receiver_class)
    return Residuals(el, res, tuple(dev.sats), prof, dev.path)
