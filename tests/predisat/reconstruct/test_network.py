"""Tests of predisat.reconstruct.network on the Gembloux test network: synthetic 60 m surveys
on lines 144 and 161, none on line 140."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from predisat.camera.models import CameraModel
from predisat.masks.dataset import read_dataset_table, read_partition
from predisat.masks.fileformat import read_masks
from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.network import process_network
from predisat.reconstruct.params import PipelineParams
from predisat.track.network import Network
from tests.predisat.reconstruct.test_batch import blue_sky

CAM = CameraModel.pinhole_from_fov(160, 120, 74.0)
PARAMS = PipelineParams(chunk_m=30.0, segmenter="blue")
SURVEYED = ("144", "161")


@pytest.fixture(scope="module")
def network(test_data: Path) -> Network:
    return Network.from_file(test_data / "track" / "network_gembloux.geojson")


@pytest.fixture(scope="module")
def surveys(network: Network, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from predisat.synth.generate import generate_survey

    root = tmp_path_factory.mktemp("net")
    for k, lid in enumerate(SURVEYED):
        generate_survey(network.line(lid).parts[0], 700.0, 760.0, sky="clear", seed=3 + k,
                        out_dir=root / lid, camera=CAM, progress=False)  # fmt: skip
        (root / "surveys").mkdir(exist_ok=True)
        shutil.copytree(root / lid / "survey", root / "surveys" / lid)
    (root / "surveys" / "999").mkdir()  # a folder matching no line
    return root / "surveys"


@pytest.fixture(scope="module")
def serial_run(network: Network, surveys: Path, tmp_path_factory: pytest.TempPathFactory) -> Any:
    out = tmp_path_factory.mktemp("out")
    return process_network(network, surveys, out, PARAMS, scheduler="serial", progress=False,
                           segmenter=blue_sky)  # fmt: skip


def test_every_line_is_listed_and_the_dataset_holds_the_per_line_runs(
    network: Network, surveys: Path, serial_run: Any, tmp_path: Path
) -> None:
    res = serial_run
    assert [(r.line_id, r.status) for r in res.lines] == [
        ("144", "done"), ("161", "done"), ("140", "no survey")]  # fmt: skip
    assert "140" in res.lines[2].message and res.unmatched_surveys == ("999",)
    table = read_dataset_table(res.dataset_dir)
    assert sorted(set(table.column("line").to_pylist())) == sorted(SURVEYED)
    for lid in SURVEYED:
        # ground truth: `predisat process` of the survey alone, on the line's track
        alone = process_survey(surveys / lid, tmp_path / lid, PARAMS, progress=False,
                               segmenter=blue_sky, track=network.line(lid).parts[0])  # fmt: skip
        want = read_masks(alone.masks_path)
        got = read_partition(res.dataset_dir, lid, 1)
        assert got.n_pos == want.n_pos == 7
        for name in ("chainage_m", "lat_deg", "lon_deg", "mask_el_deg", "source", "margin_deg"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), name
        rows = [i for i, x in enumerate(table.column("line").to_pylist()) if x == lid]
        flat = np.concatenate(table.column("mask_el_deg").take(rows).to_numpy(zero_copy_only=False))
        assert np.array_equal(flat.reshape(want.mask_el_deg.shape), want.mask_el_deg)
        # the frames were matched on the line's own track: the masks lie on it
        assert np.all((want.chainage_m >= 699.0) & (want.chainage_m <= 761.0))


def test_a_finished_line_is_not_redone_a_changed_one_is(
    network: Network, surveys: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    process_network(network, surveys, out, PARAMS, scheduler="serial", progress=False,
                    segmenter=blue_sky)  # fmt: skip
    files = {lid: out / "masks" / f"line={lid}" / "part=1" / "masks.parquet" for lid in SURVEYED}
    stamp = {lid: f.stat().st_mtime_ns for lid, f in files.items()}
    again = process_network(network, surveys, out, PARAMS, scheduler="serial", progress=False,
                            segmenter=blue_sky)  # fmt: skip
    assert [r.status for r in again.lines] == ["resumed", "resumed", "no survey"]
    assert [r.n_pos for r in again.lines[:2]] == [7, 7]
    assert {lid: f.stat().st_mtime_ns for lid, f in files.items()} == stamp
    # one image of line 161 replaced (its modification time moves): that line alone is redone
    img = sorted((surveys / "161" / "images").rglob("*.*"))[0]
    st = img.stat()
    try:
        os.utime(img, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
        third = process_network(network, surveys, out, PARAMS, scheduler="serial",
                                progress=False, segmenter=blue_sky)  # fmt: skip
    finally:
        os.utime(img, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert [r.status for r in third.lines] == ["resumed", "done", "no survey"]
    assert files["144"].stat().st_mtime_ns == stamp["144"]


def test_a_broken_survey_fails_its_line_only(
    network: Network, surveys: Path, tmp_path: Path
) -> None:
    broken = tmp_path / "surveys"
    shutil.copytree(surveys, broken)
    (broken / "161" / "manifest.csv").write_text("nonsense\n")
    (broken / "140").mkdir()  # a folder for line 140, but no survey in it
    res = process_network(network, broken, tmp_path / "out", PARAMS, scheduler="serial",
                          progress=False, segmenter=blue_sky)  # fmt: skip
    assert [r.status for r in res.lines] == ["done", "failed", "no survey"]
    assert "manifest.csv" in res.lines[1].message
    assert res.lines[2].message.endswith("140 has no survey.yaml")
    with pytest.raises(ValueError, match=r"manifest\.csv"):
        process_network(network, broken, tmp_path / "out2", PARAMS, scheduler="serial",
                        progress=False, segmenter=blue_sky, strict=True)  # fmt: skip
    # a line that broke after an earlier run: its masks are withdrawn from the dataset, kept
    # (a user trial read the old masks back as the line's)
    out = tmp_path / "out4"
    process_network(network, surveys, out, PARAMS, scheduler="serial", progress=False,
                    segmenter=blue_sky)  # fmt: skip
    assert set(read_dataset_table(out / "masks")["line"].to_pylist()) == set(SURVEYED)
    res = process_network(network, broken, out, PARAMS, scheduler="serial", progress=False,
                          segmenter=blue_sky)  # fmt: skip
    assert [r.status for r in res.lines] == ["resumed", "failed", "no survey"]
    assert "withdrawn to" in res.lines[1].message
    assert set(read_dataset_table(out / "masks")["line"].to_pylist()) == {"144"}
    (kept,) = (out / "withdrawn").iterdir()  # one dated withdrawal
    assert (kept / "masks" / "line=161" / "part=1" / "masks.parquet").is_file()
    assert (kept / "lines" / "161" / "masks.parquet").is_file()
    assert not (out / "lines" / "161" / "masks.parquet").exists()
    # its survey gone altogether: the same (a survey of line 144 alone this time)
    only = tmp_path / "only144"
    shutil.copytree(surveys / "144", only / "144")
    res = process_network(network, only, out, PARAMS, scheduler="serial", progress=False,
                          segmenter=blue_sky)  # fmt: skip
    assert [r.status for r in res.lines] == ["resumed", "no survey", "no survey"]
    assert "withdrawn" not in res.lines[1].message  # withdrawn already: nothing left
    shutil.rmtree(only / "144")
    res = process_network(network, only, out, PARAMS, scheduler="serial", progress=False,
                          segmenter=blue_sky)  # fmt: skip
    assert "withdrawn to" in res.lines[0].message
    assert not (out / "masks" / "line=144").exists()
    with pytest.raises(FileNotFoundError, match="no such surveys folder"):
        process_network(network, tmp_path / "none", tmp_path / "out3", PARAMS)


@pytest.mark.slow
def test_dask_workers_write_the_serial_bytes(
    network: Network, surveys: Path, serial_run: Any, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    a = process_network(network, surveys, tmp_path / "a", PARAMS, scheduler="serial",
                        progress=False, segmenter=blue_sky)  # fmt: skip
    b = process_network(network, surveys, tmp_path / "b", PARAMS, scheduler="local", workers=2,
                        progress=False, segmenter=blue_sky)  # fmt: skip
    assert [r.status for r in b.lines] == [r.status for r in a.lines]
    for r, s in zip(a.lines[:2], b.lines[:2], strict=True):
        assert r.masks_path is not None and s.masks_path is not None
        assert r.masks_path.read_bytes() == s.masks_path.read_bytes()


@pytest.mark.slow
def test_a_cluster_worker_stamps_the_clients_pinned_time(
    network: Network, surveys: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """A user trial: with SOURCE_DATE_EPOCH set for the command and not on the cluster's
    workers, each line's provenance carried the worker's clock (the masks were the same).
    Here the worker has another pinned time (an empty one breaks a library's import)."""
    from distributed import LocalCluster

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    a = process_network(network, surveys, tmp_path / "a", PARAMS, scheduler="serial",
                        progress=False, segmenter=blue_sky)  # fmt: skip
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0",
                      env={"SOURCE_DATE_EPOCH": "1600000000"}) as cluster:  # fmt: skip
        b = process_network(network, surveys, tmp_path / "b", PARAMS,
                            scheduler=cluster.scheduler_address, progress=False,
                            segmenter=blue_sky)  # fmt: skip
    done = [(r, s) for r, s in zip(a.lines, b.lines, strict=True) if r.masks_path is not None]
    assert done
    for r, s in done:
        assert s.masks_path is not None
        assert r.masks_path.read_bytes() == s.masks_path.read_bytes()


