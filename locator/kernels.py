"""Compiled kernels of the 1-D locator: the antenna-path table, the SATHIA pairs, the 1-D WLS.

:func:`locator.sathia.solve_pairs` and :func:`locator.wls.solve_wls` were numpy code whose cost
was the interpreter's, not the arithmetic's (hundreds of small array operations per epoch). The
kernels here do the same arithmetic, operation for operation and in the same order, so that
their results are those of the numpy code bit for bit (``tests/regression/
test_locator_reference.py`` pins this on frozen outputs of the numpy code):

* element-wise expressions keep numpy's evaluation order (``a * b + c`` is never fused: numba
  does not contract without ``fastmath``);
* a row norm is ``sqrt((x*x + y*y) + z*z)`` (numpy's ``add.reduce`` over 3 elements) and a
  1-D sum is numpy's pairwise summation (:func:`pairwise_sum`);
* where the numpy code called BLAS or LAPACK (OpenBLAS, as numpy's wheels ship it), the
  kernels spell out what those routines compute on these small shapes, fused multiply-adds
  included (:func:`fma`): ``(n, 3) @ (3,)`` (:func:`dot3`), ``(2, n) @ (n, 2)`` and
  ``(2, n) @ (n,)`` (:func:`_normal_equations`), the 2 x 2 ``solve`` and ``inv`` (LU with
  partial pivoting, :func:`_lu2`). These were found by comparing with numpy on random inputs
  on the machine the reference was made on (AMD EPYC, OpenBLAS 0.3.31 as numpy 2.4 ships it);
  unlike a BLAS call, whose kernel depends on the CPU, the kernels give the same bits on
  every machine.

The satellite directions of the run stay numpy's: its ``arctan2`` is not libm's (they differ in
the last bit on about 8 % of random inputs here), so a compiled copy would not give the same
bits, and a direction a bit off can flip a trust decision at a mask's edge. The heading check
(:func:`heading_kernel`) is the exception: it only tests a heading against a tolerance of
degrees, and its pseudo-inverse came from LAPACK's SVD, which cannot be spelled out; compiled,
its heading differs from the numpy code's by about 1e-8 deg and its decisions are the same
(the frozen reference allows ``heading_diff_deg`` 1e-7 deg and nothing else).
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from numpy.typing import NDArray

__all__ = [
    "along_track_kernel",
    "dot3",
    "fma",
    "heading_kernel",
    "inputs_ok_kernel",
    "pair_kernel",
    "pairwise_sum",
    "pos_vec_kernel",
    "three_pairs_kernel",
    "union_kernel",
    "wls_kernel",
]



@intrinsic
def _fma_intrinsic(typingctx: object, a: object, b: object, c: object) -> tuple[object, object]:
    """The LLVM ``fma`` intrinsic (numba's typing context passes ``typingctx``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context: object, builder: ir.IRBuilder, signature: object, args: list) -> object:
        f64 = ir.DoubleType()
        fnty = ir.FunctionType(f64, [f64, f64, f64])
        fn = builder.module.declare_intrinsic("llvm.fma", [f64], fnty)
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, nogil=True, error_model="numpy")
def fma(a: float, b: float, c: float) -> float:
    """``a * b + c`` rounded once (IEEE fused multiply-add)."""
    return _fma_intrinsic(a, b, c)  # type: ignore[call-arg]  # the typing context is implicit


