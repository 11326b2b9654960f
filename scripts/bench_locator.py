"""Throughput of the 1-D locator beside the code before its speed-up and a 3-D least-squares fix.

Three codes on the same epochs, alternately, ``--repeat`` times; each time is the CPU time of
its process (``time.process_time``: on a shared machine the wall time counts the other users'
work) and the best of each is kept:

* **locator**: ``locator.run.run_locator`` of this repository (corrections where the source
  has them, selection, SATHIA pairs, intervals, FDE, heading check, odometry);
* **old locator**: the same call on the code of ``--old-rev`` (default ``1403519``, the locator
  of 2026-12-04 before its pair work was compiled: the code the issue measured at 193 epochs/s),
  taken from git (``git archive``) into a temporary folder and run in a child process, so both
  run side by side in one command on the same epochs;
* **3-D LSQ**: a general 3-D position + clock fix on the same epochs (no selection, no
  integrity): ``locator.spp.solve_observations`` on real data (the same corrections, iterated
  weighted least squares, elevation mask 0), a plain Gauss-Newton on the corrected
  pseudoranges of the simulated epochs.

Epochs:

* **real**: GEONET stations 0759 and 3040 (RTKLIB test data, 240 epochs, GPS C1) on a virtual
  straight track through each station, no masks (``trust="none"``);
* **simulated**: the stored epochs of ``tests/data/locator_regression`` as the locator sees them
  (satellite positions and corrected pseudoranges): the demo world's stop-and-go run (151
  epochs, about 30 received signals, all constellations) with the world's true masks (about 23
  satellites trusted) and without masks (about 30), active integrity (three pairs) and passive
  (every pair, up to 435); the Nice-Digne canyon run (a campaign job: NLOS, exclusions) with
  its true masks. Default error model and ``k``.

Prints epochs per second of each and the ratios: old / new time (the speed-up) and new / 3-D
time (what the 1-D locator costs beside a 3-D fix).

Usage::

    .venv/bin/python scripts/bench_locator.py [--data ../shared/data/gnss/rtklib] [--repeat 3]
        [--old-rev 1403519]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _code_path() -> None:
    """This repository first on the path (a worktree measures itself, not an installed copy);
    in the child the old tree before it."""
    sys.path.insert(0, str(REPO))
    sys.path.insert(0, str(REPO / "scripts"))
    if "--child" in sys.argv:
        sys.path.insert(0, sys.argv[sys.argv.index("--child") + 1])


_code_path()

from locator.fde import LocatorConfig  # noqa: E402
from locator.run import RunConfig, run_locator  # noqa: E402

Case = tuple[str, Callable[[], int]]
"""A label and a function running the locator on its epochs (returns the number of epochs)."""


def wls_3d(sat_ecef_m: np.ndarray, rho_m: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Gauss-Newton position + clock from corrected pseudoranges (equal weights)."""
    x = np.append(x0, 0.0)
    for _ in range(10):
        d = sat_ecef_m - x[:3]
        r = np.linalg.norm(d, axis=-1)
        h = np.hstack([-d / r[:, None], np.ones((len(r), 1))])
        dx = np.linalg.lstsq(h, rho_m - r - x[3], rcond=None)[0]
        x = x + dx
        if np.linalg.norm(dx[:3]) < 1e-4:
            break
    return x


def timed(fn: Callable[[], object]) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def locator_cases(data: Path) -> tuple[list[Case], dict[str, Callable[[], object]]]:
    """The locator's runs (by label) and the 3-D fix on the same epochs (by label).

    Uses only what the old code has too: ``run_locator``, ``RunConfig``, ``LocatorConfig``,
    ``RinexSource``, ``AntennaPath`` and the stored cases' loader.
    """
    from locator_static import GEONET_0759_ECEF_M, virtual_track

    from locator.corrections import RangeModel
    from locator.observations import Observations
    from locator.sathia import AntennaPath
    from locator.sources import RinexSource
    from tests.regression.locator_cases import SimCase, load_sim_case

    runs = []
    for name in ("0759", "3040"):
        obs = Observations.from_rinex(data / f"{name}0920.05o")
        model = RangeModel.from_rinex_nav(data / f"{name}0920.05n")
        x = GEONET_0759_ECEF_M if name == "0759" else obs.header.approx_position_ecef_m
        src = RinexSource(model, obs, "G", odometer=np.zeros(len(obs.gps_s)))
        runs.append((AntennaPath(virtual_track(np.asarray(x, float), 45.0), 0.0), src, model, obs))
    none = _config("none", "active")

    def real() -> int:
        for path, src, _, _ in runs:
            run_locator(path, src, start_chainage_m=2000.0, config=none)
        return sum(len(r[3].gps_s) for r in runs)

    def real_3d() -> None:
        from locator.spp import solve_observations

        for _, _, model, obs in runs:
            solve_observations(model, obs, el_mask_deg=0.0)

    cases: list[Case] = [("real (0759, 3040; GPS)", real)]
    baselines: dict[str, Callable[[], object]] = {"real (0759, 3040; GPS)": real_3d}
    for name, trust, integrity, label in (
        ("demo", "masks", "active", "demo world, true masks"),
        ("demo", "none", "active", "demo world, no masks, active"),
        ("demo", "none", "passive", "demo world, no masks, passive"),
        ("canyon", "masks", "active", "canyon world, true masks"),
    ):
        case = load_sim_case(name)
        cfg = _config(trust, integrity)

        def project(case: SimCase = case, cfg: RunConfig = cfg) -> int:
            run_locator(case.path, case.source, start_chainage_m=case.start_m, config=cfg,
                        masks=case.masks)  # fmt: skip
            return len(case.source.gps_s)

        def fix_3d(case: SimCase = case) -> None:
            x = case.path.ecef_at(float(case.start_m))
            for k in range(len(case.source.gps_s)):
                e = case.source.observe(k, x[:3])
                if len(e.sats) >= 4:
                    x = wls_3d(e.sat_ecef_m, e.pseudorange_m, x[:3])

        cases.append((label, project))
        baselines[label] = fix_3d
    return cases, baselines


