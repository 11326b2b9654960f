"""Command-line options that ``locator run`` and ``locator balises`` share (argparse only here
and in :mod:`locator.cli`; the library takes typed parameters)."""

from __future__ import annotations

import argparse
from typing import Any

from predisat.cli.args import non_negative_float

__all__ = ["add_map_doubt", "map_doubt_of"]


def add_map_doubt(p: argparse.ArgumentParser) -> None:
    """``--map-doubt LAT VERT``: :attr:`locator.fde.LocatorConfig.map_doubt_lateral_m` and
    ``map_doubt_vertical_m``."""
    from locator.fde import LocatorConfig  # lazy: --help without numba

    d = LocatorConfig.__dataclass_fields__
    lat, vert = d["map_doubt_lateral_m"].default, d["map_doubt_vertical_m"].default
    p.add_argument(
        "--map-doubt", nargs=2, type=non_negative_float, metavar=("LAT", "VERT"),
        help="how far the antenna may be beside and above or below the track map, metres: the "
        "map's accuracy, the antenna's lateral lever arm, cant, a passing loop; each pair "
        f"interval is widened to bound the error that makes (default {lat:g} {vert:g}: a map "
        "good to a metre; an OpenStreetMap line needs several metres; 0 0: the source's pairs; "
        "docs/locator.md)",
    )  # fmt: skip


def map_doubt_of(args: argparse.Namespace) -> dict[str, Any]:
    """``LocatorConfig`` keywords of ``--map-doubt`` (none when not given: the defaults)."""
    given = getattr(args, "map_doubt", None)
    if given is None:
        return {}
    return {"map_doubt_lateral_m": float(given[0]), "map_doubt_vertical_m": float(given[1])}
