r"""Flocking of double integrators: Olfati-Saber (2006), Algorithm 1 (+ gamma).

Equations (R. Olfati-Saber, "Flocking for multi-agent dynamic systems:
algorithms and theory", IEEE TAC 51(3), 2006, Sections II and IV)
-------------------------------------------------------------------
sigma-norm and its gradient, ``eps > 0``:

    ||z||_s = (sqrt(1 + eps |z|^2) - 1) / eps,   sigma_eps(z) = z / sqrt(1 + eps |z|^2)

bump function, ``h in (0, 1)``:

    rho_h(s) = 1 on [0, h),  (1 + cos(pi (s - h) / (1 - h))) / 2 on [h, 1],  0 else

action function with ``r_a = ||r||_s``, ``d_a = ||d||_s``:

    phi(s) = ((a + b) sigma_1(s + c) + (a - b)) / 2,  sigma_1(s) = s / sqrt(1 + s^2),
    c = |a - b| / sqrt(4 a b),   phi_a(s) = rho_h(s / r_a) phi(s - d_a)

Algorithm 1 (alpha-lattice), eq. (23), for agents with ``q' = p, p' = u``:

    u_i^a = c1 sum_{j in N_i} phi_a(||q_j - q_i||_s) sigma_eps(q_j - q_i)
          + c2 sum_{j in N_i} rho_h(||q_j - q_i||_s / r_a) (p_j - p_i)

The optional navigational feedback (gamma agent, Algorithm 2, eq. (24)) adds

    u_i^g = -c1_g (q_i - q_r) - c2_g (p_i - p_r)

for a gamma agent moving at constant velocity, ``q_r(t) = target +
target_velocity t``, ``p_r = target_velocity`` (``gamma=True``). ``N_i`` are the agents
within the interaction range ``r`` (terms vanish beyond ``r`` through
``rho_h``, so a superset of neighbours is harmless). Defaults follow the
paper's simulations: ``eps = 0.1, a = b = 5, h = 0.2, r = 1.2 d``.
Without gamma, Algorithm 1 may fragment; with gamma it forms a flock.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import finite_array, positive_scalar
from ._graph import NeighborSource


def sigma_norm(z, eps, xp=np):
    """``(sqrt(1 + eps |z|^2) - 1) / eps`` over the last axis."""
    return (xp.sqrt(1.0 + eps * xp.sum(z * z, axis=-1)) - 1.0) / eps


def bump(s, h, xp=np):
    """Olfati-Saber's bump ``rho_h(s)``."""
    mid = 0.5 * (1.0 + xp.cos(np.pi * (s - h) / (1.0 - h)))
    return xp.where(s < h, 1.0, xp.where(s <= 1.0, mid, 0.0)) * (s >= 0)


def phi_alpha(s, r_a, d_a, a, b, h, xp=np):
    """Pairwise action ``rho_h(s / r_a) phi(s - d_a)`` on sigma-distances ``s``."""
    c = abs(a - b) / xp.sqrt(4.0 * a * b)
    z = s - d_a + c
    phi = 0.5 * ((a + b) * z / xp.sqrt(1.0 + z * z) + (a - b))
    return bump(s / r_a, h, xp) * phi


def flocking_law(position, velocity, idx, d, r, *, eps=0.1, a=5.0, b=5.0, h=0.2,
                 c1=1.0, c2=1.0, xp=np):
    """Olfati-Saber's u^alpha (N, D) for neighbour lists ``idx`` (N, K).

    The bump is evaluated once and the unit vectors ``sigma_eps`` are folded
    into (N, K) weights: fewer (N, K, D) temporaries than the equations
    written term by term.
    """
    r_a = (xp.sqrt(1.0 + eps * r * r) - 1.0) / eps
    d_a = (xp.sqrt(1.0 + eps * d * d) - 1.0) / eps
    mask = idx >= 0
    safe = xp.where(mask, idx, xp.arange(position.shape[0])[:, None])
    dq = position[safe] - position[:, None, :]                # (N, K, D)
    nrm2 = xp.sum(dq * dq, axis=-1)
    root = xp.sqrt(1.0 + eps * nrm2)
    s = (root - 1.0) / eps
    x = s / r_a                                               # >= 0: bump inline
    rho = xp.where(x < h, 1.0, xp.where(
        x <= 1.0, 0.5 * (1.0 + xp.cos(np.pi * (x - h) / (1.0 - h))), 0.0))
    c = abs(a - b) / xp.sqrt(4.0 * a * b)
    z = s - d_a + c
    phi = 0.5 * ((a + b) * z / xp.sqrt(1.0 + z * z) + (a - b))
    w_q = xp.where(mask, rho * phi / root, 0.0)                # phi_a sigma_eps weight
    w_p = xp.where(mask, rho, 0.0)                             # a_ij
    return (c1 * xp.sum(w_q[..., None] * dq, axis=1)
            + c2 * xp.sum(w_p[..., None] * (velocity[safe] - velocity[:, None, :]),
                          axis=1))


def order_parameter(velocity, xp=np):
    """Velocity alignment ``|sum_i p_i| / sum_i |p_i|`` in [0, 1] (1: aligned)."""
    return xp.sqrt(xp.sum(xp.sum(velocity, axis=0) ** 2)) / xp.maximum(
        xp.sum(xp.sqrt(xp.sum(velocity * velocity, axis=-1))), 1e-300)


