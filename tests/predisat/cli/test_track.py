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
    assert "--track" in err and "cannot chain" in err
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
