"""Stations, bridges and the chosen track's name, read from track files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pyproj import Geod

from predisat.track import Station
from predisat.track.map import TrackMap, demo_track
from predisat.track.readers import write_geojson
from predisat.track.stations import points_as_stations

GEOD = Geod(ellps="WGS84")
RIVIERA = "track/riviera_andora_alassio.geojson"
MAIN = {"usage": "main", "service": None}


def _line(lon0: float, lat0: float, n: int = 5, props: dict | None = None) -> dict:
    coords = [[lon0 + 0.001 * i, lat0] for i in range(n)]
    return {"type": "Feature", "properties": props or {},
            "geometry": {"type": "LineString", "coordinates": coords}}  # fmt: skip


def _point(lon: float, lat: float, props: dict) -> dict:
    return {"type": "Feature", "properties": props,
            "geometry": {"type": "Point", "coordinates": [lon, lat]}}  # fmt: skip


def test_osm_stops_are_stations_once_per_name(test_data: Path) -> None:
    tm = TrackMap.from_geojson(test_data / RIVIERA, where=MAIN, chain="longest")
    doc = json.loads((test_data / RIVIERA).read_text())
    named = {
        f["properties"]["name"]: f["geometry"]["coordinates"]
        for f in doc["features"]
        if f["geometry"]["type"] == "Point" and f["properties"].get("railway") == "stop"
    }
    assert sorted(s.name for s in tm.stations) == sorted(named) == [
        "Alassio", "Andora", "Laigueglia",
    ]  # fmt: skip
    first = next(s for s in tm.stations if s.name == "Alassio")
    assert (first.lon_deg, first.lat_deg) == tuple(named["Alassio"])


def test_riviera_bridges_are_chainage_intervals(test_data: Path) -> None:
    tm = TrackMap.from_geojson(test_data / RIVIERA, where=MAIN, chain="longest")
    doc = json.loads((test_data / RIVIERA).read_text())
    on_bridge = 0.0
    for f in doc["features"]:
        p = f["properties"]
        if f["geometry"]["type"] != "LineString" or p.get("bridge", "no") == "no":
            continue
        if p.get("usage") != "main" or "service" in p:
            continue
        c = np.array(f["geometry"]["coordinates"])
        pr = tm.project(c[:, 1], c[:, 0])
        if np.all(np.abs(pr.offset_m) < 1.5) and np.all(pr.along_m < 1.5):
            on_bridge += GEOD.line_length(c[:, 0], c[:, 1])
    bridges = np.array(tm.bridges_m)
    assert on_bridge > 0.0 and len(bridges) >= 1
    assert np.sum(bridges[:, 1] - bridges[:, 0]) == pytest.approx(on_bridge, rel=0.02)
    assert not tm.in_tunnel(bridges.mean(axis=1)).any()


def test_station_property_and_round_trip(tmp_path: Path) -> None:
    doc = {"type": "FeatureCollection", "features": [
        _line(4.0, 50.0),
        _point(4.001, 50.0005, {"station": "Halt A"}),
        _point(4.002, 50.0005, {"railway": "halt", "name": "Halt B"}),
        _point(4.003, 50.0005, {"railway": "milestone", "name": "not a station"}),
        _point(4.003, 50.0005, {"km_m": 1000.0, "station": "a post"}),
    ]}  # fmt: skip
    path = tmp_path / "t.geojson"
    path.write_text(json.dumps(doc))
    tm = TrackMap.from_geojson(path)
    assert tm.stations == (Station("Halt A", 50.0005, 4.001), Station("Halt B", 50.0005, 4.002))
    out = tmp_path / "back.geojson"
    write_geojson(tm, out)
    assert TrackMap.from_geojson(out).stations == tm.stations


def test_bad_station_is_refused() -> None:
    with pytest.raises(ValueError, match="lat_deg 95"):
        Station("x", 95.0, 4.0)
    # a point with a name but no usable coordinates is skipped, not a crash
    assert points_as_stations([({"station": "x"}, np.array([np.nan, 50.0]))]) == []


def test_chosen_track_is_named(tmp_path: Path) -> None:
    doc = {"type": "FeatureCollection", "name": "line 9", "features": [
        _line(4.0, 50.0, props={"trackname": "A", "trackcode": "L 9_1"}),
        _line(4.0, 50.01, props={"trackname": "B", "trackcode": "L 9_2"}),
    ]}  # fmt: skip
    path = tmp_path / "two.geojson"
    path.write_text(json.dumps(doc))
    assert TrackMap.from_geojson(path, track="B").name == "line 9, track B (L 9_2)"
    assert TrackMap.from_geojson(path, track="L 9_1").name == "line 9, track L 9_1 (A)"


def test_demo_track_has_its_operating_points() -> None:
    names = [s.name for s in demo_track().stations]
    assert names == ["GEMBLOUX", "JEMEPPE-FR.M", "JEMEPPE/S-M"]
