"""``locator balises`` end to end in the small synthetic canyon of tests/locator/_scene.py.

Truth: the simulator's chainage of the antenna; the balise passage times follow from it.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from locator.balises.balisefile import BaliseList
from locator.balises.campaign import locate_with_odometry
from locator.cli import main
from locator.odometry.confidence import OdometerAccuracy
from locator.odometry.odometer import OdometerConfig
from locator.odometry.simulated import odometer_along_run
from locator.run import RunConfig
from locator.sathia import AntennaPath
from locator.sim.simfile import SimRun
from predisat.synth.world import World
from tests.locator._scene import canyon_world


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("balises")
    canyon_world().save(root / "world.npz")
    # the run starts 65 m into the map, beyond the start's 50 m uncertainty: nearer its end the
    # first claims would be voided (TRACK_END: the train might be before the map)
    rc = main(["-q", "simulate", "--world", str(root / "world.npz"), "--duration", "40",
               "--speed", "10", "--seed", "3", "--start-chainage", "65",
               "--out", str(root / "sim")])  # fmt: skip
    assert rc == 0
    return root / "sim"


def test_odometer_along_a_simulated_run_keeps_the_truth(sim_dir):
    sim = SimRun.read(sim_dir)
    cfg = OdometerConfig()
    so = odometer_along_run(sim, cfg, seed=2)
    # the truth on the cycle grid passes through the simulator's chainage at every epoch
    np.testing.assert_allclose(np.interp(sim.gps_s, so.truth_t_s, so.truth_chainage_m),
                               sim.chainage_m, atol=1e-6)  # fmt: skip
    moved = sim.chainage_m - sim.chainage_m[0]
    lo, hi = OdometerAccuracy.from_config(cfg).displacement_bounds_m(so.epoch_odo_m)
    assert np.all((lo <= moved) & (moved <= hi))
    assert abs(so.epoch_odo_m[-1] - moved[-1]) < 0.02 * abs(moved[-1]) + 1.0


def test_the_run_may_start_from_a_stored_position_that_is_off(sim_dir, tmp_path, capsys):
    """A trial: the command always started at the true chainage, which flatters every fix
    before the first claim; --start-error starts it off (ahead) and is recorded, and one
    beyond the start uncertainty is refused by name."""
    base = ["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--spacing", "25"]
    assert main([*base, "--start-error", "30", "--out", str(tmp_path / "off")]) == 0
    assert main([*base, "--out", str(tmp_path / "at")]) == 0
    info = json.loads((tmp_path / "off" / "summary.json").read_text())
    assert info["start_error_m"] == 30.0
    off = pd.read_parquet(tmp_path / "off" / "epochs.parquet")
    at = pd.read_parquet(tmp_path / "at" / "epochs.parquet")
    # the first fused estimate stands 30 m ahead of the truth, and the interval still holds it
    first_off, first_at = off.iloc[0], at.iloc[0]
    truth = float(SimRun.read(sim_dir).chainage_m[0])
    assert float(first_at["fused_chainage_m"]) == pytest.approx(truth, abs=0.5)
    assert float(first_off["fused_chainage_m"]) == pytest.approx(truth + 30.0, abs=0.5)
    assert first_off["fused_lo_m"] <= truth <= first_off["fused_hi_m"]
    capsys.readouterr()
    assert main([*base, "--start-error", "80", "--out", str(tmp_path / "far")]) == 2
    assert "start_error_m (80 m) must lie within" in capsys.readouterr().err


def test_balises_command_writes_captures_with_timing(sim_dir, tmp_path, capsys):
    out = tmp_path / "b"
    rc = main(["-q", "balises", "--sim", str(sim_dir), "--masks",
               str(sim_dir / "true_masks.parquet"), "--spacing", "25", "--radius", "12", "25",
               "--out", str(out)])  # fmt: skip
    assert rc == 0
    assert "r25" in capsys.readouterr().out
    caps = pd.read_csv(out / "captures.csv")
    assert (out / "captures.png").is_file() and (out / "epochs.parquet").is_file()
    info = json.loads((out / "summary.json").read_text())
    assert info["safe_front"]["front_outside"] == 0
    # the width setting and the systems are named (a user trial found neither anywhere)
    assert info["integrity"] == "integrity risk 1e-12 per epoch"
    assert info["constellation"] == "all" and info["claims"] == "safety claim"
    sim = SimRun.read(sim_dir)
    p = caps[caps["passed"] & (caps["config"] == "r25")]
    assert len(p) >= 4
    # true passage times from the simulator's chainage (stop-and-go profile, from rest)
    t_true = np.interp(p["chainage_m"], sim.chainage_m, sim.gps_s)
    np.testing.assert_allclose(p["t_true_s"], t_true, atol=0.02)
    got = p[p["captured"]]
    assert len(got) >= 0.75 * len(p)
    assert (got["timing_error_s"].abs() < 1.0).all()
    # the time scale is said, and the UTC column agrees with skyfield's leap seconds
    from skyfield.api import load

    assert "GPS seconds" in info["time_scale"] and info["track"] and info["software"]
    ts = load.timescale(builtin=True)
    row = got.iloc[0]
    utc = ts.tai(1980, 1, 6, 0, 0, 19.0 + float(row["t_pass_s"])).utc_datetime()
    got_utc = pd.Timestamp(row["t_pass_utc"]).tz_localize("UTC")
    assert abs((got_utc - pd.Timestamp(utc)).total_seconds()) < 0.002
    # captures at a width the user chose rest on no safety claim, and captures.csv says so
    assert main(["-q", "balises", "--sim", str(sim_dir), "--masks",
                 str(sim_dir / "true_masks.parquet"), "--spacing", "25", "--radius", "12",
                 "--k-sigma", "2", "--out", str(tmp_path / "k")]) == 0  # fmt: skip
    caps = pd.read_csv(tmp_path / "k" / "captures.csv")
    assert caps["captured"].any() and not caps["safety_claim"].any()
    # ... and the console too (a user trial's --k-sigma 1.7 table read as any other)
    assert "NOT A SAFETY CLAIM" in capsys.readouterr().out
    claims = json.loads((tmp_path / "k" / "summary.json").read_text())["claims"]
    assert claims == "claim at a fixed k = 2 (no integrity budget)"


def test_a_bad_balise_list_is_one_line_naming_the_row(sim_dir, tmp_path, capsys):
    track = World.load(sim_dir / "world.npz").track
    bl = BaliseList.along_track(track, 100.0, 400.0, 100.0)
    p = bl.to_csv(tmp_path / "b.csv")
    df = pd.read_csv(p)
    df.loc[2, "id"] = df.loc[0, "id"]
    df.to_csv(p, index=False)
    rc = main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--balises", str(p),
               "--out", str(tmp_path / "x")])  # fmt: skip
    assert rc == 2
    err = capsys.readouterr().err
    assert "line 4" in err and "already used on line 2" in err and "\n" == err[-1]


def test_a_recorded_odometer_log_is_used_and_a_gap_is_refused(sim_dir, tmp_path, capsys):
    from locator.odometry.logfile import write_odometer_log

    sim = SimRun.read(sim_dir)
    log = odometer_along_run(sim, OdometerConfig(), seed=5).log
    p = write_odometer_log(log, tmp_path / "odo.csv")
    rc = main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--spacing", "25",
               "--odometer-log", str(p), "--out", str(tmp_path / "ok")])  # fmt: skip
    assert rc == 0
    info = json.loads((tmp_path / "ok" / "summary.json").read_text())
    assert info["accuracy"]["over_rel"] == 0.05  # a log of unknown odometer: SUBSET-041
    assert info["odometer"] == {"log": str(p)}  # not the simulated odometer's settings
    assert info["safe_front"]["front_outside"] == 0
    df = pd.read_csv(p)
    df.drop(index=range(100, 110)).to_csv(p, index=False)
    rc = main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--odometer-log", str(p),
               "--out", str(tmp_path / "bad")])  # fmt: skip
    assert rc == 2
    assert "line 102: gap of 1.10 s" in capsys.readouterr().err


def test_the_captures_take_the_odometers_acceleration_limit(sim_dir, tmp_path):
    """A log admitted at 2.5 m/s^2 must not be bounded at the default 1.5 in the captures'
    prediction and interpolation."""
    from locator.odometry.logfile import write_odometer_log

    sim = SimRun.read(sim_dir)
    p = write_odometer_log(odometer_along_run(sim, OdometerConfig(), seed=5).log,
                           tmp_path / "odo.csv")  # fmt: skip
    for extra, want in (([], 1.5), (["--max-accel", "2.5"], 2.5)):
        out = tmp_path / f"a{want:g}"
        rc = main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--spacing", "25",
                   "--odometer-log", str(p), *extra, "--out", str(out)])  # fmt: skip
        assert rc == 0
        caps = json.loads((out / "summary.json").read_text())["captures"]
        assert caps and {c["max_accel_mps2"] for c in caps.values()} == {want}


def test_a_start_error_beyond_the_start_uncertainty_is_refused(sim_dir):
    sim = SimRun.read(sim_dir)
    path = AntennaPath(World.load(sim_dir.parent / "world.npz").track, 4.0)
    with pytest.raises(ValueError, match="start_uncertainty_m"):
        locate_with_odometry(sim, path, RunConfig(trust="none", start_uncertainty_m=10.0),
                             start_error_m=12.0)  # fmt: skip
    # within it, the run starts off the truth by that much and its interval still holds it
    run = locate_with_odometry(sim, path, RunConfig(trust="none", start_uncertainty_m=10.0),
                               start_error_m=-9.0)  # fmt: skip
    ep = run.epochs
    assert ep["fused_chainage_m"].iloc[0] == pytest.approx(sim.chainage_m[0] - 9.0, abs=1e-6)
    assert ((ep["fused_lo_m"] <= ep["truth_m"]) & (ep["truth_m"] <= ep["fused_hi_m"])).all()


def test_printed_summary_gives_the_capture_rate_in_percent():
    from locator.balises.command import format_summary

    summary = pd.DataFrame({
        "config": ["r25"], "passages": [12], "captured": [11], "capture_rate": [11 / 12],
        "false": [0], "hazardous": [1], "front_outside": [3], "timing_abs_median_s": [0.0123],
        "delay_median_s": [0.5], "delay_p95_s": [0.9],
    })  # fmt: skip
    header, row = format_summary(summary).splitlines()
    cells = dict(zip(header.split(), row.split(), strict=True))
    assert cells["capture_%"] == "91.7" and "capture_rate" not in cells
    assert cells["timing_abs_median_s"] == "0.012"
    assert cells["hazardous"] == "1" and cells["front_outside"] == "3"


def test_an_error_model_of_another_receiver_gives_no_claim_and_no_capture(sim_dir, tmp_path,
                                                                          capsys):
    # the rule of `locator run`: a model calibrated for another receiver does not apply to the
    # simulated one, so no epoch claims and no balise is captured (unless forced)
    from predisat.gnss.errormodel import (
        Applicability,
        ErrorModel,
        IntervalModel,
        SystemModel,
        write_error_model,
    )

    e = ErrorModel(0.8, 0.3)
    model = write_error_model(
        tmp_path / "other.json", IntervalModel(e),
        systems={s: SystemModel(e, ("C1C",), 1000, 100, 0.05) for s in "GRECJ"},
        applicability=Applicability(("TRIMBLE NETR9",), ("ASH701073.1     SNOW",)),
    )  # fmt: skip
    base = ["-q", "balises", "--sim", str(sim_dir), "--masks",
            str(sim_dir / "true_masks.parquet"), "--spacing", "25", "--error-model", str(model)]
    assert main([*base, "--out", str(tmp_path / "no")]) == 0
    err = capsys.readouterr().err
    assert "locator balises: NO SAFETY CLAIM" in err and "NETR9" in err
    ep = pd.read_parquet(tmp_path / "no" / "epochs.parquet")
    assert not ep["claim"].any()
    caps = pd.read_csv(tmp_path / "no" / "captures.csv")
    assert caps["passed"].any() and not caps["captured"].any()
    info = json.loads((tmp_path / "no" / "summary.json").read_text())
    assert info["error_model"]["use"] == "none" and info["error_model"]["mismatches"]
    assert main([*base, "--force-error-model", "--out", str(tmp_path / "forced")]) == 0
    err = capsys.readouterr().err
    assert "--force-error-model" in err and "NOT A SAFETY CLAIM" in err
    ep = pd.read_parquet(tmp_path / "forced" / "epochs.parquet")
    assert ep["claim"].any() and ep["flag_names"].str.contains("FORCED_ERROR_MODEL").all()
    assert not ep["safety_claim"].any()
    assert json.loads((tmp_path / "forced" / "summary.json").read_text())["error_model"][
        "use"] == "forced"  # fmt: skip
    # captures.csv alone says that its captures rest on no safety claim
    caps = pd.read_csv(tmp_path / "forced" / "captures.csv")
    assert caps["captured"].any() and not caps["safety_claim"].any()
    # a model of this receiver checked only to 0.05 per pseudorange: not as deep as the
    # integrity risk asks, no claim either (and no hint at an option balises does not have)
    sim_model = write_error_model(
        tmp_path / "shallow.json", IntervalModel(e),
        systems={s: SystemModel(e, ("sim",), 1000, 100, 0.05) for s in "GRECJ"},
        applicability=Applicability(("simulated",), ("simulated",), "simulated"),
    )  # fmt: skip
    shallow = [*base[:-1], str(sim_model)]
    assert main([*shallow, "--out", str(tmp_path / "shallow")]) == 0
    err = capsys.readouterr().err
    assert "deeper than" in err and "--assume-gaussian-tail" not in err
    assert not pd.read_parquet(tmp_path / "shallow" / "epochs.parquet")["claim"].any()


def test_captures_csv_keeps_the_times_full_precision(sim_dir, tmp_path):
    from locator.balises.campaign import balises_to_folder, capture_table
    from locator.balises.capture import CaptureConfig

    sim = SimRun.read(sim_dir)
    path = AntennaPath(World.load(sim_dir / "world.npz").track, 4.0)
    bl = BaliseList.along_track(path.track, float(sim.chainage_m[0]) + 20.0,
                                float(sim.chainage_m[-1]), 25.0)  # fmt: skip
    caps = {"r12": CaptureConfig.gaderos(12.0)}
    cfg = RunConfig(trust="none")
    balises_to_folder(sim, path, bl, tmp_path, config=cfg, captures=caps)
    back = pd.read_csv(tmp_path / "captures.csv")
    # the same run again, in memory (seeded: identical)
    scored = capture_table(locate_with_odometry(sim, path, cfg, odometer=OdometerConfig()), bl,
                           caps)  # fmt: skip
    for col in ("t_pass_s", "t_emit_s", "t_true_s", "timing_error_s", "chainage_m"):
        np.testing.assert_array_equal(back[col].to_numpy(float), scored[col].to_numpy(float))
    assert back["t_true_s"].notna().any() and back["t_pass_s"].notna().any()


def test_captures_csv_says_each_balise_q_reference(sim_dir, tmp_path):
    """A user trial: the list's q_reference (whether a telegram may reset the odometer's
    interval) was not in captures.csv; it is, as the list's 0/1, and reads back."""
    track = World.load(sim_dir / "world.npz").track
    sim = SimRun.read(sim_dir)
    bl = BaliseList.along_track(track, float(sim.chainage_m[0]) + 20.0,
                                float(sim.chainage_m[-1]), 25.0)  # fmt: skip
    p = bl.to_csv(tmp_path / "b.csv")
    df = pd.read_csv(p)
    df.loc[1::2, "q_reference"] = 0
    df.to_csv(p, index=False, float_format="%.17g")
    assert main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--balises", str(p),
                 "--out", str(tmp_path / "q")]) == 0  # fmt: skip
    caps = pd.read_csv(tmp_path / "q" / "captures.csv")
    want = dict(zip(df["id"], df["q_reference"], strict=True))
    assert caps["q_reference"].tolist() == [want[i] for i in caps["id"]]
    assert set(caps["q_reference"]) == {0, 1}
    # and the list written from the table's columns reads back as a balise list
    cols = ["id", "chainage_m", "telegram", "q_reference"]
    back = caps[caps["config"] == caps["config"].iloc[0]][cols].merge(
        df.drop(columns=["chainage_m", "telegram", "q_reference"]), on="id")
    back.to_csv(tmp_path / "again.csv", index=False, float_format="%.17g")
    again = BaliseList.from_csv(tmp_path / "again.csv", track)
    assert again.q_reference.tolist() == [bool(want[i]) for i in again.ids]


