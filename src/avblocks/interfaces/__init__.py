"""Interface blocks: the same ports as a model block, talking to the outside
world (robots, physics engines, cameras). Each family is an optional extra
and is imported only when used: ``avblocks.interfaces.ros2`` needs
``pip install avblocks[ros2]``, ``avblocks.interfaces.mujoco`` needs
``avblocks[mujoco]``, ``avblocks.interfaces.vision`` needs ``avblocks[vision]``,
``avblocks.interfaces.mavlink`` (PX4/ArduPilot drones) needs
``avblocks[mavlink]``, ``avblocks.interfaces.crazyflie`` (Crazyflies
through Crazyswarm2 over Zenoh) needs ``avblocks[crazyflie]``;
``avblocks.interfaces.flight`` is the protocol-free flight layer (phases,
limits, fail-safe) the drone interfaces share.
"""

from __future__ import annotations

import importlib

__all__ = ["ros2", "mujoco", "vision", "flight", "mavlink", "crazyflie"]


def __getattr__(name):
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(name)
