"""Virtual balise lists: the stored reference points (source document 001) and their file.

A virtual balise is a reference point stored on board (and in the RBC's database): an id, a
position on the track, and the telegram a real balise there would send. The list is a CSV file
(``docs/odometry.md``), one balise per row, **in increasing chainage**:

| column | unit | meaning |
|---|---|---|
| ``id`` | - | unique identifier, case aside (NID_BG style, any text without commas) |
| ``chainage_m`` | m | position along the track map |
| ``lat_deg``, ``lon_deg``, ``h_m`` | deg, m | its coordinates (WGS84), on the track axis |
| ``telegram`` | - | the telegram to emit (opaque text, e.g. hexadecimal) |
| ``q_reference`` | - | optional: 1 (default) usable as a location reference, 0 not |
| ``accuracy_m`` | m | optional: location accuracy (Q_LOCACC), default 1 m |

Rejected with :class:`BaliseFileError` naming the file, the line and the fix: a file that is
not text, columns not separated by commas, missing columns, empty or non-numeric values, an
empty ``id`` or ``telegram``, **duplicate ids**, chainages **out of order**, chainages **off the
track** (outside ``[0, length]``), and coordinates that do not lie on the track at the stated
chainage (more than ``max_offset_m`` away horizontally: heights are not compared,
:func:`horizontal_offset_m`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from locator.csvinput import read_csv_table
from predisat.geodesy import geodetic_to_ecef
from predisat.readonly import freeze_array_fields
from predisat.track import TrackMap

__all__ = ["ALONG_TOL_M", "Q_LOCACC_MAX_M", "BaliseFileError", "BaliseList", "horizontal_offset_m"]

REQUIRED = ("id", "chainage_m", "lat_deg", "lon_deg", "h_m", "telegram")


class BaliseFileError(ValueError):
    """A balise list that cannot be used; the message names the file, the line and the fix."""


# what each numeric column holds, for the messages
_UNITS = {
    "chainage_m": "the chainage in metres along the track map",
    "lat_deg": "the latitude in decimal degrees (WGS84)",
    "lon_deg": "the longitude in decimal degrees (WGS84)",
    "h_m": "the ellipsoidal height in metres (0 if unknown: it is not compared)",
    "q_reference": "1 (usable as a location reference) or 0",
    "accuracy_m": "the location accuracy in metres",
}
# column names of other lists and the column each probably is
_ALIASES = {"chainage": "chainage_m", "km": "chainage_m", "lat": "lat_deg",
            "latitude": "lat_deg", "lon": "lon_deg", "lng": "lon_deg", "longitude": "lon_deg",
            "h": "h_m", "height": "h_m", "height_m": "h_m", "alt": "h_m", "nid_bg": "id",
            "name": "id", "accuracy": "accuracy_m", "acc_m": "accuracy_m",
            "q_locacc": "accuracy_m", "locacc_m": "accuracy_m", "q_locacc_m": "accuracy_m",
            "q_ref": "q_reference", "qref": "q_reference"}  # fmt: skip
OPTIONAL = ("q_reference", "accuracy_m")


#: the largest location accuracy a balise telegram can state (Q_LOCACC, 6 bits of 1 m)
Q_LOCACC_MAX_M = 63.0

ALONG_TOL_M = 0.5
"""How far along the track a balise's coordinates may place it beyond its ``accuracy_m`` from
its chainage: the map's own error and rounding."""


def horizontal_offset_m(
    track: TrackMap, chainage_m: NDArray, lat_deg: NDArray, lon_deg: NDArray, h_m: NDArray
) -> NDArray:
    """Horizontal distance between balise coordinates and the track point at their chainage, m.

    Measured in the track point's own east-north plane: heights are not compared (a track map
    often carries none, h 0, and the chainage the capture uses is horizontal).
    """
    here = track.ecef_at(chainage_m)
    d = geodetic_to_ecef(lat_deg, lon_deg, h_m) - here
    lat, lon, _ = track.position_at(chainage_m)
    la, lo = np.radians(lat), np.radians(lon)
    # the ellipsoid normal at the track point, ECEF
    up = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)
    horizontal = d - np.sum(d * up, axis=-1, keepdims=True) * up
    return np.asarray(np.linalg.norm(horizontal, axis=-1), float)


