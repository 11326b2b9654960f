"""The locator's epoch loop: predicted interval, trust decision, fix, heading and odometry checks.

Per epoch ``k`` (see ``docs/locator.md``, "A run"):

1. **Predicted interval** (odometry, :mod:`locator.odometry.fusion`). The last fused interval,
   moved by the odometer distance since then and widened by the odometer's over- and
   under-reading bounds (:class:`locator.odometry.confidence.OdometerAccuracy`; default the
   ETCS SUBSET-041 requirement, 5 m + 5 %). Without an odometer the motion is bounded by
   ``max_speed_mps`` times the elapsed time. At the start: ``start_chainage_m +-
   start_uncertainty_m`` (a balise, a stop at a known platform).
2. **Trust decision** (``trust``): ``"masks"`` keeps a satellite only above the worst case of
   the masks (mask + margin) over the whole predicted interval
   (:func:`locator.selection.select_satellites`); ``"cutoff"`` keeps those above a flat
   elevation; ``"none"`` keeps every received signal above the horizon. Directions are
   computed at the centre of the predicted interval.
3. **Fix**: :func:`locator.fde.locate` on the trusted satellites (SATHIA pairs, integrity mode
   by count, FDE when ``integrity="active"``).
4. **Heading check** (2024 patent): the virtual beacon is the multiple of ``beacon_spacing_m``
   at least half a spacing behind the estimate; the heading estimated from the delays must agree
   with the chord from the beacon to the estimate's track point. A failure voids the claim.
5. **Odometry check**: a claimed interval that does not meet the predicted one, or (by default,
   ``odometry_conflict="estimate"``) whose estimate lies outside it, contradicts the odometer:
   the claim is voided (``ODOMETRY_CONFLICT``), an alarm, not a reset.
6. **Fusion**: a claimed interval that meets the prediction is intersected with it
   (``fused_lo_m``, ``fused_hi_m``); without a claim the fused interval is the prediction. The
   estimate (``fused_chainage_m``) is a 1-D Kalman filter (odometer steps, claimed fixes
   weighted by their WLS variance), clipped to the fused interval.

A fix with a safety claim re-anchors the bounds it tightened (each bound of the fused interval
keeps its own anchor: the odometer's fixed error is counted once per anchor, not at every epoch);
otherwise the prediction keeps growing from the last anchors, so a wrong claim cannot be
"forgotten" silently.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import IntFlag
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from locator.fde import INTEGRITY_MODES, Fix, FixFlag, LocatorConfig, locate
from locator.heading_check import HeadingStatus, check_heading
from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.fusion import (
    FusionStatus,
    blend_estimate,
    motion_bound,
    predict_estimate,
    predict_interval,
)
from locator.partition import MAX_STRETCHES, combine_stretches, trust_stretches
from locator.sathia import AntennaPath
from locator.selection import Exclusion, direction_at, select_satellites
from locator.sources import EpochData, EpochSource
from predisat.availability.interval import IntervalMode
from predisat.geodesy import ecef_to_geodetic, enu_rotation
from predisat.jsontypes import JsonDict
from predisat.masks.gaps import close_gaps
from predisat.masks.maskset import MaskSet
from predisat.track.alias import TrackAliases

__all__ = [
    "ERROR_MODEL_CAVEATS",
    "FORCED_BANNER",
    "TRUST_MODES",
    "Odometer",
    "RunConfig",
    "RunFlag",
    "claim_label",
    "fixed_k_of",
    "flag_names",
    "no_safety_banner",
    "run_locator",
]

TRUST_MODES = ("masks", "cutoff", "none")


class RunFlag(IntFlag):
    """Flags of the run loop, above :class:`locator.fde.FixFlag`'s bits."""

    ODOMETRY_CONFLICT = 1 << 16  # the claimed interval misses the odometry prediction
    NO_ERROR_MODEL = 1 << 17  # no calibrated error model applies to the data: no claim
    FORCED_ERROR_MODEL = 1 << 18  # intervals under a model forced onto data it does not fit
    GAUSSIAN_TAIL = 1 << 19  # claims beyond the depth the model's tails were checked to
    NO_STRETCH_CLAIM = 1 << 20  # partitioned trust: no stretch's claim holds a part of its own
    TRACK_END = 1 << 21  # the prediction reaches past an end of the track map: maybe off it
    HEADING_UNCHECKED = 1 << 22  # the heading check could not tell (unobservable, no beacon)
    ASSUMED_MASK = 1 << 23  # a used satellite was trusted where the mask rests on no view
    CLAIM_AT_TRACK_END = 1 << 24  # TRACK_END voided a claim whose interval the end bounded
    IONO_UNCORRECTED = 1 << 25  # a used satellite's ionosphere had no broadcast model
    ODOMETRY_SUSPECT = 1 << 26  # a conflict earlier, not yet cleared by agreeing fixes: no claim
    TRACK_ALIAS = 1 << 27  # the track passes beside the claim elsewhere, and nothing rules it out
    OFF_TRACK = 1 << 28  # the trusted satellites' 3-D fix lies beside the map beyond its doubt
    OFF_TRACK_UNCHECKED = 1 << 29  # no 3-D fix to check that (fewer than 5 consistent): stated
    START_CONFLICT = 1 << 30  # the satellites put the train beyond the start's interval: widened


ERROR_MODEL_CAVEATS = {
    "": "safety claim",
    "forced": "intervals under a forced error model (not a safety claim)",
    "gaussian_tail": "safety claim under the assumed Gaussian tail",
}
"""What a run's ``claim`` column means, by :attr:`RunConfig.error_model_caveat`."""


def claim_label(caveat: str, fixed_k_sigma: float | None = None) -> str:
    """``"safety claim"``, or what the claims are under a caveat (:data:`ERROR_MODEL_CAVEATS`);
    a caveat this version does not know (a run folder of a later one) is named as it is.

    ``fixed_k_sigma`` is the ``k`` of a run without an integrity budget (``--k-sigma``): its
    claims rest on a width the user chose, not on a stated risk, and are worded so (a review:
    ``k = 2`` was called "safety claim", a risk of 0.046 per epoch with one pair).
    """
    label = ERROR_MODEL_CAVEATS.get(caveat, f"claim under caveat {caveat!r} (not a safety claim)")
    if fixed_k_sigma is None or caveat not in ("", "gaussian_tail"):
        return label
    return label.replace("safety claim", f"claim at a fixed k = {fixed_k_sigma:g} (no integrity "
                         "budget)", 1)  # fmt: skip


FORCED_BANNER = "NOT A SAFETY CLAIM: intervals under a forced error model (--force-error-model)"
"""Written over every figure of a run whose claims were made under a forced error model."""


def no_safety_banner(caveat: str, fixed_k_sigma: float | None = None) -> str | None:
    """The red line over a run's figures when its claims are no safety claims (a forced error
    model, a fixed ``k``, a caveat this version does not know), None for safety claims."""
    if caveat == "forced":
        return FORCED_BANNER
    if caveat not in ERROR_MODEL_CAVEATS:
        return f"NOT A SAFETY CLAIM: claims under caveat {caveat!r}"
    if fixed_k_sigma is not None:
        return (f"NOT A SAFETY CLAIM: intervals at a fixed k = {fixed_k_sigma:g} (--k-sigma, "
                "no integrity budget)")  # fmt: skip
    return None


def fixed_k_of(config: Mapping[str, Any]) -> float | None:
    """The fixed ``k`` of a run's ``config`` (``run.json``; :meth:`RunConfig.to_dict`), None
    when an integrity budget set the widths or an older run does not say."""
    loc = config.get("locator") if isinstance(config, Mapping) else None
    if not isinstance(loc, Mapping) or "budget" not in loc or loc["budget"] is not None:
        return None
    k = (loc.get("model") or {}).get("k_sigma")
    return float(k) if isinstance(k, int | float) else None


def flag_names(flags: int) -> str:
    """``"NO_SAFETY_CLAIM|BLUNT"`` for a flags value ("" for 0)."""
    return "|".join(name for value, name in _FLAG_BITS if flags & value)


# (value, name) of every named flag bit, FixFlag's then RunFlag's (iterating the enums per
# epoch cost more than the rest of the row)
_FLAG_BITS = tuple((int(f.value), str(f.name)) for enum in (FixFlag, RunFlag) for f in enum
                   if f.value and f.name)  # fmt: skip


# The odometer's confidence (over- and under-reading bounds, motion bound without one); the name
# ``Odometer`` is kept for the callers of the placeholder it replaces.
Odometer = OdometerAccuracy


