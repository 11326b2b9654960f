"""Survey-camera frames of a synthetic world by ray casting, shading and a camera sensor model.

:func:`render_frame` produces what a survey camera records (uint8 BGR) and the exact sky label of
every pixel. It is two stages, also usable on their own:

* :func:`render_radiance`: scene radiance (linear RGB, kcd/m2) per pixel, averaged over
  ``supersample**2`` jittered rays (anti-aliasing: thin wires come out as faint lines), and the
  label from the ray through the pixel centre. Hits are shaded with the sun (cast shadows by
  shadow rays, cloud shadows from the sky model) and the sky + ground environment (order-2
  spherical harmonics) times a ray-cast ambient visibility; procedural textures per material
  (bricks, plaster with windows reflecting the sky, foliage, rock strata, concrete panels,
  metal); Fresnel mirrors (glass curtain walls and windows, water, wet ground: Schlick's
  reflectance of the material's ``f0``, the sky or the scenery along the mirrored ray, rippled
  normals); aerial perspective toward the horizon colour.
* :func:`expose`: the camera: veiling glare and lens flare from a sun in or near the field,
  bloom of saturated highlights, lens blur, vignetting, auto-exposure with a random bias, white
  balance error, Poisson-Gaussian sensor noise with gain in the dark, a filmic tone curve and
  sRGB gamma. JPEG compression happens when the frame is written (``SurveyWriter``).

Labels: 255 sky, 128 a thin L-band-transparent structure (wire, cantilever tube) with sky behind
it, 0 anything else (including pixels outside a fisheye's image circle).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import CameraModel, Mount, tilt_shift_m, vehicle_to_enu
from predisat.synth.materials import MATERIALS
from predisat.synth.raycast import Caster, Hits, SceneMesh, make_caster
from predisat.synth.sky import SkyModel, fbm
from predisat.synth.world import World

__all__ = [
    "GLASS_PANE_M",
    "LABEL_OBSTACLE",
    "LABEL_SKY",
    "LABEL_THIN",
    "WINDOW_GRID_M",
    "Casters",
    "RenderOptions",
    "SensorState",
    "camera_pose",
    "expose",
    "render_frame",
    "render_radiance",
    "schlick_reflectance",
]

LABEL_SKY = 255
LABEL_THIN = 128
LABEL_OBSTACLE = 0

_LUMA = np.array([0.2126, 0.7152, 0.0722])
_ALBEDO = np.array([m.albedo_rgb for m in MATERIALS], float)
_TEXTURE = tuple(m.texture for m in MATERIALS)
_THIN = np.array([m.thin for m in MATERIALS], bool)
_F0 = np.array([m.f0 for m in MATERIALS], float)
_TINT = np.array([m.tint_rgb for m in MATERIALS], float)
_RIPPLE = np.array([m.ripple_rad for m in MATERIALS], float)
_GLASS = next(m for m in MATERIALS if m.name == "glass")

GLASS_PANE_M = (1.5, 3.6)
"""Curtain-wall module (width, storey height), metres: a 0.08 m mullion at the start of each
module's width, a 0.9 m opaque spandrel at the foot of each storey, glass between."""
WINDOW_GRID_M = (2.4, 3.2)
"""Window rows of a white facade (pitch across, storey height), metres; windows 1.2 m wide and
1.6 m tall from 0.9 m above each storey's floor, glass like the curtain walls."""


@dataclass(frozen=True)
class RenderOptions:
    """Renderer and camera settings (defaults give photo-like 45 deg survey frames).

    Attributes
    ----------
    supersample : int
        ``n``: ``n x n`` stratified jittered rays per pixel (1: the pixel centre only).
    shadows : bool
        Cast shadow rays toward the sun.
    ambient_rays : int
        Ambient-visibility rays per pixel (0: no ambient occlusion).
    visibility_m : float
        Meteorological visibility for aerial perspective (overcast uses a third of it).
    exposure_ev_sd : float
        Standard deviation of the auto-exposure error, EV.
    exposure_target : float
        Linear value the metered scene is exposed to (before the tone curve).
    max_exposure : float
        Largest exposure (1 / kcd m-2) reached by shutter time alone; darker scenes add gain.
    vignetting : float
        Relative fall-off at the image corner.
    blur_px : float
        Lens blur, Gaussian sigma in pixels (per-frame jitter of +-25 %).
    full_well_e : float
        Electrons at clipping (shot noise); ``read_noise_e``: read noise, electrons.
    glare : float
        Strength of sun veiling glare, flare ghosts and bloom (0 disables them).
    wb_error : float
        Standard deviation of the per-channel white-balance error.
    """

    supersample: int = 2
    shadows: bool = True
    ambient_rays: int = 2
    visibility_m: float = 8000.0
    exposure_ev_sd: float = 0.3
    exposure_target: float = 0.2
    max_exposure: float = 0.6
    vignetting: float = 0.35
    blur_px: float = 0.6
    full_well_e: float = 5000.0
    read_noise_e: float = 4.0
    glare: float = 1.0
    wb_error: float = 0.04

    def __post_init__(self) -> None:
        if int(self.supersample) != self.supersample or not 1 <= self.supersample <= 8:
            raise ValueError(f"supersample must be an integer in [1, 8], got {self.supersample}")
        if self.ambient_rays < 0 or self.visibility_m <= 0 or self.full_well_e <= 0:
            raise ValueError("ambient_rays must be >= 0; visibility_m, full_well_e positive")


