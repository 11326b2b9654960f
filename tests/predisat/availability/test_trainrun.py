"""Train run: speed profiles obeyed, chainage monotone, trusted satellites re-derived with PROJ."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import Transformer

from predisat.availability.satellites import TrustRule, default_ephemeris, default_window
from predisat.availability.trainrun import SpeedProfile, trainrun
from predisat.track.map import TrackMap


@pytest.fixture(scope="module")
def track() -> TrackMap:
    return TrackMap.from_latlon(np.linspace(50.40, 50.45, 6), np.linspace(4.60, 4.70, 6), 120.0)


def test_limits_profile_obeys_limits_and_acceleration() -> None:
    sp = SpeedProfile.from_limits([0.0, 1000.0, 2500.0, 4000.0], [30.0, 12.0, 25.0, 0.0],
                                  accel_mps2=0.6, decel_mps2=0.8)  # fmt: skip
    t = np.arange(0.0, 600.0, 0.5)
    d = sp.distance_at(t)
    v = sp.speed_at(t)
    limit = np.array([30.0, 12.0, 25.0, 0.0])[
        np.searchsorted([0, 1000, 2500, 4000], d, "right") - 1
    ]
    assert np.all(v <= limit + 1e-6 + 0.1 * (limit == 0))
    assert np.all(np.diff(d) >= -1e-9)
    dv = np.diff(v) / 0.5
    assert dv.max() <= 0.6 + 1e-2 and dv.min() >= -0.8 - 1e-2
    assert d[-1] == pytest.approx(4000.0, abs=1.0)  # stops at the end of the table
    # the train is at 12 m/s or less over the whole 1000-2500 m section
    assert np.all(v[(d > 1000) & (d < 2500)] <= 12.0 + 1e-6)


def test_constant_speed_run_both_directions(track: TrackMap) -> None:
    eph = default_ephemeris()
    t0 = default_window()[0] + 6 * 3600.0
    fwd = trainrun(track, eph, TrustRule.cutoff(10), 500.0, t0, SpeedProfile.constant(20.0),
                   step_s=10.0, duration_s=200.0)  # fmt: skip
    np.testing.assert_allclose(fwd.chainage_m, 500.0 + 20.0 * np.arange(21) * 10.0, atol=1e-6)
    np.testing.assert_allclose(fwd.gps_s, t0 + np.arange(21) * 10.0)
    back = trainrun(track, eph, TrustRule.cutoff(10), 5000.0, t0, SpeedProfile.constant(20.0),
                    step_s=10.0, direction=-1)  # fmt: skip
    assert np.all(np.diff(back.chainage_m) < 0)
    assert back.chainage_m[-1] == pytest.approx(0.0, abs=1e-6)  # runs to the start of the track
    assert fwd.count.min() >= 6 and np.all(np.isfinite(fwd.interval_m))


def test_trusted_satellites_rederived(track: TrackMap) -> None:
    eph = default_ephemeris()
    t0 = default_window()[0] + 15 * 3600.0
    run = trainrun(track, eph, TrustRule.cutoff(15), 1000.0, t0, SpeedProfile.constant(30.0),
                   step_s=30.0, duration_s=120.0, antenna_height_m=4.0)  # fmt: skip
    for k in (0, 4):
        lat, lon, h = track.position_at(run.chainage_m[k])
        topo = Transformer.from_pipeline(
            "+proj=pipeline +step +proj=topocentric +ellps=WGS84 "
            f"+lat_0={float(lat)} +lon_0={float(lon)} +h_0={float(h) + 4.0}"
        )
        pos, _, _ = eph.evaluate([run.gps_s[k]], run.sats)
        e, n, u = topo.transform(pos[0, :, 0], pos[0, :, 1], pos[0, :, 2])
        el = np.degrees(np.arctan2(u, np.hypot(e, n)))
        want = [s for s, x in zip(run.sats, el, strict=True) if np.isfinite(x) and x > 15.0]
        assert run.trusted_sats(k) == want
        assert run.count[k] == len(want)
    df = run.to_frame()
    assert list(df.columns)[:3] == ["gps_s", "chainage_m", "speed_mps"]
    assert df["sats"].iloc[0].split() == run.trusted_sats(0)
