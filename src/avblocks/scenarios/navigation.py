"""Navigation (a learning task): N agents reach their goals among polygon
obstacles, sensing with range rays, without collisions.

Set-up
------
``agents`` single integrators (``vehicles.SingleIntegrator``, speed
``speed`` per unit of command) in the square arena ``[-half, half]^2``
with rectangular obstacles (``obstacles``: a list of ``(cx, cy, w, h)``),
an :class:`~avblocks.environment.World` with walls at the arena's border
(:func:`arena`). Each agent has a goal (``goals.value``, a
``blocks.Constant``). The library's own sensing blocks do the geometry:

- ``lidar``, an :class:`~avblocks.environment.RangeSensor` with ``rays``
  rays evenly spread in the world frame (from ``-pi``), reading the distance
  to the first obstacle edge, wall or other agent (a disc of ``radius``) up
  to ``max_range``;
- ``contact``, a :class:`~avblocks.environment.Collision` of the agents'
  discs (``radius``) with the obstacles, the walls and each other (touching
  counts).

Both are traceable (the compiled engine uses their edge-grid method, the
NumPy engine their shapely method; they agree to 1e-9 m).

Task (what :func:`avblocks.rl.parallel_env` ``("navigation")`` exposes)
------------------------------------------------------------------------
- **action** (per agent, 2): velocity command in ``[-1, 1]^2`` times
  ``speed`` [m/s].
- **observation** (per agent, ``4 + rays + 2(N-1)``): goal relative to
  the agent (m), own position divided by ``half``, the ray ranges divided
  by ``max_range``, the other agents relative to it (m), nearest first
  with ``sort_others`` (the default), else in index order (``task.obs``);
  with ``observe_velocity``, 2(N-1) more: the other agents' velocity
  commands of the last step relative to its own, in the same order.
- **reward** (per agent): ``progress * (d_prev - d)`` (``d`` the distance
  to the goal, over the last control step) ``+ goal_bonus * [d <
  goal_radius]`` (``goal_bonus`` 0.1)
  ``- collision * [touching an obstacle, a wall or another agent]``
  ``- proximity * closeness`` where closeness sums ``clip(1 - gap/margin,
  0, 1)`` over the other agents and the nearest obstacle or wall (``gap``:
  distance minus the contact distance; a smooth warning before contact)
  ``+ success_bonus * success - first_hit * [first contact of the episode]``
  (both 0 by default) (``task.reward``; the weights: :data:`REWARD`, set
  with ``weights=`` in :func:`make_diagram` and :func:`rl_task`).
- **done**: never; episodes last ``max_steps`` control steps (default 60
  of 0.1 s).
- **success** (per agent, ``task.success``): at its goal (within
  ``goal_radius``) and no collision so far in the episode. The success
  rate of a policy is the fraction of agents with ``success`` at the last
  step, over evaluation episodes.

Starts and goals are drawn anew at every reset, at least ``clearance`` from
obstacles and walls (an :class:`~avblocks.environment.EdgeGrid` disc test)
and ``5 * radius`` apart.

The task is fair as drawn (``benchmarks/navigation_failures.py``, 1,000
resets): no agent touches anything at t=0, no pair of starts or of goals is
closer than the requested 0.5 m, and the longest shortest collision-free
path of an agent alone is 3.6 m, 3.6 s at 1 m/s (any direction can be
driven at 1 m/s) against the 6 s horizon. What is hard is the agents
among themselves: the scripted controller's failures are mostly contacts
between agents (27 % of the agents), then ending away from the goal
without contact (9 %), rarely obstacles or walls (2 %).

``avblocks run navigation`` runs the scripted controller (goal attraction
plus repulsion from the nearest obstacle points and agents);
``controller="policy.npz"`` runs a trained
:class:`~avblocks.controllers.Policy` instead.
"""

from __future__ import annotations

import inspect

import numpy as np

from avblocks.blocks import Constant, Function
from avblocks.core.block import Block
from avblocks.core.diagram import Diagram
from avblocks.core.errors import ParameterError
from avblocks.environment import Collision, Disc, EdgeGrid, RangeSensor, World, rectangle
from avblocks.environment.boxes import boundary_distance, split_boxes
from avblocks.utility.arrays import fold, norm2
from avblocks.vehicles import SingleIntegrator

from ._task import (
    command_source,
    drive_at_speed,
    drop_diagonal,
    free_points,
    pairwise,
    sort_rows,
)

MOVIE = {"pose": "fleet.position", "trail": 3.0}

OBSTACLES = ((0.0, 0.0, 0.8, 0.5), (-0.9, 0.8, 0.5, 0.3), (0.9, -0.8, 0.3, 0.6))


