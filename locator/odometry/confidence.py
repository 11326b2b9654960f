"""The ETCS confidence interval of the odometer and the train's safe front and rear ends.

Source document 004. The odometer measures the distance from the last relevant reference
(balise group, real or virtual, usable as reference: ``Q_REFERENCE = 1``) and a confidence
interval growing with that distance:

* ``D_DOUBTOVER``: how much the odometer may have over-read (the train is at most that much
  behind the estimate); ``D_DOUBTUNDER``: how much it may have under-read (at most that much
  ahead). Both are ``reference accuracy + abs + rel * distance since the reference``
  (:class:`OdometerAccuracy`; ETCS SUBSET-041 asks for at least ``5 m + 5 %``).
* estimated front end; **max safe front end** = estimated + ``D_DOUBTUNDER`` (furthest ahead
  in the direction of travel); **min safe front end** = estimated - ``D_DOUBTOVER``. The same
  for the rear end (front minus the train length), valid only with train-integrity
  confirmation (NaN otherwise).
* A reference balise resets the interval to the reference's location accuracy; a balise with
  ``Q_REFERENCE = 0`` does not reset it, but a later balise at a **known distance** from it lets
  the interval fall back to its value at the first one.
* A **linked** balise is accepted only inside its **expectation window**: from when the max
  safe front reaches its first possible position (location - accuracy) until the min safe
  front passes its last possible position (location + accuracy). Outside the window it is
  rejected (no reset): :func:`in_expectation_window`.

Positions are chainages (m); the train moves with ``orientation`` +1 (toward increasing
chainage) or -1. The odometer distance is signed along the train's forward axis.
Every bound errs on the safe side: ``over`` and ``under`` are bounds of the sensor errors (from
:class:`locator.odometry.odometer.OdometerConfig` by :meth:`OdometerAccuracy.from_config`, or the
SUBSET-041 requirement), never estimates.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.odometry.odometer import OdometerConfig
from predisat.readonly import freeze_array_fields

__all__ = [
    "BalisePassage",
    "OdometerAccuracy",
    "SafeFronts",
    "in_expectation_window",
    "safe_fronts",
]


@dataclass(frozen=True)
class OdometerAccuracy:
    """Growth of the odometer's confidence interval with the distance since the reference.

    ``D_DOUBTOVER(d) = abs_error_m + over_rel * |d|`` and ``D_DOUBTUNDER(d) = abs_error_m +
    under_rel * |d|`` (plus the reference's own accuracy, added by the caller).

    Attributes
    ----------
    abs_error_m : float
        Fixed part, m.
    over_rel, under_rel : float
        Bounds of the relative over- and under-reading.
    max_speed_mps : float
        Motion bound where no odometer is available: the train moved at most this fast, m/s.
    """

    abs_error_m: float = 5.0
    over_rel: float = 0.05
    under_rel: float = 0.05
    max_speed_mps: float = 45.0

    def __post_init__(self) -> None:
        if self.abs_error_m < 0 or self.max_speed_mps < 0:
            raise ValueError(f"OdometerAccuracy needs abs_error_m, max_speed_mps >= 0: {self}")
        if not (0 <= self.over_rel < 1 and 0 <= self.under_rel < 1):
            raise ValueError(f"OdometerAccuracy needs over_rel, under_rel in [0, 1): {self}")

    @classmethod
    def subset041(cls) -> OdometerAccuracy:
        """The ETCS requirement: ``+-(5 m + 5 %)`` of the distance since the reference."""
        return cls(5.0, 0.05, 0.05)

    @classmethod
    def symmetric(cls, abs_error_m: float, rel_error: float,
                  max_speed_mps: float = 45.0) -> OdometerAccuracy:  # fmt: skip
        """``+-(abs_error_m + rel_error * d)``."""
        return cls(abs_error_m, rel_error, rel_error, max_speed_mps)

    @classmethod
    def from_config(cls, config: OdometerConfig) -> OdometerAccuracy:
        """Error bounds of a configured odometer (worst case of every term, safe side).

        Over-reading (true distance shorter than measured): a calibration error, wear (a
        smaller wheel), slip of a driven axle. Under-reading: a calibration error, slide of a
        braked axle. With a radar, slip and slide are detected above its tolerance and the
        radar's speed is used, so the creep term becomes what the detector lets pass over a
        second or more: its relative tolerance plus the absolute tolerance of the seconds'
        means at the slowest speed the wheel is trusted at (``tolerance_mean_mps`` at
        ``tolerance_mps / tolerance``), the radar's scale error, and 0.5 % for the noise of a
        few cycles; without one, the whole creep.
        """
        r = config.radar
        if r is not None:
            # a review: a slide of 3.7 % held for 2 km just above the trusted speed (10 m/s)
            # passed the per-cycle test (2 % + 0.2 m/s) and left D_DOUBTUNDER by 4.6 m when
            # the creep term held the relative tolerance alone
            trusted_mps = r.tolerance_mps / r.tolerance  # 0: no absolute part, none unseen
            unseen = r.tolerance + (r.tolerance_mean_mps / trusted_mps if trusted_mps else 0.0)
            creep_over = creep_under = unseen + r.scale_error + 0.005
        else:
            creep_over = config.slip_max if config.driven else 0.0
            creep_under = config.slide_max if config.braked else 0.0
        # true = measured * ratio / (1 + creep), ratio in [(1 - cal)(1 - wear), 1 + cal]:
        # over-reading, 1 - (1 - cal)(1 - wear) / (1 + slip), is below the sum of the terms
        # and their cross term kept here; under-reading is (1 + cal) / (1 - slide) - 1
        # exactly, above that sum (a 15 % slide under-reads by 17.6 % of the reading: the
        # sum left a braked run's truth 0.4 m outside its bounds, m3)
        if not creep_under < 1.0:
            raise ValueError(f"{config}: a creep under-reading by {creep_under:.0%} or more "
                             "leaves the distance unbounded; check the radar's tolerances")
        cal = config.calibration_error
        over = cal + config.wear + creep_over + cal * creep_over
        under = (1.0 + cal) / (1.0 - creep_under) - 1.0
        return cls(config.abs_error_m, float(over), float(under))

    def doubt_over_m(self, dist_m: ArrayLike) -> NDArray:
        """``D_DOUBTOVER`` after ``dist_m`` metres (either sign) since the reference."""
        return self.abs_error_m + self.over_rel * np.abs(np.asarray(dist_m, float))

    def doubt_under_m(self, dist_m: ArrayLike) -> NDArray:
        """``D_DOUBTUNDER`` after ``dist_m`` metres (either sign) since the reference."""
        return self.abs_error_m + self.under_rel * np.abs(np.asarray(dist_m, float))

    def displacement_bounds_m(
        self, odo_m: ArrayLike, travelled_m: ArrayLike | None = None
    ) -> tuple[NDArray, NDArray]:
        """Bounds of the true signed displacement for a measured signed displacement.

        Parameters
        ----------
        odo_m : array_like
            Measured displacement, signed (either frame), m.
        travelled_m : array_like, optional
            Distance the wheels ran since the reference, either way (the sum of the
            odometer's absolute steps), m; None: ``abs(odo_m)`` (no reversal). The doubts grow
            with it: after a reversal each leg's error counts, not the net displacement's.

        Returns
        -------
        lo_m, hi_m : ndarray
            ``lo <= true <= hi``. Moving forward (``odo >= 0``) an over-read means the true
            displacement is shorter: ``lo = odo - D_DOUBTOVER``, ``hi = odo + D_DOUBTUNDER``;
            backward, the roles swap. After a reversal either leg may have over- or
            under-read: the larger doubt on both sides.
        """
        d = np.asarray(odo_m, float)
        ran = np.abs(d)
        if travelled_m is not None:
            ran = np.maximum(np.asarray(travelled_m, float), ran)
        over, under = self.doubt_over_m(ran), self.doubt_under_m(ran)
        fwd = d >= 0
        lo_doubt, hi_doubt = np.where(fwd, over, under), np.where(fwd, under, over)
        reversed_ = ran > np.abs(d) + 1e-6 * (1.0 + ran)  # rounding of the sums is no reversal
        wide = np.maximum(over, under)
        return d - np.where(reversed_, wide, lo_doubt), d + np.where(reversed_, wide, hi_doubt)

    def anchor_excess_m(
        self,
        true_m: ArrayLike,
        odo_m: ArrayLike,
        ahead_m: ArrayLike | None = None,
        behind_m: ArrayLike | None = None,
    ) -> tuple[NDArray, NDArray]:
        """How far the truth leaves the bounds from the worst earlier sample taken as anchor.

        Every sample may be an anchor (the run loop re-anchors each bound where the satellites
        tightened it, a balise resets from where it is read), so the bounds must hold between
        every pair of samples ``i <= j``, not only from the first: a 4 % over-read for 20 s
        stays inside ``abs + rel x`` the whole run's distance but not inside the bound from
        where it began. Exact for every pair as :meth:`displacement_bounds_m` with the
        travelled distance and the disputed distance since ``i``, in O(n): the bound of a pair
        across a reversal or a disputed step is the larger rate of the two, separable in ``i``
        and ``j``; within a stretch of one direction without dispute the directional rates. A
        backward or disputed step below the rounding tolerance of the whole log (``1e-6 (1 +
        ran)``, which :meth:`displacement_bounds_m` takes as no reversal) does not end a
        stretch: never below the pairwise check, above it only for a pair across such a step
        that the pairwise check takes as a reversal (the stricter, directional bound).

        Parameters
        ----------
        true_m : array_like, shape (n,)
            True signed displacement since the first sample, m.
        odo_m : array_like, shape (n,)
            Measured signed displacement since the first sample (same frame), m.
        ahead_m, behind_m : array_like, shape (n,), optional
            Disputed distance since the first sample toward ``+`` / ``-`` (non-decreasing),
            m; default none.

        Returns
        -------
        excess_m : ndarray, shape (n,)
            Per sample ``j``: the largest distance by which the true displacement from an
            earlier sample ``i`` lies outside the bounds of the measured one, m; ``<= 0``
            inside from every anchor.
        anchor : ndarray of int, shape (n,)
            The sample ``i`` of that largest excess.
        """
        r = np.asarray(true_m, float)
        d = np.asarray(odo_m, float)
        n = r.size
        if d.shape != (n,) or r.ndim != 1:
            raise ValueError(f"true_m and odo_m must be 1-D of one length, got {r.shape} and "
                             f"{d.shape}")  # fmt: skip
        a = np.zeros(n) if ahead_m is None else np.asarray(ahead_m, float)
        b = np.zeros(n) if behind_m is None else np.asarray(behind_m, float)
        if a.shape != (n,) or b.shape != (n,):
            raise ValueError(f"ahead_m and behind_m must have the shape of true_m ({n},), got "
                             f"{a.shape} and {b.shape}")  # fmt: skip
        if not (np.isfinite(r).all() and np.isfinite(d).all() and np.isfinite(a).all()
                and np.isfinite(b).all()):
            # a NaN made every later excess NaN, and NaN > 0 passed every later epoch (m8)
            raise ValueError("true_m, odo_m, ahead_m and behind_m must be finite")
        step = np.diff(d)
        ran = np.concatenate([[0.0], np.cumsum(np.abs(step))]) + a + b
        wide = max(self.over_rel, self.under_rel)
        # any pair: the wide rate, the disputed distance on its side (the looser bound, exact
        # for a pair across a reversal or a disputed step)
        excess, anchor = _pair_excess(r - d - wide * ran - a, r - d + wide * ran + b)
        # pairs within one direction and no disputed step: the directional rates
        # displacement_bounds_m takes a pair as no reversal while its wheels ran at most
        # 1e-6 (1 + ran) beyond its displacement (rounding): a backward step or a disputed
        # step below that is no break of a stretch here either, else such a pair got the wide
        # rate only and a sub-millimetre jitter hid a violation of the directional bounds
        tol = 1e-6 * (1.0 + ran[-1])
        disputed = (np.diff(a) + np.diff(b)) > tol
        step_dir = np.where(np.abs(step) > 0.5 * tol, step, 0.0)
        up, down = 1.0 + self.under_rel, 1.0 - self.over_rel  # forward: hi and lo rates
        for s, e, sign in _monotone_stretches(step_dir, disputed):
            hi_rate, lo_rate = (up, down) if sign >= 0 else (down, up)
            ex, an = _pair_excess(r[s:e] - hi_rate * d[s:e], r[s:e] - lo_rate * d[s:e])
            worse = ex > excess[s:e]
            excess[s:e] = np.where(worse, ex, excess[s:e])
            anchor[s:e] = np.where(worse, an + s, anchor[s:e])
        return excess - self.abs_error_m, anchor


@dataclass(frozen=True)
class BalisePassage:
    """A balise group detected by the train (a reference candidate for the odometer).

    Attributes
    ----------
    index : int
        Odometer sample at which it was read.
    chainage_m : float
        Its location.
    accuracy_m : float
        Its location accuracy (``Q_LOCACC``), m.
    q_reference : bool
        Usable as a reference (``Q_REFERENCE = 1``): resets the interval.
    linked : bool
        Announced by linking: accepted only inside its expectation window.
    known_from : int or None
        Position in the passage list of an earlier balise at a known distance from this one
        (the linking distance); the interval falls back to its value there.
    """

    index: int
    chainage_m: float
    accuracy_m: float = 1.0
    q_reference: bool = True
    linked: bool = True
    known_from: int | None = None

    def __post_init__(self) -> None:
        if self.index < 0 or self.accuracy_m < 0:
            raise ValueError(f"BalisePassage needs index >= 0 and accuracy_m >= 0: {self}")


@dataclass(frozen=True)
class SafeFronts:
    """Estimated and safe front and rear ends per odometer sample (chainages, m).

    Attributes
    ----------
    est_front_m, max_safe_front_m, min_safe_front_m : ndarray, shape (n,)
        Max safe = furthest ahead in the direction of travel; NaN before the first reference.
    est_rear_m, max_safe_rear_m, min_safe_rear_m : ndarray, shape (n,)
        NaN without train-integrity confirmation.
    doubt_over_m, doubt_under_m : ndarray, shape (n,)
        ``D_DOUBTOVER``, ``D_DOUBTUNDER``.
    dist_since_ref_m : ndarray, shape (n,)
        Distance the wheels ran since the last reference, either way (a reversal adds both
        legs), m.
    accepted : ndarray of bool, shape (n_passage,)
        Whether each passage was accepted (inside its expectation window, or not linked).
    linking_alarm : ndarray of bool, shape (n,)
        From a linked balise read outside its expectation window until the next accepted
        reference: the interval was wrong or the balise misplaced (ETCS's linking reaction
        is the train's to apply). The doubts there are widened to cover both the interval
        and the balise's possible location.
    orientation : int
    """

    est_front_m: NDArray
    max_safe_front_m: NDArray
    min_safe_front_m: NDArray
    est_rear_m: NDArray
    max_safe_rear_m: NDArray
    min_safe_rear_m: NDArray
    doubt_over_m: NDArray
    doubt_under_m: NDArray
    dist_since_ref_m: NDArray
    accepted: NDArray
    linking_alarm: NDArray
    orientation: int

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def front_lo_m(self) -> NDArray:
        """Lower chainage bound of the front end."""
        return np.minimum(self.max_safe_front_m, self.min_safe_front_m)

    @property
    def front_hi_m(self) -> NDArray:
        """Upper chainage bound of the front end."""
        return np.maximum(self.max_safe_front_m, self.min_safe_front_m)

    @property
    def length_m(self) -> NDArray:
        """Length of the confidence interval, m."""
        return self.doubt_over_m + self.doubt_under_m


def in_expectation_window(
    balise_chainage_m: float,
    accuracy_m: float,
    max_safe_front_m: ArrayLike,
    min_safe_front_m: ArrayLike,
    orientation: int,
) -> NDArray:
    """Whether a linked balise read now is inside its expectation window.

    Accepted from when the max safe front has reached the balise's first possible position
    (``chainage - accuracy`` in the direction of travel) until the min safe front passes its
    last possible position (``chainage + accuracy``).

    Parameters
    ----------
    balise_chainage_m, accuracy_m : float
    max_safe_front_m, min_safe_front_m : array_like, shape (n,)
        Chainages at the reading time(s).
    orientation : {+1, -1}

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    o = _orientation(orientation)
    ahead = o * (np.asarray(max_safe_front_m, float) - balise_chainage_m) >= -accuracy_m
    behind = o * (np.asarray(min_safe_front_m, float) - balise_chainage_m) <= accuracy_m
    return ahead & behind


def _orientation(orientation: int) -> int:
    if orientation not in (1, -1):
        raise ValueError(f"orientation must be +1 or -1, got {orientation}")
    return int(orientation)


def safe_fronts(
    odo_m: ArrayLike,
    passages: Sequence[BalisePassage],
    accuracy: OdometerAccuracy,
    *,
    orientation: int = 1,
    antenna_to_front_m: float = 0.0,
    train_length_m: float = 100.0,
    integrity_confirmed: ArrayLike | bool = True,
    extra_ahead_m: ArrayLike | None = None,
    extra_behind_m: ArrayLike | None = None,
) -> SafeFronts:
    """ETCS confidence interval and safe ends along an odometer log.

    The balise reader is taken at the location the odometer's position refers to (the
    antenna); the front end is ``antenna_to_front_m`` ahead of it in the direction of travel.

    Parameters
    ----------
    odo_m : array_like, shape (n,)
        Odometer distance, signed along the train's forward axis, m.
    passages : sequence of BalisePassage
        In reading order (non-decreasing ``index``). The first must be a reference (the start).
    accuracy : OdometerAccuracy
    orientation : {+1, -1}
        +1 when the train's forward axis points toward increasing chainage.
    antenna_to_front_m, train_length_m : float
        Geometry, m.
    integrity_confirmed : bool or array_like of bool, shape (n,)
        Train integrity confirmed at each sample (rear ends NaN where not).
    extra_ahead_m, extra_behind_m : array_like, shape (n,), optional
        The odometer's disputed distance, cumulative, along / against the forward axis, m
        (:class:`locator.odometry.odometer.OdometerLog`: where wheel and radar disagreed);
        added to ``D_DOUBTUNDER`` / ``D_DOUBTOVER`` from the reference on. Default: none.

    Returns
    -------
    SafeFronts
    """
    o = _orientation(orientation)
    odo = np.asarray(odo_m, float)
    n = len(odo)
    if odo.ndim != 1:
        raise ValueError("odo_m must be 1-D")
    idx = [p.index for p in passages]
    if any(b < a for a, b in itertools.pairwise(idx)) or any(i >= n for i in idx):
        raise ValueError("passages must be in reading order with index < len(odo_m)")
    if antenna_to_front_m < 0 or train_length_m <= 0:
        raise ValueError("antenna_to_front_m must be >= 0 and train_length_m > 0")
    ran = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(odo)))])  # either way, m
    ahead = np.zeros(n) if extra_ahead_m is None else np.asarray(extra_ahead_m, float)
    behind = np.zeros(n) if extra_behind_m is None else np.asarray(extra_behind_m, float)
    if ahead.shape != (n,) or behind.shape != (n,):
        raise ValueError("extra_ahead_m and extra_behind_m must have one value per odo_m")
    # forward motion: the disputed distance behind adds to the over-reading doubt; and the
    # doubts grow with it (the wheel that ran on while the radar was believed at 0 has its
    # own relative error: a review found fronts 28 m off without)
    disputed = np.column_stack([behind, ahead])
    ran = ran + ahead + behind
    est = np.full(n, np.nan)
    over = np.full(n, np.nan)
    under = np.full(n, np.nan)
    since = np.full(n, np.nan)
    accepted = np.zeros(len(passages), bool)
    alarm = np.zeros(n, bool)
    alarm_from: int | None = None  # the sample of a rejected linked balise not yet cleared
    ran_ref = 0.0  # distance run to the last accepted reference
    # the reference in force: (odometer at it, its chainage, doubt over / under at it,
    # distance run to it, index of its sample)
    ref: tuple[float, float, float, float, float, int] | None = None
    # the reference the expectation windows are drawn from: the last accepted one, never the
    # interval widened over a rejected balise (a user trial: a list 30 m off rejected its
    # first balise, the widened window then accepted the second, equally misplaced, reset the
    # interval to it and cleared the alarm: the true front 28.9 m outside, unflagged)
    ref_window: tuple[float, float, float, float, float, int] | None = None
    at_passage: dict[int, tuple[float, float, float]] = {}  # estimate and doubts at passages
    bounds = [*idx[1:], n]
    for j, p in enumerate(passages):
        k = p.index
        e_k = ov_k = un_k = float("nan")
        if ref is not None:
            state = _state_at(ref, odo[k], ran[k], accuracy, o, disputed[k] - disputed[ref[5]])
            e_k, ov_k, un_k = (float(v) for v in state)
            if p.linked:
                assert ref_window is not None
                w_e, w_ov, w_un = (float(v) for v in _state_at(
                    ref_window, odo[k], ran[k], accuracy, o,
                    disputed[k] - disputed[ref_window[5]]))  # fmt: skip
                hi_f = w_e + o * w_un
                lo_f = w_e - o * w_ov
                ok = bool(in_expectation_window(p.chainage_m, p.accuracy_m, hi_f, lo_f, o))
            else:
                ok = True
        else:
            if not p.q_reference:
                raise ValueError("the first passage must be a reference (Q_REFERENCE = 1)")
            ok = True
        accepted[j] = ok
        if ok and p.q_reference:
            ref = (float(odo[k]), p.chainage_m, p.accuracy_m, p.accuracy_m, float(ran[k]), k)
            ref_window = ref
            alarm_from, ran_ref = None, float(ran[k])
        elif ok and p.known_from is not None and p.known_from in at_passage:
            # known distance from an earlier balise: fall back to the doubts held there, but
            # never below this balise's own location accuracy (the estimate is its location:
            # a review found fronts 8.5 m out with a 20 m accuracy taken as the earlier 5.5 m)
            _, ov_b, un_b = at_passage[p.known_from]
            ov_b, un_b = max(ov_b, p.accuracy_m), max(un_b, p.accuracy_m)
            ref = (float(odo[k]), p.chainage_m, ov_b, un_b, float(ran[k]), k)
            ref_window = ref
            ran_ref = float(ran[k])
        elif not ok:
            # a linked balise outside its expectation window: no reset (the ETCS rule), but
            # the reading proves the interval wrong or the balise misplaced. The interval is
            # widened to cover both, and flagged from here until the next reference (a review:
            # the fronts ran on from the old reference and missed the truth by 4.9 m)
            u = o * (p.chainage_m - e_k)
            ov_w, un_w = max(ov_k, p.accuracy_m - u), max(un_k, u + p.accuracy_m)
            ref = (float(odo[k]), e_k, ov_w, un_w, float(ran[k]), k)
            alarm_from = k if alarm_from is None else alarm_from
        assert ref is not None
        # what a later known-distance balise falls back to: this one's own accuracy where it
        # reset the interval, the widened interval where it was rejected, else the doubts held
        if ok and p.q_reference:
            at_passage[j] = (p.chainage_m, p.accuracy_m, p.accuracy_m)
        elif not ok:
            at_passage[j] = (e_k, ref[2], ref[3])
        else:
            at_passage[j] = (e_k, ov_k, un_k)
        seg = slice(k, bounds[j])
        e, ov, un = _state_at(ref, odo[seg], ran[seg], accuracy, o,
                              disputed[seg] - disputed[ref[5]])  # fmt: skip
        est[seg], over[seg], under[seg] = e, ov, un
        since[seg] = ran[seg] - ran_ref
        alarm[seg] = alarm_from is not None
    front = est + o * antenna_to_front_m
    max_f = front + o * under
    min_f = front - o * over
    conf = np.broadcast_to(np.asarray(integrity_confirmed, bool), (n,))
    rear = front - o * train_length_m

    def only_confirmed(a: NDArray) -> NDArray:
        return np.where(conf, a, np.nan)

    return SafeFronts(
        est_front_m=front, max_safe_front_m=max_f, min_safe_front_m=min_f,
        est_rear_m=only_confirmed(rear), max_safe_rear_m=only_confirmed(max_f - o * train_length_m),
        min_safe_rear_m=only_confirmed(min_f - o * train_length_m),
        doubt_over_m=over, doubt_under_m=under, dist_since_ref_m=since, accepted=accepted,
        linking_alarm=alarm, orientation=o,
    )  # fmt: skip


