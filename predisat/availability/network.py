"""Availability over a network: one report per line part and the network summary.

:func:`network_availability` runs :func:`predisat.availability.run.run_availability` (what
``predisat availability`` runs) for every line part with masks, one task per part on a
:class:`predisat.scheduler.TaskRunner` (each report computed serially inside its task), into
``OUT/<part key>/``. A part whose ``network.json`` holds the same key (its mask file's SHA-256,
the track's geometry, the options, the code) is not redone.

:func:`write_network_summary` writes the network's table (``summary.csv``: one row per line
part, those without a survey or that failed included), a map of the network coloured by the
share of time with at least 4 trusted satellites under the masks (``network_map.png``) and a
page linking each report (``summary.html`` and ``summary.md``). See ``docs/network.md``.
"""

from __future__ import annotations

import hashlib
import html
import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

from predisat import __version__
from predisat.atomic import staged_folder, write_bytes_atomic
from predisat.availability.interval import DEFAULT_MAP_DOUBT, MapDoubt
from predisat.codeversion import code_fingerprint
from predisat.gnss.errormodel import IntervalModel
from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH, IntegrityBudget
from predisat.jsontypes import JsonDict
from predisat.scheduler import Scheduler, TaskRunner
from predisat.storage import absolute
from predisat.track.map import TrackMap
from predisat.track.network import Network, track_key

__all__ = [
    "AvailabilityOptions",
    "LineAvailability",
    "LineInput",
    "network_availability",
    "write_network_summary",
]


@dataclass(frozen=True)
class AvailabilityOptions:
    """The options of :func:`~predisat.availability.run.run_availability` shared by every
    line (the names and defaults of ``predisat availability``)."""

    nav: tuple[str, ...] | None = None
    start: float | str | None = None
    end: float | str | None = None
    step_s: float = 30.0
    constellation: str = "gps"
    cutoff_deg: tuple[float, ...] = (15.0,)
    interval_every: int = 10
    integrity_risk: float | None = DEFAULT_RISK_PER_EPOCH  # None: ``k_sigma`` fixes k
    k_sigma: float | None = None
    map_doubt: MapDoubt = DEFAULT_MAP_DOUBT

    def key(self) -> JsonDict:
        nav = None if self.nav is None else [
            [str(p), hashlib.sha256(Path(p).read_bytes()).hexdigest()] for p in self.nav
        ]
        return {"nav": nav, "start": self.start, "end": self.end, "step_s": self.step_s,
                "constellation": self.constellation, "cutoff_deg": list(self.cutoff_deg),
                "interval_every": self.interval_every,
                "integrity_risk": self.integrity_risk, "k_sigma": self.k_sigma,
                "map_doubt_m": [self.map_doubt.lateral_m, self.map_doubt.vertical_m]}  # fmt: skip


@dataclass(frozen=True)
class LineInput:
    """One line part's masks and track map."""

    line_id: str
    part: int
    key: str
    masks_path: str
    track: TrackMap


@dataclass(frozen=True)
class LineAvailability:
    """One line part's report: where it is and its line-wide figures, one row per rule.

    Attributes
    ----------
    line_id, part, key : as :class:`LineInput`
    report_html : Path
    summary : list of dict
        :meth:`predisat.availability.engine.Availability.summary` per rule, masks first.
    resumed : bool
        Found finished from an earlier run.
    elapsed_s : float
    run : dict
        What the figures rest on (:data:`RUN_FIELDS` of the report's run description: the
        window, navigation data, constellation, synthetic-data notes, warnings).
    """

    line_id: str
    part: int
    key: str
    report_html: Path
    summary: list[JsonDict] = field(default_factory=list)
    resumed: bool = False
    elapsed_s: float = 0.0
    run: JsonDict = field(default_factory=dict)


RUN_FIELDS = ("window", "navigation", "constellation", "synthetic", "warnings")
"""The fields of a line's run description the network summary repeats."""