@dataclass(frozen=True)
class RunConfig:
    """Parameters of :func:`run_locator`.

    Attributes
    ----------
    locator : LocatorConfig
        Error model, ``k_sigma``, window, FDE.
    integrity : {"active", "passive"}
    trust : {"masks", "cutoff", "none"}
    cutoff_deg : float
        Flat elevation cut-off of ``trust="cutoff"``.
    extra_margin_deg : float
        Added to the masks' own margins.
    trust_stretches : int
        With ``trust="masks"``: at most this many stretches of the predicted interval, each
        with its own trusted set and fix (:mod:`locator.partition`, "partitioned trust";
        default :data:`locator.partition.MAX_STRETCHES`); 1 is the single set of the worst
        mask over the whole interval.
    odometer : OdometerAccuracy
        Over- and under-reading bounds of the source's odometer (default SUBSET-041).
    start_uncertainty_m : float
        Half width of the first predicted interval around ``start_chainage_m``.
    heading_check : bool
    beacon_spacing_m, heading_tolerance_deg : float
    odometry_check : bool
    odometry_conflict : {"estimate", "overlap"}
        When a claim contradicts the odometry: ``"overlap"`` when its interval misses the
        prediction; ``"estimate"`` (default, stricter) also when its estimate lies outside the
        prediction (a fix whose interval only grazes the prediction is suspect: a fault the FDE
        missed shows up as an estimate far from where the odometer says the train is).
    odometry_reconfirm : int
        After an odometry conflict the odometry is suspect: either side may be wrong, and the
        trust decisions rest on its prediction (the masks of the predicted stretch). Every
        epoch is flagged ``ODOMETRY_SUSPECT``, makes no claim and its fused interval is not to
        be used (fusion ``suspect``: balise capture skips it) until this many consecutive fixes
        that would have claimed agree with the prediction; the last of them claims again (a
        trial: a stuck direction channel put the fused interval 1.4 km off for the rest of the
        run, 165-177 of 381 epochs without any flag). 0: the conflict alone is flagged.
    odometry_suspect : {"repeated", "every"}
        Which conflicts begin that suspicion. ``"every"``: each one. ``"repeated"`` (default):
        each, except one where only the estimate lies outside the prediction while the claimed
        interval holds the whole prediction (a blunt fix: its interval says nothing against
        the odometry); that one voids its claim and begins the suspicion only when the
        estimate passes the same bound again 1 to 3 s later. A drifting odometer does so; a
        blunt fix's noise is one event, and at 10 Hz its ten fixes of a second are one event
        too. The per-epoch rule raised 0.91 false conflicts per km at 10 Hz against 0.07 at
        1 Hz, and one at a tunnel portal held the suspicion through the tunnel: 10 Hz balise
        capture fell from 99.7 to 90.4 % (docs/odometry.md). An over-reading or stuck
        odometer is caught as before.
    odometry_recover_s : float or None
        A suspicion that lasts this long (s, from the conflict that began it), with conflicts
        in both halves of the last such span, sets the odometer aside for the rest of the run:
        the prediction becomes the motion bound from the last anchors
        (``odometer.max_speed_mps``, true whatever the odometer did), and the suspicion clears
        as above when fixes agree with it (a lasting fault: a stuck direction channel, a wrong
        start position, a restart from a stored position the train has left, left the run
        without claims to its end in a user trial). Isolated false alarms do not: a user
        trial's healthy odometer was set aside after two alarms 8 s apart, and under masks the
        motion bound grew past anything they trust; the run claimed nothing more. The odometer
        is not taken back: a trial that did so gave a stuck direction channel's prediction back
        its fault, the trust decisions rested on it, and a claim missed the train before the
        next conflict showed.
        Column ``odometer_used``. None: never.
    start_check_m : float or None
        Until a claim first locates the run, a 3-D fix of every satellite above
        ``cutoff_deg`` (the sky check's, projected on the track: no claim rests on it) that lies
        more than this beyond the prediction at ``start_check_epochs`` consecutive epochs where
        it exists contradicts the start (``start_chainage_m +- start_uncertainty_m``). The
        prediction is then widened to also cover that fix +- this distance (the union of the
        start's place and the satellites'; the bound it moves is re-anchored there), the
        epochs are flagged ``START_CONFLICT`` until a claim locates the run, and the odometry
        is suspect (``odometry_reconfirm`` agreeing fixes before a claim). Widening is the safe
        side whichever is wrong: the trust decision takes the worst mask over both places, a
        claim must meet both, and the prediction still holds every place the start's did.
        A trial: a start 300 m ahead of the train chose satellites by the masks of where the
        train was not for the whole run (116 NLOS signals used in 216 epochs, no word of it).
        Before the run is located, a fix whose claimed interval contradicts the prediction
        (``ODOMETRY_CONFLICT``) widens it over that interval the same way: a start 50-100 m
        off (beyond its uncertainty, its sky fixes within this margin) conflicted for 20 s,
        had its healthy odometer set aside and claimed nothing for the rest of the run.
        Column ``start_check_m`` (the fix's chainage, NaN where not checked). None: no check.
    start_check_epochs : int
        Consecutive contradicting epochs (those without a fix neither count nor break the
        run of them) before the start is called contradicted: one NLOS-biased fix is not.
    sky_check_m : float or None
        Where the epoch makes no claim (too few trusted satellites: the prediction may have
        left the masks' coverage, or a fault put it where the masks trust nothing), a 3-D fix
        of every satellite above ``cutoff_deg`` is projected on the track; one that lies more
        than this beyond the prediction, and within it of the track, is an odometry conflict
        (no claim rests on it: untrusted satellites may only raise a doubt). A user trial: a
        stuck direction channel carried the prediction off the masks' coverage and the run
        gave 101 of 103 intervals off the train with no flag. Column ``sky_check_m`` (the
        check's chainage, NaN without one). None: no check.
    alias_m : float or None
        Where another stretch of the track passes within this distance of the claimed interval
        (horizontally; a balloon loop's legs, a switchback, a spiral:
        :class:`predisat.track.alias.TrackAliases`), a claim stands only when the run was
        located at a place without such a stretch and its prediction since rules every other
        stretch out; else it is flagged ``TRACK_ALIAS`` and not claimed. A user trial: a start
        on the other leg of a balloon loop 15 m away, which the pair intersections cannot tell
        apart, gave 59 claims in 111 epochs off the train; 50 m apart, fault detection caught
        it. None: no check.
    off_track_k_sigma : float or None
        At a claimed epoch, a 3-D least-squares fix of the trusted satellites (five or more,
        weighted by the error model) that lies beside the map by more than the map's lateral
        doubt (:attr:`locator.fde.LocatorConfig.map_doubt_lateral_m`) plus this many of its
        own cross-track sigmas voids the claim (``OFF_TRACK``): the train is not on the mapped
        track (a branch the map lacks, another track), or a trusted signal is reflected. A
        user trial: a train that took a branch missing from the map got 10 claims while 5-42 m
        beside it, unflagged (the 1-D fault detection caught only larger offsets). The same
        for the fix's height above the antenna on the map, against the map's vertical doubt
        (:attr:`locator.fde.LocatorConfig.map_doubt_vertical_m`) plus this many of its
        vertical sigmas (column ``off_track_up_m``): a map 15 m off in height gave a user trial
        hazardous claims, the 1-D fault detection excluding healthy satellites. 5: a
        Gaussian false alarm of 6e-7 per epoch. The 3-D fix has its own fault detection and
        exclusion (a chi-square test at ``locator.p_false_alarm``, the worst satellite left
        out while five remain): a satellite the 1-D fix excluded voided a review's correct
        claims. Without five consistent satellites the claim stands, flagged
        ``OFF_TRACK_UNCHECKED``. Column ``off_track_m`` (the fix's offset, NaN where not
        checked). None: no check.
    fusion : bool
        Intersect claimed intervals with the odometry prediction (the next anchor); False
        anchors on the claimed interval alone.
    error_model_applies : bool
        False when no calibrated error model applies to the data
        (:meth:`predisat.gnss.errormodel.ErrorModelFile.mismatches`): every epoch still gets a
        position, flagged ``NO_ERROR_MODEL`` and without a safety claim.
    model_el_min_deg, model_el_max_deg : float
        Elevations the error model was calibrated over; satellites below or above them are
        left out (``below_model``, ``above_model``), since their sigma would be an
        extrapolation (a user trial: a model fitted up to 60.7 deg took satellites up to
        72.7 deg on another station).
    error_model_caveat : {"", "forced", "gaussian_tail"}
        What the claims rest on beyond a model that applies: ``"forced"``, a model that does
        not apply, forced by the user (every epoch flagged ``FORCED_ERROR_MODEL``: not a safety
        claim); ``"gaussian_tail"``, pair intervals wider than the model's tails were checked
        to, under its Gaussian shape (flagged ``GAUSSIAN_TAIL``). ``""``: neither.
    """

    locator: LocatorConfig = field(default_factory=LocatorConfig)
    integrity: str = "active"
    trust: str = "masks"
    cutoff_deg: float = 15.0
    extra_margin_deg: float = 0.0
    trust_stretches: int = MAX_STRETCHES
    odometer: OdometerAccuracy = field(default_factory=OdometerAccuracy.subset041)
    start_uncertainty_m: float = 50.0
    heading_check: bool = True
    beacon_spacing_m: float = 100.0
    heading_tolerance_deg: float = 2.0
    odometry_check: bool = True
    odometry_conflict: str = "estimate"
    odometry_reconfirm: int = 3
    odometry_suspect: str = "repeated"
    odometry_recover_s: float | None = 20.0
    start_check_m: float | None = 50.0
    start_check_epochs: int = 2
    sky_check_m: float | None = 300.0
    alias_m: float | None = 100.0
    off_track_k_sigma: float | None = 5.0
    fusion: bool = True
    error_model_applies: bool = True
    model_el_min_deg: float = 0.0
    model_el_max_deg: float = 90.0
    error_model_caveat: str = ""

    def __post_init__(self) -> None:
        if self.integrity not in INTEGRITY_MODES:
            raise ValueError(f"integrity must be one of {INTEGRITY_MODES}, got {self.integrity!r}")
        if self.trust not in TRUST_MODES:
            raise ValueError(f"trust must be one of {TRUST_MODES}, got {self.trust!r}")
        if not 0 <= self.cutoff_deg < 90:
            raise ValueError(f"cutoff_deg must be in [0, 90), got {self.cutoff_deg}")
        if self.extra_margin_deg < 0 or self.start_uncertainty_m < 0:
            raise ValueError("extra_margin_deg and start_uncertainty_m must be >= 0")
        if self.odometry_conflict not in ("estimate", "overlap"):
            raise ValueError(
                f"odometry_conflict must be 'estimate' or 'overlap', got {self.odometry_conflict!r}"
            )
        if self.off_track_k_sigma is not None and not self.off_track_k_sigma > 0:
            raise ValueError(f"off_track_k_sigma must be > 0 or None, got {self.off_track_k_sigma}")
        if self.alias_m is not None and not self.alias_m >= 20.0:
            raise ValueError(f"alias_m must be >= 20 m (four 5 m samples of the track) or None, "
                             f"got {self.alias_m}")  # fmt: skip
        if self.start_check_m is not None and not self.start_check_m > 0:
            raise ValueError(f"start_check_m must be > 0 m or None, got {self.start_check_m}")
        if int(self.start_check_epochs) != self.start_check_epochs or self.start_check_epochs < 1:
            raise ValueError(
                f"start_check_epochs must be an integer >= 1, got {self.start_check_epochs}"
            )
        if self.sky_check_m is not None and not self.sky_check_m > 0:
            raise ValueError(f"sky_check_m must be > 0 m or None, got {self.sky_check_m}")
        if self.odometry_recover_s is not None and not self.odometry_recover_s > 0:
            raise ValueError(
                f"odometry_recover_s must be > 0 s or None, got {self.odometry_recover_s}"
            )
        if self.odometry_suspect not in ("repeated", "every"):
            raise ValueError(
                f"odometry_suspect must be 'repeated' or 'every', got {self.odometry_suspect!r}"
            )
        if int(self.odometry_reconfirm) != self.odometry_reconfirm or self.odometry_reconfirm < 0:
            raise ValueError(
                f"odometry_reconfirm must be an integer >= 0, got {self.odometry_reconfirm}"
            )
        if int(self.trust_stretches) != self.trust_stretches or self.trust_stretches < 1:
            raise ValueError(
                f"trust_stretches must be an integer >= 1 (1: one trusted set over the whole "
                f"predicted interval), got {self.trust_stretches}"
            )
        if not self.beacon_spacing_m > 0:
            raise ValueError(f"beacon_spacing_m must be positive, got {self.beacon_spacing_m}")
        if not 0.0 <= self.model_el_min_deg < 90.0:
            raise ValueError(f"model_el_min_deg must be in [0, 90), got {self.model_el_min_deg}")
        if not self.model_el_min_deg <= self.model_el_max_deg <= 90.0:
            raise ValueError(f"model_el_max_deg must be in [model_el_min_deg, 90], got "
                             f"{self.model_el_max_deg}")  # fmt: skip
        if self.error_model_caveat not in ERROR_MODEL_CAVEATS:
            raise ValueError(f"error_model_caveat must be one of {sorted(ERROR_MODEL_CAVEATS)}, "
                             f"got {self.error_model_caveat!r}")  # fmt: skip
        if self.error_model_caveat and not self.error_model_applies:
            raise ValueError("error_model_caveat is for claims under a model; with "
                             "error_model_applies=False there is none")  # fmt: skip

    @property
    def makes_safety_claims(self) -> bool:
        """Whether a claim of this run is a safety claim: not under a forced error model, and
        with widths from an integrity budget (a fixed ``k`` is a width the user chose, whose
        risk nothing states)."""
        return no_safety_banner(self.error_model_caveat, self.locator.fixed_k_sigma) is None

    def to_dict(self) -> JsonDict:
        d = dataclasses.asdict(self)
        d["locator"]["model"]["error"] = dataclasses.asdict(self.locator.model.error)
        return d


