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

Joint mode (``mode="joint"``)
----------------------------
One QP over all agents' velocities ``u = (u_1, ..., u_N)`` (Wang, Ames &
Egerstedt 2017, the centralised barrier certificate):

.. math::

    u = \arg\min_u \sum_i |u_i - \hat u_i|^2 \quad\text{s.t.}\quad
        -(p_i - p_j)^T (u_i - u_j) \le \tfrac{\gamma}{2} h_{ij}
        \quad (i < j,\ |p_i - p_j| \le r_s)

(``dh_ij/dt = 2 (p_i - p_j)^T (u_i - u_j) >= -gamma h_ij``). The pairs
come from a ``scipy.spatial.cKDTree`` (``query_pairs``, sensing range
``r_s``) or from the union of the neighbour lists of the port; the
constraint matrix is sparse (two ``D``-blocks per row) and the QP is solved
by Clarabel (interior point, sparse, Apache-2.0, wheels for every
platform; chosen over OSQP, whose ADMM iterates are only accurate to about
1e-3 without polishing, and quadprog, which is dense). Unlike the per-agent
split, the joint QP lets one agent give way more than the other, which is
what frees the jams of the split filter. ``u = 0`` is feasible while every
``h_ij >= 0``, so the QP has a solution while the agents are safe.

Deadlocks: the pure joint QP still stops in symmetric configurations
(``\hat u_i`` a non-negative combination of the active constraint normals,
a KKT point at ``u = 0``: e.g. a perfectly symmetric antipodal swap). The
right-hand bias adds ``rho J \hat u_i`` (``J`` the clockwise quarter turn)
to the nominal velocity of every agent with a neighbour closer than
``2 D_s``. In a jam the nominal velocities point at each other, so the
added terms form a consistent rotation of the cluster; a rigid rotation
``u_i = omega J (p_i - c)`` leaves every ``h_ij`` unchanged
(``(p_i - p_j)^T J (p_i - p_j) = 0``), so it is always feasible. With the
biased nominal ``w_i = \hat u_i + rho J \hat u_i`` the cost of
``u = epsilon omega J (p_i - c)`` is ``sum |w_i|^2 - 2 epsilon omega
sum_i w_i^T J (p_i - c) + O(epsilon^2)`` and ``w_i^T J (p_i - c) =
\hat u_i^T J (p_i - c) + rho \hat u_i^T (p_i - c)``. In a jam the nominal
velocities point into the cluster (``\hat u_i^T (p_i - c) < 0``, the
first term vanishes for radial ones), so the derivative is non-zero and
``u = 0`` is not the optimum: the cluster turns instead of stopping.
Turning changes the geometry until each agent's nominal velocity points out of the cluster.
This is an argument for the symmetric jam, not a proof for every
configuration (in floating point the unbiased joint QP often escapes the
symmetric swap as well, through round-off). The tests show the perfectly
symmetric 20-agent swap completing for circle / safety radius ratios 4 to
10 (right-hand bias 1), where the per-agent filter jams, and the jittered
swap scenario completing at Robotarium's ratio 5.88. Note that the bias
adds speed: up to ``sqrt(1 + rho^2)`` times the nominal one.

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


def _clarabel():
    try:
        import clarabel
    except ImportError:
        raise ParameterError("mode='joint' needs the clarabel QP solver",
                             block="CollisionAvoidance", param="mode",
                             hint="pip install 'avblocks[safety]' (or: pip install "
                                  "clarabel), or use mode='agent'") from None
    return clarabel


def joint_min_norm_qp(u_nom, a, b):
    """``argmin sum |u - u_nom|^2 s.t. a @ u.ravel() <= b`` with Clarabel.

    ``u_nom`` (N, D); ``a`` a scipy.sparse (M, N*D) matrix; ``b`` (M,).
    Returns ``(u, status)``: (N, D) and Clarabel's status string.
    """
    import scipy.sparse as sp
    clarabel = _clarabel()
    shape = u_nom.shape
    q = -np.asarray(u_nom, dtype=float).ravel()
    nv = q.size
    if a.shape[0] == 0:
        return np.array(u_nom, dtype=float), "Solved"
    p_mat = sp.identity(nv, format="csc")
    a = sp.csc_matrix(a)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    solver = clarabel.DefaultSolver(p_mat, q, a, np.asarray(b, dtype=float),
                                    [clarabel.NonnegativeConeT(a.shape[0])], settings)
    sol = solver.solve()
    return np.asarray(sol.x, dtype=float).reshape(shape), str(sol.status)


def pair_constraints(position, pairs, radius, gamma):
    """Sparse ``(A, b)`` of the pairwise barrier constraints of the joint QP.

    Row ``r`` for pair ``(i, j)``: ``-(p_i - p_j)^T (u_i - u_j) <= gamma/2 h_ij``.
    """
    import scipy.sparse as sp
    n, dim = position.shape
    m = len(pairs)
    i, j = pairs[:, 0], pairs[:, 1]
    dp = position[i] - position[j]                          # (M, D)
    h = np.sum(dp * dp, axis=1) - radius * radius
    rows = np.repeat(np.arange(m), 2 * dim)
    cols = np.concatenate([i[:, None] * dim + np.arange(dim),
                           j[:, None] * dim + np.arange(dim)], axis=1).ravel()
    vals = np.concatenate([-dp, dp], axis=1).ravel()
    a = sp.csc_matrix((vals, (rows, cols)), shape=(m, n * dim))
    return a, 0.5 * gamma * h


