"""Argument types shared by the command lines: output paths checked before any work starts.

A run that computes for minutes and then cannot write (``--out`` names a file where a folder
is expected, or the reverse) loses the work; argparse refuses such paths at once, with the fix.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["output_dir", "output_file"]


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
    """An output file: not a folder, in a folder that exists."""
    p = Path(value)
    if p.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value} is a folder; give a file path (inside it, if that is where it belongs)"
        )
    if not p.parent.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value}: folder {p.parent} does not exist; create it first or choose another path"
        )
    return p
