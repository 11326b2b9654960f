"""End-to-end tests of the ``locator`` command line in a small synthetic canyon.

The world is two vertical rock walls beside a straight 600 m track (tests/locator/_scene.py);
the satellites are the real orbits of the embedded navigation day. Ground truth comes from the
simulator's ray casting: a signal is NLOS when the direct ray is blocked and a reflection is
tracked.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from locator.cli import main
from locator.runio import read_run
from locator.sathia import AntennaPath
from locator.sim.simfile import SignalState, SimRun
from locator.workflow import check_track
from predisat.gnss.errormodel import (
    Applicability,
    ErrorModel,
    IntervalModel,
    SystemModel,
    read_error_model,
    write_error_model,
)
from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH, IntegrityBudget
from predisat.track.map import demo_track
from tests.locator._scene import canyon_world


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    world = canyon_world()
    world.save(root / "world.npz")
    rc = main(["-q", "simulate", "--world", str(root / "world.npz"), "--duration", "40",
               "--speed", "10", "--seed", "3", "--out", str(root / "sim")])  # fmt: skip
    assert rc == 0
    return root / "sim"


def _nlos_used(epochs: pd.DataFrame, sim: SimRun) -> int:
    col = {s: k for k, s in enumerate(sim.sats)}
    return sum(
        sim.state[k, col[s]] == SignalState.NLOS
        for k, used in enumerate(epochs["used"])
        for s in str(used).split()
    )


def test_simulate_writes_a_run_with_truth_and_masks(sim_dir):
    sim = SimRun.read(sim_dir)
    assert sim.n_epoch == 41
    assert (sim_dir / "true_masks.parquet").is_file() and (sim_dir / "world.npz").is_file()
    # the canyon walls block and reflect: NLOS signals must be there for the next tests to bite
    assert (sim.state == SignalState.NLOS).sum() > 20


def test_masks_whose_open_sky_is_assumed_are_said_and_so_are_the_claims_that_used_it(
    sim_dir, tmp_path, capsys
):
    """A trial's masks with every bin ASSUMED at 0 deg claimed 71 % where the true masks
    claimed 29 %, and `locator run` said nothing (`predisat availability` warned)."""
    from dataclasses import replace

    from predisat.masks.fileformat import read_masks, write_masks
    from predisat.masks.maskset import BinSource

    true = read_masks(sim_dir / "true_masks.parquet")
    assumed = write_masks(replace(true, mask_el_deg=np.zeros_like(true.mask_el_deg),
                                  source=np.full_like(true.source, BinSource.ASSUMED)),
                          tmp_path / "assumed.masks.parquet")  # fmt: skip
    capsys.readouterr()
    assert main(["-q", "run", "--sim", str(sim_dir), "--masks", str(assumed), "--out",
                 str(tmp_path / "a")]) == 0  # fmt: skip
    out, err = capsys.readouterr()
    assert "100.0 % of the directions these masks leave open rest on an assumption" in err
    epochs, _ = read_run(tmp_path / "a")
    claims = int(epochs["claim"].sum())
    assert claims > 0
    assert f"claims on an assumption: {claims} of {claims} (100.0 %)" in out
    # the true masks (no ASSUMED bin open) say neither
    true_file = str(sim_dir / "true_masks.parquet")
    assert main(["-q", "run", "--sim", str(sim_dir), "--masks", true_file, "--out",
                 str(tmp_path / "t")]) == 0  # fmt: skip
    out, err = capsys.readouterr()
    assert "rest on an assumption" not in err and "claims on an assumption" not in out


def test_masks_beside_the_runs_map_need_the_same_track_said(sim_dir, tmp_path, capsys):
    """The simulation's own masks on its track moved 3 m sideways: the other track of a double
    line, or another map of this one; refused unless --masks-same-track says which."""
    from predisat.synth.world import World

    t = World.load(sim_dir / "world.npz").track
    s = np.arange(0.0, t.length_m, 5.0)
    lat, lon, h = t.position_at(s)
    hd = np.radians(t.heading_at(s))  # 3 m to the left of the direction of travel
    lat2 = lat + 3.0 * np.sin(hd) / 111_200.0
    lon2 = lon - 3.0 * np.cos(hd) / (111_200.0 * np.cos(np.radians(lat)))
    coords = [[float(a), float(b), float(c)] for a, b, c in zip(lon2, lat2, h, strict=True)]
    other = tmp_path / "B.geojson"
    other.write_text(json.dumps({"type": "FeatureCollection", "features": [{
        "type": "Feature", "properties": {"name": "B"},
        "geometry": {"type": "LineString", "coordinates": coords}}]}))  # fmt: skip
    base = ["-q", "run", "--sim", str(sim_dir), "--masks", str(sim_dir / "true_masks.parquet"),
            "--track", str(other)]  # fmt: skip
    capsys.readouterr()
    assert main([*base, "--out", str(tmp_path / "r1")]) == 2
    assert "lie 3.0 m right of track 'B'" in capsys.readouterr().err
    assert not (tmp_path / "r1").exists()
    assert main([*base, "--masks-same-track", "--out", str(tmp_path / "r2")]) == 0
    assert "taken as the same physical track, as asked" in capsys.readouterr().err


def test_run_with_true_masks_never_uses_nlos(sim_dir, tmp_path, capsys):
    sim = SimRun.read(sim_dir)
    assert main(["-q", "run", "--sim", str(sim_dir), "--no-masks", "--out",
                 str(tmp_path / "none")]) == 0  # fmt: skip
    none, meta = read_run(tmp_path / "none")
    assert len(none) == sim.n_epoch and meta["config"]["trust"] == "none"
    assert _nlos_used(none, sim) > 0  # without masks the receiver's NLOS signals get in
    masks = str(sim_dir / "true_masks.parquet")
    assert main(["-q", "run", "--sim", str(sim_dir), "--masks", masks, "--out",
                 str(tmp_path / "masks"), "--format", "csv"]) == 0  # fmt: skip
    masked, mmeta = read_run(tmp_path / "masks")
    assert _nlos_used(masked, sim) == 0
    from locator.partition import MAX_STRETCHES

    # partitioned trust by default, and the help says how many
    assert mmeta["config"]["trust_stretches"] == MAX_STRETCHES > 1
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert f"(default {MAX_STRETCHES}, locator.partition.MAX_STRETCHES" in " ".join(
        capsys.readouterr().out.split()
    )
    assert (tmp_path / "masks" / "epochs.csv").is_file()
    for name in ("interval_time.png", "interval_chainage.png", "interval_lengths.png"):
        assert (tmp_path / "masks" / name).stat().st_size > 5000

    assert main(["evaluate", str(tmp_path / "masks"), "--sim", str(sim_dir)]) == 0
    ev = json.loads((tmp_path / "masks" / "evaluation.json").read_text())
    scored = pd.read_csv(tmp_path / "masks" / "scored.csv")
    assert ev["epochs"] == sim.n_epoch
    # the rule the claims were drawn under stays with the scores
    assert ev["trust"] == "trust masks" and ev["claims"] == "safety claim"
    assert "integrity risk" in ev["interval_width"] or "k =" in ev["interval_width"]
    assert np.allclose(scored["truth_m"], sim.chainage_m)
    assert ev["hmi"] == int(((scored["claim"]) & ~scored["inside"]).sum())


def test_calibrate_learns_the_simulated_noise(sim_dir, tmp_path):
    out = tmp_path / "cal" / "model.json"  # a folder not made yet, as in docs/locator.md
    assert main(["calibrate", "--sim", str(sim_dir), "--out", str(out)]) == 0
    model = read_error_model(out)
    # the simulator draws direct-signal noise from ErrorModel() (a = b = 2 m: 3.46 m at 45 deg)
    # plus code multipath off the walls
    s45 = float(model.error.sigma_m(45.0))
    assert 2.5 < s45 < 6.0
    assert out.with_suffix(".png").is_file()
    assert main(["-q", "run", "--sim", str(sim_dir), "--cutoff", "15", "--error-model", str(out),
                 "--out", str(tmp_path / "cut")]) == 0  # fmt: skip
    _, meta = read_run(tmp_path / "cut")
    assert meta["config"]["locator"]["model"]["error"]["a_m"] == pytest.approx(model.error.a_m)
    # the default is the overbound of the least-squares estimate, which --bound estimate writes
    # a simulation's systems share one clock and one noise law: fitted together (pooled)
    written = json.loads(out.read_text())
    fitted = written["fitted"]
    assert fitted["bound"] == "overbound" and fitted["pooled_systems"] == "CEGJR"
    g = fitted["system_G"]
    assert g["factor"] >= 1.0 and g == fitted["system_E"]
    # it applies to simulated receivers, on the simulator's 'sim' code, from the elevations fitted
    app = written["applicability"]
    assert app["receivers"] == ["simulated"] and app["receiver_class"] == "simulated"
    assert written["systems"]["G"]["codes"] == ["sim"]
    assert written["systems"]["G"]["n_independent"] <= written["systems"]["G"]["n_residuals"]
    est = tmp_path / "estimate.json"
    assert main(["calibrate", "--sim", str(sim_dir), "--bound", "estimate", "--out", str(est)]) == 0
    estimate = read_error_model(est).error
    assert estimate.a_m == pytest.approx(g["estimate"]["a_m"])
    assert model.error.b_m == pytest.approx(estimate.b_m * g["factor"])


def test_calibrate_takes_several_observation_files(test_data, tmp_path, capsys):
    obs = str(test_data / "gnss_obs" / "07590920_10ep.05o")
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    out = tmp_path / "m.json"
    # ten epochs are too few to check six bins' tails: the message says what to do
    assert main(["calibrate", "--obs", obs, "--nav", nav, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--bound estimate" in err and "--obs" in err
    assert main(["calibrate", "--obs", obs, "--nav", nav, "--bound", "estimate",
                 "--out", str(out)]) == 0  # fmt: skip
    one = json.loads(out.read_text())["fitted"]["residuals"]
    # an estimate checks no tail: it claims no count of independent samples (a trial: it
    # printed its residual count as one)
    said = capsys.readouterr().out
    assert "independence not assessed" in said and " independent)" not in said
    assert "for receiver TRIMBLE 5700 / antenna" in said
    # two files, the first and the last five epochs (as two sessions of one station would
    # be): their residuals add up to the whole file's
    from locator.observations import read_rinex_obs

    lines = Path(obs).read_text().splitlines(keepends=True)
    cut = int(read_rinex_obs(obs).epoch_line[5]) - 1  # the sixth epoch's first line
    head = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    halves = [tmp_path / "a.05o", tmp_path / "b.05o"]
    halves[0].write_text("".join(lines[:cut]))
    halves[1].write_text("".join(lines[:head] + lines[cut:]))
    assert main(["calibrate", "--obs", *map(str, halves), "--nav", nav, "--bound", "estimate",
                 "--out", str(out)]) == 0  # fmt: skip
    fitted = json.loads(out.read_text())["fitted"]
    assert fitted["residuals"] == one and len(fitted["station_ecef_m"]) == 2
    # one file given twice would weigh double: refused, and so is a copy of it (the same
    # station's epochs under another name)
    assert main(["calibrate", "--obs", obs, obs, "--nav", nav, "--out", str(out)]) == 2
    assert "given twice" in capsys.readouterr().err
    shutil.copy(obs, tmp_path / "copy.05o")
    argv = ["calibrate", "--obs", obs, str(tmp_path / "copy.05o"), "--nav", nav, "--out", str(out)]
    assert main(argv) == 2
    assert "hold 10 epochs of the same station" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # refused by the parser, before any work
        # an existing --sim: a missing one would be the error (its one line names no --k-sigma)
        main(["calibrate", "--sim", str(out.parent), "--k-sigma", "0", "--out", str(out)])
    assert exc.value.code == 2 and "argument --k-sigma" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # --station is one position: refused by the parser
        main(["calibrate", "--obs", str(halves[0]), str(halves[1]), "--nav", nav,
              "--station", "1", "2", "3", "--out", str(out)])  # fmt: skip
    assert exc.value.code == 2 and "--station is for one --obs file" in capsys.readouterr().err


def test_calibrate_refuses_a_station_in_km_or_far_from_the_truth(test_data, tmp_path, capsys):
    from locator.observations import Observations

    obs = str(test_data / "gnss_obs" / "07590920_10ep.05o")
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    out = tmp_path / "m.json"
    head = Observations.from_rinex(obs).header.approx_position_ecef_m
    base = ["calibrate", "--obs", obs, "--nav", nav, "--bound", "estimate", "--out", str(out)]
    # the header's position in km: named as such, nothing written
    assert main([*base, "--station", *(f"{v / 1000:.4f}" for v in head)]) == 2
    assert "did you give kilometres" in capsys.readouterr().err and not out.exists()
    # 3 km east of the truth: the residuals are kilometres, no receiver's noise; refused
    east = head + 3000.0 * np.array([-np.sin(np.arctan2(head[1], head[0])),
                                     np.cos(np.arctan2(head[1], head[0])), 0.0])  # fmt: skip
    assert main([*base, "--station", *(f"{v:.3f}" for v in east)]) == 2
    err = capsys.readouterr().err
    assert "3000 m from the approximate position" in err and "is wrong" in err
    assert not out.exists() and not out.with_suffix(".png").exists()
    # the header's own position is accepted, without a warning
    assert main([*base, "--station", *(f"{v:.3f}" for v in head)]) == 0
    assert "warning" not in capsys.readouterr().err and out.exists()


def test_calibrate_takes_the_antenna_delta_and_refuses_a_phone_declared_geodetic(
    test_data, tmp_path, capsys
):
    """User trials: a header's 1.5 m ANTENNA: DELTA H/E/N changed nothing (the model fitted at
    the marker); a phone's RINEX file declared geodetic was taken for one."""
    from locator.observations import Observations

    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    head = Observations.from_rinex(obs).header.approx_position_ecef_m
    lines = obs.read_text().splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if "ANTENNA: DELTA H/E/N" in ln)
    lines[k] = f"{1.5:14.4f}{0.0:14.4f}{0.0:14.4f}".ljust(60) + "ANTENNA: DELTA H/E/N\n"
    raised = tmp_path / "delta.05o"
    raised.write_text("".join(lines))
    base = ["calibrate", "--nav", nav, "--bound", "estimate"]
    assert main([*base, "--obs", str(raised), "--out", str(tmp_path / "a.json")]) == 0
    assert "1.5 m up" in capsys.readouterr().err
    up = head / np.linalg.norm(head)  # within 0.2 deg of the ellipsoid's normal here
    from predisat.geodesy import ecef_to_geodetic, enu_rotation

    lat, lon, _ = ecef_to_geodetic(head)
    arp = head + 1.5 * enu_rotation(lat, lon)[2]
    assert np.dot(arp - head, up) > 1.49
    assert main([*base, "--obs", str(obs), "--station", *(f"{v:.4f}" for v in arp),
                 "--out", str(tmp_path / "b.json")]) == 0  # fmt: skip
    a = json.loads((tmp_path / "a.json").read_text())["fitted"]
    b = json.loads((tmp_path / "b.json").read_text())["fitted"]
    np.testing.assert_allclose(a["station_ecef_m"], b["station_ecef_m"], atol=1e-3)
    assert a["residuals"] == b["residuals"]
    phone = str(test_data / "gnss_obs" / "android_rinex_obs_pixel6_6ep.23o")
    assert main([*base, "--obs", phone, "--receiver-class", "geodetic",
                 "--out", str(tmp_path / "p.json")]) == 2  # fmt: skip
    assert "written by a phone" in capsys.readouterr().err
    # the reverse (a user trial): a geodetic station declared phone made a phone-class model,
    # which then claimed on phone logs by their class alone and gave a hazardous epoch
    assert main([*base, "--obs", str(obs), "--receiver-class", "phone",
                 "--out", str(tmp_path / "q.json")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "'TRIMBLE 5700'" in err and "not recognised as a phone" in err
    assert not (tmp_path / "q.json").exists()


def test_calibrate_refuses_a_reference_station_declared_automotive(test_data, tmp_path, capsys):
    """A review: a geodetic station's residuals made an automotive-class model, which any
    automotive receiver would then use by its class alone, with a station's tight sigma."""
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    base = ["calibrate", "--nav", nav, "--bound", "estimate", "--receiver-class", "automotive"]
    assert main([*base, "--obs", str(obs), "--out", str(tmp_path / "a.json")]) == 2
    err = capsys.readouterr().err
    assert "'TRIMBLE 5700', a reference-station receiver" in err
    assert "--receiver-class geodetic" in err and not (tmp_path / "a.json").exists()
    lines = obs.read_text().splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if "REC # / TYPE / VERS" in ln)

    def variant(name: str, receiver: str, marker_type: str) -> str:
        out = list(lines)
        out[k] = f"{'00000':<20}{receiver:<20}{'1.0':<20}REC # / TYPE / VERS\n"
        out.insert(k, f"{marker_type:<60}MARKER TYPE\n")
        (tmp_path / name).write_text("".join(out))
        return str(tmp_path / name)

    # an automotive receiver on a surveyed pillar (MARKER TYPE GEODETIC: the monument's, a
    # review): the natural way to calibrate one, accepted with the user's class
    car = variant("car.05o", "UBLOX ZED-F9P", "GEODETIC")
    assert main([*base, "--obs", car, "--out", str(tmp_path / "c.json")]) == 0
    app = json.loads((tmp_path / "c.json").read_text())["applicability"]
    assert app["receiver_class"] == "automotive" and app["receivers"] == ["UBLOX ZED-F9P"]
    # and a station receiver is refused whatever its marker says
    geo = variant("geo.05o", "SEPT POLARX5", "NON_GEODETIC")
    assert main([*base, "--obs", geo, "--out", str(tmp_path / "b.json")]) == 2
    assert "'SEPT POLARX5', a reference-station receiver" in capsys.readouterr().err
    # and the station itself may still be declared what it is
    geodetic = [*base[:-1], "geodetic", "--obs", str(obs), "--out", str(tmp_path / "d.json")]
    assert main(geodetic) == 0


def test_errors_are_one_line_messages(sim_dir, tmp_path, capsys):
    # a missing trust rule, input file or source: refused by the parser, before any work
    for argv, expected in [
        (["--sim", str(sim_dir)], "one of the arguments --masks --cutoff --no-masks is required"),
        (["--sim", str(sim_dir), "--no-masks", "--error-model", str(tmp_path / "missing.json")],
         "locator calibrate"),
        (["--no-masks"], "one of the arguments --sim --obs --device-gnss is required"),
        (["--sim", str(sim_dir), "--no-masks", "--trust-stretches", "2"],
         "--trust-stretches is for --masks runs"),
        (["--sim", str(sim_dir), "--masks", str(sim_dir / "true_masks.parquet"),
          "--trust-stretches", "0"], "argument --trust-stretches: 0 must be 1 or more"),
    ]:  # fmt: skip
        with pytest.raises(SystemExit) as exc:
            main(["run", *argv, "--out", str(tmp_path / "x")])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert expected in err and err.count("error:") == 1 and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_a_run_on_another_track_is_refused(sim_dir):
    sim = SimRun.read(sim_dir)
    with pytest.raises(ValueError, match="away from track"):
        check_track(AntennaPath(demo_track(), 4.0), sim.antenna_ecef_m, "sim")


def _virtual_track(path):
    """A straight 2 km track through GEONET 0759's known position (chainage 1000 m there)."""
    from predisat.geodesy import LocalFrame, ecef_to_geodetic

    station = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # GEONET 0759
    lat, lon, h = (float(v) for v in ecef_to_geodetic(station))
    d = np.linspace(-1000.0, 1000.0, 21)
    la, lo, hh = LocalFrame(lat, lon, h).to_geodetic(
        np.stack([d * np.sin(0.7), d * np.cos(0.7), np.zeros_like(d)], -1)
    )
    pd.DataFrame({"lat_deg": la, "lon_deg": lo, "h_m": hh}).to_csv(path, index=False)
    return path


def test_rinex_run_refuses_a_wrong_track_or_masks_and_tells_skipped_epochs(
    test_data, tmp_path, capsys
):
    from predisat.masks.fileformat import write_masks
    from predisat.masks.maskset import MaskSet

    track = _virtual_track(tmp_path / "virtual.csv")
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    run = ["run", "--obs", str(obs), "--nav", str(nav), "--antenna-height", "0"]
    # no --track: the default line 144, about 9000 km from a Japanese station
    assert main([*run, "--no-masks", "--out", str(tmp_path / "a")]) == 2
    assert "away from track" in capsys.readouterr().err
    # masks of line 144 on the station's track
    line = demo_track()
    ch = np.array([4000.0, 4010.0])
    lat, lon, _ = line.position_at(ch)
    m = MaskSet.from_arrays(ch, lat, lon, 0.0, line.heading_at(ch), np.zeros((2, 360)))
    masks = write_masks(m, tmp_path / "l144.masks.parquet")
    out = ["--out", str(tmp_path / "b")]
    assert main([*run, "--track", str(track), "--masks", str(masks), *out]) == 2
    assert "do not fit track" in capsys.readouterr().err
    # a file cut inside its last epoch record: the dropped epoch is told
    lines = obs.read_text().splitlines(keepends=True)
    cut = tmp_path / "cut.05o"
    cut.write_text("".join(lines[:-3]))
    assert main(["-q", *run, "--track", str(track), "--no-masks", *out]) == 0
    run_cut = ["run", "--obs", str(cut), "--nav", str(nav), "--antenna-height", "0"]
    assert main(["-q", *run_cut, "--track", str(track), "--no-masks",
                 "--out", str(tmp_path / "c")]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "cut.05o: 1 record(s) skipped" in err and "epoch dropped" in err
    assert len(read_run(tmp_path / "c")[0]) == len(read_run(tmp_path / "b")[0]) - 1
    # navigation data of another day (2010 records for a 2005 station file): nothing to do
    other_day = test_data / "gnss" / "brdc1820_G01G02G05.10n"
    bad_nav = ["--obs", str(obs), "--nav", str(other_day), "--out", str(tmp_path / "e.json")]
    for argv in (["run", *bad_nav[:4], "--track", str(track), "--no-masks", "--out",
                  str(tmp_path / "d")], ["calibrate", *bad_nav]):  # fmt: skip
        assert main(argv) == 2
        msg = capsys.readouterr().err
        assert "lie outside the navigation data" in msg and "2010-07-01" in msg


@pytest.mark.parametrize("dh_m", [-45.0, 30.0])
def test_a_track_at_the_wrong_height_is_refused(test_data, tmp_path, capsys, dh_m):
    """A map without heights, or with heights above the geoid (45 m in Belgium), put the
    locator's fixes tens of metres off (a geometry review); the receiver's own fixes, a few
    metres good in height, tell. The height of the station, independent of the code, is
    GEONET's published position (_virtual_track)."""
    track = _virtual_track(tmp_path / "virtual.csv")
    df = pd.read_csv(track)
    df.assign(h_m=df["h_m"] + dh_m).to_csv(tmp_path / "low.csv", index=False)
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    args = ["run", "--track", str(tmp_path / "low.csv"), "--obs", str(obs), "--nav", str(nav),
            "--no-masks", "--antenna-height", "0", "--out", str(tmp_path / "low")]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err
    told = re.search(r"fixes lie ([\d.]+) m (above|below) its antenna", err)
    assert told, err
    assert abs(float(told[1]) - abs(dh_m)) <= 3 and told[2] == ("above" if dh_m < 0 else "below")
    assert "at most 20 m is accepted" in err and "ellipsoidal heights" in err
    assert ("too low" if dh_m < 0 else "too high") in err and not (tmp_path / "low").exists()
    # the same track without heights: said so
    df.assign(h_m=0.0).to_csv(tmp_path / "flat.csv", index=False)
    args[2] = str(tmp_path / "flat.csv")
    assert main(args) == 2
    assert "the track map has no heights (h = 0 everywhere)" in capsys.readouterr().err
    # the track at its height, the antenna said to stand 4 m above it: within the bound, but
    # beyond the 1 m of vertical map doubt the intervals are widened for: said (a user trial,
    # 2026-12-07: 4.4 m, nothing said); at its true height, nothing said
    ok = ["-q", "run", "--track", str(track), "--obs", str(obs), "--nav", str(nav),
          "--no-masks", "--antenna-height", "4", "--out", str(tmp_path / "ok")]  # fmt: skip
    assert main(ok) == 0
    err = capsys.readouterr().err
    told = re.search(r"own fixes\) lie ([\d.]+) m below the antenna on the track", err)
    assert told and 2.5 < float(told[1]) < 5.5 and "1 m of vertical map doubt" in err, err
    ok[ok.index("--antenna-height") + 1] = "0"
    ok[-1] = str(tmp_path / "ok0")
    assert main(ok) == 0
    assert "own fixes) lie" not in capsys.readouterr().err


def test_rinex_runs_refuse_shifted_time_tags_and_say_when_they_could_not_check_them(
    test_data, tmp_path, capsys, monkeypatch
):
    """Tags 100 ms late (a converter's): 24 hazardous claims in 24 for a trial, now refused
    in one line; six satellites leave the tags unchecked, and the run says so."""
    track = _virtual_track(tmp_path / "virtual.csv")
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    lines = obs.read_text().splitlines(keepends=True)
    late = []
    for line in lines:  # RINEX 2 epoch lines: " yy mm dd hh mm ss.sssssss  f nnGnnGnn..."
        if line.startswith(" 05  4  2"):
            sec = float(line[15:26]) + 0.1
            line = line[:15] + f"{sec:11.7f}" + line[26:]
        late.append(line)
    (tmp_path / "late.05o").write_text("".join(late))
    run = ["run", "--nav", str(nav), "--track", str(track), "--no-masks",
           "--antenna-height", "0"]  # fmt: skip
    capsys.readouterr()
    assert main([*run, "--obs", str(tmp_path / "late.05o"), "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert re.search(r"time tags disagree with their pseudoranges by -(9\d|10\d)\.\d ms", err)
    assert err.count("\n") == 1
    # the clean file: checked on its 10 epochs, nothing said; asked for 11, said
    assert main(["-q", *run, "--obs", str(obs), "--out", str(tmp_path / "b")]) == 0
    assert "could not be checked" not in capsys.readouterr().err
    monkeypatch.setattr("locator.timetag.MIN_EVIDENCE_EPOCHS", 11)
    assert main(["-q", *run, "--obs", str(obs), "--out", str(tmp_path / "c")]) == 0
    assert "time tags could not be checked against its pseudoranges (10 of" in (
        capsys.readouterr().err
    )


def test_epochs_left_without_a_code_by_a_change_of_observation_types_are_told(
    test_data, tmp_path, capsys
):
    """A header record (event flag 4) that drops C1 mid-file: half a trial's run had no fix,
    and nothing said why."""
    track = _virtual_track(tmp_path / "virtual.csv")
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    lines = obs.read_text().splitlines(keepends=True)
    epochs = [k for k, line in enumerate(lines) if line.startswith(" 05  4  2")]
    out = lines[: epochs[6]]
    out += ["                            4  1\n",
            "     3    L1    L2    P2" + " " * 36 + "# / TYPES OF OBSERV\n"]  # fmt: skip
    for line in lines[epochs[6]:]:
        if line.startswith(" 05  4  2"):
            out.append(line)
        else:  # the record's fields are 16 wide: L1 C1 L2 P2 -> L1 L2 P2
            out.append(line[:16] + line[32:])
    (tmp_path / "noc1.05o").write_text("".join(out))
    assert main(["-q", "run", "--obs", str(tmp_path / "noc1.05o"), "--nav", str(nav),
                 "--track", str(track), "--no-masks", "--antenna-height", "0",
                 "--out", str(tmp_path / "r")]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert re.search(r"noc1\.05o: warning: 4 of 10 epochs \(the first at line \d+\) after the "
                     r"header record at line \d+ \(event flag 4\) that changed the observation "
                     r"types have no pseudorange of the codes the locator reads \(G: C1C", err)


def test_run_on_real_rinex_through_a_virtual_track(test_data, tmp_path, capsys):
    """GEONET 0759 (10 epochs, GPS C1) on a straight track through its known position."""
    track = _virtual_track(tmp_path / "virtual.csv")
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    args = ["-q", "run", "--track", str(track), "--obs", str(obs), "--nav", str(nav),
            "--no-masks", "--antenna-height", "0", "--out", str(tmp_path / "real")]  # fmt: skip
    assert main(args) == 0
    ep, meta = read_run(tmp_path / "real")
    assert len(ep) == 10 and meta["source"]["source"] == "rinex"
    # the start came from the header position projected on the track: the middle, 1000 m
    # the built-in model is the simulator's: no safety claim on a real receiver, positions
    # given and flagged, the message says which model is missing and how to make one
    assert (ep["n_used"] >= 6).all() and not ep["claim"].any()
    assert ep["flag_names"].str.contains("NO_ERROR_MODEL").all()
    cap = capsys.readouterr()
    err = cap.err
    assert "NO SAFETY CLAIM" in err and "TRIMBLE 5700" in err and "locator calibrate" in err
    # 30 s epochs on a 2 km map: the prediction (45 m/s x 30 s) reaches past its ends, said
    # with the reason (a user trial took the flag for a defect)
    at_end = int(ep["flag_names"].str.contains("TRACK_END").sum())
    assert at_end >= 5
    assert f"past an end of the track map in {at_end} of 10 epochs" in cap.out
    assert "(30 s here: 1350 m)" in cap.out
    # SATHIA on real single-frequency ranges: within a few metres of the station
    assert np.abs(ep["chainage_m"] - 1000.0).max() < 5.0
    assert ((ep["lo_m"] <= 1000.0) & (1000.0 <= ep["hi_m"])).all()
    assert main(["evaluate", str(tmp_path / "real"), "--truth-chainage", "1000"]) == 0
    assert "epochs 10" in capsys.readouterr().out
    # a model stating this receiver, antenna and code, its tails checked deeper than the
    # default budget's widest pair interval, claims; another antenna does not
    e = ErrorModel(2.0, 2.0)

    def model(name: str, antenna: str, tail: float = 1e-13) -> str:
        app = Applicability(("TRIMBLE 5700",), (antenna,), el_min_deg=5.0)
        sys_g = {"G": SystemModel(e, ("C1",), 1000, 100, tail)}
        return str(write_error_model(tmp_path / name, IntervalModel(e), systems=sys_g,
                                     applicability=app))  # fmt: skip

    for name, antenna, claims in (("same.json", "TRM29659.00", True),
                                  ("other.json", "LEIAR25.R3      LEIT", False)):  # fmt: skip
        run = str(tmp_path / f"run_{name}")
        assert main([*args[:-1], run, "--error-model", model(name, antenna)]) == 0
        ep, meta = read_run(run)
        assert ep["claim"].all() == claims and ep["claim"].any() == claims
        assert meta["config"]["model_el_min_deg"] == 5.0
    assert "antenna 'TRM29659.00' is not among" in capsys.readouterr().err
    # the same model checked only to 0.05 per pseudorange (k 1.96): the budget's k, up to 7.13
    # lies beyond it, so no claim unless the Gaussian tail is assumed, or a k within it asked
    shallow = model("shallow.json", "TRM29659.00", 0.05)
    # a claim may rest on one disjoint pair (blunt pairs dropped from a union of 4-5)
    k_deep = IntegrityBudget(DEFAULT_RISK_PER_EPOCH).k_sigma(1)
    for extra, claims, flag in (([], False, "NO_ERROR_MODEL"),
                                (["--assume-gaussian-tail"], True, "GAUSSIAN_TAIL"),
                                (["--k-sigma", "1.9"], True, None)):  # fmt: skip
        run = str(tmp_path / f"shallow{len(extra)}")
        assert main([*args[:-1], run, "--error-model", shallow, *extra]) == 0
        ep, meta = read_run(run)
        assert ep["claim"].all() == claims and ep["claim"].any() == claims
        # a fixed k is a width the user chose: its claims are no safety claims, in the table too
        assert (ep["safety_claim"] == (ep["claim"] & (extra[:1] != ["--k-sigma"]))).all()
        rec = meta["error_model"]
        assert rec["file"] == shallow and rec["systems"]["G"]["tail_probability"] == 0.05
        if flag is None:
            assert rec["use"] == "calibrated" and not rec["depth_shortfall"]
            assert not ep["flag_names"].str.contains("GAUSSIAN_TAIL|NO_ERROR_MODEL").any()
        else:
            assert ep["flag_names"].str.contains(flag).all()
            assert rec["k_sigma_max"] == pytest.approx(k_deep, abs=1e-4)
            assert "checked to 0.05 per pseudorange" in rec["depth_shortfall"][0]
    out, err = capsys.readouterr()
    assert "NO SAFETY CLAIM" in err and "--assume-gaussian-tail" in err
    assert "safety claim under the assumed Gaussian tail 100.0 %" in out
    assert "was calibrated on" not in err
    # a model made from this very file: its claims are no independent check, and it is said
    app = Applicability(("TRIMBLE 5700",), ("TRM29659.00",), el_min_deg=5.0, sources=(str(obs),))
    own = write_error_model(tmp_path / "own.json", IntervalModel(e), applicability=app,
                            systems={"G": SystemModel(e, ("C1",), 1000, 100, 1e-13)})  # fmt: skip
    assert main([*args[:-1], str(tmp_path / "own"), "--error-model", str(own)]) == 0
    assert "was calibrated on" in capsys.readouterr().err
    assert read_run(tmp_path / "own")[1]["error_model"]["calibrated_on_this_data"] is True
    # a locator-error-model/1 file says nothing of what it was calibrated for: no claim unless
    # forced, and the message says so
    old = tmp_path / "v1.json"
    old.write_text(json.dumps({"format": "locator-error-model/1", "a_m": 2.0, "b_m": 2.0,
                               "min_el_deg": 1.0, "k_sigma": 2.0}))  # fmt: skip
    assert main([*args[:-1], str(tmp_path / "v1"), "--error-model", str(old)]) == 0
    assert not read_run(tmp_path / "v1")[0]["claim"].any()
    assert "locator-error-model/1" in capsys.readouterr().err
    assert main([*args[:-1], str(tmp_path / "v1f"), "--error-model", str(old),
                 "--force-error-model"]) == 0  # fmt: skip
    ep, meta = read_run(tmp_path / "v1f")
    # forced: intervals given, but recorded and flagged as what they are, never a safety claim
    assert ep["claim"].all() and ep["flag_names"].str.contains("FORCED_ERROR_MODEL").all()
    assert not ep["safety_claim"].any()  # the table alone must not read as safety claims
    assert meta["error_model"]["use"] == "forced" and meta["error_model"]["mismatches"]
    assert meta["config"]["error_model_caveat"] == "forced"
    out, err = capsys.readouterr()
    assert "--force-error-model" in err and "NOT A SAFETY CLAIM" in err
    assert "not a safety claim) 100.0 %" in out and "epochs: safety claim" not in out
    assert main(["evaluate", str(tmp_path / "v1f"), "--truth-chainage", "1000"]) == 0
    assert "intervals under a forced error model (not a safety claim)" in capsys.readouterr().out


def test_start_and_truth_chainages_off_the_track_or_masks_are_refused(sim_dir, tmp_path, capsys):
    from predisat.masks.fileformat import read_masks, write_masks

    sim = SimRun.read(sim_dir)
    length_m = AntennaPath(canyon_world().track, 4.0).length_m
    base = ["run", "--sim", str(sim_dir), "--out", str(tmp_path / "r")]
    assert main([*base, "--no-masks", "--start-chainage", str(length_m + 500)]) == 2
    assert "off track" in capsys.readouterr().err
    # masks of a stretch that does not hold the start: nothing could be trusted there
    true = read_masks(sim_dir / "true_masks.parquet")
    lo_m = sim.chainage_m[0] + 300.0
    assert lo_m < true.chainage_m.max()
    part = write_masks(true.subset(lo_m, np.inf), tmp_path / "part.masks.parquet")
    assert main([*base, "--masks", str(part)]) == 2
    err = capsys.readouterr().err
    assert "never enters the masks" in err and "part.masks.parquet" in err
    assert not (tmp_path / "r").exists()  # refused before writing anything
    # a train starting before the masks and running into them: told, then run
    ahead = write_masks(true.subset(sim.chainage_m[0] + 100.0, np.inf), tmp_path / "a.parquet")
    assert main(["-q", *base[:-1], str(tmp_path / "ahead"), "--masks", str(ahead)]) == 0
    assert "warning: start chainage" in capsys.readouterr().err
    # a truth chainage off the run's track is refused and the evaluation left as it was
    assert main(["-q", *base, "--no-masks"]) == 0
    assert main(["evaluate", str(tmp_path / "r"), "--sim", str(sim_dir)]) == 0
    before = (tmp_path / "r" / "evaluation.json").read_text()
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "r"), "--truth-chainage", "99999"]) == 2
    assert "off track" in capsys.readouterr().err
    assert (tmp_path / "r" / "evaluation.json").read_text() == before


def test_far_receiver_is_told_its_true_distance(test_data, tmp_path, capsys):
    from pyproj import Transformer

    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    run = ["run", "--obs", str(obs), "--nav", str(nav), "--no-masks", "--antenna-height", "0"]
    assert main([*run, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    km = float(err.split("the antenna is ")[1].split(" km away")[0])
    # independent reference: PROJ's geodetic-to-ECEF of the line's middle, chord to the station
    line = demo_track()
    lat, lon, h = line.position_at(line.length_m / 2)
    to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
    mid = np.array(to_ecef.transform(float(lon), float(lat), float(h)))
    station = np.array([-3976219.5082, 3382372.5671, 3652512.9849])  # GEONET 0759
    assert km == pytest.approx(np.linalg.norm(station - mid) / 1000, rel=0.01)
    # an explicit start overrides the header, with a warning instead of a silent run
    assert main(["-q", *run, "--start-chainage", "4500", "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and " km away from track" in err and "running from --start" in err


def test_ctrl_c_is_one_line_not_a_traceback(sim_dir, tmp_path, capsys, monkeypatch):
    import locator.workflow as wf

    def ctrl_c_in_numba(*_, **__):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher returned a result with an exception set") from exc

    monkeypatch.setattr(wf, "run_to_folder", ctrl_c_in_numba)
    code = main(["-q", "run", "--sim", str(sim_dir), "--no-masks", "--out", str(tmp_path / "r")])
    assert code == 130
    assert "locator: interrupted" in capsys.readouterr().err


def test_rinex_run_without_any_iono_model_warns_once_and_flags_epochs(
    test_data, tmp_path, capsys
):
    track = _virtual_track(tmp_path / "virtual.csv")
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav_lines = (test_data / "gnss_obs" / "07590920_0000_0200.05n").read_text().splitlines(True)
    nav = tmp_path / "no_iono.05n"
    nav.write_text("".join(t for t in nav_lines if "ION ALPHA" not in t and "ION BETA" not in t))
    run = ["-q", "run", "--obs", str(obs), "--antenna-height", "0", "--track", str(track),
           "--no-masks"]  # fmt: skip
    assert main([*run, "--nav", str(nav), "--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert err.count("no broadcast ionosphere model for G") == 1 and "iono_uncorrected" in err
    assert read_run(tmp_path / "a")[0]["iono_uncorrected"].all()
    nav_ok = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    assert main([*run, "--nav", str(nav_ok), "--out", str(tmp_path / "b")]) == 0
    assert "ionosphere" not in capsys.readouterr().err
    assert not read_run(tmp_path / "b")[0]["iono_uncorrected"].any()


def test_run_draws_its_intervals_for_the_integrity_risk(sim_dir, tmp_path, capsys, monkeypatch):
    from scipy.stats import norm

    masks = str(sim_dir / "true_masks.parquet")
    base = ["-q", "run", "--sim", str(sim_dir), "--masks", masks]
    assert main([*base, "--integrity-risk", "1e-7", "--out", str(tmp_path / "r")]) == 0
    assert "integrity risk 1e-07 per epoch" in capsys.readouterr().out
    _, meta = read_run(tmp_path / "r")
    assert meta["config"]["locator"]["budget"] == {"risk_per_epoch": 1e-7}
    assert f"k = {norm.isf((1e-7 / 2) ** (1 / 3)):.2f} (three pairs)" in meta["interval_width"]
    assert main([*base, "--out", str(tmp_path / "d")]) == 0  # the default budget
    assert read_run(tmp_path / "d")[1]["config"]["locator"]["budget"] == {"risk_per_epoch": 1e-12}
    capsys.readouterr()
    assert main([*base, "--k-sigma", "2", "--out", str(tmp_path / "k")]) == 0
    _, meta = read_run(tmp_path / "k")
    assert meta["config"]["locator"]["budget"] is None
    assert meta["config"]["locator"]["model"]["k_sigma"] == 2.0
    # a width the user chose is no stated risk: its claims are not worded "safety claim"
    out = capsys.readouterr().out
    assert "epochs: claim at a fixed k = 2 (no integrity budget)" in out
    assert "safety claim" not in out
    assert main(["evaluate", str(tmp_path / "k"), "--sim", str(sim_dir)]) == 0
    out = capsys.readouterr().out
    assert "claim at a fixed k = 2 (no integrity budget)" in out and "safety claim" not in out
    # and what evaluation.json (and the figures' caption) records of them
    ev = json.loads((tmp_path / "k" / "evaluation.json").read_text())
    assert ev["claims"] == "claim at a fixed k = 2 (no integrity budget)"
    assert main(["evaluate", str(tmp_path / "d"), "--sim", str(sim_dir)]) == 0
    assert "safety claim" in capsys.readouterr().out
    for bad in (["--integrity-risk", "1e-7", "--k-sigma", "2"], ["--integrity-risk", "5"]):
        with pytest.raises(SystemExit) as exc:
            main([*base, *bad, "--out", str(tmp_path / "x")])
        assert exc.value.code == 2 and "--integrity-risk" in capsys.readouterr().err
    # the demo takes the same setting and hands it to its runs
    import locator.workflow

    seen = {}
    monkeypatch.setattr(locator.workflow, "demo",
                        lambda *a, **kw: seen.update(kw) or (_ for _ in ()).throw(SystemExit(0)))
    with pytest.raises(SystemExit):
        main(["demo", "--out", str(tmp_path / "demo"), "--integrity-risk", "1e-6"])
    assert seen["integrity"].risk_per_epoch == 1e-6


def test_a_library_warning_is_one_line_under_the_command(sim_dir, tmp_path, capsys):
    from predisat.masks.fileformat import read_masks, write_masks
    from predisat.masks.maskset import concat_masksets

    full = read_masks(sim_dir / "true_masks.parquet")
    ch = full.chainage_m
    a, b = float(ch[len(ch) // 3]), float(ch[2 * len(ch) // 3])
    holed = write_masks(concat_masksets([full.subset(-1e9, a), full.subset(b, 1e9)]),
                        tmp_path / "holed.parquet")  # fmt: skip
    capsys.readouterr()
    assert main(["-q", "run", "--sim", str(sim_dir), "--masks", str(holed), "--out",
                 str(tmp_path / "r")]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert f"locator: warning: {holed}: 1 hole(s) between its positions" in err
    assert "MaskHoleWarning" not in err and "warnings.warn" not in err


def test_a_rinex_run_over_two_systems_is_refused_before_any_work(test_data, tmp_path, capsys):
    """A user trial: GPS + Galileo pairs at NYA1 (2.6 m of inter-system bias) gave a hazardous
    misleading interval that neither system alone gave; the pairs cancel one clock only."""
    obs = test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx"
    nav = test_data / "gnss" / "KMS300DNK_R_20221591000_01H_MN.rnx.gz"
    argv = ["run", "--obs", str(obs), "--nav", str(nav), "--no-masks", "--antenna-height", "0",
            "--constellation", "gps+galileo", "--out", str(tmp_path / "ge")]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "2 systems (E, G)" in err and "inter-system bias" in err and "--constellation" in err
    assert not (tmp_path / "ge").exists()


def test_a_rinex_file_without_an_epoch_is_named_not_a_numpy_error(test_data, tmp_path, capsys):
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    lines = obs.read_text().splitlines(keepends=True)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line)
    for name, text, what in (("head.05o", "".join(lines[: end + 3]), "no complete observation"),
                             ("empty.05o", "", "the file is empty")):  # fmt: skip
        (tmp_path / name).write_text(text)
        argv = ["run", "--obs", str(tmp_path / name), "--nav", str(nav), "--no-masks",
                "--out", str(tmp_path / "x")]  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert name in err and what in err and "zero-size" not in err


def test_run_refuses_sp3_or_tle_for_navigation_naming_what_it_needs(test_data, tmp_path, capsys):
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    for nav in (test_data / "gnss" / "igs15904_G01G02G05.sp3",
                test_data / "gnss" / "TLE_GNSS_20121101.txt"):  # fmt: skip
        argv = ["run", "--obs", str(obs), "--nav", str(nav), "--no-masks",
                "--out", str(tmp_path / "x")]  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert nav.name in err and "broadcast RINEX navigation" in err


def test_quiet_after_the_subcommand_and_a_phone_log_given_as_rinex(test_data, tmp_path, capsys):
    """A user trial: `locator run ... -q` was refused, and a device_gnss CSV given to --obs got
    no hint of --device-gnss."""
    from locator.cli import build_parser

    args = build_parser().parse_args(["evaluate", str(tmp_path), "--truth-chainage", "0", "-q"])
    assert args.quiet is True
    truth = ["--truth-chainage", "0"]
    assert build_parser().parse_args(["-q", "evaluate", str(tmp_path), *truth]).quiet is True
    assert build_parser().parse_args(["evaluate", str(tmp_path), *truth]).quiet is False
    phone = test_data / "gsdc" / "gdc2023_pixel7pro_device_gnss_2ep.csv"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    assert main(["run", "--obs", str(phone), "--nav", str(nav), "--no-masks",
                 "--out", str(tmp_path / "x")]) == 2  # fmt: skip
    assert "give it with --device-gnss" in capsys.readouterr().err


def _lead_in_map(track, lead_m: float, path: Path, reverse: bool = False) -> Path:
    """The same line with its chainage origin ``lead_m`` earlier (a straight lead-in), as a
    GeoJSON; reversed, chainage 0 at the far end."""
    from predisat.geodesy import WGS84

    lat, lon, h = track.lat_deg, track.lon_deg, track.h_m
    az = WGS84.inv(lon[1], lat[1], lon[0], lat[0])[0]
    lon0, lat0, _ = WGS84.fwd(lon[0], lat[0], az, lead_m)
    coords = [[float(lon0), float(lat0), float(h[0])], *np.column_stack([lon, lat, h]).tolist()]
    if reverse:
        coords = coords[::-1]
    path.write_text(
        json.dumps(
            {
                "type": "Feature",
                "properties": {"name": "other map"},
                "geometry": {"type": "LineString", "coordinates": coords},
            }
        )
    )
    return path


def test_a_map_metres_beside_the_simulated_line_is_told(sim_dir, tmp_path, capsys):
    """A trial: the 10 m network map of line 144, 4.6 m beside the simulated line, was taken
    without a word, though the pair intervals take the antenna on the map (1.5 m of doubt)."""
    from predisat.geodesy import WGS84
    from predisat.synth.world import World

    track = World.load(sim_dir / "world.npz").track
    lat, lon, h = track.lat_deg, track.lon_deg, track.h_m
    az = np.append(WGS84.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])[0], np.nan)
    az[-1] = az[-2]
    lon2, lat2, _ = WGS84.fwd(lon, lat, az + 90.0, np.full(lon.shape, 4.5))
    beside = tmp_path / "beside.geojson"
    beside.write_text(json.dumps({
        "type": "Feature", "properties": {"name": "beside"},
        "geometry": {"type": "LineString",
                     "coordinates": np.column_stack([lon2, lat2, h]).tolist()},
    }))  # fmt: skip
    base = ["-q", "run", "--sim", str(sim_dir), "--no-masks"]
    assert main([*base, "--track", str(beside), "--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    assert "its true antenna positions lie 4.5 m left of track 'beside'" in err
    other = _lead_in_map(track, 100.0, tmp_path / "other.geojson")  # the same line: no word
    assert main([*base, "--track", str(other), "--out", str(tmp_path / "o")]) == 0
    assert "true antenna positions lie" not in capsys.readouterr().err


def test_a_simulation_on_another_map_of_its_line_is_located_and_scored_in_that_maps_chainage(
    sim_dir, tmp_path, capsys
):
    """The simulation's chainage is its world's; a map whose origin is 100 m earlier (by
    construction, WGS84.fwd) puts the start, the odometer and the truth 100 m further on. Before,
    the run started 100 m off (no claim) and evaluate scored 97 m errors."""
    from predisat.synth.world import World
    from predisat.track import TrackMap

    sim = SimRun.read(sim_dir)
    own_track = World.load(sim_dir / "world.npz").track
    other = _lead_in_map(own_track, 100.0, tmp_path / "other.geojson")
    base = ["-q", "run", "--sim", str(sim_dir), "--no-masks"]
    assert main([*base, "--out", str(tmp_path / "own")]) == 0
    assert main([*base, "--track", str(other), "--out", str(tmp_path / "other")]) == 0
    own, _ = read_run(tmp_path / "own")
    moved, meta = read_run(tmp_path / "other")
    assert meta["start_chainage_m"] == pytest.approx(sim.chainage_m[0] + 100.0, abs=0.5)
    # the lead-in lifts the own map's end-of-map voids near the start; no claim lost to the shift
    assert moved["claim"].mean() >= own["claim"].mean() > 0.5
    # scored without the map: refused, naming --track; with it: the errors of the own map
    assert main(["evaluate", str(tmp_path / "other"), "--sim", str(sim_dir)]) == 2
    assert "give the run's map as --track" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "own"), "--sim", str(sim_dir)]) == 0
    assert main(["evaluate", str(tmp_path / "other"), "--sim", str(sim_dir),
                 "--track", str(other)]) == 0  # fmt: skip
    e_own = json.loads((tmp_path / "own" / "evaluation.json").read_text())
    e_moved = json.loads((tmp_path / "other" / "evaluation.json").read_text())
    key = next(k for k in e_own if "median" in k and "err" in k)
    assert e_moved[key] == pytest.approx(e_own[key], abs=1.0)
    # a simulation without its world.npz (copied as its three files): run.json says the truth
    # was projected, and evaluate still asks for the map (a review found it scored 97 m errors)
    bare = tmp_path / "bare_sim"
    shutil.copytree(sim_dir, bare, ignore=shutil.ignore_patterns("world.npz"))
    assert main([*base[:3], str(bare), "--no-masks", "--track", str(other),
                 "--out", str(tmp_path / "bare")]) == 0  # fmt: skip
    assert read_run(tmp_path / "bare")[1]["sim_chainage"] == "projected"
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "bare"), "--sim", str(bare)]) == 2
    assert "give the run's map as --track" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "bare"), "--sim", str(bare),
                 "--track", str(other)]) == 0  # fmt: skip
    e_bare = json.loads((tmp_path / "bare" / "evaluation.json").read_text())
    assert e_bare[key] == pytest.approx(e_moved[key], abs=1e-9)
    # reversed: chainage counted from the other end, the odometer's sign with it
    rev = TrackMap.from_geojson(_lead_in_map(own_track, 100.0, tmp_path / "rev.geojson", True))
    from locator.workflow import sim_on_track

    on_rev = sim_on_track(sim, rev, "sim")
    np.testing.assert_allclose(on_rev.chainage_m, rev.length_m - 100.0 - sim.chainage_m, atol=0.3)
    # ... and the direction of travel in that chainage: the odometer follows it (a user
    # trial's `locator balises --track` on a reversed map was refused as a reversal)
    assert on_rev.meta["direction"] == -int(sim.meta.get("direction", 1))
    from locator.odometry.odometer import OdometerConfig
    from locator.odometry.simulated import odometer_along_run

    so = odometer_along_run(on_rev, OdometerConfig.ideal(), 0)
    assert so.orientation == on_rev.meta["direction"]
    np.testing.assert_allclose(so.truth_chainage_m[[0, -1]], on_rev.chainage_m[[0, -1]], atol=0.3)


def test_a_crawling_simulation_on_a_map_counting_from_the_other_end_turns_its_direction(
    tmp_path,
):
    """A run that never moves a metre between epochs (0.8 m/s at 1 Hz) on a reversed map: its
    direction turns as a faster run's does (it kept +1 and the odometer refused the run as "the
    run goes back 16.04 m against its direction (+1)")."""
    from locator.odometry.odometer import OdometerConfig
    from locator.odometry.simulated import odometer_along_run
    from locator.workflow import sim_on_track
    from predisat.synth.world import World
    from predisat.track import TrackMap

    canyon_world().save(tmp_path / "world.npz")
    assert main(["-q", "simulate", "--world", str(tmp_path / "world.npz"), "--duration", "40",
                 "--speed", "0.8", "--seed", "3", "--start-chainage", "65",
                 "--out", str(tmp_path / "sim")]) == 0  # fmt: skip
    sim = SimRun.read(tmp_path / "sim")
    assert np.abs(np.diff(sim.chainage_m)).max() <= 1.0
    track = World.load(tmp_path / "world.npz").track
    rev = TrackMap.from_geojson(_lead_in_map(track, 100.0, tmp_path / "rev.geojson", True))
    on_rev = sim_on_track(sim, rev, "sim")
    assert on_rev.meta["direction"] == -int(sim.meta.get("direction", 1))
    so = odometer_along_run(on_rev, OdometerConfig.ideal(), 0)
    np.testing.assert_allclose(so.truth_chainage_m[[0, -1]], on_rev.chainage_m[[0, -1]], atol=0.3)


def test_a_map_of_another_line_or_one_that_stops_short_is_refused_for_a_simulation(sim_dir):
    from locator.workflow import sim_on_track
    from predisat.synth.world import World

    sim = SimRun.read(sim_dir)
    track = World.load(sim_dir / "world.npz").track
    end = float(sim.chainage_m.max()) - 20.0  # the map stops 20 m before the run's end
    lat, lon, h = track.position_at(np.linspace(0.0, end, 30))
    from predisat.track import TrackMap

    short = TrackMap.from_latlon(lat, lon, h, name="short")
    with pytest.raises(ValueError, match=r"passes \d+ m beside track 'short'.*stops short"):
        sim_on_track(sim, short, "sim")


def test_a_simulation_on_a_map_without_heights_is_refused_unless_the_bound_is_raised(
    sim_dir, tmp_path, capsys
):
    from predisat.synth.world import World

    track = World.load(sim_dir / "world.npz").track  # 150 m above the ellipsoid
    coords = np.column_stack([track.lon_deg, track.lat_deg, 0.0 * track.h_m]).tolist()
    flat = tmp_path / "flat.geojson"
    flat.write_text(
        json.dumps(
            {
                "type": "Feature",
                "properties": {"name": "h0"},
                "geometry": {"type": "LineString", "coordinates": coords},
            }
        )
    )
    base = ["-q", "run", "--sim", str(sim_dir), "--no-masks", "--track", str(flat)]
    assert main([*base, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    told = re.search(r"lie ([\d.]+) m above its antenna", err)
    true_h = np.median(track.position_at(SimRun.read(sim_dir).chainage_m)[2])
    assert told and float(told.group(1)) == pytest.approx(true_h, abs=0.5) and "h = 0" in err
    assert not (tmp_path / "a").exists()
    assert main([*base, "--max-height-offset", "1000", "--out", str(tmp_path / "b")]) == 0


def test_a_run_that_fails_to_write_leaves_the_folder_of_the_run_before(
    sim_dir, tmp_path, capsys, monkeypatch
):
    """A full disk after the new table was written left it beside the previous run's run.json
    and figures, and evaluate scored it under the old trust rule (a user trial)."""
    import errno

    import locator.runio as runio

    out = tmp_path / "run"
    assert main(["-q", "run", "--sim", str(sim_dir), "--cutoff", "30", "--out", str(out)]) == 0
    from predisat.atomic import LOCK_NAME  # names the process that wrote, not an output

    def files():
        return {p.name: p.read_bytes() for p in out.iterdir()
                if p.is_file() and p.name != LOCK_NAME}  # fmt: skip

    before = files()

    def full(epochs, folder, title="", banner=None):
        raise OSError(errno.ENOSPC, "No space left on device",
                      str(Path(folder) / ".interval_time.a1b2c3d4.png"))  # fmt: skip

    monkeypatch.setattr(runio, "write_figures", full)
    assert main(["-q", "run", "--sim", str(sim_dir), "--no-masks", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"no space left on the disk (writing {out / 'interval_time.png'})" in err
    after = files()
    assert after == before  # wholly the run before: its table, run.json and figures
    assert read_run(out)[1]["config"]["trust"] == "cutoff"


def test_a_truth_file_out_of_order_empty_or_in_km_is_refused_naming_the_line(
    sim_dir, tmp_path, capsys
):
    """Read bare, rows newest first gave 6 hazardous epochs that were not, an empty cell 1, and
    kilometres 4 km errors (a user trial); a good file scores as the simulation does."""
    sim = SimRun.read(sim_dir)
    out = tmp_path / "r"
    assert main(["-q", "run", "--sim", str(sim_dir), "--no-masks", "--out", str(out)]) == 0
    truth = pd.DataFrame({"gps_s": sim.gps_s, "chainage_m": sim.chainage_m})
    cases = {
        "good.csv": (truth, None),
        "newest_first.csv": (truth[::-1], r"line 3: gps_s [\d.]+ does not follow [\d.]+; sort"),
        "empty.csv": (truth.astype(object).assign(chainage_m=lambda d: d["chainage_m"].where(
            d.index != 4, "")), r"line 6: chainage_m is empty"),
        "km.csv": (truth.assign(chainage_m=truth["chainage_m"] / 1000.0),
                   "chainage_m reads as kilometres"),
    }  # fmt: skip
    for name, (table, refused) in cases.items():
        table.to_csv(tmp_path / name, index=False, float_format="%.17g")
        rc = main(["evaluate", str(out), "--truth-csv", str(tmp_path / name)])
        err = capsys.readouterr().err
        if refused is None:
            assert rc == 0, err
            by_csv = json.loads((out / "evaluation.json").read_text())
        else:
            assert rc == 2 and re.search(rf"{re.escape(name)}(, |: ){refused}", err), (name, err)
    assert main(["evaluate", str(out), "--sim", str(sim_dir)]) == 0
    assert json.loads((out / "evaluation.json").read_text()) == by_csv


def test_a_standing_trains_truth_in_metres_is_not_taken_for_kilometres(sim_dir, tmp_path):
    """A review: an RTK truth spanning 3 cm beside estimates spanning 24 m was refused as km."""
    out = tmp_path / "r"
    assert main(["-q", "run", "--sim", str(sim_dir), "--no-masks", "--out", str(out)]) == 0
    epochs, _ = read_run(out)
    still = float(np.nanmedian(epochs["chainage_m"])) + 3.0  # a train standing near it
    truth = pd.DataFrame({"gps_s": epochs["gps_s"], "chainage_m": still + 0.0003 * np.arange(
        len(epochs))})  # fmt: skip
    truth.to_csv(tmp_path / "rtk.csv", index=False, float_format="%.17g")
    assert main(["evaluate", str(out), "--truth-csv", str(tmp_path / "rtk.csv")]) == 0


def test_simulate_on_a_track_of_ones_own_needs_its_stretch(tmp_path, capsys, test_data):
    """A user trial: `simulate --track` on another line, without --from-km/--to-km, built line
    144's demo window (4.0-6.3 km) there, inside a 13 km tunnel of that line, saying only
    "building the world (4000-6300 m)"."""
    track = Path(__file__).parents[2] / "predisat/data/line144_track_A.geojson"
    assert main(["simulate", "--track", str(track), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert "--from-km and --to-km" in err and "line 144" in err
    assert not (tmp_path / "s").exists()
    # an OpenStreetMap extract is chosen as in `predisat synth` (the error told the trial's
    # user to give --where and --chain, which simulate and run did not take)
    osm = test_data / "track/riviera_andora_alassio.geojson"
    argv = ["--track", str(osm), "--where", "usage=main", "service=", "--chain", "longest"]
    assert main(["simulate", *argv, "--out", str(tmp_path / "s")]) == 2
    assert "--from-km and --to-km" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "--chain" in capsys.readouterr().out


def test_simulate_starts_inside_the_navigation_data(sim_dir, tmp_path, test_data, capsys):
    """A user trial simulated the embedded 2020 day with a 2010 navigation file: no
    satellite, exit 0. Now the default start is 08:00 of the file's day, and a start outside
    its data is refused naming both."""
    nav = test_data / "gnss/brdc1820_G01G02G05.10n"
    world = sim_dir / "world.npz"
    rc = main(["-q", "simulate", "--world", str(world), "--duration", "10", "--nav", str(nav),
               "--out", str(tmp_path / "sim")])  # fmt: skip
    assert rc == 0
    sim = SimRun.read(tmp_path / "sim")
    from predisat.gnss.timescale import calendar_to_gps_s

    assert sim.gps_s[0] == calendar_to_gps_s(2010, 7, 1, 8)
    assert np.isin(sim.state, (SignalState.LOS, SignalState.NLOS)).any()  # satellites placed
    rc = main(["-q", "simulate", "--world", str(world), "--duration", "10", "--nav", str(nav),
               "--start", "2015-01-01T08:00", "--out", str(tmp_path / "sim2")])  # fmt: skip
    err = capsys.readouterr().err
    assert rc != 0 and "--start 2015-01-01" in err and "outside the navigation data" in err


def test_masks_made_for_a_higher_antenna_are_refused(sim_dir, tmp_path, capsys):
    """A user trial ran masks made for a 4.0 m antenna with --antenna-height 3.0 in silence;
    from 1.0 m lower the near obstacles stand higher and 0.027 % of the directions were
    trusted falsely (predisat.masks.antenna)."""
    from predisat.masks.fileformat import read_masks

    masks = sim_dir / "true_masks.parquet"
    assert read_masks(masks).provenance["antenna_height_m"] == 4.0
    base = ["-q", "run", "--sim", str(sim_dir), "--masks", str(masks)]
    assert main([*base, "--antenna-height", "3.0", "--out", str(tmp_path / "low")]) == 2
    err = capsys.readouterr().err
    assert "made for an antenna 4 m above the track axis, the train's is at 3 m" in err
    assert main([*base, "--antenna-height", "4.5", "--out", str(tmp_path / "high")]) == 0
    assert "err on the safe side" in capsys.readouterr().err



def test_the_masks_survey_checks_and_sky_in_tunnels_are_said_as_availability_says_them(
    sim_dir, tmp_path, capsys
):
    """A review: masks whose provenance says the survey's cameras were swapped (such masks
    trusted 8.6 % of the demo run's directions falsely, 0.10 % unswapped) and masks open deep
    in a tunnel of the map ran in silence; `predisat availability` warned of both."""
    from dataclasses import replace

    from predisat.masks.fileformat import read_masks, write_masks
    from predisat.synth.world import World

    true = read_masks(sim_dir / "true_masks.parquet")
    checks = {"side_check": {"right": {"agree": 3, "disagree": 40, "pairs": 43,
                                       "swapped": True}}}  # fmt: skip
    sw = write_masks(replace(true, provenance={**true.provenance, **checks}),
                     tmp_path / "swapped.masks.parquet")  # fmt: skip
    t = World.load(sim_dir / "world.npz").track
    s = np.arange(0.0, t.length_m + 1e-9, 5.0)
    lat, lon, h = t.position_at(s)
    coords = [[float(a), float(b), float(c)] for a, b, c in zip(lon, lat, h, strict=True)]
    tunnel = tmp_path / "tunnel.geojson"
    line = {"type": "LineString", "coordinates": coords}
    feature = {"type": "Feature", "properties": {"name": "T"}, "geometry": line}
    tunnel.write_text(json.dumps({"type": "FeatureCollection", "chainage": "vertex order",
                                  "tunnels_m": [[0.0, 600.0]], "features": [feature]}))
    capsys.readouterr()
    assert main(["-q", "run", "--sim", str(sim_dir), "--masks", str(sw), "--track", str(tunnel),
                 "--out", str(tmp_path / "r")]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "right camera's frames slid the other way" in err
    assert "left and right are probably swapped" in err
    assert "tags as tunnel, over 100 m from a portal" in err
    # the simulation's own masks on its own map say neither
    assert main(["-q", "run", "--sim", str(sim_dir), "--masks",
                 str(sim_dir / "true_masks.parquet"), "--out", str(tmp_path / "t")]) == 0
    err = capsys.readouterr().err
    assert "swapped" not in err and "tunnel" not in err


def test_masks_checked_against_an_antenna_height_nobody_gave_are_said(
    test_data, tmp_path, capsys
):
    """A review: without --antenna-height the masks' 4 m was checked against the default 4 m,
    whatever the train's antenna, in silence (a 3 m antenna under 4 m masks: 0.027 % of the
    directions trusted falsely)."""
    from predisat.masks.fileformat import write_masks
    from predisat.masks.maskset import MaskSet
    from predisat.track import load_track

    track_file = _virtual_track(tmp_path / "virtual.csv")
    track = load_track(track_file)
    ch = np.arange(0.0, track.length_m, 10.0)
    m = MaskSet.from_track(track, ch, np.full((ch.size, 360), 10.0),
                           provenance={"antenna_height_m": 4.0})  # fmt: skip
    masks = write_masks(m, tmp_path / "v.masks.parquet")
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = test_data / "gnss_obs" / "07590920_0000_0200.05n"
    run = ["-q", "run", "--obs", str(obs), "--nav", str(nav), "--track", str(track_file),
           "--masks", str(masks)]  # fmt: skip
    capsys.readouterr()
    assert main([*run, "--out", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err
    assert "the train antenna's height was not given (--antenna-height): taken as 4 m" in err
    assert "made for an antenna 4 m above the track axis" in err
    assert main([*run, "--antenna-height", "4", "--out", str(tmp_path / "b")]) == 0
    assert "was not given" not in capsys.readouterr().err

def _python(code: str) -> subprocess.CompletedProcess[str]:
    root = Path(__file__).resolve().parents[2]
    env = {"PYTHONPATH": str(root), "PATH": ""}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=root, env=env, timeout=120)  # fmt: skip


@pytest.mark.parametrize(
    "interrupt", ["raise KeyboardInterrupt()", "raise ImportError('x') from KeyboardInterrupt()"]
)
def test_a_ctrl_c_while_the_commands_import_ends_as_interrupted(interrupt: str) -> None:
    # a finder that interrupts the import of one command module as a Ctrl-C would there
    # (in a C extension's import it comes as an ImportError caused by the KeyboardInterrupt)
    code = (
        "import sys\n"
        "class Stop:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'locator.workflow':\n"
        f"            {interrupt}\n"
        "sys.meta_path.insert(0, Stop())\n"
        "from locator.cli import main\n"
        "sys.exit(main(['run', '--help']))\n"  # `run`'s arguments import the locator
    )
    proc = _python(code)
    assert proc.returncode == 130, proc.stderr
    assert "interrupted before the command started" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_an_import_error_not_from_ctrl_c_still_raises() -> None:
    code = (
        "import sys\n"
        "class Broken:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'locator.workflow':\n"
        "            raise ImportError('a broken install')\n"
        "sys.meta_path.insert(0, Broken())\n"
        "from locator.cli import main\n"
        "main(['run', '--help'])\n"
    )
    proc = _python(code)
    assert proc.returncode == 1
    assert "a broken install" in proc.stderr and "Traceback" in proc.stderr


def test_evaluating_an_older_fixed_k_run_does_not_label_its_claims_safety_claims(
    sim_dir, tmp_path
):
    """A review (hW): versions before 029e738 wrote safety_claim = claim at a fixed --k-sigma;
    `locator evaluate` of such a folder drew the red "no safety claim" banner (from run.json)
    over intervals coloured and counted as safety claims, and wrote scored.parquet with
    safety_claim True, which a reader of the table alone takes for safety claims."""
    from locator.runio import write_table

    run = tmp_path / "old_k"
    assert main(["-q", "run", "--sim", str(sim_dir), "--no-masks", "--k-sigma", "2",
                 "--out", str(run)]) == 0  # fmt: skip
    ep, meta = read_run(run)
    assert ep["claim"].any() and not ep["safety_claim"].any()
    assert meta["config"]["locator"]["budget"] is None
    write_table(ep.assign(safety_claim=ep["claim"]), run, "epochs", "parquet")  # as then
    assert main(["-q", "evaluate", str(run), "--sim", str(sim_dir)]) == 0
    scored = pd.read_parquet(run / "scored.parquet")
    assert scored["claim"].any() and not scored["safety_claim"].any()
    # and one older still, without the column: the scored table says it
    write_table(ep.drop(columns="safety_claim"), run, "epochs", "parquet")
    assert main(["-q", "evaluate", str(run), "--sim", str(sim_dir)]) == 0
    scored = pd.read_parquet(run / "scored.parquet")
    assert "safety_claim" in scored and not scored["safety_claim"].any()


@pytest.mark.parametrize("receiver", ["", "UNKNOWN", "UBLOX ZED-F9P"])
def test_a_receiver_without_a_name_or_a_mass_market_chip_is_refused_as_geodetic(
    test_data, tmp_path, capsys, receiver
):
    """A user trial: a class-geodetic model (one station) claimed 100 % on a file whose
    receiver type was 'UNKNOWN', and on a u-blox's, both declared --receiver-class geodetic."""
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    lines = obs.read_text().splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if "REC # / TYPE / VERS" in ln)
    lines[k] = ("00000".ljust(20) + receiver.ljust(20) + "1.0".ljust(20) + "REC # / TYPE / VERS\n")
    other = tmp_path / "other.05o"
    other.write_text("".join(lines))
    cal = ["calibrate", "--obs", str(other), "--nav", nav, "--bound", "estimate"]
    assert main([*cal, "--receiver-class", "geodetic", "--out", str(tmp_path / "m.json")]) == 2
    assert "--receiver-class geodetic would take a reference station" in capsys.readouterr().err
    assert not (tmp_path / "m.json").exists()
    track = _virtual_track(tmp_path / "virtual.csv")
    run = ["-q", "run", "--obs", str(other), "--nav", nav, "--antenna-height", "0", "--track",
           str(track), "--no-masks"]  # fmt: skip
    assert main([*run, "--receiver-class", "geodetic", "--out", str(tmp_path / "r")]) == 2
    assert "--receiver-class geodetic would take a reference station" in capsys.readouterr().err
    # without the declaration the file runs (no claim: no model for it)
    assert main([*run, "--out", str(tmp_path / "s")]) == 0


def test_a_class_model_from_one_receiver_is_told(test_data, tmp_path, capsys):
    """A class model from one station applies to every receiver declared of that class: said."""
    obs = str(test_data / "gnss_obs" / "07590920_10ep.05o")
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    argv = ["calibrate", "--obs", obs, "--nav", nav, "--bound", "estimate",
            "--receiver-class", "geodetic", "--out", str(tmp_path / "m.json")]  # fmt: skip
    assert main(argv) == 0
    assert "from one receiver and antenna (TRIMBLE 5700 / TRM29659.00)" in capsys.readouterr().err


def test_calibrate_without_any_klobuchar_set_says_so_and_records_it(test_data, tmp_path, capsys):
    """A Galileo-only navigation file has no Klobuchar set: the residuals keep the ionospheric
    delay, which the model then fits as pseudorange error. A user trial (2026-12-07, NYA1 E
    C1X: b 0.41 -> 1.16 m) got no word, and the file still read "single: one code with the
    broadcast ionosphere"; `locator run` warns in the same case."""
    import gzip

    obs = str(test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx")
    lines = gzip.open(test_data / "gnss" / "KMS300DNK_R_20221591000_01H_MN.rnx.gz", "rt")
    text, keep, head = [], True, True
    for line in lines:  # the RINEX 4 file's Galileo records only (its GPS/BeiDou ION left out)
        if not head and line.startswith(">"):
            keep = line.split()[2].startswith("E")
        if head or keep:
            text.append(line)
        head = head and "END OF HEADER" not in line
    nav = tmp_path / "galileo_only.rnx"
    nav.write_text("".join(text))
    out = tmp_path / "m.json"
    assert main(["calibrate", "--obs", obs, "--nav", str(nav), "--constellation", "E",
                 "--bound", "estimate", "--out", str(out)]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "no broadcast ionosphere model for E" in err
    assert json.loads(out.read_text())["fitted"]["iono_uncorrected_systems"] == ["E"]
    # with the mixed file (GPS Klobuchar): nothing said, nothing recorded
    full = str(test_data / "gnss" / "KMS300DNK_R_20221591000_01H_MN.rnx.gz")
    assert main(["calibrate", "--obs", obs, "--nav", full, "--constellation", "E",
                 "--bound", "estimate", "--out", str(out)]) == 0  # fmt: skip
    assert "ionosphere" not in capsys.readouterr().err
    assert json.loads(out.read_text())["fitted"]["iono_uncorrected_systems"] == []


def test_a_height_check_without_any_fix_near_the_track_says_so(capsys) -> None:
    """Pseudoranges that give no fix within 200 m of the track left the track-height check
    silent (a user trial, 2026-12-07: a RINEX scale factor ignored, ranges ten times long)."""
    import argparse
    from types import SimpleNamespace

    from locator.cli import _warn_height

    path = SimpleNamespace(antenna_height_m=4.0)
    _warn_height(float("nan"), path, "x.obs (its epochs' own fixes)", argparse.Namespace())
    err = capsys.readouterr().err
    assert "none within 200 m of the track" in err and "could not be checked" in err
    _warn_height(0.5, path, "x.obs (its epochs' own fixes)", argparse.Namespace())
    assert capsys.readouterr().err == ""


def test_dual_frequency_runs_take_only_a_model_calibrated_on_the_same_combination(
    test_data, tmp_path, capsys, sim_dir
):
    """`--dual-frequency` ranges with the ionosphere-free combination (C1 + P2 on GEONET 0759's
    RINEX 2 file): `calibrate --dual-frequency` records the processing and the pair of codes,
    and a single-frequency model never applies to a dual-frequency run (its noise is about 3x)."""
    track = _virtual_track(tmp_path / "virtual.csv")
    obs = str(test_data / "gnss_obs" / "07590920_10ep.05o")
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    for mode, extra in (("single", []), ("dual", ["--dual-frequency"])):
        assert main(["calibrate", "--obs", obs, "--nav", nav, "--bound", "estimate", *extra,
                     "--out", str(tmp_path / f"{mode}.json")]) == 0  # fmt: skip
    dual = json.loads((tmp_path / "dual.json").read_text())
    assert dual["applicability"]["frequency"] == "dual" and dual["systems"]["G"]["codes"] == [
        "C1+P2"
    ]
    assert json.loads((tmp_path / "single.json").read_text())["systems"]["G"]["codes"] == ["C1"]
    run = ["-q", "run", "--obs", obs, "--nav", nav, "--dual-frequency", "--no-masks",
           "--antenna-height", "0", "--track", str(track)]  # fmt: skip
    for mode in ("single", "dual"):
        out = tmp_path / f"r_{mode}"
        assert main([*run, "--error-model", str(tmp_path / f"{mode}.json"), "--out", str(out)]) == 0
        record = json.loads((out / "run.json").read_text())
        assert record["source"]["frequency"] == "dual"
        said = "dual-frequency data, single-frequency model" in record["error_model"]["mismatches"]
        assert said == (mode == "single")
        if mode == "single":  # the model to make is named with the processing of the run
            assert "`locator calibrate --obs FILE --nav NAV --dual-frequency`" in (
                capsys.readouterr().err
            )
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["run", "--sim", str(sim_dir), "--no-masks", "--dual-frequency", "--out",
              str(tmp_path / "s")])  # fmt: skip
    assert "--dual-frequency is for --obs runs" in capsys.readouterr().err


def test_fixes_without_an_ionosphere_model_do_not_blame_the_map(capsys) -> None:
    """A review (2026-12-07): NYA1 with Galileo-only navigation, the receiver's own
    single-frequency fixes 3.9 m high from the ionosphere alone, and the warning blamed a
    correct map; it now says what lifted them."""
    import argparse
    from types import SimpleNamespace

    from locator.cli import _warn_height

    path = SimpleNamespace(antenna_height_m=0.0)
    args = argparse.Namespace(max_height_offset=20.0)
    _warn_height(3.9, path, "nya1 (its epochs' own fixes)", args, ["E"])
    err = capsys.readouterr().err
    assert "without a broadcast ionosphere model for E" in err and "heights or the" not in err
    _warn_height(3.9, path, "nya1 (its epochs' own fixes)", args)
    assert "the track map's heights or the antenna height are off" in capsys.readouterr().err


def test_a_code_with_next_to_no_residuals_is_not_named_calibrated(test_data, tmp_path) -> None:
    """A trial (n8): NYA1's model named C1C+C2X calibrated from 8 of 16 361 residuals and then
    let an L1/L2C-only run claim under it. KMS3 ranges G09 with C1C+C2L at one epoch of 19 and
    every other GPS range with C1C+C2W: only the pair with residuals enough is named."""
    obs = str(test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx")
    nav = str(test_data / "gnss" / "KMS300DNK_R_20221591000_01H_MN.rnx.gz")
    out = tmp_path / "m.json"
    assert main(["-q", "calibrate", "--obs", obs, "--nav", nav, "--dual-frequency", "--bound",
                 "estimate", "--out", str(out)]) == 0  # fmt: skip
    model = json.loads(out.read_text())
    assert model["systems"]["G"]["codes"] == ["C1C+C2W"]
    (pair,) = model["applicability"]["pairs"]
    assert "C1C+C2L" not in json.dumps(pair)


def test_ranges_of_a_code_the_model_was_not_calibrated_on_are_left_out_alone(
    test_data, tmp_path, capsys
) -> None:
    """A trial (n8): one C1C+C2L epoch of G09 in KMS3's dual-frequency run made the whole run
    mismatch a model calibrated on C1C+C2W. Its ranges alone are now left out, said, with the
    reason per epoch; the rest of the run is judged as C1C+C2W."""
    from locator.observations import Observations
    from predisat.geodesy import LocalFrame, ecef_to_geodetic

    obs = str(test_data / "gnss_obs" / "KMS300DNK_R_20221591000_01H_30S_MO.crx")
    nav = str(test_data / "gnss" / "KMS300DNK_R_20221591000_01H_MN.rnx.gz")
    model = tmp_path / "m.json"
    assert main(["-q", "calibrate", "--obs", obs, "--nav", nav, "--dual-frequency", "--bound",
                 "estimate", "--out", str(model)]) == 0  # fmt: skip
    station = Observations.from_rinex(obs).header.approx_position_ecef_m
    lat, lon, h = (float(v) for v in ecef_to_geodetic(station))
    d = np.linspace(-1000.0, 1000.0, 21)
    la, lo, hh = LocalFrame(lat, lon, h).to_geodetic(
        np.stack([d * np.sin(0.7), d * np.cos(0.7), np.zeros_like(d)], -1)
    )
    track = tmp_path / "kms3.csv"
    pd.DataFrame({"lat_deg": la, "lon_deg": lo, "h_m": hh}).to_csv(track, index=False)
    capsys.readouterr()
    out = tmp_path / "r"
    assert main(["run", "--obs", obs, "--nav", nav, "--dual-frequency", "--no-masks",
                 "--antenna-height", "0", "--track", str(track), "--error-model", str(model),
                 "--constellation", "G", "--out", str(out)]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "left out 1 of" in err and "C1C+C2L (1)" in err
    record = json.loads((out / "run.json").read_text())
    assert record["source"]["codes_left_out"] == {"G": {"C1C+C2L": 1}}
    assert record["source"]["codes_kept"] == {"G": ["C1C+C2W"]}
    # the model's other reasons stand (an estimate is no overbound), the code is not one
    assert not [w for w in record["error_model"]["mismatches"] if "C1C+C2L" in w]
    assert record["error_model"]["data"].count("C1C+C2L") == 0


def test_calibrate_refuses_a_file_whose_antenna_moved(test_data, tmp_path, capsys):
    """Calibration takes every epoch at one station position: a file whose event records say
    the antenna moved (flag 2 or 3, or a later ANTENNA: DELTA H/E/N other than the header's)
    is refused naming the line; until 2026-12-07 the later epochs' residuals were taken at the
    first position. A splice comment, or the header's own values again, still pass."""
    obs = test_data / "gnss_obs" / "07590920_10ep.05o"
    nav = str(test_data / "gnss_obs" / "07590920_0000_0200.05n")
    lines = obs.read_text().splitlines(keepends=True)
    ep6 = [i for i, ln in enumerate(lines) if ln.startswith(" 05  4  2")][5]  # 6th epoch
    base = ["calibrate", "--nav", nav, "--bound", "estimate"]

    def with_block(name: str, records: list[str]) -> str:
        block = [" " * 28 + f"4{len(records):3d}\n", *records]
        (tmp_path / name).write_text("".join(lines[:ep6] + block + lines[ep6:]))
        return str(tmp_path / name)

    same = f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}".ljust(60) + "ANTENNA: DELTA H/E/N\n"
    moved = f"{1.5:14.4f}{0.0:14.4f}{0.0:14.4f}".ljust(60) + "ANTENNA: DELTA H/E/N\n"
    splice = "RINEX FILE SPLICE".ljust(60) + "COMMENT\n"
    for name, recs in (("splice.05o", [splice]), ("same.05o", [splice, same])):
        assert main([*base, "--obs", with_block(name, recs),
                     "--out", str(tmp_path / f"{name}.json")]) == 0  # fmt: skip
    path = with_block("moved.05o", [splice, moved])
    assert main([*base, "--obs", path, "--out", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert f"moved.05o, line {ep6 + 1}: the antenna moved (ANTENNA: DELTA H/E/N 1.5000" in err
    assert "--station" in err and not (tmp_path / "m.json").exists()
    new_site = [*lines[:ep6], " " * 28 + "3  1\n", "0760".ljust(60) + "MARKER NAME\n"]
    (tmp_path / "site.05o").write_text("".join(new_site + lines[ep6:]))
    site = str(tmp_path / "site.05o")
    assert main([*base, "--obs", site, "--out", str(tmp_path / "s.json")]) == 2
    assert "flag 3, new site occupation" in capsys.readouterr().err


def test_a_start_the_satellites_contradict_is_told(capsys):
    """`locator run` says when the satellites contradicted the start (flag START_CONFLICT): a
    trial's start 300 m off ran the whole demo on the masks of another place, in silence."""
    from locator.cli import _say_start_conflict
    from locator.run import RunFlag

    flag = int(RunFlag.START_CONFLICT)
    ep = pd.DataFrame({"gps_s": 100.0 + np.arange(6), "flags": [0, flag, flag, flag, flag, 0],
                       "start_check_m": [4024.0, 4032.0, 4005.0, np.nan, 4020.0, np.nan],
                       "claim": [False, False, False, False, True, True]})  # fmt: skip
    _say_start_conflict(ep, 4300.0, True, 15.0)
    err = " ".join(capsys.readouterr().err.split())
    assert "start chainage 4300 m (or the odometry since) contradicts the satellites" in err
    assert "put the train at 4032 m (epoch 1, gps_s 101)" in err
    assert "4 epochs are flagged START_CONFLICT" in err and "at epoch 4" in err
    assert "check --start-chainage" in err
    ep["flags"] = 0
    _say_start_conflict(ep, 4300.0, True, 15.0)
    assert capsys.readouterr().err == ""


def test_a_start_contradicted_by_a_fix_without_a_sky_fix_is_told(capsys):
    """The fix's own claimed interval can widen the start (RunConfig.start_check_m) at an
    epoch without a sky fix (fewer than five satellites): the warning names that interval,
    where it used to need a sky fix's chainage."""
    from locator.cli import _say_start_conflict
    from locator.run import RunFlag

    flag = int(RunFlag.START_CONFLICT)
    ep = pd.DataFrame({"gps_s": 100.0 + np.arange(3), "flags": [flag, flag, 0],
                       "start_check_m": [np.nan, np.nan, np.nan], "lo_m": [990.0, 995.0, 1000.0],
                       "hi_m": [1030.0, 1035.0, 1040.0],
                       "claim": [False, True, True]})  # fmt: skip
    _say_start_conflict(ep, 1075.0, True, 15.0)
    err = " ".join(capsys.readouterr().err.split())
    assert "the trusted satellites' fix put the train at 990-1030 m (epoch 0" in err
    assert "a claim located the run at epoch 1" in err


def test_calibrate_takes_a_file_whose_site_is_occupied_before_its_first_epoch(test_data, tmp_path):
    """A flag-3 new site occupation before any epoch, with the header's own MARKER NAME, moves
    nothing: every epoch is at that site (it was refused, told to split the file at a line
    before its first epoch). Its records still count: a position other than the header's is
    refused, and a flag 2 (start moving antenna) anywhere."""
    from locator.cli import _refuse_moved_station
    from locator.observations import read_rinex_obs
    from predisat.cli.common import CliError

    lines = (test_data / "gnss_obs" / "07590920_10ep.05o").read_text().splitlines()
    i = next(k for k, line in enumerate(lines) if "END OF HEADER" in line) + 1

    def with_event(flag: int, *recs: str) -> object:
        f = tmp_path / f"f{flag}_{len(recs)}.05o"
        f.write_text("\n".join([*lines[:i], f"{lines[i][:26]}  {flag}{len(recs):3d}", *recs,
                                *lines[i:]]) + "\n")  # fmt: skip
        return read_rinex_obs(f)

    marker = f"{'0759':<60}MARKER NAME"
    _refuse_moved_station(with_event(3, marker), "f")  # accepted
    moved = f"{'  -3976219.5082  3382372.5671  3652522.9849':<60}APPROX POSITION XYZ"
    with pytest.raises(CliError, match="APPROX POSITION XYZ"):
        _refuse_moved_station(with_event(3, marker, moved), "f")
    with pytest.raises(CliError, match="flag 2, start moving antenna"):
        _refuse_moved_station(with_event(2, marker), "f")
