"""Fuzzing the file readers: valid seed files, mutations, and the errors each reader may raise.

Each :class:`Reader` holds a valid input (one file, or a folder of files for a survey), the
call that reads it and its *named* errors. :func:`mutate` damages a file as a user's disk,
copy or editor would (byte flips, truncation, a line deleted, duplicated or swapped, a field
replaced by an odd token, random bytes inserted, a line spliced from elsewhere, generated
lines of odd tokens and numbers); the
mutations are driven by a ``draw(lo, hi)`` function, so that Hypothesis
(``tests/fuzz/test_fuzz_readers.py``, small budget in CI) and a plain random generator
(``scripts/fuzz_readers.py``, large budget) share them. :func:`run_one` reads one mutated
input: the reader's named errors, which must name the file, pass; any other exception is a
bug and is raised again as :class:`FuzzFailure`.
"""

from __future__ import annotations

import tempfile
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

__all__ = ["READERS", "FuzzFailure", "Reader", "mutate", "reader", "run_one", "targets"]

DATA = Path(__file__).resolve().parents[1] / "data"

Draw = Callable[[int, int], int]
"""``draw(lo, hi)``: an integer in ``[lo, hi]`` (both included)."""

TOKENS = (
    b"", b"0", b"-0", b"-1", b"1e308", b"-1e308", b"nan", b"NaN", b"inf", b"-inf", b"1e-320",
    b"9" * 25, b"x", b"D", b"E", b"0x10", b" ", b"\t", b",", b";", b"\"", b"'", b"{", b"}",
    b"[", b"]", b"null", b"true", b"[]", b"{}", b"\x00", b"\xff\xfe", "é".encode(), b"\xe9",
    b"99:99:99", b"2023 13 40 25 61 61.0", b"G99", b"R00", b"X01", b"%", b"*", b"#", b"&",
    b"!!python/object:os.system", b"~", b"---", b"...", b"\r", b"\n", b"1.#IND", b"+",
)  # fmt: skip


class FuzzFailure(AssertionError):
    """A reader raised something else than its named errors (or one that names no file)."""


@dataclass(frozen=True)
class Reader:
    """A reader under test.

    Attributes
    ----------
    name : str
    seeds : tuple of dict of str to bytes
        Valid inputs: each a folder's files (relative path -> content); the mutated file is
        one of ``mutable``.
    mutable : tuple of str
        The files of a seed that are damaged (relative paths); empty: each seed is one file,
        the one damaged.
    read : callable
        ``read(folder)``: reads the input written into ``folder``.
    errors : tuple of exception types
        The named errors the reader may raise.
    """

    name: str
    seeds: tuple[dict[str, bytes], ...]
    mutable: tuple[str, ...]
    read: Callable[[Path], object]
    errors: tuple[type[BaseException], ...]


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def mutate(data: bytes, draw: Draw, other: bytes = b"") -> bytes:
    """``data`` damaged by one to four mutations chosen with ``draw``; ``other`` gives lines
    to splice in (another valid file of the same format)."""
    for _ in range(draw(1, 4)):
        n = len(data)
        op = draw(0, 11)
        if op == 0 and n:  # flip bits of one byte
            i = draw(0, n - 1)
            data = data[:i] + bytes([data[i] ^ draw(1, 255)]) + data[i + 1 :]
        elif op == 1:  # truncate
            data = data[: draw(0, n)]
        elif op == 2 and n:  # overwrite a stretch with zeros or one byte
            i = draw(0, n - 1)
            k = draw(1, 64)
            data = data[:i] + bytes([draw(0, 255)]) * k + data[i + k :]
        elif op == 3:  # insert random bytes
            i = draw(0, n)
            data = data[:i] + bytes(draw(0, 255) for _ in range(draw(1, 8))) + data[i:]
        elif op in (4, 5, 6):  # delete / duplicate / swap lines
            lines = _lines(data)
            i = draw(0, len(lines) - 1)
            if op == 4:
                del lines[i : i + draw(1, 3)]
            elif op == 5:
                lines[i:i] = lines[i : i + draw(1, 3)] * draw(1, 3)
            else:
                j = draw(0, len(lines) - 1)
                lines[i], lines[j] = lines[j], lines[i]
            data = b"".join(lines)
        elif op in (7, 8):  # replace a field of a line by an odd token
            lines = _lines(data)
            i = draw(0, len(lines) - 1)
            line = lines[i]
            cut = [k for k, c in enumerate(line) if c in b" ,:\t="] or [0]
            a = cut[draw(0, len(cut) - 1)] + 1
            b = min(len(line), a + draw(0, 20))
            lines[i] = line[:a] + TOKENS[draw(0, len(TOKENS) - 1)] + line[b:]
            data = b"".join(lines)
        elif op == 9 and other:  # splice a line of another file in
            src = _lines(other)
            lines = _lines(data)
            lines.insert(draw(0, len(lines)), src[draw(0, len(src) - 1)])
            data = b"".join(lines)
        elif op == 10 and n:  # a number's digit changed
            digits = [k for k, c in enumerate(data) if 48 <= c <= 57]
            if digits:
                i = digits[draw(0, len(digits) - 1)]
                data = data[:i] + bytes([48 + draw(0, 9)]) + data[i + 1 :]
        elif op == 11:  # generated lines of odd tokens and digits in place of a stretch
            lines = _lines(data)
            i = draw(0, len(lines))
            new = [
                b" ".join(
                    TOKENS[draw(0, len(TOKENS) - 1)] if draw(0, 1) else b"%d" % draw(-99, 9999)
                    for _ in range(draw(0, 8))
                ) + b"\n"
                for _ in range(draw(1, 3))
            ]
            lines[i : i + draw(0, 2)] = new
            data = b"".join(lines)
    return data