@dataclass(frozen=True)
class SensorState:
    """Per-frame random camera state, drawn from a generator so that a seed fixes a frame."""

    exposure_ev: float
    blur_px: float
    wb_gain_rgb: tuple[float, float, float]
    noise_seed: int

    @classmethod
    def draw(cls, rng: np.random.Generator, options: RenderOptions) -> SensorState:
        """The state of one frame, drawn from ``rng`` with the spreads of ``options``."""
        ev = float(rng.normal(0.0, options.exposure_ev_sd))
        blur = float(options.blur_px * rng.uniform(0.75, 1.25))
        wb = 1.0 + options.wb_error * rng.standard_normal(3)
        wb = wb / (wb @ _LUMA)
        return cls(
            ev, blur, (float(wb[0]), float(wb[1]), float(wb[2])), int(rng.integers(0, 2**31))
        )


@dataclass(frozen=True)
class Casters:
    """The two ray casters a frame needs: every face, and L-band-blocking faces only."""

    full: Caster
    lband: Caster

    @classmethod
    def for_world(cls, world: SceneMesh, backend: str = "open3d") -> Casters:
        """Both casters of ``world`` with ray-casting ``backend`` ``"open3d"`` or ``"trimesh"``."""
        return cls(make_caster(world, backend), make_caster(world, backend, lband_only=True))


def camera_pose(
    world: World,
    chainage_m: float,
    mount: Mount,
    antenna_height_m: float = 4.0,
    reverse: bool = False,
    roll_deg: float = 0.0,
    pitch_deg: float = 0.0,
) -> tuple[NDArray, NDArray]:
    """Camera centre (3,) and camera-to-world rotation (3, 3) at a chainage, in world ENU.

    The track heading is measured in the local ENU at the antenna and carried into the world
    frame with :meth:`LocalFrame.rotation_from`, so far from the frame origin the camera still
    looks square to the track and its horizon stays level. ``roll_deg`` and ``pitch_deg`` tilt
    the vehicle about the track axis at rail level (:meth:`Mount.on_vehicle`,
    :func:`~predisat.camera.models.tilt_shift_m`): on a canted curve the horizon rolls with
    it and the cameras move toward the inside.
    """
    tilted = mount.on_vehicle(roll_deg, pitch_deg)
    s = float(chainage_m)
    antenna = np.asarray(world.antenna_enu(s, antenna_height_m), float)
    lat, lon, _ = world.track.position_at(s)
    heading = float(np.asarray(world.track.heading_at(s)))
    to_frame = world.frame.rotation_from(lat, lon)
    rot = to_frame @ tilted.camera_to_enu(heading, reverse)
    # the vehicle tilts about the rails, carrying the antenna toward the curve's inside
    shift = vehicle_to_enu(heading, reverse) @ tilt_shift_m(roll_deg, pitch_deg, antenna_height_m)
    pos = antenna + to_frame @ (
        shift + np.asarray(tilted.camera_position_enu(np.zeros(3), heading, reverse))
    )
    return pos, rot


# --------------------------------------------------------------------------------------------
# textures
# --------------------------------------------------------------------------------------------


