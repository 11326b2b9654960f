"""Track maps: a smooth 3-D track axis with chainage, heading, curvature and projection.

A published track axis is a simplified polyline (line 144's file keeps 1 m tolerance, which
leaves kinks of about 3 deg every 50-60 m). Every quantity here comes from a smoothing cubic
spline of the polyline in the map's local ENU frame, with the largest smoothing that keeps the
curve within ``tolerance_m`` of the source; chainage is the arc length of that curve. See
``docs/track-map.md``.

The fit itself is in :mod:`predisat.track.smooth`. Readers for GeoJSON and CSV files live in
:mod:`predisat.track.readers` and are exposed here as :meth:`TrackMap.from_geojson` and
:meth:`TrackMap.from_csv`.
"""

from __future__ import annotations

import copy
import functools
import math
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely import LineString, STRtree, box

from predisat.geodesy import WGS84, LocalFrame
from predisat.readonly import freeze_array_fields
from predisat.track.errors import TrackMapError
from predisat.track.footpoint import project_point
from predisat.track.posts import (
    KilometrePost,
    kilometre_gaps,
    monotone_posts,
    project_posts,
)
from predisat.track.readers import TrackFile, parse_csv_track, parse_geojson_track, sniff_format
from predisat.track.smooth import FittedCurve, dense_polyline, fit_curve
from predisat.track.stations import Station

__all__ = [
    "DEMO_TRACK_FILE",
    "KilometrePost",
    "Projection",
    "TrackMap",
    "TrackMapError",
    "demo_track",
    "load_track",
]

DEMO_TRACK_FILE = "line144_track_A.geojson"
"""Packaged demo line (``predisat/data``): Belgian line 144, track A, Infrabel open data."""


@dataclass(frozen=True)
class Projection:
    """Points projected horizontally onto the track axis (see :meth:`TrackMap.project`).

    Attributes
    ----------
    chainage_m : ndarray, shape (...)
        Chainage of the foot point, clamped to ``[0, length_m]``.
    offset_m : ndarray, shape (...)
        Horizontal cross-track offset, positive to the left of increasing chainage.
    height_m : ndarray, shape (...)
        Height of the point above the track axis at the foot point (along the local vertical);
        meaningless when the point's height was not given.
    along_m : ndarray, shape (...)
        Horizontal distance beyond the nearest end of the track (0 inside), metres.
    clamped : ndarray of bool, shape (...)
        True where the point lies beyond an end of the track (``along_m > 1 mm``).
    """

    chainage_m: NDArray
    offset_m: NDArray
    height_m: NDArray
    along_m: NDArray
    clamped: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)


