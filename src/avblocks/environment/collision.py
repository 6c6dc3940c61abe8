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

The computation runs in NumPy/shapely: the block is not traceable by JAX
(it runs in the NumPy simulator only).
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..core.block import Block
from ..core.errors import ParameterError
from ._common import agent_count, declare_agents_input, maybe_periodic
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


class Collision(Block):
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

    Equations
    ---------
    See :func:`collide`; touching counts.

    Notes
    -----
    NumPy/shapely side computation: not JAX-traceable.

    Example
    -------
    >>> import numpy as np
    >>> from avblocks.environment import World, Collision, Disc, rectangle
    >>> col = Collision(World([rectangle(1, -1, 2, 1)]), 2, footprint=Disc(0.5))
    >>> y = col.output(0.0, {}, {"pose": np.array([[0.5, 0, 0], [-3, 0, 0]])}, np)
    >>> y["collision"].tolist(), y["hit_index"].tolist()
    ([True, False], [0, -1])
    """

    #: NumPy/SciPy/shapely only: the compiled backend refuses it by name.
    traceable = False

    def __init__(self, world, n, *, footprint=None, input="pose", margin=0.0,
                 agents=True, period=None):
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

    def output(self, t, x, u, xp):
        return collide(self.world, np.asarray(u[self.input]), self.footprint,
                       float(self.margin), self.agents)


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
