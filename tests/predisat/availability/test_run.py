"""Tests of predisat.availability.run: the availability command's orchestration and outputs."""

from __future__ import annotations

import argparse
import dataclasses
import html
import json
import re
import warnings
from datetime import datetime, timedelta, timezone
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from pyproj import Transformer

from predisat.availability.run import (
    load_navigation,
    nav_span_gps_s,
    parse_time,
    run_availability,
)
from predisat.availability.satellites import default_ephemeris
from predisat.cli.availability import add_arguments
from predisat.cli.availability import run as run_from_args
from predisat.masks.fileformat import MaskFileError, write_masks
from predisat.masks.maskset import MaskSet
from predisat.track.map import TrackMap, demo_track

STEP_DEG = 5.0
START = "2020-06-25T06:00"
END = "2020-06-25T08:00"
STEP_S = 300.0
WALL = (4200.0, 4300.0)  # chainage of a 60 deg wall on the left
GPS_EPOCH = datetime(1980, 1, 6)


def _synthetic_masks(track: TrackMap) -> MaskSet:
    """5 deg everywhere, a 60 deg wall over +-60 deg around the left normal inside WALL."""
    ch = np.arange(4000.0, 4400.1, 20.0)
    heading = track.heading_at(ch)
    az = np.arange(round(360 / STEP_DEG)) * STEP_DEG
    rel = (az[None, :] - (heading[:, None] - 90.0) + 180.0) % 360.0 - 180.0
    wall = (ch[:, None] >= WALL[0]) & (ch[:, None] <= WALL[1]) & (np.abs(rel) <= 60.0)
    mask = np.where(wall, 60.0, 5.0)
    return MaskSet.from_track(track, ch, mask, az_step_deg=STEP_DEG, margin_deg=1.0)


def _said(warnings: list[str]) -> list[str]:
    """The warnings other than the coarse sampling's (most tests sample a few epochs)."""
    return [w for w in warnings if " s apart: the shares of time are of these" not in w
            and "the interval lengths rest on" not in w]  # fmt: skip


@pytest.fixture(scope="module")
def track() -> TrackMap:
    return demo_track()


@pytest.fixture(scope="module")
def masks(track: TrackMap) -> MaskSet:
    return _synthetic_masks(track)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory, track: TrackMap, masks: MaskSet):
    tmp = tmp_path_factory.mktemp("avail")
    path = write_masks(masks, tmp / "synthetic.masks.parquet")
    return run_availability(
        path, track, None, out_dir=tmp / "out", start=START, end=END, step_s=STEP_S,
        constellation="gps", cutoff_deg=15.0, n_sky=2, interval_every=1, progress=False,
        counts_table=True,
    )  # fmt: skip