@dataclass(frozen=True, eq=False)
class TrackMap:
    """A track axis on the WGS84 ellipsoid, with chainage along a smooth fit of the source.

    Build it with :meth:`from_latlon`, :meth:`from_geojson`, :meth:`from_csv` or
    :func:`demo_track`; do not call the constructor with unchecked data.

    Attributes
    ----------
    name : str
    lat_deg, lon_deg, h_m : ndarray, shape (n,)
        Vertices of the chained source polyline, in order of increasing chainage.
    frame : LocalFrame
        Local ENU frame at the first vertex; ``enu_at`` returns coordinates in it.
    kilometre_posts : tuple of KilometrePost
        In order of increasing chainage, the kilometre strictly monotone along it: posts that
        are not (duplicated, out of order) are dropped with a warning
        (:func:`~predisat.track.posts.monotone_posts`).
    source, attribution : str
        Where the geometry came from and the attribution its licence requires.
    tunnels_m : tuple of (start_m, end_m)
        Chainage intervals tagged as tunnels in the source (OpenStreetMap ``tunnel=*``).
    bridges_m : tuple of (start_m, end_m)
        Chainage intervals tagged as bridges in the source (OpenStreetMap ``bridge=*``).
    stations : tuple of Station
        Named places of the line found in the source (for maps).
    tolerance_m : float
        Largest horizontal distance allowed between the smooth fit and the source polyline.
    vertical_tolerance_m : float
        The same for heights.
    """

    name: str
    lat_deg: NDArray
    lon_deg: NDArray
    h_m: NDArray
    frame: LocalFrame
    kilometre_posts: tuple[KilometrePost, ...] = ()
    source: str = ""
    attribution: str = ""
    tunnels_m: tuple[tuple[float, float], ...] = ()
    bridges_m: tuple[tuple[float, float], ...] = ()
    stations: tuple[Station, ...] = ()
    tolerance_m: float = 1.0
    vertical_tolerance_m: float = 1.0
    _curve: FittedCurve = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        freeze_array_fields(self)
        # the posts map chainage to the line's kilometres only where they run one way
        posts = monotone_posts(self.kilometre_posts, f"track {self.name!r}")
        object.__setattr__(self, "kilometre_posts", posts)
        enu = self.frame.to_enu(self.lat_deg, self.lon_deg, self.h_m)
        curve = fit_curve(enu, self.frame, self.tolerance_m, self.vertical_tolerance_m)
        object.__setattr__(self, "_curve", curve)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_latlon(
        cls,
        lat_deg: ArrayLike,
        lon_deg: ArrayLike,
        h_m: ArrayLike = 0.0,
        name: str = "track",
        *,
        tolerance_m: float = 1.0,
        vertical_tolerance_m: float | None = None,
        kilometre_posts: Sequence[KilometrePost] = (),
        tunnels_m: Sequence[tuple[float, float]] = (),
        source: str = "",
        attribution: str = "",
    ) -> TrackMap:
        """Track map from the vertices of a polyline, in order of increasing chainage.

        Parameters
        ----------
        lat_deg, lon_deg : array_like, shape (n,)
            Geodetic vertices, degrees; ``n >= 2``.
        h_m : array_like, shape (n,) or scalar
            Ellipsoidal heights, metres (default 0).
        name : str
        tolerance_m : float
            Horizontal tolerance of the source (its simplification tolerance); the smooth fit
            stays within it.
        vertical_tolerance_m : float, optional
            Tolerance for heights; default ``tolerance_m``.

        Raises
        ------
        TrackMapError
            Fewer than two distinct vertices, non-finite or impossible coordinates, or a
            polyline that crosses itself.
        """
        lat = np.array(lat_deg, dtype=float).ravel()
        lon = np.array(lon_deg, dtype=float).ravel()
        if lat.shape != lon.shape:
            raise TrackMapError(
                f"lat_deg has {lat.size} values but lon_deg has {lon.size}; pass one per vertex"
            )
        h = np.array(np.broadcast_to(np.asarray(h_m, float), lat.shape), dtype=float)
        _check_vertices(lat, lon, h, where=f"track {name!r}")
        if tolerance_m <= 0:
            raise TrackMapError(f"tolerance_m must be > 0, got {tolerance_m}")
        vtol = tolerance_m if vertical_tolerance_m is None else float(vertical_tolerance_m)
        if vtol <= 0:
            raise TrackMapError(f"vertical_tolerance_m must be > 0, got {vtol}")
        lat, lon, h = _drop_repeats(lat, lon, h)
        if lat.size < 2:
            raise TrackMapError(
                f"track {name!r} has fewer than 2 distinct vertices; a track needs a line"
            )
        frame = LocalFrame(float(lat[0]), float(lon[0]), float(h[0]))
        enu = frame.to_enu(lat, lon, h)
        _check_simple(enu, where=f"track {name!r}", frame=frame)
        _check_grade(enu, h, where=f"track {name!r}", frame=frame)
        return cls(
            name=name,
            lat_deg=lat,
            lon_deg=lon,
            h_m=h,
            frame=frame,
            kilometre_posts=tuple(kilometre_posts),
            source=source,
            attribution=attribution,
            tunnels_m=tuple((float(a), float(b)) for a, b in tunnels_m),
            tolerance_m=float(tolerance_m),
            vertical_tolerance_m=vtol,
        )

    @classmethod
    def from_geojson(
        cls,
        path: str | Path,
        track: str | None = None,
        h_m: float = 0.0,
        **kwargs: Any,  # Any: forwarded to parse_geojson_track's keyword options
    ) -> TrackMap:
        """Track map from a GeoJSON file; the options are those of
        :func:`predisat.track.readers.parse_geojson_track`."""
        return cls.from_track_file(parse_geojson_track(path, track=track, h_m=h_m, **kwargs))

    @classmethod
    def from_csv(
        cls, path: str | Path, **kwargs: Any  # Any: forwarded to parse_csv_track's options
    ) -> TrackMap:
        """Track map from a CSV of lat/lon[/h]; the options are those of
        :func:`predisat.track.readers.parse_csv_track`."""
        return cls.from_track_file(parse_csv_track(path, **kwargs))

    @classmethod
    def from_track_file(cls, tf: TrackFile) -> TrackMap:
        """Track map from a parsed file: the smooth fit, the chainage direction (with the
        kilometre posts when the file has at least two), posts and tunnels on the axis."""

        def build(lat: NDArray, lon: NDArray, h: NDArray) -> TrackMap:
            try:
                return cls.from_latlon(
                    lat, lon, h, name=tf.name, tolerance_m=tf.tolerance_m,
                    vertical_tolerance_m=tf.vertical_tolerance_m, source=tf.source,
                    attribution=tf.attribution,
                )  # fmt: skip
            except TrackMapError as exc:
                raise TrackMapError(f"{tf.path}: {exc}") from None

        tm = build(tf.lat_deg, tf.lon_deg, tf.h_m)
        _check_turns(tm, str(tf.path))
        _check_on_land(tm, str(tf.path))
        posts = project_posts(tm, tf.posts, tf.max_post_offset_m)
        flip, spans, bridges = tf.reverse, list(tf.tunnel_spans), list(tf.bridge_spans)
        if not flip and len(posts) >= 2 and not tf.vertex_order:
            by_s = sorted(posts, key=lambda p: p.chainage_m)
            flip = by_s[-1].km_m < by_s[0].km_m
        if flip:
            tm = build(tf.lat_deg[::-1], tf.lon_deg[::-1], tf.h_m[::-1])
            posts = project_posts(tm, tf.posts, tf.max_post_offset_m)
            n = len(tf.lat_deg)
            spans = [(n - 1 - b, n - 1 - a) for a, b in spans]
            bridges = [(n - 1 - b, n - 1 - a) for a, b in bridges]
        kept = monotone_posts(posts, f"{tf.path}")
        for a, b in kilometre_gaps(kept):
            pa, pb = (next(p for p in kept if p.chainage_m == c) for c in (a, b))
            warnings.warn(
                f"{tf.path}: the kilometre posts at km {pa.km_m / 1000:.3f} (chainage {a:.0f} m) "
                f"and km {pb.km_m / 1000:.3f} ({b:.0f} m) do not follow the track between them "
                "(a kilometre equation, a restart or posts missing): the line's kilometres are "
                "left empty there",
                stacklevel=2,
            )

        def written(chain: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
            # write_geojson's intervals are in the vertex order's chainage
            length = tm.length_m
            if not chain:
                return []
            was = tf.chainage_length_m
            if was is not None and abs(was - length) > 0.5:
                raise TrackMapError(
                    f"{tf.path}: its tunnels_m/bridges_m were written for a line {was:.3f} m "
                    f"long, its line is {length:.3f} m: the line was edited since, or is read "
                    "with another fit tolerance than it was written with (its tolerance_m "
                    "member, --tolerance), and the intervals would stand elsewhere; read it "
                    "with its own tolerance, write the map again, or remove them"
                )
            off = [(a, b) for a, b in chain if b < -0.01 or a > length + 0.01]
            if off:
                raise TrackMapError(
                    f"{tf.path}: tunnels_m/bridges_m hold {off[0]} outside its line (0 to "
                    f"{length:.3f} m); write the map again, or remove them"
                )
            if flip:
                chain = [(length - b, length - a) for a, b in chain]
            return [(max(0.0, a), min(length, b)) for a, b in chain]

        return tm.with_metadata(
            kilometre_posts=kept,
            tunnels_m=sorted(_tunnel_intervals(tm, spans) + written(tf.tunnels_chainage_m)),
            bridges_m=sorted(_tunnel_intervals(tm, bridges) + written(tf.bridges_chainage_m)),
            stations=tf.stations,
        )  # fmt: skip

    def with_metadata(
        self,
        *,
        kilometre_posts: Sequence[KilometrePost] | None = None,
        tunnels_m: Sequence[tuple[float, float]] | None = None,
        name: str | None = None,
        bridges_m: Sequence[tuple[float, float]] | None = None,
        stations: Sequence[Station] | None = None,
    ) -> TrackMap:
        """A copy with other metadata, sharing the fitted axis (no refit)."""
        new = copy.copy(self)
        if kilometre_posts is not None:
            posts = monotone_posts(kilometre_posts, f"track {self.name!r}")
            object.__setattr__(new, "kilometre_posts", posts)
        if tunnels_m is not None:
            tun = tuple((float(a), float(b)) for a, b in tunnels_m)
            object.__setattr__(new, "tunnels_m", tun)
        if name is not None:
            object.__setattr__(new, "name", name)
        if bridges_m is not None:
            object.__setattr__(new, "bridges_m", tuple((float(a), float(b)) for a, b in bridges_m))
        if stations is not None:
            object.__setattr__(new, "stations", tuple(stations))
        return new

    # ------------------------------------------------------------------ properties
    @property
    def length_m(self) -> float:
        """Arc length of the smooth axis, metres (chainage runs from 0 to this)."""
        return self._curve.length_m

    @cached_property
    def max_deviation_m(self) -> float:
        """Largest horizontal distance between the smooth axis and the source polyline, metres.

        Symmetric (Hausdorff): source points every 1 m projected onto the axis, and axis nodes
        every metre measured to the source polyline.
        """
        poly = self.polyline_enu_m
        _, dense, _ = dense_polyline(poly, 1.0)
        to_axis = np.abs(self.project_enu(dense).offset_m)
        nodes = shapely.points(self._curve.node_enu_m[:, :2])
        to_poly = shapely.distance(nodes, shapely.LineString(poly[:, :2]))
        return float(max(np.max(to_axis), np.max(to_poly)))

    @property
    def max_vertical_deviation_m(self) -> float:
        """Largest height difference between the smooth axis and the source polyline."""
        return self._curve.max_vertical_deviation_m

    @cached_property
    def polyline_enu_m(self) -> NDArray:
        """Source vertices in :attr:`frame`, shape (n, 3)."""
        out = self.frame.to_enu(self.lat_deg, self.lon_deg, self.h_m)
        out.setflags(write=False)
        return out

    @property
    def geodesic_length_m(self) -> float:
        """Length of the source polyline along WGS84 geodesics (pyproj), metres."""
        return float(WGS84.line_length(self.lon_deg, self.lat_deg))

    # ------------------------------------------------------------------ evaluation
    def _t(self, chainage_m: ArrayLike) -> NDArray:
        s = np.asarray(chainage_m, float)
        if not np.all(np.isfinite(s)):
            raise TrackMapError("chainage_m contains NaN or infinite values")
        return np.asarray(self._curve.t_of_s(np.clip(s, 0.0, self.length_m)))

    def enu_at(self, chainage_m: ArrayLike) -> NDArray:
        """Axis position in :attr:`frame` ENU, shape ``chainage_m.shape + (3,)``, metres.

        Chainages outside ``[0, length_m]`` are clamped to the ends.
        """
        return np.asarray(self._curve.spline(self._t(chainage_m)))

    def ecef_at(self, chainage_m: ArrayLike) -> NDArray:
        """Axis position in ECEF, shape ``chainage_m.shape + (3,)``, metres."""
        return self.frame.enu_to_ecef(self.enu_at(chainage_m))

    def position_at(self, chainage_m: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
        """Geodetic axis position ``(lat_deg, lon_deg, h_m)``, each shaped like ``chainage_m``."""
        return self.frame.to_geodetic(self.enu_at(chainage_m))

    def tangent_at(self, chainage_m: ArrayLike) -> NDArray:
        """Unit tangent (direction of increasing chainage) in :attr:`frame`, shape (..., 3)."""
        d = np.asarray(self._curve.spline(self._t(chainage_m), 1))
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def up_at(self, chainage_m: ArrayLike) -> NDArray:
        """Local vertical (ellipsoid normal) at the axis, in :attr:`frame`, shape (..., 3)."""
        lat, lon, _ = self.position_at(chainage_m)
        return self.frame.rotation_from(lat, lon)[..., :, 2]

    def heading_at(self, chainage_m: ArrayLike) -> NDArray:
        """Azimuth of increasing chainage in the local ENU at the point, degrees in [0, 360)."""
        s = np.asarray(chainage_m, float)
        lat, lon, _ = self.position_at(s)
        rot = self.frame.rotation_from(lat, lon)  # local -> frame; transpose maps back
        local = np.einsum("...ji,...j->...i", rot, self.tangent_at(s))
        return np.mod(np.degrees(np.arctan2(local[..., 0], local[..., 1])), 360.0)

    def grade_at(self, chainage_m: ArrayLike) -> NDArray:
        """Gradient of the axis, rise over horizontal run (dimensionless, + uphill)."""
        tan = self.tangent_at(chainage_m)
        up = self.up_at(chainage_m)
        rise = np.sum(tan * up, axis=-1)
        return rise / np.sqrt(np.maximum(1.0 - rise**2, 1e-300))

    def curvature_at(self, chainage_m: ArrayLike) -> NDArray:
        """Signed horizontal curvature, 1/m, positive when the track turns left.

        Computed in the local horizontal plane at the point, from the smooth fit.
        """
        t = self._t(chainage_m)
        d1 = np.asarray(self._curve.spline(t, 1))
        d2 = np.asarray(self._curve.spline(t, 2))
        up = self.up_at(chainage_m)
        h1 = d1 - np.sum(d1 * up, axis=-1, keepdims=True) * up
        h2 = d2 - np.sum(d2 * up, axis=-1, keepdims=True) * up
        cross = np.sum(np.cross(h1, h2) * up, axis=-1)
        return cross / np.linalg.norm(h1, axis=-1) ** 3

    def kilometre_at(self, chainage_m: ArrayLike) -> NDArray:
        """The line's kilometre reference (metres) at given chainages, from the posts.

        Linear between posts, extrapolated up to 1 km beyond them; NaN when the map has no
        kilometre posts (none in the file, or none usable: the map keeps only posts strictly
        monotone along the chainage), and between two posts whose kilometres do not follow the
        chainage (:func:`~predisat.track.posts.kilometre_gaps`: a kilometre equation, a
        restart, posts missing). Metadata for reports, not a measurement.
        """
        s = np.asarray(chainage_m, float)
        posts = sorted(self.kilometre_posts, key=lambda p: p.chainage_m)
        if not posts:
            return np.full(s.shape, np.nan)
        cs = np.array([p.chainage_m for p in posts])
        km = np.array([p.km_m for p in posts])
        if cs.size == 1:  # as beyond the outer posts: 1 km at most
            return np.where(np.abs(s - cs[0]) <= _POST_REACH_M, km[0] + (s - cs[0]), np.nan)
        out = np.interp(s, cs, km)
        lo, hi = s < cs[0], s > cs[-1]
        slope_lo = (km[1] - km[0]) / (cs[1] - cs[0]) if cs[1] > cs[0] else 1.0
        slope_hi = (km[-1] - km[-2]) / (cs[-1] - cs[-2]) if cs[-1] > cs[-2] else 1.0
        out = np.where(lo, km[0] + slope_lo * (s - cs[0]), out)
        out = np.where(hi, km[-1] + slope_hi * (s - cs[-1]), out)
        gaps = kilometre_gaps(posts)
        for a, b in gaps:
            out = np.where((s > a) & (s < b), np.nan, out)
        if gaps and gaps[0][0] == cs[0]:  # no trusted slope to extrapolate with
            out = np.where(lo, np.nan, out)
        if gaps and gaps[-1][1] == cs[-1]:
            out = np.where(hi, np.nan, out)
        # far beyond the outer posts the kilometres may restart or jump (posts dropped there)
        far = (s < cs[0] - _POST_REACH_M) | (s > cs[-1] + _POST_REACH_M)
        return np.where(far, np.nan, out)

    def in_tunnel(self, chainage_m: ArrayLike) -> NDArray:
        """True where the chainage lies in a tagged tunnel interval, shape like ``chainage_m``."""
        s = np.asarray(chainage_m, float)
        out = np.zeros(s.shape, bool)
        for a, b in self.tunnels_m:
            out |= (s >= a) & (s <= b)
        return out

    # ------------------------------------------------------------------ projection
    def project(
        self, lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike | None = None
    ) -> Projection:
        """Project geodetic points horizontally onto the axis.

        Parameters
        ----------
        lat_deg, lon_deg : array_like, shape (...)
        h_m : array_like, shape (...), optional
            Ellipsoidal heights; when omitted the points are taken at the height of the
            source's first vertex, which changes only ``height_m`` of the result.

        Returns
        -------
        Projection
        """
        lat, lon = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
        h = self.frame.h_m if h_m is None else np.broadcast_to(np.asarray(h_m, float), lat.shape)
        return self.project_enu(self.frame.to_enu(lat, lon, h))

    def project_enu(self, enu_m: ArrayLike, *, max_iter: int = 50) -> Projection:
        """Project points given in :attr:`frame` ENU, shape (..., 3), onto the axis.

        The foot point is where the horizontal (local-vertical-free) part of ``p - r(s)`` is
        normal to the tangent: a coarse nearest node on a 1 m resample of the axis, then Newton
        steps until ``|ds| < 1e-6`` m. Points beyond the ends are clamped and flagged.
        """
        p = np.asarray(enu_m, float)
        if p.shape[-1:] != (3,):
            raise TrackMapError(f"enu_m must have shape (..., 3), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise TrackMapError("enu_m contains NaN or infinite values")
        shape = p.shape[:-1]
        pts = p.reshape(-1, 3)
        c = self._curve
        if len(pts) == 1:
            xs, rows = self._node_lists
            x, y, z = (float(v) for v in pts[0])
            one = project_point(c, self.length_m, xs, rows, (x, y, z), max_iter)
            if one is not None:
                return Projection(*(np.full(shape, v) for v in one))
        _, idx = c.tree.query(pts[:, :2])
        s = c.node_s_m[idx].astype(float)
        up = c.node_up[idx]
        length = self.length_m
        for _ in range(max_iter):
            t = np.asarray(c.t_of_s(s))
            r = np.asarray(c.spline(t))
            d1 = np.asarray(c.spline(t, 1))
            d2 = np.asarray(c.spline(t, 2))
            up = self._up_interp(s)
            ds_dt = np.linalg.norm(d1, axis=-1, keepdims=True)
            tan = d1 / ds_dt  # unit, d r / d s
            dtan = (d2 - np.sum(d2 * tan, -1, keepdims=True) * tan) / ds_dt**2  # d tan / d s
            d = pts - r
            dh = d - np.sum(d * up, -1, keepdims=True) * up
            f = np.sum(dh * tan, -1)
            # f(s) = dh . tan; df/ds = -|tan_h|^2 + dh . dtan  (up varies negligibly)
            tan_h = tan - np.sum(tan * up, -1, keepdims=True) * up
            fp = -np.sum(tan_h * tan_h, -1) + np.sum(dh * dtan, -1)
            fp = np.where(fp < -0.1, fp, -np.sum(tan_h * tan_h, -1))  # beyond curvature centre
            step = -f / fp
            s_new = np.clip(s + step, 0.0, length)
            done = np.abs(s_new - s) < 1e-6
            s = s_new
            if np.all(done):
                break
        t = np.asarray(c.t_of_s(s))
        r = np.asarray(c.spline(t))
        d1 = np.asarray(c.spline(t, 1))
        up = self._up_interp(s)
        tan = d1 / np.linalg.norm(d1, axis=-1, keepdims=True)
        d = pts - r
        height = np.sum(d * up, -1)
        dh = d - height[:, None] * up
        left = np.cross(up, tan)
        left /= np.linalg.norm(left, axis=-1, keepdims=True)
        offset = np.sum(dh * left, -1)
        at_end = (s <= 0.0) | (s >= length)
        along = np.where(at_end, np.abs(np.sum(dh * tan, -1)), 0.0)
        clamped = along > 1e-3
        return Projection(
            chainage_m=s.reshape(shape),
            offset_m=offset.reshape(shape),
            height_m=height.reshape(shape),
            along_m=along.reshape(shape),
            clamped=clamped.reshape(shape),
        )

    @cached_property
    def _node_lists(self) -> tuple[list[float], list[list[float]]]:
        """The nodes' chainage and vertical as Python lists, for the one-point projection."""
        c = self._curve
        return c.node_s_m.tolist(), [row.tolist() for row in c.node_up_rows]

    def _up_interp(self, s: NDArray) -> NDArray:
        c = self._curve
        up = np.stack([np.interp(s, c.node_s_m, row) for row in c.node_up_rows], axis=-1)
        return up / np.linalg.norm(up, axis=-1, keepdims=True)

    def sample(self, step_m: float, start_m: float = 0.0, end_m: float | None = None) -> NDArray:
        """Chainages every ``step_m`` from ``start_m`` to ``end_m`` (default the end), inclusive
        of the start, shape (n,)."""
        if step_m <= 0:
            raise TrackMapError(f"step_m must be > 0, got {step_m}")
        end = self.length_m if end_m is None else float(end_m)
        return np.arange(float(start_m), end + 1e-9, step_m)


# ---------------------------------------------------------------------- helpers


def _check_vertices(lat: NDArray, lon: NDArray, h: NDArray, where: str) -> None:
    if lat.size == 0:
        raise TrackMapError(f"{where} has no vertices; a track needs at least 2")
    if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon)) and np.all(np.isfinite(h))):
        bad = int(np.flatnonzero(~(np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)))[0])
        raise TrackMapError(f"{where}: vertex {bad} has a NaN or infinite coordinate")
    if np.any(np.abs(lat) > 90.0):
        bad = int(np.flatnonzero(np.abs(lat) > 90.0)[0])
        raise TrackMapError(
            f"{where}: vertex {bad} has latitude {lat[bad]:.6f} deg, outside [-90, 90]; are "
            "latitude and longitude swapped? (GeoJSON coordinates are [lon, lat])"
        )
    if np.any(np.abs(lon) > 360.0):
        bad = int(np.flatnonzero(np.abs(lon) > 360.0)[0])
        raise TrackMapError(f"{where}: vertex {bad} has impossible longitude {lon[bad]:.6f} deg")
    if np.any(np.abs(h) > 10000.0):
        bad = int(np.flatnonzero(np.abs(h) > 10000.0)[0])
        raise TrackMapError(
            f"{where}: vertex {bad} has height {h[bad]:.1f} m; heights are metres above the "
            "ellipsoid (is a coordinate column misplaced?)"
        )


