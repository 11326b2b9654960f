"""``predisat demo``: the whole chain on the embedded demo line, and the steps other packages add.

The demo renders a synthetic survey of line 144 with ground truth, processes it into masks,
scores them and writes the availability report. Packages installed beside PREDISAT add later
steps through the entry-point group :data:`DEMO_STEPS_GROUP` (the ``locator`` package adds the
simulated train run located under each trust rule): ``predisat`` never imports them, so the
dependencies run one way (``docs/architecture.md``).
"""

from __future__ import annotations

import argparse
import html
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from predisat.cli.args import (
    add_command,
    finite_float,
    integrity_risk,
    output_dir,
    positive_int,
    seed_value,
)
from predisat.cli.common import km_range
from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH, IntegrityBudget

if TYPE_CHECKING:
    import pandas as pd

    from predisat.masks.maskset import MaskSet
    from predisat.synth.generate import SynthResult
    from predisat.track import TrackMap

__all__ = [
    "DEMO_CAMERA",
    "DEMO_CANT_SPEED_KMH",
    "DEMO_FROM_KM",
    "DEMO_RATES",
    "DEMO_STEPS_GROUP",
    "DEMO_TO_KM",
    "DemoContext",
    "DemoPlan",
    "DemoStep",
    "DemoStepResult",
    "add_parser",
    "availability_table",
    "default_workers",
    "demo_steps",
    "render_demo_survey",
    "run",
    "write_index",
]

