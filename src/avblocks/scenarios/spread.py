"""Spread (a learning task): N agents cover N landmarks without colliding.

Set-up
------
``agents`` single integrators (``vehicles.SingleIntegrator``, speed
``speed`` per unit of command) in the square ``[-half, half]^2`` and as many
landmarks (a ``blocks.Constant``, numeric parameter ``landmarks.value``).
The multi-agent particle environments' "simple spread" task, on the
library's own blocks.

Task (what :func:`avblocks.rl.parallel_env` ``("spread")`` exposes)
--------------------------------------------------------------------
- **action** (per agent, 2): velocity command in ``[-1, 1]^2``, times
  ``speed`` [m/s] (``action`` block).
- **observation** (per agent, ``2 + 2N + 2(N-1)``): own position, every
  landmark relative to the agent, every other agent relative to it
  (``task.obs``, a ``tasks.SpreadTask``).
- **reward** (per agent): ``-sum_l min_i |p_i - l|`` (shared: how far the
  landmarks are from being covered), minus ``collision`` for each other
  agent closer than ``2 * radius`` (``task.reward``).
- **done**: never (episodes end after ``max_steps`` control steps).
- **success**: every landmark has an agent within ``cover`` of it
  (``task.success``, per run; the outcome line reports it at the end).

Starts and landmarks are drawn anew at every reset (uniform in the square).
``avblocks run spread`` runs the scripted controller: each agent is assigned
a landmark by a minimum-total-distance matching (Hungarian method) and
drives to it (``controllers.HolonomicPointToPoint``; the matching is
:func:`avblocks.tasks.assign_landmarks`, ``scipy.optimize.linear_sum_assignment``
at build time, from the starts).

The scenario file ``spread.yaml`` is this module's twin (the same blocks,
starts, landmarks and assignment from the :func:`spread_starts` and
:func:`spread_targets` generators): it is what ``avblocks run spread``
runs, to the same numbers; ``--set controller=policy.npz`` runs a trained
policy in both (a ``tasks.TaskCommand`` in the file). :func:`make_diagram`
and :func:`rl_task` remain the Python API (the learning environments).
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import Constant
from avblocks.core.diagram import Diagram
from avblocks.core.errors import ParameterError
from avblocks.scenarios._task import command_source, drive_at_speed, uniform_points
from avblocks.tasks import SpreadTask, assign_landmarks
from avblocks.vehicles import SingleIntegrator

MOVIE = {"pose": "fleet.position", "trail": 2.0}


def _starts(n, half, seed):
    rng = np.random.default_rng([int(seed), 31])
    return rng.uniform(-half, half, (n, 2)), rng.uniform(-half, half, (n, 2))


def _checked(agents, seed):
    from avblocks.core.params import count, integer
    from avblocks.scenarios.limits import budget
    n = count(agents, None, "agents", lo=1)
    budget(n * n + 4 * n, "spread_starts")
    return n, integer(seed, None, "seed")


def spread_starts(agents, half, seed, which="agents"):
    """The draws of :func:`make_diagram` for a seed: the agents' (N, 2)
    starts (``which: agents``) or the (N, 2) landmarks (``which:
    landmarks``), uniform in ``[-half, half]^2``. A scenario-file generator
    (``{spread_starts: {agents: $agents, half: $half, seed: $seed}}``)."""
    n, seed = _checked(agents, seed)
    if which not in ("agents", "landmarks"):
        raise ValueError(f"which must be 'agents' or 'landmarks', got {which!r:.40}")
    p0, lm = _starts(n, float(half), seed)
    return p0 if which == "agents" else lm


#: Most agents :func:`spread_targets` matches. The Hungarian method takes
#: O(N^3) time, which no memory limit bounds: 2,000 agents take about 1 s
#: here, 4,000 about 4.5 s, 30,000 would take most of an hour. A scenario
#: file is someone else's file: its generators stay within seconds.
MAX_MATCHED = 2_000


def spread_targets(agents, half, seed):
    """(N, 1, 2): each agent's landmark by the minimum-total-distance
    matching of the starts and landmarks :func:`spread_starts` draws
    (:func:`avblocks.tasks.assign_landmarks`), as one-waypoint lists for
    ``controllers.HolonomicPointToPoint``. A scenario-file generator, for
    at most :data:`MAX_MATCHED` agents (the matching's time grows as N^3)."""
    n, seed = _checked(agents, seed)
    if n > MAX_MATCHED:
        raise ParameterError("spread_targets: the minimum-distance matching takes O(N^3) "
                             "time", param="agents", expected=f"<= {MAX_MATCHED:,} agents",
                             found=f"{n:,}", hint="About 1 s at 2,000 agents, 4.5 s at 4,000")
    p0, lm = _starts(n, float(half), seed)
    return assign_landmarks(p0, lm)[:, None, :]


#: this case study's scenario-file generators
GENERATORS = {"spread_starts": spread_starts, "spread_targets": spread_targets}


def make_diagram(agents=3, half=1.0, speed=1.0, radius=0.1, cover=0.1, controller="scripted",
                 seed=1, t_final=5.0, dt=0.1):
    """The spread diagram and its simulation settings (module docstring)."""
    n = int(agents)
    p0, lm = _starts(n, float(half), seed)
    d = Diagram("spread")
    fleet = d.add(SingleIntegrator(p0, v_max=float(speed) * np.sqrt(2)), name="fleet")
    marks = d.add(Constant(lm), name="landmarks")
    task = d.add(SpreadTask(n, radius=float(radius), cover=float(cover)), name="task")
    d.connect(fleet.position, task.position)
    d.connect(marks.y, task.landmarks)
    if controller == "scripted":
        from avblocks.controllers import HolonomicPointToPoint
        drive = d.add(HolonomicPointToPoint(assign_landmarks(p0, lm)[:, None, :], gain=2.0,
                                            v_max=float(speed), radius=0.01), name="drive")
        d.connect(fleet.position, drive.position)
        d.connect(drive.velocity, fleet.velocity)
    else:
        src, port = command_source(d, controller, n, task.obs)
        drive_at_speed(d, getattr(src, port), fleet.velocity, speed)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4", "seed": int(seed),
           "log": [fleet.position, task.reward, task.success, marks.y]}
    return d, sim


