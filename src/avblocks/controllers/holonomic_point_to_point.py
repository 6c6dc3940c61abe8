"""Point-to-point motion of holonomic agents (integrators, quadrotors).

Equations
---------
For an agent at ``p`` (D = 2 or 3) with current waypoint ``g``:

    w = sat_{v_max}(K (g - p)),   sat_c(z) = z min(1, c / |z|)

a velocity set-point; ``p`` converges exponentially to ``g`` with rate ``K``
(straight line, capped at ``v_max``). Waypoints advance when ``|g - p| <=
radius``, the same semantics as :class:`~avblocks.controllers.PointToPoint`.

Reference: AVLib paper, Section III.B (point-to-point motion); the holonomic
case of the feedback-linearized law (no off-axis point needed).
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from .point_to_point import declare_goto_parameters, waypoint_array


def _ndim(a):
    try:
        return np.ndim(a)
    except ValueError:          # ragged nested lists
        return -1


def _per_agent_lists(waypoints):
    return (isinstance(waypoints, (list, tuple)) and len(waypoints) > 0
            and all(_ndim(w) == 2 for w in waypoints) and _ndim(waypoints) != 2)


def waypoint_array_nd(waypoints, n, dim, block="HolonomicPointToPoint"):
    """Like :func:`waypoint_array` for D-dimensional waypoints: (N, M, D), (N,)."""
    if dim == 2:
        return waypoint_array(waypoints, n, block)
    if _per_agent_lists(waypoints):
        lists = [np.asarray(w, dtype=float) for w in waypoints]
    else:
        a = np.asarray(waypoints, dtype=float)
        if a.ndim == 1:
            a = a[None]
        lists = [a] * n if a.ndim == 2 else list(a)
    if len(lists) != n or any(w.ndim != 2 or w.shape[1] != dim or len(w) < 1
                              or not np.all(np.isfinite(w)) for w in lists):
        raise ParameterError("wrong waypoints", block=block, param="waypoints",
                             expected=f"(M, {dim}), ({n}, M, {dim}) or {n} lists "
                                      f"(M_i, {dim}) of finite numbers")
    counts = np.array([len(w) for w in lists], dtype=np.int64)
    out = np.empty((n, int(counts.max()), dim))
    for i, w in enumerate(lists):
        out[i, :len(w)] = w
        out[i, len(w):] = w[-1]
    return out, counts


def holonomic_point_to_point_law(position, goal, gain, v_max, xp=np):
    """Velocity set-point ``sat_{v_max}(K (goal - position))``, (N, D)."""
    w = gain[..., None] * (goal - position) if np.ndim(gain) else gain * (goal - position)
    norm = xp.sqrt(xp.sum(w * w, axis=-1))
    scale = xp.minimum(1.0, v_max / xp.maximum(norm, 1e-300))
    return w * scale[:, None]


class HolonomicPointToPoint(Block):
    """Drives N holonomic agents through their waypoints.

    Ports
    -----
    position : in, (N, D) — agent positions (D = 2 or 3).
    velocity : out, (N, D) — velocity set-point.
    target : out, (N, D) — current waypoint.
    done : out, (N,) bool — last waypoint reached.

    State
    -----
    wp : discrete (N,) int — current waypoint, advanced at major steps.

    Parameters
    ----------
    waypoints : (M, D), (N, M, D) or list of N (M_i, D)
    n : int, optional (needed when all agents share one list)
    dim : int, 2 or 3 (default: from the waypoints)
    gain, v_max : float or (N,) > 0;  radius : float > 0 (m).

    Numeric parameters
    ------------------

    ``waypoints`` (padded (N, M, D); the counts are structural), ``gain``,
    ``v_max`` and ``radius`` are numeric parameters.
    """

    def __init__(self, waypoints, *, n=None, dim=None, gain=1.0, v_max=1.0, radius=0.2):
        super().__init__()
        name = "HolonomicPointToPoint"
        shared = not _per_agent_lists(waypoints)
        if dim is None:
            first = np.asarray(waypoints[0] if not shared else waypoints, dtype=float)
            dim = first.shape[-1]
        if dim not in (2, 3):
            raise ParameterError("dim must be 2 or 3", block=name, param="dim", found=dim)
        if n is None:
            if not shared:
                n = len(waypoints)
            elif _ndim(waypoints) == 3:
                n = np.shape(waypoints)[0]
            else:
                raise ParameterError("n (number of agents) is needed when all agents "
                                     "share one waypoint list", block=name, param="n")
        self.n = n = int(n)
        self.dim = dim
        wps, self.counts = waypoint_array_nd(waypoints, n, dim, name)
        self.declare_parameter("waypoints", wps, unit="m",
                               doc="(N, M, D), padded with each agent's last waypoint")
        declare_goto_parameters(self, n, gain, v_max, radius, name)
        self._rows = np.arange(n)
        self._last = self.counts - 1
        self.declare_discrete_state("wp", np.zeros(n, dtype=np.int64))
        self.declare_input("position", (n, dim), unit="m")
        self.declare_output("velocity", (n, dim), unit="m/s")
        self.declare_output("target", (n, dim), unit="m")
        self.declare_output("done", (n,), "bool")

    @property
    def wps(self):
        """The padded (N, M, D) waypoint array (the ``waypoints`` parameter)."""
        return self.waypoints

    def _goal(self, wp, xp):
        return self.waypoints[self._rows, wp]

    def output(self, t, x, u, xp):
        goal = self._goal(x["wp"], xp)
        p = u["position"]
        vel = holonomic_point_to_point_law(p, goal, self.gain, self.v_max, xp)
        dist = xp.sqrt(xp.sum((goal - p) ** 2, axis=-1))
        done = (x["wp"] == self._last) & (dist <= self.radius)
        return {"velocity": vel, "target": goal, "done": done}

    def update(self, t, x, u, xp):
        wp = x["wp"]
        goal = self._goal(wp, xp)
        dist = xp.sqrt(xp.sum((goal - u["position"]) ** 2, axis=-1))
        return {"wp": xp.where((dist <= self.radius) & (wp < self._last), wp + 1, wp)}
