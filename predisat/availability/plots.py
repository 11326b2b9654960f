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
from matplotlib import patheffects
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Rectangle
from numpy.typing import NDArray

from predisat.availability.engine import Availability
from predisat.geodesy import LocalFrame, unwrap_lon_deg, wrap_lon_deg
from predisat.gnss.timescale import gps_s_to_datetime64, gps_s_to_utc_datetime64
from predisat.readonly import freeze_array_fields
from predisat.track import KilometrePost, TrackMap

__all__ = [
    "COUNT_CLASSES",
    "LOCOPROL",
    "SPAN_STYLES",
    "LineSpan",
    "LineStyle",
    "MapPoint",
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
_ONE_S = np.timedelta64(1, "s")


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
@dataclass(frozen=True)
class LineSpan:
    """A stretch labelled on the along-line figures (tunnel, bridge, no sky).

    Attributes
    ----------
    start_m, end_m : float
        Chainage bounds, metres.
    kind : str
        One of :data:`SPAN_STYLES` (``"tunnel"``, ``"bridge"``, ``"no sky"``).
    label : str
        Text written over the stretch (default: ``kind``).
    """

    start_m: float
    end_m: float
    kind: str
    label: str = ""

    def __post_init__(self) -> None:
        if self.kind not in SPAN_STYLES:
            raise ValueError(
                f"LineSpan.kind {self.kind!r} unknown; use one of {sorted(SPAN_STYLES)}"
            )
        if not self.end_m >= self.start_m:
            raise ValueError(
                f"LineSpan end_m ({self.end_m}) must not be before start_m ({self.start_m})"
            )

    @property
    def text(self) -> str:
        """The label written on the figures."""
        return self.label or self.kind


SPAN_STYLES: dict[str, dict[str, str]] = {
    "tunnel": {"color": "#4d4d4d", "hatch": "xx"},
    "bridge": {"color": "#8073ac", "hatch": "||"},
    "no sky": {"color": "#b2182b", "hatch": "//"},
}
"""Face colour and hatch of each kind of :class:`LineSpan`."""


def _post_label(p: KilometrePost) -> str:
    return p.label or f"km {p.km_m / 1000.0:.3f}"


def _x_axes(
    ax: Axes, posts: Sequence[KilometrePost], lo_m: float, hi_m: float, *, max_labels: int = 14,
    bottom: bool = True, top: bool = True,
) -> None:  # fmt: skip
    """Kilometre posts first (bottom axis, labelled), chainage beside (top axis, grey).

    Without kilometre posts the bottom axis is chainage. Posts closer than
    ``(hi - lo) / max_labels`` to the previous labelled one are skipped so labels never
    overlap. ``bottom`` / ``top``: draw the labels of that axis (rows of a stacked figure
    share them).
    """
    shown = _thin(posts, lo_m, hi_m, max_labels)
    for p in shown:
        ax.axvline(p.chainage_m / 1000.0, color="#dddddd", linewidth=0.6, zorder=0)
    if not shown:
        ax.tick_params(labelbottom=bottom)
        if bottom:
            ax.set_xlabel("chainage (km) - the track has no kilometre posts")
        return
    ax.set_xticks([p.chainage_m / 1000.0 for p in shown], [_post_label(p) for p in shown])
    ax.tick_params(axis="x", labelbottom=bottom, labelsize=8)
    if bottom:
        ax.set_xlabel("kilometre post (line km)")
    if top:
        sec = ax.secondary_xaxis("top")
        sec.tick_params(labelsize=7, colors="#777777", length=2)
        sec.set_xlabel("chainage (km, distance along the track map)", fontsize=7,
                       color="#777777")  # fmt: skip


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


def _draw_spans(axes: Sequence[Axes], spans: Sequence[LineSpan], lo_m: float, hi_m: float) -> None:
    """Hatched bands over the labelled stretches on every axis; the label on the first."""
    for k, sp in enumerate(spans):
        a, b = max(sp.start_m, lo_m), min(sp.end_m, hi_m)
        if b < a:
            continue
        if b - a < 1e-3 * (hi_m - lo_m):  # a point-like stretch still shows
            a, b = a - 5e-4 * (hi_m - lo_m), b + 5e-4 * (hi_m - lo_m)
        style = SPAN_STYLES[sp.kind]
        for ax in axes:
            ax.axvspan(a / 1000.0, b / 1000.0, facecolor=style["color"], alpha=0.12,
                       hatch=style["hatch"], edgecolor=style["color"], linewidth=0,
                       zorder=0.5, label=f"_span {sp.kind}")  # fmt: skip
        axes[0].text(
            (a + b) / 2000.0, 0.98 - 0.09 * (k % 2), sp.text,
            transform=axes[0].get_xaxis_transform(), ha="center", va="top", fontsize=7,
            color=style["color"], fontweight="bold",
            bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1},
            zorder=6, gid=f"span:{sp.kind}",
        )  # fmt: skip


