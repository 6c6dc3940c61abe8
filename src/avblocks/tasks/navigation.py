"""The navigation task: N agents reach their goals among obstacles,
sensing with range rays, without collisions.

Blocks: :class:`NavigationTask` (observation, reward, success, fed by an
:class:`~avblocks.environment.RangeSensor` and a
:class:`~avblocks.environment.Collision`) and the scripted controller
:class:`NavigationLaw`. The case study that wires them, with its arena and
its reward described in full, is :mod:`avblocks.scenarios.navigation`
(``navigation.yaml``).

Reference: goal-reaching among obstacles with range sensing, as in the
navigation tasks of VMAS (M. Bettini et al., "VMAS: A Vectorized
Multi-Agent Simulator for Collective Robot Learning", DARS 2022); the
scripted law is a potential field (O. Khatib, "Real-time obstacle avoidance
for manipulators and mobile robots", IJRR 1986).
"""

from __future__ import annotations

import inspect

import numpy as np

from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import count, positive_scalar
from ..environment import World
from ..environment.boxes import boundary_distance, split_boxes
from ..utility.arrays import fold, norm2
from .common import drop_diagonal, pairwise, sort_rows


def _world(world, block):
    """``world`` if it is an :class:`avblocks.environment.World`, else a
    :class:`ParameterError` naming the block (a file gives one as
    ``{world: {...}}``)."""
    if not isinstance(world, World):
        raise ParameterError("world must be an avblocks.environment.World", block=block,
                             param="world", expected="World",
                             found=type(world).__name__)
    return world

