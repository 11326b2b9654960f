"""Checks and analysis for scripts/independent_world.py (sub-commands check, attribute, thumbs).

* ``check OUT``: the truth re-cast with a second ray caster (trimesh + embreex) at a few
  positions; the camera model against ``cv2.fisheye.projectPoints``; image pixels ->
  ``cv2.fisheye.undistortPoints`` rays -> trimesh hit object against the renderer's object
  buffer.
* ``attribute OUT MASKS``: every falsely trusted direction of a mask file (the evaluator's
  definition: elevation grid cell centres ``(k + 0.5) * 0.1 deg`` above mask + margin and not
  above the truth) is re-cast in the world and attributed to the object class it hits;
  summaries by class, position, sector; where visible sky is lost.
* ``thumbs OUT``: a PNG contact sheet of frames.
* ``cantcheck OUT``: a canted world (``build --cant-speed-kmh``): (a) the horizon of a far flat
  plane in a side camera's image, level and rolled, against the physics of a body leaning into
  the curve; (b) the written roll's sign against the curve's hand from the manifest positions
  alone, and the design cant against the radius from them; (c) the largest roll and the
  antenna's lateral shift there.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np

EL_STEP = 0.1


def add_commands(sub):
    c = sub.add_parser("check", help="self-checks of the truth and the camera")
    c.add_argument("out")
    c.add_argument("--positions", default="0,37,73")
    c.set_defaults(func=cmd_check)
    a = sub.add_parser("attribute", help="false trust by object class")
    a.add_argument("out")
    a.add_argument("masks")
    a.add_argument("--json", default=None)
    a.set_defaults(func=cmd_attribute)
    t = sub.add_parser("thumbs", help="contact sheet of frames")
    t.add_argument("out")
    t.add_argument("--frames", default="0,20,40,60,80,100")
    t.add_argument("--png", default=None)
    t.add_argument("--size", type=int, default=384)
    t.set_defaults(func=cmd_thumbs)
    add_plot(sub)
    add_segcheck(sub)
    k = sub.add_parser("cantcheck", help="self-checks of a canted world's attitude")
    k.add_argument("out")
    k.add_argument("--json", default=None, help="default OUT/truth/cantcheck.json")
    k.set_defaults(func=cmd_cantcheck)


def _world(out):
    import independent_world as iw

    meta = json.loads((Path(out) / "world" / "objects.json").read_text())
    z = np.load(Path(out) / "world" / "mesh.npz")
    return iw, meta, z


def _trimesh_caster(z):
    import trimesh

    mesh = trimesh.Trimesh(z["V"], z["F"], process=False)
    return mesh, trimesh.ray.ray_pyembree.RayMeshIntersector(mesh)


def _antenna(iw, track, s, h_ant):
    lat, lon, h = (float(np.asarray(v).ravel()[0]) for v in track.tm.position_at([s]))
    M = track.local_to_world(lat, lon)
    return track.world_from_geo(lat, lon, h + h_ant), M


def _dirs(az_deg, el_deg, M):
    a, e = np.radians(az_deg), np.radians(el_deg)
    d = np.stack([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e) + 0 * a], -1)
    return d @ M.T


def cmd_check(args):
    iw, meta, z = _world(args.out)
    from predisat.masks.truth import TrueMasks

    tm = TrueMasks.load(Path(args.out) / "truth" / "true_masks.npz")
    s0, s1 = float(tm.chainage_m[0]), float(tm.chainage_m[-1])
    track = iw.Track(s0 - 200, s1 + 200, meta["frame_mid_chainage_m"])
    _mesh, rmi = _trimesh_caster(z)
    res = {}
    # 1. truth with a second caster: same sub-azimuths, elevations every 0.05 deg
    n_sub, step = 5, 0.5
    sub = (np.arange(n_sub) - (n_sub - 1) / 2) * step / n_sub
    worst = []
    for pi in [int(x) for x in args.positions.split(",")]:
        o, M = _antenna(iw, track, tm.chainage_m[pi], tm.antenna_height_m)
        az = (np.arange(720)[:, None] * step + sub[None, :]).ravel()
        el = np.arange(0, 90.0001, 0.05)
        best = np.zeros(az.size)
        for j0 in range(0, el.size, 200):
            ee = el[j0 : j0 + 200]
            d = _dirs(az[:, None], ee[None, :], M).reshape(-1, 3)
            hit = rmi.intersects_any(np.broadcast_to(o, d.shape), d).reshape(az.size, ee.size)
            top = np.where(hit.any(1), ee[hit.shape[1] - 1 - np.argmax(hit[:, ::-1], 1)], -1)
            best = np.maximum(best, np.where(hit.any(1), top, 0))
        m2 = best.reshape(720, n_sub).max(1)
        diff = m2 - tm.mask_el_deg[pi]
        worst.append(float(np.abs(diff).max()))
        res[f"pos{pi}"] = {
            "chainage_m": float(tm.chainage_m[pi]),
            "max_abs_diff_deg": float(np.abs(diff).max()),
            "p99_abs_diff_deg": float(np.percentile(np.abs(diff), 99)),
            "bins_over_0.1deg": int((np.abs(diff) > 0.1).sum()),
        }
        print(
            f"truth vs trimesh at {tm.chainage_m[pi]:.0f} m: max |diff| "
            f"{np.abs(diff).max():.3f} deg, 99% {np.percentile(np.abs(diff), 99):.3f}, "
            f"bins > 0.1 deg: {(np.abs(diff) > 0.1).sum()} of 720",
            flush=True,
        )
    # 2. camera model vs cv2.fisheye.projectPoints
    cam = iw.Fisheye()
    rng = np.random.default_rng(0)
    th = rng.uniform(0, math.radians(85), 5000)
    ph = rng.uniform(-np.pi, np.pi, 5000)
    X = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    u, v = cam.project(X)
    K = np.array([[cam.f, 0, cam.cx], [0, cam.f, cam.cy], [0, 0, 1.0]])
    D = np.array(cam.k, float).reshape(4, 1)
    uv_cv, _ = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)
    e = np.hypot(uv_cv[:, 0, 0] - u, uv_cv[:, 0, 1] - v).max()
    res["cv2_projectPoints_max_px"] = float(e)  # type: ignore[assignment]
    print(f"projection vs cv2.fisheye.projectPoints (theta < 85 deg): max {e:.2e} px")
    rays, valid, thg = cam.pixel_rays()
    sel = valid & (thg < math.radians(85))
    uu, vv = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    pts = np.ascontiguousarray(np.stack([uu[sel], vv[sel]], -1)[::97])  # cv2 misreads strided views
    und = cv2.fisheye.undistortPoints(
        pts.reshape(-1, 1, 2),
        K,
        D,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12),
    )
    rc = np.concatenate([und[:, 0, :], np.ones((len(pts), 1))], 1)
    rc /= np.linalg.norm(rc, axis=1, keepdims=True)
    mine = rays[sel][::97]
    ang = np.degrees(np.arccos(np.clip(np.sum(rc * mine, 1), -1, 1))).max()
    res["unproject_vs_cv2_max_deg"] = float(ang)  # type: ignore[assignment]
    print(f"pixel -> ray vs cv2.fisheye.undistortPoints (theta < 85 deg): max {ang:.2e} deg")
    # 3. pixel -> cv2 ray -> trimesh hit object vs the renderer's object buffer
    tri_obj = z["tri_obj"]
    for fb in sorted((Path(args.out) / "world").glob("objbuf_*.npz")):
        q = np.load(fb)
        obj, R_cw, c_pos = q["obj"], q["R_cw"], q["c_pos"]
        rp = rng.integers(0, cam.width, (4000, 2)).astype(float)
        und = cv2.fisheye.undistortPoints(
            rp.reshape(-1, 1, 2),
            K,
            D,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12),
        )
        rc = np.concatenate([und[:, 0, :], np.ones((len(rp), 1))], 1)
        rc /= np.linalg.norm(rc, axis=1, keepdims=True)
        thp = np.arccos(rc[:, 2])
        ok = thp < math.radians(85)
        d = rc[ok] @ R_cw.T
        _loc, idx_ray, idx_tri = rmi.intersects_location(
            np.broadcast_to(c_pos, d.shape), d, multiple_hits=False
        )
        hit_obj = np.full(ok.sum(), -1)
        hit_obj[idx_ray] = tri_obj[idx_tri]
        ui, vi = rp[ok, 0].astype(int), rp[ok, 1].astype(int)
        agree = float(np.mean(hit_obj == obj[vi, ui]))
        res[f"objbuf_{fb.stem}"] = agree  # type: ignore[assignment]
        print(f"{fb.stem}: object at {ok.sum()} pixels, trimesh(cv2 ray) == render: {agree:.4f}")
    Path(args.out, "truth", "selfcheck.json").write_text(json.dumps(res, indent=1))


def cmd_attribute(args):
    iw, meta, z = _world(args.out)
    from predisat.masks.fileformat import read_masks
    from predisat.reconstruct.evaluate import compare, load_truth

    mpath = Path(args.masks)
    if mpath.is_dir():
        mpath = mpath / "masks.parquet"
    masks = read_masks(mpath)
    truth = load_truth(args.out)
    cmp = compare(masks, truth)
    m = cmp.mask_el_deg + (cmp.margin_deg if cmp.margin_deg is not None else 0.0)
    t = cmp.truth_el_deg
    s0, s1 = float(truth.chainage_m[0]), float(truth.chainage_m[-1])
    track = iw.Track(s0 - 200, s1 + 200, meta["frame_mid_chainage_m"])
    classes = meta["classes"]
    obj_cls = z["obj_cls"]
    tri_obj = z["tri_obj"]
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(z["V"].astype(np.float32)), o3d.core.Tensor(z["F"].astype(np.uint32))  # type: ignore[call-overload]
    )
    grid = (np.arange(900) + 0.5) * EL_STEP
    n_sub = 5
    sub = (np.arange(n_sub) - (n_sub - 1) / 2) * 0.5 / n_sub
    order = np.argsort(np.abs(sub))
    tob = np.load(Path(args.out) / "truth" / "truth_objects.npz")["cls_top"]
    tidx = np.searchsorted(np.asarray(truth.chainage_m, float), cmp.chainage_m)
    recs = []  # (pos, bin, el, class, blocked, distance)
    trusted_pos = np.zeros(len(cmp.chainage_m), np.int64)
    false_pos = np.zeros(len(cmp.chainage_m), np.int64)
    lost = {"cross": 0, "along": 0}
    vis = {"cross": 0, "along": 0}
    lost_src: dict = {}
    lost_el = np.zeros(9, np.int64)
    for i, s in enumerate(cmp.chainage_m):
        cnt_tr = 900 - np.searchsorted(grid, m[i], side="right")
        trusted_pos[i] = cnt_tr.sum()
        cnt_los = 900 - np.searchsorted(grid, t[i], side="right")
        cnt_trlos = 900 - np.searchsorted(grid, np.maximum(m[i], t[i]), side="right")
        for sec in ("cross", "along"):
            k = cmp.sector[i] == sec
            vis[sec] += int(cnt_los[k].sum())
            lost[sec] += int((cnt_los - cnt_trlos)[k].sum())
        for b in np.flatnonzero(cnt_los > cnt_trlos):
            src = int(cmp.source[i, b])
            lost_src[src] = lost_src.get(src, 0) + int(cnt_los[b] - cnt_trlos[b])
            g = grid[(grid > t[i, b]) & (grid <= m[i, b])]
            np.add.at(lost_el, np.minimum((g // 10).astype(int), 8), 1)
        bad = np.flatnonzero(m[i] < t[i])
        if bad.size == 0:
            continue
        o, M = _antenna(iw, track, s, truth.antenna_height_m)
        pb, pe = [], []
        for b in bad:
            g = grid[(grid > m[i, b]) & (grid <= t[i, b])]
            pb.append(np.full(g.size, b))
            pe.append(g)
        pb, pe = np.concatenate(pb), np.concatenate(pe)  # type: ignore[assignment]
        false_pos[i] = pb.size  # type: ignore[attr-defined]
        if pb.size == 0:  # type: ignore[attr-defined]
            continue
        found = np.full(pb.size, -1)  # type: ignore[attr-defined]
        dist = np.full(pb.size, np.nan)  # type: ignore[attr-defined]
        for j in order:
            az = cmp.az_deg[pb] + sub[j]
            d = _dirs(az, pe, M)
            rays = np.concatenate([np.broadcast_to(o, d.shape), d], -1).astype(np.float32)
            ans = scene.cast_rays(o3d.core.Tensor(rays), nthreads=0)  # type: ignore[call-overload]
            th = ans["t_hit"].numpy()
            pid = ans["primitive_ids"].numpy().astype(np.int64)
            hit = np.isfinite(th) & (found < 0)
            found[hit] = tri_obj[pid[hit]]
            dist[hit] = th[hit]
        blocked = found >= 0
        # a direction no ray of the bin hits is open sky under an overhang (lamp arm,
        # cantilever, deck): false trust by the mask's definition (everything under the bin's
        # highest obstacle counts as blocked); it is attributed to the object setting the truth
        cls = np.where(blocked, obj_cls[np.maximum(found, 0)], tob[tidx[i], pb])
        recs.append(np.stack([np.full(pb.size, i), pb, pe, cls, blocked, dist], 1))  # type: ignore[attr-defined]
    recs_a = np.concatenate(recs) if recs else np.zeros((0, 6))
    tot_tr = int(trusted_pos.sum())
    out = {
        "trusted": tot_tr,
        "false": len(recs_a),
        "false_trust_pct": 100.0 * len(recs_a) / max(tot_tr, 1),
    }
    out["blocked_share_pct"] = 100.0 * float(recs_a[:, 4].mean()) if len(recs_a) else 0.0
    out["by_class"] = _by_class(recs_a, cmp, classes, t, m)
    out["by_class_blocked"] = _by_class(recs_a[recs_a[:, 4] > 0], cmp, classes, t, m)
    out["by_class_overhang"] = _by_class(recs_a[recs_a[:, 4] == 0], cmp, classes, t, m)
    _rest(out, recs_a, cmp, trusted_pos, false_pos, lost, vis, lost_src, lost_el, args)


def _by_class(recs_a, cmp, classes, t, m):
    by_cls = {}
    for c in np.unique(recs_a[:, 3]).astype(int) if len(recs_a) else []:
        k = recs_a[:, 3] == c
        name = classes[c] if c >= 0 else "none"
        pos = recs_a[k, 0].astype(int)
        bins = recs_a[k, 1].astype(int)
        per_pos = np.bincount(pos, minlength=len(cmp.chainage_m))
        top = np.argsort(per_pos)[::-1][:4]
        err = (t - m)[pos, bins]
        by_cls[name] = {
            "share_pct": 100.0 * k.sum() / len(recs_a),
            "directions": int(k.sum()),
            "positions": int((per_pos > 0).sum()),
            "cross_share_pct": 100.0 * float(np.mean(cmp.sector[pos, bins] == "cross")),
            "worst": [
                {
                    "chainage_m": float(cmp.chainage_m[p]),
                    "directions": int(per_pos[p]),
                    "az_range": _az_range(cmp.az_deg[bins[pos == p]]),
                    "el_range": [
                        float(recs_a[k][pos == p, 2].min()),
                        float(recs_a[k][pos == p, 2].max()),
                    ],
                    "max_under_deg": float((t - m)[p, bins[pos == p]].max()),
                    "az_rel_track": _az_range(
                        np.mod(cmp.az_deg[bins[pos == p]] - cmp.heading_deg[p], 360)
                    ),
                }
                for p in top
                if per_pos[p] > 0
            ],
            "median_under_deg": float(np.median(err)),
            "blocked_pct": 100.0 * float(recs_a[k, 4].mean()),
            "median_hit_distance_m": float(np.nanmedian(recs_a[k, 5]))
            if np.isfinite(recs_a[k, 5]).any()
            else None,
        }
    return dict(sorted(by_cls.items(), key=lambda kv: -kv[1]["directions"]))


def _rest(out, recs_a, cmp, trusted_pos, false_pos, lost, vis, lost_src, lost_el, args):
    fpp = 100.0 * false_pos / np.maximum(trusted_pos, 1)
    w = np.argsort(fpp)[::-1][:8]
    out["positions_with_false_trust"] = int((false_pos > 0).sum())
    out["worst_positions"] = [
        {"chainage_m": float(cmp.chainage_m[p]), "false_trust_pct": float(fpp[p])}
        for p in w
        if false_pos[p] > 0
    ]
    out["sky_lost_pct"] = {k: 100.0 * lost[k] / max(vis[k], 1) for k in lost}
    out["sky_lost_by_source_pct_of_lost"] = {
        str(k): 100.0 * v / max(sum(lost_src.values()), 1) for k, v in sorted(lost_src.items())
    }
    out["sky_lost_by_el_band_10deg"] = lost_el.tolist()
    # sector of false trust
    if len(recs_a):
        pos, bins = recs_a[:, 0].astype(int), recs_a[:, 1].astype(int)
        out["false_cross_share_pct"] = 100.0 * float(np.mean(cmp.sector[pos, bins] == "cross"))
        out["false_by_source"] = {
            str(s): int(np.sum(cmp.source[pos, bins] == s))
            for s in np.unique(cmp.source[pos, bins])
        }
    txt = json.dumps(out, indent=1, default=float)
    print(txt)
    if args.json:
        Path(args.json).write_text(txt)


def _az_range(az):
    az = np.sort(np.mod(np.asarray(az, float), 360))
    if az.size == 0:
        return None
    gaps = np.diff(np.concatenate([az, [az[0] + 360]]))
    k = int(np.argmax(gaps))
    lo, hi = az[(k + 1) % az.size], az[k]
    return [float(lo), float(hi)]


def cmd_thumbs(args):
    out = Path(args.out)
    tiles = []
    for i in [int(x) for x in args.frames.split(",")]:
        row = []
        for side in ("left", "right"):
            im = cv2.imread(str(out / "images" / f"{side}_{i:06d}.jpg"))
            im = cv2.resize(im, (args.size, args.size), interpolation=cv2.INTER_AREA)  # type: ignore[arg-type]
            cv2.putText(im, f"{side} {i}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 255, 255), 1)
            row.append(im)
        tiles.append(np.hstack(row))
    sheet = np.vstack(tiles)
    png = args.png or str(out / "thumbs.png")
    cv2.imwrite(png, sheet)
    print(png)


def add_plot(sub):
    p = sub.add_parser("plot", help="mask vs truth at some positions, with the frames")
    p.add_argument("out")
    p.add_argument("masks")
    p.add_argument("--chainages", required=True, help="comma-separated chainages")
    p.add_argument("--png", required=True)
    p.set_defaults(func=cmd_plot)


def cmd_plot(args):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from predisat.masks.fileformat import read_masks
    from predisat.reconstruct.evaluate import compare, load_truth

    mpath = Path(args.masks)
    masks = read_masks(mpath / "masks.parquet" if mpath.is_dir() else mpath)
    truth = load_truth(args.out)
    cmp = compare(masks, truth)
    meta = json.loads((Path(args.out) / "world" / "objects.json").read_text())
    tob = np.load(Path(args.out) / "truth" / "truth_objects.npz")["cls_top"]
    chs = [float(c) for c in args.chainages.split(",")]
    fig, axs = plt.subplots(
        len(chs),
        3,
        figsize=(18, 4 * len(chs)),
        gridspec_kw={"width_ratios": [3, 1, 1]},
        squeeze=False,
    )
    cmap = plt.get_cmap("tab20")
    for r, c in enumerate(chs):
        i = int(np.argmin(np.abs(cmp.chainage_m - c)))
        ti = int(np.argmin(np.abs(truth.chainage_m - c)))
        rel = np.mod(cmp.az_deg - cmp.heading_deg[i], 360)  # type: ignore[index]
        o = np.argsort(rel)
        ax = axs[r, 0]
        ax.plot(rel[o], truth.mask_el_deg[ti][o], "k-", lw=1, label="truth (max)")
        ax.plot(rel[o], truth.mask_min_el_deg[ti][o], "-", color="0.6", lw=0.8, label="truth (min)")
        ax.plot(rel[o], cmp.mask_el_deg[i][o], "r-", lw=1, label="mask")
        for k in np.unique(tob[ti]):
            sel = tob[ti] == k
            if k >= 0:
                ax.scatter(
                    rel[sel],
                    np.full(sel.sum(), -3),
                    s=4,
                    color=cmap(k % 20),
                    label=meta["classes"][k],
                )
        src = cmp.source[i]
        ax.scatter(rel, np.full(rel.size, -6), s=3, c=src, cmap="viridis", vmin=0, vmax=3)
        ax.set_xlim(0, 360)
        ax.set_ylim(-8, 92)
        ax.set_xticks(range(0, 361, 45))
        ax.set_title(
            f"{c:.0f} m: azimuth relative to the track (0 ahead, 90 right, 270 left); "
            "class strip = object setting the truth, lowest strip = mask source"
        )
        ax.legend(fontsize=6, ncol=4, loc="upper right")
        for j, side in enumerate(("left", "right")):
            k = round((c - truth.chainage_m[0]) / 10)
            im = cv2.imread(str(Path(args.out) / "images" / f"{side}_{k:06d}.jpg"))[..., ::-1]  # type: ignore[index]
            axs[r, 1 + j].imshow(im)
            axs[r, 1 + j].set_axis_off()
            axs[r, 1 + j].set_title(side)
    fig.tight_layout()
    fig.savefig(args.png, dpi=70)
    print(args.png)


def add_segcheck(sub):
    p = sub.add_parser("segcheck", help="the pipeline's per-frame sky labels against the world")
    p.add_argument("out")
    p.add_argument("process_out", help="the `predisat process --out` folder (its cache/seg-*)")
    p.add_argument("--every", type=int, default=1)
    p.add_argument("--overlay", default="", help="frame ids to draw, comma-separated")
    p.add_argument("--json", default=None)
    p.set_defaults(func=cmd_segcheck)


def cmd_segcheck(args):
    """Pixels of the upper hemisphere labelled sky by the pipeline while a solid object is
    there (false sky), per class; pixels labelled obstacle while the sky is open (sky lost).
    The sky labels are read from the pipeline's segmentation cache (packed bits, one per
    pixel; `thin` = pixels the thin-structure rule made transparent)."""
    import independent_world as iw
    import yaml

    out = Path(args.out)
    meta = json.loads((out / "world" / "objects.json").read_text())
    classes = meta["classes"]
    z = np.load(out / "world" / "mesh.npz")
    tri_obj, obj_cls = z["tri_obj"], z["obj_cls"]
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(z["V"].astype(np.float32)), o3d.core.Tensor(z["F"].astype(np.uint32))  # type: ignore[call-overload]
    )
    seg = sorted(Path(args.process_out, "cache").glob("seg-*"))[0]
    sy = yaml.safe_load((out / "survey.yaml").read_text())
    import csv

    rows = list(csv.DictReader(open(out / "manifest.csv")))
    track = iw.Track(5800, 7200, meta["frame_mid_chainage_m"])
    att = read_attitude(out)
    cam = iw.Fisheye()
    rays_cam, valid, _ = cam.pixel_rays()
    n_cls = len(classes)
    tot = np.zeros(n_cls, np.int64)
    fsky = np.zeros(n_cls, np.int64)
    fthin = np.zeros(n_cls, np.int64)
    open_px = lost_px = 0
    per_frame = []
    draw = set(args.overlay.split(",")) if args.overlay else set()
    for r in rows[:: args.every]:
        f = seg / (r["frame_id"] + ".npz")
        if not f.is_file():
            continue
        q = np.load(f)
        sky = np.unpackbits(q["sky"])[: cam.width * cam.height].reshape(cam.height, cam.width) > 0
        thin = np.unpackbits(q["thin"])[: cam.width * cam.height].reshape(cam.height, cam.width) > 0
        s = float(r["chainage_m"])
        lat, lon, h, Rv = track.pose(s)
        mt = sy["cameras"][r["side"]]["mount"]
        R_cw = Rv @ iw.cam_to_vehicle(mt)
        ant = track.world_from_geo(lat, lon, h + sy["antenna_height_m"])
        c_pos = ant + Rv @ np.array(mt["lever_arm_m"])
        if att is not None:  # a canted world: the pose its frames were rendered with
            c_pos, R_cw, _ = iw.camera_pose(
                track, s, sy["antenna_height_m"], r["side"], *att[round(s, 3)]
            )
        d = rays_cam @ R_cw.T
        up = d @ Rv[:, 2] > 0.0  # above the local horizontal
        sel = valid & up
        rr = np.concatenate([np.broadcast_to(c_pos, d[sel].shape), d[sel]], -1).astype(np.float32)
        ans = scene.cast_rays(o3d.core.Tensor(rr), nthreads=0)  # type: ignore[call-overload]
        hit = np.isfinite(ans["t_hit"].numpy())
        cls = np.full(hit.size, -1)
        cls[hit] = obj_cls[tri_obj[ans["primitive_ids"].numpy()[hit].astype(np.int64)]]
        sk = sky[sel]
        th_ = thin[sel]
        np.add.at(tot, cls[hit], 1)
        np.add.at(fsky, cls[hit & sk], 1)
        np.add.at(fthin, cls[hit & th_], 1)
        open_px += int((~hit).sum())
        lost_px += int((~hit & ~sk).sum())
        per_frame.append((r["frame_id"], s, int((hit & sk).sum()), int(hit.sum())))
        if r["frame_id"] in draw:
            im = cv2.imread(str(out / r["image"])).astype(float)  # type: ignore[union-attr]
            fs = np.zeros(sel.shape, bool)
            fs[sel] = hit & sk
            lo = np.zeros(sel.shape, bool)
            lo[sel] = ~hit & ~sk
            im[fs] = 0.4 * im[fs] + 0.6 * np.array([0, 0, 255.0])
            im[lo] = 0.5 * im[lo] + 0.5 * np.array([255.0, 0, 0])
            cv2.imwrite(f"/tmp/indep/seg_{out.name}_{r['frame_id']}.png", im.astype(np.uint8))
    res = {
        "upper_hemisphere_pixels_by_class": {
            classes[k]: int(tot[k]) for k in range(n_cls) if tot[k]
        },
        "labelled_sky_pct_by_class": {
            classes[k]: 100.0 * fsky[k] / tot[k] for k in range(n_cls) if tot[k]
        },
        "thin_pct_by_class": {
            classes[k]: 100.0 * fthin[k] / tot[k] for k in range(n_cls) if tot[k]
        },
        "open_sky_labelled_obstacle_pct": 100.0 * lost_px / max(open_px, 1),
        "worst_frames": sorted(per_frame, key=lambda x: -x[2])[:10],
    }
    txt = json.dumps(res, indent=1)
    print(txt)
    if args.json:
        Path(args.json).write_text(txt)


def read_attitude(out):
    """{chainage (rounded to mm): (roll_deg, pitch_deg)} from world/attitude.csv (a canted
    world, with or without the IMU columns), else None (a level world)."""
    f = Path(out) / "world" / "attitude.csv"
    if not f.is_file():
        return None
    a = np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
    return {round(float(r[0]), 3): (float(r[3]), float(r[4])) for r in a}


def _horizon_row(iw, cam, c_pos, R_cw, up, u_col):
    """Image row of the horizon of a far flat plane (level, 2 m below the camera, 40 km
    across: dip < 0.003 deg) in pixel column u_col: the first row from the top whose ray
    hits the plane, refined to 1/64 px by bisection on the row coordinate."""
    import open3d as o3d

    # the plane: a square of 40 km side through c_pos - 2 up, normal up
    e1 = np.cross(up, [1.0, 0, 0] if abs(up[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    q = c_pos - 2.0 * up
    L = 20000.0
    V = np.array([q + L * (a * e1 + b * e2) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    sc = o3d.t.geometry.RaycastingScene()
    sc.add_triangles(
        o3d.core.Tensor((V - c_pos).astype(np.float32)),  # type: ignore[call-overload]  # camera at the origin: float32 safe
        o3d.core.Tensor(np.array([[0, 1, 2], [0, 2, 3]], np.uint32)),  # type: ignore[call-overload]
    )

    def ray(u, v):  # pixel -> unit ray in the camera frame (the renderer's own unprojection)
        x, y = (u - cam.cx) / cam.f, (v - cam.cy) / cam.f
        r = math.hypot(x, y)
        th = float(np.interp(r, cam._td, cam._th))
        for _ in range(5):
            k1, k2, k3, k4 = cam.k
            t2 = th * th
            der = 1 + 3 * k1 * t2 + 5 * k2 * t2**2 + 7 * k3 * t2**3 + 9 * k4 * t2**4
            th -= (float(cam.thetad(th)) - r) / der
        ph = math.atan2(y, x)
        return np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])

    def hits(vs):
        d = np.array([R_cw @ ray(u_col, v) for v in vs])
        rr = np.concatenate([np.zeros_like(d), d], 1).astype(np.float32)
        return np.isfinite(sc.cast_rays(o3d.core.Tensor(rr))["t_hit"].numpy())  # type: ignore[call-overload]

    rows = np.arange(0, cam.height, 1.0)
    rows = rows[np.hypot(u_col - cam.cx, rows - cam.cy) <= cam.circle_px - 1]
    h = hits(rows)
    k = int(np.argmax(h))
    lo, hi = rows[k - 1], rows[k]
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        if hits([mid])[0]:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def cmd_cantcheck(args):
    import csv

    import independent_world as iw
    import yaml

    out = Path(args.out)
    sy = yaml.safe_load((out / "survey.yaml").read_text())
    meta = json.loads((out / "world" / "objects.json").read_text())
    h_ant = float(sy["antenna_height_m"])
    rows = [r for r in csv.DictReader(open(out / "manifest.csv")) if r["side"] == "left"]
    att = read_attitude(out)
    if att is None:
        raise SystemExit(f"{out}: no world/attitude.csv: not a canted world")
    cant = np.loadtxt(out / "truth" / "cant.csv", delimiter=",", skiprows=1, ndmin=2)
    imu = "roll_deg" in rows[0] and rows[0]["roll_deg"] != ""
    s = np.array([float(r["chainage_m"]) for r in rows])
    # the roll as written (the manifest's, or with --no-imu the one rendered with)
    written = [
        (float(r["roll_deg"]), float(r["pitch_deg"])) if imu else att[round(x, 3)]
        for r, x in zip(rows, s, strict=True)
    ]
    roll = np.array([w[0] for w in written])
    pitch = np.array([w[1] for w in written])
    res: dict = {"imu_columns": bool(imu), "positions": len(s)}
    # (b) the curve's hand and radius from the manifest's antenna positions alone (ECEF ->
    # ENU at the middle; the turn of consecutive chords, the circle through three positions)
    lat = np.array([float(r["lat_deg"]) for r in rows])
    lon = np.array([float(r["lon_deg"]) for r in rows])
    hh = np.array([float(r["h_m"]) for r in rows])
    X = iw.ecef_from_geodetic(lat, lon, hh)
    m = len(s) // 2
    P = (X - X[m]) @ iw.enu_rotation(lat[m], lon[m]).T
    turn = np.full(len(s), np.nan)
    radius = np.full(len(s), np.nan)
    for i in range(1, len(s) - 1):
        a, b = P[i] - P[i - 1], P[i + 1] - P[i]
        cz = a[0] * b[1] - a[1] * b[0]  # > 0: the track turns left (anticlockwise from above)
        turn[i] = np.sign(cz)
        c = P[i + 1] - P[i - 1]
        la, lb, lc = (np.linalg.norm(x[:2]) for x in (a, b, c))
        radius[i] = la * lb * lc / max(2.0 * abs(cz), 1e-12)  # circumradius abc / (4 area)
    cant_at = dict(zip(np.round(cant[:, 0], 3), cant[:, 1], strict=True))
    cmm = np.array([cant_at[round(x, 3)] for x in s])
    on_curve = (cmm >= 5) & np.isfinite(turn)
    expect = -turn  # roll positive raises the left: the left goes down on a left curve
    ok = np.sign(roll[on_curve]) == expect[on_curve]
    V = sy.get("canted_vehicle", {}).get("design_speed_kmh")
    cmax = sy.get("canted_vehicle", {}).get("max_cant_mm", 160.0)
    c_from_r = np.minimum(cmax, 11.8 * V**2 / radius) if V else np.full(len(s), np.nan)
    c_from_r = 5.0 * np.floor(c_from_r / 5.0 + 0.5)
    dc = np.abs(c_from_r - cmm)[np.isfinite(radius)]
    res["b_roll_sign"] = {
        "positions_on_cant": int(on_curve.sum()),
        "left_hand": int((turn[on_curve] > 0).sum()),
        "right_hand": int((turn[on_curve] < 0).sum()),
        "sign_agrees": int(ok.sum()),
        "pass": bool(ok.all() and on_curve.any()),
        "min_radius_m_from_positions": float(np.nanmin(radius)),
        "cant_from_positions_vs_written_max_abs_mm": float(dc.max()),
        "cant_from_positions_vs_written_within_5mm_pct": float(100.0 * np.mean(dc <= 5.0)),
    }
    print(
        f"(b) roll sign vs the curve's hand from the manifest positions: "
        f"{int(ok.sum())}/{int(on_curve.sum())} positions with cant agree "
        f"({int((turn[on_curve] > 0).sum())} left-hand, {int((turn[on_curve] < 0).sum())} "
        f"right-hand); min R from positions {np.nanmin(radius):.0f} m; design cant from that R "
        f"vs truth/cant.csv: max |diff| {dc.max():.0f} mm, {100.0 * np.mean(dc <= 5.0):.0f} % "
        f"within 5 mm"
    )
    # (c) the largest roll; the antenna's shift there (rotation about the rail-level axis)
    s0, s1 = float(s[0]), float(s[-1])
    track = iw.Track(s0 - 200, s1 + 200, meta["frame_mid_chainage_m"])
    k = int(np.argmax(np.abs(roll)))
    lat_k, lon_k, h_k, Rv = track.pose(s[k])
    ant_n = track.world_from_geo(lat_k, lon_k, h_k + h_ant)
    _, _, ant_b = iw.camera_pose(track, s[k], h_ant, "left", roll[k], pitch[k])
    d = ant_b - ant_n
    res["c_largest_roll"] = {
        "chainage_m": float(s[k]),
        "roll_deg": float(roll[k]),
        "max_abs_roll_deg": float(abs(roll[k])),
        "cant_mm": float(cmm[k]),
        "antenna_left_shift_m": float(d @ Rv[:, 1]),
        "antenna_up_shift_m": float(d @ Rv[:, 2]),
        "expected_left_shift_m": float(-h_ant * math.sin(math.radians(roll[k]))),
        "max_abs_pitch_deg": float(np.abs(pitch).max()),
    }
    print(
        f"(c) max |roll| {abs(roll[k]):.3f} deg (roll {roll[k]:+.3f}) at {s[k]:.0f} m, cant "
        f"{cmm[k]:.0f} mm: antenna shifted {d @ Rv[:, 1]:+.4f} m to the left (expected "
        f"-h sin(roll) = {-h_ant * math.sin(math.radians(roll[k])):+.4f}), "
        f"{d @ Rv[:, 2]:+.4f} m up; max |pitch| {np.abs(pitch).max():.3f} deg"
    )
    # (a) the horizon of a far flat plane in the side cameras, level vs rolled, at the
    # largest roll of a left-hand curve (else of the world's curve, the expectation mirrored)
    left_curve = on_curve & (turn > 0)
    cand = np.flatnonzero(left_curve) if left_curve.any() else np.flatnonzero(on_curve)
    ka = int(cand[np.argmax(np.abs(roll[cand]))])
    cam = iw.Fisheye()
    res["a_horizon"] = {"chainage_m": float(s[ka]), "roll_deg": float(roll[ka]), "curve": (
        "left" if turn[ka] > 0 else "right")}
    all_ok = True
    for side in ("left", "right"):
        _, _, _, Rv = track.pose(s[ka])
        up = Rv[:, 2]
        c0, R0, _ = iw.camera_pose(track, s[ka], h_ant, side)
        c1, R1, _ = iw.camera_pose(track, s[ka], h_ant, side, roll[ka], pitch[ka])
        v0 = _horizon_row(iw, cam, c0, R0, up, cam.cx)
        v1 = _horizon_row(iw, cam, c1, R1, up, cam.cx)
        el0 = math.degrees(math.asin(R0[:, 2] @ up))
        el1 = math.degrees(math.asin(R1[:, 2] @ up))
        # physics: the side going down (roll < 0: the left) tilts its camera's axis down by
        # |roll|, so the horizon rises in its image (smaller row); the other side mirrors
        side_down = "left" if roll[ka] < 0 else "right"
        higher = side == side_down
        v_exp = cam.cy + cam.f * float(cam.thetad(math.radians(el1)))
        passed = (v1 < v0) == higher
        all_ok &= passed
        res["a_horizon"][side] = {
            "axis_elevation_level_deg": el0,
            "axis_elevation_rolled_deg": el1,
            "horizon_row_level_px": v0,
            "horizon_row_rolled_px": v1,
            "horizon_row_rolled_from_lens_model_px": v_exp,
            "expected": "higher" if higher else "lower",
            "pass": bool(passed),
        }
        print(
            f"(a) {side} camera at {s[ka]:.0f} m ({res['a_horizon']['curve']}-hand curve, roll "
            f"{roll[ka]:+.3f} deg): optical axis elevation {el0:.3f} -> {el1:.3f} deg; horizon "
            f"row {v0:.2f} -> {v1:.2f} px (lens model {v_exp:.2f}); expected "
            f"{'higher' if higher else 'lower'} in the image: {'PASS' if passed else 'FAIL'}"
        )
    res["a_horizon"]["pass"] = bool(all_ok)
    res["pass"] = bool(all_ok and res["b_roll_sign"]["pass"])
    print("cantcheck:", "PASS" if res["pass"] else "FAIL")
    Path(args.json or out / "truth" / "cantcheck.json").write_text(json.dumps(res, indent=1))
