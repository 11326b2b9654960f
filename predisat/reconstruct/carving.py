"""Full 360 deg masks from side-camera frames by free-space carving (issue 3, item 4).

Method (``docs/reconstruction.md``):

1. each frame's sky mask becomes a :class:`~predisat.reconstruct.skyline.SkyProfile` (lowest
   elevation of
   the top sky run per relative azimuth);
2. the profiles carve a conservative 2.5-D corridor
   :class:`~predisat.reconstruct.heightfield.HeightField`
   (upper bound of obstacle height per cell, ``+inf`` where unknown), and a clearance prior fills
   the space between the cameras unless an overhead structure is detected;
3. from each antenna position the height field is ray cast in every azimuth bin (horizon: the
   steepest cell top along the ray, using each cell's nearest point, so the result is never
   below what the bounds allow); where a ray leaves the modelled corridor, the far field is
   bounded by what the position's own cameras saw as sky in that direction (with an azimuth
   allowance for the camera-antenna parallax), or by a stated default where they saw nothing;
4. each bin gets a source flag: ASSUMED when the value rests on an unknown cell or on the
   far-field default (no camera at the position saw that azimuth's far field, e.g. straight
   along the track), else OBSERVED when the direction at the mask elevation lies in the view of
   a camera at the position, else RECONSTRUCTED.

The pipeline runs :meth:`Reconstructor.run` on chainage windows; a position's result depends on
the frames within :attr:`ReconstructionParams.overlap_m` of it only, so a window needs the frames
of its positions' range extended by ``overlap_m`` on both sides.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import IntEnum

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from predisat.camera.models import CameraModel, Mount, vehicle_to_enu
from predisat.gnss.fresnel import L1_WAVELENGTH_M, TRANSPARENT_FRACTION
from predisat.jsontypes import JsonDict
from predisat.masks.maskset import BinSource, MaskSet
from predisat.reconstruct.heightfield import (
    HeightField,
    LowestBounds,
    ThinRule,
    UnseenRule,
    apply_clearance_prior,
    carve_box,
    carve_profile,
    contradicted_raise,
    corridor_grid,
    sweep_along_track,
)
from predisat.reconstruct.skyline import (
    LOW_CONFIDENCE_WINDOW_DEG,
    Rectifier,
    SkyProfile,
    erode_sky_deg,
)
from predisat.track import TrackMap

__all__ = [
    "BinPart",
    "FrameView",
    "Reconstruction",
    "ReconstructionParams",
    "ReconstructionTrace",
    "Reconstructor",
    "bin_support",
    "cell_sweep_of",
    "close_covered",
    "far_elevation_bound",
    "lacking_side",
    "lacking_side_overhead",
    "reconstruct_masks",
    "side_cameras",
    "suspect_frames",
]


_DESCRIPTOR_TOL_DEG = 3.0
_WINDOW_MARGIN_M = 5.0  # corridor beyond the rays' reach, so that the prior's bins are whole
# The cameras' ceiling caps the clearance cells this near an antenna at their exact bound;
# farther, the rasterised bound is within a few tenths of a degree of it anyway.
_CEILING_CAP_M = 5.0
# A camera's view along the track bounds what spans it only if seen up to this near the zenith
# (the default rectification grid's top row is at 89.94 deg).
_ZENITH_SEEN_DEG = 1.0


@dataclass(frozen=True)
class ReconstructionParams:
    """Settings of the reconstruction (metres and degrees).

    Attributes
    ----------
    cell_m : float
        Height-field cell size. Near obstacles are over-estimated by up to about one cell in
        distance (0.5 m at 10 m: ~1 deg on a tall wall).
    half_width_m : float
        Modelled corridor half-width either side of the axis; beyond it the far-field rule
        applies.
    reach_m : float
        How far antenna rays are followed in the height field.
    carve_range_m : float
        Horizontal range from a camera within which its sky rays carve cells.
    clearance_half_width_m : float
        Half-width of the free space above the track between the cameras (structure gauge),
        free unless an overhead structure is detected.
    clearance_floor_m : float
        Height above the rail assumed for the clearance cells (platforms are lower).
    overhead_band_m : (float, float)
        Lateral band (both sides) examined for structures spanning the track.
    overhead_height_m : float
        Bands on both sides entirely bounded above this height above the rail mean a deck or a
        tunnel.
    zenith_el_deg, zenith_rel_az_deg : float
        A camera whose sky run starts above ``zenith_el_deg`` over at least half of the
        relative azimuths within ``zenith_rel_az_deg`` of its look direction has something
        wide over it (crown, canopy): the clearance is blocked within ``zenith_spread_m`` of
        that frame.
    zenith_spread_m : float
    overhead_along_el_deg : float or None
        A camera whose top sky run starts above this elevation over at least half of the
        azimuths within ``overhead_along_half_deg`` of straight along the track (ahead or
        behind) sees something over the track line close by (a catenary cantilever or
        registration arm, a gantry, a crown): the clearance is blocked within
        ``overhead_along_spread_m`` of that frame, and towards the obstacle up to
        ``overhead_along_height_m / tan(e)`` beyond (``e`` the lowest elevation of the
        obstacle's top there): a structure over the track seen at ``e`` stands that far away
        if its top is ``overhead_along_height_m`` above the camera. ``None`` disables it.
    overhead_along_half_deg, overhead_along_spread_m : float
    overhead_along_height_m : float
        The tallest structure over the track, above the cameras, that the rule above locates
        (a signal gantry's girder between two frames, ``docs/reconstruction.md`` section 10).
    clearance_unseen_deg : float or None
        Widest feature over the track a frame's sky may hide without a thin mask saying so (a
        cantilever about a pixel wide: the pipeline's thin-structure policy, 0.7 deg): a frame
        bounds a clearance cell only where such a feature would be transparent
        (``docs/reconstruction.md`` section 11). ``None`` disables it.
    along_view_half_deg : float or None
        Half-width of the azimuth window straight along the track in which a position's left
        and right cameras bound what may span the track (``docs/reconstruction.md``, section 2:
        a street between facades, a slot between rock walls); ``None`` disables it.
    antenna_height_m : float
        Antenna above the rail at the mask positions.
    az_step_deg : float
        Mask bin width.
    n_sub : int
        Rays per bin (bin edges shared with the neighbours).
    far_default_deg : float
        Far-field elevation assumed in directions no camera at the position saw (ASSUMED).
    position_tol_m : float
        Frames within this chainage distance of a position are "at" the position.
    min_confidence : float
        Image columns with a lower segmentation confidence have their skyline raised (their
        sky above still clears).
    min_sky_el_deg : float or None
        A frame's image column whose sky reaches below this elevation is voided (clears
        nothing): no sky lies under the horizon (its dip is 0.2 deg from 30 m up; the
        rectified elevations ignore the track's grade, a degree or two, and the cant of a
        curve, up to 6.9 deg for 180 mm), so the segmentation there took an obstacle down to
        its foot for sky (section 15 of docs/reconstruction.md). None turns the check off.
    covered_share : float
        A position whose mask reaches the zenith (90 deg) in at least this share of its
        azimuth bins is under a structure (a deck, a canopy): the zenith lies in every azimuth,
        so every bin becomes 90 deg, source ``RECONSTRUCTED`` (section 15 of
        docs/reconstruction.md). Above 1 turns the rule off.
    low_confidence_windows : float
        By how many confidence windows (the rows either side of a skyline its confidence
        speaks for); ``inf``: such columns clear nothing.
    low_confidence_window_deg : float
        A confidence window of a panoramic (``"equirect"``) camera, degrees of elevation
        (:data:`~predisat.reconstruct.skyline.LOW_CONFIDENCE_WINDOW_DEG`: the side fisheye's
        window of rows as an angle); frame cameras keep windows of their own rows.
    panorama_raise : {"image", "grid"}
        Where a panorama's low-confidence raise is taken
        (:meth:`~predisat.reconstruct.skyline.Rectifier.profile`): ``"image"`` (default, down
        its image columns; on a canted vehicle a wire near the zenith voids whole frames) or
        ``"grid"`` (per level azimuth, opt-in: recovers much of the panorama's sky but lets a
        camera behind the antenna see past a cantilever over it; docs/rigs.md).
    rectify_az_step_deg, rectify_el_step_deg : float
        Sky-profile sampling.
    descriptor_min_el_deg : float
        A side whose perpendicular horizon is lower has no obstacle descriptor.
    descriptor_gauge_m : float
        Cells nearer the antenna than this, metres, set no side descriptor: the clearance
        where no fixed structure above platform height stands (masts 2.5-3.5 m from the axis),
        and the antenna's own cell, whose height bound a few centimetres over the antenna read
        as an obstacle at 0 m (a user trial: 21 of 32 side descriptors of the quick demo,
        4.0-4.9 m high). On that demo the distances' median error against the truth went from
        -3.8 / -5.7 m (left / right) to +0.3 / -2.3 m, phantom obstacles from 11 to 5 of 32.
    carve_past_deg : float or None
        A side camera's rays carve this far past its half-space too (relative azimuths up to
        ``90 + carve_past_deg`` from its look direction), in columns it sees from the zenith
        down, and outside the clearance only (``docs/reconstruction.md``, section 17). None:
        the half-space only, as before 2026-12-05.
    fusion_rank : int
        Independent views (frames, or groups of frames sharing a ``FrameView.view_group``)
        that must agree before a cell is lowered: a cell keeps the ``min(fusion_rank, n)``-th
        lowest bound of the ``n`` views that bounded it (``docs/reconstruction.md``, fault
        model). 1: the lowest bound (the carving before issue 30, bit for bit).
    consistency_rank : int or None
        The consistency check between views at ``fusion_rank = 1`` (``docs/reconstruction.md``,
        section 6, clause 6): a view's obstacle ray (just under its skyline, above
        ``CHECK_MIN_EL_DEG``, within ``CHECK_MAX_REL_AZ_DEG`` of its look direction) that
        passes over every cell of the fused field is contradicted by the cells it crossed;
        each is raised to the ray, at most to its ``consistency_rank``-th lowest bound.
        ``None``: no check (the default).
    suspect_share : float or None
        A frame whose skyline lies more than ``suspect_tol_deg`` below both neighbouring frames
        of its camera (within ``suspect_neighbour_m``) over at least this share of the azimuths
        all three saw is a *suspect frame*: reported with the reason and left out of the
        reconstruction (leaving a frame out only removes sky evidence). ``None``: no check.
    suspect_tol_deg, suspect_neighbour_m : float
    antenna_clearance_m : float
        Least distance of any structure from the antenna's path (a contact wire over a roof
        antenna; a stated assumption): the thin-structure rule (``docs/reconstruction.md``,
        section 8) takes a thin feature's Fresnel zone at least this large.
    thin_wavelength_m : float
        Wavelength of the thin-structure rule: the shortest the receiver tracks (L1, the
        safe side).
    resolve_width_m : float or None
        Narrowest upright obstacle the carving must not lose (a catenary mast, a signal post):
        a frame farther from a cell than this width over the frame's unseen angle (the wider of
        ``clearance_unseen_deg`` and its thin features: what its segmentation may drop) cannot
        see such an obstacle there, so where any nearer frame bounds the cell, the cell keeps
        the lowest of the nearer frames' bounds only (``docs/reconstruction.md``, section 14).
        ``None``: every frame within ``carve_range_m`` lowers every cell. It applies at
        ``fusion_rank = 1`` (the default); at higher ranks the k-th lowest bound already needs
        k views to agree, and the rule is not applied. A frame without an unseen angle
        (``clearance_unseen_deg`` None and no thin features) resolves to ``carve_range_m``.
    resolve_positions : tuple of str
        The camera positions (``Mount.side``) whose far frames the rule above leaves out: the
        cameras that look along the track (cab and roof), whose far frames see the masts beside
        the track a pixel wide. Side cameras see them across, near, and the rule applied to
        them cost 2-4 points of sky for no false trust measured (section 14).
    cell_sweep_m : float or None
        Half-length along the track over which each position's mask bounds the sky
        (``docs/reconstruction.md``, section 12): with it a mask cell holds the worst over
        its length, not its centre, since the train may stand anywhere in it. ``None``: half
        the largest gap between consecutive positions of the window (5 m for positions every
        10 m; 0 for a single position). Default ``0``: the mask at the position itself; the
        sweep is opt-in because it doubles the sky lost at the positions (section 12).
    chainage_shift_m : float
        How far all the frames of a window may be off along the track together (the survey's
        chainage error common to them), metres (``docs/reconstruction.md``, section 18). The
        frames' own doubts (``FrameView.along_doubt_m``) hold what they may be off from each
        other; this shift moves the whole carved world, so each mask takes the sky from
        anywhere within it: the height field is swept by it (as ``cell_sweep_m``, the two
        adding), the overhead intervals and the cameras' along-track ceilings reach that much
        further, and the far field's parallax allowance takes it in. Default 0.
    """

    cell_m: float = 0.5
    half_width_m: float = 40.0
    reach_m: float = 250.0
    carve_range_m: float = 60.0
    clearance_half_width_m: float = 2.0
    clearance_floor_m: float = 1.0
    overhead_band_m: tuple[float, float] = (3.0, 9.0)
    overhead_height_m: float = 6.0
    zenith_el_deg: float = 75.0
    zenith_rel_az_deg: float = 30.0
    zenith_spread_m: float = 7.0
    overhead_along_el_deg: float | None = 45.0
    overhead_along_half_deg: float = 5.0
    overhead_along_spread_m: float = 1.5
    overhead_along_height_m: float = 8.0
    along_view_half_deg: float | None = 1.0
    clearance_unseen_deg: float | None = 0.7
    antenna_height_m: float = 4.0
    az_step_deg: float = 0.5
    n_sub: int = 4
    far_default_deg: float = 5.0
    position_tol_m: float = 5.0
    min_confidence: float = 0.5
    min_sky_el_deg: float | None = -8.0
    covered_share: float = 0.9
    low_confidence_windows: float = 2.0
    low_confidence_window_deg: float = LOW_CONFIDENCE_WINDOW_DEG
    panorama_raise: str = "image"
    rectify_az_step_deg: float = 0.25
    rectify_el_step_deg: float = 0.125
    descriptor_min_el_deg: float = 10.0
    descriptor_gauge_m: float = 2.5
    fusion_rank: int = 1
    consistency_rank: int | None = None
    carve_past_deg: float | None = 20.0
    suspect_share: float | None = None
    suspect_tol_deg: float = 5.0
    suspect_neighbour_m: float = 25.0
    antenna_clearance_m: float = 0.5
    thin_wavelength_m: float = L1_WAVELENGTH_M
    resolve_width_m: float | None = 0.25
    resolve_positions: tuple[str, ...] = ("front", "rear", "roof")
    cell_sweep_m: float | None = 0.0
    chainage_shift_m: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.chainage_shift_m) and self.chainage_shift_m >= 0):
            raise ValueError(
                "ReconstructionParams.chainage_shift_m must be a finite length >= 0 metres, got "
                f"{self.chainage_shift_m}"
            )
        if not self.covered_share > 0:
            raise ValueError(
                "ReconstructionParams.covered_share must be a share > 0 of the azimuth bins (0.9; "
                f"above 1 turns the covered-position rule off), got {self.covered_share}"
            )
        if self.min_sky_el_deg is not None and not math.isfinite(self.min_sky_el_deg):
            raise ValueError(
                "ReconstructionParams.min_sky_el_deg must be a finite elevation in degrees (-8) "
                f"or None (no check), got {self.min_sky_el_deg}"
            )
        if self.resolve_width_m is not None and not (
            math.isfinite(self.resolve_width_m) and self.resolve_width_m > 0
        ):
            raise ValueError(
                "ReconstructionParams.resolve_width_m must be a finite width > 0 metres (the "
                "narrowest upright obstacle, e.g. 0.25 for a catenary mast), or None (no "
                f"resolution rule), got {self.resolve_width_m}"
            )
        if self.cell_sweep_m is not None and not (
            math.isfinite(self.cell_sweep_m) and self.cell_sweep_m >= 0
        ):
            raise ValueError(
                "ReconstructionParams.cell_sweep_m must be a finite length >= 0 metres (0: the "
                f"mask at the position only), or None (from the positions), got "
                f"{self.cell_sweep_m}"
            )
        if not (math.isfinite(self.overhead_along_height_m) and self.overhead_along_height_m >= 0):
            raise ValueError(
                "overhead_along_height_m must be a finite height >= 0 metres (the tallest "
                f"structure over the track the along-overhead rule locates), got "
                f"{self.overhead_along_height_m}"
            )
        if not (self.antenna_clearance_m > 0 and self.thin_wavelength_m > 0):
            raise ValueError(
                "antenna_clearance_m and thin_wavelength_m must be > 0 metres, got "
                f"{self.antenna_clearance_m} and {self.thin_wavelength_m}"
            )
        n_az = round(360.0 / self.az_step_deg)
        if abs(n_az * self.az_step_deg - 360.0) > 1e-9:
            raise ValueError(f"az_step_deg = {self.az_step_deg} must divide 360")
        for name in ("cell_m", "half_width_m", "reach_m", "carve_range_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ReconstructionParams.{name} must be > 0")
        if self.n_sub < 1:
            raise ValueError("ReconstructionParams.n_sub must be >= 1")
        if not self.low_confidence_windows >= 0:
            raise ValueError(
                "ReconstructionParams.low_confidence_windows must be >= 0 (inf: low-confidence "
                "columns clear nothing)"
            )
        if self.panorama_raise not in ("image", "grid"):
            raise ValueError(
                "ReconstructionParams.panorama_raise must be 'image' (the default) or 'grid', got "
                f"{self.panorama_raise!r}"
            )
        if not self.low_confidence_window_deg > 0:
            raise ValueError(
                "ReconstructionParams.low_confidence_window_deg must be > 0 degrees, got "
                f"{self.low_confidence_window_deg}"
            )
        if self.carve_past_deg is not None and not 0.0 < self.carve_past_deg <= 60.0:
            raise ValueError(
                "ReconstructionParams.carve_past_deg must be in (0, 60] degrees (20: the columns "
                f"a side fisheye sees past the zenith) or None, got {self.carve_past_deg}"
            )
        if self.fusion_rank < 1:
            raise ValueError(
                "ReconstructionParams.fusion_rank must be >= 1 (1: the lowest bound over the "
                f"frames, 2: no single view can lower a cell), got {self.fusion_rank}"
            )
        if self.consistency_rank is not None and (
            self.consistency_rank < 2 or self.fusion_rank != 1
        ):
            raise ValueError(
                "ReconstructionParams.consistency_rank must be >= 2 (the order statistic a "
                "contradicted cell is raised to at most), and applies at fusion_rank = 1 only; "
                f"got {self.consistency_rank} at fusion_rank {self.fusion_rank}"
            )
        if self.suspect_share is not None and not 0.0 < self.suspect_share <= 1.0:
            raise ValueError(
                "ReconstructionParams.suspect_share must lie in (0, 1], or be None to disable "
                f"the suspect-frame check, got {self.suspect_share}"
            )
        if not (self.suspect_tol_deg > 0 and self.suspect_neighbour_m > 0):
            raise ValueError(
                "ReconstructionParams.suspect_tol_deg and suspect_neighbour_m must be > 0"
            )
        if self.along_view_half_deg is not None and not 0.0 < self.along_view_half_deg <= 45.0:
            raise ValueError(
                "ReconstructionParams.along_view_half_deg must lie in (0, 45] degrees, or be "
                "None to disable the cameras' ceiling over the track"
            )

    @property
    def overlap_m(self) -> float:
        """Chainage margin of frames (and corridor) needed beyond a window's positions (with
        the suspect-frame check, the frames used plus their neighbours)."""
        return self.used_m + (0.0 if self.suspect_share is None else self.suspect_neighbour_m)

    @property
    def used_m(self) -> float:
        """Chainage margin of the frames a window's reconstruction uses."""
        return self.reach_m + self.carve_range_m + _WINDOW_MARGIN_M

    @property
    def n_az(self) -> int:
        return round(360.0 / self.az_step_deg)


