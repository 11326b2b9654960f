"""Margin calibration on one synthetic survey, validation on another seed (issue 3, item 5).

The trust rule is ``el > mask + margin`` of the azimuth bin. ``calibrate_margin`` finds, per
(sector, source) group, the smallest margin such that >= 99.9 % of the trusted directions of
survey A are truly in line of sight. This script applies that table to survey B (rendered
with another seed, same recipe) and reports, per sector (cross-track, along-track, all):

* false trust: trusted directions that are truly blocked, as a share of trusted directions;
* sky lost: truly visible directions that are not trusted, as a share of truly visible ones;
* median and 95th percentile of the signed mask error ``mask - truth`` (degrees);

once with the calibrated margins and once with the margins the masks carry as processed
(``MaskSet.margin_deg``), and for both splits (A -> B and B -> A). Directions are the
(position, bin, elevation) triples of :mod:`predisat.reconstruct.evaluate` (0.1 deg elevation grid,
counted analytically per bin).

Usage::

    # surveys A and B: the demo's recipe (line 144, km 4-6, 640x480 fisheye, mixed), seeds 1, 2
    for s in 1 2; do
      .venv/bin/python scripts/margin_split.py render --seed $s --out /tmp/fe_seed$s
      .venv/bin/predisat process /tmp/fe_seed$s/survey --out /tmp/fe_seed$s/masks --workers 1
    done
    .venv/bin/python scripts/margin_split.py split /tmp/fe_seed1 /tmp/fe_seed2 \\
        --out /tmp/fe_split.json
    # add --camera pinhole to render for the pinhole figures

Each survey folder holds ``survey/``, ``truth/`` and ``masks/`` (``masks.parquet``).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from predisat.masks.margins import EL_STEP_DEG, SECTORS, MarginTable
from predisat.masks.maskset import MaskSet
from predisat.reconstruct.evaluate import (
    Comparison,
    calibrate_margin,
    compare,
    load_truth,
    trust_counts,
)

__all__ = [
    "SplitSurvey",
    "load_split_survey",
    "main",
    "markdown",
    "render",
    "sector_rows",
    "split_report",
]

_SECTOR_ROWS = (*SECTORS, "all")


def render(
    seed: int,
    out_dir: Path,
    workers: int = 1,
    camera: Literal["pinhole", "fisheye"] = "fisheye",
    spacing_m: float = 10.0,
) -> Path:
    """Render the demo's synthetic survey (``predisat demo`` recipe) with another seed.

    :func:`predisat.cli.demo.render_demo_survey`, as ``predisat demo --camera CAMERA --seed SEED``.

    Returns
    -------
    Path
        The survey folder (``out_dir / "survey"``).
    """
    from predisat.cli.demo import render_demo_survey

    synth = render_demo_survey(
        out_dir, seed=seed, camera=camera, workers=workers, progress=False, spacing_m=spacing_m
    )
    print(
        f"render: seed {seed}, {camera}, {synth.n_frames} frames at {synth.n_positions} "
        f"positions -> {synth.survey_dir} (truth {synth.truth_dir})"
    )
    return Path(synth.survey_dir)


# ---------------------------------------------------------------------- the split
@dataclass(frozen=True, eq=False)
class SplitSurvey:
    """One synthetic survey's masks paired with its truth.

    Attributes
    ----------
    name : str
        Label (folder name and seed).
    root : Path
        Folder holding ``truth/`` and ``masks/masks.parquet``.
    seed : int or None
        Generator seed read from ``truth/README.txt`` (None when absent).
    comparison : Comparison
        Mask and truth on the truth's azimuth bins, shape (n_pos, n_az).
    processed_margin_deg : ndarray, shape (n_pos, n_az)
        The margin the masks carry as processed, on the same positions and bins, degrees.
    """

    name: str
    root: Path
    seed: int | None
    comparison: Comparison
    processed_margin_deg: NDArray


def _seed_of(truth_dir: Path) -> int | None:
    readme = truth_dir / "README.txt"
    if not readme.is_file():
        return None
    found = re.search(r"\bseed:\s*(\d+)", readme.read_text())
    return int(found.group(1)) if found else None


def _masks_path(root: Path) -> Path:
    for cand in (root / "masks" / "masks.parquet", root / "masks.parquet"):
        if cand.is_file():
            return cand
    raise FileNotFoundError(
        f"{root}: no masks/masks.parquet; run `predisat process {root / 'survey'} "
        f"--out {root / 'masks'}` first"
    )


def load_split_survey(root: Path) -> SplitSurvey:
    """Masks (``root/masks``) and truth (``root/truth``) of one generator output folder."""
    from predisat.masks.fileformat import read_masks

    masks: MaskSet = read_masks(_masks_path(root))
    comp = compare(masks, load_truth(root))
    # compare() keeps the matched mask rows in order; chainages are strictly increasing, so
    # searchsorted recovers their indices exactly
    rows = np.searchsorted(masks.chainage_m, comp.chainage_m)
    cols = masks.bin_index(comp.az_deg)
    margin = np.asarray(masks.margin_deg, float)[rows][:, cols]
    seed = _seed_of(root / "truth")
    name = f"{root.name} (seed {seed})" if seed is not None else root.name
    return SplitSurvey(name, root, seed, comp, margin)


def sector_rows(
    comparison: Comparison, margin_deg: NDArray, el_step_deg: float = EL_STEP_DEG
) -> list[dict[str, Any]]:
    """False trust, sky lost and mask error per sector (cross, along, all).

    Parameters
    ----------
    comparison : Comparison
        Mask and truth, shape (n_pos, n_az).
    margin_deg : ndarray, shape (n_pos, n_az)
        Margin of every bin, degrees.
    el_step_deg : float
        Elevation grid step of the direction counts.

    Returns
    -------
    list of dict
        Per sector: ``n_bins``, ``trusted`` / ``trusted_blocked`` / ``visible`` direction
        counts, ``false_trust`` (trusted and truly blocked / trusted; 0 when nothing is
        trusted), ``sky_lost`` (truly visible and not trusted / truly visible),
        ``median_error_deg`` and ``p95_error_deg`` (``mask - truth``, no margin),
        ``mean_margin_deg``.
    """
    m = comparison.mask_el_deg.ravel()
    t = comparison.truth_el_deg.ravel()
    mg = np.broadcast_to(np.asarray(margin_deg, float), comparison.mask_el_deg.shape).ravel()
    sec = comparison.sector.ravel()
    trusted, good, visible = trust_counts(m, t, mg, el_step_deg)
    err = m - t
    rows = []
    for name in _SECTOR_ROWS:
        sel = np.ones(m.size, bool) if name == "all" else sec == name
        n_tr, n_good, n_vis = int(trusted[sel].sum()), int(good[sel].sum()), int(visible[sel].sum())
        rows.append({
            "sector": name,
            "n_bins": int(sel.sum()),
            "trusted": n_tr,
            "trusted_blocked": n_tr - n_good,
            "visible": n_vis,
            "false_trust": (n_tr - n_good) / n_tr if n_tr else 0.0,
            "sky_lost": 1.0 - n_good / n_vis if n_vis else 0.0,
            "median_error_deg": float(np.median(err[sel])) if sel.any() else float("nan"),
            "p95_error_deg": float(np.percentile(err[sel], 95)) if sel.any() else float("nan"),
            "mean_margin_deg": float(mg[sel].mean()) if sel.any() else float("nan"),
        })  # fmt: skip
    return rows


def split_report(
    calib: SplitSurvey,
    test: SplitSurvey,
    target: float = 0.999,
    confidence: float | None = 0.99,
    offset_deg: float = 0.0,
) -> dict[str, Any]:
    """Calibrate on ``calib`` (by sector and source), evaluate on ``test``.

    ``confidence`` is that of :func:`predisat.reconstruct.evaluate.calibrate_margin` (None:
    in-sample
    point estimate). ``offset_deg`` lowers every mask of both surveys by that much before
    calibrating (a stress test: masks that need a margin).

    Returns
    -------
    dict
        ``calibrated_on``, ``tested_on``, ``target``, ``margins`` (the table's records),
        ``rows``: :func:`sector_rows` of ``test`` with margins ``"calibrated"`` and
        ``"as processed"``, plus the calibrated margins on ``calib`` itself
        (``"calibrated, in-sample"``).
    """
    if offset_deg:
        calib, test = _lowered(calib, offset_deg), _lowered(test, offset_deg)
    table: MarginTable = calibrate_margin(
        calib.comparison, target=target, by=("sector", "source"), confidence=confidence
    )
    rows = []
    cases = (
        ("as processed", test, test.processed_margin_deg),
        ("calibrated", test, table.margin_for(test.comparison.sector, test.comparison.source)),
        (
            "calibrated, in-sample",
            calib,
            table.margin_for(calib.comparison.sector, calib.comparison.source),
        ),
    )
    for label, surv, margin in cases:
        for r in sector_rows(surv.comparison, margin, table.el_step_deg):
            rows.append({"margins": label, "evaluated_on": surv.name, **r})
    return {
        "calibrated_on": calib.name,
        "tested_on": test.name,
        "target": target,
        "confidence": confidence,
        "offset_deg": offset_deg,
        "margins": json.loads(table.table.to_json(orient="records")),
        "rows": rows,
    }


def _lowered(survey: SplitSurvey, offset_deg: float) -> SplitSurvey:
    comp = replace(
        survey.comparison,
        mask_el_deg=np.clip(survey.comparison.mask_el_deg - offset_deg, 0.0, 90.0),
    )
    return replace(survey, name=f"{survey.name} - {offset_deg:g} deg", comparison=comp)


def _fmt_pct(x: float) -> str:
    return f"{100.0 * x:.3f} %"


def markdown(reports: list[dict[str, Any]]) -> str:
    """Margin tables and the per-sector results as markdown."""
    lines = []
    for rep in reports:
        lines += [
            f"### calibrated on {rep['calibrated_on']}, tested on {rep['tested_on']} "
            f"(target {rep['target']}, confidence {rep['confidence']})",
            "",
            "| sector | source | margin (deg) | bins | reached | LOS share | sky lost |",
            "|---|---|---|---|---|---|---|",
        ]
        for m in rep["margins"]:
            share = "-" if m["los_share"] is None else f"{100.0 * m['los_share']:.3f} %"
            lost = "-" if m["sky_lost"] is None else _fmt_pct(m["sky_lost"])
            lines.append(
                f"| {m['sector']} | {m['source']} | {m['margin_deg']:.1f} | {m['n_bins']} | "
                f"{m['reached']} | {share} | {lost} |"
            )
        lines += [
            "",
            "| margins | evaluated on | sector | bins | false trust | trusted & blocked / "
            "trusted | sky lost | median err (deg) | p95 err (deg) | mean margin (deg) |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rep["rows"]:
            lines.append(
                f"| {r['margins']} | {r['evaluated_on']} | {r['sector']} | {r['n_bins']} | "
                f"{_fmt_pct(r['false_trust'])} | {r['trusted_blocked']} / {r['trusted']} | "
                f"{_fmt_pct(r['sky_lost'])} | {r['median_error_deg']:.2f} | "
                f"{r['p95_error_deg']:.2f} | {r['mean_margin_deg']:.2f} |"
            )
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("render", help="render the demo recipe with another seed")
    p.add_argument("--seed", type=int, required=True, help="random seed of scenery and sky")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--workers", type=int, default=1, help="rendering processes (default 1)")
    p.add_argument("--camera", choices=("fisheye", "pinhole"), default="fisheye",
                   help="camera model (default fisheye, as the demo)")  # fmt: skip
    p.add_argument("--spacing-m", type=float, default=10.0, help="position spacing (10 m)")
    p = sub.add_parser("split", help="calibrate on A, test on B, and the reverse")
    p.add_argument("a", type=Path, help="survey A folder (truth/, masks/)")
    p.add_argument("b", type=Path, help="survey B folder, rendered with another seed")
    p.add_argument("--target", type=float, default=0.999, help="LOS share target (0.999)")
    p.add_argument(
        "--confidence",
        type=float,
        default=0.99,
        help="block-resampling confidence of the margins (0.99; 0: in-sample)",
    )
    p.add_argument(
        "--offset",
        type=float,
        action="append",
        default=None,
        metavar="DEG",
        help="also run with every mask lowered by DEG (stress test; repeatable)",
    )
    p.add_argument("--out", type=Path, help="JSON output file")
    args = parser.parse_args(argv)
    if args.command == "render":
        render(args.seed, args.out, args.workers, args.camera, args.spacing_m)
        return 0

    try:
        a, b = load_split_survey(args.a), load_split_survey(args.b)
    except (FileNotFoundError, ValueError) as exc:
        print(f"margin_split: error: {exc}", file=sys.stderr)
        return 2
    if a.seed is not None and a.seed == b.seed:
        parser.error(
            f"{args.a} and {args.b} were both rendered with seed {a.seed}; validation needs "
            "a survey made with another seed"
        )
    conf = args.confidence if args.confidence > 0 else None
    reports = [
        split_report(x, y, args.target, conf, off)
        for off in [0.0, *(args.offset or [])]
        for x, y in ((a, b), (b, a))
    ]
    print(markdown(reports))
    if args.out is not None:
        doc = {
            "surveys": {
                s.name: {"path": str(s.root), "seed": s.seed,
                         "n_positions": int(s.comparison.chainage_m.size),
                         "unmatched_positions": s.comparison.unmatched}
                for s in (a, b)
            },
            "el_step_deg": EL_STEP_DEG,
            "splits": reports,
        }  # fmt: skip
        args.out.write_text(json.dumps(doc, indent=1))
        print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
