"""Pseudorange simulator in a synthetic world: a train run with LOS, multipath, NLOS and loss.

:func:`simulate_run` drives a train along a :class:`predisat.synth.world.World` with a
:class:`predisat.availability.trainrun.SpeedProfile` and, at every epoch, for every satellite of the
ephemeris above the horizon:

1. the satellite position at transmission (light time, Earth rotation during the travel), as
   :class:`locator.corrections.RangeModel` gives it;
2. the direct ray from the antenna toward it, cast in the world's L-band geometry (wires and
   thin tubes ignored): free means **LOS**;
3. the best single-bounce specular reflection (:mod:`locator.sim.multipath`); for a LOS signal it
   causes code **multipath** (delay-lock-loop error); for a blocked one it is tracked when
   strong enough (**NLOS**: the pseudorange is long by the reflection's extra path), otherwise
   the signal is **LOST**;
4. noise of standard deviation :class:`predisat.gnss.errormodel.ErrorModel` ``sigma(el)``
   (scaled up by the C/N0 loss of a reflected signal), white or first-order Gauss-Markov;
5. the receiver clock, bias and drift driven by white and random-walk frequency noise
   (:class:`ClockModel`).

The output are **corrected** pseudoranges (satellite clock, relativity, group delay, ionosphere
and troposphere already removed, as :attr:`locator.corrections.CorrectedRanges.corrected_m`)
with the satellite positions used, so the locator runs on them directly::

    corrected_m = range_m + clock_bias_m + noise_m + multipath_m + nlos_extra_m

and, as ground truth, every term. See ``docs/simulation.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.corrections import OMEGA_E_RADPS
from locator.sim.multipath import (
    SIGNALS,
    Reflections,
    ReflectorIndex,
    ReflectorSearch,
    SignalModel,
    dll_error_m,
    find_reflections,
)
from locator.sim.simfile import SignalState, SimRun
from predisat.availability.satellites import select_satellites
from predisat.availability.trainrun import SpeedProfile
from predisat.geodesy import enu_rotation, enu_to_azel
from predisat.gnss.errormodel import ErrorModel
from predisat.gnss.orbits import C_MPS
from predisat.jsontypes import JsonDict

if TYPE_CHECKING:
    from predisat.synth.world import World  # the renderer's world: needs the [synth] extra

__all__ = ["ClockModel", "OrbitSource", "SkySource", "simulate_run", "transmit_positions"]


class OrbitSource(Protocol):
    """What :func:`transmit_positions` needs of an ephemeris
    (:class:`predisat.gnss.ephemeris.Ephemeris` is one)."""

    def evaluate(
        self, gps_s: ArrayLike, sats: Sequence[str]
    ) -> tuple[NDArray, NDArray, object]: ...


class SkySource(OrbitSource, Protocol):
    """What :func:`simulate_run` needs of an ephemeris: positions and the satellite list."""

    @property
    def satellites(self) -> Sequence[str]: ...


@dataclass(frozen=True)
class ClockModel:
    """Receiver clock: bias ``b`` (c times the offset, m) and drift ``d`` (m/s).

    Two-state model, exact in discrete time over a step ``dt``::

        b[k+1] = b[k] + d[k] dt + w_b,   d[k+1] = d[k] + w_d
        cov(w_b, w_d) = [[q_b dt + q_d dt^3 / 3, q_d dt^2 / 2], [q_d dt^2 / 2, q_d dt]]

    ``q_b`` is the white-frequency-noise and ``q_d`` the random-walk-frequency-noise spectral
    density (Brown & Hwang). The defaults are those of a TCXO (h0 = 2e-19, h-2 = 2e-20).

    Attributes
    ----------
    bias_m, drift_mps : float
        Values at the first epoch.
    q_bias_m2ps : float
        ``q_b = c^2 h0 / 2``, m^2/s.
    q_drift_m2ps3 : float
        ``q_d = 2 pi^2 c^2 h-2``, m^2/s^3.
    """

    bias_m: float = 1.0e4
    drift_mps: float = 30.0
    q_bias_m2ps: float = 0.5 * C_MPS**2 * 2e-19
    q_drift_m2ps3: float = 2.0 * np.pi**2 * C_MPS**2 * 2e-20

    def __post_init__(self) -> None:
        if self.q_bias_m2ps < 0 or self.q_drift_m2ps3 < 0:
            raise ValueError(f"ClockModel noise densities must be >= 0: {self}")

    @classmethod
    def from_allan(
        cls, h0: float, h_minus2: float, bias_m: float = 1.0e4, drift_mps: float = 30.0
    ) -> ClockModel:
        """Clock from the power-law coefficients of its fractional frequency (h0, h-2)."""
        return cls(bias_m, drift_mps, 0.5 * C_MPS**2 * h0, 2.0 * np.pi**2 * C_MPS**2 * h_minus2)

    @classmethod
    def perfect(cls, bias_m: float = 0.0, drift_mps: float = 0.0) -> ClockModel:
        """A noise-free clock: ``b = bias_m + drift_mps * t``."""
        return cls(bias_m, drift_mps, 0.0, 0.0)

    def step_covariance(self, dt_s: float) -> NDArray:
        """Covariance (2, 2) of ``(w_b, w_d)`` over one step of ``dt_s`` seconds."""
        qb, qd, dt = self.q_bias_m2ps, self.q_drift_m2ps3, float(dt_s)
        return np.array(
            [[qb * dt + qd * dt**3 / 3.0, qd * dt**2 / 2.0], [qd * dt**2 / 2.0, qd * dt]]
        )

    def sample(
        self, n_epoch: int, dt_s: float, rng: np.random.Generator
    ) -> tuple[NDArray, NDArray]:
        """Bias and drift at ``n_epoch`` epochs ``dt_s`` apart, shapes (n_epoch,)."""
        if n_epoch < 1 or dt_s <= 0:
            raise ValueError(f"need n_epoch >= 1 and dt_s > 0, got {n_epoch}, {dt_s}")
        cov = self.step_covariance(dt_s)
        # eigen-decomposition instead of Cholesky: the covariance may be singular (no noise)
        val, vec = np.linalg.eigh(cov)
        w = rng.standard_normal((n_epoch - 1, 2)) @ (vec * np.sqrt(np.maximum(val, 0.0))).T
        drift = self.drift_mps + np.concatenate([[0.0], np.cumsum(w[:, 1])])
        bias = self.bias_m + np.concatenate([[0.0], np.cumsum(drift[:-1] * dt_s + w[:, 0])])
        return bias, drift


def _rotate_earth(pos: NDArray, theta: NDArray) -> NDArray:
    """Rotate ECEF positions by ``-theta`` about z (Earth rotation during the signal travel)."""
    c, s = np.cos(theta), np.sin(theta)
    x, y = pos[..., 0], pos[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y, pos[..., 2]], axis=-1)


def transmit_positions(
    ephemeris: OrbitSource, gps_s: ArrayLike, sats: Sequence[str], rx_ecef_m: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Satellite positions at transmission, in the Earth-fixed frame at reception.

    Light time from the geometric range, iterated; the satellite's path over the last 0.2 s
    before reception is the quadratic through three ephemeris evaluations (error < 1 um).

    Parameters
    ----------
    ephemeris : Ephemeris
        Anything with ``evaluate(gps_s, sats) -> (pos (n, n_sat, 3), clock, status)``.
    gps_s : array_like, shape (n_epoch,)
        True reception epochs.
    sats : sequence of str, length n_sat
    rx_ecef_m : array_like, shape (n_epoch, 3)
        Receiver positions.

    Returns
    -------
    sat_ecef_m : ndarray, shape (n_epoch, n_sat, 3)
        NaN where the ephemeris does not trust the satellite.
    range_m : ndarray, shape (n_epoch, n_sat)
        Geometric range receiver - satellite.
    """
    t = np.atleast_1d(np.asarray(gps_s, float))
    rx = np.asarray(rx_ecef_m, float).reshape(len(t), 3)
    h = 0.1
    pos, _, _ = ephemeris.evaluate(np.concatenate([t, t - h, t - 2 * h]), tuple(sats))
    p0, p1, p2 = pos[: len(t)], pos[len(t) : 2 * len(t)], pos[2 * len(t) :]
    rng = np.linalg.norm(p0 - rx[:, None], axis=-1)
    sat = p0
    for _ in range(3):  # converges to far below a micrometre
        x = -(rng / C_MPS)[..., None]
        sat = (
            p0 * ((x + h) * (x + 2 * h) / (2 * h * h))
            - p1 * (x * (x + 2 * h) / (h * h))
            + p2 * (x * (x + h) / (2 * h * h))
        )
        sat = _rotate_earth(sat, OMEGA_E_RADPS * rng / C_MPS)
        rng = np.linalg.norm(sat - rx[:, None], axis=-1)
    return sat, rng