_EXCLUSION_NAMES = {int(e): e.name.lower() for e in Exclusion}
# enum members and flag sets the loop uses, looked up once (Python 3.11's Enum.__getattr__ and
# IntFlag arithmetic cost microseconds per use)
_ODOMETRY, _FUSED, _CONFLICT = FusionStatus.ODOMETRY, FusionStatus.FUSED, FusionStatus.CONFLICT
_SUSPECT = FusionStatus.SUSPECT
_SUSPECT_FLAGS = int(RunFlag.ODOMETRY_SUSPECT | FixFlag.NO_SAFETY_CLAIM)
_HEADING_FAIL, _HEADING_UNOBSERVABLE = HeadingStatus.FAIL, HeadingStatus.UNOBSERVABLE
_HEADING_UNCHECKED = int(RunFlag.HEADING_UNCHECKED)
_ASSUMED_MASK = int(RunFlag.ASSUMED_MASK)
_IONO_UNCORRECTED = int(RunFlag.IONO_UNCORRECTED)
_CLAIM_AT_TRACK_END = int(RunFlag.CLAIM_AT_TRACK_END)
_HEADING_FAIL_FLAGS = int(FixFlag.HEADING_FAIL | FixFlag.NO_SAFETY_CLAIM)
_CONFLICT_FLAGS = int(RunFlag.ODOMETRY_CONFLICT | FixFlag.NO_SAFETY_CLAIM)
_ALIAS_FLAGS = int(RunFlag.TRACK_ALIAS | FixFlag.NO_SAFETY_CLAIM)
_OFF_TRACK_FLAGS = int(RunFlag.OFF_TRACK | FixFlag.NO_SAFETY_CLAIM)
_OFF_TRACK_UNCHECKED = int(RunFlag.OFF_TRACK_UNCHECKED)
_START_CONFLICT = int(RunFlag.START_CONFLICT)
_NO_MODEL_FLAGS = int(RunFlag.NO_ERROR_MODEL | FixFlag.NO_SAFETY_CLAIM)
_NO_STRETCH_FLAGS = int(RunFlag.NO_STRETCH_CLAIM | FixFlag.NO_SAFETY_CLAIM)
_CAVEAT_FLAGS = {"forced": int(RunFlag.FORCED_ERROR_MODEL),
                 "gaussian_tail": int(RunFlag.GAUSSIAN_TAIL)}  # fmt: skip
_NO_CLAIM_FLAGS = int(FixFlag.NO_SAFETY_CLAIM | FixFlag.TOO_FEW)
_TRACK_END, _NO_SAFETY_CLAIM = int(RunFlag.TRACK_END), int(FixFlag.NO_SAFETY_CLAIM)
_END_TOL_M = 0.5  # a claimed bound this close to a track end is the end's, not the satellites'
_NO_FIX_FLAGS = int(FixFlag.TOO_FEW | FixFlag.NO_SAFETY_CLAIM)
_NONE_NAME = IntervalMode.NONE.name.lower()
# beyond this a satellite's elevation differs between the prediction's ends by more than
# 0.004 deg (locator.selection): trust takes the lowest of the centre and the two ends
_LONG_PREDICTION_M = 400.0
# the sky fix's distance beside the track beyond which it is no evidence, when the sky check
# itself is off (RunConfig.sky_check_m None) but the start check is on
_SKY_NEAR_M = 300.0
# a blunt fix's estimate conflict begins the suspicion when the same bound is passed again
# this long after it, s (RunConfig.odometry_suspect)
_REPEAT_S = (1.0, 3.0)


