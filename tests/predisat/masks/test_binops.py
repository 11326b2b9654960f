"""Tests for predisat.masks.binops against brute-force definitions."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.masks.binops import RangeMax, conservative_resample


def brute_window_max(row, step, a, w):
    """Max over bins whose closed interval meets the closed window [a - w, a + w] (circular)."""
    best = -np.inf
    for k, v in enumerate(row):
        d = abs((k * step - a + 180.0) % 360.0 - 180.0)  # circular distance of centres
        if d <= w + step / 2:
            best = max(best, float(v))
    return best


@pytest.mark.parametrize(("step", "w"), [(1.0, 1.0), (0.5, 1.0), (1.0, 0.5), (5.0, 3.75), (2.0, 0)])
def test_conservative_resample_matches_brute_force(step, w):
    rng = np.random.default_rng(8)
    n_az = round(360 / step)
    mask = rng.uniform(0, 60, (3, n_az))
    az = np.concatenate([np.arange(0, 361, 1.0), rng.uniform(0, 360, 50)])
    got = conservative_resample(mask, step, az, w)
    assert got.shape == (3, az.size)
    for p in range(3):
        want = [brute_window_max(mask[p], step, a, w) for a in az]
        np.testing.assert_allclose(got[p], want)


def test_conservative_resample_rejects_negative_width():
    with pytest.raises(ValueError, match="half_width_deg"):
        conservative_resample(np.zeros(360), 1.0, [0.0], -1.0)


@pytest.mark.parametrize(("n", "block"), [(1, 16), (7, 4), (100, 16), (257, 1), (300, 8)])
def test_range_max_matches_brute_force(n, block):
    rng = np.random.default_rng(n)
    values = rng.normal(size=(n, 5)).astype(np.float32)
    i = rng.integers(0, n, 500)
    j = np.minimum(i + rng.integers(0, n, 500) // rng.integers(1, 10, 500), n - 1)
    i, j = np.concatenate([i, [0, n - 1, 0]]), np.concatenate([j, [n - 1, n - 1, 0]])
    got = RangeMax(values, block=block).query(i, j)
    want = np.stack([values[a : b + 1].max(axis=0) for a, b in zip(i, j, strict=True)])
    np.testing.assert_array_equal(got, want)