@njit(cache=True, nogil=True, error_model="numpy")
def pairwise_sum(a: NDArray) -> float:
    """``np.sum`` of a contiguous float64 vector, bit for bit (numpy's pairwise summation)."""
    n = a.shape[0]
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    if n <= 128:
        r = a[:8].copy()
        i = 8
        while i < n - (n % 8):
            for j in range(8):
                r[j] += a[i + j]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        while i < n:
            res += a[i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return pairwise_sum(a[:n2]) + pairwise_sum(a[n2:])


@njit(cache=True, nogil=True, error_model="numpy")
def dot3(d0: float, d1: float, d2: float, t0: float, t1: float, t2: float) -> float:
    """A row of numpy's ``(n, 3) @ (3,)`` (OpenBLAS ``dgemv_t``)."""
    return fma(d2, t2, fma(d0, t0, d1 * t1))


@njit(cache=True, nogil=True, error_model="numpy")
def _norm3(x: float, y: float, z: float) -> float:
    return np.sqrt((x * x + y * y) + z * z)


# ---------------------------------------------------------------------- the path table
# AntennaPath's cubic Hermite table (step 1 m, see locator.sathia): ``x``, ``dx`` (n_tab, 3)


@njit(cache=True, nogil=True, error_model="numpy")
def _cell(s: float, n_tab: int, length: float) -> tuple[int, float]:
    c = min(max(s, 0.0), length)
    i = min(int(c / 1.0), n_tab - 2)
    return i, (c - float(i)) / 1.0


@njit(cache=True, nogil=True, error_model="numpy")
def _pos_vec(x: NDArray, dx: NDArray, length: float, s: float, out: NDArray) -> None:
    """``AntennaPath.ecef_at`` of an array (its vectorised formula) at one chainage."""
    i, u = _cell(s, x.shape[0], length)
    u2 = u * u
    u3 = u * u * u
    h00 = 2 * u3 - 3 * u2 + 1
    h10 = (u3 - 2 * u2 + u) * 1.0
    h01 = -2 * u3 + 3 * u2
    h11 = (u3 - u2) * 1.0
    for c in range(3):
        out[c] = h00 * x[i, c] + h10 * dx[i, c] + h01 * x[i + 1, c] + h11 * dx[i + 1, c]


@njit(cache=True, nogil=True, error_model="numpy")
def inputs_ok_kernel(sat: NDArray, rho: NDArray, sig: NDArray, i: NDArray, j: NDArray) -> bool:
    """Whether :func:`locator.sathia.solve_pairs`'s arrays are valid: every position,
    pseudorange and sigma finite, every sigma positive, every pair two distinct indices in
    ``[0, n)`` (shapes checked by the caller)."""
    n = rho.shape[0]
    for k in range(n):
        if not (np.isfinite(sat[k, 0]) and np.isfinite(sat[k, 1]) and np.isfinite(sat[k, 2])
                and np.isfinite(rho[k]) and np.isfinite(sig[k]) and sig[k] > 0):  # fmt: skip
            return False
    for q in range(i.shape[0]):
        if i[q] < 0 or i[q] >= n or j[q] < 0 or j[q] >= n or i[q] == j[q]:
            return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def pos_vec_kernel(x: NDArray, dx: NDArray, length: float, s: float, out: NDArray) -> bool:
    """``AntennaPath.ecef_at`` of a 0-d array (its array formula) into ``out`` (3,); False
    (``out`` untouched) when ``s`` is not finite."""
    if not np.isfinite(s):
        return False
    _pos_vec(x, dx, length, s, out)
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _pos_scalar(x: NDArray, dx: NDArray, length: float, s: float, out: NDArray) -> None:
    """``AntennaPath.ecef_at`` of a Python float (its scalar formula)."""
    k, v = _cell(s, x.shape[0], length)
    v2 = v * v
    v3 = v * v * v
    a = 2 * v3 - 3 * v2 + 1
    b = (v3 - 2 * v2 + v) * 1.0
    c_ = 3 * v2 - 2 * v3
    d = (v3 - v2) * 1.0
    for c in range(3):
        out[c] = a * x[k, c] + b * dx[k, c] + c_ * x[k + 1, c] + d * dx[k + 1, c]


@njit(cache=True, nogil=True, error_model="numpy")
def _tangent(x: NDArray, dx: NDArray, length: float, s: float, out: NDArray) -> None:
    """``AntennaPath.tangent_ecef_at`` at one chainage (unit vector)."""
    i, u = _cell(s, x.shape[0], length)
    u2 = u * u
    a = 6 * u2 - 6 * u
    b = 3 * u2 - 4 * u + 1
    c_ = 3 * u2 - 2 * u
    for c in range(3):
        out[c] = a * (x[i, c] - x[i + 1, c]) / 1.0 + b * dx[i, c] + c_ * dx[i + 1, c]
    n = _norm3(out[0], out[1], out[2])
    for c in range(3):
        out[c] = out[c] / n


# ---------------------------------------------------------------------- SATHIA pairs


@njit(cache=True, nogil=True, error_model="numpy")
def _range_diff(xs: NDArray, sat: NDArray, i: int, j: int) -> float:
    ri = _norm3(xs[0] - sat[i, 0], xs[1] - sat[i, 1], xs[2] - sat[i, 2])
    rj = _norm3(xs[0] - sat[j, 0], xs[1] - sat[j, 1], xs[2] - sat[j, 2])
    return ri - rj


@njit(cache=True, nogil=True, error_model="numpy")
def _median(v: NDArray) -> float:
    if np.isnan(v).any():
        return np.nan
    s = np.sort(v)
    n = s.shape[0]
    if n % 2:
        return 0.0 + s[n // 2]
    return (0.0 + s[n // 2 - 1] + s[n // 2]) / 2.0


@njit(cache=True, nogil=True, error_model="numpy")
def pair_kernel(
    x: NDArray, dx: NDArray, length: float, a_w: float, b_w: float, grid: NDArray,
    sat: NDArray, rho: NDArray, sig: NDArray, pi: NDArray, pj: NDArray, k_sigma: float,
    prior_m: float, tol_m: float, max_iter: int, extra: NDArray,
) -> tuple:  # fmt: skip
    """The arithmetic of :func:`locator.sathia.solve_pairs` (grid, brackets, Illinois, roots,
    intervals, status, slopes); returns ``k, sk, root, lo, hi, slope, n_roots, misfit,
    status`` and whether a refined chainage was not finite (the caller raises). ``extra``
    (p,) widens each pair's band ``k sigma_K`` by a bound on a bias (the map doubt), metres;
    zeros leave the results bit for bit."""
    p = pi.shape[0]
    k = np.empty(p)
    sk = np.empty(p)
    band = np.empty(p)
    target = np.empty((p, 3))
    for q in range(p):
        k[q] = rho[pi[q]] - rho[pj[q]]
        sk[q] = np.sqrt(sig[pi[q]] ** 2 + sig[pj[q]] ** 2)
        band[q] = k_sigma * sk[q] + extra[q]
        target[q, 0] = k[q] + 0.0
        target[q, 1] = k[q] + band[q]
        target[q, 2] = k[q] + -band[q]
    rng = _grid_ranges(x, dx, length, grid, sat, pi, pj)
    misfit = np.zeros(p)
    first_in = np.zeros(p, np.bool_)
    last_in = np.zeros(p, np.bool_)
    bq, bl, a, b, fa, fb = _brackets(rng, grid, pi, pj, target, 1.0, band, misfit, first_in,
                                     last_in)  # fmt: skip
    s, bad = _illinois(x, dx, length, sat, pi, pj, target, bq, bl, a, b, fa, fb, tol_m,
                       max_iter)  # fmt: skip
    n_roots, chosen = _choose_roots(bq, bl, s, p, prior_m)
    lo, hi, status = _bounds(bq, bl, s, chosen, n_roots, first_in, last_in, a_w, b_w, length)
    slope = _slopes(x, dx, length, sat, pi, pj, chosen)
    for q in range(p):
        if n_roots[q] > 0:
            misfit[q] = 0.0
    return k, sk, chosen, lo, hi, slope, n_roots, misfit, status, bad


@njit(cache=True, nogil=True, error_model="numpy")
def _grid_ranges(
    x: NDArray, dx: NDArray, length: float, grid: NDArray, sat: NDArray, pi: NDArray,
    pj: NDArray,
) -> NDArray:  # fmt: skip
    """Ranges (n_sat, n_grid) of the satellites in pairs at every grid point (others unset)."""
    n_sat, g_n = sat.shape[0], grid.shape[0]
    used = np.zeros(n_sat, np.bool_)
    for q in range(pi.shape[0]):
        used[pi[q]] = True
        used[pj[q]] = True
    rng = np.empty((n_sat, g_n))
    xs = np.empty(3)
    for g in range(g_n):
        _pos_vec(x, dx, length, grid[g], xs)
        for m in range(n_sat):
            if used[m]:
                rng[m, g] = _norm3(xs[0] - sat[m, 0], xs[1] - sat[m, 1], xs[2] - sat[m, 2])
    return rng


@njit(cache=True, nogil=True, error_model="numpy")
def _brackets(
    rng: NDArray, grid: NDArray, pi: NDArray, pj: NDArray, target: NDArray, k_sigma: float,
    sk: NDArray, misfit: NDArray, first_in: NDArray, last_in: NDArray,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:  # fmt: skip
    """Every sign change of ``f`` on the grid (pair, level, ends, ``f`` at the ends) in numpy's
    ``nonzero`` order (grid, pair, level); fills ``misfit``, ``first_in``, ``last_in``."""
    p = pi.shape[0]
    cap = max(16, 4 * p)
    bq = np.empty(cap, np.int64)
    bl = np.empty(cap, np.int64)
    bg = np.empty(cap, np.int64)
    fa = np.empty(cap)
    fb = np.empty(cap)
    n_br = 0
    for q in range(p):
        while True:  # grow the bracket arrays outside the hot loop (_scan_pair) when full
            n_new = _scan_pair(rng, pi[q], pj[q], target, k_sigma * sk[q], q, bq, bl, bg, fa,
                               fb, n_br, misfit, first_in, last_in)  # fmt: skip
            if n_new >= 0:
                n_br = n_new
                break
            cap *= 2
            bq, bl, bg = _grow(bq, cap), _grow(bl, cap), _grow(bg, cap)
            fa, fb = _grow(fa, cap), _grow(fb, cap)
    # the order ties between roots are broken in
    order = np.argsort(bg[:n_br] * (3 * p) + bq[:n_br] * 3 + bl[:n_br], kind="mergesort")
    bq, bl, bg = bq[:n_br][order], bl[:n_br][order], bg[:n_br][order]
    fa, fb = fa[:n_br][order], fb[:n_br][order]
    a = np.empty(n_br)
    b = np.empty(n_br)
    for t in range(n_br):
        a[t], b[t] = grid[bg[t]], grid[bg[t] + 1]
    return bq, bl, a, b, fa, fb


@njit(cache=True, nogil=True, error_model="numpy")
def _illinois(
    x: NDArray, dx: NDArray, length: float, sat: NDArray, pi: NDArray, pj: NDArray,
    target: NDArray, bq: NDArray, bl: NDArray, a: NDArray, b: NDArray, fa: NDArray,
    fb: NDArray, tol_m: float, max_iter: int,
) -> tuple[NDArray, bool]:  # fmt: skip
    """Illinois on every bracket in lockstep (the numpy code stopped when all had converged):
    the roots, and whether a chainage was not finite. Updates ``a, b, fa, fb`` in place."""
    n_br = a.shape[0]
    xs = np.empty(3)
    s = a.copy()
    fs = np.empty(n_br)
    side = np.zeros(n_br, np.int8)
    bad = False
    for _ in range(max_iter):
        done = True
        for t in range(n_br):
            if fb[t] != fa[t]:
                s[t] = (a[t] * fb[t] - b[t] * fa[t]) / (fb[t] - fa[t])
            else:
                s[t] = 0.5 * (a[t] + b[t])
            if not np.isfinite(s[t]):
                bad = True
        if bad:
            break
        for t in range(n_br):
            _pos_vec(x, dx, length, s[t], xs)
            fs[t] = _range_diff(xs, sat, pi[bq[t]], pj[bq[t]]) - target[bq[t], bl[t]]
            if not np.abs(fs[t]) < tol_m:
                done = False
        if done:
            break
        for t in range(n_br):
            left = (fs[t] < 0) == (fa[t] < 0)
            if left and side[t] == 1:
                fb[t] = 0.5 * fb[t]
            if (not left) and side[t] == -1:
                fa[t] = 0.5 * fa[t]
            if left:
                a[t], fa[t] = s[t], fs[t]
            else:
                b[t], fb[t] = s[t], fs[t]
            side[t] = 1 if left else -1
    return s, bad


@njit(cache=True, nogil=True, error_model="numpy")
def _choose_roots(
    bq: NDArray, bl: NDArray, s: NDArray, p: int, prior_m: float
) -> tuple[NDArray, NDArray]:
    """Roots per pair and the chosen one: closest to the consensus of the unambiguous pairs."""
    n_br = s.shape[0]
    n_roots = np.zeros(p, np.int64)
    for t in range(n_br):
        if bl[t] == 0:
            n_roots[bq[t]] += 1
    n_single = 0
    for t in range(n_br):
        if bl[t] == 0 and n_roots[bq[t]] == 1:
            n_single += 1
    singles = np.empty(n_single)
    m = 0
    for t in range(n_br):
        if bl[t] == 0 and n_roots[bq[t]] == 1:
            singles[m] = s[t]
            m += 1
    ref = _median(singles) if n_single else prior_m
    best = np.full(p, np.inf)
    for t in range(n_br):
        if bl[t] == 0:
            best[bq[t]] = _nanmin(best[bq[t]], np.abs(s[t] - ref))
    chosen = np.full(p, np.nan)
    for t in range(n_br):
        if bl[t] == 0 and np.abs(s[t] - ref) == best[bq[t]]:
            chosen[bq[t]] = s[t]
    return n_roots, chosen


@njit(cache=True, nogil=True, error_model="numpy")
def _bounds(
    bq: NDArray, bl: NDArray, s: NDArray, chosen: NDArray, n_roots: NDArray, first_in: NDArray,
    last_in: NDArray, a_w: float, b_w: float, length: float,
) -> tuple[NDArray, NDArray, NDArray]:  # fmt: skip
    """Pair intervals (nearest bound-level roots each side of the chosen root; the band's
    hull without a root) and :class:`locator.sathia.PairStatus` flags."""
    p, n_br = chosen.shape[0], s.shape[0]
    below = np.full(p, -np.inf)
    above = np.full(p, np.inf)
    hull_lo = np.full(p, np.inf)
    hull_hi = np.full(p, -np.inf)
    for t in range(n_br):
        if bl[t] == 0:
            continue
        q = bq[t]
        c = chosen[q]
        if s[t] < c:
            below[q] = _nanmax(below[q], s[t])
        if s[t] > c:
            above[q] = _nanmin(above[q], s[t])
        hull_lo[q] = _nanmin(hull_lo[q], s[t])
        hull_hi[q] = _nanmax(hull_hi[q], s[t])
    lo = np.empty(p)
    hi = np.empty(p)
    status = np.zeros(p, np.uint8)
    for q in range(p):
        if first_in[q]:
            hull_lo[q] = -np.inf
        if last_in[q]:
            hull_hi[q] = np.inf
        none = not np.isfinite(chosen[q])
        empty = none and not (hull_lo[q] <= hull_hi[q])
        bw = hull_lo[q] if none else below[q]
        ab = hull_hi[q] if none else above[q]
        lo[q] = 0.0 if (np.isinf(bw) and bw < 0 and a_w <= 0.0) else bw
        hi[q] = length if (np.isinf(ab) and ab > 0 and b_w >= length) else ab
        if empty:
            lo[q] = np.nan
            hi[q] = np.nan
        st = 0
        if n_roots[q] == 0:
            st |= 1
        if empty:
            st |= 16
        if n_roots[q] > 1:
            st |= 2
        if np.isinf(lo[q]) and lo[q] < 0:
            st |= 4
        if np.isinf(hi[q]) and hi[q] > 0:
            st |= 8
        status[q] = st
    return lo, hi, status


@njit(cache=True, nogil=True, error_model="numpy")
def _slopes(
    x: NDArray, dx: NDArray, length: float, sat: NDArray, pi: NDArray, pj: NDArray,
    chosen: NDArray,
) -> NDArray:  # fmt: skip
    """``dK/ds = (u_j - u_i) . t`` at the chosen roots (NaN without one)."""
    p = chosen.shape[0]
    xs = np.empty(3)
    slope = np.full(p, np.nan)
    tt = np.empty(3)
    for q in range(p):
        if np.isfinite(chosen[q]):
            _pos_vec(x, dx, length, chosen[q], xs)
            _tangent(x, dx, length, chosen[q], tt)
            i, j = pi[q], pj[q]
            vi0, vi1, vi2 = sat[i, 0] - xs[0], sat[i, 1] - xs[1], sat[i, 2] - xs[2]
            vj0, vj1, vj2 = sat[j, 0] - xs[0], sat[j, 1] - xs[1], sat[j, 2] - xs[2]
            ni = _norm3(vi0, vi1, vi2)
            nj = _norm3(vj0, vj1, vj2)
            e0 = (vj0 / nj - vi0 / ni) * tt[0]
            e1 = (vj1 / nj - vi1 / ni) * tt[1]
            e2 = (vj2 / nj - vi2 / ni) * tt[2]
            slope[q] = (e0 + e1) + e2
    return slope


@njit(cache=True, nogil=True, error_model="numpy")
def _scan_pair(
    rng: NDArray, iq: int, jq: int, target: NDArray, band: float, q: int, bq: NDArray,
    bl: NDArray, bg: NDArray, fa: NDArray, fb: NDArray, n_br: int, misfit: NDArray,
    first_in: NDArray, last_in: NDArray,
) -> int:  # fmt: skip
    """One pair's ``f`` on the grid: its brackets appended from ``n_br`` (the new count, -1
    when the arrays are full), smallest ``|f|`` of level 0, the window's ends in the band."""
    g_n = rng.shape[1]
    cap = bq.shape[0]
    t0, t1, t2 = target[q, 0], target[q, 1], target[q, 2]
    p0 = p1 = p2 = 0.0
    m_ = 0.0
    for g in range(g_n):
        diff = rng[iq, g] - rng[jq, g]
        c0, c1, c2 = diff - t0, diff - t1, diff - t2
        v = np.abs(c0)
        if g == 0:
            m_ = v
            first_in[q] = v <= band
        else:
            if v < m_ or np.isnan(v):  # np.min: NaN propagates
                m_ = v
            for lv in range(3):
                pv = p0 if lv == 0 else (p1 if lv == 1 else p2)
                cv = c0 if lv == 0 else (c1 if lv == 1 else c2)
                if (pv < 0) != (cv < 0):
                    if n_br == cap:
                        return -1
                    bq[n_br], bl[n_br], bg[n_br] = q, lv, g - 1
                    fa[n_br], fb[n_br] = pv, cv
                    n_br += 1
        if g == g_n - 1:
            last_in[q] = v <= band
        p0, p1, p2 = c0, c1, c2
    misfit[q] = m_
    return n_br


@njit(cache=True, nogil=True, error_model="numpy")
def _grow(v: NDArray, n: int) -> NDArray:
    out = np.empty(n, v.dtype)
    out[: v.shape[0]] = v
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _nanmax(a: float, b: float) -> float:
    """``np.maximum``: NaN propagates."""
    if np.isnan(a) or np.isnan(b):
        return np.nan
    return a if a >= b else b


@njit(cache=True, nogil=True, error_model="numpy")
def _nanmin(a: float, b: float) -> float:
    """``np.minimum``: NaN propagates."""
    if np.isnan(a) or np.isnan(b):
        return np.nan
    return a if a <= b else b


# ---------------------------------------------------------------------- 1-D WLS


@njit(cache=True, nogil=True, error_model="numpy")
def _lu2(m00: float, m01: float, m10: float, m11: float) -> tuple[bool, float, float, float, float]:
    """LU of a 2 x 2 matrix with partial pivoting as OpenBLAS's ``dgetrf`` computes it:
    ``(swapped, u11, u12, l21, u22)``."""
    piv = np.abs(m10) > np.abs(m00)
    if piv:
        m00, m01, m10, m11 = m10, m11, m00, m01
    l21 = m10 * (1.0 / m00)
    return piv, m00, m01, l21, m11 - l21 * m01


@njit(cache=True, nogil=True, error_model="numpy")
def _normal_equations(
    h0: NDArray, w: NDArray, v: NDArray, tmp: NDArray
) -> tuple[float, float, float, float, float, float]:
    """``N = H^T (w H)`` (OpenBLAS ``dgemm``: one fused accumulation per entry) and
    ``H^T (w v)`` (``dgemv``: pairs of products, four at a time, then the tail), ``H = [h0, 1]``.
    """
    n = h0.shape[0]
    n00 = n01 = n10 = n11 = 0.0
    for k in range(n):
        wh = w[k] * h0[k]
        w1 = w[k] * 1.0
        n00 = fma(h0[k], wh, n00)
        n01 = fma(h0[k], w1, n01)
        n10 = fma(1.0, wh, n10)
        n11 = fma(1.0, w1, n11)
    for k in range(n):
        tmp[k] = w[k] * v[k]
    m = n - n % 4
    r0 = r1 = 0.0
    for k in range(0, m, 2):
        r0 = r0 + fma(h0[k], tmp[k], h0[k + 1] * tmp[k + 1])
        r1 = r1 + fma(1.0, tmp[k], 1.0 * tmp[k + 1])
    for k in range(m, n):
        r0 = fma(h0[k], tmp[k], r0)
        r1 = fma(1.0, tmp[k], r1)
    return n00, n01, n10, n11, r0, r1


@njit(cache=True, nogil=True, error_model="numpy")
def _design(
    x: NDArray, dx: NDArray, length: float, sat: NDArray, s: float, r: NDArray, h0: NDArray
) -> None:
    """Ranges ``r`` and along-track design column ``h0 = -(d @ t) / r`` at chainage ``s``."""
    xs = np.empty(3)
    tt = np.empty(3)
    _pos_scalar(x, dx, length, s, xs)
    _tangent(x, dx, length, s, tt)
    for k in range(sat.shape[0]):
        d0, d1, d2 = sat[k, 0] - xs[0], sat[k, 1] - xs[1], sat[k, 2] - xs[2]
        r[k] = _norm3(d0, d1, d2)
        h0[k] = -dot3(d0, d1, d2, tt[0], tt[1], tt[2]) / r[k]


@njit(cache=True, nogil=True, error_model="numpy")
def _clock(
    x: NDArray, dx: NDArray, length: float, sat: NDArray, rho: NDArray, w: NDArray, s: float
) -> float:
    """``sum(w (rho - r)) / sum(w)`` at chainage ``s``."""
    xs = np.empty(3)
    _pos_scalar(x, dx, length, s, xs)
    tmp = np.empty(sat.shape[0])
    for k in range(sat.shape[0]):
        r = _norm3(sat[k, 0] - xs[0], sat[k, 1] - xs[1], sat[k, 2] - xs[2])
        tmp[k] = w[k] * (rho[k] - r)
    return pairwise_sum(tmp) / pairwise_sum(w)


@njit(cache=True, nogil=True, error_model="numpy")
def wls_kernel(
    x: NDArray, dx: NDArray, length: float, sat: NDArray, rho: NDArray, sig: NDArray,
    prior_m: float, max_iter: int, tol_m: float,
) -> tuple[float, float, NDArray, NDArray, NDArray, float, int, bool, bool]:  # fmt: skip
    """The arithmetic of :func:`locator.wls.solve_wls`: ``s, b, cov, residual, normalised
    residual, chi2, iterations, converged`` and whether a normal matrix was singular (the
    caller raises numpy's ``LinAlgError``)."""
    n = rho.shape[0]
    w = np.empty(n)
    for k in range(n):
        w[k] = 1.0 / sig[k] ** 2
    s = min(max(prior_m, 0.0), length)
    b = _clock(x, dx, length, sat, rho, w, s)
    r = np.empty(n)
    h0 = np.empty(n)
    v = np.empty(n)
    tmp = np.empty(n)
    converged = False
    it = 0
    cov = np.full((2, 2), np.nan)
    res = np.full(n, np.nan)
    nres = np.full(n, np.nan)
    for it in range(1, max_iter + 1):
        _design(x, dx, length, sat, s, r, h0)
        for k in range(n):
            v[k] = rho[k] - r[k] - b
        n00, n01, n10, n11, r0, r1 = _normal_equations(h0, w, v, tmp)
        piv, u11, u12, l21, u22 = _lu2(n00, n01, n10, n11)
        if u11 == 0.0 or u22 == 0.0:
            return s, b, cov, res, nres, np.nan, it, False, True
        b0, b1 = (r1, r0) if piv else (r0, r1)
        x1 = fma(-l21, b0, b1) / u22
        x0 = fma(-u12, x1, b0) / u11
        s_new = min(max(s + x0, 0.0), length)
        b += x1
        ds = s_new - s
        if s_new != s + x0:  # clamped: re-solve the clock at the end point
            b = _clock(x, dx, length, sat, rho, w, s_new)
        s = s_new
        if np.abs(ds) < tol_m:
            converged = True
            break
    _design(x, dx, length, sat, s, r, h0)
    for k in range(n):
        res[k] = rho[k] - r[k] - b
        v[k] = 0.0
    n00, n01, n10, n11, _, _ = _normal_equations(h0, w, v, tmp)
    piv, u11, u12, l21, u22 = _lu2(n00, n01, n10, n11)
    if u11 == 0.0 or u22 == 0.0:
        return s, b, cov, res, nres, np.nan, it, converged, True
    ru11, ru22 = 1.0 / u11, 1.0 / u22
    for col in range(2):
        e0, e1 = (1.0, 0.0) if col == 0 else (0.0, 1.0)
        b0, b1 = (e1, e0) if piv else (e0, e1)
        x1 = fma(-l21, b0, b1) * ru22
        cov[1, col] = x1
        cov[0, col] = fma(-u12, x1, b0) * ru11
    for k in range(n):
        hk = (h0[k], 1.0)
        acc = 0.0
        for i in range(2):
            for j in range(2):
                acc += (hk[i] * cov[i, j]) * hk[j]
        qr = 1.0 / w[k] - acc
        if qr > 1e-9 / w[k]:
            nres[k] = res[k] / np.sqrt(max(qr, 0.0))
        tmp[k] = w[k] * res[k] ** 2
    return s, b, cov, res, nres, pairwise_sum(tmp), it, converged, False


# ---------------------------------------------------------------------- pair planning, union


@njit(cache=True, nogil=True, error_model="numpy")
def along_track_kernel(
    x: NDArray, dx: NDArray, length: float, s: float, sat: NDArray
) -> NDArray:
    """:func:`locator.intervals.along_track_g`: ``(d @ t) / |d|``, ``d = sat - x(s)``."""
    xs = np.empty(3)
    tt = np.empty(3)
    _pos_scalar(x, dx, length, s, xs)
    _tangent(x, dx, length, s, tt)
    out = np.empty(sat.shape[0])
    for k in range(sat.shape[0]):
        d0, d1, d2 = sat[k, 0] - xs[0], sat[k, 1] - xs[1], sat[k, 2] - xs[2]
        out[k] = dot3(d0, d1, d2, tt[0], tt[1], tt[2]) / _norm3(d0, d1, d2)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _argmin(v: NDArray) -> int:
    """``np.argmin``: the first minimum, the first NaN if any."""
    best = 0
    for k in range(v.shape[0]):
        if np.isnan(v[k]):
            return k
        if v[k] < v[best]:
            best = k
    return best


@njit(cache=True, nogil=True, error_model="numpy")
def three_pairs_kernel(
    g: NDArray, sig: NDArray, k_sigma: float, pool_size: int, pi: NDArray, pj: NDArray,
    sets: NDArray,
) -> NDArray:  # fmt: skip
    """:func:`predisat.availability.interval.three_independent_pairs` of one epoch whose
    satellites are all trusted (``m >= 6``), shape (3, 2); ``pi, pj, sets``: its matching table
    for the pool size ``min(pool_size, m)``."""
    m = g.shape[0]
    p = min(pool_size, m)
    pool = np.arange(m)
    if m > p:
        s0 = sig[0] + 0.0
        for k in range(1, m):
            v = sig[k] + 0.0
            if v < s0 or np.isnan(v):
                s0 = v
        rank_lo = np.empty(m)
        rank_hi = np.empty(m)
        for k in range(m):
            spread = np.sqrt(sig[k] * sig[k] + s0 * s0)
            rank_lo[k] = spread / (1.0 - g[k]) + 0.0
            rank_hi[k] = spread / (1.0 + g[k]) + 0.0
        picked = np.empty(p, np.int64)
        n_lo = p // 2
        for c in range(p):
            k = _argmin(rank_lo) if c < n_lo else _argmin(rank_hi)
            picked[c] = k
            rank_hi[k] = np.inf
            if c < n_lo:
                rank_lo[k] = np.inf
        pool = np.sort(picked)
    n_pairs = pi.shape[0]
    h = np.empty(n_pairs)
    for q in range(n_pairs):
        a, b = pool[pi[q]], pool[pj[q]]
        dg = np.abs(g[a] - g[b])
        sk = np.sqrt(sig[a] ** 2 + sig[b] ** 2)
        h[q] = k_sigma * sk / dg if dg > 0 else np.inf
    n_sets = sets.shape[0]
    worst = np.empty(n_sets)
    for t in range(n_sets):
        h0, h1, h2 = h[sets[t, 0]], h[sets[t, 1]], h[sets[t, 2]]
        if np.isnan(h0) or np.isnan(h1) or np.isnan(h2):
            worst[t] = np.nan
        else:
            worst[t] = max(h0, max(h1, h2))
    w_min = worst[_argmin(worst)]
    total = np.empty(n_sets)
    for t in range(n_sets):
        if worst[t] == w_min:
            total[t] = 0.0 + h[sets[t, 0]] + h[sets[t, 1]] + h[sets[t, 2]]
        else:
            total[t] = np.inf
    best = _argmin(total)
    out = np.empty((3, 2), np.int64)
    for c in range(3):
        out[c, 0] = pool[pi[sets[best, c]]]
        out[c, 1] = pool[pj[sets[best, c]]]
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def union_kernel(
    lo: NDArray, hi: NDArray, root: NDArray, slope: NDArray, sk: NDArray
) -> tuple[float, float, float, bool]:
    """The arithmetic of :func:`locator.intervals.union_interval` (no NaN bound):
    ``lo, hi, estimate, consistent``."""
    p = lo.shape[0]
    w = np.empty(p)
    wr = np.empty(p)
    lo_min, lo_max, hi_min, hi_max = lo[0], lo[0], hi[0], hi[0]
    for q in range(p):
        lo_min, lo_max = min(lo_min, lo[q]), max(lo_max, lo[q])
        hi_min, hi_max = min(hi_min, hi[q]), max(hi_max, hi[q])
        if np.isfinite(root[q]):
            sl = slope[q]
            if np.isnan(sl):
                sl = 0.0
            elif np.isinf(sl):
                sl = np.finfo(np.float64).max if sl > 0 else -np.finfo(np.float64).max
            w[q] = (sl / sk[q]) ** 2
        else:
            w[q] = 0.0
        r = root[q]
        if np.isnan(r):
            r = 0.0
        elif np.isinf(r):
            r = np.finfo(np.float64).max if r > 0 else -np.finfo(np.float64).max
        wr[q] = w[q] * r
    sw = pairwise_sum(w)
    est = pairwise_sum(wr) / pairwise_sum(w) if sw > 0 else np.nan
    return lo_min, hi_max, est, lo_max <= hi_min


# ---------------------------------------------------------------------- the heading check


@njit(cache=True, nogil=True, error_model="numpy")
def heading_kernel(
    b1: NDArray, rot: NDArray, sat: NDArray, rho: NDArray, sig: NDArray, up_m: float
) -> tuple[float, float, float, float, float, float, float, bool]:
    """The least squares of :func:`locator.heading_check.check_heading` in ``(b, dE, dN)``.

    Not bit for bit with the numpy code it replaced: the directions use libm's ``atan2``
    (numpy's differs in the last bit on some inputs) and the pseudo-inverse of the 3 x 3 normal
    matrix comes from the SVD numba calls (LAPACK ``gesdd`` of SciPy's OpenBLAS, not
    numpy's); the same pseudo-inverse rule (singular values below ``1e-15`` of the largest
    dropped) and the same rank rule (``matrix_rank``: above ``3 eps`` of the largest).
    ``tests/regression/test_locator_reference.py`` bounds the difference.

    Returns
    -------
    clock_m, de_m, dn_m, chi2, cov_ee, cov_en, cov_nn, full_rank
    """
    n = sat.shape[0]
    a = np.empty((n, 3))
    y = np.empty(n)
    w = np.empty(n)
    for k in range(n):
        d0, d1, d2 = sat[k, 0] - b1[0], sat[k, 1] - b1[1], sat[k, 2] - b1[2]
        e = rot[0, 0] * d0 + rot[0, 1] * d1 + rot[0, 2] * d2
        nn = rot[1, 0] * d0 + rot[1, 1] * d1 + rot[1, 2] * d2
        u = rot[2, 0] * d0 + rot[2, 1] * d1 + rot[2, 2] * d2
        horiz = np.hypot(e, nn)
        az = np.arctan2(e, nn)
        el = np.arctan2(u, horiz)
        ce = np.cos(el)
        a[k, 0] = 1.0
        a[k, 1] = -ce * np.sin(az)
        a[k, 2] = -ce * np.cos(az)
        y[k] = (rho[k] - np.sqrt(horiz * horiz + u * u)) + np.sin(el) * up_m
        w[k] = 1.0 / (sig[k] * sig[k])
    normal = np.zeros((3, 3))
    rhs = np.zeros(3)
    for k in range(n):
        for r in range(3):
            rhs[r] += a[k, r] * w[k] * y[k]
            for c in range(3):
                normal[r, c] += a[k, r] * w[k] * a[k, c]
    u_, s, vt = np.linalg.svd(normal)
    s_max = s.max()
    cov = np.zeros((3, 3))
    for q in range(3):
        if s[q] > 1e-15 * s_max:
            inv = 1.0 / s[q]
            for r in range(3):
                for c in range(3):
                    cov[r, c] += vt[q, r] * inv * u_[c, q]
    rank = 0
    for q in range(3):
        if s[q] > s_max * 3.0 * np.finfo(np.float64).eps:
            rank += 1
    x = np.zeros(3)
    for r in range(3):
        for c in range(3):
            x[r] += cov[r, c] * rhs[c]
    chi2 = 0.0
    for k in range(n):
        res = y[k] - (a[k, 0] * x[0] + a[k, 1] * x[1] + a[k, 2] * x[2])
        chi2 += w[k] * res * res
    return x[0], x[1], x[2], chi2, cov[1, 1], cov[1, 2], cov[2, 2], rank == 3