def rl_task(agents=3, half=1.0, speed=1.0, radius=0.1, cover=0.1):
    """The learning task (module docstring): settings for :class:`avblocks.rl.Task`."""
    n, h = int(agents), float(half)
    d, sim = make_diagram(agents=n, half=h, speed=speed, radius=radius, cover=cover,
                          controller="action")

    def reset(key, xp):
        from avblocks.core import rng
        k1, k2 = rng.split(key, xp, 2)
        return {"fleet.position": uniform_points(k1, n, h, xp, min_sep=4 * radius),
                "landmarks.value": uniform_points(k2, n, h, xp)}

    return {"diagram": d, "act": "action", "observe": "task.obs", "reward": "task.reward",
            "done": "task.done", "reset": reset, "info": {"success": "task.success"},
            "dt": sim["dt"], "substeps": 1, "max_steps": 50, "solver": "euler"}


def outcome(res, params):
    """Whether (and when) every landmark was covered; the final shared reward."""
    ok = np.asarray(res["task.success"])
    t_ok = float(res.t[np.argmax(ok)]) if ok.any() else None
    r = float(np.asarray(res["task.reward"])[-1, 0])
    n = np.asarray(res["fleet.position"]).shape[1]
    head = (f"all {n} landmarks covered at {t_ok:.3g} s" if t_ok is not None else
            f"landmarks not all covered by {res.t[-1]:.3g} s")
    return f"{head}, final reward {r:.3f}", {"covered_s": t_ok, "final_reward": r,
                                              "success": bool(ok[-1])}


def figures(res, out, params):
    """spread.png: paths to the landmarks."""
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import save_figure
    p = np.asarray(res["fleet.position"])
    lm = np.asarray(res["landmarks.y"])[0]
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    for i in range(p.shape[1]):
        ax.plot(p[:, i, 0], p[:, i, 1], lw=1.5)
        ax.plot(p[0, i, 0], p[0, i, 1], "o", color="0.4", ms=4)
    ax.plot(lm[:, 0], lm[:, 1], "kx", ms=9, mew=2, label="landmarks")
    h = float(params.get("half", 1.0))
    ax.set_xlim(-h * 1.1, h * 1.1)
    ax.set_ylim(-h * 1.1, h * 1.1)
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_title(f"spread: {p.shape[1]} agents cover {p.shape[1]} landmarks")
    return [save_figure(fig, f"{out}/spread.png")]
