"""The report orients an engineer: places by kilometre post with the chainage beside, the
track named, synthetic data flagged, UTC beside GPS time, labelled stretches, a real map,
readable sky plots and the provenance folded away (issue 33)."""

from __future__ import annotations

import dataclasses
import json
import re
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.patches import Polygon, Rectangle

from predisat.availability import plots
from predisat.availability.engine import Availability
from predisat.availability.report import (
    ReportInputs,
    _km_label,
    basemap_from_geojson,
    build_report,
    constellation_names,
    line_spans,
)
from predisat.availability.run import synthetic_notes
from predisat.availability.satellites import LinePositions, SatellitePositions, azel
from predisat.geodesy import enu_rotation, geodetic_to_ecef
from predisat.gnss.ephemeris import EphemerisStatus
from predisat.masks.maskset import BinSource, MaskSet
from predisat.track.map import demo_track

STEP_S = 600.0
T0 = 1277078400.0  # 2020-06-25 00:00 GPST
LEAP_S = 18.0  # GPS - UTC since 2017 (IERS Bulletin C)
CH = 4000.0 + 10.0 * np.arange(10)


@pytest.fixture(scope="module")
def track():
    # a tunnel over positions 7-8 and a bridge beyond the stretch (not labelled)
    return demo_track().with_metadata(tunnels_m=[(4068.0, 4082.0)], bridges_m=[(9000.0, 9100.0)])


def _result(track, rule: str, count: np.ndarray) -> Availability:
    pos = LinePositions.from_track(track, CH, 4.0)
    n_pos, n_ep = count.shape
    interval = np.where(count >= 2, 40.0 + count, np.nan).astype(np.float32)
    return Availability(
        pos, T0 + STEP_S * np.arange(n_ep), ("G01", "E02"), rule, count.astype(np.uint8),
        interval, np.full(count.shape, 0.5, np.float32), np.full(n_pos, 160.0), {},
    )  # fmt: skip


def _masks_counts() -> np.ndarray:
    c = np.full((10, 4), 6)
    c[2:4] = 0  # positions 2-3: nothing trusted at any epoch (no sky)
    c[5, 1] = 0  # position 5: one bad epoch only (not "no sky")
    return c


@pytest.fixture(scope="module")
def results(track):
    return (
        _result(track, "masks", _masks_counts()),
        _result(track, "no mask", np.full((10, 4), 9)),
        _result(track, "cutoff 15 deg", np.full((10, 4), 7)),
    )


@pytest.fixture(scope="module")
def masks(track):
    src = np.zeros((10, 72), np.uint8)
    src[:, 10:20] = BinSource.ASSUMED  # azimuth 50-95 deg assumed everywhere
    m = MaskSet.from_track(track, CH, np.full((10, 72), 10.0), margin_deg=0.0)
    return MaskSet.from_arrays(
        m.chainage_m, m.lat_deg, m.lon_deg, m.h_m, m.heading_deg, m.mask_el_deg,
        az_step_deg=5.0, source=src, margin_deg=0.0,
        provenance={"survey_hash": "f00d" * 16, "survey_generator": "predisat.synth.generate"},
    )  # fmt: skip


@pytest.fixture(scope="module")
def satellites(track):
    """G01 fixed at (az 90, el 30) and E02 at (200, 60) in the sky of the first position."""
    pos = LinePositions.from_track(track, CH[:1], 4.0)
    rx = geodetic_to_ecef(pos.lat_deg[0], pos.lon_deg[0], pos.h_m[0])
    rot = enu_rotation(pos.lat_deg[0], pos.lon_deg[0])
    az, el = np.radians([90.0, 200.0]), np.radians([30.0, 60.0])
    unit = np.c_[np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)]
    p = np.repeat((rx + 2.02e7 * unit @ rot)[None], 4, axis=0)
    gps_s = T0 + STEP_S * np.arange(4)
    status = EphemerisStatus(gps_s, ("G01", "E02"), np.zeros((4, 2), np.int8),
                             np.full((4, 2), "", object))  # fmt: skip
    return SatellitePositions(gps_s, ("G01", "E02"), p, status)


