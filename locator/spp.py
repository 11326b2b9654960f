"""Reference 3-D single point positioning: weighted least squares on corrected pseudoranges.

The general position fix the 1-D locator is compared with: per epoch, unknowns ECEF x, y, z and
one receiver clock offset per satellite system, from the single-frequency model of
:mod:`locator.corrections`. Satellites below ``el_mask_deg`` or without usable navigation data
are excluded and the reason is kept; an epoch that cannot be solved is reported by file, line
and epoch, never dropped silently.

Weights follow RTKLIB's default code variance ``a^2 + b^2 / sin^2(el)`` (a = b = 0.3 m) plus a
quarter of the Klobuchar delay squared (the model removes about half of the ionosphere).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.corrections import CorrectedRanges, RangeModel
from locator.observations import Observations, ObsProblem
from predisat.geodesy import ecef_to_geodetic

__all__ = ["PositionFix", "first_guess", "solve_epoch", "solve_observations"]


@dataclass(frozen=True)
class PositionFix:
    """One epoch's least-squares solution.

    Attributes
    ----------
    gps_s : float
    ecef_m : ndarray, shape (3,)
        NaN when not solved.
    clock_m : mapping of system letter to metres
        Receiver clock offset times c, per system.
    sats_used : tuple of str
    residuals_m : ndarray, shape (n_used,)
        Post-fit residuals of the used satellites.
    pdop : float
    n_iter : int
    status : str
        ``"ok"`` or why no solution.
    excluded : mapping of satellite to reason
    ranges : CorrectedRanges or None
        The final model evaluation, with every correction term.
    """

    gps_s: float
    ecef_m: NDArray
    clock_m: Mapping[str, float]
    sats_used: tuple[str, ...]
    residuals_m: NDArray
    pdop: float
    n_iter: int
    status: str
    excluded: Mapping[str, str]
    ranges: CorrectedRanges | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def _failed(gps_s: float, status: str, excluded: Mapping[str, str], n_iter: int) -> PositionFix:
    return PositionFix(
        gps_s, np.full(3, np.nan), {}, (), np.zeros(0), np.nan, n_iter, status, dict(excluded)
    )


def solve_epoch(
    model: RangeModel,
    gps_s: float,
    sats: Sequence[str],
    pseudorange_m: ArrayLike,
    codes: str | Sequence[str] = "C1C",
    x0_ecef_m: ArrayLike | None = None,
    el_mask_deg: float = 10.0,
    max_iter: int = 10,
    tol_m: float = 1e-4,
) -> PositionFix:
    """Position and receiver clocks of one epoch by iterated weighted least squares.

    Parameters
    ----------
    model : RangeModel
    gps_s : float
        Reception epoch.
    sats : sequence of str, length n_sat
    pseudorange_m : array_like, shape (n_sat,)
    codes : str or sequence of str
        Observation code per pseudorange.
    x0_ecef_m : array_like, shape (3,), optional
        First guess (default: the Earth's centre; the atmosphere and the elevation mask are
        applied once the guess is within 100 km of the surface).
    el_mask_deg : float
    max_iter : int
    tol_m : float
        Stop when the position update is below this.
    """
    states = model.states(gps_s, sats, pseudorange_m, codes)
    x = np.zeros(3) if x0_ecef_m is None else np.asarray(x0_ecef_m, float).copy()
    if not np.all(np.isfinite(x)):
        x = np.zeros(3)
    sats = states.sats
    excluded: dict[str, str] = {}
    for it in range(1, max_iter + 1):
        near = bool(6.2e6 < np.linalg.norm(x) < 6.5e6)
        cr = model.correct(gps_s, sats, pseudorange_m, x, codes, states, atmosphere=near)
        use = cr.usable.copy()
        if near:
            use &= cr.el_deg >= el_mask_deg
        excluded = {s: r for s, r, u in zip(sats, cr.reason, use, strict=True) if not u and r}
        if near:
            excluded.update(
                {
                    s: f"elevation {e:.1f} deg below the mask"
                    for s, e, u, r in zip(sats, cr.el_deg, use, cr.reason, strict=True)
                    if not u and not r
                }
            )
        systems = sorted({s[0] for s, u in zip(sats, use, strict=True) if u})
        n_use = int(use.sum())
        if n_use < 3 + len(systems) or not systems:
            return _failed(
                gps_s, f"{n_use} usable satellites for {3 + len(systems)} unknowns", excluded, it
            )
        los = (cr.sat_ecef_m[use] - x) / cr.range_m[use, None]
        sys_of = np.array([systems.index(s[0]) for s, u in zip(sats, use, strict=True) if u])
        h = np.zeros((n_use, 3 + len(systems)))
        h[:, :3] = -los
        h[np.arange(n_use), 3 + sys_of] = 1.0
        # clocks enter linearly: each pass estimates them whole, only the position is updated
        y = cr.corrected_m[use] - cr.range_m[use]
        sin_el = np.sin(np.radians(cr.el_deg[use])) if near else np.ones(n_use)
        var = 0.09 + 0.09 / sin_el**2 + (0.5 * cr.iono_m[use]) ** 2
        w = 1.0 / var
        hw = h * w[:, None]
        try:
            cov = np.linalg.inv(h.T @ hw)
        except np.linalg.LinAlgError:
            return _failed(gps_s, "singular geometry", excluded, it)
        dx = cov @ (hw.T @ y)
        x = x + dx[:3]
        clocks = dx[3:]
        if np.linalg.norm(dx[:3]) < tol_m and near:
            res = y - h @ dx
            cr = model.correct(gps_s, sats, pseudorange_m, x, codes, states, atmosphere=True)
            pdop = float(np.sqrt(np.trace(np.linalg.inv(h.T @ h)[:3, :3])))
            used = tuple(s for s, u in zip(sats, use, strict=True) if u)
            clock_m = {s: float(c) for s, c in zip(systems, clocks, strict=True)}
            return PositionFix(gps_s, x, clock_m, used, res, pdop, it, "ok", excluded, cr)
    return _failed(gps_s, f"not converged after {max_iter} iterations", excluded, max_iter)


def first_guess(obs: Observations) -> NDArray | None:
    """The header's approximate position (ECEF m, shape (3,)) as a fix's first guess, or None
    when it is missing (RINEX writes 0 0 0) or not near the Earth's surface."""
    hx = obs.header.approx_position_ecef_m
    return hx if np.all(np.isfinite(hx)) and np.linalg.norm(hx) > 6e6 else None


