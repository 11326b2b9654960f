"""Score sky segmentation on folders of images with reference masks.

Usage::

    python scripts/eval_sky.py --data ../shared/data/sky/ade20k \
        --data ../shared/data/sky/fisheye_hk --out eval_sky_out
    python scripts/eval_sky.py --data /tmp/seg_synth_clear --out eval_sky_out   # synthetic
    # the committed sheet of docs/segmentation.md: the four worst of each real set
    python scripts/eval_sky.py --method ensemble --data ../shared/data/sky/ade20k \
        --data ../shared/data/sky/fisheye_hk --out /tmp/eval_sky_out \
        --sheet docs/figures/sky_worst_cases.png

Each folder is one of the layouts of :mod:`predisat.sky.photoeval` (ADE20K, fisheye_hk, generic
images/ + masks/, or a ``predisat synth`` output folder). For each it writes
``<name>_per_image.csv``, ``<name>_summary.md`` and ``<name>_worst.png`` into ``--out`` and prints
the summary. The research-only photos are read in place; nothing of them is copied elsewhere
than ``--out`` (keep that outside the repository, except the small worst-case sheet).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

from predisat.sky.network import NET_METHODS, SkyNet, classifier_with_net
from predisat.sky.photoeval import evaluate_folder, worst_cases_sheet
from predisat.sky.segment import METHODS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", action="append", required=True, metavar="DIR",
                        help="folder of images with masks (repeatable)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--limit", type=int, help="score only the first N images of each folder")
    parser.add_argument("--worst", type=int, default=8, help="cases in the contact sheet")
    parser.add_argument("--method", choices=METHODS, help="segmentation method (default: the "
                        "library's default)")
    parser.add_argument("--net", type=Path, metavar="ONNX",
                        help="a candidate sky network (with its .json card) instead of the "
                             "shipped one, for --method cnn or ensemble")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--sheet", type=Path, metavar="PNG",
                        help="also write one contact sheet of the --sheet-per-set worst cases "
                             "of every folder")
    parser.add_argument("--sheet-per-set", type=int, default=4, metavar="N",
                        help="cases per folder in --sheet (at most --worst)")
    args = parser.parse_args(argv)
    classifier = None
    if args.net is not None:
        if args.method not in NET_METHODS:
            parser.error("--net needs --method cnn or --method ensemble")
        classifier = classifier_with_net(args.method, SkyNet.load(args.net))
    summaries = []
    sheet: list = []
    for data in args.data:
        ev = evaluate_folder(data, out_dir=args.out, progress=not args.quiet, limit=args.limit,
                             n_worst=args.worst, method=args.method, classifier=classifier)
        s = ev.summary.assign(data=Path(data).name, layout=ev.layout)
        summaries.append(s)
        print(f"{data} ({ev.layout}):")
        print(ev.summary.to_string(index=False, float_format=lambda x: f"{x:.4f}"))
        for kind, path in ev.files.items():
            print(f"  wrote {kind}: {path}")
        sheet += ev.worst_cases[: args.sheet_per_set]
    if args.sheet is not None and sheet:
        print(f"wrote {worst_cases_sheet(sheet, args.sheet, thumb_w_px=150)}")
    pd.concat(summaries).to_csv(Path(args.out) / "summary_all.csv", index=False,
                                float_format="%.5g")
    return 0


if __name__ == "__main__":
    sys.exit(main())
