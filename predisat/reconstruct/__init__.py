"""From sky masks to 360 deg elevation masks: skyline directions, carving, the batch run.

* :mod:`predisat.reconstruct.skyline` - a frame's sky mask to skyline directions.
* :mod:`predisat.reconstruct.heightfield` - the corridor height field carved free by sky rays.
* :mod:`predisat.reconstruct.carving` - full-360 masks of every position from many frames.
* :mod:`predisat.reconstruct.batch` - ``predisat process``: survey folder to mask file, with
  its parts :mod:`~predisat.reconstruct.params` (settings), :mod:`~predisat.reconstruct.frames`
  (reading and segmenting a frame), :mod:`~predisat.reconstruct.framecache` (the cache and the
  fingerprints), :mod:`~predisat.reconstruct.chunks` (one chainage chunk),
  :mod:`~predisat.reconstruct.executor` (this process or a worker pool) and
  :mod:`~predisat.reconstruct.badframes`.
* :mod:`predisat.reconstruct.evaluate`, :mod:`predisat.reconstruct.evalfigures` - masks
  against synthetic ground truth, margin fitting, and the figures.
"""
