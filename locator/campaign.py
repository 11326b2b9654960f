"""Campaign of simulated train runs: the worlds x start times x rules grid, resumable, on a
:class:`~predisat.scheduler.Scheduler` (this process, a local Dask cluster or an existing one).

Synthetic worlds (:data:`WORLDS`: four ``WorldSpec.mixed`` stretches of Belgian line 144 and
the Nice-Digne canyon recipe; optionally the world of a ``predisat demo`` folder with its
pipeline masks), trains with a station stop running both ways at start times spread over the
embedded navigation day (all constellations, 1 Hz). Every simulated run (LOS, code multipath,
NLOS through reflections, loss) is located with active integrity under each rule of
:data:`CONFIGS`:

* ``masks``: the world's true masks (a perfect survey) with a 1 deg margin, ``k = 3.89``;
* ``none``: every received signal; ``cutoff15``: a flat 15 deg elevation cut-off;
* ``masks_k2``: the masks with the source's ``k = 2``;
* ``masks_budget``: the masks with an :class:`~predisat.gnss.integrity.IntegrityBudget` (each
  epoch's ``k`` from the campaign's risk per epoch);
* ``masks_split``: ``masks_budget`` with partitioned trust (``RunConfig.trust_stretches`` =
  :data:`locator.partition.MAX_STRETCHES`: a trusted set and a fix per stretch of the predicted
  interval);
* ``none_budget`` / ``cutoff15_budget``: no masks and the 15 deg cut-off with the budget;
* ``pipeline`` / ``pipeline_budget`` / ``pipeline_split``: the same with the masks ``predisat
  process`` made of the world's rendered survey (the worlds of :func:`pipeline_world`: a
  ``predisat demo`` folder, or a rendered and processed synthetic survey).

One job is one run of one world under every rule; its epochs table (:func:`run_job`) is saved
as ``OUT/jobs/<world>_<run>_<key>.parquet``, the key hashing the job, the setup (rules, risk,
error model, world files) and the code of ``locator`` and ``predisat``: a rerun skips the jobs
whose file exists and redoes the others, so a campaign killed at any point resumes where it
stopped, and the final tables (``epochs.parquet``, ``summary.csv``, ``summary.json``) are built
from the job files in job order, byte-identical to those of an uninterrupted serial run.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import json
import time
import zipfile
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from locator.evaluate import score_run, summarise
from locator.fde import LocatorConfig
from locator.partition import MAX_STRETCHES
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.sim.simfile import SignalState
from locator.sim.simulate import simulate_run
from locator.sources import SimSource
from predisat.atomic import atomic_path
from predisat.availability.satellites import default_ephemeris, default_window
from predisat.availability.trainrun import SpeedProfile
from predisat.gnss.ephemeris import Ephemeris
from predisat.gnss.errormodel import ErrorModel, IntervalModel, read_error_model, write_error_model
from predisat.gnss.integrity import IntegrityBudget
from predisat.masks.maskset import MaskSet
from predisat.masks.truth import TrueMasks
from predisat.scheduler import Scheduler, TaskRunner
from predisat.synth.world import World, WorldSpec
from predisat.track.map import demo_track

if TYPE_CHECKING:
    from locator.sim.multipath import ReflectorIndex

__all__ = [
    "CALIB_WORLD",
    "CONFIGS",
    "MARGIN_DEG",
    "PROFILE_T_S",
    "PROFILE_V_MPS",
    "WORLDS",
    "CampaignResult",
    "CampaignSetup",
    "CampaignWorld",
    "Job",
    "WorldData",
    "calibrate",
    "code_fingerprint",
    "demo_world",
    "error_model_file",
    "figure",
    "hmi_rate_upper",
    "job_key",
    "jobs_for",
    "load_world",
    "pipeline_world",
    "report",
    "rule_widths",
    "run_campaign",
    "run_job",
    "stanford",
    "world_files",
]

_REPO = Path(__file__).resolve().parents[1]
MARGIN_DEG = 1.0
"""Margin, degrees, added to the true masks of the ``masks`` rules."""

# 0 -> 20 m/s in 40 s, cruise 30 s, brake to a stop in 30 s, dwell 60 s, go again
PROFILE_T_S = (0.0, 40.0, 70.0, 100.0, 160.0, 200.0, 1.0e4)
"""Times, seconds, of the campaign's speed profile (a station stop)."""
PROFILE_V_MPS = (0.0, 20.0, 20.0, 0.0, 0.0, 20.0, 20.0)
"""Speeds, m/s, at :data:`PROFILE_T_S`."""

