"""``predisat evaluate``: masks against synthetic ground truth (and margin calibration),
printed and written as ``evaluation.csv/json/png``; the library is
:mod:`predisat.reconstruct.evaluate`."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from predisat.cli.args import (
    add_checks,
    existing_file,
    existing_path,
    fraction,
    needs,
    output_dir,
)
from predisat.jsontypes import JsonDict, strict_json_text
from predisat.masks.fileformat import mask_file_path, read_masks
from predisat.masks.margins import MarginTable
from predisat.reconstruct.evalfigures import evaluation_figure
from predisat.reconstruct.evaluate import (
    POSITION_LIMIT,
    applied_margins,
    calibrate_margin,
    compare,
    evaluate_masks,
    format_table,
    load_truth,
    position_false_trust,
)

__all__ = ["add_arguments", "run"]


# --target and --confidence of --calibrate (None in the parser: given or not)
TARGET = 0.999
CONFIDENCE = 0.99


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``predisat evaluate``."""
    parser.add_argument("masks", type=existing_path("a mask file (masks.parquet) or a `predisat "
                        "process` output folder"), metavar="MASKS",
                        help="mask file, or a `predisat process` output folder")  # fmt: skip
    parser.add_argument(
        "--truth", type=existing_path("synthetic ground truth: a `predisat synth` output "
        "folder, its truth/ or true_masks.npz"), required=True, metavar="PATH",
        help="synthetic ground truth: generator output folder, its truth/ or true_masks.npz",
    )  # fmt: skip
    parser.add_argument(
        "--out", type=output_dir, metavar="DIR",
        help="folder for evaluation.csv/json/png (default: print only)",
    )
    m = parser.add_mutually_exclusive_group()
    m.add_argument(
        "--calibrate", action="store_true",
        help="calibrate margins on this truth and write margins.json (in --out)",
    )  # fmt: skip
    m.add_argument("--margins", type=existing_file("a margin table (margins.json of `predisat "
                   "evaluate --calibrate`)"), metavar="JSON",
                   help="margin table (margins.json) to evaluate (default: the mask file's own "
                   "margins)")  # fmt: skip
    parser.add_argument("--target", type=fraction, metavar="SHARE",
                        help="with --calibrate: share of trusted directions that must be truly "
                        f"line-of-sight (default {TARGET})")  # fmt: skip
    parser.add_argument(
        "--confidence", type=_share_or_zero, metavar="SHARE",
        help="with --calibrate: the target must hold on this share of 200 m block resamples "
        f"of the line (default {CONFIDENCE}; 0 for the in-sample point estimate)",
    )  # fmt: skip
    add_checks(
        parser,
        needs("--target", "target", lambda a: a.calibrate, "--calibrate"),
        needs("--confidence", "confidence", lambda a: a.calibrate, "--calibrate"),
    )


def _share_or_zero(value: str) -> float:
    """``--confidence``: 0 or a share in (0, 1] (percent refused, as :func:`fraction`)."""
    return 0.0 if value.strip() in ("0", "0.0") else fraction(value)


def other_survey_note(provenance: JsonDict, truth: str | Path) -> str | None:
    """A warning when the truth comes from a generator folder whose survey is not the one the
    masks were made from (their ``survey_hash``): the positions pair by chainage alone, so the
    masks of one world scored against another's truth give figures of neither (a user trial
    read 7.4 % false trust that way). None when they agree or cannot be told."""
    from predisat.reconstruct.framecache import survey_hash
    from predisat.survey import Survey, SurveyError

    want = provenance.get("survey_hash")
    p = Path(truth)
    gen = p.parent.parent if p.is_file() else (p.parent if p.name == "truth" else p)
    sibling = gen / "survey"
    if not want or not (sibling / "survey.yaml").is_file():
        return None
    try:
        got = survey_hash(Survey.load(sibling, check_images=False, on_error="skip"))
    except (SurveyError, OSError, ValueError):
        return None
    if got == want:
        return None
    return (
        f"{truth} is the ground truth of {sibling}, not of the survey the masks were made from "
        f"({provenance.get('survey', '?')}): positions pair by chainage alone, so the figures "
        "may score the masks against another world; give the truth of the masks' own survey "
        "(a changed copy of the same survey is fine if that is what you mean)"
    )


def run(args: argparse.Namespace) -> pd.DataFrame:
    """Run ``predisat evaluate`` from parsed arguments; prints and returns the table."""
    path = mask_file_path(args.masks)
    masks = read_masks(path)
    note = other_survey_note(masks.provenance, args.truth)
    if note is not None:
        print(f"predisat evaluate: warning: {note}", file=sys.stderr)
    comp = compare(masks, load_truth(args.truth))
    margins = MarginTable.from_json(args.margins) if args.margins is not None else None
    out = Path(args.out) if args.out is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    if args.calibrate:
        confidence = CONFIDENCE if args.confidence is None else args.confidence
        target = TARGET if args.target is None else args.target
        margins = calibrate_margin(comp, target=target, confidence=confidence or None)
        print(margins.table.to_string(index=False))
        if out is not None:
            margins.to_json(out / "margins.json")
            margins.table.to_csv(out / "margins.csv", index=False)
    table = evaluate_masks(comp, margins)
    applied = applied_margins(comp, margins)
    file_margins = margins is None and applied is not None
    if file_margins:
        print("the *_margin columns use the mask file's own margins (margin_deg)")
    elif margins is not None and applied_margins(comp, None) is not None:
        print("the *_margin columns use the margin table, not the mask file's own margins")
    print(format_table(table))
    per = position_false_trust(comp)
    worst = int(np.argmax(per))
    over = int((per > POSITION_LIMIT).sum())
    marked = " (evaluation.png marks them)" if over and out is not None else ""
    print(f"false trust per position: worst {100 * per[worst]:.3g} % at "
          f"{comp.chainage_m[worst]:.0f} m; {over} of {per.size} positions above "
          f"{100 * POSITION_LIMIT:g} %{marked}")  # fmt: skip
    if comp.unmatched:
        print(f"{comp.unmatched} mask position(s) without truth were left out")
    if out is not None:
        table.to_csv(out / "evaluation.csv", index=False)
        doc = {
            "masks": str(path),
            "truth": str(args.truth),
            "margins": (
                margins.table.to_dict(orient="records") if margins is not None
                else "mask file" if file_margins else None
            ),
            "n_positions": int(comp.chainage_m.size),
            "positions_above_limit": over,
            "position_limit": POSITION_LIMIT,
            "worst_position": {
                "chainage_m": float(comp.chainage_m[worst]),
                "false_trust": float(per[worst]),
            },
            "rows": json.loads(table.to_json(orient="records")),
        }
        # strict JSON: a share of nothing (no visible sky in a tunnel) is null
        (out / "evaluation.json").write_text(strict_json_text(doc))
        fig = evaluation_figure(comp, 0.0 if applied is None else applied,
                                title=f"{path.name} against {args.truth}")
        fig.savefig(out / "evaluation.png", dpi=100)
        print(f"written {out / 'evaluation.csv'}, evaluation.json, evaluation.png")
    return table
