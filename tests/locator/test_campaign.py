"""The campaign (locator.campaign): job grid, resume after a kill, Dask against serial.

A tiny grid (one 400 m world, two runs, two rules) keeps it fast; the ground truth of the
resume and scheduler tests is the serial uninterrupted run, compared byte for byte.
"""

from __future__ import annotations

import shutil
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
    hmi_rate_upper,
    job_key,
    jobs_for,
    load_world,
    pipeline_world,
    report,
    run_campaign,
    run_job,
    stanford,
    world_files,
)
from locator.campaign_command import CONFIG_NAMES, WORLD_NAMES
from locator.cli import main
from predisat.availability.satellites import default_window
from predisat.gnss.errormodel import ErrorModel, IntervalModel
from predisat.masks.fileformat import write_masks
from predisat.masks.truth import TrueMasks
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
    World.build(demo_track(), spec, 3).save(world_files(cache, "tiny")[0])
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
    # each rule's width is named (the console named a k = 2 its budget rules do not use)
    import json

    widths = json.loads((serial / "summary.json").read_text())["integrity"]
    assert widths["risk_per_epoch"] == setup.risk_per_epoch
    assert widths["per_rule"]["masks"].startswith("k = 3.89 per pair interval (1e-4 per pair")


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


def test_a_torn_job_file_is_redone(setup: CampaignSetup, serial: Path, tmp_path: Path) -> None:
    """A user trial: a job file emptied or cut short (a power cut; nothing is fsynced) was taken
    as done, and every rerun stopped on it."""
    shutil.copytree(serial / "jobs", tmp_path / "jobs")
    files = sorted((tmp_path / "jobs").iterdir())
    files[0].write_bytes(b"")
    files[1].write_bytes(files[1].read_bytes()[:200])
    result = run_campaign(tmp_path, setup, jobs_for(["tiny"], 2), Scheduler.serial())
    assert result.ran == 2
    _same_bytes(serial, tmp_path)


def test_cache_files_of_other_code_or_torn_are_built_again(tmp_path: Path) -> None:
    """A user trial changed the calibration and the cache gave back the old model under its old
    name; a torn world file gave a traceback naming no file."""
    spec = CampaignWorld("tiny", 1000.0, 1800.0, 3)
    first = load_world(spec, tmp_path)
    wfile, mfile = world_files(tmp_path, "tiny")
    assert wfile.exists() and mfile.exists() and first.digest
    stale = tmp_path / "tiny_world-000000000000.npz"
    stale.write_bytes(b"other code's world")
    wfile.write_bytes(wfile.read_bytes()[:100])  # torn
    again = load_world(spec, tmp_path)
    assert again.digest == first.digest  # built again, the same bytes
    assert not stale.exists()  # another code's file of the same stem is removed


def test_figures_of_rules_no_longer_run_are_removed(serial: Path, tmp_path: Path) -> None:
    frames = pd.read_parquet(serial / "epochs.parquet")
    (tmp_path / "stanford_masks_k2.png").write_bytes(b"an earlier campaign's")
    paths = stanford(frames, tmp_path)
    assert sorted(p.name for p in tmp_path.glob("stanford_*.png")) == sorted(
        f"stanford_{r}.png" for r in _RULES
    ) == sorted(p.name for p in paths)


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


def _processed_world(folder: Path, cache: Path, pipeline_raise_deg: float) -> None:
    """The tiny world laid out like an ``eval_rigs.py`` world folder, its "pipeline" masks
    the true masks raised by ``pipeline_raise_deg`` (a survey that sees more obstacles)."""
    truth = folder / "synth" / "truth"
    truth.mkdir(parents=True)
    for name in ("world.npz", "truth.npz"):
        src = cache / f"tiny_{name}"
        (truth / ("true_masks.npz" if name == "truth.npz" else name)).write_bytes(src.read_bytes())
    tm = TrueMasks.load(truth / "true_masks.npz")
    from predisat.masks.maskset import MaskSet

    raised = MaskSet.from_arrays(
        tm.chainage_m, tm.lat_deg, tm.lon_deg, tm.h_m, tm.heading_deg,
        np.minimum(tm.mask_el_deg + pipeline_raise_deg, 90.0),
    )  # fmt: skip
    (folder / "proc").mkdir()
    write_masks(raised, folder / "proc" / "masks.parquet")


def test_a_processed_world_brings_its_pipeline_masks_to_the_pipeline_rules(
    setup: CampaignSetup, tmp_path: Path
) -> None:
    data = setup.worlds["tiny"]
    src = tmp_path / "cache"
    src.mkdir()
    data.world.save(src / "tiny_world.npz")
    from predisat.synth.truth import true_masks

    true_masks(data.world).save(src / "tiny_truth.npz")
    _processed_world(tmp_path / "w", src, 30.0)
    world = pipeline_world(tmp_path / "w", "tiny")
    assert world.pipeline is not None
    # the masks read back are the raised ones, cell for cell
    assert np.all(world.pipeline.mask_el_deg >= world.masks.mask_el_deg - 1.0 - 1e-9)
    rules = ("masks_split", "pipeline_split", "none_budget", "cutoff15_budget")
    ps = CampaignSetup(setup.model, rules, 1e-12, {"tiny": world})
    df = run_job(ps, jobs_for(["tiny"], 1)[0])
    assert set(df["config"].unique()) == set(rules)
    used = df.groupby("config")["n_used"].mean()
    # raised masks trust fewer satellites than the true ones; no masks trust the most
    assert used["pipeline_split"] < used["masks_split"] < used["none_budget"]
    with pytest.raises(FileNotFoundError, match=r"proc/masks\.parquet"):
        pipeline_world(tmp_path / "cache", "x")


