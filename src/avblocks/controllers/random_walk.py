"""Random walk of unicycles: new speed and heading at random intervals.

Behaviour
---------
Each agent holds a target speed ``v_i`` and target heading ``psi_i``. At its
switching times it draws new ones; between them it drives

    v = v_i,    omega = sat_{omega_max}(K wrap(psi_i - theta))

(heading tracking). Switching intervals are drawn per agent from a
user-chosen :class:`Distribution` (normal, uniform or exponential), the
speed uniformly in ``speed = (v_lo, v_hi)``, the heading uniformly in
(-pi, pi] or, with ``turn_std``, as the previous heading plus a normal turn.

Switch times are a schedule ``T_{k+1} = T_k + tau_k`` (the first at the
start); a switch happens at the first major step with ``t >= T_k``, so the
realised times lag the schedule by less than one step and the intervals
``tau_k`` follow the distribution exactly. Negative normal draws are clipped
to ``min_interval``. Intervals much shorter than the step are caught up one
per step.

Boundary (optional ``bounds=(xmin, ymin, xmax, ymax)`` or convex
``polygon`` (M, 2)): at each major step an agent outside the region shrunk by
``margin`` whose target heading points outwards across a violated edge gets
a new target heading: ``"reflect"`` mirrors it about that edge (angle of
incidence = angle of reflection); ``"turn_back"`` points it at the region's
centroid.

Randomness comes from a declared random state: the same seed gives the same
run. Reference: AVLib paper, Section III.B (random walk emulating Brownian
motion, intervals from a user-defined normal, uniform or exponential
distribution) and case study IV.B (search by random walk).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import rng
from ..core.block import Block
from ..core.errors import ParameterError
from ..core.params import finite_array, positive_scalar
from ..utility.angles import wrap_angle


@dataclass(frozen=True)
class Distribution:
    """A distribution of switching intervals (s).

    ``Distribution("normal", mean, std)``, ``Distribution("uniform", low,
    high)`` or ``Distribution("exponential", mean)``.
    """

    kind: str
    a: float = 1.0
    b: float | None = None

    def __post_init__(self):
        k = self.kind
        if k not in ("normal", "uniform", "exponential"):
            raise ParameterError("unknown distribution", block="RandomWalk",
                                 param="interval",
                                 expected=("normal", "uniform", "exponential"), found=k)
        a = float(self.a)
        b = None if self.b is None else float(self.b)
        ok = np.isfinite(a) and (b is None or np.isfinite(b))
        if k == "exponential":
            ok = ok and a > 0 and b is None
        elif k == "normal":
            ok = ok and b is not None and b > 0
        else:
            ok = ok and b is not None and 0 <= a < b
        if not ok:
            raise ParameterError(
                "bad distribution parameters", block="RandomWalk", param="interval",
                expected={"normal": "(mean, std > 0)", "uniform": "(0 <= low < high)",
                          "exponential": "(mean > 0,)"}[k], found=(self.a, self.b))

    @classmethod
    def parse(cls, spec):
        if isinstance(spec, Distribution):
            return spec
        if isinstance(spec, str):
            spec = (spec,)
        try:
            return cls(*spec)
        except TypeError:
            raise ParameterError("interval must be a Distribution or a tuple like "
                                 "('exponential', mean)", block="RandomWalk",
                                 param="interval", found=spec) from None

    @property
    def params(self):
        """``(a,)`` or ``(a, b)``: the numeric values of the distribution."""
        return (float(self.a),) if self.b is None else (float(self.a), float(self.b))

    def sample(self, key, shape, xp=np, params=None):
        """Draw; ``params`` (like :attr:`params`) overrides ``a``, ``b``."""
        a, b = (self.a, self.b) if params is None else (
            params[0], params[1] if len(params) > 1 else None)
        if self.kind == "normal":
            return rng.normal(key, shape, xp, a, b)
        if self.kind == "uniform":
            return rng.uniform(key, shape, xp, a, b)
        return rng.exponential(key, shape, xp, a)

    def scipy(self):
        """The same distribution as a frozen :mod:`scipy.stats` object."""
        from scipy import stats
        if self.kind == "normal":
            return stats.norm(self.a, self.b)
        if self.kind == "uniform":
            return stats.uniform(self.a, self.b - self.a)
        return stats.expon(scale=self.a)


def convex_halfplanes(polygon, block="RandomWalk"):
    """Unit outward normals (M, 2) and offsets (M,) with ``n . p <= c`` inside."""
    p = finite_array(polygon, block, "polygon")
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
        raise ParameterError("polygon must be (M, 2), M >= 3", block=block,
                             param="polygon", found=p.shape)
    area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    if area2 < 0:                       # make it counter-clockwise
        p, area2 = p[::-1], -area2
    e = np.roll(p, -1, axis=0) - p
    cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
    if area2 == 0 or np.any(cross < -1e-12 * np.abs(area2)):
        raise ParameterError("polygon must be convex and non-degenerate", block=block,
                             param="polygon")
    nrm = np.stack([e[:, 1], -e[:, 0]], axis=-1)
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    return nrm, np.sum(nrm * p, axis=1), p.mean(axis=0)


def random_walk_cmd(pose, speed, heading, gain, omega_max, xp=np):
    """(v, omega): hold ``speed``, turn toward ``heading`` (saturated P law)."""
    err = wrap_angle(heading - pose[:, 2], xp)
    return xp.stack([speed, xp.clip(gain * err, -omega_max, omega_max)], axis=-1)


class RandomWalk(Block):
    """Random walk for N unicycles (see the module docstring).

    Ports
    -----
    pose : in, (N, 3).
    cmd : out, (N, 2) — (v, omega).
    next_switch : out, (N,) — scheduled time of each agent's next switch.

    State
    -----
    t_next (N,) scheduled switch time; speed (N,), heading (N,) targets;
    started (N,) bool; key — random state.

    Parameters
    ----------
    n : int
    interval : Distribution or tuple — e.g. ``("exponential", 2.0)``,
        ``("normal", 3.0, 0.5)``, ``("uniform", 1.0, 4.0)``.
    speed : (v_lo, v_hi) — uniform speed range (m/s).
    turn_std : float, optional — draw heading as previous + N(0, turn_std);
        default: uniform in (-pi, pi].
    gain : float — heading gain K (1/s);  omega_max : float (rad/s).
    bounds : (xmin, ymin, xmax, ymax), optional;  polygon : (M, 2) convex.
    boundary : "reflect" or "turn_back";  margin : float (m).
    min_interval : float >= 0 — lower clip of drawn intervals.

    Numeric parameters
    ------------------

    Numeric parameters: ``interval_params`` (the distribution's ``(a,)`` or
    ``(a, b)``), ``speed`` (2,), ``turn_std`` (when given), ``gain``,
    ``omega_max``, ``min_interval``, ``margin``. The distribution kind, the
    region (``bounds``/``polygon``) and ``boundary`` are structural.
    """

    def __init__(self, n, *, interval=("exponential", 2.0), speed=(0.5, 1.0),
                 turn_std=None, gain=2.0, omega_max=np.inf, bounds=None, polygon=None,
                 boundary="reflect", margin=0.0, min_interval=0.0):
        super().__init__()
        name = "RandomWalk"
        self.n = n = int(n)
        self.interval = Distribution.parse(interval)
        sp = finite_array(speed, name, "speed", shape=(2,))
        if not sp[0] <= sp[1]:
            raise ParameterError("speed must be (low, high) with low <= high",
                                 block=name, param="speed", found=sp)
        dp = self.declare_parameter
        dp("interval_params", self.interval.params,
           bounds=(None, None) if self.interval.kind == "normal" else (0, None),
           unit="s", doc="(a,) or (a, b) of the interval distribution")
        dp("speed", sp, unit="m/s", doc="(low, high) of the uniform speed draw")
        if turn_std is None:
            self.turn_std = None
        else:
            dp("turn_std", positive_scalar(turn_std, name, "turn_std"),
               bounds=(1e-12, None), unit="rad")
        dp("gain", positive_scalar(gain, name, "gain"), bounds=(1e-12, None), unit="1/s")
        dp("omega_max", positive_scalar(omega_max, name, "omega_max", allow_inf=True),
           bounds=(0, None), allow_inf=True, unit="rad/s")
        dp("min_interval", positive_scalar(min_interval, name, "min_interval",
                                           allow_zero=True), bounds=(0, None), unit="s")
        dp("margin", positive_scalar(margin, name, "margin", allow_zero=True),
           bounds=(0, None), unit="m")
        if bounds is not None and polygon is not None:
            raise ParameterError("give bounds or polygon, not both", block=name,
                                 param="bounds")
        if bounds is not None:
            b = finite_array(bounds, name, "bounds", shape=(4,))
            polygon = [[b[0], b[1]], [b[2], b[1]], [b[2], b[3]], [b[0], b[3]]]
        self.region = None if polygon is None else convex_halfplanes(polygon, name)
        if boundary not in ("reflect", "turn_back"):
            raise ParameterError("boundary must be 'reflect' or 'turn_back'", block=name,
                                 param="boundary", found=boundary)
        self.boundary = boundary
        self.declare_discrete_state("t_next", np.zeros(n))
        self.declare_discrete_state("speed", np.zeros(n))
        self.declare_discrete_state("heading", np.zeros(n))
        self.declare_discrete_state("started", np.zeros(n, dtype=bool))
        self.declare_random_state("key")
        self.declare_input("pose", (n, 3), unit="m, m, rad")
        self.declare_output("cmd", (n, 2), unit="m/s, rad/s", labels=("v", "omega"))
        self.declare_output("next_switch", (n,), unit="s")

    def output(self, t, x, u, xp):
        pose = u["pose"]
        st = x["started"]
        heading = xp.where(st, x["heading"], pose[:, 2])
        cmd = random_walk_cmd(pose, xp.where(st, x["speed"], 0.0), heading,
                              self.gain, self.omega_max, xp)
        return {"cmd": cmd, "next_switch": x["t_next"]}

    def update(self, t, x, u, xp):
        n = self.n
        key, k1, k2, k3 = rng.split(x["key"], xp, 4)
        pose = u["pose"]
        st = x["started"]
        due = (~st) | (t >= x["t_next"])
        tau = xp.maximum(self.interval.sample(k1, (n,), xp, self.interval_params),
                         self.min_interval)
        t_next = xp.where(due, xp.where(st, x["t_next"], t) + tau, x["t_next"])
        v_new = rng.uniform(k2, (n,), xp, self.speed[0], self.speed[1])
        if self.turn_std is None:
            h_new = rng.uniform(k3, (n,), xp, -np.pi, np.pi)
        else:
            base = xp.where(st, x["heading"], pose[:, 2])
            h_new = wrap_angle(base + rng.normal(k3, (n,), xp, 0.0, self.turn_std), xp)
        speed = xp.where(due, v_new, x["speed"])
        heading = xp.where(due, h_new, xp.where(st, x["heading"], pose[:, 2]))
        if self.region is not None:
            heading = self._boundary(pose[:, :2], heading, xp)
        return {"key": key, "t_next": t_next, "speed": speed, "heading": heading,
                "started": xp.ones_like(st)}

    def _boundary(self, p, heading, xp):
        nrm, c, centroid = self.region
        viol = p @ nrm.T - (c - self.margin)                  # (N, M) > 0: outside
        h = xp.stack([xp.cos(heading), xp.sin(heading)], axis=-1)
        outward = h @ nrm.T                                    # (N, M)
        score = xp.where((viol > 0) & (outward > 0), viol, -xp.inf)
        j = xp.argmax(score, axis=1)
        hit = xp.max(score, axis=1) > -xp.inf
        nj = xp.asarray(nrm)[j]
        if self.boundary == "reflect":
            hn = xp.sum(h * nj, axis=-1)
            r = h - 2 * hn[:, None] * nj
            new = xp.arctan2(r[:, 1], r[:, 0])
        else:
            new = xp.arctan2(centroid[1] - p[:, 1], centroid[0] - p[:, 0])
        return xp.where(hit, new, heading)
