"""Track map files: GeoJSON (LineString / MultiLineString, WGS84) and CSV of lat/lon[/h].

GeoJSON lines are chained end to start (parts reversed where needed) into one polyline; a file
holding several tracks needs a selector (``track=`` or ``where=``). Kilometre posts (Point
features with a ``km_m`` property, or OpenStreetMap ``railway=milestone`` nodes) and tunnel
tags (OpenStreetMap ``tunnel=*``) are kept as metadata on the :class:`~predisat.track.map.TrackMap`.
See ``docs/track-map.md``.
"""

from __future__ import annotations

import csv
import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from predisat.atomic import write_bytes_atomic
from predisat.geodesy import WGS84, LocalFrame, unwrap_lon_deg, wrap_lon_deg
from predisat.jsontypes import JsonDict
from predisat.readonly import freeze_array_fields
from predisat.track.chain import Part, chain_all, chain_longest, concatenate_parts
from predisat.track.errors import TrackMapError
from predisat.track.posts import KilometrePost, points_as_posts, project_posts
from predisat.track.stations import Station, points_as_stations

if TYPE_CHECKING:
    from predisat.track.map import TrackMap

__all__ = [
    "MAX_VERTEX_SPACING_M",
    "NAME_KEYS",
    "TrackFile",
    "attribution_of",
    "checked_parts",
    "feature_label",
    "geojson_features",
    "geojson_in_lonlat",
    "kilometre_posts_from_sections",
    "parse_csv_track",
    "parse_geojson_track",
    "sniff_format",
    "write_geojson",
]

NAME_KEYS = ("trackname", "trackcode", "name", "ref", "id", "@id")
"""Feature properties that ``track=`` is matched against (Infrabel, OpenStreetMap, generic)."""
_ID_KEYS = ("id", "@id")  # feature numbers: a match on them alone may be another line's number
_LABEL_KEYS = tuple(k for k in NAME_KEYS if k not in _ID_KEYS)  # the names proper

_OSM_ATTRIBUTION = (
    "© OpenStreetMap contributors, ODbL 1.0 (https://www.openstreetmap.org/copyright)"
)


def attribution_of(members: Mapping[str, Any]) -> str:
    """The attribution a GeoJSON file's top-level ``members`` ask for: its ``attribution``,
    or OpenStreetMap's (ODbL) when its ``copyright`` names OpenStreetMap (overpass exports);
    "" when neither."""
    said = str(members.get("attribution", "") or "")
    if not said and "openstreetmap" in str(members.get("copyright", "")).lower():
        said = _OSM_ATTRIBUTION
    return said


@dataclass(frozen=True)
class TrackFile:
    """What a track map file says: the chained source vertices and the metadata.

    :meth:`predisat.track.map.TrackMap.from_geojson` and ``from_csv`` build the track map from
    it (smooth fit, chainage direction, kilometre posts and tunnels on the fitted axis).

    Attributes
    ----------
    path : Path
    lat_deg, lon_deg, h_m : ndarray, shape (n,)
        Source vertices in file order after chaining (WGS84, ellipsoidal metres).
    name, source, attribution : str
    tolerance_m : float
    vertical_tolerance_m : float or None
    posts : list of (km_m, label, [lon, lat(, h)])
        Kilometre posts as found in the file (:func:`predisat.track.posts.points_as_posts`).
    tunnel_spans, bridge_spans : list of (int, int)
        Vertex index spans of tunnel and bridge parts.
    stations : list of Station
        Named places found in the file (:func:`predisat.track.stations.points_as_stations`).
    reverse : bool
        Chainage asked to run against the vertex order (``reverse=True``).
    vertex_order : bool
        The file says its chainage runs in vertex order (member ``"chainage": "vertex order"``,
        written by :func:`write_geojson`): kilometre posts that fall along it do not turn it.
    max_post_offset_m : float
        Posts farther than this from the track are ignored.
    """

    path: Path
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    name: str
    source: str
    attribution: str = ""
    tolerance_m: float = 1.0
    vertical_tolerance_m: float | None = None
    posts: list[tuple[float, str, NDArray]] = field(default_factory=list)
    tunnel_spans: list[tuple[int, int]] = field(default_factory=list)
    bridge_spans: list[tuple[int, int]] = field(default_factory=list)
    stations: list[Station] = field(default_factory=list)
    reverse: bool = False
    vertex_order: bool = False
    tunnels_chainage_m: list[tuple[float, float]] = field(default_factory=list)
    bridges_chainage_m: list[tuple[float, float]] = field(default_factory=list)
    chainage_length_m: float | None = None
    max_post_offset_m: float = 50.0

    def __post_init__(self) -> None:
        freeze_array_fields(self)


def sniff_format(path: str | Path) -> Literal["geojson", "csv"]:
    """``"geojson"`` when the file's first non-blank character opens a JSON object, else
    ``"csv"``: by content, so that a ``.txt`` or ``.json`` file is read for what it is."""
    with open(path, "rb") as fh:
        head = fh.read(4096).lstrip(b"\xef\xbb\xbf \t\r\n")
    if not head:  # empty: nothing to tell by; the name says what was meant
        return "geojson" if str(path).lower().endswith((".geojson", ".json")) else "csv"
    return "geojson" if head[:1] in (b"{", b"[") else "csv"


# ---------------------------------------------------------------------- GeoJSON


def _read_utf8(path: Path) -> str:
    """The text of a track file; TrackMapError when it is not UTF-8, naming the line."""
    data = path.read_bytes()
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise TrackMapError(
            f"{path}, line {line}: not UTF-8 text (byte {exc.start}: {exc.reason}); save the "
            "track map as UTF-8"
        ) from None