INFO = {
    "line": "test line",
    "track": "line 144 track A (14.17 km)",
    "rules": ["masks", "no mask", "cutoff 15 deg"],
    "window": "2020-06-25 00:00:00 - 2020-06-25 00:40:00 GPST",
    "window_gps_s": [T0, T0 + 4 * STEP_S],
    "mask_provenance": {"survey_hash": "f00d" * 16, "params": {"k": 1}},
    "synthetic": ["The masks were made from a synthetic survey."],
}


@pytest.fixture(scope="module")
def html(results, masks, satellites, track) -> str:
    inputs = ReportInputs(
        results, masks, satellites, track, INFO, sky_chainage_m=(CH[0], CH[6]),
        files={"geojson": "availability.geojson"},
    )  # fmt: skip
    return build_report(inputs)


def _utc(gps_s: float) -> str:
    return f"{datetime(1980, 1, 6) + timedelta(seconds=gps_s - LEAP_S):%Y-%m-%d %H:%M:%S}"


# ----------------------------------------------------------------------------- HTML
def test_places_are_kilometre_posts_with_the_chainage_beside(html: str, track) -> None:
    km = float(track.kilometre_at(CH[6])) / 1000.0
    # the sky plot's place (alt text) and nowhere a bare "chainage ... (km ...)" of old
    assert f"km {km:.3f} (chainage {CH[6] / 1000:.3f} km)" in html
    assert not re.search(r"chainage [0-9.]+ km \(km", html)


def test_hatched_bands_are_named_by_both_ends(html: str, track) -> None:
    """A user trial: a tunnel that began before the stretch was named by its start alone,
    a place outside the stretch."""
    ends = [_km_label(track, x) for x in (4068.0, 4082.0)]
    assert "Hatched bands: no sky 20 m (" in html and f"tunnel ({ends[0]} - {ends[1]})" in html


def test_header_names_the_track_and_gives_utc_beside_gps(html: str) -> None:
    assert "<th>Track</th><td>line 144 track A (14.17 km)</td>" in html
    row = re.search(r"<th>Time window</th><td>(.*?)</td>", html)
    assert row is not None
    assert "2020-06-25 00:00:00 - 2020-06-25 00:40:00 GPST" in row.group(1)
    assert f"UTC {_utc(T0)} - {_utc(T0 + 4 * STEP_S)} UTC" in row.group(1)


def test_synthetic_banner_comes_first(html: str) -> None:
    banner = html.index('class="synthetic"')
    assert banner < html.index('<table class="meta">') < html.index('id="summary"')
    assert "synthetic survey" in html[banner : banner + 200]


def test_provenance_is_folded(html: str) -> None:
    details = html.index('<section id="provenance"><h2>Provenance</h2><details>')
    # the hash appears once, inside the folded section, not in the header table
    assert html.count("f00d" * 16) == 1 and html.index("f00d" * 16) > details
    assert "Mask provenance" not in html


def test_constellations_are_named_in_figure_titles(html: str) -> None:
    titles = re.findall(r"<figure id=\"fig-(\w+)\"><h3>(.*?)</h3>", html)
    assert {t[0] for t in titles} >= {"map", "along", "counts", "sky", "interval"}
    for fid, title in titles:
        if fid != "opening":  # geometry only: no satellite in it
            assert "GPS + Galileo" in title, (fid, title)
    assert constellation_names(("E11", "G01", "R03")) == "GPS + GLONASS + Galileo"


def test_files_are_links(html: str) -> None:
    assert '<a href="availability.geojson"><code>availability.geojson</code></a>' in html


# ----------------------------------------------------------------------------- synthetic
def test_synthetic_notes_from_provenance(tmp_path: Path) -> None:
    assert synthetic_notes({"survey_generator": "predisat.synth.generate"})
    assert synthetic_notes({"source": "true masks of the simulated world"})
    assert synthetic_notes({"survey": str(tmp_path), "survey_hash": "x"}) == []
    # masks processed before the provenance kept the generator: read the survey's own file
    (tmp_path / "survey.yaml").write_text("generator: predisat.synth.generate\n")
    assert "synthetic survey" in synthetic_notes({"survey": str(tmp_path)})[0]


