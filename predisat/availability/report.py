"""The availability report: one self-contained HTML file, its summary table and GIS layer.

:func:`build_report` assembles the page from :class:`~predisat.availability.engine.Availability`
results of several trust rules on the same positions (surveyed masks, no mask, flat cut-offs):
a header saying what was computed from what, a summary table beside the LOCOPROL figures, a
sentence saying what the survey changes, and the figures of :mod:`predisat.availability.plots`,
each with a
one-line caption on how to read it. Figures are embedded as base64 PNG; the page uses no
script, no external style sheet, font or image, and needs no network.

:func:`summary_frame` is the summary table (one row per rule) and :func:`geojson_layer` the line
coloured by availability for QGIS. The orchestration (loading, computing, writing files) is
:func:`predisat.availability.run.run_availability`.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from matplotlib.figure import Figure
from numpy.typing import NDArray

from predisat.availability import plots
from predisat.availability.engine import Availability, write_counts
from predisat.availability.satellites import SYSTEM_NAMES, SatellitePositions, TrustRule, azel
from predisat.geodesy import enu_rotation, geodetic_to_ecef
from predisat.gnss.ephemeris import Reason
from predisat.gnss.timescale import gps_s_to_utc_datetime64, gps_s_to_utc_text
from predisat.jsontypes import JsonDict
from predisat.masks.maskset import WEAK_SUPPORT, BinSource, MaskSet
from predisat.track import KilometrePost, TrackMap, TrackMapError
from predisat.track.readers import geojson_in_lonlat

__all__ = [
    "LOCOPROL_ROW",
    "SHARE_CLASSES",
    "ReportInputs",
    "basemap_from_geojson",
    "build_report",
    "constellation_names",
    "geojson_layer",
    "line_spans",
    "share_class",
    "summary_frame",
    "write_tables",
]

SHARE_CLASSES: tuple[tuple[float, str, str], ...] = (
    (0.99, ">= 99 %", "#2166ac"),
    (0.95, "95-99 %", "#92c5de"),
    (0.80, "80-95 %", "#f4a582"),
    (0.0, "< 80 %", "#b2182b"),
)
"""Classes of the share of time with >= 4 trusted satellites: (lower bound, label, colour)."""

LOCOPROL_ROW: dict[str, str] = {
    "rule": "LOCOPROL trials, line 144 (GPS, 2000s receiver, real masking)",
    "share_ge2": "",
    "share_ge4": "95 %",
    "share_ge6": "60 %",
    "mean_count": "",
    "longest_below4_m": "",
    "longest_below4_s": "",
    "interval": "about 70 m typical, up to 600 m",
}
"""The reference row of the summary table (``docs/seeds-digest.md``, document 000)."""


def share_class(share: float) -> tuple[str, str]:
    """Label and colour of a share of time with >= 4 satellites (:data:`SHARE_CLASSES`)."""
    for lo, label, colour in SHARE_CLASSES:
        if share >= lo:
            return label, colour
    return SHARE_CLASSES[-1][1], SHARE_CLASSES[-1][2]


# ------------------------------------------------------------------------- tables
def summary_frame(results: Sequence[Availability]) -> pd.DataFrame:
    """Line-wide figures, one row per rule (``Availability.summary`` columns, rule first)."""
    if not results:
        raise ValueError("results is empty: pass at least one Availability")
    return pd.DataFrame([r.summary() for r in results])


def _with_interval_setting(summary: pd.DataFrame, info: JsonDict) -> pd.DataFrame:
    """The interval columns with the setting they were drawn for beside them.

    A table read alone (a spreadsheet, another tool) must not show an interval length without
    its risk or k, error model and map doubt (a trial found them only in ``summary.json``).
    """
    par = info.get("interval_model_params")
    if "interval_median_m" not in summary.columns or not isinstance(par, dict):
        return summary
    out = summary.copy()
    at = list(out.columns).index("interval_p95_m") + 1
    risk = par.get("integrity_risk_per_epoch")
    cols = {
        "interval_integrity_risk_per_epoch": np.nan if risk is None else float(risk),
        "interval_k_sigma": np.nan if par.get("k_sigma") is None else float(par["k_sigma"]),
        "interval_error_a_m": float(par.get("a_m", np.nan)),
        "interval_error_b_m": float(par.get("b_m", np.nan)),
        "interval_map_doubt_lateral_m": float(par.get("map_doubt_lateral_m", 0.0)),
        "interval_map_doubt_vertical_m": float(par.get("map_doubt_vertical_m", 0.0)),
    }
    for i, (name, value) in enumerate(cols.items()):
        # rules drawn without intervals (NaN median) carry no setting either
        out.insert(at + i, name, np.where(out["interval_median_m"].notna(), value, np.nan))
    return out


def geojson_layer(
    results: Sequence[Availability], track: TrackMap | None = None
) -> JsonDict:
    """The line cut into one segment per position, coloured by the masks' share >= 4.

    The features are those of ``results[0].to_geojson_lines(track)`` (the first result is
    the masks rule) with ``line_km`` (when the track has kilometre posts; null where they say
    nothing) and, for styling in QGIS or any GeoJSON viewer: ``rule``,
    ``share_ge4_class`` (:data:`SHARE_CLASSES` label), ``stroke`` (its colour),
    ``stroke-width``, and ``share_ge4_<rule>`` / ``share_ge6_<rule>`` for every other rule.
    """
    if not results:
        raise ValueError("results is empty: pass at least one Availability")
    base = results[0]
    fc = base.to_geojson_lines(track)
    # the line's kilometre, as positions.csv has it (a GIS user trial missed it in QGIS)
    km = None
    if track is not None and len(getattr(track, "kilometre_posts", ())) > 0:
        km = track.kilometre_at(base.chainage_m) / 1000.0
    others = {}
    for r in results[1:]:
        slug = _slug(r.rule)
        others[f"share_ge4_{slug}"] = r.share_at_least(4)
        others[f"share_ge6_{slug}"] = r.share_at_least(6)
    for i, feat in enumerate(fc["features"]):
        props = feat["properties"]
        label, colour = share_class(float(props["share_ge4"]))
        props["rule"] = base.rule
        props["share_ge4_class"] = label
        props["stroke"] = colour
        props["stroke-width"] = 4
        if km is not None:  # null where the posts say nothing (a kilometre equation)
            props["line_km"] = float(km[i]) if np.isfinite(km[i]) else None
        for key, values in others.items():
            props[key] = float(values[i])
    return fc


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in text.lower()).strip("_")


def write_tables(
    out: Path,
    results: Sequence[Availability],
    track: TrackMap | None,
    info: JsonDict,
    counts_table: bool,
) -> tuple[dict[str, Path], pd.DataFrame]:
    """Write the summary, per-position and per-epoch tables and the GeoJSON layer.

    Parameters
    ----------
    out : Path
        Existing output folder.
    results : sequence of Availability
        One per rule, masks first, on the same positions.
    track : TrackMap or None
        Kilometre column (``line_km``) and GeoJSON geometry.
    info : dict
        Run description, stored in ``summary.json`` and the Parquet metadata.
    counts_table : bool
        Also write ``counts.parquet`` (every count, long format).

    Returns
    -------
    files : dict of str to Path
    summary : pandas.DataFrame
    """
    files: dict[str, Path] = {}
    summary = _with_interval_setting(summary_frame(results), info)
    files["summary_csv"] = out / "summary.csv"
    summary.to_csv(files["summary_csv"], index=False, float_format="%.12g")
    files["summary_json"] = out / "summary.json"
    files["summary_json"].write_text(
        json.dumps(
            {"run": info, "summary": [_plain(r.summary()) for r in results]},
            indent=1,
            default=str,
        )
    )
    km = None
    if track is not None and len(getattr(track, "kilometre_posts", ())) > 0:
        km = track.kilometre_at(results[0].chainage_m) / 1000.0
    pos = []
    ep = []
    for r in results:
        p = r.position_table()
        if km is not None:
            p.insert(1, "line_km", km)
        p.insert(0, "rule", r.rule)
        pos.append(p)
        e = r.epoch_table()
        e.insert(0, "rule", r.rule)
        e.insert(2, "utc", gps_s_to_utc_datetime64(e["gps_s"].to_numpy()).astype("M8[ms]"))
        ep.append(e)
    meta = {b"predisat.availability.run": json.dumps(info, default=str).encode()}
    for name, df in (("positions", pd.concat(pos)), ("epochs", pd.concat(ep))):
        files[f"{name}_csv"] = out / f"{name}.csv"
        df.to_csv(files[f"{name}_csv"], index=False, float_format="%.12g")
        files[f"{name}_parquet"] = out / f"{name}.parquet"
        table = pa.Table.from_pandas(df, preserve_index=False)
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **meta})
        pq.write_table(table, files[f"{name}_parquet"])
    if counts_table:
        files["counts_parquet"] = out / "counts.parquet"
        write_counts(files["counts_parquet"], results)
    files["geojson"] = out / "availability.geojson"
    files["geojson"].write_text(json.dumps(geojson_layer(results, track)))
    return files, summary


def basemap_from_geojson(path: str | Path, max_lines: int = 20000) -> tuple[NDArray, ...]:
    """The lines of a GeoJSON file as an offline basemap (``ReportInputs.basemap_lonlat``).

    LineString, MultiLineString and the rings of (Multi)Polygon features, WGS84 longitude /
    latitude in degrees (for example an OpenStreetMap extract of railways or roads).

    Parameters
    ----------
    path : path
        The GeoJSON file.
    max_lines : int
        Refuse files with more polylines than this (a basemap is a background, not a
        country).

    Returns
    -------
    tuple of ndarray, shape (n, 2)

    Raises
    ------
    ValueError
        Naming the file, the feature and the fix.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(
            f"basemap {p}: cannot be read as GeoJSON ({exc}); give a GeoJSON FeatureCollection "
            "of lines (WGS84 lon/lat)"
        ) from None
    try:  # a national grid's export with its crs member, as --track reads it (a trial)
        doc = geojson_in_lonlat(doc, p)
    except TrackMapError as exc:
        raise ValueError(f"basemap {exc}") from None
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(feats, list):
        raise ValueError(f"basemap {p}: no 'features' list; give a GeoJSON FeatureCollection")
    out: list[NDArray] = []
    for i, f in enumerate(feats):
        geom = (f or {}).get("geometry") or {}
        kind, coords = geom.get("type"), geom.get("coordinates") or []
        if kind == "LineString":
            parts = [coords]
        elif kind in ("MultiLineString", "Polygon"):
            parts = list(coords)
        elif kind == "MultiPolygon":
            parts = [ring for poly in coords for ring in poly]
        else:
            continue
        for part in parts:
            a = np.asarray(part, float)
            if a.ndim != 2 or a.shape[1] < 2 or not np.isfinite(a[:, :2]).all():
                raise ValueError(
                    f"basemap {p}: feature {i} ({kind}) has malformed coordinates; give "
                    "[lon, lat] pairs"
                )
            if np.abs(a[:, 1]).max() > 90.0 or np.abs(a[:, 0]).max() > 180.0:
                raise ValueError(
                    f"basemap {p}: feature {i} has coordinates outside lon/lat range; give "
                    "WGS84 longitude, latitude in degrees"
                )
            out.append(a[:, :2])
    if len(out) > max_lines:
        raise ValueError(
            f"basemap {p}: {len(out)} lines, more than {max_lines}; cut the file to the "
            "line's surroundings"
        )
    return tuple(out)