@dataclass(frozen=True, eq=False)
class FrameView:
    """One frame as the reconstruction needs it.

    Attributes
    ----------
    chainage_m : float
    sky_mask : ndarray of bool, shape ``camera.shape``
        True for sky and for thin L-band-transparent structure (wires).
    camera : CameraModel
    mount : Mount
    antenna_enu_m : ndarray, shape (3,)
        Antenna position at the frame in the track frame (``track.frame``) ENU.
    heading_deg : float
        Track heading at the frame.
    reverse : bool
        Train driving toward decreasing chainage.
    confidence : ndarray, shape (width_px,), optional
        Per-column segmentation confidence.
    frame_id : str
    view_group : str
        Frames with the same non-empty group count as one view in the fault-tolerant fusion
        (``ReconstructionParams.fusion_rank``): frames that may share a fault, such as one
        camera's frames of one pass (dirt on its lens). Empty: the frame is a view of its own.
    thin_mask : ndarray of bool, shape ``camera.shape``, optional
        Pixels that are sky in ``sky_mask`` only by the thin-structure policy (obstacle
        features at most ``thin_width_deg`` across). The reconstruction lets the sky seen
        through them prove free space only as far as the first Fresnel zone rule allows
        (``docs/reconstruction.md``, section 8); beyond, they are obstacles. None: no such
        pixel is known (every sky pixel is sky).
    thin_width_deg : float
        Widest feature ``thin_mask`` may hold, degrees (the policy's width in pixels times
        the camera's widest pixel).
    attitude_doubt_deg : float
        Angle by which the frame's pose may be off (``mount`` is the level-frame mount of the
        vehicle's nominal attitude, :mod:`predisat.reconstruct.attitude`): its sky is eroded
        by it before anything is cleared (``docs/reconstruction.md``, section 16).
    along_doubt_m, across_doubt_m, height_doubt_m : float
        How far the camera centre may be from where ``antenna_enu_m`` and ``mount`` put it,
        along the vehicle, across it and vertically (level frame), metres: the attitude's
        doubt moves the centre too, the body turning about the rails
        (:func:`~predisat.camera.models.tilt_doubt_m`). Every bound the frame sets holds from
        any centre that near (section 16).
    """

    chainage_m: float
    sky_mask: NDArray = field(repr=False)
    camera: CameraModel
    mount: Mount
    antenna_enu_m: NDArray
    heading_deg: float
    reverse: bool = False
    confidence: NDArray | None = field(default=None, repr=False)
    frame_id: str = ""
    view_group: str = ""
    thin_mask: NDArray | None = field(default=None, repr=False)
    thin_width_deg: float = 0.0
    attitude_doubt_deg: float = 0.0
    along_doubt_m: float = 0.0
    across_doubt_m: float = 0.0
    height_doubt_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("attitude_doubt_deg", "along_doubt_m", "across_doubt_m", "height_doubt_m"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"FrameView.{name} must be finite and >= 0, got {v}")

    @property
    def position_doubt_m(self) -> float:
        """How far the camera centre may be from its nominal one horizontally, metres."""
        return float(np.hypot(self.along_doubt_m, self.across_doubt_m))

    def doubt_box_m(self, local_to_frame: NDArray) -> tuple[float, float, float]:
        """The camera centre's doubt along the track frame's x, y and z, metres: the box of
        the vehicle frame's doubts turned into the frame (``local_to_frame``, (3, 3), the
        rotation from the local ENU at the frame into the track frame)."""
        if self.along_doubt_m == self.across_doubt_m == self.height_doubt_m == 0.0:
            return (0.0, 0.0, 0.0)
        to_frame = np.asarray(local_to_frame, float) @ vehicle_to_enu(self.heading_deg,
                                                                      self.reverse)
        box = np.abs(to_frame) @ np.array([self.along_doubt_m, self.across_doubt_m,
                                           self.height_doubt_m])  # fmt: skip
        return (float(box[0]), float(box[1]), float(box[2]))


class BinPart(IntEnum):
    """The part of the reconstruction that sets a bin's mask elevation
    (:attr:`ReconstructionTrace.part`; step 3 of the method, ``docs/reconstruction.md``)."""

    FAR_FIELD = 0
    """The far-field bound: the skyline of a camera at the position (with its parallax
    allowance), or ``far_default_deg`` where none saw the bin; also where it equals the height
    field's horizon, and where its cap lowered the far cells (``far_capped``)."""
    NEAR_GRID = 1
    """A height-field cell whose nearest point is nearer than ``half_width_m``."""
    FAR_GRID = 2
    """A height-field cell at least ``half_width_m`` away, not capped by the far field."""
    RESOLVED = 3
    """A far cell the mast rule resolved (``HeightField.resolved``), kept over the far field's
    cap."""
    COVERED = 4
    """Raised to 90 deg by the covered-position rule (:func:`close_covered`)."""


@dataclass(frozen=True, eq=False)
class ReconstructionTrace:
    """Where each bin of a :class:`Reconstruction` gets its value: the part of the
    reconstruction that sets it and, for a height-field part, the cell (``Reconstructor.run(...,
    trace=True)``). A diagnosis of the masks (``scripts/along_attribution.py``); the masks
    themselves do not depend on it.

    Attributes
    ----------
    part : ndarray of uint8, shape (n_pos, n_az)
        :class:`BinPart` codes. Of two parts giving the same value the first in the order
        far field, near grid, resolved, far grid is named.
    cell : ndarray of int64, shape (n_pos, n_az)
        For ``NEAR_GRID``, ``FAR_GRID`` and ``RESOLVED``, the flat index (``row * nx + col``)
        into ``height_field``'s raster of the cell whose ray sets the bin (of equal rays, the
        lowest index); -1 for the other parts and where no cell set the ray.
    unknown : ndarray of bool, shape (n_pos, n_az)
        The height-field part that sets the bin met an unknown cell (its value is 90 deg).
    far_seen : ndarray of bool, shape (n_pos, n_az)
        A camera at the position saw the bin's far field (else the bound is ``far_default_deg``).
    far_capped : ndarray of bool, shape (n_pos, n_az)
        The far field's cap lowered the bin's far cells (they stood higher than it).
    height_field : HeightField
        The field the rays were cast in (swept along the track when ``cell_sweep_m`` or
        ``chainage_shift_m`` asks for it); ``cell`` indexes its raster.
    antenna_m : ndarray, shape (n_pos, 3)
        The antennas the rays were cast from, in the track frame.
    local_to_frame : ndarray, shape (n_pos, 3, 3)
        Rotations from each antenna's local ENU into the track frame: the ray of azimuth
        ``az`` (from north) runs along ``local_to_frame[i] @ (sin az, cos az, 0)``.
    frames : tuple of FrameView
        The frames the reconstruction used (within ``used_m`` of the positions, after the
        suspect-frame check).
    profiles : tuple of SkyProfile
        Their sky profiles.
    overhead_rules : dict of str to ndarray, shape (k, 2)
        Chainage intervals, metres, whose clearance was taken as overhead, per rule:
        ``"zenith"`` and ``"along"`` (the frames' zenith and along-track rules),
        ``"lacking side"`` (:func:`lacking_side_overhead`) and ``"given"`` (the ``overhead_m``
        of :meth:`Reconstructor.run`). The tall bands the clearance prior finds itself are in
        ``height_field.overhead_m`` only, with all of these.
    """

    part: NDArray
    cell: NDArray
    unknown: NDArray
    far_seen: NDArray
    far_capped: NDArray
    height_field: HeightField
    antenna_m: NDArray
    local_to_frame: NDArray
    frames: tuple[FrameView, ...]
    profiles: tuple[SkyProfile, ...]
    overhead_rules: dict[str, NDArray]


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """Masks of one chainage window, ready for :class:`~predisat.masks.maskset.MaskSet`.

    Attributes
    ----------
    chainage_m : ndarray, shape (n_pos,)
    az_deg : ndarray, shape (n_az,)
        Bin centres.
    mask_el_deg : ndarray of float32, shape (n_pos, n_az)
        Final mask, degrees in [0, 90].
    source : ndarray of uint8, shape (n_pos, n_az)
        :class:`~predisat.masks.maskset.BinSource` codes.
    grid_el_deg : ndarray of float32, shape (n_pos, n_az)
        Horizon of the height field alone (before the far-field rule; may be negative).
    far_el_deg : ndarray of float32, shape (n_pos, n_az)
        Far-field bound used beyond the corridor.
    descriptors : dict of str to ndarray, shape (n_pos,)
        ``left/right_obstacle_distance_m`` and ``left/right_obstacle_height_m`` (NaN: none or
        unknown height).
    overhead_m : ndarray, shape (k, 2)
        Chainage intervals detected as overhead structures.
    params : ReconstructionParams
    suspect_frames : tuple of (str, str)
        Frames left out by the suspect-frame check: ``(frame_id, reason)``.
    support : ndarray of uint8, shape (n_pos, n_az), or None
        Independent views behind each bin's value (:func:`bin_support`; 0 for ASSUMED bins
        and bins set by a prior).
    trace : ReconstructionTrace or None
        Where each bin's value comes from (``Reconstructor.run(..., trace=True)``); None
        otherwise.
    """

    chainage_m: NDArray
    az_deg: NDArray
    mask_el_deg: NDArray
    source: NDArray
    grid_el_deg: NDArray
    far_el_deg: NDArray
    descriptors: dict[str, NDArray]
    overhead_m: NDArray
    params: ReconstructionParams
    suspect_frames: tuple[tuple[str, str], ...] = ()
    support: NDArray | None = None
    trace: ReconstructionTrace | None = None

    def to_maskset(
        self,
        track: TrackMap,
        *,
        margin_deg: ArrayLike = 0.0,
        provenance: JsonDict | None = None,
    ) -> MaskSet:
        """A :class:`~predisat.masks.maskset.MaskSet` of these masks along ``track``.

        ``margin_deg`` and ``provenance`` as in :meth:`MaskSet.from_arrays
        <predisat.masks.maskset.MaskSet.from_arrays>`; the reconstruction parameters are
        recorded in the provenance as ``reconstruction`` unless given.
        """
        prov = dict(provenance or {})
        prov.setdefault("reconstruction", _params_dict(self.params))
        return MaskSet.from_track(
            track,
            self.chainage_m,
            self.mask_el_deg,
            az_step_deg=self.params.az_step_deg,
            source=self.source,
            descriptors=self.descriptors,
            provenance=prov,
            margin_deg=margin_deg,
            support=self.support,
        )


def _params_dict(p: ReconstructionParams) -> JsonDict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in p.__dict__.items()}


