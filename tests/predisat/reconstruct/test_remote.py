"""``predisat process`` on fsspec URLs: a survey served over HTTP (loopback) or held in
``memory://``, outputs to ``memory://``; compared with the run on local folders."""

from __future__ import annotations

import io
import json
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

import fsspec
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from predisat.camera.models import CameraModel
from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.params import PipelineParams
from predisat.survey import SurveyError
from tests.predisat.http_folder import serve_folder
from tests.predisat.reconstruct.test_batch import blue_sky

CAM = CameraModel.pinhole_from_fov(160, 120, 74.0)
PARAMS = PipelineParams(chunk_m=30.0, segmenter="blue")  # 3 chunks over 3000..3060 m
MEMORY = fsspec.filesystem("memory")


@pytest.fixture(scope="module")
def survey_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    out = tmp_path_factory.mktemp("synth")
    generate_survey(
        demo_track(), 3000.0, 3060.0, sky="clear", seed=3, out_dir=out, camera=CAM,
        progress=False,
    )  # fmt: skip
    return out / "survey"


@pytest.fixture
def mem() -> Iterator[str]:
    root = f"memory://process-{uuid.uuid4().hex[:8]}"
    yield root
    if MEMORY.exists(root.removeprefix("memory://")):
        MEMORY.rm(root.removeprefix("memory://"), recursive=True)