def _plain(d: JsonDict) -> JsonDict:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


# ------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class ReportInputs:
    """Everything the report shows.

    Attributes
    ----------
    results : tuple of Availability
        One per rule on the same positions; the masks rule first.
    masks : MaskSet
        The mask set of the masks rule (sky plots, provenance).
    satellites : SatellitePositions
        The satellites of the window (sky-plot tracks).
    track : TrackMap or None
        Kilometre posts and attribution.
    info : dict
        Header fields: ``line``, ``stretch``, ``window``, ``navigation``, ``constellation``,
        ``rules``, ``masks``, ``mask_provenance``, ``software``, ``created_utc``, ...
    sky_chainage_m : tuple of float
        Places of the sky plots.
    files : dict of str to path
        Companion files to list (shown by name, linked relatively: they must sit in the
        report's folder).
    basemap_lonlat : tuple of ndarray, shape (n, 2)
        Offline background polylines of the map (longitude, latitude, degrees), e.g. from
        :func:`basemap_from_geojson`.
    """

    results: tuple[Availability, ...]
    masks: MaskSet
    satellites: SatellitePositions
    track: TrackMap | None = None
    info: Mapping[str, Any] = field(default_factory=dict)  # Any: JSON values of the run info
    sky_chainage_m: tuple[float, ...] = ()
    files: Mapping[str, str | Path] = field(default_factory=dict)
    basemap_lonlat: tuple[NDArray, ...] = ()


