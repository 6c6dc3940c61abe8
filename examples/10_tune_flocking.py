"""Tune Olfati-Saber flocking gains by gradient descent through a whole run (JAX).

    python examples/10_tune_flocking.py [ITERATIONS]

Twenty double integrators start scattered (the ``flocking`` scenario) and
flock with Algorithm 1 of Olfati-Saber (2006) plus a moving target. The cost
of a 20 s run is the lattice error plus a price on the commands,

    J(c1, c2) = mean_{t, (i,j)} (|q_i - q_j| - d)^2 + rho * mean_{t, i} |u_i|^2,

over the neighbour pairs (i, j). The neighbour sets are frozen at the start
(``make_diagram(neighbors="frozen")``: a fixed graph, no search block) — a
gradient through a run assumes neighbour sets that do not switch when a gain
changes a little, and finite differences of NumPy runs agree with it to 1e-8
(tests/scenarios/test_flocking_ensemble_grad.py). ``av.compile`` traces the
diagram once; ``runner.value_and_grad`` gives J and dJ/d(c1, c2) by reverse
mode with the gains passed in as data (no recompilation per iteration).
Gradient descent on log-gains (they stay positive); the tuned gains are then
checked on the NumPy engine. Writes tune_flocking.png: J per iteration, and the
mean lattice error over time before and after.
"""

import os
import sys

import matplotlib

matplotlib.use("Agg")
import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import avblocks as av  # noqa: E402
from avblocks.scenarios import flocking  # noqa: E402

iterations = int(sys.argv[1]) if len(sys.argv) > 1 else 20
small = bool(os.environ.get("AVBLOCKS_EXAMPLE_SMALL"))
if small:
    iterations = min(iterations, 3)
n, d, spread, rho = (8, 7.0, 18.0, 0.01) if small else (20, 7.0, 30.0, 0.01)
t_final, dt = (3.0, 0.04) if small else (20.0, 0.02)

dg, sim = flocking.make_diagram(agents=n, d=d, spread=spread, t_final=t_final, dt=dt,
                                neighbors="frozen", c1=0.5, c2=0.5)
p0, _ = flocking.initial_conditions(n, d, spread, 2.0, sim["seed"])
pairs = flocking.pairs(flocking.frozen_adjacency(p0, 12, 1.2 * d))
log = ["flock.position", "law.accel"]
runner = av.compile(dg, t_final, dt=dt, log=log)


def cost(res, xp=jnp):
    """J of a run (jax.numpy when differentiated, NumPy for the check)."""
    return flocking.lattice_cost(res["flock.position"], res["law.accel"], pairs, d,
                                 effort=rho, xp=xp)


def gains(z):
    return {"law.c1": np.exp(z[0]), "law.c2": np.exp(z[1])}


z = np.log([0.5, 0.5])          # log-gains
history = []
step, prev = 0.5, None
for it in range(iterations):
    J, g = runner.value_and_grad(cost, ["law.c1", "law.c2"], params=gains(z))
    J = float(J)
    gz = np.array([float(g["law.c1"]), float(g["law.c2"])]) * np.exp(z)
    history.append((J, *np.exp(z)))
    if prev is not None and J > prev:
        step *= 0.5                     # overshoot: shorter steps
    prev = J
    print(f"iteration {it:2d}: c1 = {np.exp(z[0]):.3f}  c2 = {np.exp(z[1]):.3f}"
          f"  J = {J:8.4f}")
    z = z - step * gz / max(np.linalg.norm(gz), 1e-12)
history = np.array(history)
best = history[np.argmin(history[:, 0])]

# the tuned gains on the NumPy engine: the same cost, the errors before/after
before = av.simulate(dg, t_final, dt=dt, log=log, params=gains(np.log(history[0, 1:])))
after = av.simulate(dg, t_final, dt=dt, log=log,
                    params={"law.c1": best[1], "law.c2": best[2]})
J_np = float(cost(after, np))


def lattice_error(res):
    i, j = pairs
    q = np.asarray(res["flock.position"])
    return np.abs(np.linalg.norm(q[:, i] - q[:, j], axis=-1) - d).mean(axis=1)


fig, (ax, ae) = plt.subplots(1, 2, figsize=(11, 4.2))
ax.plot(history[:, 0], "o-", ms=3)
ax.set_xlabel("gradient step")
ax.set_ylabel("cost J")
ax.set_title(f"J: {history[0, 0]:.3f} -> {best[0]:.3f} "
             f"(c1 {history[0, 1]:.2f} -> {best[1]:.2f}, "
             f"c2 {history[0, 2]:.2f} -> {best[2]:.2f})", fontsize=9)
ax.grid(alpha=0.3)
for res, style, label in ((before, "--", "initial gains"), (after, "-", "tuned gains")):
    ae.plot(res.t, lattice_error(res), style, label=label)
ae.set_xlabel("t [s]")
ae.set_ylabel("mean | |q_i - q_j| - d |  over neighbour pairs [m]")
ae.legend()
ae.grid(alpha=0.3)
fig.tight_layout()
fig.savefig("tune_flocking.png", dpi=100)
print(f"J {history[0, 0]:.4f} -> {best[0]:.4f} (NumPy engine: {J_np:.4f}); "
      f"compilations: {runner.compilations}; wrote tune_flocking.png")