# ----------------------------------------------------------------------------- spans
def test_spans_label_tunnels_and_no_sky(results, track) -> None:
    spans = line_spans(results, track)
    assert [(s.kind, s.start_m, s.end_m) for s in spans] == [
        ("no sky", 4015.0, 4035.0),  # positions 2-3, half-way to the neighbours
        ("tunnel", 4068.0, 4082.0),
    ]
    assert spans[0].text == "no sky 20 m"
    fig = plots.availability_along_line(results, track.kilometre_posts, spans)
    for ax in fig.axes[:2]:
        bands = [p for p in ax.patches if isinstance(p, Polygon | Rectangle)
                 and p.get_label().startswith("_span")]  # fmt: skip
        assert sorted(p.get_label() for p in bands) == ["_span no sky", "_span tunnel"]
        for p in bands:
            assert p.get_hatch()
    labels = {t.get_gid(): t.get_text() for t in fig.axes[0].texts if t.get_gid()}
    assert labels == {"span:no sky": "no sky 20 m", "span:tunnel": "tunnel"}


def test_along_line_axis_gives_kilometre_posts_below_and_chainage_above(results) -> None:
    track = demo_track()
    ch = 3000.0 + 100.0 * np.arange(25)
    pos = LinePositions.from_track(track, ch, 4.0)
    count = np.full((25, 2), 6, np.uint8)
    r = Availability(pos, T0 + np.arange(2.0), ("G01",), "masks", count, None, None,
                     np.full(25, 170.0), {})  # fmt: skip
    posts = [p for p in track.kilometre_posts if ch[0] <= p.chainage_m <= ch[-1]]
    fig = plots.availability_along_line([r], posts)
    bottom = fig.axes[1]
    fig.canvas.draw()
    assert bottom.get_xlabel() == "kilometre post (line km)"
    got = [t.get_text() for t in bottom.get_xticklabels()]
    assert got == [p.label for p in posts] == ["km 3.000", "km 4.000", "km 5.000"]
    np.testing.assert_allclose(bottom.get_xticks(), [p.chainage_m / 1000 for p in posts])
    top = [c for c in fig.axes[0].child_axes]
    assert len(top) == 1 and top[0].get_xlabel().startswith("chainage (km")


# ----------------------------------------------------------------------------- map
def test_map_has_scale_bar_north_arrow_posts_stations_and_basemap(results, tmp_path) -> None:
    track = demo_track()
    base = tmp_path / "base.geojson"
    road = [[4.68, 50.52], [4.70, 50.52]]
    base.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "LineString",
                                                            "coordinates": road}}]}))  # fmt: skip
    lines = basemap_from_geojson(base)
    st = [plots.MapPoint(s.name, s.lat_deg, s.lon_deg) for s in track.stations]
    fig = plots.line_map(results[0], track, stations=st, basemap_lonlat=lines)
    overview, detail = fig.axes[:2]
    for ax in (overview, detail):
        gids = {a.get_gid() for a in [*ax.lines, *ax.texts, *ax.patches]}
        assert {"scalebar", "scalebar:label", "basemap"} <= gids
        arrows = [t for t in ax.texts if t.get_gid() == "northarrow"]
        assert len(arrows) == 1 and arrows[0].get_text() == "N"
        assert arrows[0].xy[1] > arrows[0].xyann[1]  # pointing up: north is up
        # the scale bar's drawn length is the length it says (axes in km)
        bar = next(a for a in ax.lines if a.get_gid() == "scalebar")
        text = next(a for a in ax.texts if a.get_gid() == "scalebar:label").get_text()
        value, unit = text.split()
        want_km = float(value) / (1000.0 if unit == "m" else 1.0)
        assert np.ptp(bar.get_xdata()) == pytest.approx(want_km)
    names = {t.get_gid() for t in overview.texts}
    # the whole line shows its operating points and km posts; the stretch box is drawn
    assert {"station:GEMBLOUX", "station:JEMEPPE-FR.M"} <= names
    assert any(p.get_gid() == "stretchbox" for p in overview.patches)
    assert any((t.get_gid() or "").startswith("kmpost:km 4.000") for t in detail.texts)


