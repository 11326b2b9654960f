"""The time a run writes into its outputs: now, or pinned by ``SOURCE_DATE_EPOCH``.

The reproducible-builds convention: a run that pins its time writes the same bytes as any other
run with the same inputs (a resumed one, one on a cluster), which is how those runs are compared
with a serial one. ``predisat process`` and ``predisat availability`` both stamp through here.
"""

from __future__ import annotations

import os
from datetime import UTC, datetime

__all__ = ["pinned_utc", "utc_stamp"]


def pinned_utc() -> str | None:
    """The time of ``SOURCE_DATE_EPOCH`` when it is set, ISO 8601 UTC to the second, else None.

    Raises
    ------
    ValueError
        ``SOURCE_DATE_EPOCH`` is set but is not whole seconds since 1970-01-01 UTC.
    """
    pinned = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    if not pinned:
        return None
    try:
        return datetime.fromtimestamp(int(pinned), UTC).isoformat(timespec="seconds")
    except (ValueError, OverflowError, OSError):
        raise ValueError(
            f"SOURCE_DATE_EPOCH={pinned!r} is not a time; give whole seconds since "
            "1970-01-01 UTC (e.g. 1700000000) or unset it"
        ) from None


def utc_stamp(pinned: str | None = None) -> str:
    """``pinned`` when given, else now: UTC, ISO 8601 to the second."""
    return pinned if pinned is not None else datetime.now(UTC).isoformat(timespec="seconds")