class NavigationTask(Block):
    """Observation, reward and success of the navigation task.

    Ports
    -----
    position : in, (N, 2) [m]
    goals : in, (N, 2) [m]
    ranges : in, (N, rays) [m], the range sensor's readings
    contact : in, (N,) bool, the collision block's ``collision``
    obs : out, (N, 4 + rays + 2(N-1))
    reward : out, (N,)
    done : out, (N,) bool (always false)
    collision : out, (N,) bool: touching an obstacle, a wall or an agent now
    at_goal : out, (N,) bool
    success : out, (N,) bool: at the goal and no collision so far

    State
    -----
    prev : discrete (N,), distance to the goal at the previous step
    hit : discrete (N,) bool, a collision happened this episode

    Parameters
    ----------
    n : int
        Agents.
    world : World
        The obstacles and walls (their edges: the closeness term).
    rays : int
        Number of range rays (structural).
    half : float
        Half the side of the square arena [m] (scales the own position).
    radius : float
        Agent radius [m].
    goal_radius : float
        At the goal within this distance [m].
    max_range : float
        The range sensor's reach [m] (scales the ranges).
    progress, collision, proximity, goal_bonus, first_hit, success_bonus : float
        Reward weights (numeric parameters).
    margin : float
        Gap below which the closeness term grows [m].
    sort_others : bool
        Other agents nearest first (structural).
    observe_velocity : bool
        Also observe the other agents' velocity commands of the last step
        relative to its own (input ``velocity``, not direct feedthrough;
        structural).
    prev0 : array_like, optional
        (N,) initial distance to the goal [m] (the first step's progress is
        measured from it; default zeros). The case study sets it from the
        starts and goals.

    Numeric parameters
    ------------------

    ``half``, ``radius``, ``goal_radius``, ``max_range``, ``margin`` and the
    reward weights ``progress``, ``collision``, ``proximity``,
    ``goal_bonus``, ``first_hit``, ``success_bonus`` (scalars, read at every
    call: ``"task.progress"``...). ``n``, ``rays``, ``world`` (its edges),
    ``sort_others``, ``observe_velocity`` are structural; ``prev0`` is the
    initial state of ``prev``.

    Equations
    ---------
    With ``d`` the distance to the goal, ``d_prev`` its value at the last
    step, ``c`` the contact flag and ``h`` "a contact happened before":

    - ``obs = [g - p, p / half, ranges / max_range, others (m)]``;
    - ``reward = progress (d_prev - d) + goal_bonus [d < goal_radius]
      + success_bonus success - first_hit [c and not h] - collision c
      - proximity closeness`` (closeness: ``sum clip(1 - gap / margin, 0,
      1)`` over the other agents and the nearest obstacle or wall);
    - ``success = [d < goal_radius] and not (h or c)``.

    The functions broadcast over leading batch axes (``batch_axes``: the
    NumPy vector environment steps K copies in one call).
    """

    batch_axes = True
    example = {"n": "$agents", "world": {"world": {"bounds": [-1.5, -1.5, 1.5, 1.5],
                                                   "walls": True}}}
    parameter_info = {"n": {"bounds": [1, None]}}

    def __init__(self, n, world, *, rays=12, half=1.5, radius=0.1, goal_radius=0.15,
                 max_range=1.0, progress=5.0, collision=2.5, proximity=0.5, margin=0.2,
                 goal_bonus=0.1, first_hit=0.0, success_bonus=0.0, sort_others=True,
                 observe_velocity=False, prev0=None):
        super().__init__()
        self.n = n = count(n, "NavigationTask", "n", lo=1)
        world = _world(world, "NavigationTask")
        self.rays = int(rays)
        self.sort_others = bool(sort_others)
        self.observe_velocity = bool(observe_velocity)
        seg = np.asarray(world.segments, float).reshape(-1, 4)        # walls included
        # rectangles (the walls too) as boxes in closed form, other edges as such
        self.boxes, _, rest = split_boxes(seg.reshape(-1, 2, 2), world.segment_owner)
        self.rest_seg = seg[rest]
        self.declare_parameter("half", half, bounds=(0, None), unit="m")
        self.declare_parameter("radius", radius, bounds=(0, None), unit="m")
        self.declare_parameter("goal_radius", goal_radius, bounds=(0, None), unit="m")
        self.declare_parameter("max_range", max_range, bounds=(0, None), unit="m")
        self.declare_parameter("progress", progress, bounds=(0, None))
        self.declare_parameter("collision", collision, bounds=(0, None))
        self.declare_parameter("proximity", proximity, bounds=(0, None))
        self.declare_parameter("margin", margin, bounds=(1e-6, None), unit="m")
        self.declare_parameter("goal_bonus", goal_bonus, bounds=(0, None))
        self.declare_parameter("first_hit", first_hit, bounds=(0, None))
        self.declare_parameter("success_bonus", success_bonus, bounds=(0, None))
        self.declare_input("position", (n, 2), unit="m")
        self.declare_input("goals", (n, 2), unit="m")
        self.declare_input("ranges", (n, self.rays), unit="m")
        self.declare_input("contact", (n,), "bool")
        prev = np.zeros(n) if prev0 is None else np.asarray(prev0, dtype=float)
        if prev.shape != (n,) or not np.all(np.isfinite(prev)):
            raise ParameterError("prev0 must be N finite distances", block="NavigationTask",
                                 param="prev0", expected=f"({n},)", found=prev.shape)
        self.declare_discrete_state("prev", prev, dtype="float64")
        self.declare_discrete_state("hit", np.zeros(n, dtype=bool))
        if self.observe_velocity:
            # the commands of the last step (not feedthrough: read from state)
            self.declare_input("velocity", (n, 2), unit="m/s", feedthrough=False)
            self.declare_discrete_state("vel", np.zeros((n, 2)), dtype="float64")
        self.declare_output("obs", (n, 4 + self.rays + 2 * (n - 1)
                                    * (2 if self.observe_velocity else 1)))
        self.declare_output("reward", (n,))
        self.declare_output("done", (n,), "bool")
        self.declare_output("collision", (n,), "bool")
        self.declare_output("at_goal", (n,), "bool")
        self.declare_output("success", (n,), "bool")

    def _closeness(self, p, xp):
        """Sum over the other agents and the nearest obstacle or wall of
        ``clip(1 - gap / margin, 0, 1)`` (gap: distance minus the contact
        distance): a smooth warning before contact."""
        r, m = self.radius, self.margin
        gap_a = pairwise(p, xp) - 2 * r
        near_a = fold(xp.add, xp.clip(1.0 - gap_a / m, 0.0, 1.0), -1, xp)
        gap = boundary_distance(p[..., 0:1], p[..., 1:2], self.boxes, self.rest_seg,
                                xp) - r                                   # (..., N)
        return near_a + xp.clip(1.0 - gap / m, 0.0, 1.0)

    def output(self, t, x, u, xp):
        p, g, col = u["position"], u["goals"], u["contact"]
        rel = g - p
        d = xp.sqrt(norm2(rel) + 1e-12)
        # every agent relative to each (row i, column j: j - i), the diagonal
        # dropped by two shifted slices (no gather), then sorted by ranks
        rel_a = p[..., None, :, :] - p[..., :, None, :]                 # (..., n, n, 2)
        parts = [rel_a]
        if self.observe_velocity:
            v = x["vel"]
            parts.append(v[..., None, :, :] - v[..., :, None, :])
        parts = [drop_diagonal(q, xp) for q in parts]                 # (..., n, n-1, k)
        if self.sort_others and self.n > 2:
            parts = sort_rows(norm2(parts[0]), parts, xp)
        others = [xp.reshape(q, p.shape[:-2] + (self.n, -1)) for q in parts]
        obs = xp.concatenate([rel, p / self.half, u["ranges"] / self.max_range, *others],
                             axis=-1)
        at = d < self.goal_radius
        success = at & ~(x["hit"] | col)
        first = col & ~x["hit"]
        reward = (self.progress * (x["prev"] - d) + self.goal_bonus * at
                  + self.success_bonus * success - self.first_hit * first
                  - self.collision * col - self.proximity * self._closeness(p, xp))
        return {"obs": obs, "reward": reward, "done": xp.zeros(d.shape, dtype=bool),
                "collision": col, "at_goal": at, "success": success}

    def update(self, t, x, u, xp):
        p, g = u["position"], u["goals"]
        rel = g - p
        new = {"prev": xp.sqrt(norm2(rel) + 1e-12),
               "hit": x["hit"] | u["contact"]}
        if self.observe_velocity:
            new["vel"] = u["velocity"]
        return new