def _along_axes(
    n_rows: int, height_in: float, results: Sequence[Availability],
    posts: Sequence[KilometrePost], spans: Sequence[LineSpan] = (),
) -> tuple[Figure, list[Axes]]:  # fmt: skip
    fig = Figure(figsize=(_FIG_W_IN, height_in), layout="constrained")
    axes = [fig.add_subplot(n_rows, 1, i + 1) for i in range(n_rows)]
    s = results[0].chainage_m
    lo, hi = float(s[0]), float(s[-1])
    for i, ax in enumerate(axes):
        ax.set_xlim(lo / 1000.0, hi / 1000.0)
        ax.grid(True, axis="y", color="#e5e5e5", linewidth=0.6)
        _x_axes(ax, posts, lo, hi, bottom=i == n_rows - 1, top=i == 0)
    _draw_spans(axes, spans, lo, hi)
    return fig, axes


def _halo(width: float) -> list[patheffects.AbstractPathEffect]:
    """A white outline that keeps text readable over lines."""
    return [patheffects.withStroke(linewidth=width, foreground="white")]


def _title(fig: Figure, title: str) -> None:
    if title:
        fig.suptitle(title, fontsize=10)


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
    results: Sequence[Availability],
    kilometre_posts: Sequence[KilometrePost] = (),
    spans: Sequence[LineSpan] = (),
    title: str = "",
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
    fig, axes = _along_axes(2, 4.6, results, kilometre_posts, spans)
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
    _title(fig, title)
    return fig


def opening_angle_along_line(
    results: Sequence[Availability],
    kilometre_posts: Sequence[KilometrePost] = (),
    spans: Sequence[LineSpan] = (),
    title: str = "",
) -> Figure:
    """Cross-track opening angle along the line, per rule (degrees)."""
    check_results(results)
    fig, (ax,) = _along_axes(1, 2.6, results, kilometre_posts, spans)
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
    _title(fig, title)
    return fig


def interval_along_line(
    results: Sequence[Availability],
    kilometre_posts: Sequence[KilometrePost] = (),
    spans: Sequence[LineSpan] = (),
    title: str = "",
) -> Figure:
    """Predicted interval length along the line: median (line) and 95th percentile (band).

    Over the epochs with >= 4 trusted satellites at each position; log scale.
    """
    check_results(results)
    fig, (ax,) = _along_axes(1, 3.0, results, kilometre_posts, spans)
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
    for key, text, dash in (
        ("interval_typical_m", "typical", (0, (6, 3))),
        ("interval_max_m", "largest", (0, (1.5, 2.5))),
    ):
        ref = LOCOPROL[key]
        ax.axhline(ref, color=_REF_COLOUR, linewidth=1.2, linestyle=dash,
                   label=f"_LOCOPROL {text}")  # fmt: skip
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
    _title(fig, title)
    return fig


# ------------------------------------------------------------------------- chainage x time
def _count_cmap() -> tuple[ListedColormap, BoundaryNorm]:
    cmap = ListedColormap([c[3] for c in COUNT_CLASSES])
    bounds = [c[0] for c in COUNT_CLASSES] + [256]
    return cmap, BoundaryNorm(bounds, cmap.N)


