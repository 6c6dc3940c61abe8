"""Honeybee search and alarm (AVLib paper, case study IV.B, both halves): a
dozen scouts random-walk a bounded search area looking for a hazardous
source; a scout that senses it flies back to the nest entrance, enters, and
the alarm spreads through the ~500 bees of the nest by contact.

Set-up
------
One ``vehicles.Unicycle`` block holds everyone: agents ``0..scouts-1`` are
the scouts, the others the nest bees (placed as in :mod:`nest`: uniformly in
a regular hexagon at ``density`` bees per m^2, entrance at its left
corner). ``blocks.Select`` splits the poses.

Scouts: ``controllers.AgentModes`` gives each scout a mode,

- ``search``: ``controllers.RandomWalk`` reflected inside the rectangle
  :func:`search_area` (left of the nest); ``search -> return`` when
  ``environment.TargetDetection`` senses the source within
  ``sensing_radius``;
- ``return``: ``controllers.PointToPoint`` to the entrance (just inside the
  nest's left corner); ``return -> nest`` within ``entry_radius`` of it;
- ``nest``: a second ``RandomWalk`` reflected inside the hexagon; a scout in
  this mode seeds the alarm (the ``flag`` input of ``environment.Gossip``).

Nest bees random-walk in the hexagon (as in :mod:`nest`); ``Gossip`` over
all agents spreads the alarm to every agent within ``comm_range`` of an
informed one at every step. A ``blocks.Function`` running
:func:`choose_command` picks each scout's command by its mode and joins the
nest's commands.

The scenario file ``honeybee.yaml`` is this module's twin (the same blocks,
its guards as data, ``choose_command`` named by import path): it is what
``avblocks run honeybee`` runs, to the same numbers.

Logged: ``bees.pose`` (everyone), ``modes.mode`` (scouts: 0 search,
1 return, 2 nest), ``detect.detected`` and ``gossip.informed``.

Outcome (defaults, seed 1): the source is found at 111 s, the first finder
is back in the nest at 140 s and all 500 nest bees know at 237 s (about
20 s of wall time on a 2-core machine). The run compiles (``avblocks run
honeybee --backend jax``) with the same outcome.
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import Function, Select
from avblocks.controllers import AgentModes, PointToPoint, RandomWalk
from avblocks.core.diagram import Diagram
from avblocks.core.ports import Port
from avblocks.environment import Gossip, TargetDetection
from avblocks.scenarios.nest import hexagon, hexagon_radius, nest_poses
from avblocks.vehicles import Unicycle

MODES = ("search", "return", "nest")


def entrance(radius):
    """The nest entrance: just inside the hexagon's left corner."""
    return np.array([-radius + 1.0, 0.0])


def search_area(radius, size=(50.0, 60.0), gap=4.0):
    """(xmin, ymin, xmax, ymax) of the search area, left of the nest."""
    x1 = -radius - gap
    return (x1 - size[0], -size[1] / 2, x1, size[1] / 2)


def scout_poses(scouts, radius, seed):
    """Scouts start just outside the entrance, heading out (left)."""
    rng = np.random.default_rng([int(seed), 13])
    x = -radius - 6.0 - rng.uniform(0.0, 2.0, scouts)
    y = rng.uniform(-2.0, 2.0, scouts)
    return np.column_stack([x, y, np.pi + rng.uniform(-0.5, 0.5, scouts)])


def choose_command(t, mode, search, home, inside, walk, xp):
    """The ``choose`` block's function: each scout's command by its mode
    (0 ``search``, 1 ``return``, 2 ``nest``), followed by the nest bees'
    ``walk`` commands; ``flag`` marks the scouts in the nest (they seed the
    alarm)."""
    m_ = mode[:, None]
    cmd = xp.where(m_ == 0, search, xp.where(m_ == 1, home, inside))
    flag = xp.concatenate([mode == 2, xp.zeros(walk.shape[0], dtype=bool)])
    return {"cmd": xp.concatenate([cmd, walk], axis=0), "flag": flag}


def hazard_outline(source=(-55.0, 18.0), radius=3.0):
    """A 24-point circle around the source (the movie draws it)."""
    a = np.linspace(0, 6.2, 24)
    s = np.asarray(source, float)
    return np.column_stack([s[0] + radius * np.cos(a), s[1] + radius * np.sin(a)])


