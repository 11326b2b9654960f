"""Sky segmentation of camera frames, and its evaluation on labelled photos.

* :mod:`predisat.sky.segment` - :func:`segment_sky`: the sky mask, skyline and confidence.
* :mod:`predisat.sky.options` - :data:`~predisat.sky.options.METHODS` and ``SkyOptions``.
* :mod:`predisat.sky.morphology` - the thin-structure policy and connected components on runs.
* :mod:`predisat.sky.skyline` - the skyline of a mask and its per-column confidence.
* :mod:`predisat.sky.features` - per-pixel colour and texture features.
* :mod:`predisat.sky.perceptron` - the per-pixel perceptron on those features.
* :mod:`predisat.sky.network` - the small U-Net (ONNX, run by OpenCV) and the ensemble.
* :mod:`predisat.sky.grabcut` - the classical seeds + GrabCut method.
* :mod:`predisat.sky.photoeval` - scoring a segmenter against reference sky masks.
"""