def simulate_run(
    world: World,
    ephemeris: SkySource,
    start_chainage_m: float,
    t0_gps_s: float,
    speed_profile: SpeedProfile,
    duration_s: float,
    rate_hz: float = 1.0,
    *,
    direction: int = +1,
    antenna_height_m: float = 4.0,
    seed: int = 0,
    error_model: ErrorModel | None = None,
    clock_model: ClockModel | None = None,
    signal_model: SignalModel | None = None,
    search: ReflectorSearch | None = None,
    noise_time_constant_s: float = 0.0,
    multipath: bool = True,
    constellation: str | Sequence[str] = "all",
    sats: Sequence[str] | None = None,
    min_el_deg: float = 0.0,
    reflectors: ReflectorIndex | None = None,
    backend: str = "open3d",
) -> SimRun:
    """Simulate the corrected pseudoranges of a train run in a synthetic world.

    Parameters
    ----------
    world : World
        The scene (:class:`predisat.synth.world.World`); the run must stay inside its
        scenery (``world.extent_m``).
    ephemeris : Ephemeris
        Satellite orbits (:class:`predisat.gnss.ephemeris.Ephemeris`, e.g.
        :func:`predisat.availability.satellites.default_ephemeris`).
    start_chainage_m, t0_gps_s : float
        Departure chainage and time.
    speed_profile : SpeedProfile
        Train speed (stops, acceleration, braking).
    duration_s, rate_hz : float
        Length of the run and epochs per second.
    direction : {+1, -1}
        Toward increasing or decreasing chainage.
    antenna_height_m : float
        Antenna above the rail, along the local vertical.
    seed : int
        Seeds the noise and the clock; the same inputs and seed give the same run.
    error_model : ErrorModel, optional
        Noise of a direct signal, ``sigma(el)`` (default ``ErrorModel()``).
    clock_model : ClockModel, optional
    signal_model : SignalModel, optional
        C/N0, tracking threshold, reflection loss, correlator.
    search : ReflectorSearch, optional
        Reflector search parameters.
    noise_time_constant_s : float
        Correlation time of the noise (first-order Gauss-Markov); 0 for white noise.
    multipath : bool
        Add the code multipath of reflections to direct signals.
    constellation : str or sequence of str
        Systems to simulate (``"all"``, ``"GE"``, ...), or explicit ``sats``.
    min_el_deg : float
        Satellites below this elevation are not simulated.
    reflectors : ReflectorIndex, optional
        Reuse an index (and its ray caster) of ``world`` across runs.
    backend : {"open3d", "trimesh"}
        Ray casting backend when ``reflectors`` is not given.

    Returns
    -------
    SimRun
    """
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 or -1, got {direction}")
    if not (duration_s >= 0 and rate_hz > 0):
        raise ValueError(f"need duration_s >= 0 and rate_hz > 0, got {duration_s}, {rate_hz}")
    if noise_time_constant_s < 0:
        raise ValueError(f"noise_time_constant_s must be >= 0, got {noise_time_constant_s}")
    error_model = error_model or ErrorModel()
    clock_model = clock_model or ClockModel()
    signal_model = signal_model or SignalModel()
    search = search or ReflectorSearch()
    dt = 1.0 / rate_hz
    t_rel = np.arange(int(np.floor(duration_s * rate_hz + 1e-9)) + 1) * dt
    gps = t0_gps_s + t_rel
    move = _motion(world, start_chainage_m, t_rel, speed_profile, direction, antenna_height_m)
    sky = _sky(world, ephemeris, gps, move, constellation, sats, min_el_deg)
    index = reflectors or ReflectorIndex(world, backend=backend)
    sig = _signals(index, move, sky, search, signal_model)
    err = _errors(sky, sig, signal_model, error_model, clock_model, dt, seed,
                  noise_time_constant_s, multipath)  # fmt: skip
    meta = {
        "created_by": "locator.sim.simulate.simulate_run",
        "t0_gps_s": float(t0_gps_s),
        "start_chainage_m": float(start_chainage_m),
        "direction": int(direction),
        "duration_s": float(duration_s),
        "rate_hz": float(rate_hz),
        "antenna_height_m": float(antenna_height_m),
        "seed": int(seed),
        "speed_profile": speed_profile.kind,
        "noise_time_constant_s": float(noise_time_constant_s),
        "multipath": bool(multipath),
        "min_el_deg": float(min_el_deg),
        "error_model": asdict(error_model),
        "clock_model": asdict(clock_model),
        "signal_model": asdict(signal_model),
        "reflector_search": asdict(search),
        "frame": [world.frame.lat_deg, world.frame.lon_deg, world.frame.h_m],
        "track": getattr(world.track, "name", "track"),
        "world_seed": int(getattr(world, "seed", 0)),
        "world_spec": world.spec.to_dict() if hasattr(world.spec, "to_dict") else None,
        "ephemeris": list(getattr(ephemeris, "sources", ())),
        "backend": getattr(index.caster, "backend", backend),
    }
    return _sim_run(world, gps, move, sky, sig, err, meta)


