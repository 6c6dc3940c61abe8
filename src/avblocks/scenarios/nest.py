"""Information propagation in a crowded nest (AVLib paper, case study IV.B):
a few informed scouts enter a hexagonal nest where ~500 agents random-walk,
and the information spreads by contact (gossip within the comm range) until
everyone knows. Logs ``bees.pose`` and ``gossip.informed``.

Set-up
------
``agents`` unicycles (``vehicles.Unicycle``) are placed uniformly at random
in a regular hexagon whose size keeps the density at ``density`` agents per
m^2 (500 agents: about 32 m across). Each runs a ``controllers.RandomWalk``
(exponential switching intervals, speeds in ``speed``) reflected at the
hexagon's edges. The first ``scouts`` agents start informed, near the
entrance on the hexagon's left side (``blocks.Constant`` seeds the
``flag`` input of ``environment.Gossip``). At every step every informed
agent informs every agent within ``comm_range`` (``p_loss`` drops contacts).

What to look at: the informed count ``res["gossip.informed"].sum(axis=1)``
(non-decreasing; everyone by 94.8 s at the defaults), and the wave of
informed agents in the movie. The run compiles (``avblocks run nest
--backend jax``) and gives the same outcome: the random walks and the
gossip draw from the same counter-based stream in both engines. To colour
the agents by the informed flag::

    from avblocks.viz import save_movie
    save_movie(res, "nest.mp4", color="gossip.informed", every=2)

(:data:`MOVIE` holds these options for ``avblocks run nest --movie``.)

Consistency: with ``p_loss = 0`` the logged ``informed[k + 1]`` equals one
gossip round (``environment.gossip_step``) on ``informed[k]`` at the logged
poses ``pose[k]`` (``log_every = 1``).
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import Constant
from avblocks.controllers import RandomWalk
from avblocks.core.diagram import Diagram
from avblocks.environment import Gossip
from avblocks.vehicles import Unicycle

#: Options for ``viz.save_movie`` (``avblocks run nest --movie nest.mp4``).
MOVIE = {"color": "gossip.informed", "every": 2}


def hexagon(radius, center=(0.0, 0.0)):
    """Vertices (6, 2) of a regular hexagon (flat sides top and bottom)."""
    a = np.arange(6) * np.pi / 3
    return np.column_stack([center[0] + radius * np.cos(a),
                            center[1] + radius * np.sin(a)])


def hexagon_radius(agents, density):
    """Circumradius of the hexagon holding ``agents`` at ``density`` per m^2."""
    area = agents / float(density)
    return float(np.sqrt(2.0 * area / (3.0 * np.sqrt(3.0))))


def _in_hexagon(p, radius):
    x, y = np.abs(p[:, 0]), np.abs(p[:, 1])
    h = radius * np.sqrt(3.0) / 2.0
    return (y <= h) & (np.sqrt(3.0) * x + y <= np.sqrt(3.0) * radius)


def nest_poses(agents, radius, scouts, seed, margin=0.3):
    """Initial poses: uniform in the hexagon (shrunk by ``margin``); the first
    ``scouts`` agents near the left corner (the entrance)."""
    rng = np.random.default_rng([int(seed), 11])
    r_in = radius - margin
    pts = np.zeros((0, 2))
    while len(pts) < agents:
        c = rng.uniform(-r_in, r_in, (2 * agents, 2))
        pts = np.vstack([pts, c[_in_hexagon(c, r_in)]])
    pts = pts[:agents]
    k = min(int(scouts), agents)
    if k:
        pts[:k] = np.column_stack([-r_in + rng.uniform(0.2, 1.5, k),
                                   rng.uniform(-1.0, 1.0, k)])
    theta = rng.uniform(-np.pi, np.pi, agents)
    return np.column_stack([pts, theta])


def make_diagram(agents=500, scouts=5, comm_range=1.0, density=0.5, speed=(0.3, 0.6),
                 mean_interval=2.0, p_loss=0.0, seed=1, t_final=100.0, dt=0.05,
                 log_every=1, comm_capacity=None):
    """The nest diagram and its simulation settings (see the module docstring).

    ``comm_capacity``: candidates per bee of the gossip's neighbour search in
    a compiled run (``--backend jax``); None (default): the compiled engine
    plans it from the first positions and re-plans on overflow; the NumPy
    engine sizes itself.
    """
    n = int(agents)
    radius = hexagon_radius(n, density)
    poly = hexagon(radius)
    d = Diagram("nest")
    bees = d.add(Unicycle(pose0=nest_poses(n, radius, scouts, seed)), name="bees")
    walk = d.add(RandomWalk(n, interval=("exponential", float(mean_interval)),
                            speed=tuple(float(v) for v in speed), gain=3.0,
                            polygon=poly, boundary="reflect", margin=0.2), name="walk")
    seeds = np.zeros(n, dtype=bool)
    seeds[:min(int(scouts), n)] = True
    flag = d.add(Constant(seeds), name="scouts")
    gossip = d.add(Gossip(n, radius=float(comm_range), p_loss=float(p_loss),
                          capacity=_capacity(comm_capacity)),
                   name="gossip")
    d.connect(bees.pose, walk.pose)
    d.connect(walk.cmd, bees.cmd)
    d.connect(bees.pose, gossip.pose)
    d.connect(flag.y, gossip.flag)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
           "log": [bees.pose, gossip.informed], "log_every": int(log_every),
           "seed": int(seed)}
    return d, sim


def outcome(res, params):
    """"all 500 informed at 94.8 s" (or how many by the end)."""
    from avblocks.scenarios.report import first_time_all
    inf = np.asarray(res["gossip.informed"])
    n = inf.shape[1]
    t_all = first_time_all(res.t, inf)
    count = inf.sum(axis=1)
    t_half = float(res.t[int(np.argmax(count >= n / 2))]) if (count >= n / 2).any() else None
    nums = {"agents": n, "scouts": int(count[0]), "all_informed_at_s": t_all,
            "half_informed_at_s": t_half, "informed_at_end": int(count[-1])}
    if t_all is not None:
        return f"all {n} informed at {t_all:.3g} s (half at {t_half:.3g} s)", nums
    return f"{int(count[-1])} of {n} informed by t = {res.t[-1]:.3g} s", nums


def figures(res, out, params):
    """nest.png: the nest when half the agents know, and the informed count."""
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import plot_fraction, save_figure
    from avblocks.viz import plot_frame
    inf = np.asarray(res["gossip.informed"])
    n = inf.shape[1]
    count = inf.sum(axis=1)
    k = int(np.argmax(count >= n / 2)) if (count >= n / 2).any() else len(res.t) - 1
    fig, (a, b) = plt.subplots(1, 2, figsize=(11.0, 5.0),
                               gridspec_kw={"width_ratios": [1, 1.15]})
    plot_frame(res, t=res.t[k], pose="bees.pose", ax=a, color="gossip.informed", size=0.8,
               title=f"the nest at t = {res.t[k]:.3g} s: informed (red), not yet (grey)")
    r = hexagon_radius(n, float(params["density"]))
    h = np.vstack([hexagon(r), hexagon(r)[:1]])
    a.plot(h[:, 0], h[:, 1], color="0.3", lw=1.0)
    a.set_xlim(-1.1 * r, 1.1 * r)
    a.set_ylim(-1.1 * r, 1.1 * r)
    plot_fraction(res, "gossip.informed", ax=b, label="informed",
                  title=f"{n} random walkers, {int(count[0])} scouts, "
                        f"contact range {float(params['comm_range']):g} m")
    return [save_figure(fig, f"{out}/nest.png")]


# ------------------------------------------------- generators for scenario files
# (the YAML twin names this case study's geometry: see avblocks.scenarios.generators)
def _nest_hexagon(agents, density):
    return hexagon(hexagon_radius(int(agents), float(density)))


def _nest_poses(agents, density, scouts, seed):
    return nest_poses(int(agents), hexagon_radius(int(agents), float(density)), scouts, seed)


#: the generators this case study offers to scenario files
GENERATORS = {
    "nest_hexagon": _nest_hexagon,
    "nest_poses": _nest_poses,
}


def _capacity(value):
    """``comm_capacity``: None (the compiled engine plans the search) or an int."""
    return None if value is None else int(value)
