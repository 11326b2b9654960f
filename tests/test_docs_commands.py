"""Every command line the documentation shows still parses: its subcommand exists and each of
its ``--options`` is one the command (or the script) takes.

The docs show about 350 ``predisat`` / ``locator`` command lines and 200 ``scripts/*.py`` ones
(README.md and docs/*.md, in code blocks and inline code). An option renamed or dropped leaves
them wrong without a word; a user copying one gets "unrecognized arguments". Option names are
checked against the real parsers (``build_parser``); a script's options against the option
strings in its source, and where one is not found there, against its ``--help`` (options made
in a loop, subcommands, scripts that hand over to a command).
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from locator.cli import build_parser as locator_parser
from predisat.cli.app import build_parser as predisat_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
# the command's own flags may stand before the subcommand (`locator -q balises ...`): that line
# is checked too (it was not matched at all, m8)
_CMD = re.compile(
    r"(?:^|(?<=[\s(`$]))(?:[\w./-]*/)?(predisat|locator)(?:\s+-[\w-]+)*\s+([a-z][a-z-]*)\b"
    r"([^`\n]*)"
)
_SCRIPT = re.compile(r"scripts/(\w+\.py)((?:[ \t]+[^\s`|;&>]+)*)")
_OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
_BLOCK = re.compile(r"```[a-z]*\n(.*?)```", re.S)


def _pieces(text: str) -> list[str]:
    """Lines of the code blocks (continuations joined) and inline code spans of prose."""
    lines = [ln for b in _BLOCK.findall(text) for ln in b.replace("\\\n", " ").splitlines()]
    prose = _BLOCK.sub("", text)
    return lines + re.findall(r"`([^`\n]+)`", prose)


def _command_part(rest: str) -> str:
    """The arguments of one command: up to a shell operator or a comment."""
    return re.split(r"\s(?:&&|\|\||;|\||>|2>|#)\s?", rest)[0]


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    raise AssertionError(f"{parser.prog} has no subcommands")


@functools.cache
def _cli_options() -> dict[str, dict[str, set[str]]]:
    out: dict[str, dict[str, set[str]]] = {}
    for prog, build in (("predisat", predisat_parser), ("locator", locator_parser)):
        out[prog] = {
            name: {s for a in sub._actions for s in a.option_strings}
            for name, sub in _subcommands(build()).items()
        }
    return out


@functools.cache
def _script_help(name: str, sub: str | None) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    argv = [sys.executable, str(ROOT / "scripts" / name), *([sub] if sub else []), "--help"]
    done = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    return done.stdout


def _documented() -> list[tuple[str, str]]:
    """(doc file name, piece of code) for every piece that names a command or a script."""
    return [(doc.name, piece) for doc in DOCS for piece in _pieces(doc.read_text())
            if _CMD.search(piece) or _SCRIPT.search(piece)]  # fmt: skip


def test_the_docs_show_commands_to_check() -> None:
    # the scanner finds what it is meant to (a change of the docs' layout must not make the
    # checks below vacuous)
    pieces = _documented()
    n_cli = sum(1 for _, p in pieces for _ in _CMD.finditer(p.strip()))
    n_scripts = sum(1 for _, p in pieces for _ in _SCRIPT.finditer(p))
    assert n_cli > 200 and n_scripts > 100, (n_cli, n_scripts)


def test_every_documented_command_line_uses_options_the_command_takes() -> None:
    known = _cli_options()
    wrong = []
    for doc, piece in _documented():
        text = piece.strip()
        if text.startswith(("from ", "import ")):
            continue  # Python: `from locator import ...`
        for prog, sub, rest in (m.groups() for m in _CMD.finditer(text)):
            if sub not in known[prog]:
                if "scripts/" not in text:  # `scripts/bench_locator.py ... # locator beside`
                    wrong.append(f"{doc}: `{text[:90]}`: `{prog}` has no command `{sub}`")
                continue
            for option in _OPTION.findall(_command_part(rest)):
                if option not in known[prog][sub]:
                    wrong.append(f"{doc}: `{text[:90]}`: `{prog} {sub}` takes no {option}")
    assert not wrong, "\n".join(wrong)


def test_every_documented_script_line_uses_options_the_script_takes() -> None:
    wrong = []
    for doc, piece in _documented():
        for name, rest in (m.groups() for m in _SCRIPT.finditer(piece)):
            path = ROOT / "scripts" / name
            if not path.is_file():
                wrong.append(f"{doc}: `{piece.strip()[:90]}`: no script scripts/{name}")
                continue
            args = _command_part(rest).split()
            source = path.read_text()
            for option in _OPTION.findall(" ".join(args)):
                if re.search(rf"[\"']{re.escape(option)}[\"']", source):
                    continue
                sub = args[0] if args and not args[0].startswith("-") else None
                if f"  {option}" in _script_help(name, sub):
                    continue
                wrong.append(f"{doc}: `{piece.strip()[:90]}`: scripts/{name} takes no {option}")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("bad", ["--no-such-option", "--chainage-km"])
def test_the_check_sees_an_option_a_command_does_not_take(bad: str) -> None:
    # the rule above on a made-up line: it must not pass everything
    known = _cli_options()
    m = _CMD.search(f".venv/bin/predisat export MASKS --format rtklib {bad} 4")
    assert m is not None
    prog, sub, rest = m.groups()
    assert sub in known[prog] and bad in _OPTION.findall(_command_part(rest))
    assert bad not in known[prog][sub]


def test_a_line_with_the_command_s_own_flag_before_the_subcommand_is_checked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``locator -q balises --no-such-option``: the global flag before the subcommand kept the
    line from being matched, so none of its options was checked (m8)."""
    import tests.test_docs_commands as mod

    doc = tmp_path / "x.md"
    doc.write_text("```bash\nlocator -q balises --sim SIM --no-such-option 3\n```\n"
                   "and `predisat --version` alone\n")
    monkeypatch.setattr(mod, "DOCS", [doc])
    with pytest.raises(AssertionError, match="takes no --no-such-option"):
        test_every_documented_command_line_uses_options_the_command_takes()
