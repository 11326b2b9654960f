"""Tests of predisat.track.network on the Gembloux test network (three 1.5 km stretches of
Infrabel lines) and on small hand-written network files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import numpy as np
import pytest
from pyproj import Geod

from predisat.track import TrackMapError
from predisat.track.network import Network, line_key, part_key, track_key

GEOD = Geod(ellps="WGS84")


@pytest.fixture(scope="module")
def gembloux(test_data: Path) -> Path:
    return test_data / "track" / "network_gembloux.geojson"


def _line(lid: Any, coords: list[list[float]], **props: Any) -> dict[str, Any]:
    return {"type": "Feature", "properties": {"linecalfa": lid, **props},
            "geometry": {"type": "LineString", "coordinates": coords}}  # fmt: skip


def _write(tmp_path: Path, feats: list[dict[str, Any]], name: str = "net.geojson") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return p


# a straight 2 km east-west piece near Gembloux and pieces along it
def _piece(lon0: float, lon1: float, lat: float = 50.56) -> list[list[float]]:
    return [[float(x), lat] for x in np.linspace(lon0, lon1, 5)]


def test_lines_ids_and_lengths_agree_with_the_file(gembloux: Path) -> None:
    net = Network.from_file(gembloux)
    assert net.line_ids == ("144", "161", "140") and net.id_key == "linecalfa"
    doc = json.loads(gembloux.read_text())
    assert net.lines[0].parts[0].tolerance_m == 10.0  # the file's tolerance_m member
    for ln, feat in zip(net.lines, doc["features"], strict=True):
        c = np.array(feat["geometry"]["coordinates"])
        geodesic_m = GEOD.line_length(c[:, 0], c[:, 1])
        (tm,) = ln.parts
        assert ln.track_name == "A"
        assert abs(tm.length_m - geodesic_m) < 0.01 * geodesic_m
        # chainage runs along the file's direction: 0 at the first vertex
        p = tm.project(np.array([c[0, 1], c[-1, 1]]), np.array([c[0, 0], c[-1, 0]]))
        assert p.chainage_m[0] < 1.0 and abs(p.chainage_m[1] - tm.length_m) < 1.0
    assert net.skipped == ()


def test_line_selection_and_unknown_line(gembloux: Path) -> None:
    net = Network.from_file(gembloux, lines=["161"])
    assert net.line_ids == ("161",)
    with pytest.raises(TrackMapError, match=r"no line '999'.*lines: 140, 144, 161"):
        Network.from_file(gembloux, lines=["999"])
    with pytest.raises(KeyError, match="no line '7'"):
        net.line("7")


def test_reference_track_out_of_service_and_parts(tmp_path: Path) -> None:
    feats = [
        _line("12", _piece(4.60, 4.62), trackname="B"),
        _line("12", _piece(4.60, 4.62, 50.5601), trackname="A"),
        _line("12", _piece(4.62, 4.64, 50.5601), trackname="A", status="Hors service"),
        # line 7: two pieces meeting end to end (one part), a third 1.4 km away (a second part)
        _line("7", _piece(4.70, 4.71), trackname="E/U"),
        _line("7", _piece(4.72, 4.71), trackname="E/U"),  # reversed: chained anyway
        _line("7", _piece(4.74, 4.75), trackname="E/U"),
        _line("01", _piece(4.80, 4.81)),  # "01" is not line "1"
        _line("1", _piece(4.80, 4.81, 50.57)),
    ]
    net = Network.from_file(_write(tmp_path, feats))
    assert net.line_ids == ("12", "7", "01", "1")
    l12 = net.line("12")
    assert l12.track_name == "A" and l12.features == (1,)
    why = {(s.line_id, s.what.split(" (")[0]): s.reason for s in net.skipped}
    assert why[("12", "feature 0")].startswith("another track")
    assert why[("12", "feature 2")] == "out of service"
    l7 = net.line("7")
    assert len(l7.parts) == 2 and l7.features == (3, 4, 5)
    want = [GEOD.line_length([4.70, 4.72], [50.56, 50.56]), GEOD.line_length([4.74, 4.75],
                                                                               [50.56] * 2)]
    assert np.allclose([p.length_m for p in l7.parts], want, rtol=1e-3)
    assert [l7.part_key(k) for k in (1, 2)] == ["7.part1", "7.part2"]
    assert net.line("01").key == "01" and part_key("50A/3", 1, 1) == "50A%2F3"
    assert unquote(line_key("50A/3")) == "50A/3"
    # a larger gap allowance chains the far piece too; the geometry key follows the change
    one = Network.from_file(_write(tmp_path, feats), max_gap_m=2000.0, lines=["7"])
    assert len(one.line("7").parts) == 1
    assert track_key(one.line("7").parts[0]) != track_key(l7.parts[0])
    assert track_key(l7.parts[0]) == track_key(Network.from_file(
        _write(tmp_path, feats), lines=["7"]).line("7").parts[0])  # fmt: skip


def test_bad_network_files_are_refused_with_the_fix(tmp_path: Path) -> None:
    bad = tmp_path / "bad.geojson"
    bad.write_text('{"type": "FeatureCollection", "features": [')
    with pytest.raises(TrackMapError, match=r"bad.geojson: not valid JSON .*line 1"):
        Network.from_file(bad)
    noid = _write(tmp_path, [_line("3", _piece(4.6, 4.7)),
                             {"type": "Feature", "properties": {"name": "x"},
                              "geometry": {"type": "LineString",
                                           "coordinates": _piece(4.6, 4.7)}}])  # fmt: skip
    with pytest.raises(TrackMapError, match=r"feature 1 \(name=x\) has no line id .*'linecalfa'"):
        Network.from_file(noid)
    anon = tmp_path / "anon.geojson"
    anon.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "LineString",
                                                           "coordinates": _piece(4.6, 4.7)}}]}))
    with pytest.raises(TrackMapError, match=r"no property names the lines .*line_id.*--id-key"):
        Network.from_file(anon)
    swapped = _write(tmp_path, [_line("3", [[50.56, 4.6], [50.56, 4.7], [50.57, 4.8]],
                                      length=GEOD.line_length([4.6, 4.7, 4.8],
                                                              [50.56, 50.56, 50.57]))])
    with pytest.raises(TrackMapError, match=r"feature 0: .*coordinates look swapped"):
        Network.from_file(swapped)
    text = _write(tmp_path, [_line("3", [["4.6", "50.5"], ["4.7", "50.5"]])])
    with pytest.raises(TrackMapError, match=r"feature 0 .*not strings"):
        Network.from_file(text)
    branch = _write(tmp_path, [_line("9", _piece(4.60, 4.61)), _line("9", _piece(4.61, 4.62)),
                               _line("9", [[4.61, 50.56], [4.62, 50.57]])])
    with pytest.raises(TrackMapError, match=r"line 9: its pieces branch .*select one track"):
        Network.from_file(branch)
    skipped = Network.from_file(
        _write(tmp_path, [*json.loads(branch.read_text())["features"],
                          _line("4", _piece(4.7, 4.8))]), on_bad_line="skip")  # fmt: skip
    assert skipped.line_ids == ("4",)
    assert [s.what for s in skipped.skipped] == ["line 9"]
    points = _write(tmp_path, [{"type": "Feature", "properties": {"line": "1"},
                                "geometry": {"type": "Point", "coordinates": [4.6, 50.5]}}])
    with pytest.raises(TrackMapError, match="no LineString or MultiLineString feature"):
        Network.from_file(points)


def test_whole_belgian_network(shared_data: Path) -> None:
    """Infrabel's published file: every line in service, line 144 on its track A."""
    path = shared_data / "railway/infrabel/belgium_geovoies_simpl10m.geojson"
    net = Network.from_file(path, lines=["144", "161", "36N"], tolerance_m=10.0)
    doc = json.loads(path.read_text())
    for ln in net.lines:
        feats = [doc["features"][i] for i in ln.features]
        assert {f["properties"]["linecalfa"] for f in feats} == {ln.line_id}
        assert {f["properties"]["trackname"] for f in feats} == {"A"}
        declared = sum(f["properties"]["length"] for f in feats)
        assert abs(ln.length_m - declared) < 0.005 * declared  # Infrabel's own length
    out = {s.what for s in net.skipped if s.reason == "out of service"}
    assert any("L 144_2" in w for w in out)  # line 144's track B is mostly out of service