def test_track_name_selects_one_track_of_a_file_holding_several(sim_dir, tmp_path, capsys):
    track = World.load(sim_dir / "world.npz").track
    # with the world's heights: a map without them is refused (check_track_height)
    coords = np.column_stack([track.lon_deg, track.lat_deg, track.h_m]).tolist()
    far = [[lon + 0.1, lat, h] for lon, lat, h in coords]  # another track, 7 km east
    feats = [{"type": "Feature", "properties": {"trackname": name},
              "geometry": {"type": "LineString", "coordinates": c}}
             for name, c in (("A", coords), ("B", far))]  # fmt: skip
    gj = tmp_path / "two.geojson"
    gj.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    base = ["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--spacing", "25",
            "--track", str(gj)]  # fmt: skip
    assert main([*base, "--out", str(tmp_path / "x")]) == 2
    assert "--track-name" in capsys.readouterr().err
    assert main([*base, "--track-name", "A", "--out", str(tmp_path / "a")]) == 0
    assert (tmp_path / "a" / "captures.csv").is_file()
    # --track-name without --track is refused before any work
    with pytest.raises(SystemExit):
        main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--track-name", "A",
              "--out", str(tmp_path / "y")])  # fmt: skip
    assert "--track-name needs --track" in capsys.readouterr().err