@dataclass(frozen=True)
class _Motion:
    """The train along the run: chainage, speed, heading of travel, antenna positions."""

    chainage_m: NDArray
    speed_mps: NDArray
    heading_deg: NDArray
    ant_enu_m: NDArray
    ant_ecef_m: NDArray


def _motion(
    world: World, start_chainage_m: float, t_rel: NDArray, speed_profile: SpeedProfile,
    direction: int, antenna_height_m: float,
) -> _Motion:  # fmt: skip
    chain = start_chainage_m + direction * speed_profile.distance_at(t_rel)
    lo, hi = world.extent_m
    if chain.min() < lo - 1e-6 or chain.max() > hi + 1e-6:
        raise ValueError(
            f"the run covers chainage {chain.min():.1f}-{chain.max():.1f} m but the world's "
            f"scenery is {lo:.1f}-{hi:.1f} m; shorten duration_s, move start_chainage_m or "
            "build a longer world"
        )
    speed = speed_profile.speed_at(t_rel)
    heading = (np.asarray(world.track.heading_at(chain), float) + (direction < 0) * 180.0) % 360
    ant_enu = world.antenna_enu(chain, antenna_height_m)
    return _Motion(chain, speed, heading, ant_enu, world.frame.enu_to_ecef(ant_enu))