# the command's line in `predisat --help`
HELP = "run the pipeline on the embedded demo (2 km of line 144)"

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
    quick : bool
        ``predisat demo --quick``: a step keeps its work short (fewer epochs), not its kind.
    integrity : IntegrityBudget
        The integrity risk per epoch the demo's intervals are drawn for
        (``--integrity-risk``), the availability report's and the locator step's.
    """

    out_dir: Path
    track: TrackMap
    truth_dir: Path
    masks: MaskSet
    quiet: bool = False
    quick: bool = False
    integrity: IntegrityBudget = field(default_factory=IntegrityBudget)


@dataclass(frozen=True)
class DemoStepResult:
    """What a demo step prints (``text``), the outputs it lists at the end by name
    (``outputs``) and one line on what each shows (``what``, by the same names; the demo's
    ``index.html`` links every output with it)."""

    text: str
    outputs: Mapping[str, Path] = field(default_factory=dict)
    what: Mapping[str, str] = field(default_factory=dict)


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
# the demo line's curves canted as a 100 km/h line's, the vehicle rolling with them: a level
# vehicle on its R = 600 m curve reads as an IMU mistake (docs/reconstruction.md, section 16)
DEMO_CANT_SPEED_KMH = 100.0


def render_demo_survey(
    out_dir: str | os.PathLike[str],
    seed: int = 1,
    camera: str = DEMO_CAMERA,
    workers: int = 1,
    progress: bool = True,
    spacing_m: float = 10.0,
    from_km: float = DEMO_FROM_KM,
    to_km: float = DEMO_TO_KM,
    image_size_px: tuple[int, int] = DEMO_IMAGE_SIZE_PX,
) -> SynthResult:
    """The demo's synthetic survey: line 144 km ``from_km``-``to_km`` (default
    ``DEMO_FROM_KM``-``DEMO_TO_KM``), mixed scenery and skies, the default ``camera``
    (``"fisheye"`` or ``"pinhole"``) resized to ``image_size_px`` (width, height; default
    ``DEMO_IMAGE_SIZE_PX``), a position every ``spacing_m``
    (:func:`predisat.synth.generate.generate_survey`)."""
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
        camera=default_camera(camera).resized(*image_size_px),  # type: ignore[arg-type]
        progress=progress,
        workers=workers,
        overwrite=True,
        spacing_m=spacing_m,
        cant_speed_kmh=DEMO_CANT_SPEED_KMH,
    )


@dataclass(frozen=True)
class DemoPlan:
    """The size of a demo run: the stretch, the spacing of the positions, the frames' size
    and the availability epochs.

    Attributes
    ----------
    from_km, to_km : float
        Chainage of the stretch, km.
    spacing_m : float
        Distance between positions, metres (two frames each: left and right).
    image_size_px : tuple of int
        Width and height of the frames, pixels.
    step_s : float
        Spacing of the availability report's epochs, seconds.
    """

    from_km: float = DEMO_FROM_KM
    to_km: float = DEMO_TO_KM
    spacing_m: float = 10.0
    image_size_px: tuple[int, int] = DEMO_IMAGE_SIZE_PX
    step_s: float = 30.0

    @classmethod
    def full(cls, from_km: float | None = None, to_km: float | None = None) -> DemoPlan:
        """The demo: 2 km of line 144 (or the stretch given), 640 x 480 frames every 10 m."""
        return cls(DEMO_FROM_KM if from_km is None else from_km,
                   DEMO_TO_KM if to_km is None else to_km)  # fmt: skip

    @classmethod
    def quick(cls, from_km: float | None = None, to_km: float | None = None) -> DemoPlan:
        """``--quick``: the same steps on 0.3 km (or the stretch given), 320 x 240 frames every
        20 m and availability epochs every 120 s."""
        lo = DEMO_FROM_KM if from_km is None else from_km
        hi = lo + QUICK_LENGTH_KM if to_km is None else to_km
        return cls(lo, hi, 20.0, QUICK_IMAGE_SIZE_PX, 120.0)

    @property
    def n_positions(self) -> int:
        """Antenna positions, every ``spacing_m`` from the start to the end inclusive."""
        return math.floor((self.to_km - self.from_km) * 1000.0 / self.spacing_m + 1e-9) + 1

    @property
    def n_frames(self) -> int:
        """Frames rendered and processed: a left and a right one per position."""
        return 2 * self.n_positions

    def estimate_s(self, workers: int) -> dict[str, float]:
        """Wall time of each step, seconds, from the per-frame and per-position rates measured
        on two quiet cores (:data:`DEMO_RATES`), frames scaled by their pixel count; a busy
        machine takes longer. Keys: ``render``, ``process``, ``evaluate``, ``availability``,
        ``steps`` (the installed demo steps)."""
        px = self.image_size_px[0] * self.image_size_px[1] / (640.0 * 480.0)
        par = min(max(1, workers), 2) / 2.0  # the rates were measured with 2 workers
        r = DEMO_RATES
        epochs = 86400.0 / self.step_s
        return {
            "render": r["render_s"] + self.n_frames * r["render_s_per_frame"] * px / par,
            "process": r["process_s"] + self.n_frames * r["process_s_per_frame"] * px / par,
            "evaluate": r["evaluate_s"],
            "availability": r["availability_s"]
            + self.n_positions * epochs * r["availability_s_per_position_epoch"],
            "steps": r["steps_s"] + self.n_positions * r["steps_s_per_position"],
        }


QUICK_LENGTH_KM = 0.3
QUICK_IMAGE_SIZE_PX = (320, 240)

DEMO_RATES: dict[str, float] = {
    "render_s": 5.0,
    "render_s_per_frame": 0.42,
    "process_s": 4.0,
    "process_s_per_frame": 0.03,
    "evaluate_s": 1.0,
    "availability_s": 2.0,
    "availability_s_per_position_epoch": 3e-6,
    "steps_s": 6.0,
    "steps_s_per_position": 0.05,
}
"""Wall seconds of the demo's steps on two quiet cores: a fixed part and a part per 640 x 480
frame, per position-epoch of the availability report or per position. From the CPU seconds
of each step (this process and its workers) of ``predisat demo --quick`` (32 frames of 320 x
240: rendering 11.5 s, processing 5.9, evaluation 0.4, availability 1.8, locator 6.8) and
``predisat demo --from-km 4.0 --to-km 4.4`` (82 frames of 640 x 480: 69.8, 9.2, 0.5, 2.1, 7.1),
measured on 2026-12-04 with ``--workers 2``; rendering and processing divided by their two
workers."""


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
        # rounded down, as in the report: 99.96 % of the time is not 100 %
        t[c] = (1000.0 * t[c] + 1e-9).map(math.floor) / 10.0
    return str(t.to_string(index=False, float_format=lambda x: f"{x:.1f}"))


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def run(args: argparse.Namespace) -> int:
    """Run ``predisat demo``: render, process, evaluate, report, then every installed demo
    step (:func:`demo_steps`); writes ``index.html`` linking every output."""
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
    plan = (DemoPlan.quick if args.quick else DemoPlan.full)(args.from_km, args.to_km)
    lo_m, hi_m = km_range(track, plan.from_km, plan.to_km)
    plan = replace(plan, from_km=lo_m / 1000.0, to_km=hi_m / 1000.0)
    w, h = plan.image_size_px
    print(
        f"demo: {track.name}, chainage {plan.from_km:.1f}-{plan.to_km:.1f} km, mixed scenery "
        f"and skies, {args.camera} side cameras {w} x {h} px, seed {args.seed}"
        f"{', quick' if args.quick else ''} -> {out}"
    )
    est = plan.estimate_s(args.workers)
    print(
        f"demo: estimate {_duration(sum(est.values()))} for {plan.n_frames} frames at "
        f"{plan.n_positions} positions ({', '.join(f'{k} {v:.0f} s' for k, v in est.items())};"
        " rates measured on 2 quiet cores, a busy machine takes longer"
        + ("" if args.quick else "; --quick for a short run") + ")"
    )
    took: dict[str, float] = {}
    t0 = time.perf_counter()
    print(f"demo 1/{n}: rendering the synthetic survey and its ground truth")
    synth = render_demo_survey(
        out, seed=args.seed, camera=args.camera, workers=args.workers, progress=not args.quiet,
        from_km=plan.from_km, to_km=plan.to_km, spacing_m=plan.spacing_m,
        image_size_px=plan.image_size_px,
    )  # fmt: skip
    sheet = contact_sheet(synth.survey_dir, out / "contact_sheet.png")
    took["render"] = time.perf_counter() - t0

    print(f"demo 2/{n}: processing the frames into elevation masks{_left(est, took)}")
    t1 = time.perf_counter()
    processed = process_survey(
        synth.survey_dir, out / "masks", workers=args.workers, progress=not args.quiet,
        replace=True,  # the demo's folder is the demo's: its survey was just re-rendered
    )  # fmt: skip
    took["process"] = time.perf_counter() - t1
    print(f"  {processed}")

    print(f"demo 3/{n}: masks against the synthetic ground truth{_left(est, took)}")
    t1 = time.perf_counter()
    comp = compare(processed.masks, load_truth(synth.truth_dir))
    table = evaluate_masks(comp)
    overall = table[table["source"] == "all"]
    with_cols = ["sector", "median_error_deg", "p95_error_deg", "false_trust", "sky_lost"]
    print(format_table(overall[with_cols]))
    eval_png = out / "evaluation.png"
    evaluation_figure(comp, title="Demo masks against the ground truth").savefig(eval_png, dpi=100)
    took["evaluate"] = time.perf_counter() - t1

    print(f"demo 4/{n}: availability report (embedded navigation day, GPS only, as the locator "
          f"step){_left(est, took)}")  # fmt: skip
    t1 = time.perf_counter()
    budget = IntegrityBudget(args.integrity_risk)
    # the file just written, not the set in memory: the report's header and provenance then
    # name the masks it used (an in-memory set reads "in memory")
    report = run_availability(
        Path(processed.masks_path), track, None, out_dir=out / "availability",
        step_s=plan.step_s,
        progress=not args.quiet, integrity=budget,
    )  # fmt: skip
    took["availability"] = time.perf_counter() - t1
    print(availability_table(report.summary))
    print("  (GPS only; LOCOPROL on line 144: >= 4 satellites 95 % of the time, >= 6 60 %)")

    ctx = DemoContext(out, track, synth.truth_dir, processed.masks, quiet=args.quiet,
                      quick=args.quick, integrity=budget)  # fmt: skip
    outputs: dict[str, tuple[Path, str]] = {
        "survey": (synth.survey_dir, "the rendered survey: survey.yaml, manifest.csv and the "
                   "left and right frames"),
        "ground truth": (synth.truth_dir, "the synthetic world, its true masks and per-frame "
                         "sky labels"),
        "contact sheet": (sheet, "a dozen of the rendered frames side by side"),
        "masks": (Path(processed.masks_path), "the elevation masks the pipeline made from "
                  "the frames (docs/mask-format.md)"),
        "evaluation": (eval_png, "the masks' error and the sky they lose against the ground "
                       "truth, by direction"),
        "report": (Path(report.report_html), "the availability report: satellites trusted "
                   "along the line under the masks, no mask and a 15 deg cut-off (GPS)"),
        "availability table": (Path(report.report_html).parent / "summary.csv",
                               "every figure of the availability report, one row per rule"),
    }  # fmt: skip
    t1 = time.perf_counter()
    for k, step in enumerate(steps, start=5):
        print(f"demo {k}/{n}: {step.title}{_left(est, took)}")
        result = step.run(ctx)
        print(result.text)
        outputs.update({name: (path, result.what.get(name, name))
                        for name, path in result.outputs.items()})  # fmt: skip
    took["steps"] = time.perf_counter() - t1
    index = write_index(out, outputs, f"PREDISAT demo: {track.name}, chainage "
                        f"{plan.from_km:.1f}-{plan.to_km:.1f} km{' (quick)' if args.quick else ''}")
    dt = time.perf_counter() - t0
    print(
        f"demo: done in {_duration(dt)} (estimate {_duration(sum(est.values()))}; "
        f"{', '.join(f'{k} {v:.0f} s' for k, v in took.items())}); {synth.n_frames} frames at "
        f"{synth.n_positions} positions (rendering {synth.n_frames / took['render']:.2f} "
        f"frames/s, processing {synth.n_frames / took['process']:.2f} frames/s)\n"
        f"  index:         {index}"
        + "".join(f"\n  {name + ':':14} {path}" for name, (path, _) in outputs.items())
    )
    return 0


def _left(estimate_s: Mapping[str, float], took_s: Mapping[str, float]) -> str:
    """`` (about N s left)``: the estimate of the steps to come, scaled by how the steps done
    compared with their estimate on this machine."""
    done = sum(estimate_s[k] for k in took_s)
    pace = sum(took_s.values()) / done if done > 0 else 1.0
    left = pace * sum(v for k, v in estimate_s.items() if k not in took_s)
    return f" (about {_duration(left)} left)"


def write_index(
    out_dir: Path, outputs: Mapping[str, tuple[Path, str]], title: str
) -> Path:
    """``out_dir/index.html``: a link to every output (relative to ``out_dir``) with one line
    on what it shows; ``outputs`` maps a name to (path, one line)."""
    rows = []
    for name, (path, what) in outputs.items():
        target = Path(os.path.relpath(Path(path), out_dir)).as_posix()
        if Path(path).is_dir():
            target += "/"
        rows.append(
            f'<li><a href="{html.escape(target, quote=True)}">{html.escape(name)}</a>: '
            f"{html.escape(what)}</li>"
        )
    page = (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<title>{html.escape(title)}</title></head>\n<body>\n<h1>{html.escape(title)}</h1>\n"
        "<p>The masks and the train runs are synthetic: obstructions drawn on the real line "
        "144 and rendered, with exact ground truth.</p>\n<ul>\n"
        + "\n".join(rows)
        + "\n</ul>\n</body></html>\n"
    )
    path = out_dir / "index.html"
    path.write_text(page, encoding="utf-8")
    return path


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``demo`` subcommand on the ``predisat`` subparsers."""
    full, quick = DemoPlan.full(), DemoPlan.quick()
    p = add_command(
        sub, "demo", HELP,
        f"Render a synthetic survey of line 144 (km {full.from_km:g}-{full.to_km:g}: "
        f"{full.n_frames} frames, about {sum(full.estimate_s(2).values()) / 60:.0f} min on two "
        "quiet cores) with ground truth, process it into "
        "masks, compare them with the truth, write the availability report, then run the "
        "installed demo steps: the locator's locates a simulated train run under each trust "
        "rule (`locator demo`). An estimate of the time is printed first; --quick runs the "
        f"same steps on {quick.to_km - quick.from_km:g} km ({quick.n_frames} smaller frames, "
        "under 90 s). index.html in --out links every output.",
    )  # fmt: skip
    p.add_argument(
        "--out", default="demo_out", type=output_dir, metavar="DIR", help="output folder"
    )
    p.add_argument("--quick", action="store_true",
                   help=f"the same steps, short: {quick.to_km - quick.from_km:g} km, "
                   f"{quick.image_size_px[0]} x {quick.image_size_px[1]} frames every "
                   f"{quick.spacing_m:g} m, availability every {quick.step_s:g} s (coarser "
                   "masks: its figures are not the demo's)")
    p.add_argument("--seed", type=seed_value, metavar="N", default=1, help="random seed")
    p.add_argument("--integrity-risk", type=integrity_risk, metavar="P",
                   default=DEFAULT_RISK_PER_EPOCH,
                   help="integrity risk per epoch the availability report's and the locator "
                   "step's intervals are drawn for (docs/locator.md)")
    p.add_argument(
        "--camera", choices=("fisheye", "pinhole"), default=DEMO_CAMERA,
        help="side camera model",
    )  # fmt: skip
    p.add_argument("--from-km", type=finite_float, metavar="KM",
                   help=f"start of the stretch, chainage km (default {DEMO_FROM_KM:g})")
    p.add_argument("--to-km", type=finite_float, metavar="KM",
                   help=f"end of the stretch, chainage km (default {DEMO_TO_KM:g}; --quick: "
                   f"{QUICK_LENGTH_KM:g} km after the start). Another stretch is another "
                   "world: the scenery recipe is drawn for it (under 800 m a short recipe), not "
                   "cut out of the default demo's")
    p.add_argument("--workers", type=positive_int, default=default_workers(), metavar="N",
                   help="rendering and processing processes")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