def _load_json(path: Path) -> Any:
    if not path.is_file():
        raise TrackMapError(f"{path}: no such file")
    text = _read_utf8(path)
    if not text.strip():
        raise TrackMapError(f"{path}: the file is empty; expected a GeoJSON FeatureCollection")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TrackMapError(
            f"{path}: not valid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno}); "
            "expected a GeoJSON FeatureCollection"
        ) from None
    return geojson_in_lonlat(doc, path)


def geojson_in_lonlat(doc: Any, path: Path) -> Any:
    """``doc`` with its coordinates turned into WGS84 [lon, lat] when it names another CRS
    in the legacy (GeoJSON 2008) ``crs`` member: exports of national grids (Lambert 72,
    EPSG:31370) still carry it, and a user trial's was read as degrees and told to swap them.
    RFC 7946 files have no ``crs``: returned as they are."""
    crs_doc = doc.get("crs") if isinstance(doc, dict) else None
    props = (crs_doc.get("properties") or {}) if isinstance(crs_doc, dict) else {}
    kind = str(crs_doc.get("type", "")).lower() if isinstance(crs_doc, dict) else ""
    name = props.get("name")
    if kind == "epsg" and props.get("code") is not None:  # the GeoJSON 2008 draft's form
        name = f"EPSG:{props['code']}"
    elif kind == "link" or (crs_doc is not None and not name):
        # ignored, a grid's metres were read as degrees and told to swap (a GIS user trial)
        raise TrackMapError(
            f"{path}: its crs member ({json.dumps(crs_doc)[:120]}) cannot be read; name the "
            "CRS: \"crs\": {\"type\": \"name\", \"properties\": {\"name\": "
            "\"EPSG:31370\"}} (or export the file in WGS84, RFC 7946)"
        )
    if not name:
        return doc
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError
    from pyproj.transformer import TransformerGroup

    try:
        crs = CRS.from_user_input(str(name))
    except CRSError:
        raise TrackMapError(
            f"{path}: its crs member names {name!r}, which pyproj does not know; give the file "
            "in WGS84 longitude and latitude (RFC 7946)"
        ) from None
    if crs.equals(CRS.from_epsg(4326), ignore_axis_order=True):
        return doc
    vertical = [c for c in crs.sub_crs_list if c.is_vertical] if crs.is_compound else []
    if vertical and not _has_heights(doc):  # nothing to convert: the plane part alone
        crs, vertical = crs.sub_crs_list[0], []
    if vertical:
        # heights above a geoid: the track map needs ellipsoidal ones (the locator meets the
        # satellites' hyperbolae on the track in 3-D; 45 m of geoid moved fixes by tens of m)
        group = TransformerGroup(crs, "EPSG:4979", always_xy=True)  # best available first
        to_3d = group.transformers[0] if group.transformers else None
        if to_3d is None or "ballpark vertical" in to_3d.description.lower():
            grids = sorted({
                g.short_name for op in group.unavailable_operations for g in op.grids
                if not g.available
            })  # fmt: skip
            need = (f" (PROJ lacks {', '.join(grids)}: `pyproj sync --file NAME` for each, "
                    "or PROJ's projsync; network access needed)" if grids else "")  # fmt: skip
            raise TrackMapError(
                f"{path}: its heights are in {vertical[0].name} (above the geoid, not the "
                f"WGS84 ellipsoid) and PROJ cannot turn them into ellipsoidal heights{need}; "
                "install the grid, or give the file in WGS84 longitude, latitude and "
                "ellipsoidal height"
            )
        horizontal = crs.sub_crs_list[0]
    else:
        to_3d, horizontal = None, crs
        if crs.is_projected and _has_heights(doc):
            # a national grid's heights are usually above its geoid, not the ellipsoid (a
            # real-data trial: Lambert 72 with Ostend heights read 45 m low, no word)
            warnings.warn(
                f"{path}: its crs {name!r} names no height datum; its heights are taken as "
                "WGS84 ellipsoidal heights. If they are above sea level, name the compound CRS "
                "(e.g. EPSG:31370+5710 for Lambert 72 + Ostend height) so that they are "
                "converted",
                stacklevel=2,
            )
    to_lonlat = Transformer.from_crs(horizontal, "EPSG:4326", always_xy=True)

    def turn(c: Any) -> Any:
        if isinstance(c, list) and c and isinstance(c[0], (int, float)):
            if to_3d is not None and len(c) > 2:
                lon, lat, h = to_3d.transform(float(c[0]), float(c[1]), float(c[2]))
                return [lon, lat, h, *c[3:]]
            lon, lat = to_lonlat.transform(float(c[0]), float(c[1]))
            return [lon, lat, *c[2:]]
        return [turn(x) for x in c] if isinstance(c, list) else c

    def walk(node: Any) -> Any:
        if isinstance(node, dict):
            return {k: (turn(v) if k == "coordinates" else walk(v)) for k, v in node.items()
                    if k != "crs"}  # fmt: skip
        return [walk(x) for x in node] if isinstance(node, list) else node

    return walk(doc)


def _has_heights(node: Any) -> bool:
    """Whether any coordinate of a GeoJSON document has a third value (a height)."""
    if isinstance(node, dict):
        return any(_has_heights(v) for k, v in node.items() if k != "crs")
    if isinstance(node, list):
        if node and isinstance(node[0], (int, float)):
            return len(node) > 2
        return any(_has_heights(x) for x in node)
    return False


def _features(doc: Any, path: Path) -> list[dict[str, Any]]:
    if not isinstance(doc, dict) or "type" not in doc:
        raise TrackMapError(f"{path}: not a GeoJSON object (no 'type' member)")
    kind = doc["type"]
    if kind == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list):
            raise TrackMapError(f"{path}: FeatureCollection without a 'features' list")
        return [f for f in feats if isinstance(f, dict)]
    if kind == "Feature":
        return [doc]
    if kind in ("LineString", "MultiLineString", "Point", "GeometryCollection"):
        return [{"type": "Feature", "properties": {}, "geometry": doc}]
    raise TrackMapError(f"{path}: unsupported GeoJSON type {kind!r}")


