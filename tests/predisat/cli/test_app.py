"""Command-line behaviour: help, clear errors on bad arguments (exit code 2, no traceback)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from locator import cli as locator_cli
from predisat.cli import app as cli
from predisat.cli import common

# Existing inputs for the tests of other options (inputs are checked at parse time too).
AN_INPUT_DIR = str(Path(__file__).parent)
AN_INPUT_FILE = __file__
AVAIL = ["availability", "--masks", AN_INPUT_FILE]


def test_help_lists_commands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("synth", "demo", "availability", "evaluate-sky"):
        assert command in out


def test_locator_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        locator_cli.main(["--help"])
    assert exc.value.code == 0
    assert "SATHIA" in capsys.readouterr().out


def test_synth_rejects_range_outside_track(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    code = cli.main(["synth", "--from-km", "3", "--to-km", "99", "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert "--from-km 3 --to-km 99" in err and "not inside the track" in err


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--from-km", "6", "--to-km", "4"], "start must be below the end"),
        (["--from-km", "4000", "--to-km", "6000"], "did you give metres? (--from-km 4 --to-km 6)"),
    ],
)
def test_km_range_mistakes_get_the_fix(tmp_path, capsys, argv: list[str], expected: str) -> None:
    for main, command in ((cli.main, "synth"), (cli.main, "demo"), (locator_cli.main, "simulate")):
        code = main([command, *argv, "--out", str(tmp_path / "o")])
        assert code == 2
        assert expected in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_km_range_takes_the_track_end_and_gives_no_metres_hint_for_a_small_overshoot() -> None:
    from predisat.cli.common import CliError, km_range
    from predisat.track import demo_track

    track = demo_track()
    top_km = track.length_m / 1000.0
    # the end given rounded up by a float's width (a user trial's 3999.99999 m track, 4 km)
    assert km_range(track, 0.0, top_km + 1e-7) == (0.0, track.length_m)
    # a start within the rounding of the end is no stretch (the end is clamped first)
    with pytest.raises(CliError, match="start must be below the end"):
        km_range(track, top_km + 2e-4, top_km + 4e-4)
    # past the end by more than a rounding: refused with the track's range, no metres advice
    with pytest.raises(CliError) as exc:
        km_range(track, top_km - 1.0, top_km + 1.9)
    assert "not inside the track" in str(exc.value) and "did you give metres" not in str(exc.value)


def test_synth_rejects_missing_track_file(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.geojson"
    code = cli.main(["synth", "--track", str(missing), "--out", str(tmp_path / "o")])
    assert code == 2
    assert str(missing) in capsys.readouterr().err


def test_console_scripts_installed() -> None:
    # The entry points are what a user types; check they resolve to our main functions.
    for name in ("predisat", "locator"):
        res = subprocess.run(
            [sys.executable, "-c", f"from importlib.metadata import entry_points as e; "
             f"print([x.value for x in e(group='console_scripts') if x.name == '{name}'])"],
            capture_output=True, text=True, check=True,
        )
        assert f"{name}.cli:main" in res.stdout


def test_evaluate_sky_rejects_missing_folder(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "no_photos"
    code = cli.main(["evaluate-sky", "--data", str(missing)])
    assert code == 2
    assert str(missing) in capsys.readouterr().err


def test_shipped_scenery_recipe_is_valid() -> None:
    import yaml

    from predisat.synth.world import WorldSpec

    recipe = Path(__file__).resolve().parents[3] / "surveys" / "nice_digne_canyon.yaml"
    spec = WorldSpec.from_dict(yaml.safe_load(recipe.read_text()))
    assert {"rock_walls", "tunnel", "cutting"} <= spec.kinds


def test_synth_rejects_bad_scenery_recipe(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("stretches: [{kind: volcano, start_m: 0, end_m: 100}]\n")
    code = cli.main(["synth", "--to-km", "0.2", "--scenery", str(bad), "--out", str(tmp_path)])
    assert code == 2
    assert "--scenery" in capsys.readouterr().err


def test_synth_rejects_a_solar_hour_off_the_clock(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli.main(["synth", "--to-km", "0.2", "--solar-hour", "25", "--out",
                     str(tmp_path / "o")])  # fmt: skip
    assert code == 2
    assert "--solar-hour 25" in capsys.readouterr().err
    assert not (tmp_path / "o" / "survey").exists()


def test_synth_360_rig_refuses_side_camera_options(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    for extra in (["--camera", "pinhole"], ["--pitch-deg", "30"]):
        code = cli.main(["synth", "--to-km", "0.2", "--rig", "360", *extra,
                         "--out", str(tmp_path / "o")])  # fmt: skip
        assert code == 2
        assert "--rig 360 has no side cameras" in capsys.readouterr().err
    assert not (tmp_path / "o" / "survey").exists()


def test_where_filters_parse_and_reject_bad_items() -> None:
    assert common.parse_where(["usage=main", "service="]) == {"usage": "main", "service": None}
    assert common.parse_where(None) is None
    with pytest.raises(common.CliError, match="KEY=VALUE"):
        common.parse_where(["usage"])


def test_evaluate_sky_with_a_candidate_network(
    tmp_path, test_data, capsys: pytest.CaptureFixture[str]
) -> None:
    import csv
    import shutil

    from tests.predisat.candidate_net import net_copy

    data = tmp_path / "toy"  # the two held-out frames of the test data, as images/ + masks/
    (data / "images").mkdir(parents=True)
    (data / "masks").mkdir()
    for stem in ("cloudy_right_000006", "cloudy_right_000012"):
        shutil.copy(test_data / "sky_synth" / f"{stem}.jpg", data / "images")
        shutil.copy(test_data / "sky_synth" / f"{stem}_label.png", data / "masks" / f"{stem}.png")

    def ious(*extra: str) -> list[float]:
        out = tmp_path / f"out{len(list(tmp_path.iterdir()))}"
        assert cli.main(["evaluate-sky", "--data", str(data), "--out", str(out), "--quiet",
                         "--method", "ensemble", *extra]) == 0
        with open(out / "toy" / "toy_per_image.csv", newline="") as fh:
            return [float(r["iou"]) for r in csv.DictReader(fh)]

    shipped = ious()
    # the shipped network from another file scores the same; at another input size it runs
    # (and scores otherwise)
    assert ious("--sky-net", str(net_copy(tmp_path / "same"))) == shipped
    assert ious("--sky-net", str(net_copy(tmp_path / "other", input_px=32))) != shipped
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # refused by the parser, before any work
        cli.main(["evaluate-sky", "--data", str(data), "--method", "learned",
                  "--sky-net", str(tmp_path / "same" / "net.onnx")])
    assert exc.value.code == 2
    assert "--sky-net is for --method cnn or ensemble" in capsys.readouterr().err


def test_process_strict_and_bad_margins_fail_cleanly(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    import csv

    from predisat.camera.models import CameraModel
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    generate_survey(
        demo_track(), 4000.0, 4020.0, sky="clear", seed=4, out_dir=tmp_path,
        camera=CameraModel.pinhole_from_fov(160, 120, 74.0), progress=False,
    )  # fmt: skip
    survey = tmp_path / "survey"
    with open(survey / "manifest.csv", newline="") as fh:
        victim = list(csv.DictReader(fh))[2]
    (survey / victim["image"]).write_bytes(b"not a jpeg")
    base = ["process", str(survey), "--quiet", "--chunk-m", "100", "--scheduler", "serial"]

    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # refused by the parser, before any work
        cli.main([*base, "--out", str(tmp_path / "a"), "--margins", "nope.json"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "nope.json" in err and "--calibrate" in err and "Traceback" not in err

    assert cli.main([*base, "--out", str(tmp_path / "b"), "--strict"]) == 2
    err = capsys.readouterr().err
    assert victim["frame_id"] in err and "without --strict" in err and "Traceback" not in err
    assert not (tmp_path / "b" / "masks.parquet").exists()

    assert cli.main([*base, "--out", str(tmp_path / "c")]) == 0  # skipped, listed
    with open(tmp_path / "c" / "bad_frames.csv", newline="") as fh:
        assert [r["frame_id"] for r in csv.DictReader(fh)] == [victim["frame_id"]]


def test_export_writes_the_three_formats(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    from predisat.masks import fileformat as maskio
    from tests.predisat.masks.test_fileformat import make_set

    masks = make_set(step=0.5)
    src = maskio.write_masks(masks, tmp_path / "masks.parquet")
    ch = float(masks.chainage_m[3]) + 1.0
    want = {
        "urbannav": maskio.to_urbannav_csv(masks, tmp_path / "u.csv"),
        "rtklib": maskio.to_rtklib_mask(masks, ch, tmp_path / "r.txt"),
        "pvgis": maskio.to_pvgis_horizon(masks, ch, tmp_path / "p.txt"),
    }
    for fmt, ref in want.items():
        out = tmp_path / f"cli_{fmt}"
        extra = [] if fmt == "urbannav" else ["--chainage", str(ch)]
        assert cli.main(["export", str(src), "--format", fmt, "--out", str(out), *extra]) == 0
        assert out.read_bytes() == ref.read_bytes()
    bare = tmp_path / "bare.txt"
    (tmp_path / "provenance.json").write_text("{}")  # a finished process folder's record
    assert cli.main(["export", str(tmp_path), "--format", "rtklib", "--out", str(bare),
                     "--chainage", str(ch), "--bare"]) == 0  # fmt: skip
    assert bare.read_bytes() == maskio.to_rtklib_mask(
        masks, ch, tmp_path / "rb.txt", include_margin=False
    ).read_bytes()
    capsys.readouterr()
    assert cli.main(["export", str(src), "--format", "pvgis", "--out", str(bare),
                     "--chainage", "1e7"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "outside" in err and "Traceback" not in err
    # a missing output folder is created, as other commands create theirs (was refused:
    # "create it first")
    for fmt in want:
        out = tmp_path / "new" / fmt / "mask.txt"
        extra = [] if fmt == "urbannav" else ["--chainage", str(ch)]
        assert cli.main(["export", str(src), "--format", fmt, "--out", str(out), *extra]) == 0
        assert out.read_bytes() == want[fmt].read_bytes()
    # urbannav: a header line by default, as UrbanNav's files; --no-header drops it
    out = tmp_path / "nohdr.csv"
    assert cli.main(["export", str(src), "--format", "urbannav", "--out", str(out),
                     "--no-header"]) == 0  # fmt: skip
    assert out.read_bytes() == maskio.to_urbannav_csv(
        masks, tmp_path / "un.csv", header=False
    ).read_bytes()
    assert want["urbannav"].read_text().startswith("lat_deg,lon_deg,h_m,e_0,")
    # options of another format: refused by the parser (tests/predisat/cli/test_vocabulary.py)


@pytest.mark.slow
def test_demo_end_to_end_on_a_short_stretch(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    from predisat.masks.fileformat import read_masks
    from predisat.masks.truth import TrueMasks

    out = tmp_path / "demo"
    assert cli.main(["demo", "--out", str(out), "--from-km", "4.0", "--to-km", "4.1",
                     "--workers", "1", "--quiet"]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert "demo 5/5" in printed and "demo: done" in printed and "demo: estimate" in printed
    from tests.predisat.cli.test_demo import assert_index_complete

    links = assert_index_complete(out)
    for name in ("contact_sheet.png", "evaluation.png", "availability/report.html",
                 "masks/masks.parquet", "locator/summary.csv"):  # fmt: skip
        assert name in links
    masks = read_masks(out / "masks" / "masks.parquet")
    np.testing.assert_allclose(masks.chainage_m, np.arange(4000.0, 4100.1, 10.0), atol=1e-3)
    for name in ("evaluation.png", "contact_sheet.png", "availability/report.html",
                 "locator/summary.csv"):  # fmt: skip
        assert (out / name).stat().st_size > 0, name
    import pandas as pd

    summary = pd.read_csv(out / "locator" / "summary.csv")
    assert all(summary[c].dtype.kind == "i" for c in ("epochs", "hmi", "hmi_fix", "mi"))
    # the masks' safety, counted here on a 0.1 deg elevation grid against the rendered truth
    truth = TrueMasks.load(out / "truth" / "true_masks.npz")
    rows = [int(np.argmin(np.abs(truth.chainage_m - s))) for s in masks.chainage_m]
    assert truth.az_deg.size == masks.n_az
    grid = (np.arange(900) + 0.5) * 0.1
    trusted = grid[None, None, :] > masks.effective_mask_deg.astype(float)[..., None]
    visible = grid[None, None, :] > truth.mask_el_deg[rows][..., None]
    assert trusted.sum() > 0.2 * visible.sum()  # the masks open a real share of the sky
    assert (trusted & ~visible).sum() <= 0.001 * trusted.sum()  # the 99.9 % target
    capsys.readouterr()
    assert cli.main(["demo", "--out", str(out), "--from-km", "5", "--to-km", "4"]) == 2
    assert "--from-km" in capsys.readouterr().err


def test_interrupted_process_keeps_its_work(
    tmp_path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C during the chunks: one line, exit code 130, and the rerun segments nothing again."""
    import predisat.reconstruct.batch as pl
    from predisat.camera.models import CameraModel
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    generate_survey(
        demo_track(), 4000.0, 4020.0, sky="clear", seed=5, out_dir=tmp_path,
        camera=CameraModel.pinhole_from_fov(160, 120, 74.0), progress=False,
    )  # fmt: skip
    args = ["process", str(tmp_path / "survey"), "--quiet", "--out", str(tmp_path / "m"),
            "--scheduler", "serial"]

    def ctrl_c(*_: object) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(pl, "run_chunks", ctrl_c)
        capsys.readouterr()
        assert cli.main(args) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "rerun the same command" in err and "Traceback" not in err
    assert not (tmp_path / "m" / "masks.parquet").exists()

    def ctrl_c_in_numba(*_: object) -> None:
        # what a numba-compiled function raises when Ctrl-C lands inside it
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher returned a result with an exception set") from exc

    def other_system_error(*_: object) -> None:
        raise SystemError("a genuine internal error")

    def ctrl_c_in_an_extension_import(*_: object) -> None:
        # what a C extension's import raises when Ctrl-C lands in it (matplotlib's ft2font)
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    def genuine_import_error(*_: object) -> None:
        raise ImportError("a genuine import error")

    with monkeypatch.context() as m:
        m.setattr(pl, "run_chunks", ctrl_c_in_numba)
        assert cli.main(args) == 130
        m.setattr(pl, "run_chunks", ctrl_c_in_an_extension_import)
        assert cli.main(args) == 130
        m.setattr(pl, "run_chunks", other_system_error)
        with pytest.raises(SystemError, match="genuine"):
            cli.main(args)
        m.setattr(pl, "run_chunks", genuine_import_error)
        with pytest.raises(ImportError, match="genuine"):
            cli.main(args)
        # and while the command line itself imports the commands' modules
        m.setattr(cli, "build_parser", ctrl_c_in_an_extension_import)
        assert cli.main(args) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "Traceback" not in err
    assert cli.main(args) == 0
    done = capsys.readouterr()
    assert ", 0 frames segmented" in done.out + done.err  # the cache of the first run


