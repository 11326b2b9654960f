"""Regression: the reconstruction's compiled ray march and its helpers against the kernel
they replaced (``tests/regression/reference_march.py``, kept verbatim) and against numpy and
the C library, bit for bit.

These pin an optimisation, not correctness: they fail when a faster kernel stops giving the
earlier result. Correctness is tested against independent ground truth (ray casting in the
synthetic world) in tests/predisat/reconstruct.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from predisat.camera.models import CameraModel
from predisat.reconstruct.carving import (
    ReconstructionParams,
    _ray_distances,
)
from tests.regression.reference_march import reference_march

AZIMUTH = 60.0
WALL = {"height_m": 30.0, "distance_m": 10.0, "roughness_m": 0.0, "batter": 0.0}
PINHOLE = CameraModel.pinhole_from_fov(200, 150, 74.0)
FISHEYE = CameraModel.fisheye_from_fov(200, 150, 110.0)
PARAMS = ReconstructionParams(reach_m=150.0, carve_range_m=50.0)


# ---------------------------------------------------------------------- the ray march kernel
# against ``reference_march``, the kernel it replaced (kept verbatim in its own module)


def _random_march_case(rng: np.random.Generator, own: str, nan: bool) -> tuple:
    """Arguments of ``_march_rays`` on a random corridor: a band of region cells along a
    rotated axis, ground below the antenna rising or falling with the distance, tall and low
    columns, unknown cells, a clearance strip (``clear``) under a ceiling cap, a tilted
    vertical and rotated rays; ``own`` sets the antenna's own cell (``"ground"``,
    ``"above"``: a column over the antenna, ``"unknown"``, ``"nan"``)."""
    f32 = np.float32
    c = f32(0.5)
    ny, nx = (int(v) for v in rng.integers(50, 130, 2))
    px, py = rng.uniform(0.3, 0.7) * nx, rng.uniform(0.3, 0.7) * ny  # antenna, in cells
    theta = rng.uniform(0.0, np.pi)
    yy, xx = np.mgrid[0:ny, 0:nx] + 0.5
    off = (xx - px) * -np.sin(theta) + (yy - py) * np.cos(theta)  # lateral offset (cells)
    region = np.abs(off) < rng.uniform(10.0, 60.0)
    region &= rng.random((ny, nx)) > 0.002  # holes: rays stop there
    clear = region & (np.abs(off) < 4.0)
    a_z = f32(rng.uniform(-5.0, 5.0) + 4.0)
    dist_m = np.hypot(xx - px, yy - py) * c
    bound = a_z - 4.0 + rng.uniform(-0.1, 0.1) * dist_m + rng.normal(0.0, 0.3, (ny, nx))
    kind = rng.random((ny, nx))
    bound = np.where(kind < 0.02, a_z + rng.uniform(0.0, 30.0, (ny, nx)), bound)  # tall
    bound = np.where((kind >= 0.02) & (kind < 0.04), a_z - 6.0, bound)  # low
    bound = np.where(kind > 0.995, np.inf, bound)  # unknown
    if nan:
        bound = np.where((kind > 0.99) & (kind < 0.9915), np.nan, bound)
    bound = bound.astype(np.float32)
    ox, oy = int(np.floor(px)), int(np.floor(py))
    ax, ay = f32(px - ox), f32(py - oy)
    if rng.random() < 0.3:  # on a cell corner, far_m a whole number of cells: exact ties
        ax = ay = f32(0.0)
    region[oy, ox] = True
    bound[oy, ox] = {"ground": a_z - 3.0, "above": a_z + 1.0, "unknown": np.inf,
                     "nan": np.nan}[own]  # fmt: skip
    clear[oy, ox] = True
    n_rays = 720
    az = np.sort(rng.uniform(0.0, 2.0 * np.pi, n_rays))
    d = np.stack([np.sin(az), np.cos(az)], axis=1)
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    dist_cells = (
        _ray_distances(ReconstructionParams(reach_m=float(rng.uniform(20.0, 45.0)))) / 0.5
    ).astype(np.float32)
    up = np.array([rng.normal(0.0, 1e-3), rng.normal(0.0, 1e-3), 1.0])
    up /= np.linalg.norm(up)
    capped = rng.random() < 0.7
    cap_t, cap_dz = (rng.uniform(0.1, 2.0), rng.uniform(0.0, 1.0)) if capped else (np.inf, 0.0)
    return (
        d, dist_cells, bound.ravel(), region.ravel(), nx, ny, ax, ay, ox, oy, c, a_z,
        f32(up[2]), f32(up[0] * c), f32(up[1] * c), f32(rng.integers(6, 30) * c),
        clear.ravel(), f32(cap_t), f32(cap_dz), f32(5.0),
    )  # fmt: skip


@pytest.mark.parametrize("own", ["ground", "above", "unknown", "nan"])
def test_march_rays_reproduces_the_reference_march_bit_for_bit(own: str) -> None:
    """The optimised ray march against the straightforward one it replaced (the cell distance
    computed inline instead of by ``hypotf``, the tilt once per sample, scalar maxima), on
    random corridors: every ray's near and far values, bit for bit (NaN included)."""
    from predisat.reconstruct.carving import _march_rays

    rng = np.random.default_rng(["ground", "above", "unknown", "nan"].index(own))
    seen = np.zeros(5, int)
    for case in range(12):
        args = _random_march_case(rng, own, nan=case % 3 == 2)
        views = rng.integers(0, 9, args[2].size).astype(np.int32)
        out, want = _march_rays(*args, views), reference_march(*args)
        got = out[:2]
        # the support is the views of a cell the ray met (-1: none), never invented
        for sup in out[2:]:
            assert sup.dtype == np.int32 and np.all((sup == -1) | np.isin(sup, views))
        for g, w in zip(got, want, strict=True):
            assert g.dtype == w.dtype == np.float32
            np.testing.assert_array_equal(g.view(np.int32), w.view(np.int32))
        near, far = want
        seen += [np.isfinite(near).sum(), np.isfinite(far).sum(), np.isposinf(near).sum(),
                 np.isposinf(far).sum(), np.isnan(near).sum() + np.isnan(far).sum()]  # fmt: skip
    if own == "ground":  # the cases reach every outcome: finite, unknown and NaN, near and far
        assert (seen > 0).all(), seen


