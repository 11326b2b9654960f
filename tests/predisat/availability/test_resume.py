"""``predisat availability``: saved blocks, an interrupted run resumed, URL inputs/outputs."""

from __future__ import annotations

import io
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import fsspec
import numpy as np
import pyarrow.parquet as pq
import pytest

from predisat.availability import engine
from predisat.availability.engine import BlockCheckpoint
from predisat.availability.run import run_availability
from predisat.availability.satellites import (
    LinePositions,
    SatellitePositions,
    TrustRule,
    default_ephemeris,
    default_window,
)
from predisat.masks.fileformat import write_masks
from predisat.masks.maskset import MaskSet
from predisat.track.map import TrackMap, demo_track
from tests.predisat.http_folder import serve_folder

START, END, STEP_S = "2020-06-25T06:00", "2020-06-25T07:00", 300.0
MEMORY = fsspec.filesystem("memory")
# 201 positions: 4 blocks of up to 64 per rule, 3 rules (masks, no mask, cut-off 15 deg)
N_BLOCKS = 12
BLOCK_TASK = engine.block_task


def _masks(track: TrackMap, wall_deg: float = 60.0) -> MaskSet:
    """10 deg everywhere, a wall over 4100-4200 m on the left."""
    ch = np.arange(4000.0, 4400.1, 2.0)
    az = np.arange(72) * 5.0
    rel = (az[None, :] - (track.heading_at(ch)[:, None] - 90.0) + 180.0) % 360.0 - 180.0
    wall = (ch[:, None] >= 4100.0) & (ch[:, None] <= 4200.0) & (np.abs(rel) <= 60.0)
    return MaskSet.from_track(track, ch, np.where(wall, wall_deg, 10.0), az_step_deg=5.0)


@pytest.fixture(scope="module")
def track() -> TrackMap:
    return demo_track()


@pytest.fixture
def mask_file(tmp_path: Path, track: TrackMap) -> Path:
    return write_masks(_masks(track), tmp_path / "m.masks.parquet")


def _run(masks: Any, out: Any, progress: bool = False, **kw: Any) -> Any:
    return run_availability(
        masks, None, None, out_dir=out, start=START, end=END, step_s=STEP_S, n_sky=1,
        interval_every=2, progress=progress, scheduler="serial", **kw,
    )  # fmt: skip


def _files(out: Path) -> dict[str, bytes]:
    """The outputs (not the lock file, which names the process that wrote them)."""
    from predisat.atomic import LOCK_NAME

    return {p.name: p.read_bytes() for p in sorted(out.iterdir())
            if p.is_file() and p.name != LOCK_NAME}  # fmt: skip


class _Blocks:
    """engine.block_task, counting the blocks it computes and failing at the n-th."""

    def __init__(self, fail_at: int | None = None) -> None:
        self.done: list[int] = []
        self.fail_at = fail_at

    def __call__(self, shared: Any, block: Any) -> Any:
        if self.fail_at is not None and len(self.done) + 1 == self.fail_at:
            raise RuntimeError("killed mid-run")
        self.done.append(block.a)
        return BLOCK_TASK(shared, block)