class Reconstructor:
    """Runs the reconstruction on chainage windows, keeping the per-camera rectifiers.

    Parameters
    ----------
    params : ReconstructionParams, optional
    """

    # a curve's frames need one per rounded attitude, and a side camera two (its half-space and
    # the wider grid it carves with, section 17): tens of MB each
    _MAX_RECTIFIERS = 48

    def __init__(self, params: ReconstructionParams | None = None) -> None:
        self.params = params or ReconstructionParams()
        self._rectifiers: OrderedDict[tuple[CameraModel, Mount, float | None], Rectifier] = (
            OrderedDict()
        )

    @property
    def _min_sky_el_deg(self) -> float:
        m = self.params.min_sky_el_deg
        return -np.inf if m is None else m

    def rectifier(
        self, camera: CameraModel, mount: Mount, span_deg: float | None = None
    ) -> Rectifier:
        """The (cached) :class:`~predisat.reconstruct.skyline.Rectifier` of a camera and mount
        (``span_deg``: of a grid that wide, :meth:`Rectifier.build`)."""
        key = (camera, mount, span_deg)
        if key in self._rectifiers:
            self._rectifiers.move_to_end(key)
        else:
            p = self.params
            self._rectifiers[key] = Rectifier.build(
                camera, mount, p.rectify_az_step_deg, p.rectify_el_step_deg, span_deg=span_deg
            )
            if len(self._rectifiers) > self._MAX_RECTIFIERS:
                self._rectifiers.popitem(last=False)  # frames come in chainage order
        return self._rectifiers[key]

    @staticmethod
    def _sure_sky(f: FrameView, sky: NDArray) -> NDArray:
        """``sky`` eroded by the frame's attitude doubt (section 16): sky only where every
        direction the pixel may truly have is sky."""
        if f.attitude_doubt_deg <= 0.0:
            return sky
        return erode_sky_deg(sky, f.camera, f.attitude_doubt_deg)

    def _profile(self, rect: Rectifier, f: FrameView, sky: NDArray) -> SkyProfile:
        """``rect``'s profile of ``sky`` (a mask of frame ``f``), eroded by its doubt."""
        p = self.params
        try:
            return rect.profile(
                self._sure_sky(f, sky), f.heading_deg, f.reverse, f.confidence,
                p.min_confidence, p.low_confidence_windows, p.low_confidence_window_deg,
                self._min_sky_el_deg, p.panorama_raise,
            )  # fmt: skip
        except ValueError as exc:
            raise ValueError(f"frame {f.frame_id or f.chainage_m}: {exc}") from None

    def profiles(self, frames: Sequence[FrameView]) -> list[SkyProfile]:
        """Sky profile of every frame."""
        return [self._profile(self.rectifier(f.camera, f.mount), f, f.sky_mask) for f in frames]

    def solid_profiles(
        self, frames: Sequence[FrameView], profiles: Sequence[SkyProfile]
    ) -> list[SkyProfile]:
        """Sky profile of every frame with its thin-structure pixels (``FrameView.thin_mask``)
        as obstacles: ``profiles[i]`` itself for a frame without any."""
        out = []
        for f, prof in zip(frames, profiles, strict=True):
            if f.thin_mask is None or not np.any(f.thin_mask):
                out.append(prof)
                continue
            solid = np.asarray(f.sky_mask, bool) & ~np.asarray(f.thin_mask, bool)
            out.append(self._profile(self.rectifier(f.camera, f.mount), f, solid))
        return out

    def past_profiles(
        self, frames: Sequence[FrameView]
    ) -> list[tuple[SkyProfile, SkyProfile] | None]:
        """Per frame of a side camera (``left``, ``right``; not a panorama), its profile and
        solid profile (:meth:`solid_profiles`) over ``180 + 2 carve_past_deg`` degrees of
        relative azimuth, for the carving only; None for the other frames, and for all with
        ``carve_past_deg`` None.

        A side fisheye pitched 45 deg sees past the zenith, beyond its half-space. A column
        there clears what its sky rays pass over as any other does, but only where the camera
        sees it from the zenith down (the carving takes the sky above a column's top as going
        on); the other columns past the half-space are left unseen (``+inf``).
        """
        p = self.params
        if p.carve_past_deg is None:
            return [None] * len(frames)
        out: list[tuple[SkyProfile, SkyProfile] | None] = []
        for f in frames:
            if f.mount.side not in ("left", "right") or f.camera.model == "equirect":
                out.append(None)
                continue
            rect = self.rectifier(f.camera, f.mount, 180.0 + 2.0 * p.carve_past_deg)
            # past the half-space, a column counts only if seen from its top row (the zenith)
            blind = (np.abs(rect.rel_az_deg) > 90.0) & (rect.pixel_index[0] < 0)
            pair: list[SkyProfile] = []
            for sky in (f.sky_mask, None if f.thin_mask is None or not np.any(f.thin_mask)
                        else np.asarray(f.sky_mask, bool) & ~np.asarray(f.thin_mask, bool)):
                if sky is None:
                    pair.append(pair[0])
                    continue
                prof = self._profile(rect, f, sky)
                pair.append(replace(prof, sky_el_deg=np.where(blind, np.inf, prof.sky_el_deg)))
            out.append((pair[0], pair[1]))
        return out

    def height_field(
        self,
        frames: Sequence[FrameView],
        track: TrackMap,
        lo_m: float,
        hi_m: float,
        profiles: Sequence[SkyProfile] | None = None,
        overhead_m: Sequence[tuple[float, float]] = (),
    ) -> HeightField:
        """Carve the corridor ``[lo_m, hi_m]`` with ``frames``; ``overhead_m``: chainage
        intervals whose clearance is taken as overhead besides those the frames show."""
        p = self.params
        hf = corridor_grid(track, lo_m, hi_m, p.half_width_m, p.cell_m)
        profs = list(profiles) if profiles is not None else self.profiles(frames)
        solids = self.solid_profiles(frames, profs)
        bound = hf.bound_m.copy()
        views = np.zeros(hf.shape, np.int32)
        resolved = None
        if frames:
            carver = self._carver(hf, frames, track, profs, solids)
            cams, rots = carver.cams, carver.rots
            if p.consistency_rank is not None:  # rank 1, then the consistency check
                fusion = _view_fusion(hf, frames, cams, p, carver, p.consistency_rank)
                bound = np.minimum(hf.bound_m, fusion.lowest(1))
                views = fusion.views
                if p.resolve_width_m is not None:
                    bound, views, resolved = _resolving_bounds(
                        hf, bound, views, frames, cams, p, carver
                    )
                cap = np.minimum(hf.bound_m, fusion.lowest(p.consistency_rank))
                bound = _consistent_bounds(hf, bound, np.maximum(cap, bound), profs, cams,
                                           rots, p)  # fmt: skip
            elif p.fusion_rank == 1:  # the lowest bound: every frame lowers the cells in place
                seen = np.zeros(hf.shape, np.bool_)
                for idx in _view_groups(frames).values():
                    for i in idx:
                        carver.carve(i, bound, p.carve_range_m, seen)
                    # a view counts once per cell, whatever its frames (within their boxes)
                    b = np.array([carve_box(hf, cams[i], p.carve_range_m) for i in idx])
                    box = (slice(int(b[:, 0].min()), int(b[:, 1].max())),
                           slice(int(b[:, 2].min()), int(b[:, 3].max())))  # fmt: skip
                    views[box] += seen[box]
                    seen[box] = False
                if p.resolve_width_m is not None:
                    bound, views, resolved = _resolving_bounds(
                        hf, bound, views, frames, cams, p, carver
                    )
            else:
                bound, views = _fused_bounds(hf, frames, cams, p, carver)
        frame_over = _frame_overhead(frames, profs, p)
        over = (
            frame_over["zenith"]
            + frame_over["along"]
            + [(float(a), float(b)) for a, b in overhead_m]
        )
        ceilings = None
        if frames and p.along_view_half_deg is not None:
            # thin pixels as obstacles: a feature along the track may hang within its Fresnel
            # reach over the antenna, and the ceiling has no distance to tell (a review)
            ceilings = _camera_ceilings(frames, solids, cams, p.along_view_half_deg,
                                        p.chainage_shift_m)  # fmt: skip
        carved = bound.copy()
        overhead = apply_clearance_prior(
            hf, bound, p.clearance_half_width_m, p.clearance_floor_m,
            p.overhead_band_m, p.overhead_height_m, extra_overhead_m=np.array(over, float),
            camera_ceilings=ceilings,
        )  # fmt: skip
        # a bound the prior set rests on its rule, not on the views that carved the cell
        views[bound != carved] = 0
        if resolved is not None:  # a bound the prior set is no view's, resolved or not
            resolved = resolved & (bound == carved) & np.isfinite(bound)
        bound.setflags(write=False)
        views.setflags(write=False)
        return HeightField(
            hf.cell_m, hf.ix0, hf.iy0, bound, hf.region, hf.chainage_m, hf.offset_m,
            hf.rail_z_m, overhead, np.zeros((0, 4)) if ceilings is None else ceilings, views,
            resolved,
        )  # fmt: skip

    def _carver(
        self, hf: HeightField, frames: Sequence[FrameView], track: TrackMap,
        profs: Sequence[SkyProfile], solids: Sequence[SkyProfile],
    ) -> _FrameCarver:  # fmt: skip
        """The carving of each frame on ``hf``'s raster, as :meth:`height_field` carves."""
        p = self.params
        pasts = self.past_profiles(frames)
        cams, rots = _camera_geometry(frames, track)
        rules = _thin_rules(hf, frames, cams, p)
        unseen = _unseen_rules(frames, p)
        return _FrameCarver(hf, frames, profs, solids, pasts, cams, rots, rules, unseen,
                            p.clearance_half_width_m, track, p.carve_range_m)  # fmt: skip

    def frame_bounds(
        self,
        frames: Sequence[FrameView],
        track: TrackMap,
        field: HeightField,
        profiles: Sequence[SkyProfile] | None = None,
    ) -> list[NDArray]:
        """Each frame's carving alone on ``field``'s raster: per frame, float32 bounds of
        shape ``field.shape`` (``+inf`` where the frame bounds nothing), as :meth:`height_field`
        carves it (its profile and solid profile, a side camera's profile past its half-space,
        its thin-structure and unseen-arm rules, its position doubt; over ``carve_range_m``),
        before the frames are fused and before the clearance prior.

        ``field``: a height field of the corridor (:attr:`ReconstructionTrace.height_field`);
        only its raster's geometry is read. ``profiles``: the frames' sky profiles
        (:meth:`profiles`; :attr:`ReconstructionTrace.profiles`), computed if not given. A
        diagnosis (``scripts/trace_cells.py``: which frame bounds a cell how low). With
        ``fusion_rank`` 1 and no consistency check, the lowest of them is the field's bound of
        every cell a view bounds (``views > 0``) but those the mast rule raised
        (``HeightField.resolved``).
        """
        if not frames:
            return []
        profs = list(profiles) if profiles is not None else self.profiles(frames)
        carver = self._carver(field, frames, track, profs, self.solid_profiles(frames, profs))
        out = []
        for i in range(len(frames)):
            b = np.full(field.shape, np.inf, np.float32)
            carver.carve(i, b, self.params.carve_range_m)
            out.append(b)
        return out

    def run(
        self,
        frames: Sequence[FrameView],
        chainage_m: ArrayLike,
        track: TrackMap,
        overhead_m: Sequence[tuple[float, float]] = (),
        side_cameras: Sequence[str] = (),
        *,
        trace: bool = False,
    ) -> Reconstruction:
        """Masks at ``chainage_m`` (one window) from ``frames``.

        ``frames`` should hold every frame within :attr:`ReconstructionParams.overlap_m` of the
        positions; frames farther away are ignored. ``overhead_m``: chainage intervals (lo,
        hi), metres, where the clearance over the track is taken as overhead whatever the
        frames show. ``side_cameras``: the rig's cameras looking sideways (``mount.side``
        names): a position without a frame of one of them, among the frames used, has the
        clearance taken as overhead too (:func:`lacking_side_overhead`). ``trace``: also
        return where each bin's value comes from (:attr:`Reconstruction.trace`; the rays are
        cast once more for the cells, the masks are the same bit for bit).
        """
        p = self.params
        s = np.atleast_1d(np.asarray(chainage_m, float))
        if s.ndim != 1 or s.size == 0 or not np.all(np.isfinite(s)):
            raise ValueError("chainage_m must be a non-empty 1-D array of finite chainages")
        lo, hi = float(s.min()), float(s.max())
        keep = [f for f in frames if lo - p.overlap_m <= f.chainage_m <= hi + p.overlap_m]
        profs = self.profiles(keep)
        suspects: dict[int, str] = {}
        if p.suspect_share is not None:
            suspects = suspect_frames(keep, profs, p)
        # the frames used: within used_m; the check above also read their neighbours, so a
        # frame is judged the same in every window
        use = [
            i for i, f in enumerate(keep)
            if lo - p.used_m <= f.chainage_m <= hi + p.used_m and i not in suspects
        ]  # fmt: skip
        suspect_list = tuple(
            (keep[i].frame_id or f"{keep[i].chainage_m:.3f}", why)
            for i, why in sorted(suspects.items())
            if lo - p.used_m <= keep[i].chainage_m <= hi + p.used_m
        )
        keep = [keep[i] for i in use]
        profs = [profs[i] for i in use]
        given = [(float(a), float(b)) for a, b in overhead_m]
        lacking: list[tuple[float, float]] = []
        if side_cameras:  # after the suspect check: a frame it left out is missing too
            lacking = lacking_side_overhead(
                s, [[f.chainage_m for f in keep if f.mount.side == side] for side in side_cameras],
                p, max((f.along_doubt_m for f in keep), default=0.0),
            )  # fmt: skip
            overhead_m = [*overhead_m, *lacking]
        margin = p.reach_m + _WINDOW_MARGIN_M
        hf = self.height_field(keep, track, lo - margin, hi + margin, profs, overhead_m)
        res_hf = None
        if hf.resolved is not None and hf.resolved.any():
            # the height field with the resolved cells only (the others far under the rail);
            # a mast stands no higher than the tallest structure by the track the clearance
            # rules take (overhead_along_height_m above the cameras): a resolved cell counts up
            # to that height, not with the loose bounds of steep rays
            top = hf.rail_z_m + p.antenna_height_m + p.overhead_along_height_m
            low = np.where(hf.resolved, np.minimum(hf.bound_m, top), hf.rail_z_m - 1.0e3)
            low = low.astype(np.float32)
            res_hf = replace(hf, bound_m=low, views=None if hf.views is None else np.where(
                hf.resolved, hf.views, 0).astype(np.int32))  # fmt: skip
        ant, rot = _antennas(track, s, p.antenna_height_m)
        sweep_m = cell_sweep_of(s) if p.cell_sweep_m is None else p.cell_sweep_m
        sweep_m += p.chainage_shift_m  # the carved world may stand that far off (section 18)
        if sweep_m > 0:
            # the obstacles as seen from anywhere in the cell; the cameras' ceiling caps are
            # exact at the position only, so they are not applied to a swept cell
            hf = sweep_along_track(hf, track, sweep_m, p.clearance_half_width_m)
            if res_hf is not None:
                res_hf = sweep_along_track(res_hf, track, sweep_m, p.clearance_half_width_m)
            caps = None
        else:
            caps = _ceiling_caps(hf.camera_ceilings, s, ant)
        near_el, near_unknown, far_grid_el, far_unknown, near_sup, far_sup = _horizon_parts(
            hf, ant, rot, p, caps
        )
        # the far cells a frame near enough to see a mast bounded: the far field's cap below
        # does not lower them (a camera at the position, half_width_m away or more, sees such
        # a mast a pixel wide or less, and its sky over it proves nothing; a review: the 360
        # rig's roof panorama missed catenary masts 43-63 m ahead, 0.3-0.4 deg wide, and its
        # sky capped the masts' cells that the frames near them had kept)
        far_res = None
        if res_hf is not None:
            _, _, far_res_el, _, _, far_res_sup = _horizon_parts(res_hf, ant, rot, p, caps)
            far_res = (far_res_el, far_res_sup)
        # the far field has no distance: a thin feature seen there may be far, hence opaque
        far_el, far_seen, seen, far_views = _far_field(
            keep, self.solid_profiles(keep, profs), s, ant, track, p
        )
        # Cells at least half_width_m away, in a bin a camera at the position saw, are capped
        # by that camera's sky: it proves nothing farther stands higher (the parallax
        # allowance of the far field assumes that distance). Loosely carved far cells (a hill
        # over a tunnel, bounded only by steep rays) no longer close the sky it saw. At a
        # fusion rank r the cap needs r views too: one over-exposed frame capped cells nine
        # views had bounded, 8.6 deg under the truth at rank 2 (a review)
        far_grid = _bins(far_grid_el, p.n_sub)
        cap = _far_cap(far_seen, far_views, p.fusion_rank)
        capped = np.minimum(far_grid, far_el)
        if far_res is not None:
            capped = np.maximum(capped, _bins(far_res[0], p.n_sub))
        grid_bin = np.maximum(_bins(near_el, p.n_sub), np.where(cap, capped, far_grid))
        unknown_bin = (_bins(near_unknown.astype(float), p.n_sub) > 0) | (
            (_bins(far_unknown.astype(float), p.n_sub) > 0) & ~far_seen
        )
        mask = np.clip(np.maximum(grid_bin, far_el), 0.0, 90.0)
        observed = _observed(seen, mask, p)
        src = np.full(mask.shape, int(BinSource.RECONSTRUCTED), np.uint8)
        src[observed] = int(BinSource.OBSERVED)
        # the value rests on an unknown cell, or on the stated far-field default (no camera at
        # this position saw the far field in that azimuth)
        assumed = unknown_bin | ~far_seen
        src[assumed] = int(BinSource.ASSUMED)
        mask, src, closed = close_covered(mask, src, p.covered_share)
        assumed = assumed & ~closed
        support = bin_support(
            (near_el, near_sup),
            (far_grid_el, far_sup),
            far_el,
            far_seen,
            far_views,
            assumed,
            p.n_sub,
            p.fusion_rank,
            far_res,
        )
        desc = _descriptors(hf, track, s, ant, p)
        traced = None
        if trace:
            over = {k: np.asarray(v, float).reshape(-1, 2)
                    for k, v in _frame_overhead(keep, profs, p).items()}  # fmt: skip
            over["lacking side"] = np.asarray(lacking, float).reshape(-1, 2)
            over["given"] = np.asarray(given, float).reshape(-1, 2)
            traced = _trace(
                hf, res_hf, ant, rot, p, caps, (near_el, near_unknown), (far_grid_el, far_unknown),
                far_el, far_seen, cap, closed, keep, profs, over,
            )  # fmt: skip
        return Reconstruction(
            chainage_m=s,
            az_deg=np.arange(p.n_az) * p.az_step_deg,
            mask_el_deg=mask.astype(np.float32),
            source=src,
            grid_el_deg=grid_bin.astype(np.float32),
            far_el_deg=far_el.astype(np.float32),
            descriptors=desc,
            overhead_m=hf.overhead_m,
            params=p,
            suspect_frames=suspect_list,
            support=support,
            trace=traced,
        )