class Flocking(Block):
    """Olfati-Saber flocking (alpha-lattice) for N double integrators.

    Ports
    -----
    position, velocity : in, (N, D).
    neighbors : in, (N, K) int64 (port mode only; e.g. agents within ``r``).
    accel : out, (N, D) — acceleration command ``u^alpha (+ u^gamma)``.

    Parameters
    ----------
    n : int;  dim : int (default 2);  d : float > 0 — lattice distance (m).
    r : float > d — interaction range (default 1.2 d).
    eps, a, b, h, c1, c2 : law constants (module docstring).
    gamma : bool — add the navigational term towards ``target``.
    target : (D,) or (N, D); target_velocity : same; c1_gamma, c2_gamma.
    radius mode: ``neighbors="internal"`` with ``k_max`` computes neighbours
    within ``r`` inside the block (compiles: ``utility.spatial``); ``adjacency``
    a fixed graph.

    ``d``, ``r``, ``eps``, ``a``, ``b``, ``h``, ``c1``, ``c2``, ``target``,
    ``target_velocity`` (both (N, D)), ``c1_gamma`` and ``c2_gamma`` are
    numeric parameters (``"flock.c1"``...; the constraints ``r > d`` and
    ``a <= b`` are checked at construction only); ``gamma``, ``neighbors``,
    ``k_max``, ``adjacency``, ``n`` and ``dim`` are structural.

    Reference: R. Olfati-Saber, IEEE TAC 51(3):401-420, 2006, Algorithm 1
    (and the gamma term of Algorithm 2).
    """

    def __init__(self, n, d, *, r=None, dim=2, eps=0.1, a=5.0, b=5.0, h=0.2,
                 c1=1.0, c2=1.0, gamma=False, target=0.0, target_velocity=0.0,
                 c1_gamma=0.2, c2_gamma=0.4, neighbors="port", k_max=None,
                 adjacency=None):
        super().__init__()
        name = "Flocking"
        self.n = n = int(n)
        dim = int(dim)
        d = positive_scalar(d, name, "d")
        r = 1.2 * d if r is None else positive_scalar(r, name, "r")
        if r <= d:
            raise ParameterError("interaction range r must exceed d", block=name,
                                 param="r", expected=f"> {d}", found=r)
        a, b = positive_scalar(a, name, "a"), positive_scalar(b, name, "b")
        if a > b:
            raise ParameterError("need 0 < a <= b", block=name, param="a",
                                 expected=f"<= b = {b}", found=a)
        if not 0 < float(h) < 1:
            raise ParameterError("h must lie in (0, 1)", block=name, param="h", found=h)
        dp = self.declare_parameter
        dp("d", d, bounds=(1e-12, None), unit="m", doc="lattice distance")
        dp("r", r, bounds=(1e-12, None), unit="m", doc="interaction range (> d)")
        dp("eps", positive_scalar(eps, name, "eps"), bounds=(1e-12, None))
        dp("a", a, bounds=(1e-12, None))
        dp("b", b, bounds=(1e-12, None))
        dp("h", float(h), bounds=(1e-9, 1 - 1e-9))
        dp("c1", positive_scalar(c1, name, "c1", allow_zero=True), bounds=(0, None))
        dp("c2", positive_scalar(c2, name, "c2", allow_zero=True), bounds=(0, None))
        self.gamma = bool(gamma)
        dp("target", np.broadcast_to(finite_array(target, name, "target"), (n, dim)),
           unit="m")
        dp("target_velocity", np.broadcast_to(
            finite_array(target_velocity, name, "target_velocity"), (n, dim)), unit="m/s")
        dp("c1_gamma", positive_scalar(c1_gamma, name, "c1_gamma", allow_zero=True),
           bounds=(0, None))
        dp("c2_gamma", positive_scalar(c2_gamma, name, "c2_gamma", allow_zero=True),
           bounds=(0, None))
        self.declare_input("position", (n, dim), unit="m")
        self.declare_input("velocity", (n, dim), unit="m/s")
        if neighbors not in ("port", "internal"):
            raise ParameterError("neighbors must be 'port' or 'internal'", block=name,
                                 param="neighbors", found=neighbors)
        radius = r if neighbors == "internal" else None
        self.graph = NeighborSource(self, n, adjacency=adjacency, radius=radius,
                                    k_max=k_max, radius_param="r")
        self.declare_output("accel", (n, dim), unit="m/s^2")

    def configure(self, inputs):
        self.graph.configure(inputs)

    def output(self, t, x, u, xp):
        q, p = u["position"], u["velocity"]
        idx, _ = self.graph.get(u, q, xp)
        acc = flocking_law(q, p, idx, self.d, self.r, eps=self.eps, a=self.a,
                           b=self.b, h=self.h, c1=self.c1, c2=self.c2, xp=xp)
        if self.gamma:
            q_r = self.target + self.target_velocity * t
            acc = acc - self.c1_gamma * (q - q_r) - self.c2_gamma * (
                p - self.target_velocity)
        return {"accel": acc}