_POST_REACH_M = 1000.0  # line kilometres extrapolated at most this far beyond the outer posts

FOLD_TURN_DEG = 90.0
"""Largest turn of a track's heading within :data:`_FOLD_BASE_M` of chainage. A railway needs
hundreds of metres to turn a right angle (a tram's 20 m radius: 31 m); an axis that turns back
within 10 m folds: two parts overlapping by 1 m at a joint made it turn by 178 deg on line 144,
lengthen every chainage after it by 2.4 m and lose the smoothing of the whole line (a user
trial). A coarse polyline's corner is not a fold: a 41 deg corner of Infrabel's 10 m export
cut within a metre (a radius of 17.7 m) is a real curve of 180 m."""
_FOLD_BASE_M = 10


def _check_turns(tm: TrackMap, where: str) -> None:
    """Refuse a track whose smooth axis turns by more than :data:`FOLD_TURN_DEG` within 10 m of
    chainage anywhere (the heading sampled every metre, unwrapped)."""
    s = np.arange(0.0, tm.length_m + 1.0, 1.0).clip(max=tm.length_m)
    if s.size <= _FOLD_BASE_M:
        return
    heading = np.unwrap(np.radians(tm.heading_at(s)))
    turn = np.degrees(np.abs(heading[_FOLD_BASE_M:] - heading[:-_FOLD_BASE_M]))
    worst = int(np.argmax(turn))
    if turn[worst] > FOLD_TURN_DEG:
        at = float(s[worst] + 0.5 * _FOLD_BASE_M)
        lat, lon, _ = tm.position_at(at)
        raise TrackMapError(
            f"{where}: track {tm.name!r} turns by {turn[worst]:.0f} deg within "
            f"{_FOLD_BASE_M} m at chainage {at:.0f} m (lat {float(lat):.6f}, lon "
            f"{float(lon):.6f}): the line folds back there (parts that overlap or step back at "
            "a joint, a spur); fix the geometry at that place"
        )