def _state_at(
    ref: tuple[float, float, float, float, float, int],
    odo: ArrayLike,
    ran: ArrayLike,
    acc: OdometerAccuracy,
    o: int,
    disputed: NDArray,
) -> tuple[NDArray, NDArray, NDArray]:
    """Estimate (chainage) and doubts at odometer readings ``odo`` (and the distances the
    wheels ran to them, ``ran``, and the disputed distance behind / ahead since the
    reference, ``disputed`` of shape (..., 2)), from the reference in force."""
    odo0, chain0, over0, under0, ran0, _ = ref
    d = np.asarray(odo, float) - odo0
    est = chain0 + o * d
    # forward motion: over-reading shortens the true travel (true behind the estimate)
    lo, hi = acc.displacement_bounds_m(d, np.asarray(ran, float) - ran0)
    return est, over0 + (d - lo) + disputed[..., 0], under0 + (hi - d) + disputed[..., 1]


def _pair_excess(upper: NDArray, lower: NDArray) -> tuple[NDArray, NDArray]:
    """Per ``j``: ``max_{i <= j}`` of ``upper[j] - upper[i]`` and ``lower[i] - lower[j]`` (the
    truth beyond the bound above and below, before the fixed part), and its ``i``."""
    idx = np.arange(upper.size)
    low = np.minimum.accumulate(upper)
    at_low = np.maximum.accumulate(np.where(upper == low, idx, 0))
    high = np.maximum.accumulate(lower)
    at_high = np.maximum.accumulate(np.where(lower == high, idx, 0))
    above, below = upper - low, high - lower
    return np.maximum(above, below), np.where(above >= below, at_low, at_high)


def _monotone_stretches(step_m: NDArray, disputed: NDArray) -> list[tuple[int, int, int]]:
    """Sample ranges ``[start, end)`` whose steps keep one direction (zeros aside) and hold no
    disputed step, with that direction (+1, -1; 0 standing); neighbours share a sample."""
    out = []
    start, sign, moved_to = 0, 0, 0  # moved_to: the sample the last moving step ended at
    for k, (s, bad) in enumerate(zip(np.sign(step_m), disputed, strict=True)):
        if bad or (s and sign and s != sign):  # step k runs from sample k to k + 1
            if k > start:
                out.append((start, k + 1, sign))
            # after a reversal the new direction's stretch starts where the old direction's
            # last step ended: the standing (zero) steps between belong to both (a stretch
            # starting at k left the anchors of a stop before the reversal to the wide rate:
            # up to 2 m under the pair-by-pair check, m9)
            start, sign = (k + 1, 0) if bad else (moved_to, int(s))
        elif s:
            sign = int(s)
        if s or bad:
            moved_to = k + 1
    if len(step_m) > start:
        out.append((start, len(step_m) + 1, sign))
    return out
