"""Argument types and checks shared by the ``predisat`` and ``locator`` command lines.

One vocabulary for both: every option's value is checked before any work starts, under the
option's name and with the fix, and the values a person is likely to give in the wrong unit
(an angle in radians, a chainage in kilometres, a speed in km/h, a share in percent) are
refused with the value they probably meant.

* Types (``type=`` of ``add_argument``): :func:`output_dir`, :func:`output_file`,
  :func:`existing_file`, :func:`existing_path`, :func:`existing_dir` (a missing input names
  what it should contain), :func:`finite_float`, :func:`positive_int`, :func:`positive_float`,
  :func:`non_negative_float`, :func:`cutoff_deg`, :func:`pitch_deg`, :func:`speed_mps`,
  :func:`rate_hz`, :func:`antenna_height_m`, :func:`fraction`, :func:`constellation`,
  :func:`integrity_risk`.
* The pair-interval width: :func:`integrity_options` (``--integrity-risk`` or ``--k-sigma``)
  and :func:`integrity_budget` (the budget they give, None for a fixed ``k``).
* Parsers: :class:`Parser` (a missing input is one line, without the usage),
  :class:`HelpFormatter` (argparse's own defaults in the help),
  :func:`add_command` (a described subcommand), :func:`add_checks` and :func:`run_checks`
  (options that exclude or need each other, refused at parse time), :func:`chainage_hint`.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from predisat.availability.interval import MapDoubt
from predisat.gnss.integrity import DEFAULT_RISK_PER_EPOCH, IntegrityBudget
from predisat.storage import Location, is_remote, location

__all__ = [
    "MAX_TRAIN_SPEED_MPS",
    "TIME_HELP",
    "HelpFormatter",
    "Parser",
    "add_checks",
    "add_command",
    "add_map_doubt",
    "antenna_height_m",
    "caused_by_interrupt",
    "chainage_hint",
    "constellation",
    "constellation_label",
    "constellation_letters",
    "cutoff_deg",
    "existing_dir",
    "existing_file",
    "existing_path",
    "finite_float",
    "fraction",
    "given",
    "integrity_budget",
    "integrity_options",
    "integrity_risk",
    "map_doubt_arg",
    "needs",
    "non_negative_float",
    "output_dir",
    "output_file",
    "pitch_deg",
    "positive_float",
    "positive_int",
    "rate_hz",
    "requires",
    "run_checks",
    "scheduler_options",
    "scheduler_text",
    "speed_mps",
    "storage_options",
    "url_or",
]

MAX_TRAIN_SPEED_MPS = 100.0
"""360 km/h: above every commercial service (350 km/h); a faster value is a unit mistake."""

_MAX_RATE_HZ = 100.0  # GNSS receivers log at 1-20 Hz, the fastest at 100 Hz
_MAX_ANTENNA_HEIGHT_M = 10.0  # a train's roof antenna is 4-5 m above the rail

TIME_HELP = "GPS time 2020-06-25T06:00, UTC 2020-06-25T06:00Z, or GPS seconds"
"""The forms of a time option (``--start``), as :func:`predisat.availability.run.parse_time`
reads them."""

Check = Callable[[argparse.Namespace], str | None]
"""A check of parsed options: the error message, or None when they are consistent."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's ``(default: ...)`` after every option's help, except where it says nothing:
    flags, required options, positionals and ``None`` defaults (whose help says what happens
    when the option is absent)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if (
            "%(default)" in text
            or action.default is None
            or action.default is argparse.SUPPRESS
            or action.required
            or not action.option_strings
            or action.nargs == 0  # flags: store_true, store_const, help, version
        ):
            return text
        return f"{text} (default: %(default)s)"


#: What the input types (:func:`existing_file`, :func:`existing_dir`, :func:`existing_path`)
#: say of a path that is not there; :class:`Parser` prints such an error on one line.
_MISSING = ("no such file", "no such folder", "no such file or folder")


class Parser(argparse.ArgumentParser):
    """argparse's parser, except that a missing input file or folder is reported on one line
    (``prog: error: argument --dem: x.hgt: no such file; give ...``, exit 2), as the inputs
    found missing while running: the usage text would hide the message and says nothing of
    the fix. Other parse errors keep the usage. Subcommands inherit the class."""

    def error(self, message: str) -> NoReturn:
        """Print ``message`` (with the usage unless an input is missing) and exit 2."""
        if any(f": {m}; give " in message for m in _MISSING):
            self.exit(2, f"{self.prog}: error: {message}\n")
        super().error(message)


