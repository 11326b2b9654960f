"""The horizon ray march as it was until 2026-12-02 (commit 3645ffc), kept verbatim.

It is the reference that the faster ``predisat.reconstruct.carving._march_rays`` must reproduce
bit for bit (``tests/regression/test_march_kernels.py``) and the baseline of
``scripts/bench_march.py``. It pins an optimisation, not correctness.
"""

import numpy as np
from numba import njit

__all__ = ["reference_march"]


@njit(nogil=True)
def reference_march(
    d, dist_cells, bound, region, nx, ny, ax, ay, ox, oy, c, a_z, up_z, up_x_c, up_y_c, far_m,
    clear, cap_t, cap_dz, cap_m,
):  # fmt: skip
    zero = np.float32(0.0)
    one = np.float32(1.0)
    overhead = np.float32(3.4028235e38)
    n_rays = d.shape[0]
    best = np.full((2, n_rays), -np.inf, np.float32)
    start = np.float32(-np.inf)
    col0 = np.int32(np.floor(ax)) + ox
    row0 = np.int32(np.floor(ay)) + oy
    if 0 <= col0 < nx and 0 <= row0 < ny and region[row0 * nx + col0]:
        top = bound[row0 * nx + col0]
        rel0 = (top - a_z) * up_z
        if rel0 != rel0:
            start = rel0
        elif rel0 > zero:
            start = top if top == np.inf else overhead
            if start != np.inf and clear[row0 * nx + col0] and cap_t < np.inf and cap_m > zero:
                fx0 = max(ax, one - ax) + one
                fy0 = max(ay, one - ay) + one
                start = min(start, cap_t - cap_dz / (np.float32(np.hypot(fx0, fy0)) * c))
    for j in range(n_rays):
        dx, dy = d[j, 0], d[j, 1]
        best[0, j] = start
        if start == np.inf or start != start:
            continue
        pcol, prow = col0, row0
        stop = False
        for k in range(dist_cells.size):
            fx = ax + dx * dist_cells[k]
            fy = ay + dy * dist_cells[k]
            col = np.int32(np.floor(fx)) + ox
            row = np.int32(np.floor(fy)) + oy
            if col < 0 or col >= nx or row < 0 or row >= ny:
                break
            if not region[row * nx + col]:
                break
            n_cells = 3 if (col != pcol and row != prow) else 1
            for m in range(n_cells):
                cc, rr = (col, row) if m == 0 else ((col, prow) if m == 1 else (pcol, row))
                if cc < 0 or cc >= nx or rr < 0 or rr >= ny:
                    continue
                flat = rr * nx + cc
                if not region[flat]:
                    continue
                r, part = reference_cell_tangent(
                    flat, cc - ox, rr - oy, fx, fy, bound, clear, ax, ay, c, a_z, up_z,
                    up_x_c, up_y_c, far_m, cap_t, cap_dz, cap_m,
                )  # fmt: skip
                if r != r:
                    best[part, j] = r
                    stop = True
                    break
                if r > best[part, j]:
                    best[part, j] = r
                if best[part, j] == np.inf:
                    stop = True
                    break
            if stop:
                break
            pcol, prow = col, row
    return best[0], best[1]


@njit(nogil=True)
def reference_cell_tangent(
    flat, col_rel, row_rel, fx, fy, bound, clear, ax, ay, c, a_z, up_z, up_x_c, up_y_c, far_m,
    cap_t, cap_dz, cap_m,
):  # fmt: skip
    zero = np.float32(0.0)
    one = np.float32(1.0)
    tiny = np.float32(1e-3)
    cl = np.float32(col_rel)
    rl = np.float32(row_rel)
    ex = max(max(cl - ax, zero), ax - cl - one)
    ey = max(max(rl - ay, zero), ay - rl - one)
    near = max(np.float32(np.hypot(ex, ey)) * c, tiny)
    rel = (bound[flat] - a_z) * up_z
    rel = rel + ((fx - ax) * up_x_c + (fy - ay) * up_y_c)
    r = rel / near
    if cap_t < np.inf and near < cap_m and clear[flat] and r < np.inf:
        gx = max(abs(cl - one - ax), abs(cl + np.float32(2.0) - ax))
        gy = max(abs(rl - one - ay), abs(rl + np.float32(2.0) - ay))
        r = min(r, cap_t - cap_dz / (np.float32(np.hypot(gx, gy)) * c))
    part = 1 if near >= far_m else 0
    return np.float32(r), part