def test_the_hmi_rate_bound_is_clopper_pearson() -> None:
    from scipy.stats import binom

    # no event: the bound solves (1 - p)^n = 0.05 exactly
    for n in (1, 30, 10**6):
        assert hmi_rate_upper(0, n) == pytest.approx(1.0 - 0.05 ** (1.0 / n), rel=1e-9)
    # k events: P(X <= k | p = bound) = 0.05
    for k, n in ((1, 100), (6, 108_768), (40, 5_000)):
        assert binom.cdf(k, n, hmi_rate_upper(k, n)) == pytest.approx(0.05, rel=1e-6)
    assert np.isnan(hmi_rate_upper(0, 0))
    assert hmi_rate_upper(3, 3) == 1.0


def test_the_report_bounds_the_hmi_rate_per_epoch_and_per_run(serial: Path) -> None:
    frames = pd.read_parquet(serial / "epochs.parquet")
    g = frames[frames["config"] == "masks"]
    assert g["hmi"].sum() == 0
    table = report(frames)
    n, runs = len(g), g.groupby(["world", "run"]).ngroups
    assert table.loc["masks", "runs"] == runs == 2
    assert table.loc["masks", "hmi_rate_upper95"] == pytest.approx(1.0 - 0.05 ** (1.0 / n))
    # three HMI epochs in one run: the per-epoch bound from 3 of n, the per-run one from 1 of 2
    hit = frames.index[(frames["config"] == "masks") & (frames["run"] == 1)][:3]
    frames.loc[hit, "hmi"] = True
    table = report(frames)
    assert table.loc["masks", "hmi"] == 3
    assert table.loc["masks", "hmi_rate_upper95"] == pytest.approx(hmi_rate_upper(3, n))
    assert table.loc["masks", "hmi_run_upper95"] == pytest.approx(hmi_rate_upper(1, 2))


def test_command_refuses_a_badly_named_pipeline_world(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for bad in ("noequals", "canyon=" + str(tmp_path), "x=" + str(tmp_path / "missing")):
        with pytest.raises(SystemExit) as stop:
            main(["campaign", "--out", str(tmp_path / "c"), "--pipeline-world", bad,
                  "--scheduler", "serial"])  # fmt: skip
        assert stop.value.code == 2
        assert repr(bad) in capsys.readouterr().err
        assert not (tmp_path / "c").exists()


def test_a_stopped_campaign_of_other_options_withdraws_the_earlier_tables(
    setup: CampaignSetup, serial: Path, tmp_path: Path
) -> None:
    """A finished campaign's summary stayed beside the job files of a rerun with other options
    that was stopped, and read as that rerun's result."""
    import shutil

    shutil.copytree(serial, tmp_path, dirs_exist_ok=True)
    jobs = jobs_for(["tiny"], 3)  # one more run: one job to do

    def kill(job: Job, path: Path) -> None:
        raise _Killed(f"killed after {path.name}")

    with pytest.raises(_Killed):
        run_campaign(tmp_path, setup, jobs, Scheduler.serial(), on_job_done=kill)
    for name in _FILES:
        assert not (tmp_path / name).exists(), name


def test_the_code_fingerprint_covers_the_shipped_navigation_file(tmp_path, monkeypatch) -> None:
    """The jobs read predisat's embedded navigation file: another file must redo them."""
    import predisat
    from locator.campaign import code_fingerprint

    pkg = tmp_path / "predisat"
    (pkg / "data" / "nav").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    nav = pkg / "data" / "nav" / "brdc.rnx"
    nav.write_text("one")
    monkeypatch.setattr(predisat, "__file__", str(pkg / "__init__.py"))
    first = code_fingerprint()
    nav.write_text("two")
    assert code_fingerprint() != first
    nav.write_text("one")
    assert code_fingerprint() == first


def test_a_wrong_scheduler_address_keeps_the_finished_tables(
    setup: CampaignSetup, serial: Path, tmp_path: Path
) -> None:
    """A rerun with one more run and a mistyped --scheduler address withdrew the finished
    campaign's tables and figures, then was refused (the address is checked first now)."""
    shutil.copytree(serial, tmp_path, dirs_exist_ok=True)
    (tmp_path / "campaign.png").write_bytes(b"png")
    with pytest.raises(OSError, match="no Dask scheduler answers"):
        run_campaign(tmp_path, setup, jobs_for(["tiny"], 3), Scheduler.at("tcp://127.0.0.1:1"))
    for name in (*_FILES, "campaign.png"):
        assert (tmp_path / name).read_bytes() == (
            (serial / name).read_bytes() if name != "campaign.png" else b"png"
        ), name


def test_rewritten_tables_withdraw_the_earlier_figures(
    setup: CampaignSetup, serial: Path, tmp_path: Path
) -> None:
    """A rerun with fewer runs (no job to do) rewrote the tables while the earlier campaign's
    figures stayed until the command redrew them: stopped in between, the folder held the
    new summary beside the figures of the earlier, larger campaign."""
    shutil.copytree(serial, tmp_path, dirs_exist_ok=True)
    for name in ("campaign.png", "stanford_masks.png"):
        (tmp_path / name).write_bytes(b"figure of the 2-run campaign")
    result = run_campaign(tmp_path, setup, jobs_for(["tiny"], 1), Scheduler.serial())
    assert result.ran == 0
    assert pd.read_parquet(tmp_path / "epochs.parquet")["run"].unique().tolist() == [0]
    assert not (tmp_path / "campaign.png").exists()
    assert not (tmp_path / "stanford_masks.png").exists()
