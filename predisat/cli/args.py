"""Argument types shared by the command lines, checked before any work starts.

A run that computes for minutes and then cannot write (``--out`` names a file where a folder
is expected, or the reverse) loses the work, and a value the library refuses later is reported
under its internal name; argparse refuses both at once, under the option's name, with the fix.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

__all__ = ["caused_by_interrupt", "cutoff_deg", "finite_float", "non_negative_float",
           "output_dir", "output_file", "positive_float", "positive_int"]  # fmt: skip


def output_dir(value: str) -> Path:
    """An output folder: absent (it is created) or an existing folder, never a file."""
    p = Path(value)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value} is an existing file, not a folder; give a folder path (it is created "
            "if absent)"
        )
    return p


def output_file(value: str) -> Path:
    """An output file: not a folder, and not under a file (missing folders are created)."""
    p = Path(value)
    if p.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value} is a folder; give a file path (inside it, if that is where it belongs)"
        )
    blocking = next((a for a in p.parents if a.exists() and not a.is_dir()), None)
    if blocking is not None:
        raise argparse.ArgumentTypeError(
            f"{value}: {blocking} is a file, so no folder can be made there; choose another path"
        )
    return p


def finite_float(value: str) -> float:
    """Any finite number (a chainage, a kilometre)."""
    return _number(value)


def _number(value: str) -> float:
    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a number") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"{value} is not a finite number")
    return x


def positive_int(value: str) -> int:
    """A count of at least 1 (workers, epochs)."""
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a whole number") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"{value} must be 1 or more")
    return n


def positive_float(value: str) -> float:
    """A finite number above 0 (a spacing, a step, a duration)."""
    x = _number(value)
    if x <= 0.0:
        raise argparse.ArgumentTypeError(f"{value} must be above 0")
    return x


def non_negative_float(value: str) -> float:
    """A finite number of 0 or more (a margin, an uncertainty)."""
    x = _number(value)
    if x < 0.0:
        raise argparse.ArgumentTypeError(f"{value} must be 0 or more")
    return x


def cutoff_deg(value: str) -> float:
    """An elevation cut-off in degrees, in [0, 90)."""
    x = _number(value)
    if not 0.0 <= x < 90.0:
        raise argparse.ArgumentTypeError(
            f"{value} is not an elevation cut-off; give degrees in [0, 90)"
        )
    return x


def caused_by_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` comes from Ctrl-C: numba-compiled code turns the KeyboardInterrupt
    into a SystemError caused by it, which a command line should treat as an interrupt."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return False
