"""Tests of predisat.availability.report and predisat.availability.plots on small hand-made
results."""

from __future__ import annotations

import base64
import re
from datetime import datetime, timedelta
from html.parser import HTMLParser
from typing import Any

import numpy as np
import pytest
from matplotlib.colors import to_rgba

from predisat.availability import plots
from predisat.availability.engine import Availability
from predisat.availability.report import (
    SHARE_CLASSES,
    ReportInputs,
    build_report,
    geojson_layer,
    share_class,
    summary_frame,
)
from predisat.availability.satellites import LinePositions, SatellitePositions
from predisat.geodesy import geodetic_to_ecef
from predisat.gnss.ephemeris import EphemerisStatus, Reason
from predisat.masks.maskset import MaskSet
from predisat.track.map import demo_track

STEP_S = 600.0
T0 = 1277078400.0  # 2020-06-25 00:00 GPST
LEAP_S = 18.0  # GPS - UTC since 2017 (IERS Bulletin C)
CH = 4000.0 + 10.0 * np.arange(10)


@pytest.fixture(scope="module")
def track():
    return demo_track()


def _result(track, rule: str, count: np.ndarray, opening: float = 170.0) -> Availability:
    pos = LinePositions.from_track(track, CH, 4.0)
    n_pos, n_ep = count.shape
    interval = np.where(count >= 2, 40.0 + count, np.nan).astype(np.float32)
    return Availability(
        pos, T0 + STEP_S * np.arange(n_ep), ("G01", "G02"), rule, count.astype(np.uint8),
        interval, np.full(count.shape, 0.5, np.float32), np.full(n_pos, opening), {},
    )  # fmt: skip


def _masks_counts() -> np.ndarray:
    c = np.zeros((10, 4), int)
    c[:5] = [6, 6, 3, 3]  # share >= 4: 0.5, >= 6: 0.5
    c[5:] = 4  # share >= 4: 1, >= 6: 0
    return c


@pytest.fixture(scope="module")
def results(track):
    return (
        _result(track, "masks", _masks_counts(), 150.0),
        _result(track, "no mask", np.full((10, 4), 9), 180.0),
        _result(track, "cutoff 15 deg", np.full((10, 4), 7), 150.0),
    )


@pytest.fixture(scope="module")
def masks(track):
    return MaskSet.from_track(track, CH, np.full((10, 72), 10.0), margin_deg=1.0)


@pytest.fixture(scope="module")
def satellites(track):
    """Two satellites fixed in the sky of the first position: (90, 30) and (200, 60) deg."""
    pos = LinePositions.from_track(track, CH[:1], 4.0)
    rx = geodetic_to_ecef(pos.lat_deg[0], pos.lon_deg[0], pos.h_m[0])
    from predisat.geodesy import enu_rotation

    rot = enu_rotation(pos.lat_deg[0], pos.lon_deg[0])
    az, el = np.radians([90.0, 200.0]), np.radians([30.0, 60.0])
    unit = np.c_[np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)]
    enu = 2.02e7 * unit
    sat = rx + enu @ rot  # ENU -> ECEF (rotation is ECEF-to-ENU)
    p = np.repeat(sat[None], 4, axis=0)
    reason = np.zeros((4, 2), np.int8)
    reason[3, 1] = Reason.UNHEALTHY
    p[3, 1] = np.nan
    gps_s = T0 + STEP_S * np.arange(4)
    status = EphemerisStatus(gps_s, ("G01", "G02"), reason, np.full((4, 2), "", object))
    return SatellitePositions(gps_s, ("G01", "G02"), p, status)


class _Collect(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.rows: list[list[str]] = []
        self._row: list[str] | None = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs) -> None:
        self.tags.append((tag, dict(attrs)))
        if tag == "tr":
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag) -> None:
        if tag in ("td", "th") and self._row is not None and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.rows.append(self._row)
            self._row = None

    def handle_data(self, data) -> None:
        if self._cell is not None:
            self._cell.append(data)


