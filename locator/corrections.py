"""The standard single-frequency pseudorange model, from broadcast data only.

For one epoch and any satellites, :meth:`RangeModel.correct` returns the satellite positions at
transmission time expressed in the Earth-fixed frame of reception, and the pseudoranges
corrected term by term::

    corrected_m = pseudorange_m + sat_clock_m + relativity_m - group_delay_m - iono_m - tropo_m
                = geometric range + c * receiver clock offset + noise

* ``sat_clock_m`` - c (af0 + af1 dt + af2 dt^2), the broadcast polynomial (GLONASS:
  c (-TauN + GammaN dt));
* ``relativity_m`` - the periodic relativistic clock term, c * (-2 r.v / c^2) (equal to the
  ICD's F e sqrt(A) sin E for a Keplerian orbit; 0 for GLONASS, whose broadcast clock needs none
  by convention, as in RTKLIB). :class:`predisat.gnss.ephemeris.Ephemeris` already includes this
  term
  in its ``clock_s``; here it is split out for reporting, ``sat_clock_m + relativity_m`` is
  exactly ``c * clock_s``;
* ``group_delay_m`` - c times the broadcast group delay of the signal used, which the broadcast
  clock (referred to an ionosphere-free pair) omits: GPS/QZSS TGD (gamma TGD on L2), Galileo BGD
  E1/E5b for I/NAV and BGD E1/E5a for F/NAV clocks (0 on E5a/E5b with the matching message),
  BeiDou TGD1 on B1I and TGD2 on B2I (B3I is the reference), NavIC TGD on L5, GLONASS 0;
* ``iono_m`` - Klobuchar (IS-GPS-200 20.3.3.5.2.5) with the GPS coefficients of the
  navigation header, scaled by (f_L1 / f)^2 to the signal's carrier; BeiDou satellites use the
  BeiDou coefficients (BDSA/BDSB) with the same algorithm when the header has them; Galileo
  uses the GPS coefficients (NeQuick-G is out of scope); 0 when no coefficients are known;
* ``tropo_m`` - Saastamoinen zenith delays (hydrostatic and wet) in a standard atmosphere
  (1013.25 hPa, 15 deg C and a relative humidity at sea level, lapse rates as RTKLIB), mapped
  with the Niell (1996) mapping functions.

The transmission time comes from the pseudorange itself (t_rx - P / c is the satellite clock's
reading at transmission, whatever the receiver clock), minus the satellite clock. The Earth
rotation during the signal travel (Sagnac) rotates the satellite by omega_e tau about the z axis,
tau being the geometric travel time to the approximate receiver position, iterated.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.fileerror import FileLineError, read_text_lines
from predisat.geodesy import ecef_to_geodetic, enu_rotation, enu_to_azel
from predisat.gnss.ephemeris import Ephemeris, Reason, ValidityPolicy
from predisat.gnss.orbits import C_MPS
from predisat.gnss.rinex_nav import read_rinex_nav
from predisat.gnss.timescale import gps_s_to_datetime64
from predisat.readonly import freeze_array_fields

__all__ = [
    "OMEGA_E_RADPS",
    "UNCORRECTED_IONO_SIGMA_M",
    "BroadcastIono",
    "CorrectedRanges",
    "RangeModel",
    "SatelliteStates",
    "carrier_frequency_hz",
    "cnav_group_delay_s",
    "group_delay_s",
    "klobuchar_bds_delay_m",
    "klobuchar_delay_m",
    "niell_mapping",
    "saastamoinen_zenith_m",
    "troposphere_delay_m",
    "uncorrected_iono_sigma_m",
]

OMEGA_E_RADPS = 7.2921151467e-5
"""Earth rotation rate (WGS84, IS-GPS-200), rad/s."""

F_L1_HZ = 1575.42e6
F_B1I_HZ = 1561.098e6  # BeiDou B1I: the frequency of the BeiDou Klobuchar model's delay
# carrier per (system, band digit); GLONASS FDMA bands are computed from the channel number
_FREQ_HZ: dict[tuple[str, str], float] = {
    ("G", "1"): 1575.42e6,
    ("G", "2"): 1227.60e6,
    ("G", "5"): 1176.45e6,
    ("J", "1"): 1575.42e6,
    ("J", "2"): 1227.60e6,
    ("J", "5"): 1176.45e6,
    ("J", "6"): 1278.75e6,
    ("E", "1"): 1575.42e6,
    ("E", "5"): 1176.45e6,
    ("E", "7"): 1207.14e6,
    ("E", "8"): 1191.795e6,
    ("E", "6"): 1278.75e6,
    ("C", "2"): 1561.098e6,
    ("C", "1"): 1575.42e6,
    ("C", "5"): 1176.45e6,
    ("C", "7"): 1207.14e6,
    ("C", "6"): 1268.52e6,
    ("C", "8"): 1191.795e6,
    ("I", "5"): 1176.45e6,
    ("I", "9"): 2492.028e6,
    ("R", "3"): 1202.025e6,
    ("R", "4"): 1600.995e6,
    ("R", "6"): 1248.06e6,
}


def carrier_frequency_hz(sat: str, code: str, glonass_k: int | None = None) -> float:
    """Carrier frequency of an observation code (RINEX 2 or 3) of a satellite; NaN if unknown.

    BeiDou ``C1I``/``C1Q`` (RINEX 3.00-3.01 naming of B1I) map to B1I; other band-1 BeiDou
    codes to B1C. GLONASS G1/G2 need the frequency channel ``glonass_k``.
    """
    system = sat[0]
    band = code[1:2]
    if system == "R" and band in "12" and band:
        if glonass_k is None:
            return float("nan")
        return (
            (1602.0e6 + 0.5625e6 * glonass_k) if band == "1" else (1246.0e6 + 0.4375e6 * glonass_k)
        )
    if system == "C" and band == "1" and code[2:3] in ("I", "Q"):
        return 1561.098e6
    return _FREQ_HZ.get((system, band), float("nan"))


def cnav_group_delay_s(code: str, tgd_s: float, isc_l1ca_s: float, isc_l2c_s: float) -> float:
    """Group delay to subtract from a GPS/QZSS CNAV record's clock for one signal, seconds.

    IS-GPS-200 30.3.3.3.1.1: L1 C/A ``TGD - ISC_L1CA``, L2C ``TGD - ISC_L2C``; P(Y) as in
    LNAV (``TGD`` on L1, ``gamma TGD`` on L2). The CNAV clock refers, as LNAV's, to the L1/L2
    P(Y) ionosphere-free combination.

    Parameters
    ----------
    code : str
        Observation code (``"C1C"``, ``"C2L"``, ``"C1"``, ...).
    tgd_s, isc_l1ca_s, isc_l2c_s : float
        Columns ``tgd_cnav_s``, ``isc_l1ca_s`` and ``isc_l2c_s`` of the CNAV record in use.

    Returns
    -------
    float
        NaN for any other signal (L1C, L5: not paired here) or when a term is missing.
    """
    band, attr = code[1:2], code[2:3]
    if not attr:  # RINEX 2: C1 is C/A, C2 L2C, P1 and P2 P(Y)
        attr = {"P": "P", "C": "C" if band == "1" else "X"}.get(code[:1], "?")
    if band == "1":
        if attr == "C":
            return tgd_s - isc_l1ca_s
        return tgd_s if attr in ("P", "W", "Y") else float("nan")
    if band == "2":
        if attr in ("S", "L", "X"):
            return tgd_s - isc_l2c_s
        return (77.0 / 60.0) ** 2 * tgd_s if attr in ("P", "W", "Y", "D") else float("nan")
    return float("nan")


def group_delay_s(sat: str, code: str, tgd_s: float, aux26: float, data_source: float) -> float:
    """Broadcast group delay to subtract from the satellite clock for one signal, seconds.

    Parameters
    ----------
    sat, code : str
        Satellite id and observation code.
    tgd_s, aux26, data_source : float
        Columns ``tgd_s``, ``aux26`` and ``aux20`` of the Keplerian record in use (see
        :data:`predisat.gnss.rinex_nav.KEPLER_FIELDS`).

    Returns
    -------
    float
        NaN when the signal has no defined broadcast group delay (the caller should not use it).
    """
    system, band = sat[0], code[1:2]
    if system in "GJ":
        gamma = (77.0 / 60.0) ** 2
        if band == "1" and code[2:3] not in ("", "C", "P", "W", "Y"):
            # L1C (S, L, X), QZSS L1S (Z) or L1C/B (B): TGD plus CNAV-2's ISCs, which no record
            # read here carries; refused here too, not only by the default code priority (a
            # review: RinexSource(priority={"G": ("C1L",)}) ranged L1C with L1 C/A's TGD)
            return float("nan")
        return {"1": tgd_s, "2": gamma * tgd_s}.get(band, float("nan"))
    if system == "I":
        return tgd_s if band == "5" else float("nan")
    if system == "E":
        fnav = (int(np.nan_to_num(data_source)) & 0b010) != 0 and not (
            int(np.nan_to_num(data_source)) & 0b101
        )
        bgd = tgd_s if fnav else aux26  # E1/E5a (F/NAV clock) or E1/E5b (I/NAV clock)
        f1, f2 = 1575.42, (1176.45 if fnav else 1207.14)
        if band == "1":
            return bgd
        if (band == "5" and fnav) or (band == "7" and not fnav):
            return (f1 / f2) ** 2 * bgd
        return float("nan")
    if system == "C":
        b1i = band == "2" or (band == "1" and code[2:3] in ("I", "Q"))
        if b1i:
            return tgd_s
        return {"7": aux26, "6": 0.0}.get(band, float("nan"))
    if system == "R":
        return 0.0
    return float("nan")


# ------------------------------------------------------------------------- ionosphere
# Klobuchar coefficient sets tried per system, own system first (see BroadcastIono.klobuchar)
_KLOBUCHAR_ORDER = {"C": ("BDS", "GPS", "QZS"), "J": ("QZS", "GPS", "BDS")}
_KLOBUCHAR_DEFAULT_ORDER = ("GPS", "QZS", "BDS")
# RINEX 4 "> ION" messages -> the RINEX 3 header keys of the same coefficients
_ION_KEYS = {("G", "LNAV"): "GPS", ("J", "LNAV"): "QZS", ("C", "D1D2"): "BDS", ("E", "IFNV"): "GAL"}


@dataclass(frozen=True)
class BroadcastIono:
    """Broadcast ionospheric coefficients of navigation files.

    Attributes
    ----------
    gps_alpha, gps_beta : ndarray, shape (4,) or None
        Klobuchar coefficients (s, s/sc, s/sc^2, s/sc^3 and s, ...), RINEX 2 ``ION ALPHA`` /
        ``ION BETA``, RINEX 3 ``GPSA``/``GPSB`` or the first RINEX 4 ``> ION G.. LNAV``.
    bds_alpha, bds_beta : ndarray, shape (4,) or None
        BeiDou Klobuchar coefficients (``BDSA``/``BDSB``, RINEX 4 ``> ION C.. D1D2``).
    gal_ai : ndarray, shape (3,) or None
        Galileo NeQuick-G effective ionisation coefficients (``GAL``, RINEX 4
        ``> ION E.. IFNV``); read, not used (no maintained NeQuick-G package: see
        ``docs/ephemerides.md``).
    source : str
        ``"file:line"`` of the GPS coefficients.
    qzs_alpha, qzs_beta : ndarray, shape (4,) or None
        QZSS Klobuchar coefficients (``QZSA``/``QZSB``, RINEX 4 ``> ION J.. LNAV``).
    sources : mapping of str to str
        ``"file:line"`` of every set held, by ``"GPS"``, ``"QZS"``, ``"BDS"``, ``"GAL"``.
    stale : mapping of str to str
        Sets left out because every file's set lay more than :data:`IONO_MAX_AGE_S` from the
        time asked for (:meth:`from_rinex_nav` ``near_gps_s``): ``"file:line (date)"`` by set
        name. Their systems count as without a model (flagged, sigma inflated).
    candidates : mapping of str to tuple
        Every set the files hold, by RINEX 3 header key (``GPSA``, ``BDSB``, ``GAL``...):
        ``(coefficients, "file:line", time in GPS seconds)``, the time infinite for a RINEX
        2/3 header (:meth:`from_rinex_nav`); what :meth:`near` chooses from, without reading
        the files again.
    """

    gps_alpha: NDArray | None = None
    gps_beta: NDArray | None = None
    bds_alpha: NDArray | None = None
    bds_beta: NDArray | None = None
    gal_ai: NDArray | None = None
    source: str = ""
    qzs_alpha: NDArray | None = None
    qzs_beta: NDArray | None = None
    sources: Mapping[str, str] = field(default_factory=dict)
    stale: Mapping[str, str] = field(default_factory=dict)
    candidates: Mapping[str, tuple[tuple[NDArray, str, float], ...]] = field(
        default_factory=dict, repr=False
    )

    @classmethod
    def from_rinex_nav(
        cls,
        paths: str | Path | Sequence[str | Path],
        near_gps_s: float | None = None,
        file_epochs: Mapping[str, float] | None = None,
    ) -> BroadcastIono:
        """Coefficients of RINEX 2/3 navigation headers and RINEX 4 ``> ION`` records.

        Parameters
        ----------
        paths : path or sequence of paths
        near_gps_s : float, optional
            The time the coefficients are for (e.g. the observations' middle), GPS seconds:
            each set is taken from the file (RINEX 2/3 header) or record (RINEX 4) nearest to
            it, and left out (``stale``) when even that is more than :data:`IONO_MAX_AGE_S`
            away: the coefficients of another day describe another ionosphere (a user trial
            listing a 2010 file before a 2022 one moved the ranges by 2-5 m). None: the first
            file that has a set wins, within a RINEX 4 file its first record.
        file_epochs : mapping of str to float, optional
            A time per file name for the RINEX 2/3 headers, which carry none of their own (the
            median epoch of the file's records, :meth:`RangeModel.with_iono_near`); a header
            set of a file not named counts as infinitely far.
        """
        if isinstance(paths, (str, Path)):
            paths = [paths]
        candidates: dict[str, list[tuple[NDArray, str, float]]] = {}
        for p in paths:
            for key, val, where, t in _without_empty_klobuchar(_read_iono(Path(p))):
                candidates.setdefault(key, []).append((val, where, t))
        return cls._chosen({k: tuple(v) for k, v in candidates.items()}, near_gps_s, file_epochs)

    def near(
        self, gps_s: float, file_epochs: Mapping[str, float] | None = None
    ) -> BroadcastIono:
        """The sets of :attr:`candidates` nearest to ``gps_s`` (as :meth:`from_rinex_nav`
        ``near_gps_s`` and ``file_epochs``); ``self`` when it holds no candidates (sets given
        by the caller)."""
        if not self.candidates:
            return self
        return self._chosen(self.candidates, gps_s, file_epochs)

    @classmethod
    def _chosen(
        cls,
        candidates: Mapping[str, tuple[tuple[NDArray, str, float], ...]],
        near_gps_s: float | None,
        file_epochs: Mapping[str, float] | None,
    ) -> BroadcastIono:
        """The instance of ``candidates`` chosen for ``near_gps_s`` (see :meth:`from_rinex_nav`);
        a header set (no time of its own) takes its file's time in ``file_epochs``."""
        epochs = file_epochs or {}

        def timed(c: tuple[NDArray, str, float]) -> float:
            return c[2] if np.isfinite(c[2]) else epochs.get(c[1].rsplit(":", 1)[0], np.inf)

        found: dict[str, tuple[NDArray, str]] = {}
        stale: dict[str, str] = {}
        for key, cands in candidates.items():
            if near_gps_s is None:
                found[key] = cands[0][:2]
                continue
            val, where, _ = best = min(cands, key=lambda c: abs(timed(c) - near_gps_s))
            t = timed(best)  # the first of the nearest on ties
            if abs(t - near_gps_s) <= IONO_MAX_AGE_S:
                found[key] = (val, where)
            else:
                when = str(gps_s_to_datetime64(t))[:10] if np.isfinite(t) else "no date"
                stale[key[:3]] = f"{where} ({when})"
        stale = {k: v for k, v in stale.items() if k + "A" not in found and k not in found}
        get = {k: v[0] for k, v in found.items()}
        return cls(
            get.get("GPSA"),
            get.get("GPSB"),
            get.get("BDSA"),
            get.get("BDSB"),
            get.get("GAL"),
            found.get("GPSA", (None, ""))[1],
            get.get("QZSA"),
            get.get("QZSB"),
            {k[:3]: v[1] for k, v in sorted(found.items()) if k[:3] in _ION_KEYS.values()},
            stale,
            candidates,
        )

    def klobuchar(self, system: str) -> tuple[NDArray, NDArray, str] | None:
        """Klobuchar (alpha, beta, set name) used for a system letter, or None when no set.

        A system uses its own set (BeiDou ``BDS``, QZSS ``QZS``), else GPS's, else any other
        broadcast Klobuchar set: the coefficients describe the same ionosphere, and any of them
        removes much more of the delay than none (Galileo and GLONASS broadcast no Klobuchar
        set). The name tells which (``"GPS"``, ``"QZS"``, ``"BDS"``).
        """
        sets = {
            "GPS": (self.gps_alpha, self.gps_beta),
            "QZS": (self.qzs_alpha, self.qzs_beta),
            "BDS": (self.bds_alpha, self.bds_beta),
        }
        for name in _KLOBUCHAR_ORDER.get(system, _KLOBUCHAR_DEFAULT_ORDER):
            a, b = sets[name]
            if a is not None and b is not None:
                return a, b, name
        return None

    def coefficients(self, system: str) -> tuple[NDArray, NDArray] | None:
        """Klobuchar (alpha, beta) used for a system letter (:meth:`klobuchar`), or None."""
        k = self.klobuchar(system)
        return None if k is None else (k[0], k[1])


def _read_iono(path: Path) -> list[tuple[str, NDArray, str, float]]:
    """Coefficient sets of one file: (RINEX 3 header key ``GPSA``, ``BDSB``, ``GAL``...,
    coefficients, ``"file:line"``, time in GPS seconds: a RINEX 4 record's transmission, a
    header's infinite: it has none of its own)."""
    if not path.is_file():
        raise FileLineError(path, None, "no such navigation file; check the path")
    first = read_text_lines(path, FileLineError)[:1]
    try:
        v4 = bool(first) and "RINEX VERSION / TYPE" in first[0] and float(first[0][:9]) >= 4.0
    except ValueError:
        v4 = False
    if not v4:
        return [(key, val, where, np.inf) for key, (val, where) in _read_iono_header(path).items()]
    out: list[tuple[str, NDArray, str, float]] = []
    for m in read_rinex_nav(path).iono:
        key = _ION_KEYS[(m.system, m.message)]
        if key == "GAL":
            out.append((key, m.coefficients, m.source, m.epoch_gps_s))
        else:
            out.append((key + "A", m.coefficients[:4], m.source, m.epoch_gps_s))
            out.append((key + "B", m.coefficients[4:], m.source, m.epoch_gps_s))
    return out


def _without_empty_klobuchar(
    sets: list[tuple[str, NDArray, str, float]],
) -> list[tuple[str, NDArray, str, float]]:
    """The sets of one file without a Klobuchar set whose alpha coefficients are all zero.

    Such a set (a receiver that had not yet decoded the ionosphere page writes zeros) is no
    model: the amplitude is zero, and the algorithm returns its night-time constant of 5 ns
    (1.5 m at the zenith) at any hour. Taken as a model, it left 2-9 m of the delay in GEONET
    0759's ranges at 09:30 local time without a flag or an inflated sigma (SPP mean up error
    -0.2 -> +2.8 m; a user trial, 2026-12-07); RTKLIB's ``ionmodel`` replaces a set of eight
    zeros by a default one.
    Left out with a warning, its systems count as without a model (flagged, sigma inflated)
    unless another set serves them.
    """
    empty = {(k[:-1], where.rsplit(":", 1)[0], t) for k, val, where, t in sets
             if k.endswith("A") and k != "GAL" and not np.any(val)}  # fmt: skip
    if not empty:
        return sets
    for name, file, _ in sorted(empty):
        warnings.warn(
            f"{file}: the {name} Klobuchar coefficients are all zero (no ionosphere data "
            "decoded): left out; its systems count as without a broadcast ionosphere model "
            "unless another set serves them",
            UserWarning,
            stacklevel=3,
        )
    def dropped(c: tuple[str, NDArray, str, float]) -> bool:
        return c[0] != "GAL" and (c[0][:-1], c[2].rsplit(":", 1)[0], c[3]) in empty

    return [c for c in sets if not dropped(c)]


def _file_epochs(eph: Ephemeris) -> dict[str, float]:
    """Median record epoch (GPS seconds) per navigation file name of an ephemeris."""
    names: list[NDArray] = []
    times: list[NDArray] = []
    for table in (eph.kepler, eph.glonass):
        if table is not None and len(table):
            names.append(np.array([str(s).rsplit(":", 1)[0] for s in table.source]))
            times.append(np.asarray(table.epoch_gps_s, float))
    if not names:
        return {}
    name, t = np.concatenate(names), np.concatenate(times)
    return {str(n): float(np.median(t[name == n])) for n in np.unique(name)}


def _read_iono_header(path: Path) -> dict[str, tuple[NDArray, str]]:
    lines = read_text_lines(path, FileLineError)
    out: dict[str, tuple[NDArray, str]] = {}
    for i, line in enumerate(lines):
        label = line[60:].strip()
        try:
            if label in ("ION ALPHA", "ION BETA"):
                key = "GPSA" if label == "ION ALPHA" else "GPSB"
                vals = [line[2 + 12 * k : 14 + 12 * k] for k in range(4)]
            elif label == "IONOSPHERIC CORR":
                key = line[:4].strip()
                vals = [line[5 + 12 * k : 17 + 12 * k] for k in range(4 if key != "GAL" else 3)]
            elif label == "END OF HEADER":
                break
            else:
                continue
            arr = np.array([float(v.strip().replace("D", "E").replace("d", "E")) for v in vals])
        except ValueError:
            raise FileLineError(path, i + 1, f"unreadable {label!r} coefficients") from None
        out.setdefault(key, (arr, f"{path.name}:{i + 1}"))
    return out


IONO_MAX_AGE_S = 2 * 86400.0
"""Furthest a broadcast ionosphere set may lie from the time it is used for, seconds
(:meth:`BroadcastIono.from_rinex_nav`): the operators update the coefficients about daily; a
daily file's records sit around its middle, so 2 days keep the day before and after."""

UNCORRECTED_IONO_SIGMA_M = 5.0
"""Standard deviation added, at the zenith on L1, to a pseudorange whose ionospheric delay no
broadcast model corrects, metres (scaled by the thin-shell obliquity factor and (f_L1 / f)^2:
about 15 m on L1 at 5 deg). The mid-latitude daytime vertical delay on L1 is 2-10 m at moderate
solar activity; an uncorrected Galileo-only run showed hour-long along-track biases of 4-5 m
(issue 31). A bias, not noise: the inflation widens the intervals, it cannot average it away."""


def uncorrected_iono_sigma_m(el_deg: ArrayLike, freq_hz: ArrayLike = F_L1_HZ) -> NDArray:
    """Pseudorange sigma standing for an ionospheric delay left uncorrected, metres.

    Parameters
    ----------
    el_deg : array_like
        Elevation, degrees.
    freq_hz : array_like
        Carrier frequency (NaN gives NaN).

    Returns
    -------
    ndarray
        ``UNCORRECTED_IONO_SIGMA_M * F(el) * (f_L1 / f)^2`` with the 350 km thin-shell obliquity
        factor ``F = 1 / sqrt(1 - (R cos el / (R + 350 km))^2)``.
    """
    el = np.radians(np.asarray(el_deg, float))
    ratio = 6371.0 / (6371.0 + 350.0) * np.cos(el)
    obliquity = 1.0 / np.sqrt(1.0 - ratio**2)
    return UNCORRECTED_IONO_SIGMA_M * obliquity * (F_L1_HZ / np.asarray(freq_hz, float)) ** 2


def klobuchar_delay_m(
    gps_s: ArrayLike,
    lat_deg: ArrayLike,
    lon_deg: ArrayLike,
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    alpha: ArrayLike,
    beta: ArrayLike,
) -> NDArray:
    """Slant ionospheric group delay on L1 (1575.42 MHz), Klobuchar model (IS-GPS-200).

    Parameters
    ----------
    gps_s : array_like, shape (...)
        GPS time (the local time of the pierce point derives from the GPS time of day).
    lat_deg, lon_deg : array_like, shape (...)
        Receiver geodetic position.
    az_deg, el_deg : array_like, shape (...)
        Satellite direction.
    alpha, beta : array_like, shape (4,)

    Returns
    -------
    ndarray, shape (...)
        Delay in metres (positive: the code is late); 0 where ``el_deg <= 0``.
    """
    a = np.asarray(alpha, float)
    b = np.asarray(beta, float)
    el_sc = np.asarray(el_deg, float) / 180.0
    az = np.radians(np.asarray(az_deg, float))
    psi = 0.0137 / (el_sc + 0.11) - 0.022  # Earth-centred angle, semicircles
    phi_i = np.clip(np.asarray(lat_deg, float) / 180.0 + psi * np.cos(az), -0.416, 0.416)
    lam_i = np.asarray(lon_deg, float) / 180.0 + psi * np.sin(az) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)  # geomagnetic latitude
    t = np.mod(43200.0 * lam_i + np.asarray(gps_s, float), 86400.0)
    f = 1.0 + 16.0 * (0.53 - el_sc) ** 3  # obliquity
    amp = np.maximum(a[0] + phi_m * (a[1] + phi_m * (a[2] + phi_m * a[3])), 0.0)
    per = np.maximum(b[0] + phi_m * (b[1] + phi_m * (b[2] + phi_m * b[3])), 72000.0)
    x = 2.0 * np.pi * (t - 50400.0) / per
    day = np.where(np.abs(x) < 1.57, amp * (1.0 - x**2 / 2.0 + x**4 / 24.0), 0.0)
    return np.where(el_sc > 0, C_MPS * f * (5e-9 + day), 0.0)


def klobuchar_bds_delay_m(
    gps_s: ArrayLike,
    lat_deg: ArrayLike,
    lon_deg: ArrayLike,
    az_deg: ArrayLike,
    el_deg: ArrayLike,
    alpha: ArrayLike,
    beta: ArrayLike,
) -> NDArray:
    """Slant ionospheric group delay on B1I (1561.098 MHz), BeiDou's Klobuchar model.

    BDS-SIS-ICD-B1I 3.0, 5.2.4.7; the GPS form (:func:`klobuchar_delay_m`) with the same
    coefficients differs by up to 1.2 m at 15 deg (a user trial, Copenhagen): a thin shell at
    375 km with the exact pierce point (Earth radius 6378 km), the pierce point's
    **geographic** latitude (not geomagnetic) in semicircles, ``|phi_M|`` in the polynomials,
    the period clamped to 72 000 - 172 800 s, the amplitude's cosine itself (no series), and
    the local time from BeiDou time (GPS - 14 s).

    Parameters
    ----------
    gps_s : array_like, shape (...)
        GPS time.
    lat_deg, lon_deg : array_like, shape (...)
        Receiver geodetic position.
    az_deg, el_deg : array_like, shape (...)
        Satellite direction.
    alpha, beta : array_like, shape (4,)
        The broadcast BeiDou coefficients (s, s/sc, ...; RINEX ``BDSA`` / ``BDSB``).

    Returns
    -------
    ndarray, shape (...)
        Delay in metres on B1I (scale by ``(f_B1I / f)^2`` for another carrier); 0 where
        ``el_deg <= 0``.
    """
    a = np.asarray(alpha, float)
    b = np.asarray(beta, float)
    el = np.radians(np.asarray(el_deg, float))
    az = np.radians(np.asarray(az_deg, float))
    ratio = 6378.0 / (6378.0 + 375.0) * np.cos(el)
    psi = np.pi / 2.0 - el - np.arcsin(ratio)  # Earth-centred angle, rad
    lat_u, lon_u = np.radians(np.asarray(lat_deg, float)), np.radians(np.asarray(lon_deg, float))
    lat_m = np.arcsin(np.sin(lat_u) * np.cos(psi) + np.cos(lat_u) * np.sin(psi) * np.cos(az))
    lon_m = lon_u + np.arcsin(np.sin(psi) * np.sin(az) / np.cos(lat_m))
    x = np.abs(lat_m) / np.pi  # semicircles
    amp = np.maximum(a[0] + x * (a[1] + x * (a[2] + x * a[3])), 0.0)
    per = np.clip(b[0] + x * (b[1] + x * (b[2] + x * b[3])), 72000.0, 172800.0)
    t = np.mod(np.asarray(gps_s, float) - 14.0 + 43200.0 * lon_m / np.pi, 86400.0)
    day = np.where(np.abs(t - 50400.0) < per / 4.0, amp * np.cos(2 * np.pi * (t - 50400.0) / per),
                   0.0)  # fmt: skip
    return np.where(el > 0, C_MPS * (5e-9 + day) / np.sqrt(1.0 - ratio**2), 0.0)


# ------------------------------------------------------------------------- troposphere
def saastamoinen_zenith_m(
    lat_deg: ArrayLike, h_m: ArrayLike, humidity: float = 0.7
) -> tuple[NDArray, NDArray]:
    """Zenith hydrostatic and wet delays, Saastamoinen model in a standard atmosphere.

    Pressure 1013.25 hPa (1 - 2.2557e-5 h)^5.2568, temperature 15 deg C - 6.5 K/km, water
    vapour from ``humidity`` (relative, 0-1) - the same standard atmosphere as RTKLIB's
    ``tropmodel``. Heights below 0 are taken as 0; above 10 km the delays are 0, as in
    ``tropmodel`` (a first iterate of a fix can lie there; the standard atmosphere's pressure
    has no real value above 44 km).

    Returns
    -------
    zhd_m, zwd_m : ndarray, shape (...)
    """
    lat = np.radians(np.asarray(lat_deg, float))
    h_all = np.maximum(np.asarray(h_m, float), 0.0)
    h = np.minimum(h_all, _TROPO_TOP_M)
    pres = 1013.25 * np.power(1.0 - 2.2557e-5 * h, 5.2568)
    temp = 15.0 - 6.5e-3 * h + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    zhd = 0.0022768 * pres / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * h / 1e3)
    zwd = 0.002277 * (1255.0 / temp + 0.05) * e
    above = h_all > _TROPO_TOP_M
    return np.where(above, 0.0, zhd), np.where(above, 0.0, zwd)


