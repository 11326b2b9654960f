"""Regression: the height field's carving kernels against the implementation they replaced
(``_reference_carve``, kept here verbatim) and against numpy's arithmetic, bit for bit.

These pin an optimisation, not correctness: they fail when a faster kernel stops giving the
earlier result. Correctness is tested against independent ground truth (ray casting in the
synthetic world) in tests/predisat/reconstruct.
"""

from __future__ import annotations

import numpy as np

from predisat.reconstruct.heightfield import HeightField, carve_profile
from predisat.reconstruct.skyline import SkyProfile

C = 0.5
N = 200  # cells from -50 m to +50 m in x and y


# ---------------------------------------------------------------------- carving vs reference
def _reference_carve(
    hf: HeightField, bound: np.ndarray, prof: SkyProfile, cam: np.ndarray, rot: np.ndarray,
    range_m: float,
) -> int:  # fmt: skip
    """:func:`carve_profile` as written before 2026-12-03: azimuth and range of every corner
    of the lattice (numpy), then the cell loop in plain Python."""
    c = hf.cell_m
    ny, nx = hf.shape
    cx, cy, cz = (float(v) for v in cam)
    c0 = max(int(np.floor((cx - range_m) / c)) - hf.ix0, 0)
    c1 = min(int(np.ceil((cx + range_m) / c)) - hf.ix0, nx)
    r0 = max(int(np.floor((cy - range_m) / c)) - hf.iy0, 0)
    r1 = min(int(np.ceil((cy + range_m) / c)) - hf.iy0, ny)
    if c1 <= c0 or r1 <= r0:
        return 0
    xl = (hf.ix0 + np.arange(c0, c1 + 1)) * c - cx
    yl = (hf.iy0 + np.arange(r0, r1 + 1)) * c - cy
    dx, dy = np.meshgrid(xl, yl)
    e = rot[0, 0] * dx + rot[1, 0] * dy
    n = rot[0, 1] * dx + rot[1, 1] * dy
    beta = np.mod(np.degrees(np.arctan2(e, n)) - prof.look_az_deg + 180.0, 360.0) - 180.0
    rho = np.hypot(e, n)
    fin = np.isfinite(prof.sky_el_deg)
    tan_sky = np.where(fin, np.tan(np.radians(np.where(fin, prof.sky_el_deg, 0.0))), np.inf)
    b0, step = float(prof.rel_az_deg[0]), float(prof.rel_az_deg[1] - prof.rel_az_deg[0])
    n_b = tan_sky.size
    up = rot[:, 2]
    region, sub = hf.region[r0:r1, c0:c1], bound[r0:r1, c0:c1]
    count = 0
    for r in range(r1 - r0):
        y_a = yl[r]
        ny_ = max(max(y_a, 0.0), -(y_a + c))
        for q in range(c1 - c0):
            if not region[r, q]:
                continue
            bs = (beta[r, q], beta[r, q + 1], beta[r + 1, q], beta[r + 1, q + 1])
            bmin, bmax = min(min(bs[0], bs[1]), min(bs[2], bs[3])), max(max(bs[0], bs[1]),
                                                                        max(bs[2], bs[3]))
            if not bmax - bmin < 90.0:
                continue
            i_lo, i_hi = int(np.floor((bmin - b0) / step)), int(np.ceil((bmax - b0) / step))
            if i_lo < 0 or i_hi > n_b - 1:
                continue
            rho_far = max(max(rho[r, q], rho[r, q + 1]), max(rho[r + 1, q], rho[r + 1, q + 1]))
            if not rho_far <= range_m:
                continue
            t_max = max(tan_sky[i_lo : i_hi + 1])
            if not np.isfinite(t_max):
                continue
            x_a = xl[q]
            if t_max >= 0.0:
                h = rho_far * t_max
            else:
                h = float(np.hypot(max(max(x_a, 0.0), -(x_a + c)), ny_)) * t_max
            tilt = -(up[0] * (x_a + c / 2) + up[1] * (y_a + c / 2)) / up[2]
            z = np.float32(cz + tilt + h / up[2])
            if z < sub[r, q]:
                sub[r, q] = z
            count += 1
    return count


