"""Trust margins per (sector, source) group: the table the pipeline applies to its masks.

A margin raises the mask of a bin by a few tenths of a degree, by the bin's sector relative to
the track (:data:`SECTORS`: ``cross`` within 45 deg of the perpendicular, else ``along``) and its
source (observed, reconstructed, assumed...). :class:`MarginTable` is fitted on a synthetic
survey against its ground truth by :func:`predisat.reconstruct.evaluate.calibrate_margin`
(``predisat evaluate --calibrate`` writes ``margins.json``), and applied by
``predisat process --margins``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from predisat.jsontypes import JsonDict
from predisat.masks.maskset import BinSource, MaskSet

__all__ = [
    "EL_STEP_DEG",
    "MARGIN_GROUP_OF",
    "MARGIN_SOURCES",
    "SECTORS",
    "MarginTable",
    "sector_of",
]

EL_STEP_DEG = 0.1
"""Elevation grid step of the direction counts (cell centres ``(k + 0.5) * step``)."""
SECTORS = ("cross", "along")
_SOURCE_NAMES = {int(s): s.name.lower() for s in BinSource}
MARGIN_GROUP_OF = {c: (int(BinSource.ASSUMED) if c == BinSource.TERRAIN else c)
                   for c in _SOURCE_NAMES}  # fmt: skip
"""The source code whose margin each source takes: a terrain bin was raised to a DEM horizon
after the margins were fitted and takes the margin of the far field it replaced (ASSUMED)."""
MARGIN_SOURCES = tuple(n for c, n in _SOURCE_NAMES.items() if MARGIN_GROUP_OF[c] == c)
"""The source names a margin table has rows for (terrain needs none of its own)."""


def sector_of(az_deg: ArrayLike, heading_deg: ArrayLike) -> NDArray:
    """``"cross"`` within 45 deg of ``heading +- 90``, else ``"along"`` (broadcast shapes)."""
    rel = np.mod(np.asarray(az_deg, float) - np.asarray(heading_deg, float), 180.0)
    return np.where(np.abs(rel - 90.0) <= 45.0, "cross", "along")


@dataclass(frozen=True, eq=False)
class MarginTable:
    """Margins per (sector, source) group, from :func:`calibrate_margin`.

    Attributes
    ----------
    table : pandas.DataFrame
        Columns ``sector``, ``source`` (name), ``margin_deg``, ``n_bins``, ``n_positions``,
        ``sampled`` (enough positions to calibrate alone), ``reached`` (target met),
        ``los_share`` (trusted directions truly in line of sight, achieved),
        ``sky_lost`` (truly visible directions not trusted); plus ``sector="*"`` /
        ``source="*"`` wildcard rows for unseen groups.
    target : float
    el_step_deg : float
    """

    table: pd.DataFrame
    target: float
    el_step_deg: float = EL_STEP_DEG
    meta: JsonDict = field(default_factory=dict)

    def margin_for(self, sector: NDArray, source: NDArray) -> NDArray:
        """Margin of every bin given its sector (str) and source code, degrees.

        Raises
        ------
        ValueError
            When a bin's (sector, source) group has no row in the table (a guess, even the
            table's largest margin, could be below what calibration would give it).
        """
        lut = {
            (str(sec), str(src)): float(m)
            for sec, src, m in zip(
                self.table["sector"], self.table["source"], self.table["margin_deg"], strict=True
            )
        }
        out = np.full(np.shape(sector), np.nan, float)
        source = np.asarray(source).copy()
        for own, like in MARGIN_GROUP_OF.items():
            if own != like:
                source[source == own] = like
        for (sec, src), m in lut.items():
            code = next((c for c, n in _SOURCE_NAMES.items() if n == src), None)
            if code is None:
                continue
            out[(sector == sec) & (source == code)] = m
        if np.isnan(out).any():
            k = np.flatnonzero(np.isnan(out).ravel())[0]
            group = (str(np.ravel(sector)[k]), _SOURCE_NAMES.get(int(np.ravel(source)[k]), "?"))
            raise ValueError(
                f"margin table has no row for (sector, source) {group}; calibrate with "
                "calibrate_margin (it writes every group) or add the row"
            )
        return out

    def check(self, where: str = "margin table") -> None:
        """Raise ValueError, naming ``where`` and the fix, unless the table has the columns
        ``sector``, ``source`` and ``margin_deg``, a finite margin >= 0 in every row and a row
        for each (sector, source) group by its name (wildcard ``*`` rows allowed)."""
        fix = "write it with `predisat evaluate MASKS --truth DIR --calibrate`"
        t = self.table
        missing = {"sector", "source", "margin_deg"} - set(t.columns)
        if missing:
            raise ValueError(f"{where}: no column(s) {sorted(missing)}; {fix}")
        margin = pd.to_numeric(t["margin_deg"], errors="coerce").to_numpy(float)
        bad = ~np.isfinite(margin) | (margin < 0)
        if bad.any():
            raise ValueError(f"{where}: margin_deg must be finite and >= 0 (row "
                             f"{int(np.flatnonzero(bad)[0])}); {fix}")  # fmt: skip
        sources = MARGIN_SOURCES
        keys = [(str(a), str(b)) for a, b in zip(t["sector"], t["source"], strict=True)]
        seen: dict[tuple[str, str], int] = {}
        for row, key in enumerate(keys):
            if key in seen:
                raise ValueError(
                    f"{where}: rows {seen[key]} and {row} both give (sector, source) {key} "
                    f"(margins {margin[seen[key]]:g} and {margin[row]:g} deg): which one holds "
                    f"cannot be told; keep one row per group; {fix}"
                )
            seen[key] = row
        pairs = set(keys)
        want = {(s, c) for s in SECTORS for c in sources}
        if not want <= pairs:
            raise ValueError(f"{where}: no margin for (sector, source) {sorted(want - pairs)}; "
                             f"a table needs all of {sorted(want)}; {fix}")  # fmt: skip
        odd = {p for p in pairs - want if "*" not in p}
        if odd:
            raise ValueError(f"{where}: unknown (sector, source) {sorted(odd)}; sectors are "
                             f"{list(SECTORS)}, sources {list(sources)}; {fix}")  # fmt: skip

    def apply(self, masks: MaskSet) -> MaskSet:
        """Copy of ``masks`` with these margins (:meth:`MaskSet.with_margin`)."""
        sec = sector_of(masks.az_deg[None, :], masks.heading_deg[:, None])
        return masks.with_margin(self.margin_for(sec, masks.source))

    def to_json(self, path: str | os.PathLike[str]) -> None:
        """Write the table as JSON (read back by :meth:`from_json`)."""
        doc = {
            "target": self.target,
            "el_step_deg": self.el_step_deg,
            "meta": self.meta,
            "margins": self.table.to_dict(orient="records"),
        }
        Path(path).write_text(json.dumps(doc, indent=1))

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> MarginTable:
        """The table :meth:`to_json` wrote (``margins.json`` of ``predisat evaluate
        --calibrate``).

        Raises
        ------
        ValueError
            When the file is not such a table (not JSON, or no ``target`` / ``margins``),
            naming the file, what it lacks and how to make one.
        """
        fix = ("make a margin table with `predisat evaluate MASKS --truth TRUTH --calibrate "
               "--out DIR` (it writes DIR/margins.json)")  # fmt: skip
        try:
            doc = json.loads(Path(path).read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path}: not a margin table (not JSON: {exc}); {fix}") from None
        if not isinstance(doc, dict):
            raise ValueError(f"{path}: not a margin table (not a JSON object); {fix}")
        for key in ("target", "margins"):
            if key not in doc:
                raise ValueError(f"{path}: not a margin table (no {key!r}); {fix}")
        rows = doc["margins"]
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise ValueError(
                f"{path}: 'margins' must be a list of rows, each an object with sector, source "
                f"and margin_deg; {fix}"
            )
        try:
            target = float(doc["target"])
            el_step = float(doc.get("el_step_deg", EL_STEP_DEG))
        except (TypeError, ValueError):
            raise ValueError(
                f"{path}: 'target' and 'el_step_deg' must be numbers, got {doc['target']!r} "
                f"and {doc.get('el_step_deg')!r}; {fix}"
            ) from None
        return cls(pd.DataFrame(rows), target, el_step, dict(doc.get("meta", {})))
