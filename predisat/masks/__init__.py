"""Per-position elevation masks: the mask set, its kernels, its file format and exporters.

* :mod:`predisat.masks.maskset` - :class:`MaskSet` and the trust queries.
* :mod:`predisat.masks.binops` - vectorised kernels on binned masks.
* :mod:`predisat.masks.fileformat` - mask file v1 (GeoParquet) and the exporters.
"""
