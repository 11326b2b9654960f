"""Per-position elevation masks: the mask set, its kernels, its file format and exporters.

* :mod:`predisat.masks.maskset` - :class:`MaskSet`, the trust queries, concatenation.
* :mod:`predisat.masks.binops` - vectorised kernels on binned masks.
* :mod:`predisat.masks.fileformat` - mask file v1 (GeoParquet) and the exporters.
* :mod:`predisat.masks.margins` - the trust margins per (sector, source) and their file.
* :mod:`predisat.masks.gaps` - closing the holes of a survey (nothing trusted there).
* :mod:`predisat.masks.truth` - :class:`TrueMasks`, the reference masks are scored against.
* :mod:`predisat.masks.registration` - masks carried onto another map of the line.
* :mod:`predisat.masks.merge` - masks of parallel tracks (passing loops) merged worst-case.
* :mod:`predisat.masks.antenna` - the antenna height masks hold for, checked against a train's.
"""