def solve_observations(
    model: RangeModel,
    obs: Observations,
    el_mask_deg: float = 10.0,
    priority: Mapping[str, Sequence[str]] | None = None,
    epochs: ArrayLike | None = None,
) -> tuple[pd.DataFrame, list[ObsProblem]]:
    """Solve every epoch of an observation file (or those indexed by ``epochs``).

    Returns
    -------
    table : pandas.DataFrame
        One row per epoch: ``gps_s``, ``x_m``, ``y_m``, ``z_m``, ``lat_deg``, ``lon_deg``,
        ``h_m``, ``n_used``, ``pdop``, ``status``.
    problems : list of ObsProblem
        Epochs without a solution and satellites without usable navigation data, by file,
        line and epoch.
    """
    sel = obs.pseudorange(priority)
    m = model.with_glonass_slots(obs.header.glonass_slots)
    if len(obs.gps_s):  # the ionosphere of the observations' day, not of the first file listed
        m = m.with_iono_near(float(np.median(obs.gps_s)))
    x0 = first_guess(obs)
    rows, problems = [], []
    index = np.arange(len(obs.gps_s)) if epochs is None else np.asarray(epochs, int)
    for i in index:
        t = obs.gps_s[i]
        have = np.isfinite(sel.pseudorange_m[i])
        sats = [s for s, h in zip(obs.sats, have, strict=True) if h]
        codes = list(sel.code[i, have])
        line = int(obs.epoch_line[i])
        if not sats:
            problems.append(ObsProblem(obs.path, line, float(t), "no usable pseudorange"))
            rows.append({"gps_s": t, "status": "no pseudorange", "n_used": 0})
            continue
        fix = solve_epoch(
            model=m,
            gps_s=float(t),
            sats=sats,
            pseudorange_m=sel.pseudorange_m[i, have],
            codes=codes,
            x0_ecef_m=x0,
            el_mask_deg=el_mask_deg,
        )
        nav = {s: r for s, r in fix.excluded.items() if not r.startswith(("elevation", "below"))}
        if nav:
            problems.append(
                ObsProblem(
                    obs.path,
                    line,
                    float(t),
                    "no usable navigation data: " + ", ".join(f"{s} ({r})" for s, r in nav.items()),
                )
            )
        if not fix.ok:
            problems.append(ObsProblem(obs.path, line, float(t), f"no position: {fix.status}"))
        else:
            x0 = fix.ecef_m
        lat, lon, h = ecef_to_geodetic(fix.ecef_m)
        rows.append(
            {
                "gps_s": t,
                "x_m": fix.ecef_m[0],
                "y_m": fix.ecef_m[1],
                "z_m": fix.ecef_m[2],
                "lat_deg": float(lat),
                "lon_deg": float(lon),
                "h_m": float(h),
                "n_used": len(fix.sats_used),
                "pdop": fix.pdop,
                "status": fix.status,
            }
        )
    return pd.DataFrame(rows), problems