def pairs_in_range(position, sensing_range):
    """(M, 2) int64 pairs ``i < j`` closer than ``sensing_range`` (cKDTree)."""
    from scipy.spatial import cKDTree
    r = float(sensing_range)
    if not np.isfinite(r):
        n = len(position)
        iu = np.triu_indices(n, 1)
        return np.column_stack(iu).astype(np.int64)
    return cKDTree(position).query_pairs(r, output_type="ndarray").astype(np.int64)


def pairs_from_neighbors(idx):
    """(M, 2) unique pairs ``i < j`` from padded neighbour lists (N, K)."""
    idx = np.asarray(idx)
    n, k = idx.shape
    i = np.repeat(np.arange(n), k)
    j = idx.ravel()
    keep = (j >= 0) & (j != i)
    lo, hi = np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])
    if lo.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    return np.unique(np.column_stack([lo, hi]), axis=0).astype(np.int64)


def _right_hand(position, u_nom, pairs, radius, right_hand):
    if right_hand == 0 or len(pairs) == 0:
        return u_nom
    dp = position[pairs[:, 0]] - position[pairs[:, 1]]
    close = np.sum(dp * dp, axis=1) < 4 * radius * radius
    near = np.zeros(len(position), dtype=bool)
    near[pairs[close, 0]] = True
    near[pairs[close, 1]] = True
    turn = np.stack([u_nom[:, 1], -u_nom[:, 0]], axis=-1)
    return u_nom + np.where(near[:, None], right_hand * turn, 0.0)


def joint_safety_filter(position, u_nom, pairs, radius, gamma=1.0, right_hand=0.0):
    """CBF-filtered velocities (N, D) from ONE QP over all agents.

    ``pairs`` (M, 2) int: the constrained pairs (e.g. :func:`pairs_in_range`).
    ``right_hand`` (2-D): the bias of :func:`safety_filter`, applied to the
    nominal velocity of agents with a partner closer than ``2 radius`` (see
    the module docstring for why it frees symmetric jams). NumPy only.
    """
    position = np.asarray(position, dtype=float)
    u_nom = np.asarray(u_nom, dtype=float)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    u_nom = _right_hand(position, u_nom, pairs, float(radius), float(right_hand))
    a, b = pair_constraints(position, pairs, float(radius), float(gamma))
    u, status = joint_min_norm_qp(u_nom, a, b)
    if not np.all(np.isfinite(u)):
        # the solver failed (only seen with agents already overlapping):
        # standing still keeps every h_ij where it is
        return np.zeros_like(u_nom)
    return u


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
        block instead of the port (agent mode compiles: the k nearest from
        a :class:`~avblocks.utility.spatial.NeighborSearch`).
    mode : ``"agent"`` (default) — one small exact QP per agent, half of each
        pair's constraint each (vectorised, JAX-traceable);
        ``"joint"`` — one sparse QP over all agents (Clarabel, NumPy only, not
        traceable; needs the ``safety`` extra). With ``sensing_range`` the
        joint mode takes every pair within range from a k-d tree (``k_max``
        is not used); with the port, the union of the neighbour lists.
        See the module docstring: joint frees jams the split filter keeps.

    ``radius``, ``gamma``, ``right_hand`` (2-D) and ``sensing_range`` (when
    given) are numeric parameters; ``n``, ``dim``, ``k_max`` are structural.
    """

    def __init__(self, n, radius, *, gamma=1.0, right_hand=0.0, dim=2,
                 sensing_range=None, k_max=6, mode="agent"):
        super().__init__()
        name = "CollisionAvoidance"
        if not isinstance(mode, str) or mode not in ("agent", "joint"):
            raise ParameterError("mode must be 'agent' or 'joint'", block=name,
                                 param="mode", found=mode)
        self.mode = mode
        if mode == "joint":
            _clarabel()
            self.traceable = False
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
        if mode == "joint" and sensing_range is not None and k_max is None:
            k_max = 1                       # not used: pairs from a k-d tree
        self.graph = NeighborSource(self, n, radius=sensing_range,
                                    k_max=k_max if sensing_range is not None else None,
                                    radius_param="sensing_range")
        self.declare_output("velocity", (n, dim), unit="m/s")

    def configure(self, inputs):
        self.graph.configure(inputs)

    def output(self, t, x, u, xp):
        p = u["position"]
        rh = self.right_hand
        if self.dim != 2 or not self.param_flag("rh", xp, np.any, "right_hand"):
            rh = 0.0
        if self.mode == "joint":
            p = np.asarray(p, dtype=float)
            if self.graph.mode == "radius":
                pairs = pairs_in_range(p, float(self.sensing_range))
            else:
                pairs = pairs_from_neighbors(self.graph.get(u, p, np)[0])
            return {"velocity": joint_safety_filter(p, u["velocity_nominal"], pairs,
                                                    float(self.radius), float(self.gamma),
                                                    float(rh))}
        idx, _ = self.graph.get(u, p, xp)
        return {"velocity": safety_filter(p, u["velocity_nominal"], idx, self.radius,
                                          self.gamma, rh, xp)}
