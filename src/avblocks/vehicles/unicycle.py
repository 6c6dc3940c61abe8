"""First-order unicycle, AVLib paper eq. (1).

Equations
---------
    dx/dt = v cos(theta)
    dy/dt = v sin(theta)
    dtheta/dt = omega

with (v, omega) optionally clipped to ``|v| <= v_max``, ``|omega| <= omega_max``.

Reference: "AVLib: A Simulink Library for Multi-Agent Systems Research"
(the AVLib paper), Section III.A, eq. (1); Siegwart & Nourbakhsh,
*Introduction to Autonomous Mobile Robots*, ch. 3.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.memo import shared
from ..core.params import limit, poses
from ..utility.angles import heading_trig, wrap_angle
from ..utility.arrays import columns
from ._common import any_finite


def unicycle_rhs(pose, cmd, xp=np):
    """Pose derivative of N unicycles: ``pose`` (N, 3), ``cmd`` (N, 2) -> (N, 3).

    Only the heading of ``pose`` is read; its cos/sin go through
    :func:`~avblocks.core.memo.shared` (taken once per pose array per step
    when a controller needs them too)."""
    c, s = shared(heading_trig, pose, xp)
    v = cmd[:, 0]
    if xp is np:                        # same values, fewer temporaries
        out = np.empty((v.shape[0], 3))
        np.multiply(v, c, out=out[:, 0])
        np.multiply(v, s, out=out[:, 1])
        out[:, 2] = cmd[:, 1]
        return out
    return columns(xp, v * c, v * s, cmd[:, 1])


def wrapped_pose(p, xp=np):
    """``(x, y, wrap_angle(theta))`` of poses (N, 3)."""
    if xp is np:
        # wrap_angle's arithmetic, operation for operation, in one buffer:
        # w = ceil((theta - pi) / (2 pi)) turns. When no heading needs a turn
        # (all in (-pi, pi]; a NaN counts as one) the state array is returned
        # (nothing writes into states or outputs). Counting the nonzero
        # turns decides that for the price of one cheap pass, where a test of
        # max |theta| cost two more passes over the strided column whenever
        # the headings have left (-pi, pi] (most steps of a long run)
        th = p[:, 2]
        w = th - np.pi
        w *= 0.5 / np.pi
        np.ceil(w, out=w)
        if not np.count_nonzero(w):
            return p
        w *= 2 * np.pi
        out = p.copy()
        np.subtract(th, w, out=out[:, 2])
        return out
    return columns(xp, p[:, 0], p[:, 1], wrap_angle(p[:, 2], xp))


def clip_cmd(cmd, v_max, omega_max, xp=np):
    """Clip (v, omega) to symmetric limits (arrays of shape (N,) or scalars)."""
    v = xp.clip(cmd[:, 0], -v_max, v_max)
    w = xp.clip(cmd[:, 1], -omega_max, omega_max)
    return xp.stack([v, w], axis=-1)


class Unicycle(Block):
    """N first-order unicycles (paper eq. 1) in one block.

    Ports
    -----
    cmd : in, (N, 2) [m/s, rad/s]
        Forward speed v and turn rate omega (not direct feedthrough).
    pose : out, (N, 3) [m, m, rad]
        x, y and heading wrapped to (-pi, pi].

    State
    -----
    pose : continuous (N, 3); the heading state is not wrapped, the output is.

    Parameters
    ----------
    pose0 : array_like, (N, 3)
        Initial poses; N is the number of vehicles.
    v_max, omega_max : float or (N,), optional
        Symmetric input limits (default: none). Numeric parameters of shape
        (N,), bounds [0, inf] (inf: no limit).
    saturation_output : bool, optional
        Add an output ``saturated`` (N, 2) bool: whether ``|v| > v_max`` and
        ``|omega| > omega_max`` for the current command. It depends on the
        command at the same instant, so asking for it declares ``cmd``
        direct-feedthrough; a controller that reads ``pose`` and drives
        ``cmd`` then forms an algebraic loop. Off by default for that reason
        (log or display it only, or use a Saturation block in front).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.Unicycle(pose0=np.zeros((2, 3)))
    >>> b.derivative(0, b.initial_state(), {"cmd": np.array([[1.0, 0.5]] * 2)}, np)["pose"][0]
    array([1. , 0. , 0.5])
    """

    def __init__(self, pose0, *, v_max=np.inf, omega_max=np.inf,
                 saturation_output=False):
        super().__init__()
        p0 = poses(pose0, "Unicycle", "pose0")
        self.n = n = p0.shape[0]
        for nm, val in (("v_max", v_max), ("omega_max", omega_max)):
            self.declare_parameter(nm, limit(val, n, "Unicycle", nm), bounds=(0, None),
                                   allow_inf=True, unit="m/s" if nm == "v_max" else "rad/s",
                                   doc="symmetric input limit (inf: none)")
        self.declare_continuous_state("pose", p0, unit="m, m, rad",
                                      labels=("x", "y", "theta"))
        self.declare_input("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"),
                           doc="forward speed and turn rate",
                           feedthrough=bool(saturation_output))
        self.declare_output("pose", (n, 3), unit="m, m, rad",
                            labels=("x", "y", "theta"), doc="pose, heading in (-pi, pi]")
        self.saturation_output = bool(saturation_output)
        if self.saturation_output:
            self.declare_output("saturated", (n, 2), "bool", labels=("v", "omega"),
                                doc="command exceeds the limit (cmd is feedthrough)")

    def output(self, t, x, u, xp):
        y = {"pose": shared(wrapped_pose, x["pose"], xp)}
        if self.saturation_output:
            lim = xp.stack([self.v_max, self.omega_max], axis=-1)
            y["saturated"] = xp.abs(u["cmd"]) > lim
        return y

    def derivative(self, t, x, u, xp):
        cmd = u["cmd"]
        if self.param_flag("limited", xp, any_finite, "v_max", "omega_max"):
            cmd = clip_cmd(cmd, self.v_max, self.omega_max, xp)
        # the heading's trig is taken of the wrapped pose (the output):
        # the same values (a whole number of turns apart), and the same
        # array as the controllers downstream see, so it is computed once
        return {"pose": unicycle_rhs(shared(wrapped_pose, x["pose"], xp), cmd, xp)}