def test_basemap_errors_name_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "b.geojson"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match=r"basemap .*b\.geojson: cannot be read as GeoJSON"):
        basemap_from_geojson(bad)
    bad.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"geometry": {"type": "LineString", "coordinates": [[50.5, 400.0], [50.6, 4.0]]}}]}))
    with pytest.raises(ValueError, match="feature 0 has coordinates outside lon/lat"):
        basemap_from_geojson(bad)


# ----------------------------------------------------------------------------- sky plots
def _view(masks: MaskSet, satellites: SatellitePositions, margin: float) -> plots.SkyView:
    pos = LinePositions.from_track(demo_track(), CH[:1], 4.0)
    az, el = azel(pos.ecef_m[0], pos.enu_rotation[0], satellites.pos_ecef_m)
    return plots.SkyView(
        "t", 90.0, 5.0, np.full(72, 10.0), np.full(72, margin), az, el,
        np.ones(az.shape, bool), ("G01", "E02"), (15.0,),
        assumed=np.asarray(masks.source[0]) == BinSource.ASSUMED,
    )  # fmt: skip


def test_sky_plot_names_satellites_and_keeps_rings_readable(masks, satellites) -> None:
    fig = plots.sky_plots([_view(masks, satellites, 0.0)])
    ax: Any = fig.axes[0]
    texts = {t.get_gid(): t for t in ax.texts if t.get_gid()}
    # each satellite named on its own track (G01 at el 30, E02 at el 60: r = 90 - el)
    assert texts["sat:G01"].get_position() == pytest.approx((np.pi / 2, 60.0), abs=1e-6)
    assert texts["sat:E02"].get_position() == pytest.approx((np.radians(200.0), 30.0), abs=1e-6)
    # ring labels above every satellite track, on an opaque box
    top_track = max(ln.get_zorder() for ln in ax.get_lines())
    for e in (15, 30, 60):
        ring = texts[f"ring:{e}"]
        assert ring.get_text() == f"{e}°" and ring.get_zorder() > top_track
        assert ring.get_bbox_patch() is not None
        assert to_rgba(ring.get_bbox_patch().get_facecolor())[:3] == (1.0, 1.0, 1.0)
    # the polar axis' own (hidden-under-tracks) radius labels are gone
    assert all(t.get_text() == "" for t in ax.get_yticklabels())


def test_sky_plot_legend_has_no_zero_margin_and_hatches_assumed_sky(masks, satellites) -> None:
    fig = plots.sky_plots([_view(masks, satellites, 0.0)])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "margin" not in labels and "assumed (not seen)" in labels
    hatched = [c for c in fig.axes[0].collections if c.get_gid() == "assumed"]
    assert len(hatched) == 1 and hatched[0].get_hatch() == "////"
    # the hatch covers exactly the assumed bins (azimuth 47.5-97.5 deg) down to the mask
    verts = hatched[0].get_paths()[0].vertices
    inside = verts[verts[:, 1] < 90.0 - 1e-9]
    assert np.degrees(inside[:, 0]).min() == pytest.approx(47.5)
    assert np.degrees(inside[:, 0]).max() == pytest.approx(97.5)
    with_margin = plots.sky_plots([_view(masks, satellites, 1.0)])
    assert "margin" in [t.get_text() for t in with_margin.legends[0].get_texts()]