# ------------------------------------------------------------------------- formatting
def _pct(x: float) -> str:
    """Share as a percentage rounded down (99.96 % must not read as 100 %)."""
    if x is None or not math.isfinite(x):
        return ""
    return f"{math.floor(1000.0 * x + 1e-9) / 10.0:.1f} %"


def _num(x: float, unit: str, digits: int = 0) -> str:
    """A length the reader should not take as shorter than it is (an interval, a stretch
    without 4 satellites), rounded up: 103.498 m reads 104 m, not 103 (a user trial)."""
    if x is None or not math.isfinite(x):
        return "–"
    up = math.ceil(x * 10**digits - 1e-9) / 10**digits
    return f"{up:,.{digits}f}".replace(",", " ") + f" {unit}"


def _duration(s: float) -> str:
    if not math.isfinite(s):
        return "–"
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def _e(x: object) -> str:
    return html.escape(str(x), quote=True)


def _img(fig: Figure, alt: str) -> str:
    data = base64.b64encode(plots.figure_to_png(fig)).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{data}">'


def _km_label(track: TrackMap | None, chainage_m: float) -> str:
    """A place: the line's kilometre first, the chainage beside (``km 4.123 (chainage
    4.150 km)``); the chainage alone when the track has no kilometre posts."""
    chain = f"chainage {chainage_m / 1000:.3f} km"
    if track is not None and len(getattr(track, "kilometre_posts", ())) > 0:
        km = float(track.kilometre_at(chainage_m))
        if math.isfinite(km):
            return f"km {km / 1000:.3f} ({chain})"
    return chain


