"""Do an observation file's time tags agree with its pseudoranges?

A receiver's pseudorange is, by definition, the difference between its own time tag of
reception and the satellite's time of transmission, times c: a receiver clock offset shows in
both, and cancels in the transmission time ``t_tag - P / c`` that places the satellites. A
file whose tags and ranges disagree by ``delta`` (a converter that shifts the tags, a clock
offset applied to one and not the other: RINEX ``RCV CLOCK OFFS APPL``, a receiver's
millisecond clock jump written into the ranges only) places every satellite where it was
``delta`` earlier or later. Each range is then off by its range rate times ``delta`` (up to
about 800 m/s: 40 m at 50 ms); the errors differ between satellites, so they do not cancel in
the locator's pair differences, and a user trial measured 24 hazardous claims in 24 with tags
100 ms late.

The offset is observable: it is a fifth unknown of the single point fix whose column is each
satellite's range rate (coarse-time navigation; F. van Diggelen, *A-GPS*, 2009, ch. 4).
:func:`tag_offsets` estimates it at sampled epochs and :func:`check_time_tags` refuses a run
whose offsets are not negligible.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from locator.corrections import RangeModel
from locator.observations import Observations
from locator.spp import PositionFix, first_guess, solve_epoch
from predisat.availability.satellites import select_satellites

__all__ = [
    "MAX_TAG_OFFSET_S",
    "MIN_EVIDENCE_EPOCHS",
    "TagOffsets",
    "check_time_tags",
    "tag_offset",
    "tag_offsets",
]

MAX_TAG_OFFSET_S = 0.003
"""Largest disagreement between time tags and pseudoranges a run is located with: 3 ms moves a
satellite's range by at most 2.4 m (range rates stay under 800 m/s), inside the pseudorange
error model; beyond it the error grows by up to 0.8 m per ms. Clean files of four geodetic
receivers read within 0.05 ms; 5 ms was refused on each with 74-120 epochs of evidence, and
GPS alone with 19 epochs needed 10 ms (``docs/observations.md``)."""

MIN_EVIDENCE_EPOCHS = 10
"""Sampled epochs with evidence below which a run says its tags could not be checked (one
system with 6 satellites in view leaves no epoch enough redundancy)."""

_MIN_SIGNIFICANCE = 4.0  # a median offset is believed when this many sigmas from zero
_MIN_JUMPS = 3  # sampled epochs each significantly off that make a jump
_MIN_REDUNDANT = 2  # ranges beyond the unknowns an epoch needs to say anything on its tags
_MAX_SCALE = 9.0  # residuals above 3 times the weights' sigma: a faulty range, no evidence
_ITERATIONS = 5  # solutions per epoch at most, the tag moved by the offset found
_CONVERGED_S = 0.002  # an offset found below this is not worth another solution


def tag_offset(model: RangeModel, fix: PositionFix) -> tuple[float, float]:
    """Time-tag offset of one solved epoch, robust to one faulty range, with its sigma.

    Parameters
    ----------
    model : RangeModel
        The model that solved ``fix``.
    fix : PositionFix
        A solved epoch (``fix.ok``), with its ranges.

    Returns
    -------
    offset_s, sigma_s : float
        The offset ``delta`` such that the satellites were where the ephemeris places them at
        ``t_tag - P / c + delta``, seconds: of the five-state fits that each leave one range
        out, the least significant (``|delta| / sigma`` smallest), so that one faulty range
        cannot make an offset. NaN without a solution, with fewer than two ranges beyond the
        unknowns (position, one clock per system, the offset), or when that fit's residuals
        stand more than 3 times above the weights' sigma (more than one faulty range).
    """
    fit = _fit(model, fix)
    if fit is None:
        return float("nan"), float("nan")
    return _robust(fit, 0.0)


def _robust(fit: _Fit, shift_s: float) -> tuple[float, float]:
    """The least significant leave-one-out offset (plus ``shift_s``, the tag's move) and its
    sigma; NaN when that fit's residuals stand above 3 sigma (more than one faulty range:
    choosing among the fits that stay within it instead let two swapped satellites read as
    -20 s and refuse a file)."""
    k = _least_significant(fit, shift_s)
    if fit.loo[k, 2] > _MAX_SCALE:
        return float("nan"), float("nan")
    return float(shift_s + fit.loo[k, 0]), float(np.sqrt(fit.loo[k, 1] * fit.loo[k, 2]))


def _least_significant(fit: _Fit, shift_s: float) -> int:
    """The leave-one-out fit whose offset (plus ``shift_s``) is the fewest sigmas from 0."""
    sigma = np.sqrt(fit.loo[:, 1] * fit.loo[:, 2])
    return int(np.argmin(np.abs(shift_s + fit.loo[:, 0]) / sigma))


@dataclass(frozen=True)
class _Fit:
    """An epoch's five-state fits with each range left out."""

    loo: NDArray  # (n, 3): offset, its variance from the weights, the residuals' scale


