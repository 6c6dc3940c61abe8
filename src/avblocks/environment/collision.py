"""Collision detection: agent footprints against obstacles and each other.

:func:`collide` is the pure computation; :class:`Collision` wraps it as a
block and :class:`StopOnCollision` zeros the command of collided agents
(AVLib paper, Section III.C: "can be used to stop the vehicle when a
collision occurs").

Method (never an N^2 loop)
--------------------------
- agents vs obstacles: broad phase with the world's shapely ``STRtree``
  (one vectorized envelope query for all footprints), then an exact narrow
  phase on the candidate pairs, vectorized in shapely/NumPy:
  disc footprint vs polygon: ``distance(center, polygon) <= r`` (0 inside);
  disc vs circle: ``|c1 - c2| <= r1 + r2``; polygon footprint vs polygon:
  ``intersects``; polygon footprint vs circle: ``distance(polygon, c) <= R``.
- agents vs agents: broad phase with a ``cKDTree`` over the pose points
  (pairs closer than the sum of the largest bounding radii), then the exact
  test on those pairs.

Touching counts as a collision (closed sets). ``margin`` > 0 inflates every
footprint by that distance (a safety distance).

That is :func:`collide`, the exact NumPy/shapely method
(``Collision(..., method="shapely")``). ``method="grid"`` computes the same
predicates with ``xp`` code that the compiled (JAX) engine traces
(:func:`collide_grid`):

- agents vs obstacles: the world's edges as padded arrays with a
  uniform-grid broad phase (:class:`~avblocks.environment.edges.EdgeGrid`,
  built for the largest footprint reach ``bounding radius + margin``);
  each agent tests only the candidate edges, circles and polygons of its
  cell (an (N, K) product, ``K`` the fullest cell's list); in a small world
  every obstacle, rectangles as boxes in closed form (the grid's
  ``dense``);
- agents vs agents: :class:`~avblocks.utility.spatial.NeighborSearch`
  (a cell list) within twice the largest reach, then the exact test on
  the candidates: discs ``|c_i - c_j| <= r_i + r_j + 2 m``; polygons:
  least edge-edge distance ``<= 2 m`` or one polygon's vertex inside the
  other.

Both methods give the same booleans and indices except for contacts
within ~1e-12 m of touching (float64 rounding; tests compare them on
random worlds with concave polygons, holes, circles and walls).

The default, ``method="auto"``, is traceable: a compiled run uses the grid
method and the NumPy engine the shapely one, the faster there at every N
measured (``benchmarks/environment.py``, 2 cores, 200 random obstacles, one
agent per 16 m^2: discs 0.17 / 0.98 / 10.5 ms at N = 100 / 1,000 / 10,000
against 0.91 / 4.5 / 54 ms for the grid code in NumPy).
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import positive_scalar
from ..utility.arrays import fold
from ..utility.spatial import Need, NeighborSearch
from ._common import (
    SMALL_N,
    EdgeGridOwner,
    agent_count,
    all_pairs,
    declare_agents_input,
    maybe_periodic,
)
from .edges import point_in_ring, segment_segment_dist2
from .footprint import Disc, Footprint
from .world import World, _disc_obstacle_hits


def _poly_obstacle_hits(world, polys, margin):
    if world.n_obstacles == 0 or len(polys) == 0:
        e = np.zeros(0, np.int64)
        return e, e
    query = shapely.buffer(polys, margin, join_style="mitre") if margin > 0 else polys
    a, o = world.tree.query(query)
    circ = world.is_circle[o]
    hit = np.zeros(len(a), dtype=bool)
    if np.any(~circ):
        ap, op = a[~circ], o[~circ]
        if margin > 0:
            hit[~circ] = shapely.distance(polys[ap], world._geom_arr[op]) <= margin
        else:
            hit[~circ] = shapely.intersects(polys[ap], world._geom_arr[op])
    if np.any(circ):
        ac, oc = a[circ], o[circ]
        pts = shapely.points(world.circle_center[oc])
        hit[circ] = shapely.distance(polys[ac], pts) <= world.circle_radius[oc] + margin
    return a[hit].astype(np.int64), o[hit].astype(np.int64)


def _agent_pairs(points, reach):
    """Unordered pairs (i < j) whose points are within ``reach`` (k-d tree)."""
    if len(points) < 2:
        return np.zeros((0, 2), np.int64)
    return cKDTree(points).query_pairs(reach, output_type="ndarray").astype(np.int64)


def _first_index(n, who, what):
    """Per agent, the smallest ``what`` among its entries in ``who``; -1 if none."""
    out = np.full(n, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(out, who, what)
    return np.where(out == np.iinfo(np.int64).max, -1, out)


def collide(world, pose, footprint, margin=0.0, agents=True):
    """Collisions of N posed footprints with the world and each other.

    Parameters
    ----------
    world : World
    pose : (N, 3) poses or (N, 2) positions (heading 0)
    footprint : Footprint
    margin : float
        Safety distance added around every footprint.
    agents : bool
        Also check agent-agent contacts.

    Returns
    -------
    dict with ``hit_obstacle``, ``hit_agent``, ``collision`` (N,) bool,
    ``hit_index`` (N,) int64 (smallest index of an obstacle touched, -1 if
    none) and ``hit_agent_index`` (N,) int64 (smallest index of another
    agent touched, -1 if none).
    """
    pose = np.asarray(pose, dtype=float)
    n = pose.shape[0]
    centers = pose[:, :2]
    if isinstance(footprint, Disc):
        r = footprint.radii(n) + margin
        ao, oo = _disc_obstacle_hits(world, centers, r)
        pairs = _agent_pairs(centers, 2.0 * r.max()) if agents and n > 1 else None
        if pairs is not None and len(pairs):
            i, j = pairs.T
            d = np.hypot(*(centers[i] - centers[j]).T)
            pairs = pairs[d <= r[i] + r[j]]
    else:
        polys = footprint.posed(pose)
        ao, oo = _poly_obstacle_hits(world, polys, margin)
        pairs = None
        if agents and n > 1:
            b = footprint.bounding_radius(n) + margin
            pairs = _agent_pairs(centers, 2.0 * b.max())
            if len(pairs):
                i, j = pairs.T
                if margin > 0:
                    ok = shapely.distance(polys[i], polys[j]) <= 2.0 * margin
                else:
                    ok = shapely.intersects(polys[i], polys[j])
                pairs = pairs[ok]
    hit_obstacle = np.zeros(n, dtype=bool)
    hit_obstacle[ao] = True
    hit_agent = np.zeros(n, dtype=bool)
    if pairs is not None and len(pairs):
        who = np.concatenate([pairs[:, 0], pairs[:, 1]])
        other = np.concatenate([pairs[:, 1], pairs[:, 0]])
        hit_agent[who] = True
        agent_index = _first_index(n, who, other)
    else:
        agent_index = np.full(n, -1, dtype=np.int64)
    return {"hit_obstacle": hit_obstacle, "hit_agent": hit_agent,
            "collision": hit_obstacle | hit_agent,
            "hit_index": _first_index(n, ao, oo),
            "hit_agent_index": agent_index}


def _posed_xp(body, pose, xp):
    """(N, V, 2) world vertices of body-frame polygons (N, V, 2) at poses."""
    if pose.shape[1] >= 3:
        c, s = xp.cos(pose[:, 2]), xp.sin(pose[:, 2])
    else:
        c = xp.ones(pose.shape[:1], dtype=pose.dtype)
        s = xp.zeros(pose.shape[:1], dtype=pose.dtype)
    vx, vy = body[..., 0], body[..., 1]
    x = c[:, None] * vx - s[:, None] * vy + pose[:, 0:1]
    y = s[:, None] * vx + c[:, None] * vy + pose[:, 1:2]
    return xp.stack([x, y], axis=-1)


def _first_pair(idx, hit, xp):
    big = np.int32(np.iinfo(np.int32).max)
    f = fold(xp.minimum, xp.where(hit, idx, big), 1, xp)
    any_ = f < big
    return any_, xp.where(any_, f, -1)


def collide_grid(grid, search, pose, footprint, margin=0.0, agents=True, xp=np):
    """:func:`collide` in ``xp`` code (traceable): ``grid`` an
    :class:`EdgeGrid` of the world built for reach >= the largest footprint
    reach plus ``margin``; ``search`` a :class:`NeighborSearch` with reach >=
    twice that (None: no agent-agent test)."""
    n = pose.shape[0]
    centers = pose[:, :2]
    m = xp.asarray(margin, dtype=pose.dtype)
    if isinstance(footprint, Disc):
        r = xp.asarray(footprint.radii(n), dtype=pose.dtype) + m
        ho, first = grid.disc_hits(centers, r, xp)
        reach = 2.0 * xp.max(r)
    else:
        body = xp.asarray(footprint.body(n), dtype=pose.dtype)
        verts = _posed_xp(body, pose, xp)
        ho, first = grid.polygon_hits(verts, centers, m, xp)
        reach = 2.0 * (float(np.max(footprint.bounding_radius(n))) + m)
    if agents and n > 1 and search is not None:
        dense = all_pairs(search, centers, xp)          # far pairs: never a hit
        idx, dist = dense if dense is not None else search.within(centers, reach, xp=xp)
        ok = idx >= 0
        j = xp.where(ok, idx, 0)
        if isinstance(footprint, Disc):
            rj = r[None, :] if dense is not None else r[j]     # all pairs: column j is j
            hit = ok & (dist <= r[:, None] + rj)
        else:
            vi = verts[:, None, :, None, :]                    # (N, 1, V, 1, 2)
            vj = verts[j]                                       # (N, M, V, 2)
            ai, bi = vi, xp.roll(verts, -1, axis=1)[:, None, :, None, :]
            aj = vj[:, :, None, :, :]
            bj = xp.roll(vj, -1, axis=2)[:, :, None, :, :]
            dd = segment_segment_dist2(ai[..., 0], ai[..., 1], bi[..., 0], bi[..., 1],
                                       aj[..., 0], aj[..., 1], bj[..., 0], bj[..., 1],
                                       xp)                      # (N, M, V, V), squared
            near = xp.min(dd, axis=(-2, -1)) <= 4.0 * m * m
            # one polygon inside the other: a vertex of one inside the other
            j_in_i = point_in_ring(vj[:, :, 0, 0], vj[:, :, 0, 1], verts, xp)
            i0 = xp.broadcast_to(verts[:, None, 0, :], vj[:, :, 0, :].shape)
            i_in_j = point_in_ring(i0[..., 0:1], i0[..., 1:2], vj, xp)[..., 0]
            hit = ok & (near | j_in_i | i_in_j)
        ha, ai_ = _first_pair(idx, hit, xp)
    else:
        ha = xp.zeros((n,), dtype=bool)
        ai_ = xp.full((n,), -1, dtype=np.int32)
    if xp is np:                                   # the declared dtype (traced: cast
        first, ai_ = first.astype(np.int64), ai_.astype(np.int64)   # by the engine)
    return {"hit_obstacle": ho, "hit_agent": ha, "collision": ho | ha,
            "hit_index": first, "hit_agent_index": ai_}


class Collision(EdgeGridOwner, Block):
    """Collision detector for N agents in a :class:`World` (AVLib III.C).

    Ports
    -----
    pose : in, (N, 3) [m, m, rad]  (or ``position`` (N, 2) with input="position")
    hit_obstacle : out, (N,) bool
        The agent's footprint touches or overlaps an obstacle (or a wall).
    hit_agent : out, (N,) bool
        The footprint touches or overlaps another agent's footprint.
    collision : out, (N,) bool
        ``hit_obstacle | hit_agent``.
    hit_index : out, (N,) int64
        Index (in ``world``'s obstacle order) of the lowest-numbered obstacle
        touched, ``-1`` if none.
    hit_agent_index : out, (N,) int64
        Lowest index of another agent touched, ``-1`` if none.

    Parameters
    ----------
    world : World
    n : int
        Number of agents.
    footprint : Footprint
        :class:`Disc` (default radius 0.2 m), :func:`Rectangle` or
        :class:`PolygonFootprint` (see :func:`default_footprint`).
    input : "pose" or "position"
    margin : float
        Safety distance added around each footprint (default 0); a numeric
        parameter (``"coll.margin"``).
    agents : bool
        Check agent-agent contacts (default True).
    period : float, optional
        Make the block discrete (outputs computed at hits and held): a
        period equal to the simulation step computes collisions once per
        step instead of at every solver stage.
    method : "auto", "grid" or "shapely"
        ``"grid"``: traceable ``xp`` code (:func:`collide_grid`) in both
        engines. ``"shapely"``: the exact NumPy/shapely :func:`collide`
        (NumPy engine only). ``"auto"`` (default): grid when compiled,
        shapely in the NumPy engine (faster there). They agree except
        within ~1e-12 m of touching.
    capacity : int, optional
        Static per-cell capacity of the agent-agent neighbour search for
        the compiled engine (see :class:`~avblocks.utility.spatial.NeighborSearch`).
        Default: all pairs when ``n <= SMALL_N`` (exact, nothing to plan),
        else planned by the compiled engine from the first positions.
    reach : float, optional
        Largest ``bounding radius + margin`` the static grid and neighbour
        search serve (structural). Default ``bounding radius + 2 margin``:
        a compiled run may double ``margin`` without a rebuild.

    Equations
    ---------
    See :func:`collide`; touching counts. The grid is built for ``reach``:
    a larger margin set later re-builds it in the NumPy engine and is
    reported as an overflow by a compiled run.

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import World, Collision, Disc, rectangle
    >>> col = Collision(World([rectangle(1, -1, 2, 1)]), 2, footprint=Disc(0.5))
    >>> y = col.output(0.0, {}, {"pose": np.array([[0.5, 0, 0], [-3, 0, 0]])}, np)
    >>> y["collision"].tolist(), y["hit_index"].tolist()
    ([True, False], [0, -1])
    """

    #: Arguments of a small instance (the editor's palette template).
    example = {'world': {'corridor': {'x0': 24.0, 'x1': 32.0, 'width': 2.0}},
               'n': '$agents',
               'footprint': {'disc': {'radius': 0.25}}}

    def __init__(self, world, n, *, footprint=None, input="pose", margin=0.0,
                 agents=True, period=None, method="auto", capacity=None,
                 reach=None):
        super().__init__()
        if not isinstance(world, World):
            raise ParameterError("world must be an avblocks.environment.World",
                                 block="Collision", param="world",
                                 found=type(world).__name__)
        self.n = n = agent_count(n, "Collision")
        footprint = Disc(0.2) if footprint is None else footprint
        if not isinstance(footprint, Footprint):
            raise ParameterError("footprint must be a Disc, Rectangle or "
                                 "PolygonFootprint", block="Collision",
                                 param="footprint", found=type(footprint).__name__)
        footprint.bounding_radius(n)  # validates per-agent sizes
        if not (np.isfinite(margin) and margin >= 0):
            raise ParameterError("margin must be >= 0", block="Collision",
                                 param="margin", found=margin)
        self.world, self.footprint = world, footprint
        self.declare_parameter("margin", float(margin), bounds=(0, None), unit="m")
        self.agents = bool(agents)
        self.input = declare_agents_input(self, n, input)
        self.declare_output("hit_obstacle", (n,), "bool", doc="touches an obstacle")
        self.declare_output("hit_agent", (n,), "bool", doc="touches another agent")
        self.declare_output("collision", (n,), "bool", doc="touches anything")
        self.declare_output("hit_index", (n,), "int64",
                            doc="lowest obstacle index touched, -1 if none")
        self.declare_output("hit_agent_index", (n,), "int64",
                            doc="lowest other agent index touched, -1 if none")
        maybe_periodic(self, period)
        if method not in ("auto", "grid", "shapely"):
            raise ParameterError("method must be 'auto', 'grid' or 'shapely'",
                                 block="Collision", param="method",
                                 expected=["auto", "grid", "shapely"], found=method)
        self.method = method
        if method == "shapely":
            #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
            self.traceable = False
            return
        if reach is None:
            reach = float(np.max(footprint.bounding_radius(n))) + 2.0 * float(margin)
        reach = positive_scalar(reach, "Collision", "reach", allow_zero=True)
        self._grid_cache = {}            # EdgeGrid per reach (a memo: not in the compile key)
        self._reach = reach
        sreach = max(2.0 * reach, 1e-9)
        if capacity is None and n <= SMALL_N:
            sreach = math.inf           # all pairs: (N, N), exact, no plan needed
        self.search = (NeighborSearch(reach=sreach, points=self.input, capacity=capacity)
                       if self.agents and n > 1 else None)

    def output(self, t, x, u, xp):
        if self.method == "shapely" or (self.method == "auto" and xp is np):
            return collide(self.world, np.asarray(u[self.input]), self.footprint,
                           float(self.margin), self.agents)
        grid = self.edges
        need = float(np.max(self.footprint.bounding_radius(self.n))) + self.margin
        if xp is np:
            if float(need) > grid.reach:
                grid = self._grid(float(need))
        else:
            from ..core import diagnostics
            diagnostics.report(grid, Need(xp.asarray(0), need), grid)
        return collide_grid(grid, self.search, u[self.input], self.footprint,
                            self.margin, self.agents, xp)


class StopOnCollision(Block):
    """Zero the command of agents that collided (optionally latched).

    Ports
    -----
    cmd : in, (N, m)
    collision : in, (N,) bool
    cmd : out, (N, m)
        ``0`` for stopped agents, the input command otherwise.
    stopped : out, (N,) bool
        Agents whose command is zeroed now.

    State
    -----
    stopped : discrete (N,) bool, with ``latch=True``: once collided, an
    agent stays stopped (updated every major step).

    Parameters
    ----------
    n : int
    cmd_dim : int
        Command width (2 for the unicycle family).
    latch : bool
        Keep agents stopped after their first collision (default True).

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import StopOnCollision
    >>> b = StopOnCollision(2)
    >>> u = {"cmd": np.ones((2, 2)), "collision": np.array([True, False])}
    >>> b.output(0.0, b.initial_state(), u, np)["cmd"].tolist()
    [[0.0, 0.0], [1.0, 1.0]]
    """

    def __init__(self, n, cmd_dim=2, *, latch=True):
        super().__init__()
        self.n = n = agent_count(n, "StopOnCollision")
        self.latch = bool(latch)
        self.declare_input("cmd", (n, int(cmd_dim)), doc="command to pass on")
        self.declare_input("collision", (n,), "bool", doc="collision flags")
        self.declare_output("cmd", (n, int(cmd_dim)), doc="command, zero when stopped")
        self.declare_output("stopped", (n,), "bool", doc="agents stopped now")
        if self.latch:
            self.declare_discrete_state("stopped", np.zeros(n, dtype=bool))

    def output(self, t, x, u, xp):
        stop = u["collision"]
        if self.latch:
            stop = stop | x["stopped"]
        cmd = xp.where(stop[:, None], xp.zeros_like(u["cmd"]), u["cmd"])
        return {"cmd": cmd, "stopped": stop}

    def update(self, t, x, u, xp):
        return {"stopped": x["stopped"] | u["collision"]}