def _trace(
    hf: HeightField,
    res_hf: HeightField | None,
    ant: NDArray,
    rot: NDArray,
    p: ReconstructionParams,
    caps: NDArray | None,
    near: tuple[NDArray, NDArray],
    far_grid: tuple[NDArray, NDArray],
    far_el: NDArray,
    far_seen: NDArray,
    cap: NDArray,
    closed: NDArray,
    frames: Sequence[FrameView],
    profiles: Sequence[SkyProfile],
    overhead_rules: dict[str, NDArray],
) -> ReconstructionTrace:
    """The :class:`ReconstructionTrace` of :meth:`Reconstructor.run`'s parts: the bins' parts
    as the run combines them (``near``, ``far_grid``: per-ray elevation and unknown flag;
    ``cap``: :func:`_far_cap`; ``closed``: :func:`close_covered`'s), and the cells, from the
    rays cast once more with each cell's own index in place of its views."""
    index = np.arange(hf.bound_m.size, dtype=np.int32).reshape(hf.shape)
    near_cell, far_cell = _horizon_parts(replace(hf, views=index), ant, rot, p, caps)[4:]
    near_b, near_c = _bins_with_support(near[0], near_cell, p.n_sub)
    fg_b, fg_c = _bins_with_support(far_grid[0], far_cell, p.n_sub)
    lowered = np.minimum(fg_b, far_el)
    kept = np.zeros(far_el.shape, bool)
    fr_c = np.full(far_el.shape, -1, np.int64)
    if res_hf is not None:
        res_el, _, _, res_cell = _horizon_parts(replace(res_hf, views=index), ant, rot, p,
                                                caps)[2:]  # fmt: skip
        fr_b, fr_c = _bins_with_support(res_el, res_cell, p.n_sub)
        kept = cap & (fr_b > lowered)
        lowered = np.maximum(lowered, fr_b)
    with np.errstate(invalid="ignore"):
        far_capped = cap & (far_el < fg_b) & ~kept
    far_part = np.where(cap, lowered, fg_b)
    grid = np.maximum(near_b, far_part)
    part = np.select(
        [closed, far_el >= grid, near_b >= far_part, kept],
        [BinPart.COVERED, BinPart.FAR_FIELD, BinPart.NEAR_GRID, BinPart.RESOLVED],
        BinPart.FAR_GRID,
    ).astype(np.uint8)
    cell = np.select(
        [part == BinPart.NEAR_GRID, part == BinPart.FAR_GRID, part == BinPart.RESOLVED],
        [near_c, fg_c, fr_c], -1,
    ).astype(np.int64)  # fmt: skip
    near_unknown = _bins(near[1].astype(float), p.n_sub) > 0
    far_unknown = _bins(far_grid[1].astype(float), p.n_sub) > 0
    unknown = ((part == BinPart.NEAR_GRID) & near_unknown) | (
        (part == BinPart.FAR_GRID) & far_unknown
    )
    return ReconstructionTrace(
        part=part, cell=cell, unknown=unknown, far_seen=np.asarray(far_seen, bool),
        far_capped=np.asarray(far_capped, bool), height_field=hf, antenna_m=ant,
        local_to_frame=rot, frames=tuple(frames),
        profiles=tuple(profiles), overhead_rules=overhead_rules,
    )  # fmt: skip


def cell_sweep_of(chainage_m: ArrayLike) -> float:
    """Half the largest gap between consecutive positions, metres (0 for one position): the
    half-length along the track each mask cell must cover (:attr:`MaskSet.cell_bounds_m
    <predisat.masks.maskset.MaskSet.cell_bounds_m>` puts the cell edges midway)."""
    s = np.sort(np.atleast_1d(np.asarray(chainage_m, float)))
    return float(np.max(np.diff(s)) / 2.0) if s.size > 1 else 0.0


def reconstruct_masks(
    frames: Sequence[FrameView],
    chainage_m: ArrayLike,
    track: TrackMap,
    params: ReconstructionParams | None = None,
) -> Reconstruction:
    """Masks at ``chainage_m`` from ``frames`` (see :class:`Reconstructor`)."""
    return Reconstructor(params).run(frames, chainage_m, track)


# ---------------------------------------------------------------------- fault tolerance


class _FrameCarver:
    """Carves one frame into a raster: its profile (:func:`carve_profile`), then, for a side
    camera with a :meth:`Reconstructor.past_profiles` pair, the wider profile on the cells
    beyond the clearance on the camera's own side of the axis (``docs/reconstruction.md``,
    section 17)."""

    def __init__(
        self, hf: HeightField, frames: Sequence[FrameView], profs: Sequence[SkyProfile],
        solids: Sequence[SkyProfile], pasts: Sequence[tuple[SkyProfile, SkyProfile] | None],
        cams: NDArray, rots: NDArray, rules: Sequence[ThinRule | None],
        unseen: Sequence[UnseenRule | None], clearance_half_width_m: float,
        track: TrackMap, range_m: float,
    ) -> None:  # fmt: skip
        self.hf, self.frames, self.profs, self.solids, self.pasts = hf, frames, profs, solids, pasts
        self.cams, self.rots, self.rules, self.unseen = cams, rots, rules, unseen
        # per side of the axis (+1: left of increasing chainage), the cells beyond the clearance
        # and their distance from the axis
        self.beyond: dict[float, tuple[NDArray, NDArray]] = {}
        self.side = np.zeros(len(frames))
        self.reach_m = np.zeros(len(frames))
        if any(x is not None for x in pasts):
            off = np.nan_to_num(hf.offset_m, nan=0.0)
            for sign in (1.0, -1.0):
                near = sign * off
                self.beyond[sign] = (hf.region & (near >= clearance_half_width_m), near)
            # the camera's side of the axis and its distance from it, projected on the track,
            # not read from this chunk's raster (a camera outside it would get none, and the
            # carving would depend on the chunking)
            cam_off = np.asarray(track.project_enu(cams).offset_m, float)
            self.side = np.where(np.abs(cam_off) >= 0.5, np.sign(cam_off), 0.0)
            # How far out a cell may straddle the camera's line: a metre past it, plus the
            # track curving away from the straight line within the carving range (the
            # sharpest curvature there) and the camera's doubt.
            k = np.array([
                np.abs(np.asarray(track.curvature_at(np.clip(
                    f.chainage_m + np.arange(-range_m, range_m + 5.0, 5.0), 0.0, track.length_m
                )), float)).max()
                for f in frames
            ])  # fmt: skip
            bend = 0.5 * range_m**2 * k
            doubt = np.array([f.position_doubt_m for f in frames])
            self.reach_m = np.abs(cam_off) + 1.0 + bend + doubt

    def carve(self, i: int, raster: NDArray, range_m: float, seen: NDArray | None = None) -> None:
        doubt = self.frames[i].doubt_box_m(self.rots[i])
        carve_profile(self.hf, raster, self.profs[i], self.cams[i], self.rots[i], range_m,
                      seen=seen, solid=self.solids[i], thin_rule=self.rules[i],
                      unseen_rule=self.unseen[i], position_doubt_m=doubt)  # fmt: skip
        past = self.pasts[i]
        side = float(self.side[i])
        if past is None or side == 0.0:
            return
        # The camera's own side beyond the clearance, out to the cells that straddle its own
        # line, which its half-space cuts in two; farther out, and across the track, its
        # half-space or the other camera looks from in front.
        beyond, near = self.beyond[side]
        r0, r1, c0, c1 = carve_box(self.hf, self.cams[i], range_m)  # all carve_profile reads
        strip = np.zeros(beyond.shape, np.bool_)
        box = (slice(r0, r1), slice(c0, c1))
        strip[box] = beyond[box] & (near[box] < self.reach_m[i])
        carve_profile(replace(self.hf, region=strip), raster, past[0], self.cams[i],
                      self.rots[i], range_m, seen=seen, solid=past[1], thin_rule=self.rules[i],
                      unseen_rule=self.unseen[i], position_doubt_m=doubt)  # fmt: skip


def _fused_bounds(
    hf: HeightField,
    frames: Sequence[FrameView],
    cams: NDArray,
    p: ReconstructionParams,
    carver: _FrameCarver,
) -> tuple[NDArray, NDArray]:
    """Bounds fused over independent views (:class:`~predisat.reconstruct.heightfield.
    LowestBounds` with ``p.fusion_rank``): each view (a frame, or the frames of one
    ``view_group``) carves a scratch raster of its own, then counts once per cell. Returns the
    bounds and the number of views per cell."""
    fusion = _view_fusion(hf, frames, cams, p, carver, p.fusion_rank)
    return np.minimum(hf.bound_m, fusion.fused()), fusion.views


def _view_fusion(
    hf: HeightField,
    frames: Sequence[FrameView],
    cams: NDArray,
    p: ReconstructionParams,
    carver: _FrameCarver,
    rank: int,
) -> LowestBounds:
    """The ``rank`` lowest bounds of each cell over the views (:func:`_fused_bounds`)."""
    groups = _view_groups(frames)
    fusion = LowestBounds(hf.shape, rank)
    scratch = np.full(hf.shape, np.inf, np.float32)
    for idx in groups.values():
        boxes = []
        for i in idx:
            box = carve_box(hf, cams[i], p.carve_range_m)
            if box[1] > box[0] and box[3] > box[2]:
                carver.carve(i, scratch, p.carve_range_m)
                boxes.append(box)
        if not boxes:
            continue
        b = np.array(boxes)
        union = (int(b[:, 0].min()), int(b[:, 1].max()), int(b[:, 2].min()), int(b[:, 3].max()))
        fusion.add(scratch, union)
        scratch[union[0] : union[1], union[2] : union[3]] = np.inf
    return fusion


# the consistency check (ReconstructionParams.consistency_rank; docs/reconstruction.md, section 6)
CHECK_BELOW_DEG = 0.25  # an obstacle ray: this far under the skyline (two rectified rows)
# Lower skylines are the far field's (a horizon over open land, hills): a ray under them
# passes over the whole corridor whatever the views, and raised the open side's cells to the
# camera's height (the fusion tests' wall scene)
CHECK_MIN_EL_DEG = 5.0
CHECK_FROM_M = 3.0  # cells nearer the camera are loosely bounded by every view: passed over
# Rays looking farther along the track are not checked: they end on obstacles beyond the
# carving range, and raising the cells beside the track under them cost 8 points of sky on
# the fault-injection survey for almost no false trust (section 6)
CHECK_MAX_REL_AZ_DEG = 75.0


def _consistent_bounds(
    hf: HeightField,
    bound: NDArray,
    cap: NDArray,
    profs: Sequence[SkyProfile],
    cams: NDArray,
    rots: NDArray,
    p: ReconstructionParams,
) -> NDArray:
    """``bound`` raised where the views' obstacle rays contradict it, at most to ``cap``
    (:func:`~predisat.reconstruct.heightfield.contradicted_raise`). Only raises cells."""
    code = np.where(hf.region, 1, 0).astype(np.int8)
    with np.errstate(invalid="ignore"):
        code[hf.region & (np.abs(hf.offset_m) < p.clearance_half_width_m)] = 2
    low = np.ascontiguousarray(bound, np.float32)
    cap = np.ascontiguousarray(cap, np.float32)
    raised = np.full(hf.shape, -np.inf, np.float32)
    for prof, cam, rot in zip(profs, cams, rots, strict=True):
        contradicted_raise(
            low, cap, code, hf.ix0, hf.iy0, float(hf.cell_m), np.asarray(cam, float),
            np.ascontiguousarray(rot, float), float(prof.look_az_deg),
            np.asarray(prof.rel_az_deg, float), np.asarray(prof.sky_el_deg, float),
            CHECK_BELOW_DEG, CHECK_MIN_EL_DEG, CHECK_MAX_REL_AZ_DEG, CHECK_FROM_M,
            float(p.carve_range_m), 0.5 * float(hf.cell_m), raised,
        )  # fmt: skip
    return np.maximum(low, raised).astype(np.float32)