def arena(half=1.5, obstacles=OBSTACLES):
    """The navigation world: rectangles ``(cx, cy, w, h)`` and walls
    bounding ``[-half, half]^2`` (an :class:`~avblocks.environment.World`)."""
    h = float(half)
    rects = [rectangle(cx - w / 2, cy - hh / 2, cx + w / 2, cy + hh / 2)
             for cx, cy, w, hh in obstacles]
    return World(rects, bounds=(-h, -h, h, h), walls=True)


def ray_angles(rays):
    """World-frame ray directions: ``rays`` evenly spread from ``-pi``."""
    return np.linspace(-np.pi, np.pi, int(rays), endpoint=False)


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
    world : World, the obstacles and walls (their edges: the closeness term).
    half, radius, goal_radius, max_range, progress, collision, proximity,
    margin, goal_bonus, first_hit, success_bonus : numeric (module docstring).
    rays : int (structural), number of range rays.
    sort_others : bool (structural), other agents nearest first.
    observe_velocity : bool (structural), also observe the other agents'
        velocity commands of the last step relative to its own (input
        ``velocity``, not direct feedthrough).

    The functions broadcast over leading batch axes (``batch_axes``: the
    NumPy vector environment steps K copies in one call).
    """

    batch_axes = True

    def __init__(self, n, world, *, rays=12, half=1.5, radius=0.1, goal_radius=0.15,
                 max_range=1.0, progress=5.0, collision=2.5, proximity=0.5, margin=0.2,
                 goal_bonus=0.1, first_hit=0.0, success_bonus=0.0, sort_others=True,
                 observe_velocity=False):
        super().__init__()
        self.n = n
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
        self.declare_discrete_state("prev", np.zeros(n), dtype="float64")
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


def _weights(weights):
    w = dict(REWARD)
    for k, v in (weights or {}).items():
        if k not in REWARD:
            raise ParameterError("unknown reward weight", block="task", param=str(k),
                                 expected=sorted(REWARD), found=k)
        w[k] = float(v)
    return w


def scripted_law(edges, half, speed, radius):
    """The hand-written controller: unit attraction to the goal (slowing
    within 0.3 m), repulsion from the nearest point of each obstacle edge,
    the walls and other agents within 0.35 m, plus a sideways term that
    slides around an obstacle in front. Returns ``f(t, position, goals, xp)``
    giving a command in ``[-1, 1]^2``."""
    edges = np.asarray(edges, float)
    d0 = 0.35

    def law(t, position, goals, xp):
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

    return law


def _obstacle_edges(world):
    """(E, 4) edges of the obstacles (walls excluded): the scripted law's."""
    keep = np.asarray(world.segment_owner) < world.n_user
    return np.asarray(world.segments, float)[keep]


def _draw(n, half, grid, seed, clearance):
    rng = np.random.default_rng([int(seed), 57])
    from avblocks.core import rng as avrng
    k = avrng.key(int(rng.integers(2**31)), "navigation")
    k1, k2 = avrng.split(k, np, 2)
    p0 = free_points(k1, n, half, grid, clearance, np, min_sep=0.4)
    g = free_points(k2, n, half, grid, clearance, np, min_sep=0.4)
    return p0, g


def make_diagram(agents=4, half=1.5, speed=1.0, radius=0.1, goal_radius=0.15, rays=12,
                 max_range=1.0, clearance=0.25, obstacles=OBSTACLES, controller="scripted",
                 seed=1, t_final=6.0, dt=0.1, sort_others=True, observe_velocity=False,
                 vehicles=None, weights=None):
    """The navigation diagram and its simulation settings (module docstring).

    ``vehicles``: optional ``vehicles(diagram, p0) -> (position, velocity)``
    adding other vehicles than the single integrators (``"fleet"``): the
    output port giving the (N, 2) positions the task senses from and the
    input port taking the (N, 2) velocity commands [m/s] (e.g. MuJoCo ground
    robots behind an off-axis point map). Everything else is unchanged.

    ``weights``: reward weights of the task block (:data:`REWARD`, e.g.
    ``{"first_hit": 5.0}``); the others keep their defaults."""
    n, h, r = int(agents), float(half), float(radius)
    w = _weights(weights)
    world = arena(h, obstacles)
    p0, goals = _draw(n, h, EdgeGrid(world, float(clearance)), seed, float(clearance))
    d = Diagram("navigation")
    if vehicles is None:
        fleet = d.add(SingleIntegrator(p0, v_max=float(speed) * np.sqrt(2)), name="fleet")
        position, velocity = fleet.position, fleet.velocity
    else:
        position, velocity = vehicles(d, p0)
    gl = d.add(Constant(goals), name="goals")
    lidar = d.add(RangeSensor(world, n, angles=ray_angles(rays), max_range=float(max_range),
                              agent_radius=r, input="position"), name="lidar")
    contact = d.add(Collision(world, n, footprint=Disc(r), input="position"), name="contact")
    task = d.add(NavigationTask(n, world, rays=int(rays), half=h, radius=r,
                                goal_radius=float(goal_radius),
                                max_range=float(max_range),
                                sort_others=bool(sort_others),
                                observe_velocity=bool(observe_velocity), **w), name="task")
    task.block.set_initial("prev", np.linalg.norm(goals - p0, axis=1))
    for b in (lidar, contact, task):
        d.connect(position, b.position)
    d.connect(gl.y, task.goals)
    d.connect(lidar.ranges, task.ranges)
    d.connect(contact.collision, task.contact)
    if controller == "scripted":
        law = scripted_law(_obstacle_edges(world), h, float(speed), r)
        src = d.add(Function(law, inputs={"position": (n, 2), "goals": (n, 2)},
                             outputs={"cmd": (n, 2)}), name="drive")
        d.connect(position, src.position)
        d.connect(gl.y, src.goals)
        cmd = src.cmd
    else:
        src, port = command_source(d, controller, n, task.obs)
        cmd = getattr(src, port)
    gain = drive_at_speed(d, cmd, velocity, speed)
    if observe_velocity:
        d.connect(gain.y, task.velocity)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4", "seed": int(seed),
           "log": [position, gl.y, task.success, task.collision, task.reward]}
    return d, sim


