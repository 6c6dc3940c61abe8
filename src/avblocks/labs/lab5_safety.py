"""Lab 5's checks: a control-barrier-function safety filter.

Independent truth: the projection onto the half-plane ``a . u >= b``
computed here; the library's ``controllers.safety_filter`` with one
neighbour per agent; the constraint itself (``a . u >= b`` met, ``u``
unchanged where it already held); and the closed loop: two agents swapping
places never come closer than the safety radius, and arrive.
"""

from __future__ import annotations

import numpy as np

from ..blocks import Constant
from ..controllers import HolonomicPointToPoint, safety_filter
from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import SingleIntegrator
from .grading import Failed, Lab, compare, expect_shape


def _case(n, seed):
    rng = np.random.default_rng(seed)
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


def _call(mod, p, u, nb, radius, gamma):
    out = mod.safety_filter_pair(p.copy(), u.copy(), nb.copy(), radius, gamma, xp=np)
    return expect_shape("velocity (safety_filter_pair)", out, p.shape)


def check_projection(mod):
    p, u, nb = _case(12, 1)
    radius, gamma = 1.0, 2.0
    found = _call(mod, p, u, nb, radius, gamma)
    want = _truth(p, u, nb, radius, gamma)
    active = int(np.sum(np.any(want != u, axis=1)))
    compare("velocity (safety_filter_pair)", want, found, atol=1e-9,
            case=f" at 12 random configurations ({active} with the constraint active)")
    return f"the projection at 12 configurations, {active} of them active"


def check_constraint(mod):
    p, u, nb = _case(40, 2)
    radius, gamma = 0.8, 1.5
    nb[::7] = -1                                        # some agents have no neighbour
    found = _call(mod, p, u, nb, radius, gamma)
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


def check_library(mod):
    p, u, nb = _case(15, 3)
    found = _call(mod, p, u, nb, 1.2, 0.7)
    want = safety_filter(p, u, nb[:, None], 1.2, gamma=0.7)
    compare("velocity (safety_filter_pair)", want, found, atol=1e-9,
            case=" against controllers.safety_filter with one neighbour each")
    return "controllers.safety_filter with one neighbour per agent"


def check_swap(mod):
    radius = 1.0
    p0 = np.array([[-3.0, 0.1], [3.0, -0.1]])
    goals = np.array([[3.0, 0.0], [-3.0, 0.0]])
    d = Diagram()
    agents = d.add(SingleIntegrator(position0=p0), name="agents")
    go = d.add(HolonomicPointToPoint(goals[:, None, :], gain=1.0, v_max=1.0, radius=0.05),
               name="go")
    safe = d.add(mod.MySafetyFilter(2, radius, gamma=2.0), name="safe")
    d.connect(agents.position, go.position)
    d.connect(agents.position, safe.position)
    d.connect(go.velocity, safe.velocity_nom)
    d.connect(safe.velocity, agents.velocity)
    res = simulate(d, 30.0, dt=0.01, log=[agents.position])
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


LAB = Lab(5, "safety", "Collision avoidance: a control-barrier-function safety filter",
          names=("safety_filter_pair", "MySafetyFilter"),
          checks=[("the projection", check_projection),
                  ("the barrier constraint", check_constraint),
                  ("same as controllers.safety_filter", check_library),
                  ("two agents swap without contact", check_swap)])