def _offset_fix(
    track: TrackMap, chainage_m: float, lat_deg: float, lon_deg: float, h_m: float,
    max_offset_m: float,
) -> str:
    """How to fix coordinates off the track: chainage in km, lat/lon swapped, or in general."""
    km = 1000.0 * chainage_m
    if 0.0 <= km <= track.length_m:
        o = horizontal_offset_m(track, np.array([km]), np.array([lat_deg]), np.array([lon_deg]),
                                np.array([h_m]))[0]  # fmt: skip
        if o <= max_offset_m:
            return (f"did you give kilometres? its coordinates lie on the track at "
                    f"{km:.1f} m: give chainage_m in metres")  # fmt: skip
    o = horizontal_offset_m(track, np.array([chainage_m]), np.array([lon_deg]),
                            np.array([lat_deg]), np.array([h_m]))[0]  # fmt: skip
    if o <= max_offset_m:
        return "lat_deg and lon_deg look swapped: exchange the two columns"
    other = track.length_m - chainage_m
    if 0.0 <= other <= track.length_m:
        o = horizontal_offset_m(track, np.array([other]), np.array([lat_deg]),
                                np.array([lon_deg]), np.array([h_m]))[0]  # fmt: skip
        if o <= max_offset_m:
            return (f"chainage measured from the other end? its coordinates lie on the track "
                    f"at {other:.1f} m (the map's length {track.length_m:.1f} m less "
                    f"{chainage_m:.1f} m): give chainage_m from the map's first point")
    return "correct the chainage or the coordinates (or the track map)"