def feature_label(i: int, props: Mapping[str, Any]) -> str:
    """How error messages name feature ``i``: ``"feature 3 (trackname=A, trackcode=L 144_1)"``."""
    names = [f"{k}={props[k]}" for k in NAME_KEYS if k in props]
    return f"feature {i}" + (f" ({', '.join(names[:2])})" if names else "")


def _check_lonlat(coords: NDArray, where: str, path: Path, bbox: Sequence[float] | None) -> None:
    if coords.ndim != 2 or coords.shape[1] < 2 or not np.all(np.isfinite(coords)):
        raise TrackMapError(
            f"{path}: {where} has malformed coordinates; expected [[lon, lat(, h)], ...]"
        )
    lon, lat = coords[:, 0], coords[:, 1]
    if np.any(np.abs(lat) > 90.0) or np.any(np.abs(lon) > 180.0):
        k = int(np.flatnonzero((np.abs(lat) > 90.0) | (np.abs(lon) > 180.0))[0])
        # a longitude past 180 with a valid latitude is a line unwrapped across the
        # antimeridian, not swapped coordinates (a geometry review: told to swap them)
        if np.all(np.abs(coords[:, :2]) > 360.0):  # metres of a grid, not degrees swapped
            fix = ("the coordinates are metres of a projection (Belgian Lambert 72 or 2008, "
                   "UTM) and the file names no crs: add the crs member of its own CRS, e.g. "
                   "\"crs\": {\"type\": \"name\", \"properties\": {\"name\": "
                   "\"EPSG:31370\"}} for Lambert 72, EPSG:3812 for Lambert 2008, or export "
                   "it in WGS84")  # fmt: skip
        elif abs(lat[k]) <= 90.0 and abs(lon[k]) <= 540.0:
            fix = "longitudes must lie within [-180, 180]: wrap it (subtract 360)"
        else:
            fix = "GeoJSON coordinates are [lon, lat] (longitude first): swap them"
        raise TrackMapError(
            f"{path}: {where} vertex {k} = {coords[k, :2].tolist()} is not a valid "
            f"[lon, lat]; {fix}"
        )
    if bbox is not None:
        lon0, lat0, lon1, lat1 = bbox
        inside = (lon >= lon0) & (lon <= lon1) & (lat >= lat0) & (lat <= lat1)
        if not np.all(inside):
            swapped = (lat >= lon0) & (lat <= lon1) & (lon >= lat0) & (lon <= lat1)
            k = int(np.flatnonzero(~inside)[0])
            hint = (
                "the coordinates look swapped: GeoJSON coordinates are [lon, lat]"
                if np.all(swapped)
                else "check the file or the expected_bbox"
            )
            raise TrackMapError(
                f"{path}: {where} vertex {k} = {coords[k, :2].tolist()} lies outside the "
                f"expected bbox {list(bbox)} (lon_min, lat_min, lon_max, lat_max); {hint}"
            )


def geojson_features(path: str | Path) -> tuple[JsonDict, list[JsonDict]]:
    """The top-level members and the features of a GeoJSON file (a bare geometry or Feature is
    one feature).

    Raises
    ------
    TrackMapError
        Missing, empty, non-UTF-8 or invalid JSON file, or not a GeoJSON object (named).
    """
    p = Path(path)
    doc = _load_json(p)
    feats = _features(doc, p)
    return (doc if isinstance(doc, dict) else {}), feats


def checked_parts(
    path: str | Path,
    features: Sequence[tuple[int, JsonDict, JsonDict]],
    expected_bbox: Sequence[float] | None = None,
) -> list[Part]:
    """The checked parts of line features ``(feature index, properties, geometry)``: numeric
    ``[lon, lat(, h)]`` vertices, valid coordinates (not swapped), no 50 km jump, lengths
    agreeing with a declared ``length``; at least one part of two vertices or more.

    Raises
    ------
    TrackMapError
        Naming the file, the feature and part, and the fix.
    """
    return _line_parts(list(features), expected_bbox, Path(path))


#: Consecutive vertices further apart than this are refused: no railway map draws 50 km of
#: track as one straight chord, while one mistyped digit of a coordinate moves a vertex by
#: hundreds of km (and the smooth fit of such a "track" takes minutes and gigabytes).
MAX_VERTEX_SPACING_M = 50_000.0
def _far_vertex(lat_deg: NDArray, lon_deg: NDArray) -> tuple[int, float] | None:
    """The first pair ``(k, distance_m)`` of consecutive vertices k, k + 1 further apart than
    :data:`MAX_VERTEX_SPACING_M` on the WGS84 ellipsoid, or None."""
    d = np.asarray(WGS84.inv(lon_deg[:-1], lat_deg[:-1], lon_deg[1:], lat_deg[1:])[2], float)
    far = np.flatnonzero(d > MAX_VERTEX_SPACING_M)
    return (int(far[0]), float(d[far[0]])) if far.size else None


_LENGTH_KEYS = ("length_m", "length")


def _check_declared_length(
    props: Mapping[str, Any], parts: Sequence[NDArray], where: str, path: Path
) -> None:
    """Catch [lat, lon] files that are still valid numbers, from a declared feature length.

    Infrabel and other infrastructure managers publish each track's length; swapping latitude
    and longitude changes the geodesic length by a few per cent (the degree of longitude
    shrinks with latitude) while a faithful file agrees to well under 1 %.
    """
    declared = next((props[k] for k in _LENGTH_KEYS if k in props), None)
    if not parts or not isinstance(declared, int | float) or not declared > 0:
        return
    direct = sum(float(WGS84.line_length(c[:, 0], c[:, 1])) for c in parts)
    swapped = sum(
        float(WGS84.line_length(c[:, 1], c[:, 0])) for c in parts if np.all(np.abs(c[:, 0]) <= 90)
    )
    rel_direct = abs(direct - declared) / declared
    if rel_direct > 0.01 and abs(swapped - declared) / declared < rel_direct / 4:
        raise TrackMapError(
            f"{path}: {where}: the coordinates give {direct:.0f} m but the feature declares a "
            f"length of {declared:.0f} m, which they give when read as [lat, lon]: the "
            "coordinates look swapped; GeoJSON coordinates are [lon, lat] (longitude first)"
        )


