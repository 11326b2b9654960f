"""One argument vocabulary for ``predisat`` and ``locator`` (issue 33, item 1): every
subcommand described, every option with its default, contradictions and likely unit mistakes
refused at parse time with the fix, and missing files named with what they should hold."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from locator import cli as locator_cli
from predisat.cli import app as predisat_cli
from predisat.cli.args import HelpFormatter


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """Every subcommand parser, by its name (nested subcommands as ``a b``)."""
    found: dict[str, argparse.ArgumentParser] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found[name] = sub
                found.update({f"{name} {k}": v for k, v in _subparsers(sub).items()})
    return found


def _commands() -> list[tuple[str, argparse.ArgumentParser]]:
    out = []
    builds = (("predisat", predisat_cli.build_parser), ("locator", locator_cli.build_parser))
    for prog, build in builds:
        out += [(f"{prog} {name}", p) for name, p in _subparsers(build()).items()]
    return out


COMMANDS = _commands()


def test_both_command_lines_have_their_subcommands() -> None:
    names = {name for name, _ in COMMANDS}
    for expected in ("predisat synth", "predisat process", "predisat availability",
                     "predisat export", "predisat evaluate", "predisat evaluate-sky",
                     "predisat demo", "locator simulate", "locator run", "locator evaluate",
                     "locator calibrate", "locator demo", "locator balises",
                     "locator place-balises"):  # fmt: skip
        assert expected in names


@pytest.mark.parametrize(("name", "parser"), COMMANDS, ids=[n for n, _ in COMMANDS])
def test_every_subcommand_is_described_and_every_option_names_its_default(
    name: str, parser: argparse.ArgumentParser
) -> None:
    assert parser.description and len(parser.description.split()) >= 8, name
    assert parser.formatter_class is HelpFormatter, name
    formatter = parser._get_formatter()
    # one of a required group (--sim or --obs; --masks, --cutoff or --no-masks) is required
    in_required_group = {id(a) for g in parser._mutually_exclusive_groups if g.required
                         for a in g._group_actions}  # fmt: skip
    for action in parser._actions:
        if not action.option_strings or isinstance(action, argparse._HelpAction):
            continue  # positionals are required; -h is argparse's
        flag = action.nargs == 0
        assert action.help, f"{name} {action.option_strings[0]}: no help"
        if flag or action.required or id(action) in in_required_group:
            continue
        # the help as printed: argparse's "(default: X)", or the text saying what happens
        text = formatter._expand_help(action) if action.help else ""
        assert "default" in text, f"{name} {action.option_strings[0]}: {text!r} names no default"
        assert "(default: None)" not in text, f"{name} {action.option_strings[0]}: {text!r}"


def test_demo_help_names_the_locator_step_the_estimate_and_quick(capsys) -> None:
    with pytest.raises(SystemExit):
        predisat_cli.main(["demo", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "locator" in out and "--quick" in out and "estimate" in out and "index.html" in out


# --- contradictions refused at parse time (argparse: usage, message, exit 2) -----------------


def _refused(main, argv: list[str], capsys, *, usage: bool = True) -> str:
    """The message of a refusal at parse time: exit status 2 and argparse's usage line, or
    (``usage=False``: a missing input) the one line ``prog: error: ...``."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    if usage:
        assert err.startswith("usage:")
    else:
        assert len(err.splitlines()) == 1 and " error: argument " in err, err
    return " ".join(err.split())


@pytest.fixture
def files(tmp_path: Path) -> dict[str, str]:
    """Existing placeholder inputs: parse-time checks look at the options, not the contents."""
    names = {"masks": "m.parquet", "csv": "t.csv", "json": "e.json", "obs": "a.obs",
             "nav": "a.nav", "npz": "w.npz", "yaml": "s.yaml"}  # fmt: skip
    out = {}
    for key, name in names.items():
        (tmp_path / name).write_text("x")
        out[key] = str(tmp_path / name)
    for key in ("sim", "run", "dir"):
        (tmp_path / key).mkdir()
        out[key] = str(tmp_path / key)
    out["out"] = str(tmp_path / "out")
    return out