def add_command(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    name: str,
    help: str,
    description: str,
) -> argparse.ArgumentParser:
    """A subcommand with its one-line ``help`` (the command list), its ``description`` (its own
    ``--help``) and :class:`HelpFormatter`."""
    if not description.strip():
        raise ValueError(f"subcommand {name}: give a description (what it does, what it writes)")
    return sub.add_parser(name, help=help, description=description, formatter_class=HelpFormatter)


def given(args: argparse.Namespace, dest: str) -> bool:
    """Whether the option stored in ``dest`` was given (its default is None or False)."""
    value = getattr(args, dest, None)
    return value is not None and value is not False


def needs(
    option: str, dest: str, condition: Callable[[argparse.Namespace], bool], what: str
) -> Check:
    """``option`` (stored in ``dest``) is refused unless ``condition`` holds: "``option`` is for
    ``what``; drop it"."""

    def check(args: argparse.Namespace) -> str | None:
        if given(args, dest) and not condition(args):
            return f"{option} is for {what}; drop it"
        return None

    return check


def requires(option: str, dest: str, other: str, other_dest: str, why: str = "") -> Check:
    """``option`` (stored in ``dest``) is refused without ``other`` (stored in ``other_dest``)."""

    def check(args: argparse.Namespace) -> str | None:
        if given(args, dest) and not given(args, other_dest):
            return f"{option} needs {other}" + (f" ({why})" if why else "")
        return None

    return check


def add_checks(parser: argparse.ArgumentParser, *checks: Check) -> None:
    """Checks of the parsed options of ``parser`` (a subcommand), run by :func:`run_checks`."""
    parser.set_defaults(_checks=tuple(checks), _parser=parser)


def run_checks(args: argparse.Namespace) -> None:
    """Run the chosen subcommand's checks: the first failing one exits through argparse's
    ``error`` (usage, message, exit code 2), before any work."""
    parser: argparse.ArgumentParser | None = getattr(args, "_parser", None)
    for check in getattr(args, "_checks", ()):
        message = check(args)
        if message and parser is not None:
            parser.error(message)


def output_dir(value: str) -> Path:
    """An output folder: absent (it is created) or an existing folder, never a file."""
    p = Path(value)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value} is an existing file, not a folder; give a folder path (it is created "
            "if absent)"
        )
    return p


def output_file(value: str) -> Path:
    """An output file: not a folder, and not under a file (missing folders are created)."""
    p = Path(value)
    if p.is_dir():
        raise argparse.ArgumentTypeError(
            f"{value} is a folder; give a file path (inside it, if that is where it belongs)"
        )
    blocking = next((a for a in p.parents if a.exists() and not a.is_dir()), None)
    if blocking is not None:
        raise argparse.ArgumentTypeError(
            f"{value}: {blocking} is a file, so no folder can be made there; choose another path"
        )
    return p


def existing_file(content: str) -> Callable[[str], Path]:
    """An input file, which must exist and not be a folder; ``content`` says what it holds
    (``"a CSV with columns gps_s, chainage_m"``) for the message when it does not."""

    def parse(value: str) -> Path:
        p = Path(value)
        if p.is_dir():
            raise argparse.ArgumentTypeError(f"{value} is a folder; give {content}")
        if not p.is_file():
            raise argparse.ArgumentTypeError(f"{value}: no such file; give {content}")
        return p

    parse.__name__ = "file"  # argparse names the type in its messages
    return parse


def existing_dir(content: str) -> Callable[[str], Path]:
    """An input folder, which must exist; ``content`` says what it holds."""

    def parse(value: str) -> Path:
        p = Path(value)
        if not p.is_dir():
            kind = "a file, not a folder" if p.exists() else "no such folder"
            raise argparse.ArgumentTypeError(f"{value}: {kind}; give {content}")
        return p

    parse.__name__ = "folder"
    return parse


def existing_path(content: str) -> Callable[[str], Path]:
    """An input file or folder, which must exist; ``content`` says what it holds."""

    def parse(value: str) -> Path:
        p = Path(value)
        if not p.exists():
            raise argparse.ArgumentTypeError(f"{value}: no such file or folder; give {content}")
        return p

    parse.__name__ = "path"
    return parse


