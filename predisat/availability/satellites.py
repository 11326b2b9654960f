"""Satellites seen from a line: constellation selection, positions, azimuth/elevation, trust.

The pieces the availability engine (:mod:`predisat.availability.engine`) and the train-run view
(:mod:`predisat.availability.trainrun`) share:

* :func:`select_satellites` - constellation selection (``"gps"``, ``"gps+galileo"``, ``"all"``
  or system letters such as ``"GE"``);
* :class:`SatellitePositions` - ECEF positions of the selected satellites at every epoch, with
  the ephemeris trust decision (status ``OK``) as ``valid``;
* :class:`LinePositions` - antenna positions along the line (chainage, WGS84, track heading);
* :func:`azel` - azimuth and elevation of every satellite from every position (float64
  reference; the engine has a chunked float32 path);
* :class:`TrustRule` - the trust decision: above a :class:`~predisat.masks.maskset.MaskSet` (mask
  plus
  margin), above a flat cut-off, or merely above the horizon;
* :func:`default_ephemeris` and :func:`default_window` - the embedded navigation day
  (IGS station Esbjerg, 2020-06-25, all constellations) so that availability runs offline.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.geodesy import enu_rotation, enu_to_azel, geodetic_to_ecef
from predisat.gnss.ephemeris import Ephemeris, EphemerisStatus
from predisat.gnss.timescale import calendar_to_gps_s
from predisat.readonly import freeze_array_fields
from predisat.track import TrackMap

__all__ = [
    "CONSTELLATIONS",
    "DEFAULT_NAV_FILE",
    "SYSTEM_NAMES",
    "LinePositions",
    "MaskLike",
    "SatellitePositions",
    "TrustRule",
    "azel",
    "default_ephemeris",
    "default_window",
    "select_satellites",
    "system_letters",
]

SYSTEM_NAMES: dict[str, str] = {
    "G": "GPS",
    "R": "GLONASS",
    "E": "Galileo",
    "C": "BeiDou",
    "J": "QZSS",
    "I": "NavIC/IRNSS",
}
"""RINEX system letters and the constellations they stand for."""

CONSTELLATIONS: dict[str, str] = {
    "gps": "G",
    "gps+galileo": "GE",
    "galileo": "E",
    "gps+glonass": "GR",
    "all": "GRECJI",
}
"""Named constellation selections (system letters). Any string of letters also works."""

DEFAULT_NAV_FILE = "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
"""Embedded navigation day (``predisat/data/nav``): IGS Esbjerg, 2020-06-25, RINEX 3.05."""


def select_satellites(
    sats: Sequence[str], constellation: str | Sequence[str] = "all"
) -> tuple[str, ...]:
    """Satellites of the chosen constellations, in the given order.

    Parameters
    ----------
    sats : sequence of str
        Satellite ids (``"G05"``, ``"E11"``, ...).
    constellation : str or sequence of str
        A name of :data:`CONSTELLATIONS` (case-insensitive), a string of system letters
        (``"GE"``, ``"G,E"``) or a sequence of letters.

    Returns
    -------
    tuple of str
    """
    letters = system_letters(constellation)
    return tuple(s for s in sats if s[:1] in letters)


def system_letters(constellation: str | Sequence[str]) -> set[str]:
    """The system letters a constellation name or letter string means (``"gps+galileo"`` ->
    ``{"G", "E"}``); ValueError naming the choices for anything else."""
    if isinstance(constellation, str):
        key = constellation.strip().lower()
        if key in CONSTELLATIONS:
            return set(CONSTELLATIONS[key])
        letters = [c for c in constellation.upper() if c not in " ,+;"]
    else:
        letters = [str(c).upper() for c in constellation]
    bad = [c for c in letters if c not in SYSTEM_NAMES]
    if not letters or bad:
        raise ValueError(
            f"constellation {constellation!r} is not understood: use one of "
            f"{sorted(CONSTELLATIONS)} or system letters from {''.join(SYSTEM_NAMES)}"
        )
    return set(letters)


# --------------------------------------------------------------------------- positions
@dataclass(frozen=True)
class LinePositions:
    """Antenna positions along a line.

    Attributes
    ----------
    chainage_m, lat_deg, lon_deg, h_m, heading_deg : ndarray, shape (n_pos,)
        Chainage, WGS84 position of the antenna and track heading (azimuth of increasing
        chainage, degrees).
    """

    chainage_m: NDArray
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    heading_deg: NDArray

    def __post_init__(self) -> None:
        arrays = [np.atleast_1d(np.asarray(getattr(self, n), float)) for n in _POS_FIELDS]
        try:
            arrays = list(np.broadcast_arrays(*arrays))
        except ValueError as exc:
            raise ValueError(
                "LinePositions fields must share one shape (n_pos,): "
                + ", ".join(f"{n} {a.shape}" for n, a in zip(_POS_FIELDS, arrays, strict=True))
            ) from exc
        for name, arr in zip(_POS_FIELDS, arrays, strict=True):
            if arr.ndim != 1:
                raise ValueError(f"LinePositions.{name} must be 1-D, got shape {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"LinePositions.{name} contains NaN or infinite values")
            arr = arr.copy()
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @classmethod
    def from_track(
        cls, track: TrackMap, chainage_m: ArrayLike, antenna_height_m: float = 0.0
    ) -> LinePositions:
        """Positions on a :class:`~predisat.track.map.TrackMap` axis, raised by an antenna
        height."""
        s = np.atleast_1d(np.asarray(chainage_m, float))
        lat, lon, h = track.position_at(s)
        return cls(s, lat, lon, np.asarray(h) + antenna_height_m, track.heading_at(s))

    @classmethod
    def from_masks(cls, masks: MaskLike) -> LinePositions:
        """The positions of a mask set (its antenna positions and headings)."""
        return cls(masks.chainage_m, masks.lat_deg, masks.lon_deg, masks.h_m, masks.heading_deg)

    @property
    def n_pos(self) -> int:
        return len(self.chainage_m)

    @property
    def ecef_m(self) -> NDArray:
        """Antenna ECEF positions, shape (n_pos, 3), metres."""
        return geodetic_to_ecef(self.lat_deg, self.lon_deg, self.h_m)

    @property
    def enu_rotation(self) -> NDArray:
        """ECEF-to-local-ENU rotations, shape (n_pos, 3, 3)."""
        return enu_rotation(self.lat_deg, self.lon_deg)

    @property
    def tangent_enu(self) -> NDArray:
        """Unit track tangent (increasing chainage) in each local ENU, horizontal, (n_pos, 3)."""
        h = np.radians(self.heading_deg)
        return np.stack([np.sin(h), np.cos(h), np.zeros_like(h)], axis=-1)

    def take(self, index: ArrayLike) -> LinePositions:
        """A subset (or reordering) of the positions."""
        i = np.asarray(index)
        return LinePositions(*(getattr(self, n)[i] for n in _POS_FIELDS))


_POS_FIELDS = ("chainage_m", "lat_deg", "lon_deg", "h_m", "heading_deg")


@dataclass(frozen=True)
class SatellitePositions:
    """ECEF positions of selected satellites over a time window.

    Attributes
    ----------
    gps_s : ndarray, shape (n_epoch,)
    sats : tuple of str, length n_sat
    pos_ecef_m : ndarray, shape (n_epoch, n_sat, 3)
        NaN where the ephemeris does not trust the satellite.
    status : EphemerisStatus
        The ephemeris' reasons, for reports.
    """

    gps_s: NDArray
    sats: tuple[str, ...]
    pos_ecef_m: NDArray
    status: EphemerisStatus

    def __post_init__(self) -> None:
        freeze_array_fields(self)
        want = (len(self.gps_s), len(self.sats))
        if self.pos_ecef_m.shape != (*want, 3) or self.status.reason.shape != want:
            raise ValueError(
                f"pos_ecef_m {self.pos_ecef_m.shape} and status.reason "
                f"{self.status.reason.shape} must have shapes {(*want, 3)} and {want} "
                f"({want[0]} epochs, {want[1]} satellites): replace them together"
            )

    @classmethod
    def from_ephemeris(
        cls,
        ephemeris: Ephemeris,
        gps_s: ArrayLike,
        constellation: str | Sequence[str] = "all",
        sats: Sequence[str] | None = None,
    ) -> SatellitePositions:
        """Evaluate an ephemeris for the chosen constellations (or explicit ``sats``)."""
        want = select_satellites(ephemeris.satellites if sats is None else sats, constellation)
        if not want:
            raise ValueError(
                f"no satellite of constellation {constellation!r} in the ephemeris "
                f"({', '.join(ephemeris.sources)}); choose another constellation or file"
            )
        pos, _, status = ephemeris.evaluate(gps_s, want)
        return cls(np.asarray(status.gps_s, float), want, pos, status)

    @property
    def valid(self) -> NDArray:
        """Ephemeris-trusted (epoch, satellite) pairs, bool, shape (n_epoch, n_sat)."""
        return np.all(np.isfinite(self.pos_ecef_m), axis=-1)

    @property
    def systems(self) -> NDArray:
        """System letter of each satellite, shape (n_sat,)."""
        return np.array([s[0] for s in self.sats])


def azel(
    rx_ecef_m: ArrayLike, rotation: ArrayLike, sat_ecef_m: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Azimuth and elevation of satellites from receivers (float64, geometric, no light time).

    Parameters
    ----------
    rx_ecef_m : array_like, shape (..., 3)
        Receiver positions.
    rotation : array_like, shape (..., 3, 3)
        ECEF-to-ENU rotations at the receivers (:func:`predisat.geodesy.enu_rotation`).
    sat_ecef_m : array_like, shape (n_epoch, n_sat, 3)

    Returns
    -------
    az_deg, el_deg : ndarray, shape (..., n_epoch, n_sat)
        NaN where the satellite position is NaN.
    """
    rx = np.asarray(rx_ecef_m, float)
    rot = np.asarray(rotation, float)
    sat = np.asarray(sat_ecef_m, float)
    d = sat - rx[..., None, None, :]
    enu = np.einsum("...ij,...tsj->...tsi", rot, d)
    az, el, _ = enu_to_azel(enu)
    return az, el