def _config(trust: str, integrity: str) -> RunConfig:
    """The same work on both sides: k = 2 and one trusted set (the old code knows neither the
    integrity budget nor partitioned trust, the new one defaults to both)."""
    loc_fields = {f.name for f in dataclasses.fields(LocatorConfig)}
    run_fields = {f.name for f in dataclasses.fields(RunConfig)}
    loc = LocatorConfig(budget=None) if "budget" in loc_fields else LocatorConfig()
    extra = {"trust_stretches": 1} if "trust_stretches" in run_fields else {}
    return RunConfig(loc, trust=trust, integrity=integrity, **extra)  # type: ignore[arg-type]


def child(data: Path) -> int:
    """One timed run of every case on the code first on the path; JSON label -> [n, s]."""
    cases, _ = locator_cases(data)
    for _, fn in cases:  # warm caches (file reads) as the parent does
        fn()
    out = {}
    for label, fn in cases:
        t = time.process_time()
        n = fn()
        out[label] = [n, time.process_time() - t]
    print(json.dumps(out))
    return 0


def old_tree(rev: str, into: Path) -> Path:
    """``locator``, ``predisat`` and ``surveys`` of ``rev`` extracted under ``into``."""
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", rev, "locator", "predisat", "surveys"],
        check=True, capture_output=True,
    ).stdout  # fmt: skip
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--data", type=Path, default=REPO.parent / "shared" / "data" / "gnss" / "rtklib"
    )
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--old-rev", default="1403519", help="git revision of the old locator")
    ap.add_argument("--child", metavar="TREE", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        return child(args.data)
    cases, baselines = locator_cases(args.data)
    for _, fn in cases:  # compile / load the kernels before timing
        fn()
    best: dict[str, list[float]] = {label: [np.inf, np.inf, np.inf] for label, _ in cases}
    n_of: dict[str, int] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tree = old_tree(args.old_rev, Path(tmp))
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tree), str(REPO)])}
        cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(tree),
               "--data", str(args.data)]  # fmt: skip
        for _ in range(args.repeat):  # alternate so that all three see the same machine load
            old = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True,
                                            text=True, cwd=tmp).stdout)  # fmt: skip
            for label, fn in cases:
                t = time.process_time()
                n_of[label] = fn()
                b = best[label]
                b[0] = min(b[0], time.process_time() - t)
                b[1] = min(b[1], old[label][1])
                b[2] = min(b[2], timed(baselines[label]))
                assert old[label][0] == n_of[label]
    head = (f"{'epochs':<32} {'n':>4} {'locator':>9} {'old':>9} {'3-D LSQ':>9} "
            f"{'old/new':>8} {'new/3-D':>8}")  # fmt: skip
    print(head)
    print(f"{'':<32} {'':>4} {'ep/s':>9} {'ep/s':>9} {'ep/s':>9}")
    for label, _ in cases:
        n, (tn, to, tb) = n_of[label], best[label]
        print(f"{label:<32} {n:>4} {n / tn:>9.0f} {n / to:>9.0f} {n / tb:>9.0f} "
              f"{to / tn:>7.2f}x {tn / tb:>7.2f}x")  # fmt: skip
    print(f"CPU time, best of {args.repeat}, alternately; old = the locator at {args.old_rev}; "
          "new/3-D = locator time over 3-D least-squares time on the same epochs (the locator "
          "also selects, forms pair intervals, runs FDE, the heading and odometry checks)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
