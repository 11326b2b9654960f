"""The vehicle's attitude at each frame: measured, or bounded from the track (section 16 of
``docs/reconstruction.md``).

The rectification takes the vehicle frame as level. On a canted curve the body rolls by up to
7-9 deg and on a grade it pitches by a degree or two, so a side camera's skyline reads low on
one side by about that angle: false trust. Each frame therefore gets

* a *nominal* attitude, by which its mount is turned into the level frame
  (:meth:`predisat.camera.models.Mount.on_vehicle`): the manifest's measured roll and pitch
  (an IMU's), else the middle of the interval the track allows;
* a *doubt*, the angle its true attitude may still be off by: the IMU's stated accuracy, else
  half the interval's width. The frame's sky is eroded by it
  (:func:`predisat.reconstruct.skyline.erode_sky_deg`), so that no sky pixel whose true
  direction might be an obstacle clears anything.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import tilt_doubt_m
from predisat.track import TrackMap
from predisat.track.cant import (
    CantLimits,
    CantTable,
    equilibrium_cant_mm,
    inside_roll_sign,
    roll_bounds_deg,
)

__all__ = [
    "ATTITUDE_STEP_DEG",
    "CANT_DEFICIENCY_TOL_MM",
    "CANT_ON_SHARP_MM",
    "CANT_TABLE_FLOOR_MM",
    "CHAINAGE_STEP_M",
    "CURVE_WINDOW_M",
    "STRAIGHT_PER_M",
    "FrameAttitude",
    "frame_attitudes",
    "level_attitudes",
    "survey_speed_kmh",
]

CURVE_WINDOW_M = 150.0
"""An unmeasured roll is bounded by the sharpest curve within this distance: a curve's cant
ramps in over its transition (and on older curves without one, over the straight before
it), where the smoothed map's curvature reads low (EN 13803: cant gradients down to 1:400,
so 160 mm over 64 m; twice that for the smoothing)."""
STRAIGHT_PER_M = 1e-4
"""Curvature under which the track counts as straight (R > 10 km): no cant to speak of."""
_SHARP_PER_M = 1e-3  # R < 1 km: a curve of a line run above 40 km/h carries cant
CANT_ON_SHARP_MM = 5.0
"""A cant-table value under this on a curve sharper than R = 1 km reads as metres or a missing
value: it is not used."""
CANT_TABLE_FLOOR_MM = 20.0
"""A cant table whose largest value on the frames' curves sharper than R = 1 km is under this
is not used at all (a table in centimetres: a curve that sharp on a line run above 40 km/h
carries at least its equilibrium cant's 19 mm)."""
CANT_DEFICIENCY_TOL_MM = 100.0
"""How far past ``CantLimits.max_deficiency_mm`` a cant table may put the survey vehicle's
deficiency before its value is ruled out: the map's smoothed curvature, a transition's
chainage and a tilting train's larger deficiency (up to 300 mm) stay within it."""
_LEVEL_DEG = 0.5  # a measured roll this near level on such a curve: radians, or a tilt sensor
_ROLL_TOL_DEG = 1.0  # a measured roll this far outside the track's interval contradicts it
_DISTRUST_SHARE = 0.2  # ruled out on this share of the frames on curves: no roll is trusted

ATTITUDE_STEP_DEG = 0.05
"""Nominal attitudes are rounded to this step, so that frames on a curve share rectifiers
(the rounding, 0.025 deg at most, is a fifth of the rectification grid's elevation step)."""


@dataclass(frozen=True, eq=False)
class FrameAttitude:
    """Nominal attitude and doubt of frames, degrees, shape (n,) each.

    ``roll_deg`` positive raises the vehicle's left side, ``pitch_deg`` its nose (directions
    of travel, as the mount); ``measured`` is True where the manifest gave them and the track
    agrees. ``contradicted`` marks frames whose measured roll the track rules out, or all the
    measured frames when it rules out more than a fifth of those on curves (one IMU mistake is
    everywhere; bounded instead), ``table_ignored`` frames whose cant-table value it rules out
    (shape (n,) each). ``doubt_deg`` is the largest angle between the true and the nominal
    attitude (the rays' erosion), ``roll_doubt_deg`` and ``pitch_doubt_deg`` its two parts
    (the cameras' move, :func:`~predisat.camera.models.tilt_doubt_m`); None: each
    ``doubt_deg``. ``imu_distrusted`` and ``table_distrusted`` say whether the whole IMU or
    the whole cant table was set aside (:func:`frame_attitudes`' ``verdicts``).
    """

    roll_deg: NDArray
    pitch_deg: NDArray
    doubt_deg: NDArray
    measured: NDArray
    contradicted: NDArray | None = None
    table_ignored: NDArray | None = None
    roll_doubt_deg: NDArray | None = None
    pitch_doubt_deg: NDArray | None = None
    # the two whole-survey verdicts: no measured roll trusted (one IMU mistake everywhere), no
    # cant-table value used (its unit wrong); a run takes them once for its whole survey
    imu_distrusted: bool = False
    table_distrusted: bool = False

    def camera_doubt_m(
        self, k: int, lever_arm_m: ArrayLike, antenna_height_m: float
    ) -> tuple[float, float, float]:
        """How far frame ``k``'s camera (``lever_arm_m`` from the antenna, vehicle frame) may
        stand from where its nominal attitude puts it: along, across, up, metres
        (:func:`~predisat.camera.models.tilt_doubt_m`, each part of the doubt ``doubt_deg``
        where it is not split)."""
        roll = self.doubt_deg if self.roll_doubt_deg is None else self.roll_doubt_deg
        pitch = self.doubt_deg if self.pitch_doubt_deg is None else self.pitch_doubt_deg
        return tilt_doubt_m(lever_arm_m, antenna_height_m, float(self.roll_deg[k]),
                            float(self.pitch_deg[k]), float(roll[k]), float(pitch[k]))  # fmt: skip


def frame_attitudes(
    track: TrackMap,
    chainage_m: ArrayLike,
    roll_deg: ArrayLike,
    pitch_deg: ArrayLike,
    reverse: bool,
    *,
    cant: CantLimits | None = None,
    grade_doubt_deg: float = 2.3,
    imu_doubt_deg: float = 0.0,
    cant_table: CantTable | None = None,
    speed_kmh: ArrayLike | None = None,
    chainage_doubt_m: float = 0.0,
    verdicts: tuple[bool, bool] | None = None,
) -> FrameAttitude:
    """The attitude each frame is rectified with, and what it may still be off by.

    Parameters
    ----------
    track : TrackMap
    chainage_m : array_like, shape (n,)
    roll_deg, pitch_deg : array_like, shape (n,)
        Measured vehicle attitude (``Frames.roll_deg, pitch_deg``); NaN where not measured.
    reverse : bool
        The survey drives toward decreasing chainage.
    cant : CantLimits, optional
        Bounds the roll where it is not measured (from the track's curvature).
    grade_doubt_deg : float
        Where the pitch is not measured it is taken from the track map's grade (0 for a map
        without heights), give or take this angle.
    imu_doubt_deg : float
        Accuracy of the measured roll and pitch, degrees (each).
    cant_table : CantTable, optional
        The cant where the infrastructure's records give it: the unmeasured roll is then
        bounded around it (NaN outside the table: from the curvature).
    speed_kmh : array_like, shape (n,), optional
        The survey vehicle's speed at the frames (:func:`survey_speed_kmh`), NaN where not
        known: it fixes the body's roll on its springs to one side.
    chainage_doubt_m : float
        How far each frame's true chainage may be from ``chainage_m``, metres (the survey's
        positioning, ``docs/reconstruction.md`` section 18): the track's bounds and the cant
        table are read anywhere within it, and each angle's interval is the union of those
        found every :data:`CHAINAGE_STEP_M` and at both ends.
    verdicts : (bool, bool), optional
        Whether the whole IMU and the whole cant table are set aside, as decided over the
        whole survey (its :class:`FrameAttitude`'s ``imu_distrusted``, ``table_distrusted``):
        frames read in windows (a run's chunks) then get the survey's decision, not each
        window's (a review: a frame read by two chunks could be rectified two ways). By
        default decided over these frames.

    Returns
    -------
    FrameAttitude
        Nominal angles rounded to :data:`ATTITUDE_STEP_DEG`, the rounding added to a doubt
        that is not 0.
    """
    if not (np.isfinite(chainage_doubt_m) and chainage_doubt_m >= 0.0):
        raise ValueError(f"chainage_doubt_m must be a length >= 0 metres, got {chainage_doubt_m}")
    if chainage_doubt_m > 0.0:
        return _attitudes_over_chainage(
            track, chainage_m, roll_deg, pitch_deg, reverse, chainage_doubt_m, cant=cant,
            grade_doubt_deg=grade_doubt_deg, imu_doubt_deg=imu_doubt_deg,
            cant_table=cant_table, speed_kmh=speed_kmh, verdicts=verdicts,
        )  # fmt: skip
    s = np.asarray(chainage_m, float)
    roll = np.broadcast_to(np.asarray(roll_deg, float), s.shape)
    pitch = np.broadcast_to(np.asarray(pitch_deg, float), s.shape)
    for name, v in (("grade_doubt_deg", grade_doubt_deg), ("imu_doubt_deg", imu_doubt_deg)):
        if not (np.isfinite(v) and 0.0 <= v < 10.0):
            raise ValueError(f"{name} must be an angle in [0, 10) degrees, got {v}")
    given = np.isfinite(roll) & np.isfinite(pitch)
    known = None if cant_table is None else cant_table.cant_mm_at(s)
    speed = None if speed_kmh is None else np.broadcast_to(np.asarray(speed_kmh, float), s.shape)
    # the track's own interval, with a table value it rules out dropped (a table in metres,
    # or zeros over a sharp curve)
    r_lo, r_hi, sharp = _roll_interval(track, s, reverse, cant, known, speed)
    table_ignored = np.zeros(s.shape, bool)
    table_distrusted = False
    if known is not None:
        table_ignored, table_distrusted = _implausible_cant(
            track, s, known, sharp, speed, cant or CantLimits(),
            None if verdicts is None else verdicts[1],
        )  # fmt: skip
        if table_ignored.any():
            known = np.where(table_ignored, np.nan, known)
            r_lo, r_hi, sharp = _roll_interval(track, s, reverse, cant, known, speed)
    if not np.all(np.isfinite(r_lo) & np.isfinite(r_hi)):
        bad = s[~(np.isfinite(r_lo) & np.isfinite(r_hi))]
        raise ValueError(
            f"no attitude bound at chainage {bad[0]:.1f} m ({bad.size} frames): the track "
            "map gives no curvature there; check the frames' chainages"
        )
    # a measured roll the track rules out is a mistake (sign, radians, an accelerometer's
    # apparent vertical): bounded instead, as if not measured
    tol = _ROLL_TOL_DEG + imu_doubt_deg
    level_on_sharp = (
        sharp
        & (np.abs(roll) < _LEVEL_DEG)
        & (np.ones(s.shape, bool) if known is None else ~np.isfinite(known))
    )
    contradicted = given & ((roll < r_lo - tol) | (roll > r_hi + tol) | level_on_sharp)
    # One IMU mistake (axes, units, a tilt sensor) is everywhere: when the track rules out the
    # roll of more than a fifth of the frames on curves, none of its rolls is trusted.
    curved = given & (np.abs(np.asarray(track.curvature_at(s), float)) > STRAIGHT_PER_M)
    imu_distrusted = (bool(contradicted.sum() > _DISTRUST_SHARE * max(int(curved.sum()), 1))
                      if verdicts is None else bool(verdicts[0]))  # fmt: skip
    if imu_distrusted:
        contradicted = given.copy()
    measured = given & ~contradicted
    out_roll = np.where(measured, roll, 0.5 * (r_lo + r_hi))
    grade_deg = np.degrees(np.arctan(np.asarray(track.grade_at(s), float)))
    out_pitch = np.where(measured, pitch, -grade_deg if reverse else grade_deg)
    out_pitch = np.where(contradicted, pitch, out_pitch)  # the pitch was not contradicted
    roll_doubt = np.where(measured, imu_doubt_deg, 0.5 * (r_hi - r_lo))
    # a roll ruled out is bounded, and its IMU's doubt kept on top (as before the split)
    roll_doubt = np.where(contradicted, roll_doubt + imu_doubt_deg, roll_doubt)
    pitch_doubt = np.where(measured | contradicted, imu_doubt_deg, grade_doubt_deg)
    q_roll = np.round(out_roll / ATTITUDE_STEP_DEG) * ATTITUDE_STEP_DEG
    q_pitch = np.round(out_pitch / ATTITUDE_STEP_DEG) * ATTITUDE_STEP_DEG
    # A doubt takes the rounding in; with none (an attitude taken as exact) the rounding,
    # 0.05 deg at most, is under half a pixel of the shipped cameras and under the
    # rectification grid's step, which the rectifier's obstacle growth covers.
    sure = (roll_doubt + pitch_doubt) == 0
    roll_doubt = np.where(sure, 0.0, roll_doubt + np.abs(q_roll - out_roll))
    pitch_doubt = np.where(sure, 0.0, pitch_doubt + np.abs(q_pitch - out_pitch))
    # a turn about the roll axis then the pitch axis is within the sum of the two angles
    return FrameAttitude(q_roll + 0.0, q_pitch + 0.0, roll_doubt + pitch_doubt, measured,
                         contradicted, table_ignored, roll_doubt, pitch_doubt,
                         imu_distrusted, table_distrusted)  # fmt: skip


CHAINAGE_STEP_M = 0.25
"""Step at which :func:`frame_attitudes` reads the track over a chainage doubt. Between two
readings a bound moves by about its change between neighbouring readings (its slope times a
step), or jumps at a curve's threshold to a value the readings either side hold; but it may
reach an extreme just before a jump, which no reading holds (a review found the roll's lower
bound 0.02 deg past the union that way). Each interval is therefore widened by the bound's
largest change between neighbouring readings, jumps of over :data:`_JUMP_DEG` left out, plus
:data:`_BETWEEN_STEPS_DEG` (tested every 2 cm on the demo line and on a track of R = 150 m)."""
_BETWEEN_STEPS_DEG = 0.01
_JUMP_DEG = 0.5


def _attitudes_over_chainage(
    track: TrackMap,
    chainage_m: ArrayLike,
    roll_deg: ArrayLike,
    pitch_deg: ArrayLike,
    reverse: bool,
    chainage_doubt_m: float,
    **kwargs: Any,
) -> FrameAttitude:
    """:func:`frame_attitudes` of frames whose chainage is known within ``chainage_doubt_m``:
    the union, per angle, of the intervals found at the offsets."""
    s = np.asarray(chainage_m, float)
    n_steps = max(int(np.ceil(2.0 * chainage_doubt_m / CHAINAGE_STEP_M)), 1)
    parts = [
        frame_attitudes(track, s + e, roll_deg, pitch_deg, reverse, **kwargs)
        for e in np.linspace(-chainage_doubt_m, chainage_doubt_m, n_steps + 1)
    ]
    roll_doubt = [a.doubt_deg if a.roll_doubt_deg is None else a.roll_doubt_deg for a in parts]
    pitch_doubt = [a.doubt_deg if a.pitch_doubt_deg is None else a.pitch_doubt_deg for a in parts]
    angles = []
    for mid, half in (([a.roll_deg for a in parts], roll_doubt),
                      ([a.pitch_deg for a in parts], pitch_doubt)):  # fmt: skip
        lo_s = np.asarray(mid) - np.asarray(half)  # (offsets, frames)
        hi_s = np.asarray(mid) + np.asarray(half)
        lo, hi = lo_s.min(axis=0), hi_s.max(axis=0)
        change = np.abs(np.concatenate([np.diff(lo_s, axis=0), np.diff(hi_s, axis=0)]))
        slope = np.where(change <= _JUMP_DEG, change, 0.0).max(axis=0, initial=0.0)
        # an exact angle stays exact
        slack = np.where(hi - lo > 0.0, _BETWEEN_STEPS_DEG + slope, 0.0)
        lo, hi = lo - slack, hi + slack
        q = np.round(0.5 * (lo + hi) / ATTITUDE_STEP_DEG) * ATTITUDE_STEP_DEG
        doubt = np.maximum(hi - q, q - lo)  # the rounding taken in
        angles.append((q + 0.0, np.where(hi - lo == 0.0, 0.0, doubt)))
    (roll, r_doubt), (pitch, p_doubt) = angles
    return FrameAttitude(
        roll, pitch, r_doubt + p_doubt,
        np.all([a.measured for a in parts], axis=0),
        np.any([_flags(a.contradicted, s) for a in parts], axis=0),
        np.any([_flags(a.table_ignored, s) for a in parts], axis=0),
        r_doubt, p_doubt,
        any(a.imu_distrusted for a in parts), any(a.table_distrusted for a in parts),
    )  # fmt: skip


def _flags(values: NDArray | None, like: NDArray) -> NDArray:
    """``values``, or all False shaped like ``like`` for None."""
    return np.zeros(like.shape, bool) if values is None else values


def level_attitudes(
    track: TrackMap, chainage_m: ArrayLike, *args: object, **kwargs: object
) -> FrameAttitude:
    """Every frame level and sure, whatever it is given: the pipeline before the vehicle's
    attitude counted (section 16), for comparisons. Takes :func:`frame_attitudes`' arguments,
    so that it can stand in for it."""
    z = np.zeros(np.asarray(chainage_m, float).shape)
    return FrameAttitude(z, z, z, np.ones(z.shape, bool))


def survey_speed_kmh(chainage_m: ArrayLike, gps_s: ArrayLike, side: ArrayLike) -> NDArray:
    """Each frame's speed along the track from its camera's neighbouring frames, km/h.

    Parameters
    ----------
    chainage_m, gps_s, side : array_like, shape (n,)
        The frames' chainage, time and camera (``Frames`` columns); frames of one camera are
        taken in time order.

    Returns
    -------
    ndarray, shape (n,)
        ``|d chainage / d t|`` by central differences over the camera's frames (one-sided at
        its ends); NaN for a camera with fewer than two timed frames, or a NaN chainage.
    """
    s = np.asarray(chainage_m, float)
    t = np.asarray(gps_s, float)
    cam = np.asarray(side)
    out = np.full(s.shape, np.nan)
    for c in np.unique(cam):
        idx = np.flatnonzero((cam == c) & np.isfinite(s) & np.isfinite(t))
        if idx.size < 2:
            continue
        idx = idx[np.argsort(t[idx], kind="stable")]
        ts, ss = t[idx], s[idx]
        if np.any(np.diff(ts) <= 0):
            continue  # repeated times: no speed to trust
        out[idx] = np.abs(np.gradient(ss, ts)) * 3.6
    return out


def _implausible_cant(
    track: TrackMap,
    chainage_m: NDArray,
    cant_mm: NDArray,
    sharp: NDArray,
    speed_kmh: NDArray | None,
    limits: CantLimits,
    whole: bool | None = None,
) -> tuple[NDArray, bool]:
    """Frames whose cant-table value the track or the survey's own run rules out, shape (n,),
    and whether that is the whole table (``whole``, when given, decides it instead):
    under :data:`CANT_ON_SHARP_MM` on a curve sharper than R = 1 km (a table in metres, a
    missing value written 0), or so low that the survey vehicle, at its speed there, would
    have run with more than :data:`CANT_DEFICIENCY_TOL_MM` beyond the largest deficiency
    trains run with (a table in centimetres, or another track's). When that rules out more
    than a fifth of the frames on curves, the whole table is (its unit is wrong)."""
    known = np.isfinite(cant_mm)
    out = sharp & known & (cant_mm < CANT_ON_SHARP_MM)
    k = np.abs(np.asarray(track.curvature_at(chainage_m), float))
    if speed_kmh is not None:
        with np.errstate(invalid="ignore"):
            deficiency = equilibrium_cant_mm(k, speed_kmh) - cant_mm
            out |= known & (deficiency > limits.max_deficiency_mm + CANT_DEFICIENCY_TOL_MM)
    if whole is None:
        curved = known & (k > STRAIGHT_PER_M)
        whole = bool(out.sum() > _DISTRUST_SHARE * max(int(curved.sum()), 1))
        # a unit check that needs no speed: a line canted for trains faster than 40 km/h puts
        # 20 mm or more on its curves sharper than R = 1 km; a table whose largest value there
        # is under that is in centimetres (a review: 150 mm written 15 passed at 60 km/h, the
        # true roll up to 5.7 deg outside the bound)
        on_sharp = sharp & known
        whole |= bool(on_sharp.any() and float(np.max(cant_mm[on_sharp])) < CANT_TABLE_FLOOR_MM)
    return (known.copy() if whole else out), whole


def _roll_interval(
    track: TrackMap,
    chainage_m: NDArray,
    reverse: bool,
    cant: CantLimits | None,
    cant_mm: NDArray | None,
    speed_kmh: NDArray | None,
) -> tuple[NDArray, NDArray, NDArray]:
    """The vehicle's roll (positive raising its left side) an unmeasured frame may have,
    degrees, shape (n,) each: the union over the curves of each hand within
    :data:`CURVE_WINDOW_M` (a cant ramps in before its curve, where the smoothed map's
    curvature reads low or of the other hand), or track roll only on straight track; and
    whether the frame stands on a curve sharper than R = 1 km."""
    offsets = np.arange(-CURVE_WINDOW_M, CURVE_WINDOW_M + 1e-9, 5.0)
    near = np.clip(chainage_m[:, None] + offsets, 0.0, float(track.length_m))
    k = np.asarray(track.curvature_at(near.ravel()), float).reshape(near.shape)
    k = np.concatenate([k, np.asarray(track.curvature_at(chainage_m), float)[:, None]], axis=1)
    left = np.max(np.maximum(k, 0.0), axis=1)  # curves turning left toward increasing chainage
    right = np.max(np.maximum(-k, 0.0), axis=1)
    here = np.abs(k[:, -1])
    lo = np.full(chainage_m.shape, np.inf)
    hi = np.full(chainage_m.shape, -np.inf)
    for kk, present in ((left, left > STRAIGHT_PER_M), (-right, right > STRAIGHT_PER_M)):
        a, b = roll_bounds_deg(kk, cant, cant_mm=cant_mm, speed_kmh=speed_kmh)  # inward
        sign = inside_roll_sign(kk, reverse)
        r1, r2 = sign * a, sign * b
        lo = np.where(present, np.minimum(lo, np.minimum(r1, r2)), lo)
        hi = np.where(present, np.maximum(hi, np.maximum(r1, r2)), hi)
    # no curve of either hand near: the roll may go either way
    a, b = roll_bounds_deg(np.maximum(left, right), cant, cant_mm=cant_mm, speed_kmh=speed_kmh)
    edge = np.maximum(np.abs(a), np.abs(b))
    straight = ~np.isfinite(lo)
    return np.where(straight, -edge, lo), np.where(straight, edge, hi), here > _SHARP_PER_M
