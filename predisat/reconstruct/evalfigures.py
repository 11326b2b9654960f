"""Figures of a mask evaluation (``predisat evaluate --out``): where along the line the masks
lose sky and where they trust blocked directions.

:func:`evaluation_figure` draws, for a :class:`predisat.reconstruct.evaluate.Comparison`:

* a chainage x relative-azimuth map of the error ``mask - truth`` (degrees; blue: the mask is
  too high, sky lost; red: too low, blocked directions trusted), azimuth measured clockwise
  from the direction of increasing chainage so that the track runs along 0 and 180 deg;
  ASSUMED bins hatched ``////`` and, when the mask file carries its support, the other
  weakly supported bins (fewer than :data:`~predisat.masks.maskset.WEAK_SUPPORT`
  independent views) dotted, so that one sees where the mask is a guess;
* per position, the share of truly visible directions lost, across and along the track
  (linear axis), and below, on an axis of its own, the share of trusted directions that are
  truly blocked with its 0.1 % target (log axis).

matplotlib only (no pyplot state); returns a :class:`matplotlib.figure.Figure`.
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from numpy.typing import ArrayLike, NDArray

from predisat.masks.margins import EL_STEP_DEG
from predisat.masks.maskset import WEAK_SUPPORT, BinSource
from predisat.reconstruct.evaluate import Comparison, trust_counts

__all__ = ["FALSE_TRUST_TARGET_PCT", "evaluation_figure", "flag_runs", "per_position_shares"]

FALSE_TRUST_TARGET_PCT = 0.1
"""The false-trust target drawn on its own (log) axis, percent of trusted directions."""


def per_position_shares(
    comparison: Comparison, margin_deg: ArrayLike = 0.0, el_step_deg: float = EL_STEP_DEG
) -> dict[str, NDArray]:
    """Sky lost and false trust per position.

    Parameters
    ----------
    comparison : Comparison
        Mask and truth, shape (n_pos, n_az).
    margin_deg : float or array_like, shape (n_pos, n_az)
        Margin of every bin, degrees.

    Returns
    -------
    dict of ndarray, shape (n_pos,)
        ``sky_lost_cross``, ``sky_lost_along`` (truly visible directions not trusted / truly
        visible, per sector; NaN when nothing is visible) and ``false_trust`` (trusted and
        truly blocked / trusted, all bins; 0 when nothing is trusted).
    """
    trusted, good, visible = trust_counts(
        comparison.mask_el_deg, comparison.truth_el_deg, margin_deg, el_step_deg
    )
    out: dict[str, NDArray] = {}
    for sector in ("cross", "along"):
        sel = comparison.sector == sector
        vis = np.where(sel, visible, 0).sum(axis=1).astype(float)
        got = np.where(sel, good, 0).sum(axis=1).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[f"sky_lost_{sector}"] = np.where(vis > 0, 1.0 - got / vis, np.nan)
    tr = trusted.sum(axis=1).astype(float)
    bad = tr - good.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out["false_trust"] = np.where(tr > 0, bad / np.maximum(tr, 1.0), 0.0)
    return out


def flag_runs(flags: NDArray, extent: tuple[float, float, float, float]) -> NDArray:
    """Rectangles covering the flagged cells of an image drawn with ``imshow(flags.T,
    origin="lower", extent=extent)``: one per run of flagged bins of a position.

    Parameters
    ----------
    flags : ndarray of bool, shape (n_pos, n_bin)
        Column ``i`` of the image is position ``i``, row ``k`` bin ``k``.
    extent : (x0, x1, y0, y1)
        The image's extent.

    Returns
    -------
    ndarray, shape (n_runs, 4, 2)
        Corners (x, y) of each rectangle, counter-clockwise from the lower left.
    """
    f = np.asarray(flags, bool)
    n_pos, n_bin = f.shape
    x0, x1, y0, y1 = extent
    dx, dy = (x1 - x0) / n_pos, (y1 - y0) / n_bin
    pad = np.zeros((n_pos, 1), bool)
    edge = np.diff(np.concatenate([pad, f, pad], axis=1).astype(np.int8), axis=1)
    pos, start = np.nonzero(edge == 1)
    _, stop = np.nonzero(edge == -1)  # same row-major order: the run's end
    xa, xb = x0 + pos * dx, x0 + (pos + 1) * dx
    ya, yb = y0 + start * dy, y0 + stop * dy
    return np.stack([np.stack([xa, ya], -1), np.stack([xb, ya], -1),
                     np.stack([xb, yb], -1), np.stack([xa, yb], -1)], axis=1)  # fmt: skip


def evaluation_figure(
    comparison: Comparison,
    margin_deg: ArrayLike = 0.0,
    title: str = "",
    heading_deg: ArrayLike | None = None,
) -> Figure:
    """Error map and per-position shares of one evaluation.

    Parameters
    ----------
    comparison : Comparison
        Mask and truth, shape (n_pos, n_az).
    margin_deg : float or array_like, shape (n_pos, n_az)
        Margin of every bin (for the shares), degrees.
    title : str
    heading_deg : array_like, shape (n_pos,), optional
        Track heading at the compared positions (direction of increasing chainage), degrees;
        default ``comparison.heading_deg`` (set by :func:`predisat.reconstruct.evaluate.compare`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    if heading_deg is None:
        heading_deg = comparison.heading_deg
    if heading_deg is None:
        raise ValueError("heading_deg is required when the comparison carries no heading")
    hd = np.asarray(heading_deg, float)
    s = np.asarray(comparison.chainage_m, float)
    if hd.shape != s.shape:
        raise ValueError(
            f"heading_deg must have one value per compared position ({s.size}), got {hd.shape}"
        )
    az = np.asarray(comparison.az_deg, float)
    rel = np.mod(az[None, :] - hd[:, None], 360.0)
    # bins are regular, so sorted by azimuth from the heading, column k sits at ~k * step
    order = np.argsort(rel, axis=1)
    err = np.take_along_axis(comparison.mask_el_deg - comparison.truth_el_deg, order, axis=1)
    shares = per_position_shares(comparison, margin_deg)

    fig = Figure(figsize=(11, 9.0), layout="constrained")
    ax, bx, cx = fig.subplots(3, 1, sharex=True, height_ratios=[3, 1.6, 1.6])
    step = float(np.median(np.diff(s))) if s.size > 1 else 10.0
    extent = (s[0] - step / 2, s[-1] + step / 2, 0.0, 360.0)
    img = ax.imshow(
        err.T, origin="lower", aspect="auto", extent=extent, cmap="RdBu", vmin=-30, vmax=30,
        interpolation="nearest",
    )  # fmt: skip
    for y, name in ((0.0, "ahead"), (90.0, "right"), (180.0, "behind"), (270.0, "left")):
        ax.axhline(y, color="k", lw=0.4, alpha=0.5)
        ax.text(extent[0], y + 2, f" {name}", fontsize=7, va="bottom")
    for y in (45.0, 135.0, 225.0, 315.0):
        ax.axhline(y, color="k", lw=0.4, ls=":", alpha=0.5)
    ax.set_ylabel("azimuth from the direction\nof increasing chainage (deg)")
    ax.set_yticks([0, 45, 90, 135, 180, 225, 270, 315, 360])
    flags = {
        "assumed": comparison.source == BinSource.ASSUMED,
        "weak": (np.zeros(err.shape, bool) if comparison.support is None else
                 (comparison.support < WEAK_SUPPORT) & (comparison.source != BinSource.ASSUMED)
                 & (comparison.source != BinSource.TERRAIN)),
    }  # fmt: skip
    handles = []
    for name, hatch, colour, label in (
        ("assumed", "////", "#222222", "assumed (not seen)"),
        ("weak", "....", "#6a3d9a", f"weakly supported (< {WEAK_SUPPORT} views)"),
    ):
        runs = flag_runs(np.take_along_axis(flags[name], order, axis=1), extent)
        if runs.size:
            ax.add_collection(PolyCollection(
                list(runs), facecolors="none", edgecolors=colour, hatch=hatch, linewidths=0,
                gid=name,
            ))  # fmt: skip
            handles.append(Patch(facecolor="white", edgecolor=colour, hatch=hatch, label=label))
    if handles:
        ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.9)
    cb = fig.colorbar(img, ax=ax, shrink=0.9)
    cb.set_label("mask - truth (deg)\nblue: sky lost, red: blocked trusted")
    ax.set_title(title or "Masks against ground truth")

    # each quantity on its own axis: a target on a log axis never sits on a linear scale
    bx.plot(s, 100 * shares["sky_lost_cross"], color="#2166ac", lw=1.2, label="across the track")
    bx.plot(s, 100 * shares["sky_lost_along"], color="#67a9cf", lw=1.2, label="along the track")
    bx.set_ylabel("sky lost (%)\ntruly visible, not trusted")
    bx.set_ylim(0, 101)
    bx.grid(alpha=0.3)
    bx.legend(loc="upper right", fontsize=8, ncol=2)
    bx.set_title("Sky lost: truly visible directions the masks do not trust (cost)", fontsize=9,
                 loc="left")  # fmt: skip

    ft = 100 * shares["false_trust"]
    cx.set_yscale("log")
    cx.set_ylim(1e-4, 100)
    cx.plot(s[ft > 0], ft[ft > 0], "o", ms=3, color="#b2182b",
            label="false trust (trusted & blocked / trusted)")  # fmt: skip
    cx.axhline(FALSE_TRUST_TARGET_PCT, color="#b2182b", ls="--", lw=1.0,
               label=f"target {FALSE_TRUST_TARGET_PCT:g} %")  # fmt: skip
    cx.set_ylabel("false trust (%)\nlog scale")
    cx.grid(alpha=0.3, which="major")
    zero = int(np.sum(ft <= 0))
    cx.set_title(
        "False trust: trusted directions that are truly blocked (safety); "
        f"none at {zero} of {ft.size} positions (not drawn on the log axis)",
        fontsize=9, loc="left",
    )  # fmt: skip
    cx.legend(loc="upper right", fontsize=8)
    cx.set_xlabel("chainage (m)")
    return fig
