"""Antipodal swap with a safety filter: single integrators on a circle
drive to the diametrically opposite point; a control-barrier-function
filter (CollisionAvoidance) keeps every pair at least ``safety`` apart.

Set-up
------
``agents`` single integrators (``vehicles.SingleIntegrator``) start nearly
evenly spaced on a circle of radius ``radius`` (angles perturbed by
``jitter`` of the spacing); each one's goal is the opposite point.
``controllers.HolonomicPointToPoint`` gives the nominal velocity (gain
``gain``, capped per agent, see below); ``controllers.CollisionAvoidance``
minimally modifies it so that ``|p_i - p_j| >= safety`` for every pair
within ``sensing`` (its own cell-list neighbour search, which the
compiled backend traces; ``capacity`` agents per cell at most, all of
them by default). ``right_hand`` adds a roundabout bias and the jitter
and per-agent speed caps (``v_max`` times 1 minus up to
``speed_spread``) break the symmetry. A ``blocks.Function`` makes planar
poses (heading along the velocity, or towards the goal once stopped) for
plots and movies.

The filter is the joint barrier certificate (``mode="joint"``, the
default): one QP over all agents, solved by the built-in, traceable ADMM
solver (``solver="admm"``; ``"clarabel"`` is the interior-point
reference of the ``safety`` extra). Why the joint QP is the default: the
per-agent split (``mode="agent"``, each agent takes half of every pair's
constraint, ``k`` nearest neighbours) jams at the centre of a dense swap.
At ``safety=0.85`` (circle / safety radius 5.88, Robotarium's default
ratio) it leaves agents stuck at 30 s, while the joint QP lets one agent
give way more than the other and brings all 20 home by about 16 s
(closest approach 0.850 m either way); the joint QP also completes the
swap for ratios 3.25 to 8 (tested; 20 agents cannot start on the circle
at least one safety radius apart below 3.2) and the perfectly symmetric
swap (``jitter=0, speed_spread=0``) for ratios 4 to 10. Without
symmetry breaking (``right_hand=0, jitter=0, speed_spread=0``) even the
joint QP stops at the symmetric KKT point ``u = 0``.

Logged: ``fleet.position``, ``view.pose``, ``drive.done``. Expect a minimum
pairwise distance of ``safety`` (to solver accuracy) and every agent at its
goal by about 16 s at the defaults (measured on a shared 2-core machine:
about 4 s of wall time with NumPy, where the per-agent filter took 3.4 s to
bring everyone home by 21 s; compiled with ``--backend jax``: 15 s to
compile, 2.8 s per further run, the same outcome numbers).

Reference: L. Wang, A. D. Ames, M. Egerstedt, "Safety barrier certificates
for collisions-free multirobot systems", IEEE T-RO 33(3), 2017.
"""

from __future__ import annotations

import numpy as np

from avblocks.blocks import Function
from avblocks.controllers import CollisionAvoidance, HolonomicPointToPoint
from avblocks.core.diagram import Diagram
from avblocks.vehicles import SingleIntegrator

#: Options for ``viz.save_movie`` (``avblocks run swap --movie s.mp4``).
MOVIE = {"pose": "view.pose", "trail": 4.0}


def circle_swap(n, radius, jitter=0.0, seed=1):
    """Start positions on a circle (N, 2) and their antipodes; ``jitter``
    (rad) perturbs the angles (uniform in +-jitter/2 of the spacing)."""
    rng = np.random.default_rng([int(seed), 9])
    a = 2 * np.pi * (np.arange(n) + jitter * rng.uniform(-0.5, 0.5, n)) / n
    start = radius * np.column_stack([np.cos(a), np.sin(a)])
    return start, -start


