"""Figures of a locator run (matplotlib, no pyplot state).

* :func:`interval_vs_time` - the confidence interval and the estimate against time, relative
  to the truth when it is known (error plot), with claimed and unclaimed epochs told apart and
  HMI epochs marked; the number of trusted satellites below;
* :func:`interval_vs_chainage` - the same along the line;
* :func:`length_histogram` - interval lengths of the claimed epochs per integrity mode, with
  LOCOPROL's typical 70 m and worst 600 m marked.

Every function takes the epoch table of :func:`locator.run.run_locator` (scored by
:func:`locator.evaluate.score_run` when truth is known) and returns a
:class:`matplotlib.figure.Figure`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["interval_vs_chainage", "interval_vs_time", "length_histogram"]

LOCOPROL_TYPICAL_M = 70.0
LOCOPROL_WORST_M = 600.0
_MODE_COLOURS = {"three_pairs": "#1b7837", "all_pairs": "#5aae61", "best_pair": "#f1a340"}


def _relative(epochs: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Estimate and bounds, minus the truth when known."""
    ref = epochs["truth_m"].to_numpy(float) if "truth_m" in epochs else 0.0
    label = "minus true chainage (m)" if "truth_m" in epochs else "chainage (m)"
    return (
        epochs["chainage_m"].to_numpy(float) - ref,
        epochs["lo_m"].to_numpy(float) - ref,
        epochs["hi_m"].to_numpy(float) - ref,
        label,
    )


def _draw(ax: Axes, x: np.ndarray, epochs: pd.DataFrame) -> None:
    est, lo, hi, label = _relative(epochs)
    claim = epochs["claim"].to_numpy(bool)
    for sel, colour, name in ((claim, "#2166ac", "claimed"), (~claim, "#bbbbbb", "no claim")):
        if sel.any():
            ax.vlines(
                x[sel], lo[sel], hi[sel], colour, lw=1.0, alpha=0.6, label=f"interval, {name}"
            )
    ax.plot(x, est, ".", ms=2, color="k", label="estimate")
    if "hmi" in epochs and epochs["hmi"].any():
        h = epochs["hmi"].to_numpy(bool)
        ax.plot(x[h], np.zeros(h.sum()) if "truth_m" in epochs else est[h], "rx", ms=7,
                label=f"HMI ({h.sum()})")  # fmt: skip
    if "truth_m" in epochs:
        ax.axhline(0.0, color="r", lw=0.8)
        finite = np.concatenate([lo[np.isfinite(lo)], hi[np.isfinite(hi)]])
        if finite.size:
            lim = float(np.percentile(np.abs(finite), 99)) * 1.2 + 5.0
            ax.set_ylim(-lim, lim)
    ax.set_ylabel(label)
    ax.legend(loc="upper right", fontsize=7, ncol=4)
    ax.grid(alpha=0.3)


def interval_vs_time(epochs: pd.DataFrame, title: str = "") -> Figure:
    """Interval and estimate against time since the first epoch, and trusted counts."""
    fig = Figure(figsize=(10, 6), layout="constrained")
    ax, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    t = epochs["gps_s"].to_numpy(float)
    t = t - t[0] if len(t) else t
    _draw(ax, t, epochs)
    ax.set_title(title or "Confidence interval against time")
    ax2.step(t, epochs["n_received"], where="mid", color="#999999", label="received")
    ax2.step(t, epochs["n_trusted"], where="mid", color="#2166ac", label="trusted")
    ax2.step(t, epochs["n_used"], where="mid", color="k", lw=0.8, label="used")
    for n in (2, 4, 6):
        ax2.axhline(n, color="#dddddd", lw=0.6, zorder=0)
    ax2.set_ylabel("satellites")
    ax2.set_xlabel("time since start (s)")
    ax2.legend(loc="upper right", fontsize=7, ncol=3)
    return fig


def interval_vs_chainage(epochs: pd.DataFrame, title: str = "") -> Figure:
    """Interval and estimate along the line (x: true chainage when known, else the estimate)."""
    fig = Figure(figsize=(10, 4), layout="constrained")
    ax = fig.subplots()
    col = "truth_m" if "truth_m" in epochs else "chainage_m"
    _draw(ax, epochs[col].to_numpy(float) / 1e3, epochs)
    ax.set_xlabel(("true " if col == "truth_m" else "estimated ") + "chainage (km)")
    ax.set_title(title or "Confidence interval along the line")
    return fig


def length_histogram(epochs: pd.DataFrame, title: str = "") -> Figure:
    """Histogram of claimed interval lengths per integrity mode (log x axis)."""
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    claim = epochs["claim"].to_numpy(bool)
    length = epochs["length_m"].to_numpy(float)
    ok = claim & np.isfinite(length) & (length > 0)
    if ok.any():
        bins = np.geomspace(max(length[ok].min(), 1.0), max(length[ok].max(), 10.0) * 1.01, 40)
        data, labels, colours = [], [], []
        for mode, colour in _MODE_COLOURS.items():
            sel = ok & (epochs["mode"].to_numpy(str) == mode)
            if sel.any():
                data.append(length[sel])
                labels.append(f"{mode.replace('_', ' ')} ({sel.sum()})")
                colours.append(colour)
        ax.hist(data, bins=list(bins), stacked=True, color=colours, label=labels)
        ax.set_xscale("log")
        med = float(np.median(length[ok]))
        ax.axvline(med, color="k", lw=1.0, label=f"median {med:.0f} m")
    for v, name in ((LOCOPROL_TYPICAL_M, "LOCOPROL typical"), (LOCOPROL_WORST_M, "LOCOPROL max")):
        ax.axvline(v, color="#b2182b", ls="--", lw=0.8, label=f"{name} {v:.0f} m")
    share = claim.mean() if len(claim) else 0.0
    ax.set_title(title or f"Interval length, claimed epochs ({100 * share:.1f} % of epochs)")
    ax.set_xlabel("interval length (m)")
    ax.set_ylabel("epochs")
    ax.legend(fontsize=7)
    return fig