def _rotation(rng: np.random.Generator) -> np.ndarray:
    """A local-to-frame rotation: any heading, a tilt of up to a few degrees."""
    a, t = rng.uniform(0, 2 * np.pi), rng.normal(0.0, 0.03, 2)
    rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(t[0]), -np.sin(t[0])],
                   [0.0, np.sin(t[0]), np.cos(t[0])]])  # fmt: skip
    ry = np.array([[np.cos(t[1]), 0.0, np.sin(t[1])], [0.0, 1.0, 0.0],
                   [-np.sin(t[1]), 0.0, np.cos(t[1])]])  # fmt: skip
    return rz @ rx @ ry


def test_carve_profile_matches_the_whole_lattice_reference_bit_for_bit() -> None:
    """Only the corners that can matter get an azimuth and a range now: the bounds and the
    counts must be those of the whole-lattice computation, whatever the geometry."""
    import cv2

    rng = np.random.default_rng(21)
    carved = 0
    for k in range(60):
        n = int(rng.integers(20, 60))
        cell_m = float(rng.choice([0.25, 0.5, 1.0]))
        ix0, iy0 = (int(v) for v in rng.integers(-40, 10, 2))
        noise = cv2.GaussianBlur(rng.random((n, n)).astype(np.float32), (0, 0), 3.0)
        region = noise > np.quantile(noise, rng.uniform(0.0, 0.6))
        z = np.zeros((n, n), np.float32)
        start = rng.uniform(0.0, 30.0, (n, n)).astype(np.float32)
        start[rng.random((n, n)) < 0.3] = np.inf
        hf = HeightField(cell_m, ix0, iy0, start, region, z, z, z)
        # a profile on the rectifier's axis (0.25 deg columns within +-90 deg) or a coarser
        # one, with unseen (+inf) and downward columns
        n_b = int(rng.choice([720, 180, 37]))
        half = 90.0 if k % 4 else float(rng.uniform(20.0, 179.0))
        b = -half + 2 * half / n_b * (np.arange(n_b) + 0.5)
        el = rng.uniform(-20.0, 80.0, n_b)
        el[rng.random(n_b) < 0.2] = np.inf
        prof = SkyProfile(b, el, np.full(n_b, -30.0), np.full(n_b, 89.0),
                          float(rng.uniform(0.0, 360.0)))  # fmt: skip
        cam = np.array([(ix0 + rng.uniform(0, n)) * cell_m, (iy0 + rng.uniform(0, n)) * cell_m,
                        rng.uniform(1.0, 5.0)])  # fmt: skip
        rot = _rotation(rng)
        range_m = float(rng.uniform(0.2, 0.6) * n * cell_m)
        got, ref = start.copy(), start.copy()
        n_got = carve_profile(hf, got, prof, cam, rot, range_m)
        n_ref = _reference_carve(hf, ref, prof, cam, rot, range_m)
        assert n_got == n_ref
        np.testing.assert_array_equal(got, ref)
        carved += n_ref > 0
    assert carved > 40


def test_carve_corners_compute_east_and_north_as_numpy_does() -> None:
    from predisat.reconstruct.heightfield import _carve_corners, _corner_lattice

    rng = np.random.default_rng(4)
    xl, yl = np.sort(rng.normal(0, 30, 41)), np.sort(rng.normal(0, 30, 33))
    rot = _rotation(rng)
    region = np.ones((32, 40), bool)
    # no pruning (a cosine below -1, an infinite range): every corner, in lattice order
    idx, e, n = _carve_corners(xl, yl, region, rot[0, 0], rot[1, 0], rot[0, 1], rot[1, 1],
                               0.0, 1.0, -2.0, np.inf)  # fmt: skip
    dx, dy = np.meshgrid(xl, yl)
    np.testing.assert_array_equal(idx, np.arange(dx.size))
    assert np.array_equal(e, (rot[0, 0] * dx + rot[1, 0] * dy).ravel())
    assert np.array_equal(n, (rot[0, 1] * dx + rot[1, 1] * dy).ravel())
    # the azimuth lattice: numpy's degrees and modulo, bit for bit, zero remainders included
    atan = np.concatenate([np.arctan2(e, n), np.radians([-180.0, 0.0, 90.0, 180.0]), [-0.0]])
    for look in (0.0, 37.25, -90.0, 180.0, 359.9):
        beta, _ = _corner_lattice(np.arange(atan.size), atan, np.zeros(atan.size), look,
                                    1, atan.size)  # fmt: skip
        ref = np.mod(np.degrees(atan) - look + 180.0, 360.0) - 180.0
        assert np.array_equal(beta[0], ref) and np.array_equal(np.signbit(beta[0]), np.signbit(ref))
