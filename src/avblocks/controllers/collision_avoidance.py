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

Joint mode (``mode="joint"``, the default)
-----------------------------------------
One QP over all agents' velocities ``u = (u_1, ..., u_N)`` (Wang, Ames &
Egerstedt 2017, the centralised barrier certificate):

.. math::

    u = \arg\min_u \sum_i |u_i - \hat u_i|^2 \quad\text{s.t.}\quad
        -(p_i - p_j)^T (u_i - u_j) \le \tfrac{\gamma}{2} h_{ij}
        \quad (\text{pairs } (i, j) \text{ that see each other})

(``dh_ij/dt = 2 (p_i - p_j)^T (u_i - u_j) >= -gamma h_ij``). The pairs
are the union of the neighbour lists (the port, or the block's own cell
list search with ``sensing_range``: the ``k_max`` nearest within range,
or every pair within range with ``k_max=None``). Unlike the per-agent
split, the joint QP lets one agent give way more than the other, which is
what frees the jams of the split filter. ``u = 0`` is feasible while every
``h_ij >= 0``, so the QP has a solution while the agents are safe (and
even when they overlap, a uniform expansion about the centroid satisfies
every constraint, unless two agents coincide).

Why the joint QP is the default: the per-agent filter leaves 2 of 20
agents of the Robotarium swap (circle / safety radius 5.88) jammed for
good, the joint QP brings all home (tested for ratios 3 to 8). It needs
no optional dependency and compiles: the default solver
(``solver="admm"``, :func:`admm_pair_qp`) is consensus ADMM written in
``xp`` with static shapes (padded pairs) and a fixed budget, so the same
code runs in the NumPy engine and under ``jit``/``vmap``/``grad``. Its
stated tolerance: stopped when the primal residual and the last change
are below ``tol (1 + max |u_nominal|)`` (``tol = 1e-10``, at most 500
iterations); on jammed 20-agent clusters it agrees with an exact
active-set solution (quadprog) to 1e-9 and meets every constraint to 1e-9
relative (tests). ``solver="clarabel"`` solves the same QP by Clarabel
(interior point, sparse; the ``safety`` extra, NumPy only; about 3e-7
from quadprog on the same clusters), kept as a reference.

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
swap scenario completing for ratios 3 to 8. Note that the bias
adds speed: up to ``sqrt(1 + rho^2)`` times the nominal one.

Reference: L. Wang, A. D. Ames & M. Egerstedt, "Safety barrier certificates
for collisions-free multirobot systems", IEEE T-RO 33(3), 2017; U. Borrmann
et al., "Control barrier certificates for safe swarm behavior", ADHS 2015.
"""

from __future__ import annotations

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar
from ._graph import NeighborSource, gather
from .cbf_qp import (  # noqa: F401 (re-exported: the QPs lived here)
    _clarabel,
    _loop,
    _subsets,
    admm_pair_qp,
    joint_min_norm_qp,
    min_norm_qp,
    neighbor_edges,
    scatter_add,
)


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
    """CBF-filtered velocities (N, D) from ONE QP over all agents (Clarabel).

    ``pairs`` (M, 2) int: the constrained pairs (e.g. :func:`pairs_in_range`).
    ``right_hand`` (2-D): the bias of :func:`safety_filter`, applied to the
    nominal velocity of agents with a partner closer than ``2 radius`` (see
    the module docstring for why it frees symmetric jams). NumPy only; the
    traceable equivalent is :func:`joint_filter`.
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


# ------------------------------------------------- the traceable joint QP (ADMM)
def joint_filter(position, u_nom, idx, radius, gamma=1.0, right_hand=0.0, xp=np, **solver):
    """The joint CBF QP (see the module docstring) over the pairs listed in
    the padded neighbour lists ``idx`` (N, K) (their union), solved by
    :func:`admm_pair_qp`: pure ``xp``, traceable, differentiable.

    ``right_hand`` (2-D): the roundabout bias of :func:`joint_safety_filter`.
    Returns ``(u, residual)``.
    """
    ei, ej, ok = neighbor_edges(idx, xp)
    if xp is np:                          # the padding only adds exact zeros
        keep = np.flatnonzero(ok)
        ei, ej, ok = ei[keep], ej[keep], ok[keep]
    dp = position[ei] - position[ej]                      # p_i - p_j, (E, D)
    d2 = xp.sum(dp * dp, axis=-1)
    h = d2 - radius * radius
    if not (isinstance(right_hand, (int, float)) and right_hand == 0):
        n = position.shape[0]
        close = xp.where(ok & (d2 < 4 * radius * radius), 1.0, 0.0)
        near = (scatter_add(n, ei, close, xp) + scatter_add(n, ej, close, xp)) > 0
        turn = xp.stack([u_nom[:, 1], -u_nom[:, 0]], axis=-1)
        u_nom = u_nom + xp.where(near[:, None], right_hand * turn, 0.0)
    return admm_pair_qp(u_nom, ei, ej, ok, -dp, 0.5 * gamma * h, xp, **solver)


