"""Stations: named places of the line (stations, halts, operating points), kept for maps.

:func:`points_as_stations` reads them from GeoJSON point features: OpenStreetMap
``railway=station`` / ``halt`` / ``stop`` nodes or train ``public_transport`` stops with a
``name``, or any point with a ``station`` property (its name); one per name. Kilometre-post
points (``km_m``, ``railway=milestone``) are not stations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from numpy.typing import NDArray

from predisat.jsontypes import JsonDict

__all__ = ["Station", "points_as_stations"]

_OSM_STATION_KINDS = ("station", "halt", "stop")


@dataclass(frozen=True)
class Station:
    """A named place of the line, WGS84.

    Attributes
    ----------
    name : str
    lat_deg, lon_deg : float
        Position, degrees (not necessarily on the track axis: a station building, an
        operating point).
    """

    name: str
    lat_deg: float
    lon_deg: float

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("Station.name is empty: give the station's name")
        if not (math.isfinite(self.lat_deg) and abs(self.lat_deg) <= 90.0):
            raise ValueError(f"Station {self.name!r}: lat_deg {self.lat_deg} outside -90..90")
        if not (math.isfinite(self.lon_deg) and abs(self.lon_deg) <= 180.0):
            raise ValueError(f"Station {self.name!r}: lon_deg {self.lon_deg} outside -180..180")


def points_as_stations(points: Sequence[tuple[JsonDict, NDArray]]) -> list[Station]:
    """The point features that are stations, in file order, one per name.

    Parameters
    ----------
    points : sequence of (properties, coordinates)
        GeoJSON Point features (``[lon, lat(, h)]``): ``railway=station``, ``halt`` or
        ``stop``, or ``public_transport=station|stop_position`` with ``train=yes``, with a
        ``name`` (OpenStreetMap); or a ``station`` property holding the name.
    """
    out: list[Station] = []
    seen: set[str] = set()
    for props, xy in points:
        if "km_m" in props:
            continue
        name = ""
        if isinstance(props.get("station"), str):
            name = str(props["station"])
        elif props.get("railway") in _OSM_STATION_KINDS or (
            props.get("public_transport") in ("station", "stop_position")
            and props.get("train") == "yes"
        ):
            name = str(props.get("name") or "")
        if not name or name in seen or xy.shape not in ((2,), (3,)):
            continue
        lon, lat = float(xy[0]), float(xy[1])
        if not (math.isfinite(lat) and math.isfinite(lon)):
            continue
        seen.add(name)
        out.append(Station(name, lat, lon))
    return out
