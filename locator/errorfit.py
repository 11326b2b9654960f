"""Learning the elevation-dependent error model from data with known truth (``locator calibrate``).

The source (LOCOPROL) learns ``sigma(el)`` from measurements where the position is known. The
residual of a corrected pseudorange at the true antenna position is
``rho - |x_true - S| = clock + error``; :func:`locator.intervals.fit_error_model` removes the
clock per epoch and fits ``sigma(el)**2 = a**2 + (b / sin el)**2``. Two kinds of data:

* :func:`sim_residuals` - a simulated run; by default only the signals the masks are meant to
  leave (direct, ``los``: noise and code multipath), since a mask-aware locator never uses NLOS
  by design; ``states=("los", "nlos")`` learns what a maskless receiver sees;
* :func:`static_residuals` - a static station's RINEX file and its known position (a geodetic
  marker): real noise, multipath and broadcast-model errors.

:func:`station_residuals` and :func:`simulated_residuals` wrap them with what the data is
(:class:`Residuals`: satellites, codes, :class:`~predisat.gnss.errormodel.ReceiverProfile`);
:func:`fit_systems` fits and overbounds each constellation on its own and
:func:`model_file_parts` turns the fits into what an error-model file states (per-system
models, their sample sizes and the tail probability they were checked to, the applicability).
:func:`receiver_profile` describes a RINEX source the same way, for the check that a model
applies (``locator run``). :func:`binned_sigma` gives the empirical sigma per elevation bin for
the figure.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.intervals import (
    Overbound,
    fit_error_model,
    overbound_error_model,
    usable_residuals,
)
from locator.observations import Observations
from locator.sim.simfile import SignalState, SimRun
from locator.sources import RinexSource
from predisat.availability.satellites import select_satellites
from predisat.geodesy import ecef_to_geodetic, enu_rotation, enu_to_azel
from predisat.gnss.errormodel import (
    MIN_FIT_RESIDUALS,
    Applicability,
    ErrorModel,
    IntervalModel,
    ReceiverProfile,
    SystemModel,
    name_key,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "Residuals",
    "SystemFit",
    "binned_sigma",
    "calibration_figure",
    "fit_systems",
    "guess_receiver_class",
    "model_file_parts",
    "receiver_profile",
    "sim_residuals",
    "simulated_profile",
    "simulated_residuals",
    "static_residuals",
    "station_evidence",
    "station_residuals",
]

_STATES = {"los": SignalState.LOS, "nlos": SignalState.NLOS}


def sim_residuals(sim: SimRun, states: Sequence[str] = ("los",)) -> tuple[NDArray, NDArray]:
    """Elevations and residuals ``corrected - true range`` of a simulated run.

    Returns
    -------
    el_deg, residual_m : ndarray, shape (n_epoch, n_sat)
        NaN where the signal is not of ``states``.
    """
    bad = [s for s in states if s not in _STATES]
    if bad or not states:
        raise ValueError(f"states must be among {sorted(_STATES)}, got {list(states)}")
    take = np.isin(sim.state, [_STATES[s] for s in states])
    el = np.where(take, sim.el_deg, np.nan)
    res = np.where(take, sim.corrected_m - sim.range_m, np.nan)
    return el, res


def static_residuals(
    source: RinexSource, station_ecef_m: ArrayLike, min_el_deg: float = 5.0
) -> tuple[NDArray, NDArray]:
    """Elevations and residuals of a static station at its known position.

    Parameters
    ----------
    source : RinexSource
        Observations and broadcast model (its ``constellation`` selects the systems).
    station_ecef_m : array_like, shape (3,)
        Known antenna reference point, ECEF metres.
    min_el_deg : float
        Lower elevations are left out.

    Returns
    -------
    el_deg, residual_m : ndarray, shape (n_epoch, n_sat_of_source)
    """
    x = np.asarray(station_ecef_m, float).reshape(3)
    obs: Observations = source.obs
    names = list(obs.sats)
    col = {s: k for k, s in enumerate(names)}
    el = np.full((len(obs.gps_s), len(names)), np.nan)
    res = np.full_like(el, np.nan)
    lat, lon, _ = ecef_to_geodetic(x)
    rot = enu_rotation(lat, lon)
    for k in range(len(obs.gps_s)):
        d = source.observe(k, x)
        if not d.sats:
            continue
        rng = np.linalg.norm(d.sat_ecef_m - x, axis=-1)
        _, e, _ = enu_to_azel((d.sat_ecef_m - x) @ rot.T)
        j = [col[s] for s in d.sats]
        keep = e >= min_el_deg
        el[k, j] = np.where(keep, e, np.nan)
        res[k, j] = np.where(keep, d.pseudorange_m - rng, np.nan)
    return el, res


# Receiver names or programs of smartphone logs (GnssLogger and its RINEX converters, the phone
# makers' names that loggers copy into the receiver type; not Motorola, whose Oncore receivers
# are no phones, nor Geo++, whose reference-network software writes station files).
_PHONE_MARKS = ("GNSSLOGGER", "GNSSTORINEX", "ANDROID", "PIXEL", "GALAXY", "SAMSUNG",
                "XIAOMI", "HUAWEI", "ONEPLUS", "NEXUS")  # fmt: skip

# Receiver types (IGS names, as in its rcvr_ant.tab) that only reference stations and geodetic
# surveys carry: their residuals are a fixed, open-sky antenna's.
_STATION_RECEIVERS = ("TRIMBLE NETR", "TRIMBLE ALLOY", "TRIMBLE 4000", "TRIMBLE 4700",
                      "TRIMBLE 5700", "SEPT POLARX", "LEICA GR", "LEICA GMX", "LEICA RS",
                      "LEICA SR", "JAVAD TRE", "JAVAD DELTA", "JPS LEGACY", "JPS E_GGD",
                      "TPS NETG", "TPS NET-G", "TPS ODYSSEY", "ASHTECH UZ", "ASHTECH Z-XII",
                      "AOA BENCHMARK", "AOA SNR", "ROGUE")  # fmt: skip


def station_evidence(receiver_type: str) -> str:
    """Why a RINEX header is a reference station's (its receiver type is one only such stations
    carry), ``""`` when nothing says so. Such data cannot stand for an automotive receiver's
    errors. ``MARKER TYPE GEODETIC`` alone is no evidence: it describes the monument, and an
    automotive receiver calibrated on a surveyed pillar stands on one (a review)."""
    rec = " ".join(receiver_type.upper().split())
    if rec.startswith(_STATION_RECEIVERS):
        return f"receiver {receiver_type.strip()!r}, a reference-station receiver"
    return ""


# Receiver types of mass-market chips (cars, trackers, low-cost rovers): never a geodetic receiver.
_MASS_MARKET_MARKS = ("UBLOX", "U-BLOX", "TESEO", "BROADCOM", "QUALCOMM", "MEDIATEK", "SIRF",
                      "QUECTEL",
                      # u-blox parts named without the maker (RTKLIB and converters write the
                      # module's name: ZED-F9P, UBX-M8030, NEO-M8T), and other low-cost chips
                      "UBX-", "ZED-F9", "NEO-M", "NEO-6", "NEO-7", "MAX-M", "LEA-M", "LEA-6",
                      "SKYTRAQ", "ALLYSTAR", "BCM47", "MTK")  # fmt: skip


def not_geodetic_evidence(receiver_type: str) -> str:
    """Why a RINEX header cannot be taken as a geodetic receiver's when the user declares it
    (``""``: nothing against it). A geodetic-class model applies to any receiver declared
    geodetic by its class alone: a blank or ``Unknown`` receiver type (as phone converters and
    RTKLIB without ``-hr`` write) or a mass-market chip would get a reference station's sigma
    (a user trial: both claimed 100 % under a one-station class model)."""
    rec = " ".join(receiver_type.upper().split())
    if rec in {"", "NONE", "-", "?", "N/A", "NA"} or rec.startswith("UNKNOWN"):
        return f"its receiver type is {receiver_type.strip() or 'blank'!r}"
    if any(m in rec for m in _MASS_MARKET_MARKS):
        return f"receiver {receiver_type.strip()!r}, a mass-market chip"
    return ""


def guess_receiver_class(receiver_type: str, program: str = "") -> str:
    """``"phone"`` for a smartphone log (by the receiver or program name), else "" (a
    geodetic or automotive receiver is not recognisable by its name: say so explicitly)."""
    text = f"{receiver_type} {program}".upper()
    return "phone" if any(m in text for m in _PHONE_MARKS) else ""


def receiver_profile(
    source: RinexSource, receiver_class: str | None = None, frequency: str | None = None
) -> ReceiverProfile:
    """What a RINEX source is: receiver and antenna (header), the pseudorange codes it gives
    each system used (the code priority's choice over the whole file; ``"C1C+C2W"`` for an
    ionosphere-free pair), the processing.

    ``receiver_class`` None guesses it (:func:`guess_receiver_class`); ``frequency`` None
    takes the source's (``RinexSource.frequency``).
    """
    obs = source.obs
    table = source.code_table
    keep = set(select_satellites(obs.sats, source.constellation))
    codes: dict[str, set[str]] = {}
    for j, sat in enumerate(obs.sats):
        if sat not in keep:
            continue
        used = {str(c) for c in np.unique(table[:, j]) if c}
        if used:
            codes.setdefault(sat[0], set()).update(used)
    if frequency is None:
        frequency = source.frequency
    h = obs.header
    cls = (
        guess_receiver_class(h.receiver_type, h.program)
        if receiver_class is None
        else receiver_class
    )
    return ReceiverProfile(
        h.receiver_type, h.antenna_type, {k: tuple(sorted(v)) for k, v in codes.items()},
        frequency, cls,
    )  # fmt: skip


def simulated_profile(systems: Sequence[str]) -> ReceiverProfile:
    """A simulated receiver using ``systems`` (the simulator has no signal codes: ``sim``)."""
    return ReceiverProfile("simulated", "simulated", {s: ("sim",) for s in systems}, "single",
                           "simulated")  # fmt: skip


@dataclass(frozen=True)
class Residuals:
    """Residuals of one data set and what it is.

    Attributes
    ----------
    el_deg, residual_m : ndarray, shape (n_epoch, n_sat)
        As :func:`static_residuals`; NaN where absent.
    sats : tuple of str, length n_sat
    profile : ReceiverProfile
    source : str
        The file or folder, for the model's record.
    """

    el_deg: NDArray
    residual_m: NDArray
    sats: tuple[str, ...]
    profile: ReceiverProfile
    source: str


def _columns(data: Residuals, letters: Sequence[str]) -> tuple[NDArray, NDArray]:
    """``(el_deg, residual_m)`` of the columns of the systems ``letters``."""
    cols = np.array([s[0] in letters for s in data.sats], bool)
    return data.el_deg[:, cols], data.residual_m[:, cols]


def station_residuals(
    source: RinexSource,
    station_ecef_m: ArrayLike,
    *,
    min_el_deg: float = 5.0,
    receiver_class: str | None = None,
) -> Residuals:
    """:func:`static_residuals` with the satellites, codes and receiver of the source."""
    el, res = static_residuals(source, station_ecef_m, min_el_deg)
    profile = receiver_profile(source, receiver_class)
    return Residuals(el, res, tuple(source.obs.sats), _codes_with_residuals(source, profile, res),
                     str(source.obs.path))  # fmt: skip


def _codes_with_residuals(
    source: RinexSource, profile: ReceiverProfile, residual_m: NDArray
) -> ReceiverProfile:
    """``profile`` naming, per system, only the codes the residuals calibrate: those with at
    least :data:`MIN_FIT_RESIDUALS` residuals, or at least half of the system's.

    A code the file used at a few epochs was named calibrated with next to no residuals behind
    it (a trial: NYA1's ``C1C+C2X``, 8 residuals of 16 361, then let an L1/L2C-only run claim
    under a model whose tails never saw L2C's inter-signal bias)."""
    obs = source.obs
    code = source.code_table
    have = np.isfinite(residual_m)
    kept: dict[str, tuple[str, ...]] = {}
    for sys_, codes in profile.codes.items():
        cols = np.array([s[0] == sys_ for s in obs.sats], bool)
        n_sys = int(have[:, cols].sum())
        counts = {c: int((have[:, cols] & (code[:, cols] == c)).sum()) for c in codes}
        keep = tuple(c for c in codes
                     if counts[c] >= MIN_FIT_RESIDUALS or 2 * counts[c] >= n_sys > 0)  # fmt: skip
        if keep:
            kept[sys_] = keep
    return replace(profile, codes=kept)


def simulated_residuals(
    sim: SimRun, states: Sequence[str] = ("los",), source: str = ""
) -> Residuals:
    """:func:`sim_residuals` of a simulated run with its (simulated) receiver."""
    el, res = sim_residuals(sim, states)
    systems = sorted({s[0] for s in sim.sats})
    return Residuals(el, res, tuple(sim.sats), simulated_profile(systems), source)


@dataclass(frozen=True)
class SystemFit:
    """The fit of one constellation over every data set given.

    Attributes
    ----------
    system : str
    estimate : ErrorModel
        Least-squares fit (:func:`locator.intervals.fit_error_model`).
    overbound : Overbound or None
        Its tail overbound (None for ``bound="estimate"``).
    codes : tuple of str
    n_residuals : int
    el_min_deg, el_max_deg : float
    pair_factors : tuple of (receiver, antenna, factor)
        Of a fit over several receiver x antenna pairs: each pair's own tail check against
        the pooled overbound (:func:`_pair_checked`), the inflation it needed (1: bounded);
        the overbound holds the largest. Empty for one pair, or an estimate.
    """

    system: str  # the letters fitted together ("G"; "GREC" pooled)
    estimate: ErrorModel
    overbound: Overbound | None
    codes: tuple[str, ...]
    n_residuals: int
    el_min_deg: float
    el_max_deg: float
    pair_factors: tuple[tuple[str, str, float], ...] = ()

    @property
    def model(self) -> ErrorModel:
        """The overbound's model, or the estimate."""
        return self.estimate if self.overbound is None else self.overbound.model

    def system_model(self) -> SystemModel:
        """What the file states about this system."""
        ob = self.overbound
        n_ind = self.n_residuals if ob is None else ob.n_independent
        tail = float("nan") if ob is None else ob.tail_probability
        return SystemModel(self.model, self.codes, self.n_residuals, n_ind, tail)


def _stack(parts: Sequence[tuple[NDArray, NDArray]]) -> tuple[NDArray, NDArray]:
    """Epoch rows of several ``(el_deg, residual_m)`` pairs, padded with NaN to one width."""
    n = max(p[0].shape[1] for p in parts)

    def wide(a: NDArray) -> NDArray:
        return np.pad(a, ((0, 0), (0, n - a.shape[1])), constant_values=np.nan)

    return (np.concatenate([wide(p[0]) for p in parts]),
            np.concatenate([wide(p[1]) for p in parts]))  # fmt: skip


def fit_systems(
    data: Sequence[Residuals],
    *,
    bound: str = "overbound",
    confidence: float | None = 0.95,
    n_bins: int = 6,
    pool_systems: bool = False,
) -> dict[str, SystemFit]:
    """Fit (and overbound) each constellation of ``data`` on its own.

    Parameters
    ----------
    data : sequence of Residuals
        Every data set the model is to cover (several receivers, days, sites).
    bound : {"overbound", "estimate"}
    confidence : float or None
        Of the tail check (:func:`locator.intervals.overbound_error_model`): each one-sided
        tail against the Clopper-Pearson bound of its share in independent samples; None:
        the empirical two-sided share.
    n_bins : int
        Elevation bins of the overbound.
    pool_systems : bool
        Fit every system together and give each the pooled model: only for data whose
        systems share one clock and one error law (a simulation); real receivers have
        inter-system biases and per-system errors.

    Returns
    -------
    dict
        System letter to :class:`SystemFit`; systems with too few residuals for the fit are
        left out (a model then does not cover them).
    """
    if bound not in ("overbound", "estimate"):
        raise ValueError(f"bound must be 'overbound' or 'estimate', got {bound!r}")
    if not data:
        raise ValueError("fit_systems needs at least one data set")
    out: dict[str, SystemFit] = {}
    letters = sorted({s[0] for d in data for s in d.sats})
    groups = [("".join(letters), letters)] if pool_systems else [(x, [x]) for x in letters]
    short: list[str] = []
    for key, group in groups:
        parts = [_columns(d, group) for d in data if any(s[0] in group for s in d.sats)]
        el, res = _stack(parts)
        ok = np.isfinite(el) & np.isfinite(res)
        # the residuals the fit uses: counted and ranged by the same rule (a review: the
        # count took epochs with 1-2 satellites of the system in, which the fit leaves out)
        use = usable_residuals(el, res)
        try:
            est = fit_error_model(el, res)
            ob = (overbound_error_model(el, res, est, n_bins=n_bins, confidence=confidence)
                  if bound == "overbound" else None)  # fmt: skip
        except ValueError:
            # too few residuals in epochs with 3 satellites of the system: say how many (not
            # of a file's systems that were not chosen, which have none: a user trial's
            # message named C, J, R, S for a gps+galileo calibration)
            if ok.any():
                short.append(f"{key} {int(use.sum())} in {int(use.any(axis=1).sum())} epochs")
            continue
        pair_factors: tuple[tuple[str, str, float], ...] = ()
        if ob is not None and not pool_systems:
            ob, pair_factors = _pair_checked(data, group, ob, n_bins, confidence)
        for sys_ in group:
            # a pooled fit covers only the systems it saw: a simulation's satellites never in
            # view (QZSS in Belgium) got the pooled model and its count (a docs audit)
            if not any(np.isfinite(_columns(d, [sys_])[1]).any() for d in data):
                continue
            codes = sorted({c for d in data for c in d.profile.codes.get(sys_, ())})
            out[sys_] = SystemFit(key, est, ob, tuple(codes), int(use.sum()),
                                  float(el[use].min()), float(el[use].max()),
                                  pair_factors)  # fmt: skip
    if not out:
        # overbound_error_model: min_tail 10 in a tail share of at most 0.32 of each bin
        need = MIN_FIT_RESIDUALS * n_bins // 6 if bound == "overbound" else 2 * n_bins
        raise ValueError(
            f"no system has enough residuals in epochs with 3 satellites of it for the fit"
            f"{' and its overbound' if bound == 'overbound' else ''} (residuals: "
            f"{'; '.join(short) or 'none'}; about {need} needed per system) in "
            f"{', '.join(Path(d.source).name for d in data)}; give "
            "more or longer data sets"
        )
    return out


def _pair_checked(
    data: Sequence[Residuals], group: Sequence[str], ob: Overbound, n_bins: int,
    confidence: float | None,
) -> tuple[Overbound, tuple[tuple[str, str, float], ...]]:  # fmt: skip
    """The pooled overbound ``ob`` inflated until it also bounds each receiver x antenna pair's
    own tails, and each pair's factor.

    A pooled tail check counts mostly the larger data set: a smaller station with heavier tails
    stood under a bound its own residuals exceed, and the model applies to it by name (a
    review, stops 49-50). Each pair is checked on its own against the pooled model, at the
    same confidence (its own, smaller, sample); a pair with too few residuals for a check
    (fewer than a fit needs, ``MIN_FIT_RESIDUALS``) is not covered by name anyway.
    """
    pairs: dict[tuple[str, str], list[tuple[NDArray, NDArray]]] = {}
    for d in data:
        if any(s_[0] in group for s_ in d.sats):
            # the names as a run matches them (Applicability: case and blanks ignored), so a
            # pair spelled two ways is checked on all its residuals
            key = (name_key(d.profile.receiver_type), name_key(d.profile.antenna_type))
            pairs.setdefault(key, []).append(_columns(d, group))
    if len(pairs) < 2:
        return ob, ()
    out: list[tuple[str, str, float]] = []
    factor = 1.0
    for (rec, ant), parts in sorted(pairs.items()):
        el, res = _stack(parts)
        try:
            own = overbound_error_model(el, res, ob.model, n_bins=n_bins, confidence=confidence)
        except ValueError:  # too few residuals for a tail check of its own
            continue
        out.append((rec, ant, float(own.factor)))
        factor = max(factor, float(own.factor))
    if factor > 1.0:
        m = ob.model
        ob = replace(
            ob, model=ErrorModel(m.a_m * factor, m.b_m * factor, m.min_el_deg),
            factor=ob.factor * factor,
        )  # fmt: skip
    return ob, tuple(out)


def model_file_parts(
    fits: Mapping[str, SystemFit],
    data: Sequence[Residuals],
    *,
    k_sigma: float,
    receiver_class: str = "",
    method: str = "overbound",
) -> tuple[IntervalModel, dict[str, SystemModel], Applicability]:
    """The envelope model, the per-system models and the applicability of a model file.

    The envelope (largest ``a`` and ``b`` over the systems) is what a reader of the
    ``locator-error-model/1`` fields (``predisat availability``) sees.
    """
    ms = [f.model for f in fits.values()]
    env = ErrorModel(max(m.a_m for m in ms), max(m.b_m for m in ms),
                     max(m.min_el_deg for m in ms))  # fmt: skip
    freq = {d.profile.frequency for d in data}
    if len(freq) > 1:
        raise ValueError("data sets mix single- and dual-frequency processing: calibrate apart")
    # each receiver x antenna combination with the systems, codes and residuals it gave
    combos: dict[tuple[str, str], dict[str, tuple[set[str], int]]] = {}
    for d in data:
        per = combos.setdefault((d.profile.receiver_type, d.profile.antenna_type), {})
        for sys_ in fits:
            el_s, res = _columns(d, [sys_])
            if np.isfinite(res).any():
                # counted as a tail check counts them (epochs with >= 3 of the system's
                # satellites): a pair whose own check could not run is then not covered by
                # name (Applicability refuses fewer than MIN_FIT_RESIDUALS)
                n = int(usable_residuals(el_s, res).sum())
                codes, n0 = per.get(sys_, (set(), 0))
                per[sys_] = (codes | set(d.profile.codes.get(sys_, ())), n0 + n)
    pairs = tuple(
        (r, a, tuple((s_, tuple(sorted(c)), n) for s_, (c, n) in sorted(per.items())))
        for (r, a), per in sorted(combos.items())
    )
    lo, hi = max(f.el_min_deg for f in fits.values()), min(f.el_max_deg for f in fits.values())
    if not lo < hi:
        ranges = ", ".join(f"{k} {f.el_min_deg:.1f}-{f.el_max_deg:.1f}" for k, f in
                           sorted(fits.items()))  # fmt: skip
        raise ValueError(
            f"the systems were fitted on elevation ranges with nothing in common ({ranges} "
            "deg): one model cannot serve them together; calibrate each constellation apart "
            "(--constellation)"
        )
    app = Applicability(
        tuple(sorted({d.profile.receiver_type for d in data})),
        tuple(sorted({d.profile.antenna_type for d in data})),
        receiver_class,
        freq.pop(),
        # the elevations every system was fitted on: one range serves all systems in a run
        # (a pooled model's GPS, fitted up to 72.7 deg, took satellites up to Galileo's 75.8)
        lo,
        hi,
        method,
        tuple(d.source for d in data),
        pairs,
    )
    return (IntervalModel(env, k_sigma), {k: f.system_model() for k, f in fits.items()}, app)


def binned_sigma(
    el_deg: ArrayLike, residual_m: ArrayLike, edges_deg: ArrayLike | None = None
) -> pd.DataFrame:
    """Empirical sigma of clock-free residuals per elevation bin.

    The clock is removed per epoch by the median of the residuals (robust, independent of any
    model), so the figure checks the fit rather than repeating it.

    Returns
    -------
    pandas.DataFrame
        ``el_lo_deg``, ``el_hi_deg``, ``el_mid_deg``, ``n``, ``sigma_m`` (RMS).
    """
    el = np.asarray(el_deg, float)
    r = np.asarray(residual_m, float)
    ok = np.isfinite(el) & np.isfinite(r)
    ok &= ok.sum(axis=1, keepdims=True) >= 4
    clock = np.zeros((len(r), 1))
    rows_ok = ok.any(axis=1)
    clock[rows_ok, 0] = np.nanmedian(np.where(ok, r, np.nan)[rows_ok], axis=1)
    e = (r - clock)[ok]
    eln = el[ok]
    edges = np.arange(0.0, 91.0, 5.0) if edges_deg is None else np.asarray(edges_deg, float)
    rows = []
    for a, b in itertools.pairwise(edges):
        sel = (eln >= a) & (eln < b)
        if sel.sum() >= 10:
            rows.append((a, b, 0.5 * (a + b), int(sel.sum()), float(np.sqrt(np.mean(e[sel] ** 2)))))
    return pd.DataFrame(rows, columns=["el_lo_deg", "el_hi_deg", "el_mid_deg", "n", "sigma_m"])


def calibration_figure(
    table: pd.DataFrame, model: ErrorModel, title: str = "", estimate: ErrorModel | None = None
) -> Figure:
    """Binned empirical sigma against the model's ``sigma(el)`` (and the estimate it bounds)."""
    # lazy: matplotlib only for this figure; the residual functions must not import it
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.subplots()
    ax.plot(table["el_mid_deg"], table["sigma_m"], "o", label="residual RMS per 5 deg bin")
    el = np.linspace(max(model.min_el_deg, 2.0), 90.0, 200)
    name = "model" if estimate is None else "overbound"
    ax.plot(el, model.sigma_m(el), "-",
            label=f"{name}: a = {model.a_m:.2f} m, b = {model.b_m:.2f} m")  # fmt: skip
    if estimate is not None:
        ax.plot(el, estimate.sigma_m(el), "--", color="0.5",
                label=f"fit: a = {estimate.a_m:.2f} m, b = {estimate.b_m:.2f} m")  # fmt: skip
    ax.set_xlabel("elevation (deg)")
    ax.set_ylabel("pseudorange sigma (m)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title or "Error model")
    return fig