# --------------------------------------------------------------------------- trust
class MaskLike(Protocol):
    """What the trust decision needs of a :class:`predisat.masks.maskset.MaskSet`."""

    @property
    def chainage_m(self) -> NDArray: ...

    @property
    def lat_deg(self) -> NDArray: ...

    @property
    def lon_deg(self) -> NDArray: ...

    @property
    def h_m(self) -> NDArray: ...

    @property
    def heading_deg(self) -> NDArray: ...

    @property
    def az_deg(self) -> NDArray: ...

    @property
    def az_step_deg(self) -> float: ...

    def bin_index(self, az_deg: ArrayLike) -> NDArray: ...

    def mask_at(self, chainage_m: ArrayLike, az_deg: ArrayLike) -> NDArray: ...

    def opening_angle_deg(self) -> NDArray: ...


_MODES = ("mask", "none", "cutoff")


@dataclass(frozen=True)
class TrustRule:
    """When a satellite in the sky is trusted at a position.

    Build with :meth:`mask`, :meth:`cutoff` or :meth:`none`:

    * ``mask``: elevation strictly above the mask at the satellite's azimuth plus the mask's
      margin (``MaskSet.mask_at``), at the mask position nearest the chainage;
    * ``cutoff``: elevation strictly above a flat cut-off (e.g. 10 or 15 deg), everywhere;
    * ``none``: elevation above the horizon (0 deg).

    The ephemeris trust (status ``OK``) is applied by the callers on top.
    """

    mode: str
    cutoff_deg: float = 0.0
    masks: Any = None  # Any: a MaskLike in mode 'mask' (checked below), else None

    def __post_init__(self) -> None:
        if self.mode not in _MODES:
            raise ValueError(f"TrustRule.mode must be one of {_MODES}, got {self.mode!r}")
        if self.mode == "mask" and self.masks is None:
            raise ValueError("TrustRule mode 'mask' needs masks (use TrustRule.mask(masks))")
        if not -90.0 <= self.cutoff_deg < 90.0:
            raise ValueError(f"cutoff_deg must be in [-90, 90), got {self.cutoff_deg}")

    @classmethod
    def mask(cls, masks: MaskLike) -> TrustRule:
        return cls("mask", 0.0, masks)

    @classmethod
    def cutoff(cls, cutoff_deg: float) -> TrustRule:
        return cls("cutoff", float(cutoff_deg))

    @classmethod
    def none(cls) -> TrustRule:
        return cls("none", 0.0)

    @property
    def label(self) -> str:
        """Short human name: ``"masks"``, ``"cutoff 15 deg"`` or ``"no mask"``."""
        if self.mode == "mask":
            return "masks"
        if self.mode == "cutoff":
            return f"cutoff {self.cutoff_deg:g} deg"
        return "no mask"

    @property
    def n_az(self) -> int:
        """Number of azimuth bins of :meth:`threshold_table` (1 without masks)."""
        return len(self.masks.az_deg) if self.mode == "mask" else 1

    def threshold_table(self, chainage_m: ArrayLike) -> NDArray:
        """Elevation a satellite must exceed, per position and azimuth bin.

        Returns
        -------
        ndarray of float32, shape (n_pos, n_az)
            ``n_az`` is 1 for ``cutoff`` and ``none``.
        """
        s = np.atleast_1d(np.asarray(chainage_m, float))
        if self.mode != "mask":
            return np.full((len(s), 1), self.cutoff_deg, np.float32)
        az = np.asarray(self.masks.az_deg, float)
        table = self.masks.mask_at(s[:, None], az[None, :])
        return np.asarray(np.broadcast_to(table, (len(s), len(az))), np.float32)

    def bins(self, az_deg: ArrayLike) -> NDArray:
        """Azimuth bin of each direction (all 0 without masks), integer array like ``az_deg``."""
        if self.mode != "mask":
            return np.zeros(np.shape(az_deg), np.intp)
        return np.asarray(self.masks.bin_index(az_deg), np.intp)

    def trusted(self, chainage_m: ArrayLike, az_deg: ArrayLike, el_deg: ArrayLike) -> NDArray:
        """Trusted directions, bool, broadcast shape of the inputs (NaN elevation: False)."""
        s, az, el = np.broadcast_arrays(
            np.asarray(chainage_m, float), np.asarray(az_deg, float), np.asarray(el_deg, float)
        )
        ok = np.isfinite(el) & np.isfinite(az)
        if self.mode != "mask":
            return ok & (np.where(ok, el, -np.inf) > self.cutoff_deg)
        thr = np.asarray(self.masks.mask_at(s, np.where(ok, az, 0.0)), float)
        return ok & (np.where(ok, el, -np.inf) > thr)

    def opening_angle_deg(self, n_pos: int) -> NDArray:
        """Cross-track opening angle per position: 180 deg minus the left and right limits."""
        if self.mode == "mask":
            return np.asarray(self.masks.opening_angle_deg(), float)
        return np.full(n_pos, 180.0 - 2.0 * max(self.cutoff_deg, 0.0))


# --------------------------------------------------------------------------- embedded day
def default_ephemeris() -> Ephemeris:
    """The embedded navigation day: IGS station Esbjerg (DK), 2020-06-25, all constellations.

    RINEX 3.05 mixed broadcast navigation (GPS, GLONASS, Galileo, BeiDou, QZSS; SBAS skipped)
    from the georust/rinex test resources (MIT / Apache-2.0; see
    ``predisat/data/nav/ATTRIBUTION.md``). Use :func:`default_window` for its day.
    """
    ref = resources.files("predisat") / "data" / "nav" / DEFAULT_NAV_FILE
    with resources.as_file(ref) as path:
        return Ephemeris.from_rinex(path)


def default_window(step_s: float = 30.0) -> NDArray:
    """Epochs of the embedded day, 2020-06-25 00:00 to 24:00 GPST (end excluded), ``gps_s``."""
    if step_s <= 0:
        raise ValueError(f"step_s must be positive, got {step_s}")
    start = float(calendar_to_gps_s(2020, 6, 25))
    return start + np.arange(0.0, 86400.0, step_s)
