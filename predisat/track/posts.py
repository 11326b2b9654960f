"""Kilometre posts: the line's own kilometre references, kept at their chainage on a track.

:func:`points_as_posts` reads them from GeoJSON point features (a ``km_m`` property, or
OpenStreetMap ``railway=milestone`` nodes); :func:`project_posts` places them on a track map.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.jsontypes import JsonDict

__all__ = ["KilometrePost", "points_as_posts", "project_posts"]


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
