"""Controllers: each a block with standard ports, its law a pure function."""

from .formations import formation, formation_offsets, leader_tree, references, virtual_grid
from .leader_follower import LeaderFollower, leader_follower_law, leader_follower_terms
from .point_to_point import PointToPoint, point_to_point_law

__all__ = [
    "PointToPoint", "point_to_point_law",
    "LeaderFollower", "leader_follower_law", "leader_follower_terms",
    "formation", "formation_offsets", "leader_tree", "references", "virtual_grid",
]