def _fit(model: RangeModel, fix: PositionFix) -> _Fit | None:
    """The five-state fits of a solved epoch; None when not solvable or not redundant enough
    (two ranges beyond the unknowns: one left out, one to check the rest)."""
    cr = fix.ranges
    if not fix.ok or cr is None:
        return None
    use = np.isin(np.asarray(cr.states.sats), fix.sats_used)
    sats = [s for s, u in zip(cr.states.sats, use, strict=True) if u]
    systems = sorted({s[0] for s in sats})
    n = len(sats)
    if n < 4 + len(systems) + _MIN_REDUNDANT:  # position, clocks, the offset, and redundancy
        return None
    t_tx = np.asarray(cr.states.transmit_gps_s, float)[use]
    both = model.ephemeris.evaluate(np.concatenate([t_tx - 0.5, t_tx + 0.5]), sats)[0]
    idx = np.arange(n)
    vel = both[idx + n, idx] - both[idx, idx]  # m/s, central difference over 1 s
    los = (cr.sat_ecef_m[use] - fix.ecef_m) / cr.range_m[use, None]
    h = np.zeros((n, 4 + len(systems)))
    h[:, :3] = -los
    h[idx, 3 + np.array([systems.index(s[0]) for s in sats])] = 1.0
    h[:, -1] = np.sum(los * vel, axis=1)  # range rate: d range / d delta
    y = cr.corrected_m[use] - cr.range_m[use]
    sin_el = np.sin(np.radians(cr.el_deg[use]))
    # the fix's own weights (RTKLIB's code variance): an estimate, not a bound
    w = 1.0 / (0.09 + 0.09 / sin_el**2 + (0.5 * cr.iono_m[use]) ** 2)
    # One faulty range (a bias the locator's FDE would exclude) leans on the offset: 10 m on
    # one of 7 GPS satellites read as -5.5 ms and 100 m as -126 ms (a trial and two reviews;
    # earlier versions refused such files). Left out in turn, the fit without it shows none.
    loo = []
    for k in range(n):
        others = idx != k
        sub = _solve(h[others], w[others], y[others])
        if sub is None:  # one range fewer leaves the rest singular: no robust estimate
            return None
        loo.append(sub)
    return _Fit(np.array(loo, float))


def _solve(h: NDArray, w: NDArray, y: NDArray) -> tuple[float, float, float] | None:
    """Weighted least squares: the last unknown, its variance from the weights, and the
    factor the residuals scale it by (at least 1); None when singular or not redundant."""
    dof = len(y) - h.shape[1]
    if dof < 1:
        return None
    hw = h * w[:, None]
    try:
        cov = np.linalg.inv(hw.T @ h)
    except np.linalg.LinAlgError:
        return None
    x = cov @ (hw.T @ y)
    res = y - h @ x
    return float(x[-1]), float(cov[-1, -1]), max(float(np.sum(w * res**2)) / dof, 1.0)


@dataclass(frozen=True)
class TagOffsets:
    """Time-tag offsets at sampled epochs of a file.

    Attributes
    ----------
    gps_s : ndarray, shape (n,)
        The sampled epochs (those solved with enough satellites).
    offset_s, sigma_s : ndarray, shape (n,)
        Each epoch's offset (robust to one faulty range: :func:`tag_offset`) and its
        standard deviation, seconds.
    """

    gps_s: NDArray
    offset_s: NDArray
    sigma_s: NDArray

    @property
    def median_s(self) -> float:
        """Median offset, seconds (NaN without an epoch)."""
        return float(np.median(self.offset_s)) if len(self.offset_s) else float("nan")

    @property
    def median_sigma_s(self) -> float:
        """Standard deviation of the median: ``1.2533 * 1.4826 * MAD / sqrt(n)``, at least
        the epochs' own median sigma over ``sqrt(n)``."""
        n = len(self.offset_s)
        if n == 0:
            return float("nan")
        mad = float(np.median(np.abs(self.offset_s - self.median_s)))
        spread = max(1.4826 * mad, float(np.median(self.sigma_s)))
        return 1.2533 * spread / np.sqrt(n)

    def jumps(self, min_s: float = MAX_TAG_OFFSET_S) -> NDArray:
        """Epochs whose own offset is beyond ``min_s`` and 4 of their sigmas, (k,)."""
        return np.asarray(self.gps_s)[self._off(min_s)]

    def jumps_median_s(self, min_s: float = MAX_TAG_OFFSET_S) -> float:
        """Median offset of the epochs of :meth:`jumps`, seconds (NaN without one)."""
        off = np.asarray(self.offset_s)[self._off(min_s)]
        return float(np.median(off)) if len(off) else float("nan")

    def _off(self, min_s: float) -> NDArray:
        x = np.abs(np.asarray(self.offset_s))
        return (x > min_s) & (x > _MIN_SIGNIFICANCE * np.asarray(self.sigma_s))


