"""Figures of the availability report (matplotlib, no pyplot state).

Every function returns a :class:`matplotlib.figure.Figure` built without ``pyplot`` (so no
global figure registry and no GUI backend is touched) and is drawn from
:class:`~predisat.availability.engine.Availability` results of one line, one window and several
trust
rules. Along-line figures share the same x axis (chainage in km, kilometre posts on the top
axis) so they can be read one under the other.

* :func:`availability_along_line` - share of time with >= 4 and >= 6 trusted satellites;
* :func:`count_maps` - chainage x time maps of trusted-satellite counts, one per rule, with the
  discrete classes of :data:`COUNT_CLASSES`;
* :func:`sky_plots` - polar sky plots (north up, azimuth clockwise, zenith at the centre) with
  the mask filled and the satellite tracks over the window;
* :func:`opening_angle_along_line` and :func:`interval_along_line`.

:func:`figure_to_png` renders a figure to PNG bytes for embedding.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TypedDict

import matplotlib.dates as mdates
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from numpy.typing import NDArray

from predisat.availability.engine import Availability
from predisat.geodesy import LocalFrame
from predisat.gnss.timescale import gps_s_to_datetime64
from predisat.track import KilometrePost, TrackMap

__all__ = [
    "COUNT_CLASSES",
    "LOCOPROL",
    "LineStyle",
    "SkyView",
    "availability_along_line",
    "check_results",
    "count_maps",
    "figure_to_png",
    "interval_along_line",
    "line_map",
    "opening_angle_along_line",
    "rule_style",
    "sky_plots",
]

COUNT_CLASSES: tuple[tuple[int, int | None, str, str], ...] = (
    (0, 2, "0-1", "#b2182b"),
    (2, 4, "2-3", "#f4a582"),
    (4, 6, "4-5", "#92c5de"),
    (6, None, "6+", "#2166ac"),
)
"""Count classes of the maps: (lowest count, first count above, label, colour)."""

LOCOPROL: dict[str, float] = {
    "share_ge4": 0.95,
    "share_ge6": 0.60,
    "interval_typical_m": 70.0,
    "interval_max_m": 600.0,
    "opening_angle_open_deg": 170.0,
}
"""LOCOPROL trials on line 144 (GPS, real masking; ``docs/seeds-digest.md``)."""

_REF_COLOUR = "#6a3d9a"
_INTERVAL_CLIP_M = 10000.0
_MAP_MAX_CELLS = (400, 720)  # (positions, epochs) drawn per count-map panel
_FIG_W_IN = 11.0


class LineStyle(TypedDict):
    """Keyword arguments of ``Axes.plot`` that draw a trust rule."""

    color: str
    linestyle: str
    linewidth: float


def rule_style(label: str, index: int = 0) -> LineStyle:
    """Line style of a trust rule in every figure (masks: solid blue; no mask: grey dashed)."""
    if label == "masks":
        return {"color": "#1f5fa8", "linestyle": "-", "linewidth": 1.8}
    if label == "no mask":
        return {"color": "#7f7f7f", "linestyle": "--", "linewidth": 1.4}
    others = ("#e6730b", "#8c564b", "#2ca02c", "#bcbd22")
    return {"color": others[index % len(others)], "linestyle": ":", "linewidth": 1.8}


def _styles(results: Sequence[Availability]) -> list[LineStyle]:
    out, k = [], 0
    for r in results:
        out.append(rule_style(r.rule, k))
        if r.rule not in ("masks", "no mask"):
            k += 1
    return out


def figure_to_png(fig: Figure, dpi: int = 100) -> bytes:
    """PNG bytes of a figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


# ------------------------------------------------------------------------- axes helpers
def _km_axis(
    ax: Axes, posts: Sequence[KilometrePost], lo_m: float, hi_m: float, max_labels: int = 14,
    lines: bool = True,
) -> None:  # fmt: skip
    """Kilometre posts (``KilometrePost``-like: chainage_m, km_m, label) on the top axis.

    Posts closer than ``(hi - lo) / max_labels`` to the previous labelled one are skipped so
    the labels never overlap.
    """
    shown = _thin(posts, lo_m, hi_m, max_labels)
    top = ax.secondary_xaxis("top")
    top.set_xticks(
        [p.chainage_m / 1000.0 for p in shown],
        [p.label or f"km {p.km_m / 1000.0:.3f}" for p in shown],
    )
    top.tick_params(labelsize=7, length=3)
    if lines:
        for p in shown:
            ax.axvline(p.chainage_m / 1000.0, color="#dddddd", linewidth=0.6, zorder=0)


