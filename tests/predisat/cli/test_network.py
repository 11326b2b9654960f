"""``predisat network`` end to end on the Gembloux test network (two 60 m synthetic surveys,
one line without a survey): dataset, one report per line, summary; bad network files."""

from __future__ import annotations

import html
import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from predisat.availability.run import run_availability
from predisat.camera.models import CameraModel
from predisat.cli.app import main
from predisat.masks.fileformat import read_masks
from predisat.track.network import Network

CAM = CameraModel.pinhole_from_fov(160, 120, 74.0)
WINDOW = ["--start", "2020-06-25T06:00", "--end", "2020-06-25T08:00", "--step", "600"]


@pytest.fixture(scope="module")
def network_file(test_data: Path) -> Path:
    return test_data / "track" / "network_gembloux.geojson"


@pytest.fixture(scope="module")
def surveys(network_file: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from predisat.synth.generate import generate_survey

    net = Network.from_file(network_file)
    root = tmp_path_factory.mktemp("cli-net")
    for k, lid in enumerate(("144", "161")):
        generate_survey(net.line(lid).parts[0], 300.0, 360.0, sky="clear", seed=5 + k,
                        out_dir=root / lid, camera=CAM, progress=False)  # fmt: skip
        shutil.copytree(root / lid / "survey", root / "surveys" / lid)
    return root / "surveys"


def test_network_command_writes_dataset_reports_and_summary(
    network_file: Path, surveys: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = ["network", str(network_file), "--surveys", str(surveys), "--out", str(out),
            "--scheduler", "serial", "--chunk-m", "30", "--segmenter", "grabcut", "--quiet",
            *WINDOW]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "line 140 part 1: no survey" in printed
    table = pd.read_csv(out / "summary.csv", dtype={"line_id": str})
    assert table.line_id.tolist() == ["144", "161", "140"]
    assert table.status.tolist() == ["done", "done", "no survey"]
    net = Network.from_file(network_file)
    for row in table.itertuples():
        if row.status != "done":
            assert pd.isna(row.share_ge4_masks) and not isinstance(row.report, str)
            continue
        # ground truth: `predisat availability`'s library call on the line's partition
        alone = run_availability(out / f"masks/line={row.line_id}/part=1/masks.parquet",
                                 net.line(row.line_id).parts[0], out_dir=tmp_path / row.line_id,
                                 start="2020-06-25T06:00", end="2020-06-25T08:00", step_s=600.0,
                                 scheduler="serial", progress=False)  # fmt: skip
        masks_row, cut_row = alone.summary.iloc[0], alone.summary.iloc[2]
        assert row.share_ge4_masks == pytest.approx(masks_row.share_ge4, abs=1e-6)
        assert row.share_ge4_cutoff == pytest.approx(cut_row.share_ge4, abs=1e-6)
        assert row.n_pos == masks_row.n_pos == 7
        ch = read_masks(out / f"masks/line={row.line_id}/part=1/masks.parquet").chainage_m
        assert (row.from_m, row.to_m) == (ch[0], ch[-1])
        assert row.surveyed_km == pytest.approx((ch[-1] - ch[0]) / 1000.0)
        assert (out / row.report).is_file()
    assert (out / "network_map.png").stat().st_size > 10_000
    md = (out / "summary.md").read_text()
    assert "| 140 | 1 | no survey |" in md and "availability/144/report.html" in md
    # what the figures rest on, said in the summary itself (it is read without the reports)
    info = json.loads((out / "availability/144/summary.json").read_text())["run"]
    for said in (f"Satellites counted: {info['constellation']}", f"Window: {info['window']}",
                 f"Navigation: {info['navigation']}"):  # fmt: skip
        assert said in md and html.escape(said) in (out / "summary.html").read_text()
    assert info["synthetic"] and all(f"Synthetic data: {n}" in md for n in info["synthetic"])
    marker = json.loads((out / "availability/144/network.json").read_text())
    # a rerun redoes nothing: the reports' markers and files stay
    stamp = (out / "availability/144/report.html").stat().st_mtime_ns
    assert main(argv) == 0
    assert "0 processed, 2 already done" in capsys.readouterr().out
    assert (out / "availability/144/report.html").stat().st_mtime_ns == stamp
    assert json.loads((out / "availability/144/network.json").read_text()) == marker
    # a report made by other code (a development install, one version) is made again: a
    # review found a rerun skipping the new refusals and warnings
    assert marker["key"]["code_fingerprint"]
    marker["key"]["code_fingerprint"] = "0" * 16
    (out / "availability/144/network.json").write_text(json.dumps(marker))
    assert main(argv) == 0
    assert (out / "availability/144/report.html").stat().st_mtime_ns != stamp


def test_bad_network_file_is_refused_with_its_name(
    tmp_path: Path, surveys: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "lines.geojson"
    bad.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": "x"},
         "geometry": {"type": "LineString", "coordinates": [[4.6, 50.5], [4.7, 50.5]]}}]}))
    code = main(["network", str(bad), "--surveys", str(surveys), "--out", str(tmp_path / "o"),
                 "--scheduler", "serial"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "lines.geojson: no property names the lines" in err and "--id-key" in err
    code = main(["network", str(bad), "--surveys", str(surveys), "--out", str(tmp_path / "o"),
                 "--id-key", "name", "--lines", "y", "--scheduler", "serial"])  # fmt: skip
    assert code == 2 and "no line 'y'" in capsys.readouterr().err


def test_a_line_with_bad_track_data_is_left_out_and_said(
    tmp_path: Path, test_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A user trial: a line with swapped coordinates was left out with exit 0, said only in
    the summary's "Left out" section."""
    doc = json.loads((test_data / "track" / "network_gembloux.geojson").read_text())
    bad = next(f for f in doc["features"] if f["properties"].get("linecalfa") == "161")
    bad["geometry"]["coordinates"] = [[c[1], c[0], *c[2:]] for c in
                                      bad["geometry"]["coordinates"]]  # fmt: skip
    path = tmp_path / "net.geojson"
    path.write_text(json.dumps(doc))
    (tmp_path / "surveys").mkdir()
    code = main(["network", str(path), "--surveys", str(tmp_path / "surveys"), "--out",
                 str(tmp_path / "o"), "--scheduler", "serial", "--no-availability",
                 "-q"])  # fmt: skip
    assert code == 0
    err = capsys.readouterr().err
    assert "predisat network: warning: line 161 left out:" in err
