"""Command line of the 1-D locator (``locator``)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from predisat import __version__

__all__ = ["main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="locator",
        description=(
            "1-D track-constrained GNSS locator (satellite-pair hyperbolic intersection with "
            "the track, SATHIA) with mask-aware satellite selection. Subcommands arrive with "
            "issue #5 (run, simulate, calibrate, evaluate)."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    parser.parse_args(argv)
    parser.print_help()
    return 0
