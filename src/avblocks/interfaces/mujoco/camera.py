""":class:`SceneCamera`: images of a :class:`Scene` at a camera rate.

The camera block renders from agent *poses wired to it*, not from the
physics block's state: so it shows a scene whose agents come from a
:class:`PhysicsWorld`, from plain model blocks (``vehicles.Unicycle``,
``vehicles.Quadrotor``) or from both at once (co-simulation), and it
renders the same picture for the same poses whichever block made them.
It is periodic (``period`` = the camera rate), so rendering happens only
at its sample hits, never inside solver stages; the image is held between
hits.

Pixel convention (used by :func:`camera_matrix` and
:mod:`avblocks.interfaces.vision`): ``u`` = column index, ``v`` = row index
(row 0 at the top), pixel centres at integers. With vertical field of view
``fovy`` and an image of W x H::

    f = (H / 2) / tan(fovy / 2),   K = [[f, 0, (W - 1) / 2],
                                        [0, f, (H - 1) / 2],
                                        [0, 0, 1]]

in the OpenCV camera frame (x right, y down, z forward) = MuJoCo's camera
frame (x right, y up, looking along -z) times diag(1, -1, -1).
"""

from __future__ import annotations

import numpy as np

from ...core.block import Block
from ...core.errors import ParameterError
from ._gl import import_mujoco
from .scene import EXAMPLE_SCENE, Scene

_NAME = "SceneCamera"

#: MuJoCo camera axes -> OpenCV camera axes.
MJ_TO_CV = np.diag([1.0, -1.0, -1.0])


def camera_matrix(fovy_deg, width, height):
    """Intrinsic matrix K (3, 3) of a MuJoCo camera (see the module docstring)."""
    f = 0.5 * height / np.tan(np.deg2rad(fovy_deg) / 2)
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2],
                     [0.0, 0.0, 1.0]])