def _thin_rules(
    hf: HeightField, frames: Sequence[FrameView], cams: NDArray, p: ReconstructionParams
) -> list[ThinRule | None]:
    """The thin-structure rule of each frame (None: no thin mask): its widest thin feature,
    ``TRANSPARENT_FRACTION^2 * wavelength``, the antenna clearance and the camera's offset
    from the axis (its cell's, shrunk toward the axis by half a cell diagonal; 0 outside the
    corridor)."""
    row, col, ok = hf.index(cams[:, 0], cams[:, 1])
    out: list[ThinRule | None] = []
    k2 = TRANSPARENT_FRACTION**2 * p.thin_wavelength_m
    for i, f in enumerate(frames):
        if f.thin_mask is None or f.thin_width_deg <= 0.0:
            out.append(None)
            continue
        off = float(hf.offset_m[row[i], col[i]]) if ok[i] else float("nan")
        # a camera known within a doubt may stand that much nearer the axis
        near = abs(off) - 0.7072 * hf.cell_m - f.position_doubt_m
        shrunk = np.sign(off) * max(near, 0.0) if np.isfinite(off) else 0.0
        out.append(ThinRule(float(np.radians(f.thin_width_deg)), k2, p.antenna_clearance_m,
                            float(shrunk)))  # fmt: skip
    return out


def _resolve_range_m(frames: Sequence[FrameView], p: ReconstructionParams) -> NDArray:
    """Per frame, the distance within which it sees an upright obstacle ``p.resolve_width_m``
    wide: that width over its unseen angle (the wider of ``p.clearance_unseen_deg`` and its
    thin features), at most ``p.carve_range_m``."""
    assert p.resolve_width_m is not None
    base = 0.0 if p.clearance_unseen_deg is None else p.clearance_unseen_deg
    ang = np.radians([max(base, f.thin_width_deg) for f in frames])
    with np.errstate(divide="ignore"):
        return np.minimum(p.resolve_width_m / np.tan(ang), p.carve_range_m)


def _resolving_bounds(
    hf: HeightField, bound: NDArray, views: NDArray, frames: Sequence[FrameView],
    cams: NDArray, p: ReconstructionParams, carver: _FrameCarver,
) -> tuple[NDArray, NDArray, NDArray | None]:  # fmt: skip
    """``bound`` (every frame's lowest) without the bounds of far frames of the cameras in
    ``p.resolve_positions`` on the cells some frame near enough to see a mast bounds
    (``ReconstructionParams.resolve_width_m``), and ``views`` (the support count) where a cell
    was raised: the views whose frames still bound it, not the far frames left out; and the
    cells it raised (``HeightField.resolved``; None without a camera of
    ``p.resolve_positions``).

    A far frame's sky passes over a mast it cannot resolve (a pixel or less), and the plain
    carving keeps the lowest bound, so one far frame erases a mast every near frame sees. The
    bounds kept are among ``bound``'s, so this only raises cells.
    """
    subject = np.array([f.mount.side in p.resolve_positions for f in frames], bool)
    if not subject.any():
        return bound, views, None
    ranges = _resolve_range_m(frames, p)
    near = hf.bound_m.copy()
    scratch = hf.bound_m.copy()
    resolved = np.zeros(hf.shape, np.bool_)  # cells a frame within its range bounds
    near_views = np.zeros(hf.shape, np.int32)
    for idx in _view_groups(frames).values():
        group = np.zeros(hf.shape, np.bool_)  # a view counts once per cell, whatever its frames
        for i in idx:
            r_m = float(ranges[i])
            own = np.zeros(hf.shape, np.bool_)
            if subject[i]:  # within its range only, which marks the cells it resolves
                if r_m > 0:
                    carver.carve(i, near, r_m, own)
                resolved |= own
            else:
                carver.carve(i, near, p.carve_range_m, own)
                if r_m > 0:  # the cells it resolves
                    carver.carve(i, scratch, r_m, resolved)
            group |= own
        near_views += group
    raised = resolved & (near > bound)
    out = np.where(resolved, np.maximum(near, bound), bound).astype(bound.dtype)
    return out, np.where(raised, near_views, views).astype(views.dtype), raised


def _unseen_rules(frames: Sequence[FrameView], p: ReconstructionParams) -> list[UnseenRule | None]:
    """The unseen-arm rule of each frame (:class:`~predisat.reconstruct.heightfield.
    UnseenRule`): the wider of ``p.clearance_unseen_deg`` and the frame's thin features."""
    if p.clearance_unseen_deg is None:
        return [None] * len(frames)
    k2 = TRANSPARENT_FRACTION**2 * p.thin_wavelength_m
    return [
        UnseenRule(float(np.radians(max(p.clearance_unseen_deg, f.thin_width_deg))), k2,
                   p.antenna_clearance_m, p.clearance_half_width_m)
        for f in frames
    ]  # fmt: skip


def _view_groups(frames: Sequence[FrameView]) -> dict[str, list[int]]:
    """Indices of the frames of each independent view: a ``view_group``, or a frame alone."""
    groups: dict[str, list[int]] = {}
    for i, f in enumerate(frames):
        groups.setdefault(f.view_group or f"\0frame{i}", []).append(i)
    return groups


def suspect_frames(
    frames: Sequence[FrameView], profiles: Sequence[SkyProfile], p: ReconstructionParams
) -> dict[int, str]:
    """Frames whose sky contradicts both neighbouring frames of the same camera.

    For each frame with a frame of the same camera (side) before and after it within
    ``p.suspect_neighbour_m`` of chainage, compare the three sky profiles azimuth by
    azimuth (same relative azimuth: the neighbours look the same way): the frame contradicts
    its neighbours where it saw sky more than ``p.suspect_tol_deg`` below the lower of their
    skylines (or where they saw no sky at all). A frame contradicting them over at least
    ``p.suspect_share`` of the azimuths all three saw is suspect: over-exposure, flare, a
    drop or dirt on the lens, a wrong mask. Objects near the camera shift between frames
    10 m apart, which is why the share must be large; a fault shared by the neighbours (the
    same dirt on three frames) is not seen.

    Returns
    -------
    dict of int to str
        Index into ``frames`` -> reason (names the neighbours and the share).
    """
    share_min = 1.0 if p.suspect_share is None else p.suspect_share
    by_side: dict[str, list[int]] = {}
    for i, f in enumerate(frames):
        by_side.setdefault(f.mount.side, []).append(i)
    out: dict[int, str] = {}
    for idx in by_side.values():
        order = sorted(idx, key=lambda i: frames[i].chainage_m)
        for a, i, b in zip(order[:-2], order[1:-1], order[2:], strict=True):
            fi, fa, fb = frames[i], frames[a], frames[b]
            if (
                fi.chainage_m - fa.chainage_m > p.suspect_neighbour_m
                or fb.chainage_m - fi.chainage_m > p.suspect_neighbour_m
            ):
                continue
            pi, pa, pb = profiles[i], profiles[a], profiles[b]
            if not (pi.rel_az_deg.shape == pa.rel_az_deg.shape == pb.rel_az_deg.shape):
                continue  # another camera model: not comparable column by column
            seen = (
                np.isfinite(pi.seen_lo_deg) & np.isfinite(pa.seen_lo_deg)
                & np.isfinite(pb.seen_lo_deg)
            )  # fmt: skip
            n = int(seen.sum())
            if n == 0:
                continue
            with np.errstate(invalid="ignore"):
                top = np.minimum(pa.sky_el_deg, pb.sky_el_deg)  # +inf: neither saw sky
                low = np.isfinite(pi.sky_el_deg) & (pi.sky_el_deg < top - p.suspect_tol_deg)
            # a column voided for sky under the horizon (where its neighbours' are not) is a
            # contradiction too, not a column that saw no sky
            low |= _voided(pi) & ~_voided(pa) & ~_voided(pb)
            share = float((low & seen).sum()) / n
            if share >= share_min:
                out[i] = (
                    f"sky contradicts the neighbouring frames {fa.frame_id or fa.chainage_m} "
                    f"and {fb.frame_id or fb.chainage_m}: on {100 * share:.0f} % of the "
                    f"azimuths all three saw, its skyline is more than {p.suspect_tol_deg:g} "
                    "deg below both (over-exposure, flare, a drop or dirt on the lens, or a "
                    "wrong mask); left out of the reconstruction: check the image"
                )
    return out


def _voided(prof: SkyProfile) -> NDArray:
    return np.zeros(prof.rel_az_deg.shape, bool) if prof.voided is None else prof.voided


# ---------------------------------------------------------------------- geometry helpers


def close_covered(
    mask_el_deg: NDArray, source: NDArray, covered_share: float
) -> tuple[NDArray, NDArray, NDArray]:
    """Positions under a structure closed in every bin.

    Under a deck or canopy the zenith is closed, and the zenith lies in every azimuth: a mask
    holding the highest obstructed elevation is 90 deg in every bin there, also in the few
    (along the track, beyond the corridor) whose own cells no camera bounded.

    Parameters
    ----------
    mask_el_deg : ndarray, shape (n_pos, n_az)
    source : ndarray of uint8, shape (n_pos, n_az)
    covered_share : float
        A position with at least this share of its bins at 90 deg is under a structure.

    Returns
    -------
    mask_el_deg, source : ndarray
        New arrays; the bins raised take source ``RECONSTRUCTED``.
    raised : ndarray of bool, shape (n_pos, n_az)
        The bins raised to 90 deg.
    """
    mask = np.asarray(mask_el_deg, float)
    covered = np.mean(mask >= 90.0, axis=1) >= covered_share
    raised = covered[:, None] & (mask < 90.0)
    src = np.where(raised, np.uint8(BinSource.RECONSTRUCTED), source).astype(np.uint8)
    return np.where(covered[:, None], 90.0, mask), src, raised


def _frame_overhead(
    frames: Sequence[FrameView], profs: Sequence[SkyProfile], p: ReconstructionParams
) -> dict[str, list[tuple[float, float]]]:
    """Chainage intervals whose clearance the frames' own rules take as overhead: ``zenith``
    (within ``zenith_spread_m`` of a frame that saw something wide over it,
    :func:`_zenith_blocked`, widened by its along-track doubt and the chainage shift) and
    ``along`` (:func:`_along_overhead`)."""
    zenith = [
        (f.chainage_m - p.zenith_spread_m - f.along_doubt_m - p.chainage_shift_m,
         f.chainage_m + p.zenith_spread_m + f.along_doubt_m + p.chainage_shift_m)
        for f, prof in zip(frames, profs, strict=True)
        if _zenith_blocked(prof, p)
    ]  # fmt: skip
    return {"zenith": zenith, "along": _along_overhead(frames, profs, p)}


def _zenith_blocked(prof: SkyProfile, p: ReconstructionParams) -> bool:
    """Whether the camera saw an obstacle near its zenith, close to its look direction."""
    near = np.abs(prof.rel_az_deg) <= p.zenith_rel_az_deg
    seen = near & (prof.seen_hi_deg >= p.zenith_el_deg)
    if not seen.any():
        return False
    # a wide obstacle (crown, canopy, close wall), not a mast beside the camera
    return bool(np.mean(prof.sky_el_deg[seen] > p.zenith_el_deg) >= 0.5)


def _along_overhead(
    frames: Sequence[FrameView], profs: Sequence[SkyProfile], p: ReconstructionParams
) -> list[tuple[float, float]]:
    """Chainage intervals over which the frames that saw an obstacle high up straight along
    the track (:func:`_along_tops`) mark the clearance as overhead. One camera suffices: a
    cantilever reaches from its mast to the track axis, over the antenna, but not over the
    other camera's line (demanding both cameras left the demo's false trust at 0.124 %).

    Each interval reaches ``overhead_along_spread_m`` either side of the frame and, towards
    an obstacle seen at elevation ``e``, ``overhead_along_height_m / tan(e)`` plus the
    camera's lever arm along the track beyond: the obstacle's top at most
    ``overhead_along_height_m`` above the camera stands at most that far away. Until
    2026-12-05 the interval was the spread alone, and a signal gantry's girder 4-6 m from the
    two frames that saw it (at 50 and 57 deg) lay between their intervals: the clearance
    prior declared the cells under it free (``docs/reconstruction.md``, section 10)."""
    s = p.overhead_along_spread_m
    out = []
    for f, prof in zip(frames, profs, strict=True):
        tops = _along_tops(prof, f, p)
        if not np.isfinite(tops).any():
            continue
        slack = s + abs(float(f.mount.lever_arm_m[0])) + f.along_doubt_m + p.chainage_shift_m
        reach = [
            slack + p.overhead_along_height_m / np.tan(np.radians(e))
            if np.isfinite(e) else s
            for e in tops
        ]  # fmt: skip
        out.append((f.chainage_m - reach[1], f.chainage_m + reach[0]))
    return out


def lacking_side_overhead(
    positions_m: ArrayLike,
    side_chainages_m: Sequence[ArrayLike],
    p: ReconstructionParams,
    along_doubt_m: float = 0.0,
) -> list[tuple[float, float]]:
    """Chainage intervals where the clearance over the track must be taken as overhead
    because a side camera of the rig has no frame at a position.

    Only the camera on a mast's side sees its cantilever over the antenna (one camera
    suffices in :func:`_along_overhead`), and the neighbouring frames 10 m away see it too
    low along the track to stand in. A review (stop 47) set aside one left frame at a mast:
    the clearance prior called the cells under the cantilever free and that position trusted
    14.4 % of its directions falsely, 65 deg under the truth; a camera's frames set aside
    over 200 m gave 1.4 %.

    Parameters
    ----------
    positions_m : array_like, shape (n,)
        The mask positions' chainages, metres.
    side_chainages_m : sequence of array_like
        Per side camera of the rig (a camera looking sideways, not a panorama), the chainages
        of its usable frames, metres.
    p : ReconstructionParams
        ``position_tol_m`` (a frame within it is the position's own) and ``chainage_shift_m``.
    along_doubt_m : float
        The largest along-track doubt of the frames, metres.

    Returns
    -------
    list of (float, float)
        ``position_tol_m`` plus the doubts either side of each position lacking a side's own
        frame.
    """
    s = np.atleast_1d(np.asarray(positions_m, float))
    reach = p.position_tol_m + along_doubt_m + p.chainage_shift_m
    lacking = lacking_side(s, side_chainages_m, p.position_tol_m)
    return [(float(x - reach), float(x + reach)) for x in s[lacking]]


def side_cameras(cameras: Mapping[str, CameraModel]) -> list[str]:
    """The rig's cameras that look sideways (left, right; not a panorama), by place, sorted:
    those whose own frame every position needs (:func:`lacking_side_overhead`)."""
    return [side for side, cam in sorted(cameras.items())
            if side in ("left", "right") and cam.model != "equirect"]  # fmt: skip


