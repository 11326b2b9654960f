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
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from locator.corrections import RangeModel
from locator.observations import Observations
from locator.spp import PositionFix, solve_epoch
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
receivers gave medians within 0.6 ms (``docs/observations.md``)."""

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
    """Time-tag offset of one solved epoch, with its standard deviation.

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
        ``t_tag - P / c + delta``, seconds. NaN without a solution, with fewer than two ranges
        beyond the unknowns (position, one clock per system, the offset), or when the
        residuals stand more than 3 times above the weights' sigma (a faulty range).
    """
    fit = _fit(model, fix)
    if fit is None:
        return float("nan"), float("nan")
    return _evidence(fit)[:2]


def _evidence(fit: _Fit) -> tuple[float, float, bool]:
    """An epoch's offset, its sigma and whether only an offset explains the ranges; NaN when
    the epoch is no evidence on the tags.

    Three hypotheses: no offset and no fault (four states, every range), an offset (five
    states), one faulty range and no offset (four states, a range left out). An epoch the
    first explains shows no offset beyond its noise (its five-state estimate is kept, not
    counted as a detection); one that only the second explains detects an offset; one that a
    faulty range explains as well says nothing on the tags (a bias of 10 m on one of 7
    satellites reads as an offset of -5.5 ms: a review's, which refused the file).
    """
    nan = float("nan")
    if fit.redundant < _MIN_REDUNDANT or fit.scale > _MAX_SCALE:
        return nan, nan, False
    if not fit.plain_fits and fit.one_fault_fits:
        return nan, nan, False
    return fit.delta_s, float(np.sqrt(fit.var_s2 * fit.scale)), not fit.plain_fits


@dataclass(frozen=True)
class _Fit:
    """An epoch's five-state fit and how the four-state hypotheses fit the same ranges."""

    delta_s: float  # the offset
    var_s2: float  # its variance from the weights
    scale: float  # the residuals' variance factor (at least 1)
    redundant: int  # ranges beyond the five-state unknowns
    plain_fits: bool  # four states, every range: residuals within the model
    one_fault_fits: bool  # four states with one range left out fit


def _fit(model: RangeModel, fix: PositionFix) -> _Fit | None:
    """The five-state fit of a solved epoch and the four-state alternatives; None when not
    solvable."""
    cr = fix.ranges
    if not fix.ok or cr is None:
        return None
    use = np.isin(np.asarray(cr.states.sats), fix.sats_used)
    sats = [s for s, u in zip(cr.states.sats, use, strict=True) if u]
    systems = sorted({s[0] for s in sats})
    n = len(sats)
    if n < 4 + len(systems) + 1:  # position, clocks, the offset, and one redundant range
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
    full = _solve(h, w, y)
    if full is None:
        return None
    plain = _solve(h[:, :-1], w, y)  # the offset left out: x, y, z and the clocks
    plain_fits = plain is not None and plain[2] <= _MAX_SCALE
    one_fault = False
    if not plain_fits:
        for j in range(n):
            others = np.arange(n) != j
            alt = _solve(h[others][:, :-1], w[others], y[others])
            if alt is not None and alt[2] <= _MAX_SCALE:
                one_fault = True
                break
    return _Fit(full[0], full[1], full[2], n - h.shape[1], plain_fits, one_fault)


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
        Each epoch's offset and its standard deviation, seconds.
    detected : ndarray of bool, shape (n,)
        Only an offset explains the epoch's ranges (neither none, nor one faulty range).
    """

    gps_s: NDArray
    offset_s: NDArray
    sigma_s: NDArray
    detected: NDArray

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
        """Epochs that detect an offset beyond ``min_s`` and 4 of their sigmas, (k,)."""
        return np.asarray(self.gps_s)[self._off(min_s)]

    def detected_median_s(self, min_s: float = MAX_TAG_OFFSET_S) -> float:
        """Median offset of the epochs of :meth:`jumps`, seconds (NaN without one)."""
        off = np.asarray(self.offset_s)[self._off(min_s)]
        return float(np.median(off)) if len(off) else float("nan")

    def _off(self, min_s: float) -> NDArray:
        x = np.abs(np.asarray(self.offset_s))
        return np.asarray(self.detected, bool) & (x > min_s) & (
            x > _MIN_SIGNIFICANCE * np.asarray(self.sigma_s)
        )


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
    hx = obs.header.approx_position_ecef_m
    x0: NDArray | None = hx if np.all(np.isfinite(hx)) and np.linalg.norm(hx) > 6e6 else None
    rows = []
    for i in np.asarray(epochs, int):
        have = np.isfinite(sel.pseudorange_m[i]) & wanted
        if not have.any():
            continue
        sats = [s for s, h in zip(obs.sats, have, strict=True) if h]
        t, shift = float(obs.gps_s[i]), 0.0
        first: _Fit | None = None
        # the range rates are a linearisation: an offset of seconds (a time scale mixed up)
        # is found by moving the tag and solving again; the hypotheses are judged at the tag
        for _ in range(_ITERATIONS):
            fix = solve_epoch(m, t + shift, sats, sel.pseudorange_m[i, have],
                              list(sel.code[i, have]), x0_ecef_m=x0)  # fmt: skip
            fit = _fit(m, fix) if fix.ok else None
            if fit is None:
                break
            first = first or fit
            x0 = fix.ecef_m
            shift += fit.delta_s
            if abs(fit.delta_s) < _CONVERGED_S:
                d, sd, found = _evidence(replace(
                    fit, delta_s=shift, plain_fits=first.plain_fits,
                    one_fault_fits=first.one_fault_fits,
                ))  # fmt: skip
                if np.isfinite(d) and np.isfinite(sd):
                    rows.append((t, d, sd, float(found)))
                break
    arr = np.array(rows, float).reshape(-1, 4)
    return TagOffsets(arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3] > 0.5)


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
        When three of the sampled epochs detect an offset (:meth:`TagOffsets.jumps`: only an
        offset explains their ranges) beyond ``max_offset_s`` and 4 of their own sigmas
        (about 6e-5 per epoch without one), in the whole file or in part of it.
    """
    n = len(obs.gps_s)
    idx = np.unique(np.linspace(0, max(n - 1, 0), min(n_epochs, n)).astype(int))
    off = tag_offsets(model, obs, idx, constellation)
    if not len(off.offset_s):
        return off
    jumps = off.jumps(max_offset_s)
    if len(jumps) >= _MIN_JUMPS:
        med = off.detected_median_s(max_offset_s)
        n_ok = len(off.offset_s)
        what = (
            f"by {med * 1e3:+.1f} ms (the median of the {len(jumps)} of {n_ok} sampled epochs "
            f"that show it"
            + ("" if len(jumps) > n_ok // 2 else f", from gps_s {jumps[0]:.0f}: a jump in the file")
            + ")"
        )
        seconds = abs(med) > 5.0 and abs(med - round(med)) < 0.05  # GPS - UTC >= 11 s since 1996
        scale = (
            f" About {round(med):+d} s is a time scale mixed up: UTC, GLONASS or BeiDou time "
            "read as GPS time (GPS - UTC = 18 s since 2017, GPS - BDT = 14 s; the time system "
            "of the header's TIME OF FIRST OBS)."
            if seconds
            else ""
        )
        raise ValueError(
            f"{label}: the epochs' time tags disagree with their pseudoranges {what}; only "
            f"offsets within {max_offset_s * 1e3:g} ms are accepted. The satellites' range rates "
            "show it (no single faulty range explains these epochs): each range would be off by "
            "its rate times the offset, metres per millisecond that the pair differences do not "
            "cancel. Causes: a converter that shifted the time tags, or a "
            "receiver clock offset applied to the tags and not to the ranges (or the reverse: "
            "RINEX 'RCV CLOCK OFFS APPL'), or a clock jump written into one only. Convert the "
            f"file again from the receiver's raw data.{scale}"
        )
    return off
