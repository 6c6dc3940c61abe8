"""Neighbour queries over agent positions (k-d tree or cell list, never an N^2 loop).

The neighbour format that controllers consume: an ``(N, K)`` int64 array of
agent indices, padded with ``-1``, sorted by distance; ``idx >= 0`` is the
mask. ``K`` is fixed (``k_max``) so shapes stay static.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core import diagnostics
from ..core.block import Block
from ..core.errors import ParameterError
from ..utility.spatial import Need, NeighborSearch, verlet
from ..utility.spatial.queries import compact, k_smallest
from ._common import agent_count, declare_agents_input, maybe_periodic


def radius_neighbors(pos, radius, k_max):
    """Up to ``k_max`` nearest other agents within ``radius`` of each agent.

    The range is inclusive: an agent exactly ``radius`` away is a neighbour.

    Parameters
    ----------
    pos : (N, D) array
    radius : float
    k_max : int

    Returns
    -------
    idx : (N, k_max) int64, padded with -1, nearest first
    dist : (N, k_max) float, ``inf`` where padded
    """
    pos = np.asarray(pos, dtype=float)
    n = pos.shape[0]
    k = min(int(k_max) + 1, n)
    tree = cKDTree(pos)
    # the tree's bound is strict; make the range inclusive (|d| <= radius)
    dist, idx = tree.query(pos, k=k, distance_upper_bound=np.nextafter(radius, np.inf))
    dist = dist.reshape(n, k)
    idx = idx.reshape(n, k)
    # drop self (distance 0 to itself; with duplicates the self index may be
    # second, so remove it by identity)
    self_col = idx == np.arange(n)[:, None]
    keep = ~self_col
    # shift rows left where self was found; each row has at most one self entry
    order = np.argsort(~keep, axis=1, kind="stable")
    idx = np.take_along_axis(idx, order, axis=1)[:, : k - 1] if k > 1 else idx[:, :0]
    dist = np.take_along_axis(dist, order, axis=1)[:, : k - 1] if k > 1 else dist[:, :0]
    missing = ~np.isfinite(dist) | (idx >= n)
    idx = np.where(missing, -1, idx).astype(np.int64)
    dist = np.where(missing, np.inf, dist)
    if idx.shape[1] < k_max:
        pad = k_max - idx.shape[1]
        idx = np.pad(idx, ((0, 0), (0, pad)), constant_values=-1)
        dist = np.pad(dist, ((0, 0), (0, pad)), constant_values=np.inf)
    return idx, dist


def knn(pos, k):
    """The ``k`` nearest other agents of each agent (no range limit)."""
    return radius_neighbors(pos, np.inf, k)


def fov_neighbors(pose, radius, k_max, fov):
    """Up to ``k_max`` nearest agents within ``radius`` and the field of view.

    Agent ``j`` is in agent ``i``'s field of view when the bearing of ``j``
    seen from ``i``, relative to ``i``'s heading, lies in ``[-fov/2, fov/2]``
    (boundaries included). The k-d tree is queried for a few more than
    ``k_max`` candidates; rows that still lack neighbours are re-queried with
    twice as many (a handful of rounds, never a loop over agents).

    Parameters
    ----------
    pose : (N, 3) array (x, y, theta)
    radius : float
    k_max : int
    fov : float
        Full opening angle in radians, ``(0, 2 pi]``.

    Returns
    -------
    idx : (N, k_max) int64 padded with -1, nearest first
    dist : (N, k_max) float, ``inf`` where padded
    """
    pose = np.asarray(pose, dtype=float)
    n = pose.shape[0]
    k_max = int(k_max)
    out_i = np.full((n, k_max), -1, dtype=np.int64)
    out_d = np.full((n, k_max), np.inf)
    if n < 2 or k_max < 1:
        return out_i, out_d
    pos = pose[:, :2]
    half = 0.5 * float(fov)
    tree = cKDTree(pos)
    rows = np.arange(n)
    kq = min(n, max(2 * (k_max + 1), 8))
    while rows.size:
        d, j = tree.query(pos[rows], k=kq,
                          distance_upper_bound=np.nextafter(radius, np.inf))
        d, j = d.reshape(len(rows), kq), j.reshape(len(rows), kq)
        valid = (j < n) & (j != rows[:, None])
        jc = np.where(valid, j, 0)
        delta = pos[jc] - pos[rows][:, None, :]
        rel = np.arctan2(delta[..., 1], delta[..., 0]) - pose[rows, 2][:, None]
        rel = np.abs((rel + np.pi) % (2 * np.pi) - np.pi)
        vis = valid & (rel <= half + 1e-12)
        done = (vis.sum(axis=1) >= k_max) | (kq >= n) | ~np.isfinite(d[:, -1])
        r = rows[done]
        order = np.argsort(~vis[done], axis=1, kind="stable")[:, :k_max]
        vi = np.take_along_axis(vis[done], order, axis=1)
        ji = np.take_along_axis(j[done], order, axis=1)
        di = np.take_along_axis(d[done], order, axis=1)
        m = order.shape[1]
        out_i[r, :m] = np.where(vi, ji, -1)
        out_d[r, :m] = np.where(vi, di, np.inf)
        rows = rows[~done]
        kq = min(n, 2 * kq)
    return out_i, out_d


def to_networkx(idx, dist=None, *, directed=False):
    """The neighbour graph of an ``(N, K)`` index array as a networkx graph.

    Nodes are ``0 .. N-1`` (isolated agents included); an edge ``i -> j``
    for every ``j = idx[i, k] >= 0``, with attribute ``distance`` when
    ``dist`` is given. ``directed=False`` (default) gives an undirected
    ``Graph`` (an edge when either agent lists the other).
    """
    import networkx as nx
    idx = np.asarray(idx)
    g = nx.DiGraph() if directed else nx.Graph()
    g.add_nodes_from(range(idx.shape[0]))
    i, k = np.nonzero(idx >= 0)
    j = idx[i, k]
    if dist is None:
        g.add_edges_from(zip(i.tolist(), j.tolist()))
    else:
        dd = np.asarray(dist)[i, k]
        g.add_edges_from((a, b, {"distance": c})
                         for a, b, c in zip(i.tolist(), j.tolist(), dd.tolist()))
    return g


#: Distance reported by the :class:`Neighbors` block where ``neighbors`` is
#: padded (the simulator rejects infinite outputs; the index ``-1`` is the mask).
PAD_DISTANCE = -1.0

#: Largest agent count whose compiled Neighbors compares every pair.
DENSE_MAX = 128


def dense_within(points, radius, width, xp=np):
    """Every other point within ``radius`` (inclusive) of each point by
    comparing every pair: ``(idx (N, width) -1 padded, in index order; the
    most one point had)``. O(N^2) memory (small N)."""
    n = points.shape[0]
    d2 = 0.0
    for a in range(points.shape[1]):
        c = points[:, a]
        da = c[None, :] - c[:, None]
        d2 = d2 + da * da
    ids = xp.arange(n)
    r = xp.asarray(radius, dtype=d2.dtype)
    ok = (d2 <= r * r) & (ids[None, :] != ids[:, None])
    (idx,), most = compact(ok, [(xp.broadcast_to(ids[None, :], (n, n)), -1)], width, xp)
    return idx, most


def dense_nearest(points, radius, k, xp=np):
    """The ``k`` nearest other points within ``radius`` (inclusive) of each
    point by comparing every pair: ``(idx (N, k) -1 padded, dist (N, k) inf
    padded)``, sorted by squared distance ``dx^2 + dy^2``, ties by the smaller
    index (``k`` passes of a row minimum) -- the order and the arithmetic of
    :func:`avblocks.utility.spatial.nearest`, so both give the same
    neighbours. O(N^2) memory: for small N (``Neighbors`` uses it for compiled
    runs with ``method="dense"``, or ``"auto"`` and at most :data:`DENSE_MAX`
    agents)."""
    idx, dist, _ = dense_select(points, radius, k, xp)
    return idx, dist


def dense_select(points, radius, k, xp=np, passes=None):
    """:func:`dense_nearest` with at most ``passes`` selection passes (None:
    ``k``), and the most others within ``radius`` one point had. The result
    is :func:`dense_nearest`'s whenever no point had more than ``passes``
    (each pass selects one neighbour of every point; the passes a point does
    not need select nothing): a caller that cuts the passes short reports
    that count and is rerun when it exceeded them (``Neighbors``: its plan's
    ``hits``)."""
    n = points.shape[0]
    cols = [points[:, a] for a in range(points.shape[1])]
    d2 = 0.0
    for c in cols:
        da = c[None, :] - c[:, None]
        d2 = d2 + da * da
    # int32 indices: the tie-breaking minima of the selection move half the
    # bytes of int64 ones (measured 8-10 % of the search in a vmapped
    # ensemble); the result is int64 as the port says
    ids = xp.arange(n, dtype=xp.int32)
    r = xp.asarray(radius, dtype=d2.dtype)
    ok = (d2 <= r * r) & (ids[None, :] != ids[:, None])
    most = xp.max(xp.sum(ok, axis=0)) if n else 0
    d2 = xp.where(ok, d2, xp.inf)
    # the search's exact selection (k passes of a minimum, ties by index:
    # k_smallest) over the candidates of each point; d2 is symmetric (the
    # same squares either way), so the candidates of point q are column q
    # and each pass takes elementwise minima of rows (measured 25 % faster
    # than minima of each row in a vmapped ensemble)
    m2, j = k_smallest(d2, ids[:, None], k if passes is None else min(int(k), int(passes)),
                       xp, axis=0, nonneg=True)
    pad = int(k) - m2.shape[1]
    if pad:
        m2 = xp.concatenate([m2, xp.full((n, pad), xp.inf, dtype=m2.dtype)], axis=1)
        j = xp.concatenate([j, xp.full((n, pad), -1, dtype=j.dtype)], axis=1)
    fin = xp.isfinite(m2)
    idx = xp.where(fin, j, -1).astype(np.int64)
    return idx, xp.where(fin, xp.sqrt(xp.where(fin, m2, 1.0)), xp.inf), most


class Neighbors(Block):
    """Range-limited, k-nearest and field-of-view neighbour sets.

    Ports
    -----
    pose : in, (N, 3) [m, m, rad]  (or ``position`` (N, 2) with input="position")
    neighbors : out, (N, K) int64
        Indices of up to ``K`` other agents, nearest first (ties: smaller
        index first), padded with -1.
    distance : out, (N, K) float [m]
        Their distances; ``PAD_DISTANCE`` (-1) where padded.

    Parameters
    ----------
    n : int
        Number of agents.
    k : int
        ``K``, the most neighbours kept per agent (static shape).
    radius : float
        Sensing range (default: unlimited; then the k nearest, by comparing
        every pair: O(N^2), for small N).
    fov : float, optional
        Full field-of-view angle in radians (needs ``input="pose"``); a
        neighbour's bearing relative to the heading must lie in
        ``[-fov/2, fov/2]``. Default: all around.
    box : (L_x, L_y), optional
        Periodic world ``[0, L_x) x [0, L_y)``: distances by the minimum
        image (``radius <= min(L) / 2``).
    method : "cells" (default), "dense" or "auto"
        How a compiled run searches: the cell list (below); every pair, an
        (N, N) array (:func:`dense_nearest`; the same neighbours, cheaper for
        small N and across ensembles; not with ``fov`` or ``box``); or
        ``"auto"``: every pair up to :data:`DENSE_MAX` agents, else the cell
        list. The NumPy engine always uses the k-d tree. Comparing every
        pair, a compiled run makes as many selection passes as the search's
        plan has ``hits`` (the most others within range one agent had at
        ``t0``, times the headroom, at least 8) when that is below ``k``;
        an agent with more is an overflow, handled as the cell list's
        (re-planned and rerun, or raised; see
        :mod:`avblocks.core.compiled.plans`).
    capacity : int, optional
        Fix the compiled search's static capacity (candidates per agent, see
        :mod:`avblocks.utility.spatial`) instead of letting the compiled
        engine plan it from the initial positions (with a skin, also the
        width of the Verlet list).
    skin : float, optional
        Verlet skin [m] of compiled runs (:mod:`avblocks.utility.spatial.verlet`):
        the block keeps, as discrete state, a list of the agents within
        ``radius + skin`` of each agent, built by the search above, and
        selects the ``K`` nearest within ``radius`` among them each time it
        is evaluated; the list is built again when the agents may have
        moved by ``skin / 2`` relative to each other since it was (tested
        at every evaluation; a motion common to all agents -- translation,
        rotation, contraction -- is discounted: ``verlet.moved``).
        The neighbours are exactly those of a fresh search (same indices,
        same order, same distances). Default ``0``: a fresh search every
        time (measured faster on the flocking benchmarks, whose agents
        move up to 0.45 m per step relative to each other while the flock
        contracts: a list lasted 4-5 steps at ``skin = 0.2 r``; see
        docs/benchmarks.md). No skin with an unlimited radius; in a
        periodic box the skin is cut to ``min(box)/2 - radius``. The NumPy
        engine ignores it (its k-d tree is faster there) and leaves the
        list state untouched.

    input : "pose" or "position"
    period : float, optional
        Discrete block with this period (outputs held between hits).

    Equations
    ---------
    ``N_i = the K nearest j != i with |p_j - p_i| <= radius`` and, with a
    field of view, ``|wrap(atan2(p_j - p_i) - theta_i)| <= fov / 2``.

    Notes
    -----
    ``radius`` and ``fov`` (when given) are numeric parameters; ``k`` and
    whether there is a field of view are structural. The search's cells are
    sized for the ``radius`` given here: a compiled run whose ``radius`` is
    later raised above it reports an overflow.

    Compiles (``backend="jax"``): the search is the cell list of
    :class:`avblocks.utility.spatial.NeighborSearch` (exact: the same
    neighbours in the same order as the NumPy engine, whose radius queries
    use SciPy's k-d tree, measured faster there).

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import Neighbors
    >>> b = Neighbors(3, k=2, radius=1.5, input="position")
    >>> y = b.output(0.0, {}, {"position": np.array([[0.0, 0], [1, 0], [3, 0]])}, np)
    >>> y["neighbors"].tolist()
    [[1, -1], [0, -1], [-1, -1]]
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {"n": "$agents", "k": 3}

    def __init__(self, n, k, *, radius=np.inf, fov=None, input="pose", period=None,
                 box=None, capacity=None, method="cells", skin=0.0):
        super().__init__()
        if method not in ("cells", "dense", "auto"):
            raise ParameterError("method must be 'cells', 'dense' or 'auto'",
                                 block="Neighbors", param="method", found=method)
        self.method = method
        self.n = n = agent_count(n, "Neighbors")
        self.k = k = agent_count(k, "Neighbors")
        radius = float(radius)
        if not radius > 0:
            raise ParameterError("radius must be > 0", block="Neighbors",
                                 param="radius", expected="> 0", found=radius)
        if fov is not None:
            fov = float(fov)
            if not (0 < fov <= 2 * np.pi):
                raise ParameterError("fov must lie in (0, 2 pi]", block="Neighbors",
                                     param="fov", expected="(0, 2 pi]", found=fov)
            if fov >= 2 * np.pi:
                fov = None
        self.declare_parameter("radius", radius, bounds=(1e-12, None), allow_inf=True,
                               unit="m")
        if fov is None:
            self.fov = None
        else:
            self.declare_parameter("fov", fov, bounds=(1e-12, 2 * np.pi), unit="rad")
        self.input = declare_agents_input(self, n, input, need_heading=fov is not None)
        skin = float(skin)
        if not (skin >= 0 and np.isfinite(skin)):
            raise ParameterError("skin must be a finite length >= 0", block="Neighbors",
                                 param="skin", expected=">= 0", found=skin)
        if not np.isfinite(radius):
            skin = 0.0
        elif box is not None:
            skin = max(0.0, min(skin, 0.5 * float(np.min(box)) - radius))
        #: Verlet skin (structural: 0 means a fresh search at every evaluation)
        self.skin = skin
        try:
            self.search = NeighborSearch(radius + skin, points=self.input, box=box,
                                         capacity=capacity)
        except ParameterError as e:
            raise ParameterError(str(e.args[0]) if e.args else "bad search settings",
                                 block="Neighbors", param="box" if box is not None
                                 else "capacity") from e
        # hits (the most others within range of one agent) are read by the
        # Verlet list and by the dense selection; a cell-list search that
        # only answers the k nearest plans without counting them
        self.search.counts_hits = bool(skin) or self._dense()
        if skin > 0:
            width = 1 if self.search.cells is None else self.search.cells.hits
            self.declare_discrete_state("verlet_list", np.full((n, width), -1),
                                        dtype=np.int64, doc="Verlet list: agents "
                                        "within radius + skin at the last build, -1 padded")
            self.declare_discrete_state("verlet_anchor", np.zeros((n, 2)), unit="m",
                                        doc="positions at the last build")
            self.declare_discrete_state("verlet_built", 0, dtype=np.int64, agents=False,
                                        doc="1 once the list was built")
            self.declare_discrete_state("verlet_last", np.zeros((n, 2)), unit="m",
                                        doc="positions at the last update")
        self.declare_output("neighbors", (n, k), "int64",
                            doc="neighbour indices, nearest first, -1 padded")
        self.declare_output("distance", (n, k), unit="m",
                            doc="neighbour distances, -1 where padded")
        maybe_periodic(self, period)

    def _dense(self):
        """Whether a compiled run compares every pair (``method``; no field of
        view, no periodic box): for small N an (N, N) array costs less than
        the sort and binary searches, and vectorises across an ensemble."""
        if self.method == "cells" or self.fov is not None or self.search.box is not None:
            return False
        return self.method == "dense" or self.n <= DENSE_MAX

    def searches(self):
        """The neighbour search this block owns, planned by the compiled
        engine: the cell list's sizes; with a skin the Verlet list's width;
        when compiled runs compare every pair, the plan's ``hits`` bounds
        the selection passes (:func:`dense_select`)."""
        return [self.search]

    def searches_planned(self):
        """Called by the compiled engine after it planned (or grew) the
        searches: the Verlet list state takes the plan's width."""
        if self.skin and self.search.cells is not None:
            w = int(self.search.cells.hits)
            if self._init["verlet_list"].shape[1] != w:
                self.redeclare_state("verlet_list", np.full((self.n, w), -1),
                                     dtype=np.int64)

    def _verlet(self, x, p, xp, margin=0.0):
        """The Verlet list valid for positions ``p`` and its anchor."""
        reach = self.radius + self.skin
        if self._dense():
            w = int(self.search.cells.hits)

            def build(q):
                idx, most = dense_within(q, reach, w, xp)
                self.search._report(Need(0, xp.asarray(reach), most), self.search.cells,
                                    xp)
                return idx
        else:
            def build(q):
                return verlet.by_index(self.search.within(q, reach, xp=xp)[0], xp)
        return verlet.refresh(p, x["verlet_anchor"], x["verlet_list"], x["verlet_built"],
                              self.radius, self.skin, build, xp, box=self.search.box,
                              margin=margin)

    def update(self, t, x, u, xp):
        if xp is np or not self.skin:
            return {}                   # the NumPy engine searches afresh (k-d tree)
        p = u[self.input][:, :2]
        # build early when the next evaluation would probably have to: within
        # the last update-to-update motion of the bound (any list built
        # is exact; this only saves building twice, in output and here)
        margin = verlet.step_bound(p, x["verlet_last"], xp, box=self.search.box)
        cand, anchor = self._verlet(x, p, xp, margin=margin)
        return {"verlet_list": cand, "verlet_anchor": anchor,
                "verlet_built": xp.ones_like(x["verlet_built"]), "verlet_last": p}

    def output(self, t, x, u, xp):
        p = u[self.input]
        if xp is not np and self.skin:
            cand, _ = self._verlet(x, p[:, :2], xp)
            box = self.search.box
            idx, dist = verlet.select(p[:, :2], cand, self.radius, self.k, xp,
                                      box=None if box is None else tuple(box),
                                      heading=p[:, 2] if self.fov is not None else None,
                                      fov=self.fov)
            return {"neighbors": idx, "distance": xp.where(idx >= 0, dist, PAD_DISTANCE)}
        if xp is not np and self._dense():
            # as many selection passes as the plan's hits (the most others
            # within range one agent had at t0, with headroom) when fewer
            # than k and an overflow is caught after the run
            plan = self.search.cells
            passes = plan.hits if (plan is not None and plan.hits is not None
                                   and plan.hits < self.k
                                   and diagnostics.kept(self.search)) else None
            idx, dist, most = dense_select(p[:, :2], self.radius, self.k, xp, passes)
            if passes is not None:
                self.search._report(Need(0, 0.0, most), plan, xp)
            return {"neighbors": idx,
                    "distance": xp.where(idx >= 0, dist, PAD_DISTANCE)}
        if self.fov is None:
            idx, dist = self.search.nearest(p[:, :2], self.radius, self.k, xp=xp)
        else:
            idx, dist = self.search.nearest(p[:, :2], self.radius, self.k, xp=xp,
                                            heading=p[:, 2], fov=self.fov)
        return {"neighbors": idx, "distance": xp.where(idx >= 0, dist, PAD_DISTANCE)}
