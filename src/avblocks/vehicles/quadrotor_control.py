"""Velocity control for quadrotors: a cascaded velocity -> attitude -> rate
controller (:class:`QuadrotorVelocityControl`) and
:func:`velocity_controlled_quadrotor`, the subsystem that makes a
:class:`~avblocks.vehicles.Quadrotor` a holonomic agent taking velocity
commands, and :class:`VelocityControlledQuadrotor`, the same subsystem as a
class that a scenario file names (``type: vehicles.VelocityControlledQuadrotor``)."""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.diagram import Diagram
from ..core.errors import ParameterError
from ..core.params import agent_array, positive_scalar
from ._common import limit
from ._rotations import (
    cross,
    dot,
    quat_normalize,
    quat_to_rotmat,
    vee,
)
from .quadrotor import _kind, _set_airframe, wrench_to_rotors


class QuadrotorVelocityControl(Block):
    """Cascaded velocity -> attitude -> rate controller for N quadrotors.

    With a :class:`Quadrotor` it makes a holonomic agent with the same
    ``velocity`` set-point input as a 3D :class:`SingleIntegrator` (see
    :func:`velocity_controlled_quadrotor`), so controllers written for
    holonomic agents fly quadrotors unchanged.

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        Velocity set-point (world frame).
    measured_velocity : in, (N, 3) [m/s]
    attitude : in, (N, 4)
    rates : in, (N, 3) [rad/s]
        Quadrotor state feedback (wire from the Quadrotor's outputs).
    wrench : out, (N, 4) (``output="wrench"``) or rotors : out, (N, 4).

    Parameters
    ----------
    n : int
    mass, inertia, gravity, drag, frame, arm_length, yaw_coeff :
        The vehicle's parameters (see :meth:`for_quadrotor`).
    output : {"wrench", "rotors"}
    kv : float
        Velocity gain [1/s] (default 2.5).
    k_att : float
        Attitude gain [1/s]: rate set-point per radian of error (default 8).
    k_rate : float
        Rate-loop gain [1/s] (default 25).
    tilt_max : float
        Largest commanded tilt [rad] (default 0.5).
    rate_max : float
        Largest commanded body rate [rad/s] (default 6).
    yaw : float or (N,)
        Yaw set-point [rad] (default 0).
    rotor_max, thrust_max : float or (N,)
        Actuator limits.

    Numeric parameters
    ------------------

    Every value above except ``n``, ``output`` and ``frame`` (structural) is
    a numeric parameter (``"ctrl.kv"``...; per-agent ones of shape (N,) or
    (N, 3)). :meth:`for_quadrotor` copies the vehicle's values once.

    Equations
    ---------
    Velocity loop (desired force, drag feed-forward, tilt limited)::

        a = kv (v_ref - v) + c v / m,  a_xy scaled to |a_xy| <= g tan(tilt_max),
        a_z >= -0.8 g,  F = m (a + g e_z),  T = F . R e_z
    Attitude loop (Lee et al. 2010): ``b3d = F/|F|``, ``b1d`` from the yaw
    set-point, ``R_d = [b1d, b2d, b3d]``, ``e_R = 1/2 vee(R_d^T R - R^T R_d)``,
    ``omega_d = -k_att e_R`` (clipped to rate_max).
    Rate loop: ``tau = J k_rate (omega_d - omega) + omega x J omega``.

    Performance: with the default gains and a 1 kg, J = (0.01, 0.01, 0.02)
    vehicle, starting from hover, a 1 m/s horizontal velocity step settles to
    within 2 % in 1.08 s, a vertical one in 1.57 s (first order with time
    constant 1/kv: ln(50)/kv), measured with RK4 at dt = 5 ms in
    ``tests/vehicles/test_quadrotor.py``. Yaw stays within 0.03 rad of its
    set-point during a diagonal step.

    References
    ----------
    Lee, Leok & McClamroch (2010); Mahony, Kumar & Corke (2012), Section V.
    """

    def __init__(self, n, *, mass=1.0, inertia=(0.01, 0.01, 0.02), gravity=9.81,
                 drag=0.0, output="wrench", frame="x", arm_length=0.2,
                 yaw_coeff=0.016, kv=2.5, k_att=8.0, k_rate=25.0, tilt_max=0.5,
                 rate_max=6.0, yaw=0.0, rotor_max=np.inf, thrust_max=np.inf):
        super().__init__()
        name = "QuadrotorVelocityControl"
        self.n = n = int(n)
        _set_airframe(self, name, n, mass, inertia, drag, frame, arm_length, yaw_coeff)
        dp = self.declare_parameter
        dp("gravity", positive_scalar(gravity, name, "gravity"), bounds=(1e-12, None),
           unit="m/s^2")
        self.out_kind = _kind(output, name, "output")
        dp("kv", positive_scalar(kv, name, "kv"), bounds=(1e-12, None), unit="1/s")
        dp("k_att", positive_scalar(k_att, name, "k_att"), bounds=(1e-12, None),
           unit="1/s")
        dp("k_rate", positive_scalar(k_rate, name, "k_rate"), bounds=(1e-12, None),
           unit="1/s")
        tilt = positive_scalar(tilt_max, name, "tilt_max")
        if tilt >= np.pi / 2:
            raise ParameterError("tilt limit must be below pi/2", block=name,
                                 param="tilt_max", expected="< pi/2", found=tilt_max)
        dp("tilt_max", tilt, bounds=(1e-12, np.pi / 2 - 1e-9), unit="rad")
        dp("rate_max", positive_scalar(rate_max, name, "rate_max", allow_inf=True),
           bounds=(1e-12, None), allow_inf=True, unit="rad/s")
        dp("yaw", agent_array(yaw, n, name, "yaw"), unit="rad")
        dp("rotor_max", limit(rotor_max, n, name, "rotor_max"), bounds=(0, None),
           allow_inf=True, unit="N")
        dp("thrust_max", limit(thrust_max, n, name, "thrust_max"), bounds=(0, None),
           allow_inf=True, unit="N")
        xyz = ("x", "y", "z")
        self.declare_input("velocity", (n, 3), unit="m/s", labels=xyz,
                           doc="velocity set-point, world frame")
        self.declare_input("measured_velocity", (n, 3), unit="m/s", labels=xyz)
        self.declare_input("attitude", (n, 4), labels=("w", "x", "y", "z"))
        self.declare_input("rates", (n, 3), unit="rad/s", labels=("p", "q", "r"))
        if output == "wrench":
            self.declare_output("wrench", (n, 4), unit="N, N m, N m, N m",
                                labels=("T", "tau_x", "tau_y", "tau_z"))
        else:
            self.declare_output("rotors", (n, 4), unit="N", labels=("f1", "f2", "f3", "f4"))

    @classmethod
    def for_quadrotor(cls, quad, **gains):
        """A controller with the physical parameters of ``quad`` (a Quadrotor)."""
        return cls(quad.n, mass=quad.mass, inertia=quad.inertia, gravity=quad.gravity,
                   drag=quad.drag, output=quad.input, frame=quad.frame,
                   arm_length=quad.arm_length, yaw_coeff=quad.yaw_coeff,
                   rotor_max=quad.rotor_max, thrust_max=quad.thrust_max, **gains)

    def output(self, t, x, u, xp):
        g = self.gravity
        m = self.mass[:, None]
        vel = u["measured_velocity"]
        q = quat_normalize(u["attitude"], xp)
        om = u["rates"]
        # velocity loop -> desired acceleration, tilt limited
        a = self.kv * (u["velocity"] - vel) + (self.drag / m) * vel
        axy = a[:, :2]
        # the floor inside the root: sqrt's derivative at 0 is infinite, and
        # JAX would differentiate the hover (a_xy = 0) to NaN (av.linearize, av.grad)
        nxy = xp.sqrt(xp.maximum(dot(axy, axy), 1e-300))
        axy = axy * xp.minimum(1.0, g * xp.tan(self.tilt_max) / nxy)[:, None]
        az = xp.maximum(a[:, 2], -0.8 * g) + g
        F = m * xp.concatenate([axy, az[:, None]], axis=-1)
        R = quat_to_rotmat(q, xp)
        thrust = dot(F, R[:, :, 2])
        # attitude loop (geometric, Lee et al. 2010)
        b3 = F / xp.sqrt(dot(F, F))[:, None]
        zero = xp.zeros_like(self.yaw)
        b1c = xp.stack([xp.cos(self.yaw), xp.sin(self.yaw), zero], axis=-1)
        b2 = cross(b3, b1c, xp)
        b2 = b2 / xp.sqrt(dot(b2, b2))[:, None]
        b1 = cross(b2, b3, xp)
        Rd = xp.stack([b1, b2, b3], axis=-1)
        E = xp.swapaxes(Rd, -1, -2) @ R
        e_r = 0.5 * vee(E - xp.swapaxes(E, -1, -2), xp)
        om_d = xp.clip(-self.k_att * e_r, -self.rate_max, self.rate_max)
        # rate loop
        J = self.inertia
        tau = J * (self.k_rate * (om_d - om)) + cross(om, J * om, xp)
        thrust = xp.clip(thrust, 0.0, self.thrust_max)
        w = xp.concatenate([thrust[:, None], tau], axis=-1)
        if self.out_kind == "wrench":
            return {"wrench": w}
        f = wrench_to_rotors(w, self.arm_length, self.yaw_coeff, self.frame, xp)
        return {"rotors": xp.clip(f, 0.0, self.rotor_max[:, None])}


