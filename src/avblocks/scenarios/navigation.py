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
:class:`~avblocks.controllers.Policy` instead. The task block and the
scripted law are :class:`avblocks.tasks.NavigationTask` and
:class:`avblocks.tasks.NavigationLaw`.

The scenario file ``navigation.yaml`` is this module's twin (the same
blocks; arena, starts, goals and ray angles from the
:func:`navigation_arena`, :func:`navigation_starts` and
:func:`navigation_rays` generators): it is what ``avblocks run
navigation`` runs, to the same numbers; ``--set controller=policy.npz``
runs a trained policy there too (a ``tasks.TaskCommand``).
:func:`make_diagram` (with ``vehicles=``, ``weights=``,
``observe_velocity=``) and :func:`rl_task` remain the Python API.
"""

from __future__ import annotations

import functools

import numpy as np

from avblocks.blocks import Constant
from avblocks.core.diagram import Diagram
from avblocks.core.errors import ParameterError
from avblocks.environment import Collision, Disc, EdgeGrid, RangeSensor, World, rectangle
from avblocks.scenarios._task import command_source, drive_at_speed, free_points
from avblocks.tasks import REWARD, NavigationLaw, NavigationTask, scripted_law  # noqa: F401
from avblocks.vehicles import SingleIntegrator

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


def _weights(weights):
    w = dict(REWARD)
    for k, v in (weights or {}).items():
        if k not in REWARD:
            raise ParameterError("unknown reward weight", block="task", param=str(k),
                                 expected=sorted(REWARD), found=k)
        w[k] = float(v)
    return w


def _draw(n, half, grid, seed, clearance):
    rng = np.random.default_rng([int(seed), 57])
    from avblocks.core import rng as avrng
    k = avrng.key(int(rng.integers(2**31)), "navigation")
    k1, k2 = avrng.split(k, np, 2)
    p0 = free_points(k1, n, half, grid, clearance, np, min_sep=0.4)
    g = free_points(k2, n, half, grid, clearance, np, min_sep=0.4)
    return p0, g


def _checked(agents, seed, obstacles):
    from avblocks.core.params import count, integer
    from avblocks.scenarios.limits import budget
    n = count(agents, None, "agents", lo=1)
    budget(24 * 2 * n, "navigation_starts")
    obs = np.asarray(obstacles, dtype=float).reshape(-1, 4) if np.size(obstacles) else ()
    return n, integer(seed, None, "seed"), tuple(map(tuple, obs))


@functools.lru_cache(maxsize=8)
def _cached_grid(half, clearance, obstacles):
    return EdgeGrid(arena(half, obstacles), clearance)


@functools.lru_cache(maxsize=32)
def _cached_draw(n, half, seed, clearance, obstacles):
    """The starts and goals of a seed; a file asks three times (starts,
    goals, their distances) and the editor at every check: the obstacle
    grid (most of the time: 0.1 s) and the draws are made once."""
    p0, g = _draw(n, half, _cached_grid(half, clearance, obstacles), seed, clearance)
    p0.setflags(write=False)
    g.setflags(write=False)
    return p0, g


def navigation_arena(half=1.5, obstacles=OBSTACLES):
    """:func:`arena` as a scenario-file generator:
    ``world: {navigation_arena: {half: $half, obstacles: $obstacles}}``."""
    obs = np.asarray(obstacles, dtype=float).reshape(-1, 4) if np.size(obstacles) else ()
    return arena(float(half), tuple(map(tuple, obs)))


def navigation_starts(agents, seed, half=1.5, clearance=0.25, obstacles=OBSTACLES,
                      which="starts"):
    """The draws of :func:`make_diagram` for a seed: the agents' (N, 2)
    starts (``which: starts``), their (N, 2) goals (``goals``) or the (N,)
    distances between them (``distance``: the task block's ``prev0``), at
    least ``clearance`` from the obstacles and walls of the arena. A
    scenario-file generator (``{navigation_starts: {agents: $agents, seed:
    $seed, ...}}``)."""
    n, seed, obs = _checked(agents, seed, obstacles)
    if which not in ("starts", "goals", "distance"):
        raise ValueError(f"which must be 'starts', 'goals' or 'distance', got {which!r:.40}")
    p0, g = _cached_draw(n, float(half), seed, float(clearance), obs)
    p0, g = p0.copy(), g.copy()
    if which == "distance":
        return np.linalg.norm(g - p0, axis=1)
    return p0 if which == "starts" else g


def navigation_rays(rays=12):
    """:func:`ray_angles` as a scenario-file generator (the range sensor's
    ``angles``): ``{navigation_rays: {rays: $rays}}``."""
    from avblocks.core.params import count
    return ray_angles(count(rays, None, "rays", lo=1, hi=10**6))


#: this case study's scenario-file generators
GENERATORS = {"navigation_arena": navigation_arena, "navigation_starts": navigation_starts,
              "navigation_rays": navigation_rays}


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
                                observe_velocity=bool(observe_velocity),
                                prev0=np.linalg.norm(goals - p0, axis=1), **w), name="task")
    for b in (lidar, contact, task):
        d.connect(position, b.position)
    d.connect(gl.y, task.goals)
    d.connect(lidar.ranges, task.ranges)
    d.connect(contact.collision, task.contact)
    if controller == "scripted":
        src = d.add(NavigationLaw(n, world, half=h), name="drive")
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