def _matches(
    props: Mapping[str, Any], track: str | None, where: Mapping[str, object] | None
) -> bool:
    if track is not None and not any(str(props.get(k)) == track for k in NAME_KEYS):
        return False
    for key, want in (where or {}).items():
        if want is None:
            if key in props:
                return False
        elif str(props.get(key)) != str(want):
            return False
    return True


def _numbers(vertex: Any) -> bool:
    return isinstance(vertex, list) and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) for c in vertex
    )


def _refuse_id_only_match(
    selected: Sequence[tuple[int, dict[str, Any], dict[str, Any]]], track: str | None, path: Path
) -> None:
    """``track="144"`` must not pick, without a word, the feature numbered 144 of another line:
    a feature matched only by its number while it has a name is refused."""
    if track is None:
        return
    for i, props, _ in selected:
        if any(str(props.get(k)) == track for k in _LABEL_KEYS):
            continue
        if any(k in props for k in _LABEL_KEYS):
            key = next(k for k in _ID_KEYS if str(props.get(k)) == track)
            raise TrackMapError(
                f"{path}: track={track!r} matches only the {key} of {feature_label(i, props)}, "
                f"another name; give the track's name as track=, or "
                f"where={{{key!r}: {props[key]!r}}} to select that feature by its number"
            )


def parse_geojson_track(
    path: str | Path,
    track: str | None = None,
    h_m: float = 0.0,
    *,
    where: Mapping[str, object] | None = None,
    chain: Literal["all", "longest"] = "all",
    max_gap_m: float = 2.0,
    max_turn_deg: float = 30.0,
    reverse: bool = False,
    expected_bbox: Sequence[float] | None = None,
    tolerance_m: float | None = None,
    max_post_offset_m: float = 50.0,
    name: str | None = None,
    source: str | None = None,
    attribution: str | None = None,
) -> TrackFile:
    """Read a track axis from a GeoJSON file (WGS84 ``[lon, lat(, h)]``); see
    :meth:`predisat.track.map.TrackMap.from_geojson`, which builds the track map from it.

    Parameters
    ----------
    path : str or Path
    track : str, optional
        Select the features whose ``trackname``, ``trackcode``, ``name``, ``ref`` or ``id``
        equals this (e.g. ``"A"`` or ``"L 144_1"``). Needed when the file holds several named
        tracks.
    h_m : float
        Ellipsoidal height used when the coordinates carry none (default 0).
    where : mapping, optional
        Further property filters, ``{key: value}``; a value of None requires the key to be
        absent (e.g. ``{"usage": "main", "service": None}`` for OpenStreetMap main lines).
    chain : {"all", "longest"}
        ``"all"``: every selected part must join into one line (gaps above ``max_gap_m`` are
        errors). ``"longest"``: keep the longest drivable chain (joints within ``max_gap_m``,
        turning at most ``max_turn_deg``) through a network of ways, as in OpenStreetMap.
    max_gap_m : float
        Largest gap allowed between the end of one part and the start of the next.
    max_turn_deg : float
        Largest change of direction at a joint for ``chain="longest"``.
    reverse : bool
        Reverse the direction of chainage. By default chainage increases with the kilometre
        posts when the file has at least two, else along the first selected part.
    expected_bbox : (lon_min, lat_min, lon_max, lat_max), optional
        Reject vertices outside it (catches swapped coordinates that are still valid).
    tolerance_m : float, optional
        Source tolerance for the smooth fit (see :class:`~predisat.track.map.TrackMap`); by
        default the file's ``tolerance_m`` member (a map written by :func:`write_geojson`),
        else 1 m.
    max_post_offset_m : float
        Kilometre-post points farther than this from the track are ignored.
    name, source, attribution : str, optional
        Override what the file says (``name``/``source``/``attribution`` members written by
        :func:`write_geojson`; OpenStreetMap's copyright notice).

    Raises
    ------
    TrackMapError
        Naming the file, the feature/part and the fix.
    """
    path = Path(path)
    doc = _load_json(path)
    lines, points = _lines_and_points(_features(doc, path), path)
    selected = _select_lines(lines, track, where, chain, path)
    parts = _line_parts(selected, expected_bbox, path)

    first = parts[0].coords[0]
    frame = LocalFrame(float(first[1]), float(first[0]))
    if chain == "all":
        try:
            order = chain_all(parts, frame, max_gap_m, path)
        except TrackMapError as exc:
            raise TrackMapError(str(exc) + _osm_chain_hint(selected, where)) from None
    elif chain == "longest":
        order = chain_longest(parts, frame, max_gap_m, max_turn_deg, path)
    else:
        raise TrackMapError(f"chain must be 'all' or 'longest', got {chain!r}")

    coords, tunnel_spans = concatenate_parts(parts, order)
    _, bridge_spans = concatenate_parts(parts, order, "bridge")
    has_h = all(parts[k].coords.shape[1] >= 3 for k, _ in order)
    lon, lat = coords[:, 0], coords[:, 1]
    h = coords[:, 2] if has_h else np.full(len(coords), float(h_m))

    posts_raw = points_as_posts(points)
    used = {parts[k].feature for k, _ in order}  # the name lists the chained features only
    chained = [x for x in selected if x[0] in used]
    _warn_mixed_status(chained, [parts[k] for k, _ in order], frame, path)
    members = doc if isinstance(doc, dict) else {}
    if attribution is None:
        attribution = attribution_of(members)
    tol = (float(tolerance_m) if tolerance_m is not None
           else float(members["tolerance_m"]) if "tolerance_m" in members else 1.0)  # fmt: skip
    return TrackFile(
        path, lat, lon, h,
        name=name or _selected_name(str(members.get("name") or path.stem), track, chained),
        source=source or str(members.get("source") or path.name),
        attribution=attribution, tolerance_m=tol, posts=posts_raw,
        tunnel_spans=list(tunnel_spans), bridge_spans=list(bridge_spans),
        stations=points_as_stations(points), reverse=reverse,
        vertex_order=members.get("chainage") == _VERTEX_ORDER,
        max_post_offset_m=max_post_offset_m,
        tunnels_chainage_m=_chainage_spans(members, "tunnels_m", path),
        chainage_length_m=(float(members["chainage_length_m"])
                           if isinstance(members.get("chainage_length_m"), int | float)
                           else None),
        bridges_chainage_m=_chainage_spans(members, "bridges_m", path),
    )  # fmt: skip


