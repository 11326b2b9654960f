"""Frozen inputs and outputs of the 1-D locator, to pin its speed-ups bit for bit.

The inputs (``tests/data/locator_regression/``) are two simulated runs replayed from stored
epochs (the demo world's stop-and-go of ``scripts/bench_locator.py`` and a campaign job in the
Nice-Digne canyon world of ``scripts/locator_campaign.py``, many NLOS signals and exclusions)
with their worlds' true masks, the in-repo 10 epochs of GEONET 0759 on virtual tracks, and
random single epochs for :func:`locator.sathia.solve_pairs` (straight and curved paths, windows
at the track ends, faulty ranges). The reference outputs were computed by the locator as it was
on 2026-12-04 (commit 1403519), before its pair work was compiled; ``python -m
tests.regression.locator_cases`` wrote them and must not be run again unless a change of
results is intended (and then say so in the commit).

These pin an optimisation, not correctness: correctness is tested against independent ground
truth in ``tests/locator``.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from locator.fde import LocatorConfig
from locator.run import RunConfig, run_locator
from locator.sathia import AntennaPath, solve_pairs
from locator.sources import EpochData
from predisat.gnss.errormodel import ErrorModel, IntervalModel
from predisat.jsontypes import JsonDict
from predisat.masks.maskset import MaskSet
from predisat.track.map import TrackMap, demo_track
from tests.locator._scene import arc_path, random_sky, ranges, sky, straight_path

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "locator_regression"
GNSS_OBS = REPO / "tests" / "data" / "gnss_obs"
SIM_CASES = ("demo", "canyon")
#: columns of run_locator's output that are compared (all but the timing ``solve_ms``)
COMPARED = (
    "epoch", "gps_s", "pred_lo_m", "pred_hi_m", "n_received", "n_trusted", "n_used",
    "chainage_m", "lo_m", "hi_m", "length_m", "mode", "integrity", "flags", "flag_names",
    "claim", "claim_fix", "wls_chainage_m", "wls_sigma_m", "heading_status",
    "heading_diff_deg", "used", "excluded", "fused_lo_m", "fused_hi_m", "fused_chainage_m",
    "fusion", "odo_since_anchor_m", "iono_uncorrected",
)  # fmt: skip
#: the error model the campaign learned (its cache's ``error_model.json``, 2026-12-04)
CAMPAIGN_ERROR = ErrorModel(a_m=2.119019725933748, b_m=1.9937601951764212)


@dataclass(frozen=True, eq=False)
class ReplaySource:
    """Stored epochs (an :class:`locator.sources.EpochSource`): a simulated run as the locator
    saw it, whatever position it asks about (a simulation's ranges do not depend on it)."""

    gps: NDArray
    odometer: NDArray
    sats: tuple[str, ...]
    sat_ecef_m: NDArray  # (n_epoch, n_sat, 3), NaN where not received
    pseudorange_m: NDArray  # (n_epoch, n_sat)

    @property
    def gps_s(self) -> NDArray:
        return self.gps

    @property
    def odometer_m(self) -> NDArray:
        return self.odometer

    def observe(self, epoch: int, rx_ecef_m: NDArray) -> EpochData:
        j = np.flatnonzero(np.isfinite(self.pseudorange_m[epoch]))
        return EpochData(
            tuple(self.sats[k] for k in j),
            np.array(self.sat_ecef_m[epoch, j]),
            np.array(self.pseudorange_m[epoch, j]),
            {},
        )

    def describe(self) -> JsonDict:
        return {"source": "replay"}


@dataclass(frozen=True)
class SimCase:
    path: AntennaPath
    source: ReplaySource
    start_m: float
    masks: MaskSet


def load_sim_case(name: str) -> SimCase:
    """A stored simulated run and its masks (``tests/data/locator_regression/<name>.npz``)."""
    z = np.load(DATA / f"{name}.npz")
    mm = z["sat_mm"].astype(float)
    sat = np.where(mm == _NAN_MM, np.nan, mm / 1000.0)
    rho_mm = z["rho_mm"].astype(float)
    rho = np.where(rho_mm == _NAN_MM, np.nan, rho_mm / 1000.0)
    src = ReplaySource(z["gps_s"], z["odometer_m"], tuple(str(s) for s in z["sats"]), sat, rho)
    masks = MaskSet.from_arrays(
        z["mask_chainage_m"], z["mask_lat_deg"], z["mask_lon_deg"], z["mask_h_m"],
        z["mask_heading_deg"], z["mask_el_ddeg"] / 10.0, margin_deg=1.0,
    )  # fmt: skip
    return SimCase(AntennaPath(demo_track(), 4.0), src, float(z["start_m"]), masks)


def sim_configs() -> dict[str, tuple[RunConfig, bool]]:
    """The campaign's rules (and passive integrity): name -> (config, uses the masks)."""
    # every width fixed (budget=None): the references were written with one k per rule;
    # "default" is LocatorConfig()'s of then, k = 2 (the default is now the budget)
    k389 = LocatorConfig(model=IntervalModel.for_risk(1e-4, CAMPAIGN_ERROR), budget=None)
    k2 = LocatorConfig(model=IntervalModel(CAMPAIGN_ERROR, k_sigma=2.0), budget=None)
    k2_default = LocatorConfig(budget=None)
    return {
        "masks": (RunConfig(k389, trust="masks", trust_stretches=1), True),
        "none": (RunConfig(k389, trust="none"), False),
        "cutoff15": (RunConfig(k389, trust="cutoff", cutoff_deg=15.0), False),
        "masks_k2": (RunConfig(k2, trust="masks", trust_stretches=1), True),
        "passive_none": (RunConfig(k2_default, integrity="passive", trust="none"), False),
        "default_none": (RunConfig(k2_default, trust="none"), False),
    }


def as_the_reference(cfg: RunConfig) -> RunConfig:
    """``cfg`` without what came after the reference (2026-12-06): the suspect latch after an
    odometry conflict (the conflict alone flagged; so whether a blunt fix's conflict begins it
    does not matter), its recovery on the motion bound, the sky
    check of epochs without a claim, the start check, the track-alias and off-track checks,
    and the map doubt in the pair bands
    (zero: the source's pairs). All are tested in ``tests/locator``."""
    loc = dataclasses.replace(cfg.locator, map_doubt_lateral_m=0.0, map_doubt_vertical_m=0.0)
    return dataclasses.replace(cfg, odometry_reconfirm=0, odometry_recover_s=None,
                               sky_check_m=None, start_check_m=None, alias_m=None,
                               off_track_k_sigma=None,
                               locator=loc)  # fmt: skip


def run_sim_case(case: SimCase, config: str) -> pd.DataFrame:
    cfg, with_masks = sim_configs()[config]
    cfg = as_the_reference(cfg)
    ep = run_locator(case.path, case.source, start_chainage_m=case.start_m, config=cfg,
                     masks=case.masks if with_masks else None)  # fmt: skip
    return ep.loc[:, list(COMPARED)]


def virtual_track(station_ecef_m: NDArray, heading_deg: float) -> TrackMap:
    """A straight track through the station, chainage 2000 m there (``scripts/locator_static``)."""
    from predisat.geodesy import LocalFrame, ecef_to_geodetic

    lat, lon, h = (float(v) for v in ecef_to_geodetic(station_ecef_m))
    frame = LocalFrame(lat, lon, h)
    d = np.linspace(-2000.0, 2000.0, 41)
    hd = np.radians(heading_deg)
    enu = np.stack([d * np.sin(hd), d * np.cos(hd), np.zeros_like(d)], axis=-1)
    la, lo, hh = frame.to_geodetic(enu)
    return TrackMap.from_latlon(la, lo, hh, name=f"virtual {heading_deg:.0f} deg", tolerance_m=0.01)


GEONET_0759_ECEF_M = np.array([-3976219.5082, 3382372.5671, 3652512.9849])
REAL_HEADINGS_DEG = (0.0, 45.0, 90.0, 135.0)


def run_real_case(heading_deg: float, integrity: str) -> pd.DataFrame:
    """The in-repo 10 epochs of GEONET 0759 on a virtual straight track (GPS, corrections)."""
    from locator.corrections import RangeModel
    from locator.observations import Observations
    from locator.sources import RinexSource

    obs = Observations.from_rinex(GNSS_OBS / "07590920_10ep.05o")
    model = RangeModel.from_rinex_nav(GNSS_OBS / "07590920_0000_0200.05n")
    src = RinexSource(model, obs, "G", odometer=np.zeros(len(obs.gps_s)))
    path = AntennaPath(virtual_track(GEONET_0759_ECEF_M, heading_deg), 0.0)
    cfg = as_the_reference(RunConfig(LocatorConfig(budget=None), integrity=integrity,
                                      trust="none"))  # k = 2  # fmt: skip
    ep = run_locator(path, src, start_chainage_m=2000.0, config=cfg)
    return ep.loc[:, list(COMPARED)]


PAIR_FIELDS = ("i", "j", "k_m", "sigma_k_m", "root_m", "lo_m", "hi_m", "slope", "n_roots",
               "misfit_m", "status")  # fmt: skip
N_PAIR_CASES = 40


@cache
def _pair_paths() -> tuple[AntennaPath, ...]:
    return (straight_path(60.0), arc_path(300.0, 120.0, lead_m=200.0), arc_path(80.0, 300.0))


def pair_case_inputs(
    case: int,
) -> tuple[AntennaPath, float, NDArray, NDArray, NDArray, np.random.Generator]:
    """A pair case's path, true chainage, satellites, ranges and sigmas, and its generator
    where they leave it (the faults and the prior are drawn next)."""
    rng = np.random.default_rng(1000 + case)
    path = _pair_paths()[case % 3]
    s_true = float(rng.choice([rng.uniform(0.0, path.length_m), 3.0, path.length_m - 2.0]))
    x = path.ecef_at(s_true)
    n = int(rng.integers(2, 10))
    az, el = random_sky(rng, n, min_el_deg=5.0)
    sat = sky(x, az, el)
    sig = rng.uniform(0.5, 6.0, n)
    return path, s_true, sat, ranges(sat, x, sig, rng), sig, rng


def pair_cases() -> Iterator[tuple[int, dict[str, NDArray]]]:
    """Random single epochs for ``solve_pairs``: every field of the solution per case."""
    for case in range(N_PAIR_CASES):
        path, s_true, sat, rho, sig, rng = pair_case_inputs(case)
        n = len(rho)
        if case % 4 == 1:  # a faulty range
            rho[int(rng.integers(n))] += rng.choice([60.0, 400.0, -3000.0])
        prior = s_true + float(rng.normal(0.0, [20.0, 300.0, 1500.0][case % 3]))
        prior = float(np.clip(prior, -50.0, path.length_m + 50.0))
        pairs = None if case % 2 == 0 else np.stack(np.triu_indices(n, 1), -1)[::2]
        sol = solve_pairs(path, sat, rho, sig, pairs, prior_m=prior,
                          window_m=float(rng.choice([150.0, 1000.0])),
                          k_sigma=float(rng.choice([2.0, 3.89])),
                          step_m=float(rng.choice([5.0, 2.5])))  # fmt: skip
        yield case, {f: np.asarray(getattr(sol, f)) for f in PAIR_FIELDS}


# ---------------------------------------------------------------------- writing the reference

_NAN_MM = np.iinfo(np.int64).min


def _to_mm(v: NDArray) -> NDArray:
    return np.where(np.isfinite(v), np.round(np.nan_to_num(v) * 1000.0), 0).astype(np.int64) \
        + np.where(np.isfinite(v), 0, _NAN_MM)


def _write_sim_inputs() -> None:  # pragma: no cover - run once, by hand
    """Simulate the two runs and store them (the locator's view) with their true masks cropped
    to the run and rounded to 0.1 deg (the inputs are what is stored: the rounding changes
    nothing for the comparison)."""
    import tempfile

    import yaml

    from locator.sim.multipath import ReflectorIndex
    from locator.sim.simulate import simulate_run
    from locator.sources import SimSource
    from locator.workflow import DEMO_RANGE_M, simulate_to_folder
    from predisat.availability.satellites import default_ephemeris, default_window
    from predisat.availability.trainrun import SpeedProfile
    from predisat.synth.truth import true_masks
    from predisat.synth.world import World, WorldSpec

    eph, day = default_ephemeris(), float(default_window()[0])
    track = demo_track()
    worlds = {
        "demo": World.build(track, WorldSpec.mixed(*DEMO_RANGE_M, seed=0), 0),
        "canyon": World.build(track, WorldSpec.from_dict(yaml.safe_load(
            (REPO / "surveys" / "nice_digne_canyon.yaml").read_text())), 7),
    }  # fmt: skip
    for name, world in worlds.items():
        if name == "demo":  # scripts/bench_locator.py's run, first 150 s
            with tempfile.TemporaryDirectory() as tmp:
                sim, _ = simulate_to_folder(world, eph, tmp, t0_gps_s=day + 8 * 3600, seed=1,
                                            masks_out=False, duration_s=150.0)  # fmt: skip
        else:  # a campaign job (scripts/locator_campaign.py's profile), its first 85 s
            profile = SpeedProfile.from_time_table(
                [0.0, 40.0, 70.0, 100.0, 160.0, 200.0, 1.0e4],
                [0.0, 20.0, 20.0, 0.0, 0.0, 20.0, 20.0])  # fmt: skip
            lo = world.extent_m[0]
            sim = simulate_run(world, eph, lo + 15.0, day + 0.3 * 86400.0, profile, 85.0, 1.0,
                               seed=7000, reflectors=ReflectorIndex(world))  # fmt: skip
        src = SimSource(sim)
        sats = sim.sats
        n_ep = sim.n_epoch
        sat = np.full((n_ep, len(sats), 3), np.nan)
        rho = np.full((n_ep, len(sats)), np.nan)
        for k in range(n_ep):
            d = src.observe(k, np.zeros(3))
            j = [sats.index(s) for s in d.sats]
            sat[k, j] = d.sat_ecef_m
            rho[k, j] = d.pseudorange_m
        tm = true_masks(world)
        c = sim.chainage_m
        keep = (tm.chainage_m >= c.min() - 300.0) & (tm.chainage_m <= c.max() + 300.0)
        np.savez_compressed(
            DATA / f"{name}.npz", gps_s=sim.gps_s, odometer_m=src.odometer_m,
            truth_chainage_m=c, sats=np.array(sats), sat_mm=_to_mm(sat), rho_mm=_to_mm(rho),
            start_m=float(c[0]), mask_chainage_m=tm.chainage_m[keep],
            mask_lat_deg=tm.lat_deg[keep], mask_lon_deg=tm.lon_deg[keep], mask_h_m=tm.h_m[keep],
            mask_heading_deg=tm.heading_deg[keep],
            mask_el_ddeg=np.round(tm.mask_el_deg[keep] * 10.0).astype(np.int16),
        )  # fmt: skip


def _write_reference() -> None:  # pragma: no cover - run once, by hand, with the OLD code
    frames = []
    for name in SIM_CASES:
        case = load_sim_case(name)
        for cfg in sim_configs():
            frames.append(run_sim_case(case, cfg).assign(case=name, config=cfg))
    for hd in REAL_HEADINGS_DEG:
        for integrity in ("active", "passive"):
            frames.append(run_real_case(hd, integrity).assign(case=f"0759_{hd:.0f}",
                                                              config=integrity))  # fmt: skip
    pd.concat(frames, ignore_index=True).to_parquet(DATA / "reference_runs.parquet")
    arrays = {f"{c}/{f}": v for c, sol in pair_cases() for f, v in sol.items()}
    np.savez_compressed(DATA / "reference_pairs.npz", **arrays)  # type: ignore[arg-type]


if __name__ == "__main__":  # pragma: no cover
    DATA.mkdir(parents=True, exist_ok=True)
    if "--inputs" in sys.argv:
        _write_sim_inputs()
    _write_reference()