def run_locator(
    path: AntennaPath,
    source: EpochSource,
    *,
    start_chainage_m: float,
    config: RunConfig | None = None,
    masks: MaskSet | None = None,
    progress: Callable[[int], object] | None = None,
) -> pd.DataFrame:
    """Locate the train at every epoch of a source.

    Parameters
    ----------
    path : AntennaPath
        Track and antenna height.
    source : EpochSource
        :class:`locator.sources.SimSource` or :class:`locator.sources.RinexSource`.
    start_chainage_m : float
        Where the run starts (within ``config.start_uncertainty_m``).
    config : RunConfig, optional
    masks : MaskSet, optional
        Required with ``trust="masks"``.
    progress : callable, optional
        Called with the number of epochs done (e.g. ``tqdm.update``).

    Returns
    -------
    pandas.DataFrame
        One row per epoch: ``epoch``, ``gps_s``, ``pred_lo_m``, ``pred_hi_m`` (odometry
        prediction used for the trust decision), ``n_received``, ``n_trusted``, ``n_used``,
        ``chainage_m``, ``lo_m``, ``hi_m``, ``length_m``, ``mode``, ``integrity``, ``flags``,
        ``flag_names``, ``claim`` (claim after every check), ``safety_claim`` (``claim``,
        except under a forced error model or a fixed ``k``, whose claims are not safety claims:
        :attr:`RunConfig.makes_safety_claims`),
        ``claim_fix`` (the fix's own claim, before the heading and odometry checks),
        ``wls_chainage_m``, ``wls_sigma_m``,
        ``heading_status``, ``heading_diff_deg``, ``used`` (satellite ids, space separated),
        ``excluded`` (``sat:reason`` items), ``fused_lo_m``, ``fused_hi_m``,
        ``fused_chainage_m`` (odometry and satellites, step 6), ``n_used_assumed`` (used
        satellites trusted where the mask rests on the far field's assumption), ``fusion``
        (:class:`locator.odometry.fusion.FusionStatus` name), ``odo_since_anchor_m`` (distance
        the wheels ran since the older of the two bounds' anchors, either way, m),
        ``odo_disputed_m`` (the odometer's disputed distance in the prediction since its anchors:
        where wheel and radar disagreed, both readings are covered, m), ``odometer_used``
        (False where the prediction was the motion bound: no odometer, or one set aside,
        ``RunConfig.odometry_recover_s``), ``solve_ms``,
        ``iono_uncorrected`` (True when a trusted satellite's ionospheric delay was left
        uncorrected, no broadcast model being available, and its sigma inflated:
        :data:`locator.corrections.UNCORRECTED_IONO_SIGMA_M`), ``start_check_m`` (the sky
        fix's chainage the start was checked against before the run was located, NaN
        elsewhere: :attr:`RunConfig.start_check_m`).
    """
    cfg = config or RunConfig()
    if cfg.trust == "masks" and masks is None:
        raise ValueError("trust='masks' needs masks: pass a MaskSet or choose trust='cutoff'")
    if masks is not None:
        # holes between positions (a set joined in memory) trust nothing, as a file's do
        masks = close_gaps(masks)[0]
    if not 0.0 <= start_chainage_m <= path.length_m:
        raise ValueError(
            f"start_chainage_m {start_chainage_m:.1f} is off the track (0-{path.length_m:.1f} m)"
        )
    gps = np.asarray(source.gps_s, float)
    odo = source.odometer_m
    state = _Tracker.start(start_chainage_m, cfg.start_uncertainty_m, odo, gps,
                           getattr(source, "odometer_extra_m", None))  # fmt: skip
    aliases = None if cfg.alias_m is None else TrackAliases.of(path.track, cfg.alias_m)
    # a start beside another stretch of the track may be on either (a header position, a
    # stated start): the run is located only by a claim where the track is alone
    state.unique = not (aliases and aliases.within(start_chainage_m - cfg.start_uncertainty_m,
                                                   start_chainage_m + cfg.start_uncertainty_m).size)
    rows: list[JsonDict] = []
    beacons: dict[float, tuple[NDArray, NDArray]] = {}  # the heading check's beacon frames
    for k in range(len(gps)):
        t0 = time.perf_counter()
        p_lo, p_hi, d = state.predict(k, gps, odo, cfg, path.length_m)
        centre = 0.5 * (p_lo + p_hi)
        data = source.observe(k, path.ecef_at(centre))
        excluded = dict(data.rejected)
        n_rx = len(data.sats)
        if n_rx:
            az, el = direction_at(path, centre, data.sat_ecef_m)
        else:
            az = el = np.zeros(0)
        start_m = float("nan")
        if state.unlocated and cfg.start_check_m is not None and n_rx:
            start_m = _sky_check(path, data, el, cfg.cutoff_deg,
                                 cfg.sky_check_m or _SKY_NEAR_M)  # fmt: skip
            widened = _start_check(state, cfg, start_m, p_lo, p_hi, state.here(k, gps, odo),
                                   path.length_m)  # fmt: skip
            if widened is not None:  # the satellites' place too: trust, fix and check over both
                p_lo, p_hi = widened
                centre = 0.5 * (p_lo + p_hi)
                az, el = direction_at(path, centre, data.sat_ecef_m)
                if aliases:
                    state.unique = state.unique and not aliases.within(p_lo, p_hi).size
                if cfg.odometry_reconfirm:
                    if not state.suspect:
                        state.suspect_since_s = float(gps[k])
                    state.suspect, state.agreed = True, 0
        el_trust = el
        if n_rx and p_hi - p_lo > _LONG_PREDICTION_M:
            # the lowest elevation over the interval, not its centre's (locator.selection)
            _, el_ends = direction_at(path, np.array([p_lo, p_hi]), data.sat_ecef_m)
            el_trust = np.minimum(el, el_ends.min(axis=0))
        if cfg.trust == "masks" and cfg.trust_stretches > 1 and n_rx:
            assert masks is not None
            fix, idx, uncorrected, conflict = _split_fix(
                path, cfg, masks, data, az, el, p_lo, p_hi, excluded, beacons, el_trust
            )
        else:
            trusted = _trust(cfg, masks, p_lo, p_hi, az, el_trust, data.sats, excluded, el)
            idx = np.flatnonzero(trusted)
            fix, uncorrected = _fix(path, cfg, data, el, idx, centre)
            conflict = ""
        row = _row(k, gps[k], p_lo, p_hi, n_rx, len(idx), fix, cfg.integrity)
        row["iono_uncorrected"] = uncorrected
        row["start_check_m"] = start_m
        f_lo, f_hi, status = p_lo, p_hi, _ODOMETRY
        if fix is not None:
            for s in fix.excluded_sats:
                excluded[s] = "fde"
            status, blunt = _check(path, cfg, fix, data, el, idx, row, p_lo, p_hi, beacons,
                                   conflict)  # fmt: skip
        else:
            blunt = 0
        row["sky_check_m"] = float("nan")
        off = False
        if not row["claim_fix"] and cfg.sky_check_m is not None and cfg.odometry_check:
            sky_m = _sky_check(path, data, el, cfg.cutoff_deg, cfg.sky_check_m)
            row["sky_check_m"] = sky_m
            off = sky_m < p_lo - cfg.sky_check_m or sky_m > p_hi + cfg.sky_check_m  # NaN: False
        if state.inverted or off:  # crossed bounds, or the sky elsewhere: the odometry is wrong
            flags = int(row["flags"]) | _CONFLICT_FLAGS
            row.update(flags=flags, flag_names=flag_names(flags), claim=False)
            status, blunt = _CONFLICT, 0
        if (state.unlocated and cfg.start_check_m is not None and status == _CONFLICT
                and not (state.inverted or off) and row["claim_fix"]
                and np.isfinite(row["lo_m"]) and np.isfinite(row["hi_m"])):  # fmt: skip
            # before a claim located the run, a fix whose claimed interval contradicts the
            # prediction contradicts the start as much as the odometer: the prediction is
            # widened over that interval (only adds places). A start 75 m off (50 m stated) had
            # sky fixes within start_check_m of the prediction: 20 s of conflicts, the healthy
            # odometer set aside, no claim in the rest of the run (151 epochs)
            lo_f, hi_f = float(row["lo_m"]), float(row["hi_m"])
            state.widen(lo_f, hi_f, p_lo, p_hi, state.here(k, gps, odo), path.length_m)
            state.start_doubt = True
            if aliases:
                state.unique = state.unique and not aliases.within(min(lo_f, p_lo),
                                                                   max(hi_f, p_hi)).size
        if uncorrected:  # in the flags too, where a reader of the claims looks (a user trial)
            flags = int(row["flags"]) | _IONO_UNCORRECTED
            row.update(flags=flags, flag_names=flag_names(flags))
        if state.past_start or state.past_end:
            _track_end(row, state, path.length_m)
        row["n_used_assumed"] = 0
        if fix is not None and masks is not None and cfg.trust == "masks":
            _assumed_bins(row, masks, az[idx][np.asarray(fix.used, bool)], p_lo, p_hi)
        if state.start_doubt:  # until a claim locates the run (the claim itself included)
            flags = int(row["flags"]) | _START_CONFLICT
            row.update(flags=flags, flag_names=flag_names(flags))
        suspected = not blunt or cfg.odometry_suspect == "every" or state.repeated(gps[k], blunt)
        if status == _CONFLICT and cfg.odometry_reconfirm and suspected:
            if not state.suspect:
                state.suspect_since_s = float(gps[k])
            # counted toward setting the odometer aside all the same: after a wrong start's
            # widening the conflicts stop; an odometer wrong from the start goes on conflicting
            state.conflicts_s.append(float(gps[k]))
            state.suspect, state.agreed = True, 0
        elif state.suspect:
            if fix is not None and row["claim"]:  # a fix that agrees with the prediction
                state.agreed += 1
                state.suspect = state.agreed < cfg.odometry_reconfirm
            if state.suspect:
                flags = int(row["flags"]) | _SUSPECT_FLAGS
                row.update(flags=flags, flag_names=flag_names(flags), claim=False)
                status = _SUSPECT
        row["off_track_m"] = row["off_track_up_m"] = float("nan")
        if cfg.off_track_k_sigma is not None and row["claim"]:
            _off_track_check(path, cfg, data, el, idx, row)
        if aliases and row["claim"]:
            _alias_check(aliases, state, row, p_lo, p_hi)
        row["odometer_used"] = odo is not None and state.odometer_on
        _recover(state, cfg, float(gps[k]), odo is not None)
        if fix is not None and row["claim"]:
            here = state.here(k, gps, odo)
            f_lo, f_hi = state.fuse(fix, row["wls_sigma_m"], p_lo, p_hi, here, cfg.fusion)
            status = _FUSED
            state.unlocated = state.start_doubt = False
        row.update(
            fused_lo_m=f_lo, fused_hi_m=f_hi, fused_chainage_m=state.est,
            fusion=status.name.lower(), odo_since_anchor_m=abs(d),
            odo_disputed_m=state.disputed,
        )  # fmt: skip
        row["excluded"] = " ".join(f"{s}:{r}" for s, r in excluded.items())
        row["solve_ms"] = 1e3 * (time.perf_counter() - t0)
        rows.append(row)
        if progress is not None:
            progress(1)
    epochs = pd.DataFrame(rows)
    # a claim under a forced model or at a fixed k is an interval, not a safety claim: readers
    # of the table alone (no run.json) must not take it for one
    if len(epochs):
        epochs["safety_claim"] = epochs["claim"].astype(bool) & cfg.makes_safety_claims
    return epochs