# ----------------------------------------------------------------------------- report
def test_report_table_values_and_no_external_resources(results, masks, satellites, track):
    inputs = ReportInputs(
        results, masks, satellites, track, {"line": "test line", "rules": ["masks"]},
        sky_chainage_m=(CH[0], CH[7]), files={"geojson": "availability.geojson"},
    )  # fmt: skip
    text = build_report(inputs)
    p = _Collect()
    p.feed(text)
    rows = {r[0]: r for r in p.rows if r}
    # masks: >= 2 always; >= 4 in 30 of 40 cells; >= 6 in 10; cells are all 10 m long
    assert rows["masks"][1:4] == ["100.0 %", "75.0 %", "25.0 %"]
    # the 5 first positions are below 4 together at epochs 2-3: 50 m, 2 epochs = 20 min
    assert rows["masks"][5:7] == ["50 m", "20 min"]
    # the verdict says when (epoch 2, UTC) and where (position 0) those stretches are
    utc = datetime(1980, 1, 6) + timedelta(seconds=T0 + 2 * STEP_S - LEAP_S)
    assert f"50 m ({utc:%Y-%m-%d %H:%M:%S} UTC)" in text
    km = float(track.kilometre_at(CH[0])) / 1000.0  # position 0, from the track's km posts
    # kilometre posts first, chainage beside
    assert f"20 min (km {km:.3f} (chainage {CH[0] / 1000:.3f} km))" in text
    assert rows["no mask"][2] == "100.0 %" and rows["cutoff 15 deg"][3] == "100.0 %"
    assert any(k.startswith("LOCOPROL") for k in rows)
    assert "test line" in text
    assert "UNHEALTHY" in text and "G02" in text
    imgs = [a["src"] for t, a in p.tags if t == "img"]
    assert len(imgs) == 6  # map, availability, counts, sky, opening, interval
    for src in imgs:
        assert base64.b64decode(src.split(",", 1)[1])[:4] == b"\x89PNG"
    assert not re.search(r"""(src|href)\s*=\s*["'](https?:|//)""", text)
    assert "<script" not in text


def test_report_needs_masks_first_and_shared_positions(results, masks, satellites, track):
    with pytest.raises(ValueError, match="must be the masks rule"):
        build_report(ReportInputs(results[1:], masks, satellites, track))
    short = _result(track, "no mask", np.full((10, 4), 9))
    short = Availability(
        short.positions.take(np.arange(5)), short.gps_s, short.sats, "no mask",
        short.count[:5], None, None, short.opening_angle_deg[:5],
    )  # fmt: skip
    with pytest.raises(ValueError, match="must share their positions"):
        build_report(ReportInputs((results[0], short), masks, satellites, track))


def test_summary_frame_rows(results):
    df = summary_frame(results)
    assert list(df["rule"]) == ["masks", "no mask", "cutoff 15 deg"]
    assert df.loc[0, "share_ge4"] == pytest.approx(0.75)
    assert df.loc[0, "longest_below4_m"] == pytest.approx(50.0)


def test_percentages_round_down():
    from predisat.availability.report import _pct

    assert _pct(0.9996) == "99.9 %" and _pct(1.0) == "100.0 %" and _pct(0.95) == "95.0 %"


def test_share_classes():
    assert share_class(1.0)[1] == SHARE_CLASSES[0][2]
    assert share_class(0.97)[0] == "95-99 %"
    assert share_class(0.95)[0] == "95-99 %"
    assert share_class(0.5)[0] == "< 80 %"


def test_geojson_layer_properties(results, track):
    fc = geojson_layer(results, track)
    assert len(fc["features"]) == 10
    for i, f in enumerate(fc["features"]):
        props = f["properties"]
        want4 = 0.5 if i < 5 else 1.0
        assert props["share_ge4"] == pytest.approx(want4)
        assert props["stroke"] == ("#b2182b" if i < 5 else "#2166ac")
        assert props["share_ge4_no_mask"] == 1.0 and props["share_ge6_cutoff_15_deg"] == 1.0
        assert props["rule"] == "masks"
        # the line's kilometre, as positions.csv gives it (the demo line's posts)
        assert props["line_km"] == pytest.approx(float(track.kilometre_at(CH[i])) / 1000.0)


