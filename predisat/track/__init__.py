"""Track maps: the smooth 3-D track axis with chainage, its files, part chaining and fit.

* :mod:`predisat.track.map` - :class:`TrackMap` (chainage, heading, curvature, projection) and
  :func:`load_track`, the one loader every command uses (GeoJSON or CSV by content).
* :mod:`predisat.track.readers` - parsing GeoJSON and CSV track files (:class:`TrackFile`),
  kilometre posts from line sections, writing GeoJSON.
* :mod:`predisat.track.chain` - chaining the parts of a track file into one polyline.
* :mod:`predisat.track.smooth` - the penalised B-spline fit through a simplified polyline.
* :mod:`predisat.track.footpoint` - one point's projection in Python floats (the locator's
  per-epoch check), bit for bit the array projection.
* :mod:`predisat.track.alias` - where the track passes beside itself (:class:`TrackAliases`).
* :mod:`predisat.track.posts` - kilometre posts; :mod:`predisat.track.stations` - stations;
  :mod:`predisat.track.errors` - the error.
"""

from predisat.track.alias import TrackAliases
from predisat.track.errors import TrackMapError
from predisat.track.map import TrackMap, demo_track, load_track
from predisat.track.posts import KilometrePost
from predisat.track.stations import Station

__all__ = [
    "KilometrePost",
    "Station",
    "TrackAliases",
    "TrackMap",
    "TrackMapError",
    "demo_track",
    "load_track",
]
