"""Passive and active integrity: one epoch of the 1-D locator, with fault detection and exclusion.

:func:`locate` turns one epoch of trusted measurements into a fix: a chainage, a confidence
interval and flags.

* **Passive integrity** (``integrity="passive"``): every measurement is used and nothing is
  excluded; with 4 or more satellites the interval is the union of *all* pair intervals
  (scheme ``"all"``), so poor measurements and blunt pairs only lengthen it. Faults are
  flagged, not acted on.
* **Active integrity / FDE** (``integrity="active"``):

  1. *detection*: the 1-D weighted least squares (:func:`locator.wls.solve_wls`) gives
     ``chi2`` with ``n - 2`` degrees of freedom; a fault is declared when its p-value is below
     ``p_false_alarm``, or when the SATHIA pair intervals have no common point, or a pair
     contradicts the whole search window (``PairStatus.EMPTY``);
  2. *exclusion*: the satellite with the largest normalised residual (w-test) is removed and
     the epoch is solved again, up to ``max_exclusions`` times and only while at least 3
     satellites remain after the exclusion (so that the remaining set can still be tested);
     a fault that cannot be isolated is flagged ``FAULT_DETECTED`` and the fix makes no safety
     claim;
  3. *geometry*: pairs whose intersection with the track is blunt (``|g_i - g_j| <
     min_slope``, the along-track sensitivity at the prior) are dropped in the all-pairs mode;
     in the other modes a blunt chosen pair is flagged;
  4. the interval is formed by the count rule of :mod:`locator.intervals` (three independent
     pairs for >= 6 satellites, all pairs for 4-5, best pair without safety claim for 2-3).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntFlag

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.intervals import along_track_g, plan_pairs, union_interval
from locator.sathia import AntennaPath, PairSolution, PairStatus, solve_pairs
from locator.wls import WlsSolution, solve_wls
from predisat.availability.interval import (
    INDEPENDENT_PAIRS,
    IntervalMode,
    MapDoubt,
    interval_mode,
    width_text,
)
from predisat.gnss.errormodel import IntervalModel
from predisat.gnss.integrity import DEFAULT_BUDGET, IntegrityBudget, disjoint_pairs
from predisat.readonly import freeze_array_fields

__all__ = ["INTEGRITY_MODES", "Fix", "FixFlag", "LocatorConfig", "locate", "map_doubt_bias_m"]

# the ellipsoid normal at a point is the gradient of x^2/a^2 + y^2/a^2 + z^2/b^2: x scaled by
# (1, 1, (a/b)^2)
_ELLIPSOID_NORMAL_SCALE = np.array([1.0, 1.0, 1.0 / (1.0 - 1.0 / 298.257223563) ** 2])

INTEGRITY_MODES = ("passive", "active")


class FixFlag(IntFlag):
    """Flags of a :class:`Fix` (0: a clean fix with a safety claim)."""

    NONE = 0
    NO_SAFETY_CLAIM = 1  # 2-3 satellites, or any condition below that voids the claim
    TOO_FEW = 2  # fewer than 2 satellites: no fix
    EXCLUDED = 4  # FDE excluded at least one satellite
    FAULT_DETECTED = 8  # an inconsistency remains (not isolated, or passive)
    BLUNT = 16  # blunt pairs dropped (active, all-pairs) or a blunt pair used
    AMBIGUOUS = 32  # a pair cut the track more than once in the window
    NO_ROOT = 64  # a pair did not cut the track in the window
    UNBOUNDED = 128  # the interval reaches the search window's end
    INCONSISTENT_PAIRS = 256  # the pair intervals have no common point
    EMPTY_PAIR = 512  # a pair contradicts the whole search window (PairStatus.EMPTY)
    HEADING_FAIL = 1024  # the virtual-beacon heading check failed (locator.run)


@dataclass(frozen=True)
class LocatorConfig:
    """Parameters of :func:`locate`.

    Attributes
    ----------
    model : IntervalModel
        Error model and ``k_sigma`` (width of each pair interval when no ``budget`` is given).
    budget : IntegrityBudget or None
        The integrity risk per epoch: each epoch's pairs are ``k`` wide for the number of
        disjoint pairs among those united (:func:`predisat.gnss.integrity.disjoint_pairs`:
        three in three-pair mode, two for every pair of 4-5 satellites, fewer when blunt pairs
        were dropped), and ``model.k_sigma`` is not used. Default
        :data:`predisat.gnss.integrity.DEFAULT_BUDGET` (1e-12 per epoch, as ``locator run``'s
        ``--integrity-risk``); None keeps ``model.k_sigma`` in every mode (``k = 2``: the
        source's, 2.4e-5 per epoch with three pairs).
    window_m, step_m : float
        SATHIA search window half width and grid step, metres.
    min_slope : float
        Pairs with ``|g_i - g_j|`` below this are blunt (metres of range difference per metre
        of chainage); 0.2 keeps every pair's half length under ``5 k sigma_K``.
    p_false_alarm : float
        Chi-square test level of the detection.
    max_exclusions : int
    map_doubt_lateral_m, map_doubt_vertical_m : float
        How far the antenna may be beside and above or below the antenna path (the track map
        raised by the antenna height), metres: the map's accuracy, the antenna's lateral lever
        arm, the cant's sway, a train on a loop. Each pair's band grows by the largest bias
        that puts in its range difference, ``lat |(u_i - u_j)_level| + vert |(u_i - u_j).up|``
        (:func:`map_doubt_bias_m`: any level direction), so the pair still bounds the
        train (a trial: antennas 1.5-4.5 m beside the map broke the 1e-12 budget, and gave
        hazardous misleading information with k = 2 on real stations; docs/locator.md).
        Default 1.5 m and 1 m: a map good to a metre, a centred roof antenna, cant; 0 and 0
        give the pairs of the source.
    """

    model: IntervalModel = field(default_factory=IntervalModel)
    budget: IntegrityBudget | None = DEFAULT_BUDGET
    window_m: float = 1000.0
    step_m: float = 5.0
    min_slope: float = 0.2
    p_false_alarm: float = 1e-3
    max_exclusions: int = 2
    map_doubt_lateral_m: float = MapDoubt().lateral_m  # the availability prediction's default
    map_doubt_vertical_m: float = MapDoubt().vertical_m

    def __post_init__(self) -> None:
        if not (self.window_m > 0 and self.step_m > 0):
            raise ValueError(f"window_m and step_m must be positive: {self}")
        if not 0 <= self.min_slope < 2:
            raise ValueError(f"min_slope must be in [0, 2), got {self.min_slope}")
        if not 0 < self.p_false_alarm < 1:
            raise ValueError(f"p_false_alarm must be in (0, 1), got {self.p_false_alarm}")
        if self.max_exclusions < 0:
            raise ValueError(f"max_exclusions must be >= 0, got {self.max_exclusions}")
        for name in ("map_doubt_lateral_m", "map_doubt_vertical_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0 metres, got {v}")

    def k_sigma_for(self, pairs: ArrayLike) -> float:
        """Half width (sigmas of ``K``) of the pair intervals when ``pairs`` (p, 2) are united.

        ``model.k_sigma`` without a budget; with one, the budget's ``k`` for the disjoint
        pairs among them (at least one).
        """
        if self.budget is None:
            return self.model.k_sigma
        return self.budget.k_sigma(max(disjoint_pairs(pairs), 1))

    @property
    def fixed_k_sigma(self) -> float | None:
        """The one ``k`` of every pair interval without an integrity budget (``--k-sigma``:
        a width the user chose, no stated risk), None when a budget sets the widths."""
        return self.model.k_sigma if self.budget is None else None

    def width_text(self) -> str:
        """The pair-interval width in words: the budget and each mode's ``k``, or the one ``k``
        (:func:`predisat.availability.interval.width_text`)."""
        text = width_text(self.budget if self.budget is not None else self.model.k_sigma)
        return text + self._doubt_text()

    @property
    def map_doubt(self) -> MapDoubt:
        """The map doubt as the availability prediction takes it."""
        return MapDoubt(self.map_doubt_lateral_m, self.map_doubt_vertical_m)

    def _doubt_text(self) -> str:
        return ", " + self.map_doubt.describe()

    def width_label(self) -> str:
        """Short form for figure titles: ``integrity risk 1e-12 per epoch`` or ``k = 2``."""
        return f"k = {self.model.k_sigma:g}" if self.budget is None else self.budget.label()

    def plan_k_sigma(self, n_sat: int) -> float:
        """``k`` of the pair choice for ``n_sat`` trusted satellites: the predicted mode's
        (:data:`predisat.availability.interval.INDEPENDENT_PAIRS`), as the availability
        prediction chooses them."""
        if self.budget is None:
            return self.model.k_sigma
        mode = IntervalMode(int(interval_mode(n_sat)))
        return self.budget.k_sigma(INDEPENDENT_PAIRS.get(mode, 1))


@dataclass(frozen=True)
class Fix:
    """One epoch's location.

    Attributes
    ----------
    chainage_m : float
        SATHIA estimate (weighted mean of the pair roots); NaN without a fix.
    lo_m, hi_m : float
        Confidence interval (union of the pair intervals of the mode).
    mode : IntervalMode
    integrity : str
        ``"passive"`` or ``"active"``.
    flags : FixFlag
    used : ndarray of bool, shape (n_sat,)
        Satellites in the final solution.
    excluded : tuple of int
        Satellites excluded by FDE, in order.
    pairs : PairSolution
        The pairs united, with indices into the epoch's satellites.
    wls : WlsSolution or None
        The reference estimator on the used satellites.
    sats : tuple of str
    """

    chainage_m: float
    lo_m: float
    hi_m: float
    mode: IntervalMode
    integrity: str
    flags: FixFlag
    used: NDArray
    excluded: tuple[int, ...]
    pairs: PairSolution | None
    wls: WlsSolution | None
    sats: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def safety_claim(self) -> bool:
        return not (int(self.flags) & _NO_CLAIM_OR_TOO_FEW)

    @property
    def length_m(self) -> float:
        return self.hi_m - self.lo_m

    def contains(self, chainage_m: float) -> bool:
        return bool(self.lo_m <= chainage_m <= self.hi_m)

    @property
    def excluded_sats(self) -> tuple[str, ...]:
        return tuple(self.sats[k] if self.sats else str(k) for k in self.excluded)


def locate(
    path: AntennaPath,
    sat_ecef_m: ArrayLike,
    pseudorange_m: ArrayLike,
    el_deg: ArrayLike,
    *,
    prior_m: float,
    integrity: str = "active",
    config: LocatorConfig | None = None,
    sigma_m: ArrayLike | None = None,
    sats: Sequence[str] = (),
) -> Fix:
    """Locate the train along the track at one epoch.

    Parameters
    ----------
    path : AntennaPath
    sat_ecef_m : array_like, shape (n_sat, 3)
        Positions of the *trusted* satellites (:mod:`locator.selection`), metres.
    pseudorange_m : array_like, shape (n_sat,)
        Corrected pseudoranges, metres.
    el_deg : array_like, shape (n_sat,)
        Elevations for the error model, degrees.
    prior_m : float
        Centre of the search window (previous fix + odometry), chainage metres.
    integrity : {"active", "passive"}
    config : LocatorConfig, optional
    sigma_m : array_like, shape (n_sat,), optional
        Overrides ``config.model.error.sigma_m(el_deg)``.
    sats : sequence of str
        Satellite ids, for the report.

    Returns
    -------
    Fix
    """
    if integrity not in INTEGRITY_MODES:
        raise ValueError(f"integrity must be one of {INTEGRITY_MODES}, got {integrity!r}")
    cfg = config or LocatorConfig()
    sat = np.asarray(sat_ecef_m, float)
    rho = np.asarray(pseudorange_m, float)
    el = np.asarray(el_deg, float)
    n = len(rho)
    sig = cfg.model.error.sigma_m(el) if sigma_m is None else np.asarray(sigma_m, float)
    if sat.shape != (n, 3) or el.shape != (n,) or sig.shape != (n,):
        raise ValueError(
            f"sat_ecef_m must be ({n}, 3) and el_deg, sigma_m ({n},) like pseudorange_m: got "
            f"{sat.shape}, {el.shape}, {sig.shape}"
        )
    if sats and len(sats) != n:
        raise ValueError(f"sats has {len(sats)} names for {n} satellites")
    used = np.ones(n, bool)
    excluded: list[int] = []
    active = integrity == "active"
    while True:
        fix, fault, worst = _solve(path, sat, rho, sig, used, prior_m, cfg, active)
        can_exclude = active and len(excluded) < cfg.max_exclusions and used.sum() - 1 >= 3
        if fault and can_exclude and worst >= 0:
            used = used.copy()
            used[worst] = False
            excluded.append(worst)
            continue
        flags = int(fix.flags)
        if excluded:
            flags |= _EXCLUDED
        if fault:
            flags |= _FAULT | _NO_CLAIM
        return dataclasses.replace(
            fix, flags=_fix_flag(flags), used=used, excluded=tuple(excluded), integrity=integrity,
            sats=tuple(sats),
        )  # fmt: skip


# the flag and status bits as ints: an enum member looked up per epoch cost more than the
# arithmetic of the epoch (Python 3.11's Enum.__getattr__)
_NO_CLAIM, _EXCLUDED = int(FixFlag.NO_SAFETY_CLAIM), int(FixFlag.EXCLUDED)
_FAULT, _BLUNT, _AMBIGUOUS = int(FixFlag.FAULT_DETECTED), int(FixFlag.BLUNT), int(FixFlag.AMBIGUOUS)
_NO_ROOT_F, _UNBOUNDED_F = int(FixFlag.NO_ROOT), int(FixFlag.UNBOUNDED)
_INCONSISTENT, _EMPTY_F = int(FixFlag.INCONSISTENT_PAIRS), int(FixFlag.EMPTY_PAIR)
_P_MULTIPLE, _P_NO_ROOT, _P_EMPTY = (int(PairStatus.MULTIPLE_ROOTS), int(PairStatus.NO_ROOT),
                                     int(PairStatus.EMPTY))  # fmt: skip
_P_UNBOUNDED = int(PairStatus.UNBOUNDED_LOW | PairStatus.UNBOUNDED_HIGH)
_MODE_ALL, _MODE_NONE = IntervalMode.ALL_PAIRS, IntervalMode.NONE
_NO_CLAIM_OR_TOO_FEW = int(FixFlag.NO_SAFETY_CLAIM | FixFlag.TOO_FEW)


@functools.cache
def _fix_flag(flags: int) -> FixFlag:
    """``FixFlag(flags)``, built once per value (a composite IntFlag is slow to make)."""
    return FixFlag(flags)


def _solve(
    path: AntennaPath,
    sat: NDArray,
    rho: NDArray,
    sig: NDArray,
    used: NDArray,
    prior_m: float,
    cfg: LocatorConfig,
    active: bool,
) -> tuple[Fix, bool, int]:
    """Fix on the used satellites; whether a fault shows; the worst satellite (global index)."""
    idx = np.flatnonzero(used)
    m = len(idx)
    if m < 2:
        empty = Fix(np.nan, np.nan, np.nan, IntervalMode.NONE, "", FixFlag.TOO_FEW
                    | FixFlag.NO_SAFETY_CLAIM, used, (), None, None)  # fmt: skip
        return empty, False, -1
    s_u, r_u, g_sig = sat[idx], rho[idx], sig[idx]
    wls = solve_wls(path, s_u, r_u, g_sig, prior_m=prior_m)
    nres = np.abs(wls.normalised_residual)
    worst = int(idx[np.nanargmax(nres)]) if np.isfinite(nres).any() else -1
    fault = wls.dof >= 1 and wls.p_value() < cfg.p_false_alarm

    flags = 0
    centre = wls.chainage_m if wls.converged else prior_m
    g = along_track_g(path, centre, s_u)
    pairs, mode = plan_pairs(g, g_sig, cfg.plan_k_sigma(m), scheme="auto" if active else "all")
    blunt = np.abs(g[pairs[:, 0]] - g[pairs[:, 1]]) < cfg.min_slope
    if blunt.any():
        flags |= _BLUNT
        if active and mode is _MODE_ALL:
            pairs = pairs[~blunt]
    # the width of the pairs actually united: fewer disjoint pairs after a drop, a wider k
    k_sigma = cfg.k_sigma_for(pairs)
    # window on the WLS fix: a prior further off than the window would void every pair
    bias = None
    if cfg.map_doubt_lateral_m > 0 or cfg.map_doubt_vertical_m > 0:
        bias = map_doubt_bias_m(path, centre, s_u, pairs, cfg.map_doubt_lateral_m,
                                cfg.map_doubt_vertical_m)  # fmt: skip
    sol = solve_pairs(path, s_u, r_u, g_sig, pairs, prior_m=centre, window_m=cfg.window_m,
                      k_sigma=k_sigma, step_m=cfg.step_m, bias_bound_m=bias)  # fmt: skip
    sol = dataclasses.replace(sol, i=idx[sol.i], j=idx[sol.j])
    uni = union_interval(sol, mode if sol.n_pairs else _MODE_NONE)
    st = int(np.bitwise_or.reduce(sol.status)) if sol.n_pairs else 0
    if st & _P_MULTIPLE:
        flags |= _AMBIGUOUS
    if st & _P_NO_ROOT:
        flags |= _NO_ROOT_F
    if st & _P_EMPTY:
        flags |= _EMPTY_F
        fault = True
    if st & _P_UNBOUNDED:
        flags |= _UNBOUNDED_F
    if sol.n_pairs and not (st & _P_EMPTY) and not uni.consistent:
        flags |= _INCONSISTENT
        fault = True
    if not uni.safety_claim:
        flags |= _NO_CLAIM
    if sol.n_pairs == 0:
        flags |= _NO_CLAIM
    fix = Fix(uni.estimate_m, uni.lo_m, uni.hi_m, uni.mode, "", _fix_flag(flags), used, (), sol,
              wls)  # fmt: skip
    return fix, bool(fault), worst


def map_doubt_bias_m(
    path: AntennaPath, chainage_m: float, sat_ecef_m: NDArray, pairs: NDArray,
    lateral_m: float, vertical_m: float,
) -> NDArray:  # fmt: skip
    """Largest range-difference bias of each pair from an antenna up to ``lateral_m`` beside
    and ``vertical_m`` above or below the path, metres.

    Moving the antenna by ``delta`` changes ``|x - S_i| - |x - S_j|`` by
    ``-(u_i - u_j) . delta`` to first order (``u`` unit vectors antenna -> satellite; the
    satellites' 20 000 km make the second order micrometres). "Beside" is taken in any level
    direction, not only across the track at ``chainage_m``: the pair is searched over a window
    of hundreds of metres, where a curve turns the normal (a review: on a 300 m radius the
    bound across the track at the window's centre was exceeded 2-6 times at 50-500 m from it),
    and its centre is a fix a fault may move. Over that box the largest bias is
    ``lateral |(u_i - u_j)_level| + vertical |(u_i - u_j).up|``, at most 1.24 times the bound
    across the track on the trial's skies.

    Parameters
    ----------
    path : AntennaPath
    chainage_m : float
        Where the directions are taken (clipped to the path); over a search window they turn
        by microradians, the vertical by 1e-4 rad per kilometre.
    sat_ecef_m : ndarray, shape (n_sat, 3)
    pairs : ndarray of int, shape (n_pairs, 2)
    lateral_m, vertical_m : float

    Returns
    -------
    ndarray, shape (n_pairs,)
    """
    c = min(max(float(chainage_m), 0.0), path.length_m)
    x = path.ecef_at(c)
    up = x * _ELLIPSOID_NORMAL_SCALE
    up = up / np.linalg.norm(up)
    u = np.asarray(sat_ecef_m, float) - x
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    pr = np.asarray(pairs, np.intp).reshape(-1, 2)
    du = u[pr[:, 0]] - u[pr[:, 1]]
    vert = du @ up
    level = np.linalg.norm(du - vert[:, None] * up, axis=-1)
    return lateral_m * level + vertical_m * np.abs(vert)