def make_diagram(agents=500, scouts=12, source=(-55.0, 18.0), sensing_radius=3.0,
                 entry_radius=1.0, comm_range=1.0, density=0.5, speed=(0.3, 0.6),
                 scout_speed=(1.0, 1.5), mean_interval=2.0, p_loss=0.0, seed=1,
                 t_final=250.0, dt=0.1, log_every=5, comm_capacity=None):
    """The honeybee diagram and its simulation settings (see the module
    docstring). ``comm_capacity``: candidates per bee of the gossip's
    neighbour search in a compiled run (None: planned by the compiled
    engine; the NumPy engine sizes itself)."""
    n, m = int(agents), int(scouts)
    radius = hexagon_radius(n, density)
    poly = hexagon(radius)
    gate = entrance(radius)
    area = search_area(radius)
    pose0 = np.vstack([scout_poses(m, radius, seed), nest_poses(n, radius, 0, seed)])

    d = Diagram("honeybee")
    bees = d.add(Unicycle(pose0=pose0), name="bees")
    sp = d.add(Select(np.arange(m)), name="scout_pose")
    npose = d.add(Select(np.arange(m, m + n)), name="nest_pose")
    search = d.add(RandomWalk(m, interval=("exponential", float(mean_interval)),
                              speed=tuple(float(v) for v in scout_speed), gain=3.0,
                              bounds=area, boundary="reflect", margin=1.0), name="search")
    home = d.add(PointToPoint(gate[None, :], n=m, d=0.2, gain=1.0,
                              v_max=float(scout_speed[1]), radius=0.2), name="home")
    inside = d.add(RandomWalk(m, interval=("exponential", float(mean_interval)),
                              speed=tuple(float(v) for v in speed), gain=3.0,
                              polygon=poly, boundary="reflect", margin=0.2), name="inside")
    walk = d.add(RandomWalk(n, interval=("exponential", float(mean_interval)),
                            speed=tuple(float(v) for v in speed), gain=3.0,
                            polygon=poly, boundary="reflect", margin=0.2), name="walk")
    detect = d.add(TargetDetection(m, np.asarray(source, float)[None, :],
                                   sensing_radius=float(sensing_radius)), name="detect")
    r2 = float(entry_radius) ** 2

    def at_gate(u, xp):
        dx = u["pose"][:, 0] - gate[0]
        dy = u["pose"][:, 1] - gate[1]
        return dx * dx + dy * dy <= r2

    modes = d.add(AgentModes(m, list(MODES),
                             [("search", "return", lambda u, xp: u["detected"]),
                              ("return", "nest", at_gate)],
                             initial="search", inputs={"detected": (m,), "pose": (m, 3)}),
                  name="modes")

    brain = d.add(Function(choose_command, inputs={"mode": Port("mode", (m,), "int64"),
                                           "search": (m, 2), "home": (m, 2),
                                           "inside": (m, 2), "walk": (n, 2)},
                           outputs={"cmd": (m + n, 2), "flag": Port("flag", (m + n,), "bool")}),
                  name="choose")
    gossip = d.add(Gossip(m + n, radius=float(comm_range), p_loss=float(p_loss),
                          capacity=_capacity(comm_capacity)),
                   name="gossip")
    d.connect(bees.pose, sp.u)
    d.connect(bees.pose, npose.u)
    for blk in (search, home, inside, detect):
        d.connect(sp.y, blk.pose)
    d.connect(npose.y, walk.pose)
    d.connect(sp.y, modes.pose)
    d.connect(detect.detected, modes.detected)
    d.connect(modes.mode, brain.mode)
    d.connect(search.cmd, brain.search)
    d.connect(home.cmd, brain.home)
    d.connect(inside.cmd, brain.inside)
    d.connect(walk.cmd, brain.walk)
    d.connect(brain.cmd, bees.cmd)
    d.connect(bees.pose, gossip.pose)
    d.connect(brain.flag, gossip.flag)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
           "log": [bees.pose, modes.mode, detect.detected, gossip.informed],
           "log_every": int(log_every), "seed": int(seed)}
    return d, sim


def timeline(res, scouts):
    """Times of the first detection, the first scout back in the nest, and
    the whole nest informed (None where it did not happen), and the
    informed fraction of the nest over time."""
    from avblocks.scenarios.report import first_time_all
    mode = np.asarray(res["modes.mode"])
    inf = np.asarray(res["gossip.informed"])[:, int(scouts):]

    def first(mask):
        return float(res.t[int(np.argmax(mask))]) if mask.any() else None

    return {"detected_s": first((mode >= 1).any(axis=1)),
            "returned_s": first((mode == 2).any(axis=1)),
            "all_informed_s": first_time_all(res.t, inf),
            "fraction": inf.mean(axis=1)}


def outcome(res, params):
    """"source found at 150 s, scout back at 200 s, all 500 informed at 280 s"."""
    m = int(params["scouts"])
    tl = timeline(res, m)
    n = np.asarray(res["gossip.informed"]).shape[1] - m
    nums = {k: v for k, v in tl.items() if k != "fraction"}
    nums["informed_at_end"] = float(tl["fraction"][-1])
    nums["finders"] = int((np.asarray(res["modes.mode"])[-1] >= 1).sum())
    if tl["detected_s"] is None:
        return f"source not found by t = {res.t[-1]:.3g} s", nums
    parts = [f"source found at {tl['detected_s']:.3g} s"]
    parts.append(f"first scout back in the nest at {tl['returned_s']:.3g} s"
                 if tl["returned_s"] is not None else "no scout back yet")
    parts.append(f"all {n} nest bees informed at {tl['all_informed_s']:.3g} s"
                 if tl["all_informed_s"] is not None else
                 f"{100 * tl['fraction'][-1]:.0f} % of the nest informed by "
                 f"{res.t[-1]:.3g} s")
    return ", ".join(parts), nums


