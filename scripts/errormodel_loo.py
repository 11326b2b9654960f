"""Leave-one-receiver-out validation of the error-model overbound on every usable real receiver.

For each receiver of ``../shared/data/gnss`` that can be run (observations, orbits and a known
position) and each of its constellations, an error model is calibrated on the *other* receivers
of its class (``locator.errorfit.fit_systems``: each system apart) and the held-out receiver is
located with it on straight virtual tracks through its known position at four headings
(``locator_static.virtual_track``; no masks: open sky, active integrity, the odometer reads
zero). The receiver's chainage (2000 m) is the truth.

Receivers:

* geodetic stations: GEONET 0759 and 3040 (Trimble 5700, GPS C1, 2005-04-02, 1 h at 30 s);
  Ny-Alesund NYA1 (Trimble NetR9, GPS C1C, Galileo C1X, 2024-05-03, a day at 30 s; runs on
  every ``--nya-step``-th epoch, calibration on all); Copenhagen KMS3 (Septentrio PolaRx5, GPS
  C1C, Galileo C1C, 2022-06-08, 19 epochs at 30 s);
* phones (GSDC ``device_gnss.csv`` with its satellite positions and corrections,
  ``locator.devicegnss``; static at their ground truth): GSDC 2022 (a phone standing in a car,
  2021-04-29, 6 epochs at 1 s) and GSDC 2023 Pixel 7 Pro (2023-09-07, 5 epochs), GPS and
  Galileo E1 (C1C). A phone is held out against a *phone* model (the other phone: far too few
  samples, usually no model at all) and against the *geodetic* model of every station (another
  class: it does not apply, measured anyway).

Variants: ``new`` (one-sided tails against the 95 % Clopper-Pearson bound of their share in
independent samples, ``confidence=0.95``), ``legacy`` (the two-sided empirical share of
before), ``estimate`` (the least-squares fit, no bound: to show that the check can fail), each
at the ``--k`` values (``budget``: the integrity budget of ``locator run``, 1e-12 per epoch).
Whether the model *applies* to the held-out receiver (class, codes, samples) is reported; the
runs claim as if it did, so that the model's quality is measured on every receiver.

Prints one row per held-out receiver, system, model class and variant (epochs, applies, claim
share, HMI with the 95 % upper bound on the HMI rate per epoch, interval median / p95, Stanford
regions) and the totals; writes the table (``loo.csv``), a Stanford diagram per model and k, and
a sheet with one per held-out receiver (``stanford_receivers_*.png``) into ``--out``. Residuals
are cached in ``--cache`` (the NYA1 day takes about 80 s per system to compute).

Usage::

    .venv/bin/python scripts/errormodel_loo.py --out /tmp/loo [--data ../shared/data/gnss]
        [--cache /tmp/loo_cache] [--nya-step 4] [--variants new,legacy,estimate]
        [--k 2,3.89,budget] [--receivers NAME,...] [--map-doubt LAT VERT]
        [--track-offset ACROSS DOWN]

``--map-doubt`` is the runs' map doubt (default 1.5 1, as ``locator run``): on a track laid
through the antenna it is pure margin, which hides a model too tight for the receiver (the
estimates' 165 HMI of ``--map-doubt 0 0`` become 0); ``--track-offset`` lays the tracks beside
and below the antenna, so that the doubt is used up by a map error as large as it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from locator_static import GEONET_0759_ECEF_M, HALF_LENGTH_M, HEADINGS_DEG, virtual_track

from locator.corrections import RangeModel
from locator.devicegnss import (
    DeviceGnssSource,
    device_residuals,
    read_device_gnss,
    read_ground_truth,
)
from locator.errorfit import Residuals, fit_systems, model_file_parts, station_residuals
from locator.evaluate import score_run, summarise
from locator.fde import LocatorConfig
from locator.observations import Observations
from locator.plots import stanford_diagram
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath
from locator.sources import EpochSource, RinexSource
from predisat.geodesy import LocalFrame, ecef_to_geodetic
from predisat.gnss.errormodel import ErrorModelFile, IntervalModel, ReceiverProfile
from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH, IntegrityBudget

REPO = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Station:
    name: str
    obs: str
    nav: tuple[str, ...]
    systems: str
    ecef_m: tuple[float, float, float] | None = None  # None: the header position


NYA = "georust_rinex/NYA100NOR_S_20241240000_01D_"
STATIONS = (
    Station(
        "0759",
        "rtklib/07590920.05o",
        ("rtklib/07590920.05n",),
        "G",
        tuple(GEONET_0759_ECEF_M.tolist()),
    ),
    Station("3040", "rtklib/30400920.05o", ("rtklib/30400920.05n",), "G"),
    Station("NYA1", NYA + "30S_MO.crx.gz", tuple(f"{NYA}{s}N.rnx.gz" for s in "GEC"), "GE"),
    Station(
        "KMS3",
        "georust_rinex/KMS300DNK_R_20221591000_01H_30S_MO.crx",
        ("georust_rinex/KMS300DNK_R_20221591000_01H_MN.rnx.gz",),
        "GE",
    ),
)


@dataclass(frozen=True)
class Phone:
    name: str
    device_gnss: str  # GSDC device_gnss.csv: satellite positions and corrections per row
    truth: str
    systems: str


GLP = "gnss_lib_py/"
PHONES = (
    Phone("GSDC22", GLP + "google_decimeter_2022_device_gnss.csv",
          GLP + "google_decimeter_2022_ground_truth.csv", "GE"),
    Phone("Pixel7Pro", GLP + "gdc2023_pixel7pro_device_gnss.csv",
          GLP + "gdc2023_pixel7pro_ground_truth.csv", "GE"),
)  # fmt: skip
CLASS = {**{st.name: "geodetic" for st in STATIONS}, **{ph.name: "phone" for ph in PHONES}}


def clopper_pearson_upper(k: int, n: int, confidence: float = 0.95) -> float:
    """One-sided upper bound of a rate from ``k`` events in ``n`` independent trials."""
    from scipy.stats import beta

    return 1.0 if k >= n else float(beta.ppf(confidence, k + 1, n - k))


def every(obs: Observations, step: int) -> Observations:
    """Every ``step``-th epoch of ``obs``."""
    if step <= 1:
        return obs
    k = slice(None, None, step)
    return dataclasses.replace(
        obs, gps_s=obs.gps_s[k], values={c: v[k] for c, v in obs.values.items()},
        lli={c: v[k] for c, v in obs.lli.items()}, snr={c: v[k] for c, v in obs.snr.items()},
        epoch_flag=obs.epoch_flag[k], rx_clock_offset_s=obs.rx_clock_offset_s[k],
        epoch_line=obs.epoch_line[k],
    )  # fmt: skip


def residuals(st: Station, system: str, src: RinexSource, x: np.ndarray, cache: Path) -> Residuals:
    """The station's residuals of one system (cached: ``cache/<name>_<system>.npz``)."""
    f = cache / f"{st.name}_{system}.npz"
    if f.is_file():
        z = np.load(f, allow_pickle=False)
        p = json.loads(str(z["profile"]))
        prof = ReceiverProfile(p["receiver_type"], p["antenna_type"],
                               {k: tuple(v) for k, v in p["codes"].items()})  # fmt: skip
        return Residuals(z["el"], z["res"], tuple(z["sats"].tolist()), prof, st.obs)
    r = station_residuals(src, x)
    cache.mkdir(parents=True, exist_ok=True)
    prof_json = json.dumps({"receiver_type": r.profile.receiver_type,
                            "antenna_type": r.profile.antenna_type,
                            "codes": {k: list(v) for k, v in r.profile.codes.items()}})  # fmt: skip
    np.savez(f, el=r.el_deg, res=r.residual_m, sats=np.array(r.sats), profile=prof_json)
    return dataclasses.replace(r, source=st.obs)


