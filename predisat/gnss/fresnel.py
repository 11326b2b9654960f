"""When a thin structure is transparent to a GNSS signal: the first Fresnel zone.

A structure of physical width ``w`` (a wire, a lamp arm, a rail, a mast) at distance ``d``
from the antenna hides part of the first Fresnel zone of the ray, radius
``r_F = sqrt(lambda d)`` (the satellite is at infinity, so ``d1 d2 / (d1 + d2) = d``). The
signal diffracts around it; the loss follows from the Fresnel integrals of the two edges of
a strip (ITU-R P.526, section 4, knife-edge diffraction: the field beyond a screen is the sum
over the open parts of the wavefront, ``E / E0 = (1 + j) / 2 * integral of exp(-j pi t^2 / 2)
dt`` over the open ``v``, ``v = h sqrt(2 / (lambda d))``). :func:`strip_loss_db` computes it.

The rule (:func:`transparent`): a structure is transparent when ``w <= TRANSPARENT_FRACTION *
r_F``, with ``TRANSPARENT_FRACTION = 0.1``: an infinitely long strip of width ``r_F / 10``
costs 0.61 dB centred on the ray and 0.91 dB at worst (off centre by about ``r_F / 2``, where
the two edges' contributions add in phase), under 1 dB, within the ordinary C/N0 spread of a
tracked satellite. A finite structure (a lamp arm) hides less than the infinite strip, so
the rule is on the safe side for it. The wavelength is the shortest the receiver tracks
(L1/E1, 0.1903 m: the smallest zone; L5 0.2548 m would allow 16 % wider structures), also on
the safe side. An unknown or non-finite distance is never transparent.

``docs/reconstruction.md`` (section 8) and ``docs/synthetic-world.md`` apply it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import fresnel

__all__ = [
    "L1_WAVELENGTH_M",
    "L5_WAVELENGTH_M",
    "TRANSPARENT_FRACTION",
    "fresnel_radius_m",
    "max_transparent_width_m",
    "strip_loss_db",
    "transparent",
]

_C_MPS = 299_792_458.0
L1_WAVELENGTH_M = _C_MPS / 1575.42e6
"""GPS L1 / Galileo E1 wavelength, 0.1903 m (the shortest of the usual signals: the safe side)."""
L5_WAVELENGTH_M = _C_MPS / 1176.45e6
"""GPS L5 / Galileo E5a wavelength, 0.2548 m."""
TRANSPARENT_FRACTION = 0.1
"""A structure no wider than this share of the first Fresnel zone radius is transparent
(worst-case strip loss 0.91 dB, see the module docstring)."""


def fresnel_radius_m(distance_m: ArrayLike, wavelength_m: float = L1_WAVELENGTH_M) -> NDArray:
    """First Fresnel zone radius ``sqrt(lambda d)`` at ``distance_m`` from the antenna (metres,
    any shape; NaN for a negative or NaN distance)."""
    d = np.asarray(distance_m, float)
    if not wavelength_m > 0:
        raise ValueError(f"wavelength_m must be > 0, got {wavelength_m}")
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.where(d >= 0, d, np.nan) * wavelength_m)


def max_transparent_width_m(
    distance_m: ArrayLike, wavelength_m: float = L1_WAVELENGTH_M
) -> NDArray:
    """Widest transparent structure at ``distance_m`` from the antenna (metres, any shape):
    ``TRANSPARENT_FRACTION * sqrt(lambda d)``; 0 where the distance is unknown (NaN, inf or
    negative)."""
    d = np.asarray(distance_m, float)
    ok = np.isfinite(d) & (d >= 0)
    r = fresnel_radius_m(np.where(ok, d, 0.0), wavelength_m)
    return np.where(ok, TRANSPARENT_FRACTION * r, 0.0)


def transparent(
    width_m: ArrayLike, distance_m: ArrayLike, wavelength_m: float = L1_WAVELENGTH_M
) -> NDArray:
    """Whether a structure of physical ``width_m`` at ``distance_m`` from the antenna is
    transparent to the signal (both metres, broadcast). False for an unknown distance (NaN,
    inf) or width."""
    w = np.asarray(width_m, float)
    with np.errstate(invalid="ignore"):
        return np.asarray(np.isfinite(w) & (w <= max_transparent_width_m(distance_m, wavelength_m)))


def strip_loss_db(
    width_m: ArrayLike,
    distance_m: ArrayLike,
    offset_m: ArrayLike = 0.0,
    wavelength_m: float = L1_WAVELENGTH_M,
) -> NDArray:
    """Diffraction loss (dB, > 0 = weaker) of an infinitely long strip across the ray.

    Parameters
    ----------
    width_m : array_like
        Strip width, metres.
    distance_m : array_like
        Distance of the strip from the antenna along the ray, metres (> 0).
    offset_m : array_like
        Offset of the strip's centre from the ray, metres.
    wavelength_m : float

    Returns
    -------
    ndarray
        ``-20 log10 |E / E0|`` with ``E / E0 = 1 - (1 + j) / 2 * integral_{v1}^{v2}
        exp(-j pi t^2 / 2) dt``, ``v = h sqrt(2 / (lambda d))`` at the strip's edges (ITU-R
        P.526's Fresnel-Kirchhoff field of the open wavefront, both sides of the strip).
    """
    w = np.asarray(width_m, float)
    d = np.asarray(distance_m, float)
    h = np.asarray(offset_m, float)
    scale = np.sqrt(2.0 / (wavelength_m * d))
    v1, v2 = (h - w / 2.0) * scale, (h + w / 2.0) * scale
    s1, c1 = fresnel(v1)
    s2, c2 = fresnel(v2)
    blocked = (c2 - c1) - 1j * (s2 - s1)
    field = 1.0 - (1.0 + 1.0j) / 2.0 * blocked
    return np.asarray(-20.0 * np.log10(np.abs(field)))
