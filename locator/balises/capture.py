"""Virtual balise capture on the fused interval (source document 001), and its scoring.

GADEROS used two zones around a virtual balise: a large **arm zone** and a small **capture
zone**. A fix inside the capture zone captures the balise; a balise passed with fixes in the arm
zone only is captured too, its time recomputed from the fixes. Here the fixes are the locator's
**fused** estimates (satellites and odometry, :mod:`locator.odometry.fusion`), each with its
interval; a fix counts only when the fused interval is short enough: "if the current accuracy
is good enough". Enough here is what a balise telegram can state: the capture carries its
location accuracy ``q_locacc_m`` (the fused interval's reach about the estimate, the
odometer's doubt over the distance the passage time is carried along it, and the balise's own
survey accuracy), and ETCS's ``Q_LOCACC`` field holds 0-63 m (6 bits, SUBSET-026
packet 5), so a fix whose interval reaches further than ``max_locacc_m`` (63 m) from its
estimate cannot capture.

Per balise at chainage ``b``, with ``u_k = o (s_k - b)`` the estimate's progress past it in the
direction of travel ``o`` over the valid fixes:

1. **passage**: the first pair of consecutive valid fixes with ``u_prev < 0 <= u_cross`` (one
   telegram per balise; the estimate wandering back does not emit again), at most
   ``max_gap_s`` apart (else missed: no telegram rather than a wrongly timed one);
2. **zone**: ``capture`` when one of the two fixes is in the capture zone (``|u| <= radius``,
   or the along-track window ``-before <= u <= after``), else ``arm`` when one is in the arm
   zone, else missed (the fixes jumped over the zones);
3. **reported passage time** (the time the telegram carries): with the odometer, the time at
   which the crossing fix's estimate, carried back along the odometer's distance, was at the
   balise (a satellite correction between the two fixes moves the estimate by a jump that is
   not motion: interpolating across it would time the passage by the jump); without it,
   linear interpolation of the estimate between the two fixes;
   **after a voided epoch** (before the first satellite claim, or an interval too long to
   state), with the odometer: the first valid fix whose estimate, carried back along the
   odometer to the epoch before it, was short of the balise (``0 <= u_k < o (odo_k -
   odo_{k-1})``: the train passed the balise during that last step) is a passage too, timed
   the same way; its stated accuracy adds the odometer's doubt over the carried-back
   distance (``odo_accuracy``). Without it the balise passed in the step that ended a tunnel
   or the run's first claim would be missed although the crossing fix locates it;
4. **emission**: ``emit="at_fix"`` sends the telegram at the crossing fix (causal: the train
   knows it passed only then; Barbu, GADEROS final report), plus ``latency_s``;
   ``emit="predicted"`` schedules it at a fix short of the balise and inside a zone, for
   ``t + (-u) / v`` with the odometer speed, when that comes before the next fix is due; the
   first fix that schedules emits it (causal: whatever the next fix shows), the crossing fix
   otherwise (:func:`_schedule_ahead`).

The radius is tested along the track (the fixes are map-matched): the chord between two track
points is shorter than the arc by under 3 cm for 25 m on a 300 m radius, so the along-track test
never captures where the chord test would not.

:func:`score_captures` compares with the truth (true passage time from the true chainage):
timing error, delay, position error; a capture is **false** when the train was not passing the
balise at the reported time (true position more than ``false_tolerance_m`` away; default the
capture radius, or the reported time outside the truth), and **hazardous** when the true
position lies outside the telegram's own stated accuracy ``q_locacc_m``: a consumer that resets
on the telegram would then hold a wrong interval.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.balises.balisefile import Q_LOCACC_MAX_M, BaliseList
from locator.odometry.confidence import OdometerAccuracy, in_expectation_window

__all__ = ["EMIT_MODES", "Q_LOCACC_MAX_M", "CaptureConfig", "capture_balises", "score_captures"]

EMIT_MODES = ("at_fix", "predicted")

# ``miss_reason`` of a balise not captured (the first rule its passage failed)
MISS_NO_PAIR = "no two valid fixes around it"  # not yet located, or the interval too long
MISS_ZONE = "fixes jumped over the zones"
MISS_GAP = "fixes too far apart"
MISS_LATE = "passage before the earlier fix"
MISS_Q = "stated accuracy over Q_LOCACC"
MISS_WINDOW = "outside the expectation window"


@dataclass(frozen=True)
class CaptureConfig:
    """Zones and rules of the capture.

    Attributes
    ----------
    capture_radius_m : float
        Capture zone half length (radius mode), m.
    arm_radius_m : float
        Arm zone half length, m (0: no arm zone).
    window_before_m, window_after_m : float or None
        Along-track capture window instead of the radius: from ``before`` metres ahead of the
        balise to ``after`` metres past it (both given, or neither).
    max_locacc_m : float
        A fix counts only when its fused interval reaches at most this far from its estimate
        (either side, plus the balise's survey accuracy), m; at most ``Q_LOCACC_MAX_M``, the
        largest accuracy a telegram can state.
    emit : {"at_fix", "predicted"}
    latency_s : float
        Processing time added to every emission, s.
    require_window : bool
        Reject a capture outside the balise's expectation window at the crossing fix (the
        ETCS rule for linked balises, :func:`locator.odometry.confidence.in_expectation_window`
        on the fused interval); False only reports it (``in_window``).
    max_gap_s : float
        The two fixes around the passage must be at most this far apart, s: across a longer
        gap (fixes voided by the accuracy gate, a stop between them) the time cannot be
        interpolated, and no telegram is safer than a wrong one.
    max_accel_mps2 : float
        The train's largest acceleration or braking, m/s^2 (the odometer's
        ``max_accel_mps2``): with ``emit="predicted"``, how far the arrival may be from the
        one predicted at constant speed, in the telegram's stated accuracy.
    """

    capture_radius_m: float = 12.0
    arm_radius_m: float = 0.0
    window_before_m: float | None = None
    window_after_m: float | None = None
    max_locacc_m: float = Q_LOCACC_MAX_M
    emit: str = "at_fix"
    latency_s: float = 0.0
    require_window: bool = False
    max_gap_s: float = 2.0
    max_accel_mps2: float = 1.5

    def __post_init__(self) -> None:
        if not self.capture_radius_m > 0 or self.arm_radius_m < 0:
            raise ValueError(
                f"capture_radius_m must be > 0 and arm_radius_m >= 0, got "
                f"{self.capture_radius_m}, {self.arm_radius_m}"
            )
        if (self.window_before_m is None) != (self.window_after_m is None):
            raise ValueError("give both window_before_m and window_after_m, or neither")
        if self.window_before_m is not None and (
            self.window_before_m < 0 or self.window_after_m is None or self.window_after_m < 0
        ):
            raise ValueError("window_before_m and window_after_m must be >= 0")
        if not self.max_gap_s > 0:
            raise ValueError(f"max_gap_s must be positive, got {self.max_gap_s}")
        if not self.max_accel_mps2 > 0:
            raise ValueError(f"max_accel_mps2 must be positive, got {self.max_accel_mps2}")
        if not 0 < self.max_locacc_m <= Q_LOCACC_MAX_M or self.latency_s < 0:
            raise ValueError(
                f"max_locacc_m must be in (0, {Q_LOCACC_MAX_M:g}] m (what Q_LOCACC can state) "
                f"and latency_s >= 0, got {self.max_locacc_m}, {self.latency_s}"
            )
        if self.emit not in EMIT_MODES:
            raise ValueError(f"emit must be one of {EMIT_MODES}, got {self.emit!r}")

    @classmethod
    def gaderos(cls, capture_radius_m: float, arm_radius_m: float = 0.0) -> CaptureConfig:
        """Radius zones (GADEROS): capture radius, optional arm radius."""
        return cls(capture_radius_m=capture_radius_m, arm_radius_m=arm_radius_m)

    @classmethod
    def window(cls, before_m: float, after_m: float) -> CaptureConfig:
        """An along-track capture window ``[b - before, b + after]`` in the travel direction."""
        return cls(capture_radius_m=max(before_m, after_m, 1e-3), window_before_m=before_m,
                   window_after_m=after_m)  # fmt: skip

    def in_capture(self, u_m: NDArray) -> NDArray:
        """Progress past the balise (m, signed) inside the capture zone."""
        if self.window_before_m is not None and self.window_after_m is not None:
            return (u_m >= -self.window_before_m) & (u_m <= self.window_after_m)
        return np.abs(u_m) <= self.capture_radius_m

    def in_arm(self, u_m: NDArray) -> NDArray:
        """Progress past the balise inside the arm zone."""
        return np.abs(u_m) <= self.arm_radius_m


def capture_balises(
    t_s: ArrayLike,
    est_m: ArrayLike,
    lo_m: ArrayLike,
    hi_m: ArrayLike,
    balises: BaliseList,
    config: CaptureConfig,
    *,
    orientation: int,
    speed_mps: ArrayLike | None = None,
    odo_m: ArrayLike | None = None,
    located: ArrayLike | None = None,
    odo_accuracy: OdometerAccuracy | None = None,
    odo_extra_m: ArrayLike | None = None,
) -> pd.DataFrame:
    """Capture the balises of a list along a run.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Fix times, increasing, s.
    est_m, lo_m, hi_m : array_like, shape (n,)
        Fused estimate and interval per fix (chainage), m; NaN where there is none.
    balises : BaliseList
    config : CaptureConfig
    orientation : {+1, -1}
        Direction of travel along the chainage.
    speed_mps : array_like, shape (n,), optional
        Odometer speed, needed by ``emit="predicted"``.
    odo_m : array_like, shape (n,), optional
        Odometer distance at each fix, signed toward increasing chainage, m: times the passage
        from the crossing fix back along the odometer (module docstring, step 3).
    located : array_like of bool, shape (n,), optional
        Fixes whose interval the satellites have confirmed (a claim at or before the fix);
        others cannot capture: an estimate carried from an unverified start position is no
        satellite location. Default: every fix.
    odo_accuracy : OdometerAccuracy, optional
        The odometer's bounds: every telegram timed along the odometer adds
        ``max(D_DOUBTOVER, D_DOUBTUNDER)`` of the carried distance to its stated accuracy
        (default: :meth:`OdometerAccuracy.subset041`, the ETCS requirement); given with
        ``odo_m``, it also enables the passage at the first valid fix after a voided epoch
        (module docstring, step 3).
    odo_extra_m : array_like, shape (n, 2), optional
        The odometer's disputed distance at each fix, cumulative, toward lower and higher
        chainage, m (:class:`locator.odometry.simulated.SimOdometer`'s ``epoch_extra_m``):
        what the carried-back step disputed adds to that accuracy. Default: none.

    Returns
    -------
    pandas.DataFrame
        One row per balise: ``id``, ``chainage_m``, ``telegram``, ``q_reference`` (the
        list's, 1 or 0: whether the telegram may reset the odometer's confidence interval),
        ``captured``, ``zone``
        (``capture``, ``arm`` or ``""``), ``epoch`` (the crossing fix, -1 if none),
        ``t_pass_s`` (reported passage time), ``t_emit_s``, ``lo_m``, ``hi_m`` (fused interval
        at the crossing fix), ``gap_s`` (time between the two fixes), ``in_window`` (the
        passage fell inside the balise's expectation window on the fused interval),
        ``q_locacc_m`` (the telegram's location accuracy: the furthest either fix's fused
        interval reaches from its estimate, the crossing fix's with the odometer's doubt
        over the distance it is carried back (or, predicted, ahead, with the train's
        acceleration over the wait), plus the balise's survey accuracy, rounded up to the
        metre as Q_LOCACC), ``after_void`` (captured at the first valid fix after a voided
        epoch).
    """
    if orientation not in (1, -1):
        raise ValueError(f"orientation must be +1 or -1, got {orientation}")
    t = np.asarray(t_s, float)
    s = np.asarray(est_m, float)
    lo, hi = np.asarray(lo_m, float), np.asarray(hi_m, float)
    if not (t.shape == s.shape == lo.shape == hi.shape) or t.ndim != 1:
        raise ValueError("t_s, est_m, lo_m and hi_m must be 1-D of one length")
    v = None if speed_mps is None else np.asarray(speed_mps, float)
    if config.emit == "predicted" and (v is None or v.shape != t.shape):
        raise ValueError("emit='predicted' needs speed_mps with one value per fix")
    b = np.asarray(balises.chainage_m, float)
    b_acc = np.asarray(balises.accuracy_m, float)
    odo = None if odo_m is None else np.asarray(odo_m, float)
    if odo is not None and odo.shape != t.shape:
        raise ValueError("odo_m must have one value per fix")
    if odo is not None and (np.diff(orientation * odo) < -1e-6).any():
        k = int(np.flatnonzero(np.diff(orientation * odo) < -1e-6)[0]) + 1
        raise ValueError(
            f"odo_m runs back at fix {k} (against the orientation {orientation:+d}): the "
            "passage times are read along the odometer, one way; capture each leg of a "
            "reversing run apart"
        )
    # the odometer's bounds: without them, the ETCS requirement (5 m + 5 %) on the safe side
    odo_acc = OdometerAccuracy.subset041() if odo_accuracy is None else odo_accuracy
    extra = np.zeros((len(t), 2)) if odo_extra_m is None else np.asarray(odo_extra_m, float)
    if extra.shape != (len(t), 2):
        raise ValueError(f"odo_extra_m must have shape ({len(t)}, 2), got {extra.shape}")
    ok = np.ones(t.shape, bool) if located is None else np.asarray(located, bool)
    if ok.shape != t.shape:
        raise ValueError("located must have one value per fix")
    with np.errstate(invalid="ignore"):
        reach = np.maximum(s - lo, hi - s)  # the interval's reach about the estimate
        valid = ok & np.isfinite(s) & (reach <= config.max_locacc_m)  # voided fixes skipped
    idx = np.flatnonzero(valid)
    n_b = len(b)
    out = {
        "captured": np.zeros(n_b, bool), "zone": np.full(n_b, "", object),
        "epoch": np.full(n_b, -1, np.int64), "t_pass_s": np.full(n_b, np.nan),
        "t_emit_s": np.full(n_b, np.nan), "lo_m": np.full(n_b, np.nan),
        "hi_m": np.full(n_b, np.nan), "gap_s": np.full(n_b, np.nan),
        "in_window": np.zeros(n_b, bool), "q_locacc_m": np.full(n_b, np.nan),
        "after_void": np.zeros(n_b, bool),
        # why a balise was not captured (a user trial's list with accuracy_m in cm was
        # missed 22 times in 22 with nothing saying why): filled for the pair rule's misses
        "miss_reason": np.full(n_b, MISS_NO_PAIR, object),
    }  # fmt: skip
    if len(idx) >= 2 and n_b:
        u = orientation * (s[idx][None, :] - b[:, None])  # (n_b, n_valid)
        cross = (u[:, :-1] < 0.0) & (u[:, 1:] >= 0.0)
        has = cross.any(axis=1)
        j = np.argmax(cross, axis=1)
        rows = np.flatnonzero(has)
        jp = j[rows]
        kp, kc = idx[jp], idx[jp + 1]
        up, uc = u[rows, jp], u[rows, jp + 1]
        in_c = config.in_capture(up) | config.in_capture(uc)
        in_a = ~in_c & (config.in_arm(up) | config.in_arm(uc))
        # expectation window at the crossing fix: max safe front reached b - acc, min safe
        # front not past b + acc (the fused interval's ends in the travel direction)
        acc = b_acc[rows]
        max_safe = np.where(orientation > 0, hi[kc], lo[kc])
        min_safe = np.where(orientation > 0, lo[kc], hi[kc])
        window = (orientation * (max_safe - b[rows]) >= -acc) & (
            orientation * (min_safe - b[rows]) <= acc
        )
        got = (in_c | in_a) & (t[kc] - t[kp] <= config.max_gap_s + 1e-9)
        if odo is not None:
            # the odometer reading when the crossing fix's estimate, carried back, was at b
            o_pass = orientation * (odo[kc] - (s[kc] - b[rows]))
            t_pass = np.minimum(np.interp(o_pass, orientation * odo, t), t[kc])
            # a passage the odometer puts well before the earlier fix was not made between the
            # two: the estimate caught up with a lagging odometer (a radar at 0), and the
            # telegram would be a late position report (a user trial: 72 s late, counted)
            got &= t_pass >= t[kp] - config.max_gap_s - 1e-9
            # the time comes from the crossing fix carried back uc metres along the odometer:
            # its doubt over them is the telegram's too (a review: 3.9 m out with q = 3 m)
            k_pass = np.clip(np.searchsorted(t, t_pass, side="right") - 1, 0, len(t) - 1)
            carry = reach[kc] + _carry_doubt_m(odo_acc, uc, extra[kc] - extra[k_pass])
            q_m = np.maximum(reach[kp], carry)
        else:
            t_pass = t[kp] + (-up / (uc - up)) * (t[kc] - t[kp])
            q_m = np.maximum(reach[kp], reach[kc])
        # the time is read linearly between two fixes (the odometer's too): a train that
        # accelerates may be a t_gap^2 / 8 off that line (a review: braking at 1.5 m/s^2
        # over a 2 s gap, 3.65 m from the balise with q = 3 m)
        q = np.ceil(q_m + _interpolation_m(config, t[kc] - t[kp]) + b_acc[rows] - 1e-9)
        got &= q <= config.max_locacc_m
        if config.require_window:
            got &= window
        # the first rule each miss failed: listed from the last rule applied above to the
        # first, as each np.where overwrites the reasons before it
        why = np.full(len(rows), "", object)
        gap_why = np.array([
            f"{MISS_GAP} ({int((~ok[a + 1:c]).sum())} fixes between not located or doubtful, "
            f"{int((ok[a + 1:c] & ~valid[a + 1:c]).sum())} too long to state)"
            for a, c in zip(kp, kc, strict=True)], object)  # fmt: skip
        late = np.ones(len(rows), bool) if odo is None else (
            t_pass >= t[kp] - config.max_gap_s - 1e-9)  # fmt: skip
        for fail, text in (
            (config.require_window & ~window, MISS_WINDOW),
            (q > config.max_locacc_m, None),
            (~late, MISS_LATE),
            (t[kc] - t[kp] > config.max_gap_s + 1e-9, gap_why),
            (~(in_c | in_a), MISS_ZONE),
        ):
            if text is None:  # the stated accuracy, with its value
                text = np.array([f"{MISS_Q} ({x:.0f} m > {config.max_locacc_m:g} m)"
                                 for x in q], object)  # fmt: skip
            why = np.where(fail, text, why)
        out["miss_reason"][rows] = why
        t_emit = t[kc].copy()
        r = rows[got]
        out["captured"][r] = True
        out["zone"][r] = np.where(in_c[got], "capture", "arm")
        out["epoch"][r] = kc[got]
        out["t_pass_s"][r] = t_pass[got]
        out["t_emit_s"][r] = t_emit[got] + config.latency_s
        out["lo_m"][r] = lo[kc[got]]
        out["hi_m"][r] = hi[kc[got]]
        out["gap_s"][r] = (t[kc] - t[kp])[got]
        out["q_locacc_m"][r] = q[got]
        out["in_window"][rows] = window
    if odo is not None and odo_accuracy is not None and len(idx) and n_b:
        _capture_after_void(t, s, lo, hi, reach, valid, odo, odo_accuracy, b, b_acc, config,
                            orientation, out, extra)  # fmt: skip
    if config.emit == "predicted" and len(idx) >= 2 and n_b:
        assert v is not None
        _schedule_ahead(t, s, lo, hi, reach, idx, v, b, b_acc, config, orientation, out,
                        odo_acc, extra)  # fmt: skip
    out["miss_reason"] = np.where(out["captured"], "", out["miss_reason"])
    return pd.DataFrame({"id": list(balises.ids), "chainage_m": b,
                         "telegram": list(balises.telegram),
                         "q_reference": np.asarray(balises.q_reference, bool).astype(int),
                         **out})  # fmt: skip


def _schedule_ahead(
    t: NDArray,
    s: NDArray,
    lo: NDArray,
    hi: NDArray,
    reach: NDArray,
    idx: NDArray,
    v: NDArray,
    b: NDArray,
    b_acc: NDArray,
    config: CaptureConfig,
    orientation: int,
    out: dict[str, NDArray],
    accuracy: OdometerAccuracy,
    extra: NDArray,
) -> None:
    """``emit="predicted"``, causally: at each valid fix short of a balise and inside its zone,
    the telegram is scheduled for the predicted arrival ``t + (-u) / v`` when that comes before
    the next fix is due (the fixes' usual period); the first such fix of a balise emits it,
    whatever the next fix shows (a train braking to a stop short of the balise sends it all
    the same: the score calls that false). A balise no fix schedules keeps its capture at the
    crossing fix. A fix whose telegram would fall after the data's last epoch schedules
    nothing (what follows the recording cannot be scored). Fills ``out`` in place.

    The rule used to be applied only to balises a later fix was seen to cross, and judged with
    that fix's interval: hindsight, which hid the stop-short case (a user trial's review).
    """
    period = float(np.median(np.diff(t[idx])))
    # the odometer's speed is in dispute where its disputed distance grew in the last step
    # (wheel and radar disagree, or a standing radar under a turning wheel): a prediction
    # from it may run at a failed radar's speed (a review: a radar reading twice the speed
    # gave q = 5 m for 12 m); the pair rule times those balises instead
    grew = np.zeros(len(t), bool)
    grew[1:] = (np.diff(extra, axis=0).sum(axis=1) > 0.0)
    for n in range(len(b)):
        u = orientation * (s[idx] - b[n])
        with np.errstate(divide="ignore", invalid="ignore"):
            ahead = -u / v[idx]
        # the arrival is predicted -u metres ahead at the odometer's speed: its doubt over
        # them, and the train's acceleration over the wait, are the telegram's too (a review:
        # 3.7 m out with q = 3 m)
        wait_s = np.where(np.isfinite(ahead), np.maximum(ahead, 0.0), 0.0)
        q = np.ceil(reach[idx] + _carry_doubt_m(accuracy, u)
                    + 0.5 * config.max_accel_mps2 * wait_s**2 + b_acc[n] - 1e-9)  # fmt: skip
        zone = config.in_capture(u) | config.in_arm(u)
        ok = (u < 0) & zone & (v[idx] > 0) & (ahead < period) & (q <= config.max_locacc_m)
        ok &= ~grew[idx]
        # within the data: a telegram scheduled after the last epoch cannot be scored (the
        # recording stops; the truth with it), and was counted hazardous as unknown
        ok &= t[idx] + ahead <= t[-1]
        first = np.flatnonzero(ok)
        if not len(first):
            continue
        k = int(idx[first[0]])
        sched = t[k] + float(ahead[first[0]])
        shift = orientation * float(-u[first[0]])  # the interval carried to the arrival
        max_safe = (hi[k] if orientation > 0 else lo[k]) + shift
        min_safe = (lo[k] if orientation > 0 else hi[k]) + shift
        window = bool(in_expectation_window(b[n], b_acc[n], max_safe, min_safe, orientation))
        if config.require_window and not window:
            continue
        out["captured"][n] = True
        out["zone"][n] = "capture" if config.in_capture(u[first[0]]) else "arm"
        out["epoch"][n] = k
        out["t_pass_s"][n] = sched
        out["t_emit_s"][n] = sched + config.latency_s
        out["lo_m"][n], out["hi_m"][n] = lo[k], hi[k]
        out["gap_s"][n] = period
        out["q_locacc_m"][n] = q[first[0]]
        out["in_window"][n] = window
        out["after_void"][n] = False


def _capture_after_void(
    t: NDArray,
    s: NDArray,
    lo: NDArray,
    hi: NDArray,
    reach: NDArray,
    valid: NDArray,
    odo: NDArray,
    accuracy: OdometerAccuracy,
    b: NDArray,
    b_acc: NDArray,
    config: CaptureConfig,
    orientation: int,
    out: dict[str, NDArray],
    extra: NDArray,
) -> None:
    """The passage at the first valid fix after a voided epoch (``out`` updated in place for
    the balises the pair rule did not capture; module docstring, step 3)."""
    k = np.flatnonzero(valid[1:] & ~valid[:-1]) + 1  # valid fixes after a voided epoch
    k = k[t[k] - t[k - 1] <= config.max_gap_s + 1e-9]
    todo = np.flatnonzero(~out["captured"])
    if not len(k) or not len(todo):
        return
    step = orientation * (odo[k] - odo[k - 1])  # (m,) forward distance of the last step
    u = orientation * (s[k][None, :] - b[todo, None])  # (n_todo, m)
    back = u - step[None, :]  # the estimate carried back to the epoch before
    cross = (u >= 0.0) & (back < 0.0) & (step[None, :] > 0.0)
    has = cross.any(axis=1)
    j = np.argmax(cross, axis=1)[has]
    rows = todo[has]
    kc = k[j]
    uc, ub = u[has, j], back[has, j]
    in_c = config.in_capture(uc) | config.in_capture(ub)
    in_a = ~in_c & (config.in_arm(uc) | config.in_arm(ub))
    doubt = _carry_doubt_m(accuracy, uc, extra[kc] - extra[kc - 1])
    # read along the odometer known at the fixes only: linearly over the step, as the pair
    # rule's time, and as far off that line as the train's acceleration allows
    doubt = doubt + _interpolation_m(config, t[kc] - t[kc - 1])
    q = np.ceil(reach[kc] + doubt + b_acc[rows] - 1e-9)
    max_safe = np.where(orientation > 0, hi[kc], lo[kc])
    min_safe = np.where(orientation > 0, lo[kc], hi[kc])
    window = (orientation * (max_safe - b[rows]) >= -b_acc[rows]) & (
        orientation * (min_safe - b[rows]) <= b_acc[rows]
    )
    got = (in_c | in_a) & (q <= config.max_locacc_m)
    if config.require_window:
        got &= window
    o_pass = orientation * (odo[kc] - (s[kc] - b[rows]))
    t_pass = np.minimum(np.interp(o_pass, orientation * odo, t), t[kc])
    got &= t_pass >= t[kc - 1] - config.max_gap_s - 1e-9  # not a late report (pair rule)
    r = rows[got]
    out["captured"][r] = True
    out["after_void"][r] = True
    out["zone"][r] = np.where(in_c[got], "capture", "arm")
    out["epoch"][r] = kc[got]
    out["t_pass_s"][r] = t_pass[got]
    # emitted at the crossing fix (the train knows it passed only then)
    out["t_emit_s"][r] = t[kc][got] + config.latency_s
    out["lo_m"][r] = lo[kc][got]
    out["hi_m"][r] = hi[kc][got]
    out["gap_s"][r] = (t[kc] - t[kc - 1])[got]
    out["q_locacc_m"][r] = q[got]
    out["in_window"][rows] = window


def score_captures(
    captures: pd.DataFrame,
    truth_t_s: ArrayLike,
    truth_chainage_m: ArrayLike,
    *,
    orientation: int,
    false_tolerance_m: float,
    margin_m: float = 0.0,
) -> pd.DataFrame:
    """Captures against the true motion.

    Parameters
    ----------
    captures : pandas.DataFrame
        From :func:`capture_balises`.
    truth_t_s, truth_chainage_m : array_like, shape (m,)
        True chainage of the antenna over time, dense enough for linear interpolation (the
        simulation's epochs or an odometer cycle grid); monotone in the travel direction.
    orientation : {+1, -1}
    false_tolerance_m : float
        A capture whose true position at the reported passage time is further than this from
        the balise is false.
    margin_m : float
        A balise counts as passed only when the true run covers it with this margin at both
        ends (the first fixes need to arm).

    Returns
    -------
    pandas.DataFrame
        ``captures`` plus ``passed`` (the train truly passed it, with the margin: the
        passages the capture rate counts), ``t_true_s`` (true passage
        time), ``timing_error_s`` (reported - true), ``delay_s`` (emission - true),
        ``position_error_m`` (true position at the reported time minus the balise, along the
        travel direction), ``false`` (captured, and the true position at the reported time
        is off by more than the tolerance, or that time lies outside the truth),
        ``hazardous`` (captured, and the true position is off by more than the telegram's
        ``q_locacc_m``, or unknown), ``missed`` (passed and not captured).

    Notes
    -----
    A balise beyond the truth's last position is not "never reached" by itself: a simulated
    run ends in motion, and the estimate may cross a balise the train reaches a metre after
    the recording stops. The position at the reported time judges it, as everywhere else.
    """
    tt = np.asarray(truth_t_s, float)
    u_true = orientation * np.asarray(truth_chainage_m, float)
    if np.any(np.diff(u_true) < -1e-9):
        raise ValueError("truth_chainage_m must not move against the travel direction")
    b = orientation * captures["chainage_m"].to_numpy(float)
    reached = (b >= u_true[0]) & (b <= u_true[-1])
    passed = (b >= u_true[0] + margin_m) & (b <= u_true[-1] - margin_m)
    # the first time each is reached: a train stopping on a balise passes it on arrival
    # (np.interp over the stop's repeated positions took its departure: a user trial's
    # telegram 62 s late was scored 1.5 s)
    k = np.clip(np.searchsorted(u_true, b, side="left"), 1, len(u_true) - 1)
    du = u_true[k] - u_true[k - 1]
    frac = np.where(du > 0, (b - u_true[k - 1]) / np.where(du > 0, du, 1.0), 1.0)
    between = tt[k - 1] + np.clip(frac, 0.0, 1.0) * (tt[k] - tt[k - 1])
    first = np.where(b <= u_true[0], tt[0], between)
    t_true = np.where(reached, first, np.nan)
    t_pass = captures["t_pass_s"].to_numpy(float)
    pos = np.interp(t_pass, tt, u_true) - b
    cap = captures["captured"].to_numpy(bool)
    out = captures.copy()
    out["passed"] = passed
    out["t_true_s"] = t_true
    out["timing_error_s"] = t_pass - t_true
    out["delay_s"] = captures["t_emit_s"].to_numpy(float) - t_true
    out["position_error_m"] = np.where(cap, pos, np.nan)
    known = (t_pass >= tt[0]) & (t_pass <= tt[-1])
    off = np.where(known, np.abs(np.nan_to_num(pos, nan=np.inf)), np.inf)
    out["false"] = cap & (off > false_tolerance_m)
    q = captures["q_locacc_m"].to_numpy(float)
    out["hazardous"] = cap & ~(off <= q)
    out["missed"] = passed & ~cap
    return out


def _carry_doubt_m(
    accuracy: OdometerAccuracy, dist_m: NDArray, disputed_m: NDArray | None = None
) -> NDArray:
    """The odometer's doubt over ``dist_m`` metres (either sign) carried along it, with the
    disputed distance ``disputed_m`` (shape (..., 2), behind / ahead; None: none) in that span
    and the relative error over it, m (either side: the larger)."""
    doubt = np.maximum(accuracy.doubt_over_m(dist_m), accuracy.doubt_under_m(dist_m))
    if disputed_m is None:
        return doubt
    rel = max(accuracy.over_rel, accuracy.under_rel)
    return doubt + (1.0 + rel) * np.asarray(disputed_m, float).sum(axis=-1)


def _interpolation_m(config: CaptureConfig, gap_s: NDArray) -> NDArray:
    """How far a train at ``config.max_accel_mps2`` may be from the straight line between two
    fixes ``gap_s`` apart (its time read linearly between them), m: ``a gap^2 / 8``."""
    return config.max_accel_mps2 * np.asarray(gap_s, float) ** 2 / 8.0