@dataclass(frozen=True)
class _Shared:
    out_dir: str
    options: AvailabilityOptions
    options_key: JsonDict
    code_fingerprint: str  # the client's; the runner checks the workers run the same code


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _task(shared: _Shared, item: LineInput) -> LineAvailability:
    """One line part's report (serially), then its ``network.json`` marker."""
    from predisat.availability.run import run_availability

    t0 = time.perf_counter()
    out = Path(shared.out_dir) / item.key
    marker = out / "network.json"
    key = {
        "masks_sha256": _sha256(Path(item.masks_path)),
        "track_key": track_key(item.track),
        "options": shared.options_key,
        "software_version": str(__version__),
        # a development install changes code under one version: a report of other code is
        # made again (a review: new refusals and warnings were skipped on a rerun)
        "code_fingerprint": shared.code_fingerprint,
    }
    if marker.is_file() and (out / "report.html").is_file():
        old = json.loads(marker.read_text())
        if old.get("key") == key:
            return LineAvailability(item.line_id, item.part, item.key, out / "report.html",
                                    old["summary"], True, time.perf_counter() - t0,
                                    old.get("run", {}))  # fmt: skip
    o = shared.options
    run = run_availability(
        item.masks_path, item.track, None if o.nav is None else list(o.nav), out_dir=out,
        start=o.start, end=o.end, step_s=o.step_s, constellation=o.constellation,
        cutoff_deg=o.cutoff_deg, interval_every=o.interval_every, scheduler="serial",
        progress=False,
        interval_model=IntervalModel() if o.k_sigma is None else IntervalModel(k_sigma=o.k_sigma),
        integrity=None if o.integrity_risk is None else IntegrityBudget(o.integrity_risk),
        map_doubt=o.map_doubt,
    )  # fmt: skip
    summary = [_plain(r.summary()) for r in run.results]
    described = _plain({k: run.info.get(k) for k in RUN_FIELDS})
    write_bytes_atomic(marker, json.dumps({"key": key, "summary": summary, "run": described},
                                          indent=1).encode())  # fmt: skip
    return LineAvailability(item.line_id, item.part, item.key, Path(run.report_html), summary,
                            False, time.perf_counter() - t0, described)  # fmt: skip


def _plain(d: JsonDict) -> JsonDict:
    """JSON-safe values (numpy scalars to Python, NaN to None)."""
    out: JsonDict = {}
    for k, v in d.items():
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, float) and not np.isfinite(v):
            v = None
        out[k] = v
    return out


