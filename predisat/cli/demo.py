"""``predisat demo``: the whole chain on the embedded demo line, and the steps other packages add.

The demo renders a synthetic survey of line 144 with ground truth, processes it into masks,
scores them and writes the availability report. Packages installed beside PREDISAT add later
steps through the entry-point group :data:`DEMO_STEPS_GROUP` (the ``locator`` package adds the
simulated train run located under each trust rule): ``predisat`` never imports them, so the
dependencies run one way (``docs/architecture.md``).
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from predisat.cli.args import finite_float, output_dir, positive_int
from predisat.cli.common import km_range

if TYPE_CHECKING:
    import pandas as pd

    from predisat.masks.maskset import MaskSet
    from predisat.synth.generate import SynthResult
    from predisat.track import TrackMap

__all__ = [
    "DEMO_CAMERA",
    "DEMO_FROM_KM",
    "DEMO_STEPS_GROUP",
    "DEMO_TO_KM",
    "DemoContext",
    "DemoStep",
    "DemoStepResult",
    "add_parser",
    "availability_table",
    "default_workers",
    "demo_steps",
    "render_demo_survey",
    "run",
]

DEMO_STEPS_GROUP = "predisat.demo_steps"
"""Entry-point group of the demo's later steps: each entry is a :class:`DemoStep`."""


@dataclass(frozen=True)
class DemoContext:
    """What a demo step gets: the demo's folder, track, ground truth and processed masks.

    Attributes
    ----------
    out_dir : Path
        The demo's output folder; a step writes in a subfolder of its own.
    track : TrackMap
    truth_dir : Path
        The synthetic ground truth (``world.npz``, ``true_masks.npz``).
    masks : MaskSet
        The masks the pipeline made from the frames.
    quiet : bool
    """

    out_dir: Path
    track: TrackMap
    truth_dir: Path
    masks: MaskSet
    quiet: bool = False


@dataclass(frozen=True)
class DemoStepResult:
    """What a demo step prints (``text``) and the outputs it lists at the end, by name."""

    text: str
    outputs: Mapping[str, Path] = field(default_factory=dict)


class DemoStep(Protocol):
    """A later step of ``predisat demo``, registered under :data:`DEMO_STEPS_GROUP`."""

    @property
    def title(self) -> str: ...

    def run(self, ctx: DemoContext) -> DemoStepResult: ...


def demo_steps() -> list[DemoStep]:
    """The installed demo steps, in the order of their entry-point names."""
    from importlib.metadata import entry_points  # lazy: 25 ms, only the demo needs it

    found = sorted(entry_points(group=DEMO_STEPS_GROUP), key=lambda ep: ep.name)
    return [ep.load() for ep in found]


DEMO_FROM_KM = 4.0
DEMO_TO_KM = 6.0
DEMO_IMAGE_SIZE_PX = (640, 480)  # the default side camera, resampled: keeps the demo quick
# The fisheye sees down to the horizon and 90 deg to either side of its look direction; with
# the pinhole the masks lose 63-65 % of the visible sky instead of 14-16 % (docs/pipeline.md).
DEMO_CAMERA = "fisheye"


def render_demo_survey(
    out_dir: str | os.PathLike[str],
    seed: int = 1,
    camera: str = DEMO_CAMERA,
    workers: int = 1,
    progress: bool = True,
    spacing_m: float = 10.0,
    from_km: float = DEMO_FROM_KM,
    to_km: float = DEMO_TO_KM,
) -> SynthResult:
    """The demo's synthetic survey: line 144 km ``from_km``-``to_km`` (default
    ``DEMO_FROM_KM``-``DEMO_TO_KM``), mixed scenery and skies, the default ``camera``
    (``"fisheye"`` or ``"pinhole"``) resized to ``DEMO_IMAGE_SIZE_PX``, a position every
    ``spacing_m`` (:func:`predisat.synth.generate.generate_survey`)."""
    from predisat.camera.models import default_camera
    from predisat.synth.generate import generate_survey
    from predisat.track import demo_track

    return generate_survey(
        demo_track(),
        from_km * 1000.0,
        to_km * 1000.0,
        sky="mixed",
        seed=seed,
        out_dir=out_dir,
        camera=default_camera(camera).resized(*DEMO_IMAGE_SIZE_PX),  # type: ignore[arg-type]
        progress=progress,
        workers=workers,
        overwrite=True,
        spacing_m=spacing_m,
    )


def default_workers() -> int:
    """Rendering processes by default: the cores, at most 2."""
    return max(1, min(2, os.cpu_count() or 1))


def availability_table(summary: pd.DataFrame) -> str:
    """The line-wide figures a reader looks at first, one row per trust rule."""
    cols = {
        "rule": "rule",
        "share_ge2": ">=2 sats %",
        "share_ge4": ">=4 sats %",
        "share_ge6": ">=6 sats %",
        "mean_count": "mean sats",
        "longest_below4_m": "longest <4 m",
        "interval_median_m": "interval median m",
        "interval_p95_m": "p95 m",
    }
    t = summary[list(cols)].rename(columns=cols)
    for c in (">=2 sats %", ">=4 sats %", ">=6 sats %"):
        t[c] = 100.0 * t[c]
    return str(t.to_string(index=False, float_format=lambda x: f"{x:.1f}"))