def velocity_controlled_quadrotor(quad, controller=None, name=None, **gains):
    """A subsystem: ``quad`` flown by a :class:`QuadrotorVelocityControl`.

    Returns a :class:`~avblocks.core.Diagram` with input ``velocity`` (N, 3)
    and outputs ``position`` (N, 3), ``pose`` (N, 3) and ``attitude`` (N, 4):
    the ports of a 3D :class:`SingleIntegrator` plus the planar pose, so it
    replaces one in a diagram without touching the controller.

    >>> import numpy as np, avblocks as av
    >>> sub = av.vehicles.velocity_controlled_quadrotor(av.vehicles.Quadrotor(np.zeros((2, 3))))
    >>> sorted(sub.input_ports), sorted(sub.output_ports)
    (['velocity'], ['attitude', 'pose', 'position'])
    """
    ctrl = controller if controller is not None else \
        QuadrotorVelocityControl.for_quadrotor(quad, **gains)
    d = Diagram(name)
    qh = d.add(quad, name="quad")
    ch = d.add(ctrl, name="ctrl")
    d.connect(qh.velocity, ch.measured_velocity)
    d.connect(qh.attitude, ch.attitude)
    d.connect(qh.rates, ch.rates)
    port = quad.input
    d.connect(ch.port(port), qh.port(port))
    d.export_input("velocity", ch.velocity)
    d.export_output("position", qh.position)
    d.export_output("pose", qh.pose)
    d.export_output("attitude", qh.attitude)
    return d