def count_maps(
    results: Sequence[Availability],
    kilometre_posts: Sequence[KilometrePost] = (),
    title: str = "",
) -> Figure:
    """Trusted-satellite count over the line (x) and GPS time (y), one panel per rule.

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
        ax.set_xlim(lo_s / 1000.0, hi_s / 1000.0)
        _x_axes(ax, kilometre_posts, float(s[0]), float(s[-1]), max_labels=3)
        if i == 0:
            day = str(gps_s_to_datetime64(t[0]).astype("M8[D]"))
            leap = (gps_s_to_datetime64(t[0]) - gps_s_to_utc_datetime64(t[0])) // _ONE_S
            ax.set_ylabel(f"GPS time ({day}; UTC = GPS - {leap} s)")
        else:
            ax.tick_params(labelleft=False)
    handles = [Patch(color=c[3], label=c[2]) for c in COUNT_CLASSES]
    fig.legend(
        handles=handles, title="trusted satellites", loc="outside right center", fontsize=8,
        title_fontsize=8, frameon=False,
    )  # fmt: skip
    _title(fig, title)
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
    assumed : ndarray of bool, shape (n_az,), or None
        Bins whose mask is assumed (``BinSource.ASSUMED``: neither seen nor reconstructed),
        drawn hatched.
    terrain : ndarray of bool, shape (n_az,), or None
        Bins raised to a digital elevation model's horizon (``BinSource.TERRAIN``), drawn
        hatched the other way.
    weak : ndarray of bool, shape (n_az,), or None
        The other weakly supported bins (``MaskSet.support`` below ``WEAK_SUPPORT``: fewer
        than two independent views behind the bound), drawn dotted.
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
    assumed: NDArray | None = None
    terrain: NDArray | None = None
    weak: NDArray | None = None

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
        for name in ("assumed", "terrain", "weak"):
            flags = getattr(self, name)
            if flags is not None and (
                self.mask_el_deg is None or np.shape(flags) != np.shape(self.mask_el_deg)
            ):
                raise ValueError(
                    f"SkyView: {name} needs a mask and one flag per mask bin, got shape "
                    f"{np.shape(flags)} for mask "
                    f"{None if self.mask_el_deg is None else self.mask_el_deg.shape}"
                )
        freeze_array_fields(self)


_WEAK_COLOUR = "#6a3d9a"


def _staircase(az_step_deg: float, values: NDArray) -> tuple[NDArray, NDArray]:
    """Bin values as a closed staircase in polar angle (radians)."""
    n = len(values)
    centre = np.arange(n) * az_step_deg
    edges = np.stack([centre - az_step_deg / 2.0, centre + az_step_deg / 2.0], axis=1).ravel()
    vals = np.repeat(np.asarray(values, float), 2)
    return np.radians(np.append(edges, edges[0] + 360.0)), np.append(vals, vals[0])


_RING_EL_DEG = (15, 30, 60)
_RING_LABEL_AZ_DEG = 157.5  # SSE: under no track arrow (the track's own labels are L/R)


def _sky_axes(ax: Any) -> None:
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_rlim(0, 90)
    ax.set_rticks([90 - e for e in _RING_EL_DEG] + [90], [""] * (len(_RING_EL_DEG) + 1))
    ax.tick_params(labelsize=7)
    ax.set_thetagrids([0, 90, 180, 270], ["N", "E", "S", "W"])
    ax.grid(color="#bbbbbb", linewidth=0.5)


def _ring_labels(ax: Any) -> None:
    """Elevation of each ring, on a white box above every track (never hidden)."""
    for e in _RING_EL_DEG:
        ax.text(np.radians(_RING_LABEL_AZ_DEG), 90 - e, f"{e}°", fontsize=7, color="#333333",
                ha="center", va="center", zorder=20, gid=f"ring:{e}",
                bbox={"facecolor": "white", "edgecolor": "#bbbbbb", "linewidth": 0.4,
                      "pad": 0.8, "alpha": 0.95})  # fmt: skip


def _draw_mask(ax: Any, v: SkyView) -> None:
    if v.mask_el_deg is None:
        return
    margin = np.zeros_like(v.mask_el_deg) if v.margin_deg is None else v.margin_deg
    th, eff = _staircase(v.az_step_deg, np.minimum(v.mask_el_deg + margin, 90.0))
    _, raw = _staircase(v.az_step_deg, v.mask_el_deg)
    if np.any(margin > 0):
        ax.fill_between(th, 90.0 - eff, 90.0, color="#f0c8a0", linewidth=0, zorder=1)
    ax.fill_between(th, 90.0 - raw, 90.0, color="#8c6d4f", linewidth=0, zorder=1.1)
    if v.assumed is not None and np.any(v.assumed):
        _, flag = _staircase(v.az_step_deg, np.asarray(v.assumed, float))
        ax.fill_between(th, np.where(flag > 0, 90.0 - eff, 90.0), 90.0, facecolor="none",
                        edgecolor="#222222", hatch="////", linewidth=0, zorder=1.2,
                        gid="assumed")  # fmt: skip
    if v.terrain is not None and np.any(v.terrain):
        _, flag = _staircase(v.az_step_deg, np.asarray(v.terrain, float))
        ax.fill_between(th, np.where(flag > 0, 90.0 - eff, 90.0), 90.0, facecolor="none",
                        edgecolor="#1b5e20", hatch="\\\\", linewidth=0, zorder=1.2,
                        gid="terrain")  # fmt: skip
    if v.weak is not None and np.any(v.weak):
        _, flag = _staircase(v.az_step_deg, np.asarray(v.weak, float))
        ax.fill_between(th, np.where(flag > 0, 90.0 - eff, 90.0), 90.0, facecolor="none",
                        edgecolor=_WEAK_COLOUR, hatch="....", linewidth=0, zorder=1.2,
                        gid="weak")  # fmt: skip


def _draw_sky(ax: Any, v: SkyView, label_sats: bool) -> None:
    _sky_axes(ax)
    _draw_mask(ax, v)
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
        _sat_labels(ax, v.sats, theta, el, trusted)
    _ring_labels(ax)
    ax.set_title(v.title, fontsize=9)


def _sat_labels(
    ax: Any, sats: Sequence[str], theta: NDArray, el: NDArray, trusted: NDArray
) -> None:
    """Each satellite's name on its own track, spread apart.

    Candidates are the track points between 15 and 75 deg elevation; satellites are placed
    one after the other (fewest candidates first), each at the candidate farthest from the
    labels already placed (the ring labels included), so names do not pile up at the zenith,
    on one another or under a ring label.
    """
    x = (90.0 - el) * np.sin(theta)
    y = (90.0 - el) * np.cos(theta)
    ok = np.isfinite(el) & (el >= 15.0) & (el <= 75.0)
    ring_th = np.radians(_RING_LABEL_AZ_DEG)
    # the ring labels count as placed: names keep clear of them
    placed = [(float((90 - e) * np.sin(ring_th)), float((90 - e) * np.cos(ring_th)))
              for e in _RING_EL_DEG]  # fmt: skip
    order = np.argsort(ok.sum(axis=0), kind="stable")
    for j in order:
        cand = np.flatnonzero(ok[:, j])
        if cand.size == 0:
            continue
        cand = cand[:: max(1, cand.size // 200)]
        px, py = np.asarray(placed).T
        d = np.hypot(x[cand, j, None] - px[None, :], y[cand, j, None] - py[None, :])
        k = int(cand[np.argmax(d.min(axis=1))])
        placed.append((float(x[k, j]), float(y[k, j])))
        colour = "#1f5fa8" if trusted[k, j] else "#606060"
        ax.text(theta[k, j], 90.0 - el[k, j], sats[j], fontsize=6, color=colour, ha="center",
                va="center", zorder=7, gid=f"sat:{sats[j]}", path_effects=_halo(2.0))  # fmt: skip


def sky_plots(views: Sequence[SkyView], label_sats: bool = True, title: str = "") -> Figure:
    """Polar sky plots side by side: north up, azimuth clockwise, zenith at the centre.

    Filled: the mask (dark), the margin (light, when there is one), assumed bins (hatched),
    bins raised to the terrain (hatched the other way) and the other weakly supported bins
    (dotted: fewer than two independent views behind the bound);
    dotted circles: flat cut-offs; line with arrow: the track, increasing chainage; blue:
    satellite track while trusted under the masks, grey: above the horizon but not trusted;
    each satellite named on its own track, spread apart (``label_sats``). Elevation rings 15,
    30 and 60 deg are labelled on white above the tracks.
    """
    if not views:
        raise ValueError("views is empty: pass at least one SkyView")
    n = len(views)
    ncol = min(n, 4)
    nrow = (n + ncol - 1) // ncol
    fig = Figure(figsize=(_FIG_W_IN, 3.3 * nrow + 0.6), layout="constrained")
    for i, v in enumerate(views):
        ax = fig.add_subplot(nrow, ncol, i + 1, projection="polar")
        _draw_sky(ax, v, label_sats)
    handles = [Patch(color="#8c6d4f", label="mask")]
    if any(v.margin_deg is not None and np.any(np.asarray(v.margin_deg) > 0) for v in views):
        handles.append(Patch(color="#f0c8a0", label="margin"))
    if any(v.assumed is not None and np.any(v.assumed) for v in views):
        handles.append(Patch(facecolor="white", edgecolor="#222222", hatch="////",
                             label="assumed (not seen)"))  # fmt: skip
    if any(v.terrain is not None and np.any(v.terrain) for v in views):
        handles.append(Patch(facecolor="white", edgecolor="#1b5e20", hatch="\\\\",
                             label="terrain (elevation model)"))  # fmt: skip
    if any(v.weak is not None and np.any(v.weak) for v in views):
        handles.append(Patch(facecolor="white", edgecolor=_WEAK_COLOUR, hatch="....",
                             label="weakly supported (< 2 views)"))  # fmt: skip
    handles += [
        Patch(color="#1f5fa8", label="satellite, trusted"),
        Patch(color="#b0b0b0", label="satellite, masked"),
    ]
    if any(v.cutoff_deg for v in views):
        handles.append(Patch(color="#e6730b", label="flat cut-off (dotted)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8,
               frameon=False)  # fmt: skip
    _title(fig, title)
    return fig


# ------------------------------------------------------------------------- map
@dataclass(frozen=True)
class MapPoint:
    """A named place on the map (a station, a stop), WGS84 degrees."""

    name: str
    lat_deg: float
    lon_deg: float


def _nice_length_m(span_m: float) -> float:
    """A 1-2-5 length close to a quarter of ``span_m`` (metres), for the scale bar."""
    target = max(span_m / 4.0, 1.0)
    k = 10.0 ** np.floor(np.log10(target))
    return float(max(m * k for m in (1.0, 2.0, 5.0) if m * k <= target))


def _scale_bar(ax: Axes) -> None:
    """A scale bar (axes units are km) in the lower left corner."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    length_km = _nice_length_m((x1 - x0) * 1000.0) / 1000.0
    xs, ys = x0 + 0.05 * (x1 - x0), y0 + 0.06 * (y1 - y0)
    ax.plot([xs, xs + length_km], [ys, ys], color="k", linewidth=3, solid_capstyle="butt",
            zorder=8, gid="scalebar")  # fmt: skip
    text = f"{length_km:g} km" if length_km >= 1 else f"{length_km * 1000:g} m"
    ax.text(xs + length_km / 2, ys + 0.015 * (y1 - y0), text, ha="center", va="bottom",
            fontsize=8, zorder=8, gid="scalebar:label")  # fmt: skip