def run_one(r: Reader, seed: dict[str, bytes], target: str, data: bytes, folder: Path) -> bool:
    """Write ``seed`` with ``target`` replaced by ``data`` into ``folder`` and read it.

    Returns
    -------
    bool
        True when read, False when refused with a named error.

    Raises
    ------
    FuzzFailure
        Any other exception, or a named error whose message names no file.
    """
    for rel, content in seed.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data if rel == target else content)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r.read(folder)
    except r.errors as exc:
        text = str(exc)
        if folder.name not in text and Path(target).name not in text:
            raise FuzzFailure(
                f"{r.name}: {type(exc).__name__} names no file: {text[:300]}"
            ) from exc
        return False
    except Exception as exc:
        raise FuzzFailure(f"{r.name}: {type(exc).__name__}: {exc}"[:500]) from exc
    return True


# ---- the readers and their seeds ------------------------------------------------------------


def _files(*paths: str) -> tuple[dict[str, bytes], ...]:
    return tuple({"input" + Path(p).suffix: (DATA / p).read_bytes()} for p in paths)


def _single(folder: Path) -> Path:
    return next(p for p in folder.iterdir() if p.name.startswith("input"))


def _rinex_obs() -> Reader:
    from locator.observations import RinexObsError, read_rinex_obs

    def read(folder: Path) -> object:
        return read_rinex_obs(_single(folder))

    seeds = _files(
        "gnss_obs/07590920_10ep.05o", "gnss_obs/android_rinex_obs_pixel6_6ep.23o",
        "gnss_obs/rinex_obs_rinex_obs_mixed_types.20o", "gnss_obs/rinex_obs_z_tracking.rnx",
    )  # fmt: skip
    return Reader("rinex_obs", seeds, (), read, (RinexObsError,))