def _chainage_spans(members: Mapping[str, Any], key: str, path: Path) -> list[tuple[float, float]]:
    """Tunnel or bridge chainage intervals written by :func:`write_geojson` (members
    ``tunnels_m``, ``bridges_m``, in the vertex order's chainage), else none."""
    if key not in members:
        return []
    if members.get("chainage") != _VERTEX_ORDER:
        # the intervals mean nothing in another chainage: dropped in silence, the tunnels
        # were lost (a review)
        raise TrackMapError(
            f"{path}: member {key!r} is in the vertex order's chainage, but the file lacks "
            f'"chainage": "{_VERTEX_ORDER}" (as write_geojson writes it): restore it, or '
            "remove the member"
        )
    try:
        spans = [(float(a), float(b)) for a, b in members[key]]
    except (TypeError, ValueError):
        raise TrackMapError(f"{path}: member {key!r} must be a list of [start_m, end_m] "
                            "chainage pairs") from None  # fmt: skip
    if any(not (np.isfinite(a) and np.isfinite(b) and a <= b) for a, b in spans):
        raise TrackMapError(f"{path}: member {key!r} holds a pair that is not a finite "
                            "[start_m, end_m] with start <= end")  # fmt: skip
    return spans


def _mm(x: float, rnd: Any) -> float:
    return float(rnd(round(x * 1000.0, 6)) / 1000.0)


def _selected_name(base: str, track: str | None, selected: list[_LineFeature]) -> str:
    """The file's name, with the track chosen in it (``--track-name``) and that track's other
    names (``trackname``, ``trackcode``, ...): ``"line144, track A (L 144_1)"``; the file's
    name alone when it already names that track (a survey's track.geojson is named after the
    track map written into it, and the survey selects it by that name)."""
    if track is None or track == base:
        return base
    keys = ("trackname", "trackcode", "name", "ref")
    others = sorted(
        {str(p[k]) for _, p, _ in selected for k in keys if p.get(k) not in (None, "")} - {track}
    )
    if len(others) > 6:  # a longest chain through a network: not every line's code in the name
        others = [*others[:6], f"+{len(others) - 6} more"]
    return f"{base}, track {track}" + (f" ({', '.join(others)})" if others else "")


_LineFeature = tuple[int, JsonDict, JsonDict]  # feature index, properties, geometry


# properties that say whether a line is in service: Infrabel's ``status`` ("En activité",
# "Hors service") and OpenStreetMap's ``railway`` ("rail", "disused", "abandoned"); not
# ``usage`` (main, branch: a use, and a review found it warned on a line all in service)
_STATUS_KEYS = ("status", "railway")


def _warn_mixed_status(
    chained: list[_LineFeature], parts: list[Part], frame: LocalFrame, path: Path
) -> None:
    """Warn when the features joined into the track differ in a status property: one name
    (Infrabel's track B of line 144) can hold a line in service and one out of service, and a
    survey or a locator run on the joined line would mix them without a word."""
    length_m: dict[int, float] = {}
    for part in parts:
        enu = frame.to_enu(part.coords[:, 1], part.coords[:, 0])[:, :2]
        step_m = float(np.hypot(*np.diff(enu, axis=0).T).sum()) if len(enu) > 1 else 0.0
        length_m[part.feature] = length_m.get(part.feature, 0.0) + step_m
    for key in _STATUS_KEYS:
        values: dict[str, float] = {}
        for i, props, _ in chained:
            value = str(props.get(key, "(none)"))
            values[value] = values.get(value, 0.0) + length_m.get(i, 0.0)
        if len(values) > 1 and any(key in props for _, props, _ in chained):
            shares = ", ".join(f"{v!r} {m:,.0f} m" for v, m in sorted(values.items()))
            warnings.warn(
                f"{path}: the line joins features of different {key} ({shares}); keep one "
                f"with where={{{key!r}: VALUE}} (command line: --where \"{key}=VALUE\", with "
                "--chain longest if its pieces do not join), or check that the whole line is "
                "the one you mean",
                stacklevel=3,
            )


def _lines_and_points(
    feats: list[JsonDict], path: Path
) -> tuple[list[_LineFeature], list[tuple[JsonDict, NDArray]]]:
    """The line features and the points (properties, ``[lon, lat(, h)]``) of a GeoJSON file."""
    lines: list[_LineFeature] = []
    points: list[tuple[JsonDict, NDArray]] = []
    for i, f in enumerate(feats):
        geom = f.get("geometry") or {}
        props = f.get("properties") or {}
        if geom.get("type") in ("LineString", "MultiLineString"):
            lines.append((i, props, geom))
        elif geom.get("type") == "Point":
            points.append((props, np.asarray(geom.get("coordinates", []), float)))
    if not lines:
        raise TrackMapError(
            f"{path}: no LineString or MultiLineString feature; a track map needs the track "
            "axis as a line"
        )
    return lines, points


