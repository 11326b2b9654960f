"""Procedural upright photos with exact sky labels: training data for the sky classifier.

The corridor renderer (:mod:`predisat.synth.render`) gives physically consistent side-camera
frames of a railway line, but its scenery is narrow: a model trained on it alone takes light
facades, snow and concrete in real photos for sky (``docs/segmentation.md``). This module
draws *domain-randomised* 2-D scenes instead: a sky (clear gradients, hazy, overcast, dusk,
clouds with dark bases, the sun and its glare) behind layers of obstacles with random shapes,
colours and textures (mountains with snow, hills and tree lines, buildings in perspective with
window grids, white, grey, brick or glass facades that mirror the sky, trees with gaps in
their foliage, masts, wires, bridge decks and branches hanging from the top edge, roads, snow,
water), through random camera effects (exposure and clipping, white balance, vignetting,
blur, noise, JPEG). Every pixel's label is known exactly: 255 sky, 128 thin L-band-transparent
structure against the sky (wires: sky under the thin-structure policy), 0 obstacle.

Nothing here is meant to look like one real place; the variety is the point. Only the
project's own code and seeds make these images, so a model trained on them may ship.

>>> photo = random_photo(7)
>>> photo.image_bgr.shape, photo.label.shape
((240, 320, 3), (240, 320))
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from predisat.synth.sky import fbm

__all__ = ["SkyPhoto", "random_photo"]

SKY, THIN, OBSTACLE = 255, 128, 0
_SIZES_PX = ((320, 240), (240, 320), (288, 288), (352, 198), (320, 240), (256, 256))


@dataclass(frozen=True)
class SkyPhoto:
    """One procedural photo.

    Attributes
    ----------
    image_bgr : ndarray of uint8, shape (H, W, 3)
    label : ndarray of uint8, shape (H, W)
        255 sky, 128 thin structure against the sky (counted as sky), 0 obstacle.
    seed : int
    kind : str
        The scene recipe (``street``, ``landscape``, ``canopy``, ``mixed``).
    """

    image_bgr: NDArray[np.uint8]
    label: NDArray[np.uint8]
    seed: int
    kind: str


class _Canvas:
    """Float RGB (0-1, display referred) image and its label, painted back to front."""

    def __init__(self, w: int, h: int, rng: np.random.Generator, seed: int) -> None:
        self.w, self.h, self.rng, self.seed = w, h, rng, seed
        self.rgb = np.zeros((h, w, 3), np.float32)
        self.label = np.full((h, w), SKY, np.uint8)
        self.yy, self.xx = np.mgrid[0:h, 0:w].astype(np.float32)
        self._salt = 0

    def noise(self, scale_px: float, octaves: int = 4) -> NDArray:
        self._salt += 1
        off = self.rng.uniform(0, 256, 2)
        return fbm(self.xx / scale_px + off[0], self.yy / scale_px + off[1],
                   self.seed * 31 + self._salt, octaves=octaves)

    def paint(self, mask: NDArray, colour: NDArray, label: int = OBSTACLE) -> None:
        """Opaque paint: ``colour`` (H, W, 3) or (3,) where ``mask``."""
        col = np.broadcast_to(np.asarray(colour, np.float32), self.rgb.shape)
        self.rgb[mask] = col[mask]
        if label == THIN:
            self.label[mask & (self.label != OBSTACLE)] = THIN
        else:
            self.label[mask] = label


def _colour(rng: np.random.Generator, base: tuple[float, float, float], jitter: float) -> NDArray:
    return np.clip(np.asarray(base) * (1 + rng.normal(0, jitter, 3)), 0, 1).astype(np.float32)


def _hsv(hue_deg: float, sat: float, val: float) -> NDArray:
    """RGB (3,) of a hue (deg), saturation and value in 0-1."""
    px = np.array([[[hue_deg / 2.0, sat * 255.0, val * 255.0]]], np.float32)
    rgb = cv2.cvtColor(px.astype(np.uint8), cv2.COLOR_HSV2RGB)[0, 0] / 255.0
    return np.asarray(rgb, np.float32)


def _sky(c: _Canvas) -> NDArray:
    """Sky background (H, W, 3) and returns the horizon colour."""
    rng = c.rng
    kind = rng.choice(["clear", "clear", "clear", "hazy", "overcast", "overcast", "dusk", "storm",
                       "cloudy", "cloudy", "cloudy"])
    horizon_y = c.h * rng.uniform(0.3, 1.6)
    if kind in ("clear", "cloudy"):
        # from pale to deep navy: the zenith of real clear skies spans a wide range
        zen = _hsv(rng.uniform(195, 235), rng.uniform(0.25, 0.9), rng.uniform(0.3, 0.98))
        hor = np.clip(zen + (1 - zen) * rng.uniform(0.35, 0.9), 0, 1).astype(np.float32)
    elif kind == "hazy":
        zen = _hsv(rng.uniform(190, 230), rng.uniform(0.1, 0.35), rng.uniform(0.6, 0.95))
        hor = _colour(rng, (0.85, 0.87, 0.88), 0.05)
    elif kind == "overcast":
        g = rng.uniform(0.35, 1.0)
        zen = _colour(rng, (g, g, g * rng.uniform(0.97, 1.1)), 0.03)
        hor = np.clip(zen * rng.uniform(0.8, 1.15), 0, 1).astype(np.float32)
    elif kind == "storm":
        zen = _hsv(rng.uniform(200, 290), rng.uniform(0.1, 0.6), rng.uniform(0.12, 0.5))
        hor = np.clip(zen * rng.uniform(1.1, 2.0), 0, 1).astype(np.float32)
    else:
        zen = _colour(rng, (0.25, 0.35, 0.65), 0.2)
        hor = _hsv(rng.uniform(10, 45), rng.uniform(0.3, 0.8), rng.uniform(0.7, 1.0))
    t = np.clip(1.0 - (horizon_y - c.yy) / (horizon_y + 1e-6), 0.0, 1.0) ** rng.uniform(0.5, 2.5)
    tilt = rng.normal(0, 0.15) * (c.xx / c.w - 0.5)
    t = np.clip(t + tilt, 0, 1)[..., None]
    sky = zen * (1 - t) + hor * t
    if kind in ("cloudy", "overcast", "storm") or rng.random() < 0.25:
        scale = rng.uniform(0.1, 0.5) * c.w
        dens = c.noise(scale, 5)
        cover = rng.uniform(0.3, 0.75)
        alpha = np.clip((dens - (1 - cover) * 0.9 - 0.1) * rng.uniform(3, 8), 0, 1)
        # cloud bases darker than their tops (self-shadowing): the light follows the smoothed
        # density gradient along the rows
        grad = np.gradient(cv2.GaussianBlur(dens, (0, 0), max(1.0, scale * 0.05)), axis=0)
        shade = np.clip(1.0 - rng.uniform(0, 1.5) * grad * scale, 0.55, 1.1)
        white = rng.uniform(0.75, 1.0)
        if rng.random() < 0.35:
            white *= rng.uniform(0.45, 0.8)  # dark rain clouds
        cloud = np.clip(white * shade, 0, 1.1)[..., None] * np.array([1, 1, 1.02], np.float32)
        sky = sky * (1 - alpha[..., None]) + cloud * alpha[..., None]
    if rng.random() < 0.3:
        # the sun and its glare, often clipped to white
        sx, sy = rng.uniform(-0.2, 1.2) * c.w, rng.uniform(-0.3, 0.7) * c.h
        d = np.hypot(c.xx - sx, c.yy - sy) / max(c.w, c.h)
        glow = rng.uniform(0.3, 1.5) * np.exp(-d / rng.uniform(0.03, 0.2))
        sky = sky + glow[..., None] * np.array([1.0, 0.97, 0.9], np.float32)
    c.rgb[:] = sky
    return np.asarray(hor)


def _ridge(c: _Canvas, base_y: float, amp_px: float, scale_px: float, octaves: int = 5) -> NDArray:
    """A random 1-D ridge line y(x) (W,)."""
    n = fbm(np.arange(c.w) / scale_px + c.rng.uniform(0, 256), np.full(c.w, c.rng.uniform(0, 256)),
            c.seed * 17 + int(c.rng.integers(1 << 20)), octaves=octaves)
    return np.asarray(base_y + amp_px * (n - 0.5) * 2.0, np.float32)


def _mountains(c: _Canvas, hor: NDArray) -> None:
    rng = c.rng
    ridge = _ridge(c, c.h * rng.uniform(0.15, 0.7), c.h * rng.uniform(0.05, 0.4),
                   c.w * rng.uniform(0.15, 0.6), 6)
    mask = c.yy >= ridge[None, :]
    rock = _colour(rng, (0.35, 0.36, 0.4), 0.1) * rng.uniform(0.5, 1.6)
    haze = rng.uniform(0.0, 0.7)
    tex = c.noise(c.w * 0.03, 5)
    col = (rock * (1 - haze) + hor * haze)[None, None, :] * (0.6 + 0.8 * tex[..., None])
    if rng.random() < 0.45:
        # snow: bright, smooth, bluish in the shade, below the crest
        line = ridge + c.h * rng.uniform(0.05, 0.6) * c.noise(c.w * 0.05, 3)[0][None, :]
        snow = mask & (c.yy < line) | (mask & (rng.random() < 0.3))
        shade = 0.75 + 0.3 * c.noise(c.w * 0.08, 3)
        white = _colour(rng, (0.95, 0.96, 1.0), 0.04)
        col = np.where(snow[..., None], white * shade[..., None], col)
    c.paint(mask, col)


def _treeline(c: _Canvas) -> None:
    rng = c.rng
    ridge = _ridge(c, c.h * rng.uniform(0.35, 0.85), c.h * rng.uniform(0.02, 0.12),
                   c.w * rng.uniform(0.01, 0.05), 4)
    mask = c.yy >= ridge[None, :]
    green = _colour(rng, (0.18, 0.26, 0.12), 0.35)
    tex = c.noise(c.w * 0.01, 3)
    c.paint(mask, green * (0.5 + tex[..., None]))


def _facade_colour(rng: np.random.Generator, hor: NDArray) -> NDArray:
    palette = [(0.92, 0.92, 0.9), (0.85, 0.82, 0.75), (0.7, 0.7, 0.72), (0.55, 0.3, 0.22),
               (0.8, 0.7, 0.55), (0.5, 0.5, 0.52), (0.95, 0.95, 0.97)]
    if rng.random() < 0.2:
        return np.clip(hor * rng.uniform(0.85, 1.05), 0, 1).astype(np.float32)  # as pale as sky
    return _colour(rng, palette[int(rng.integers(len(palette)))], 0.08)


def _building(c: _Canvas, hor: NDArray, sky_img: NDArray, x0: float, x1: float) -> None:
    rng = c.rng
    top0 = c.h * rng.uniform(-0.3, 0.8)
    top1 = top0 + c.h * rng.normal(0, 0.25)  # perspective: slanted roof line
    u = (c.xx - x0) / max(x1 - x0, 1.0)
    top = top0 + (top1 - top0) * u
    inside = (u >= 0) & (u < 1) & (c.yy >= top)
    if rng.random() < 0.3:  # gable or tower roof
        peak = rng.uniform(0.05, 0.3) * c.h
        top = top - peak * (1 - np.abs(2 * u - 1))
        inside = (u >= 0) & (u < 1) & (c.yy >= top)
    if not inside.any():
        return
    v = (c.yy - top) / (c.h * rng.uniform(0.05, 0.25))  # floors
    glass = rng.random() < 0.15
    base = _facade_colour(rng, hor)
    light = rng.uniform(0.55, 1.15)
    col = np.broadcast_to(base * light, c.rgb.shape).copy()
    grain = c.noise(c.w * rng.uniform(0.005, 0.05), 3)
    col *= (0.85 + 0.3 * grain)[..., None]
    ncols = rng.integers(2, 14)
    fu, fv = np.mod(u * ncols, 1.0), np.mod(v, 1.0)
    if glass:
        # a curtain wall mirrors the sky, cut by mullions
        refl = np.flipud(sky_img) if rng.random() < 0.5 else sky_img
        col = refl * rng.uniform(0.5, 0.95) * _colour(rng, (0.8, 0.9, 1.0), 0.08)
        mull = (fu < 0.06) | (fv < 0.08)
        col[mull] = base * 0.5
    elif rng.random() < 0.9:
        wx0, wx1 = rng.uniform(0.1, 0.35), rng.uniform(0.6, 0.9)
        wy0, wy1 = rng.uniform(0.15, 0.35), rng.uniform(0.65, 0.9)
        win = (fu > wx0) & (fu < wx1) & (fv > wy0) & (fv < wy1) & (v > 0.4)
        if rng.random() < 0.4:
            wcol = sky_img * rng.uniform(0.3, 0.8)  # windows mirroring the sky
        else:
            wcol = np.broadcast_to(_colour(rng, (0.12, 0.13, 0.15), 0.4), c.rgb.shape)
        col = np.where(win[..., None], wcol, col)
        frame = (~win) & (fu > wx0 - 0.04) & (fu < wx1 + 0.04) & (fv > wy0 - 0.05) & \
            (fv < wy1 + 0.05) & (v > 0.4)
        col[frame] = np.clip(col[frame] * rng.uniform(0.6, 1.3), 0, 1)
    if rng.random() < 0.5:  # cornice band under the roof line
        band = (c.yy - top) < rng.uniform(0.01, 0.04) * c.h
        col[band] *= rng.uniform(0.5, 1.2)
    c.paint(inside, col)


def _buildings(c: _Canvas, hor: NDArray) -> None:
    rng = c.rng
    sky_img = c.rgb.copy()
    edges = np.sort(rng.uniform(-0.2, 1.2, int(rng.integers(1, 7))) * c.w)
    for a, b in itertools.pairwise(edges):
        if rng.random() < 0.8:
            _building(c, hor, sky_img, a, b)
    if len(edges) == 1 or rng.random() < 0.4:
        w = rng.uniform(0.2, 0.7) * c.w
        x0 = rng.choice([-0.1 * c.w, c.w - w])
        _building(c, hor, sky_img, x0, x0 + w)


def _tree(c: _Canvas, cx: float, cy: float, r: float) -> None:
    rng = c.rng
    d = np.hypot((c.xx - cx) / (r * rng.uniform(0.7, 1.3)), (c.yy - cy) / r)
    warp = c.noise(r * 0.4, 4)
    crown = d + 0.6 * (warp - 0.5) < 1.0
    # foliage with gaps, denser in the middle of the crown
    leaf = c.noise(max(r * rng.uniform(0.03, 0.12), 1.5), 3)
    dens = rng.uniform(0.25, 0.55) + 0.35 * np.clip(d, 0, 1)
    foliage = crown & (leaf > dens * rng.uniform(0.5, 1.0))
    trunk_w = max(2.0, r * rng.uniform(0.08, 0.2))
    trunk = (np.abs(c.xx - cx) < trunk_w / 2) & (c.yy > cy)
    hue = _colour(rng, [(0.2, 0.32, 0.12), (0.3, 0.38, 0.15), (0.45, 0.32, 0.1),
                        (0.12, 0.2, 0.1)][int(rng.integers(4))], 0.2)
    light = 0.45 + 0.9 * c.noise(max(r * 0.15, 2), 3)
    # sunlit from above: the top of the crown brighter
    light = light * np.clip(1.2 - 0.5 * (c.yy - (cy - r)) / (2 * r), 0.5, 1.3)
    c.paint(trunk, _colour(rng, (0.25, 0.2, 0.15), 0.3))
    c.paint(foliage, hue * light[..., None])


def _trees(c: _Canvas) -> None:
    rng = c.rng
    for _ in range(int(rng.integers(1, 5))):
        r = c.h * rng.uniform(0.1, 0.6)
        _tree(c, rng.uniform(-0.1, 1.1) * c.w, rng.uniform(0.0, 0.8) * c.h, r)


def _overhang(c: _Canvas) -> None:
    """Foliage or a deck hanging from the top edge (sky must not touch the top there)."""
    rng = c.rng
    if rng.random() < 0.5:
        _tree(c, rng.uniform(0, 1) * c.w, -rng.uniform(0.0, 0.3) * c.h, c.h * rng.uniform(0.3, 0.7))
    else:
        y1 = rng.uniform(0.05, 0.35) * c.h
        deck = c.yy < y1 + (c.xx / c.w - 0.5) * rng.normal(0, 0.2) * c.h
        col = _colour(rng, (0.45, 0.44, 0.42), 0.3) * (0.7 + 0.3 * c.noise(c.w * 0.1, 3))[..., None]
        c.paint(deck, col)


def _masts_wires(c: _Canvas) -> None:
    rng = c.rng
    grey = _colour(rng, (0.4, 0.4, 0.42), 0.4)
    for _ in range(int(rng.integers(0, 4))):
        x = rng.uniform(0, c.w)
        w = rng.uniform(4.0, 12.0)
        top = rng.uniform(0.0, 0.6) * c.h
        c.paint((np.abs(c.xx - x) < w / 2) & (c.yy > top), grey * rng.uniform(0.5, 1.2))
    for _ in range(int(rng.integers(0, 5))):
        y0, y1 = rng.uniform(0.0, 0.7, 2) * c.h
        sag = rng.uniform(0, 0.1) * c.h
        u = c.xx / c.w
        y = y0 + (y1 - y0) * u + sag * 4 * u * (1 - u)
        width = rng.uniform(0.6, 2.0)
        wire = np.abs(c.yy - y) < width / 2
        c.paint(wire, np.float32(rng.uniform(0.05, 0.4)) * np.ones(3, np.float32), THIN)


def _ground(c: _Canvas, sky_img: NDArray) -> None:
    rng = c.rng
    y = c.h * rng.uniform(0.6, 1.1) + (c.xx[0] / c.w - 0.5) * rng.normal(0, 0.1) * c.h
    mask = c.yy >= y[None, :]
    kind = rng.choice(["road", "grass", "snow", "water", "sand", "desert", "dry"])
    tex = c.noise(c.w * 0.02, 4)[..., None]
    if kind == "water":
        col = np.flipud(sky_img) * rng.uniform(0.4, 0.9) * (0.9 + 0.2 * tex)
    else:
        base = {"road": (0.4, 0.4, 0.42), "grass": (0.25, 0.35, 0.15), "snow": (0.93, 0.95, 1.0),
                "sand": (0.75, 0.68, 0.5), "desert": (0.82, 0.74, 0.6),
                "dry": (0.62, 0.55, 0.3)}[str(kind)]
        col = _colour(rng, base, 0.1) * (0.75 + 0.5 * tex)
        if kind in ("desert", "dry", "grass"):
            # shrubs and stones: dark specks whose size shrinks toward the horizon
            specks = c.noise(c.w * rng.uniform(0.01, 0.03), 3) > rng.uniform(0.62, 0.75)
            col = np.where(specks[..., None], col * rng.uniform(0.2, 0.5), col)
    c.paint(mask, col)


def _camera(c: _Canvas) -> NDArray[np.uint8]:
    """Exposure, tone curve, white balance, vignetting, blur, noise, JPEG: the final image."""
    rng = c.rng
    img = c.rgb * rng.uniform(0.75, 1.5) * _colour(rng, (1.0, 1.0, 1.0), 0.06)
    r = np.hypot(c.xx / c.w - 0.5, c.yy / c.h - 0.5)
    img = img * (1 - rng.uniform(0, 0.35) * r[..., None] ** 2)
    img = np.clip(img, 0, 1) ** rng.uniform(0.8, 1.25)
    if rng.random() < 0.3:
        hsv = cv2.cvtColor(img.astype(np.float32), cv2.COLOR_RGB2HSV)  # hue in degrees
        hsv[..., 0] = np.mod(hsv[..., 0] + rng.normal(0, 8.0), 360.0)
        hsv[..., 1] = np.clip(hsv[..., 1] * rng.uniform(0.6, 1.4), 0, 1)
        img = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    sigma = rng.uniform(0, 1.0)
    if sigma > 0.3:
        img = cv2.GaussianBlur(img, (0, 0), sigma)
    img = img + rng.normal(0, rng.uniform(0, 0.015), img.shape).astype(np.float32)
    bgr = (np.clip(img, 0, 1)[..., ::-1] * 255 + 0.5).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(50, 96))])
    if not ok:  # pragma: no cover - encoding an in-memory uint8 image does not fail
        return bgr
    return np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR), np.uint8)


def random_photo(seed: int, size_px: tuple[int, int] | None = None) -> SkyPhoto:
    """Draw one procedural upright photo and its exact sky label.

    Parameters
    ----------
    seed : int
        Everything (layout, colours, camera) follows from it.
    size_px : (width, height), optional
        Default: one of a few common aspect ratios around 320 x 240, chosen by the seed.

    Returns
    -------
    SkyPhoto
    """
    rng = np.random.default_rng([int(seed), 0x5C1])
    w, h = size_px if size_px is not None else _SIZES_PX[int(rng.integers(len(_SIZES_PX)))]
    if w < 16 or h < 16:
        raise ValueError(f"size_px must be at least 16 x 16, got {size_px}")
    c = _Canvas(int(w), int(h), rng, int(seed))
    kind = str(rng.choice(["street", "landscape", "canopy", "mixed"]))
    hor = _sky(c)
    sky_img = c.rgb.copy()
    if kind in ("landscape", "mixed") and rng.random() < 0.8:
        _mountains(c, hor)
    if kind != "street" and rng.random() < 0.6:
        _treeline(c)
    if kind in ("street", "mixed") or rng.random() < 0.2:
        _buildings(c, hor)
    if kind in ("canopy", "mixed", "landscape") and rng.random() < 0.7:
        _trees(c)
    if rng.random() < (0.5 if kind == "canopy" else 0.12):
        _overhang(c)
    if rng.random() < 0.5:
        _masts_wires(c)
    if rng.random() < 0.8:
        _ground(c, sky_img)
    # horizontal flip and a small roll, as a hand-held camera
    if rng.random() < 0.5:
        c.rgb, c.label = c.rgb[:, ::-1].copy(), c.label[:, ::-1].copy()
    image = _camera(c)
    label = c.label
    roll = rng.normal(0, 3.0)
    if abs(roll) > 0.5:
        m = cv2.getRotationMatrix2D((w / 2, h / 2), roll, 1.0 + abs(roll) / 40)
        image = np.asarray(cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR,
                                          borderMode=cv2.BORDER_REFLECT), np.uint8)
        label = np.asarray(cv2.warpAffine(label, m, (w, h), flags=cv2.INTER_NEAREST,
                                          borderMode=cv2.BORDER_REFLECT), np.uint8)
    return SkyPhoto(np.ascontiguousarray(image), np.ascontiguousarray(label), int(seed), kind)
