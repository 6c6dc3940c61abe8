"""ROS 2 robots as blocks (extra ``[ros2]``: eclipse-zenoh, rosbags).

``Robots`` replaces a vehicle model block with the same ports and talks to
robots over Zenoh (zenoh-bridge-ros2dds or rmw_zenoh key conventions) or
rclpy; ``emulate`` runs robot stand-ins for tests; ``replace_block`` swaps
a diagram's model block for a ``Robots`` block.
"""

from ._zenoh import Link, free_port, open_router, open_session
from .errors import PreflightError, RobotError, RobotLinkError, RobotWarning
from .robots import Robots
from .swap import replace_block, robots_like

__all__ = ["Robots", "Link", "open_router", "open_session", "free_port",
           "PreflightError", "RobotError", "RobotLinkError", "RobotWarning",
           "replace_block", "robots_like"]
