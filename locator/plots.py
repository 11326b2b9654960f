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

import textwrap
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = [
    "NO_SAFETY_BANNER",
    "forced",
    "interval_vs_chainage",
    "interval_vs_time",
    "length_histogram",
    "run_figures",
    "stanford_diagram",
    "systems_text",
]

LOCOPROL_TYPICAL_M = 70.0
LOCOPROL_WORST_M = 600.0
_MODE_COLOURS = {"three_pairs": "#1b7837", "all_pairs": "#5aae61", "best_pair": "#f1a340"}


def _with_systems(title: str, constellations: str) -> str:
    return _wrapped(f"{title} ({constellations})" if constellations else title)


def _wrapped(title: str, width: int = 110) -> str:
    """A title in lines of at most ``width`` characters (a long one ran off the figure at both
    ends, and with it a forced model's caveat: a user trial)."""
    return textwrap.fill(title, width)


NO_SAFETY_BANNER = ("NOT A SAFETY CLAIM: intervals under a forced error model or a fixed k "
                    "(no integrity budget)")  # fmt: skip
"""Written over every figure of a table some of whose claims are no safety claims, when the
caller does not say why (:func:`locator.run.no_safety_banner` says)."""


def forced(epochs: pd.DataFrame) -> bool:
    """True when some claim of the table is no safety claim (a forced error model or a fixed
    ``k``: column ``safety_claim``)."""
    return "safety_claim" in epochs and bool(
        (epochs["claim"].astype(bool) & ~epochs["safety_claim"].astype(bool)).any()
    )


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
    safe = epochs["safety_claim"].to_numpy(bool) if "safety_claim" in epochs else claim
    styles = ((claim & safe, "#2166ac", "claimed"),
              (claim & ~safe, "#e08214", "claimed, no safety claim"),
              (~claim, "#bbbbbb", "no claim"))  # fmt: skip
    for sel, colour, name in styles:
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


def run_figures(
    epochs: pd.DataFrame, title: str = "", banner: str | None = None
) -> dict[str, Figure]:
    """A run's figures by file name: interval against time and chainage, lengths and, when the
    table is scored (``truth_m``), the Stanford diagram; over each, in red, ``banner`` (why the
    claims are no safety claims: :func:`locator.run.no_safety_banner`), or
    :data:`NO_SAFETY_BANNER` when it is None and some claim of the table is no safety claim."""
    gnss = systems_text(epochs)
    figs = {
        "interval_time.png": interval_vs_time(epochs, title, gnss),
        "interval_chainage.png": interval_vs_chainage(epochs, title, gnss),
        "interval_lengths.png": length_histogram(epochs, constellations=gnss),
    }
    if "truth_m" in epochs:
        figs["stanford.png"] = stanford_diagram(epochs, title)
    if banner is None and forced(epochs):
        banner = NO_SAFETY_BANNER
    if banner:  # over every figure, not at the end of a title (a user trial)
        for fig in figs.values():
            fig.suptitle(banner, color="#b2182b", fontweight="bold", fontsize=11)
    return figs


def interval_vs_time(epochs: pd.DataFrame, title: str = "", constellations: str = "") -> Figure:
    """Interval and estimate against time since the first epoch, and trusted counts
    (``constellations`` named in the title)."""
    fig = Figure(figsize=(10, 6), layout="constrained")
    ax, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    t = epochs["gps_s"].to_numpy(float)
    t = t - t[0] if len(t) else t
    _draw(ax, t, epochs)
    ax.set_title(_with_systems(title or "Confidence interval against time", constellations))
    ax2.step(t, epochs["n_received"], where="mid", color="#999999", label="received")
    ax2.step(t, epochs["n_trusted"], where="mid", color="#2166ac", label="trusted")
    ax2.step(t, epochs["n_used"], where="mid", color="k", lw=0.8, label="used")
    for n in (2, 4, 6):
        ax2.axhline(n, color="#dddddd", lw=0.6, zorder=0)
    ax2.set_ylabel(f"{constellations}\nsatellites" if constellations else "satellites",
                   fontsize=8)  # fmt: skip
    ax2.set_xlabel("time since start (s)")
    ax2.legend(loc="upper right", fontsize=7, ncol=3)
    return fig


def interval_vs_chainage(
    epochs: pd.DataFrame, title: str = "", constellations: str = ""
) -> Figure:
    """Interval and estimate along the line (x: true chainage when known, else the estimate);
    ``constellations`` named in the title."""
    fig = Figure(figsize=(10, 4), layout="constrained")
    ax = fig.subplots()
    col = "truth_m" if "truth_m" in epochs else "chainage_m"
    _draw(ax, epochs[col].to_numpy(float) / 1e3, epochs)
    ax.set_xlabel(("true " if col == "truth_m" else "estimated ") + "chainage (km)")
    ax.set_title(_with_systems(title or "Confidence interval along the line", constellations))
    return fig