def _thin(
    posts: Sequence[KilometrePost], lo_m: float, hi_m: float, max_labels: int
) -> list[KilometrePost]:
    """Posts inside [lo, hi], each at least (hi - lo) / max_labels after the previous one."""
    inside = sorted((p for p in posts if lo_m <= p.chainage_m <= hi_m), key=_chainage)
    gap = (hi_m - lo_m) / max(max_labels, 1)
    shown: list[KilometrePost] = []
    for p in inside:
        if not shown or p.chainage_m - shown[-1].chainage_m >= gap:
            shown.append(p)
    return shown


def _chainage(post: KilometrePost) -> float:
    return float(post.chainage_m)


def _along_axes(
    n_rows: int, height_in: float, results: Sequence[Availability], posts: Sequence[KilometrePost]
) -> tuple[Figure, list[Axes]]:
    fig = Figure(figsize=(_FIG_W_IN, height_in), layout="constrained")
    axes = [fig.add_subplot(n_rows, 1, i + 1) for i in range(n_rows)]
    s = results[0].chainage_m
    lo, hi = float(s[0]), float(s[-1])
    for i, ax in enumerate(axes):
        ax.set_xlim(lo / 1000.0, hi / 1000.0)
        ax.grid(True, axis="y", color="#e5e5e5", linewidth=0.6)
        if i == 0:
            _km_axis(ax, posts, lo, hi)
        else:
            for p in _thin(posts, lo, hi, 14):
                ax.axvline(p.chainage_m / 1000.0, color="#dddddd", linewidth=0.6, zorder=0)
        if i < n_rows - 1:
            ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("chainage (km)")
    return fig, axes


def check_results(results: Sequence[Availability]) -> None:
    """Fail unless ``results`` holds at least one result and all share their positions.

    Parameters
    ----------
    results : sequence of Availability
        One per trust rule.

    Raises
    ------
    ValueError
        Empty, or a rule computed on other positions than the first.
    """
    if not results:
        raise ValueError("results is empty: pass at least one Availability")
    s0 = results[0].chainage_m
    for r in results[1:]:
        if r.chainage_m.shape != s0.shape or not np.allclose(r.chainage_m, s0):
            raise ValueError(
                f"results must share their positions: rule {r.rule!r} has "
                f"{len(r.chainage_m)} positions, {results[0].rule!r} {len(s0)}; "
                "compute every rule on the same LinePositions"
            )


# ------------------------------------------------------------------------- along the line
def availability_along_line(
    results: Sequence[Availability], kilometre_posts: Sequence[KilometrePost] = ()
) -> Figure:
    """Share of time with >= 4 (top) and >= 6 (bottom) trusted satellites along the line.

    Parameters
    ----------
    results : sequence of Availability
        One per trust rule, on the same positions.
    kilometre_posts : sequence of KilometrePost, optional
        Shown on the top axis.
    """
    check_results(results)
    fig, axes = _along_axes(2, 4.6, results, kilometre_posts)
    for ax, n in zip(axes, (4, 6), strict=True):
        for r, style in zip(results, _styles(results), strict=True):
            ax.plot(r.chainage_m / 1000.0, 100.0 * r.share_at_least(n), label=r.rule, **style)
        ref = LOCOPROL[f"share_ge{n}"]
        ax.axhline(100 * ref, color=_REF_COLOUR, linewidth=1.0, linestyle=(0, (6, 3)))
        ax.text(
            0.995, 100 * ref, f"LOCOPROL line 144: {100 * ref:.0f} %", color=_REF_COLOUR,
            ha="right", va="bottom", fontsize=7, transform=ax.get_yaxis_transform(),
        )  # fmt: skip
        ax.set_ylim(-3, 105)
        ax.set_ylabel(f"time with ≥ {n}\ntrusted sats (%)")
    axes[0].legend(loc="lower left", fontsize=8, ncol=len(results), framealpha=0.9)
    return fig


