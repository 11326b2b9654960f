"""Masks with and without the terrain step against a ray-cast truth (docs/terrain.md).

Reads a mask file (``predisat process`` output), the synthetic truth of the same survey and the
DEM tiles; raises the masks to the terrain (:func:`predisat.masks.terrain.raise_to_terrain`)
and prints, for the masks as they are and raised: false trust (trusted directions truly
blocked / trusted) and sky lost (truly visible directions not trusted / visible), over every
bin and over the bins the pipeline flagged ASSUMED (the far field no camera saw), with the
mask file's margins; the share of bins the terrain raised.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/eval_terrain.py --masks OUT/masks.parquet \\
        --truth SYNTH_OUT --dem ../shared/data/terrain/srtm3_nice/*.hgt [--out masks_t.parquet]
"""

from __future__ import annotations

import argparse

import numpy as np

from predisat.masks.fileformat import mask_file_path, read_masks, write_masks
from predisat.masks.maskset import BinSource, MaskSet
from predisat.masks.terrain import bin_terrain, coverage_notes, raise_to_terrain
from predisat.reconstruct.evaluate import compare, load_truth, trust_counts
from predisat.terrain import Dem


def _figures(masks: MaskSet, truth_dir: str, select: np.ndarray | None) -> tuple[float, float]:
    comp = compare(masks, load_truth(truth_dir))
    margin = 0.0 if comp.margin_deg is None else comp.margin_deg
    trusted, trusted_los, los = trust_counts(comp.mask_el_deg, comp.truth_el_deg, margin)
    if select is not None:
        trusted, trusted_los, los = trusted[select], trusted_los[select], los[select]
    t, tl, v = int(trusted.sum()), int(trusted_los.sum()), int(los.sum())
    return (t - tl) / max(t, 1), (v - tl) / max(v, 1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--masks", required=True, help="mask file or process output folder")
    ap.add_argument("--truth", required=True, help="synth output folder (truth/)")
    ap.add_argument("--dem", nargs="+", required=True, help="SRTM .hgt or GeoTIFF tiles")
    ap.add_argument("--above-ground", type=float, default=4.0, help="antenna above rail, m")
    ap.add_argument("--out", help="write the raised masks here")
    args = ap.parse_args(argv)
    masks = read_masks(mask_file_path(args.masks))
    dem = Dem.from_files(args.dem)
    hz = bin_terrain(masks, dem, antenna_above_ground_m=args.above_ground)
    raised = raise_to_terrain(masks, hz, dem_source=dem.source)
    for note in coverage_notes(raised, hz, dem.source):
        print(f"warning: {note}")
    comp = compare(masks, load_truth(args.truth))
    assumed = comp.source == BinSource.ASSUMED
    up = raised.mask_el_deg > masks.mask_el_deg
    a = masks.source == BinSource.ASSUMED
    on_assumed = up[a] if a.any() else np.zeros(1)
    flagged = float((raised.source == BinSource.TERRAIN).mean())
    print(f"{masks.n_pos} positions, {masks.n_az} bins each; assumed bins "
          f"{100 * assumed.mean():.1f} %; raised by the terrain {100 * float(up.mean()):.1f} % "
          f"of all bins ({100 * flagged:.1f} % flagged TERRAIN: rays covered to 25 km), "
          f"{100 * float(on_assumed.mean()):.1f} % of the assumed")  # fmt: skip
    print(f"{'masks':>10} {'bins':>8} {'false trust %':>14} {'sky lost %':>11}")
    for name, m in (("as is", masks), ("terrain", raised)):
        for where, sel in (("all", None), ("assumed", assumed)):
            ft, sl = _figures(m, args.truth, sel)
            print(f"{name:>10} {where:>8} {100 * ft:14.5f} {100 * sl:11.2f}")
    if args.out:
        write_masks(raised, args.out)
        print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