CONFIGS = ("masks", "none", "cutoff15", "masks_k2", "masks_budget", "masks_split", "none_budget",
           "cutoff15_budget", "pipeline", "pipeline_budget", "pipeline_split")  # fmt: skip
"""Every rule; the ``pipeline`` ones apply to the worlds with pipeline masks only."""

_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class CampaignWorld:
    """A synthetic world of the campaign: a stretch of the demo track (line 144, track A).

    Attributes
    ----------
    name : str
    from_m, to_m : float
        Chainage span, metres.
    seed : int
    recipe : str or None
        A world recipe YAML relative to the repository (``WorldSpec.from_dict``), else
        ``WorldSpec.mixed(from_m, to_m, seed)``.
    """

    name: str
    from_m: float
    to_m: float
    seed: int
    recipe: str | None = None

    def spec(self) -> WorldSpec:
        """The world's specification."""
        if self.recipe:
            import yaml

            return WorldSpec.from_dict(yaml.safe_load((_REPO / self.recipe).read_text()))
        return WorldSpec.mixed(self.from_m, self.to_m, seed=self.seed)


WORLDS = (
    CampaignWorld("mixed-1", 1000.0, 3300.0, 11),
    CampaignWorld("mixed-2", 4000.0, 6300.0, 12),
    CampaignWorld("mixed-3", 7000.0, 9300.0, 13),
    CampaignWorld("mixed-4", 10000.0, 12300.0, 14),
    CampaignWorld("canyon", 0.0, 1300.0, 7, "surveys/nice_digne_canyon.yaml"),
)
"""The campaign's worlds (``--worlds`` names them)."""

CALIB_WORLD = CampaignWorld("calib", 12300.0, 14100.0, 99)
"""The world the error model is learned on (:func:`calibrate`), apart from :data:`WORLDS`."""


@dataclass(frozen=True)
class Job:
    """One simulated run: run ``run`` of ``world`` from ``t0_gps_s`` in ``direction`` (+-1)."""

    world: str
    run: int
    t0_gps_s: float
    direction: int


@dataclass(frozen=True)
class WorldData:
    """A world ready for jobs: the world, its true masks (with :data:`MARGIN_DEG`), the
    pipeline masks (None for the worlds built here, which have no rendered survey) and the
    digest of the files they came from.

    Its reflector index (:meth:`reflectors`) is built on first use in each process and never
    pickled (a ray caster): a cluster worker builds it once for all its jobs of the world.
    """

    name: str
    world: World
    masks: MaskSet
    pipeline: MaskSet | None
    digest: str
    _built: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def reflectors(self) -> ReflectorIndex:
        """The world's :class:`~locator.sim.multipath.ReflectorIndex` (built once)."""
        if "index" not in self._built:
            from locator.sim.multipath import ReflectorIndex

            self._built["index"] = ReflectorIndex(self.world)
        index: ReflectorIndex = self._built["index"]
        return index

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_built"] = {}
        return state


@dataclass(frozen=True)
class CampaignSetup:
    """What every job shares: the learned error model, the rules, the integrity risk per
    epoch of the ``*_budget`` rules and the worlds by name."""

    model: IntervalModel
    configs: tuple[str, ...]
    risk_per_epoch: float
    worlds: Mapping[str, WorldData]

    def digest(self) -> str:
        """Hash of everything a job's result depends on besides the job and the code."""
        h = hashlib.sha256()
        h.update(repr((self.model, self.configs, self.risk_per_epoch)).encode())
        for name in sorted(self.worlds):
            h.update(f"{name}:{self.worlds[name].digest}".encode())
        return h.hexdigest()