@pytest.mark.parametrize(
    ("main", "argv"),
    [
        (cli.main, ["export", AN_INPUT_FILE, "--format", "urbannav", "--out", "{dir}"]),
        (cli.main, ["availability", "--out", "{file}"]),
        (cli.main, ["synth", "--out", "{file}"]),
        (cli.main, ["process", AN_INPUT_DIR, "--out", "{file}"]),
        (locator_cli.main, ["calibrate", "OBS", "--out", "{dir}"]),
        (locator_cli.main, ["run", "SIM", "--out", "{file}"]),
    ],
)
def test_wrong_kind_of_output_path_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], main, argv: list[str]
) -> None:
    # A folder where a file is written (or the reverse) must stop at parse time, not after
    # minutes of work; and the existing path must be left untouched.
    existing_file = tmp_path / "report.txt"
    existing_file.write_text("keep")
    args = [a.format(dir=tmp_path, file=existing_file) for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--out" in err
    assert ("is a folder" in err) if "{dir}" in argv else ("is an existing file" in err)
    assert existing_file.read_text() == "keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.txt"]


@pytest.mark.parametrize(
    ("main", "argv", "option"),
    [
        (cli.main, [*AVAIL, "--out", "o", "--cutoff", "-5"], "--cutoff"),
        (cli.main, [*AVAIL, "--out", "o", "--cutoff", "90"], "--cutoff"),
        (cli.main, [*AVAIL, "--out", "o", "--workers", "0"], "--workers"),
        (cli.main, [*AVAIL, "--out", "o", "--interval-every", "0"],
         "--interval-every"),
        (cli.main, [*AVAIL, "--out", "o", "--step", "nan"], "--step"),
        (cli.main, ["process", AN_INPUT_DIR, "--out", "o", "--chunk-m", "-1"], "--chunk-m"),
        (cli.main, ["synth", "--out", "o", "--spacing-m", "0"], "--spacing-m"),
        (locator_cli.main, ["run", "--out", "o", "--cutoff", "-5"], "--cutoff"),
        (locator_cli.main, ["run", "--out", "o", "--extra-margin", "-1"], "--extra-margin"),
        (locator_cli.main, ["run", "--out", "o", "--start-uncertainty", "-1"],
         "--start-uncertainty"),
        (locator_cli.main, ["simulate", "--out", "o", "--rate", "0"], "--rate"),
        (locator_cli.main, ["run", "--out", "o", "--k-sigma", "0"], "--k-sigma"),
        (locator_cli.main, ["calibrate", "--out", "o", "--k-sigma", "nan"], "--k-sigma"),
        (cli.main, [*AVAIL, "--out", "o", "--k-sigma", "-1"],
         "--k-sigma"),
        (cli.main, ["synth", "--out", "o", "--from-km", "nan"], "--from-km"),
        (locator_cli.main, ["simulate", "--out", "o", "--to-km", "inf"], "--to-km"),
    ],
)  # fmt: skip
def test_out_of_range_options_are_refused_under_their_own_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], main, argv: list[str], option: str
) -> None:
    args = [str(tmp_path / a) if a == "o" else a for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}" in err
    assert "_deg" not in err and "_m " not in err  # no internal parameter names


