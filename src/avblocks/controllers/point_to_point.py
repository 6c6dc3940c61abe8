"""Point-to-point motion through waypoints by feedback linearization.

Equations
---------
For a unicycle at (x, y, theta) the point at distance d ahead,
``p = (x + d cos theta, y + d sin theta)``, has velocity

    dp/dt = R(theta) diag(1, d) [v, omega]^T,

an invertible map for d != 0. Commanding ``dp/dt = w`` with
``w = sat_{v_max}(K (g - p))`` (g the current waypoint) therefore gives

    v     =  cos(theta) w_x + sin(theta) w_y
    omega = (-sin(theta) w_x + cos(theta) w_y) / d

and p converges exponentially to g with rate K (until the saturation).

Reference: AVLib paper, Section III.B (point-to-point by feedback
linearization); Lawton, Beard & Young (2003), "A decentralized approach to
formation maneuvers", IEEE Trans. Robotics and Automation 19(6), for the
off-axis point.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.memo import shared
from ..core.params import agent_array, positive_scalar
from ..utility.angles import heading_trig
from ..utility.arrays import columns


def _per_agent_lists(w) -> bool:
    """True for a list of per-agent (M_i, 2) waypoint arrays."""
    if not isinstance(w, (list, tuple)) or not w:
        return False
    try:
        return all(np.asarray(e, dtype=float).ndim == 2 for e in w)
    except (TypeError, ValueError):
        return False


def waypoint_array(waypoints, n, block="PointToPoint"):
    """Normalize waypoints to a padded (N, M, 2) array and counts (N,).

    Accepts one list (M, 2) shared by all agents, an (N, M, 2) array, or a
    list of N arrays (M_i, 2) of different lengths (padded with the last one).
    """
    if _per_agent_lists(waypoints):
        lists = [np.asarray(w, dtype=float) for w in waypoints]
        if len(lists) != n:
            raise ParameterError("one waypoint list per agent", block=block,
                                 param="waypoints", expected=n, found=len(lists))
    else:
        try:
            a = np.asarray(waypoints, dtype=float)
        except (TypeError, ValueError):
            raise ParameterError("waypoints must be numeric", block=block,
                                 param="waypoints") from None
        if a.ndim == 1 and a.shape == (2,):
            a = a[None]
        if a.ndim == 2 and a.shape[1] == 2:
            lists = [a] * n
        elif a.ndim == 3 and a.shape[0] == n and a.shape[2] == 2:
            lists = list(a)
        else:
            raise ParameterError("wrong shape", block=block, param="waypoints",
                                 expected=f"(M, 2), ({n}, M, 2) or a list of {n} "
                                          "(M_i, 2) arrays", found=a.shape)
    counts = np.array([len(w) for w in lists], dtype=np.int64)
    if np.any(counts < 1):
        raise ParameterError("every agent needs at least one waypoint", block=block,
                             param="waypoints")
    for w in lists:
        if w.ndim != 2 or w.shape[1] != 2 or not np.all(np.isfinite(w)):
            raise ParameterError("each waypoint list must be a finite (M, 2) array",
                                 block=block, param="waypoints", found=w.shape)
    m = int(counts.max())
    out = np.empty((n, m, 2))
    for i, w in enumerate(lists):
        out[i, :len(w)] = w
        out[i, len(w):] = w[-1]
    return out, counts


def declare_goto_parameters(block, n, gain, v_max, radius, name):
    """Declare the numeric parameters every go-to-waypoint law has: ``gain``
    (N,) [1/s], ``v_max`` (N,) [m/s, inf allowed] and the arrival
    ``radius`` [m]."""
    block.declare_parameter("gain", agent_array(gain, n, name, "gain", positive=True),
                            bounds=(1e-12, None), unit="1/s")
    block.declare_parameter("v_max", agent_array(v_max, n, name, "v_max", positive=True),
                            bounds=(1e-12, None), allow_inf=True, unit="m/s")
    block.declare_parameter("radius", positive_scalar(radius, name, "radius"),
                            bounds=(1e-12, None), unit="m")


def point_to_point_law(pose, goal, d, gain, v_max, xp=np, radius=None):
    """(v, omega) driving the off-axis point of each unicycle to ``goal``.

    ``pose`` (N, 3), ``goal`` (N, 2), ``d``, ``gain``, ``v_max`` scalars or (N,).
    With ``radius`` also returns whether each point is within it of its goal.
    """
    c, s = shared(heading_trig, pose, xp)
    if xp is np:
        return _law_np(pose, goal, c, s, d, gain, v_max, radius)
    ex = goal[:, 0] - pose[:, 0] - d * c
    ey = goal[:, 1] - pose[:, 1] - d * s
    # |K e| saturated at v_max: w = K e * min(1, v_max / (K |e|))
    e2 = ex * ex + ey * ey
    k = xp.minimum(gain, v_max / xp.maximum(xp.sqrt(e2), 1e-300))
    wx, wy = k * ex, k * ey
    cmd = columns(xp, c * wx + s * wy, (c * wy - s * wx) * (1.0 / d))
    if radius is None:
        return cmd
    return cmd, e2 <= radius * radius


def _law_np(pose, goal, c, s, d, gain, v_max, radius):
    """:func:`point_to_point_law` under NumPy: the same operations in the
    same order (the same values, bit for bit), in five buffers instead of
    about twenty temporaries (W1 at N = 10^3: each allocation is a few
    tenths of a microsecond of a step of about 100)."""
    ex = goal[:, 0] - pose[:, 0]
    t = np.multiply(d, c)
    ex -= t                              # ex = g_x - x - d c
    ey = goal[:, 1] - pose[:, 1]
    np.multiply(d, s, out=t)
    ey -= t
    e2 = ex * ex
    np.multiply(ey, ey, out=t)
    e2 += t
    k = np.sqrt(e2)                      # k = min(K, v_max / max(|e|, tiny))
    np.maximum(k, 1e-300, out=k)
    np.divide(v_max, k, out=k)
    np.minimum(gain, k, out=k)
    wx = np.multiply(k, ex, out=ex)
    wy = np.multiply(k, ey, out=ey)
    cmd = np.empty((c.shape[0], 2))
    np.multiply(c, wx, out=t)
    np.multiply(s, wy, out=k)
    np.add(t, k, out=cmd[:, 0])          # v = c wx + s wy
    np.multiply(c, wy, out=t)
    np.multiply(s, wx, out=k)
    t -= k
    np.multiply(t, 1.0 / d, out=cmd[:, 1])   # omega = (c wy - s wx) / d
    if radius is None:
        return cmd
    return cmd, e2 <= radius * radius


class PointToPoint(Block):
    """Drives N unicycles, each through its own list of waypoints.

    Ports
    -----
    pose : in, (N, 3) — vehicle poses (direct feedthrough).
    cmd : out, (N, 2) — (v, omega) for a unicycle-family vehicle.
    target : out, (N, 2) — the waypoint each agent is heading to.
    arrived : out, (N,) bool — the controlled point is within ``radius`` of
        its current target.
    done : out, (N,) bool — true once the last waypoint has been reached
        (latched; set at the major step where the arrival is detected and
        visible from the next one).

    State
    -----
    wp : discrete (N,) int — index of the current waypoint, advanced at major
    steps when the controlled point is within ``radius`` of it. The agent
    holds at its last waypoint.
    done : discrete (N,) bool — latched arrival at the last waypoint.

    Parameters
    ----------
    waypoints : (M, 2), (N, M, 2) or list of N (M_i, 2)
    n : int, optional
        Number of agents (needed when ``waypoints`` is shared).
    d : float
        Distance of the controlled point ahead of the axle (m), > 0.
    gain : float or (N,)
        Convergence rate K (1/s).
    v_max : float or (N,)
        Speed limit of the controlled point (m/s).
    radius : float
        Arrival radius (m).

    Numeric parameters
    ------------------

    ``waypoints`` (as the padded (N, M, 2) array; the counts M_i are
    structural), ``d``, ``gain``, ``v_max`` (both (N,)) and ``radius`` are
    numeric parameters: ``"drive.gain"``, ``"drive.waypoints"``...

    Equations: see the module docstring.
    """

    update_uses_outputs = True

    def __init__(self, waypoints, *, n=None, d=0.1, gain=1.0, v_max=1.0, radius=0.2):
        super().__init__()
        if n is None:
            if _per_agent_lists(waypoints):
                n = len(waypoints)
            elif np.ndim(waypoints) == 3:
                n = np.shape(waypoints)[0]
            else:
                raise ParameterError("n (number of agents) is needed when all "
                                     "agents share one waypoint list",
                                     block="PointToPoint", param="n")
        self.n = n = int(n)
        wps, self.counts = waypoint_array(waypoints, n)
        name = "PointToPoint"
        self.declare_parameter("waypoints", wps, bounds=(None, None), unit="m",
                               doc="(N, M, 2), padded with each agent's last waypoint")
        self.declare_parameter("d", positive_scalar(d, name, "d"), bounds=(1e-9, None),
                               unit="m")
        declare_goto_parameters(self, n, gain, v_max, radius, name)
        m = wps.shape[1]
        self._single = m == 1
        self._base = np.arange(n) * m
        self._last = self.counts - 1
        self.declare_discrete_state("wp", np.zeros(n, dtype=np.int64))
        self.declare_discrete_state("done", np.zeros(n, dtype=bool))
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_output("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"))
        self.declare_output("target", (n, 2), unit="m", labels=("x", "y"))
        self.declare_output("arrived", (n,), "bool")
        self.declare_output("done", (n,), "bool")

    @property
    def wps(self):
        """The padded (N, M, 2) waypoint array (the ``waypoints`` parameter)."""
        return self.waypoints

    def _goal(self, wp, xp):
        w = self.waypoints
        if self._single:
            return w[:, 0]
        return xp.take(xp.reshape(w, (-1, 2)), self._base + wp, axis=0)

    def output(self, t, x, u, xp):
        goal = self._goal(x["wp"], xp)
        cmd, arrived = point_to_point_law(u["pose"], goal, self.d, self.gain, self.v_max,
                                          xp, radius=self.radius)
        return {"cmd": cmd, "target": goal, "arrived": arrived, "done": x["done"]}

    def update(self, t, x, u, xp, y):
        wp, reached = x["wp"], y["arrived"]
        if self._single:                # one waypoint: it is the last one
            return {"wp": wp, "done": x["done"] | reached}
        last = wp == self._last
        return {"wp": xp.where(reached & ~last, wp + 1, wp),
                "done": x["done"] | (reached & last)}