def make_diagram(agents=20, radius=5.0, safety=0.6, v_max=1.0, gain=1.0, gamma=2.0,
                 right_hand=1.0, sensing=3.0, k=6, goal_radius=0.05, jitter=0.5,
                 speed_spread=0.3, seed=1, t_final=30.0, dt=0.05, log_every=1,
                 mode="joint", solver="admm", capacity=None):
    """The swap diagram and its simulation settings (``capacity``: agents
    per cell of the safety filter's neighbour search, default all)."""
    n = int(agents)
    capacity = n if capacity is None else int(capacity)
    start, goal = circle_swap(n, float(radius), float(jitter), seed)
    rng = np.random.default_rng([int(seed), 10])
    v_cap = float(v_max) * (1.0 - float(speed_spread) * rng.uniform(0.0, 1.0, n))
    rest = np.arctan2(goal[:, 1] - start[:, 1], goal[:, 0] - start[:, 0])

    def pose(t, position, velocity, xp):
        speed = xp.sqrt(xp.sum(velocity * velocity, axis=1))
        heading = xp.where(speed > 1e-3, xp.arctan2(velocity[:, 1], velocity[:, 0]), rest)
        return xp.concatenate([position, heading[:, None]], axis=1)

    dg = Diagram("swap")
    fleet = dg.add(SingleIntegrator(start), name="fleet")
    drive = dg.add(HolonomicPointToPoint(goal[:, None, :], gain=float(gain),
                                         v_max=v_cap, radius=float(goal_radius)),
                   name="drive")
    safe = dg.add(CollisionAvoidance(n, float(safety), gamma=float(gamma),
                                     right_hand=float(right_hand), mode=mode,
                                     solver=solver, sensing_range=float(sensing),
                                     k_max=int(k), capacity=capacity),
                  name="safety")
    view = dg.add(Function(pose, inputs={"position": (n, 2), "velocity": (n, 2)},
                           outputs={"pose": (n, 3)}), name="view")
    dg.connect(fleet.position, drive.position)
    dg.connect(fleet.position, safe.position)
    dg.connect(drive.velocity, safe.velocity_nominal)
    dg.connect(safe.velocity, fleet.velocity)
    dg.connect(fleet.position, view.position)
    dg.connect(safe.velocity, view.velocity)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
           "log": [view.pose, fleet.position, drive.done], "log_every": int(log_every),
           "seed": int(seed)}
    return dg, sim


def outcome(res, params):
    """Arrival time, closest approach against the safety radius."""
    from avblocks.scenarios.report import first_time_all, min_pairwise_distance
    done = np.asarray(res["drive.done"])
    t_all = first_time_all(res.t, done)
    dmin, kmin = min_pairwise_distance(res["fleet.position"])
    safety = float(params["safety"])
    n = done.shape[1]
    nums = {"all_at_goal_s": t_all, "at_goal_end": int(done[-1].sum()),
            "closest_approach_m": dmin, "safety_m": safety}
    head = (f"all {n} at their goals at {t_all:.3g} s" if t_all is not None else
            f"{int(done[-1].sum())} of {n} at their goals by t = {res.t[-1]:.3g} s")
    return f"{head}, closest approach {dmin:.3f} m (safety radius {safety:g} m)", nums


def figures(res, out, params):
    """swap.png: paths and the closest pair distance against the safety radius."""
    import matplotlib.pyplot as plt
    from scipy.spatial.distance import pdist

    from avblocks.scenarios.report import save_figure
    from avblocks.viz import plot_trajectories
    fig, (a, b) = plt.subplots(1, 2, figsize=(11.0, 5.0),
                               gridspec_kw={"width_ratios": [1.1, 1]})
    p = np.asarray(res["fleet.position"])
    plot_trajectories(res, "view.pose" if "view.pose" in res else "fleet.position", ax=a,
                      title=f"{p.shape[1]} agents swap sides through a safety filter")
    dmin = np.array([pdist(p[k]).min() for k in range(len(res.t))])
    safety = float(params["safety"])
    b.plot(res.t, dmin, color="tab:blue", lw=1.5, label="closest pair")
    b.axhline(safety, color="tab:red", ls="--", lw=1.2, label=f"safety radius {safety:g} m")
    b.set_xlabel("t [s]")
    b.set_ylabel("distance [m]")
    b.set_ylim(0, max(float(dmin.max()) * 1.05, 1.5 * safety))
    b.set_title("closest pair of agents")
    b.legend(fontsize=8)
    b.grid(True, alpha=0.3)
    return [save_figure(fig, f"{out}/swap.png")]


# ------------------------------------------------- generators for scenario files
# (the YAML twin names this case study's geometry: see avblocks.scenarios.generators)
def _circle_swap(n, radius, jitter=0.0, seed=1, which="start"):
    start, goal = circle_swap(int(n), float(radius), float(jitter), seed)
    if which == "start":
        return start
    if which == "goal":
        return goal[:, None, :]
    raise ValueError(f"which must be 'start' or 'goal', got {which!r}")


def _speed_caps(n, v_max, spread, seed=1, stream=10):
    rng = np.random.default_rng([int(seed), int(stream)])
    return float(v_max) * (1.0 - float(spread) * rng.uniform(0.0, 1.0, int(n)))


#: the generators this case study offers to scenario files
GENERATORS = {
    "circle_swap": _circle_swap,
    "speed_caps": _speed_caps,
}