@dataclass(frozen=True)
class _Sky:
    """The satellites above the horizon at every epoch, (n_epoch, n_sat[, 3])."""

    names: tuple[str, ...]
    sat_ecef_m: NDArray
    range_m: NDArray
    az_deg: NDArray
    el_deg: NDArray
    visible: NDArray
    sat_enu_m: NDArray  # NaN where not visible


def _sky(
    world: World, ephemeris: SkySource, gps: NDArray, move: _Motion,
    constellation: str | Sequence[str], sats: Sequence[str] | None, min_el_deg: float,
) -> _Sky:  # fmt: skip
    names = select_satellites(ephemeris.satellites if sats is None else sats, constellation)
    if not names:
        raise ValueError(
            f"no satellite of constellation {constellation!r} among "
            f"{'the ephemeris' if sats is None else 'sats'}; choose another constellation"
        )
    ant_enu, ant_ecef = move.ant_enu_m, move.ant_ecef_m
    sat_ecef, rng_m = transmit_positions(ephemeris, gps, names, ant_ecef)
    lat, lon, _ = world.frame.to_geodetic(ant_enu)
    rot = enu_rotation(lat, lon)
    az, el, _ = enu_to_azel(np.einsum("tij,tsj->tsi", rot, sat_ecef - ant_ecef[:, None]))
    visible = np.isfinite(el) & (el > min_el_deg)
    sat_enu = world.frame.ecef_to_enu(np.where(visible[..., None], sat_ecef, 0.0))
    sat_enu = np.where(visible[..., None], sat_enu, np.nan)
    return _Sky(tuple(names), sat_ecef, rng_m, az, el, visible, sat_enu)


