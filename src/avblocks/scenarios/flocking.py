"""Olfati-Saber flocking: double integrators start scattered with random
velocities, form an alpha-lattice (neighbours ``d`` apart) and align their
velocities while a gamma term steers the flock after a moving target.

Set-up
------
``agents`` point masses (``vehicles.DoubleIntegrator``) start uniformly in a
square of side ``spread`` (at least ``0.6 d`` apart) with velocities uniform
in ``[-v0, v0]^2``. ``environment.Neighbors`` lists up to ``k`` agents
within the interaction range ``r = 1.2 d`` (once per step);
``controllers.Flocking`` computes Algorithm 1 of Olfati-Saber (2006) plus
the navigational feedback towards a gamma agent moving from ``target`` with
constant velocity ``target_velocity``. A ``blocks.Function`` turns
position and velocity into planar poses (heading along the velocity) and the
order parameter ``|sum_i v_i| / sum_i |v_i|`` (1: aligned).

Logged: ``flock.position``, ``flock.velocity``, ``view.pose`` (for plots
and movies) and ``view.order``. Expect ``order > 0.99`` and nearest
neighbours close to ``d`` at the end (``d = 7 m`` as in the paper).

Reference: R. Olfati-Saber, "Flocking for multi-agent dynamic systems:
algorithms and theory", IEEE TAC 51(3), 2006.
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import Function
from avblocks.controllers import Flocking, order_parameter
from avblocks.core.diagram import Diagram
from avblocks.environment import Neighbors
from avblocks.utility import random_positions
from avblocks.vehicles import DoubleIntegrator

#: Options for ``viz.save_movie`` (``avblocks run flocking --movie f.mp4``).
MOVIE = {"pose": "view.pose", "trail": 5.0}


def pose_and_order(t, position, velocity, xp):
    """Planar poses (heading along the velocity) and the order parameter."""
    heading = xp.arctan2(velocity[:, 1], velocity[:, 0])
    return {"pose": xp.concatenate([position, heading[:, None]], axis=1),
            "order": order_parameter(velocity, xp)}


def initial_conditions(agents=50, d=7.0, spread=50.0, v0=2.0, seed=1):
    """Start positions and velocities ``(p0, vel0)``, each (agents, 2), of seed ``seed``."""
    n = int(agents)
    rng = np.random.default_rng([int(seed), 3])
    p0 = random_positions(n, area=(float(spread), float(spread)),
                          min_separation=0.6 * float(d), seed=int(seed))
    vel0 = rng.uniform(-float(v0), float(v0), (n, 2))
    return p0, vel0


def frozen_adjacency(position, k=12, r=8.4):
    """(N, N) 0/1 adjacency: each agent's ``k`` nearest others within ``r`` of
    ``position`` (made symmetric). The "frozen neighbours" graph of
    ``make_diagram(neighbors="frozen")``."""
    from scipy.spatial import cKDTree
    n = len(position)
    dist, idx = cKDTree(position).query(position, k=min(int(k) + 1, n),
                                        distance_upper_bound=float(r))
    a = np.zeros((n, n))
    for col in range(1, idx.shape[1]):          # column 0 is the agent itself
        ok = np.isfinite(dist[:, col])
        a[np.flatnonzero(ok), idx[ok, col]] = 1.0
    return np.maximum(a, a.T)


def make_diagram(agents=50, d=7.0, spread=50.0, v0=2.0, target=(25.0, 25.0),
                 target_velocity=(2.0, 1.0), k=12, seed=1, t_final=60.0, dt=0.02,
                 log_every=5, neighbors="search", c1=1.0, c2=1.0):
    """The flocking diagram and its simulation settings.

    ``neighbors="search"`` (default) lists up to ``k`` agents within
    ``r = 1.2 d`` every step (``environment.Neighbors``). ``neighbors="frozen"``
    fixes each agent's neighbour set to the one at the start
    (:func:`frozen_adjacency`, a fixed graph of ``controllers.Flocking``; no
    search block): the neighbour sets then cannot switch when a gain or an
    initial velocity is perturbed, which is what a gradient through the run
    (and finite differences that agree with it) assumes. ``c1``, ``c2`` are
    the alpha-lattice gains of ``controllers.Flocking``.
    """
    n = int(agents)
    d = float(d)
    if neighbors not in ("search", "frozen"):
        from avblocks.core.errors import ParameterError
        raise ParameterError("neighbors must be 'search' or 'frozen'", block="flocking",
                             param="neighbors", found=neighbors)
    p0, vel0 = initial_conditions(n, d, spread, v0, seed)
    dg = Diagram("flocking")
    flock = dg.add(DoubleIntegrator(p0, velocity0=vel0), name="flock")
    opts = {}
    if neighbors == "frozen":
        opts["adjacency"] = frozen_adjacency(p0, k, 1.2 * d)
    law = dg.add(Flocking(n, d, gamma=True, target=np.asarray(target, float),
                          target_velocity=np.asarray(target_velocity, float),
                          c1=float(c1), c2=float(c2), **opts), name="law")
    view = dg.add(Function(pose_and_order, inputs={"position": (n, 2), "velocity": (n, 2)},
                           outputs={"pose": (n, 3), "order": ()}), name="view")
    if neighbors == "search":
        nb = dg.add(Neighbors(n, int(k), radius=1.2 * d, input="position",
                              period=float(dt), method="auto"), name="neighbors")
        dg.connect(flock.position, nb.position)
        dg.connect(nb.neighbors, law.neighbors)
    dg.connect(flock.position, law.position)
    dg.connect(flock.velocity, law.velocity)
    dg.connect(law.accel, flock.accel)
    dg.connect(flock.position, view.position)
    dg.connect(flock.velocity, view.velocity)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
           "log": [view.pose, flock.position, flock.velocity, view.order],
           "log_every": int(log_every), "seed": int(seed)}
    return dg, sim


def _nearest(position):
    from scipy.spatial import cKDTree
    dist, _ = cKDTree(position).query(position, k=2)
    return dist[:, 1]


def _order(res):
    if "view.order" in res:
        return np.asarray(res["view.order"]).reshape(len(res.t))
    v = np.asarray(res["flock.velocity"])
    return np.array([order_parameter(v[k], np) for k in range(len(v))], float)


def outcome(res, params):
    """Order parameter at the end, nearest-neighbour spacing against ``d``,
    closest approach over the run."""
    from avblocks.scenarios.report import min_pairwise_distance
    order = _order(res)
    nn = _nearest(np.asarray(res["flock.position"])[-1])
    dmin, _ = min_pairwise_distance(res["flock.position"])
    d = float(params["d"])
    nums = {"order_end": float(order[-1]), "nearest_median_m": float(np.median(nn)),
            "d_m": d, "closest_approach_m": dmin}
    return (f"order {order[-1]:.3f} at {res.t[-1]:.3g} s, nearest neighbours "
            f"{np.median(nn):.2f} m apart (median; d = {d:g} m), closest approach "
            f"{dmin:.2f} m"), nums


def figures(res, out, params):
    """flocking.png: paths (colour per agent) and the order parameter."""
    import matplotlib.pyplot as plt

    from avblocks.scenarios.report import save_figure
    from avblocks.viz import plot_trajectories
    fig, (a, b) = plt.subplots(1, 2, figsize=(11.0, 5.0),
                               gridspec_kw={"width_ratios": [1.2, 1]})
    key = "view.pose" if "view.pose" in res else "flock.position"
    n = np.asarray(res[key]).shape[1]
    plot_trajectories(res, key, ax=a,
                      title=f"{n} double integrators flocking after a moving target")
    order = _order(res)
    b.plot(res.t, order, color="tab:blue", lw=1.5)
    b.set_ylim(0, 1.05)
    b.set_xlabel("t [s]")
    b.set_ylabel("order |sum v| / sum |v|  (1: aligned)")
    b.set_title("alignment of the velocities")
    b.grid(True, alpha=0.3)
    return [save_figure(fig, f"{out}/flocking.png")]


def ensemble_x0(seeds, agents=50, d=7.0, spread=50.0, v0=2.0):
    """``x0`` for :meth:`avblocks.Runner.ensemble`: run ``k`` starts from the
    positions and velocities of ``make_diagram(seed=seeds[k])``.

    Example (256 runs of 50 agents over 30 s in one call)::

        dg, sim = flocking.make_diagram(agents=50, t_final=30.0)
        runner = av.compile(dg, **{k: v for k, v in sim.items() if k != "seed"})
        res = runner.ensemble(seeds=range(256), x0=flocking.ensemble_x0(range(256)))
        res["flock.position"]          # (256, T, 50, 2)
    """
    starts = [initial_conditions(agents, d, spread, v0, s) for s in seeds]
    return {"flock.position": np.stack([p for p, _ in starts]),
            "flock.velocity": np.stack([v for _, v in starts])}


def pairs(adjacency):
    """Index arrays ``(i, j)``, ``i < j``, of the edges of an (N, N) adjacency."""
    i, j = np.nonzero(np.triu(np.asarray(adjacency), 1))
    return i, j


def lattice_cost(position, accel, pairs_ij, d, effort=0.01, xp=np):
    """Flocking cost of a run: mean over samples and neighbour pairs of the
    squared distance error ``(|q_i - q_j| - d)^2`` plus ``effort`` times the
    mean squared control ``|u_i|^2``.

    ``position``, ``accel``: (T, N, D) logs; ``pairs_ij``: the frozen
    neighbour pairs (:func:`pairs`). Works on NumPy and ``jax.numpy`` arrays
    (``xp``), so the same function gives the cost of a NumPy run and the
    traced cost of :func:`avblocks.grad`.
    """
    i, j = pairs_ij
    dq = position[:, i] - position[:, j]
    dist = xp.sqrt(xp.sum(dq * dq, axis=-1))
    return xp.mean((dist - d) ** 2) + effort * xp.mean(xp.sum(accel * accel, axis=-1))