# ----------------------------------------------------------------------------- in a browser
def test_report_in_headless_chromium(results, masks, satellites, track, tmp_path: Path) -> None:
    """The page as Chromium renders it: every figure captioned with alt text, images decoded,
    no broken local link, the provenance folded, and a screenshot of every section."""
    from tests.predisat.availability.browser import (
        broken_local_links,
        chromium_missing,
        headless_chromium,
        page_facts,
        screenshot_sections,
    )

    why = chromium_missing()
    if why:
        pytest.skip(why)
    (tmp_path / "availability.geojson").write_text("{}")
    (tmp_path / "summary.csv").write_text("rule\n")
    inputs = ReportInputs(
        results, masks, satellites, track, INFO, sky_chainage_m=(CH[0], CH[6]),
        files={"geojson": tmp_path / "availability.geojson", "summary_csv": "summary.csv"},
    )  # fmt: skip
    page = tmp_path / "report.html"
    page.write_text(build_report(inputs), encoding="utf-8")
    with headless_chromium() as driver:
        facts = page_facts(driver, page)
        shots = screenshot_sections(driver, page, tmp_path / "shots", "report")
    assert facts.sections == [
        "header", "summary", "map", "along", "counts", "sky", "opening", "interval", "files",
        "provenance",
    ]  # fmt: skip
    assert len(facts.figures) == 6
    for fig in facts.figures:
        assert fig["caption"] and fig["alt"], fig["id"]
        assert fig["complete"] and fig["width"] == 1100, fig["id"]  # the PNG decoded
    assert broken_local_links(facts.links, page) == []
    assert "summary.csv" in facts.links and "availability.geojson" in facts.links
    assert facts.details_open and not any(facts.details_open)
    assert facts.banner.startswith("Synthetic data.")
    assert [s.name for s in shots] == [f"report_{s}.png" for s in facts.sections]
    for s in shots:
        assert s.read_bytes()[:4] == b"\x89PNG" and s.stat().st_size > 1000


def test_broken_link_check_finds_missing_and_remote_files(tmp_path: Path) -> None:
    from tests.predisat.availability.browser import broken_local_links

    (tmp_path / "here.csv").write_text("")
    page = tmp_path / "r.html"
    links = ["here.csv", "gone.csv", "data:image/png;base64,AA", "#top", "https://x.org/a.png"]
    assert broken_local_links(links, page) == [
        "gone.csv", "https://x.org/a.png (remote: the report must load nothing)",
    ]  # fmt: skip


def test_sky_plot_hatches_terrain_bins_apart(masks, satellites) -> None:
    base = _view(masks, satellites, 0.0)
    terrain = np.zeros(72, bool)
    terrain[36:40] = True  # azimuth 177.5-197.5 deg raised to an elevation model's horizon
    fig = plots.sky_plots([dataclasses.replace(base, terrain=terrain)])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "terrain (elevation model)" in labels and "assumed (not seen)" in labels
    hatched = [c for c in fig.axes[0].collections if c.get_gid() == "terrain"]
    assert len(hatched) == 1 and hatched[0].get_hatch() != "////"
    verts = hatched[0].get_paths()[0].vertices
    inside = verts[verts[:, 1] < 90.0 - 1e-9]
    assert np.degrees(inside[:, 0]).min() == pytest.approx(177.5)
    assert np.degrees(inside[:, 0]).max() == pytest.approx(197.5)
    plain = plots.sky_plots([base])
    assert "terrain (elevation model)" not in [t.get_text() for t in plain.legends[0].get_texts()]


def test_sky_plot_dots_weakly_supported_bins(masks, satellites) -> None:
    base = _view(masks, satellites, 0.0)
    weak = np.zeros(72, bool)
    weak[9:12] = True  # azimuth 42.5-57.5 deg: fewer than two views behind the bound
    fig = plots.sky_plots([dataclasses.replace(base, weak=weak)])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "weakly supported (< 2 views)" in labels
    dotted = [c for c in fig.axes[0].collections if c.get_gid() == "weak"]
    assert len(dotted) == 1 and dotted[0].get_hatch() == "...."
    verts = dotted[0].get_paths()[0].vertices
    inside = verts[verts[:, 1] < 90.0 - 1e-9]
    assert np.degrees(inside[:, 0]).min() == pytest.approx(42.5)
    assert np.degrees(inside[:, 0]).max() == pytest.approx(57.5)
    plain = plots.sky_plots([base])
    plain_labels = [t.get_text() for t in plain.legends[0].get_texts()]
    assert "weakly supported (< 2 views)" not in plain_labels
    with pytest.raises(ValueError, match="weak needs a mask and one flag per mask bin"):
        dataclasses.replace(base, weak=np.zeros(5, bool))