def _select_lines(
    lines: list[_LineFeature],
    track: str | None,
    where: Mapping[str, object] | None,
    chain: str,
    path: Path,
) -> list[_LineFeature]:
    """The line features selected by ``track`` and ``where``: at least one, of one track
    unless ``chain="longest"``."""
    selected = [x for x in lines if _matches(x[1], track, where)]
    _refuse_id_only_match(selected, track, path)
    if not selected:
        avail = sorted({f"{k}={p[k]}" for _, p, _ in lines for k in _LABEL_KEYS if k in p})
        raise TrackMapError(
            f"{path}: no line feature matches track={track!r} where={dict(where or {})}; "
            + _no_match_hint(lines, track, where, avail)
        )
    if track is None and chain == "all":
        for key in ("trackname", "name"):
            names = sorted({str(p[key]) for _, p, _ in selected if key in p})
            if len(names) > 1:
                raise TrackMapError(
                    f"{path}: the file holds several tracks ({key}: {', '.join(names[:20])}); "
                    "choose one with track=... (command line: --track-name)"
                    + _shared_name_hint(selected, key, len(names))
                )
    return selected


def _no_match_hint(
    lines: list[_LineFeature],
    track: str | None,
    where: Mapping[str, object] | None,
    avail: list[str],
) -> str:
    """What the file does hold, nearest the user's guess first: the first 20 names in
    alphabetical order hid line 144 among Infrabel's 405 track codes, a mistyped key
    (``--where line=144``) was not said absent, and an OpenStreetMap file without line names
    answered "(no names)" without the keys that select its lines (a user trial)."""
    import difflib

    keys = sorted({k for _, p, _ in lines for k in p})
    missing = [k for k, v in (where or {}).items() if v is not None and k not in keys]
    if missing:
        return (f"no line feature has the propert{'ies' if len(missing) > 1 else 'y'} "
                f"{', '.join(map(repr, missing))}; their properties: "
                f"{', '.join(keys[:40])}")  # fmt: skip
    if avail:
        values = {a.split("=", 1)[1]: a for a in avail}
        near: list[str] = []
        if track is not None:
            near = [a for v, a in values.items() if track.lower() in v.lower()]
            near += [values[v] for v in difflib.get_close_matches(track, list(values), 5, 0.6)]
        shown = list(dict.fromkeys([*near[:10], *avail]))[:20]
        more = f", ... ({len(avail)} in all)" if len(avail) > len(shown) else ""
        return f"available{' (nearest first)' if near else ''}: {', '.join(shown)}{more}"
    few = []
    first = ("usage", "service", "railway:track_ref", "passenger_lines", "status")  # OSM, Infrabel
    for k in sorted(keys, key=lambda k: (k not in first, first.index(k) if k in first else 0, k)):
        if k in _ID_KEYS:
            continue
        vals = sorted({str(p[k]) for _, p, _ in lines if k in p})
        if 1 < len(vals) <= 12 or (len(vals) == 1 and len(lines) > 1):
            few.append(f"{k}={'|'.join(vals[:6])}{'|...' if len(vals) > 6 else ''}")
    return ("the lines carry no name; select them by their properties instead (--where "
            f"KEY=VALUE, KEY= for absent): {'; '.join(few[:12]) or '(none)'}")


def _osm_chain_hint(selected: list[_LineFeature], where: Mapping[str, object] | None) -> str:
    """For OpenStreetMap ways that could not be chained whole: the selection the docs give
    for a main line (a user trial: the error named the options, not their values)."""
    if where or not any("usage" in p or "service" in p for _, p, _ in selected):
        return ""
    return ("; for an OpenStreetMap extract the main line is usually "
            "where={'usage': 'main', 'service': None}, chain='longest' (command line: --where "
            "usage=main service= --chain longest)")


def _shared_name_hint(selected: list[_LineFeature], key: str, n_names: int) -> str:
    """When each ``key`` value (Infrabel's ``trackname`` A, B) is shared by many lines (the
    national file: 430 features, 4 tracknames), which key tells them apart, with an example:
    ``--track-name A`` chained track A of every line (a user trial)."""
    for other in ("trackcode", "ref", "name"):
        if other == key:
            continue
        codes = sorted({str(p[other]) for _, p, _ in selected if p.get(other) not in (None, "")})
        if len(codes) > n_names:
            _, first, _ = next(x for x in selected if x[1].get(other) not in (None, ""))
            more = f", ... ({len(codes)} in all)" if len(codes) > 8 else ""
            return (
                f"; each {key} is shared by several lines, {other} tells them apart "
                f"({', '.join(codes[:8])}{more}): track={str(first[other])!r} "
                f"(command line: --track-name '{first[other]}')"
            )
    return ""