def opening_angle_along_line(
    results: Sequence[Availability], kilometre_posts: Sequence[KilometrePost] = ()
) -> Figure:
    """Cross-track opening angle along the line, per rule (degrees)."""
    check_results(results)
    fig, (ax,) = _along_axes(1, 2.6, results, kilometre_posts)
    for r, style in zip(results, _styles(results), strict=True):
        ax.plot(r.chainage_m / 1000.0, r.opening_angle_deg, label=r.rule, **style)
    ref = LOCOPROL["opening_angle_open_deg"]
    ax.axhline(ref, color=_REF_COLOUR, linewidth=1.0, linestyle=(0, (6, 3)))
    ax.text(
        0.995, ref, "LOCOPROL: up to 170° in open country", color=_REF_COLOUR, ha="right",
        va="top", fontsize=7, transform=ax.get_yaxis_transform(),
    )  # fmt: skip
    lo = min(float(np.nanmin(r.opening_angle_deg)) for r in results)
    ax.set_ylim(max(min(lo - 10.0, 120.0), -10.0), 185)
    ax.set_ylabel("opening angle (°)")
    ax.legend(loc="lower left", fontsize=8, ncol=len(results), framealpha=0.9)
    return fig


def interval_along_line(
    results: Sequence[Availability], kilometre_posts: Sequence[KilometrePost] = ()
) -> Figure:
    """Predicted interval length along the line: median (line) and 95th percentile (band).

    Over the epochs with >= 4 trusted satellites at each position; log scale.
    """
    check_results(results)
    fig, (ax,) = _along_axes(1, 3.0, results, kilometre_posts)
    any_value = False
    top = 0.0
    for r, style in zip(results, _styles(results), strict=True):
        q = r.interval_quantiles((0.5, 0.95))
        top = max(top, float(np.nanmax(q, initial=0.0)))
        x = r.chainage_m / 1000.0
        if np.any(np.isfinite(q)):
            any_value = True
        ax.plot(x, q[:, 0], label=f"{r.rule} (median)", **style)
        ax.fill_between(x, q[:, 0], q[:, 1], color=style["color"], alpha=0.15, linewidth=0)
        ax.plot(x, q[:, 1], color=style["color"], linewidth=0.7, alpha=0.8)
    for key, text in (("interval_typical_m", "typical"), ("interval_max_m", "largest")):
        ref = LOCOPROL[key]
        ax.axhline(ref, color=_REF_COLOUR, linewidth=1.0, linestyle=(0, (6, 3)))
        ax.text(
            0.995, ref, f"LOCOPROL {text}: {ref:.0f} m", color=_REF_COLOUR, ha="right",
            va="bottom", fontsize=7, transform=ax.get_yaxis_transform(),
        )  # fmt: skip
    ax.set_ylabel("interval length (m)")
    if any_value:
        ax.set_yscale("log")
        # a few places without geometry give km-long intervals; keep the usual range readable
        ax.set_ylim(top=min(max(top * 1.3, 1000.0), _INTERVAL_CLIP_M))
        if top > _INTERVAL_CLIP_M:
            ax.set_ylabel(f"interval length (m)\nclipped at {_INTERVAL_CLIP_M / 1000:g} km")
    ax.legend(loc="upper left", fontsize=8, ncol=len(results), framealpha=0.9)
    return fig


# ------------------------------------------------------------------------- chainage x time
def _count_cmap() -> tuple[ListedColormap, BoundaryNorm]:
    cmap = ListedColormap([c[3] for c in COUNT_CLASSES])
    bounds = [c[0] for c in COUNT_CLASSES] + [256]
    return cmap, BoundaryNorm(bounds, cmap.N)