@dataclass(frozen=True)
class CampaignResult:
    """What :func:`run_campaign` did: every job, how many it ran now, the job files in job
    order, the epochs of every job and rule, the summary per rule and the wall time, seconds."""

    jobs: tuple[Job, ...]
    ran: int
    paths: tuple[Path, ...]
    frames: pd.DataFrame
    table: pd.DataFrame
    wall_s: float


def _file_digest(paths: Sequence[Path]) -> str:
    h = hashlib.sha256()
    for p in paths:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def _cached(cache: Path, stem: str, suffix: str) -> Path:
    """``cache/<stem>-<code>.<suffix>``: a cache file of other code is never read back (a user
    trial changed the calibration and the old model came back under the old name)."""
    return cache / f"{stem}-{_code_key()}{suffix}"


@contextlib.contextmanager
def _building(path: Path) -> Iterator[Path]:
    """:func:`~predisat.atomic.atomic_path` for a cache file, whose other code's versions (the
    same stem) are removed once it is written, not when it is only looked up."""
    with atomic_path(path) as tmp:
        yield tmp
    stem = path.name[: -len(path.suffix) - 1 - len(_code_key())]
    for old in path.parent.glob(f"{stem}-*{path.suffix}"):
        if old != path:
            old.unlink(missing_ok=True)


@functools.lru_cache(maxsize=1)
def _code_key() -> str:
    return code_fingerprint()[:12]


def _readable(path: Path, read: Callable[[Path], Any]) -> Any:
    """``read(path)``, or None after removing ``path`` when it does not read (a torn file: a
    power cut after the rename; nothing is fsynced), so that it is built again."""
    if not path.exists():
        return None
    try:
        return read(path)
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
        path.unlink(missing_ok=True)
        return None


def world_files(cache: Path, name: str) -> tuple[Path, Path]:
    """The cache files of world ``name`` for this code: ``<name>_world-<code>.npz`` and
    ``<name>_truth-<code>.npz``."""
    return _cached(cache, f"{name}_world", ".npz"), _cached(cache, f"{name}_truth", ".npz")


def error_model_file(cache: Path) -> Path:
    """The cache file of the calibrated error model for this code, ``error_model-<code>.json``."""
    return _cached(cache, "error_model", ".json")


def calibrate(cache: Path) -> IntervalModel:
    """Learn the error model on :data:`CALIB_WORLD` (six runs, direct signals only), cached in
    ``cache/error_model-<code>.json`` (read when present and readable)."""
    from locator.errorfit import sim_residuals
    from locator.intervals import fit_error_model

    path = error_model_file(cache)
    known = _readable(path, read_error_model)
    if known is not None:
        return known
    world = World.build(demo_track(), CALIB_WORLD.spec(), CALIB_WORLD.seed)
    eph, day = default_ephemeris(), default_window()[0]
    els, ress = [], []
    for r in range(6):
        sim = simulate_run(
            world, eph, world.extent_m[0] + 10.0, day + r * 4 * 3600 + 1800,
            SpeedProfile.constant(12.0), 140.0, 1.0, seed=500 + r,
        )  # fmt: skip
        e, res = sim_residuals(sim)
        els.append(e)
        ress.append(res)
    n = max(x.shape[1] for x in els)
    el = np.concatenate(
        [np.pad(x, ((0, 0), (0, n - x.shape[1])), constant_values=np.nan) for x in els]
    )
    res = np.concatenate(
        [np.pad(x, ((0, 0), (0, n - x.shape[1])), constant_values=np.nan) for x in ress]
    )
    model = IntervalModel(fit_error_model(el, res), k_sigma=2.0)
    cache.mkdir(parents=True, exist_ok=True)
    with _building(path) as tmp:
        write_error_model(tmp, model, {"data": "6 simulated runs of the calibration world"})
    return read_error_model(path)  # as a resumed run reads it


def _masks_of(tm: TrueMasks, provenance: str) -> MaskSet:
    return MaskSet.from_arrays(
        tm.chainage_m, tm.lat_deg, tm.lon_deg, tm.h_m, tm.heading_deg, tm.mask_el_deg,
        margin_deg=MARGIN_DEG, provenance={"source": provenance},
    )  # fmt: skip


