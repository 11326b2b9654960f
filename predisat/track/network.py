"""Railway networks: many lines in one GeoJSON file, each line's track map(s).

A network file is a GeoJSON FeatureCollection of LineString / MultiLineString features, each
carrying the id of its line (property ``line_id``, ``line``, ``linecalfa`` - Infrabel's line
number such as ``"144"`` or ``"50A/3"`` - or ``ref``; or the one given as ``id_key``). Infrabel's
``geovoies`` files (every track axis of the Belgian network) are read as they are published.

* **One track per line.** A double-track line has a feature per track (Infrabel ``trackname``
  ``A`` and ``B``; ``E/U`` is a single-track line). A survey train runs on one of them and
  the masks of two tracks 4 m apart differ by less than the survey's own error, so a line is
  processed on one reference track: ``track=`` when given, else ``A``, else ``E/U``, else the
  first name in sort order. The other tracks are listed in :attr:`Network.skipped`.
* **In service only.** Features whose ``status`` says out of service (Infrabel ``Hors
  service``) are left out by default and listed in :attr:`Network.skipped`.
* **Disconnected parts.** A line's reference track may come in pieces that do not meet (the
  Belgian file has gaps of 20 m to 60 km where a line shares another's track, or where
  sections were closed). Pieces whose ends lie within ``max_gap_m`` are chained into one
  polyline (:func:`predisat.track.chain.chain_all`); each group that does not meet another is
  a **part** of the line with its own :class:`~predisat.track.map.TrackMap` and its own
  chainage from 0, numbered 1, 2, ... in file order. A part has its own survey and mask file;
  nothing is chained across a gap (chainage there would be a fiction).
* A line whose pieces branch (three ends meeting) cannot be one polyline: it is refused with
  the line, the pieces and the fix, or listed in :attr:`Network.skipped` with
  ``on_bad_line="skip"``.

See ``docs/network.md``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal
from urllib.parse import quote

import numpy as np

from predisat.geodesy import LocalFrame
from predisat.jsontypes import JsonDict
from predisat.track.chain import Part, chain_all, concatenate_parts
from predisat.track.errors import TrackMapError
from predisat.track.map import TrackMap
from predisat.track.readers import (
    TrackFile,
    attribution_of,
    checked_parts,
    feature_label,
    geojson_features,
)

__all__ = [
    "ID_KEYS",
    "OUT_OF_SERVICE",
    "TRACK_PREFERENCE",
    "Network",
    "NetworkLine",
    "Skipped",
    "line_key",
    "overlapping_parts",
    "part_key",
    "track_key",
]

ID_KEYS = ("line_id", "line", "linecalfa", "ref")
"""Feature properties holding the line id, tried in this order (the first every line feature
has)."""
TRACK_KEY = "trackname"
TRACK_PREFERENCE = ("A", "E/U")
"""Reference track of a line when ``track=`` is not given (Infrabel: ``A`` the first track of
a double-track line, ``E/U`` a single-track line), then the first name in sort order."""
OUT_OF_SERVICE = ("hors service", "buiten dienst", "out of service", "disused", "abandoned")
"""``status`` values (case-insensitive) of features left out with ``in_service=True``."""


def line_key(line_id: str) -> str:
    """The line id as one file-name segment: URI-encoded as Hive partitioning does
    (``"50A/3"`` -> ``"50A%2F3"``); ``urllib.parse.unquote`` gives the id back."""
    return quote(line_id, safe="")


def part_key(line_id: str, part: int, n_parts: int) -> str:
    """Folder name of a line part's survey and outputs: :func:`line_key`, with ``.part<k>``
    when the line has several parts (``"211.part2"``)."""
    return line_key(line_id) if n_parts == 1 else f"{line_key(line_id)}.part{part}"


def track_key(track: TrackMap) -> str:
    """SHA-256 (16 hex digits) of a track map's vertices and tolerances: results keyed by it
    are redone when a line's geometry changes in the network file."""
    h = hashlib.sha256()
    for arr in (track.lat_deg, track.lon_deg, track.h_m):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    h.update(f"{track.tolerance_m!r} {track.vertical_tolerance_m!r}".encode())
    return h.hexdigest()[:16]