def _line_parts(
    selected: list[_LineFeature], expected_bbox: Sequence[float] | None, path: Path
) -> list[Part]:
    """The parts (polylines of at least two vertices) of the selected line features, checked;
    at least one."""
    parts: list[Part] = []
    single: list[str] = []  # lines of one vertex, named if nothing else is left
    for i, props, geom in selected:
        label = feature_label(i, props)
        raw = geom.get("coordinates") or []
        seqs = [raw] if geom["type"] == "LineString" else list(raw)
        tunnel = str(props.get("tunnel", "no")).lower() not in ("no", "false", "0")
        bridge = str(props.get("bridge", "no")).lower() not in ("no", "false", "0")
        n_before = len(parts)
        for j, seq in enumerate(seqs):
            where_s = label if geom["type"] == "LineString" else f"{label} part {j}"
            coords = _part_coords(seq, where_s, path)
            if coords.size == 0:
                continue
            _check_lonlat(coords, where_s, path, expected_bbox)
            far = _far_vertex(coords[:, 1], coords[:, 0]) if len(coords) >= 2 else None
            if far is not None:
                k, d = far
                raise TrackMapError(
                    f"{path}: {where_s} vertices {k} and {k + 1} ({coords[k, :2].tolist()}, "
                    f"{coords[k + 1, :2].tolist()}) are {d / 1000:.0f} km apart (more than "
                    f"{MAX_VERTEX_SPACING_M / 1000:.0f} km): a mistyped coordinate? fix it"
                )
            if len(coords) >= 2:
                parts.append(Part(where_s, i, coords, tunnel, bridge))
            else:
                single.append(where_s)
        _check_declared_length(props, [p.coords for p in parts[n_before:]], label, path)
    if not parts:
        if single:
            raise TrackMapError(
                f"{path}: {_first(single)} {'has' if len(single) == 1 else 'have'} a single "
                "vertex; a track line needs at least two [lon, lat] points"
            )
        raise TrackMapError(f"{path}: the selected features have no coordinates (empty lines)")
    return parts


def _part_coords(seq: Any, where_s: str, path: Path) -> NDArray:  # Any: a JSON value
    """The vertices of one part as floats, shape (n, 2 or 3); JSON numbers only."""
    try:
        if not all(_numbers(v) for v in seq):  # "4.6" would pass np.asarray(float)
            raise ValueError
        sizes = {len(v) for v in seq}
        if len(sizes) > 1 and min(sizes) >= 2:
            # some vertices with a height, some without: the heights are left out and the
            # track's h_m taken, as for a 2-D file (docs/track-map.md)
            return np.asarray([v[:2] for v in seq], float)
        return np.asarray(seq, float)
    except (TypeError, ValueError):
        raise TrackMapError(
            f"{path}: {where_s} has malformed coordinates; expected [[lon, lat], ...] "
            "of numbers (JSON numbers, not strings)"
        ) from None


def kilometre_posts_from_sections(
    track: TrackMap,
    path: str | Path,
    *,
    step_m: float = 1000.0,
    max_offset_m: float = 50.0,
) -> list[KilometrePost]:
    """Kilometre posts on ``track`` from Infrabel-style line sections.

    Each section is a LineString with ``mfrom`` / ``mto`` kilometre references (metres) and
    ``ptcarfromname`` / ``ptcartoname`` place names. The kilometre reference runs linearly along
    the section's geodesic length; posts are placed at every multiple of ``step_m`` and at the
    section ends, and projected onto ``track`` (points off the track's ends are dropped).
    """
    doc = _load_json(Path(path))
    raw: list[tuple[float, str, NDArray]] = []
    for i, f in enumerate(_features(doc, Path(path))):
        props, geom = f.get("properties") or {}, f.get("geometry") or {}
        if geom.get("type") != "LineString" or "mfrom" not in props or "mto" not in props:
            continue
        c = np.asarray(geom["coordinates"], float)
        _check_lonlat(c, feature_label(i, props), Path(path), None)
        _, _, seg = WGS84.inv(c[:-1, 0], c[:-1, 1], c[1:, 0], c[1:, 1])
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        m0, m1 = float(props["mfrom"]), float(props["mto"])
        km_vertex = m0 + (m1 - m0) * cum / cum[-1]
        wanted = np.arange(np.ceil(min(m0, m1) / step_m), np.floor(max(m0, m1) / step_m) + 1)
        kms = np.concatenate([[m0, m1], wanted * step_m + 0.0])  # + 0.0: no "km -0.000"
        names = [str(props.get("ptcarfromname", "")), str(props.get("ptcartoname", ""))]
        order = np.argsort(km_vertex) if m1 < m0 else np.arange(len(km_vertex))
        lon = wrap_lon_deg(np.interp(kms, km_vertex[order], unwrap_lon_deg(c[order, 0])))
        lat = np.interp(kms, km_vertex[order], c[order, 1])
        for j, km in enumerate(kms):
            label = names[j] if j < 2 and names[j] else f"km {km / 1000.0:.3f}"
            raw.append((float(km), label, np.array([lon[j], lat[j]])))
    posts = project_posts(track, raw, max_offset_m)
    unique: dict[float, KilometrePost] = {}
    for p in posts:  # a section end is also the next section's start
        if p.km_m not in unique or (unique[p.km_m].label.startswith("km ") and p.label):
            unique[p.km_m] = p
    return sorted(unique.values(), key=lambda p: p.chainage_m)


_VERTEX_ORDER = "vertex order"