class CollisionAvoidance(Block):
    """CBF safety filter for N single integrators (or off-axis points).

    Ports
    -----
    position : in, (N, D), D = 2 or 3.
    velocity_nominal : in, (N, D) — desired velocities.
    neighbors : in, (N, K) int (without ``sensing_range`` only) — agents that
        may come close; use a sensing range well above ``radius``.
    velocity : out, (N, D) — the minimally modified, safe velocities.

    Parameters
    ----------
    n : int;  radius : float > 0 — safety distance D_s (m).
    gamma : float > 0 — barrier gain (1/s).
    right_hand : float >= 0 — roundabout bias against deadlocks (2-D; see
        :func:`safety_filter`), default 0 (pure minimal filter).
    dim : int (2 or 3).
    sensing_range : float, optional — find the neighbours inside the block
        (a :class:`~avblocks.utility.spatial.NeighborSearch` cell list, which
        traces) instead of the port: the ``k_max`` nearest agents within
        range (joint mode: the union of these lists, each pair once;
        ``k_max=None`` in joint mode: every pair within range, which costs
        ``(N, 3^D capacity)`` padded pairs in a compiled run).
    k_max : int or None — see ``sensing_range`` (default 6).
    capacity : int, optional — points per cell of that search, fixed for
        compiled runs (without it a compiled run needs the engine to plan
        the search from the initial positions).
    mode : ``"joint"`` (default) — one QP over all agents (Wang, Ames &
        Egerstedt 2017), which lets one agent give way more than the other
        and frees the jams of the split filter; ``"agent"`` — one small
        exact QP per agent, half of each pair's constraint each (closed
        form; jams in dense symmetric swaps, see the module docstring).
    solver : joint mode only. ``"admm"`` (default) — :func:`admm_pair_qp`,
        pure ``xp``: traceable, differentiable, no extra dependency; it
        agrees with Clarabel to about 1e-8 (absolute, velocities of order
        1) on the tested problems, constraints met to ``tol``.
        ``"clarabel"`` — the interior-point reference (NumPy only, needs the
        ``safety`` extra).
    iterations, tol : the ADMM budget and stopping tolerance (relative to
        ``1 + max |u_nominal|``).

    Notes
    -----
    ``radius``, ``gamma``, ``right_hand`` (2-D) and ``sensing_range`` (when
    given) are numeric parameters; the rest are structural.
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "radius": 1.0}

    def __init__(self, n, radius, *, gamma=1.0, right_hand=0.0, dim=2,
                 sensing_range=None, k_max=6, mode="joint", solver="admm",
                 iterations=500, tol=1e-10, capacity=None):
        super().__init__()
        name = "CollisionAvoidance"
        if not isinstance(mode, str) or mode not in ("agent", "joint"):
            raise ParameterError("mode must be 'agent' or 'joint'", block=name,
                                 param="mode", found=mode)
        if not isinstance(solver, str) or solver not in ("admm", "clarabel"):
            raise ParameterError("solver must be 'admm' or 'clarabel'", block=name,
                                 param="solver", found=solver)
        self.mode = mode
        self.solver = solver
        if mode == "joint" and solver == "clarabel":
            _clarabel()
            self.traceable = False
        try:
            self.iterations = int(iterations)
            self.tol = float(tol)
        except (TypeError, ValueError):
            raise ParameterError("iterations and tol must be numbers", block=name,
                                 param="iterations") from None
        if self.iterations < 1 or not self.tol >= 0:
            raise ParameterError("need iterations >= 1 and tol >= 0", block=name,
                                 param="iterations", found=(iterations, tol))
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
        self.search = None
        if sensing_range is not None:
            r = positive_scalar(sensing_range, name, "sensing_range", allow_inf=True)
            self.declare_parameter("sensing_range", r, bounds=(1e-12, None),
                                   allow_inf=True, unit="m")
            if k_max is None and mode == "agent":
                raise ParameterError("k_max is needed in agent mode", block=name,
                                     param="k_max")
            if k_max is not None and int(k_max) < 1:
                raise ParameterError("k_max must be >= 1", block=name,
                                     param="k_max", found=k_max)
            self.k_max = None if k_max is None else int(k_max)
            if capacity is not None and int(capacity) < 1:
                raise ParameterError("capacity must be >= 1", block=name,
                                     param="capacity", found=capacity)
            from ..utility.spatial import NeighborSearch
            self.search = NeighborSearch(r, points="position", capacity=capacity, dim=dim)
            self.graph = None
        else:
            self.graph = NeighborSource(self, n)
        self.declare_output("velocity", (n, dim), unit="m/s")

    def configure(self, inputs):
        if self.graph is not None:
            self.graph.configure(inputs)

    def _neighbors(self, u, p, xp):
        if self.search is None:
            return self.graph.get(u, p, xp)[0]
        if xp is not np and self.search.cells is None:
            raise ParameterError(
                "a compiled run needs a static plan for the neighbour search",
                block="CollisionAvoidance", param="capacity",
                expected="capacity=<agents per cell> (the number of agents never "
                         "overflows)", found=None)
        r = self.sensing_range if xp is not np else float(self.sensing_range)
        if self.k_max is not None:
            return self.search.nearest(p, r, self.k_max, xp=xp)[0]
        return self.search.within(p, r, xp=xp)[0]

    def output(self, t, x, u, xp):
        p = u["position"]
        rh = self.right_hand
        if self.dim != 2 or not self.param_flag("rh", xp, np.any, "right_hand"):
            rh = 0.0
        if self.mode == "joint" and self.solver == "clarabel":
            p = np.asarray(p, dtype=float)
            if self.search is not None and self.k_max is None:
                pairs = pairs_in_range(p, float(self.sensing_range))
            elif self.search is not None:
                pairs = pairs_from_neighbors(self._neighbors(u, p, np))
            else:
                pairs = pairs_from_neighbors(self.graph.get(u, p, np)[0])
            return {"velocity": joint_safety_filter(p, u["velocity_nominal"], pairs,
                                                    float(self.radius), float(self.gamma),
                                                    float(rh))}
        idx = self._neighbors(u, p, xp)
        if self.mode == "joint":
            v, _ = joint_filter(p, u["velocity_nominal"], idx, self.radius, self.gamma,
                                rh, xp, iterations=self.iterations, tol=self.tol)
            return {"velocity": v}
        return {"velocity": safety_filter(p, u["velocity_nominal"], idx, self.radius,
                                          self.gamma, rh, xp)}
