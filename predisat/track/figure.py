"""A track map at a glance: plan, height profile and curvature along the chainage.

What a user checks before surveying or locating on a map of their own line (``predisat
track``): that the selection chained the right ways in the right order, where the tunnels,
bridges and stations fell, that the heights are there, and that the fitted axis has no kink
(curvature spikes) the source polyline did not have.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from predisat.track.map import TrackMap

__all__ = ["track_figure"]

_TUNNEL, _BRIDGE, _AXIS = "#b2182b", "#2166ac", "#444444"


def track_figure(track: TrackMap, title: str = "", step_m: float = 5.0) -> Figure:
    """Plan (east/north in km from the map's first vertex, north up), heights and curvature
    radius against chainage, with tunnels (red), bridges (blue), stations and kilometre posts.

    Parameters
    ----------
    track : TrackMap
    title : str
        Over the figure (default: the map's name and length).
    step_m : float
        Sampling step along the axis, metres (> 0).
    """
    if not (np.isfinite(step_m) and step_m > 0):
        raise ValueError(f"step_m must be a positive number of metres, got {step_m}")
    s = track.sample(step_m)
    enu_km = track.enu_at(s) / 1000.0
    fig = Figure(figsize=(11.0, 7.0), layout="constrained")
    axes = fig.subplot_mosaic([["plan", "h"], ["plan", "k"]], width_ratios=[1.2, 1.0])
    plan, prof, curv = axes["plan"], axes["h"], axes["k"]
    plan.plot(enu_km[:, 0], enu_km[:, 1], color=_AXIS, lw=1.2, zorder=2)
    for spans, colour in ((track.tunnels_m, _TUNNEL), (track.bridges_m, _BRIDGE)):
        for lo_m, hi_m in spans:
            seg = track.enu_at(np.linspace(lo_m, hi_m, 50)) / 1000.0
            plan.plot(seg[:, 0], seg[:, 1], color=colour, lw=4.0, zorder=3, solid_capstyle="butt")
            for ax in (prof, curv):
                ax.axvspan(lo_m / 1000.0, hi_m / 1000.0, color=colour, alpha=0.15, lw=0)
    for end_m, mark in ((0.0, "start"), (track.length_m, "end")):
        xy = track.enu_at(end_m) / 1000.0
        plan.plot(*xy[:2], "o", color="k", ms=5, zorder=4)
        plan.annotate(f"{mark} ({end_m:,.0f} m)", (xy[0], xy[1]), fontsize=8, xytext=(5, 5),
                      textcoords="offset points")  # fmt: skip
    posts = track.kilometre_posts
    every = max(1, int(np.ceil(len(posts) / 15)))  # at most ~15 labels on the plan
    for i, post in enumerate(posts):
        # a dot, labelled with its kilometre: a "|" tick vanished on a north-south stretch
        xy = track.enu_at(post.chainage_m) / 1000.0
        plan.plot(*xy[:2], "o", color=_AXIS, ms=3, zorder=4)
        if i % every == 0:
            plan.annotate(f"km {post.km_m / 1000.0 + 0.0:g}", (xy[0], xy[1]), fontsize=7,
                          xytext=(-4, 0), textcoords="offset points", ha="right",
                          color="#666666")  # fmt: skip
    if track.stations:
        lat = np.array([st.lat_deg for st in track.stations])
        lon = np.array([st.lon_deg for st in track.stations])
        p = track.project(lat, lon)
        # where the station is, not its foot on the axis: one beyond an end (GEMBLOUX, 540 m
        # before line 144's start) was drawn on the end, as if on the line
        xy = track.frame.to_enu(lat, lon, np.full(lat.shape, track.frame.h_m)) / 1000.0
        for st, (x, y), ch, off_map in zip(track.stations, xy[:, :2], p.chainage_m,
                                           p.along_m > 1.0, strict=True):  # fmt: skip
            plan.plot(x, y, "s", color="#222222", markerfacecolor="#ffd92f", ms=7, zorder=5)
            plan.annotate(f"{st.name} ({'off the map' if off_map else f'{ch:,.0f} m'})", (x, y),
                          fontsize=8, xytext=(6, -3), textcoords="offset points")  # fmt: skip
            for ax in () if off_map else (prof, curv):
                ax.axvline(ch / 1000.0, color="#999999", lw=0.8, ls=":")
    plan.set_aspect("equal", adjustable="datalim")
    plan.set_xlabel("east of the first vertex (km)")
    plan.set_ylabel("north of the first vertex (km)")
    plan.grid(alpha=0.3)
    handles = [Patch(color=_TUNNEL, label=f"tunnel ({len(track.tunnels_m)})"),
               Patch(color=_BRIDGE, label=f"bridge ({len(track.bridges_m)})")]  # fmt: skip
    plan.legend(handles=handles, fontsize=8, loc="best")
    _, _, h_m = track.position_at(s)
    if np.any(track.h_m != 0.0):
        prof.plot(s / 1000.0, h_m, color=_AXIS, lw=1.0)
        prof.set_ylabel("height above the ellipsoid (m)")
    else:
        prof.text(0.5, 0.5, "no heights in the map (h = 0):\n`locator run` on real data "
                  "refuses it", ha="center", va="center", transform=prof.transAxes,
                  color=_TUNNEL)  # fmt: skip
        prof.set_ylabel("height (m)")
    prof.grid(alpha=0.3)
    # radius, not curvature: the number a track engineer reads (R 300 m is a sharp curve)
    k = np.abs(track.curvature_at(s))
    # the smallest radius per bin: every sample of a 50-200 km line drew a barcode
    n_bins = max(1, min(len(s), 300))
    edges = np.linspace(0, len(s), n_bins + 1).astype(int)
    k_max = np.maximum.reduceat(k, edges[:-1]) if len(s) else k
    s_mid = s[np.minimum((edges[:-1] + edges[1:]) // 2, len(s) - 1)] if len(s) else s
    radius_m = np.where(k_max > 1e-6, 1.0 / np.maximum(k_max, 1e-12), np.nan)
    curv.semilogy(s_mid / 1000.0, radius_m, color=_AXIS, lw=0.8)
    curv.set_ylim(50.0, 1e5)
    curv.set_ylabel("smallest curve radius (m, log;\nstraight: blank)")
    curv.set_xlabel("chainage (km)")
    curv.grid(alpha=0.3, which="both")
    prof.sharex(curv)
    fig.suptitle(title or f"{track.name}: {track.length_m:,.0f} m", fontsize=10)
    return fig
