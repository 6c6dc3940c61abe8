"""Pursuit (a learning task): N pursuers catch a slower evader.

Set-up
------
``agents`` pursuers and one evader, all single integrators
(``vehicles.SingleIntegrator``) in the square arena ``[-half, half]^2``.
The evader (speed ``evader_speed`` < ``speed``) runs a scripted flee law
(``tasks.Flee``): away from the pursuers
weighted by inverse squared distance, pushed back from the walls within
``0.3 half``. Capture: a pursuer within ``capture`` of the evader.

Task (what :func:`avblocks.rl.parallel_env` ``("pursuit")`` exposes)
---------------------------------------------------------------------
- **action** (per pursuer, 2): velocity command in ``[-1, 1]^2`` times
  ``speed`` [m/s].
- **observation** (per pursuer, ``4 + 2(N-1)``): own position divided by
  ``half``, the evader relative to it, the other pursuers relative to it
  (``task.obs``, a ``tasks.PursuitTask``).
- **reward** (per pursuer, shared): ``-0.1 min_i |p_i - e|`` per step and
  ``+10`` at capture (``task.reward``).
- **done**: capture (every pursuer's flag; the episode then terminates),
  else truncation after ``max_steps`` control steps (default 80 of 0.1 s).
- **success**: the evader was captured (``task.success``).

Starts are drawn anew at every reset: pursuers on a ring of radius
``0.9 half``, the evader near the centre. ``avblocks run pursuit`` runs the
scripted pursuers: pure pursuit (each heads straight at the evader,
``tasks.Chase``).

The scenario file ``pursuit.yaml`` is this module's twin (the same blocks,
the starts from the :func:`pursuit_starts` generator): it is what
``avblocks run pursuit`` runs, to the same numbers; ``--set
controller=policy.npz`` runs a trained policy in both (a
``tasks.TaskCommand`` in the file). :func:`make_diagram` and
:func:`rl_task` remain the Python API (the learning environments).
"""

from __future__ import annotations

import numpy as np

from avblocks.core.diagram import Diagram
from avblocks.scenarios._task import command_source, drive_at_speed
from avblocks.tasks import Chase, Flee, PursuitTask
from avblocks.vehicles import SingleIntegrator

MOVIE = {"pose": "pursuers.position", "trail": 3.0}


def ring_starts(key, n, half, xp):
    """Pursuers on a ring of radius 0.9 half at random angles, the evader in
    the central square of side 0.6 half (both engines)."""
    from avblocks.core import rng
    k1, k2 = rng.split(key, xp, 2)
    a = rng.uniform(k1, (n,), xp, -np.pi, np.pi)
    p = 0.9 * half * xp.stack([xp.cos(a), xp.sin(a)], axis=-1)
    return p, rng.uniform(k2, (1, 2), xp, -0.3 * half, 0.3 * half)


def _starts(n, half, seed):
    from avblocks.core import rng
    return ring_starts(rng.key(int(seed), "pursuit"), n, half, np)


def pursuit_starts(agents, half, seed, which="pursuers"):
    """The starts of :func:`make_diagram` for a seed: the pursuers' (N, 2)
    positions on the ring (``which: pursuers``) or the evader's (1, 2)
    (``which: evader``). A scenario-file generator
    (``{pursuit_starts: {agents: $agents, half: $half, seed: $seed}}``)."""
    from avblocks.core.params import count, integer
    n = count(agents, None, "agents", lo=1)
    if which not in ("pursuers", "evader"):
        raise ValueError(f"which must be 'pursuers' or 'evader', got {which!r:.40}")
    p, e = _starts(n, float(half), integer(seed, None, "seed"))
    return p if which == "pursuers" else e


#: this case study's scenario-file generators
GENERATORS = {"pursuit_starts": pursuit_starts}


def make_diagram(agents=3, half=1.5, speed=1.0, evader_speed=0.7, capture=0.15,
                 controller="scripted", seed=1, t_final=8.0, dt=0.1):
    """The pursuit diagram and its simulation settings (module docstring)."""
    n, h = int(agents), float(half)
    p0, e0 = _starts(n, h, seed)
    d = Diagram("pursuit")
    purs = d.add(SingleIntegrator(p0, v_max=float(speed) * np.sqrt(2)), name="pursuers")
    ev = d.add(SingleIntegrator(e0, v_max=float(evader_speed)), name="evader")
    flee = d.add(Flee(n, half=h, speed=float(evader_speed)), name="flee")
    task = d.add(PursuitTask(n, half=h, capture=float(capture)), name="task")
    d.connect(purs.position, flee.pursuers)
    d.connect(ev.position, flee.evader)
    d.connect(flee.velocity, ev.velocity)
    d.connect(purs.position, task.pursuers)
    d.connect(ev.position, task.evader)
    if controller == "scripted":
        src = d.add(Chase(n), name="chase")
        d.connect(purs.position, src.pursuers)
        d.connect(ev.position, src.evader)
        cmd = src.cmd
    else:
        src, port = command_source(d, controller, n, task.obs)
        cmd = getattr(src, port)
    drive_at_speed(d, cmd, purs.velocity, speed)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4", "seed": int(seed),
           "log": [purs.position, ev.position, task.distance, task.success]}
    return d, sim


def rl_task(agents=3, half=1.5, speed=1.0, evader_speed=0.7, capture=0.15):
    """The learning task (module docstring): settings for :class:`avblocks.rl.Task`."""
    n, h = int(agents), float(half)
    d, sim = make_diagram(agents=n, half=h, speed=speed, evader_speed=evader_speed,
                          capture=capture, controller="action")

    def reset(key, xp):
        p, e = ring_starts(key, n, h, xp)
        return {"pursuers.position": p, "evader.position": e}

    return {"diagram": d, "act": "action", "observe": "task.obs", "reward": "task.reward",
            "done": "task.done", "reset": reset, "info": {"success": "task.success"},
            "dt": sim["dt"], "substeps": 1, "max_steps": 80}


def outcome(res, params):
    """Capture time (first time a pursuer is within ``capture``)."""
    dist = np.asarray(res["task.distance"])
    cap = float(params.get("capture", 0.15))
    hit = dist < cap
    t_cap = float(res.t[np.argmax(hit)]) if hit.any() else None
    n = np.asarray(res["pursuers.position"]).shape[1]
    head = (f"{n} pursuers caught the evader at {t_cap:.3g} s" if t_cap is not None else
            f"no capture by {res.t[-1]:.3g} s (closest {dist.min():.3f} m)")
    return head, {"capture_s": t_cap, "closest_m": float(dist.min())}


def figures(res, out, params):
    """pursuit.png: pursuers' and evader's paths."""
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import save_figure
    p = np.asarray(res["pursuers.position"])
    e = np.asarray(res["evader.position"])[:, 0]
    hit = np.asarray(res["task.distance"]) < float(params.get("capture", 0.15))
    k = int(np.argmax(hit)) + 1 if hit.any() else len(res.t)
    h = float(params.get("half", 1.5))
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    for i in range(p.shape[1]):
        ax.plot(p[:k, i, 0], p[:k, i, 1], lw=1.5, label="pursuer" if i == 0 else None)
    ax.plot(e[:k, 0], e[:k, 1], "k--", lw=1.5, label="evader")
    ax.plot(*e[k - 1], "r*", ms=12)
    ax.set_xlim(-h * 1.05, h * 1.05)
    ax.set_ylim(-h * 1.05, h * 1.05)
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_title(outcome(res, params)[0], fontsize=9)
    return [save_figure(fig, f"{out}/pursuit.png")]
