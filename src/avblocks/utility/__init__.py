"""Utilities: angle wrapping, SE(2) transforms, initial poses."""

from .angles import angle_diff, wrap_angle

__all__ = ["wrap_angle", "angle_diff"]
