"""The locator's step of ``predisat demo``: a simulated train run located under each trust rule.

Registered in the entry-point group ``predisat.demo_steps`` (``pyproject.toml``), so that
``predisat demo`` runs it without importing ``locator``.
"""

from __future__ import annotations

import pandas as pd

from locator.plots import systems_text
from locator.runio import read_run
from locator.workflow import demo, rule_folder
from predisat.cli.demo import DemoContext, DemoStepResult

__all__ = ["DEMO_CONSTELLATION", "STEP", "LocatorDemoStep", "format_demo_table"]


def format_demo_table(
    table: pd.DataFrame, constellations: str = "", report_above: bool = True
) -> str:
    """The demo's summary table (one row per trust rule) as text, shares in percent, with
    every count of ``summary.csv`` (HMI before and after the checks, MI) and the
    constellations the run received (the availability report counts GPS only by default;
    ``report_above`` False: no report was printed before, ``locator demo``)."""
    cols = {
        "rule": "rule",
        "claim_share": "claim %",
        "mode_three_pairs_share": ">=6 sats %",
        "length_median_m": "interval med m",
        "length_p95_m": "p95 m",
        "abs_error_median_m": "|err| med m",
        "hmi": "HMI",
        "hmi_fix": "HMI before checks",
        "mi": "MI",
    }
    t = table[list(cols)].rename(columns=cols).copy()
    for c in ("claim %", ">=6 sats %"):
        t[c] = 100 * t[c]
    gnss = constellations or "every constellation of the navigation day"
    same = (
        "the availability report above counts the same by default"
        if gnss == "GPS"
        else "the availability report above counts GPS only"
    )
    received = f"{gnss} received; {same}" if report_above else f"{gnss} received"
    return str(t.round(1).to_string(index=False)) + (
        f"\n  ({received}. MI: epochs whose interval misses the truth without a "
        "safety claim; HMI: missed while claimed)"
        "\n  (LOCOPROL on line 144: six satellites 60 % of the time; intervals about 70 m, up "
        "to 600 m)"
    )


class LocatorDemoStep:
    """Simulate a train run through the demo's world, locate it with the pipeline's masks,
    the true masks, no masks and a 15 deg cut-off, and tabulate the outcomes."""

    title = "a simulated train run located with the 1-D locator under each trust rule"

    def run(self, ctx: DemoContext) -> DemoStepResult:
        """Run the step in ``ctx.out_dir / "locator"`` (GPS only, as the availability report)."""
        from predisat.synth.world import World  # the renderer's world: needs the [synth] extra

        world = World.load(ctx.truth_dir / "world.npz", ctx.track)
        out = ctx.out_dir / "locator"
        # the train runs where the pipeline made masks, so that every rule is scored there
        stretch = (float(ctx.masks.chainage_m.min()), float(ctx.masks.chainage_m.max()))
        table = demo(out, world=world, pipeline_masks=ctx.masks, log=lambda s: None,
                     constellation=DEMO_CONSTELLATION, stretch_m=stretch,
                     integrity=ctx.integrity)  # fmt: skip
        outputs = {"locator summary": out / "summary.csv"}
        what = {"locator summary": "the simulated train run located under each trust rule "
                "(GPS): claims, interval lengths, errors, misleading epochs"}  # fmt: skip
        for rule in table["rule"]:
            folder = out / rule_folder(str(rule))
            for png in sorted(folder.glob("*.png")):
                name = f"locator {rule}: {png.stem.replace('_', ' ')}"
                outputs[name] = png
                what[name] = f"{_FIGURES.get(png.stem, 'figure')} under {rule} (GPS)"
        gnss = systems_text(read_run(out / "true_masks")[0])  # the satellites the runs received
        from locator.fde import LocatorConfig

        width = LocatorConfig(budget=ctx.integrity).width_text()  # the runs' own configuration
        text = format_demo_table(table, gnss) + f"\n  (pair intervals: {width})"
        return DemoStepResult(text, outputs, what)


DEMO_CONSTELLATION = "gps"
"""The satellites the demo's train run uses: GPS, as ``predisat availability`` by default."""

_FIGURES = {
    "interval_chainage": "the located interval and the true chainage along the line",
    "interval_time": "the located interval and the true chainage over time",
    "interval_lengths": "the distribution of the located intervals' lengths",
    "stanford": "the Stanford integrity diagram (error against half-interval, regions counted)",
}


STEP = LocatorDemoStep()
"""The entry point ``locator`` of ``predisat.demo_steps``."""