def count_maps(
    results: Sequence[Availability], kilometre_posts: Sequence[KilometrePost] = ()
) -> Figure:
    """Trusted-satellite count over chainage (x) and GPS time (y), one panel per rule.

    Counts are binned in :data:`COUNT_CLASSES`; every cell is one position and one epoch, or,
    beyond 400 positions or 720 epochs, the lowest count of a block of them.
    """
    check_results(results)
    n = len(results)
    fig = Figure(figsize=(_FIG_W_IN, 3.9), layout="constrained")
    axes = [fig.add_subplot(1, n, i + 1) for i in range(n)]
    cmap, norm = _count_cmap()
    s = results[0].chainage_m
    t = results[0].gps_s
    lo_s, hi_s = _edges(s)
    lo_t, hi_t = _edges(t)
    t_num = mdates.date2num(gps_s_to_datetime64(np.array([lo_t, hi_t])).astype("M8[us]"))
    for i, (ax, r) in enumerate(zip(axes, results, strict=True)):
        ax.imshow(
            _block_min(r.count, _MAP_MAX_CELLS).T, origin="lower", aspect="auto",
            interpolation="nearest", cmap=cmap, norm=norm,
            extent=(lo_s / 1000.0, hi_s / 1000.0, t_num[0], t_num[1]),
        )  # fmt: skip
        ax.yaxis_date()
        ax.yaxis.set_major_formatter(mdates.DateFormatter("%H:%M"))
        ax.set_title(r.rule, fontsize=10)
        ax.set_xlabel("chainage (km)")
        if i == 0:
            day = str(gps_s_to_datetime64(t[0]).astype("M8[D]"))
            ax.set_ylabel(f"GPS time ({day})")
        else:
            ax.tick_params(labelleft=False)
        _km_axis(ax, kilometre_posts, float(s[0]), float(s[-1]), max_labels=3, lines=False)
    handles = [Patch(color=c[3], label=c[2]) for c in COUNT_CLASSES]
    fig.legend(
        handles=handles, title="trusted satellites", loc="outside right center", fontsize=8,
        title_fontsize=8, frameon=False,
    )  # fmt: skip
    return fig


def _cells(chainage_m: NDArray) -> tuple[NDArray, NDArray]:
    """Cell bounds of positions: half-way to the neighbours, half a spacing beyond the ends."""
    c = np.asarray(chainage_m, float)
    if len(c) == 1:
        return c.copy(), c.copy()
    mid = (c[1:] + c[:-1]) / 2.0
    return np.r_[2 * c[0] - mid[0], mid], np.r_[mid, 2 * c[-1] - mid[-1]]


