"""The 1-D track-constrained GNSS locator (SATHIA) with mask-aware satellite selection.

Per epoch: :func:`select_satellites` keeps the satellites above the worst-case mask of the
current confidence interval; :func:`locate` intersects satellite-pair hyperboloids with the
antenna's path (:func:`solve_pairs`), unites the pair intervals by the integrity mode and runs
fault detection and exclusion; :func:`solve_wls` is the 1-D least-squares reference and
:func:`check_heading` the virtual-beacon heading check. :func:`run_locator` runs the whole
epoch loop over a :class:`SimSource` or :class:`RinexSource` and :func:`score_run` scores it
against the truth. See ``docs/locator.md``.
"""

from locator.evaluate import score_run, summarise
from locator.fde import INTEGRITY_MODES, Fix, FixFlag, LocatorConfig, locate
from locator.heading_check import HeadingCheck, HeadingStatus, check_heading, delay_model_m
from locator.intervals import (
    UnionInterval,
    along_track_g,
    best_pair,
    fit_error_model,
    plan_pairs,
    three_independent_pairs,
    union_interval,
)
from locator.run import TRUST_MODES, Odometer, RunConfig, RunFlag, run_locator
from locator.sathia import (
    AntennaPath,
    PairSolution,
    PairStatus,
    all_pairs,
    range_difference_m,
    solve_pairs,
)
from locator.selection import Exclusion, Selection, direction_at, select_satellites
from locator.sources import EpochData, RinexSource, SimSource
from locator.wls import WlsSolution, solve_wls

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
