"""Interface blocks: the same ports as a model block, talking to the outside
world (robots, physics engines, cameras). Each family is an optional extra
and is imported only when used: ``avblocks.interfaces.ros2`` needs
``pip install avblocks[ros2]``, ``avblocks.interfaces.mujoco`` needs
``avblocks[mujoco]``, ``avblocks.interfaces.vision`` needs ``avblocks[vision]``.
"""

from __future__ import annotations

import importlib

__all__ = ["ros2", "mujoco", "vision"]


def __getattr__(name):
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(name)
