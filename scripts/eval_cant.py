"""A canted curve, three ways: the vehicle's roll measured, not given, or given as level
(docs/reconstruction.md, section 16).

Renders a synthetic survey with ``cant_speed_kmh`` (the body rolls toward each curve's inside,
and the manifest carries the roll as an IMU would), then processes it three times from the
same images, the manifests differing only in their ``roll_deg, pitch_deg`` columns:

* ``measured``: as rendered;
* ``unknown``: the columns emptied (the pipeline bounds the roll from the track's curves);
* ``level``: the columns set to 0 (on a sharp curve the track rules that out: bounded);
* ``table``: the columns emptied, the line's cant given as a table (the generator's
  ``truth/cant.csv``, as the infrastructure's records would give it; cant worlds only);
* ``ignored``: every frame taken as level and sure, whatever the manifest says: the pipeline
  before it knew of cant (in this process, serial).

Prints false trust (trusted directions truly blocked / trusted), the worst position's, the
positions above 0.1 % and the sky lost (truly visible directions not trusted / visible), with
the ray-cast truth as reference. ``--no-cant`` renders a level vehicle instead (the price of
the bound where there is no roll to find).

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_cant.py --from-km 0.45 --to-km 1.15 \\
        --seed 21 --sky cloudy --work /tmp/cant_right
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from predisat.camera.rigs import Rig
from predisat.masks.maskset import MaskSet
from predisat.reconstruct.attitude import level_attitudes
from predisat.reconstruct.batch import process_survey
from predisat.reconstruct.evaluate import compare, load_truth, trust_counts
from predisat.reconstruct.params import PipelineParams
from predisat.synth.generate import generate_survey
from predisat.track import demo_track
from predisat.track.cant import CantTable

VARIANTS = {"measured": None, "unknown": "", "level": "0.0", "table": "", "ignored": None}


def _variant(src: Path, dst: Path, value: str | None) -> Path:
    """A copy of the survey folder (images linked) whose manifest's attitude is ``value``."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for item in ("survey.yaml", "calib", "track.geojson"):
        (shutil.copytree if (src / item).is_dir() else shutil.copy)(src / item, dst / item)
    os.symlink((src / "images").resolve(), dst / "images")
    with open(src / "manifest.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    if value is not None:
        for r in rows:
            r["roll_deg"] = r["pitch_deg"] = value
    with open(dst / "manifest.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    return dst


def _ignoring_attitude(survey: Path, out: Path) -> MaskSet:
    """``process_survey`` with every frame level and sure (serial, in this process)."""
    import predisat.reconstruct.chunks as chunks

    saved = chunks.frame_attitudes
    chunks.frame_attitudes = level_attitudes
    try:
        return process_survey(survey, out, PipelineParams(), progress=False,
                              scheduler="serial").masks  # fmt: skip
    finally:
        chunks.frame_attitudes = saved


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from-km", type=float, required=True)
    ap.add_argument("--to-km", type=float, required=True)
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--sky", default="cloudy")
    ap.add_argument("--cant-speed-kmh", type=float, default=100.0)
    ap.add_argument("--no-cant", action="store_true", help="a level vehicle")
    ap.add_argument("--work", type=Path, required=True, help="scratch folder")
    ap.add_argument("--reuse", action="store_true", help="keep a survey rendered before")
    args = ap.parse_args(argv)
    world = args.work / "world"
    if not (args.reuse and (world / "survey" / "manifest.csv").is_file()):
        generate_survey(
            demo_track(), 1000 * args.from_km, 1000 * args.to_km, sky=args.sky,
            seed=args.seed, out_dir=world, rig=Rig.preset("side-fisheye"),
            cant_speed_kmh=None if args.no_cant else args.cant_speed_kmh,
            overwrite=True, workers=2,
        )  # fmt: skip
    truth = load_truth(world / "truth")
    print(f"{'manifest':>9} {'false trust %':>14} {'worst pos %':>12} {'pos > 0.1 %':>12} "
          f"{'sky lost %':>11} {'max roll':>9} {'max doubt':>10}")  # fmt: skip
    cache: Path | None = None
    table_csv = world / "truth" / "cant.csv"
    for name, value in VARIANTS.items():
        params = PipelineParams()
        if name == "table":
            if not table_csv.is_file():
                continue
            params = PipelineParams(cant_table=CantTable.from_csv(table_csv))
        survey = _variant(world / "survey", args.work / f"survey_{name}", value)
        out = args.work / f"masks_{name}"
        if out.exists():
            shutil.rmtree(out)
        if cache is not None:  # the same images: the segmentation is reused
            shutil.copytree(cache, out / "cache")
        if name == "ignored":
            masks = _ignoring_attitude(survey, out)
        else:
            masks = process_survey(survey, out, params, progress=False).masks
        cache = out / "cache"
        c = compare(masks, truth)
        trusted, good, los = trust_counts(c.mask_el_deg, c.truth_el_deg)
        ft_pos = (trusted - good).sum(axis=1) / np.maximum(trusted.sum(axis=1), 1)
        att = masks.provenance["attitude"]
        # nothing trusted (every direction closed): no false trust, and all the sky lost
        ft = 100 * (1 - good.sum() / trusted.sum()) if trusted.sum() else 0.0
        print(f"{name:>9} {ft:14.3g} "
              f"{100 * ft_pos.max():12.3g} {int((ft_pos > 1e-3).sum()):>7} of {ft_pos.size:<3} "
              f"{100 * (1 - good.sum() / los.sum()):11.1f} {att['max_abs_roll_deg']:9.2f} "
              f"{att['max_doubt_deg']:10.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
