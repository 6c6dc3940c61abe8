"""A 3-D formation flight of quadrotors (default five) that runs in
simulation and, unchanged, on drones (``--robots mavlink`` or
``--robots crazyflies``, on the emulators or real vehicles).

Set-up
------
N velocity-controlled quadrotors (``vehicles.VelocityControlledQuadrotor``,
block ``fleet``) start hovering on a line along x at ``height`` (on drones
the takeoff phase brings them there). A virtual structure
(:class:`~avblocks.controllers.FormationReference`, block ``ref``) gives each vehicle its planned
position: a "crown", N slots on a circle of radius ``radius`` around a
centre, alternately ``dz`` above and below it, that keeps its shape
while its centre flies a circle of radius ``path_radius`` in ``period``
seconds, rising and sinking by ``climb`` on the way. For the first
``gather`` seconds the planned positions blend from the start line into
the crown (a smoothstep), so the plan starts where the vehicles are.
Each vehicle tracks its planned position (:class:`~avblocks.controllers.ReferenceTracker`,
block ``track``)::

    v_i = v_ref,i + k (p_ref,i - p_i),   |v_i| <= v_max

Outcome (:func:`outcome`, the same in simulation and in flight): formation
error (RMS and largest distance to the planned position after
``gather``), the smallest distance between two vehicles over the run.
Figure (:func:`figures`): planned against flown paths, top view and side
view.

The scenario file ``drone_formation.yaml`` is this module's twin (the same
blocks, the start line and the crown from its generators ``drone_start``
and ``crown_offsets``): it is what ``avblocks run drone_formation`` runs
and what the editor opens, to the same numbers.

Run it::

    avblocks run drone_formation
    avblocks mavlink emulate --n 5 --pose0 "$(python -c 'from avblocks.scenarios.\\
        drone_formation import start_positions; print(start_positions(5, 0).tolist())')"
    avblocks run drone_formation --robots mavlink
"""

from __future__ import annotations

import numpy as np

from avblocks.controllers import FormationReference, ReferenceTracker
from avblocks.core.diagram import Diagram
from avblocks.vehicles import VelocityControlledQuadrotor

from ._metrics import min_pairwise_distance

#: Parameters (``--set name=value``).
PARAMS = {"agents": 5, "spacing": 1.0, "height": 1.5, "radius": 1.0, "dz": 0.3,
          "path_radius": 1.5, "climb": 0.3, "period": 24.0, "gather": 6.0, "gain": 1.5,
          "v_max": 1.5, "t_final": 24.0, "dt": 0.02, "seed": 1}


def start_positions(n=5, height=1.5, spacing=1.0):
    """Where the vehicles start (N, 3): a line along x centred on 0."""
    x = (np.arange(n) - (n - 1) / 2) * spacing
    return np.column_stack([x, np.zeros(n), np.full(n, float(height))])


def crown_offsets(n=5, radius=1.0, dz=0.3):
    """The crown's slots (N, 3): angles 2 pi k / N on a circle, heights +-dz
    alternately around it; given to the vehicles in the order of their x
    on the start line (west-most vehicle, west-most slot), so the gather
    paths do not cross."""
    k = np.arange(n)
    a = np.pi / 2 + 2 * np.pi * k / n
    slots = np.column_stack([radius * np.cos(a), radius * np.sin(a),
                             np.where(k % 2 == 0, dz, -dz)])
    return slots[np.argsort(slots[:, 0], kind="stable")]


#: The scenario's blocks live in :mod:`avblocks.controllers` (the names
#: this module had before stay valid).
Tracker = ReferenceTracker


def _drone_start(n, height=1.5, spacing=1.0):
    """Generator ``drone_start``: :func:`start_positions` for a scenario file."""
    from .limits import budget
    budget(3 * int(n), "drone_start")
    return start_positions(int(n), float(height), float(spacing))


def _crown_offsets(n, radius=1.0, dz=0.3):
    """Generator ``crown_offsets``: :func:`crown_offsets` for a scenario file."""
    from .limits import budget
    budget(3 * int(n), "crown_offsets")
    return crown_offsets(int(n), float(radius), float(dz))


