"""One facade for satellite positions and clocks: broadcast (RINEX), precise (SP3) or TLE.

``Ephemeris`` answers, for any epochs and satellites at once, where each satellite is (ECEF),
its clock offset, and whether it may be trusted, with the reason when it may not:

* ``UNHEALTHY`` - the broadcast record in force flags the satellite unhealthy (any non-zero
  health; GPS/QZSS accuracy of 6144 m or more, i.e. "no accuracy prediction"; Galileo SISA
  "NAPA");
* ``OUTSIDE_VALIDITY`` - the nearest record is farther from the epoch than the system's validity
  window (:class:`ValidityPolicy`), or the epoch is outside the SP3 or TLE span;
* ``NO_DATA`` - the source has no record at all for that satellite;
* ``MISSING_SAMPLE`` - SP3 has no position in the interpolation window (gap, bad values), or
  SGP4 failed;
* ``INCONSISTENT`` - the broadcast record in force, though flagged healthy, disagrees with most
  of its neighbouring records of the same satellite by more than
  :attr:`ValidityPolicy.consistency_m` (a corrupted record, as found for G01 on 2010-07-01);
  a record with no neighbour in reach is compared with the nearest record of its satellite up
  to a day away (GLONASS: 6 h), more coarsely (:data:`FAR_CONSISTENCY_M`);
* ``UNCHECKED`` - the broadcast record in force is its satellite's only one within a day
  (GLONASS: 6 h):
  nothing can tell it from a corrupted one (an hourly file; a user trial kept only 06:00-07:00
  of that 2010-07-01 file and G01's record put a satellite 20 000 km from the real one at
  35-80 deg above the line). Not trusted unless :attr:`ValidityPolicy.trust_unchecked` (the
  locator checks every satellite against its pseudoranges; the availability report has no
  measurement to do so).

Positions and clocks are NaN wherever the status is not ``OK``; :meth:`Ephemeris.status`
gives the reasons and :meth:`EphemerisStatus.report` a table of every distrusted satellite.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cached_property
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from predisat.geodesy import enu_rotation, enu_to_azel, geodetic_to_ecef
from predisat.gnss.orbits import glonass_state, kepler_state
from predisat.gnss.rinex_nav import NavRecords, read_rinex_nav
from predisat.gnss.sp3 import Sp3, read_sp3
from predisat.gnss.tle import TleSet, read_tle
from predisat.readonly import freeze_array_fields

__all__ = [
    "CNAV_MAX_AGE_S",
    "FAR_CONSISTENCY_M",
    "Ephemeris",
    "EphemerisStatus",
    "Reason",
    "ValidityPolicy",
    "record_disagreement",
]


class Reason(IntEnum):
    """Why a satellite is not trusted at an epoch (0 = trusted)."""

    OK = 0
    NO_DATA = 1
    OUTSIDE_VALIDITY = 2
    UNHEALTHY = 3
    MISSING_SAMPLE = 4
    INCONSISTENT = 5
    UNCHECKED = 6


FAR_CONSISTENCY_M = 10_000.0
"""Two records of a satellite up to :data:`_FAR_GAP_S` apart disagreeing by more than this
(metres, half-way between them) are not of one orbit. Honest records extrapolated a day agree
far better: GPS 128 m median (197 m worst), GLONASS 1.5 km (1.9 km) at 16-48 h against precise
orbits (a user trial, 2026-12-06); a record of another orbit, as G01's, is thousands of
kilometres off."""

CNAV_MAX_AGE_S = 5400.0
"""Largest ``|t - toe|`` of a CNAV record, seconds: half its 3 h curve fit (IS-GPS-200
30.3.3.1.1), assumed centred on toe (the BRUX records of 2026-07-23 were first sent about 1 h
before their toe)."""

# the farthest two records are compared, seconds: each is extrapolated half of it. GLONASS's
# integrated state drifts faster: honest records 20-22 h apart differed by up to 15 km
# (brdc3050.12g, a review), so its records are compared up to 6 h apart only
_FAR_GAP_S = {"kepler": 26 * 3600.0, "glonass": 6 * 3600.0}


def _default_max_age() -> dict[str, float]:
    # half-widths of the validity window around the reference epoch (toe, tb), seconds:
    # GPS: 4 h curve fit centred on toe (IS-GPS-200); QZSS: 2 h fit (IS-QZSS); Galileo: records
    # are refreshed every 10 min to 3 h, 2 h is a conservative age limit (the SDD allows 4 h);
    # BeiDou: hourly updates, +-1 h; IRNSS: as GPS; GLONASS: tb every 30 min, +-15 min (ICD).
    return {"G": 7200.0, "J": 3600.0, "E": 7200.0, "C": 3600.0, "I": 7200.0, "R": 900.0}


@dataclass(frozen=True)
class ValidityPolicy:
    """Validity windows and record preferences of broadcast ephemerides.

    Attributes
    ----------
    max_age_s : mapping of system letter to seconds
        Largest ``|t - toe|`` (GLONASS ``|t - tb|``) at which a record is used.
    use_fit_interval : bool
        Widen the GPS window to half the record's fit interval when that exceeds 4 h.
    galileo_message : {"inav", "fnav"}
        Which Galileo message to prefer when both carry the same toe (positions agree; clocks
        refer to E1/E5b for I/NAV, E1/E5a for F/NAV).
    tle_max_age_s : float
        Largest ``|t - TLE epoch|`` (default 7 days).
    consistency_m : float or None
        A record whose position differs by more than this from most of its (up to four)
        neighbouring records of the same satellite, compared half-way between their reference
        epochs, is not trusted. None disables the check (and the two below).
    trust_unchecked : bool
        Trust a record that no other record of its satellite within a day can check
        (``Reason.UNCHECKED`` otherwise). For a user that checks every satellite against
        measurements (the locator's pseudoranges); never for predictions.
    cnav : {"fallback", "never", "prefer"}
        Use of GPS/QZSS CNAV records (RINEX 4): ``"fallback"`` for satellites with no legacy
        (LNAV) record among the files only, ``"never"``, or ``"prefer"`` (a satellite with CNAV
        records uses only those). The two messages' orbits agree within a metre (G04, G05 on
        2026-07-23); the legacy one stays the default, its clock and TGD conventions being
        the ones every file carries. A CNAV record is used up to :data:`CNAV_MAX_AGE_S` from
        its toe; its group delays (TGD and ISCs) are applied by
        :func:`locator.corrections.cnav_group_delay_s`.
    """

    max_age_s: Mapping[str, float] = field(default_factory=_default_max_age)
    use_fit_interval: bool = True
    galileo_message: str = "inav"
    tle_max_age_s: float = 7 * 86400.0
    consistency_m: float | None = 100.0
    trust_unchecked: bool = False
    cnav: str = "fallback"

    def __post_init__(self) -> None:
        if self.cnav not in ("fallback", "never", "prefer"):
            raise ValueError(f"cnav must be 'fallback', 'never' or 'prefer', got {self.cnav!r}")


@dataclass(frozen=True)
class EphemerisStatus:
    """Trust of each (epoch, satellite) pair.

    Attributes
    ----------
    gps_s : ndarray, shape (n_epoch,)
    sats : tuple of str, length n_sat
    reason : ndarray of int8, shape (n_epoch, n_sat)
        :class:`Reason` values.
    record : ndarray of object, shape (n_epoch, n_sat)
        ``"file:line"`` of the broadcast record used (``""`` for SP3/TLE or none).
    """

    gps_s: NDArray
    sats: tuple[str, ...]
    reason: NDArray
    record: NDArray

    def __post_init__(self) -> None:
        freeze_array_fields(self)

    @property
    def valid(self) -> NDArray:
        """Trusted pairs, bool, shape (n_epoch, n_sat)."""
        return self.reason == Reason.OK

    def report(self) -> pd.DataFrame:
        """Every run of consecutive epochs in which a satellite is not trusted, one row each.

        Columns: ``sat``, ``reason`` (name), ``first_gps_s``, ``last_gps_s``, ``n_epochs``,
        ``record`` (the broadcast record at the run's start, if any).
        """
        rows = []
        for j, sat in enumerate(self.sats):
            r = self.reason[:, j]
            change = np.nonzero(np.diff(r) != 0)[0] + 1
            starts = np.concatenate([[0], change])
            ends = np.concatenate([change, [len(r)]])
            for a, b in zip(starts, ends, strict=True):
                if b > a and r[a] != Reason.OK:
                    rows.append(
                        {
                            "sat": sat,
                            "reason": Reason(int(r[a])).name,
                            "first_gps_s": float(self.gps_s[a]),
                            "last_gps_s": float(self.gps_s[b - 1]),
                            "n_epochs": int(b - a),
                            "record": self.record[a, j],
                        }
                    )
        cols = ["sat", "reason", "first_gps_s", "last_gps_s", "n_epochs", "record"]
        return pd.DataFrame(rows, columns=cols)


def _unhealthy(rec: NavRecords) -> NDArray:
    health = rec.col("health")
    if rec.kind == "kepler" and len(rec):
        # QZSS LNAV: the lowest health bit is L1C/B (formerly LEX), a signal never used here
        # (IS-QZSS-PNT 5.4.1; RTKLIB masks it too): a 2012 file flagged every J01 record so
        qzss = np.array([s[0] == "J" for s in rec.sat])
        clear = np.where(np.isfinite(health), health, 0.0).astype(np.int64) & ~1
        health = np.where(qzss & np.isfinite(health), clear, health)
    bad = np.isnan(health) | (health != 0)
    if rec.kind == "kepler":
        system = np.array([s[0] for s in rec.sat])
        acc = rec.col("accuracy_m")
        bad |= np.isin(system, ["G", "J"]) & (acc >= 6144.0)
        bad |= (system == "E") & (acc < 0)  # SISA "no accuracy prediction available"
        cnav = _cnav_rows(rec)
        if np.any(cnav):
            # CNAV health is three signal bits, L1 (4), L2 (2), L5 (1) (IS-GPS-200 30.3.3.1.1.2):
            # L5 is flagged on every satellite while it is pre-operational, and is not used here
            bits = np.where(np.isfinite(health), health, 7.0).astype(np.int64)
            ura_ed = rec.col("urai_ed")  # 15: no accuracy prediction (as 6144 m in LNAV)
            cnav_bad = ((bits & 0b110) != 0) | ~(ura_ed < 15)
            bad = np.where(cnav, cnav_bad, bad)
    return bad


def _cnav_rows(rec: NavRecords) -> NDArray:
    """GPS/QZSS CNAV records, bool, shape (n,)."""
    if rec.kind != "kepler" or "cnav" not in rec.fields:
        return np.zeros(len(rec), bool)
    return rec.col("cnav") == 1.0


def _message_choice(rec: NavRecords, cnav: str) -> NDArray:
    """Records used under :attr:`ValidityPolicy.cnav`, bool, shape (n,)."""
    is_cnav = _cnav_rows(rec)
    if not np.any(is_cnav):
        return np.ones(len(rec), bool)
    if cnav == "never":
        return ~is_cnav
    if cnav == "prefer":
        return is_cnav | ~np.isin(rec.sat, np.unique(rec.sat[is_cnav]))
    return ~is_cnav | ~np.isin(rec.sat, np.unique(rec.sat[~is_cnav]))


def _preference(rec: NavRecords, galileo_message: str) -> NDArray:
    """Higher is preferred among records of one satellite with the same reference epoch."""
    if rec.kind != "kepler" or len(rec) == 0:
        return np.zeros(len(rec))
    system = np.array([s[0] for s in rec.sat])
    src = np.nan_to_num(rec.col("aux20")).astype(np.int64)
    inav = (src & 0b101) != 0
    fnav = (src & 0b010) != 0
    want = inav if galileo_message == "inav" else fnav
    return np.where((system == "E") & want, 1.0, 0.0)


def _record_windows(rec: NavRecords, policy: ValidityPolicy) -> NDArray:
    max_age = np.array([policy.max_age_s.get(s[0], 0.0) for s in rec.sat])
    if rec.kind == "kepler" and policy.use_fit_interval and len(rec):
        fit_h = rec.col("fit")
        gps = rec.sat.astype("<U1") == "G"
        max_age = np.where(gps & (fit_h > 4.0), fit_h * 1800.0, max_age)
    return np.where(_cnav_rows(rec), np.minimum(max_age, CNAV_MAX_AGE_S), max_age)


def record_disagreement(
    rec: NavRecords, max_age_s: NDArray, horizon: float = 1.0
) -> tuple[NDArray, NDArray, NDArray]:
    """Position differences between neighbouring records of each satellite.

    Each record is compared with the next two records of the same satellite (distinct
    reference epochs), half-way between their reference epochs, when that midpoint lies within
    ``horizon`` times both records' validity half-widths.

    Returns
    -------
    a, b : ndarray of int, shape (n_pairs,)
        Record indices of each compared pair.
    diff_m : ndarray, shape (n_pairs,)
        3-D position difference at the midpoint.
    """
    order = np.lexsort((rec.ref_gps_s, rec.sat))
    a_list, b_list = [], []
    for step in (1, 2):
        a, b = order[:-step], order[step:]
        same = (rec.sat[a] == rec.sat[b]) & (rec.ref_gps_s[b] > rec.ref_gps_s[a])
        half_gap = (rec.ref_gps_s[b] - rec.ref_gps_s[a]) / 2.0
        near = half_gap <= horizon * np.minimum(max_age_s[a], max_age_s[b])
        a_list.append(a[same & near])
        b_list.append(b[same & near])
    a, b = np.concatenate(a_list), np.concatenate(b_list)
    return a, b, _apart_half_way(rec, a, b)


def _inconsistent(
    rec: NavRecords, max_age_s: NDArray, threshold_m: float | None
) -> tuple[NDArray, NDArray]:
    """Records that disagree with most of their compared neighbours, and records no other
    record could be compared with (both all False when the check is off).

    A record no neighbour within the validity horizon reaches is compared with the nearest
    record of its satellite up to ``_FAR_GAP_S`` away, at :data:`FAR_CONSISTENCY_M` (that
    record counts the comparison too: where only the two of them meet, both are distrusted,
    the evidence being contradictory)."""
    bad = np.zeros(len(rec), bool)
    if threshold_m is None or len(rec) < 1:
        return bad, bad.copy()
    a, b, diff = record_disagreement(rec, max_age_s)
    disagree = diff > threshold_m
    n_all = np.bincount(np.concatenate([a, b]), None, len(rec))
    fa, fb, fdiff = _far_disagreement(rec, np.flatnonzero(n_all == 0))
    a, b = np.concatenate([a, fa]), np.concatenate([b, fb])
    disagree = np.concatenate([disagree, fdiff > FAR_CONSISTENCY_M])
    n_dis = np.bincount(np.concatenate([a, b]), np.tile(disagree, 2), len(rec))
    n_all = np.bincount(np.concatenate([a, b]), None, len(rec))
    return n_dis > n_all - n_dis, n_all == 0


def _far_disagreement(rec: NavRecords, rows: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Each record of ``rows`` against the nearest record of its satellite with another
    reference epoch, up to ``_FAR_GAP_S`` away: the pairs and their difference half-way,
    metres (as :func:`record_disagreement`)."""
    if rows.size == 0:
        return rows, rows, np.zeros(0)
    order = np.lexsort((rec.ref_gps_s, rec.sat))
    where = np.empty(len(rec), np.intp)
    where[order] = np.arange(len(rec))
    sat, ref = rec.sat[order], rec.ref_gps_s[order]
    pos = where[rows]
    best = np.full(rows.size, -1, np.intp)
    gap = np.full(rows.size, np.inf)
    for step in (-1, 1):  # the nearest distinct epoch on either side (duplicates skipped)
        k = pos + step
        while True:
            inside = (k >= 0) & (k < len(rec))
            kk = np.clip(k, 0, len(rec) - 1)
            same_epoch = inside & (sat[kk] == sat[pos]) & (ref[kk] == ref[pos])
            if not same_epoch.any():
                break
            k = np.where(same_epoch, k + step, k)
        inside = (k >= 0) & (k < len(rec))
        kk = np.clip(k, 0, len(rec) - 1)
        ok = inside & (sat[kk] == sat[pos])
        g = np.where(ok, np.abs(ref[kk] - ref[pos]), np.inf)
        better = g < gap
        best = np.where(better, kk, best)
        gap = np.where(better, g, gap)
    keep = gap <= _FAR_GAP_S[rec.kind]
    a, b = rows[keep], order[best[keep]]
    return a, b, _apart_half_way(rec, a, b)


def _apart_half_way(rec: NavRecords, a: NDArray, b: NDArray) -> NDArray:
    """3-D distance between the positions records ``a`` and ``b`` give half-way between
    their reference epochs, metres, shape (n_pairs,)."""
    if len(a) == 0:
        return np.zeros(0)
    state = kepler_state if rec.kind == "kepler" else glonass_state
    tm = (rec.ref_gps_s[a] + rec.ref_gps_s[b]) / 2.0
    pa, _ = state(rec, a, tm)
    pb, _ = state(rec, b, tm)
    return np.linalg.norm(pa - pb, axis=-1)


class _RecordChecks(NamedTuple):
    """One record set's epoch-independent checks (:attr:`Ephemeris._record_checks`)."""

    rec: NavRecords
    state: Any
    bad: NDArray
    max_age: NDArray
    odd: NDArray
    unchecked: NDArray
    by_sat: dict[str, tuple[NDArray, NDArray]]


@dataclass(frozen=True)
class Ephemeris:
    """Satellite positions, clocks and trust from one kind of source.

    Build with :meth:`from_rinex`, :meth:`from_sp3` or :meth:`from_tle`.

    Attributes
    ----------
    kind : {"broadcast", "sp3", "tle"}
    satellites : tuple of str
        Every satellite the source knows (``"G05"``, ``"E11"``, ``"C01"``, ``"R07"``).
    sources : tuple of str
        Files read.
    policy : ValidityPolicy
    """

    kind: str
    satellites: tuple[str, ...]
    sources: tuple[str, ...]
    policy: ValidityPolicy
    kepler: NavRecords | None = None
    glonass: NavRecords | None = None
    sp3: Sp3 | None = None
    tle: TleSet | None = None

    # ----------------------------------------------------------------- constructors
    @classmethod
    def from_rinex(
        cls, paths: str | Path | Sequence[str | Path], policy: ValidityPolicy | None = None
    ) -> Ephemeris:
        """Broadcast ephemerides of one or more RINEX 2/3 navigation files (merged)."""
        if isinstance(paths, (str, Path)):
            paths = [paths]
        navs = [read_rinex_nav(p) for p in paths]
        if not navs:
            raise ValueError("from_rinex needs at least one path")
        kep = NavRecords.concat([n.kepler for n in navs])
        glo = NavRecords.concat([n.glonass for n in navs])
        sats = tuple(sorted(set(kep.sat.tolist()) | set(glo.sat.tolist())))
        return cls("broadcast", sats, tuple(n.path for n in navs), policy or ValidityPolicy(),
                   kepler=kep, glonass=glo)  # fmt: skip

    @classmethod
    def from_sp3(cls, paths: str | Path | Sequence[str | Path]) -> Ephemeris:
        """Precise orbits of one or more SP3 files (merged)."""
        sp3 = read_sp3(paths)
        return cls("sp3", sp3.sats, sp3.paths, ValidityPolicy(), sp3=sp3)

    @classmethod
    def from_tle(
        cls,
        path: str | Path,
        names: Mapping[str, str] | None = None,
        policy: ValidityPolicy | None = None,
    ) -> Ephemeris:
        """Coarse orbits from a TLE file (SGP4); ``names`` maps titles/NORAD ids to sat ids."""
        tle = read_tle(path, names)
        return cls("tle", tle.sats, (tle.path,), policy or ValidityPolicy(), tle=tle)

    # ----------------------------------------------------------------- evaluation
    def evaluate(
        self, gps_s: ArrayLike, sats: Sequence[str] | None = None
    ) -> tuple[NDArray, NDArray, EphemerisStatus]:
        """Positions, clocks and status in one pass.

        Parameters
        ----------
        gps_s : array_like, shape (n_epoch,)
        sats : sequence of str, optional
            Default: :attr:`satellites`.

        Returns
        -------
        pos_ecef_m : ndarray, shape (n_epoch, n_sat, 3)
            NaN where not trusted.
        clock_s : ndarray, shape (n_epoch, n_sat)
            NaN where not trusted (and, for SP3, where the clock is missing).
        status : EphemerisStatus
        """
        t = np.atleast_1d(np.asarray(gps_s, float))
        if t.ndim != 1:
            raise ValueError(f"gps_s must be a scalar or 1-D, got shape {t.shape}")
        want = tuple(self.satellites if sats is None else sats)
        n_t, n_s = len(t), len(want)
        pos = np.full((n_t, n_s, 3), np.nan)
        clk = np.full((n_t, n_s), np.nan)
        reason = np.full((n_t, n_s), Reason.NO_DATA, np.int8)
        record = np.full((n_t, n_s), "", object)
        if self.kind == "broadcast":
            self._broadcast(t, want, pos, clk, reason, record)
        elif self.kind == "sp3":
            assert self.sp3 is not None
            p = self.sp3.position_at(t, want)
            c = self.sp3.clock_at(t, want)
            known = np.array([s in self.sp3.sats for s in want], bool)
            ep = self.sp3.epochs_gps_s
            inside = (t >= ep[0]) & (t <= ep[-1])
            reason[:, known] = np.where(
                inside[:, None], Reason.MISSING_SAMPLE, Reason.OUTSIDE_VALIDITY
            )
            ok = known[None, :] & inside[:, None] & np.all(np.isfinite(p), axis=-1)
            reason[ok] = Reason.OK
            pos[ok] = p[ok]
            clk[ok] = c[ok]
        else:
            assert self.tle is not None
            p, err = self.tle.position_ecef(t, want)
            lookup = {s: i for i, s in enumerate(self.tle.sats)}
            for j, s in enumerate(want):
                if s not in lookup:
                    continue
                age = np.abs(t - self.tle.epochs_gps_s[lookup[s]])
                reason[:, j] = np.where(
                    age > self.policy.tle_max_age_s,
                    Reason.OUTSIDE_VALIDITY,
                    np.where(err[:, j] == 0, Reason.OK, Reason.MISSING_SAMPLE),
                )
            ok = reason == Reason.OK
            pos[ok] = p[ok]
        return pos, clk, EphemerisStatus(t, want, reason, record)

    @cached_property
    def _record_checks(self) -> tuple[_RecordChecks, ...]:
        """The checks of every navigation record and each satellite's records, made once: they
        do not depend on the epochs, and redone on every call they took two thirds of a day's
        `locator run` (a scale trial: 25.6 of 38.9 s on NYA1; the records are read-only)."""
        pol = self.policy
        out = []
        for rec, state in ((self.kepler, kepler_state), (self.glonass, glonass_state)):
            if rec is None or len(rec) == 0:
                continue
            use = _message_choice(rec, pol.cnav)
            if not np.all(use):
                rec = rec.take(use)  # rows keep their "file:line" (the locator's key)
            pref = _preference(rec, pol.galileo_message)
            max_age = _record_windows(rec, pol)
            by_sat = {}
            for sat in np.unique(rec.sat).tolist():
                rows = np.nonzero(rec.sat == sat)[0]
                # one record per reference epoch: the preferred message, then the latest listed
                order = np.lexsort((rows, pref[rows], rec.ref_gps_s[rows]))
                rows = rows[order]
                ref = rec.ref_gps_s[rows]
                last = np.ones(len(rows), bool)
                last[:-1] = ref[1:] != ref[:-1]
                by_sat[sat] = (rows[last], ref[last])
            odd, unchecked = _inconsistent(rec, max_age, pol.consistency_m)
            if pol.trust_unchecked:
                unchecked = np.zeros_like(unchecked)
            out.append(_RecordChecks(rec, state, _unhealthy(rec), max_age, odd, unchecked,
                                     by_sat))  # fmt: skip
        return tuple(out)

    def _broadcast(self, t, want, pos, clk, reason, record) -> None:
        for checks in self._record_checks:
            rec, state, bad, max_age, odd, unchecked = (
                checks.rec, checks.state, checks.bad, checks.max_age, checks.odd,
                checks.unchecked)  # fmt: skip
            jobs_i, jobs_e, jobs_s = [], [], []
            for j, sat in enumerate(want):
                if sat not in checks.by_sat:
                    continue
                rows, ref = checks.by_sat[sat]
                k = np.clip(np.searchsorted(ref, t), 1, max(len(ref) - 1, 1))
                if len(ref) == 1:
                    pick = np.zeros(len(t), np.intp)
                else:
                    # nearest reference epoch; on a tie the later (newer) record
                    pick = np.where(np.abs(t - ref[k - 1]) < np.abs(ref[k] - t), k - 1, k)
                r = rows[pick]
                age = np.abs(t - rec.ref_gps_s[r])
                reason[:, j] = np.where(
                    age > max_age[r],
                    Reason.OUTSIDE_VALIDITY,
                    np.where(
                        bad[r],
                        Reason.UNHEALTHY,
                        np.where(odd[r], Reason.INCONSISTENT,
                                 np.where(unchecked[r], Reason.UNCHECKED, Reason.OK)),
                    ),
                )
                record[:, j] = rec.source[r]
                ok = np.nonzero(reason[:, j] == Reason.OK)[0]
                jobs_i.append(r[ok])
                jobs_e.append(ok)
                jobs_s.append(np.full(len(ok), j))
            if not jobs_i:
                continue
            ri, ei, si = (np.concatenate(a) for a in (jobs_i, jobs_e, jobs_s))
            if len(ri):
                p, c = state(rec, ri, t[ei])
                pos[ei, si] = p
                clk[ei, si] = c

    def position_ecef(self, gps_s: ArrayLike, sats: Sequence[str] | None = None) -> NDArray:
        """ECEF positions, shape (n_epoch, n_sat, 3), metres; NaN where not trusted."""
        return self.evaluate(gps_s, sats)[0]

    def clock_s(self, gps_s: ArrayLike, sats: Sequence[str] | None = None) -> NDArray:
        """Satellite clock offsets, shape (n_epoch, n_sat), seconds; NaN where not trusted."""
        return self.evaluate(gps_s, sats)[1]

    def status(self, gps_s: ArrayLike, sats: Sequence[str] | None = None) -> EphemerisStatus:
        """Trust and reasons for every (epoch, satellite); see :class:`EphemerisStatus`."""
        return self.evaluate(gps_s, sats)[2]

    def valid(self, gps_s: ArrayLike, sats: Sequence[str] | None = None) -> NDArray:
        """Trusted (epoch, satellite) pairs, bool, shape (n_epoch, n_sat)."""
        return self.status(gps_s, sats).valid

    def azel(
        self,
        gps_s: ArrayLike,
        lat_deg: ArrayLike,
        lon_deg: ArrayLike,
        h_m: ArrayLike = 0.0,
        sats: Sequence[str] | None = None,
    ) -> tuple[NDArray, NDArray]:
        """Azimuth and elevation of the satellites seen from receiver positions.

        Geometric directions at the epoch (light time and aberration neglected: under 0.0012
        deg for GNSS orbits).

        Parameters
        ----------
        gps_s : array_like, shape (n_epoch,)
        lat_deg, lon_deg, h_m : array_like, shape (...)
            Receiver positions (WGS84).
        sats : sequence of str, optional

        Returns
        -------
        az_deg, el_deg : ndarray, shape (..., n_epoch, n_sat)
            NaN where the satellite is not trusted.
        """
        sat_ecef = self.position_ecef(gps_s, sats)
        rx = geodetic_to_ecef(lat_deg, lon_deg, h_m)
        rot = enu_rotation(lat_deg, lon_deg)  # (..., 3, 3)
        d = sat_ecef - rx[..., None, None, :]
        enu = np.einsum("...ij,...tsj->...tsi", rot, d)
        az, el, _ = enu_to_azel(enu)
        return az, el
