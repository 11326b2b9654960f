"""Left and right swapped: the side check's votes and what a swap costs (reconstruction.md §19).

For each survey given as ``SURVEY:CACHE`` (a survey folder and the segmentation cache of an
earlier ``predisat process``, its ``out/cache``), prints each side camera's pairs of consecutive
frames that slid the mount's way and the other way (:mod:`predisat.reconstruct.sides`), and with
``--swap`` the same for a copy whose manifest ``side`` column is swapped. With ``--truth`` (the
generator's output folder), each run's masks are processed (the cache copied, so only the
reconstruction runs) and scored against the ray-cast truth: false trust and sky lost, as
``predisat evaluate`` does.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_sides.py --work /tmp/sides --swap \\
        --truth demo_out demo_out/survey:demo_out/masks/cache
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from predisat.reconstruct.framecache import decode_cache
from predisat.reconstruct.sides import SideVotes, expected_flow_sign, side_votes, sky_profile
from predisat.survey import Survey


def votes(survey_dir: Path, cache: Path) -> list[SideVotes]:
    """Each side camera's votes from the cached segmentations (``cache``: a ``seg-*`` folder or
    the ``cache`` folder holding one)."""
    seg = cache if cache.name.startswith("seg-") else next(cache.glob("seg-*"))
    survey = Survey.load(survey_dir, check_images=False, on_error="skip")
    fr, out = survey.frames, []
    for side, sc in sorted(survey.cameras.items()):
        idx = sorted(np.flatnonzero(fr.side == side), key=lambda i: float(fr.gps_s[i]))
        profiles = []
        for i in idx:
            path = seg / f"{fr.frame_id[i]}.npz"
            if not path.is_file():
                continue
            with np.load(path) as z:
                got = decode_cache(z, json.loads(str(z["meta"])), str(fr.frame_id[i]))
            if isinstance(got, tuple):
                profiles.append(sky_profile(got[0]))
        out.append(side_votes(side, profiles, expected_flow_sign(sc.mount)))
    return out


def swapped_copy(src: Path, dst: Path) -> Path:
    """``src`` with the manifest's ``side`` column swapped (images and calibrations linked)."""
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for p in src.iterdir():
        if p.name == "manifest.csv":
            continue
        (dst / p.name).symlink_to(p.resolve())
    man = pd.read_csv(src / "manifest.csv")
    man["side"] = man["side"].map({"left": "right", "right": "left"}).fillna(man["side"])
    man.to_csv(dst / "manifest.csv", index=False)
    return dst


def score(survey_dir: Path, cache: Path, truth: Path, out: Path) -> str:
    """False trust and sky lost of the masks of ``survey_dir`` against ``truth``."""
    from predisat.reconstruct.batch import process_survey
    from predisat.reconstruct.evaluate import compare, load_truth, trust_counts

    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(cache, out / "cache")
    masks = process_survey(survey_dir, out, progress=False).masks
    c = compare(masks, load_truth(truth))
    trusted, good, visible = trust_counts(c.mask_el_deg, c.truth_el_deg)
    ft = 100.0 * (1.0 - good.sum() / max(int(trusted.sum()), 1))
    return f"false trust {ft:.5f} %, sky lost {100.0 * (1.0 - good.sum() / visible.sum()):.2f} %"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("surveys", nargs="+", help="SURVEY:CACHE pairs")
    ap.add_argument("--work", type=Path, required=True, help="a scratch folder")
    ap.add_argument("--swap", action="store_true", help="also a copy with the sides swapped")
    ap.add_argument("--truth", type=Path, help="score the masks against this ground truth")
    args = ap.parse_args(argv)
    for k, pair in enumerate(args.surveys):
        survey, cache = (Path(x) for x in pair.split(":", 1))
        runs = [("as given", survey)]
        if args.swap:
            runs.append(("sides swapped", swapped_copy(survey, args.work / f"swapped_{k}")))
        for label, folder in runs:
            line = "; ".join(f"{v.side} {v.agree} / {v.disagree}"
                             + (" SWAPPED" if v.swapped else "")
                             for v in votes(folder, cache))  # fmt: skip
            if args.truth is not None:
                line += "; " + score(folder, cache, args.truth,
                                     args.work / f"out_{k}_{label.replace(' ', '_')}")
            print(f"{survey} ({label}): mount's way / other way: {line}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
