"""GNSS time scales: GPS seconds, UTC and leap seconds, BeiDou and GLONASS time.

Every time inside PREDISAT is ``gps_s``: float seconds since the GPS epoch
1980-01-06T00:00:00 on the GPS time scale (no leap seconds). This module converts at the edges:

* calendar dates on any GNSS time scale (GPST, GST, QZSST, IRNSS time, BDT, UTC and GLONASS
  time as written in RINEX, which is UTC) to ``gps_s``;
* ``gps_s`` to UTC calendar dates (``numpy.datetime64``), e.g. for sgp4 or reports.

Galileo system time, QZSS time and IRNSS time are steered to GPST within tens of nanoseconds and
are treated as equal to it. BDT is GPST - 14 s (BDT started on 2006-01-01 00:00:00 UTC, when
GPST - UTC was 14 s). RINEX navigation files give GLONASS epochs in UTC (the receiver has already
removed the 3 h of UTC(SU)+3h), so only the leap seconds remain to be added.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "BDT_MINUS_GPST_S",
    "GPS_EPOCH",
    "LEAP_SECONDS",
    "LEAP_TABLE_CERTAIN_UNTIL_UTC",
    "SECONDS_PER_WEEK",
    "calendar_to_gps_s",
    "datetime64_to_gps_s",
    "gps_minus_utc_at_gps_s",
    "gps_minus_utc_s",
    "gps_s_to_datetime64",
    "gps_s_to_text",
    "gps_s_to_utc_datetime64",
    "gps_s_to_utc_text",
    "utc_datetime64_to_gps_s",
    "week_seconds_to_gps_s",
]

GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
SECONDS_PER_WEEK = 604800.0
BDT_MINUS_GPST_S = -14.0
"""BDT = GPST - 14 s (constant; both scales are free of leap seconds)."""

# (first UTC day with the new offset, GPST - UTC in s). Source: IERS Bulletin C; no leap second
# has been announced after 2017-01-01 (Bulletin C 69, January 2025).
LEAP_SECONDS: tuple[tuple[str, int], ...] = (
    ("1981-07-01", 1),
    ("1982-07-01", 2),
    ("1983-07-01", 3),
    ("1985-07-01", 4),
    ("1988-01-01", 5),
    ("1990-01-01", 6),
    ("1991-01-01", 7),
    ("1992-07-01", 8),
    ("1993-07-01", 9),
    ("1994-07-01", 10),
    ("1996-01-01", 11),
    ("1997-07-01", 12),
    ("1999-01-01", 13),
    ("2006-01-01", 14),
    ("2009-01-01", 15),
    ("2012-07-01", 16),
    ("2015-07-01", 17),
    ("2017-01-01", 18),
)

LEAP_TABLE_CERTAIN_UNTIL_UTC = "2026-01-01"
"""The table holds before this UTC day: Bulletin C 69 ruled out a leap second at the end of June
2025, and the next possible one is at the end of December 2025. Later, a navigation file's LEAP
SECONDS is the check (:func:`predisat.gnss.rinex_nav.read_rinex_nav`)."""

_LEAP_UTC_S = np.array(
    [(np.datetime64(d, "ns") - GPS_EPOCH) / np.timedelta64(1, "s") for d, _ in LEAP_SECONDS]
)
_LEAP_N = np.array([n for _, n in LEAP_SECONDS], float)
# the same instants on the GPS scale (the new offset already counts there)
_LEAP_GPS_S = _LEAP_UTC_S + _LEAP_N


def calendar_to_gps_s(
    year: ArrayLike,
    month: ArrayLike,
    day: ArrayLike,
    hour: ArrayLike = 0,
    minute: ArrayLike = 0,
    second: ArrayLike = 0.0,
) -> NDArray:
    """Seconds since the GPS epoch of calendar dates counted on a leap-free scale.

    The date is interpreted on the scale it is written in: for GPST (and GST, QZSST) the result
    is ``gps_s``; for UTC it is the UTC seconds count, to be passed through
    :func:`utc_datetime64_to_gps_s`-style correction (see :func:`gps_minus_utc_s`).

    Parameters
    ----------
    year, month, day, hour, minute : array_like of int, shape (...)
    second : array_like of float, shape (...)

    Returns
    -------
    ndarray of float, shape (...)
    """
    y, mo, d, h, mi, s = np.broadcast_arrays(
        np.asarray(year, np.int64),
        np.asarray(month, np.int64),
        np.asarray(day, np.int64),
        np.asarray(hour, np.int64),
        np.asarray(minute, np.int64),
        np.asarray(second, float),
    )
    # days from civil (Howard Hinnant's algorithm), exact for any Gregorian date
    yy = y - (mo <= 2)
    era = np.floor_divide(yy, 400)
    yoe = yy - era * 400
    mp = (mo + 9) % 12
    doy = (153 * mp + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    days_unix = era * 146097 + doe - 719468
    days = days_unix - 3657  # 1980-01-06 is day 3657 after 1970-01-01
    return days * 86400.0 + h * 3600.0 + mi * 60.0 + s


def gps_minus_utc_s(utc_s: ArrayLike) -> NDArray:
    """GPST - UTC in seconds at UTC instants given as seconds since 1980-01-06 on the UTC scale.

    Parameters
    ----------
    utc_s : array_like, shape (...)
        UTC calendar seconds counted from 1980-01-06T00:00:00 (as returned by
        :func:`calendar_to_gps_s` for a UTC date).

    Returns
    -------
    ndarray of float, shape (...)
    """
    idx = np.searchsorted(_LEAP_UTC_S, np.asarray(utc_s, float), side="right")
    return np.concatenate([[0.0], _LEAP_N])[idx]


def gps_minus_utc_at_gps_s(gps_s: ArrayLike) -> NDArray:
    """GPST - UTC in seconds at instants given in ``gps_s``, shape as ``gps_s``.

    During an inserted leap second (UTC 23:59:60) it is still the old offset: that second and
    the next map onto the same ``datetime64`` (:func:`gps_s_to_utc_text` writes ``23:59:60``).
    """
    idx = np.searchsorted(_LEAP_GPS_S, np.asarray(gps_s, float), side="right")
    return np.concatenate([[0.0], _LEAP_N])[idx]


def datetime64_to_gps_s(t: ArrayLike) -> NDArray:
    """``gps_s`` of ``numpy.datetime64`` values that are already on the GPS time scale."""
    return (np.asarray(t, "datetime64[ns]") - GPS_EPOCH) / np.timedelta64(1, "s")


def utc_datetime64_to_gps_s(t_utc: ArrayLike) -> NDArray:
    """``gps_s`` of UTC instants given as ``numpy.datetime64`` (leap seconds added)."""
    utc_s = datetime64_to_gps_s(t_utc)
    return utc_s + gps_minus_utc_s(utc_s)


def gps_s_to_datetime64(gps_s: ArrayLike) -> NDArray:
    """GPS-scale calendar dates (``datetime64[ns]``) of ``gps_s`` values (no leap seconds);
    NaT where ``gps_s`` is NaN (numpy warned on casting it)."""
    g = np.asarray(gps_s, float)
    ok = np.isfinite(g)
    ns = np.round(np.where(ok, g, 0.0) * 1e9).astype(np.int64).astype("timedelta64[ns]")
    out = np.where(ok, GPS_EPOCH + ns, np.datetime64("NaT", "ns"))
    return out[()] if out.ndim == 0 else out  # a scalar for a scalar, as before


def gps_s_to_text(gps_s: float) -> str:
    """GPS-scale calendar text of one ``gps_s`` for messages: ``2020-06-25 06:00:00``."""
    return str(gps_s_to_datetime64(float(gps_s)).astype("M8[s]")).replace("T", " ")


def gps_s_to_utc_text(gps_s: float) -> str:
    """UTC calendar text of one ``gps_s``, leap seconds removed: ``2011-09-14 01:46:25 UTC``.

    The inserted second itself reads ``23:59:60`` (``2016-12-31 23:59:60 UTC``).
    """
    g = float(gps_s)
    k = int(np.searchsorted(_LEAP_GPS_S, g, side="right"))
    if k < _LEAP_GPS_S.size and _LEAP_GPS_S[k] - 1.0 <= g:
        # numpy has no 23:59:60: the second before it, written with 60
        before = str(gps_s_to_utc_datetime64(g - 1.0).astype("M8[s]")).replace("T", " ")
        return before[:-2] + "60 UTC"
    return str(gps_s_to_utc_datetime64(g).astype("M8[s]")).replace("T", " ") + " UTC"


def gps_s_to_utc_datetime64(gps_s: ArrayLike) -> NDArray:
    """UTC dates (``datetime64[ns]``) of ``gps_s`` values, leap seconds removed.

    numpy's dates have no 23:59:60: an inserted leap second maps onto the next day's first
    second (:func:`gps_s_to_utc_text` writes it out).
    """
    g = np.asarray(gps_s, float)
    return gps_s_to_datetime64(g - gps_minus_utc_at_gps_s(g))


def week_seconds_to_gps_s(week: ArrayLike, sow_s: ArrayLike) -> NDArray:
    """``gps_s`` of a continuous GPS week number and seconds of week."""
    return np.asarray(week, float) * SECONDS_PER_WEEK + np.asarray(sow_s, float)
