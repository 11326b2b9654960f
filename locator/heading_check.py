"""Heading check of an estimated location against a virtual beacon (2024 patent, digest 002).

A database stores virtual beacons (position) and the heading of the track segment each lies on.
Given a location estimate naming beacon ``B1``, the delay of each satellite's signal relative to
the signal expected at ``B1`` is::

    c dtau_k = rho_k - |B1 - S_k| = b - cos(el_k) cos(az_k - hdg) Rx + eps_k

(``b`` the receiver clock, which the patent's formula leaves implicit; ``el, az`` seen from
``B1``; ``Rx`` the offset of the antenna from ``B1`` along the direction ``hdg``). The patent
writes ``+ (1/c) cos(el) cos(az - hdg) Rx`` with the offset counted from the antenna to ``B1``;
the content is the same.

Solution. ``cos(el) cos(az - hdg) Rx = e_k dE + n_k dN`` with ``(e_k, n_k) = cos(el_k)
(sin az_k, cos az_k)`` and ``(dE, dN) = Rx (sin hdg, cos hdg)``, so the nonlinear problem in
``(hdg, Rx)`` is a *linear* weighted least squares in ``(b, dE, dN)``: exact, no search over
``hdg``, and its covariance gives the uncertainty of ``hdg = atan2(dE, dN)``:
``sigma_hdg = sigma_perp / |d|`` (``sigma_perp`` the standard deviation of the displacement across
its own direction). A known height of the antenna above ``B1`` (antenna height, grade) is
removed first (``sin(el) dU``).

Ambiguity and comparison. ``(hdg, Rx)`` and ``(hdg + 180, -Rx)`` give the same delays; we report
``Rx >= 0`` (``hdg`` points from ``B1`` to the antenna) and compare headings **modulo 180 deg**:
the antenna may be either side of the beacon, so only the axis is tested. The difference
``delta`` is folded into [-90, 90) deg.

Decision. The location is *unreliable* when ``|delta| > k sigma_hdg + tolerance_deg``
(``tolerance_deg`` covers the stored heading's own error and the segment's curvature between
``B1`` and the antenna). Near the beacon the heading is unobservable (``|d|`` of the order of
the noise): when ``sigma_hdg > max_sigma_deg`` the check is ``UNOBSERVABLE`` and passes nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from locator.kernels import heading_kernel
from locator.wls import as_observations
from predisat.geodesy import ecef_to_geodetic, enu_rotation

__all__ = ["HeadingCheck", "HeadingStatus", "check_heading", "delay_model_m"]


class HeadingStatus(IntEnum):
    PASS = 0  # heading agrees with the beacon's segment
    FAIL = 1  # disagrees: wrong track or wrong beacon; location unreliable
    UNOBSERVABLE = 2  # too close to the beacon (or too few satellites) to tell


_PASS, _FAIL, _UNOBSERVABLE = HeadingStatus.PASS, HeadingStatus.FAIL, HeadingStatus.UNOBSERVABLE


@dataclass(frozen=True)
class HeadingCheck:
    """Result of :func:`check_heading`.

    Attributes
    ----------
    heading_deg : float
        Estimated direction from the beacon to the antenna, degrees in [0, 360).
    offset_m : float
        ``Rx``, horizontal distance from the beacon, metres (>= 0).
    along_m : float
        Signed offset along the stored heading, ``Rx cos(hdg - hdg_stored)``, metres.
    sigma_heading_deg : float
    difference_deg : float
        Estimated minus stored heading, modulo 180, in [-90, 90).
    threshold_deg : float
        ``k sigma_heading + tolerance``.
    clock_m : float
        Receiver clock estimate, metres.
    chi2 : float
        Weighted residual sum of squares (``n - 3`` degrees of freedom).
    status : HeadingStatus
    """

    heading_deg: float
    offset_m: float
    along_m: float
    sigma_heading_deg: float
    difference_deg: float
    threshold_deg: float
    clock_m: float
    chi2: float
    status: HeadingStatus

    @property
    def reliable(self) -> bool:
        """Only a passed check vouches for the location."""
        return self.status == HeadingStatus.PASS


def delay_model_m(
    az_deg: ArrayLike, el_deg: ArrayLike, heading_deg: float, offset_m: float, clock_m: float = 0.0
) -> NDArray:
    """Delays ``c dtau_k = b - cos(el) cos(az - hdg) Rx`` of the model, metres, shape of ``az``."""
    az = np.radians(np.asarray(az_deg, float))
    el = np.radians(np.asarray(el_deg, float))
    return clock_m - np.cos(el) * np.cos(az - np.radians(heading_deg)) * offset_m


def check_heading(
    beacon_ecef_m: ArrayLike,
    beacon_heading_deg: float,
    sat_ecef_m: ArrayLike,
    pseudorange_m: ArrayLike,
    sigma_m: ArrayLike,
    *,
    up_m: float = 0.0,
    k_sigma: float = 3.0,
    tolerance_deg: float = 1.0,
    max_sigma_deg: float = 10.0,
    rotation: ArrayLike | None = None,
) -> HeadingCheck:
    """Estimate heading and offset from a virtual beacon and compare with its stored heading.

    Parameters
    ----------
    beacon_ecef_m : array_like, shape (3,)
        Beacon ``B1`` position (the point whose expected signals are the reference), metres.
    beacon_heading_deg : float
        Stored heading of B1's track segment, degrees.
    sat_ecef_m : array_like, shape (n_sat, 3)
    pseudorange_m, sigma_m : array_like, shape (n_sat,)
        Corrected pseudoranges and sigmas, metres; ``n_sat >= 4`` for any redundancy.
    up_m : float
        Known height of the antenna above B1 along the vertical, metres.
    k_sigma, tolerance_deg, max_sigma_deg : float
        Decision parameters (module docstring).
    rotation : array_like, shape (3, 3), optional
        ``predisat.geodesy.enu_rotation`` at the beacon's geodetic position, when the caller
        has it already (the run loop does); computed from ``beacon_ecef_m`` otherwise.

    Returns
    -------
    HeadingCheck
    """
    b1 = np.asarray(beacon_ecef_m, float).reshape(3)
    sat, rho, sig = as_observations(sat_ecef_m, pseudorange_m, sigma_m)
    if not (np.isfinite(sat).all() and np.isfinite(rho).all() and np.all(sig > 0)):
        raise ValueError("sat_ecef_m / pseudorange_m must be finite and sigma_m positive")
    if len(rho) < 3:
        raise ValueError(f"check_heading needs at least 3 satellites, got {len(rho)}")
    if rotation is None:
        lat, lon, _ = ecef_to_geodetic(b1)
        rot = enu_rotation(lat, lon)
    else:
        rot = np.asarray(rotation, float)
        if rot.shape != (3, 3):
            raise ValueError(f"rotation must be a (3, 3) matrix, got shape {rot.shape}")
    # compiled (locator.kernels): the linear least squares in (b, dE, dN) and its covariance
    clock, de, dn, chi2, c_ee, c_en, c_nn, rank_ok = heading_kernel(
        np.ascontiguousarray(b1), np.ascontiguousarray(rot), np.ascontiguousarray(sat),
        np.ascontiguousarray(rho), np.ascontiguousarray(sig), float(up_m),
    )  # fmt: skip
    rx = math.hypot(de, dn)
    hdg = math.degrees(math.atan2(de, dn)) % 360.0
    # variance across the displacement direction -> heading variance
    p_e, p_n = math.cos(math.radians(hdg)), -math.sin(math.radians(hdg))
    var_perp = p_e * (c_ee * p_e + c_en * p_n) + p_n * (c_en * p_e + c_nn * p_n)
    sigma_hdg = (
        math.degrees(math.sqrt(max(var_perp, 0.0)) / rx) if rx > 0 and rank_ok else math.inf
    )
    diff = (hdg - beacon_heading_deg + 90.0) % 180.0 - 90.0
    thr = k_sigma * sigma_hdg + tolerance_deg
    if not sigma_hdg <= max_sigma_deg:
        status = _UNOBSERVABLE
    elif abs(diff) > thr:
        status = _FAIL
    else:
        status = _PASS
    along = rx * math.cos(math.radians(hdg - beacon_heading_deg))
    return HeadingCheck(hdg, rx, along, sigma_hdg, diff, thr, clock, chi2, status)
