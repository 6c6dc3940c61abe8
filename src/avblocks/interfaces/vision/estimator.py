""":class:`GroundPointEstimator`: a tracked pixel -> the point on the ground.

Equations
---------
With the carrier's position ``p`` and attitude ``q`` (body -> world), a
camera mounted at ``m`` (body frame) with axes ``M`` (MuJoCo convention,
columns x right, y up, z backwards)::

    c = p + R(q) m,    R_cam = R(q) M diag(1, -1, -1)     (OpenCV axes)
    point = c + s d,   d = R_cam K^-1 (u, v, 1)^T,  s = (z0 - c_z) / d_z

``valid`` is ``found and s > 0``; where not valid the point holds its last
valid value (a discrete state), so a controller reading it keeps going to
where the target was last seen.
"""

from __future__ import annotations

import numpy as np

from ...core.block import Block
from ...core.errors import ParameterError
from .pinhole import _K, camera_pose, pixel_to_ground

_NAME = "GroundPointEstimator"


class GroundPointEstimator(Block):
    """Ground point seen at a pixel by a camera carried by each of N agents.

    Ports
    -----
    centroid : in, (N, 2) [px]
    found : in, (N,) bool
    position : in, (N, 3) [m]; attitude : in, (N, 4) (w, x, y, z)
        The carrier's pose (wire from a Quadrotor or PhysicsWorld).
    point : out, (N, 3) [m], the last valid estimate (initially ``point0``)
    valid : out, (N,) bool, this sample's estimate is fresh

    State
    -----
    last : discrete (N, 3), the last valid estimate.

    Parameters
    ----------
    n : int
    K : (3, 3)
        Camera intrinsics (``SceneCamera.camera_matrix()``).
    mount_pos : (3,), mount_rot : (3, 3)
        Camera position and axes in the body frame
        (``CameraMount.pos``, ``CameraMount.rotation()``).
    z0 : float
        Height of the plane the tracked point lies on [m] (the target's
        centre height).
    point0 : (3,) or (N, 3)
        Estimate before the first detection (default: below the carrier's
        start is unknown, so the origin).

    The sample time is inherited (the tracker's, i.e. the camera's).
    """

    #: NumPy/MuJoCo/OpenCV code: the compiled (JAX) backend refuses it by name.
    traceable = False

    update_uses_outputs = True

    #: what the editor's palette starts a new block with: a downward camera
    #: of 160 x 120 pixels and 60 degrees under the body
    example = {"n": 1, "K": {"camera_matrix": {"fovy": 60.0, "width": 160, "height": 120}},
               "mount_pos": [0.0, 0.0, -0.06], "mount_rot": {"camera_axes": {}}}

    def __init__(self, n, K, mount_pos, mount_rot, *, z0=0.0, point0=(0.0, 0.0, 0.0)):
        super().__init__()
        self.n = n = int(n)
        self.K = _K(K).copy()
        self.mount_pos = np.asarray(mount_pos, float)
        self.mount_rot = np.asarray(mount_rot, float)
        if self.mount_pos.shape != (3,) or self.mount_rot.shape != (3, 3):
            raise ParameterError("mount_pos must be (3,) and mount_rot (3, 3)", block=_NAME,
                                 param="mount_pos, mount_rot",
                                 found=(self.mount_pos.shape, self.mount_rot.shape))
        self.z0 = float(z0)
        p0 = np.broadcast_to(np.asarray(point0, float), (n, 3)).copy()
        self.declare_inherited()
        self.declare_input("centroid", (n, 2), unit="px")
        self.declare_input("found", (n,), "bool")
        self.declare_input("position", (n, 3), unit="m")
        self.declare_input("attitude", (n, 4))
        self.declare_discrete_state("last", p0, unit="m")
        self.declare_output("point", (n, 3), unit="m", labels=("x", "y", "z"))
        self.declare_output("valid", (n,), "bool")

    def estimate(self, u):
        c, R = camera_pose(u["position"], u["attitude"], self.mount_pos, self.mount_rot)
        p, ok = pixel_to_ground(u["centroid"], self.K, c, R, self.z0)
        ok = ok & np.asarray(u["found"], bool)
        return p, ok

    def output(self, t, x, u, xp):
        p, ok = self.estimate(u)
        return {"point": np.where(ok[:, None], p, x["last"]), "valid": ok}

    def update(self, t, x, u, xp, y):
        return {"last": y["point"]}