def test_an_interrupted_run_resumes_without_redoing_finished_blocks(
    tmp_path: Path, mask_file: Path, track: TrackMap, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    whole = _Blocks()
    monkeypatch.setattr(engine, "block_task", whole)
    _run(mask_file, tmp_path / "whole")
    assert len(whole.done) == N_BLOCKS
    assert not (tmp_path / "whole" / "blocks").exists()  # deleted once the outputs are written
    want = _files(tmp_path / "whole")

    broken = _Blocks(fail_at=7)
    monkeypatch.setattr(engine, "block_task", broken)
    with pytest.raises(RuntimeError, match="killed mid-run"):
        _run(mask_file, tmp_path / "resumed")
    saved = sorted((tmp_path / "resumed" / "blocks").rglob("*.npz"))
    assert len(saved) == 6 == len(broken.done)
    assert not (tmp_path / "resumed" / "report.html").exists()
    # a torn block (a power cut after its rename) is computed again, not read
    saved[-1].write_bytes(saved[-1].read_bytes()[:100])

    again = _Blocks()
    monkeypatch.setattr(engine, "block_task", again)
    capsys.readouterr()
    res = _run(mask_file, tmp_path / "resumed", progress=True)
    assert len(again.done) == N_BLOCKS - 5
    assert [r.provenance["blocks_resumed"] for r in res.results] == [4, 1, 0]
    # and says so (a user could not tell a resume from a fresh run)
    err = capsys.readouterr().err
    assert "4 of " in err and "1 of " in err and "blocks resumed from the checkpoint" in err
    assert _files(tmp_path / "resumed") == want  # every output, byte for byte
    assert not (tmp_path / "resumed" / "blocks").exists()


def test_blocks_saved_from_other_inputs_are_not_taken(
    tmp_path: Path, track: TrackMap, monkeypatch: pytest.MonkeyPatch
) -> None:
    t = default_window(STEP_S)[:12]
    sats = SatellitePositions.from_ephemeris(default_ephemeris(), t, "gps")
    first, other = _masks(track), _masks(track, wall_deg=30.0)
    positions = LinePositions.from_masks(first)
    saved = BlockCheckpoint(tmp_path / "blocks")
    monkeypatch.setattr(engine, "block_task", _Blocks(fail_at=4))
    with pytest.raises(RuntimeError):  # blocks [0, 64), [64, 128), [128, 192) saved
        engine.compute_availability(sats, positions, TrustRule.mask(first), checkpoint=saved)
    again = _Blocks()
    monkeypatch.setattr(engine, "block_task", again)
    res = engine.compute_availability(sats, positions, TrustRule.mask(other), checkpoint=saved)
    # the thresholds changed over 4100-4200 m (positions 50-100): the blocks [0, 64) and
    # [64, 128) are redone, [128, 192) is taken back, [192, 201) was never saved
    assert sorted(again.done) == [0, 64, 192] and res.provenance["blocks_resumed"] == 1
    fresh = engine.compute_availability(sats, positions, TrustRule.mask(other))
    assert res.count.tobytes() == fresh.count.tobytes()
    assert res.interval_m is not None and fresh.interval_m is not None
    assert res.interval_m.tobytes() == fresh.interval_m.tobytes()
    assert not np.array_equal(res.count, engine.compute_availability(
        sats, positions, TrustRule.mask(first)).count)  # the change mattered  # fmt: skip


@pytest.fixture
def mem() -> Iterator[str]:
    root = f"memory://availability-{uuid.uuid4().hex[:8]}"
    yield root
    if MEMORY.exists(root.removeprefix("memory://")):
        MEMORY.rm(root.removeprefix("memory://"), recursive=True)


def test_masks_over_http_and_outputs_in_memory_are_the_local_bytes(
    tmp_path: Path, mask_file: Path, mem: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    local = _run(mask_file, tmp_path / "local")
    want = _files(tmp_path / "local")
    with serve_folder(mask_file.parent) as url:
        res = _run(f"{url}/{mask_file.name}", f"{mem}/out")
        assert res.report_html == f"{mem}/out/report.html"
        got = {k: MEMORY.cat_file(f"{mem}/out/{k}") for k in want}
        assert sorted(MEMORY.ls(f"{mem}/out", detail=False)) == sorted(
            f"/{mem.removeprefix('memory://')}/out/{k}" for k in want
        )  # the outputs alone: no blocks/, no temporary object
        # the run description names the masks by their URL (summary.json, the report, the
        # Parquet tables' metadata); every other file is the local run's, byte for byte
        given = f"{url}/{mask_file.name}"
        differ = {k for k in want if got[k] != want[k]}
        assert differ == {"summary.json", "report.html", "positions.parquet", "epochs.parquet"}
        for k in sorted(differ):
            if k.endswith(".parquet"):
                a, b = pq.read_table(tmp_path / "local" / k), pq.read_table(io.BytesIO(got[k]))
                assert a.to_pandas().equals(b.to_pandas())
                meta_a = a.schema.metadata[b"predisat.availability.run"].decode()
                meta_b = b.schema.metadata[b"predisat.availability.run"].decode()
                assert meta_b.replace(given, str(mask_file)) == meta_a
            else:
                assert got[k].decode().replace(given, str(mask_file)) == want[k].decode(), k
        assert res.summary.equals(local.summary)
        with pytest.raises(FileNotFoundError, match="check the URL"):
            _run(f"{url}/absent.masks.parquet", f"{mem}/x")


def test_blocks_saved_under_another_integrity_setting_are_not_taken(
    tmp_path: Path, track: TrackMap, monkeypatch: pytest.MonkeyPatch
) -> None:
    from predisat.gnss.integrity import IntegrityBudget

    t = default_window(STEP_S)[:12]
    sats = SatellitePositions.from_ephemeris(default_ephemeris(), t, "gps")
    masks = _masks(track)
    positions = LinePositions.from_masks(masks)
    saved = BlockCheckpoint(tmp_path / "blocks")
    rule = TrustRule.mask(masks)
    loose, tight = IntegrityBudget(1e-3), IntegrityBudget(1e-12)
    engine.compute_availability(sats, positions, rule, integrity=loose, checkpoint=saved)
    assert sorted((tmp_path / "blocks").rglob("*.npz"))  # every block saved
    again = _Blocks()
    monkeypatch.setattr(engine, "block_task", again)
    res = engine.compute_availability(sats, positions, rule, integrity=tight, checkpoint=saved)
    assert sorted(again.done) == [0, 64, 128, 192] and res.provenance["blocks_resumed"] == 0
    fresh = engine.compute_availability(sats, positions, rule, integrity=tight)
    assert res.interval_m is not None and fresh.interval_m is not None
    assert res.interval_m.tobytes() == fresh.interval_m.tobytes()
    loose_iv = engine.compute_availability(sats, positions, rule, integrity=loose).interval_m
    assert loose_iv is not None and not np.allclose(
        np.nan_to_num(loose_iv), np.nan_to_num(res.interval_m))  # the setting mattered


def test_a_run_that_fails_while_writing_leaves_the_run_before_whole(
    tmp_path: Path, mask_file: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Written in place, a full disk left cut tables that pandas read as whole and new tables
    beside the previous run's report (a user trial); an earlier run's --counts table stayed
    beside a later report (a review)."""
    import errno

    import predisat.availability.report as report

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    out = tmp_path / "out"
    _run(mask_file, out, counts_table=True)
    before = _files(out)
    assert "counts.parquet" in before

    def full(*args: Any, **kwargs: Any) -> str:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(report, "build_report", full)
    with pytest.raises(OSError, match="No space"):
        _run(mask_file, out, cutoff_deg=(10.0,))  # another run: other rules, no counts
    assert _files(out) == before  # wholly the run before
    assert not [p for p in out.iterdir() if p.name.startswith(".staging-")]
    monkeypatch.undo()
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    _run(mask_file, out, cutoff_deg=(10.0,))
    after = _files(out)
    assert "counts.parquet" not in after and "report.html" in after
    assert after["summary.csv"] != before["summary.csv"]


def test_a_process_folder_at_a_url_needs_its_run_record(tmp_path: Path) -> None:
    """A review: a URL folder's masks were read without the run record a local folder needs
    (a stopped rerun leaves the previous run's masks without it)."""
    from predisat.availability.run import _load_masks
    from predisat.masks.fileformat import MaskFileError

    t = demo_track()
    ch = np.arange(3000.0, 3100.0, 10.0)
    lat, lon, h = t.position_at(ch)
    m = MaskSet.from_arrays(ch, lat, lon, h, t.heading_at(ch), np.full((ch.size, 72), 20.0))
    write_masks(m, tmp_path / "masks.parquet")
    root = f"availability-record-{uuid.uuid4().hex[:8]}"
    MEMORY.put_file(str(tmp_path / "masks.parquet"), f"{root}/masks.parquet")
    try:
        with pytest.raises(MaskFileError, match=r"without provenance\.json"):
            _load_masks(f"memory://{root}")
        MEMORY.pipe(f"{root}/provenance.json", b"{}")
        assert _load_masks(f"memory://{root}")[0].n_pos == ch.size
    finally:
        MEMORY.rm(root, recursive=True)


def test_a_quiet_command_line_run_still_says_it_resumed(
    tmp_path: Path, mask_file: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from predisat.cli import app

    argv = ["availability", "--masks", str(mask_file), "--out", str(tmp_path / "o"),
            "--start", START, "--end", END, "--step", str(STEP_S), "--interval-every", "2",
            "--scheduler", "serial", "--quiet"]  # fmt: skip
    monkeypatch.setattr(engine, "block_task", _Blocks(fail_at=3))
    with pytest.raises(RuntimeError, match="killed mid-run"):
        app.main(argv)
    monkeypatch.setattr(engine, "block_task", _Blocks())
    capsys.readouterr()
    assert app.main(argv) == 0
    out = capsys.readouterr()
    # --quiet drops the bar, and with it the library's resume line: the command says it
    assert "blocks resumed from the checkpoint" not in out.err
    assert "2 of " in out.out and "resumed from an interrupted run's checkpoint" in out.out


def test_a_wrong_scheduler_address_makes_no_output_folder(tmp_path: Path, mask_file: Path) -> None:
    """A mistyped --scheduler address was refused after the output folder was made, leaving
    an empty folder holding a lock file."""
    from predisat.scheduler import Scheduler

    with pytest.raises(OSError, match="no Dask scheduler answers"):
        run_availability(
            mask_file, None, None, out_dir=tmp_path / "new", start=START, end=END,
            step_s=STEP_S, n_sky=1, scheduler=Scheduler.at("tcp://127.0.0.1:1"),
        )  # fmt: skip
    assert not (tmp_path / "new").exists()