class VelocityControlledQuadrotor(Diagram):
    """N quadrotors flown by velocity set-points: a Quadrotor and its controller as one subsystem.

    The subsystem :func:`velocity_controlled_quadrotor` builds, as a class
    a scenario file can name (``type: vehicles.VelocityControlledQuadrotor``):
    a :class:`Quadrotor` (block ``quad``) flown by a
    :class:`QuadrotorVelocityControl` (block ``ctrl``) that has the
    vehicle's own mass, inertia, drag and airframe. It has the ports of a
    3-D :class:`SingleIntegrator` plus the planar pose and the attitude,
    so a controller written for holonomic agents flies quadrotors
    unchanged, and ``--robots mavlink`` / ``crazyflies`` replace it whole.

    Ports
    -----
    velocity : in, (N, 3) [m/s]
        Velocity set-point (world frame).
    position : out, (N, 3) [m]
        Centre of mass, world frame.
    pose : out, (N, 3)
        x, y [m] and yaw [rad].
    attitude : out, (N, 4)
        Unit quaternion w, x, y, z.

    Parameters
    ----------
    position0 : array_like, (N, 3)
        Start positions [m] (hovering, level).
    mass : float or (N,)
        [kg], default 1.
    inertia : array_like, (3,) or (N, 3)
        Diagonal inertia [kg m^2], default (0.01, 0.01, 0.02).
    drag : float, (3,) or (N, 3)
        Linear drag c [N s/m] along the world axes (default 0).
    arm_length : float or (N,)
        Rotor distance from the centre l [m], default 0.2.
    kv : float
        Velocity gain [1/s] (default 2.5).
    k_att : float
        Attitude gain [1/s] (default 8).
    k_rate : float
        Rate-loop gain [1/s] (default 25).
    tilt_max : float
        Largest commanded tilt [rad] (default 0.5).
    yaw : float or (N,)
        Yaw set-point [rad] (default 0).

    Numeric parameters
    ------------------

    The subsystem owns none itself: its numeric keywords become parameters
    of the two blocks inside, addressed through it as
    ``"<name>.quad.<parameter>"`` and ``"<name>.ctrl.<parameter>"``
    (``<name>`` the name it is added under, e.g. ``"fleet.ctrl.kv"``).
    The vehicle ``quad`` has ``mass``, ``inertia``, ``drag``,
    ``arm_length``, ``yaw_coeff``, ``gravity``, ``rotor_max``,
    ``thrust_max``, ``torque_max`` and ``quat_gain``; the controller
    ``ctrl`` has the gains ``kv``, ``k_att``, ``k_rate``, the limits
    ``tilt_max``, ``rate_max``, ``thrust_max``, ``rotor_max``, the set-point
    ``yaw`` and its own model of the vehicle (``mass``, ``inertia``,
    ``drag``, ``arm_length``, ``yaw_coeff``, ``gravity``: copies made at
    construction, so setting ``"fleet.quad.mass"`` alone gives a controller
    whose model is off; set both to change the vehicle it knows).

    Equations
    ---------
    The vehicle: :class:`Quadrotor` (Newton-Euler rigid body, wrench
    input). The controller: :class:`QuadrotorVelocityControl` (velocity
    loop ``a = kv (v_ref - v) + c v / m``, geometric attitude loop of Lee
    et al., rate loop). A velocity step settles as a first-order lag of
    time constant ``1 / kv``.

    References
    ----------
    Lee, Leok & McClamroch (2010); Mahony, Kumar & Corke (2012), Section V.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> q = av.vehicles.VelocityControlledQuadrotor(np.zeros((2, 3)))
    >>> sorted(q.input_ports), sorted(q.output_ports)
    (['velocity'], ['attitude', 'pose', 'position'])
    """

    example = {"position0": {"random_positions": {"n": "$agents", "area": [50, 50],
                                                  "dim": 3, "seed": "$seed"}}}

    def __init__(self, position0, *, mass=1.0, inertia=(0.01, 0.01, 0.02), drag=0.0,
                 arm_length=0.2, kv=2.5, k_att=8.0, k_rate=25.0, tilt_max=0.5, yaw=0.0):
        super().__init__(None)
        from .quadrotor import Quadrotor
        quad = Quadrotor(position0, mass=mass, inertia=inertia, drag=drag,
                         arm_length=arm_length)
        ctrl = QuadrotorVelocityControl.for_quadrotor(quad, kv=kv, k_att=k_att,
                                                      k_rate=k_rate, tilt_max=tilt_max,
                                                      yaw=yaw)
        self.n = quad.n
        qh = self.add(quad, name="quad")
        ch = self.add(ctrl, name="ctrl")
        self.connect(qh.velocity, ch.measured_velocity)
        self.connect(qh.attitude, ch.attitude)
        self.connect(qh.rates, ch.rates)
        self.connect(ch.wrench, qh.wrench)
        self.export_input("velocity", ch.velocity)
        self.export_output("position", qh.position)
        self.export_output("pose", qh.pose)
        self.export_output("attitude", qh.attitude)

    # the declarations a palette reads from a block, answered by the subsystem
    @property
    def _inputs(self):
        return self.input_ports

    @property
    def _outputs(self):
        return self.output_ports

    @property
    def parameters(self) -> dict:
        """The numeric parameters of the vehicle and its controller by
        constructor name (the vehicle's where both have one)."""
        return {**self["ctrl"].block.parameters, **self["quad"].block.parameters}

    def port_table(self, n=None, *, symbolic=True) -> dict:
        """The subsystem's ports with the agent axis as ``N``
        (:func:`avblocks.core.declarations.port_table`)."""
        from ..core.declarations import port_table
        return port_table(self, n, symbolic=symbolic)