def test_output_file_may_be_in_a_new_folder_but_not_under_a_file(tmp_path: Path) -> None:
    import argparse

    from predisat.cli.args import output_file

    assert output_file(str(tmp_path / "new" / "m.json")) == tmp_path / "new" / "m.json"
    (tmp_path / "f.txt").write_text("x")
    with pytest.raises(argparse.ArgumentTypeError, match=r"f\.txt is a file"):
        output_file(str(tmp_path / "f.txt" / "sub" / "m.json"))


def test_availability_basemap_is_checked_and_passed_on(tmp_path, capsys, monkeypatch) -> None:
    from predisat.cli import availability as cli_availability

    masks = tmp_path / "m.parquet"
    masks.write_bytes(b"")  # only its existence is checked before the run
    with pytest.raises(SystemExit) as stop:  # refused by the parser, naming the file
        cli.main(["availability", "--masks", str(masks), "--basemap",
                  str(tmp_path / "none.geojson"), "--out", str(tmp_path / "o")])  # fmt: skip
    assert stop.value.code == 2 and "none.geojson" in capsys.readouterr().err
    base = tmp_path / "osm.geojson"
    base.write_text('{"type": "FeatureCollection", "features": []}')
    seen = {}
    monkeypatch.setattr(cli_availability, "run_availability",
                        lambda *a, **kw: seen.update(kw) or (_ for _ in ()).throw(SystemExit(0)))
    with pytest.raises(SystemExit):
        cli.main(["availability", "--masks", str(masks), "--basemap", str(base), "--out",
                  str(tmp_path / "o"), "--scheduler", "serial"])  # fmt: skip
    assert Path(seen["basemap"]) == base