def url_or(parse: Callable[[str], Path]) -> Callable[[str], Location]:
    """``parse`` for a local path (``file://`` URLs included); an fsspec URL of another file
    system (``s3://``, ``http(s)://``...) is taken as it is: it is checked when it is opened,
    with the storage options (:mod:`predisat.storage`)."""

    def parse_url(value: str) -> Location:
        loc = location(value)
        return loc if is_remote(loc) else parse(str(loc))

    parse_url.__name__ = getattr(parse, "__name__", "path")
    return parse_url


def storage_options(value: str) -> dict[str, Any]:
    """``--storage-options``: a JSON object of fsspec file system options."""
    try:
        doc = json.loads(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"{value!r} is not JSON ({exc}); give an object such as "
            '\'{"anon": true}\' or \'{"key": "...", "secret": "..."}\''
        ) from None
    if not isinstance(doc, dict):
        raise argparse.ArgumentTypeError(
            f"{value!r} is not a JSON object; give an object such as "
            '\'{"anon": true}\''
        )
    return doc


def _number(value: str) -> float:
    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a number") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"{value} is not a finite number")
    return x


def finite_float(value: str) -> float:
    """Any finite number (a chainage, a kilometre)."""
    return _number(value)


def positive_int(value: str) -> int:
    """A count of at least 1 (workers, epochs)."""
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a whole number") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"{value} must be 1 or more")
    return n


def seed_value(value: str) -> int:
    """A random seed: a whole number in [0, 2**32) (numpy's generators take no negative
    one, and said so in their own words)."""
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a whole number") from None
    if not 0 <= n < 2**32:
        raise argparse.ArgumentTypeError(f"{value} must be a whole number from 0 to 2**32 - 1")
    return n


def positive_float(value: str) -> float:
    """A finite number above 0 (a spacing, a step, a duration)."""
    x = _number(value)
    if x <= 0.0:
        raise argparse.ArgumentTypeError(f"{value} must be above 0")
    return x


def non_negative_float(value: str) -> float:
    """A finite number of 0 or more (a margin, an uncertainty)."""
    x = _number(value)
    if x < 0.0:
        raise argparse.ArgumentTypeError(f"{value} must be 0 or more")
    return x


def _degrees(value: str) -> float:
    """An angle in degrees; a value that reads as radians (a fraction up to pi/2) is refused
    with its degrees, unless written with the unit (``0.5deg``)."""
    text = value.strip()
    explicit = text.lower().endswith("deg")
    x = _number(text[:-3] if explicit else text)
    if not explicit and x != round(x) and abs(x) <= 0.5 * math.pi + 1e-9:
        raise argparse.ArgumentTypeError(
            f"{value} looks like radians ({value} rad = {math.degrees(x):.1f} deg); give "
            f"degrees ({round(math.degrees(x)):g}), or write {value}deg if you mean "
            f"{value} degrees"
        )
    return x


def cutoff_deg(value: str) -> float:
    """An elevation cut-off in degrees, in [0, 90); a fraction up to pi/2 reads as radians
    and is refused unless written ``0.5deg``."""
    x = _degrees(value)
    if not 0.0 <= x < 90.0:
        raise argparse.ArgumentTypeError(
            f"{value} is not an elevation cut-off; give degrees in [0, 90)"
        )
    return x


def pitch_deg(value: str) -> float:
    """A camera pitch above the horizontal in degrees, in [-90, 90] (radians refused)."""
    x = _degrees(value)
    if not -90.0 <= x <= 90.0:
        raise argparse.ArgumentTypeError(f"{value} is not a pitch; give degrees in [-90, 90]")
    return x


def speed_mps(value: str) -> float:
    """A train speed in metres per second, above 0 and at most :data:`MAX_TRAIN_SPEED_MPS`."""
    x = positive_float(value)
    if x > MAX_TRAIN_SPEED_MPS:
        raise argparse.ArgumentTypeError(
            f"{value} m/s is {3.6 * x:.0f} km/h, beyond any train (at most "
            f"{MAX_TRAIN_SPEED_MPS:g} m/s = {3.6 * MAX_TRAIN_SPEED_MPS:.0f} km/h); give metres "
            f"per second: {value} km/h is {x / 3.6:.1f}"
        )
    return x


