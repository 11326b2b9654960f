"""Tests of the corridor height field's carving against bounds computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.reconstruct.heightfield import HeightField, RangeMax1D, carve_profile
from predisat.reconstruct.skyline import SkyProfile

C = 0.5
N = 200  # cells from -50 m to +50 m in x and y


def field() -> tuple[HeightField, np.ndarray]:
    z = np.zeros((N, N), np.float32)
    hf = HeightField(C, -N // 2, -N // 2, np.full((N, N), np.inf, np.float32),
                     np.ones((N, N), bool), z, z, z)  # fmt: skip
    return hf, hf.bound_m.copy()


def cell(x_m: float, y_m: float) -> tuple[int, int]:
    return int(np.floor(y_m / C)) + N // 2, int(np.floor(x_m / C)) + N // 2


def profile(sky_el_deg: np.ndarray, look_az_deg: float = 90.0) -> SkyProfile:
    b = -90.0 + 0.25 * (np.arange(720) + 0.5)
    lo = np.full(b.size, -30.0)
    return SkyProfile(b, np.asarray(sky_el_deg, float), lo, np.full(b.size, 89.0), look_az_deg)


CAM = np.array([0.1, 0.1, 3.0])


def test_a_cell_takes_the_sky_ray_over_its_farthest_corner() -> None:
    hf, bound = field()
    n = carve_profile(hf, bound, profile(np.full(720, 30.0)), CAM, np.eye(3), 60.0)
    assert n > 0
    # cell [10, 10.5) x [0, 0.5) east of the camera: farthest corner (10.4, 0.4) from it
    far = np.hypot(10.4, 0.4)
    assert bound[cell(10.2, 0.2)] == pytest.approx(3.0 + far * np.tan(np.radians(30.0)), abs=1e-4)
    # behind the camera (west), beyond the range, or outside the profile: not carved
    assert np.isinf(bound[cell(-10.2, 0.2)])
    assert np.isinf(bound[cell(45.2, 40.2)])  # 60.3 m away
    # a second, lower skyline only lowers the bounds
    before = bound.copy()
    carve_profile(hf, bound, profile(np.full(720, 10.0)), CAM, np.eye(3), 60.0)
    assert np.all(bound <= before)
    assert bound[cell(10.2, 0.2)] == pytest.approx(3.0 + far * np.tan(np.radians(10.0)), abs=1e-4)


def test_unseen_columns_clear_nothing_and_downward_rays_use_the_nearest_point() -> None:
    hf, bound = field()
    el = np.full(720, -10.0)
    b = -90.0 + 0.25 * (np.arange(720) + 0.5)
    el[np.abs(b) < 5.0] = np.inf  # no sky seen within 5 deg of the look direction
    carve_profile(hf, bound, profile(el), CAM, np.eye(3), 60.0)
    assert np.isinf(bound[cell(20.2, 0.2)])  # straight east: that column saw no sky
    # north-east, 45 deg off the look direction: the downward ray bounds the cell at its
    # nearest point (15, 15) from the camera at (0.1, 0.1)
    near = np.hypot(14.9, 14.9)
    got = bound[cell(15.2, 15.2)]
    assert got == pytest.approx(3.0 - near * np.tan(np.radians(10.0)), abs=1e-4)


def test_range_max_matches_a_direct_maximum() -> None:
    rng = np.random.default_rng(0)
    v = rng.normal(size=257)
    v[[5, 100]] = np.inf
    lo = rng.integers(0, 257, 500)
    hi = np.minimum(lo + rng.integers(0, 60, 500), 256)
    got = RangeMax1D(v).query(lo, hi)
    np.testing.assert_array_equal(got, [v[a : b + 1].max() for a, b in zip(lo, hi, strict=True)])


def test_clearance_under_an_overhead_structure_takes_the_highest_band_bound() -> None:
    """Bands 3-9 m either side bounded above 6 m mark an overhead structure; there the
    clearance (|offset| < 2 m) takes the highest band bound within the 2 m spread, and stays
    unknown where a band cell is unknown. Elsewhere it is the 1 m floor."""
    from predisat.reconstruct.heightfield import apply_clearance_prior

    xs = (np.arange(N) - N // 2 + 0.5) * C  # cell centres, m
    ch, off = np.meshgrid(xs, xs)  # chainage along x (columns), offset along y (rows)
    z = np.zeros((N, N), np.float32)
    hf = HeightField(C, -N // 2, -N // 2, z, np.ones((N, N), bool), ch, off, z)
    bound = np.full((N, N), 0.5, np.float32)  # open ground, carved low
    bands = (np.abs(off) >= 3.0) & (np.abs(off) <= 9.0)
    strip = np.abs(off) < 2.0
    bound[strip] = np.inf  # never seen by a side camera
    for a, b in ((10.0, 14.0), (30.0, 34.0)):
        bound[bands & (ch >= a) & (ch < b)] = 8.0  # walls or a deck on both sides
    bound[cell(11.2, 5.2)] = 12.0  # one taller band cell
    bound[cell(31.2, -6.2)] = np.inf  # one band cell nobody saw
    over = apply_clearance_prior(hf, bound, 2.0, 1.0, (3.0, 9.0), 6.0)
    # tall bins 10-13 and 30-33 (1 m bins), widened by the 2 m spread; the bin past the last
    # cell (50-51 m) holds no band cell and counts as tall, the conservative side
    np.testing.assert_allclose(over, [[8.0, 16.0], [28.0, 36.0], [48.0, 51.0]])

    def at(x_m: float) -> float:
        return float(bound[cell(x_m, 0.2)])

    assert at(20.2) == 1.0 and at(-5.2) == 1.0  # free clearance: the floor
    assert at(9.2) == 12.0 and at(12.2) == 12.0 and at(13.2) == 12.0  # bins 9-13 see 11.2
    assert at(8.2) == 8.0 and at(14.2) == 8.0 and at(15.2) == 8.0
    assert np.isinf(at(29.2)) and np.isinf(at(31.2)) and np.isinf(at(33.2))  # near 31.2
    assert at(34.2) == 8.0 and at(28.2) == 8.0


def test_cameras_bound_the_clearance_between_facades() -> None:
    """Where the overhead rule fires, a position whose cameras saw sky straight along the track
    caps the clearance at ``z + d * tan``, d to the far end of the cell (its centre's distance
    plus half a cell diagonal), ahead and behind; a cell straddling the position takes the
    steeper side; an ``inf`` tangent (no sky seen: a deck) bounds nothing, and the band bound
    stays where it is lower."""
    from predisat.reconstruct.heightfield import apply_clearance_prior

    xs = (np.arange(N) - N // 2 + 0.5) * C
    ch, off = np.meshgrid(xs, xs)
    z = np.zeros((N, N), np.float32)
    hf = HeightField(C, -N // 2, -N // 2, z, np.ones((N, N), bool), ch, off, z)
    bound = np.full((N, N), 0.5, np.float32)
    bands = (np.abs(off) >= 3.0) & (np.abs(off) <= 9.0)
    bound[np.abs(off) < 2.0] = np.inf
    bound[bands & (ch >= 10.0) & (ch < 40.0)] = 20.0  # facades 20 m high on both sides
    bound[bands & (ch >= -30.0) & (ch < -20.0)] = 7.0  # and a low deck
    t30, t45 = np.tan(np.radians(30.0)), np.tan(np.radians(45.0))
    rows = np.array([[20.1, 3.0, t30, t45], [30.0, 3.0, np.inf, np.inf], [-10.0, 3.0, 10.0, 10.0]])
    apply_clearance_prior(hf, bound, 2.0, 1.0, (3.0, 9.0), 6.0, camera_ceilings=rows)
    half = C * np.sqrt(0.5)  # half a cell diagonal

    def at(x_m: float) -> float:
        return float(bound[cell(x_m, 0.7)])

    # cell centres 22.25 (ahead), 19.25 and 17.25 (behind), 20.25 (straddles 20.1)
    assert at(22.2) == pytest.approx(3.0 + (2.15 + half) * t30, abs=1e-4)
    assert at(19.2) == pytest.approx(3.0 + (0.85 + half) * t45, abs=1e-4)
    assert at(17.2) == pytest.approx(3.0 + (2.85 + half) * t45, abs=1e-4)
    assert at(20.2) == pytest.approx(3.0 + (0.15 + half) * t45, abs=1e-4)
    # the position at 30 m saw no sky along the track: 36 m keeps the bound from 20.1 m
    assert at(36.2) == pytest.approx(3.0 + (16.15 + half) * t30, abs=1e-4)
    # the deck's band bound (7 m) is lower than the steep ceiling from -10 m: it stays
    assert at(-25.2) == 7.0
    assert at(45.2) == 1.0 and at(0.2) == 1.0  # no overhead structure: the floor


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