def test_a_survey_is_refused_on_a_network_track_that_leaves_its_own(
    test_data: Path, surveys: Path, tmp_path: Path
) -> None:
    import json

    from predisat.geodesy import WGS84

    # the surveys were rendered on the file fitted within its 10 m simplification (and name
    # that track in their survey.yaml); fitted within 1 m, the curve follows the simplified
    # polyline's corners, metres and degrees away where the frames were taken
    doc = json.loads((test_data / "track" / "network_gembloux.geojson").read_text())
    doc["tolerance_m"] = 1.0
    (tmp_path / "tight.geojson").write_text(json.dumps(doc))
    tight = Network.from_file(tmp_path / "tight.geojson")
    own = Network.from_file(test_data / "track" / "network_gembloux.geojson")
    a, b = own.line("144").parts[0], tight.line("144").parts[0]
    ch = np.arange(700.0, 761.0, 5.0)
    (lat_a, lon_a, _), (lat_b, lon_b, _) = a.position_at(ch), b.position_at(ch)
    assert np.max(WGS84.inv(lon_a, lat_a, lon_b, lat_b)[2]) > 5.0  # independent: PROJ
    res = process_network(tight, surveys, tmp_path / "out", PARAMS, scheduler="serial",
                          progress=False, segmenter=blue_sky)  # fmt: skip
    by_line = {r.line_id: r for r in res.lines}
    for lid in SURVEYED:
        assert by_line[lid].status == "failed", lid
        assert "leaves the survey's own track" in by_line[lid].message
        assert "--tolerance-m" in by_line[lid].message
    # `predisat process --track` takes the same check: refused before any work
    with pytest.raises(ValueError, match="leaves the survey's own track"):
        process_survey(surveys / "144", tmp_path / "alone", PARAMS, track=b, progress=False,
                       segmenter=blue_sky)  # fmt: skip
    assert not (tmp_path / "alone" / "masks.parquet").exists()