# ----------------------------------------------------------------------------- plots
def test_sky_plot_places_satellites(satellites, masks, track):
    from predisat.availability.satellites import TrustRule, azel

    pos = LinePositions.from_track(track, CH[:1], 4.0)
    az, el = azel(pos.ecef_m[0], pos.enu_rotation[0], satellites.pos_ecef_m)
    trusted = TrustRule.mask(masks).trusted(CH[0], az, el)
    view = plots.SkyView(
        "t", 90.0, 5.0, np.full(72, 10.0), np.full(72, 1.0), az, el, trusted, ("G01", "G02"),
        (15.0,),
    )  # fmt: skip
    fig = plots.sky_plots([view])
    ax: Any = fig.axes[0]
    assert ax.name == "polar"
    assert ax.get_theta_direction() == -1  # clockwise
    assert ax.get_theta_offset() == pytest.approx(np.pi / 2)  # north up
    blue = [ln for ln in ax.get_lines() if to_rgba(ln.get_color()) == to_rgba("#1f5fa8")]
    pts = np.concatenate([np.c_[ln.get_xdata(), ln.get_ydata()] for ln in blue])
    pts = pts[np.isfinite(pts).all(axis=1)]
    # zenith at the centre: r = 90 - el
    assert np.any(np.hypot(pts[:, 0] - np.pi / 2, pts[:, 1] - 60.0) < 1e-3)
    assert np.any(np.hypot(pts[:, 0] - np.radians(200.0), pts[:, 1] - 30.0) < 1e-3)


def test_sky_view_checks_shapes():
    with pytest.raises(ValueError, match="share one shape"):
        plots.SkyView("t", 0.0, 5.0, None, None, np.zeros((3, 2)), np.zeros((3, 1)),
                      np.zeros((3, 2), bool), ("a", "b"))  # fmt: skip


def test_count_map_image_and_classes(results, track):
    fig = plots.count_maps(results, track.kilometre_posts)
    image_axes = [ax for ax in fig.axes if ax.get_images()]
    assert len(image_axes) == 3
    im = image_axes[0].get_images()[0]
    np.testing.assert_array_equal(np.asarray(im.get_array()), _masks_counts().T)
    for count, cls in ((0, 0), (1, 0), (3, 1), (5, 2), (6, 3), (11, 3)):
        level = np.asarray(im.norm(np.array([count])))[0]
        assert im.cmap(level) == to_rgba(plots.COUNT_CLASSES[cls][3])


def test_count_map_keeps_the_worst_count_of_each_block(track):
    rng = np.random.default_rng(3)
    count = rng.integers(0, 10, size=(10, 1500))
    fig = plots.count_maps([_result(track, "masks", count)])
    im = next(ax for ax in fig.axes if ax.get_images()).get_images()[0]
    # 1500 epochs > 720 drawn: blocks of 3 epochs, each shown with its lowest count
    want = count.reshape(10, 500, 3).min(axis=2)
    np.testing.assert_array_equal(np.asarray(im.get_array()), want.T)


def test_along_line_figures(results, track):
    fig = plots.availability_along_line(results, track.kilometre_posts)
    top = fig.axes[0]
    lines = {ln.get_label(): ln for ln in top.get_lines()}
    np.testing.assert_allclose(
        np.asarray(lines["masks"].get_ydata(), float), np.repeat([50.0, 100.0], 5)
    )
    np.testing.assert_allclose(np.asarray(lines["masks"].get_xdata(), float), CH / 1000.0)
    fig = plots.opening_angle_along_line(results)
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    np.testing.assert_allclose(np.asarray(lines["no mask"].get_ydata(), float), 180.0)
    fig = plots.interval_along_line(results)
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    # masks: epochs with >= 4 have counts 6, 6 (pos 0-4) or 4 (pos 5-9); interval = 40 + count
    np.testing.assert_allclose(
        np.asarray(lines["masks (median)"].get_ydata(), float), np.repeat([46.0, 44.0], 5)
    )
    assert plots.figure_to_png(fig)[:4] == b"\x89PNG"


def test_lengths_in_the_report_are_rounded_up() -> None:
    """A user trial read a predicted interval of 103.498 m as "103 m": shorter than it is."""
    from predisat.availability.report import _num

    assert _num(103.498, "m") == "104 m"
    assert _num(100.0, "m") == "100 m"
    assert _num(1234.01, "m", 1) == "1 234.1 m"
    assert _num(float("nan"), "m") == "–"
