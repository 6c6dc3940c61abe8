"""Differential-drive robot: two driven wheels on one axle.

Equations
---------
    v     = r (omega_R + omega_L) / 2
    omega = r (omega_R - omega_L) / b
    dx/dt = v cos(theta),  dy/dt = v sin(theta),  dtheta/dt = omega

with wheel radius r, track width b (distance between the wheel contact
points) and wheel angular speeds clipped to ``|omega_L|, |omega_R| <=
wheel_speed_max``. Positive wheel speeds drive the robot forward.

Reference: Siegwart, Nourbakhsh & Scaramuzza, *Introduction to Autonomous
Mobile Robots*, 2nd ed. (2011), Section 3.2.1 (differential drive).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.memo import shared
from ..core.params import agent_array, poses
from ._common import any_finite, limit
from .unicycle import unicycle_rhs, wrapped_pose


def wheels_to_twist(wheels, wheel_radius, track_width, xp=np):
    """(omega_L, omega_R) (N, 2) -> (v, omega) (N, 2)."""
    wl, wr = wheels[:, 0], wheels[:, 1]
    v = wheel_radius * (wr + wl) / 2
    w = wheel_radius * (wr - wl) / track_width
    return xp.stack([v, w], axis=-1)


def twist_to_wheels(twist, wheel_radius, track_width, xp=np):
    """(v, omega) (N, 2) -> (omega_L, omega_R) (N, 2): the inverse mapping."""
    v, w = twist[:, 0], twist[:, 1]
    half = w * track_width / 2
    return xp.stack([(v - half) / wheel_radius, (v + half) / wheel_radius], axis=-1)


def diffdrive_rhs(pose, wheels, wheel_radius, track_width, xp=np):
    """Pose derivative (N, 3) of N differential-drive robots."""
    return unicycle_rhs(pose, wheels_to_twist(wheels, wheel_radius, track_width, xp), xp)


class DiffDrive(Block):
    """N differential-drive robots driven by wheel speeds.

    Ports
    -----
    wheels : in, (N, 2) [rad/s]
        Left and right wheel angular speeds (not direct feedthrough).
    pose : out, (N, 3) [m, m, rad]
        x, y (axle midpoint) and heading wrapped to (-pi, pi].

    State
    -----
    pose : continuous (N, 3) (heading not wrapped).

    Parameters
    ----------
    pose0 : array_like, (N, 3)
        Initial poses.
    wheel_radius : float or (N,)
        r [m], > 0.
    track_width : float or (N,)
        b [m], distance between the two wheels, > 0.
    wheel_speed_max : float or (N,), optional
        Symmetric wheel-speed limit [rad/s] (default: none).

    Numeric parameters
    ------------------

    ``wheel_radius``, ``track_width`` and ``wheel_speed_max`` are numeric
    parameters of shape (N,).

    Equations
    ---------
    See the module docstring; ``wheels_to_twist`` / ``twist_to_wheels`` are
    the mapping to and from the unicycle command.

    References
    ----------
    Siegwart, Nourbakhsh & Scaramuzza (2011), Section 3.2.1.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.DiffDrive(np.zeros((1, 3)), wheel_radius=0.1, track_width=0.5)
    >>> b.derivative(0, b.initial_state(), {"wheels": np.array([[10.0, 10.0]])}, np)["pose"]
    array([[1., 0., 0.]])
    """

    def __init__(self, pose0, *, wheel_radius=0.05, track_width=0.3,
                 wheel_speed_max=np.inf):
        super().__init__()
        name = "DiffDrive"
        p0 = poses(pose0, name, "pose0")
        self.n = n = p0.shape[0]
        self.declare_parameter(
            "wheel_radius", agent_array(wheel_radius, n, name, "wheel_radius",
                                        positive=True), bounds=(1e-12, None), unit="m")
        self.declare_parameter(
            "track_width", agent_array(track_width, n, name, "track_width",
                                       positive=True), bounds=(1e-12, None), unit="m")
        self.declare_parameter(
            "wheel_speed_max", limit(wheel_speed_max, n, name, "wheel_speed_max"),
            bounds=(0, None), allow_inf=True, unit="rad/s")
        self.declare_continuous_state("pose", p0, unit="m, m, rad",
                                      labels=("x", "y", "theta"))
        self.declare_input("wheels", (n, 2), unit="rad/s", labels=("left", "right"),
                           doc="wheel angular speeds", feedthrough=False)
        self.declare_output("pose", (n, 3), unit="m, m, rad",
                            labels=("x", "y", "theta"), doc="pose, heading in (-pi, pi]")

    def output(self, t, x, u, xp):
        return {"pose": shared(wrapped_pose, x["pose"], xp)}

    def derivative(self, t, x, u, xp):
        w = u["wheels"]
        if self.param_flag("limited", xp, any_finite, "wheel_speed_max"):
            m = self.wheel_speed_max[:, None]
            w = xp.clip(w, -m, m)
        # trig of the wrapped heading: shared with the controllers (core.memo)
        return {"pose": diffdrive_rhs(shared(wrapped_pose, x["pose"], xp), w,
                                      self.wheel_radius, self.track_width, xp)}