def lacking_side(
    positions_m: ArrayLike, side_chainages_m: Sequence[ArrayLike], tol_m: float
) -> NDArray:
    """Which positions lack a frame of some side camera within ``tol_m``, shape (n,) bool
    (``positions_m`` and ``side_chainages_m`` as :func:`lacking_side_overhead`)."""
    s = np.atleast_1d(np.asarray(positions_m, float))
    lacking = np.zeros(s.size, bool)
    for ch in side_chainages_m:
        c = np.sort(np.atleast_1d(np.asarray(ch, float)))
        if c.size == 0:
            lacking[:] = True
            continue
        k = np.clip(np.searchsorted(c, s), 1, max(c.size - 1, 1)) if c.size > 1 else None
        near = (np.abs(s - c[0]) if k is None
                else np.minimum(np.abs(s - c[k - 1]), np.abs(c[k] - s)))  # fmt: skip
        lacking |= near > tol_m
    return lacking


def _along_blocked(prof: SkyProfile, frame: FrameView, p: ReconstructionParams) -> bool:
    """Whether the camera saw an obstacle high up straight along the track (ahead or behind),
    :func:`_along_tops`."""
    return bool(np.isfinite(_along_tops(prof, frame, p)).any())


def _along_tops(prof: SkyProfile, frame: FrameView, p: ReconstructionParams) -> NDArray:
    """``(e_ahead, e_behind)`` in degrees: where the camera saw an obstacle above
    ``overhead_along_el_deg`` straight along the track towards increasing (decreasing)
    chainage, the lowest elevation of its top among those columns; ``inf`` elsewhere.

    Such an obstacle is something over the track line close to the frame, which the
    clearance prior must not declare free (issue 30: a 6 cm registration arm 1-2 m over the
    antenna is opaque under the Fresnel rule, and the thin-structure policy does not remove a
    feature that wide; a signal gantry). A cab camera looks along the track: its own view is
    left to the carving. So is a 360-degree panorama's: it sees the cells over the antenna
    itself, and on the track axis under the catenary the rule fired for it on most frames at
    a cost of 5-10 points of the sky along the track for almost no false trust
    (``docs/reconstruction.md``, section 9)."""
    out = np.full(2, np.inf)
    if p.overhead_along_el_deg is None or frame.mount.side in ("front", "rear"):
        return out
    if frame.camera.model == "equirect":
        return out
    el = p.overhead_along_el_deg
    # angular distance of each profile azimuth from straight ahead, and from straight behind
    off = (prof.az_deg - frame.heading_deg + 180.0) % 360.0 - 180.0
    hit = prof.sky_el_deg > el
    covers = (prof.seen_hi_deg >= el) & (prof.seen_lo_deg <= el)
    for k, rel in enumerate((np.abs(off), 180.0 - np.abs(off))):
        seen = (rel <= p.overhead_along_half_deg) & covers
        if seen.any() and np.mean(hit[seen]) >= 0.5:
            # an obstacle up to the zenith (no sky there) counts as at 90 deg
            out[k] = min(float(prof.sky_el_deg[seen & hit].min()), 90.0)
    return out


def _both_sides(frames: Iterable[FrameView]) -> bool:
    """Whether cameras of one position see both sides of the track: a left and a right
    camera, or a 360-degree panorama (a cab camera sees along the track, not beside it)."""
    seen: set[str] = set()
    for f in frames:
        seen |= {"left", "right"} if f.camera.model == "equirect" else {f.mount.side}
    return {"left", "right"} <= seen


def _camera_ceilings(
    frames: Sequence[FrameView],
    profiles: Sequence[SkyProfile],
    cams: NDArray,
    half_deg: float,
    shift_m: float = 0.0,
) -> NDArray:
    """Rows ``(chainage_m, z_m, tan_ahead, tan_behind)`` for
    :func:`~predisat.reconstruct.heightfield.apply_clearance_prior`: per position seen by a left
    and a right camera (or a 360-degree panorama, :func:`_both_sides`), the tangent of the
    highest elevation from which either camera saw sky straight along the track (within
    ``half_deg``) up to the zenith, towards increasing and decreasing chainage (``inf`` when a
    camera did not see sky there, or did not see that direction up to within
    ``_ZENITH_SEEN_DEG`` of the zenith; clamped at 0), and the height of the highest camera,
    raised by its along-track lever arm times the steeper tangent (with a lever arm, an
    ``inf`` tangent makes the whole row bound nothing). ``shift_m`` (the window's chainage
    shift, section 18) is added to each camera's along-track doubt."""
    at: dict[float, list[int]] = {}
    for i, f in enumerate(frames):
        at.setdefault(round(f.chainage_m, 3), []).append(i)
    rows = []
    for ch, idx_all in at.items():
        # cab cameras take no part: their lever arm along the track would raise the ceiling
        # of the whole position (or void it), and the side cameras' ceiling stays as safe
        idx = [i for i in idx_all if frames[i].mount.side not in ("front", "rear")]
        if not _both_sides(frames[i] for i in idx):
            continue  # one side camera proves nothing about the other side of the track
        tans = np.full((len(idx), 2), np.inf)
        # cameras ahead of or behind the antenna: their ceilings, measured from the antenna's
        # chainage, start that much higher
        slack_m = max(abs(float(frames[i].mount.lever_arm_m[0])) for i in idx)
        for n, i in enumerate(idx):
            prof = profiles[i]
            for m, back in enumerate((0.0, 180.0)):
                rel = prof.az_deg - frames[i].heading_deg - back
                cols = np.abs(np.mod(rel + 180.0, 360.0) - 180.0) <= half_deg
                el = prof.sky_el_deg[cols]
                # +inf skylines (no sky at the top), unseen columns and columns not seen up to
                # the zenith (a deck above them would go unseen) bound nothing
                seen = np.isfinite(prof.seen_lo_deg[cols]).all() and bool(
                    (prof.seen_hi_deg[cols] >= 90.0 - _ZENITH_SEEN_DEG).all()
                )
                if cols.any() and seen and el.max() < 90.0:
                    # sky seen below the horizon proves no less than sky from the horizon up
                    tans[n, m] = np.tan(np.radians(max(float(el.max()), 0.0)))
        tan = tans.max(axis=0)
        # a camera known within a doubt may stand that much higher, and that far along
        doubt_m = max(frames[i].along_doubt_m for i in idx) + shift_m
        z = float(max(cams[i, 2] + frames[i].height_doubt_m for i in idx))
        if slack_m > 0.0:
            # between the antenna and a camera the camera's other direction bounds: both must
            if not np.isfinite(tan).all():
                tan = np.full(2, np.inf)
            else:
                z += slack_m * float(tan.max())
        fin = np.isfinite(tan)
        if doubt_m > 0.0 and fin.any():
            # a camera up to doubt_m along the track from the position: a point d ahead is
            # at most d + doubt_m ahead of it, or (d < doubt_m) at most doubt_m behind it
            if fin.all():
                z += doubt_m * float(tan.max())
            else:
                # only one direction bounds: the row starts doubt_m further that way, so that
                # no cell it bounds may lie behind the camera, and from a camera up to
                # 2 doubt_m behind its new start
                ch += doubt_m if fin[0] else -doubt_m
                z += 2.0 * doubt_m * float(tan[fin][0])
        rows.append((ch, z, *tan))
    return np.asarray(rows, float).reshape(-1, 4)


def _ceiling_caps(ceilings: NDArray, s: NDArray, antenna_m: NDArray) -> NDArray:
    """Per antenna ``(tan_cap, dz_m)`` (n, 2): from the ceiling row nearest the position,
    ``tan_cap`` bounds the elevation tangent at which the antenna sees anything in the
    clearance over the track, and ``dz_m`` is the antenna's height above the row's ceiling
    moved to the position (``(inf, 0)`` where that is negative, or no row bounds).

    A point at chainage distance ``d`` from the position is at most ``d + delta`` from a row
    ``delta`` away, so it stands at most at ``z + delta * tan + d * tan`` (the ceiling,
    pointwise, before any rasterisation; ``tan`` the steeper of the row's two, as a point
    within ``delta`` may lie on either side of its cameras), and its horizontal distance
    ``r`` from the antenna is at least ``d``: seen from the antenna at height
    ``z + delta * tan + dz`` its tangent is at most ``tan - dz / r``. 1 % is added to
    ``tan`` for the track's curvature (a chord is shorter than its arc). Until 2026-12-07 only
    a row within 1 mm of the position counted: a stop's merged view stands at one of its
    frames, mostly off the position, and the antenna's own cell kept the rasterised ceiling
    of its far end, above the antenna: the whole position read 90 deg
    (``docs/reconstruction.md``, section 24).
    """
    out = np.tile(np.array([np.inf, 0.0]), (s.size, 1))
    c = np.asarray(ceilings, float).reshape(-1, 4)
    if not c.size:
        return out
    j = np.abs(c[None, :, 0] - s[:, None]).argmin(axis=1)
    delta = np.abs(c[j, 0] - s)
    tan = np.maximum(c[j, 2], c[j, 3]) * 1.01
    with np.errstate(invalid="ignore"):
        dz = antenna_m[:, 2] - c[j, 1] - np.where(delta > 0.0, delta * tan, 0.0)
    ok = np.isfinite(tan) & (dz >= 0.0)
    out[ok, 0] = tan[ok]
    out[ok, 1] = dz[ok]
    return out


def _local_rotations(track: TrackMap, enu_m: NDArray) -> NDArray:
    lat, lon, _ = track.frame.to_geodetic(enu_m)
    return np.asarray(track.frame.rotation_from(lat, lon))


def _camera_geometry(frames: Sequence[FrameView], track: TrackMap) -> tuple[NDArray, NDArray]:
    """Camera centres (n, 3) and local-to-frame rotations (n, 3, 3) of frames."""
    ant = np.stack([np.asarray(f.antenna_enu_m, float) for f in frames])
    rot = _local_rotations(track, ant)
    cams = np.empty_like(ant)
    for i, f in enumerate(frames):
        arm_local = vehicle_to_enu(f.heading_deg, f.reverse) @ np.asarray(f.mount.lever_arm_m)
        cams[i] = ant[i] + rot[i] @ arm_local
    return cams, rot


def _antennas(track: TrackMap, s: NDArray, height_m: float) -> tuple[NDArray, NDArray]:
    axis = np.asarray(track.enu_at(s), float)
    rot = _local_rotations(track, axis)
    ant = axis + height_m * rot[:, :, 2]
    return ant, rot


def _sub_azimuths(p: ReconstructionParams) -> NDArray:
    """Ray azimuths: ``n_sub`` per bin starting at each bin's left edge."""
    n = p.n_az * p.n_sub
    return np.mod(np.arange(n) * (p.az_step_deg / p.n_sub) - p.az_step_deg / 2.0, 360.0)


def _bins(per_ray: NDArray, n_sub: int) -> NDArray:
    """Bin maximum of per-ray values (..., n_az * n_sub), the right edge included."""
    v = per_ray.reshape(*per_ray.shape[:-1], -1, n_sub)
    right = np.roll(v[..., 0], -1, axis=-1)
    return np.maximum(v.max(axis=-1), right)


def _bins_with_support(per_ray: NDArray, support: NDArray, n_sub: int) -> tuple[NDArray, NDArray]:
    """:func:`_bins` and, per bin, the support of the ray that sets it (the weakest of equal
    ones)."""
    v = per_ray.reshape(*per_ray.shape[:-1], -1, n_sub)
    w = support.reshape(*support.shape[:-1], -1, n_sub)
    cand = np.concatenate([v, np.roll(v[..., :1], -1, axis=-2)], axis=-1)
    cand_s = np.concatenate([w, np.roll(w[..., :1], -1, axis=-2)], axis=-1)
    top = _bins(per_ray, n_sub)
    with np.errstate(invalid="ignore"):
        at = (cand == top[..., None]) | np.isnan(top)[..., None]
    big = np.iinfo(np.int32).max
    return top, np.where(at, cand_s, big).min(axis=-1)


def _pick_support(a: NDArray, sa: NDArray, b: NDArray, sb: NDArray) -> NDArray:
    """Support of ``max(a, b)``: that of the larger, the weaker of the two on a tie."""
    with np.errstate(invalid="ignore"):
        return np.where(a > b, sa, np.where(b > a, sb, np.minimum(sa, sb)))


def _far_cap(far_seen: NDArray, far_views: NDArray, fusion_rank: int) -> NDArray:
    """Bins whose far height-field cells the far field caps: a camera at the position saw
    the bin, with at least ``fusion_rank`` views behind the far field's bound."""
    return np.asarray(far_seen & (far_views >= fusion_rank), bool)


def bin_support(
    near: tuple[NDArray, NDArray],
    far_grid: tuple[NDArray, NDArray],
    far_el: NDArray,
    far_seen: NDArray,
    far_views: NDArray,
    assumed: NDArray,
    n_sub: int,
    fusion_rank: int = 1,
    far_resolved: tuple[NDArray, NDArray] | None = None,
) -> NDArray:
    """Independent views behind each bin's value (``docs/reconstruction.md``, section 7).

    The bin's value is the highest of the near height field, the far height field (capped by
    the far field where a camera at the position saw the bin, with ``fusion_rank`` views or
    more) and the far field; its support is that of the part that sets it (the weaker on a
    tie): for a height-field part, the views that bounded the cell setting the steepest ray
    of the bin (``HeightField.views``, 0 for a cell a prior set); for the far field, the views
    that saw the bin (``far_views``). Where the cap lowered the far cells the bin rests on the
    far field's views whichever part sets it (the far cells' own views no longer back what is
    left of them: a review found one over-exposed frame's bins reported with 12 views). ASSUMED
    bins get 0: they rest on an unknown cell or the far-field default.

    Parameters
    ----------
    near, far_grid : (ndarray, ndarray), shapes (n_pos, n_az * n_sub)
        Per-ray elevation (deg) and support (int, -1: no cell) of the two height-field parts.
    far_el : ndarray, shape (n_pos, n_az)
        Far-field bound, deg.
    far_seen : ndarray of bool, shape (n_pos, n_az)
        A camera at the position saw the far field in the bin.
    far_views : ndarray of int, shape (n_pos, n_az)
        Views behind the far-field bound.
    assumed : ndarray of bool, shape (n_pos, n_az)
        ASSUMED bins.
    n_sub : int
        Rays per bin.
    fusion_rank : int
        ``ReconstructionParams.fusion_rank`` (the cap's condition).
    far_resolved : tuple of ndarray, optional
        Per-ray elevation and support of the far cells the cap leaves
        (``HeightField.resolved``): where they set a capped bin, its support is theirs.

    Returns
    -------
    ndarray of uint8, shape (n_pos, n_az)
        Views per bin, capped at 255.
    """
    near_b, near_s = _bins_with_support(near[0], near[1], n_sub)
    fg_b, fg_s = _bins_with_support(far_grid[0], far_grid[1], n_sub)
    cap = _far_cap(far_seen, far_views, fusion_rank)
    with np.errstate(invalid="ignore"):
        capped = cap & (far_el < fg_b)
    far_part = np.where(cap, np.minimum(fg_b, far_el), fg_b)
    far_part_s = np.where(capped, far_views, fg_s)
    if far_resolved is not None:
        fr_b, fr_s = _bins_with_support(far_resolved[0], far_resolved[1], n_sub)
        kept = cap & (fr_b > far_part)
        far_part = np.where(kept, fr_b, far_part)
        far_part_s = np.where(kept, fr_s, far_part_s)
        capped = capped & ~kept
    grid = np.maximum(near_b, far_part)
    grid_s = _pick_support(near_b, near_s, far_part, far_part_s)
    far_s = np.where(far_seen, far_views, 0)
    sup = _pick_support(grid, grid_s, far_el, far_s)
    sup = np.where(capped, np.minimum(sup, far_views), sup)
    sup = np.where(assumed, 0, np.clip(sup, 0, 255))
    return sup.astype(np.uint8)


