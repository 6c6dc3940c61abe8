""":class:`PhysicsWorld`: the dynamic agents of a :class:`Scene`, simulated
by MuJoCo in lockstep with the diagram.

How it stays a pure block
-------------------------
The MuJoCo state *is* the block's discrete state: ``qpos`` (nq,),
``qvel`` (nv,) and ``warmstart`` (nv,) (MuJoCo's constraint-solver warm
start, so a step depends on nothing but the state). At each sample hit
``update(t, x, u)``

1. writes ``x`` into a private ``MjData`` (its previous content is never
   read),
2. runs ``round(period / timestep)`` MuJoCo steps; before each, it sets
   the applied forces from the held inputs ``u`` and the current
   sub-step state (below),
3. returns copies of the new ``qpos``, ``qvel``, ``warmstart``.

``output`` reads the agents' ports from the state alone (no input is
direct feedthrough). So the state is logged like any block's, a run is
repeatable bit for bit (same state + inputs -> same next state), and the
simulator's order "outputs at t_k, updates at t_k, outputs at t_k+1"
makes the block a zero-order-hold sampled plant: inputs are held over the
period, as on a real robot's command link.

Actuation (inside the sub-steps)
--------------------------------
Ground robots (unicycle ``cmd`` = (v, omega); diff-drive ``wheels`` =
(omega_L, omega_R) mapped to (v, omega) with the robot's wheel radius and
track width) are servoed to the commanded body velocity by generalized
forces on their (x, y, theta) joints::

    F_xy   = m / tau_v (v (cos th, sin th) - (dx, dy))
    tau_th = I_zz / tau_w (omega - dth)

a first-order velocity loop with time constants ``tau_v``, ``tau_w``
(default 0.02 s; the model blocks have none, so poses differ from
:class:`~avblocks.vehicles.Unicycle` by about ``v tau_v``). Contacts with
obstacles and other robots are MuJoCo's.

Quadrotors (``wrench`` = (T, tau_x, tau_y, tau_z), or ``rotors`` through
the mixer of :mod:`avblocks.vehicles.quadrotor`, thrusts clipped at 0)
receive the force ``R (0, 0, T) - c v`` and torque ``R tau`` at their
centre of mass (world frame, ``xfrc_applied``); gravity is MuJoCo's.
MuJoCo's free-joint velocity is (world linear, body angular): exactly
the ``velocity`` and ``rates`` of :class:`~avblocks.vehicles.Quadrotor`.
"""

from __future__ import annotations

import numpy as np

from ...core.block import Block
from ...core.errors import ParameterError
from ...utility.angles import wrap_angle
from ...vehicles import quat_to_rotmat, quat_yaw
from ...vehicles.diffdrive import wheels_to_twist
from ...vehicles.quadrotor import rotors_to_wrench
from ._gl import import_mujoco
from .scene import EXAMPLE_SCENE, Scene

_NAME = "PhysicsWorld"