@dataclass(frozen=True)
class _Signals:
    """What the receiver gets of each satellite: direct, reflected, tracked, state."""

    refl: Reflections
    cn0_direct_dbhz: NDArray
    cn0_refl_dbhz: NDArray
    tracked_direct: NDArray
    nlos: NDArray
    state: NDArray
    received: NDArray


def _signals(
    index: ReflectorIndex, move: _Motion, sky: _Sky, search: ReflectorSearch,
    signal_model: SignalModel,
) -> _Signals:  # fmt: skip
    ant_enu, visible, el = move.ant_enu_m, sky.visible, sky.el_deg
    n_ep, n_sat = visible.shape
    ie, js = np.nonzero(visible)
    los = np.zeros((n_ep, n_sat), bool)
    if len(ie):
        u = sky.sat_enu_m[ie, js] - ant_enu[ie]
        los[ie, js] = ~index.caster.occluded(ant_enu[ie], u)
    refl = find_reflections(
        index, ant_enu, sky.sat_enu_m, visible, search, signal_model.min_arrival_el_deg
    )
    cn0_direct = signal_model.cn0_direct_dbhz(el)
    cn0_refl = signal_model.cn0_reflected_dbhz(refl.arrival_el_deg)
    tracked_direct = los & (cn0_direct >= signal_model.threshold_dbhz)
    nlos = visible & ~los & refl.found & (cn0_refl >= signal_model.threshold_dbhz)
    state = np.full((n_ep, n_sat), SignalState.NOT_VISIBLE, np.int8)
    state[visible] = SignalState.LOST
    state[tracked_direct] = SignalState.LOS
    state[nlos] = SignalState.NLOS
    return _Signals(refl, cn0_direct, cn0_refl, tracked_direct, nlos, state,
                    tracked_direct | nlos)  # fmt: skip


@dataclass(frozen=True)
class _Errors:
    """The terms of the corrected pseudoranges, (n_epoch[, n_sat])."""

    clock_bias_m: NDArray
    clock_drift_mps: NDArray
    sigma_m: NDArray
    noise_m: NDArray
    multipath_m: NDArray
    nlos_extra_m: NDArray
    corrected_m: NDArray


