"""The pseudorange error model ``sigma(el)``, the pair-interval width, and error-model files.

:class:`ErrorModel` is the elevation-dependent pseudorange error that the availability
prediction (:mod:`predisat.availability.interval`) and the locator (``locator``) share;
:class:`IntervalModel` adds the width ``k_sigma`` of each satellite-pair interval.

An error-model file (``locator calibrate --out FILE.json``, format :data:`ERROR_MODEL_FORMAT`)
is a JSON object with the envelope model of every system (``a_m``, ``b_m``, ``min_el_deg``,
``k_sigma``; what ``predisat availability`` reads), ``systems`` (per system letter its own
``a_m``, ``b_m``, the pseudorange codes, the number of residuals and of independent samples and
the tail probability the overbound was checked to), ``applicability`` (:class:`Applicability`:
receivers, antennas, receiver class, processing, elevation range, method, inputs) and
``fitted`` (information only). A model applies to a data set (:class:`ReceiverProfile`) only
when :meth:`Applicability.mismatches` finds nothing; a ``locator-error-model/1`` file has no
applicability block and applies to nothing unless the user forces it.
:func:`read_error_model_file` reads both formats, :func:`read_error_model` the envelope alone.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat import __version__
from predisat.atomic import write_bytes_atomic
from predisat.jsontypes import strict_json_text

__all__ = [
    "ERROR_MODEL_FORMAT",
    "ERROR_MODEL_FORMAT_V1",
    "MIN_FIT_RESIDUALS",
    "RECEIVER_CLASSES",
    "SIMULATOR_METHOD",
    "Applicability",
    "ErrorModel",
    "ErrorModelFile",
    "ErrorModelFileError",
    "IntervalModel",
    "ReceiverProfile",
    "SystemModel",
    "default_model_file",
    "name_key",
    "read_error_model",
    "read_error_model_file",
    "write_error_model",
]

ERROR_MODEL_FORMAT = "locator-error-model/2"
ERROR_MODEL_FORMAT_V1 = "locator-error-model/1"  # no applicability: applies to nothing unforced

# Receiver classes a model or a data set may name ("" when unknown).
RECEIVER_CLASSES = ("geodetic", "automotive", "phone", "simulated")
MIN_FIT_RESIDUALS = 6 * math.ceil(10 / 0.32)
"""Residuals of one system below which no overbound can be fitted (6 elevation bins, each
with 10 samples in a tail share of at most 0.32: ``locator.intervals.overbound_error_model``'s
defaults): a receiver of a pooled model that gave fewer is not covered by name."""
FREQUENCY_MODES = ("single", "dual")


class ErrorModelFileError(ValueError):
    """An error-model file that cannot be read; the message names the file and the fix."""


@dataclass(frozen=True)
class ErrorModel:
    """Elevation-dependent pseudorange error, ``sigma(el)**2 = a**2 + (b / sin(el))**2``.

    The form is RTKLIB's code/phase variance model; the defaults (a = b = 2 m: 2.8 m at the
    zenith, 3.5 m at 45 deg, 8.0 m at 15 deg, 11.7 m at 10 deg) are of the order of
    single-frequency code errors with broadcast orbits, clocks and ionosphere. They are a
    **model to be learned** (``locator calibrate``), not measured values.

    Attributes
    ----------
    a_m, b_m : float
        Constant and elevation-dependent parts, metres.
    min_el_deg : float
        Elevations below this are treated as this (keeps sigma finite at the horizon).
    """

    a_m: float = 2.0
    b_m: float = 2.0
    min_el_deg: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.a_m) and np.isfinite(self.b_m)):
            raise ValueError(f"ErrorModel a_m, b_m must be finite metres: {self}")
        if self.a_m < 0 or self.b_m < 0 or self.a_m + self.b_m <= 0:
            raise ValueError(f"ErrorModel a_m, b_m must be >= 0, not both 0: {self}")
        if not 0 < self.min_el_deg < 90:
            raise ValueError(f"ErrorModel.min_el_deg must be in (0, 90), got {self.min_el_deg}")

    def sigma_m(self, el_deg: ArrayLike) -> NDArray:
        """Pseudorange sigma in metres, shape of ``el_deg``."""
        el = np.maximum(np.asarray(el_deg, float), self.min_el_deg)
        return self.sigma_from_sin(np.sin(np.radians(el)))

    def sigma_from_sin(self, sin_el: ArrayLike) -> NDArray:
        """The same from ``sin(el)`` (any float dtype, kept), for the vectorised engine."""
        s = np.asarray(sin_el)
        lo = np.sin(np.radians(self.min_el_deg))
        s = np.maximum(s, np.asarray(lo, s.dtype))
        return np.sqrt(self.a_m**2 + (self.b_m / s) ** 2)


@dataclass(frozen=True)
class IntervalModel:
    """Error model plus the width factor of each pair interval.

    Attributes
    ----------
    error : ErrorModel
    k_sigma : float
        Half width of a pair interval in sigmas of ``K``. Default 2 as in the source
        (``+-2 xi``). Note: for Gaussian errors 2 sigma leaves 4.6e-2 outside per pair, not
        the 1e-4 the source claims (that needs 3.89 sigma: :meth:`for_risk`).
    """

    error: ErrorModel = field(default_factory=ErrorModel)
    k_sigma: float = 2.0

    def __post_init__(self) -> None:
        if not (self.k_sigma > 0 and np.isfinite(self.k_sigma)):
            raise ValueError(
                f"IntervalModel.k_sigma must be positive and finite, got {self.k_sigma} "
                "(the source's 2; 3.89 gives 1e-4 per pair)"
            )

    @classmethod
    def for_risk(cls, risk_per_pair: float, error: ErrorModel | None = None) -> IntervalModel:
        """``k_sigma`` giving a two-sided Gaussian risk per pair (1e-4 -> 3.89)."""
        # lazy: scipy.stats is slow to import and only this rarely used constructor needs it
        from scipy.stats import norm

        if not 0 < risk_per_pair < 1:
            raise ValueError(f"risk_per_pair must be in (0, 1), got {risk_per_pair}")
        return cls(error or ErrorModel(), float(norm.isf(risk_per_pair / 2.0)))


def name_key(text: str) -> str:
    """A receiver or antenna name as the model's applicability compares it: without case and
    with its blanks collapsed (``"sept  polarx5 "`` -> ``"SEPT POLARX5"``)."""
    return " ".join(str(text).upper().split())


# Receiver or antenna names that identify nothing (smartphone RINEX writes "Unknown").
_UNKNOWN = {"", "UNKNOWN", "NONE", "-"}
SIMULATOR_METHOD = "simulator noise model"
"""The method of the built-in model: the simulator's own noise, which needs no tail check."""