def rate_hz(value: str) -> float:
    """An epoch rate in hertz, above 0 and at most 100 (what GNSS receivers log at)."""
    x = positive_float(value)
    if x > _MAX_RATE_HZ:
        raise argparse.ArgumentTypeError(
            f"{value} Hz is beyond any GNSS receiver (at most {_MAX_RATE_HZ:g} Hz); give epochs "
            "per second, e.g. 1 or 10"
        )
    return x


def antenna_height_m(value: str) -> float:
    """An antenna height above the rail in metres, in [0, 10]."""
    x = non_negative_float(value)
    if x > _MAX_ANTENNA_HEIGHT_M:
        raise argparse.ArgumentTypeError(
            f"{value} m is no antenna height above the rail (at most {_MAX_ANTENNA_HEIGHT_M:g} m;"
            f" a roof antenna is 4-5 m); give metres ({value} cm is {x / 100:g})"
        )
    return x


def fraction(value: str) -> float:
    """A share in (0, 1]; a value in (1, 100] reads as percent and is refused with the share."""
    x = _number(value)
    if 1.0 < x <= 100.0:
        raise argparse.ArgumentTypeError(
            f"{value} looks like percent; give a share in (0, 1] ({value} % is {x / 100:g})"
        )
    if not 0.0 < x <= 1.0:
        raise argparse.ArgumentTypeError(f"{value} is not a share; give a number in (0, 1]")
    return x


def constellation(value: str) -> str:
    """A constellation selection: a name (``gps``, ``gps+galileo``, ``galileo``,
    ``gps+glonass``, ``all``) or RINEX system letters (``GE``); kept as given."""
    from predisat.availability.satellites import CONSTELLATIONS, SYSTEM_NAMES

    key = value.strip().lower()
    letters = [c for c in value.upper() if c not in " ,+;"]
    if key in CONSTELLATIONS or (letters and all(c in SYSTEM_NAMES for c in letters)):
        return value
    names = ", ".join(CONSTELLATIONS)
    raise argparse.ArgumentTypeError(
        f"{value!r} is no constellation; give one of {names}, or system letters "
        f"({', '.join(f'{k} {v}' for k, v in SYSTEM_NAMES.items())})"
    )


def constellation_letters(value: str) -> str:
    """The system letters of a :func:`constellation` selection (``"gps+galileo"`` -> ``"GE"``)."""
    from predisat.availability.satellites import CONSTELLATIONS

    key = value.strip().lower()
    letters = CONSTELLATIONS.get(key, "".join(c for c in value.upper() if c not in " ,+;"))
    return "".join(dict.fromkeys(letters))


def constellation_label(value: str) -> str:
    """The systems of a :func:`constellation` selection by name (``"GPS, Galileo"``)."""
    from predisat.availability.satellites import SYSTEM_NAMES

    return ", ".join(SYSTEM_NAMES.get(c, c) for c in constellation_letters(value))


def chainage_hint(value_m: float, lo_m: float, hi_m: float, option: str) -> str:
    """A hint when ``value_m`` (outside ``[lo_m, hi_m]``) reads as kilometres inside it
    (``"; did you give kilometres? (--chainage 5200)"``), else ``""``."""
    if lo_m <= value_m <= hi_m:
        return ""
    if lo_m <= 1000.0 * value_m <= hi_m:
        return f"; the value is metres, did you give kilometres? ({option} {1000.0 * value_m:g})"
    return ""