def length_histogram(epochs: pd.DataFrame, title: str = "", constellations: str = "") -> Figure:
    """Histogram of claimed interval lengths per integrity mode (log x axis).

    The x axis is labelled at 1-2-5 steps in plain metres (no overlapping minor labels);
    LOCOPROL's typical and largest intervals are drawn in two different styles.
    """
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    claim = epochs["claim"].to_numpy(bool)
    length = epochs["length_m"].to_numpy(float)
    ok = claim & np.isfinite(length) & (length > 0)
    lo, hi = LOCOPROL_TYPICAL_M, LOCOPROL_WORST_M
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
        med = float(np.median(length[ok]))
        ax.axvline(med, color="k", lw=1.0, label=f"median {med:.0f} m")
        lo, hi = min(lo, float(bins[0])), max(hi, float(bins[-1]))
    for v, name, colour, dash in _LOCOPROL_LINES:
        ax.axvline(v, color=colour, linestyle=dash, lw=1.2, label=f"{name} {v:.0f} m")
    ax.set_xscale("log")
    ax.set_xlim(lo / 1.15, hi * 1.15)
    _clean_log_ticks(ax, lo / 1.15, hi * 1.15)
    share = claim.mean() if len(claim) else 0.0
    gnss = f" - {constellations}" if constellations else ""
    what = "claimed epochs" if not forced(epochs) else "epochs claimed, no safety claim"
    ax.set_title(_wrapped(title or f"Interval length, {what} ({100 * share:.1f} % of "
                          f"epochs){gnss}"), fontsize=10)  # fmt: skip
    ax.set_xlabel("interval length (m, log scale)")
    ax.set_ylabel("epochs")
    ax.legend(fontsize=7)
    return fig


STANFORD_MIN_M = 0.1
"""Lower edge of the Stanford diagram's axes, metres (smaller errors are drawn on it)."""

_STANFORD_STYLE = {
    "normal": ("#1b7837", "normal"),
    "hmi": ("#b2182b", "HMI"),
    "unavailable": ("#6a6a6a", "unavailable"),
    "mi": ("#e08214", "MI"),
}