def test_a_line_read_alone_is_the_networks_line(gembloux: Path) -> None:
    """`predisat synth --track NETWORK --where linecalfa=144` renders on the network's geometry:
    the same chainage as `predisat network` processes the survey on."""
    from predisat.track import load_track

    net = Network.from_file(gembloux)
    for lid in net.line_ids:
        alone = load_track(gembloux, where={"linecalfa": lid})
        (part,) = net.line(lid).parts
        assert track_key(alone) == track_key(part)
        assert alone.length_m == part.length_m


def test_where_filters_before_the_id_key_is_looked_for(tmp_path: Path, gembloux: Path) -> None:
    """A user trial: `--where usage=main` was refused on a siding that lacks the id key,
    which the filter would have removed."""
    doc = json.loads(gembloux.read_text())
    siding = json.loads(json.dumps(doc["features"][0]))
    siding["properties"] = {"usage": "siding"}  # no linecalfa
    for f in doc["features"]:
        f["properties"]["usage"] = "main"
    doc["features"].append(siding)
    path = tmp_path / "net.geojson"
    path.write_text(json.dumps(doc))
    with pytest.raises(TrackMapError, match="linecalfa"):
        Network.from_file(path)  # the siding lacks the key
    net = Network.from_file(path, where={"usage": "main"})
    assert sorted(ln.line_id for ln in net.lines) == ["140", "144", "161"]
    with pytest.raises(TrackMapError, match="no line feature matches where usage=spur"):
        Network.from_file(path, where={"usage": "spur"})


