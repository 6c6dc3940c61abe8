"""Lab 4's checks: consensus and the graph Laplacian.

Independent truth: ``L = D - A`` and ``-K L x`` computed here; the average
is invariant and every agent ends at it; the disagreement's decay rate on a
ring of N agents, whose second Laplacian eigenvalue is known in closed
form, ``lambda_2 = 2 - 2 cos(2 pi / N)``.

With a seed (``--seed``, ``--student``) the graphs, gains, positions and
the ring's size are drawn per student (graphs whose consensus is slow
enough to miss the 20 s deadline are drawn again: their second eigenvalue
is computed here).
"""

from __future__ import annotations

import numpy as np

from ..core.diagram import Diagram
from ..core.frontend import simulate
from ..vehicles import SingleIntegrator
from .grading import Failed, Lab, check_ports, compare, expect_shape


def _graph(sub, n, seed, p=0.5):
    rng = sub.rng(seed)
    a = rng.uniform(0.2, 2.0, (n, n)) * (rng.random((n, n)) < p)
    a = np.triu(a, 1)
    a = a + a.T
    ring = np.roll(np.eye(n), 1, axis=1)            # keep it connected
    return np.maximum(a, ring + ring.T)


def _ring(n):
    ring = np.roll(np.eye(n), 1, axis=1)
    return ring + ring.T


def check_ports_(sub):
    b = sub.MyConsensus(_ring(5), dim=3)
    return check_ports(b, inputs={"position": (5, 3)}, outputs={"velocity": (5, 3)})


def check_laplacian(sub):
    n = sub.pick(7, lambda: int(sub.rng(11).integers(5, 10)))
    a = _graph(sub, n, 1)
    found = expect_shape("laplacian", sub.laplacian(a.copy()), (n, n))
    want = np.diag(a.sum(axis=1)) - a
    compare("laplacian", want, found, atol=1e-12, case=" of a random weighted graph (rows)")
    return f"D - A of a weighted graph of {n} nodes"


def _velocity(block, p):
    y = block.output(0.0, {}, {"position": p.copy()}, np)
    if not isinstance(y, dict) or "velocity" not in y:
        raise Failed(f"output must return {{'velocity': (N, D) array}}, returned "
                     f"{type(y).__name__}" + (f" with keys {list(y)}" if isinstance(y, dict)
                                              else ""))
    return expect_shape("velocity", y["velocity"], p.shape)


def check_law(sub):
    a = _graph(sub, 6, 2)
    k = sub.pick(0.7, lambda: round(float(sub.rng(12).uniform(0.3, 1.5)), 3))
    p = sub.rng(3).normal(size=(6, 2)) * 4
    found = _velocity(sub.MyConsensus(a, gain=k), p)
    want = -k * (np.diag(a.sum(axis=1)) - a) @ p
    compare("velocity", want, found, atol=1e-9, case=f" (K = {k}, a random weighted graph)")
    return "u = -K L x on a weighted graph"


def _run(block, p0, t_final, dt=0.02):
    d = Diagram()
    agents = d.add(SingleIntegrator(position0=p0), name="agents")
    law = d.add(block, name="law")
    d.connect(agents.position, law.position)
    d.connect(law.velocity, agents.velocity)
    res = simulate(d, t_final, dt=dt, log=[agents.position])
    return res.t, res[agents.position]


def _lambda2(a):
    return float(np.sort(np.linalg.eigvalsh(np.diag(a.sum(axis=1)) - a))[1])


def check_average(sub):
    k = sub.pick(1.0, lambda: round(float(sub.rng(13).uniform(0.8, 1.5)), 3))
    a = _graph(sub, 8, 4)
    for j in range(1, 50):              # a drawn graph slow to agree in 20 s: the next one
        if not sub.seeded or k * _lambda2(a) >= 1.2:
            break
        a = _graph(sub, 8, 4 + 1000 * j)
    p0 = sub.rng(5).normal(size=(8, 2)) * 5
    _, traj = _run(sub.MyConsensus(a, gain=k), p0, 20.0)
    mean0 = p0.mean(axis=0)
    compare("position (mean over the agents)", mean0[None], traj[-1].mean(axis=0)[None],
            atol=1e-9, case=" at 20 s: the average must not move")
    compare("position", np.repeat(mean0[None], 8, axis=0), traj[-1], atol=1e-6,
            case=" at 20 s: every agent at the initial average")
    return "the average is kept and every agent reaches it"


def check_rate(sub):
    rng = sub.rng(14)
    n, k = sub.pick((10, 0.5), lambda: (int(rng.integers(8, 11)),
                                        round(float(rng.uniform(0.4, 0.7)), 3)))
    lam2 = 2 - 2 * np.cos(2 * np.pi / n)
    p0 = sub.rng(6).normal(size=(n, 2)) * 3
    t, traj = _run(sub.MyConsensus(_ring(n), gain=k), p0, 40.0, dt=0.05)
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
