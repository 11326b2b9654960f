"""``predisat availability`` killed and resumed, and what saving the blocks costs.

Usage::

    python scripts/availability_resume.py [--work DIR] [--kill-share 0.5] [--hours 24]

On the whole demo line (line 144, a position every 10 m, the synthetic masks of
``scripts/bench_availability.py``) over ``--hours`` of the embedded day at 30 s, GPS,
interval every 10th epoch, serially:

1. **cost of saving**: the engine on the masks rule without saving blocks (the baseline),
   saving every block into a fresh folder, and taking every block back from that folder
   (a rerun after a kill at the very end); wall times and ratios;
2. **kill and resume**: the command uninterrupted, then the same command killed (SIGKILL)
   once ``--kill-share`` of all its blocks are saved, then run again: its wall time, the
   blocks it took back, and whether every output file is the uninterrupted run's, byte for
   byte (``SOURCE_DATE_EPOCH`` pinned).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from predisat.availability.engine import BlockCheckpoint, compute_availability
from predisat.availability.satellites import (
    LinePositions,
    SatellitePositions,
    TrustRule,
    default_ephemeris,
    default_window,
)
from predisat.masks.fileformat import write_masks
from predisat.masks.maskset import MaskSet

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_availability import synthetic_masks


def cost_of_saving(masks: MaskSet, hours: float, work: Path) -> None:
    t = default_window(30.0)[: int(hours * 120)]
    sats = SatellitePositions.from_ephemeris(default_ephemeris(), t, "gps")
    pos = LinePositions.from_masks(masks)
    rule = TrustRule.mask(masks)
    folder = work / "blocks"
    shutil.rmtree(folder, ignore_errors=True)
    compute_availability(sats, pos, rule, interval_every=10)  # warm-up
    runs = {}
    for name, checkpoint in (("no saving (baseline)", None),
                             ("saving every block", BlockCheckpoint(folder)),
                             ("taking every block back", BlockCheckpoint(folder))):  # fmt: skip
        t0 = time.perf_counter()
        res = compute_availability(sats, pos, rule, checkpoint=checkpoint, interval_every=10)
        runs[name] = (time.perf_counter() - t0, res)
    base_t, base = runs["no saving (baseline)"]
    size = sum(p.stat().st_size for p in folder.iterdir())
    print(f"cost of saving: {pos.n_pos} positions x {len(t)} epochs, masks rule, "
          f"{res.provenance['blocks']} blocks; load average {os.getloadavg()[0]:.1f}")
    for name, (took, r) in runs.items():
        same = r.count.tobytes() == base.count.tobytes() and (
            r.interval_m is not None and base.interval_m is not None
            and r.interval_m.tobytes() == base.interval_m.tobytes()
        )  # fmt: skip
        print(f"  {name:<26s} {took:7.2f} s  ratio {base_t / took:5.2f}  "
              f"resumed {r.provenance['blocks_resumed']:3d}  same bits {same}")
    print(f"  saved blocks: {size / 1e6:.1f} MB")
    shutil.rmtree(folder)


def kill_and_resume(mask_file: Path, hours: float, share: float, work: Path) -> None:
    end = f"2020-06-25T{int(hours):02d}:00" if hours < 24 else "2020-06-26T00:00"
    env = {**os.environ, "SOURCE_DATE_EPOCH": "1700000000"}

    def argv(out: Path) -> list[str]:
        return [sys.executable, "-c", "import sys; from predisat.cli import main; sys.exit(main())",
                "availability", "--masks", str(mask_file),
                "--start", "2020-06-25T00:00", "--end", end, "--out", str(out),
                "--scheduler", "serial", "--quiet"]  # fmt: skip

    whole, resumed = work / "whole", work / "resumed"
    for d in (whole, resumed):
        shutil.rmtree(d, ignore_errors=True)
    t0 = time.perf_counter()
    subprocess.run(argv(whole), env=env, check=True)
    t_whole = time.perf_counter() - t0
    n_pos = len(synthetic_masks().chainage_m)
    total = 3 * -(-n_pos // 64)  # 3 rules (masks, no mask, 15 deg), blocks of 64 positions
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv(resumed), env=env)
    saved = 0
    while proc.poll() is None:
        saved = len(list((resumed / "blocks").rglob("*.npz")))
        if saved >= share * total:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    t_kill = time.perf_counter() - t0
    saved = len(list((resumed / "blocks").rglob("*.npz")))
    t0 = time.perf_counter()
    subprocess.run(argv(resumed), env=env, check=True)
    t_resume = time.perf_counter() - t0
    names = sorted(p.name for p in whole.iterdir() if p.is_file())
    same = all((whole / n).read_bytes() == (resumed / n).read_bytes() for n in names)
    same = same and names == sorted(p.name for p in resumed.iterdir() if p.is_file())
    print(f"kill and resume ({total} blocks; load average {os.getloadavg()[0]:.1f}):")
    print(f"  uninterrupted command          {t_whole:7.2f} s")
    print(f"  killed (SIGKILL) after         {t_kill:7.2f} s with {saved} blocks saved")
    print(f"  rerun (resumed)                {t_resume:7.2f} s  ratio to uninterrupted "
          f"{t_whole / t_resume:5.2f}")  # fmt: skip
    print(f"  every output file ({len(names)}) the uninterrupted run's, byte for byte: {same}; "
          f"blocks/ left: {(resumed / 'blocks').exists()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path,
                    default=Path(tempfile.gettempdir()) / "availability_resume")  # fmt: skip
    ap.add_argument("--kill-share", type=float, default=0.5)
    ap.add_argument("--hours", type=float, default=24.0)
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    masks = synthetic_masks()
    mask_file = write_masks(masks, args.work / "line144.masks.parquet")
    cost_of_saving(masks, args.hours, args.work)
    kill_and_resume(mask_file, args.hours, args.kill_share, args.work)


if __name__ == "__main__":
    main()