def load_world(spec: CampaignWorld, cache: Path) -> WorldData:
    """The world of ``spec`` and its true masks, built into ``cache`` on first use
    (:func:`world_files`, keyed by the code) and read from there afterwards; a file that does
    not read (torn) is built again."""
    from predisat.synth.truth import true_masks

    wfile, mfile = world_files(cache, spec.name)
    track = demo_track()
    world = _readable(wfile, lambda p: World.load(p, track))
    if world is None:
        # built, saved, then read back: the same world whether this run built it or not
        cache.mkdir(parents=True, exist_ok=True)
        with _building(wfile) as tmp:
            World.build(track, spec.spec(), spec.seed).save(tmp)
        world = World.load(wfile, track)
        mfile.unlink(missing_ok=True)  # the truth of the world just built
    tm = _readable(mfile, TrueMasks.load)
    if tm is None:
        with _building(mfile) as tmp:
            true_masks(world).save(tmp)
        tm = TrueMasks.load(mfile)
    masks = _masks_of(tm, f"true masks of world {spec.name}")
    return WorldData(spec.name, world, masks, None, _file_digest([wfile, mfile]))


def demo_world(folder: Path) -> WorldData:
    """The world of a ``predisat demo`` folder with its pipeline masks, named ``demo``
    (:func:`pipeline_world`)."""
    return pipeline_world(folder, "demo")


_TRUTH_DIRS = ("truth", "synth/truth")
_MASK_FILES = ("masks/masks.parquet", "proc/masks.parquet")


def pipeline_world(folder: Path, name: str) -> WorldData:
    """A rendered world with the masks ``predisat process`` made of its survey.

    Parameters
    ----------
    folder : Path
        A ``predisat demo --out`` folder (``truth/world.npz``, ``truth/true_masks.npz``,
        ``masks/masks.parquet``) or the folder of one world of ``scripts/eval_rigs.py`` /
        ``scripts/eval_ood_world.py`` (``synth/truth/...``, ``proc/masks.parquet``). The world
        must lie on the demo track (line 144, track A).
    name : str
        The world's name in the campaign (job files, tables).
    """
    truth = next((folder / d for d in _TRUTH_DIRS if (folder / d / "world.npz").exists()), None)
    masks = next((folder / f for f in _MASK_FILES if (folder / f).exists()), None)
    if truth is None or masks is None or not (truth / "true_masks.npz").exists():
        raise FileNotFoundError(
            f"{folder}: not a rendered and processed world (needs truth/world.npz, "
            "truth/true_masks.npz and masks/masks.parquet, or synth/truth/... and "
            "proc/masks.parquet); run `predisat demo --out DIR`, or `predisat synth` then "
            "`predisat process`, first"
        )
    from predisat.masks.fileformat import read_masks

    files = [truth / "world.npz", truth / "true_masks.npz", masks]
    world = World.load(files[0], demo_track())
    true = _masks_of(TrueMasks.load(files[1]), f"true masks of world {name}")
    return WorldData(name, world, true, read_masks(files[2]), _file_digest(files))


def jobs_for(worlds: Sequence[str], runs_per_world: int) -> list[Job]:
    """The jobs of ``runs_per_world`` runs of each world, world by world.

    Run ``r`` of world ``w`` starts at the fraction ``frac(offset_w + r * golden ratio)`` of
    the day and runs forwards when ``r`` is even: spread evenly for any number of runs, and
    independent of that number and of the other worlds, so that adding runs keeps the
    finished ones and a subset reproduces them.
    """
    if runs_per_world < 1:
        raise ValueError(f"runs_per_world must be >= 1, got {runs_per_world}")
    day = default_window()[0]
    jobs = []
    for w in worlds:
        offset = (zlib.crc32(w.encode()) % 1000) / 1000.0
        for r in range(runs_per_world):
            t0 = day + np.mod(offset + r * _GOLDEN, 1.0) * 86400.0
            jobs.append(Job(w, r, float(t0), +1 if r % 2 == 0 else -1))
    return jobs


