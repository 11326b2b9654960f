"""Tests of predisat.gnss.timescale's calendar text against datetime and IERS Bulletin C."""

from __future__ import annotations

from datetime import datetime, timedelta

import pytest

from predisat.gnss.timescale import gps_s_to_text, gps_s_to_utc_text

GPS_EPOCH = datetime(1980, 1, 6)


@pytest.mark.parametrize(
    ("gps_text", "gps_minus_utc_s"),
    [
        ("2016-12-31 23:59:00", 17),  # before the leap second of 2016-12-31 23:59:60 UTC
        ("2017-01-01 00:01:00", 18),  # after it
        ("2009-06-01 12:00:00", 15),
    ],
)
def test_utc_text_removes_the_leap_seconds_of_the_day(gps_text: str, gps_minus_utc_s: int) -> None:
    t = datetime.strptime(gps_text, "%Y-%m-%d %H:%M:%S")
    gps_s = (t - GPS_EPOCH).total_seconds()
    assert gps_s_to_text(gps_s) == gps_text
    want = t - timedelta(seconds=gps_minus_utc_s)
    assert gps_s_to_utc_text(gps_s) == want.strftime("%Y-%m-%d %H:%M:%S UTC")


@pytest.mark.parametrize(
    ("gps_text", "utc_text"),
    [  # the leap second inserted after 2016-12-31 23:59:59 UTC (Bulletin C 52), GPST - UTC 17 -> 18
        ("2017-01-01 00:00:16", "2016-12-31 23:59:59 UTC"),
        ("2017-01-01 00:00:17", "2016-12-31 23:59:60 UTC"),
        ("2017-01-01 00:00:18", "2017-01-01 00:00:00 UTC"),
        ("2015-07-01 00:00:16", "2015-06-30 23:59:60 UTC"),  # Bulletin C 49, 16 -> 17
    ],
)
def test_the_inserted_second_reads_23_59_60(gps_text: str, utc_text: str) -> None:
    gps_s = (datetime.strptime(gps_text, "%Y-%m-%d %H:%M:%S") - GPS_EPOCH).total_seconds()
    assert gps_s_to_utc_text(gps_s) == utc_text
    assert gps_s_to_utc_text(gps_s + 0.5) == utc_text
