"""Virtual balise lists: the stored reference points (source document 001) and their file.

A virtual balise is a reference point stored on board (and in the RBC's database): an id, a
position on the track, and the telegram a real balise there would send. The list is a CSV file
(``docs/odometry.md``), one balise per row, **in increasing chainage**:

| column | unit | meaning |
|---|---|---|
| ``id`` | - | unique identifier (NID_BG style, any text without commas) |
| ``chainage_m`` | m | position along the track map |
| ``lat_deg``, ``lon_deg``, ``h_m`` | deg, m | its coordinates (WGS84), on the track axis |
| ``telegram`` | - | the telegram to emit (opaque text, e.g. hexadecimal) |
| ``q_reference`` | - | optional: 1 (default) usable as a location reference, 0 not |
| ``accuracy_m`` | m | optional: location accuracy (Q_LOCACC), default 1 m |

Rejected with :class:`BaliseFileError` naming the file, the line and the fix: missing columns,
empty or non-numeric values, **duplicate ids**, chainages **out of order**, chainages **off the
track** (outside ``[0, length]``), and coordinates that do not lie on the track at the stated
chainage (more than ``max_offset_m`` away).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from predisat.geodesy import geodetic_to_ecef
from predisat.track import TrackMap

__all__ = ["BaliseFileError", "BaliseList"]

REQUIRED = ("id", "chainage_m", "lat_deg", "lon_deg", "h_m", "telegram")


class BaliseFileError(ValueError):
    """A balise list that cannot be used; the message names the file, the line and the fix."""


def _line(i: int) -> int:
    return int(i) + 2  # data row i is on file line i + 2 (line 1 is the header)


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
        try:
            df = pd.read_csv(p, dtype={"id": str, "telegram": str}, keep_default_na=False)
        except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
            raise BaliseFileError(f"{p}: cannot read the balise list ({exc}); give a CSV file "
                                  f"with columns {', '.join(REQUIRED)}") from exc  # fmt: skip
        missing = [c for c in REQUIRED if c not in df.columns]
        if missing:
            raise BaliseFileError(f"{p}: missing columns {missing}; a balise list needs "
                                  f"{', '.join(REQUIRED)} (docs/odometry.md)")  # fmt: skip
        if len(df) == 0:
            raise BaliseFileError(f"{p}: no balise; add one row per balise")
        num = {}
        for col in ("chainage_m", "lat_deg", "lon_deg", "h_m", "q_reference", "accuracy_m"):
            if col not in df.columns:
                continue
            v = pd.to_numeric(df[col].replace("", np.nan), errors="coerce").to_numpy(float)
            bad = np.flatnonzero(~np.isfinite(v))
            if len(bad):
                raise BaliseFileError(f"{p}, line {_line(bad[0])}: {col} is empty or not a "
                                      "number; fill it in")  # fmt: skip
            num[col] = v
        ids = tuple(str(x).strip() for x in df["id"])
        seen: dict[str, int] = {}
        for i, b in enumerate(ids):
            if not b:
                raise BaliseFileError(f"{p}, line {_line(i)}: empty id; give every balise an id")
            if b in seen:
                raise BaliseFileError(
                    f"{p}, line {_line(i)}: id {b!r} already used on line {_line(seen[b])}; "
                    "ids must be unique: rename one of them"
                )
            seen[b] = i
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
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r} at {c[i]:.1f} m does not follow "
                f"{ids[i - 1]!r} at {c[i - 1]:.1f} m; sort the rows by increasing chainage "
                "(two balises at one place are one group: keep one row)"
            )
        lat, lon, h = num["lat_deg"], num["lon_deg"], num["h_m"]
        here = track.ecef_at(c)
        off = np.linalg.norm(geodetic_to_ecef(lat, lon, h) - here, axis=-1)
        bad = np.flatnonzero(off > max_offset_m)
        if len(bad):
            i = bad[0]
            raise BaliseFileError(
                f"{p}, line {_line(i)}: balise {ids[i]!r}: its coordinates are {off[i]:.1f} m "
                f"from the track point at chainage {c[i]:.1f} m (more than {max_offset_m:g} m); "
                "correct the chainage or the coordinates (or the track map)"
            )
        q = num.get("q_reference", np.ones(len(c)))
        if not np.all(np.isin(q, (0.0, 1.0))):
            i = int(np.flatnonzero(~np.isin(q, (0.0, 1.0)))[0])
            raise BaliseFileError(f"{p}, line {_line(i)}: q_reference must be 0 or 1")
        acc = num.get("accuracy_m", np.ones(len(c)))
        if np.any(acc < 0):
            i = int(np.flatnonzero(acc < 0)[0])
            raise BaliseFileError(f"{p}, line {_line(i)}: accuracy_m must be >= 0")
        return cls(ids, c, lat, lon, h, tuple(str(x) for x in df["telegram"]), q.astype(bool),
                   acc, str(p))  # fmt: skip

    def to_csv(self, path: str | Path) -> Path:
        """Write the list (floats with 17 significant digits: exact round trip)."""
        p = Path(path)
        pd.DataFrame({
            "id": self.ids, "chainage_m": self.chainage_m, "lat_deg": self.lat_deg,
            "lon_deg": self.lon_deg, "h_m": self.h_m, "telegram": self.telegram,
            "q_reference": self.q_reference.astype(int), "accuracy_m": self.accuracy_m,
        }).to_csv(p, index=False, float_format="%.17g")  # fmt: skip
        return p