# ------------------------------------------------------------------------- sections
def _summary_table(results: Sequence[Availability], gnss: str = "", width: str = "") -> str:
    head = (
        "<tr><th>rule</th><th>≥ 2</th><th>≥ 4</th><th>≥ 6</th><th>mean count</th>"
        "<th>longest &lt; 4<br>(along the line)</th><th>longest &lt; 4<br>(at one place)</th>"
        "<th>interval median / 95 %<br>(epochs with ≥ 4)</th></tr>"
    )
    rows = []
    for r in results:
        s = r.summary()
        iv = (
            f"{_num(s.get('interval_median_m', math.nan), 'm')} / "
            f"{_num(s.get('interval_p95_m', math.nan), 'm')}"
        )
        cls = ' class="main"' if r.rule == "masks" else ""
        rows.append(
            f"<tr{cls}><td>{_e(r.rule)}</td><td>{_pct(s['share_ge2'])}</td>"
            f"<td>{_pct(s['share_ge4'])}</td><td>{_pct(s['share_ge6'])}</td>"
            f"<td>{s['mean_count']:.1f}</td><td>{_num(s['longest_below4_m'], 'm')}</td>"
            f"<td>{_duration(s['longest_below4_s'])}</td><td>{iv}</td></tr>"
        )
    ref = LOCOPROL_ROW
    rows.append(
        f'<tr class="ref"><td>{_e(ref["rule"])}</td><td>{ref["share_ge2"]}</td>'
        f"<td>{ref['share_ge4']}</td><td>{ref['share_ge6']}</td><td></td><td></td><td></td>"
        f"<td>{_e(ref['interval'])}</td></tr>"
    )
    return (
        '<table class="summary"><caption>Share of time with at least 2, 4 and 6 trusted '
        f"{_e(gnss) + ' ' if gnss else ''}satellites over the whole stretch (place and time "
        "weighted equally)"
        f"{'; predicted intervals at ' + _e(width) if width else ''}</caption>"
        f"<thead>{head}</thead><tbody>{''.join(rows)}</tbody></table>"
    )


def _verdict(results: Sequence[Availability], track: TrackMap | None) -> str:
    """One paragraph: what the masks change against the other rules, and the worst place."""
    m = results[0]
    sm = m.summary()
    parts = [
        f"With the surveyed <b>masks</b>, at least 4 satellites are trusted "
        f"<b>{_pct(sm['share_ge4'])}</b> of the time and at least 6 "
        f"<b>{_pct(sm['share_ge6'])}</b>."
    ]
    others = [
        f"{_e(r.rule)} would claim {_pct(r.line_share_at_least(4))} and "
        f"{_pct(r.line_share_at_least(6))}"
        for r in results[1:]
    ]
    if others:
        parts.append("Ignoring the survey, " + "; ".join(others) + ".")
    share4 = m.share_at_least(4)
    i = int(np.argmin(share4))
    when = f" ({sm['longest_below4_m_at_utc']})" if sm["longest_below4_m"] > 0 else ""
    where = (
        f" ({_km_label(track, float(sm['longest_below4_s_at_chainage_m']))})"
        if sm["longest_below4_s"] > 0
        else ""
    )
    parts.append(
        f"The worst place is {_km_label(track, float(m.chainage_m[i]))} "
        f"({_pct(float(share4[i]))} of the time with ≥ 4); the longest stretch below 4 at one "
        f"instant is {_num(sm['longest_below4_m'], 'm')}{when}, the longest time below 4 at one "
        f"place {_duration(sm['longest_below4_s'])}{where}."
    )
    return "<p class=verdict>" + " ".join(parts) + "</p>"


def constellation_names(sats: Sequence[str]) -> str:
    """The constellations of satellite names, spelt out: ``"GPS"``, ``"GPS + Galileo"``."""
    letters = sorted({x[0] for x in sats}, key=lambda c: "GRECJIS".find(c) % 10)
    return " + ".join(SYSTEM_NAMES.get(c, c) for c in letters)


def _window_text(info: Mapping[str, Any]) -> str:
    """The time window in GPS time with UTC beside (from ``window_gps_s``)."""
    gps = info.get("window", "")
    span = info.get("window_gps_s")
    if not span:
        return str(gps)
    lo, hi = (float(x) for x in span)
    return (
        f"{gps}; UTC {gps_s_to_utc_text(lo).removesuffix(' UTC')} - "
        f"{gps_s_to_utc_text(hi)}"
    )


def _header(info: Mapping[str, Any]) -> str:
    margin = info.get("mask_margin_deg")
    margin_text = ""
    if margin:
        lo, hi = margin
        margin_text = f" (margin {lo:g}°)" if lo == hi else f" (margin {lo:g}–{hi:g}°)"
    rows = [
        ("Line", info.get("line", "")),
        ("Track", info.get("track", "")),
        ("Stretch", info.get("stretch", "")),
        ("Time window", _window_text(info)),
        ("Navigation data", info.get("navigation", "")),
        ("Constellations", info.get("constellation", "")),
        ("Rules compared", ", ".join(info.get("rules", []))),
        ("Masks", f"{info.get('masks', '')}{margin_text}"),
        ("Survey rig", info.get("rig", "")),
        ("Vehicle attitude", info.get("attitude", "")),
        ("Survey positioning", info.get("positioning", "")),
        ("Far field", info.get("far_field", "")),
        ("Antenna", info.get("antenna", "")),
        ("Interval model", info.get("interval_model", "")),
        ("Interval width", info.get("interval_width", "")),
        ("Software", f"{info.get('software', '')}, report made {info.get('created_utc', '')}"),
    ]
    body = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows if v != "")
    return f'<table class="meta">{body}</table>'