def _start_check(
    state: _Tracker, cfg: RunConfig, start_m: float, p_lo: float, p_hi: float,
    here: tuple[float, ...], length_m: float,
) -> tuple[float, float] | None:  # fmt: skip
    """Count a sky fix ``start_m`` beyond the prediction by more than ``cfg.start_check_m``
    (:attr:`RunConfig.start_check_m`); at ``cfg.start_check_epochs`` consecutive ones widen
    the prediction to cover it +- that distance and return the widened ``(lo, hi)``, else
    None. Only ever widens: the new prediction holds every place the old one did."""
    m = cfg.start_check_m
    assert m is not None
    if not np.isfinite(start_m):  # no evidence: neither counts nor breaks the run
        return None
    if p_lo - m <= start_m <= p_hi + m:
        state.start_votes = 0
        return None
    state.start_votes += 1
    if state.start_votes < cfg.start_check_epochs:
        return None
    state.start_votes = 0
    state.start_doubt = True
    return state.widen(start_m - m, start_m + m, p_lo, p_hi, here, length_m)


def _sky_check(
    path: AntennaPath, data: EpochData, el: NDArray, cutoff_deg: float, near_m: float
) -> float:
    """Chainage of a 3-D least-squares fix (position and clock, from the Earth's centre) of
    every satellite above ``cutoff_deg``, projected on the track; NaN with fewer than five, when
    it does not converge, or when it lies more than ``near_m`` beside the track or beyond its
    ends (no evidence)."""
    use = np.flatnonzero(np.isfinite(el) & (el > cutoff_deg))
    if len(use) < 5:
        return float("nan")
    sat, rho = data.sat_ecef_m[use], data.pseudorange_m[use]
    got = _lsq_fix(sat, rho, np.ones(len(use)), np.zeros(4), 12)
    if got is None:
        return float("nan")
    lat, lon, h = ecef_to_geodetic(got[0][:3])
    pr = path.track.project(lat, lon, h)
    # horizontal only: a 2-D map carries no heights, and a fix's height is its worst axis
    if bool(pr.clamped) or not abs(float(pr.offset_m)) <= near_m:
        return float("nan")
    return float(pr.chainage_m)


def _lsq_fix(
    sat: NDArray, rho: NDArray, w: NDArray, x0: NDArray, max_iter: int
) -> tuple[NDArray, NDArray] | None:
    """Iterated least-squares position and clock (4,) from satellites (n, 3), pseudoranges and
    weights (n,) (1 / sigma), from ``x0``, and the weighted design matrix (n, 4) of the last
    step; None when it does not converge to a millimetre in ``max_iter`` steps."""
    x = np.asarray(x0, float)
    for _ in range(max_iter):
        d = sat - x[:3]
        r = np.linalg.norm(d, axis=1)
        a = np.column_stack([-d / r[:, None], np.ones(len(r))]) * w[:, None]
        step = np.linalg.lstsq(a, (rho - r - x[3]) * w, rcond=None)[0]
        x = x + step
        if np.linalg.norm(step[:3]) < 1e-3:
            return x, a
    return None


def _off_track_check(
    path: AntennaPath, cfg: RunConfig, data: EpochData, el: NDArray, idx: NDArray, row: JsonDict
) -> None:
    """Void a claim whose trusted satellites' 3-D fix lies beside the map beyond the map's
    lateral doubt and ``off_track_k_sigma`` of its cross-track sigma
    (:attr:`RunConfig.off_track_k_sigma`); the offset goes in ``row["off_track_m"]``. Where
    no such fix can be made, ``OFF_TRACK_UNCHECKED`` says so (the claim stands)."""
    got = _off_track_m(path, cfg, data, el, idx, float(row["chainage_m"]))
    if got is None:
        flags = int(row["flags"]) | _OFF_TRACK_UNCHECKED
        row.update(flags=flags, flag_names=flag_names(flags))
        return
    off, limit, up, up_limit = got
    row["off_track_m"], row["off_track_up_m"] = off, up
    if off > limit or abs(up) > up_limit:
        flags = int(row["flags"]) | _OFF_TRACK_FLAGS
        row.update(flags=flags, flag_names=flag_names(flags), claim=False)


@functools.lru_cache(maxsize=256)
def _chi2_threshold(p_false_alarm: float, dof: int) -> float:
    """The chi-square test's threshold, remembered: SciPy's ``isf`` costs a third of a
    millisecond, a tenth of an epoch, and takes a handful of values in a run."""
    from scipy.stats import chi2

    return float(chi2.isf(p_false_alarm, dof))


def _off_track_m(
    path: AntennaPath, cfg: RunConfig, data: EpochData, el: NDArray, idx: NDArray, near_m: float
) -> tuple[float, float, float, float] | None:
    """(offset beside the map, its limit, height above the antenna on the map, its limit) of
    the 3-D fix of the satellites ``idx``, m, after the fault detection and exclusion of that
    fix (a satellite the 1-D fix had excluded voided a review's correct claims); None without
    five consistent satellites, a fix or a foot point inside the map. The height: a map 15 m
    too high or low let the 1-D fault detection exclude healthy satellites to absorb it, and
    the biased interval missed the train (26 of 59 claims at one heading, a user trial)."""
    sigma = np.asarray(cfg.locator.model.error.sigma_m(el[idx]), float)
    if data.extra_sigma_m is not None:
        sigma = np.hypot(sigma, data.extra_sigma_m[idx])
    sat, rho, w = data.sat_ecef_m[idx], data.pseudorange_m[idx], 1.0 / sigma
    keep = np.ones(len(idx), bool)
    while keep.sum() >= 5:
        got = _lsq_fix(sat[keep], rho[keep], w[keep], np.append(path.ecef_at(near_m), 0.0), 10)
        if got is None:
            return None
        x, a = got
        res = (rho[keep] - np.linalg.norm(sat[keep] - x[:3], axis=1) - x[3]) * w[keep]
        dof = int(keep.sum()) - 4
        if float(res @ res) <= _chi2_threshold(cfg.locator.p_false_alarm, dof):
            break
        if keep.sum() == 5:
            return None  # a fault it cannot isolate
        keep[np.flatnonzero(keep)[int(np.argmax(np.abs(res)))]] = False
    else:
        return None
    try:
        cov = np.linalg.inv(a.T @ a)[:3, :3]
    except np.linalg.LinAlgError:
        return None
    lat, lon, h = ecef_to_geodetic(x[:3])
    pr = path.track.project(lat, lon, h)
    if bool(pr.clamped):
        return None  # past an end: TRACK_END's business
    rot = enu_rotation(lat, lon)
    c_enu = rot @ cov @ rot.T
    c_en = c_enu[:2, :2]
    hd = math.radians(float(path.track.heading_at(float(pr.chainage_m))))
    n = np.array([math.cos(hd), -math.sin(hd)])  # level, across the track
    sigma_ct = math.sqrt(max(float(n @ c_en @ n), 0.0))
    sigma_up = math.sqrt(max(float(c_enu[2, 2]), 0.0))
    k = cfg.off_track_k_sigma
    assert k is not None
    return (abs(float(pr.offset_m)), cfg.locator.map_doubt_lateral_m + k * sigma_ct,
            float(pr.height_m) - path.antenna_height_m,
            cfg.locator.map_doubt_vertical_m + k * sigma_up)  # fmt: skip


