"""Camera calibration files: the canonical layout and tolerant readers for common layouts.

The canonical layout (written by :meth:`predisat.camera.models.CameraModel.to_yaml` with
``cv2.FileStorage``) is OpenCV FileStorage YAML::

    %YAML:1.0            (OpenCV 5 writes "%YAML 1.2")
    ---
    format: predisat-camera
    version: 1
    camera_name: side_pinhole
    model: pinhole                  # or fisheye, or equirect (a 360-degree panorama)
    image_width: 800
    image_height: 600
    camera_matrix: !!opencv-matrix  # 3x3, fx 0 cx / 0 fy cy / 0 0 1
    distortion_coefficients: !!opencv-matrix  # 1xN: k1 k2 p1 p2 [k3] | k1 k2 k3 k4
                                              # (absent for equirect)

Also read: ROS ``camera_info`` YAML (``distortion_model`` plumb_bob / equidistant), OpenCV's
calibration sample (``fisheye_model`` flag), camodocal files used by VINS-Fusion and GVINS
(``model_type: PINHOLE`` / ``KANNALA_BRANDT``), Kalibr camchains (``camera_model: pinhole`` with
``distortion_model: radtan`` / ``equidistant``) and ORB-SLAM2/3 settings (``Camera.type:
PinHole`` / ``KannalaBrandt8``). Other projection models are rejected with
:class:`CalibrationError` naming the file and the model.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal, TypedDict

import numpy as np
import yaml

__all__ = [
    "CANONICAL_FORMAT",
    "CANONICAL_VERSION",
    "CalibrationError",
    "CalibrationFields",
    "read_calibration",
]

CANONICAL_FORMAT = "predisat-camera"
CANONICAL_VERSION = 1

_PINHOLE_NAMES = {"pinhole", "plumb_bob", "radtan", "radial-tangential", "opencv"}
_FISHEYE_NAMES = {"fisheye", "equidistant", "kannala_brandt", "kannalabrandt8", "kb4"}
_EQUIRECT_NAMES = {"equirect", "equirectangular"}
_UNSUPPORTED_HINT = (
    "PREDISAT supports the pinhole model with radial-tangential distortion, the OpenCV "
    "fisheye (Kannala-Brandt k1..k4) model and stitched equirectangular (360-degree) "
    "panoramas; recalibrate with one of them, e.g. with cv2.calibrateCamera or "
    "cv2.fisheye.calibrate"
)


class CalibrationError(ValueError):
    """A calibration file that cannot be read; the message names the file and the fix."""


class _Loader(yaml.SafeLoader):
    """SafeLoader that understands OpenCV's ``!!opencv-matrix`` tags."""


class CalibrationFields(TypedDict):
    """:class:`~predisat.camera.models.CameraModel` keyword arguments read from a calibration
    file (:func:`read_calibration`): focal lengths and principal point in pixels, the lens model
    and its distortion coefficients (OpenCV order)."""

    name: str
    model: Literal["pinhole", "fisheye", "equirect"]
    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...]


def _construct_opencv_matrix(loader: yaml.SafeLoader, node: yaml.MappingNode) -> np.ndarray:
    m = loader.construct_mapping(node, deep=True)
    try:
        return np.asarray(m["data"], float).reshape(int(m["rows"]), int(m["cols"]))
    except (KeyError, TypeError, ValueError) as exc:
        # a YAMLError, so that the message names the file and the matrix's line
        what = f"no {exc} field" if isinstance(exc, KeyError) else str(exc)
        raise yaml.constructor.ConstructorError(
            None, None,
            f"opencv-matrix: {what}; give rows, cols and rows x cols numbers in data",
            node.start_mark,
        ) from None


for _tag in ("opencv-matrix", "opencv-nd-matrix"):
    _Loader.add_constructor(f"tag:yaml.org,2002:{_tag}", _construct_opencv_matrix)