_TROPO_TOP_M = 1.0e4


# Niell (1996), table 3: hydrostatic average and amplitude, wet; rows lat 15, 30, 45, 60, 75
_NMF_LAT = np.array([15.0, 30.0, 45.0, 60.0, 75.0])
_NMF_H_AVG = np.array(
    [
        [1.2769934e-3, 2.9153695e-3, 62.610505e-3],
        [1.2683230e-3, 2.9152299e-3, 62.837393e-3],
        [1.2465397e-3, 2.9288445e-3, 63.721774e-3],
        [1.2196049e-3, 2.9022565e-3, 63.824265e-3],
        [1.2045996e-3, 2.9024912e-3, 64.258455e-3],
    ]
)
_NMF_H_AMP = np.array(
    [
        [0.0, 0.0, 0.0],
        [1.2709626e-5, 2.1414979e-5, 9.0128400e-5],
        [2.6523662e-5, 3.0160779e-5, 4.3497037e-5],
        [3.4000452e-5, 7.2562722e-5, 84.795348e-5],
        [4.1202191e-5, 11.723375e-5, 170.37206e-5],
    ]
)
_NMF_WET = np.array(
    [
        [5.8021897e-4, 1.4275268e-3, 4.3472961e-2],
        [5.6794847e-4, 1.5138625e-3, 4.6729510e-2],
        [5.8118019e-4, 1.4572752e-3, 4.3908931e-2],
        [5.9727542e-4, 1.5007428e-3, 4.4626982e-2],
        [6.1641693e-4, 1.7599082e-3, 5.4736038e-2],
    ]
)
_NMF_HEIGHT = (2.53e-5, 5.49e-3, 1.14e-3)