@dataclass(frozen=True)
class ReceiverProfile:
    """What a data set is, as far as an error model cares.

    Attributes
    ----------
    receiver_type, antenna_type : str
        As in the RINEX header (``REC # / TYPE / VERS``, ``ANT # / TYPE``; the antenna without
        its radome column); ``"simulated"`` for a simulation.
    codes : mapping of system letter to tuple of str
        Pseudorange codes used per system (``{"G": ("C1C",)}``; RINEX 2 ``C1`` as is).
    frequency : {"single", "dual"}
        How the locator combines them: one frequency with the broadcast ionosphere model.
    receiver_class : str
        One of :data:`RECEIVER_CLASSES`, or "" when unknown.
    """

    receiver_type: str
    antenna_type: str
    codes: Mapping[str, tuple[str, ...]]
    frequency: str = "single"
    receiver_class: str = ""

    def __post_init__(self) -> None:
        _check_frequency_and_class(self.frequency, self.receiver_class)

    @property
    def systems(self) -> tuple[str, ...]:
        """System letters used, sorted."""
        return tuple(sorted(self.codes))

    def describe(self) -> str:
        """``"TRIMBLE 5700 / TRM29659.00, G C1"``, for messages; several codes of a system
        ``"G C1C+C2L or C1C+C2W"`` (a dual-frequency pair is itself written with ``+``)."""
        codes = ", ".join(f"{s} {' or '.join(c)}" for s, c in sorted(self.codes.items()))
        cls = f" ({self.receiver_class})" if self.receiver_class else ""
        return f"{self.receiver_type or '?'} / {self.antenna_type or '?'}{cls}, {codes}"