class PhysicsWorld(Block):
    """The dynamic agent groups of a :class:`Scene`, simulated by MuJoCo.

    Ports (one dynamic group: exactly its model block's ports; several:
    each prefixed ``<group>_``)
    -----
    Ground robots (like :class:`~avblocks.vehicles.Unicycle` /
    :class:`~avblocks.vehicles.DiffDrive`):

    cmd : in, (N, 2) [m/s, rad/s]  (kind "unicycle"), or
    wheels : in, (N, 2) [rad/s]    (kind "diffdrive")
    pose : out, (N, 3) [m, m, rad], heading in (-pi, pi]

    Quadrotors (like :class:`~avblocks.vehicles.Quadrotor`):

    wrench : in, (N, 4) [N, N m, N m, N m] or rotors : in, (N, 4) [N]
        (thrust clipped to [0, thrust_max], rotors to [0, rotor_max]; torque
        limits of the model block are not applied)
    position : out, (N, 3); velocity : out, (N, 3), world frame;
    attitude : out, (N, 4) (w, x, y, z); rates : out, (N, 3), body frame;
    pose : out, (N, 3) (x, y, yaw)

    No input is direct feedthrough.

    State
    -----
    qpos (nq,), qvel (nv,), warmstart (nv,): discrete, MuJoCo's.

    Parameters
    ----------
    scene : Scene
    period : float
        Sample period [s] = the diagram's major step normally; a whole
        number of MuJoCo timesteps (``scene.timestep``).
    tau_v, tau_w : float
        Velocity-loop time constants of ground robots [s] (>= 2 timesteps).
    prefix : bool, optional
        Force port prefixes (default: only with several dynamic groups).
    state_outputs : bool
        Also output ``qpos`` (nq,) and ``qvel`` (nv,) (not agent-indexed),
        to log MuJoCo's state with the other signals (default False: the
        ports stay exactly the model block's).

    Equations
    ---------
    See the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> from avblocks.interfaces.mujoco import Scene, PhysicsWorld
    >>> scene = Scene()
    >>> _ = scene.add_ground_robots("robots", [[0.0, 0.0, 0.0]])
    >>> b = PhysicsWorld(scene, period=0.01)
    >>> x = b.update(0.0, b.initial_state(), {"cmd": np.array([[1.0, 0.0]])}, np)
    >>> b.output(0.01, x, {}, np)["pose"].shape
    (1, 3)
    """

    #: NumPy/MuJoCo/OpenCV code: the compiled (JAX) backend refuses it by name.
    traceable = False

    #: what the editor's palette starts a new block with: a scene in numbers
    #: (a ground robot and a quadrotor), as a scenario file gives it
    example = {"scene": EXAMPLE_SCENE, "period": 0.01}

    def __init__(self, scene, period=0.01, *, tau_v=0.02, tau_w=0.02, prefix=None,
                 state_outputs=False):
        super().__init__()
        if not isinstance(scene, Scene):
            raise ParameterError("scene must be an avblocks.interfaces.mujoco.Scene",
                                 block=_NAME, param="scene", found=type(scene).__name__)
        self.mj = import_mujoco()
        self.scene = scene
        m = self.model = scene.model
        period = float(period)
        nsub = period / m.opt.timestep
        if not (np.isfinite(nsub) and nsub >= 1 and abs(nsub - round(nsub)) < 1e-6):
            raise ParameterError("period must be a whole number of MuJoCo timesteps",
                                 block=_NAME, param="period",
                                 expected=f"k * {m.opt.timestep:g} s", found=period)
        self.nsub = int(round(nsub))
        for nm, v in (("tau_v", tau_v), ("tau_w", tau_w)):
            if not (np.isfinite(v) and v >= 2 * m.opt.timestep):
                raise ParameterError("velocity-loop time constant too small for an "
                                     "explicit servo", block=_NAME, param=nm,
                                     expected=f">= {2 * m.opt.timestep:g} s", found=v)
            # numeric parameters: `--set`, Simulator.set_param("world.tau_v", ...)
            self.declare_parameter(nm, float(v), (), bounds=(2 * m.opt.timestep, None),
                                   unit="s", doc="ground-robot velocity servo time constant")
        self.groups = scene.dynamic_groups
        if not self.groups:
            raise ParameterError("the scene has no dynamic agent group", block=_NAME,
                                 param="scene", hint="add_ground_robots/add_quadrotors "
                                 "with kinematic=False")
        pre = len(self.groups) > 1 if prefix is None else bool(prefix)
        self._pn = {g.name: (f"{g.name}_" if pre else "") for g in self.groups}
        self._data = self.mj.MjData(m)
        self.declare_periodic(period)
        self.declare_discrete_state("qpos", scene.initial_qpos(), agents=False,
                                    doc="MuJoCo generalized positions")
        self.declare_discrete_state("qvel", np.zeros(m.nv), agents=False,
                                    doc="MuJoCo generalized velocities")
        self.declare_discrete_state("warmstart", np.zeros(m.nv), agents=False,
                                    doc="MuJoCo constraint solver warm start")
        quads = [g for g in self.groups if g.kind == "quad"]
        if len(self.groups) == 1 and quads:
            # the airframe attributes of vehicles.Quadrotor, so that
            # QuadrotorVelocityControl.for_quadrotor / velocity_controlled_quadrotor
            # take this block in its place
            g = quads[0]
            self.n = g.n
            for k in ("mass", "inertia", "drag", "arm_length", "yaw_coeff", "frame", "input"):
                setattr(self, k, g.params[k])
            self.gravity = float(-m.opt.gravity[2])
            self.rotor_max = g.params["rotor_max"]
            self.thrust_max = g.params["thrust_max"]
        elif len(self.groups) == 1:
            self.n = self.groups[0].n
        self.state_outputs = bool(state_outputs)
        if self.state_outputs:
            self.declare_output("qpos", (m.nq,), agents=False)
            self.declare_output("qvel", (m.nv,), agents=False)
        xyz = ("x", "y", "z")
        for g in self.groups:
            p, n = self._pn[g.name], g.n
            if g.kind == "ground":
                if g.params["kind"] == "diffdrive":
                    self.declare_input(p + "wheels", (n, 2), unit="rad/s",
                                       labels=("left", "right"), feedthrough=False)
                else:
                    self.declare_input(p + "cmd", (n, 2), unit="m/s, rad/s",
                                       labels=("v", "omega"), feedthrough=False)
                self.declare_output(p + "pose", (n, 3), unit="m, m, rad",
                                    labels=("x", "y", "theta"))
            else:
                kind = g.params["input"]
                self.declare_input(p + kind, (n, 4),
                                   unit="N, N m, N m, N m" if kind == "wrench" else "N",
                                   feedthrough=False)
                self.declare_output(p + "position", (n, 3), unit="m", labels=xyz)
                self.declare_output(p + "velocity", (n, 3), unit="m/s", labels=xyz)
                self.declare_output(p + "attitude", (n, 4), labels=("w", "x", "y", "z"))
                self.declare_output(p + "rates", (n, 3), unit="rad/s", labels=("p", "q", "r"))
                self.declare_output(p + "pose", (n, 3), unit="m, m, rad",
                                    labels=("x", "y", "yaw"))

    # ----------------------------------------------------------------- output
    def output(self, t, x, u, xp):
        qpos, qvel = x["qpos"], x["qvel"]
        y = {"qpos": qpos, "qvel": qvel} if self.state_outputs else {}
        for g in self.groups:
            p = self._pn[g.name]
            if g.kind == "ground":
                q = qpos[g.qadr]
                y[p + "pose"] = np.column_stack([q[:, 0], q[:, 1], wrap_angle(q[:, 2])])
            else:
                q = qpos[g.qadr]
                v = qvel[g.vadr]
                att = q[:, 3:] / np.linalg.norm(q[:, 3:], axis=1, keepdims=True)
                y[p + "position"] = q[:, :3]
                y[p + "velocity"] = v[:, :3]
                y[p + "attitude"] = att
                y[p + "rates"] = v[:, 3:]
                y[p + "pose"] = np.column_stack([q[:, :2], quat_yaw(att, np)])
        return y

    # ----------------------------------------------------------------- update
    def _commands(self, u):
        """Per group, the held command in model units: (v, omega) or (T, tau)."""
        out = []
        for g in self.groups:
            p, prm = self._pn[g.name], g.params
            if g.kind == "ground":
                if prm["kind"] == "diffdrive":
                    c = wheels_to_twist(np.asarray(u[p + "wheels"], float),
                                        prm["wheel_radius"], prm["track_width"])
                else:
                    c = np.asarray(u[p + "cmd"], float)
            elif prm["input"] == "rotors":
                f = np.clip(np.asarray(u[p + "rotors"], float), 0.0, prm["rotor_max"][:, None])
                c = rotors_to_wrench(f, prm["arm_length"], prm["yaw_coeff"], prm["frame"])
            else:
                c = np.asarray(u[p + "wrench"], float).copy()
                c[:, 0] = np.clip(c[:, 0], 0.0, prm["thrust_max"])
            out.append(c)
        return out

    def _apply(self, d, cmds):
        for g, c in zip(self.groups, cmds):
            prm = g.params
            if g.kind == "ground":
                th = d.qpos[g.qadr[:, 2]]
                v = d.qvel[g.vadr]
                kv = prm["mass"] / self.tau_v
                d.qfrc_applied[g.vadr[:, 0]] = kv * (c[:, 0] * np.cos(th) - v[:, 0])
                d.qfrc_applied[g.vadr[:, 1]] = kv * (c[:, 0] * np.sin(th) - v[:, 1])
                d.qfrc_applied[g.vadr[:, 2]] = prm["izz"] / self.tau_w * (c[:, 1] - v[:, 2])
            else:
                q = d.qpos[g.qadr[:, 3:]]
                R = quat_to_rotmat(q / np.linalg.norm(q, axis=1, keepdims=True))
                f = R[:, :, 2] * c[:, :1] - prm["drag"] * d.qvel[g.vadr[:, :3]]
                tau = np.einsum("nij,nj->ni", R, c[:, 1:])
                d.xfrc_applied[g.body_ids] = np.concatenate([f, tau], axis=1)

    def update(self, t, x, u, xp):
        mj, m, d = self.mj, self.model, self._data
        d.qpos[:] = x["qpos"]
        d.qvel[:] = x["qvel"]
        d.qacc_warmstart[:] = x["warmstart"]
        d.time = float(t)
        cmds = self._commands(u)
        for _ in range(self.nsub):
            self._apply(d, cmds)
            mj.mj_step(m, d)
        return {"qpos": d.qpos.copy(), "qvel": d.qvel.copy(),
                "warmstart": d.qacc_warmstart.copy()}