def _models(
    train: list[Residuals], variant: str, cls: str
) -> tuple[ErrorModelFile, str] | str:
    """The error-model file learned on ``train`` by ``variant``, or why there is none."""
    conf = 0.95 if variant == "new" else None
    bound = "estimate" if variant == "estimate" else "overbound"
    try:
        fits = fit_systems(train, confidence=conf, bound=bound)
    except ValueError as exc:
        return str(exc)
    model, systems, app = model_file_parts(fits, train, k_sigma=2.0, receiver_class=cls,
                                           method=bound)  # fmt: skip
    return ErrorModelFile(model, systems, app), "+".join(sorted({Path(t.source).name[:12]
                                                                for t in train}))  # fmt: skip


def _track_point(x: np.ndarray, heading_deg: float, offset: tuple[float, float]) -> np.ndarray:
    """Where the virtual track at ``heading_deg`` passes: ``offset = (across, down)`` metres to
    the right of and below the antenna ``x`` (the map's error, which the run does not know)."""
    across, down = offset
    if across == 0.0 and down == 0.0:
        return x
    frame = LocalFrame(*(float(v) for v in ecef_to_geodetic(x)))
    hd = np.radians(heading_deg)
    return frame.enu_to_ecef([across * np.cos(hd), -across * np.sin(hd), -down])