def test_odometer_accuracy_in_percent_is_refused_with_the_fraction(sim_dir, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--odometer-accuracy", "5",
              "5", "5", "--out", str(tmp_path / "x")])  # fmt: skip
    err = capsys.readouterr().err
    assert "5 % is 0.05" in err and "OdometerAccuracy(" not in err


def test_a_log_off_its_bounds_is_refused_and_a_missed_front_is_warned_on_the_console(
    sim_dir, tmp_path, capsys
):
    from locator.balises.command import _truth_warnings
    from locator.odometry.logfile import write_odometer_log

    # an odometer over-reading by 20 % (distance and speed alike: the log is consistent) with
    # bounds claimed at zero: its safe front would miss the truth, so it is refused up front
    sim = SimRun.read(sim_dir)
    log = odometer_along_run(sim, OdometerConfig(), seed=5).log
    p = write_odometer_log(log, tmp_path / "odo.csv")
    df = pd.read_csv(p)
    df.assign(dist_m=1.2 * df["dist_m"], speed_mps=1.2 * df["speed_mps"]).to_csv(
        p, index=False, float_format="%.17g")  # fmt: skip
    argv = ["-q", "balises", "--sim", str(sim_dir), "--masks", str(sim_dir / "true_masks.parquet"),
            "--spacing", "25", "--odometer-log", str(p)]  # fmt: skip
    rc = main([*argv, "--odometer-accuracy", "0", "0", "0", "--out", str(tmp_path / "b")])
    assert rc == 2 and "1.2 times the train's distance" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()
    # within the SUBSET-041 bounds it runs; a front the truth shows outside (any other cause)
    # is warned about loudly, with the hazardous captures
    rc = main([*argv, "--odometer-accuracy", "5", "0.25", "0.25", "--out", str(tmp_path / "c")])
    assert rc == 0
    capsys.readouterr()
    summary = pd.DataFrame([{"front_outside": 3, "epochs": 41, "hazardous": 1, "config": "r5"}])
    lines = _truth_warnings(summary, tmp_path / "c")
    assert "OUTSIDE the safe front interval at 3 of 41 epochs" in lines[0]
    assert "1 HAZARDOUS capture(s) with r5" in lines[1]