def run(args: argparse.Namespace) -> int:
    """Run ``predisat demo``: render, process, evaluate, report, then every installed demo
    step (:func:`demo_steps`)."""
    # imported here: the renderer and the reconstruction are heavy, `predisat --help` is not
    from predisat.availability.run import run_availability
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.evalfigures import evaluation_figure
    from predisat.reconstruct.evaluate import compare, evaluate_masks, format_table, load_truth
    from predisat.synth.generate import contact_sheet
    from predisat.track import demo_track

    steps = demo_steps()
    n = 4 + len(steps)
    out = Path(args.out)
    track = demo_track()
    lo_m, hi_m = km_range(track, args.from_km, args.to_km)
    lo_km, hi_km = lo_m / 1000.0, hi_m / 1000.0
    print(
        f"demo: {track.name}, chainage {lo_km:.1f}-{hi_km:.1f} km, mixed scenery and "
        f"skies, {args.camera} side cameras, seed {args.seed} -> {out}"
    )
    t0 = time.perf_counter()
    print(f"demo 1/{n}: rendering the synthetic survey and its ground truth")
    synth = render_demo_survey(
        out, seed=args.seed, camera=args.camera, workers=args.workers, progress=not args.quiet,
        from_km=lo_km, to_km=hi_km,
    )  # fmt: skip
    t_synth = time.perf_counter() - t0
    sheet = contact_sheet(synth.survey_dir, out / "contact_sheet.png")

    print(f"demo 2/{n}: processing the frames into elevation masks")
    t1 = time.perf_counter()
    processed = process_survey(
        synth.survey_dir, out / "masks", workers=args.workers, progress=not args.quiet
    )
    t_process = time.perf_counter() - t1
    print(f"  {processed}")

    print(f"demo 3/{n}: masks against the synthetic ground truth")
    comp = compare(processed.masks, load_truth(synth.truth_dir))
    table = evaluate_masks(comp)
    overall = table[table["source"] == "all"]
    with_cols = ["sector", "median_error_deg", "p95_error_deg", "false_trust", "sky_lost"]
    print(format_table(overall[with_cols]))
    eval_png = out / "evaluation.png"
    evaluation_figure(comp, title="Demo masks against the ground truth").savefig(eval_png, dpi=100)

    print(f"demo 4/{n}: availability report (embedded navigation day, GPS)")
    run = run_availability(
        processed.masks, track, None, out_dir=out / "availability", progress=not args.quiet
    )
    print(availability_table(run.summary))
    print("  (LOCOPROL on line 144: >= 4 satellites 95 % of the time, >= 6 60 %)")

    ctx = DemoContext(out, track, synth.truth_dir, processed.masks, quiet=args.quiet)
    outputs: dict[str, Path] = {}
    for k, step in enumerate(steps, start=5):
        print(f"demo {k}/{n}: {step.title}")
        result = step.run(ctx)
        print(result.text)
        outputs.update(result.outputs)
    dt = time.perf_counter() - t0
    print(
        f"demo: done in {dt:.0f} s; {synth.n_frames} frames at {synth.n_positions} positions "
        f"(rendering {synth.n_frames / t_synth:.2f} frames/s, processing "
        f"{synth.n_frames / t_process:.2f} frames/s)\n"
        f"  survey:        {synth.survey_dir}\n"
        f"  ground truth:  {synth.truth_dir}\n"
        f"  contact sheet: {sheet}\n"
        f"  masks:         {processed.masks_path}\n"
        f"  evaluation:    {eval_png}\n"
        f"  report:        {run.report_html}"
        + "".join(f"\n  {name + ':':14} {path}" for name, path in outputs.items())
    )
    return 0


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``demo`` subcommand on the ``predisat`` subparsers."""
    p = sub.add_parser(
        "demo",
        help="run the pipeline on the embedded demo (2 km of line 144)",
        description=(
            "Render a synthetic survey of 2 km of line 144 with ground truth, process it into "
            "masks, compare them with the truth, write the availability report, then run the "
            "installed demo steps (the locator's: a simulated train run located under each "
            "trust rule)."
        ),
    )
    p.add_argument(
        "--out", default="demo_out", type=output_dir, metavar="DIR", help="output folder"
    )
    p.add_argument("--seed", type=int, default=1, help="random seed")
    p.add_argument(
        "--camera", choices=("fisheye", "pinhole"), default=DEMO_CAMERA,
        help=f"side camera model (default {DEMO_CAMERA})",
    )  # fmt: skip
    p.add_argument("--from-km", type=finite_float, default=DEMO_FROM_KM, metavar="KM",
                   help=f"start of the stretch (default {DEMO_FROM_KM})")
    p.add_argument("--to-km", type=finite_float, default=DEMO_TO_KM, metavar="KM",
                   help=f"end of the stretch (default {DEMO_TO_KM}). Another stretch is another "
                   "world: the scenery recipe is drawn for it (under 800 m a short recipe), not "
                   "cut out of the default demo's")
    p.add_argument("--workers", type=positive_int, default=default_workers(),
                   help="rendering processes")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