def caused_by_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` comes from Ctrl-C: numba-compiled code turns the KeyboardInterrupt
    into a SystemError caused by it, which a command line should treat as an interrupt."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return False


def integrity_risk(value: str) -> float:
    """An integrity risk per epoch: a probability in (0, 0.1]; a percentage is refused."""
    x = _number(value)
    if x <= 0.0:
        raise argparse.ArgumentTypeError(f"{value} must be above 0 (a probability, e.g. 1e-12)")
    if x > 0.1:
        hint = f"; {x:g} % is {x / 100:g}" if x <= 100 else ""
        raise argparse.ArgumentTypeError(
            f"{value} is no integrity risk per epoch (a probability up to 0.1, e.g. 1e-12 for "
            f"the source's three pairs){hint}"
        )
    return x


def k_sigma_value(value: str) -> float:
    """A pair interval half width in sigmas whose risk per pair, ``2 Q(k)``, is at most the
    largest integrity risk :func:`integrity_risk` takes (0.1: ``k >= 1.645``)."""
    from scipy.stats import norm

    x = _number(value)
    k_min = float(norm.isf(0.05))
    if not (x >= k_min):
        risk = f" bounds each pair at a risk of {2 * norm.sf(x):.2g}" if x > 0 else " is no width"
        raise argparse.ArgumentTypeError(
            f"{value}{risk}; --k-sigma must be at least {k_min:.3f} (a risk of 0.1 per pair), "
            "and --integrity-risk is the way to state a risk (default 1e-12 per epoch)"
        )
    return x


def scheduler_text(text: str) -> str:
    """``--scheduler``: ``local``, ``serial`` or an address, checked when the command line is
    read (a mistyped ``lcoal`` failed only after the inputs were read)."""
    from predisat.scheduler import Scheduler

    try:
        Scheduler.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def scheduler_options(p: argparse.ArgumentParser, tasks: str, threads: bool = False) -> None:
    """``--scheduler local|serial|ADDRESS`` and ``--workers N`` (:mod:`predisat.scheduler`);
    ``tasks`` names what runs as tasks ("the chunks"); ``threads``: whether a serial run takes
    ``--workers`` threads (tasks that are thread-safe)."""
    p.add_argument(
        "--scheduler", default="local", metavar="local|serial|ADDRESS", type=scheduler_text,
        help=f"where {tasks} run: a local Dask cluster (default), this process (serial), or an "
        "existing Dask cluster by its scheduler's address (tcp://HOST:8786)",
    )  # fmt: skip
    p.add_argument(
        "--workers", type=positive_int, metavar="N",
        help="worker processes of the local cluster (default: the machine's cores)"
        + (", threads with --scheduler serial (default 1)" if threads else ""),
    )  # fmt: skip


def integrity_options(p: argparse.ArgumentParser) -> None:
    """``--integrity-risk P`` (default: :data:`~predisat.gnss.integrity.DEFAULT_RISK_PER_EPOCH`)
    or ``--k-sigma K``, one of them: the width of the pair intervals."""
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--integrity-risk", type=integrity_risk, metavar="P",
        help="integrity risk per epoch the intervals are drawn for; each interval mode's k "
        f"follows from it (default {DEFAULT_RISK_PER_EPOCH:g}, the source's three pairs: k = "
        f"{IntegrityBudget().k_sigma(3):.2f} with three pairs, "
        f"{IntegrityBudget().k_sigma(2):.2f} with all pairs of 4-5; docs/locator.md)",
    )  # fmt: skip
    g.add_argument(
        "--k-sigma", type=k_sigma_value, metavar="K",
        help="instead of a risk: one pair interval half width in sigmas for every mode (default: "
        "none, the risk decides; the source's 2 is 4.6e-2 per pair, 3.89 is 1e-4)",
    )  # fmt: skip


def integrity_budget(args: argparse.Namespace) -> IntegrityBudget | None:
    """The budget of :func:`integrity_options`' options; None when ``--k-sigma`` fixes ``k``."""
    if getattr(args, "k_sigma", None) is not None:
        return None
    risk = getattr(args, "integrity_risk", None)
    return IntegrityBudget(DEFAULT_RISK_PER_EPOCH if risk is None else risk)


def add_map_doubt(p: argparse.ArgumentParser) -> None:
    """``--map-doubt LAT VERT``: :class:`predisat.availability.interval.MapDoubt`, the same
    option on ``locator run``, ``locator balises`` and ``predisat availability``."""
    d = MapDoubt()
    p.add_argument(
        "--map-doubt", nargs=2, type=non_negative_float, metavar=("LAT", "VERT"),
        help="how far the antenna may be beside and above or below the track map, metres: the "
        "map's accuracy, the antenna's lateral lever arm, cant, a passing loop; each pair "
        f"interval is widened to bound the error that makes (default {d.lateral_m:g} "
        f"{d.vertical_m:g}: a map good to a metre; an OpenStreetMap line needs several metres; "
        "0 0: the source's pairs; docs/locator.md)",
    )  # fmt: skip


def map_doubt_arg(args: argparse.Namespace) -> MapDoubt:
    """The :class:`~predisat.availability.interval.MapDoubt` of ``--map-doubt`` (its default
    when not given)."""
    given_m = getattr(args, "map_doubt", None)
    return MapDoubt() if given_m is None else MapDoubt(float(given_m[0]), float(given_m[1]))
