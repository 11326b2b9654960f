"""Tests of predisat.reconstruct.evalfigures: per-position shares against an explicit elevation
grid."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from predisat.masks.margins import sector_of
from predisat.reconstruct.evalfigures import evaluation_figure, per_position_shares
from predisat.reconstruct.evaluate import Comparison

GRID = (np.arange(900) + 0.5) * 0.1


def _comparison(seed: int = 4) -> tuple[Comparison, np.ndarray]:
    rng = np.random.default_rng(seed)
    n_pos, n_az = 12, 72
    truth = rng.uniform(0, 40, (n_pos, n_az))
    mask = np.clip(truth + rng.normal(2.0, 3.0, (n_pos, n_az)), 0, 90)
    az = np.arange(n_az) * 5.0
    heading = rng.uniform(0, 360, n_pos)
    comp = Comparison(
        chainage_m=1000.0 + 10.0 * np.arange(n_pos), mask_el_deg=mask, truth_el_deg=truth,
        source=np.zeros((n_pos, n_az), np.uint8), sector=sector_of(az[None, :], heading[:, None]),
        az_deg=az,
    )  # fmt: skip
    return comp, heading


def test_per_position_shares_match_an_explicit_grid() -> None:
    comp, _ = _comparison()
    margin = 1.5
    got = per_position_shares(comp, margin)
    g = GRID[None, None, :]
    trusted = g > (comp.mask_el_deg + margin)[..., None]
    visible = g > comp.truth_el_deg[..., None]
    for i in range(comp.chainage_m.size):
        ft = (trusted[i] & ~visible[i]).sum() / trusted[i].sum()
        assert got["false_trust"][i] == pytest.approx(ft)
        for sector in ("cross", "along"):
            sel = comp.sector[i] == sector
            lost = (visible[i][sel] & ~trusted[i][sel]).sum() / visible[i][sel].sum()
            assert got[f"sky_lost_{sector}"][i] == pytest.approx(lost)
    assert got["false_trust"].max() > 0  # the noisy masks do trust some blocked directions


def test_figure_draws_and_checks_headings() -> None:
    comp, heading = _comparison()
    fig = evaluation_figure(comp, 0.5, title="t", heading_deg=heading)
    assert isinstance(fig, Figure) and len(fig.axes) >= 3
    with pytest.raises(ValueError, match="heading_deg"):
        evaluation_figure(comp, heading_deg=heading[:-1])
    with pytest.raises(ValueError, match="heading_deg"):
        evaluation_figure(comp)  # built by hand, without headings