@dataclass(frozen=True)
class NetworkLine:
    """One line of a network: its id, the reference track and that track's connected parts.

    Attributes
    ----------
    line_id : str
        The line's id as the file gives it (``"144"``, ``"50A/3"``).
    track_name : str
        The reference track (``"A"``, ``"E/U"``; ``""`` when the file names none).
    parts : tuple of TrackMap
        The connected parts of the track, in file order; each has its chainage from 0.
    features : tuple of int
        Indices of the file's features that make the track.
    """

    line_id: str
    track_name: str
    parts: tuple[TrackMap, ...]
    features: tuple[int, ...]

    @property
    def length_m(self) -> float:
        """Sum of the parts' lengths, metres."""
        return float(sum(p.length_m for p in self.parts))

    @property
    def key(self) -> str:
        """:func:`line_key` of the id."""
        return line_key(self.line_id)

    def part_key(self, part: int) -> str:
        """:func:`part_key` of part ``part`` (1-based)."""
        if not 1 <= part <= len(self.parts):
            raise ValueError(
                f"line {self.line_id} has {len(self.parts)} part(s); part must be in "
                f"1..{len(self.parts)}, got {part}"
            )
        return part_key(self.line_id, part, len(self.parts))


@dataclass(frozen=True)
class Skipped:
    """Something the file holds that the network leaves out, and why.

    Attributes
    ----------
    line_id : str
    what : str
        ``"feature 12 (trackname=B, trackcode=L 144_2)"`` or ``"line 29"``.
    reason : str
    """

    line_id: str
    what: str
    reason: str


@dataclass(frozen=True)
class Network:
    """The lines of a network file, each on its reference track (see the module docstring).

    Build it with :meth:`from_file`.

    Attributes
    ----------
    path : Path
    name, attribution : str
    id_key : str
        The property the line ids came from.
    lines : tuple of NetworkLine
        In file order of their first feature.
    skipped : tuple of Skipped
        Tracks, features and lines left out, with the reason.
    """

    path: Path
    name: str
    attribution: str
    id_key: str
    lines: tuple[NetworkLine, ...]
    skipped: tuple[Skipped, ...] = ()

    @property
    def line_ids(self) -> tuple[str, ...]:
        return tuple(ln.line_id for ln in self.lines)

    @property
    def length_m(self) -> float:
        """Length of every line's reference track, metres."""
        return float(sum(ln.length_m for ln in self.lines))

    def line(self, line_id: str) -> NetworkLine:
        """The line ``line_id``; KeyError naming the lines there are."""
        for ln in self.lines:
            if ln.line_id == line_id:
                return ln
        raise KeyError(
            f"{self.path}: no line {line_id!r} in the network; lines: {_some(self.line_ids)}"
        )

    @classmethod
    def from_file(
        cls,
        path: str | Path,
        *,
        lines: Sequence[str] | None = None,
        id_key: str | None = None,
        track: str | None = None,
        where: Mapping[str, object] | None = None,
        in_service: bool = True,
        max_gap_m: float = 10.0,
        tolerance_m: float = 1.0,
        on_bad_line: Literal["raise", "skip"] = "raise",
    ) -> Network:
        """Read a network file (GeoJSON FeatureCollection of lines, WGS84 ``[lon, lat(, h)]``).

        Parameters
        ----------
        path : str or Path
        lines : sequence of str, optional
            Build only these lines (ids as in the file); default all. An id the file does not
            hold is refused.
        id_key : str, optional
            The property holding the line id; default the first of :data:`ID_KEYS` that every
            line feature has.
        track : str, optional
            Reference track name (``trackname``) of every line; default
            :data:`TRACK_PREFERENCE`. A line without that track is listed in ``skipped``.
        where : mapping, optional
            Further property filters ``{key: value}`` (None: key absent), as
            :func:`predisat.track.readers.parse_geojson_track`.
        in_service : bool
            Leave out features whose ``status`` is one of :data:`OUT_OF_SERVICE`.
        max_gap_m : float
            Pieces of a track whose ends are closer than this are chained into one part.
        tolerance_m : float
            Source tolerance of the smooth fit (the file's ``tolerance_m`` member wins; 10 for
            Infrabel's ``simpl10m`` file).
        on_bad_line : {"raise", "skip"}
            A line whose track cannot be built (branching pieces, a polyline crossing itself):
            raise, or list it in ``skipped``.

        Raises
        ------
        TrackMapError
            Naming the file, the feature or line, and the fix.
        """
        p = Path(path)
        if not max_gap_m > 0:
            raise TrackMapError(f"max_gap_m must be > 0, got {max_gap_m}")
        members, feats = geojson_features(p)
        tol = float(members.get("tolerance_m", tolerance_m))
        attribution = attribution_of(members)  # OpenStreetMap's ODbL notice included
        line_feats = [
            (i, f.get("properties") or {}, f.get("geometry") or {})
            for i, f in enumerate(feats)
            if (f.get("geometry") or {}).get("type") in ("LineString", "MultiLineString")
        ]
        if not line_feats:
            raise TrackMapError(
                f"{p}: no LineString or MultiLineString feature; a network file holds the lines' "
                "track axes as line features"
            )
        if where:
            # before the id key is looked for: a feature the filter removes need not carry it
            # (a user trial's --where usage=main was refused on a siding without the key)
            line_feats = [x for x in line_feats if _matches(x[1], where)]
            if not line_feats:
                asked = ", ".join(f"{k}={v}" for k, v in where.items())
                raise TrackMapError(
                    f"{p}: no line feature matches where {asked}; check the property names "
                    "and values (--where KEY=VALUE)"
                )
        key = _id_key(p, line_feats, id_key)
        skipped: list[Skipped] = []
        groups: dict[str, list[tuple[int, JsonDict, JsonDict]]] = {}
        for i, props, geom in line_feats:
            lid = str(props[key])
            if in_service and str(props.get("status", "")).strip().lower() in OUT_OF_SERVICE:
                skipped.append(Skipped(lid, feature_label(i, props), "out of service"))
                continue
            if not _matches(props, where):
                continue
            groups.setdefault(lid, []).append((i, props, geom))
        if lines is not None:
            missing = [lid for lid in lines if lid not in groups]
            if missing:
                raise TrackMapError(
                    f"{p}: no line {', '.join(map(repr, missing))} in service in the file (line "
                    f"ids from property {key!r}); lines: {_some(sorted(groups))}"
                )
            groups = {lid: groups[lid] for lid in lines}
        keys: dict[str, str] = {}
        built: list[NetworkLine] = []
        for lid, group in groups.items():
            lkey = line_key(lid)
            if lkey in keys:  # quote() is injective: only an equal id can collide
                raise TrackMapError(f"{p}: line ids {keys[lkey]!r} and {lid!r} collide")
            keys[lkey] = lid
            chosen, others = _reference_track(group, track)
            for i, props, _ in others:
                why = "another track of the line (one reference track per line)"
                skipped.append(Skipped(lid, feature_label(i, props), why))
            if not chosen:
                names = sorted({str(pr.get(TRACK_KEY)) for _, pr, _ in group})
                why = f"no track {track!r} (tracks: {', '.join(names)})"
                skipped.append(Skipped(lid, f"line {lid}", why))
                continue
            name = str(chosen[0][1].get(TRACK_KEY, "") or "")
            try:
                parts, empty = _line_parts(p, lid, name, chosen, max_gap_m, tol, attribution)
            except TrackMapError as exc:
                if on_bad_line == "raise":
                    raise
                skipped.append(Skipped(lid, f"line {lid}", str(exc)))
                continue
            skipped += [Skipped(lid, what, "zero length (every vertex the same)") for what in empty]
            built.append(NetworkLine(lid, name, parts, tuple(i for i, _, _ in chosen)))
        if not built:
            raise TrackMapError(
                f"{p}: no line left to build ({len(skipped)} left out: "
                f"{'; '.join(f'{s.what}: {s.reason}' for s in skipped[:3])}); check the "
                "selection (lines, track, where, in_service)"
            )
        return cls(p, str(members.get("name") or p.stem), attribution, key, tuple(built),
                   tuple(skipped))  # fmt: skip


