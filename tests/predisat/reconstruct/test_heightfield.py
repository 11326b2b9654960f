"""Tests of the corridor height field's carving against bounds computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.gnss.fresnel import L1_WAVELENGTH_M, TRANSPARENT_FRACTION
from predisat.reconstruct.heightfield import (
    HeightField,
    RangeMax1D,
    UnseenRule,
    carve_profile,
)
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


def test_the_unseen_arm_rule_keeps_far_frames_out_of_the_clearance() -> None:
    """A camera on the track axis looking along it (a cab camera) with sky from 10 deg up: a
    cantilever about a pixel wide may hide in that sky unflagged (``docs/reconstruction.md``
    section 11), so with an :class:`UnseenRule` the clearance cells (centre within 2 m of the
    axis) are bounded only where a 0.7 deg feature at their far corner would be transparent,
    ``(theta L)^2 <= k2 max(0.5 m, nearest offset)``; the other cells exactly as without it."""
    z = np.zeros((N, N), np.float32)
    yc = ((np.arange(N) - N // 2) + 0.5) * C  # cell centres north = offset from the axis
    off = np.broadcast_to(yc[:, None], (N, N)).astype(np.float32)
    hf = HeightField(C, -N // 2, -N // 2, np.full((N, N), np.inf, np.float32),
                     np.ones((N, N), bool), z, off, z)  # fmt: skip
    prof = profile(np.full(720, 10.0))
    plain = hf.bound_m.copy()
    carve_profile(hf, plain, prof, CAM, np.eye(3), 60.0)
    theta, k2 = np.radians(0.7), TRANSPARENT_FRACTION**2 * L1_WAVELENGTH_M
    ruled = hf.bound_m.copy()
    carve_profile(hf, ruled, prof, CAM, np.eye(3), 60.0,
                  unseen_rule=UnseenRule(float(theta), k2, 0.5, 2.0))  # fmt: skip
    carved_in, kept_out = 0, 0
    for x in np.arange(1.0, 40.0, C):
        for y in yc[np.abs(yc) < 6.0]:
            r, q = cell(float(x) + 0.25, float(y))
            if not np.isfinite(plain[r, q]):
                continue
            if abs(y) >= 2.0:
                assert ruled[r, q] == plain[r, q]
                continue
            xs, ys = np.array([x, x + C]) - CAM[0], np.array([y - C / 2, y + C / 2]) - CAM[1]
            rho_far = np.hypot(xs[:, None], ys[None, :]).max()
            length = rho_far / np.cos(np.radians(10.0))
            d = max(0.5, abs(y) - 0.7072 * C)
            if (theta * length) ** 2 <= k2 * d:
                assert ruled[r, q] == plain[r, q]
                carved_in += 1
            else:
                assert np.isinf(ruled[r, q])
                kept_out += 1
    assert carved_in > 0 and kept_out > 0
    # on the axis the reach is sqrt(k2 0.5) / theta = 2.5 m: a cell 5 m ahead is not bounded
    assert np.isinf(ruled[cell(5.2, 0.2)]) and np.isfinite(plain[cell(5.2, 0.2)])


def _displacements(box_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Camera shifts within the doubt's box (x, y, z): its 26 face, edge and corner points at
    full length on each axis, and random shifts inside it."""
    g = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                  if (i, j, k) != (0, 0, 0)], float)  # fmt: skip
    inner = rng.uniform(-1.0, 1.0, (40, 3))
    return np.vstack([g, inner]) * box_m


def _tilted(angle_rad: float, yaw_rad: float) -> np.ndarray:
    """A local-to-frame rotation far from the frame's origin: a yaw and a small tilt."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("zxy", [yaw_rad, angle_rad, -0.7 * angle_rad]).as_matrix()


@pytest.mark.parametrize(("tilt_rad", "unseen"), [(0.0, False), (3e-3, False), (0.02, False),
                                                  (0.0, True)])  # fmt: skip
def test_a_position_doubt_bounds_every_cell_from_every_centre_within_it(
    tilt_rad: float, unseen: bool
) -> None:
    """The bound carved with a doubt is at least the bound each camera centre within the
    doubt's box would carve with the same skyline (the kernel without doubt, from the true
    centre), also where the local horizontal is tilted in the frame, and with the unseen-arm
    rule (its cells' offsets are the world's: they do not move with the camera)."""
    rng = np.random.default_rng(7)
    el = rng.uniform(-15.0, 60.0, 720)
    el[rng.uniform(size=720) < 0.05] = np.inf  # columns that saw no sky
    prof = profile(el)
    box = np.array([0.3, 0.2, 0.1])
    rot = _tilted(tilt_rad, 0.4)
    hf, padded = field()
    rule = None
    if unseen:  # offsets from an axis along x, the clearance 2 m either side
        yc = ((np.arange(N) - N // 2) + 0.5) * C
        off = np.broadcast_to(yc[:, None], (N, N)).astype(np.float32)
        hf = HeightField(C, -N // 2, -N // 2, hf.bound_m, hf.region, hf.chainage_m, off,
                         hf.rail_z_m)  # fmt: skip
        k2 = TRANSPARENT_FRACTION**2 * L1_WAVELENGTH_M
        rule = UnseenRule(float(np.radians(0.7)), k2, 0.5, 2.0)
    carve_profile(hf, padded, prof, CAM, rot, 40.0, unseen_rule=rule,
                  position_doubt_m=tuple(box))  # fmt: skip
    _, nominal = field()
    carve_profile(hf, nominal, prof, CAM, rot, 40.0, unseen_rule=rule)
    assert np.isfinite(padded).sum() > 1000
    below = 0
    for t in _displacements(box, rng):
        _, true = field()
        carve_profile(hf, true, prof, CAM + t, rot, 40.0, unseen_rule=rule)
        # inf >= inf holds; a finite padded bound where the true centre bounds nothing fails
        assert np.all(padded >= true - 1e-5), t
        below += int(np.sum(nominal < true - 1e-3))
    # without the doubt, the nominal centre's bounds fall below some true centre's: the
    # cells the doubt protects
    assert below > 0


def test_a_position_doubt_of_zero_changes_nothing_and_a_negative_one_is_refused() -> None:
    hf, a = field()
    _, b = field()
    prof = profile(np.linspace(-10.0, 50.0, 720))
    carve_profile(hf, a, prof, CAM, np.eye(3), 40.0)
    carve_profile(hf, b, prof, CAM, np.eye(3), 40.0, position_doubt_m=(0.0, 0.0, 0.0))
    assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="position_doubt_m"):
        carve_profile(hf, b, prof, CAM, np.eye(3), 40.0, position_doubt_m=(0.1, -0.1, 0.0))