def _tex_coords(p: NDArray, n: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Planar texture coordinates (metres) of hit points and whether the face is vertical."""
    vertical = np.abs(n[:, 2]) < 0.7
    t = np.stack([-n[:, 1], n[:, 0]], -1)
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-9)
    u = np.where(vertical, p[:, 0] * t[:, 0] + p[:, 1] * t[:, 1], p[:, 0])
    v = np.where(vertical, p[:, 2], p[:, 1])
    return u, v, vertical


def _fade(feature_m: float, footprint_m: NDArray) -> NDArray:
    """Weight of a texture detail of a given size: 1 above four pixel footprints, 0 below one."""
    return np.clip((feature_m / footprint_m - 1.0) / 3.0, 0.0, 1.0)


def _cell_rand(i: NDArray, j: NDArray, salt: int) -> NDArray:
    h = (i.astype(np.int64) * 73856093) ^ (j.astype(np.int64) * 19349663) ^ (salt * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    return ((h >> 8) & 0xFFFF).astype(float) / 65535.0


def _albedo(
    mat: NDArray, p: NDArray, n: NDArray, footprint_m: NDArray, seed: int
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Textured albedo (k, 3), constant mirror reflectance (k,), Fresnel reflectance at normal
    incidence (k,) and its tint (k, 3) of hit points."""
    alb = _ALBEDO[mat].copy()
    mirror = np.zeros(len(mat))
    f0 = _F0[mat].copy()
    tint = _TINT[mat].copy()
    u, v, vertical = _tex_coords(p, n)
    kinds = np.array(_TEXTURE)[mat]
    large = fbm(u / 6.0, v / 6.0, seed + 11, octaves=3)  # stains, weathering
    for kind in set(kinds.tolist()):
        k = np.flatnonzero(kinds == kind)
        uk, vk, fk, lk = u[k], v[k], footprint_m[k], large[k]
        if kind in ("grass", "foliage"):
            scale = 0.4 if kind == "foliage" else 1.5
            fine = fbm(uk / scale, vk / scale + 0.37 * p[k, 0], seed + 21, octaves=4)
            clump = (fine - 0.5) * 2.2 * _fade(scale, fk)
            hue = np.stack([1.0 + 0.8 * (lk - 0.5), np.ones_like(lk), 1.0 - 0.5 * (lk - 0.5)], -1)
            alb[k] *= hue * np.clip(1.0 + clump + 0.6 * (lk - 0.5), 0.2, 2.2)[:, None]
        elif kind in ("gravel", "bark"):
            fine = fbm(uk / 0.08, vk / (0.08 if kind == "gravel" else 0.6), seed + 31, octaves=3)
            alb[k] *= np.clip(1.0 + 1.4 * (fine - 0.5) * _fade(0.08, fk), 0.3, 2.0)[:, None]
        elif kind == "brick":
            row = np.floor(vk / 0.075)
            col = np.floor(uk / 0.225 + 0.5 * (row % 2))
            mortar = (np.mod(vk, 0.075) < 0.012) | (np.mod(uk / 0.225 + 0.5 * (row % 2), 1) < 0.05)
            per = 0.75 + 0.5 * _cell_rand(row, col, seed)
            w = _fade(0.075, fk)
            brick = np.where(mortar, 1.8, per)
            soot = fbm(uk / 1.5, vk / 0.8, seed + 13, octaves=3)
            alb[k] *= (1.0 + w * (brick - 1.0) + 0.8 * (lk - 0.5) + 0.5 * (soot - 0.5))[:, None]
        elif kind == "rock":
            warp = fbm(uk / 8.0, vk / 8.0, seed + 41, octaves=3)
            band = fbm(np.zeros_like(vk), (vk + 6.0 * warp) / 0.7, seed + 43, octaves=4)
            crack = fbm(uk / 0.5, vk / 0.5, seed + 47, octaves=3)
            tone = 1.0 + 1.2 * (band - 0.5) - 0.8 * np.clip(0.38 - crack, 0, 1) * _fade(0.3, fk)
            tint = np.stack(
                [1.0 + 0.3 * (band - 0.5), np.ones_like(band), 1.0 - 0.3 * (band - 0.5)], -1
            )
            alb[k] *= tint * np.clip(tone, 0.3, 2.0)[:, None]
        elif kind in ("concrete", "plaster", "metal", "tiles"):
            grain = fbm(uk / 0.2, vk / 0.2, seed + 51, octaves=3)
            tone = 1.0 + 0.5 * (lk - 0.5) + 0.15 * (grain - 0.5) * _fade(0.2, fk)
            if kind == "concrete":
                joint = (np.mod(uk, 3.0) < 0.03) | (np.mod(vk, 1.5) < 0.03)
                tone = tone - 0.35 * joint * _fade(0.03, fk)
            elif kind == "tiles":
                tone = tone - 0.4 * (np.mod(vk, 0.3) < 0.06) * _fade(0.06, fk)
            elif kind == "metal":
                ribs = 0.5 + 0.5 * np.cos(2 * np.pi * uk / 0.2)
                tone = tone + 0.15 * (ribs - 0.5) * _fade(0.1, fk)
                mirror[k] = 0.03
            alb[k] *= np.clip(tone, 0.2, 2.0)[:, None]
            if kind == "plaster":
                # windows: dark glass reflecting the sky, on the walls of buildings
                fu, fv = np.mod(uk, 3.0) / 3.0, np.mod(vk, 3.2) / 3.2
                vert = vertical[k]
                win = vert & (fu > 0.3) & (fu < 0.75) & (fv > 0.3) & (fv < 0.8)
                frame = vert & (fu > 0.27) & (fu < 0.78) & (fv > 0.27) & (fv < 0.83) & ~win
                alb[k[win]] = 0.04
                alb[k[frame]] = 0.7
                mirror[k[win]] = 0.25
        elif kind == "glass":  # curtain wall: mullions and spandrels opaque, panes mirror
            fu = np.mod(uk, GLASS_PANE_M[0])
            fv = np.mod(vk, GLASS_PANE_M[1])
            solid = (fu < 0.08) | (fv < 0.9)
            alb[k[solid]] = (0.10, 0.11, 0.12)
            f0[k[solid]] = 0.0
        elif kind == "white":  # pale render with rows of glass windows
            grain = fbm(uk / 0.3, vk / 0.3, seed + 53, octaves=3)
            tone = 1.0 + 0.12 * (lk - 0.5) + 0.08 * (grain - 0.5) * _fade(0.3, fk)
            alb[k] *= np.clip(tone, 0.5, 1.2)[:, None]
            fu, fv = np.mod(uk, WINDOW_GRID_M[0]), np.mod(vk, WINDOW_GRID_M[1])
            win = vertical[k] & (fu >= 0.6) & (fu < 1.8) & (fv >= 0.9) & (fv < 2.5)
            alb[k[win]] = _GLASS.albedo_rgb
            f0[k[win]] = _GLASS.f0
            tint[k[win]] = _GLASS.tint_rgb
    return np.clip(alb, 0.0, 0.95), mirror, f0, tint


def schlick_reflectance(f0: ArrayLike, cos_incidence: ArrayLike) -> NDArray:
    """Fresnel reflectance by Schlick's approximation, ``f0 + (1 - f0) (1 - cos)^5``.

    Parameters
    ----------
    f0 : array_like
        Reflectance at normal incidence, 0-1.
    cos_incidence : array_like
        Cosine of the angle between the viewing ray and the surface normal (clipped to 0-1).

    Returns
    -------
    ndarray
        Reflectance, broadcast shape.
    """
    c = np.clip(np.asarray(cos_incidence, float), 0.0, 1.0)
    f = np.asarray(f0, float)
    return np.asarray(f + (1.0 - f) * (1.0 - c) ** 5)


def _rippled(n: NDArray, p: NDArray, ripple_rad: NDArray, seed: int) -> NDArray:
    """Normals (k, 3) tilted by a smooth random field of standard deviation ``ripple_rad``."""
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(n, t1)
    # fbm has a standard deviation of about 0.1 about its mean 0.5
    g1 = (fbm(p[:, 0] / 0.6, p[:, 1] / 0.6 + p[:, 2], seed + 61, octaves=4) - 0.5) / 0.1
    g2 = (fbm(p[:, 0] / 0.6 + 5.3, p[:, 1] / 0.6 - p[:, 2], seed + 67, octaves=4) - 0.5) / 0.1
    out = n + ripple_rad[:, None] * (g1[:, None] * t1 + g2[:, None] * t2)
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _mirrored_radiance(
    world: SceneMesh,
    casters: Casters,
    sky: SkyModel,
    origin: NDArray,
    refl: NDArray,
    elapsed_s: float,
    options: RenderOptions,
) -> NDArray:
    """Radiance (k, 3) arriving along mirrored rays: the sky where they escape, the scenery
    (textured, sunlit, without further mirrors) where they hit it."""
    out = sky.radiance(refl, origin, elapsed_s)
    hits = casters.full.cast(origin, refl)
    h = np.flatnonzero(hits.hit)
    if h.size == 0:
        return np.asarray(out)
    t = hits.distance_m[h]
    p = origin[h] + refl[h] * t[:, None]
    n = hits.normal[h]
    n = np.where((np.sum(n * refl[h], -1) > 0)[:, None], -n, n)
    mat = np.asarray(world.face_material)[hits.face_id[h]].astype(int)
    alb, _, _, _ = _albedo(mat, p, n, np.full(h.size, 0.05), int(getattr(world, "seed", 0)))
    light = sky.ambient_radiance(n)
    e_sun = sky.sun_irradiance
    if np.any(e_sun > 0):
        s = sky.sun_direction
        cos = np.clip(n @ s, 0.0, 1.0)
        trans = sky.sun_transmittance(p, elapsed_s) * cos
        if options.shadows:
            trans = trans * ~casters.full.occluded(p + 0.02 * n, np.broadcast_to(s, p.shape))
        light = light + trans[:, None] * (e_sun / np.pi)[None, :]
    vis_m = options.visibility_m / (3.0 if sky.condition == "overcast" else 1.0)
    haze = (1.0 - np.exp(-t / vis_m))[:, None]
    out = np.array(out, float)
    out[h] = alb * light * (1.0 - haze) + sky.horizon_radiance[None, :] * haze
    return out


# --------------------------------------------------------------------------------------------
# shading
# --------------------------------------------------------------------------------------------


def _hemisphere(n: NDArray, rng: np.random.Generator) -> NDArray:
    """Cosine-weighted random directions (k, 3) about unit normals (k, 3)."""
    r1, r2 = rng.random(len(n)), rng.random(len(n))
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t = np.cross(n, a)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(n, t)
    r, phi = np.sqrt(r1), 2 * np.pi * r2
    return (
        (r * np.cos(phi))[:, None] * t
        + (r * np.sin(phi))[:, None] * b
        + np.sqrt(1 - r1)[:, None] * n
    )


def _shade(
    world: SceneMesh,
    casters: Casters,
    sky: SkyModel,
    origin: NDArray,
    d: NDArray,
    t: NDArray,
    face: NDArray,
    normal: NDArray,
    visibility: NDArray,
    pixel_angle_rad: float,
    elapsed_s: float,
    options: RenderOptions,
) -> NDArray:
    """Radiance (k, 3) of hit samples."""
    p = origin + d * t[:, None]
    n = np.where((np.sum(normal * d, -1) > 0)[:, None], -normal, normal)
    mat = np.asarray(world.face_material)[face].astype(int)
    # footprint of a pixel on the surface, stretched by grazing incidence
    footprint = t * pixel_angle_rad / np.maximum(np.abs(np.sum(n * d, -1)), 0.15)
    seed = int(getattr(world, "seed", 0))
    alb, mirror, f0, tint = _albedo(mat, p, n, footprint, seed)
    light = sky.ambient_radiance(n) * visibility[:, None]
    e_sun = sky.sun_irradiance
    if np.any(e_sun > 0):
        s = sky.sun_direction
        cos = np.clip(n @ s, 0.0, 1.0)
        lit = np.flatnonzero(cos > 0)
        sun = np.zeros(len(p))
        if lit.size:
            trans = sky.sun_transmittance(p[lit], elapsed_s)
            if options.shadows:
                blocked = casters.full.occluded(
                    p[lit] + 0.02 * n[lit], np.broadcast_to(s, (lit.size, 3))
                )
                trans = trans * ~blocked
            sun[lit] = cos[lit] * trans
        light = light + sun[:, None] * (e_sun / np.pi)[None, :]
    rad = alb * light
    if np.any(mirror > 0):
        m = np.flatnonzero(mirror > 0)
        refl = d[m] - 2.0 * np.sum(d[m] * n[m], -1, keepdims=True) * n[m]
        rad[m] = rad[m] * (1 - mirror[m, None]) + mirror[m, None] * sky.radiance(
            refl, p[m], elapsed_s
        )
    if np.any(f0 > 0):  # Fresnel mirrors: glass, water, wet ground
        m = np.flatnonzero(f0 > 0)
        nm = n[m]
        rip = _RIPPLE[mat[m]]
        if np.any(rip > 0):
            nm = _rippled(nm, p[m], rip, seed)
        cos = -np.sum(d[m] * nm, -1)
        refl = d[m] + 2.0 * cos[:, None] * nm
        below = np.minimum(np.sum(refl * n[m], -1), 0.0)  # a ripple tilted it into the surface
        refl = refl - 2.0 * below[:, None] * n[m]
        refl /= np.linalg.norm(refl, axis=-1, keepdims=True)
        r = schlick_reflectance(f0[m], cos)[:, None]
        mirrored = _mirrored_radiance(world, casters, sky, p[m] + 0.02 * n[m], refl, elapsed_s,
                                      options)  # fmt: skip
        rad[m] = rad[m] * (1.0 - r) + r * tint[m] * mirrored
    vis_m = options.visibility_m / (3.0 if sky.condition == "overcast" else 1.0)
    haze = (1.0 - np.exp(-t / vis_m))[:, None]
    return rad * (1.0 - haze) + sky.horizon_radiance[None, :] * haze


def _ambient_visibility(
    casters: Casters,
    origin: NDArray,
    d: NDArray,
    t: NDArray,
    normal: NDArray,
    hit_index: NDArray,
    shape: tuple[int, int],
    rng: np.random.Generator,
    n_rays: int,
) -> NDArray:
    """Share of the ambient light reaching each pixel's centre hit, smoothed over 5 x 5 pixels."""
    h, w = shape
    if n_rays == 0 or hit_index.size == 0:
        return np.ones(h * w)
    p = origin + d[hit_index] * t[hit_index, None]
    n = normal[hit_index]
    n = np.where((np.sum(n * d[hit_index], -1) > 0)[:, None], -n, n)
    acc = np.zeros(hit_index.size)
    for _ in range(n_rays):
        dirs = _hemisphere(n, rng)
        hits = casters.full.cast(p + 0.02 * n, dirs)
        # a far obstacle still passes most light around it; a near one bounces a little
        acc += np.where(
            np.isfinite(hits.distance_m), 0.15 + 0.85 * (1 - np.exp(-hits.distance_m / 60.0)), 1.0
        )
    vis = np.zeros(h * w, np.float32)
    wgt = np.zeros(h * w, np.float32)
    vis[hit_index] = acc / n_rays
    wgt[hit_index] = 1.0
    k = (5, 5)
    num = cv2.GaussianBlur(vis.reshape(h, w), k, 1.2)
    den = cv2.GaussianBlur(wgt.reshape(h, w), k, 1.2)
    return (num / np.maximum(den, 1e-6)).ravel()


@lru_cache(maxsize=8)
def _camera_rays(camera: CameraModel) -> tuple[NDArray, NDArray]:
    """Unit camera-frame rays through pixel centres (H*W, 3) and pixel corners (H+1, W+1, 3).

    NaN rows mark pixels outside the image (beyond a fisheye's circle); corner rays outside it
    are replaced by the nearest centre's ray so interpolation stays finite.
    """
    u, v = camera.pixel_grid()
    centre = camera.pixel_to_ray(u, v).reshape(-1, 3)
    vc, uc = np.mgrid[0 : camera.height_px + 1, 0 : camera.width_px + 1] - 0.5
    corner = camera.pixel_to_ray(uc.astype(float), vc.astype(float))
    bad = ~np.all(np.isfinite(corner), -1)
    if np.any(bad):
        cc = centre.reshape(camera.height_px, camera.width_px, 3)
        near = cc[np.clip(np.round(vc).astype(int), 0, camera.height_px - 1),
                  np.clip(np.round(uc).astype(int), 0, camera.width_px - 1)]  # fmt: skip
        corner = np.where(bad[..., None], np.nan_to_num(near, nan=0.0), corner)
        corner[np.linalg.norm(corner, axis=-1) == 0] = (0.0, 0.0, 1.0)
    for a in (centre, corner):
        a.setflags(write=False)
    return centre, corner


def render_radiance(
    world: SceneMesh,
    casters: Casters,
    camera: CameraModel,
    camera_pose: tuple[ArrayLike, ArrayLike],
    sky: SkyModel,
    rng: np.random.Generator,
    options: RenderOptions | None = None,
    elapsed_s: float = 0.0,
) -> tuple[NDArray, NDArray]:
    """Scene radiance and sky label of a frame.

    Anti-aliasing by coverage: every pixel casts ``supersample**2`` jittered rays to measure
    which share of it is covered by obstacles; the covered share takes the shading of the
    surface seen (through the centre, or through a sub-ray when only those hit, e.g. a wire
    thinner than a pixel), the rest the sky radiance.

    Parameters
    ----------
    world : SceneMesh
        A :class:`~predisat.synth.world.World`, or any mesh with ``face_material`` (indices
        into ``MATERIALS``) and optionally ``seed``.
    casters : Casters
        Built on ``world`` (see :meth:`Casters.for_world`).
    camera : CameraModel
    camera_pose : (position (3,), R_cam_to_enu (3, 3))
        Camera centre in world ENU metres and rotation with ``v_enu = R @ v_camera``.
    sky : SkyModel
        Sun and sky in the world's ENU frame.
    rng : numpy.random.Generator
        Sample jitter and ambient rays.
    options : RenderOptions, optional
    elapsed_s : float
        Seconds since the start of the run (cloud drift).

    Returns
    -------
    radiance : ndarray, shape (H, W, 3), float32
        Linear RGB, kcd/m2 (0 outside a fisheye's image circle).
    label : ndarray, shape (H, W), uint8
        255 sky, 128 thin L-band-transparent structure against the sky, 0 otherwise, from the
        ray through the pixel centre.
    """
    opt = options or RenderOptions()
    pos, rot = _checked_pose(camera_pose)
    h, w = camera.height_px, camera.width_px
    rc, corner = _camera_rays(camera)
    valid = np.all(np.isfinite(rc), axis=-1)
    dc = np.where(valid[:, None], rc, [0.0, 0.0, 1.0]) @ rot.T
    orig = np.broadcast_to(pos, dc.shape)
    hc = casters.full.cast(orig, dc)
    label = _centre_label(casters, world.face_material, hc, orig, dc, valid)
    hit_c = hc.hit & valid
    cover, d_obj = _coverage(casters, hit_c, valid, corner, rot, orig, dc, (h, w), rng, opt)
    obj, t_o, f_o, n_o = _surface_hits(casters, hc, hit_c, cover, orig, d_obj)
    vis = _ambient_visibility(casters, pos, d_obj, t_o, n_o, obj, (h, w), rng, opt.ambient_rays)
    out = np.zeros((h * w, 3))
    if obj.size:
        out[obj] = _shade(
            world,
            casters,
            sky,
            pos,
            d_obj[obj],
            t_o[obj],
            f_o[obj],
            n_o[obj],
            vis[obj],
            1.0 / max(camera.fx, camera.fy),
            elapsed_s,
            opt,
        )
    # the sky behind the uncovered share
    sky_px = np.flatnonzero((cover < 1.0) & valid)
    if sky_px.size:
        c = cover[sky_px, None]
        out[sky_px] = out[sky_px] * c + sky.radiance(dc[sky_px], pos, elapsed_s) * (1.0 - c)
    out[~valid] = 0.0
    return out.reshape(h, w, 3).astype(np.float32), label.reshape(h, w)


def _checked_pose(camera_pose: tuple[ArrayLike, ArrayLike]) -> tuple[NDArray, NDArray]:
    """Camera centre (3,) and camera-to-ENU rotation (3, 3) of a pose, the rotation checked."""
    pos = np.asarray(camera_pose[0], float).reshape(3)
    rot = np.asarray(camera_pose[1], float)
    if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6):
        raise ValueError("camera_pose[1] must be a (3, 3) rotation matrix (camera to ENU)")
    return pos, rot


