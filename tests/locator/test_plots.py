"""Figures of a locator run that cannot be misread (issue 33): clean log ticks, distinct
reference styles, the constellations named; the demo table shows every count."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba

from locator.demostep import format_demo_table
from locator.plots import interval_vs_chainage, interval_vs_time, length_histogram, systems_text


def _epochs(n: int = 200, seed: int = 2) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    truth = 4000.0 + 10.0 * np.arange(n)
    length = rng.uniform(18.0, 95.0, n)  # the demo's range: 2 x 10^1 .. 10^2 crowded labels
    est = truth + rng.normal(0.0, 2.0, n)
    return pd.DataFrame({
        "gps_s": 1.2771e9 + np.arange(n), "chainage_m": est, "lo_m": est - length / 2,
        "hi_m": est + length / 2, "length_m": length, "claim": np.ones(n, bool),
        "mode": np.where(np.arange(n) % 5 == 0, "all_pairs", "three_pairs"),
        "n_received": 24, "n_trusted": 9, "n_used": 9, "truth_m": truth,
        "used": "G01 G05 E11 R07", "excluded": "C08:outside_coverage",
    })  # fmt: skip


def _overlaps(boxes) -> bool:
    boxes = sorted(boxes, key=lambda b: b.x0)
    return any(a.x1 > b.x0 for a, b in pairwise(boxes))


def test_histogram_log_ticks_are_plain_and_do_not_overlap() -> None:
    fig = length_histogram(_epochs())
    ax = fig.axes[0]
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    lo, hi = ax.get_xlim()
    major = [t for t in ax.get_xticklabels() if t.get_text() and lo <= t.get_position()[0] <= hi]
    texts = [t.get_text() for t in major]
    # plain numbers at 1-2-5 steps, readable as metres (no "2 x 10^1" mathtext)
    assert texts == ["20", "50", "100", "200", "500"]
    assert all(float(t) in (20.0, 50.0, 100.0, 200.0, 500.0) for t in texts)
    assert not _overlaps([t.get_window_extent(renderer) for t in major])
    assert all(t.get_text() == "" for t in ax.get_xticklabels(minor=True))


def test_histogram_references_have_distinct_styles() -> None:
    ax = length_histogram(_epochs()).axes[0]
    refs = {ln.get_label(): ln for ln in ax.get_lines() if "LOCOPROL" in ln.get_label()}
    assert sorted(refs) == ["LOCOPROL max 600 m", "LOCOPROL typical 70 m"]
    a, b = refs.values()
    assert to_rgba(a.get_color()) != to_rgba(b.get_color())
    assert a.get_linestyle() != b.get_linestyle()


def test_titles_name_the_constellations() -> None:
    ep = _epochs()
    gnss = systems_text(ep)
    assert gnss == "GPS + GLONASS + Galileo + BeiDou"  # used G, E, R; excluded C
    assert systems_text(ep.drop(columns=["used", "excluded"])) == ""
    for fig in (interval_vs_time(ep, "run", gnss), interval_vs_chainage(ep, "run", gnss)):
        assert fig.axes[0].get_title() == f"run ({gnss})"
    assert gnss in length_histogram(ep, constellations=gnss).axes[0].get_title()


def test_demo_table_shows_mi_and_the_constellations() -> None:
    table = pd.DataFrame({
        "rule": ["pipeline masks", "no masks"], "claim_share": [0.69869, 0.825328],
        "mode_three_pairs_share": [0.663755, 0.951965], "length_median_m": [27.6, 25.8],
        "length_p95_m": [62.7, 34.4], "abs_error_median_m": [2.19, 1.89], "hmi": [0, 0],
        "hmi_fix": [0, 0], "mi": [1, 3],
    })  # fmt: skip
    text = format_demo_table(table, "GPS + Galileo")
    header, *rows = text.splitlines()
    assert header.split()[-1] == "MI"
    assert [r.split()[-1] for r in rows[:2]] == ["1", "3"]
    assert "69.9" in rows[0] and "0.69869" not in text  # percent, not fractions
    assert "GPS + Galileo received; the availability report above counts GPS only" in text


def test_claims_under_a_forced_model_are_drawn_and_bannered_as_no_safety_claim() -> None:
    """A user trial: a forced model's intervals were drawn as "interval, claimed", and the
    caveat, at the end of a 320-character title, ran off the figure."""
    from locator.plots import NO_SAFETY_BANNER, run_figures
    from locator.run import FORCED_BANNER, no_safety_banner

    long_title = "line 144 A: trust masks, k 3.89 per pair; " * 8
    ok = _epochs()
    ok["safety_claim"] = ok["claim"]
    for fig in run_figures(ok, long_title).values():
        assert fig._suptitle is None
    forced_ = ok.assign(safety_claim=False)
    figs = run_figures(forced_, long_title, no_safety_banner("forced"))
    assert set(figs) == {"interval_time.png", "interval_chainage.png", "interval_lengths.png",
                         "stanford.png"}  # fmt: skip
    for name, fig in figs.items():
        assert fig._suptitle is not None and fig._suptitle.get_text() == FORCED_BANNER, name
        title = fig.axes[0].get_title()
        assert all(len(line) <= 110 for line in title.splitlines()), name
    labels = figs["interval_time.png"].axes[0].get_legend_handles_labels()[1]
    assert "interval, claimed, no safety claim" in labels
    assert "interval, claimed" not in labels
    assert "no safety claim" in figs["interval_lengths.png"].axes[0].get_title()
    # a fixed k is no safety claim either, and is named as what it is, not a forced model;
    # a caller that does not say why gets the banner that covers both
    fixed = run_figures(forced_, long_title, no_safety_banner("", 2.0))["interval_time.png"]
    text = fixed._suptitle.get_text()
    assert "fixed k = 2" in text and "forced" not in text
    assert run_figures(forced_, long_title)["interval_time.png"]._suptitle.get_text() == (
        NO_SAFETY_BANNER)
    assert no_safety_banner("") is None and no_safety_banner("gaussian_tail") is None