def rl_task(agents=4, half=1.5, speed=1.0, radius=0.1, goal_radius=0.15, rays=12,
            max_range=1.0, clearance=0.25, obstacles=OBSTACLES, sort_others=True,
            observe_velocity=False, weights=None):
    """The learning task (module docstring): settings for :class:`avblocks.rl.Task`.
    ``weights``: reward weights (:data:`REWARD`) as :func:`make_diagram`."""
    n, h = int(agents), float(half)
    d, sim = make_diagram(agents=n, half=h, speed=speed, radius=radius,
                          goal_radius=goal_radius, rays=rays, max_range=max_range,
                          clearance=clearance, obstacles=obstacles, controller="action",
                          sort_others=sort_others, observe_velocity=observe_velocity,
                          weights=weights)
    c = float(clearance)
    grid = EdgeGrid(arena(h, obstacles), c)

    def reset(key, xp):
        from avblocks.core import rng
        k1, k2 = rng.split(key, xp, 2)
        p0 = free_points(k1, n, h, grid, c, xp, min_sep=5 * float(radius))
        g = free_points(k2, n, h, grid, c, xp, min_sep=5 * float(radius))
        return {"fleet.position": p0, "goals.value": g,
                "task.prev": xp.sqrt(xp.sum((g - p0) ** 2, -1) + 1e-12)}

    return {"diagram": d, "act": "action", "observe": "task.obs", "reward": "task.reward",
            "done": "task.done", "reset": reset,
            "info": {"success": "task.success", "collision": "task.collision"},
            "dt": sim["dt"], "substeps": 1, "max_steps": 60, "solver": "euler"}


def outcome(res, params):
    """Agents at their goals without a collision at the end; collisions seen."""
    ok = np.asarray(res["task.success"])[-1]
    col = np.asarray(res["task.collision"]).any(axis=0)
    n = ok.size
    return (f"{int(ok.sum())} of {n} agents at their goals without collision at "
            f"{res.t[-1]:.3g} s ({int(col.sum())} touched something)",
            {"success": int(ok.sum()), "agents": n, "collided": int(col.sum())})


def figures(res, out, params):
    """navigation.png: obstacles, paths, goals."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from avblocks.scenarios.report import save_figure
    p = np.asarray(res["fleet.position"])
    g = np.asarray(res["goals.y"])[0]
    h = float(params.get("half", 1.5))
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    for cx, cy, w, hh in params.get("obstacles", OBSTACLES):
        ax.add_patch(Rectangle((cx - w / 2, cy - hh / 2), w, hh, color="0.55"))
    for i in range(p.shape[1]):
        line, = ax.plot(p[:, i, 0], p[:, i, 1], lw=1.5)
        ax.plot(*p[0, i], "o", color=line.get_color(), ms=4)
        ax.plot(*g[i], "x", color=line.get_color(), ms=9, mew=2)
    ax.add_patch(Rectangle((-h, -h), 2 * h, 2 * h, fill=False, lw=1.5))
    ax.set_xlim(-h * 1.05, h * 1.05)
    ax.set_ylim(-h * 1.05, h * 1.05)
    ax.set_aspect("equal")
    line, _ = outcome(res, params)
    ax.set_title(line, fontsize=8)
    return [save_figure(fig, f"{out}/navigation.png")]