@dataclass(frozen=True, eq=False)
class BaliseList:
    """Virtual balises along a track, in increasing chainage.

    Attributes
    ----------
    ids : tuple of str, length n
    chainage_m : ndarray, shape (n,)
        Strictly increasing.
    lat_deg, lon_deg, h_m : ndarray, shape (n,)
    telegram : tuple of str, length n
    q_reference : ndarray of bool, shape (n,)
    accuracy_m : ndarray, shape (n,)
    source : str
        Where the list came from (a file, or how it was generated).
    """

    ids: tuple[str, ...]
    chainage_m: NDArray
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    telegram: tuple[str, ...]
    q_reference: NDArray
    accuracy_m: NDArray
    source: str = ""

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def along_track(
        cls,
        track: TrackMap,
        start_m: float,
        stop_m: float,
        spacing_m: float,
        *,
        prefix: str = "VB",
        accuracy_m: float = 1.0,
    ) -> BaliseList:
        """Balises every ``spacing_m`` from ``start_m`` up to ``stop_m`` on a track map.

        Parameters
        ----------
        track : predisat.track.map.TrackMap
        start_m, stop_m, spacing_m : float
            Chainages, m; ``0 <= start_m < stop_m <= track.length_m``.
        prefix : str
            Ids are ``prefix`` plus a running number.
        accuracy_m : float
        """
        if not (0.0 <= start_m < stop_m <= track.length_m) or not spacing_m > 0:
            raise ValueError(
                f"along_track needs 0 <= start_m < stop_m <= {track.length_m:.1f} and "
                f"spacing_m > 0, got {start_m}, {stop_m}, {spacing_m}"
            )
        c = np.arange(start_m, stop_m + 1e-9, spacing_m)
        lat, lon, h = track.position_at(c)
        n = len(c)
        ids = tuple(f"{prefix}{k:05d}" for k in range(n))
        return cls(
            ids, c, np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float),
            tuple(f"{0x5A00 + k:06X}" for k in range(n)), np.ones(n, bool),
            np.full(n, float(accuracy_m)), f"every {spacing_m:g} m from {start_m:g} m",
        )  # fmt: skip

    @classmethod
    def from_csv(
        cls, path: str | Path, track: TrackMap, *, max_offset_m: float = 5.0
    ) -> BaliseList:
        """Read and validate a balise list against the track map it refers to.

        Parameters
        ----------
        path : str or Path
        track : predisat.track.map.TrackMap
        max_offset_m : float
            Largest distance between a balise's coordinates and the track point at its
            chainage, m.
        """
        p = Path(path)
        table = read_csv_table(p, REQUIRED, what="balise list", error=BaliseFileError,
                               doc="docs/odometry.md", aliases=_ALIASES,
                               optional=OPTIONAL)  # fmt: skip
        df = table.frame
        if len(df) == 0:
            raise BaliseFileError(f"{p}: no balise; add one row per balise")
        num = {}
        for col in ("chainage_m", "lat_deg", "lon_deg", "h_m", "q_reference", "accuracy_m"):
            if col not in df.columns:
                continue
            v = table.numbers(col, f"give {_UNITS[col]}")
            bad = np.flatnonzero(~np.isfinite(v))
            if len(bad):
                raise BaliseFileError(f"{p}, line {table.line(bad[0])}: {col} is empty or not a "
                                      "number; fill it in")  # fmt: skip
            num[col] = v

        def _line(i: int | np.integer) -> int:
            return table.line(int(i))

        ids = tuple(str(x).strip() for x in df["id"])
        seen: dict[str, int] = {}
        for i, b in enumerate(ids):
            if not b:
                raise BaliseFileError(f"{p}, line {_line(i)}: empty id; give every balise an id")
            if "," in b:
                raise BaliseFileError(
                    f"{p}, line {_line(i)}: id {b!r} holds a comma (quoted); ids are text "
                    "without commas (the captures' tables are CSV): rename it"
                )
            # ids told apart by case only are one balise to a reader (a review)
            key = b.casefold()
            if key in seen:
                same = "" if ids[seen[key]] == b else f" (as {ids[seen[key]]!r}: case aside)"
                raise BaliseFileError(
                    f"{p}, line {_line(i)}: id {b!r} already used on line "
                    f"{_line(seen[key])}{same}; ids must be unique: rename one of them"
                )
            seen[key] = i
        telegrams = tuple(str(x).strip() for x in df["telegram"])
        sent: dict[str, int] = {}
        for i, tg in enumerate(telegrams):
            if not tg:
                raise BaliseFileError(
                    f"{p}, line {_line(i)}: balise {ids[i]!r} has an empty telegram; give the "
                    "telegram it emits (e.g. hexadecimal)"
                )
            # the telegram is what a consumer reads (its balise group's identity): two balises
            # sending one telegram are one balise to it, located at either place (a user
            # trial's copied row, id and position edited, telegram not, was accepted)
            key = tg.casefold()
            if key in sent:
                first = sent[key]
                same = "" if telegrams[first] == tg else " (case aside)"
                raise BaliseFileError(
                    f"{p}, line {_line(i)}: balise {ids[i]!r} sends the telegram {tg!r} of "
                    f"balise {ids[first]!r} on line {_line(first)}{same}; a receiver could not "
                    "tell the two apart: give each balise its own telegram"
                )
            sent[key] = i
        # projected coordinates (Belgian Lambert 72, UTM: metres) in the degree columns: they
        # are no angle, the offset below is NaN and passed its test (a user trial's Lambert 72
        # list fell through to "enu_m contains NaN" with no file, line or fix)
        for col, lim in (("lat_deg", 90.0), ("lon_deg", 180.0)):
            bad = np.flatnonzero(np.abs(num[col]) > lim)
            if len(bad):
                i = bad[0]
                raise BaliseFileError(
                    f"{p}, line {_line(i)}: {col} {num[col][i]:g} is no "
                    f"{'latitude' if col == 'lat_deg' else 'longitude'} (at most {lim:g} deg): "
                    "projected coordinates in metres (Belgian Lambert 72, UTM)? give WGS84 "
                    "decimal degrees"
                )
        c = num["chainage_m"]
        length = float(track.length_m)
        bad = np.flatnonzero((c < 0.0) | (c > length))
        if len(bad):
            i = bad[0]
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r} at chainage {c[i]:.1f} m is off the "
                f"track (0-{length:.1f} m); correct its chainage or use the track map it was "
                "surveyed on"
            )
        bad = np.flatnonzero(np.diff(c) <= 0)
        if len(bad):
            i = bad[0] + 1
            # one row in kilometres among metres reads as out of order: its coordinates
            # say which (a user trial's 4.1 was told to sort the rows)
            for k in (i, i - 1):
                at = float(track.project(num["lat_deg"][k:k + 1], num["lon_deg"][k:k + 1],
                                         num["h_m"][k:k + 1]).chainage_m[0])  # fmt: skip
                if abs(at - 1000.0 * c[k]) < max(50.0, abs(at - c[k]) / 10.0):
                    raise BaliseFileError(
                        f"{p}, line {_line(k)}: balise {ids[k]!r}: chainage {c[k]:g} - did you "
                        f"give kilometres? its coordinates lie on the track at {at:.1f} m; give "
                        "chainage_m in metres"
                    )
            if len(c) > 1 and np.all(np.diff(c) < 0):
                # every row decreasing: a list measured from the other end keeps its order
                at = float(track.project(num["lat_deg"][:1], num["lon_deg"][:1],
                                         num["h_m"][:1]).chainage_m[0])  # fmt: skip
                if abs(at - (length - c[0])) <= max_offset_m + num.get(
                        "accuracy_m", np.ones(len(c)))[0] + ALONG_TOL_M:  # fmt: skip
                    raise BaliseFileError(
                        f"{p}, line {_line(0)}: balise {ids[0]!r} at {c[0]:.1f} m: the "
                        "chainages decrease and its coordinates lie on the track at "
                        f"{at:.1f} m (the map's length {length:.1f} m less {c[0]:.1f} m): "
                        "chainage measured from the other end? give chainage_m from the "
                        "map's first point"
                    )
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r} at {c[i]:.1f} m does not follow "
                f"{ids[i - 1]!r} at {c[i - 1]:.1f} m; sort the rows by increasing chainage "
                "(two balises at one place are one group: keep one row)"
            )
        lat, lon, h = num["lat_deg"], num["lon_deg"], num["h_m"]
        off = horizontal_offset_m(track, c, lat, lon, h)
        bad = np.flatnonzero(off > max_offset_m)
        if len(bad):
            i = bad[0]
            fix = _offset_fix(track, c[i], lat[i], lon[i], h[i], max_offset_m)
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r}: its coordinates are {off[i]:.1f} m "
                f"horizontally from the track point at chainage {c[i]:.1f} m (more than "
                f"{max_offset_m:g} m); {fix}"
            )
        q = num.get("q_reference", np.ones(len(c)))
        if not np.all(np.isin(q, (0.0, 1.0))):
            i = int(np.flatnonzero(~np.isin(q, (0.0, 1.0)))[0])
            raise BaliseFileError(f"{p}, line {_line(i)}: q_reference must be 0 or 1")
        acc = num.get("accuracy_m", np.ones(len(c)))
        if np.any(acc < 0):
            i = int(np.flatnonzero(acc < 0)[0])
            raise BaliseFileError(f"{p}, line {_line(i)}: accuracy_m must be >= 0")
        if np.any(acc >= Q_LOCACC_MAX_M):
            # the telegram's accuracy adds the fix's reach to it: never within Q_LOCACC's
            # 63 m, so the balise could never be captured (a user trial's 70 m: a silent miss)
            i = int(np.flatnonzero(acc >= Q_LOCACC_MAX_M)[0])
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r}: accuracy_m {acc[i]:g} leaves nothing "
                f"of the {Q_LOCACC_MAX_M:g} m a telegram may state (ETCS Q_LOCACC, 6 bits): it "
                "could never be captured; survey the balise's position better, or check the "
                "unit (metres)"
            )
        # the coordinates place the balise along the track too: further from its chainage than
        # its stated accuracy, one of the three is wrong, and the telegram's accuracy (built on
        # accuracy_m) would not hold it (a user trial: 4.8 m apart, accuracy 0.5 m, accepted)
        along = np.abs(np.asarray(track.project(lat, lon, h).chainage_m, float) - c)
        bad = np.flatnonzero(along > acc + ALONG_TOL_M)
        if len(bad):
            i = int(bad[0])
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r}: its coordinates lie {along[i]:.1f} m "
                f"along the track from its chainage {c[i]:.1f} m, more than its accuracy_m "
                f"{acc[i]:g} (+{ALONG_TOL_M:g} m for the map): the chainage, the coordinates "
                "or the accuracy is wrong; correct the one that is, or state an accuracy both "
                "support"
            )
        return cls(ids, c, lat, lon, h, telegrams, q.astype(bool), acc, str(p))

    def to_csv(self, path: str | Path) -> Path:
        """Write the list (floats with 17 significant digits: exact round trip)."""
        p = Path(path)
        pd.DataFrame({
            "id": self.ids, "chainage_m": self.chainage_m, "lat_deg": self.lat_deg,
            "lon_deg": self.lon_deg, "h_m": self.h_m, "telegram": self.telegram,
            "q_reference": self.q_reference.astype(int), "accuracy_m": self.accuracy_m,
        }).to_csv(p, index=False, float_format="%.17g")  # fmt: skip
        return p
