"""Where the reconstruction loses the sky, bin by bin (issue 32, docs/reconstruction.md section 9).

Reconstructs a rig's masks from its *ideal* sky masks (ray cast, no segmentation error; the
frames of ``scripts/eval_rigs.py``'s ideal pass) on a held-out world rendered by
``scripts/eval_rigs.py`` (its ``synth/truth`` folder: ``world.npz`` and ``true_masks.npz``;
the world and the antenna positions do not depend on the rig, so one truth folder serves every
rig), then attributes every bin where the mask stands above the truth to the part of the
reconstruction that sets the mask there, as the reconstruction itself reports it
(``Reconstructor.run(..., trace=True)``, :class:`~predisat.reconstruct.carving.
ReconstructionTrace`; the rig's side cameras passed as ``predisat process`` does):

* ``far: assumed`` the far-field default (no camera at the position saw that far field);
* ``far: seen`` the far-field bound of a camera at the position (its skyline, with the
  camera-antenna parallax allowance); ``far: seen, capped far cells`` where that bound also
  capped higher far cells of the height field;
* ``near|far grid: unknown`` a ray of the height field met a cell no frame bounded;
* ``near|far grid: prior ...`` the cell is a clearance cell whose bound the clearance prior set
  (an overhead structure: by the zenith rule, the along-track overhead rule, a position lacking
  a side camera's own frame, an interval given, the tall bands on both sides; ``ceiling``
  when the cameras' ceiling set the bound);
* ``near|far grid: carved ...`` a carved cell (split into clearance cells over the track and
  others): the carving's bound stands above the true obstacle (a cell bounded from its far
  corner, a cell only high rays reach);
* ``far grid, mast rule: ...`` a far cell the mast rule resolved, kept over the far field's
  cap;
* ``covered (closed to 90)`` a position closed over most azimuths, closed in every bin.

and likewise every bin where the mask is below the truth (false trust), with the kind of
scenery at the position. Prints the lost sky (truly visible directions not trusted / truly
visible, per sector) and the false trust per cause. ``--params`` sets
:class:`~predisat.reconstruct.carving.ReconstructionParams` fields (JSON) for a what-if.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/along_attribution.py --rig 360 --seeds 11 12 13 \\
        --truth /tmp/eval_rigs_full/360_s{seed}/synth/truth --work /tmp/attr
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import pickle
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from predisat.camera.rigs import RIG_NAMES, Rig
from predisat.masks.margins import sector_of
from predisat.masks.truth import TrueMasks
from predisat.reconstruct.batch import finished_chunk_jobs
from predisat.reconstruct.carving import (
    BinPart,
    FrameView,
    Reconstruction,
    ReconstructionParams,
    Reconstructor,
    side_cameras,
)
from predisat.reconstruct.chunks import ChunkInputs, ChunkJob, chunk_inputs
from predisat.reconstruct.evaluate import trust_counts
from predisat.reconstruct.heightfield import _camera_ceiling
from predisat.reconstruct.params import PipelineParams
from predisat.synth.render import Casters
from predisat.synth.truth import ideal_frames, true_masks
from predisat.synth.world import World

SECTORS = ("cross", "along", "ahead", "behind")


def frames_for(rig: Rig, world: World, tm: TrueMasks, cache: Path | None,
               thin_deg: float | None) -> list[FrameView]:  # fmt: skip
    """Ideal frames of ``rig`` every 10 m over the truth's run and 150 m beyond (as
    ``scripts/eval_rigs.py``), with the pipeline's thin-structure policy ``thin_deg`` (None:
    every thin-material face is sky), cached in ``cache``."""
    if cache is not None and cache.exists():
        out: list[FrameView] = pickle.loads(cache.read_bytes())
        return out
    s = tm.chainage_m
    lo, hi = max(world.extent_m[0], s[0] - 150.0), min(world.extent_m[1], s[-1] + 150.0)
    frames: list[FrameView] = []
    for pos, cam, mount in rig.cameras:
        frames += ideal_frames(world, np.arange(lo, hi + 1e-9, 10.0), cam, {pos: mount},
                               thin_deg=thin_deg)  # fmt: skip
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        cache.write_bytes(pickle.dumps(frames))
    return frames


def pipeline_frames(run_dir: Path, lo_m: float = -math.inf,
                    hi_m: float = math.inf) -> list[tuple[ChunkJob, ChunkInputs]]:  # fmt: skip
    """The chunks of a ``process_survey`` run (``scripts/eval_rigs.py``'s layout:
    ``run_dir/synth/survey`` processed into ``run_dir/proc``) meeting the chainage window
    ``[lo_m, hi_m]``, each with the frames, positions, track, side cameras and parameters its
    reconstruction ran on, rebuilt as ``predisat process`` built them (the vehicle's attitude,
    the doubts, the stops merged: :func:`predisat.reconstruct.batch.finished_chunk_jobs`,
    :func:`predisat.reconstruct.chunks.chunk_inputs`)."""
    jobs = finished_chunk_jobs(run_dir / "proc", run_dir / "synth" / "survey", lo_m=lo_m,
                               hi_m=hi_m)  # fmt: skip
    return [(job, chunk_inputs(job)) for job in jobs]


def truth_subset(tm: TrueMasks, keep: np.ndarray) -> TrueMasks:
    """``tm`` at the positions ``keep`` (boolean, shape (n,)) only."""
    n = tm.chainage_m.shape[0]
    return dataclasses.replace(tm, **{
        f.name: getattr(tm, f.name)[keep] for f in dataclasses.fields(tm)
        if isinstance(getattr(tm, f.name), np.ndarray) and getattr(tm, f.name).shape[:1] == (n,)
        and f.name != "az_deg"
    })  # fmt: skip


def _intervals_hit(ch: np.ndarray, intervals: np.ndarray | list[tuple[float, float]]) -> np.ndarray:
    out = np.zeros(ch.shape, bool)
    for a, b in np.asarray(intervals, float).reshape(-1, 2):
        out |= (ch >= a - 0.5) & (ch <= b + 0.5)
    return out


def check_trace(rec: Reconstruction, plain: Reconstruction) -> None:
    """Raise unless the traced reconstruction ``rec`` gives the untraced one's mask bit for bit
    and its trace's parts give the mask: the far-field bins the far field's bound, the
    height-field bins the grid's horizon, the covered bins 90 deg."""
    if not np.array_equal(rec.mask_el_deg, plain.mask_el_deg):
        raise RuntimeError("the traced reconstruction's mask differs from the untraced one")
    tr = rec.trace
    assert tr is not None
    far = tr.part == BinPart.FAR_FIELD
    covered = tr.part == BinPart.COVERED
    grid = ~far & ~covered
    m = rec.mask_el_deg
    ok = (np.array_equal(m[far], np.clip(rec.far_el_deg[far], 0.0, 90.0))
          and np.array_equal(m[grid], np.clip(rec.grid_el_deg[grid], 0.0, 90.0))
          and bool((m[covered] == 90.0).all()))  # fmt: skip
    if not ok:
        raise RuntimeError("the attribution's parts do not give the reconstruction's mask")


