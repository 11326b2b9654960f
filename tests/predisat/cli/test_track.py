"""``predisat track``: a track map shown as a selection gives it, and written alone (a user
trial on another line: there was no command to make or look at one's own map)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from pyproj import Geod

from predisat.cli import app as cli

GEOD = Geod(ellps="WGS84")
RIVIERA = "track/riviera_andora_alassio.geojson"
SELECT = ["--where", "usage=main", "service=", "--chain", "longest"]


def _length_m(text: str) -> float:
    m = re.search(r"([0-9,]+\.[0-9]) m of chainage", text)
    assert m is not None, text
    return float(m.group(1).replace(",", ""))


def test_a_selected_line_is_summed_up_drawn_and_written_alone(test_data, tmp_path, capsys):
    src = test_data / RIVIERA
    out, fig = tmp_path / "line.geojson", tmp_path / "line.png"
    assert cli.main(["track", str(src), *SELECT, "--out", str(out), "--figure", str(fig)]) == 0
    text = capsys.readouterr().out
    # the length is the chained ways' own (a geodesic sum over the written vertices, pyproj)
    doc = json.loads(out.read_text())
    (line,) = [f for f in doc["features"] if f["geometry"]["type"] == "LineString"]
    c = np.array(line["geometry"]["coordinates"], float)
    length_m = _length_m(text)
    assert length_m == pytest.approx(GEOD.line_length(c[:, 0], c[:, 1]), rel=5e-4)
    # the OSM stop positions on the line are listed with their chainage, nearly on the axis
    for name in ("Alassio", "Laigueglia"):
        assert re.search(rf"{name} \([0-9,]+ m, [0-9] m beside\)", text), text
    assert "heights: none" in text and re.search(r"tunnels: [1-9]", text)
    # read back with --track alone: the same line, tunnels and bridges, no selection needed
    capsys.readouterr()
    assert cli.main(["track", str(out)]) == 0
    again = capsys.readouterr().out
    for label in ("tunnels", "bridges", "stations"):
        assert re.search(rf"^{label}: .*$", again, re.M).group(0) == re.search(  # type: ignore[union-attr]
            rf"^{label}: .*$", text, re.M).group(0)  # type: ignore[union-attr]  # fmt: skip
    assert _length_m(again) == pytest.approx(length_m, abs=0.05)
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_network_without_a_selection_is_refused_with_the_fix(test_data, tmp_path, capsys):
    out = tmp_path / "line.geojson"
    assert cli.main(["track", str(test_data / RIVIERA), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "FILE" in err and "cannot chain" in err
    # the OSM ways carry usage/service: the selection the docs give is said (a user trial)
    assert "--where usage=main service= --chain longest" in err
    assert not out.exists()


def test_the_figure_draws_plan_heights_and_radii_with_the_tunnels(test_data):
    from predisat.track import TrackMap
    from predisat.track.figure import track_figure

    tm = TrackMap.from_geojson(test_data / RIVIERA, where={"usage": "main", "service": None},
                               chain="longest")  # fmt: skip
    fig = track_figure(tm)
    plan = fig.axes[0]
    assert plan.get_aspect() == 1.0
    # one thick red line per tunnel on the plan, one red band per tunnel on each profile
    red = [ln for ln in plan.get_lines() if ln.get_color() == "#b2182b"]
    assert len(red) == len(tm.tunnels_m) > 0
    with pytest.raises(ValueError, match="step_m"):
        track_figure(tm, step_m=0.0)


def _demo_file():
    from importlib import resources

    from predisat.track.map import DEMO_TRACK_FILE

    return resources.files("predisat") / "data" / DEMO_TRACK_FILE


def test_a_station_beyond_an_end_is_said_off_the_map(capsys):
    # line 144's GEMBLOUX lies 540 m before the map's start (pyproj over the vertices): it
    # read "GEMBLOUX (0 m, 41 m beside)", as if on the line (a user trial)
    assert cli.main(["track", str(_demo_file())]) == 0
    text = capsys.readouterr().out
    m = re.search(r"GEMBLOUX \(off the map: ([0-9,]+) m before the start\)", text)
    assert m is not None, text
    assert 500 < float(m.group(1).replace(",", "")) < 580
    assert re.search(r"JEMEPPE/S-M \(off the map: [0-9,]+ m past the end\)", text), text
    assert re.search(r"JEMEPPE-FR\.M \(13,0[0-9]{2} m, 0 m beside\)", text), text


def test_kilometre_posts_from_line_sections_are_shown_and_written(tmp_path, capsys):
    demo = json.loads(_demo_file().read_text())
    (line,) = [f for f in demo["features"] if f["geometry"]["type"] == "LineString"]
    bare = {"type": "FeatureCollection", "features": [line]}
    track, sections = tmp_path / "axis.geojson", tmp_path / "sections.geojson"
    track.write_text(json.dumps(bare))
    section = {"type": "Feature", "geometry": line["geometry"],
               "properties": {"mfrom": -250, "mto": 13900, "ptcarfromname": "A",
                              "ptcartoname": "B"}}  # fmt: skip
    sections.write_text(json.dumps({"type": "FeatureCollection", "features": [section]}))
    assert cli.main(["track", str(track)]) == 0
    assert "--posts-from" in capsys.readouterr().out  # the hint where there are none
    out = tmp_path / "with_posts.geojson"
    assert cli.main(["track", str(track), "--posts-from", str(sections), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert re.search(r"kilometre posts: 1[5-6], km -0.25 at 0 m to km 13.9 at 14,171 m", text), text
    assert "km -0 " not in text
    assert cli.main(["track", str(out)]) == 0  # the written map keeps them
    assert re.search(r"kilometre posts: 1[5-6], km -0.25", capsys.readouterr().out)
    far = tmp_path / "far.geojson"
    far_line = {"type": "LineString", "coordinates": [[8.0, 44.0], [8.01, 44.0]]}
    far_section = {"type": "Feature", "properties": {"mfrom": 0, "mto": 1000}, "geometry": far_line}
    far.write_text(json.dumps({"type": "FeatureCollection", "features": [far_section]}))
    assert cli.main(["track", str(track), "--posts-from", str(far)]) == 2
    assert "no line section" in capsys.readouterr().err


def _shared_tracknames(tmp_path):
    """Two lines, tracks A and B of each, as in Infrabel's national file (trackname shared)."""
    feats = []
    for line, lat in ((1, 50.0), (2, 50.2)):
        for track, dlon in (("A", 0.0), ("B", 0.0001)):
            lon = 4.0 + dlon + np.linspace(0.0, 0.02, 11)
            feats.append({"type": "Feature",
                          "properties": {"trackname": track, "trackcode": f"L {line}_{track}",
                                         "linecalfa": str(line)},
                          "geometry": {"type": "LineString",
                                       "coordinates": np.column_stack(
                                           [lon, np.full(11, lat)]).tolist()}})  # fmt: skip
    path = tmp_path / "network.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "name": "network",
                                "features": feats}))  # fmt: skip
    return path


