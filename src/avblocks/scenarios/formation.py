"""Formation switching through a corridor (AVLib paper, case study IV.D): a
leader drives through waypoints, followers keep a wedge by leader
following, and a supervisor switches the formation to a column before a
corridor between two walls and back to the wedge after it.

Set-up
------
``followers + 1`` unicycles. Agent 0, the leader, runs
``controllers.PointToPoint`` through :data:`WAYPOINTS` (only its row of the
command is used); the others run ``controllers.LeaderFollower`` with
``references_input=True`` on the leader tree of the wedge (each follower
tracks the nearest agent ahead of it). A ``controllers.Supervisor`` with
states ``wedge`` and ``column`` watches the leader's x position:

- ``wedge -> column`` when ``X_SWITCH_IN <= x_leader < CORRIDOR[1]``
  (the column forms before the corridor entrance at ``CORRIDOR[0]``);
- ``column -> wedge`` when ``x_leader >= X_SWITCH_OUT`` (the whole column
  has left the corridor);

and outputs ``ref`` (N, 2), the precomputed ``(l_ref, alpha_ref)`` of the
current formation (``controllers.references`` of each shape on the same
leader tree), wired to the followers' ``ref`` input. The corridor's walls
are two ``environment.World`` rectangles (:data:`WORLD`);
``environment.Collision`` (disc footprints of radius ``body_radius``)
reports ``hit_obstacle`` and ``hit_agent``.

Logged: ``fleet.pose``, ``lf.error`` ((l, alpha) errors, 0 for the leader),
``supervisor.mode`` (0 wedge, 1 column), ``collision.hit_obstacle``,
``collision.hit_agent``. A movie with the walls drawn:
``save_movie(res, "formation.mp4", obstacles=WORLD.geoms, trail=8.0)``
(:data:`MOVIE`).
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import RateLimiter
from avblocks.controllers import (
    LeaderFollower,
    PointToPoint,
    Supervisor,
    formation_offsets,
    leader_tree,
    references,
)
from avblocks.core.diagram import Diagram
from avblocks.environment import Collision, Disc, World, rectangle
from avblocks.vehicles import Unicycle

#: Corridor: x from CORRIDOR[0] to CORRIDOR[1], free width CORRIDOR[2] around y = 0.
CORRIDOR = (24.0, 32.0, 2.0)
#: Leader waypoints (x, y).
WAYPOINTS = np.array([[12.0, 0.0], [42.0, 0.0], [48.0, 1.0], [53.0, 3.0], [58.0, 6.0]])


def corridor_world(x0=CORRIDOR[0], x1=CORRIDOR[1], width=CORRIDOR[2], wall=4.0):
    """Two walls ``wall`` thick from x0 to x1, ``width`` apart around y = 0."""
    return World([rectangle(x0, width / 2, x1, width / 2 + wall),
                  rectangle(x0, -width / 2 - wall, x1, -width / 2)])


#: The two walls of the corridor.
WORLD = corridor_world()
#: Options for ``viz.save_movie`` (``avblocks run formation --movie f.mp4``).
MOVIE = {"obstacles": WORLD.geoms, "trail": 8.0}
STATES = ("wedge", "column")


def formation_references(n, spacing, d, tree="star"):
    """``leader`` (N,) and the references ``{state: (N, 2)}`` of both shapes
    on the wedge's leader tree."""
    leader = leader_tree(formation_offsets("wedge", n, spacing), tree)
    refs = {s: np.column_stack(references(formation_offsets(s, n, spacing), leader, d))
            for s in STATES}
    return leader, refs


def switch_points(n, spacing, lead_in=10.0, margin=2.0):
    """Leader x positions where the supervisor switches in and out."""
    x_in = CORRIDOR[0] - lead_in
    x_out = CORRIDOR[1] + (n - 1) * spacing + margin
    return x_in, x_out


