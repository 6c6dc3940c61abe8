"""Reference solution of lab 5 (kept with the tests, not in the template).

Lab 5: collision avoidance with a safety filter. Write
`safety_filter_pair`, then run `avblocks lab check 5 lab5_safety.py`.

Agents are single integrators, dp_i/dt = u_i. A nominal law (going to a
goal, flocking) proposes u_nom; the filter changes it as little as
possible so that no two agents come closer than `radius`. For agent i and
its neighbour j the barrier

    h_ij = |p_i - p_j|^2 - radius^2        (>= 0: safe)

stays non-negative when dh_ij/dt >= -gamma h_ij (a control barrier
function; Wang, Ames and Egerstedt 2017). dh/dt = 2 (p_i - p_j).(u_i - u_j):
each agent takes half of the constraint,

    a . u_i >= b,     a = p_i - p_j,   b = -gamma h_ij / 4,

and the velocity closest to u_nom that meets it is the projection

    u_i = u_nom_i + max(0, b - a . u_nom_i) a / |a|^2.

Here every agent filters against its nearest neighbour only (the block
below finds it); the library's controllers.CollisionAvoidance filters
against all of them at once (a quadratic program).

Rules of the library: the agent axis comes first, compute with `xp`, never
loop over agents, never write into the inputs.
"""

import numpy as np

import avblocks as av


def safety_filter_pair(position, u_nom, neighbor, radius, gamma, xp=np):
    """(N, D) filtered velocities.

    position, u_nom (N, D); neighbor (N,) int, the index j of each agent's
    neighbour (-1: none, then u_nom passes unchanged); radius > 0 the
    safety distance [m]; gamma > 0 the barrier gain [1/s].
    """
    has = neighbor >= 0
    a = position[xp.where(has, neighbor, 0)] - position
    h = xp.sum(a * a, axis=-1) - radius * radius
    b = -gamma * h / 4
    short = xp.maximum(0.0, b - xp.sum(a * u_nom, axis=-1))
    a2 = xp.maximum(xp.sum(a * a, axis=-1), 1e-300)
    return xp.where(has[:, None], u_nom + (short / a2)[:, None] * a, u_nom)


class MySafetyFilter(av.Block):
    """Filters N nominal velocities against each agent's nearest neighbour
    (already written: it calls safety_filter_pair).

    Ports: position (N, D) in; velocity_nom (N, D) in; velocity (N, D) out.
    """

    def __init__(self, n, radius, gamma=1.0, dim=2):
        super().__init__()
        self.n, self.radius, self.gamma = n, float(radius), float(gamma)
        self.declare_input("position", (n, dim), unit="m")
        self.declare_input("velocity_nom", (n, dim), unit="m/s")
        self.declare_output("velocity", (n, dim), unit="m/s")

    def output(self, t, x, u, xp):
        p = u["position"]
        diff = p[:, None, :] - p[None, :, :]
        dist = xp.sum(diff * diff, axis=-1) + xp.where(xp.eye(self.n) > 0, xp.inf, 0.0)
        nearest = xp.argmin(dist, axis=1)
        return {"velocity": safety_filter_pair(p, u["velocity_nom"], nearest, self.radius,
                                               self.gamma, xp)}
