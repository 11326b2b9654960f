"""The 1-D track-constrained GNSS locator (SATHIA) with mask-aware satellite selection.

Per epoch: :func:`select_satellites` keeps the satellites above the worst-case mask of the
current confidence interval; :func:`locate` intersects satellite-pair hyperboloids with the
antenna's path (:func:`solve_pairs`), unites the pair intervals by the integrity mode and runs
fault detection and exclusion; :func:`solve_wls` is the 1-D least-squares reference and
:func:`check_heading` the virtual-beacon heading check. :func:`run_locator` runs the whole
epoch loop over a :class:`SimSource` or :class:`RinexSource` and :func:`score_run` scores it
against the truth. See ``docs/locator.md``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from predisat.clock import pinned_utc

# The names load on first use (PEP 562), so that ``locator --help``, a bad argument or a bad
# SOURCE_DATE_EPOCH answer without importing scipy and numba (the command line checks the
# variable itself, as ``predisat`` does, and exits with one line).
_WHERE = {
    "AntennaPath": "locator.sathia",
    "EpochData": "locator.sources",
    "Exclusion": "locator.selection",
    "Fix": "locator.fde",
    "FixFlag": "locator.fde",
    "HeadingCheck": "locator.heading_check",
    "HeadingStatus": "locator.heading_check",
    "INTEGRITY_MODES": "locator.fde",
    "LocatorConfig": "locator.fde",
    "Odometer": "locator.run",
    "PairSolution": "locator.sathia",
    "PairStatus": "locator.sathia",
    "RinexSource": "locator.sources",
    "RunConfig": "locator.run",
    "RunFlag": "locator.run",
    "Selection": "locator.selection",
    "SimSource": "locator.sources",
    "TRUST_MODES": "locator.run",
    "UnionInterval": "locator.intervals",
    "WlsSolution": "locator.wls",
    "all_pairs": "locator.sathia",
    "along_track_g": "locator.intervals",
    "best_pair": "locator.intervals",
    "check_heading": "locator.heading_check",
    "delay_model_m": "locator.heading_check",
    "direction_at": "locator.selection",
    "fit_error_model": "locator.intervals",
    "locate": "locator.fde",
    "plan_pairs": "locator.intervals",
    "range_difference_m": "locator.sathia",
    "run_locator": "locator.run",
    "score_run": "locator.evaluate",
    "select_satellites": "locator.selection",
    "solve_pairs": "locator.sathia",
    "solve_wls": "locator.wls",
    "summarise": "locator.evaluate",
    "three_independent_pairs": "locator.intervals",
    "union_interval": "locator.intervals",
}

if TYPE_CHECKING:
    from locator.evaluate import (
        score_run,
        summarise,
    )
    from locator.fde import (
        INTEGRITY_MODES,
        Fix,
        FixFlag,
        LocatorConfig,
        locate,
    )
    from locator.heading_check import (
        HeadingCheck,
        HeadingStatus,
        check_heading,
        delay_model_m,
    )
    from locator.intervals import (
        UnionInterval,
        along_track_g,
        best_pair,
        fit_error_model,
        plan_pairs,
        three_independent_pairs,
        union_interval,
    )
    from locator.run import (
        TRUST_MODES,
        Odometer,
        RunConfig,
        RunFlag,
        run_locator,
    )
    from locator.sathia import (
        AntennaPath,
        PairSolution,
        PairStatus,
        all_pairs,
        range_difference_m,
        solve_pairs,
    )
    from locator.selection import (
        Exclusion,
        Selection,
        direction_at,
        select_satellites,
    )
    from locator.sources import (
        EpochData,
        RinexSource,
        SimSource,
    )
    from locator.wls import (
        WlsSolution,
        solve_wls,
    )

__all__ = [
    "INTEGRITY_MODES",
    "TRUST_MODES",
    "AntennaPath",
    "EpochData",
    "Exclusion",
    "Fix",
    "FixFlag",
    "HeadingCheck",
    "HeadingStatus",
    "LocatorConfig",
    "Odometer",
    "PairSolution",
    "PairStatus",
    "RinexSource",
    "RunConfig",
    "RunFlag",
    "Selection",
    "SimSource",
    "UnionInterval",
    "WlsSolution",
    "all_pairs",
    "along_track_g",
    "best_pair",
    "check_heading",
    "delay_model_m",
    "direction_at",
    "fit_error_model",
    "locate",
    "plan_pairs",
    "range_difference_m",
    "run_locator",
    "score_run",
    "select_satellites",
    "solve_pairs",
    "solve_wls",
    "summarise",
    "three_independent_pairs",
    "union_interval",
]


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'locator' has no attribute {name!r}")
    # a bad SOURCE_DATE_EPOCH named here: numpy's f2py, which the modules reach through scipy,
    # reads it with int() at import and fails without saying which variable
    pinned_utc()
    value = getattr(importlib.import_module(where), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