def test_process_cell_sweep_reaches_the_reconstruction(tmp_path, monkeypatch) -> None:
    from predisat.cli import process as cli_process

    survey = tmp_path / "survey"
    survey.mkdir()
    (survey / "survey.yaml").write_text("format: predisat-survey/1\n")
    seen: dict[str, object] = {}

    def fake(survey_dir, out, params, **kw):  # type: ignore[no-untyped-def]
        seen["params"] = params
        raise SystemExit(0)

    monkeypatch.setattr(cli_process, "process_survey", fake)
    for extra, expected in (([], 0.0), (["--cell-sweep"], None)):
        with pytest.raises(SystemExit):
            cli.main(["process", str(survey), "--out", str(tmp_path / "o"), *extra])
        assert seen.pop("params").reconstruction.cell_sweep_m == expected  # type: ignore[attr-defined]
    for extra, past in (([], 20.0), (["--half-space-only"], None)):
        with pytest.raises(SystemExit):
            cli.main(["process", str(survey), "--out", str(tmp_path / "o"), *extra])
        assert seen.pop("params").reconstruction.carve_past_deg == past  # type: ignore[attr-defined]


def test_python_dash_m_runs_both_command_lines() -> None:
    import subprocess
    import sys

    from predisat import __version__

    for package, out in (("predisat", f"predisat {__version__}"), ("locator", "locator")):
        done = subprocess.run([sys.executable, "-m", package, "--version"], capture_output=True,
                              text=True, timeout=120, check=False)  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith(out)