def _alias_check(
    aliases: TrackAliases, state: _Tracker, row: JsonDict, p_lo: float, p_hi: float
) -> None:
    """Void a claim beside another stretch of the track unless the run, located where the track
    is alone, predicts every such stretch out (:attr:`RunConfig.alias_m`); a claim where the
    track is alone locates the run."""
    lo, hi = float(row["lo_m"]), float(row["hi_m"])
    if not aliases.within(lo, hi).size:
        state.unique = True
        return
    if state.unique and aliases.excluded_by(lo, hi, p_lo, p_hi):
        return
    flags = int(row["flags"]) | _ALIAS_FLAGS
    row.update(flags=flags, flag_names=flag_names(flags), claim=False)


def _recover(state: _Tracker, cfg: RunConfig, gps_s: float, has_odometer: bool) -> None:
    """Set a suspect odometer aside for the rest of the run after ``cfg.odometry_recover_s``
    (the next predictions are the motion bound). It is not taken back: a recovery trial that
    took a stuck direction channel's odometer back once fixes had cleared the suspicion gave
    the prediction back its fault; the trust decisions rested on it and a claim missed the
    train (1 HMI in 520 claims) an epoch before the next conflict showed."""
    if not has_odometer or cfg.odometry_recover_s is None:
        return
    if state.suspect and state.odometer_on:
        # a conflict that lasts, not one or two isolated false alarms followed by epochs without
        # a claim (under masks, a lost run: a user trial's healthy odometer was set aside
        # after two alarms 8 s apart, and the run claimed nothing in its last 215 epochs)
        wait = cfg.odometry_recover_s
        c = [x for x in state.conflicts_s if x >= gps_s - wait]
        state.conflicts_s[:] = c  # older ones no longer count
        lasting = any(x < gps_s - 0.5 * wait for x in c) and any(x >= gps_s - 0.5 * wait for x in c)
        if gps_s - state.suspect_since_s >= wait and lasting:
            state.odometer_on = False
            state.recoveries += 1


def _clip(x: float, lo: float, hi: float) -> float:
    """``float(np.clip(x, lo, hi))`` of floats (NaN stays NaN), without numpy's call cost."""
    return min(max(x, lo), hi)


Anchor = tuple[float, ...]
"""A bound's anchor: (chainage m, odometer reading m, gps_s, distance the wheels had run m,
disputed distance toward lower and toward higher chainage m) where it was last set."""


@dataclass
class _Tracker:
    """The run's state between epochs: each bound's anchor and the estimate's filter.

    One anchor per bound: a bound the satellites did not tighten keeps its older anchor, so the
    odometer's fixed error is not added again at every epoch.
    """

    lo_anchor: Anchor
    hi_anchor: Anchor
    est: float
    est_var: float
    odo_prev: float
    ran: NDArray  # distance the wheels ran to each epoch, either way (0 without odometer), m
    # the odometer's disputed distance to each epoch, shape (n, 2): toward lower / higher
    # chainage (locator.odometry.odometer: a sensor failure), m
    extra: NDArray
    past_start: bool = False  # the last prediction reached before chainage 0
    past_end: bool = False  # ... or past the track's length
    suspect: bool = False  # an odometry conflict not yet cleared (RunConfig.odometry_reconfirm)
    agreed: int = 0  # fixes agreeing with the prediction since the last conflict
    disputed: float = 0.0  # the last prediction's disputed odometer distance, m
    odometer_on: bool = True  # False: set aside (RunConfig.odometry_recover_s)
    inverted: bool = False  # the last prediction's bounds crossed (an odometer fault)
    suspect_since_s: float = float("nan")  # gps_s of the conflict that began the suspicion
    # gps_s of the conflicts of the last odometry_recover_s: a lasting conflict has some in
    # both halves of that wait
    conflicts_s: list[float] = field(default_factory=list)
    blunt_s: list[tuple[float, int]] = field(default_factory=list)  # (time, bound passed)
    recoveries: int = 0
    unique: bool = True  # located where the track is alone since the start (RunConfig.alias_m)
    unlocated: bool = True  # no claim fused since the start (RunConfig.start_check_m)
    start_doubt: bool = False  # the satellites contradicted the start, no claim since
    start_votes: int = 0  # consecutive sky fixes beyond the prediction (start_check_epochs)

    @classmethod
    def start(
        cls, start_m: float, uncertainty_m: float, odo: NDArray | None, gps: NDArray,
        extra: NDArray | None = None,
    ) -> _Tracker:  # fmt: skip
        odo0 = 0.0 if odo is None else float(odo[0])
        ran = np.zeros(len(gps))
        if odo is not None:
            ran[1:] = np.cumsum(np.abs(np.diff(np.asarray(odo, float))))
        disputed = np.zeros((len(gps), 2)) if extra is None or odo is None else extra
        # the doubts grow with the disputed distance too: where the radar was believed at 0
        # the wheel ran on, and its own relative error needs bounding (a review: 28 m off)
        ran = ran + (disputed[:, 0] - disputed[0, 0]) + (disputed[:, 1] - disputed[0, 1])
        x0 = (float(disputed[0, 0]), float(disputed[0, 1]))
        return cls((start_m - uncertainty_m, odo0, gps[0], 0.0, *x0),
                   (start_m + uncertainty_m, odo0, gps[0], 0.0, *x0),
                   start_m, (uncertainty_m / 3.0) ** 2, odo0, ran, disputed)  # fmt: skip

    def repeated(self, gps_s: float, side: int) -> bool:
        """Whether a blunt fix's estimate conflict at ``gps_s``, past the prediction's lower
        (``side`` -1) or upper (+1) bound, repeats one 1-3 s before on the same side; it is
        remembered for the next (RunConfig.odometry_suspect)."""
        lo, hi = _REPEAT_S
        again = any(s == side and lo - 1e-6 <= gps_s - t <= hi for t, s in self.blunt_s)
        self.blunt_s[:] = [(t, s) for t, s in self.blunt_s if gps_s - t <= hi]
        self.blunt_s.append((gps_s, side))
        return again

    def widen(
        self, lo: float, hi: float, p_lo: float, p_hi: float, here: tuple[float, ...],
        length_m: float,
    ) -> tuple[float, float]:  # fmt: skip
        """The prediction ``(p_lo, p_hi)`` widened to also cover ``(lo, hi)`` (clipped to
        the track): each bound it moves is re-anchored there (``here``: the epoch's readings),
        so the next predictions grow from the widened bounds, never from inside the old ones
        (a bound re-anchored below the old one stays below it: the odometer's fixed error is
        counted once more). The estimate's variance grows to the widened interval."""
        if lo < p_lo:
            self.lo_anchor = (lo, *here)
            self.past_start = self.past_start or lo < 0.0
        if hi > p_hi:
            self.hi_anchor = (hi, *here)
            self.past_end = self.past_end or hi > length_m
        w_lo, w_hi = _clip(min(lo, p_lo), 0.0, length_m), _clip(max(hi, p_hi), 0.0, length_m)
        self.est_var = max(self.est_var, ((w_hi - w_lo) / 6.0) ** 2)
        return w_lo, w_hi

    def here(self, k: int, gps: NDArray, odo: NDArray | None) -> tuple[float, ...]:
        """An anchor's readings at epoch ``k`` (all but its chainage)."""
        return (0.0 if odo is None else float(odo[k]), float(gps[k]), float(self.ran[k]),
                float(self.extra[k, 0]), float(self.extra[k, 1]))  # fmt: skip

    def predict(
        self, k: int, gps: NDArray, odo: NDArray | None, cfg: RunConfig, length_m: float
    ) -> tuple[float, float, float]:
        """The odometry prediction ``(lo, hi)`` on the track at epoch ``k``, the odometer
        distance since the older anchor; advances the estimate by the odometer's step."""
        lo_anchor, hi_anchor = self.lo_anchor, self.hi_anchor
        reading = odo
        odo = odo if self.odometer_on else None  # set aside: the motion bound
        self.disputed = 0.0
        if odo is not None:
            d_lo, d_hi = float(odo[k] - lo_anchor[1]), float(odo[k] - hi_anchor[1])
            # the doubts grow with the distance the wheels ran, not the net displacement
            ran_lo, ran_hi = self.ran[k] - lo_anchor[3], self.ran[k] - hi_anchor[3]
            lo_p = predict_interval(lo_anchor[0], lo_anchor[0], d_lo, cfg.odometer, ran_lo)[0]
            hi_p = predict_interval(hi_anchor[0], hi_anchor[0], d_hi, cfg.odometer, ran_hi)[1]
            # where the wheel and the radar disagreed, either may be right: both are covered
            x_lo, x_hi = self.extra[k, 0] - lo_anchor[4], self.extra[k, 1] - hi_anchor[5]
            lo_p, hi_p = lo_p - x_lo, hi_p + x_hi
            self.disputed = float(x_lo + x_hi)
        else:
            ran_lo = ran_hi = 0.0
            lo_p = motion_bound(lo_anchor[0], 0.0, gps[k] - lo_anchor[2], cfg.odometer)[0]
            hi_p = motion_bound(0.0, hi_anchor[0], gps[k] - hi_anchor[2], cfg.odometer)[1]
        # crossed bounds: the odometer contradicts its own anchors (each bound holds the train
        # while its bounds hold); the motion bound holds whatever it did
        self.inverted = bool(lo_p > hi_p)
        if self.inverted:
            lo_p = motion_bound(lo_anchor[0], 0.0, gps[k] - lo_anchor[2], cfg.odometer)[0]
            hi_p = motion_bound(0.0, hi_anchor[0], gps[k] - hi_anchor[2], cfg.odometer)[1]
        d = max(ran_lo, ran_hi)
        self.past_start = float(lo_p) < 0.0
        self.past_end = float(hi_p) > length_m
        p_lo = _clip(float(lo_p), 0.0, length_m)
        p_hi = _clip(float(hi_p), 0.0, length_m)
        step = 0.0 if odo is None else float(odo[k]) - self.odo_prev
        e, v = predict_estimate(self.est, self.est_var, step, cfg.odometer)
        self.odo_prev = self.odo_prev + step if reading is None else float(reading[k])
        if odo is None:  # no motion model: the estimate's variance grows with the motion bound
            v = v + (cfg.odometer.max_speed_mps * (gps[k] - gps[max(k - 1, 0)])) ** 2
        self.est, self.est_var = _clip(float(e), p_lo, p_hi), float(v)
        return p_lo, p_hi, d

    def fuse(
        self, fix: Fix, wls_sigma_m: float, p_lo: float, p_hi: float,
        here: tuple[float, ...],
        fusion: bool,
    ) -> tuple[float, float]:  # fmt: skip
        """The fused interval of a claimed fix and the prediction; re-anchors the bounds the
        satellites tightened (all of them without fusion or outside the prediction) and blends
        the fix into the estimate."""
        f_lo, f_hi = fix.lo_m, fix.hi_m
        if fusion and fix.hi_m >= p_lo and fix.lo_m <= p_hi:
            f_lo, f_hi = max(f_lo, p_lo), min(f_hi, p_hi)
            if fix.lo_m > p_lo:  # the satellites tightened the lower bound
                self.lo_anchor = (f_lo, *here)
            if fix.hi_m < p_hi:
                self.hi_anchor = (f_hi, *here)
        else:
            self.lo_anchor, self.hi_anchor = (f_lo, *here), (f_hi, *here)
        fix_sd = wls_sigma_m
        if not np.isfinite(fix_sd) or fix_sd <= 0:
            fix_sd = 0.25 * (fix.hi_m - fix.lo_m)  # the interval as about 4 sigma
        e, v = blend_estimate(self.est, self.est_var, fix.chainage_m, fix_sd**2)
        self.est, self.est_var = _clip(float(e), f_lo, f_hi), float(v)
        return f_lo, f_hi