@dataclass(frozen=True)
class SystemModel:
    """The model of one constellation and what supports it.

    Attributes
    ----------
    error : ErrorModel
    codes : tuple of str
        Pseudorange codes calibrated.
    n_residuals : int
        Clock-free residuals used.
    n_independent : int
        Independent samples they amount to (time correlation removed), the count that the tail
        check's confidence uses.
    tail_probability : float
        Smallest two-sided probability per pseudorange at which the Gaussian overbound was
        checked against the data (the risk it bounds; beyond it the Gaussian shape is an
        extrapolation). NaN for a least-squares estimate, which bounds nothing.
    """

    error: ErrorModel
    codes: tuple[str, ...]
    n_residuals: int
    n_independent: int
    tail_probability: float

    def __post_init__(self) -> None:
        # a user trial's hand-edited files were taken as they were: tail_probability 5.0
        # (then blamed on "0 independent samples"), n_independent -5, codes "sim" (three codes)
        if not self.codes or not all(isinstance(c, str) and c for c in self.codes):
            raise ValueError(f"codes must be a list of observation codes, got {self.codes!r}")
        if not 0 <= self.n_independent <= self.n_residuals:
            raise ValueError(
                f"n_independent must lie in [0, n_residuals = {self.n_residuals}], got "
                f"{self.n_independent}"
            )
        p = self.tail_probability
        if not (math.isnan(p) or 0.0 < p <= 1.0):  # 1: nothing checked
            raise ValueError(f"tail_probability must be a probability in (0, 1] or null, got {p}")

    @property
    def k_checked(self) -> float:
        """``k`` of a two-sided Gaussian at :attr:`tail_probability` (NaN without one)."""
        if not 0.0 < self.tail_probability < 1.0:
            return float("nan")
        from scipy.stats import norm  # lazy: slow import, only for messages

        return float(norm.isf(self.tail_probability / 2.0))


