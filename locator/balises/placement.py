"""Where a virtual balise may be placed: the predicted fused interval against ``Q_LOCACC``.

A planning rule, not a capture rule: a virtual balise is captured only when the fused interval
reaches at most ``Q_LOCACC`` (63 m) from the estimate (:mod:`locator.balises.capture`), so a
balise is worth placing only where the interval is predicted to be that tight whichever way the
train runs. Inside a satellite outage (a tunnel) the odometer carries the interval from the
portal the train entered by: its reach there is the reach at the portal plus the odometer's
doubt over the distance since (``max(D_DOUBTOVER, D_DOUBTUNDER)``, the bound that grows the
interval's longer side). Outside outages the reach is the portal's (the satellites keep it).

The prediction holds for a train that was located before the outage; a start of mission inside
an outage (position known only to the stored start uncertainty) is not a placement question.

:func:`place_balises` applies the rule to candidates every so many metres along a track map and
returns the placeable ones as a :class:`~locator.balises.balisefile.BaliseList` (the
``locator place-balises`` command, :mod:`locator.balises.place_command`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from locator.balises.balisefile import BaliseList
from locator.balises.capture import Q_LOCACC_MAX_M
from locator.odometry.confidence import OdometerAccuracy
from predisat.track import TrackMap

__all__ = ["place_balises", "placement_check", "predicted_reach_m"]


def predicted_reach_m(
    chainage_m: ArrayLike,
    outages_m: Sequence[tuple[float, float]],
    accuracy: OdometerAccuracy,
    entry_reach_m: float,
) -> NDArray:
    """Predicted reach of the fused interval about the estimate, worst of both directions.

    Parameters
    ----------
    chainage_m : array_like, shape (n,)
        Balise chainages, m.
    outages_m : sequence of (start_m, end_m)
        Stretches without satellite claims (tunnels), chainage, ``start < end``.
    accuracy : OdometerAccuracy
        The odometer's bounds.
    entry_reach_m : float
        Reach of the fused interval where the outage begins (e.g. the open-sky p95), m.

    Returns
    -------
    ndarray, shape (n,)
        ``entry_reach_m + max(D_DOUBTOVER, D_DOUBTUNDER)(d)`` with ``d`` the distance since the
        portal entered, the larger of the two directions; ``entry_reach_m`` outside outages.
    """
    b = np.asarray(chainage_m, float)
    if not entry_reach_m >= 0:
        raise ValueError(f"entry_reach_m must be >= 0, got {entry_reach_m}")
    d_in = np.zeros(b.shape)
    for start, end in outages_m:
        if not start < end:
            raise ValueError(f"outage ({start}, {end}): start must be below end")
    for start, end in _joined(outages_m):
        # overlapping or touching outages are one: no satellite between them to reset the
        # reach (a map's tunnel and an --outage over its approach, a tunnel in two pieces
        # were each taken from their own portals: 48 m predicted for 78 m, m8)
        inside = (b >= start) & (b <= end)
        d_in = np.where(inside, np.maximum(d_in, np.maximum(b - start, end - b)), d_in)
    doubt = np.maximum(accuracy.doubt_over_m(d_in), accuracy.doubt_under_m(d_in))
    return np.where(d_in > 0, entry_reach_m + doubt, entry_reach_m)


def placement_check(
    chainage_m: ArrayLike,
    accuracy_m: ArrayLike,
    outages_m: Sequence[tuple[float, float]],
    accuracy: OdometerAccuracy,
    entry_reach_m: float,
    max_locacc_m: float = Q_LOCACC_MAX_M,
) -> tuple[NDArray, NDArray]:
    """Per balise: the predicted telegram accuracy and whether it fits ``Q_LOCACC``.

    Parameters
    ----------
    chainage_m, accuracy_m : array_like, shape (n,)
        Balise chainages and survey accuracies, m.
    outages_m, accuracy, entry_reach_m
        As :func:`predicted_reach_m`.
    max_locacc_m : float
        The largest accuracy a telegram may state, m (63: ``Q_LOCACC``'s 6 bits).

    Returns
    -------
    q_m : ndarray, shape (n,)
        Predicted stated accuracy (reach + survey accuracy, rounded up to the metre), m.
    placeable : ndarray of bool, shape (n,)
        ``q_m <= max_locacc_m``.
    """
    reach = predicted_reach_m(chainage_m, outages_m, accuracy, entry_reach_m)
    q = np.ceil(reach + np.asarray(accuracy_m, float) - 1e-9)
    return q, q <= max_locacc_m


def place_balises(
    track: TrackMap,
    start_m: float,
    stop_m: float,
    spacing_m: float,
    outages_m: Sequence[tuple[float, float]],
    accuracy: OdometerAccuracy,
    entry_reach_m: float,
    *,
    accuracy_m: float = 1.0,
    max_locacc_m: float = Q_LOCACC_MAX_M,
    prefix: str = "VB",
) -> tuple[BaliseList, pd.DataFrame]:
    """Candidate balises every ``spacing_m`` along a track, kept where the rule places them.

    Parameters
    ----------
    track : predisat.track.TrackMap
    start_m, stop_m, spacing_m : float
        Candidates every ``spacing_m`` from ``start_m`` up to ``stop_m`` (chainage), m.
    outages_m, accuracy, entry_reach_m
        As :func:`predicted_reach_m`.
    accuracy_m : float
        Survey accuracy of every balise (its ``accuracy_m``), m.
    max_locacc_m : float
        The largest accuracy a telegram may state, m (at most 63: ``Q_LOCACC``).
    prefix : str
        Ids are ``prefix`` plus the candidate's running number, placed or not (a balise keeps
        its id when the rule's inputs change).

    Returns
    -------
    placed : BaliseList
        The placeable candidates, as :meth:`BaliseList.to_csv` writes and ``locator balises
        --balises`` reads them (may be empty).
    table : pandas.DataFrame
        Every candidate: ``id``, ``chainage_m``, ``in_outage``, ``predicted_q_m`` (the
        telegram accuracy predicted by :func:`placement_check`), ``placeable``.
    """
    if not 0.0 < max_locacc_m <= Q_LOCACC_MAX_M:
        raise ValueError(f"max_locacc_m {max_locacc_m:g} must lie in (0, {Q_LOCACC_MAX_M:g}] m "
                         "(Q_LOCACC has 6 bits of 1 m)")  # fmt: skip
    if not 0.0 <= accuracy_m < max_locacc_m:
        raise ValueError(f"accuracy_m {accuracy_m:g} must lie in [0, {max_locacc_m:g}) m: a "
                         "balise surveyed that badly could never be captured")  # fmt: skip
    cand = BaliseList.along_track(track, start_m, stop_m, spacing_m, prefix=prefix,
                                  accuracy_m=accuracy_m)  # fmt: skip
    c = np.asarray(cand.chainage_m, float)
    q, ok = placement_check(c, cand.accuracy_m, outages_m, accuracy, entry_reach_m,
                            max_locacc_m)  # fmt: skip
    inside = np.zeros(c.shape, bool)
    for lo, hi in outages_m:
        inside |= (c >= lo) & (c <= hi)
    keep = np.flatnonzero(ok)
    placed = BaliseList(
        tuple(cand.ids[k] for k in keep), c[keep], cand.lat_deg[keep], cand.lon_deg[keep],
        cand.h_m[keep], tuple(cand.telegram[k] for k in keep), cand.q_reference[keep],
        cand.accuracy_m[keep],
        f"placed by the placement rule (Q_LOCACC <= {max_locacc_m:g} m) from {cand.source}",
    )  # fmt: skip
    table = pd.DataFrame({"id": list(cand.ids), "chainage_m": c, "in_outage": inside,
                          "predicted_q_m": q, "placeable": ok})  # fmt: skip
    return placed, table


def _joined(outages_m: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The outages with overlapping or touching ones joined, in chainage order."""
    out: list[list[float]] = []
    for start, end in sorted((float(a), float(b)) for a, b in outages_m):
        if out and start <= out[-1][1]:
            out[-1][1] = max(out[-1][1], end)
        else:
            out.append([start, end])
    return [(a, b) for a, b in out]