def test_a_trackname_shared_by_lines_says_which_key_tells_them_apart(tmp_path, capsys):
    path = _shared_tracknames(tmp_path)
    assert cli.main(["track", str(path)]) == 2
    err = capsys.readouterr().err
    assert "several tracks (trackname: A, B)" in err
    assert "trackcode tells them apart" in err and "--track-name 'L 1_A'" in err
    assert cli.main(["track", str(path), "--track-name", "L 2_A"]) == 0
    assert capsys.readouterr().out.startswith("network, track L 2_A (A): ")


def test_a_longest_chain_is_named_after_the_lines_it_chained(tmp_path, capsys):
    # --track-name A --chain longest of Infrabel's national file chained lines 161 and 162 and
    # was named after the 163 track-A features selected (1 430 characters, a user trial)
    path = _shared_tracknames(tmp_path)
    assert cli.main(["track", str(path), "--track-name", "A", "--chain", "longest"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert re.match(r"network, track A \(L [12]_A\): ", first), first


def test_an_unknown_name_or_key_is_answered_with_what_the_file_holds(test_data, tmp_path, capsys):
    # Infrabel's national file answered --track-name "L 144" with its first 20 track codes in
    # alphabetical order (L 01_1 ... L 11/1_1), --where line=144 without saying that no
    # feature has a "line", and the Riviera's OSM ways with "(no names)" (a user trial)
    path = _shared_tracknames(tmp_path)
    assert cli.main(["track", str(path), "--track-name", "L 2"]) == 2
    assert "available (nearest first): trackcode=L 2_A, trackcode=L 2_B" in capsys.readouterr().err
    assert cli.main(["track", str(path), "--where", "line=2"]) == 2
    err = capsys.readouterr().err
    assert "no line feature has the property 'line'" in err and "linecalfa" in err
    assert cli.main(["track", str(test_data / RIVIERA), "--track-name", "Genova"]) == 2
    err = capsys.readouterr().err
    assert "the lines carry no name" in err and "usage=main" in err and "service=" in err


def test_the_smallest_curve_is_said_and_a_coarse_source_gets_a_wider_tolerance(
    test_data, tmp_path, capsys
):
    """A user trial: Infrabel's 10 m simplification of line 144 read a smallest radius of 88 m
    (the 1 m file: 399 m), with no word and no way to widen the fit's tolerance."""
    from predisat.track import TrackMap

    src = test_data / RIVIERA
    assert cli.main(["track", str(src), *SELECT]) == 0
    text = capsys.readouterr().out
    m = re.search(r"curves: smallest radius ([0-9,]+) m at ([0-9,]+) m", text)
    assert m is not None, text
    # against the circle through three axis points 10 m apart around the place (geometry of
    # the fitted axis, not its curvature formula)
    tm = TrackMap.from_geojson(src, where={"usage": "main", "service": None}, chain="longest")
    at = float(m.group(2).replace(",", ""))
    p = tm.enu_at(np.clip([at - 10.0, at, at + 10.0], 0.0, tm.length_m))[:, :2]
    a, b, c = (np.linalg.norm(p[i] - p[j]) for i, j in ((0, 1), (1, 2), (0, 2)))
    (u, v), (w, z) = p[1] - p[0], p[2] - p[0]
    area2 = abs(u * z - v * w)
    assert float(m.group(1).replace(",", "")) == pytest.approx(a * b * c / (2.0 * area2), rel=0.05)
    out = tmp_path / "wide.geojson"
    assert cli.main(["track", str(src), *SELECT, "--tolerance", "5", "--out", str(out)]) == 0
    wide = capsys.readouterr().out
    dev = float(re.search(r"stays within ([0-9.]+) m of them \(tolerance 5 m\)", wide).group(1))
    assert dev <= 5.0 + 0.05
    # the written map keeps its tolerance; another one on reading fits another line, on which
    # the written tunnels would stand elsewhere: refused, naming the tolerance
    assert "(tolerance 5 m)" in (cli.main(["track", str(out)]), capsys.readouterr().out)[1]
    assert cli.main(["track", str(out), "--tolerance", "1"]) == 2
    assert "another fit tolerance" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["track", str(out), "--tolerance", "0"])
    assert "--tolerance: 0 must be above 0" in capsys.readouterr().err


def test_a_selection_on_a_csv_map_is_refused_not_ignored(tmp_path, capsys):
    """A user trial: --track-name and --where on a CSV map (one line) were silently ignored."""
    path = tmp_path / "line.csv"
    path.write_text("lat_deg,lon_deg\n50.5,4.70\n50.5,4.72\n50.5,4.74\n")
    assert cli.main(["track", str(path), "--track-name", "A", "--where", "usage=main"]) == 2
    err = capsys.readouterr().err
    assert "a CSV track map holds one line" in err and "drop --track-name, --where" in err
    assert cli.main(["track", str(path)]) == 0
    # one post labels the kilometre around it, said so (not "km 80 ... to km 80")
    from predisat.cli.track import summary_lines
    from predisat.track import KilometrePost, TrackMap

    tm = TrackMap.from_csv(path).with_metadata(kilometre_posts=[KilometrePost(500.0, 80_000.0)])
    (line,) = [x for x in summary_lines(tm) if x.startswith("kilometre posts")]
    assert line == "kilometre posts: 1, km 80 at 500 m (it labels the kilometre around it only)"


def test_a_stretch_is_said_in_chainage_and_in_the_line_s_kilometres():
    """A user trial read --from-km as the line's kilometre: on line 144 the post "km 1.000"
    stands at chainage 964 m (the Infrabel line sections), so chainage 1-3 km is km 1.04-3.0."""
    from dataclasses import replace

    from predisat.cli.common import stretch_text
    from predisat.track import demo_track

    track = demo_track()
    post = next(p for p in track.kilometre_posts if p.km_m == 1000.0)
    text = stretch_text(track, post.chainage_m, 3000.0)
    assert text.startswith(f"chainage {post.chainage_m / 1000:.3f}-3.000 km (line km 1.000-")
    bare = replace(track, kilometre_posts=())
    assert stretch_text(bare, 1000.0, 3000.0) == "chainage 1.000-3.000 km"
