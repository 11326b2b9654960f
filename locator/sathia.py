"""SATHIA: satellite-pair hyperboloid / track intersection (the LOCOPROL 1-D algorithm).

Differencing two pseudoranges removes the receiver clock, ``K_ij = rho_i - rho_j``. Every
point whose distances to the two satellites differ by ``K_ij`` lies on one sheet of a
hyperboloid of revolution with the satellites as foci; its intersections with the antenna's
path along the track are where the train may be. Along the path ``x(s)``::

    f_ij(s) = |x(s) - S_i| - |x(s) - S_j| - K_ij,     df_ij/ds = (u_j - u_i) . t

(``u`` unit vectors antenna -> satellite, ``t`` the unit tangent). The roots of ``f_ij`` in a
search window ``[prior - W, prior + W]`` are found together for every pair: ``f`` is
evaluated on a grid of the window (one track evaluation for all pairs), sign changes bracket
the roots and an Illinois (modified regula falsi) iteration refines every bracket at once.

The pair's confidence interval is the connected part of ``{s : |f_ij(s)| <= k sigma_K}`` that
holds the chosen root, bounded by the nearest roots of ``f_ij = +- k sigma_K``
(``sigma_K**2 = sigma_i**2 + sigma_j**2``). A bound that would lie beyond the window is
``-inf``/``+inf`` (the pair does not bound the train there) unless the window ends at a track
end, which then bounds it.

A pair may cut the path several times in the window (a curved track, a blunt pair) or not at
all (a faulty range, a prior far off). Several roots: pairs with a single root give a
consensus chainage (their median), and every ambiguous pair takes the root closest to it
(closest to the prior when no pair is unambiguous); the pair is flagged ``MULTIPLE_ROOTS``.
No root: ``root_m`` is NaN and the pair is flagged ``NO_ROOT``. Its interval is the hull of
``{s : |f_ij(s)| <= k sigma_K}`` within the window (a blunt pair whose root lies beyond the
window still bounds, or fails to bound, the train); when that set is empty the pair
contradicts the window (a faulty range, a prior far off): the bounds are NaN, the pair is
flagged ``EMPTY`` and ``misfit_m`` gives the smallest ``|f|`` over the window.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntFlag
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.kernels import inputs_ok_kernel, pair_kernel, pos_vec_kernel
from predisat.readonly import freeze_array_fields
from predisat.track.map import TrackMap

__all__ = [
    "AntennaPath",
    "PairSolution",
    "PairStatus",
    "all_pairs",
    "range_difference_m",
    "solve_pairs",
]


TABLE_STEP_M = 1.0
"""Step of the antenna-path table that :meth:`AntennaPath.ecef_at` interpolates, metres."""

_WGS84_A_M = 6378137.0
_WGS84_B_M = _WGS84_A_M * (1.0 - 1.0 / 298.257223563)
_INV_AXES2 = np.array([_WGS84_A_M**-2, _WGS84_A_M**-2, _WGS84_B_M**-2])


class PairStatus(IntFlag):
    """Per-pair outcome flags of :func:`solve_pairs` (0 = a single root, bounded interval)."""

    OK = 0
    NO_ROOT = 1  # no intersection in the window
    MULTIPLE_ROOTS = 2  # several intersections; the consistent one was chosen
    UNBOUNDED_LOW = 4  # the interval reaches the window's lower end inside the track
    UNBOUNDED_HIGH = 8  # the interval reaches the window's upper end inside the track
    EMPTY = 16  # no point of the window is within k sigma_K: the pair contradicts the window


@dataclass(frozen=True)
class AntennaPath:
    """The antenna's path along a track: the track axis raised by the antenna height.

    Attributes
    ----------
    track : TrackMap
    antenna_height_m : float
        Height of the antenna phase centre above the track axis along the local vertical.
        Lateral lever arms and cant are not modelled here: they move the antenna across the
        track, which moves each pair's root along it by ``d (u_i - u_j).n`` over the slope; the
        pair intervals bound it only up to the stated map doubt
        (``LocatorConfig.map_doubt_lateral_m``; ``docs/locator.md``, limits).
    """

    track: TrackMap
    antenna_height_m: float = 0.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.antenna_height_m):
            raise ValueError(f"antenna_height_m must be finite, got {self.antenna_height_m}")

    @property
    def length_m(self) -> float:
        """Chainage range of the path, ``[0, length_m]``."""
        return self.track.length_m

    def ecef_at(self, chainage_m: ArrayLike) -> NDArray:
        """Antenna position in ECEF at chainages, shape ``chainage_m.shape + (3,)``, metres.

        Cubic Hermite interpolation of a table of exact positions and tangents every
        :data:`TABLE_STEP_M` (:meth:`exact_ecef_at`): the locator calls this thousands of times
        per second and the track spline is slow to evaluate. The error is ``h^4 / 384`` times
        the fourth derivative of the path: micrometres on railway curvature.
        """
        if isinstance(chainage_m, np.ndarray) and chainage_m.ndim == 0:  # one point, as an array
            x, dx = self.hermite_table
            out = np.empty(3)
            # compiled: the array formula below on one point, bit for bit
            if not pos_vec_kernel(x, dx, float(self.length_m), float(chainage_m), out):
                raise ValueError("chainage_m contains NaN or infinite values")
            return out
        if isinstance(chainage_m, (float, int, np.floating)):  # the loop's scalar calls
            k, v = self._locate_scalar(float(chainage_m))
            _, x, dx = self._table
            v2, v3 = v * v, v * v * v
            return (
                (2 * v3 - 3 * v2 + 1) * x[k] + ((v3 - 2 * v2 + v) * TABLE_STEP_M) * dx[k]
                + (3 * v2 - 2 * v3) * x[k + 1] + ((v3 - v2) * TABLE_STEP_M) * dx[k + 1]
            )  # fmt: skip
        i, u, s = self._locate(chainage_m)
        _, x, dx = self._table
        h = TABLE_STEP_M
        u2, u3 = u * u, u * u * u
        h00, h10 = 2 * u3 - 3 * u2 + 1, (u3 - 2 * u2 + u) * h
        h01, h11 = -2 * u3 + 3 * u2, (u3 - u2) * h
        out = (h00[:, None] * x[i] + h10[:, None] * dx[i] + h01[:, None] * x[i + 1]
               + h11[:, None] * dx[i + 1])  # fmt: skip
        return out.reshape((*s.shape, 3))

    def tangent_ecef_at(self, chainage_m: ArrayLike) -> NDArray:
        """Unit tangent (increasing chainage) in ECEF, shape ``chainage_m.shape + (3,)``."""
        i, u, s = self._locate(chainage_m)
        _, x, dx = self._table
        h = TABLE_STEP_M
        u2 = u * u
        d = ((6 * u2 - 6 * u)[:, None] * (x[i] - x[i + 1]) / h
             + (3 * u2 - 4 * u + 1)[:, None] * dx[i]
             + (3 * u2 - 2 * u)[:, None] * dx[i + 1])  # fmt: skip
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return d.reshape((*s.shape, 3))

    def exact_ecef_at(self, chainage_m: ArrayLike) -> NDArray:
        """Antenna position from the track spline itself (the reference of :meth:`ecef_at`)."""
        axis = self.track.enu_at(chainage_m) @ self._rotation + self._origin_ecef_m
        if self.antenna_height_m == 0.0:
            return axis
        # gradient of x^2/a^2 + y^2/a^2 + z^2/b^2 at the axis point: the ellipsoid normal to
        # within h e^2 / a (2e-9 rad at h = 2 km), far cheaper than a geodetic round trip
        n = axis * _INV_AXES2
        return axis + self.antenna_height_m * n / np.linalg.norm(n, axis=-1, keepdims=True)

    @property
    def hermite_table(self) -> tuple[NDArray, NDArray]:
        """Positions and unit tangents (both ECEF, shape (n, 3)) every :data:`TABLE_STEP_M`
        from chainage 0 (the last node may lie past the end, extended linearly): what
        :meth:`ecef_at` interpolates (and ``locator.kernels`` with it)."""
        _, x, dx = self._table
        return x, dx

    def _locate_scalar(self, chainage_m: float) -> tuple[int, float]:
        if not math.isfinite(chainage_m):
            raise ValueError("chainage_m contains NaN or infinite values")
        c = min(max(chainage_m, 0.0), self.length_m)
        k = min(int(c / TABLE_STEP_M), len(self._table[0]) - 2)
        return k, (c - k * TABLE_STEP_M) / TABLE_STEP_M

    def _locate(self, chainage_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
        """Table interval, fraction within it (chainage clamped to the ends), and the input."""
        s = np.asarray(chainage_m, float)
        if not np.all(np.isfinite(s)):
            raise ValueError("chainage_m contains NaN or infinite values")
        grid = self._table[0]
        c = np.clip(s, 0.0, self.length_m).ravel()
        i = np.minimum((c / TABLE_STEP_M).astype(np.intp), len(grid) - 2)
        return i, (c - grid[i]) / TABLE_STEP_M, s

    @cached_property
    def _table(self) -> tuple[NDArray, NDArray, NDArray]:
        # a uniform grid from 0 whose last node may lie past the end (extended linearly)
        n = int(np.ceil(self.length_m / TABLE_STEP_M)) + 1
        grid = np.arange(max(n, 2), dtype=float) * TABLE_STEP_M
        g = np.minimum(grid, self.length_m)
        x = self.exact_ecef_at(g)
        dx = self.track.tangent_at(g) @ self._rotation  # d(position)/d(chainage): arc length
        x = x + (grid - g)[:, None] * dx
        return grid, x, dx
    # the frame's rotation and origin, computed once (LocalFrame recomputes them per call)
    @cached_property
    def _rotation(self) -> NDArray:
        return self.track.frame.rotation

    @cached_property
    def _origin_ecef_m(self) -> NDArray:
        return self.track.frame.origin_ecef_m


@dataclass(frozen=True)
class PairSolution:
    """Intersections of satellite pairs with the antenna path, one entry per pair.

    Attributes
    ----------
    i, j : ndarray of int, shape (p,)
        Satellite indices of each pair (``K = rho_i - rho_j``).
    k_m : ndarray, shape (p,)
        Measured range difference ``K``, metres.
    sigma_k_m : ndarray, shape (p,)
        ``sqrt(sigma_i**2 + sigma_j**2)``, metres.
    k_sigma : float
        Interval half width in sigmas of ``K``.
    root_m : ndarray, shape (p,)
        Chosen intersection chainage, metres (NaN: no root).
    lo_m, hi_m : ndarray, shape (p,)
        Pair confidence interval, metres (NaN: empty, see ``EMPTY``; ``-inf``/``+inf``:
        unbounded).
    slope : ndarray, shape (p,)
        ``df/ds = (u_j - u_i) . t`` at the root: metres of range difference per metre of
        chainage; small means a blunt intersection.
    n_roots : ndarray of int, shape (p,)
        Number of intersections in the window.
    misfit_m : ndarray, shape (p,)
        Smallest ``|f|`` on the search grid (0 when a root exists).
    status : ndarray of uint8, shape (p,)
        :class:`PairStatus` flags.
    """

    i: NDArray
    j: NDArray
    k_m: NDArray
    sigma_k_m: NDArray
    k_sigma: float
    root_m: NDArray
    lo_m: NDArray
    hi_m: NDArray
    slope: NDArray
    n_roots: NDArray
    misfit_m: NDArray
    status: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def n_pairs(self) -> int:
        return int(self.i.size)

    @property
    def length_m(self) -> NDArray:
        """Interval lengths ``hi - lo``, shape (p,)."""
        return self.hi_m - self.lo_m

    @property
    def valid(self) -> NDArray:
        """Pairs with a root and a bounded interval, bool (p,)."""
        return np.isfinite(self.root_m) & np.isfinite(self.lo_m) & np.isfinite(self.hi_m)

    def contains(self, chainage_m: ArrayLike) -> NDArray:
        """Whether each pair interval holds ``chainage_m`` (broadcast against (p,))."""
        s = np.asarray(chainage_m, float)
        return (self.lo_m <= s) & (s <= self.hi_m)

    def take(self, index: ArrayLike) -> PairSolution:
        """The pairs at ``index`` (int or bool array)."""
        k = np.asarray(index)
        return PairSolution(
            self.i[k], self.j[k], self.k_m[k], self.sigma_k_m[k], self.k_sigma, self.root_m[k],
            self.lo_m[k], self.hi_m[k], self.slope[k], self.n_roots[k], self.misfit_m[k],
            self.status[k],
        )  # fmt: skip


def all_pairs(n_sat: int) -> NDArray:
    """Every pair ``(i, j)``, ``i < j``, of ``n_sat`` satellites, shape (n_sat*(n_sat-1)/2, 2)."""
    i, j = np.triu_indices(int(n_sat), 1)
    return np.stack([i, j], axis=-1)


def range_difference_m(x_ecef_m: ArrayLike, sat_i_m: ArrayLike, sat_j_m: ArrayLike) -> NDArray:
    """``|x - S_i| - |x - S_j|``, broadcasting ``(..., 3)`` inputs, metres."""
    x = np.asarray(x_ecef_m, float)
    return np.linalg.norm(x - np.asarray(sat_i_m), axis=-1) - np.linalg.norm(
        x - np.asarray(sat_j_m), axis=-1
    )


def solve_pairs(
    path: AntennaPath,
    sat_ecef_m: ArrayLike,
    pseudorange_m: ArrayLike,
    sigma_m: ArrayLike,
    pairs: ArrayLike | None = None,
    *,
    prior_m: float,
    window_m: float = 1000.0,
    k_sigma: float = 2.0,
    step_m: float = 5.0,
    bias_bound_m: ArrayLike | None = None,
) -> PairSolution:
    """Intersect satellite-pair hyperboloids with the antenna path (one epoch).

    Parameters
    ----------
    path : AntennaPath
    sat_ecef_m : array_like, shape (n_sat, 3)
        Satellite positions at transmission, expressed in ECEF at reception, metres.
    pseudorange_m : array_like, shape (n_sat,)
        Corrected pseudoranges, metres (the receiver clock is common to all).
    sigma_m : array_like, shape (n_sat,)
        Pseudorange sigmas, metres (e.g. :meth:`predisat.availability.interval.ErrorModel.sigma_m`).
    pairs : array_like of int, shape (p, 2), optional
        Pairs to solve; default every pair.
    prior_m : float
        Centre of the search window (previous estimate, odometry, ...), chainage in metres.
    window_m : float
        Half width ``W`` of the search window; clipped to the track.
    k_sigma : float
        Interval half width in sigmas of ``K``.
    step_m : float
        Grid step of the root bracketing. Two roots closer than this may be missed (only at a
        near-tangent, where the pair is blunt anyway).
    bias_bound_m : array_like, shape (n_pairs,), optional
        A bound on each pair's range-difference bias beyond its noise, metres, added to its
        band: ``|f| <= k sigma_K + bias`` (the antenna up to a distance beside or above the
        path, :attr:`locator.fde.LocatorConfig.map_doubt_lateral_m`). Default none.

    Returns
    -------
    PairSolution
    """
    sat = np.asarray(sat_ecef_m, float)
    rho = np.asarray(pseudorange_m, float)
    sig = np.asarray(sigma_m, float)
    n = sat.shape[0] if sat.ndim == 2 else -1
    pr = all_pairs(max(n, 0)) if pairs is None else np.asarray(pairs, np.intp).reshape(-1, 2)
    i, j = pr[:, 0], pr[:, 1]
    i64, j64 = np.ascontiguousarray(i, np.int64), np.ascontiguousarray(j, np.int64)
    # one compiled pass over the arrays; the checks below name what is wrong when it fails
    if not (sat.shape == (n, 3) and rho.shape == sig.shape == (n,)
            and window_m > 0 and step_m > 0 and k_sigma > 0 and math.isfinite(prior_m)
            and inputs_ok_kernel(sat, rho, sig, i64, j64)):  # fmt: skip
        n = _check_inputs(sat, rho, sig)
        _check_options(pr, n, prior_m, window_m, k_sigma, step_m)
    length = path.length_m
    a = min(max(float(prior_m - window_m), 0.0), length)  # np.clip's result, without its cost
    b = min(max(float(prior_m + window_m), 0.0), length)
    n_step = max(int(np.ceil((b - a) / step_m)), 1)
    grid = np.linspace(a, b, n_step + 1)
    x, dx = path.hermite_table
    # compiled (locator.kernels): the same arithmetic as the numpy code it replaced, bit for bit
    if bias_bound_m is None:
        extra = np.zeros(len(i))
    else:
        extra = np.ascontiguousarray(bias_bound_m, float)
        if extra.shape != (len(i),) or not (np.isfinite(extra).all() and (extra >= 0).all()):
            raise ValueError(f"bias_bound_m must be finite and >= 0, one per pair ({len(i)},), "
                             f"got shape {extra.shape}")  # fmt: skip
    k, sk, chosen, lo, hi, slope, n_roots, misfit, status, bad = pair_kernel(
        x, dx, float(length), a, b, grid, sat, rho, sig, i64, j64, float(k_sigma),
        float(prior_m), 1e-4, 30, extra,
    )  # fmt: skip
    if bad:
        raise ValueError("chainage_m contains NaN or infinite values")
    return PairSolution(
        i=i, j=j, k_m=k, sigma_k_m=sk, k_sigma=float(k_sigma), root_m=chosen, lo_m=lo, hi_m=hi,
        slope=slope, n_roots=n_roots, misfit_m=misfit, status=status,
    )  # fmt: skip


# ---------------------------------------------------------------------- helpers


def _check_inputs(sat: NDArray, rho: NDArray, sig: NDArray) -> int:
    if sat.ndim != 2 or sat.shape[-1] != 3:
        raise ValueError(f"sat_ecef_m must have shape (n_sat, 3), got {sat.shape}")
    n = sat.shape[0]
    if rho.shape != (n,) or sig.shape != (n,):
        raise ValueError(
            f"pseudorange_m and sigma_m must have shape ({n},) like sat_ecef_m; got "
            f"{rho.shape} and {sig.shape}"
        )
    bad = ~(np.isfinite(sat).all(-1) & np.isfinite(rho) & np.isfinite(sig) & (sig > 0))
    if bad.any():
        raise ValueError(
            f"satellite {int(np.flatnonzero(bad)[0])} has a NaN position, pseudorange or a "
            "non-positive sigma; drop it before solving (see locator.selection)"
        )
    return n


def _check_options(
    pr: NDArray, n: int, prior_m: float, window_m: float, k_sigma: float, step_m: float
) -> None:
    if pr.size and (pr.min() < 0 or pr.max() >= n or np.any(pr[:, 0] == pr[:, 1])):
        raise ValueError(f"pairs must hold two distinct satellite indices in [0, {n}); got {pr}")
    if not (window_m > 0 and step_m > 0 and k_sigma > 0):
        raise ValueError(
            f"window_m, step_m and k_sigma must be positive: {window_m}, {step_m}, {k_sigma}"
        )
    if not np.isfinite(prior_m):
        raise ValueError(f"prior_m must be finite, got {prior_m}")

