"""Second-order unicycle: the unicycle of eq. (1) driven by force and torque.

Equations
---------
    dx/dt     = v cos(theta)
    dy/dt     = v sin(theta)
    dtheta/dt = omega
    m dv/dt     = f   - b_v v
    J domega/dt = tau - b_omega omega

with (f, tau) optionally clipped to ``|f| <= f_max``, ``|tau| <= tau_max``
and linear damping ``b_v``, ``b_omega >= 0`` (default 0: the paper's model).

Reference: "AVLib: A Simulink Library for Multi-Agent Systems Research"
(the AVLib paper), Section III.A (second-order unicycle); the damping terms
are the usual viscous friction of e.g. Siciliano & Khatib (eds.), *Springer
Handbook of Robotics*, ch. 49 (wheeled robots).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.memo import shared
from ..core.params import agent_array, poses
from ._common import any_finite, limit
from .unicycle import unicycle_rhs, wrapped_pose


def unicycle2_rhs(pose, twist, wrench, mass, inertia, lin_damping=0.0,
                  ang_damping=0.0, xp=np):
    """Derivatives of N second-order unicycles.

    ``pose`` (N, 3), ``twist`` (N, 2) = (v, omega), ``wrench`` (N, 2) =
    (f, tau); ``mass``, ``inertia``, dampings scalars or (N,).
    Returns ``(dpose, dtwist)``.
    """
    dpose = unicycle_rhs(pose, twist, xp)
    dv = (wrench[:, 0] - lin_damping * twist[:, 0]) / mass
    dw = (wrench[:, 1] - ang_damping * twist[:, 1]) / inertia
    return dpose, xp.stack([dv, dw], axis=-1)


class Unicycle2(Block):
    """N second-order unicycles (mass, inertia, force and torque inputs).

    Ports
    -----
    wrench : in, (N, 2) [N, N m]
        Forward force f and yaw torque tau (not direct feedthrough).
    pose : out, (N, 3) [m, m, rad]
        x, y and heading wrapped to (-pi, pi].
    twist : out, (N, 2) [m/s, rad/s]
        Forward speed v and turn rate omega.

    State
    -----
    pose : continuous (N, 3) (heading not wrapped); twist : continuous (N, 2).

    Parameters
    ----------
    pose0 : array_like, (N, 3)
        Initial poses; N is the number of vehicles.
    twist0 : array_like, (2,) or (N, 2), optional
        Initial (v, omega) (default zero).
    mass, inertia : float or (N,)
        Mass m [kg] and yaw moment of inertia J [kg m^2], > 0.
    lin_damping, ang_damping : float or (N,), optional
        Viscous damping b_v [N s/m] and b_omega [N m s/rad], >= 0 (default 0).
    f_max, tau_max : float or (N,), optional
        Symmetric input limits (default: none).

    Numeric parameters
    ------------------

    ``mass``, ``inertia``, the dampings and the limits are numeric
    parameters of shape (N,) (``"block.mass"`` ...); ``pose0``/``twist0``
    are initial states (set them with ``x0=``).

    Equations
    ---------
    See the module docstring: ``m dv/dt = f - b_v v``, ``J domega/dt = tau -
    b_omega omega`` and the unicycle kinematics.

    References
    ----------
    AVLib paper, Section III.A.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.Unicycle2(np.zeros((1, 3)), mass=2.0, inertia=0.5)
    >>> d = b.derivative(0, b.initial_state(), {"wrench": np.array([[1.0, 1.0]])}, np)
    >>> d["twist"]
    array([[0.5, 2. ]])
    """

    def __init__(self, pose0, *, twist0=0.0, mass=1.0, inertia=1.0,
                 lin_damping=0.0, ang_damping=0.0, f_max=np.inf, tau_max=np.inf):
        super().__init__()
        name = "Unicycle2"
        p0 = poses(pose0, name, "pose0")
        self.n = n = p0.shape[0]
        tw0 = agent_array(twist0, n, name, "twist0", (2,))
        dp = self.declare_parameter
        dp("mass", agent_array(mass, n, name, "mass", positive=True),
           bounds=(1e-12, None), unit="kg")
        dp("inertia", agent_array(inertia, n, name, "inertia", positive=True),
           bounds=(1e-12, None), unit="kg m^2")
        dp("lin_damping", agent_array(lin_damping, n, name, "lin_damping",
                                      nonnegative=True), bounds=(0, None), unit="N s/m")
        dp("ang_damping", agent_array(ang_damping, n, name, "ang_damping",
                                      nonnegative=True), bounds=(0, None), unit="N m s/rad")
        dp("f_max", limit(f_max, n, name, "f_max"), bounds=(0, None), allow_inf=True,
           unit="N")
        dp("tau_max", limit(tau_max, n, name, "tau_max"), bounds=(0, None),
           allow_inf=True, unit="N m")
        self.declare_continuous_state("pose", p0, unit="m, m, rad",
                                      labels=("x", "y", "theta"))
        self.declare_continuous_state("twist", tw0, unit="m/s, rad/s",
                                      labels=("v", "omega"))
        self.declare_input("wrench", (n, 2), unit="N, N m", labels=("f", "tau"),
                           doc="forward force and yaw torque", feedthrough=False)
        self.declare_output("pose", (n, 3), unit="m, m, rad",
                            labels=("x", "y", "theta"), doc="pose, heading in (-pi, pi]")
        self.declare_output("twist", (n, 2), unit="m/s, rad/s", labels=("v", "omega"),
                            doc="forward speed and turn rate")

    def output(self, t, x, u, xp):
        return {"pose": shared(wrapped_pose, x["pose"], xp), "twist": x["twist"]}

    def derivative(self, t, x, u, xp):
        w = u["wrench"]
        if self.param_flag("limited", xp, any_finite, "f_max", "tau_max"):
            w = xp.stack([xp.clip(w[:, 0], -self.f_max, self.f_max),
                          xp.clip(w[:, 1], -self.tau_max, self.tau_max)], axis=-1)
        # trig of the wrapped heading: shared with the controllers (core.memo)
        pose = shared(wrapped_pose, x["pose"], xp)
        dp, dt = unicycle2_rhs(pose, x["twist"], w, self.mass, self.inertia,
                               self.lin_damping, self.ang_damping, xp)
        return {"pose": dp, "twist": dt}

