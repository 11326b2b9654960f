"""The synthetic corridor world: procedural scenes along a track, ground truth, rendered frames.

The ``[synth]`` extra (open3d, trimesh, embreex): ``pip install 'predisat[synth]'``.

* :mod:`predisat.synth.world`, :mod:`predisat.synth.scenery` - the recipe and the mesh.
* :mod:`predisat.synth.materials` - surface materials (no renderer needed to read them).
* :mod:`predisat.synth.raycast` - ray casting backends (Embree, open3d).
* :mod:`predisat.synth.truth` - true masks, obstacle descriptors, ideal sky masks.
* :mod:`predisat.synth.sky`, :mod:`predisat.synth.render` - sky radiance and camera frames.
* :mod:`predisat.synth.generate` - a whole survey folder with its ground truth.
* :mod:`predisat.synth.photos` - procedural training photos for the sky models.
"""
