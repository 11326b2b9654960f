"""The ``locator campaign`` sub-command: its arguments and its entry point.

:func:`add_parser` registers the sub-command on the ``locator`` command line
(:mod:`locator.cli` calls it); :func:`cmd_campaign` runs it through
:func:`locator.campaign.run_campaign`. The names below repeat :data:`locator.campaign.WORLDS`
and :data:`locator.campaign.CONFIGS` so that ``locator --help`` does not import the simulator
(a test keeps them equal).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from predisat.cli.args import (
    add_command,
    existing_dir,
    integrity_risk,
    output_dir,
    output_file,
    positive_int,
    scheduler_options,
)
from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH

if TYPE_CHECKING:
    from predisat.scheduler import Scheduler

__all__ = ["CONFIG_NAMES", "WORLD_NAMES", "add_parser", "cmd_campaign"]

WORLD_NAMES = ("mixed-1", "mixed-2", "mixed-3", "mixed-4", "canyon")
"""Names of :data:`locator.campaign.WORLDS`."""
CONFIG_NAMES = (
    "masks", "none", "cutoff15", "masks_k2", "masks_budget", "masks_split", "none_budget",
    "cutoff15_budget", "pipeline", "pipeline_budget", "pipeline_split",
)  # fmt: skip
"""Names of :data:`locator.campaign.CONFIGS`."""
_RUNS_PER_WORLD = 88


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Add ``campaign`` to the sub-parsers of the ``locator`` command line."""
    p = add_command(
        sub, "campaign",
        "simulated campaign: worlds x start times x rules, on Dask, resumable",
        "Simulate train runs in synthetic worlds at start times spread over the day and locate "
        "each under every rule (true masks, none, 15 deg cut-off, k = 2, integrity budget, "
        "pipeline masks); one Parquet file per run under OUT/jobs (a rerun skips the finished "
        "ones), then OUT/epochs.parquet, summary.csv, summary.json, campaign.png and one "
        "Stanford diagram per rule (docs/locator.md, campaign).",
    )  # fmt: skip
    p.add_argument("--out", required=True, type=output_dir, metavar="DIR",
                   help="output folder (created; an existing one is resumed)")  # fmt: skip
    p.add_argument(
        "--cache", type=output_dir, metavar="DIR",
        help="worlds, true masks and the learned error model, built on first use and read "
        "afterwards (default OUT/cache)",
    )  # fmt: skip
    p.add_argument("--worlds", nargs="*", choices=WORLD_NAMES, default=list(WORLD_NAMES),
                   metavar="NAME", help=f"worlds to run, of {', '.join(WORLD_NAMES)} "
                   "(default all; none with --demo or --pipeline-world: those only)")  # fmt: skip
    p.add_argument(
        "--demo",
        type=existing_dir("a `predisat demo --out` folder (truth/world.npz, masks/masks.parquet)"),
        metavar="DIR",
        help="add the demo world and its pipeline masks (the pipeline rules; default: none, "
        "the synthetic worlds only)",
    )
    p.add_argument(
        "--pipeline-world", action="append", type=_named_world, default=[],
        metavar="NAME=DIR",
        help="add a rendered and processed world under NAME (repeatable): a `predisat demo "
        "--out` folder, or a world folder of scripts/eval_rigs.py or scripts/eval_ood_world.py "
        "(synth/truth, proc/masks.parquet); its pipeline masks join the pipeline rules",
    )  # fmt: skip
    p.add_argument("--runs-per-world", type=positive_int, default=_RUNS_PER_WORLD, metavar="N",
                   help=f"runs per world (default {_RUNS_PER_WORLD}); more runs keep the "
                   "finished ones")  # fmt: skip
    p.add_argument("--configs", nargs="+", choices=CONFIG_NAMES, default=list(CONFIG_NAMES),
                   metavar="RULE", help=f"rules, of {', '.join(CONFIG_NAMES)} (default all; "
                   "the pipeline ones need --demo or --pipeline-world)")  # fmt: skip
    p.add_argument(
        "--integrity-risk", type=integrity_risk, default=DEFAULT_RISK_PER_EPOCH, metavar="P",
        help="integrity risk per epoch of the *_budget rules (default "
        f"{DEFAULT_RISK_PER_EPOCH:g}); the other rules fix their k (docs/locator.md)",
    )  # fmt: skip
    scheduler_options(p, "the runs", threads=True)
    p.add_argument(
        "--figure",
        type=output_file,
        metavar="PNG",
        help="write the summary figure here too (default only OUT/campaign.png)",
    )
    p.set_defaults(func=cmd_campaign)
    return p


