"""The job behind ``locator balises``: locate a simulated run with odometry, capture its balises.

:func:`locate_with_odometry` simulates the odometer along the run, runs the epoch loop with its
bounds (fusion, :mod:`locator.odometry.fusion`) and returns the epochs with the truth;
:func:`capture_table` captures a balise list under several capture configurations and scores
every passage; :func:`balises_to_folder` does both and writes ``epochs.parquet``,
``captures.csv``, ``summary.json`` and ``captures.png``.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from numpy.typing import NDArray

from locator.balises.balisefile import BaliseList
from locator.balises.capture import CaptureConfig, capture_balises, score_captures
from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.odometer import OdometerConfig, OdometerLog
from locator.odometry.simulated import SimOdometer, odometer_along_run, odometer_from_log
from locator.run import RunConfig, claim_label, run_locator
from locator.sathia import AntennaPath
from locator.sim.simfile import SimRun
from locator.sources import SimSource
from predisat import __version__
from predisat.atomic import check_writable, staged_folder
from predisat.clock import utc_stamp
from predisat.gnss.timescale import gps_s_to_utc_datetime64
from predisat.jsontypes import strict_json_text
from predisat.masks.maskset import MaskSet
from predisat.track import TrackMap

__all__ = [
    "ODOMETERS",
    "LocatedRun",
    "balises_to_folder",
    "capture_summary",
    "capture_table",
    "locate_with_odometry",
    "located_epochs",
    "safe_front_check",
    "scenery_tunnel_epochs",
]

# fused intervals not to be used: an odometry conflict, or one not yet cleared (locator.run)
_DOUBTFUL = ("conflict", "suspect")

ODOMETERS = {
    "trailer-radar": OdometerConfig.trailer_axle_with_radar,
    "motor-radar": lambda: OdometerConfig.motor_axle(radar=True),
    "motor": lambda: OdometerConfig.motor_axle(radar=False),
    "ideal": OdometerConfig.ideal,
}


@dataclass(frozen=True, eq=False)
class LocatedRun:
    """A run located with odometry.

    Attributes
    ----------
    epochs : pandas.DataFrame
        :func:`locator.run.run_locator`'s table plus ``truth_m`` (true antenna chainage) and
        ``odo_speed_mps`` (odometer speed at the epoch).
    odometer : SimOdometer
    accuracy : OdometerAccuracy
        The bounds the run used.
    """

    epochs: pd.DataFrame
    odometer: SimOdometer
    accuracy: OdometerAccuracy


def locate_with_odometry(
    sim: SimRun,
    path: AntennaPath,
    config: RunConfig,
    *,
    masks: MaskSet | None = None,
    odometer: OdometerConfig | None = None,
    seed: int = 0,
    accuracy: OdometerAccuracy | None = None,
    log: OdometerLog | None = None,
    start_error_m: float = 0.0,
    progress: Callable[[int], object] | None = None,
    constellation: str = "all",
) -> LocatedRun:
    """Simulate the odometer along ``sim`` (or take ``log``) and run the locator with its bounds.

    ``start_error_m`` is the error of the position the run starts from (the train's stored
    position at start of mission): the locator starts at the true chainage plus this, within
    ``config.start_uncertainty_m``; 0 starts it at the truth, which flatters every fix before the
    first satellite claim.

    ``accuracy`` defaults to the configured odometer's bounds
    (:meth:`OdometerAccuracy.from_config`); pass :meth:`OdometerAccuracy.subset041` to use the
    ETCS requirement instead (the safe choice for a recorded log of unknown odometer).
    ``progress`` is called with the number of epochs done since its last call.
    """
    if not abs(start_error_m) <= config.start_uncertainty_m:
        raise ValueError(
            f"start_error_m ({start_error_m:g} m) must lie within the run's "
            f"start_uncertainty_m ({config.start_uncertainty_m:g} m): the locator's first "
            "interval would not hold the train"
        )
    odo_cfg = odometer or OdometerConfig()
    if log is not None:
        so = odometer_from_log(sim, log, odo_cfg.cycle_s)
    else:
        so = odometer_along_run(sim, odo_cfg, seed)
    acc = accuracy or OdometerAccuracy.from_config(odo_cfg)
    cfg = replace(config, odometer=acc)
    ep = run_locator(
        path,
        SimSource(sim, constellation=constellation, odometer=so.epoch_odo_m,
                  odometer_extra=so.epoch_extra_m),
        start_chainage_m=float(np.clip(sim.chainage_m[0] + start_error_m, 0.0, path.length_m)),
        config=cfg,
        masks=masks,
        progress=progress,
    )
    ep["truth_m"] = np.asarray(sim.chainage_m, float)
    ep["odo_speed_mps"] = so.log.speed_at(ep["gps_s"].to_numpy(float))
    return LocatedRun(ep, so, acc)


def located_epochs(epochs: pd.DataFrame) -> NDArray:
    """Epochs whose fused interval may time a balise passage, bool, shape (n,): a satellite
    claim has confirmed the run's position, and no odometry conflict (the epoch's own, or one
    not cleared since: fusion ``conflict``, ``suspect``) makes the interval doubtful (a review:
    a stuck direction channel's conflicting epochs captured a balise 150-300 m away)."""
    claimed = np.logical_or.accumulate(epochs["claim"].to_numpy(bool))
    return claimed & ~np.isin(epochs["fusion"].to_numpy(object), _DOUBTFUL)


def capture_table(
    run: LocatedRun,
    balises: BaliseList,
    configs: Mapping[str, CaptureConfig],
    *,
    margin_m: float = 30.0,
) -> pd.DataFrame:
    """Capture and score every balise under each configuration.

    A fix captures only once a satellite claim has confirmed the run's position (``located``
    of :func:`capture_balises`), and the passage is timed back along the odometer (also at the
    first valid fix after a voided epoch, with the run's odometer bounds).

    Returns one row per (configuration, balise): :func:`score_captures` columns plus
    ``config`` and ``capture_radius_m``. A capture is false when the true position at the
    reported passage time is further from the balise than the configuration's capture radius.
    """
    ep = run.epochs
    t = ep["gps_s"].to_numpy(float)
    o = run.odometer.orientation
    located = located_epochs(ep)
    out = []
    for name, cc in configs.items():
        cap = capture_balises(
            t, ep["fused_chainage_m"].to_numpy(float), ep["fused_lo_m"].to_numpy(float),
            ep["fused_hi_m"].to_numpy(float), balises, cc, orientation=o,
            speed_mps=ep["odo_speed_mps"].to_numpy(float), odo_m=run.odometer.epoch_odo_m,
            located=located, odo_accuracy=run.accuracy, odo_extra_m=run.odometer.epoch_extra_m,
        )  # fmt: skip
        sc = score_captures(cap, run.odometer.truth_t_s, run.odometer.truth_chainage_m,
                            orientation=o, false_tolerance_m=cc.capture_radius_m,
                            margin_m=margin_m)  # fmt: skip
        sc.insert(0, "config", name)
        sc.insert(1, "capture_radius_m", cc.capture_radius_m)
        out.append(sc)
    return pd.concat(out, ignore_index=True)


def capture_summary(scored: pd.DataFrame) -> pd.DataFrame:
    """Per configuration: passages, balises not reached (not passed by the run, with the
    scoring margin), capture rate, false and hazardous captures, the telegrams' location
    accuracy (p95), timing error, delay."""
    rows = []
    for name, g in scored.groupby("config", sort=False):
        p = g[g["passed"]]
        cap = p[p["captured"]]
        te = np.abs(cap["timing_error_s"].to_numpy(float))
        dl = cap["delay_s"].to_numpy(float)
        rows.append({
            "config": name, "capture_radius_m": float(g["capture_radius_m"].iloc[0]),
            "passages": len(p), "captured": len(cap),
            "capture_rate": len(cap) / len(p) if len(p) else np.nan,
            "arm_share": float((cap["zone"] == "arm").mean()) if len(cap) else np.nan,
            "not_reached": int((~g["passed"]).sum()),
            "false": int(g["false"].sum()), "hazardous": int(g["hazardous"].sum()),
            "q_locacc_p95_m": float(np.quantile(cap["q_locacc_m"], 0.95))
            if len(cap) else np.nan,
            "timing_abs_median_s": float(np.median(te)) if len(te) else np.nan,
            "timing_abs_p95_s": float(np.quantile(te, 0.95)) if len(te) else np.nan,
            "delay_median_s": float(np.median(dl)) if len(dl) else np.nan,
            "delay_p95_s": float(np.quantile(dl, 0.95)) if len(dl) else np.nan,
            "position_abs_p95_m": float(np.quantile(np.abs(cap["position_error_m"]), 0.95))
            if len(cap) else np.nan,
            "miss_reasons": _miss_reasons(p[~p["captured"]]),
        })  # fmt: skip
    return pd.DataFrame(rows)


def _miss_reasons(missed: pd.DataFrame) -> str:
    """The missed passages counted by reason (``miss_reason`` without its value), most first:
    ``"stated accuracy over Q_LOCACC: 20; fixes jumped over the zones: 2"``; "" without."""
    if not len(missed) or "miss_reason" not in missed.columns:
        return ""
    why = missed["miss_reason"].fillna("").astype(str).str.replace(r" \(.*\)$", "", regex=True)
    counts = why.value_counts()
    return "; ".join(f"{k or 'unknown'}: {int(n)}" for k, n in counts.items())


def safe_front_check(
    run: LocatedRun, *, antenna_to_front_m: float = 5.0, max_length_m: float = 100.0
) -> dict[str, float]:
    """Safe-front integrity and availability of a located run.

    The front end is ``antenna_to_front_m`` ahead of the antenna in the direction of travel;
    its safe bounds are the fused interval moved by the same amount (the offset is exact), so
    the true front lies in ``[min safe, max safe]`` exactly when the true antenna lies in the
    fused interval.

    Epochs of an odometry conflict, and after one until agreeing fixes clear it (fusion
    ``conflict`` and ``suspect``, flagged), give no safe front: they are counted apart.

    Returns
    -------
    dict
        ``epochs``, ``front_outside`` (count, epochs giving a safe front),
        ``front_outside_flagged`` (count, conflict and suspect epochs: said, not hazardous),
        ``gnss_claim_share`` (satellite claims), ``fused_share`` (a safe front whose fused
        interval is at most ``max_length_m`` long), ``odometry_only`` (share of epochs
        carried by the odometry), ``suspect`` (share of suspect epochs), ``conflicts``
        (alarms, count).
    """
    ep = run.epochs
    o = run.odometer.orientation
    truth_front = ep["truth_m"] + o * antenna_to_front_m
    lo = ep["fused_lo_m"] + o * antenna_to_front_m
    hi = ep["fused_hi_m"] + o * antenna_to_front_m
    outside = ~((lo <= truth_front + 1e-9) & (truth_front <= hi + 1e-9))
    doubtful = ep["fusion"].isin(_DOUBTFUL)
    length = ep["fused_hi_m"] - ep["fused_lo_m"]
    return {
        "epochs": float(len(ep)),
        "front_outside": float((outside & ~doubtful).sum()),
        "front_outside_flagged": float((outside & doubtful).sum()),
        "gnss_claim_share": float(ep["claim"].mean()),
        "fused_share": float(((length <= max_length_m) & ~doubtful).mean()),
        "odometry_only": float((ep["fusion"] == "odometry").mean()),
        "suspect": float((ep["fusion"] == "suspect").mean()),
        "conflicts": float((ep["fusion"] == "conflict").sum()),
    }


def scenery_tunnel_epochs(sim: SimRun) -> NDArray:
    """Epochs of a simulated run inside a tunnel of its world's scenery, bool, shape (n,).

    A world's tunnels are stretches of its recipe (every ``WorldSpec.mixed`` world has one),
    not tunnels of its track map, which holds only those tagged in the source (OpenStreetMap):
    shading ``track.in_tunnel`` alone left a user trial's 200 m tunnel unshaded under the
    figure's "grey: tunnel". Read on the simulation's own chainage (before ``sim_on_track``).
    """
    c = np.asarray(sim.chainage_m, float)
    spec = sim.meta.get("world_spec") or {}
    inside = np.zeros(c.shape, bool)
    for st in spec.get("stretches", []) if isinstance(spec, dict) else []:
        if st.get("kind") == "tunnel":
            inside |= (c >= float(st["start_m"])) & (c <= float(st["end_m"]))
    return inside


def _figure(run: LocatedRun, scored: pd.DataFrame, title: str, track: TrackMap,
            tunnel_epochs: NDArray | None = None) -> Figure:
    # a Figure of its own, no pyplot state (as the report's figures)
    ep = run.epochs
    t = ep["gps_s"].to_numpy(float)
    t = t - t[0]
    truth = ep["truth_m"].to_numpy(float)
    fig = Figure(figsize=(10, 8))
    # misses on a strip of their own: on the timing axis they fell among real timing errors
    # (-514 to +254 ms in a user trial's run)
    ax = fig.subplots(3, 1, sharex=True, height_ratios=[3, 3, 1])
    tunnel = np.asarray(track.in_tunnel(truth), bool)
    if tunnel_epochs is not None:
        tunnel = tunnel | np.asarray(tunnel_epochs, bool)
    for a in ax:  # where the satellites cannot help: the tunnels, shaded
        a.fill_between(t, 0, 1, where=tunnel, transform=a.get_xaxis_transform(),
                       color="0.85", step="mid", lw=0)  # fmt: skip
    ax[0].fill_between(t, ep["fused_lo_m"] - truth, ep["fused_hi_m"] - truth, step="mid",
                       color="tab:blue", alpha=0.3, label="fused interval - truth")  # fmt: skip
    claim = ep["claim"].to_numpy(bool)
    ax[0].plot(t[claim], (ep["fused_chainage_m"] - truth)[claim], ".", ms=2, color="tab:blue",
               label="estimate - truth (satellite claim)")  # fmt: skip
    ax[0].plot(t[~claim], (ep["fused_chainage_m"] - truth)[~claim], ".", ms=2, color="tab:red",
               label="estimate - truth (odometry only)")  # fmt: skip
    ax[0].axhline(0.0, color="k", lw=0.5)
    ax[0].set_ylabel("m")
    ax[0].legend(loc="upper left", fontsize=8)
    # a long title (track, integrity, claims) wrapped, not cut at the figure's edges
    ax[0].set_title(textwrap.fill(title, 110), fontsize=9)
    t0 = float(ep["gps_s"].iloc[0])
    markers = "osD^v<>p"
    for j, (name, g) in enumerate(scored.groupby("config", sort=False)):
        g = g[g["passed"]]
        c = g["captured"].to_numpy(bool)
        colour = f"C{j % 10}"
        # hollow, one marker a configuration: radii that capture alike stay visible
        ax[1].plot(g["t_true_s"][c] - t0, 1e3 * g["timing_error_s"][c], markers[j % 8],
                   ms=4 + 1.5 * j, mfc="none", color=colour,
                   label=f"{name}: timing error")  # fmt: skip
        # the misses of each configuration on a row of their own
        ax[2].plot(g["t_true_s"][~c] - t0, np.full((~c).sum(), j), "x", color=colour, ms=5,
                   label=f"{name}: missed ({(~c).sum()})")  # fmt: skip
    names = list(dict.fromkeys(scored["config"]))
    ax[1].set_ylabel("reported - true passage (ms)")
    ax[1].legend(loc="best", fontsize=7, ncol=2)  # not over the points (a user trial)
    ax[2].set_yticks(range(len(names)), names, fontsize=7)
    ax[2].set_ylim(-0.5, len(names) - 0.5)
    ax[2].set_title("missed passages", fontsize=8)
    ax[2].set_xlabel("time since start (s); grey: tunnel" if tunnel.any()
                     else "time since start (s); no tunnel in the run")  # fmt: skip
    ax[2].legend(loc="upper left", fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def balises_to_folder(
    sim: SimRun,
    path: AntennaPath,
    balises: BaliseList,
    out: str | Path,
    *,
    config: RunConfig,
    masks: MaskSet | None = None,
    odometer: OdometerConfig | None = None,
    captures: Mapping[str, CaptureConfig] | None = None,
    seed: int = 0,
    meta: Mapping[str, object] | None = None,
    constellation: str = "all",
    log: OdometerLog | None = None,
    accuracy: OdometerAccuracy | None = None,
    progress: Callable[[int], object] | None = None,
    tunnel_epochs: NDArray | None = None,
    start_error_m: float = 0.0,
) -> tuple[pd.DataFrame, Path]:
    """Locate a simulated run with odometry, capture the balises, write the folder.

    ``log`` replaces the simulated odometer by a recorded one (``accuracy`` then should be its
    bounds, e.g. :meth:`OdometerAccuracy.subset041`). Writes ``epochs.parquet`` (the run table
    with the truth), ``captures.csv`` (one row per configuration and balise, with timing
    errors and the list's ``q_reference``; ``safety_claim`` is False for every capture under
    a forced error model or a fixed ``k``: :attr:`locator.run.RunConfig.makes_safety_claims`),
    ``summary.json`` and ``captures.png``.

    ``progress`` is called with the number of epochs located since its last call;
    ``start_error_m`` as in :func:`locate_with_odometry` (0: the run starts at the truth).

    Returns
    -------
    summary : pandas.DataFrame
        :func:`capture_summary` of the captures, plus ``epochs`` and ``front_outside`` of
        :func:`safe_front_check` (one run: the same in every row).
    folder : Path
    """
    folder = Path(out)
    check_writable(folder)  # before the epochs, not after them
    odo_cfg = odometer or OdometerConfig()
    caps = dict(captures or {"r12": CaptureConfig.gaderos(12.0)})
    run = locate_with_odometry(sim, path, config, masks=masks, odometer=odo_cfg, seed=seed,
                               log=log, accuracy=accuracy, progress=progress,
                               constellation=constellation,
                               start_error_m=start_error_m)  # fmt: skip
    scored = capture_table(run, balises, caps)
    # captures under a forced error model rest on intervals that are no safety claim: the
    # table must say so row by row (it is read without summary.json)
    scored["safety_claim"] = scored["captured"].astype(bool) & config.makes_safety_claims
    summary = capture_summary(scored)
    front = safe_front_check(run)
    summary["epochs"] = int(front["epochs"])
    summary["front_outside"] = int(front["front_outside"])
    # written together and published with summary.json last: in place, a full disk left a
    # new table beside an earlier run's summary (predisat.atomic.staged_folder)
    with staged_folder(folder, last=("summary.json",)) as stage:
        run.epochs.to_parquet(stage / "epochs.parquet")
        # the times in UTC beside the GPS seconds: a signalling engineer reads the file alone
        utc = gps_s_to_utc_datetime64(scored["t_pass_s"].to_numpy(float))
        scored["t_pass_utc"] = np.where(np.isnat(utc), "", np.datetime_as_string(utc, unit="ms"))
        # 17 significant digits: GPS seconds (1.3e9) keep their milliseconds, floats round-trip
        scored.to_csv(stage / "captures.csv", index=False, float_format="%.17g")
        budget = config.locator.budget
        info = {
            "software": f"predisat {__version__}", "created_utc": utc_stamp(),
            "track": path.track.name,
            "time_scale": "t_*_s columns: GPS seconds (GPST, continuous since 1980-01-06 "
                          "00:00:00; UTC = GPST - leap seconds); t_pass_utc: the same in UTC",
            "balises": balises.source, "n_balises": len(balises),
            # a recorded log replaces the simulated odometer: its settings would mislead
            "odometer": ({"log": log.source} if log is not None else asdict(odo_cfg)),
            "accuracy": asdict(run.accuracy),
            "constellation": constellation, "start_error_m": start_error_m,
            "integrity": (budget.label() if budget is not None
                          else f"k = {config.locator.model.k_sigma:g} for every pair interval"),
            "claims": claim_label(config.error_model_caveat, config.locator.fixed_k_sigma),
            "captures": {k: asdict(v) for k, v in caps.items()},
            "summary": summary.to_dict(orient="records"),
            "safe_front": front, **dict(meta or {}),
        }  # fmt: skip
        # strict JSON (NaN -> null: a balise never reached has no timing), as jq and browsers read
        (stage / "summary.json").write_text(strict_json_text(info))
        fig = _figure(run, scored, f"{path.track.name}: virtual balises on the fused interval "
                      f"({info['integrity']}; {info['claims']})", path.track,
                      tunnel_epochs)
        fig.savefig(stage / "captures.png", dpi=100)
    return summary, folder