def _fix(
    path: AntennaPath, cfg: RunConfig, data: EpochData, el: NDArray, idx: NDArray,
    centre: float,
) -> tuple[Fix | None, bool]:  # fmt: skip
    """The fix of the trusted satellites ``idx`` (None below 2) and whether an uncorrected
    ionosphere inflated their sigma."""
    sigma = None
    extra = data.extra_sigma_m
    uncorrected = extra is not None and bool(np.any(extra[idx] > 0))
    if uncorrected:
        assert extra is not None
        sigma = np.hypot(cfg.locator.model.error.sigma_m(el[idx]), extra[idx])
    if len(idx) < 2:
        return None, uncorrected
    fix = locate(
        path, data.sat_ecef_m[idx], data.pseudorange_m[idx], el[idx], prior_m=centre,
        integrity=cfg.integrity, config=cfg.locator, sigma_m=sigma,
        sats=[data.sats[i] for i in idx],
    )  # fmt: skip
    return fix, uncorrected


def _check(
    path: AntennaPath, cfg: RunConfig, fix: Fix, data: EpochData, el: NDArray, idx: NDArray,
    row: JsonDict, p_lo: float, p_hi: float, beacons: dict[float, tuple[NDArray, NDArray]],
    conflict: str = "",
) -> tuple[FusionStatus, int]:  # fmt: skip
    """The heading and odometry checks of a fix, written into ``row`` (flags, claim); the
    fusion status (``CONFLICT`` when the claim contradicts the odometry, or ``conflict``: the
    stretches' claims contradict it, :func:`locator.partition.combine_stretches`: ``"hard"``
    by their intervals, ``"blunt"`` by their estimates alone), and for a conflict of a blunt
    fix (its estimate outside the prediction, its claimed interval holding all of it) the
    bound its estimate passed (-1 lower, +1 upper; else 0: RunConfig.odometry_suspect)."""
    status = _ODOMETRY
    hc = _heading(path, cfg, fix, data.sat_ecef_m[idx], data.pseudorange_m[idx], el[idx], beacons)
    flags = int(fix.flags)
    if hc is not None:
        row["heading_status"] = hc.status.name.lower()
        row["heading_diff_deg"] = hc.difference_deg
        if hc.status == _HEADING_FAIL:
            flags |= _HEADING_FAIL_FLAGS
    if cfg.heading_check and (hc is None or hc.status == _HEADING_UNOBSERVABLE):
        # the claim rests on the pair intervals alone: said, not voided (docs/locator.md)
        flags |= _HEADING_UNCHECKED
    claim = row["claim_fix"]
    hard = conflict == "hard" or fix.hi_m < p_lo or fix.lo_m > p_hi
    miss = hard or conflict == "blunt"
    if cfg.odometry_conflict == "estimate":
        miss = miss or not p_lo <= fix.chainage_m <= p_hi
    blunt = 0
    if claim and cfg.odometry_check and miss:
        flags |= _CONFLICT_FLAGS
        status = _CONFLICT
        if not hard and fix.lo_m <= p_lo and fix.hi_m >= p_hi:
            blunt = -1 if fix.chainage_m < 0.5 * (p_lo + p_hi) else 1
    if not cfg.error_model_applies:
        flags |= _NO_MODEL_FLAGS
    elif cfg.error_model_caveat:
        flags |= _CAVEAT_FLAGS[cfg.error_model_caveat]
    claim = claim and not flags & _NO_CLAIM_FLAGS
    row.update(flags=flags, flag_names=flag_names(flags), claim=bool(claim))
    return status, blunt


