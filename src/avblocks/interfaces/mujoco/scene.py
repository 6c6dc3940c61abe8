"""A MuJoCo scene built from avblocks data (or from a user's MJCF file).

A :class:`Scene` is plain data, like :class:`~avblocks.environment.World`:
agent groups, obstacles, ground and cameras. It compiles once to a MuJoCo
model shared by the blocks that use it: :class:`~.physics.PhysicsWorld`
(simulates the dynamic groups) and :class:`~.camera.SceneCamera` (renders
images of the scene from any agent poses).

Agent groups
------------
``add_ground_robots(name, pose0)``
    N planar robots (unicycle or differential drive): a cylinder body on
    three joints (slide x, slide y, hinge z about the body centre), so the
    generalized coordinates *are* ``(x, y, theta)``. They collide with
    obstacles and with each other, not with the ground (they carry no
    weight on it: the velocity loop is a body-velocity servo, see
    :mod:`.physics`).
``add_quadrotors(name, position0)``
    N free bodies (mass, diagonal inertia) with a visual airframe and,
    optionally, a camera under each (``camera=CameraMount(...)``).
    They collide with the ground and obstacles, not with ground robots.

``kinematic=True`` makes a group of MuJoCo *mocap* bodies instead: they
are not simulated by :class:`PhysicsWorld` (their poses come from other
blocks, e.g. a plain :class:`~avblocks.vehicles.Unicycle`: co-simulation)
but cameras see them at the poses wired to the camera block.

Obstacles of a World
--------------------
Polygons are extruded to prisms of height ``obstacle_height`` (split into
convex pieces by a constrained Delaunay triangulation when concave or
holed, since MuJoCo collides convex meshes); circles become cylinders.

Collision bits (contype/conaffinity): ground 2/2, ground robots 1/1,
quadrotors 2/2, obstacles 3/3, mocap bodies 0/0 (seen, never touched).

Frames: world z up. A camera looks along its own -z with x to the image
right and y to the image top (MuJoCo's convention).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...core.errors import ParameterError
from ...core.params import agent_array, limit, poses, positive_scalar
from ...vehicles.quadrotor import mixer_matrix
from ._gl import import_mujoco
from .mjcf import MJCFWriter

_NAME = "Scene"


def _rgba(color, where):
    c = np.asarray(color, dtype=float).ravel()
    if c.shape == (3,):
        c = np.append(c, 1.0)
    if c.shape != (4,) or np.any(c < 0) or np.any(c > 1):
        raise ParameterError("colour must be (r, g, b) or (r, g, b, a) in [0, 1]",
                             block=_NAME, param=where, found=color)
    return c


def look_at_axes(pos, lookat, up=(0.0, 0.0, 1.0)):
    """MuJoCo ``xyaxes`` (x right, y up) of a camera at ``pos`` looking at ``lookat``."""
    f = np.asarray(lookat, float) - np.asarray(pos, float)
    nf = np.linalg.norm(f)
    if nf < 1e-12:
        raise ParameterError("camera position and look-at point coincide",
                             block=_NAME, param="lookat", found=lookat)
    f = f / nf
    x = np.cross(f, up)
    if np.linalg.norm(x) < 1e-9:           # looking straight up or down
        x = np.cross(f, (0.0, 1.0, 0.0))
    x = x / np.linalg.norm(x)
    z = -f
    y = np.cross(z, x)
    return np.concatenate([x, y])


@dataclass(frozen=True)
class CameraMount:
    """A camera fixed to each agent of a group.

    ``pos`` in the body frame [m]; ``xyaxes`` the camera's x (image right)
    and y (image up) axes in the body frame. The default looks straight
    down from under the body, image top = body forward (+x), image right =
    body right (-y). ``fovy`` is the vertical field of view [deg].
    """

    pos: tuple = (0.0, 0.0, -0.05)
    xyaxes: tuple = (0.0, -1.0, 0.0, 1.0, 0.0, 0.0)
    fovy: float = 60.0

    def rotation(self):
        """Camera axes in the body frame: columns x, y, z (3, 3)."""
        a = np.asarray(self.xyaxes, float)
        x = a[:3] / np.linalg.norm(a[:3])
        y = a[3:] - x * np.dot(x, a[3:])
        y = y / np.linalg.norm(y)
        return np.column_stack([x, y, np.cross(x, y)])


def _mount_of(mj, m, cam):
    """The :class:`CameraMount` of camera ``cam`` of model ``m`` (its pose
    in its body's frame and its field of view)."""
    R = np.zeros(9)
    mj.mju_quat2Mat(R, m.cam_quat[cam])
    R = R.reshape(3, 3)
    return CameraMount(pos=tuple(float(v) for v in m.cam_pos[cam]),
                       xyaxes=tuple(float(v) for v in (*R[:, 0], *R[:, 1])),
                       fovy=float(m.cam_fovy[cam]))


@dataclass
class Group:
    """One agent group of a scene (see :class:`Scene`)."""

    name: str
    kind: str                   # "ground" or "quad"
    n: int
    bodies: list
    kinematic: bool = False
    params: dict = field(default_factory=dict)
    camera: CameraMount | None = None

    @property
    def camera_names(self):
        return [f"{b}_cam" for b in self.bodies] if self.camera is not None else []


#: A small scene in a scenario file's numbers (a kinematic ground robot and
#: a quadrotor with a downward camera): what the editor's palette starts the
#: physics and camera blocks with.
EXAMPLE_SCENE = {"mujoco_scene": {
    "world": {"bounds": [-5.0, -5.0, 5.0, 5.0]},
    "ground_robots": {"rover": {"pose0": [[0.0, 0.0, 0.0]], "radius": 0.25,
                            "height": 0.12, "color": [0.85, 0.05, 0.05],
                            "kinematic": True}},
    "quadrotors": {"uav": {"position0": [[0.0, 0.0, 4.0]], "arm_length": 0.25,
                           "camera": {"pos": [0.0, 0.0, -0.06], "fovy": 60.0}}}}}


class Scene(MJCFWriter):
    """Agents, obstacles, ground and cameras of a MuJoCo world.

    Parameters
    ----------
    world : environment.World, optional
        Its obstacles become walls/prisms and cylinders.
    ground : bool
        Add a ground plane (z = 0).
    ground_size : (xmin, ymin, xmax, ymax), optional
        Extent of the plane (default: the world's bounds, else +-20 m).
    texture : {"checker", None} or path
        Ground texture: a grey checker (default), plain grey, or an image
        file (PNG) stretched over the plane.
    obstacle_height : float
        Height of extruded obstacles [m] (default 1).
    timestep : float
        MuJoCo's step [s] (default 0.002).
    max_image : (width, height)
        Largest offscreen image the cameras may render (default 640x480).
    shadows : bool
        Let the sun cast shadows and the ground reflect (default False: a
        flat-lit scene renders several times faster in software GL and is
        easier to threshold; ``SceneCamera(shadows=True)`` then draws them).

    Examples
    --------
    >>> import numpy as np
    >>> from avblocks.interfaces.mujoco import Scene
    >>> s = Scene()
    >>> g = s.add_ground_robots("robots", np.zeros((2, 3)))
    >>> g.n, s.model.nq
    (2, 6)
    """

    def __init__(self, world=None, *, ground=True, ground_size=None, texture="checker",
                 obstacle_height=1.0, obstacle_color=(0.55, 0.6, 0.7), timestep=0.002,
                 max_image=(640, 480), gravity=9.81, shadows=False):
        self.world = world
        self.ground = bool(ground)
        if ground_size is None:
            b = getattr(world, "bounds", None)
            ground_size = b if b is not None else (-20.0, -20.0, 20.0, 20.0)
        gs = np.asarray(ground_size, float)
        if gs.shape != (4,) or not (gs[2] > gs[0] and gs[3] > gs[1]):
            raise ParameterError("ground_size must be (xmin, ymin, xmax, ymax)",
                                 block=_NAME, param="ground_size", found=ground_size)
        self.ground_size = gs
        if texture not in ("checker", None) and not Path(str(texture)).is_file():
            raise ParameterError("ground texture must be 'checker', None or an image file",
                                 block=_NAME, param="texture", found=texture)
        self.texture = texture
        self.obstacle_height = positive_scalar(obstacle_height, _NAME, "obstacle_height")
        self.obstacle_color = _rgba(obstacle_color, "obstacle_color")
        self.timestep = positive_scalar(timestep, _NAME, "timestep")
        self.gravity = positive_scalar(gravity, _NAME, "gravity", allow_zero=True)
        mi = tuple(int(v) for v in max_image)
        if len(mi) != 2 or min(mi) < 1:
            raise ParameterError("max_image must be (width, height)", block=_NAME,
                                 param="max_image", found=max_image)
        self.max_image = mi
        self.shadows = bool(shadows)
        self.groups: dict[str, Group] = {}
        self.fixed_cameras: dict[str, dict] = {}
        self._mjcf = None        # user MJCF text (from_mjcf)
        self._model = None

    # ------------------------------------------------------------- building
    def _new_group(self, name):
        if self._model is not None:
            raise ParameterError("the scene is compiled already; add groups first",
                                 block=_NAME, param=name)
        if not isinstance(name, str) or not name.isidentifier():
            raise ParameterError("group name must be an identifier", block=_NAME,
                                 param="name", found=name)
        if name in self.groups or name in self.fixed_cameras:
            raise ParameterError("name used twice in the scene", block=_NAME,
                                 param="name", found=name)

    def add_ground_robots(self, name, pose0, *, radius=0.2, height=0.15, mass=1.0,
                          color=(0.2, 0.4, 0.9), kind="unicycle", wheel_radius=0.05,
                          track_width=0.3, kinematic=False, marker=True):
        """N planar robots; ``kind`` "unicycle" (input ``cmd`` (v, omega)) or
        "diffdrive" (input ``wheels``, wheel angular speeds). ``marker``
        draws a white heading mark on top (leave it off for a target that a
        colour tracker must see whole). Returns the group."""
        self._new_group(name)
        p0 = poses(pose0, _NAME, "pose0")
        n = p0.shape[0]
        if kind not in ("unicycle", "diffdrive"):
            raise ParameterError("unknown ground robot kind", block=_NAME, param="kind",
                                 expected="'unicycle' or 'diffdrive'", found=kind)
        prm = {"pose0": p0,
               "radius": positive_scalar(radius, _NAME, "radius"),
               "height": positive_scalar(height, _NAME, "height"),
               "mass": agent_array(mass, n, _NAME, "mass", positive=True),
               "color": _rgba(color, "color"), "kind": kind,
               "wheel_radius": positive_scalar(wheel_radius, _NAME, "wheel_radius"),
               "track_width": positive_scalar(track_width, _NAME, "track_width"),
               "marker": bool(marker)}
        g = Group(name, "ground", n, [f"{name}{i}" for i in range(n)], bool(kinematic), prm)
        self.groups[name] = g
        return g

    def add_quadrotors(self, name, position0, *, attitude0=(1.0, 0.0, 0.0, 0.0),
                       mass=1.0, inertia=(0.01, 0.01, 0.02), arm_length=0.2,
                       frame="x", yaw_coeff=0.016, drag=0.0, input="wrench",
                       rotor_max=np.inf, thrust_max=np.inf,
                       color=(0.25, 0.25, 0.28), camera=None, kinematic=False):
        """N quadrotors with the airframe parameters of
        :class:`~avblocks.vehicles.Quadrotor`; ``camera`` a :class:`CameraMount`
        (or True for the default downward camera). ``rotor_max`` clips rotor
        thrusts (``input="rotors"``), ``thrust_max`` the collective thrust
        (``input="wrench"``), as in the model block. Returns the group."""
        self._new_group(name)
        p0 = poses(position0, _NAME, "position0", dim=3)
        n = p0.shape[0]
        q0 = agent_array(attitude0, n, _NAME, "attitude0", (4,))
        q0 = q0 / np.linalg.norm(q0, axis=1, keepdims=True)
        mixer_matrix(frame)
        if input not in ("wrench", "rotors"):
            raise ParameterError("unknown quadrotor input", block=_NAME, param="input",
                                 expected="'wrench' or 'rotors'", found=input)
        if camera is True:
            camera = CameraMount()
        if camera is not None and not isinstance(camera, CameraMount):
            raise ParameterError("camera must be a CameraMount, True or None",
                                 block=_NAME, param="camera", found=type(camera).__name__)
        prm = {"position0": p0, "attitude0": q0,
               "mass": agent_array(mass, n, _NAME, "mass", positive=True),
               "inertia": agent_array(inertia, n, _NAME, "inertia", (3,), positive=True),
               "arm_length": agent_array(arm_length, n, _NAME, "arm_length", positive=True),
               "yaw_coeff": agent_array(yaw_coeff, n, _NAME, "yaw_coeff", positive=True),
               "drag": agent_array(drag, n, _NAME, "drag", (3,), nonnegative=True),
               "rotor_max": limit(rotor_max, n, _NAME, "rotor_max"),
               "thrust_max": limit(thrust_max, n, _NAME, "thrust_max"),
               "frame": frame, "input": input, "color": _rgba(color, "color")}
        g = Group(name, "quad", n, [f"{name}{i}" for i in range(n)], bool(kinematic),
                  prm, camera)
        self.groups[name] = g
        return g

    def add_camera(self, name, pos, lookat=(0.0, 0.0, 0.0), *, fovy=45.0):
        """A fixed scene camera at ``pos`` looking at ``lookat``."""
        self._new_group(name)
        pos = np.asarray(pos, float)
        self.fixed_cameras[name] = {"pos": pos, "xyaxes": look_at_axes(pos, lookat),
                                    "fovy": positive_scalar(fovy, _NAME, "fovy")}

    @classmethod
    def from_mjcf(cls, mjcf, *, ground_robots=None, quadrotors=None, folder=None, **kw):
        """A scene from a user's MJCF (file path or XML text).

        A file is loaded from its path, so its ``<include>`` files and its
        assets (meshes, textures, ...) are found relative to it. With
        ``folder`` (a path) every file the MJCF names, through includes
        too, must lie under ``folder``, checked before MuJoCo reads
        anything (a :class:`~avblocks.core.errors.ParameterError` naming
        the file, the element and the path otherwise); a scenario file's
        ``mujoco_scene: {mjcf: ...}`` passes its own folder.

        ``ground_robots`` / ``quadrotors``: ``{group: [body names]}``. A
        ground robot body needs three joints in order: slide x, slide y,
        hinge z (world axes); a quadrotor body a free joint; a mocap body
        makes the group kinematic (a kinematic ground robot is drawn at
        its body's height in the file). Masses and inertias are the
        model's. A camera named ``<body>_cam`` on each body of a quadrotor
        group is the group's camera mount (``SceneCamera(scene, group)``;
        the first body's pose and field of view stand for all); every
        other named camera is a fixed camera. The offscreen buffer
        (``max_image``) is the file's ``<visual><global offwidth offheight>``.
        """
        s = cls(ground=False, **kw)
        is_file = Path(str(mjcf)).suffix == ".xml" and Path(str(mjcf)).is_file()
        if folder is not None:
            if not is_file:
                raise ParameterError("with 'folder' the MJCF is an .xml file's path",
                                     block=_NAME, param="mjcf", found=f"{str(mjcf):.60}")
            from ._files import check_mjcf_files
            check_mjcf_files(mjcf, folder)
        text = Path(mjcf).read_text() if is_file else str(mjcf)
        s._mjcf = text
        mj = import_mujoco()
        try:
            m = (mj.MjModel.from_xml_path(str(Path(mjcf).resolve())) if is_file
                 else mj.MjModel.from_xml_string(text))
        except Exception as e:  # noqa: BLE001 - MuJoCo's own parse error
            raise ParameterError(f"MuJoCo cannot load the MJCF: {e}", block=_NAME,
                                 param="mjcf") from None
        owned = set()       # cameras that are a group's mount
        for kind, spec in (("ground", ground_robots or {}), ("quad", quadrotors or {})):
            for gname, bodies in spec.items():
                ids = []
                for b in bodies:
                    i = mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, b)
                    if i < 0:
                        raise ParameterError("no such body in the MJCF", block=_NAME,
                                             param=gname, found=b)
                    ids.append(i)
                n = len(ids)
                kin = bool(np.all(m.body_mocapid[ids] >= 0))
                prm = {"mass": m.body_mass[ids].copy(),
                       "inertia": m.body_inertia[ids].copy()}
                mount = None
                if kind == "quad":
                    prm.update(arm_length=np.full(n, 0.2), yaw_coeff=np.full(n, 0.016),
                               drag=np.zeros((n, 3)), frame="x", input="wrench",
                               rotor_max=np.full(n, np.inf), thrust_max=np.full(n, np.inf))
                    cams = [mj.mj_name2id(m, mj.mjtObj.mjOBJ_CAMERA, f"{b}_cam")
                            for b in bodies]
                    if all(c >= 0 and m.cam_bodyid[c] == i for c, i in zip(cams, ids)):
                        mount = _mount_of(mj, m, cams[0])
                        owned.update(cams)
                else:
                    prm.update(kind="unicycle", wheel_radius=0.05, track_width=0.3)
                    if kin:         # drawn at the file's height (set_poses: z = height / 2)
                        prm["height"] = 2.0 * float(m.body_pos[ids[0], 2])
                s.groups[gname] = Group(gname, kind, n, list(bodies), kin, prm, mount)
        for c in range(m.ncam):
            name = mj.mj_id2name(m, mj.mjtObj.mjOBJ_CAMERA, c)
            if name and c not in owned:
                s.fixed_cameras[name] = {"pos": m.cam_pos[c].copy(),
                                         "fovy": float(m.cam_fovy[c])}
        s.max_image = (int(m.vis.global_.offwidth), int(m.vis.global_.offheight))
        s._model = m
        s._map()
        return s

    @property
    def model(self):
        """The compiled ``mujoco.MjModel`` (built on first use, then fixed)."""
        if self._model is None:
            mj = import_mujoco()
            self._model = mj.MjModel.from_xml_string(self.to_mjcf())
            self._map()
        return self._model

    # --------------------------------------------------------------- indices
    def _map(self):
        """Index arrays of each group into qpos / qvel / mocap."""
        mj = import_mujoco()
        m = self._model
        for g in self.groups.values():
            ids = np.array([mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, b) for b in g.bodies])
            g.body_ids = ids
            if g.kinematic:
                g.mocap_ids = m.body_mocapid[ids].copy()
                if np.any(g.mocap_ids < 0):
                    raise ParameterError("a kinematic group needs mocap bodies",
                                         block=_NAME, param=g.name)
                continue
            ja, jn = m.body_jntadr[ids], m.body_jntnum[ids]
            if g.kind == "quad":
                ok = np.all(jn == 1) and np.all(m.jnt_type[ja] == mj.mjtJoint.mjJNT_FREE)
                if not ok:
                    raise ParameterError("a quadrotor body needs one free joint",
                                         block=_NAME, param=g.name)
                g.qadr = m.jnt_qposadr[ja][:, None] + np.arange(7)
                g.vadr = m.jnt_dofadr[ja][:, None] + np.arange(6)
            else:
                jt = m.jnt_type
                ok = np.all(jn == 3)
                if ok:
                    j3 = ja[:, None] + np.arange(3)
                    ok = (np.all(jt[j3[:, :2]] == mj.mjtJoint.mjJNT_SLIDE)
                          and np.all(jt[j3[:, 2]] == mj.mjtJoint.mjJNT_HINGE)
                          and np.allclose(m.jnt_axis[j3[:, 0]], (1, 0, 0))
                          and np.allclose(m.jnt_axis[j3[:, 1]], (0, 1, 0))
                          and np.allclose(m.jnt_axis[j3[:, 2]], (0, 0, 1)))
                if not ok:
                    raise ParameterError("a ground robot body needs joints slide x, "
                                         "slide y, hinge z (in that order)",
                                         block=_NAME, param=g.name)
                g.qadr = m.jnt_qposadr[j3]
                g.vadr = m.jnt_dofadr[j3]
                g.params["izz"] = m.body_inertia[ids, 2].copy()
                g.params["mass"] = m.body_mass[ids].copy()

    @property
    def dynamic_groups(self):
        _ = self.model          # compiles, fills the index arrays
        return [g for g in self.groups.values() if not g.kinematic]

    def camera_names(self):
        """Every camera of the scene: per-agent ones, then fixed ones."""
        names = []
        for g in self.groups.values():
            names += g.camera_names
        return names + list(self.fixed_cameras)

    def set_poses(self, data, values):
        """Write agent poses into ``data``: ``values`` maps ``"group_port"`` to
        arrays (ground: ``pose`` (N, 3); quad: ``position`` (N, 3), ``attitude``
        (N, 4)); dynamic groups go to qpos, kinematic ones to mocap."""
        for g in self.groups.values():
            if g.kind == "ground":
                p = np.asarray(values[f"{g.name}_pose"], float)
                if g.kinematic:
                    h = g.params.get("height", 0.0)
                    data.mocap_pos[g.mocap_ids] = np.column_stack(
                        [p[:, :2], np.full(g.n, h / 2)])
                    half = p[:, 2] / 2
                    data.mocap_quat[g.mocap_ids] = np.column_stack(
                        [np.cos(half), np.zeros(g.n), np.zeros(g.n), np.sin(half)])
                else:
                    data.qpos[g.qadr] = p
            else:
                pos = np.asarray(values[f"{g.name}_position"], float)
                q = np.asarray(values[f"{g.name}_attitude"], float)
                if g.kinematic:
                    data.mocap_pos[g.mocap_ids] = pos
                    data.mocap_quat[g.mocap_ids] = q
                else:
                    data.qpos[g.qadr] = np.concatenate([pos, q], axis=1)

    def initial_qpos(self):
        """qpos with every dynamic group at its initial pose."""
        mj = import_mujoco()
        m = self.model
        d = mj.MjData(m)
        for g in self.dynamic_groups:
            if g.kind == "ground" and "pose0" in g.params:
                d.qpos[g.qadr] = g.params["pose0"]
            elif g.kind == "quad" and "position0" in g.params:
                d.qpos[g.qadr] = np.concatenate([g.params["position0"],
                                                 g.params["attitude0"]], axis=1)
        return d.qpos.copy()
