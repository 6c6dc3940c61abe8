"""Lab 5's checks: a control-barrier-function safety filter, and flocking.

Independent truth: the projection onto the half-plane ``a . u >= b``
computed here; the library's ``controllers.safety_filter`` with one
neighbour per agent; the constraint itself (``a . u >= b`` met, ``u``
unchanged where it already held); and the closed loop: two agents swapping
places never come closer than the safety radius, and arrive.

Flocking (part 2), Olfati-Saber (2006), Algorithm 1, eq. (23): the
student's ``flocking_alpha`` against the paper's equations written here
pair by pair with scalar arithmetic (sigma-norm, bump ``rho_h``, action
``phi_alpha``); against the library's ``controllers.flocking_law`` with
other constants in 3-D; and the closed loop of twelve double integrators
behind a moving target: no pair closer than 0.35 d at any time, at the end
every pair at least 0.8 d apart, every agent with a neighbour within r,
and the velocities aligned (order parameter at least 0.999).

The filter's inputs arrive read-only: writing the correction into
``u_nom`` in place (in a diagram, another block's output) fails at once
with a message naming it. With a seed (``--seed``, ``--student``) the
configurations, radii, gains and the flocking constants are drawn per
student.
"""

from __future__ import annotations

import math

import numpy as np

from ..controllers import HolonomicPointToPoint, flocking_law, safety_filter
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import DoubleIntegrator, SingleIntegrator
from .grading import Failed, Lab, compare, expect_shape


def _case(sub, n, seed):
    rng = sub.rng(seed)
    p = rng.uniform(-2, 2, (n, 2))
    u = rng.normal(size=(n, 2))
    nb = (np.arange(n) + 1) % n
    return p, u, nb


def _truth(p, u, nb, radius, gamma):
    a = p - p[nb]
    h = np.sum(a * a, axis=1) - radius ** 2
    b = -gamma * h / 4
    short = np.maximum(0.0, b - np.sum(a * u, axis=1))
    out = u + (short / np.sum(a * a, axis=1))[:, None] * a
    return np.where((nb >= 0)[:, None], out, u)


def _call(sub, p, u, nb, radius, gamma):
    out = sub.safety_filter_pair(p.copy(), u.copy(), nb.copy(), radius, gamma, xp=np)
    return expect_shape("velocity (safety_filter_pair)", out, p.shape)


def _radius_gamma(sub, k, fixed):
    rng = sub.rng(100 + k)
    return sub.pick(fixed, lambda: (round(float(rng.uniform(0.6, 1.4)), 3),
                                    round(float(rng.uniform(0.5, 3.0)), 3)))


def check_projection(sub):
    p, u, nb = _case(sub, 12, 1)
    radius, gamma = _radius_gamma(sub, 1, (1.0, 2.0))
    found = _call(sub, p, u, nb, radius, gamma)
    want = _truth(p, u, nb, radius, gamma)
    active = int(np.sum(np.any(want != u, axis=1)))
    compare("velocity (safety_filter_pair)", want, found, atol=1e-9,
            case=f" at 12 random configurations ({active} with the constraint active)")
    return f"the projection at 12 configurations, {active} of them active"


def check_constraint(sub):
    p, u, nb = _case(sub, 40, 2)
    radius, gamma = _radius_gamma(sub, 2, (0.8, 1.5))
    nb[::7] = -1                                        # some agents have no neighbour
    found = _call(sub, p, u, nb, radius, gamma)
    has = nb >= 0
    a = p - p[np.where(has, nb, 0)]
    b = -gamma * (np.sum(a * a, axis=1) - radius ** 2) / 4
    slack = np.sum(a * found, axis=1) - b
    bad = has & (slack < -1e-9)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise Failed(f"agent {i}: (p_i - p_j) . u_i = {np.dot(a[i], found[i]):.4g}, "
                     f"expected >= b = {b[i]:.4g} (j = {nb[i]})")
    held = has & (np.sum(a * u, axis=1) >= b)
    compare("velocity (where the constraint already held)", u[held], found[held], atol=1e-12,
            case=": must be u_nom unchanged")
    compare("velocity (agents without a neighbour, -1)", u[~has], found[~has], atol=1e-12,
            case=": must be u_nom unchanged")
    return "a . u >= b met; u_nom kept where it was safe or alone"


def check_library(sub):
    p, u, nb = _case(sub, 15, 3)
    radius, gamma = _radius_gamma(sub, 3, (1.2, 0.7))
    found = _call(sub, p, u, nb, radius, gamma)
    want = safety_filter(p, u, nb[:, None], radius, gamma=gamma)
    compare("velocity (safety_filter_pair)", want, found, atol=1e-9,
            case=" against controllers.safety_filter with one neighbour each")
    return "controllers.safety_filter with one neighbour per agent"


