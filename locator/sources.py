"""Epoch sources of the locator: simulated runs and real RINEX observations.

The epoch loop (:func:`locator.run.run_locator`) asks a source, epoch by epoch, for the
corrected pseudoranges of the signals the receiver tracks, given an approximate antenna position
(the centre of the predicted interval; the corrections need it to ~100 m). Two sources:

* :class:`SimSource` - a :class:`locator.sim.simfile.SimRun` of the synthetic world: every received
  signal (LOS and NLOS alike: a receiver cannot tell them apart), with the truth kept for
  :mod:`locator.evaluate`, and an odometer with a scale error;
* :class:`RinexSource` - a RINEX 2/3 observation file and broadcast navigation
  (:class:`locator.corrections.RangeModel`): single-frequency pseudoranges corrected for the
  satellite clock, relativity, group delay, Earth rotation, Klobuchar ionosphere and troposphere.
  Satellites without usable navigation data are reported per epoch with the reason. Where no
  broadcast ionosphere model exists, the delay stays in the pseudorange and the epoch data carry
  an inflated sigma for it (:attr:`EpochData.extra_sigma_m`). With ``dual_frequency`` the
  ranges are the ionosphere-free combination of two codes instead (no ionosphere model needed;
  satellites without the second code are left out with the reason).

Pairs of pseudoranges are differenced, so every satellite of an epoch must share one receiver
clock: the simulator has a single clock; on real data mixing systems needs inter-system biases,
which the 1-D locator does not estimate, so :class:`RinexSource` takes one system unless told
otherwise (``constellation``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from locator.corrections import RangeModel, uncorrected_iono_sigma_m
from locator.observations import (
    SECOND_FREQUENCY_PRIORITY,
    Observations,
    PseudorangeSelection,
)
from locator.sim.simfile import SignalState, SimRun
from predisat.availability.satellites import select_satellites
from predisat.jsontypes import JsonDict
from predisat.readonly import freeze_array_fields

__all__ = ["EpochData", "EpochSource", "RinexSource", "SimSource", "check_odometer"]


class EpochData(NamedTuple):
    """The usable signals of one epoch.

    Attributes
    ----------
    sats : tuple of str, length n
    sat_ecef_m : ndarray, shape (n, 3)
        Satellite positions at transmission, in the Earth-fixed frame of reception, metres.
    pseudorange_m : ndarray, shape (n,)
        Corrected pseudoranges (one receiver clock left in them), metres.
    rejected : mapping of str to str
        Satellites observed but not usable, with the reason.
    extra_sigma_m : ndarray, shape (n,), optional
        Standard deviation to add (root sum of squares) to the error model's for each
        satellite, metres: the ionospheric delay no broadcast model corrected
        (:func:`locator.corrections.uncorrected_iono_sigma_m`), 0 where corrected. None: nothing
        to add (the simulator).
    """

    sats: tuple[str, ...]
    sat_ecef_m: NDArray
    pseudorange_m: NDArray
    rejected: Mapping[str, str]
    extra_sigma_m: NDArray | None = None


class EpochSource(Protocol):
    """What :func:`locator.run.run_locator` needs from a source of epochs.

    A source with an odometer may also have ``odometer_extra_m``: the odometer's disputed
    distance per epoch, shape (n_epoch, 2), cumulative, toward lower and toward higher
    chainage, m (:class:`locator.odometry.odometer.OdometerLog`), or None.
    """

    @property
    def gps_s(self) -> NDArray: ...

    @property
    def odometer_m(self) -> NDArray | None:
        """Odometer distance per epoch, signed toward increasing chainage (None: no odometer)."""
        ...

    def observe(self, epoch: int, rx_ecef_m: NDArray) -> EpochData: ...

    def describe(self) -> JsonDict: ...


@dataclass(frozen=True, eq=False)
class SimSource:
    """Epochs of a simulated run.

    Attributes
    ----------
    sim : SimRun
    odometer_scale_error : float
        Relative scale error of the simulated odometer (wheel wear, slip): the odometer reads
        ``(1 + e)`` times the true distance. ETCS allows 5 % (SUBSET-041).
    include_nlos : bool
        Give NLOS signals to the locator (a real receiver does); False shows the ideal.
    constellation : str
        Systems used (``"all"``, ``"G"``, ``"GE"``, ...).
    odometer : ndarray, shape (n_epoch,), optional
        Odometer distance per epoch, signed toward increasing chainage (e.g. a simulated
        :class:`locator.odometry.odometer.OdometerLog` sampled at the epochs); replaces the
        scale-error model when given.
    odometer_extra : ndarray, shape (n_epoch, 2), optional
        The odometer's disputed distance per epoch, cumulative, non-decreasing, toward lower
        and toward higher chainage, m (``OdometerLog.extra_ahead_m`` / ``extra_behind_m`` in
        the chainage frame); needs ``odometer``.
    """

    sim: SimRun
    odometer_scale_error: float = 0.02
    include_nlos: bool = True
    constellation: str = "all"
    odometer: NDArray | None = field(default=None)
    odometer_extra: NDArray | None = field(default=None)

    def __post_init__(self) -> None:
        check_odometer(self.odometer, self.odometer_extra, len(self.sim.gps_s))
        if not abs(self.odometer_scale_error) < 0.5:
            raise ValueError(
                f"odometer_scale_error must be within +-0.5, got {self.odometer_scale_error}"
            )
        freeze_array_fields(self)

    @property
    def gps_s(self) -> NDArray:
        return self.sim.gps_s

    @property
    def truth_chainage_m(self) -> NDArray:
        return self.sim.chainage_m

    @property
    def odometer_m(self) -> NDArray:
        if self.odometer is not None:
            return np.asarray(self.odometer, float)
        c = self.sim.chainage_m
        return (c - c[0]) * (1.0 + self.odometer_scale_error)

    @property
    def odometer_extra_m(self) -> NDArray | None:
        return None if self.odometer_extra is None else np.asarray(self.odometer_extra, float)

    @cached_property
    def _columns(self) -> NDArray:
        keep = set(select_satellites(self.sim.sats, self.constellation))
        return np.array([s in keep for s in self.sim.sats], bool)

    @cached_property
    def _names(self) -> NDArray:
        """Satellite ids as an object array (one gather per epoch instead of a Python loop)."""
        return np.array(self.sim.sats, dtype=object)

    def observe(self, epoch: int, rx_ecef_m: NDArray) -> EpochData:
        state = self.sim.state[epoch]
        take = state == SignalState.LOS
        if self.include_nlos:
            take = take | (state == SignalState.NLOS)
        take &= self._columns
        j = np.flatnonzero(take)
        return EpochData(
            tuple(self._names[j].tolist()),
            np.array(self.sim.sat_ecef_m[epoch, j]),
            np.array(self.sim.corrected_m[epoch, j]),
            {},
        )

    def describe(self) -> JsonDict:
        return {
            "source": "simulation",
            "odometer_scale_error": None if self.odometer is not None
            else self.odometer_scale_error,
            "odometer": "given" if self.odometer is not None else "scale error",
            "include_nlos": self.include_nlos,
            "constellation": self.constellation,
            "sim": {k: self.sim.meta.get(k) for k in ("seed", "world_seed", "t0_gps_s",
                                                       "duration_s", "rate_hz", "track")},
        }  # fmt: skip


@dataclass(frozen=True, eq=False)
class RinexSource:
    """Epochs of a RINEX observation file with broadcast navigation.

    Attributes
    ----------
    model : RangeModel
        Broadcast ephemeris and ionosphere (:meth:`RangeModel.from_rinex_nav`).
    obs : Observations
    constellation : str
        Systems used; one system by default (module docstring).
    priority : mapping of system letter to codes, optional
        Pseudorange code priority (:meth:`Observations.pseudorange`).
    odometer : ndarray, shape (n_epoch,), optional
        Odometer distance per epoch, metres; None when the receiver has none (the run then
        bounds the motion by a maximum speed).
    odometer_extra : ndarray, shape (n_epoch, 2), optional
        The odometer's disputed distance per epoch, cumulative, non-decreasing, toward lower
        and toward higher chainage, m (``OdometerLog.extra_ahead_m`` / ``extra_behind_m`` in
        the chainage frame); needs ``odometer``.
    dual_frequency : bool
        Range with the ionosphere-free combination ``(f1^2 P1 - f2^2 P2) / (f1^2 - f2^2)`` of
        the code ``priority`` chooses and the second code of
        :data:`~locator.observations.SECOND_FREQUENCY_PRIORITY`, each corrected for its own
        broadcast group delay: no ionosphere model is needed, the code noise and multipath
        grow (about 3x for L1/L2), so the error model must be calibrated on the same
        processing (``frequency: dual``). Satellites without a second code are left out.
    codes_kept : mapping of system letter to codes, optional
        The only codes (:attr:`code_table` spelling: ``"C1C"``, ``"C1C+C2W"``) whose ranges
        are used, for the systems named; the others' ranges are left out with the reason
        (the codes an error model was calibrated on: a few epochs of another code must not
        take the claim from the whole run). None: every code.
    """

    model: RangeModel
    obs: Observations
    constellation: str = "G"
    priority: Mapping[str, Sequence[str]] | None = None
    odometer: NDArray | None = field(default=None)
    odometer_extra: NDArray | None = field(default=None)
    dual_frequency: bool = False
    codes_kept: Mapping[str, Sequence[str]] | None = None

    def __post_init__(self) -> None:
        check_odometer(self.odometer, self.odometer_extra, len(self.obs.gps_s))
        if not self._columns.any():
            raise ValueError(
                f"{self.obs.path}: no satellite of constellation {self.constellation!r}; it has "
                f"{sorted({s[0] for s in self.obs.sats})}"
            )

    @property
    def gps_s(self) -> NDArray:
        return self.obs.gps_s

    @property
    def odometer_m(self) -> NDArray | None:
        return None if self.odometer is None else np.asarray(self.odometer, float)

    @property
    def odometer_extra_m(self) -> NDArray | None:
        return None if self.odometer_extra is None else np.asarray(self.odometer_extra, float)

    @cached_property
    def _selection(self) -> PseudorangeSelection:
        return self.obs.pseudorange(self.priority)

    @cached_property
    def _second(self) -> PseudorangeSelection:
        return self.obs.pseudorange(SECOND_FREQUENCY_PRIORITY)

    @property
    def frequency(self) -> str:
        """``"dual"`` (ionosphere-free combination) or ``"single"``: the processing an error
        model must have been calibrated on."""
        return "dual" if self.dual_frequency else "single"

    @cached_property
    def _all_codes(self) -> NDArray:
        first = self._selection.code
        if not self.dual_frequency:
            return first
        second = self._second.code
        both = (first != "") & (second != "")
        return np.where(both, np.char.add(np.char.add(first, "+"), second), "")

    @cached_property
    def _left_out(self) -> NDArray:
        """Where a range's code is not among :attr:`codes_kept`, shape (n_epoch, n_sat)."""
        table = self._all_codes
        out = np.zeros(table.shape, bool)
        if self.codes_kept is None:
            return out
        for j, sat in enumerate(self.obs.sats):
            kept = self.codes_kept.get(sat[0])
            if kept is not None:
                out[:, j] = (table[:, j] != "") & ~np.isin(table[:, j], list(kept))
        return out

    @cached_property
    def code_table(self) -> NDArray:
        """The code of each range, shape (n_epoch, n_sat): ``"C1C"``, or for the
        ionosphere-free combination ``"C1C+C2W"``; ``""`` where there is none (with
        ``dual_frequency``, where either code is missing; with :attr:`codes_kept`, where the
        code is not kept)."""
        return np.where(self._left_out, "", self._all_codes)

    def left_out_codes(self) -> dict[str, dict[str, int]]:
        """The ranges :attr:`codes_kept` leaves out: system -> code -> number of ranges
        (satellites of the constellation only)."""
        out: dict[str, dict[str, int]] = {}
        rows, cols = np.nonzero(self._left_out & self._columns[None, :])
        for i, j in zip(rows, cols, strict=True):
            by = out.setdefault(self.obs.sats[j][0], {})
            code = str(self._all_codes[i, j])
            by[code] = by.get(code, 0) + 1
        return out

    def _not_kept(self, epoch: int, listed: NDArray) -> dict[str, str]:
        return {self.obs.sats[k]: f"code {self._all_codes[epoch, k]} not among those the error "
                "model was calibrated on (codes_kept)"
                for k in np.flatnonzero(listed & self._left_out[epoch])}  # fmt: skip

    def codes(self, epoch: int, j: NDArray) -> list[str]:
        """The code of each range of the columns ``j`` at ``epoch`` (:attr:`code_table`)."""
        return [str(c) for c in self.code_table[epoch, j]]

    @cached_property
    def _model(self) -> RangeModel:
        # the ionosphere of the observations' day, not of whichever file was listed first
        mid_s = float(np.median(self.obs.gps_s)) if len(self.obs.gps_s) else 0.0
        return self.model.with_glonass_slots(self.obs.header.glonass_slots).with_iono_near(mid_s)

    @property
    def systems(self) -> tuple[str, ...]:
        """System letters of the satellites used, sorted."""
        return tuple(sorted({s[0] for s, c in zip(self.obs.sats, self._columns, strict=True) if c}))

    @property
    def iono_missing(self) -> tuple[str, ...]:
        """Systems used for which no broadcast ionosphere model exists: their delay stays in
        the pseudoranges, every epoch is flagged and its sigma inflated (module docstring).
        None with ``dual_frequency``: the combination removes the delay."""
        if self.dual_frequency:
            return ()
        return tuple(s for s in self.systems if self._model.iono.klobuchar(s) is None)

    @property
    def iono_stale(self) -> Mapping[str, str]:
        """Ionosphere sets of the navigation files left out as of another day than the
        observations (:attr:`locator.corrections.BroadcastIono.stale`)."""
        return self._model.iono.stale

    @cached_property
    def _columns(self) -> NDArray:
        keep = set(select_satellites(self.obs.sats, self.constellation))
        return np.array([s in keep for s in self.obs.sats], bool)

    def observe(self, epoch: int, rx_ecef_m: NDArray) -> EpochData:
        if self.dual_frequency:
            return self._observe_dual(epoch, rx_ecef_m)
        pr = self._selection.pseudorange_m[epoch]
        listed = np.isfinite(pr) & self._columns
        dropped = self._not_kept(epoch, listed)
        j = np.flatnonzero(listed & ~self._left_out[epoch])
        sats = tuple(self.obs.sats[k] for k in j)
        if not sats:
            return EpochData((), np.zeros((0, 3)), np.zeros(0), dropped)
        codes = list(self._selection.code[epoch, j])
        cr = self._model.correct(float(self.obs.gps_s[epoch]), sats, pr[j], rx_ecef_m, codes)
        ok = cr.usable & np.isfinite(cr.corrected_m)
        rejected = {s: str(r) or "not usable" for s, r, u in zip(sats, cr.reason, ok, strict=True)
                    if not u}  # fmt: skip
        rejected.update(dropped)
        extra = np.where(
            cr.iono_uncorrected, uncorrected_iono_sigma_m(cr.el_deg, cr.states.freq_hz), 0.0
        )
        return EpochData(
            tuple(s for s, u in zip(sats, ok, strict=True) if u),
            cr.sat_ecef_m[ok],
            cr.corrected_m[ok],
            rejected,
            extra[ok],
        )

    def _observe_dual(self, epoch: int, rx_ecef_m: NDArray) -> EpochData:
        """The ionosphere-free combination of the two codes' corrected ranges: every term but
        the ionosphere and the group delay is the same on both frequencies and passes through
        (the two weights differ by one); each range's own group delay is taken off first."""
        pr1 = self._selection.pseudorange_m[epoch]
        pr2 = self._second.pseudorange_m[epoch]
        listed = np.isfinite(pr1) & self._columns
        rejected = {self.obs.sats[k]: "no second frequency for the ionosphere-free combination"
                    for k in np.flatnonzero(listed & ~np.isfinite(pr2))}  # fmt: skip
        rejected.update(self._not_kept(epoch, listed & np.isfinite(pr2)))
        j = np.flatnonzero(listed & np.isfinite(pr2) & ~self._left_out[epoch])
        sats = tuple(self.obs.sats[k] for k in j)
        if not sats:
            return EpochData((), np.zeros((0, 3)), np.zeros(0), rejected)
        t = float(self.obs.gps_s[epoch])
        code1 = list(self._selection.code[epoch, j])
        code2 = list(self._second.code[epoch, j])
        c1 = self._model.correct(t, sats, pr1[j], rx_ecef_m, code1, ionosphere=False)
        c2 = self._model.correct(t, sats, pr2[j], rx_ecef_m, code2, ionosphere=False)
        f1, f2 = c1.states.freq_hz, c2.states.freq_hz
        w1 = f1**2 / (f1**2 - f2**2)
        combined = w1 * c1.corrected_m - (w1 - 1.0) * c2.corrected_m
        ok = c1.usable & c2.usable & np.isfinite(combined) & (f1 != f2)
        for s, r1, r2, u in zip(sats, c1.reason, c2.reason, ok, strict=True):
            if not u:
                rejected[s] = str(r1) or str(r2) or "not usable"
        return EpochData(
            tuple(s for s, u in zip(sats, ok, strict=True) if u),
            c1.sat_ecef_m[ok],
            combined[ok],
            rejected,
            np.zeros(int(ok.sum())),
        )

    def where(self, epoch: int) -> str:
        """File, line and epoch of ``epoch``, for messages."""
        return self.obs.where(epoch)

    def describe(self) -> JsonDict:
        return {
            "source": "rinex",
            "obs": str(self.obs.path),
            "nav": [str(p) for p in getattr(self.model.ephemeris, "sources", ())],
            "constellation": self.constellation,
            "frequency": self.frequency,
            "odometer": self.odometer is not None,
            "marker": self.obs.header.marker_name,
            # systems whose ionospheric delay no broadcast model corrects (sigma inflated)
            "iono_uncorrected_systems": list(self.iono_missing),
            # the combination uses no broadcast ionosphere: none named as if it had
            "iono_sources": {} if self.dual_frequency else dict(self._model.iono.sources),
            "iono_stale": {} if self.dual_frequency else dict(self.iono_stale),
            # ranges of codes the error model was not calibrated on, left out
            "codes_kept": None if self.codes_kept is None
            else {k: list(v) for k, v in sorted(self.codes_kept.items())},
            "codes_left_out": self.left_out_codes(),
        }


def check_odometer(odometer: NDArray | None, extra: NDArray | None, n_epoch: int) -> None:
    """Refuse a source's odometer that has not one value per epoch, and a disputed distance
    (``odometer_extra``) that is not ``(n_epoch, 2)``, >= 0 and non-decreasing, or that comes
    without an odometer."""
    if odometer is not None and np.shape(odometer) != (n_epoch,):
        raise ValueError(
            f"odometer must have one value per epoch (({n_epoch},)), got {np.shape(odometer)}"
        )
    if extra is None:
        return
    a = np.asarray(extra, float)
    if odometer is None:
        raise ValueError("odometer_extra needs odometer: the disputed distance is the odometer's")
    if a.shape != (n_epoch, 2):
        raise ValueError(f"odometer_extra must have shape ({n_epoch}, 2), got {a.shape}")
    if not (np.all(np.isfinite(a)) and np.all(a >= 0) and np.all(np.diff(a, axis=0) >= 0)):
        raise ValueError("odometer_extra must be finite, >= 0 and non-decreasing (cumulative, m)")