def test_report_sky_views_flag_weak_bins_from_the_support(results, masks, satellites, track):
    """The report's sky views: weak = support below 2, apart from assumed and terrain bins;
    none without support (a version 1 or 2 file)."""
    from predisat.availability.report import _sky_views

    sup = np.full(masks.mask_el_deg.shape, 3, np.uint8)
    sup[:, 30:33] = 1  # weak, observed
    sup[:, 12] = 0  # weak but assumed (10-20): hatched as assumed, not dotted
    with_sup = dataclasses.replace(masks, support=sup)
    inputs = ReportInputs(results, with_sup, satellites, track, INFO, sky_chainage_m=(CH[0],))
    (view,) = _sky_views(inputs)
    assert view.weak is not None and np.flatnonzero(view.weak).tolist() == [30, 31, 32]
    plain = ReportInputs(results, masks, satellites, track, INFO, sky_chainage_m=(CH[0],))
    assert _sky_views(plain)[0].weak is None


def test_a_basemap_in_a_national_grid_is_read_in_its_crs(tmp_path: Path) -> None:
    """--track read a Lambert 72 GeoJSON with its crs member; --basemap refused the same file
    (a GIS user trial). pyproj is the reference."""
    from pyproj import Transformer

    lon = np.array([4.69, 4.70, 4.71])
    lat = np.array([50.56, 50.565, 50.57])
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:31370", always_xy=True).transform(lon, lat)
    doc = {"type": "FeatureCollection",
           "crs": {"type": "name", "properties": {"name": "EPSG:31370"}},
           "features": [{"type": "Feature", "properties": {},
                         "geometry": {"type": "LineString",
                                      "coordinates": np.c_[x, y].tolist()}}]}  # fmt: skip
    path = tmp_path / "l72.geojson"
    path.write_text(json.dumps(doc))
    (line,) = basemap_from_geojson(path)
    np.testing.assert_allclose(line, np.c_[lon, lat], atol=1e-7)


def test_interval_figure_names_its_k_in_its_own_title(results, masks, satellites, track,
                                                      monkeypatch) -> None:
    """The interval figure's image, taken out of the report, says which integrity setting
    drew it (a review of 2026-12-07: only the caption beside it did)."""
    from predisat.availability import report as report_mod

    seen: list[str] = []
    real = report_mod.plots.interval_along_line

    def spy(*args, **kwargs):
        seen.append(args[3] if len(args) > 3 else kwargs.get("title", ""))
        return real(*args, **kwargs)

    monkeypatch.setattr(report_mod.plots, "interval_along_line", spy)
    info = dict(INFO, interval_model_params={
        "k_sigma": None, "integrity_risk_per_epoch": 1e-12,
        "k_sigma_by_mode": {"BEST_PAIR": 7.1305, "ALL_PAIRS": 4.8230, "THREE_PAIRS": 3.7770},
        "map_doubt_lateral_m": 1.5, "map_doubt_vertical_m": 1.0,
    })  # fmt: skip
    build_report(ReportInputs(results, masks, satellites, track, info,
                              sky_chainage_m=(CH[0], CH[6])))  # fmt: skip
    assert seen and "risk 1e-12" in seen[0] and "k 3.78 / 4.82 / 7.13" in seen[0], seen
    assert "map doubt 1.5 / 1 m" in seen[0]
    seen.clear()
    info = dict(INFO, interval_model_params={"k_sigma": 2.0, "map_doubt_lateral_m": 0.0,
                                             "map_doubt_vertical_m": 0.0})  # fmt: skip
    build_report(ReportInputs(results, masks, satellites, track, info,
                              sky_chainage_m=(CH[0], CH[6])))  # fmt: skip
    assert "k 2.00 every mode, no map doubt" in seen[0], seen