CONTRADICTIONS = [
    # the user's case: --masks with --no-masks silently used the masks
    (locator_cli.main, "run --sim {sim} --masks {masks} --no-masks --out {out}", "--no-masks"),
    (locator_cli.main, "run --sim {sim} --masks {masks} --cutoff 15 --out {out}", "--cutoff"),
    (locator_cli.main, "run --sim {sim} --obs {obs} --nav {nav} --no-masks --out {out}", "--obs"),
    (locator_cli.main, "run --sim {sim} --nav {nav} --no-masks --out {out}", "--nav"),
    (locator_cli.main, "run --obs {obs} --no-masks --out {out}", "--obs needs --nav"),
    (locator_cli.main, "run --sim {sim} --out {out}", "--masks --cutoff --no-masks"),
    (locator_cli.main, "run --sim {sim} --no-masks --extra-margin 2 --out {out}",
     "--extra-margin"),
    (locator_cli.main, "simulate --world {npz} --scenery {yaml} --out {out}", "--scenery"),
    (locator_cli.main, "simulate --world {npz} --from-km 4 --out {out}", "--from-km"),
    (locator_cli.main, "simulate --scenery {yaml} --to-km 5 --out {out}", "--to-km"),
    (locator_cli.main, "simulate --world {npz} --world-seed 3 --out {out}", "--world-seed"),
    (locator_cli.main, "calibrate --sim {sim} --obs {obs} --nav {nav} --out {out}", "--obs"),
    (locator_cli.main, "calibrate --obs {obs} --nav {nav} --states nlos --out {out}",
     "--states"),
    (locator_cli.main, "calibrate --sim {sim} --nav {nav} --out {out}", "--nav"),
    (locator_cli.main, "calibrate --obs {obs} {obs} --nav {nav} --station 1 2 3 --out {out}",
     "--station"),
    (locator_cli.main, "evaluate {run} --sim {sim} --truth-chainage 4000", "--truth-chainage"),
    (locator_cli.main, "balises --sim {sim} --masks {masks} --no-masks --out {out}",
     "--no-masks"),
    (locator_cli.main, "balises --sim {sim} --no-masks --odometer motor --odometer-log {csv} "
     "--out {out}", "--odometer-log"),
    (locator_cli.main, "balises --sim {sim} --no-masks --max-accel 2 --out {out}", "--max-accel"),
    (predisat_cli.main, "export {masks} --format urbannav --chainage 4000 --out {out}",
     "--chainage"),
    (predisat_cli.main, "export {masks} --format rtklib --out {out}", "--chainage M"),
    (predisat_cli.main, "export {masks} --format rtklib --chainage 4000 --header --out {out}",
     "--header"),
    (predisat_cli.main, "export {masks} --format rtklib --chainage 4000 --no-header "
     "--out {out}", "--no-header"),
    (predisat_cli.main, "export {masks} --format urbannav --header --no-header --out {out}",
     "not both"),
    (predisat_cli.main, "export {masks} --format rtklib --chainage 4000 --pvgis-layout table "
     "--out {out}", "--pvgis-layout"),
    (predisat_cli.main, "evaluate {masks} --truth {dir} --calibrate --margins {json}",
     "--margins"),
    (predisat_cli.main, "evaluate {masks} --truth {dir} --target 0.99", "--target"),
    (predisat_cli.main, "synth --camera fisheye --calibration {yaml} --out {out}",
     "--calibration"),
    (predisat_cli.main, "process {dir} --segmenter learned --sky-net {npz} --out {out}",
     "--sky-net"),
    (predisat_cli.main, "evaluate-sky --data {dir} --method grabcut --sky-net {npz}",
     "--sky-net"),
    (locator_cli.main, "run --sim {sim} --no-masks --integrity-risk 1e-9 --k-sigma 2 --out {out}",
     "--k-sigma"),
    (predisat_cli.main, "availability --masks {masks} --integrity-risk 1e-9 --k-sigma 2 "
     "--out {out}", "--k-sigma"),
    (locator_cli.main, "balises --sim {sim} --no-masks --integrity-risk 1e-9 --k-sigma 2 "
     "--out {out}", "--k-sigma"),
]