def test_export_says_how_far_the_position_written_is_from_the_chainage_asked(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    from predisat.masks import fileformat as maskio
    from tests.predisat.masks.test_fileformat import make_set

    masks = make_set(step=0.5)
    src = maskio.write_masks(masks, tmp_path / "masks.parquet")
    ch = masks.chainage_m
    asked = float(ch[3]) + 0.3 * float(ch[4] - ch[3])
    out = tmp_path / "r.txt"
    capsys.readouterr()
    assert cli.main(["export", str(src), "--format", "rtklib", "--out", str(out),
                     "--chainage", f"{asked}"]) == 0  # fmt: skip
    said = capsys.readouterr().out
    away = f"{abs(asked - float(ch[3])):.2f} m away"
    assert f"{float(ch[3]):.2f} m" in said and away in said and "not a bound" in said
    # within the end cell, past the last position: written (the exporters take the cell)
    beyond = float(masks.cell_bounds_m[-1]) - 0.01
    assert cli.main(["export", str(src), "--format", "rtklib", "--out", str(out),
                     "--chainage", f"{beyond}"]) == 0  # fmt: skip
    # past the coverage, by less than the old 50 m reach: refused by the command with its hint
    # (the library refused it with a bare message before)
    past = float(masks.cell_bounds_m[-1]) + 1.0
    assert cli.main(["export", str(src), "--format", "rtklib", "--out", str(out),
                     "--chainage", f"{past}"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "--chainage" in err and "outside the masks of" in err