@dataclass(frozen=True)
class Applicability:
    """What an error model was calibrated for, and how.

    Attributes
    ----------
    receivers, antennas : tuple of str
        Receiver and antenna types of the calibration data (``REC # / TYPE``, ``ANT # / TYPE``).
    receiver_class : str
        The class the model is meant to cover ("" for the listed receivers only). A model of a
        class applies to any receiver of that class: only when it was validated so (leave one
        receiver out, ``docs/errormodel.md``).
    frequency : {"single", "dual"}
    el_min_deg, el_max_deg : float
        Elevations of the calibration residuals; satellites below ``el_min_deg`` are outside the
        model.
    method : str
        How the model was made (``"overbound"``: :func:`locator.errorfit` tail overbound;
        ``"estimate"``: least squares, no bound).
    sources : tuple of str
        Input files (observations, simulations).
    pairs : tuple of (receiver, antenna, ((system, codes, n_residuals), ...))
        Each receiver x antenna combination calibrated, with the systems, codes and residuals
        it gave. A model pooled over several receivers applies by name only to a combination
        it holds, and only to the codes that combination gave (a user trial: a model of
        receiver A + antenna X and receiver B + antenna Y claimed for B + X; Galileo C1C of
        19 epochs of one station claimed under 998 independent samples of another's C1X).
        Empty in files written before it: such a file applies by name only when it names one
        receiver and one antenna.
    """

    receivers: tuple[str, ...]
    antennas: tuple[str, ...]
    receiver_class: str = ""
    frequency: str = "single"
    el_min_deg: float = 0.0
    el_max_deg: float = 90.0
    method: str = "overbound"
    sources: tuple[str, ...] = ()
    pairs: tuple[tuple[str, str, tuple[tuple[str, tuple[str, ...], int], ...]], ...] = ()

    def __post_init__(self) -> None:
        _check_frequency_and_class(self.frequency, self.receiver_class)
        if not 0.0 <= self.el_min_deg <= self.el_max_deg <= 90.0:
            raise ValueError(
                f"elevation range must satisfy 0 <= el_min_deg <= el_max_deg <= 90, got "
                f"{self.el_min_deg}, {self.el_max_deg}"
            )

    @property
    def _is_simulator(self) -> bool:
        """The simulator's own noise model (no tail to check): its method and its receivers,
        so that a file naming the method for a real receiver does not skip the check."""
        return self.method == SIMULATOR_METHOD and tuple(self.receivers) == ("simulated",)

    def _pair_mismatches(self, profile: ReceiverProfile, rx: str, ant: str) -> list[str]:
        """Why a model matched by name does not hold ``profile``'s receiver x antenna
        combination and codes (the receiver and the antenna are each among the calibrated)."""
        if not self.pairs:
            if len(self.receivers) > 1 or len(self.antennas) > 1:
                return [
                    f"the model pools receivers {sorted(self.receivers)} and antennas "
                    f"{sorted(self.antennas)} without recording which were calibrated together "
                    "(a file of an older locator): calibrate again with `locator calibrate`"
                ]
            return []
        mine = [p for p in self.pairs if name_key(p[0]) == rx and name_key(p[1]) == ant]
        if not mine:
            held = "; ".join(f"{r} / {a}" for r, a, _ in self.pairs)
            return [
                f"receiver {profile.receiver_type!r} with antenna {profile.antenna_type!r} was "
                f"never calibrated together (the model holds {held})"
            ]
        why = []
        for sys_, codes in sorted(profile.codes.items()):
            got = {c for _, _, per in mine for s_, cs, _ in per if s_ == sys_ for c in cs}
            n = sum(n_ for _, _, per in mine for s_, _, n_ in per if s_ == sys_)
            # only codes another pair holds were "calibrated on other receivers" (a code no
            # pair holds is told by mismatches: a trial's dual-frequency run under its own
            # station's single-frequency model was told the codes came from other receivers)
            elsewhere = {c for p in self.pairs for s_, cs, _ in p[2] if s_ == sys_ for c in cs}
            new = sorted((set(codes) - got) & elsewhere)
            if new:
                why.append(
                    f"system {sys_} code(s) {new} were calibrated on other receivers or "
                    f"antennas only ({profile.receiver_type} / {profile.antenna_type} gave "
                    f"{sorted(got) or 'none'}, {n} residuals)"
                )
            elif got and n < MIN_FIT_RESIDUALS:
                # its own data could not have been fitted: the model's sigma and tail check
                # are the other receivers' (a trial: 165 residuals of one station pooled with
                # 32 596 of another)
                why.append(
                    f"system {sys_}: {profile.receiver_type} / {profile.antenna_type} gave "
                    f"only {n} residuals to the pooled model (a fit of its own needs about "
                    f"{MIN_FIT_RESIDUALS}): the model's figures are other receivers'; calibrate "
                    "on more data of this receiver and antenna"
                )
        return why

    def mismatches(self, profile: ReceiverProfile, systems: Mapping[str, SystemModel]) -> list[str]:
        """Why the model does not apply to ``profile`` (empty: it applies).

        The receiver must be one calibrated (by its type; an unknown type never matches a
        name) or of the model's class; the antenna likewise (any antenna for a class model);
        every system used must have a model calibrated on its code whose tails were checked
        (``tail_probability < 1``); an estimate is not an overbound; the processing must match.
        """
        why = []
        rx, ant = name_key(profile.receiver_type), name_key(profile.antenna_type)
        by_class = bool(self.receiver_class) and profile.receiver_class == self.receiver_class
        if not by_class:
            known = {name_key(r) for r in self.receivers} - _UNKNOWN
            if rx in _UNKNOWN or rx not in known:
                why.append(
                    f"receiver {profile.receiver_type or 'unknown'!r} is not among the "
                    f"calibrated {sorted(self.receivers)}"
                    + (f" nor of class {self.receiver_class!r}" if self.receiver_class else "")
                )
            ants = {name_key(a) for a in self.antennas} - _UNKNOWN
            if ant in _UNKNOWN or ant not in ants:
                why.append(
                    f"antenna {profile.antenna_type or 'unknown'!r} is not among the calibrated "
                    f"{sorted(self.antennas)}"
                )
            if not why:
                why.extend(self._pair_mismatches(profile, rx, ant))
        for sys_, codes in sorted(profile.codes.items()):
            m = systems.get(sys_)
            if m is None:
                why.append(f"system {sys_} was not calibrated (model has {sorted(systems)})")
                continue
            new = sorted(set(codes) - set(m.codes))
            if new:
                why.append(f"system {sys_} code(s) {new} not calibrated (model: {list(m.codes)})")
            if m.tail_probability >= 1.0:
                why.append(
                    f"system {sys_}: its {m.n_independent} independent samples were too few to "
                    "check any tail of the overbound (calibrate on more days or receivers)"
                )
            elif not m.tail_probability > 0.0 and not self._is_simulator:
                # NaN (null in the file): nothing says the tails were ever checked
                why.append(
                    f"system {sys_}: the file records no tail check of its model (calibrate "
                    "with `locator calibrate`, which checks the overbound's tails)"
                )
        if self.method == "estimate":
            why.append("a least-squares estimate, not an overbound (calibrate without --bound "
                       "estimate)")  # fmt: skip
        elif self.method != "overbound" and not self._is_simulator:
            why.append(f"method {self.method!r} is not an overbound (calibrate with `locator "
                       "calibrate`)")  # fmt: skip
        if profile.frequency != self.frequency:
            why.append(f"{profile.frequency}-frequency data, {self.frequency}-frequency model")
        return why