@pytest.mark.parametrize(("main", "argv", "named"), CONTRADICTIONS,
                         ids=[a for _, a, _ in CONTRADICTIONS])  # fmt: skip
def test_contradictions_are_refused_before_any_work(main, argv, named, files, capsys) -> None:
    err = _refused(main, argv.format(**files).split(), capsys)
    assert named in err
    assert not Path(files["out"]).exists()


# --- likely unit mistakes: refused with the value meant -------------------------------------


UNIT_MISTAKES = [
    # the user's cases
    (predisat_cli.main, "availability --masks {masks} --cutoff 0.26 --out {out}",
     "looks like radians (0.26 rad = 14.9 deg)"),
    (locator_cli.main, "run --sim {sim} --cutoff 0.26 --out {out}", "looks like radians"),
    (locator_cli.main, "simulate --speed 300 --out {out}", "300 m/s is 1080 km/h"),
    # the same vocabulary elsewhere
    (locator_cli.main, "balises --sim {sim} --cutoff 0.2 --out {out}", "radians"),
    (predisat_cli.main, "synth --pitch-deg 0.78 --out {out}", "radians"),
    (locator_cli.main, "simulate --rate 1000 --out {out}", "Hz"),
    (locator_cli.main, "run --sim {sim} --no-masks --antenna-height 400 --out {out}",
     "400 cm is 4"),
    (predisat_cli.main, "evaluate {masks} --truth {dir} --calibrate --target 99.9",
     "looks like percent"),
    (predisat_cli.main, "availability --masks {masks} --constellation gsp --out {out}",
     "no constellation"),
    (locator_cli.main, "run --sim {sim} --no-masks --constellation X --out {out}",
     "no constellation"),
    (locator_cli.main, "run --sim {sim} --no-masks --integrity-risk 1 --out {out}",
     "1 % is 0.01"),
    (predisat_cli.main, "availability --masks {masks} --integrity-risk 0.5 --out {out}",
     "no integrity risk per epoch"),
    (predisat_cli.main, "demo --integrity-risk 0 --out {out}", "a probability"),
]


@pytest.mark.parametrize(("main", "argv", "hint"), UNIT_MISTAKES,
                         ids=[a for _, a, _ in UNIT_MISTAKES])  # fmt: skip
def test_likely_unit_mistakes_are_refused_with_the_value_meant(main, argv, hint, files,
                                                               capsys) -> None:  # fmt: skip
    assert hint in _refused(main, argv.format(**files).split(), capsys)


def test_small_angles_in_degrees_are_accepted_with_their_unit(files) -> None:
    parser = predisat_cli.build_parser()
    a = parser.parse_args(["availability", "--masks", files["masks"], "--cutoff", "0.5deg", "0",
                           "15", "--out", files["out"]])  # fmt: skip
    assert a.cutoff == [0.5, 0.0, 15.0]
    b = locator_cli.build_parser().parse_args(["simulate", "--speed", "83.3", "--out",
                                               files["out"]])  # fmt: skip
    assert b.speed == 83.3


# --- missing input files: one line naming the file, with what it should hold ---------------


MISSING = [
    # the user's case: a bare "[Errno 2]"
    (locator_cli.main, "evaluate {run} --truth-csv {missing}", ("gps_s", "chainage_m")),
    (locator_cli.main, "run --sim {missing} --no-masks --out {out}", ("locator simulate",)),
    (locator_cli.main, "run --sim {sim} --masks {missing} --out {out}", ("mask file",)),
    (locator_cli.main, "run --sim {sim} --no-masks --error-model {missing} --out {out}",
     ("locator calibrate",)),
    (locator_cli.main, "simulate --scenery {missing} --out {out}", ("scenery recipe",)),
    (locator_cli.main, "balises --sim {sim} --no-masks --odometer-log {missing} --out {out}",
     ("odometer log",)),
    (predisat_cli.main, "process {missing} --out {out}", ("survey.yaml",)),
    (predisat_cli.main, "availability --masks {missing} --out {out}", ("mask file",)),
    (predisat_cli.main, "export {missing} --format urbannav --out {out}", ("mask file",)),
]


