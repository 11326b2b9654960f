"""Chaining the parts of a track map file into one polyline.

A track in a GeoJSON file is rarely one LineString: Infrabel splits a track into sections and
OpenStreetMap into ways that branch at every switch. :func:`chain_all` joins every selected part
end to start (reversing parts as needed) and rejects gaps; :func:`chain_longest` finds the
longest drivable chain through a network of ways; :func:`concatenate_parts` joins the ordered
parts and keeps the vertex spans of tunnel parts. Used by :mod:`predisat.track.readers`; see
``docs/track-map.md``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from predisat.geodesy import LocalFrame
from predisat.readonly import freeze_array_fields
from predisat.track.errors import TrackMapError

__all__ = ["Part", "chain_all", "chain_longest", "concatenate_parts"]


@dataclass(frozen=True)
class Part:
    """One LineString (or one part of a MultiLineString) of a track map file.

    Attributes
    ----------
    label : str
        Where it comes from, for error messages: ``"feature 0 (trackname=A) part 2"``.
    feature : int
        Index of its feature in the file.
    coords : ndarray, shape (k, 2) or (k, 3)
        ``lon_deg, lat_deg[, h_m]`` vertices in file order, ``k >= 2``.
    tunnel : bool
        The feature is tagged as a tunnel (OpenStreetMap ``tunnel=*``).
    bridge : bool
        The feature is tagged as a bridge (OpenStreetMap ``bridge=*``).
    """

    label: str
    feature: int
    coords: NDArray
    tunnel: bool
    bridge: bool = False

    def __post_init__(self) -> None:
        freeze_array_fields(self)


def _endpoints_enu(parts: Sequence[Part], frame: LocalFrame) -> tuple[NDArray, NDArray]:
    heads = np.array([p.coords[0, :2] for p in parts])
    tails = np.array([p.coords[-1, :2] for p in parts])
    return (
        frame.to_enu(heads[:, 1], heads[:, 0])[:, :2],
        frame.to_enu(tails[:, 1], tails[:, 0])[:, :2],
    )


def chain_all(
    parts: Sequence[Part], frame: LocalFrame, max_gap_m: float, path: Path
) -> list[tuple[int, bool]]:
    """Order every part end to start by nearest endpoints.

    Parameters
    ----------
    parts : sequence of Part
    frame : LocalFrame
        Frame in which endpoint gaps are measured (horizontal, metres).
    max_gap_m : float
        Largest gap allowed between the end of one part and the start of the next.
    path : Path
        The file, for error messages.

    Returns
    -------
    list of (int, bool)
        ``(part index, reversed)`` in chain order; the first part in file order runs forward.

    Raises
    ------
    TrackMapError
        A part whose nearest end is farther than ``max_gap_m`` from the chain.
    """
    n = len(parts)
    heads, tails = _endpoints_enu(parts, frame)
    ends = np.concatenate([heads, tails])  # endpoint e: part e % n, tail if e >= n
    dist = np.linalg.norm(ends[:, None] - ends[None], axis=-1)
    same = np.arange(2 * n)[:, None] % n == np.arange(2 * n)[None] % n
    dist[same] = np.inf
    # Start at the most isolated endpoint: the free end of the line.
    start = int(np.argmax(dist.min(axis=1))) if n > 1 else 0
    first = start % n
    order = [(first, start >= n)]  # starting at a tail means the part runs reversed
    used = {first}
    cur = heads[first] if start >= n else tails[first]
    while len(used) < n:
        d_head = np.linalg.norm(heads - cur, axis=1)
        d_tail = np.linalg.norm(tails - cur, axis=1)
        d_head[list(used)] = np.inf
        d_tail[list(used)] = np.inf
        k_h, k_t = int(np.argmin(d_head)), int(np.argmin(d_tail))
        k, rev, gap = (
            (k_h, False, d_head[k_h]) if d_head[k_h] <= d_tail[k_t] else (k_t, True, d_tail[k_t])
        )
        if gap > max_gap_m:
            last = parts[order[-1][0]].label
            raise TrackMapError(
                f"{path}: cannot chain {parts[k].label}: its nearest end is {gap:.1f} m from the "
                f"end of {last} (max_gap_m={max_gap_m}); select one track (track=..., where=...; "
                "command line: --track-name, --where), use chain='longest' (--chain longest) for "
                "a network of ways, or raise max_gap_m (Python only)"
            )
        order.append((k, rev))
        used.add(k)
        cur = heads[k] if rev else tails[k]
    # Keep the file's direction: the first part in file order should run forward.
    if dict(order)[0]:
        order = [(k, not r) for k, r in reversed(order)]
    return order


def chain_longest(
    parts: Sequence[Part], frame: LocalFrame, max_gap_m: float, max_turn_deg: float, path: Path
) -> list[tuple[int, bool]]:
    """Longest drivable chain through a network of ways (no reversal at joints).

    Joints must lie within ``max_gap_m`` and turn by at most ``max_turn_deg``; the search is a
    depth-first enumeration from every part without a predecessor.

    Returns
    -------
    list of (int, bool)
        ``(part index, reversed)`` in chain order, mostly in the ways' own direction.

    Raises
    ------
    TrackMapError
        When the network has too many branches to search (narrow the selection).
    """
    n = len(parts)
    enu = [frame.to_enu(p.coords[:, 1], p.coords[:, 0])[:, :2] for p in parts]
    length = np.array([np.sum(np.linalg.norm(np.diff(e, axis=0), axis=1)) for e in enu])
    # State 2k: part k forward, 2k+1: reversed. Exit point and direction of each state.
    start_pt = np.array([e[0] if r == 0 else e[-1] for e in enu for r in (0, 1)])
    end_pt = np.array([e[-1] if r == 0 else e[0] for e in enu for r in (0, 1)])

    def unit(v: NDArray) -> NDArray:
        return v / max(float(np.linalg.norm(v)), 1e-9)

    start_dir = np.array(
        [unit(e[1] - e[0]) if r == 0 else unit(e[-2] - e[-1]) for e in enu for r in (0, 1)]
    )
    end_dir = np.array(
        [unit(e[-1] - e[-2]) if r == 0 else unit(e[0] - e[1]) for e in enu for r in (0, 1)]
    )
    cos_max = np.cos(np.radians(max_turn_deg))
    gap = np.linalg.norm(end_pt[:, None] - start_pt[None], axis=-1)
    turn_ok = end_dir @ start_dir.T >= cos_max
    succ = (gap <= max_gap_m) & turn_ok
    st = np.arange(2 * n)
    succ[st[:, None] // 2 == st[None] // 2] = False
    nexts = [[int(m) for m in np.flatnonzero(row)] for row in succ]
    has_pred = succ.any(axis=0)
    starts = [int(s) for s in np.flatnonzero(~has_pred)] or list(range(2 * n))

    best: tuple[float, list[int]] = (-1.0, [])
    budget = [200_000]

    def dfs(s: int, used: set[int], acc: float, trail: list[int]) -> None:
        nonlocal best
        budget[0] -= 1
        if budget[0] < 0:
            raise TrackMapError(
                f"{path}: too many branches to search for the longest chain; narrow the "
                "selection with where=... (e.g. {'usage': 'main', 'service': None}; command "
                "line: --where usage=main service=)"
            )
        ext = [m for m in nexts[s] if m // 2 not in used]
        if not ext and acc > best[0]:
            best = (acc, list(trail))
        for m in ext:
            used.add(m // 2)
            trail.append(m)
            dfs(m, used, acc + length[m // 2], trail)
            trail.pop()
            used.discard(m // 2)

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 4 * n + 100))
    try:
        for s in starts:
            dfs(s, {s // 2}, float(length[s // 2]), [s])
    finally:
        sys.setrecursionlimit(limit)
    order = [(s // 2, bool(s % 2)) for s in best[1]]
    if sum(r for _, r in order) > len(order) / 2:  # prefer the file's way direction
        order = [(k, not r) for k, r in reversed(order)]
    return order


def concatenate_parts(
    parts: Sequence[Part],
    order: Sequence[tuple[int, bool]],
    flag: Literal["tunnel", "bridge"] = "tunnel",
) -> tuple[NDArray, list[tuple[int, int]]]:
    """Join ordered parts into one vertex array, dropping shared joint vertices.

    Returns
    -------
    coords : ndarray, shape (n, 2) or (n, 3)
        ``lon_deg, lat_deg[, h_m]``; heights only when every part has them.
    spans : list of (int, int)
        First and last vertex index of every part flagged ``flag`` (tunnel or bridge) in
        ``coords``.
    """
    chunks: list[NDArray] = []
    spans: list[tuple[int, int]] = []
    n = 0
    width = min(parts[k].coords.shape[1] for k, _ in order)
    for idx, (k, rev) in enumerate(order):
        c = parts[k].coords[::-1] if rev else parts[k].coords
        c = c[:, :width]
        if idx > 0 and np.allclose(c[0, :2], chunks[-1][-1, :2], atol=1e-9, rtol=0.0):
            c = c[1:]  # shared joint vertex
            first = n - 1
        else:
            first = n
        chunks.append(c)
        n += len(c)
        if getattr(parts[k], flag):
            spans.append((first, n - 1))
    return np.concatenate(chunks), spans