def start_poses(n, spacing, offset, seed):
    """The wedge's slots, followers perturbed by up to ``offset`` (and
    +-0.3 rad); the leader at the origin heading along x."""
    rng = np.random.default_rng([int(seed), 5])
    start = formation_offsets("wedge", int(n), float(spacing)) + rng.uniform(
        -float(offset), float(offset), (int(n), 2))
    start[0] = 0.0
    pose0 = np.column_stack([start, rng.uniform(-0.3, 0.3, int(n))])
    pose0[0, 2] = 0.0
    return pose0


def make_diagram(followers=4, spacing=1.5, speed=0.6, gain=1.5, d=0.2, body_radius=0.25,
                 ref_rate=(0.3, 0.15), offset=0.6, seed=1, t_final=100.0, dt=0.02,
                 log_every=5, tree="star", agents=None):
    """The formation-switching diagram and its simulation settings
    (``agents``, when given, is ``followers + 1``: the name every scenario
    shares)."""
    n = int(followers) + 1 if agents is None else int(agents)
    if n < 2:
        from avblocks.core.errors import ParameterError
        raise ParameterError("a formation needs a leader and a follower", param="agents",
                             expected=">= 2", found=n)
    spacing = float(spacing)
    leader, refs = formation_references(n, spacing, float(d), tree)
    x_in, x_out = switch_points(n, spacing)
    pose0 = start_poses(n, spacing, offset, seed)

    dg = Diagram("formation")
    fleet = dg.add(Unicycle(pose0=pose0), name="fleet")
    drive = dg.add(PointToPoint(WAYPOINTS, n=n, d=float(d), gain=1.0, v_max=float(speed),
                                radius=0.3), name="drive")
    lf = dg.add(LeaderFollower(leader, d=float(d), k_l=float(gain), k_alpha=float(gain),
                               references_input=True), name="lf")
    sup = dg.add(Supervisor(
        list(STATES),
        [("wedge", "column",
          lambda u, xp: (u["pose"][0, 0] >= x_in) & (u["pose"][0, 0] < x_out)),
         ("column", "wedge", lambda u, xp: u["pose"][0, 0] >= x_out)],
        initial="wedge", inputs={"pose": (n, 3)}, outputs={"ref": refs}),
        name="supervisor")
    col = dg.add(Collision(WORLD, n, footprint=Disc(float(body_radius)), period=float(dt)),
                 name="collision")
    dg.connect(fleet.pose, drive.pose)
    dg.connect(fleet.pose, lf.pose)
    dg.connect(drive.cmd, lf.cmd_in)
    dg.connect(lf.cmd, fleet.cmd)
    dg.connect(fleet.pose, sup.pose)
    if ref_rate is not None:
        morph = dg.add(RateLimiter(np.asarray(ref_rate, float), initial=refs["wedge"]),
                       name="morph")
        dg.connect(sup.ref, morph.u)
        dg.connect(morph.y, lf.ref)
    else:
        dg.connect(sup.ref, lf.ref)
    dg.connect(fleet.pose, col.pose)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
           "log": [fleet.pose, lf.error, sup.mode, col.hit_obstacle, col.hit_agent],
           "log_every": int(log_every), "seed": int(seed)}
    return dg, sim


def _switches(res):
    mode = np.asarray(res["supervisor.mode"]).reshape(len(res.t))
    return mode, np.flatnonzero(np.diff(mode) != 0) + 1


def outcome(res, params):
    """States visited, formation error just before each switch, closest
    approach between agents, contacts with the walls."""
    from avblocks.scenarios.report import min_pairwise_distance
    mode, sw = _switches(res)
    err = np.abs(np.asarray(res["lf.error"]))[..., 0].max(axis=1)     # max |l error|
    seq = [STATES[int(mode[0])]] + [STATES[int(mode[i])] for i in sw]
    before = [float(err[max(i - 2, 0)]) for i in sw] + [float(err[-1])]
    dmin, kmin = min_pairwise_distance(res["fleet.pose"])
    walls = int(np.asarray(res["collision.hit_obstacle"]).any(axis=1).sum())
    agents = int(np.asarray(res["collision.hit_agent"]).any(axis=1).sum())
    nums = {"states": seq, "switch_times_s": [float(res.t[i]) for i in sw],
            "formation_error_before_switch_m": before[:-1],
            "formation_error_end_m": before[-1], "closest_approach_m": dmin,
            "samples_touching_wall": walls, "samples_touching_agent": agents}
    line = (f"{' -> '.join(seq)}; formation error {max(before):.2g} m before each "
            f"switch and at the end, closest approach {dmin:.2f} m, "
            f"{'no contact' if walls + agents == 0 else f'{walls + agents} samples in contact'}")
    return line, nums