def overlapping_parts(
    network: Network, *, within_m: float = 5.0, min_overlap_m: float = 50.0
) -> list[str]:
    """Sentences for lines whose parts lie on each other (within ``within_m`` over more than
    ``min_overlap_m``): the same track drawn twice in the file, processed twice and counted
    twice in the network's length (a user trial's overlapping pieces of one line became two
    parts without a word).

    Parameters
    ----------
    network : Network
    within_m : float
        Largest distance between the parts' axes, metres.
    min_overlap_m : float
        Shortest overlap said, metres.

    Returns
    -------
    list of str
        One sentence per pair of overlapping parts (empty when none).
    """
    out = []
    for line in network.lines:
        for a in range(len(line.parts)):
            for b in range(a + 1, len(line.parts)):
                pa, pb = line.parts[a], line.parts[b]
                s = np.arange(0.0, pa.length_m, 5.0)
                lat, lon, _ = pa.position_at(s)
                proj = pb.project(lat, lon)
                near = (np.abs(np.asarray(proj.offset_m, float)) <= within_m) & ~np.asarray(
                    proj.clamped, bool)  # fmt: skip
                overlap = 5.0 * float(near.sum())
                if overlap > min_overlap_m:
                    out.append(
                        f"line {line.line_id}: parts {a + 1} and {b + 1} lie on each other over "
                        f"about {overlap:.0f} m (the same track drawn twice in the network "
                        "file?): both are processed and counted; keep one of the pieces"
                    )
    return out


def _some(names: Sequence[str], n: int = 20) -> str:
    more = f" and {len(names) - n} more" if len(names) > n else ""
    return ", ".join(names[:n]) + more


