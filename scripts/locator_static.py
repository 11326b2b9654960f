"""The 1-D locator on real pseudoranges: a static station on a virtual straight track.

GEONET stations 0759 and 3040 (RTKLIB test data, 2005-04-02 00:00-00:59:30, 120 epochs at
30 s, GPS C1, ``../shared/data/gnss/rtklib``). A straight virtual track, 4 km long, is laid
through each station's known antenna position (0759: GEONET coordinates; 3040: its header
position) at several headings; the station's chainage is the truth (2000 m). The error model
is learned on the *other* station (``locator.errorfit.static_residuals``), so no figure uses
the data it was fitted on; ``--bound`` chooses the overbound (default, as ``locator
calibrate``) or the least-squares estimate. Every received GPS signal above the horizon is
used (open sky: no mask), active integrity, the odometer reads zero (the train stands still).

Prints per station and heading: epochs, share of epochs per mode, share with a claim,
along-track error (median, 95th percentile of |error|) of SATHIA and of the 1-D WLS, interval
length (median, 95th percentile), HMI.

Usage::

    .venv/bin/python scripts/locator_static.py [--data ../shared/data/gnss/rtklib] [--out DIR]
        [--k-sigma K] [--bound overbound|estimate]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from locator.corrections import RangeModel
from locator.errorfit import static_residuals
from locator.evaluate import score_run, summarise
from locator.fde import LocatorConfig
from locator.intervals import fit_error_model, overbound_error_model
from locator.observations import Observations
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.sources import RinexSource
from predisat.geodesy import LocalFrame, ecef_to_geodetic
from predisat.gnss.errormodel import IntervalModel
from predisat.track.map import TrackMap

REPO = Path(__file__).resolve().parents[1]
GEONET_0759_ECEF_M = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # GEONET
HALF_LENGTH_M = 2000.0
HEADINGS_DEG = (0.0, 45.0, 90.0, 135.0)


def virtual_track(station_ecef_m: np.ndarray, heading_deg: float) -> TrackMap:
    """A straight track through the station at its antenna height, chainage 2000 m there."""
    lat, lon, h = (float(v) for v in ecef_to_geodetic(station_ecef_m))
    frame = LocalFrame(lat, lon, h)
    d = np.linspace(-HALF_LENGTH_M, HALF_LENGTH_M, 41)
    hd = np.radians(heading_deg)
    enu = np.stack([d * np.sin(hd), d * np.cos(hd), np.zeros_like(d)], axis=-1)
    la, lo, hh = frame.to_geodetic(enu)
    return TrackMap.from_latlon(la, lo, hh, name=f"virtual {heading_deg:.0f} deg", tolerance_m=0.01)


def station(data: Path, name: str) -> tuple[RinexSource, np.ndarray]:
    obs = Observations.from_rinex(data / f"{name}0920.05o")
    model = RangeModel.from_rinex_nav(data / f"{name}0920.05n")
    src = RinexSource(model, obs, "G", odometer=np.zeros(len(obs.gps_s)))
    x = GEONET_0759_ECEF_M if name == "0759" else obs.header.approx_position_ecef_m
    # the header position is of the marker; the antenna reference point is delta_h above it
    return src, np.asarray(x, float)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--data", type=Path, default=REPO.parent / "shared" / "data" / "gnss" / "rtklib"
    )
    ap.add_argument("--out", type=Path, help="write each run's scored table here")
    ap.add_argument("--k-sigma", type=float, default=2.0, help="pair half width (source: 2)")
    ap.add_argument("--bound", choices=("overbound", "estimate"), default="overbound",
                    help="as `locator calibrate --bound` (default: overbound)")  # fmt: skip
    args = ap.parse_args(argv)
    stations = {n: station(args.data, n) for n in ("0759", "3040")}
    models = {}
    for name, (src, x) in stations.items():
        el, res = static_residuals(src, x)
        fit = fit_error_model(el, res)
        error = overbound_error_model(el, res, fit).model if args.bound == "overbound" else fit
        models[name] = IntervalModel(error, k_sigma=args.k_sigma)
        print(f"error model ({args.bound}) learned on {name}: a = {error.a_m:.2f} m, "
              f"b = {error.b_m:.2f} m (estimate {fit.a_m:.2f}, {fit.b_m:.2f})")  # fmt: skip
    rows = []
    for name, (src, x) in stations.items():
        other = "3040" if name == "0759" else "0759"
        for hd in HEADINGS_DEG:
            path = AntennaPath(virtual_track(x, hd), 0.0)
            cfg = RunConfig(
                LocatorConfig(model=models[other], budget=None),
                trust="none",
                start_uncertainty_m=50.0,
            )
            ep = run_locator(path, src, start_chainage_m=HALF_LENGTH_M, config=cfg)
            sc = score_run(ep, np.full(len(ep), HALF_LENGTH_M))
            if args.out:
                args.out.mkdir(parents=True, exist_ok=True)
                sc.to_csv(args.out / f"{name}_{hd:.0f}.csv", index=False)
            rows.append({"station": name, "heading_deg": hd, "model_from": other, **summarise(sc)})
    table = pd.DataFrame(rows)
    cols = ["station", "heading_deg", "epochs", "mode_three_pairs_share", "claim_share",
            "abs_error_median_m", "abs_error_p95_m", "wls_abs_error_median_m",
            "wls_abs_error_p95_m", "length_median_m", "length_p95_m", "hmi"]  # fmt: skip
    pd.set_option("display.width", 200)
    print(table[cols].round(3).to_string(index=False))
    both = summarise(
        pd.concat(
            [pd.read_csv(p) for p in sorted(args.out.glob("*.csv"))], ignore_index=True
        )
    ) if args.out else None  # fmt: skip
    if both:
        print("all runs:", {k: round(v, 3) for k, v in both.items()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
