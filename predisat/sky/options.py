"""Options of the sky segmentation: the methods (:data:`METHODS`) and :class:`SkyOptions`.

:func:`predisat.sky.segment.segment_sky` documents the methods these options tune.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["METHODS", "SkyOptions"]

METHODS = ("ensemble", "cnn", "learned", "grabcut")


@dataclass(frozen=True)
class SkyOptions:
    """Parameters of :func:`segment_sky` (defaults suit 45 deg side cameras and street photos).

    Attributes
    ----------
    fisheye : bool
        Upward-looking fisheye: only pixels inside the lens circle are segmented, seeds may lie
        anywhere inside it (not only at the top), and sky gaps are searched by default.
    circle_px : tuple of float, optional
        Lens circle ``(cx, cy, radius)`` in full-resolution pixels; default: the inscribed
        circle of the image shrunk by ``circle_margin``.
    circle_margin : float
        Fraction of the default radius trimmed off (the dark vignetted rim of the lens).
    work_size_px : int
        Longest side of the working image for seeds and GrabCut; the mask is upsampled.
    texture_quantile : float
        Quantile of the texture energy below which a pixel is "smooth" (clipped to
        ``texture_min``..``texture_max``, in Lab lightness units per pixel).
    texture_min, texture_max : float
    texture_weight : float
        Scale of the log-texture channel of the GrabCut feature image (higher: texture counts
        more against colour).
    grabcut_iterations : int
    min_seed_fraction : float
        Smallest seed region, as a fraction of the valid area (unless it is at least 30 % of the
        largest candidate).
    detect_gaps : bool, optional
        Search sky gaps in obstacles (foliage). Default: True for fisheye, False otherwise (in
        side-camera use gaps below the skyline are blocked anyway, and on street photos the
        search confuses white window frames with sky).
    gap_max_mahalanobis : float
        Colour distance (Mahalanobis, Lab) to the sky model below which a gap pixel may be sky.
    gap_min_tophat : float
        How much brighter (Lab lightness) than its surroundings a gap pixel must be.
    thin_px : int
        Thin-structure width in full-resolution pixels: obstacle features at most this wide,
        against the sky, are L-band transparent and counted as sky (0 disables the policy).
    refine_band_px : int
        Half-width of the band around the boundary re-decided at full resolution by a colour
        GrabCut (0 disables the refinement).
    min_sky_lightness : float
        Darkest (OpenCV 8-bit Lab lightness, 0-255) non-blue region taken as a sky seed: a dark
        tunnel or wall filling the frame yields no seed, hence no sky.
    method : {"learned", "ensemble", "cnn", "grabcut"}
        ``"ensemble"`` (default, chosen by measurement, see ``docs/segmentation.md``): the
        mean of both probabilities below (the safest masks, the best on real photos);
        ``"learned"``: the per-pixel classifier of :mod:`predisat.sky.perceptron`; ``"cnn"``: the
        network of :mod:`predisat.sky.network`; ``"grabcut"``: the classical seeds + GrabCut
        method. The GrabCut parameters above apply to ``"grabcut"`` only (``thin_px``,
        ``circle_*``, ``fisheye`` to all); the "Learned method" ones below to the three
        learned methods.
    refine_guided : bool
        Learned method: sharpen the upsampled probability on the image edges (guided filter).
    min_island_fraction : float
        Learned method: a sky region that does not touch the top of an upright frame is kept
        only if it covers this share of the valid area (sky under a bridge deck); in a fisheye
        photo every sky region is kept (sky gaps in foliage).
    min_sky_fraction : float
        Learned method, upright frames: sky specks touching the top smaller than this share of
        the valid area are dropped (noise on a dark tunnel wall).
    max_hole_fraction : float
        Learned method: obstacle specks enclosed by sky and smaller than this share of the
        valid area are classifier noise and become sky.
    line_contrast : float
        Narrow obstacles lost to the working resolution (:mod:`predisat.sky.lines`): least
        depth, Lab lightness (0-255), of a dark line feature inside the classified sky that is
        turned back into an obstacle before the thin-structure policy (0 disables the step).
    line_min_elongation : float
        Least length-to-width ratio of such a feature.
    grey_chroma, grey_sky_probability : float
        Learned method: a pixel whose Lab chroma is below ``grey_chroma`` (white, grey: cloud,
        or a pale facade, a concrete pier, a grey mast) is sky only where the classifier's
        probability reaches ``grey_sky_probability`` instead of 0.5: on scenery it was not
        trained on, the classifier scores pale surfaces 0.5-0.8 and open sky near 1
        (docs/segmentation.md, "Grey pixels need a surer classifier"). A
        ``grey_sky_probability`` of 0.5 turns the rule off.
    uncertain_hole_fraction, uncertain_hole_probability : float
        Learned method: obstacle regions enclosed by sky (touching no frame edge; in a fisheye
        photo any region), smaller than this share of the valid area, whose mean sky
        probability is at least ``uncertain_hole_probability``, become sky (dark cloud
        bases). A region cut by the frame edge stays an obstacle: it may be a mast, a wall or
        the opposite rock face whose rest is out of the picture.
    """

    fisheye: bool = False
    circle_px: tuple[float, float, float] | None = None
    circle_margin: float = 0.04
    work_size_px: int = 400
    texture_quantile: float = 0.4
    texture_min: float = 4.0
    texture_max: float = 20.0
    texture_weight: float = 25.0
    grabcut_iterations: int = 3
    min_seed_fraction: float = 0.01
    detect_gaps: bool | None = None
    gap_max_mahalanobis: float = 2.5
    gap_min_tophat: float = 20.0
    thin_px: int = 3
    refine_band_px: int = 6
    min_sky_lightness: float = 100.0
    method: str = "ensemble"
    refine_guided: bool = True
    min_island_fraction: float = 0.01
    min_sky_fraction: float = 0.002
    max_hole_fraction: float = 0.0005
    uncertain_hole_fraction: float = 0.05
    uncertain_hole_probability: float = 0.25
    line_contrast: float = 25.0
    line_min_elongation: float = 5.0
    grey_chroma: float = 8.0
    grey_sky_probability: float = 0.7

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        fractions = (self.min_island_fraction, self.min_sky_fraction, self.max_hole_fraction,
                     self.uncertain_hole_fraction, self.uncertain_hole_probability)
        if not all(0.0 <= f <= 1.0 for f in fractions):
            raise ValueError(
                "min_island_fraction, min_sky_fraction, max_hole_fraction, "
                "uncertain_hole_fraction and uncertain_hole_probability must lie in [0, 1]"
            )
        if not (0.5 <= self.grey_sky_probability <= 1.0 and self.grey_chroma >= 0.0):
            raise ValueError(
                "grey_sky_probability must lie in [0.5, 1] (0.5: no rule) and grey_chroma be "
                f">= 0 Lab units, got {self.grey_sky_probability}, {self.grey_chroma}"
            )
        if self.work_size_px < 32:
            raise ValueError(f"work_size_px must be >= 32, got {self.work_size_px}")
        if not 0.0 < self.texture_quantile < 1.0:
            raise ValueError(f"texture_quantile must lie in (0, 1), got {self.texture_quantile}")
        if not 0.0 < self.texture_min <= self.texture_max:
            raise ValueError("need 0 < texture_min <= texture_max")
        if self.grabcut_iterations < 1:
            raise ValueError(f"grabcut_iterations must be >= 1, got {self.grabcut_iterations}")
        if self.line_contrast < 0 or self.line_min_elongation < 1:
            raise ValueError(
                "line_contrast must be >= 0 (0 disables the step) and line_min_elongation "
                f">= 1, got {self.line_contrast} and {self.line_min_elongation}"
            )
        if self.thin_px < 0:
            raise ValueError(f"thin_px must be >= 0 (0 disables the policy), got {self.thin_px}")
        if not 0.0 <= self.circle_margin < 1.0:
            raise ValueError(f"circle_margin must lie in [0, 1), got {self.circle_margin}")
        if self.circle_px is not None and (len(self.circle_px) != 3 or self.circle_px[2] <= 0):
            raise ValueError("circle_px must be (cx, cy, radius) with radius > 0")

    @property
    def gaps(self) -> bool:
        """Whether sky gaps are searched (``detect_gaps`` resolved against ``fisheye``)."""
        return self.fisheye if self.detect_gaps is None else bool(self.detect_gaps)