def _north_arrow(ax: Axes) -> None:
    """A north arrow in the upper left corner (the local frame's north is up)."""
    ax.annotate("N", xy=(0.06, 0.95), xytext=(0.06, 0.80), xycoords="axes fraction",
                ha="center", va="center", fontsize=10, fontweight="bold", zorder=8,
                arrowprops={"arrowstyle": "-|>", "color": "k", "linewidth": 1.5},
                gid="northarrow")  # fmt: skip


def _enu_km(frame: LocalFrame, lat: NDArray, lon: NDArray) -> NDArray:
    return np.asarray(frame.to_enu(lat, lon)[..., :2] / 1000.0)


def _padded_box(
    xy: NDArray, pad_frac: float, min_aspect: float
) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) around points (km), padded and widened to width/height >= min_aspect
    (and height/width >= 1/2 min_aspect) so a straight line does not make a sliver of a map."""
    x0, y0 = xy.min(axis=0)
    x1, y1 = xy.max(axis=0)
    pad = pad_frac * max(x1 - x0, y1 - y0, 0.2)
    x0, x1, y0, y1 = x0 - pad, x1 + pad, y0 - pad, y1 + pad
    w, h = x1 - x0, y1 - y0
    if w < min_aspect * h:
        grow = (min_aspect * h - w) / 2
        x0, x1 = x0 - grow, x1 + grow
    elif h < 0.5 * min_aspect * w:
        grow = (0.5 * min_aspect * w - h) / 2
        y0, y1 = y0 - grow, y1 + grow
    return float(x0), float(x1), float(y0), float(y1)


def _map_axes_decor(ax: Axes) -> None:
    ax.set_aspect("equal", adjustable="box")
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_color("#999999")


def line_map(
    result: Availability,
    track: TrackMap | None = None,
    classes: Sequence[tuple[float, str, str]] = (),
    stations: Sequence[MapPoint] = (),
    basemap_lonlat: Sequence[NDArray] = (),
    title: str = "",
) -> Figure:
    """Map of the stretch, segments coloured by the share of time with >= 4 trusted satellites.

    North up (the local east/north frame at the stretch's middle), with a scale bar, a north
    arrow, the kilometre posts and the stations. With a track the figure has two panels: the
    whole line with its stations and the stretch boxed (left), the stretch (right).

    Parameters
    ----------
    result : Availability
        The rule to colour by (the masks).
    track : TrackMap, optional
        Segments follow it; the rest of the track is drawn in grey and its kilometre posts
        are marked.
    classes : sequence of (lower bound, label, colour)
        Share classes, highest first (default: a single blue).
    stations : sequence of MapPoint
        Named places drawn as squares.
    basemap_lonlat : sequence of ndarray, shape (n, 2)
        Offline background polylines (longitude, latitude in degrees), drawn light grey under
        everything (for example other railways or roads from an OpenStreetMap extract).
    title : str
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
        lon = wrap_lon_deg(np.interp(s, pos.chainage_m, unwrap_lon_deg(pos.lon_deg)))
    segs = list(_enu_km(frame, lat, lon))
    share = result.share_at_least(4)
    colours = [next((c for b, _, c in classes if sh >= b), classes[-1][2]) for sh in share]
    pts = np.concatenate(segs)
    box = _padded_box(pts, 0.15, 1.3)
    fig = Figure(figsize=(_FIG_W_IN, 5.0), layout="constrained")
    if track is not None:
        overview, ax = fig.subplots(1, 2, width_ratios=[1, 1.6])
    else:
        overview, ax = None, fig.add_subplot(1, 1, 1)
    whole = None
    if track is not None:
        sw = np.linspace(0.0, float(track.length_m), 800)
        lat_w, lon_w, _ = track.position_at(sw)
        whole = _enu_km(frame, lat_w, lon_w)
    for a in (overview, ax):
        if a is None:
            continue
        for line in basemap_lonlat:
            ll = np.asarray(line, float)
            xy = _enu_km(frame, ll[:, 1], ll[:, 0])
            a.plot(xy[:, 0], xy[:, 1], color="#e3e3e3", linewidth=0.8, zorder=0.5,
                   gid="basemap")  # fmt: skip
        if whole is not None:
            a.plot(whole[:, 0], whole[:, 1], color="#b5b5b5", linewidth=1.4, zorder=1)
    if overview is not None and whole is not None and track is not None:
        _overview(overview, track, frame, whole, box, stations)
    ax.add_collection(LineCollection(segs, colors=colours, linewidths=5, zorder=2))
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    _map_axes_decor(ax)
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    if track is not None:
        _map_posts(ax, track, frame, box, skip={st.name for st in stations})
    _map_stations(ax, stations, frame, box)
    ax.set_title("the stretch", fontsize=9)
    _scale_bar(ax)
    _north_arrow(ax)
    handles = [Patch(color=c, label=label) for _, label, c in classes]
    fig.legend(handles=handles, title="time with ≥ 4\ntrusted (masks)", fontsize=8,
               title_fontsize=8, loc="outside right upper", frameon=False)  # fmt: skip
    _title(fig, title)
    return fig


def _overview(
    ax: Axes, track: TrackMap, frame: LocalFrame, whole: NDArray,
    box: tuple[float, float, float, float], stations: Sequence[MapPoint],
) -> None:  # fmt: skip
    """The whole line, its stations and first/last kilometre posts, the stretch boxed."""
    lim = _padded_box(whole, 0.08, 0.8)
    ax.add_patch(Rectangle(
        (box[0], box[2]), box[1] - box[0], box[3] - box[2], fill=False, edgecolor="#b2182b",
        linewidth=1.5, zorder=4, gid="stretchbox",
    ))  # fmt: skip
    _map_axes_decor(ax)
    ax.set_xlim(lim[0], lim[1])
    ax.set_ylim(lim[2], lim[3])
    _map_posts(ax, track, frame, lim, max_labels=6, skip={st.name for st in stations})
    _map_stations(ax, stations, frame, lim)
    ax.set_title("the whole line", fontsize=9)
    _scale_bar(ax)
    _north_arrow(ax)


def _map_posts(
    ax: Axes, track: TrackMap, frame: LocalFrame, box: tuple[float, float, float, float],
    max_labels: int = 8, skip: set[str] | frozenset[str] = frozenset(),
) -> None:  # fmt: skip
    """Kilometre posts inside ``box`` (km), at most ``max_labels`` labelled along it; posts
    labelled with a name in ``skip`` (a station drawn with its own label) stay unlabelled."""
    posts = getattr(track, "kilometre_posts", ())
    if not posts:
        return
    ch = np.array([p.chainage_m for p in posts], float)
    lat, lon, _ = track.position_at(ch)
    xy = _enu_km(frame, lat, lon).reshape(-1, 2)
    inside = [
        p for p, (x, y) in zip(posts, xy, strict=True)
        if box[0] <= x <= box[1] and box[2] <= y <= box[3]
    ]  # fmt: skip
    if not inside:
        return
    lo = min(p.chainage_m for p in inside)
    hi = max(p.chainage_m for p in inside)
    shown = {id(p) for p in _thin(inside, lo, hi + 1e-6, max_labels)}
    for p, (x, y) in zip(posts, xy, strict=True):
        if p not in inside:
            continue
        ax.plot(x, y, "o", color="#444444", markersize=3, zorder=3, gid="kmpost")
        if id(p) in shown and _post_label(p) not in skip:
            ax.annotate(_post_label(p), (x, y), fontsize=7, color="#444444", xytext=(4, 2),
                        textcoords="offset points", zorder=6, gid=f"kmpost:{_post_label(p)}",
                        path_effects=_halo(2.0))  # fmt: skip


def _map_stations(
    ax: Axes, stations: Sequence[MapPoint], frame: LocalFrame,
    box: tuple[float, float, float, float],
) -> None:  # fmt: skip
    for st in stations:
        x, y = _enu_km(frame, np.asarray(st.lat_deg), np.asarray(st.lon_deg))
        if not (box[0] <= x <= box[1] and box[2] <= y <= box[3]):
            continue
        ax.plot(x, y, "s", color="#222222", markerfacecolor="#ffd92f", markersize=7, zorder=7,
                gid="station")  # fmt: skip
        ax.annotate(st.name, (x, y), fontsize=8, fontweight="bold", xytext=(6, -3),
                    textcoords="offset points", zorder=7, gid=f"station:{st.name}",
                    path_effects=_halo(2.5))  # fmt: skip