def _banners(info: Mapping[str, Any]) -> str:
    """The synthetic-data banner and the warnings, above everything."""
    out = [
        f'<p class="synthetic" role="note"><b>Synthetic data.</b> {_e(w)}</p>'
        for w in info.get("synthetic", ())
    ]
    out += [f'<p class="warn">Warning: {_e(w)}</p>' for w in info.get("warnings", ())]
    return "".join(out)


def _provenance(info: Mapping[str, Any]) -> str:
    """Hashes and inputs in a folded section (one row per field; nested values as JSON)."""
    rows: list[tuple[str, object]] = [
        ("masks file", info.get("masks", "")),
        ("navigation", info.get("navigation", "")),
        ("track source", info.get("track_source", "")),
        ("software", info.get("software", "")),
        ("report made (UTC)", info.get("created_utc", "")),
    ]
    for k, v in (info.get("mask_provenance", {}) or {}).items():
        text = json.dumps(v, default=str) if isinstance(v, (dict, list)) else v
        rows.append((f"masks: {k}", text))
    body = "".join(
        f"<tr><th>{_e(k)}</th><td><code>{_e(v)}</code></td></tr>" for k, v in rows if v != ""
    )
    return (
        "<details><summary>Provenance: the inputs, their hashes and the software (click to "
        f"open)</summary><table class=\"small prov\">{body}</table></details>"
    )


def _figure(img: str, title: str, caption: str, fig_id: str) -> str:
    return (
        f'<figure id="fig-{fig_id}"><h3>{_e(title)}</h3>{img}<figcaption>{caption}'
        "</figcaption></figure>"
    )