def figures(res, out, params):
    """honeybee.png: the scouts' search paths, the source and the nest; and
    the informed fraction of the nest over time with the three events."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    from avblocks.scenarios.report import save_figure
    m = int(params["scouts"])
    pose = np.asarray(res["bees.pose"])
    n = pose.shape[1] - m
    radius = hexagon_radius(n, float(params["density"]))
    area = search_area(radius)
    tl = timeline(res, m)
    fig, (a, b) = plt.subplots(1, 2, figsize=(12.0, 5.2),
                               gridspec_kw={"width_ratios": [1.35, 1]})
    a.add_patch(Rectangle(area[:2], area[2] - area[0], area[3] - area[1], fill=False,
                          ls="--", ec="0.5", label="search area"))
    h = np.vstack([hexagon(radius), hexagon(radius)[:1]])
    a.plot(h[:, 0], h[:, 1], color="0.3", lw=1.0, label="nest")
    inf_end = np.asarray(res["gossip.informed"])[-1, m:]
    a.scatter(pose[-1, m:, 0], pose[-1, m:, 1], s=3,
              c=np.where(inf_end, "tab:red", "0.6"), zorder=2)
    mode = np.asarray(res["modes.mode"])
    cols = plt.get_cmap("tab20")(np.arange(m) % 20)
    for i in range(m):
        found = (mode[:, i] >= 1).any()
        a.plot(pose[:, i, 0], pose[:, i, 1], lw=1.6 if found else 0.6,
               alpha=1.0 if found else 0.5, color=cols[i], zorder=3)
    a.scatter(pose[0, :m, 0], pose[0, :m, 1], s=14, facecolors="white", edgecolors="0.2",
              zorder=4, label="scouts' start")
    src = np.asarray(params["source"], float)
    a.add_patch(Circle(src, float(params["sensing_radius"]), color="tab:orange",
                       alpha=0.3, zorder=1))
    a.scatter(*src, marker="*", s=160, color="tab:orange", ec="k", zorder=5,
              label="hazard (sensing radius)")
    a.set_aspect("equal")
    a.set_xlabel("x [m]")
    a.set_ylabel("y [m]")
    a.legend(loc="lower left", fontsize=7)
    a.set_title(f"{m} scouts search; finders (thick) fly home")
    b.plot(res.t, 100 * tl["fraction"], color="tab:red", lw=1.5)
    for key, label, y in (("detected_s", "source found", 85), ("returned_s", "scout home", 60),
                          ("all_informed_s", "all informed", 35)):
        if tl[key] is not None:
            b.axvline(tl[key], color="0.3", ls=":", lw=1.0)
            b.annotate(f"{label}\n{tl[key]:.0f} s", (tl[key], y), xytext=(-3, 0),
                       textcoords="offset points", ha="right", fontsize=8,
                       bbox=dict(fc="white", ec="none", alpha=0.8))
    b.set_ylim(-2, 102)
    b.set_xlabel("t [s]")
    b.set_ylabel("nest bees informed [%]")
    b.set_title(f"the alarm in a nest of {n}")
    b.grid(True, alpha=0.3)
    return [save_figure(fig, f"{out}/honeybee.png")]


def _capacity(value):
    """``comm_capacity``: None (the compiled engine plans the search) or an int."""
    return None if value is None else int(value)


def _radius(agents, density):
    return hexagon_radius(int(agents), float(density))


def _honeybee_poses(agents, scouts, density, seed):
    r = _radius(agents, density)
    return np.vstack([scout_poses(int(scouts), r, seed),
                      nest_poses(int(agents), r, 0, seed)])


def _honeybee_area(agents, density):
    return [float(v) for v in search_area(_radius(agents, density))]


def _honeybee_entrance(agents, density):
    return entrance(_radius(agents, density))[None, :]


def _hazard(source, radius=3.0):
    return hazard_outline(source, float(radius))


#: Generators of honeybee.yaml (the scenario file twin of this module): the
#: scouts' and bees' start poses, the search rectangle, the entrance
#: (as a 1 x 2 waypoint list) and the hazard's outline for the movie.
GENERATORS = {
    "honeybee_poses": _honeybee_poses,
    "honeybee_area": _honeybee_area,
    "honeybee_entrance": _honeybee_entrance,
    "hazard_outline": _hazard,
}

#: Options for ``viz.save_movie`` (``avblocks run honeybee --movie hb.gif``).
MOVIE = {"pose": "bees.pose", "color": "gossip.informed", "size": 1.2,
         "title": "honeybee search and alarm: informed in red",
         "obstacles": [hazard_outline()]}
