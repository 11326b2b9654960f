"""A simulated train run with ground truth, and its file format (``locator.simrun/1``).

:class:`SimRun` holds what :func:`locator.sim.simulate.simulate_run` produces: per epoch the true
train state and receiver clock, per (epoch, satellite) the satellite position, the corrected
pseudorange the locator consumes and every error term that went into it. On disk a run is a
folder of three files (format in ``docs/simulation.md``)::

    run/
      meta.json          format, satellites, frame, models, seeds, world recipe
      epochs.parquet     one row per epoch (or epochs.csv)
      signals.parquet    one row per (epoch, satellite above the horizon) (or signals.csv)

:meth:`SimRun.write` writes it (Parquet by default, CSV on request) and :meth:`SimRun.read`
reads either back.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from enum import IntEnum
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import pyarrow as pa
from numpy.typing import NDArray

from predisat.geodesy import ecef_to_geodetic
from predisat.jsontypes import JsonDict
from predisat.readonly import readonly_array
from predisat.synth.materials import MATERIALS

__all__ = [
    "SIMRUN_FORMAT",
    "EpochObservations",
    "SignalState",
    "SimRun",
    "SimRunError",
    "json_default",
    "read_folder_table",
]

SIMRUN_FORMAT = "locator.simrun/1"


class SignalState(IntEnum):
    """What reaches the antenna from a satellite at an epoch."""

    NOT_VISIBLE = 0  # below the horizon or no trusted ephemeris: not simulated
    LOS = 1  # direct signal tracked (possibly with multipath)
    NLOS = 2  # direct path blocked, a reflection tracked: biased pseudorange
    LOST = 3  # nothing tracked (blocked and no usable reflection)


class SimRunError(ValueError):
    """A simulated-run folder that cannot be read; the message names the file and the fix."""


class EpochObservations(NamedTuple):
    """The received signals of one epoch, as the locator takes them."""

    sats: tuple[str, ...]
    sat_ecef_m: NDArray  # (k, 3)
    corrected_m: NDArray  # (k,)
    el_deg: NDArray  # (k,)
    sigma_m: NDArray  # (k,)


_EPOCH_VECTORS = {"antenna_ecef_m": ("x_m", "y_m", "z_m"), "antenna_enu_m": ("e_m", "n_m", "u_m")}
_EPOCH_SCALARS = ("gps_s", "chainage_m", "speed_mps", "heading_deg", "clock_bias_m",
                  "clock_drift_mps")  # fmt: skip
_SIGNAL_SCALARS = ("az_deg", "el_deg", "range_m", "corrected_m", "sigma_m", "cn0_dbhz",
                   "noise_m", "multipath_m", "nlos_extra_m", "reflection_delay_m")  # fmt: skip
_SIGNAL_VECTORS = {
    "sat_ecef_m": ("sat_x_m", "sat_y_m", "sat_z_m"),
    "reflection_point_enu_m": ("reflection_e_m", "reflection_n_m", "reflection_u_m"),
}
_STATE_NAMES = {s: s.name.lower() for s in SignalState}


@dataclass(frozen=True, eq=False)
class SimRun:
    """A simulated run: truth per epoch, measurements and truth per (epoch, satellite).

    Arrays of shape (n_epoch, n_sat) hold NaN (or -1 for integers) where the satellite is
    not visible; the measurement fields also where the signal is lost.

    Attributes
    ----------
    gps_s : ndarray, shape (n_epoch,)
        True reception epochs (the receiver tags its epochs in GPS time; its clock offset
        appears in the ranges only).
    chainage_m, speed_mps : ndarray, shape (n_epoch,)
        True chainage of the antenna's track point and train speed (>= 0).
    heading_deg : ndarray, shape (n_epoch,)
        Azimuth of the direction of travel.
    antenna_ecef_m, antenna_enu_m : ndarray, shape (n_epoch, 3)
        True antenna position, ECEF and in the world's frame.
    clock_bias_m, clock_drift_mps : ndarray, shape (n_epoch,)
        Receiver clock offset times c, and its rate.
    sats : tuple of str, length n_sat
    state : ndarray of int8, shape (n_epoch, n_sat)
        :class:`SignalState`.
    sat_ecef_m : ndarray, shape (n_epoch, n_sat, 3)
        Satellite at transmission, in the Earth-fixed frame of reception (as
        :class:`locator.corrections.CorrectedRanges.sat_ecef_m`).
    az_deg, el_deg : ndarray, shape (n_epoch, n_sat)
        True direction from the antenna.
    range_m : ndarray, shape (n_epoch, n_sat)
        True geometric range antenna - satellite.
    corrected_m : ndarray, shape (n_epoch, n_sat)
        The corrected pseudorange ``range_m + clock_bias_m + noise_m + multipath_m +
        nlos_extra_m`` (LOS and NLOS only).
    sigma_m : ndarray, shape (n_epoch, n_sat)
        Standard deviation of ``noise_m``.
    cn0_dbhz : ndarray, shape (n_epoch, n_sat)
        C/N0 of the tracked signal (of the best reflection when lost, NaN if none).
    noise_m, multipath_m, nlos_extra_m : ndarray, shape (n_epoch, n_sat)
        Error terms: noise, code multipath of a direct signal, extra path of a tracked
        reflection (0 for LOS).
    reflection_delay_m : ndarray, shape (n_epoch, n_sat)
        Extra path of the strongest reflection found (LOS: the multipath's; NLOS: equals
        ``nlos_extra_m``; LOST: the too-weak one's), NaN when none.
    reflector_face : ndarray of int64, shape (n_epoch, n_sat)
        Reflecting face of that reflection (index into ``world.faces``), -1 when none.
    reflector_material : ndarray of int16, shape (n_epoch, n_sat)
        Its material id (index into :data:`predisat.synth.world.MATERIALS`), -1 when none.
    reflection_point_enu_m : ndarray, shape (n_epoch, n_sat, 3)
        Its reflection point in the world's frame.
    meta : mapping
        Frame, antenna height, rate, seeds, models, world recipe, ephemeris sources.
    """

    gps_s: NDArray
    chainage_m: NDArray
    speed_mps: NDArray
    heading_deg: NDArray
    antenna_ecef_m: NDArray
    antenna_enu_m: NDArray
    clock_bias_m: NDArray
    clock_drift_mps: NDArray
    sats: tuple[str, ...]
    state: NDArray
    sat_ecef_m: NDArray
    az_deg: NDArray
    el_deg: NDArray
    range_m: NDArray
    corrected_m: NDArray
    sigma_m: NDArray
    cn0_dbhz: NDArray
    noise_m: NDArray
    multipath_m: NDArray
    nlos_extra_m: NDArray
    reflection_delay_m: NDArray
    reflector_face: NDArray
    reflector_material: NDArray
    reflection_point_enu_m: NDArray
    meta: Mapping[str, Any] = field(default_factory=dict)  # Any: JSON values (as JsonDict)

    def __post_init__(self) -> None:
        n_ep, n_sat = len(self.gps_s), len(self.sats)
        object.__setattr__(self, "sats", tuple(self.sats))
        for f in fields(self):
            val = getattr(self, f.name)
            if not isinstance(val, np.ndarray):
                continue
            want: tuple[int, ...]
            if f.name in _EPOCH_SCALARS:
                want = (n_ep,)
            elif f.name in _EPOCH_VECTORS:
                want = (n_ep, 3)
            elif f.name in _SIGNAL_VECTORS:
                want = (n_ep, n_sat, 3)
            else:
                want = (n_ep, n_sat)
            if val.shape != want:
                raise ValueError(f"SimRun.{f.name} has shape {val.shape}, expected {want}")
            object.__setattr__(self, f.name, readonly_array(val))

    # ----------------------------------------------------------------- views
    @property
    def n_epoch(self) -> int:
        return len(self.gps_s)

    @property
    def received(self) -> NDArray:
        """Boolean (n_epoch, n_sat): a pseudorange exists (LOS or NLOS)."""
        return (self.state == SignalState.LOS) | (self.state == SignalState.NLOS)

    @property
    def error_m(self) -> NDArray:
        """Total error of the corrected pseudorange beyond the receiver clock, (n_epoch, n_sat)."""
        return self.corrected_m - self.range_m - self.clock_bias_m[:, None]

    def counts(self) -> pd.DataFrame:
        """Number of LOS, NLOS and lost signals per epoch."""
        return pd.DataFrame(
            {s.name.lower(): (self.state == s).sum(axis=1) for s in list(SignalState)[1:]},
            index=pd.Index(self.gps_s, name="gps_s"),
        )

    def observations(self, epoch: int, include_nlos: bool = True) -> EpochObservations:
        """The received signals of one epoch (LOS, and NLOS unless ``include_nlos=False``)."""
        take = self.state[epoch] == SignalState.LOS
        if include_nlos:
            take |= self.state[epoch] == SignalState.NLOS
        j = np.flatnonzero(take)
        return EpochObservations(
            tuple(self.sats[k] for k in j),
            np.array(self.sat_ecef_m[epoch, j]),
            np.array(self.corrected_m[epoch, j]),
            np.array(self.el_deg[epoch, j]),
            np.array(self.sigma_m[epoch, j]),
        )

    # ----------------------------------------------------------------- tables
    def to_frames(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """The ``epochs`` and ``signals`` tables of the file format."""
        ep: dict[str, Any] = {"epoch": np.arange(self.n_epoch)}
        for name in _EPOCH_SCALARS:
            ep[name] = getattr(self, name)
        for name, cols in _EPOCH_VECTORS.items():
            for k, c in enumerate(cols):
                ep[c] = getattr(self, name)[:, k]
        lat, lon, h = ecef_to_geodetic(self.antenna_ecef_m)
        ep.update(lat_deg=lat, lon_deg=lon, h_m=h)
        i, j = np.nonzero(self.state != SignalState.NOT_VISIBLE)
        sig: dict[str, Any] = {
            "epoch": i,
            "gps_s": self.gps_s[i],
            "sat": np.array(self.sats, dtype=object)[j] if self.sats else np.array([], object),
            "state": np.array([_STATE_NAMES[SignalState(int(s))] for s in self.state[i, j]],
                              dtype=object),
        }  # fmt: skip
        for name in _SIGNAL_SCALARS:
            sig[name] = getattr(self, name)[i, j]
        for name, cols in _SIGNAL_VECTORS.items():
            for k, c in enumerate(cols):
                sig[c] = getattr(self, name)[i, j, k]
        sig["reflector_face"] = self.reflector_face[i, j]
        sig["reflector_material"] = _material_names(self.reflector_material[i, j])
        return pd.DataFrame(ep), pd.DataFrame(sig)

    # ----------------------------------------------------------------- files
    def write(self, path: str | Path, fmt: str = "parquet") -> Path:
        """Write the run to the folder ``path`` (created; existing files are replaced).

        Parameters
        ----------
        path : str or Path
        fmt : {"parquet", "csv"}

        Returns
        -------
        Path
            The folder.
        """
        if fmt not in ("parquet", "csv"):
            raise ValueError(f"fmt must be 'parquet' or 'csv', got {fmt!r}")
        out = Path(path)
        out.mkdir(parents=True, exist_ok=True)
        for stale in ("epochs", "signals"):
            for ext in ("parquet", "csv"):
                (out / f"{stale}.{ext}").unlink(missing_ok=True)
        epochs, signals = self.to_frames()
        if fmt == "parquet":
            epochs.to_parquet(out / "epochs.parquet", index=False)
            signals.to_parquet(out / "signals.parquet", index=False)
        else:
            epochs.to_csv(out / "epochs.csv", index=False, float_format="%.17g")
            signals.to_csv(out / "signals.csv", index=False, float_format="%.17g")
        meta = {"format": SIMRUN_FORMAT, "sats": list(self.sats), **dict(self.meta)}
        (out / "meta.json").write_text(json.dumps(meta, indent=2, default=json_default) + "\n")
        return out

    @classmethod
    def read(cls, path: str | Path) -> SimRun:
        """Read a run folder written by :meth:`write` (Parquet or CSV)."""
        folder = Path(path)
        meta_path = folder / "meta.json"
        if not meta_path.is_file():
            raise SimRunError(
                f"{folder}: no meta.json; give the folder written by SimRun.write "
                "(`locator simulate --out FOLDER`)"
            )
        try:
            meta = json.loads(meta_path.read_text())
        except json.JSONDecodeError as exc:
            raise SimRunError(f"{meta_path}: not valid JSON ({exc}); rewrite the run") from exc
        if meta.get("format") != SIMRUN_FORMAT:
            raise SimRunError(
                f"{meta_path}: format {meta.get('format')!r} is not {SIMRUN_FORMAT!r}; "
                "this reader only knows version 1"
            )
        epochs = _read_table(folder, "epochs")
        signals = _read_table(folder, "signals")
        sats = tuple(str(s) for s in meta.pop("sats", []))
        meta.pop("format")
        if "direction" in meta and meta["direction"] not in (1, -1):
            # read by the odometer and the balise captures; a bad value was named nowhere
            raise SimRunError(
                f"{meta_path}: direction {meta['direction']!r} must be 1 (toward increasing "
                "chainage) or -1; rewrite the run with `locator simulate`"
            )
        return _from_frames(folder, epochs, signals, sats, meta)


def json_default(obj: object) -> object:
    """``json.dumps`` ``default`` for numpy scalars and arrays, tuples and sets."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (tuple, set)):
        return list(obj)
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")


def read_folder_table(
    folder: Path,
    name: str,
    error: type[Exception],
    rewrite: str,
    dtype: Mapping[str, type] | None = None,
) -> pd.DataFrame:
    """``name.parquet`` (preferred) or ``name.csv`` from ``folder``, shared by the simulation
    and run readers.

    ``error`` is raised for a missing or unreadable table, naming the file and ``rewrite``
    (the command that writes the folder again); ``dtype`` types CSV columns.
    """
    pq, csv = folder / f"{name}.parquet", folder / f"{name}.csv"
    if pq.is_file():
        try:
            return pd.read_parquet(pq)
        except (pa.ArrowException, OSError) as exc:
            raise error(
                f"{pq}: not a readable Parquet file ({exc}); the folder is damaged, rerun "
                f"{rewrite}"
            ) from None
    if csv.is_file():
        return pd.read_csv(csv, keep_default_na=False, na_values=[""], dtype=dtype)
    raise error(f"{folder}: neither {name}.parquet nor {name}.csv; give a folder written by "
                f"{rewrite}")  # fmt: skip


def _material_names(ids: NDArray) -> NDArray:
    """Material names (object array, ``""`` for -1) of the material ids ``ids``."""
    if not np.any(ids >= 0):
        return np.array([""], dtype=object)[ids]
    return np.array([m.name for m in MATERIALS] + [""], dtype=object)[ids]


def _material_ids(names: pd.Series, where: Path) -> list[int]:
    """Material ids (-1 for ``""``) of the material names ``names``; unknown names raise."""
    named = set(names) - {""}
    if not named:
        return [-1] * len(names)
    mat_ids = {m.name: k for k, m in enumerate(MATERIALS)}
    bad = sorted(named - set(mat_ids))
    if bad:
        raise SimRunError(f"{where}: unknown reflector materials {bad}")
    return [mat_ids.get(m, -1) for m in names]


def _read_table(folder: Path, name: str) -> pd.DataFrame:
    return read_folder_table(folder, name, SimRunError, "`locator simulate`",
                             {"sat": str, "state": str, "reflector_material": str})  # fmt: skip


def _require(df: pd.DataFrame, cols: tuple[str, ...], where: Path) -> None:
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise SimRunError(f"{where}: missing columns {missing}; rewrite the run with SimRun.write")


def _from_frames(
    folder: Path, epochs: pd.DataFrame, signals: pd.DataFrame, sats: tuple[str, ...], meta: JsonDict
) -> SimRun:
    ep_cols = ("epoch", *_EPOCH_SCALARS, *(c for v in _EPOCH_VECTORS.values() for c in v))
    sig_vec = tuple(c for v in _SIGNAL_VECTORS.values() for c in v)
    sig_cols = ("epoch", "sat", "state", *_SIGNAL_SCALARS, "reflector_face",
                "reflector_material", *sig_vec)  # fmt: skip
    _require(epochs, ep_cols, folder / "epochs")
    _require(signals, sig_cols, folder / "signals")
    epochs = epochs.sort_values("epoch")
    n_ep, n_sat = len(epochs), len(sats)
    if not np.array_equal(epochs["epoch"].to_numpy(), np.arange(n_ep)):
        raise SimRunError(f"{folder / 'epochs'}: epoch numbers must be 0..{n_ep - 1} once each")
    kw: dict[str, Any] = {n: epochs[n].to_numpy(float) for n in _EPOCH_SCALARS}
    for name, cols in _EPOCH_VECTORS.items():
        kw[name] = epochs[list(cols)].to_numpy(float)
    sat_index = {s: k for k, s in enumerate(sats)}
    unknown = sorted(set(signals["sat"].astype(str)) - set(sat_index))
    if unknown:
        raise SimRunError(
            f"{folder / 'signals'}: satellites {unknown} are not listed in meta.json 'sats'"
        )
    i = signals["epoch"].to_numpy(int)
    if len(i) and (i.min() < 0 or i.max() >= n_ep):
        raise SimRunError(f"{folder / 'signals'}: epoch numbers outside 0..{n_ep - 1}")
    j = np.array([sat_index[str(s)] for s in signals["sat"]], dtype=np.intp)
    by_name = {v: k for k, v in _STATE_NAMES.items()}
    bad = sorted(set(signals["state"].astype(str)) - set(by_name))
    if bad:
        raise SimRunError(f"{folder / 'signals'}: unknown states {bad}; use {list(by_name)}")
    state = np.zeros((n_ep, n_sat), np.int8)
    state[i, j] = [int(by_name[str(s)]) for s in signals["state"]]
    for name in _SIGNAL_SCALARS:
        arr = np.full((n_ep, n_sat), np.nan)
        arr[i, j] = signals[name].to_numpy(float)
        kw[name] = arr
    for name, cols in _SIGNAL_VECTORS.items():
        arr = np.full((n_ep, n_sat, 3), np.nan)
        arr[i, j] = signals[list(cols)].to_numpy(float)
        kw[name] = arr
    face = np.full((n_ep, n_sat), -1, np.int64)
    face[i, j] = signals["reflector_face"].to_numpy(np.int64)
    mat_names = signals["reflector_material"].fillna("").astype(str)
    mat = np.full((n_ep, n_sat), -1, np.int16)
    mat[i, j] = _material_ids(mat_names, folder / "signals")
    return SimRun(sats=sats, state=state, reflector_face=face, reflector_material=mat,
                  meta=meta, **kw)  # fmt: skip