class _Collect(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.rows: list[list[str]] = []
        self._row: list[str] | None = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        if tag == "tr":
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._row is not None and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.rows.append(self._row)
            self._row = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def _gps_s(dt: datetime) -> float:
    return (dt - GPS_EPOCH).total_seconds()


def _independent_azel(lat: float, lon: float, h: float, sat_ecef: np.ndarray):
    """Azimuth/elevation with PROJ's topocentric conversion (independent of predisat)."""
    tr = Transformer.from_pipeline(
        f"+proj=topocentric +ellps=WGS84 +lat_0={lat} +lon_0={lon} +h_0={h}"
    )
    e, n, u = tr.transform(sat_ecef[..., 0], sat_ecef[..., 1], sat_ecef[..., 2])
    az = np.degrees(np.arctan2(e, n)) % 360.0
    el = np.degrees(np.arctan2(u, np.hypot(e, n)))
    return az, el


# ----------------------------------------------------------------------------- outputs
def test_every_listed_file_is_described(run) -> None:
    html = run.report_html.read_text()
    assert "ephemeris_status.csv</code></a> – each run of epochs" in html
    assert not any(f"– {key}" in html for key in ("ephemeris_status_csv", "summary_csv"))
    # every listed file is a link to a file the run wrote beside the report
    for name in re.findall(r'<a href="([^"]+)">', html):
        assert (run.report_html.parent / name).is_file(), name


def test_html_is_self_contained_with_table_and_images(run) -> None:
    text = run.report_html.read_text(encoding="utf-8")
    p = _Collect()
    p.feed(text)
    names = [t for t, _ in p.tags]
    assert "script" not in names and "link" not in names and "iframe" not in names
    for _, attrs in p.tags:
        for key in ("src", "href"):
            v = attrs.get(key)
            if v is not None:
                assert not v.lower().startswith(("http:", "https:", "//", "ftp:")), v
    assert "url(" not in text  # no CSS-loaded resources
    imgs = [a["src"] for t, a in p.tags if t == "img"]
    assert len(imgs) >= 5
    import base64

    for src in imgs:
        assert src is not None and src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    first = [r[0] for r in p.rows if r]
    for rule in ("masks", "no mask", "cutoff 15 deg"):
        assert rule in first
    assert any(c.startswith("LOCOPROL") for c in first)
    assert "line 144" in text and "2020-06-25 06:00:00" in text


def test_summary_row_matches_positions_table(run, masks: MaskSet) -> None:
    summ = pd.read_csv(run.files["summary_csv"])
    pos = pd.read_csv(run.files["positions_csv"])
    assert list(summ["rule"]) == ["masks", "no mask", "cutoff 15 deg"]
    assert len(pos) == 3 * masks.n_pos
    for rule, g in pos.groupby("rule"):
        # line share = cell-length-weighted mean of the per-position shares (independent cells)
        s = g["chainage_m"].to_numpy()
        mid = (s[1:] + s[:-1]) / 2
        edges = np.concatenate([[s[0] - (mid[0] - s[0])], mid, [s[-1] + (s[-1] - mid[-1])]])
        w = np.diff(edges)
        want = np.sum(g["share_ge4"].to_numpy() * w) / np.sum(w)
        got = float(summ.loc[summ["rule"] == rule, "share_ge4"].iloc[0])
        assert got == pytest.approx(want, abs=1e-6)
    # the wall must cost satellites against no mask (and never add any)
    m = pos[pos["rule"] == "masks"].set_index("chainage_m")
    n = pos[pos["rule"] == "no mask"].set_index("chainage_m")
    assert (m["mean_count"] <= n["mean_count"] + 1e-9).all()
    inside = (m.index >= WALL[0]) & (m.index <= WALL[1])
    outside = ~inside
    assert m["mean_count"][inside].mean() < m["mean_count"][outside].mean() - 1.0


def test_counts_match_an_independent_computation(run, masks: MaskSet) -> None:
    t = np.arange(_gps_s(datetime(2020, 6, 25, 6)), _gps_s(datetime(2020, 6, 25, 8)), STEP_S)
    eph = default_ephemeris()
    gps = [s for s in eph.satellites if s.startswith("G")]
    sat = eph.position_ecef(t, gps)  # (n_ep, n_sat, 3), NaN where not trusted
    counts = pq.read_table(run.files["counts_parquet"]).to_pandas()
    for i in (0, 11):  # outside and inside the wall
        ch = float(masks.chainage_m[i])
        az, el = _independent_azel(masks.lat_deg[i], masks.lon_deg[i], masks.h_m[i], sat)
        k = np.floor(np.nan_to_num(az) / STEP_DEG + 0.5).astype(int) % round(360 / STEP_DEG)
        thr = masks.mask_el_deg[i][k] + masks.margin_deg[i][k]
        want = {
            "no mask": np.sum(np.nan_to_num(el, nan=-99) > 0.0, axis=1),
            "cutoff 15 deg": np.sum(np.nan_to_num(el, nan=-99) > 15.0, axis=1),
            "masks": np.sum(np.nan_to_num(el, nan=-99) > thr, axis=1),
        }
        for rule, w in want.items():
            got = counts[(counts["rule"] == rule) & np.isclose(counts["chainage_m"], ch)]
            got = got.sort_values("gps_s")
            np.testing.assert_allclose(got["gps_s"].to_numpy(), t)
            np.testing.assert_array_equal(got["count"].to_numpy(), w, err_msg=f"{rule} {ch}")


def test_parquet_equals_csv(run) -> None:
    for name in ("positions", "epochs"):
        a = pd.read_csv(run.files[f"{name}_csv"])
        b = pq.read_table(run.files[f"{name}_parquet"]).to_pandas()
        assert list(a.columns) == list(b.columns)
        num = [c for c in a.columns if pd.api.types.is_float_dtype(b[c])]
        np.testing.assert_allclose(a[num].to_numpy(), b[num].to_numpy(), rtol=1e-10, atol=1e-9)
        meta = pq.read_schema(run.files[f"{name}_parquet"]).metadata
        assert b"predisat.availability.run" in meta


def test_geojson_follows_the_track(run, track: TrackMap, masks: MaskSet) -> None:
    fc = json.loads(run.files["geojson"].read_text())
    assert fc["type"] == "FeatureCollection"
    assert len(fc["features"]) == masks.n_pos
    s = masks.chainage_m
    edges = np.concatenate([[s[0] - 10.0], (s[1:] + s[:-1]) / 2, [s[-1] + 10.0]])
    for i, f in enumerate(fc["features"]):
        assert f["geometry"]["type"] == "LineString"
        props = f["properties"]
        assert 0.0 <= props["share_ge4"] <= 1.0
        assert props["stroke"].startswith("#") and "share_ge4_no_mask" in props
        xy = np.asarray(f["geometry"]["coordinates"])
        lat, lon, _ = track.position_at(np.linspace(edges[i], edges[i + 1], len(xy)))
        np.testing.assert_allclose(xy[:, 0], lon, atol=1e-9)
        np.testing.assert_allclose(xy[:, 1], lat, atol=1e-9)


# ----------------------------------------------------------------------------- errors
def test_missing_masks_file_names_it(tmp_path: Path) -> None:
    missing = tmp_path / "nope.masks.parquet"
    with pytest.raises(MaskFileError, match=r"nope\.masks\.parquet: no such mask file"):
        run_availability(missing, None, None, out_dir=tmp_path / "o", progress=False)


def test_missing_nav_file_names_it(tmp_path: Path, masks: MaskSet) -> None:
    with pytest.raises(FileNotFoundError, match=r"nav file .*brdc9999\.20n \(--nav\).*embedded"):
        run_availability(
            masks, None, [tmp_path / "brdc9999.20n"], out_dir=tmp_path / "o", progress=False
        )


def test_window_outside_nav_data(tmp_path: Path, masks: MaskSet) -> None:
    # "lies", "lie" as the subject asks (was "lie(s)")
    with pytest.raises(ValueError, match=r"^the window lies outside the navigation data.*ESBC00DNK"
                       r".*--start"):  # fmt: skip
        run_availability(
            masks, None, None, out_dir=tmp_path / "o", start="2021-01-01T00:00",
            end="2021-01-01T01:00", step_s=600, progress=False,
        )  # fmt: skip
    # partly outside: the end runs past the data
    with pytest.raises(ValueError, match=r"epochs \(.*\) lie outside the navigation data"):
        run_availability(
            masks, None, None, out_dir=tmp_path / "o", start="2020-06-25T23:00",
            end="2020-06-26T04:00", step_s=600, progress=False,
        )  # fmt: skip


def test_masks_on_another_track_are_refused(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    # the same line moved 0.005 deg north (about 550 m)
    other = TrackMap.from_latlon(track.lat_deg + 0.005, track.lon_deg, track.h_m, name="moved")
    with pytest.raises(ValueError, match="do not fit track"):
        run_availability(masks, other, None, out_dir=tmp_path / "o", progress=False)


def test_masks_on_another_map_of_the_line_are_registered_and_said(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    """Another map of the same track (its vertices every 25 m from chainage 3000 m: chainages
    3 km lower and a little shorter, positions apart on the curves): the masks are put on it
    by position, never trust more than on their own map, and the report says so."""
    s = np.arange(3000.0, 5001.0, 25.0)
    lat, lon, h = track.position_at(s)
    other = TrackMap.from_latlon(lat, lon, h, name="resampled")
    common = dict(start=START, end="2020-06-25T06:30", step_s=900, n_sky=1, progress=False)
    run_availability(masks, track, None, out_dir=tmp_path / "own",
                           **common)  # type: ignore[arg-type]  # fmt: skip
    r = run_availability(masks, other, None, out_dir=tmp_path / "other",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (said,) = _said(r.info["warnings"])
    assert "another map of this line than 'resampled'" in said and "re-registered" in said
    summary = json.loads((tmp_path / "other" / "summary.json").read_text())
    assert _said(summary["run"]["warnings"]) == [said]
    assert "stretch" in summary["run"] and "chainage 1.0" in summary["run"]["stretch"]
    mine = json.loads((tmp_path / "own" / "summary.json").read_text())["summary"][0]
    theirs = summary["summary"][0]
    for k in ("share_ge2", "share_ge4", "share_ge6"):
        assert theirs[k] <= mine[k] + 1e-9
    assert 'class="warn"' in r.report_html.read_text(encoding="utf-8")


def test_masks_beside_the_map_as_another_tracks_are_refused_unless_said_same_track(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    """The same axis moved 4 m sideways (the other track of a double line, or a map of this
    track 4 m off): refused by default, registered with ``masks_same_track``, and said."""
    from predisat.masks.registration import OtherTrackError

    s = np.arange(3000.0, 5001.0, 10.0)
    lat, lon, h = track.position_at(s)
    north = np.radians(track.heading_at(s))  # 4 m to the left of the direction of travel
    lat = lat + 4.0 * np.sin(north) / 111_200.0
    lon = lon - 4.0 * np.cos(north) / (111_200.0 * np.cos(np.radians(lat)))
    other = TrackMap.from_latlon(lat, lon, h, name="track B")
    common = dict(start=START, end="2020-06-25T06:30", step_s=900, n_sky=1, progress=False)
    with pytest.raises(OtherTrackError, match=r"lie 4\.0 m right of track 'track B'"):
        run_availability(masks, other, None, out_dir=tmp_path / "b",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    assert not (tmp_path / "b" / "report.html").exists()
    r = run_availability(masks, other, None, out_dir=tmp_path / "b", masks_same_track=True,
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (said,) = _said(r.info["warnings"])
    assert "4.0 m beside it (the median): taken as the same physical track, as asked" in said
    # the command line: refused by default, the option says it
    path = write_masks(masks.subset(3000.0, 5000.0), tmp_path / "m.masks.parquet")
    parser = add_arguments(argparse.ArgumentParser())
    base = ["--masks", str(path), "--start", START, "--end", "2020-06-25T06:30", "--step",
            "900", "--quiet", "--scheduler", "serial"]  # fmt: skip
    with pytest.raises(OtherTrackError):
        run_from_args(parser.parse_args([*base, "--out", str(tmp_path / "c1")]), other)
    run_from_args(parser.parse_args([*base, "--masks-same-track", "--out", str(tmp_path / "c2")]),
                  other)  # fmt: skip
    assert (tmp_path / "c2" / "report.html").is_file()


def test_one_position_sky_in_a_tagged_tunnel_and_masks_off_the_embedded_map_are_said(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    """A user trial: a one-position file wrote NaN shares; flat masks over a map's tunnels
    read 100 % unwarned; masks named after the embedded line but off it lost their kilometre
    posts without a word."""
    from dataclasses import replace

    common = dict(start=START, end="2020-06-25T06:30", step_s=900, n_sky=1, progress=False)
    with pytest.raises(ValueError, match=r"hold one position.*at least two positions"):
        run_availability(masks.subset(4000.0, 4000.0), track, None, out_dir=tmp_path / "one",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    with pytest.raises(ValueError, match=r"hold one position .* in the stretch asked"):
        run_availability(masks, track, None, out_dir=tmp_path / "one", from_m=4000.0,
                         to_m=4005.0, **common)  # type: ignore[arg-type]  # fmt: skip
    tunnel = replace(track, tunnels_m=((4050.0, 4400.0),))
    r = run_availability(masks, tunnel, None, out_dir=tmp_path / "t",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (said,) = _said(r.info["warnings"])
    assert "trust some sky at 8 of 8 positions" in said and "tags as tunnel" in said
    closed = masks.with_margin(0.0)
    closed = replace(closed, mask_el_deg=np.where(
        (closed.chainage_m >= 4150.0)[:, None], np.float32(90.0), closed.mask_el_deg))
    r = run_availability(closed, tunnel, None, out_dir=tmp_path / "c",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    assert _said(r.info["warnings"]) == []
    # named after the embedded line, 3 km off it: its own chainages, and said
    lat, lon, _ = track.position_at(masks.chainage_m + 3000.0)
    off = replace(masks, lat_deg=lat, lon_deg=lon,
                  provenance={**masks.provenance, "track": track.name})  # fmt: skip
    r = run_availability(off, None, None, out_dir=tmp_path / "o",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    assert any("no map of it was given" in w for w in r.info["warnings"])


def test_coarse_sampling_is_said() -> None:
    from predisat.availability.run import sampling_notes

    assert sampling_notes(2880, 30.0, 10) == []
    (coarse,) = sampling_notes(1, 86400.0, 1)[:1]
    assert coarse.startswith("1 epoch 86400 s apart: the shares of time are of these instants")
    assert len(sampling_notes(24, 3600.0, 1)) == 2
    (few,) = sampling_notes(2880, 30.0, 1000)
    assert few.startswith("the interval lengths rest on 3 epochs (--interval-every 1000)")


def test_the_default_window_follows_the_counted_system(
    tmp_path: Path, masks: MaskSet, track: TrackMap, shared_data: Path
) -> None:
    """A user trial: NYA1's daily GPS, Galileo and BeiDou files with the default GPS count;
    the window started at the Galileo records of the day before, where GPS has none, and the
    run was refused as a gap in the data."""
    from predisat.availability.run import _default_start, load_navigation

    d = shared_data / "gnss" / "georust_rinex"
    nav = [d / f"NYA100NOR_S_20241240000_01D_{k}N.rnx.gz" for k in "GEC"]
    eph = load_navigation(nav)
    assert _default_start(eph, False, {"G"}) > _default_start(eph, False, None)
    r = run_availability(masks, track, nav, out_dir=tmp_path / "o", step_s=3600.0,
                         progress=False)  # fmt: skip
    assert r.results[0].gps_s.size >= 20 and r.results[0].sats[0].startswith("G")


def test_holes_in_the_navigation_data_are_said(
    tmp_path: Path, masks: MaskSet, track: TrackMap, shared_data: Path
) -> None:
    """A user trial: an SP3 file with satellites zeroed for 13 h, and all constellations
    counted from a window where GPS had no records yet, were said only in the folded files
    section."""
    src = shared_data / "gnss" / "rtklib" / "igs15904.sp3"
    lines = src.read_text().splitlines(keepends=True)
    stars = [i for i, ln in enumerate(lines) if ln.startswith("*")]
    # G05 zeroed (SP3's "no position") for 3 h (12 epochs at 15 min) from 10:00
    holed = [ln if not (ln.startswith("PG05") and stars[40] < i < stars[52])
             else "PG05      0.000000      0.000000      0.000000 999999.999999\n"
             for i, ln in enumerate(lines)]  # fmt: skip
    (tmp_path / "holed.sp3").write_text("".join(holed))
    common = dict(step_s=900.0, progress=False)
    r = run_availability(masks, track, [src], out_dir=tmp_path / "a",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    assert not [w for w in r.info["warnings"] if "no usable record" in w]
    r = run_availability(masks, track, [tmp_path / "holed.sp3"], out_dir=tmp_path / "b",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (hole,) = [w for w in r.info["warnings"] if "no usable record" in w]
    assert "of 1 satellite(s)" in hole and "G05 (" in hole
    # NYA1's three daily files counted together: the default window starts where every
    # counted system has records; one asked from Galileo's records of the day before, where
    # GPS and BeiDou have none, is said
    d = shared_data / "gnss" / "georust_rinex"
    nav = [d / f"NYA100NOR_S_20241240000_01D_{k}N.rnx.gz" for k in "GEC"]
    r = run_availability(masks, track, nav, out_dir=tmp_path / "c", constellation="all",
                         step_s=3600.0, progress=False)  # fmt: skip
    assert not [w for w in r.info["warnings"] if "holds no usable" in w]
    r = run_availability(masks, track, nav, out_dir=tmp_path / "d", constellation="all",
                         start="2024-05-02T23:20", end="2024-05-03T03:00", step_s=600.0,
                         progress=False)  # fmt: skip
    said = [w for w in r.info["warnings"] if "holds no usable" in w]
    assert any("GPS satellite in" in w for w in said), said


def test_sky_km_outside_the_stretch(tmp_path: Path, masks: MaskSet, track: TrackMap) -> None:
    with pytest.raises(ValueError, match=r"sky_km \(--sky-km\) \[9\.0\] outside"):
        run_availability(masks, track, None, out_dir=tmp_path / "o", sky_km=[9.0],
                         progress=False)  # fmt: skip


def test_stretch_given_in_metres_or_reversed(tmp_path: Path, masks: MaskSet) -> None:
    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    parser = add_arguments(argparse.ArgumentParser())
    for km, expected in (
        (["6", "4"], "the start must be below the end"),
        (["4000", "4100"], r"no position of masks .*m\.masks\.parquet, which cover 4-4\.1 km"),
    ):
        args = parser.parse_args(["--masks", str(path), "--out", str(tmp_path / "o"),
                                  "--from-km", km[0], "--to-km", km[1], "--quiet"])  # fmt: skip
        with pytest.raises(ValueError, match=expected):
            run_from_args(args)
    args = parser.parse_args(["--masks", str(path), "--out", str(tmp_path / "o"),
                              "--from-km", "7", "--quiet"])  # fmt: skip
    with pytest.raises(ValueError, match=r"^from_m 7000 m \(--from-km 7\): no position") as exc:
        run_from_args(args)
    assert "inf" not in str(exc.value)
    assert not (tmp_path / "o").exists()


def test_a_stretch_beyond_the_masks_or_a_hole_in_them_is_said_in_the_report(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    from predisat.masks.maskset import concat_masksets

    common = dict(start=START, end="2020-06-25T06:30", step_s=900, n_sky=1, progress=False)
    part = masks.subset(4000.0, 4100.0)
    r = run_availability(part, track, None, out_dir=tmp_path / "a", from_m=3000.0, to_m=4050.0,
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (beyond,) = _said(r.info["warnings"])
    assert beyond.startswith("--from-km 3 (chainage km) lies beyond masks in memory")
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert _said(summary["run"]["warnings"]) == [beyond]
    # a file with a hole: closed on reading, said in the report (not only a Python warning),
    # and the positions closing it lie on the track (the track check accepts them)
    joined = concat_masksets([masks.subset(4000.0, 4100.0), masks.subset(4300.0, 4400.0)])
    # in memory too: the hole is closed and said
    r = run_availability(joined, track, None, out_dir=tmp_path / "m",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (hole,) = _said(r.info["warnings"])
    assert hole.startswith("masks in memory: 1 hole(s) between positions (4100-4300 m)")
    holed = write_masks(joined, tmp_path / "h.parquet")
    r = run_availability(holed, track, None, out_dir=tmp_path / "h",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (hole,) = _said(r.info["warnings"])
    assert "1 hole(s)" in hole and "4100-4300 m" in hole
    assert 'class="warn"' in r.report_html.read_text(encoding="utf-8")


def test_bad_step_and_reversed_window(tmp_path: Path, masks: MaskSet) -> None:
    with pytest.raises(ValueError, match=r"step_s \(--step\)"):
        run_availability(masks, None, None, out_dir=tmp_path / "o", step_s=0, progress=False)
    with pytest.raises(ValueError, match=r"end \(.*--end\) must be after start \(.*--start\)"):
        run_availability(masks, None, None, out_dir=tmp_path / "o", start=START, end=START,
                         progress=False)  # fmt: skip


# ----------------------------------------------------------------------------- inputs
def test_parse_time_scales() -> None:
    gpst = _gps_s(datetime(2020, 6, 25, 6))
    assert parse_time("2020-06-25T06:00", "--start") == pytest.approx(gpst)
    assert parse_time("2020-06-25 06:00:00", "--start") == pytest.approx(gpst)
    # GPST - UTC = 18 s in 2020 (IERS Bulletin C): a UTC instant is 18 s later in GPS time
    assert parse_time("2020-06-25T06:00Z", "--start") == pytest.approx(gpst + 18.0)
    assert parse_time("2020-06-25T06:00 utc", "--start") == pytest.approx(gpst + 18.0)
    aware = datetime(2020, 6, 25, 8, tzinfo=timezone(timedelta(hours=2)))
    assert parse_time(aware, "--start") == pytest.approx(gpst + 18.0)
    # local time with its offset, as text: the same UTC instant (it read as GPS time, 18 s off)
    for text in ("2020-06-25T08:00+02:00", "2020-06-25 08:00:00+0200", "2020-06-25T05:00-01:00",
                 "2020-06-25T08:00+02"):  # fmt: skip
        assert parse_time(text, "--start") == pytest.approx(gpst + 18.0), text
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's timezone notice must not leak
        with pytest.raises(ValueError, match="zone names such as CEST are not read"):
            parse_time("2020-06-25T08:00 CEST", "--start")
    assert parse_time("1277445600", "--start") == 1277445600.0
    assert parse_time(None, "--end") is None
    with pytest.raises(ValueError, match="--end 'tomorrow' is not a time"):
        parse_time("tomorrow", "--end")


@pytest.mark.parametrize(
    ("name", "kind", "first"),
    [
        ("igs15904_G01G02G05.sp3", "sp3", datetime(2010, 7, 1)),
        ("brdc1820_G01G02G05.10n", "broadcast", datetime(2010, 7, 1)),
        ("TLE_GNSS_20121101.txt", "tle", None),
    ],
)
def test_navigation_kind_by_content(test_data, name: str, kind: str, first) -> None:
    eph = load_navigation([test_data / "gnss" / name])
    assert eph.kind == kind
    lo, hi = nav_span_gps_s(eph)
    assert lo < hi
    if first is not None:
        assert lo == pytest.approx(_gps_s(first), abs=3600.0)


def test_unknown_nav_file_is_refused(tmp_path: Path) -> None:
    f = tmp_path / "notes.txt"
    f.write_text("hello\nworld\n")
    with pytest.raises(ValueError, match="not a RINEX navigation, SP3 or TLE file"):
        load_navigation([f])


def test_sp3_window_defaults_inside_the_file(tmp_path: Path, masks: MaskSet, test_data) -> None:
    # 3 satellites, 2010-07-01 00:00-07:45: the default window must start at the file's start
    small = masks.subset(4000.0, 4060.0)
    r = run_availability(
        small, None, [test_data / "gnss" / "igs15904_G01G02G05.sp3"], out_dir=tmp_path / "o",
        end="2010-07-01T01:00", step_s=900, n_sky=1, progress=False,
    )  # fmt: skip
    assert r.results[0].gps_s[0] == pytest.approx(_gps_s(datetime(2010, 7, 1)))
    assert len(r.results[0].gps_s) == 4
    assert r.results[1].count.max() <= 3
    # three satellites are not a constellation, and precise orbits hold no health flags:
    # both said in the run and at the top of the report
    sparse, health = _said(r.info["warnings"])
    assert "holds 3 GPS satellites" in sparse and "understated" in sparse
    assert "(sp3) carries no health flags" in health and "optimistic" in health
    assert 'class="warn"' in r.report_html.read_text(encoding="utf-8")


def test_full_navigation_day_gives_no_warning(run) -> None:
    # the embedded day (IGS Esbjerg, 2020-06-25) has the whole GPS constellation
    assert _said(run.info["warnings"]) == []
    page = run.report_html.read_text(encoding="utf-8")
    assert page.count('class="warn"') == len(run.info["warnings"])  # the sampling's only


def test_cli_arguments_round_trip(tmp_path: Path, masks: MaskSet, track: TrackMap) -> None:
    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    parser = add_arguments(argparse.ArgumentParser())
    args = parser.parse_args(
        ["--masks", str(path), "--out", str(tmp_path / "cli"), "--start", START, "--end",
         "2020-06-25T07:00", "--step", "600", "--cutoff", "10", "20", "--sky-km", "4.05",
         "--quiet"]
    )  # fmt: skip
    r = run_from_args(args, track=track)
    assert [x.rule for x in r.results] == ["masks", "no mask", "cutoff 10 deg", "cutoff 20 deg"]
    assert r.report_html.is_file() and (tmp_path / "cli" / "availability.geojson").is_file()
    # a higher cut-off can only remove satellites
    assert np.all(r.results[3].count <= r.results[2].count)


def test_interval_model_from_a_locator_error_model_file(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    from predisat.gnss.errormodel import ErrorModel, IntervalModel, write_error_model

    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    parser = add_arguments(argparse.ArgumentParser())
    base = ["--masks", str(path), "--start", START, "--end", "2020-06-25T07:00", "--step",
            "600", "--interval-every", "1", "--sky-km", "4.05", "--quiet",
            "--map-doubt", "0", "0"]  # fmt: skip (no map doubt: the lengths scale with sigma)
    k2 = [*base, "--k-sigma", "2"]
    default = run_from_args(parser.parse_args([*k2, "--out", str(tmp_path / "d")]), track)
    # sigma doubled everywhere (a = b = 4 m instead of 2 m): every interval exactly doubles
    model = write_error_model(tmp_path / "e.json", IntervalModel(ErrorModel(4.0, 4.0), 2.0))
    wide = run_from_args(
        parser.parse_args([*k2, "--error-model", str(model), "--out", str(tmp_path / "w")]),
        track,
    )
    k389 = run_from_args(
        parser.parse_args([*base, "--k-sigma", "3.89", "--out", str(tmp_path / "k")]), track
    )
    d, w, k = (r.results[0].interval_m for r in (default, wide, k389))
    assert np.isfinite(d).sum() > 10
    np.testing.assert_allclose(w, 2.0 * d, rtol=1e-5)
    np.testing.assert_allclose(k, 3.89 / 2.0 * d, rtol=1e-5)
    assert "k = 3.89 in every mode" in k389.report_html.read_text(encoding="utf-8")
    # the caption says which model made the intervals: the default is flagged as such
    captions = [html.unescape(r.report_html.read_text(encoding="utf-8"))
                for r in (default, wide, k389)]  # fmt: skip
    assert "source's default" in captions[0]
    assert "source's default" not in captions[1] and "Error model: sigma" in captions[1]
    assert "4.000² + (4.000 / sin el)²" in captions[1]
    # k = 3.89 with the default error model: the model is the default, the width named
    assert "source's default" in captions[2] and "k = 3.89 in every mode" in captions[2]
    # a track file given by the user is named in the footer (the test track has no attribution)
    assert f"Track: {track.name}" in captions[0]
    # the locator's default map doubt widens every pair, and the caption says so
    doubted = [a for a in k2 if a not in ("--map-doubt", "0")]
    located = run_from_args(parser.parse_args([*doubted, "--out", str(tmp_path / "m")]), track)
    x = located.results[0].interval_m
    assert np.array_equal(np.isfinite(x), np.isfinite(d)) and np.all(x[np.isfinite(d)] > d[
        np.isfinite(d)])  # fmt: skip
    caption = html.unescape(located.report_html.read_text(encoding="utf-8"))
    assert "widened for an antenna up to 1.5 m beside and 1 m above or below the map" in caption
    assert "no map doubt" in captions[0]
    # the run records the model's numbers, so a report can be made again
    run = json.loads((tmp_path / "w" / "summary.json").read_text())["run"]
    assert run["interval_model_params"] == {
        "a_m": 4.0, "b_m": 4.0, "min_el_deg": 1.0, "k_sigma": 2.0,
        "integrity_risk_per_epoch": None, "k_sigma_by_mode": None,
        "map_doubt_lateral_m": 0.0, "map_doubt_vertical_m": 0.0,
    }  # fmt: skip
    # and summary.csv, read alone, names the setting beside each rule's interval lengths
    table = pd.read_csv(tmp_path / "w" / "summary.csv")
    drawn = table["interval_median_m"].notna()
    assert drawn.any()
    assert (table.loc[drawn, "interval_error_a_m"] == 4.0).all()
    assert (table.loc[drawn, "interval_k_sigma"] == 2.0).all()
    assert table.loc[drawn, "interval_integrity_risk_per_epoch"].isna().all()
    doubted_table = pd.read_csv(tmp_path / "m" / "summary.csv")
    assert (doubted_table.loc[doubted_table["interval_median_m"].notna(),
                              "interval_map_doubt_lateral_m"] == 1.5).all()  # fmt: skip
    # a Parquet file: refused when read; a folder: by the parser (predisat.cli.args)
    with pytest.raises(ValueError, match="--error-model"):
        run_from_args(parser.parse_args([*base, "--error-model", str(path), "--out",
                                         str(tmp_path / "x")]), track)  # fmt: skip
    with pytest.raises(SystemExit):
        parser.parse_args([*base, "--error-model", str(tmp_path), "--out", str(tmp_path / "x")])
    for k in ("0", "inf"):  # refused by the parser, before any work
        with pytest.raises(SystemExit):
            parser.parse_args([*base, "--k-sigma", k, "--out", str(tmp_path / "x")])


def test_an_error_model_must_hold_every_counted_system(
    tmp_path: Path, masks: MaskSet, track: TrackMap, capsys: pytest.CaptureFixture[str]
) -> None:
    from predisat.gnss.errormodel import (
        Applicability,
        ErrorModel,
        IntervalModel,
        SystemModel,
        write_error_model,
    )

    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    parser = add_arguments(argparse.ArgumentParser())
    base = ["--masks", str(path), "--start", START, "--end", "2020-06-25T07:00", "--step",
            "600", "--interval-every", "1", "--sky-km", "4.05", "--quiet",
            "--k-sigma", "2"]  # fmt: skip
    app = Applicability(("R1",), ("A1",))

    def model(name: str, systems: dict[str, tuple[float, float]]) -> str:
        sm = {c: SystemModel(ErrorModel(a, a), ("C1C",), 1000, 300, tail)
              for c, (a, tail) in systems.items()}  # fmt: skip
        top = max(a for a, _ in systems.values())  # the envelope of every system
        env = IntervalModel(ErrorModel(top, top), 2.0)
        return str(write_error_model(tmp_path / name, env, systems=sm, applicability=app))

    # a BeiDou-only model does not bound GPS intervals: refused, naming both
    beidou = model("c.json", {"C": (3.0, 0.01)})
    with pytest.raises(ValueError, match=r"no model of GPS.*holds BeiDou"):
        run_from_args(parser.parse_args([*base, "--error-model", beidou, "--out",
                                         str(tmp_path / "c")]), track)  # fmt: skip
    # the counted system's own model is used, not the file's envelope
    both = model("gc.json", {"G": (4.0, 0.01), "C": (9.0, 0.01)})
    plain = model("g.json", {"G": (4.0, 0.01)})
    runs = [run_from_args(parser.parse_args([*base, "--error-model", m, "--out",
                                             str(tmp_path / n)]), track)
            for m, n in ((both, "gc"), (plain, "g"))]  # fmt: skip
    a, b = (r.results[0].interval_m for r in runs)
    assert np.isfinite(a).sum() > 10
    np.testing.assert_allclose(a, b, rtol=1e-9)
    err = capsys.readouterr().err.splitlines()
    assert _said([w for w in err if "warning" in w]) == []  # checked to 0.01: k 2.58 covers k 2
    # at the integrity budget's k (up to 7.13 for one pair) the same model is too shallow: said
    budget = [x for x in base if x not in ("--k-sigma", "2")]
    run_from_args(parser.parse_args([*budget, "--error-model", plain, "--out",
                                     str(tmp_path / "b")]), track)  # fmt: skip
    err = capsys.readouterr().err
    assert "checked to 0.01 per pseudorange" in err and "Gaussian tail" in err
    # a model whose GPS tail was never checked is used, and said to bound nothing
    unchecked = model("u.json", {"G": (4.0, 1.0)})
    run_from_args(parser.parse_args([*base, "--error-model", unchecked, "--out",
                                     str(tmp_path / "u")]), track)  # fmt: skip
    err = capsys.readouterr().err
    assert "no tail of GPS was checked" in err and "not bounds" in err
    # ... and in the report and its summary, which are read without the console
    (u,) = [w for w in json.loads((tmp_path / "u" / "summary.json").read_text())
            ["run"]["warnings"] if "no tail of GPS was checked" in w]  # fmt: skip
    assert html.escape(u) in (tmp_path / "u" / "report.html").read_text(encoding="utf-8")


def test_the_integrity_budget_sets_each_modes_k(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    from scipy.stats import norm

    from predisat.availability.interval import interval_mode

    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    parser = add_arguments(argparse.ArgumentParser())
    base = ["--masks", str(path), "--start", START, "--end", "2020-06-25T07:00", "--step",
            "600", "--interval-every", "1", "--sky-km", "4.05", "--quiet", "--scheduler",
            "serial", "--map-doubt", "0", "0"]  # fmt: skip (no map doubt: k scales the lengths)
    # k = 2 scaled back to one sigma (a k under 1.645, a risk above 0.1 per pair, is refused)
    one = run_from_args(parser.parse_args([*base, "--k-sigma", "2", "--out", str(tmp_path / "1")]),
                        track)  # fmt: skip
    runs = {
        1e-12: run_from_args(parser.parse_args([*base, "--out", str(tmp_path / "d")]), track),
        1e-7: run_from_args(parser.parse_args([*base, "--integrity-risk", "1e-7", "--out",
                                               str(tmp_path / "r")]), track),
    }  # fmt: skip
    unit = one.results[0].interval_m / 2.0
    mode = interval_mode(one.results[0].count)
    for risk, r in runs.items():
        # k = Q^-1((T / 2)^(1 / m)), m = 3 / 2 / 1 independent pairs by mode
        want = {3: norm.isf((risk / 2) ** (1 / 3)), 2: norm.isf((risk / 2) ** 0.5),
                1: norm.isf(risk / 2)}  # fmt: skip
        got = r.results[0].interval_m
        seen = set()
        for m, kk in want.items():
            sel = (mode == m) & np.isfinite(unit)
            np.testing.assert_allclose(got[sel], kk * unit[sel], rtol=1e-5)
            if sel.any():
                seen.add(m)
        assert 3 in seen  # the stretch has three-pair epochs, so the test bites
        text = html.unescape(r.report_html.read_text(encoding="utf-8"))
        assert f"integrity risk {risk:.3g} per epoch" in text
        assert f"k = {want[3]:.2f} (three pairs)" in text
        params = json.loads((r.report_html.parent / "summary.json").read_text())["run"][
            "interval_model_params"]  # fmt: skip
        assert params["integrity_risk_per_epoch"] == risk and params["k_sigma"] is None
        assert params["k_sigma_by_mode"]["THREE_PAIRS"] == pytest.approx(want[3])
        table = pd.read_csv(r.report_html.parent / "summary.csv")
        drawn = table["interval_median_m"].notna()
        assert drawn.any() and table.loc[drawn, "interval_k_sigma"].isna().all()
        assert (table.loc[drawn, "interval_integrity_risk_per_epoch"] == risk).all()
    for bad in (["--integrity-risk", "5"], ["--integrity-risk", "0"],
                ["--integrity-risk", "1e-7", "--k-sigma", "2"]):  # fmt: skip
        with pytest.raises(SystemExit):
            parser.parse_args([*base, *bad, "--out", str(tmp_path / "x")])


def test_untrusted_satellites_are_reported(run) -> None:
    # Every (epoch, satellite) the ephemeris refuses (NaN position) must appear in the status
    # table, with its reason: such satellites are never trusted and must not vanish silently.
    t = np.arange(_gps_s(datetime(2020, 6, 25, 6)), _gps_s(datetime(2020, 6, 25, 8)), STEP_S)
    eph = default_ephemeris()
    gps = [s for s in eph.satellites if s.startswith("G")]
    refused = ~np.all(np.isfinite(eph.position_ecef(t, gps)), axis=-1)
    status = pd.read_csv(run.files["ephemeris_status_csv"])
    assert set(status.columns) >= {"sat", "reason", "first_gps_s", "last_gps_s", "n_epochs"}
    assert int(status["n_epochs"].sum()) == int(refused.sum())
    for j, sat in enumerate(gps):
        assert int(status.loc[status["sat"] == sat, "n_epochs"].sum()) == int(refused[:, j].sum())
    assert (status["reason"] != "OK").all()


def test_command_line_selects_one_track_of_a_file(
    tmp_path: Path, masks: MaskSet, track: TrackMap, capsys: pytest.CaptureFixture[str]
) -> None:
    from predisat.cli.app import main
    from predisat.track.readers import write_geojson

    write_geojson(track, tmp_path / "a.geojson")
    doc = json.loads((tmp_path / "a.geojson").read_text())
    line_a = next(f for f in doc["features"] if f["geometry"]["type"] == "LineString")
    line_a["properties"]["trackname"] = "A"
    line_b = json.loads(json.dumps(line_a))  # a parallel track 30 m east
    line_b["properties"]["trackname"] = "B"
    line_b["geometry"]["coordinates"] = [[x + 4.2e-4, y, *h] for x, y, *h in
                                         line_a["geometry"]["coordinates"]]  # fmt: skip
    doc["features"] = [line_a, line_b]
    both = tmp_path / "ab.geojson"
    both.write_text(json.dumps(doc))
    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    argv = ["availability", "--masks", str(path), "--track", str(both), "--start", START,
            "--end", "2020-06-25T06:30", "--step", "900", "--quiet", "--scheduler", "serial"]
    assert main([*argv, "--out", str(tmp_path / "x")]) == 2
    assert "several tracks (trackname: A, B)" in (err := capsys.readouterr().err)
    assert "--track-name" in err
    assert main([*argv, "--track-name", "A", "--out", str(tmp_path / "a")]) == 0
    assert (tmp_path / "a" / "report.html").is_file()
    assert main([*argv, "--track-name", "B", "--out", str(tmp_path / "b")]) == 2  # 30 m off
    assert "do not fit track" in capsys.readouterr().err


def test_an_error_starts_on_its_own_line_after_the_progress_bar(
    tmp_path: Path, masks: MaskSet, capsys: pytest.CaptureFixture[str]
) -> None:
    from predisat.cli.app import main

    path = write_masks(masks.subset(4000.0, 4100.0), tmp_path / "m.masks.parquet")
    argv = ["availability", "--masks", str(path), "--start", START, "--end", START,
            "--out", str(tmp_path / "x"), "--scheduler", "serial"]  # fmt: skip
    assert main(argv) == 2  # an empty window, refused after the bar has started
    err = capsys.readouterr().err
    assert "availability" in err.split("predisat availability: error")[0]  # the bar was drawn
    assert "\npredisat availability: error: " in err


def test_masks_made_on_the_embedded_line_get_its_kilometre_posts_without_track(
    tmp_path: Path, masks: MaskSet, track: TrackMap
) -> None:
    """Masks whose provenance names the embedded line 144, and which lie on it, are reported
    with its kilometre posts when no --track is given (a user trial read 'Track none given'
    and 'no kilometre posts' for the demo's own masks); masks of another map are not."""
    import dataclasses

    def report(ms: MaskSet, name: str) -> str:
        path = write_masks(ms, tmp_path / f"{name}.masks.parquet")
        r = run_availability(
            path, None, None, out_dir=tmp_path / name, start=START, end="2020-06-25T06:10",
            step_s=600, constellation="gps", cutoff_deg=15.0, n_sky=1, interval_every=10,
            progress=False,
        )  # fmt: skip
        return html.unescape(Path(r.report_html).read_text(encoding="utf-8"))

    on_line = dataclasses.replace(masks, provenance={**masks.provenance, "track": track.name})
    text = report(on_line, "line")
    assert "none given" not in text and "the track has no kilometre posts" not in text
    assert track.name in text
    # the same name on masks that do not lie on the line: their own positions, as before
    moved = dataclasses.replace(on_line, lat_deg=on_line.lat_deg + 0.01)
    assert "none given" in report(moved, "moved")


def test_sp3_default_window_ends_with_the_data_and_a_gap_is_named(
    tmp_path: Path, masks: MaskSet, test_data
) -> None:
    src = test_data / "gnss" / "igs15904_G01G02G05.sp3"
    small = masks.subset(4000.0, 4060.0)
    # no --end: the window ends with the last sample (07:45), none past it is asked for
    r = run_availability(small, None, [src], out_dir=tmp_path / "d", step_s=900, n_sky=1,
                         progress=False)  # fmt: skip
    assert r.results[0].gps_s[-1] == pytest.approx(_gps_s(datetime(2010, 7, 1, 7, 45)))
    # the same file without its 03:00-04:00 samples: the error names the gap, not the span
    lines = src.read_text().splitlines(keepends=True)
    out, drop = [], False
    for ln in lines:
        if ln.startswith("*"):
            drop = ln.split()[4] in ("3",) or (ln.split()[4] == "4" and ln.split()[5] == "0")
        if not drop or ln.startswith("EOF"):
            out.append(ln)
    gap = tmp_path / "gap.sp3"
    gap.write_text("".join(out))
    with pytest.raises(ValueError, match=r"in a gap of the navigation data gap\.sp3"):
        run_availability(small, None, [gap], out_dir=tmp_path / "g", start="2010-07-01T00:00",
                         end="2010-07-01T07:00", step_s=900, n_sky=1, progress=False)  # fmt: skip


def test_constellation_warnings_say_what_the_data_holds_in_its_era(
    tmp_path: Path, masks: MaskSet, test_data
) -> None:
    small = masks.subset(4000.0, 4060.0)
    common = dict(step_s=900, n_sky=1, progress=False)
    # a GPS-only file asked for GPS and Galileo: the counts are of GPS only, and it is said
    r = run_availability(small, None, [test_data / "gnss" / "igs15904_G01G02G05.sp3"],
                         out_dir=tmp_path / "ge", end="2010-07-01T01:00",
                         constellation="gps+galileo", **common)  # type: ignore[arg-type]  # fmt: skip
    (absent,) = [w for w in r.info["warnings"] if "asks for" in w]
    assert "asks for Galileo" in absent and "holds no satellite" in absent
    assert r.info["constellation"].endswith("GPS (3 satellites)")
    # GLONASS had 16-20 satellites in service in 2009 (a whole file then is not "sparse"), 24
    # again from late 2011; two are a partial file in either era
    from predisat.availability.run import sparse_navigation
    from predisat.availability.satellites import SatellitePositions
    from predisat.gnss.ephemeris import EphemerisStatus

    real = SatellitePositions.from_ephemeris(
        load_navigation([test_data / "gnss" / "brdc0910_R02R08.09g"]),
        np.array([parse_time("2009-04-01T06:00", "t")]), "R",
    )  # fmt: skip
    assert sparse_navigation(real, "x")[0].startswith("x holds 2 GLONASS satellites")
    with pytest.raises(ValueError, match=r"status\.reason .* replace them together"):
        dataclasses.replace(real, sats=("R01", "R02", "R03"), pos_ecef_m=np.ones((1, 3, 3)))

    def glonass(n: int, when: str) -> SatellitePositions:
        gps_s, sats = np.array([parse_time(when, "t")]), tuple(f"R{k + 1:02d}" for k in range(n))
        status = EphemerisStatus(gps_s, sats, np.zeros((1, n), np.int8),
                                 np.full((1, n), "", object))  # fmt: skip
        return SatellitePositions(gps_s, sats, np.ones((1, n, 3)), status)

    assert sparse_navigation(glonass(19, "2009-04-01T06:00"), "x") == []
    (w,) = sparse_navigation(glonass(19, "2013-04-01T06:00"), "x")
    assert "holds 19 GLONASS satellites" in w and "22 or more" in w
    (w,) = sparse_navigation(glonass(2, "2009-04-01T06:00"), "x")
    assert "holds 2 GLONASS satellites" in w and "16 or more" in w


def test_doubts_of_the_navigation_data_are_said(tmp_path: Path, masks: MaskSet,
                                                test_data) -> None:  # fmt: skip
    """User trials, each said nothing: a phantom satellite counted from an hour's file (G01's
    record of 06:00 is another satellite's orbit); GLONASS records of another year asked with
    GPS (the figures GPS only, labelled GPS + GLONASS); a window past the day's records."""
    small = masks.subset(4000.0, 4060.0)
    common = dict(step_s=900, n_sky=1, progress=False)
    gps = test_data / "gnss" / "brdc1820_G01G02G05.10n"
    lines = gps.read_text().splitlines(keepends=True)
    head = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln) + 1
    keep = lines[:head]
    for k in range(head, len(lines), 8):  # G01 reduced to its record of 06:00
        prn, hour, minute = int(lines[k][:2]), int(lines[k][12:15]), int(lines[k][15:18])
        if prn != 1 or (hour, minute) == (6, 0):
            keep += lines[k:k + 8]
    one = tmp_path / "g01_once.10n"
    one.write_text("".join(keep))
    r = run_availability(small, None, [one], out_dir=tmp_path / "u", start="2010-07-01T05:00",
                         end="2010-07-01T07:00", **common)  # type: ignore[arg-type]  # fmt: skip
    (w,) = [w for w in r.info["warnings"] if "cross-check" in w]
    assert "1 satellite(s) (G01)" in w and "not counted" in w and "BRDC" in w
    none = r.results[1]  # the rules: masks, no mask, cut-offs
    assert int(none.count.max()) <= 2  # G02 and G05 at most
    # only G01's record in force at every epoch: refused, not counted as no data
    only = tmp_path / "g01_only.10n"
    only.write_text("".join(lines[:head] + [ln for k in range(head, len(lines), 8)
                                            if int(lines[k][:2]) == 1
                                            and lines[k][11:17].split() == ["6", "0"]
                                            for ln in lines[k:k + 8]]))  # fmt: skip
    with pytest.raises(ValueError, match=r"only one within a day.*full broadcast"):
        run_availability(small, None, [only], out_dir=tmp_path / "o", start="2010-07-01T05:30",
                         end="2010-07-01T06:30", **common)  # type: ignore[arg-type]  # fmt: skip
    # GLONASS of 2009 asked with GPS of 2010
    glo = test_data / "gnss" / "brdc0910_R02R08.09g"
    r = run_availability(small, None, [gps, glo], out_dir=tmp_path / "g", end="2010-07-01T02:00",
                         start="2010-07-01T00:00", constellation="gps+glonass",
                         **common)  # type: ignore[arg-type]  # fmt: skip
    (w,) = [w for w in r.info["warnings"] if "anywhere in the window" in w]
    assert "no usable GLONASS" in w and "2009-04-01" in w
    # ... and with the default window, which falls on neither file's whole day: the refusal
    # gives each system's span, not one span of fifteen months
    with pytest.raises(ValueError,
                       match=r"cover different times \(GPS 2010-07-01.*GLONASS 2009-04-01"):
        run_availability(small, None, [gps, glo], out_dir=tmp_path / "h",
                         constellation="gps+glonass", **common)  # type: ignore[arg-type]  # fmt: skip
    # a window 2 h past the file's last GPS records (22:00), G05's last of 20:00: it drops
    # out once that record is older than its 2 h of validity
    short = tmp_path / "g05_short.10n"
    short.write_text("".join(lines[:head] + [
        ln for k in range(head, len(lines), 8)
        if not (int(lines[k][:2]) == 5 and lines[k][11:17].split() == ["22", "0"])
        for ln in lines[k:k + 8]]))  # fmt: skip
    r = run_availability(small, None, [short], out_dir=tmp_path / "p", start="2010-07-01T22:00",
                         end="2010-07-02T00:00", **common)  # type: ignore[arg-type]  # fmt: skip
    (w,) = [w for w in r.info["warnings"] if "after the last GPS records" in w]
    assert "1 of its satellites drop out" in w and "adjacent day" in w
    # 2 h past them every record is still in force: nothing drops, nothing to say (a user
    # trial's day from 00:00 with records from 02:00 was warned of all the same)
    r = run_availability(small, None, [gps], out_dir=tmp_path / "p2", start="2010-07-01T22:00",
                         end="2010-07-02T00:00", **common)  # type: ignore[arg-type]  # fmt: skip
    assert not [w for w in r.info["warnings"] if "GPS records" in w]
    r = run_availability(small, None, [gps], out_dir=tmp_path / "q", start="2010-07-01T06:00",
                         end="2010-07-01T08:00", **common)  # type: ignore[arg-type]  # fmt: skip
    assert not [w for w in r.info["warnings"] if "records of" in w or "cross-check" in w]


def test_masks_made_for_a_higher_antenna_than_the_trains_are_refused(
    tmp_path: Path, masks: MaskSet
) -> None:
    from dataclasses import replace

    from predisat.masks.antenna import AntennaHeightError

    at4 = replace(masks, provenance={**masks.provenance, "antenna_height_m": 4.0})
    with pytest.raises(AntennaHeightError, match=r"masks in memory were made for an antenna 4 m "
                       r"above the track axis, the train's is at 3 m"):  # fmt: skip
        run_availability(at4, None, None, out_dir=tmp_path / "o", step_s=3600, progress=False,
                         antenna_height_m=3.0)  # fmt: skip
    res = run_availability(at4, None, None, out_dir=tmp_path / "o", step_s=3600, n_sky=1,
                           progress=False, antenna_height_m=4.5)  # fmt: skip
    assert any("err on the safe side" in w for w in res.info["warnings"])
    # the report's header says which antenna the figures are for, and whether it was checked
    assert res.info["antenna"] == ("masks made for an antenna 4 m above the track axis; the "
                                   "train's, 4.5 m, checked against them")  # fmt: skip
    unchecked = run_availability(at4, None, None, out_dir=tmp_path / "u", step_s=3600, n_sky=1,
                                 progress=False)  # fmt: skip
    assert "the train's antenna not checked" in unchecked.info["antenna"]
    page = Path(unchecked.report_html).read_text()
    assert "<th>Antenna</th><td>masks made for an antenna 4 m above" in page
    # masks that state no height: nothing can be checked, and the row says so
    bare = dataclasses.replace(masks, provenance={k: v for k, v in masks.provenance.items()
                                                  if k != "antenna_height_m"})  # fmt: skip
    res = run_availability(bare, None, None, out_dir=tmp_path / "b", step_s=3600, n_sky=1,
                           progress=False, antenna_height_m=3.0)  # fmt: skip
    assert res.info["antenna"] == ("the masks state no antenna height, taken as made for the "
                                   "train's (3 m): nothing could be checked")  # fmt: skip


def test_a_far_stations_navigation_file_is_said_to_understate(shared_data: Path) -> None:
    """A user trial gave a Japanese station's broadcast file to line 144: 3.3 satellites above
    10 deg had a record where a merged file gave 7.0, with no warning. Above the station its
    own day's file holds the satellites it sees; above Belgium 56 % are missing."""
    from predisat.availability.run import station_file_gaps
    from predisat.availability.satellites import SatellitePositions
    from predisat.geodesy import ecef_to_geodetic
    from predisat.gnss.ephemeris import Ephemeris
    from predisat.gnss.timescale import calendar_to_gps_s

    eph = Ephemeris.from_rinex(shared_data / "gnss/rtklib/07590920.05n")
    t = calendar_to_gps_s(2005, 4, 2) + np.arange(0.0, 86400.0, 600.0)
    sats = SatellitePositions.from_ephemeris(eph, t, "gps")
    lat, lon, h = (float(v) for v in ecef_to_geodetic(np.array([-3976219.5, 3382372.6,
                                                                3652513.0])))  # fmt: skip
    assert station_file_gaps(eph, sats, lat, lon, h, "0759") == []  # the station's own sky
    far = station_file_gaps(eph, sats, 50.56, 4.69, 150.0, "0759")  # line 144, Belgium
    assert len(far) == 1 and "0759 has no usable record for" in far[0]
    assert "merged broadcast file" in far[0]


def test_a_station_file_is_not_sparse_for_satellites_below_its_horizon_in_a_short_window(
    tmp_path: Path, masks: MaskSet
) -> None:
    """A user trial: an hour's report on the embedded day said it "holds 21 GPS satellites
    ... every count is understated" of the 10 satellites whose records were out of their
    validity there, all below the line's horizon. The file holds records of 31."""
    from predisat.availability.satellites import SatellitePositions, default_ephemeris
    from predisat.gnss.ephemeris import Reason

    r = run_availability(masks.subset(4000.0, 4060.0), None, None, out_dir=tmp_path / "h",
                         start="2020-06-25T08:00Z", end="2020-06-25T09:00Z", step_s=60,
                         n_sky=1, progress=False)  # fmt: skip
    sats = SatellitePositions.from_ephemeris(default_ephemeris(), r.results[0].gps_s, "gps")
    lost = (np.asarray(sats.status.reason) == Reason.OUTSIDE_VALIDITY).any(axis=0)
    assert lost.any()  # satellites with records, not valid in the window
    assert not [w for w in r.info["warnings"] if "understated" in w]


def test_satellites_out_all_through_a_window_past_their_records_are_said() -> None:
    """A review: one satellite's next-day 00:00 record moved the system's span, so the others,
    past their own 22:00 records and out all through a 00:30-02:00 window, were counted
    nowhere (the count needed them valid elsewhere in the window) and nothing was said."""
    from types import SimpleNamespace as NS

    from predisat.availability.run import navigation_doubts
    from predisat.gnss.ephemeris import Reason

    t = np.arange(88200.0, 93600.0 + 1, 300.0)
    reason = np.full((t.size, 4), int(Reason.OUTSIDE_VALIDITY))
    reason[:, 0] = int(Reason.OK)

    class Rec:
        sat = np.array(["G01", "G02", "G03", "G04", "G01"])
        ref_gps_s = np.array([79200.0] * 4 + [86400.0])

        def __len__(self) -> int:
            return 5

    sats = NS(gps_s=t, valid=reason == int(Reason.OK), status=NS(reason=reason),
              sats=["G01", "G02", "G03", "G04"])  # fmt: skip
    eph = NS(kepler=Rec(), glonass=None, kind="broadcast")
    (w,) = navigation_doubts(sats, eph, "brdc")  # type: ignore[arg-type]
    assert "3 of its satellites drop out" in w


def test_a_dual_frequency_model_is_said_to_count_every_satellite(tmp_path: Path) -> None:
    """A model of the ionosphere-free combination (`locator calibrate --dual-frequency`): the
    prediction counts every satellite in view, a dual-frequency run only those with the
    second code (a review: used without a word)."""
    from predisat.cli.availability import _interval_model
    from predisat.gnss.errormodel import (
        Applicability,
        ErrorModel,
        IntervalModel,
        SystemModel,
        write_error_model,
    )

    def model(frequency: str) -> str:
        sm = SystemModel(ErrorModel(1.4, 0.6), ("C1C+C2W",) if frequency == "dual" else ("C1C",),
                         5000, 900, 1e-3)  # fmt: skip
        app = Applicability(("TRIMBLE NETR9",), ("TRM59800.00 NONE",), frequency=frequency)
        return str(write_error_model(tmp_path / f"{frequency}.json",
                                     IntervalModel(ErrorModel(1.4, 0.6), 2.0),
                                     systems={"G": sm}, applicability=app))  # fmt: skip

    for frequency in ("single", "dual"):
        notes: list[str] = []
        _interval_model(model(frequency), 2.0, "gps", notes=notes)
        said = any("dual-frequency model" in n for n in notes)
        assert said == (frequency == "dual"), notes
