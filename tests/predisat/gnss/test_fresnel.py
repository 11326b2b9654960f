"""Tests of predisat.gnss.fresnel: the thin-structure rule against a numerical integration of
the Fresnel-Kirchhoff field behind a strip (no scipy.special), on lamp arms, rails, contact
wires and masts at several distances."""

from __future__ import annotations

import numpy as np
import pytest

from predisat.gnss.fresnel import (
    L1_WAVELENGTH_M,
    L5_WAVELENGTH_M,
    TRANSPARENT_FRACTION,
    fresnel_radius_m,
    max_transparent_width_m,
    strip_loss_db,
    transparent,
)

LAMBDA = 0.190294  # c / 1575.42 MHz, m


def _loss_numeric(width_m: float, distance_m: float, offset_m: float, lam: float) -> float:
    """-20 log10 |1 - (1 + j)/2 * int_{v1}^{v2} exp(-j pi t^2 / 2) dt|, trapezoids."""
    s = np.sqrt(2.0 / (lam * distance_m))
    t = np.linspace((offset_m - width_m / 2) * s, (offset_m + width_m / 2) * s, 4001)
    f = np.exp(-1j * np.pi * t**2 / 2.0)
    integral = np.sum((f[1:] + f[:-1]) / 2.0 * np.diff(t))
    return float(-20.0 * np.log10(abs(1.0 - (1.0 + 1.0j) / 2.0 * integral)))


def _worst_loss(width_m: float, distance_m: float, lam: float = LAMBDA) -> float:
    r = np.sqrt(lam * distance_m)
    return max(_loss_numeric(width_m, distance_m, h, lam) for h in np.linspace(-r, r, 41))


def test_wavelengths_and_radius() -> None:
    assert L1_WAVELENGTH_M == pytest.approx(LAMBDA, abs=1e-6)
    assert L5_WAVELENGTH_M == pytest.approx(0.254828, abs=1e-6)
    assert fresnel_radius_m(10.0) == pytest.approx(np.sqrt(LAMBDA * 10.0))
    assert np.isnan(fresnel_radius_m(-1.0))


@pytest.mark.parametrize("width_m, distance_m, offset_m", [
    (0.012, 1.0, 0.0), (0.08, 3.0, 0.2), (0.3, 40.0, -1.0), (0.5, 2.0, 0.5),
])  # fmt: skip
def test_strip_loss_matches_the_numerical_integral(width_m, distance_m, offset_m) -> None:
    got = float(strip_loss_db(width_m, distance_m, offset_m))
    assert got == pytest.approx(_loss_numeric(width_m, distance_m, offset_m, LAMBDA), abs=1e-4)


def test_the_fraction_keeps_the_worst_loss_under_one_db() -> None:
    for d in (1.0, 5.0, 30.0):
        r = np.sqrt(LAMBDA * d)
        assert _worst_loss(TRANSPARENT_FRACTION * r, d) < 1.0
        assert _worst_loss(2.0 * TRANSPARENT_FRACTION * r, d) > 1.5  # twice as wide: not


# structure, width (m), distance from the antenna (m), transparent at L1 by the worst-case
# numerical loss (<= 0.915 dB, the loss of a strip of r_F / 10); hand-checked figures:
# r_F = sqrt(0.1903 d): 0.436 m at 1 m, 0.617 at 2, 0.975 at 5, 1.380 at 10, 2.76 at 40,
# 3.08 at 50
CASES = [
    ("contact wire 12 mm", 0.012, 0.5, True),
    ("contact wire 12 mm", 0.012, 1.0, True),
    ("contact wire 12 mm", 0.012, 20.0, True),
    ("cantilever tube 55 mm", 0.055, 1.5, False),
    ("cantilever tube 55 mm", 0.055, 2.0, True),
    ("lamp arm 80 mm", 0.08, 2.0, False),
    ("lamp arm 80 mm", 0.08, 5.0, True),
    ("footbridge rail 50 mm", 0.05, 1.0, False),
    ("footbridge rail 50 mm", 0.05, 3.0, True),
    ("mast 0.3 m", 0.3, 5.0, False),
    ("mast 0.3 m", 0.3, 40.0, False),
    ("mast 0.3 m", 0.3, 50.0, True),
]


@pytest.mark.parametrize("name, width_m, distance_m, want", CASES)
def test_structures_at_several_distances(name, width_m, distance_m, want) -> None:
    by_loss = _worst_loss(width_m, distance_m) <= 0.915
    assert by_loss == want, name
    assert bool(transparent(width_m, distance_m)) == want, name


def test_unknown_distance_is_never_transparent_and_l5_is_looser() -> None:
    assert not transparent(0.001, np.nan) and not transparent(0.001, np.inf)
    assert not transparent(np.nan, 5.0)
    assert max_transparent_width_m(np.nan) == 0.0
    # a 5.5 cm tube at 1.5 m: opaque at L1, transparent at L5 (the shortest wave decides)
    assert not transparent(0.055, 1.5) and transparent(0.055, 1.5, L5_WAVELENGTH_M)
