"""The 1-D track-constrained GNSS locator (SATHIA) with mask-aware satellite selection.

Per epoch: :func:`select_satellites` keeps the satellites above the worst-case mask of the
current confidence interval; :func:`locate` intersects satellite-pair hyperboloids with the
antenna's path (:func:`solve_pairs`), unites the pair intervals by the integrity mode and runs
fault detection and exclusion; :func:`solve_wls` is the 1-D least-squares reference and
:func:`check_heading` the virtual-beacon heading check. :func:`run_locator` runs the whole
epoch loop over a :class:`SimSource` or :class:`RinexSource` and :func:`score_run` scores it
against the truth. See ``docs/locator.md``.
"""

from predisat.clock import pinned_utc

# a bad SOURCE_DATE_EPOCH named here: numpy's f2py, which the imports below reach through
# scipy, reads it with int() at import and fails without saying which variable
pinned_utc()

from locator.evaluate import score_run, summarise  # noqa: E402
from locator.fde import INTEGRITY_MODES, Fix, FixFlag, LocatorConfig, locate  # noqa: E402
from locator.heading_check import HeadingCheck, HeadingStatus, check_heading, delay_model_m  # noqa: E402
from locator.intervals import (  # noqa: E402
    UnionInterval,
    along_track_g,
    best_pair,
    fit_error_model,
    plan_pairs,
    three_independent_pairs,
    union_interval,
)
from locator.run import TRUST_MODES, Odometer, RunConfig, RunFlag, run_locator  # noqa: E402
from locator.sathia import (  # noqa: E402
    AntennaPath,
    PairSolution,
    PairStatus,
    all_pairs,
    range_difference_m,
    solve_pairs,
)
from locator.selection import Exclusion, Selection, direction_at, select_satellites  # noqa: E402
from locator.sources import EpochData, RinexSource, SimSource  # noqa: E402
from locator.wls import WlsSolution, solve_wls  # noqa: E402

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