def _load_yaml(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        fix = (
            "check the path (a survey.yaml's are relative to its folder) or put the file there"
            if isinstance(exc, FileNotFoundError)
            else "check the file's permissions"
        )
        raise CalibrationError(
            f"{path}: cannot read calibration file ({exc.strerror}); {fix}"
        ) from None
    except UnicodeDecodeError as exc:
        raise CalibrationError(
            f"{path}: not UTF-8 text (byte {exc.start}: {exc.reason}); save the calibration "
            "as UTF-8 YAML (OpenCV FileStorage)"
        ) from None
    # OpenCV writes a "%YAML:1.0" directive that is not valid YAML; drop any directive line.
    lines = [ln for ln in text.splitlines() if not ln.startswith("%YAML")]
    try:
        data = yaml.load("\n".join(lines), Loader=_Loader)
    except yaml.YAMLError as exc:
        raise CalibrationError(f"{path}: not valid (OpenCV FileStorage) YAML: {exc}") from None
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: expected a YAML mapping of calibration fields")
    return data


def _num(data: dict[str, Any], key: str, path: Path) -> float:
    if key not in data:
        raise CalibrationError(f"{path}: missing field {key!r}")
    try:
        return float(data[key])
    except (TypeError, ValueError):
        raise CalibrationError(
            f"{path}: field {key!r} must be a number, got {data[key]!r}"
        ) from None


def _pixels(data: dict[str, Any], key: str, path: Path) -> int:
    """An image size field as int; CalibrationError when it is not finite."""
    value = _num(data, key, path)
    if not np.isfinite(value):
        raise CalibrationError(
            f"{path}: field {key!r} must be a number of pixels, got {data[key]!r}"
        )
    return int(value)


def _matrix(data: dict[str, Any], key: str, path: Path) -> np.ndarray:
    """A matrix given as ``!!opencv-matrix``, a ROS ``{rows, cols, data}`` map or a list."""
    value = data.get(key)
    if value is None:
        raise CalibrationError(f"{path}: missing field {key!r}")
    try:
        if isinstance(value, dict):
            return np.asarray(value["data"], float).reshape(int(value["rows"]), int(value["cols"]))
        return np.asarray(value, float)
    except (KeyError, TypeError, ValueError):
        raise CalibrationError(f"{path}: field {key!r} is not a numeric matrix") from None


_KNOWN_OTHER_MODELS = {
    "mei": "MEI unified omnidirectional",
    "omni": "omnidirectional (Mei)",
    "scaramuzza": "Scaramuzza omnidirectional",
    "ds": "double sphere",
    "eucm": "extended unified",
}


def _reject(path: Path, model: object) -> CalibrationError:
    label = _KNOWN_OTHER_MODELS.get(str(model).strip().lower())
    what = f"{model!r} ({label})" if label else repr(model)
    return CalibrationError(f"{path}: camera model {what} is not supported. {_UNSUPPORTED_HINT}")


def _model_name(value: object, path: Path) -> Literal["pinhole", "fisheye", "equirect"]:
    name = str(value).strip().lower()
    if name in _PINHOLE_NAMES:
        return "pinhole"
    if name in _FISHEYE_NAMES:
        return "fisheye"
    if name in _EQUIRECT_NAMES:
        return "equirect"
    raise _reject(path, value)


def _from_opencv(data: dict[str, Any], path: Path) -> CalibrationFields:
    """Canonical layout, OpenCV calibration sample and ROS camera_info."""
    model: Literal["pinhole", "fisheye", "equirect"]
    if "model" in data:
        model = _model_name(data["model"], path)
    elif "distortion_model" in data:
        model = _model_name(data["distortion_model"], path)
    elif "fisheye_model" in data:
        model = "fisheye" if int(data["fisheye_model"]) else "pinhole"
    else:
        model = "pinhole"  # ROS camera_info and OpenCV's default
    k = _matrix(data, "camera_matrix", path)
    if k.size != 9:
        raise CalibrationError(f"{path}: camera_matrix must be 3x3, got {k.size} values")
    k = k.reshape(3, 3)
    if abs(k[0, 1]) > 1e-9 * abs(k[0, 0]):
        raise CalibrationError(f"{path}: camera_matrix has skew {k[0, 1]}; skew is not supported")
    if model == "equirect":
        # a stitched panorama has no lens distortion left: none is written, zeros are accepted
        dist = (
            _matrix(data, "distortion_coefficients", path).ravel()
            if "distortion_coefficients" in data
            else np.zeros(0)
        )
        if np.any(dist != 0):
            raise CalibrationError(
                f"{path}: an equirect (360-degree panorama) calibration has no distortion; "
                f"remove distortion_coefficients or set them to 0, got {dist.tolist()}"
            )
        dist = np.zeros(0)
    else:
        dist = _matrix(data, "distortion_coefficients", path).ravel()
    if model == "pinhole" and dist.size > 5:
        if np.any(dist[5:] != 0):
            raise CalibrationError(
                f"{path}: {dist.size} distortion coefficients (rational or thin-prism model) are "
                f"not supported. {_UNSUPPORTED_HINT}"
            )
        dist = dist[:5]
    return {
        "name": str(data.get("camera_name", path.stem)),
        "model": model,
        "width_px": _pixels(data, "image_width", path),
        "height_px": _pixels(data, "image_height", path),
        "fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2],
        "dist": tuple(dist.tolist()),
    }  # fmt: skip


def _from_camodocal(data: dict[str, Any], path: Path) -> CalibrationFields:
    """camodocal layout (VINS-Mono/Fusion, GVINS): PINHOLE and KANNALA_BRANDT."""
    model_type = str(data["model_type"]).strip().upper()
    proj = data.get("projection_parameters") or {}
    name = str(data.get("camera_name", path.stem))
    width_px = _pixels(data, "image_width", path)
    height_px = _pixels(data, "image_height", path)
    if model_type == "PINHOLE":
        dist = data.get("distortion_parameters") or {}
        return {
            "name": name, "width_px": width_px, "height_px": height_px, "model": "pinhole",
            "fx": _num(proj, "fx", path), "fy": _num(proj, "fy", path),
            "cx": _num(proj, "cx", path), "cy": _num(proj, "cy", path),
            "dist": tuple(_num(dist, k, path) for k in ("k1", "k2", "p1", "p2")),
        }  # fmt: skip
    if model_type == "KANNALA_BRANDT":
        # camodocal's k2..k5 are the theta^3..theta^9 coefficients, OpenCV's k1..k4
        return {
            "name": name, "width_px": width_px, "height_px": height_px, "model": "fisheye",
            "fx": _num(proj, "mu", path), "fy": _num(proj, "mv", path),
            "cx": _num(proj, "u0", path), "cy": _num(proj, "v0", path),
            "dist": tuple(_num(proj, k, path) for k in ("k2", "k3", "k4", "k5")),
        }  # fmt: skip
    raise _reject(path, data["model_type"])


def _from_kalibr(data: dict[str, Any], path: Path) -> CalibrationFields:
    """Kalibr camchain entry: intrinsics [fu, fv, pu, pv], distortion_coeffs, resolution."""
    if str(data["camera_model"]).strip().lower() != "pinhole":
        raise _reject(path, data["camera_model"])
    model = _model_name(data.get("distortion_model", "radtan"), path)
    try:
        fu, fv, pu, pv = (float(x) for x in data["intrinsics"])
        w, h = (int(x) for x in data["resolution"])
        dist = tuple(float(x) for x in data.get("distortion_coeffs", [0.0] * 4))
    except (KeyError, TypeError, ValueError):
        raise CalibrationError(
            f"{path}: Kalibr entry needs intrinsics [fu, fv, pu, pv] and resolution [w, h]"
        ) from None
    return {
        "name": str(data.get("rostopic", path.stem)), "model": model, "width_px": w,
        "height_px": h, "fx": fu, "fy": fv, "cx": pu, "cy": pv, "dist": dist,
    }  # fmt: skip


def _from_orbslam(data: dict[str, Any], path: Path) -> CalibrationFields:
    """ORB-SLAM3 (``Camera1.*``) and ORB-SLAM2 (``Camera.*``) settings."""
    cam_type = str(data.get("Camera.type", "PinHole")).strip()
    prefix = "Camera1." if "Camera1.fx" in data else "Camera."
    fx, fy, cx, cy = (_num(data, prefix + k, path) for k in ("fx", "fy", "cx", "cy"))
    width_px = _pixels(data, "Camera.width", path)
    height_px = _pixels(data, "Camera.height", path)
    if cam_type.lower() == "pinhole":
        dist = [_num(data, prefix + k, path) for k in ("k1", "k2", "p1", "p2")]
        if prefix + "k3" in data:
            dist.append(_num(data, prefix + "k3", path))
        return {"name": path.stem, "width_px": width_px, "height_px": height_px, "fx": fx,
                "fy": fy, "cx": cx, "cy": cy, "model": "pinhole", "dist": tuple(dist)}  # fmt: skip
    if cam_type.lower() == "kannalabrandt8":
        dist4 = tuple(_num(data, prefix + k, path) for k in ("k1", "k2", "k3", "k4"))
        return {"name": path.stem, "width_px": width_px, "height_px": height_px, "fx": fx,
                "fy": fy, "cx": cx, "cy": cy, "model": "fisheye", "dist": dist4}  # fmt: skip
    raise _reject(path, cam_type)


def read_calibration(path: str | os.PathLike[str]) -> CalibrationFields:
    """Read a calibration file into :class:`~predisat.camera.models.CameraModel` keyword arguments.

    Parameters
    ----------
    path : path-like
        Calibration YAML in any layout listed in the module docstring.

    Returns
    -------
    CalibrationFields
        ``name, model, width_px, height_px, fx, fy, cx, cy`` (pixels) and ``dist``.

    Raises
    ------
    CalibrationError
        Unreadable file, unknown layout, missing field or unsupported model.
    """
    p = Path(path)
    data = _load_yaml(p)
    if "format" in data and data["format"] == CANONICAL_FORMAT:
        version = data.get("version")
        if version != CANONICAL_VERSION:
            raise CalibrationError(
                f"{p}: calibration format version {version!r} is not supported (this PREDISAT "
                f"reads version {CANONICAL_VERSION}); upgrade predisat or rewrite the file"
            )
    if "cam0" in data and isinstance(data["cam0"], dict):  # Kalibr camchain: first camera
        data = data["cam0"]
    if "model_type" in data:
        return _from_camodocal(data, p)
    if "camera_model" in data and "intrinsics" in data:
        return _from_kalibr(data, p)
    if "Camera.type" in data or "Camera1.fx" in data or "Camera.fx" in data:
        return _from_orbslam(data, p)
    if "camera_matrix" in data:
        return _from_opencv(data, p)
    raise CalibrationError(
        f"{p}: unknown calibration layout (expected camera_matrix + distortion_coefficients as "
        "written by CameraModel.to_yaml, or a ROS camera_info, camodocal, Kalibr or ORB-SLAM "
        "file)"
    )