@dataclass(frozen=True)
class ErrorModelFile:
    """An error-model file: per-system models, their envelope and what they apply to.

    Attributes
    ----------
    model : IntervalModel
        The envelope of :attr:`systems` (largest ``a`` and ``b``) and ``k_sigma``.
    systems : mapping of system letter to SystemModel
        Empty for a ``locator-error-model/1`` file.
    applicability : Applicability or None
        None for a ``locator-error-model/1`` file (applies to nothing unless forced).
    path : str
        Where it was read from ("" for a built-in model).
    format : str
    """

    model: IntervalModel
    systems: Mapping[str, SystemModel] = field(default_factory=dict)
    applicability: Applicability | None = None
    path: str = ""
    format: str = ERROR_MODEL_FORMAT

    def mismatches(self, profile: ReceiverProfile) -> list[str]:
        """Why the model does not apply to ``profile`` (empty: it applies)."""
        if self.applicability is None:
            return [
                f"{self.path or 'the model'} is a {self.format} file, which does not state what "
                "it was calibrated for"
            ]
        return self.applicability.mismatches(profile, self.systems)

    def depth_shortfall(self, systems: Sequence[str], k_sigma: float) -> list[str]:
        """Why intervals of width ``k_sigma`` claim a smaller risk than ``systems``' models were
        checked to (empty: every one was checked at least that deep).

        A system's tail was checked to :attr:`SystemModel.tail_probability` per pseudorange
        (two-sided ``k`` :attr:`SystemModel.k_checked`); a wider interval rests on the Gaussian
        shape beyond that depth, an extrapolation that heavy tails break
        (``docs/errormodel.md``). A system without a checked depth (NaN: the simulator's own
        noise model, or a least-squares estimate, which :meth:`mismatches` already refuses)
        gives no reason here.

        Parameters
        ----------
        systems : sequence of str
            System letters of the data.
        k_sigma : float
            The widest pair interval's ``k`` a claim may rest on.

        Returns
        -------
        list of str
            One reason per system checked less deep, empty when none.
        """
        if not k_sigma > 0:
            raise ValueError(f"k_sigma must be positive, got {k_sigma}")
        from scipy.stats import norm  # lazy: slow import, only for this check

        need = float(2.0 * norm.sf(k_sigma))  # two-sided probability per pseudorange
        why = []
        for sys_ in sorted(set(systems)):
            m = self.systems.get(sys_)
            if m is None or not 0.0 < m.tail_probability < 1.0 or m.k_checked >= k_sigma:
                continue
            why.append(
                f"system {sys_} was checked to {m.tail_probability:.2g} per pseudorange "
                f"(k {m.k_checked:.3f}, {m.n_independent} independent samples); k {k_sigma:.3f} "
                f"claims {need:.1g}, which needs about {10.0 / need:.2g} independent samples in "
                "each elevation bin"
            )
        return why

    def for_systems(self, systems: Sequence[str]) -> IntervalModel:
        """The envelope model of ``systems`` (all of the file's models when none is known)."""
        ms = [self.systems[s].error for s in systems if s in self.systems]
        if not ms or len(ms) < len(systems):
            return self.model
        env = ErrorModel(max(m.a_m for m in ms), max(m.b_m for m in ms),
                         max(m.min_el_deg for m in ms))  # fmt: skip
        return IntervalModel(env, self.model.k_sigma)

    @property
    def el_min_deg(self) -> float:
        """Lowest calibrated elevation (0 when the file does not say)."""
        return 0.0 if self.applicability is None else self.applicability.el_min_deg

    @property
    def el_max_deg(self) -> float:
        """Highest calibrated elevation (90 when the file does not say)."""
        return 90.0 if self.applicability is None else self.applicability.el_max_deg


