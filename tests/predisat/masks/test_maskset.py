"""Tests for predisat.masks.maskset: the MaskSet model and its trust queries.

Ground truth is computed here by brute force from the documented definitions (bin intervals,
chainage cells as midpoints between positions), never by calling the code under test.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

from predisat.masks.maskset import REQUIRED_DESCRIPTORS, BinSource, MaskError, MaskSet


def make_set(n_pos=40, step=1.0, seed=0, spacing=None, margin=0.0, **kw):
    rng = np.random.default_rng(seed)
    n_az = round(360 / step)
    if spacing is None:
        ch = np.cumsum(rng.uniform(5.0, 15.0, n_pos)) + 100.0
    else:
        ch = 100.0 + spacing * np.arange(n_pos)
    mask = rng.uniform(0.0, 70.0, (n_pos, n_az)).astype(np.float32)
    return MaskSet.from_arrays(
        ch,
        50.0 + 1e-4 * np.arange(n_pos),
        4.0 + 1e-4 * np.arange(n_pos),
        np.full(n_pos, 100.0),
        rng.uniform(0, 360, n_pos),
        mask,
        az_step_deg=step,
        source=rng.integers(0, 3, (n_pos, n_az)),
        margin_deg=margin,
        **kw,
    )


# ---------------------------------------------------------------- brute-force references
def brute_bin(az, step):
    """Bin k holds az when az lies in [k*step - step/2, k*step + step/2) modulo 360."""
    n_az = round(360 / step)
    a = az % 360.0
    for k in range(n_az):
        lo = k * step - step / 2
        if (a - lo) % 360.0 < step:
            return k
    raise AssertionError("no bin")


def brute_cells(ch):
    """Cell edges of each position: midpoints, half a spacing beyond the ends."""
    edges = [ch[0] - (ch[1] - ch[0]) / 2]
    edges += [(a + b) / 2 for a, b in itertools.pairwise(ch)]
    edges += [ch[-1] + (ch[-1] - ch[-2]) / 2]
    return [(edges[i], edges[i + 1]) for i in range(len(ch))]


# ---------------------------------------------------------------- construction
def test_from_arrays_defaults_and_properties():
    n, n_az = 5, 72
    mask = np.full((n, n_az), 10.0)
    m = MaskSet.from_arrays(
        np.arange(n) * 10.0, np.full(n, 50.0), np.full(n, 4.0), 0.0, np.full(n, 370.0), mask
    )
    assert m.n_pos == n and m.n_az == n_az
    assert m.az_step_deg == 5.0
    np.testing.assert_array_equal(m.az_deg, np.arange(0, 360, 5.0))
    assert m.mask_el_deg.dtype == np.float32 and m.source.dtype == np.uint8
    assert (m.source == BinSource.OBSERVED).all()
    assert m.margin_deg.shape == (n, n_az) and (m.margin_deg == 0).all()
    np.testing.assert_allclose(m.heading_deg, 10.0)  # wrapped into [0, 360)
    for name in REQUIRED_DESCRIPTORS:
        assert np.isnan(m.descriptors[name]).all()
    assert {"software", "software_version", "created_utc"} <= m.provenance.keys()


def test_arrays_are_read_only_copies():
    ch = np.arange(4) * 10.0
    mask = np.full((4, 360), 5.0, np.float32)
    m = MaskSet.from_arrays(ch, np.full(4, 50.0), np.full(4, 4.0), 0.0, np.zeros(4), mask)
    ch[0] = -99.0
    mask[:] = 80.0
    assert m.chainage_m[0] == 0.0 and (m.mask_el_deg == 5.0).all()
    with pytest.raises(ValueError):
        m.mask_el_deg[0, 0] = 1.0
    with pytest.raises(AttributeError):
        m.az_step_deg = 2.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"chainage_m": [0.0, 10.0, 10.0, 30.0]}, ["chainage_m", "row 2 (10 m)", "increasing"]),
        ({"chainage_m": [0.0, np.nan, 20.0, 30.0]}, ["chainage_m[1]", "not finite"]),
        ({"lat_deg": [50.0, 95.0, 50.0, 50.0]}, ["lat_deg[1]", "[-90, 90]"]),
        ({"mask_el_deg": "high"}, ["mask_el_deg[2, 7]", "= 90.5 is outside [0, 90]"]),
        ({"mask_el_deg": "nan"}, ["mask_el_deg[0, 9]", "is NaN"]),
        ({"mask_el_deg": "neg"}, ["mask_el_deg[1, 3]", "[0, 90]"]),
        ({"mask_el_deg": np.zeros((3, 360))}, ["mask_el_deg", "shape", "(4, 360)"]),
        ({"az_step_deg": 0.7}, ["az_step_deg", "whole number"]),
        ({"source": "bad"}, ["source[3, 5]", "BinSource"]),
        ({"margin_deg": -1.0}, ["margin_deg", "negative"]),
        ({"margin_deg": np.zeros((4, 10))}, ["margin_deg", "shape"]),
        ({"descriptors": {"Left Dist": np.zeros(4)}}, ["descriptor name", "Left Dist"]),
        ({"descriptors": {"chainage_m": np.zeros(4)}}, ["descriptor name", "chainage_m"]),
        ({"descriptors": {"x_m": np.zeros(3)}}, ["x_m", "shape"]),
        ({"provenance": {"when": object()}}, ["provenance", "JSON"]),
    ],
)
def test_validation_errors_name_field_and_row(change, words):
    args: dict[str, Any] = {
        "chainage_m": [0.0, 10.0, 20.0, 30.0],
        "lat_deg": np.full(4, 50.0),
        "lon_deg": np.full(4, 4.0),
        "h_m": 0.0,
        "heading_deg": np.zeros(4),
        "mask_el_deg": np.full((4, 360), 10.0),
    }
    kw: dict = {}
    for key, value in change.items():
        if key == "mask_el_deg" and isinstance(value, str):
            mask = np.full((4, 360), 10.0)
            if value == "high":
                mask[2, 7] = 90.5
            elif value == "nan":
                mask[0, 9] = np.nan
            else:
                mask[1, 3] = -0.1
            args[key] = mask
        elif key == "source":
            src = np.zeros((4, 360), int)
            src[3, 5] = 7
            kw["source"] = src
        elif key in args:
            args[key] = value
        else:
            kw[key] = value
    with pytest.raises(MaskError) as err:
        MaskSet.from_arrays(*args.values(), **kw)
    for w in words:
        assert w in str(err.value)


class _StandInTrack:
    """A straight track due east from (lat0, lon0): independent of predisat.track.map."""

    name = "stand-in"

    def position_at(self, chainage_m):
        s = np.asarray(chainage_m, float)
        lon = 4.0 + s / (111_320.0 * np.cos(np.radians(50.0)))
        return np.full_like(s, 50.0), lon, np.full_like(s, 80.0)

    def heading_at(self, chainage_m):
        return np.full_like(np.asarray(chainage_m, float), 90.0)


def test_from_track_fills_positions_and_heading():
    ch = np.array([0.0, 10.0, 20.0])
    m = MaskSet.from_track(_StandInTrack(), ch, np.full((3, 360), 5.0), provenance={"survey": "s1"})
    np.testing.assert_allclose(m.lat_deg, 50.0)
    np.testing.assert_allclose(m.h_m, 80.0)
    np.testing.assert_allclose(m.heading_deg, 90.0)
    assert m.lon_deg[2] > m.lon_deg[0]
    assert m.provenance["track"] == "stand-in" and m.provenance["survey"] == "s1"


# ---------------------------------------------------------------- lookups
@pytest.mark.parametrize("step", [1.0, 0.5, 5.0])
def test_bin_index_matches_interval_definition(step):
    m = make_set(n_pos=3, step=step)
    rng = np.random.default_rng(1)
    az = np.concatenate(
        [
            rng.uniform(-720, 720, 300),
            [0.0, step / 2, -step / 2, 360 - step / 2, 359.999, 360.0, 720.25],
        ]
    )
    got = m.bin_index(az)
    assert got.shape == az.shape
    assert got.tolist() == [brute_bin(a, step) for a in az]
    with pytest.raises(MaskError, match="NaN"):
        m.bin_index([np.nan])


def test_position_index_and_coverage():
    m = make_set(n_pos=12)
    ch = m.chainage_m.tolist()
    cells = brute_cells(ch)
    rng = np.random.default_rng(2)
    s = rng.uniform(ch[0] - 20, ch[-1] + 20, 500)
    idx, inside = m.position_index(s)
    for si, ii, ins in zip(s, idx, inside, strict=True):
        nearest = int(np.argmin(np.abs(np.asarray(ch) - si)))
        assert ii == nearest
        assert ins == (cells[0][0] <= si <= cells[-1][1])
    _, inside_nan = m.position_index(np.nan)
    assert not inside_nan


def test_mask_at_and_trusted_against_brute_force_loop():
    m = make_set(n_pos=15, step=0.5, margin=0.0)
    rng = np.random.default_rng(3)
    margin = rng.uniform(0, 3, m.mask_el_deg.shape)
    m = m.with_margin(margin)
    ch = m.chainage_m.tolist()
    cells = brute_cells(ch)
    s = rng.uniform(ch[0] - 15, ch[-1] + 15, (40, 1))
    az = rng.uniform(0, 360, (1, 25))
    el = rng.uniform(0, 90, (40, 25))
    got = m.mask_at(s, az)
    ok = m.trusted(s, az, el)
    assert got.shape == (40, 25) and ok.shape == (40, 25)
    for r in range(40):
        for c in range(25):
            si, ai = s[r, 0], az[0, c]
            if not cells[0][0] <= si <= cells[-1][1]:
                assert got[r, c] == np.inf and not ok[r, c]
                continue
            i = int(np.argmin(np.abs(np.asarray(ch) - si)))
            k = brute_bin(ai, 0.5)
            want = float(m.mask_el_deg[i, k]) + float(np.float32(margin[i, k]))
            assert got[r, c] == pytest.approx(want, abs=1e-5)
            assert ok[r, c] == (el[r, c] > got[r, c])
    assert not m.trusted(ch[0], np.nan, 89.0)
    assert not m.trusted(ch[0], 10.0, np.nan)


def test_trusted_is_strict_and_sources_are_looked_up():
    n = 3
    mask = np.full((n, 360), 20.0)
    src = np.zeros((n, 360), int)
    src[1, 90] = BinSource.ASSUMED
    m = MaskSet.from_arrays(
        [0.0, 10.0, 20.0],
        np.full(n, 50.0),
        np.full(n, 4.0),
        0.0,
        np.zeros(n),
        mask,
        source=src,
        margin_deg=2.0,
    )
    assert not m.trusted(10.0, 90.0, 22.0)  # equal to mask + margin: not above
    assert m.trusted(10.0, 90.0, 22.001)
    assert m.source_at(10.0, 90.2) == BinSource.ASSUMED
    assert m.source_at(10.0, 91.0) == BinSource.OBSERVED


# ---------------------------------------------------------------- worst case
def test_worst_case_matches_brute_force_max():
    m = make_set(n_pos=300, step=2.0, seed=4)  # several blocks and sparse-table levels
    eff = m.mask_el_deg.astype(float) + m.margin_deg
    ch = m.chainage_m.tolist()
    cells = brute_cells(ch)
    rng = np.random.default_rng(5)
    lo = rng.uniform(ch[0], ch[-1], 400)
    width = np.concatenate([np.zeros(50), rng.uniform(0, 40, 150), rng.uniform(0, 3000, 200)])
    hi = np.minimum(lo + width, ch[-1])
    # exact cell edges and exact positions too
    lo = np.concatenate([lo, [cells[10][1], ch[20], cells[0][0]]])
    hi = np.concatenate([hi, [cells[10][1], ch[25], cells[-1][1]]])
    got = m.worst_case(lo, hi)
    assert got.shape == (lo.size, m.n_az)
    for q in range(lo.size):
        touching = [i for i, (a, b) in enumerate(cells) if a <= hi[q] and b >= lo[q]]
        np.testing.assert_allclose(got[q], eff[touching].max(axis=0), atol=1e-5)
    # the edge between cells 10 and 11 touches both
    assert (got[-3] >= eff[10] - 1e-5).all() and (got[-3] >= eff[11] - 1e-5).all()


def test_worst_case_outside_coverage_and_shapes():
    m = make_set(n_pos=20, spacing=10.0)  # positions 100..290, cells 95..295
    assert m.worst_case(150.0, 160.0).shape == (m.n_az,)
    assert m.worst_case(np.full((2, 3), 150.0), 170.0).shape == (2, 3, m.n_az)
    assert np.isinf(m.worst_case(90.0, 120.0)).all()  # reaches outside: blocked
    clipped = m.worst_case(90.0, 120.0, clip=True)
    eff = m.mask_el_deg + m.margin_deg
    np.testing.assert_allclose(clipped, eff[:3].max(axis=0))  # cells of 100, 110, 120
    assert np.isinf(m.worst_case(400.0, 500.0, clip=True)).all()
    with pytest.raises(MaskError, match="lo"):
        m.worst_case(200.0, 150.0)


def test_worst_case_many_queries_match_brute_force():
    # 10^5 queries at once (the availability engine's use); 300 of them against a loop over
    # the positions whose cells touch the clipped interval (speed: scripts/bench_worst_case.py)
    m = make_set(n_pos=3000, step=1.0, spacing=10.0, seed=6)
    rng = np.random.default_rng(7)
    lo = rng.uniform(100, 30000, 100_000)
    hi = lo + rng.uniform(0, 600, lo.size)
    out = m.worst_case(lo, hi, clip=True)
    assert out.shape == (100_000, 360)
    b = m.cell_bounds_m
    eff = m.effective_mask_deg
    for k in rng.choice(lo.size, 300, replace=False):
        a, z = max(lo[k], b[0]), min(hi[k], b[-1])
        if a > z:
            assert np.all(np.isinf(out[k]))
            continue
        touch = [i for i in range(m.n_pos) if b[i] <= z and b[i + 1] >= a]
        np.testing.assert_array_equal(out[k], eff[touch].max(axis=0))


def test_worst_case_of_one_interval_matches_brute_force():
    # the scalar path (one interval, the locator's epoch) against a loop over the cells that
    # touch it: inside, at cell edges, past either end with and without clip, and infinite ends
    m = make_set(n_pos=300, step=2.0, spacing=10.0, seed=8)
    b = m.cell_bounds_m
    eff = m.effective_mask_deg
    rng = np.random.default_rng(9)
    lo = np.concatenate([rng.uniform(b[0] - 50, b[-1], 300), [b[3], b[0], -np.inf, b[0] - 1]])
    hi = np.concatenate([lo[:300] + rng.uniform(0, 400, 300), [b[3], b[-1], 500.0, b[0] - 0.5]])
    for q in range(lo.size):
        for clip in (False, True):
            got = m.worst_case(float(lo[q]), float(hi[q]), clip=clip)
            assert got.shape == (m.n_az,) and got.dtype == eff.dtype
            a, z = (max(lo[q], b[0]), min(hi[q], b[-1])) if clip else (lo[q], hi[q])
            if (clip and a > z) or (not clip and (lo[q] < b[0] or hi[q] > b[-1])):
                assert np.all(np.isinf(got)), (q, clip)
                continue
            touch = [i for i in range(m.n_pos) if b[i] <= z and b[i + 1] >= a]
            np.testing.assert_array_equal(got, eff[touch].max(axis=0))
    with pytest.raises(MaskError, match="NaN"):
        m.worst_case(float("nan"), 10.0)


# ---------------------------------------------------------------- opening angle
def test_opening_angle_uses_cross_track_bins():
    n = 2
    mask = np.zeros((n, 360))
    # heading 0 (north): left of increasing chainage is west (270), right is east (90)
    mask[0, 270], mask[0, 90] = 10.0, 20.0
    # heading 30: left 300, right 120
    mask[1, 300], mask[1, 120], mask[1, 121] = 40.0, 5.0, 30.0
    m = MaskSet.from_arrays(
        [0.0, 10.0], np.full(n, 50.0), np.full(n, 4.0), 0.0, [0.0, 30.0], mask, margin_deg=1.0
    )
    np.testing.assert_allclose(m.opening_angle_deg(include_margin=False), [150.0, 135.0])
    np.testing.assert_allclose(m.opening_angle_deg(), [148.0, 133.0])
    # a 1-deg half width also takes bin 121 on the right of position 1
    np.testing.assert_allclose(
        m.opening_angle_deg(include_margin=False, half_width_deg=1.0), [150.0, 110.0]
    )


# ---------------------------------------------------------------- derived sets
def test_with_margin_and_subset_do_not_mutate():
    m = make_set(n_pos=10, margin=0.5)
    m2 = m.with_margin(3.0)
    assert (m.margin_deg == 0.5).all() and (m2.margin_deg == 3.0).all()
    np.testing.assert_array_equal(m2.mask_el_deg, m.mask_el_deg)
    lo, hi = m.chainage_m[2], m.chainage_m[5]
    sub = m.subset(lo, hi)
    assert sub.n_pos == 4
    np.testing.assert_array_equal(sub.chainage_m, m.chainage_m[2:6])
    np.testing.assert_array_equal(sub.source, m.source[2:6])
    assert sub.descriptors.keys() == m.descriptors.keys()
    assert m.n_pos == 10
    with pytest.raises(MaskError, match="no position"):
        m.subset(0.0, 1.0)


def test_support_follows_subset_concat_and_gap_closing():
    from predisat.masks.gaps import close_gaps
    from predisat.masks.maskset import WEAK_SUPPORT, concat_masksets

    base = make_set(n_pos=10)
    sup = np.arange(base.n_pos * base.n_az).reshape(base.n_pos, base.n_az) % 7
    ms = MaskSet.from_arrays(
        base.chainage_m, base.lat_deg, base.lon_deg, base.h_m, base.heading_deg,
        base.mask_el_deg, source=base.source, support=sup,
    )  # fmt: skip
    assert WEAK_SUPPORT == 2 and ms.support is not None and not ms.support.flags.writeable
    lo, hi = float(ms.chainage_m[2]), float(ms.chainage_m[5])
    assert np.array_equal(ms.subset(lo, hi).support, sup[2:6])
    a, b = ms.subset(-1e9, float(ms.chainage_m[4])), ms.subset(float(ms.chainage_m[5]), 1e9)
    assert np.array_equal(concat_masksets([a, b]).support, sup)
    # a part without support: the whole has none (a missing count is not "no view")
    assert concat_masksets([a, base.subset(float(base.chainage_m[5]), 1e9)]).support is None
    assert not ms.equals(base) and ms.equals(ms.subset(-1e9, 1e9))
    # inserted gap positions rest on nothing: support 0; the others keep theirs
    keep = np.r_[0:3, 7:10]
    holed = MaskSet.from_arrays(
        100.0 + 10.0 * keep, ms.lat_deg[keep], ms.lon_deg[keep], ms.h_m[keep],
        ms.heading_deg[keep], ms.mask_el_deg[keep], source=ms.source[keep], support=sup[keep],
    )  # fmt: skip
    closed, gaps = close_gaps(holed, _LineTrack())
    assert gaps == [(120.0, 170.0)] and closed.n_pos == 10 and closed.support is not None
    new = np.isin(closed.chainage_m, [130.0, 140.0, 150.0, 160.0])
    assert np.all(closed.support[new] == 0)
    assert np.array_equal(closed.support[~new], sup[keep])


class _LineTrack:
    """Positions on a meridian, for close_gaps (which only asks positions and headings)."""

    name = "line"

    def position_at(self, chainage_m):
        s = np.asarray(chainage_m, float)
        return 50.0 + s / 111_000.0, np.full(s.shape, 4.0), np.full(s.shape, 100.0)

    def heading_at(self, chainage_m):
        return np.zeros(np.shape(chainage_m))


def test_assumed_over_matches_every_cell_touching_the_interval():
    from predisat.masks.maskset import BinSource

    rng = np.random.default_rng(3)
    base = make_set(n_pos=40)
    src = np.where(rng.random(base.mask_el_deg.shape) < 0.05, int(BinSource.ASSUMED),
                   int(BinSource.OBSERVED))  # fmt: skip
    ms = MaskSet.from_arrays(base.chainage_m, base.lat_deg, base.lon_deg, base.h_m,
                             base.heading_deg, base.mask_el_deg, source=src)  # fmt: skip
    b = ms.cell_bounds_m
    for _ in range(200):
        lo, hi = np.sort(rng.uniform(b[0] - 20.0, b[-1] + 20.0, 2))
        got = ms.assumed_over(lo, hi)
        if lo < b[0] or hi > b[-1]:
            assert got.all()  # the train may be where no mask exists
            continue
        touching = (b[1:] >= lo) & (b[:-1] <= hi)  # brute force: closed cells
        assert np.array_equal(got, (src[touching] == BinSource.ASSUMED).any(axis=0))
    with pytest.raises(MaskError, match="lo <= hi"):
        ms.assumed_over(10.0, 5.0)


def test_bin_source_codes_are_0_to_n_minus_1() -> None:
    # _source_array validates codes with a range check: a code out of the range would pass
    assert [int(s) for s in BinSource] == list(range(len(BinSource)))
