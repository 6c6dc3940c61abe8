"""Utilities: angle wrapping, SE(2) transforms, 3-D rotations, initial poses."""

from .angles import angle_diff, wrap_angle
from .arrays import columns
from .poses import random_poses, random_positions
from .se2 import (
    body_to_world,
    rotate,
    se2_compose,
    se2_from_matrix,
    se2_inverse,
    se2_relative,
    se2_to_matrix,
    velocity_body_to_world,
    velocity_world_to_body,
    world_to_body,
)
from .se3 import (
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_euler,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_to_euler,
    quat_to_matrix,
)

__all__ = [
    "wrap_angle", "angle_diff", "columns",
    "rotate", "se2_compose", "se2_inverse", "se2_relative", "body_to_world",
    "world_to_body", "velocity_body_to_world", "velocity_world_to_body",
    "se2_to_matrix", "se2_from_matrix",
    "quat_multiply", "quat_conjugate", "quat_normalize", "quat_rotate",
    "quat_to_matrix", "quat_from_axis_angle", "quat_from_euler", "quat_to_euler",
    "random_positions", "random_poses",
]
