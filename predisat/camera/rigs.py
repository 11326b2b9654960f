"""Survey rigs: the cameras of a survey vehicle as named presets (``docs/rigs.md``).

* ``"side-fisheye"`` (the default): a fisheye on each side, 45 deg up, square to the track;
* ``"side-fisheye+cab"``: those, plus a fisheye in each cab, 30 deg up along the track (ahead
  and behind), which sees the sky straight along the track that the side cameras see only
  obliquely;
* ``"360"``: one 360-degree panoramic camera on the roof (equirectangular frames), which sees
  every azimuth from below the horizon to the zenith.

A rig maps each camera's place on the vehicle (:data:`predisat.camera.models.POSITIONS`) to its
calibration and mount, the mapping :class:`predisat.survey.SurveyWriter` and the synthetic
renderer take.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

from predisat.camera.models import CameraModel, Mount, Position, default_camera

__all__ = ["DEFAULT_RIG", "PANORAMA_WIDTH_PX", "RIG_NAMES", "Rig"]

RIG_NAMES = ("side-fisheye", "side-fisheye+cab", "360")
DEFAULT_RIG = "side-fisheye"

#: Columns of the preset 360-degree panorama (0.25 deg per pixel; 1440 x 720, about the pixel
#: count of the two 800 x 600 side cameras).
PANORAMA_WIDTH_PX = 1440

_DESCRIPTIONS = {
    "side-fisheye": "left and right fisheyes (110 deg vertical field), 45 deg up, square to "
    "the track",
    "side-fisheye+cab": "left and right fisheyes 45 deg up, plus front and rear cab fisheyes "
    "30 deg up along the track",
    "360": "one 360-degree equirectangular panorama on the roof, level, image centre ahead",
}


@dataclass(frozen=True)
class Rig:
    """The cameras of a survey vehicle.

    Attributes
    ----------
    name : str
        A preset name (:data:`RIG_NAMES`) or a free label.
    cameras : tuple of (position, CameraModel, Mount)
        One entry per camera, positions unique and equal to their mount's ``side``.
    description : str
        What the rig is, in a sentence.
    """

    name: str
    cameras: tuple[tuple[Position, CameraModel, Mount], ...]
    description: str = ""

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ValueError(f"rig {self.name!r} has no camera; give at least one")
        positions = [p for p, _, _ in self.cameras]
        if len(set(positions)) != len(positions):
            raise ValueError(f"rig {self.name!r}: camera positions {positions} repeat one")
        for pos, _, mount in self.cameras:
            if mount.side != pos:
                raise ValueError(
                    f"rig {self.name!r}: the {pos} camera has a mount for {mount.side!r}; "
                    f"give Mount({pos!r}, ...)"
                )

    @classmethod
    def preset(
        cls,
        name: str = DEFAULT_RIG,
        side_camera: CameraModel | None = None,
        side_pitch_deg: float = 45.0,
    ) -> Rig:
        """A named rig (:data:`RIG_NAMES`).

        Parameters
        ----------
        name : {"side-fisheye", "side-fisheye+cab", "360"}
        side_camera : CameraModel, optional
            Calibration of the side cameras (default: the shipped side fisheye,
            :func:`~predisat.camera.models.default_camera`); the cab cameras are always the
            shipped fisheye. Not allowed for ``"360"``.
        side_pitch_deg : float
            Pitch of the side cameras above the horizontal.
        """
        if name not in RIG_NAMES:
            raise ValueError(f"unknown rig {name!r}; choose one of {RIG_NAMES}")
        if name == "360":
            if side_camera is not None or side_pitch_deg != 45.0:
                raise ValueError(
                    "rig '360' has no side cameras: drop the side camera and pitch settings"
                )
            pano = CameraModel.equirect(PANORAMA_WIDTH_PX, name="roof_360")
            return cls(name, (("roof", pano, Mount.default("roof")),), _DESCRIPTIONS[name])
        fisheye = default_camera("fisheye")
        side = side_camera if side_camera is not None else fisheye
        cams: list[tuple[Position, CameraModel, Mount]] = [
            (s, side, replace(Mount.default(s), pitch_deg=float(side_pitch_deg)))
            for s in ("left", "right")
        ]
        if name == "side-fisheye+cab":
            cams += [(p, fisheye, Mount.default(p)) for p in ("front", "rear")]
        label = name
        if side != fisheye or side_pitch_deg != 45.0:
            # the preset's name alone would say "fisheye" of pinhole side cameras (a user trial)
            label = (f"{name} with {side.model} side cameras ({side.width_px}x{side.height_px}"
                     f" px, pitch {float(side_pitch_deg):g} deg)")  # fmt: skip
        return cls(label, tuple(cams), _DESCRIPTIONS[name])

    @property
    def positions(self) -> tuple[Position, ...]:
        """The camera positions, in rig order."""
        return tuple(p for p, _, _ in self.cameras)

    def as_mapping(self) -> dict[str, tuple[CameraModel, Mount]]:
        """Position -> (calibration, mount), the form :class:`~predisat.survey.SurveyWriter`
        takes."""
        return {p: (cam, mount) for p, cam, mount in self.cameras}

    @property
    def mounts(self) -> Mapping[str, Mount]:
        """Position -> mount."""
        return {p: mount for p, _, mount in self.cameras}

    def scaled(self, factor: float) -> Rig:
        """The same rig with every camera's resolution scaled by ``factor`` (same lenses and
        fields of view, :meth:`CameraModel.resized`), e.g. 0.5 for quick renders."""
        if not 0.0 < factor <= 4.0:
            raise ValueError(f"factor must lie in (0, 4], got {factor}")
        cams = tuple(
            (p, cam.resized(max(2, round(cam.width_px * factor)),
                            max(2, round(cam.height_px * factor))), mount)
            for p, cam, mount in self.cameras
        )  # fmt: skip
        return replace(self, cameras=cams)
