"""MuJoCo physics world with cameras (extra ``[mujoco]``).

- :class:`Scene`: agents, ``environment.World`` obstacles, ground and
  cameras compiled to one MuJoCo model (or a user's MJCF, :meth:`Scene.from_mjcf`);
- :class:`PhysicsWorld`: a periodic block simulating the scene's dynamic
  agents with the ports of the model blocks they replace
  (``vehicles.Unicycle`` / ``DiffDrive`` / ``Quadrotor``);
- :class:`SceneCamera`: a periodic block rendering per-agent and fixed
  cameras into ``image`` (C, H, W, 3) uint8, with ``camera_matrix``.

Headless: importing a block picks ``MUJOCO_GL`` (EGL, then OSMesa) before
MuJoCo is imported (see :mod:`._gl`); :class:`MuJoCoUnavailable` names what
to install when neither works.
"""

from ._gl import MuJoCoUnavailable, choose_backend, import_mujoco
from .camera import SceneCamera, camera_matrix
from .physics import PhysicsWorld
from .scene import CameraMount, Scene, look_at_axes

__all__ = ["Scene", "CameraMount", "PhysicsWorld", "SceneCamera", "camera_matrix",
           "look_at_axes", "MuJoCoUnavailable", "choose_backend", "import_mujoco"]