def figures(res, out, params):
    """formation.png: the paths through the corridor with the formation at
    three moments, and the formation error over time (log scale)."""
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import save_figure
    from avblocks.viz import plot_trajectories
    mode, sw = _switches(res)
    pose = np.asarray(res["fleet.pose"])
    fig, (a, b) = plt.subplots(2, 1, figsize=(9.0, 7.0),
                               gridspec_kw={"height_ratios": [1.6, 1]})
    plot_trajectories(res, "fleet.pose", ax=a, obstacles=WORLD, waypoints=WAYPOINTS,
                      title="formation: wedge -> column before the corridor -> "
                            "wedge after it")
    marks = [max(sw[0] - 1, 0) // 2] + [(sw[0] + sw[1]) // 2] + [len(res.t) - 1] \
        if len(sw) >= 2 else [len(res.t) - 1]
    for i in marks:
        a.scatter(pose[i, :, 0], pose[i, :, 1], s=14, c="k", zorder=5)
        a.annotate(f"{STATES[int(mode[i])]} (t = {res.t[i]:.0f} s)",
                   (pose[i, :, 0].mean(), pose[i, :, 1].max() + 0.6), ha="center",
                   fontsize=8)
    err = np.abs(np.asarray(res["lf.error"])).max(axis=1)
    b.semilogy(res.t, np.maximum(err[:, 0], 1e-6), label="max |distance error| [m]")
    b.semilogy(res.t, np.maximum(err[:, 1], 1e-6), label="max |bearing error| [rad]")
    for i in sw:
        b.axvline(res.t[i], color="0.4", ls=":")
        b.annotate(f"-> {STATES[int(mode[i])]}", (res.t[i], 0.5), xytext=(3, 0),
                   textcoords="offset points", fontsize=8)
    b.set_ylim(1e-6, 3.0)
    b.set_xlabel("t [s]")
    b.set_ylabel("follower error")
    b.legend(fontsize=8, loc="upper right")
    b.grid(True, alpha=0.3)
    return [save_figure(fig, f"{out}/formation.png")]


# ------------------------------------------------- generators for scenario files
# (the YAML twin names this case study's geometry: see avblocks.scenarios.generators)
def _formation_start(n, spacing, offset, seed):
    return start_poses(int(n), float(spacing), float(offset), seed)


def _formation_refs(n, spacing, d, tree="star", state="wedge"):
    leader, refs = formation_references(int(n), float(spacing), float(d), tree)
    if state == "leader":
        return leader
    if state not in refs:
        raise ValueError(f"state must be one of {sorted(refs)} or 'leader', got {state!r}")
    return refs[state]


def _formation_switch(n, spacing, which="in"):
    x_in, x_out = switch_points(int(n), float(spacing))
    return {"in": x_in, "out": x_out}[which]


def _corridor(x0, x1, width, wall=4.0):
    return corridor_world(float(x0), float(x1), float(width), float(wall))


def _team_size(agents=None, followers=None):
    """``agents`` when given, else ``followers + 1`` (a leader and its
    followers)."""
    if agents is not None:
        return int(agents)
    if followers is None:
        raise ValueError("give agents or followers")
    return int(followers) + 1


#: the generators this case study offers to scenario files
GENERATORS = {
    "team_size": _team_size,
    "formation_start": _formation_start,
    "formation_references": _formation_refs,
    "formation_switch": _formation_switch,
    "corridor": _corridor,
}