def stanford_diagram(
    scored: pd.DataFrame, title: str = "", alert_limit_m: float | None = None
) -> Figure:
    """Stanford integrity diagram: absolute along-track error against the protection level.

    Every epoch with an estimate and a bounded interval is a point (``|error|``, the
    half-interval toward the truth, :func:`locator.evaluate.stanford_points`) on log axes from
    :data:`STANFORD_MIN_M`: claimed epochs as a 2-D histogram (log colour), epochs without a
    claim in grey. Regions: below the
    diagonal the truth is inside the interval (normal when claimed, unavailable otherwise),
    above it outside (HMI when claimed, MI otherwise); with an alert limit, protection levels
    above it are unavailable. The count of each region is printed in it.

    Parameters
    ----------
    scored : pandas.DataFrame
        :func:`locator.evaluate.score_run` output.
    title : str
    alert_limit_m : float, optional
    """
    # lazy: evaluate is light, but keep the figure module's imports to plotting
    from matplotlib.colors import LogNorm

    from locator.evaluate import stanford_counts, stanford_points

    pts = stanford_points(scored, alert_limit_m)
    counts = stanford_counts(scored, alert_limit_m)
    region = pts["region"].to_numpy(str)
    x = pts["abs_error_m"].to_numpy(float)
    y = pts["protection_m"].to_numpy(float)
    drawn = region != "no_interval"
    fig = Figure(figsize=(6.4, 5.6), layout="constrained")
    ax = fig.subplots()
    finite = np.concatenate([x[drawn], y[drawn]])
    finite = finite[np.isfinite(finite) & (finite > 0)]
    top = float(finite.max()) * 1.5 if finite.size else 100.0
    if alert_limit_m is not None:
        top = max(top, 1.5 * alert_limit_m)
    lim = (STANFORD_MIN_M, max(top, 10.0 * STANFORD_MIN_M))  # smaller values drawn at the edge
    edges = np.geomspace(lim[0], lim[1], 61)
    claimed = drawn & np.isin(region, ["normal", "hmi"])
    if claimed.any():
        cx, cy = np.clip(x[claimed], *lim), np.clip(y[claimed], *lim)
        h, _, _ = np.histogram2d(cx, cy, bins=[edges, edges])
        # over the no-claim points: at a million epochs their cloud hid the claims
        mesh = ax.pcolormesh(edges, edges, np.where(h > 0, h, np.nan).T, cmap="viridis",
                             norm=LogNorm(vmin=1, vmax=max(float(h.max()), 2.0)),
                             zorder=2)  # fmt: skip
        per_bin = "claimed epochs per bin" + (" (no safety claim)" if forced(scored) else "")
        fig.colorbar(mesh, ax=ax, label=per_bin)
    other = drawn & ~claimed
    ax.fill_between(lim, lim, [lim[0], lim[0]], color="#b2182b", alpha=0.07, lw=0)
    ax.scatter(np.clip(x[other], *lim), np.clip(y[other], *lim), s=9, color="#555555",
               alpha=0.5, lw=0, label="no safety claim", rasterized=True, zorder=1)  # fmt: skip
    hmi = region == "hmi"
    ax.scatter(np.clip(x[hmi], *lim), np.clip(y[hmi], *lim), s=28,
               marker="x", color="#b2182b", label="HMI epochs", zorder=3)  # fmt: skip
    ax.plot(lim, lim, color="k", lw=1.0)
    if alert_limit_m is not None:
        ax.axhline(alert_limit_m, color="k", ls="--", lw=1.0)
        ax.text(lim[0] * 1.2, alert_limit_m * 1.08, f"alert limit {alert_limit_m:g} m",
                fontsize=8)  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(*lim)
    ax.set_ylim(*lim)
    ax.set_aspect("equal")
    # region labels with counts: below the diagonal inside, above it outside
    g = np.sqrt(lim[1] / lim[0])
    spots = {"normal": (lim[0] * g**0.25, lim[1] / g**0.35),
             "hmi": (lim[1] / g**0.35, lim[0] * g**0.25)}  # fmt: skip
    for key, (px, py) in spots.items():
        colour, name = _STANFORD_STYLE[key]
        ax.text(px, py, f"{name}\n{counts[key]:,}", color=colour, fontsize=10, ha="center",
                va="center", fontweight="bold")  # fmt: skip
    n_all = len(region)
    ax.text(0.98, 0.02,
            f"no claim: unavailable {counts['unavailable']:,}, MI {counts['mi']:,}\n"
            f"no interval {counts['no_interval']:,} of {n_all:,} epochs",
            transform=ax.transAxes, ha="right", va="bottom", fontsize=8,
            color=_STANFORD_STYLE["mi"][0])  # fmt: skip
    ax.set_xlabel("absolute along-track error |estimate - truth| (m)")
    ax.set_ylabel("protection level: half-interval toward the truth (m)")
    ax.set_title(_wrapped(title or "Stanford integrity diagram", 70))
    ax.legend(loc="upper left", fontsize=7)
    return fig


_LOCOPROL_LINES: tuple[tuple[float, str, str, str], ...] = (
    (LOCOPROL_TYPICAL_M, "LOCOPROL typical", "#b2182b", "--"),
    (LOCOPROL_WORST_M, "LOCOPROL max", "#542788", ":"),
)
"""The two LOCOPROL references: value, label, line style (distinct colour and dash)."""


def _clean_log_ticks(ax: Axes, lo: float, hi: float) -> None:
    """Major ticks at 1-2-5 steps inside [lo, hi] labelled in plain numbers, minor unlabelled;
    thinned to 1-10 steps when the range is wide."""
    decades = np.arange(np.floor(np.log10(lo)), np.ceil(np.log10(hi)) + 1)
    steps = (1.0, 2.0, 5.0) if np.log10(hi / lo) <= 2.5 else (1.0,)
    ticks = [m * 10.0**d for d in decades for m in steps if lo <= m * 10.0**d <= hi]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    ax.xaxis.set_minor_locator(LogLocator(base=10.0, subs=[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]))
    ax.xaxis.set_minor_formatter(NullFormatter())


def systems_text(epochs: pd.DataFrame) -> str:
    """The constellations of the satellites a run received (``used`` and ``excluded``
    columns), spelt out: ``"GPS + GLONASS + Galileo + BeiDou"``; "" when unknown."""
    ids: set[str] = set()
    for col in ("used", "excluded"):
        if col in epochs:
            for cell in epochs[col].dropna().astype(str).unique():
                ids.update(tok.split(":")[0] for tok in cell.split() if tok)
    letters = {i[0] for i in ids if len(i) >= 2 and i[0] in _SYSTEM_NAMES}
    return " + ".join(name for c, name in _SYSTEM_NAMES.items() if c in letters)


_SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS",
                 "I": "NavIC", "S": "SBAS"}  # fmt: skip
