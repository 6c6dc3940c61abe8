"""Near-identity (off-axis point) mapping: holonomic set-points on unicycles.

Equations
---------
The point ``p = (x + d cos theta, y + d sin theta)`` of a unicycle moves with
``dp/dt = R(theta) diag(1, d) [v, omega]^T``. Inverting, a velocity set-point
``w`` (N, 2) for ``p`` is realised exactly by

    v     =  cos(theta) w_x + sin(theta) w_y
    omega = (-sin(theta) w_x + cos(theta) w_y) / d,    d > 0.

So any single-integrator law (consensus, formation, coverage, a safety
filter) runs on unicycles: feed it the off-axis points (:class:`OffAxisPoint`)
and map its velocity output back with :class:`HolonomicToUnicycle`. Two
blocks, not one, because the holonomic controller sits between them (one
block would be an algebraic loop).

Reference: Lawton, Beard & Young, "A decentralized approach to formation
maneuvers", IEEE TRA 19(6), 2003; Cortes, Martinez & Bullo (2009),
*Distributed Control of Robotic Networks*; the same map as
:func:`~avblocks.controllers.point_to_point_law`.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.memo import shared
from ..core.params import positive_scalar
from ..utility.angles import heading_trig


def off_axis_point(pose, d, xp=np):
    """(N, 2) points at distance ``d`` ahead of unicycles ``pose`` (N, 3)."""
    c, s = shared(heading_trig, pose, xp)
    return xp.stack([pose[:, 0] + d * c, pose[:, 1] + d * s], axis=-1)


def holonomic_to_unicycle(pose, velocity, d, xp=np):
    """(v, omega) (N, 2) making the off-axis points move with ``velocity`` (N, 2)."""
    c, s = shared(heading_trig, pose, xp)
    wx, wy = velocity[:, 0], velocity[:, 1]
    return xp.stack([c * wx + s * wy, (-s * wx + c * wy) / d], axis=-1)


class OffAxisPoint(Block):
    """Off-axis points of N unicycles.

    Ports: pose (N, 3) in; position (N, 2) out ``(x + d cos th, y + d sin th)``.
    Parameters: n, d > 0 (m); ``d`` is a numeric parameter.
    """

    def __init__(self, n, d=0.1):
        super().__init__()
        self.n = n = int(n)
        self.declare_parameter("d", positive_scalar(d, "OffAxisPoint", "d"),
                               bounds=(1e-9, None), unit="m")
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_output("position", (n, 2), unit="m", labels=("x", "y"))

    def output(self, t, x, u, xp):
        return {"position": off_axis_point(u["pose"], self.d, xp)}


class HolonomicToUnicycle(Block):
    """Unicycle commands realising a velocity set-point of the off-axis point.

    Ports
    -----
    pose : in, (N, 3); velocity : in, (N, 2) [m/s] set-point of the point.
    cmd : out, (N, 2) (v, omega).

    Parameters: n, d > 0 (m) — same ``d`` as the OffAxisPoint feeding the
    holonomic controller; ``d`` is a numeric parameter. Equations: module
    docstring.

    >>> import numpy as np
    >>> b = HolonomicToUnicycle(1, d=0.5)
    >>> b.output(0, {}, {"pose": np.array([[0, 0, np.pi / 2]]),
    ...                  "velocity": np.array([[1.0, 0.0]])}, np)["cmd"].round(6)
    array([[ 0., -2.]])
    """

    def __init__(self, n, d=0.1):
        super().__init__()
        self.n = n = int(n)
        self.declare_parameter("d", positive_scalar(d, "HolonomicToUnicycle", "d"),
                               bounds=(1e-9, None), unit="m")
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_input("velocity", (n, 2), unit="m/s", labels=("vx", "vy"))
        self.declare_output("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"))

    def output(self, t, x, u, xp):
        return {"cmd": holonomic_to_unicycle(u["pose"], u["velocity"], self.d, xp)}