def _ray_distances(p: ReconstructionParams) -> NDArray:
    c = p.cell_m
    near = np.arange(c / 2.0, min(30.0, p.reach_m), c / 2.0)
    far = np.arange(near[-1] + c, p.reach_m + 1e-9, c)
    return np.concatenate([near, far])


def horizon(
    hf: HeightField, antenna_m: NDArray, local_to_frame: NDArray, p: ReconstructionParams
) -> tuple[NDArray, NDArray]:
    """Horizon of the height field from antennas, per ray.

    Each ray is sampled every half cell up to 30 m and every cell beyond, up to ``reach_m`` or
    until it leaves the corridor. A sample's cell counts with its top bound seen from the
    cell's *nearest* point. Where the ray crosses a cell corner between two samples (both
    indices change), both cells at that corner count too, so every cell the ray passes
    through is counted (before 2026-12-02 such cells were skipped: bins up to 3.6 deg low in
    a check against an exact ceiling on rotated grids).

    Parameters
    ----------
    hf : HeightField
    antenna_m : ndarray, shape (n, 3)
        Antenna positions in the track frame.
    local_to_frame : ndarray, shape (n, 3, 3)
        Rotations from each antenna's local ENU into the track frame.
    p : ReconstructionParams

    Returns
    -------
    el_deg : ndarray, shape (n, n_az * n_sub)
        Steepest elevation of a cell top along each ray (``-90`` when it meets no cell); 90
        where it meets an unknown cell or where the antenna's own cell stands above it.
    unknown : ndarray of bool, shape (n, n_az * n_sub)
        The ray met an unknown cell.
    """
    near, near_unknown, far, far_unknown = _horizon_parts(hf, antenna_m, local_to_frame, p)[:4]
    return np.maximum(near, far), near_unknown | far_unknown