def test_balises_never_reached_are_said_so(sim_dir, tmp_path, capsys):
    track = World.load(sim_dir / "world.npz").track
    sim = SimRun.read(sim_dir)
    hi = float(sim.chainage_m.max())
    bl = BaliseList.along_track(track, hi + 40.0, min(hi + 100.0, track.length_m), 20.0)
    p = bl.to_csv(tmp_path / "far.csv")
    rc = main(["balises", "--sim", str(sim_dir), "--no-masks", "--balises", str(p),
               "--out", str(tmp_path / "b")])  # fmt: skip
    assert rc == 0
    out, err = capsys.readouterr()
    # without -q it says what it does before the long work, and shows the locating progress
    assert out.startswith(f"locator balises: {sim.n_epoch} epochs, {len(bl)} balises")
    assert "locating" in err
    assert "not reached" in out and "NaN" not in out
    assert f"not reached: {len(bl)} of {len(bl)} balises" in out
    # their timings are unknown: null in a strict JSON summary, not NaN (which jq refuses)

    def refuse(name: str) -> None:
        raise ValueError(f"non-standard JSON constant {name}")

    info = json.loads((tmp_path / "b" / "summary.json").read_text(), parse_constant=refuse)
    assert any(v is None for row in info["summary"] for v in row.values())


