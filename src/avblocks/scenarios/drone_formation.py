"""A 3-D formation flight of quadrotors (default five) that runs in
simulation and, unchanged, on drones (``--robots mavlink`` or
``--robots crazyflies``, on the emulators or real vehicles).

Set-up
------
N velocity-controlled quadrotors (``vehicles.velocity_controlled_quadrotor``,
block ``fleet``) start hovering on a line along x at ``height`` (on drones
the takeoff phase brings them there). A virtual structure
(:class:`FormationReference`, block ``ref``) gives each vehicle its planned
position: a "crown", N slots on a circle of radius ``radius`` around a
centre, alternately ``dz`` above and below it, that keeps its shape
while its centre flies a circle of radius ``path_radius`` in ``period``
seconds, rising and sinking by ``climb`` on the way. For the first
``gather`` seconds the planned positions blend from the start line into
the crown (a smoothstep), so the plan starts where the vehicles are.
Each vehicle tracks its planned position (:class:`Tracker`, block
``track``)::

    v_i = v_ref,i + k (p_ref,i - p_i),   |v_i| <= v_max

Outcome (:func:`outcome`, the same in simulation and in flight): formation
error (RMS and largest distance to the planned position after
``gather``), the smallest distance between two vehicles over the run.
Figure (:func:`figures`): planned against flown paths, top view and side
view.

Run it::

    avblocks run drone_formation
    avblocks mavlink emulate --n 5 --pose0 "$(python -c 'from avblocks.scenarios.\\
        drone_formation import start_positions; print(start_positions(5, 0).tolist())')"
    avblocks run drone_formation --robots mavlink
"""

from __future__ import annotations

import numpy as np

from avblocks.core.block import Block
from avblocks.core.diagram import Diagram
from avblocks.vehicles import Quadrotor, velocity_controlled_quadrotor

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


class FormationReference(Block):
    """Planned positions and velocities of a turning 3-D formation.

    Ports
    -----
    position : out, (N, 3) [m]
    velocity : out, (N, 3) [m/s]

    Parameters
    ----------
    start : (N, 3)
        Start positions (the plan begins there).
    offsets : (N, 3)
        Slots around the centre, in the formation's frame.
    path_radius, period : float
        The centre flies a circle of this radius [m] in ``period`` [s].
    climb : float
        ... rising and sinking by this much [m] on the way (h_z).
    gather : float
        Blending time from the start into the formation [s].

    Equations
    ---------
    With ``T = max(t - gather, 0)`` (the formation forms in place, then
    flies): ``c = c0 + (R_c sin wT, R_c (1 - cos wT), h_z sin wT)``,
    ``w = 2 pi / period``, ``q_i = c + o_i``; planned ``p_i = (1 - s) p0_i + s q_i`` with
    ``s = 3 tau^2 - 2 tau^3``, ``tau = min(t / gather, 1)``; the velocity is
    the exact time derivative.

    References
    ----------
    M. A. Lewis, K.-H. Tan, "High precision formation control of mobile
    robots using virtual structures", Autonomous Robots 4, 1997.
    """

    def __init__(self, start, offsets, path_radius=1.5, period=24.0, gather=6.0,
                 climb=0.3):
        super().__init__()
        self.p0 = np.asarray(start, float)
        self.o = np.asarray(offsets, float)
        self.n = n = len(self.p0)
        self.c0 = np.array([self.p0[:, 0].mean(), self.p0[:, 1].mean(), self.p0[:, 2].mean()])
        self.rc, self.w, self.tg = float(path_radius), 2 * np.pi / float(period), float(gather)
        self.hz = float(climb)
        self.declare_output("position", (n, 3), unit="m")
        self.declare_output("velocity", (n, 3), unit="m/s")

    def output(self, t, x, u, xp):
        rc, hz = self.rc, self.hz
        w = xp.where(t > self.tg, self.w, 0.0)
        tt = xp.maximum(t - self.tg, 0.0)
        ps, pc = xp.sin(self.w * tt), xp.cos(self.w * tt)
        c = self.c0 + xp.stack([rc * ps, rc * (1.0 - pc), hz * ps])
        cd = w * xp.stack([rc * pc, rc * ps, hz * pc])
        q, qd = c + self.o, cd + 0.0 * self.o
        tau = xp.minimum(t / self.tg, 1.0)
        s = 3 * tau**2 - 2 * tau**3
        sd = xp.where(t < self.tg, (6 * tau - 6 * tau**2) / self.tg, 0.0)
        return {"position": (1 - s) * self.p0 + s * q,
                "velocity": sd * (q - self.p0) + s * qd}


class Tracker(Block):
    """Track planned positions with a velocity command.

    Ports
    -----
    position : in, (N, 3) [m]
    ref_position, ref_velocity : in, (N, 3)
    velocity : out, (N, 3) [m/s]

    Parameters
    ----------
    n : int
    gain : float [1/s]
    v_max : float [m/s]

    Equations
    ---------
    ``v = v_ref + k (p_ref - p)``, scaled to ``|v| <= v_max``.

    References
    ----------
    Proportional tracking with feed-forward (Lewis and Tan, 1997).
    """

    def __init__(self, n, gain=1.5, v_max=1.5):
        super().__init__()
        self.n, self.k, self.v_max = int(n), float(gain), float(v_max)
        for p in ("position", "ref_position", "ref_velocity"):
            self.declare_input(p, (n, 3))
        self.declare_output("velocity", (n, 3), unit="m/s")

    def output(self, t, x, u, xp):
        v = u["ref_velocity"] + self.k * (u["ref_position"] - u["position"])
        sp = xp.sqrt(xp.sum(v * v, axis=-1, keepdims=True))
        return {"velocity": v * xp.minimum(1.0, self.v_max / xp.maximum(sp, 1e-12))}


def make_diagram(agents=5, spacing=1.0, height=1.5, radius=1.0, dz=0.3, path_radius=1.5,
                 climb=0.3, period=24.0, gather=6.0, gain=1.5, v_max=1.5, t_final=24.0,
                 dt=0.02, seed=1):
    """The diagram and its simulation settings (see the module docstring)."""
    n = int(agents)
    p0 = start_positions(n, height, spacing)
    d = Diagram("drone_formation")
    fleet = d.add(velocity_controlled_quadrotor(Quadrotor(p0)), name="fleet")
    ref = d.add(FormationReference(p0, crown_offsets(n, radius, dz), path_radius, period,
                                   gather, climb), name="ref")
    trk = d.add(Tracker(n, gain, v_max), name="track")
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
    """Smallest distance [m] between two vehicles over the run."""
    p = res["fleet.position"]
    dist = np.linalg.norm(p[:, :, None] - p[:, None], axis=-1)
    n = p.shape[1]
    dist[:, np.arange(n), np.arange(n)] = np.inf
    return float(dist.min())


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
