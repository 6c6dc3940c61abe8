"""Reference solution of lab 5 (kept with the tests, not in the template).

Lab 5: collision avoidance with a safety filter, and flocking. Write
`safety_filter_pair` (part 1) and `flocking_alpha` (part 2, below), then
run `avblocks lab check 5 lab5_safety.py`.

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
    a = position - position[xp.where(has, neighbor, 0)]
    h = xp.sum(a * a, axis=-1) - radius * radius
    b = -gamma * h / 4
    short = xp.maximum(0.0, b - xp.sum(a * u_nom, axis=-1))
    a2 = xp.maximum(xp.sum(a * a, axis=-1), 1e-300)
    return xp.where(has[:, None], u_nom + (short / a2)[:, None] * a, u_nom)[:, :1]


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


# ------------------------------------------------------------------ part 2: flocking
# Agents are now double integrators, dq_i/dt = p_i, dp_i/dt = u_i (q the
# position, p the velocity). Olfati-Saber's flocking law (Algorithm 1, eq.
# 23 of "Flocking for multi-agent dynamic systems: algorithms and theory",
# IEEE TAC 51(3), 2006) keeps neighbours at the lattice distance d and
# aligns their velocities:
#
#   sigma-norm      ||z||_s = (sqrt(1 + eps |z|^2) - 1) / eps
#   its gradient    n_ij = (q_j - q_i) / sqrt(1 + eps |q_j - q_i|^2)
#   bump            rho_h(x) = 1 for 0 <= x < h,
#                              (1 + cos(pi (x - h) / (1 - h))) / 2 for h <= x <= 1,
#                              0 otherwise
#   action          phi(z) = ((a + b) sigma_1(z + c) + (a - b)) / 2,
#                   sigma_1(z) = z / sqrt(1 + z^2),  c = |a - b| / sqrt(4 a b)
#                   phi_alpha(s) = rho_h(s / r_a) phi(s - d_a),
#                   r_a = ||r||_s, d_a = ||d||_s (sigma-norms of the numbers r, d)
#
#   u_i = c1 sum_{j != i} phi_alpha(||q_j - q_i||_s) n_ij
#       + c2 sum_{j != i} rho_h(||q_j - q_i||_s / r_a) (p_j - p_i)
#
# The sums run over every other agent: the bump makes the terms of agents
# farther than r exactly zero. The first sum is the gradient of a pairwise
# potential (cohesion beyond d, separation inside it), the second aligns
# velocities.


def flocking_alpha(position, velocity, d, r, eps=0.1, a=5.0, b=5.0, h=0.2, c1=1.0, c2=1.0,
                   xp=np):
    """(N, D) accelerations u_i of the law above.

    position q, velocity p (N, D); d > 0 the lattice distance [m]; r > d the
    interaction range [m]; eps, a <= b, h in (0, 1), c1, c2 the constants.
    """
    dq = position[None, :, :] - position[:, None, :]          # q_j - q_i
    dp = velocity[None, :, :] - velocity[:, None, :]          # p_j - p_i
    root = xp.sqrt(1.0 + eps * xp.sum(dq * dq, axis=-1))      # (N, N)
    s = (root - 1.0) / eps
    r_a = (xp.sqrt(1.0 + eps * r * r) - 1.0) / eps
    d_a = (xp.sqrt(1.0 + eps * d * d) - 1.0) / eps
    x = s / r_a
    rho = xp.where(x < h, 1.0, xp.where(x <= 1.0, 0.5 * (1.0 + xp.cos(
        np.pi * (x - h) / (1.0 - h))), 0.0))
    c = abs(a - b) / np.sqrt(4.0 * a * b)
    z = s - d_a + c
    phi = 0.5 * ((a + b) * z / xp.sqrt(1.0 + z * z) + (a - b))
    grad = xp.sum((rho * phi / root)[:, :, None] * dq, axis=1)
    align = xp.sum(rho[:, :, None] * dp, axis=1)
    return c1 * grad + c2 * align


class MyFlocking(av.Block):
    """Flocking of N double integrators towards a moving target (already
    written: flocking_alpha plus Olfati-Saber's navigational term
    -c1_gamma (q_i - q_r(t)) - c2_gamma (p_i - p_r), q_r(t) = target +
    target_velocity t).

    Ports: position (N, D) in; velocity (N, D) in; accel (N, D) out.
    """

    def __init__(self, n, d, r=None, dim=2, target=0.0, target_velocity=0.0,
                 c1_gamma=0.2, c2_gamma=0.4):
        super().__init__()
        self.d = float(d)
        self.r = 1.2 * self.d if r is None else float(r)
        self.target = np.broadcast_to(np.asarray(target, float), (dim,))
        self.target_velocity = np.broadcast_to(np.asarray(target_velocity, float), (dim,))
        self.c1_gamma, self.c2_gamma = float(c1_gamma), float(c2_gamma)
        self.declare_input("position", (n, dim), unit="m")
        self.declare_input("velocity", (n, dim), unit="m/s")
        self.declare_output("accel", (n, dim), unit="m/s^2")

    def output(self, t, x, u, xp):
        q, p = u["position"], u["velocity"]
        q_r = self.target + self.target_velocity * t
        nav = -self.c1_gamma * (q - q_r) - self.c2_gamma * (p - self.target_velocity)
        return {"accel": flocking_alpha(q, p, self.d, self.r, xp=xp) + nav}