def _centre_label(
    casters: Casters, face_material: NDArray, hc: Hits, orig: NDArray, dc: NDArray, valid: NDArray
) -> NDArray:
    """Label (H*W,) uint8 from the centre rays' hits ``hc``; L-band-transparent hits are looked
    through."""
    mat_c = hc.material_id(face_material)
    thin = hc.hit & _THIN[np.maximum(mat_c, 0)]
    label = np.where(hc.hit, LABEL_OBSTACLE, LABEL_SKY).astype(np.uint8)
    if np.any(thin):
        behind = casters.lband.occluded(orig[: int(thin.sum())], dc[thin])
        label[np.flatnonzero(thin)[~behind]] = LABEL_THIN
    label[~valid] = LABEL_OBSTACLE
    return label


def _coverage(
    casters: Casters,
    hit_c: NDArray,
    valid: NDArray,
    corner: NDArray,
    rot: NDArray,
    orig: NDArray,
    dc: NDArray,
    shape: tuple[int, int],
    rng: np.random.Generator,
    opt: RenderOptions,
) -> tuple[NDArray, NDArray]:
    """Obstacle coverage (H*W,) of each pixel and the direction (H*W, 3) to shade it along.

    Jittered sub-rays are cast near silhouettes only (within 3 px of a hit/miss change, which
    also catches wires thinner than a pixel: their centre-ray hits are dashes 1 / width px
    apart); where the centre ray misses, one hitting sub-ray's direction is kept.
    """
    n = int(opt.supersample)
    cover = hit_c.astype(float)
    if n <= 1:
        return cover, dc
    h, w = shape
    hm = hit_c.reshape(h, w).astype(np.uint8)
    kernel = np.ones((7, 7), np.uint8)
    near = (cv2.dilate(hm, kernel) > 0) & (cv2.dilate(1 - hm, kernel) > 0)
    edge = np.flatnonzero(near.ravel() & valid)
    corner_e = np.stack([corner[:-1, :-1], corner[:-1, 1:], corner[1:, :-1], corner[1:, 1:]],
                        -2).reshape(-1, 4, 3)[edge]  # fmt: skip
    cov = np.zeros(edge.size)
    d_obj = dc.copy()
    found = hit_c[edge].copy()
    grid = (np.arange(n) + 0.5) / n
    for ga in grid:
        for gb in grid:
            fu = np.clip(ga + rng.uniform(-0.5, 0.5, edge.size) / n, 0.0, 1.0)[:, None]
            fv = np.clip(gb + rng.uniform(-0.5, 0.5, edge.size) / n, 0.0, 1.0)[:, None]
            r = (corner_e[:, 0] * (1 - fu) + corner_e[:, 1] * fu) * (1 - fv) + (
                corner_e[:, 2] * (1 - fu) + corner_e[:, 3] * fu
            ) * fv
            d = r @ rot.T
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            occ = casters.full.occluded(orig[: edge.size], d)
            cov += occ
            new = occ & ~found
            d_obj[edge[new]] = d[new]
            found |= new
    cover[edge] = cov / (n * n)
    return cover, d_obj


