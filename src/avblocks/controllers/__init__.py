"""Controllers: each a block with standard ports, its law a pure function."""

from .point_to_point import PointToPoint, point_to_point_law

__all__ = ["PointToPoint", "point_to_point_law"]