def _rinex_nav() -> Reader:
    from predisat.gnss.rinex_nav import RinexError, read_rinex_nav

    seeds = _files(
        "gnss/brdc0910_R02R08.09g", "gnss/brdc1820_G01G02G05.10n",
        "gnss/rinex_nav_BRDC00WRD_S_20230730000_01D_MN_E01E02.rnx",
        "gnss_obs/07590920_0000_0200.05n",
        "gnss/rinex4_nav_BRUX_20260723_G04G05_LNAV_CNAV.rnx",  # RINEX 4 with CNAV records
    )  # fmt: skip
    return Reader(
        "rinex_nav", seeds, (), lambda f: read_rinex_nav(_single(f)), (RinexError,)
    )


def _sp3() -> Reader:
    from predisat.gnss.sp3 import Sp3Error, read_sp3

    seeds = _files("gnss/igl15253_R02R08.sp3", "gnss/igs15904_G01G02G05.sp3")
    return Reader("sp3", seeds, (), lambda f: read_sp3(_single(f)), (Sp3Error,))


def _tle() -> Reader:
    from predisat.gnss.tle import TleError, read_tle

    seeds = _files("gnss/TLE_GNSS_20121101.txt")
    return Reader("tle", seeds, (), lambda f: read_tle(_single(f)), (TleError,))


def _track_csv_bytes() -> bytes:
    from predisat.geodesy import WGS84

    lon, lat, _ = WGS84.fwd(np.full(12, 4.6), np.full(12, 50.5), np.zeros(12),
                            np.arange(12) * 50.0)  # fmt: skip
    rows = [b"lat_deg,lon_deg,h_m\n"]
    rows += [f"{a:.7f},{o:.7f},{150 + k * 0.1:.2f}\n".encode()
             for k, (a, o) in enumerate(zip(lat, lon, strict=True))]  # fmt: skip
    return b"".join(rows)


def _track_geojson_bytes() -> bytes:
    """The CSV's track as ``write_geojson`` writes it, one value per line (line edits hit
    values); the riviera excerpt of tests/data takes seconds to fit, too slow to fuzz."""
    import json

    from predisat.track.map import TrackMap
    from predisat.track.readers import parse_csv_track, write_geojson

    with tempfile.TemporaryDirectory() as tmp:
        csv_path, path = Path(tmp) / "t.csv", Path(tmp) / "t.geojson"
        csv_path.write_bytes(_track_csv_bytes())
        write_geojson(TrackMap.from_track_file(parse_csv_track(csv_path)), path)
        doc = json.loads(path.read_text())
    return json.dumps(doc, indent=1).encode()


def _track() -> Reader:
    from predisat.track import load_track
    from predisat.track.errors import TrackMapError

    seeds = ({"input.csv": _track_csv_bytes()}, {"input.geojson": _track_geojson_bytes()})
    return Reader("track", seeds, (), lambda f: load_track(_single(f)), (TrackMapError,))


def _calibration() -> Reader:
    from predisat.camera.calibfile import CalibrationError, read_calibration

    seeds = tuple({"input.yaml": c} for k, c in _survey_seed().items() if k.endswith("t.yaml"))
    return Reader(
        "calibration", seeds, (), lambda f: read_calibration(_single(f)), (CalibrationError,)
    )


def _error_model() -> Reader:
    from predisat.gnss.errormodel import (
        Applicability,
        ErrorModel,
        ErrorModelFileError,
        IntervalModel,
        SystemModel,
        read_error_model_file,
        write_error_model,
    )

    e = ErrorModel(0.3, 1.2, 5.0)
    with tempfile.TemporaryDirectory() as tmp:
        p = write_error_model(Path(tmp) / "em.json", IntervalModel(e, 2.0),
                              {"n": 120, "note": "fuzz seed"},
                              systems={"G": SystemModel(e, ("C1C",), 1200, 60, 0.05)},
                              applicability=Applicability(("TRIMBLE NETR9",), ("ANT",),
                                                          el_min_deg=5.0))  # fmt: skip
        seed = {"input.json": p.read_bytes()}
    return Reader(
        "error_model", (seed,), (), lambda f: read_error_model_file(_single(f)),
        (ErrorModelFileError,),
    )  # fmt: skip