def tag_offsets(
    model: RangeModel, obs: Observations, epochs: Sequence[int] | NDArray,
    constellation: str = "all",
) -> TagOffsets:  # fmt: skip
    """Time-tag offsets at the epochs indexed by ``epochs``.

    Parameters
    ----------
    model : RangeModel
    obs : Observations
    epochs : sequence of int
        Indices into ``obs.gps_s``.
    constellation : str
        The systems whose ranges are used (``predisat.availability.satellites.
        select_satellites``): those of the run, so that a system it leaves out cannot refuse
        it.

    Returns
    -------
    TagOffsets
    """
    sel = obs.pseudorange()
    wanted = np.isin(np.asarray(obs.sats), select_satellites(obs.sats, constellation))
    m = model.with_glonass_slots(obs.header.glonass_slots)
    x0 = first_guess(obs)
    rows = []
    for i in np.asarray(epochs, int):
        have = np.isfinite(sel.pseudorange_m[i]) & wanted
        if not have.any():
            continue
        sats = [s for s, h in zip(obs.sats, have, strict=True) if h]
        t, shift = float(obs.gps_s[i]), 0.0
        # the range rates are a linearisation: an offset of seconds (a time scale mixed up)
        # is found by moving the tag and solving again
        for _ in range(_ITERATIONS):
            fix = solve_epoch(m, t + shift, sats, sel.pseudorange_m[i, have],
                              list(sel.code[i, have]), x0_ecef_m=x0)  # fmt: skip
            fit = _fit(m, fix) if fix.ok else None
            if fit is None:
                break
            x0 = fix.ecef_m
            # the tag moves by the robust estimate: the fit of every range would follow a
            # faulty one (two swapped satellites moved it by 20 s)
            step = float(fit.loo[_least_significant(fit, 0.0), 0])
            if abs(step) < _CONVERGED_S:
                d, sd = _robust(fit, shift)
                if np.isfinite(d) and np.isfinite(sd):
                    rows.append((t, d, sd))
                break
            shift += step
    arr = np.array(rows, float).reshape(-1, 3)
    return TagOffsets(arr[:, 0], arr[:, 1], arr[:, 2])


def check_time_tags(
    model: RangeModel, obs: Observations, label: str, n_epochs: int = 120,
    max_offset_s: float = MAX_TAG_OFFSET_S, constellation: str = "all",
) -> TagOffsets:  # fmt: skip
    """Refuse a file whose time tags disagree with its pseudoranges.

    Parameters
    ----------
    model : RangeModel
    obs : Observations
    label : str
        The file, for the message.
    n_epochs : int
        Epochs sampled, spread over the file.
    max_offset_s : float
        Largest offset accepted, seconds (:data:`MAX_TAG_OFFSET_S`).
    constellation : str
        The run's systems (:func:`tag_offsets`).

    Returns
    -------
    TagOffsets
        The offsets of the sampled epochs that carry evidence (for the run's record; the
        caller says so when there are fewer than :data:`MIN_EVIDENCE_EPOCHS`).

    Raises
    ------
    ValueError
        When the median offset is beyond ``max_offset_s`` and 4 of its sigmas, or when three
        sampled epochs are each beyond it and 4 of their own sigmas (a jump in part of the
        file, which the median hides).
    """
    n = len(obs.gps_s)
    idx = np.unique(np.linspace(0, max(n - 1, 0), min(n_epochs, n)).astype(int))
    off = tag_offsets(model, obs, idx, constellation)
    if not len(off.offset_s):
        return off
    med, sig = off.median_s, off.median_sigma_s
    whole = abs(med) > max_offset_s and abs(med) > _MIN_SIGNIFICANCE * sig
    jumps = off.jumps(max_offset_s)
    if whole or len(jumps) >= _MIN_JUMPS:
        n_ok = len(off.offset_s)
        if whole:
            what = (f"by {med * 1e3:+.1f} ms (the median of {n_ok} sampled epochs, "
                    f"+-{sig * 1e3:.1f} ms)")  # fmt: skip
        else:
            med = off.jumps_median_s(max_offset_s)
            what = (f"by {med * 1e3:+.1f} ms at {len(jumps)} of {n_ok} sampled epochs (from "
                    f"gps_s {jumps[0]:.0f}): a jump in the file")  # fmt: skip
        seconds = abs(med) > 5.0 and abs(med - round(med)) < 0.05  # GPS - UTC >= 11 s since 1996
        scale = (
            f" About {round(med):+d} s is a time scale mixed up: UTC, GLONASS or BeiDou time "
            "read as GPS time (GPS - UTC = 18 s since 2017, GPS - BDT = 14 s; the time system "
            "of the header's TIME OF FIRST OBS)."
            if seconds
            else ""
        )
        raise ValueError(
            f"{label}: the epochs' time tags disagree with their pseudoranges {what}; at most "
            f"{max_offset_s * 1e3:g} ms is accepted. The satellites' range rates show it (with "
            "any one range left out): each range would be off by its rate times the offset, up "
            "to 0.8 m per millisecond, which the pair differences do not cancel. Causes: a "
            "converter that shifted the time tags, or a receiver clock offset applied to the "
            "tags and not to the ranges (or the reverse: RINEX 'RCV CLOCK OFFS APPL'), or a "
            f"clock jump written into one only. Convert the file again from the receiver's raw "
            f"data.{scale}"
        )
    return off