class SceneCamera(Block):
    """Renders C cameras of a :class:`Scene` into ``image`` (C, H, W, 3) uint8.

    Ports
    -----
    <group>_pose : in, (N, 3)
        For each ground-robot group of the scene (dynamic or kinematic).
    <group>_position : in, (N, 3); <group>_attitude : in, (N, 4)
        For each quadrotor group.
    image : out, (C, H, W, 3) uint8
        RGB, row 0 at the top. With ``cameras=<group>`` the leading axis is
        the group's agent axis (one camera per agent).

    Parameters
    ----------
    scene : Scene
    cameras : str or list of str
        A group name (its per-agent cameras), a fixed camera's name, or a
        list of camera names (``scene.camera_names()``).
    width, height : int
        Image size [px] (at most the scene's ``max_image``; keep
        ``max_image`` at the largest camera's size: with software GL each
        render costs in proportion to the whole offscreen buffer, 3x for a
        160x120 image in a 640x480 buffer).
    period, offset : float
        Camera sample time [s] (a multiple of the diagram's step).
    shadows, reflections : bool
        MuJoCo's shadow and reflection passes (off by default: ~8x faster
        with software GL, and a flat-shaded image is easier to threshold).

    Attributes
    ----------
    camera_names : list of str
    fovy : (C,) vertical fields of view [deg]
    K : (C, 3, 3) intrinsic matrices (:meth:`camera_matrix`).
    """

    #: NumPy/MuJoCo/OpenCV code: the compiled (JAX) backend refuses it by name.
    traceable = False

    #: what the editor's palette starts a new block with: the quadrotor's
    #: downward camera of a scene in numbers
    example = {"scene": EXAMPLE_SCENE,
               "cameras": "uav", "width": 160, "height": 120, "period": 0.1}

    def __init__(self, scene, cameras, *, width=320, height=240, period=0.1,
                 offset=0.0, shadows=False, reflections=False):
        super().__init__()
        if not isinstance(scene, Scene):
            raise ParameterError("scene must be an avblocks.interfaces.mujoco.Scene",
                                 block=_NAME, param="scene", found=type(scene).__name__)
        self.mj = import_mujoco(render=True)
        self.scene = scene
        m = self.model = scene.model
        allc = scene.camera_names()
        if isinstance(cameras, str):
            if cameras in scene.groups:
                names = scene.groups[cameras].camera_names
                if not names:
                    raise ParameterError("this group has no cameras", block=_NAME,
                                         param="cameras", found=cameras,
                                         hint="add_quadrotors(..., camera=CameraMount())")
            else:
                names = [cameras]
        else:
            names = list(cameras)
        bad = [c for c in names if c not in allc]
        if bad or not names:
            raise ParameterError("unknown camera", block=_NAME, param="cameras",
                                 expected=f"a group with cameras or one of {allc}",
                                 found=bad or cameras)
        self.camera_names = names
        self.width, self.height = int(width), int(height)
        mw, mh = scene.max_image
        if not (0 < self.width <= mw and 0 < self.height <= mh):
            raise ParameterError("image size outside the scene's offscreen buffer",
                                 block=_NAME, param="width, height",
                                 expected=f"<= {mw} x {mh} (Scene(max_image=...))",
                                 found=(width, height))
        self.cam_ids = np.array([self.mj.mj_name2id(m, self.mj.mjtObj.mjOBJ_CAMERA, c)
                                 for c in names])
        self.fovy = m.cam_fovy[self.cam_ids].copy()
        self.K = np.stack([camera_matrix(f, self.width, self.height) for f in self.fovy])
        self.shadows, self.reflections = bool(shadows), bool(reflections)
        self._renderer = None
        self._data = None
        self.declare_periodic(period, offset)
        for g in scene.groups.values():
            if g.kind == "ground":
                self.declare_input(f"{g.name}_pose", (g.n, 3), unit="m, m, rad")
            else:
                self.declare_input(f"{g.name}_position", (g.n, 3), unit="m")
                self.declare_input(f"{g.name}_attitude", (g.n, 4))
        self.declare_output("image", (len(names), self.height, self.width, 3), "uint8",
                            doc="RGB images, row 0 at the top")

    def camera_matrix(self, i=0):
        """Intrinsic matrix K (3, 3) of camera ``i``."""
        return self.K[i].copy()

    def _ensure(self):
        if self._renderer is None:
            mj = self.mj
            self._data = mj.MjData(self.model)
            try:
                r = mj.Renderer(self.model, self.height, self.width)
            except Exception as e:  # noqa: BLE001 - GL start failures vary by platform
                from ._gl import INSTALL_HINT, MuJoCoUnavailable
                raise MuJoCoUnavailable(
                    f"MuJoCo cannot open an offscreen OpenGL context ({e})",
                    block=_NAME,
                    hint="if you imported mujoco before avblocks, set MUJOCO_GL=egl or "
                         "MUJOCO_GL=osmesa before that import; else " + INSTALL_HINT
                ) from None
            r.scene.flags[mj.mjtRndFlag.mjRND_SHADOW] = self.shadows
            r.scene.flags[mj.mjtRndFlag.mjRND_REFLECTION] = self.reflections
            self._renderer = r
        return self._renderer, self._data

    def pose_data(self, u):
        """An MjData with the wired poses set and kinematics computed."""
        r, d = self._ensure()
        self.scene.set_poses(d, u)
        self.mj.mj_kinematics(self.model, d)
        self.mj.mj_camlight(self.model, d)
        return d

    def render(self, u):
        """Images (C, H, W, 3) for the poses in ``u`` (the block's inputs)."""
        d = self.pose_data(u)
        r = self._renderer
        out = np.empty((len(self.cam_ids), self.height, self.width, 3), np.uint8)
        for k, cid in enumerate(self.cam_ids):
            r.update_scene(d, camera=int(cid))
            r.render(out=out[k])
        return out

    def camera_poses(self, u):
        """World positions (C, 3) and OpenCV-frame rotations (C, 3, 3)
        (columns: camera x right, y down, z forward in the world) for ``u``."""
        d = self.pose_data(u)
        pos = d.cam_xpos[self.cam_ids].copy()
        R = d.cam_xmat[self.cam_ids].reshape(-1, 3, 3) @ MJ_TO_CV
        return pos, R

    def output(self, t, x, u, xp):
        return {"image": self.render(u)}

    def on_stop(self):
        if self._renderer is not None:
            try:
                self._renderer.close()
            except Exception:  # noqa: BLE001 - some GL backends fail to free
                pass
            self._renderer = None
