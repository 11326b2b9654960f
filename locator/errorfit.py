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

:func:`binned_sigma` gives the empirical sigma per elevation bin for the figure.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.observations import Observations
from locator.sim.simfile import SignalState, SimRun
from locator.sources import RinexSource
from predisat.geodesy import ecef_to_geodetic, enu_rotation, enu_to_azel
from predisat.gnss.errormodel import ErrorModel

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["binned_sigma", "calibration_figure", "sim_residuals", "static_residuals"]

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