def _runs(src: EpochSource, x: np.ndarray, model: IntervalModel, budget: bool,
          el_min: float, doubt: tuple[float, float] = (1.5, 1.0),
          offset: tuple[float, float] = (0.0, 0.0)) -> pd.DataFrame:  # fmt: skip
    """Scored runs on the virtual tracks through ``x`` (or ``offset`` beside and below it) at
    every heading, with the map doubt ``doubt`` (lateral, vertical; ``locator run``'s default)."""
    scored = []
    for hd in HEADINGS_DEG:
        path = AntennaPath(virtual_track(_track_point(x, hd, offset), hd), 0.0)
        loc = LocatorConfig(model=model, budget=IntegrityBudget(DEFAULT_RISK_PER_EPOCH)
                            if budget else None, map_doubt_lateral_m=doubt[0],
                            map_doubt_vertical_m=doubt[1])  # fmt: skip
        cfg = RunConfig(loc, trust="none", model_el_min_deg=el_min)
        ep = run_locator(path, src, start_chainage_m=HALF_LENGTH_M, config=cfg)
        scored.append(score_run(ep, np.full(len(ep), HALF_LENGTH_M)))
    return pd.concat(scored, ignore_index=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "gnss")
    ap.add_argument("--out", type=Path, required=True, help="table and Stanford diagrams")
    ap.add_argument("--cache", type=Path, help="residual cache (default: OUT/cache)")
    ap.add_argument(
        "--nya-step",
        type=int,
        default=4,
        help="NYA1 runs on every N-th epoch (default 4: 720 epochs at 120 s)",
    )
    ap.add_argument(
        "--variants", default="new,legacy,estimate", help="new, legacy, estimate (comma separated)"
    )
    ap.add_argument("--k", default="2,3.89",
                    help="k_sigma values, comma separated; 'budget' for the integrity budget of "
                    "`locator run` (1e-12 per epoch)")  # fmt: skip
    ap.add_argument("--receivers", help="held-out receivers only (comma separated names)")
    ap.add_argument("--map-doubt", nargs=2, type=float, default=(1.5, 1.0), metavar=("LAT", "VERT"),
                    help="the runs' map doubt, metres (default 1.5 1, as `locator run`; 0 0: "
                    "the pair intervals of the error model alone)")  # fmt: skip
    ap.add_argument("--track-offset", nargs=2, type=float, default=(0.0, 0.0),
                    metavar=("ACROSS", "DOWN"),
                    help="lay the virtual tracks this far right of and below the antenna, "
                    "metres (a map error; default 0 0: through the antenna)")  # fmt: skip
    args = ap.parse_args(argv)
    cache = args.cache or args.out / "cache"
    variants = [v.strip() for v in args.variants.split(",")]
    ks: list[float | str] = [v if v == "budget" else float(v) for v in args.k.split(",")]
    sources: dict[tuple[str, str], tuple[EpochSource, np.ndarray, int]] = {}
    data: dict[tuple[str, str], Residuals] = {}
    for st in STATIONS:
        obs = Observations.from_rinex(args.data / st.obs)
        nav = RangeModel.from_rinex_nav([args.data / n for n in st.nav])
        x = np.asarray(st.ecef_m if st.ecef_m else obs.header.approx_position_ecef_m, float)
        step = args.nya_step if st.name == "NYA1" else 1
        run_obs = every(obs, step)
        for s in st.systems:
            data[st.name, s] = residuals(st, s, RinexSource(nav, obs, s), x, cache)
            odo = np.zeros(len(run_obs.gps_s))
            sources[st.name, s] = (RinexSource(nav, run_obs, s, odometer=odo), x, step)
        print(f"{st.name}: {obs.header.receiver_type} / {obs.header.antenna_type}, "
              f"{len(obs.gps_s)} epochs, systems {st.systems}", flush=True)  # fmt: skip
    for ph in PHONES:
        dev = read_device_gnss(args.data / ph.device_gnss)
        truth = read_ground_truth(args.data / ph.truth)
        xt = truth.at(dev.gps_s)
        moved = float(np.max(np.linalg.norm(xt - xt[0], axis=-1)))
        if moved > 0.5:
            print(f"{ph.name}: the phone moves {moved:.1f} m during its epochs; a straight "
                  "virtual track through one point does not hold it: left out", flush=True)
            continue
        for s in ph.systems:
            phone = DeviceGnssSource(dev, s, odometer=np.zeros(len(dev.gps_s)))
            data[ph.name, s] = device_residuals(phone, truth)
            sources[ph.name, s] = (phone, xt[0], 1)
        print(f"{ph.name}: phone (GSDC device_gnss), {len(dev.gps_s)} epochs at 1 s, static "
              f"(truth moves {100 * moved:.1f} cm), systems {ph.systems}", flush=True)
    held_out = set(args.receivers.split(",")) if args.receivers else None
    rows: list[dict] = []
    scored_all: dict[tuple[str, str, float | str], list[pd.DataFrame]] = {}
    per_rx: dict[tuple[str, str, str, float | str], pd.DataFrame] = {}
    for (name, s), (src, x, _step) in sources.items():
        if held_out is not None and name not in held_out:
            continue
        cls = CLASS[name]
        held = data[name, s]
        profile = dataclasses.replace(held.profile, receiver_class=cls)
        # the class's own model (other receivers of the class) and, for a phone, the geodetic one
        trainings = [(cls, [d for (n2, s2), d in data.items()
                            if s2 == s and n2 != name and CLASS[n2] == cls])]  # fmt: skip
        if cls != "geodetic":
            trainings.append(("geodetic", [d for (n2, s2), d in data.items()
                                           if s2 == s and CLASS[n2] == "geodetic"]))  # fmt: skip
        for model_cls, train in trainings:
            if not train:
                print(f"{name} {s}: no other {model_cls} receiver of system {s}: no LOO model")
                continue
            names = "+".join(n2 for (n2, s2), d in data.items() if any(d is t for t in train))
            for variant in variants:
                got = _models(train, variant, model_cls)
                if isinstance(got, str):
                    print(f"{name} {s} {variant} ({model_cls} model): none ({got})", flush=True)
                    rows.append({"station": name, "class": cls, "system": s, "model": model_cls,
                                 "variant": variant, "trained_on": names,
                                 "applies": f"no model: {got}"})  # fmt: skip
                    continue
                mf, _ = got
                why = mf.mismatches(profile)
                sm = mf.systems.get(s)
                if sm is None:
                    continue
                el_min = mf.applicability.el_min_deg if mf.applicability else 5.0
                for k in ks:
                    model = IntervalModel(sm.error, 2.0 if k == "budget" else float(k))
                    sc = _runs(src, x, model, k == "budget", el_min,
                               tuple(args.map_doubt), tuple(args.track_offset))
                    key = f"{model_cls}:{variant}"
                    scored_all.setdefault((cls, key, k), []).append(sc)
                    per_rx[name, s, key, k] = sc
                    sm_ = summarise(sc)
                    n_ep = int(sm_["epochs"]) // len(HEADINGS_DEG)
                    hmi = int(sm_["hmi"])
                    rows.append({
                        "station": name, "class": cls, "system": s, "model": model_cls,
                        "variant": variant, "k": k, "trained_on": names, "a_m": sm.error.a_m,
                        "b_m": sm.error.b_m, "n_indep": sm.n_independent,
                        "tail_p": sm.tail_probability, "applies": "yes" if not why else
                        "; ".join(why), "epochs": int(sm_["epochs"]),
                        "claim_share": sm_["claim_share"], "hmi": hmi,
                        "hmi_rate_up95": clopper_pearson_upper(hmi, n_ep),
                        "len_median_m": sm_["length_median_m"], "len_p95_m": sm_["length_p95_m"],
                        **{c: int(v) for c, v in sm_.items() if c.startswith("stanford_")},
                    })  # fmt: skip
                    r = rows[-1]
                    print(f"{name} {s} {model_cls} {variant} k={k}: a {r['a_m']:.2f} b "
                          f"{r['b_m']:.2f} m, {r['n_indep']} indep., tail {r['tail_p']:.2g}; "
                          f"{r['epochs']} epochs, claim {100 * r['claim_share']:.1f} %, HMI "
                          f"{hmi} (rate <= {r['hmi_rate_up95']:.2g} at 95 %, {n_ep} epochs), "
                          f"length {r['len_median_m']:.1f} / {r['len_p95_m']:.1f} m; applies: "
                          f"{r['applies']}", flush=True)  # fmt: skip
    table = pd.DataFrame(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "loo.csv", index=False)
    pd.set_option("display.width", 250)
    cols = ["station", "system", "model", "variant", "k", "a_m", "b_m", "n_indep", "tail_p",
            "epochs", "claim_share", "hmi", "hmi_rate_up95", "len_median_m", "len_p95_m"]
    print(table[[c for c in cols if c in table]].round(3).to_string(index=False))
    print("totals per held-out class, model class:variant and k:")
    for (held_cls, key, k), parts in scored_all.items():
        sc = pd.concat(parts, ignore_index=True)
        t = summarise(sc)
        n_ep = int(t["epochs"]) // len(HEADINGS_DEG)
        print(
            f"  {held_cls} held out, {key} k={k}: {int(t['epochs'])} epochs ({n_ep} per heading), "
            f"HMI rate <= {clopper_pearson_upper(int(t['hmi']), n_ep):.2g} at 95 %, claim "
            f"{100 * t['claim_share']:.1f} "
            f"%, HMI {int(t['hmi'])}, interval median {t['length_median_m']:.1f} m, p95 "
            f"{t['length_p95_m']:.1f} m; Stanford "
            + ", ".join(f"{c[9:]} {int(v)}" for c, v in t.items() if c.startswith("stanford_"))
        )
        cls_, variant = key.split(":")
        what = {"new": "new overbound", "legacy": "two-sided overbound",
                "estimate": "estimate (no bound)"}.get(variant, variant)  # fmt: skip
        fig = stanford_diagram(sc, f"{held_cls}s held out, {cls_} model, {what}, k = {k}")
        fig.savefig(args.out / f"stanford_{held_cls}_{cls_}_{variant}_k{k}.png", dpi=100)
    _per_receiver_sheets(per_rx, args.out)
    return 0


def _per_receiver_sheets(
    per_rx: dict[tuple[str, str, str, float | str], pd.DataFrame], out: Path
) -> None:
    """One sheet per model and k: a Stanford diagram per held-out receiver and system."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    keys = sorted({(key, str(k)) for (_n, _s, key, k) in per_rx})
    for key, k in keys:
        panels = [(n, s, sc) for (n, s, key2, k2), sc in per_rx.items()
                  if key2 == key and str(k2) == k]  # fmt: skip
        ncol = min(4, len(panels))
        nrow = -(-len(panels) // ncol)
        sheet = Figure(figsize=(4 * ncol, 3.6 * nrow), layout="constrained")
        axes = np.atleast_1d(sheet.subplots(nrow, ncol)).ravel()
        for ax in axes:
            ax.axis("off")
        for ax, (n, s, sc) in zip(axes, panels, strict=False):
            fig = stanford_diagram(sc, f"{n} {s} ({key}, k = {k})")
            canvas = FigureCanvasAgg(fig)
            canvas.draw()
            ax.imshow(np.asarray(canvas.buffer_rgba()))
        sheet.savefig(out / f"stanford_receivers_{key.replace(':', '_')}_k{k}.png", dpi=90)


if __name__ == "__main__":
    sys.exit(main())