def check_swap(sub):
    rng = sub.rng(15)
    radius = sub.pick(1.0, lambda: round(float(rng.uniform(0.8, 1.2)), 3))
    dy = sub.pick(0.1, lambda: round(float(rng.uniform(0.05, 0.2)), 3))
    p0 = np.array([[-3.0, dy], [3.0, -dy]])
    goals = np.array([[3.0, 0.0], [-3.0, 0.0]])
    d = Diagram()
    agents = d.add(SingleIntegrator(position0=p0), name="agents")
    go = d.add(HolonomicPointToPoint(goals[:, None, :], gain=1.0, v_max=1.0, radius=0.05),
               name="go")
    safe = d.add(sub.MySafetyFilter(2, radius, gamma=2.0), name="safe")
    d.connect(agents.position, go.position)
    d.connect(agents.position, safe.position)
    d.connect(go.velocity, safe.velocity_nom)
    d.connect(safe.velocity, agents.velocity)
    res = simulate(d, 30.0, dt=0.02, log=[agents.position])
    x = res[agents.position]
    gap = np.linalg.norm(x[:, 0] - x[:, 1], axis=1)
    k = int(np.argmin(gap))
    if gap[k] < radius - 1e-3:
        raise Failed(f"the two agents came {gap[k]:.4f} m apart at t = {res.t[k]:.2f} s; "
                     f"the safety radius is {radius} m")
    miss = np.linalg.norm(x[-1] - goals, axis=1)
    if np.any(miss > 0.1):
        raise Failed(f"after 30 s agent {int(np.argmax(miss))} is {miss.max():.3f} m from its "
                     f"goal (expected < 0.1 m): does the filter stop them for good?")
    return f"closest approach {gap[k]:.3f} m (radius {radius} m); both at their goals"


# ------------------------------------------------------------------ part 2: flocking
def _alpha_truth(q, p, d, r, eps, a, b, h, c1, c2):
    """Eq. (23) of Olfati-Saber (2006), pair by pair in scalar arithmetic."""
    def snorm(sq):                                       # ||z||_s from |z|^2
        return (math.sqrt(1.0 + eps * sq) - 1.0) / eps

    def rho(x):
        if 0.0 <= x < h:
            return 1.0
        if h <= x <= 1.0:
            return 0.5 * (1.0 + math.cos(math.pi * (x - h) / (1.0 - h)))
        return 0.0

    c = abs(a - b) / math.sqrt(4.0 * a * b)
    r_a, d_a = snorm(r * r), snorm(d * d)

    def phi_alpha(s):
        z = s - d_a + c
        return rho(s / r_a) * 0.5 * ((a + b) * z / math.sqrt(1.0 + z * z) + (a - b))

    n, dim = q.shape
    out = np.zeros((n, dim))
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            dq = [float(q[j, k] - q[i, k]) for k in range(dim)]
            sq = sum(x * x for x in dq)
            s = snorm(sq)
            grad = phi_alpha(s) / math.sqrt(1.0 + eps * sq)
            w = rho(s / r_a)
            for k in range(dim):
                out[i, k] += c1 * grad * dq[k] + c2 * w * float(p[j, k] - p[i, k])
    return out


def _flock_case(sub, n, dim, seed, spread):
    rng = sub.rng(seed)
    return rng.uniform(0, spread, (n, dim)), rng.normal(size=(n, dim))


def _alpha(sub, q, p, d, r, **k):
    out = sub.flocking_alpha(q.copy(), p.copy(), d, r, xp=np, **k)
    return expect_shape("accel (flocking_alpha)", out, q.shape)


def check_flocking_equations(sub):
    q, p = _flock_case(sub, 10, 2, 7, 3.0)
    d, r = sub.pick((1.0, 1.2), lambda: (1.0, round(float(sub.rng(16).uniform(1.1, 1.6)), 3)))
    found = _alpha(sub, q, p, d, r)
    want = _alpha_truth(q, p, d, r, 0.1, 5.0, 5.0, 0.2, 1.0, 1.0)
    dist = np.linalg.norm(q[:, None] - q[None], axis=-1)[np.triu_indices(10, 1)]
    within = int(np.sum(dist < r))
    compare("accel (flocking_alpha)", want, found, atol=1e-9,
            case=f" at 10 agents ({within} of 45 pairs within r = {r} m), eq. (23)")
    return f"eq. (23) at 10 agents, {within} of 45 pairs within range"


