"""Sun position and the appearance of the sky for synthetic frames.

* :func:`sun_azel` (from :mod:`predisat.gnss.sun`): the solar position at GPS times and places.
* :class:`SkyModel`: linear-RGB radiance of the sky for ray directions in a local ENU frame, and
  the light it casts on obstacles (direct sun through the clouds, ambient sky and ground bounce).
  Clear skies follow the Preetham et al. (1999) analytic model (Perez luminance and chromaticity
  distributions driven by turbidity); scattered-cloud skies add a procedural cumulus layer (fBm
  noise on a plane at the cloud base, self-shadowed, partly covering the sun); overcast skies are
  a near-uniform grey deck with the CIE overcast gradient (zenith three times the horizon).
* :func:`fbm`: tileable fractal value noise, also used by the renderer's textures.

Radiance is in kcd/m2 (Preetham's zenith luminance scale) and irradiance in klx, so that a white
Lambertian wall in full sun is about five times brighter than the clear-sky zenith, as in photos.
Only the ratios matter: the camera model applies its own exposure.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtri

from predisat.gnss.sun import sun_direction_enu

__all__ = [
    "SKY_CONDITIONS",
    "SkyModel",
    "fbm",
]

SKY_CONDITIONS = ("clear", "cloudy", "overcast")

_SUN_RADIUS_DEG = 0.2666
_XYZ_TO_SRGB = np.array(
    [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]]
)


# --------------------------------------------------------------------------------------------
# Procedural noise
# --------------------------------------------------------------------------------------------

_TILE_PX = 256


@lru_cache(maxsize=32)
def _noise_tile(seed: int) -> NDArray:
    tile = np.random.default_rng([seed, 0x5EED]).random((_TILE_PX, _TILE_PX), dtype=np.float32)
    tile.setflags(write=False)
    return tile


def fbm(
    x: ArrayLike,
    y: ArrayLike,
    seed: int = 0,
    octaves: int = 5,
    lacunarity: float = 2.0,
    gain: float = 0.5,
) -> NDArray:
    """Fractal (fBm) value noise on the plane, mean about 0.5, roughly in [0, 1].

    Bicubic interpolation of a 256 x 256 random lattice (periodic), one rotated and shifted copy
    per octave so the lattice never shows.

    Parameters
    ----------
    x, y : array_like, shape (...)
        Coordinates in lattice cells (feature size of the first octave is about one cell).
    seed : int
        Chooses the lattice.
    octaves : int
        Number of octaves (each ``lacunarity`` times finer and ``gain`` times weaker).

    Returns
    -------
    ndarray of float32, shape (...)
    """
    if octaves < 1:
        raise ValueError(f"octaves must be >= 1, got {octaves}")
    xa, ya = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    shape = xa.shape
    xf, yf = xa.ravel(), ya.ravel()
    n = xf.size
    if n == 0:
        return np.zeros(shape, np.float32)
    width = min(n, 4096)
    rows = -(-n // width)
    pad = rows * width - n
    tile = _noise_tile(int(seed))
    total = np.zeros(n, np.float32)
    amp, norm, freq = 1.0, 0.0, 1.0
    for k in range(octaves):
        ang = 0.61 * k + 0.3
        ca, sa = np.cos(ang), np.sin(ang)
        u = freq * (ca * xf - sa * yf) + 37.1 * k
        v = freq * (sa * xf + ca * yf) + 91.7 * k
        mu = np.pad(np.mod(u, _TILE_PX).astype(np.float32), (0, pad)).reshape(rows, width)
        mv = np.pad(np.mod(v, _TILE_PX).astype(np.float32), (0, pad)).reshape(rows, width)
        val = cv2.remap(tile, mu, mv, cv2.INTER_CUBIC, borderMode=cv2.BORDER_WRAP)
        total += amp * val.ravel()[:n]
        norm += amp
        amp *= gain
        freq *= lacunarity
    return (total / norm).reshape(shape)


def _smoothstep(e0: float | NDArray, e1: float | NDArray, x: NDArray) -> NDArray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


# --------------------------------------------------------------------------------------------
# Sky model
# --------------------------------------------------------------------------------------------

# Preetham et al. (1999), appendix: Perez coefficients as linear functions of turbidity T
_PREETHAM_Y = np.array(
    [[0.1787, -1.4630], [-0.3554, 0.4275], [-0.0227, 5.3251], [0.1206, -2.5771], [-0.0670, 0.3703]]
)
_PREETHAM_X = np.array(
    [
        [-0.0193, -0.2592],
        [-0.0665, 0.0008],
        [-0.0004, 0.2125],
        [-0.0641, -0.8989],
        [-0.0033, 0.0452],
    ]
)
_PREETHAM_YC = np.array(
    [
        [-0.0167, -0.2608],
        [-0.0950, 0.0092],
        [-0.0079, 0.2102],
        [-0.0441, -1.6537],
        [-0.0109, 0.0529],
    ]
)
_ZENITH_X = np.array(
    [
        [0.00166, -0.00375, 0.00209, 0.0],
        [-0.02903, 0.06377, -0.03202, 0.00394],
        [0.11693, -0.21196, 0.06052, 0.25886],
    ]
)
_ZENITH_Y = np.array(
    [
        [0.00275, -0.00610, 0.00317, 0.0],
        [-0.04214, 0.08970, -0.04153, 0.00516],
        [0.15346, -0.26756, 0.06670, 0.26688],
    ]
)


def _perez(coef: NDArray, cos_theta: NDArray, gamma: NDArray) -> NDArray:
    a, b, c, d, e = coef
    return (1.0 + a * np.exp(b / np.maximum(cos_theta, 0.02))) * (
        1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2
    )


def _xyy_to_rgb(x: NDArray, y: NDArray, lum: NDArray) -> NDArray:
    y = np.maximum(y, 1e-4)
    xyz = np.stack([x / y * lum, lum, (1.0 - x - y) / y * lum], axis=-1)
    return np.maximum(xyz @ _XYZ_TO_SRGB.T, 0.0)


def _fibonacci_sphere(n: int) -> NDArray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def _sh9(d: NDArray) -> NDArray:
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack(
        [
            0.282095 * np.ones_like(x),
            0.488603 * y,
            0.488603 * z,
            0.488603 * x,
            1.092548 * x * y,
            1.092548 * y * z,
            0.315392 * (3.0 * z * z - 1.0),
            1.092548 * x * z,
            0.546274 * (x * x - y * y),
        ],
        axis=-1,
    )


@dataclass(frozen=True)
class SkyModel:
    """Sky radiance and scene lighting for one sky condition and sun position.

    Build with :meth:`clear`, :meth:`cloudy` or :meth:`overcast`. Directions and positions are
    in a local ENU frame (metres); the cloud layer is a horizontal plane ``cloud_base_m`` above
    the ray origins' ``z = 0`` and drifts with ``wind_mps`` (east, north).

    Attributes
    ----------
    condition : {"clear", "cloudy", "overcast"}
    sun_az_deg, sun_el_deg : float
        Sun position; below the horizon the sky is rendered as at sunrise, without direct sun.
    seed : int
        Chooses the cloud pattern.
    cloud_cover : float
        Fraction of the sky covered by clouds (0 clear, 1 overcast).
    turbidity : float
        Preetham turbidity (2 very clear, 3 hazy summer day, 6 hazy).
    """

    condition: str
    sun_az_deg: float
    sun_el_deg: float
    seed: int = 0
    cloud_cover: float = 0.0
    turbidity: float = 2.5
    cloud_base_m: float = 1500.0
    cloud_scale_m: float = 900.0
    wind_mps: tuple[float, float] = (6.0, 2.0)
    ground_albedo: float = 0.18

    def __post_init__(self) -> None:
        if self.condition not in SKY_CONDITIONS:
            raise ValueError(f"condition must be one of {SKY_CONDITIONS}, got {self.condition!r}")
        if not 0.0 <= self.cloud_cover <= 1.0:
            raise ValueError(f"cloud_cover must lie in [0, 1], got {self.cloud_cover}")
        if not 1.7 <= self.turbidity <= 10.0:
            raise ValueError(f"turbidity must lie in [1.7, 10] (Preetham), got {self.turbidity}")
        if not -90.0 <= self.sun_el_deg <= 90.0:
            raise ValueError(f"sun_el_deg must lie in [-90, 90], got {self.sun_el_deg}")

    # ---- named constructors ---------------------------------------------------------------

    @classmethod
    def clear(cls, sun_az_deg: float, sun_el_deg: float, seed: int = 0) -> SkyModel:
        """Cloudless sky; turbidity drawn in [2.0, 3.5] from ``seed``."""
        rng = np.random.default_rng([seed, 1])
        return cls(
            "clear",
            float(sun_az_deg),
            float(sun_el_deg),
            seed,
            cloud_cover=0.0,
            turbidity=float(rng.uniform(2.0, 3.5)),
        )

    @classmethod
    def cloudy(cls, sun_az_deg: float, sun_el_deg: float, seed: int = 0) -> SkyModel:
        """Scattered cumulus: cover in [0.25, 0.65], base 900-2000 m, drawn from ``seed``."""
        rng = np.random.default_rng([seed, 2])
        return cls(
            "cloudy",
            float(sun_az_deg),
            float(sun_el_deg),
            seed,
            cloud_cover=float(rng.uniform(0.25, 0.65)),
            turbidity=float(rng.uniform(2.5, 4.5)),
            cloud_base_m=float(rng.uniform(900.0, 2000.0)),
            cloud_scale_m=float(rng.uniform(600.0, 1200.0)),
            wind_mps=(float(rng.normal(0, 6)), float(rng.normal(0, 6))),
        )

    @classmethod
    def overcast(cls, sun_az_deg: float, sun_el_deg: float, seed: int = 0) -> SkyModel:
        """Full grey deck, no direct sun; faint brighter patch toward the hidden sun."""
        rng = np.random.default_rng([seed, 3])
        return cls(
            "overcast",
            float(sun_az_deg),
            float(sun_el_deg),
            seed,
            cloud_cover=1.0,
            turbidity=float(rng.uniform(3.0, 6.0)),
            cloud_base_m=float(rng.uniform(400.0, 900.0)),
            cloud_scale_m=float(rng.uniform(1500.0, 3000.0)),
        )

    @classmethod
    def of(cls, condition: str, sun_az_deg: float, sun_el_deg: float, seed: int = 0) -> SkyModel:
        """Dispatch on ``condition`` (one of :data:`SKY_CONDITIONS`)."""
        if condition not in SKY_CONDITIONS:
            raise ValueError(f"sky condition must be one of {SKY_CONDITIONS}, got {condition!r}")
        return getattr(cls, condition)(sun_az_deg, sun_el_deg, seed)

    # ---- sun ------------------------------------------------------------------------------

    @property
    def sun_direction(self) -> NDArray:
        """Unit ENU vector toward the sun, shape (3,)."""
        return sun_direction_enu(self.sun_az_deg, self.sun_el_deg)

    @cached_property
    def _sun_el_eff_deg(self) -> float:
        return float(np.clip(self.sun_el_deg, 0.5, 90.0))

    @cached_property
    def sun_irradiance(self) -> NDArray:
        """Direct-normal irradiance of the unobstructed sun, linear RGB (3,), klx.

        Zero when the sky is overcast or the sun is below the horizon. Air mass from Kasten &
        Young (1989); Rayleigh plus turbidity-scaled aerosol extinction reddens a low sun.
        """
        if self.condition == "overcast" or self.sun_el_deg <= 0.0:
            return np.zeros(3)
        z = 90.0 - self.sun_el_deg
        am = 1.0 / (np.cos(np.radians(z)) + 0.50572 * (96.07995 - z) ** -1.6364)
        tau = 0.10 * np.array([0.51, 1.0, 2.2]) + 0.045 * (self.turbidity - 1.0) * np.array(
            [0.8, 1.0, 1.3]
        )
        return 135.0 * np.exp(-am * tau)

    # ---- clear-sky radiance ---------------------------------------------------------------

    def _clear_radiance(self, d: NDArray) -> NDArray:
        t = self.turbidity
        theta_s = np.radians(90.0 - self._sun_el_eff_deg)
        s = sun_direction_enu(self.sun_az_deg, self._sun_el_eff_deg)
        cos_theta = np.clip(d[..., 2], 0.0, 1.0)
        gamma = np.arccos(np.clip(d @ s, -1.0, 1.0))
        chi = (4.0 / 9.0 - t / 120.0) * (np.pi - 2.0 * theta_s)
        yz = (4.0453 * t - 4.9710) * np.tan(chi) - 0.2155 * t + 2.4192
        tv = np.array([t * t, t, 1.0])
        th = np.array([theta_s**3, theta_s**2, theta_s, 1.0])
        xz, ycz = tv @ _ZENITH_X @ th, tv @ _ZENITH_Y @ th
        out = []
        zero = np.zeros(())
        for coef_tab, zenith in ((_PREETHAM_Y, yz), (_PREETHAM_X, xz), (_PREETHAM_YC, ycz)):
            coef = coef_tab[:, 0] * t + coef_tab[:, 1]
            out.append(zenith * _perez(coef, cos_theta, gamma) / _perez(coef, 1.0 + zero, theta_s))
        lum, x, y = out
        # aureole: forward scattering by aerosols concentrated within a few degrees of the sun
        lum = lum * (1.0 + 0.25 * (t - 1.0) * np.exp(-np.degrees(gamma) / 2.5))
        return _xyy_to_rgb(x, y, lum)

    def _sun_disc(self, d: NDArray) -> NDArray:
        if self.condition == "overcast" or self.sun_el_deg <= -_SUN_RADIUS_DEG:
            return np.zeros((*d.shape[:-1], 3))
        cosr = np.cos(np.radians(_SUN_RADIUS_DEG))
        omega = 2.0 * np.pi * (1.0 - cosr)
        inside = _smoothstep(cosr - 2e-6, cosr + 2e-6, d @ self.sun_direction)
        below = d[..., 2] < 0.0  # the ground hides the part of the disc below the horizon
        return np.where(below, 0.0, inside)[..., None] * (self.sun_irradiance / omega)

    # ---- clouds ---------------------------------------------------------------------------

    def _layer_xy(self, points: NDArray, d: NDArray, elapsed_s: float) -> tuple[NDArray, NDArray]:
        """Where rays from points along d pierce the cloud base: layer coordinates, distance."""
        dz = np.maximum(d[..., 2], 1e-3)
        ell = np.maximum(self.cloud_base_m - points[..., 2], 1.0) / dz
        wind = np.asarray(self.wind_mps, float) * elapsed_s
        xy = (points[..., :2] + d[..., :2] * ell[..., None] - wind) / self.cloud_scale_m
        return xy, ell

    def _cloud_density(self, xy: NDArray, octaves: int = 6) -> tuple[NDArray, NDArray]:
        """Cloud opacity in [0, 1] and optical thickness in [0, 1] on the layer."""
        n = fbm(xy[..., 0], xy[..., 1], self.seed + 101, octaves=octaves)
        if self.condition == "overcast":
            return np.ones_like(n), np.ones_like(n)
        # fBm with gain 0.5 is close to normal, sd about 0.15: put the threshold at the quantile
        # that leaves cloud_cover of the sky covered
        c = np.clip(self.cloud_cover, 1e-3, 1.0 - 1e-3)
        thr = 0.5 + 0.15 * float(ndtri(1.0 - c))
        return _smoothstep(thr - 0.03, thr + 0.10, n), np.clip((n - thr) / 0.25, 0.0, 1.0)

    def _cloudy_radiance(self, d: NDArray, origin: NDArray, elapsed_s: float) -> NDArray:
        clear = self._clear_radiance(d) + self._sun_disc(d)
        up = d[..., 2] > 0.0
        xy, ell = self._layer_xy(origin, d, elapsed_s)
        dens, thick = self._cloud_density(xy)
        dens = np.where(up, dens, 0.0)
        # self-shadowing: thicker cloud between this point and the sun darkens its base
        s = self.sun_direction
        step = 0.18 * s[:2] / max(np.hypot(s[0], s[1]), 1e-3) * min(1.0, 0.6 / max(s[2], 0.2))
        toward = self._cloud_density(xy + step, octaves=4)[1]
        lit = np.clip(1.0 - 2.0 * (toward - 0.6 * thick), 0.0, 1.0)
        e_sun = self.sun_irradiance
        mu = np.clip(d @ s, -1.0, 1.0)
        g = 0.65  # Henyey-Greenstein: thin cloud edges glow around the sun
        hg = (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * mu) ** 1.5)
        neutral = float(self._ambient_sky_mean @ np.array([0.2126, 0.7152, 0.0722]))
        base = neutral * (1.6 - 0.8 * thick)[..., None] * np.array([0.97, 0.98, 1.0])
        sunlit = (e_sun / np.pi)[None, :] * (0.35 * lit * (1.0 - 0.5 * thick))[..., None]
        silver = (e_sun * 0.35)[None, :] * (hg * (1.0 - thick))[..., None]
        cloud = (base + sunlit + silver).reshape(clear.shape)
        # far clouds: the layer's detail averages out and aerial perspective veils it
        far = _smoothstep(8e3, 40e3, ell)
        alpha = np.clip(dens * 1.05, 0.0, 1.0) * (1.0 - far) + 0.6 * self.cloud_cover * far
        alpha = np.where(up, alpha, 0.0) * _smoothstep(0.0, 0.03, d[..., 2])
        haze = 1.0 - np.exp(-ell / 25e3)
        horizon = self.horizon_radiance
        cloud = cloud * (1.0 - haze[..., None]) + horizon * haze[..., None]
        return clear * (1.0 - alpha[..., None]) + cloud * alpha[..., None]

    def _overcast_radiance(self, d: NDArray, origin: NDArray, elapsed_s: float) -> NDArray:
        el = np.clip(d[..., 2], 0.0, 1.0)
        lz = 0.123 + 8.6 * np.sin(np.radians(self._sun_el_eff_deg))  # Krochmann
        lum = lz * (1.0 + 2.0 * el) / 3.0  # CIE standard overcast sky
        xy, _ = self._layer_xy(origin, d, elapsed_s)
        texture = fbm(xy[..., 0], xy[..., 1], self.seed + 202, octaves=5)
        lum = lum * (1.0 + 0.5 * (texture - 0.5))
        s = sun_direction_enu(self.sun_az_deg, self._sun_el_eff_deg)
        lum = lum * (1.0 + 0.25 * np.exp(-np.degrees(np.arccos(np.clip(d @ s, -1, 1))) / 20.0))
        tint = np.array([0.93, 0.97, 1.03]) + 0.02 * (self.turbidity - 4.0) * np.array(
            [1.0, 0.5, -1.0]
        )
        return lum[..., None] * tint

    @cached_property
    def horizon_radiance(self) -> NDArray:
        """Mean sky radiance just above the horizon, linear RGB (3,), kcd/m2: the haze colour
        of aerial perspective."""
        az = np.radians(np.arange(0.0, 360.0, 10.0))
        d = np.stack([np.sin(az) * 0.999, np.cos(az) * 0.999, np.full_like(az, 0.045)], -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        if self.condition == "overcast":
            rad = self._overcast_radiance(d, np.zeros(3), 0.0)
        else:
            rad = self._clear_radiance(d)
        return rad.mean(axis=0)

    @cached_property
    def _ambient_sky_mean(self) -> NDArray:
        """Cosine-weighted mean clear-sky radiance of the upper hemisphere, RGB (3,)."""
        d = _fibonacci_sphere(800)
        d = d[d[:, 2] > 0]
        rad = self._clear_radiance(d)
        w = d[:, 2]
        return (rad * w[:, None]).sum(0) / w.sum()

    # ---- public radiance / lighting -------------------------------------------------------

    def radiance(
        self,
        directions: ArrayLike,
        origin_m: ArrayLike = (0.0, 0.0, 0.0),
        elapsed_s: float = 0.0,
    ) -> NDArray:
        """Sky radiance seen along unit ENU directions, linear RGB, kcd/m2.

        Parameters
        ----------
        directions : array_like, shape (..., 3)
            Unit vectors (ENU). Below the horizon the sky continues as a hazy ground.
        origin_m : array_like, shape (3,) or (..., 3)
            Where the rays start (the camera), metres in the same ENU frame: sets where they
            pierce the cloud layer, so that clouds keep their place between frames.
        elapsed_s : float
            Seconds since the start of the run (clouds drift with ``wind_mps``).

        Returns
        -------
        ndarray, shape (..., 3)
        """
        d = np.asarray(directions, float)
        if d.shape[-1:] != (3,):
            raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
        o = np.broadcast_to(np.asarray(origin_m, float), d.shape)
        if self.condition == "clear":
            rad = self._clear_radiance(d) + self._sun_disc(d)
        elif self.condition == "cloudy":
            rad = self._cloudy_radiance(d, o, elapsed_s)
        else:
            rad = self._overcast_radiance(d, o, elapsed_s)
        # below the horizon: the far landscape, fading from the haze colour to the ground
        below = np.clip(-d[..., 2] / 0.08, 0.0, 1.0)[..., None]
        return rad * (1.0 - below) + self.ground_radiance * below

    def sun_transmittance(self, points_m: ArrayLike, elapsed_s: float = 0.0) -> NDArray:
        """Share of the direct sun reaching points through the clouds, shape (...), in [0, 1].

        Cloud shadows move over the scene with the clouds; 0 everywhere when overcast or when
        the sun is below the horizon; 1 for a clear sky. Obstacles are not considered here
        (the renderer casts shadow rays for them).
        """
        p = np.asarray(points_m, float)
        if self.condition == "overcast" or self.sun_el_deg <= 0.0:
            return np.zeros(p.shape[:-1])
        if self.condition == "clear":
            return np.ones(p.shape[:-1])
        s = np.broadcast_to(self.sun_direction, p.shape)
        xy, _ = self._layer_xy(p, s, elapsed_s)
        dens = self._cloud_density(xy, octaves=4)[0]
        return np.clip(1.0 - 0.92 * dens, 0.0, 1.0)

    @cached_property
    def _sky_sh(self) -> NDArray:
        """Order-2 spherical-harmonic coefficients (9, 3) of the sky + ground environment."""
        d = _fibonacci_sphere(2000)
        up = d[:, 2] > 0.0
        rad = np.empty((len(d), 3))
        rad[up] = self.radiance(d[up]) - self._sun_disc(d[up])  # the sun is the direct term
        rad[~up] = self.ground_radiance
        return (4.0 * np.pi / len(d)) * _sh9(d).T @ rad

    @cached_property
    def ground_radiance(self) -> NDArray:
        """Radiance of open level ground (ballast, fields) lit by sun and sky, RGB (3,)."""
        d = _fibonacci_sphere(800)
        d = d[d[:, 2] > 0]
        if self.condition == "overcast":
            rad = self._overcast_radiance(d, np.zeros(3), 0.0)
        elif self.condition == "cloudy":
            c = self.cloud_cover
            rad = self._clear_radiance(d) * (1 - c) + c * self._ambient_sky_mean * 0.9
        else:
            rad = self._clear_radiance(d)
        e_sky = 2.0 * np.pi * (rad * d[:, 2:3]).mean(0)  # hemisphere integral of L cos
        sun_share = 1.0 - 0.8 * self.cloud_cover if self.condition == "cloudy" else 1.0
        e_sun = self.sun_irradiance * max(np.sin(np.radians(self.sun_el_deg)), 0.0) * sun_share
        tint = np.array([0.95, 1.0, 0.85])  # greenish-brown land
        return self.ground_albedo * tint * (e_sky + e_sun) / np.pi

    def ambient_radiance(self, normals: ArrayLike) -> NDArray:
        """Radiance of a white Lambertian surface lit by sky and ground only, RGB (..., 3).

        ``E(n) / pi`` from the order-2 spherical-harmonic irradiance of the environment
        (Ramamoorthi & Hanrahan 2001); multiply by albedo and by the surface's sky visibility.

        Parameters
        ----------
        normals : array_like, shape (..., 3)
            Unit surface normals (ENU).
        """
        n = np.asarray(normals, float)
        x, y, z = n[..., 0:1], n[..., 1:2], n[..., 2:3]
        lm = self._sky_sh
        c1, c2, c3, c4, c5 = 0.429043, 0.511664, 0.743125, 0.886227, 0.247708
        e = (
            c1 * lm[8] * (x * x - y * y)
            + c3 * lm[6] * z * z
            + c4 * lm[0]
            - c5 * lm[6]
            + 2 * c1 * (lm[4] * x * y + lm[7] * x * z + lm[5] * y * z)
            + 2 * c2 * (lm[3] * x + lm[1] * y + lm[2] * z)
        )
        return np.maximum(e, 0.0) / np.pi