def network_availability(
    inputs: Sequence[LineInput],
    out_dir: str | os.PathLike[str],
    options: AvailabilityOptions | None = None,
    *,
    scheduler: Scheduler | str | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> list[LineAvailability]:
    """One availability report per line part, ``out_dir/<key>/report.html``, in input order.

    Parameters
    ----------
    inputs : sequence of LineInput
    out_dir : path-like
    options : AvailabilityOptions, optional
    scheduler, workers
        Where the line tasks run (:meth:`predisat.scheduler.Scheduler.parse`).
    progress : bool
        A progress bar of the line parts.
    """
    from tqdm import tqdm

    opts = options or AvailabilityOptions()
    where = scheduler if isinstance(scheduler, Scheduler) else Scheduler.parse(scheduler, workers)
    if where.kind == "address":  # a worker resolves a relative path in its own folder
        out_dir = absolute(out_dir)
        if opts.nav is not None:
            opts = replace(opts, nav=tuple(absolute(n) for n in opts.nav))
        inputs = [replace(item, masks_path=absolute(item.masks_path)) for item in inputs]
    shared = _Shared(str(out_dir), opts, opts.key(), code_fingerprint())
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    done: dict[str, LineAvailability] = {}
    bar = tqdm(total=len(inputs), desc="availability", unit="line", disable=not progress)
    try:
        seen = [str(out_dir), *(item.masks_path for item in inputs), *(opts.nav or ())]
        with TaskRunner(where, code_version=code_fingerprint, paths=seen) as runner:
            for res in runner.map_unordered(_task, shared, list(inputs), name="line-report"):
                done[res.key] = res
                bar.update(1)
    finally:
        bar.close()
    return [done[i.key] for i in inputs]


_COLUMNS = ["line_id", "part", "key", "status", "length_km", "surveyed_km", "from_m", "to_m",
            "n_pos", "n_frames",
            "n_bad_frames", "share_ge4_masks", "share_ge4_cutoff", "longest_below4_m_masks",
            "mean_count_masks", "report", "message"]  # fmt: skip


def write_network_summary(
    network: Network,
    lines: pd.DataFrame,
    reports: Sequence[LineAvailability],
    out_dir: str | os.PathLike[str],
) -> dict[str, Path]:
    """The network's summary: table, map and page.

    Parameters
    ----------
    network : Network
        For the map (every line's reference track, grey where there are no masks).
    lines : pandas.DataFrame
        One row per line part: ``line_id``, ``part``, ``key``, ``status``, ``length_m``,
        ``from_m``, ``to_m`` (chainage of the first and last mask position, NaN without
        masks), ``n_pos``, ``n_frames``, ``n_bad_frames``, ``message``.
    reports : sequence of LineAvailability
        The reports of the parts with masks.
    out_dir : path-like

    Returns
    -------
    dict of str to Path
        ``"csv"``, ``"map"``, ``"html"``, ``"md"``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    by_key = {r.key: r for r in reports}
    rows = []
    for row in lines.to_dict("records"):
        rep = by_key.get(str(row["key"]))
        masks = rep.summary[0] if rep else {}
        cut = rep.summary[2] if rep and len(rep.summary) > 2 else {}
        rows.append({
            "line_id": row["line_id"], "part": int(row["part"]), "key": row["key"],
            "status": row["status"], "length_km": float(row["length_m"]) / 1000.0,
            "surveyed_km": (float(row["to_m"]) - float(row["from_m"])) / 1000.0,
            "from_m": float(row["from_m"]), "to_m": float(row["to_m"]),
            "n_pos": int(row["n_pos"]), "n_frames": int(row["n_frames"]),
            "n_bad_frames": int(row["n_bad_frames"]),
            "share_ge4_masks": masks.get("share_ge4", np.nan),
            "share_ge4_cutoff": cut.get("share_ge4", np.nan),
            "longest_below4_m_masks": masks.get("longest_below4_m", np.nan),
            "mean_count_masks": masks.get("mean_count", np.nan),
            "report": "" if rep is None else os.path.relpath(rep.report_html, out),
            "message": row.get("message", ""),
        })  # fmt: skip
    table = pd.DataFrame(rows, columns=_COLUMNS)
    cutoff_rule = next((r.summary[2]["rule"] for r in reports if len(r.summary) > 2), "")
    names = {"csv": "summary.csv", "map": "network_map.png", "html": "summary.html",
             "md": "summary.md"}  # fmt: skip
    # all four written before any earlier one is replaced: a full disk left them cut
    with staged_folder(out, last=(names["html"], names["md"])) as stage:
        table.to_csv(stage / names["csv"], index=False, float_format="%.6g")
        _network_map(network, table, stage / names["map"])
        basis = _basis(reports)
        page = _markdown(network, table, cutoff_rule, basis)
        (stage / names["md"]).write_text(page, encoding="utf-8")
        page = _html(network, table, cutoff_rule, basis)
        (stage / names["html"]).write_text(page, encoding="utf-8")
    return {k: out / name for k, name in names.items()}


def _basis(reports: Sequence[LineAvailability]) -> list[str]:
    """What every line's figures rest on, said once per distinct value: satellites counted,
    navigation data, window, synthetic data, warnings (a summary is read without the
    reports)."""
    out: list[str] = []
    for name, label in (("constellation", "Satellites counted"), ("navigation", "Navigation"),
                        ("window", "Window")):  # fmt: skip
        values = sorted({str(r.run[name]) for r in reports if r.run.get(name)})
        if values:
            out.append(f"{label}: {'; '.join(values)}")
    notes = sorted({str(n) for r in reports for n in (r.run.get("synthetic") or [])})
    out += [f"Synthetic data: {n}" for n in notes]
    warned = sorted({f"{r.key}: {w}" for r in reports for w in (r.run.get("warnings") or [])})
    out += [f"Warning: {w}" for w in warned]
    return out


def _network_map(network: Network, table: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    share = {(r.line_id, r.part): r for r in _rows(table)}
    cmap, norm = colormaps["RdYlGn"], Normalize(0.0, 1.0)
    lat_all = np.concatenate([tm.lat_deg for ln in network.lines for tm in ln.parts])
    lon_all = np.concatenate([tm.lon_deg for ln in network.lines for tm in ln.parts])
    lat_mid = float(np.mean(lat_all))
    # the figure takes the network's shape: 9 in wide, as tall as the map needs (3-9 in)
    wide = max(float(np.ptp(lon_all)) * np.cos(np.radians(lat_mid)), 1e-6)
    tall_in = float(np.clip(7.0 * float(np.ptp(lat_all)) / wide + 2.0, 3.5, 9.0))
    fig, ax = plt.subplots(figsize=(9.0, tall_in), dpi=100)
    for ln in network.lines:
        for k, tm in enumerate(ln.parts, start=1):
            lo = np.linspace(0.0, tm.length_m, max(2, int(tm.length_m // 20.0)))
            lat, lon, _ = tm.position_at(lo)
            ax.plot(lon, lat, color="0.6", lw=1.5, ls=(0, (4, 2)), zorder=2)
            row = share.get((ln.line_id, k))
            s = np.nan if row is None else float(row.share_ge4_masks)
            if row is not None and np.isfinite(s):  # the surveyed stretch, coloured
                a, b = float(row.from_m), float(row.to_m)
                ch = np.linspace(a, b, max(2, int((b - a) // 5.0)))
                la, lo_deg, _ = tm.position_at(ch)
                ax.plot(lo_deg, la, color=cmap(norm(s)), lw=5, solid_capstyle="butt", zorder=3)
            mid = len(lat) // 2
            ax.annotate(f"{ln.line_id}" + (f" p{k}" if len(ln.parts) > 1 else ""),
                        (lon[mid], lat[mid]), fontsize=8, xytext=(4, 4),
                        textcoords="offset points", zorder=4)  # fmt: skip
    ax.set_aspect(1.0 / np.cos(np.radians(lat_mid)))
    ax.set_xlabel("longitude, deg")
    ax.set_ylabel("latitude, deg")
    ax.set_title(f"{network.name}: share of time with >= 4 trusted satellites (masks)\n"
                 "grey dashed: the network's track where there are no masks",
                 fontsize=10)  # fmt: skip
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=ax, orientation="horizontal", fraction=0.06, pad=0.18, aspect=40,
                 label=">= 4 trusted satellites, share of time")
    if network.attribution:
        fig.text(0.01, 0.01, network.attribution, fontsize=6, color="0.4")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _rows(t: pd.DataFrame) -> list[SimpleNamespace]:
    """The table's rows with attribute access."""
    return [SimpleNamespace(**{str(k): v for k, v in r.items()}) for r in t.to_dict("records")]


def _km(x: object) -> str:
    return f"{float(x):.2f}" if isinstance(x, float) and np.isfinite(x) else "-"


def _m(x: object) -> str:
    return f"{float(x):.0f}" if isinstance(x, float) and np.isfinite(x) else "-"


def _pct(x: object) -> str:
    return f"{100.0 * float(x):.1f}" if isinstance(x, float) and np.isfinite(x) else "-"


def _markdown(network: Network, t: pd.DataFrame, cutoff_rule: str, basis: Sequence[str]) -> str:
    said = "".join(f"* {b}\n" for b in basis)
    head = (f"# Network {network.name}\n\n{len(t)} line part(s), "
            f"{t.length_km.sum():.2f} km; masks for {int((t.n_pos > 0).sum())}. "
            f"{network.attribution}\n\n"
            + (f"{said}\n" if said else "") +
            "![network map](network_map.png)\n\n"
            "| line | part | status | km | surveyed km | positions | frames | bad frames | "
            f">=4 masks % | >=4 {cutoff_rule or 'cut-off'} % | longest <4 m | report |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|\n")  # fmt: skip
    body = "".join(
        f"| {r.line_id} | {r.part} | {r.status} | {r.length_km:.2f} | {_km(r.surveyed_km)} | "
        f"{r.n_pos} | {r.n_frames} | "
        f"{r.n_bad_frames} | {_pct(r.share_ge4_masks)} | {_pct(r.share_ge4_cutoff)} | "
        f"{_m(r.longest_below4_m_masks)} | "
        + (f"[report]({r.report})" if r.report else "")
        + (" warning: " if r.report and r.message else "") + r.message.replace("|", "/")
        + " |\n"
        for r in _rows(t)
    )
    skipped = "".join(f"* {s.line_id}: {s.what}: {s.reason}\n" for s in network.skipped)
    return head + body + (f"\n## Left out of the network file\n\n{skipped}" if skipped else "")


def _html(network: Network, t: pd.DataFrame, cutoff_rule: str, basis: Sequence[str]) -> str:
    e = html.escape
    warn = ("Warning", "Synthetic")
    said = "".join(
        f'<p class="warn">{e(b)}</p>' if b.startswith(warn) else f"<p>{e(b)}</p>" for b in basis
    )
    rows = "".join(
        f"<tr><td>{e(r.line_id)}</td><td>{r.part}</td><td>{e(r.status)}</td>"
        f"<td>{r.length_km:.2f}</td><td>{_km(r.surveyed_km)}</td><td>{r.n_pos}</td>"
        f"<td>{r.n_frames}</td>"
        f"<td>{r.n_bad_frames}</td><td>{_pct(r.share_ge4_masks)}</td>"
        f"<td>{_pct(r.share_ge4_cutoff)}</td><td>{_m(r.longest_below4_m_masks)}</td><td>"
        + (f'<a href="{e(r.report)}">report</a>' if r.report else "")
        + (f'<p class="warn">{e(r.message)}</p>' if r.report and r.message else
           "" if r.report else e(r.message))
        + "</td></tr>"
        for r in _rows(t)
    )
    skipped = "".join(f"<li>{e(s.line_id)}: {e(s.what)}: {e(s.reason)}</li>"
                      for s in network.skipped)  # fmt: skip
    return (
        f"<!doctype html><html><head><meta charset=utf-8><title>Network {e(network.name)}"
        "</title><style>body{font-family:sans-serif;margin:16px}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
        ".warn{background:#fff3cd;padding:4px}</style></head><body>"
        f"<h1>Network {e(network.name)}</h1><p>{len(t)} line part(s), "
        f"{t.length_km.sum():.2f} km; masks for {int((t.n_pos > 0).sum())}. "
        f"{e(network.attribution)}</p>{said}<img src=network_map.png alt='network map'>"
        "<table><tr><th>line</th><th>part</th><th>status</th><th>km</th><th>surveyed km</th>"
        "<th>positions</th>"
        "<th>frames</th><th>bad frames</th><th>&ge;4 masks %</th>"
        f"<th>&ge;4 {e(cutoff_rule or 'cut-off')} %</th><th>longest &lt;4, m</th>"
        f"<th>report</th></tr>{rows}</table>"
        + (f"<h2>Left out of the network file</h2><ul>{skipped}</ul>" if skipped else "")
        + "</body></html>\n"
    )