def test_hypot32_is_the_float32_hypot() -> None:
    """The ray march's inline distance (float64 square root of exact squares, rounded to
    float32) against ``np.hypot`` on float32 (the C library's ``hypotf``), bit for bit: on
    random values over 16 decades and on the nearest-edge offsets of a raster."""
    from predisat.reconstruct.carving import _hypot32

    @njit
    def many(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = np.empty(x.size, np.float32)
        for i in range(x.size):
            out[i] = _hypot32(x[i], y[i])
        return out

    rng = np.random.default_rng(5)
    x = (rng.random(400_000) * 10.0 ** rng.uniform(-8, 8, 400_000)).astype(np.float32)
    y = (rng.random(400_000) * 10.0 ** rng.uniform(-8, 8, 400_000)).astype(np.float32)
    y[::7] = 0.0
    cl = np.arange(-700, 700, dtype=np.float32)
    a = np.float32(0.3718)
    edge = np.maximum(np.maximum(cl - a, np.float32(0.0)), a - cl - np.float32(1.0))
    gx, gy = (v.ravel() for v in np.meshgrid(edge, edge[::3]))
    for u, v in ((x, y), (gx, gy)):
        np.testing.assert_array_equal(many(u, v).view(np.int32), np.hypot(u, v).view(np.int32))


def test_range_scan_returns_the_sparse_table_element_bit_for_bit() -> None:
    """The far field's range maxima by a scan (since 2026-12-03) are the elements
    RangeMax1D gives: ties of -0.0 and +0.0, infinities and NaN included."""
    from predisat.reconstruct.carving import _range_max_seen
    from predisat.reconstruct.heightfield import RangeMax1D

    rng = np.random.default_rng(2)
    pool = np.array([-0.0, 0.0, 1.5, -2.0, np.inf, -np.inf, 3.0, np.nan])
    for k in range(300):
        n = int(rng.integers(1, 60))
        values = rng.choice(pool[:7] if k % 3 else pool, n)
        seen = rng.random(n) < 0.9
        lo = rng.integers(0, n, 50)
        hi = np.minimum(lo + rng.integers(0, 12, 50), n - 1)
        got, ok = _range_max_seen(values, seen, lo, hi)
        ref = RangeMax1D(values).query(lo, hi)
        assert np.array_equal(got, ref, equal_nan=True)
        assert np.array_equal(np.signbit(got), np.signbit(ref))
        ref_seen = -RangeMax1D(-seen.astype(float)).query(lo, hi) > 0.5
        np.testing.assert_array_equal(ok, ref_seen)
