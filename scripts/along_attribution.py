"""Where the reconstruction loses the sky, bin by bin (issue 32, docs/reconstruction.md section 9).

Reconstructs a rig's masks from its *ideal* sky masks (ray cast, no segmentation error; the
frames of ``scripts/eval_rigs.py``'s ideal pass) on a held-out world rendered by
``scripts/eval_rigs.py`` (its ``synth/truth`` folder: ``world.npz`` and ``true_masks.npz``;
the world and the antenna positions do not depend on the rig, so one truth folder serves every
rig), then attributes every bin where the mask stands above the truth to the part of the
reconstruction that sets the mask there:

* ``far: assumed`` the far-field default (no camera at the position saw that far field);
* ``far: seen`` the far-field bound of a camera at the position (its skyline, with the
  camera-antenna parallax allowance);
* ``near|far grid: unknown`` a ray of the height field met a cell no frame bounded;
* ``near|far grid: prior ...`` the cell is a clearance cell whose bound the clearance prior set
  (an overhead structure detected: by the zenith rule, the along-track overhead rule, the tall
  bands on both sides; ``ceiling`` when the cameras' ceiling set the bound);
* ``near|far grid: carved ...`` a carved cell (split into clearance cells over the track and
  others): the carving's bound stands above the true obstacle (a cell bounded from its far
  corner, a cell only high rays reach).

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
import pickle
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from predisat.camera.rigs import RIG_NAMES, Rig
from predisat.masks.margins import sector_of
from predisat.masks.truth import TrueMasks
from predisat.reconstruct import carving as cv
from predisat.reconstruct.badframes import BadFrame
from predisat.reconstruct.carving import FrameView, ReconstructionParams, Reconstructor
from predisat.reconstruct.evaluate import trust_counts
from predisat.reconstruct.framecache import decode_cache
from predisat.reconstruct.heightfield import _camera_ceiling
from predisat.reconstruct.params import PipelineParams
from predisat.survey import Survey
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


def pipeline_frames(run_dir: Path, track: Any) -> list[FrameView]:
    """The frames a ``process_survey`` run reconstructed from: ``run_dir/synth/survey`` with
    the segmentations cached in ``run_dir/proc/cache`` (``scripts/eval_rigs.py``'s layout), as
    :func:`predisat.reconstruct.chunks.run_chunk` builds them."""
    survey = Survey.load(run_dir / "synth" / "survey", track=track, check_images=False,
                         on_error="skip")  # fmt: skip
    # the newest segmentation cache: the one of the last run (the code of the segmentation
    # is part of its name; older ones stay behind)
    caches = sorted((run_dir / "proc" / "cache").glob("seg-*"), key=lambda d: d.stat().st_mtime)
    if not caches:
        raise ValueError(f"{run_dir / 'proc' / 'cache'}: no segmentation cache; run "
                         "scripts/eval_rigs.py there first")  # fmt: skip
    fr = survey.frames
    s = np.round(np.asarray(fr.chainage_m, float), 3)
    ant = np.asarray(track.enu_at(s), float) + survey.antenna_height_m * np.asarray(
        track.up_at(s), float
    )
    heading = np.asarray(track.heading_at(s), float)
    pp = PipelineParams()
    out = []
    for k in range(len(s)):
        fid, side = str(fr.frame_id[k]), str(fr.side[k])
        with np.load(caches[-1] / f"{fid}.npz", allow_pickle=False) as z:
            got = decode_cache(z, json.loads(str(z["meta"])), fid)
        if isinstance(got, BadFrame):
            continue
        sky, conf, thin = got
        cam, mount = survey.cameras[side].camera, survey.cameras[side].mount
        width = pp.thin_px(cam) * cam.widest_pixel_deg if thin is not None else 0.0
        out.append(FrameView(chainage_m=float(s[k]), sky_mask=np.array(sky), camera=cam,
                             mount=mount, antenna_enu_m=ant[k], heading_deg=float(heading[k]),
                             reverse=bool(survey.reverse), confidence=conf, frame_id=fid,
                             thin_mask=None if thin is None else np.array(thin),
                             thin_width_deg=width))  # fmt: skip
    return out


def _intervals_hit(ch: np.ndarray, intervals: list[tuple[float, float]]) -> np.ndarray:
    out = np.zeros(ch.shape, bool)
    for a, b in intervals:
        out |= (ch >= a - 0.5) & (ch <= b + 0.5)
    return out


def attribute(frames: list[FrameView], tm: TrueMasks, world: World,
              p: ReconstructionParams) -> dict[str, Any]:  # fmt: skip
    """Cause of each bin's value (n_pos, n_az) of str, the mask, and the reconstruction."""
    rc = Reconstructor(p)
    s = tm.chainage_m
    rec = rc.run(frames, s, world.track)
    lo, hi = float(s.min()), float(s.max())
    keep = [f for f in frames if lo - p.used_m <= f.chainage_m <= hi + p.used_m]
    profs = rc.profiles(keep)
    margin = p.reach_m + cv._WINDOW_MARGIN_M
    hf = rc.height_field(keep, world.track, lo - margin, hi + margin, profs)
    # the views raster replaced by cell indices: the support the ray march returns then names
    # the cell that set each ray
    carved_views = hf.views
    index = np.arange(1, hf.bound_m.size + 1, dtype=np.int32).reshape(hf.shape)
    hf_idx = dataclasses.replace(hf, views=index)
    ant, rot = cv._antennas(world.track, s, p.antenna_height_m)
    caps = cv._ceiling_caps(hf.camera_ceilings, s, ant)
    near_el, near_unk, fg_el, fg_unk, near_cell, fg_cell = cv._horizon_parts(
        hf_idx, ant, rot, p, caps
    )
    far_el, far_seen, _, _ = cv._far_field(keep, rc.solid_profiles(keep, profs), s, ant,
                                           world.track, p)  # fmt: skip
    near_b, near_c = cv._bins_with_support(near_el, near_cell, p.n_sub)
    fg_b, fg_c = cv._bins_with_support(fg_el, fg_cell, p.n_sub)
    far_part = np.where(far_seen, np.minimum(fg_b, far_el), fg_b)
    grid = np.maximum(near_b, far_part)
    mask = np.clip(np.maximum(grid, far_el), 0.0, 90.0)
    if not np.allclose(mask, rec.mask_el_deg, atol=1e-4):
        raise RuntimeError("the attribution's mask differs from the reconstruction's")
    near_unk_b = cv._bins(near_unk.astype(float), p.n_sub) > 0
    fg_unk_b = cv._bins(fg_unk.astype(float), p.n_sub) > 0
    # overhead intervals per rule
    zen = [(f.chainage_m - p.zenith_spread_m, f.chainage_m + p.zenith_spread_m)
           for f, pr in zip(keep, profs, strict=True) if cv._zenith_blocked(pr, p)]  # fmt: skip
    along = cv._along_overhead(keep, profs, p)
    # the tall bands' own intervals: the same carving with the two frame rules off
    no_rules = dataclasses.replace(p, overhead_along_el_deg=None, zenith_el_deg=90.0)
    bands = [tuple(r) for r in Reconstructor(no_rules).height_field(
        keep, world.track, lo - margin, hi + margin, profs).overhead_m]  # fmt: skip
    flat_ch = hf.chainage_m.ravel()
    flat_off = hf.offset_m.ravel()
    flat_views = (np.zeros(hf.shape, np.int32) if carved_views is None else carved_views).ravel()
    in_clear = np.abs(np.nan_to_num(flat_off, nan=99.0)) < p.clearance_half_width_m
    ceil_top = np.full(flat_ch.shape, np.inf)
    if hf.camera_ceilings.size:
        sel = np.flatnonzero(in_clear)
        ceil_top[sel] = _camera_ceiling(hf.camera_ceilings, flat_ch[sel],
                                           hf.cell_m * np.sqrt(0.5))  # fmt: skip
    bound_flat = hf.bound_m.ravel()

    def cell_cause(cell: int, part: str) -> str:
        k = cell - 1
        if k < 0:
            return f"{part}: no cell"
        ch = flat_ch[k : k + 1]
        if flat_views[k] == 0 and in_clear[k]:
            rules = []
            if _intervals_hit(ch, zen)[0]:
                rules.append("zenith")
            if _intervals_hit(ch, along)[0]:
                rules.append("along-overhead")
            if _intervals_hit(ch, bands)[0]:
                rules.append("tall bands")
            if not rules:
                rules.append("?")
            how = "ceiling" if abs(bound_flat[k] - ceil_top[k]) < 1e-3 else "band top"
            return f"{part}: prior ({'+'.join(rules)}; {how})"
        if flat_views[k] == 0:
            return f"{part}: prior (other)"
        return f"{part}: carved ({'clearance' if in_clear[k] else 'beside the track'})"

    cause = np.empty(mask.shape, object)
    for i in range(mask.shape[0]):
        for j in range(mask.shape[1]):
            if far_el[i, j] >= grid[i, j]:
                cause[i, j] = "far: seen" if far_seen[i, j] else "far: assumed"
            elif near_b[i, j] >= far_part[i, j]:
                cause[i, j] = ("near grid: unknown" if near_unk_b[i, j]
                               else cell_cause(int(near_c[i, j]), "near grid"))  # fmt: skip
            elif far_seen[i, j] and far_el[i, j] <= fg_b[i, j]:
                cause[i, j] = "far: seen"
            else:
                cause[i, j] = ("far grid: unknown" if fg_unk_b[i, j]
                               else cell_cause(int(fg_c[i, j]), "far grid"))  # fmt: skip
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
        else:
            frames = pipeline_frames(Path(args.pipeline.format(seed=seed)), world.track)
        res = attribute(frames, tm, world, p)
        t = tally(res["cause"], res["mask"], tm, world)
        per_seed[seed] = t
        what = "ideal sky masks" if args.pipeline is None else "pipeline sky masks"
        print_table(t, f"{args.rig}, seed {seed}, {what}: sky lost per cause "
                    "(share of the truly visible directions of the sector)")  # fmt: skip
        total = t if total is None else merge(total, t)
    if total is not None and len(args.seeds) > 1:
        print_table(total, f"{args.rig}, seeds {args.seeds} pooled")
    if args.out is not None:
        doc = {"params": json.loads(args.params), "per_seed": per_seed, "pooled": total}
        args.out.write_text(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