def _errors(
    sky: _Sky, sig: _Signals, signal_model: SignalModel, error_model: ErrorModel,
    clock_model: ClockModel, dt: float, seed: int, noise_time_constant_s: float,
    multipath: bool,
) -> _Errors:  # fmt: skip
    n_ep, n_sat = sky.visible.shape
    refl, nlos = sig.refl, sig.nlos
    gen = np.random.default_rng([int(seed), 5])
    bias, drift = clock_model.sample(n_ep, dt, gen)
    z = gen.standard_normal((n_ep, n_sat))
    if noise_time_constant_s > 0:
        phi = np.exp(-dt / noise_time_constant_s)
        for k in range(1, n_ep):  # stationary unit-variance AR(1) per satellite
            z[k] = phi * z[k - 1] + np.sqrt(1.0 - phi**2) * z[k]
    sigma = np.asarray(error_model.sigma_m(np.where(sky.visible, sky.el_deg, 90.0)), float)
    sigma = np.where(
        nlos, sigma * 10.0 ** ((sig.cn0_direct_dbhz - sig.cn0_refl_dbhz) / 20.0), sigma
    )
    mp = np.zeros((n_ep, n_sat))
    if multipath:
        chip = np.array([SIGNALS.get(s[0], SIGNALS["G"])[0] for s in sky.names])
        wavelength = np.array([SIGNALS.get(s[0], SIGNALS["G"])[1] for s in sky.names])
        with_refl = sig.tracked_direct & refl.found
        amp = np.clip(10.0 ** ((sig.cn0_refl_dbhz - sig.cn0_direct_dbhz) / 20.0), 0.0, 0.99)
        phase = 2.0 * np.pi * refl.extra_m / wavelength + signal_model.reflection_phase_rad
        mp_all = dll_error_m(
            np.where(with_refl, refl.extra_m, np.nan), np.where(with_refl, amp, 0.0),
            np.nan_to_num(phase), chip, signal_model.correlator_spacing_chip,
        )  # fmt: skip
        mp = np.where(with_refl, mp_all, 0.0)
    noise = sigma * z
    extra = np.where(nlos, refl.extra_m, 0.0)
    corrected = sky.range_m + bias[:, None] + noise + mp + extra
    return _Errors(bias, drift, sigma, noise, mp, extra, corrected)


def _sim_run(
    world: World, gps: NDArray, move: _Motion, sky: _Sky, sig: _Signals, err: _Errors,
    meta: JsonDict,
) -> SimRun:  # fmt: skip
    """The run's record: received terms NaN where not received, geometry where not visible."""
    received, visible, refl = sig.received, sky.visible, sig.refl

    def rx_only(a: NDArray) -> NDArray:
        return np.where(received, a, np.nan)

    def vis_only(a: NDArray) -> NDArray:
        return np.where(visible[..., None] if a.ndim == 3 else visible, a, np.nan)

    mat = np.where(refl.found, np.asarray(world.face_material)[np.maximum(refl.face_id, 0)], -1)
    cn0 = np.where(sig.tracked_direct, sig.cn0_direct_dbhz,
                   np.where(refl.found, sig.cn0_refl_dbhz, np.nan))  # fmt: skip
    return SimRun(
        gps_s=gps,
        chainage_m=move.chainage_m,
        speed_mps=move.speed_mps,
        heading_deg=move.heading_deg,
        antenna_ecef_m=move.ant_ecef_m,
        antenna_enu_m=move.ant_enu_m,
        clock_bias_m=err.clock_bias_m,
        clock_drift_mps=err.clock_drift_mps,
        sats=sky.names,
        state=sig.state,
        sat_ecef_m=vis_only(sky.sat_ecef_m),
        az_deg=vis_only(sky.az_deg),
        el_deg=vis_only(sky.el_deg),
        range_m=vis_only(sky.range_m),
        corrected_m=rx_only(err.corrected_m),
        sigma_m=rx_only(err.sigma_m),
        cn0_dbhz=vis_only(cn0),
        noise_m=rx_only(err.noise_m),
        multipath_m=rx_only(err.multipath_m),
        nlos_extra_m=rx_only(err.nlos_extra_m),
        reflection_delay_m=vis_only(refl.extra_m),
        reflector_face=np.where(visible, refl.face_id, -1),
        reflector_material=mat.astype(np.int16),
        reflection_point_enu_m=vis_only(refl.point_enu_m),
        meta=meta,
    )
