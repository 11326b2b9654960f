"""Kilometre posts: the line's own kilometre references, kept at their chainage on a track.

:func:`points_as_posts` reads them from GeoJSON point features (a ``km_m`` property, or
OpenStreetMap ``railway=milestone`` nodes); :func:`project_posts` places them on a track map;
:func:`monotone_posts` keeps those that can map chainage to the line's kilometres.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.jsontypes import JsonDict

__all__ = [
    "POST_SLOPE_RANGE",
    "KilometrePost",
    "kilometre_gaps",
    "monotone_posts",
    "points_as_posts",
    "project_posts",
]

POST_SLOPE_RANGE = (0.5, 2.0)
"""Kilometres per metre of chainage between two neighbouring posts that interpolation trusts.
Real posts agree with the track within a few per cent; far outside, the kilometres jump between
them (a kilometre equation at a line change, a restart at 0, posts missing across one): an
interpolation said km 10.375 where the line's was 7.250 (a GIS user trial)."""


@dataclass(frozen=True)
class KilometrePost:
    """A kilometre post of the line, kept as metadata at its chainage on this track.

    Attributes
    ----------
    chainage_m : float
        Chainage of the post on this track map.
    km_m : float
        The line's own kilometre reference at the post, in metres (e.g. 12850.0 for km 12.850).
    label : str
        Free text (a place name, or the formatted kilometre).
    """

    chainage_m: float
    km_m: float
    label: str = ""


class _Projection(Protocol):
    @property
    def chainage_m(self) -> NDArray: ...

    @property
    def offset_m(self) -> NDArray: ...

    @property
    def clamped(self) -> NDArray: ...


class _Projects(Protocol):  # the part of predisat.track.map.TrackMap used here
    def project(
        self, lat_deg: ArrayLike, lon_deg: ArrayLike, h_m: ArrayLike | None = None
    ) -> _Projection: ...


def points_as_posts(
    points: Sequence[tuple[JsonDict, NDArray]],
) -> list[tuple[float, str, NDArray]]:
    """``(km_m, label, [lon, lat(, h)])`` of the point features that are kilometre posts.

    Parameters
    ----------
    points : sequence of (properties, coordinates)
        GeoJSON Point features: a ``km_m`` property (metres), or an OpenStreetMap
        ``railway=milestone`` node with ``railway:position`` (kilometres).
    """
    out = []
    for props, xy in points:
        km: float | None = None
        if "km_m" in props:
            km = float(props["km_m"])
        elif props.get("railway") == "milestone" and "railway:position" in props:
            txt = str(props["railway:position"]).replace(",", ".").split(";")[0]
            try:
                km = 1000.0 * float(txt.strip().lower().removeprefix("km").strip())
            except ValueError:
                km = None
        if km is None or xy.shape not in ((2,), (3,)):
            continue
        label = str(props.get("label") or props.get("name") or f"km {km / 1000.0:.3f}")
        out.append((km, label, xy))
    return out


def project_posts(
    tm: _Projects, posts: Sequence[tuple[float, str, NDArray]], max_offset_m: float
) -> list[KilometrePost]:
    """The posts (as from :func:`points_as_posts`) at their chainage on ``tm``, sorted; posts
    off the track's ends or farther than ``max_offset_m`` (m) from it are dropped."""
    if not posts:
        return []
    xy = np.array([p[2][:2] for p in posts])
    pr = tm.project(xy[:, 1], xy[:, 0])
    keep = (~pr.clamped) & (np.abs(pr.offset_m) <= max_offset_m)
    out = [
        KilometrePost(float(s), km, label)
        for (km, label, _), s, k in zip(posts, pr.chainage_m, keep, strict=True)
        if k
    ]
    return sorted(out, key=lambda p: p.chainage_m)


def _post_text(p: KilometrePost) -> str:
    km = f"km {p.km_m / 1000.0:.3f}"
    label = "" if p.label in ("", km) else f" ({p.label})"
    return f"{km}{label} at chainage {p.chainage_m / 1000.0:.3f} km"


def kilometre_gaps(posts: Sequence[KilometrePost]) -> list[tuple[float, float]]:
    """The chainage intervals between neighbouring posts (sorted by chainage) whose kilometres
    do not follow the chainage (:data:`POST_SLOPE_RANGE`): the line's kilometre is unknown
    there."""
    ordered = sorted(posts, key=lambda p: p.chainage_m)
    lo, hi = POST_SLOPE_RANGE
    gaps = []
    for a, b in itertools.pairwise(ordered):
        ds = b.chainage_m - a.chainage_m
        slope = abs(b.km_m - a.km_m) / ds if ds > 0 else np.inf
        if not lo <= slope <= hi:
            gaps.append((a.chainage_m, b.chainage_m))
    return gaps


_SAME_POST_M = 1.0  # two posts of one kilometre this close along the chainage are one


def monotone_posts(posts: Sequence[KilometrePost], where: str) -> tuple[KilometrePost, ...]:
    """The posts that can map chainage to the line's kilometres, sorted by chainage.

    Between two neighbouring posts both the chainage and the kilometre must change strictly,
    the kilometre in the direction most neighbours agree on (it increases along the chainage
    unless the chainage was reversed against the posts). Both posts of every pair that does
    not (a milestone out of order, two kilometres at one place) are dropped, until the
    rest is strictly monotone: interpolating through them would give a flat or backward
    kilometre (a whole stretch labelled with one kilometre). A warning names the dropped posts.
    The same kilometre twice within a metre (a milestone mapped on both tracks) is kept once.

    Parameters
    ----------
    posts : sequence of KilometrePost
    where : str
        What holds the posts (a file name, a track's name), for the warning.

    Returns
    -------
    tuple of KilometrePost
        The usable posts, in order of increasing chainage.

    Warns
    -----
    UserWarning
        When posts are dropped, naming each and the fix.
    """
    kept: list[KilometrePost] = []
    for p in sorted(posts, key=lambda p: p.chainage_m):
        # one milestone mapped twice (on both tracks of a double line, in OpenStreetMap): the
        # same kilometre within a metre is one post, not a pair that drops both
        if kept and p.km_m == kept[-1].km_m and p.chainage_m - kept[-1].chainage_m < _SAME_POST_M:
            continue
        kept.append(p)
    if len(kept) < 2:
        return tuple(kept)
    km = np.array([p.km_m for p in kept])
    direction = 1.0 if np.sum(np.sign(np.diff(km))) >= 0 else -1.0
    dropped: list[KilometrePost] = []
    while len(kept) >= 2:
        cs = np.array([p.chainage_m for p in kept])
        km = np.array([p.km_m for p in kept])
        bad_pair = ~((np.diff(cs) > 0) & (direction * np.diff(km) > 0))
        if not bad_pair.any():
            break
        bad = np.zeros(len(kept), bool)
        bad[:-1] |= bad_pair
        bad[1:] |= bad_pair
        dropped += [p for p, b in zip(kept, bad, strict=True) if b]
        kept = [p for p, b in zip(kept, bad, strict=True) if not b]
    if dropped:
        dropped.sort(key=lambda p: p.chainage_m)
        warnings.warn(
            f"{where}: kilometre posts {', '.join(_post_text(p) for p in dropped)} do not run "
            "strictly along the chainage (duplicated, out of order or at one place): they are "
            f"not used for the line's kilometres ({len(kept)} post(s) kept); correct or remove "
            "them in the track file",
            stacklevel=3,
        )
    return tuple(kept)