def _named_world(text: str) -> tuple[str, Path]:
    name, sep, folder = text.partition("=")
    if not sep or not name or not folder:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected NAME=DIR, e.g. ood-41=/tmp/ood/fisheye_s41"
        )
    if name in WORLD_NAMES or name == "demo":
        raise argparse.ArgumentTypeError(
            f"{text!r}: {name!r} is a built-in world's name; choose another NAME"
        )
    path = Path(folder)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r}: {folder} is not a folder")
    return name, path


def cmd_campaign(args: argparse.Namespace) -> int:
    """Run ``locator campaign``; prints the summary per rule."""
    from predisat.scheduler import Scheduler

    scheduler = Scheduler.parse(args.scheduler, args.workers)
    extra: list[tuple[str, Path]] = list(args.pipeline_world)
    names = [n for n, _ in extra]
    if len(set(names)) != len(names):
        raise ValueError(f"--pipeline-world: a NAME given twice in {names}; name each once")
    rendered = args.demo is not None or bool(extra)
    if not rendered and not args.worlds:
        raise ValueError(
            "--worlds without names: no world to run; name some, or add --demo DIR or "
            "--pipeline-world NAME=DIR"
        )
    if not rendered and set(args.configs) <= {"pipeline", "pipeline_budget", "pipeline_split"}:
        raise ValueError(
            f"--configs {' '.join(args.configs)}: the pipeline rules need the pipeline masks of "
            "a `predisat demo` folder or of a processed world; add --demo DIR or "
            "--pipeline-world NAME=DIR"
        )
    from predisat.atomic import exclusive_folder

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    # two campaigns into one folder ran every job twice and mixed their figures (a user trial)
    with exclusive_folder(out):
        return _campaign(args, out, scheduler, extra)


def _campaign(
    args: argparse.Namespace, out: Path, scheduler: Scheduler, extra: list[tuple[str, Path]]
) -> int:
    import pandas as pd

    from locator.campaign import (
        WORLDS,
        CampaignSetup,
        calibrate,
        demo_world,
        figure,
        jobs_for,
        load_world,
        pipeline_world,
        rule_widths,
        run_campaign,
        stanford,
    )

    cache: Path = args.cache or out / "cache"
    quiet = bool(getattr(args, "quiet", False))

    def say(text: str) -> None:
        if not quiet:
            print(text, file=sys.stderr, flush=True)

    t = time.perf_counter()
    model = calibrate(cache)
    e = model.error
    say(f"error model: sigma(el)^2 = {e.a_m:.3f}^2 + ({e.b_m:.3f} / sin el)^2 m^2, learned on "
        f"the campaign's own simulation ({time.perf_counter() - t:.0f} s)")  # fmt: skip
    for rule, width in rule_widths(args.configs, args.integrity_risk).items():
        say(f"  {rule}: {width}")
    worlds = {}
    for spec in WORLDS:
        if spec.name in args.worlds:
            t = time.perf_counter()
            worlds[spec.name] = load_world(spec, cache)
            say(f"world {spec.name} ready ({time.perf_counter() - t:.0f} s)")
    if args.demo is not None:
        worlds["demo"] = demo_world(args.demo)
    for name, folder in extra:
        worlds[name] = pipeline_world(folder, name)
        say(f"world {name} ready ({folder})")
    setup = CampaignSetup(model, tuple(args.configs), args.integrity_risk, worlds)
    jobs = jobs_for(list(worlds), args.runs_per_world)
    say(f"{scheduler.describe()}")
    result = run_campaign(out, setup, jobs, scheduler, log=say)
    per_rule = result.frames.groupby("config", sort=False).size()
    say(f"{result.ran} runs done now, {len(jobs)} in all; {int(per_rule.iloc[0]):,} epochs per "
        f"rule ({result.wall_s:.0f} s)")  # fmt: skip
    figure(result.frames, result.table, [out / "campaign.png", *filter(None, [args.figure])])
    stanford(result.frames, out)
    with pd.option_context("display.width", 200):
        print(result.table.T.to_string(float_format=lambda v: f"{v:.4g}"))
    return 0
