"""The campaign (locator.campaign): job grid, resume after a kill, Dask against serial.

A tiny grid (one 400 m world, two runs, two rules) keeps it fast; the ground truth of the
resume and scheduler tests is the serial uninterrupted run, compared byte for byte.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from locator.campaign import (
    CONFIGS,
    WORLDS,
    CampaignSetup,
    CampaignWorld,
    Job,
    job_key,
    jobs_for,
    load_world,
    run_campaign,
)
from locator.campaign_command import CONFIG_NAMES, WORLD_NAMES
from locator.cli import main
from predisat.availability.satellites import default_window
from predisat.gnss.errormodel import ErrorModel, IntervalModel
from predisat.scheduler import Scheduler
from predisat.synth.world import Stretch, World, WorldSpec
from predisat.track.map import demo_track

_FILES = ("epochs.parquet", "summary.csv", "summary.json")
_RULES = ("masks", "none")


class _Killed(RuntimeError):
    pass


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> CampaignSetup:
    """A 400 m world of rock walls on one side (NLOS and blocked signals), cached as the
    campaign's world ``tiny``, and a fixed error model."""
    cache = tmp_path_factory.mktemp("cache")
    spec = WorldSpec((Stretch("rock_walls", 1000.0, 1400.0, "left"),), catenary=False, hills=False)
    World.build(demo_track(), spec, 3).save(cache / "tiny_world.npz")
    data = load_world(CampaignWorld("tiny", 1000.0, 1400.0, 3), cache)
    model = IntervalModel(ErrorModel(2.1, 2.0), 2.0)
    return CampaignSetup(model, _RULES, 1e-12, {"tiny": data})


@pytest.fixture(scope="module")
def serial(setup: CampaignSetup, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Output folder of the serial uninterrupted run of the tiny grid."""
    out = tmp_path_factory.mktemp("serial")
    result = run_campaign(out, setup, jobs_for(["tiny"], 2), Scheduler.serial())
    assert result.ran == 2
    return out


def _same_bytes(a: Path, b: Path) -> None:
    for name in _FILES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    ja, jb = sorted((a / "jobs").iterdir()), sorted((b / "jobs").iterdir())
    assert [p.name for p in ja] == [p.name for p in jb]
    for pa, pb in zip(ja, jb, strict=True):
        assert pa.read_bytes() == pb.read_bytes(), pa.name


def test_command_names_match_the_library() -> None:
    assert WORLD_NAMES == tuple(w.name for w in WORLDS)
    assert CONFIG_NAMES == CONFIGS


def test_jobs_spread_over_the_day_and_stable_under_more_runs() -> None:
    day0 = default_window()[0]
    few, many = jobs_for(["a", "b"], 3), jobs_for(["b", "a"], 40)
    # adding runs or worlds keeps the finished jobs
    assert set(few) <= set(many)
    t = np.array([j.t0_gps_s for j in many if j.world == "a"])
    assert ((t >= day0) & (t < day0 + 86400.0)).all()
    # golden-ratio spread: 40 starts leave no gap above 2.5 / 40 of the day
    gaps = np.diff(np.sort(np.r_[t, t.min() + 86400.0]))
    assert gaps.max() < 2.5 * 86400.0 / 40
    assert [j.direction for j in many[:4]] == [1, -1, 1, -1]
    with pytest.raises(ValueError, match="runs_per_world"):
        jobs_for(["a"], 0)


def test_serial_tables(serial: Path, setup: CampaignSetup) -> None:
    epochs = pd.read_parquet(serial / "epochs.parquet")
    # job order (world, run), then rule order, within each job
    order = epochs.drop_duplicates(["run", "config"])[["run", "config"]]
    assert list(order.itertuples(index=False, name=None)) == [
        (0, "masks"), (0, "none"), (1, "masks"), (1, "none"),
    ]  # fmt: skip
    assert "solve_ms" not in epochs.columns  # a wall-clock time would differ between runs
    # every rule locates the same epochs; the truth follows the 400 m world
    sizes = epochs.groupby(["run", "config"]).size()
    assert sizes.nunique() == 1 and sizes.iloc[0] > 10
    assert epochs["truth_m"].between(1000.0, 1400.0).all()
    table = pd.read_csv(serial / "summary.csv", index_col="config")
    assert list(table.index) == list(_RULES)
    assert (table["epochs"] == sizes.iloc[0] * 2).all()


def test_resume_after_a_kill_gives_the_same_bytes(
    setup: CampaignSetup, serial: Path, tmp_path: Path
) -> None:
    jobs = jobs_for(["tiny"], 2)
    done: list[Job] = []

    def kill(job: Job, path: Path) -> None:
        done.append(job)
        raise _Killed(f"killed after {path.name}")

    with pytest.raises(_Killed):
        run_campaign(tmp_path, setup, jobs, Scheduler.serial(), on_job_done=kill)
    assert len(done) == 1
    first = next((tmp_path / "jobs").iterdir())
    stamp = first.stat().st_mtime_ns
    assert not (tmp_path / "epochs.parquet").exists()

    again: list[Job] = []
    result = run_campaign(
        tmp_path, setup, jobs, Scheduler.serial(), on_job_done=lambda j, p: again.append(j)
    )
    assert result.ran == 1 and again == [j for j in jobs if j != done[0]]
    assert first.stat().st_mtime_ns == stamp  # the finished job was not redone
    _same_bytes(serial, tmp_path)


def test_key_changes_with_setup_and_code(setup: CampaignSetup) -> None:
    job = jobs_for(["tiny"], 1)[0]
    other = CampaignSetup(setup.model, setup.configs, 1e-9, setup.worlds)
    assert job_key(job, setup.digest(), "c") != job_key(job, other.digest(), "c")
    assert job_key(job, setup.digest(), "c") != job_key(job, setup.digest(), "d")
    assert job_key(job, setup.digest(), "c") == job_key(job, setup.digest(), "c")


def test_local_dask_cluster_gives_the_serial_bytes(
    setup: CampaignSetup, serial: Path, tmp_path: Path
) -> None:
    result = run_campaign(tmp_path, setup, jobs_for(["tiny"], 2), Scheduler.local(2))
    assert result.ran == 2
    _same_bytes(serial, tmp_path)


def test_command_refuses_pipeline_rules_without_demo(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["campaign", "--out", str(tmp_path / "c"), "--configs", "pipeline",
                 "--scheduler", "serial"])  # fmt: skip
    assert code == 2
    assert "--demo" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
    code = main(["campaign", "--out", str(tmp_path / "c"), "--worlds", "--scheduler", "serial"])
    assert code == 2
    assert "no world to run" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