#: The reward's weights (the task block's parameters) and their defaults,
#: read from :class:`NavigationTask`'s signature (one place for the values).
REWARD = {k: inspect.signature(NavigationTask).parameters[k].default
          for k in ("progress", "goal_bonus", "success_bonus", "collision", "first_hit",
                    "proximity", "margin")}


def navigation_command(position, goals, edges, half, xp):
    """The hand-written controller's command (N, 2) in ``[-1, 1]^2``: unit
    attraction to the goal (slowing within 0.3 m), repulsion from the
    nearest point of each obstacle edge (``edges`` (E, 4)), the walls of
    ``[-half, half]^2`` and other agents within 0.35 m, plus a sideways term
    that slides around an obstacle in front (:class:`NavigationLaw`'s
    equations)."""
    d0 = 0.35
    p = position
    rel = goals - p
    dist = xp.sqrt(xp.sum(rel * rel, -1, keepdims=True) + 1e-12)
    att = rel / dist * xp.minimum(1.0, dist / 0.3)
    # nearest points on edges
    a, b = edges[:, :2], edges[:, 2:]
    ab = b - a
    ap = p[:, None, :] - a
    s = xp.clip(xp.sum(ap * ab, -1) / xp.sum(ab * ab, -1), 0.0, 1.0)
    away = ap - s[..., None] * ab                              # (n, E, 2)
    da = xp.sqrt(xp.sum(away * away, -1) + 1e-12)
    w = xp.where(da < d0, (1.0 / da - 1.0 / d0) * 0.15, 0.0)
    rep = xp.sum(away / da[..., None] * w[..., None], axis=1)
    # walls
    for k in (0, 1):
        lo = p[:, k] + half
        hi = half - p[:, k]
        f = xp.where(lo < d0, (1.0 / lo - 1.0 / d0) * 0.15, 0.0) - \
            xp.where(hi < d0, (1.0 / hi - 1.0 / d0) * 0.15, 0.0)
        rep = rep + f[:, None] * np.eye(2)[k]
    # agents
    dp = p[:, None, :] - p[None, :, :]
    dd = xp.sqrt(xp.sum(dp * dp, -1) + 1e-12) + np.eye(p.shape[0]) * 1e3
    wa = xp.where(dd < d0, (1.0 / dd - 1.0 / d0) * 0.1, 0.0)
    rep = rep + xp.sum(dp / dd[..., None] * wa[..., None], axis=1)
    # slide: the repulsion turned 90 degrees towards the goal's side
    perp = xp.stack([-rep[:, 1], rep[:, 0]], axis=-1)
    side = xp.sign(xp.sum(perp * rel, -1, keepdims=True) + 1e-9)
    v = att + rep + 0.5 * side * perp
    nv = xp.sqrt(xp.sum(v * v, -1, keepdims=True) + 1e-12)
    return v / xp.maximum(nv, 1.0)