def _block_min(count: NDArray, max_cells: tuple[int, int]) -> NDArray:
    """Block minimum of a (n_pos, n_epoch) array down to at most ``max_cells`` cells.

    More cells than a panel has pixels would be resampled arbitrarily (and slowly); the block
    minimum keeps the worst count, the one that matters for safety.
    """
    out = np.asarray(count)
    for axis, limit in enumerate(max_cells):
        n = out.shape[axis]
        k = -(-n // limit)  # block length
        if k <= 1:
            continue
        pad = (-n) % k
        if pad:
            edge = np.take(out, [-1], axis=axis)
            out = np.concatenate([out, np.repeat(edge, pad, axis=axis)], axis=axis)
        shape = list(out.shape)
        shape[axis : axis + 1] = [shape[axis] // k, k]
        out = out.reshape(shape).min(axis=axis + 1)
    return out


def _edges(x: NDArray) -> tuple[float, float]:
    x = np.asarray(x, float)
    if len(x) < 2:
        return float(x[0]) - 0.5, float(x[0]) + 0.5
    return float(x[0] - (x[1] - x[0]) / 2.0), float(x[-1] + (x[-1] - x[-2]) / 2.0)


# ------------------------------------------------------------------------- sky plots
@dataclass(frozen=True)
class SkyView:
    """What one sky plot shows.

    Attributes
    ----------
    title : str
    heading_deg : float
        Track heading at the place (drawn as the track direction).
    az_step_deg : float
        Mask bin width (bin ``k`` centred on ``k * az_step_deg``).
    mask_el_deg, margin_deg : ndarray, shape (n_az,), or None
        Skyline and margin per bin, degrees (``None``: no mask / no margin drawn).
    sat_az_deg, sat_el_deg : ndarray, shape (n_epoch, n_sat)
        Satellite directions over the window (NaN where the ephemeris does not trust them).
    trusted : ndarray of bool, shape (n_epoch, n_sat)
        Trusted under the masks rule.
    sats : tuple of str
    cutoff_deg : tuple of float
        Flat cut-offs drawn as dotted circles.
    """

    title: str
    heading_deg: float
    az_step_deg: float
    mask_el_deg: NDArray | None
    margin_deg: NDArray | None
    sat_az_deg: NDArray
    sat_el_deg: NDArray
    trusted: NDArray
    sats: tuple[str, ...]
    cutoff_deg: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        shapes = [np.shape(self.sat_az_deg), np.shape(self.sat_el_deg), np.shape(self.trusted)]
        if not (shapes[0] == shapes[1] == shapes[2]) or len(shapes[0]) != 2:
            raise ValueError(
                "SkyView: sat_az_deg, sat_el_deg and trusted must share one shape "
                f"(n_epoch, n_sat), got {shapes[0]}, {shapes[1]}, {shapes[2]}"
            )
        if len(self.sats) != shapes[0][1]:
            raise ValueError(
                f"SkyView: {len(self.sats)} satellite names for {shapes[0][1]} columns"
            )


def _staircase(az_step_deg: float, values: NDArray) -> tuple[NDArray, NDArray]:
    """Bin values as a closed staircase in polar angle (radians)."""
    n = len(values)
    centre = np.arange(n) * az_step_deg
    edges = np.stack([centre - az_step_deg / 2.0, centre + az_step_deg / 2.0], axis=1).ravel()
    vals = np.repeat(np.asarray(values, float), 2)
    return np.radians(np.append(edges, edges[0] + 360.0)), np.append(vals, vals[0])


def _sky_axes(ax: Any) -> None:
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_rlim(0, 90)
    ax.set_rticks([30, 60, 90], ["60°", "30°", "0°"])
    ax.set_rlabel_position(200)
    ax.tick_params(labelsize=7)
    ax.set_thetagrids([0, 90, 180, 270], ["N", "E", "S", "W"])
    ax.grid(color="#cccccc", linewidth=0.5)


def _draw_sky(ax: Any, v: SkyView, label_sats: bool) -> None:
    _sky_axes(ax)
    if v.mask_el_deg is not None:
        margin = np.zeros_like(v.mask_el_deg) if v.margin_deg is None else v.margin_deg
        th, eff = _staircase(v.az_step_deg, np.minimum(v.mask_el_deg + margin, 90.0))
        _, raw = _staircase(v.az_step_deg, v.mask_el_deg)
        ax.fill_between(th, 90.0 - eff, 90.0, color="#f0c8a0", linewidth=0, zorder=1)
        ax.fill_between(th, 90.0 - raw, 90.0, color="#8c6d4f", linewidth=0, zorder=1.1)
    circle = np.radians(np.linspace(0, 360, 181))
    for c in v.cutoff_deg:
        ax.plot(circle, np.full_like(circle, 90.0 - c), color="#e6730b", linestyle=":",
                linewidth=1.0, zorder=2)  # fmt: skip
    # track direction: increasing chainage through the zenith
    h = np.radians(v.heading_deg)
    ax.plot([h + np.pi, h], [90, 90], color="#333333", linewidth=0.8, zorder=2)
    ax.annotate(
        "", xy=(h, 88), xytext=(h, 70), zorder=3,
        arrowprops={"arrowstyle": "-|>", "color": "#333333", "linewidth": 0.8},
    )  # fmt: skip
    for side, d in (("L", -90.0), ("R", 90.0)):
        ax.text(np.radians(v.heading_deg + d), 80, side, fontsize=8, fontweight="bold",
                ha="center", va="center", color="#333333", zorder=3)  # fmt: skip
    az = np.asarray(v.sat_az_deg, float)
    el = np.asarray(v.sat_el_deg, float)
    trusted = np.asarray(v.trusted, bool)
    theta = np.radians(az)
    r = 90.0 - el
    above = el > 0.0
    # break the polyline where the azimuth wraps through north
    wrap = np.zeros_like(above)
    wrap[1:] = np.abs(np.diff(theta, axis=0)) > np.pi
    ok_t = above & trusted & ~wrap
    ok_b = above & ~trusted & ~wrap
    ax.plot(theta, np.where(ok_b, r, np.nan), color="#b0b0b0", linewidth=0.8, zorder=4)
    ax.plot(theta, np.where(ok_t, r, np.nan), color="#1f5fa8", linewidth=1.3, zorder=5)
    if label_sats:
        for j, sat in enumerate(v.sats):
            el_j = np.where(above[:, j], el[:, j], -np.inf)
            if not np.isfinite(el_j).any():
                continue
            k = int(np.argmin(np.where(np.isfinite(el_j), el_j, np.inf)))  # where it sets/rises
            ax.text(theta[k, j], r[k, j], sat, fontsize=5.5, color="#222222", ha="center",
                    va="bottom", zorder=6)  # fmt: skip
    ax.set_title(v.title, fontsize=9)


def sky_plots(views: Sequence[SkyView], label_sats: bool = False) -> Figure:
    """Polar sky plots side by side: north up, azimuth clockwise, zenith at the centre.

    Filled: the mask (dark) and the margin (light); dotted circles: flat cut-offs; line with
    arrow: the track, increasing chainage; blue: satellite track while trusted under the masks,
    grey: above the horizon but not trusted.
    """
    if not views:
        raise ValueError("views is empty: pass at least one SkyView")
    n = len(views)
    ncol = min(n, 4)
    nrow = (n + ncol - 1) // ncol
    fig = Figure(figsize=(_FIG_W_IN, 3.2 * nrow + 0.5), layout="constrained")
    for i, v in enumerate(views):
        ax = fig.add_subplot(nrow, ncol, i + 1, projection="polar")
        _draw_sky(ax, v, label_sats)
    handles = [
        Patch(color="#8c6d4f", label="mask"),
        Patch(color="#f0c8a0", label="margin"),
        Patch(color="#1f5fa8", label="satellite, trusted"),
        Patch(color="#b0b0b0", label="satellite, masked"),
    ]
    if views[0].cutoff_deg:
        handles.append(Patch(color="#e6730b", label="flat cut-off (dotted)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8,
               frameon=False)  # fmt: skip
    return fig


# ------------------------------------------------------------------------- map
def line_map(
    result: Availability,
    track: TrackMap | None = None,
    classes: Sequence[tuple[float, str, str]] = (),
) -> Figure:
    """Map of the stretch (local east/north, km), segments coloured by share of time >= 4.

    Parameters
    ----------
    result : Availability
        The rule to colour by (the masks).
    track : TrackMap, optional
        Segments follow it; the rest of the track is drawn in light grey for orientation and
        its kilometre posts are marked.
    classes : sequence of (lower bound, label, colour)
        Share classes, highest first (default: a single blue).
    """
    classes = tuple(classes) or ((0.0, "all", "#1f5fa8"),)
    pos = result.positions
    mid = len(pos.chainage_m) // 2
    frame = LocalFrame(float(pos.lat_deg[mid]), float(pos.lon_deg[mid]), 0.0)
    lo, hi = _cells(pos.chainage_m)
    s = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, 5)[None, :]  # (n_pos, 5)
    if track is not None:
        lat, lon, _ = track.position_at(s)
    else:
        lat = np.interp(s, pos.chainage_m, pos.lat_deg)
        lon = np.interp(s, pos.chainage_m, pos.lon_deg)
    segs = list(frame.to_enu(lat, lon)[..., :2] / 1000.0)
    share = result.share_at_least(4)
    colours = [next((c for b, _, c in classes if sh >= b), classes[-1][2]) for sh in share]
    pts = np.concatenate(segs)
    span = np.ptp(pts[:, :2], axis=0) + 0.2
    height_in = 4.2
    width_in = float(np.clip(height_in * span[0] / span[1] + 1.8, 4.5, _FIG_W_IN))
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    if track is not None:
        s = np.linspace(0.0, float(track.length_m), 800)
        lat, lon, _ = track.position_at(s)
        xy = frame.to_enu(lat, lon)[:, :2] / 1000.0
        ax.plot(xy[:, 0], xy[:, 1], color="#cfcfcf", linewidth=1.2, zorder=1)
        for p in _thin(getattr(track, "kilometre_posts", ()), 0.0, float(track.length_m), 20):
            p_lat, p_lon, _ = track.position_at(p.chainage_m)
            x, y = frame.to_enu(p_lat, p_lon)[:2] / 1000.0
            ax.plot(x, y, "o", color="#555555", markersize=2.5, zorder=3)
            ax.annotate(p.label or f"km {p.km_m / 1000:.3f}", (x, y), fontsize=7,
                        color="#555555", xytext=(3, 3), textcoords="offset points")  # fmt: skip
    ax.add_collection(LineCollection(segs, colors=colours, linewidths=5, zorder=2))
    pad = 0.15 * max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]), 0.2)
    ax.set_xlim(pts[:, 0].min() - pad, pts[:, 0].max() + pad)
    ax.set_ylim(pts[:, 1].min() - pad, pts[:, 1].max() + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    ax.grid(True, color="#eeeeee", linewidth=0.6)
    handles = [Patch(color=c, label=label) for _, label, c in classes]
    fig.legend(handles=handles, title="time with ≥ 4\ntrusted (masks)", fontsize=8,
               title_fontsize=8, loc="outside right upper", frameon=False)  # fmt: skip
    return fig