def attribute(frames: list[FrameView], tm: TrueMasks, world: World, p: ReconstructionParams,
              sides: list[str], track: Any = None) -> dict[str, Any]:  # fmt: skip
    """Cause of each bin's value (n_pos, n_az) of str, the mask, and the reconstruction.

    The parts and cells are the reconstruction's own (``Reconstructor.run(..., trace=True)``);
    ``sides``: the rig's side cameras, as ``predisat process`` passes them; ``track``: the
    run's (default the world's)."""
    s = tm.chainage_m
    track = world.track if track is None else track
    rec = Reconstructor(p).run(frames, s, track, side_cameras=sides, trace=True)
    check_trace(rec, Reconstructor(p).run(frames, s, track, side_cameras=sides))
    tr = rec.trace
    assert tr is not None
    mask = np.asarray(rec.mask_el_deg, float)
    hf = tr.height_field
    rules = dict(tr.overhead_rules)
    # the tall bands' own intervals: the same carving with the two frame rules off and no
    # interval given
    no_rules = dataclasses.replace(p, overhead_along_el_deg=None, zenith_el_deg=90.0)
    lo, hi = float(np.nanmin(hf.chainage_m)), float(np.nanmax(hf.chainage_m))
    rules["tall bands"] = Reconstructor(no_rules).height_field(
        list(tr.frames), track, lo, hi, list(tr.profiles)).overhead_m  # fmt: skip
    flat_ch = hf.chainage_m.ravel()
    flat_off = hf.offset_m.ravel()
    flat_views = (np.zeros(hf.shape, np.int32) if hf.views is None else hf.views).ravel()
    in_clear = np.abs(np.nan_to_num(flat_off, nan=99.0)) < p.clearance_half_width_m
    ceil_top = np.full(flat_ch.shape, np.inf)
    if hf.camera_ceilings.size:
        sel = np.flatnonzero(in_clear)
        ceil_top[sel] = _camera_ceiling(hf.camera_ceilings, flat_ch[sel],
                                        hf.cell_m * np.sqrt(0.5))  # fmt: skip
    bound_flat = hf.bound_m.ravel()

    def cell_cause(k: int, part: str) -> str:
        if k < 0:
            return f"{part}: no cell"
        ch = flat_ch[k : k + 1]
        if flat_views[k] == 0 and in_clear[k]:
            hit = [name for name in ("zenith", "along", "lacking side", "given", "tall bands")
                   if _intervals_hit(ch, rules[name])[0]]  # fmt: skip
            how = "ceiling" if abs(bound_flat[k] - ceil_top[k]) < 1e-3 else "band top"
            return f"{part}: prior ({'+'.join(hit or ['?'])}; {how})"
        if flat_views[k] == 0:
            return f"{part}: prior (other)"
        return f"{part}: carved ({'clearance' if in_clear[k] else 'beside the track'})"

    names = {BinPart.NEAR_GRID: "near grid", BinPart.FAR_GRID: "far grid",
             BinPart.RESOLVED: "far grid, mast rule"}  # fmt: skip
    cause = np.empty(mask.shape, object)
    for i in range(mask.shape[0]):
        for j in range(mask.shape[1]):
            part = BinPart(int(tr.part[i, j]))
            if part == BinPart.COVERED:
                cause[i, j] = "covered (closed to 90)"
            elif part == BinPart.FAR_FIELD:
                cause[i, j] = ("far: assumed" if not tr.far_seen[i, j]
                               else "far: seen, capped far cells" if tr.far_capped[i, j]
                               else "far: seen")  # fmt: skip
            elif tr.unknown[i, j]:
                cause[i, j] = f"{names[part]}: unknown"
            else:
                cause[i, j] = cell_cause(int(tr.cell[i, j]), names[part])
    return {"cause": cause, "mask": mask, "rec": rec}