@pytest.mark.parametrize(("main", "argv", "words"), MISSING, ids=[a for _, a, _ in MISSING])
def test_a_missing_input_is_named_with_what_it_should_hold(main, argv, words, files, tmp_path,
                                                           capsys) -> None:  # fmt: skip
    missing = str(tmp_path / "missing.csv")
    err = _refused(main, argv.format(missing=missing, **files).split(), capsys, usage=False)
    assert missing in err and "Errno" not in err
    for word in words:
        assert word in err


def test_the_default_constellations_agree_and_are_printed() -> None:
    """The locator and the availability report count the same satellites by default."""
    from locator.demostep import DEMO_CONSTELLATION
    from predisat.cli.args import constellation_label

    run = locator_cli.build_parser().parse_args(["run", "--sim", ".", "--no-masks", "--out", "o"])
    avail = predisat_cli.build_parser().parse_args(["availability", "--masks", ".", "--out", "o"])
    assert run.constellation == avail.constellation == DEMO_CONSTELLATION == "gps"
    assert constellation_label(run.constellation) == "GPS"
    assert constellation_label("GE") == "GPS, Galileo"


# --- the user's other cases -----------------------------------------------------------------


def test_export_chainage_in_km_gets_the_metres_meant(tmp_path: Path, capsys) -> None:
    from predisat.masks import fileformat as maskio
    from tests.predisat.masks.test_fileformat import make_set

    masks = make_set()  # positions at 250-360 m of chainage
    src = maskio.write_masks(masks, tmp_path / "masks.parquet")
    out = tmp_path / "r.txt"
    assert predisat_cli.main(["export", str(src), "--format", "rtklib", "--chainage", "0.3",
                              "--out", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "did you give kilometres? (--chainage 300)" in err and not out.exists()
    # far from every position (not km either): refused, no nearest-position mask written
    assert predisat_cli.main(["export", str(src), "--format", "rtklib", "--chainage", "2000",
                              "--out", str(out)]) == 2  # fmt: skip
    assert "outside the masks" in capsys.readouterr().err and not out.exists()
    assert predisat_cli.main(["export", str(src), "--format", "rtklib", "--chainage", "300",
                              "--out", str(out)]) == 0  # fmt: skip


def test_simulate_builds_a_short_world(tmp_path: Path, capsys) -> None:
    """`locator simulate --from-km 4 --to-km 4.2` was refused (the mixed recipe needs 0.8 km)."""
    from locator.sim.simfile import SimRun

    out = tmp_path / "sim"
    assert locator_cli.main(["simulate", "--from-km", "4", "--to-km", "4.2", "--out",
                             str(out)]) == 0  # fmt: skip
    sim = SimRun.read(out)
    assert sim.n_epoch > 5
    assert 4000.0 < sim.chainage_m.min() and sim.chainage_m.max() < 4200.0
    capsys.readouterr()
    # below the minimum: refused with the minimum named
    assert locator_cli.main(["simulate", "--from-km", "4", "--to-km", "4.05", "--out",
                             str(tmp_path / "tiny")]) == 2  # fmt: skip
    assert "at least 0.1 km" in capsys.readouterr().err


def test_process_refuses_another_surveys_folder_unless_replace(tmp_path: Path, capsys) -> None:
    """`process` into another survey's --out recomputed silently and left stale chunks."""
    import json

    from predisat.camera.models import CameraModel
    from predisat.masks.fileformat import read_masks
    from predisat.synth.generate import generate_survey
    from predisat.track.map import demo_track

    cam = CameraModel.pinhole_from_fov(160, 120, 74.0)
    for name, lo_m in (("a", 4000.0), ("b", 5000.0)):
        generate_survey(demo_track(), lo_m, lo_m + 20.0, sky="clear", seed=5,
                        out_dir=tmp_path / name, camera=cam, progress=False)  # fmt: skip
    out = tmp_path / "m"

    def process(name: str, *extra: str) -> int:
        return predisat_cli.main(["process", str(tmp_path / name / "survey"), "--quiet",
                                  "--out", str(out), *extra])  # fmt: skip

    def chunks() -> set[str]:
        return {p.name for p in (out / "chunks").iterdir()}

    assert process("a") == 0
    first, masks_a = chunks(), (out / "masks.parquet").read_bytes()
    assert first == {"4000_5000.json", "4000_5000.parquet"}
    capsys.readouterr()
    assert process("b") == 2
    err = capsys.readouterr().err
    assert str(out) in err and "another survey" in err and "--replace" in err
    assert chunks() == first and (out / "masks.parquet").read_bytes() == masks_a  # untouched
    assert process("b", "--replace") == 0
    assert chunks() == {"5000_6000.json", "5000_6000.parquet"}  # survey a's chunk removed
    ch = read_masks(out / "masks.parquet").chainage_m
    assert ch.min() >= 5000.0 and ch.max() <= 5020.0 + 1e-6
    # the same survey in other chunks: the old chunks do not stay beside the new ones
    assert process("b", "--chunk-m", "10") == 0
    names = set(json.loads((out / "provenance.json").read_text())["chunks"])
    assert chunks() == {f"{n}{s}" for n in names for s in (".json", ".parquet")}
    assert "5000_6000.json" not in chunks()


def test_chainage_hint_names_the_metres_meant_only_when_they_fit() -> None:
    from predisat.cli.args import chainage_hint

    assert chainage_hint(5.2, 4000.0, 6000.0, "--chainage").endswith("(--chainage 5200)")
    assert chainage_hint(5200.0, 4000.0, 6000.0, "--chainage") == ""  # inside: no hint
    assert chainage_hint(9.0, 4000.0, 6000.0, "--chainage") == ""  # 9 km is not inside either


def test_quiet_is_accepted_before_and_after_the_locator_subcommand() -> None:
    parser = locator_cli.build_parser()
    run = ["run", "--sim", ".", "--no-masks", "--out", "o"]
    assert parser.parse_args(run).quiet is False
    assert parser.parse_args(["-q", *run]).quiet is True
    assert parser.parse_args([*run, "--quiet"]).quiet is True


def test_synth_sky_choices_are_the_renderers() -> None:
    from predisat.synth.generate import SKY_CHOICES

    assert set(predisat_cli.SKY_CHOICES) == set(SKY_CHOICES)


def test_one_integrity_risk_setting_for_every_command() -> None:
    from predisat.cli.args import integrity_budget
    from predisat.cli.demo import DemoContext
    from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH

    demo = predisat_cli.build_parser().parse_args(["demo", "--integrity-risk", "1e-8"])
    assert demo.integrity_risk == 1e-8
    assert predisat_cli.build_parser().parse_args(["demo"]).integrity_risk == 1e-12
    assert DemoContext.__dataclass_fields__["integrity"].default_factory().risk_per_epoch == (
        DEFAULT_RISK_PER_EPOCH
    )
    assert integrity_budget(argparse.Namespace(k_sigma=None, integrity_risk=None)) is not None
    assert integrity_budget(argparse.Namespace(k_sigma=2.0, integrity_risk=None)) is None
    # a k whose pairs risk more than the largest risk --integrity-risk takes is refused
    # (a user trial's --k-sigma 0.5: "safety claim 96.7 %" at 0.62 per pair)
    from predisat.cli.args import k_sigma_value

    assert k_sigma_value("2") == 2.0 and k_sigma_value("1.65") == 1.65
    for bad in ("0.5", "1.6", "0", "-2"):
        with pytest.raises(argparse.ArgumentTypeError, match=r"at least 1\.645"):
            k_sigma_value(bad)


def test_synth_rig_choices_are_the_presets() -> None:
    from predisat.camera.rigs import DEFAULT_RIG, RIG_NAMES

    assert predisat_cli.RIG_CHOICES == RIG_NAMES
    assert DEFAULT_RIG == "side-fisheye"


@pytest.mark.parametrize(("name", "parser"), COMMANDS, ids=[n for n, _ in COMMANDS])
def test_quiet_is_also_dash_q_after_the_subcommand(name: str, parser) -> None:
    """A user typed `predisat process ... -q` (as `locator run ... -q`) and was refused."""
    opts = parser._option_string_actions
    if "--quiet" in opts:
        assert opts.get("-q") is opts["--quiet"], name


def test_a_mistyped_scheduler_is_refused_before_any_work(tmp_path, capsys) -> None:
    """``--scheduler lcoal`` was taken for a host: the inputs were read and the output folder
    made before 'missing port number' (a user trial)."""
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        predisat_cli.main(["process", str(tmp_path), "--out", str(out), "--scheduler", "lcoal"])
    assert exc.value.code == 2
    assert "'lcoal' is not an address" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize(
    ("cli", "module", "func", "argv", "kept"),
    [
        (predisat_cli, "predisat.cli.app", "cmd_availability",
         ["availability", "--masks", "m.parquet", "--out", "o"], "finished blocks are kept"),
        (locator_cli, "locator.campaign_command", "cmd_campaign",
         ["campaign", "--out", "o"], "finished jobs are kept"),
    ],
)  # fmt: skip
def test_ctrl_c_on_a_resumable_command_says_its_work_is_kept(
    monkeypatch, capsys, tmp_path, cli, module, func, argv, kept
) -> None:
    """A user trial's Ctrl-C on availability and campaign printed only 'interrupted', though
    both resume their finished blocks and jobs."""
    import importlib

    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.parquet").write_bytes(b"")  # the options are checked: a file is there

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib.import_module(module), func, interrupted)
    assert cli.main(argv) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and kept in err and "rerun the same command" in err


def _help_lines(parser: argparse.ArgumentParser) -> dict[str, str | None]:
    """Each subcommand's line in the command list."""
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {a.dest: a.help for a in action._choices_actions}


def _options(parser: argparse.ArgumentParser) -> list[tuple[tuple[str, ...], str, object]]:
    return [(tuple(a.option_strings), a.dest, a.default) for a in parser._actions]


@pytest.mark.parametrize("module", [predisat_cli, locator_cli], ids=["predisat", "locator"])
def test_a_command_built_alone_is_the_command_built_with_all(module: object) -> None:
    """Only the chosen subcommand's arguments are built (they import its library: seconds); it
    must parse as in the whole parser, and the list of commands must read the same."""
    build = module.build_parser  # type: ignore[attr-defined]
    whole = build()
    alone_all = _subparsers(whole)
    assert set(module.COMMAND_HELP) == set(alone_all)  # type: ignore[attr-defined]
    assert _help_lines(build([])) == _help_lines(whole)
    for name in module.COMMAND_HELP:  # type: ignore[attr-defined]
        parser = build([name])
        assert _help_lines(parser) == _help_lines(whole)
        assert _options(_subparsers(parser)[name]) == _options(alone_all[name]), name
        for other, stub in _subparsers(parser).items():  # listed, not built
            if other != name:
                assert {a.dest for a in stub._actions} <= {"help", "quiet"}, other


@pytest.mark.parametrize(
    ("module", "argv", "heavy"),
    [
        ("predisat.cli.app", ["export", "--help"], ["predisat.availability.run",
                                                    "predisat.reconstruct.batch"]),
        ("predisat.cli.app", [], ["predisat.availability.run", "predisat.reconstruct.batch"]),
        ("locator.cli", ["evaluate", "-h"], ["locator.workflow", "locator.balises"]),
    ],
)  # fmt: skip
def test_the_command_line_imports_only_the_chosen_command(
    module: str, argv: list[str], heavy: list[str]
) -> None:
    import subprocess
    import sys

    code = (
        f"import sys\nfrom {module} import COMMAND_HELP, build_parser\n"
        "from predisat.cli.common import command_parser\n"
        f"assert command_parser(build_parser, COMMAND_HELP, {argv!r}, 'x') is not None\n"
        f"print([m for m in {heavy!r} if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).parents[3])  # fmt: skip
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
