"""The 1-D locator's pair solver and WLS as they were until 2026-12-04 (commit 1403519), numpy,
kept verbatim (renamed ``reference_solve_pairs`` / ``reference_solve_wls``; only the section
markers dropped).

They are the baseline of ``scripts/bench_locator_kernels.py`` and a second reference of
``tests/regression/test_locator_reference.py`` (random epochs beyond the frozen ones). They pin
an optimisation, not correctness.
"""

# ruff: noqa
# mypy: ignore-errors
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.sathia import AntennaPath, PairSolution, PairStatus, all_pairs, range_difference_m
from locator.wls import WlsSolution, as_observations

__all__ = ["reference_solve_pairs", "reference_solve_wls"]


def reference_solve_pairs(
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

    Returns
    -------
    PairSolution
    """
    sat = np.asarray(sat_ecef_m, float)
    rho = np.asarray(pseudorange_m, float)
    sig = np.asarray(sigma_m, float)
    n = _check_inputs(sat, rho, sig)
    pr = all_pairs(n) if pairs is None else np.asarray(pairs, np.intp).reshape(-1, 2)
    _check_options(pr, n, prior_m, window_m, k_sigma, step_m)
    i, j = pr[:, 0], pr[:, 1]
    p = len(i)
    length = path.length_m
    a = float(np.clip(prior_m - window_m, 0.0, length))
    b = float(np.clip(prior_m + window_m, 0.0, length))
    n_step = max(int(np.ceil((b - a) / step_m)), 1)
    grid = np.linspace(a, b, n_step + 1)

    k = rho[i] - rho[j]
    sk = np.sqrt(sig[i] ** 2 + sig[j] ** 2)
    # three level sets per pair: the root and the two interval bounds
    level = np.stack([np.zeros(p), k_sigma * sk, -k_sigma * sk], axis=-1)  # (p, 3)
    target = k[:, None] + level  # (p, 3)

    rng = np.linalg.norm(path.ecef_at(grid)[:, None, :] - sat[None], axis=-1)  # (g, n)
    diff = rng[:, i] - rng[:, j]  # (g, p)
    f = diff[:, :, None] - target[None]  # (g, p, 3)
    misfit = np.abs(f[:, :, 0]).min(axis=0) if p else np.zeros(0)

    neg = f < 0
    g_idx, p_idx, l_idx = np.nonzero(neg[:-1] != neg[1:])
    roots = _refine(path, sat, i[p_idx], j[p_idx], target[p_idx, l_idx],
                    grid[g_idx], grid[g_idx + 1], f[g_idx, p_idx, l_idx],
                    f[g_idx + 1, p_idx, l_idx])  # fmt: skip

    centre = l_idx == 0
    n_roots = np.bincount(p_idx[centre], minlength=p)
    chosen = _choose_roots(p_idx[centre], roots[centre], n_roots, prior_m, p)
    band = np.abs(f[:, :, 0]) <= k_sigma * sk  # (g, p)
    lo, hi, empty = _intervals(chosen, p_idx[~centre], roots[~centre], band, a, b, length)
    status = _status(n_roots, empty, lo, hi)
    slope = _slopes(path, sat, i, j, chosen)
    return PairSolution(
        i=i, j=j, k_m=k, sigma_k_m=sk, k_sigma=float(k_sigma), root_m=chosen, lo_m=lo, hi_m=hi,
        slope=slope, n_roots=n_roots, misfit_m=np.where(n_roots > 0, 0.0, misfit),
        status=status,
    )  # fmt: skip




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


def _intervals(
    chosen: NDArray,
    bp: NDArray,
    bs: NDArray,
    band: NDArray,
    a: float,
    b: float,
    length: float,
) -> tuple[NDArray, NDArray, NDArray]:
    """Interval ``(lo, hi)`` per pair and its emptiness, from the bound-level roots.

    ``bp``, ``bs``: pair and chainage of each bound-level root; ``band`` (g, p): the grid
    points inside ``|f| <= k sigma_K``; ``[a, b]`` the window on a track of ``length``.
    """
    p = len(chosen)
    # interval: nearest bound-level root on each side of the chosen root
    below = np.full(p, -np.inf)
    above = np.full(p, np.inf)
    if len(bp):
        c = chosen[bp]
        np.maximum.at(below, bp[bs < c], bs[bs < c])
        np.minimum.at(above, bp[bs > c], bs[bs > c])
    # no root: the pair's set {|f| <= k sigma_K} may still meet the window (a blunt pair whose
    # root lies outside it); keep the hull of that set, NaN when it is empty
    none = ~np.isfinite(chosen)
    hull_lo = np.full(p, np.inf)
    hull_hi = np.full(p, -np.inf)
    np.minimum.at(hull_lo, bp, bs)
    np.maximum.at(hull_hi, bp, bs)
    if p:
        hull_lo = np.where(band[0], -np.inf, hull_lo)
        hull_hi = np.where(band[-1], np.inf, hull_hi)
    empty = none & ~(hull_lo <= hull_hi)
    below = np.where(none, hull_lo, below)
    above = np.where(none, hull_hi, above)
    # the track ends bound the train; window ends inside the track do not
    lo = np.where(np.isneginf(below) & (a <= 0.0), 0.0, below)
    hi = np.where(np.isposinf(above) & (b >= length), length, above)
    lo = np.where(empty, np.nan, lo)
    hi = np.where(empty, np.nan, hi)
    return lo, hi, empty


def _status(n_roots: NDArray, empty: NDArray, lo: NDArray, hi: NDArray) -> NDArray:
    """:class:`PairStatus` flags per pair, uint8."""
    status = np.zeros(len(n_roots), np.uint8)
    status |= np.where(n_roots == 0, PairStatus.NO_ROOT, 0).astype(np.uint8)
    status |= np.where(empty, PairStatus.EMPTY, 0).astype(np.uint8)
    status |= np.where(n_roots > 1, PairStatus.MULTIPLE_ROOTS, 0).astype(np.uint8)
    status |= np.where(np.isneginf(lo), PairStatus.UNBOUNDED_LOW, 0).astype(np.uint8)
    status |= np.where(np.isposinf(hi), PairStatus.UNBOUNDED_HIGH, 0).astype(np.uint8)
    return status


def _slopes(path: AntennaPath, sat: NDArray, i: NDArray, j: NDArray, chosen: NDArray) -> NDArray:
    """``dK/ds`` of each pair at its chosen root (NaN without a root)."""
    has = np.isfinite(chosen)
    slope = np.full(len(chosen), np.nan)
    if has.any():
        s_ok = chosen[has]
        x = path.ecef_at(s_ok)
        t = path.tangent_ecef_at(s_ok)
        u_i = _unit(sat[i[has]] - x)
        u_j = _unit(sat[j[has]] - x)
        slope[has] = np.sum((u_j - u_i) * t, axis=-1)
    return slope


def _unit(v: NDArray) -> NDArray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _refine(
    path: AntennaPath,
    sat: NDArray,
    i: NDArray,
    j: NDArray,
    target: NDArray,
    a: NDArray,
    b: NDArray,
    fa: NDArray,
    fb: NDArray,
    *,
    tol_m: float = 1e-4,
    max_iter: int = 30,
) -> NDArray:
    """Roots of ``range_diff(s) - target`` in brackets ``[a, b]``, all at once (Illinois)."""
    a, b, fa, fb = a.copy(), b.copy(), fa.copy(), fb.copy()
    if a.size == 0:
        return a
    s = a
    side = np.zeros(a.shape, np.int8)
    for _ in range(max_iter):
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(fb != fa, (a * fb - b * fa) / (fb - fa), 0.5 * (a + b))
        fs = range_difference_m(path.ecef_at(s), sat[i], sat[j]) - target
        if np.all(np.abs(fs) < tol_m):
            break
        left = (fs < 0) == (fa < 0)  # root in [s, b]
        # Illinois: halve the stale end's value when the same end is kept twice
        fb = np.where(left & (side == 1), 0.5 * fb, fb)
        fa = np.where(~left & (side == -1), 0.5 * fa, fa)
        a, fa = np.where(left, s, a), np.where(left, fs, fa)
        b, fb = np.where(left, b, s), np.where(left, fb, fs)
        side = np.where(left, 1, -1).astype(np.int8)
    return s


def _choose_roots(
    pair: NDArray, root: NDArray, n_roots: NDArray, prior_m: float, p: int
) -> NDArray:
    """One root per pair: the one closest to the consensus of the unambiguous pairs."""
    single = n_roots[pair] == 1
    ref = float(np.median(root[single])) if single.any() else float(prior_m)
    dist = np.abs(root - ref)
    best = np.full(p, np.inf)
    np.minimum.at(best, pair, dist)
    pick = dist == best[pair]
    chosen = np.full(p, np.nan)
    chosen[pair[pick]] = root[pick]
    return chosen


def reference_solve_wls(
    path: AntennaPath,
    sat_ecef_m: ArrayLike,
    pseudorange_m: ArrayLike,
    sigma_m: ArrayLike,
    *,
    prior_m: float,
    max_iter: int = 20,
    tol_m: float = 1e-4,
) -> WlsSolution:
    """Weighted least-squares chainage and clock of one epoch.

    Parameters
    ----------
    path : AntennaPath
    sat_ecef_m : array_like, shape (n_sat, 3)
    pseudorange_m, sigma_m : array_like, shape (n_sat,)
        Corrected pseudoranges and their sigmas, metres; ``n_sat >= 2``.
    prior_m : float
        Starting chainage. Gauss-Newton converges from hundreds of metres away on real
        geometry; on a track that winds back on itself it may find the wrong branch, so start
        from the previous fix or from SATHIA.
    max_iter : int
    tol_m : float
        Stop when the chainage step is below this.

    Returns
    -------
    WlsSolution
    """
    sat, rho, sig = as_observations(sat_ecef_m, pseudorange_m, sigma_m)
    n = len(rho)
    if n < 2:
        raise ValueError(f"solve_wls needs at least 2 satellites, got {n}")
    if not (np.isfinite(sat).all() and np.isfinite(rho).all() and np.all(sig > 0)):
        raise ValueError("sat_ecef_m / pseudorange_m must be finite and sigma_m positive")
    w = 1.0 / sig**2
    length = path.length_m
    s = float(np.clip(prior_m, 0.0, length))
    x = path.ecef_at(s)
    b = float(np.sum(w * (rho - np.linalg.norm(sat - x, axis=-1))) / np.sum(w))
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported
        x = path.ecef_at(s)
        d = sat - x
        r = np.linalg.norm(d, axis=-1)
        h = np.stack([-(d @ path.tangent_ecef_at(s)) / r, np.ones(n)], axis=-1)
        v = rho - r - b
        normal = h.T @ (w[:, None] * h)
        step = np.linalg.solve(normal, h.T @ (w * v))
        s_new = float(np.clip(s + step[0], 0.0, length))
        b += float(step[1])
        ds = s_new - s
        if s_new != s + step[0]:  # clamped: re-solve the clock at the end point
            r_end = np.linalg.norm(sat - path.ecef_at(s_new), axis=-1)
            b = float(np.sum(w * (rho - r_end)) / np.sum(w))
        s = s_new
        if abs(ds) < tol_m:
            converged = True
            break
    x = path.ecef_at(s)
    d = sat - x
    r = np.linalg.norm(d, axis=-1)
    h = np.stack([-(d @ path.tangent_ecef_at(s)) / r, np.ones(n)], axis=-1)
    res = rho - r - b
    normal = h.T @ (w[:, None] * h)
    cov = np.linalg.inv(normal)
    qr = 1.0 / w - np.einsum("ki,ij,kj->k", h, cov, h)
    with np.errstate(invalid="ignore", divide="ignore"):
        nres = np.where(qr > 1e-9 / w, res / np.sqrt(np.maximum(qr, 0.0)), np.nan)
    return WlsSolution(
        chainage_m=s,
        clock_m=b,
        covariance=cov,
        residual_m=res,
        normalised_residual=nres,
        chi2=float(np.sum(w * res**2)),
        dof=n - 2,
        iterations=it,
        converged=converged,
        at_end=bool(s <= 0.0 or s >= length),
    )