def sectors(tm: TrueMasks) -> dict[str, np.ndarray]:
    """Boolean (n_pos, n_az) per sector: cross / along (as the margins'), and ahead / behind
    (within 45 deg of the direction of increasing / decreasing chainage)."""
    sec = sector_of(tm.az_deg[None, :], tm.heading_deg[:, None])
    rel = np.mod(tm.az_deg[None, :] - tm.heading_deg[:, None] + 180.0, 360.0) - 180.0
    return {"cross": sec == "cross", "along": sec == "along",
            "ahead": np.abs(rel) < 45.0, "behind": np.abs(rel) > 135.0}  # fmt: skip


def kind_at(world: World, ch: np.ndarray) -> np.ndarray:
    out = np.full(ch.shape, "open", object)
    for st in world.spec.stretches:
        if st.kind != "open":
            out[(ch >= st.start_m - 30.0) & (ch <= st.end_m + 30.0)] = st.kind
    return out


def tally(cause: np.ndarray, mask: np.ndarray, tm: TrueMasks, world: World) -> dict[str, Any]:
    trusted, good, los = trust_counts(mask, tm.mask_el_deg, 0.0)
    lost = los - good
    false = trusted - good
    sec = sectors(tm)
    kinds = np.broadcast_to(kind_at(world, tm.chainage_m)[:, None], mask.shape)
    out: dict[str, Any] = {"visible": {k: int(los[v].sum()) for k, v in sec.items()},
                           "trusted": int(trusted.sum()), "lost": defaultdict(dict),
                           "false": defaultdict(dict)}  # fmt: skip
    for c in np.unique(cause):
        at = cause == c
        for k, v in sec.items():
            out["lost"][c][k] = int(lost[at & v].sum())
        out["false"][c]["all"] = int(false[at].sum())
        for kind in np.unique(kinds[at & (false > 0)]):
            out["false"][c][kind] = int(false[at & (kinds == kind)].sum())
    return out


def merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {"visible": {}, "trusted": a["trusted"] + b["trusted"],
                           "lost": defaultdict(dict), "false": defaultdict(dict)}  # fmt: skip
    for k in set(a["visible"]) | set(b["visible"]):
        out["visible"][k] = a["visible"].get(k, 0) + b["visible"].get(k, 0)
    for part in ("lost", "false"):
        for c in set(a[part]) | set(b[part]):
            for k in set(a[part].get(c, {})) | set(b[part].get(c, {})):
                out[part][c][k] = a[part].get(c, {}).get(k, 0) + b[part].get(c, {}).get(k, 0)
    return out


def print_table(t: dict[str, Any], title: str) -> None:
    vis, n_trusted = t["visible"], max(t["trusted"], 1)

    def row(name: str, lost: dict[str, int], false: int) -> str:
        shares = "".join(f"{100 * lost.get(k, 0) / max(vis[k], 1):10.2f}" for k in SECTORS)
        return f"{name:<52}{shares}{100 * false / n_trusted:15.4f}"

    head = "".join(f"{k + ' %':>10}" for k in SECTORS)
    print(f"\n{title}\n{'cause':<52}{head}{'false trust %':>15}")
    for c in sorted(t["lost"], key=lambda c: -t["lost"][c].get("along", 0)):
        print(row(c, t["lost"][c], t["false"].get(c, {}).get("all", 0)))
    tot = {k: sum(t["lost"][c].get(k, 0) for c in t["lost"]) for k in SECTORS}
    print(row("total (sky lost)", tot, sum(t["false"][c].get("all", 0) for c in t["false"])))
    worst = [(c, k, n) for c, d in t["false"].items() for k, n in d.items() if k != "all" and n]
    if worst:
        print(
            "false trust by cause and scenery (directions): "
            + ", ".join(f"{c} / {k}: {n}" for c, k, n in sorted(worst, key=lambda x: -x[2])[:8])
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", choices=RIG_NAMES, required=True)
    ap.add_argument("--seeds", nargs="+", type=int, default=[11, 12, 13])
    ap.add_argument(
        "--truth",
        default="/tmp/eval_rigs_full/360_s{seed}/synth/truth",
        help="truth folder of scripts/eval_rigs.py per seed ({seed} substituted)",
    )
    ap.add_argument("--scale", type=float, default=0.5, help="camera resolution factor")
    ap.add_argument(
        "--work", type=Path, default=Path("/tmp/along_attr"), help="cache of the ideal frames"
    )
    ap.add_argument(
        "--thin-deg",
        default=str(PipelineParams().thin_deg),
        help="thin-structure policy of the ideal masks, degrees (the pipeline's "
        "default), or 'none': every thin-material face is sky (eval_rigs.py's ideal "
        "pass before 2026-12-05)",
    )
    ap.add_argument(
        "--pipeline",
        default=None,
        help="instead of ideal masks, the segmentations of a scripts/eval_rigs.py "
        "run folder per seed, e.g. /tmp/eval_rigs_full/360_s{seed} (its "
        "synth/survey and proc/cache)",
    )
    ap.add_argument("--params", default="{}", help="ReconstructionParams fields, JSON")
    ap.add_argument("--out", type=Path, default=None, help="JSON of the tables")
    args = ap.parse_args(argv)
    fields: dict[str, Any] = {
        k: tuple(v) if isinstance(v, list) else v for k, v in json.loads(args.params).items()
    }
    p = ReconstructionParams(**fields)
    rig = Rig.preset(args.rig).scaled(args.scale)
    total: dict[str, Any] | None = None
    per_seed = {}
    for seed in args.seeds:
        truth = Path(args.truth.format(seed=seed))
        world = World.load(truth / "world.npz")
        tm = TrueMasks.load(truth / "true_masks.npz")
        # the truth of today's code (the L-band caster and its thin-structure rule), on the
        # same world and positions: truth folders rendered before a change of the truth are
        # scored against the current one
        tm_cache = args.work / f"truth_s{seed}.npz"
        if tm_cache.exists():
            tm = TrueMasks.load(tm_cache)
        else:
            caster = Casters.for_world(world, "open3d").lband
            tm = true_masks(world, tm.chainage_m, tm.antenna_height_m, caster=caster)
            args.work.mkdir(parents=True, exist_ok=True)
            tm.save(tm_cache)
        thin = None if args.thin_deg == "none" else float(args.thin_deg)
        cache = args.work / (f"{args.rig.replace('+', '_')}_s{seed}_x{args.scale:g}"
                             f"{'' if thin is None else f'_thin{thin:g}'}.pkl")  # fmt: skip
        if args.pipeline is None:
            frames = frames_for(rig, world, tm, cache, thin)
            sides = side_cameras({pos: cam for pos, cam, _ in rig.cameras})
            res = attribute(frames, tm, world, p, sides)
            t = tally(res["cause"], res["mask"], tm, world)
            n_suspect = len(res["rec"].suspect_frames)
        else:
            # each chunk of the run from its own frames and settings (--params over the run's)
            pooled: dict[str, Any] | None = None
            n_suspect = 0
            run = Path(args.pipeline.format(seed=seed))
            ch = tm.chainage_m
            for job, inp in pipeline_frames(run, float(ch.min()), float(ch.max())):
                keep = (ch >= job.lo_m) & (ch < job.hi_m)
                if not keep.any():
                    continue
                sub = truth_subset(tm, keep)
                res = attribute(list(inp.views), sub, world,
                                dataclasses.replace(inp.params, **fields),
                                list(inp.side_cameras), inp.track)  # fmt: skip
                part = tally(res["cause"], res["mask"], sub, world)
                pooled = part if pooled is None else merge(pooled, part)
                n_suspect += len(res["rec"].suspect_frames)
            if pooled is None:
                raise SystemExit(f"{run}: no chunk of the run holds the truth's positions")
            t = pooled
        per_seed[seed] = t
        what = "ideal sky masks" if args.pipeline is None else "pipeline sky masks"
        print_table(t, f"{args.rig}, seed {seed}, {what}: sky lost per cause "
                    "(share of the truly visible directions of the sector)")  # fmt: skip
        print(f"mask = the reconstruction's, bit for bit (traced and untraced); frames set "
              f"aside as suspect: {n_suspect}")  # fmt: skip
        total = t if total is None else merge(total, t)
    if total is not None and len(args.seeds) > 1:
        print_table(total, f"{args.rig}, seeds {args.seeds} pooled")
    if args.out is not None:
        doc = {"params": json.loads(args.params), "per_seed": per_seed, "pooled": total}
        args.out.write_text(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
