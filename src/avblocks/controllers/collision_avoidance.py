r"""Collision avoidance: a control-barrier-function safety filter.

Equations
---------
For single integrators ``p_i' = u_i`` and safety radius ``D_s`` the pairwise
barrier ``h_ij = |p_i - p_j|^2 - D_s^2 >= 0`` stays non-negative if
``dh_ij/dt >= -gamma h_ij``, i.e. ``2 (p_i - p_j)^T (u_i - u_j) >= -gamma h_ij``.
Each agent takes half of every pair's responsibility (decentralised) and
solves its own small QP, the minimal change of its nominal velocity:

.. math::

    u_i = \arg\min_u |u - \hat u_i|^2 \quad\text{s.t.}\quad
          -(p_i - p_j)^T u \le \tfrac{\gamma}{4} h_{ij},\ j \in N_i

(both agents' constraints add up to the pairwise one). With ``h_ij > 0``,
``u = 0`` is feasible, so the QP always has a solution while the agents are
safe.

Exact vectorised solution: the optimum of a QP in ``R^D`` with linear
constraints is the projection of ``\hat u`` onto the affine span of at most
``D`` active constraints. The block enumerates every subset of at most ``D``
of the (at most ``K``) constraints, projects, keeps the feasible candidates
and returns the nearest one, which is the optimum (it is among the
candidates and every candidate is feasible). Cost ``O(K^D)`` candidates per
agent, all agents at once, no solver loop. If no candidate is feasible
(only possible once agents are already closer than ``D_s``), the candidate
with the smallest worst violation is used.

Unicycles: filter the velocities of their off-axis points (positions from
:class:`OffAxisPoint`, output to :class:`HolonomicToUnicycle`); the body
centres then stay ``D_s - 2 d`` apart.

Reference: L. Wang, A. D. Ames & M. Egerstedt, "Safety barrier certificates
for collisions-free multirobot systems", IEEE T-RO 33(3), 2017; U. Borrmann
et al., "Control barrier certificates for safe swarm behavior", ADHS 2015.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar
from ._graph import NeighborSource, gather


def _subsets(k, dim):
    return [np.array(c, dtype=np.int64) for m in range(1, dim + 1)
            for c in itertools.combinations(range(k), m)]


def min_norm_qp(u_nom, a, b, mask, xp=np, tol=1e-9):
    """Exact ``argmin |u - u_nom|^2 s.t. a_k . u <= b_k`` (k where ``mask``).

    ``u_nom`` (N, D), ``a`` (N, K, D), ``b`` (N, K), ``mask`` (N, K) bool.
    Enumerates active sets of size <= D (see the module docstring). A set of
    ``D`` constraints is solved as the square system ``A_s u = b_s`` itself
    (the vertex), not through its Gram matrix, whose condition number is
    the square of it: nearly antiparallel constraints (the corner of a thin
    wedge) stay exact. Feasibility is tested to ``tol`` relative to the size
    of each constraint (``|a_k| |u| + |b_k|``).
    """
    n, k, dim = a.shape
    big = 1e300
    bm = xp.where(mask, b, big)
    a = xp.where(mask[..., None], a, 0.0)
    b0 = xp.where(mask, b, 0.0)
    cands, valid = [u_nom], [xp.ones(n, dtype=bool)]
    for s in _subsets(k, dim):
        a_s = a[:, s, :]                                   # (N, m, D)
        b_s = b0[:, s]
        m = len(s)
        if m == dim:
            # the vertex: A_s u = b_s (condition number of A_s, not A_s A_s^T)
            if dim == 2:
                det = a_s[:, 0, 0] * a_s[:, 1, 1] - a_s[:, 0, 1] * a_s[:, 1, 0]
                scale = (xp.sqrt(xp.sum(a_s[:, 0] ** 2, -1))
                         * xp.sqrt(xp.sum(a_s[:, 1] ** 2, -1)))
                det_ok = xp.abs(det) > 1e-13 * scale
                dd = xp.where(det_ok, det, 1.0)
                u = xp.stack([(a_s[:, 1, 1] * b_s[:, 0] - a_s[:, 0, 1] * b_s[:, 1]) / dd,
                              (a_s[:, 0, 0] * b_s[:, 1] - a_s[:, 1, 0] * b_s[:, 0]) / dd],
                             axis=-1)
            else:
                det = xp.linalg.det(a_s)
                scale = xp.prod(xp.sqrt(xp.sum(a_s ** 2, -1)), axis=-1)
                det_ok = xp.abs(det) > 1e-13 * scale
                as_ = xp.where(det_ok[:, None, None], a_s, xp.eye(m))
                u = xp.linalg.solve(as_, b_s[..., None])[..., 0]
            # a vertex is the optimum of its set only when the multipliers
            # are >= 0; the nearest-feasible choice below settles that
            good = xp.all(mask[:, s], axis=1) & det_ok
            cands.append(xp.where(good[:, None], u, u_nom))
            valid.append(good)
            continue
        r = xp.sum(a_s * u_nom[:, None, :], axis=-1) - b_s
        g = xp.einsum("nid,njd->nij", a_s, a_s)             # (N, m, m)
        if m == 1:
            det_ok = g[:, 0, 0] > 1e-300
            lam = (r[:, 0] / xp.where(det_ok, g[:, 0, 0], 1.0))[:, None]
        else:                                              # m = 2 < D = 3
            det = g[:, 0, 0] * g[:, 1, 1] - g[:, 0, 1] * g[:, 1, 0]
            det_ok = xp.abs(det) > 1e-13 * g[:, 0, 0] * g[:, 1, 1]
            dd = xp.where(det_ok, det, 1.0)
            lam = xp.stack([(g[:, 1, 1] * r[:, 0] - g[:, 0, 1] * r[:, 1]) / dd,
                            (g[:, 0, 0] * r[:, 1] - g[:, 1, 0] * r[:, 0]) / dd], axis=-1)
        good = xp.all(mask[:, s], axis=1) & det_ok
        cands.append(xp.where(good[:, None], u_nom - xp.sum(lam[..., None] * a_s, axis=1),
                              u_nom))
        valid.append(good)
    c = xp.stack(cands, axis=1)                            # (N, C, D)
    ok = xp.stack(valid, axis=1)                           # (N, C)
    viol = xp.einsum("nkd,ncd->nck", a, c) - bm[:, None, :]   # (N, C, K)
    anorm = xp.sqrt(xp.sum(a * a, axis=-1))                # (N, K)
    cnorm = xp.sqrt(xp.sum(c * c, axis=-1))                # (N, C)
    size = anorm[:, None, :] * cnorm[:, :, None] + xp.abs(b0)[:, None, :] + 1.0
    rel = viol / size
    worst = xp.max(xp.where(mask[:, None, :], rel, -big), axis=-1)
    worst = xp.where(ok, worst, big)
    dist = xp.sum((c - u_nom[:, None, :]) ** 2, axis=-1)
    dist = xp.where(ok & (worst <= tol), dist, xp.inf)
    best = xp.argmin(dist, axis=1)
    pick = xp.where(xp.isfinite(xp.min(dist, axis=1)), best, xp.argmin(worst, axis=1))
    return xp.take_along_axis(c, pick[:, None, None], axis=1)[:, 0, :]


def safety_filter(position, u_nom, idx, radius, gamma=1.0, right_hand=0.0, xp=np):
    """CBF-filtered velocities (N, D) for neighbour lists ``idx`` (N, K).

    ``right_hand > 0`` (2-D only) first adds ``right_hand`` times the nominal
    velocity turned 90 degrees clockwise for agents with a neighbour closer
    than ``2 radius``: a roundabout rule that breaks the symmetric deadlocks
    of the pure filter (e.g. antipodal swaps).
    """
    pj, mask = gather(position, idx, xp)
    dp = position[:, None, :] - pj                         # p_i - p_j
    d2 = xp.sum(dp * dp, axis=-1)
    h = d2 - radius * radius
    if not (isinstance(right_hand, (int, float)) and right_hand == 0):
        near = xp.any(mask & (d2 < 4 * radius * radius), axis=1)
        turn = xp.stack([u_nom[:, 1], -u_nom[:, 0]], axis=-1)
        u_nom = u_nom + xp.where(near[:, None], right_hand * turn, 0.0)
    return min_norm_qp(u_nom, -dp, 0.25 * gamma * h, mask, xp)


class CollisionAvoidance(Block):
    """CBF safety filter for N single integrators (or off-axis points).

    Ports
    -----
    position : in, (N, D), D = 2 or 3.
    velocity_nominal : in, (N, D) — desired velocities.
    neighbors : in, (N, K) int64 (port mode only) — agents that may come close;
        use a sensing range well above ``radius`` (K small: cost grows as K^D).
    velocity : out, (N, D) — the minimally modified, safe velocities.

    Parameters
    ----------
    n : int;  radius : float > 0 — safety distance D_s (m).
    gamma : float > 0 — barrier gain (1/s).
    right_hand : float >= 0 — roundabout bias against deadlocks (2-D; see
        :func:`safety_filter`), default 0 (pure minimal filter).
    dim : int (2 or 3);  sensing_range, k_max : compute neighbours inside the
        block (NumPy only) instead of the port.

    ``radius``, ``gamma``, ``right_hand`` (2-D) and ``sensing_range`` (when
    given) are numeric parameters; ``n``, ``dim``, ``k_max`` are structural.
    """

    def __init__(self, n, radius, *, gamma=1.0, right_hand=0.0, dim=2,
                 sensing_range=None, k_max=6):
        super().__init__()
        name = "CollisionAvoidance"
        self.n = n = int(n)
        self.declare_parameter("radius", positive_scalar(radius, name, "radius"),
                               bounds=(1e-12, None), unit="m", doc="safety distance")
        self.declare_parameter("gamma", positive_scalar(gamma, name, "gamma"),
                               bounds=(1e-12, None), unit="1/s")
        if dim not in (2, 3):
            raise ParameterError("dim must be 2 or 3", block=name, param="dim", found=dim)
        self.dim = dim
        rh = positive_scalar(right_hand, name, "right_hand", allow_zero=True)
        if rh and dim != 2:
            raise ParameterError("right_hand needs dim = 2", block=name,
                                 param="right_hand")
        if dim == 2:
            self.declare_parameter("right_hand", rh, bounds=(0, None))
        else:
            self.right_hand = 0.0
        self.declare_input("position", (n, dim), unit="m")
        self.declare_input("velocity_nominal", (n, dim), unit="m/s")
        self.graph = NeighborSource(self, n, radius=sensing_range,
                                    k_max=k_max if sensing_range is not None else None,
                                    radius_param="sensing_range")
        self.declare_output("velocity", (n, dim), unit="m/s")

    def configure(self, inputs):
        self.graph.configure(inputs)

    def output(self, t, x, u, xp):
        p = u["position"]
        idx, _ = self.graph.get(u, p, xp)
        rh = self.right_hand
        if self.dim != 2 or not self.param_flag("rh", xp, np.any, "right_hand"):
            rh = 0.0
        return {"velocity": safety_filter(p, u["velocity_nominal"], idx, self.radius,
                                          self.gamma, rh, xp)}
