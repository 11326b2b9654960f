"""Camera models (pinhole, fisheye), mounts on the vehicle and calibration files.

* :mod:`predisat.camera.models` - :class:`CameraModel`, :class:`Mount`, the vehicle frame.
* :mod:`predisat.camera.calibfile` - reading intrinsic calibration files of common layouts.
"""
