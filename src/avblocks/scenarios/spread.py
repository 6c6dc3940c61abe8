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
  (``task.obs``).
- **reward** (per agent): ``-sum_l min_i |p_i - l|`` (shared: how far the
  landmarks are from being covered), minus ``collision`` for each other
  agent closer than ``2 * radius`` (``task.reward``).
- **done**: never (episodes end after ``max_steps`` control steps).
- **success**: every landmark has an agent within ``cover`` of it
  (``task.success``, per run; the outcome line reports it at the end).

Starts and landmarks are drawn anew at every reset (uniform in the square).
``avblocks run spread`` runs the scripted controller: each agent is assigned
a landmark by a minimum-total-distance matching (Hungarian method) and
drives to it (``controllers.HolonomicPointToPoint``).
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import Constant
from avblocks.core.block import Block
from avblocks.core.diagram import Diagram
from avblocks.vehicles import SingleIntegrator

from ._task import command_source, drive_at_speed, others_index, pairwise, uniform_points

MOVIE = {"pose": "fleet.position", "trail": 2.0}


class SpreadTask(Block):
    """Observation, reward and success of the spread task (module docstring).

    Ports
    -----
    position : in, (N, 2) [m]
    landmarks : in, (N, 2) [m]
    obs : out, (N, 2 + 2N + 2(N-1))
    reward : out, (N,)
    done : out, (N,) bool (always false)
    success : out, () bool: every landmark covered within ``cover``.
    """

    def __init__(self, n, *, radius=0.1, cover=0.1, collision=1.0):
        super().__init__()
        self.n = n
        self.idx = others_index(n)
        self.declare_parameter("radius", radius, bounds=(0, None), unit="m")
        self.declare_parameter("cover", cover, bounds=(0, None), unit="m")
        self.declare_parameter("collision", collision, bounds=(0, None))
        self.declare_input("position", (n, 2), unit="m")
        self.declare_input("landmarks", (n, 2), unit="m")
        self.declare_output("obs", (n, 2 + 2 * n + 2 * (n - 1)))
        self.declare_output("reward", (n,))
        self.declare_output("done", (n,), "bool")
        self.declare_output("success", (), "bool", agents=False)

    def output(self, t, x, u, xp):
        p, lm = u["position"], u["landmarks"]
        n = self.n
        rel_l = lm[None, :, :] - p[:, None, :]                    # (n, L, 2)
        rel_o = p[self.idx] - p[:, None, :]                       # (n, n-1, 2)
        obs = xp.concatenate([p, xp.reshape(rel_l, (n, -1)), xp.reshape(rel_o, (n, -1))],
                             axis=1)
        dl = xp.sqrt(xp.sum(rel_l * rel_l, axis=-1))              # (agent, landmark)
        near = xp.min(dl, axis=0)                                 # per landmark
        hits = xp.sum(pairwise(p, xp) < 2 * self.radius, axis=1)
        reward = -xp.sum(near) - self.collision * hits
        return {"obs": obs, "reward": reward, "done": xp.zeros((n,), dtype=bool),
                "success": xp.all(near < self.cover)}


def _starts(n, half, seed):
    rng = np.random.default_rng([int(seed), 31])
    return rng.uniform(-half, half, (n, 2)), rng.uniform(-half, half, (n, 2))


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
        from scipy.optimize import linear_sum_assignment

        from avblocks.controllers import HolonomicPointToPoint
        cost = np.linalg.norm(p0[:, None, :] - lm[None, :, :], axis=-1)
        _, col = linear_sum_assignment(cost)
        drive = d.add(HolonomicPointToPoint(lm[col][:, None, :], gain=2.0,
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