def _id_key(p: Path, feats: list[tuple[int, JsonDict, JsonDict]], id_key: str | None) -> str:
    """The property every line feature holds its line id in; refused with the first feature
    lacking it."""
    candidates = (id_key,) if id_key is not None else ID_KEYS
    for key in candidates:
        lacking = [(i, pr) for i, pr, _ in feats if pr.get(key) in (None, "")]
        if not lacking:
            return key
        if id_key is not None or len(lacking) < len(feats):
            i, pr = lacking[0]
            raise TrackMapError(
                f"{p}: {feature_label(i, pr)} has no line id (property {key!r}, which "
                f"{len(feats) - len(lacking)} other line features have); give every line "
                f"feature its line's id in {key!r}"
            )
    raise TrackMapError(
        f"{p}: no property names the lines (tried {', '.join(ID_KEYS)}); give every line "
        "feature a 'line_id' property (or name the property: id_key=..., command line: "
        "--id-key)"
    )


def _matches(props: Mapping[str, Any], where: Mapping[str, object] | None) -> bool:
    for k, want in (where or {}).items():
        if want is None:
            if k in props:
                return False
        elif str(props.get(k)) != str(want):
            return False
    return True


def _reference_track(
    group: list[tuple[int, JsonDict, JsonDict]], track: str | None
) -> tuple[list[tuple[int, JsonDict, JsonDict]], list[tuple[int, JsonDict, JsonDict]]]:
    """The features of the line's reference track, and those of its other tracks."""
    names = sorted({str(pr.get(TRACK_KEY, "") or "") for _, pr, _ in group})
    if track is not None:
        pick = track
    else:
        pick = next((t for t in TRACK_PREFERENCE if t in names), names[0])
    chosen = [x for x in group if str(x[1].get(TRACK_KEY, "") or "") == pick]
    others = [x for x in group if str(x[1].get(TRACK_KEY, "") or "") != pick]
    return chosen, others


def _components(parts: Sequence[Part], max_gap_m: float) -> list[list[int]]:
    """Groups of parts whose ends meet within ``max_gap_m`` (transitively), in file order."""
    first = parts[0].coords[0]
    frame = LocalFrame(float(first[1]), float(first[0]))
    ends = np.array([[p.coords[0, :2], p.coords[-1, :2]] for p in parts]).reshape(-1, 2)
    enu = frame.to_enu(ends[:, 1], ends[:, 0])[:, :2]
    near = np.linalg.norm(enu[:, None] - enu[None], axis=-1) <= max_gap_m
    n = len(parts)
    label = list(range(n))

    def root(k: int) -> int:
        while label[k] != k:
            label[k] = label[label[k]]
            k = label[k]
        return k

    for a, b in zip(*np.nonzero(near), strict=True):
        ra, rb = root(int(a) // 2), root(int(b) // 2)
        if ra != rb:
            label[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(root(k), []).append(k)
    return sorted(groups.values(), key=lambda g: g[0])


def _line_parts(
    p: Path,
    line_id: str,
    track_name: str,
    chosen: list[tuple[int, JsonDict, JsonDict]],
    max_gap_m: float,
    tolerance_m: float,
    attribution: str,
) -> tuple[tuple[TrackMap, ...], list[str]]:
    """The track maps of the connected parts of one line's reference track, and the pieces
    left out for having no length."""
    pieces = checked_parts(p, chosen)
    span = [float(np.ptp(q.coords[:, :2], axis=0).max()) for q in pieces]
    empty = [q.label for q, d in zip(pieces, span, strict=True) if d == 0.0]
    pieces = [q for q, d in zip(pieces, span, strict=True) if d > 0.0]
    if not pieces:
        raise TrackMapError(f"{p}: line {line_id}: every piece has zero length; fix the file")
    comps = _components(pieces, max_gap_m)
    out = []
    label = f"line {line_id}" + (f" track {track_name}" if track_name else "")
    for k, comp in enumerate(comps, start=1):
        sub = [pieces[j] for j in comp]
        first = sub[0].coords[0]
        frame = LocalFrame(float(first[1]), float(first[0]))
        try:
            order = chain_all(sub, frame, max_gap_m, p)
        except TrackMapError as exc:
            raise TrackMapError(
                f"{label}: its pieces branch (three ends meet) and make no single polyline "
                f"({exc}); select one track (track=, where=) or fix the file"
            ) from None
        coords, tunnels = concatenate_parts(sub, order)
        has_h = all(sub[j].coords.shape[1] >= 3 for j, _ in order)
        h = coords[:, 2] if has_h else np.zeros(len(coords))
        name = label + (f" part {k}" if len(comps) > 1 else "")
        tf = TrackFile(
            p, coords[:, 1], coords[:, 0], h, name=name, source=p.name,
            attribution=attribution, tolerance_m=tolerance_m, tunnel_spans=tunnels,
        )  # fmt: skip
        try:
            out.append(TrackMap.from_track_file(tf))
        except TrackMapError as exc:
            raise TrackMapError(f"{label}: {exc}") from None
    return tuple(out), empty
