"""Settings of a batch run (``predisat process``): chunk length, reconstruction, segmenter."""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field, fields, replace

from predisat.camera.models import CameraModel
from predisat.jsontypes import JsonDict
from predisat.reconstruct.carving import ReconstructionParams
from predisat.reconstruct.framecache import sky_net_sha256
from predisat.reconstruct.stops import STOP_SPAN_M
from predisat.sky.network import NET_METHODS
from predisat.track.cant import CantLimits, CantTable

__all__ = [
    "DEFAULT_SEGMENTER",
    "MAX_CHAINAGE_DOUBT_M",
    "THIN_DEG",
    "PipelineParams",
]

# chosen by measurement (docs/segmentation.md); the demo and `predisat process` use it
DEFAULT_SEGMENTER = "ensemble"
THIN_DEG = 0.7  # docs/segmentation.md, "Thin-structure policy": wires and cables, not masts
MAX_CHAINAGE_DOUBT_M = 50.0
"""Largest chainage doubt a run takes, metres: beyond, a survey says too little about where
its frames were to bound anything near the track."""


@dataclass(frozen=True)
class PipelineParams:
    """Settings of :func:`process_survey`.

    Attributes
    ----------
    chunk_m : float
        Chainage length of a chunk; chunk ``k`` holds the positions in
        ``[k * chunk_m, (k + 1) * chunk_m)``. A chunk is reconstructed from the frames within
        ``reconstruction.overlap_m`` (315 m) of it, so short chunks carve frames many times
        over (200 m: ~4x); 1000 m (~1.6x) keeps a resumed run's loss under a minute.
    reconstruction : ReconstructionParams
    segmenter : str
        Segmentation method of :func:`default_segmenter` (one of
        :data:`predisat.sky.segment.METHODS`), recorded in the provenance and the cache key;
        with a custom segmenter function, its own distinct name.
    sky_net : str, optional
        A sky network file (ONNX, with its ``.json`` card beside it, as written by
        ``scripts/train_sky_cnn.py``) used instead of the shipped one by the ``cnn`` and
        ``ensemble`` methods, to try a candidate. Its files' SHA-256 goes into the provenance,
        the resume key and the segmentation cache key, so no result of another network is
        reused.
    thin_deg : float
        The thin-structure policy of the default segmenter in angle: obstacle features at most
        this wide are L-band transparent (``docs/segmentation.md``). Each camera gets
        ``SkyOptions.thin_px = max(1, round(thin_deg / camera.widest_pixel_deg))`` (3 px on the
        demo's 640x480 fisheye): the widest pixel of the frame, so that no feature much wider
        than ``thin_deg`` anywhere in it is made transparent; 0 disables the policy. Custom
        segmenters apply their own.
    cant : CantLimits
        Bounds the vehicle's roll on curves where the manifest gives no measured attitude
        (``docs/reconstruction.md``, section 16).
    grade_doubt_deg : float
        Where the manifest gives no measured pitch, the track map's grade is taken give or
        take this angle (a map without heights reads level): 2.3 deg is a 40 per mille grade,
        steeper than adhesion lines are built.
    imu_doubt_deg : float
        Accuracy of the manifest's measured roll and pitch, degrees each. 0 (the default)
        takes them as exact, as the mount is taken: give your GNSS/INS's (0.1 for a MEMS
        unit in motion). On the demo 0.1 costs 1.6 points of sky (docs/reconstruction.md,
        section 16).
    cant_table : CantTable, optional
        The cant along the track from the infrastructure's records: where the manifest has no
        measured roll, it is bounded around that cant and the survey's speed instead of the
        curvature's whole range. Its content's SHA-256 goes into the provenance and the
        resume key.
    chainage_doubt_m : float, optional
        How far any frame's true chainage may be from the manifest's, metres: the survey's
        positioning accuracy along the track, as a bound (a few centimetres with RTK, metres
        with plain GNSS). Each camera is then bounded from anywhere within it: its centre's
        doubt box and its sky's erosion grow (``docs/reconstruction.md``, section 18). None
        (the default): the survey's own statement (``chainage_doubt_m`` in survey.yaml), 0
        when it makes none; :func:`~predisat.reconstruct.batch.process_survey` resolves it.
    chainage_jitter_m : float, optional
        How far the frames within a few hundred metres (a window, ``overlap_m``) may be off
        from each other's error, metres: the largest ``|e_i - b|`` about an error ``b`` they
        share (a GNSS/INS's relative accuracy, centimetres over half a minute, against its
        metres of absolute error). Given below ``chainage_doubt_m``, each frame is bounded
        within it and the masks take the sky from anywhere within the doubt as a shift of the
        whole window (``ReconstructionParams.chainage_shift_m``), which costs less sky than
        bounding every frame within the doubt. None: the survey's ``chainage_jitter_m``, else
        the doubt itself (nothing assumed about how the errors go together).
    mount_doubt_deg : float
        How far each camera's true mounting (pitch, roll, yaw on the vehicle) may be from its
        calibration, degrees: every frame's sky is eroded by it, as by an attitude doubt (an
        erosion by an angle holds any turn of the camera by that angle). 0 (the default): the
        mounts taken as exact. A user trial pitched one camera 2 deg off its calibration:
        0.056 % of the directions trusted falsely, 0.35 % at the worst position, with no
        check noticing (``docs/reconstruction.md``, section 16).
    antenna_height_m : float, optional
        The train antenna's height above the track axis the masks are made for, metres (the
        masks' ``provenance["antenna_height_m"]``); None (the default): the survey's
        ``antenna_height_m``. The cameras stay where the survey's rig puts them. A train
        antenna lower than the masks' sees near obstacles higher (:mod:`predisat.masks.antenna`).
    stop_gap_m : float
        Frames of one camera whose chainages lie within this of the next (a stop or a crawl,
        captured on time rather than distance) are merged into one view before carving: sky
        only where every one of them saw sky (:mod:`predisat.reconstruct.stops`,
        ``docs/reconstruction.md``, section 24). Metres, >= 0; 0 merges frames at one
        chainage only. The 10 m spacing of a distance-triggered survey merges nothing; 0.2 m
        (the default) chains a standing train's frames (their chainages sorted, centimetres
        apart) and leaves a crawl's or a video's frames 0.25 m apart and more as views of
        their own (merged, their position doubt costs sky).
    stop_span_m : float
        A chain spreading over more than this (a slower crawl) is cut into pieces spreading
        at most this; metres, in [``stop_gap_m``, 5]. 0.5 m (the default) holds a standing
        train's chainage jitter of decimetres (a projected GNSS position) in one view.
    """

    chunk_m: float = 1000.0
    reconstruction: ReconstructionParams = field(default_factory=ReconstructionParams)
    segmenter: str = DEFAULT_SEGMENTER
    sky_net: str | None = None
    thin_deg: float = THIN_DEG
    cant: CantLimits = field(default_factory=CantLimits)
    grade_doubt_deg: float = 2.3
    imu_doubt_deg: float = 0.0
    cant_table: CantTable | None = None
    chainage_doubt_m: float | None = None
    chainage_jitter_m: float | None = None
    antenna_height_m: float | None = None
    mount_doubt_deg: float = 0.0
    stop_gap_m: float = 0.2
    stop_span_m: float = STOP_SPAN_M

    def __post_init__(self) -> None:
        h = self.antenna_height_m
        if h is not None and not (math.isfinite(h) and 0.0 < h <= 8.0):
            raise ValueError(f"antenna_height_m must lie in (0, 8] metres above the track axis, "
                             f"got {h}")  # fmt: skip
        for name in ("chainage_doubt_m", "chainage_jitter_m"):
            doubt = getattr(self, name)
            if doubt is not None and not (
                math.isfinite(doubt) and 0 <= doubt <= MAX_CHAINAGE_DOUBT_M
            ):
                raise ValueError(
                    f"{name} must be a length in [0, {MAX_CHAINAGE_DOUBT_M:g}] metres (the "
                    f"survey's positioning accuracy along the track), got {doubt}"
                )
        for name in ("grade_doubt_deg", "imu_doubt_deg", "mount_doubt_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0 <= v < 10.0):
                raise ValueError(f"{name} must be an angle in [0, 10) degrees, got {v}")
        if not (math.isfinite(self.stop_gap_m) and 0.0 <= self.stop_gap_m <= 5.0):
            raise ValueError(f"stop_gap_m must be a length in [0, 5] metres (frames of one "
                             f"camera closer than this are one view), got {self.stop_gap_m}")
        if not (math.isfinite(self.stop_span_m) and self.stop_gap_m <= self.stop_span_m <= 5.0):
            raise ValueError(f"stop_span_m must be a length in [stop_gap_m, 5] metres (the "
                             f"longest spread of one stop's frames), got {self.stop_span_m}")
        if not (math.isfinite(self.chunk_m) and self.chunk_m > 0):
            raise ValueError(f"chunk_m must be a positive number of metres, got {self.chunk_m}")
        if not (math.isfinite(self.thin_deg) and 0.0 <= self.thin_deg < 10.0):
            raise ValueError(f"thin_deg must lie in [0, 10) degrees (0 disables the "
                             f"thin-structure policy), got {self.thin_deg}")  # fmt: skip
        if self.sky_net is not None:
            if self.segmenter not in NET_METHODS:
                raise ValueError(
                    f"sky_net {self.sky_net} is used by the segmenters {NET_METHODS}, not by "
                    f"{self.segmenter!r}; choose one of them (CLI: --segmenter ensemble)"
                )

    def thin_px(self, camera: CameraModel) -> int:
        """``SkyOptions.thin_px`` for frames of ``camera`` (see ``thin_deg``)."""
        if self.thin_deg == 0.0:
            return 0
        return max(1, round(self.thin_deg / camera.widest_pixel_deg))

    @classmethod
    def from_record(cls, record: JsonDict, where: str) -> PipelineParams:
        """The parameters of a run's record (``provenance.json``'s ``params``, as
        :meth:`to_dict` writes them); fields the record lacks (a run of older code) take their
        defaults. A cant table is recorded by its digest only: ``where`` names the record in
        the error asking for it.

        Raises
        ------
        ValueError
            The run used a cant table.
        """
        table = (record.get("attitude") or {}).get("cant_table")
        if table is not None:
            raise ValueError(
                f"{where}: the run used a cant table ({table.get('source')}), which the record "
                "holds by its digest only; pass params= with that cant_table"
            )
        names = {f.name for f in fields(ReconstructionParams)}
        kept_recon: JsonDict = {
            k: tuple(v) if isinstance(v, list) else v
            for k, v in (record.get("reconstruction") or {}).items() if k in names
        }  # fmt: skip
        recon = ReconstructionParams(**kept_recon)
        att = dict(record.get("attitude") or {})
        cant = CantLimits(**{k: att[k] for k in {f.name for f in fields(CantLimits)} if k in att})
        base = cls()
        kept = {k: record[k] for k in ("chunk_m", "segmenter", "thin_deg", "chainage_doubt_m",
                                       "chainage_jitter_m", "stop_gap_m", "stop_span_m")
                if k in record}  # fmt: skip
        net = record.get("sky_net")
        return replace(
            base, **kept, reconstruction=recon, cant=cant,
            sky_net=None if net is None else str(net["path"]),
            grade_doubt_deg=float(att.get("grade_doubt_deg", base.grade_doubt_deg)),
            imu_doubt_deg=float(att.get("imu_doubt_deg", base.imu_doubt_deg)),
            mount_doubt_deg=float(att.get("mount_doubt_deg", base.mount_doubt_deg)),
            antenna_height_m=recon.antenna_height_m,
        )  # fmt: skip

    def to_dict(self) -> JsonDict:
        """JSON-serialisable form (recorded in every chunk's provenance)."""
        rec = {
            k: (list(v) if isinstance(v, tuple) else v)
            for k, v in asdict(self.reconstruction).items()
        }
        out: JsonDict = {
            "chunk_m": self.chunk_m, "segmenter": self.segmenter, "reconstruction": rec,
            "thin_deg": self.thin_deg,
            "attitude": {**asdict(self.cant), "grade_doubt_deg": self.grade_doubt_deg,
                         "imu_doubt_deg": self.imu_doubt_deg,
                         **({"mount_doubt_deg": self.mount_doubt_deg}
                            if self.mount_doubt_deg else {}),
                         "cant_table": _table_record(self.cant_table)},
            "chainage_doubt_m": self.chainage_doubt_m,
            "chainage_jitter_m": self.chainage_jitter_m,
            "stop_gap_m": self.stop_gap_m,
            "stop_span_m": self.stop_span_m,
        }  # fmt: skip
        if self.sky_net is not None:
            # absent for the shipped network, so the run keys of earlier runs stay valid
            out["sky_net"] = {"path": str(self.sky_net), "sha256": sky_net_sha256(self.sky_net)}
        return out


def _table_record(table: CantTable | None) -> JsonDict | None:
    """A cant table as the provenance records it: where from, rows, SHA-256 of the values."""
    if table is None:
        return None
    digest = hashlib.sha256(table.chainage_m.tobytes() + table.cant_mm.tobytes()).hexdigest()
    return {"source": table.source, "rows": int(table.chainage_m.size), "sha256": digest}
