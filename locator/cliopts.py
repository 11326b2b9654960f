"""Command-line options that ``locator run`` and ``locator balises`` share (argparse only here
and in :mod:`locator.cli`; the library takes typed parameters)."""

from __future__ import annotations

import argparse
from typing import Any

from predisat.cli.args import add_map_doubt, map_doubt_arg

__all__ = ["add_map_doubt", "map_doubt_of"]


def map_doubt_of(args: argparse.Namespace) -> dict[str, Any]:
    """``LocatorConfig`` keywords of ``--map-doubt`` (:func:`predisat.cli.args.add_map_doubt`,
    the option ``predisat availability`` shares; none when not given: the defaults)."""
    if getattr(args, "map_doubt", None) is None:
        return {}
    doubt = map_doubt_arg(args)
    return {"map_doubt_lateral_m": doubt.lateral_m, "map_doubt_vertical_m": doubt.vertical_m}
