"""Smooth fit of a track axis: a penalised cubic B-spline through a simplified polyline.

A published track axis is a polyline simplified to a tolerance (Douglas-Peucker), with kinks at
every vertex. :func:`fit_curve` resamples it by chord length, fits a P-spline (Eilers & Marx
1996) with the largest penalty that keeps every sample within the tolerance, horizontally and
in height separately, and parameterises the result by arc length (the chainage of
:class:`predisat.track.map.TrackMap`). See ``docs/track-map.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline, CubicHermiteSpline
from scipy.linalg import solveh_banded
from scipy.spatial import cKDTree

from predisat.geodesy import LocalFrame
from predisat.readonly import freeze_array_fields

__all__ = ["FittedCurve", "dense_polyline", "fit_curve"]

_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(5)


@dataclass(frozen=True)
class FittedCurve:
    """The fitted axis: position ``r(t)`` in frame ENU and the map ``t(s)`` from arc length.

    Attributes
    ----------
    spline : BSpline
        ``t -> (e, n, u)`` in the frame, metres; ``t`` is the chord length of the source.
    t_of_s : CubicHermiteSpline
        Chainage (arc length of ``spline``) to ``t``.
    length_m : float
        Arc length of the whole curve.
    node_s_m, node_enu_m, node_up : ndarray, shapes (k,), (k, 3), (k, 3)
        Nodes every ~1 m of ``t``: their chainage, position and local vertical (unit, in the
        frame), the starting points of projection.
    node_up_rows : ndarray, shape (3, k)
        ``node_up`` one contiguous row per component (``np.interp`` copies a strided column
        on every call: most of a one-point projection's time).
    tree : cKDTree
        Horizontal (e, n) index of the nodes.
    max_vertical_deviation_m : float
        Largest height residual of the fit at its samples.
    lam_h, lam_v : float
        The chosen horizontal and vertical penalties.
    """

    spline: BSpline
    t_of_s: CubicHermiteSpline
    length_m: float
    node_s_m: NDArray
    node_enu_m: NDArray
    node_up: NDArray
    node_up_rows: NDArray
    tree: cKDTree
    max_vertical_deviation_m: float
    lam_h: float
    lam_v: float

    def __post_init__(self) -> None:
        freeze_array_fields(self)


def dense_polyline(enu: NDArray, spacing_m: float) -> tuple[NDArray, NDArray, NDArray]:
    """Resample a polyline so that no step exceeds ``spacing_m``.

    Returns the chord-length parameter ``t`` (n,), the points (n, 3) and the indices of the
    source vertices in them.
    """
    seg = np.linalg.norm(np.diff(enu, axis=0), axis=1)
    n_sub = np.maximum(1, np.ceil(seg / spacing_m).astype(int))
    starts = np.repeat(np.arange(len(seg)), n_sub)
    frac = np.concatenate([np.arange(k) / k for k in n_sub])
    out = np.concatenate([enu[starts] + frac[:, None] * np.diff(enu, axis=0)[starts], enu[-1:]])
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(out, axis=0), axis=1))])
    return t, out, np.concatenate([[0], np.cumsum(n_sub)])


class _PSpline:
    """Penalised cubic B-spline (P-spline) on uniform knots, prepared once for many penalties.

    Minimises ``sum w (y - f(t))^2 + lam * sum (second difference of coefficients)^2``; the
    difference penalty approximates ``h^3 * integral f''^2`` (Eilers & Marx 1996).
    """

    def __init__(self, t: NDArray, w: NDArray, knot_step_m: float) -> None:
        n_int = max(1, int(np.ceil(t[-1] / knot_step_m)))
        h = t[-1] / n_int
        self.knots = h * np.arange(-3, n_int + 4, dtype=float)
        self.knots[3], self.knots[-4] = 0.0, t[-1]  # exact ends for design_matrix's bounds
        self.t = t
        self.design = BSpline.design_matrix(np.clip(t, 0.0, t[-1]), self.knots, 3).tocsr()
        self.w = w
        gram = (self.design.T @ self.design.multiply(w[:, None])).todia()
        m = self.design.shape[1]
        self.band = np.zeros((4, m))  # upper banded form for solveh_banded
        for off in range(4):
            diag = gram.diagonal(off)
            self.band[3 - off, off:] = diag
        d2 = np.zeros((4, m))  # D^T D of the second-difference operator, upper banded
        if m <= 4:  # dense: (m - 2, m) for a long track would not fit in memory
            dd = np.zeros((m - 2, m))
            rows = np.arange(m - 2)
            dd[rows, rows], dd[rows, rows + 1], dd[rows, rows + 2] = 1.0, -2.0, 1.0
            dtd = dd.T @ dd
            for off in range(min(4, m)):
                d2[3 - off, off:] = np.diagonal(dtd, off)
        else:
            main = np.full(m, 6.0)
            main[[0, -1]], main[[1, -2]] = 1.0, 5.0
            first = np.full(m - 1, -4.0)
            first[[0, -1]] = -2.0
            d2[3], d2[2, 1:], d2[1, 2:] = main, first, 1.0
        self.penalty = d2

    def fit(self, y: NDArray, lam: float) -> tuple[BSpline, float]:
        """Spline for ``y`` (n,) or (n, k) and its largest residual (norm over k)."""
        rhs = self.design.T @ (self.w.reshape((-1,) + (1,) * (y.ndim - 1)) * y)
        coef = solveh_banded(self.band + lam * self.penalty, rhs)
        res = self.design @ coef - y
        worst = np.abs(res) if res.ndim == 1 else np.linalg.norm(res, axis=1)
        return BSpline(self.knots, coef, 3, extrapolate=True), float(np.max(worst))


def _largest_lam(ps: _PSpline, y: NDArray, tol: float) -> tuple[BSpline, float, float]:
    """The fit with the largest penalty whose largest residual stays within ``tol``.

    Returns the spline, its ``lam`` and its largest residual.
    """
    # log10(lam): near-interpolating to nearly straight; higher penalties lose precision.
    lo, hi = -3.0, 7.0
    best = ps.fit(y, 10.0**lo)
    if best[1] > tol:
        return best[0], 10.0**lo, best[1]
    top = ps.fit(y, 10.0**hi)
    if top[1] <= tol:
        return top[0], 10.0**hi, top[1]
    while hi - lo > 0.05:
        mid = 0.5 * (lo + hi)
        cand = ps.fit(y, 10.0**mid)
        if cand[1] <= tol:
            lo, best = mid, cand
        else:
            hi = mid
    return best[0], 10.0**lo, best[1]


_FIT_SPACING_M = 2.0
# Weight of the resampled chord points relative to the source vertices. Douglas-Peucker keeps
# real vertices of the line, so the fit should lean on them; the chord points only keep the
# curve within tolerance between sparse vertices (see docs/track-map.md for the comparison).
_CHORD_WEIGHT = 0.03
_KNOT_STEP_M = 4.0


def fit_curve(enu: NDArray, frame: LocalFrame, tol_h: float, tol_v: float) -> FittedCurve:
    """Smooth 3-D axis through a polyline, with arc-length parameterisation and a node index.

    Parameters
    ----------
    enu : ndarray, shape (n, 3)
        Source vertices in ``frame`` ENU, metres, in order of increasing chainage, without
        repeated vertices.
    frame : LocalFrame
        The frame of ``enu`` (used to smooth heights as heights above the ellipsoid).
    tol_h, tol_v : float
        Largest horizontal and vertical residual allowed at the fit samples, metres.

    Returns
    -------
    FittedCurve
    """
    t, pts, vidx = dense_polyline(enu, _FIT_SPACING_M)
    w = np.full(t.shape, _CHORD_WEIGHT)
    w[vidx] = 1.0
    ps = _PSpline(t, w, _KNOT_STEP_M)
    spl_h, lam_h, _ = _largest_lam(ps, pts[:, :2], tol_h)
    # Heights are smoothed as heights: the frame's "up" drops by s^2 / 2R along the line (15 m
    # over 14 km), which a smoothing penalty would otherwise flatten.
    lat, lon, _ = frame.to_geodetic(pts)
    base = frame.to_enu(lat, lon, np.zeros_like(lat))[:, 2]
    spl_v, lam_v, dev_v = _largest_lam(ps, pts[:, 2] - base, tol_v)
    spl_b, _ = ps.fit(base, 1e-3)  # smooth by construction: near-interpolation keeps its sag
    coef_u = np.asarray(spl_v.c) + np.asarray(spl_b.c)
    coef = np.concatenate([np.asarray(spl_h.c), coef_u[:, None]], axis=1)
    spline = BSpline(ps.knots, coef, 3, extrapolate=True)

    # Arc length on a ~1 m grid of t by 5-point Gauss-Legendre per step (exact to ~1e-12 m).
    n_step = max(4, int(np.ceil(t[-1] / 1.0)))
    tk = np.linspace(0.0, t[-1], n_step + 1)
    a, b = tk[:-1], tk[1:]
    tq = 0.5 * (b - a)[:, None] * _GAUSS_X[None, :] + 0.5 * (a + b)[:, None]
    speed = np.linalg.norm(np.asarray(spline(tq, 1)), axis=-1)
    seg = 0.5 * (b - a) * (speed @ _GAUSS_W)
    sk = np.concatenate([[0.0], np.cumsum(seg)])
    speed_k = np.linalg.norm(np.asarray(spline(tk, 1)), axis=-1)
    t_of_s = CubicHermiteSpline(sk, tk, 1.0 / speed_k, extrapolate=True)

    node_enu = np.asarray(spline(tk))
    lat, lon, _ = frame.to_geodetic(node_enu)
    node_up = frame.rotation_from(lat, lon)[..., :, 2]
    return FittedCurve(
        spline=spline,
        t_of_s=t_of_s,
        length_m=float(sk[-1]),
        node_s_m=sk,
        node_enu_m=node_enu,
        node_up=node_up,
        node_up_rows=np.ascontiguousarray(node_up.T),
        tree=cKDTree(node_enu[:, :2]),
        max_vertical_deviation_m=dev_v,
        lam_h=lam_h,
        lam_v=lam_v,
    )
