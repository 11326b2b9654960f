"""The error of the track package: a track map file or vertex list that cannot be used."""

__all__ = ["TrackMapError"]


class TrackMapError(ValueError):
    """A track map file or vertex list that cannot be used; the message says why and the fix."""