def rule_widths(configs: Sequence[str], risk_per_epoch: float) -> dict[str, str]:
    """How wide each rule draws its pair intervals, for the console and ``summary.json`` (a
    user trial found the campaign naming a k of 2 that its budget rules do not use)."""
    per_pair = IntervalModel.for_risk(1e-4, ErrorModel()).k_sigma
    out = {}
    for name in configs:
        if name.endswith(("_budget", "_split")):
            out[name] = f"integrity risk {risk_per_epoch:.3g} per epoch (k by interval mode)"
        elif name == "masks_k2":
            out[name] = "k = 2 per pair interval (the learned model's)"
        else:
            out[name] = f"k = {per_pair:.2f} per pair interval (1e-4 per pair, the source's)"
    return out


def _rules(setup: CampaignSetup, data: WorldData) -> dict[str, tuple[RunConfig, MaskSet | None]]:
    learned = setup.model
    # k for a 1e-4 two-sided Gaussian risk per pair (the risk the source states for its +-2 xi)
    loc = LocatorConfig(model=IntervalModel.for_risk(1e-4, learned.error), budget=None)
    budget = LocatorConfig(model=learned, budget=IntegrityBudget(setup.risk_per_epoch))
    k2 = LocatorConfig(model=learned, budget=None)  # the learned model's k = 2
    # the single set (trust_stretches=1) written out: the rules stay what they were whatever
    # RunConfig's default
    split = RunConfig(budget, trust="masks", trust_stretches=MAX_STRETCHES)
    rules: dict[str, tuple[RunConfig, MaskSet | None]] = {
        "masks": (RunConfig(loc, trust="masks", trust_stretches=1), data.masks),
        "none": (RunConfig(loc, trust="none"), None),
        "cutoff15": (RunConfig(loc, trust="cutoff", cutoff_deg=15.0), None),
        "masks_k2": (RunConfig(k2, trust="masks", trust_stretches=1), data.masks),
        "masks_budget": (RunConfig(budget, trust="masks", trust_stretches=1), data.masks),
        "masks_split": (split, data.masks),
    }
    rules["none_budget"] = (RunConfig(budget, trust="none"), None)
    rules["cutoff15_budget"] = (RunConfig(budget, trust="cutoff", cutoff_deg=15.0), None)
    if data.pipeline is not None:
        rules["pipeline"] = (RunConfig(loc, trust="masks", trust_stretches=1), data.pipeline)
        rules["pipeline_budget"] = (
            RunConfig(budget, trust="masks", trust_stretches=1),
            data.pipeline,
        )
        rules["pipeline_split"] = (split, data.pipeline)
    return {k: v for k, v in rules.items() if k in setup.configs}


def run_job(setup: CampaignSetup, job: Job) -> pd.DataFrame:
    """Simulate ``job`` and locate it under every rule of ``setup``.

    Returns
    -------
    pandas.DataFrame
        One row per epoch and rule: the columns of :func:`locator.evaluate.score_run` (but
        ``used``, ``excluded``, ``flag_names`` and the timing ``solve_ms``), ``n_nlos_used``
        (NLOS signals among the used ones), ``config``, ``world``, ``run``, ``direction``,
        ``n_los`` and ``n_nlos`` (signals received in each state).
    """
    if job.world not in setup.worlds:
        raise KeyError(f"job of world {job.world!r}: not among {sorted(setup.worlds)}")
    data = setup.worlds[job.world]
    world = data.world
    lo, hi = world.extent_m
    start = lo + 15.0 if job.direction > 0 else hi - 15.0
    profile = SpeedProfile.from_time_table(list(PROFILE_T_S), list(PROFILE_V_MPS))
    span = hi - lo - 30.0
    duration = float(
        np.interp(span, profile.distance_at(np.arange(0, 2000.0)), np.arange(0, 2000.0))
    )
    seed = zlib.crc32(job.world.encode()) % 10007 * 1000 + job.run
    sim = simulate_run(
        world, _ephemeris(), start, job.t0_gps_s, profile, np.floor(duration), 1.0,
        direction=job.direction, seed=seed, reflectors=data.reflectors(),
    )  # fmt: skip
    path = AntennaPath(world.track, 4.0)
    src = SimSource(sim)
    rules = _rules(setup, data)
    # the NLOS signals of each epoch, once for every rule (a set lookup per used signal)
    nlos_at = [{sim.sats[j] for j in np.flatnonzero(row)} for row in sim.state == SignalState.NLOS]
    out = []
    for name, (cfg, ms) in rules.items():
        ep = run_locator(path, src, start_chainage_m=start, config=cfg, masks=ms)
        sc = score_run(ep, sim.chainage_m)
        n_nlos = [sum(s in nlos_at[k] for s in used.split()) for k, used in enumerate(sc["used"])]
        # solve_ms is a wall-clock time, not a result: without it a job's table is the same
        # wherever and whenever it ran
        sc = sc.drop(columns=["used", "excluded", "flag_names", "solve_ms"])
        sc["n_nlos_used"] = n_nlos
        sc["config"] = name
        out.append(sc)
    df = pd.concat(out, ignore_index=True)
    df["world"] = job.world
    df["run"] = job.run
    df["direction"] = job.direction
    df["n_los"] = np.tile((sim.state == SignalState.LOS).sum(1), len(rules))
    df["n_nlos"] = np.tile((sim.state == SignalState.NLOS).sum(1), len(rules))
    return df


