"""What the ``predisat`` and ``locator`` command lines share: the error wrapper of ``main``,
the track options and the kilometre range.

``locator`` uses this public module; neither command line imports the other.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import warnings
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from predisat.atomic import access_error_text, storage_error_text
from predisat.cli.args import caused_by_interrupt, run_checks

if TYPE_CHECKING:
    from predisat.track import TrackMap

__all__ = [
    "SYNTH_MODULES",
    "CliError",
    "add_masks_same_track",
    "add_track_selection",
    "command_parser",
    "km_range",
    "parse_where",
    "run_main",
    "stretch_text",
    "track_option",
]

SYNTH_MODULES = frozenset({"trimesh", "open3d", "embreex"})
"""The packages of the ``[synth]`` extra (the synthetic world and its renderer)."""


class CliError(Exception):
    """A user-facing error: printed without a traceback."""


def command_parser(
    build: Callable[[Collection[str] | None], argparse.ArgumentParser],
    commands: Collection[str],
    argv: Sequence[str] | None,
    label: str,
) -> argparse.ArgumentParser | None:
    """The parser ``build`` makes with the arguments of the one subcommand ``argv`` names.

    A subcommand's arguments import its library (seconds), so only the chosen one is built; the
    command line's own options take no value, so the subcommand is ``argv``'s first word that
    is not an option (none: the command list alone). None after a Ctrl-C during those imports,
    with a line saying nothing was written.
    """
    words = sys.argv[1:] if argv is None else argv
    first = next((word for word in words if not word.startswith("-")), None)
    try:
        return build([first] if first is not None and first in commands else [])
    except (KeyboardInterrupt, ImportError, RuntimeError) as exc:
        # Ctrl-C in a C extension's import comes as an ImportError caused by it, and in a
        # dataclass's class body as a RuntimeError from __set_name__ (a test's random Ctrl-C)
        if not caused_by_interrupt(exc):
            raise
        print(f"\n{label}: interrupted before the command started; nothing was written: rerun "
              "the same command", file=sys.stderr)  # fmt: skip
        return None


def run_main(
    parser: argparse.ArgumentParser,
    argv: Sequence[str] | None,
    label: str,
    *,
    interrupted_note: dict[str, str] | None = None,
) -> int:
    """Parse ``argv`` and run the chosen subcommand's ``func``, as a command line should.

    Options that exclude or need each other are refused at parse time
    (:func:`predisat.cli.args.run_checks`: usage and message, exit 2). Errors written for a
    person (:class:`CliError`, ``ValueError``, ``OSError``, ``KeyError``) are printed on one
    line as ``<label>: error: ...`` (exit 2), Ctrl-C as ``interrupted`` (exit 130, with
    ``interrupted_note[command]`` when given); ``label`` may hold ``{command}``, the
    subcommand's name. Warnings the library gives are printed on one line each as
    ``<label>: warning: ...``.
    """
    try:
        args = parser.parse_args(argv)
    except OSError as exc:  # a path option the system cannot look up (a name over 255 bytes)
        where = f"{exc.filename}: " if exc.filename else ""
        parser.error(f"{where}{exc.strerror or exc}; give a shorter or valid path")
    run_checks(args)  # options that exclude or need each other: refused before any work
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0
    name = label.format(command=getattr(args, "command", ""))
    note = (interrupted_note or {}).get(getattr(args, "command", ""), "")
    seen: list[int] = []

    def on_sigint(signum: int, frame: object) -> None:
        seen.append(signum)
        raise KeyboardInterrupt

    # a KeyboardInterrupt raised inside a ctypes callback (numba loading its cache through
    # llvmlite) is printed and swallowed there, and the run went on to exit 0: the handler
    # remembers the Ctrl-C so that the command still ends as interrupted
    previous = None
    with contextlib.suppress(ValueError):  # not the main thread: the default handling stays
        previous = signal.signal(signal.SIGINT, on_sigint)
    # ... and ctypes reports the swallowed interrupt as an unraisable exception with a
    # traceback (llvmlite's cache callbacks): the command's own "interrupted" line says it
    previous_hook = sys.unraisablehook

    def on_unraisable(report: Any) -> None:
        if seen and isinstance(report.exc_value, KeyboardInterrupt):
            return
        previous_hook(report)

    sys.unraisablehook = on_unraisable

    def one_line(message: Warning | str, category: type[Warning], *_: Any, **__: Any) -> None:
        # a library's warning is for the user of the command: one line under its name, as its
        # errors are, not Python's file:line and source echo
        print(f"{name}: warning: {message}", file=sys.stderr)

    try:
        with warnings.catch_warnings():
            warnings.showwarning = one_line
            return _run_func(args, name, note, seen)
    finally:
        sys.unraisablehook = previous_hook
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


def _run_func(args: argparse.Namespace, name: str, note: str, seen: list[int]) -> int:
    """``args.func(args)`` with the exits of :func:`run_main`."""
    try:
        code = int(args.func(args))
        if seen:
            print(f"\n{name}: interrupted{note}", file=sys.stderr)
            return 130
        return code
    except ModuleNotFoundError as exc:
        if exc.name not in SYNTH_MODULES:
            raise
        print(f"{name}: error: this command needs the synthetic world's ray casting ({exc.name} "
              "is not installed): pip install 'predisat[synth]' (or bash scripts/setup.sh)",
              file=sys.stderr)  # fmt: skip
        return 2
    except (CliError, ValueError, OSError, KeyError) as exc:
        # library errors are written to be read by a person: no traceback; a full disk or a
        # file-size limit named with the file meant (not its temporary name) and the fix
        text = storage_error_text(exc) or access_error_text(exc) or exc
        print(f"{name}: error: {text}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError, ImportError) as exc:
        # Ctrl-C inside a numba-compiled function surfaces as a SystemError caused by it, and
        # inside a C extension's import (matplotlib's ft2font) as an ImportError caused by it
        if not caused_by_interrupt(exc):  # a genuine SystemError or ImportError
            raise
        print(f"\n{name}: interrupted{note}", file=sys.stderr)
        return 130


def parse_where(items: Sequence[str] | None) -> dict[str, str | None] | None:
    """``KEY=VALUE`` property filters; ``KEY=`` selects features without that property."""
    if not items:
        return None
    where: dict[str, str | None] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise CliError(f"--where {item}: expected KEY=VALUE (or KEY= for 'property absent')")
        where[key] = value or None
    return where


def track_option(
    path: str | None,
    name: str | None = None,
    chain: Literal["all", "longest"] = "all",
    where: Sequence[str] | None = None,
    *,
    tolerance_m: float | None = None,
    option: str = "--track",
) -> TrackMap:
    """``--track`` (with ``--track-name``, ``--chain``, ``--where``): the demo line when
    absent, else :func:`predisat.track.load_track` (GeoJSON or CSV by content); errors start
    with ``option`` (``"FILE"`` for a positional argument)."""
    # lazy, as every library import of the command line: `--help` answers without pyproj
    from predisat.track import TrackMapError, demo_track, load_track
    from predisat.track.readers import sniff_format

    if path is None:
        return demo_track()
    selection = [o for o, given in (("--track-name", name is not None), ("--where", bool(where)),
                                    ("--chain longest", chain != "all")) if given]  # fmt: skip
    if selection and Path(path).is_file() and sniff_format(Path(path)) != "geojson":
        # a CSV holds one line: a selection that cannot apply must not pass unnoticed
        raise CliError(f"{option} {path}: a CSV track map holds one line, with nothing to "
                       f"select: drop {', '.join(selection)} (they pick one line of a GeoJSON "
                       "file)")  # fmt: skip
    try:
        return load_track(path, name, chain=chain, where=parse_where(where),
                          tolerance_m=tolerance_m)  # fmt: skip
    except TrackMapError as exc:
        raise CliError(f"{option} {exc}") from None


def add_masks_same_track(p: argparse.ArgumentParser) -> None:
    """``--masks-same-track``: masks beside the map as another track's are taken (said)."""
    from predisat.masks.registration import OTHER_TRACK_OFFSET_M

    p.add_argument("--masks-same-track", action="store_true",
                   help="the track map is of the physical track the masks were surveyed on "
                   "(another survey or simplification of its axis): masks lying more than "
                   f"{OTHER_TRACK_OFFSET_M:g} m beside it are registered on it instead of "
                   "refused as another track's (default: refused)")  # fmt: skip