def default_model_file(k_sigma: float = 2.0) -> ErrorModelFile:
    """The built-in ``ErrorModel()`` (a = b = 2 m): the simulator's own noise model.

    It applies to simulated receivers only (the simulator draws its direct-signal noise from
    it); no real receiver has been shown to be bounded by it (a smartphone log was not: one
    hazardous epoch in 599), so a real data set needs a calibrated model for a safety claim.
    """
    e = ErrorModel()
    return ErrorModelFile(
        IntervalModel(e, k_sigma),
        {s: SystemModel(e, ("sim",), 0, 0, float("nan")) for s in "GRECJ"},
        Applicability(("simulated",), ("simulated",), "simulated", "single", 0.0, 90.0,
                      SIMULATOR_METHOD, ()),
        "",
    )  # fmt: skip


def _count(value: object) -> int:
    """A whole count >= 0 from JSON (a hand-edited 1.5 or -3 is refused, not truncated)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"n_residuals must be a whole number >= 0, got {value!r}")
    return value


def write_error_model(
    path: str | Path,
    model: IntervalModel,
    fitted: Mapping[str, object] | None = None,
    *,
    systems: Mapping[str, SystemModel] | None = None,
    applicability: Applicability | None = None,
) -> Path:
    """Write an error-model JSON file (:data:`ERROR_MODEL_FORMAT`).

    Without ``applicability`` the file says it was calibrated for nothing in particular
    (no receiver, no system): it then applies to no data set unless forced.
    """
    e = model.error
    app = applicability or Applicability((), ())
    data = {
        "format": ERROR_MODEL_FORMAT,
        "a_m": e.a_m,
        "b_m": e.b_m,
        "min_el_deg": e.min_el_deg,
        "k_sigma": model.k_sigma,
        "systems": {
            s: {
                "a_m": m.error.a_m,
                "b_m": m.error.b_m,
                "min_el_deg": m.error.min_el_deg,
                "codes": list(m.codes),
                "n_residuals": int(m.n_residuals),
                "n_independent": int(m.n_independent),
                "tail_probability": m.tail_probability if np.isfinite(m.tail_probability) else None,
            }
            for s, m in sorted((systems or {}).items())
        },
        "applicability": {
            "receivers": list(app.receivers),
            "antennas": list(app.antennas),
            "receiver_class": app.receiver_class,
            "frequency": app.frequency,
            "el_min_deg": app.el_min_deg,
            "el_max_deg": app.el_max_deg,
            "method": app.method,
            "sources": list(app.sources),
            "pairs": [
                {"receiver": r, "antenna": a,
                 "systems": {s_: {"codes": list(cs), "n_residuals": int(n)} for s_, cs, n in per}}
                for r, a, per in app.pairs
            ],
        },
        "fitted": dict(fitted or {}),
        "software_version": __version__,
    }
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(p, strict_json_text(data).encode())
    return p


def read_error_model(path: str | Path) -> IntervalModel:
    """The envelope model of an error-model file (either format; applicability not checked)."""
    return read_error_model_file(path).model


def read_error_model_file(path: str | Path) -> ErrorModelFile:
    """Read an error-model JSON file (:func:`write_error_model`; also ``/1`` files)."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except FileNotFoundError as exc:
        raise ErrorModelFileError(f"{p}: no such file; make one with `locator calibrate`") from exc
    except IsADirectoryError as exc:
        raise ErrorModelFileError(
            f"{p}: is a folder; give the JSON file `locator calibrate` wrote"
        ) from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ErrorModelFileError(
            f"{p}: not a JSON text file ({exc}); give the file `locator calibrate` wrote"
        ) from exc
    fmt = d.get("format") if isinstance(d, dict) else None
    if isinstance(fmt, str) and fmt.startswith("locator-error-model/") and fmt not in (
        ERROR_MODEL_FORMAT, ERROR_MODEL_FORMAT_V1
    ):
        raise ErrorModelFileError(
            f"{p}: an error-model file of another version ({fmt}); this locator reads "
            f"{ERROR_MODEL_FORMAT} and {ERROR_MODEL_FORMAT_V1}: use the locator that wrote it, or "
            "calibrate again with this one"
        )
    if fmt not in (ERROR_MODEL_FORMAT, ERROR_MODEL_FORMAT_V1):
        raise ErrorModelFileError(
            f"{p}: not an error-model file ({ERROR_MODEL_FORMAT} or {ERROR_MODEL_FORMAT_V1}); "
            "make one with `locator calibrate`"
        )
    assert isinstance(d, dict)
    try:
        err = ErrorModel(float(d["a_m"]), float(d["b_m"]), float(d.get("min_el_deg", 1.0)))
        model = IntervalModel(err, float(d.get("k_sigma", 2.0)))
    except (KeyError, TypeError, ValueError) as exc:
        raise ErrorModelFileError(
            f"{p}: bad error model ({exc}); expected a_m, b_m, k_sigma"
        ) from exc
    if fmt == ERROR_MODEL_FORMAT_V1:
        return ErrorModelFile(model, {}, None, str(p), fmt)
    try:
        systems = {
            str(s): SystemModel(
                ErrorModel(float(m["a_m"]), float(m["b_m"]), float(m.get("min_el_deg", 1.0))),
                _codes(m["codes"]),
                int(m["n_residuals"]),
                int(m["n_independent"]),
                float("nan") if m.get("tail_probability") is None else float(m["tail_probability"]),
            )
            for s, m in dict(d["systems"]).items()
        }
        a = dict(d["applicability"])
        app = Applicability(
            tuple(str(r) for r in a["receivers"]),
            tuple(str(r) for r in a["antennas"]),
            str(a.get("receiver_class", "")),
            str(a.get("frequency", "single")),
            float(a["el_min_deg"]),
            float(a["el_max_deg"]),
            str(a.get("method", "")),
            tuple(str(r) for r in a.get("sources", ())),
            tuple(
                (str(q["receiver"]), str(q["antenna"]),
                 tuple((str(s_), _codes(v["codes"]), _count(v["n_residuals"]))
                       for s_, v in sorted(dict(q["systems"]).items())))
                for q in a.get("pairs", ())
            ),
        )
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise ErrorModelFileError(
            f"{p}: bad {ERROR_MODEL_FORMAT} file ({exc!r}); expected 'systems' (per system a_m, "
            "b_m, codes, n_residuals, n_independent, tail_probability) and 'applicability' "
            "(receivers, antennas, el_min_deg, el_max_deg); write it again with `locator calibrate`"
        ) from exc
    return ErrorModelFile(model, systems, app, str(p), fmt)


def _codes(value: object) -> tuple[str, ...]:
    """A system's ``codes`` of a model file: a list of strings (a bare string, read letter by
    letter, would name codes nobody tracks)."""
    if isinstance(value, str) or not isinstance(value, (list, tuple)):
        raise ValueError(
            f"codes must be a list of observation codes, e.g. [\"C1C\"], got {value!r}"
        )
    return tuple(str(c) for c in value)


def _check_frequency_and_class(frequency: str, receiver_class: str) -> None:
    """The guard a receiver profile and a model's applicability share."""
    if frequency not in FREQUENCY_MODES:
        raise ValueError(f"frequency must be one of {FREQUENCY_MODES}, got {frequency!r}")
    if receiver_class not in ("", *RECEIVER_CLASSES):
        raise ValueError(
            f"receiver_class must be one of {RECEIVER_CLASSES} or '', got {receiver_class!r}"
        )