@functools.cache
def _ephemeris() -> Ephemeris:
    """:func:`~predisat.availability.satellites.default_ephemeris`, read once per process (the
    RINEX file took a fifth of a job)."""
    return default_ephemeris()


def code_fingerprint() -> str:
    """Hash of the source of the ``locator`` and ``predisat`` packages (every ``.py`` file)
    and of the data the jobs read from them (predisat's shipped navigation file and models):
    a job file of other code or data is never taken for this code's result (on the safe side:
    any change redoes every job)."""
    import predisat

    h = hashlib.sha256()
    pkg = Path(predisat.__file__).resolve().parent
    data = [*sorted((pkg / "data" / "nav").glob("*")), *sorted((pkg / "data" / "models").glob("*"))]
    for root in (Path(__file__).resolve().parent, pkg):
        for p in [*sorted(root.rglob("*.py")), *(data if root == pkg else [])]:
            h.update(str(p.relative_to(root.parent)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def job_key(job: Job, setup_digest: str, code_digest: str) -> str:
    """16 hex digits naming a job's result: its job, setup (:meth:`CampaignSetup.digest`) and
    code (:func:`code_fingerprint`)."""
    text = f"{job.world}|{job.run}|{job.t0_gps_s!r}|{job.direction}|{setup_digest}|{code_digest}"
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _timed_job(setup: CampaignSetup, job: Job) -> tuple[Job, pd.DataFrame, float]:
    t = time.perf_counter()
    df = run_job(setup, job)
    return job, df, time.perf_counter() - t


def hmi_rate_upper(n_hmi: int, n: int, confidence: float = 0.95) -> float:
    """One-sided Clopper-Pearson upper bound on a rate seen ``n_hmi`` times in ``n`` trials
    (``3 / n`` roughly when ``n_hmi`` is 0); NaN without trials."""
    from scipy.stats import beta

    if n < 1:
        return float("nan")
    if n_hmi >= n:
        return 1.0
    return float(beta.ppf(confidence, n_hmi + 1, n - n_hmi))


def report(frames: pd.DataFrame) -> pd.DataFrame:
    """One row per rule (in order of appearance): :func:`locator.evaluate.summarise` of its
    epochs, ``nlos_used_share`` (share of epochs using an NLOS signal), ``runs`` and the 95 %
    upper bounds of the HMI rate per epoch (``hmi_rate_upper95``: the epochs taken as
    independent trials, which they are not at 1 Hz) and per run (``hmi_run_upper95``: the
    share of runs with any HMI, runs being independent draws of start time and seed)."""
    rows = []
    for cfg, g in frames.groupby("config", sort=False):
        s = dict(summarise(g))
        s["nlos_used_share"] = float((g["n_nlos_used"] > 0).mean())
        per_run = g.groupby(["world", "run"], sort=False)["hmi"].any()
        s["runs"] = float(len(per_run))
        s["hmi_rate_upper95"] = hmi_rate_upper(int(g["hmi"].sum()), len(g))
        s["hmi_run_upper95"] = hmi_rate_upper(int(per_run.sum()), len(per_run))
        rows.append({"config": cfg, **s})
    return pd.DataFrame(rows).set_index("config")


def _job_done(path: Path) -> bool:
    """A job file whose Parquet footer reads and holds rows; a torn one (a power cut after the
    rename, nothing being fsynced) is removed to be redone (a user trial: every rerun stopped
    on it)."""
    if not path.exists():
        return False
    import pyarrow.parquet as pq

    try:
        if pq.read_metadata(path).num_rows > 0:
            return True
    except (OSError, ValueError):
        pass
    path.unlink(missing_ok=True)
    return False


def _withdraw(out: Path) -> None:
    """Remove the campaign's tables and figures from ``out`` (not its job files)."""
    for name in ("summary.json", "summary.csv", "epochs.parquet", "campaign.png"):
        (out / name).unlink(missing_ok=True)
    for old in out.glob("stanford_*.png"):
        old.unlink(missing_ok=True)


def _write_parquet(df: pd.DataFrame, path: Path) -> None:
    with atomic_path(path) as tmp:
        df.to_parquet(tmp)


def _write_text(text: str, path: Path) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def run_campaign(
    out: Path,
    setup: CampaignSetup,
    jobs: Sequence[Job],
    scheduler: Scheduler | None = None,
    log: Callable[[str], None] | None = None,
    on_job_done: Callable[[Job, Path], None] | None = None,
) -> CampaignResult:
    """Run the jobs not yet done, then write the final tables.

    Parameters
    ----------
    out : Path
        Output folder: ``jobs/`` (one Parquet file per job), ``epochs.parquet`` (every job's
        epochs in job order), ``summary.csv`` and ``summary.json`` (:func:`report`, overall
        and per world).
    setup : CampaignSetup
    jobs : sequence of Job
    scheduler : Scheduler, optional
        Where the jobs run (default serial). The workers need no shared file system: the
        worlds travel with ``setup`` and the job files are written here.
    log : callable, optional
        Receives one line of progress per finished job.
    on_job_done : callable, optional
        Called with each job and its file once the file is written (an exception from it
        stops the campaign; the finished job files stay).
    """
    t0 = time.perf_counter()
    say = log or (lambda _m: None)
    code, setup_digest = code_fingerprint(), setup.digest()
    folder = out / "jobs"
    folder.mkdir(parents=True, exist_ok=True)
    paths = {j: folder / f"{j.world}_{j.run:04d}_{job_key(j, setup_digest, code)}.parquet"
             for j in jobs}  # fmt: skip
    todo = [j for j in jobs if not _job_done(paths[j])]
    say(f"{len(jobs)} jobs, {len(todo)} to do")
    # workers running other code would return other code's results under this code's keys
    with TaskRunner(scheduler or Scheduler.serial(), code_version=code_fingerprint) as runner:
        if todo:
            # connect (and check the workers) first: a mistyped --scheduler address withdrew
            # a finished campaign's tables and figures, then was refused
            runner.client()
        # an earlier campaign's tables and figures (other rules, risk, worlds, runs or code)
        # must not stay beside this one's job files looking finished when it is stopped (as
        # `predisat process` withdraws its published masks, reconstruct.batch._withdraw_published);
        # withdrawn even with no job to do: the tables are rewritten below and the figures by
        # the command after them, and a rerun with fewer runs or worlds stopped in between left
        # the new tables beside the earlier campaign's figures
        _withdraw(out)
        for k, (job, df, dt) in enumerate(
            runner.map_unordered(_timed_job, setup, todo, name="campaign"), 1
        ):
            _write_parquet(df, paths[job])
            say(f"[{k}/{len(todo)}] {paths[job].name}: {len(df)} rows, {dt:.1f} s "
                f"(elapsed {time.perf_counter() - t0:.0f} s)")  # fmt: skip
            if on_job_done is not None:
                on_job_done(job, paths[job])
    ordered = tuple(paths[j] for j in jobs)
    frames = pd.concat([pd.read_parquet(p) for p in ordered], ignore_index=True)
    table = report(frames)
    per_world = {
        w: report(g).to_dict(orient="index") for w, g in frames.groupby("world", sort=False)
    }
    _write_parquet(frames, out / "epochs.parquet")
    widths = rule_widths(setup.configs, setup.risk_per_epoch)
    _write_text(
        json.dumps({"all": table.to_dict(orient="index"), "per_world": per_world,
                    "integrity": {"risk_per_epoch": setup.risk_per_epoch, "per_rule": widths}},
                   indent=1),
        out / "summary.json",
    )  # fmt: skip
    buf = io.StringIO()
    table.to_csv(buf)
    _write_text(buf.getvalue(), out / "summary.csv")
    return CampaignResult(tuple(jobs), len(todo), ordered, frames, table, time.perf_counter() - t0)


def figure(frames: pd.DataFrame, table: pd.DataFrame, paths: Sequence[Path]) -> None:
    """Interval length distributions (claimed epochs) and the outcome shares of ``table``
    (:func:`report`) per rule, written to every path of ``paths`` (PNG)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax, bx = fig.subplots(1, 2, width_ratios=[3, 2])
    colours = {"masks": "#1b7837", "pipeline": "#762a83", "none": "#b2182b", "cutoff15": "#ef8a62",
               "masks_k2": "#7fbf7b", "masks_budget": "#2166ac",
               "pipeline_budget": "#c2a5cf", "masks_split": "#053061",
               "pipeline_split": "#40004b"}  # fmt: skip
    bins = np.geomspace(3.0, 3000.0, 60)
    for cfg, g in frames.groupby("config", sort=False):
        length = g.loc[g["claim"], "length_m"].to_numpy(float)
        med = f"median {np.median(length):.0f} m" if length.size else "no claim"
        ax.hist(length, bins=bins, histtype="step", lw=1.5, color=colours.get(str(cfg)),
                label=f"{cfg} ({med})")  # fmt: skip
    for v in (70.0, 600.0):
        ax.axvline(v, color="k", ls="--", lw=0.8)
    ax.text(70.0, ax.get_ylim()[1] * 0.95, " LOCOPROL typical", fontsize=8)
    ax.text(600.0, ax.get_ylim()[1] * 0.85, " LOCOPROL max", fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("interval length, claimed epochs (m)")
    ax.set_ylabel("epochs")
    ax.legend(fontsize=8)
    names = list(table.index)
    x = np.arange(len(names))
    six = table["mode_three_pairs_share"].to_numpy(float) * 100
    bx.bar(x - 0.2, six, 0.4, color="#9ecae1", label="three-pair mode (>= 6 satellites)")
    bx.bar(x + 0.2, table["claim_share"].to_numpy(float) * 100, 0.4, color="#3182bd",
           label="claim (a safety claim under the *_budget / *_split rules only; the "
                 "others at a fixed k, no integrity budget)")  # fmt: skip
    for k, h in enumerate(table["hmi"].astype(int)):
        bx.text(k, 102, f"HMI {h}", ha="center", fontsize=9, color="#b2182b" if h else "k")
    bx.axhline(60.0, color="k", ls="--", lw=0.8)
    bx.text(len(names) - 0.5, 61.0, "LOCOPROL: 6 sats 60 %", ha="right", fontsize=8)
    bx.set_xticks(x, names)
    bx.set_ylim(0, 112)
    bx.set_ylabel("% of epochs")
    bx.legend(fontsize=8, loc="lower right")
    fig.suptitle("Locator campaign, epochs per rule: "
                 + ", ".join(f"{c} {int(n):,}" for c, n in table["epochs"].items()))  # fmt: skip
    for path in paths:
        fig.savefig(path, dpi=110)


def stanford(frames: pd.DataFrame, out: Path) -> list[Path]:
    """One Stanford integrity diagram per rule, ``out/stanford_<config>.png``."""
    from locator.plots import stanford_diagram

    paths = []
    for cfg, g in frames.groupby("config", sort=False):
        fig = stanford_diagram(g, title=f"Stanford diagram, rule {cfg} ({len(g):,} epochs)")
        paths.append(out / f"stanford_{cfg}.png")
        with atomic_path(paths[-1]) as tmp:
            fig.savefig(tmp, dpi=110)
    for old in out.glob("stanford_*.png"):  # an earlier campaign's rules, not this one's
        if old not in paths:
            old.unlink(missing_ok=True)
    return paths