def _surface_hits(
    casters: Casters, hc: Hits, hit_c: NDArray, cover: NDArray, orig: NDArray, d_obj: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Covered pixels with a surface to shade (k,) and every pixel's hit distance (H*W,), face
    (H*W,) and normal (H*W, 3) along ``d_obj`` (recast where only a sub-ray hit)."""
    obj = np.flatnonzero(cover > 0)
    redo = obj[~hit_c[obj]]
    t_o, f_o, n_o = hc.distance_m.copy(), hc.face_id.copy(), hc.normal.copy()
    if redo.size:
        ho = casters.full.cast(orig[: redo.size], d_obj[redo])
        t_o[redo], f_o[redo], n_o[redo] = ho.distance_m, ho.face_id, ho.normal
    obj = obj[f_o[obj] >= 0]
    return obj, t_o, f_o, n_o


# --------------------------------------------------------------------------------------------
# camera and sensor
# --------------------------------------------------------------------------------------------


def _sun_glare(
    rays_cam: NDArray, camera: CameraModel, sun_cam: NDArray, e_sun: NDArray, strength: float
) -> NDArray:
    """Veiling glare and flare ghosts (H, W, 3) of a sun at unit camera direction ``sun_cam``.

    Veiling glare falls as 1 / angle^2 (the CIE glare spread function scaled down tenfold for
    a camera lens); ghosts are soft discs mirrored through the image centre. A 360-degree
    panorama (``equirect``) is stitched from lenses looking every way: the sun is always in
    front of one of them (full veil, no obliquity factor) and the stitching leaves no ghost
    at a mirrored place.
    """
    h, w = camera.height_px, camera.width_px
    pano = camera.model == "equirect"
    cos_axis = 1.0 if pano else float(sun_cam[2])
    if cos_axis <= 0.05 or strength <= 0:
        return np.zeros((h, w, 3))
    ang = np.degrees(np.arccos(np.clip(rays_cam @ sun_cam, -1.0, 1.0)))
    veil = strength * cos_axis / np.maximum(ang, 0.5) ** 2
    out = veil[..., None] * e_sun[None, None, :]
    if pano:
        return out
    us_px, vs_px = camera.ray_to_pixel(sun_cam[None, :])
    us, vs = float(us_px[0]), float(vs_px[0])
    if np.isfinite(us) and -0.1 * w < us < 1.1 * w and -0.1 * h < vs < 1.1 * h:
        cu, cv = camera.cx, camera.cy
        v, u = np.mgrid[0:h, 0:w]
        ghosts = ((-0.35, 0.045, (0.6, 1.0, 0.7)), (-0.7, 0.08, (0.7, 0.6, 1.0)),
                  (-1.2, 0.03, (1.0, 0.8, 0.5)), (0.45, 0.02, (0.8, 1.0, 1.0)))  # fmt: skip
        for t, radius, tint in ghosts:
            gu, gv = cu + t * (us - cu), cv + t * (vs - cv)
            r = np.hypot(u - gu, v - gv) / (radius * w)
            disc = np.clip(1.2 - r, 0.0, 1.0) ** 0.5 * (r < 1.2)
            out += (strength * 0.004 * disc)[..., None] * (e_sun * np.asarray(tint))[None, None]
    return out


def expose(
    radiance: ArrayLike,
    camera: CameraModel,
    state: SensorState,
    options: RenderOptions | None = None,
    sun_cam: ArrayLike | None = None,
    sun_irradiance_rgb: ArrayLike = (0.0, 0.0, 0.0),
    white_rgb: ArrayLike = (1.0, 1.0, 1.0),
) -> NDArray:
    """Turn scene radiance into the camera's 8-bit BGR image.

    Parameters
    ----------
    radiance : array_like, shape (H, W, 3)
        Linear RGB radiance (kcd/m2), e.g. from :func:`render_radiance`.
    camera : CameraModel
    state : SensorState
        Exposure bias, blur, white-balance error and noise seed of this frame.
    options : RenderOptions, optional
    sun_cam : array_like, shape (3,), optional
        Unit direction to the sun in the camera frame, when the sun is visible from the camera
        (not behind an obstacle); adds veiling glare and flare ghosts.
    sun_irradiance_rgb : array_like, shape (3,)
        Sun irradiance reaching the lens (klx), for the glare.
    white_rgb : array_like, shape (3,)
        Illuminant colour the auto white balance neutralises.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        BGR image (before JPEG compression).
    """
    opt = options or RenderOptions()
    rad = np.asarray(radiance, float)
    h, w = camera.height_px, camera.width_px
    if rad.shape != (h, w, 3):
        raise ValueError(f"radiance must have shape ({h}, {w}, 3), got {rad.shape}")
    rays = _camera_rays(camera)[0].reshape(h, w, 3)
    inside = np.all(np.isfinite(rays), -1)
    rays = np.where(inside[..., None], rays, [0.0, 0.0, 1.0])
    img = rad.copy()
    if sun_cam is not None and opt.glare > 0:
        img += _sun_glare(
            rays,
            camera,
            np.asarray(sun_cam, float),
            np.asarray(sun_irradiance_rgb, float),
            opt.glare,
        )
    # optics: blur and vignetting
    if state.blur_px > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), state.blur_px)
    if camera.model != "equirect":  # a stitched panorama is flat-fielded
        theta = np.arccos(np.clip(rays[..., 2], -1.0, 1.0))
        corner = max(float(theta[inside].max()), 1e-3) if np.any(inside) else 1.0
        img *= (1.0 - opt.vignetting * (theta / corner) ** 2)[..., None]
    # auto-exposure: centre-weighted mean luminance to the target, with a random bias
    y = img @ _LUMA
    y = np.minimum(y, 3.0 * float(np.median(y[inside])) if np.any(inside) else 1.0)  # clipped
    v, u = np.mgrid[0:h, 0:w]
    wgt = np.exp(-(((u - w / 2) / (0.45 * w)) ** 2 + ((v - h / 2) / (0.45 * h)) ** 2)) * inside
    meter = max(float(np.sum(y * wgt) / max(np.sum(wgt), 1e-9)), 1e-6)
    k = opt.exposure_target * 2.0**state.exposure_ev / meter
    gain = max(1.0, k / opt.max_exposure)
    white = np.asarray(white_rgb, float)
    wb = float(white @ _LUMA) / np.maximum(white, 1e-9) * np.asarray(state.wb_gain_rgb)
    x = img * k * wb[None, None, :]
    if opt.glare > 0:  # bloom of highlights beyond clipping
        excess = np.clip(x - 1.0, 0.0, 30.0)
        if np.any(excess > 0):
            x += 0.05 * opt.glare * cv2.GaussianBlur(excess, (0, 0), 0.015 * w + 1.0)
            x += 0.15 * opt.glare * cv2.GaussianBlur(excess, (0, 0), 2.0)
    # sensor: Poisson-Gaussian noise, gain in the dark
    nrng = np.random.default_rng(state.noise_seed)
    fw = opt.full_well_e / gain
    e = np.clip(x, 0.0, 1.5) * fw
    e = (
        e
        + np.sqrt(e) * nrng.standard_normal(e.shape)
        + opt.read_noise_e * nrng.standard_normal(e.shape)
    )
    x = np.clip(e / fw, 0.0, None)
    # camera rendering: filmic shoulder, a touch of saturation, sRGB gamma
    white_pt = 2.5
    x = x * (1.0 + x / white_pt**2) / (1.0 + x) * 1.35
    lum = (x @ _LUMA)[..., None]
    x = np.clip(lum + 1.15 * (x - lum), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    out = np.clip(np.round(srgb * 255.0), 0, 255).astype(np.uint8)
    out[~inside] = 0
    return np.ascontiguousarray(out[..., ::-1])


def render_frame(
    world: SceneMesh,
    casters: Casters,
    camera: CameraModel,
    camera_pose: tuple[ArrayLike, ArrayLike],
    sky: SkyModel,
    rng: np.random.Generator,
    options: RenderOptions | None = None,
    elapsed_s: float = 0.0,
) -> tuple[NDArray, NDArray]:
    """Render one survey frame: the camera image and its exact sky label.

    Parameters are those of :func:`render_radiance`; the same generator then draws the frame's
    :class:`SensorState`, so a seed fixes the frame exactly.

    Returns
    -------
    image : ndarray, shape (H, W, 3), uint8
        BGR, before JPEG compression.
    label : ndarray, shape (H, W), uint8
        255 sky, 128 thin L-band-transparent structure against the sky, 0 otherwise.
    """
    opt = options or RenderOptions()
    rad, label = render_radiance(world, casters, camera, camera_pose, sky, rng, opt, elapsed_s)
    state = SensorState.draw(rng, opt)
    pos = np.asarray(camera_pose[0], float).reshape(3)
    rot = np.asarray(camera_pose[1], float)
    s = sky.sun_direction
    sun_cam = None
    e_sun = sky.sun_irradiance
    if np.any(e_sun > 0):
        trans = float(sky.sun_transmittance(pos[None, :], elapsed_s)[0])
        if trans > 0.02 and not bool(casters.full.occluded(pos[None, :], s[None, :])[0]):
            sun_cam = rot.T @ s
            e_sun = e_sun * trans
    up = np.array([0.0, 0.0, 1.0])
    white = sky.ambient_radiance(up) + sky.sun_irradiance * max(s[2], 0.0) / np.pi
    img = expose(rad, camera, state, opt, sun_cam, e_sun, white)
    return img, label