def _horizon_parts(
    hf: HeightField,
    antenna_m: NDArray,
    local_to_frame: NDArray,
    p: ReconstructionParams,
    caps: NDArray | None = None,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
    """:func:`horizon` split at ``p.half_width_m``: elevation and unknown flag over the cells
    whose nearest point is nearer, then over the others (``-90``: no such cell), then the
    support of each: the ``hf.views`` of the cell that set the ray's value (-1: no cell).

    ``caps`` (n, 2), from :func:`_ceiling_caps`: the clearance cells within
    ``_CEILING_CAP_M`` of each antenna count at most with ``tan_cap - dz_m / r``, ``r`` the
    distance of the farthest point of the cell and its neighbours (the cameras' ceiling is
    exact pointwise, its rasterised bound is not: the cell straddling a position holds the
    bound of its far end). ``_CEILING_CAP_M = 0`` disables the cap.
    """
    az = np.radians(_sub_azimuths(p))
    dist_cells = _ray_distances(p).astype(np.float32) / np.float32(hf.cell_m)
    c = hf.cell_m
    ny, nx = hf.shape
    bound = np.ascontiguousarray(hf.bound_m, np.float32).ravel()
    region = np.ascontiguousarray(hf.region, np.bool_).ravel()
    with np.errstate(invalid="ignore"):
        clear = hf.region & (np.abs(hf.offset_m) < p.clearance_half_width_m)
    clear = np.ascontiguousarray(clear, np.bool_).ravel()
    n = antenna_m.shape[0]
    if caps is None:
        caps = np.tile(np.array([np.inf, 0.0]), (n, 1))
    el = np.empty((n, az.size))
    el_far = np.empty((n, az.size))
    unknown = np.empty((n, az.size), bool)
    unknown_far = np.empty((n, az.size), bool)
    sup = np.empty((n, az.size), np.int32)
    sup_far = np.empty((n, az.size), np.int32)
    views = np.ascontiguousarray(
        np.zeros(hf.shape, np.int32) if hf.views is None else hf.views, np.int32
    ).ravel()
    d_loc = np.stack([np.sin(az), np.cos(az), np.zeros_like(az)], axis=-1)
    for i in range(n):
        a = antenna_m[i]
        rot = local_to_frame[i]
        up = rot[:, 2]
        d = d_loc @ rot.T
        d = np.ascontiguousarray(
            d[:, :2] / np.linalg.norm(d[:, :2], axis=1, keepdims=True), np.float32
        )
        # antenna position in cells: integer part (global, exact) and fraction (float32), so
        # that every window computes bit-identical samples
        gx, gy = np.floor(a[0] / c), np.floor(a[1] / c)
        best, best_far, sup[i], sup_far[i] = _march_rays(
            d, dist_cells, bound, region, nx, ny,
            np.float32(a[0] / c - gx), np.float32(a[1] / c - gy),
            int(gx) - hf.ix0, int(gy) - hf.iy0, np.float32(c), np.float32(a[2]),
            np.float32(up[2]), np.float32(up[0] * c), np.float32(up[1] * c),
            np.float32(p.half_width_m), clear, np.float32(caps[i, 0]), np.float32(caps[i, 1]),
            np.float32(_CEILING_CAP_M), views,
        )  # fmt: skip
        unknown[i] = np.isposinf(best)
        unknown_far[i] = np.isposinf(best_far)
        with np.errstate(invalid="ignore"):
            el[i] = np.degrees(np.arctan(best.astype(float)))
            el_far[i] = np.degrees(np.arctan(best_far.astype(float)))
    return el, unknown, el_far, unknown_far, sup, sup_far


# long: one numba kernel; helpers called per cell cost 3.8-4x (scripts/bench_march.py)
@njit(cache=True, nogil=True, error_model="numpy")
def _march_rays(
    d: NDArray, dist_cells: NDArray, bound: NDArray, region: NDArray, nx: int, ny: int,
    ax: np.float32, ay: np.float32, ox: int, oy: int, c: np.float32, a_z: np.float32,
    up_z: np.float32, up_x_c: np.float32, up_y_c: np.float32, far_m: np.float32,
    clear: NDArray, cap_t: np.float32, cap_dz: np.float32, cap_m: np.float32, views: NDArray,
) -> tuple[NDArray, NDArray, NDArray, NDArray]:  # fmt: skip
    """Steepest bound tangent along each ray, over the cells nearer than ``far_m`` and over the
    others (float32; ``+inf`` once a ray meets an unknown cell there), and the ``views``
    (int32, the raster's) of the cell that set each (the first of equal ones; -1 where no cell
    did).

    A ray stops at its first sample outside the modelled region, at its first unknown cell
    (``+inf``) and at a NaN bound (carving never writes one; the ray's value is then NaN). A
    cell is far when its nearest point is at least ``far_m`` away. A ``clear`` cell (over the
    track) nearer than ``cap_m`` (the antenna's own cell too, when ``cap_m > 0``) counts at most
    with ``cap_t - cap_dz / r``, ``r`` the distance of the farthest point of the cell and its
    8 neighbours (metres; a ray sampled every half cell may cross a neighbour's corner
    unsampled, and the cap must not hide what that neighbour may hold). All arithmetic is
    float32 in a fixed order (distances: :func:`_hypot32`), so that overlapping windows give
    bit-identical results.

    ``d`` (n_rays, 2): unit ray directions in the frame's horizontal plane; ``dist_cells``:
    increasing sample distances (cells); ``bound``, ``region``, ``clear``: the raster
    (``ny * nx``, row-major); ``ax, ay``: antenna position within its cell (cells, in
    ``[0, 1)``), whose raster index is ``(ox, oy)``; ``c``: cell size; ``a_z``: antenna height;
    ``up_z``, ``up_x_c / c``, ``up_y_c / c``: its local vertical in the frame (the x and y
    terms tilt each sample point's height); ``far_m``, ``cap_m``: metres.
    """
    # Until 2026-12-02 each cell called libm's hypotf and a non-inlined helper that recomputed
    # the sample's tilt, with the maxima in an array: 3.8-4.0x slower on the demo surveys, for
    # bit for bit the same values (scripts/bench_march.py). The numpy error model only drops
    # the checks for division by zero: every divisor is at least 1e-3 m.
    zero = np.float32(0.0)
    one = np.float32(1.0)
    two = np.float32(2.0)
    tiny = np.float32(1e-3)
    overhead = np.float32(3.4028235e38)  # tangent of 90 deg in float32, not "unknown"
    n_rays = d.shape[0]
    best = np.empty((2, n_rays), np.float32)  # near part, far part
    support = np.empty((2, n_rays), np.int32)
    # squared offsets of each column's and row's nearest edge from the antenna (cells, exact in
    # float64): a cell's distance is then one addition and one square root
    ex2 = np.empty(nx)
    for i in range(nx):
        cl = np.float32(i - ox)
        ex = max(max(cl - ax, zero), ax - cl - one)
        ex2[i] = np.float64(ex) * np.float64(ex)
    ey2 = np.empty(ny)
    for i in range(ny):
        rl = np.float32(i - oy)
        ey = max(max(rl - ay, zero), ay - rl - one)
        ey2[i] = np.float64(ey) * np.float64(ey)
    capped = cap_t < np.inf
    # The antenna's own cell, which rays leaving it early may never sample: standing above the
    # antenna, it blocks every ray up to the zenith (not the 89.9 deg that the distance floor
    # would leave); unknown, it blocks them as unknown.
    start = np.float32(-np.inf)
    start_views = np.int32(-1)
    col0 = np.int32(np.floor(ax)) + ox
    row0 = np.int32(np.floor(ay)) + oy
    if 0 <= col0 < nx and 0 <= row0 < ny and region[row0 * nx + col0]:
        top = bound[row0 * nx + col0]
        start_views = views[row0 * nx + col0]
        rel0 = (top - a_z) * up_z
        if rel0 != rel0:
            start = rel0
        elif rel0 > zero:
            start = top if top == np.inf else overhead
            if start != np.inf and clear[row0 * nx + col0] and capped and cap_m > zero:
                # the ceiling over the track: nothing in the cell above the cap, seen from the
                # farthest corner of the cell and its neighbours (the worst point; rays sampled
                # every half cell may cut a neighbour's corner unsampled)
                fx0 = max(ax, one - ax) + one
                fy0 = max(ay, one - ay) + one
                start = min(start, cap_t - cap_dz / (_hypot32(fx0, fy0) * c))
    for j in range(n_rays):
        dx, dy = d[j, 0], d[j, 1]
        b_near = start
        b_far = np.float32(-np.inf)
        s_near = start_views if start > -np.inf or start != start else np.int32(-1)
        s_far = np.int32(-1)
        best[0, j] = start
        best[1, j] = b_far
        support[0, j] = s_near
        support[1, j] = s_far
        if start == np.inf or start != start:
            continue
        pcol, prow = col0, row0
        stop = False
        for k in range(dist_cells.size):
            fx = ax + dx * dist_cells[k]
            fy = ay + dy * dist_cells[k]
            col = np.int32(np.floor(fx)) + ox
            row = np.int32(np.floor(fy)) + oy
            if col < 0 or col >= nx or row < 0 or row >= ny:
                break
            if not region[row * nx + col]:
                break
            # the tilt of the sample point, the same for every cell it counts
            tilt = (fx - ax) * up_x_c + (fy - ay) * up_y_c
            # Samples at most a cell apart change each index by at most one; when both change,
            # the ray crossed one of the two cells at that corner unsampled: count both.
            n_cells = 3 if (col != pcol and row != prow) else 1
            for m in range(n_cells):
                if m == 0:
                    cc, rr = col, row  # in the region: checked above
                else:
                    cc, rr = (col, prow) if m == 1 else (pcol, row)
                    if cc < 0 or cc >= nx or rr < 0 or rr >= ny or not region[rr * nx + cc]:
                        continue
                flat = rr * nx + cc
                # bound tangent of the cell seen from its nearest point (the square root is
                # _hypot32 of that point's offsets)
                near = max(np.float32(np.sqrt(ex2[cc] + ey2[rr])) * c, tiny)
                rel = (bound[flat] - a_z) * up_z
                r = (rel + tilt) / near
                if capped and near < cap_m and clear[flat] and r < np.inf:
                    # farthest point of the cell and its 8 neighbours (see the own cell above)
                    cl = np.float32(cc - ox)
                    rl = np.float32(rr - oy)
                    gx = max(abs(cl - one - ax), abs(cl + two - ax))
                    gy = max(abs(rl - one - ay), abs(rl + two - ay))
                    r = min(r, cap_t - cap_dz / (_hypot32(gx, gy) * c))
                # a NaN bound makes the ray's value NaN; an unknown cell hides whatever lies
                # farther: both stop the ray
                if near >= far_m:
                    if r > b_far or r != r:
                        b_far = r
                        s_far = views[flat]
                        stop = r == np.inf or r != r
                elif r > b_near or r != r:
                    b_near = r
                    s_near = views[flat]
                    stop = r == np.inf or r != r
                if stop:
                    break
            if stop:
                break
            pcol, prow = col, row
        best[0, j] = b_near
        best[1, j] = b_far
        support[0, j] = s_near
        support[1, j] = s_far
    return best[0], best[1], support[0], support[1]


@njit(cache=True, nogil=True, inline="always")
def _hypot32(x: np.float32, y: np.float32) -> np.float32:
    """``hypot`` of two float32 values, rounded to float32 from float64.

    Their squares are exact in float64, so this is what glibc's ``hypotf`` returns, bit for
    bit, without the call (which cost more than the rest of the ray march).
    """
    xd = np.float64(x)
    yd = np.float64(y)
    return np.float32(np.sqrt(xd * xd + yd * yd))


# ---------------------------------------------------------------------- far field and flags


def _far_field(
    frames: Sequence[FrameView],
    profiles: Sequence[SkyProfile],
    s: NDArray,
    ant: NDArray,
    track: TrackMap,
    p: ReconstructionParams,
) -> tuple[NDArray, NDArray, list[list[tuple[SkyProfile, float]]], NDArray]:
    """Far-field elevation bound per bin, whether a camera saw it, the profiles per position and
    the number of views behind each bound.

    A frame at the position bounds the far field at an azimuth by the highest skyline it saw
    within the parallax allowance ``asin(baseline / half_width)`` around it, raised by
    :func:`far_elevation_bound` where the camera may be farther from a far object than the
    antenna, or higher (``docs/reconstruction.md``, section 20). The bound of a bin is the
    lowest over the frames that saw the whole bin; bins no frame saw get ``far_default_deg``.

    With ``fusion_rank`` above 1 no single view lowers the far field either: in a bin a frame
    at the position saw, the bound is the higher of the position's own bound and the
    ``min(fusion_rank, n)``-th lowest over the ``n`` views (frames, or ``view_group``
    groups) among the position's frames and the frames within ``suspect_neighbour_m`` of it
    that saw the bin, each with its own azimuth allowance (a neighbour 10 m away sees a far
    object up to ``asin(10 / half_width)`` aside). The own bound stays a floor: a neighbour
    sees a far object from elsewhere, a little lower or higher, which no allowance covers
    (taking the order statistic alone doubled the false trust under injected faults).
    """
    n_az = p.n_az
    far = np.full((s.size, n_az), np.inf)
    seen_any = np.zeros((s.size, n_az), bool)
    far_views = np.zeros((s.size, n_az), np.int32)
    per_pos: list[list[tuple[SkyProfile, float]]] = [[] for _ in range(s.size)]
    if frames:
        ch = np.array([f.chainage_m for f in frames])
        cams, _ = _camera_geometry(frames, track)
        rise = _shift_rise_m(track, ch, p.chainage_shift_m)
        near_m = _far_distance_m(track, s, ant, p.half_width_m)
        az_sub = _sub_azimuths(p)
        for i in range(s.size):
            own: dict[str, NDArray] = {}  # bins each view at the position saw
            for j in np.flatnonzero(np.abs(ch - s[i]) <= p.position_tol_m):
                prof = profiles[int(j)]
                allow, vals, ok = _far_view(
                    prof, frames[int(j)], cams[j], ant[i], float(rise[j]), float(near_m[i]),
                    az_sub, p,
                )
                per_pos[i].append((prof, allow))
                fb = _bins(np.where(ok, vals, np.nan), p.n_sub)
                covered = ~np.isnan(fb)
                far[i] = np.where(covered, np.fmin(far[i], fb), far[i])
                seen_any[i] |= covered
                key = frames[int(j)].view_group or f"\0frame{int(j)}"
                own[key] = own[key] | covered if key in own else covered
            for covered in own.values():
                far_views[i] += covered
            if p.fusion_rank > 1 and seen_any[i].any():
                near = np.flatnonzero(np.abs(ch - s[i]) <= max(p.suspect_neighbour_m,
                                                                p.position_tol_m))  # fmt: skip
                # never below the position's own frames: a neighbour sees a far object from
                # elsewhere (the azimuth allowance covers its parallax, not its elevation)
                robust, n_views = _robust_far(
                    frames, profiles, cams, near, ant[i], rise, float(near_m[i]), az_sub, p
                )
                far[i] = np.where(seen_any[i], np.fmax(far[i], robust), far[i])
                far_views[i] = np.where(seen_any[i], np.maximum(far_views[i], n_views), 0)
    far_el = np.where(seen_any, far, p.far_default_deg)
    far_el = np.where(np.isinf(far_el), 90.0, far_el)
    return far_el, seen_any, per_pos, far_views


def _robust_far(
    frames: Sequence[FrameView],
    profiles: Sequence[SkyProfile],
    cams: NDArray,
    near: NDArray,
    antenna_m: NDArray,
    rise_m: NDArray,
    far_m: float,
    az_sub: NDArray,
    p: ReconstructionParams,
) -> tuple[NDArray, NDArray]:
    """Far-field bound per bin from the frames ``near`` an antenna: per view (a frame, or the
    lowest over a ``view_group``) the highest skyline within its parallax allowances, then the
    ``min(fusion_rank, n)``-th lowest over the ``n`` views that saw the bin (``+inf`` where
    none did), and ``n``."""
    views: dict[str, NDArray] = {}
    for j in near:
        f = frames[int(j)]
        _, vals, ok = _far_view(
            profiles[int(j)], f, cams[j], antenna_m, float(rise_m[j]), far_m, az_sub, p
        )
        fb = _bins(np.where(ok, vals, np.nan), p.n_sub)
        key = f.view_group or f"\0frame{int(j)}"
        views[key] = np.fmin(views[key], fb) if key in views else fb
    stack = np.sort(np.stack(list(views.values())), axis=0)  # NaN (unseen) sorts last
    n = np.sum(~np.isnan(stack), axis=0)
    k = np.minimum(n, p.fusion_rank) - 1
    out = np.take_along_axis(stack, np.maximum(k, 0)[None], axis=0)[0]
    return np.where(n > 0, out, np.inf), n


def _far_view(
    prof: SkyProfile,
    frame: FrameView,
    cam_m: NDArray,
    antenna_m: NDArray,
    rise_m: float,
    far_m: float,
    az_sub: NDArray,
    p: ReconstructionParams,
) -> tuple[float, NDArray, NDArray]:
    """A frame's far-field bound at an antenna, per sub-azimuth: its azimuth allowance (deg),
    the bound (deg; ``+inf`` where a column had no sky) and whether the view covered it.

    The camera may stand ``position_doubt_m + chainage_shift_m`` from its nominal centre
    ``cam_m`` (and ``height_doubt_m`` plus the track's rise over the shift, ``rise_m``,
    higher): the azimuth allowance takes the far object's direction from there, and
    :func:`far_elevation_bound` its elevation from the antenna (section 20).
    """
    offset = np.asarray(cam_m, float) - np.asarray(antenna_m, float)
    doubt = frame.position_doubt_m + p.chainage_shift_m
    base = float(np.hypot(offset[0], offset[1])) + doubt
    allow = float(np.degrees(np.arcsin(min(1.0, base / far_m))))
    vals, ok = _profile_max(prof, az_sub, allow)
    vals = far_elevation_bound(
        vals, az_sub, offset[:2], float(offset[2]) + frame.height_doubt_m + rise_m, doubt, far_m
    )
    return allow, vals, ok


def far_elevation_bound(
    sky_el_deg: ArrayLike,
    az_deg: ArrayLike,
    offset_en_m: ArrayLike,
    rise_m: float,
    doubt_m: float,
    far_m: float,
) -> NDArray:
    """Highest elevation, from an antenna, of anything at least ``far_m`` away horizontally
    that a camera near it saw at or under ``sky_el_deg``.

    A far object is seen lower from a camera farther from it, or higher up. With the object at
    horizontal distance ``D >= far_m`` from the antenna in azimuth ``az`` (unit vector ``u``)
    and the camera at ``d`` (``offset_en_m``, within ``doubt_m``) from it, the camera's
    distance over the antenna's is at most ``max(1, |u - d / far_m| + doubt_m / far_m)`` (the
    ratio is convex in ``1 / D``, so its largest value is at ``D = far_m`` or infinitely far)
    and at least ``max(0, 1 - (|d| + doubt_m) / far_m)``; a camera higher by ``rise_m`` adds
    at most ``rise_m / far_m`` to the tangent. The direction in which the camera saw the
    object is the azimuth allowance's business: ``sky_el_deg`` is the highest skyline within
    it.

    Parameters
    ----------
    sky_el_deg : array_like, shape (n,)
        Highest skyline the camera saw about each azimuth, degrees (``+inf``: no sky; NaN:
        not seen, both kept).
    az_deg : array_like, shape (n,)
        Azimuths from the antenna, degrees from north.
    offset_en_m : array_like, shape (2,)
        Camera centre minus antenna, east and north, metres.
    rise_m : float
        How much higher than the antenna the camera may stand, metres (negative: lower).
    doubt_m : float
        How far from ``offset_en_m`` the camera may stand horizontally, metres (>= 0).
    far_m : float
        Nearest horizontal distance of the far field from the antenna, metres (> 0).

    Returns
    -------
    ndarray, shape (n,)
        The bound, degrees (at least ``sky_el_deg`` when the camera stands at the antenna).
    """
    if not far_m > 0.0 or not doubt_m >= 0.0:
        raise ValueError(f"far_m must be > 0 and doubt_m >= 0, got {far_m} and {doubt_m}")
    el = np.asarray(sky_el_deg, float)
    az = np.radians(np.asarray(az_deg, float))
    d = np.asarray(offset_en_m, float) / far_m
    r = doubt_m / far_m
    farther = np.maximum(1.0, np.hypot(np.sin(az) - d[0], np.cos(az) - d[1]) + r)
    nearer = max(0.0, 1.0 - float(np.hypot(d[0], d[1])) - r)
    finite = np.isfinite(el)
    tan = np.tan(np.radians(np.where(finite, el, 0.0)))
    tan = np.where(tan >= 0.0, farther * tan, nearer * tan) + max(0.0, rise_m) / far_m
    return np.where(finite, np.degrees(np.arctan(tan)), el)


def _shift_rise_m(track: TrackMap, chainage_m: NDArray, shift_m: float) -> NDArray:
    """How much higher the track stands anywhere within ``shift_m`` of each chainage than at
    it, metres (0 without a shift): a survey shifted along the track also moves up the grade."""
    if shift_m <= 0.0 or chainage_m.size == 0:
        return np.zeros(chainage_m.shape)
    n = max(2, int(np.ceil(2.0 * shift_m / 0.25)) + 1)
    ds = np.linspace(-shift_m, shift_m, n)
    at = np.clip(chainage_m[:, None] + ds[None, :], 0.0, track.length_m)
    z = np.asarray(track.enu_at(at.ravel()), float)[:, 2].reshape(at.shape)
    z0 = np.asarray(track.enu_at(chainage_m), float)[:, 2]
    # the grade's change between samples 0.25 m apart is far below a millimetre
    return np.maximum(0.0, z.max(axis=1) - z0) + 0.001


def _far_distance_m(track: TrackMap, s: NDArray, ant: NDArray, half_width_m: float) -> NDArray:
    """Nearest horizontal distance of the far field from each antenna, metres: the corridor's
    half width less the antenna's offset from the track axis (a canted vehicle leans it)."""
    axis = np.asarray(track.enu_at(s), float)
    lean = np.hypot(ant[:, 0] - axis[:, 0], ant[:, 1] - axis[:, 1])
    return np.maximum(half_width_m - lean, 1.0)


def _profile_max(prof: SkyProfile, az_deg: NDArray, allow_deg: float) -> tuple[NDArray, NDArray]:
    """Highest skyline of a profile within ``+-allow_deg`` of each azimuth, and whether every
    profile column in that range was seen (values there are +inf when a column had no sky)."""
    b = prof.rel_az_deg
    step = float(b[1] - b[0])
    rel = np.mod(az_deg - prof.look_az_deg + 180.0, 360.0) - 180.0
    i_lo = np.floor((rel - allow_deg - b[0]) / step).astype(np.int64)
    i_hi = np.ceil((rel + allow_deg - b[0]) / step).astype(np.int64)
    values = np.asarray(prof.sky_el_deg, float)
    seen = np.isfinite(prof.seen_lo_deg)
    if _full_circle(prof):
        # a 360-degree profile: ranges run on across the seam behind the camera
        n = b.size
        values, seen = np.tile(values, 3), np.tile(seen, 3)
        i_lo, i_hi = i_lo + n, i_hi + n
        b_size = 3 * n
    else:
        b_size = b.size
    inside = (i_lo >= 0) & (i_hi <= b_size - 1)
    lo, hi = np.clip(i_lo, 0, b_size - 1), np.clip(i_hi, 0, b_size - 1)
    vals, all_seen = _range_max_seen(values, seen, lo, hi)
    return vals, inside & all_seen


def _full_circle(prof: SkyProfile) -> bool:
    """Whether a profile covers every relative azimuth (a 360-degree panorama's)."""
    b = prof.rel_az_deg
    return b.size > 1 and abs(b.size * float(b[1] - b[0]) - 360.0) < 1e-6


@njit(cache=True, nogil=True)
def _range_max_seen(
    values: NDArray, seen: NDArray, lo: NDArray, hi: NDArray
) -> tuple[NDArray, NDArray]:
    """Per query ``k``, the maximum of ``values[lo[k]:hi[k] + 1]`` and whether ``seen`` holds
    over that range (``lo <= hi``).

    The element :class:`~predisat.reconstruct.heightfield.RangeMax1D` returns, bit for bit: both
    give the
    range's last maximal element (``np.maximum`` keeps its second operand on ties, so its
    sparse table does too), NaN when the range holds one. The ranges here span a few columns
    (the parallax allowance), so a scan beats building two sparse tables per frame.
    """
    n = lo.size
    out = np.empty(n)
    ok = np.empty(n, np.bool_)
    for k in range(n):
        m = values[lo[k]]
        all_seen = seen[lo[k]]
        for i in range(lo[k] + 1, hi[k] + 1):
            v = values[i]
            if not (m > v or m != m):  # np.maximum(m, v)
                m = v
            all_seen = all_seen and seen[i]
        out[k] = m
        ok[k] = all_seen
    return out, ok


def _observed(
    seen: list[list[tuple[SkyProfile, float]]], mask: NDArray, p: ReconstructionParams
) -> NDArray:
    """Bins whose direction at the mask elevation lies in the view of a camera at the position."""
    out = np.zeros(mask.shape, bool)
    az = np.arange(p.n_az) * p.az_step_deg
    for i, items in enumerate(seen):
        for prof, _ in items:
            b = prof.rel_az_deg
            step = float(b[1] - b[0])
            rel = np.mod(az - prof.look_az_deg + 180.0, 360.0) - 180.0
            k = np.floor((rel - b[0]) / step + 0.5).astype(np.int64)
            if _full_circle(prof):
                k = np.mod(k, b.size)  # across the seam behind a 360-degree camera
            inside = (k >= 0) & (k < b.size)
            k = np.clip(k, 0, b.size - 1)
            with np.errstate(invalid="ignore"):
                ok = inside & (mask[i] >= prof.seen_lo_deg[k] - 1e-6)
                ok &= mask[i] <= prof.seen_hi_deg[k] + 1e-6
            out[i] |= ok
    return out


def _descriptors(
    hf: HeightField, track: TrackMap, s: NDArray, ant: NDArray, p: ReconstructionParams
) -> dict[str, NDArray]:
    """Reflection-risk descriptors from the height field, per side.

    Along the horizontal perpendicular through each antenna (left: ``heading - 90``), the cell
    that sets the horizon there is the obstacle: its nearest distance from the track axis and
    its bound above the rail. NaN when that horizon is below ``descriptor_min_el_deg`` (open
    side) and, for the height, when the cell is unknown. A monocular visual hull over-estimates
    heights behind tall obstacles and cannot range a uniform edge running along the track, so
    the distance is that of the horizon-setting cell, not of the obstacle's foot.
    """
    axis = np.asarray(track.enu_at(s), float)
    t = np.asarray(track.tangent_at(s), float)[:, :2]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    left = np.stack([-t[:, 1], t[:, 0]], axis=1)
    y = _ray_distances(p)
    c = hf.cell_m
    out: dict[str, NDArray] = {}
    for name, sign in (("left", 1.0), ("right", -1.0)):
        pts = ant[:, None, :2] + sign * y[None, :, None] * left[:, None, :]
        row, col, ok = hf.index(pts[..., 0], pts[..., 1])
        ok &= hf.region[row, col]
        valid = np.logical_and.accumulate(ok, axis=1)
        h = hf.bound_m[row, col].astype(float)
        x0 = (hf.ix0 + col) * c - ant[:, 0:1]
        y0 = (hf.iy0 + row) * c - ant[:, 1:2]
        near = np.hypot(np.maximum(np.maximum(x0, 0.0), -(x0 + c)),
                        np.maximum(np.maximum(y0, 0.0), -(y0 + c)))  # fmt: skip
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(valid & (near >= p.descriptor_gauge_m),
                             (h - ant[:, 2:3]) / np.maximum(near, 1e-3), -np.inf)  # fmt: skip
        rows = np.arange(s.size)
        el_all = np.degrees(np.arctan(ratio))
        el = el_all.max(axis=1)
        # the first cell within a few degrees of the horizon: the obstacle's top edge rather
        # than the (higher-bounded) hull behind it
        k = np.argmax(el_all >= el[:, None] - _DESCRIPTOR_TOL_DEG, axis=1)
        has = el >= p.descriptor_min_el_deg
        top = h[rows, k] - axis[:, 2]
        out[f"{name}_obstacle_distance_m"] = np.where(has, near[rows, k], np.nan)
        out[f"{name}_obstacle_height_m"] = np.where(has & np.isfinite(top), top, np.nan)
    return out