def test_masks_of_another_line_are_refused(sim_dir, tmp_path, capsys):
    """`balises` looked the masks up by chainage whatever line they were made on; they are put
    on the run's track by position now, as in `locator run` (line 144's masks: refused)."""
    from predisat.masks.fileformat import write_masks
    from predisat.masks.maskset import MaskSet
    from predisat.track import demo_track

    line = demo_track()
    ch = np.arange(0.0, 400.0, 10.0)
    lat, lon, _ = line.position_at(ch)
    other = write_masks(MaskSet.from_arrays(ch, lat, lon, 0.0, line.heading_at(ch),
                                            np.zeros((ch.size, 360))),
                        tmp_path / "l144.masks.parquet")  # fmt: skip
    argv = ["-q", "balises", "--sim", str(sim_dir), "--masks", str(other), "--spacing", "25",
            "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "do not fit track" in capsys.readouterr().err
    assert not (tmp_path / "o" / "captures.csv").exists()


def test_another_map_of_the_line_gives_the_same_captures_in_its_own_chainage(sim_dir, tmp_path):
    """A map whose origin is 100 m earlier (a straight lead-in, WGS84.fwd): balises, start,
    odometer and truth all move by 100 m, and the captures are those of the world's map."""
    from tests.locator.test_cli import _lead_in_map

    track = World.load(sim_dir / "world.npz").track
    other = _lead_in_map(track, 100.0, tmp_path / "other.geojson")
    base = ["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--spacing", "25"]
    assert main([*base, "--out", str(tmp_path / "own")]) == 0
    assert main([*base, "--track", str(other), "--out", str(tmp_path / "other")]) == 0
    own = pd.read_csv(tmp_path / "own" / "captures.csv")
    moved = pd.read_csv(tmp_path / "other" / "captures.csv")
    assert len(own) == len(moved) > 0
    np.testing.assert_allclose(moved["chainage_m"], own["chainage_m"] + 100.0, atol=0.5)
    for col in ("captured", "false", "hazardous", "missed"):
        assert (moved[col] == own[col]).all(), col
    np.testing.assert_allclose(moved["timing_error_s"], own["timing_error_s"], atol=0.05,
                               equal_nan=True)  # fmt: skip


def test_a_map_running_the_other_way_gives_the_same_captures(sim_dir, tmp_path):
    """A map counting its chainage from the other end (an OpenStreetMap way drawn the other
    way): the train runs toward falling chainage on it. A user trial's run was refused as
    "the run goes back 2464.88 m against its direction (+1)"."""
    from tests.locator.test_cli import _lead_in_map

    track = World.load(sim_dir / "world.npz").track
    rev = _lead_in_map(track, 100.0, tmp_path / "rev.geojson", True)
    base = ["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--spacing", "25"]
    assert main([*base, "--out", str(tmp_path / "own")]) == 0
    assert main([*base, "--track", str(rev), "--out", str(tmp_path / "rev")]) == 0
    own = pd.read_csv(tmp_path / "own" / "captures.csv")
    back = pd.read_csv(tmp_path / "rev" / "captures.csv")
    assert back["passed"].sum() == own["passed"].sum() > 0
    assert not back["hazardous"].any()
    assert back["captured"].sum() >= own["captured"].sum() - 1


def test_the_banner_names_the_systems_the_simulation_holds(tmp_path, test_data, capsys):
    """A user trial's GPS-only simulation was announced as "constellation all (GPS, GLONASS,
    Galileo, BeiDou, QZSS, NavIC/IRNSS)"."""
    canyon_world().save(tmp_path / "world.npz")
    assert main(["-q", "simulate", "--world", str(tmp_path / "world.npz"), "--duration", "40",
                 "--speed", "10", "--start-chainage", "65", "--nav",
                 str(test_data / "gnss/brdc1820_G01G02G05.10n"),
                 "--out", str(tmp_path / "sim")]) == 0  # fmt: skip
    capsys.readouterr()
    main(["balises", "--sim", str(tmp_path / "sim"), "--no-masks", "--spacing", "25",
          "--out", str(tmp_path / "b")])  # fmt: skip
    out = capsys.readouterr().out
    assert "constellation all (GPS in the simulation)" in out


def test_placed_balises_are_the_list_locator_balises_reads(sim_dir, tmp_path, capsys):
    """`locator place-balises` writes what `locator balises --balises` reads: a world's track,
    an outage over the run, the candidates the rule refuses left out (docs/odometry.md)."""
    placed = tmp_path / "placed.csv"
    assert main(["place-balises", "--world", str(sim_dir.parent / "world.npz"), "--from-km",
                 "0.08", "--to-km", "0.45", "--spacing", "25", "--outage", "100", "600",
                 "--entry-reach", "30", "--max-locacc", "50", "--out", str(placed)]) == 0
    printed = capsys.readouterr().out
    assert "not placeable: 105-130 m" in printed  # 30 + 1 + 4.007 % x 470 + 1: 51 m
    ids = pd.read_csv(placed)["id"].tolist()
    assert 0 < len(ids) < 15
    assert main(["-q", "balises", "--sim", str(sim_dir), "--no-masks", "--balises", str(placed),
                 "--out", str(tmp_path / "b")]) == 0  # fmt: skip
    caps = pd.read_csv(tmp_path / "b" / "captures.csv")
    assert caps["id"].tolist() == ids


def test_the_odometer_choices_are_the_campaigns_odometers() -> None:
    # written out for the parsers (the campaign is not imported at start-up): one list
    from locator.balises.campaign import ODOMETERS
    from locator.balises.command import DEFAULT_ODOMETER, ODOMETER_KINDS

    assert ODOMETER_KINDS == tuple(ODOMETERS) and DEFAULT_ODOMETER in ODOMETERS


def test_masks_made_for_a_higher_antenna_or_a_swapped_survey_are_checked_as_locator_run_does(
    sim_dir, tmp_path, capsys
):
    """A review: masks made for a 5.5 m antenna ran with the simulation's 4 m antenna in
    silence (`locator run` refuses them), and a survey with swapped cameras went unsaid."""
    from dataclasses import replace

    from predisat.masks.fileformat import read_masks, write_masks

    true = read_masks(sim_dir / "true_masks.parquet")
    high = write_masks(replace(true, provenance={**true.provenance, "antenna_height_m": 5.5}),
                       tmp_path / "high.masks.parquet")  # fmt: skip
    base = ["-q", "balises", "--sim", str(sim_dir), "--spacing", "25"]
    capsys.readouterr()
    assert main([*base, "--masks", str(high), "--out", str(tmp_path / "high")]) == 2
    assert "made for an antenna 5.5 m above the track axis" in capsys.readouterr().err
    swapped = {"left": {"agree": 2, "disagree": 30, "pairs": 32, "swapped": True}}
    sw = write_masks(replace(true, provenance={**true.provenance, "side_check": swapped}),
                     tmp_path / "swapped.masks.parquet")  # fmt: skip
    assert main([*base, "--masks", str(sw), "--out", str(tmp_path / "sw")]) == 0
    assert "left and right are probably swapped" in capsys.readouterr().err
