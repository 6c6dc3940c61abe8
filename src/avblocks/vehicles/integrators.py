"""Holonomic point agents in 2D or 3D: single and double integrators.

Equations
---------
Single integrator::

    dp/dt = sat_v(u),          sat_v(u) = u min(1, v_max / |u|)

Double integrator (input ``accel`` in m/s^2, or ``force`` in N divided by
the mass)::

    dp/dt = v
    dv/dt = P(v, sat_a(a)) - c v / m

``sat_a`` scales the acceleration down to norm ``a_max``; ``c`` is an
optional linear drag [N s/m]. ``P`` enforces the speed limit: when
``|v| >= v_max`` the component of the acceleration along v that would
speed the agent up further is removed (the tangential part is kept); as
the switch happens inside a solver step, speed may overshoot ``v_max`` by
at most ``a_max dt`` and is then held.
All norms are Euclidean over the 2 or 3 components (limits are isotropic).

Reference: the standard agent models of consensus and flocking, e.g.
Olfati-Saber, "Flocking for multi-agent dynamic systems", IEEE TAC 51(3),
2006, eq. (1); Mesbahi & Egerstedt, *Graph Theoretic Methods in Multiagent
Networks* (2010), ch. 3.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import agent_array, poses
from ._common import any_finite, clip_norm, limit
from ._rotations import dot


def _dim(position0, dim, block):
    a = np.asarray(position0, dtype=float)
    if dim is None:
        dim = a.shape[-1] if a.ndim >= 1 else 0
    if dim not in (2, 3):
        raise ParameterError("dim must be 2 or 3", block=block, param="dim",
                             expected="2 or 3", found=dim)
    return poses(position0, block, "position0", dim=dim), dim


def speed_limited_accel(vel, acc, v_max, xp=np):
    """Remove the part of ``acc`` that would push ``|vel|`` beyond ``v_max``."""
    sq = dot(vel, vel)
    moving = sq > 0
    speed = xp.sqrt(xp.where(moving, sq, 1.0))      # double where: finite gradients
    vhat = vel / speed[:, None]
    along = dot(acc, vhat)
    cut = xp.where(moving & (speed >= v_max) & (along > 0), along, 0.0)
    return acc - cut[:, None] * vhat


class SingleIntegrator(Block):
    """N holonomic agents with velocity input, in 2D or 3D.

    Ports
    -----
    velocity : in, (N, dim) [m/s]
        Velocity set-point (not direct feedthrough).
    position : out, (N, dim) [m]

    State
    -----
    position : continuous (N, dim).

    Parameters
    ----------
    position0 : array_like, (N, dim)
        Initial positions.
    dim : {2, 3}, optional
        Space dimension (default: from ``position0``).
    v_max : float or (N,), optional
        Speed limit [m/s] (norm, default: none). Numeric parameter, (N,).

    Equations
    ---------
    ``dp/dt = u min(1, v_max / |u|)`` (module docstring).

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.SingleIntegrator(np.zeros((1, 2)), v_max=1.0)
    >>> b.derivative(0, b.initial_state(), {"velocity": np.array([[3.0, 4.0]])}, np)
    {'position': array([[0.6, 0.8]])}
    """

    def __init__(self, position0, *, dim=None, v_max=np.inf):
        super().__init__()
        name = "SingleIntegrator"
        p0, self.dim = _dim(position0, dim, name)
        self.n = n = p0.shape[0]
        self.declare_parameter("v_max", limit(v_max, n, name, "v_max"), bounds=(0, None),
                               allow_inf=True, unit="m/s")
        labels = ("x", "y", "z")[: self.dim]
        self.declare_continuous_state("position", p0, unit="m", labels=labels)
        self.declare_input("velocity", (n, self.dim), unit="m/s", labels=labels,
                           doc="velocity set-point", feedthrough=False)
        self.declare_output("position", (n, self.dim), unit="m", labels=labels)

    def output(self, t, x, u, xp):
        return {"position": x["position"]}

    def derivative(self, t, x, u, xp):
        v = u["velocity"]
        if self.param_flag("limited", xp, any_finite, "v_max"):
            v = clip_norm(v, self.v_max, xp)
        return {"position": v}


class DoubleIntegrator(Block):
    """N holonomic point masses with acceleration (or force) input, 2D or 3D.

    Ports
    -----
    accel : in, (N, dim) [m/s^2]
        Acceleration command (``input="accel"``, default), or
    force : in, (N, dim) [N]
        Force (``input="force"``), divided by ``mass``.
    position : out, (N, dim) [m]
    velocity : out, (N, dim) [m/s]

    State
    -----
    position, velocity : continuous (N, dim).

    Parameters
    ----------
    position0 : array_like, (N, dim)
    velocity0 : array_like, (dim,) or (N, dim), optional (default zero)
    dim : {2, 3}, optional (default: from ``position0``)
    input : {"accel", "force"}
    mass : float or (N,), optional
        [kg] (default 1).
    drag : float or (N,), optional
        Linear drag coefficient c [N s/m] (default 0).
    a_max, v_max : float or (N,), optional
        Acceleration and speed limits (norms; default none).

    Numeric parameters
    ------------------

    ``mass``, ``drag``, ``a_max`` and ``v_max`` are numeric parameters of
    shape (N,); ``input`` and ``dim`` are structural.

    Equations
    ---------
    See the module docstring.

    Examples
    --------
    >>> import numpy as np, avblocks as av
    >>> b = av.vehicles.DoubleIntegrator(np.zeros((1, 3)))
    >>> b.derivative(0, b.initial_state(), {"accel": np.ones((1, 3))}, np)["velocity"]
    array([[1., 1., 1.]])
    """

    def __init__(self, position0, *, velocity0=0.0, dim=None, input="accel",
                 mass=1.0, drag=0.0, a_max=np.inf, v_max=np.inf):
        super().__init__()
        name = "DoubleIntegrator"
        p0, self.dim = _dim(position0, dim, name)
        self.n = n = p0.shape[0]
        if input not in ("accel", "force"):
            raise ParameterError("unknown input kind", block=name, param="input",
                                 expected="'accel' or 'force'", found=input)
        self.input = input
        v0 = agent_array(velocity0, n, name, "velocity0", (self.dim,))
        dp = self.declare_parameter
        dp("mass", agent_array(mass, n, name, "mass", positive=True),
           bounds=(1e-12, None), unit="kg")
        dp("drag", agent_array(drag, n, name, "drag", nonnegative=True),
           bounds=(0, None), unit="N s/m")
        dp("a_max", limit(a_max, n, name, "a_max"), bounds=(0, None), allow_inf=True,
           unit="m/s^2")
        dp("v_max", limit(v_max, n, name, "v_max"), bounds=(0, None), allow_inf=True,
           unit="m/s")
        labels = ("x", "y", "z")[: self.dim]
        self.declare_continuous_state("position", p0, unit="m", labels=labels)
        self.declare_continuous_state("velocity", v0, unit="m/s", labels=labels)
        if input == "accel":
            self.declare_input("accel", (n, self.dim), unit="m/s^2", labels=labels,
                               doc="acceleration command", feedthrough=False)
        else:
            self.declare_input("force", (n, self.dim), unit="N", labels=labels,
                               doc="applied force", feedthrough=False)
        self.declare_output("position", (n, self.dim), unit="m", labels=labels)
        self.declare_output("velocity", (n, self.dim), unit="m/s", labels=labels)

    def output(self, t, x, u, xp):
        return {"position": x["position"], "velocity": x["velocity"]}

    def derivative(self, t, x, u, xp):
        vel = x["velocity"]
        a = u["accel"] if self.input == "accel" else u["force"] / self.mass[:, None]
        if self.param_flag("alim", xp, any_finite, "a_max"):
            a = clip_norm(a, self.a_max, xp)
        if self.param_flag("vlim", xp, any_finite, "v_max"):
            a = speed_limited_accel(vel, a, self.v_max, xp)
        if self.param_flag("drag", xp, np.any, "drag"):
            a = a - (self.drag / self.mass)[:, None] * vel
        return {"position": vel, "velocity": a}