def _masks() -> Reader:
    from predisat.masks.fileformat import MaskFileError, read_masks, write_masks
    from predisat.masks.maskset import MaskError, MaskSet

    rng = np.random.default_rng(0)
    n_pos, n_az = 4, 36
    ms = MaskSet.from_arrays(
        100.0 + 10.0 * np.arange(n_pos), 50.6 + 1e-4 * np.arange(n_pos),
        4.4 - 1e-4 * np.arange(n_pos), np.full(n_pos, 110.0), np.full(n_pos, 90.0),
        rng.uniform(0, 60, (n_pos, n_az)), az_step_deg=10.0,
    )  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        p = write_masks(ms, Path(tmp) / "m.parquet")
        seed = {"input.parquet": p.read_bytes()}
    return Reader(
        "masks", (seed,), (), lambda f: read_masks(_single(f)), (MaskFileError, MaskError)
    )


@cache
def _survey_seed() -> dict[str, bytes]:
    """A tiny valid survey folder (4 frames per side, 32x24 px; the right camera with
    distortion): relative path -> content."""
    from predisat.camera.models import CameraModel, Mount
    from predisat.survey import SurveyWriter

    cam = CameraModel.pinhole_from_fov(32, 24, 74.0, name="tiny")
    bent = CameraModel.pinhole_from_fov(32, 24, 74.0, dist=(-0.1, 0.02, 0.001, 0.0), name="bent")
    cams = {"left": (cam, Mount.default("left")), "right": (bent, Mount("right", -85.0, 40.0))}
    img = np.zeros((24, 32, 3), np.uint8)
    img[:8] = 200
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "s"
        with SurveyWriter(root, cams, metadata={"description": "fuzz seed"}) as w:
            for i in range(4):
                for side in ("left", "right"):
                    w.add_frame(img, side, 1_400_000_000.25 + i, chainage_m=100.0 + 10.0 * i)
        return {
            str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
        }


def _survey() -> Reader:
    from predisat.survey import Survey, SurveyError

    seed = _survey_seed()
    mutable = tuple(k for k in seed if k.endswith((".yaml", ".csv")))
    return Reader(
        "survey", (seed,), mutable, lambda f: Survey.load(f, on_error="skip"), (SurveyError,)
    )


def _device_gnss() -> Reader:
    from locator.devicegnss import DeviceGnssError, read_device_gnss

    seeds = _files("gsdc/google_decimeter_2022_device_gnss_1ep.csv",
                   "gsdc/gdc2023_pixel7pro_device_gnss_2ep.csv")  # fmt: skip
    return Reader(
        "device_gnss", seeds, (), lambda f: read_device_gnss(_single(f)), (DeviceGnssError,)
    )


def _gsdc_truth() -> Reader:
    from locator.devicegnss import DeviceGnssError, read_ground_truth

    seeds = _files("gsdc/gdc2023_pixel7pro_ground_truth.csv")
    return Reader(
        "gsdc_truth", seeds, (), lambda f: read_ground_truth(_single(f)), (DeviceGnssError,)
    )


_MAKERS: dict[str, Callable[[], Reader]] = {
    "rinex_obs": _rinex_obs,
    "rinex_nav": _rinex_nav,
    "sp3": _sp3,
    "tle": _tle,
    "track": _track,
    "survey": _survey,
    "calibration": _calibration,
    "error_model": _error_model,
    "masks": _masks,
    "device_gnss": _device_gnss,
    "gsdc_truth": _gsdc_truth,
}
READERS = tuple(_MAKERS)
"""The names of the fuzzed readers."""


@cache
def reader(name: str) -> Reader:
    """The :class:`Reader` named ``name`` (one of :data:`READERS`), its seeds made once."""
    return _MAKERS[name]()


def targets(r: Reader, seed: dict[str, bytes]) -> list[str]:
    """The files of ``seed`` that may be damaged (a single-file seed: its file)."""
    return [k for k in seed if k in r.mutable] if r.mutable else list(seed)