def add_track_selection(p: argparse.ArgumentParser) -> None:
    """Which line of a GeoJSON holding several (Infrabel files, OpenStreetMap extracts)."""
    p.add_argument("--track-name", metavar="NAME",
                   help="which track when the file holds several (default: the only one)")
    p.add_argument(
        "--chain",
        choices=["all", "longest"],
        default="all",
        help="chain every selected way (all) or the longest connected chain of a network",
    )
    p.add_argument(
        "--where",
        nargs="+",
        metavar="KEY=VALUE",
        help="GeoJSON property filters, e.g. usage=main service= (KEY=: property absent; "
        "default: no filter)",
    )


_END_SLACK_KM = 5e-4  # half a metre past a track's end reads as its end


def km_range(
    track: TrackMap, from_km: float | None, to_km: float | None
) -> tuple[float, float]:
    """``--from-km/--to-km`` as metres of chainage, refused with the fix when not a stretch."""
    top_km = track.length_m / 1000.0
    lo_km = 0.0 if from_km is None else float(from_km)
    hi_km = top_km if to_km is None else float(to_km)
    if top_km < hi_km <= top_km + _END_SLACK_KM:
        hi_km = top_km  # a track's length is a float sum (3999.99999 m for 4 km): its end
    if not lo_km < hi_km:
        reason = "the start must be below the end (chainage grows along the track)"
    elif not (0.0 <= lo_km and hi_km <= top_km):
        reason = f"not inside the track ({track.name}: 0-{top_km:.3f} km of chainage)"
    else:
        return lo_km * 1000.0, hi_km * 1000.0
    hint = ""
    if lo_km < hi_km and hi_km > 10.0 * top_km and hi_km / 1000.0 <= top_km:
        hint = (
            f"; the values are kilometres, did you give metres? "
            f"(--from-km {lo_km / 1000:g} --to-km {hi_km / 1000:g})"
        )
    raise CliError(f"--from-km {lo_km:g} --to-km {hi_km:g}: {reason}{hint}")


def stretch_text(track: TrackMap, lo_m: float, hi_m: float) -> str:
    """``chainage 1.000-3.000 km``, with the line's kilometres when the map's posts give them:
    ``--from-km`` / ``--to-km`` are chainage, which the line's own kilometres are not (on line
    144 chainage 1 km is km 1.036)."""
    text = f"chainage {lo_m / 1000:.3f}-{hi_m / 1000:.3f} km"
    km = track.kilometre_at([lo_m, hi_m])
    if np.all(np.isfinite(km)) and float(np.max(np.abs(km - [lo_m, hi_m]))) >= 1.0:
        text += f" (line km {km[0] / 1000:.3f}-{km[1] / 1000:.3f} by its kilometre posts)"
    return text