#: value generators of this case study (``{drone_start: {n: $agents, ...}}``)
GENERATORS = {"drone_start": _drone_start, "crown_offsets": _crown_offsets}


def make_diagram(agents=5, spacing=1.0, height=1.5, radius=1.0, dz=0.3, path_radius=1.5,
                 climb=0.3, period=24.0, gather=6.0, gain=1.5, v_max=1.5, t_final=24.0,
                 dt=0.02, seed=1):
    """The diagram and its simulation settings (see the module docstring)."""
    n = int(agents)
    p0 = start_positions(n, height, spacing)
    d = Diagram("drone_formation")
    fleet = d.add(VelocityControlledQuadrotor(p0), name="fleet")
    ref = d.add(FormationReference(p0, crown_offsets(n, radius, dz), path_radius, period,
                                   gather, climb), name="ref")
    trk = d.add(ReferenceTracker(n, gain, v_max), name="track")
    d.connect(fleet.position, trk.position)
    d.connect(ref.position, trk.ref_position)
    d.connect(ref.velocity, trk.ref_velocity)
    d.connect(trk.velocity, fleet.velocity)
    sim = {"t_final": float(t_final), "dt": float(dt), "solver": "rk4",
           "log": ["fleet.position", "ref.position", "track.velocity"], "log_every": 5,
           "seed": int(seed)}     # nothing is random here; the name all scenarios share
    return d, sim


def formation_error(res, gather=PARAMS["gather"]):
    """(RMS, max) distance [m] of the vehicles to their planned positions
    from ``gather`` seconds on."""
    e = np.linalg.norm(res["fleet.position"] - res["ref.position"], axis=-1)
    e = e[np.asarray(res.t) >= gather - 1e-9]
    if not e.size:                  # the run ended before the formation formed
        return float("nan"), float("nan")
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def min_separation(res):
    """Smallest distance [m] between two vehicles over the run (in 3-D; a
    k-d tree per logged sample, so memory grows with the vehicles, not
    their square: all pairs of all samples at once took over 24 GB for
    1,500 vehicles)."""
    return min_pairwise_distance(res["fleet.position"], dims=3)[0]


def outcome(res, params=None):
    """Formation error and minimum separation (one line and the numbers)."""
    g = float((params or {}).get("gather", PARAMS["gather"]))
    rms, emax = formation_error(res, g)
    sep = min_separation(res)
    return (f"formation: RMS error {rms:.3f} m, max {emax:.3f} m after {g:g} s; "
            f"min separation {sep:.2f} m",
            {"formation_rms_m": rms, "formation_max_m": emax, "min_separation_m": sep})


def figures(res, out, params=None):
    """``paths.png``: planned (dashed) against flown paths, top and side view."""
    from pathlib import Path

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from avblocks.core.atomic import atomic_path
    p, r = res["fleet.position"], res["ref.position"]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.8),
                                 gridspec_kw={"width_ratios": [1.2, 1]})
    colors = plt.cm.tab10(np.arange(p.shape[1]) % 10)
    t = np.asarray(res.t)
    for i, c in enumerate(colors):
        ax.plot(r[:, i, 0], r[:, i, 1], "--", color=c, lw=1.0)
        ax.plot(p[:, i, 0], p[:, i, 1], "-", color=c, lw=1.6, label=f"vehicle {i + 1}")
        ax.plot(*p[0, i, :2], "o", color=c, ms=4)
        ax.plot(*p[-1, i, :2], "s", color=c, ms=5)
        bx.plot(t, r[:, i, 2], "--", color=c, lw=1.0)
        bx.plot(t, p[:, i, 2], "-", color=c, lw=1.6)
    ax.set_aspect("equal")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    ax.set_title("top view: planned (dashed) and flown (solid)")
    ax.legend(fontsize=7, loc="upper left")
    bx.set_xlabel("t [s]")
    bx.set_ylabel("z (up) [m]")
    bx.set_title("height: planned (dashed) and flown (solid)")
    line = outcome(res, params)[0]
    fig.suptitle(line, fontsize=9)
    fig.tight_layout()
    path = Path(out) / "paths.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return [path]
