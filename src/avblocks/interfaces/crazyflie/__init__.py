"""Crazyflies through Crazyswarm2's ROS 2 interface over Zenoh (extra
``[crazyflie]``: eclipse-zenoh, rosbags).

``Crazyflies`` replaces a velocity-controlled quadrotor with the same
ports and flies N Crazyflies through a ``crazyflie_server`` running on
rmw_zenoh: set-points on ``/cfN/cmd_full_state`` (or
``/cfN/cmd_velocity_world``), takeoff, land and notify_setpoints_stop
through the services, poses from ``/cfN/pose``; flight phases, limits and
the fail-safe come from :mod:`avblocks.interfaces.flight`. Landing
follows Crazyswarm2's contract: the last set-point, then
``notify_setpoints_stop``, then ``land``.
``CrazyflieEmulator`` (``avblocks crazyflies emulate``) stands in for the
server and the vehicles; ``Guard`` (``avblocks crazyflies guard``), run
beside the server, lands the vehicles whose set-points stop. The
message and service definitions are those of Crazyswarm2 1.0.5's
``crazyflie_interfaces`` (see :mod:`._types`).
"""

from .block import Crazyflies
from .emulator import CrazyflieEmulator
from .guard import Guard
from .link import CrazyflieLink, battery_fraction

__all__ = ["Crazyflies", "CrazyflieEmulator", "CrazyflieLink", "Guard", "battery_fraction"]