def scripted_law(edges, half, speed, radius):
    """The hand-written controller (``navigation_command``) with its
    edges and walls fixed: returns ``f(t, position, goals, xp)`` giving a
    command in ``[-1, 1]^2``. ``speed`` and ``radius`` are not used (kept
    for callers)."""
    edges = np.asarray(edges, float)

    def law(t, position, goals, xp):
        return navigation_command(position, goals, edges, half, xp)

    return law


def obstacle_edges(world):
    """(E, 4) edges of a world's obstacles, walls excluded: what
    :class:`NavigationLaw` is repelled by."""
    keep = np.asarray(world.segment_owner) < world.n_user
    return np.asarray(world.segments, float)[keep]


class NavigationLaw(Block):
    """The navigation task's scripted controller: goal attraction plus
    repulsion from obstacle edges, walls and other agents, sliding around.

    Ports
    -----
    position : in, (N, 2) [m]
    goals : in, (N, 2) [m]
    cmd : out, (N, 2), in the unit disc

    Parameters
    ----------
    n : int
        Agents.
    world : World
        The obstacles (their edges; walls excluded, see ``half``).
    half : float
        The walls bound ``[-half, half]^2`` [m].

    Numeric parameters
    ------------------

    ``half`` (read at every call: the walls move with it); the obstacle
    edges are fixed by ``world`` at construction (structural).

    Equations
    ---------
    Attraction ``a = (g - p) / |g - p| min(1, |g - p| / 0.3)``; repulsion,
    within ``d0 = 0.35`` m, ``0.15 (1/d - 1/d0)`` along the way from each
    edge's nearest point and from each wall, ``0.1 (1/d - 1/d0)`` from each
    other agent (a potential field, Khatib 1986); the repulsion ``r`` turned
    90 degrees towards the goal's side, ``s``; ``v = a + r + 0.5 s`` and
    ``cmd = v / max(|v|, 1)`` (``navigation_command``).

    Examples
    --------
    >>> import numpy as np
    >>> from avblocks.environment import World
    >>> law = NavigationLaw(1, World([], bounds=(-5, -5, 5, 5), walls=True), half=5.0)
    >>> law.output(0.0, {}, {"position": np.zeros((1, 2)),
    ...                      "goals": np.array([[2.0, 0.0]])}, np)["cmd"].round(6)
    array([[1., 0.]])
    """

    example = {"n": "$agents", "world": {"world": {"bounds": [-1.5, -1.5, 1.5, 1.5],
                                                   "walls": True}}}
    parameter_info = {"n": {"bounds": [1, None]}, "half": {"bounds": [0, None], "unit": "m"}}

    def __init__(self, n, world, *, half=1.5):
        super().__init__()
        self.n = n = count(n, "NavigationLaw", "n", lo=1)
        self.declare_parameter("half", positive_scalar(half, "NavigationLaw", "half"),
                               bounds=(1e-12, None), unit="m")
        self.edges = obstacle_edges(_world(world, "NavigationLaw"))
        self.declare_input("position", (n, 2), unit="m")
        self.declare_input("goals", (n, 2), unit="m")
        self.declare_output("cmd", (n, 2))

    def output(self, t, x, u, xp):
        return {"cmd": navigation_command(u["position"], u["goals"], self.edges, self.half,
                                          xp)}
