"""Quadrotor: 6-DoF rigid body with four rotors, vectorized over agents.

Frames: world z up (ENU), body x forward, y left, z up; thrust acts along
body +z. Attitude ``q = (w, x, y, z)`` rotates body vectors into the world.

Equations
---------
::

    dp/dt     = v
    m dv/dt   = R(q) (0, 0, T) - m g e_z - c v
    dq/dt     = 1/2 q * (0, omega) + k_q (1 - |q|^2) q
    J domega/dt = tau - omega x (J omega)

with collective thrust T [N], body torques tau [N m], diagonal inertia
``J = diag(Jx, Jy, Jz)``, linear drag c [N s/m] (world frame, per axis).
The quaternion is kept normalized in two ways: the derivative carries the
stabilizing term ``k_q (1 - |q|^2) q`` (zero on the unit sphere; it pulls
the norm back, ``d|q|^2/dt = 2 k_q (1 - |q|^2) |q|^2``), and the
``attitude`` output and the rotation used in the dynamics are computed
from ``q / |q|``.

Rotor mixer (``input="rotors"``): rotor i sits at angle a_i in the body xy
plane at distance l (arm length) and spins with sign s_i; its thrust f_i
gives::

    T = sum f_i,  tau_x = l sum sin(a_i) f_i,  tau_y = -l sum cos(a_i) f_i,
    tau_z = k_m sum s_i f_i

``"+"`` frame: a = (0, 90, 180, 270) deg (front, left, back, right);
``"x"`` frame: a = (45, 135, 225, 315) deg (front-left, back-left,
back-right, front-right). In both, s = (-1, +1, -1, +1): rotors 1 and 3
spin counter-clockwise seen from above (reaction torque -z), 2 and 4
clockwise. Body axes: x forward, y left, z up.

Real airframes number their motors differently; name them to use their
order directly (rotor i of ``f`` is that airframe's motor i):

* ``"crazyflie"`` (Bitcraze Crazyflie 2.x): M1 front-right, M2 back-right,
  M3 back-left, M4 front-left, a = (315, 225, 135, 45) deg; M1 and M3
  counter-clockwise, M2 and M4 clockwise, s = (-1, +1, -1, +1).
* ``"px4"`` (PX4 "Generic Quadrotor x"): 1 front-right, 2 back-left,
  3 front-left, 4 back-right, a = (315, 135, 45, 225) deg; 1 and 2
  counter-clockwise, 3 and 4 clockwise, s = (-1, -1, +1, +1).

Rotor thrusts are clipped to ``[0, rotor_max]``.

References
----------
R. Mahony, V. Kumar, P. Corke, "Multirotor aerial vehicles: modeling,
estimation, and control of quadrotor", IEEE Robotics & Automation Magazine
19(3), 2012 (model, mixer); T. Lee, M. Leok, N. H. McClamroch, "Geometric
tracking control of a quadrotor UAV on SE(3)", CDC 2010 (attitude error
used by :class:`QuadrotorVelocityControl`); J. Sola (2017), quaternion
kinematics.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import agent_array, poses, positive_scalar
from ._common import any_finite, limit
from ._rotations import (
    cross,
    quat_derivative,
    quat_normalize,
    quat_rotate,
    quat_yaw,
)

_ANGLES = {"+": np.deg2rad([0.0, 90.0, 180.0, 270.0]),
           "x": np.deg2rad([45.0, 135.0, 225.0, 315.0]),
           # Bitcraze Crazyflie 2.x: M1 front-right, M2 back-right, M3 back-left,
           # M4 front-left; M1 and M3 counter-clockwise, M2 and M4 clockwise
           "crazyflie": np.deg2rad([315.0, 225.0, 135.0, 45.0]),
           # PX4 "Generic Quadrotor x": 1 front-right, 2 back-left, 3 front-left,
           # 4 back-right; 1 and 2 counter-clockwise, 3 and 4 clockwise
           "px4": np.deg2rad([315.0, 135.0, 45.0, 225.0])}
# s_i: -1 counter-clockwise seen from above (reaction torque -z), +1 clockwise
_SPINS = {"+": np.array([-1.0, 1.0, -1.0, 1.0]),
          "x": np.array([-1.0, 1.0, -1.0, 1.0]),
          "crazyflie": np.array([-1.0, 1.0, -1.0, 1.0]),
          "px4": np.array([-1.0, -1.0, 1.0, 1.0])}
_SPIN = _SPINS["x"]


def _unit_mixer(frame):
    a = _ANGLES[frame]
    b = np.stack([np.ones(4), np.round(np.sin(a), 15), -np.round(np.cos(a), 15),
                  _SPINS[frame]])
    inv = np.linalg.inv(b)
    mats = (b, np.where(np.abs(inv) < 1e-12, 0.0, inv))
    for m in mats:
        m.flags.writeable = False
    return mats


_MIXERS = {f: _unit_mixer(f) for f in _ANGLES}


def rotor_angles(frame="x"):
    """Azimuth of each rotor arm in the body frame (rad, from +x towards +y),
    in motor order, for ``frame`` ``"+"``, ``"x"``, ``"crazyflie"`` or
    ``"px4"`` (a copy)."""
    if frame not in _ANGLES:
        raise ParameterError("unknown frame", param="frame", expected=sorted(_ANGLES),
                             found=frame)
    return _ANGLES[frame].copy()


def mixer_matrix(frame="x"):
    """The 4x4 unit mixer B: ``(T, tau_x/l, tau_y/l, tau_z/k_m) = B f`` (read-only)."""
    if frame not in _MIXERS:
        raise ParameterError("unknown rotor frame", block="Quadrotor", param="frame",
                             expected=f"one of {sorted(_MIXERS)}", found=frame)
    return _MIXERS[frame][0]


def _apply(mat, cols, xp):
    """``mat @ cols`` for a constant 4x4 ``mat`` and 4 (N,) columns, written
    out (skipping zeros): no BLAS call, whose threads spin on a busy machine
    and make a (N, 4) x (4, 4) product slower than this."""
    rows = []
    for j in range(4):
        acc = None
        for i in range(4):
            c = float(mat[j, i])
            if abs(c) < 1e-15:
                continue
            term = cols[i] if c == 1.0 else (-cols[i] if c == -1.0 else c * cols[i])
            acc = term if acc is None else acc + term
        rows.append(acc if acc is not None else 0.0 * cols[0])
    return rows


def rotors_to_wrench(f, arm_length, yaw_coeff, frame="x", xp=np):
    """Rotor thrusts (N, 4) -> (T, tau_x, tau_y, tau_z) (N, 4)."""
    b = mixer_matrix(frame)
    t, sx, sy, sz = _apply(b, [f[:, i] for i in range(4)], xp)
    return xp.stack([t, arm_length * sx, arm_length * sy, yaw_coeff * sz], axis=-1)


def wrench_to_rotors(w, arm_length, yaw_coeff, frame="x", xp=np):
    """(T, tau_x, tau_y, tau_z) (N, 4) -> rotor thrusts (N, 4) (exact inverse)."""
    mixer_matrix(frame)
    cols = [w[:, 0], w[:, 1] / arm_length, w[:, 2] / arm_length, w[:, 3] / yaw_coeff]
    return xp.stack(_apply(_MIXERS[frame][1], cols, xp), axis=-1)


def quadrotor_rhs(vel, q, rates, thrust, torque, mass, inertia, gravity=9.81,
                  drag=0.0, quat_gain=1.0, xp=np):
    """Derivatives of N quadrotors.

    ``vel`` (N, 3), ``q`` (N, 4), ``rates`` (N, 3), ``thrust`` (N,),
    ``torque`` (N, 3), ``mass`` (N,), ``inertia`` (N, 3), ``drag`` (N, 3)
    or scalar. Returns ``(dp, dv, dq, domega)``.
    """
    qn = quat_normalize(q, xp)
    zero = xp.zeros_like(thrust)
    f_world = quat_rotate(qn, xp.stack([zero, zero, thrust], axis=-1), xp)
    acc = (f_world - drag * vel) / mass[:, None]
    acc = acc - xp.stack([zero, zero, zero + gravity], axis=-1)
    dq = quat_derivative(q, rates, quat_gain, xp)
    dw = (torque - cross(rates, inertia * rates, xp)) / inertia
    return vel, acc, dq, dw


def _set_airframe(blk, name, n, mass, inertia, drag, frame, arm_length, yaw_coeff):
    """Validate and set the physical parameters both quadrotor blocks share."""
    dp = blk.declare_parameter
    dp("mass", agent_array(mass, n, name, "mass", positive=True), bounds=(1e-12, None),
       unit="kg")
    dp("inertia", agent_array(inertia, n, name, "inertia", (3,), positive=True),
       bounds=(1e-12, None), unit="kg m^2")
    dp("drag", agent_array(drag, n, name, "drag", (3,), nonnegative=True),
       bounds=(0, None), unit="N s/m")
    mixer_matrix(frame)                       # raises for an unknown frame
    blk.frame = frame
    dp("arm_length", agent_array(arm_length, n, name, "arm_length", positive=True),
       bounds=(1e-12, None), unit="m")
    dp("yaw_coeff", agent_array(yaw_coeff, n, name, "yaw_coeff", positive=True),
       bounds=(1e-12, None), unit="m")


def _kind(value, name, param):
    """``'wrench'`` or ``'rotors'``, else a ParameterError."""
    if value not in ("wrench", "rotors"):
        raise ParameterError(f"unknown {param} kind", block=name, param=param,
                             expected="'wrench' or 'rotors'", found=value)
    return value


class Quadrotor(Block):
    """N quadrotors (6-DoF rigid bodies) in one block.

    Ports
    -----
    wrench : in, (N, 4) [N, N m, N m, N m]
        Collective thrust T and body torques (``input="wrench"``), or
    rotors : in, (N, 4) [N]
        Four rotor thrusts through the mixer (``input="rotors"``).
        Neither is direct feedthrough.
    position : out, (N, 3) [m]
    velocity : out, (N, 3) [m/s], world frame
    attitude : out, (N, 4), unit quaternion (w, x, y, z), body -> world
    rates : out, (N, 3) [rad/s], body angular velocity
    pose : out, (N, 3) [m, m, rad], (x, y, yaw) for 2D views and controllers

    State
    -----
    position, velocity, attitude (N, 4; normalized softly, see module
    docstring), rates: continuous.

    Parameters
    ----------
    position0 : array_like, (N, 3)
    velocity0, rates0 : array_like, (3,) or (N, 3), optional (default 0)
    attitude0 : array_like, (4,) or (N, 4), optional (default identity)
    mass : float or (N,)
        [kg], default 1.
    inertia : array_like, (3,) or (N, 3)
        Diagonal inertia [kg m^2], default (0.01, 0.01, 0.02).
    gravity : float
        [m/s^2], default 9.81.
    input : {"wrench", "rotors"}
    frame : {"x", "+", "crazyflie", "px4"}
        Rotor layout and motor order (``input="rotors"``; see the module notes).
    arm_length : float or (N,)
        Rotor distance from the centre l [m], default 0.2.
    yaw_coeff : float or (N,)
        Rotor drag-torque to thrust ratio k_m [m], default 0.016.
    rotor_max : float or (N,)
        Rotor thrust limit [N] (default: none; thrusts are always >= 0).
    thrust_max : float or (N,)
        Collective thrust limit with ``input="wrench"`` (T clipped to
        [0, thrust_max]).
    torque_max : float, (3,) or (N, 3)
        Body torque limits with ``input="wrench"``.
    drag : float, (3,) or (N, 3)
        Linear drag c [N s/m] along the world axes (default 0).
    quat_gain : float
        k_q [1/s], quaternion norm stabilization (default 1).

    Numeric parameters
    ------------------

    Numeric parameters (per agent, N leading): ``mass``, ``inertia``,
    ``drag``, ``arm_length``, ``yaw_coeff``, ``rotor_max``, ``thrust_max``,
    ``torque_max``; scalars ``gravity`` and ``quat_gain``. ``input`` and
    ``frame`` are structural.

    Equations
    ---------
    See the module docstring.

    References
    ----------
    Mahony, Kumar & Corke (2012).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.Quadrotor(np.zeros((1, 3)), mass=1.0)
    >>> hover = np.array([[9.81, 0.0, 0.0, 0.0]])
    >>> b.derivative(0, b.initial_state(), {"wrench": hover}, np)["velocity"]
    array([[0., 0., 0.]])
    """

    def __init__(self, position0, *, velocity0=0.0, attitude0=(1.0, 0.0, 0.0, 0.0),
                 rates0=0.0, mass=1.0, inertia=(0.01, 0.01, 0.02), gravity=9.81,
                 input="wrench", frame="x", arm_length=0.2, yaw_coeff=0.016,
                 rotor_max=np.inf, thrust_max=np.inf, torque_max=np.inf, drag=0.0,
                 quat_gain=1.0):
        super().__init__()
        name = "Quadrotor"
        p0 = poses(position0, name, "position0", dim=3)
        self.n = n = p0.shape[0]
        v0 = agent_array(velocity0, n, name, "velocity0", (3,))
        w0 = agent_array(rates0, n, name, "rates0", (3,))
        q0 = agent_array(attitude0, n, name, "attitude0", (4,))
        nq = np.linalg.norm(q0, axis=1)
        if np.any(nq < 1e-9):
            raise ParameterError("attitude quaternion must be nonzero", block=name,
                                 param="attitude0", found="a zero quaternion")
        q0 = q0 / nq[:, None]
        _set_airframe(self, name, n, mass, inertia, drag, frame, arm_length, yaw_coeff)
        dp = self.declare_parameter
        dp("gravity", positive_scalar(gravity, name, "gravity", allow_zero=True),
           bounds=(0, None), unit="m/s^2")
        self.input = _kind(input, name, "input")
        dp("rotor_max", limit(rotor_max, n, name, "rotor_max"), bounds=(0, None),
           allow_inf=True, unit="N")
        dp("thrust_max", limit(thrust_max, n, name, "thrust_max"), bounds=(0, None),
           allow_inf=True, unit="N")
        dp("torque_max", limit(torque_max, n, name, "torque_max", (3,)), bounds=(0, None),
           allow_inf=True, unit="N m")
        dp("quat_gain", positive_scalar(quat_gain, name, "quat_gain", allow_zero=True),
           bounds=(0, None), unit="1/s")
        xyz = ("x", "y", "z")
        self.declare_continuous_state("position", p0, unit="m", labels=xyz)
        self.declare_continuous_state("velocity", v0, unit="m/s", labels=xyz)
        self.declare_continuous_state("attitude", q0, labels=("w", "x", "y", "z"))
        self.declare_continuous_state("rates", w0, unit="rad/s", labels=("p", "q", "r"))
        if input == "wrench":
            self.declare_input("wrench", (n, 4), unit="N, N m, N m, N m",
                               labels=("T", "tau_x", "tau_y", "tau_z"),
                               doc="collective thrust and body torques", feedthrough=False)
        else:
            self.declare_input("rotors", (n, 4), unit="N", labels=("f1", "f2", "f3", "f4"),
                               doc=f"rotor thrusts, '{frame}' frame", feedthrough=False)
        self.declare_output("position", (n, 3), unit="m", labels=xyz)
        self.declare_output("velocity", (n, 3), unit="m/s", labels=xyz, doc="world frame")
        self.declare_output("attitude", (n, 4), labels=("w", "x", "y", "z"),
                            doc="unit quaternion, body -> world")
        self.declare_output("rates", (n, 3), unit="rad/s", labels=("p", "q", "r"),
                            doc="body angular velocity")
        self.declare_output("pose", (n, 3), unit="m, m, rad", labels=("x", "y", "yaw"),
                            doc="planar pose (x, y, yaw)")

    def output(self, t, x, u, xp):
        p = x["position"]
        q = quat_normalize(x["attitude"], xp)
        yaw = quat_yaw(q, xp)
        return {"position": p, "velocity": x["velocity"], "attitude": q,
                "rates": x["rates"],
                "pose": xp.concatenate([p[:, :2], yaw[:, None]], axis=-1)}

    def wrench(self, u, xp=np):
        """Saturated (T, tau) (N, 4) from the input dict."""
        if self.input == "rotors":
            f = u["rotors"]
            if self.param_flag("rlim", xp, any_finite, "rotor_max"):
                f = xp.clip(f, 0.0, self.rotor_max[:, None])
            else:
                f = xp.maximum(f, 0.0)
            return rotors_to_wrench(f, self.arm_length, self.yaw_coeff, self.frame, xp)
        w = u["wrench"]
        if self.param_flag("tlim", xp, any_finite, "thrust_max", "torque_max"):
            lo = xp.concatenate([xp.zeros((self.n, 1)), -self.torque_max], axis=-1)
            hi = xp.concatenate([self.thrust_max[:, None], self.torque_max], axis=-1)
            w = xp.clip(w, lo, hi)
        return w

    def derivative(self, t, x, u, xp):
        w = self.wrench(u, xp)
        dp, dv, dq, dw = quadrotor_rhs(x["velocity"], x["attitude"], x["rates"],
                                       w[:, 0], w[:, 1:], self.mass, self.inertia,
                                       self.gravity,
                                       self.drag if self.param_flag("drag", xp, np.any,
                                                                    "drag") else 0.0,
                                       self.quat_gain, xp)
        return {"position": dp, "velocity": dv, "attitude": dq, "rates": dw}