def write_geojson(track: TrackMap, path: str | Path) -> None:
    """Write a track map as GeoJSON that :meth:`TrackMap.from_geojson` reads back identically.

    The source vertices go in one LineString feature (with heights when any is non-zero),
    kilometre posts as Point features with ``km_m`` and ``label``, stations as Point features
    with ``station``; ``name``, ``source``,
    ``attribution`` and ``tolerance_m`` as members of the FeatureCollection, and ``"chainage":
    "vertex order"``: a map whose chainage runs against its kilometres (read with
    ``reverse=True``) would otherwise be turned back by its posts on reading (a user trial).
    """
    with_h = bool(np.any(track.h_m != 0.0))
    cols = [track.lon_deg, track.lat_deg] + ([track.h_m] if with_h else [])
    coords = [[round(float(v), 9) for v in row] for row in np.column_stack(cols)]
    feats: list[dict[str, Any]] = [
        {
            "type": "Feature",
            "properties": {"name": track.name, "length_m": round(track.length_m, 3)},
            "geometry": {"type": "LineString", "coordinates": coords},
        }
    ]
    if track.kilometre_posts:
        s = np.array([p.chainage_m for p in track.kilometre_posts])
        lat, lon, _ = track.position_at(s)
        for p, la, lo in zip(track.kilometre_posts, lat, lon, strict=True):
            feats.append(
                {
                    "type": "Feature",
                    "properties": {"km_m": p.km_m, "label": p.label},
                    "geometry": {
                        "type": "Point",
                        "coordinates": [round(float(lo), 9), round(float(la), 9)],
                    },
                }
            )
    for st in track.stations:
        feats.append(
            {
                "type": "Feature",
                "properties": {"station": st.name},
                "geometry": {
                    "type": "Point",
                    "coordinates": [round(st.lon_deg, 9), round(st.lat_deg, 9)],
                },
            }
        )
    doc = {
        "type": "FeatureCollection",
        "name": track.name,
        "source": track.source,
        "attribution": track.attribution,
        "tolerance_m": track.tolerance_m,
        "chainage": _VERTEX_ORDER,
        # tunnels and bridges (OpenStreetMap tunnel=* / bridge=* ways) are not in the single
        # LineString written above: kept as chainage intervals, read back by from_geojson
        # rounded outwards: a tunnel to the map's end stopped 0.4 mm short of it
        "tunnels_m": [[_mm(a, math.floor), _mm(b, math.ceil)] for a, b in track.tunnels_m],
        "bridges_m": [[_mm(a, math.floor), _mm(b, math.ceil)] for a, b in track.bridges_m],
        # the line the intervals were written for: a line edited since misplaces them
        "chainage_length_m": round(track.length_m, 3),
        "features": feats,
    }
    # atomic: an interrupted write must not leave half a map that a later command reads
    write_bytes_atomic(path, (json.dumps(doc, ensure_ascii=False, indent=1) + "\n").encode())


# ---------------------------------------------------------------------- CSV

_LAT = ("lat_deg", "lat", "latitude")
_LON = ("lon_deg", "lon", "lng", "long", "longitude")
_H = ("h_m", "h", "height", "height_m", "alt", "altitude", "ele", "elevation")


def parse_csv_track(
    path: str | Path,
    *,
    name: str | None = None,
    h_m: float = 0.0,
    tolerance_m: float = 1.0,
    vertical_tolerance_m: float | None = None,
    source: str | None = None,
    attribution: str = "",
) -> TrackFile:
    """Read a track axis from a CSV with a header: ``lat_deg, lon_deg[, h_m]`` (vertex order).

    Accepted header names: latitude ``lat_deg|lat|latitude``, longitude
    ``lon_deg|lon|lng|long|longitude``, height ``h_m|h|height|alt|altitude|ele|elevation``
    (ellipsoidal metres; ``h_m`` is used when the column is absent). Lines starting with ``#``
    are comments.
    """
    path = Path(path)
    if not path.is_file():
        raise TrackMapError(f"{path}: no such file")
    lines = [
        ln
        for ln in _read_utf8(path).splitlines()
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not lines:
        raise TrackMapError(f"{path}: the file is empty; expected a header lat_deg,lon_deg[,h_m]")
    rows = list(csv.reader(lines))
    header = [c.strip().lower() for c in rows[0]]

    def col(names: Sequence[str]) -> int | None:
        for nm in names:
            if nm in header:
                return header.index(nm)
        return None

    i_lat, i_lon, i_h = col(_LAT), col(_LON), col(_H)
    if i_lat is None or i_lon is None:
        raise TrackMapError(
            f"{path}: header {rows[0]} lacks a latitude and a longitude column; name them "
            "lat_deg and lon_deg (h_m optional)"
        )
    vals = []
    for r, row in enumerate(rows[1:], start=2):
        try:
            lat = float(row[i_lat])
            lon = float(row[i_lon])
            h = float(row[i_h]) if i_h is not None and row[i_h].strip() else h_m
        except (ValueError, IndexError):
            raise TrackMapError(
                f"{path}: data line {r} {row} is not numeric lat/lon/h; fix or remove it"
            ) from None
        vals.append((lat, lon, h))
    if len(vals) < 2:
        raise TrackMapError(f"{path}: needs at least 2 vertices, found {len(vals)}")
    arr = np.array(vals)
    if np.any(np.abs(arr[:, 0]) > 90.0):
        k = int(np.flatnonzero(np.abs(arr[:, 0]) > 90.0)[0])
        if np.all(np.abs(arr[:, :2]) > 360.0):  # metres of a projection, not degrees swapped
            raise TrackMapError(
                f"{path}: data line {k + 2} has latitude {arr[k, 0]}: the coordinates are "
                "metres of a projection (Belgian Lambert 72 or 2008, UTM), not WGS84 degrees; "
                "convert them to lat_deg, lon_deg, or give a GeoJSON with its `crs` member "
                "(docs/track-map.md)"
            )
        raise TrackMapError(
            f"{path}: data line {k + 2} has latitude {arr[k, 0]} outside [-90, 90]; are the "
            "latitude and longitude columns swapped?"
        )
    far = _far_vertex(arr[:, 0], arr[:, 1])
    if far is not None:
        k, d = far
        raise TrackMapError(
            f"{path}: data lines {k + 2} and {k + 3} ({arr[k, 0]}, {arr[k, 1]} and "
            f"{arr[k + 1, 0]}, {arr[k + 1, 1]}) are {d / 1000:.0f} km apart (more than "
            f"{MAX_VERTEX_SPACING_M / 1000:.0f} km between vertices): a mistyped coordinate? "
            "fix it"
        )
    return TrackFile(
        path, arr[:, 0], arr[:, 1], arr[:, 2], name=name or path.stem,
        source=source or path.name, attribution=attribution, tolerance_m=tolerance_m,
        vertical_tolerance_m=vertical_tolerance_m,
    )  # fmt: skip


def _first(names: list[str], n: int = 5) -> str:
    """``a, b, c`` or ``a, b, c and 4 more``."""
    more = f" and {len(names) - n} more" if len(names) > n else ""
    return ", ".join(names[:n]) + more