MIN_SHARE_ON_LAND = 0.5
"""Least share of a track's length that must lie on land (:func:`_land_at`): bridges, causeways
and a coastline keep a line well above it. Below, its coordinates are swapped: a Belgian line
144 with latitude and longitude exchanged (a track CSV under a hand-written header, a GeoJSON in
lat, lon order) landed off Somalia and was used without a word, with 0.30 % false trust in the
masks made on it (two user trials)."""

_LAND_STEP_DEG = 0.1


@functools.cache
def _land_grid() -> NDArray:
    """The packaged 0.1 deg land grid (``predisat/data/land_0p1deg.npz``, made by
    ``scripts/make_land_grid.py`` from NOAA's GLOBE 1 km mask, public domain): read once, 6 MB
    (the 1 km mask itself took 940 MB and 1-2 s at every track file's load)."""
    with resources.files("predisat").joinpath("data/land_0p1deg.npz").open("rb") as f:
        doc = np.load(f)
        rows, cols = (int(v) for v in doc["shape"])
        grid = np.unpackbits(doc["land"], axis=1, count=cols).astype(bool)
    assert grid.shape == (rows, cols)
    grid.setflags(write=False)
    return grid


def _land_at(lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray:
    """Whether there is land in the 0.1 deg cell (about 11 km) of each point.

    Parameters
    ----------
    lat_deg, lon_deg : array_like, shape (...)

    Returns
    -------
    ndarray of bool, shape (...)
        True where any of the cell's 1 km cells of NOAA's GLOBE mask is land (a coastal point
        on the coarse mask's sea side counts as land).
    """
    grid = _land_grid()
    lat, lon = np.broadcast_arrays(np.asarray(lat_deg, float), np.asarray(lon_deg, float))
    row = np.clip(((90.0 - lat) / _LAND_STEP_DEG).astype(int), 0, grid.shape[0] - 1)
    col = (np.floor((lon + 180.0) / _LAND_STEP_DEG).astype(int)) % grid.shape[1]
    return grid[row, col]


def _check_on_land(tm: TrackMap, where: str) -> None:
    """Refuse a track lying mostly at sea (sampled every 100 m), naming where it lies and
    where it would lie with its coordinates swapped."""
    s = np.linspace(0.0, tm.length_m, max(2, int(tm.length_m // 100.0) + 1))
    lat, lon, _ = tm.position_at(s)
    land = _land_at(lat, lon)
    if land.mean() >= MIN_SHARE_ON_LAND:
        return
    mid = len(s) // 2
    lat_m, lon_m = float(lat[mid]), (float(lon[mid]) + 180.0) % 360.0 - 180.0
    swapped = abs(lon_m) <= 90.0 and bool(_land_at(lon_m, lat_m))
    if swapped:
        hint = (f"with latitude and longitude swapped it would lie at lat {lon_m:.4f}, "
                f"lon {lat_m:.4f}, on land: they are swapped")  # fmt: skip
    else:
        hint = "are the latitude and longitude swapped, or the coordinates of another CRS?"
    raise TrackMapError(
        f"{where}: track {tm.name!r} lies at sea over {100 * (1 - land.mean()):.0f} % of its "
        f"length (around lat {lat_m:.4f}, lon {lon_m:.4f}); {hint} (GeoJSON "
        "coordinates are [lon, lat]; a CSV's columns are read by their header)"
    )


MAX_GRADE = 0.15
"""Steepest mean grade a track's heights may show over :data:`_GRADE_BASE_M` (150 per mille:
steeper than any adhesion railway; main lines stay under 40). Beyond, the third coordinate is
not a height: a measure or a chainage exported as Z made line 144 climb 8 966 m at 45 deg and
41 % longer (a user trial)."""
_GRADE_BASE_M = 200.0


def _check_grade(enu: NDArray, h: NDArray, where: str, frame: LocalFrame) -> None:
    """Refuse heights that rise or fall faster than :data:`MAX_GRADE` over 200 m (the whole
    line when shorter, from 20 m)."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(enu[:, :2], axis=0).T))])
    base = min(_GRADE_BASE_M, float(s[-1]))
    if base < 20.0:
        return
    i = np.arange(s.size)
    j = np.searchsorted(s, s + base - 1e-9)
    ok = j < s.size
    i, j = i[ok], j[ok]
    grade = np.abs(h[j] - h[i]) / np.maximum(s[j] - s[i], 1e-9)
    k = int(np.argmax(grade))
    if grade[k] > MAX_GRADE:
        lat, lon, _ = frame.to_geodetic(enu[i[k]])
        raise TrackMapError(
            f"{where}: its heights change by {h[j[k]] - h[i[k]]:+.0f} m over "
            f"{s[j[k]] - s[i[k]]:.0f} m near lat {float(lat):.6f}, lon {float(lon):.6f} (a "
            f"{100 * grade[k]:.0f} % grade; railways stay under {100 * MAX_GRADE:.0f} %): the "
            "third coordinate is not a height (a measure or a chainage exported as Z?); drop "
            "it, or give heights above the ellipsoid"
        )


def _drop_repeats(lat: NDArray, lon: NDArray, h: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    keep = np.ones(lat.size, bool)
    keep[1:] = (np.diff(lat) != 0) | (np.diff(lon) != 0) | (np.diff(h) != 0)
    return lat[keep], lon[keep], h[keep]


def _check_simple(enu: NDArray, where: str, frame: LocalFrame) -> None:
    """Reject a polyline whose horizontal trace crosses itself, naming the place."""
    line = LineString(enu[:, :2])
    if line.is_simple:
        return
    segs = [LineString(enu[i : i + 2, :2]) for i in range(len(enu) - 1)]
    tree = STRtree(segs)
    for i, seg in enumerate(segs):
        for j in tree.query(box(*seg.bounds)):
            if j > i + 1 and seg.intersects(segs[j]):
                pt = seg.intersection(segs[j]).representative_point()
                lat, lon, _ = frame.to_geodetic([pt.x, pt.y, 0.0])
                raise TrackMapError(
                    f"{where}: the chained line crosses itself between segments {i} and {j} "
                    f"near lat {float(lat):.6f}, lon {float(lon):.6f}; select a single track "
                    "(track=..., --track-name) or fix the part order in the file"
                )
    raise TrackMapError(f"{where}: the chained line overlaps itself; select a single track")


def demo_track() -> TrackMap:
    """Belgian line 144 (Gembloux - Jemeppe-sur-Sambre), track A, about 14.2 km.

    Infrabel open data (attribution required, see ``predisat/data/ATTRIBUTION.md``), with
    kilometre posts derived from Infrabel's line sections.
    """
    ref = resources.files("predisat") / "data" / DEMO_TRACK_FILE
    with resources.as_file(ref) as path:
        return TrackMap.from_geojson(path)


def _tunnel_intervals(
    tm: TrackMap, spans: Sequence[tuple[int, int]]
) -> list[tuple[float, float]]:
    if not spans:
        return []
    idx = np.array(spans)
    enu = tm.polyline_enu_m
    s = np.sort(tm.project_enu(enu[idx.ravel()]).chainage_m.reshape(-1, 2), axis=1)
    merged: list[list[float]] = []
    for a, b in sorted(s.tolist()):
        if merged and a <= merged[-1][1] + 1.0:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged]


def load_track(
    path: str | os.PathLike[str],
    name: str | None = None,
    *,
    chain: Literal["all", "longest"] = "all",
    where: Mapping[str, str | None] | None = None,
    tolerance_m: float | None = None,
) -> TrackMap:
    """The track map in a file, GeoJSON or CSV by its content (not its suffix).

    The one loader of every command (``predisat process``, ``synth``, ``availability``,
    ``locator run`` ...) and of survey folders.

    Parameters
    ----------
    path : path-like
        A GeoJSON file (LineString / MultiLineString) or a CSV of ``lat_deg, lon_deg[, h_m]``.
    name : str, optional
        Which track of a GeoJSON file holding several (``track=`` of
        :func:`~predisat.track.readers.parse_geojson_track`); ignored for a CSV (one line).
    chain : {"all", "longest"}
        How the selected GeoJSON parts are chained.
    where : mapping, optional
        GeoJSON property filters (``{key: value}``, None: key absent).
    tolerance_m : float, optional
        How far (m) the smooth fit may leave the source vertices (:class:`TrackMap`); by
        default the file's own (a written map's ``tolerance_m``), else 1 m. A coarsely
        simplified source (10 m) needs more, or its kinks read as sharp curves.

    Raises
    ------
    TrackMapError
        When the file is missing or unusable, naming the file, the record and the fix.
    """
    p = Path(path)
    if not p.is_file():
        raise TrackMapError(
            f"{p}: no such file; give a GeoJSON (LineString) or CSV (lat_deg, lon_deg[, h_m]) "
            "track map"
        )
    if tolerance_m is not None and not (math.isfinite(tolerance_m) and tolerance_m > 0):
        raise TrackMapError(f"tolerance_m must be a positive number of metres, got {tolerance_m}")
    if sniff_format(p) == "geojson":
        return TrackMap.from_geojson(p, track=name, chain=chain, where=where,
                                     tolerance_m=tolerance_m)  # fmt: skip
    if tolerance_m is not None:
        return TrackMap.from_csv(p, tolerance_m=tolerance_m)
    return TrackMap.from_csv(p)
