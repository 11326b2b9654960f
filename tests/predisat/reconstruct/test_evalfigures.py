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


def test_each_target_sits_on_its_own_axis() -> None:
    """The 0.1 % false-trust target is a horizontal line on a log axis that holds nothing
    else; the sky-lost axis is linear and holds no target (issue 33: the target used to sit on
    a twin axis at the height of "50 %" of the sky-lost scale)."""
    from predisat.reconstruct.evalfigures import FALSE_TRUST_TARGET_PCT

    comp, heading = _comparison()
    fig = evaluation_figure(comp, 0.5, title="t", heading_deg=heading)
    image, lost, trust = (ax for ax in fig.axes if ax.get_label() != "<colorbar>")
    # no twin axes: every data axis has its own place in the figure
    boxes = [ax.get_position().bounds for ax in (image, lost, trust)]
    assert len(set(boxes)) == 3
    assert lost.get_yscale() == "linear" and trust.get_yscale() == "log"
    assert "sky lost (%)" in lost.get_ylabel() and "false trust (%)" in trust.get_ylabel()

    def flat_lines(ax):
        return [ln for ln in ax.get_lines() if len(set(np.asarray(ln.get_ydata(), float))) == 1]

    assert flat_lines(lost) == []
    (target,) = flat_lines(trust)
    assert np.asarray(target.get_ydata(), float)[0] == FALSE_TRUST_TARGET_PCT == 0.1
    assert "0.1 %" in target.get_label()
    # the target is drawn at 0.1 on the axis' own (log) scale: its display height matches
    fig.canvas.draw()
    y_disp = trust.transData.transform((0.0, 0.1))[1]
    y0, y1 = trust.get_window_extent().y0, trust.get_window_extent().y1
    lo, hi = np.log10(trust.get_ylim())
    assert (y_disp - y0) / (y1 - y0) == pytest.approx((np.log10(0.1) - lo) / (hi - lo))


def _covered(runs: np.ndarray, n_pos: int, n_bin: int, extent) -> np.ndarray:
    """Cells whose centre lies inside one of the rectangles (brute force)."""
    x0, x1, y0, y1 = extent
    xc = x0 + (np.arange(n_pos) + 0.5) * (x1 - x0) / n_pos
    yc = y0 + (np.arange(n_bin) + 0.5) * (y1 - y0) / n_bin
    out = np.zeros((n_pos, n_bin), int)
    for r in runs:
        (xa, ya), (xb, yb) = r[0], r[2]
        out += ((xc[:, None] > xa) & (xc[:, None] < xb)) & ((yc[None, :] > ya) & (yc[None, :] < yb))
    return out


def test_flag_runs_cover_exactly_the_flagged_cells() -> None:
    from predisat.reconstruct.evalfigures import flag_runs

    rng = np.random.default_rng(0)
    flags = rng.random((9, 40)) < 0.3
    flags[:, -1] = True  # runs reaching the last bin
    extent = (995.0, 1085.0, 0.0, 360.0)
    runs = flag_runs(flags, extent)
    cov = _covered(runs, *flags.shape, extent)
    assert cov.max() == 1  # no overlap
    np.testing.assert_array_equal(cov.astype(bool), flags)
    # one rectangle per run of a position
    n_runs = sum(int(np.sum(np.diff(np.r_[0, row.astype(int), 0]) == 1)) for row in flags)
    assert runs.shape == (n_runs, 4, 2)


def test_figure_hatches_assumed_and_weakly_supported_bins() -> None:
    import dataclasses

    from predisat.reconstruct.evalfigures import flag_runs

    comp, heading = _comparison()
    rng = np.random.default_rng(1)
    source = rng.integers(0, 3, comp.mask_el_deg.shape).astype(np.uint8)
    support = rng.integers(0, 4, comp.mask_el_deg.shape).astype(np.uint8)
    comp = dataclasses.replace(comp, source=source, support=support)
    fig = evaluation_figure(comp, 0.5, title="t", heading_deg=heading)
    image = fig.axes[0]
    drawn = {c.get_gid(): c for c in image.collections if c.get_gid()}
    assert set(drawn) == {"assumed", "weak"}
    assert drawn["assumed"].get_hatch() == "////" and drawn["weak"].get_hatch() == "...."
    # the weak rectangles cover the bins with < 2 views that are not assumed, in the map's
    # order (azimuth from the heading)
    rel = np.mod(comp.az_deg[None, :] - heading[:, None], 360.0)
    order = np.argsort(rel, axis=1)
    want = np.take_along_axis((support < 2) & (source != 2), order, axis=1)
    s = comp.chainage_m
    extent = (s[0] - 5.0, s[-1] + 5.0, 0.0, 360.0)
    paths = np.array([p.vertices[:4] for p in drawn["weak"].get_paths()])
    np.testing.assert_allclose(paths, flag_runs(want, extent))
    assert _covered(paths, *want.shape, extent).astype(bool).tolist() == want.tolist()
    # a file without support: only the assumed bins are hatched
    fig = evaluation_figure(dataclasses.replace(comp, support=None), heading_deg=heading)
    assert {c.get_gid() for c in fig.axes[0].collections if c.get_gid()} == {"assumed"}