def test_a_line_s_processing_warnings_name_the_line(
    network: Network, surveys: Path, tmp_path: Path
) -> None:
    """A user trial: the raised-horizon warning of one line was printed bare among the
    others', and kept nowhere. Now each line's warnings are its result's message (the
    summary's `message` column), the same when it is resumed."""
    from predisat.reconstruct.batch import source_report

    out = tmp_path / "out"
    res = process_network(network, surveys, out, PARAMS, scheduler="serial", progress=False,
                          segmenter=blue_sky)  # fmt: skip
    for r in res.lines[:2]:
        own = [ln for ln in source_report(read_masks(r.masks_path), track=network.line(
               r.line_id).parts[0]) if ln.startswith("warning")]  # fmt: skip
        assert bool(r.message) == bool(own)
        # each warning's chainage stretch is in the line's message, and the fix names the
        # command that has the option (`predisat network` takes no elevation tiles)
        for ln in own:
            assert ln.split(":")[1].strip() in r.message
        assert "(--dem)" not in r.message and "(process --dem" not in r.message
        if "elevation tiles" in r.message:
            assert "predisat process --dem" in r.message
    again = process_network(network, surveys, out, PARAMS, scheduler="serial", progress=False,
                            segmenter=blue_sky)  # fmt: skip
    assert [r.message for r in again.lines[:2]] == [r.message for r in res.lines[:2]]
    assert any(r.message for r in res.lines[:2])  # these short pinhole surveys assume much


def test_a_full_disk_stops_the_run_instead_of_failing_a_line(
    network: Network, surveys: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A full disk inside a line's processing was reported as that line "failed" (and that an
    earlier run's masks were withdrawn, in a fresh folder), and the run exited 0."""
    import errno

    import predisat.reconstruct.network as net

    def full(*args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", "/x/.masks.a1b2c3d4.parquet")

    monkeypatch.setattr(net, "process_survey", full)
    with pytest.raises(OSError, match="No space left") as info:
        process_network(network, surveys, tmp_path / "out", PARAMS, scheduler="serial",
                        progress=False, segmenter=blue_sky)  # fmt: skip
    assert info.value.errno == errno.ENOSPC
    assert not (tmp_path / "out" / "withdrawn").exists()
