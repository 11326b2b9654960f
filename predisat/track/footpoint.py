"""One point's foot on the track axis, in Python floats, bit for bit the vectorised projection.

:meth:`predisat.track.map.TrackMap.project_enu` runs its Newton steps on arrays; for the one
point the locator projects at every claimed epoch (its off-track check), the numpy calls on
arrays of one row cost about 0.6 ms a point, most of an epoch's time. :func:`project_point`
does the same arithmetic, in the same order, on Python floats (about 4x faster): the spline
evaluations are the same SciPy calls, the interpolation of the local vertical is numpy's
``interp`` formula for one value (``numpy/_core/src/multiarray/compiled_base.c``), and the
norms, dot and cross products add their terms in numpy's order for three elements. The tests
compare it with the array path bit for bit on random points near, beyond and on the axis's
nodes (``tests/predisat/track/test_footpoint.py``); the array path stays the reference.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numpy as np

from predisat.track.smooth import FittedCurve

__all__ = ["interp_one", "project_point"]

Vec = tuple[float, float, float]


def interp_one(x: float, xp: Sequence[float], fp: Sequence[float]) -> float:
    """``np.interp(x, xp, fp)`` for one value, bit for bit.

    Parameters
    ----------
    x : float
    xp : sequence of float, shape (n,)
        Increasing abscissae, n >= 2.
    fp : sequence of float, shape (n,)

    Returns
    -------
    float
        ``fp[0]`` left of ``xp[0]``, ``fp[-1]`` right of and at ``xp[-1]``, ``fp[j]`` at a
        node, numpy's ``slope * (x - xp[j]) + fp[j]`` between.
    """
    if x > xp[-1] or x == xp[-1]:
        return fp[-1]
    if x < xp[0]:
        return fp[0]
    j = bisect.bisect_right(xp, x) - 1
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    out = slope * (x - xp[j]) + fp[j]
    if math.isnan(out):  # numpy's fallbacks for infinite slopes
        out = slope * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(out) and fp[j] == fp[j + 1]:
            out = fp[j]
    return out


def _unit(v0: float, v1: float, v2: float) -> Vec:
    n = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    return v0 / n, v1 / n, v2 / n


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def project_point(
    curve: FittedCurve,
    length_m: float,
    node_s_m: Sequence[float],
    node_up_rows: Sequence[Sequence[float]],
    enu_m: Vec,
    max_iter: int = 50,
) -> tuple[float, float, float, float, bool] | None:
    """Foot point of one point on the axis, as ``TrackMap.project_enu`` finds it.

    Parameters
    ----------
    curve : FittedCurve
        The axis.
    length_m : float
        Its length (the clamp of the chainage).
    node_s_m, node_up_rows : sequences of float, shapes (k,) and (3, k)
        ``curve.node_s_m`` and ``curve.node_up_rows`` as Python lists (converting them costs
        more than the projection: the caller keeps them).
    enu_m : (float, float, float)
        The point in the curve's frame, metres, finite.
    max_iter : int
        Newton steps at most.

    Returns
    -------
    (chainage_m, offset_m, height_m, along_m, clamped), or None
        None where a step would divide by zero (a degenerate axis), for the array path to
        give numpy's answer.
    """
    px, py, pz = enu_m
    _, i = curve.tree.query(np.array([[px, py]]))
    s = float(curve.node_s_m[int(i[0])])
    try:
        for _ in range(max_iter):
            r, tan, d2, ds = _frame_at(curve, s, derivative2=True)
            up = _unit(*(interp_one(s, node_s_m, row) for row in node_up_rows))
            q = _dot(d2, tan)
            ds2 = ds * ds  # numpy squares; Python's pow() differs in the last bit
            dtan = ((d2[0] - q * tan[0]) / ds2, (d2[1] - q * tan[1]) / ds2,
                    (d2[2] - q * tan[2]) / ds2)  # fmt: skip
            d = (px - r[0], py - r[1], pz - r[2])
            h = _dot(d, up)
            dh = (d[0] - h * up[0], d[1] - h * up[1], d[2] - h * up[2])
            f = _dot(dh, tan)
            tu = _dot(tan, up)
            tan_h = (tan[0] - tu * up[0], tan[1] - tu * up[1], tan[2] - tu * up[2])
            gg = _dot(tan_h, tan_h)
            fp = -gg + _dot(dh, dtan)
            if not fp < -0.1:  # beyond the curvature centre
                fp = -gg
            s_new = min(max(s + -f / fp, 0.0), length_m)
            done = abs(s_new - s) < 1e-6
            s = s_new
            if done:
                break
        r, tan, _, _ = _frame_at(curve, s, derivative2=False)
        up = _unit(*(interp_one(s, node_s_m, row) for row in node_up_rows))
        d = (px - r[0], py - r[1], pz - r[2])
        height = _dot(d, up)
        dh = (d[0] - height * up[0], d[1] - height * up[1], d[2] - height * up[2])
        left = _unit(up[1] * tan[2] - up[2] * tan[1], up[2] * tan[0] - up[0] * tan[2],
                     up[0] * tan[1] - up[1] * tan[0])  # fmt: skip
    except ZeroDivisionError:
        return None
    offset = _dot(dh, left)
    along = abs(_dot(dh, tan)) if (s <= 0.0 or s >= length_m) else 0.0
    return s, offset, height, along, along > 1e-3


def _frame_at(curve: FittedCurve, s: float, *, derivative2: bool) -> tuple[Vec, Vec, Vec, float]:
    """Axis point, unit tangent, second derivative in t (zeros unless asked) and |dr/dt| at
    chainage ``s``, through the same SciPy calls as the array path."""
    t = np.asarray(curve.t_of_s(np.array([s])))
    r0, r1, r2 = (float(v) for v in np.asarray(curve.spline(t))[0])
    a0, a1, a2 = (float(v) for v in np.asarray(curve.spline(t, 1))[0])
    d2: Vec = (0.0, 0.0, 0.0)
    if derivative2:
        b0, b1, b2 = (float(v) for v in np.asarray(curve.spline(t, 2))[0])
        d2 = (b0, b1, b2)
    ds = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    return (r0, r1, r2), (a0 / ds, a1 / ds, a2 / ds), d2, ds