def test_overlapping_parts_of_a_line_are_said(tmp_path: Path, gembloux: Path) -> None:
    """A user trial drew line 144 as two overlapping pieces: two parts, processed and counted
    twice, without a word."""
    from predisat.track.network import overlapping_parts

    doc = json.loads(gembloux.read_text())
    f144 = next(f for f in doc["features"] if f["properties"]["linecalfa"] == "144")
    xy = f144["geometry"]["coordinates"]
    assert len(xy) >= 6
    second = json.loads(json.dumps(f144))
    f144["geometry"]["coordinates"] = xy[: len(xy) * 2 // 3 + 1]
    second["geometry"]["coordinates"] = xy[len(xy) // 3:]
    doc["features"].append(second)
    path = tmp_path / "net.geojson"
    path.write_text(json.dumps(doc))
    assert overlapping_parts(Network.from_file(gembloux)) == []
    net = Network.from_file(path)
    (said,) = overlapping_parts(net)
    assert said.startswith("line 144: parts 1 and 2 lie on each other over about")


def test_openstreetmap_s_notice_is_carried(tmp_path: Path, gembloux: Path) -> None:
    """A user trial: an overpass export's ODbL notice (its `copyright` member) reached neither
    the network summary nor its map, where a single track's reader carried it."""
    doc = json.loads(gembloux.read_text())
    doc.pop("attribution", None)
    doc["copyright"] = ("The data included in this document is from www.openstreetmap.org. "
                        "The data is made available under ODbL.")  # fmt: skip
    path = tmp_path / "osm.geojson"
    path.write_text(json.dumps(doc))
    net = Network.from_file(path)
    assert "OpenStreetMap contributors" in net.attribution and "ODbL" in net.attribution
