"""Ackermann-steered car: the kinematic bicycle, rear-axle reference point.

Equations
---------
    dx/dt     = v cos(theta)
    dy/dt     = v sin(theta)
    dtheta/dt = v tan(delta) / L

with (x, y) the midpoint of the rear axle, wheelbase L, speed v clipped to
``|v| <= v_max`` and steering angle clipped to ``|delta| <= delta_max``
(``< pi/2``). With a steering actuator lag ``steer_tau > 0`` the steering
angle becomes a state driven toward the (clipped) command::

    ddelta/dt = clip((clip(delta_cmd) - delta) / steer_tau, +-steer_rate_max)

At constant v and delta the rear axle moves on a circle of radius
``L / tan(delta)`` centred at ``(x0 - R sin(theta0), y0 + R cos(theta0))``.

References: S. M. LaValle, *Planning Algorithms* (2006), Section 13.1.2.1
(simple car); R. Rajamani, *Vehicle Dynamics and Control*, 2nd ed. (2012),
Section 2.2 (kinematic bicycle model, here with the rear axle as reference so
the slip angle is zero).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import agent_array, poses
from ..utility.angles import wrap_angle
from ._common import limit


def ackermann_rhs(pose, v, delta, wheelbase, xp=np):
    """Pose derivative (N, 3) of N kinematic bicycles (rear-axle reference)."""
    th = pose[:, 2]
    return xp.stack([v * xp.cos(th), v * xp.sin(th), v * xp.tan(delta) / wheelbase],
                    axis=-1)


class Ackermann(Block):
    """N car-like (Ackermann-steered) vehicles, kinematic bicycle model.

    Ports
    -----
    cmd : in, (N, 2) [m/s, rad]
        Forward speed v and steering angle delta (not direct feedthrough).
    pose : out, (N, 3) [m, m, rad]
        Rear-axle midpoint x, y and heading wrapped to (-pi, pi].
    steer : out, (N,) [rad]
        Actual steering angle; only with ``steer_tau > 0`` (then a state).

    State
    -----
    pose : continuous (N, 3) (heading not wrapped); steer : continuous (N,)
    with an actuator lag.

    Parameters
    ----------
    pose0 : array_like, (N, 3)
        Initial poses.
    wheelbase : float or (N,)
        L [m], > 0.
    v_max : float or (N,), optional
        Speed limit [m/s] (default: none).
    delta_max : float or (N,), optional
        Steering limit [rad], < pi/2 (default 0.6).
    steer_tau : float, optional
        First-order steering actuator time constant [s] (default 0: none).
    steer_rate_max : float or (N,), optional
        Steering rate limit [rad/s] with a lag (default: none).
    steer0 : float or (N,), optional
        Initial steering angle with a lag (default 0).

    Numeric parameters
    ------------------

    Numeric parameters (shape (N,) unless said): ``wheelbase``, ``v_max``,
    ``delta_max``; with a lag also ``steer_tau`` (scalar, > 0) and
    ``steer_rate_max``. Whether there is a lag (``steer_tau > 0``) is
    structural: it decides the ``steer`` state and output.

    Equations
    ---------
    See the module docstring.

    References
    ----------
    LaValle (2006) Section 13.1.2.1; Rajamani (2012) Section 2.2.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.Ackermann(np.zeros((1, 3)), wheelbase=2.0, delta_max=1.0)
    >>> b.derivative(0, b.initial_state(), {"cmd": np.array([[2.0, np.pi / 4]])}, np)["pose"]
    array([[2., 0., 1.]])
    """

    def __init__(self, pose0, *, wheelbase=2.5, v_max=np.inf, delta_max=0.6,
                 steer_tau=0.0, steer_rate_max=np.inf, steer0=0.0):
        super().__init__()
        name = "Ackermann"
        p0 = poses(pose0, name, "pose0")
        self.n = n = p0.shape[0]
        self.declare_parameter("wheelbase", agent_array(wheelbase, n, name, "wheelbase",
                                                        positive=True),
                               bounds=(1e-12, None), unit="m")
        self.declare_parameter("v_max", limit(v_max, n, name, "v_max"), bounds=(0, None),
                               allow_inf=True, unit="m/s")
        dmax = limit(delta_max, n, name, "delta_max")
        if np.any(dmax >= np.pi / 2):
            raise ParameterError("steering limit must be below pi/2", block=name,
                                 param="delta_max", expected="< pi/2",
                                 found=float(dmax.max()))
        self.declare_parameter("delta_max", dmax, bounds=(0, np.pi / 2 - 1e-9),
                               unit="rad")
        steer_tau = float(steer_tau)
        if not (np.isfinite(steer_tau) and steer_tau >= 0):
            raise ParameterError("must be >= 0", block=name, param="steer_tau",
                                 expected=">= 0", found=steer_tau)
        self.lag = steer_tau > 0
        if self.lag:
            self.declare_parameter("steer_tau", steer_tau, bounds=(1e-12, None), unit="s")
            self.declare_parameter("steer_rate_max",
                                   limit(steer_rate_max, n, name, "steer_rate_max"),
                                   bounds=(0, None), allow_inf=True, unit="rad/s")
        else:
            self.steer_tau = 0.0
            self.steer_rate_max = limit(steer_rate_max, n, name, "steer_rate_max")
        self.declare_continuous_state("pose", p0, unit="m, m, rad",
                                      labels=("x", "y", "theta"))
        if self.lag:
            s0 = agent_array(steer0, n, name, "steer0")
            self.declare_continuous_state("steer", np.clip(s0, -dmax, dmax), unit="rad")
        self.declare_input("cmd", (n, 2), unit="m/s, rad", labels=("v", "delta"),
                           doc="forward speed and steering angle", feedthrough=False)
        self.declare_output("pose", (n, 3), unit="m, m, rad",
                            labels=("x", "y", "theta"), doc="pose, heading in (-pi, pi]")
        if self.lag:
            self.declare_output("steer", (n,), unit="rad", doc="actual steering angle")

    def output(self, t, x, u, xp):
        p = x["pose"]
        y = {"pose": xp.concatenate([p[:, :2], wrap_angle(p[:, 2:3], xp)], axis=-1)}
        if self.lag:
            y["steer"] = x["steer"]
        return y

    def derivative(self, t, x, u, xp):
        cmd = u["cmd"]
        v = xp.clip(cmd[:, 0], -self.v_max, self.v_max)
        dcmd = xp.clip(cmd[:, 1], -self.delta_max, self.delta_max)
        if not self.lag:
            return {"pose": ackermann_rhs(x["pose"], v, dcmd, self.wheelbase, xp)}
        delta = x["steer"]
        rate = xp.clip((dcmd - delta) / self.steer_tau, -self.steer_rate_max,
                       self.steer_rate_max)
        return {"pose": ackermann_rhs(x["pose"], v, delta, self.wheelbase, xp),
                "steer": rate}