def line_spans(results: Sequence[Availability], track: TrackMap | None) -> list[plots.LineSpan]:
    """The stretches labelled on the along-line figures, in chainage order.

    Tunnels (``track.tunnels_m``) and bridges (``track.bridges_m``) of the track map that
    overlap the positions, and "no sky" stretches: runs of positions where the masks rule
    (``results[0]``) trusts no satellite at any epoch, each covering its positions' cells
    (half-way to the neighbours).

    Parameters
    ----------
    results : sequence of Availability
        The masks rule first.
    track : TrackMap or None

    Returns
    -------
    list of plots.LineSpan
    """
    s = np.asarray(results[0].chainage_m, float)
    lo_s, hi_s = float(s[0]), float(s[-1])
    spans: list[plots.LineSpan] = []
    for kind, attr in (("tunnel", "tunnels_m"), ("bridge", "bridges_m")):
        for a, b in getattr(track, attr, ()) or ():
            if b >= lo_s and a <= hi_s:
                spans.append(plots.LineSpan(float(a), float(b), kind))
    blind = np.asarray(results[0].count).max(axis=1) == 0
    if blind.any():
        mid = (s[1:] + s[:-1]) / 2.0
        lo_c = np.r_[s[0], mid]
        hi_c = np.r_[mid, s[-1]]
        edges = np.flatnonzero(np.diff(np.r_[0, blind.astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2] - 1, strict=True):
            length = hi_c[b] - lo_c[a]
            spans.append(
                plots.LineSpan(float(lo_c[a]), float(hi_c[b]), "no sky", f"no sky {length:.0f} m")
            )
    return sorted(spans, key=lambda x: x.start_m)


def _sky_views(inputs: ReportInputs) -> list[plots.SkyView]:
    masks = inputs.masks
    sats = inputs.satellites
    rule = TrustRule.mask(masks)
    cutoffs = tuple(
        float(r.rule.split()[1]) for r in inputs.results if r.rule.startswith("cutoff ")
    )
    share4 = inputs.results[0].share_at_least(4)
    views = []
    for ch in inputs.sky_chainage_m:
        i = int(masks.position_index(ch)[0])
        rx = geodetic_to_ecef(masks.lat_deg[i], masks.lon_deg[i], masks.h_m[i])
        az, el = azel(rx, enu_rotation(masks.lat_deg[i], masks.lon_deg[i]), sats.pos_ecef_m)
        trusted = rule.trusted(masks.chainage_m[i], az, el)
        title = (
            f"{_km_label(inputs.track, float(masks.chainage_m[i]))}\n"
            f"≥ 4 trusted {100 * share4[i]:.0f} % of the time"
        )
        views.append(
            plots.SkyView(
                title,
                float(masks.heading_deg[i]),
                float(masks.az_step_deg),
                np.asarray(masks.mask_el_deg[i], float),
                np.asarray(masks.margin_deg[i], float),
                az,
                el,
                trusted,
                tuple(sats.sats),
                cutoffs,
                assumed=np.asarray(masks.source[i]) == BinSource.ASSUMED,
                terrain=np.asarray(masks.source[i]) == BinSource.TERRAIN,
                weak=None if masks.support is None else (
                    (np.asarray(masks.support[i]) < WEAK_SUPPORT)
                    & ~np.isin(masks.source[i], [BinSource.ASSUMED, BinSource.TERRAIN])),
            )
        )
    return views


def _ephemeris_note(sats: SatellitePositions) -> str:
    reason = sats.status.reason
    rows = []
    for code in Reason:
        if code == Reason.OK:
            continue
        hit = reason == code
        if hit.any():
            who = [s for j, s in enumerate(sats.sats) if hit[:, j].any()]
            share = float(hit.mean())
            rows.append(
                f"<tr><td>{_e(code.name)}</td><td>{_e(', '.join(who))}</td>"
                f"<td>{100 * share:.1f} %</td></tr>"
            )
    if not rows:
        return "<p>The ephemeris trusted every satellite at every epoch.</p>"
    return (
        "<details><summary>Satellites the ephemeris did not trust (they count for no rule)"
        "</summary><table class=small><tr><th>reason</th><th>satellites</th><th>share of "
        f"satellite-epochs</th></tr>{''.join(rows)}</table></details>"
    )


_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,'DejaVu Sans',sans-serif;
margin:0;background:#f6f6f4;color:#222;font-size:14px;line-height:1.4}
main{max-width:1180px;margin:0 auto;padding:18px 24px 40px;background:#fff}
h1{font-size:22px;margin:4px 0 2px}h2{font-size:17px;margin:26px 0 6px;
border-bottom:1px solid #ddd;padding-bottom:3px}h3{font-size:14px;margin:6px 0}
.sub{color:#555;margin:0 0 12px}
.warn{background:#fff3cd;border-left:4px solid #e0a800;padding:6px 10px;margin:8px 0}
.synthetic{background:#fde0ef;border:2px solid #c51b7d;color:#4d0026;padding:8px 12px;
margin:8px 0;font-size:15px}
details{margin:8px 0}summary{cursor:pointer;color:#333;font-weight:600}
table.prov td code{word-break:break-all;font-size:11px}
table{border-collapse:collapse}th,td{padding:3px 9px;text-align:left;vertical-align:top}
table.meta th{color:#555;font-weight:600;white-space:nowrap}
table.meta td{max-width:950px}
table.summary{margin:6px 0;font-size:14px}
table.summary caption{text-align:left;color:#555;font-size:12px;padding-bottom:4px}
table.summary th{background:#eef1f5;border-bottom:1px solid #bbb;font-weight:600;
font-size:12px}
table.summary td{border-bottom:1px solid #e3e3e3;text-align:right;white-space:nowrap}
table.summary td:first-child{text-align:left;white-space:normal}
table.summary tr.main td{font-weight:600;background:#f3f8fd}
table.summary tr.ref td{color:#6a3d9a;font-style:italic}
p.verdict{background:#fffbe6;border-left:4px solid #e6b800;padding:8px 12px;margin:10px 0}
figure{margin:18px 0 8px}figure img{max-width:100%;display:block}
figcaption{color:#444;font-size:13px;margin-top:4px}
.row{display:flex;gap:18px;align-items:flex-start}.col{flex:1 1 50%}
table.small{font-size:12px}table.small td,table.small th{border-bottom:1px solid #eee}
.files code{background:#f1f1f1;padding:0 3px}
footer{color:#666;font-size:12px;margin-top:26px;border-top:1px solid #ddd;padding-top:6px}
"""


def build_report(inputs: ReportInputs) -> str:
    """The report as one HTML document (figures embedded; no script, no external resource).

    Parameters
    ----------
    inputs : ReportInputs

    Returns
    -------
    str
        The HTML text.
    """
    results = inputs.results
    if not results:
        raise ValueError("ReportInputs.results is empty: compute at least the masks rule")
    if results[0].rule != "masks":
        raise ValueError(f"ReportInputs.results[0] must be the masks rule, got {results[0].rule!r}")
    plots.check_results(results)
    posts = tuple(getattr(inputs.track, "kilometre_posts", ()) or ())
    s = results[0].chainage_m
    posts = tuple(p for p in posts if s[0] <= p.chainage_m <= s[-1])
    return _page(inputs, _figures(inputs, posts))


def _stations(track: TrackMap | None) -> list[plots.MapPoint]:
    return [
        plots.MapPoint(st.name, float(st.lat_deg), float(st.lon_deg))
        for st in getattr(track, "stations", ()) or ()
    ]


def _figures(inputs: ReportInputs, posts: Sequence[KilometrePost]) -> dict[str, str]:
    """The report's figures by section id, in the order shown."""
    results = inputs.results
    info = inputs.info
    gnss = constellation_names(inputs.satellites.sats)
    rules = ", ".join(r.rule for r in results)
    spans = line_spans(results, inputs.track)
    where = _stretch_text(inputs)
    span_note = (
        " Hatched bands: "
        # both ends: a tunnel that began before the stretch was named by a start outside it
        # (a user trial: "tunnel (chainage 22.127 km)" on a stretch of 25.0-26.4 km)
        + ", ".join(f"{x.text} ({_km_label(inputs.track, x.start_m)} - "
                    f"{_km_label(inputs.track, x.end_m)})" for x in spans)
        + "."
        if spans
        else ""
    )
    axis_note = (
        "Bottom axis: the line's kilometre posts; top axis: chainage along the track map."
        if posts
        else "Axis: chainage along the track map (the track has no kilometre posts)."
    )
    figs: dict[str, str] = {}
    figs["map"] = _figure(
        _img(
            plots.line_map(
                results[0], inputs.track, SHARE_CLASSES, _stations(inputs.track),
                inputs.basemap_lonlat, title=f"{where}, {gnss}",
            ),
            f"Map of {where}: the line coloured by the share of time with at least 4 trusted "
            f"{gnss} satellites under the masks, with kilometre posts, stations, a scale bar "
            "and a north arrow",
        ),
        f"Map ({gnss}, masks)",
        "Left: the whole line with its stations (squares) and kilometre posts (dots), the "
        "stretch boxed in red. Right: the stretch, one segment per surveyed position, coloured "
        f"by the share of time with ≥ 4 trusted {gnss} satellites under the masks. North up; "
        "the scale bar is in the lower left corner. The same layer is "
        "<code>availability.geojson</code> (QGIS).",
        "map",
    )
    figs["along"] = _figure(
        _img(
            plots.availability_along_line(results, posts, spans, f"Trusted {gnss} satellites"),
            f"Line plot: share of time with at least 4 (top) and 6 (bottom) trusted {gnss} "
            f"satellites along {where}, one line per rule ({rules})",
        ),
        f"Availability along the line ({gnss})",
        f"Share of the time window with at least 4 (top) and 6 (bottom) trusted {gnss} "
        "satellites at each place, per rule. Where the blue line (masks) drops below the "
        "others, the survey found obstructions the other rules ignore. Purple: LOCOPROL "
        f"line-wide figures (GPS). {axis_note}{span_note}",
        "along",
    )
    figs["counts"] = _figure(
        _img(
            plots.count_maps(results, posts, f"Trusted {gnss} satellites over place and time"),
            f"Colour maps of the number of trusted {gnss} satellites over place (x) and time "
            f"(y), one panel per rule ({rules})",
        ),
        f"Trusted {gnss} satellites over place and time",
        "Each column is a place (kilometre posts below, chainage above), each row an instant "
        "(GPS time; UTC is GPS time minus the leap seconds given on the axis). Red: fewer than "
        "2 trusted satellites (no position); salmon: 2-3 (no safety claim); light blue: 4-5 "
        "(all pairs); blue: 6 or more (three independent pairs, the SIL-4 case). Long lines "
        "or windows show the lowest count of each block of cells.",
        "counts",
    )
    views = _sky_views(inputs)
    if views:
        places = "; ".join(v.title.split("\n")[0] for v in views)
        figs["sky"] = _figure(
            _img(
                plots.sky_plots(views, title=f"{gnss} satellites over the window"),
                f"Polar sky plots at {len(views)} places ({places}): the surveyed mask, its "
                f"margin and the tracks of the {gnss} satellites, each named",
            ),
            f"Sky plots at chosen places ({gnss})",
            "Looking up: north at the top, east to the right, zenith at the centre, horizon "
            "at the rim; rings at 15, 30 and 60° elevation (labelled on white). Brown: the "
            "surveyed mask; beige: its safety margin; hatched: assumed bins (not seen by a "
            "camera nor reconstructed); dotted orange: the flat cut-off; the black line with "
            "the arrow is the track (increasing chainage), L/R its sides. Satellite tracks "
            "over the whole window are blue while trusted and grey while masked, each named on "
            "its own track.",
            "sky",
        )
    figs["opening"] = _figure(
        _img(
            plots.opening_angle_along_line(results, posts, spans),
            f"Line plot: the opening angle across the track along {where}, per rule",
        ),
        "Opening angle across the track",
        "180° minus the mask elevation to the left and to the right of the track (margin "
        "included): the width of the sky slice that reaches the antenna directly. A flat "
        f"cut-off c gives 180° - 2c everywhere. {axis_note}",
        "opening",
    )
    every = info.get("interval_every", "")
    model_note = (
        "The error model is the source's default (a = b = 2 m), to be calibrated with "
        "`locator calibrate`, not a measurement."
        if info.get("interval_model_is_default", True)
        else f"Error model: {info.get('interval_model', '')}."
    )
    width = info.get("interval_width", "")
    if width:
        model_note += f" Pair intervals ± k sigma_K, {width}."
    short = _width_short(info)
    figs["interval"] = _figure(
        _img(
            plots.interval_along_line(
                results, posts, spans,
                f"Predicted interval with {gnss} satellites" + (f" ({short})" if short else ""),
            ),
            f"Line plot, logarithmic: median and 95th percentile of the predicted confidence "
            f"interval length with {gnss} satellites along {where}, per rule, with the LOCOPROL "
            "typical (dashed) and largest (dotted) lengths",
        ),
        f"Predicted confidence-interval length along the line ({gnss})",
        "Median (line) and 95th percentile (band edge) of the predicted SATHIA interval "
        f"over the epochs with ≥ 4 trusted {gnss} satellites (computed every {_e(every)} "
        "epochs); log scale. Purple dashed: LOCOPROL's typical 70 m; purple dotted: its "
        f"largest 600 m. {_e(model_note)}",
        "interval",
    )
    return figs


def _width_short(info: Mapping[str, Any]) -> str:
    """The intervals' width in a few words, for the figure's own title: a PNG taken out of
    the report still says which k (and map doubt) drew it. "" when the run does not say."""
    par = info.get("interval_model_params") or {}
    by_mode = par.get("k_sigma_by_mode")
    if by_mode:
        ks = [by_mode.get(m) for m in ("THREE_PAIRS", "ALL_PAIRS", "BEST_PAIR")]
        text = "k " + " / ".join(f"{k:.2f}" for k in ks if k is not None)
        risk = par.get("integrity_risk_per_epoch")
        if risk is not None:
            text = f"risk {risk:g} per epoch: {text} (3 pairs / 4-5 / 1 pair)"
    elif par.get("k_sigma") is not None:
        text = f"k {float(par['k_sigma']):.2f} every mode"
    else:
        return ""
    lat, vert = par.get("map_doubt_lateral_m"), par.get("map_doubt_vertical_m")
    if lat is not None and vert is not None:
        text += f", map doubt {lat:g} / {vert:g} m" if (lat or vert) else ", no map doubt"
    return text


def _stretch_text(inputs: ReportInputs) -> str:
    s = inputs.results[0].chainage_m
    a, b = _km_label(inputs.track, float(s[0])), _km_label(inputs.track, float(s[-1]))
    return f"{a} to {b}"


def _section(sid: str, body: str) -> str:
    return f'<section id="{sid}">{body}</section>\n'


def _page(inputs: ReportInputs, figs: Mapping[str, str]) -> str:
    """The HTML document: banners, header, summary, verdict, figures, files, provenance."""
    results = inputs.results
    info = inputs.info
    gnss = constellation_names(inputs.satellites.sats)
    files = "".join(
        f'<li><a href="{_e(Path(p).name)}"><code>{_e(Path(p).name)}</code></a> – '
        f"{_e(_FILE_DOC.get(k, k))}</li>"
        for k, p in inputs.files.items()
    )
    attribution = info.get("track_attribution", "")
    nav_note = (
        "Navigation: IGS station Esbjerg broadcast ephemerides of 2020-06-25 (georust/rinex "
        "test data, MIT/Apache-2.0)."
        if info.get("nav_is_embedded")
        else ""
    )
    title = f"GNSS availability – {info.get('line', '')}"
    sections = [
        _section("header", f"{_banners(info)}{_header(info)}"),
        _section(
            "summary",
            f"<h2>Summary ({_e(gnss)})</h2>"
            f"{_summary_table(results, gnss, info.get('interval_width', ''))}"
            f"{_verdict(results, inputs.track)}"
            '<p class="sub">Trusted: ephemeris healthy and valid, and elevation above the '
            "rule's threshold (mask + margin of the satellite's azimuth bin; the cut-off; or "
            'the horizon). "Longest &lt; 4 along the line": the longest run of places with '
            'fewer than 4 at one instant; "at one place": the longest time below 4 at one '
            "place. Places are given by the line's kilometre posts with the chainage beside. "
            "The LOCOPROL row is from other years, satellites and masks (GPS only): a "
            "yardstick, not a test.</p>",
        ),
        *(_section(k, v) for k, v in figs.items()),
        _section(
            "files",
            f'<h2>Files</h2><ul class="files">{files}</ul>{_ephemeris_note(inputs.satellites)}',
        ),
        _section("provenance", f"<h2>Provenance</h2>{_provenance(info)}"),
    ]
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_e(title)}</title><style>{_CSS}</style></head>
<body><main>
<h1>{_e(title)}</h1>
<p class="sub">Which {_e(gnss)} satellites a train may trust along the line, from the surveyed
elevation masks, compared with no mask and a flat cut-off.</p>
{"".join(sections)}
<footer>{_e(info.get("software", ""))}. Track: {_e(attribution)} {_e(nav_note)}
Definitions: docs/availability.md and docs/report.md of PREDISAT.</footer>
</main></body></html>
"""


_FILE_DOC = {
    "summary_csv": "one row per rule (the summary table)",
    "summary_json": "the summary and the run's inputs",
    "positions_csv": "one row per rule and position",
    "positions_parquet": "the same, Parquet",
    "epochs_csv": "one row per rule and epoch (line-wide shares)",
    "epochs_parquet": "the same, Parquet",
    "counts_parquet": "every trusted-satellite count (rule, chainage, time)",
    "geojson": "the line coloured by availability (QGIS: style on share_ge4 or stroke)",
    "ephemeris_status_csv": "each run of epochs in which the ephemeris did not trust a "
    "satellite (unhealthy, outside its validity, inconsistent, no data)",
    "report": "this report",
    "basemap": "the offline background of the map",
}