def _marini(sin_el: NDArray, a: ArrayLike, b: ArrayLike, c: ArrayLike) -> NDArray:
    a, b, c = (np.asarray(v, float) for v in (a, b, c))
    return (1.0 + a / (1.0 + b / (1.0 + c))) / (sin_el + a / (sin_el + b / (sin_el + c)))


def niell_mapping(
    gps_s: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike, el_deg: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Niell (1996) hydrostatic and wet mapping functions.

    Parameters
    ----------
    gps_s : array_like, shape (...)
        Time (for the seasonal term; day of year counted on the GPS calendar).
    lat_deg, h_m, el_deg : array_like, shape (...)

    Returns
    -------
    m_dry, m_wet : ndarray, shape (...)
        NaN where ``el_deg <= 0``.
    """
    t = np.asarray(gps_s, float)
    lat = np.asarray(lat_deg, float)
    el = np.radians(np.asarray(el_deg, float))
    dt = gps_s_to_datetime64(t)
    jan1 = dt.astype("datetime64[Y]").astype("datetime64[ns]")
    doy = (dt - jan1) / np.timedelta64(1, "D") + 1.0
    season = np.cos(2.0 * np.pi * (doy - 28.0) / 365.25 + np.where(lat < 0, np.pi, 0.0))
    alat = np.abs(lat)

    def interp(table: NDArray, k: int) -> NDArray:
        return np.interp(alat, _NMF_LAT, table[:, k])

    ah, bh, ch = (interp(_NMF_H_AVG, k) - interp(_NMF_H_AMP, k) * season for k in range(3))
    aw, bw, cw = (interp(_NMF_WET, k) for k in range(3))
    s = np.sin(el)
    a_ht, b_ht, c_ht = (np.float64(v) for v in _NMF_HEIGHT)
    dm = (1.0 / s - _marini(s, a_ht, b_ht, c_ht)) * np.asarray(h_m, float) / 1e3
    m_dry = _marini(s, ah, bh, ch) + dm
    m_wet = _marini(s, aw, bw, cw)
    bad = el <= 0
    return np.where(bad, np.nan, m_dry), np.where(bad, np.nan, m_wet)


def troposphere_delay_m(
    gps_s: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike, el_deg: ArrayLike, humidity: float = 0.7
) -> NDArray:
    """Slant tropospheric delay: Saastamoinen zenith delays times Niell mapping, metres."""
    zhd, zwd = saastamoinen_zenith_m(lat_deg, h_m, humidity)
    m_dry, m_wet = niell_mapping(gps_s, lat_deg, h_m, el_deg)
    return zhd * m_dry + zwd * m_wet


# ------------------------------------------------------------------------- the range model
@dataclass(frozen=True)
class SatelliteStates:
    """Satellite states at transmission time for one reception epoch (receiver-independent).

    Attributes
    ----------
    gps_s : float
        Reception epoch (receiver time tag).
    sats : tuple of str
    code : ndarray of str, shape (n_sat,)
    pseudorange_m : ndarray, shape (n_sat,)
    transmit_gps_s : ndarray, shape (n_sat,)
    pos_ecef_m : ndarray, shape (n_sat, 3)
        At transmission, in the Earth-fixed frame of the transmission instant.
    sat_clock_m, relativity_m, group_delay_m : ndarray, shape (n_sat,)
    freq_hz : ndarray, shape (n_sat,)
    reason : ndarray of str, shape (n_sat,)
        ``""`` when usable, otherwise why not (``"no pseudorange"``, an ephemeris
        :class:`~predisat.gnss.ephemeris.Reason` name, ``"no group delay for C5X"``, ...).
    """

    gps_s: float
    sats: tuple[str, ...]
    code: NDArray
    pseudorange_m: NDArray
    transmit_gps_s: NDArray
    pos_ecef_m: NDArray
    sat_clock_m: NDArray
    relativity_m: NDArray
    group_delay_m: NDArray
    freq_hz: NDArray
    reason: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)


@dataclass(frozen=True)
class CorrectedRanges:
    """Corrected pseudoranges of one epoch seen from an approximate receiver position.

    Attributes
    ----------
    states : SatelliteStates
    rx_ecef_m : ndarray, shape (3,)
    sat_ecef_m : ndarray, shape (n_sat, 3)
        Satellite at transmission, rotated into the Earth-fixed frame of reception.
    range_m : ndarray, shape (n_sat,)
        Geometric range from ``rx_ecef_m`` to ``sat_ecef_m``.
    earth_rotation_m : ndarray, shape (n_sat,)
        Change of the geometric range due to the rotation (Sagnac), for reports.
    iono_m, tropo_m : ndarray, shape (n_sat,)
        Slant delays (0 when the atmosphere is not applied).
    az_deg, el_deg : ndarray, shape (n_sat,)
    usable : ndarray of bool, shape (n_sat,)
    reason : ndarray of str, shape (n_sat,)
    iono_model : ndarray of str, shape (n_sat,)
        Klobuchar set applied (``"GPS"``, ``"QZS"``, ``"BDS"``, :meth:`BroadcastIono.klobuchar`);
        ``""`` where no ionospheric correction was applied (see :attr:`iono_uncorrected`).
    """

    states: SatelliteStates
    rx_ecef_m: NDArray
    sat_ecef_m: NDArray
    range_m: NDArray
    earth_rotation_m: NDArray
    iono_m: NDArray
    tropo_m: NDArray
    az_deg: NDArray
    el_deg: NDArray
    usable: NDArray
    reason: NDArray
    iono_model: NDArray = field(default_factory=lambda: np.zeros(0, "<U3"))

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def iono_uncorrected(self) -> NDArray:
        """Satellites whose ionospheric delay stays in :attr:`corrected_m`, shape (n_sat,)."""
        if len(self.iono_model) != len(self.states.sats):
            return np.ones(len(self.states.sats), bool)
        return self.iono_model == ""

    @property
    def corrected_m(self) -> NDArray:
        """Pseudorange with every modelled term removed, shape (n_sat,)."""
        s = self.states
        return (
            s.pseudorange_m
            + s.sat_clock_m
            + s.relativity_m
            - s.group_delay_m
            - self.iono_m
            - self.tropo_m
        )

    def breakdown(self) -> dict[str, NDArray]:
        """Every term in metres by name, for tables and plots."""
        s = self.states
        return {
            "pseudorange_m": s.pseudorange_m,
            "sat_clock_m": s.sat_clock_m,
            "relativity_m": s.relativity_m,
            "group_delay_m": s.group_delay_m,
            "iono_m": self.iono_m,
            "tropo_m": self.tropo_m,
            "earth_rotation_m": self.earth_rotation_m,
            "range_m": self.range_m,
            "corrected_m": self.corrected_m,
        }


def _rotate_z(pos: NDArray, theta: NDArray) -> NDArray:
    c, s = np.cos(theta), np.sin(theta)
    x, y = pos[..., 0], pos[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y, pos[..., 2]], axis=-1)


@dataclass(frozen=True)
class RangeModel:
    """Broadcast ephemeris, ionospheric coefficients and model settings.

    Build with :meth:`from_rinex_nav`. ``glonass_k`` maps GLONASS ids to frequency channels
    (from the navigation records; an observation header's slots may be merged in with
    :meth:`with_glonass_slots`).
    """

    ephemeris: Ephemeris
    iono: BroadcastIono = field(default_factory=BroadcastIono)
    humidity: float = 0.7
    glonass_k: Mapping[str, int] = field(default_factory=dict)
    record_row: Mapping[str, int] = field(default_factory=dict)

    @classmethod
    def from_rinex_nav(
        cls,
        paths: str | Path | Sequence[str | Path],
        policy: ValidityPolicy | None = None,
        humidity: float = 0.7,
    ) -> RangeModel:
        """Model from RINEX 2/3 navigation files (records merged, header coefficients).

        The default policy trusts a record no other record of its satellite can check
        (``ValidityPolicy.trust_unchecked``): a receiver's hourly file holds one record per
        satellite, and the locator checks every satellite against its pseudorange (the fix's
        residuals, fault detection and exclusion), which a record of another orbit fails.
        """
        eph = Ephemeris.from_rinex(paths, policy or ValidityPolicy(trust_unchecked=True))
        return cls.from_ephemeris(eph, BroadcastIono.from_rinex_nav(eph.sources), humidity)

    @classmethod
    def from_ephemeris(
        cls, eph: Ephemeris, iono: BroadcastIono | None = None, humidity: float = 0.7
    ) -> RangeModel:
        """Model from an existing broadcast :class:`Ephemeris`."""
        if eph.kind != "broadcast":
            raise ValueError(
                f"RangeModel needs a broadcast ephemeris (group delays), got {eph.kind}"
            )
        rows = {} if eph.kepler is None else {s: i for i, s in enumerate(eph.kepler.source)}
        k: dict[str, int] = {}
        if eph.glonass is not None and len(eph.glonass):
            fn = eph.glonass.col("freq_num")
            for s, v in zip(eph.glonass.sat, fn, strict=True):
                if np.isfinite(v):
                    k[str(s)] = int(v)
        return cls(eph, iono or BroadcastIono(), humidity, k, rows)

    def with_iono_near(self, gps_s: float) -> RangeModel:
        """A copy whose ionosphere sets are those of its navigation files nearest to ``gps_s``
        (:meth:`BroadcastIono.from_rinex_nav` ``near_gps_s``); unchanged when its sets were not
        read from its own files (given by the caller, or none)."""
        files = {Path(p).name for p in self.ephemeris.sources}
        used = {str(w).rsplit(":", 1)[0] for w in self.iono.sources.values()}
        if not used or not used <= files:
            return self
        # chosen among the sets read once (a review: the files were read again at each call:
        # the command line, the source and the fixes each asked)
        iono = self.iono.near(gps_s, _file_epochs(self.ephemeris))
        return RangeModel(self.ephemeris, iono, self.humidity, self.glonass_k, self.record_row)

    def with_glonass_slots(self, slots: Mapping[str, int]) -> RangeModel:
        """A copy whose GLONASS channels include ``slots`` (e.g. an observation header's)."""
        return RangeModel(
            self.ephemeris, self.iono, self.humidity, {**self.glonass_k, **slots}, self.record_row
        )

    def states(
        self,
        gps_s: float,
        sats: Sequence[str],
        pseudorange_m: ArrayLike,
        codes: str | Sequence[str] = "C1C",
    ) -> SatelliteStates:
        """Satellite positions, clocks and group delays at transmission (no receiver needed).

        Parameters
        ----------
        gps_s : float
            Reception epoch as tagged by the receiver.
        sats : sequence of str, length n_sat
        pseudorange_m : array_like, shape (n_sat,)
            NaN where absent.
        codes : str or sequence of str
            Observation code of each pseudorange (selects carrier and group delay).
        """
        sats = tuple(sats)
        n = len(sats)
        pr = np.asarray(pseudorange_m, float).reshape(n)
        code = np.array([codes] * n if isinstance(codes, str) else list(codes), "<U3")
        if code.shape != (n,):
            raise ValueError(f"codes must be one code or one per satellite ({n}), got {codes!r}")
        t_tx = gps_s - np.where(np.isfinite(pr), pr, 0.0) / C_MPS
        # the clock varies by < 1e-11 s over the few ms of the first guess: one pass suffices
        _, clk0, _ = self.ephemeris.evaluate(t_tx, sats)
        clk0 = np.diagonal(clk0).copy()
        t_tx = t_tx - np.nan_to_num(clk0)
        pos3, clk3, st3 = self.ephemeris.evaluate(
            np.concatenate([t_tx, t_tx - 0.5, t_tx + 0.5]), sats
        )
        idx = np.arange(n)
        pos, clk = pos3[idx, idx], clk3[idx, idx]
        before, after = pos3[idx + n, idx], pos3[idx + 2 * n, idx]
        vel = after - before  # central difference over 1 s
        # a record trusted at transmission but not half a second later (or earlier), at the
        # edge of its validity: one-sided over 0.5 s (the relativistic term within a few cm),
        # not a NaN range without a reason ("not usable"; a trial: NYA1 E33 at 15:30:00)
        vel = np.where(
            np.isfinite(vel), vel, np.where(np.isfinite(after), after - pos, pos - before) * 2.0
        )
        rel = np.where(
            [s[0] == "R" for s in sats], 0.0, -2.0 * np.sum(pos * vel, axis=-1) / C_MPS**2
        )
        reason = np.array([Reason(int(r)).name for r in st3.reason[idx, idx]], object)
        reason[reason == "OK"] = ""
        freq = np.full(n, np.nan)
        tgd = np.full(n, np.nan)
        kep = self.ephemeris.kepler
        for j, s in enumerate(sats):
            freq[j] = carrier_frequency_hz(s, code[j], self.glonass_k.get(s))
            if reason[j]:
                continue
            if s[0] == "R":
                tgd[j] = 0.0
            elif kep is not None and st3.record[j, j] in self.record_row:
                row = self.record_row[st3.record[j, j]]
                if "cnav" in kep.fields and kep.col("cnav")[row] == 1.0:
                    tgd[j] = cnav_group_delay_s(code[j], kep.col("tgd_cnav_s")[row],
                                                kep.col("isc_l1ca_s")[row],
                                                kep.col("isc_l2c_s")[row])  # fmt: skip
                else:
                    tgd[j] = group_delay_s(
                        s, code[j], kep.col("tgd_s")[row], kep.col("aux26")[row],
                        kep.col("aux20")[row],
                    )  # fmt: skip
            if not np.isfinite(tgd[j]):
                reason[j] = f"no broadcast group delay for {code[j] or 'this signal'}"
            elif not np.isfinite(freq[j]):
                reason[j] = f"unknown carrier of {code[j]}"
        reason[~np.isfinite(pr)] = "no pseudorange"
        return SatelliteStates(
            gps_s,
            sats,
            code,
            pr,
            t_tx,
            pos,
            C_MPS * (clk - rel),
            C_MPS * rel,
            C_MPS * tgd,
            freq,
            reason.astype(str),
        )

    def correct(
        self,
        gps_s: float,
        sats: Sequence[str],
        pseudorange_m: ArrayLike,
        rx_ecef_m: ArrayLike,
        codes: str | Sequence[str] = "C1C",
        states: SatelliteStates | None = None,
        atmosphere: bool = True,
        ionosphere: bool = True,
    ) -> CorrectedRanges:
        """Corrected pseudoranges and rotated satellite positions for one epoch.

        Parameters
        ----------
        gps_s : float
            Reception epoch (receiver time tag).
        sats : sequence of str, length n_sat
        pseudorange_m : array_like, shape (n_sat,)
        rx_ecef_m : array_like, shape (3,)
            Approximate receiver position (a few km is enough for the rotation; the
            atmosphere and elevations need it within ~100 m).
        codes : str or sequence of str
            Observation code of each pseudorange.
        states : SatelliteStates, optional
            From :meth:`states` for the same epoch, to reuse across iterations.
        atmosphere : bool
            Apply ionosphere and troposphere (switch off while the position is unknown).
        ionosphere : bool
            Apply the broadcast ionosphere (off for the two ranges of an ionosphere-free
            combination: :class:`locator.sources.RinexSource` ``dual_frequency``).

        Returns
        -------
        CorrectedRanges
        """
        st = states if states is not None else self.states(gps_s, sats, pseudorange_m, codes)
        rx = np.asarray(rx_ecef_m, float).reshape(3)
        pos = st.pos_ecef_m
        rng0 = np.linalg.norm(pos - rx, axis=-1)
        rot, rng = pos, rng0
        for _ in range(3):  # tau from the geometric range; converges to < 1 um in 2 passes
            rot = _rotate_z(pos, OMEGA_E_RADPS * rng / C_MPS)
            rng = np.linalg.norm(rot - rx, axis=-1)
        n = len(st.sats)
        reason = st.reason.astype(object).copy()
        az = el = np.full(n, np.nan)
        iono = tropo = np.zeros(n)
        iono_model = np.full(n, "", "<U3")
        if np.linalg.norm(rx) > 6.0e6:
            lat, lon, h = (float(v) for v in ecef_to_geodetic(rx))
            enu = (rot - rx) @ enu_rotation(lat, lon).T
            az, el, _ = enu_to_azel(enu)
            if atmosphere:
                tropo = troposphere_delay_m(gps_s, lat, h, el, self.humidity)
                iono = np.zeros(n)
                for letter in {s[0] for s in st.sats} if ionosphere else ():
                    sel = np.array([s[0] == letter for s in st.sats])
                    coef = self.iono.klobuchar(letter)
                    if coef is not None and coef[2] == "BDS":  # BeiDou's own form, on B1I
                        d = klobuchar_bds_delay_m(gps_s, lat, lon, az[sel], el[sel], *coef[:2])
                        iono[sel] = d * (F_B1I_HZ / st.freq_hz[sel]) ** 2
                        iono_model[sel] = coef[2]
                    elif coef is not None:
                        d = klobuchar_delay_m(gps_s, lat, lon, az[sel], el[sel], *coef[:2])
                        iono[sel] = d * (F_L1_HZ / st.freq_hz[sel]) ** 2
                        iono_model[sel] = coef[2]
                below = el <= 0
                reason[below & (reason == "")] = "below the horizon"
                tropo = np.where(below, np.nan, tropo)
        elif atmosphere:
            raise ValueError(
                "rx_ecef_m is not near the Earth's surface; pass atmosphere=False"
                " until a first position is known"
            )
        usable = reason == ""
        return CorrectedRanges(
            st, rx, rot, rng, rng - rng0, iono, tropo, az, el, usable, reason.astype(str),
            iono_model,
        )  # fmt: skip
