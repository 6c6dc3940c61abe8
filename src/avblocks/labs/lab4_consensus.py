"""Lab 4's checks: consensus and the graph Laplacian.

Independent truth: ``L = D - A`` and ``-K L x`` computed here; the average
is invariant and every agent ends at it; the disagreement's decay rate on a
ring of N agents, whose second Laplacian eigenvalue is known in closed
form, ``lambda_2 = 2 - 2 cos(2 pi / N)``.
"""

from __future__ import annotations

import numpy as np

from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import SingleIntegrator
from .grading import Failed, Lab, check_ports, compare, expect_shape


def _graph(n, seed, p=0.5):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.2, 2.0, (n, n)) * (rng.random((n, n)) < p)
    a = np.triu(a, 1)
    a = a + a.T
    ring = np.roll(np.eye(n), 1, axis=1)            # keep it connected
    return np.maximum(a, ring + ring.T)


def _ring(n):
    ring = np.roll(np.eye(n), 1, axis=1)
    return ring + ring.T


def check_ports_(mod):
    b = mod.MyConsensus(_ring(5), dim=3)
    return check_ports(b, inputs={"position": (5, 3)}, outputs={"velocity": (5, 3)})


def check_laplacian(mod):
    a = _graph(7, 1)
    found = expect_shape("laplacian", mod.laplacian(a.copy()), (7, 7))
    want = np.diag(a.sum(axis=1)) - a
    compare("laplacian", want, found, atol=1e-12, case=" of a random weighted graph (rows)")
    return "D - A of a weighted graph of 7 nodes"


def _velocity(block, p):
    y = block.output(0.0, {}, {"position": p.copy()}, np)
    if not isinstance(y, dict) or "velocity" not in y:
        raise Failed(f"output must return {{'velocity': (N, D) array}}, returned "
                     f"{type(y).__name__}" + (f" with keys {list(y)}" if isinstance(y, dict)
                                              else ""))
    return expect_shape("velocity", y["velocity"], p.shape)


def check_law(mod):
    a, k = _graph(6, 2), 0.7
    p = np.random.default_rng(3).normal(size=(6, 2)) * 4
    found = _velocity(mod.MyConsensus(a, gain=k), p)
    want = -k * (np.diag(a.sum(axis=1)) - a) @ p
    compare("velocity", want, found, atol=1e-9, case=f" (K = {k}, a random weighted graph)")
    return "u = -K L x on a weighted graph"


def _run(block, p0, t_final, dt=0.01):
    d = Diagram()
    agents = d.add(SingleIntegrator(position0=p0), name="agents")
    law = d.add(block, name="law")
    d.connect(agents.position, law.position)
    d.connect(law.velocity, agents.velocity)
    res = simulate(d, t_final, dt=dt, log=[agents.position])
    return res.t, res[agents.position]


def check_average(mod):
    a, k = _graph(8, 4), 1.0
    p0 = np.random.default_rng(5).normal(size=(8, 2)) * 5
    _, traj = _run(mod.MyConsensus(a, gain=k), p0, 20.0)
    mean0 = p0.mean(axis=0)
    compare("position (mean over the agents)", mean0[None], traj[-1].mean(axis=0)[None],
            atol=1e-9, case=" at 20 s: the average must not move")
    compare("position", np.repeat(mean0[None], 8, axis=0), traj[-1], atol=1e-6,
            case=" at 20 s: every agent at the initial average")
    return "the average is kept and every agent reaches it"


def check_rate(mod):
    n, k = 10, 0.5
    lam2 = 2 - 2 * np.cos(2 * np.pi / n)
    p0 = np.random.default_rng(6).normal(size=(n, 2)) * 3
    t, traj = _run(mod.MyConsensus(_ring(n), gain=k), p0, 40.0)
    dis = np.linalg.norm(traj - traj.mean(axis=1, keepdims=True), axis=(1, 2))
    i1, i2 = np.searchsorted(t, 20.0), np.searchsorted(t, 40.0) - 1
    if not (dis[i2] > 0 and dis[i1] > 0):
        raise Failed("the disagreement vanished exactly: was the law applied at all?")
    rate = np.log(dis[i1] / dis[i2]) / (t[i2] - t[i1])
    if abs(rate - k * lam2) <= 0.01 * k * lam2:
        return (f"ring of {n}: decay rate {rate:.4f}/s, K lambda_2 = {k * lam2:.4f}/s")
    raise Failed(f"the disagreement |x - mean| on a ring of {n} (K = {k}) decays at "
                 f"{rate:.4f}/s between 20 and 40 s; expected K lambda_2 = "
                 f"{k * lam2:.4f}/s (lambda_2 = 2 - 2 cos(2 pi / {n}))")


LAB = Lab(4, "consensus", "Consensus and the graph Laplacian: convergence rate and the "
          "second eigenvalue", names=("laplacian", "MyConsensus"),
          checks=[("ports", check_ports_), ("laplacian", check_laplacian),
                  ("the law u = -K L x", check_law),
                  ("average kept, consensus reached", check_average),
                  ("convergence rate K lambda_2", check_rate)])