def _split_fix(
    path: AntennaPath, cfg: RunConfig, masks: MaskSet, data: EpochData, az: NDArray,
    el: NDArray, p_lo: float, p_hi: float, excluded: dict[str, str],
    beacons: dict[float, tuple[NDArray, NDArray]], el_trust: NDArray | None = None,
) -> tuple[Fix | None, NDArray, bool, str]:  # fmt: skip
    """Partitioned trust (:mod:`locator.partition`): a fix per stretch of the prediction, one
    claim from all. Returns the epoch's fix (the chosen stretch's, its interval the hull of the
    parts), its trusted satellites, whether an uncorrected ionosphere inflated a sigma, and
    whether the stretches' claims contradict the prediction: ``""`` no, ``"hard"`` by their
    intervals, ``"blunt"`` by their estimates alone (``RunConfig.odometry_conflict``). Reasons
    go into ``excluded`` for the satellites no stretch trusts. ``el_trust`` (default ``el``) is
    the elevation the trust decision takes (the lowest over a long prediction); the fixes take
    ``el``."""
    el_t = el if el_trust is None else el_trust
    stretches = trust_stretches(masks, p_lo, p_hi, az, el_t, max_stretches=cfg.trust_stretches,
                                extra_margin_deg=cfg.extra_margin_deg)  # fmt: skip
    n = len(stretches)
    if n == 1:  # one trusted set over the whole prediction: the single set's decision exactly
        idx = np.flatnonzero(_trust(cfg, masks, p_lo, p_hi, az, el_t, data.sats, excluded, el))
        fix, uncorrected = _fix(path, cfg, data, el, idx, 0.5 * (p_lo + p_hi))
        return fix, idx, uncorrected, ""
    fixes: list[Fix | None] = []
    sets: list[NDArray] = []
    claimed = np.zeros(n, bool)
    f_lo, f_hi, est = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    n_used = np.zeros(n, np.int64)
    uncorrected = False
    for j, st in enumerate(stretches):
        trusted = st.selection.trusted
        if cfg.model_el_min_deg > 0.0:
            trusted = trusted & (el_t >= cfg.model_el_min_deg)
        if cfg.model_el_max_deg < 90.0:
            trusted = trusted & (el <= cfg.model_el_max_deg)
        idx = np.flatnonzero(trusted)
        fix, unc = _fix(path, cfg, data, el, idx, 0.5 * (st.lo_m + st.hi_m))
        uncorrected = uncorrected or unc
        fixes.append(fix)
        sets.append(idx)
        if fix is None:
            continue
        f_lo[j], f_hi[j], est[j], n_used[j] = fix.lo_m, fix.hi_m, fix.chainage_m, fix.used.sum()
        if fix.safety_claim:
            hc = _heading(path, cfg, fix, data.sat_ecef_m[idx], data.pseudorange_m[idx], el[idx],
                          beacons)  # fmt: skip
            claimed[j] = hc is None or hc.status != _HEADING_FAIL
    comb = combine_stretches(
        [s.lo_m for s in stretches], [s.hi_m for s in stretches], claimed, f_lo, f_hi, est,
        n_used=n_used, estimate_inside=cfg.odometry_conflict == "estimate",
    )  # fmt: skip
    ever = np.zeros(len(data.sats), bool)
    for idx in sets:
        ever[idx] = True
    first = stretches[0].selection.reason
    for i in np.flatnonzero(~ever):
        reasons = [int(s.selection.reason[i]) for s in stretches if s.selection.reason[i]]
        code = max(reasons) if reasons else int(first[i])
        outside = "above_model" if el[i] > cfg.model_el_max_deg else "below_model"
        excluded[data.sats[i]] = _EXCLUSION_NAMES[code] if code else outside
    if comb.chosen < 0:
        return None, np.zeros(0, np.int64), uncorrected, ""
    fix = fixes[comb.chosen]
    assert fix is not None
    if comb.claim or comb.conflict:
        fix = dataclasses.replace(fix, lo_m=comb.lo_m, hi_m=comb.hi_m)
    else:  # no claim (none, or the hull is the prediction): the fix's own interval
        fix = dataclasses.replace(fix, flags=fix.flags | _NO_STRETCH_FLAGS)
    kind = ""
    if comb.conflict:  # by the intervals, or by the estimates alone?
        by_interval = combine_stretches(
            [s.lo_m for s in stretches], [s.hi_m for s in stretches], claimed, f_lo, f_hi, est,
            n_used=n_used, estimate_inside=False,
        ).conflict  # fmt: skip
        kind = "hard" if by_interval else "blunt"
    return fix, sets[comb.chosen], uncorrected, kind


def _assumed_bins(
    row: dict[str, Any], masks: MaskSet, az_used: NDArray, p_lo: float, p_hi: float
) -> None:
    """Count the used satellites whose bin rests, somewhere over the prediction, on the far
    field's assumption (no view saw it) and flag the epoch ``ASSUMED_MASK``: weak evidence,
    said, not voided (the margins of assumed bins are calibrated apart, docs/reconstruction.md)."""
    if not len(az_used):
        return
    n = int(masks.assumed_over(p_lo, p_hi)[masks.bin_index(az_used)].sum())
    row["n_used_assumed"] = n
    if n:
        flags = int(row["flags"]) | _ASSUMED_MASK
        row.update(flags=flags, flag_names=flag_names(flags))


def _track_end(row: dict[str, Any], state: _Tracker, length_m: float) -> None:
    """Flag an epoch whose prediction reaches past an end of the track map (the map may end
    before the line does: the train may be off it) and void a claim whose interval the end
    bounds: the pair solver cannot look past the map, so such an interval may miss a train
    beyond it. A claim well inside the map still stands: the satellites placed it there."""
    flags = int(row["flags"]) | _TRACK_END
    at_end = (state.past_start and row["lo_m"] <= _END_TOL_M) or (
        state.past_end and row["hi_m"] >= length_m - _END_TOL_M
    )
    if row["claim"] and at_end:
        flags |= _NO_SAFETY_CLAIM | _CLAIM_AT_TRACK_END
        row["claim"] = False
    row.update(flags=flags, flag_names=flag_names(flags))


def _trust(
    cfg: RunConfig,
    masks: MaskSet | None,
    lo_m: float,
    hi_m: float,
    az: NDArray,
    el: NDArray,
    sats: tuple[str, ...],
    excluded: dict[str, str],
    el_fix: NDArray | None = None,
) -> NDArray:
    """Trusted satellites of the epoch; records the reason of every other one in ``excluded``.
    ``el`` is the elevation the trust decision takes (the lowest over a long prediction);
    ``el_fix`` (default ``el``) the one the fix weighs, which the model's upper elevation
    bounds."""
    if len(sats) == 0:
        return np.zeros(0, bool)
    if cfg.trust == "masks":
        assert masks is not None
        sel = select_satellites(masks, lo_m, hi_m, az, el, extra_margin_deg=cfg.extra_margin_deg)
        for s, r in zip(sats, sel.reason, strict=True):
            if r:
                excluded[s] = _EXCLUSION_NAMES[int(r)]
        trusted = np.asarray(sel.trusted, bool)
    else:
        floor = cfg.cutoff_deg if cfg.trust == "cutoff" else 0.0
        trusted = el > floor
        for s, good in zip(sats, trusted, strict=True):
            if not good:
                excluded[s] = "below_cutoff" if cfg.trust == "cutoff" else "below_horizon"
    if cfg.model_el_min_deg > 0.0:
        low = trusted & ~(el >= cfg.model_el_min_deg)
        for s in np.asarray(sats)[low]:
            excluded[str(s)] = "below_model"
        trusted = trusted & ~low
    if cfg.model_el_max_deg < 90.0:
        high = trusted & ~((el if el_fix is None else el_fix) <= cfg.model_el_max_deg)
        for s in np.asarray(sats)[high]:
            excluded[str(s)] = "above_model"
        trusted = trusted & ~high
    return trusted


def _row(
    k: int,
    gps_s: float,
    p_lo: float,
    p_hi: float,
    n_rx: int,
    n_trusted: int,
    fix: Fix | None,
    integrity: str,
) -> dict[str, Any]:
    row: dict[str, Any] = {
        "epoch": k, "gps_s": gps_s, "pred_lo_m": p_lo, "pred_hi_m": p_hi,
        "n_received": n_rx, "n_trusted": n_trusted, "n_used": 0,
        "chainage_m": np.nan, "lo_m": np.nan, "hi_m": np.nan, "length_m": np.nan,
        "mode": _NONE_NAME, "integrity": integrity,
        "flags": _NO_FIX_FLAGS, "flag_names": "",
        "claim": False, "claim_fix": False, "wls_chainage_m": np.nan, "wls_sigma_m": np.nan,
        "heading_status": "", "heading_diff_deg": np.nan, "used": "",
    }  # fmt: skip
    row["flag_names"] = flag_names(row["flags"])
    if fix is None:
        return row
    wls = fix.wls
    row.update(
        n_used=int(fix.used.sum()), chainage_m=fix.chainage_m, lo_m=fix.lo_m, hi_m=fix.hi_m,
        length_m=fix.length_m, mode=fix.mode.name.lower(), flags=int(fix.flags),
        flag_names=flag_names(int(fix.flags)), claim_fix=bool(fix.safety_claim),
        claim=bool(fix.safety_claim),
        wls_chainage_m=wls.chainage_m if wls is not None else np.nan,
        wls_sigma_m=wls.sigma_chainage_m if wls is not None else np.nan,
        used=" ".join(s for s, u in zip(fix.sats, fix.used, strict=True) if u),
    )  # fmt: skip
    return row


def _heading(
    path: AntennaPath, cfg: RunConfig, fix: Fix, sat: NDArray, rho: NDArray, el: NDArray,
    beacons: dict[float, tuple[NDArray, NDArray]],
) -> Any:  # fmt: skip
    """Heading check of the fix against its virtual beacon, or None when not applicable.

    ``beacons`` caches each beacon's ECEF position and ENU rotation (a geodetic conversion per
    beacon, not per epoch)."""
    if not cfg.heading_check or fix.used.sum() < 4 or not np.isfinite(fix.chainage_m):
        return None
    s, sp = fix.chainage_m, cfg.beacon_spacing_m
    b = math.floor((s - 0.5 * sp) / sp) * sp
    if b < 0.0:  # no beacon behind: take the one ahead
        b = math.ceil((s + 0.5 * sp) / sp) * sp
    if not 0.0 <= b <= path.length_m:
        return None
    if b not in beacons:
        xb = path.ecef_at(b)
        lat, lon, _ = ecef_to_geodetic(xb)
        beacons[b] = xb, enu_rotation(lat, lon)
    beacon, rot = beacons[b]
    east, north = rot[:2] @ (path.ecef_at(s) - beacon)
    az = math.degrees(math.atan2(east, north)) % 360.0
    u = fix.used
    sigma = cfg.locator.model.error.sigma_m(el[u])
    return check_heading(
        beacon, az, sat[u], rho[u], sigma, tolerance_deg=cfg.heading_tolerance_deg,
        rotation=rot,
    )  # fmt: skip
