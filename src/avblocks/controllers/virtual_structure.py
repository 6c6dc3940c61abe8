"""A virtual structure for holonomic agents in 3-D (quadrotors, integrators):
:class:`FormationReference` plans each agent's position and velocity in a
formation that flies a circle, :class:`ReferenceTracker` follows the plan
with a velocity command.

Equations
---------
With ``T = max(t - t_g, 0)`` (the formation first forms in place for
``t_g`` = ``gather`` seconds, then flies) and ``w = 2 pi / period``, the
centre is

    c(t) = c0 + (R_c sin wT, R_c (1 - cos wT), h_z sin wT),

``c0`` the mean start position; agent ``i`` has the slot ``q_i = c + o_i``
and is planned at

    p_i = (1 - s) p0_i + s q_i,   s = 3 tau^2 - 2 tau^3,   tau = min(t / t_g, 1),

a smoothstep from its start ``p0_i`` into its slot; the planned velocity
is the exact time derivative. The tracker commands

    v_i = sat_{v_max}(v_ref,i + k (p_ref,i - p_i)),   sat_c(z) = z min(1, c / |z|).

Reference: M. A. Lewis, K.-H. Tan, "High precision formation control of
mobile robots using virtual structures", Autonomous Robots 4, 1997
(the structure as one rigid body whose motion gives every agent's
reference; proportional tracking with feed-forward).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import agent_array, positive_scalar


def _points(value, name, param, n=None):
    a = np.asarray(value, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or len(a) < 1 or (n is not None and len(a) != n):
        raise ParameterError("expected one 3-D point per agent", block=name, param=param,
                             expected=f"({n if n is not None else 'N'}, 3)",
                             found=np.shape(value))
    if not np.all(np.isfinite(a)):
        raise ParameterError("points must be finite", block=name, param=param)
    return a


def virtual_structure_reference(t, start, offsets, path_radius, period, gather, climb,
                                xp=np):
    """Planned ``(position, velocity)``, each (N, 3), of the formation at
    time ``t`` (see the module's equations): ``start`` (N, 3) where the
    plan begins, ``offsets`` (N, 3) the slots around the centre."""
    w0 = 2 * np.pi / period
    w = xp.where(t > gather, w0, 0.0)
    tt = xp.maximum(t - gather, 0.0)
    ps, pc = xp.sin(w0 * tt), xp.cos(w0 * tt)
    c0 = xp.stack([xp.mean(start[:, 0]), xp.mean(start[:, 1]), xp.mean(start[:, 2])])
    c = c0 + xp.stack([path_radius * ps, path_radius * (1.0 - pc), climb * ps])
    cd = w * xp.stack([path_radius * pc, path_radius * ps, climb * pc])
    q, qd = c + offsets, cd + 0.0 * offsets
    tau = xp.minimum(t / gather, 1.0)
    s = 3 * tau**2 - 2 * tau**3
    sd = xp.where(t < gather, (6 * tau - 6 * tau**2) / gather, 0.0)
    return (1 - s) * start + s * q, sd * (q - start) + s * qd


class FormationReference(Block):
    """Planned positions and velocities of a 3-D formation flying a circle (a virtual structure).

    A source block: no inputs. Wire its outputs to a
    :class:`ReferenceTracker` (or any law taking a reference position and
    velocity).

    Ports
    -----
    position : out, (N, 3) [m]
        Each agent's planned position.
    velocity : out, (N, 3) [m/s]
        Its time derivative.

    Parameters
    ----------
    start : array_like, (N, 3)
        Start positions [m]: the plan begins there.
    offsets : array_like, (N, 3)
        Each agent's slot around the formation's centre [m].
    path_radius : float
        The centre flies a circle of this radius [m].
    period : float
        ... in this many seconds [s].
    gather : float
        Blending time from the start into the formation [s]; the circle
        starts after it.
    climb : float
        The centre rises and sinks by this much on the circle [m].

    Numeric parameters
    ------------------

    All six (``start`` and ``offsets`` per agent, the others scalars).

    Equations
    ---------
    See :mod:`avblocks.controllers.virtual_structure`:
    ``c = c0 + (R_c sin wT, R_c (1 - cos wT), h_z sin wT)``, ``T = max(t - t_g, 0)``,
    ``w = 2 pi / period``, ``p_i = (1 - s) p0_i + s (c + o_i)`` with the
    smoothstep ``s = 3 tau^2 - 2 tau^3``, ``tau = min(t / t_g, 1)``; the
    velocity is the exact time derivative.

    References
    ----------
    M. A. Lewis, K.-H. Tan, "High precision formation control of mobile
    robots using virtual structures", Autonomous Robots 4, 1997.

    Examples
    --------
    >>> import numpy as np
    >>> from avblocks.controllers import FormationReference
    >>> ref = FormationReference(np.zeros((2, 3)), [[1, 0, 0], [-1, 0, 0]])
    >>> p, v = ref.output(6.0, {}, {}, np).values()
    >>> p.tolist()
    [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]
    """

    traceable = True
    example = {"start": {"drone_start": {"n": "$agents", "height": 1.5}},
               "offsets": {"crown_offsets": {"n": "$agents"}}}

    def __init__(self, start, offsets, path_radius=1.5, period=24.0, gather=6.0,
                 climb=0.3):
        super().__init__()
        name = "FormationReference"
        p0 = _points(start, name, "start")
        self.n = n = len(p0)
        dp = self.declare_parameter
        dp("start", p0, unit="m", doc="where the plan begins")
        dp("offsets", _points(offsets, name, "offsets", n), unit="m",
           doc="slots around the centre")
        dp("path_radius", positive_scalar(path_radius, name, "path_radius",
                                          allow_zero=True), bounds=(0, None), unit="m")
        dp("period", positive_scalar(period, name, "period"), bounds=(1e-12, None),
           unit="s")
        dp("gather", positive_scalar(gather, name, "gather"), bounds=(1e-12, None),
           unit="s")
        dp("climb", float(climb), (), unit="m")
        self.declare_output("position", (n, 3), unit="m", labels=("x", "y", "z"))
        self.declare_output("velocity", (n, 3), unit="m/s", labels=("x", "y", "z"))

    def output(self, t, x, u, xp):
        p, v = virtual_structure_reference(t, self.start, self.offsets, self.path_radius,
                                           self.period, self.gather, self.climb, xp)
        return {"position": p, "velocity": v}


def reference_tracking_law(position, ref_position, ref_velocity, gain, v_max, xp=np):
    """``sat_{v_max}(v_ref + k (p_ref - p))``, (N, 3)."""
    v = ref_velocity + gain * (ref_position - position)
    sp = xp.sqrt(xp.sum(v * v, axis=-1, keepdims=True))
    return v * xp.minimum(1.0, v_max / xp.maximum(sp, 1e-12))


class ReferenceTracker(Block):
    """Follow planned positions with a velocity command (proportional with feed-forward).

    Ports
    -----
    position : in, (N, 3) [m]
        The agents' positions.
    ref_position : in, (N, 3) [m]
        Planned positions.
    ref_velocity : in, (N, 3) [m/s]
        Planned velocities (feed-forward).
    velocity : out, (N, 3) [m/s]
        Velocity set-point, e.g. for a velocity-controlled quadrotor.

    Parameters
    ----------
    n : int
        Number of agents.
    gain : float or (N,)
        Position gain k [1/s].
    v_max : float or (N,)
        Largest commanded speed [m/s].

    Numeric parameters
    ------------------

    ``gain`` and ``v_max`` (N,).

    Equations
    ---------
    ``v = v_ref + k (p_ref - p)``, scaled to ``|v| <= v_max``. With
    ``|v| < v_max`` the error ``e = p_ref - p`` of an agent that follows
    its set-point obeys ``de/dt = -k e``.

    References
    ----------
    M. A. Lewis, K.-H. Tan, "High precision formation control of mobile
    robots using virtual structures", Autonomous Robots 4, 1997.
    """

    traceable = True
    example = {"n": "$agents", "gain": 1.5, "v_max": 1.5}

    def __init__(self, n, gain=1.5, v_max=1.5):
        super().__init__()
        name = "ReferenceTracker"
        self.n = n = int(n)
        self.declare_parameter("gain", agent_array(gain, n, name, "gain", positive=True),
                               bounds=(1e-12, None), unit="1/s")
        self.declare_parameter("v_max", agent_array(v_max, n, name, "v_max",
                                                    positive=True),
                               bounds=(1e-12, None), allow_inf=True, unit="m/s")
        for p, unit in (("position", "m"), ("ref_position", "m"), ("ref_velocity", "m/s")):
            self.declare_input(p, (n, 3), unit=unit)
        self.declare_output("velocity", (n, 3), unit="m/s")

    def output(self, t, x, u, xp):
        return {"velocity": reference_tracking_law(
            u["position"], u["ref_position"], u["ref_velocity"], self.gain[:, None],
            self.v_max[:, None], xp)}
