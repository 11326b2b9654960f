"""Tests of the pseudorange simulator (locator.sim.simulate, locator.sim.multipath).

Ground truth is analytic: two vertical walls beside a straight track, satellites placed at
chosen directions, the image method for the extra path of a reflection; the code-tracking
error is checked against a brute-force search of the discriminator's zero; the satellite
positions at transmission against the independent RangeModel and a light-time equation solved
with scipy.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from locator.corrections import OMEGA_E_RADPS, RangeModel
from locator.sim.multipath import ReflectorIndex, ReflectorSearch, SignalModel, dll_error_m
from locator.sim.simfile import SignalState, SimRun
from locator.sim.simulate import ClockModel, simulate_run, transmit_positions
from predisat.availability.trainrun import SpeedProfile
from predisat.geodesy import azel_to_enu, enu_rotation
from predisat.gnss.errormodel import ErrorModel
from predisat.gnss.orbits import C_MPS
from predisat.synth.materials import MATERIALS, material_id
from predisat.synth.world import Stretch, World, WorldSpec
from tests.locator._scene import (
    CANYON_FRAME as FRAME,
)
from tests.locator._scene import (
    LEFT_X_M,
    canyon_track,
    canyon_world,
)

T0 = 1.277e9
H_ANT_M = 4.0


@pytest.fixture(scope="module")
def canyon() -> World:
    """Two smooth vertical rock walls, 10 m left (30 m high) and 10 m right (15 m high)."""
    return canyon_world()


@pytest.fixture(scope="module")
def canyon_index(canyon) -> ReflectorIndex:
    return ReflectorIndex(canyon)


class FixedSky:
    """Ephemeris stand-in: satellites fixed in ECEF at given az/el from ``origin``."""

    def __init__(self, az_deg, el_deg, origin_ecef, distance_m: float = 2.2e7):
        rot = enu_rotation(*_latlon(origin_ecef))
        d = azel_to_enu(np.asarray(az_deg, float), np.asarray(el_deg, float)) @ rot
        self.pos = np.asarray(origin_ecef, float) + distance_m * d
        self.satellites = tuple(f"G{k + 1:02d}" for k in range(len(self.pos)))
        self.sources = ("fixed sky",)

    def evaluate(self, gps_s, sats):
        t = np.atleast_1d(np.asarray(gps_s, float))
        idx = [self.satellites.index(s) for s in sats]
        pos = np.broadcast_to(self.pos[idx], (len(t), len(idx), 3)).copy()
        return pos, np.zeros((len(t), len(idx))), None


def _latlon(ecef):
    lat, lon, _ = FRAME.to_geodetic(FRAME.ecef_to_enu(np.asarray(ecef, float)))
    return float(lat), float(lon)


# az, el: NLOS off the left wall / blocked both ways / open along the track /
# over the right wall, reflection passes over the left one / LOS with a left-wall reflection
SKY_AZ = [90.0, 270.0, 0.0, 90.0, 60.0]
SKY_EL = [30.0, 40.0, 60.0, 70.0, 60.0]


def _sky(world: World) -> FixedSky:
    return FixedSky(SKY_AZ, SKY_EL, world.frame.enu_to_ecef(world.antenna_enu(300.0, H_ANT_M)))


def _run(world, index, sky, **kw) -> SimRun:
    args = dict(seed=3, reflectors=index, antenna_height_m=H_ANT_M)
    args.update(kw)
    speed = args.pop("speed", SpeedProfile.constant(10.0))
    duration = args.pop("duration_s", 30.0)
    return simulate_run(world, sky, 150.0, T0, speed, duration, **args)


def _unit_to_sats(run: SimRun) -> np.ndarray:
    d = run.sat_ecef_m - run.antenna_ecef_m[:, None]
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    lat, lon, _ = FRAME.to_geodetic(run.antenna_enu_m)
    # ECEF -> local ENU at each antenna, then into the world frame (tilt < 1e-4 rad here)
    local = np.einsum("tij,tsj->tsi", enu_rotation(lat, lon), d)
    to_frame = FRAME.rotation_from(lat, lon)
    return np.einsum("tij,tsj->tsi", to_frame, local)


def test_canyon_states_and_image_method(canyon, canyon_index):
    run = _run(canyon, canyon_index, _sky(canyon), multipath=False)
    st = run.state
    expect = [SignalState.NLOS, SignalState.LOST, SignalState.LOS, SignalState.LOS,
              SignalState.LOS]  # fmt: skip
    for j, want in enumerate(expect):
        assert np.all(st[:, j] == want), (run.sats[j], np.unique(st[:, j]))
    # image method: extra path = 2 h (u . n), h the antenna's distance to the wall plane
    u = _unit_to_sats(run)
    h = run.antenna_enu_m[:, 0] - LEFT_X_M
    expected = 2.0 * h * (u[:, 0, 0])  # n = east for the west wall; u . n = u_east
    np.testing.assert_allclose(run.nlos_extra_m[:, 0], expected, atol=0.01)
    assert np.all(np.abs(expected - 2 * 10 * np.cos(np.radians(30))) < 0.05)
    # the reflection point lies on the left wall at the mirror height
    p = run.reflection_point_enu_m[:, 0]
    np.testing.assert_allclose(p[:, 0], LEFT_X_M, atol=1e-3)
    rise = run.antenna_enu_m[:, 2] + h * np.tan(np.radians(30.0))
    np.testing.assert_allclose(p[:, 2], rise, atol=0.02)
    assert np.all(MATERIALS[run.reflector_material[0, 0]].name == "rock")
    # NLOS pseudorange = range + clock + noise + extra; lost: no pseudorange
    np.testing.assert_allclose(
        run.corrected_m[:, 0],
        run.range_m[:, 0] + run.clock_bias_m + run.noise_m[:, 0] + expected,
        atol=0.02,
    )
    assert np.all(np.isnan(run.corrected_m[:, 1]))
    # the reflection of G05 is multipath on a direct signal: same image-method delay
    np.testing.assert_allclose(run.reflection_delay_m[:, 4], 2.0 * h * u[:, 4, 0], atol=0.01)
    assert np.all(run.reflector_face[:, 2:4] == -1)


def test_nlos_noise_scaled_by_cn0(canyon, canyon_index):
    sm = SignalModel()
    run = _run(canyon, canyon_index, _sky(canyon), multipath=False, signal_model=sm)
    el = run.el_deg[:, 0]
    ratio = 10 ** (sm.reflection_loss_db / 20)  # a vertical wall keeps the arrival elevation
    np.testing.assert_allclose(run.sigma_m[:, 0], ErrorModel().sigma_m(el) * ratio, rtol=1e-6)
    np.testing.assert_allclose(run.cn0_dbhz[:, 0], sm.cn0_direct_dbhz(el) - 8.0, rtol=1e-9)


def test_weak_reflection_is_lost(canyon, canyon_index):
    strict = SignalModel(threshold_dbhz=40.0)  # the reflected 33 dB-Hz is not tracked
    run = _run(canyon, canyon_index, _sky(canyon), signal_model=strict, duration_s=5.0)
    assert np.all(run.state[:, 0] == SignalState.LOST)
    assert np.all(np.isfinite(run.reflection_delay_m[:, 0]))


def test_los_error_statistics_match_model(canyon, canyon_index):
    model = ErrorModel(1.5, 3.0)
    run = _run(canyon, canyon_index, _sky(canyon), multipath=False, error_model=model,
               duration_s=40.0, rate_hz=5.0, speed=SpeedProfile.constant(2.0))  # fmt: skip
    los = run.state == SignalState.LOS
    err = run.error_m[los]
    np.testing.assert_allclose(err, run.noise_m[los], atol=1e-6)
    sig = model.sigma_m(run.el_deg[los])
    z = err / sig
    assert len(z) > 500
    assert abs(z.mean()) < 4.0 / np.sqrt(len(z))
    assert abs(z.std() - 1.0) < 0.08


def test_gauss_markov_noise_correlation(canyon, canyon_index):
    tau = 20.0
    run = _run(canyon, canyon_index, _sky(canyon), multipath=False, duration_s=400.0,
               noise_time_constant_s=tau, speed=SpeedProfile.constant(1.0))  # fmt: skip
    z = run.noise_m[:, 2] / run.sigma_m[:, 2]  # G03 is LOS all the time
    r1 = np.corrcoef(z[:-1], z[1:])[0, 1]
    assert abs(r1 - np.exp(-1.0 / tau)) < 0.03
    assert 0.6 < z.std() < 1.4


def test_los_multipath_follows_dll_model(canyon, canyon_index):
    sm = SignalModel()
    run = _run(canyon, canyon_index, _sky(canyon), signal_model=sm)
    delay = run.reflection_delay_m[:, 4]
    amp = 10 ** (-sm.reflection_loss_db / 20)
    phase = 2 * np.pi * delay / 0.190294 + np.pi
    want = [
        _dll_brute(d / 293.052, amp, ph, 0.1) * 293.052 for d, ph in zip(delay, phase, strict=True)
    ]
    np.testing.assert_allclose(run.multipath_m[:, 4], want, atol=2e-3)
    assert np.all(run.multipath_m[:, 2] == 0)  # no reflector for G03
    np.testing.assert_allclose(
        run.error_m[:, 4], run.noise_m[:, 4] + run.multipath_m[:, 4], atol=1e-6
    )


def _dll_brute(delta_chip: float, amp: float, phase: float, spacing: float) -> float:
    """Zero of the coherent early-minus-late discriminator, by root search."""

    def corr(tau):
        return max(0.0, 1.0 - abs(tau))

    a = amp * np.cos(phase)

    def disc(e):
        early = corr(e - spacing / 2) + a * corr(e - spacing / 2 - delta_chip)
        late = corr(e + spacing / 2) + a * corr(e + spacing / 2 - delta_chip)
        return early - late

    return brentq(disc, -0.5, 0.5, xtol=1e-12)


@pytest.mark.parametrize("spacing", [0.1, 0.5, 1.0])
def test_dll_error_matches_brute_force(spacing):
    rng = np.random.default_rng(7)
    delta = rng.uniform(0.0, 1.8, 300)
    amp = rng.uniform(0.0, 0.9, 300)
    phase = rng.uniform(0.0, 2 * np.pi, 300)
    got = dll_error_m(delta, amp, phase, 1.0, spacing)
    want = [_dll_brute(d, a, p, spacing) for d, a, p in zip(delta, amp, phase, strict=True)]
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert dll_error_m(np.nan, 0.5, 0.0, 293.0) == 0.0


def test_tunnel_loses_everything():
    track = canyon_track()
    spec = WorldSpec((Stretch("open", 0, 600), Stretch("tunnel", 250, 450)),
                     catenary=False, hills=False, terrain_margin_m=200.0)  # fmt: skip
    world = World.build(track, spec, seed=1)
    sky = FixedSky([10, 100, 200, 300, 45], [80, 50, 30, 20, 10],
                   world.frame.enu_to_ecef(world.antenna_enu(300.0)))  # fmt: skip
    run = simulate_run(world, sky, 200.0, T0, SpeedProfile.constant(10.0), 20.0, seed=1)
    inside = (run.chainage_m > 280) & (run.chainage_m < 420)
    outside = run.chainage_m < 230
    assert inside.sum() >= 10 and outside.sum() >= 2
    assert np.all(run.state[inside] == SignalState.LOST)
    assert np.all(np.isnan(run.corrected_m[inside]))
    assert np.all(run.state[outside][:, :4] == SignalState.LOS)  # 10 deg may meet the portal


def test_clock_drift_integrates():
    perfect = ClockModel.perfect(bias_m=500.0, drift_mps=-3.0)
    b, d = perfect.sample(11, 0.5, np.random.default_rng(0))
    np.testing.assert_allclose(b, 500.0 - 3.0 * 0.5 * np.arange(11), atol=1e-9)
    np.testing.assert_allclose(d, -3.0)
    # with noise: increments have the two-state covariance
    clock = ClockModel(0.0, 10.0, q_bias_m2ps=0.04, q_drift_m2ps3=0.01)
    dt = 2.0
    b, d = clock.sample(40001, dt, np.random.default_rng(1))
    wb = b[1:] - b[:-1] - d[:-1] * dt
    wd = np.diff(d)
    cov = np.cov(np.stack([wb, wd]))
    np.testing.assert_allclose(cov, clock.step_covariance(dt), rtol=0.05)
    q = clock.step_covariance(dt)
    assert np.isclose(q[0, 0], 0.04 * 2 + 0.01 * 8 / 3)  # q_b dt + q_d dt^3 / 3
    assert abs(d[0] - 10.0) < 1e-12


def test_clock_enters_the_ranges(canyon, canyon_index):
    clock = ClockModel.perfect(bias_m=1234.5, drift_mps=2.0)
    run = _run(canyon, canyon_index, _sky(canyon), clock_model=clock, duration_s=10.0)
    t = run.gps_s - run.gps_s[0]
    np.testing.assert_allclose(run.clock_bias_m, 1234.5 + 2.0 * t, atol=1e-9)
    los = run.state[:, 2] == SignalState.LOS
    np.testing.assert_allclose(
        run.corrected_m[los, 2] - run.range_m[los, 2] - run.noise_m[los, 2],
        run.clock_bias_m[los], atol=1e-6,
    )  # fmt: skip


def test_speed_profile_with_stop(canyon, canyon_index):
    speed = SpeedProfile.from_time_table([0, 10, 12, 22, 24, 40], [10, 0, 0, 0, 8, 8])
    run = _run(canyon, canyon_index, _sky(canyon), speed=speed, duration_s=40.0)
    stopped = (run.gps_s - T0 >= 12) & (run.gps_s - T0 <= 22)
    assert stopped.sum() == 11
    assert np.all(run.speed_mps[stopped] == 0)
    assert np.ptp(run.chainage_m[stopped]) < 1e-9
    # distance run before the stop: triangle of the deceleration, exactly
    assert np.isclose(run.chainage_m[stopped][0] - 150.0, 10 * 10 / 2, atol=1e-6)
    assert np.all(np.diff(run.chainage_m) >= -1e-12)
    # while stopped the multipath of the left-wall reflection is frozen
    assert np.ptp(run.multipath_m[stopped, 4]) < 1e-9


def test_reverse_direction_heading(canyon, canyon_index):
    run = _run(canyon, canyon_index, _sky(canyon), direction=-1, duration_s=5.0)
    np.testing.assert_allclose(run.chainage_m, 150.0 - 10.0 * np.arange(6), atol=1e-6)
    assert np.allclose((run.heading_deg - 180.0 + 180) % 360 - 180, 0.0, atol=0.01)


def test_run_leaving_the_world_is_refused(canyon, canyon_index):
    with pytest.raises(ValueError, match="shorten duration_s"):
        _run(canyon, canyon_index, _sky(canyon), duration_s=100.0)


def test_reproducible(canyon, canyon_index):
    a = _run(canyon, canyon_index, _sky(canyon), duration_s=5.0)
    b = _run(canyon, canyon_index, _sky(canyon), duration_s=5.0)
    c = _run(canyon, canyon_index, _sky(canyon), duration_s=5.0, seed=4)
    np.testing.assert_array_equal(a.corrected_m, b.corrected_m)
    assert not np.allclose(a.noise_m[:, 2], c.noise_m[:, 2])


def test_transmit_positions_solve_light_time():
    """Circular orbit stand-in: compare with the light-time equation solved by brentq."""
    r_orbit, w_orbit = 2.656e7, 1.4585e-4

    class Circle:
        satellites = ("G01",)

        def evaluate(self, t, sats):
            t = np.atleast_1d(t)
            ang = w_orbit * (t - T0)
            p = np.stack([r_orbit * np.cos(ang), r_orbit * 0.3 * np.sin(ang),
                          r_orbit * 0.95 * np.sin(ang)], -1)  # fmt: skip
            return p[:, None, :], np.zeros((len(t), 1)), None

    rx = FRAME.enu_to_ecef(np.array([[0.0, 0.0, 0.0], [100.0, 50.0, 3.0]]))
    t = np.array([T0 + 3000.0, T0 + 3001.0])
    _, rng = transmit_positions(Circle(), t, ("G01",), rx)
    for k in range(2):

        def f(tau, k=k):
            p = Circle().evaluate(t[k] - tau, ("G01",))[0][0, 0]
            th = OMEGA_E_RADPS * tau
            rot = np.array([[np.cos(th), np.sin(th), 0], [-np.sin(th), np.cos(th), 0], [0, 0, 1]])
            return np.linalg.norm(rot @ p - rx[k]) - C_MPS * tau

        tau = brentq(f, 0.05, 0.2, xtol=1e-15)
        np.testing.assert_allclose(rng[k, 0], C_MPS * tau, atol=1e-4)


@pytest.fixture(scope="module")
def real_eph():
    from predisat.availability.satellites import default_ephemeris

    return default_ephemeris()


def test_real_ephemeris_consistent_with_range_model(real_eph):
    """Satellite positions at transmission agree with locator.corrections.RangeModel."""
    from predisat.availability.satellites import default_window

    t = float(default_window()[0] + 5 * 3600.0)
    rx = FRAME.enu_to_ecef(np.array([[0.0, 0.0, 4.0]]))
    sats = tuple(s for s in real_eph.satellites if s[0] in "GE")
    sat, rng = transmit_positions(real_eph, [t], sats, rx)
    ok = np.isfinite(rng[0])
    assert ok.sum() >= 20
    sats_ok = tuple(s for s, k in zip(sats, ok, strict=True) if k)
    clk = real_eph.evaluate([t], sats_ok)[1][0]
    model = RangeModel.from_ephemeris(real_eph)
    # a pseudorange whose transmission time is the geometric one: P = range - c dt_sat
    cr = model.correct(t, sats_ok, rng[0, ok] - C_MPS * clk, rx[0], atmosphere=False)
    np.testing.assert_allclose(sat[0, ok], cr.sat_ecef_m, atol=2e-3)
    np.testing.assert_allclose(rng[0, ok], cr.range_m, atol=2e-3)


def test_open_world_real_sky_feeds_the_locator(real_eph):
    from locator import AntennaPath, LocatorConfig, locate
    from predisat.availability.satellites import default_window
    from predisat.gnss.errormodel import IntervalModel

    track = canyon_track(900.0)
    spec = WorldSpec((Stretch("open", 0, 880),), catenary=False, hills=False,
                     terrain_margin_m=300.0)  # fmt: skip
    world = World.build(track, spec, seed=2)
    t0 = float(default_window()[0] + 8 * 3600.0)
    run = simulate_run(world, real_eph, 100.0, t0, SpeedProfile.constant(20.0), 20.0,
                       seed=5, constellation="GE", min_el_deg=5.0)  # fmt: skip
    counts = run.counts()
    assert np.all(counts["los"] >= 8)
    assert np.all(counts["nlos"] == 0)
    path = AntennaPath(track, antenna_height_m=4.0)
    cfg = LocatorConfig(model=IntervalModel(ErrorModel(), k_sigma=3.0), budget=None)
    held = 0
    for i in range(0, run.n_epoch, 4):
        obs = run.observations(i)
        fix = locate(path, obs.sat_ecef_m, obs.corrected_m, obs.el_deg,
                     prior_m=run.chainage_m[i] + 30.0, config=cfg)  # fmt: skip
        held += fix.lo_m <= run.chainage_m[i] <= fix.hi_m
    assert held >= 5


def test_simulated_run_file_round_trip(canyon, canyon_index, tmp_path):
    run = _run(canyon, canyon_index, _sky(canyon), duration_s=5.0)
    back = SimRun.read(run.write(tmp_path / "sim"))
    for name in ("corrected_m", "nlos_extra_m", "reflection_point_enu_m", "sat_ecef_m",
                 "reflector_face", "reflector_material", "state", "clock_bias_m"):  # fmt: skip
        np.testing.assert_array_equal(getattr(back, name), getattr(run, name), err_msg=name)
    assert back.meta["signal_model"]["reflection_loss_db"] == 8.0
    assert back.meta["world_spec"]["stretches"][0]["kind"] == "rock_walls"


def test_recipe_rock_wall_reflection():
    """A smooth rock wall of a World.build recipe: image-method delay, lost behind it."""
    track = canyon_track()
    wall_m = {"height_m": 40, "distance_m": 8, "roughness_m": 0, "batter": 0}
    spec = WorldSpec((Stretch("open", 0, 590), Stretch("rock_walls", 100, 500, "left", wall_m)),
                     catenary=False, hills=False, terrain_margin_m=200.0)  # fmt: skip
    world = World.build(track, spec, seed=1)
    sky = FixedSky([90, 120, 270], [30, 50, 20], world.frame.enu_to_ecef(world.antenna_enu(300.0)))
    run = simulate_run(world, sky, 200.0, T0, SpeedProfile.constant(10.0), 20.0, seed=1)
    assert np.all(run.state[:, :2] == SignalState.LOS)
    assert np.all(run.state[:, 2] == SignalState.LOST)  # behind the wall, nothing to reflect
    u = _unit_to_sats(run)
    h = run.antenna_enu_m[:, 0] + 8.0
    np.testing.assert_allclose(run.reflection_delay_m[:, :2], 2 * h[:, None] * u[:, :2, 0],
                               atol=0.01)  # fmt: skip
    assert np.all(run.multipath_m[:, :2] != 0)


def test_glass_facades_and_water_reflect_lband():
    # the out-of-distribution scenery's mirrors are L-band reflectors too; thin, vegetal and
    # ground materials are not
    reflects = ReflectorSearch().reflects
    for name in ("glass", "white_facade", "water", "brick", "concrete"):
        assert reflects[material_id(name)], name
    for name in ("foliage", "grass", "wire", "lattice", "conductor"):
        assert not reflects[material_id(name)], name