def check_flocking_library(sub):
    q, p = _flock_case(sub, 9, 3, 8, 4.0)
    rng = sub.rng(17)
    k = sub.pick(dict(eps=0.2, a=3.0, b=6.0, h=0.3, c1=2.0, c2=0.5), lambda: {
        key: round(float(v), 3) for key, v in (
            ("eps", rng.uniform(0.05, 0.3)), ("a", rng.uniform(1.0, 4.0)),
            ("b", rng.uniform(4.0, 8.0)), ("h", rng.uniform(0.1, 0.5)),
            ("c1", rng.uniform(0.5, 2.5)), ("c2", rng.uniform(0.2, 1.5)))})
    found = _alpha(sub, q, p, 1.5, 2.5, **k)
    idx = np.array([[j for j in range(9) if j != i] for i in range(9)])
    want = flocking_law(q, p, idx, 1.5, 2.5, xp=np, **k)
    compare("accel (flocking_alpha)", want, found, atol=1e-9,
            case=" in 3-D, " + ", ".join(f"{n}={v:g}" for n, v in k.items())
                 + ", against controllers.flocking_law")
    return "controllers.flocking_law in 3-D with other constants"


def check_flock_forms(sub):
    n, d = 12, 1.0
    r = 1.2 * d
    rng = sub.rng(5)
    grid = np.stack(np.meshgrid(np.arange(4.0), np.arange(3.0)), -1).reshape(-1, 2) * 1.1
    q0, v0 = grid + rng.uniform(-0.2, 0.2, (n, 2)), rng.normal(size=(n, 2))
    dg = Diagram()
    flock = dg.add(DoubleIntegrator(q0, velocity0=v0), name="flock")
    target_v = sub.pick([1.0, 0.5], lambda: [round(float(v), 3) for v in
                                             rng.uniform(-1.0, 1.0, 2)])
    law = dg.add(sub.MyFlocking(n, d, target=[2.0, 2.0], target_velocity=target_v),
                 name="law")
    dg.connect(flock.position, law.position)
    dg.connect(flock.velocity, law.velocity)
    dg.connect(law.accel, flock.accel)
    res = simulate(dg, 20.0, dt=0.05, log=[flock.position, flock.velocity])
    x, v = np.asarray(res[flock.position]), np.asarray(res[flock.velocity])
    if not np.all(np.isfinite(x)):
        raise Failed("the positions became NaN or inf during the 20 s run")
    gap = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1) + np.where(np.eye(n), np.inf, 0)
    closest = gap.min(axis=(1, 2))
    k = int(np.argmin(closest))
    if closest[k] < 0.35 * d:
        raise Failed(f"two agents came {closest[k]:.3f} m apart at t = {res.t[k]:.2f} s "
                     f"(expected at least 0.35 d = {0.35 * d:g} m): is the separation "
                     f"(phi_alpha < 0 inside d) pushing them apart?")
    if closest[-1] < 0.8 * d:
        raise Failed(f"after 20 s the closest pair is {closest[-1]:.3f} m apart, expected "
                     f"at least 0.8 d = {0.8 * d:g} m (the lattice distance is {d:g} m)")
    lonely = gap[-1].min(axis=1)
    if np.any(lonely > r):
        i = int(np.argmax(lonely))
        raise Failed(f"after 20 s agent {i}'s nearest neighbour is {lonely[i]:.3f} m away, "
                     f"beyond the range r = {r:g} m: the flock came apart")
    order = float(np.linalg.norm(v[-1].sum(axis=0)) / np.linalg.norm(v[-1], axis=1).sum())
    if order < 0.999:
        raise Failed(f"after 20 s the order parameter |sum p_i| / sum |p_i| is {order:.4f}, "
                     f"expected at least 0.999 (velocities aligned)")
    return (f"closest pair {closest.min():.3f} m over the run, {closest[-1]:.3f} m at the end; "
            f"order parameter {order:.5f}")


LAB = Lab(5, "safety", "Collision avoidance with a safety filter, and flocking",
          names=("safety_filter_pair", "MySafetyFilter", "flocking_alpha", "MyFlocking"),
          checks=[("the projection", check_projection),
                  ("the barrier constraint", check_constraint),
                  ("same as controllers.safety_filter", check_library),
                  ("two agents swap without contact", check_swap),
                  ("flocking: eq. (23) pair by pair", check_flocking_equations),
                  ("flocking: same as controllers.flocking_law", check_flocking_library),
                  ("flocking: a flock forms", check_flock_forms)])