@pytest.fixture
def local_run(survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The run on local folders, timestamps pinned (SOURCE_DATE_EPOCH)."""
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    process_survey(survey_dir, tmp_path / "local", PARAMS, progress=False, segmenter=blue_sky)
    return tmp_path / "local"


def _published(out: Path) -> list[str]:
    """The files a run publishes (not the cache, not the timings of provenance.json)."""
    chunks = sorted(p.name for p in (out / "chunks").iterdir())
    assert len(chunks) == 6
    return ["masks.parquet", "bad_frames.csv", *(f"chunks/{n}" for n in chunks)]


def test_outputs_to_memory_are_the_bytes_of_the_local_run(
    survey_dir: Path, local_run: Path, mem: str
) -> None:
    res = process_survey(survey_dir, f"{mem}/out", PARAMS, progress=False, segmenter=blue_sky)
    assert res.masks_path == f"{mem}/out/masks.parquet" and res.chunks_done == 3
    for name in _published(local_run):
        assert MEMORY.cat_file(f"{mem}/out/{name}") == (local_run / name).read_bytes(), name
    # a rerun resumes from the chunks and the cache in memory://
    again = process_survey(survey_dir, f"{mem}/out", PARAMS, progress=False,
                           segmenter=blue_sky)  # fmt: skip
    assert (again.chunks_done, again.chunks_skipped, again.frames_segmented) == (0, 3, 0)


def _ipc_bytes(table: pa.Table) -> bytes:
    """A table's columns as Arrow IPC bytes, without its metadata."""
    sink = pa.BufferOutputStream()
    stripped = table.replace_schema_metadata(None)
    with pa.ipc.new_stream(sink, stripped.schema) as writer:
        writer.write_table(stripped)
    return sink.getvalue().to_pybytes()


def _same_except_location(
    local: Path, remote: bytes, survey: str, local_survey: Path, name: str
) -> None:
    """A file of the URL run holds what the local run's holds, with the survey named by its
    URL (and, in the chunk markers, the images stamped by size and HTTP headers)."""
    want = (local / name).read_bytes()
    if name.endswith(".csv"):
        assert remote == want
        return
    if name.endswith(".json"):
        a, b = json.loads(want), json.loads(remote)
        assert b.pop("survey") == survey and a.pop("survey") == str(local_survey)
        assert a.pop("frames_key") != b.pop("frames_key")
        assert a == b
        return
    ta, tb = pq.read_table(local / name), pq.read_table(io.BytesIO(remote))
    assert _ipc_bytes(tb) == _ipc_bytes(ta)  # the columns, bit for bit (NaN included)
    ma = json.loads(ta.schema.metadata[b"predisat"])
    mb = json.loads(tb.schema.metadata[b"predisat"])
    assert mb["provenance"].pop("survey") == survey
    ma["provenance"].pop("survey")
    assert ma == mb


def test_survey_over_http_gives_the_local_runs_masks(
    survey_dir: Path, local_run: Path, tmp_path: Path, mem: str
) -> None:
    with serve_folder(survey_dir) as url:
        res = process_survey(url, f"{mem}/out", PARAMS, progress=False, segmenter=blue_sky)
        assert res.n_frames == 14 and res.frames_segmented == 14 and res.bad_frames == ()
        for name in _published(local_run):
            remote = MEMORY.cat_file(f"{mem}/out/{name}")
            _same_except_location(local_run, remote, url, survey_dir, name)
        # resumed: the HTTP stamps (size, Last-Modified) of the images have not changed
        again = process_survey(url, f"{mem}/out", PARAMS, progress=False, segmenter=blue_sky)
        assert (again.chunks_done, again.chunks_skipped) == (0, 3)


def test_missing_remote_files_name_the_url_and_the_fix(
    survey_dir: Path, tmp_path: Path, mem: str
) -> None:
    copy = tmp_path / "survey"
    shutil.copytree(survey_dir, copy)
    gone = sorted((copy / "images").rglob("*.jpg"))[3]
    gone.unlink()
    with serve_folder(copy) as url:
        res = process_survey(url, f"{mem}/out", PARAMS, progress=False, segmenter=blue_sky)
        (bad,) = res.bad_frames
        rel = gone.relative_to(copy).as_posix()
        assert f"image {url}/{rel} is missing; restore it or drop the frame" in bad.message
        with pytest.raises(SurveyError) as err:
            process_survey(f"{url}/elsewhere", f"{mem}/out2", PARAMS, progress=False,
                           segmenter=blue_sky)  # fmt: skip
        text = str(err.value)
        assert f"{url}/elsewhere/survey.yaml: no such file" in text
        assert "check the URL" in text


def test_memory_urls_are_refused_with_worker_processes(survey_dir: Path, mem: str) -> None:
    with pytest.raises(ValueError, match="memory:// lives in this process"):
        process_survey(survey_dir, f"{mem}/out", PARAMS, progress=False, scheduler="local",
                       workers=2, segmenter=blue_sky)  # fmt: skip


def test_command_line_takes_urls(
    survey_dir: Path, local_run: Path, mem: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from predisat.cli.app import main

    with serve_folder(survey_dir) as url:
        argv = ["process", url, "--out", f"{mem}/cli", "--scheduler", "serial", "--quiet",
                "--chunk-m", "30", "--storage-options", "{}"]
        assert main(argv) == 0, capsys.readouterr().err
    assert MEMORY.exists(f"{mem.removeprefix('memory://')}/cli/masks.parquet")
    with pytest.raises(SystemExit) as stop:  # argparse refuses it
        main(["process", str(survey_dir), "--out", "x", "--storage-options", "[1]"])
    assert stop.value.code == 2
    assert "is not a JSON object" in capsys.readouterr().err


@pytest.mark.slow
def test_dask_workers_read_the_survey_from_its_url(
    survey_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The tasks get URLs and storage options, not files: worker processes read the frames
    over HTTP themselves, with the token the options give, and write the serial run's bytes."""
    from distributed import LocalCluster

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    opts = {"client_kwargs": {"headers": {"Authorization": "Bearer s3cret"}}}
    with serve_folder(survey_dir, token="s3cret") as url:
        with pytest.raises(SurveyError, match=r"survey\.yaml"):  # no token: refused (401)
            process_survey(url, tmp_path / "x", PARAMS, progress=False, segmenter=blue_sky)
        process_survey(url, tmp_path / "serial", PARAMS, progress=False, segmenter=blue_sky,
                       storage_options=opts)  # fmt: skip
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address="127.0.0.1:0") as cluster:  # fmt: skip
            res = process_survey(url, tmp_path / "dask", PARAMS, progress=False,
                                 segmenter=blue_sky, scheduler=cluster.scheduler_address,
                                 storage_options=opts)  # fmt: skip
    assert res.frames_segmented == 14 and res.chunks_done == 3 and res.bad_frames == ()
    for name in _published(tmp_path / "serial"):
        assert (tmp_path / "dask" / name).read_bytes() == (
            tmp_path / "serial" / name
        ).read_bytes(), name
