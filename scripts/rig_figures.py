"""What each survey rig sees: a sky-coverage polar plot per rig preset (docs/rigs.md).

For every direction above the horizon (azimuth relative to the direction of travel, elevation),
counts the rig's cameras whose image holds it (:meth:`CameraModel.ray_to_pixel` inside the
image), from the presets of :class:`predisat.camera.rigs.Rig` at full resolution. Zenith at the
centre, horizon at the rim, ahead at the top, right of the train to the right.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/rig_figures.py --out docs/figures/rigs_coverage.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure goes to a file

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap

from predisat.camera.rigs import RIG_NAMES, Rig


def coverage(rig: Rig, az_deg: np.ndarray, el_deg: np.ndarray) -> np.ndarray:
    """Cameras seeing each (elevation, azimuth) direction, shape (n_el, n_az); azimuth
    clockwise from the direction of travel."""
    a, e = np.meshgrid(np.radians(az_deg), np.radians(el_deg))
    # vehicle frame: x forward, y left, z up; clockwise azimuth turns toward -y
    d = np.stack([np.cos(e) * np.cos(a), -np.cos(e) * np.sin(a), np.sin(e)], -1)
    count = np.zeros(a.shape, int)
    for _, cam, mount in rig.cameras:
        u, v = cam.ray_to_pixel(d @ mount.camera_to_vehicle())  # R^T d, row-wise
        count += cam.contains(u, v)
    return count


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("docs/figures/rigs_coverage.png"))
    args = ap.parse_args(argv)
    az = np.arange(0.0, 360.0, 0.5)
    el = np.arange(0.0, 90.01, 0.5)
    cmap = ListedColormap(["#d9d9d9", "#9ecae1", "#3182bd", "#08519c", "#08306b"])
    norm = BoundaryNorm([-0.5, 0.5, 1.5, 2.5, 3.5, 4.5], cmap.N)
    fig, axes = plt.subplots(1, len(RIG_NAMES), figsize=(4.6 * len(RIG_NAMES), 5.0),
                             subplot_kw={"projection": "polar"})  # fmt: skip
    for ax, name in zip(axes, RIG_NAMES, strict=True):
        rig = Rig.preset(name)
        n = coverage(rig, az, el)
        mesh = ax.pcolormesh(np.radians(az), 90.0 - el, n, cmap=cmap, norm=norm, shading="auto")
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        ax.set_rlim(0, 90)
        ax.set_rticks([30, 60, 90], labels=["60°", "30°", "0°"])
        ax.set_xticks(np.radians([0, 90, 180, 270]), labels=["ahead", "right", "behind", "left"])
        low = n[el <= 15.0]
        along = np.minimum(np.abs(np.mod(az + 180, 360) - 180), np.abs(np.mod(az, 360) - 180))
        ax.set_title(f"{name}\nsky seen: {100 * np.mean(n > 0):.0f} % of the directions\n"
                     f"0-15° up within 20° of the track axis: "
                     f"{100 * np.mean(low[:, along <= 20] > 0):.0f} %", fontsize=9)  # fmt: skip
    cb = fig.colorbar(mesh, ax=axes, orientation="horizontal", fraction=0.05, pad=0.1,
                      ticks=[0, 1, 2, 3, 4])  # fmt: skip
    cb.set_label("cameras seeing the direction (zenith at the centre, horizon at the rim)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110, bbox_inches="tight")
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
