"""The synthetic corridor world: procedural scenes along a track, ground truth, rendered frames."""
